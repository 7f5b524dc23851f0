//! A planned surface workingstep as command blocks: [`SurfaceBlock`]s along the passes
//! (and, in zig-zag, the links between them), rapid line blocks for the lifts.
//!
//! A surface larger than a block's section ([`MAX_SURF_CTRL`] per direction) is split
//! exactly by knot insertion ([`split_surface`]): every column is split as a curve in `u`
//! at the same knots (then every row in `v`), so the pieces trace the very same surface
//! with the very same parameters. A pass is cut where it crosses from one piece to the
//! next; each block carries the piece its path runs on.
//!
//! Every surface block's path is one straight segment in `(u, v)` (degree 1, knots
//! `0 0 1 1`): a pass, the part of a pass on one piece, or a zig-zag link along the
//! domain boundary. The feeds are the programmed feed with start and end feed 0 (a stop
//! at every block end) until the look-ahead learns surface blocks; `length_mm` is the
//! contact point's path length on the surface.
//!
//! Forward mode (and the approach and the final retract) lifts the tool: rapid lines
//! straight up along the tool axis to a safe height (5 mm above the highest tool
//! reference point `M` over the surface), across, and down.

use crate::step::{FreeformStep, PathMode, StepError};
use crate::surface_path::{eval2, SurfacePath};
use shared::nurbs::surface::{unit_normal, SurfaceData, MAX_SURF_CTRL};
use shared::nurbs::{split_to_capacity, SplitCurve};
use shared::protocol::{
    BlockKind, CommandBlock, SurfaceBlock, SurfaceSection, SurfaceTool, FLAG_RAPID,
    FLAG_STOP_AT_END,
};
use shared::Machine;

/// Clearance of the lifts above the highest tool reference point.
pub const LIFT_CLEARANCE_MM: f64 = 5.0;

/// A surface with its own storage.
#[derive(Debug, Clone, PartialEq)]
pub struct OwnedSurface {
    pub degree_u: usize,
    pub degree_v: usize,
    pub n_u: usize,
    pub n_v: usize,
    pub knots_u: Vec<f64>,
    pub knots_v: Vec<f64>,
    pub ctrl: Vec<[f64; 4]>,
}

impl OwnedSurface {
    pub fn from_data(s: &SurfaceData<'_>) -> Self {
        OwnedSurface {
            degree_u: s.degree_u,
            degree_v: s.degree_v,
            n_u: s.n_u,
            n_v: s.n_v,
            knots_u: s.knots_u.to_vec(),
            knots_v: s.knots_v.to_vec(),
            ctrl: s.ctrl.to_vec(),
        }
    }
    pub fn data(&self) -> SurfaceData<'_> {
        SurfaceData {
            degree_u: self.degree_u,
            degree_v: self.degree_v,
            knots_u: &self.knots_u,
            knots_v: &self.knots_v,
            n_u: self.n_u,
            n_v: self.n_v,
            ctrl: &self.ctrl,
        }
    }
    /// `(u0, u1, v0, v1)`.
    pub fn domain(&self) -> (f64, f64, f64, f64) {
        (
            self.knots_u[self.degree_u],
            self.knots_u[self.n_u],
            self.knots_v[self.degree_v],
            self.knots_v[self.n_v],
        )
    }
    fn transposed(&self) -> Self {
        let mut ctrl = Vec::with_capacity(self.ctrl.len());
        for j in 0..self.n_v {
            for i in 0..self.n_u {
                ctrl.push(self.ctrl[i * self.n_v + j]);
            }
        }
        OwnedSurface {
            degree_u: self.degree_v,
            degree_v: self.degree_u,
            n_u: self.n_v,
            n_v: self.n_u,
            knots_u: self.knots_v.clone(),
            knots_v: self.knots_u.clone(),
            ctrl,
        }
    }
}

/// Splits along `u` so that no piece has more than `max_ctrl` control points along `u`.
fn split_u(s: &OwnedSurface, max_ctrl: usize) -> Option<Vec<OwnedSurface>> {
    if s.n_u <= max_ctrl {
        return Some(vec![s.clone()]);
    }
    let columns: Vec<Vec<SplitCurve>> = (0..s.n_v)
        .map(|j| {
            let c = SplitCurve {
                degree: s.degree_u,
                knots: s.knots_u.clone(),
                ctrl: (0..s.n_u).map(|i| s.ctrl[i * s.n_v + j]).collect(),
            };
            split_to_capacity(c, max_ctrl)
        })
        .collect();
    let first = columns.first()?;
    // The split points depend on the knots only, so every column splits alike.
    if columns
        .iter()
        .any(|c| c.len() != first.len() || c.iter().zip(first).any(|(a, b)| a.knots != b.knots))
    {
        return None;
    }
    let mut out = Vec::with_capacity(first.len());
    for (k, piece) in first.iter().enumerate() {
        let n_u = piece.ctrl.len();
        let mut ctrl = vec![[0.0; 4]; n_u * s.n_v];
        for (j, col) in columns.iter().enumerate() {
            for (i, c) in col[k].ctrl.iter().enumerate() {
                ctrl[i * s.n_v + j] = *c;
            }
        }
        out.push(OwnedSurface {
            degree_u: s.degree_u,
            degree_v: s.degree_v,
            n_u,
            n_v: s.n_v,
            knots_u: piece.knots.clone(),
            knots_v: s.knots_v.clone(),
            ctrl,
        });
    }
    Some(out)
}

/// Splits a valid surface exactly into pieces of at most `max_ctrl` control points per
/// direction (`max_ctrl > 2·(degree + 1)`), ordered along `u` first, then `v`. `None`
/// only if the pieces of the columns disagree (an internal error).
pub fn split_surface(s: &SurfaceData<'_>, max_ctrl: usize) -> Option<Vec<OwnedSurface>> {
    let mut out = Vec::new();
    for piece in split_u(&OwnedSurface::from_data(s), max_ctrl)? {
        for t in split_u(&piece.transposed(), max_ctrl)? {
            out.push(t.transposed());
        }
    }
    Some(out)
}

/// What a surface workingstep turns into.
#[derive(Debug, Clone)]
pub enum SurfaceCommand {
    Surface(Box<SurfaceBlock>),
    /// A rapid line (lift, traverse, approach).
    Motion(Box<CommandBlock>),
}

/// A block section with its `(u0, u1, v0, v1)` domain.
type Section = (SurfaceSection, (f64, f64, f64, f64));

/// One straight `(u, v)` segment on the surface.
#[derive(Debug, Clone, Copy)]
struct Segment {
    from: (f64, f64),
    to: (f64, f64),
}

fn length_on_surface(s: &SurfaceData<'_>, seg: Segment) -> f64 {
    let (du, dv) = (seg.to.0 - seg.from.0, seg.to.1 - seg.from.1);
    // Quadrature pieces end where the segment crosses a knot.
    let (knots, a, d) = if du != 0.0 {
        (s.knots_u, seg.from.0, du)
    } else {
        (s.knots_v, seg.from.1, dv)
    };
    let mut breaks: Vec<f64> = knots.iter().map(|k| (k - a) / d).collect();
    breaks.sort_by(f64::total_cmp);
    let breaks = crate::surface_path::breaks_between(&breaks, 0.0, 1.0);
    shared::nurbs::arc_length(&breaks, 4, |t| {
        let d = eval2(s, seg.from.0 + t * du, seg.from.1 + t * dv);
        let v = [
            d.su[0] * du + d.sv[0] * dv,
            d.su[1] * du + d.sv[1] * dv,
            d.su[2] * du + d.sv[2] * dv,
        ];
        (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
    })
}

/// The tool reference point `M = P + R·n + (H − R)·z` at `(u, v)`.
pub fn tool_point(s: &SurfaceData<'_>, tool: &SurfaceTool, u: f64, v: f64) -> [f64; 3] {
    let d = eval2(s, u, v);
    let n = unit_normal(d.su, d.sv);
    let (r, h, k) = (tool.radius_mm, tool.length_mm, tool.normal_sign);
    core::array::from_fn(|x| d.p[x] + r * k * n[x] + (h - r) * tool.axis[x])
}

fn rapid(line: u32, a: [f64; 3], b: [f64; 3], machine: &Machine) -> CommandBlock {
    let mut blk = CommandBlock::empty(BlockKind::Motion, 0, line);
    blk.degree = 1;
    blk.n_ctrl = 2;
    blk.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
    blk.ctrl[0] = [a[0], a[1], a[2], 1.0];
    blk.ctrl[1] = [b[0], b[1], b[2], 1.0];
    blk.flags = FLAG_RAPID | FLAG_STOP_AT_END;
    blk.feed_mm_per_min = machine.rapid_mm_per_min;
    blk.length_mm = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2) + (b[2] - a[2]).powi(2)).sqrt();
    blk.acc_mm_per_s2 = machine.path_acc_mm_per_s2;
    blk.jerk_mm_per_s3 = machine.path_jerk_mm_per_s3;
    blk
}

/// The blocks of a planned workingstep, numbered from 0 in order (renumber when merging
/// with other blocks). Every block validates.
pub fn surface_commands(
    step: &FreeformStep,
    path: &SurfacePath,
    machine: &Machine,
) -> Result<Vec<SurfaceCommand>, StepError> {
    let fail = |message: String| StepError {
        line: step.line,
        id: Some(step.id),
        rule: "blocks",
        message,
    };
    let whole = step.surface.data();
    let pieces = split_surface(&whole, MAX_SURF_CTRL)
        .ok_or_else(|| fail("the surface could not be split into block sections".into()))?;
    let sections: Vec<Section> = pieces
        .iter()
        .map(|p| SurfaceSection::from_data(&p.data()).map(|s| (s, p.domain())))
        .collect::<Option<_>>()
        .ok_or_else(|| fail("a surface piece exceeds the block section".into()))?;
    let tool = SurfaceTool {
        radius_mm: step.tool.radius_mm(),
        length_mm: step.tool.length_mm,
        axis: [0.0, 0.0, 1.0],
        normal_sign: path.normal_sign,
    };
    // The surface segments in order, and where the tool lifts between them.
    let mut runs: Vec<Vec<Segment>> = Vec::new();
    for (k, p) in path.passes.iter().enumerate() {
        let seg = Segment {
            from: path.uv(p.from, p.fixed),
            to: path.uv(p.to, p.fixed),
        };
        match (path.mode, runs.last_mut()) {
            (PathMode::Zigzag, Some(run)) => {
                let prev = path.passes[k - 1];
                run.push(Segment {
                    from: path.uv(prev.to, prev.fixed),
                    to: path.uv(p.from, p.fixed),
                });
                run.push(seg);
            }
            _ => runs.push(vec![seg]),
        }
    }
    // Safe height: above every tool reference point of the surface.
    let (u0, u1, v0, v1) = OwnedSurface::from_data(&whole).domain();
    let mut top = f64::NEG_INFINITY;
    for i in 0..=64 {
        for j in 0..=64 {
            let u = u0 + (u1 - u0) * i as f64 / 64.0;
            let v = v0 + (v1 - v0) * j as f64 / 64.0;
            top = top.max(tool_point(&whole, &tool, u, v)[2]);
        }
    }
    let safe_z = top + LIFT_CLEARANCE_MM;
    let line = step.line;
    let mut out = Vec::new();
    let mut last_top: Option<[f64; 3]> = None;
    for run in &runs {
        let Some(first) = run.first() else { continue };
        let m0 = tool_point(&whole, &tool, first.from.0, first.from.1);
        let above = [m0[0], m0[1], safe_z];
        if let Some(t) = last_top {
            out.push(SurfaceCommand::Motion(Box::new(rapid(
                line, t, above, machine,
            ))));
        }
        out.push(SurfaceCommand::Motion(Box::new(rapid(
            line, above, m0, machine,
        ))));
        for seg in run {
            for (sub, section) in cut_at_pieces(*seg, &sections) {
                let mut b = SurfaceBlock::empty(0, line);
                b.surface = *section;
                b.tool = tool;
                let p = &mut b.path;
                p.degree = 1;
                p.n_ctrl = 2;
                p.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
                p.ctrl[0] = [sub.from.0, sub.from.1, 0.0, 1.0];
                p.ctrl[1] = [sub.to.0, sub.to.1, 0.0, 1.0];
                p.feed_mm_per_min = step.technology.feed_mm_per_min;
                p.length_mm = length_on_surface(&whole, sub);
                p.acc_mm_per_s2 = machine.path_acc_mm_per_s2;
                p.jerk_mm_per_s3 = machine.path_jerk_mm_per_s3;
                out.push(SurfaceCommand::Surface(Box::new(b)));
            }
        }
        let end = run[run.len() - 1].to;
        let m1 = tool_point(&whole, &tool, end.0, end.1);
        let t = [m1[0], m1[1], safe_z];
        out.push(SurfaceCommand::Motion(Box::new(rapid(
            line, m1, t, machine,
        ))));
        last_top = Some(t);
    }
    for (seq, c) in out.iter_mut().enumerate() {
        let res = match c {
            SurfaceCommand::Surface(b) => {
                b.path.seq = seq as u64;
                b.validate()
            }
            SurfaceCommand::Motion(b) => {
                b.seq = seq as u64;
                b.validate().map(|_| ())
            }
        };
        res.map_err(|e| fail(format!("internal: {e}")))?;
    }
    Ok(out)
}

/// The parts of an axis-parallel segment on each piece, in the segment's direction.
fn cut_at_pieces(seg: Segment, sections: &[Section]) -> Vec<(Segment, &SurfaceSection)> {
    let along_u = seg.from.1 == seg.to.1;
    let (fixed, a, b) = if along_u {
        (seg.from.1, seg.from.0, seg.to.0)
    } else {
        (seg.from.0, seg.from.1, seg.to.1)
    };
    let (lo, hi) = (a.min(b), a.max(b));
    // The pieces the fixed parameter lies on: the first one for each range of the other.
    let mut hits: Vec<(f64, f64, &SurfaceSection)> = Vec::new();
    for (s, (u0, u1, v0, v1)) in sections {
        let (f0, f1, r0, r1) = if along_u {
            (*v0, *v1, *u0, *u1)
        } else {
            (*u0, *u1, *v0, *v1)
        };
        if fixed < f0 || fixed > f1 || r1 <= lo || r0 >= hi {
            continue;
        }
        if hits.iter().any(|h| h.0 == r0) {
            continue;
        }
        hits.push((r0.max(lo), r1.min(hi), s));
    }
    hits.sort_by(|x, y| x.0.total_cmp(&y.0));
    if b < a {
        hits.reverse();
    }
    hits.into_iter()
        .map(|(r0, r1, s)| {
            let (p, q) = if b < a { (r1, r0) } else { (r0, r1) };
            let sub = if along_u {
                Segment {
                    from: (p, fixed),
                    to: (q, fixed),
                }
            } else {
                Segment {
                    from: (fixed, p),
                    to: (fixed, q),
                }
            };
            (sub, s)
        })
        .collect()
}

#[cfg(test)]
mod tests;
