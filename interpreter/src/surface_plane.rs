//! Plane-parallel tool paths (`PLANE_CC_STRATEGY`, ISO 14649-11): the cutter-contact
//! points of each pass lie in one of a family of parallel planes `n·C = c`, `n` the
//! strategy's plane normal in machine coordinates. A pass is a piece of the surface's
//! intersection with one plane: a curve in the `(u, v)` domain, which the blocks carry
//! as cubic Bézier curves per patch ([`crate::surface_blocks`]).
//!
//! # Finding the intersections
//!
//! The domain is covered by a grid of [`CELLS_PER_SPAN`] cells per knot span each way (so
//! knot lines are grid lines and a cell lies in one Bézier patch). With `f = n·S` at the
//! nodes, each plane's zero set of `f − c` is traced cell by cell (marching squares; a
//! saddle cell is resolved by its centre value), the crossings chained into polylines:
//! open ones end on the domain boundary, closed ones are loops inside it, and a plane
//! that cuts the surface in several places gives several pieces (each its own pass). Every
//! crossing is then moved onto the plane exactly, by a safeguarded Newton iteration along
//! its grid edge (so it stays on the knot line it crosses, where neighbouring blocks
//! join). A plane that misses the surface gives no pass.
//!
//! # Spacing
//!
//! As in [`crate::surface_path`], two neighbouring passes a surface distance `w` apart
//! leave a scallop `h ≈ w²/8·(1/R + κ)`, `κ` the normal curvature across the passes. Here
//! the direction across is `X = N × T` with `T = N × n` along the intersection (`N` the
//! unit normal towards the tool), and planes `Δ` apart are `w = Δ/|n·X|` apart on the
//! surface, so each node allows a plane step `Δ = |n·X|·√(8h/(1/R + κ_X))` (`w` capped
//! by the stepover). From a plane `c` the next one is the smallest step allowed over the
//! cells the strip `[c, c + Δ₀]` touches, `Δ₀` the smallest over the cells plane `c`
//! touches (every cell of the narrower strip then allows at least the step taken). The
//! planes run from just inside the lowest `f` of the surface to just inside the highest.
//!
//! # Edges
//!
//! Where passes end on a boundary edge of the domain at an angle `θ` to it, their ends lie
//! `w/sin θ` apart along the edge, and the band between one pass's end and the next's is
//! farther from the cut than the middle between two passes: a point there is at most
//! `w/(1 + sin θ)` from the nearer pass (the end of one, the side of the other), against
//! `w/2` between passes, so the scallop there is `(2/(1 + sin θ))²` times the one between
//! passes (1.78 times at 30°). Zig-zag links run along the edge only in every other of
//! those gaps. Where that factor would take the predicted scallop beyond the tolerance,
//! the path ends with a boundary pass: the contact point goes once round the whole
//! domain boundary, from where the last pass ends, so every point of such a band is
//! within `w/2` of a cut (the edge pass on one side, the passes on the others).
//!
//! # Planes parallel to the tool axis or not
//!
//! Any normal is accepted, the tool axis included (horizontal planes: Z-level passes),
//! but where a plane touches the surface tangentially (`|n·X|` small: the surface is
//! nearly parallel to the planes) the passes would have to be infinitely close, so a
//! surface that is anywhere within [`MIN_SLOPE_DEG`] of parallel to the planes is refused,
//! naming the point and the `DIRECTION` of the normal.

use crate::step::{FreeformStep, PathMode, PlaneCcStrategy, StepError, Strategy};
use crate::surface_path::{
    check_reach, cross, distinct, dot, eval2, norm, step_error, subdivide, tool_side_sign, SAFETY,
};
use shared::nurbs::surface::SurfaceData;

/// Grid cells per knot span in each direction.
pub const CELLS_PER_SPAN: usize = 16;
/// The planes may come no closer to parallel with the surface than this.
pub const MIN_SLOPE_DEG: f64 = 3.0;
/// More planes than this means the tolerance is unreasonably small for the surface.
pub const MAX_PLANES: usize = 20_000;
/// The first and last plane lie this far inside the surface's extent along the normal
/// (an extreme plane touches the surface only along its boundary or at a point).
const INSET_MM: f64 = 1e-6;

/// A boundary edge of the `(u, v)` domain.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Edge {
    U0,
    U1,
    V0,
    V1,
}

/// One pass: a piece of the intersection of the surface with the plane `n·C = level`.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanePass {
    /// Index of the plane (0 = the first).
    pub plane: usize,
    pub level_mm: f64,
    /// Points on the plane, in cutting order, `(u, v)` of the whole surface; one on
    /// every grid line the pass crosses. A loop repeats its first point at the end.
    pub uv: Vec<(f64, f64)>,
    /// For each segment `uv[k]..uv[k+1]`: the knot spans `(in u, in v)` it lies in.
    pub spans: Vec<(usize, usize)>,
    pub closed: bool,
    /// The boundary edges the ends lie on (open passes).
    pub start_edge: Option<Edge>,
    pub end_edge: Option<Edge>,
}

/// A planned plane-parallel path.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanePath {
    pub normal: [f64; 3],
    pub mode: PathMode,
    pub passes: Vec<PlanePass>,
    /// Planes that cut the surface.
    pub planes: usize,
    /// `+1` when `S_u × S_v` faces the tool (towards +z), else `−1`.
    pub normal_sign: f64,
    pub radius_mm: f64,
    /// The largest distance of a contact point from its plane the blocks may have.
    pub chordal_mm: f64,
    /// Plane steps (smallest and largest; the last, which closes the extent, left out).
    pub min_step_mm: f64,
    pub max_step_mm: f64,
    /// The largest scallop height the spacing formula predicts at the chosen planes.
    pub predicted_scallop_mm: f64,
    /// The boundary pass ([Edges](self#edges)), cut after the last pass: straight
    /// `(u, v)` segments along the domain's edges, from its first point (where the last
    /// pass ends, if that is on an edge) once round and back to it. Empty where the
    /// passes leave no band along the edges beyond the tolerance.
    pub boundary: Vec<(f64, f64)>,
    /// The largest factor `(2/(1 + sin θ))²` of the open passes' ends.
    pub edge_factor: f64,
    /// Cutting length on the surface along the passes (polylines through the grid
    /// crossings: a little short of the curves') and the boundary pass.
    pub length_mm: f64,
}

/// How much more than between passes is left in the band along an edge that passes meet
/// at an angle whose sine is `sin_theta` ([Edges](self#edges)).
pub fn edge_factor(sin_theta: f64) -> f64 {
    let k = 2.0 / (1.0 + sin_theta.clamp(0.0, 1.0));
    k * k
}

/// The sine of the angle between an open pass and the edge one of its ends lies on.
fn end_sine(s: &SurfaceData<'_>, pass: &PlanePass, at_end: bool) -> Option<f64> {
    let n = pass.uv.len();
    if pass.closed || n < 2 {
        return None;
    }
    let (inner, end, edge) = if at_end {
        (pass.uv[n - 2], pass.uv[n - 1], pass.end_edge?)
    } else {
        (pass.uv[1], pass.uv[0], pass.start_edge?)
    };
    let d = eval2(s, end.0, end.1);
    let q = eval2(s, inner.0, inner.1).p;
    let t = [d.p[0] - q[0], d.p[1] - q[1], d.p[2] - q[2]];
    let e = match edge {
        Edge::U0 | Edge::U1 => d.sv,
        Edge::V0 | Edge::V1 => d.su,
    };
    let (lt, le) = (norm(t), norm(e));
    (lt > 0.0 && le > 0.0).then(|| norm(cross(t, e)) / (lt * le))
}

/// The boundary pass from `start` on `edge` once round the domain `(u0, u1, v0, v1)`,
/// counter-clockwise in `(u, v)`: along `V0` with `u` rising, `U1`, `V1`, `U0`.
fn boundary_loop(start: (f64, f64), edge: Edge, domain: (f64, f64, f64, f64)) -> Vec<(f64, f64)> {
    let (u0, u1, v0, v1) = domain;
    // The corner each edge leads to, in that order.
    let corners = [(u1, v0), (u1, v1), (u0, v1), (u0, v0)];
    let first = match edge {
        Edge::V0 => 0,
        Edge::U1 => 1,
        Edge::V1 => 2,
        Edge::U0 => 3,
    };
    let mut out = vec![start];
    out.extend((0..4).map(|k| corners[(first + k) % 4]));
    out.push(start);
    out
}

fn scale(a: [f64; 3], k: f64) -> [f64; 3] {
    [a[0] * k, a[1] * k, a[2] * k]
}

/// Grid lines of one direction: `CELLS_PER_SPAN` per knot span, the knots exactly.
fn grid_lines(breaks: &[f64]) -> Vec<f64> {
    subdivide(breaks, CELLS_PER_SPAN)
}

/// What the spacing needs at a surface point, for planes with unit normal `n`.
pub struct PlaneLocal {
    /// Unit normal towards the tool.
    pub n: [f64; 3],
    /// `|n·X|`: the plane distance per unit of surface distance across the passes.
    pub slope: f64,
    /// Normal curvature across the passes (convex seen from the tool > 0).
    pub kappa_cross: f64,
    /// Smallest normal curvature over all directions.
    pub kappa_min: f64,
}

/// [`PlaneLocal`] at `(u, v)`, `None` where the surface is degenerate.
pub fn plane_local(
    s: &SurfaceData<'_>,
    u: f64,
    v: f64,
    plane: [f64; 3],
    sign: f64,
) -> Option<PlaneLocal> {
    let d = eval2(s, u, v);
    let nu = cross(d.su, d.sv);
    let len = norm(nu);
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let n = scale(nu, sign / len);
    let (l, m, nn) = (-dot(d.suu, n), -dot(d.suv, n), -dot(d.svv, n));
    let (e, f, g) = (dot(d.su, d.su), dot(d.su, d.sv), dot(d.sv, d.sv));
    let det_i = e * g - f * f;
    let mean2 = e * nn + g * l - 2.0 * f * m;
    let det_ii = l * nn - m * m;
    let disc = (mean2 * mean2 - 4.0 * det_i * det_ii).max(0.0).sqrt();
    let kappa_min = (mean2 - disc) / (2.0 * det_i);
    // Along the intersection T = N × n, across it X = N × T (unit, in the tangent plane).
    let t = cross(n, plane);
    let tl = norm(t);
    let (slope, kappa_cross) = if tl < 1e-12 {
        (0.0, kappa_min)
    } else {
        let x = cross(n, scale(t, 1.0 / tl));
        // X = a·S_u + b·S_v: the first fundamental form solves for (a, b).
        let (xu, xv) = (dot(d.su, x), dot(d.sv, x));
        let a = (g * xu - f * xv) / det_i;
        let b = (e * xv - f * xu) / det_i;
        (
            dot(plane, x).abs(),
            l * a * a + 2.0 * m * a * b + nn * b * b,
        )
    };
    Some(PlaneLocal {
        n,
        slope,
        kappa_cross,
        kappa_min,
    })
}

/// The grid of a surface with `f = n·S` and the plane step each node allows.
pub struct Grid {
    pub gu: Vec<f64>,
    pub gv: Vec<f64>,
    /// `f[i * gv.len() + j]` at `(gu[i], gv[j])`.
    pub f: Vec<f64>,
    /// Plane step allowed at each node.
    pub step: Vec<f64>,
    /// Per node: `(|n·X|, κ_X)`, for the predicted scallop.
    pub local: Vec<(f64, f64)>,
}

impl Grid {
    fn at(&self, i: usize, j: usize) -> usize {
        i * self.gv.len() + j
    }
    /// `(f_min, f_max, step_min)` of cell `(i, j)`.
    fn cell(&self, i: usize, j: usize) -> (f64, f64, f64) {
        let ids = [
            self.at(i, j),
            self.at(i + 1, j),
            self.at(i, j + 1),
            self.at(i + 1, j + 1),
        ];
        let (mut lo, mut hi, mut st) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY);
        for k in ids {
            lo = lo.min(self.f[k]);
            hi = hi.max(self.f[k]);
            st = st.min(self.step[k]);
        }
        (lo, hi, st)
    }
}

/// A grid edge: `H(i, j)` from node `(i, j)` to `(i+1, j)` (`u` varies), `V(i, j)` from
/// `(i, j)` to `(i, j+1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
enum GEdge {
    H(usize, usize),
    V(usize, usize),
}

/// Moves a crossing of `f = level` on a grid edge onto the plane: Newton along the edge,
/// kept inside the bracket by bisection.
fn refine(s: &SurfaceData<'_>, grid: &Grid, normal: [f64; 3], level: f64, e: GEdge) -> (f64, f64) {
    let (fixed_u, lo, hi, fixed) = match e {
        GEdge::H(i, j) => (false, grid.gu[i], grid.gu[i + 1], grid.gv[j]),
        GEdge::V(i, j) => (true, grid.gv[j], grid.gv[j + 1], grid.gu[i]),
    };
    let uv = |x: f64| if fixed_u { (fixed, x) } else { (x, fixed) };
    let g = |x: f64| {
        let (u, v) = uv(x);
        let d = eval2(s, u, v);
        let dx = if fixed_u { d.sv } else { d.su };
        (dot(normal, d.p) - level, dot(normal, dx))
    };
    let (mut a, mut b) = (lo, hi);
    let (ga, gb) = (g(a).0, g(b).0);
    if ga == 0.0 {
        return uv(a);
    }
    if gb == 0.0 {
        return uv(b);
    }
    // The sign change is there by construction; orient so that g(a) < 0 < g(b).
    if ga > 0.0 {
        core::mem::swap(&mut a, &mut b);
    }
    let mut x = lo + (hi - lo) * (-ga / (gb - ga)).clamp(0.0, 1.0);
    // The point returned is always one evaluated: a Newton step below an ulp would fall
    // on the bracket's end and be replaced by its midpoint.
    for _ in 0..100 {
        let (gx, dgx) = g(x);
        if gx.abs() < 1e-13 {
            break;
        }
        if gx < 0.0 {
            a = x;
        } else {
            b = x;
        }
        let (l, h) = (a.min(b), a.max(b));
        if h - l < 1e-15 * (1.0 + h.abs()) {
            break;
        }
        let newton = x - gx / dgx;
        x = if newton.is_finite() && newton > l && newton < h {
            newton
        } else {
            0.5 * (a + b)
        };
    }
    uv(x)
}

/// A grid cell `(i, j)`: from node `(i, j)` to `(i+1, j+1)`.
type Cell = (usize, usize);

/// A traced piece: its grid edges in order, the cells between them, whether it closes.
type Traced = (Vec<GEdge>, Vec<Cell>, bool);

/// The cells' segments of the zero set of `f − level`, chained: each piece as its grid
/// edges in order, and whether it closes.
fn trace(grid: &Grid, level: f64) -> Vec<Traced> {
    use std::collections::BTreeMap;
    let (nu, nv) = (grid.gu.len(), grid.gv.len());
    let pos = |i: usize, j: usize| grid.f[grid.at(i, j)] - level >= 0.0;
    // Per grid edge with a crossing: the (cell, other edge) pairs it joins.
    let mut links: BTreeMap<GEdge, Vec<(GEdge, Cell)>> = BTreeMap::new();
    let mut add = |a: GEdge, b: GEdge, cell: Cell| {
        links.entry(a).or_default().push((b, cell));
        links.entry(b).or_default().push((a, cell));
    };
    for i in 0..nu - 1 {
        for j in 0..nv - 1 {
            let (s00, s10, s11, s01) = (pos(i, j), pos(i + 1, j), pos(i + 1, j + 1), pos(i, j + 1));
            let (bottom, right, top, left) = (
                GEdge::H(i, j),
                GEdge::V(i + 1, j),
                GEdge::H(i, j + 1),
                GEdge::V(i, j),
            );
            let mut cut = Vec::with_capacity(4);
            if s00 != s10 {
                cut.push(bottom);
            }
            if s10 != s11 {
                cut.push(right);
            }
            if s11 != s01 {
                cut.push(top);
            }
            if s01 != s00 {
                cut.push(left);
            }
            match cut.len() {
                2 => add(cut[0], cut[1], (i, j)),
                4 => {
                    let centre = 0.25
                        * (grid.f[grid.at(i, j)]
                            + grid.f[grid.at(i + 1, j)]
                            + grid.f[grid.at(i + 1, j + 1)]
                            + grid.f[grid.at(i, j + 1)])
                        - level
                        >= 0.0;
                    if centre == s00 {
                        // 00 and 11 joined through the middle: cut off 10 and 01.
                        add(bottom, right, (i, j));
                        add(top, left, (i, j));
                    } else {
                        add(left, bottom, (i, j));
                        add(right, top, (i, j));
                    }
                }
                _ => {}
            }
        }
    }
    let mut used: std::collections::BTreeSet<GEdge> = Default::default();
    let mut out = Vec::new();
    let walk = |start: GEdge, used: &mut std::collections::BTreeSet<GEdge>| {
        let mut edges = vec![start];
        let mut cells = Vec::new();
        used.insert(start);
        let mut prev_cell: Option<Cell> = None;
        let mut cur = start;
        loop {
            let next = links.get(&cur).and_then(|l| {
                l.iter()
                    .find(|(e, c)| Some(*c) != prev_cell && (!used.contains(e) || *e == start))
            });
            let Some(&(e, c)) = next else { break };
            cells.push(c);
            edges.push(e);
            if e == start {
                return (edges, cells, true);
            }
            used.insert(e);
            prev_cell = Some(c);
            cur = e;
        }
        (edges, cells, false)
    };
    let ends: Vec<GEdge> = links
        .iter()
        .filter(|(_, l)| l.len() == 1)
        .map(|(e, _)| *e)
        .collect();
    for e in ends {
        if !used.contains(&e) {
            out.push(walk(e, &mut used));
        }
    }
    let rest: Vec<GEdge> = links.keys().copied().collect();
    for e in rest {
        if !used.contains(&e) {
            out.push(walk(e, &mut used));
        }
    }
    out
}

/// Span index of grid line `i` (cells `i..i+1` lie in span `i / CELLS_PER_SPAN`).
fn span_of_cell(i: usize) -> usize {
    i / CELLS_PER_SPAN
}

fn boundary_edge(grid: &Grid, e: GEdge) -> Option<Edge> {
    let (nu, nv) = (grid.gu.len(), grid.gv.len());
    match e {
        GEdge::H(_, 0) => Some(Edge::V0),
        GEdge::H(_, j) if j == nv - 1 => Some(Edge::V1),
        GEdge::V(0, _) => Some(Edge::U0),
        GEdge::V(i, _) if i == nu - 1 => Some(Edge::U1),
        _ => None,
    }
}

/// The pieces of the plane `level`, refined onto it, unordered and unoriented.
pub fn plane_pieces(
    s: &SurfaceData<'_>,
    grid: &Grid,
    normal: [f64; 3],
    plane: usize,
    level: f64,
) -> Vec<PlanePass> {
    let mut out = Vec::new();
    for (edges, cells, closed) in trace(grid, level) {
        if edges.len() < 2 {
            continue;
        }
        let uv: Vec<(f64, f64)> = edges
            .iter()
            .map(|e| refine(s, grid, normal, level, *e))
            .collect();
        let spans = cells
            .iter()
            .map(|&(i, j)| (span_of_cell(i), span_of_cell(j)))
            .collect();
        let (start_edge, end_edge) = if closed {
            (None, None)
        } else {
            (
                edges.first().and_then(|e| boundary_edge(grid, *e)),
                edges.last().and_then(|e| boundary_edge(grid, *e)),
            )
        };
        out.push(PlanePass {
            plane,
            level_mm: level,
            uv,
            spans,
            closed,
            start_edge,
            end_edge,
        });
    }
    out
}

impl PlanePass {
    fn reverse(&mut self) {
        self.uv.reverse();
        self.spans.reverse();
        core::mem::swap(&mut self.start_edge, &mut self.end_edge);
    }
}

/// The tool side, checked over the grid: `+1` when `S_u × S_v` faces +z.
fn tool_side(
    step: &FreeformStep,
    st: &PlaneCcStrategy,
    s: &SurfaceData<'_>,
    gu: &[f64],
    gv: &[f64],
) -> Result<f64, StepError> {
    let sign = tool_side_sign(s, gu.iter().flat_map(|&u| gv.iter().map(move |&v| (u, v))));
    for &u in gu {
        for &v in gv {
            let l = plane_local(s, u, v, st.normal, sign);
            check_reach(step, u, v, l.as_ref().map(|l| (l.n, l.kappa_min)))?;
            let Some(l) = l else { continue };
            if l.slope < MIN_SLOPE_DEG.to_radians().sin() {
                return Err(StepError {
                    line: st.normal_line,
                    id: Some(st.normal_id),
                    rule: "strategy",
                    message: format!(
                        "the planes of PLANE_CC_STRATEGY #{} are within {MIN_SLOPE_DEG}° of \
                         parallel to surface #{} at (u, v) = ({u:.4}, {v:.4}): the passes would \
                         have to be infinitely close there; choose a normal further from the \
                         surface's normal",
                        st.id, step.surface.id
                    ),
                });
            }
        }
    }
    Ok(sign)
}

/// The grid with `f = n·S` and the plane steps.
pub fn grid(s: &SurfaceData<'_>, st: &PlaneCcStrategy, radius_mm: f64, sign: f64) -> Grid {
    let gu = grid_lines(&distinct(s.knots_u));
    let gv = grid_lines(&distinct(s.knots_v));
    let h_aim = SAFETY * st.scallop_mm;
    let mut f = Vec::with_capacity(gu.len() * gv.len());
    let mut step = Vec::with_capacity(f.capacity());
    let mut local = Vec::with_capacity(f.capacity());
    for &u in &gu {
        for &v in &gv {
            f.push(dot(st.normal, eval2(s, u, v).p));
            match plane_local(s, u, v, st.normal, sign) {
                Some(l) => {
                    let k = (1.0 / radius_mm + l.kappa_cross).max(1e-12);
                    let mut w = (8.0 * h_aim / k).sqrt();
                    if let Some(cap) = st.stepover_mm {
                        w = w.min(cap);
                    }
                    step.push(w * l.slope);
                    local.push((l.slope, l.kappa_cross));
                }
                None => {
                    step.push(0.0);
                    local.push((0.0, 0.0));
                }
            }
        }
    }
    Grid {
        gu,
        gv,
        f,
        step,
        local,
    }
}

/// Plans the plane-parallel passes of a workingstep with a `PLANE_CC_STRATEGY`.
pub fn plan(step: &FreeformStep) -> Result<PlanePath, StepError> {
    let fail = |rule: &'static str, message: String| step_error(step, rule, message);
    let Strategy::PlaneCc(st) = &step.strategy else {
        return Err(fail(
            "internal",
            "plane planner called for another strategy".into(),
        ));
    };
    let s = step.surface.data();
    let r = step.tool.radius_mm();
    let gu = grid_lines(&distinct(s.knots_u));
    let gv = grid_lines(&distinct(s.knots_v));
    let sign = tool_side(step, st, &s, &gu, &gv)?;
    let grid = grid(&s, st, r, sign);
    let (nu, nv) = (grid.gu.len(), grid.gv.len());
    let cells: Vec<(f64, f64, f64)> = (0..nu - 1)
        .flat_map(|i| (0..nv - 1).map(move |j| (i, j)))
        .map(|(i, j)| grid.cell(i, j))
        .collect();
    let (f_lo, f_hi) = grid
        .f
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    let (c_first, c_last) = (f_lo + INSET_MM, f_hi - INSET_MM);
    let min_step = |lo: f64, hi: f64| {
        cells
            .iter()
            .filter(|c| c.1 >= lo && c.0 <= hi)
            .fold(f64::INFINITY, |m, c| m.min(c.2))
    };
    // The scallop the formula predicts between planes `lo` and `hi`.
    let predicted = |lo: f64, hi: f64| {
        let mut h: f64 = 0.0;
        for (k, &(slope, kappa)) in grid.local.iter().enumerate() {
            let fk = grid.f[k];
            if fk >= lo && fk <= hi && slope > 0.0 {
                let w = (hi - lo) / slope;
                h = h.max(w * w / 8.0 * (1.0 / r + kappa));
            }
        }
        h
    };
    let mut levels = vec![c_first];
    let (mut min_d, mut max_d, mut worst_h) = (f64::INFINITY, 0.0f64, 0.0f64);
    let mut c = c_first;
    while c < c_last {
        let d0 = min_step(c, c);
        let d = min_step(c, c + d0);
        if !(d.is_finite() && d > 0.0) {
            return Err(fail(
                "stepover",
                format!("no plane step found at the plane {c:.6} mm along the normal"),
            ));
        }
        let mut next = c + d;
        if next >= c_last - 1e-9 * (1.0 + c_last.abs()) {
            next = c_last;
        } else {
            min_d = min_d.min(d);
        }
        max_d = max_d.max(next - c);
        worst_h = worst_h.max(predicted(c, next));
        levels.push(next);
        c = next;
        if levels.len() > MAX_PLANES {
            return Err(fail(
                "stepover",
                format!(
                    "more than {MAX_PLANES} planes for a scallop height of {} mm",
                    st.scallop_mm
                ),
            ));
        }
    }
    if levels.len() <= 2 {
        min_d = max_d;
    }
    // The cutting direction within a plane: across the tool axis if the planes are not
    // horizontal, else along x.
    let along = {
        let t = cross(st.normal, [0.0, 0.0, 1.0]);
        let l = norm(t);
        if l > 1e-6 {
            scale(t, 1.0 / l)
        } else {
            [1.0, 0.0, 0.0]
        }
    };
    let at = |p: (f64, f64)| eval2(&s, p.0, p.1).p;
    let mut passes = Vec::new();
    let mut planes = 0;
    for (k, &level) in levels.iter().enumerate() {
        let mut pieces = plane_pieces(&s, &grid, st.normal, k, level);
        if pieces.is_empty() {
            continue;
        }
        let flip = st.mode == PathMode::Zigzag && planes % 2 == 1;
        planes += 1;
        for p in &mut pieces {
            let (a, b) = (at(p.uv[0]), at(p.uv[p.uv.len() - 1]));
            let ahead = if p.closed {
                // A loop runs counter-clockwise about the normal.
                let mut area = [0.0; 3];
                for w in p.uv.windows(2) {
                    let c = cross(at(w[0]), at(w[1]));
                    area = [area[0] + c[0], area[1] + c[1], area[2] + c[2]];
                }
                dot(area, st.normal)
            } else {
                dot([b[0] - a[0], b[1] - a[1], b[2] - a[2]], along)
            };
            if (ahead < 0.0) != flip {
                p.reverse();
            }
        }
        // Pieces of one plane in the cutting direction.
        pieces.sort_by(|x, y| {
            let (px, py) = (at(x.uv[0]), at(y.uv[0]));
            dot(px, along).total_cmp(&dot(py, along))
        });
        if flip {
            pieces.reverse();
        }
        passes.extend(pieces);
    }
    let edge_factor = passes
        .iter()
        .flat_map(|p| [end_sine(&s, p, false), end_sine(&s, p, true)])
        .flatten()
        .map(edge_factor)
        .fold(1.0, f64::max);
    let boundary = if edge_factor * worst_h > st.scallop_mm {
        let domain = (grid.gu[0], grid.gu[nu - 1], grid.gv[0], grid.gv[nv - 1]);
        // From where the last pass ends on an edge, else (a loop) from the first corner.
        let (from, edge) = passes
            .last()
            .filter(|p| !p.closed)
            .and_then(|p| Some((*p.uv.last()?, p.end_edge?)))
            .unwrap_or(((domain.0, domain.2), Edge::V0));
        boundary_loop(from, edge, domain)
    } else {
        Vec::new()
    };
    let polyline = |uv: &[(f64, f64)]| {
        uv.windows(2)
            .map(|w| {
                let (a, b) = (at(w[0]), at(w[1]));
                norm([b[0] - a[0], b[1] - a[1], b[2] - a[2]])
            })
            .sum::<f64>()
    };
    // The boundary's straight (u, v) segments through points 1/64 of each apart.
    let boundary_points: Vec<(f64, f64)> = boundary
        .windows(2)
        .flat_map(|w| {
            (0..64).map(move |k| {
                let t = k as f64 / 64.0;
                (
                    w[0].0 + t * (w[1].0 - w[0].0),
                    w[0].1 + t * (w[1].1 - w[0].1),
                )
            })
        })
        .chain(boundary.last().copied())
        .collect();
    let length = passes.iter().map(|p| polyline(&p.uv)).sum::<f64>() + polyline(&boundary_points);
    Ok(PlanePath {
        normal: st.normal,
        mode: st.mode,
        passes,
        planes,
        normal_sign: sign,
        radius_mm: r,
        chordal_mm: st.chordal_mm,
        min_step_mm: min_d,
        max_step_mm: max_d,
        predicted_scallop_mm: worst_h,
        boundary,
        edge_factor,
        length_mm: length,
    })
}

#[cfg(test)]
mod tests;
