//! The limb model as a digital filter, and its inverse `Z_c` as the compensation filter.
//!
//! [`LimbModel::compensation`] realises `Z_c = 1/H_u`. Its poles are the zeros of `H_u`,
//! the roots of the cubic numerator, which is Hurwitz (so `Z_c` is stable) exactly when
//! (Routh) all coefficients are positive and
//!
//! ```math
//! (1 + g_2)\, (b_2/m_2) > g_2\, \tau\, (k_2/m_2);
//! ```
//!
//! that fails for some corners of the parameter box (a stiff, lightly damped skin under a
//! slow leg), and is then an error. The cubic is factored (companion matrix) into a real
//! root and a quadratic, so that `Z_c` is the product of a first-order section
//! `(1 + τ s) / (g2 τ (s − r))` and a second-order one `(s² + B s + K) / (s² + q1 s + q0)`,
//! each mapped by the bilinear transform `s = c (1 − z⁻¹)/(1 + z⁻¹)` with
//! `c = 2π f_w / tan(π f_w / f_s)`, prewarped at the band's geometric centre `f_w` (the
//! warping error is then under 0.2 % in frequency over 40-1024 Hz at 48 kHz). Sections are
//! never multiplied out into one polynomial.
//!
//! `|Z_c|` rises at about +20 dB/decade from the leg's corner up to the real root
//! `≈ (1 + g2)/(g2 τ)` rad/s (8.6 kHz for Table 1's mean) and levels off at `1/g2`
//! (+46 dB): boosting that much outside the band would only amplify noise and drive the
//! actuator where it does nothing useful. A second-order Butterworth low-pass at twice the
//! band's top edge is cascaded: it turns the slope above the band to −20 dB/decade and
//! costs only `10 log10(1 + 2⁻⁴) = 0.26 dB` at the band's top edge (at 1.5 times the edge
//! it would cost 0.78 dB there, more than the 0.5 dB the compensation may deviate). The
//! cutoff is capped at 0.45 f_s. Finally the gain is set so the mean dB gain over the band
//! (256 points on a log grid) is 0 dB: the compensation reshapes, it does not amplify.

use num_complex::Complex64;

use super::LimbModel;
use crate::compensation::CompensationError;
use crate::numeric::roots;
use crate::signal::{Biquad, Sos, butterworth};
use crate::units::{Band, Hz, SampleRate};

impl LimbModel {
    /// Whether `H_u`'s numerator is Hurwitz (Routh), i.e. whether `Z_c = 1/H_u` is stable.
    #[must_use]
    pub fn is_invertible(&self) -> bool {
        let [a3, a2, a1, a0] = self.numerator();
        a3 > 0.0 && a2 > 0.0 && a1 > 0.0 && a0 > 0.0 && a2 * a1 > a3 * a0
    }

    /// The analog sections `(numerator, denominator)` of `H_u / level`, coefficients of
    /// `[s², s, 1]`: a first-order section with the numerator's real root, then the
    /// second-order one with the skin's denominator.
    fn analog_sections(&self) -> Result<[AnalogSection; 2], CompensationError> {
        self.validate()?;
        let num = self.numerator();
        let r = roots(&num).ok_or(CompensationError::Unstable {
            what: "the numerator of H_u could not be factored",
        })?;
        // With positive coefficients a real cubic has at least one (negative) real root.
        // Take the real root of largest modulus for the first-order section, so that a
        // conjugate pair (or the two smaller real roots) forms the quadratic.
        let is_real = |z: &Complex64| z.im.abs() <= 1e-9 * z.norm().max(1e-300);
        let (ri, _) = r
            .iter()
            .enumerate()
            .filter(|(_, z)| is_real(z))
            .max_by(|a, b| a.1.norm().total_cmp(&b.1.norm()))
            .ok_or(CompensationError::Unstable {
                what: "the numerator of H_u has no real root",
            })?;
        let real = r[ri].re;
        let rest: Vec<Complex64> = r
            .iter()
            .enumerate()
            .filter(|(i, _)| *i != ri)
            .map(|(_, z)| *z)
            .collect();
        let q1 = -(rest[0] + rest[1]).re;
        let q0 = (rest[0] * rest[1]).re;
        let p = &self.params;
        Ok([
            ([0.0, num[0], -num[0] * real], [0.0, p.b3_k3, 1.0]),
            ([1.0, q1, q0], [1.0, p.b2_m2, p.k2_m2]),
        ])
    }

    /// `level · H_u` discretised by the bilinear transform prewarped at `prewarp`, as
    /// second-order sections.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] for an invalid model or a prewarp frequency
    /// not strictly between 0 and Nyquist; [`CompensationError::Unstable`] when the
    /// numerator cannot be factored.
    pub fn sos(&self, rate: SampleRate, prewarp: Hz) -> Result<Sos, CompensationError> {
        let c = bilinear_constant(rate, prewarp)?;
        let mut sections = Vec::with_capacity(2);
        for (num, den) in self.analog_sections()? {
            sections.push(bilinear(num, den, c)?);
        }
        scale(&mut sections, self.level);
        Ok(Sos::new(sections))
    }

    /// The compensation filter: `Z_c = 1/H_u` band-limited and normalised (see the module
    /// docs), as second-order sections at `rate`.
    ///
    /// # Errors
    /// [`CompensationError::InvalidParameter`] for an invalid model or a band that does not
    /// fit below Nyquist; [`CompensationError::Unstable`] when `H_u`'s numerator is not
    /// Hurwitz (so `1/H_u` has a pole in the right half-plane).
    pub fn compensation(&self, rate: SampleRate, band: Band) -> Result<Sos, CompensationError> {
        self.validate()?;
        if !band.fits(rate) {
            return Err(CompensationError::invalid(
                "band.hi",
                band.hi.0,
                "0 < lo < hi < Nyquist, all finite",
            ));
        }
        if !self.is_invertible() {
            return Err(CompensationError::Unstable {
                what: "H_u has a zero in the right half-plane ((1 + g2) b2/m2 <= g2 b3/k3 k2/m2), so 1/H_u is unstable",
            });
        }
        let centre = Hz((band.lo.0 * band.hi.0).sqrt());
        let c = bilinear_constant(rate, centre)?;
        let mut sections = Vec::with_capacity(3);
        for (num, den) in self.analog_sections()? {
            sections.push(bilinear(den, num, c)?);
        }
        let cutoff = Hz((2.0 * band.hi.0).min(0.45 * rate.hz()));
        let lp = butterworth::lowpass(2, cutoff, rate)
            .map_err(|_| CompensationError::invalid("band.hi", band.hi.0, "2 hi below Nyquist"))?;
        sections.extend(lp.sections);
        let grid = band.log_grid(256);
        let sos = Sos::new(sections.clone());
        let mean_db = grid
            .iter()
            .map(|&f| 20.0 * sos.response(rate.omega(f)).norm().log10())
            .sum::<f64>()
            / grid.len() as f64;
        if !mean_db.is_finite() {
            return Err(CompensationError::Unstable {
                what: "the compensation filter's gain is not finite over the band",
            });
        }
        scale(&mut sections, 10f64.powf(-mean_db / 20.0));
        let sos = Sos::new(sections);
        if !sos.is_stable() {
            return Err(CompensationError::Unstable {
                what: "the discretised compensation filter",
            });
        }
        Ok(sos)
    }
}

/// An analog section `(numerator, denominator)`, coefficients of `[s², s, 1]`.
type AnalogSection = ([f64; 3], [f64; 3]);

/// Folds `k` into the first section's numerator.
fn scale(sections: &mut [Biquad], k: f64) {
    if let Some(s) = sections.first_mut() {
        for b in &mut s.b {
            *b *= k;
        }
    }
}

/// `c` of `s = c (1 − z⁻¹)/(1 + z⁻¹)`, chosen so that `f` maps to itself.
fn bilinear_constant(rate: SampleRate, f: Hz) -> Result<f64, CompensationError> {
    crate::numeric::prewarp_constant(rate, f)
        .ok_or_else(|| CompensationError::invalid("prewarp", f.0, "0 < f < Nyquist"))
}

/// The bilinear transform of `num(s)/den(s)` as a biquad (see [`crate::numeric::bilinear`]).
fn bilinear(num: [f64; 3], den: [f64; 3], c: f64) -> Result<Biquad, CompensationError> {
    Biquad::from_row(crate::numeric::bilinear(num, den, c)).ok_or(CompensationError::Unstable {
        what: "a bilinear section has a zero leading denominator coefficient",
    })
}
