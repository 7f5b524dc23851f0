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
//! That shape is right where the jerk binds. Where the acceleration does (a machine
//! whose jerk is high next to its acceleration, as LinuxCNC's limits), a rounder shape
//! passes gentle turns faster: [`corners_on`] chooses each corner's shape for its
//! machine ([`shape`]), [`corners`] keeps the table's.
//!
//! # Blends that pay
//!
//! A blend is passed at the speed its curvature and its rate of change allow, and the
//! planner holds the whole blend block to that speed. At a small tolerance and a large
//! turn that is a crawl: the ratios above make `dκ/ds` nearly constant along the blend
//! (about `0.21/h²` at 90°, a clothoid-like ramp up and down of the curvature), so no
//! part of the blend is much faster than the rest, and at `P0.01` and 90° the built-in
//! machine passes it at about 2 mm/s over its 0.055 mm, slower than stopping exactly at
//! the corner. [`corners_on`] therefore weighs each corner, in program order, between its
//! blend and its exact path (what `G61` does there: an exact stop above
//! `corner_angle_deg`, the kink's junction speed below) and keeps the blend only when it
//! is not slower:
//!
//! * first a screen ([`screen`]): where the exact corner is passed at least as fast as
//!   the blend's cap (first: at the feed itself, found before the blend is planned at
//!   all) and no other kink is within two steps of it at the feed (closer kinks are
//!   slowed as a run, which the screen's two long lines do not show), or every run of
//!   close kinks it may be in is passed at the feed too ([`run_at_feed`]), it is left exact:
//!   no blend can be quicker there but for the few µm of path it cuts (a tie goes to
//!   the exact path here, where stepping keeps the blend: 0.01–0.02 % longer on 5 000
//!   chords of a circle and of a raster on LinuxCNC's machine, nothing on the built-in
//!   one or on the repository's programs). That is nearly every corner of dense CAM output with small turns, and planning
//!   each blend alone cost ~0.15 ms a corner (5 000 chords of a circle, 0.5° turns:
//!   `cnc check` 3.84 s → 0.01 s; closer chords, 0.08 mm at F3000, whose kinks are
//!   within two steps of each other: 95 µs → 3 µs a line). Left exact, a dense run may
//!   still lose a little where the machine speeds up or slows down along it (the
//!   profile keeps what the run's direction change leaves at the feed): R20 in 0.1 mm
//!   chords on LinuxCNC's limits, 9.430 s stepped, 9.489 s screened. Otherwise each way is taken as one slow stretch in
//!   the feed `F` of the two lines, the blend at the cap the planner gives it alone over
//!   its length, the exact corner at the speed the planner passes it at between two long
//!   lines. Each costs `2·(T(F→v) − D(F→v)/F) + ℓ·(1/v − 1/F)` against running on at `F`
//!   (`T`, `D`: the jerk-limited speed change's time and distance under the machine's
//!   weakest acceleration and jerk). Where one way loses at least twice as little (and
//!   2 ms less), that way is taken. Two closed forms spare most of the planning there,
//!   each giving the answer planning gives: a turn far below the kink's bound is passed
//!   at the feed ([`surely_at_feed`]), and a blend whose highest possible speed
//!   ([`blend_speed_bound`]) already loses clearly more is not planned;
//! * otherwise both ways are planned and stepped through the interpolator's engine
//!   ([`crate::estimate`], what `cnc check --estimate` runs) over the corner's
//!   neighbourhood: the lines joined to it by blendable corners, as far as the machine
//!   needs to stop from their feed twice over on each side, or to the nearest exact
//!   stop ([`stops`]: the machine is at rest there either way), from rest to rest, the
//!   corners before it as already decided and those after it exact. The blend is kept if
//!   its cycles are no more. (Ending at the stops changed none of the 82 estimates of
//!   the repository's programs and halved `cnc check` on a zigzag of short lines, 8.3 →
//!   4.8 s for 5 000 lines);
//! * then each chain of corners (each at the end of the line the one before goes into,
//!   [`chains`]) is stepped from rest to rest as decided and with every corner the screen
//!   left open blended, and the quicker kept: not whole, but each stretch of it where the
//!   two differ, with four stopping distances on either side ([`differing_stretches`]).
//!   Corner by corner, one blend among exact stops may not pay where the chain blended
//!   does: a zigzag of 0.5 mm lines at 22.6°, `P0.01`, F3000 on the built-in machine was
//!   left exact at every corner, 4.141 s for 60 lines against 2.528 s blended.
//!
//! The corners left exact are put under `G61` (a path-mode change before the line that
//! ends at the corner and the mode in force back after it), so the result is final:
//! [`corners`] and [`corners_on`] return it unchanged. Nothing emitted changes shape: a
//! kept blend is the blend above, within `tol`; a corner left exact is the programmed
//! corner.
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

use super::{add, dot, sub};
use crate::program::{Move, PathControl};
use shared::path::norm;
use shared::Machine;
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

/// The interpolation period (ns) a blend is weighed against the exact path at
/// ([`corners_on`]), clamped to the machine's range: the moves do not know the period they
/// will run at, and the choice barely depends on it.
pub const DECISION_PERIOD_NS: u64 = 1_000_000;

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

/// The moves with every eligible corner blended (see the module page), whether the blend
/// pays or not (see [`corners_on`]); the moves themselves, not a copy, when the program
/// never selects `G64 P` with a tolerance.
pub fn corners(moves: &[Move]) -> Cow<'_, [Move]> {
    match eligible(moves, None) {
        Some(plans) => Cow::Owned(emit(moves, &plans)),
        None => Cow::Borrowed(moves),
    }
}

/// The blend planned at each eligible corner, shaped for the curvature's limits `normal`
/// ([`shape::choose`]; the table's shapes without them); `None` where there is none (the
/// program never selects `G64 P` with a tolerance, or no corner qualifies).
fn eligible(moves: &[Move], normal: Option<shape::Normal>) -> Option<Vec<Option<Corner>>> {
    let blends_anywhere = moves.iter().any(|m| {
        matches!(m, Move::PathMode { control: PathControl::Blend { tolerance_mm: Some(t), .. }, .. } if *t > 0.0)
    });
    if !blends_anywhere {
        return None;
    }
    let plans = plan_corners(moves, normal);
    (!plans.iter().all(Option::is_none)).then_some(plans)
}

/// [`corners`], keeping only the blends that pay on `machine`: each eligible corner, in
/// program order, is planned and stepped both ways in its neighbourhood (see the module
/// page, "Blends that pay"), and is blended only when that is not slower than following
/// the exact path there (`G61`: an exact stop above `corner_angle_deg`, the kink's speed
/// below). A corner left exact is put under `G61` (a path-mode change before the line
/// that ends at it, and the mode in force back after it), so the moves this returns are
/// returned unchanged by [`corners`] and by this function.
pub fn corners_on<'a>(moves: &'a [Move], machine: &Machine) -> Cow<'a, [Move]> {
    corners_weighed(moves, machine, Weighing::EachCorner)
}

/// How [`decide`] weighs the corners the screen leaves open.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Weighing {
    /// Each alone, in program order, then each stretch of a chain where that differs
    /// from blending them all: what the planner does.
    EachCorner,
    /// Those with another open corner within their reach not alone but as a cluster,
    /// blended against exact ([`open_beside`]): for timing ways a program may take
    /// before it is planned ([`cycles_of_quick`]).
    Clusters,
}

/// [`corners_on`], weighing as asked.
fn corners_weighed<'a>(moves: &'a [Move], machine: &Machine, how: Weighing) -> Cow<'a, [Move]> {
    let Some(plans) = eligible(moves, Some(normal_of(machine))) else {
        return Cow::Borrowed(moves);
    };
    let decided = decide(moves, &plans, machine, how);
    Cow::Owned(emit_marked(moves, &decided.plans, &decided.exact))
}

/// The limits a blend's curvature may take on `machine`: its weakest acceleration and
/// jerk at the curvature's share ([`shape::choose`]).
fn normal_of(machine: &Machine) -> shape::Normal {
    let w = weakest(machine);
    shape::Normal {
        acc: super::NORMAL_SHARE * w.acc,
        jerk: shape::JERK_WEIGHT * super::NORMAL_SHARE * w.jerk,
    }
}

/// The corners [`corners_on`] keeps, and the mode in force on each line whose end corner
/// it leaves exact.
struct Decided {
    plans: Vec<Option<Corner>>,
    exact: Vec<Option<PathControl>>,
}

/// The period ways are timed at: [`DECISION_PERIOD_NS`], within the machine's periods.
pub(super) fn decision_period(machine: &Machine) -> u64 {
    DECISION_PERIOD_NS.clamp(
        machine.min_period_us * 1000,
        machine.max_period_us.max(machine.min_period_us) * 1000,
    )
}

/// The machine's weakest acceleration and jerk, path or axis.
pub(super) fn weakest(machine: &Machine) -> shared::profile::Limits {
    let axes = machine.axes.as_array();
    shared::profile::Limits {
        acc: axes
            .iter()
            .map(|x| x.max_acc_mm_per_s2)
            .fold(machine.path_acc_mm_per_s2, f64::min),
        jerk: axes
            .iter()
            .map(|x| x.max_jerk_mm_per_s3)
            .fold(machine.path_jerk_mm_per_s3, f64::min),
    }
}

/// The speed (mm/s) and the distance to stop from it (mm) that bound a corner's
/// neighbourhood: what the machine's weakest acceleration and jerk (path or axis) need to
/// stop from the faster of the two lines' feeds, jerk-limited.
pub(super) fn stop_distance(v: f64, machine: &Machine) -> f64 {
    let shared::profile::Limits { acc: a, jerk: j } = weakest(machine);
    if v * j <= a * a {
        v * (v / j).sqrt()
    } else {
        0.5 * v * (v / a + a / j)
    }
}

/// Each corner of `plans`, in program order, kept or left exact by which of the two is
/// quicker through its neighbourhood ([`time_around`]).
fn decide(moves: &[Move], plans: &[Option<Corner>], machine: &Machine, how: Weighing) -> Decided {
    let period_ns = decision_period(machine);
    // The line each blended corner comes from, by the line it goes into.
    let mut prev = vec![None; moves.len()];
    for (i, c) in plans.iter().enumerate() {
        if let Some(c) = c {
            prev[c.next] = Some(i);
        }
    }
    let screened: Vec<Option<bool>> = (0..moves.len())
        .map(|i| screen(moves, plans, i, machine, period_ns))
        .collect();
    let mut kept: Vec<Option<Corner>> = plans.to_vec();
    // The path mode in force on each line.
    let mut control = vec![None; moves.len()];
    let mut mode = None;
    for (m, c) in moves.iter().zip(&mut control) {
        if let Move::PathMode { control: now, .. } = m {
            mode = Some(*now);
        }
        *c = mode;
    }
    for i in 0..moves.len() {
        if plans[i].is_none() {
            continue;
        }
        let pays = screened[i].unwrap_or_else(|| {
            if how == Weighing::Clusters && open_beside(moves, plans, &screened, &prev, i, machine)
            {
                return false;
            }
            let blend = time_around(moves, plans, &kept, &prev, i, true, machine, period_ns);
            let exact_path = time_around(moves, plans, &kept, &prev, i, false, machine, period_ns);
            match (blend, exact_path) {
                (Some(b), Some(e)) => b <= e,
                // A neighbourhood the planner or the engine refuses: as before, blended.
                _ => true,
            }
        });
        if !pays {
            kept[i] = None;
        }
    }
    // Corner by corner, each weighed with the corners after it exact: in a chain of
    // corners closer than the machine needs to reach the feed, one blend among exact
    // stops does not pay where the whole chain blended does (a zigzag of 0.5 mm lines at
    // 22°, P0.01, F3000 on the built-in machine, 300 of them: 22.617 s corner by corner, 14.369 s with
    // every corner the screen leaves open blended). So each chain of corners is also
    // stepped both ways, every corner the screen leaves open blended against the corners
    // as decided, and the quicker kept: not the whole chain, but each stretch of it where
    // the two ways differ, with what the machine needs to stop twice over on either side
    // ([`differing_stretches`]). (Stepped whole, a raster whose every row end was weighed
    // stepped the whole program twice: 100 000 lines of `G1` in 0.5 mm steps, `cnc check`
    // 1.57 s, 0.91 s without the chains.)
    for (first, last) in chains(plans, &prev) {
        let mut lines = vec![first];
        let mut k = first;
        while k != last {
            match plans[k] {
                Some(c) => {
                    lines.push(c.next);
                    k = c.next;
                }
                None => break,
            }
        }
        if let Some(c) = plans[last] {
            lines.push(c.next);
        }
        let open: Vec<Option<Corner>> = lines
            .iter()
            .map(|&k| plans[k].filter(|_| screened[k] != Some(false)))
            .collect();
        let greedy: Vec<Option<Corner>> = lines.iter().map(|&k| kept[k]).collect();
        if open
            .iter()
            .map(Option::is_some)
            .eq(greedy.iter().map(Option::is_some))
        {
            continue;
        }
        let segs: Option<Vec<_>> = lines
            .iter()
            .map(|&k| match &moves[k] {
                Move::Line { from, to, feed, .. } => Some((*from, *to, *feed)),
                _ => None,
            })
            .collect();
        let Some(segs) = segs else { continue };
        let v = segs
            .iter()
            .map(|s| s.2)
            .fold(0.0, f64::max)
            .min(machine.max_feed_mm_per_min)
            / 60.0;
        let trim = lines
            .iter()
            .filter_map(|&k| plans[k].map(|c| c.trim_mm))
            .fold(0.0, f64::max);
        // (Four stopping distances: with two, as a corner's own neighbourhood, the
        // generated programs' estimates moved by -0.3 to +0.1 %, the sine polyline under a
        // bare `G64` 15.047 -> 15.059 s; with four none is slower than stepped whole.)
        let reach = 4.0 * stop_distance(v, machine) + 2.0 * trim;
        let trims: Vec<f64> = lines
            .iter()
            .map(|&k| plans[k].map_or(0.0, |c| c.trim_mm))
            .collect();
        for st in differing_stretches(&segs, &open, &greedy, &trims, reach) {
            // The far lines cut from their outer ends.
            let towards = |a, b, len: f64| {
                add(
                    a,
                    super::unit_of(sub(b, a))
                        .unwrap_or([0.0; 3])
                        .map(|x| x * len),
                )
            };
            let mut cut = segs[st.lo..=st.hi].to_vec();
            let n = cut.len();
            cut[0].0 = towards(cut[0].1, cut[0].0, st.first_len);
            cut[n - 1].1 = towards(cut[n - 1].0, cut[n - 1].1, st.last_len);
            let cycles = |chosen: &[Option<Corner>]| {
                window_cycles(&cut, |w| chosen[st.lo + w], machine, period_ns)
            };
            if let (Some(o), Some(g)) = (cycles(&open), cycles(&greedy)) {
                // Only the corners stepped: those at the ends of the lines `lo..hi` (the
                // last line is cut inside, its end corner left to its own stretch).
                if o < g {
                    for w in st.lo..st.hi {
                        kept[lines[w]] = open[w];
                    }
                }
            }
        }
    }
    let exact = (0..moves.len())
        .map(|i| {
            if plans[i].is_some() && kept[i].is_none() {
                control[i]
            } else {
                None
            }
        })
        .collect();
    Decided { plans: kept, exact }
}

/// A stretch of a chain of lines that [`decide`] weighs both ways: the lines `lo..=hi`,
/// the first kept for its last `first_len` mm, the last for its first `last_len` mm.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Stretch {
    lo: usize,
    hi: usize,
    first_len: f64,
    last_len: f64,
}

/// Where the two ways `a` and `b` of a chain of lines `segs` (the corner at the end of
/// each line, or none) differ, each with `reach` (mm) of the chain on either side of
/// it, overlapping ones joined. Outside them the two ways are the same corners, and what
/// lies farther than a few stopping distances from a corner where they differ changes
/// little of the time through it (the reasoning of [`time_around`]'s neighbourhood,
/// which is stepped the same way, from rest to rest). The far lines
/// are cut to the reach, but never below what the blend at their inner end takes of them
/// (`trims`: each line's end corner's trim), as in [`time_around`].
fn differing_stretches(
    segs: &[([f64; 3], [f64; 3], f64)],
    a: &[Option<Corner>],
    b: &[Option<Corner>],
    trims: &[f64],
    reach: f64,
) -> Vec<Stretch> {
    let n = segs.len();
    // Where each line ends along the chain.
    let mut ends = Vec::with_capacity(n);
    let mut s = 0.0;
    for seg in segs {
        s += norm(sub(seg.1, seg.0));
        ends.push(s);
    }
    let start_of = |w: usize| if w == 0 { 0.0 } else { ends[w - 1] };
    let differ = (0..n.saturating_sub(1)).filter(|&w| a[w].is_some() != b[w].is_some());
    let mut spans: Vec<(f64, f64)> = Vec::new();
    for w in differ {
        let (lo, hi) = (ends[w] - reach, ends[w] + reach);
        match spans.last_mut() {
            Some(last) if lo <= last.1 => last.1 = hi,
            _ => spans.push((lo, hi)),
        }
    }
    spans
        .into_iter()
        .map(|(from, to)| {
            // The line `from` falls in (the first whose end is past it), and `to`'s.
            let lo = ends.partition_point(|&e| e <= from).min(n - 1);
            let hi = ends.partition_point(|&e| e < to).min(n - 1);
            let len = |w: usize| ends[w] - start_of(w);
            let first_len = (ends[lo] - from.max(start_of(lo)))
                .max(2.0 * trims[lo])
                .min(len(lo));
            let last_len = (to.min(ends[hi]) - start_of(hi))
                .max(2.0 * if hi > 0 { trims[hi - 1] } else { 0.0 })
                .min(len(hi));
            Stretch {
                lo,
                hi,
                first_len,
                last_len,
            }
        })
        .collect()
}

/// How far along the path the corner `here` at the end of line `i` is weighed on either
/// side ([`time_around`]): twice what the machine needs to stop from the faster of its
/// two lines' feeds, and twice its trim. `None` unless both are lines.
fn reach_of(moves: &[Move], i: usize, here: &Corner, machine: &Machine) -> Option<f64> {
    let feed = |k: usize| match &moves[k] {
        Move::Line { feed, .. } => Some(*feed),
        _ => None,
    };
    let v = feed(i)?
        .max(feed(here.next)?)
        .min(machine.max_feed_mm_per_min)
        / 60.0;
    Some(2.0 * stop_distance(v, machine) + 2.0 * here.trim_mm)
}

/// Whether another corner the screen left open stands within the reach of the corner at
/// the end of line `i` along its chain, either way ([`reach_of`]).
fn open_beside(
    moves: &[Move],
    plans: &[Option<Corner>],
    screened: &[Option<bool>],
    prev: &[Option<usize>],
    i: usize,
    machine: &Machine,
) -> bool {
    let Some((here, reach)) = plans[i].and_then(|c| Some((c, reach_of(moves, i, &c, machine)?)))
    else {
        return false;
    };
    let line = |k: usize| match &moves[k] {
        Move::Line { from, to, .. } => Some(norm(sub(*to, *from))),
        _ => None,
    };
    let open = |k: usize| plans[k].is_some() && screened[k].is_none();
    // Back: the corner at the start of each line walked, while within the reach.
    let (mut k, mut along) = (i, 0.0);
    while let Some(p) = prev[k] {
        along += line(k).unwrap_or(f64::INFINITY);
        if along >= reach {
            break;
        }
        if open(p) {
            return true;
        }
        k = p;
    }
    // Ahead: the corner at the end of each line walked.
    let mut k = here.next;
    let mut along = 0.0;
    while let Some(c) = plans[k] {
        along += line(k).unwrap_or(f64::INFINITY);
        if along >= reach {
            return false;
        }
        if open(k) {
            return true;
        }
        k = c.next;
    }
    false
}

/// Each chain of corners as the lines `(first, last)` whose end corners begin and end it:
/// corners one after another, each at the end of the line the one before goes into.
fn chains(plans: &[Option<Corner>], prev: &[Option<usize>]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    for (i, c) in plans.iter().enumerate() {
        if c.is_none() || prev[i].is_some_and(|p| plans[p].is_some()) {
            continue;
        }
        let mut last = i;
        while let Some(c) = plans[last] {
            match plans[c.next] {
                Some(_) => last = c.next,
                None => break,
            }
        }
        out.push((i, last));
    }
    out
}

/// How much one way's time lost at a corner must be below the other's for [`screen`] to
/// decide without stepping the neighbourhood: a factor, and an absolute margin (s).
const SCREEN_FACTOR: f64 = 2.0;
const SCREEN_MARGIN_S: f64 = 2e-3;

/// The quick answer for the corner at the end of line `i`, where it is clear: `Some(true)`
/// to blend, `Some(false)` to leave it exact, `None` to step the neighbourhood
/// ([`time_around`]). Each way is one slow stretch in the lines' feed `F`: the blend at its
/// planned cap `v_b` over its length `ℓ`, the exact corner at the speed the planner passes
/// it at, `v_e` (0 at an exact stop), over no length; each costs, against running on at
/// `F`, `2·(T(F→v) − D(F→v)/F) + ℓ·(1/v − 1/F)` with the jerk-limited speed change's
/// time `T` and distance `D` under the machine's weakest acceleration and jerk. Both are
/// planned alone (the blend block, and the two lines meeting at the corner, each long
/// enough to reach `F` and stop from it), which is cheap next to stepping the
/// neighbourhood, and clear when one way loses [`SCREEN_FACTOR`] times less than the
/// other (and [`SCREEN_MARGIN_S`] less).
fn screen(
    moves: &[Move],
    plans: &[Option<Corner>],
    i: usize,
    machine: &Machine,
    period_ns: u64,
) -> Option<bool> {
    let c = plans[i]?;
    let feed = |k: usize| match &moves[k] {
        Move::Line { feed, .. } => Some(*feed),
        _ => None,
    };
    let f = feed(i)?.min(feed(c.next)?).min(machine.max_feed_mm_per_min);
    let v = f / 60.0;
    // The exact corner's speed holds in the program only where the kinks on either side
    // are at least two steps away: closer kinks are slowed as a run (`CloseKinks`), which
    // the two long lines below do not show.
    let leg = |k: usize| match &moves[k] {
        Move::Line { from, to, .. } => norm(sub(*to, *from)),
        _ => 0.0,
    };
    let period_s = period_ns as f64 * 1e-9;
    let alone = leg(i).min(leg(c.next)) >= 2.0 * v * period_s;
    let mut beside: Option<bool> = None;
    let mut beside_at_feed = || {
        *beside.get_or_insert_with(|| alone || run_at_feed(moves, i, c.next, v, machine, period_s))
    };
    // A corner passed at the feed loses nothing to blend (the blend, never faster than
    // the feed, can at most tie): left exact without planning the blend. So too where
    // closer kinks stand beside it, when every run of them it may be slowed in is
    // passed at the feed as well ([`run_at_feed`]): dense CAM output of tiny turns,
    // whose every corner was otherwise stepped both ways (a spiral of 0.08 mm chords
    // turning 0.11°, `G64 P0.01`, F3000: 95 µs a line in `cnc check`). Where the turn is
    // far too small to slow the feed ([`surely_at_feed`]) that is known without planning
    // the two lines (nearly every corner of dense CAM output: a raster of 0.5 mm steps
    // whose heights bend it by a few hundredths of a degree, 2 µs a corner planned).
    let at_feed = surely_at_feed(&c, v, machine, period_s);
    if at_feed && beside_at_feed() {
        return Some(false);
    }
    let v_e = exact_corner_speed(&c, f, machine, period_ns) / 60.0;
    if v_e >= v && beside_at_feed() {
        return Some(false);
    }
    let lim = weakest(machine);
    let lost = |u: f64, len: f64| {
        let u = u.min(v);
        let t = lim.change_time(v - u);
        let slow = if len > 0.0 {
            len * (1.0 / u - 1.0 / v)
        } else {
            0.0
        };
        2.0 * (t - lim.change_distance(v, u) / v) + slow
    };
    let le = lost(v_e, 0.0);
    // Where even the blend's highest possible speed loses clearly more than the exact
    // corner, it is left exact without planning the blend: the same answer as below, as
    // the loss only grows as the speed falls and the length grows
    // ([`blend_speed_bound`]; the spiral of the bench, 1° turns in 0.04 mm chords at
    // F3000 under a bare `G64`: 90 % of `cnc check` was planning blends alone here).
    let (v_up, len_down) = blend_speed_bound(&c, v, machine);
    if le * SCREEN_FACTOR + SCREEN_MARGIN_S <= lost(v_up, len_down) {
        return Some(false);
    }
    let (v_b, len_b) = blend_alone(&c, f, machine, period_ns);
    let v_b = v_b / 60.0;
    if v_b.is_nan() || v_b <= 0.0 || !len_b.is_finite() {
        return None;
    }
    let lb = lost(v_b, len_b);
    if alone && v_e >= v_b {
        Some(false)
    } else if lb * SCREEN_FACTOR + SCREEN_MARGIN_S <= le {
        Some(true)
    } else if le * SCREEN_FACTOR + SCREEN_MARGIN_S <= lb {
        Some(false)
    } else {
        None
    }
}

/// The speed (mm/min) the planner passes the corner `c` at, left exact, between two
/// lines at the feed `f` (mm/min) long enough to reach it and stop from it.
fn exact_corner_speed(c: &Corner, f: f64, machine: &Machine, period_ns: u64) -> f64 {
    let leg = 2.0 * stop_distance(f / 60.0, machine) + c.trim_mm;
    let (a, b) = (c.u1.map(|x| -x * leg), c.u2.map(|x| x * leg));
    let line = |from, to| Move::Line {
        line: 0,
        from,
        to,
        rapid: false,
        feed: f,
    };
    let mut blocks = super::build(
        &[line(a, [0.0; 3]), line([0.0; 3], b), Move::End { line: 0 }],
        machine,
    );
    super::plan(&mut blocks, machine, period_ns);
    let ends: Vec<f64> = super::commands(&blocks)
        .iter()
        .filter(|b| b.length_mm > 0.0)
        .map(|b| b.end_feed_mm_per_min)
        .collect();
    ends[..ends.len().saturating_sub(1)]
        .iter()
        .fold(f, |m, x| m.min(*x))
}

/// The control points of the blend of the corner `c`, moved so that its corner is at the
/// origin (where [`blend_alone`] plans it and [`blend_speed_bound`] samples it).
fn local_blend(c: &Corner) -> Vec<[f64; 4]> {
    let o = c.corner;
    let local = Corner {
        corner: [0.0; 3],
        ..*c
    };
    let start = sub(sub(c.corner, c.u1.map(|x| x * c.trim_mm)), o);
    let end = sub(add(c.corner, c.u2.map(|x| x * c.trim_mm)), o);
    control_points(&local, start, end)
}

/// The cap (mm/min) the planner gives the blend of the corner `c` planned alone at the
/// feed `f` (mm/min), and its length (mm).
fn blend_alone(c: &Corner, f: f64, machine: &Machine, period_ns: u64) -> (f64, f64) {
    let moves = [
        Move::Nurbs {
            line: 0,
            degree: 5,
            knots: vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0],
            ctrl: local_blend(c),
            feed: f,
        },
        Move::End { line: 0 },
    ];
    let mut blocks = super::build(&moves, machine);
    super::plan(&mut blocks, machine, period_ns);
    let planned = super::commands(&blocks);
    let motion = || planned.iter().filter(|b| b.length_mm > 0.0);
    (
        motion().map(|b| b.feed_mm_per_min).fold(f, f64::min),
        motion().map(|b| b.length_mm).sum(),
    )
}

/// The control points of a Bézier curve's derivative (`M` = `N − 1` of them).
fn hodograph_of<const N: usize, const M: usize>(q: [[f64; 3]; N]) -> [[f64; 3]; M] {
    debug_assert_eq!(M + 1, N);
    let n = M as f64;
    std::array::from_fn(|i| sub(q[i + 1], q[i]).map(|x| x * n))
}

/// A Bézier curve's point at `t` (de Casteljau; plain loops, which the compiler keeps
/// inline: `[T; N]::map` here was not, and took most of the screen's time). Also the
/// naive CAM merge's smoothed pieces, certified by sampling.
pub(super) fn de_casteljau<const N: usize>(mut b: [[f64; 3]; N], t: f64) -> [f64; 3] {
    for k in (1..N).rev() {
        for i in 0..k {
            let next = b[i + 1];
            for (x, n) in b[i].iter_mut().zip(next) {
                *x += t * (n - *x);
            }
        }
    }
    b[0]
}

/// The largest curvature and rate of change of curvature (per arc length) of the
/// quintic Bézier curve `p` at `samples + 1` evenly spaced parameters, and the length of
/// the chords between them ([`blend_speed_bound`], [`shape::figures`]).
pub(super) fn peaks_of(p: [[f64; 3]; 6], samples: usize) -> (f64, f64, f64) {
    // The control points of the curve's first three derivatives.
    let d1: [[f64; 3]; 5] = hodograph_of(p);
    let d2: [[f64; 3]; 4] = hodograph_of(d1);
    let d3: [[f64; 3]; 3] = hodograph_of(d2);
    let (mut kappa, mut rate, mut len) = (0.0f64, 0.0f64, 0.0);
    let mut last = p[0];
    for i in 0..=samples {
        let t = i as f64 / samples as f64;
        let (e1, e2, e3) = (
            de_casteljau(d1, t),
            de_casteljau(d2, t),
            de_casteljau(d3, t),
        );
        let sp = norm(e1);
        let x = cross(e1, e2);
        let xn = norm(x);
        if sp > 0.0 {
            kappa = kappa.max(xn / sp.powi(3));
            if xn > 0.0 {
                // d|x|/dt and d|e1|/dt, so dκ/dt = (d|x|/dt)/s³ − 3|x|·(ds/dt)/s⁴.
                let dxn = dot(x, cross(e1, e3)) / xn;
                let dsp = dot(e1, e2) / sp;
                rate = rate.max(((dxn / sp.powi(3) - 3.0 * xn * dsp / sp.powi(4)) / sp).abs());
            }
        }
        let q = de_casteljau(p, t);
        len += norm(sub(q, last));
        last = q;
    }
    (kappa, rate, len)
}

/// Samples of a blend for [`blend_speed_bound`].
const BOUND_SAMPLES: usize = 16;
/// The margin [`blend_speed_bound`] keeps on its speed and its length.
const BOUND_MARGIN: f64 = 1.01;

/// A speed (mm/s) no lower than the cap the planner gives the blend of `c` at the feed
/// `v` (mm/s) and a length (mm) no longer than the blend's, without planning it: the
/// path's acceleration and jerk at the largest curvature `κ` and curvature rate
/// `|dκ/ds|` of [`BOUND_SAMPLES`] samples, `min(v, √(A/κ), ∛(J/|dκ/ds|))`, and the
/// chords between the samples. The planner holds every sample of its own (its peaks
/// searched) within the limits, at shares of them, with the rate of the curvature
/// vector, which is no less than the rate of its length. So its cap is lower, and a
/// margin of a hundredth covers a sample near a peak the planner's do not hit (the
/// property test `a_blends_speed_bound_is_no_lower_than_its_planned_cap`).
fn blend_speed_bound(c: &Corner, v: f64, machine: &Machine) -> (f64, f64) {
    let ctrl = local_blend(c);
    let p: [[f64; 3]; 6] = std::array::from_fn(|i| [ctrl[i][0], ctrl[i][1], ctrl[i][2]]);
    let (kappa, rate, len) = peaks_of(p, BOUND_SAMPLES);
    let by_acc = if kappa > 0.0 {
        (machine.path_acc_mm_per_s2 / kappa).sqrt()
    } else {
        f64::INFINITY
    };
    let by_jerk = if rate > 0.0 {
        (machine.path_jerk_mm_per_s3 / rate).cbrt()
    } else {
        f64::INFINITY
    };
    (
        v.min(BOUND_MARGIN * by_acc.min(by_jerk)),
        len / BOUND_MARGIN,
    )
}

/// How far within the planner's kink bound [`surely_at_feed`] asks a corner to be.
const SURE_MARGIN: f64 = 0.5;
/// And within each axis's velocity (the planner's line cap is that bound itself: only
/// its rounding is left out).
const SURE_VEL_MARGIN: f64 = 1.0 - 1e-9;

/// Whether the planner surely passes the exact corner `c` at the speed `v` (mm/s)
/// between two lines long enough to reach it, without planning them: both lines' axis
/// velocities at `v` within [`SURE_VEL_MARGIN`] of their limits, and the direction
/// change at `v` in one period (`v·2·sin(θ/2)/T`, which bounds every axis's share too)
/// within [`SURE_MARGIN`] of the weakest acceleration's kink share. The planner's kink speed is the least of those bounds at
/// their full share, so this only says "at the feed" where planning would too (the
/// property test `a_corner_surely_at_feed_is_planned_at_feed`); where it says no, the
/// screen plans the two lines.
fn surely_at_feed(c: &Corner, v: f64, machine: &Machine, period_s: f64) -> bool {
    let axes = machine.axes.as_array();
    let within_vel = |u: [f64; 3]| {
        (0..3).all(|k| v * u[k].abs() <= SURE_VEL_MARGIN * axes[k].max_vel_mm_per_min / 60.0)
    };
    let half_sin = super::half_turn_sin(dot(c.u1, c.u2));
    within_vel(c.u1)
        && within_vel(c.u2)
        && v * 2.0 * half_sin <= SURE_MARGIN * super::KINK_SHARE * weakest(machine).acc * period_s
}

/// Whether every run of close kinks the planner may slow the corner at the end of line
/// `i` in (into line `next`) is passed at the feed `v` (mm/s), its own kink included.
/// The planner takes each run of kinks closer than two steps (at the speeds planned at
/// them) at the speed whose direction change over all their turns `Θ` stays within the
/// acceleration, `A·T / (2·sin(Θ/2))` with `A` no lower than the weakest acceleration
/// (path or axis) times the kink share (`CloseKinks` in the planner). A run's speeds are
/// at most the feeds of the lines at its kinks, so every run this corner is in lies
/// within two steps, at the highest feed of the lines there, on either side of it
/// ([`turns_within`] widens its reach until that holds), and the sum of the programmed
/// turns there bounds the turn of each. `false` where that walk meets a move that is
/// neither a feed line, a path-mode change nor a rest, or where the bound is not met.
fn run_at_feed(
    moves: &[Move],
    i: usize,
    next: usize,
    v: f64,
    machine: &Machine,
    period_s: f64,
) -> bool {
    let Some(turn) = turns_within(moves, i, next, 2.0 * period_s, machine) else {
        return false;
    };
    super::KINK_SHARE * weakest(machine).acc * period_s
        >= v * 2.0 * (0.5 * turn.min(std::f64::consts::PI)).sin()
}

/// A move as [`turns_within`] walks it: a feed line (its unit direction, length and
/// feed in mm/s), a rest no run of kinks reaches across, or anything else.
enum Walked {
    Line([f64; 3], f64, f64),
    Rest,
    Other,
}

/// The angle (radians) between the unit directions `a` and `b`.
pub(super) fn turn_between(a: [f64; 3], b: [f64; 3]) -> f64 {
    2.0 * super::half_turn_sin(dot(a, b)).min(1.0).asin()
}

/// The sum of the turns (radians) of the programmed corners less than a reach from the
/// corner at the end of line `i` (into line `next`) along the path on either side, that
/// corner's own included, and the reach: `window_s` (s) at the highest feed of the
/// lines within it (within the machine's highest feed), widened until it holds. A rest
/// (a rapid, a dwell, a stop or the end) ends the walk that way; `None` where it meets
/// anything else but a feed line or a path-mode change (an arc, a curve, a spindle
/// change, a line too short to have a direction).
fn turns_within(
    moves: &[Move],
    i: usize,
    next: usize,
    window_s: f64,
    machine: &Machine,
) -> Option<f64> {
    let top = machine.max_feed_mm_per_min / 60.0;
    let walked = |k: usize| match &moves[k] {
        Move::Line {
            from,
            to,
            rapid: false,
            feed,
            ..
        } => {
            let d = sub(*to, *from);
            let l = norm(d);
            if l > MIN_LEG_MM {
                Walked::Line(d.map(|x| x / l), l, (feed / 60.0).min(top))
            } else {
                Walked::Other
            }
        }
        Move::Line { rapid: true, .. }
        | Move::Dwell { .. }
        | Move::Stop { .. }
        | Move::End { .. } => Walked::Rest,
        _ => Walked::Other,
    };
    let path_mode = |k: &usize| matches!(moves[*k], Move::PathMode { .. });
    let (Walked::Line(ui, li, fi), Walked::Line(un, ln, fn_)) = (walked(i), walked(next)) else {
        return None;
    };
    let before = |k: usize| (0..k).rev().find(|k| !path_mode(k));
    let after = |k: usize| (k + 1..moves.len()).find(|k| !path_mode(k));
    // The turns met walking from line `k` (direction `u`, `dist` mm from the corner at
    // its far end) by `step` until `reach`; the fastest feed met raised on the way.
    let walk = |step: &dyn Fn(usize) -> Option<usize>,
                (mut k, mut u, mut dist): (usize, [f64; 3], f64),
                reach: f64,
                fastest: &mut f64| {
        let mut sum = 0.0;
        while dist < reach {
            let Some(q) = step(k) else {
                break;
            };
            match walked(q) {
                Walked::Line(uq, lq, fq) => {
                    sum += turn_between(u, uq);
                    *fastest = fastest.max(fq);
                    (k, u, dist) = (q, uq, dist + lq);
                }
                Walked::Rest => break,
                Walked::Other => return None,
            }
        }
        Some(sum)
    };
    let mut fastest = fi.max(fn_);
    if !(fastest.is_finite() && window_s.is_finite()) {
        return None;
    }
    loop {
        let reach = window_s * fastest;
        // Back from the start of line `i`, and on from the end of line `next`.
        let sum = turn_between(ui, un)
            + walk(&before, (i, ui, li), reach, &mut fastest)?
            + walk(&after, (next, un, ln), reach, &mut fastest)?;
        if window_s * fastest <= reach {
            return Some(sum);
        }
    }
}

/// The cycles the neighbourhood of the corner at the end of line `i` takes, from rest to
/// rest, with that corner blended (`blend`) or exact: the lines that join it by blendable
/// corners, as far back and ahead as the machine needs to stop from their feed twice
/// over (the far lines cut to that), the corners before it as already decided (`kept`),
/// the corners after it exact. Planned by [`super::plan`] and stepped by the
/// interpolator's engine ([`crate::estimate`]), as `cnc check --estimate` does. `None`
/// when either refuses.
#[allow(clippy::too_many_arguments)]
fn time_around(
    moves: &[Move],
    plans: &[Option<Corner>],
    kept: &[Option<Corner>],
    prev: &[Option<usize>],
    i: usize,
    blend: bool,
    machine: &Machine,
    period_ns: u64,
) -> Option<u64> {
    let here = plans[i]?;
    let line = |k: usize| match &moves[k] {
        Move::Line { from, to, feed, .. } => Some((*from, *to, *feed)),
        _ => None,
    };
    let reach = reach_of(moves, i, &here, machine)?;
    // The lines of the neighbourhood, by index, and the length kept of each far one.
    let mut back = vec![i];
    let mut along = 0.0;
    let mut k = i;
    loop {
        let (a, b, _) = line(k)?;
        along += norm(sub(b, a));
        match prev[k] {
            Some(p) if along < reach && !(kept[p].is_none() && stops(plans[p], machine)) => {
                back.push(p);
                k = p;
            }
            _ => break,
        }
    }
    back.reverse();
    let mut ahead = vec![here.next];
    let mut along = 0.0;
    let mut k = here.next;
    loop {
        let (a, b, _) = line(k)?;
        along += norm(sub(b, a));
        match plans[k] {
            Some(c) if along < reach && !stops(Some(c), machine) => {
                ahead.push(c.next);
                k = c.next;
            }
            _ => break,
        }
    }
    let idx: Vec<usize> = back.into_iter().chain(ahead).collect();
    let n = idx.len();
    // The corner at the end of each line of the neighbourhood, as it is planned here.
    let corner_of = |w: usize| -> Option<Corner> {
        let k = idx[w];
        let c = if k < i {
            kept[k]
        } else if k == i && blend {
            plans[k]
        } else {
            None
        };
        c.filter(|_| w + 1 < n)
    };
    // The far lines cut to what the reach needs, but never below what the blend at their
    // inner end takes of them (so each blend keeps its trim).
    let mut segs: Vec<([f64; 3], [f64; 3], f64)> = Vec::with_capacity(n);
    let total_back: f64 = idx[..idx.iter().position(|&k| k == here.next).unwrap_or(n)]
        .iter()
        .filter_map(|&k| line(k).map(|(a, b, _)| norm(sub(b, a))))
        .sum();
    let total_ahead: f64 = idx[idx.iter().position(|&k| k == here.next).unwrap_or(n)..]
        .iter()
        .filter_map(|&k| line(k).map(|(a, b, _)| norm(sub(b, a))))
        .sum();
    for (w, &k) in idx.iter().enumerate() {
        let (mut a, mut b, f) = line(k)?;
        let len = norm(sub(b, a));
        let u = sub(b, a).map(|x| x / len);
        if w == 0 && total_back > reach {
            let keep_len = (len - (total_back - reach))
                .max(2.0 * plans[k].map_or(0.0, |c| c.trim_mm))
                .min(len);
            a = sub(b, u.map(|x| x * keep_len));
        }
        if w + 1 == n && total_ahead > reach {
            let start_trim = plans[idx[w - 1]].map_or(0.0, |c| c.trim_mm);
            let keep_len = (len - (total_ahead - reach)).max(2.0 * start_trim).min(len);
            b = add(a, u.map(|x| x * keep_len));
        }
        segs.push((a, b, f));
    }
    window_cycles(&segs, corner_of, machine, period_ns)
}

/// Whether the corner `c`, left exact, is an exact stop (a turn sharper than the
/// machine's `corner_angle_deg`, a hair's margin kept for the planner's own rounding of
/// the angle): the machine comes to rest there whatever is on either side, so a
/// neighbourhood ([`time_around`]) ends there.
fn stops(c: Option<Corner>, machine: &Machine) -> bool {
    c.is_some_and(|c| dot(c.u1, c.u2) < machine.corner_angle_deg.to_radians().cos() - 1e-9)
}

/// The cycles the lines `segs` (from, to, feed) take from rest to rest, with the corner
/// `corner_of(w)` blended at the end of line `w` (none at the last), planned by
/// [`super::plan`] and stepped by the interpreter's engine ([`crate::estimate`]). `None`
/// when either refuses.
fn window_cycles(
    segs: &[([f64; 3], [f64; 3], f64)],
    corner_of: impl Fn(usize) -> Option<Corner>,
    machine: &Machine,
    period_ns: u64,
) -> Option<u64> {
    let n = segs.len();
    // Moved to the origin, where the engine starts.
    let o = segs.first()?.0;
    let mut window: Vec<Move> = segs
        .iter()
        .map(|&(a, b, feed)| Move::Line {
            line: 0,
            from: sub(a, o),
            to: sub(b, o),
            rapid: false,
            feed,
        })
        .collect();
    window.push(Move::End { line: 0 });
    let wplans: Vec<Option<Corner>> = (0..=n)
        .map(|w| {
            (w + 1 < n).then(|| corner_of(w)).flatten().map(|c| Corner {
                next: w + 1,
                corner: sub(c.corner, o),
                ..c
            })
        })
        .collect();
    cycles_of(&emit(&window, &wplans), machine, period_ns)
}

/// The cycles `moves` (from the origin, where the engine starts, to an end) take,
/// built, planned by [`super::plan`] and stepped by the interpreter's engine
/// ([`crate::estimate`]). `None` when either refuses.
pub(super) fn cycles_of(moves: &[Move], machine: &Machine, period_ns: u64) -> Option<u64> {
    cycles_weighed(moves, machine, period_ns, Weighing::EachCorner)
}

/// [`cycles_of`] with the corners weighed in clusters where they stand close
/// ([`Weighing::Clusters`]): for timing a way a program may take before it is planned
/// ([`super::naive_cam`]'s merged, programmed and smoothed stretches), where the way
/// taken is then planned as the planner plans. (Weighing each of a stretch's merged
/// lines' corners alone was 70 % of `cnc check` on dense chords under `G64 P0.01`.)
pub(super) fn cycles_of_quick(moves: &[Move], machine: &Machine, period_ns: u64) -> Option<u64> {
    cycles_weighed(moves, machine, period_ns, Weighing::Clusters)
}

/// [`cycles_of`], the corners weighed as asked.
fn cycles_weighed(moves: &[Move], machine: &Machine, period_ns: u64, how: Weighing) -> Option<u64> {
    let weighed = corners_weighed(moves, machine, how);
    let mut blocks = super::build(&weighed, machine);
    super::plan(&mut blocks, machine, period_ns);
    // (Each block made a command block as it is stepped: a chain may be the whole program.)
    let commands = blocks.iter().enumerate().map(|(i, b)| b.command(i as u64));
    let est = crate::estimate::estimate_of(commands, machine, period_ns, u64::MAX).ok()??;
    Some(est.cycles)
}

/// [`emit`], with the lines whose end corner is left exact (`exact`: the mode in force
/// there) put under `G61` for that line alone.
fn emit_marked(
    moves: &[Move],
    plans: &[Option<Corner>],
    exact: &[Option<PathControl>],
) -> Vec<Move> {
    if exact.iter().all(Option::is_none) {
        return emit(moves, plans);
    }
    let mut marked = Vec::with_capacity(moves.len() + 2 * exact.len());
    let mut at = Vec::with_capacity(moves.len());
    for (i, m) in moves.iter().enumerate() {
        let line = match m {
            Move::Line { line, .. } => *line,
            _ => 0,
        };
        if exact[i].is_some() {
            marked.push(Move::PathMode {
                line,
                control: PathControl::ExactPath,
            });
        }
        at.push(marked.len());
        marked.push(m.clone());
        if let Some(c) = &exact[i] {
            marked.push(Move::PathMode { line, control: *c });
        }
    }
    let mut p = vec![None; marked.len()];
    for (i, c) in plans.iter().enumerate() {
        if let Some(c) = c {
            p[at[i]] = Some(Corner {
                next: at[c.next],
                ..*c
            });
        }
    }
    emit(&marked, &p)
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
fn plan_corners(moves: &[Move], normal: Option<shape::Normal>) -> Vec<Option<Corner>> {
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
                        plans[i] = corner(*from, *to, *f2, *t2, t, normal).map(|mut c| {
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
/// it gets one, shaped for `normal` ([`shape::choose`]).
fn corner(
    a0: [f64; 3],
    a1: [f64; 3],
    b0: [f64; 3],
    b1: [f64; 3],
    tol: f64,
    normal: Option<shape::Normal>,
) -> Option<Corner> {
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
    let (c1, c2, trim_mm) = shape::choose(theta, tol, (0.5 * la).min(0.5 * lb), normal);
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

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

mod shape;
#[cfg(test)]
mod tests;

/// Whether a NURBS has the shape of a corner blend (degree 5, one Bézier span, weights
/// 1, its first three and its last three control points each on one line), as
/// [`corners`] makes them. The planner does not split such a curve where its speed
/// limit changes (its pieces once broke the feed by 0.4 % on a random blended chain);
/// a programmed curve of that very shape is then only held to its slowest point.
pub fn is_blend_shape(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> bool {
    let on_a_line = |p: &[[f64; 4]]| {
        let xyz = |q: [f64; 4]| [q[0], q[1], q[2]];
        let (u, v) = (sub(xyz(p[1]), xyz(p[0])), sub(xyz(p[2]), xyz(p[0])));
        norm(cross(u, v)) <= 1e-9 * dot(v, v).max(f64::MIN_POSITIVE)
    };
    degree == 5
        && ctrl.len() == 6
        && knots.len() == 12
        && knots[..6].iter().all(|k| *k == knots[0])
        && knots[6..].iter().all(|k| *k == knots[11])
        && ctrl.iter().all(|p| p[3] == 1.0)
        && on_a_line(&ctrl[..3])
        && on_a_line(&ctrl[3..])
}
