//! Corner blending under `G64 P<tol>`: where two straight feed moves meet at an angle,
//! both are trimmed near the corner and joined by a quintic Bézier curve (an exact
//! polynomial NURBS, [`Move::Nurbs`]) that is tangent and curvature-continuous (G2) with
//! both lines and stays within `tol` of the programmed corner. The planner then passes
//! the corner at the speed the blend's curvature allows instead of stopping there.
//!
//! # The blend
//!
//! Corner `C`, incoming unit direction `u1`, outgoing `u2`, turn angle `θ` (the angle
//! between `u1` and `u2`: 0 straight on, 180° a reversal), trim length `L` on each leg.
//! The six control points lie three on each leg:
//!
//! ```text
//! P0 = C − L·u1    P1 = C − c1·L·u1    P2 = C − c2·L·u1
//! P3 = C + c2·L·u2 P4 = C + c1·L·u2    P5 = C + L·u2        (1 > c1 > c2 >= 0)
//! ```
//!
//! `P0, P1, P2` on one line make the curve leave the first leg along `u1` with zero
//! curvature (the curvature of a Bézier curve at its end is `(n−1)/n · |ΔP0 × ΔP1| /
//! |ΔP0|³`), and likewise into the second leg: line, blend and line join with one
//! tangent and no jump in curvature, so the planner's junction test sees them as smooth.
//!
//! # Deviation, in closed form
//!
//! With the quintic Bernstein polynomials `B0…B5`, `B(t) − C = L·(−f(t)·u1 + g(t)·u2)`,
//! `f = B0 + c1·B1 + c2·B2`, `g = c2·B3 + c1·B4 + B5`, and `f(t) = g(1 − t)`. The
//! coefficients of `g` never decrease, so `g` never decreases (and `f` never increases).
//! At the middle `f = g = m`, `m = (1 + 5·c1 + 10·c2)/32`, so the blend passes the
//! corner at the distance
//!
//! ```text
//! h = |B(½) − C| = L·m·|u2 − u1| = 2·L·m·sin(θ/2).
//! ```
//!
//! For `t <= ½` (the other half is the mirror image) the foot of `B(t)` on the first
//! leg's line lies `L·(−f + g·cos θ)` along `u1` from `C`: in `[−L, 0]`, since
//! `0 <= g <= f` and `f + g <= 1`. So `B(t)`'s distance from the programmed path is at
//! most its distance from that line, `L·g(t)·sin θ <= L·m·sin θ = h·cos(θ/2)`. The other
//! way round, a point `X` of the trimmed piece of leg 1 is either the foot of some
//! `B(t)`, `t <= ½` (then within `L·m·sin θ`), or lies between `C` and the foot of
//! `B(½)`, and then `|X − B(½)| <= |C − B(½)| = h`. Hence the two paths (the programmed
//! corner and the blended one) are within `h` of each other both ways (their Hausdorff
//! distance is at most `h`); `L` is chosen so that `h <= tol`. This is the corner
//! deviation of industrial controls (e.g. ISG/Beckhoff's "distance between the
//! programmed corner point and the interim point of the contouring curve", LinuxCNC's
//! blend tolerance): the corner itself is missed by at most `tol`, and no point of the
//! blend is farther than `tol·cos(θ/2)` from the programmed lines.
//!
//! # Trim length
//!
//! `L = min(tol / (2·m·sin(θ/2)), ½·|leg 1|, ½·|leg 2|)`: as much as the tolerance
//! allows, but never more than half of either line, so the blends at the two ends of a
//! line never overlap (a line used up by both becomes no block at all; the two blends
//! then meet with one tangent and zero curvature). Short legs get shorter blends and
//! correspondingly less deviation.
//!
//! # The shape ratios `c1`, `c2`
//!
//! With the deviation fixed, the speed through a blend is set by its peak curvature `κ`
//! (`v²·κ` within the acceleration) and, for blends of tolerances below about a
//! millimetre, by the peak rate of change of curvature `dκ/ds` (`v³·dκ/ds` within the
//! jerk), which is the tighter. [`RATIOS`] holds, per 10° of turn, the `c1, c2` that
//! minimise `max dκ/ds · h²` (found offline by a grid search refined by pattern search
//! over dense samples; the optimum is flat, and the table's values are within 4 % of it).
//! They barely move for gentle turns (`c1 ≈ 0.6`, `c2 ≈ 0.15`) and approach 1 towards a
//! reversal. Between rows they are interpolated linearly; the deviation formula holds for
//! any `c1, c2`.
//!
//! # Where it applies
//!
//! A corner is blended when the move that ends at it is a feed line (`G1`, not `G0`)
//! programmed under `G64 P<tol>` with `tol > 0`, and the next motion is a feed line
//! (only path-mode changes may stand between them). Not blended (the exact path, as
//! before): rapids (their path is kept exact, clear of fixtures, and a feed/rapid change
//! stops anyway), corners with arcs or NURBS, turns below [`MIN_TURN_RAD`] (nothing to
//! gain), turns above [`MAX_TURN_DEG`] (a reversal: an exact stop, see there), legs
//! shorter than [`MIN_LEG_MM`], and corners with a dwell, stop, spindle change or
//! program end between the lines. The blend carries the source line of the move that
//! ends at the corner: it replaces that move's end, and the next line has not begun
//! (a feed hold inside the blend stops "in" that line, as the reports should say). Its
//! feed is the lower of the two lines' feeds.

use super::{dot, sub};
use crate::program::{Move, PathControl};
use shared::path::norm;
use std::borrow::Cow;

/// Turns below this (radians) are left as they are: a kink of 1e-4 rad costs the
/// planner nothing (its junction speed `A·T/θ` is far above any feed).
pub const MIN_TURN_RAD: f64 = 1e-4;

/// Turns above this (degrees) are reversals: an exact stop, no blend. Near a reversal
/// the optimal blend is a hairpin whose `dκ/ds` grows without bound (84 `/h²` at 170°
/// against 0.22 at 90°): at `P0.01` it would pass at about 0.3 mm/s, a stop in all but
/// name, and at 180° there is no blend at all.
pub const MAX_TURN_DEG: f64 = 170.0;

/// Legs shorter than this (mm) are degenerate: their corners are not blended.
pub const MIN_LEG_MM: f64 = 1e-6;

/// A line whose trimmed remainder is shorter than this (mm) is left out.
const MIN_REST_MM: f64 = 1e-9;

/// Shape ratios per turn angle: `(turn in degrees, c1, c2)`, see the module page.
const RATIOS: [(f64, f64, f64); 18] = [
    (0.0, 0.600, 0.150),
    (10.0, 0.600, 0.150),
    (20.0, 0.600, 0.150),
    (30.0, 0.605, 0.150),
    (40.0, 0.610, 0.160),
    (50.0, 0.605, 0.180),
    (60.0, 0.600, 0.200),
    (70.0, 0.605, 0.225),
    (80.0, 0.610, 0.250),
    (90.0, 0.616, 0.278),
    (100.0, 0.637, 0.300),
    (110.0, 0.650, 0.347),
    (120.0, 0.675, 0.394),
    (130.0, 0.706, 0.447),
    (140.0, 0.747, 0.506),
    (150.0, 0.791, 0.591),
    (160.0, 0.847, 0.694),
    (170.0, 0.916, 0.825),
];

/// `(c1, c2)` for a turn of `theta_deg`, interpolated in [`RATIOS`].
pub fn ratios(theta_deg: f64) -> (f64, f64) {
    let last = RATIOS[RATIOS.len() - 1];
    if theta_deg >= last.0 {
        return (last.1, last.2);
    }
    let i = RATIOS
        .partition_point(|r| r.0 <= theta_deg)
        .clamp(1, RATIOS.len() - 1);
    let (a, b) = (RATIOS[i - 1], RATIOS[i]);
    let s = ((theta_deg - a.0) / (b.0 - a.0)).clamp(0.0, 1.0);
    (a.1 + s * (b.1 - a.1), a.2 + s * (b.2 - a.2))
}

/// `m = g(½)`: the blend passes the corner at `2·L·m·sin(θ/2)`.
pub fn mid_weight(c1: f64, c2: f64) -> f64 {
    (1.0 + 5.0 * c1 + 10.0 * c2) / 32.0
}

/// The moves with every eligible corner blended (see the module page); the moves
/// themselves, not a copy, when the program never selects `G64 P` with a tolerance.
pub fn corners(moves: &[Move]) -> Cow<'_, [Move]> {
    let blends_anywhere = moves.iter().any(|m| {
        matches!(m, Move::PathMode { control: PathControl::Blend { tolerance_mm: Some(t), .. }, .. } if *t > 0.0)
    });
    if !blends_anywhere {
        return Cow::Borrowed(moves);
    }
    let plans = plan_corners(moves);
    if plans.iter().all(Option::is_none) {
        return Cow::Borrowed(moves);
    }
    Cow::Owned(emit(moves, &plans))
}

/// A corner to blend: at the end of the line at the index it is stored under, into the
/// feed line at `next`.
#[derive(Debug, Clone, Copy)]
struct Corner {
    next: usize,
    corner: [f64; 3],
    u1: [f64; 3],
    u2: [f64; 3],
    trim_mm: f64,
    c1: f64,
    c2: f64,
}

/// The tolerance in force for each move (mm; `None` where corners are not blended) and,
/// for each feed line that ends at a corner to blend, the corner.
fn plan_corners(moves: &[Move]) -> Vec<Option<Corner>> {
    let mut plans = vec![None; moves.len()];
    let mut tol: Option<f64> = None;
    for (i, m) in moves.iter().enumerate() {
        match m {
            Move::PathMode { control, .. } => {
                tol = match control {
                    PathControl::Blend {
                        tolerance_mm: Some(t),
                        ..
                    } if *t > 0.0 => Some(*t),
                    _ => None,
                };
            }
            Move::Line {
                from,
                to,
                rapid: false,
                ..
            } => {
                let Some(t) = tol else { continue };
                // The next motion, with only path-mode changes in between.
                let next = moves[i + 1..]
                    .iter()
                    .position(|n| !matches!(n, Move::PathMode { .. }))
                    .map(|k| i + 1 + k);
                if let Some(j) = next {
                    if let Move::Line {
                        from: f2,
                        to: t2,
                        rapid: false,
                        ..
                    } = &moves[j]
                    {
                        plans[i] = corner(*from, *to, *f2, *t2, t).map(|mut c| {
                            c.next = j;
                            c
                        });
                    }
                }
            }
            _ => {}
        }
    }
    plans
}

/// The blend of the corner between the lines `a0 → a1` and `b0 → b1` within `tol`, if
/// it gets one.
fn corner(a0: [f64; 3], a1: [f64; 3], b0: [f64; 3], b1: [f64; 3], tol: f64) -> Option<Corner> {
    let (da, db) = (sub(a1, a0), sub(b1, b0));
    let (la, lb) = (norm(da), norm(db));
    if la < MIN_LEG_MM || lb < MIN_LEG_MM || norm(sub(b0, a1)) > MIN_REST_MM {
        return None;
    }
    let u1 = da.map(|x| x / la);
    let u2 = db.map(|x| x / lb);
    // atan2 of sine and cosine: accurate at both ends of the range.
    let theta = norm(cross(u1, u2)).atan2(dot(u1, u2));
    if !(MIN_TURN_RAD..=MAX_TURN_DEG.to_radians()).contains(&theta) {
        return None;
    }
    let (c1, c2) = ratios(theta.to_degrees());
    let m = mid_weight(c1, c2);
    let trim_mm = (tol / (2.0 * m * (0.5 * theta).sin()))
        .min(0.5 * la)
        .min(0.5 * lb);
    Some(Corner {
        next: 0,
        corner: a1,
        u1,
        u2,
        trim_mm,
        c1,
        c2,
    })
}

/// What is left of a trimmed line: start, end, and whether it is kept as a move.
type Piece = ([f64; 3], [f64; 3], bool);

/// The moves with the lines trimmed and the blends inserted after the lines they end.
fn emit(moves: &[Move], plans: &[Option<Corner>]) -> Vec<Move> {
    // Trim at the start of each line (from the corner before it).
    let mut trim_start = vec![0.0; moves.len()];
    for c in plans.iter().flatten() {
        trim_start[c.next] = c.trim_mm;
    }
    // Where each line's remaining piece starts and ends, and whether it is left at all.
    // A line used up by the blends at both ends leaves one point, shared by both.
    let mut pieces: Vec<Option<Piece>> = vec![None; moves.len()];
    for (i, m) in moves.iter().enumerate() {
        if let Move::Line { from, to, .. } = m {
            let (a, b) = (trim_start[i], plans[i].map_or(0.0, |c| c.trim_mm));
            if a == 0.0 && b == 0.0 {
                continue;
            }
            let d = sub(*to, *from);
            let len = norm(d);
            let u = d.map(|x| x / len);
            let s = add(*from, u.map(|x| x * a));
            let e = sub(*to, u.map(|x| x * b));
            if len - a - b > MIN_REST_MM {
                pieces[i] = Some((
                    if a > 0.0 { s } else { *from },
                    if b > 0.0 { e } else { *to },
                    true,
                ));
            } else {
                let mid = [0, 1, 2].map(|k| 0.5 * (s[k] + e[k]));
                pieces[i] = Some((mid, mid, false));
            }
        }
    }
    let mut out = Vec::with_capacity(moves.len() + plans.iter().flatten().count());
    for (i, m) in moves.iter().enumerate() {
        let Move::Line {
            line, rapid, feed, ..
        } = m
        else {
            out.push(m.clone());
            continue;
        };
        let Some((s, e, keep)) = pieces[i] else {
            out.push(m.clone());
            continue;
        };
        if keep {
            out.push(Move::Line {
                line: *line,
                from: s,
                to: e,
                rapid: *rapid,
                feed: *feed,
            });
        }
        if let Some(c) = plans[i] {
            let Some((next_start, _, _)) = pieces[c.next] else {
                continue;
            };
            let next_feed = match &moves[c.next] {
                Move::Line { feed, .. } => *feed,
                _ => *feed,
            };
            out.push(Move::Nurbs {
                line: *line,
                degree: 5,
                knots: vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
                ctrl: control_points(&c, e, next_start),
                feed: feed.min(next_feed),
            });
        }
    }
    out
}

/// The blend's six control points (weights 1), from the exact trim points `start` and
/// `end` that the lines' pieces end and start at.
fn control_points(c: &Corner, start: [f64; 3], end: [f64; 3]) -> Vec<[f64; 4]> {
    let on1 = |k: f64| sub(c.corner, c.u1.map(|x| x * k * c.trim_mm));
    let on2 = |k: f64| add(c.corner, c.u2.map(|x| x * k * c.trim_mm));
    [start, on1(c.c1), on1(c.c2), on2(c.c2), on2(c.c1), end]
        .iter()
        .map(|p| [p[0], p[1], p[2], 1.0])
        .collect()
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[cfg(test)]
mod tests;
