//! `FastCurve::load`, which the engine calls at every block's start (or ahead of it),
//! fills the evaluator in place instead of building a new one and moving it in: it must
//! leave every field as `FastCurve::new` builds it, whatever curve was loaded before, so
//! the same bits follow (compared through `Debug`, which prints every `f64` so that it
//! reads back to the same bits).

use proptest::prelude::*;
use shared::nurbs::fast::FastCurve;
use shared::nurbs::{MAX_CTRL, MAX_DEGREE};

#[derive(Debug, Clone)]
struct Curve {
    degree: usize,
    knots: Vec<f64>,
    ctrl: Vec<[f64; 4]>,
}

/// A random clamped rational curve of degree `1..=MAX_DEGREE`, interior knots that may
/// repeat up to the degree, weights in 0.2..5.
fn random_curve() -> impl Strategy<Value = Curve> {
    (1usize..=MAX_DEGREE)
        .prop_flat_map(|p| (Just(p), 0usize..=(MAX_CTRL - 1 - p)))
        .prop_flat_map(|(p, extra)| {
            let pt = (
                -100.0f64..100.0,
                -100.0f64..100.0,
                -100.0f64..100.0,
                0.2f64..5.0,
            );
            (
                Just(p),
                proptest::collection::vec(pt, p + 1 + extra),
                proptest::collection::vec(
                    prop_oneof![3 => 0.05f64..2.0, 1 => Just(0.0)],
                    extra + 1,
                ),
            )
        })
        .prop_map(|(p, pts, gaps)| {
            let mut knots = vec![0.0; p + 1];
            let mut run = 0;
            let mut k = 0.0;
            for g in gaps.iter().take(gaps.len() - 1) {
                // No knot repeated beyond the degree (the curve would break apart).
                let g = if *g == 0.0 && run + 1 >= p { 0.5 } else { *g };
                run = if g == 0.0 { run + 1 } else { 0 };
                k += g;
                knots.push(k);
            }
            let end = k + gaps.last().copied().unwrap_or(1.0).max(0.05);
            knots.extend(std::iter::repeat_n(end, p + 1));
            Curve {
                degree: p,
                knots,
                ctrl: pts.into_iter().map(|(x, y, z, w)| [x, y, z, w]).collect(),
            }
        })
}

fn params(c: &Curve, ts: &[f64]) -> Vec<f64> {
    let (lo, hi) = (c.knots[c.degree], c.knots[c.ctrl.len()]);
    let mut us: Vec<f64> = ts.iter().map(|t| lo + t * (hi - lo)).collect();
    us.extend_from_slice(&c.knots);
    us.extend_from_slice(&[lo - 1.0, hi + 1.0]);
    us
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn load_in_place_leaves_what_new_builds(
        a in random_curve(),
        b in random_curve(),
        ts in proptest::collection::vec(0.0f64..=1.0, 4),
    ) {
        let mut f = FastCurve::new(a.degree, &a.knots, &a.ctrl).expect("valid curve");
        for u in params(&a, &ts) {
            f.eval(u);
        }
        f.load(b.degree, &b.knots, &b.ctrl).expect("valid curve");
        let mut g = FastCurve::new(b.degree, &b.knots, &b.ctrl).expect("valid curve");
        prop_assert_eq!(format!("{f:?}"), format!("{g:?}"));
        for u in params(&b, &ts) {
            prop_assert_eq!(f.eval(u), g.eval(u));
        }
        prop_assert_eq!(format!("{f:?}"), format!("{g:?}"));
    }
}
