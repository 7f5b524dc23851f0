//! Knot insertion (Boehm) and exact splitting of a curve into pieces that fit one block.
//! These run in the interpreter, never in the cycle, so they may allocate.

/// A curve piece as plain vectors: degree, knots, control points `[x, y, z, w]`.
#[derive(Debug, Clone, PartialEq)]
pub struct SplitCurve {
    pub degree: usize,
    pub knots: Vec<f64>,
    pub ctrl: Vec<[f64; 4]>,
}

fn to_h(c: [f64; 4]) -> [f64; 4] {
    [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]]
}
fn from_h(h: [f64; 4]) -> [f64; 4] {
    [h[0] / h[3], h[1] / h[3], h[2] / h[3], h[3]]
}

/// Inserts `u` once into a clamped curve; the curve's shape and parametrisation are unchanged.
/// `u` must lie strictly inside the domain.
pub fn insert_knot(curve: &SplitCurve, u: f64) -> SplitCurve {
    let p = curve.degree;
    let n = curve.ctrl.len();
    let k = super::find_span(p, &curve.knots, n, u);
    let mut ctrl = Vec::with_capacity(n + 1);
    for i in 0..=n {
        let q = if i + p <= k {
            curve.ctrl[i]
        } else if i > k {
            curve.ctrl[i - 1]
        } else {
            // Blend in homogeneous space so weights are carried exactly.
            let t = &curve.knots;
            let alpha = (u - t[i]) / (t[i + p] - t[i]);
            let (a, b) = (to_h(curve.ctrl[i]), to_h(curve.ctrl[i - 1]));
            from_h(core::array::from_fn(|j| {
                alpha * a[j] + (1.0 - alpha) * b[j]
            }))
        };
        ctrl.push(q);
    }
    let mut knots = curve.knots.clone();
    knots.insert(k + 1, u);
    SplitCurve {
        degree: p,
        knots,
        ctrl,
    }
}

/// Splits a curve exactly at the interior parameter `u` into a left and a right curve.
pub fn split_at(curve: &SplitCurve, u: f64) -> (SplitCurve, SplitCurve) {
    let p = curve.degree;
    let mut c = curve.clone();
    while c.knots.iter().filter(|&&k| k == u).count() < p {
        c = insert_knot(&c, u);
    }
    let s = c.knots.iter().filter(|&&k| k == u).count();
    let j = c.knots.iter().position(|&k| k == u).unwrap_or(0);
    let mut lk = c.knots[..j + p].to_vec();
    lk.push(u);
    let left = SplitCurve {
        degree: p,
        knots: lk,
        ctrl: c.ctrl[..j].to_vec(),
    };
    let mut rk = vec![u; p + 1];
    rk.extend_from_slice(&c.knots[j + s..]);
    let right = SplitCurve {
        degree: p,
        knots: rk,
        ctrl: c.ctrl[j - 1 + (s - p)..].to_vec(),
    };
    (left, right)
}

/// Splits a validated curve into consecutive pieces of at most `max_ctrl` control points
/// each, exactly (by knot insertion at existing interior knots): the pieces trace the very
/// same curve with the same parameter values. `max_ctrl` must exceed `2 * (degree + 1)`.
pub fn split_to_capacity(curve: SplitCurve, max_ctrl: usize) -> Vec<SplitCurve> {
    let mut out = Vec::new();
    let mut stack = vec![curve];
    while let Some(c) = stack.pop() {
        if c.ctrl.len() <= max_ctrl {
            out.push(c);
            continue;
        }
        let p = c.degree;
        let (lo, hi) = (c.knots[0], c.knots[c.knots.len() - 1]);
        // The interior knot whose index is nearest the middle keeps the pieces balanced.
        let mid = c.knots.len() / 2;
        let u = (p + 1..c.knots.len() - p - 1)
            .filter(|&i| c.knots[i] > lo && c.knots[i] < hi)
            .min_by_key(|&i| i.abs_diff(mid))
            .map(|i| c.knots[i]);
        match u {
            Some(u) => {
                let (l, r) = split_at(&c, u);
                // Right first so the left piece is popped (and emitted) first.
                stack.push(r);
                stack.push(l);
            }
            None => out.push(c), // cannot happen for a valid clamped curve this long
        }
    }
    out
}
