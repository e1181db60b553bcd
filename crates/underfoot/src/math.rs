//! The few math functions the `no_std` core needs, in one place.
//!
//! With `std` they are std's own methods, so everything rendered with std is bit for bit
//! what it was before the crate could build without it; without `std` they are `libm`'s
//! (within an ulp or so: a firmware build may differ from a host build in the last bits,
//! never in behaviour).

macro_rules! unary {
    ($($(#[$doc:meta])* $name:ident => $libm:ident;)+) => {$(
        $(#[$doc])*
        #[inline]
        #[must_use]
        pub fn $name(x: f64) -> f64 {
            #[cfg(feature = "std")]
            return x.$name();
            #[cfg(not(feature = "std"))]
            return libm::$libm(x);
        }
    )+};
}

unary! {
    /// `e^x`.
    exp => exp;
    /// Natural logarithm.
    ln => log;
    /// Base-10 logarithm.
    log10 => log10;
    /// Square root.
    sqrt => sqrt;
    /// Cosine.
    cos => cos;
    /// Sine.
    sin => sin;
    /// Nearest integer, halves away from zero.
    round => round;
    /// Largest integer not above.
    floor => floor;
    /// Integer part, towards zero.
    trunc => trunc;
    /// Absolute value.
    abs => fabs;
}

/// `x^y`.
#[inline]
#[must_use]
pub fn powf(x: f64, y: f64) -> f64 {
    #[cfg(feature = "std")]
    return x.powf(y);
    #[cfg(not(feature = "std"))]
    return libm::pow(x, y);
}

/// The angle of `(x, y)`, in `(-pi, pi]`.
#[inline]
#[must_use]
pub fn atan2(y: f64, x: f64) -> f64 {
    #[cfg(feature = "std")]
    return y.atan2(x);
    #[cfg(not(feature = "std"))]
    return libm::atan2(y, x);
}
