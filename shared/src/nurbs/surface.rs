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
//! first; the partial sums (`a_i`, `b_i` above) depend on that parameter and the window
//! only, so they are kept and reused while it does not change, and a point costs the
//! other direction's basis and `12(q+1)` multiply-adds. The order of every sum is fixed
//! by the [`Passes`] setting alone, never by the history of calls, so an evaluator gives
//! the same bits as a fresh one with the same setting, on any path; a path that does not
//! hold the parameter fixed just recomputes the partial sums at every point.
//!
//! Capacity (fixed, no allocation): degrees up to [`MAX_SURF_DEGREE`] = 5 and at most
//! [`MAX_SURF_CTRL`] = 16 control points in each direction (8 kB of homogeneous points in
//! the evaluator). Control points are row-major: `ctrl[i * n_v + j]` is `P_ij`, `i` along
//! `u`, stored `[x, y, z, w]` with the weight not premultiplied.

use super::fast::{axpy, SpanCursor, ORD};
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
    /// `[w·x, w·y, w·z, w]` of `P_ij` at `hw[i][j]`.
    hw: [[[f64; 4]; MAX_SURF_CTRL]; MAX_SURF_CTRL],
    /// `hw[span_u-p+r][span_v-q+c]` at `win[r][c]`.
    win: [[[f64; 4]; SORD]; SORD],
    passes: Passes,
    /// The fixed parameter's bits the partial sums below belong to (`None` after a
    /// window reload).
    key: Option<u64>,
    /// Partial sums over the fixed direction: values and derivatives of that direction's
    /// basis against each row (`AlongU`) or column (`AlongV`) of the window.
    part_n: [[f64; 4]; SORD],
    part_d: [[f64; 4]; SORD],
    /// Whether the AVX2 kernel may run (same operations, same bits; see
    /// [`super::fast`]).
    simd: bool,
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
        let mut out = FastSurface {
            cu: SpanCursor::new(s.degree_u, s.knots_u, s.n_u),
            cv: SpanCursor::new(s.degree_v, s.knots_v, s.n_v),
            degree_u: s.degree_u,
            degree_v: s.degree_v,
            hw,
            win: [[[0.0; 4]; SORD]; SORD],
            passes: Passes::default(),
            key: None,
            part_n: [[0.0; 4]; SORD],
            part_d: [[0.0; 4]; SORD],
            simd: super::fast::simd_available(),
        };
        out.load_window();
        Ok(out)
    }

    /// The same evaluator for a tool path whose passes run as `passes` says.
    pub fn with_passes(s: &SurfaceData<'_>, passes: Passes) -> Result<Self, SurfaceError> {
        let mut out = Self::new(s)?;
        out.passes = passes;
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
        self.key = None;
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
            // SAFETY: `simd` is set only when the running CPU reports AVX2.
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
    #[target_feature(enable = "avx2")]
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
        if moved_u || moved_v {
            self.load_window();
        }
        let (p, q) = (p.min(MAX_SURF_DEGREE), q.min(MAX_SURF_DEGREE));
        let (mut r0, mut ru, mut rv) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
        match self.passes {
            Passes::AlongU => {
                // v fixed: per row r, a_r = Σ_c N_c(v) r_rc and b_r = Σ_c N'_c(v) r_rc.
                if self.key != Some(v.to_bits()) {
                    let bv = self.cv.ders(q, v);
                    for (r, row) in self.win.iter().enumerate().take(p + 1) {
                        let (mut a, mut b) = ([0.0f64; 4], [0.0f64; 4]);
                        for (c, pt) in row.iter().enumerate().take(q + 1) {
                            axpy(&mut a, bv.n[c], pt);
                            axpy(&mut b, bv.d1[c], pt);
                        }
                        self.part_n[r] = a;
                        self.part_d[r] = b;
                    }
                    self.key = Some(v.to_bits());
                }
                let bu = self.cu.ders(p, u);
                for r in 0..=p {
                    axpy(&mut r0, bu.n[r], &self.part_n[r]);
                    axpy(&mut ru, bu.d1[r], &self.part_n[r]);
                    axpy(&mut rv, bu.n[r], &self.part_d[r]);
                }
            }
            Passes::AlongV => {
                // u fixed: per column c, a_c = Σ_r N_r(u) r_rc and b_c = Σ_r N'_r(u) r_rc.
                if self.key != Some(u.to_bits()) {
                    let bu = self.cu.ders(p, u);
                    for c in 0..=q {
                        let (mut a, mut b) = ([0.0f64; 4], [0.0f64; 4]);
                        for (r, row) in self.win.iter().enumerate().take(p + 1) {
                            axpy(&mut a, bu.n[r], &row[c]);
                            axpy(&mut b, bu.d1[r], &row[c]);
                        }
                        self.part_n[c] = a;
                        self.part_d[c] = b;
                    }
                    self.key = Some(u.to_bits());
                }
                let bv = self.cv.ders(q, v);
                for c in 0..=q {
                    axpy(&mut r0, bv.n[c], &self.part_n[c]);
                    axpy(&mut rv, bv.d1[c], &self.part_n[c]);
                    axpy(&mut ru, bv.n[c], &self.part_d[c]);
                }
            }
        }
        let inv_w = 1.0 / r0[3];
        let mut out = SurfacePoint {
            span_u: self.cu.span(),
            span_v: self.cv.span(),
            ..SurfacePoint::default()
        };
        for k in 0..3 {
            let pk = r0[k] * inv_w;
            out.p[k] = pk;
            out.du[k] = (ru[k] - ru[3] * pk) * inv_w;
            out.dv[k] = (rv[k] - rv[3] * pk) * inv_w;
        }
        out.normal = unit_normal(out.du, out.dv);
        out
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
        for rational in [false, true] {
            let s = seed_surface(rational);
            let mut f = FastSurface::new(&s.data()).expect("valid surface");
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
                            panic!("rational {rational} at ({u}, {v}): {m}");
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
            let mut baseline = FastSurface::new(&s.data()).expect("valid surface");
            for (u, v) in pts {
                let e = f.eval(u, v);
                let mut g = FastSurface::new(&s.data()).expect("valid surface");
                prop_assert_eq!(e, g.eval(u, v));
                prop_assert_eq!(e, baseline.eval_baseline(u, v), "AVX2 and baseline kernels");
                let t = along_v.eval(u, v);
                let mut h = FastSurface::with_passes(&s.data(), Passes::AlongV).expect("valid");
                prop_assert_eq!(t, h.eval(u, v));
                for want in [piegl_tiller_surface(&s.data(), u, v), conventional_surface(&s.data(), u, v)] {
                    for (name, got) in [("along u", &e), ("along v", &t)] {
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
