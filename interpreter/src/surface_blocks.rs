//! A planned surface workingstep as wire blocks (protocol 4, seed 000): surface blocks
//! (`FLAG_SURFACE`, one rational Bézier patch and a straight pass in its `(u, v)`, or a
//! cubic one with `FLAG_UV_CUBIC` for the plane passes of [`plane_commands`]) along the
//! passes and, in zig-zag, along the links between them; rapid line blocks in tool-point
//! space for the lifts; a program end.
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

use crate::step::check::PlannedPath;
use crate::step::{FreeformStep, PathMode, StepError};
use crate::surface_path::SurfacePath;
use crate::surface_plane::{PlanePass, PlanePath};
use shared::nurbs::reference::piegl_tiller_surface;
use shared::nurbs::surface::SurfaceData;
use shared::nurbs::{split_to_capacity, SplitCurve, MAX_CTRL};
use shared::path;
use shared::protocol::{
    BlockKind, CommandBlock, FLAG_RAPID, FLAG_STOP_AT_END, FLAG_SURFACE, FLAG_UV_CUBIC,
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
    /// The surface blocks of straight `(u, v)` segments of the whole surface, cut at the
    /// patches (blocks of no length left out).
    fn segments(&self, run: &[Segment]) -> Vec<CommandBlock> {
        let mut blocks = Vec::new();
        for seg in run {
            for (patch, local) in cut_at_patches(*seg, self.patches) {
                let b = self.block(patch, local);
                if b.length_mm > 1e-9 {
                    blocks.push(b);
                }
            }
        }
        blocks
    }

    /// The surface block of a cubic `(u, v)` pass on `patch` (patch-local control points).
    fn cubic_block(&self, patch: &OwnedSurface, uv: [[f64; 2]; 4]) -> CommandBlock {
        let mut b = self.block(
            patch,
            Segment {
                from: (uv[0][0], uv[0][1]),
                to: (uv[3][0], uv[3][1]),
            },
        );
        b.flags |= FLAG_UV_CUBIC;
        b.surface.uv_inner = [uv[1], uv[2]];
        b.length_mm = path::length(&b);
        b
    }

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

/// The patches of a step's surface, or why a block cannot hold one.
fn patches_of(step: &FreeformStep) -> Result<Vec<OwnedSurface>, StepError> {
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
    bezier_patches(&whole)
        .ok_or_else(|| fail("the surface could not be split into Bézier patches".into()))
}

/// Safe height: above every tool reference point of the surface.
fn safe_height(step: &FreeformStep, emit: &Emit<'_>) -> f64 {
    let whole = step.surface.data();
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
    top + LIFT_CLEARANCE_MM
}

/// Joins runs of surface blocks with lifts: from `start` to each run, and from the last
/// up to the safe height. Returns the blocks and where they leave the tool.
fn join_runs(
    runs: Vec<Vec<CommandBlock>>,
    line: u32,
    start: [f64; 3],
    safe_z: f64,
    machine: &Machine,
) -> (Vec<CommandBlock>, [f64; 3]) {
    let mut out = Vec::new();
    let mut pos = start;
    for blocks in runs {
        let (Some(first), Some(last)) = (blocks.first(), blocks.last()) else {
            continue;
        };
        let (m0, m1) = (path::eval(first, 0.0).p, path::eval(last, 1.0).p);
        travel(&mut out, line, pos, m0, safe_z, machine);
        out.extend(blocks);
        pos = m1;
    }
    let top = [pos[0], pos[1], safe_z.max(pos[2])];
    travel(&mut out, line, pos, top, safe_z, machine);
    (out, top)
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
    let patches = patches_of(step)?;
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
    let safe_z = safe_height(step, &emit);
    let runs = runs
        .iter()
        .map(|run| emit.segments(run))
        .collect::<Vec<_>>();
    Ok(join_runs(runs, step.line, start, safe_z, machine))
}

/// The blocks of a planned plane-parallel workingstep ([`crate::surface_plane`]),
/// unplanned, as [`surface_commands`] gives them for a UV path: each pass cut at the
/// patches, each piece one block whose `(u, v)` pass is a cubic Bézier curve fitted to
/// the plane's intersection ([`fit_piece`]: every contact point within the chordal
/// tolerance of its plane, checked densely, the piece split where it is not). In
/// zig-zag, a pass that ends on the same edge of the domain as the next one (of the next
/// plane) starts is joined to it along that edge; everything else is joined by lifts.
/// The boundary pass, if the path has one, follows the last pass as straight `(u, v)`
/// segments along the edges.
pub fn plane_commands(
    step: &FreeformStep,
    path: &PlanePath,
    machine: &Machine,
    start: [f64; 3],
) -> Result<(Vec<CommandBlock>, [f64; 3]), StepError> {
    let patches = patches_of(step)?;
    let emit = Emit {
        patches: &patches,
        radius_mm: step.tool.radius_mm(),
        length_mm: step.tool.length_mm,
        normal_sign: if path.normal_sign < 0.0 { -1 } else { 1 },
        feed_mm_per_min: step.technology.feed_mm_per_min,
        line: step.line,
        machine,
    };
    let whole = step.surface.data();
    let mut distinct_v: Vec<f64> = whole.knots_v.to_vec();
    distinct_v.dedup();
    // Patches are ordered along u first, then v (see [`bezier_patches`]).
    let n_spans_v = distinct_v.len() - 1;
    let fit = Fit {
        step,
        emit: &emit,
        whole: &whole,
        normal: path.normal,
        tol_mm: path.chordal_mm,
    };
    let mut runs: Vec<Vec<CommandBlock>> = Vec::new();
    let mut prev: Option<&PlanePass> = None;
    for pass in &path.passes {
        let mut blocks = Vec::new();
        // The pass piece by piece, one piece per patch.
        let mut k0 = 0;
        while k0 < pass.spans.len() {
            let mut k1 = k0;
            while k1 + 1 < pass.spans.len() && pass.spans[k1 + 1] == pass.spans[k0] {
                k1 += 1;
            }
            let (su, sv) = pass.spans[k0];
            let patch = patches.get(su * n_spans_v + sv).ok_or_else(|| StepError {
                line: step.line,
                id: Some(step.id),
                rule: "internal",
                message: format!("no patch for the knot spans ({su}, {sv})"),
            })?;
            fit.piece(patch, &pass.uv[k0..=k1 + 1], pass.level_mm, 0, &mut blocks)?;
            k0 = k1 + 1;
        }
        let link = match (path.mode, prev) {
            (PathMode::Zigzag, Some(p)) => {
                p.plane != pass.plane
                    && !p.closed
                    && !pass.closed
                    && p.end_edge.is_some()
                    && p.end_edge == pass.start_edge
            }
            _ => false,
        };
        match (link, runs.last_mut(), prev) {
            (true, Some(run), Some(p)) => {
                let (a, b) = (p.uv[p.uv.len() - 1], pass.uv[0]);
                run.extend(emit.segments(&[Segment { from: a, to: b }]));
                run.extend(blocks);
            }
            _ => runs.push(blocks),
        }
        prev = Some(pass);
    }
    // The boundary pass, straight on from the last pass where it begins at its end.
    let edge: Vec<Segment> = path
        .boundary
        .windows(2)
        .map(|w| Segment {
            from: w[0],
            to: w[1],
        })
        .collect();
    if !edge.is_empty() {
        let blocks = emit.segments(&edge);
        let on = prev.is_some_and(|p| !p.closed && p.uv.last() == path.boundary.first());
        match runs.last_mut() {
            Some(run) if on => run.extend(blocks),
            _ => runs.push(blocks),
        }
    }
    let safe_z = safe_height(step, &emit);
    Ok(join_runs(runs, step.line, start, safe_z, machine))
}

/// The blocks of a planned workingstep, whichever its strategy ([`surface_commands`],
/// [`plane_commands`]).
pub fn step_commands(
    step: &FreeformStep,
    path: &PlannedPath,
    machine: &Machine,
    start: [f64; 3],
) -> Result<(Vec<CommandBlock>, [f64; 3]), StepError> {
    match path {
        PlannedPath::Uv(p) => surface_commands(step, p, machine, start),
        PlannedPath::Plane(p) => plane_commands(step, p, machine, start),
    }
}

/// Fits the blocks of plane passes.
struct Fit<'a> {
    step: &'a FreeformStep,
    emit: &'a Emit<'a>,
    whole: &'a SurfaceData<'a>,
    normal: [f64; 3],
    tol_mm: f64,
}

/// Samples per block where the fitted pass is checked against its plane.
pub const FIT_SAMPLES: usize = 256;
/// How often a piece may be halved before the fit gives up.
const MAX_FIT_DEPTH: u32 = 24;

impl Fit<'_> {
    fn fail(&self, message: String) -> StepError {
        StepError {
            line: self.step.line,
            id: Some(self.step.id),
            rule: "blocks",
            message,
        }
    }

    /// `n·S` and its gradient in `(u, v)` of the whole surface.
    fn f_grad(&self, p: (f64, f64)) -> (f64, [f64; 2]) {
        let d = crate::surface_path::eval2(self.whole, p.0, p.1);
        let n = self.normal;
        let dot = |a: [f64; 3]| n[0] * a[0] + n[1] * a[1] + n[2] * a[2];
        (dot(d.p), [dot(d.su), dot(d.sv)])
    }

    /// A point near the plane's curve moved onto it along the gradient.
    fn project(&self, mut p: (f64, f64), level: f64, dom: (f64, f64, f64, f64)) -> (f64, f64) {
        for _ in 0..50 {
            let (f, g) = self.f_grad(p);
            let g2 = g[0] * g[0] + g[1] * g[1];
            if g2.is_nan() || g2 <= 0.0 || (f - level).abs() < 1e-13 {
                break;
            }
            let k = (f - level) / g2;
            p = (
                (p.0 - k * g[0]).clamp(dom.0, dom.1),
                (p.1 - k * g[1]).clamp(dom.2, dom.3),
            );
        }
        p
    }

    /// The blocks of one piece of a pass on `patch`: points `pts` (whole-surface
    /// `(u, v)`, on the plane `level`), fitted by one cubic if it keeps within the
    /// tolerance, else halved.
    fn piece(
        &self,
        patch: &OwnedSurface,
        pts: &[(f64, f64)],
        level: f64,
        depth: u32,
        out: &mut Vec<CommandBlock>,
    ) -> Result<(), StepError> {
        let dom = patch.domain();
        let to_local = |p: (f64, f64)| {
            [
                ((p.0 - dom.0) / (dom.1 - dom.0)).clamp(0.0, 1.0),
                ((p.1 - dom.2) / (dom.3 - dom.2)).clamp(0.0, 1.0),
            ]
        };
        let local: Vec<[f64; 2]> = pts.iter().map(|p| to_local(*p)).collect();
        let m = local.len() - 1;
        // Unit tangents of the level curve at both ends, in local coordinates, pointing
        // along the piece.
        let tangent = |p: (f64, f64), along: [f64; 2]| {
            let (_, g) = self.f_grad(p);
            let t = [-g[1] / (dom.1 - dom.0), g[0] / (dom.3 - dom.2)];
            let l = t[0].hypot(t[1]);
            let s = if t[0] * along[0] + t[1] * along[1] < 0.0 {
                -1.0
            } else {
                1.0
            };
            if l > 0.0 {
                [s * t[0] / l, s * t[1] / l]
            } else {
                let al = along[0].hypot(along[1]).max(f64::MIN_POSITIVE);
                [along[0] / al, along[1] / al]
            }
        };
        let sub = |a: [f64; 2], b: [f64; 2]| [a[0] - b[0], a[1] - b[1]];
        let t0 = tangent(pts[0], sub(local[1], local[0]));
        let t1 = tangent(pts[m], sub(local[m], local[m - 1]));
        let inner = hermite_fit(&local, t0, t1);
        let b = self
            .emit
            .cubic_block(patch, [local[0], inner[0], inner[1], local[m]]);
        let worst = (0..=FIT_SAMPLES)
            .map(|k| {
                let c = path::surface_at(&b, k as f64 / FIT_SAMPLES as f64).p;
                let n = self.normal;
                (n[0] * c[0] + n[1] * c[1] + n[2] * c[2] - level).abs()
            })
            .fold(0.0f64, f64::max);
        if worst <= self.tol_mm {
            if b.length_mm > 1e-9 {
                out.push(b);
            }
            return Ok(());
        }
        if depth >= MAX_FIT_DEPTH {
            return Err(self.fail(format!(
                "the pass in the plane {level:.6} mm along the normal could not be fitted \
                 within {} mm near (u, v) = ({:.6}, {:.6}) (still {worst:.3e} mm off after \
                 {MAX_FIT_DEPTH} halvings; {} points {:?})",
                self.tol_mm,
                pts[0].0,
                pts[0].1,
                pts.len(),
                pts
            )));
        }
        if m >= 2 {
            let h = m / 2;
            self.piece(patch, &pts[..=h], level, depth + 1, out)?;
            return self.piece(patch, &pts[h..], level, depth + 1, out);
        }
        // Two points only: a third on the curve between them.
        let mid = self.project(
            (0.5 * (pts[0].0 + pts[1].0), 0.5 * (pts[0].1 + pts[1].1)),
            level,
            dom,
        );
        self.piece(patch, &[pts[0], mid, pts[1]], level, depth + 1, out)
    }
}

/// The inner control points of the cubic Bézier from `pts[0]` to `pts[m]` with end
/// tangents along `t0` and `t1` whose lengths fit the points best (least squares at their
/// chord-length parameters); the chord's length when there is nothing to fit. Kept in
/// `[0, 1]²`.
fn hermite_fit(pts: &[[f64; 2]], t0: [f64; 2], t1: [f64; 2]) -> [[f64; 2]; 2] {
    let m = pts.len() - 1;
    let (a, b) = (pts[0], pts[m]);
    let dist = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
    let mut acc = vec![0.0];
    for w in pts.windows(2) {
        acc.push(acc[acc.len() - 1] + dist(w[0], w[1]));
    }
    let total = acc[m];
    let chord = dist(a, b).max(1e-12);
    let dot = |p: [f64; 2], q: [f64; 2]| p[0] * q[0] + p[1] * q[1];
    let (mut s11, mut s12, mut s22, mut r1, mut r2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in 1..m {
        let t = acc[k] / total;
        let (h00, h10, h01, h11) = (
            2.0 * t * t * t - 3.0 * t * t + 1.0,
            t * t * t - 2.0 * t * t + t,
            -2.0 * t * t * t + 3.0 * t * t,
            t * t * t - t * t,
        );
        let r = [
            pts[k][0] - h00 * a[0] - h01 * b[0],
            pts[k][1] - h00 * a[1] - h01 * b[1],
        ];
        s11 += h10 * h10 * dot(t0, t0);
        s12 += h10 * h11 * dot(t0, t1);
        s22 += h11 * h11 * dot(t1, t1);
        r1 += h10 * dot(t0, r);
        r2 += h11 * dot(t1, r);
    }
    let det = s11 * s22 - s12 * s12;
    let (mut al, mut be) = (chord, chord);
    if m >= 2 && det.abs() > 1e-14 * (s11 * s22).max(f64::MIN_POSITIVE) {
        let x = (r1 * s22 - r2 * s12) / det;
        let y = (s11 * r2 - s12 * r1) / det;
        if x > 0.1 * chord && y > 0.1 * chord && x < 3.0 * total && y < 3.0 * total {
            (al, be) = (x, y);
        }
    }
    let c = |x: f64| x.clamp(0.0, 1.0);
    [
        [c(a[0] + al * t0[0] / 3.0), c(a[1] + al * t0[1] / 3.0)],
        [c(b[0] - be * t1[0] / 3.0), c(b[1] - be * t1[1] / 3.0)],
    ]
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
    let mut pos = crate::blocks::check::START_MM;
    let mut scallop: f64 = 0.0;
    let mut last_line = 0;
    let mut travel = start_travel_error(machine).into_iter().collect::<Vec<_>>();
    for (step, sp) in &planned {
        let (b, end) = step_commands(step, sp, machine, pos).map_err(|e| vec![e])?;
        travel.extend(travel_errors(step, &b, machine));
        blocks.extend(b);
        pos = end;
        scallop = scallop.max(sp.predicted_scallop_mm());
        last_line = step.line;
    }
    if !travel.is_empty() {
        return Err(travel);
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

/// The machine's start (the origin) outside its travel, as the error of a part.
pub fn start_travel_error(machine: &Machine) -> Option<StepError> {
    crate::blocks::check::start_outside(machine).map(|message| StepError {
        line: 1,
        id: None,
        rule: "travel",
        message,
    })
}

/// The blocks of workingstep `step` whose path leaves the machine's travel (as
/// [`shared::travel::check_block`] judges them, the interpolator's own check), each as
/// an error naming the workingstep: the first on each line of the file, so that a pass
/// grid beyond a limit is not reported a thousand times.
pub fn travel_errors(
    step: &FreeformStep,
    blocks: &[CommandBlock],
    machine: &Machine,
) -> Vec<StepError> {
    let mut errs: Vec<StepError> = Vec::new();
    for b in blocks {
        if let Err(e) = shared::travel::check_block(b, &machine.axes) {
            if errs.last().is_some_and(|l| l.line == b.source_line) {
                continue;
            }
            let what = if b.is_surface() {
                "a pass over the surface"
            } else {
                "a rapid move of the lifts"
            };
            errs.push(StepError {
                line: b.source_line,
                id: Some(step.id),
                rule: "travel",
                message: format!(
                    "{what} of workingstep '{}' leaves the machine's travel: {e}",
                    step.name
                ),
            });
        }
    }
    errs
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
