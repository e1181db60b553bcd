//! What an engine is set up with, and what can go wrong setting it up.

use crate::compensation::CompensationError;
use crate::compensation::chain::Compensation;
use crate::force::drive::{DriveKind, Polarity};
use crate::force::steps::DetectorConfig;
use crate::safety::WatchdogConfig;
use crate::synthesis::VoiceError;
use crate::units::{Decibels, Hz, Newtons, SampleRate, Seconds};

/// Everything the engine is set up with.
#[derive(Debug, Clone, PartialEq)]
pub struct EngineConfig {
    /// Audio rate.
    pub rate: SampleRate,
    /// Number of channels (actuators), each with its own input and material.
    pub channels: usize,
    /// The largest block rendered in one go; larger device buffers are split.
    pub max_block: usize,
    /// What drives the filters.
    pub drive: DriveKind,
    /// Which half of `dF/dt` the `ForceRate` drive keeps.
    pub polarity: Polarity,
    /// Standard deviation of the per-step numerator perturbation: `None` (the default) for
    /// each material's own, sized from its recordings' spread between steps
    /// ([`PreparedMaterial::perturbation`](crate::synthesis::PreparedMaterial::perturbation)),
    /// `Some(0.01)` for the IIR paper's 1% on every material.
    pub perturbation: Option<f32>,
    /// Seed of the perturbation and of the excitation's trains; channel `c` uses streams
    /// derived from it.
    pub seed: u64,
    /// Nominal body weight the force drives normalise by (default 70 kg).
    pub nominal_weight: Newtons,
    /// About how often sensor readings arrive (sets the force ramp, and the reading
    /// period assumed for readings without a sensor time; default 500 Hz).
    pub sensor_rate: Hz,
    /// Jitter margin of the sensor clock (`M` in [`clock`](super::clock)): a stamped reading sent
    /// without a frame plays one block plus this after its sensor time (default 10 ms).
    pub sensor_latency: Seconds,
    /// Heel-strike detection.
    pub detector: DetectorConfig,
    /// Input watchdog.
    pub watchdog: WatchdogConfig,
    /// Output gain before the limiter (default 0 dB).
    pub gain: Decibels,
    /// Limiter ceiling relative to full scale (default -6 dB).
    pub ceiling: Decibels,
    /// Limiter release (default 50 ms).
    pub release: Seconds,
    /// Material crossfade (default 20 ms).
    pub crossfade: Seconds,
    /// Start-up and shut-down fade (default 10 ms).
    pub fade: Seconds,
    /// Capacity of the event queue (default 8192).
    pub queue_capacity: usize,
    /// Bank slots reserved beyond the bank's materials for materials added while the
    /// engine runs ([`Controller::add_material`](super::Controller::add_material)); default 0.
    pub spare_slots: usize,
    /// Device equalizer and limb compensation, applied to every channel before its
    /// limiter (default: none).
    pub compensation: Compensation,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            rate: SampleRate(48_000),
            channels: 1,
            max_block: 512,
            drive: DriveKind::Impulse,
            polarity: Polarity::Loading,
            perturbation: None,
            seed: 0x5EED,
            nominal_weight: Newtons::weight_of(70.0),
            sensor_rate: Hz(500.0),
            sensor_latency: Seconds(0.01),
            detector: DetectorConfig::default(),
            watchdog: WatchdogConfig::default(),
            gain: Decibels(0.0),
            ceiling: crate::safety::DEFAULT_CEILING,
            release: Seconds(0.05),
            crossfade: Seconds(0.02),
            fade: Seconds(0.01),
            queue_capacity: 8192,
            spare_slots: 0,
            compensation: Compensation::default(),
        }
    }
}

/// Why an engine cannot be built or a command not sent.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum EngineError {
    /// A setting is out of range.
    #[error("invalid engine setting: {0}")]
    InvalidConfig(String),
    /// A material cannot be played.
    #[error(transparent)]
    Voice(#[from] VoiceError),
    /// A material name is not in the bank.
    #[error("no material {name:?} in the engine's bank (available: {available})")]
    UnknownMaterial {
        /// The name asked for.
        name: String,
        /// The names there are.
        available: String,
    },
    /// The compensation cannot run at this engine's settings.
    #[error("compensation: {0}")]
    Compensation(#[from] CompensationError),
    /// Every spare slot of the bank is taken.
    #[error("the engine's bank is full ({capacity} slots): restart to add more materials")]
    BankFull {
        /// Slots in all.
        capacity: usize,
    },
    /// An offline render would hold more than [`super::offline::MAX_RENDER`] of output.
    #[error(
        "the track lasts {:.0} s; a render of {channels} channel(s) is at most {:.0} s",
        length.0,
        limit.0
    )]
    TooLong {
        /// How long the track is.
        length: crate::units::Seconds,
        /// Its channels.
        channels: usize,
        /// The longest render of that many channels.
        limit: crate::units::Seconds,
    },
    /// The event queue is full: the audio thread is not running or not keeping up.
    #[error("the engine's event queue is full (is the audio device running?)")]
    QueueFull,
}
