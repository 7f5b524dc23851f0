//! NURBS curves: the fixed-capacity form that crosses between processes, and the
//! algorithms on plain slices that both the interpreter (which may hold curves larger than
//! one block) and the interpolator (which evaluates one block per cycle) use.
//!
//! Control points are stored as `[x, y, z, w]`: Cartesian coordinates in mm plus the
//! weight `w > 0` (not pre-multiplied). Knot vectors are clamped: the first and the last
//! knot each appear `degree + 1` times.

mod eval;
pub mod fast;
mod knots;
mod length;
pub mod local;
pub mod reference;
pub mod surface;

pub use eval::{eval, eval_d1, find_span, CurvePoint};
pub use knots::{insert_knot, split_at, split_to_capacity, SplitCurve};
pub use length::{arc_length, arc_length_adaptive};

/// The highest degree a block may carry (order 10: Fanuc's G06.2 rank limit we accept).
pub const MAX_DEGREE: usize = 9;
/// The most control points one command block carries; larger curves are split exactly.
pub const MAX_CTRL: usize = 36;
/// Knots for `MAX_CTRL` control points at `MAX_DEGREE`.
pub const MAX_KNOTS: usize = MAX_CTRL + MAX_DEGREE + 1;

/// What is wrong with a curve. Small and `Copy`, so it can be reported from anywhere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CurveError {
    DegreeOutOfRange { degree: u32 },
    TooFewControlPoints { n_ctrl: u32, degree: u32 },
    TooManyControlPoints { n_ctrl: u32, max: u32 },
    KnotCount { n_knots: u32, expected: u32 },
    KnotsDecrease { index: u32 },
    NotClamped,
    EmptyDomain,
    WeightNotPositive { index: u32 },
    NotFinite,
}

impl core::fmt::Display for CurveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            CurveError::DegreeOutOfRange { degree } => {
                write!(f, "degree {degree} is outside 1..={MAX_DEGREE}")
            }
            CurveError::TooFewControlPoints { n_ctrl, degree } => write!(
                f,
                "{n_ctrl} control points are too few for degree {degree} (at least {} needed)",
                degree + 1
            ),
            CurveError::TooManyControlPoints { n_ctrl, max } => {
                write!(f, "{n_ctrl} control points exceed the capacity of {max}")
            }
            CurveError::KnotCount { n_knots, expected } => {
                write!(
                    f,
                    "{n_knots} knots given, {expected} expected (control points + order)"
                )
            }
            CurveError::KnotsDecrease { index } => {
                write!(f, "knot {index} is smaller than knot {}", index - 1)
            }
            CurveError::NotClamped => write!(
                f,
                "knot vector is not clamped (end knots must repeat order times)"
            ),
            CurveError::EmptyDomain => write!(f, "knot vector spans an empty parameter range"),
            CurveError::WeightNotPositive { index } => {
                write!(f, "weight of control point {index} is not > 0")
            }
            CurveError::NotFinite => {
                write!(f, "a knot, coordinate or weight is not a finite number")
            }
        }
    }
}

/// Checks a clamped NURBS given as slices; `max_ctrl` is the capacity it must fit.
pub fn validate(
    degree: usize,
    knots: &[f64],
    ctrl: &[[f64; 4]],
    max_ctrl: usize,
) -> Result<(), CurveError> {
    validate_shape(degree, knots.len(), ctrl.len(), max_ctrl)?;
    if knots.iter().any(|k| !k.is_finite()) || ctrl.iter().flatten().any(|c| !c.is_finite()) {
        return Err(CurveError::NotFinite);
    }
    for i in 1..knots.len() {
        if knots[i] < knots[i - 1] {
            return Err(CurveError::KnotsDecrease { index: i as u32 });
        }
    }
    let (lo, hi) = (knots[0], knots[knots.len() - 1]);
    if knots[..=degree].iter().any(|&k| k != lo)
        || knots[knots.len() - degree - 1..].iter().any(|&k| k != hi)
    {
        return Err(CurveError::NotClamped);
    }
    if hi <= lo {
        return Err(CurveError::EmptyDomain);
    }
    if let Some(i) = ctrl.iter().position(|c| c[3] <= 0.0) {
        return Err(CurveError::WeightNotPositive { index: i as u32 });
    }
    Ok(())
}

/// The first checks of [`validate`], on the shape alone: the degree within
/// `1..=MAX_DEGREE`, enough control points for it and no more than `max_ctrl`, and as
/// many knots as control points plus order.
pub fn validate_shape(
    degree: usize,
    n_knots: usize,
    n: usize,
    max_ctrl: usize,
) -> Result<(), CurveError> {
    if degree == 0 || degree > MAX_DEGREE {
        return Err(CurveError::DegreeOutOfRange {
            degree: degree as u32,
        });
    }
    if n < degree + 1 {
        return Err(CurveError::TooFewControlPoints {
            n_ctrl: n as u32,
            degree: degree as u32,
        });
    }
    if n > max_ctrl {
        return Err(CurveError::TooManyControlPoints {
            n_ctrl: n as u32,
            max: max_ctrl as u32,
        });
    }
    if n_knots != n + degree + 1 {
        return Err(CurveError::KnotCount {
            n_knots: n_knots as u32,
            expected: (n + degree + 1) as u32,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests;
