//! Where the tool's path along a NURBS move meets the path along the move before or
//! after it, at a concave corner under cutter compensation ([`super::comp`]).
//!
//! At a concave corner the two offset paths cross short of the programmed corner, and the
//! tool turns where they cross: the move before is cut short there and the move after
//! starts there. For lines and arcs LinuxCNC works the point out in closed form; beside
//! a NURBS move, whose offset is a fitted cubic B-spline ([`super::offset`]), it is found
//! here:
//!
//! * **Against a line or a circle** (the offset of a straight move or an arc): the
//!   spline's signed distance to it (to the line's left; outside the circle) is sampled
//!   from the spline's end at the corner, 32 times a knot span, and the first change of
//!   sign is bisected to the last bit of the parameter.
//! * **Against another spline** (a NURBS after a NURBS): both are sampled as densely as
//!   polylines, each segment of one tested against those of the other that share a cell
//!   of a grid; each crossing found is refined by Newton's method on `A(s) = B(t)`. The
//!   tool turns at the crossing nearest the end of the first curve, and that must also
//!   be the one nearest the start of the second: otherwise the two paths cross more
//!   than once near the corner and which way round the tool should go is not clear
//!   (refused by the caller).
//!
//! Neither search compares the curve with moves beyond its neighbours, as LinuxCNC does
//! not.

use shared::nurbs::{split_at, SplitCurve};

/// Samples a knot span of the spline gets.
const PER_SPAN: usize = 32;

/// The offset path of the move on the other side of the corner.
#[derive(Clone, Copy, Debug)]
pub(super) enum Other {
    /// The line through `p` along `dir` (not necessarily a unit vector).
    Line { p: [f64; 2], dir: [f64; 2] },
    /// The circle round `c` of radius `r`.
    Circle { c: [f64; 2], r: f64 },
}

/// A fitted offset as a move holds it: cubic, clamped, control points `[x, y, z, 1]`.
pub(super) struct Spline<'a> {
    pub knots: &'a [f64],
    pub ctrl: &'a [[f64; 4]],
}

impl Spline<'_> {
    fn degree(&self) -> usize {
        self.knots.len() - self.ctrl.len() - 1
    }

    fn domain(&self) -> (f64, f64) {
        let p = self.degree();
        (self.knots[p], self.knots[self.ctrl.len()])
    }

    fn at(&self, u: f64) -> [f64; 2] {
        let e = shared::nurbs::eval(self.degree(), self.knots, self.ctrl, u);
        [e.p[0], e.p[1]]
    }

    fn d1(&self, u: f64) -> [f64; 2] {
        let e = shared::nurbs::eval(self.degree(), self.knots, self.ctrl, u);
        [e.d1[0], e.d1[1]]
    }

    /// The parameters it is sampled at, in order along the curve: [`PER_SPAN`] a
    /// non-empty knot span, both ends included.
    fn samples(&self) -> Vec<f64> {
        let (lo, hi) = self.domain();
        let mut us = Vec::new();
        for w in self.knots.windows(2) {
            let (a, b) = (w[0].max(lo), w[1].min(hi));
            if b > a {
                us.extend((0..PER_SPAN).map(|i| a + (b - a) * i as f64 / PER_SPAN as f64));
            }
        }
        us.push(hi);
        us
    }
}

/// The signed distance of `q` to `other`: to the line's left, outside the circle.
fn side(other: &Other, q: [f64; 2]) -> f64 {
    match *other {
        Other::Line { p, dir } => {
            let len = dir[0].hypot(dir[1]);
            (dir[0] * (q[1] - p[1]) - dir[1] * (q[0] - p[0])) / len
        }
        Other::Circle { c, r } => (q[0] - c[0]).hypot(q[1] - c[1]) - r,
    }
}

/// Where `s` first meets `other`, searched from its start (`from_start`) or back from
/// its end: the spline's parameter there. `None`: they do not meet.
///
/// A change of sign between two samples is bisected. Where the distance dips between
/// samples without changing sign there (the curve may pass in and out of a small
/// circle, or across a line and back, between two samples), the dip is searched for its
/// least (Brent's method) and, if that crosses, the crossing before it is bisected.
pub(super) fn spline_other(s: &Spline, other: &Other, from_start: bool) -> Option<f64> {
    let mut us = s.samples();
    if !from_start {
        us.reverse();
    }
    // Positive on the corner's side.
    let g0 = side(other, s.at(us[0]));
    if g0 == 0.0 {
        return Some(us[0]);
    }
    let sign = g0.signum();
    let g = |u: f64| sign * side(other, s.at(u));
    // The first parameter where `g` is not positive, between `a` (where it is) and `b`
    // (where it is not).
    let bisect = |mut a: f64, mut b: f64| {
        for _ in 0..200 {
            let m = 0.5 * (a + b);
            if m == a || m == b {
                break;
            }
            if g(m) > 0.0 {
                a = m;
            } else {
                b = m;
            }
        }
        b
    };
    let gs: Vec<f64> = us.iter().map(|&u| g(u)).collect();
    for i in 1..us.len() {
        if gs[i] <= 0.0 {
            return Some(bisect(us[i - 1], us[i]));
        }
        // A dip at sample i: the least between its neighbours.
        if i + 1 < us.len() && gs[i] < gs[i - 1] && gs[i] <= gs[i + 1] {
            let (lo, hi) = (us[i - 1].min(us[i + 1]), us[i - 1].max(us[i + 1]));
            let (x, least) = crate::brent::refine_min(lo, hi, us[i], g);
            if least <= 0.0 {
                return Some(bisect(us[i - 1], x));
            }
        }
    }
    None
}

/// Whether segments `a0 a1` and `b0 b1` cross or touch; where, as fractions along each.
fn segments(a0: [f64; 2], a1: [f64; 2], b0: [f64; 2], b1: [f64; 2]) -> Option<(f64, f64)> {
    let r = [a1[0] - a0[0], a1[1] - a0[1]];
    let q = [b1[0] - b0[0], b1[1] - b0[1]];
    let den = r[0] * q[1] - r[1] * q[0];
    if den == 0.0 {
        return None;
    }
    let w = [b0[0] - a0[0], b0[1] - a0[1]];
    let x = (w[0] * q[1] - w[1] * q[0]) / den;
    let y = (w[0] * r[1] - w[1] * r[0]) / den;
    ((0.0..=1.0).contains(&x) && (0.0..=1.0).contains(&y)).then_some((x, y))
}

/// How two splines meet at a concave corner, the first (`a`) ending there and the
/// second (`b`) starting there.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Splines {
    /// They cross once near the corner: at `s` on `a` and `t` on `b`.
    At { s: f64, t: f64 },
    /// They never cross.
    Apart,
    /// The crossing nearest the end of `a` is not the one nearest the start of `b`.
    Tangled,
}

/// Where `a`, near its end, meets `b`, near its start (module page).
pub(super) fn splines(a: &Spline, b: &Spline) -> Splines {
    let (ua, ub) = (a.samples(), b.samples());
    let (pa, pb): (Vec<[f64; 2]>, Vec<[f64; 2]>) = (
        ua.iter().map(|&u| a.at(u)).collect(),
        ub.iter().map(|&u| b.at(u)).collect(),
    );
    let longest = pa
        .windows(2)
        .chain(pb.windows(2))
        .map(|w| (w[0][0] - w[1][0]).hypot(w[0][1] - w[1][1]))
        .fold(1e-9f64, f64::max);
    let key = |x: f64| (x / longest).floor() as i64;
    let mut grid: std::collections::HashMap<(i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    for (j, w) in pb.windows(2).enumerate() {
        for gx in key(w[0][0].min(w[1][0]))..=key(w[0][0].max(w[1][0])) {
            for gy in key(w[0][1].min(w[1][1]))..=key(w[0][1].max(w[1][1])) {
                grid.entry((gx, gy)).or_default().push(j);
            }
        }
    }
    let mut hits: Vec<(f64, f64)> = Vec::new();
    for (i, w) in pa.windows(2).enumerate() {
        let mut seen: Vec<usize> = Vec::new();
        for gx in key(w[0][0].min(w[1][0]))..=key(w[0][0].max(w[1][0])) {
            for gy in key(w[0][1].min(w[1][1]))..=key(w[0][1].max(w[1][1])) {
                for &j in grid.get(&(gx, gy)).into_iter().flatten() {
                    if seen.contains(&j) {
                        continue;
                    }
                    seen.push(j);
                    if let Some((x, y)) = segments(w[0], w[1], pb[j], pb[j + 1]) {
                        let s0 = ua[i] + x * (ua[i + 1] - ua[i]);
                        let t0 = ub[j] + y * (ub[j + 1] - ub[j]);
                        hits.push(refine(a, b, s0, t0));
                    }
                }
            }
        }
    }
    let Some(&(s, t)) = hits.iter().max_by(|x, y| x.0.total_cmp(&y.0)) else {
        return Splines::Apart;
    };
    // (One crossing found twice, on two neighbouring segments, refines to one point.)
    let first_t = hits.iter().map(|h| h.1).fold(f64::INFINITY, f64::min);
    let (lo, hi) = b.domain();
    if t - first_t > 1e-9 * (hi - lo) {
        return Splines::Tangled;
    }
    Splines::At { s, t }
}

/// Newton's method on `a(s) = b(t)` from `(s, t)`, each kept in its domain; the start
/// where it does not settle.
fn refine(a: &Spline, b: &Spline, s0: f64, t0: f64) -> (f64, f64) {
    let (da, db) = (a.domain(), b.domain());
    let (mut s, mut t) = (s0, t0);
    for _ in 0..50 {
        let (p, q) = (a.at(s), b.at(t));
        let f = [p[0] - q[0], p[1] - q[1]];
        if f[0].hypot(f[1]) < 1e-14 {
            break;
        }
        let (ta, tb) = (a.d1(s), b.d1(t));
        // [ta  -tb] [ds dt]ᵀ = −f
        let det = -ta[0] * tb[1] + ta[1] * tb[0];
        if det == 0.0 {
            return (s0, t0);
        }
        let ds = (-f[0] * -tb[1] - -f[1] * -tb[0]) / det;
        let dt = (ta[0] * -f[1] - ta[1] * -f[0]) / det;
        s = (s + ds).clamp(da.0, da.1);
        t = (t + dt).clamp(db.0, db.1);
    }
    let (p, q) = (a.at(s), b.at(t));
    if (p[0] - q[0]).hypot(p[1] - q[1]) > 1e-9 {
        return (s0, t0);
    }
    (s, t)
}

/// The part of a cubic offset `(knots, ctrl)` from `from` to `to` (parameters within
/// its domain, `from < to`), exactly, by knot insertion.
pub(super) fn piece(
    knots: &[f64],
    ctrl: &[[f64; 4]],
    from: f64,
    to: f64,
) -> (Vec<f64>, Vec<[f64; 4]>) {
    let mut c = SplitCurve {
        degree: knots.len() - ctrl.len() - 1,
        knots: knots.to_vec(),
        ctrl: ctrl.to_vec(),
    };
    let (lo, hi) = (c.knots[c.degree], c.knots[c.ctrl.len()]);
    if from > lo {
        c = split_at(&c, from).1;
    }
    if to < hi {
        c = split_at(&c, to).0;
    }
    (c.knots, c.ctrl)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight cubic from (0, 0) to (10, 0), parameter = x.
    fn straight(y: f64) -> (Vec<f64>, Vec<[f64; 4]>) {
        let knots = vec![0.0, 0.0, 0.0, 0.0, 5.0, 10.0, 10.0, 10.0, 10.0];
        let ctrl = [0.0, 10.0 / 6.0, 5.0, 50.0 / 6.0, 10.0]
            .iter()
            .map(|&x| [x, y, 0.0, 1.0])
            .collect();
        (knots, ctrl)
    }

    /// A line crossing a straight spline is met at the closed-form point, searched from
    /// either end; a line beside it is not met.
    #[test]
    fn a_line_meets_a_straight_spline_where_it_crosses() {
        let (k, c) = straight(0.0);
        let s = Spline {
            knots: &k,
            ctrl: &c,
        };
        assert!((s.at(3.7)[0] - 3.7).abs() < 1e-12);
        let line = Other::Line {
            p: [3.0, -1.0],
            dir: [1.0, 2.0],
        };
        for from_start in [true, false] {
            let u = spline_other(&s, &line, from_start).unwrap();
            assert!((u - 3.5).abs() < 1e-12, "{u}");
        }
        let beside = Other::Line {
            p: [0.0, 1.0],
            dir: [1.0, 0.0],
        };
        assert_eq!(spline_other(&s, &beside, true), None);
    }

    /// A circle crossing a straight spline twice is met at the crossing nearest the end
    /// searched from: x = 5 ± 3 for the circle of radius 5 round (5, 4).
    #[test]
    fn a_circle_is_met_at_the_crossing_nearest_the_end_searched_from() {
        let (k, c) = straight(0.0);
        let s = Spline {
            knots: &k,
            ctrl: &c,
        };
        let circle = Other::Circle {
            c: [5.0, 4.0],
            r: 5.0,
        };
        let a = spline_other(&s, &circle, true).unwrap();
        let b = spline_other(&s, &circle, false).unwrap();
        assert!(
            (a - 2.0).abs() < 1e-12 && (b - 8.0).abs() < 1e-12,
            "{a} {b}"
        );
    }

    /// A small circle that a straight spline passes in and out of between two samples
    /// (32 a span: 3.4375 and 3.59375 here) is still met, at the closed-form crossing.
    #[test]
    fn a_small_circle_between_two_samples_is_met() {
        let (k, c) = straight(0.0);
        let s = Spline {
            knots: &k,
            ctrl: &c,
        };
        // Round (3.515, 0.05), radius 0.06: crossings at x = 3.515 ± √0.0011.
        let circle = Other::Circle {
            c: [3.515, 0.05],
            r: 0.06,
        };
        let half = 0.0011f64.sqrt();
        let a = spline_other(&s, &circle, true).expect("met from the start");
        let b = spline_other(&s, &circle, false).expect("met from the end");
        assert!((a - (3.515 - half)).abs() < 1e-12, "{a}");
        assert!((b - (3.515 + half)).abs() < 1e-12, "{b}");
    }

    /// Two splines crossing once meet there; parallel ones never do; one crossing the
    /// other twice is tangled when the order of the crossings disagrees.
    #[test]
    fn two_splines_meet_where_they_cross() {
        let (ka, ca) = straight(0.0);
        let a = Spline {
            knots: &ka,
            ctrl: &ca,
        };
        // b: the straight spline turned a quarter round about (6, 0): x = 6, y = t − 4.
        let cb: Vec<[f64; 4]> = ca.iter().map(|p| [6.0, p[0] - 4.0, 0.0, 1.0]).collect();
        let b = Spline {
            knots: &ka,
            ctrl: &cb,
        };
        match splines(&a, &b) {
            Splines::At { s, t } => assert!((s - 6.0).abs() < 1e-12 && (t - 4.0).abs() < 1e-12),
            other => panic!("{other:?}"),
        }
        let (kc, cc) = straight(1.0);
        let c = Spline {
            knots: &kc,
            ctrl: &cc,
        };
        assert_eq!(splines(&a, &c), Splines::Apart);
        // d: a parabola-like arch y = 4 − (x − 5)²/4 crossing a at x = 1 and x = 9,
        // running from x = 0 to 10 in the same direction: nearest a's end is x = 9, which
        // is not d's first crossing.
        let kd = vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let cd = vec![
            [0.0, -2.25, 0.0, 1.0],
            [5.0, 10.25, 0.0, 1.0],
            [10.0, -2.25, 0.0, 1.0],
        ];
        let d = Spline {
            knots: &kd,
            ctrl: &cd,
        };
        assert_eq!(splines(&a, &d), Splines::Tangled);
    }

    /// A piece of a spline is the same curve over the same parameters.
    #[test]
    fn a_piece_is_the_same_curve() {
        let (k, c) = straight(2.0);
        let (pk, pc) = piece(&k, &c, 1.25, 7.5);
        let p = Spline {
            knots: &pk,
            ctrl: &pc,
        };
        assert_eq!(p.domain(), (1.25, 7.5));
        for u in [1.25, 3.0, 5.0, 7.5] {
            let (x, y) = (
                p.at(u),
                Spline {
                    knots: &k,
                    ctrl: &c,
                }
                .at(u),
            );
            assert!((x[0] - y[0]).hypot(x[1] - y[1]) < 1e-12);
        }
    }
}
