//! The bank as second-order sections, for firmware and interchange.

use super::ResonatorBank;
use crate::physical::PhysicalError;
use crate::signal::{Biquad, Sos};

impl ResonatorBank {
    /// The bank as a cascade of second-order sections with the same impulse response.
    ///
    /// Mode `k` alone is the section `g_k r_k \sin θ_k z^{-1} / (1 - 2 r_k \cos θ_k z^{-1} + r_k^2 z^{-2})`
    /// (`p_k = r_k e^{iθ_k}`). The bank is their sum; this brings it
    /// over a common denominator and factors the numerator, giving a cascade with the same
    /// impulse response, for firmware and interchange. The poles are kept exactly as
    /// computed; only the zeros come from a root finder, whose accuracy falls as the number
    /// of modes grows (the numerator has degree `2K - 1`). For real-time use, the parallel
    /// form of the bank is both cheaper and exact.
    ///
    /// # Errors
    /// [`PhysicalError::Factorisation`] when the numerator cannot be factored: its leading
    /// coefficient `h[1]` is zero (gains that cancel), or the root finder fails.
    pub fn to_sos(&self) -> Result<Sos, PhysicalError> {
        let denominators: Vec<[f64; 3]> = self
            .pole
            .iter()
            .map(|p| [1.0, -2.0 * p.re, p.norm_sqr()])
            .collect();
        // H(w) = w N(w) / Π A_j(w) with N(w) = Σ_k g_k Im(p_k) Π_{j≠k} A_j(w), w = z^-1.
        let mut numerator = vec![0.0; 2 * self.pole.len() - 1];
        for (k, (p, g)) in self.pole.iter().zip(&self.gain).enumerate() {
            let mut term = vec![g * p.im];
            for (j, a) in denominators.iter().enumerate() {
                if j != k {
                    term = crate::signal::sos::poly_mul(&term, a);
                }
            }
            for (n, t) in numerator.iter_mut().zip(&term) {
                *n += t;
            }
        }
        let lead = numerator[0];
        if lead == 0.0 || !lead.is_finite() {
            return Err(PhysicalError::Factorisation(
                "the first sample of the impulse response is zero",
            ));
        }
        let zeros = crate::numeric::roots(&numerator).ok_or(PhysicalError::Factorisation(
            "the root finder did not converge",
        ))?;
        let mut sections = crate::signal::zpk::sections_from_roots(&zeros, &self.pole, lead);
        // The numerator has one degree fewer than the denominator: the z^-1 of h[0] = 0.
        // It goes into a section with a spare numerator degree.
        let spare = sections
            .iter_mut()
            .filter(|s| s.b[2] == 0.0)
            .min_by_key(|s| usize::from(s.b[1] != 0.0))
            .ok_or(PhysicalError::Factorisation(
                "no section can take the delay",
            ))?;
        *spare = Biquad {
            b: [0.0, spare.b[0], spare.b[1]],
            a: spare.a,
        };
        Ok(Sos::new(sections))
    }
}
