//! Checks against independent references: the Cox–de Boor recursion evaluated from scratch,
//! central finite differences, and the closed form of the circle.

use super::*;
use proptest::prelude::*;

use super::reference::cox_de_boor as basis;

fn reference_point(p: usize, knots: &[f64], ctrl: &[[f64; 4]], u: f64) -> [f64; 3] {
    let mut a = [0.0; 3];
    let mut w = 0.0;
    for (i, c) in ctrl.iter().enumerate() {
        let nw = basis(i, p, knots, u) * c[3];
        w += nw;
        for k in 0..3 {
            a[k] += nw * c[k];
        }
    }
    a.map(|x| x / w)
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

prop_compose! {
    fn random_curve()(p in 1usize..=MAX_DEGREE, extra in 0usize..12)
        (ctrl in proptest::collection::vec(
            (-100.0f64..100.0, -100.0f64..100.0, -100.0f64..100.0, 0.2f64..5.0), p + 1 + extra),
         gaps in proptest::collection::vec(0.05f64..2.0, extra + 1), p in Just(p))
        -> SplitCurve
    {
        let n = ctrl.len();
        let mut knots = vec![0.0; p + 1];
        let mut t = 0.0;
        for g in &gaps[..n - p - 1] { t += g; knots.push(t); }
        t += gaps[n - p - 1];
        knots.extend(std::iter::repeat_n(t, p + 1));
        SplitCurve { degree: p, knots, ctrl: ctrl.into_iter().map(|(x, y, z, w)| [x, y, z, w]).collect() }
    }
}

/// The central differences' step in span `s`: a share of the span's own width. A share
/// of the whole domain's (up to 480 times a 0.05 span) made the differences' own error,
/// not the derivatives', break the tolerance on a short span whose weights fall steeply
/// (`differences_on_a_short_steep_span`).
fn difference_step(c: &SplitCurve, s: usize) -> f64 {
    1e-5 * (c.knots[s + 1] - c.knots[s])
}

/// How far central differences of step `h` about `u` (inside one span) are from the
/// evaluated first and second derivatives: the largest miss over the tolerance, 1e-4 of
/// the derivatives' size (at least 1); right derivatives stay below 1.
fn difference_error(c: &SplitCurve, u: f64, h: f64) -> f64 {
    let e = eval(c.degree, &c.knots, &c.ctrl, u);
    let (m, pl) = (
        eval(c.degree, &c.knots, &c.ctrl, u - h),
        eval(c.degree, &c.knots, &c.ctrl, u + h),
    );
    let scale1 =
        e.d1.iter()
            .chain(m.d1.iter())
            .fold(1.0f64, |a, b| a.max(b.abs()));
    let scale2 =
        e.d2.iter()
            .chain(m.d2.iter())
            .fold(1.0f64, |a, b| a.max(b.abs()));
    // The larger, or NaN if either is (which `f64::max` would drop).
    let worse = |a: f64, b: f64| if b > a || b.is_nan() { b } else { a };
    (0..3).fold(0.0f64, |worst, k| {
        let fd1 = (pl.p[k] - m.p[k]) / (2.0 * h);
        let fd2 = (pl.d1[k] - m.d1[k]) / (2.0 * h);
        let worst = worse(worst, (fd1 - e.d1[k]).abs() / (1e-4 * scale1));
        worse(worst, (fd2 - e.d2[k]).abs() / (1e-4 * scale2))
    })
}

proptest! {
    #[test]
    fn eval_matches_cox_de_boor(c in random_curve(), t in 0.0f64..=1.0) {
        prop_assert!(validate(c.degree, &c.knots, &c.ctrl, usize::MAX).is_ok());
        let (lo, hi) = (c.knots[0], *c.knots.last().unwrap());
        let u = lo + t * (hi - lo);
        let got = eval(c.degree, &c.knots, &c.ctrl, u).p;
        let want = reference_point(c.degree, &c.knots, &c.ctrl, u);
        prop_assert!(dist(got, want) < 1e-9 * 100.0, "{got:?} vs {want:?}");
    }

    #[test]
    fn each_degrees_own_evaluators_give_the_general_ones_bits(
        c in random_curve(),
        t in prop_oneof![0.0f64..=1.0, Just(0.0), Just(1.0), Just(-0.5), Just(1.5)],
    ) {
        let (lo, hi) = (c.knots[0], *c.knots.last().unwrap());
        // At knots too, where the span search and the basis meet their edge cases.
        let at_knot = c.knots[(t.abs() * c.knots.len() as f64) as usize % c.knots.len()];
        // And the curve's first control points as one Bézier span (evaluated its own way).
        let p = c.degree;
        let mut bezier_knots = vec![lo; p + 1];
        bezier_knots.extend(std::iter::repeat_n(hi, p + 1));
        let bezier = SplitCurve { degree: p, knots: bezier_knots, ctrl: c.ctrl[..=p].to_vec() };
        for (c, u) in [(&c, lo + t * (hi - lo)), (&c, at_knot), (&bezier, lo + t * (hi - lo))] {
            let got = eval(c.degree, &c.knots, &c.ctrl, u);
            let general = super::eval::eval_with::<0, 2, false, 10>(c.degree, &c.knots, &c.ctrl, u);
            let bits = |e: &CurvePoint| {
                [e.p, e.d1, e.d2].concat().iter().map(|x| x.to_bits()).collect::<Vec<_>>()
            };
            prop_assert_eq!(bits(&got), bits(&general));
            prop_assert_eq!(got.span, general.span);
            // Without the second derivative: the same point and first derivative.
            let d1 = eval_d1(c.degree, &c.knots, &c.ctrl, u);
            let first = CurvePoint { d2: [0.0; 3], ..general };
            prop_assert_eq!(bits(&d1), bits(&first));
        }
    }

    #[test]
    fn derivatives_match_finite_differences(c in random_curve(), t in 0.05f64..0.95) {
        let (lo, hi) = (c.knots[0], *c.knots.last().unwrap());
        let u = lo + t * (hi - lo);
        // Stay inside one span: differences across a knot see the lower continuity.
        let s = find_span(c.degree, &c.knots, c.ctrl.len(), u);
        let h = difference_step(&c, s);
        prop_assume!(u - h > c.knots[s] && u + h < c.knots[s + 1]);
        let err = difference_error(&c, u, h);
        prop_assert!(err < 1.0, "p = {} u = {u}: {err} times the tolerance", c.degree);
    }

    #[test]
    fn knot_insertion_and_split_keep_the_curve(c in random_curve(), t in 0.0f64..=1.0) {
        let (lo, hi) = (c.knots[0], *c.knots.last().unwrap());
        let u = lo + t * (hi - lo);
        let want = eval(c.degree, &c.knots, &c.ctrl, u).p;
        let ins = insert_knot(&c, lo + 0.37 * (hi - lo));
        prop_assert!(dist(eval(ins.degree, &ins.knots, &ins.ctrl, u).p, want) < 1e-9 * 100.0);
        let pieces = split_to_capacity(c.clone(), 2 * (c.degree + 1) + 1);
        for w in pieces.windows(2) {
            prop_assert_eq!(*w[0].knots.last().unwrap(), w[1].knots[0]);
        }
        let piece = pieces.iter().find(|pc| u <= *pc.knots.last().unwrap()).unwrap();
        prop_assert!(piece.ctrl.len() <= 2 * (c.degree + 1) + 1);
        prop_assert!(validate(piece.degree, &piece.knots, &piece.ctrl, usize::MAX).is_ok());
        let got = eval(piece.degree, &piece.knots, &piece.ctrl, u).p;
        prop_assert!(dist(got, want) < 1e-8 * 100.0, "{got:?} vs {want:?}");
    }
}

/// A curve `random_curve` can draw: degree 1, a 0.05 span between spans of 1.9 whose
/// weights fall from 4.9 to 0.2. Near the span's light end the derivatives change so fast
/// that central differences with a step of 1e-5 of the whole domain (20.95) miss them by
/// 110 times the tolerance, though they are right; a step of 1e-5 of the span's width
/// finds them (6e-4 of it).
#[test]
fn differences_on_a_short_steep_span() {
    let mut knots = vec![0.0, 0.0, 1.9, 3.8, 5.7, 7.6, 9.5, 9.55, 11.45, 13.35, 15.25];
    knots.extend([17.15, 19.05, 20.95, 20.95]);
    let mut ctrl = vec![[0.0, 0.0, 0.0, 1.0]; 13];
    ctrl[5] = [-100.0, -100.0, -100.0, 4.9];
    ctrl[6] = [99.0, 99.0, 99.0, 0.2];
    let c = SplitCurve {
        degree: 1,
        knots,
        ctrl,
    };
    assert!(validate(c.degree, &c.knots, &c.ctrl, usize::MAX).is_ok());
    let (a, b) = (c.knots[6], c.knots[7]);
    let domain_step = 1e-5 * 20.95;
    let u = a + domain_step + 0.99 * (b - a - 2.0 * domain_step);
    assert_eq!(find_span(c.degree, &c.knots, c.ctrl.len(), u), 6);
    let coarse = difference_error(&c, u, domain_step);
    assert!(coarse > 10.0, "{coarse}");
    let fine = difference_error(&c, u, difference_step(&c, 6));
    assert!(fine < 1e-2, "{fine}");
}

#[test]
fn quarter_circle_is_exact() {
    let h = core::f64::consts::FRAC_1_SQRT_2;
    let ctrl = [
        [10.0, 0.0, 0.0, 1.0],
        [10.0, 10.0, 0.0, h],
        [0.0, 10.0, 0.0, 1.0],
    ];
    let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    for i in 0..=1000 {
        let e = eval(2, &knots, &ctrl, i as f64 / 1000.0);
        let r = (e.p[0].powi(2) + e.p[1].powi(2)).sqrt();
        assert!((r - 10.0).abs() < 1e-12, "r = {r}");
    }
    let len = arc_length(&knots, 8, |u| {
        let d = eval(2, &knots, &ctrl, u).d1;
        (d[0] * d[0] + d[1] * d[1]).sqrt()
    });
    assert!(
        (len - 5.0 * core::f64::consts::PI).abs() < 1e-9,
        "length {len}"
    );
}

/// The speed `|t|·√(4 + 9t²)` of the cusp the two length tests below cross, on
/// `[-0.3, 1]`, and its length in closed form: `((4 + 9t²)^1.5 − 8)/27` each side of 0.
fn cusp_speed(t: f64) -> f64 {
    t.abs() * (4.0 + 9.0 * t * t).sqrt()
}

fn cusp_length() -> f64 {
    let side = |t: f64| ((4.0 + 9.0 * t * t).powf(1.5) - 8.0) / 27.0;
    side(-0.3) + side(1.0)
}

/// Arc length where the speed dips to zero inside a span, against the closed form: the
/// semicubical parabola `(t², t³)` through its cusp at `t = 0`, whose speed
/// `|t|·√(4 + 9t²)` is no polynomial there, from `t = -0.3` (so no piece boundary falls
/// on the cusp) to 1. Its length is `((4 + 9t²)^1.5 − 8)/27` on each side. The 32
/// pieces of the plain rule are 1.2e-5 off here, relatively (2e-6 on a planned
/// near-cusp span).
#[test]
fn arc_length_through_a_cusp_matches_the_closed_form() {
    let exact = cusp_length();
    let len = arc_length(&[-0.3, 1.0], 32, cusp_speed);
    // Within a hundredth of a nanometre a piece (`ABS_TOL_MM`) of a few pieces at the
    // cusp: far below the 5e-8 mm within which the engine lands a stop.
    assert!(
        (len - exact).abs() <= 1e-10,
        "length {len}, exact {exact}: {:e}",
        len - exact
    );
}

/// The adaptive rule through the same cusp, from the fewest pieces (one, two and four a
/// span), to the same tolerance as the fixed rule above: its halvings find the cusp.
#[test]
fn adaptive_arc_length_through_a_cusp_matches_the_closed_form() {
    let exact = cusp_length();
    for pieces in [1, 2, 4] {
        let mut points = 0;
        let len = arc_length_adaptive(&[-0.3, 1.0], pieces, |t| {
            points += 1;
            cusp_speed(t)
        });
        assert!(
            (len - exact).abs() <= 1e-10,
            "{pieces} pieces, {points} points: length {len}, exact {exact}: {:e}",
            len - exact
        );
    }
}

/// The adaptive rule on the quarter circle of radius 10 (5π), to 1e-12 mm: a smooth
/// span agrees with its halves after a few halvings.
#[test]
fn adaptive_arc_length_of_a_quarter_circle() {
    let h = core::f64::consts::FRAC_1_SQRT_2;
    let ctrl = [
        [10.0, 0.0, 0.0, 1.0],
        [10.0, 10.0, 0.0, h],
        [0.0, 10.0, 0.0, 1.0],
    ];
    let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
    let len = arc_length_adaptive(&knots, 4, |u| {
        let d = eval(2, &knots, &ctrl, u).d1;
        (d[0] * d[0] + d[1] * d[1]).sqrt()
    });
    assert!(
        (len - 5.0 * core::f64::consts::PI).abs() < 1e-12,
        "length {len}"
    );
}

#[test]
fn validation_names_the_problem() {
    let ctrl = [
        [0.0, 0.0, 0.0, 1.0],
        [1.0, 0.0, 0.0, 1.0],
        [2.0, 0.0, 0.0, -1.0],
    ];
    assert_eq!(
        validate(2, &[0.0, 0.0, 0.0, 1.0, 1.0, 1.0], &ctrl, 32),
        Err(CurveError::WeightNotPositive { index: 2 })
    );
    assert_eq!(
        validate(2, &[0.0, 0.0, 0.0, 1.0, 1.0], &ctrl, 32),
        Err(CurveError::KnotCount {
            n_knots: 5,
            expected: 6
        })
    );
    assert_eq!(
        validate(1, &[0.0, 0.0, 2.0, 1.0, 1.0], &ctrl, 32),
        Err(CurveError::KnotsDecrease { index: 3 })
    );
    assert_eq!(
        validate(0, &[], &ctrl, 32),
        Err(CurveError::DegreeOutOfRange { degree: 0 })
    );
}
