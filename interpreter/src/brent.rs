//! Brent's minimisation on an interval (Brent 1973, `localmin`): golden-section steps,
//! and parabolic steps through the best three points wherever the parabola's vertex
//! stays inside the bracket and the step shrinks. The one search of a valley the
//! interpreter uses: the planner's peaks and valleys along a curve
//! ([`crate::blocks`], its speed split), the contour's nearest point on the path
//! ([`crate::contour`]), and `cnc cam`'s and the NURBS offset's worst errors and
//! nearest points ([`refine_max`], [`refine_min`]), each with its own start and
//! tolerance.

/// The least of `f` on `[a, b]` from the point `start` (`(x, f(x))`), as `(x, f(x))`:
/// until the bracket round the best point is within `tol(x)` (at most `steps` steps).
/// `None` where `f` has no value at a point it tries.
pub(crate) fn minimise(
    mut a: f64,
    mut b: f64,
    start: (f64, f64),
    steps: usize,
    tol: impl Fn(f64) -> f64,
    mut f: impl FnMut(f64) -> Option<f64>,
) -> Option<(f64, f64)> {
    // 1 − 1/φ: the golden section's share of the larger side.
    const C: f64 = 0.381_966_011_250_105_1;
    let (mut x, mut fx) = start;
    // `w` the second best point, `v` the one before; `d` the last step, `e` the one before.
    let (mut w, mut v, mut fw, mut fv) = (x, x, fx, fx);
    let (mut d, mut e) = (0.0f64, 0.0f64);
    for _ in 0..steps {
        let xm = 0.5 * (a + b);
        let tol = tol(x);
        if (x - xm).abs() <= 2.0 * tol - 0.5 * (b - a) {
            break;
        }
        let mut parabolic = false;
        if e.abs() > tol {
            // The parabola through x, w, v: its vertex at x + p/q.
            let r = (x - w) * (fx - fv);
            let mut q = (x - v) * (fx - fw);
            let mut p = (x - v) * q - (x - w) * r;
            q = 2.0 * (q - r);
            if q > 0.0 {
                p = -p;
            } else {
                q = -q;
            }
            // Taken where it stays inside the bracket and moves less than half the step
            // before last (else the steps may not shrink).
            if p.abs() < (0.5 * q * e).abs() && p > q * (a - x) && p < q * (b - x) {
                e = d;
                d = p / q;
                let u = x + d;
                if u - a < 2.0 * tol || b - u < 2.0 * tol {
                    d = if x < xm { tol } else { -tol };
                }
                parabolic = true;
            }
        }
        if !parabolic {
            e = if x < xm { b - x } else { a - x };
            d = C * e;
        }
        let u = if d.abs() >= tol {
            x + d
        } else {
            x + tol.copysign(d)
        };
        let fu = f(u)?;
        if fu <= fx {
            if u < x {
                b = x;
            } else {
                a = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
    }
    Some((x, fx))
}

/// The least of `f` near the sample `at` in `[a, b]` (a scan's best, its neighbours
/// the bracket), to a 1e-13 share of the bracket; the sample itself where nothing
/// better is found.
pub(crate) fn refine_min(a: f64, b: f64, at: f64, f: impl Fn(f64) -> f64) -> (f64, f64) {
    let start = (at, f(at));
    let tol = 1e-13 * (b - a).abs();
    minimise(a, b, start, 200, |_| tol, |x| Some(f(x)))
        .filter(|m| m.1 <= start.1)
        .unwrap_or(start)
}

/// The most of `f` near the sample `at` in `[a, b]`, as [`refine_min`].
pub(crate) fn refine_max(a: f64, b: f64, at: f64, f: impl Fn(f64) -> f64) -> (f64, f64) {
    let (x, v) = refine_min(a, b, at, |x| -f(x));
    (x, -v)
}
