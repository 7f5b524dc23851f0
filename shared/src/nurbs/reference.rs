//! Reference evaluators written straight from the textbook formulas, kept to check the
//! fast evaluators ([`super::fast`], [`super::surface`]) and to measure them against.
//! None of this is meant for the cycle.
//!
//! * The *conventional* method, as the seeds compare against (seed 001 §2, eq. 2.1–2.9;
//!   seed 000 §2, eq. 1–12): every basis function `N_{i,p}` by the Cox–de Boor recursion
//!   from scratch on every call, its derivatives by the recursive derivative formula
//!   (eq. 2.9), the rational basis functions `R_i` and their derivatives by the quotient
//!   rule, and the sums over *all* control points, as eq. 2.1 and 2.5–2.6 write them.
//! * The *standard* algorithm for surfaces: span search and the triangular table of
//!   basis functions and derivatives (The NURBS Book, A2.1 and A2.3) per direction, the
//!   homogeneous tensor sum, then the rational derivative formula (A4.4). For curves the
//!   standard algorithm is [`super::eval`].
//!
//! Conventions shared with the fast evaluators: spans are half-open `[u_i, u_{i+1})` (so
//! at an interior knot the right-hand derivatives are returned), the last span is closed,
//! and a term whose knot difference is zero counts as zero (`0/0 := 0`).

// Index loops mirror the textbook formulas, which is how they are checked.
#![allow(clippy::needless_range_loop)]

use super::fast::ORD;
use super::surface::{unit_normal, SurfaceData, SurfacePoint};
use super::{find_span, CurvePoint};

/// `N_{i,p}(u)` by the Cox–de Boor recursion.
pub fn cox_de_boor(i: usize, p: usize, knots: &[f64], u: f64) -> f64 {
    if p == 0 {
        let last = knots[knots.len() - 1];
        let inside = knots[i] <= u && u < knots[i + 1];
        // The last non-empty span is closed so the domain end evaluates.
        let at_end = u == last && knots[i] < knots[i + 1] && knots[i + 1] == last;
        return if inside || at_end { 1.0 } else { 0.0 };
    }
    let mut v = 0.0;
    let d_left = knots[i + p] - knots[i];
    if d_left > 0.0 {
        v += (u - knots[i]) / d_left * cox_de_boor(i, p - 1, knots, u);
    }
    let d_right = knots[i + p + 1] - knots[i + 1];
    if d_right > 0.0 {
        v += (knots[i + p + 1] - u) / d_right * cox_de_boor(i + 1, p - 1, knots, u);
    }
    v
}

/// The `k`-th derivative of `N_{i,p}` by the recursive formula (seed 001 eq. 2.9).
pub fn cox_de_boor_der(i: usize, p: usize, k: usize, knots: &[f64], u: f64) -> f64 {
    if k == 0 {
        return cox_de_boor(i, p, knots, u);
    }
    if p == 0 {
        return 0.0;
    }
    let mut v = 0.0;
    let d_left = knots[i + p] - knots[i];
    if d_left > 0.0 {
        v += cox_de_boor_der(i, p - 1, k - 1, knots, u) / d_left;
    }
    let d_right = knots[i + p + 1] - knots[i + 1];
    if d_right > 0.0 {
        v -= cox_de_boor_der(i + 1, p - 1, k - 1, knots, u) / d_right;
    }
    p as f64 * v
}

fn clamp_domain(degree: usize, knots: &[f64], n: usize, u: f64) -> f64 {
    if u < knots[degree] {
        knots[degree]
    } else if u > knots[n] {
        knots[n]
    } else {
        u
    }
}

/// The conventional method for a curve (seed 001 eq. 2.1–2.9): rational basis functions
/// and their first two derivatives by the quotient rule, summed over all control points.
pub fn conventional_curve(degree: usize, knots: &[f64], ctrl: &[[f64; 4]], u: f64) -> CurvePoint {
    let n = ctrl.len();
    let u = clamp_domain(degree, knots, n, u);
    // W and its derivatives: the denominators of the quotient rule.
    let (mut w0, mut w1, mut w2) = (0.0, 0.0, 0.0);
    for (i, c) in ctrl.iter().enumerate() {
        w0 += cox_de_boor_der(i, degree, 0, knots, u) * c[3];
        w1 += cox_de_boor_der(i, degree, 1, knots, u) * c[3];
        w2 += cox_de_boor_der(i, degree, 2, knots, u) * c[3];
    }
    let mut out = CurvePoint {
        span: find_span(degree, knots, n, u),
        ..CurvePoint::default()
    };
    for (i, c) in ctrl.iter().enumerate() {
        let nw0 = cox_de_boor_der(i, degree, 0, knots, u) * c[3];
        let nw1 = cox_de_boor_der(i, degree, 1, knots, u) * c[3];
        let nw2 = cox_de_boor_der(i, degree, 2, knots, u) * c[3];
        let r0 = nw0 / w0;
        let r1 = nw1 / w0 - nw0 * w1 / (w0 * w0);
        let r2 = nw2 / w0 - (2.0 * nw1 * w1 + nw0 * w2) / (w0 * w0)
            + 2.0 * nw0 * w1 * w1 / (w0 * w0 * w0);
        for k in 0..3 {
            out.p[k] += r0 * c[k];
            out.d1[k] += r1 * c[k];
            out.d2[k] += r2 * c[k];
        }
    }
    out
}

/// The conventional method for a surface (seed 000 eq. 1–12): `R_ij`, `∂R_ij/∂u` and
/// `∂R_ij/∂v` by the quotient rule over all control points, basis functions recomputed
/// by Cox–de Boor for every term.
pub fn conventional_surface(s: &SurfaceData<'_>, u: f64, v: f64) -> SurfacePoint {
    let (p, q) = (s.degree_u, s.degree_v);
    let u = clamp_domain(p, s.knots_u, s.n_u, u);
    let v = clamp_domain(q, s.knots_v, s.n_v, v);
    let nu = |i: usize, k: usize| cox_de_boor_der(i, p, k, s.knots_u, u);
    let nv = |j: usize, k: usize| cox_de_boor_der(j, q, k, s.knots_v, v);
    let (mut w, mut wu, mut wv) = (0.0, 0.0, 0.0);
    for i in 0..s.n_u {
        for j in 0..s.n_v {
            let wij = s.ctrl[i * s.n_v + j][3];
            w += nu(i, 0) * nv(j, 0) * wij;
            wu += nu(i, 1) * nv(j, 0) * wij;
            wv += nu(i, 0) * nv(j, 1) * wij;
        }
    }
    let mut out = SurfacePoint {
        span_u: find_span(p, s.knots_u, s.n_u, u),
        span_v: find_span(q, s.knots_v, s.n_v, v),
        ..SurfacePoint::default()
    };
    for i in 0..s.n_u {
        for j in 0..s.n_v {
            let c = s.ctrl[i * s.n_v + j];
            let nw = nu(i, 0) * nv(j, 0) * c[3];
            let r = nw / w;
            let r_u = nu(i, 1) * nv(j, 0) * c[3] / w - nw * wu / (w * w);
            let r_v = nu(i, 0) * nv(j, 1) * c[3] / w - nw * wv / (w * w);
            for k in 0..3 {
                out.p[k] += r * c[k];
                out.du[k] += r_u * c[k];
                out.dv[k] += r_v * c[k];
            }
        }
    }
    out.normal = unit_normal(out.du, out.dv);
    out
}

/// The NURBS Book A2.3 (`DersBasisFuns`) for `n <= 2` derivatives: `ders[k][j]` is the
/// `k`-th derivative of `N_{span-p+j, p}` at `u`. Derivatives above `n` are zeroed. This is
/// the standard evaluator's own table ([`super::eval`]), not a second copy of it.
pub fn ders_basis_funs(p: usize, knots: &[f64], span: usize, u: f64, n: usize) -> [[f64; ORD]; 3] {
    let mut ders = super::eval::basis_ders(p, knots, span, u);
    for row in ders.iter_mut().skip(n.min(2) + 1) {
        *row = [0.0; ORD];
    }
    ders
}

/// The standard algorithm for a surface: span search and A2.3 per direction, the
/// homogeneous tensor sum (A3.6 on `P^w`), then the rational derivatives (A4.4).
pub fn piegl_tiller_surface(s: &SurfaceData<'_>, u: f64, v: f64) -> SurfacePoint {
    let (p, q) = (s.degree_u, s.degree_v);
    let u = clamp_domain(p, s.knots_u, s.n_u, u);
    let v = clamp_domain(q, s.knots_v, s.n_v, v);
    let su = find_span(p, s.knots_u, s.n_u, u);
    let sv = find_span(q, s.knots_v, s.n_v, v);
    let nu = ders_basis_funs(p, s.knots_u, su, u, 1);
    let nv = ders_basis_funs(q, s.knots_v, sv, v, 1);
    // skl[k][l]: ∂^{k+l} A^w / ∂u^k ∂v^l for k + l <= 1.
    let mut skl = [[[0.0f64; 4]; 2]; 2];
    for k in 0..=1 {
        for l in 0..=(1 - k) {
            let mut sum = [0.0f64; 4];
            for r in 0..=p {
                let mut temp = [0.0f64; 4];
                for c in 0..=q {
                    let cp = s.ctrl[(su - p + r) * s.n_v + (sv - q + c)];
                    let pw = [cp[0] * cp[3], cp[1] * cp[3], cp[2] * cp[3], cp[3]];
                    for x in 0..4 {
                        temp[x] += nv[l][c] * pw[x];
                    }
                }
                for x in 0..4 {
                    sum[x] += nu[k][r] * temp[x];
                }
            }
            skl[k][l] = sum;
        }
    }
    let w = skl[0][0][3];
    let mut out = SurfacePoint {
        span_u: su,
        span_v: sv,
        ..SurfacePoint::default()
    };
    for x in 0..3 {
        out.p[x] = skl[0][0][x] / w;
        out.du[x] = (skl[1][0][x] - skl[1][0][3] * out.p[x]) / w;
        out.dv[x] = (skl[0][1][x] - skl[0][1][3] * out.p[x]) / w;
    }
    out.normal = unit_normal(out.du, out.dv);
    out
}

/// The standard algorithm for a curve with A2.3 from this module (the production
/// [`super::eval`] is the same algorithm; this one lets the tests check A2.3 itself).
pub fn piegl_tiller_curve(degree: usize, knots: &[f64], ctrl: &[[f64; 4]], u: f64) -> CurvePoint {
    let n = ctrl.len();
    let u = clamp_domain(degree, knots, n, u);
    let span = find_span(degree, knots, n, u);
    let ders = ders_basis_funs(degree, knots, span, u, 2);
    let mut a = [[0.0f64; 4]; 3];
    for j in 0..=degree {
        let c = ctrl[span - degree + j];
        let pw = [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]];
        for k in 0..3 {
            for x in 0..4 {
                a[k][x] += ders[k][j] * pw[x];
            }
        }
    }
    let mut out = CurvePoint {
        span,
        ..CurvePoint::default()
    };
    let w = a[0][3];
    for x in 0..3 {
        out.p[x] = a[0][x] / w;
        out.d1[x] = (a[1][x] - a[1][3] * out.p[x]) / w;
        out.d2[x] = (a[2][x] - 2.0 * a[1][3] * out.d1[x] - a[2][3] * out.p[x]) / w;
    }
    out
}
