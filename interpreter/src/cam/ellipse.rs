//! `cnc cam ellipse`: an ellipse, or its offset, as a NURBS part program (seed 004, Lai,
//! Chen and Hung: NURBS ellipses and their offsets for a Fanuc `G06.2` control).
//!
//! * **The ellipse is exact.** An ellipse is the affine image of a circle, and a circle
//!   is a rational quadratic NURBS: four quarter arcs, each with its corner control point
//!   weighted `√2/2`, knots `0 0 0 1 1 2 2 3 3 4 4 4`. Scaled by `a` and `b` it is the
//!   ellipse itself, with no fitting error (the seed fitted polynomial curves with
//!   uniform knots and erred by up to 0.1 for `a = 5, b = 3`). Written as `G6.2` with its
//!   `K` knots and `R` weights (LinuxCNC) or `G06.2` (Fanuc); the weight is printed so
//!   that it reads back as the same double.
//! * **The offset is fitted.** The curve at distance `D` from an ellipse (the tool
//!   centre's path for a cutter of radius `D`) is no NURBS. It is fitted with a cubic
//!   B-spline on clamped uniform knots (so LinuxCNC's `G5.2 … L4` carries it; Fanuc's
//!   `G06.2` with its knots), by least squares on 24 points a span, its ends on the
//!   offset and its end tangents along it (the closed path has no kink where it starts).
//!   The fewest control points that meet the tolerance are found by trying each count
//!   from 8 up. The error is measured against the true offset `C(t) + D·n(t)`: the
//!   fitted curve sampled 64 times a span, each sample's nearest point on the offset
//!   found by Newton's method from its own parameter, the worst sample refined by
//!   Brent's search between its neighbours.
//!
//! Not in the real-time path; the fit's least squares are nalgebra's (normal equations
//! by Cholesky). The count of control points is searched by doubling from 8, then
//! bisecting between the last count that failed and the first that met the tolerance
//! (the error falls as the count grows).

use super::{conic_arc, point, program, uniform_knots, Curve, Cut, Job};
use nalgebra::{DMatrix, DVector};
use std::f64::consts::TAU;

/// What `cnc cam ellipse` is asked for (mm, mm/min).
#[derive(Debug, Clone, PartialEq)]
pub struct EllipseJob {
    /// Semi-axes along X and Y.
    pub a: f64,
    pub b: f64,
    pub centre: [f64; 2],
    /// The offset outward (negative: inward); 0 for the ellipse itself.
    pub offset: f64,
    /// Most distance from the true offset curve.
    pub tolerance: f64,
    pub feed: f64,
    /// Z of the cut; the tool comes down from `depth + 5` and goes back there.
    pub depth: f64,
    pub fanuc: bool,
}

impl EllipseJob {
    fn cut(&self) -> Job {
        Job {
            feed: self.feed,
            depth: self.depth,
            fanuc: self.fanuc,
        }
    }
}

/// The exact ellipse, anticlockwise from `(cx + a, cy)`.
pub fn ellipse(a: f64, b: f64, centre: [f64; 2]) -> Curve {
    conic_arc(centre, [a, 0.0], [0.0, b], 0.0, TAU)
}

/// The point of the offset at distance `d` from the ellipse (semi-axes `a`, `b`, centred
/// at the origin) at its angle parameter `t`, and its derivative in `t`.
fn offset_at(a: f64, b: f64, d: f64, t: f64) -> ([f64; 2], [f64; 2]) {
    let (s, c) = t.sin_cos();
    // The outward normal is (b cos t, a sin t) / g.
    let g = (b * b * c * c + a * a * s * s).sqrt();
    let dg = (a * a - b * b) * s * c / g;
    let p = [a * c + d * b * c / g, b * s + d * a * s / g];
    let dp = [
        -a * s + d * b * (-s * g - c * dg) / (g * g),
        b * c + d * a * (c * g - s * dg) / (g * g),
    ];
    (p, dp)
}

/// The B-spline basis functions of `degree` on `knots` at `u` (all of them).
fn basis(degree: usize, knots: &[f64], n: usize, u: f64) -> Vec<f64> {
    let last = knots[knots.len() - 1];
    let mut nk: Vec<f64> = (0..knots.len() - 1)
        .map(|i| {
            let inside = knots[i] <= u && u < knots[i + 1];
            // The domain's end belongs to the last non-empty span.
            let at_end = u >= last && knots[i] < knots[i + 1] && knots[i + 1] >= last;
            if inside || at_end {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    for p in 1..=degree {
        for i in 0..knots.len() - 1 - p {
            let l = knots[i + p] - knots[i];
            let r = knots[i + p + 1] - knots[i + 1];
            let left = if l > 0.0 {
                (u - knots[i]) / l * nk[i]
            } else {
                0.0
            };
            let right = if r > 0.0 {
                (knots[i + p + 1] - u) / r * nk[i + 1]
            } else {
                0.0
            };
            nk[i] = left + right;
        }
    }
    nk.truncate(n);
    nk
}

/// Least-squares cubic fit of the offset with `n` control points (its ends on the
/// offset, its end tangents along the offset's), in the ellipse's own frame.
fn fit(a: f64, b: f64, d: f64, n: usize) -> Option<Curve> {
    let degree = 3;
    let knots = uniform_knots(degree, n);
    let spans = (n - degree) as f64;
    let (p0, dp0) = offset_at(a, b, d, 0.0);
    let len = dp0[0].hypot(dp0[1]);
    let tan = [dp0[0] / len, dp0[1] / len];
    // Unknowns: α (P1 = P0 + α·T), β (P[n−2] = P0 − β·T), then x and y of P2 … P[n−3].
    let inner = n - 4;
    let cols = 2 + 2 * inner;
    let samples = 24 * (n - degree);
    let mut m = DMatrix::<f64>::zeros(2 * samples, cols);
    let mut rhs = DVector::<f64>::zeros(2 * samples);
    for k in 0..samples {
        let u = spans * (k as f64 + 0.5) / samples as f64;
        let t = TAU * u / spans;
        let (q, _) = offset_at(a, b, d, t);
        let nb = basis(degree, &knots, n, u);
        for axis in 0..2 {
            let row = 2 * k + axis;
            // The fixed ends: P0 = P[n−1] = q(0), with the tangent terms.
            let fixed = (nb[0] + nb[1] + nb[n - 2] + nb[n - 1]) * p0[axis];
            rhs[row] = q[axis] - fixed;
            m[(row, 0)] = nb[1] * tan[axis];
            m[(row, 1)] = -nb[n - 2] * tan[axis];
            for j in 0..inner {
                m[(row, 2 + 2 * j + axis)] = nb[2 + j];
            }
        }
    }
    // The normal equations, by Cholesky: B-spline bases are well conditioned (each
    // column overlaps only its neighbours'), and this is far cheaper than an SVD.
    let mt = m.transpose();
    let sol = (&mt * &m).cholesky()?.solve(&(&mt * &rhs));
    let mut ctrl = vec![[p0[0], p0[1], 1.0]; n];
    ctrl[1] = [p0[0] + sol[0] * tan[0], p0[1] + sol[0] * tan[1], 1.0];
    ctrl[n - 2] = [p0[0] - sol[1] * tan[0], p0[1] - sol[1] * tan[1], 1.0];
    for j in 0..inner {
        ctrl[2 + j] = [sol[2 + 2 * j], sol[3 + 2 * j], 1.0];
    }
    Some(Curve {
        degree,
        knots,
        ctrl,
    })
}

/// The distance from `p` to the offset curve (semi-axes `a`, `b`, distance `d`), its
/// nearest point searched by Newton's method from the angle `t0`.
pub fn distance_to_offset(a: f64, b: f64, d: f64, p: [f64; 2], t0: f64) -> f64 {
    let mut t = t0;
    let h = 1e-6;
    for _ in 0..30 {
        // f(t) = (O(t) − p)·O'(t); its derivative by a central difference.
        let f = |t: f64| {
            let (o, dp) = offset_at(a, b, d, t);
            (o[0] - p[0]) * dp[0] + (o[1] - p[1]) * dp[1]
        };
        let (f0, df) = (f(t), (f(t + h) - f(t - h)) / (2.0 * h));
        if df.abs() < 1e-300 {
            break;
        }
        let step = (f0 / df).clamp(-0.1, 0.1);
        t -= step;
        if step.abs() < 1e-15 {
            break;
        }
    }
    let (o, _) = offset_at(a, b, d, t);
    (o[0] - p[0]).hypot(o[1] - p[1])
}

/// The most the fitted `c` (in the ellipse's own frame) strays from the true offset:
/// 64 samples a span, the worst refined between its neighbours.
pub fn fit_error(c: &Curve, a: f64, b: f64, d: f64) -> f64 {
    let spans = c.knots[c.knots.len() - 1];
    let per = 64;
    let count = per * spans as usize;
    let err = |u: f64| distance_to_offset(a, b, d, point(c, u), TAU * u / spans);
    let mut worst = (0.0f64, 0.0f64);
    for k in 0..=count {
        let u = spans * k as f64 / count as f64;
        let e = err(u);
        if e > worst.0 {
            worst = (e, u);
        }
    }
    // The largest error between the worst sample's neighbours.
    let step = spans / count as f64;
    let lo = (worst.1 - step).max(0.0);
    let hi = (worst.1 + step).min(spans);
    worst
        .0
        .max(crate::brent::refine_max(lo, hi, worst.1, err).1)
}

/// Most control points tried before the tolerance is called out of reach.
const MAX_CTRL: usize = 400;

/// The offset fitted with the fewest control points that keep within `tol`, with its
/// error; in the ellipse's frame moved to `centre`.
pub fn offset_curve(
    a: f64,
    b: f64,
    d: f64,
    tol: f64,
    centre: [f64; 2],
) -> Result<(Curve, f64), String> {
    if d < 0.0 && -d >= b.min(a) * b.min(a) / b.max(a) {
        return Err(format!(
            "an inward offset of {} mm is not less than the ellipse's smallest radius of curvature, {} mm (min(a,b)²/max(a,b)): its offset has cusps, no tool of that radius follows it",
            -d,
            b.min(a) * b.min(a) / b.max(a)
        ));
    }
    let meets = |n: usize| -> Option<(Curve, f64)> {
        let c = fit(a, b, d, n)?;
        let e = fit_error(&c, a, b, d);
        (e <= tol).then_some((c, e))
    };
    // Doubling to a count that meets the tolerance, then bisection below it.
    let (mut lo, mut hi) = (7, 8);
    let mut best = loop {
        if let Some(found) = meets(hi) {
            break found;
        }
        if hi == MAX_CTRL {
            return Err(format!(
                "no fit with up to {MAX_CTRL} control points comes within {tol} mm of the offset: raise --tolerance"
            ));
        }
        lo = hi;
        hi = (2 * hi).min(MAX_CTRL);
    };
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        match meets(mid) {
            Some(found) => {
                best = found;
                hi = mid;
            }
            None => lo = mid,
        }
    }
    let (mut c, e) = best;
    for p in &mut c.ctrl {
        p[0] += centre[0];
        p[1] += centre[1];
    }
    Ok((c, e))
}

/// The program for `job`, and a line for the user on what was fitted.
pub fn ellipse_program(job: &EllipseJob) -> Result<(String, String), String> {
    let axes = 1e-3..=crate::program::MAX_POSITION_MM;
    if !(axes.contains(&job.a) && axes.contains(&job.b)) {
        return Err(format!(
            "--a and --b (the semi-axes) must be from {} to {} mm",
            axes.start(),
            axes.end()
        ));
    }
    if job.tolerance.is_nan() || job.tolerance <= 0.0 {
        return Err("--tolerance must be positive".into());
    }
    if job.feed.is_nan() || job.feed <= 0.0 {
        return Err("--feed must be positive".into());
    }
    if ![
        job.offset,
        job.depth,
        job.feed,
        job.centre[0],
        job.centre[1],
    ]
    .iter()
    .all(|v| v.is_finite())
    {
        return Err("--offset, --depth, --feed and --centre must be finite numbers".into());
    }
    if job.offset == 0.0 {
        let c = ellipse(job.a, job.b, job.centre);
        let what = format!(
            "ellipse a = {} mm, b = {} mm, centre X{} Y{}: exact, a rational quadratic NURBS\nwritten by cnc cam ellipse",
            job.a, job.b, job.centre[0], job.centre[1]
        );
        let summary = format!(
            "exact ellipse: {} control points of degree 2, no fitting error",
            c.ctrl.len()
        );
        return Ok((program(&job.cut(), &what, &[Cut::whole(c)]), summary));
    }
    let (c, e) = offset_curve(job.a, job.b, job.offset, job.tolerance, job.centre)?;
    let what = format!(
        "offset {} mm of the ellipse a = {} mm, b = {} mm, centre X{} Y{}\nfitted: {} control points of degree 3, at most {:.3e} mm from the true offset, tolerance {} mm\nwritten by cnc cam ellipse",
        job.offset, job.a, job.b, job.centre[0], job.centre[1], c.ctrl.len(), e, job.tolerance
    );
    let summary = format!(
        "offset {} mm: {} control points of degree 3, at most {:.3e} mm from the true offset (tolerance {} mm)",
        job.offset,
        c.ctrl.len(),
        e,
        job.tolerance
    );
    Ok((program(&job.cut(), &what, &[Cut::whole(c)]), summary))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The NURBS ellipse lies on `x²/a² + y²/b² = 1` everywhere (closed form), to a few
    /// roundings.
    #[test]
    fn the_ellipse_is_exact() {
        let (a, b) = (90.0, 60.0);
        let c = ellipse(a, b, [0.0, 0.0]);
        for k in 0..=4000 {
            let u = 4.0 * k as f64 / 4000.0;
            let p = point(&c, u);
            let f = (p[0] / a).powi(2) + (p[1] / b).powi(2);
            assert!((f - 1.0).abs() < 1e-14, "u {u}: {f}");
        }
    }

    /// The offset's closed form against a numerical one: the point `d` along the unit
    /// normal of the ellipse, and the derivative against a difference.
    #[test]
    fn the_offset_is_the_normal_displaced_point() {
        let (a, b, d) = (5.0, 3.0, 1.0);
        for k in 0..100 {
            let t = TAU * k as f64 / 100.0;
            let (p, dp) = offset_at(a, b, d, t);
            let (e, de) = ([a * t.cos(), b * t.sin()], [-a * t.sin(), b * t.cos()]);
            let l = de[0].hypot(de[1]);
            let n = [de[1] / l, -de[0] / l];
            assert!(
                (p[0] - e[0] - d * n[0]).abs() < 1e-14 && (p[1] - e[1] - d * n[1]).abs() < 1e-14
            );
            let h = 1e-6;
            let (p1, _) = offset_at(a, b, d, t + h);
            let (p0, _) = offset_at(a, b, d, t - h);
            for i in 0..2 {
                assert!((dp[i] - (p1[i] - p0[i]) / (2.0 * h)).abs() < 1e-7);
            }
        }
    }

    /// Seed 004's case (a = 5, b = 3, offset 1): within the default 0.1 µm, measured by
    /// a second, brute-force search (the fitted curve sampled 3 000 times, each point's
    /// nearest of 30 000 points of the true offset refined by Newton's method).
    #[test]
    fn the_seed_s_offset_fits_within_a_tenth_of_a_micrometre() {
        let (a, b, d, tol) = (5.0, 3.0, 1.0, 1e-4);
        let (c, e) = offset_curve(a, b, d, tol, [0.0, 0.0]).unwrap();
        assert!(e <= tol, "{e}");
        let spans = c.knots[c.knots.len() - 1];
        let dense: Vec<[f64; 2]> = (0..30_000)
            .map(|k| offset_at(a, b, d, TAU * k as f64 / 30_000.0).0)
            .collect();
        let mut worst = 0.0f64;
        for k in 0..3_000 {
            let p = point(&c, spans * k as f64 / 3_000.0);
            let (i, _) = dense
                .iter()
                .enumerate()
                .map(|(i, q)| (i, (q[0] - p[0]).hypot(q[1] - p[1])))
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .unwrap();
            let t0 = TAU * i as f64 / 30_000.0;
            worst = worst.max(distance_to_offset(a, b, d, p, t0));
        }
        assert!(worst <= tol * 1.001, "{worst} against {e}");
        // One fewer control point does not meet the tolerance.
        let fewer = fit(a, b, d, c.ctrl.len() - 1).unwrap();
        assert!(fit_error(&fewer, a, b, d) > tol);
    }
}
