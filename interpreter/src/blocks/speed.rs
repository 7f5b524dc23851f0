//! Where along a curve its speed limit changes: the velocity-limit curve of one NURBS
//! piece, and the piece split exactly (knot insertion) wherever that limit crosses a
//! level, so that each block's constant cap follows the limit instead of holding the
//! whole piece to its sharpest point.
//!
//! The limit at a point is the highest path speed the geometry there allows on its own:
//! the feed, each axis's velocity share `v·|T_i| <= V_i`, the curvature's normal
//! acceleration `v²·|k|` (path and each axis) within the machine's acceleration, and its
//! rate `v³·|dk/ds|` within the jerk. (The chord tolerance depends on the period, which a
//! build does not know; it grows with the radius as the acceleration's bound does, so
//! their levels fall at the same places.) The planner's [`super::shape`] then works out
//! each block's cap and tangential limits from its own samples; this module only decides
//! where the blocks begin and end.
//!
//! The levels are geometric, [`LEVEL`] apart below the feed. The limit is sampled
//! uniformly in the parameter, its local minima are searched between samples (Brent's
//! method: a bend of a few µm in a span of centimetres is narrower than any sampling),
//! and neighbouring samples more than one level apart are bisected until they are not
//! (or closer than [`MIN_GAP`] of the domain), so a block boundary sits within one level
//! of where the limit actually crosses it. A piece is split at most into [`MAX_PIECES`].
//!
//! The evaluator is the moving-data one of the cycle ([`FastCurve`]): 10–15 ns a point.

use shared::nurbs::fast::FastCurve;
use shared::nurbs::{split_at, CurvePoint, SplitCurve};
use shared::Machine;

/// Ratio of one speed level to the next below it.
const LEVEL: f64 = 0.8;
/// Uniform samples of a piece's limit.
const SAMPLES: usize = 64;
/// Most blocks one piece is split into.
const MAX_PIECES: usize = 32;
/// Bisection stops when two samples are closer than this share of the domain.
const MIN_GAP: f64 = 1e-7;
/// A block boundary is never closer than this share of the domain to another or to an
/// end (shorter blocks join their neighbour, whose cap is then the lower of the two).
const MIN_PIECE: f64 = 1e-5;
/// A join of two blocks that loses less time than this (s) is always made: a block
/// boundary that buys nothing is only a block more to send and step through.
const NEGLIGIBLE_S: f64 = 1e-4;
/// Most samples taken of one piece (bisections included).
const MAX_SAMPLES: usize = 4096;

/// The limit's sampler for one piece.
struct Limit<'a> {
    curve: FastCurve,
    machine: &'a Machine,
    feed_mm_s: f64,
    u0: f64,
    u1: f64,
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Unit tangent and curvature vector of a point; `None` where the curve (nearly) stops.
fn frame(e: &CurvePoint) -> Option<([f64; 3], [f64; 3])> {
    let sp = norm(e.d1);
    if sp.is_nan() || sp <= 1e-12 {
        return None;
    }
    let t = e.d1.map(|x| x / sp);
    let along = e.d2[0] * t[0] + e.d2[1] * t[1] + e.d2[2] * t[2];
    Some((t, [0, 1, 2].map(|i| (e.d2[i] - along * t[i]) / (sp * sp))))
}

impl Limit<'_> {
    /// The limit (mm/s) at `u`; `None` where the curve stops there (a cusp's point, which
    /// `build` has already made a block end).
    fn at(&mut self, u: f64) -> Option<f64> {
        self.sample(u).map(|s| s.v)
    }

    /// The [`Sample`] at `u`.
    fn sample(&mut self, u: f64) -> Option<Sample> {
        let e = self.curve.eval(u);
        let (t, k) = frame(&e)?;
        // dk/ds by a central difference, kept inside the domain.
        let h = 1e-4 * (self.u1 - self.u0);
        let (ua, ub) = ((u - h).max(self.u0), (u + h).min(self.u1));
        let (ea, eb) = (self.curve.eval(ua), self.curve.eval(ub));
        let dk = match (frame(&ea), frame(&eb)) {
            (Some((_, ka)), Some((_, kb))) => {
                let ds = norm([eb.p[0] - ea.p[0], eb.p[1] - ea.p[1], eb.p[2] - ea.p[2]]);
                if ds > 1e-15 {
                    [0, 1, 2].map(|i| (kb[i] - ka[i]) / ds)
                } else {
                    [0.0; 3]
                }
            }
            _ => [0.0; 3],
        };
        let m = self.machine;
        let mut v = self.feed_mm_s;
        let mut bound = |limit: f64, x: f64, root: fn(f64) -> f64| {
            if x > 1e-12 {
                v = v.min(root(limit / x));
            }
        };
        bound(m.path_acc_mm_per_s2, norm(k), f64::sqrt);
        for (i, ax) in m.axes.as_array().iter().enumerate() {
            bound(ax.max_vel_mm_per_min / 60.0, t[i].abs(), |x| x);
            bound(ax.max_acc_mm_per_s2, k[i].abs(), f64::sqrt);
        }
        // The jerk's bounds after the others, each cube root taken only where it may be
        // the lower (`min_cbrt`: the same bits as `v.min(x.cbrt())`). The minimum of the
        // same numbers in another order is the same number.
        let mut jerk_bound = |limit: f64, x: f64| {
            if x > 1e-12 {
                v = super::min_cbrt(v, limit / x);
            }
        };
        jerk_bound(m.path_jerk_mm_per_s3, norm(dk));
        for (i, ax) in m.axes.as_array().iter().enumerate() {
            jerk_bound(ax.max_jerk_mm_per_s3, dk[i].abs());
        }
        v.is_finite().then_some(Sample {
            u,
            p: e.p,
            v,
            level: self.level(v),
        })
    }

    /// The level of speed `v`: 0 at the feed, `n` for `LEVEL^n` of it and below.
    fn level(&self, v: f64) -> u32 {
        if v >= self.feed_mm_s * (1.0 - 1e-9) {
            0
        } else {
            let r = (v / self.feed_mm_s).max(1e-300);
            1 + (r.ln() / LEVEL.ln()).floor().clamp(0.0, 1e6) as u32
        }
    }
}

/// A sample of the limit: parameter and level.
#[derive(Debug, Clone, Copy)]
struct Sample {
    u: f64,
    /// The point there.
    p: [f64; 3],
    v: f64,
    level: u32,
}

/// `c` (one Bézier piece of a program's NURBS, as `build` hands it over) split exactly
/// where its speed limit at `feed_mm_per_min` on `machine` changes level; `c` itself
/// where it does not.
pub fn split_by_speed(c: SplitCurve, machine: &Machine, feed_mm_per_min: f64) -> Vec<SplitCurve> {
    let bounds = match boundaries(&c, machine, feed_mm_per_min) {
        Some(b) if !b.is_empty() => b,
        _ => return vec![c],
    };
    let mut out = Vec::with_capacity(bounds.len() + 1);
    let mut rest = c;
    for u in bounds {
        let (l, r) = split_at(&rest, u);
        out.push(l);
        rest = r;
    }
    out.push(rest);
    out
}

/// The parameters where `c` is split, in order, strictly inside its domain; `None` where
/// it cannot be sampled (any evaluator error: `build` keeps the piece whole).
fn boundaries(c: &SplitCurve, machine: &Machine, feed_mm_per_min: f64) -> Option<Vec<f64>> {
    let feed_mm_s = feed_mm_per_min / 60.0;
    if !(feed_mm_s > 0.0 && feed_mm_s.is_finite()) {
        return None;
    }
    let curve = FastCurve::new(c.degree, &c.knots, &c.ctrl).ok()?;
    let (u0, u1) = curve.domain();
    if u1.is_nan() || u0.is_nan() || u1 <= u0 {
        return None;
    }
    let mut lim = Limit {
        curve,
        machine,
        feed_mm_s,
        u0,
        u1,
    };
    let mut samples: Vec<Sample> = Vec::with_capacity(2 * SAMPLES);
    for i in 0..=SAMPLES {
        let u = u0 + (u1 - u0) * i as f64 / SAMPLES as f64;
        samples.extend(lim.sample(u));
    }
    // Local minima searched between their neighbours (a dip narrower than the sampling
    // still shows as a sample below both of its own).
    let mut found: Vec<Sample> = Vec::new();
    for w in samples.windows(3) {
        let (a, m, b) = (w[0], w[1], w[2]);
        if m.v <= a.v && m.v <= b.v && (m.v < a.v || m.v < b.v || m.level > 0) {
            if let Some(s) = golden_min(&mut lim, a.u, b.u) {
                found.push(s);
            }
        }
    }
    samples.extend(found);
    samples.sort_by(|a, b| a.u.total_cmp(&b.u));
    samples.dedup_by(|a, b| a.u == b.u);
    // Neighbours more than a level apart are bisected.
    let gap = MIN_GAP * (u1 - u0);
    let mut budget = MAX_SAMPLES.saturating_sub(samples.len());
    let mut dense: Vec<Sample> = Vec::with_capacity(samples.len() * 2);
    for w in samples.windows(2) {
        dense.push(w[0]);
        fill(&mut lim, w[0], w[1], gap, &mut budget, &mut dense);
    }
    dense.extend(samples.last().copied());
    Some(cut(&dense, u0, u1, feed_mm_s))
}

/// The samples strictly between `a` and `b`, in order, pushed onto `out`: the midpoint
/// while the two are more than a level apart and further than `gap`.
fn fill(
    lim: &mut Limit,
    a: Sample,
    b: Sample,
    gap: f64,
    budget: &mut usize,
    out: &mut Vec<Sample>,
) {
    if a.level.abs_diff(b.level) <= 1 || b.u - a.u <= gap || *budget == 0 {
        return;
    }
    let u = 0.5 * (a.u + b.u);
    let Some(m) = lim.sample(u) else { return };
    *budget -= 1;
    fill(lim, a, m, gap, budget, out);
    out.push(m);
    fill(lim, m, b, gap, budget, out);
}

/// The minimum of the limit on `[lo, hi]`, to 1e-9 of the interval ([`super::brent_min`]:
/// fewer points than the golden-section search it replaces).
fn golden_min(lim: &mut Limit, lo: f64, hi: f64) -> Option<Sample> {
    let (u, _) = super::brent_min(lo, hi, |u| lim.at(u))?;
    lim.sample(u)
}

/// A block-to-be between two boundaries.
#[derive(Debug, Clone, Copy)]
struct Piece {
    start: f64,
    /// The highest (slowest) level of its samples.
    level: u32,
    /// Its length, as the chords between its samples (mm).
    len: f64,
}

/// Time (s) lost by joining pieces `a` and `b` (the faster one then runs at the slower
/// one's level), with `feed` the speed of level 0.
fn join_cost(a: &Piece, b: &Piece, feed: f64) -> f64 {
    let speed = |l: u32| feed * LEVEL.powi(l as i32);
    let (fast, slow) = if a.level <= b.level { (a, b) } else { (b, a) };
    fast.len * (1.0 / speed(slow.level) - 1.0 / speed(fast.level))
}

/// Block boundaries from samples in order: where the level changes, at the sample on
/// the faster side (so the slower block holds every sample of its level and one more).
/// Then neighbours are joined, cheapest first (the time [`join_cost`] says the join
/// loses), while a block is shorter than [`MIN_PIECE`] of the domain, while there are
/// more than [`MAX_PIECES`], and while a join loses less than [`NEGLIGIBLE_S`].
fn cut(samples: &[Sample], u0: f64, u1: f64, feed: f64) -> Vec<f64> {
    let Some(first) = samples.first() else {
        return Vec::new();
    };
    let mut pieces: Vec<Piece> = vec![Piece {
        start: u0,
        level: first.level,
        len: 0.0,
    }];
    for w in samples.windows(2) {
        let (a, b) = (w[0], w[1]);
        let chord = norm([b.p[0] - a.p[0], b.p[1] - a.p[1], b.p[2] - a.p[2]]);
        let last = pieces.len() - 1;
        if a.level == b.level {
            pieces[last].len += chord;
        } else if b.level > a.level {
            // Slowing: the new piece starts at `a`, which both hold.
            pieces.push(Piece {
                start: a.u,
                level: b.level,
                len: chord,
            });
        } else {
            // Speeding up: the slow piece runs to `b`.
            pieces[last].level = pieces[last].level.max(a.level);
            pieces[last].len += chord;
            pieces.push(Piece {
                start: b.u,
                level: b.level,
                len: 0.0,
            });
        }
    }
    let min = MIN_PIECE * (u1 - u0);
    loop {
        let n = pieces.len();
        if n < 2 {
            break;
        }
        let end = |i: usize| if i + 1 < n { pieces[i + 1].start } else { u1 };
        // The cheapest join of all, and of those with a piece too short.
        let cost = |i: usize| join_cost(&pieces[i - 1], &pieces[i], feed);
        let cheapest = (1..n).min_by(|&a, &b| cost(a).total_cmp(&cost(b)));
        let short = (0..n).find(|&i| end(i) - pieces[i].start < min).map(|i| {
            if i == 0 {
                1
            } else if i + 1 == n || cost(i) <= cost(i + 1) {
                i
            } else {
                i + 1
            }
        });
        let Some(i) = short.or(cheapest.filter(|&i| n > MAX_PIECES || cost(i) < NEGLIGIBLE_S))
        else {
            break;
        };
        // Join piece `i` into `i - 1`.
        pieces[i - 1].level = pieces[i - 1].level.max(pieces[i].level);
        pieces[i - 1].len += pieces[i].len;
        pieces.remove(i);
    }
    pieces.iter().skip(1).map(|p| p.start).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cubic with one sharp bend in the middle of a long span.
    fn bend() -> SplitCurve {
        SplitCurve {
            degree: 3,
            knots: vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
            ctrl: vec![
                [0.0, 0.0, 0.0, 1.0],
                [10.0, 0.0, 0.0, 1.0],
                [10.0, 0.001, 0.0, 1.0],
                [0.0, 0.001, 0.0, 1.0],
            ],
        }
    }

    /// The golden-section search that [`super::super::brent_min`] replaced: the
    /// reference it is held to.
    fn golden_reference(lo: f64, hi: f64, f: impl Fn(f64) -> f64) -> f64 {
        const R: f64 = 0.618_033_988_749_895;
        let (mut a, mut b) = (lo, hi);
        let (mut c, mut d) = (b - R * (b - a), a + R * (b - a));
        let (mut fc, mut fd) = (f(c), f(d));
        while b - a > 1e-9 * (hi - lo) {
            if fc <= fd {
                (b, d, fd) = (d, c, fc);
                c = b - R * (b - a);
                fc = f(c);
            } else {
                (a, c, fc) = (c, d, fd);
                d = a + R * (b - a);
                fd = f(d);
            }
        }
        if fc <= fd {
            c
        } else {
            d
        }
    }

    /// Brent's search against closed forms and the golden-section search of before, on
    /// valleys the planner meets: smooth (a parabola, a cosine), narrow (the speed limit
    /// of a bend 1e-5 of the bracket wide: `√(1e-10 + (u − u₀)²)`), V-shaped (where two
    /// bounds cross: `|u − u₀|`), at an end of the bracket (a slope), and a flat
    /// stretch. Each minimum's place to 2e-9 of the bracket of the closed form (1e-9 is
    /// the tolerance of both searches; on the smooth ones, whose place is only known to
    /// about √ε, their value to a rounding), its value never below the true least value, and
    /// within 1e-8 of the golden search's plus 2e-9 (what 2e-9 of a unit slope moves);
    /// on the smooth ones in fewer than its 44 points (the parabolas find the valley in
    /// a few; closing the bracket to its tolerance round it takes the rest).
    #[test]
    fn brent_finds_the_minima_the_golden_search_found() {
        use std::cell::Cell;
        type Valley = (&'static str, fn(f64) -> f64, f64, bool);
        let cases: [Valley; 6] = [
            ("parabola", |u| (u - 0.3137).powi(2) + 2.0, 0.3137, true),
            ("cosine", |u| -(3.0 * u - 0.5).cos(), 0.5 / 3.0, true),
            (
                "narrow",
                |u| (1e-10 + (u - 0.712_345).powi(2)).sqrt(),
                0.712_345,
                false,
            ),
            ("kink", |u| (u - 0.271_828).abs(), 0.271_828, false),
            ("slope", |u| 5.0 - u, 1.0, false),
            ("flat", |u| 1.0 + (u - 0.4).max(0.0), f64::NAN, false),
        ];
        for (name, f, at, smooth) in cases {
            let points = Cell::new(0);
            let (u, v) = super::super::brent_min(0.0, 1.0, |u| {
                points.set(points.get() + 1);
                Some(f(u))
            })
            .unwrap();
            assert_eq!(v, f(u), "{name}");
            if at.is_finite() {
                // (On a smooth valley the place is only known to about √ε, where the
                // value stops changing: there, the value to a rounding.)
                if smooth {
                    assert!((v - f(at)).abs() <= 4e-16 * f(at).abs(), "{name}: {v}");
                } else {
                    assert!((u - at).abs() <= 2e-9, "{name}: {u} against {at}");
                }
                assert!(v >= f(at) - 1e-15, "{name}: {v} below {}", f(at));
            } else {
                assert!(u <= 0.4, "{name}: {u}");
            }
            let golden = f(golden_reference(0.0, 1.0, f));
            assert!(
                (v - golden).abs() <= 1e-8 * golden.abs() + 2e-9,
                "{name}: {v} against the golden search's {golden}"
            );
            if smooth {
                assert!(points.get() < 44, "{name}: {} points", points.get());
            }
        }
    }

    #[test]
    fn a_straight_piece_stays_whole() {
        let c = SplitCurve {
            degree: 3,
            knots: vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
            ctrl: vec![
                [0.0, 0.0, 0.0, 1.0],
                [1.0, 1.0, 0.0, 1.0],
                [2.0, 2.0, 0.0, 1.0],
                [3.0, 3.0, 0.0, 1.0],
            ],
        };
        assert_eq!(split_by_speed(c, &Machine::default(), 1000.0).len(), 1);
    }

    #[test]
    fn a_sharp_bend_gets_a_short_slow_block_and_the_rest_runs_at_the_feed() {
        let c = bend();
        let m = Machine::default();
        let pieces = split_by_speed(c.clone(), &m, 3000.0);
        assert!(pieces.len() >= 3, "{} pieces", pieces.len());
        // The pieces join exactly and cover the domain.
        assert_eq!(pieces[0].knots[0], 0.0);
        assert_eq!(*pieces.last().unwrap().knots.last().unwrap(), 1.0);
        for w in pieces.windows(2) {
            assert_eq!(w[0].knots.last(), w[1].knots.first());
        }
        // The slowest piece holds the bend and is a small part of the whole.
        let slow = pieces
            .iter()
            .find(|p| p.knots[0] <= 0.5 && *p.knots.last().unwrap() >= 0.5)
            .unwrap();
        let (a, b) = (slow.knots[0], *slow.knots.last().unwrap());
        assert!(b - a < 0.05, "slow piece {a}..{b}");
    }
}
