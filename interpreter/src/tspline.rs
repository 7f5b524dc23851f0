//! T-spline surfaces (Sederberg, Zheng, Bakenov and Nasri, *T-splines and T-NURCCs*,
//! 2003; machined from STEP-NC as in seed 003), cut exactly into rational bicubic Bézier
//! patches so the existing surface planner, surface blocks and the cycle's surface
//! evaluator run them unchanged.
//!
//! # The surface
//!
//! Degree 3 in `s` and `t`. Each control point `P_i` (weight `w_i > 0`) carries two local
//! knot vectors of five knots, `s_i = (s_i0 … s_i4)` and `t_i = (t_i0 … t_i4)`; its
//! blending function is `B_i(s, t) = N[s_i](s) · N[t_i](t)`, the product of the two cubic
//! B-splines on those knots, and
//!
//! `S(s, t) = Σ w_i P_i B_i(s, t) / Σ w_i B_i(s, t)`.
//!
//! # The T-mesh, in index space
//!
//! The local knots are not free: they come from the T-mesh. The mesh lives in *index
//! space* (as in Bazilevs et al., *Isogeometric analysis using T-splines*, 2010), so that
//! repeated knots, as at a clamped boundary, have lines of their own:
//!
//! * `s_lines[i]` is the `s` value of the `i`-th vertical line (constant `s`), `t_lines[j]`
//!   the `t` value of the `j`-th horizontal line; both non-decreasing, repeats allowed.
//! * The mesh's edges are pieces of these lines: `s_segments` `(i, j0, j1)` a piece of
//!   vertical line `i` from horizontal line `j0` to `j1`, `t_segments` `(j, i0, i1)`. The
//!   two outermost lines on each side (`0, 1, m−1, m`) are whole lines without being
//!   listed; they carry no control points and only end the rays below.
//! * Every control point sits on a vertex `(i, j)` of the mesh (its *anchor*), with
//!   `2 ≤ i ≤ m−2`, `2 ≤ j ≤ n−2`; every vertex in that range carries exactly one. A
//!   T-junction is a vertex where a segment ends on a line that goes on.
//! * **The rule** (Sederberg et al. §3): `s_i2 = s_lines[i]`; `s_i3` and `s_i4` are the
//!   `s` values of the first two vertical segments the ray from the anchor towards `+s`
//!   along horizontal line `j` meets, `s_i1` and `s_i0` the same towards `−s`; the same for
//!   `t` along vertical line `i`. [`TSpline::new`] derives them, or checks the ones given.
//!
//! The surface's domain is `[s_lines[3], s_lines[m−3]] × [t_lines[3], t_lines[n−3]]` (for
//! a clamped boundary, `s_lines[0..=3]` are equal). Its *T-image*, the part machined, is
//! the domain less the mesh's `holes` (rectangles between its lines: a hole inside, a
//! notch at the edge); every cell of it must be covered by some blending function's
//! support.
//!
//! # Bézier extraction
//!
//! Every distinct line value cuts the domain into *T-cells* (seed 003's T-cell matrix).
//! On a cell every blending function is a polynomial, so the surface there is one rational
//! bicubic Bézier patch: each `N[s_i]` restricted to the cell's `[a, b]` is written in the
//! Bernstein basis from its value and derivatives at `a` (`b_0 = c_0`, `b_1 = c_0 + c_1/3`,
//! `b_2 = c_0 + 2c_1/3 + c_2/3`, `b_3 = c_0 + c_1 + c_2 + c_3`, `c_k = N^(k)(a)·h^k/k!`),
//! the homogeneous net is `Σ_i w_i (P_i, 1) · b^s_i ⊗ b^t_i`. The cells refine the faces of
//! the extended T-mesh (a face is cut by the lines of the other faces), so a face gives
//! one or more patches of the same polynomial. This is exact up to rounding: the tests
//! compare it with the direct sum above (a second algorithm) to 1e-12.
//!
//! # T-regions (seed 003)
//!
//! The UV strategy machines the T-image as rectangles of cells, *T-regions*: strips of
//! covered cells in each row (forward direction along `s`) or column (along `t`), merged
//! with the strips next to them that span the same cells ([`regions`]). Each region's
//! patches are joined into one tensor-product NURBS with knots of multiplicity 3 at every
//! inner line ([`TSpline::region_surface`]): the same patches, so the same surface, and the
//! planner's passes, scallop spacing and plane intersections work on it as on any other.
//! A T-image without holes is one region.

use crate::surface_blocks::OwnedSurface;
use shared::nurbs::reference::cox_de_boor_der;

/// The degree in both directions.
pub const DEGREE: usize = 3;
/// More control points than this are refused (the planner allocates per patch).
pub const MAX_POINTS: usize = 100_000;
/// More index lines than this in a direction are refused.
pub const MAX_LINES: usize = 1100;
/// More spans of distinct line values than this across the domain in a direction are
/// refused: a T-region's surface has `3·spans + 1` control points that way, and the
/// reader takes at most 1024.
pub const MAX_CELLS: usize = 341;

/// A problem of a T-spline, with the control point it belongs to (0-based), if any.
#[derive(Debug, Clone, PartialEq)]
pub struct TError {
    pub rule: &'static str,
    pub point: Option<usize>,
    pub message: String,
}

fn terr(rule: &'static str, point: Option<usize>, message: impl Into<String>) -> TError {
    TError {
        rule,
        point,
        message: message.into(),
    }
}

/// The T-mesh in index space (module page).
#[derive(Debug, Clone, PartialEq)]
pub struct TMesh {
    pub s_lines: Vec<f64>,
    pub t_lines: Vec<f64>,
    /// `(i, j0, j1)`: vertical line `i` from horizontal line `j0` to `j1`.
    pub s_segments: Vec<[usize; 3]>,
    /// `(j, i0, i1)`: horizontal line `j` from vertical line `i0` to `i1`.
    pub t_segments: Vec<[usize; 3]>,
    /// `(i0, j0, i1, j1)`: rectangles between those lines left out of the T-image (a
    /// hole, or a notch at its edge): the surface is not machined there.
    pub holes: Vec<[usize; 4]>,
}

impl TMesh {
    fn m(&self) -> usize {
        self.s_lines.len() - 1
    }
    fn n(&self) -> usize {
        self.t_lines.len() - 1
    }
    /// Whether vertical line `i` passes through horizontal index `j`.
    pub fn vertical_at(&self, i: usize, j: usize) -> bool {
        self.vertical_covers(i, j, j)
    }
    /// Whether horizontal line `j` passes through vertical index `i`.
    pub fn horizontal_at(&self, j: usize, i: usize) -> bool {
        self.horizontal_covers(j, i, i)
    }
    /// Sorts the segments by line, as the lookups below need ([`TSpline::new`] does).
    pub fn sort(&mut self) {
        self.s_segments.sort_unstable();
        self.t_segments.sort_unstable();
    }
    /// Whether vertical line `i` has an edge from horizontal index `a` to `b` (segments
    /// sorted: [`TMesh::sort`]).
    pub fn vertical_covers(&self, i: usize, a: usize, b: usize) -> bool {
        i <= 1 || i + 1 >= self.m() || on_line(&self.s_segments, i, a, b)
    }
    /// Whether horizontal line `j` has an edge from vertical index `a` to `b` (segments
    /// sorted: [`TMesh::sort`]).
    pub fn horizontal_covers(&self, j: usize, a: usize, b: usize) -> bool {
        j <= 1 || j + 1 >= self.n() || on_line(&self.t_segments, j, a, b)
    }
    /// The five local knots of an anchor by the rays (module page), `s` then `t`.
    pub fn ray_knots(&self, anchor: [usize; 2]) -> ([f64; 5], [f64; 5]) {
        let [i, j] = anchor;
        let s = ray(&self.s_lines, i, |k| self.vertical_at(k, j));
        let t = ray(&self.t_lines, j, |k| self.horizontal_at(k, i));
        (s, t)
    }
    /// `(s0, s1, t0, t1)`.
    pub fn domain(&self) -> (f64, f64, f64, f64) {
        let (m, n) = (self.m(), self.n());
        (
            self.s_lines[3],
            self.s_lines[m - 3],
            self.t_lines[3],
            self.t_lines[n - 3],
        )
    }
}

/// Whether a segment of line `line` spans `a..=b` (`segs` sorted by line: a binary
/// search finds the line's own, so a check costs its segments, not the mesh's).
fn on_line(segs: &[[usize; 3]], line: usize, a: usize, b: usize) -> bool {
    let from = segs.partition_point(|x| x[0] < line);
    segs[from..]
        .iter()
        .take_while(|x| x[0] == line)
        .any(|&[_, lo, hi]| lo <= a && b <= hi)
}

/// The knots the two rays from line `at` meet: two lines below, `at`, two above.
fn ray(lines: &[f64], at: usize, crossed: impl Fn(usize) -> bool) -> [f64; 5] {
    let mut out = [lines[at]; 5];
    let mut found = 0;
    for k in (0..at).rev() {
        if crossed(k) {
            out[1 - found] = lines[k];
            found += 1;
            if found == 2 {
                break;
            }
        }
    }
    found = 0;
    for (k, &x) in lines.iter().enumerate().skip(at + 1) {
        if crossed(k) {
            out[3 + found] = x;
            found += 1;
            if found == 2 {
                break;
            }
        }
    }
    out
}

/// One control point.
#[derive(Debug, Clone, PartialEq)]
pub struct TPoint {
    /// Its vertex `(i, j)` in index space.
    pub anchor: [usize; 2],
    /// `[x, y, z, w]`: the point and its weight.
    pub ctrl: [f64; 4],
    pub s_knots: [f64; 5],
    pub t_knots: [f64; 5],
}

/// A checked T-spline surface of degree 3.
#[derive(Debug, Clone, PartialEq)]
pub struct TSpline {
    pub mesh: TMesh,
    pub points: Vec<TPoint>,
    /// The T-cells' edges in `s` and `t` (distinct line values in the domain) and, per
    /// cell (`[row · columns + column]`), the points whose blending functions reach it.
    cell_s: Vec<f64>,
    cell_t: Vec<f64>,
    cell_points: Vec<Vec<u32>>,
}

/// A control point as given: its anchor, point and weight, and its local knots if the
/// file gives them (else they are derived from the mesh).
#[derive(Debug, Clone, PartialEq)]
pub struct GivenPoint {
    pub anchor: [usize; 2],
    pub ctrl: [f64; 4],
    pub knots: Option<([f64; 5], [f64; 5])>,
}

fn fmt_knots(k: &[f64; 5]) -> String {
    let v: Vec<String> = k.iter().map(|x| format!("{x}")).collect();
    format!("({})", v.join(", "))
}

fn knots_agree(a: &[f64; 5], b: &[f64; 5], scale: f64) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-9 * scale)
}

impl TSpline {
    /// Checks the mesh and the points against each other (module page) and derives the
    /// local knots the file leaves out. Every problem found is returned.
    pub fn new(mut mesh: TMesh, given: Vec<GivenPoint>) -> Result<TSpline, Vec<TError>> {
        mesh.sort();
        check_mesh(&mesh).map_err(|e| vec![e])?;
        let (m, n) = (mesh.m(), mesh.n());
        let mut errs = Vec::new();
        if given.len() > MAX_POINTS {
            return Err(vec![terr(
                "control points",
                None,
                format!("{} control points exceed {MAX_POINTS}", given.len()),
            )]);
        }
        let scale = mesh
            .s_lines
            .iter()
            .chain(&mesh.t_lines)
            .fold(1.0f64, |a, x| a.max(x.abs()));
        let mut at = vec![vec![None::<usize>; n + 1]; m + 1];
        let mut points = Vec::with_capacity(given.len());
        for (k, g) in given.into_iter().enumerate() {
            let [i, j] = g.anchor;
            let w = g.ctrl[3];
            if !(w > 0.0 && w.is_finite()) {
                errs.push(terr(
                    "weights",
                    Some(k),
                    format!("weight {w} must be a positive finite number"),
                ));
            }
            if !(2..=m.saturating_sub(2)).contains(&i) || !(2..=n.saturating_sub(2)).contains(&j) {
                errs.push(terr(
                    "t-mesh",
                    Some(k),
                    format!(
                        "anchor ({}, {}) is outside lines 3..={} in s and 3..={} in t (the \
                         two outer lines on each side carry no control points)",
                        i + 1,
                        j + 1,
                        m - 1,
                        n - 1
                    ),
                ));
                continue;
            }
            if !(mesh.vertical_at(i, j) && mesh.horizontal_at(j, i)) {
                errs.push(terr(
                    "t-mesh",
                    Some(k),
                    format!(
                        "anchor ({}, {}) is no vertex of the T-mesh: no {} passes through it",
                        i + 1,
                        j + 1,
                        if mesh.vertical_at(i, j) {
                            "horizontal segment"
                        } else {
                            "vertical segment"
                        }
                    ),
                ));
                continue;
            }
            if let Some(other) = at[i][j] {
                errs.push(terr(
                    "t-mesh",
                    Some(k),
                    format!(
                        "anchor ({}, {}) already carries control point {}",
                        i + 1,
                        j + 1,
                        other + 1
                    ),
                ));
                continue;
            }
            at[i][j] = Some(k);
            let (s_knots, t_knots) = mesh.ray_knots(g.anchor);
            if let Some((gs, gt)) = g.knots {
                for (dir, given, ray) in [("s", gs, s_knots), ("t", gt, t_knots)] {
                    if !knots_agree(&given, &ray, scale) {
                        errs.push(terr(
                            "local knots",
                            Some(k),
                            format!(
                                "{dir} knots {} disagree with the T-mesh's rays from anchor \
                                 ({}, {}), which give {}",
                                fmt_knots(&given),
                                i + 1,
                                j + 1,
                                fmt_knots(&ray)
                            ),
                        ));
                    }
                }
            }
            points.push(TPoint {
                anchor: g.anchor,
                ctrl: g.ctrl,
                s_knots,
                t_knots,
            });
        }
        // Every vertex in the anchor range carries a control point.
        for (i, column) in at.iter().enumerate().take(m - 1).skip(2) {
            for (j, point) in column.iter().enumerate().take(n - 1).skip(2) {
                let inner = i > 2 && i + 2 < m && j > 2 && j + 2 < n;
                if inner && point.is_some() {
                    let edges = [
                        mesh.vertical_covers(i, j, j + 1),
                        mesh.vertical_covers(i, j - 1, j),
                        mesh.horizontal_covers(j, i, i + 1),
                        mesh.horizontal_covers(j, i - 1, i),
                    ];
                    if edges.iter().filter(|x| **x).count() < 3 {
                        errs.push(terr(
                            "t-mesh",
                            None,
                            format!(
                                "vertex ({}, {}) has {} edge{}: inside the mesh a vertex \
                                 has four, or three at a T-junction, so every face is a \
                                 rectangle",
                                i + 1,
                                j + 1,
                                edges.iter().filter(|x| **x).count(),
                                if edges.iter().filter(|x| **x).count() == 1 {
                                    ""
                                } else {
                                    "s"
                                }
                            ),
                        ));
                    }
                }
                if point.is_none() && mesh.vertical_at(i, j) && mesh.horizontal_at(j, i) {
                    errs.push(terr(
                        "t-mesh",
                        None,
                        format!(
                            "vertex ({}, {}) of the T-mesh has no control point",
                            i + 1,
                            j + 1
                        ),
                    ));
                }
            }
        }
        if !errs.is_empty() {
            return Err(errs);
        }
        let (cell_s, cell_t) = {
            let (s0, s1, t0, t1) = mesh.domain();
            (
                distinct(&mesh.s_lines, s0, s1),
                distinct(&mesh.t_lines, t0, t1),
            )
        };
        let cols = cell_s.len() - 1;
        let mut cell_points = vec![Vec::new(); cols * (cell_t.len() - 1)];
        // The cells a support reaches: between its first and last knot (at most four
        // columns and four rows of distinct values).
        let range = |edges: &[f64], k: &[f64; 5]| {
            edges.partition_point(|x| *x < k[0])..edges.partition_point(|x| *x < k[4])
        };
        for (k, p) in points.iter().enumerate() {
            let (rs, rt) = (range(&cell_s, &p.s_knots), range(&cell_t, &p.t_knots));
            for row in rt.start..rt.end.min(cell_t.len() - 1) {
                for col in rs.start..rs.end.min(cols) {
                    cell_points[row * cols + col].push(k as u32);
                }
            }
        }
        let ts = TSpline {
            mesh,
            points,
            cell_s,
            cell_t,
            cell_points,
        };
        if !ts.covered().iter().flatten().any(|c| *c) {
            return Err(vec![terr(
                "t-mesh",
                None,
                "the t_image_holes leave nothing of the T-image to machine",
            )]);
        }
        if let Some((a, b, c, d)) = ts.uncovered_cell() {
            return Err(vec![terr(
                "domain",
                None,
                format!(
                    "no blending function covers s {a}..{b}, t {c}..{d}: the T-image has a \
                     hole there"
                ),
            )]);
        }
        Ok(ts)
    }

    /// Distinct line values inside the domain, `s` then `t`: the T-cells' edges.
    pub fn cell_lines(&self) -> (Vec<f64>, Vec<f64>) {
        (self.cell_s.clone(), self.cell_t.clone())
    }

    /// The points whose blending functions reach cell `(col, row)`.
    fn reaching(&self, col: usize, row: usize) -> impl Iterator<Item = &TPoint> {
        let cols = self.cell_s.len() - 1;
        self.cell_points[row * cols + col]
            .iter()
            .map(|&k| &self.points[k as usize])
    }

    /// Whether the cell `[a, b] × [c, d]` lies in one of the mesh's holes.
    fn in_hole(&self, a: f64, b: f64, c: f64, d: f64) -> bool {
        let (sl, tl) = (&self.mesh.s_lines, &self.mesh.t_lines);
        self.mesh
            .holes
            .iter()
            .any(|&[i0, j0, i1, j1]| sl[i0] <= a && b <= sl[i1] && tl[j0] <= c && d <= tl[j1])
    }

    /// A cell of the T-image (not in a hole) that no blending function covers.
    fn uncovered_cell(&self) -> Option<(f64, f64, f64, f64)> {
        let (sl, tl) = (&self.cell_s, &self.cell_t);
        for row in 0..tl.len() - 1 {
            for col in 0..sl.len() - 1 {
                let (a, b, c, d) = (sl[col], sl[col + 1], tl[row], tl[row + 1]);
                if !self.in_hole(a, b, c, d) && self.reaching(col, row).next().is_none() {
                    return Some((a, b, c, d));
                }
            }
        }
        None
    }

    /// The T-cells of the T-image, `[row along t][column along s]`: false in a hole.
    /// (Every other cell is covered by some blending function: [`TSpline::new`] checks.)
    pub fn covered(&self) -> Vec<Vec<bool>> {
        let (sl, tl) = (&self.cell_s, &self.cell_t);
        tl.windows(2)
            .map(|c| {
                sl.windows(2)
                    .map(|a| !self.in_hole(a[0], a[1], c[0], c[1]))
                    .collect()
            })
            .collect()
    }

    /// The number of T-junctions: inner vertices with three edges, where a segment ends
    /// on a line that goes on.
    pub fn t_junctions(&self) -> usize {
        let mesh = &self.mesh;
        let (m, n) = (mesh.m(), mesh.n());
        self.points
            .iter()
            .filter(|p| {
                let [i, j] = p.anchor;
                let inner = i > 2 && i + 2 < m && j > 2 && j + 2 < n;
                let edges = [
                    mesh.vertical_covers(i, j, j + 1),
                    mesh.vertical_covers(i, j - 1, j),
                    mesh.horizontal_covers(j, i, i + 1),
                    mesh.horizontal_covers(j, i - 1, i),
                ];
                inner && edges.iter().filter(|x| **x).count() == 3
            })
            .count()
    }

    /// `S`, `S_s` and `S_t` by the sum over the blending functions (module page): the
    /// reference the Bézier patches are tested against. Spans are half-open, `[k, k')`,
    /// but on the domain's far edges the limit from inside.
    pub fn eval(&self, s: f64, t: f64) -> ([f64; 3], [f64; 3], [f64; 3]) {
        let (_, s1, _, t1) = self.mesh.domain();
        let (mut a, mut a_s, mut a_t) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
        for p in &self.points {
            let (ns, ds) = blend(&p.s_knots, s, s >= s1);
            let (nt, dt) = blend(&p.t_knots, t, t >= t1);
            if ns == 0.0 && ds == 0.0 || nt == 0.0 && dt == 0.0 {
                continue;
            }
            let w = p.ctrl[3];
            let h = [p.ctrl[0] * w, p.ctrl[1] * w, p.ctrl[2] * w, w];
            for k in 0..4 {
                a[k] += h[k] * ns * nt;
                a_s[k] += h[k] * ds * nt;
                a_t[k] += h[k] * ns * dt;
            }
        }
        let w = a[3];
        let pt: [f64; 3] = core::array::from_fn(|k| a[k] / w);
        let d_s = core::array::from_fn(|k| (a_s[k] - a_s[3] * pt[k]) / w);
        let d_t = core::array::from_fn(|k| (a_t[k] - a_t[3] * pt[k]) / w);
        (pt, d_s, d_t)
    }

    /// The rational bicubic Bézier patch of cell `(col, row)` (`[s_c, s_c+1] ×
    /// [t_r, t_r+1]` of [`Self::cell_lines`]): 4 × 4 points `[x, y, z, w]`, `[r][c]` with
    /// `r` along `s`.
    pub fn cell_patch(&self, col: usize, row: usize) -> Result<[[[f64; 4]; 4]; 4], TError> {
        let (a, b) = (self.cell_s[col], self.cell_s[col + 1]);
        let (c, d) = (self.cell_t[row], self.cell_t[row + 1]);
        let mut h = [[[0.0f64; 4]; 4]; 4];
        for p in self.reaching(col, row) {
            let bs = bernstein(&p.s_knots, a, b);
            let bt = bernstein(&p.t_knots, c, d);
            let w = p.ctrl[3];
            let hp = [p.ctrl[0] * w, p.ctrl[1] * w, p.ctrl[2] * w, w];
            for (r, row) in h.iter_mut().enumerate() {
                for (q, cell) in row.iter_mut().enumerate() {
                    let f = bs[r] * bt[q];
                    for k in 0..4 {
                        cell[k] += hp[k] * f;
                    }
                }
            }
        }
        let mut out = [[[0.0f64; 4]; 4]; 4];
        for (r, row) in h.iter().enumerate() {
            for (q, x) in row.iter().enumerate() {
                if x[3] <= 1e-300 || x[3].is_nan() {
                    return Err(terr(
                        "domain",
                        None,
                        format!(
                            "the surface has no weight at a corner of cell s {a}..{b}, t {c}..{d}"
                        ),
                    ));
                }
                out[r][q] = [x[0] / x[3], x[1] / x[3], x[2] / x[3], x[3]];
            }
        }
        Ok(out)
    }

    /// The cells `s_cells × t_cells` (indices into [`Self::cell_lines`]' windows) as one
    /// tensor-product NURBS: the cells' patches joined, knots of multiplicity 3 inside.
    pub fn region_surface(&self, region: &Region) -> Result<OwnedSurface, TError> {
        let (sl, tl) = (&self.cell_s, &self.cell_t);
        let (ks, kt) = (region.s_cells.len(), region.t_cells.len());
        let (n_u, n_v) = (3 * ks + 1, 3 * kt + 1);
        let mut ctrl = vec![[0.0f64; 4]; n_u * n_v];
        for (ci, cs) in region.s_cells.clone().enumerate() {
            for (cj, ct) in region.t_cells.clone().enumerate() {
                let patch = self.cell_patch(cs, ct)?;
                for (r, row) in patch.iter().enumerate() {
                    for (q, x) in row.iter().enumerate() {
                        ctrl[(3 * ci + r) * n_v + 3 * cj + q] = *x;
                    }
                }
            }
        }
        let knots = |lines: &[f64], cells: &std::ops::Range<usize>| {
            let mut k = vec![lines[cells.start]; 4];
            for c in cells.clone() {
                let reps = if c + 1 == cells.end { 4 } else { 3 };
                k.extend(std::iter::repeat_n(lines[c + 1], reps));
            }
            k
        };
        Ok(OwnedSurface {
            degree_u: DEGREE,
            degree_v: DEGREE,
            n_u,
            n_v,
            knots_u: knots(sl, &region.s_cells),
            knots_v: knots(tl, &region.t_cells),
            ctrl,
        })
    }
}

/// The distinct values of `lines` within `lo..=hi`.
fn distinct(lines: &[f64], lo: f64, hi: f64) -> Vec<f64> {
    let mut v: Vec<f64> = lines
        .iter()
        .copied()
        .filter(|x| *x >= lo && *x <= hi)
        .collect();
    v.dedup();
    v
}

fn check_mesh(mesh: &TMesh) -> Result<(), TError> {
    for (name, lines) in [("s", &mesh.s_lines), ("t", &mesh.t_lines)] {
        if lines.len() < 8 {
            return Err(terr(
                "knots",
                None,
                format!(
                    "{name}_knot_lines has {} lines; a cubic T-spline needs at least 8 \
                     (two outer lines, the boundary and one inner span on each side)",
                    lines.len()
                ),
            ));
        }
        if lines.len() > MAX_LINES {
            return Err(terr(
                "knots",
                None,
                format!(
                    "{name}_knot_lines has {} lines, more than {MAX_LINES}",
                    lines.len()
                ),
            ));
        }
        if let Some(k) = lines.iter().position(|x| !x.is_finite()) {
            return Err(terr(
                "knots",
                None,
                format!("{name}_knot_lines: line {} is not a finite number", k + 1),
            ));
        }
        if let Some(k) = lines.windows(2).position(|w| w[0] > w[1]) {
            return Err(terr(
                "knots",
                None,
                format!(
                    "{name}_knot_lines must not decrease: line {} is {}, line {} is {}",
                    k + 1,
                    lines[k],
                    k + 2,
                    lines[k + 1]
                ),
            ));
        }
        let last = lines.len() - 1;
        if lines[3] >= lines[last - 3] {
            return Err(terr(
                "knots",
                None,
                format!(
                    "{name}_knot_lines leave an empty domain: lines 4 and {} are both {}",
                    last - 2,
                    lines[3]
                ),
            ));
        }
        // A value on more than three lines inside (four at an end) makes blending
        // functions that jump there (a torn surface) or vanish.
        let mut k = 0;
        while k < lines.len() {
            let run = lines[k..].iter().take_while(|x| **x == lines[k]).count();
            let at_end = k == 0 || k + run == lines.len();
            if run > if at_end { 4 } else { 3 } {
                return Err(terr(
                    "knots",
                    None,
                    format!(
                        "{name}_knot_lines repeat {} on lines {}..={}: at most 3 times inside \
                         (a cubic's blending functions would tear there) and 4 at an end",
                        lines[k],
                        k + 1,
                        k + run
                    ),
                ));
            }
            k += run;
        }
        let cells = distinct(lines, lines[3], lines[last - 3]).len() - 1;
        if cells > MAX_CELLS {
            return Err(terr(
                "knots",
                None,
                format!(
                    "{name}_knot_lines cut the domain into {cells} spans; at most {MAX_CELLS} \
                     are machined (a T-region's surface would pass {} control points)",
                    crate::step::entities::MAX_READ_CTRL
                ),
            ));
        }
    }
    let (m, n) = (mesh.m(), mesh.n());
    for (name, segs, along, across) in [
        ("s_segments", &mesh.s_segments, m, n),
        ("t_segments", &mesh.t_segments, n, m),
    ] {
        for (k, &[line, a, b]) in segs.iter().enumerate() {
            if line > along || b > across || a >= b {
                return Err(terr(
                    "t-mesh",
                    None,
                    format!(
                        "{name} entry {} ({}, {}, {}) is not a piece of a line: the line \
                         must be 1..={} and the ends increasing within 1..={}",
                        k + 1,
                        line + 1,
                        a + 1,
                        b + 1,
                        along + 1,
                        across + 1
                    ),
                ));
            }
        }
    }
    let (s0, s1, t0, t1) = mesh.domain();
    for (k, &[i0, j0, i1, j1]) in mesh.holes.iter().enumerate() {
        let inside = i1 <= m
            && j1 <= n
            && i0 < i1
            && j0 < j1
            && mesh.s_lines[i0] < mesh.s_lines[i1]
            && mesh.t_lines[j0] < mesh.t_lines[j1]
            && mesh.s_lines[i0] >= s0
            && mesh.s_lines[i1] <= s1
            && mesh.t_lines[j0] >= t0
            && mesh.t_lines[j1] <= t1;
        if !inside {
            return Err(terr(
                "t-mesh",
                None,
                format!(
                    "t_image_holes entry {} ({}, {}, {}, {}) is no rectangle of the domain: \
                     from vertical line i0 to i1 and horizontal line j0 to j1, each pair \
                     increasing in value and within s {s0}..{s1}, t {t0}..{t1}",
                    k + 1,
                    i0 + 1,
                    j0 + 1,
                    i1 + 1,
                    j1 + 1
                ),
            ));
        }
    }
    // Segments end on perpendicular lines (no loose ends). Each end as (i, j).
    let ends = mesh
        .s_segments
        .iter()
        .flat_map(|&[i, j0, j1]| [(true, i, j0), (true, i, j1)])
        .chain(
            mesh.t_segments
                .iter()
                .flat_map(|&[j, i0, i1]| [(false, i0, j), (false, i1, j)]),
        );
    for (vertical, i, j) in ends {
        let crossed = if vertical {
            mesh.horizontal_at(j, i)
        } else {
            mesh.vertical_at(i, j)
        };
        if !crossed {
            let (this, other, line) = if vertical {
                ("vertical", "horizontal", i)
            } else {
                ("horizontal", "vertical", j)
            };
            return Err(terr(
                "t-mesh",
                None,
                format!(
                    "the {this} segment on line {} ends at ({}, {}), where no {other} \
                     segment passes",
                    line + 1,
                    i + 1,
                    j + 1
                ),
            ));
        }
    }
    Ok(())
}

/// The cubic B-spline on the five knots `k` and its derivative at `x` (the triangular
/// scheme, `0/0 = 0`), on spans `[k_r, k_r+1)`, or `(k_r, k_r+1]` when `left` (the limit
/// from below, for the domain's far edge).
pub fn blend(k: &[f64; 5], x: f64, left: bool) -> (f64, f64) {
    let inside = |a: f64, b: f64| {
        if left {
            a < x && x <= b
        } else {
            a <= x && x < b
        }
    };
    if !inside(k[0], k[4]) {
        return (0.0, 0.0);
    }
    let mut n = [0.0f64; 4];
    for r in 0..4 {
        n[r] = if inside(k[r], k[r + 1]) { 1.0 } else { 0.0 };
    }
    let frac = |num: f64, den: f64| if den > 0.0 { num / den } else { 0.0 };
    let mut quad = [0.0f64; 2];
    for d in 1..=3 {
        for r in 0..=(3 - d) {
            n[r] = frac(x - k[r], k[r + d] - k[r]) * n[r]
                + frac(k[r + d + 1] - x, k[r + d + 1] - k[r + 1]) * n[r + 1];
        }
        if d == 2 {
            quad = [n[0], n[1]];
        }
    }
    let der = 3.0 * (frac(quad[0], k[3] - k[0]) - frac(quad[1], k[4] - k[1]));
    (n[0], der)
}

/// The Bernstein coefficients of the cubic B-spline on `k` over `[a, b]` (within one of
/// its spans), from its value and derivatives at `a` (module page).
fn bernstein(k: &[f64; 5], a: f64, b: f64) -> [f64; 4] {
    let h = b - a;
    let d = |order: usize| cox_de_boor_der(0, DEGREE, order, k, a);
    let c0 = d(0);
    let c1 = d(1) * h;
    let c2 = d(2) * h * h / 2.0;
    let c3 = d(3) * h * h * h / 6.0;
    [
        c0,
        c0 + c1 / 3.0,
        c0 + 2.0 * c1 / 3.0 + c2 / 3.0,
        c0 + c1 + c2 + c3,
    ]
}

/// A rectangle of T-cells: column range along `s`, row range along `t`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Region {
    pub s_cells: std::ops::Range<usize>,
    pub t_cells: std::ops::Range<usize>,
}

/// Seed 003's T-regions of a cell matrix `covered[row along t][column along s]`: strips
/// of covered cells in each row (`along_s`) or column, each merged into the region above
/// it when that region spans the same cells and ends at the row before. Regions come out
/// in the order their first strip is found.
pub fn regions(covered: &[Vec<bool>], along_s: bool) -> Vec<Region> {
    let rows = covered.len();
    let cols = covered.first().map_or(0, Vec::len);
    let (outer, inner) = if along_s { (rows, cols) } else { (cols, rows) };
    let at = |o: usize, i: usize| {
        if along_s {
            covered[o][i]
        } else {
            covered[i][o]
        }
    };
    // (strip range along the passes, first and one-past-last row across).
    let mut found: Vec<(std::ops::Range<usize>, usize, usize)> = Vec::new();
    for o in 0..outer {
        let mut i = 0;
        while i < inner {
            if !at(o, i) {
                i += 1;
                continue;
            }
            let start = i;
            while i < inner && at(o, i) {
                i += 1;
            }
            let strip = start..i;
            match found
                .iter_mut()
                .find(|(r, _, end)| *r == strip && *end == o)
            {
                Some(region) => region.2 = o + 1,
                None => found.push((strip, o, o + 1)),
            }
        }
    }
    found
        .into_iter()
        .map(|(strip, a, b)| {
            if along_s {
                Region {
                    s_cells: strip,
                    t_cells: a..b,
                }
            } else {
                Region {
                    s_cells: a..b,
                    t_cells: strip,
                }
            }
        })
        .collect()
}

#[cfg(test)]
mod tests;
