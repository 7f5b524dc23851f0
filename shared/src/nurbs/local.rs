//! The moving-data evaluator ([`FastCurve`]) on a curve moved to its own origin.
//!
//! A span's power form holds the curve's coordinates in its coefficients: far from the
//! origin, a narrow span's second derivative comes out of sums of terms as large as the
//! coordinates over the span's width squared, and loses their rounding (a 1/64 span at
//! 98 mm from the origin, with a curvature of 0.08: 2e-9 off, 3e-8 of it). A rational
//! curve moved by `o` is the same curve moved (`Σ N w (P − o) / Σ N w = C − o`), with the
//! same derivatives: evaluated about its first control point, the sums are as large as
//! the curve's extent, not its distance from the origin, and the point is moved back
//! afterwards (one rounding of its coordinates).
//!
//! For the planner's samples and lengths, which evaluate each block a thousand times and
//! more; the interpolator's cycle keeps [`FastCurve`] itself.

use super::fast::FastCurve;
use super::{CurveError, CurvePoint, MAX_CTRL};

/// A curve's evaluator about its first control point.
#[derive(Debug, Clone)]
pub struct LocalCurve {
    curve: FastCurve,
    origin: [f64; 3],
}

impl LocalCurve {
    /// Checks the curve as [`FastCurve::new`] does (clamped, weights > 0, at most
    /// [`MAX_CTRL`] control points `[x, y, z, w]`).
    pub fn new(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> Result<Self, CurveError> {
        if ctrl.len() > MAX_CTRL {
            return Err(CurveError::TooManyControlPoints {
                n_ctrl: ctrl.len() as u32,
                max: MAX_CTRL as u32,
            });
        }
        let origin = ctrl.first().map_or([0.0; 3], |c| [c[0], c[1], c[2]]);
        let mut moved = [[0.0; 4]; MAX_CTRL];
        for (m, c) in moved.iter_mut().zip(ctrl) {
            *m = [c[0] - origin[0], c[1] - origin[1], c[2] - origin[2], c[3]];
        }
        Ok(LocalCurve {
            curve: FastCurve::new(degree, knots, &moved[..ctrl.len()])?,
            origin,
        })
    }

    /// Point, first and second derivative at `u` (clamped into the domain).
    #[inline(always)]
    pub fn eval(&mut self, u: f64) -> CurvePoint {
        let mut e = self.curve.eval(u);
        for (p, o) in e.p.iter_mut().zip(self.origin) {
            *p += o;
        }
        e
    }

    /// [`Self::eval`] with the third derivative ([`FastCurve::eval_d3`]).
    pub fn eval_d3(&mut self, u: f64) -> (CurvePoint, [f64; 3]) {
        let (mut e, d3) = self.curve.eval_d3(u);
        for (p, o) in e.p.iter_mut().zip(self.origin) {
            *p += o;
        }
        (e, d3)
    }
}
