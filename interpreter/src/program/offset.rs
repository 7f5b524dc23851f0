//! The tool-centre path of a NURBS move under cutter radius compensation: the curve at
//! distance `d` beside the programmed one, `O(u) = C(u) + d·n(u)` (`n` the unit normal to
//! the left of travel; `d < 0` is to the right).
//!
//! No NURBS is exactly at a constant distance from another (but for circles and
//! lines), so `O` is fitted, as seed 004 fits the offsets of ellipses:
//!
//! * **The fit**: span by span of the programmed curve (where it is smooth), a cubic
//!   B-spline cut in `s` equal parts, by least squares on 12 points of `O` a part at the
//!   same parameters, its ends on `O`'s and its end tangents along the curve's. The
//!   spans' fits join end to end (a knot three times): they share the point there and,
//!   the curve being tangent-continuous, the direction. (One fit across a knot of the
//!   curve would be held to second order there: the offset's second derivative jumps
//!   with the curve's third, and its first with the curve's second where the knot is
//!   repeated.) The least `s` that keeps every span's fit within half the machine's
//!   chord tolerance (the interpolation's chords may leave the fitted curve by the other
//!   half) is found by doubling, then bisection.
//! * **The error** is `|F(u) − O(u)|`, the distance to the offset point of the same
//!   parameter: never less than the distance to the offset curve, so the bound is safe.
//!   It is sampled 16 times a fitted span, the worst refined by Brent's search
//!   between its neighbours.
//! * **Refused**, with the parameter where it happens, as LinuxCNC refuses the corners
//!   it cannot compensate:
//!   * a bend tighter than the tool on the tool's side (the radius of curvature not
//!     above `|d|`: the offset would turn back on itself, a gouge), found at 64 points a
//!     knot span or more (a chord of the curve at most a quarter of `|d|`), every peak
//!     of the bend refined;
//!   * an offset path that crosses itself (a neck of the curve narrower than the tool:
//!     the tool would cut through the other side), found on the offset sampled as
//!     densely, its segments compared cell by cell of a grid. (The offset is not
//!     compared with the moves before and after the curve, as LinuxCNC does not compare
//!     lines and arcs with moves beyond their neighbours.)
//!   * a corner inside the curve (a knot where its tangent turns at once) whose gap in
//!     the offset exceeds a quarter of the tolerance, a point where the curve stops (no
//!     tangent there), and more knot spans than a fit may take.

use nalgebra::{DMatrix, DVector};
use shared::nurbs::find_span;
use shared::nurbs::reference::ders_basis_funs;

/// Most control points a fitted offset may take.
const MAX_FIT_CTRL: usize = 2000;

/// Points of the programmed curve sampled per knot span for the gouge and crossing
/// tests, at least ([`samples_in`]).
const PER_SPAN: usize = 64;

/// Most samples a knot span gets for those tests.
const MAX_SPAN_SAMPLES: usize = 4096;

/// Most parts a programmed span's fit may be cut in.
const MAX_PARTS: usize = 256;

/// Why an offset cannot be made.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Refusal {
    /// The curve bends tighter than the tool on its side: its radius of curvature at `u`.
    Gouge { u: f64, radius: f64 },
    /// The offset path crosses itself between the parameters `u` and `v`.
    Crossing { u: f64, v: f64 },
    /// The tangent turns by `degrees` at the knot `u`.
    Corner { u: f64, degrees: f64 },
    /// The curve has no tangent at `u` (its speed is zero there).
    Stops { u: f64 },
    /// No fit within [`MAX_FIT_CTRL`] control points came within the tolerance.
    NoFit { best: f64 },
    /// More knot spans than a fitted offset can take.
    Spans { spans: usize },
}

impl Refusal {
    /// In words, for a message naming the line.
    pub(super) fn message(&self, tol: f64) -> String {
        match self {
            Refusal::Gouge { u, radius } => format!(
                "the NURBS bends tighter than the tool at its parameter u = {u:.6} (radius of curvature {radius:.4} mm, not above the tool's radius): the offset path would turn back on itself and gouge the part"
            ),
            Refusal::Crossing { u, v } => format!(
                "the tool's offset path crosses itself between the NURBS parameters u = {u:.6} and u = {v:.6}: the part is narrower there than the tool, which would cut through its other side"
            ),
            Refusal::Corner { u, degrees } => format!(
                "the NURBS turns a corner of {degrees:.3}° at its knot u = {u:.6}: split it there into two moves, so that the corner is compensated as a corner"
            ),
            Refusal::Stops { u } => format!(
                "the NURBS has no direction at its parameter u = {u:.6} (its control points make it stop there), so the tool has no side to be on"
            ),
            Refusal::NoFit { best } => format!(
                "no fit of the tool's offset path with up to {MAX_FIT_CTRL} control points comes within half the chord tolerance, {} mm (best {best:.3e} mm)",
                tol / 2.0
            ),
            Refusal::Spans { spans } => format!(
                "the NURBS has {spans} knot spans, more than a fitted offset takes ({}): split it into several moves",
                (MAX_FIT_CTRL - 1) / 3
            ),
        }
    }
}

/// The programmed curve, `[x, y, z, w]` control points.
struct Curve<'a> {
    degree: usize,
    knots: &'a [f64],
    ctrl: &'a [[f64; 4]],
    d: f64,
}

/// What the tests need of a point of the curve.
struct At {
    p: [f64; 2],
    d1: [f64; 2],
    speed: f64,
    /// Signed curvature, positive turning left.
    kappa: f64,
}

impl Curve<'_> {
    fn at(&self, u: f64) -> At {
        let e = shared::nurbs::eval(self.degree, self.knots, self.ctrl, u);
        let (d1, d2) = ([e.d1[0], e.d1[1]], [e.d2[0], e.d2[1]]);
        let speed = d1[0].hypot(d1[1]);
        let kappa = (d1[0] * d2[1] - d1[1] * d2[0]) / speed.powi(3);
        At {
            p: [e.p[0], e.p[1]],
            d1,
            speed,
            kappa,
        }
    }

    /// `O(u)`.
    fn offset(&self, u: f64) -> [f64; 2] {
        let a = self.at(u);
        let (tx, ty) = (a.d1[0] / a.speed, a.d1[1] / a.speed);
        [a.p[0] - self.d * ty, a.p[1] + self.d * tx]
    }

    fn unit_tangent(&self, u: f64) -> [f64; 2] {
        let a = self.at(u);
        [a.d1[0] / a.speed, a.d1[1] / a.speed]
    }

    /// The distinct knots of the domain.
    fn breaks(&self) -> Vec<f64> {
        let n = self.ctrl.len();
        let mut b: Vec<f64> = self.knots[self.degree..=n].to_vec();
        b.dedup();
        b
    }
}

/// How many samples the span `[a, b]` gets for the gouge and crossing tests: at least
/// [`PER_SPAN`], and enough that the offset's chords are at most a quarter of the
/// offset apart (so a crossing is not stepped over), at most [`MAX_SPAN_SAMPLES`].
fn samples_in(c: &Curve, a: f64, b: f64) -> usize {
    let mut len = 0.0;
    let mut last = c.at(a).p;
    for i in 1..=PER_SPAN {
        let p = c.at(a + (b - a) * i as f64 / PER_SPAN as f64).p;
        len += (p[0] - last[0]).hypot(p[1] - last[1]);
        last = p;
    }
    let step = (c.d.abs() / 4.0).max(1e-3);
    ((len / step).ceil() as usize).clamp(PER_SPAN, MAX_SPAN_SAMPLES)
}

/// The gouge, corner and stop tests (module page).
fn check(c: &Curve, tol: f64) -> Result<(), Refusal> {
    let breaks = c.breaks();
    let (lo, hi) = (breaks[0], breaks[breaks.len() - 1]);
    let scale = c
        .ctrl
        .iter()
        .flat_map(|p| [p[0].abs(), p[1].abs()])
        .fold(1.0f64, f64::max);
    for w in breaks.windows(2) {
        let count = samples_in(c, w[0], w[1]);
        let h = (w[1] - w[0]) / count as f64;
        let bend = |u: f64| c.d * c.at(u).kappa;
        let mut bends = Vec::with_capacity(count + 1);
        for i in 0..=count {
            let u = w[0] + h * i as f64;
            let a = c.at(u);
            if a.speed.is_nan() || a.speed <= 1e-12 * scale / (hi - lo) || !a.kappa.is_finite() {
                return Err(Refusal::Stops { u });
            }
            bends.push(bend(u));
        }
        // Every peak of the bend refined (a sharp one may hide between samples).
        for i in 0..=count {
            let peak =
                (i == 0 || bends[i] >= bends[i - 1]) && (i == count || bends[i] >= bends[i + 1]);
            if !peak {
                continue;
            }
            let u0 = w[0] + h * i as f64;
            let (u, b) = crate::brent::refine_max((u0 - h).max(w[0]), (u0 + h).min(w[1]), u0, bend);
            if b >= 1.0 {
                return Err(Refusal::Gouge {
                    u,
                    radius: 1.0 / c.at(u).kappa.abs(),
                });
            }
        }
    }
    // Corners at inner knots: the tangent just before against the one at the knot.
    for &k in &breaks[1..breaks.len() - 1] {
        let before = c.unit_tangent(k - 1e-12 * (hi - lo).max(k.abs()));
        let after = c.unit_tangent(k);
        let turn = (before[0] * after[1] - before[1] * after[0])
            .atan2(before[0] * after[0] + before[1] * after[1]);
        if c.d.abs() * turn.abs() > tol / 4.0 {
            return Err(Refusal::Corner {
                u: k,
                degrees: turn.to_degrees(),
            });
        }
    }
    Ok(())
}

/// Whether segments `a0 a1` and `b0 b1` cross (touching ends do not count).
fn cross(a0: [f64; 2], a1: [f64; 2], b0: [f64; 2], b1: [f64; 2]) -> bool {
    let side = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])
    };
    let (d1, d2) = (side(a0, a1, b0), side(a0, a1, b1));
    let (d3, d4) = (side(b0, b1, a0), side(b0, b1, a1));
    d1 * d2 < 0.0 && d3 * d4 < 0.0
}

/// The offset sampled as [`samples_in`] says, searched for two segments that cross: each
/// segment filed in the cells of a grid (cells as wide as the longest segment) that its
/// box touches, and compared with those filed in the same cells.
fn crossing(c: &Curve) -> Result<(), Refusal> {
    let breaks = c.breaks();
    let mut pts: Vec<(f64, [f64; 2])> = Vec::new();
    for w in breaks.windows(2) {
        let count = samples_in(c, w[0], w[1]);
        for i in 0..count {
            let u = w[0] + (w[1] - w[0]) * i as f64 / count as f64;
            pts.push((u, c.offset(u)));
        }
    }
    let last = breaks[breaks.len() - 1];
    pts.push((last, c.offset(last)));
    let segs = pts.len() - 1;
    let closed = {
        let (a, b) = (pts[0].1, pts[segs].1);
        (a[0] - b[0]).hypot(a[1] - b[1]) < 1e-9
    };
    let cell = (0..segs)
        .map(|i| (pts[i].1[0] - pts[i + 1].1[0]).hypot(pts[i].1[1] - pts[i + 1].1[1]))
        .fold(1e-9f64, f64::max);
    let key = |x: f64| (x / cell).floor() as i64;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    for i in 0..segs {
        let (p, q) = (pts[i].1, pts[i + 1].1);
        for gx in key(p[0].min(q[0]))..=key(p[0].max(q[0])) {
            for gy in key(p[1].min(q[1]))..=key(p[1].max(q[1])) {
                grid.entry((gx, gy)).or_default().push(i);
            }
        }
    }
    let mut found: Option<(f64, f64)> = None;
    for members in grid.values() {
        for (k, &a) in members.iter().enumerate() {
            for &b in &members[k + 1..] {
                let (a, b) = (a.min(b), a.max(b));
                if b - a <= 1 || (closed && a == 0 && b == segs - 1) {
                    continue;
                }
                if cross(pts[a].1, pts[a + 1].1, pts[b].1, pts[b + 1].1) {
                    let hit = (pts[a].0, pts[b].0);
                    if found.is_none_or(|f| hit.0 < f.0) {
                        found = Some(hit);
                    }
                }
            }
        }
    }
    match found {
        Some((u, v)) => Err(Refusal::Crossing { u, v }),
        None => Ok(()),
    }
}

/// The least-squares cubic of the offset over the programmed span `[lo, hi]`, cut in `s`
/// equal parts: clamped knots on `[lo, hi]`, control points, and its error. Its ends are
/// `O(lo)` and `O(hi)`, its end tangents the curve's (from inside the span).
fn fit_span(c: &Curve, s: usize, lo: f64, hi: f64) -> Option<(Vec<f64>, Vec<[f64; 2]>, f64)> {
    let mut knots = vec![lo; 4];
    knots.extend((1..s).map(|i| lo + (hi - lo) * i as f64 / s as f64));
    knots.extend_from_slice(&[hi; 4]);
    let n = knots.len() - 4;
    let (p0, p1) = (c.offset(lo), c.offset(hi));
    // (The tangent at the span's end from inside it: at a knot the evaluator gives the
    // next span's.)
    let t0 = c.unit_tangent(lo);
    let t1 = c.unit_tangent(hi - 1e-9 * (hi - lo));
    // Unknowns: α (P1 = P0 + α·T0), β (P[n−2] = P[n−1] − β·T1), x and y of P2 … P[n−3].
    let cols = 2 + 2 * (n - 4);
    let mut ata = DMatrix::<f64>::zeros(cols, cols);
    let mut atb = DVector::<f64>::zeros(cols);
    let samples = 12 * s;
    for k in 0..samples {
        let u = lo + (hi - lo) * (k as f64 + 0.5) / samples as f64;
        let q = c.offset(u);
        let sp = find_span(3, &knots, n, u);
        let nb = ders_basis_funs(3, &knots, sp, u, 0)[0];
        for axis in 0..2 {
            let mut row: Vec<(usize, f64)> = Vec::with_capacity(5);
            let mut rhs = q[axis];
            for (b, &nv) in nb.iter().take(4).enumerate() {
                let j = sp - 3 + b;
                if j == 0 {
                    rhs -= nv * p0[axis];
                } else if j == n - 1 {
                    rhs -= nv * p1[axis];
                } else if j == 1 {
                    rhs -= nv * p0[axis];
                    row.push((0, nv * t0[axis]));
                } else if j == n - 2 {
                    rhs -= nv * p1[axis];
                    row.push((1, -nv * t1[axis]));
                } else {
                    row.push((2 + 2 * (j - 2) + axis, nv));
                }
            }
            for &(i, a) in &row {
                atb[i] += a * rhs;
                for &(j, b) in &row {
                    ata[(i, j)] += a * b;
                }
            }
        }
    }
    let sol = ata.cholesky()?.solve(&atb);
    if sol.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let mut ctrl = vec![p0; n];
    ctrl[n - 1] = p1;
    ctrl[1] = [p0[0] + sol[0] * t0[0], p0[1] + sol[0] * t0[1]];
    ctrl[n - 2] = [p1[0] - sol[1] * t1[0], p1[1] - sol[1] * t1[1]];
    for j in 2..n - 2 {
        ctrl[j] = [sol[2 + 2 * (j - 2)], sol[3 + 2 * (j - 2)]];
    }
    // The error against the offset point of the same parameter.
    let h: Vec<[f64; 4]> = ctrl.iter().map(|p| [p[0], p[1], 0.0, 1.0]).collect();
    let err = |u: f64| {
        let f = shared::nurbs::eval(3, &knots, &h, u).p;
        let o = c.offset(u);
        let e = (f[0] - o[0]).hypot(f[1] - o[1]);
        // (A NaN is no fit: read as the worst.)
        if e.is_nan() {
            f64::INFINITY
        } else {
            e
        }
    };
    let step = (hi - lo) / (16 * s) as f64;
    let mut worst = (lo, 0.0f64);
    for k in 0..=16 * s {
        let u = lo + step * k as f64;
        let e = err(u);
        if e > worst.1 {
            worst = (u, e);
        }
    }
    let (_, refined) = crate::brent::refine_max(
        (worst.0 - step).max(lo),
        (worst.0 + step).min(hi),
        worst.0,
        err,
    );
    Some((knots, ctrl, worst.1.max(refined)))
}

/// The offset fitted span by span of the programmed curve, each cut in `s` parts, joined
/// into one cubic (a knot three times where two spans meet: they share that point and
/// the direction there), and its error.
fn fit(c: &Curve, s: usize) -> Option<(Vec<f64>, Vec<[f64; 2]>, f64)> {
    let breaks = c.breaks();
    let mut knots = vec![breaks[0]; 4];
    let mut ctrl: Vec<[f64; 2]> = Vec::new();
    let mut error = 0.0f64;
    for (i, w) in breaks.windows(2).enumerate() {
        let (k, p, e) = fit_span(c, s, w[0], w[1])?;
        error = error.max(e);
        knots.extend_from_slice(&k[4..k.len() - 4]);
        let last = i + 2 == breaks.len();
        knots.extend(std::iter::repeat_n(w[1], if last { 4 } else { 3 }));
        ctrl.extend_from_slice(if i == 0 { &p[..] } else { &p[1..] });
    }
    Some((knots, ctrl, error))
}

/// The fitted offset: cubic, clamped, its knots, control points (XY) and error.
#[derive(Debug, Clone)]
pub(super) struct Fitted {
    pub knots: Vec<f64>,
    pub ctrl: Vec<[f64; 2]>,
    pub error: f64,
}

/// The offset at `d` of the programmed NURBS, within `tol` (module page).
pub(super) fn offset(
    degree: usize,
    knots: &[f64],
    ctrl: &[[f64; 4]],
    d: f64,
    tol: f64,
) -> Result<Fitted, Refusal> {
    let c = Curve {
        degree,
        knots,
        ctrl,
        d,
    };
    let spans = c.breaks().len() - 1;
    if spans * 3 + 1 > MAX_FIT_CTRL {
        return Err(Refusal::Spans { spans });
    }
    check(&c, tol)?;
    crossing(&c)?;
    // Half the tolerance for the fit: the interpolation's chords may leave the fitted
    // curve by the other half.
    let tol = tol / 2.0;
    let mut best = f64::INFINITY;
    let mut meets = |s: usize| -> Option<Fitted> {
        let (knots, ctrl, error) = fit(&c, s)?;
        best = best.min(error);
        (error <= tol).then_some(Fitted { knots, ctrl, error })
    };
    // Doubling to a count that meets the tolerance, then bisection below it.
    let (mut lo, mut hi) = (0, 1);
    let mut found = loop {
        if spans * (hi + 2) + 1 > MAX_FIT_CTRL || hi > MAX_PARTS {
            return Err(Refusal::NoFit { best });
        }
        if let Some(f) = meets(hi) {
            break f;
        }
        lo = hi;
        hi *= 2;
    };
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        match meets(mid) {
            Some(f) => {
                found = f;
                hi = mid;
            }
            None => lo = mid,
        }
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A circle's offset is a circle: a rational quadratic half circle (radius 10 round
    /// the origin, anticlockwise) offset 2 mm to the left (inside) and to the right
    /// (outside) lies within the tolerance of radius 8 and 12 (closed form), and the
    /// fit's own error bound is not below what is found.
    #[test]
    fn a_circle_s_offset_is_the_concentric_circle() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let ctrl = [
            [10.0, 0.0, 0.0, 1.0],
            [10.0, 10.0, 0.0, h],
            [0.0, 10.0, 0.0, 1.0],
            [-10.0, 10.0, 0.0, h],
            [-10.0, 0.0, 0.0, 1.0],
        ];
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        for (d, radius, tol) in [(2.0, 8.0, 1e-3), (-2.0, 12.0, 1e-3), (2.0, 8.0, 1e-6)] {
            let f = offset(2, &knots, &ctrl, d, tol).unwrap();
            assert!(f.error <= tol);
            let h: Vec<[f64; 4]> = f.ctrl.iter().map(|p| [p[0], p[1], 0.0, 1.0]).collect();
            let (lo, hi) = (f.knots[0], f.knots[f.knots.len() - 1]);
            let mut worst = 0.0f64;
            for k in 0..=5000 {
                let u = lo + (hi - lo) * k as f64 / 5000.0;
                let p = shared::nurbs::eval(3, &f.knots, &h, u).p;
                worst = worst.max((p[0].hypot(p[1]) - radius).abs());
            }
            assert!(
                worst <= f.error * 1.001 + 1e-12,
                "{worst} against {}",
                f.error
            );
            println!(
                "d {d}, tol {tol}: {} control points, {worst:.3e} mm",
                f.ctrl.len()
            );
        }
    }

    /// A bend tighter than the tool on its side is a gouge; on the other side it is not.
    #[test]
    fn a_bend_tighter_than_the_tool_inside_it_is_a_gouge() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let ctrl = [
            [10.0, 0.0, 0.0, 1.0],
            [10.0, 10.0, 0.0, h],
            [0.0, 10.0, 0.0, 1.0],
        ];
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        match offset(2, &knots, &ctrl, 10.5, 1e-3) {
            Err(Refusal::Gouge { radius, .. }) => assert!((radius - 10.0).abs() < 1e-9),
            other => panic!("{other:?}"),
        }
        assert!(offset(2, &knots, &ctrl, -10.5, 1e-3).is_ok());
    }
}
