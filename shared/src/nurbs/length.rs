//! Arc length by Gauss–Legendre quadrature over each knot span.

/// Gauss–Legendre nodes and weights on [-1, 1], 5 points (exact for degree-9 polynomials).
const GL5: [(f64, f64); 5] = [
    (0.0, 0.568_888_888_888_888_9),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (-0.906_179_845_938_664, 0.236_926_885_056_189_08),
    (0.906_179_845_938_664, 0.236_926_885_056_189_08),
];

/// The 5-point Gauss–Legendre rule of `speed` over `[x0, x1]`.
fn gl5(speed: &mut impl FnMut(f64) -> f64, x0: f64, x1: f64) -> f64 {
    let (mid, half) = (0.5 * (x0 + x1), 0.5 * (x1 - x0));
    GL5.iter()
        .map(|&(x, wt)| wt * speed(mid + half * x))
        .sum::<f64>()
        * half
}

/// Length of a curve given the distinct knots `breaks` of its domain and its speed
/// `|C'(u)|`. Each span is cut into `subdiv` pieces (for rational curves), and each pair
/// of neighbouring pieces is checked against the rule over both at once: where the two
/// differ by more than [`REL_TOL`] of the length and [`ABS_TOL_MM`] the pieces are
/// halved again, down to [`MAX_DEPTH`] halvings. Where they agree (every piece of an ordinary curve) the result is the sum
/// of the `subdiv` pieces, in order. A curve whose speed dips nearly to zero inside a
/// span (a control polygon folding back on itself) is no polynomial there: 32 pieces
/// of a 24 mm span left 4.7e-5 mm out, and the interpolator, which lands exact stops
/// on this length, came to the curve's end with speed still to lose.
pub fn arc_length(knots: &[f64], subdiv: usize, mut speed: impl FnMut(f64) -> f64) -> f64 {
    let mut rule = |x0: f64, x1: f64| gl5(&mut speed, x0, x1);
    let mut total = 0.0;
    for w in knots.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b <= a {
            continue;
        }
        let h = (b - a) / subdiv as f64;
        let at = |s: usize| a + h * s as f64;
        let mut s = 0;
        while s < subdiv {
            if s + 1 == subdiv {
                total += rule(at(s), at(s + 1));
                break;
            }
            let (x0, x1, x2) = (at(s), at(s + 1), at(s + 2));
            let (left, right) = (rule(x0, x1), rule(x1, x2));
            let gap = (rule(x0, x2) - (left + right)).abs();
            if agree(gap, left + right) {
                total += left;
                total += right;
            } else {
                total += refined(&mut rule, x0, x1, left, gap, MAX_DEPTH, f64::INFINITY);
                total += refined(&mut rule, x1, x2, right, gap, MAX_DEPTH, f64::INFINITY);
            }
            s += 2;
        }
    }
    total
}

/// Length of a curve given the distinct knots `breaks` of its domain and its speed
/// `|C'(u)|`, by adaptive Gauss–Legendre quadrature: each span is cut into `pieces`, and
/// each piece's 5-point rule is checked against the rule over its two halves; where the
/// two differ by more than [`REL_TOL`] of the length and [`ABS_TOL_MM`] the halves are
/// halved in turn (down to [`MAX_DEPTH`] halvings, or where halving no longer brings
/// them closer: rounding), and where they agree the halves' sum is taken (its error is
/// about 2^-10 of the difference on a smooth piece).
///
/// [`arc_length`] takes the same decisions on a fixed grid of `subdiv` pieces, checked a
/// pair at a time: 240 points a span at its 32 pieces. Here a span takes 15 points a
/// piece where the rule agrees with its halves at once, and more only where the speed
/// needs them (a near-cusp, a fast-changing rational weight). The tests hold the two to
/// each other and to closed forms (`nurbs::tests`).
pub fn arc_length_adaptive(knots: &[f64], pieces: usize, mut speed: impl FnMut(f64) -> f64) -> f64 {
    let mut rule = |x0: f64, x1: f64| gl5(&mut speed, x0, x1);
    let pieces = pieces.max(1);
    let mut total = 0.0;
    for w in knots.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b <= a {
            continue;
        }
        let h = (b - a) / pieces as f64;
        for s in 0..pieces {
            let x0 = a + h * s as f64;
            let x1 = if s + 1 == pieces {
                b
            } else {
                a + h * (s + 1) as f64
            };
            let whole = rule(x0, x1);
            total += refined(&mut rule, x0, x1, whole, f64::INFINITY, MAX_DEPTH, NOISE_MM);
        }
    }
    total
}

/// How far the rule over a piece may differ from the sum over its halves, relative to
/// the length (the rule's own error is far smaller where the two agree): a thousandth
/// of a nanometre per metre; or absolutely, [`ABS_TOL_MM`].
const REL_TOL: f64 = 1e-12;
/// A hundredth of a nanometre a piece: far below what a landing on a stop can feel
/// (the engine lands within 5e-8 mm).
const ABS_TOL_MM: f64 = 1e-11;
/// Most halvings of a piece: a 2^-16 share of it at the most.
const MAX_DEPTH: u32 = 16;

fn agree(gap: f64, halves: f64) -> bool {
    gap <= REL_TOL * halves.abs() + ABS_TOL_MM
}

/// The largest difference between a piece's rule and its halves' that
/// [`arc_length_adaptive`] takes for rounding where halving brings them no closer: a
/// nanometre. Its pieces start a quarter of a span long, where the rule may not yet
/// converge steadily (a 4 mm piece of a rational span: 1.7e-7 mm off where any lack of
/// progress stopped it); rounding is far below this.
const NOISE_MM: f64 = 1e-9;

/// The length over `[x0, x1]`, whose rule differed by `gap` from its halves', halved
/// until the halves agree. Halving stops too where it no longer brings the rule and the
/// halves closer by a quarter at least and they differ by `noise` at most: what is left
/// is rounding (far from the origin a coordinate's rounding is above the tolerance), not
/// the rule's error, which shrinks at every halving (by 2^10 on a smooth piece, by 4
/// even where the speed has a corner) once the pieces are short enough.
fn refined(
    rule: &mut impl FnMut(f64, f64) -> f64,
    x0: f64,
    x1: f64,
    whole: f64,
    parent_gap: f64,
    depth: u32,
    noise: f64,
) -> f64 {
    let xm = 0.5 * (x0 + x1);
    let (left, right) = (rule(x0, xm), rule(xm, x1));
    let gap = (whole - (left + right)).abs();
    if depth == 0 || agree(gap, left + right) || (gap >= parent_gap && gap <= noise) {
        left + right
    } else {
        refined(rule, x0, xm, left, gap, depth - 1, noise)
            + refined(rule, xm, x1, right, gap, depth - 1, noise)
    }
}
