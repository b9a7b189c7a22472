//! The arithmetic type of the geometry kernels: f64 (reference) or f32 (mixed precision).

use nalgebra::RealField;

/// Floating-point type the contact-geometry kernels are written over.
///
/// Tolerances in the kernels are multiples of [`Real::EPSILON`] times a length scale of the
/// problem at hand, so that one code path serves both precisions.
pub trait Real: RealField + Copy + Default + std::fmt::Debug + 'static {
    /// Machine epsilon of the type.
    const EPSILON: Self;
    /// Converts from f64 (rounding to nearest for f32).
    fn of(x: f64) -> Self;
    /// Converts to f64 (exact).
    fn f64(self) -> f64;
}

impl Real for f64 {
    const EPSILON: f64 = f64::EPSILON;
    #[inline(always)]
    fn of(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

impl Real for f32 {
    const EPSILON: f32 = f32::EPSILON;
    #[inline(always)]
    fn of(x: f64) -> f32 {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}
