//! The evaluators never allocate: a counting global allocator watches a million curve
//! evaluations (every degree 1..=9, forward steps across every knot, jumps back and far
//! ahead) and 1.5 million surface evaluations (both pass settings and the any-path evaluator,
//! zig-zag and random points), after construction.

use shared::alloc_count::{arm, count, Counting};
use shared::nurbs::fast::FastCurve;
use shared::nurbs::surface::{FastSurface, Passes, SurfaceData};

#[global_allocator]
static GLOBAL: Counting = Counting;

fn clamped(degree: usize, n: usize) -> Vec<f64> {
    let interior = n - degree - 1;
    let mut k = vec![0.0; degree + 1];
    k.extend((1..=interior).map(|i| i as f64 / (interior + 1) as f64));
    k.extend(std::iter::repeat_n(1.0, degree + 1));
    k
}

/// A cheap deterministic sequence in [0, 1) (no allocation, no library).
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

#[test]
fn a_million_evaluations_allocate_nothing() {
    let n = 20;
    let mut curves = Vec::new();
    for degree in 1..=9 {
        let ctrl: Vec<[f64; 4]> = (0..n)
            .map(|i| {
                let t = i as f64;
                [
                    t,
                    (0.7 * t).sin(),
                    (0.3 * t).cos(),
                    1.0 + 0.5 * (1.3 * t).sin(),
                ]
            })
            .collect();
        curves.push(FastCurve::new(degree, &clamped(degree, n), &ctrl).expect("valid curve"));
    }
    let knots = clamped(3, 10);
    let net: Vec<[f64; 4]> = (0..100)
        .map(|k| {
            let (i, j) = ((k / 10) as f64, (k % 10) as f64);
            [
                i,
                j,
                (0.5 * i).sin() * (0.4 * j).cos(),
                1.0 + 0.1 * (i - j).abs(),
            ]
        })
        .collect();
    let data = SurfaceData {
        degree_u: 3,
        degree_v: 3,
        knots_u: &knots,
        knots_v: &knots,
        n_u: 10,
        n_v: 10,
        ctrl: &net,
    };
    let mut surfaces = [
        FastSurface::with_passes(&data, Passes::AlongU).expect("valid surface"),
        FastSurface::with_passes(&data, Passes::AlongV).expect("valid surface"),
        FastSurface::for_any_path(&data).expect("valid surface"),
    ];

    let before = count();
    arm(true);
    let mut acc = 0.0;
    let mut rng = 1u64;
    let per_curve = 1_000_000 / curves.len() + 1;
    for c in &mut curves {
        for k in 0..per_curve {
            // Mostly forward steps; every 1000th point a random jump (back or ahead).
            let u = if k % 1000 == 999 {
                lcg(&mut rng) * 1.2 - 0.1
            } else {
                (k % 1000) as f64 / 999.0
            };
            let e = c.eval(u);
            acc += e.p[0] + e.d1[1] + e.d2[2];
        }
    }
    for s in &mut surfaces {
        for k in 0..500_000 {
            let (u, v) = if k % 2 == 0 {
                ((k / 1000) as f64 / 499.0, (k % 1000) as f64 / 999.0)
            } else {
                (lcg(&mut rng), lcg(&mut rng))
            };
            let e = s.eval(u, v);
            acc += e.p[0] + e.du[1] + e.dv[2] + e.normal[2];
        }
    }
    arm(false);
    let allocs = count() - before;
    assert!(acc.is_finite());
    assert_eq!(allocs, 0, "{allocs} allocations in 2.5 million evaluations");
}
