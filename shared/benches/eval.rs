//! Per-point cost of NURBS evaluation: the extended-space evaluator with moving data
//! (`shared::nurbs::fast`, `shared::nurbs::surface`) against the standard span search +
//! triangular table (The NURBS Book A2.2/A2.3: `shared::nurbs::eval` for curves,
//! `reference::piegl_tiller_surface` for surfaces) and the conventional Cox–de Boor method
//! the seeds compare against (`reference::conventional_*`).
//!
//! * `curve_eval/p{1,2,3,4,5,9}`: a rational curve with 12 control points, point + first +
//!   second derivative, stepping through the whole parameter range in 10 000 increasing
//!   steps per iteration (the evaluator persists across iterations, so each iteration
//!   starts with one jump back to the start, as a new block would). Functions:
//!   `extended` (what the interpolator runs: moving data holding the span's power form),
//!   `extended_recurrence` (the seed's literal per-point recurrence on the same moving
//!   data), `piegl_tiller`, `conventional`, and `curvo` (the `curvo` crate's
//!   `NurbsCurve3D::rational_derivatives(u, 2)`, which gives exactly point, first and
//!   second derivative; it searches the span and allocates its result vectors on every
//!   call, which is part of what is measured).
//! * `surface_eval/p2q2`, `surface_eval/p3q3`: the seed's 10x10 rational surface,
//!   `(S, S_u, S_v)` plus the unit normal along a zig-zag of 100 rows of 100 points, `u`
//!   fixed in each row. `extended` is the evaluator set up for that path
//!   ([`Passes::AlongV`]: it keeps the partial sums over `u` through a row, and the row
//!   through the current `v` span as polynomials in `v`); `extended_no_reuse` is the
//!   evaluator made by [`FastSurface::for_any_path`], so it keeps nothing between points:
//!   the cost on a path that holds neither parameter fixed.
//!
//! The conventional method is so slow that it runs on every tenth point only (1 000 per
//! iteration); the throughput figures (elements per second) stay per point, so compare
//! those, or the times divided by the element counts. Run:
//! `cargo bench -p shared --bench eval`.

use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use curvo::prelude::NurbsCurve3D;
use nalgebra::Point4;
use shared::nurbs::fast::FastCurve;
use shared::nurbs::reference::{conventional_curve, conventional_surface, piegl_tiller_surface};
use shared::nurbs::surface::{FastSurface, Passes, SurfaceData};
use shared::nurbs::{eval, CurvePoint};

const STEPS: usize = 10_000;
const CONVENTIONAL_STRIDE: usize = 10;

struct Curve {
    degree: usize,
    knots: Vec<f64>,
    ctrl: Vec<[f64; 4]>,
}

/// 12 control points on a wavy 3D path, weights between 0.5 and 2, clamped uniform knots.
fn curve(degree: usize) -> Curve {
    let n = 12;
    let ctrl = (0..n)
        .map(|i| {
            let t = i as f64;
            [
                10.0 * t,
                20.0 * (0.9 * t).sin(),
                5.0 * (0.4 * t).cos(),
                1.25 + 0.75 * (1.7 * t).sin(),
            ]
        })
        .collect();
    let interior = n - degree - 1;
    let mut knots = vec![0.0; degree + 1];
    knots.extend((1..=interior).map(|i| i as f64 / (interior + 1) as f64));
    knots.extend(std::iter::repeat_n(1.0, degree + 1));
    Curve {
        degree,
        knots,
        ctrl,
    }
}

fn params(count: usize) -> Vec<f64> {
    (0..count).map(|k| k as f64 / (count - 1) as f64).collect()
}

/// Folds a result into one number so the optimiser cannot drop the evaluation.
fn fold(e: &CurvePoint) -> f64 {
    e.p[0] + e.d1[1] + e.d2[2]
}

/// The same curve as a `curvo` NURBS (homogeneous control points `[w·x, w·y, w·z, w]`,
/// as curvo stores them), checked against ours at a few parameters before it is timed so
/// the comparison is of equal work and equal answers.
fn curvo_curve(cv: &Curve) -> NurbsCurve3D<f64> {
    let pts = cv
        .ctrl
        .iter()
        .map(|c| Point4::new(c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]))
        .collect();
    let other = NurbsCurve3D::try_new(cv.degree, pts, cv.knots.clone()).expect("curvo curve");
    for u in [0.0, 0.123, 0.5, 0.77, 1.0] {
        let ours = eval(cv.degree, &cv.knots, &cv.ctrl, u);
        let d = other.rational_derivatives(u, 2);
        for (k, want) in [ours.p, ours.d1, ours.d2].iter().enumerate() {
            for i in 0..3 {
                let err = (d[k][i] - want[i]).abs() / want[i].abs().max(100.0);
                assert!(err < 1e-9, "curvo disagrees at u = {u}, derivative {k}");
            }
        }
    }
    other
}

fn curve_eval(c: &mut Criterion) {
    for degree in [1, 2, 3, 4, 5, 9] {
        let cv = curve(degree);
        let us = params(STEPS);
        let mut g = c.benchmark_group(format!("curve_eval/p{degree}"));
        g.throughput(Throughput::Elements(STEPS as u64));
        let mut fast = FastCurve::new(cv.degree, &cv.knots, &cv.ctrl).expect("valid curve");
        g.bench_function("extended", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &u in &us {
                    acc += fold(&fast.eval(black_box(u)));
                }
                acc
            })
        });
        let mut literal = FastCurve::new(cv.degree, &cv.knots, &cv.ctrl).expect("valid curve");
        g.bench_function("extended_recurrence", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &u in &us {
                    acc += fold(&literal.eval_recurrence(black_box(u)));
                }
                acc
            })
        });
        g.bench_function("piegl_tiller", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &u in &us {
                    acc += fold(&eval(cv.degree, &cv.knots, &cv.ctrl, black_box(u)));
                }
                acc
            })
        });
        let other = curvo_curve(&cv);
        g.bench_function("curvo", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &u in &us {
                    let d = other.rational_derivatives(black_box(u), 2);
                    acc += d[0][0] + d[1][1] + d[2][2];
                }
                acc
            })
        });
        let few: Vec<f64> = us.iter().step_by(CONVENTIONAL_STRIDE).copied().collect();
        g.throughput(Throughput::Elements(few.len() as u64));
        g.sample_size(10);
        g.bench_function("conventional", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &u in &few {
                    acc += fold(&conventional_curve(
                        cv.degree,
                        &cv.knots,
                        &cv.ctrl,
                        black_box(u),
                    ));
                }
                acc
            })
        });
        g.finish();
    }
}

struct Surf {
    degree: usize,
    knots: Vec<f64>,
    ctrl: Vec<[f64; 4]>,
}

impl Surf {
    fn data(&self) -> SurfaceData<'_> {
        SurfaceData {
            degree_u: self.degree,
            degree_v: self.degree,
            knots_u: &self.knots,
            knots_v: &self.knots,
            n_u: 10,
            n_v: 10,
            ctrl: &self.ctrl,
        }
    }
}

/// The seed's case (seed 000 §4): 10x10 control points, uniform clamped knots (0.125
/// apart at degree 2), here with weights in 0.5..2 so the rational part costs what it
/// costs in general.
fn surface(degree: usize) -> Surf {
    let interior = 10 - degree - 1;
    let mut knots = vec![0.0; degree + 1];
    knots.extend((1..=interior).map(|i| i as f64 / (interior + 1) as f64));
    knots.extend(std::iter::repeat_n(1.0, degree + 1));
    let mut ctrl = Vec::new();
    for i in 0..10 {
        for j in 0..10 {
            let (x, y) = (10.0 * i as f64, 10.0 * j as f64);
            let z = 5.0 * (0.7 * i as f64).sin() * (0.5 * j as f64).cos();
            ctrl.push([
                x,
                y,
                z,
                1.25 + 0.75 * (1.3 * i as f64 + 0.4 * j as f64).sin(),
            ]);
        }
    }
    Surf {
        degree,
        knots,
        ctrl,
    }
}

/// 100 rows of 100 points: `u` steps per row, `v` runs up and down alternately.
fn zigzag() -> Vec<(f64, f64)> {
    let n = 100;
    let mut out = Vec::with_capacity(n * n);
    for i in 0..n {
        for jj in 0..n {
            let j = if i % 2 == 0 { jj } else { n - 1 - jj };
            out.push((i as f64 / (n - 1) as f64, j as f64 / (n - 1) as f64));
        }
    }
    out
}

fn surface_eval(c: &mut Criterion) {
    let path = zigzag();
    for degree in [2, 3] {
        let s = surface(degree);
        let data = s.data();
        let mut g = c.benchmark_group(format!("surface_eval/p{degree}q{degree}"));
        g.throughput(Throughput::Elements(path.len() as u64));
        // The zig-zag holds u fixed in each pass.
        for (name, passes) in [
            ("extended", Some(Passes::AlongV)),
            ("extended_no_reuse", None),
        ] {
            let mut fast = match passes {
                Some(passes) => FastSurface::with_passes(&data, passes),
                None => FastSurface::for_any_path(&data),
            }
            .expect("valid surface");
            g.bench_function(name, |b| {
                b.iter(|| {
                    let mut acc = 0.0;
                    for &(u, v) in &path {
                        let e = fast.eval(black_box(u), black_box(v));
                        acc += e.p[0] + e.du[1] + e.dv[2] + e.normal[2];
                    }
                    acc
                })
            });
        }
        g.bench_function("piegl_tiller", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &(u, v) in &path {
                    let e = piegl_tiller_surface(&data, black_box(u), black_box(v));
                    acc += e.p[0] + e.du[1] + e.dv[2] + e.normal[2];
                }
                acc
            })
        });
        let few: Vec<(f64, f64)> = path.iter().step_by(CONVENTIONAL_STRIDE).copied().collect();
        g.throughput(Throughput::Elements(few.len() as u64));
        g.sample_size(10);
        g.bench_function("conventional", |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &(u, v) in &few {
                    let e = conventional_surface(&data, black_box(u), black_box(v));
                    acc += e.p[0] + e.du[1] + e.dv[2] + e.normal[2];
                }
                acc
            })
        });
        g.finish();
    }
}

criterion_group!(benches, curve_eval, surface_eval);
criterion_main!(benches);
