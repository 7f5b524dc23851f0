//! Real-time evaluation of a rational tensor-product surface, its two partial derivatives
//! and its unit normal, by the scheme of seed 000 (Yeh: §3, eq. 13–19) built on the moving
//! data of seed 001 (§3.3).
//!
//! In extended space the surface is the four-component polynomial
//! `r(u, v) = Σ_i Σ_j N_i(u) N_j(v) [w_ij·P_ij, w_ij]` (eq. 17), so `S`, `S_u` and `S_v`
//! share one double sum and one quotient rule (eq. 18–19). The sum is contracted in `v`
//! first: per row `i` of the window, `a_i = Σ_j N_j(v) r_ij` and `b_i = Σ_j N'_j(v) r_ij`,
//! then `r = Σ N_i a_i`, `r_u = Σ N'_i a_i`, `r_v = Σ N_i b_i`: `8(p+1)(q+1) + 12(p+1)`
//! multiply-adds instead of `12(p+1)(q+1)`.
//!
//! Each direction keeps its own span registers ([`super::fast`]); the `(p+1)×(q+1)`
//! window of homogeneous control points is reloaded only when `u` or `v` crosses a knot.
//! Degrees `p = q` in 1..=5 are specialised at compile time, other pairs share a kernel.
//!
//! Moving data across points, too: a tool path over a surface runs in passes along which
//! one parameter is fixed (iso-parametric, zig-zag: seed 000's tool paths, ISO 14649's
//! `UV_STRATEGY`). The evaluator is told which ([`Passes`]) and contracts that parameter
//! first, once per pass: the partial sums (`a_i`, `b_i` above, for every row of the net
//! the pass can reach) depend on the fixed parameter only. Along the pass, each span of
//! the running direction then holds the pass as three four-component polynomials in
//! the running parameter about the span's centre (the point, its derivative along and
//! across the pass), the surface version of the curves' power form: made at each knot
//! crossing from the partial sums and the span's basis power form (computed once with
//! the surface) in `2(p+1)²` multiply-adds, and evaluated at each point by three Horner
//! chains, `3p - 1` vector multiply-adds. The order of every sum is fixed by the
//! [`Passes`] setting alone, never by the history of calls, so an evaluator gives the
//! same bits as a fresh one with the same setting, on any path; a path that does not
//! hold its parameter fixed just redoes the contraction at every point, and
//! [`FastSurface::for_any_path`] contracts the `(p+1)×(q+1)` window directly for paths
//! that hold neither.
//!
//! The quotient rule and the normal share one two-lane division: the tangents'
//! numerators `w·r_u − w_u·r` and `w·r_v − w_v·r` are `w²·S_u` and `w²·S_v`, so their
//! cross product has the normal's direction before any division, and `1/w` and
//! `1/|n|` are taken together. What bounds a point, p = q = 2 on a pass: five vector
//! FMAs, the cross product, one square root and that division, a chain of about 60
//! cycles that consecutive points overlap; the knot crossings (every 12 points on the
//! seed's zig-zag of 100 × 100) add about a fifth (`shared/BENCHMARKS.md`).
//!
//! Capacity (fixed, no allocation): degrees up to [`MAX_SURF_DEGREE`] = 5 and at most
//! [`MAX_SURF_CTRL`] = 16 control points in each direction (8 kB of homogeneous points and
//! 9 kB of span polynomials in the evaluator). Control points are row-major: `ctrl[i * n_v + j]` is `P_ij`, `i` along
//! `u`, stored `[x, y, z, w]` with the weight not premultiplied.

use super::fast::{axpy, basis_power_matrix, horner, SpanCursor, ORD};
use super::{validate, CurveError};

/// The highest degree in either direction of a surface.
pub const MAX_SURF_DEGREE: usize = 5;
/// The most control points in either direction of a surface.
pub const MAX_SURF_CTRL: usize = 16;
/// Knots per direction at full capacity.
pub const MAX_SURF_KNOTS: usize = MAX_SURF_CTRL + MAX_SURF_DEGREE + 1;

const SORD: usize = MAX_SURF_DEGREE + 1;

/// A surface given as slices, as the references and [`FastSurface::new`] take it.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceData<'a> {
    pub degree_u: usize,
    pub degree_v: usize,
    pub knots_u: &'a [f64],
    pub knots_v: &'a [f64],
    /// Control points along `u` and along `v`.
    pub n_u: usize,
    pub n_v: usize,
    /// `n_u * n_v` points `[x, y, z, w]`, row-major: `ctrl[i * n_v + j]`.
    pub ctrl: &'a [[f64; 4]],
}

impl SurfaceData<'_> {
    /// Checks the surface against [`MAX_SURF_DEGREE`] and [`MAX_SURF_CTRL`] (the
    /// references accept any size the same checks pass with `max_ctrl`).
    pub fn validate(&self, max_ctrl: usize) -> Result<(), SurfaceError> {
        let expected = self.n_u.saturating_mul(self.n_v);
        if self.ctrl.len() != expected {
            return Err(SurfaceError::CtrlCount {
                n_ctrl: self.ctrl.len() as u32,
                expected: expected as u32,
            });
        }
        // The knot checks of a curve apply per direction; `validate` wants control points
        // only to count them, so a prefix of the grid of the right length stands in.
        let dirs = [
            (Direction::U, self.degree_u, self.knots_u, self.n_u),
            (Direction::V, self.degree_v, self.knots_v, self.n_v),
        ];
        for (dir, degree, knots, n) in dirs {
            if degree > MAX_SURF_DEGREE {
                return Err(SurfaceError::DegreeTooHigh {
                    dir,
                    degree: degree as u32,
                });
            }
            let pts = self.ctrl.get(..n).ok_or(SurfaceError::CtrlCount {
                n_ctrl: self.ctrl.len() as u32,
                expected: expected as u32,
            })?;
            validate(degree, knots, pts, max_ctrl)
                .map_err(|err| SurfaceError::Knots { dir, err })?;
        }
        if self.ctrl.iter().flatten().any(|c| !c.is_finite()) {
            return Err(SurfaceError::NotFinite);
        }
        if let Some(i) = self.ctrl.iter().position(|c| c[3] <= 0.0) {
            return Err(SurfaceError::WeightNotPositive {
                row: (i / self.n_v.max(1)) as u32,
                col: (i % self.n_v.max(1)) as u32,
            });
        }
        Ok(())
    }
}

/// A parametric direction of a surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    U,
    V,
}

/// What is wrong with a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SurfaceError {
    /// The knots, degree or count of one direction, as for a curve.
    Knots {
        dir: Direction,
        err: CurveError,
    },
    DegreeTooHigh {
        dir: Direction,
        degree: u32,
    },
    CtrlCount {
        n_ctrl: u32,
        expected: u32,
    },
    WeightNotPositive {
        row: u32,
        col: u32,
    },
    NotFinite,
}

impl core::fmt::Display for SurfaceError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            SurfaceError::Knots { dir, err } => write!(f, "{dir:?} direction: {err}"),
            SurfaceError::DegreeTooHigh { dir, degree } => write!(
                f,
                "{dir:?} direction: degree {degree} exceeds the surface limit of {MAX_SURF_DEGREE}"
            ),
            SurfaceError::CtrlCount { n_ctrl, expected } => write!(
                f,
                "{n_ctrl} control points given, {expected} expected (n_u x n_v)"
            ),
            SurfaceError::WeightNotPositive { row, col } => {
                write!(f, "weight of control point ({row}, {col}) is not > 0")
            }
            SurfaceError::NotFinite => write!(f, "a coordinate or weight is not a finite number"),
        }
    }
}

/// A surface point with its partial derivatives and unit normal.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SurfacePoint {
    pub p: [f64; 3],
    pub du: [f64; 3],
    pub dv: [f64; 3],
    /// `S_u × S_v / |S_u × S_v|`; zero where the surface is degenerate (`S_u ∥ S_v`).
    pub normal: [f64; 3],
    pub span_u: usize,
    pub span_v: usize,
}

/// The unit normal from the two tangents, zero at a degenerate point.
#[inline(always)]
pub fn unit_normal(du: [f64; 3], dv: [f64; 3]) -> [f64; 3] {
    let n = [
        du[1] * dv[2] - du[2] * dv[1],
        du[2] * dv[0] - du[0] * dv[2],
        du[0] * dv[1] - du[1] * dv[0],
    ];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    if len > 0.0 {
        let inv = 1.0 / len;
        [n[0] * inv, n[1] * inv, n[2] * inv]
    } else {
        [0.0; 3]
    }
}

/// Which parameter the tool path holds fixed pass by pass (see the module docs): the
/// evaluator contracts that direction first and keeps the partial sums while it stays.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Passes {
    /// Passes run along `u`, `v` fixed in each (the contraction order of seed 000 eq. 17).
    #[default]
    AlongU,
    /// Passes run along `v`, `u` fixed in each.
    AlongV,
}

/// Surface evaluator with moving data in both directions.
#[derive(Debug, Clone)]
pub struct FastSurface {
    cu: SpanCursor<MAX_SURF_KNOTS>,
    cv: SpanCursor<MAX_SURF_KNOTS>,
    degree_u: usize,
    degree_v: usize,
    n_u: usize,
    n_v: usize,
    /// `[w·x, w·y, w·z, w]` of `P_ij` at `hw[i][j]`.
    hw: [[[f64; 4]; MAX_SURF_CTRL]; MAX_SURF_CTRL],
    /// `hw[span_u-p+r][span_v-q+c]` at `win[r][c]` (for paths that hold neither parameter).
    win: [[[f64; 4]; SORD]; SORD],
    /// `None`: a path that holds neither parameter ([`FastSurface::for_any_path`]).
    passes: Option<Passes>,
    /// The fixed parameter's bits the partial sums below belong to (`None` until the
    /// first point).
    key: Option<u64>,
    /// Partial sums over the fixed direction, for every control point index `k` of the
    /// running direction: `part_n[k] = Σ_r N_r(fixed) r_{..}` and `part_d` the same with
    /// the fixed direction's `N'` (rows of the net for `AlongU`, columns for `AlongV`).
    /// They hold through the whole pass, whatever spans the running parameter crosses.
    part_n: [[f64; 4]; MAX_SURF_CTRL],
    part_d: [[f64; 4]; MAX_SURF_CTRL],
    /// The running direction's span the polynomials below belong to (`usize::MAX` when
    /// they are stale).
    pass_span: usize,
    /// Centre of that span: the polynomials are in `t = (running parameter) - mid`.
    mid: f64,
    /// The pass through the span as polynomials in the running parameter (moving data
    /// of the pass: the partial sums through the span's basis power form): the point
    /// `c0`, its derivative along the pass `c1`, and its derivative across `cx`.
    c0: [[f64; 4]; ORD],
    c1: [[f64; 4]; ORD],
    cx: [[f64; 4]; ORD],
    /// Per direction (`[u, v]`) and span, the centre and the basis functions' power
    /// form ([`basis_power_matrix`]): computed once with the surface, so crossing a knot
    /// costs `2(p+1)²` multiply-adds and no recurrence.
    spans: [SpanPolys; 2],
    /// Whether the AVX2 kernel may run (same operations, same bits; see
    /// [`super::fast`]).
    simd: bool,
}

/// The power form of the basis of every span of one direction.
#[derive(Debug, Clone)]
struct SpanPolys {
    /// `mid[s]`: the centre of span `s`.
    mid: [f64; MAX_SURF_CTRL],
    /// `mat[s][k][j]`: coefficient of `t^k` of `N_{s-p+j}(mid[s] + t)`.
    mat: [[[f64; SORD]; SORD]; MAX_SURF_CTRL],
}

impl SpanPolys {
    /// For every non-empty span of the cursor's knots (the cursor is moved).
    fn new(c: &mut SpanCursor<MAX_SURF_KNOTS>, n_ctrl: usize) -> Self {
        let mut out = SpanPolys {
            mid: [0.0; MAX_SURF_CTRL],
            mat: [[[0.0; SORD]; SORD]; MAX_SURF_CTRL],
        };
        let first = c.span();
        for s in c.degree()..n_ctrl.min(MAX_SURF_CTRL) {
            if c.knot(s) < c.knot(s + 1) {
                c.load(s);
                let (m, mat) = basis_power_matrix(c);
                out.mid[s] = m;
                for (dst, src) in out.mat[s].iter_mut().zip(&mat) {
                    for (d, x) in dst.iter_mut().zip(src) {
                        *d = *x;
                    }
                }
            }
        }
        c.load(first);
        out
    }
}

impl FastSurface {
    /// Checks the surface against the capacity and positions on its first spans.
    pub fn new(s: &SurfaceData<'_>) -> Result<Self, SurfaceError> {
        s.validate(MAX_SURF_CTRL)?;
        let mut hw = [[[0.0; 4]; MAX_SURF_CTRL]; MAX_SURF_CTRL];
        for (i, row) in s.ctrl.chunks_exact(s.n_v).enumerate() {
            for (j, c) in row.iter().enumerate() {
                hw[i][j] = [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]];
            }
        }
        let mut cu = SpanCursor::new(s.degree_u, s.knots_u, s.n_u);
        let mut cv = SpanCursor::new(s.degree_v, s.knots_v, s.n_v);
        let spans = [
            SpanPolys::new(&mut cu, s.n_u),
            SpanPolys::new(&mut cv, s.n_v),
        ];
        let mut out = FastSurface {
            cu,
            cv,
            degree_u: s.degree_u,
            degree_v: s.degree_v,
            n_u: s.n_u,
            n_v: s.n_v,
            hw,
            win: [[[0.0; 4]; SORD]; SORD],
            passes: Some(Passes::default()),
            key: None,
            part_n: [[0.0; 4]; MAX_SURF_CTRL],
            part_d: [[0.0; 4]; MAX_SURF_CTRL],
            pass_span: usize::MAX,
            mid: 0.0,
            c0: [[0.0; 4]; ORD],
            c1: [[0.0; 4]; ORD],
            cx: [[0.0; 4]; ORD],
            spans,
            simd: super::fast::simd_available(),
        };
        out.load_window();
        Ok(out)
    }

    /// The same evaluator for a tool path whose passes run as `passes` says.
    pub fn with_passes(s: &SurfaceData<'_>, passes: Passes) -> Result<Self, SurfaceError> {
        let mut out = Self::new(s)?;
        out.passes = Some(passes);
        Ok(out)
    }

    /// The same evaluator for a path that holds neither parameter fixed: it keeps
    /// nothing between points and contracts the `(p+1)×(q+1)` window directly (the
    /// double sum in `v` first) at every point.
    pub fn for_any_path(s: &SurfaceData<'_>) -> Result<Self, SurfaceError> {
        let mut out = Self::new(s)?;
        out.passes = None;
        Ok(out)
    }

    fn load_window(&mut self) {
        let (p, q) = (self.degree_u, self.degree_v);
        let (su, sv) = (self.cu.span(), self.cv.span());
        for (wrow, hrow) in self.win.iter_mut().zip(&self.hw[su - p..=su]) {
            for (w, h) in wrow.iter_mut().zip(&hrow[sv - q..=sv]) {
                *w = *h;
            }
        }
    }

    /// `(u_min, u_max, v_min, v_max)`.
    pub fn domain(&self) -> (f64, f64, f64, f64) {
        let (u0, u1) = (
            self.cu.clamp(f64::NEG_INFINITY),
            self.cu.clamp(f64::INFINITY),
        );
        let (v0, v1) = (
            self.cv.clamp(f64::NEG_INFINITY),
            self.cv.clamp(f64::INFINITY),
        );
        (u0, u1, v0, v1)
    }

    /// `S`, `S_u`, `S_v` and the unit normal at `(u, v)`, each clamped into its domain.
    #[inline]
    pub fn eval(&mut self, u: f64, v: f64) -> SurfacePoint {
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            // SAFETY: `simd` is set only when the running CPU reports AVX2 and FMA.
            return unsafe { self.eval_avx2(u, v) };
        }
        self.eval_baseline(u, v)
    }

    /// [`Self::eval`] without the AVX2 kernel: for the test that both give the same bits.
    #[doc(hidden)]
    #[inline(never)]
    pub fn eval_baseline(&mut self, u: f64, v: f64) -> SurfacePoint {
        self.dispatch(u, v)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    fn eval_avx2(&mut self, u: f64, v: f64) -> SurfacePoint {
        self.dispatch(u, v)
    }

    #[inline(always)]
    fn dispatch(&mut self, u: f64, v: f64) -> SurfacePoint {
        match (self.degree_u, self.degree_v) {
            (1, 1) => self.eval_deg(1, 1, u, v),
            (2, 2) => self.eval_deg(2, 2, u, v),
            (3, 3) => self.eval_deg(3, 3, u, v),
            (4, 4) => self.eval_deg(4, 4, u, v),
            (5, 5) => self.eval_deg(5, 5, u, v),
            (p, q) => self.eval_deg(p, q, u, v),
        }
    }

    #[inline(always)]
    fn eval_deg(&mut self, p: usize, q: usize, u: f64, v: f64) -> SurfacePoint {
        let (u, moved_u) = self.cu.enter(u);
        let (v, moved_v) = self.cv.enter(v);
        let (p, q) = (p.min(MAX_SURF_DEGREE), q.min(MAX_SURF_DEGREE));
        let (r0, ru, rv) = match self.passes {
            Some(Passes::AlongU) => {
                // v fixed: the pass is Σ_i N_i(u) a_i with a_i = Σ_j N_j(v) r_ij, and its
                // derivative across Σ_i N_i(u) b_i with b_i = Σ_j N'_j(v) r_ij.
                if self.key != Some(v.to_bits()) {
                    self.contract(Direction::V, v);
                    self.key = Some(v.to_bits());
                }
                if self.pass_span != self.cu.span() {
                    self.load_pass(Direction::U, p);
                }
                self.pass_at(p, u - self.mid)
            }
            Some(Passes::AlongV) => {
                // u fixed: the same with the roles of u and v exchanged.
                if self.key != Some(u.to_bits()) {
                    self.contract(Direction::U, u);
                    self.key = Some(u.to_bits());
                }
                if self.pass_span != self.cv.span() {
                    self.load_pass(Direction::V, q);
                }
                let (r0, rv, ru) = self.pass_at(q, v - self.mid);
                (r0, ru, rv)
            }
            None => {
                if moved_u || moved_v {
                    self.load_window();
                }
                // Per row r of the window, a_r = Σ_c N_c(v) r_rc and b_r = Σ_c N'_c(v) r_rc.
                let bv = self.cv.ders(q, v);
                let bu = self.cu.ders(p, u);
                let (mut r0, mut ru, mut rv) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
                for (r, row) in self.win.iter().enumerate().take(p + 1) {
                    let (mut a, mut b) = ([0.0f64; 4], [0.0f64; 4]);
                    for (c, pt) in row.iter().enumerate().take(q + 1) {
                        fma4(&mut a, bv.n[c], pt);
                        fma4(&mut b, bv.d1[c], pt);
                    }
                    fma4(&mut r0, bu.n[r], &a);
                    fma4(&mut ru, bu.d1[r], &a);
                    fma4(&mut rv, bu.n[r], &b);
                }
                (r0, ru, rv)
            }
        };
        quotient(&r0, &ru, &rv, self.cu.span(), self.cv.span())
    }

    /// The partial sums over the fixed direction `dir` at its parameter `x`, for every
    /// control point index of the running direction; the pass polynomials go stale.
    /// Out of the kernels and without fused operations (once per pass), so both kernels
    /// share it.
    #[inline(never)]
    fn contract(&mut self, dir: Direction, x: f64) {
        match dir {
            Direction::V => {
                let (q, sv) = (self.degree_v, self.cv.span());
                let b = self.cv.ders(q, x);
                for (i, row) in self.hw.iter().enumerate().take(self.n_u) {
                    let (mut a, mut d) = ([0.0f64; 4], [0.0f64; 4]);
                    for (c, pt) in row[sv - q..=sv].iter().enumerate() {
                        axpy(&mut a, b.n[c], pt);
                        axpy(&mut d, b.d1[c], pt);
                    }
                    self.part_n[i] = a;
                    self.part_d[i] = d;
                }
            }
            Direction::U => {
                let (p, su) = (self.degree_u, self.cu.span());
                let b = self.cu.ders(p, x);
                let rows = &self.hw[su - p..=su];
                for j in 0..self.n_v {
                    let (mut a, mut d) = ([0.0f64; 4], [0.0f64; 4]);
                    for (r, row) in rows.iter().enumerate() {
                        axpy(&mut a, b.n[r], &row[j]);
                        axpy(&mut d, b.d1[r], &row[j]);
                    }
                    self.part_n[j] = a;
                    self.part_d[j] = d;
                }
            }
        }
        self.pass_span = usize::MAX;
    }

    /// The pass through the running direction's current span as polynomials about the
    /// span's centre, from the partial sums and the span's basis power form: once per
    /// pass and span, `2(deg+1)²` multiply-adds.
    #[inline(always)]
    #[allow(clippy::needless_range_loop)] // the indices are the formula's
    fn load_pass(&mut self, running: Direction, deg: usize) {
        let (cursor, polys) = match running {
            Direction::U => (&self.cu, &self.spans[0]),
            Direction::V => (&self.cv, &self.spans[1]),
        };
        let (deg, s) = (deg.min(MAX_SURF_DEGREE), cursor.span());
        let (mid, mat) = (polys.mid[s], &polys.mat[s]);
        let (pn, pd) = (&self.part_n[s - deg..=s], &self.part_d[s - deg..=s]);
        for k in 0..=deg {
            let (mut a, mut b) = ([0.0f64; 4], [0.0f64; 4]);
            for j in 0..=deg {
                fma4(&mut a, mat[k][j], &pn[j]);
                fma4(&mut b, mat[k][j], &pd[j]);
            }
            self.c0[k] = a;
            self.cx[k] = b;
        }
        for k in 0..deg {
            let f = (k + 1) as f64;
            for i in 0..4 {
                self.c1[k][i] = f * self.c0[k + 1][i];
            }
        }
        self.mid = mid;
        self.pass_span = s;
    }

    /// The homogeneous point, its derivative along the pass and across it, at `t` from
    /// the running span's centre: three Horner chains of degree `deg`, `deg - 1`, `deg`.
    #[inline(always)]
    fn pass_at(&self, deg: usize, t: f64) -> ([f64; 4], [f64; 4], [f64; 4]) {
        let r0 = horner(&self.c0, deg, t);
        let along = horner(&self.c1, deg.saturating_sub(1), t);
        let across = horner(&self.cx, deg, t);
        (r0, along, across)
    }
}

/// Extended space back to Cartesian (seed 000 eq. 18–19) and the unit normal, from the
/// homogeneous point `r` and its partial derivatives. With `w = r[3]`, the tangents'
/// numerators `a = w·r_u − r_u[3]·r` and `b = w·r_v − r_v[3]·r` are `w²·S_u` and `w²·S_v`,
/// so `a × b` has the normal's direction already: its length and `w` are inverted by one
/// two-lane division, instead of the normal waiting for the division that makes `S_u`.
#[inline(always)]
fn quotient(
    r: &[f64; 4],
    ru: &[f64; 4],
    rv: &[f64; 4],
    span_u: usize,
    span_v: usize,
) -> SurfacePoint {
    let w = r[3];
    let (mut a, mut b) = ([0.0; 3], [0.0; 3]);
    for k in 0..3 {
        a[k] = ru[k].mul_add(w, -ru[3] * r[k]);
        b[k] = rv[k].mul_add(w, -rv[3] * r[k]);
    }
    let n = [
        a[1].mul_add(b[2], -a[2] * b[1]),
        a[2].mul_add(b[0], -a[0] * b[2]),
        a[0].mul_add(b[1], -a[1] * b[0]),
    ];
    let len = n[0].mul_add(n[0], n[1].mul_add(n[1], n[2] * n[2])).sqrt();
    let [inv_w, inv_len] = [1.0 / w, 1.0 / len];
    let inv_w2 = inv_w * inv_w;
    let normal = if len > 0.0 {
        [n[0] * inv_len, n[1] * inv_len, n[2] * inv_len]
    } else {
        [0.0; 3]
    };
    SurfacePoint {
        p: [r[0] * inv_w, r[1] * inv_w, r[2] * inv_w],
        du: [a[0] * inv_w2, a[1] * inv_w2, a[2] * inv_w2],
        dv: [b[0] * inv_w2, b[1] * inv_w2, b[2] * inv_w2],
        normal,
        span_u,
        span_v,
    }
}

/// `acc += s · c` on a homogeneous point with fused multiply-adds (one rounding each, so
/// every CPU gives the same bits).
#[inline(always)]
fn fma4(acc: &mut [f64; 4], s: f64, c: &[f64; 4]) {
    for i in 0..4 {
        acc[i] = s.mul_add(c[i], acc[i]);
    }
}

// ORD bounds the cursor's basis arrays; the surface window must fit in them.
const _: () = assert!(SORD <= ORD);

#[cfg(test)]
mod tests {
    //! The fast surface against the conventional method and the standard A2.3 algorithm
    //! (positions 1e-12, derivatives 1e-9, relative to the larger of the value and the
    //! size of the control net), against central finite differences (1e-6 relative, the
    //! truncation error of h = 1e-5 of the domain), and the normal's unit length and
    //! orthogonality (1e-12).

    use super::*;
    use crate::nurbs::reference::{conventional_surface, piegl_tiller_surface};
    use proptest::prelude::*;

    #[derive(Debug, Clone)]
    struct Surf {
        p: usize,
        q: usize,
        ku: Vec<f64>,
        kv: Vec<f64>,
        n_u: usize,
        n_v: usize,
        ctrl: Vec<[f64; 4]>,
    }

    impl Surf {
        fn data(&self) -> SurfaceData<'_> {
            SurfaceData {
                degree_u: self.p,
                degree_v: self.q,
                knots_u: &self.ku,
                knots_v: &self.kv,
                n_u: self.n_u,
                n_v: self.n_v,
                ctrl: &self.ctrl,
            }
        }
        fn scale(&self) -> f64 {
            self.ctrl
                .iter()
                .flat_map(|c| c[..3].iter())
                .fold(1.0f64, |a, b| a.max(b.abs()))
        }
    }

    /// The seed's test case (seed 000 §4): 10x10 control points, p = q = 2, uniform
    /// interior knots 0.125 apart; a wavy grid 10 mm apart, weights 1 as in the seed or
    /// varying in 0.5..2 to exercise the rational part.
    fn seed_surface(rational: bool) -> Surf {
        let knots = vec![
            0.0, 0.0, 0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0, 1.0, 1.0,
        ];
        let mut ctrl = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                let (x, y) = (10.0 * i as f64, 10.0 * j as f64);
                let z = 5.0 * (0.7 * i as f64).sin() * (0.5 * j as f64).cos();
                let w = if rational {
                    1.25 + 0.75 * (1.3 * i as f64 + 0.4 * j as f64).sin()
                } else {
                    1.0
                };
                ctrl.push([x, y, z, w]);
            }
        }
        Surf {
            p: 2,
            q: 2,
            ku: knots.clone(),
            kv: knots,
            n_u: 10,
            n_v: 10,
            ctrl,
        }
    }

    fn max_diff(a: [f64; 3], b: [f64; 3]) -> f64 {
        (0..3).fold(0.0f64, |m, k| m.max((a[k] - b[k]).abs()))
    }

    fn max_abs(a: [f64; 3]) -> f64 {
        max_diff(a, [0.0; 3])
    }

    fn mismatch(got: &SurfacePoint, want: &SurfacePoint, scale: f64) -> Option<String> {
        let checks = [
            ("S", got.p, want.p, 1e-12),
            ("S_u", got.du, want.du, 1e-9),
            ("S_v", got.dv, want.dv, 1e-9),
        ];
        for (name, g, w, tol) in checks {
            let err = max_diff(g, w) / max_abs(w).max(scale);
            if err > tol || err.is_nan() {
                return Some(format!("{name}: {g:?} vs {w:?} (relative {err:e})"));
            }
        }
        if (got.span_u, got.span_v) != (want.span_u, want.span_v) {
            return Some("spans differ".into());
        }
        None
    }

    fn check_normal(e: &SurfacePoint) {
        let n = e.normal;
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-12, "|n| = {len}");
        for t in [e.du, e.dv] {
            let dot = n[0] * t[0] + n[1] * t[1] + n[2] * t[2];
            assert!(dot.abs() < 1e-12 * max_abs(t), "n . t = {dot}");
        }
    }

    #[test]
    fn seed_case_matches_references_finite_differences_and_normal() {
        for (rational, passes) in [
            (false, Some(Passes::AlongU)),
            (true, Some(Passes::AlongU)),
            (true, Some(Passes::AlongV)),
            (true, None),
        ] {
            let s = seed_surface(rational);
            let mut f = match passes {
                Some(passes) => FastSurface::with_passes(&s.data(), passes),
                None => FastSurface::for_any_path(&s.data()),
            }
            .expect("valid surface");
            let n = 48;
            // Zig-zag: rows of increasing u, alternately increasing and decreasing v,
            // through every knot line (multiples of 1/8 are hit exactly).
            for i in 0..=n {
                for jj in 0..=n {
                    let j = if i % 2 == 0 { jj } else { n - jj };
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    let e = f.eval(u, v);
                    for want in [
                        piegl_tiller_surface(&s.data(), u, v),
                        conventional_surface(&s.data(), u, v),
                    ] {
                        if let Some(m) = mismatch(&e, &want, s.scale()) {
                            panic!("rational {rational}, {passes:?}, at ({u}, {v}): {m}");
                        }
                    }
                    check_normal(&e);
                    // Central differences away from knot lines (the second derivative
                    // jumps there).
                    let h = 1e-5;
                    let off = |x: f64| (x * 8.0 - (x * 8.0).round()).abs() > 8.0 * h * 2.0;
                    if off(u) && off(v) {
                        let mut g = FastSurface::new(&s.data()).expect("valid surface");
                        let (up, um) = (g.eval(u + h, v).p, g.eval(u - h, v).p);
                        let (vp, vm) = (g.eval(u, v + h).p, g.eval(u, v - h).p);
                        for k in 0..3 {
                            let fu = (up[k] - um[k]) / (2.0 * h);
                            let fv = (vp[k] - vm[k]) / (2.0 * h);
                            let su = max_abs(e.du).max(1.0);
                            let sv = max_abs(e.dv).max(1.0);
                            assert!((fu - e.du[k]).abs() < 1e-6 * su, "S_u {fu} vs {}", e.du[k]);
                            assert!((fv - e.dv[k]).abs() < 1e-6 * sv, "S_v {fv} vs {}", e.dv[k]);
                        }
                    }
                }
            }
        }
    }

    fn knot_vector(p: usize, gaps: &[f64]) -> Vec<f64> {
        let mut knots = vec![0.0; p + 1];
        let (mut t, mut run) = (0.0, 0);
        let last = gaps.len() - 1;
        for (i, &g) in gaps.iter().enumerate() {
            let g = if g == 0.0 && (i == 0 || i == last || run + 1 >= p) {
                0.5
            } else {
                g
            };
            run = if g == 0.0 { run + 1 } else { 0 };
            t += g;
            if i == last {
                knots.extend(std::iter::repeat_n(t, p + 1));
            } else {
                knots.push(t);
            }
        }
        knots
    }

    /// Random rational surfaces: degrees 1..=5 each way, up to 16x16 control points,
    /// repeated interior knots, weights 0.2..5.
    fn random_surface() -> impl Strategy<Value = Surf> {
        (1usize..=5, 1usize..=5, 0usize..=6, 0usize..=6)
            .prop_flat_map(|(p, q, eu, ev)| {
                let (n_u, n_v) = (p + 1 + eu, q + 1 + ev);
                let pt = (-50.0f64..50.0, -50.0f64..50.0, -50.0f64..50.0, 0.2f64..5.0);
                let gaps = |e: usize| {
                    proptest::collection::vec(prop_oneof![3 => 0.1f64..1.0, 1 => Just(0.0)], e + 1)
                };
                (
                    Just((p, q, n_u, n_v)),
                    gaps(eu),
                    gaps(ev),
                    proptest::collection::vec(pt, n_u * n_v),
                )
            })
            .prop_map(|((p, q, n_u, n_v), gu, gv, ctrl)| Surf {
                p,
                q,
                ku: knot_vector(p, &gu),
                kv: knot_vector(q, &gv),
                n_u,
                n_v,
                ctrl: ctrl.into_iter().map(|(x, y, z, w)| [x, y, z, w]).collect(),
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn random_surfaces_match_references_and_fresh_evaluators(
            s in random_surface(),
            uv in proptest::collection::vec((-0.05f64..1.05, -0.05f64..1.05), 1..30),
        ) {
            let mut f = FastSurface::new(&s.data()).expect("valid surface");
            let (u1, v1) = (s.ku[s.n_u], s.kv[s.n_v]);
            let mut pts: Vec<(f64, f64)> = uv.iter().map(|&(a, b)| (a * u1, b * v1)).collect();
            // Exact knot hits, both ends and the corners.
            pts.extend(s.ku.iter().zip(s.kv.iter().rev()).map(|(&a, &b)| (a, b)));
            pts.extend([(0.0, 0.0), (u1, v1), (0.0, v1), (u1, 0.0)]);
            // Iso-parametric passes both ways through the first random point.
            let (pu, pv) = pts[0];
            pts.extend((0..=20).map(|k| (k as f64 / 20.0 * u1, pv)));
            pts.extend((0..=20).map(|k| (pu, k as f64 / 20.0 * v1)));
            let mut along_v = FastSurface::with_passes(&s.data(), Passes::AlongV).expect("valid");
            let mut free = FastSurface::for_any_path(&s.data()).expect("valid");
            let mut baseline = FastSurface::new(&s.data()).expect("valid surface");
            let mut baseline_v = FastSurface::with_passes(&s.data(), Passes::AlongV).expect("valid");
            for (u, v) in pts {
                let e = f.eval(u, v);
                let mut g = FastSurface::new(&s.data()).expect("valid surface");
                prop_assert_eq!(e, g.eval(u, v));
                prop_assert_eq!(e, baseline.eval_baseline(u, v), "AVX2 and baseline kernels");
                let t = along_v.eval(u, v);
                let mut h = FastSurface::with_passes(&s.data(), Passes::AlongV).expect("valid");
                prop_assert_eq!(t, h.eval(u, v));
                prop_assert_eq!(t, baseline_v.eval_baseline(u, v), "AVX2 and baseline kernels");
                let x = free.eval(u, v);
                let mut h = FastSurface::for_any_path(&s.data()).expect("valid");
                prop_assert_eq!(x, h.eval(u, v));
                for want in [piegl_tiller_surface(&s.data(), u, v), conventional_surface(&s.data(), u, v)] {
                    for (name, got) in [("along u", &e), ("along v", &t), ("free", &x)] {
                        if let Some(m) = mismatch(got, &want, s.scale()) {
                            prop_assert!(false, "{name}: p = {} q = {} at ({u}, {v}): {m}", s.p, s.q);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn bad_surfaces_are_rejected() {
        let s = seed_surface(false);
        let mut d = s.data();
        d.n_v = 9;
        assert_eq!(
            FastSurface::new(&d).err(),
            Some(SurfaceError::CtrlCount {
                n_ctrl: 100,
                expected: 90
            })
        );
        let mut d = s.data();
        d.degree_u = 6;
        assert_eq!(
            FastSurface::new(&d).err(),
            Some(SurfaceError::DegreeTooHigh {
                dir: Direction::U,
                degree: 6
            })
        );
        let mut bad = s.clone();
        bad.ctrl[23][3] = -1.0;
        assert_eq!(
            FastSurface::new(&bad.data()).err(),
            Some(SurfaceError::WeightNotPositive { row: 2, col: 3 })
        );
        let mut big = s.clone();
        big.n_u = 17;
        big.ctrl = vec![[0.0, 0.0, 0.0, 1.0]; 170];
        big.ku = (0..=19).map(|i| (i.clamp(2, 17) - 2) as f64).collect();
        assert!(matches!(
            FastSurface::new(&big.data()),
            Err(SurfaceError::Knots {
                dir: Direction::U,
                err: CurveError::TooManyControlPoints { .. }
            })
        ));
    }
}
