//! A jerk-limited time-optimal reference for the feed planner (TOPP3): the fastest
//! profile along the same exact path, on the same grid and under the same limits as the
//! acceleration-only reference of [`crate::topp`], plus the path's and each axis's jerk.
//! It is what issue #23's goal "time ≤ 1.05 × the jerk-limited optimum" is measured
//! against. Written from the literature's convex formulation (Verscheure et al. 2009
//! for the time objective in `x = v²`; the jerk linearized about the previous profile as
//! the TOPP3 papers do), solved with the `clarabel` conic solver.
//!
//! **The problem.** The grid of [`topp::grid`] (cells of at most the step, turning at
//! most [`topp::MAX_TURN_RAD`]; a junction is two points at the same `s`, merged here
//! into one node with the frames of both sides). Unknowns at each node `x_i = v_i²`;
//! `x` is linear in `s` over a cell, so the cell's path acceleration is
//! `a_c = (x_{c+1} − x_c)/(2Δs_c)` and its time `2Δs_c/(v_c + v_{c+1})`, exactly. The
//! objective is the sum of the cells' times (convex: each a second-order cone with
//! `v_i² ≤ x_i`). Constraints, every one at every node or cell:
//!
//! * **the speed limits of [`topp`]** (exact): feed, each axis's velocity, the chord at
//!   the period, rest at corners, stops, dwells and the ends, the one-period kink bound:
//!   `x_i ≤ v_cap²`;
//! * **acceleration** (exact on the grid): the set-point's acceleration `t·a_c + κ·x_p`
//!   at both ends `p` of each cell (each end with its own side's frame), its norm within
//!   `path_acc` (a cone), each axis's component within that axis's limit;
//! * **jerk, linearized** (the one approximation): the set-point's jerk is
//!   `v·(t·a' + 3κ·a + κ'·v²)` (`' = d/ds`, `κ = d²M/ds²`). At each node between two
//!   cells it is taken with `a'` the difference of the two cells' accelerations over the
//!   distance between the cells' middles, `a` their mean, and the leading `v` replaced
//!   by `v̄`, the previous solve's speed there (the first `v̄` is the
//!   acceleration-only optimum; from the third solve on `v̄` moves half way to the last
//!   solution's speeds, which damps a swing between two profiles). Then it is linear in
//!   `x`: its norm within `path_jerk_mm_per_s3` (a cone), each axis's component within
//!   that axis's jerk. The solves stop when the time changes by less than
//!   [`CONVERGED`] (or after [`MAX_ROUNDS`]); at the fixed point `v̄ = v` and the jerk
//!   is the grid profile's true one. Of a stretch's solves the fastest whose own jerk
//!   is within [`KEEP_JERK`] is kept (else the one of the lowest own jerk), so a solve
//!   that swung off never replaces a good one. [`JerkOptimum::jerk_ratio`] reports it with the
//!   profile's own speeds in units of its limit, which shows how far from the fixed
//!   point a run ended. **Known limit**: where the grid is much finer than the jerk
//!   phases of a start from rest (a 0.2 mm move on a 0.004 mm grid) the iteration does
//!   not settle (its own jerk 2.2 × the limit there); the table's grid (0.25 mm and
//!   coarser) settles (`tests/tests/topp3.rs`);
//! * **`κ'`** is the difference of the curvature vectors over a window around the node at
//!   least `v̄·T` long (`T` the period): on a smooth curve this is the derivative; where
//!   the curvature jumps (a knot of a quadratic, a junction without a kink) it gives the
//!   jerk `v²·Δκ/T` of an acceleration step taken in one period, as the engine takes it
//!   and as the feed table's jerk measure (third differences of set-points) sees it;
//! * **kinks** (a junction, or a grid cell that could not be resolved, whose tangent
//!   turns): no jerk constraint at them (no finite jerk follows a kink; the feed table's
//!   jerk measure also leaves them out); their speed keeps the one-period bound of [`topp`];
//! * **leaving and reaching rest**: at rest the jerk's leading `v` vanishes, so the
//!   node next to a rest node gets the bound of a start with zero acceleration and the
//!   jerk `J_t = min(path_jerk, J_k/|t_k|)` held: `v ≤ J_t/2·(6Δs/J_t)^(2/3)` after a
//!   cell of length `Δs` (the pure-jerk start `s = J t³/6`, `v = J t²/2`), and that
//!   cell takes at least `(6Δs/J_t)^(1/3)` (its time when the node is at the bound).
//!
//! Each stretch between two rest nodes is an independent problem. What it is and is not:
//! the optimum of the discretized problem (the grid's constraints at its nodes, jerk by
//! differences over cells), at the fixed point of the linearization (a KKT point of the
//! jerk-limited problem; the TOPP3 literature finds these globally optimal in practice,
//! not proven). Measured (`tests/tests/topp3.rs`): the 7-phase S-curve of a line to
//! 7.1e-3 at worst (0.2 mm; 2.8e-4 on 100 mm), a circle's cruise at `(J r²)^(1/3)` to
//! 4.5e-4, the acceleration-only optimum when the jerk does not bind to 1.1e-4, and a
//! change of 6.0e-4 from halving the feed table's 0.25 mm grid on LinuxCNC's NURBS
//! program. Its distance from the fixed point: [`JerkOptimum::last_change`].

use crate::topp::{self, GridPoint, RefLimits, MAX_TURN_RAD};
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use shared::protocol::CommandBlock;
use shared::Machine;

/// The solves stop when the time changes by less than this (relative).
pub const CONVERGED: f64 = 1e-3;
/// At most this many solves a stretch.
pub const MAX_ROUNDS: usize = 10;
/// A solve's profile counts as keeping the jerk when its own jerk (with its own speeds)
/// is within this many times the limit; of those, the fastest is kept.
pub const KEEP_JERK: f64 = 1.1;

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

fn nodes(grid: &[GridPoint]) -> Vec<Node> {
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
    // A junction whose tangent turns, and both ends of a cell the grid did not resolve.
    let n = out.len();
    for i in 0..n {
        if angle(out[i].t_in, out[i].t_out) > 1e-9 {
            out[i].kink = true;
        }
        if i + 1 < n && angle(out[i].t_out, out[i + 1].t_in) > 2.0 * MAX_TURN_RAD {
            out[i].kink = true;
            out[i + 1].kink = true;
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

/// The jerk coefficients at interior node `i` on `x` of nodes `i−1, i, i+1` with the
/// leading speed `vbar`, and `κ'` from the window `h` (see the module page).
fn jerk_coefs(nd: &[Node], i: usize, vbar: f64, h: f64) -> [[f64; 3]; 3] {
    let d0 = nd[i].s - nd[i - 1].s;
    let d1 = nd[i + 1].s - nd[i].s;
    let hm = 0.5 * (d0 + d1);
    // Coefficients of a_{c0} and a_{c1} on x_{i-1}, x_i, x_{i+1}.
    let c0 = [-0.5 / d0, 0.5 / d0, 0.0];
    let c1 = [0.0, -0.5 / d1, 0.5 / d1];
    let t = nd[i].t_out;
    let k = [0, 1, 2].map(|m| 0.5 * (nd[i].k_in[m] + nd[i].k_out[m]));
    let kr = curvature_rate(nd, i, h);
    let mut out = [[0.0; 3]; 3];
    for (m, o) in out.iter_mut().enumerate() {
        let da = (c1[m] - c0[m]) / hm;
        let am = 0.5 * (c0[m] + c1[m]);
        for q in 0..3 {
            o[q] = vbar * (t[q] * da + 3.0 * k[q] * am + if m == 1 { kr[q] } else { 0.0 });
        }
    }
    out
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
        let v = x[i].max(0.0).sqrt();
        let c = jerk_coefs(nd, i, v, v * lim.base.period_s);
        let j = [0, 1, 2].map(|q| c[0][q] * x[i - 1] + c[1][q] * x[i] + c[2][q] * x[i + 1]);
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

/// Solves one stretch `nd` (rest at both ends) with the jerk's leading speed taken as
/// `vbar`: the new `x`, or `None` if the solver fails.
fn solve_stretch(nd: &[Node], vbar: &[f64], lim: &JerkLimits) -> Option<Vec<f64>> {
    let n = nd.len();
    let vs = nd
        .iter()
        .map(|p| p.cap2.sqrt())
        .filter(|v| v.is_finite())
        .fold(1.0f64, f64::max);
    let v2 = vs * vs;
    let len = nd[n - 1].s - nd[0].s;
    let lref = len / (n - 1) as f64;
    // Unknowns, dimensionless: x̂_i = x_i/V², v̂_i = v_i/V, τ̂_c = τ_c·V/Δs_c.
    let (xi, vi, ti) = (|i: usize| i, |i: usize| n + i, |c: usize| 2 * n + c);
    let nvar = 3 * n - 1;
    let mut q = vec![0.0; nvar];
    let mut rows = Rows::default();
    let (pa, pj) = (lim.base.path_acc, lim.path_jerk);
    for i in 0..n {
        let mut cap = nd[i].cap2;
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
            rows.le(cap / v2, vec![(xi(i), 1.0)]);
        }
        // v̂² ≤ x̂: ‖(2v̂, x̂ − 1)‖ ≤ x̂ + 1.
        rows.soc(
            (1.0, vec![(xi(i), 1.0)]),
            &[(0.0, vec![(vi(i), 2.0)]), (-1.0, vec![(xi(i), 1.0)])],
        );
    }
    for c in 0..n - 1 {
        let ds = nd[c + 1].s - nd[c].s;
        q[ti(c)] = ds / lref;
        // τ̂ (v̂_c + v̂_{c+1}) ≥ 2: ‖(2√2, τ̂ − v̂ − v̂')‖ ≤ τ̂ + v̂ + v̂'.
        rows.soc(
            (0.0, vec![(ti(c), 1.0), (vi(c), 1.0), (vi(c + 1), 1.0)]),
            &[
                (2.0 * 2f64.sqrt(), vec![]),
                (0.0, vec![(ti(c), 1.0), (vi(c), -1.0), (vi(c + 1), -1.0)]),
            ],
        );
        // Acceleration at both ends of the cell, times 2Δs/V²:
        // t·(x̂_{c+1} − x̂_c) + 2Δs·κ·x̂_p against 2Δs·A/V².
        for (p, t, k) in [
            (c, nd[c].t_out, nd[c].k_out),
            (c + 1, nd[c + 1].t_in, nd[c + 1].k_in),
        ] {
            let comp = |m: usize| {
                let mut r = vec![(xi(c + 1), t[m]), (xi(c), -t[m])];
                let kk = 2.0 * ds * k[m];
                if p == c {
                    r[1].1 += kk;
                } else {
                    r[0].1 += kk;
                }
                (0.0, r)
            };
            let u = [comp(0), comp(1), comp(2)];
            let scale = 2.0 * ds / v2;
            rows.soc((pa * scale, vec![]), &u);
            for (m, am) in lim.base.axis_acc.iter().enumerate() {
                if *am < pa {
                    rows.le(am * scale, u[m].1.clone());
                    rows.le(am * scale, u[m].1.iter().map(|&(j, v)| (j, -v)).collect());
                }
            }
        }
    }
    // Jerk at interior nodes, linearized about `vbar`.
    for i in 1..n - 1 {
        if nd[i].kink || vbar[i] <= 0.0 {
            continue;
        }
        let c = jerk_coefs(nd, i, vbar[i], vbar[i] * lim.base.period_s);
        let comp = |m: usize| {
            (
                0.0,
                (0..3)
                    .map(|o| (xi(i - 1 + o), c[o][m] * v2))
                    .collect::<Vec<_>>(),
            )
        };
        let u = [comp(0), comp(1), comp(2)];
        rows.soc((pj, vec![]), &u);
        for (m, jm) in lim.axis_jerk.iter().enumerate() {
            if *jm < pj {
                rows.le(*jm, u[m].1.clone());
                rows.le(*jm, u[m].1.iter().map(|&(j, v)| (j, -v)).collect());
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
            .map(|i| (solver.solution.x[xi(i)] * v2).clamp(0.0, nd[i].cap2))
            .collect(),
    )
}

/// The jerk-limited optimum over a grid: the motion time, the speeds at the nodes, and
/// the convergence figures. `x0` is the first `v̄` (speeds at the grid points).
fn time_optimal(grid: &[GridPoint], v0: &[f64], lim: &JerkLimits) -> Result<JerkOptimum, String> {
    let nd = nodes(grid);
    let n = nd.len();
    // The first `v̄`: the starting speeds, at each node the lower of its points'.
    let mut vbar = vec![f64::INFINITY; n];
    let mut k = 0;
    for (gi, p) in grid.iter().enumerate() {
        while nd[k].s < p.s {
            k += 1;
        }
        vbar[k] = vbar[k].min(v0[gi]);
    }
    let mut x = vec![0.0; n];
    let (mut last_change, mut rounds) = (0.0f64, 0usize);
    let mut start = 0;
    while start + 1 < n {
        let end = (start + 1..n).find(|&i| nd[i].cap2 <= 0.0).unwrap_or(n - 1);
        let part = &nd[start..=end];
        if part.len() == 2 {
            start = end;
            continue;
        }
        let mut vb = vbar[start..=end].to_vec();
        let mut prev = f64::INFINITY;
        let mut best: Option<(f64, f64)> = None;
        let mut r = 0;
        let mut change = f64::INFINITY;
        while r < MAX_ROUNDS {
            let xs = solve_stretch(part, &vb, lim).ok_or_else(|| {
                format!(
                    "the conic solver failed on the stretch {:.3}..{:.3} mm",
                    part[0].s,
                    part[part.len() - 1].s
                )
            })?;
            r += 1;
            let t = motion_time(part, &xs, lim);
            change = ((prev - t) / t).abs();
            prev = t;
            // From the third solve on, half way to the new speeds (the plain iteration
            // can swing between two profiles where the jerk binds on a ramp).
            let w = if r >= 3 { 0.5 } else { 1.0 };
            for (b, x) in vb.iter_mut().zip(&xs) {
                *b = (1.0 - w) * *b + w * x.sqrt();
            }
            // Keep the fastest solve whose own jerk is within KEEP_JERK of the limit, else
            // the one with the lowest own jerk: a solve that swung off (a node driven
            // to rest by a too high `v̄`) never replaces a good one.
            let own = worst_ratios(part, &xs, lim).1;
            let ok = own <= KEEP_JERK;
            let better = match best {
                None => true,
                Some((bt, bj)) => {
                    if ok {
                        bj > KEEP_JERK || t < bt
                    } else {
                        bj > KEEP_JERK && own < bj
                    }
                }
            };
            if better {
                best = Some((t, own));
                x[start..=end].copy_from_slice(&xs);
            }
            if change < CONVERGED {
                break;
            }
        }
        last_change = last_change.max(change);
        rounds = rounds.max(r);
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
        jerk_ratio,
        acc_ratio,
    })
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
    let (t2, v0) = topp::time_optimal(&grid, &lim.base);
    let mut o = time_optimal(&grid, &v0, lim)?;
    o.time_s += dwell_s;
    o.dwell_s = dwell_s;
    o.acc_only_s = t2 + dwell_s;
    Ok(o)
}
