//! The planned paths against independent references:
//!
//! * contact points: the planner's second-order evaluator and the cycle's
//!   [`FastSurface`] at the path's `(u, v)` against the conventional method of seed 000
//!   (`shared::nurbs::reference::conventional_surface`), and on the torus patch against
//!   the torus equation itself; 1e-9 mm;
//! * scallop height: measured numerically from the balls swept along two neighbouring
//!   passes (the ridge height along the surface normal between them, found by bisection
//!   and golden-section searches on the standard evaluator), never from the spacing
//!   formula; it must stay within the strategy's tolerance.

use super::*;
use crate::step::read_part;
use shared::nurbs::reference::{conventional_surface, piegl_tiller_surface};
use shared::nurbs::surface::{FastSurface, SurfaceData};

const SEED: &str = include_str!("../../../examples/seed-surface.stp");
const TORUS: &str = include_str!("../../../examples/torus-patch.stp");
const CUBIC: &str = include_str!("../../../examples/cubic-wave.stp");

fn step_of(text: &str) -> FreeformStep {
    read_part(text).unwrap().remove(0)
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]])
}

/// Points along every pass, as `(u, v)`.
fn path_uv(path: &SurfacePath, per_pass: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    for p in &path.passes {
        for k in 0..=per_pass {
            let a = p.from + (p.to - p.from) * k as f64 / per_pass as f64;
            out.push(path.uv(a, p.fixed));
        }
    }
    out
}

fn contact_points_agree(text: &str) -> f64 {
    let step = step_of(text);
    let path = plan(&step).unwrap();
    let s = step.surface.data();
    let mut fast = if s.n_u <= 16 && s.n_v <= 16 {
        Some(FastSurface::with_passes(&s, path.passes_along).unwrap())
    } else {
        None
    };
    let mut worst: f64 = 0.0;
    for (u, v) in path_uv(&path, 40) {
        let reference = conventional_surface(&s, u, v).p;
        worst = worst.max(dist(eval2(&s, u, v).p, reference));
        if let Some(f) = fast.as_mut() {
            worst = worst.max(dist(f.eval(u, v).p, reference));
        }
    }
    worst
}

#[test]
fn contact_points_lie_on_the_surface() {
    for text in [SEED, TORUS, CUBIC] {
        let worst = contact_points_agree(text);
        eprintln!("contact points vs the conventional method: {worst:e} mm");
        assert!(
            worst < 1e-9,
            "contact point off the surface by {worst:e} mm"
        );
    }
}

#[test]
fn torus_contact_points_satisfy_the_torus_equation() {
    let step = step_of(TORUS);
    let path = plan(&step).unwrap();
    let s = step.surface.data();
    let pl = &step.surface.workpiece;
    let (big, small) = (40.0, 15.0);
    let mut worst: f64 = 0.0;
    for (u, v) in path_uv(&path, 40) {
        let p = eval2(&s, u, v).p;
        // Back into the torus's own frame: rot^T (p - origin).
        let d = [
            p[0] - pl.origin[0],
            p[1] - pl.origin[1],
            p[2] - pl.origin[2],
        ];
        let l: Vec<f64> = (0..3)
            .map(|c| (0..3).map(|r| pl.rot[r][c] * d[r]).sum())
            .collect();
        let rho = (l[0] * l[0] + l[1] * l[1]).sqrt();
        let off = ((rho - big).powi(2) + l[2] * l[2]).sqrt() - small;
        worst = worst.max(off.abs());
    }
    eprintln!("torus contact points off the torus by at most {worst:e} mm");
    assert!(worst < 1e-9, "torus point off by {worst:e} mm");
}

#[test]
fn second_derivatives_match_finite_differences() {
    let step = step_of(TORUS);
    let s = step.surface.data();
    let h = 1e-5;
    for &(u, v) in &[(0.3, 0.4), (0.71, 0.12), (0.5, 0.93)] {
        let d = eval2(&s, u, v);
        let du_p = eval2(&s, u + h, v);
        let du_m = eval2(&s, u - h, v);
        let dv_p = eval2(&s, u, v + h);
        let dv_m = eval2(&s, u, v - h);
        for x in 0..3 {
            let suu = (du_p.su[x] - du_m.su[x]) / (2.0 * h);
            let svv = (dv_p.sv[x] - dv_m.sv[x]) / (2.0 * h);
            let suv = (dv_p.su[x] - dv_m.su[x]) / (2.0 * h);
            assert!((suu - d.suu[x]).abs() < 1e-5 * (1.0 + suu.abs()));
            assert!((svv - d.svv[x]).abs() < 1e-5 * (1.0 + svv.abs()));
            assert!((suv - d.suv[x]).abs() < 1e-5 * (1.0 + suv.abs()));
        }
        let r = piegl_tiller_surface(&s, u, v);
        assert!(dist(r.du, d.su) < 1e-9 && dist(r.dv, d.sv) < 1e-9);
    }
}

/// The tool ball centre for the contact point at `(u, v)`.
fn centre(s: &SurfaceData<'_>, path: &SurfacePath, u: f64, v: f64) -> [f64; 3] {
    let e = piegl_tiller_surface(s, u, v);
    let n = e.normal;
    let (r, k) = (path.radius_mm, path.normal_sign);
    [
        e.p[0] + k * r * n[0],
        e.p[1] + k * r * n[1],
        e.p[2] + k * r * n[2],
    ]
}

fn golden_min(mut lo: f64, mut hi: f64, iters: usize, f: impl Fn(f64) -> f64) -> f64 {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..iters {
        if f1 < f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - g * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + g * (hi - lo);
            f2 = f(x2);
        }
    }
    f1.min(f2)
}

/// Height of the material left above the surface point at pass coordinates `(a, b)`,
/// along the normal there, by the ball swept along the pass at `fixed`.
fn left_by_pass(s: &SurfaceData<'_>, path: &SurfacePath, a: f64, b: f64, fixed: f64) -> f64 {
    let (u, v) = path.uv(a, b);
    let q = piegl_tiller_surface(s, u, v);
    let n = q.normal.map(|x| x * path.normal_sign);
    let (a0, a1) = (
        path.passes[0].from.min(path.passes[0].to),
        path.passes[0].from.max(path.passes[0].to),
    );
    let speed = {
        let e = piegl_tiller_surface(s, u, v);
        match path.passes_along {
            Passes::AlongU => norm(e.du),
            Passes::AlongV => norm(e.dv),
        }
    };
    let reach = 3.0 * path.radius_mm / speed.max(1e-9);
    let (lo, hi) = ((a - reach).max(a0), (a + reach).min(a1));
    // Signed clearance of the point t above Q from the swept ball.
    let gap = |t: f64| {
        let x = [q.p[0] + t * n[0], q.p[1] + t * n[1], q.p[2] + t * n[2]];
        golden_min(lo, hi, 50, |aa| {
            let (uu, vv) = path.uv(aa, fixed);
            dist(x, centre(s, path, uu, vv))
        }) - path.radius_mm
    };
    let (mut t0, mut t1) = (0.0, 1.0);
    if gap(t0) <= 0.0 {
        return 0.0;
    }
    if gap(t1) > 0.0 {
        return t1;
    }
    for _ in 0..40 {
        let t = 0.5 * (t0 + t1);
        if gap(t) > 0.0 {
            t0 = t;
        } else {
            t1 = t;
        }
    }
    0.5 * (t0 + t1)
}

/// The scallop between passes `k` and `k + 1` at the along parameter `a`: the ridge,
/// the highest point of what both balls leave, searched across the strip.
fn scallop_between(s: &SurfaceData<'_>, path: &SurfacePath, k: usize, a: f64) -> f64 {
    let (b0, b1) = (path.passes[k].fixed, path.passes[k + 1].fixed);
    let h = |b: f64| left_by_pass(s, path, a, b, b0).min(left_by_pass(s, path, a, b, b1));
    -golden_min(b0.min(b1), b0.max(b1), 30, |b| -h(b))
}

fn measured_scallop(text: &str) -> (f64, f64, f64) {
    let step = step_of(text);
    let path = plan(&step).unwrap();
    let s = step.surface.data();
    let n = path.passes.len();
    assert!(n >= 3, "{n} passes");
    let (a0, a1) = (path.passes[0].from, path.passes[0].to);
    let mut worst: f64 = 0.0;
    let pairs = 5.min(n - 1);
    for i in 0..pairs {
        let k = i * (n - 2) / (pairs - 1).max(1);
        for f in [0.13, 0.41, 0.77] {
            let a = a0 + (a1 - a0) * f;
            worst = worst.max(scallop_between(&s, &path, k, a));
        }
    }
    (worst, step.strategy.scallop_mm(), path.predicted_scallop_mm)
}

#[test]
fn measured_scallop_stays_within_tolerance() {
    for (name, text) in [("seed", SEED), ("torus", TORUS), ("cubic", CUBIC)] {
        let (measured, tol, predicted) = measured_scallop(text);
        eprintln!(
            "{name}: measured scallop {:.3} um, predicted {:.3} um, tolerance {:.3} um",
            measured * 1e3,
            predicted * 1e3,
            tol * 1e3
        );
        assert!(measured <= tol, "{name}: scallop {measured} mm > {tol} mm");
        // Not wastefully fine either: the spacing uses the tolerance.
        assert!(
            measured > 0.5 * tol,
            "{name}: scallop {measured} mm, far below {tol} mm"
        );
    }
}

#[test]
fn passes_cover_the_domain_in_order_and_alternate_in_zigzag() {
    let step = step_of(SEED);
    let path = plan(&step).unwrap();
    let first = path.passes[0];
    let last = path.passes[path.passes.len() - 1];
    assert_eq!((first.fixed, last.fixed), (0.0, 1.0));
    assert!(path.passes.windows(2).all(|w| w[1].fixed > w[0].fixed));
    assert!(path.passes.windows(2).all(|w| w[0].to == w[1].from));
    assert!(path.max_spacing_mm > 0.3 && path.max_spacing_mm < 1.2);
    // Forward, decreasing sideward, along v: the cubic example.
    let c = plan(&step_of(CUBIC)).unwrap();
    assert_eq!(c.passes_along, Passes::AlongV);
    assert_eq!(c.passes[0].fixed, 1.0);
    assert!(c.passes.windows(2).all(|w| w[1].fixed < w[0].fixed));
    assert!(c.passes.iter().all(|p| p.from == 0.0 && p.to == 1.0));
}

#[test]
fn the_stepover_cap_limits_the_spacing() {
    let mut step = step_of(SEED);
    if let crate::step::Strategy::Uv(st) = &mut step.strategy {
        st.stepover_mm = Some(0.25);
    }
    let path = plan(&step).unwrap();
    assert!(
        path.max_spacing_mm <= 0.25 * (1.0 + 1e-6),
        "{}",
        path.max_spacing_mm
    );
}

#[test]
fn a_ball_too_large_for_a_concave_section_is_a_gouge_error() {
    let mut step = step_of(CUBIC);
    step.tool.diameter_mm = 200.0;
    let e = plan(&step).unwrap_err();
    assert_eq!(e.rule, "gouge", "{e:?}");
    assert_eq!(e.id, Some(step.id));
}
