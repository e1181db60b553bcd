//! A person standing on the simulated tile: a limb of the compensation's model
//! ([`LimbModel`]) between the drive and the tile.

use num_complex::Complex64;

use super::tile::{SimulatedTile, TileConfig};
use crate::compensation::CompensationError;
use crate::compensation::limb::LimbModel;
use crate::compensation::sweep::Device;
use crate::signal::Sos;
use crate::units::{Hz, SampleRate};

/// A user standing on a [`SimulatedTile`]: the limb's `H_u` (bilinear, prewarped at the
/// skin's resonance) ahead of the tile, whose sensor noise is then added at the output.
///
/// The limb is placed before the tile so the noise stays where a sensor puts it, after
/// everything; for the noiseless part the order does not matter (both are linear).
#[derive(Debug, Clone)]
pub struct SimulatedUser {
    tile: SimulatedTile,
    limb: LimbModel,
    limb_sos: Sos,
    rate: SampleRate,
}

impl SimulatedUser {
    /// A user with `limb` on a tile configured by `tile`, at `rate`.
    ///
    /// # Errors
    /// As [`SimulatedTile::new`] and [`LimbModel::sos`].
    pub fn new(
        tile: &TileConfig,
        limb: LimbModel,
        rate: SampleRate,
    ) -> Result<Self, CompensationError> {
        let tile = SimulatedTile::new(tile, rate)?;
        let limb_sos = Self::limb_sections(&limb, rate)?;
        Ok(Self {
            tile,
            limb,
            limb_sos,
            rate,
        })
    }

    /// `limb`'s `H_u` as the simulation runs it at `rate`: bilinear, prewarped at the
    /// skin's resonance (at most 0.4 fs). Also a leg on its own, between an actuator and
    /// a sensor on the skin.
    ///
    /// # Errors
    /// As [`LimbModel::validate`] and [`LimbModel::sos`].
    pub fn limb_sections(limb: &LimbModel, rate: SampleRate) -> Result<Sos, CompensationError> {
        limb.validate()?;
        let prewarp = Hz(limb.params.skin_resonance().0.min(0.4 * rate.hz()));
        limb.sos(rate, prewarp)
    }

    /// The limb.
    #[must_use]
    pub fn limb(&self) -> &LimbModel {
        &self.limb
    }

    /// The limb's sections as simulated.
    #[must_use]
    pub fn limb_sos(&self) -> &Sos {
        &self.limb_sos
    }

    /// The noiseless response (tile times the discretised limb) at `f`.
    #[must_use]
    pub fn true_response(&self, f: Hz) -> Complex64 {
        self.tile.true_response(f) * self.limb_sos.response(self.rate.omega(f))
    }
}

impl Device for SimulatedUser {
    /// Plays from rest.
    fn play(&mut self, excitation: &[f64]) -> Result<Vec<f64>, CompensationError> {
        let mut x = excitation.to_vec();
        self.limb_sos.filter_in_place(&mut x);
        self.tile.play(&x)
    }
}
