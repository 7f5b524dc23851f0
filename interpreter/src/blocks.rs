//! From moves to command blocks: lines and arcs as exact NURBS (degree 1 and rational
//! quadratic), NURBS split exactly to block capacity, and the feed plan.
//!
//! The plan is a look-ahead over the whole program (the interpreter reads all of it before
//! any motion): each motion block gets a speed cap (programmed feed, reduced where its
//! curvature demands it by the path acceleration and the chord tolerance), corners sharper
//! than the machine's corner angle get an exact stop, and a backward then a forward pass
//! make every block's start and end speed reachable under the path acceleration.

use crate::program::{Move, Plane};
use shared::nurbs::{self, SplitCurve, MAX_CTRL};
use shared::path;
use shared::protocol::{BlockKind, CommandBlock, Helix, FLAG_RAPID};
use shared::Machine;
use std::f64::consts::{FRAC_PI_2, PI};

/// Most quadratic segments (of at most 90°) in one arc block: 2n+1 control points.
const ARC_SEGMENTS_PER_BLOCK: usize = (MAX_CTRL - 1) / 2;

fn curve_block(line: u32, c: &SplitCurve, helix: Helix, feed: f64, rapid: bool) -> CommandBlock {
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, line);
    b.degree = c.degree as u32;
    b.n_ctrl = c.ctrl.len() as u32;
    b.knots[..c.knots.len()].copy_from_slice(&c.knots);
    b.ctrl[..c.ctrl.len()].copy_from_slice(&c.ctrl);
    b.helix = helix;
    b.flags = if rapid { FLAG_RAPID } else { 0 };
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
            false,
        ));
        seg += count;
    }
    out
}

fn sweep_of(
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

/// Turns moves into unplanned command blocks (feeds are the caps, speeds not yet set).
pub fn build(moves: &[Move], machine: &Machine) -> Vec<CommandBlock> {
    let mut out = Vec::new();
    for m in moves {
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
                let c = SplitCurve {
                    degree: 1,
                    knots: vec![0.0, 0.0, 1.0, 1.0],
                    ctrl: vec![[from[0], from[1], from[2], 1.0], [to[0], to[1], to[2], 1.0]],
                };
                out.push(curve_block(*line, &c, Helix::NONE, f, *rapid));
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
                out.extend(blocks);
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
                for piece in nurbs::split_to_capacity(curve, MAX_CTRL) {
                    out.push(curve_block(*line, &piece, Helix::NONE, f, false));
                }
            }
            Move::Dwell { line, seconds } => {
                let mut b = CommandBlock::empty(BlockKind::Dwell, 0, *line);
                b.dwell_ns = (seconds * 1e9).round() as u64;
                out.push(b);
            }
            Move::End { line } => out.push(CommandBlock::empty(BlockKind::ProgramEnd, 0, *line)),
            // Carried for the planner and the reports; no block of their own yet.
            Move::PathMode { .. } | Move::Spindle { .. } | Move::Stop { .. } => {}
        }
    }
    for (i, b) in out.iter_mut().enumerate() {
        b.seq = i as u64;
    }
    out
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = path::norm(v);
    if n > 0.0 {
        v.map(|x| x / n)
    } else {
        v
    }
}

/// Highest speed (mm/s) the curvature of a block allows: centripetal acceleration within
/// the path acceleration, and the chord of one period within the chord tolerance.
fn curvature_cap(b: &CommandBlock, machine: &Machine, period_s: f64) -> f64 {
    let (u0, u1) = path::domain(b);
    let samples = 16 * b.n_ctrl.max(2) as usize;
    let mut cap = f64::INFINITY;
    for i in 0..=samples {
        let e = path::eval(b, u0 + (u1 - u0) * i as f64 / samples as f64);
        let sp = path::norm(e.d1);
        if sp < 1e-12 {
            continue;
        }
        let c = [
            e.d1[1] * e.d2[2] - e.d1[2] * e.d2[1],
            e.d1[2] * e.d2[0] - e.d1[0] * e.d2[2],
            e.d1[0] * e.d2[1] - e.d1[1] * e.d2[0],
        ];
        let kappa = path::norm(c) / sp.powi(3);
        if kappa > 1e-12 {
            let rho = 1.0 / kappa;
            let tol = machine.chord_tolerance_mm.min(rho);
            let chord = 2.0 * (tol * (2.0 * rho - tol)).sqrt();
            cap = cap
                .min((machine.path_acc_mm_per_s2 * rho).sqrt())
                .min(chord / period_s);
        }
    }
    cap
}

/// Fills in lengths, feed caps and start/end speeds of every motion block.
pub fn plan(blocks: &mut [CommandBlock], machine: &Machine, period_ns: u64) {
    let period_s = period_ns as f64 * 1e-9;
    let a = machine.path_acc_mm_per_s2;
    let cos_corner = machine.corner_angle_deg.to_radians().cos();
    let motion = |b: &CommandBlock| b.kind == BlockKind::Motion as u32;
    for b in blocks.iter_mut().filter(|b| motion(b)) {
        b.length_mm = path::length(b);
        let cap = curvature_cap(b, machine, period_s) * 60.0;
        b.feed_mm_per_min = b.feed_mm_per_min.min(cap);
    }
    // Junction speed limits (mm/s) at the end of each block.
    let n = blocks.len();
    let mut end = vec![0.0f64; n];
    for i in 0..n.saturating_sub(1) {
        let (b, nb) = (&blocks[i], &blocks[i + 1]);
        if !motion(b) || !motion(nb) {
            continue;
        }
        let (_, u1) = path::domain(b);
        let (v0, _) = path::domain(nb);
        let t_out = unit(path::eval(b, u1).d1);
        let t_in = unit(path::eval(nb, v0).d1);
        let cos = t_out[0] * t_in[0] + t_out[1] * t_in[1] + t_out[2] * t_in[2];
        let rapid_change = (b.flags ^ nb.flags) & FLAG_RAPID != 0;
        if cos >= cos_corner && !rapid_change {
            end[i] = b.feed_mm_per_min.min(nb.feed_mm_per_min) / 60.0;
        }
    }
    // Backward pass: every block must be able to slow to its end speed.
    let mut start = vec![0.0f64; n];
    for i in (0..n).rev() {
        if !motion(&blocks[i]) {
            continue;
        }
        let len = blocks[i].length_mm;
        let entry = if i > 0 && motion(&blocks[i - 1]) {
            end[i - 1]
        } else {
            0.0
        };
        start[i] = entry.min((end[i] * end[i] + 2.0 * a * len).sqrt());
        if i > 0 {
            end[i - 1] = start[i];
        }
    }
    // Forward pass: and able to reach it from its start speed.
    for i in 0..n {
        if !motion(&blocks[i]) {
            continue;
        }
        let len = blocks[i].length_mm;
        end[i] = end[i].min((start[i] * start[i] + 2.0 * a * len).sqrt());
        if i + 1 < n && motion(&blocks[i + 1]) {
            start[i + 1] = start[i + 1].min(end[i]);
        }
    }
    for (i, b) in blocks.iter_mut().enumerate() {
        if motion(b) {
            b.start_feed_mm_per_min = start[i] * 60.0;
            b.end_feed_mm_per_min = end[i] * 60.0;
        }
    }
}

#[cfg(test)]
mod tests;
