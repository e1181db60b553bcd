//! The table of users: each known user's equalizer curve, and the curve for a new user
//! interpolated from their limb parameters.
//!
//! The compensation paper replaces real-time correction by a preset equalizer per user, looked up from
//! the user's limb parameters ([`LimbParams`]) and interpolated between known users. Each
//! entry holds a curve of spectral weights in dB on the table's common frequency grid
//! (typically the device equalizer's weights plus `|Z_c|` in dB); the caller computes them.
//!
//! # Interpolation
//!
//! Inverse-distance weighting (Shepard, power 2) in a normalised log-parameter space:
//!
//! ```math
//! d_i^2 = \sum_{j=1}^{3} \left( \frac{\ln p_j - \ln p_{ij}}{s_j} \right)^2, \qquad
//!   w(f) = \frac{\sum_i d_i^{-2}\, w_i(f)}{\sum_i d_i^{-2}},
//! ```
//!
//! with scales `s_j` Table 1's relative standard deviations ([`LOG_SCALES`]): `0.0016/0.0037`,
//! `4.1/5.8` and `1500/2402`. The logarithm because the parameters are positive and span
//! decades (a 10 % change means the same wherever it happens); the scale because a natural
//! unit for each parameter is how much it varies between people, which makes the three
//! comparable. A query that equals a user's parameters (`d = 0`) returns that user's curve.
//! The weights are positive and sum to one, so the result is a convex combination: at every
//! frequency it lies between the smallest and largest of the users' weights.
//!
//! # File
//!
//! JSON, `{"format": "underfoot.user-table/1", "freqs": [...], "entries": [{"name",
//! "params", "weights_db"}]}`: a [`Document`] read and written like the other compensation
//! [`files`](mod@super::files) ([`document::load`], [`document::save`]): the tag checked
//! first, every entry checked as [`UserTable::add`] checks it, written to a temporary file
//! renamed over the target, so a reader never sees half a table. Tables written before the
//! document layer, with `"kind": "user-table"` and `"version": 1`, still load.
//!
//! [`document::load`]: crate::document::load
//! [`document::save`]: crate::document::save

use serde::{Deserialize, Serialize};

use super::CompensationError;
use super::limb::LimbParams;
use crate::document::Document;
use crate::units::Hz;

/// The scale of each log-parameter `[ln b3/k3, ln k2/m2, ln b2/m2]` in the interpolation's
/// distance: Table 1's standard deviation over its mean.
pub const LOG_SCALES: [f64; 3] = [0.0016 / 0.0037, 4.1 / 5.8, 1500.0 / 2402.0];

/// One known user.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserEntry {
    /// The user's name, unique in the table.
    pub name: String,
    /// Their fitted limb parameters.
    pub params: LimbParams,
    /// Their equalizer's spectral weights in dB, one per frequency of the table.
    pub weights_db: Vec<f64>,
}

/// Known users' equalizer curves on a common frequency grid; the `user-table` file
/// ([`Document`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserTable {
    /// The frequencies of every curve, ascending.
    pub freqs: Vec<Hz>,
    /// The users.
    pub entries: Vec<UserEntry>,
}

/// The squared distance between two parameter sets in the interpolation's space.
#[must_use]
pub fn distance_sq(a: &LimbParams, b: &LimbParams) -> f64 {
    a.to_array()
        .iter()
        .zip(b.to_array())
        .zip(LOG_SCALES)
        .map(|((x, y), s)| ((x.ln() - y.ln()) / s).powi(2))
        .sum()
}

impl UserTable {
    /// An empty table on `freqs`.
    ///
    /// # Errors
    /// [`CompensationError::Empty`] for no frequencies,
    /// [`CompensationError::InvalidParameter`] unless they are finite, non-negative and
    /// strictly ascending.
    pub fn new(freqs: Vec<Hz>) -> Result<Self, CompensationError> {
        check_grid(&freqs)?;
        Ok(Self {
            freqs,
            entries: Vec::new(),
        })
    }

    /// Adds `entry`, replacing (in place) a user of the same name, whom it returns.
    ///
    /// # Errors
    /// [`CompensationError::Mismatch`] when the curve's length is not the grid's,
    /// [`CompensationError::NonFinite`] for a non-finite weight,
    /// [`CompensationError::InvalidParameter`] for invalid parameters.
    pub fn add(&mut self, entry: UserEntry) -> Result<Option<UserEntry>, CompensationError> {
        self.check(&entry)?;
        match self.entries.iter_mut().find(|e| e.name == entry.name) {
            Some(slot) => Ok(Some(std::mem::replace(slot, entry))),
            None => {
                self.entries.push(entry);
                Ok(None)
            }
        }
    }

    fn check(&self, entry: &UserEntry) -> Result<(), CompensationError> {
        entry.params.validate()?;
        if entry.weights_db.len() != self.freqs.len() {
            return Err(CompensationError::Mismatch {
                what: "weights_db",
                len: entry.weights_db.len(),
                expected: self.freqs.len(),
            });
        }
        if let Some(index) = entry.weights_db.iter().position(|w| !w.is_finite()) {
            return Err(CompensationError::NonFinite {
                what: "weights_db",
                index,
            });
        }
        Ok(())
    }

    /// Removes the user called `name`, whom it returns (`None`: no such user).
    pub fn remove(&mut self, name: &str) -> Option<UserEntry> {
        let index = self.entries.iter().position(|e| e.name == name)?;
        Some(self.entries.remove(index))
    }

    /// The user called `name`.
    #[must_use]
    pub fn get(&self, name: &str) -> Option<&UserEntry> {
        self.entries.iter().find(|e| e.name == name)
    }

    /// The equalizer curve (dB, on [`UserTable::freqs`]) for a user with `params`,
    /// interpolated between the known users (see the module docs).
    ///
    /// # Errors
    /// [`CompensationError::Empty`] for a table without users,
    /// [`CompensationError::InvalidParameter`] for invalid parameters.
    pub fn interpolate(&self, params: &LimbParams) -> Result<Vec<f64>, CompensationError> {
        params.validate()?;
        if self.entries.is_empty() {
            return Err(CompensationError::Empty { what: "user table" });
        }
        let d2: Vec<f64> = self
            .entries
            .iter()
            .map(|e| distance_sq(params, &e.params))
            .collect();
        if let Some(i) = d2.iter().position(|&d| d == 0.0) {
            return Ok(self.entries[i].weights_db.clone());
        }
        // Normalising by the nearest distance keeps the weights within range however close
        // or far the query lies.
        let nearest = d2.iter().copied().fold(f64::INFINITY, f64::min);
        let w: Vec<f64> = d2.iter().map(|&d| nearest / d).collect();
        let total: f64 = w.iter().sum();
        let mut out = vec![0.0; self.freqs.len()];
        for (e, wi) in self.entries.iter().zip(&w) {
            let k = wi / total;
            for (o, v) in out.iter_mut().zip(&e.weights_db) {
                *o += k * v;
            }
        }
        Ok(out)
    }
}

/// Checks a frequency grid as [`UserTable::new`] does.
fn check_grid(freqs: &[Hz]) -> Result<(), CompensationError> {
    if freqs.is_empty() {
        return Err(CompensationError::Empty {
            what: "frequency grid",
        });
    }
    // 0 Hz is allowed: an equalizer's bins start at DC.
    if let Some(f) = freqs.iter().find(|f| !(f.0.is_finite() && f.0 >= 0.0)) {
        return Err(CompensationError::InvalidParameter {
            name: "freqs",
            value: f.0,
            expected: "finite, >= 0 Hz",
        });
    }
    if let Some(w) = freqs.windows(2).find(|w| w[1].0 <= w[0].0) {
        return Err(CompensationError::InvalidParameter {
            name: "freqs",
            value: w[1].0,
            expected: "strictly ascending",
        });
    }
    Ok(())
}

impl Document for UserTable {
    const KIND: &'static str = "user-table";
    const VERSION: u32 = 1;
    const LEGACY_KIND: Option<&'static str> = Some("user-table");
    const DESCRIPTION: &'static str = "user table";
    type Invalid = CompensationError;

    /// The grid as [`UserTable::new`] checks it, each entry as [`UserTable::add`] does, and
    /// each user's name once.
    fn validate(&self) -> Result<(), CompensationError> {
        check_grid(&self.freqs)?;
        for (i, entry) in self.entries.iter().enumerate() {
            if self.entries[..i].iter().any(|e| e.name == entry.name) {
                return Err(CompensationError::InvalidParameter {
                    name: "entries.name",
                    value: f64::NAN,
                    expected: "each user's name once",
                });
            }
            self.check(entry)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::document::{load, save};
    use crate::units::Band;
    use proptest::prelude::*;

    fn grid() -> Vec<Hz> {
        Band::new(40.0, 1024.0).log_grid(16)
    }

    fn entry(name: &str, params: LimbParams, level: f64) -> UserEntry {
        UserEntry {
            name: name.into(),
            params,
            weights_db: (0..16).map(|i| level + f64::from(i) * 0.5).collect(),
        }
    }

    fn two_users() -> UserTable {
        let mut t = UserTable::new(grid()).unwrap();
        t.add(entry("a", LimbParams::TABLE1_MEAN, 0.0)).unwrap();
        t.add(entry(
            "b",
            LimbParams {
                b3_k3: 0.006,
                k2_m2: 2e6,
                b2_m2: 900.0,
            },
            -6.0,
        ))
        .unwrap();
        t
    }

    #[test]
    fn exact_match_returns_the_users_curve() {
        let t = two_users();
        assert_eq!(
            t.interpolate(&LimbParams::TABLE1_MEAN).unwrap(),
            t.entries[0].weights_db
        );
        assert_eq!(
            t.interpolate(&t.entries[1].params).unwrap(),
            t.entries[1].weights_db
        );
        // Halfway in the normalised space: equal weights.
        let a = t.entries[0].params.to_array();
        let b = t.entries[1].params.to_array();
        let mid = LimbParams::from_array([0, 1, 2].map(|i| (a[i] * b[i]).sqrt()));
        let w = t.interpolate(&mid).unwrap();
        assert!((w[0] + 3.0).abs() < 1e-9, "{}", w[0]);
    }

    #[test]
    fn add_replaces_and_checks() {
        let mut t = two_users();
        let old = t.add(entry("a", LimbParams::TABLE1_MEAN, 3.0)).unwrap();
        assert_eq!(old.unwrap().weights_db[0], 0.0);
        assert_eq!(t.entries.len(), 2);
        assert_eq!(t.get("a").unwrap().weights_db[0], 3.0);
        let mut short = entry("c", LimbParams::TABLE1_MEAN, 0.0);
        short.weights_db.pop();
        assert!(matches!(
            t.add(short),
            Err(CompensationError::Mismatch { .. })
        ));
        let mut nan = entry("c", LimbParams::TABLE1_MEAN, 0.0);
        nan.weights_db[2] = f64::NAN;
        assert!(matches!(
            t.add(nan),
            Err(CompensationError::NonFinite { index: 2, .. })
        ));
        let bad = entry(
            "c",
            LimbParams {
                k2_m2: -1.0,
                ..LimbParams::TABLE1_MEAN
            },
            0.0,
        );
        assert!(t.add(bad).is_err());
        assert!(UserTable::new(vec![]).is_err());
        assert!(UserTable::new(vec![Hz(100.0), Hz(50.0)]).is_err());
    }

    #[test]
    fn empty_table_is_an_error() {
        let t = UserTable::new(grid()).unwrap();
        assert_eq!(
            t.interpolate(&LimbParams::TABLE1_MEAN),
            Err(CompensationError::Empty { what: "user table" })
        );
    }

    #[test]
    fn file_round_trip_and_errors() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("users.json");
        let t = two_users();
        save(&path, &t).unwrap();
        let back: UserTable = load(&path).unwrap();
        assert_eq!(back, t);

        let write = |text: &str| {
            std::fs::write(&path, text).unwrap();
            load::<UserTable>(&path)
        };
        let good = std::fs::read_to_string(&path).unwrap();
        let fails_with = |text: &str, needle: &str| {
            let err = write(text).unwrap_err().to_string();
            assert!(err.contains(needle), "{needle:?} not in {err:?}");
        };
        fails_with(&good.replace("user-table/1", "user-table/2"), "version 2");
        // An old header without its version.
        fails_with(
            &good.replace(
                "\"format\": \"underfoot.user-table/1\"",
                "\"kind\": \"user-table\"",
            ),
            "version missing",
        );
        fails_with("{ not json", "not a valid user table file");
        // A curve one entry short.
        let v: serde_json::Value = serde_json::from_str(&good).unwrap();
        let mut v2 = v.clone();
        v2["entries"][0]["weights_db"].as_array_mut().unwrap().pop();
        fails_with(&v2.to_string(), "15 entries, 16 expected");
        // Non-finite values cannot be written as JSON numbers; null is refused.
        let mut v3 = v.clone();
        v3["entries"][1]["weights_db"][4] = serde_json::Value::Null;
        fails_with(&v3.to_string(), "not a valid user table file");
        let mut v4 = v.clone();
        v4["entries"][1]["name"] = "a".into();
        fails_with(&v4.to_string(), "name once");
        assert!(load::<UserTable>(&dir.path().join("missing.json")).is_err());
        // An invalid table is not saved, and the file on disk is left alone.
        save(&path, &t).unwrap();
        let mut broken = t.clone();
        broken.entries[0].weights_db[0] = f64::INFINITY;
        assert!(save(&path, &broken).is_err());
        assert_eq!(load::<UserTable>(&path).unwrap(), t);
        // A table as the first version wrote it, with `"kind"` and `"version"`.
        let old = good.replace(
            "\"format\": \"underfoot.user-table/1\"",
            "\"kind\": \"user-table\",\n  \"version\": 1",
        );
        assert_eq!(write(&old).unwrap(), t);
    }

    fn params() -> impl Strategy<Value = LimbParams> {
        (2e-4f64..0.02, 1e5f64..5e7, 50f64..2e4).prop_map(|(a, b, c)| LimbParams {
            b3_k3: a,
            k2_m2: b,
            b2_m2: c,
        })
    }

    proptest! {
        #[test]
        fn interpolation_lies_between_the_users(
            pa in params(),
            pb in params(),
            q in params(),
            ca in prop::collection::vec(-30.0f64..30.0, 16),
            cb in prop::collection::vec(-30.0f64..30.0, 16),
        ) {
            let mut t = UserTable::new(grid()).unwrap();
            t.add(UserEntry { name: "a".into(), params: pa, weights_db: ca.clone() }).unwrap();
            t.add(UserEntry { name: "b".into(), params: pb, weights_db: cb.clone() }).unwrap();
            let w = t.interpolate(&q).unwrap();
            for ((v, a), b) in w.iter().zip(&ca).zip(&cb) {
                let tol = 1e-9 * (1.0 + a.abs().max(b.abs()));
                prop_assert!(*v >= a.min(*b) - tol && *v <= a.max(*b) + tol, "{v} not in [{a}, {b}]");
            }
        }
    }
}
