//! A planned surface workingstep as wire blocks (protocol 3, seed 000): surface blocks
//! (`FLAG_SURFACE`, one rational Bézier patch and a straight pass in its `(u, v)`)
//! along the passes and, in zig-zag, along the links between them; rapid line blocks in
//! tool-point space for the lifts; a program end.
//!
//! The surface is decomposed exactly into its Bézier patches by knot insertion to full
//! multiplicity ([`bezier_patches`]): every column is split as a curve in `u` at every
//! interior knot (then every row in `v`), so the patches trace the very same surface. A
//! pass is cut where it crosses from one patch to the next and each piece is mapped
//! affinely onto its patch's local `[0, 1]²`; the orientation is kept, so one
//! `normal_sign` serves every patch.
//!
//! Forward mode (and the approach and the final retract) lifts the tool: rapid lines
//! straight up along the tool axis to a safe height (5 mm above the highest tool
//! reference point `M` over the surface), across, and down. Every rapid starts and ends
//! exactly at the `M` the adjacent surface block gives ([`shared::path::eval`]).
//!
//! [`part_blocks`] joins every workingstep of a part from the machine's start (the
//! origin) and plans the feeds with the look-ahead of [`crate::blocks::plan`].

use crate::step::{FreeformStep, PathMode, StepError};
use crate::surface_path::SurfacePath;
use shared::nurbs::reference::piegl_tiller_surface;
use shared::nurbs::surface::SurfaceData;
use shared::nurbs::{split_to_capacity, SplitCurve, MAX_CTRL};
use shared::path;
use shared::protocol::{BlockKind, CommandBlock, FLAG_RAPID, FLAG_STOP_AT_END, FLAG_SURFACE};
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

/// Decomposes a valid surface exactly into its Bézier patches (knot insertion to full
/// multiplicity at every interior knot), ordered along `u` first, then `v`; each keeps
/// its `(u0, u1, v0, v1)` domain in the knots. `None` only if the pieces of the columns
/// disagree (an internal error).
pub fn bezier_patches(s: &SurfaceData<'_>) -> Option<Vec<OwnedSurface>> {
    let mut out = Vec::new();
    for piece in split_u(&OwnedSurface::from_data(s), s.degree_u + 1)? {
        for t in split_u(&piece.transposed(), s.degree_v + 1)? {
            out.push(t.transposed());
        }
    }
    Some(out)
}

/// One straight `(u, v)` segment on the surface.
#[derive(Debug, Clone, Copy)]
struct Segment {
    from: (f64, f64),
    to: (f64, f64),
}

/// The tool reference point `M = S + R·n + (H − R)·z` at `(u, v)` of a surface, with the
/// reference evaluator; `sign` turns `S_u × S_v` to the tool's side.
pub fn tool_point(
    s: &SurfaceData<'_>,
    radius_mm: f64,
    length_mm: f64,
    sign: f64,
    u: f64,
    v: f64,
) -> [f64; 3] {
    let e = piegl_tiller_surface(s, u, v);
    let k = radius_mm * sign;
    [
        e.p[0] + k * e.normal[0],
        e.p[1] + k * e.normal[1],
        e.p[2] + k * e.normal[2] + (length_mm - radius_mm),
    ]
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
    blk.length_mm = path::norm([b[0] - a[0], b[1] - a[1], b[2] - a[2]]);
    blk.acc_mm_per_s2 = machine.path_acc_mm_per_s2;
    blk.jerk_mm_per_s3 = machine.path_jerk_mm_per_s3;
    blk
}

/// Rapids from `from` to `to` at the safe height: up, across, down (the legs of no
/// length left out).
fn travel(
    out: &mut Vec<CommandBlock>,
    line: u32,
    from: [f64; 3],
    to: [f64; 3],
    safe_z: f64,
    machine: &Machine,
) {
    let z = safe_z.max(from[2]).max(to[2]);
    let legs = [from, [from[0], from[1], z], [to[0], to[1], z], to];
    for w in legs.windows(2) {
        if path::norm([w[1][0] - w[0][0], w[1][1] - w[0][1], w[1][2] - w[0][2]]) > 1e-9 {
            out.push(rapid(line, w[0], w[1], machine));
        }
    }
}

/// What the blocks of a workingstep need besides the step and its path.
struct Emit<'a> {
    patches: &'a [OwnedSurface],
    radius_mm: f64,
    length_mm: f64,
    normal_sign: i32,
    feed_mm_per_min: f64,
    line: u32,
    machine: &'a Machine,
}

impl Emit<'_> {
    /// The surface block of the piece `local` (patch-local `(u, v)`) of a pass on `patch`.
    fn block(&self, patch: &OwnedSurface, local: Segment) -> CommandBlock {
        let mut b = CommandBlock::empty(BlockKind::Motion, 0, self.line);
        b.flags = FLAG_SURFACE;
        b.degree = patch.degree_u as u32;
        b.n_ctrl = patch.ctrl.len().min(MAX_CTRL) as u32;
        b.ctrl[..patch.ctrl.len().min(MAX_CTRL)]
            .copy_from_slice(&patch.ctrl[..patch.ctrl.len().min(MAX_CTRL)]);
        let sp = &mut b.surface;
        sp.degree_v = patch.degree_v as u32;
        sp.uv_start = [local.from.0, local.from.1];
        sp.uv_end = [local.to.0, local.to.1];
        sp.tool_radius_mm = self.radius_mm;
        sp.tool_length_mm = self.length_mm;
        sp.normal_sign = self.normal_sign;
        b.feed_mm_per_min = self.feed_mm_per_min.min(self.machine.max_feed_mm_per_min);
        b.acc_mm_per_s2 = self.machine.path_acc_mm_per_s2;
        b.jerk_mm_per_s3 = self.machine.path_jerk_mm_per_s3;
        b.length_mm = path::length(&b);
        b
    }
}

/// The blocks of a planned workingstep, unplanned (feed caps are the programmed feed):
/// from `start` (the tool point before it) to the safe height above its last pass.
/// Returns the blocks and where they leave the tool.
pub fn surface_commands(
    step: &FreeformStep,
    path: &SurfacePath,
    machine: &Machine,
    start: [f64; 3],
) -> Result<(Vec<CommandBlock>, [f64; 3]), StepError> {
    let fail = |message: String| StepError {
        line: step.line,
        id: Some(step.id),
        rule: "blocks",
        message,
    };
    let whole = step.surface.data();
    let (p, q) = (whole.degree_u, whole.degree_v);
    if (p + 1) * (q + 1) > MAX_CTRL {
        return Err(fail(format!(
            "degrees p={p} q={q}: a Bézier patch of {} control points exceeds a block's {MAX_CTRL}",
            (p + 1) * (q + 1)
        )));
    }
    let patches = bezier_patches(&whole)
        .ok_or_else(|| fail("the surface could not be split into Bézier patches".into()))?;
    let emit = Emit {
        patches: &patches,
        radius_mm: step.tool.radius_mm(),
        length_mm: step.tool.length_mm,
        normal_sign: if path.normal_sign < 0.0 { -1 } else { 1 },
        feed_mm_per_min: step.technology.feed_mm_per_min,
        line: step.line,
        machine,
    };
    // The surface segments in order, and where the tool lifts between them.
    let mut runs: Vec<Vec<Segment>> = Vec::new();
    for (k, ps) in path.passes.iter().enumerate() {
        let seg = Segment {
            from: path.uv(ps.from, ps.fixed),
            to: path.uv(ps.to, ps.fixed),
        };
        match (path.mode, runs.last_mut()) {
            (PathMode::Zigzag, Some(run)) => {
                let prev = path.passes[k - 1];
                run.push(Segment {
                    from: path.uv(prev.to, prev.fixed),
                    to: path.uv(ps.from, ps.fixed),
                });
                run.push(seg);
            }
            _ => runs.push(vec![seg]),
        }
    }
    // Safe height: above every tool reference point of the surface.
    let (u0, u1, v0, v1) = OwnedSurface::from_data(&whole).domain();
    let sign = f64::from(emit.normal_sign);
    let mut top = f64::NEG_INFINITY;
    for i in 0..=64 {
        for j in 0..=64 {
            let u = u0 + (u1 - u0) * i as f64 / 64.0;
            let v = v0 + (v1 - v0) * j as f64 / 64.0;
            top = top.max(tool_point(&whole, emit.radius_mm, emit.length_mm, sign, u, v)[2]);
        }
    }
    let safe_z = top + LIFT_CLEARANCE_MM;
    let mut out = Vec::new();
    let mut pos = start;
    for run in &runs {
        let mut blocks = Vec::new();
        for seg in run {
            for (patch, local) in cut_at_patches(*seg, emit.patches) {
                let b = emit.block(patch, local);
                if b.length_mm > 1e-9 {
                    blocks.push(b);
                }
            }
        }
        let (Some(first), Some(last)) = (blocks.first(), blocks.last()) else {
            continue;
        };
        let (m0, m1) = (path::eval(first, 0.0).p, path::eval(last, 1.0).p);
        travel(&mut out, step.line, pos, m0, safe_z, machine);
        out.extend(blocks);
        pos = m1;
    }
    let top = [pos[0], pos[1], safe_z.max(pos[2])];
    travel(&mut out, step.line, pos, top, safe_z, machine);
    Ok((out, top))
}

/// The blocks of a whole part, planned and numbered, ending with a program end, and the
/// largest scallop height its paths leave (predicted by the pass planner): every
/// free-form workingstep in order, from the machine's start (the origin).
pub fn part_blocks(
    text: &str,
    machine: &Machine,
    period_ns: u64,
) -> Result<(Vec<CommandBlock>, f64), Vec<StepError>> {
    let planned = crate::step::check::plan_part(text)?;
    let mut blocks = Vec::new();
    let mut pos = [0.0; 3];
    let mut scallop: f64 = 0.0;
    let mut last_line = 0;
    for (step, sp) in &planned {
        let (b, end) = surface_commands(step, sp, machine, pos).map_err(|e| vec![e])?;
        blocks.extend(b);
        pos = end;
        scallop = scallop.max(sp.predicted_scallop_mm);
        last_line = step.line;
    }
    blocks.push(CommandBlock::empty(BlockKind::ProgramEnd, 0, last_line));
    crate::blocks::plan(&mut blocks, machine, period_ns);
    let mut errs = Vec::new();
    for (seq, b) in blocks.iter_mut().enumerate() {
        b.seq = seq as u64;
        if let Err(e) = b.validate() {
            errs.push(StepError {
                line: b.source_line,
                id: None,
                rule: "internal",
                message: e.to_string(),
            });
        }
    }
    if errs.is_empty() {
        Ok((blocks, scallop))
    } else {
        Err(errs)
    }
}

/// The parts of an axis-parallel segment on each patch, in the segment's direction, in
/// the patch's local `[0, 1]²`.
fn cut_at_patches(seg: Segment, patches: &[OwnedSurface]) -> Vec<(&OwnedSurface, Segment)> {
    let along_u = seg.from.1 == seg.to.1;
    let (fixed, a, b) = if along_u {
        (seg.from.1, seg.from.0, seg.to.0)
    } else {
        (seg.from.0, seg.from.1, seg.to.1)
    };
    let (lo, hi) = (a.min(b), a.max(b));
    // The patches the fixed parameter lies on: the first one for each range of the other.
    let mut hits: Vec<(f64, f64, &OwnedSurface)> = Vec::new();
    for s in patches {
        let (u0, u1, v0, v1) = s.domain();
        let (f0, f1, r0, r1) = if along_u {
            (v0, v1, u0, u1)
        } else {
            (u0, u1, v0, v1)
        };
        if fixed < f0 || fixed > f1 || r1 <= lo || r0 >= hi {
            continue;
        }
        if hits.iter().any(|h| h.0 == r0.max(lo)) {
            continue;
        }
        hits.push((r0.max(lo), r1.min(hi), s));
    }
    hits.sort_by(|x, y| x.0.total_cmp(&y.0));
    if b < a {
        hits.reverse();
    }
    let local = |x: f64, lo: f64, hi: f64| ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    hits.into_iter()
        .map(|(r0, r1, s)| {
            let (p, q) = if b < a { (r1, r0) } else { (r0, r1) };
            let (u0, u1, v0, v1) = s.domain();
            let (from, to) = if along_u {
                let f = local(fixed, v0, v1);
                ((local(p, u0, u1), f), (local(q, u0, u1), f))
            } else {
                let f = local(fixed, u0, u1);
                ((f, local(p, v0, v1)), (f, local(q, v0, v1)))
            };
            (s, Segment { from, to })
        })
        .collect()
}

#[cfg(test)]
mod tests;
