//! The fast curve evaluator against both references ([`super::super::eval`], the standard
//! A2.2/A2.3 algorithm, and the conventional Cox–de Boor method of
//! [`super::super::reference`]), against itself (stepping, jumps and fresh evaluators must
//! agree bit for bit), and against the closed form of the circle.
//!
//! Tolerances, as the issue states them: positions agree to 1e-12 and derivatives to 1e-9,
//! relative to the larger of the reference value's magnitude and the size of the control
//! polygon (so a derivative that happens to be near zero is not held to an absolute 1e-21).

use super::*;
use crate::nurbs::eval;
use crate::nurbs::reference::{conventional_curve, piegl_tiller_curve};
use crate::protocol::{BlockKind, CommandBlock};
use proptest::prelude::*;

#[derive(Debug, Clone)]
struct Curve {
    degree: usize,
    knots: Vec<f64>,
    ctrl: Vec<[f64; 4]>,
}

impl Curve {
    fn domain(&self) -> (f64, f64) {
        (self.knots[self.degree], self.knots[self.ctrl.len()])
    }
    /// The largest control-point coordinate: the length scale of the curve.
    fn scale(&self) -> f64 {
        self.ctrl
            .iter()
            .flat_map(|c| c[..3].iter())
            .fold(1.0f64, |a, b| a.max(b.abs()))
    }
    /// Parameters worth testing: every knot, the ends, points just outside, and `ts`.
    fn params(&self, ts: &[f64]) -> Vec<f64> {
        let (lo, hi) = self.domain();
        let mut us: Vec<f64> = ts.iter().map(|t| lo + t * (hi - lo)).collect();
        us.extend_from_slice(&self.knots);
        us.extend_from_slice(&[lo - 1.0, hi + 1.0, lo, hi]);
        us
    }
}

/// Random clamped rational curve of degree `1..=max_degree` with interior knots that may
/// repeat (up to multiplicity `p`, C^0), weights in 0.2..5, coordinates in ±100 mm.
fn random_curve(max_degree: usize) -> impl Strategy<Value = Curve> {
    (1usize..=max_degree)
        .prop_flat_map(|p| (Just(p), 0usize..=(MAX_CTRL - 1 - p).min(14)))
        .prop_flat_map(|(p, extra)| {
            let pt = (
                -100.0f64..100.0,
                -100.0f64..100.0,
                -100.0f64..100.0,
                0.2f64..5.0,
            );
            let gap = prop_oneof![3 => 0.05f64..2.0, 1 => Just(0.0)];
            (
                Just(p),
                proptest::collection::vec(pt, p + 1 + extra),
                proptest::collection::vec(gap, extra + 1),
                -10.0f64..10.0,
            )
        })
        .prop_map(|(p, ctrl, gaps, start)| {
            let mut knots = vec![start; p + 1];
            let (mut t, mut run) = (start, 0);
            let last = gaps.len() - 1;
            for (i, &g) in gaps.iter().enumerate() {
                // The first and last gaps stay open so the end knots keep multiplicity
                // p + 1; interior runs stop at multiplicity p.
                let g = if g == 0.0 && (i == 0 || i == last || run + 1 >= p) {
                    0.5
                } else {
                    g
                };
                run = if g == 0.0 { run + 1 } else { 0 };
                t += g;
                if i == last {
                    knots.extend(std::iter::repeat_n(t, p + 1));
                } else {
                    knots.push(t);
                }
            }
            let ctrl = ctrl.into_iter().map(|(x, y, z, w)| [x, y, z, w]).collect();
            Curve {
                degree: p,
                knots,
                ctrl,
            }
        })
}

fn max_abs(v: [f64; 3]) -> f64 {
    v.iter().fold(0.0f64, |a, b| a.max(b.abs()))
}

fn max_diff(a: [f64; 3], b: [f64; 3]) -> f64 {
    max_abs([a[0] - b[0], a[1] - b[1], a[2] - b[2]])
}

/// `None` when `got` agrees with `want` to the tolerances, else what differs.
fn mismatch(got: &CurvePoint, want: &CurvePoint, scale: f64) -> Option<String> {
    let checks = [
        ("p", got.p, want.p, 1e-12),
        ("d1", got.d1, want.d1, 1e-9),
        ("d2", got.d2, want.d2, 1e-9),
    ];
    for (name, g, w, tol) in checks {
        let err = max_diff(g, w) / max_abs(w).max(scale);
        if err > tol || err.is_nan() {
            return Some(format!("{name}: {g:?} vs {w:?} (relative {err:e})"));
        }
    }
    if got.span != want.span {
        return Some(format!("span {} vs {}", got.span, want.span));
    }
    None
}

fn fresh(c: &Curve, u: f64) -> CurvePoint {
    match FastCurve::new(c.degree, &c.knots, &c.ctrl) {
        Ok(mut f) => f.eval(u),
        Err(e) => panic!("valid curve rejected: {e}"),
    }
}

fn fast(c: &Curve) -> FastCurve {
    FastCurve::new(c.degree, &c.knots, &c.ctrl).expect("valid curve")
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn fast_matches_both_references(c in random_curve(MAX_DEGREE),
                                    ts in proptest::collection::vec(0.0f64..=1.0, 8)) {
        let mut f = fast(&c);
        let mut literal = fast(&c);
        for u in c.params(&ts) {
            let got = f.eval(u);
            let standard = eval(c.degree, &c.knots, &c.ctrl, u);
            let conventional = conventional_curve(c.degree, &c.knots, &c.ctrl, u);
            let a23 = piegl_tiller_curve(c.degree, &c.knots, &c.ctrl, u);
            for (name, want) in [("standard", standard), ("conventional", conventional), ("A2.3", a23)] {
                if let Some(m) = mismatch(&got, &want, c.scale()) {
                    prop_assert!(false, "p = {} u = {u} vs {name}: {m}", c.degree);
                }
                // The seed's per-point recurrence, kept beside the power form, too.
                if let Some(m) = mismatch(&literal.eval_recurrence(u), &want, c.scale()) {
                    prop_assert!(false, "recurrence, p = {} u = {u} vs {name}: {m}", c.degree);
                }
            }
        }
    }

    /// Increasing parameters (with every knot hit exactly), then random jumps back and
    /// forth: the moving registers must give the bits a fresh evaluator gives.
    #[test]
    fn stepping_and_jumps_equal_fresh_evaluations(
        c in random_curve(MAX_DEGREE),
        ts in proptest::collection::vec(0.0f64..=1.0, 1..120),
        jumps in proptest::collection::vec(-0.1f64..=1.1, 1..40),
    ) {
        let mut us = c.params(&ts);
        us.sort_by(f64::total_cmp);
        let mut f = fast(&c);
        let mut baseline = fast(&c);
        for &u in &us {
            let got = f.eval(u);
            prop_assert_eq!(got, fresh(&c, u), "forward step to u = {}", u);
            // The AVX2 kernels and the baseline ones: the same operations, the same bits.
            prop_assert_eq!(got, baseline.eval_baseline(u), "baseline kernel at u = {}", u);
        }
        let (lo, hi) = c.domain();
        for t in jumps {
            let u = lo + t * (hi - lo);
            let got = f.eval(u);
            prop_assert_eq!(got, fresh(&c, u), "jump to u = {}", u);
            let want = eval(c.degree, &c.knots, &c.ctrl, u);
            prop_assert!(mismatch(&got, &want, c.scale()).is_none(), "jump to u = {}", u);
        }
    }

    #[test]
    fn specialised_types_equal_the_dispatcher(c in random_curve(5), t in 0.0f64..=1.0) {
        let (lo, hi) = c.domain();
        let u = lo + t * (hi - lo);
        let want = fresh(&c, u);
        let (d, k, x) = (c.degree, &c.knots[..], &c.ctrl[..]);
        let got = match d {
            1 => CurveEval::<1>::new(d, k, x).map(|mut e| e.eval(u)),
            2 => CurveEval::<2>::new(d, k, x).map(|mut e| e.eval(u)),
            3 => CurveEval::<3>::new(d, k, x).map(|mut e| e.eval(u)),
            4 => CurveEval::<4>::new(d, k, x).map(|mut e| e.eval(u)),
            _ => CurveEval::<5>::new(d, k, x).map(|mut e| e.eval(u)),
        };
        prop_assert_eq!(got, Ok(want));
    }
}

/// A full circle of radius 10 mm about (3, -2, 5) from four rational quadratic arcs.
fn circle() -> Curve {
    let h = core::f64::consts::FRAC_1_SQRT_2;
    let (cx, cy, cz, r) = (3.0, -2.0, 5.0, 10.0);
    let pts = [
        (1.0, 0.0, 1.0),
        (1.0, 1.0, h),
        (0.0, 1.0, 1.0),
        (-1.0, 1.0, h),
        (-1.0, 0.0, 1.0),
        (-1.0, -1.0, h),
        (0.0, -1.0, 1.0),
        (1.0, -1.0, h),
        (1.0, 0.0, 1.0),
    ];
    Curve {
        degree: 2,
        knots: vec![
            0.0, 0.0, 0.0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1.0, 1.0, 1.0,
        ],
        ctrl: pts
            .iter()
            .map(|&(x, y, w)| [cx + r * x, cy + r * y, cz, w])
            .collect(),
    }
}

#[test]
fn circle_is_exact() {
    let c = circle();
    let mut f = fast(&c);
    let n = 100_000;
    for i in 0..=n {
        let e = f.eval(i as f64 / n as f64);
        let (x, y) = (e.p[0] - 3.0, e.p[1] + 2.0);
        let r = (x * x + y * y).sqrt();
        assert!((r - 10.0).abs() < 1e-12, "radius {r} at step {i}");
        assert!((e.p[2] - 5.0).abs() < 1e-12);
        // Tangent orthogonal to the radius, curvature 1/R: |C' x C''| / |C'|^3.
        let speed = (e.d1[0].powi(2) + e.d1[1].powi(2)).sqrt();
        assert!((x * e.d1[0] + y * e.d1[1]).abs() < 1e-12 * 10.0 * speed);
        let cross = e.d1[0] * e.d2[1] - e.d1[1] * e.d2[0];
        let kappa = cross / speed.powi(3);
        assert!((kappa - 0.1).abs() < 1e-12, "curvature {kappa} at step {i}");
    }
}

#[test]
fn block_and_slices_give_the_same_evaluator() {
    let c = circle();
    let mut block = CommandBlock::empty(BlockKind::Motion, 0, 1);
    block.degree = c.degree as u32;
    block.n_ctrl = c.ctrl.len() as u32;
    block.knots[..c.knots.len()].copy_from_slice(&c.knots);
    block.ctrl[..c.ctrl.len()].copy_from_slice(&c.ctrl);
    let mut from_block = FastCurve::from_block(&block).expect("valid block");
    let mut typed = CurveEval::<2>::from_block(&block).expect("valid block");
    let mut from_slices = fast(&c);
    for i in 0..=1000 {
        let u = i as f64 / 1000.0;
        let want = from_slices.eval(u);
        assert_eq!(from_block.eval(u), want);
        assert_eq!(typed.eval(u), want);
    }
    assert_eq!(from_block.domain(), (0.0, 1.0));
    assert_eq!(from_block.degree(), 2);
}

#[test]
fn bad_curves_are_rejected_at_construction() {
    let mut c = circle();
    c.ctrl[3][3] = 0.0;
    assert_eq!(
        FastCurve::new(c.degree, &c.knots, &c.ctrl).err(),
        Some(CurveError::WeightNotPositive { index: 3 })
    );
    let c = circle();
    assert_eq!(
        CurveEval::<3>::new(c.degree, &c.knots, &c.ctrl).err(),
        Some(FastCurveError::DegreeMismatch {
            expected: 3,
            found: 2
        })
    );
    let many = vec![[0.0, 0.0, 0.0, 1.0]; MAX_CTRL + 1];
    let mut knots = vec![0.0; 2];
    knots.extend((1..MAX_CTRL).map(|i| i as f64));
    knots.extend([MAX_CTRL as f64; 2]);
    assert!(matches!(
        FastCurve::new(1, &knots, &many),
        Err(CurveError::TooManyControlPoints { .. })
    ));
    // A failed reload keeps the previous curve.
    let mut f = fast(&circle());
    let before = f.eval(0.3);
    assert!(f.load(1, &knots, &many).is_err());
    assert_eq!(f.eval(0.3), before);
}

#[test]
fn nan_gives_nan_and_the_next_call_recovers() {
    let c = circle();
    let mut f = fast(&c);
    let bad = f.eval(f64::NAN);
    assert!(bad.p.iter().all(|x| x.is_nan()));
    assert_eq!(f.eval(0.6), fresh(&c, 0.6));
    assert_eq!(f.eval(f64::INFINITY), fresh(&c, 1.0));
    assert_eq!(f.eval(f64::NEG_INFINITY), fresh(&c, 0.0));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// The third derivative against central differences of the second, inside a span
    /// (where the curve is smooth); the point and its first two derivatives are the bits
    /// of the kernels without AVX2. Tolerance: 1e-6 of the larger of `|C'''|`, the
    /// second derivative over the span's width and the curve's size (the differences'
    /// own truncation is about 1e-10 of these at a step of 1e-5 of the span).
    #[test]
    fn third_derivative_matches_differences_of_the_second(
        c in random_curve(MAX_DEGREE),
        pick in 0usize..64,
        t in 0.1f64..0.9,
    ) {
        let spans: Vec<(f64, f64)> = c.knots.windows(2)
            .filter(|w| w[1] > w[0])
            .map(|w| (w[0], w[1]))
            .collect();
        let (lo, hi) = spans[pick % spans.len()];
        let u = lo + t * (hi - lo);
        let mut f = fast(&c);
        let (e, d3) = f.eval_d3(u);
        let base = fast(&c).eval_baseline(u);
        prop_assert_eq!(e.p.map(f64::to_bits), base.p.map(f64::to_bits));
        prop_assert_eq!(e.d1.map(f64::to_bits), base.d1.map(f64::to_bits));
        prop_assert_eq!(e.d2.map(f64::to_bits), base.d2.map(f64::to_bits));
        let h = 1e-5 * (hi - lo);
        let (a, b) = (f.eval_d3(u - h).0.d2, f.eval_d3(u + h).0.d2);
        let diff: [f64; 3] = std::array::from_fn(|k| (b[k] - a[k]) / (2.0 * h));
        let scale = max_abs(d3)
            .max(max_abs(e.d2) / (hi - lo))
            .max(c.scale());
        let err = max_diff(d3, diff) / scale;
        prop_assert!(err < 1e-6, "{:?} vs {:?}: {:e}", d3, diff, err);
    }
}

/// A polynomial cubic's third derivative is constant, `6 (P3 − 3 P2 + 3 P1 − P0)` on
/// `[0, 1]`, and a quadratic's is zero: to 1e-12 of the control points' size.
#[test]
fn third_derivative_of_polynomials_is_the_closed_form() {
    let p = [
        [1.0, -2.0, 0.5, 1.0],
        [4.0, 3.0, -1.0, 1.0],
        [-2.0, 5.0, 2.0, 1.0],
        [7.0, 1.0, -3.0, 1.0],
    ];
    let want: [f64; 3] =
        std::array::from_fn(|k| 6.0 * (p[3][k] - 3.0 * p[2][k] + 3.0 * p[1][k] - p[0][k]));
    let mut cubic = FastCurve::new(3, &[0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0], &p).unwrap();
    let mut quad = FastCurve::new(2, &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], &p[..3]).unwrap();
    for u in [0.0, 0.1, 0.37, 0.5, 0.99, 1.0] {
        let (_, d3) = cubic.eval_d3(u);
        assert!(max_diff(d3, want) < 1e-12 * 50.0, "{u}: {d3:?} vs {want:?}");
        let (_, d3) = quad.eval_d3(u);
        assert!(max_abs(d3) < 1e-12 * 50.0, "{u}: {d3:?}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// `FastCurve::load`, which the engine calls at every block's start (or ahead of it),
    /// fills the evaluator in place instead of building a new one and moving it in: it
    /// leaves every field as `FastCurve::new` builds it, whatever curve was loaded and
    /// evaluated before, so the same bits follow (compared through `Debug`, which prints
    /// every `f64` so that it reads back to the same bits).
    #[test]
    fn load_in_place_leaves_what_new_builds(
        a in random_curve(MAX_DEGREE),
        b in random_curve(MAX_DEGREE),
        ts in proptest::collection::vec(0.0f64..=1.0, 4),
    ) {
        let mut f = FastCurve::new(a.degree, &a.knots, &a.ctrl).expect("valid curve");
        for u in a.params(&ts) {
            f.eval(u);
        }
        f.load(b.degree, &b.knots, &b.ctrl).expect("valid curve");
        let mut g = FastCurve::new(b.degree, &b.knots, &b.ctrl).expect("valid curve");
        prop_assert_eq!(format!("{f:?}"), format!("{g:?}"));
        for u in b.params(&ts) {
            prop_assert_eq!(f.eval(u), g.eval(u));
        }
        prop_assert_eq!(format!("{f:?}"), format!("{g:?}"));
    }

    /// `FastCurve::load_valid` (the engine's load of a block validated at its intake)
    /// leaves the evaluator `load` leaves, and `FastCurve::new` builds, over a chain of
    /// curves whose degrees and counts rise and fall (each load writes only the slots the
    /// old or the new curve reaches: a slot the old one reached left stale fails here),
    /// each evaluated before the next is loaded; and `load`, for a curve not validated,
    /// still refuses what `validate` refuses, keeping its curve.
    #[test]
    fn load_valid_leaves_what_load_leaves(
        chain in proptest::collection::vec(random_curve(MAX_DEGREE), 2..6),
        ts in proptest::collection::vec(0.0f64..=1.0, 4),
        spoil in 0usize..4,
    ) {
        let first = &chain[0];
        let mut f = FastCurve::new(first.degree, &first.knots, &first.ctrl).expect("valid curve");
        let mut g = f.clone();
        for c in &chain[1..] {
            f.load_valid(c.degree, &c.knots, &c.ctrl).expect("valid curve");
            g.load(c.degree, &c.knots, &c.ctrl).expect("valid curve");
            let mut h = FastCurve::new(c.degree, &c.knots, &c.ctrl).expect("valid curve");
            prop_assert_eq!(format!("{f:?}"), format!("{g:?}"));
            prop_assert_eq!(format!("{f:?}"), format!("{h:?}"));
            for u in c.params(&ts) {
                let (a, b, e) = (f.eval(u), g.eval(u), h.eval(u));
                prop_assert_eq!(a, b);
                prop_assert_eq!(a, e);
            }
            prop_assert_eq!(format!("{f:?}"), format!("{h:?}"));
        }
        // A curve spoiled in one of the ways only `validate`'s full check sees.
        let c = &chain[0];
        let (mut knots, mut ctrl) = (c.knots.clone(), c.ctrl.clone());
        match spoil {
            0 => ctrl[0][3] = 0.0,
            1 => knots[0] -= 1.0,
            2 => ctrl[c.degree][1] = f64::NAN,
            _ => knots[c.degree + 1] = knots[0] - 1.0,
        }
        let before = format!("{g:?}");
        prop_assert!(validate(c.degree, &knots, &ctrl, MAX_CTRL).is_err());
        prop_assert_eq!(g.load(c.degree, &knots, &ctrl), validate(c.degree, &knots, &ctrl, MAX_CTRL));
        prop_assert_eq!(format!("{g:?}"), before);
        // A curve of the wrong shape is refused by both, each keeping its curve.
        let before = format!("{f:?}");
        let short = &c.knots[..c.knots.len() - 1];
        prop_assert!(f.load_valid(c.degree, short, &c.ctrl).is_err());
        prop_assert!(f.load_valid(MAX_DEGREE + 1, &c.knots, &c.ctrl).is_err());
        prop_assert_eq!(format!("{f:?}"), before);
    }
}
