//! Real-time evaluation of a rational curve and its first two derivatives by the
//! extended-space scheme with moving data (seed 001, Yeh & Sun: §3.1 computation structure,
//! §3.2 extended basis function, §3.3 moving data method).
//!
//! * **Extended space** (§3.1, eq. 3.3–3.7): the control points are stored homogeneous,
//!   `r_i = [w_i·P_i, w_i]`, so numerator and denominator of the NURBS are one
//!   four-component B-spline `r(u) = Σ N_i(u) r_i`. Its first and second derivatives come
//!   from the same basis values, and the quotient rule is applied once per point, not
//!   once per control point.
//! * **Extended basis function** (§3.2): the basis functions and the terms their first
//!   and second derivatives are made of come out of one pass over the triangular
//!   recurrence. The shared intermediate terms are the products `N_{i,j-1} / (u_{i+j} -
//!   u_i)` of the last two levels, the `γ`/`Ω` terms of eq. 3.10–3.12; the closed form of
//!   the extended branch at the top (The NURBS Book eq. 2.9) turns them into `N'`, `N''`
//!   with O(p) extra work instead of carrying derivatives through every level
//!   (`SpanCursor::ders`, used by the surfaces). For curves the derivative sums are
//!   regrouped once more: `Σ N'_r r_r = Σ t1_r q_r` with the per-span differences
//!   `q_r = p (r_{r+1} - r_r)`, and likewise for `N''`, so a point costs `3p + 1` four-
//!   component products and `N'`, `N''` are never formed.
//! * **Moving data** (§3.3): the evaluator keeps, for the current span, the window of the
//!   `p + 1` homogeneous control points, the knots either side and the reciprocals of every
//!   knot difference the recurrence divides by. While the parameter stays inside the span
//!   (forward stepping, the interpolator's common case) an evaluation is a range check plus
//!   multiply-adds: no span search, no division except the one `1 / w`. Crossing a knot
//!   reloads the window (a short forward walk, or a binary search for a jump backwards or
//!   far ahead), so every call gives the same bits as a fresh evaluator would.
//! * **The span's power form** (moving data taken one step further): inside one span the
//!   extended basis functions are fixed polynomials of degree `p`, so the whole sum
//!   `Σ N_r(u) r_r` is one four-component polynomial, and so are its derivatives. On a knot
//!   crossing the registers receive that polynomial's Taylor coefficients about the span's
//!   centre (from the window's difference points and one pass of the recurrence: about
//!   `p³/2` four-component operations, The NURBS Book eq. 3.3/3.8); a point then costs
//!   three independent Horner chains, `3p - 3` four-component multiply-adds, and the
//!   quotient rule. The expansion about the centre keeps `|t| <= h/2`, so the sums lose no
//!   more than the recurrence does (the property tests hold it to the same 1e-12).
//!   [`FastCurve::eval_recurrence`] keeps the seed's literal per-point recurrence on the
//!   same registers, for comparison and as a cross-check.
//!
//! Degrees 1..=5 are specialised at compile time ([`CurveEval<P>`], and [`FastCurve`]
//! dispatches to those) so every loop unrolls and the scratch arrays live in registers;
//! degrees 6..=9 share one kernel with the degree read at run time. Every kernel is also
//! compiled for AVX2 with FMA and chosen at construction when the CPU has both: one
//! homogeneous point is one 256-bit register, and a Horner step one fused multiply-add.
//! The per-point sums use `f64::mul_add` in both forms: IEEE 754 defines the fused
//! operation's result exactly (one rounding), so the AVX2 kernel and the baseline give
//! the same bits, tested, and a log replayed on a CPU without FMA still reproduces a run
//! exactly (slowly there: `mul_add` becomes a library call). Everything done once per
//! knot crossing uses plain operations, shared by both kernels.
//!
//! What bounds the cost: per point `4(3p - 3)` fused multiply-adds (one vector
//! instruction each with AVX2: `3p - 3` of them), one division and about fifteen flops
//! for the quotient rule, plus the range check and the result written through memory:
//! at p = 3, six vector FMAs in three independent chains, then the division and the
//! quotient rule (its chain: division, point, first, second derivative, about 40 cycles
//! of latency that consecutive points overlap). The measured 4–6 ns at p = 1..3 is that
//! fixed part: the out-of-line call, the 80-byte result and the division's latency; the
//! degree adds about 0.6 ns per step (`shared/BENCHMARKS.md`).
//!
//! The evaluator owns a copy of the curve (fixed capacity: [`MAX_CTRL`] control points,
//! premultiplied once at construction), so it holds no borrow and can live in the
//! interpolator's state between cycles. Curves with more control points are first split
//! exactly with [`super::split_to_capacity`].

// Index loops mirror the recurrence formulas (seed 001 eq. 2.3, 3.10-3.12); with the
// degree a constant they unroll and the bounds checks fold away.
#![allow(clippy::needless_range_loop)]

use super::{
    find_span, validate, validate_shape, CurveError, CurvePoint, MAX_CTRL, MAX_DEGREE, MAX_KNOTS,
};
use crate::protocol::CommandBlock;

/// Highest order (degree + 1) any evaluator here handles.
pub(crate) const ORD: usize = MAX_DEGREE + 1;

// `SpanCursor::terms` lists the levels 1..=9 of the recurrence by hand.
const _: () = assert!(
    MAX_DEGREE == 9,
    "update the level! list in SpanCursor::terms"
);

/// Basis functions of one span and their first derivatives: `n[r]`, `d1[r]` belong to
/// `N_{span-p+r, p}`, `r = 0..=p`.
pub(crate) struct BasisDers {
    pub n: [f64; ORD],
    pub d1: [f64; ORD],
}

/// The moving-data registers of one parametric direction: the current span, its bounds
/// and the knot terms the recurrence needs, reloaded only when the parameter leaves the
/// span. `K` is the knot capacity.
#[derive(Debug, Clone)]
pub(crate) struct SpanCursor<const K: usize> {
    degree: usize,
    n_ctrl: usize,
    knots: [f64; K],
    u_min: f64,
    u_max: f64,
    /// Index of the current span `[knots[span], knots[span+1])`.
    span: usize,
    /// Parameter range `[lo, hi)` in which the registers are valid, inside the domain
    /// (`hi` is just above the domain's end for the closed last span).
    lo: f64,
    hi: f64,
    /// `kl[i] = knots[span+1-i]`, `kr[i] = knots[span+i]` for `i = 1..=p`.
    kl: [f64; ORD],
    kr: [f64; ORD],
    /// `inv[j][r] = 1 / (knots[span+r+1] - knots[span+1-j+r])`: the reciprocal support
    /// length of `N_{span-j+1+r, j-1}`; never a division by zero on a non-empty span.
    inv: [[f64; ORD]; ORD],
}

impl<const K: usize> SpanCursor<K> {
    /// A cursor over validated knots (`degree + n_ctrl + 1` of them, at most `K`).
    pub(crate) fn new(degree: usize, knots: &[f64], n_ctrl: usize) -> Self {
        let mut own = [0.0; K];
        for (d, s) in own.iter_mut().zip(knots) {
            *d = *s;
        }
        let mut c = SpanCursor {
            degree,
            n_ctrl,
            knots: own,
            u_min: own[degree.min(K - 1)],
            u_max: own[n_ctrl.min(K - 1)],
            span: degree,
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
            kl: [0.0; ORD],
            kr: [0.0; ORD],
            inv: [[0.0; ORD]; ORD],
        };
        let first = find_span(degree, c.knots(), n_ctrl, c.u_min);
        c.load(first);
        c
    }

    fn knots(&self) -> &[f64] {
        &self.knots[..(self.n_ctrl + self.degree + 1).min(K)]
    }

    pub(crate) fn span(&self) -> usize {
        self.span
    }

    pub(crate) fn degree(&self) -> usize {
        self.degree
    }

    pub(crate) fn knot(&self, i: usize) -> f64 {
        self.knots[i]
    }

    /// Clamps `u` into the domain without `f64::clamp` (which panics on NaN bounds);
    /// NaN stays NaN and yields NaN results, never a panic.
    #[inline(always)]
    pub(crate) fn clamp(&self, u: f64) -> f64 {
        if u < self.u_min {
            self.u_min
        } else if u > self.u_max {
            self.u_max
        } else {
            u
        }
    }

    /// Clamps `u` into the domain and makes the registers hold its span. Returns the
    /// clamped parameter and whether the span changed, so the owner reloads its window.
    /// The common case, `u` inside the current span, is two comparisons: the registers'
    /// range lies inside the domain, so no clamping is needed there.
    #[inline(always)]
    pub(crate) fn enter(&mut self, u: f64) -> (f64, bool) {
        if u >= self.lo && u < self.hi {
            return (u, false);
        }
        self.enter_slow(u)
    }

    #[cold]
    #[inline(never)]
    fn enter_slow(&mut self, u: f64) -> (f64, bool) {
        let u = self.clamp(u);
        if u >= self.lo && u < self.hi {
            return (u, false);
        }
        (u, self.seek(u))
    }

    #[cold]
    #[inline(never)]
    fn seek(&mut self, u: f64) -> bool {
        let last = self.n_ctrl - 1;
        let mut s = self.span;
        // A few steps forward cover the common crossing of one (possibly repeated) knot
        // without a search; anything else is a binary search.
        let mut steps = 0;
        while steps < 4 && s < last && u >= self.knots[s + 1] {
            s += 1;
            steps += 1;
        }
        let found = if s < last && u >= self.knots[s] && u < self.knots[s + 1] {
            s
        } else {
            find_span(self.degree, self.knots(), self.n_ctrl, u)
        };
        let changed = found != self.span;
        self.load(found);
        changed
    }

    /// Loads the registers for span `s` (`degree <= s < n_ctrl`, non-empty).
    pub(crate) fn load(&mut self, s: usize) {
        let p = self.degree;
        self.span = s;
        let (a, b) = (self.knots[s], self.knots[s + 1]);
        // The last span is closed at the domain's end.
        self.lo = a;
        self.hi = if b >= self.u_max {
            self.u_max.next_up()
        } else {
            b
        };
        for i in 1..=p {
            self.kl[i] = self.knots[s + 1 - i];
            self.kr[i] = self.knots[s + i];
        }
        for j in 1..=p {
            for r in 0..j {
                self.inv[j][r] = 1.0 / (self.kr[r + 1] - self.kl[j - r]);
            }
        }
    }

    /// One pass of the triangular recurrence at `u` in the current span, for degree `p`
    /// (a constant after inlining in the specialised evaluators; it must be the cursor's
    /// degree, passed so the compiler sees it). Returns the basis functions of level `p`
    /// and the shared terms of levels `p` and `p - 1`: `t1[r+1] = N_{.,p-1}[r] ·
    /// inv[p][r]` and `t2[r+1] = N_{.,p-2}[r] · inv[p-1][r]`, stored one up so the zero
    /// borders of the derivative formulas need no branches.
    #[inline(always)]
    pub(crate) fn terms(&self, p: usize, u: f64) -> BasisTerms {
        let p = p.min(MAX_DEGREE);
        let mut left = [0.0; ORD];
        let mut right = [0.0; ORD];
        for i in 1..=p {
            left[i] = u - self.kl[i];
            right[i] = self.kr[i] - u;
        }
        let mut n = [0.0; ORD];
        n[0] = 1.0;
        // One call per level, each with a constant trip count, so the triangle unrolls
        // completely at every specialised degree (a nested loop stops unrolling at p = 5)
        // and a run-time degree costs a predictable branch per level, not a loop.
        let (mut last, mut prev) = ([0.0; ORD], [0.0; ORD]);
        macro_rules! level {
            ($($j:literal)*) => {$(
                if p >= $j {
                    prev = last;
                    last = self.level::<$j>(&mut n, &left, &right);
                }
            )*};
        }
        level!(1 2 3 4 5 6 7 8 9);
        let mut t1 = [0.0; ORD + 1];
        let mut t2 = [0.0; ORD + 1];
        t1[1..].copy_from_slice(&last);
        t2[1..].copy_from_slice(&prev);
        BasisTerms { n, t1, t2 }
    }

    /// Level `J` of the recurrence (The NURBS Book A2.2 with the divisions replaced by
    /// the span's reciprocals): `n` goes from degree `J - 1` to `J`; returns the terms
    /// `N_{.,J-1}[r] · inv[J][r]`.
    #[inline(always)]
    fn level<const J: usize>(
        &self,
        n: &mut [f64; ORD],
        left: &[f64; ORD],
        right: &[f64; ORD],
    ) -> [f64; ORD] {
        let mut terms = [0.0; ORD];
        let mut saved = 0.0;
        for r in 0..J {
            let temp = n[r] * self.inv[J][r];
            n[r] = saved + right[r + 1] * temp;
            saved = left[J - r] * temp;
            terms[r] = temp;
        }
        n[J] = saved;
        terms
    }

    /// The extended basis function of seed 001 §3.2 as far as surfaces need it: `N` and
    /// `N'` of the current span at `u`, the derivative from the shared terms by the
    /// closed form of the extended branch (The NURBS Book eq. 2.9).
    #[inline(always)]
    pub(crate) fn ders(&self, p: usize, u: f64) -> BasisDers {
        let BasisTerms { n, t1, .. } = self.terms(p, u);
        let p = p.min(MAX_DEGREE);
        let pf = p as f64;
        let mut d1 = [0.0; ORD];
        for r in 0..=p {
            d1[r] = pf * (t1[r] - t1[r + 1]);
        }
        BasisDers { n, d1 }
    }

    /// `inv[p][r]`, the reciprocal support of `N_{span-p+1+r, p-1}`.
    pub(crate) fn inv_top(&self, r: usize) -> f64 {
        self.inv[self.degree][r]
    }
}

/// `acc += s · c` on a homogeneous point, written out: an inner loop here kept the
/// outer sum over the window from unrolling at degree 5.
#[inline(always)]
pub(crate) fn axpy(acc: &mut [f64; 4], s: f64, c: &[f64; 4]) {
    acc[0] += s * c[0];
    acc[1] += s * c[1];
    acc[2] += s * c[2];
    acc[3] += s * c[3];
}

/// The outcome of [`SpanCursor::terms`].
pub(crate) struct BasisTerms {
    pub n: [f64; ORD],
    pub t1: [f64; ORD + 1],
    pub t2: [f64; ORD + 1],
}

/// The shared state of [`CurveEval`] and [`FastCurve`]: the premultiplied curve, the
/// knot cursor and the window of the current span's homogeneous control points.
#[derive(Debug, Clone)]
struct Core {
    cursor: SpanCursor<MAX_KNOTS>,
    /// `[w·x, w·y, w·z, w]` for every control point.
    hw: [[f64; 4]; MAX_CTRL],
    /// `hw[span-p ..= span]`, the moving window.
    win: [[f64; 4]; ORD],
    /// `q[r] = p (win[r+1] - win[r])`, `r < p`: with the shared terms `t1` these give
    /// `Σ N'_r win[r]` (the sum of eq. 3.6) in `p` instead of `p + 1` products, and no
    /// `N'` to form first.
    q: [[f64; 4]; ORD],
    /// `s[r] = (p-1) (g[r+1] - g[r])` with `g[r] = inv[p][r] q[r]`, `r < p - 1`: with
    /// `t2` these give `Σ N''_r win[r]` (eq. 3.7).
    s: [[f64; 4]; ORD],
    /// Centre of the current span: the power form below is in `t = u - mid`.
    mid: f64,
    /// The current span's homogeneous curve and its first two derivatives as
    /// polynomials in `t`: `r(u) = Σ c0[k] t^k` (`k <= p`), `r'(u) = Σ c1[k] t^k`
    /// (`k < p`), `r''(u) = Σ c2[k] t^k` (`k < p - 1`).
    c0: [[f64; 4]; ORD],
    c1: [[f64; 4]; ORD],
    c2: [[f64; 4]; ORD],
    /// Whether the CPU has AVX2, so the kernels compiled for it may run (checked once,
    /// at construction). They do the same IEEE operations in the same order as the
    /// baseline kernels (Rust never fuses a multiply and an add on its own), four lanes
    /// at a time, so both give the same bits: a replay on a machine without AVX2 is still
    /// bit-exact.
    simd: bool,
}

/// Whether the kernels compiled for AVX2 may run on this CPU.
pub(crate) fn simd_available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Calls the kernel `$name::<P>` for the degree `$deg` (1..=5, else the general one).
macro_rules! by_degree {
    ($core:expr, $deg:expr, $fixed:ident, $general:ident, $u:expr) => {
        match $deg {
            1 => $core.$fixed::<1>($u),
            2 => $core.$fixed::<2>($u),
            3 => $core.$fixed::<3>($u),
            4 => $core.$fixed::<4>($u),
            5 => $core.$fixed::<5>($u),
            _ => $core.$general($u),
        }
    };
}

impl Core {
    fn new(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> Result<Self, CurveError> {
        validate(degree, knots, ctrl, MAX_CTRL)?;
        let mut hw = [[0.0; 4]; MAX_CTRL];
        for (h, c) in hw.iter_mut().zip(ctrl) {
            *h = [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]];
        }
        let mut core = Core {
            cursor: SpanCursor::new(degree, knots, ctrl.len()),
            hw,
            win: [[0.0; 4]; ORD],
            q: [[0.0; 4]; ORD],
            s: [[0.0; 4]; ORD],
            mid: 0.0,
            c0: [[0.0; 4]; ORD],
            c1: [[0.0; 4]; ORD],
            c2: [[0.0; 4]; ORD],
            simd: simd_available(),
        };
        core.load_window();
        Ok(core)
    }

    fn load_window(&mut self) {
        let (p, s) = (self.cursor.degree, self.cursor.span);
        for (w, h) in self.win.iter_mut().zip(&self.hw[s - p..=s]) {
            *w = *h;
        }
        // The derivative terms are fixed per span: moving data, computed once per knot
        // crossing instead of once per point.
        let pf = p as f64;
        let mut g = [[0.0; 4]; ORD];
        for r in 0..p {
            for k in 0..4 {
                self.q[r][k] = pf * (self.win[r + 1][k] - self.win[r][k]);
                g[r][k] = self.cursor.inv_top(r) * self.q[r][k];
            }
        }
        for r in 0..p.saturating_sub(1) {
            for k in 0..4 {
                self.s[r][k] = (pf - 1.0) * (g[r + 1][k] - g[r][k]);
            }
        }
        self.load_power_form();
    }

    /// The span's Taylor expansion about its centre (the window through the span's
    /// [`basis_power_matrix`]) and the coefficients of its first two derivatives.
    fn load_power_form(&mut self) {
        let p = self.cursor.degree.min(MAX_DEGREE);
        let (mid, mat) = basis_power_matrix(&self.cursor);
        self.mid = mid;
        // (Past `p`, `c0`, `c1` and `c2` are zero, as [`Core::new`] and
        // [`FastCurve::load`] leave them and nothing here writes them: not cleared again.)
        for k in 0..=p {
            let mut sum = [0.0f64; 4];
            for j in 0..=p {
                axpy(&mut sum, mat[k][j], &self.win[j]);
            }
            self.c0[k] = sum;
        }
        for k in 0..p {
            let f1 = (k + 1) as f64;
            let f2 = ((k + 1) * (k + 2)) as f64;
            for i in 0..4 {
                self.c1[k][i] = f1 * self.c0[k + 1][i];
                if k + 2 <= p {
                    self.c2[k][i] = f2 * self.c0[k + 2][i];
                }
            }
        }
    }

    /// The evaluation every cycle runs: three Horner chains over the span's power form
    /// (independent, so they overlap in the pipeline) and the quotient rule.
    #[inline(always)]
    fn eval_power(&mut self, p: usize, u: f64) -> CurvePoint {
        let (u, moved) = self.cursor.enter(u);
        if moved {
            self.load_window();
        }
        let p = p.min(MAX_DEGREE);
        let t = u - self.mid;
        let a0 = horner(&self.c0, p, t);
        let a1 = if p >= 1 {
            horner(&self.c1, p - 1, t)
        } else {
            [0.0; 4]
        };
        let a2 = if p >= 2 {
            horner(&self.c2, p - 2, t)
        } else {
            [0.0; 4]
        };
        quotient(self.cursor.span(), &a0, &a1, &a2)
    }

    #[inline(always)]
    fn eval_deg(&mut self, p: usize, u: f64) -> CurvePoint {
        let (u, moved) = self.cursor.enter(u);
        if moved {
            self.load_window();
        }
        let b = self.cursor.terms(p, u);
        let p = p.min(MAX_DEGREE);
        // Extended space (seed 001 eq. 3.5-3.7): one four-component sum per derivative.
        let (mut a0, mut a1, mut a2) = ([0.0f64; 4], [0.0f64; 4], [0.0f64; 4]);
        for r in 0..=p {
            axpy(&mut a0, b.n[r], &self.win[r]);
        }
        for r in 0..p {
            axpy(&mut a1, b.t1[r + 1], &self.q[r]);
        }
        for r in 0..p.saturating_sub(1) {
            axpy(&mut a2, b.t2[r + 1], &self.s[r]);
        }
        quotient(self.cursor.span(), &a0, &a1, &a2)
    }

    /// One specialised kernel per degree, kept out of line: inlined into a caller's loop
    /// next to its siblings, the degree-5 copy lost its unrolling and ran slower than
    /// the general kernel at degree 9.
    #[inline(never)]
    fn eval_fixed<const P: usize>(&mut self, u: f64) -> CurvePoint {
        self.eval_power(P, u)
    }

    /// Degrees 6..=9: one kernel, degree read at run time.
    #[inline(never)]
    fn eval_general(&mut self, u: f64) -> CurvePoint {
        self.eval_power(self.cursor.degree, u)
    }

    /// [`Self::eval_fixed`] compiled for AVX2: the four homogeneous components of every
    /// Horner step and the three of the quotient rule go one vector instruction each.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    fn eval_fixed_avx2<const P: usize>(&mut self, u: f64) -> CurvePoint {
        self.eval_power(P, u)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    fn eval_general_avx2(&mut self, u: f64) -> CurvePoint {
        self.eval_power(self.cursor.degree, u)
    }

    /// The evaluation the interpolator runs: the AVX2 kernels where the CPU has them.
    #[inline(always)]
    fn eval(&mut self, u: f64) -> CurvePoint {
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            // SAFETY: `simd` is set only when the running CPU reports AVX2.
            return unsafe {
                by_degree!(
                    self,
                    self.cursor.degree,
                    eval_fixed_avx2,
                    eval_general_avx2,
                    u
                )
            };
        }
        by_degree!(self, self.cursor.degree, eval_fixed, eval_general, u)
    }

    /// [`Self::eval_d3_any`] in the AVX2 kernel where the CPU has it (its fused
    /// multiply-adds are a library call without it).
    fn eval_d3(&mut self, u: f64) -> (CurvePoint, [f64; 3]) {
        #[cfg(target_arch = "x86_64")]
        if self.simd {
            // SAFETY: `simd` is set only when the running CPU reports AVX2.
            return unsafe { self.eval_d3_avx2(u) };
        }
        self.eval_d3_any(u)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    #[inline(never)]
    fn eval_d3_avx2(&mut self, u: f64) -> (CurvePoint, [f64; 3]) {
        self.eval_d3_any(u)
    }

    /// [`Self::eval_power`] (the same bits for the point and its first two derivatives)
    /// with the third derivative: for the planner's curvature rate, not for the cycle.
    #[inline(always)]
    fn eval_d3_any(&mut self, u: f64) -> (CurvePoint, [f64; 3]) {
        let (u, moved) = self.cursor.enter(u);
        if moved {
            self.load_window();
        }
        let p = self.cursor.degree.min(MAX_DEGREE);
        let t = u - self.mid;
        let a0 = horner(&self.c0, p, t);
        let a1 = if p >= 1 {
            horner(&self.c1, p - 1, t)
        } else {
            [0.0; 4]
        };
        let a2 = if p >= 2 {
            horner(&self.c2, p - 2, t)
        } else {
            [0.0; 4]
        };
        let a3 = if p >= 3 {
            let mut c3 = [[0.0; 4]; ORD];
            for (k, c) in c3.iter_mut().enumerate().take(p - 2) {
                let f = ((k + 1) * (k + 2) * (k + 3)) as f64;
                *c = self.c0[k + 3].map(|x| f * x);
            }
            horner(&c3, p - 3, t)
        } else {
            [0.0; 4]
        };
        let e = quotient(self.cursor.span(), &a0, &a1, &a2);
        // `A = w·C` differentiated three times: `A''' = w'''C + 3w''C' + 3w'C'' + wC'''`.
        let (w, w1, w2, w3) = (a0[3], a1[3], a2[3], a3[3]);
        let d3 = std::array::from_fn(|k| {
            (a3[k] - w3 * e.p[k] - 3.0 * w2 * e.d1[k] - 3.0 * w1 * e.d2[k]) / w
        });
        (e, d3)
    }

    #[inline(never)]
    fn eval_recurrence_fixed<const P: usize>(&mut self, u: f64) -> CurvePoint {
        self.eval_deg(P, u)
    }

    #[inline(never)]
    fn eval_recurrence_general(&mut self, u: f64) -> CurvePoint {
        self.eval_deg(self.cursor.degree, u)
    }
}

/// The basis functions of every degree `j <= p` at the centre `m` of the cursor's
/// current span, `levels[j][r] = N_{s-j+r, j}(m)`: the levels of
/// [`SpanCursor::terms`], each one kept as it is made. What [`basis_power_matrix`] needs.
pub(crate) fn mid_levels<const K: usize>(c: &SpanCursor<K>) -> (f64, [[f64; ORD]; ORD]) {
    let (p, s) = (c.degree.min(MAX_DEGREE), c.span);
    let m = 0.5 * (c.knots[s] + c.knots[s + 1]);
    let (mut left, mut right) = ([0.0; ORD], [0.0; ORD]);
    for i in 1..=p {
        left[i] = m - c.kl[i];
        right[i] = c.kr[i] - m;
    }
    let mut n = [0.0; ORD];
    n[0] = 1.0;
    let mut levels = [[0.0f64; ORD]; ORD];
    levels[0] = n;
    macro_rules! level {
        ($($j:literal)*) => {$(
            if p >= $j {
                c.level::<$j>(&mut n, &left, &right);
                levels[$j] = n;
            }
        )*};
    }
    level!(1 2 3 4 5 6 7 8 9);
    (m, levels)
}

/// The power form of the basis functions of the cursor's current span about its centre
/// `m`: `N_{s-p+j, p}(m + t) = Σ_k mat[k][j] t^k`, so that any polynomial
/// `r(u) = Σ_j N_{s-p+j, p}(u) pts[j]` of the span has the Taylor coefficients
/// `c[k] = r^(k)(m) / k! = Σ_j mat[k][j] pts[j]`. Returns `m` and `mat`.
///
/// `r^(k)(m) = Σ_r N_{s-p+k+r, p-k}(m) Q^(k)_r` (The NURBS Book eq. 3.8 and 3.3):
/// the basis functions of degree `p - k` are level `p - k` of one pass of the
/// triangular recurrence at `m` ([`mid_levels`]), and the `Q^(k)` are the `k`-th
/// difference points, `Q^(k)_r = (p-k+1) / (u_{s+r+1} - u_{s-p+r+k}) · (Q^(k-1)_{r+1} -
/// Q^(k-1)_r)`, here run on the unit points (`pts[j]` = the `j`-th unit vector). Every
/// denominator spans the current (non-empty) span, so none is zero, and each is one of
/// the cursor's reciprocals: no division but `1/k!`. About `p³/2` operations, once per
/// knot crossing (curves) or once per span when a surface is built.
pub(crate) fn basis_power_matrix<const K: usize>(c: &SpanCursor<K>) -> (f64, [[f64; ORD]; ORD]) {
    let p = c.degree.min(MAX_DEGREE);
    let (m, levels) = mid_levels(c);
    // diff[r][j]: the k-th difference point r of the unit points, component j.
    let mut diff = [[0.0f64; ORD]; ORD];
    for (r, row) in diff.iter_mut().enumerate().take(p + 1) {
        row[r] = 1.0;
    }
    let mut mat = [[0.0f64; ORD]; ORD];
    let mut fact = 1.0;
    for k in 0..=p {
        if k > 0 {
            fact *= k as f64;
            let scale = (p - k + 1) as f64;
            for r in 0..=p - k {
                let f = scale * c.inv[p - k + 1][r];
                for j in 0..=p {
                    diff[r][j] = f * (diff[r + 1][j] - diff[r][j]);
                }
            }
        }
        let inv_fact = 1.0 / fact;
        for j in 0..=p {
            let mut sum = 0.0;
            for r in 0..=p - k {
                sum += levels[p - k][r] * diff[r][j];
            }
            mat[k][j] = sum * inv_fact;
        }
    }
    (m, mat)
}

/// `Σ coef[k] t^k` for `k <= deg`, on homogeneous points, each step one fused
/// multiply-add per component (one rounding: the same bits on every CPU, see
/// [`simd_available`]).
#[inline(always)]
pub(crate) fn horner(coef: &[[f64; 4]; ORD], deg: usize, t: f64) -> [f64; 4] {
    let mut acc = coef[deg];
    for k in (0..deg).rev() {
        for i in 0..4 {
            acc[i] = acc[i].mul_add(t, coef[k][i]);
        }
    }
    acc
}

/// Extended space back to Cartesian (seed 001 eq. 3.5–3.7): point, first and second
/// derivative from the homogeneous `r`, `r'`, `r''`, one division. Written on all four
/// lanes (the weight lane's results are dropped) so it stays in vector registers.
#[inline(always)]
fn quotient(span: usize, a0: &[f64; 4], a1: &[f64; 4], a2: &[f64; 4]) -> CurvePoint {
    let inv_w = 1.0 / a0[3];
    let (w1, w2) = (a1[3], a2[3]);
    let (mut p, mut d1, mut d2) = ([0.0; 4], [0.0; 4], [0.0; 4]);
    for k in 0..4 {
        p[k] = a0[k] * inv_w;
        d1[k] = (-w1).mul_add(p[k], a1[k]) * inv_w;
        d2[k] = (-w2).mul_add(p[k], (-2.0 * w1).mul_add(d1[k], a2[k])) * inv_w;
    }
    CurvePoint {
        p: [p[0], p[1], p[2]],
        d1: [d1[0], d1[1], d1[2]],
        d2: [d2[0], d2[1], d2[2]],
        span,
    }
}

/// Why an evaluator could not be built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FastCurveError {
    /// The curve itself is invalid.
    Curve(CurveError),
    /// A [`CurveEval<P>`] was asked to hold a curve of another degree.
    DegreeMismatch { expected: u32, found: u32 },
}

impl core::fmt::Display for FastCurveError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            FastCurveError::Curve(e) => e.fmt(f),
            FastCurveError::DegreeMismatch { expected, found } => write!(
                f,
                "curve of degree {found} given to an evaluator built for degree {expected}"
            ),
        }
    }
}

impl From<CurveError> for FastCurveError {
    fn from(e: CurveError) -> Self {
        FastCurveError::Curve(e)
    }
}

/// Evaluator for a curve of degree `P` known at compile time (`1 <= P <= 9`; degrees
/// up to 5 are the ones worth a type of their own, [`FastCurve`] covers the rest).
#[derive(Debug, Clone)]
pub struct CurveEval<const P: usize> {
    core: Core,
}

impl<const P: usize> CurveEval<P> {
    const DEGREE_OK: () = assert!(P >= 1 && P <= MAX_DEGREE, "degree outside 1..=9");

    /// Checks the curve (clamped, weights > 0, at most [`MAX_CTRL`] control points
    /// `[x, y, z, w]`, weight not premultiplied) and positions on its first span.
    pub fn new(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> Result<Self, FastCurveError> {
        #[allow(clippy::let_unit_value)]
        let () = Self::DEGREE_OK;
        if degree != P {
            return Err(FastCurveError::DegreeMismatch {
                expected: P as u32,
                found: degree as u32,
            });
        }
        Ok(CurveEval {
            core: Core::new(degree, knots, ctrl)?,
        })
    }

    /// The curve of a motion block (validated again here: a block is data from outside).
    pub fn from_block(block: &CommandBlock) -> Result<Self, FastCurveError> {
        Self::new(block.degree as usize, block.knots(), block.ctrl())
    }

    /// Point, first and second derivative at `u` (clamped into the domain).
    #[inline]
    pub fn eval(&mut self, u: f64) -> CurvePoint {
        #[cfg(target_arch = "x86_64")]
        if self.core.simd {
            // SAFETY: `simd` is set only when the running CPU reports AVX2.
            return unsafe { self.core.eval_fixed_avx2::<P>(u) };
        }
        self.core.eval_fixed::<P>(u)
    }

    /// The parameter domain `[u_min, u_max]`.
    pub fn domain(&self) -> (f64, f64) {
        (self.core.cursor.u_min, self.core.cursor.u_max)
    }
}

/// Evaluator for any degree 1..=9, dispatching to the compile-time specialisations for
/// degrees 1..=5 (one well-predicted branch per call) and a general kernel above.
#[derive(Debug, Clone)]
pub struct FastCurve {
    core: Core,
}

impl FastCurve {
    /// Checks the curve (clamped, weights > 0, at most [`MAX_CTRL`] control points
    /// `[x, y, z, w]`, weight not premultiplied) and positions on its first span.
    pub fn new(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> Result<Self, CurveError> {
        Ok(FastCurve {
            core: Core::new(degree, knots, ctrl)?,
        })
    }

    /// The curve of a motion block (validated again here: a block is data from outside).
    pub fn from_block(block: &CommandBlock) -> Result<Self, CurveError> {
        Self::new(block.degree as usize, block.knots(), block.ctrl())
    }

    /// Replaces the curve, reusing the evaluator's storage; on error the evaluator keeps
    /// its previous curve.
    ///
    /// Field by field in place, the values [`Core::new`] gives (test
    /// `load_in_place_leaves_what_new_builds`): built on the stack and moved in, the 4.5 KB
    /// were written twice, and a line's load (at the start of every block, in the cycle
    /// the interpolator loads the next block ahead) was mostly those copies.
    pub fn load(
        &mut self,
        degree: usize,
        knots: &[f64],
        ctrl: &[[f64; 4]],
    ) -> Result<(), CurveError> {
        validate(degree, knots, ctrl, MAX_CTRL)?;
        self.fill(degree, knots, ctrl);
        Ok(())
    }

    /// [`Self::load`] of a curve [`validate`] has already accepted (the interpolator's
    /// blocks, each validated when taken in: checked a second time, the curve of a line
    /// was a tenth of its load): the same evaluator, without the check (test
    /// `load_valid_leaves_what_load_leaves`). Only the curve's shape is checked again
    /// (its degree and counts, so that no index can leave its array); a curve `validate`
    /// refuses for anything else (not finite, knots not clamped or decreasing, a weight
    /// not positive) gives an evaluator of meaningless values, never a panic. Use
    /// [`Self::load`] for any curve not validated before.
    pub fn load_valid(
        &mut self,
        degree: usize,
        knots: &[f64],
        ctrl: &[[f64; 4]],
    ) -> Result<(), CurveError> {
        validate_shape(degree, knots.len(), ctrl.len(), MAX_CTRL)?;
        debug_assert_eq!(validate(degree, knots, ctrl, MAX_CTRL), Ok(()));
        self.fill(degree, knots, ctrl);
        Ok(())
    }

    /// Loads a curve of a valid shape in place. Past the curve held, every slot of the
    /// evaluator is zero (as [`Core::new`] and this leave them; evaluating writes none of
    /// them), so only the slots the old or the new curve reaches are written: on a line
    /// after a line, a few hundred bytes instead of 4.5 KB.
    fn fill(&mut self, degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) {
        let core = &mut self.core;
        let c = &mut core.cursor;
        let n_ctrl = ctrl.len();
        // How far the old curve and the new reach: control points, knots, order.
        let n_hw = c.n_ctrl.max(n_ctrl).min(MAX_CTRL);
        let n_knots = (c.n_ctrl + c.degree + 1).max(knots.len()).min(MAX_KNOTS);
        let ord = c.degree.max(degree).min(MAX_DEGREE) + 1;
        for (i, h) in core.hw[..n_hw].iter_mut().enumerate() {
            *h = match ctrl.get(i) {
                Some(c) => [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]],
                None => [0.0; 4],
            };
        }
        for (i, d) in c.knots[..n_knots].iter_mut().enumerate() {
            *d = knots.get(i).copied().unwrap_or(0.0);
        }
        c.degree = degree;
        c.n_ctrl = n_ctrl;
        c.u_min = c.knots[degree.min(MAX_KNOTS - 1)];
        c.u_max = c.knots[n_ctrl.min(MAX_KNOTS - 1)];
        c.span = degree;
        c.lo = f64::INFINITY;
        c.hi = f64::NEG_INFINITY;
        c.kl[..ord].fill(0.0);
        c.kr[..ord].fill(0.0);
        for row in &mut c.inv[..ord] {
            row[..ord].fill(0.0);
        }
        let first = find_span(degree, c.knots(), n_ctrl, c.u_min);
        c.load(first);
        for a in [
            &mut core.win,
            &mut core.q,
            &mut core.s,
            &mut core.c0,
            &mut core.c1,
            &mut core.c2,
        ] {
            a[..ord].fill([0.0; 4]);
        }
        core.mid = 0.0;
        core.simd = simd_available();
        core.load_window();
    }

    pub fn degree(&self) -> usize {
        self.core.cursor.degree
    }

    /// The parameter domain `[u_min, u_max]`.
    pub fn domain(&self) -> (f64, f64) {
        (self.core.cursor.u_min, self.core.cursor.u_max)
    }

    /// Point, first and second derivative at `u` (clamped into the domain).
    #[inline]
    pub fn eval(&mut self, u: f64) -> CurvePoint {
        self.core.eval(u)
    }

    /// Point, first and second derivative at `u`, as [`Self::eval`] gives them within
    /// rounding (the same bits as its kernels without AVX2), with the third derivative.
    /// Off the cycle: the planner's curvature rate.
    pub fn eval_d3(&mut self, u: f64) -> (CurvePoint, [f64; 3]) {
        self.core.eval_d3(u)
    }

    /// [`Self::eval`] without the AVX2 kernels: for the test that both give the same bits.
    #[doc(hidden)]
    pub fn eval_baseline(&mut self, u: f64) -> CurvePoint {
        by_degree!(
            self.core,
            self.core.cursor.degree,
            eval_fixed,
            eval_general,
            u
        )
    }

    /// The same result by the seed's per-point recurrence (§3.2, the extended basis
    /// function evaluated afresh at every point) instead of the span's power form: kept
    /// as the literal form of the method, for the benches and as a cross-check.
    pub fn eval_recurrence(&mut self, u: f64) -> CurvePoint {
        by_degree!(
            self.core,
            self.core.cursor.degree,
            eval_recurrence_fixed,
            eval_recurrence_general,
            u
        )
    }
}

#[cfg(test)]
mod tests;
