//! An independent time-optimal reference for the feed planner: acceleration-limited
//! time-optimal path parameterization (TOPP) of the exact path of a list of planned
//! command blocks, written from the textbook method (Bobrow; Shin and McKay; the
//! "numerical integration" family), not from the planner's code.
//!
//! The path is the set-point path the engine follows ([`shared::path::eval`]) through the
//! blocks as planned (a `G64 P` blend is part of it: the reference does not choose
//! blends), cut into a grid in its arc length `s`: every cell at most `step_mm` long and
//! turning its tangent by at most [`MAX_TURN_RAD`] (so a bend of 2 µm radius gets cells
//! of a fraction of a micrometre), down to [`MIN_CELL_MM`]. At each grid point the state
//! is `x = v²` (`v` the set-point's path speed) and the control is the path acceleration
//! `a = dv/dt = ½ dx/ds`; the set-point's acceleration is `t·a + κ·x` (`t` the unit
//! tangent, `κ = d²M/ds²` the curvature vector). The limits it keeps, each at every grid point:
//!
//! * **programmed feed**: `v ≤ F`, `F` the block's programmed feed capped at
//!   `max_feed_mm_per_min` (the rapid rate for a rapid); see [`programmed_feeds`];
//! * **each axis's velocity**: `|t_k|·v ≤ V_k`;
//! * **each axis's acceleration**: `|t_k·a + κ_k·x| ≤ A_k`;
//! * **the path acceleration**: `|t·a + κ·x| ≤ path_acc_mm_per_s2` (`a² + |κ|²x² ≤ A²`);
//! * **the chord tolerance at the period**: the chord of one period (`v·T` long) may
//!   deviate at most `tol = chord_tolerance_mm` from a curve of radius `ρ = 1/|κ|`:
//!   `v ≤ 2·sqrt(tol·(2ρ − tol))/T` (no limit where `2ρ ≤ tol`);
//! * **rest** (`v = 0`) at the program's start and end, on both sides of a junction whose
//!   tangent turns by more than `corner_angle_deg`, at the end of a block with
//!   `FLAG_STOP_AT_END`, and before and after every non-motion block (dwells, the end);
//! * **kinks** below the corner angle (a junction, or a grid cell the refinement could
//!   not resolve, whose tangent turns from `t1` to `t2`): the set-point turns within one
//!   period, so the velocity change `v·(t2 − t1)` must fit in one period's acceleration:
//!   `v ≤ A·T/|t2 − t1|` for the path (`|t2 − t1| = 2 sin(θ/2)`) and `v ≤ A_k·T/|t2_k −
//!   t1_k|` for each axis (the weakest relevant acceleration wins).
//!
//! Surface blocks: the grid is on the tool reference point's path (the set-point), with
//! its derivatives by central differences of [`shared::path::eval`]; the feed limit is
//! on the contact point, as the protocol defines it: `v_tool ≤ F·|dM/du|/|dC/du|`. This is
//! exact up to the differences' error (about 1e-8 relative).
//!
//! **Jerk is not limited here.** The acceleration-only optimum is therefore a lower bound
//! of every jerk-limited time on the same path and limits (a jerk-limited profile is one
//! of the profiles this optimum minimises over). It is the issue's "acceleration-only
//! optimum"; a jerk-limited reference would be at or above it.
//!
//! The algorithm: the maximum velocity curve (the largest `x` at each point for which
//! some `a` keeps every acceleration limit, by bisection, and within the speed limits);
//! a backward pass (`x_i` as large as allowed such that braking with the point's
//! strongest admissible deceleration, held over the cell, reaches no more than
//! `x_{i+1}`); a forward pass (the strongest admissible acceleration, held over the
//! cell, capped by the backward pass). Within a cell the speed rises with the cell
//! start's acceleration, holds, and falls with its deceleration into the cell's end
//! (`x` piecewise linear in `s`, so each piece's time is exactly `2Δs/(v_a + v_b)`).
//! Constraints are enforced at grid points (as TOPP-RA does); the error is of the order
//! of the cell size and is measured by halving the grid (the feed table computes every
//! optimum at `step_mm` and at `step_mm/2`).

use shared::nurbs::CurvePoint;
use shared::path;
use shared::protocol::{BlockKind, CommandBlock, FLAG_RAPID, FLAG_STOP_AT_END};
use shared::Machine;

/// Largest tangent turn of one grid cell, rad (cells turning more are halved).
pub const MAX_TURN_RAD: f64 = 0.02;
/// Cells are not halved below this length, mm.
pub const MIN_CELL_MM: f64 = 1e-7;
/// The grid step the feed table uses, mm (its time changes by less than 0.1 % at half).
pub const DEFAULT_STEP_MM: f64 = 0.02;

/// The limits the reference keeps, in mm, s.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefLimits {
    pub axis_vel: [f64; 3],
    pub axis_acc: [f64; 3],
    pub path_acc: f64,
    pub chord_tol: f64,
    pub period_s: f64,
    pub corner_rad: f64,
}

impl RefLimits {
    /// The limits of `machine` at the interpolation period `period_ns`.
    pub fn of(machine: &Machine, period_ns: u64) -> Self {
        let axes = machine.axes.as_array();
        RefLimits {
            axis_vel: axes.map(|a| a.max_vel_mm_per_min / 60.0),
            axis_acc: axes.map(|a| a.max_acc_mm_per_s2),
            path_acc: machine.path_acc_mm_per_s2,
            chord_tol: machine.chord_tolerance_mm,
            period_s: period_ns as f64 * 1e-9,
            corner_rad: machine.corner_angle_deg.to_radians(),
        }
    }
}

/// One grid point of the path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridPoint {
    /// Arc length of the set-point path from the program's first motion, mm.
    pub s: f64,
    /// Unit tangent.
    pub tangent: [f64; 3],
    /// `d²M/ds²`, normal to the tangent, 1/mm.
    pub curvature: [f64; 3],
    /// The speed limits here: feed, axis velocity, chord, rest and kinks, mm/s.
    pub v_cap: f64,
}

/// The time-optimal profile of a path.
#[derive(Debug, Clone, PartialEq)]
pub struct Optimum {
    /// Motion plus dwell time, s.
    pub time_s: f64,
    pub dwell_s: f64,
    /// Set-point path length, mm.
    pub length_mm: f64,
    /// The grid and the optimal speed at each of its points (mm/s).
    pub grid: Vec<GridPoint>,
    pub speed: Vec<f64>,
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The admissible path accelerations at `p` with `x = v²`: `None` if no acceleration
/// keeps every limit there.
fn acc_range(p: &GridPoint, x: f64, lim: &RefLimits) -> Option<(f64, f64)> {
    let k2 = dot(p.curvature, p.curvature);
    let n2 = lim.path_acc * lim.path_acc - k2 * x * x;
    if n2 < 0.0 {
        return None;
    }
    let r = n2.sqrt();
    let (mut lo, mut hi) = (-r, r);
    for k in 0..3 {
        let (c, d, a) = (p.tangent[k], p.curvature[k] * x, lim.axis_acc[k]);
        if c.abs() > 1e-12 {
            let (b0, b1) = ((-a - d) / c, (a - d) / c);
            lo = lo.max(b0.min(b1));
            hi = hi.min(b0.max(b1));
        } else if d.abs() > a {
            return None;
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// The largest `x` in `[0, cap]` for which `ok(x)`, `ok` true on an interval from 0.
fn largest(cap: f64, ok: impl Fn(f64) -> bool) -> f64 {
    if ok(cap) {
        return cap;
    }
    let (mut lo, mut hi) = (0.0, cap);
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        if ok(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-13 * hi {
            break;
        }
    }
    lo
}

/// The time-optimal speeds over a grid (consecutive points `Δs ≥ 0` apart; a junction is
/// two points at the same `s`), and the motion time. See the module page.
pub fn time_optimal(grid: &[GridPoint], lim: &RefLimits) -> (f64, Vec<f64>) {
    let n = grid.len();
    if n == 0 {
        return (0.0, Vec::new());
    }
    let mvc: Vec<f64> = grid
        .iter()
        .map(|p| {
            let cap = p.v_cap * p.v_cap;
            largest(cap, |x| acc_range(p, x, lim).is_some())
        })
        .collect();
    let mut back = mvc.clone();
    for i in (0..n - 1).rev() {
        let ds = grid[i + 1].s - grid[i].s;
        let next = back[i + 1];
        back[i] = largest(mvc[i], |x| {
            acc_range(&grid[i], x, lim).is_some_and(|(lo, _)| x + 2.0 * ds * lo <= next)
        });
    }
    let mut fwd = back.clone();
    let mut acc = vec![(0.0, 0.0); n];
    for i in 0..n - 1 {
        let ds = grid[i + 1].s - grid[i].s;
        let (lo, hi) = acc_range(&grid[i], fwd[i], lim).unwrap_or((0.0, 0.0));
        acc[i] = (hi.max(0.0), (-lo).max(0.0));
        fwd[i + 1] = back[i + 1].min(fwd[i] + 2.0 * ds * acc[i].0).max(0.0);
    }
    let speed: Vec<f64> = fwd.iter().map(|x| x.sqrt()).collect();
    let mut t = 0.0;
    for i in 0..n - 1 {
        let ds = grid[i + 1].s - grid[i].s;
        if ds > 0.0 {
            t += cell_time(ds, fwd[i], fwd[i + 1], acc[i]);
        }
    }
    (t, speed)
}

/// The time over a cell of length `ds` from `x0` to `x1` (`x = v²`): the speed rises
/// from `x0` with the acceleration `up`, holds at the larger end's, and falls into `x1`
/// with the deceleration `down` (both the cell start's, as the passes used them), which
/// meets both ends. Exact for constant limits: a cell where the speed reaches the feed,
/// or turns from accelerating to braking, is not averaged linearly.
fn cell_time(ds: f64, x0: f64, x1: f64, (up, down): (f64, f64)) -> f64 {
    // A linear piece of x over `l` from `a` to `b`.
    let lin = |l: f64, a: f64, b: f64| {
        let v = a.sqrt() + b.sqrt();
        if l <= 0.0 {
            0.0
        } else if v > 0.0 {
            2.0 * l / v
        } else {
            f64::INFINITY
        }
    };
    let (up, down) = (up.max(1e-300), down.max(1e-300));
    let top = x0.max(x1);
    // Where the rise reaches the top and where the fall leaves it.
    let s1 = ((top - x0) / (2.0 * up)).min(ds);
    let s2 = (ds - (top - x1) / (2.0 * down)).max(0.0);
    if s1 <= s2 && top > 0.0 {
        return lin(s1, x0, top) + (s2 - s1) / top.sqrt() + lin(ds - s2, top, x1);
    }
    // The rise and the fall meet below the top.
    let sm = ((x1 - x0 + 2.0 * down * ds) / (2.0 * (up + down))).clamp(0.0, ds);
    let xm = (x0 + 2.0 * up * sm).max(x0.min(x1));
    lin(sm, x0, xm) + lin(ds - sm, xm, x1)
}

/// Point and derivatives (in the block's parameter) of the set-point path, and the
/// contact point's parametric speed (the set-point's own for a curve block).
struct Local {
    p: [f64; 3],
    d1: [f64; 3],
    d2: [f64; 3],
    contact_speed: f64,
}

fn local(b: &CommandBlock, u: f64) -> Local {
    let e: CurvePoint = path::eval(b, u);
    if !b.is_surface() {
        return Local {
            p: e.p,
            d1: e.d1,
            d2: e.d2,
            contact_speed: path::norm(e.d1),
        };
    }
    // The tool point's derivatives by a three-point stencil inside the pass's [0, 1].
    let h = 1e-4;
    let c = u.clamp(h, 1.0 - h);
    let p0 = if c == u { e.p } else { path::eval(b, c).p };
    let (pm, pp) = (path::eval(b, c - h).p, path::eval(b, c + h).p);
    let r = u - c;
    let mut d1 = [0.0; 3];
    let mut d2 = [0.0; 3];
    for k in 0..3 {
        d2[k] = (pp[k] - 2.0 * p0[k] + pm[k]) / (h * h);
        d1[k] = (pp[k] - pm[k]) / (2.0 * h) + r * d2[k];
    }
    Local {
        p: e.p,
        d1,
        d2,
        contact_speed: path::norm(e.d1),
    }
}

/// The set-point path's parametric speed `|dM/du|` (for a surface block by central
/// differences of the tool point, within the pass's `[0, 1]`).
fn speed(b: &CommandBlock, u: f64) -> f64 {
    if !b.is_surface() {
        return path::norm(path::eval(b, u).d1);
    }
    let h = 1e-5;
    let (a, c) = ((u - h).max(0.0), (u + h).min(1.0));
    path::norm(sub(path::eval(b, c).p, path::eval(b, a).p)) / (c - a)
}

/// Unit tangent and curvature vector from parametric derivatives (the tangent of a
/// vanishing derivative from the chord towards `toward`).
fn frame(l: &Local, toward: impl Fn() -> [f64; 3]) -> ([f64; 3], [f64; 3], f64) {
    let sp = path::norm(l.d1);
    if sp < 1e-12 {
        let d = sub(toward(), l.p);
        let n = path::norm(d).max(1e-300);
        return (d.map(|x| x / n), [0.0; 3], sp);
    }
    let t = l.d1.map(|x| x / sp);
    let dt = dot(l.d2, t);
    let k = [0, 1, 2].map(|i| (l.d2[i] - dt * t[i]) / (sp * sp));
    (t, k, sp)
}

fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    let c = dot(a, b).clamp(-1.0, 1.0);
    let s = path::norm([
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]);
    s.atan2(c)
}

/// The length of a block's set-point path, mm, as the grid measures it: its
/// `length_mm`, but for a surface pass (whose `length_mm` is the contact point's) the
/// tool point's, by the adaptive rule of [`shared::path::length`] on [`speed`].
pub fn set_point_length(b: &CommandBlock) -> f64 {
    if !b.is_surface() {
        return b.length_mm;
    }
    shared::nurbs::arc_length_adaptive(&[0.0, 1.0], 4, |u| speed(b, u))
}

/// Length of the set-point path over `[a, b]`: 3-point Gauss–Legendre.
fn cell_length(b: &CommandBlock, u0: f64, u1: f64) -> f64 {
    const X: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
    const W: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
    let (m, h) = (0.5 * (u0 + u1), 0.5 * (u1 - u0));
    X.iter()
        .zip(W)
        .map(|(x, w)| w * speed(b, m + h * x))
        .sum::<f64>()
        * h
}

/// The grid cells of one block: `(u, Δs)` of each cell's end, in order.
fn refine(
    b: &CommandBlock,
    (u0, t0): (f64, [f64; 3]),
    (u1, t1): (f64, [f64; 3]),
    step: f64,
    depth: u32,
    out: &mut Vec<(f64, f64, bool)>,
) {
    let len = cell_length(b, u0, u1);
    let um = 0.5 * (u0 + u1);
    let lm = local(b, um);
    let (tm, _, _) = frame(&lm, || path::eval(b, u1).p);
    let turn = angle(t0, tm) + angle(tm, t1);
    let split = (len > step || turn > MAX_TURN_RAD) && len > MIN_CELL_MM && depth < 60;
    if split {
        refine(b, (u0, t0), (um, tm), step, depth + 1, out);
        refine(b, (um, tm), (u1, t1), step, depth + 1, out);
    } else {
        // A cell that still turns a lot is a kink the grid could not resolve.
        out.push((u1, len, turn > MAX_TURN_RAD));
    }
}

/// The one-period kink bound for a turn from `a` to `b` (see the module page).
fn kink_cap(a: [f64; 3], b: [f64; 3], lim: &RefLimits) -> f64 {
    let d = sub(b, a);
    let mut cap = f64::INFINITY;
    let n = path::norm(d);
    if n > 0.0 {
        cap = lim.path_acc * lim.period_s / n;
    }
    for (dk, ak) in d.iter().zip(lim.axis_acc) {
        if *dk != 0.0 {
            cap = cap.min(ak * lim.period_s / dk.abs());
        }
    }
    cap
}

/// The pointwise speed limits at a grid point: feed (`feed` on the contact point, scaled
/// to the set-point), axis velocities and chord.
fn speed_cap(feed: f64, scale: f64, t: [f64; 3], k: [f64; 3], lim: &RefLimits) -> f64 {
    let mut cap = feed * scale;
    for (ti, vi) in t.iter().zip(lim.axis_vel) {
        if ti.abs() > 0.0 {
            cap = cap.min(vi / ti.abs());
        }
    }
    let kn = path::norm(k);
    if kn > 0.0 {
        let rho = 1.0 / kn;
        if 2.0 * rho > lim.chord_tol {
            cap =
                cap.min(2.0 * (lim.chord_tol * (2.0 * rho - lim.chord_tol)).sqrt() / lim.period_s);
        }
    }
    cap
}

/// The grid of a whole block list and its dwell time. `feeds_mm_per_s[i]` is block `i`'s
/// programmed feed (see [`programmed_feeds`]).
pub fn grid(
    blocks: &[CommandBlock],
    feeds_mm_per_s: &[f64],
    lim: &RefLimits,
    step_mm: f64,
) -> (Vec<GridPoint>, f64) {
    let mut pts: Vec<GridPoint> = Vec::new();
    let mut dwell = 0.0;
    let mut rest_next = true;
    let mut s = 0.0;
    for (bi, b) in blocks.iter().enumerate() {
        if b.kind != BlockKind::Motion as u32 {
            if b.kind == BlockKind::Dwell as u32 {
                dwell += b.dwell_ns as f64 * 1e-9;
            }
            if let Some(last) = pts.last_mut() {
                last.v_cap = 0.0;
            }
            rest_next = true;
            continue;
        }
        let feed = feeds_mm_per_s[bi];
        let (u0, u1) = path::domain(b);
        // Start cells at the knots (a curve's derivatives jump only there).
        let mut breaks: Vec<f64> = if b.is_surface() {
            vec![0.0, 1.0]
        } else {
            b.knots().to_vec()
        };
        breaks.retain(|u| *u >= u0 && *u <= u1);
        breaks.dedup();
        let first = pts.len();
        let mut cells: Vec<(f64, f64, bool)> = Vec::new();
        // The forward tangent at `u` (of a vanishing derivative: the chord towards
        // `toward`, turned forward when `toward` lies behind).
        let tan = |u: f64, toward: f64| {
            let (t, _, sp) = frame(&local(b, u), || path::eval(b, toward).p);
            if sp < 1e-12 && toward < u {
                t.map(|x| -x)
            } else {
                t
            }
        };
        for w in breaks.windows(2) {
            let (a, c) = (w[0], w[1]);
            if c <= a {
                continue;
            }
            // Four cells a span to begin with, tangents from just inside it.
            for q in 0..4 {
                let ua = a + (c - a) * q as f64 / 4.0;
                let ub = if q == 3 {
                    c
                } else {
                    a + (c - a) * (q + 1) as f64 / 4.0
                };
                let ta = tan(ua + 1e-12 * (c - a), ub);
                let tb = tan(ub - 1e-12 * (c - a), ua);
                refine(b, (ua, ta), (ub, tb), step_mm, 0, &mut cells);
            }
        }
        // A block end where the parametric speed (nearly) vanishes, as at a repeated
        // control point: its tangent is right, but its curvature `d2⊥/|d1|²` is roundoff
        // over a vanishing square (1e20 /mm on g5_curva_mazatrol's 110 mm); such a point
        // takes its neighbour's curvature (the limit from inside) once the block's points
        // are known.
        let mean_speed = cells.iter().map(|c| c.1).sum::<f64>() / (u1 - u0);
        let mut vanishing: Vec<usize> = Vec::new();
        let mut at = |u: f64, kink: bool, s: f64, pts: &mut Vec<GridPoint>| {
            // The tangent's side: from just inside the block, towards its other end.
            let uu = u.clamp(u0 + 1e-12 * (u1 - u0), u1 - 1e-12 * (u1 - u0));
            let l = local(b, uu);
            let toward = if u < 0.5 * (u0 + u1) { u1 } else { u0 };
            let (mut t, k, sp) = frame(&l, || path::eval(b, toward).p);
            if sp < 1e-12 && toward < u {
                t = t.map(|x| -x);
            }
            let scale = if l.contact_speed > 0.0 {
                sp / l.contact_speed
            } else {
                1.0
            };
            if sp < 1e-6 * mean_speed {
                vanishing.push(pts.len());
            }
            let mut cap = if sp < 1e-12 {
                0.0
            } else {
                speed_cap(feed, scale, t, k, lim)
            };
            if kink {
                if let Some(prev) = pts.last() {
                    cap = cap.min(kink_cap(prev.tangent, t, lim));
                }
            }
            pts.push(GridPoint {
                s,
                tangent: t,
                curvature: k,
                v_cap: cap,
            });
        };
        at(u0, false, s, &mut pts);
        for (u, ds, kink) in cells {
            s += ds;
            at(u, kink, s, &mut pts);
        }
        for i in vanishing {
            let near = if i == first { i + 1 } else { i - 1 };
            if near < pts.len() {
                pts[i].curvature = pts[near].curvature;
            }
        }
        // The junction with the motion before.
        if rest_next {
            pts[first].v_cap = 0.0;
        } else if first > 0 {
            let (a, c) = (pts[first - 1].tangent, pts[first].tangent);
            if angle(a, c) > lim.corner_rad {
                pts[first - 1].v_cap = 0.0;
                pts[first].v_cap = 0.0;
            } else {
                let cap = kink_cap(a, c, lim);
                pts[first - 1].v_cap = pts[first - 1].v_cap.min(cap);
                pts[first].v_cap = pts[first].v_cap.min(cap);
            }
        }
        rest_next = b.flags & FLAG_STOP_AT_END != 0;
        if rest_next {
            if let Some(last) = pts.last_mut() {
                last.v_cap = 0.0;
            }
        }
    }
    if let Some(last) = pts.last_mut() {
        last.v_cap = 0.0;
    }
    (pts, dwell)
}

/// The time-optimal profile of `blocks` under `lim`, on a grid of `step_mm`.
pub fn optimum(
    blocks: &[CommandBlock],
    feeds_mm_per_s: &[f64],
    lim: &RefLimits,
    step_mm: f64,
) -> Optimum {
    let (grid, dwell_s) = grid(blocks, feeds_mm_per_s, lim, step_mm);
    let (t, speed) = time_optimal(&grid, lim);
    Optimum {
        time_s: t + dwell_s,
        dwell_s,
        length_mm: grid.last().map_or(0.0, |p| p.s),
        grid,
        speed,
    }
}

/// The programmed feed of each block, mm/s, capped at `max_feed_mm_per_min` (the rapid
/// rate for a rapid). For G-code, from the interpreter's moves (the F in force on the
/// block's source line, `G93` already turned into mm/min), independent of the planner.
/// For a STEP-NC part (and any block whose line has no move): the feed cap the planner
/// gives the block on a machine whose acceleration, jerk, chord and axis-velocity limits
/// never bind, matched by sequence number when the two plans have the same blocks, else
/// the largest of the blocks of the same source line. Only public APIs.
pub fn programmed_feeds(
    name: &str,
    text: &str,
    machine: &Machine,
    period_ns: u64,
    blocks: &[CommandBlock],
) -> Result<Vec<f64>, String> {
    use interpreter::program::Move;
    use std::collections::HashMap;
    let opts = interpreter::program::Options::default();
    let cap = |b: &CommandBlock, f: f64| {
        let m = if b.flags & FLAG_RAPID != 0 {
            machine.rapid_mm_per_min
        } else {
            machine.max_feed_mm_per_min
        };
        f.min(m) / 60.0
    };
    let mut by_line: HashMap<u32, f64> = HashMap::new();
    if !interpreter::step::check::is_step_file(name, text) {
        let prog = interpreter::program::interpret_with(text, &opts)
            .map_err(|d| interpreter::process::format_diagnostics(name, &d))?;
        for m in &prog.moves {
            let (line, feed) = match m {
                Move::Line {
                    line, rapid: true, ..
                } => (*line, machine.rapid_mm_per_min),
                Move::Line { line, feed, .. }
                | Move::Arc { line, feed, .. }
                | Move::Nurbs { line, feed, .. } => (*line, *feed),
                _ => continue,
            };
            let e = by_line.entry(line).or_insert(0.0);
            *e = e.max(feed);
        }
    }
    let motion = |b: &CommandBlock| b.kind == BlockKind::Motion as u32;
    if blocks
        .iter()
        .all(|b| !motion(b) || by_line.contains_key(&b.source_line))
    {
        return Ok(blocks
            .iter()
            .map(|b| cap(b, by_line.get(&b.source_line).copied().unwrap_or(0.0)))
            .collect());
    }
    let mut free = machine.clone();
    free.path_acc_mm_per_s2 = 1e9;
    free.path_jerk_mm_per_s3 = 1e12;
    free.chord_tolerance_mm = 1e3;
    for a in [&mut free.axes.x, &mut free.axes.y, &mut free.axes.z] {
        a.max_vel_mm_per_min = 1e9;
        a.max_acc_mm_per_s2 = 1e9;
        a.max_jerk_mm_per_s3 = 1e12;
    }
    let other = interpreter::process::compile_source(name, text, &opts, &free, period_ns)?.blocks;
    let same = other.len() == blocks.len()
        && other
            .iter()
            .zip(blocks)
            .all(|(a, b)| a.source_line == b.source_line && a.kind == b.kind);
    let mut planned: HashMap<u32, f64> = HashMap::new();
    for o in &other {
        let e = planned.entry(o.source_line).or_insert(0.0f64);
        *e = e.max(o.feed_mm_per_min);
    }
    Ok(blocks
        .iter()
        .enumerate()
        .map(|(i, b)| {
            let f = by_line.get(&b.source_line).copied().unwrap_or_else(|| {
                if same {
                    other[i].feed_mm_per_min
                } else {
                    planned.get(&b.source_line).copied().unwrap_or(0.0)
                }
            });
            cap(b, f)
        })
        .collect())
}
