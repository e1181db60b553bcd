//! What can be wrong with a gait spec or configuration.

use super::MAX_ROWS;
use super::spec::SPEC_KEYS;

/// What is wrong with a gait spec or configuration.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GaitError {
    /// A spec item without `=`.
    #[error("gait spec: {item:?} is not key=value")]
    Malformed {
        /// The item as written.
        item: String,
    },
    /// A spec key that is not one of [`SPEC_KEYS`].
    #[error("gait spec: unknown key {key:?} (in {key}={value}); known keys: {}", SPEC_KEYS.join(", "))]
    UnknownKey {
        /// The key.
        key: String,
        /// Its value.
        value: String,
    },
    /// A spec key given twice.
    #[error("gait spec: {key} is given twice")]
    DuplicateKey {
        /// The key.
        key: String,
    },
    /// A spec value that does not parse.
    #[error("gait spec: {key}={value}: {value:?} is not {expected}")]
    BadNumber {
        /// The key.
        key: String,
        /// The value as written.
        value: String,
        /// What it should be, e.g. `a whole number`.
        expected: &'static str,
    },
    /// A setting outside its range.
    #[error("gait {key} = {value} is out of range: {allowed}")]
    OutOfRange {
        /// The setting, by its spec key.
        key: &'static str,
        /// Its value.
        value: String,
        /// The range allowed.
        allowed: &'static str,
    },
    /// A walk of more than [`MAX_ROWS`] rows.
    #[error(
        "gait of {steps} steps at {cadence} steps/s and {rate} Hz needs up to {rows} rows; at \
         most {MAX_ROWS} (fewer steps or a lower rate)"
    )]
    TooLong {
        /// Steps per channel.
        steps: usize,
        /// Cadence in steps per second.
        cadence: f64,
        /// Sensor rate in hertz.
        rate: f64,
        /// Rows needed at most.
        rows: u64,
    },
}
