//! One damped mode of a surface, and the longest decay any mode plays.

use super::PhysicalError;
use crate::units::{Hz, Seconds};

/// The longest e-fold decay a mode plays, the physical counterpart of the IIR voice's
/// [`VoiceConfig::longest_decay`](crate::synthesis::VoiceConfig::longest_decay) and the
/// estimation's `max_decay` (both 0.5 s): no ground rings for seconds, and an actuator on
/// skin must not. A library refuses a stored mode beyond it
/// ([`PhysicalModel::validate`](crate::physical::PhysicalModel::validate)); a bank built in code
/// plays any longer mode at this decay ([`SurfaceMode::played_decay`]).
pub const LONGEST_DECAY: Seconds = Seconds(0.5);

/// One damped mode of a surface at the point struck.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceMode {
    /// The (damped) frequency of the ringing.
    pub frequency: Hz,
    /// The time for the ringing's envelope to decay by a factor `e`.
    pub decay: Seconds,
    /// Displacement per unit impulse, in metres per newton-second: `1 / (2π f m)` for a
    /// mode of modal mass `m` at the point struck. Its magnitude is the driving-point gain
    /// the contact sees; its sign is the mode shape's at the point the vibration is felt
    /// relative to the point struck (see the module documentation).
    pub gain: f64,
}

impl SurfaceMode {
    /// The decay the mode is played with: its own, at most [`LONGEST_DECAY`].
    #[must_use]
    pub fn played_decay(&self) -> Seconds {
        Seconds(self.decay.0.min(LONGEST_DECAY.0))
    }

    /// Checks mode `index`: a frequency in `(0, below)`, a positive and finite decay time,
    /// a finite gain.
    ///
    /// # Errors
    /// [`PhysicalError::FrequencyOutOfRange`], [`PhysicalError::BadDecay`] or
    /// [`PhysicalError::BadGain`].
    pub fn check(&self, index: usize, below: Hz) -> Result<(), PhysicalError> {
        let f = self.frequency.0;
        if !(f.is_finite() && f > 0.0 && f < below.0) {
            return Err(PhysicalError::FrequencyOutOfRange {
                index,
                frequency: self.frequency,
                nyquist: below,
            });
        }
        if !(self.decay.0.is_finite() && self.decay.0 > 0.0) {
            return Err(PhysicalError::BadDecay {
                index,
                decay: self.decay,
            });
        }
        if !self.gain.is_finite() {
            return Err(PhysicalError::BadGain {
                index,
                gain: self.gain,
            });
        }
        Ok(())
    }
}
