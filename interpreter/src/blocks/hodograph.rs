//! Lower bounds of a Bézier span's speed `|C'(u)|` without evaluating it.
//!
//! On its own parameter `t` in `[0, 1]`, a rational Bézier span `C = A/w` (`A` the
//! weighted points, `w` the weights) has the derivative `dC/dt = N/w²` with
//! `N = A'w − Aw'`, a polynomial of degree `2p − 1` whose Bernstein coefficients follow
//! from the control points. `N(t)` lies in the convex hull of its coefficients, so where
//! all of them lie well on one side of a plane through the origin, `|N|` (and with the
//! largest weight, `|C'|`) stays above that distance over the whole span; where they do
//! not, halving the span (de Casteljau) tightens the hull, down to [`CELLS`] parts.
//!
//! The cusp search and the planner's samples use it to know, before evaluating anything,
//! where the curve cannot come to (nearly) a stop: there their tests would find nothing,
//! so they are skipped, and what they find elsewhere is what they found before.

use shared::nurbs::MAX_DEGREE;

/// Equal parts of the span told apart: the bits of a `u64`.
pub const CELLS: usize = 64;

/// Most Bernstein coefficients of `N` (degree `2p − 1`).
const MAX_COEFFS: usize = 2 * MAX_DEGREE;

/// `N` of one rational Bézier span, ready to bound.
#[derive(Debug, Clone)]
pub struct Hodograph {
    /// How many coefficients (`2p`).
    n: usize,
    coeffs: [[f64; 3]; MAX_COEFFS],
    /// The largest weight: `w(t)` never exceeds it (a convex combination of them).
    w_max: f64,
    /// The parameter width of the span, `u1 − u0`: `dC/du = N / (w²·width)`.
    width: f64,
    /// More than the rounding of the coefficients, their halvings and the bound can add
    /// up to: a multiple of the sum of the magnitudes of every term that went in.
    slack: f64,
}

/// `n` choose `k` (exact: every value here is a small integer).
fn choose(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64)
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

impl Hodograph {
    /// `N` of a curve that is one Bézier span (`degree + 1` control points on clamped
    /// knots); `None` for any other curve, or one with numbers that are not finite.
    pub fn of_span(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> Option<Self> {
        let p = degree;
        if p == 0 || p > MAX_DEGREE || ctrl.len() != p + 1 || knots.len() != 2 * p + 2 {
            return None;
        }
        // Clamped: the first `p + 1` knots one number, the others another.
        if knots[0] != knots[p] || knots[p + 1] != knots[2 * p + 1] {
            return None;
        }
        let width = knots[knots.len() - 1] - knots[0];
        if !(width > 0.0 && width.is_finite()) || ctrl.iter().flatten().any(|x| !x.is_finite()) {
            return None;
        }
        let a = |k: usize| {
            let c = ctrl[k];
            [c[0] * c[3], c[1] * c[3], c[2] * c[3]]
        };
        let w = |k: usize| ctrl[k][3];
        // N = p·Σ over i in 0..p, k in 0..=p of
        //   C(p−1, i)·C(p, k)/C(2p−1, i+k) · (ΔA_i·w_k − A_k·Δw_i) · B_{i+k, 2p−1}.
        let mut coeffs = [[0.0; 3]; MAX_COEFFS];
        let mut magnitude = 0.0;
        for i in 0..p {
            let da = {
                let (a0, a1) = (a(i), a(i + 1));
                [a1[0] - a0[0], a1[1] - a0[1], a1[2] - a0[2]]
            };
            let dw = w(i + 1) - w(i);
            for k in 0..=p {
                let f = p as f64 * choose(p - 1, i) * choose(p, k) / choose(2 * p - 1, i + k);
                let ak = a(k);
                let q = &mut coeffs[i + k];
                for x in 0..3 {
                    q[x] += f * (da[x] * w(k) - ak[x] * dw);
                }
                magnitude += f * (norm(da) * w(k).abs() + norm(ak) * dw.abs());
            }
        }
        let w_max = ctrl.iter().fold(0.0f64, |m, c| m.max(c[3]));
        if !(w_max > 0.0 && magnitude.is_finite()) {
            return None;
        }
        Some(Hodograph {
            n: 2 * p,
            coeffs,
            w_max,
            width,
            slack: 1e-10 * magnitude,
        })
    }

    /// The cells (bit `j`: the `j`-th of [`CELLS`] equal parts of the domain) where
    /// `|C'(u)|` is proven to stay above twice `floor`, with room for the rounding of
    /// the bound and of any evaluation near it; a NaN floor proves nothing.
    pub fn cells_above(&self, floor: f64) -> u64 {
        let need = 2.0 * floor * self.width * self.w_max * self.w_max + self.slack;
        let mut bits = 0;
        if need.is_finite() {
            self.prove(&self.coeffs[..self.n], 0, CELLS, need, &mut bits);
        }
        bits
    }

    /// Marks the `count` cells from `first`, which `q` (the coefficients on them) covers,
    /// where `|N|` stays above `need`.
    fn prove(&self, q: &[[f64; 3]], first: usize, count: usize, need: f64, bits: &mut u64) {
        if lower_bound(q) > need {
            *bits |= if count >= CELLS {
                u64::MAX
            } else {
                ((1u64 << count) - 1) << first
            };
            return;
        }
        if count == 1 {
            return;
        }
        let (left, right) = halves(q);
        let n = q.len();
        self.prove(&left[..n], first, count / 2, need, bits);
        self.prove(&right[..n], first + count / 2, count / 2, need, bits);
    }
}

/// A lower bound of `|N(t)|` over the coefficients' span: the least distance of them
/// along their mean direction (`N(t)` is a convex combination of them). Not positive
/// when they surround the origin; NaN never passes a `>` test.
fn lower_bound(q: &[[f64; 3]]) -> f64 {
    let s = q
        .iter()
        .fold([0.0; 3], |s, c| [s[0] + c[0], s[1] + c[1], s[2] + c[2]]);
    let ns = norm(s);
    if ns.is_nan() || ns <= 0.0 {
        return f64::NEG_INFINITY;
    }
    let d = s.map(|x| x / ns);
    q.iter()
        .map(|c| c[0] * d[0] + c[1] * d[1] + c[2] * d[2])
        .fold(f64::INFINITY, f64::min)
}

type Coeffs = [[f64; 3]; MAX_COEFFS];

/// The coefficients of the two halves of a Bézier polynomial (de Casteljau at 1/2).
fn halves(q: &[[f64; 3]]) -> (Coeffs, Coeffs) {
    let n = q.len();
    let mut w: Coeffs = [[0.0; 3]; MAX_COEFFS];
    w[..n].copy_from_slice(q);
    let (mut left, mut right): (Coeffs, Coeffs) = ([[0.0; 3]; MAX_COEFFS], [[0.0; 3]; MAX_COEFFS]);
    left[0] = w[0];
    right[n - 1] = w[n - 1];
    for level in 1..n {
        for j in 0..n - level {
            let (a, b) = (w[j], w[j + 1]);
            w[j] = [
                0.5 * (a[0] + b[0]),
                0.5 * (a[1] + b[1]),
                0.5 * (a[2] + b[2]),
            ];
        }
        left[level] = w[0];
        right[n - 1 - level] = w[n - 1 - level];
    }
    (left, right)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use shared::nurbs;

    /// Knots of one Bézier span of `degree` on `[u0, u1]`.
    fn bezier(degree: usize, u0: f64, u1: f64) -> Vec<f64> {
        let mut k = vec![u0; degree + 1];
        k.extend(std::iter::repeat_n(u1, degree + 1));
        k
    }

    proptest! {
        /// Wherever a cell is proven above a floor, the evaluated speed is above it, at
        /// many points of the cell (random rational spans, floors near their speeds).
        #[test]
        fn proven_cells_are_above_the_floor(
            degree in 1usize..=5,
            pts in proptest::collection::vec(
                (-50.0f64..50.0, -50.0f64..50.0, -5.0f64..5.0, 0.2f64..3.0), 6),
            u0 in -3.0f64..3.0,
            width in 0.01f64..10.0,
            floor_share in 0.0f64..1.5,
        ) {
            let ctrl: Vec<[f64; 4]> =
                pts[..=degree].iter().map(|&(x, y, z, w)| [x, y, z, w]).collect();
            let knots = bezier(degree, u0, u0 + width);
            let h = Hodograph::of_span(degree, &knots, &ctrl).unwrap();
            let speed = |u: f64| norm(nurbs::eval(degree, &knots, &ctrl, u).d1);
            let mean = (0..=64).map(|i| speed(u0 + width * i as f64 / 64.0)).sum::<f64>() / 65.0;
            let floor = floor_share * mean;
            let bits = h.cells_above(floor);
            for cell in (0..CELLS).filter(|c| bits >> c & 1 == 1) {
                for j in 0..=16 {
                    let t = (cell as f64 + j as f64 / 16.0) / CELLS as f64;
                    let s = speed(u0 + width * t);
                    prop_assert!(s > 2.0 * floor, "cell {cell} t {t}: {s} <= 2 * {floor}");
                }
            }
        }
    }

    #[test]
    fn a_cusp_is_never_proven_clear_and_a_line_is() {
        // Out along X and back: C'(1/2) = 0, the boundary of cells 31 and 32.
        let ctrl = [
            [0.0, 0.0, 0.0, 1.0],
            [2.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let knots = bezier(2, 0.0, 1.0);
        let h = Hodograph::of_span(2, &knots, &ctrl).unwrap();
        let bits = h.cells_above(1e-9);
        assert_eq!(bits >> 31 & 3, 0, "{bits:064b}");
        assert_ne!(bits, 0);
        let line = [
            [0.0, 0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0, 2.0],
            [3.0, 1.0, 0.0, 1.0],
        ];
        let h = Hodograph::of_span(2, &knots, &line).unwrap();
        assert_eq!(h.cells_above(1e-3), u64::MAX);
    }
}
