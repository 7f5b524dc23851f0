//! From moves to command blocks: lines and arcs as exact NURBS (degree 1 and rational
//! quadratic), NURBS split exactly to block capacity, and the feed plan.
//!
//! The plan is a look-ahead over the blocks it is given: a window of the program, from
//! one rest to another or as long as the machine's `plan_window_moves` and handed on up
//! to a seam at speed ([`crate::window`]), which the interpreter plans before any of it
//! moves. Each motion block gets a speed cap (programmed feed, reduced where its
//! curvature demands it by the chord tolerance and the path's and axes' acceleration and
//! jerk) and the tangential acceleration and jerk its S-curve may use; each junction a
//! speed (exact stop at corners sharper than the machine's corner angle, limited at kinks
//! and curvature jumps); and a backward then a forward pass make every block's start and
//! end speed reachable under the jerk-limited profile the interpolator runs.
//!
//! Surface blocks (`FLAG_SURFACE`, from [`crate::surface_blocks`]) go through the same
//! plan: their caps, limits and junctions come from the tool reference point path `M`,
//! which the machine follows (`set_point_eval`), scaled to the contact point feed the
//! block's speeds are in.
//!
//! The caps follow the curve, not its sharpest point: a program's NURBS spans are split
//! exactly where their speed limit crosses a level ([`speed`]), and a straight block
//! next to a kink gives the few steps around the kink a block of their own
//! (`split_at_kinks`), so what a bend or a kink takes holds only where it is.
//!
//! A program's blocks are held as [`Block`]s until they are sent: a straight move in a
//! few numbers, anything else whole (see [`block`]); the planner takes either form
//! ([`Plannable`]) and [`commands`] gives the [`CommandBlock`]s.

pub mod block;
pub mod check;
pub mod speed;

pub use block::{commands, Block, Straight};

use crate::program::{Move, PathControl, Plane};
use cache::PlanCache;
use shared::nurbs::{self, SplitCurve, MAX_CTRL};
use shared::path;
use shared::path::sub;
use shared::profile::Limits as Jerk;
use shared::protocol::{
    BlockKind, CommandBlock, Helix, FLAG_RAPID, FLAG_STOP_AT_END, FLAG_SURFACE,
};
use shared::Machine;
use std::f64::consts::{FRAC_PI_2, PI};
use std::rc::Rc;

pub mod blend;
mod cache;
mod eval;
mod hodograph;
pub mod naive_cam;

/// Most quadratic segments (of at most 90°) in one arc block: 2n+1 control points.
const ARC_SEGMENTS_PER_BLOCK: usize = (MAX_CTRL - 1) / 2;

fn curve_block(line: u32, c: &SplitCurve, helix: Helix, feed: f64) -> CommandBlock {
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, line);
    b.degree = c.degree as u32;
    b.n_ctrl = c.ctrl.len() as u32;
    b.knots[..c.knots.len()].copy_from_slice(&c.knots);
    b.ctrl[..c.ctrl.len()].copy_from_slice(&c.ctrl);
    b.helix = helix;
    b.feed_mm_per_min = feed;
    b
}

/// The blocks of an arc (or helix) of `sweep` radians (negative clockwise) about `center`,
/// starting at `from`, with the axial motion `dz` along the plane's normal.
fn arc_blocks(
    line: u32,
    from: [f64; 3],
    center: [f64; 3],
    plane: Plane,
    sweep: f64,
    dz: f64,
    feed: f64,
) -> Vec<CommandBlock> {
    let (a, b) = plane.axes();
    let n = plane.normal();
    let r = ((from[a] - center[a]).powi(2) + (from[b] - center[b]).powi(2)).sqrt();
    let theta0 = (from[b] - center[b]).atan2(from[a] - center[a]);
    let nseg = ((sweep.abs() / FRAC_PI_2) - 1e-9).ceil().max(1.0) as usize;
    let delta = sweep / nseg as f64;
    let mm_per_rad = dz / sweep.abs();
    let point = |theta: f64, scale: f64, axial: f64| {
        let mut p = [0.0; 3];
        p[a] = center[a] + r * scale * theta.cos();
        p[b] = center[b] + r * scale * theta.sin();
        p[n] = axial;
        p
    };
    let mut out = Vec::new();
    let mut seg = 0;
    while seg < nseg {
        let count = ARC_SEGMENTS_PER_BLOCK.min(nseg - seg);
        let axial0 = from[n] + mm_per_rad * (seg as f64 * delta.abs());
        let mut ctrl = Vec::with_capacity(2 * count + 1);
        let mut knots = vec![0.0; 3];
        let w_mid = (delta / 2.0).cos();
        for j in 0..count {
            let t0 = theta0 + (seg + j) as f64 * delta;
            let p0 = point(t0, 1.0, axial0);
            let p1 = point(t0 + delta / 2.0, 1.0 / w_mid, axial0);
            ctrl.push([p0[0], p0[1], p0[2], 1.0]);
            ctrl.push([p1[0], p1[1], p1[2], w_mid]);
            knots.extend_from_slice(&[(j + 1) as f64; 2]);
        }
        let pend = point(theta0 + (seg + count) as f64 * delta, 1.0, axial0);
        ctrl.push([pend[0], pend[1], pend[2], 1.0]);
        knots.pop();
        knots.extend_from_slice(&[count as f64; 2]);
        let helix = if dz != 0.0 {
            Helix {
                axis: n as u32,
                dir: if sweep > 0.0 { 1 } else { -1 },
                center_mm: center,
                start_mm: axial0,
                mm_per_rad,
                seg_rad: delta.abs(),
            }
        } else {
            Helix::NONE
        };
        out.push(curve_block(
            line,
            &SplitCurve {
                degree: 2,
                knots,
                ctrl,
            },
            helix,
            feed,
        ));
        seg += count;
    }
    out
}

/// The signed angle an arc sweeps (negative clockwise), full turns included. The
/// G93 feed (`program::feed`) measures arcs with it too, so time and motion agree.
pub(crate) fn sweep_of(
    from: [f64; 3],
    to: [f64; 3],
    center: [f64; 3],
    plane: Plane,
    ccw: bool,
    turns: u32,
) -> f64 {
    let (a, b) = plane.axes();
    let t0 = (from[b] - center[b]).atan2(from[a] - center[a]);
    let t1 = (to[b] - center[b]).atan2(to[a] - center[a]);
    let same = (to[a] - from[a]).hypot(to[b] - from[b]) < 1e-9;
    let mut s = if ccw { t1 - t0 } else { t0 - t1 };
    while s <= 0.0 {
        s += 2.0 * PI;
    }
    while s > 2.0 * PI {
        s -= 2.0 * PI;
    }
    if same {
        s = 2.0 * PI;
    }
    s += 2.0 * PI * (turns.saturating_sub(1)) as f64;
    if ccw {
        s
    } else {
        -s
    }
}

/// The parameter of a cusp inside `c`, if it has one: a point where the curve's speed
/// `|C'|` dips to (nearly) zero and its tangent turns by more than the machine's corner
/// angle, as where a curve runs back along itself. The tool must stop there; a block
/// boundary at the cusp makes it a corner the planner stops at.
fn find_cusp(c: &SplitCurve, machine: &Machine) -> Option<f64> {
    const N: usize = hodograph::CELLS;
    let (u0, u1) = (c.knots[0], c.knots[c.knots.len() - 1]);
    let at = |i: usize| u0 + (u1 - u0) * i as f64 / N as f64;
    let d1 = |u: f64| nurbs::eval_d1(c.degree, &c.knots, &c.ctrl, u).d1;
    let cos_corner = machine.corner_angle_deg.to_radians().cos();
    let len = path::norm(d1(u0)).max(path::norm(d1(u1))).max(1e-9);
    // A cusp is only taken where the speed is within 1e-6 of the ends' at the minimum
    // found: between two samples whose cells are proven well above that, the search
    // would find none, so it is not run (for a curve that is one Bézier span, as
    // `build` hands over; any other is searched everywhere).
    let clear = hodograph::Hodograph::of_span(c.degree, &c.knots, &c.ctrl)
        .map_or(0, |h| h.cells_above(1e-6 * len));
    // Each sample's derivative is needed by the two pairs it is in.
    let mut sampled: [Option<[f64; 3]>; N + 1] = [None; N + 1];
    let mut sample = |i: usize| *sampled[i].get_or_insert_with(|| d1(at(i)));
    for i in 1..N {
        if clear >> (i - 1) & 3 == 3 {
            continue;
        }
        let (a, b) = (sample(i - 1), sample(i + 1));
        let (na, nb) = (path::norm(a), path::norm(b));
        if na < 1e-12 || nb < 1e-12 {
            continue;
        }
        if (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (na * nb) >= cos_corner {
            continue;
        }
        // The tangent turns sharply in [at(i-1), at(i+1)]: find the speed's minimum.
        let (mut lo, mut hi) = (at(i - 1), at(i + 1));
        for _ in 0..100 {
            let m1 = lo + (hi - lo) / 3.0;
            let m2 = hi - (hi - lo) / 3.0;
            if path::norm(d1(m1)) < path::norm(d1(m2)) {
                hi = m2;
            } else {
                lo = m1;
            }
        }
        let u = 0.5 * (lo + hi);
        if path::norm(d1(u)) <= 1e-6 * len && u > u0 + 1e-9 * (u1 - u0) && u < u1 - 1e-9 * (u1 - u0)
        {
            return Some(u);
        }
    }
    None
}

/// `c` split exactly at its cusps.
fn split_at_cusps(c: SplitCurve, machine: &Machine) -> Vec<SplitCurve> {
    let mut out = Vec::new();
    let mut rest = c;
    for _ in 0..16 {
        match find_cusp(&rest, machine) {
            Some(u) => {
                let (l, r) = nurbs::split_at(&rest, u);
                out.push(l);
                rest = r;
            }
            None => break,
        }
    }
    out.push(rest);
    out
}

/// Turns moves into unplanned blocks (feeds are the caps, speeds not yet set), numbered
/// in order when they become [`CommandBlock`]s ([`commands`]).
pub fn build(moves: &[Move], machine: &Machine) -> Vec<Block> {
    // `G64 P`: corners between feed lines blended first (see [`blend`]).
    let blended = blend::corners_on(moves, machine);
    let moves: &[Move] = &blended;
    // Most moves make one block.
    let mut out: Vec<Block> = Vec::with_capacity(moves.len());
    crate::pages::prefer_huge_pages(&out);
    // `G61.1` exact stop mode: every move ends at rest.
    let mut exact_stop = false;
    let stop_after_last = |out: &mut Vec<Block>| {
        if let Some(b) = out.last_mut() {
            if b.is_motion() {
                *b.flags_mut() |= FLAG_STOP_AT_END;
            }
        }
    };
    for m in moves {
        let before = out.len();
        match m {
            Move::Line {
                line,
                from,
                to,
                rapid,
                feed,
            } => {
                let f = if *rapid {
                    machine.rapid_mm_per_min
                } else {
                    feed.min(machine.max_feed_mm_per_min)
                };
                out.push(Block::Straight(Straight::new(*line, *from, *to, *rapid, f)));
            }
            Move::Arc {
                line,
                from,
                to,
                center,
                plane,
                ccw,
                turns,
                feed,
            } => {
                let sweep = sweep_of(*from, *to, *center, *plane, *ccw, *turns);
                let n = plane.normal();
                let f = feed.min(machine.max_feed_mm_per_min);
                let blocks = arc_blocks(*line, *from, *center, *plane, sweep, to[n] - from[n], f);
                out.extend(blocks.into_iter().map(Block::from));
                // The arc's exact end in the plane is the programmed end (to rounding).
            }
            Move::Nurbs {
                line,
                degree,
                knots,
                ctrl,
                feed,
            } => {
                let f = feed.min(machine.max_feed_mm_per_min);
                let curve = SplitCurve {
                    degree: *degree,
                    knots: knots.clone(),
                    ctrl: ctrl.clone(),
                };
                // One block per knot span (its Bézier piece, split exactly): the planner's
                // speed cap and profile limits are then those of each span, not the
                // worst of the whole curve.
                for span in nurbs::split_to_capacity(curve, (*degree + 1).min(MAX_CTRL)) {
                    for piece in split_at_cusps(span, machine) {
                        // And where its speed limit changes: each block's cap is then
                        // that of its own stretch of the curve. (Not a `G64 P` blend,
                        // known by its shape: split, its pieces broke the speed by
                        // 0.4 % on a random chain in `limits.rs`; they are short, and
                        // held to their slowest point as before.)
                        let parts = if blend::is_blend_shape(*degree, knots, ctrl) {
                            vec![piece]
                        } else {
                            speed::split_by_speed(piece, machine, f)
                        };
                        for part in parts {
                            out.push(curve_block(*line, &part, Helix::NONE, f).into());
                        }
                    }
                }
            }
            Move::Dwell { line, seconds } => {
                let mut b = CommandBlock::empty(BlockKind::Dwell, 0, *line);
                b.dwell_ns = (seconds * 1e9).round() as u64;
                out.push(b.into());
            }
            Move::End { line } => {
                out.push(CommandBlock::empty(BlockKind::ProgramEnd, 0, *line).into())
            }
            Move::PathMode { control, .. } => {
                // `G64 P` corners are blended above; otherwise `G61` and `G64` both
                // follow the exact path. `G61.1` stops at the end of every move.
                exact_stop = matches!(control, PathControl::ExactStop);
            }
            // A programmed stop: the machine is at rest when it is reached.
            Move::Stop { .. } => stop_after_last(&mut out),
            // Carried for the reports; no block of its own yet.
            Move::Spindle { .. } => {}
        }
        if exact_stop && out.len() > before {
            stop_after_last(&mut out);
        }
    }
    out
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `d` made a unit vector, if it has a length.
fn unit_of(d: [f64; 3]) -> Option<[f64; 3]> {
    let l = path::norm(d);
    (l > 0.0 && l.is_finite()).then(|| d.map(|x| x / l))
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// The path's unit tangent and curvature vector `dT/ds` (length the curvature, pointing
/// to the centre) at `u`.
#[cfg(test)]
fn frame(b: &CommandBlock, u: f64) -> Option<([f64; 3], [f64; 3])> {
    frame_at(&path::eval(b, u))
}

/// [`frame`] at a point already evaluated.
fn frame_at(e: &nurbs::CurvePoint) -> Option<([f64; 3], [f64; 3])> {
    let sp = path::norm(e.d1);
    if sp < 1e-12 {
        return None;
    }
    let t = e.d1.map(|x| x / sp);
    let along = dot(e.d2, t);
    let k = [0, 1, 2].map(|i| (e.d2[i] - along * t[i]) / (sp * sp));
    Some((t, k))
}

/// The curvature vector's rate along the path, `dk/ds`, at a point evaluated with its
/// third derivative `d3` (zero where the curve (nearly) stops, as [`frame_at`] finds).
/// With `k = (C' × C'') × C' / σ⁴`, `σ = |C'|`:
/// `dk/du = ((C' × C''') × C' + (C' × C'') × C'') / σ⁴ − 4 (C'·C'') / σ² · k`, and
/// `dk/ds = (dk/du) / σ`.
///
/// Not used by the planner yet, which still takes a difference of curvatures: used for
/// every sample, it made `cnc check` 15 % faster on curves, but where a curve leaves
/// its start at nearly zero parametric speed (LinuxCNC's trident, `tests/servo.rs`) its
/// division by a tiny `σ` gave a rate that capped the feed at 0.008 mm/min, and the
/// program was refused. Tested against differences and a closed form, for that step.
#[allow(dead_code)]
fn rate_at(e: &nurbs::CurvePoint, d3: [f64; 3]) -> [f64; 3] {
    use crate::surface_path::cross;
    let (c1, c2) = (e.d1, e.d2);
    let s2 = dot(c1, c1);
    let sp = s2.sqrt();
    if sp < 1e-12 {
        return [0.0; 3];
    }
    let s4 = s2 * s2;
    let c12 = cross(c1, c2);
    let k = cross(c12, c1).map(|x| x / s4);
    let (a, b) = (cross(cross(c1, d3), c1), cross(c12, c2));
    let g = 4.0 * dot(c1, c2) / s2;
    [0, 1, 2].map(|i| ((a[i] + b[i]) / s4 - g * k[i]) / sp)
}

/// What the planner takes from one block's geometry: its speed cap and the tangential
/// acceleration and jerk its profile may use (all in mm and s), and its end frames.
#[derive(Debug, Clone, Copy)]
struct Shape {
    v_cap: f64,
    acc: f64,
    jerk: f64,
    t_start: [f64; 3],
    t_end: [f64; 3],
    k_start: [f64; 3],
    k_end: [f64; 3],
    /// `dk/ds` at the start and at the end (1/mm²).
    dk_start: [f64; 3],
    dk_end: [f64; 3],
    /// Surface blocks: the largest ratio of the tool point's speed to the contact
    /// point's (the speeds above are the contact's); `None` for curves.
    surface_ratio: Option<f64>,
    /// Surface blocks: the tool point's velocity per unit of contact speed at the start
    /// and at the end, `M'/|C'|` (where the surface is only C¹ it jumps between blocks,
    /// in length as well as in direction); `None` for curves.
    m_start: Option<[f64; 3]>,
    m_end: Option<[f64; 3]>,
    /// Surface blocks: the tool point's acceleration per squared contact speed at the
    /// start and at the end, `d²M/ds²` ([`path::tool_rate2`]; it jumps between blocks at
    /// every knot of a cubic surface); `None` for curves.
    m2_start: Option<[f64; 3]>,
    m2_end: Option<[f64; 3]>,
}

impl Shape {
    /// A shape to overwrite.
    const NONE: Shape = Shape {
        v_cap: 0.0,
        acc: 0.0,
        jerk: 0.0,
        t_start: [0.0; 3],
        t_end: [0.0; 3],
        k_start: [0.0; 3],
        k_end: [0.0; 3],
        dk_start: [0.0; 3],
        dk_end: [0.0; 3],
        surface_ratio: None,
        m_start: None,
        m_end: None,
        m2_start: None,
        m2_end: None,
    };
}

/// Share of the path (and each axis's) acceleration the curvature may take at the cap
/// speed, and of the jerk; the rest is left to the speed profile along the path.
const NORMAL_SHARE: f64 = 0.5;

/// The least tangential acceleration and jerk [`shape`] leaves a block's profile: a
/// twentieth of the weakest of the path's and the axes' (a floor of a twentieth of the
/// path's alone stood above what a weak axis has).
fn profile_floors(machine: &Machine) -> (f64, f64) {
    let axes = machine.axes.as_array();
    let (acc, jerk) = axes.iter().fold(
        (machine.path_acc_mm_per_s2, machine.path_jerk_mm_per_s3),
        |(a, j), ax| (a.min(ax.max_acc_mm_per_s2), j.min(ax.max_jerk_mm_per_s3)),
    );
    (0.05 * acc, 0.05 * jerk)
}

/// Most times [`shape`] lowers a cap by a fifth ([`LOWER_STEP`]) to leave the profile
/// its floor: to 0.26 of the cap at most.
const LOWER_STEPS: usize = 6;

/// What one of [`shape`]'s steps down leaves of a cap.
const LOWER_STEP: f64 = 0.8;

/// Bisections of [`shape`]'s last step down: the cap within 0.25/2^10 (0.02 %) of the
/// highest that leaves the profile its floors.
const LOWER_BISECTIONS: usize = 10;

/// The block's speed cap and profile limits. At every sample of the curve, for the
/// speed `v`, tangential acceleration `a_t` and jerk `j_t` of the profile, the
/// set-points' acceleration is `a_t·T + v²·k` and their jerk `j_t·T + 3·v·a_t·k +
/// v³·dk/ds` (`T` the tangent, `k` the curvature vector). The cap keeps `v²|k|` within
/// `share` of the path (and each axis's) acceleration (half, or [`VALLEY_SHARE`] where
/// the profile has little use for its own), `v³|dk/ds|` within that share of the jerk,
/// each axis's velocity share `v·|T_i|` within its limit, and one period's chord within
/// the chord tolerance (exact form: a chord `c` of a circle of radius `r` deviates
/// `r - sqrt(r² - c²/4)`). The tangential limits are what is left at the cap speed.
fn shape(g: Geometry, machine: &Machine, period_s: f64, feed_mm_s: f64, share: f64) -> Shape {
    shape_from(g, None, machine, period_s, feed_mm_s, share)
}

/// [`shape`] from a curve's samples taken already (`sampled`; for a surface block, or
/// none, they are taken here).
fn shape_from(
    g: Geometry,
    sampled: Option<&Sampled>,
    machine: &Machine,
    period_s: f64,
    feed_mm_s: f64,
    share: f64,
) -> Shape {
    let axes = machine.axes.as_array();
    let a_path = machine.path_acc_mm_per_s2;
    let j_path = machine.path_jerk_mm_per_s3;
    // A surface block is planned on its tool reference point `M`, the path the machine
    // follows, at the fastest `M` moves for the contact feed (`ratio` = max |M'|/|C'|);
    // the caps and limits found for `M` are scaled back to the contact path, along which
    // the feed is programmed and the profile runs (conservative where the ratio varies;
    // the ratio's own change along the block, `r'·ṡ²`, is taken from the tangential
    // acceleration below).
    let surface = matches!(g, Geometry::Curve(b) if b.is_surface());
    let (ratio, ratio_slope) = match g {
        Geometry::Curve(b) if surface => surface_speed_ratio(b),
        _ => (1.0, 0.0),
    };
    let feed_mm_s = feed_mm_s * ratio;
    let taken: Sampled;
    let sampled: &Sampled = match (g, sampled) {
        (Geometry::Curve(_), Some(s)) if !surface => s,
        // A straight segment has one tangent and no curvature: one sample says it all
        // (the samples below would each find the same, at a hundred times the cost).
        (Geometry::Straight(d), _) => {
            let len = path::norm(d);
            taken = if len > 0.0 {
                Sampled::new((
                    vec![(d.map(|x| x / len), [0.0; 3])],
                    vec![[0.0; 3]],
                    vec![],
                    vec![],
                ))
            } else {
                Sampled::new((vec![], vec![], vec![], vec![]))
            };
            &taken
        }
        (Geometry::Curve(b), _) => {
            taken = Sampled::new(if surface {
                surface_samples(b)
            } else {
                samples(b, false)
            });
            &taken
        }
    };
    let (figs, jumps) = (&sampled.figures[..], &sampled.jumps[..]);
    let ((first, dk_first), (last, dk_last)) = (sampled.first, sampled.last);
    let mut v = feed_mm_s;
    for jump in jumps {
        if *jump > 1e-9 {
            v = v.min((share * j_path * period_s / (SAMPLED_STEP * jump)).sqrt());
        }
    }
    for f in figs {
        let kappa = f.kappa;
        if kappa > 1e-12 {
            let rho = 1.0 / kappa;
            let tol = machine.chord_tolerance_mm.min(rho);
            let chord = 2.0 * (tol * (2.0 * rho - tol)).sqrt();
            v = v.min(chord / period_s).min((share * a_path / kappa).sqrt());
        }
        if f.dkn > 1e-12 {
            v = min_cbrt(v, share * j_path / f.dkn);
        }
        for (i, ax) in axes.iter().enumerate() {
            if f.t[i] > 1e-12 {
                v = v.min(ax.max_vel_mm_per_min / 60.0 / f.t[i]);
            }
            if f.k[i] > 1e-12 {
                v = v.min((share * ax.max_acc_mm_per_s2 / f.k[i]).sqrt());
            }
            if f.dk[i] > 1e-12 {
                v = min_cbrt(v, share * ax.max_jerk_mm_per_s3 / f.dk[i]);
            }
        }
    }
    // What the cap speed leaves to the profile along the path.
    let leftover = |v: f64| {
        let mut acc = a_path;
        for f in figs {
            let (kappa, t, k, dk) = (f.kappa, &f.t, &f.k, &f.dk);
            let an = v * v * kappa;
            acc = acc.min((a_path * a_path - an * an).max(0.0).sqrt());
            let jn = v * v * v * f.dkn;
            if kappa > 1e-12 {
                acc = acc.min((j_path - jn) / (6.0 * v * kappa));
            }
            for (i, ax) in axes.iter().enumerate() {
                if t[i] > 1e-12 {
                    acc = acc.min((ax.max_acc_mm_per_s2 - v * v * k[i]) / t[i]);
                    if k[i] > 1e-12 {
                        let jn_i = v * v * v * dk[i];
                        acc = acc.min((ax.max_jerk_mm_per_s3 - jn_i) / (6.0 * v * k[i]));
                    }
                }
            }
        }
        // A surface's tool point also changes its speed where the ratio does: `r'·ṡ²`
        // along its tangent at the contact speed `ṡ` (at most `v / ratio`), taken from
        // what the profile may use; the total along the tangent stays within `acc`.
        let acc_total = acc;
        let acc = acc - ratio_slope * (v / ratio) * (v / ratio);
        let mut jerk = j_path;
        for f in figs {
            let (t, k, dk) = (&f.t, &f.k, &f.dk);
            jerk = jerk.min(j_path - 3.0 * v * acc_total * f.kappa - v * v * v * f.dkn);
            for (i, ax) in axes.iter().enumerate() {
                if t[i] > 1e-12 {
                    let other = 3.0 * v * acc_total * k[i] + v * v * v * dk[i];
                    jerk = jerk.min((ax.max_jerk_mm_per_s3 - other) / t[i]);
                }
            }
        }
        (acc, jerk)
    };
    // The profile is left at least a twentieth of the weakest acceleration and jerk
    // (`profile_floors`): where the cap leaves less (the `6·v·k·a` term of a tight bend
    // at a low speed binds the acceleration through the jerk, not through the share),
    // the cap is lowered until it does (within `LOWER_STEPS`). A floor put
    // under the acceleration instead (a twentieth of the path's) put an X limit 1.08
    // times over on a weak X (random search, seed 5: 14 curves of 600).
    let (acc_min, jerk_min) = profile_floors(machine);
    let (mut acc, mut jerk) = leftover(v);
    let v0 = v;
    for _ in 0..LOWER_STEPS {
        // (Never below the slowest feed a block may have: see `check`.)
        let slowest = shared::machine::MIN_FEED_MM_PER_MIN / 60.0 * ratio;
        if (acc >= acc_min && jerk >= jerk_min) || v * 0.8 < 4.0 * slowest || v.is_nan() {
            break;
        }
        v *= LOWER_STEP;
        (acc, jerk) = leftover(v);
    }
    // The last step down overshoots by up to a fifth: the highest cap between it and the
    // one before that still leaves the floors, by bisection (to 0.02 %). Where the
    // curvature takes most of the jerk (`VALLEY_SHARE`), the leftover falls steeply
    // with the cap and a whole step threw away what the larger share gained (the CAM
    // circle, `examples/cam-circle.ngc`, on the built-in machine: its blends at 32.4
    // mm/s with 0.95, 32.7 with half, 40.5 with the bisection).
    if v < v0 && acc >= acc_min && jerk >= jerk_min {
        let (mut lo, mut hi) = (v, (v / LOWER_STEP).min(v0));
        for _ in 0..LOWER_BISECTIONS {
            let mid = 0.5 * (lo + hi);
            let (a, j) = leftover(mid);
            if a >= acc_min && j >= jerk_min {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        v = lo;
        (acc, jerk) = leftover(v);
    }
    // Where even that is not enough (a near-cusp, whose curvature is huge), the profile
    // keeps what is left, however little, so no limit is broken: the floor, a thousandth
    // of the above, only guards against a degenerate sample.
    let (acc, jerk) = (acc.max(1e-3 * acc_min), jerk.max(1e-3 * jerk_min));
    Shape {
        v_cap: v / ratio,
        acc: acc / ratio,
        jerk: jerk / ratio,
        t_start: first.0,
        t_end: last.0,
        k_start: first.1,
        k_end: last.1,
        dk_start: dk_first,
        dk_end: dk_last,
        surface_ratio: surface.then_some(ratio),
        m_start: match g {
            Geometry::Curve(b) if surface => Some(path::tool_rate(b, 0.0)),
            _ => None,
        },
        m_end: match g {
            Geometry::Curve(b) if surface => Some(path::tool_rate(b, 1.0)),
            _ => None,
        },
        m2_start: match g {
            Geometry::Curve(b) if surface => Some(path::tool_rate2(b, 0.0)),
            _ => None,
        },
        m2_end: match g {
            Geometry::Curve(b) if surface => Some(path::tool_rate2(b, 1.0)),
            _ => None,
        },
    }
}

/// The tangential acceleration and jerk a curve block's profile may use at the speeds it
/// can have, not only at its cap: it enters at `start` at most and leaves at `end` at
/// most (mm/s, the planned junction speeds, which the interpolator never exceeds), and
/// changes its speed by `acc` at most, so at a share `x` of its length `len` its speed is
/// within `min(cap, √(start² + 2·acc·x·len), √(end² + 2·acc·(1 − x)·len))`. Where the
/// curvature is sharpest near the slower end (a valley's flank), that leaves the profile
/// more than [`shape`]'s worst case at the cap. The acceleration is the highest that
/// keeps every limit with `lim.jerk`; the jerk then what `3·v·a·|k|` and `v³·|dk/ds|`
/// leave at those speeds. Neither is less than `lim`'s nor (unless `lim`'s is) above
/// `ceiling`, what the junctions' loads leave the block.
#[cfg(test)]
#[allow(clippy::too_many_arguments)]
fn relaxed_limits(
    b: &CommandBlock,
    machine: &Machine,
    cap: f64,
    lim: Jerk,
    (start, end): (f64, f64),
    len: f64,
    ceiling: Jerk,
) -> Jerk {
    let ends = (start, end);
    relaxed_at(
        &Sampled::of(b).figures,
        machine,
        cap,
        lim,
        ends,
        len,
        ceiling,
    )
}

/// [`relaxed_limits`] from the figures of the block's samples, taken once by a caller
/// that asks for several planned speeds.
#[allow(clippy::too_many_arguments)]
fn relaxed_at(
    figures: &[Figure],
    machine: &Machine,
    cap: f64,
    lim: Jerk,
    ends: (f64, f64),
    len: f64,
    ceiling: Jerk,
) -> Jerk {
    let env = Envelope {
        figures,
        machine,
        cap,
        ends,
        len,
    };
    let top = machine
        .axes
        .as_array()
        .iter()
        .fold(machine.path_acc_mm_per_s2, |m, ax| {
            m.max(ax.max_acc_mm_per_s2)
        });
    // (`lim.acc` itself fits with `lim.jerk`: [`shape`] found the two at the cap, the
    // envelope's highest, or [`braking_relaxed`] raised the jerk to what that
    // acceleration leaves at speeds up to at least the planned start; not asked again,
    // as a limit it binds exactly may round either way.)
    if figures.is_empty() {
        return lim;
    }
    let acc = if lim.acc.partial_cmp(&top) == Some(std::cmp::Ordering::Less) {
        env.highest_acc(lim.acc, top, 20, lim.jerk)
            .min(ceiling.acc)
            .max(lim.acc)
    } else {
        lim.acc
    };
    Jerk {
        acc,
        jerk: env.jerk_left(acc).min(ceiling.jerk).max(lim.jerk),
    }
}

/// A curve block's samples (tangent and curvature, the curvature's rate, and the share
/// of the length each stands for) with the speeds it can have there: within its `cap`,
/// entered at `ends.0` and left at `ends.1` at most (mm/s), `len` mm long.
struct Envelope<'a> {
    figures: &'a [Figure],
    machine: &'a Machine,
    cap: f64,
    ends: (f64, f64),
    len: f64,
}

/// One sample of a curve block as [`Envelope`] weighs it: the norms and each axis's
/// share of its tangent, curvature and curvature rate, and the least and most share
/// of the block's length before it (widened by [`Envelope::MARGIN`]). Worked out once a
/// block ([`figures`]), not at every speed tried: the bisections of
/// [`relaxed_at`] and the braking search ask for them twenty times and more.
#[derive(Debug, Clone, Copy)]
struct Figure {
    kappa: f64,
    dkn: f64,
    t: [f64; 3],
    k: [f64; 3],
    dk: [f64; 3],
    lo: f64,
    hi: f64,
}

/// A curve block's samples as the planner keeps them ([`PlanCache`]): each one's
/// [`Figure`], the first and last (frame and curvature rate, for the junctions) and the
/// curvature jumps at its knots.
struct Sampled {
    figures: Vec<Figure>,
    jumps: Vec<f64>,
    first: (Frame, [f64; 3]),
    last: (Frame, [f64; 3]),
}

impl Sampled {
    /// The samples of curve `b` with their places ([`samples`]).
    fn of(b: &CommandBlock) -> Self {
        Self::new(samples(b, true))
    }

    /// From samples as [`samples`] gives them (without places, or places not one a
    /// sample, each sample's place is the whole block).
    fn new((pts, dk, jumps, at): Samples) -> Self {
        let first = pts.first().copied().unwrap_or(([1.0, 0.0, 0.0], [0.0; 3]));
        let last = pts.last().copied().unwrap_or(first);
        let dk_first = dk.first().copied().unwrap_or([0.0; 3]);
        let dk_last = dk.last().copied().unwrap_or(dk_first);
        let figures = if at.len() == pts.len() {
            figures(&pts, &dk, &at)
        } else {
            figures(&pts, &dk, &vec![[0.0, 1.0]; pts.len()])
        };
        Sampled {
            figures,
            jumps,
            first: (first, dk_first),
            last: (last, dk_last),
        }
    }

    /// Bytes it holds.
    fn bytes(&self) -> usize {
        std::mem::size_of::<Self>()
            + std::mem::size_of_val(&self.figures[..])
            + std::mem::size_of_val(&self.jumps[..])
    }
}

/// Each sample's [`Figure`] (`at`: the samples' places, as [`samples`] gives them with
/// `places`; none without).
fn figures(pts: &[Frame], dk: &[[f64; 3]], at: &[[f64; 2]]) -> Vec<Figure> {
    pts.iter()
        .zip(dk)
        .zip(at)
        .map(|((&(t, k), &dk), x)| Figure {
            kappa: path::norm(k),
            dkn: path::norm(dk),
            t: t.map(f64::abs),
            k: k.map(f64::abs),
            dk: dk.map(f64::abs),
            lo: (x[0] - Envelope::MARGIN).max(0.0),
            hi: (x[1] + Envelope::MARGIN).min(1.0),
        })
        .collect()
}

impl Envelope<'_> {
    /// A margin on each place for the chords' shortfall against the arc.
    const MARGIN: f64 = 0.01;

    /// The highest speed the profile can have at sample `f` when it changes its speed
    /// by `a` at most. (`√` is monotone and rounds exactly, so one root of the lower
    /// square is the lower of the two roots, bit for bit.)
    #[inline(always)]
    fn speed(&self, f: &Figure, a: f64) -> f64 {
        let ((start, end), len, cap) = (self.ends, self.len, self.cap);
        let up = start * start + 2.0 * a * f.hi * len;
        let down = end * end + 2.0 * a * (1.0 - f.lo) * len;
        cap.min(up.min(down).sqrt())
    }

    /// What a profile changing its speed by `a` at most, with the jerk `j`, puts on each
    /// of the path's and each axis's limits at sample `f`, beside the limit: the
    /// acceleration (the path's squared), the jerk at the most the acceleration's
    /// change `6·v·|k|·a` takes, and the jerk with the profile's own; then each axis's
    /// three. Each load is a sum of products of non-negative figures with `a`, `j` and
    /// [`Envelope::speed`] (itself non-decreasing in `a`), and rounding is monotone: so
    /// a load never falls as `a` rises, in floating point too.
    #[inline(always)]
    fn loads(&self, f: &Figure, a: f64, j: f64) -> [(f64, f64); 12] {
        let m = self.machine;
        let (a_path, j_path) = (m.path_acc_mm_per_s2, m.path_jerk_mm_per_s3);
        let v = self.speed(f, a);
        let an = v * v * f.kappa;
        let jn = v * v * v * f.dkn;
        let mut out = [
            (a * a + an * an, a_path * a_path),
            (6.0 * v * f.kappa * a + jn, j_path),
            (j + 3.0 * v * a * f.kappa + jn, j_path),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
            (0.0, 1.0),
        ];
        for (i, ax) in m.axes.as_array().iter().enumerate() {
            let (ti, ki, dki) = (f.t[i], f.k[i], f.dk[i]);
            let jn_i = v * v * v * dki;
            let (acc, jerk) = (ax.max_acc_mm_per_s2, ax.max_jerk_mm_per_s3);
            out[3 + 3 * i] = (a * ti + v * v * ki, acc);
            out[4 + 3 * i] = (6.0 * v * ki * a + jn_i, jerk);
            out[5 + 3 * i] = (j * ti + 3.0 * v * a * ki + jn_i, jerk);
        }
        out
    }

    /// The least share of its limit that any of [`Envelope::loads`] leaves unused
    /// (negative where one is broken): which sample binds, for
    /// [`Envelope::highest_acc`]'s choice.
    fn slack(&self, f: &Figure, a: f64, j: f64) -> f64 {
        self.loads(f, a, j)
            .iter()
            .fold(f64::INFINITY, |least, (load, limit)| {
                least.min(1.0 - load / limit)
            })
    }

    /// Whether a profile changing its speed by `a` at most, with the jerk `j`, keeps the
    /// path's and each axis's acceleration and jerk at sample `f`: every one of
    /// [`Envelope::loads`] within its limit. A sample kept at `a` is kept at any lower
    /// `a`.
    #[inline(always)]
    fn keeps(&self, f: &Figure, a: f64, j: f64) -> bool {
        self.loads(f, a, j)
            .iter()
            .all(|(load, limit)| load <= limit)
    }

    /// Whether a profile changing its speed by `a` at most, with the jerk `j`, keeps the
    /// path's and each axis's acceleration and jerk everywhere.
    #[cfg(test)]
    fn fits(&self, a: f64, j: f64) -> bool {
        self.figures.iter().all(|f| self.keeps(f, a, j))
    }

    /// The sample with the least [`Envelope::slack`] at `a` among those `pick` takes.
    fn tightest(&self, a: f64, j: f64, pick: impl Fn(&Figure) -> bool) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for (i, f) in self.figures.iter().enumerate() {
            if pick(f) {
                let s = self.slack(f, a, j);
                if best.is_none_or(|(_, b)| s < b) {
                    best = Some((i, s));
                }
            }
        }
        best.map(|(i, _)| i)
    }

    /// `highest_fitting(lo, hi, halvings, |a| fits(a, j))`, every sample asked at every
    /// step, bit for bit, asking most of the bisection's steps of a sample or two: those
    /// that bind.
    ///
    /// The bisection is run asking only a set of samples (at first the one with the
    /// least room at its first step, [`Envelope::tightest`]), and its answer `r` is then
    /// asked of every sample. Where all keep at `r`, every step the set passed (each at
    /// or below `r`, as the bisection's low end only rises) passes with all samples too
    /// ([`Envelope::keeps`] is monotone), and every step it failed fails with all: the
    /// whole bisection takes the same steps. Where some do not keep, the one with the
    /// least room joins the set and the bisection is run again. Where the set failed
    /// every step, so do all samples, and the answer is `lo` either way.
    fn highest_acc(&self, lo: f64, hi: f64, halvings: usize, j: f64) -> f64 {
        const MOST: usize = 6;
        let mut set = [0usize; MOST];
        let Some(first) = self.tightest(0.5 * (lo + hi), j, |_| true) else {
            return highest_fitting(lo, hi, halvings, |_| true);
        };
        set[0] = first;
        let mut n = 1;
        loop {
            let asked = &set[..n];
            let r = highest_fitting(lo, hi, halvings, |a| {
                asked.iter().all(|&i| self.keeps(&self.figures[i], a, j))
            });
            if r == lo {
                return r;
            }
            match self.tightest(r, j, |f| !self.keeps(f, r, j)) {
                None => return r,
                Some(i) if n < MOST => {
                    set[n] = i;
                    n += 1;
                }
                Some(_) => {
                    return highest_fitting(lo, hi, halvings, |a| {
                        self.figures.iter().all(|f| self.keeps(f, a, j))
                    })
                }
            }
        }
    }

    /// The jerk the profile may use with the acceleration `a`: what `3·v·a·|k|` and
    /// `v³·|dk/ds|` leave of the path's and each axis's, as [`shape`] takes it at the cap
    /// (the speed envelope's highest).
    fn jerk_left(&self, a: f64) -> f64 {
        let m = self.machine;
        let j_path = m.path_jerk_mm_per_s3;
        let axes = m.axes.as_array();
        let mut jerk = j_path;
        for f in self.figures {
            let v = self.speed(f, a);
            let jn = v * v * v * f.dkn;
            jerk = jerk.min(j_path - 3.0 * v * a * f.kappa - jn);
            for (i, ax) in axes.iter().enumerate() {
                if f.t[i] > 1e-12 {
                    let other = 3.0 * v * a * f.k[i] + v * v * v * f.dk[i];
                    jerk = jerk.min((ax.max_jerk_mm_per_s3 - other) / f.t[i]);
                }
            }
        }
        jerk
    }
}

/// The highest of `halvings` bisections of `[lo, hi]` where `fits` holds, `lo` taken to
/// fit and `fits` to hold below any point it holds at.
fn highest_fitting(mut lo: f64, mut hi: f64, halvings: usize, fits: impl Fn(f64) -> bool) -> f64 {
    for _ in 0..halvings {
        let mid = 0.5 * (lo + hi);
        if fits(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// `v.min(x.cbrt())`, without the cube root where it cannot be the lower: where `v³`
/// (a normal number, within a few roundings of the true cube) is below `x` by more than
/// a millionth, `∛x` is above `v`, even as `cbrt` rounds it, and the minimum is `v`.
/// Anything else (zeros, NaN, infinities, tiny or close numbers) takes the cube root.
fn min_cbrt(v: f64, x: f64) -> f64 {
    let cube = v * v * v;
    if v >= 0.0 && cube > 1e-290 && cube < x * (1.0 - 1e-6) {
        v
    } else {
        v.min(x.cbrt())
    }
}

/// What [`shape`] takes from the machine for a straight block, worked out once a plan.
/// `None` unless every limit is a positive number below 1e100: then the terms a zero
/// curvature leaves in [`shape`] are exact zeros (no product of them overflows into
/// infinity and NaN), and [`shape_straight`] can leave them out and give the same bits.
#[derive(Debug, Clone, Copy)]
struct StraightLimits {
    /// Each axis's velocity limit in mm/s (`max_vel_mm_per_min / 60.0`, as `shape`).
    vel_mm_s: [f64; 3],
    acc: [f64; 3],
    jerk: [f64; 3],
    /// `shape`'s tangential acceleration before the axes: what a zero normal
    /// acceleration leaves of the path's, `a.min(sqrt(a² - 0²))`.
    a_tangential: f64,
    j_path: f64,
    /// `shape`'s floors of the acceleration and jerk.
    acc_floor: f64,
    jerk_floor: f64,
}

impl StraightLimits {
    fn new(machine: &Machine) -> Option<Self> {
        let axes = machine.axes.as_array();
        let a_path = machine.path_acc_mm_per_s2;
        let j_path = machine.path_jerk_mm_per_s3;
        let usable = |x: f64| x > 0.0 && x < 1e100;
        let mut all = [a_path, j_path]
            .into_iter()
            .chain(axes.iter().flat_map(|a| {
                [
                    a.max_vel_mm_per_min,
                    a.max_acc_mm_per_s2,
                    a.max_jerk_mm_per_s3,
                ]
            }));
        // The normal acceleration `v²·κ` of a line: `+0` for any such `v`.
        let an = 0.0f64;
        all.all(usable).then(|| StraightLimits {
            vel_mm_s: axes.map(|a| a.max_vel_mm_per_min / 60.0),
            acc: axes.map(|a| a.max_acc_mm_per_s2),
            jerk: axes.map(|a| a.max_jerk_mm_per_s3),
            a_tangential: a_path.min((a_path * a_path - an * an).max(0.0).sqrt()),
            j_path,
            acc_floor: 1e-3 * profile_floors(machine).0,
            jerk_floor: 1e-3 * profile_floors(machine).1,
        })
    }
}

/// [`shape`] of a straight block of chord `d`, bit for bit, without the terms its zero
/// curvature makes zero; `None` where those terms might not be exact zeros (a feed
/// that is not a finite number below 1e100, a chord without a length), which `shape`
/// then handles. Lines are most blocks of most programs: this is the planner's hot path.
#[cfg(test)]
fn shape_straight(d: [f64; 3], lim: &StraightLimits, feed_mm_s: f64) -> Option<Shape> {
    let mut shape = Shape::NONE;
    shape_straight_into(d, path::norm(d), lim, feed_mm_s, &mut shape).then_some(shape)
}

/// [`shape_straight`] written into `out` (where it stays: a shape is 312 bytes), `false`
/// where it is `None`, leaving `out` as it was; `len` is the chord's `path::norm`, which
/// the planner has worked out already.
fn shape_straight_into(
    d: [f64; 3],
    len: f64,
    lim: &StraightLimits,
    feed_mm_s: f64,
    out: &mut Shape,
) -> bool {
    if !(len > 0.0 && feed_mm_s.is_finite() && feed_mm_s.abs() < 1e100) {
        return false;
    }
    let t = d.map(|x| x / len);
    // As in `shape`, axis by axis, in its order: the cap speed (only the velocity
    // limits bind a line), then the tangential acceleration (`max_acc - v²·0`), then
    // the jerk (`j - 3·v·a·0 - v³·0` is `j`).
    //
    // A component of the unit tangent is at most 1 (the norm is at least each
    // component's length, rounding included), so `limit/|t_i|` is at least `limit`: an
    // `x` already at or below the limit stays as it is, and the division (tens of
    // cycles, nine a block) is left out. Checked, not assumed: a `|t_i|` above 1 (only
    // where squares underflow) divides as before.
    let axis_by_axis = |start: f64, per_axis: &[f64; 3]| {
        t.iter().zip(per_axis).fold(start, |x, (ti, limit)| {
            let ti = ti.abs();
            if ti > 1e-12 && !(x <= *limit && ti <= 1.0) {
                x.min(limit / ti)
            } else {
                x
            }
        })
    };
    let v = axis_by_axis(feed_mm_s, &lim.vel_mm_s);
    let acc = axis_by_axis(lim.a_tangential, &lim.acc);
    let jerk = axis_by_axis(lim.j_path, &lim.jerk);
    *out = Shape {
        v_cap: v,
        acc: acc.max(lim.acc_floor),
        jerk: jerk.max(lim.jerk_floor),
        t_start: t,
        t_end: t,
        ..Shape::NONE
    };
    true
}

/// The chord of a block that is a straight segment (degree 1, two control points, no
/// helix; whatever the weights, such a curve runs straight from one to the other).
fn straight(b: &CommandBlock) -> Option<[f64; 3]> {
    let c = b.ctrl();
    (!b.is_surface() && b.degree == 1 && c.len() == 2 && b.helix.axis == Helix::NONE.axis)
        .then(|| [c[1][0] - c[0][0], c[1][1] - c[0][1], c[1][2] - c[0][2]])
}

/// A unit tangent with the curvature vector there.
type Frame = ([f64; 3], [f64; 3]);

/// Unit tangents with curvature vectors, curvature derivatives, curvature jumps.
/// One sample: the frame and dk/ds.
type Sample = (Frame, [f64; 3]);
/// Where each sample lies along its block: the least and the most share of the block's
/// length before it (see [`samples`]; empty unless asked for).
type Samples = (Vec<Frame>, Vec<[f64; 3]>, Vec<f64>, Vec<[f64; 2]>);
/// A measure of a sample, and the search of it between samples (at a parameter).
type Measure<'a> = (fn(&Sample) -> f64, &'a dyn Fn(f64) -> Option<f64>);

/// Evenly spaced samples of a curve block for each of its control points, and the
/// fewest a block (before those at its knots, those its tangent's turns add and those
/// the peak searches find). What keeps a limit from being missed between samples is
/// not this grid but the rest: the knots, the turns within [`MAX_TURN_RAD`], and the
/// searches about each sample that is a local peak. The grid only has to show the
/// peaks; most curve blocks are a single span cut from a curve by the speed split, a
/// few mm long, whose every limit is within one level of the others. (16 and 32 until
/// 2026-11-29: halved, `cnc check` on the bench's curves took 30 % fewer instructions;
/// every machining time of the peers and examples on both machines stayed within 1 ms
/// but the butterfly at F6000 on the built-in machine, 13.771 -> 13.778 s; the random
/// search of `limits.rs`, seeds 7 and 11, 300 cases each of its six kinds, found no
/// limit broken. A quarter, 4 and 16: 45 % fewer, but LinuxCNC's butterfly at F6000
/// 11.074 -> 11.092 s, against LinuxCNC's own 11.095.)
const GRID_PER_CTRL: usize = 8;
/// See [`GRID_PER_CTRL`].
const GRID_LEAST: usize = 16;
/// Local maxima of the curvature and of its rate searched between samples, of each.
const PEAKS_REFINED: usize = 3;
/// Most a unit tangent turns between two samples of a curve (where more samples can
/// make it so).
const MAX_TURN_RAD: f64 = 0.35;
/// Most samples added to one block to keep its tangent's turns within `MAX_TURN_RAD`.
const TURN_SAMPLES: usize = 512;
/// Local maxima of an axis's tangent share searched between samples: every one within
/// `1 − cos(MAX_TURN_RAD/2)` (plus a margin) of the largest sample, up to this many.
const TANGENT_PEAKS_REFINED: usize = 8;

/// Where on `[lo, hi]` the measure `f` is largest (for one peak there), to 1e-9 of the
/// interval, by [`brent_min`] on `-f`; `None` where `f` has no value at a point it tries.
fn golden_max(lo: f64, hi: f64, f: impl Fn(f64) -> Option<f64>) -> Option<f64> {
    brent_min(lo, hi, |u| f(u).map(|x| -x)).map(|(u, _)| u)
}

/// Most steps of [`brent_min`]: golden-section steps alone reach its tolerance in 44.
const BRENT_STEPS: usize = 100;

/// Where on `[lo, hi]` the measure `f` is least (for one valley there), with the value
/// there: Brent's method (parabolic steps through the best three points, a
/// golden-section step wherever the parabola would leave the bracket or not shrink it
/// fast enough), until the bracket is 1e-9 of `[lo, hi]`, the precision the plain
/// golden-section search of before stopped at. On a smooth valley the parabolas
/// converge superlinearly, and closing the bracket round the valley takes most of the
/// points (a parabola: 30 instead of 44). `None` where `f` has no value at a point it
/// tries. ([`crate::brent::minimise`] from the golden section's first point; the
/// contour's nearest-point search is the same method.)
pub(crate) fn brent_min(
    lo: f64,
    hi: f64,
    mut f: impl FnMut(f64) -> Option<f64>,
) -> Option<(f64, f64)> {
    // The golden section's first point; the search stops at a quarter of the bracket.
    let x = lo + 0.381_966_011_250_105_1 * (hi - lo);
    let fx = f(x)?;
    crate::brent::minimise(lo, hi, (x, fx), BRENT_STEPS, |_| 0.25e-9 * (hi - lo), f)
}

/// Samples of a curved block for [`shape`]: unit tangent and curvature vector at each,
/// the curvature's derivative along the path at each, and the curvature jumps at its
/// interior knots (with each sample's place along the block where `places` asks).
fn samples(b: &CommandBlock, places: bool) -> Samples {
    let (u0, u1) = path::domain(b);
    // Hundreds of points a block, nearly all inside the span of the one before:
    // the moving-data evaluator (see [`eval`]).
    let ev = eval::BlockEval::new(b);
    let frame = |u: f64| frame_at(&ev.eval(u));
    let samples = (GRID_PER_CTRL * b.n_ctrl.max(2) as usize).max(GRID_LEAST);
    // Distinct knots: dk/ds is taken by differences inside one span (where the curve is
    // smooth), and the curvature jump at a knot of continuity below C² is a junction of
    // its own.
    let mut spans: Vec<f64> = b.knots().to_vec();
    spans.dedup();
    let span_of = |u: f64| {
        let i = spans
            .partition_point(|k| *k <= u)
            .clamp(1, spans.len().max(2) - 1);
        (spans[i - 1], spans[i.min(spans.len() - 1)])
    };
    // dk/ds at `u`, by a central difference inside u's span.
    let rate = |u: f64| -> [f64; 3] {
        let (lo, hi) = span_of(u);
        let h = 1e-4 * (hi - lo);
        let (ua, ub) = ((u - h).max(lo), (u + h).min(hi));
        if ub.partial_cmp(&ua) != Some(std::cmp::Ordering::Greater) {
            return [0.0; 3];
        }
        let (ea, eb) = (ev.eval(ua), ev.eval(ub));
        match (frame_at(&ea), frame_at(&eb)) {
            (Some((_, ka)), Some((_, kb))) => {
                let ds = path::norm(sub(eb.p, ea.p));
                if ds > 1e-15 {
                    sub(kb, ka).map(|x| x / ds)
                } else {
                    [0.0; 3]
                }
            }
            _ => [0.0; 3],
        }
    };
    // The frame and dk/ds at `u`; none where the curve (nearly) stops.
    let at = |u: f64| -> Option<Sample> { Some((frame(u)?, rate(u))) };
    let mut us: Vec<f64> = Vec::with_capacity(samples + 1);
    let mut pts: Vec<Frame> = Vec::with_capacity(samples + 1);
    let mut dk: Vec<[f64; 3]> = Vec::with_capacity(samples + 1);
    // Evenly spaced, and at each interior knot (where a tangent's swing may change
    // course: the searches between samples below then look inside one span).
    let mut grid: Vec<f64> = (0..=samples)
        .map(|i| u0 + (u1 - u0) * i as f64 / samples as f64)
        .chain(spans.iter().copied().filter(|k| *k > u0 && *k < u1))
        .collect();
    grid.sort_by(f64::total_cmp);
    grid.dedup();
    for u in grid {
        if let Some((f, d)) = at(u) {
            us.push(u);
            pts.push(f);
            dk.push(d);
        }
    }
    // Where the tangent turns by more than `MAX_TURN_RAD` between two samples (a tight
    // bend), samples are added halfway until it does not: each axis's share of the
    // tangent then has at most one hump between samples, found by the search below,
    // and none peaks higher than a sample by more than `1 − cos(MAX_TURN_RAD/2)`.
    let mut budget = TURN_SAMPLES;
    let mut i = 0;
    while i + 1 < us.len() {
        let turn = dot(pts[i].0, pts[i + 1].0);
        let u = 0.5 * (us[i] + us[i + 1]);
        if turn < MAX_TURN_RAD.cos() && budget > 0 && u > us[i] && u < us[i + 1] {
            budget -= 1;
            if let Some((f, d)) = at(u) {
                us.insert(i + 1, u);
                pts.insert(i + 1, f);
                dk.insert(i + 1, d);
                continue;
            }
        }
        i += 1;
    }
    // A peak of the curvature or of its rate narrower than the sampling (a control
    // polygon folding back on itself turns in a few µm) is found between its samples:
    // the largest local maxima of each are searched (Brent's method, [`brent_min`])
    // between their neighbours, and what is found joins the samples (before the last,
    // which gives the end's tangent). The searches look at one measure: the curvature takes one
    // evaluation, its rate the two of its difference, plus one to know the curve does
    // not stop there, unless its speed is proven well above that stop
    // ([`hodograph`]; curves without a helix that are one Bézier span).
    let moving = match (b.helix.axis == Helix::NONE.axis)
        .then(|| hodograph::Hodograph::of_span(b.degree as usize, b.knots(), b.ctrl()))
        .flatten()
    {
        Some(h) => h.cells_above(1e-12),
        None => 0,
    };
    let surely_moving = |u: f64| {
        let cell = ((u - u0) / (u1 - u0) * hodograph::CELLS as f64).floor();
        (0.0..hodograph::CELLS as f64).contains(&cell) && {
            let c = cell as usize;
            let (lo, hi) = (c.saturating_sub(1), (c + 1).min(hodograph::CELLS - 1));
            (lo..=hi).all(|j| moving >> j & 1 == 1)
        }
    };
    let curvature = |u: f64| frame(u).map(|(_, k)| path::norm(k));
    let curvature_rate = |u: f64| {
        if !surely_moving(u) {
            frame(u)?;
        }
        Some(path::norm(rate(u)))
    };
    // And each axis's share of the tangent, whose peak sets that axis's velocity bound:
    // in a tight bend it swings through its peak between samples as fast as the
    // curvature does (missed in a bend at a split block's end, at its cap, it let a weak
    // axis's velocity be broken in the random search of `limits.rs`).
    // (Searched on each side of its sample, in case the swing has two humps there: the
    // tangent may pass through an axis and turn back within one sample's reach.)
    // (Only the tangent: `frame_at`'s, bit for bit, without the curvature it would work out.)
    let tangent = |i: usize| {
        let ev = &ev;
        move |u: f64| {
            let e = ev.eval(u);
            let sp = path::norm(e.d1);
            // (NaN goes on, as in `frame_at`.)
            (sp.partial_cmp(&1e-12) != Some(std::cmp::Ordering::Less)).then(|| (e.d1[i] / sp).abs())
        }
    };
    let (tx, ty, tz) = (tangent(0), tangent(1), tangent(2));
    let mut extra: Vec<Sample> = Vec::new();
    let mut extra_at: Vec<(f64, f64)> = Vec::new();
    let measures: [(Measure, bool); 5] = [
        ((|x| path::norm(x.0 .1), &curvature), false),
        ((|x| path::norm(x.1), &curvature_rate), false),
        ((|x| x.0 .0[0].abs(), &tx), true),
        ((|x| x.0 .0[1].abs(), &ty), true),
        ((|x| x.0 .0[2].abs(), &tz), true),
    ];
    let mut values: Vec<f64> = Vec::with_capacity(pts.len());
    for ((m, search), halves) in measures {
        values.clear();
        values.extend(pts.iter().zip(&dk).map(|(f, d)| m(&(*f, *d))));
        let value = |i: usize| values[i];
        // (The tangent's peaks at an end too, searched towards the domain's end: a curve
        // leaving a stop swings fastest there, and its first sample may come after.)
        let last = pts.len().saturating_sub(1);
        let ends = usize::from(halves && !pts.is_empty());
        let mut peaks: Vec<usize> = (usize::from(!halves)..pts.len().saturating_sub(1) + ends)
            .filter(|&i| {
                // (Inside a plateau, as along a straight stretch, no peak: its end is.)
                let flat = |j: usize| (value(j) - value(i)).abs() <= 1e-12;
                (i == 0 || value(i) >= value(i - 1))
                    && (i == last || value(i) >= value(i + 1))
                    && value(i) > 0.0
                    && !(halves && (i == 0 || flat(i - 1)) && (i == last || flat(i + 1)))
            })
            .collect();
        peaks.sort_by(|a, b| value(*b).total_cmp(&value(*a)));
        let refined = if halves {
            // Only a hump that can rise above the largest sample.
            let top = peaks.first().map_or(0.0, |&i| value(i));
            let reach = 1.5 * (1.0 - (0.5 * MAX_TURN_RAD).cos());
            peaks.retain(|&i| value(i) >= top - reach);
            TANGENT_PEAKS_REFINED
        } else {
            PEAKS_REFINED
        };
        for &i in peaks.iter().take(refined) {
            let ranges = if halves {
                let before = if i == 0 { u0 } else { us[i - 1] };
                let after = if i == last { u1 } else { us[i + 1] };
                [(before, us[i]), (us[i], after)]
            } else {
                [(us[i - 1], us[i + 1]), (f64::NAN, f64::NAN)]
            };
            for (lo, hi) in ranges.into_iter().filter(|r| r.0 < r.1) {
                if let Some(found) = golden_max(lo, hi, search).and_then(at) {
                    extra.push(found);
                    extra_at.push((lo, hi));
                }
            }
        }
        if halves {
            // A hump just past a knot: the curvature jumps there, so the share may turn
            // back within one sample's step and rise above both samples beside it, while
            // the sample at the knot is no peak of the samples (the share higher at the
            // sample before). Each span is smooth, so a knot is an end of the spans on
            // either side, searched towards each side where the share does not rise
            // from it, as the domain's ends are. (Found by the property test
            // `samples_hold_each_axis_tangent_peak` once the grid was halved: a hump
            // 6e-4 above every sample just after a quadratic's knot.)
            let top = peaks.first().map_or(0.0, |&i| value(i));
            let reach = 1.5 * (1.0 - (0.5 * MAX_TURN_RAD).cos());
            let searched = |i: usize| peaks.iter().take(refined).any(|&p| p == i || p == i + 1);
            let mut sides: Vec<(f64, usize)> = Vec::new();
            for (k, u) in us.iter().enumerate().take(last).skip(1) {
                if spans.binary_search_by(|x| x.total_cmp(u)).is_err() {
                    continue;
                }
                for (side, other) in [(k - 1, k - 1), (k, k + 1)] {
                    if !searched(side) && value(k) >= value(other) && value(k) >= top - reach {
                        sides.push((value(k), side));
                    }
                }
            }
            sides.sort_by(|a, b| b.0.total_cmp(&a.0));
            for &(_, i) in sides.iter().take(TANGENT_PEAKS_REFINED) {
                let (lo, hi) = (us[i], us[i + 1]);
                if lo < hi {
                    if let Some(found) = golden_max(lo, hi, search).and_then(at) {
                        extra.push(found);
                        extra_at.push((lo, hi));
                    }
                }
            }
        }
    }
    // Each sample's place along the block, by the chords between the samples in order
    // (within a few thousandths of the arc: a tangent turns at most `MAX_TURN_RAD`
    // between two); a sample found by a search lies anywhere in its search's range.
    // Only where asked (`places`: [`relaxed_limits`]); none for [`shape`].
    let mut chords: Vec<f64> = Vec::new();
    let mut total = 0.0;
    if places {
        chords.reserve(us.len());
        let mut prev: Option<[f64; 3]> = None;
        for &u in &us {
            let p = ev.eval(u).p;
            if let Some(q) = prev {
                total += path::norm(sub(p, q));
            }
            chords.push(total);
            prev = Some(p);
        }
    }
    let share = |x: f64| if total > 0.0 { x / total } else { 0.0 };
    let mut at: Vec<[f64; 2]> = chords.iter().map(|&c| [share(c), share(c)]).collect();
    if !extra.is_empty() {
        let n = pts.len() - 1;
        pts.splice(n..n, extra.iter().map(|x| x.0));
        dk.splice(n..n, extra.iter().map(|x| x.1));
        let place = |(lo, hi): (f64, f64)| {
            let a = us.partition_point(|&u| u <= lo).saturating_sub(1);
            let b = us.partition_point(|&u| u < hi).min(us.len() - 1);
            [share(chords[a]), share(chords[b])]
        };
        if places {
            at.splice(n..n, extra_at.iter().map(|&r| place(r)));
        }
    }
    // Curvature jumps at interior knots where the curve is only C¹ (or less).
    let mut jumps: Vec<f64> = Vec::new();
    let degree = b.degree as usize;
    for w in spans.windows(2).skip(1) {
        let knot = w[0];
        let mult = b.knots().iter().filter(|k| **k == knot).count();
        if degree < mult + 2 {
            let eps = 1e-9 * (u1 - u0);
            if let (Some((_, ka)), Some((_, kb))) = (frame(knot - eps), frame(knot + eps)) {
                jumps.push(path::norm(sub(kb, ka)));
            }
        }
    }
    (pts, dk, jumps, at)
}

/// Samples along a surface block's pass (`t` in `[0, 1]`).
const SURFACE_SAMPLES: usize = 32;
/// Parameter step of the finite differences on a surface block's tool point path.
const SURFACE_DT: f64 = 1e-3;

/// The set-point path of a motion block at `u` with its first and second derivatives:
/// [`shared::path::eval`] for a curve; for a surface block the tool reference point
/// `M(t)` with derivatives by central differences (`shared::path::eval` gives `M` with
/// the contact path's derivatives), the stencil kept inside the pass.
pub(crate) fn set_point_eval(b: &CommandBlock, u: f64) -> shared::nurbs::CurvePoint {
    let mut e = path::eval(b, u);
    if !b.is_surface() {
        return e;
    }
    let h = SURFACE_DT;
    let tc = u.clamp(h, 1.0 - h);
    let (a, m, z) = (
        path::eval(b, tc - h).p,
        path::eval(b, tc).p,
        path::eval(b, tc + h).p,
    );
    e.d1 = core::array::from_fn(|i| (z[i] - a[i]) / (2.0 * h));
    e.d2 = core::array::from_fn(|i| (z[i] - 2.0 * m[i] + a[i]) / (h * h));
    e
}

/// A surface block's tool point with its unit tangent and curvature vector at `t`.
fn tool_point_frame(b: &CommandBlock, t: f64) -> Option<([f64; 3], [f64; 3], [f64; 3])> {
    let e = set_point_eval(b, t);
    let sp = path::norm(e.d1);
    if sp < 1e-12 {
        return None;
    }
    let tan = e.d1.map(|x| x / sp);
    let along = dot(e.d2, tan);
    let k = [0, 1, 2].map(|i| (e.d2[i] - along * tan[i]) / (sp * sp));
    Some((e.p, tan, k))
}

/// The largest ratio of the tool point's speed to the contact point's along a surface
/// block (`(ρ + R)/ρ` on a convex section, below 1 on a concave one), and the largest
/// rate of change of that ratio per mm of the contact path (`|dr/ds|`, 1/mm).
fn surface_speed_ratio(b: &CommandBlock) -> (f64, f64) {
    // Never below 1: where `M` is slower (a concave section) the contact path keeps the
    // machine's own limits rather than more.
    let mut ratio: f64 = 1.0;
    let mut slope: f64 = 0.0;
    let mut last: Option<(f64, f64)> = None;
    for i in 0..=SURFACE_SAMPLES {
        let t = i as f64 / SURFACE_SAMPLES as f64;
        let h = SURFACE_DT;
        let tc = t.clamp(h, 1.0 - h);
        let m = sub(path::eval(b, tc + h).p, path::eval(b, tc - h).p);
        let c = path::norm(path::contact(b, tc, &path::surface_at(b, tc)).d1);
        if c > 1e-12 {
            let r = path::norm(m) / (2.0 * h * c);
            ratio = ratio.max(r);
            // The slope between two samples, over the contact length between them
            // (their mean speed times the parameter step).
            if let Some((r0, c0)) = last {
                let ds = 0.5 * (c0 + c) / SURFACE_SAMPLES as f64;
                slope = slope.max((r - r0).abs() / ds);
            }
            last = Some((r, c));
        } else {
            last = None;
        }
    }
    (ratio, RATIO_SLOPE_MARGIN * slope)
}

/// The margin on the ratio's slope found between [`SURFACE_SAMPLES`]: a chord's slope
/// is the mean over its interval, and the steepest point inside lies above it.
const RATIO_SLOPE_MARGIN: f64 = 1.5;

/// [`samples`] for a surface block: the frames of its tool point path `M`. A patch is
/// smooth inside, so there are no curvature jumps within a block.
fn surface_samples(b: &CommandBlock) -> Samples {
    let mut pts: Vec<([f64; 3], [f64; 3])> = Vec::with_capacity(SURFACE_SAMPLES + 1);
    let mut at: Vec<[f64; 3]> = Vec::with_capacity(SURFACE_SAMPLES + 1);
    for i in 0..=SURFACE_SAMPLES {
        let t = i as f64 / SURFACE_SAMPLES as f64;
        if let Some((p, tan, k)) = tool_point_frame(b, t) {
            pts.push((tan, k));
            at.push(p);
        }
    }
    let n = pts.len();
    let dk = (0..n)
        .map(|i| {
            let (lo, hi) = (i.saturating_sub(1), (i + 1).min(n.saturating_sub(1)));
            let ds = path::norm(sub(at[hi], at[lo]));
            if hi > lo && ds > 1e-15 {
                sub(pts[hi].1, pts[lo].1).map(|x| x / ds)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    (pts, dk, Vec::new(), Vec::new())
}

/// Speed (mm/s) at which the junction between two motions with these shapes can be
/// passed: the lower cap; at a kink (tangent turning by `θ`), the speed whose direction
/// change in one period stays within the acceleration (`2·v·sin(θ/2) <= A·T`); where the
/// curvature jumps by `Δk`, the speed whose acceleration step `v²·Δk` in one period stays
/// within the jerk. Zero (exact stop) for corners sharper than the machine's corner angle.
///
/// Also returns the kink, if any, for [`CloseKinks`]: its turn and the acceleration
/// (times the period) its direction change may take.
fn junction_speed(
    a: &Shape,
    b: &Shape,
    at: &Junction,
    machine: &Machine,
    fixed: &PlanLimits,
    period_s: f64,
) -> (f64, Option<Kink>) {
    if at.cos < fixed.corner_cos {
        return (0.0, None);
    }
    // Between surface blocks the tangents and curvatures are the tool point's, which
    // moves up to `ratio` times the contact speed the caps are in. Its kinks (where the
    // surface is only C¹ the normal turns at a rate that jumps) may take only the share
    // of the acceleration the curvature leaves, so kink and curvature together stay
    // within the path's.
    let ratio = match (a.surface_ratio, b.surface_ratio) {
        (None, None) => None,
        (x, y) => Some(x.unwrap_or(1.0).max(y.unwrap_or(1.0))),
    };
    let (acc, jerk, r) = match ratio {
        None => (a.acc.min(b.acc), a.jerk.min(b.jerk), 1.0),
        Some(r) => (
            (1.0 - NORMAL_SHARE) * machine.path_acc_mm_per_s2,
            (1.0 - NORMAL_SHARE) * machine.path_jerk_mm_per_s3,
            r,
        ),
    };
    let mut v = a.v_cap.min(b.v_cap);
    let half_sin = at.half_sin;
    let mut kink = None;
    if is_kink(half_sin) {
        let mut acc_t = acc * period_s / r;
        v = v.min(acc_t / (2.0 * half_sin));
        if let Some(load) = at.load {
            // The direction change with the normal acceleration there takes at most
            // `KINK_SHARE` of the path's and of each axis's, so the profile keeps some
            // (see `junction_leaves`).
            v = load.acc_speed(v, &fixed.acc, KINK_SHARE);
            // A run of close kinks (`CloseKinks`) bounds its whole direction change,
            // whose every axis's share is at most its length.
            acc_t = acc_t.min(KINK_SHARE * fixed.weakest_acc * period_s);
        }
        kink = Some(Kink {
            j: 0,
            s: 0.0,
            half_sin,
            acc_t,
            tangents: ratio.is_none().then_some((a.t_end, b.t_start)),
        });
    }
    // The tool point's velocity step across the junction, in length and direction:
    // `v·|m_b − m_a|` within one period's share of the acceleration, and within half of
    // what the two blocks' profiles may use along the tool point's path (the other half
    // they keep: `surface_step_leaves`).
    if let (Some(ma), Some(mb)) = (a.m_end, b.m_start) {
        let dm = path::norm(sub(mb, ma));
        if dm > 1e-9 {
            let room = 0.5 * tool_acc(a).min(tool_acc(b));
            v = v.min(acc * period_s / dm).min(room * period_s / dm);
        }
    }
    // The tool point's acceleration step across the junction at the contact speed `v`,
    // `v²·|m2_b − m2_a|` in one period, within half of the jerk the two blocks' profiles
    // may use along the tool point's path (the other half they keep:
    // `surface_step_leaves`) and half of the weakest axis's share. It holds the
    // tangential part too: where the surface's curvature changes at a different rate on
    // the two sides (every knot of a cubic), the ratio of the tool point's speed to the
    // contact speed turns at a different rate. Without it the T-spline example
    // (`examples/tspline-bump.stp`) crossed the knot line over its bump at 5.1 times the
    // jerk limit.
    if let Some(step) = surface_jerk_step(a, b) {
        let weakest = machine
            .axes
            .as_array()
            .iter()
            .fold(f64::INFINITY, |m, x| m.min(x.max_jerk_mm_per_s3));
        let room = 0.5
            * tool_jerk(a)
                .min(tool_jerk(b))
                .min((1.0 - NORMAL_SHARE) * weakest);
        v = v.min((room * period_s / (SAMPLED_STEP * step)).sqrt());
    }
    let dk = at.dk;
    if is_jump(dk) {
        match at.load {
            // The acceleration's step with the normal jerk there takes at most
            // `JUMP_SHARE` of the path's jerk and of each axis's; the profiles beside it
            // keep what it leaves (`junction_leaves`). (It was also held to what the
            // blocks' profiles had left of the jerk at their caps, counting their share
            // twice: LinuxCNC's quadratic butterfly at F6000 passed its knots at 10 mm/s
            // instead of 15, 15.295 s against 14.284 s on the built-in machine.)
            Some(load) => v = load.jerk_speed(v, &fixed.jerk, JUMP_SHARE),
            // Between surface blocks, within what their profiles leave.
            None => v = v.min((jerk * period_s / (SAMPLED_STEP * dk)).sqrt() / r),
        }
    }
    (v, kink)
}

/// What a junction's speed and what it leaves the blocks are worked out from, each once.
struct Junction<'a> {
    /// `T_a·T_b`, the cosine of the tangent's turn.
    cos: f64,
    /// [`half_turn_sin`].
    half_sin: f64,
    /// [`curvature_jump`].
    dk: f64,
    /// The junction's [`Load`] between curves (not surface blocks) that kink or jump,
    /// unless the turn is a corner (an exact stop, which takes nothing).
    load: Option<&'a Load>,
}

impl<'a> Junction<'a> {
    /// The junction between `a` and `b`; its load, if any, is written into `load`.
    fn of(
        a: &Shape,
        b: &Shape,
        fixed: &PlanLimits,
        period_s: f64,
        load: &'a mut Load,
    ) -> Junction<'a> {
        let cos = dot(a.t_end, b.t_start).clamp(-1.0, 1.0);
        let half_sin = half_turn_sin(cos);
        let dk = curvature_jump(a, b);
        let curves = a.surface_ratio.is_none() && b.surface_ratio.is_none();
        let loaded = cos >= fixed.corner_cos && curves && (is_kink(half_sin) || is_jump(dk));
        if loaded {
            load.fill(a, b, period_s);
        }
        Junction {
            cos,
            half_sin,
            dk,
            load: loaded.then_some(&*load),
        }
    }
}

/// What [`plan`] takes from the machine for every junction, worked out once.
struct PlanLimits {
    /// The cosine of the machine's corner angle: a sharper turn stops.
    corner_cos: f64,
    /// [`limits_of`] the machine.
    acc: [f64; 4],
    jerk: [f64; 4],
    /// The least of `acc`.
    weakest_acc: f64,
}

impl PlanLimits {
    fn new(machine: &Machine) -> Self {
        let (acc, jerk) = limits_of(machine);
        PlanLimits {
            corner_cos: machine.corner_angle_deg.to_radians().cos(),
            acc,
            jerk,
            weakest_acc: acc.iter().fold(f64::INFINITY, |m, x| m.min(*x)),
        }
    }
}

/// `sin(θ/2)` of the turn `θ` of the tangent at the junction between `a` and `b`.
/// from its cosine `cos`, `T_a·T_b` clamped to [-1, 1].
fn half_turn_sin(cos: f64) -> f64 {
    (0.5 * (1.0 - cos)).max(0.0).sqrt()
}

/// Does a turn of this `sin(θ/2)` make the junction a kink?
fn is_kink(half_sin: f64) -> bool {
    half_sin > 1e-7
}

/// The jump of the curvature vector at the junction between `a` and `b` (1/mm).
fn curvature_jump(a: &Shape, b: &Shape) -> f64 {
    path::norm(sub(a.k_end, b.k_start))
}

/// The most a step `Δa` of the acceleration moves the set-points' jerk, in units of
/// `Δa/T`. A set-point's second difference over the period `T` is the acceleration
/// averaged under a triangle of width `2·T` about it, so a step at `τ` enters two
/// neighbouring averages by the triangle's masses after `τ`: their difference, the
/// third difference, is largest for a step halfway between set-points, `7/8 − 1/8`.
/// (A curvature jump `Δk` passed at `v` is a step `v²·Δk` of the normal acceleration.)
const SAMPLED_STEP: f64 = 0.75;

/// Does a curvature jump this large count as one?
fn is_jump(dk: f64) -> bool {
    dk > 1e-9
}

/// Share of the path's (and each axis's) acceleration a kink's direction change in one
/// period may take, with the normal acceleration of the curves at the junction; the
/// profile of the two blocks keeps what that leaves at the junction speed: along the
/// path at least `sqrt(1 − share²)` of it (the direction change is normal to the path,
/// so the two add as a right angle), and on each axis what the step leaves of its own.
const KINK_SHARE: f64 = 0.9;
/// The same for a jump in curvature (a degree-2 curve's knot, a line meeting an arc):
/// the share of the jerk the acceleration's step in one period may take, with the
/// normal jerk of the curves there.
const JUMP_SHARE: f64 = 0.8;

/// Where [`Load`]'s figures and the machine's limits are kept together: one per axis,
/// then the path's.
const PATH: usize = 3;

/// The machine's acceleration and jerk limits, each axis's then the path's.
fn limits_of(machine: &Machine) -> ([f64; 4], [f64; 4]) {
    let ax = machine.axes.as_array();
    (
        [
            ax[0].max_acc_mm_per_s2,
            ax[1].max_acc_mm_per_s2,
            ax[2].max_acc_mm_per_s2,
            machine.path_acc_mm_per_s2,
        ],
        [
            ax[0].max_jerk_mm_per_s3,
            ax[1].max_jerk_mm_per_s3,
            ax[2].max_jerk_mm_per_s3,
            machine.path_jerk_mm_per_s3,
        ],
    )
}

/// What a junction between two curves puts on the set-points besides the profile along
/// the path, as a function of the speed `v` it is passed at, on each axis and along the
/// path (index [`PATH`]: lengths of the vectors): the acceleration normal to the path (a
/// kink's velocity step in one period, `v·(T_b − T_a)/T`, and the curvature's `v²·k`),
/// and the jerk normal to it (a curvature jump's step in one period, `v²·Δk/T`, and the
/// curvature's `3·v·a_t·k + v³·dk/ds`). All grow with `v`. Per axis the larger of the
/// two blocks' figures is taken.
#[derive(Debug, Clone, Copy)]
struct Load {
    /// `|T_b − T_a|/T`.
    turn: [f64; 4],
    kappa: [f64; 4],
    /// `|k_b − k_a|/T`.
    jump: [f64; 4],
    /// `3·a_t·|k|`.
    acc_kappa3: [f64; 4],
    dk: [f64; 4],
}

impl Load {
    const ZERO: Load = Load {
        turn: [0.0; 4],
        kappa: [0.0; 4],
        jump: [0.0; 4],
        acc_kappa3: [0.0; 4],
        dk: [0.0; 4],
    };

    fn of(a: &Shape, b: &Shape, period_s: f64) -> Load {
        let mut load = Load::ZERO;
        load.fill(a, b, period_s);
        load
    }

    /// Makes this [`Load::of`] `a` and `b`, in place.
    fn fill(&mut self, a: &Shape, b: &Shape, period_s: f64) {
        let turn = sub(b.t_start, a.t_end);
        let turn = [
            turn[0].abs() / period_s,
            turn[1].abs() / period_s,
            turn[2].abs() / period_s,
            path::norm(turn) / period_s,
        ];
        // Between two lines (most junctions of most programs) every figure but the turn
        // is zero: without curvature the general form below works out `|0|`, norms of
        // zero vectors, `0/T` and `3·a·0`, each `+0` for a positive period and a finite
        // acceleration of positive sign (`-0` would make `-0`). Those zeros, without the
        // arithmetic.
        let flat = |x: [f64; 3]| x == [0.0; 3];
        let plain = |acc: f64| acc.is_sign_positive() && acc < 1e300;
        if flat(a.k_end)
            && flat(b.k_start)
            && flat(a.dk_end)
            && flat(b.dk_start)
            && plain(a.acc)
            && plain(b.acc)
            && period_s > 0.0
        {
            self.turn = turn;
            self.kappa = [0.0; 4];
            self.jump = [0.0; 4];
            self.acc_kappa3 = [0.0; 4];
            self.dk = [0.0; 4];
        } else {
            *self = Load::general(a, b, turn, period_s);
        }
    }

    /// [`Load::of`] worked out in full, `turn` given.
    fn general(a: &Shape, b: &Shape, turn: [f64; 4], period_s: f64) -> Load {
        let each = |f: &dyn Fn(usize) -> f64, whole: f64| [f(0), f(1), f(2), whole];
        let jump = sub(b.k_start, a.k_end);
        let (ka, kb) = (a.k_end, b.k_start);
        let larger = |x: [f64; 3], y: [f64; 3]| {
            each(
                &|i| x[i].abs().max(y[i].abs()),
                path::norm(x).max(path::norm(y)),
            )
        };
        let acc_kappa3 = each(
            &|i| (3.0 * a.acc * ka[i].abs()).max(3.0 * b.acc * kb[i].abs()),
            (3.0 * a.acc * path::norm(ka)).max(3.0 * b.acc * path::norm(kb)),
        );
        Load {
            turn,
            kappa: larger(ka, kb),
            jump: each(
                &|i| SAMPLED_STEP * jump[i].abs() / period_s,
                SAMPLED_STEP * path::norm(jump) / period_s,
            ),
            acc_kappa3,
            dk: larger(a.dk_end, b.dk_start),
        }
    }

    fn acc(&self, c: usize, v: f64) -> f64 {
        v * self.turn[c] + v * v * self.kappa[c]
    }

    /// The most tangential acceleration a block whose curvature vector at this
    /// junction is `k` may have without raising the load's `3·a_t·|k|` (the larger of
    /// the two blocks').
    fn acc_ceiling(&self, k: [f64; 3]) -> f64 {
        let each = [k[0].abs(), k[1].abs(), k[2].abs(), path::norm(k)];
        (0..4).fold(f64::INFINITY, |m, c| {
            if each[c] > 0.0 {
                m.min(self.acc_kappa3[c] / (3.0 * each[c]))
            } else {
                m
            }
        })
    }

    fn jerk(&self, c: usize, v: f64) -> f64 {
        v * v * self.jump[c] + v * self.acc_kappa3[c] + v * v * v * self.dk[c]
    }

    /// The highest speed up to `v` whose `acc` stays within `share` of every limit:
    /// the positive root of `κ·v² + c·v = share·limit` where a limit binds.
    fn acc_speed(&self, mut v: f64, limits: &[f64; 4], share: f64) -> f64 {
        for (c, limit) in limits.iter().enumerate() {
            let room = share * limit;
            if self.acc(c, v) > room {
                let (k, t) = (self.kappa[c], self.turn[c]);
                v = 2.0 * room / (t + (t * t + 4.0 * k * room).sqrt());
            }
        }
        v
    }

    /// The highest speed up to `v` whose `jerk` stays within `share` of every limit
    /// (bisection where one binds; `jerk` grows with `v`).
    fn jerk_speed(&self, mut v: f64, limits: &[f64; 4], share: f64) -> f64 {
        for (c, limit) in limits.iter().enumerate() {
            let room = share * limit;
            if self.jerk(c, v) > room {
                v = highest_fitting(0.0, v, 64, |x| self.jerk(c, x) <= room);
            }
        }
        v
    }
}

/// The most tangential acceleration a block's profile puts on the tool point's path:
/// its own (along the contact path) times the fastest the tool point moves for it.
fn tool_acc(s: &Shape) -> f64 {
    s.acc * s.surface_ratio.unwrap_or(1.0)
}

/// The most jerk a block's profile puts on the tool point's path.
fn tool_jerk(s: &Shape) -> f64 {
    s.jerk * s.surface_ratio.unwrap_or(1.0)
}

/// `|m2_b − m2_a|` at a junction of surface blocks (1/mm): the tool point's acceleration
/// step per squared contact speed; `None` if it is nothing, or where the tool point's
/// velocity steps there too (`|m_b − m_a|` above [`TOOL_KINK`], a surface only C¹): such
/// a kink is passed within one period's acceleration, and no finite jerk follows it.
fn surface_jerk_step(a: &Shape, b: &Shape) -> Option<f64> {
    if path::norm(sub(b.m_start?, a.m_end?)) > TOOL_KINK {
        return None;
    }
    let step = path::norm(sub(b.m2_start?, a.m2_end?));
    // (Above the differences' rounding and truncation, about 1e-8 and 1e-7 per mm.)
    (step > 1e-6).then_some(step)
}

/// A velocity step of the tool point per unit of contact speed above this counts as a
/// kink of its path ([`path::tool_rate`]'s differences are good to about 1e-6 on a
/// smooth surface; a degree-2 surface's knots step by 1e-3 and more).
const TOOL_KINK: f64 = 1e-4;

/// What the tool point's velocity step at a junction of surface blocks passed at `v`
/// (`v·|m_b − m_a|` in one period, along the tool point's path where the surface's
/// curvature jumps: the ratio of its speed to the contact speed steps) leaves the two
/// blocks' profiles: their tangential acceleration on the tool point's path less the
/// step's, so the two together stay within what [`shape`] left them. Without it a part's
/// profile accelerating at 962 mm/s² passed such a step of 315 mm/s² (1.28 times the
/// LinuxCNC machine's 1000: `seed-surface-planecc.stp`, the feed table).
fn surface_step_leaves(a: &Shape, b: &Shape, v: f64, period_s: f64) -> Option<Jerk> {
    let dm = a
        .m_end
        .zip(b.m_start)
        .map(|(ma, mb)| path::norm(sub(mb, ma)));
    let step = v * dm.unwrap_or(0.0) / period_s;
    // The acceleration step's jerk (`junction_speed`), on the tool point's path.
    let jerk_step = surface_jerk_step(a, b).map_or(0.0, |d| SAMPLED_STEP * v * v * d / period_s);
    let some = |x: f64| x > 0.0 && !x.is_nan();
    if !some(step) && !some(jerk_step) {
        return None;
    }
    let left = |s: &Shape, have: f64, taken: f64| {
        if some(taken) {
            (have - taken / s.surface_ratio.unwrap_or(1.0)).max(0.0)
        } else {
            f64::INFINITY
        }
    };
    Some(Jerk {
        acc: left(a, a.acc, step).min(left(b, b.acc, step)),
        jerk: left(a, a.jerk, jerk_step).min(left(b, b.jerk, jerk_step)),
    })
}

/// The tangential acceleration and jerk the profiles of the two blocks at a junction
/// between curves may keep, passed at `v`: what [`Load`] leaves of the path's limits
/// (`sqrt(A² − acc²)`, `sqrt(J² − jerk²)`) and of each axis's (`(A_i − acc_i)/|t_i|`,
/// with `t` the larger of the two tangents' components there); `None` where nothing is
/// taken (a smooth junction). Between surface blocks, [`surface_step_leaves`].
fn junction_leaves(
    a: &Shape,
    b: &Shape,
    v: f64,
    at: &Junction,
    fixed: &PlanLimits,
    period_s: f64,
) -> Option<Jerk> {
    if a.surface_ratio.is_some() || b.surface_ratio.is_some() {
        return surface_step_leaves(a, b, v, period_s);
    }
    let kinked = is_kink(at.half_sin);
    let jumps = is_jump(at.dk);
    if !(kinked || jumps) || v <= 0.0 {
        return None;
    }
    // `Junction::of` leaves the load out only at a corner (whose speed is zero: not
    // reached) and where the tangents are not numbers (a NaN cosine); then it is worked
    // out here, the same numbers it would have.
    let worked_out;
    let load = match at.load {
        Some(l) => l,
        None => {
            worked_out = Load::of(a, b, period_s);
            &worked_out
        }
    };
    let left = |limits: &[f64; 4], taken: &dyn Fn(usize) -> f64| {
        let path = (limits[PATH] * limits[PATH] - taken(PATH).powi(2))
            .max(0.0)
            .sqrt();
        (0..PATH).fold(path, |m, i| {
            let t = a.t_end[i].abs().max(b.t_start[i].abs());
            let room = (limits[i] - taken(i)).max(0.0);
            // A tangent's component is at most 1 (checked), so `room/t` is at least
            // `room`, and an `m` at or below `room` stays: no division (as in
            // `shape_straight`).
            if t > 1e-12 && !(m <= room && t <= 1.0) {
                m.min(room / t)
            } else {
                m
            }
        })
    };
    Some(Jerk {
        acc: if kinked {
            left(&fixed.acc, &|c| load.acc(c, v))
        } else {
            f64::INFINITY
        },
        jerk: if jumps {
            left(&fixed.jerk, &|c| load.jerk(c, v))
        } else {
            f64::INFINITY
        },
    })
}

/// A kink at the end of block `j`, `s` mm along the path.
#[derive(Debug, Clone, Copy)]
struct Kink {
    j: usize,
    s: f64,
    /// `sin(θ/2)` of the tangent's turn `θ` (its angle, `2·asin`, is worked out only
    /// for a run of close kinks, which few kinks are part of).
    half_sin: f64,
    /// The acceleration the direction change may take, times the period (mm/s).
    acc_t: f64,
    /// The unit tangents before and after it, where they are the path's own (not
    /// between surface blocks, whose kinks are the tool point's).
    tangents: Option<([f64; 3], [f64; 3])>,
}

impl Kink {
    /// The tangent's turn (rad).
    fn turn(&self) -> f64 {
        2.0 * self.half_sin.min(1.0).asin()
    }
}

/// Kinks closer together than two steps: one step's direction can then change by the
/// turns of several, where each junction speed allows for its own alone. The set-points'
/// acceleration over two steps is `v·2·sin(Θ/2)/T` with `Θ` at most the sum of the
/// turns within the `2·v·T` of path the two steps cover; so every run of kinks that
/// close (at the speeds planned at them) takes the speed whose direction change over
/// all their turns stays within the acceleration.
///
/// Fed the kinks in path order as the planner finds them; it keeps only the recent ones
/// a later kink may still be that close to. Each new kink closes the longest run ending
/// at it, whose speed is the lowest of all the runs ending there, and all of that run's
/// kinks take it. Conservative: runs are measured at the speeds before this lowers them.
struct CloseKinks {
    recent: std::collections::VecDeque<Kink>,
    /// The highest junction speed seen: no run is longer than two steps at it.
    v_bound: f64,
    period_s: f64,
}

impl CloseKinks {
    fn new(period_s: f64) -> Self {
        CloseKinks {
            recent: std::collections::VecDeque::new(),
            v_bound: 0.0,
            period_s,
        }
    }

    /// A stop (or anything but a kink passed at speed) between kinks: no step spans it.
    fn stop(&mut self) {
        self.recent.clear();
    }

    /// Kink `k`, its junction speed already in `end[k.j]`; lowers `end` in place. When
    /// `k` closes a run, returns the blocks the run's steps may touch (`first..=last`,
    /// the block before its first kink to the one after `k`), the acceleration its
    /// whole direction change may take (mm/s²), which their profiles must leave room for,
    /// and `2·sin(Θ/2)` of its whole turn `Θ` (that acceleration is the run's speed
    /// times this over the period).
    fn push(&mut self, k: Kink, end: &mut [f64]) -> Option<(usize, usize, f64, f64)> {
        let two_steps = 2.0 * self.period_s;
        self.v_bound = self.v_bound.max(end[k.j]);
        while self
            .recent
            .front()
            .is_some_and(|f| k.s - f.s >= two_steps * self.v_bound)
        {
            self.recent.pop_front();
        }
        let (mut acc_t, mut v_max) = (k.acc_t, end[k.j]);
        let mut first = self.recent.len();
        for (i, l) in self.recent.iter().enumerate().rev() {
            let v = v_max.max(end[l.j]);
            if k.s - l.s >= two_steps * v {
                break;
            }
            v_max = v;
            acc_t = acc_t.min(l.acc_t);
            first = i;
        }
        let mut run = None;
        if first < self.recent.len() {
            // The run's whole turn, summed from `k` back to its first kink.
            let turn = self
                .recent
                .range(first..)
                .rev()
                .fold(k.turn(), |sum, l| sum + l.turn());
            let two_sin = 2.0 * (0.5 * turn.min(std::f64::consts::PI)).sin();
            let two_sin = match spread(self.recent.range(first..).chain(std::iter::once(&k))) {
                Some(d) => two_sin.min(2.0 * d),
                None => two_sin,
            };
            let v = acc_t / two_sin;
            for l in self.recent.range(first..) {
                end[l.j] = end[l.j].min(v);
            }
            end[k.j] = end[k.j].min(v);
            run = Some((
                self.recent[first].j,
                k.j + 1,
                acc_t / self.period_s,
                two_sin,
            ));
        }
        self.recent.push_back(k);
        run
    }
}

/// How far the tangents of a run of kinks (the one before its first kink and the one
/// after each) lie from their mean at most; `None` where a kink's tangents are not the
/// path's own. Two steps' chords (the set-points' velocities times the period) are each
/// the mean of the tangents along their path, so each lies within this of that mean
/// (a ball is convex), and their directions differ by at most twice it: a bound on the
/// run's direction change beside `2·sin(Θ/2)` of its summed turns `Θ`, which it
/// undercuts where the turns alternate (CAM output rounded to a few decimals, whose
/// chords of 20 µm turn by ±0.3° of rounding around a steady 0.1°: summed, the turns made
/// a 20 mm circle at F3000 run at half the feed on LinuxCNC's limits).
fn spread<'a>(run: impl Iterator<Item = &'a Kink> + Clone) -> Option<f64> {
    // Each tangent of the run, in order, to `f`: the first kink's before, then every
    // kink's after.
    let tangents = |f: &mut dyn FnMut([f64; 3])| -> Option<()> {
        for (n, k) in run.clone().enumerate() {
            let (before, after) = k.tangents?;
            if n == 0 {
                f(before);
            }
            f(after);
        }
        Some(())
    };
    let (mut sum, mut n) = ([0.0; 3], 0.0);
    tangents(&mut |t| {
        sum = add(sum, t);
        n += 1.0;
    })?;
    let mean = sum.map(|x| x / n);
    let mut far = 0.0f64;
    tangents(&mut |t| far = far.max(path::norm(sub(t, mean))))?;
    Some(far)
}

/// Lowers a block's profile limits to `left` where they are higher.
fn keep_within<B: Plannable>(b: &mut B, left: Jerk) {
    let now = b.limits();
    if left.acc < now.acc || left.jerk < now.jerk {
        let limits = Jerk {
            acc: now.acc.min(left.acc),
            jerk: now.jerk.min(left.jerk),
        };
        let (length, feed) = (b.length_mm(), b.feed_mm_per_min());
        b.set_caps(length, feed, limits);
    }
}

/// A motion block's path as the planner sees it.
#[derive(Debug, Clone, Copy)]
pub enum Geometry<'a> {
    /// A straight segment (degree 1, two control points, no helix, not a surface
    /// block), by its chord.
    Straight([f64; 3]),
    /// Any other curve, or a surface block.
    Curve(&'a CommandBlock),
}

/// What the planner reads and fills in of a block, held whole ([`CommandBlock`]: a
/// surface part, a single move) or as [`build`] holds a program's ([`Block`]).
pub trait Plannable {
    fn is_motion(&self) -> bool;
    /// `FLAG_*` bits.
    fn flags(&self) -> u32;
    /// The path of a motion block.
    fn geometry(&self) -> Geometry<'_>;
    fn feed_mm_per_min(&self) -> f64;
    fn length_mm(&self) -> f64;
    /// The tangential acceleration and jerk the block's profile may use.
    fn limits(&self) -> Jerk;
    /// Sets the length, the feed cap and the profile limits.
    fn set_caps(&mut self, length_mm: f64, feed_mm_per_min: f64, limits: Jerk);
    /// Sets the planned feeds at the start and the end.
    fn set_feeds(&mut self, start_mm_per_min: f64, end_mm_per_min: f64);
    /// Planned start and end speed and cap (mm/s).
    fn planned_mm_s(&self) -> (f64, f64, f64);
    /// A straight block split at the share `t` (strictly between 0 and 1) of its
    /// length into two that join exactly, the second keeping the stop flag; `None` for
    /// anything else, which is not split.
    fn split_straight(&self, t: f64) -> Option<(Self, Self)>
    where
        Self: Sized;
}

/// Plans one motion block standing alone (from rest to rest) at `feed` mm/min.
pub fn plan_alone(b: &mut CommandBlock, machine: &Machine, feed: f64) {
    b.feed_mm_per_min = feed;
    let mut one = vec![*b];
    plan(&mut one, machine, 1_000_000);
    *b = one[0];
}

/// Fills in lengths, feed caps, profile limits and start/end speeds of every motion
/// block: a look-ahead over all of `blocks` (a window of the program, ending at rest,
/// see [`crate::window`]). Junction speeds (lowered where kinks are closer than two steps, see
/// [`CloseKinks`]), then a backward pass with the jerk-limited distances of
/// [`shared::profile`], make every block able to slow to its end speed; the
/// interpolator accelerates as its limits allow by itself (no forward pass).
pub fn plan<B: Plannable>(blocks: &mut Vec<B>, machine: &Machine, period_ns: u64) {
    plan_and(blocks, machine, period_ns, |_, _| {});
}

/// [`plan`], handing every block to `done` (with its index) once it is final. What looks
/// at every planned block (`cnc check` validates them) then finds it still in the
/// cache, instead of going over the whole list again.
///
/// A program with curves is planned in rounds, each relaxed ([`relax`]) and timed
/// ([`times`]) as the interpolator will run it: first with half of each limit for the
/// curvature; then, up to [`SHARE_ROUNDS`] times, with [`shares`]' larger share for the
/// curve blocks whose speed now reaches their cap. A curve (each run of curve blocks,
/// with the block before it) keeps a round's larger shares only where its blocks take
/// less time with them (but a chain of blends, [`chain_of_blends`]); a curve that did
/// not keeps half from then on.
pub fn plan_and<B: Plannable>(
    blocks: &mut Vec<B>,
    machine: &Machine,
    period_ns: u64,
    mut done: impl FnMut(usize, &B),
) {
    split_at_kinks(blocks, machine, period_ns);
    if !blocks.iter().any(is_curve) {
        let mut none = PlanCache::new(0);
        plan_split(
            blocks,
            machine,
            period_ns,
            &|_| NORMAL_SHARE,
            &mut [],
            &mut none,
            done,
        );
        return;
    }
    // Each round plans from the programmed feeds.
    let feeds: Vec<f64> = blocks.iter().map(|b| b.feed_mm_per_min()).collect();
    let mut memo = vec![None; blocks.len()];
    let mut brakes = vec![None; blocks.len()];
    let mut last_ceiling = Vec::new();
    let mut cache = PlanCache::new(blocks.len());
    let mut round = |blocks: &mut Vec<B>, shares: &[f64]| {
        for (b, f) in blocks.iter_mut().zip(&feeds) {
            if b.is_motion() {
                let (length, limits) = (b.length_mm(), b.limits());
                b.set_caps(length, *f, limits);
            }
        }
        let ceiling = plan_split(
            blocks,
            machine,
            period_ns,
            &|i| shares[i],
            &mut brakes,
            &mut cache,
            |_, _| {},
        );
        relax(blocks, machine, &ceiling, &mut memo, &mut cache, false);
        last_ceiling = ceiling;
        times(blocks)
    };
    let mut shares = vec![NORMAL_SHARE; blocks.len()];
    let mut before = round(blocks, &shares);
    // The curves that were slower with the larger share.
    let mut frozen = vec![false; blocks.len()];
    for _ in 0..SHARE_ROUNDS {
        let mut trial = shares.clone();
        let mut promoted = false;
        for ((t, larger), f) in trial.iter_mut().zip(self::shares(blocks)).zip(&frozen) {
            if larger > *t && !f {
                *t = larger;
                promoted = true;
            }
        }
        if !promoted {
            break;
        }
        let after = round(blocks, &trial);
        let mut kept = true;
        for (first, end) in curve_runs(blocks) {
            let from = first.saturating_sub(1);
            let (t0, t1): (f64, f64) = (
                before[from..end].iter().sum(),
                after[from..end].iter().sum(),
            );
            if t1 > t0
                && trial[first..end] != shares[first..end]
                && !chain_of_blends(&blocks[first..end])
            {
                trial[first..end].copy_from_slice(&shares[first..end]);
                frozen[first..end].fill(true);
                kept = false;
            }
        }
        shares = trial;
        before = if kept { after } else { round(blocks, &shares) };
    }
    // The jerk once, on the plan kept (but for the blocks braking by their jerk, which
    // `braking_relaxed` gives theirs in every round): in every round it doubled the
    // planning's cost (nearly every curve block sampled again each round) for the same
    // plan; once, it
    // costs a third more on curves (`cnc check` on 480 lines of the bench's `curves`,
    // 866 M -> 1152 M instructions). Held to blocks that cannot reach their cap, or to
    // a tenfold negligible gain, it saved a twentieth of that and lost a third of the
    // gain (the butterfly at F6000 on the built-in machine 13.888 -> 13.945 / 13.914 s).
    // (The rounds' relaxations are kept in `memo` with what each was found from, so a
    // block relaxed the same in the round kept is not worked out again.)
    relax(blocks, machine, &last_ceiling, &mut memo, &mut cache, true);
    // (Last to first, as the backward pass hands them over.)
    for (i, b) in blocks.iter().enumerate().rev() {
        done(i, b);
    }
}

/// The most a block's limits `lim` may be raised to: what the junctions' loads leave it
/// (`ceiling`) and the machine's path limits allow, never below `lim` itself.
fn raised_within(lim: Jerk, ceiling: Jerk, machine: &Machine) -> Jerk {
    Jerk {
        acc: ceiling
            .acc
            .min(machine.path_acc_mm_per_s2.max(lim.acc))
            .max(lim.acc),
        jerk: ceiling
            .jerk
            .min(machine.path_jerk_mm_per_s3.max(lim.jerk))
            .max(lim.jerk),
    }
}

/// A block's relaxed limits and the figures they were found from (see [`relax`]).
type RelaxMemo = ([u64; 7], Jerk);

/// Whether a curve run is two or more `G64 P` blends in a row (the lines between them
/// used up, [`blend::is_blend_shape`]), whose larger share [`plan_and`] keeps without
/// judging it by the modelled times ([`times`]). That model makes every block start and
/// end without acceleration; on such a chain, each blend a millimetre or less and given
/// a twentieth of the jerk at the larger share, it leaves the speed almost no change
/// within a block, where the interpolator carries its acceleration across the
/// junctions. Measured on the final plans of the built-in machine: 600 lines turning
/// 3–10° under `P0.01` modelled at 27.865 s and stepped in 24.290 s; with the chains'
/// larger share kept, modelled at 31.695 s and stepped in 21.977 s, the model pointing
/// the wrong way. A single blend between two lines stays judged: there the line before
/// it, braking under the blend's jerk, is what the larger share costs, and the model
/// sees it (a sine polyline under a bare `G64`, every blend's share kept: 15.045 ->
/// 15.247 s). Kept for chains only: the generated programs' 3–10° turns −3.3 % on the
/// built-in machine, −0.7 to −3.6 % on LinuxCNC's limits, none slower but one by 5 ms of
/// 12.1 s (BENCHMARKS.md).
fn chain_of_blends<B: Plannable>(run: &[B]) -> bool {
    run.len() >= 2
        && run.iter().all(|b| match b.geometry() {
            Geometry::Curve(c) => {
                let (n, p) = (c.n_ctrl as usize, c.degree as usize);
                match (c.ctrl.get(..n), c.knots.get(..n + p + 1)) {
                    (Some(ctrl), Some(knots)) => blend::is_blend_shape(p, knots, ctrl),
                    _ => false,
                }
            }
            Geometry::Straight(_) => false,
        })
}

/// Most planning rounds of [`plan_and`] that give the curve blocks reaching their cap
/// the larger share. (One until the rounds were judged on relaxed plans: a second then
/// made LinuxCNC's butterfly at F6000 11.124 -> 11.074 s on LinuxCNC's limits, 10 000
/// lines of curves 823.406 -> 822.209 s; a third changed nothing.)
const SHARE_ROUNDS: usize = 2;

/// Each run of consecutive curve blocks ([`is_curve`]) as `(first, end)`, one past its
/// last, and each other block on its own.
fn curve_runs<B: Plannable>(blocks: &[B]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < blocks.len() {
        let end = (i..blocks.len())
            .find(|&k| !blocks.get(k).is_some_and(is_curve))
            .unwrap_or(blocks.len())
            .max(i + 1);
        out.push((i, end));
        i = end;
    }
    out
}

/// A block whose time the relaxation could cut by less than this (s) keeps its
/// acceleration.
const RELAX_NEGLIGIBLE_S: f64 = 1e-5;

/// Each curve block's acceleration (and, with `jerk`, its jerk) raised to what its
/// planned speeds leave ([`relaxed_limits`]): the planned speeds stay as they are
/// (junction limits the interpolator never exceeds), the profile between them gets
/// there sooner. Skipped where [`block_time`] says it could gain less than
/// [`RELAX_NEGLIGIBLE_S`] (a block held at its cap at both ends gains nothing). Never
/// above `ceiling`, the most a junction's load leaves each block
/// ([`plan_split`]): what a kink's direction change leaves, and at a curvature jump the
/// acceleration whose `3·a_t·|k|` stays within the load the junction speed was worked
/// out with ([`Load::acc_ceiling`]).
///
/// `memo` keeps each block's last relaxation with what it was found from (its planned
/// speeds, limits and ceiling): a later round that plans a block the same takes it
/// from there instead of sampling the curve again.
fn relax<B: Plannable>(
    blocks: &mut [B],
    machine: &Machine,
    ceiling: &[Jerk],
    memo: &mut [Option<RelaxMemo>],
    cache: &mut PlanCache,
    jerk: bool,
) {
    for (i, ((b, &ceiling), memo)) in blocks.iter_mut().zip(ceiling).zip(memo).enumerate() {
        if !is_curve(b) {
            continue;
        }
        let Geometry::Curve(c) = b.geometry() else {
            continue;
        };
        let (start, end, cap) = b.planned_mm_s();
        let (lim, len) = (b.limits(), b.length_mm());
        // The most the ceiling and the machine allow (the jerk only where asked); not
        // where that is no more, or gains too little for the samples' cost.
        let most = raised_within(lim, ceiling, machine);
        let most = Jerk {
            jerk: if jerk { most.jerk } else { lim.jerk },
            ..most
        };
        if most == lim {
            continue;
        }
        if block_time(lim, start, end, cap, len) - block_time(most, start, end, cap, len)
            < RELAX_NEGLIGIBLE_S
        {
            continue;
        }
        let key = [
            start,
            end,
            cap,
            lim.acc,
            lim.jerk,
            ceiling.acc,
            ceiling.jerk,
        ]
        .map(f64::to_bits);
        let relaxed = match memo {
            Some((k, relaxed)) if *k == key => *relaxed,
            _ => {
                let relaxed = relaxed_at(
                    &cache.samples(i, c).figures,
                    machine,
                    cap,
                    lim,
                    (start, end),
                    len,
                    ceiling,
                );
                *memo = Some((key, relaxed));
                relaxed
            }
        };
        let relaxed = Jerk {
            jerk: if jerk { relaxed.jerk } else { lim.jerk },
            ..relaxed
        };
        if relaxed.acc > lim.acc || relaxed.jerk > lim.jerk {
            let feed = b.feed_mm_per_min();
            b.set_caps(len, feed, relaxed);
        }
    }
}

/// Each block's time along its planned profile (zero for anything else): from its start
/// speed up to the highest it reaches within its feed, and down to its end speed, as
/// quickly as its limits allow, the braking under the lower jerk of its own and the
/// next block's. That is how the interpolator brakes for a block's end
/// (`interpolator::engine`, `Ahead::easing`): a curve given [`VALLEY_SHARE`] leaves
/// its profile a twentieth of the jerk, and the line before it brakes under that
/// twentieth. (Measured against each block under its own limits, the peers and the
/// examples plan the same but for the CAM circle, 1.774 -> 1.776 s on the built-in
/// machine: the model is kept for being the engine's, not for a gain.)
fn times<B: Plannable>(blocks: &[B]) -> Vec<f64> {
    blocks
        .iter()
        .enumerate()
        .map(|(k, b)| {
            if !b.is_motion() {
                return 0.0;
            }
            let (start, end, cap) = b.planned_mm_s();
            let lim = b.limits();
            let down = match blocks.get(k + 1) {
                Some(n) if n.is_motion() => Jerk {
                    jerk: lim.jerk.min(n.limits().jerk),
                    ..lim
                },
                _ => lim,
            };
            block_time_braking(lim, down, start, end, cap, b.length_mm())
        })
        .collect()
}

/// Time (s) to cover `len` mm from `start` to `end` mm/s within the speed `cap`, the
/// quickest under `lim`: up to the highest speed the length allows, held there, down.
fn block_time(lim: Jerk, start: f64, end: f64, cap: f64, len: f64) -> f64 {
    block_time_braking(lim, lim, start, end, cap, len)
}

/// [`block_time`] with the braking to `end` under `down`.
fn block_time_braking(lim: Jerk, down: Jerk, start: f64, end: f64, cap: f64, len: f64) -> f64 {
    if len.is_nan() || len <= 0.0 {
        return 0.0;
    }
    let fits = |v: f64| lim.change_distance(start, v) + down.change_distance(v, end) <= len;
    let floor = start.max(end);
    let peak = if fits(cap) {
        cap
    } else {
        highest_fitting(floor, cap.max(floor), 40, fits)
    };
    let ramps = lim.change_distance(start, peak) + down.change_distance(peak, end);
    let held = (len - ramps).max(0.0);
    let t_ramps = lim.change_time((peak - start).abs()) + down.change_time((peak - end).abs());
    if peak > 0.0 {
        t_ramps + held / peak
    } else {
        t_ramps
    }
}

/// The share the curvature may take in a curve's blocks whose planned speed reaches
/// their cap (see [`shares`]). (0.9 until the relaxation of each block's acceleration
/// to what its speeds leave, [`relax`], gave the profile back what a larger share takes
/// from it at the cap: 0.95 then made LinuxCNC's butterfly at F6000 11.134 -> 11.123 s
/// and 10 000 lines of curves 825.902 -> 823.406 s on LinuxCNC's limits, every other
/// row of the feed table the same; 0.98 made the butterfly 11.360 s.)
const VALLEY_SHARE: f64 = 0.95;

/// A block the share rounds of [`plan_and`] and [`relax`] work on: a motion along a
/// curve (arcs, NURBS and `G64` blends), not a surface block. (Blends were left out
/// until [`shape`] bisected its last step down; with them the CAM examples on the
/// built-in machine went circle 1.994 -> 1.776 s, polygon 7.182 -> 6.404 s.)
fn is_curve<B: Plannable>(b: &B) -> bool {
    b.is_motion() && matches!(b.geometry(), Geometry::Curve(c) if !c.is_surface())
}

/// The share of each block's acceleration and jerk the curvature may take in the next
/// planning round: [`VALLEY_SHARE`] in a curve's blocks whose speed, as planned in the
/// round before (half in the first), reaches their cap (the bottom of a valley of the
/// speed, or a stretch held at it: there the cap, not the profile's own budget, is what
/// binds), half elsewhere. The
/// curvature's larger share raises those caps; the profile's smaller one is little
/// used where the speed is held. Whether it pays is judged per curve by the planned
/// times ([`plan_and`]): on a machine whose jerk is low next to its acceleration the
/// climb in and out of a valley under a twentieth of the jerk costs more than the higher cap
/// gains (built-in machine, butterfly at F6000: 15.4 s against 16.9 s), on one whose jerk
/// is high it gains (LinuxCNC's limits: 12.07 s down to 11.25 s).
fn shares<B: Plannable>(blocks: &[B]) -> Vec<f64> {
    let n = blocks.len();
    let mut out = vec![NORMAL_SHARE; n];
    let mut reached = 0.0f64;
    for (i, b) in blocks.iter().enumerate() {
        if !b.is_motion() {
            reached = 0.0;
            continue;
        }
        let (start, end, c) = b.planned_mm_s();
        let (lim, len) = (b.limits(), b.length_mm());
        let from = start.min(reached);
        let peak = lim
            .reachable_speed(from, len)
            .min(lim.reachable_speed(end, len))
            .min(c);
        reached = end.min(lim.reachable_speed(from, len));
        if b.flags() & FLAG_STOP_AT_END != 0 {
            reached = 0.0;
        }
        if !is_curve(b) || c.is_nan() || c <= 0.0 {
            continue;
        }
        if peak >= c * (1.0 - 1e-3) {
            out[i] = VALLEY_SHARE;
        }
    }
    out
}

/// Straight blocks split next to their kinks: a kink's direction change in one period
/// takes most of the acceleration there (see [`junction_leaves`]), and the blocks on
/// either side keep only what it leaves, each along its whole length. So a straight
/// block much longer than the path a kink's steps can reach gives that stretch a block
/// of its own: `KINK_STEPS` steps at the highest speed the kink can be passed at (its
/// direction change within the weakest axis's acceleration), plus the path covered at
/// that speed while the interpolator eases a full path acceleration down under the
/// weakest jerk; the rest of the block keeps its full limits. The pieces lie exactly on
/// the line (the point between them is worked out once and is the end of one and the
/// start of the other).
fn split_at_kinks<B: Plannable>(blocks: &mut Vec<B>, machine: &Machine, period_ns: u64) {
    const KINK_STEPS: f64 = 4.0;
    let period_s = period_ns as f64 * 1e-9;
    let fixed = PlanLimits::new(machine);
    // The time the interpolator may take to ease a full acceleration down to what a kink
    // leaves: at most the path's acceleration, at the lowest jerk a line can have.
    let weakest_jerk = fixed.jerk.iter().fold(f64::INFINITY, |m, x| m.min(*x));
    let ease = fixed.acc[PATH] / weakest_jerk;
    let n = blocks.len();
    // The stretch to split off at each block's start and end (0: none).
    let mut head = vec![0.0f64; n];
    let mut tail = vec![0.0f64; n];
    let chord = |b: &B| match b.geometry() {
        Geometry::Straight(d) if b.is_motion() => Some(d),
        _ => None,
    };
    for i in 1..n {
        let (a, b) = (&blocks[i - 1], &blocks[i]);
        let (Some(da), Some(db)) = (chord(a), chord(b)) else {
            continue;
        };
        if (a.flags() ^ b.flags()) & FLAG_RAPID != 0 || a.flags() & FLAG_STOP_AT_END != 0 {
            continue;
        }
        let (la, lb) = (path::norm(da), path::norm(db));
        if !(la > 0.0 && lb > 0.0) {
            continue;
        }
        let cos = (dot(da, db) / (la * lb)).clamp(-1.0, 1.0);
        let half_sin = half_turn_sin(cos);
        if cos < fixed.corner_cos || !is_kink(half_sin) {
            continue;
        }
        let v = (fixed.weakest_acc * period_s / (2.0 * half_sin))
            .min(a.feed_mm_per_min() / 60.0)
            .min(b.feed_mm_per_min() / 60.0);
        let stretch = v * (KINK_STEPS * period_s + ease);
        if la > 4.0 * stretch {
            tail[i - 1] = stretch;
        }
        if lb > 4.0 * stretch {
            head[i] = stretch;
        }
    }
    if head.iter().chain(&tail).all(|x| *x == 0.0) {
        return;
    }
    let old = std::mem::take(blocks);
    blocks.reserve(old.len() + old.len() / 2);
    for (i, b) in old.into_iter().enumerate() {
        let len = chord(&b).map_or(0.0, path::norm);
        let mut rest = b;
        if head[i] > 0.0 {
            if let Some((h, r)) = rest.split_straight(head[i] / len) {
                blocks.push(h);
                rest = r;
            }
        }
        if tail[i] > 0.0 {
            let left = len - head[i];
            if let Some((r, t)) = rest.split_straight((left - tail[i]) / left) {
                blocks.push(r);
                rest = t;
            }
        }
        blocks.push(rest);
    }
}

/// [`plan_and`] once the blocks are split at their kinks; returns the most acceleration
/// and jerk the junctions' loads leave each block (for [`relax`]).
fn plan_split<B: Plannable>(
    blocks: &mut [B],
    machine: &Machine,
    period_ns: u64,
    share: &dyn Fn(usize) -> f64,
    memo: &mut [Option<BrakeMemo>],
    cache: &mut PlanCache,
    done: impl FnMut(usize, &B),
) -> Vec<Jerk> {
    let period_s = period_ns as f64 * 1e-9;
    let n = blocks.len();
    // Junction speed limits (mm/s) at the end of each block, each found as soon as the
    // block after it has its shape (a junction needs only its two blocks').
    let mut end = crate::pages::filled(n, 0.0f64);
    // The most acceleration and jerk a junction's load leaves each block (see [`relax`]).
    let mut ceiling = crate::pages::filled(
        n,
        Jerk {
            acc: f64::INFINITY,
            jerk: f64::INFINITY,
        },
    );
    // The shapes of the block before and of this one (where they are motions), taking
    // turns (`i % 2`), each worked out where it stays: a shape is 312 bytes, and making
    // one and handing it on were copies a block.
    let mut shapes = [Shape::NONE; 2];
    let mut shaped = [false; 2];
    let mut close = CloseKinks::new(period_s);
    let mut s = 0.0f64;
    let straight_limits = StraightLimits::new(machine);
    let fixed = PlanLimits::new(machine);
    // A junction's load, worked out where it stays (160 bytes) when it has one.
    let mut load = Load::ZERO;
    for i in 0..n {
        let b = &mut blocks[i];
        shaped[i % 2] = b.is_motion();
        if shaped[i % 2] {
            let shp = &mut shapes[i % 2];
            let feed = b.feed_mm_per_min();
            let g = b.geometry();
            let length = match g {
                Geometry::Straight(d) => path::norm(d),
                Geometry::Curve(c) => cache.length(i, c),
            };
            let fast = match (g, &straight_limits) {
                (Geometry::Straight(d), Some(lim)) => {
                    shape_straight_into(d, length, lim, feed / 60.0, shp)
                }
                _ => false,
            };
            if !fast {
                *shp = cache.shape(i, g, machine, period_s, feed / 60.0, share(i));
            }
            let limits = Jerk {
                acc: shp.acc,
                jerk: shp.jerk,
            };
            b.set_caps(length, feed.min(shp.v_cap * 60.0), limits);
            s += length;
        }
        if let Some(j) = i.checked_sub(1) {
            if shaped[j % 2] && shaped[i % 2] {
                let (sa, sb) = (&shapes[j % 2], &shapes[i % 2]);
                let (b, nb) = (&blocks[j], &blocks[i]);
                let rapid_change = (b.flags() ^ nb.flags()) & FLAG_RAPID != 0;
                let stop = b.flags() & FLAG_STOP_AT_END != 0;
                if !(rapid_change || stop) {
                    let at = Junction::of(sa, sb, &fixed, period_s, &mut load);
                    let (v, kink) = junction_speed(sa, sb, &at, machine, &fixed, period_s);
                    end[j] = v
                        .min(b.feed_mm_per_min() / 60.0)
                        .min(nb.feed_mm_per_min() / 60.0);
                    // What the junction takes at that speed, the blocks' profiles leave.
                    if let Some(left) = junction_leaves(sa, sb, end[j], &at, &fixed, period_s) {
                        keep_within(&mut blocks[j], left);
                        keep_within(&mut blocks[i], left);
                        let (ka, kb) = (sa.k_end, sb.k_start);
                        let (ca, cb) = match at.load {
                            Some(load) if is_jump(at.dk) => {
                                (load.acc_ceiling(ka), load.acc_ceiling(kb))
                            }
                            Some(_) => (f64::INFINITY, f64::INFINITY),
                            // (Worked out in `junction_leaves`: kept as they are.)
                            None => (blocks[j].limits().acc, blocks[i].limits().acc),
                        };
                        for (x, k) in [(j, ca), (i, cb)] {
                            let c = &mut ceiling[x];
                            c.acc = c.acc.min(left.acc).min(k);
                            c.jerk = c.jerk.min(left.jerk);
                        }
                    }
                    if let Some(k) = kink.filter(|_| end[j] > 0.0) {
                        let at = s - blocks[i].length_mm();
                        if let Some((first, last, acc, two_sin)) =
                            close.push(Kink { j, s: at, ..k }, &mut end)
                        {
                            // The run's direction change, at most `acc` on the path and on
                            // each axis: what it leaves, whatever the tangents. `acc` is
                            // what it takes at the speed the run is held to; where the
                            // blocks it touches are capped lower (by their feed), it
                            // takes what it does at their highest cap, which no speed in
                            // them passes. (Reserved whole, a spiral of 0.08 mm chords
                            // at F3000 left exact took 9 % longer than blended on
                            // LinuxCNC's limits: its profile kept nothing to reach the
                            // feed with.) Not on surface blocks, whose caps are the
                            // contact's speed, not the tool point's.
                            let touched = &blocks[first..=last.min(i)];
                            let acc = if touched.iter().any(|b| b.flags() & FLAG_SURFACE != 0) {
                                acc
                            } else {
                                let v_hi = touched
                                    .iter()
                                    .filter(|b| b.is_motion())
                                    .map(|b| b.planned_mm_s().2)
                                    .fold(0.0f64, f64::max);
                                acc.min(v_hi * two_sin / period_s)
                            };
                            let limits = fixed.acc;
                            let path = limits[PATH];
                            let left = Jerk {
                                acc: limits[..PATH]
                                    .iter()
                                    .fold((path * path - acc * acc).max(0.0).sqrt(), |m, a| {
                                        m.min((a - acc).max(0.0))
                                    }),
                                jerk: f64::INFINITY,
                            };
                            for (b, c) in blocks[first..=last.min(i)]
                                .iter_mut()
                                .zip(&mut ceiling[first..=last.min(i)])
                            {
                                keep_within(b, left);
                                c.acc = c.acc.min(left.acc);
                            }
                        }
                    }
                }
            }
            if end[j] <= 0.0 {
                close.stop();
            }
        }
    }
    backward(blocks, &mut end, machine, &ceiling, memo, cache, done);
    ceiling
    // No forward pass: the interpolator accelerates as fast as its limits allow by
    // itself, along the whole path at once. A forward pass (each block's end speed
    // reachable from its start with zero acceleration at both) would hold it to a
    // staircase of stops in acceleration at every block end: on a chain of tiny segments
    // from rest, a crawl.
}

/// A block's [`braking_relaxed`] and the figures it was found from (its end speed, the
/// entry asked for, the entry its limits allow, its limits, the next block's, the
/// junctions' jerk ceiling and its cap): a later share round that plans a block the same
/// takes it from there instead of sampling the curve again.
type BrakeMemo = ([u64; 9], f64, Option<Jerk>);

/// What [`braking_relaxed`] works from, besides the block and the machine.
struct Braking {
    ceiling: Jerk,
    next: Option<Jerk>,
    end: f64,
    entry: f64,
    reach: f64,
}

impl Braking {
    /// [`braking_relaxed`] for `b`, taken from `memo` where it holds this block's result
    /// for the same figures (and kept there): `b` given the limits found, and its entry
    /// returned.
    fn apply<B: Plannable>(
        &self,
        b: &mut B,
        machine: &Machine,
        memo: Option<&mut Option<BrakeMemo>>,
        samples: impl FnOnce(&CommandBlock) -> Rc<Sampled>,
    ) -> f64 {
        let lim = b.limits();
        let key = [
            self.end,
            self.entry,
            self.reach,
            lim.acc,
            lim.jerk,
            self.next.map_or(-1.0, |n| n.acc),
            self.next.map_or(-1.0, |n| n.jerk),
            self.ceiling.jerk,
            b.feed_mm_per_min(),
        ]
        .map(f64::to_bits);
        let (v, given) = match memo {
            Some(Some((k, v, given))) if *k == key => (*v, *given),
            memo => {
                let found = braking_relaxed(b, machine, self, samples);
                if let Some(m) = memo {
                    *m = Some((key, found.0, found.1));
                }
                found
            }
        };
        if let Some(l) = given {
            let (len, feed) = (b.length_mm(), b.feed_mm_per_min());
            b.set_caps(len, feed, l);
        }
        v
    }
}

/// Steps of [`braking_relaxed`]'s search for the entry, each two evaluations of the
/// limits.
const BRAKING_STEPS: usize = 2;

/// An entry speed, at most `entry`, from which curve block `b` can brake to `end`
/// within its length under the jerk that the speeds up to a little above it leave (with
/// its acceleration as it is: [`Envelope::jerk_left`]), and `b` given that jerk: near
/// the highest such, after [`BRAKING_STEPS`] (the butterfly at F6000 on the built-in
/// machine 13.771 s, against 13.810 s with twelve bisections, at under half the
/// evaluations). Judged also under the lower of these limits and the next block's
/// (`next`): the interpolator brakes for each speed ahead under the lowest limits of
/// the way to it, and the next block's are the way's first.
///
/// Braking, the block runs no faster than its entry, and below its cap the curvature's
/// `v³·|dk/ds|` and `3·v·a·|k|` take less of the jerk: a block too short for its
/// braking to reach its acceleration brakes by its jerk, which [`shape`] took at the
/// cap. Returns the entry and the limits to give the block; `reach`, the entry from
/// which it can brake under its limits as they are, and none where it is not a curve
/// or gains nothing.
fn braking_relaxed<B: Plannable>(
    b: &B,
    machine: &Machine,
    brake: &Braking,
    samples: impl FnOnce(&CommandBlock) -> Rc<Sampled>,
) -> (f64, Option<Jerk>) {
    let &Braking {
        ceiling,
        next,
        end,
        entry,
        reach,
    } = brake;
    if !is_curve(b) {
        return (reach, None);
    }
    let Geometry::Curve(c) = b.geometry() else {
        return (reach, None);
    };
    let (lim, len, feed) = (b.limits(), b.length_mm(), b.feed_mm_per_min());
    let sampled = samples(c);
    if sampled.figures.is_empty() {
        return (reach, None);
    }
    let most = raised_within(lim, ceiling, machine).jerk;
    // The entry from which the limits that the speeds up to `v` leave brake to `end`
    // (with those limits): it falls as `v` rises, since the limits do.
    let from = |v: f64| {
        let env = Envelope {
            figures: &sampled.figures,
            machine,
            cap: feed / 60.0,
            ends: (v, end),
            len,
        };
        let l = Jerk {
            jerk: env.jerk_left(lim.acc).min(most).max(lim.jerk),
            ..lim
        };
        let judged = match next {
            Some(n) => Jerk {
                acc: l.acc.min(n.acc),
                jerk: l.jerk.min(n.jerk),
            },
            None => l,
        };
        (judged.reachable_speed(end, len), l)
    };
    let (at_entry, l) = from(entry);
    if at_entry >= entry {
        return (entry, Some(l));
    }
    // Towards the highest entry `v*` with `from(v*) = v*`: `from` never rises as its
    // speed does, so from above `v*` it gives an entry at or below it, and from below, at
    // or above. Taken twice a step from the last entry below, it gives another one at
    // or below `v*` (each one the block can brake from under the limits found with it,
    // which are for a speed at least as high); on the CAM circle and the butterfly two
    // steps came within rounding of twelve bisections' answer or above it.
    let (mut below, mut l) = (at_entry, l);
    for _ in 0..BRAKING_STEPS {
        let (above, _) = from(below);
        (below, l) = from(above);
    }
    if below > reach {
        (below, Some(l))
    } else {
        (reach, None)
    }
}

/// A braking for a low further on, as [`backward`] carries it back: the low (mm/s), the
/// way to it from the start of the block last passed (mm), and the limits of that way.
#[derive(Debug, Clone, Copy)]
struct Chain {
    low: f64,
    way_mm: f64,
    lim: Jerk,
}

/// The backward pass of [`plan_split`] over the junction speed limits `end` (mm/s, at
/// each block's end; overwritten with the planned speeds).
fn backward<B: Plannable>(
    blocks: &mut [B],
    end: &mut [f64],
    machine: &Machine,
    ceiling: &[Jerk],
    memo: &mut [Option<BrakeMemo>],
    cache: &mut PlanCache,
    mut done: impl FnMut(usize, &B),
) {
    let n = blocks.len();
    // The braking the block's end lies on, where it comes from further on: the low it
    // brakes for (mm/s), how far on (mm), and under what limits.
    let mut chain: Option<Chain> = None;
    // Backward pass: every block must be able to slow to its end speed. A block's end
    // speed is final once the block after it has been passed, so its feeds are set here.
    for i in (0..n).rev() {
        if !blocks[i].is_motion() {
            done(i, &blocks[i]);
            chain = None;
            continue;
        }
        let len = blocks[i].length_mm();
        let entry = if i > 0 && blocks[i - 1].is_motion() {
            end[i - 1]
        } else {
            0.0
        };
        // The braking for a low further on continues through the block (the
        // interpolator brakes for each low ahead under the lowest limits of the way to
        // it, its acceleration carried across the block ends): one braking from the
        // low, not one from rest acceleration to rest acceleration within each block,
        // which over a chain of short blocks was a crawl (the built-in machine's jerk
        // lets a 0.04 mm block at 28 mm/s change its speed by 1.5 mm/min; 40 mm of G1
        // at F3000 cut into 1000 lines took 1.56 s, against 0.87 s as one line). Not
        // where the block after has lower limits than this one: the interpolator holds
        // such a block to braking by itself (`Engine::keep_chain`), and the braking
        // starts again from this block's end, as before. Nor through a curve or into
        // the end of one: a curve's share and relaxed limits are worked out from its
        // planned speeds, and a higher end speed there left the CAM circle's blends less
        // acceleration (1.708 -> 1.716 s, built-in machine).
        let lim_i = blocks[i].limits();
        let through = chain
            .filter(|_| {
                let curve_before = i > 0 && is_curve(&blocks[i - 1]);
                // (The block after is a motion: the chain ends at anything else.)
                let next_no_lower = blocks.get(i + 1).is_some_and(|b| {
                    let l = b.limits();
                    l.acc >= lim_i.acc && l.jerk >= lim_i.jerk
                });
                !is_curve(&blocks[i]) && !curve_before && next_no_lower
            })
            .map(|c| Chain {
                way_mm: c.way_mm + len,
                lim: Jerk {
                    acc: c.lim.acc.min(lim_i.acc),
                    jerk: c.lim.jerk.min(lim_i.jerk),
                },
                ..c
            });
        let own = if entry < end[i] || (entry == end[i] && entry != 0.0) {
            entry
        } else {
            let lim = lim_i;
            let reach = lim.reachable_speed(end[i], len);
            // Where the braking reaches the block's acceleration, the jerk binds only its
            // two ends (`a/j`), and a raised jerk buys little: left as it is (relaxing
            // there moved LinuxCNC's butterfly at F6000 11.074 -> 11.163 s through the
            // interpolator's judgement under the lowest limits of the way).
            if entry <= reach || reach - end[i] >= lim.acc * lim.acc / lim.jerk {
                entry.min(reach)
            } else {
                let next = blocks
                    .get(i + 1)
                    .filter(|n| n.is_motion())
                    .map(|n| n.limits());
                let ceiling = ceiling.get(i).copied().unwrap_or(Jerk {
                    acc: f64::INFINITY,
                    jerk: f64::INFINITY,
                });
                let brake = Braking {
                    ceiling,
                    next,
                    end: end[i],
                    entry,
                    reach,
                };
                brake.apply(&mut blocks[i], machine, memo.get_mut(i), |c| {
                    cache.samples(i, c)
                })
            }
        };
        // The start the braking through allows, where that is more than the block's own
        // braking gives (its limits perhaps raised for it: `Braking`).
        let chained = through
            .map(|c| c.lim.reachable_speed(c.low, c.way_mm))
            .filter(|r| *r > own && own < entry);
        let start = chained.map_or(own, |r| entry.min(r));
        blocks[i].set_feeds(start * 60.0, end[i] * 60.0);
        done(i, &blocks[i]);
        // The braking goes on where it bound the start, or starts at this block's end
        // where the block's own braking did; none where the entry did (a lower junction
        // speed before, from which the next braking starts).
        chain = match chained {
            Some(r) if start >= r => through,
            _ if start < entry => Some(Chain {
                low: end[i],
                way_mm: len,
                lim: blocks[i].limits(),
            }),
            _ => None,
        };
        if i > 0 {
            end[i - 1] = start;
        }
    }
}

#[cfg(test)]
mod tests;
