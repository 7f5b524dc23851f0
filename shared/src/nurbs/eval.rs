//! Point and first two derivatives of a rational curve, by span search and the triangular
//! basis-function table (The NURBS Book, A2.1/A2.3) followed by the rational quotient rule.
//! No allocation: all scratch lives in fixed arrays sized by `MAX_DEGREE`.

// Index loops mirror the textbook formulas (The NURBS Book), which is how they are checked.
#![allow(clippy::needless_range_loop)]

use super::MAX_DEGREE;

const ORDER_MAX: usize = MAX_DEGREE + 1;

/// A point on a curve with its first and second derivative with respect to the parameter.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct CurvePoint {
    pub p: [f64; 3],
    pub d1: [f64; 3],
    pub d2: [f64; 3],
    /// Index of the knot span `[knots[span], knots[span+1])` that holds the parameter.
    pub span: usize,
}

/// Index `i` with `knots[i] <= u < knots[i+1]`, clamped to the last non-empty span at the
/// end of the domain. `n_ctrl` control points, so valid spans are `degree..n_ctrl`.
pub fn find_span(degree: usize, knots: &[f64], n_ctrl: usize, u: f64) -> usize {
    let last = n_ctrl - 1;
    if u >= knots[last + 1] {
        // At (or past) the end: the last span with positive length.
        let mut i = last;
        while i > degree && knots[i] >= knots[last + 1] {
            i -= 1;
        }
        return i;
    }
    if u <= knots[degree] {
        let mut i = degree;
        while i < last && knots[i + 1] <= knots[degree] {
            i += 1;
        }
        return i;
    }
    let (mut lo, mut hi) = (degree, last + 1);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if u < knots[mid] {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    lo
}

/// Basis functions of `span` at `u` and their first and second derivatives:
/// `ders[k][j]` is the k-th derivative of N_{span-degree+j, degree}.
pub(crate) fn basis_ders(
    degree: usize,
    knots: &[f64],
    span: usize,
    u: f64,
) -> [[f64; ORDER_MAX]; 3] {
    match degree {
        1 => basis_ders_of::<1, 2, false, 2>(degree, knots, span, u),
        2 => basis_ders_of::<2, 2, false, 3>(degree, knots, span, u),
        3 => basis_ders_of::<3, 2, false, 4>(degree, knots, span, u),
        4 => basis_ders_of::<4, 2, false, 5>(degree, knots, span, u),
        5 => basis_ders_of::<5, 2, false, 6>(degree, knots, span, u),
        _ => basis_ders_of::<0, 2, false, ORDER_MAX>(degree, knots, span, u),
    }
}

/// [`basis_ders`] for the degree `P` (or, for `P = 0`, the degree given), up to the
/// `D`-th derivative (1 or 2; the rows above stay zero). One body for all: a fixed
/// degree only lets the compiler unroll the loops and drop the bounds checks, and each
/// derivative's row is worked out before the next is begun; the arithmetic, and so
/// every bit of the rows given, is the same. `O` is the table's size, `P + 1` (or the
/// largest, for `P = 0`): a table no larger than the degree needs is kept in registers
/// instead of being zeroed in memory at every call.
///
/// `SPAN`: the knots below `span` are all `knots[span]` and those above all
/// `knots[span + 1]`, as in a Bézier span's. Then every knot difference the table
/// divides by is the same number, and the compiler, seeing that, divides once where the
/// general form divides again and again by that number: the same divisions of the same
/// numbers, so again the same bits.
#[inline(always)]
fn basis_ders_of<const P: usize, const D: usize, const SPAN: bool, const O: usize>(
    degree: usize,
    knots: &[f64],
    span: usize,
    u: f64,
) -> [[f64; ORDER_MAX]; 3] {
    let p = if P == 0 { degree } else { P };
    let mut ndu = [[0.0f64; O]; O];
    let mut left = [0.0f64; O];
    let mut right = [0.0f64; O];
    ndu[0][0] = 1.0;
    let (left_1, right_1) = (u - knots[span], knots[span + 1] - u);
    for j in 1..=p {
        if SPAN {
            (left[j], right[j]) = (left_1, right_1);
        } else {
            left[j] = u - knots[span + 1 - j];
            right[j] = knots[span + j] - u;
        }
        let mut saved = 0.0;
        for r in 0..j {
            // lower triangle: knot differences; upper: basis functions
            ndu[j][r] = right[r + 1] + left[j - r];
            let temp = ndu[r][j - 1] / ndu[j][r];
            ndu[r][j] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        ndu[j][j] = saved;
    }
    let mut ders = [[0.0f64; ORDER_MAX]; 3];
    for j in 0..=p {
        ders[0][j] = ndu[j][p];
    }
    let n = p.min(D);
    let mut a = [[0.0f64; O]; 2];
    for r in 0..=p {
        let (mut s1, mut s2) = (0usize, 1usize);
        a[0] = [0.0; O];
        a[1] = [0.0; O];
        a[0][0] = 1.0;
        for k in 1..=n {
            let mut d = 0.0;
            let rk = r as isize - k as isize;
            let pk = p - k;
            if r >= k {
                a[s2][0] = a[s1][0] / ndu[pk + 1][rk as usize];
                d = a[s2][0] * ndu[rk as usize][pk];
            }
            let j1 = if rk >= -1 { 1 } else { (-rk) as usize };
            let j2 = if r as isize - 1 <= pk as isize {
                k - 1
            } else {
                p - r
            };
            for j in j1..=j2 {
                let idx = (rk + j as isize) as usize;
                a[s2][j] = (a[s1][j] - a[s1][j - 1]) / ndu[pk + 1][idx];
                d += a[s2][j] * ndu[idx][pk];
            }
            if r as isize <= pk as isize {
                a[s2][k] = -a[s1][k - 1] / ndu[pk + 1][r];
                d += a[s2][k] * ndu[r][pk];
            }
            ders[k][r] = d;
            core::mem::swap(&mut s1, &mut s2);
        }
    }
    let mut factor = p as f64;
    for k in 1..=n {
        for j in 0..=p {
            ders[k][j] *= factor;
        }
        factor *= (p - k) as f64;
    }
    ders
}

/// Evaluates a validated clamped NURBS at `u` (clamped into its domain).
pub fn eval(degree: usize, knots: &[f64], ctrl: &[[f64; 4]], u: f64) -> CurvePoint {
    // The low degrees of nearly every curve get their own copy of the same arithmetic
    // (see `basis_ders_of`): unrolled, it runs about twice as fast, to the same bits.
    match degree {
        1 => eval_of::<1, 2, 2>(degree, knots, ctrl, u),
        2 => eval_of::<2, 2, 3>(degree, knots, ctrl, u),
        3 => eval_of::<3, 2, 4>(degree, knots, ctrl, u),
        4 => eval_of::<4, 2, 5>(degree, knots, ctrl, u),
        5 => eval_of::<5, 2, 6>(degree, knots, ctrl, u),
        _ => eval_of::<0, 2, ORDER_MAX>(degree, knots, ctrl, u),
    }
}

/// [`eval`] without the second derivative (`d2` is zero): the point and the first
/// derivative, the same bits as [`eval`]'s, for a third less work (lengths, speeds).
pub fn eval_d1(degree: usize, knots: &[f64], ctrl: &[[f64; 4]], u: f64) -> CurvePoint {
    match degree {
        1 => eval_of::<1, 1, 2>(degree, knots, ctrl, u),
        2 => eval_of::<2, 1, 3>(degree, knots, ctrl, u),
        3 => eval_of::<3, 1, 4>(degree, knots, ctrl, u),
        4 => eval_of::<4, 1, 5>(degree, knots, ctrl, u),
        5 => eval_of::<5, 1, 6>(degree, knots, ctrl, u),
        _ => eval_of::<0, 1, ORDER_MAX>(degree, knots, ctrl, u),
    }
}

/// [`eval`] for the degree `P` (or, for `P = 0`, the degree given), up to the `D`-th
/// derivative (1 or 2; `d2` is zero for 1).
#[inline(always)]
pub(super) fn eval_of<const P: usize, const D: usize, const O: usize>(
    degree: usize,
    knots: &[f64],
    ctrl: &[[f64; 4]],
    u: f64,
) -> CurvePoint {
    let degree = if P == 0 { degree } else { P };
    let n = ctrl.len();
    // One Bézier span (clamped knots: the first `degree + 1` all equal, the others too).
    if n == degree + 1 && knots[0] == knots[degree] && knots[degree + 1] == knots[n + degree] {
        eval_with::<P, D, true, O>(degree, knots, ctrl, u)
    } else {
        eval_with::<P, D, false, O>(degree, knots, ctrl, u)
    }
}

/// [`eval_of`], `SPAN` as in [`basis_ders_of`].
#[inline(always)]
pub(super) fn eval_with<const P: usize, const D: usize, const SPAN: bool, const O: usize>(
    degree: usize,
    knots: &[f64],
    ctrl: &[[f64; 4]],
    u: f64,
) -> CurvePoint {
    let degree = if P == 0 { degree } else { P };
    let n = ctrl.len();
    let u = u.clamp(knots[degree], knots[n]);
    let span = find_span(degree, knots, n, u);
    let ders = basis_ders_of::<P, D, SPAN, O>(degree, knots, span, u);
    // Homogeneous numerator A (and its derivatives) and denominator w share one pass.
    let mut a = [[0.0f64; 3]; 3];
    let mut w = [0.0f64; 3];
    for j in 0..=degree {
        let c = ctrl[span - degree + j];
        for k in 0..=D {
            let nw = ders[k][j] * c[3];
            w[k] += nw;
            for (ax, ak) in a[k].iter_mut().enumerate() {
                *ak += nw * c[ax];
            }
        }
    }
    let mut out = CurvePoint {
        span,
        ..CurvePoint::default()
    };
    for ax in 0..3 {
        let p = a[0][ax] / w[0];
        let d1 = (a[1][ax] - w[1] * p) / w[0];
        out.p[ax] = p;
        out.d1[ax] = d1;
        if D >= 2 {
            out.d2[ax] = (a[2][ax] - 2.0 * w[1] * d1 - w[2] * p) / w[0];
        }
    }
    out
}
