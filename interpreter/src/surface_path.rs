//! Tool paths over a free-form surface: iso-parametric passes in the surface's `(u, v)`
//! domain for a ball-nose end mill, spaced by the scallop-height tolerance and the local
//! curvature across the passes.
//!
//! # Pass spacing
//!
//! Two neighbouring passes leave a ridge (scallop) between the two swept balls. In the
//! normal section across the passes let the surface have radius of curvature `ρ`, signed
//! so that `κ = 1/ρ > 0` where the surface bends away from the tool (convex, seen from
//! the tool) and `κ < 0` where it bends towards it. The ball centres of both passes lie
//! on the offset curve at distance `ρ + R` from the centre of curvature `O`, an angle
//! `θ = w/ρ` apart for a spacing `w` of the contact points along the surface. The ridge
//! is where the two balls' circles meet, on the bisector, at distance
//! `d = (ρ+R)·cos(θ/2) − √(R² − (ρ+R)²·sin²(θ/2))` from `O`, so the scallop height is
//! `h = d − ρ`. Expanding to second order in `θ`:
//! `d ≈ ρ + R − (ρ+R)θ²/8 − R + (ρ+R)²θ²/(8R) = ρ + (ρ+R)·ρ·θ²/(8R)`, hence
//!
//! `h ≈ w²/8 · (1/R + κ)`, and `w = √(8h / (1/R + κ))`.
//!
//! (`κ = 0` gives the flat-floor `w²/(8R)`; `1/R + κ ≤ 0` means the ball cannot follow a
//! concave section that tight: a gouge, refused.) The planner takes `κ` as the normal
//! curvature `−II(t)/I(t)` in the tangent direction `t` across the pass (`n` turned
//! towards the tool), evaluates it at samples along the current pass, along the pass
//! halfway to the next and along the next pass, and keeps the smallest spacing; it aims
//! at [`SAFETY`] of the tolerance to cover the fourth-order terms. `w` is a length on the
//! surface; the parameter step is `w / |S_b − (S_b·Ŝ_a)Ŝ_a|`, the distance between
//! neighbouring iso-lines per unit of the cross parameter. The tests measure the scallop
//! left between passes numerically from the swept balls, independently of this formula.
//!
//! Evaluation here uses second derivatives (The NURBS Book A2.3 and A4.4 on the
//! homogeneous surface), in the interpreter only; the cycle uses
//! [`shared::nurbs::surface::FastSurface`].

use crate::step::{FreeformStep, PathMode, StepError, Strategy};
use shared::nurbs::find_span;
use shared::nurbs::reference::ders_basis_funs;
use shared::nurbs::surface::{Passes, SurfaceData};

/// The share of the scallop tolerance the spacing aims at.
pub const SAFETY: f64 = 0.9;
/// Samples per knot span along a pass where the curvature is looked at.
const SAMPLES_PER_SPAN: usize = 16;
/// More passes than this means the tolerance is unreasonably small for the surface.
pub const MAX_PASSES: usize = 20_000;

/// One pass: the cross parameter is held at `fixed`; the pass runs from `from` to `to`
/// in the along parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pass {
    pub fixed: f64,
    pub from: f64,
    pub to: f64,
}

/// A planned surface path.
#[derive(Debug, Clone, PartialEq)]
pub struct SurfacePath {
    pub passes_along: Passes,
    pub mode: PathMode,
    pub passes: Vec<Pass>,
    /// `+1` when `S_u × S_v` faces the tool (towards +z), else `−1`: the normal the tool
    /// offset uses is `normal_sign · (S_u × S_v)/|S_u × S_v|`.
    pub normal_sign: f64,
    /// Ball radius `R`.
    pub radius_mm: f64,
    /// Spacings between neighbouring passes on the surface (smallest and largest of the
    /// per-pass widest; the last gap, which closes the domain, is left out of the smallest).
    pub min_spacing_mm: f64,
    pub max_spacing_mm: f64,
    /// The largest scallop height the spacing formula predicts (at the chosen spacings).
    pub predicted_scallop_mm: f64,
    /// Cutting length on the surface: the passes and, in zig-zag, the links along the
    /// domain boundary between them.
    pub length_mm: f64,
}

impl SurfacePath {
    /// `(u, v)` of a pass parameter pair `(along, cross)`.
    pub fn uv(&self, along: f64, cross: f64) -> (f64, f64) {
        match self.passes_along {
            Passes::AlongU => (along, cross),
            Passes::AlongV => (cross, along),
        }
    }

    /// The whole path as a polyline in `(u, v)`: pass ends (and, in zig-zag, the links
    /// between them). Forward mode repeats the pass start: the link there is a lift.
    pub fn uv_polyline(&self) -> Vec<(f64, f64)> {
        let mut out = Vec::with_capacity(self.passes.len() * 2);
        for p in &self.passes {
            out.push(self.uv(p.from, p.fixed));
            out.push(self.uv(p.to, p.fixed));
        }
        out
    }
}

/// Point and derivatives up to second order.
#[derive(Debug, Clone, Copy, Default)]
pub struct Ders2 {
    pub p: [f64; 3],
    pub su: [f64; 3],
    pub sv: [f64; 3],
    pub suu: [f64; 3],
    pub suv: [f64; 3],
    pub svv: [f64; 3],
}

fn clamp(deg: usize, knots: &[f64], n: usize, x: f64) -> f64 {
    x.clamp(knots[deg], knots[n])
}

/// `S` and its partial derivatives to second order (A2.3 per direction, the homogeneous
/// tensor sums, then A4.4's rational correction).
// Index loops mirror the textbook's sums, which is how they are checked.
#[allow(clippy::needless_range_loop)]
pub fn eval2(s: &SurfaceData<'_>, u: f64, v: f64) -> Ders2 {
    let (p, q) = (s.degree_u, s.degree_v);
    let u = clamp(p, s.knots_u, s.n_u, u);
    let v = clamp(q, s.knots_v, s.n_v, v);
    let su = find_span(p, s.knots_u, s.n_u, u);
    let sv = find_span(q, s.knots_v, s.n_v, v);
    let nu = ders_basis_funs(p, s.knots_u, su, u, 2);
    let nv = ders_basis_funs(q, s.knots_v, sv, v, 2);
    // a[k][l] = ∂^{k+l} A^w / ∂u^k ∂v^l.
    let mut a = [[[0.0f64; 4]; 3]; 3];
    for (r, nur) in (0..=p).map(|r| (r, [nu[0][r], nu[1][r], nu[2][r]])) {
        for c in 0..=q {
            let cp = s.ctrl[(su - p + r) * s.n_v + (sv - q + c)];
            let pw = [cp[0] * cp[3], cp[1] * cp[3], cp[2] * cp[3], cp[3]];
            for k in 0..3 {
                for l in 0..3 - k {
                    let f = nur[k] * nv[l][c];
                    for x in 0..4 {
                        a[k][l][x] += f * pw[x];
                    }
                }
            }
        }
    }
    let w = |k: usize, l: usize| a[k][l][3];
    let binom = |n: usize, k: usize| -> f64 {
        match (n, k) {
            (2, 1) => 2.0,
            _ => 1.0,
        }
    };
    let mut skl = [[[0.0f64; 3]; 3]; 3];
    for k in 0..3 {
        for l in 0..3 - k {
            let mut v3 = [a[k][l][0], a[k][l][1], a[k][l][2]];
            for j in 1..=l {
                for x in 0..3 {
                    v3[x] -= binom(l, j) * w(0, j) * skl[k][l - j][x];
                }
            }
            for i in 1..=k {
                for x in 0..3 {
                    v3[x] -= binom(k, i) * w(i, 0) * skl[k - i][l][x];
                }
                for j in 1..=l {
                    for x in 0..3 {
                        v3[x] -= binom(k, i) * binom(l, j) * w(i, j) * skl[k - i][l - j][x];
                    }
                }
            }
            for x in 0..3 {
                skl[k][l][x] = v3[x] / w(0, 0);
            }
        }
    }
    Ders2 {
        p: skl[0][0],
        su: skl[1][0],
        sv: skl[0][1],
        suu: skl[2][0],
        suv: skl[1][1],
        svv: skl[0][2],
    }
}

pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
pub(crate) fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// What the planner needs at one point, in pass coordinates (`a` along, `b` across).
struct Local {
    /// Unit normal towards the tool.
    n: [f64; 3],
    /// Distance between neighbouring iso-lines per unit of `b`.
    cross_rate: f64,
    /// Normal curvature across the pass, > 0 convex seen from the tool.
    kappa_cross: f64,
    /// Smallest normal curvature over all directions (most concave).
    kappa_min: f64,
}

fn local(d: &Ders2, along: Passes, sign: f64) -> Option<Local> {
    let (sa, sb, saa, sab, sbb) = match along {
        Passes::AlongU => (d.su, d.sv, d.suu, d.suv, d.svv),
        Passes::AlongV => (d.sv, d.su, d.svv, d.suv, d.suu),
    };
    let nu = cross(d.su, d.sv);
    let len = norm(nu);
    let sa2 = dot(sa, sa);
    if len <= 0.0 || sa2 <= 0.0 || !len.is_finite() {
        return None;
    }
    let n = [sign * nu[0] / len, sign * nu[1] / len, sign * nu[2] / len];
    // Second fundamental form with n towards the tool, negated: convex > 0.
    let (l, m, nn) = (-dot(saa, n), -dot(sab, n), -dot(sbb, n));
    let (e, f, g) = (sa2, dot(sa, sb), dot(sb, sb));
    let da = -f / e;
    let t2 = g - f * f / e; // |t|² for t = S_b − (S_b·Ŝ_a)Ŝ_a = da·S_a + S_b
    let kappa_cross = (l * da * da + 2.0 * m * da + nn) / t2;
    // Principal curvatures: det(II − κ I) = 0.
    let det_i = e * g - f * f;
    let mean2 = e * nn + g * l - 2.0 * f * m;
    let det_ii = l * nn - m * m;
    let disc = (mean2 * mean2 - 4.0 * det_i * det_ii).max(0.0).sqrt();
    let kappa_min = (mean2 - disc) / (2.0 * det_i);
    Some(Local {
        n,
        cross_rate: t2.sqrt(),
        kappa_cross,
        kappa_min,
    })
}

pub(crate) fn distinct(knots: &[f64]) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for &k in knots {
        if out.last() != Some(&k) {
            out.push(k);
        }
    }
    out
}

/// `lo`, the knots strictly between, `hi`: the pieces a quadrature must not straddle.
pub fn breaks_between(knots: &[f64], lo: f64, hi: f64) -> Vec<f64> {
    let mut out = vec![lo];
    out.extend(knots.iter().copied().filter(|&k| k > lo && k < hi));
    out.push(hi);
    out.dedup();
    out
}

/// The samples along a pass: `SAMPLES_PER_SPAN` per knot span.
fn samples(breaks: &[f64]) -> Vec<f64> {
    subdivide(breaks, SAMPLES_PER_SPAN)
}

/// `per_span` equal steps in each interval between `breaks`, the breaks exactly.
pub(crate) fn subdivide(breaks: &[f64], per_span: usize) -> Vec<f64> {
    let mut out = Vec::new();
    for w in breaks.windows(2) {
        for s in 0..per_span {
            out.push(w[0] + (w[1] - w[0]) * s as f64 / per_span as f64);
        }
    }
    out.extend(breaks.last());
    out
}

/// An error of the workingstep, on its own line and instance.
pub(crate) fn step_error(step: &FreeformStep, rule: &'static str, message: String) -> StepError {
    StepError {
        line: step.line,
        id: Some(step.id),
        rule,
        message,
    }
}

/// Which side of the surface the tool is on, over the sample points `(u, v)`: `+1` when
/// `S_u × S_v` faces +z on the whole (3-axis, tool along z), else `-1`.
pub(crate) fn tool_side_sign(s: &SurfaceData<'_>, points: impl Iterator<Item = (f64, f64)>) -> f64 {
    let mut nz_sum = 0.0;
    for (u, v) in points {
        let d = eval2(s, u, v);
        let n = cross(d.su, d.sv);
        nz_sum += n[2] / norm(n).max(f64::MIN_POSITIVE);
    }
    if nz_sum >= 0.0 {
        1.0
    } else {
        -1.0
    }
}

/// Can a ball end mill along +z machine the surface at `(u, v)`, given there the unit
/// normal towards the tool (`None`: degenerate) and the smallest normal curvature?
pub(crate) fn check_reach(
    step: &FreeformStep,
    u: f64,
    v: f64,
    normal_and_kappa_min: Option<([f64; 3], f64)>,
) -> Result<(), StepError> {
    let id = step.surface.id;
    let Some((n, kappa_min)) = normal_and_kappa_min else {
        return Err(step_error(
            step,
            "surface",
            format!("surface #{id} is degenerate at (u, v) = ({u:.4}, {v:.4})"),
        ));
    };
    if n[2] <= 1e-9 {
        return Err(step_error(
            step,
            "surface",
            format!(
                "surface #{id} turns away from the tool axis at (u, v) = ({u:.4}, {v:.4}): \
                 a 3-axis ball end mill cannot reach it"
            ),
        ));
    }
    let r = step.tool.radius_mm();
    if 1.0 / r + kappa_min <= 0.0 {
        return Err(step_error(
            step,
            "gouge",
            format!(
                "surface #{id} is concave with radius {:.3} mm at (u, v) = ({u:.4}, \
                 {v:.4}), tighter than the ball radius {r} mm",
                -1.0 / kappa_min
            ),
        ));
    }
    Ok(())
}

/// Plans the passes of a workingstep.
pub fn plan(step: &FreeformStep) -> Result<SurfacePath, StepError> {
    let s = step.surface.data();
    let r = step.tool.radius_mm();
    let fail = |rule: &'static str, message: String| step_error(step, rule, message);
    let Strategy::Uv(st) = &step.strategy else {
        return Err(fail(
            "internal",
            "the UV planner was called for another strategy".into(),
        ));
    };
    let (ku, kv) = (distinct(s.knots_u), distinct(s.knots_v));
    let (a_breaks, b_breaks) = match st.passes {
        Passes::AlongU => (ku, kv),
        Passes::AlongV => (kv, ku),
    };
    let (a0, a1) = (a_breaks[0], a_breaks[a_breaks.len() - 1]);
    let (b0, b1) = (b_breaks[0], b_breaks[b_breaks.len() - 1]);
    let uv = |a: f64, b: f64| match st.passes {
        Passes::AlongU => (a, b),
        Passes::AlongV => (b, a),
    };
    let at = |a: f64, b: f64| {
        let (u, v) = uv(a, b);
        eval2(&s, u, v)
    };
    // Which side the tool is on: the normal must face +z (3-axis, tool along z).
    let a_samples = samples(&a_breaks);
    let b_samples = samples(&b_breaks);
    let sign = tool_side_sign(
        &s,
        b_samples
            .iter()
            .flat_map(|&b| a_samples.iter().map(move |&a| uv(a, b))),
    );
    for &b in &b_samples {
        for &a in &a_samples {
            let (u, v) = uv(a, b);
            let l = local(&at(a, b), st.passes, sign);
            check_reach(step, u, v, l.as_ref().map(|l| (l.n, l.kappa_min)))?;
        }
    }
    let h_aim = SAFETY * st.scallop_mm;
    // The spacing (mm) and the parameter step it allows along the pass at `b`.
    let spacing = |b: f64| -> (f64, f64) {
        let mut best = (f64::INFINITY, f64::INFINITY);
        for &a in &a_samples {
            if let Some(l) = local(&at(a, b), st.passes, sign) {
                let k = (1.0 / r + l.kappa_cross).max(1e-12);
                let mut w = (8.0 * h_aim / k).sqrt();
                if let Some(cap) = st.stepover_mm {
                    w = w.min(cap);
                }
                let db = w / l.cross_rate;
                if db < best.1 {
                    best = (w, db);
                }
            }
        }
        best
    };
    // The spacing two passes at `b` and `b_next` have on the surface (the widest along
    // the pass, at the mid line) and the scallop the formula predicts for it.
    let predicted = |b: f64, b_next: f64| -> (f64, f64) {
        let (mut w_max, mut h_max) = (0.0f64, 0.0f64);
        let mid = 0.5 * (b + b_next);
        for &a in &a_samples {
            let Some(lm) = local(&at(a, mid), st.passes, sign) else {
                continue;
            };
            let w = (b_next - b).abs() * lm.cross_rate;
            w_max = w_max.max(w);
            for bb in [b, mid, b_next] {
                if let Some(l) = local(&at(a, bb), st.passes, sign) {
                    h_max = h_max.max(w * w / 8.0 * (1.0 / r + l.kappa_cross));
                }
            }
        }
        (w_max, h_max)
    };
    // Passes from the sideward start towards the sideward end.
    let (b_start, b_end) = if st.sideward_sign >= 0.0 {
        (b0, b1)
    } else {
        (b1, b0)
    };
    let dir = if st.sideward_sign >= 0.0 { 1.0 } else { -1.0 };
    let eps = 1e-12 * (b1 - b0);
    let mut fixed = vec![b_start];
    let mut b = b_start;
    let (mut min_w, mut max_w, mut worst_h) = (f64::INFINITY, 0.0f64, 0.0f64);
    while (b_end - b) * dir > eps {
        let (_, db0) = spacing(b);
        let mid = b + dir * db0 * 0.5;
        let next = b + dir * db0;
        let (_, db_mid) = spacing(mid.clamp(b0, b1));
        let (_, db_next) = spacing(next.clamp(b0, b1));
        let db = db0.min(db_mid).min(db_next);
        if !(db.is_finite() && db > 0.0) {
            return Err(fail(
                "stepover",
                format!("no pass spacing found near the cross parameter {b:.6}"),
            ));
        }
        let mut b_next = b + dir * db;
        if (b_end - b_next) * dir <= eps {
            b_next = b_end;
        }
        let (w_used, h) = predicted(b, b_next);
        // The gap that closes the domain is narrower by design: not a spacing.
        if b_next != b_end || fixed.len() == 1 {
            min_w = min_w.min(w_used);
        }
        max_w = max_w.max(w_used);
        worst_h = worst_h.max(h);
        fixed.push(b_next);
        b = b_next;
        if fixed.len() > MAX_PASSES {
            return Err(fail(
                "stepover",
                format!(
                    "more than {MAX_PASSES} passes for a scallop height of {} mm",
                    st.scallop_mm
                ),
            ));
        }
    }
    let (fa, fb) = if st.forward_sign >= 0.0 {
        (a0, a1)
    } else {
        (a1, a0)
    };
    let passes: Vec<Pass> = fixed
        .iter()
        .enumerate()
        .map(|(k, &b)| {
            let flip = st.mode == PathMode::Zigzag && k % 2 == 1;
            let (from, to) = if flip { (fb, fa) } else { (fa, fb) };
            Pass { fixed: b, from, to }
        })
        .collect();
    // Lengths: along each pass, and the zig-zag links along the boundary.
    let speed_a = |b: f64| {
        move |a: f64| {
            let d = at(a, b);
            norm(match st.passes {
                Passes::AlongU => d.su,
                Passes::AlongV => d.sv,
            })
        }
    };
    let mut length = 0.0;
    for p in &passes {
        length += shared::nurbs::arc_length(&a_breaks, 4, speed_a(p.fixed));
    }
    if st.mode == PathMode::Zigzag {
        for w in passes.windows(2) {
            let a = w[0].to;
            let (lo, hi) = (w[0].fixed.min(w[1].fixed), w[0].fixed.max(w[1].fixed));
            length += shared::nurbs::arc_length(&breaks_between(&b_breaks, lo, hi), 4, |b| {
                let d = at(a, b);
                norm(match st.passes {
                    Passes::AlongU => d.sv,
                    Passes::AlongV => d.su,
                })
            });
        }
    }
    if passes.len() == 1 {
        min_w = 0.0;
    }
    Ok(SurfacePath {
        passes_along: st.passes,
        mode: st.mode,
        passes,
        normal_sign: sign,
        radius_mm: r,
        min_spacing_mm: min_w,
        max_spacing_mm: max_w,
        predicted_scallop_mm: worst_h,
        length_mm: length,
    })
}

#[cfg(test)]
mod tests;
