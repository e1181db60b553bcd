//! The real FFT plans of `underfoot`, compiled once.
//!
//! rustfft (under realfft) picks an algorithm for each length at plan time among hundreds
//! of kernels (scalar, SSE and AVX butterflies, one per prime size up to 31, mixed-radix and
//! Bluestein), and all of them are generic over the float type. A crate that names
//! `realfft::RealFftPlanner<f64>` therefore compiles every kernel, and the `underfoot`
//! library is compiled twice by `cargo test` (as itself and as its unit-test harness):
//! measured with `cargo llvm-lines`, those kernels were 48 % of the library's LLVM IR, for
//! `f64` and again for `f32`. Here they are instantiated once, behind functions that are not
//! generic; the library receives each plan as a trait object and calls it through its
//! vtable, so neither it nor its tests compile a butterfly.
//!
//! The API is realfft's, trimmed to what the library uses: a [`RealFftPlanner`] for `f64`
//! (the offline pipeline: spectra, fits, deconvolution) or `f32` (the real-time FIR
//! convolver), whose plans are realfft's own [`RealToComplex`] and [`ComplexToReal`].
//!
//! ```
//! use underfoot_fft::RealFftPlanner;
//!
//! let mut planner = RealFftPlanner::<f64>::new();
//! let fft = planner.plan_fft_forward(8);
//! let mut input = vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
//! let mut spectrum = fft.make_output_vec();
//! fft.process(&mut input, &mut spectrum).unwrap();
//! // A unit impulse has a flat spectrum.
//! assert!(spectrum.iter().all(|bin| (bin.re - 1.0).abs() < 1e-12 && bin.im.abs() < 1e-12));
//! ```

use std::sync::Arc;

pub use realfft::{ComplexToReal, FftNum, RealToComplex};

/// Plans real FFTs of any length, and keeps them: a second plan of the same length and
/// direction is the first one again (realfft's planner, which this wraps).
///
/// Implemented for `f64` and `f32` only, each by functions compiled here.
pub struct RealFftPlanner<T: FftNum> {
    inner: realfft::RealFftPlanner<T>,
}

/// The planner's methods for one float type. `#[inline(never)]` because an inlined body
/// would instantiate realfft's planner, and every kernel behind it, in the caller's crate,
/// which is what this crate exists to prevent.
macro_rules! planner_for {
    ($float:ty) => {
        impl RealFftPlanner<$float> {
            /// A planner with no plans yet.
            #[inline(never)]
            pub fn new() -> Self {
                Self {
                    inner: realfft::RealFftPlanner::new(),
                }
            }

            /// The plan of a forward transform of `len` real samples into `len / 2 + 1`
            /// complex bins (unnormalised).
            #[inline(never)]
            pub fn plan_fft_forward(&mut self, len: usize) -> Arc<dyn RealToComplex<$float>> {
                self.inner.plan_fft_forward(len)
            }

            /// The plan of an inverse transform of `len / 2 + 1` complex bins into `len`
            /// real samples (unnormalised: a forward then inverse transform scales by `len`).
            #[inline(never)]
            pub fn plan_fft_inverse(&mut self, len: usize) -> Arc<dyn ComplexToReal<$float>> {
                self.inner.plan_fft_inverse(len)
            }
        }

        impl Default for RealFftPlanner<$float> {
            fn default() -> Self {
                Self::new()
            }
        }
    };
}

planner_for!(f64);
planner_for!(f32);
