//! Arc length by Gauss–Legendre quadrature over each knot span.

/// Gauss–Legendre nodes and weights on [-1, 1], 5 points (exact for degree-9 polynomials).
const GL5: [(f64, f64); 5] = [
    (0.0, 0.568_888_888_888_888_9),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (-0.906_179_845_938_664, 0.236_926_885_056_189_08),
    (0.906_179_845_938_664, 0.236_926_885_056_189_08),
];

/// Length of a curve given the distinct knots `breaks` of its domain and its speed
/// `|C'(u)|`. Each span is cut into `subdiv` pieces for rational curves.
pub fn arc_length(knots: &[f64], subdiv: usize, speed: impl Fn(f64) -> f64) -> f64 {
    let mut total = 0.0;
    for w in knots.windows(2) {
        let (a, b) = (w[0], w[1]);
        if b <= a {
            continue;
        }
        let h = (b - a) / subdiv as f64;
        for s in 0..subdiv {
            let (x0, x1) = (a + h * s as f64, a + h * (s + 1) as f64);
            let (mid, half) = (0.5 * (x0 + x1), 0.5 * (x1 - x0));
            total += GL5
                .iter()
                .map(|&(x, wt)| wt * speed(mid + half * x))
                .sum::<f64>()
                * half;
        }
    }
    total
}
