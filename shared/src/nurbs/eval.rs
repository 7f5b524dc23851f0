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
    let p = degree;
    let mut ndu = [[0.0f64; ORDER_MAX]; ORDER_MAX];
    let mut left = [0.0f64; ORDER_MAX];
    let mut right = [0.0f64; ORDER_MAX];
    ndu[0][0] = 1.0;
    for j in 1..=p {
        left[j] = u - knots[span + 1 - j];
        right[j] = knots[span + j] - u;
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
    let n = p.min(2);
    let mut a = [[0.0f64; ORDER_MAX]; 2];
    for r in 0..=p {
        let (mut s1, mut s2) = (0usize, 1usize);
        a[0] = [0.0; ORDER_MAX];
        a[1] = [0.0; ORDER_MAX];
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
    let n = ctrl.len();
    let u = u.clamp(knots[degree], knots[n]);
    let span = find_span(degree, knots, n, u);
    let ders = basis_ders(degree, knots, span, u);
    // Homogeneous numerator A (and its derivatives) and denominator w share one pass.
    let mut a = [[0.0f64; 3]; 3];
    let mut w = [0.0f64; 3];
    for j in 0..=degree {
        let c = ctrl[span - degree + j];
        for k in 0..3 {
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
        let d2 = (a[2][ax] - 2.0 * w[1] * d1 - w[2] * p) / w[0];
        out.p[ax] = p;
        out.d1[ax] = d1;
        out.d2[ax] = d2;
    }
    out
}
