//! A jerk-limited time-optimal reference for the feed planner (TOPP3): the fastest
//! profile along the same exact path, on the same grid and under the same limits as the
//! acceleration-only reference of [`crate::topp`], plus the path's and each axis's jerk.
//! It is what issue #23's goal "time ≤ 1.05 × the jerk-limited optimum" is measured
//! against. Written from the literature's convex formulation (Verscheure et al. 2009
//! for the time objective in `x = v²`; the jerk linearized about a previous profile as
//! the TOPP3 papers do, here inside a trust region so that every kept profile keeps the
//! jerk), solved with the `clarabel` conic solver.
//!
//! **The problem.** The grid of [`topp::grid`] (cells of at most the step, turning at
//! most [`topp::MAX_TURN_RAD`]; a junction is two points at the same `s`, merged here
//! into one node with the frames of both sides), with the cells beside a rest point cut
//! into pieces halving towards it ([`graded`]: a start from rest grows like `s^(4/3)`
//! in `x`, which one long cell linear in `x` overstates), and cells shorter than
//! [`MIN_NODE_MM`] merged ([`nodes`]: differences over them would measure the solver's
//! rounding). Unknowns at each node `x_i = v_i²` and at each cell its acceleration
//! `a_c`, tied by `x_{c+1} − x_c = 2Δs_c·a_c` (`x` is linear in `s` over a cell); the
//! cell's time is `2Δs_c/(v_c + v_{c+1})`, exactly. The objective is the sum of the
//! cells' times (convex: each a second-order cone with `v_i² ≤ x_i`). Each node's `x`
//! is scaled by its own trusted speed², so slow nodes are resolved as finely as fast
//! ones. Constraints, every one at every node or cell:
//!
//! * **the speed limits of [`topp`]** (exact): feed, each axis's velocity, the chord at
//!   the period, rest at corners, stops, dwells and the ends, the one-period kink bound:
//!   `x_i ≤ v_cap²`;
//! * **acceleration** (exact on the grid): the set-point's acceleration `t·a_c + κ·x_p`
//!   at both ends `p` of each cell (each end with its own side's frame), its norm within
//!   `path_acc` (a cone), each axis's component within that axis's limit;
//! * **jerk** (linearized): the set-point's jerk is `v·(t·a' + 3κ·a + κ'·v²)` (`' =
//!   d/ds`, `κ = d²M/ds²`). At each node between two cells it is taken with `a'` the
//!   difference of the two cells' accelerations over the distance between the cells'
//!   middles, `a` their mean, and the leading `v` replaced by a fixed `v̄`. Then it is
//!   linear in the unknowns: its norm within `path_jerk_mm_per_s3` (a cone), each axis's
//!   component within that axis's jerk;
//! * **`κ'`** is the difference of the curvature vectors over a window around the node at
//!   least `v̄·T` long (`T` the period) and at least a cell on each side: on a smooth
//!   curve this is the derivative;
//! * **curvature jumps** (a knot of a quadratic, a junction without a kink): the
//!   acceleration steps by `v²·Δκ` within one period, which the feed table's jerk
//!   measure (third differences of set-points) sees as at least half of `v²·|Δκ|/T`
//!   whatever the step's phase ([`STEP_JERK_SHARE`]): `x ≤ 2·J·T/|Δκ|` at the node,
//!   path and each axis (the window of `κ'` above spreads the step over two cells, a
//!   fifteenth of what the measure sees at 100 mm/s on a 0.25 mm grid);
//! * **kinks** (a junction whose tangent turns, or a cell the grid could not resolve or
//!   that merging made, turning more than `2·MAX_TURN_RAD`): no jerk constraint at them
//!   (no finite jerk follows a kink; the feed table's jerk measure leaves out the three
//!   cycles after a turning junction). Their speed keeps the one-period bounds: the
//!   acceleration's `v·|Δt|/T ≤ A` (as [`topp`]) and, for a kink inside a block (which
//!   the table's measure keeps), the jerk's `v·|Δt|/T² ≤ J`, path and each axis;
//! * **leaving and reaching rest**: at rest the jerk's leading `v` vanishes, so the
//!   node next to a rest node gets the bound of a start with zero acceleration and the
//!   jerk `J_t = min(path_jerk, J_k/|t_k|)` held: `v ≤ J_t/2·(6Δs/J_t)^(2/3)` after a
//!   cell of length `Δs` (the pure-jerk start `s = J t³/6`, `v = J t²/2`), and that
//!   cell takes at least `(6Δs/J_t)^(1/3)` (its time when the node is at the bound).
//!
//! **The iteration** (each rest-to-rest stretch on its own). The first solve takes `v̄`
//! and a trust bound `x_i ≤ u_i²` both from the acceleration-only optimum, which no
//! jerk-limited profile exceeds. Each later solve takes `u = (1 + δ)·v` of the best
//! profile so far and `v̄ = u`: a solution then has `v ≤ v̄` at every node, so its true
//! jerk `v·|…| ≤ v̄·|…| ≤ J` (an inner approximation: every solve keeps the jerk, up to
//! the window of `κ'`, which moves with `v̄`, and the solver's rounding). Its own jerk
//! (with its own speeds, [`JerkOptimum::jerk_ratio`]) is checked; the fastest solve
//! within [`KEEP_JERK`] is kept. `δ` starts at [`DELTA0`] and shrinks by [`SHRINK`]
//! whenever a solve gains less than half of it, down to [`DELTA_MIN`]; the solves stop
//! there once one gains less than [`GAIN`], or after [`MAX_ROUNDS`]. Where the jerk
//! binds, the kept profile is therefore up to `δ` short of the linearization's fixed
//! point (the speed about `δ/3`); a circle's cruise ends 0.7 % below `(J r²)^(1/3)`.
//! `TOPP3_TRACE=1` prints each solve's time and own jerk.
//!
//! What it is and is not: a jerk-feasible profile of the discretized problem (the
//! grid's constraints at its nodes, jerk by differences over cells) close to its optimum,
//! so an upper bound of that problem's optimum, not a proven optimum. Measured
//! (`tests/tests/topp3.rs`): the 7-phase S-curve of a line to 2.4e-3 at worst (the
//! reference slower), a circle's cruise to 7.4e-3 below `(J r²)^(1/3)`, the
//! acceleration-only optimum when the jerk does not bind to 1.0e-4, a change of 2.1e-4
//! from halving the feed table's 0.25 mm grid on LinuxCNC's NURBS program. **Known
//! limit**: next to rest the differences overstate the jerk (`x ∝ s^(4/3)` there: the
//! second difference at the first node is 17 % above the derivative), so a start from
//! rest is a little slow: 4.3e-3 and 5.6e-3 on a 0.2 mm move on 0.01 and 0.004 mm
//! grids; programs that stop often carry a few tenths of a percent of it.

use crate::topp::{self, GridPoint, RefLimits, MAX_TURN_RAD};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use shared::protocol::CommandBlock;
use shared::Machine;

/// At most this many solves a stretch.
pub const MAX_ROUNDS: usize = 14;
/// A solve's profile counts as keeping the jerk when its own jerk (with its own speeds)
/// is within this many times the limit; of those, the fastest is kept.
pub const KEEP_JERK: f64 = 1.0 + 2e-3;
/// The first trust factor: a solve's jerk is taken with `u = (1 + δ)·v` of the best
/// profile so far and its speeds kept below `u`; `δ` shrinks by [`SHRINK`] whenever a
/// solve gains less than half of it, down to [`DELTA_MIN`].
pub const DELTA0: f64 = 0.25;
pub const DELTA_MIN: f64 = 0.002;
/// The factor `δ` shrinks by.
pub const SHRINK: f64 = 0.6;
/// At [`DELTA_MIN`], the solves stop once one shortens the best time by less than this
/// (relative).
pub const GAIN: f64 = 1e-4;
/// Cells shorter than this are merged (see [`nodes`]), mm.
pub const MIN_NODE_MM: f64 = 1e-4;
/// Cells beside rest are graded down to this (see [`graded`]), mm.
pub const GRADE_MIN_MM: f64 = 0.005;

/// The limits of the jerk-limited reference: those of [`topp`] and the jerks, mm/s³.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JerkLimits {
    pub base: RefLimits,
    pub path_jerk: f64,
    pub axis_jerk: [f64; 3],
}

impl JerkLimits {
    /// The limits of `machine` at the interpolation period `period_ns`.
    pub fn of(machine: &Machine, period_ns: u64) -> Self {
        JerkLimits {
            base: RefLimits::of(machine, period_ns),
            path_jerk: machine.path_jerk_mm_per_s3,
            axis_jerk: machine.axes.as_array().map(|a| a.max_jerk_mm_per_s3),
        }
    }
}

/// The jerk-limited time-optimal profile of a path.
#[derive(Debug, Clone, PartialEq)]
pub struct JerkOptimum {
    /// Motion plus dwell time, s.
    pub time_s: f64,
    pub dwell_s: f64,
    /// The acceleration-only optimum on the same grid, s (motion plus dwell).
    pub acc_only_s: f64,
    /// Arc length and optimal speed (mm/s) of each node.
    pub s: Vec<f64>,
    pub speed: Vec<f64>,
    /// The largest relative change of a stretch's time in its last solve.
    pub last_change: f64,
    /// The most solves any stretch took.
    pub rounds: usize,
    /// The largest last trust factor `δ` of a stretch (the profile's jerk is taken with
    /// speeds up to `1 + δ` times its own where it binds).
    pub trust: f64,
    /// The profile's jerk with its own speeds (not `v̄`), in units of the limit (the
    /// largest of path and axes), and its acceleration likewise.
    pub jerk_ratio: f64,
    pub acc_ratio: f64,
}

/// One node: a grid point, or the two points of a junction (`in` the side before).
#[derive(Debug, Clone, Copy)]
struct Node {
    s: f64,
    cap2: f64,
    t_in: [f64; 3],
    k_in: [f64; 3],
    t_out: [f64; 3],
    k_out: [f64; 3],
    kink: bool,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    let c = dot(a, b).clamp(-1.0, 1.0);
    let s = norm([
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]);
    s.atan2(c)
}

fn nodes(grid: &[GridPoint], lim: &JerkLimits) -> Vec<Node> {
    let mut out: Vec<Node> = Vec::new();
    for p in grid {
        let cap2 = p.v_cap * p.v_cap;
        match out.last_mut() {
            Some(n) if p.s <= n.s => {
                n.cap2 = n.cap2.min(cap2);
                n.t_out = p.tangent;
                n.k_out = p.curvature;
            }
            _ => out.push(Node {
                s: p.s,
                cap2,
                t_in: p.tangent,
                k_in: p.curvature,
                t_out: p.tangent,
                k_out: p.curvature,
                kink: false,
            }),
        }
    }
    // Cells shorter than MIN_NODE_MM are merged into their neighbours (a point that is
    // neither a junction nor at rest is dropped, its speed limit kept by the point
    // before): differences over them would measure the solver's rounding.
    let mut merged: Vec<Node> = Vec::with_capacity(out.len());
    let last = out.len().saturating_sub(1);
    for (i, p) in out.iter().enumerate() {
        let plain = p.cap2 > 0.0 && angle(p.t_in, p.t_out) <= 1e-9;
        match merged.last_mut() {
            Some(q) if i < last && plain && p.s - q.s < MIN_NODE_MM => {
                q.cap2 = q.cap2.min(p.cap2);
            }
            _ => merged.push(*p),
        }
    }
    let mut out = merged;
    // A junction whose tangent turns, and both ends of a cell the grid did not resolve
    // (or that merging made): a turn within one period, whose speed keeps the
    // one-period bounds of the acceleration (as `topp`) and, inside a block, of the
    // jerk (the table's jerk measure keeps such a turn).
    let n = out.len();
    for i in 0..n {
        if angle(out[i].t_in, out[i].t_out) > 1e-9 {
            out[i].kink = true;
        } else {
            let cap2 = step_cap2(out[i].k_in, out[i].k_out, lim);
            out[i].cap2 = out[i].cap2.min(cap2);
        }
        if i + 1 < n && angle(out[i].t_out, out[i + 1].t_in) > 2.0 * MAX_TURN_RAD {
            let cap = kink_cap(out[i].t_out, out[i + 1].t_in, lim);
            for q in [i, i + 1] {
                out[q].kink = true;
                out[q].cap2 = out[q].cap2.min(cap * cap);
            }
        }
    }
    out
}

/// The least share of an acceleration step `Δa` that the set-points' jerk (their third
/// difference over `T³`) shows, whatever the step's phase between two set-points: a step
/// a share `φ` of a period after a set-point enters three third differences by
/// `(1 − φ)²/2`, `(1 + 2φ − 2φ²)/2` and `φ²/2` of `Δa/T`, the largest of which is
/// between 1/2 (a step on a set-point) and 3/4 (half-way, the planner's
/// `SAMPLED_STEP`, which must hold for every phase).
pub const STEP_JERK_SHARE: f64 = 0.5;

/// The largest speed² at a node whose curvature jumps from `k_in` to `k_out` without a
/// turn (a quadratic's knot, a line meeting an arc): the acceleration steps by
/// `v²·Δκ` there, which the set-points show as a jerk of at least
/// [`STEP_JERK_SHARE`]`·v²·|Δκ|/T`, path (norm) and each axis (component). (Taken over
/// the window of `κ'` instead, two cells of the grid, a quadratic's knots were passed
/// at up to twice the speed the measure allows.)
fn step_cap2(k_in: [f64; 3], k_out: [f64; 3], lim: &JerkLimits) -> f64 {
    let t = lim.base.period_s;
    least_over(
        [k_out[0] - k_in[0], k_out[1] - k_in[1], k_out[2] - k_in[2]],
        lim.path_jerk * t / STEP_JERK_SHARE,
        lim.axis_jerk.map(|j| j * t / STEP_JERK_SHARE),
    )
}

/// The least of `path / |d|` and each axis's `axis[k] / |d_k|` (a zero part bounds
/// nothing): the largest multiple of `d` within the path's (norm) and each axis's
/// (component) limits.
fn least_over(d: [f64; 3], path: f64, axis: [f64; 3]) -> f64 {
    let n = norm(d);
    let mut least = if n > 0.0 { path / n } else { f64::INFINITY };
    for (dk, a) in d.iter().zip(axis) {
        if *dk != 0.0 {
            least = least.min(a / dk.abs());
        }
    }
    least
}

/// The speed of a turn from `a` to `b` within one period `T`: its velocity change
/// `v·(b − a)` taken in one period keeps the acceleration, `v·|b − a|/T ≤ A`, and that
/// acceleration taken on and off in one period keeps the jerk, `v·|b − a|/T² ≤ J`, each
/// for the path (norm) and each axis (component).
fn kink_cap(a: [f64; 3], b: [f64; 3], lim: &JerkLimits) -> f64 {
    let t = lim.base.period_s;
    least_over(
        [b[0] - a[0], b[1] - a[1], b[2] - a[2]],
        (lim.base.path_acc * t).min(lim.path_jerk * t * t),
        [0, 1, 2].map(|k| (lim.base.axis_acc[k] * t).min(lim.axis_jerk[k] * t * t)),
    )
}

/// The grid with each cell beside a rest point (longer than [`GRADE_MIN_MM`]) cut into
/// pieces halving towards the rest point, down to [`GRADE_MIN_MM`] or a 64th of the
/// cell: a start from rest grows like `s^(4/3)` in `x` over its first millimetres, which
/// one cell linear in `x` (the table's long parts: cells of up to 16 mm) overstates by
/// up to half of its time. The new points take the cell's frame linearly interpolated
/// (a cell turns at most [`MAX_TURN_RAD`]) and the speed limit of its end away from rest.
pub fn graded(grid: &[GridPoint]) -> Vec<GridPoint> {
    let mut out: Vec<GridPoint> = Vec::with_capacity(grid.len());
    let lerp = |a: &GridPoint, b: &GridPoint, f: f64, cap: f64| {
        let mix = |x: [f64; 3], y: [f64; 3]| [0, 1, 2].map(|k| x[k] + f * (y[k] - x[k]));
        let t = mix(a.tangent, b.tangent);
        let n = norm(t).max(1e-300);
        GridPoint {
            s: a.s + f * (b.s - a.s),
            tangent: t.map(|x| x / n),
            curvature: mix(a.curvature, b.curvature),
            v_cap: cap,
        }
    };
    for (i, p) in grid.iter().enumerate() {
        if let Some(q) = grid.get(i + 1) {
            out.push(*p);
            let len = q.s - p.s;
            let (rest_a, rest_b) = (p.v_cap <= 0.0, q.v_cap <= 0.0);
            if len > GRADE_MIN_MM && rest_a != rest_b {
                let finest = GRADE_MIN_MM.max(len / 64.0);
                let mut fr: Vec<f64> = Vec::new();
                let mut f = 0.5;
                while f * len >= finest {
                    fr.push(f);
                    f *= 0.5;
                }
                if rest_a {
                    fr.reverse();
                    for f in fr {
                        out.push(lerp(p, q, f, q.v_cap));
                    }
                } else {
                    for f in fr {
                        out.push(lerp(p, q, 1.0 - f, p.v_cap));
                    }
                }
            }
        } else {
            out.push(*p);
        }
    }
    out
}

/// `dκ/ds` at node `i`: the curvature's difference over a window around it at least `h`
/// long and at least one cell on each side (see the module page).
fn curvature_rate(nd: &[Node], i: usize, h: f64) -> [f64; 3] {
    let n = nd.len();
    let (mut j, mut k) = (i, i);
    loop {
        let sides = (j < i || j == 0) && (k > i || k + 1 == n);
        if sides && nd[k].s - nd[j].s >= h {
            break;
        }
        let left = nd[i].s - nd[j].s;
        let right = nd[k].s - nd[i].s;
        if j > 0 && (left <= right || k + 1 == n) {
            j -= 1;
        } else if k + 1 < n {
            k += 1;
        } else {
            break;
        }
    }
    let w = nd[k].s - nd[j].s;
    if w <= 0.0 {
        return [0.0; 3];
    }
    let (a, b) = (nd[j].k_out, nd[k].k_in);
    [0, 1, 2].map(|m| (b[m] - a[m]) / w)
}

/// The largest speed² reachable a distance `ds` from rest with zero acceleration and the
/// jerk `j` held (`s = j t³/6`, `v = j t²/2`).
pub fn start_cap2(ds: f64, j: f64) -> f64 {
    let t = (6.0 * ds / j).cbrt();
    let v = 0.5 * j * t * t;
    v * v
}

/// The tangential jerk available at rest with tangent `t`.
fn rest_jerk(t: [f64; 3], lim: &JerkLimits) -> f64 {
    let mut j = lim.path_jerk;
    for (tk, jk) in t.iter().zip(lim.axis_jerk) {
        if tk.abs() > 1e-12 {
            j = j.min(jk / tk.abs());
        }
    }
    j
}

/// The jerk of the profile `x` at interior node `i` with its own speed.
fn node_jerk(nd: &[Node], x: &[f64], i: usize, period_s: f64) -> [f64; 3] {
    let v = x[i].max(0.0).sqrt();
    let a0 = (x[i] - x[i - 1]) / (2.0 * (nd[i].s - nd[i - 1].s));
    let a1 = (x[i + 1] - x[i]) / (2.0 * (nd[i + 1].s - nd[i].s));
    let [p, q, r] = jerk_terms(nd, i, v, v * period_s);
    [0, 1, 2].map(|m| p[m] * a0 + q[m] * a1 + r[m] * x[i])
}

/// The worst acceleration and jerk of the profile `x` over `nd`, with its own speeds,
/// in units of their limits.
fn worst_ratios(nd: &[Node], x: &[f64], lim: &JerkLimits) -> (f64, f64) {
    let n = nd.len();
    let (mut acc, mut jerk) = (0.0f64, 0.0f64);
    let ratio = |v: [f64; 3], path: f64, axes: [f64; 3]| {
        (0..3).fold(norm(v) / path, |m, q| m.max(v[q].abs() / axes[q]))
    };
    for c in 0..n.saturating_sub(1) {
        let ds = nd[c + 1].s - nd[c].s;
        let a = (x[c + 1] - x[c]) / (2.0 * ds);
        for (t, k, xp) in [
            (nd[c].t_out, nd[c].k_out, x[c]),
            (nd[c + 1].t_in, nd[c + 1].k_in, x[c + 1]),
        ] {
            let v = [0, 1, 2].map(|q| t[q] * a + k[q] * xp);
            acc = acc.max(ratio(v, lim.base.path_acc, lim.base.axis_acc));
        }
    }
    for i in 1..n.saturating_sub(1) {
        if nd[i].kink {
            continue;
        }
        let j = node_jerk(nd, x, i, lim.base.period_s);
        jerk = jerk.max(ratio(j, lim.path_jerk, lim.axis_jerk));
    }
    (acc, jerk)
}

/// The motion time of a profile `x` over `nd` (`x` linear in `s` over each cell): a cell
/// leaving or reaching rest takes at least `(6Δs/J_t)^(1/3)` (the pure-jerk start, its
/// time exactly when the node beside rest is at its start bound), a single cell from
/// rest to rest the pure-jerk time `4·(Δs/(2J_t))^(1/3)`.
fn motion_time(nd: &[Node], x: &[f64], lim: &JerkLimits) -> f64 {
    (0..nd.len().saturating_sub(1))
        .map(|c| {
            let ds = nd[c + 1].s - nd[c].s;
            let v = x[c].max(0.0).sqrt() + x[c + 1].max(0.0).sqrt();
            // A cell leaving or reaching rest takes at least the pure-jerk start's time.
            let start = if x[c] <= 0.0 {
                (6.0 * ds / rest_jerk(nd[c].t_out, lim)).cbrt()
            } else if x[c + 1] <= 0.0 {
                (6.0 * ds / rest_jerk(nd[c + 1].t_in, lim)).cbrt()
            } else {
                0.0
            };
            if ds <= 0.0 {
                0.0
            } else if v > 0.0 {
                (2.0 * ds / v).max(start)
            } else {
                4.0 * (ds / (2.0 * rest_jerk(nd[c].t_out, lim))).cbrt()
            }
        })
        .sum()
}

/// Rows of the conic problem: `b − A·z ∈ K`, built cone by cone.
#[derive(Default)]
struct Rows {
    ai: Vec<usize>,
    aj: Vec<usize>,
    av: Vec<f64>,
    b: Vec<f64>,
    cones: Vec<SupportedConeT<f64>>,
}

impl Rows {
    /// A cone block: each row is `(b, [(column, coefficient of A)])`, scaled so that its
    /// largest entry is 1 (a cone is invariant under a positive factor).
    fn push(&mut self, cone: SupportedConeT<f64>, rows: &[(f64, Vec<(usize, f64)>)]) {
        let big = rows
            .iter()
            .flat_map(|(b, r)| std::iter::once(b.abs()).chain(r.iter().map(|e| e.1.abs())))
            .fold(0.0f64, f64::max);
        let f = if big > 0.0 { 1.0 / big } else { 1.0 };
        for (b, r) in rows {
            let row = self.b.len();
            for &(j, v) in r {
                if v != 0.0 {
                    self.ai.push(row);
                    self.aj.push(j);
                    self.av.push(v * f);
                }
            }
            self.b.push(b * f);
        }
        self.cones.push(cone);
    }

    /// `‖u‖ ≤ w`, `u` and `w` affine: `(constant, [(column, coefficient)])`.
    fn soc(&mut self, w: (f64, Vec<(usize, f64)>), u: &[(f64, Vec<(usize, f64)>)]) {
        let mut rows = vec![(w.0, w.1.iter().map(|&(j, v)| (j, -v)).collect())];
        for (c, r) in u {
            rows.push((*c, r.iter().map(|&(j, v)| (j, -v)).collect()));
        }
        let d = rows.len();
        self.push(SupportedConeT::SecondOrderConeT(d), &rows);
    }

    /// `Σ coef·z ≤ c`.
    fn le(&mut self, c: f64, r: Vec<(usize, f64)>) {
        self.push(SupportedConeT::NonnegativeConeT(1), &[(c, r)]);
    }
}

/// The jerk at interior node `i` as `P·a₀ + Q·a₁ + R·x_i` (`a₀`, `a₁` the accelerations
/// of the cells before and after it) with the leading speed `vbar` and `κ'` from the
/// window `h`: `vbar·(t·(a₁ − a₀)/h_m + 3κ·(a₀ + a₁)/2 + κ'·x_i)`, `h_m` the distance
/// between the cells' middles (see the module page).
fn jerk_terms(nd: &[Node], i: usize, vbar: f64, h: f64) -> [[f64; 3]; 3] {
    let hm = 0.5 * (nd[i + 1].s - nd[i - 1].s);
    let t = nd[i].t_out;
    let k = [0, 1, 2].map(|m| 0.5 * (nd[i].k_in[m] + nd[i].k_out[m]));
    let kr = curvature_rate(nd, i, h);
    [
        [0, 1, 2].map(|q| vbar * (-t[q] / hm + 1.5 * k[q])),
        [0, 1, 2].map(|q| vbar * (t[q] / hm + 1.5 * k[q])),
        [0, 1, 2].map(|q| vbar * kr[q]),
    ]
}

/// Solves one stretch `nd` (rest at both ends) with the jerk's leading speed taken as
/// `vbar` and no node above it (where it is positive): the new `x`, or `None` if the
/// solver fails. The cells' accelerations are unknowns of their own (tied to `x` by
/// `x_{c+1} − x_c = 2Δs·a_c`), so a jerk row is a difference of two of them, not a
/// second difference of `x` (which the solver's rounding swamps on short cells).
fn solve_stretch(nd: &[Node], vbar: &[f64], trust: &[f64], lim: &JerkLimits) -> Option<Vec<f64>> {
    let n = nd.len();
    // The trust region: no node above its `trust` speed.
    let trusted = |i: usize| nd[i].cap2.min(trust[i] * trust[i]);
    let vs = (0..n)
        .map(|i| trusted(i).sqrt())
        .filter(|v| v.is_finite())
        .fold(1e-9f64, f64::max);
    let v2 = vs * vs;
    let len = nd[n - 1].s - nd[0].s;
    let (pa, pj) = (lim.base.path_acc, lim.path_jerk);
    // Each node's own scale `σ_i` (mm²/s²): its trusted speed², so that a slow node's `x`
    // is resolved as finely as a fast one's.
    let sig: Vec<f64> = (0..n)
        .map(|i| {
            let c = trusted(i);
            if c.is_finite() && c > 1e-12 * v2 {
                c
            } else if c.is_finite() {
                1e-12 * v2
            } else {
                v2
            }
        })
        .collect();
    let w: Vec<f64> = (0..n - 1).map(|c| sig[c].max(sig[c + 1]).sqrt()).collect();
    let tref = len / vs;
    // Unknowns, dimensionless: x̂_i = x_i/σ_i, v̂_i = v_i/√σ_i, τ̂_c = τ_c·W_c/Δs_c (W_c
    // the larger √σ of the cell's ends), â_c = a_c/A.
    let xi = |i: usize| i;
    let vi = |i: usize| n + i;
    let ti = |c: usize| 2 * n + c;
    let ai = |c: usize| 3 * n - 1 + c;
    let nvar = 4 * n - 2;
    let mut q = vec![0.0; nvar];
    let mut rows = Rows::default();
    for i in 0..n {
        let mut cap = trusted(i);
        let rest = |k: usize| nd[k].cap2 <= 0.0;
        if i > 0 && rest(i - 1) && !rest(i) {
            let j = rest_jerk(nd[i - 1].t_out, lim);
            cap = cap.min(start_cap2(nd[i].s - nd[i - 1].s, j));
        }
        if i + 1 < n && rest(i + 1) && !rest(i) {
            let j = rest_jerk(nd[i + 1].t_in, lim);
            cap = cap.min(start_cap2(nd[i + 1].s - nd[i].s, j));
        }
        if cap.is_finite() {
            rows.le(cap / sig[i], vec![(xi(i), 1.0)]);
        }
        // v̂² ≤ x̂: ‖(2v̂, x̂ − 1)‖ ≤ x̂ + 1.
        rows.soc(
            (1.0, vec![(xi(i), 1.0)]),
            &[(0.0, vec![(vi(i), 2.0)]), (-1.0, vec![(xi(i), 1.0)])],
        );
    }
    for c in 0..n - 1 {
        let ds = nd[c + 1].s - nd[c].s;
        q[ti(c)] = ds / w[c] / tref;
        // τ̂·y ≥ 2, y = (√σ_c v̂_c + √σ_{c+1} v̂_{c+1})/W_c: ‖(2√2, τ̂ − y)‖ ≤ τ̂ + y.
        let (f0, f1) = (sig[c].sqrt() / w[c], sig[c + 1].sqrt() / w[c]);
        rows.soc(
            (0.0, vec![(ti(c), 1.0), (vi(c), f0), (vi(c + 1), f1)]),
            &[
                (2.0 * 2f64.sqrt(), vec![]),
                (0.0, vec![(ti(c), 1.0), (vi(c), -f0), (vi(c + 1), -f1)]),
            ],
        );
        // σ_{c+1}·x̂_{c+1} − σ_c·x̂_c = 2Δs·A·â_c.
        rows.push(
            SupportedConeT::ZeroConeT(1),
            &[(
                0.0,
                vec![
                    (xi(c + 1), -sig[c + 1]),
                    (xi(c), sig[c]),
                    (ai(c), 2.0 * ds * pa),
                ],
            )],
        );
        // Acceleration at both ends of the cell, over A: t·â_c + κ·(σ_p/A)·x̂_p.
        for (p, t, k) in [
            (c, nd[c].t_out, nd[c].k_out),
            (c + 1, nd[c + 1].t_in, nd[c + 1].k_in),
        ] {
            let comp = |m: usize| (0.0, vec![(ai(c), t[m]), (xi(p), k[m] * sig[p] / pa)]);
            let u = [comp(0), comp(1), comp(2)];
            rows.soc((1.0, vec![]), &u);
            for (m, am) in lim.base.axis_acc.iter().enumerate() {
                if *am < pa {
                    rows.le(am / pa, u[m].1.clone());
                    rows.le(am / pa, u[m].1.iter().map(|&(j, v)| (j, -v)).collect());
                }
            }
        }
    }
    // Jerk at interior nodes, linearized about `vbar`, over the path jerk.
    for i in 1..n - 1 {
        if nd[i].kink || vbar[i] <= 0.0 {
            continue;
        }
        let [p0, p1, r] = jerk_terms(nd, i, vbar[i], vbar[i] * lim.base.period_s);
        let comp = |m: usize| {
            (
                0.0,
                vec![
                    (ai(i - 1), p0[m] * pa / pj),
                    (ai(i), p1[m] * pa / pj),
                    (xi(i), r[m] * sig[i] / pj),
                ],
            )
        };
        let u = [comp(0), comp(1), comp(2)];
        rows.soc((1.0, vec![]), &u);
        for (m, jm) in lim.axis_jerk.iter().enumerate() {
            if *jm < pj {
                rows.le(jm / pj, u[m].1.clone());
                rows.le(jm / pj, u[m].1.iter().map(|&(j, v)| (j, -v)).collect());
            }
        }
    }
    let m = rows.b.len();
    let a = CscMatrix::new_from_triplets(m, nvar, rows.ai, rows.aj, rows.av);
    let p = CscMatrix::zeros((nvar, nvar));
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .max_iter(300)
        .tol_gap_rel(1e-7)
        .tol_gap_abs(1e-7)
        .tol_feas(1e-7)
        .build()
        .ok()?;
    let mut solver = DefaultSolver::new(&p, &q, &a, &rows.b, &rows.cones, settings).ok()?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {}
        _ => return None,
    }
    Some(
        (0..n)
            .map(|i| (solver.solution.x[xi(i)] * sig[i]).clamp(0.0, nd[i].cap2))
            .collect(),
    )
}

/// The jerk-limited optimum over a grid: the motion time, the speeds at the nodes, and
/// the convergence figures. `v0` is the acceleration-only optimum at the grid points.
fn time_optimal(grid: &[GridPoint], v0: &[f64], lim: &JerkLimits) -> Result<JerkOptimum, String> {
    let nd = nodes(grid, lim);
    let n = nd.len();
    // The first `u`: the acceleration-only optimum, at each node the lower of its points'.
    let mut ubar = vec![f64::INFINITY; n];
    let mut k = 0;
    for (gi, p) in grid.iter().enumerate() {
        while k + 1 < n && nd[k + 1].s <= p.s {
            k += 1;
        }
        ubar[k] = ubar[k].min(v0[gi]);
    }
    let mut x = vec![0.0; n];
    let (mut last_change, mut rounds, mut trust) = (0.0f64, 0usize, 0.0f64);
    let mut start = 0;
    while start + 1 < n {
        let end = (start + 1..n).find(|&i| nd[i].cap2 <= 0.0).unwrap_or(n - 1);
        let part = &nd[start..=end];
        if part.len() == 2 {
            start = end;
            continue;
        }
        let (_, xs, r, change, delta) = stretch(part, &ubar[start..=end], lim)?;
        x[start..=end].copy_from_slice(&xs);
        last_change = last_change.max(change);
        rounds = rounds.max(r);
        trust = trust.max(delta);
        start = end;
    }
    let (acc_ratio, jerk_ratio) = worst_ratios(&nd, &x, lim);
    Ok(JerkOptimum {
        time_s: motion_time(&nd, &x, lim),
        dwell_s: 0.0,
        acc_only_s: 0.0,
        s: nd.iter().map(|p| p.s).collect(),
        speed: x.iter().map(|v| v.sqrt()).collect(),
        last_change,
        rounds,
        trust,
        jerk_ratio,
        acc_ratio,
    })
}

/// One stretch `part` (rest at both ends) from the acceleration-only speeds `v0`: its
/// time, profile, solves, last relative gain and last trust factor `δ`. See the module
/// page.
#[allow(clippy::type_complexity)]
fn stretch(
    part: &[Node],
    v0: &[f64],
    lim: &JerkLimits,
) -> Result<(f64, Vec<f64>, usize, f64, f64), String> {
    let fail = || {
        format!(
            "the conic solver failed on the stretch {:.3}..{:.3} mm",
            part[0].s,
            part[part.len() - 1].s
        )
    };
    let trace = std::env::var_os("TOPP3_TRACE").is_some();
    let n = part.len();
    // The first solve: the jerk's speed and the trust region both the acceleration-only
    // optimum's, which no jerk-limited profile exceeds (so its profile keeps the jerk).
    let v0: Vec<f64> = v0
        .iter()
        .zip(part)
        .map(|(v, p)| v.min(p.cap2.sqrt()))
        .collect();
    let (mut vbar, mut trust) = (v0.clone(), v0.clone());
    let mut best: Option<(f64, Vec<f64>)> = None;
    let mut delta = DELTA0;
    let (mut r, mut change) = (0, f64::INFINITY);
    while r < MAX_ROUNDS {
        let xs = solve_stretch(part, &vbar, &trust, lim).ok_or_else(fail)?;
        r += 1;
        let t = motion_time(part, &xs, lim);
        let own = worst_ratios(part, &xs, lim).1;
        if trace {
            eprintln!(
                "stretch {:.3}..{:.3} ({n} nodes) round {r} δ {delta:.4}: time {t:.6} own jerk {own:.4}",
                part[0].s,
                part[n - 1].s,
            );
        }
        let before = best.as_ref().map_or(f64::INFINITY, |b| b.0);
        if own <= KEEP_JERK && t < before {
            best = Some((t, xs));
        }
        let after = best.as_ref().map_or(f64::INFINITY, |b| b.0);
        change = if before.is_finite() {
            (before - after) / after
        } else {
            f64::INFINITY
        };
        if delta <= DELTA_MIN && change < GAIN {
            break;
        }
        // The next solve: no node more than `1 + δ` above the best profile so far, and
        // the jerk taken at that bound (so its profile keeps the jerk); `δ` shrinks by
        // [`SHRINK`] once a solve gains less than half of it.
        if change < 0.5 * delta {
            delta = (delta * SHRINK).max(DELTA_MIN);
        }
        let Some((_, b)) = &best else {
            // No kept profile yet (the solver's rounding): a tighter trust region.
            for v in trust.iter_mut() {
                *v /= 1.0 + delta;
            }
            vbar.clone_from(&trust);
            continue;
        };
        for i in 0..n {
            trust[i] = (b[i].sqrt() * (1.0 + delta)).min(part[i].cap2.sqrt());
            vbar[i] = trust[i];
        }
    }
    let (t, xs) = best.ok_or_else(fail)?;
    Ok((t, xs, r, change, delta))
}

/// The jerk-limited time-optimal profile of `blocks` under `lim`, on a grid of `step_mm`
/// (the grid of [`topp::grid`]).
pub fn optimum(
    blocks: &[CommandBlock],
    feeds_mm_per_s: &[f64],
    lim: &JerkLimits,
    step_mm: f64,
) -> Result<JerkOptimum, String> {
    let (grid, dwell_s) = topp::grid(blocks, feeds_mm_per_s, &lim.base, step_mm);
    let grid = graded(&grid);
    let (t2, v0) = topp::time_optimal(&grid, &lim.base);
    let mut o = time_optimal(&grid, &v0, lim)?;
    o.time_s += dwell_s;
    o.dwell_s = dwell_s;
    o.acc_only_s = t2 + dwell_s;
    Ok(o)
}
