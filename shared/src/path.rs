//! The geometry of a motion block: its NURBS plus, for helical arcs, the axial motion that
//! follows the angle travelled. Used by the interpreter (lengths, limits) and by the
//! interpolator (every cycle), so both see exactly the same path.
//!
//! A surface block ([`CommandBlock::is_surface`], see [`crate::protocol::SurfacePass`])
//! has two paths: the cutter-contact point on the surface, along which the feed is
//! programmed and the interpolator steps ([`contact`]), and the tool reference point it
//! publishes as the set-point ([`tool_point`]). [`eval`] gives the set-point path, the one
//! the machine follows and reports compare with; [`length`] the contact path's length.

use crate::nurbs::surface::{
    FastSurface, Passes, SurfaceData, SurfaceError, SurfacePoint, MAX_SURF_DEGREE,
};
use crate::nurbs::{self, CurvePoint};
use crate::protocol::{CommandBlock, Helix, FLAG_UV_CUBIC, NO_AXIS};

/// `[0; k]` then `[1; k]`: the knots of a Bézier patch of degree `k - 1` are a slice.
const BEZIER: [f64; 2 * (MAX_SURF_DEGREE + 1)] = {
    let mut k = [0.0; 2 * (MAX_SURF_DEGREE + 1)];
    let mut i = MAX_SURF_DEGREE + 1;
    while i < 2 * (MAX_SURF_DEGREE + 1) {
        k[i] = 1.0;
        i += 1;
    }
    k
};

/// The clamped knots of a Bézier patch of `degree` (at most [`MAX_SURF_DEGREE`]).
pub fn bezier_knots(degree: usize) -> &'static [f64] {
    let k = (degree + 1).min(MAX_SURF_DEGREE + 1);
    &BEZIER[MAX_SURF_DEGREE + 1 - k..MAX_SURF_DEGREE + 1 + k]
}

/// The Bézier patch of a validated surface block, as the surface evaluators take it.
pub fn patch(block: &CommandBlock) -> SurfaceData<'_> {
    let (p, q) = (block.degree as usize, block.surface.degree_v as usize);
    SurfaceData {
        degree_u: p,
        degree_v: q,
        knots_u: bezier_knots(p),
        knots_v: bezier_knots(q),
        n_u: p + 1,
        n_v: q + 1,
        ctrl: block.ctrl(),
    }
}

/// Is the block's pass the cubic `(u, v)` curve of [`FLAG_UV_CUBIC`] (else a line)?
#[inline]
pub fn is_cubic_pass(block: &CommandBlock) -> bool {
    block.flags & FLAG_UV_CUBIC != 0
}

/// The evaluator for a surface block's pass ([`FastSurface`]): iso-parametric passes keep
/// their partial sums and polynomials through the whole pass; a cubic pass holds neither
/// parameter.
pub fn pass_evaluator(block: &CommandBlock) -> Result<FastSurface, SurfaceError> {
    let (a, b) = (block.surface.uv_start, block.surface.uv_end);
    let patch = patch(block);
    if is_cubic_pass(block) {
        FastSurface::for_any_path(&patch)
    } else if a[1] == b[1] {
        FastSurface::with_passes(&patch, Passes::AlongU)
    } else if a[0] == b[0] {
        FastSurface::with_passes(&patch, Passes::AlongV)
    } else {
        FastSurface::for_any_path(&patch)
    }
}

/// `(u, v)` of a surface block's pass at `t` in `[0, 1]`, and its rate `d(u, v)/dt`:
/// constant on a straight pass, the cubic's derivative on a [`FLAG_UV_CUBIC`] one (exact
/// at both ends: `t = 0` gives `uv_start`, `t = 1` gives `uv_end`, bit for bit).
#[inline]
pub fn pass_uv(block: &CommandBlock, t: f64) -> ([f64; 2], [f64; 2]) {
    let sp = &block.surface;
    let (a, b) = (sp.uv_start, sp.uv_end);
    if !is_cubic_pass(block) {
        let d = [b[0] - a[0], b[1] - a[1]];
        return ([a[0] + t * d[0], a[1] + t * d[1]], d);
    }
    let [p1, p2] = sp.uv_inner;
    let s = 1.0 - t;
    let (b0, b1, b2, b3) = (s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t);
    let (d0, d1, d2) = (3.0 * s * s, 6.0 * s * t, 3.0 * t * t);
    let at = |i: usize| b0 * a[i] + b1 * p1[i] + b2 * p2[i] + b3 * b[i];
    let rate = |i: usize| d0 * (p1[i] - a[i]) + d1 * (p2[i] - p1[i]) + d2 * (b[i] - p2[i]);
    ([at(0), at(1)], [rate(0), rate(1)])
}

/// The contact path of a surface block at `t` from the surface at its pass point: the
/// point, its rate `dC/dt = S_u·du/dt + S_v·dv/dt` (the chain rule, with the pass's rate
/// at `t`), and no second derivative (the engine's chord correction does without it).
#[inline]
pub fn contact(block: &CommandBlock, t: f64, s: &SurfacePoint) -> CurvePoint {
    let (_, d) = pass_uv(block, t);
    contact_at_rate(d, s)
}

/// [`contact`] with the pass's rate `d(u, v)/dt` already known.
#[inline]
pub fn contact_at_rate(d: [f64; 2], s: &SurfacePoint) -> CurvePoint {
    CurvePoint {
        p: s.p,
        d1: [
            s.du[0] * d[0] + s.dv[0] * d[1],
            s.du[1] * d[0] + s.dv[1] * d[1],
            s.du[2] * d[0] + s.dv[2] * d[1],
        ],
        d2: [0.0; 3],
        span: 0,
    }
}

/// The tool reference point over the contact point `s` (seed 000 §3):
/// `M = C + R·n + (H − R)·z`, `n` the unit normal on the tool's side, `z = +Z`.
#[inline]
pub fn tool_point(block: &CommandBlock, s: &SurfacePoint) -> [f64; 3] {
    let sp = &block.surface;
    let (r, h) = (sp.tool_radius_mm, sp.tool_length_mm);
    let k = r * sp.normal_sign as f64;
    [
        s.p[0] + k * s.normal[0],
        s.p[1] + k * s.normal[1],
        s.p[2] + k * s.normal[2] + (h - r),
    ]
}

/// `M'/|C'|` of a validated surface block at an end of its pass (`t` 0 or 1): the tool
/// reference point's velocity per unit of contact speed, by a one-sided difference of
/// 1e-7 into the block (zero where the contact point stands still). Where the surface
/// is only C¹ it differs between two blocks that meet, in length as well as direction:
/// the ball's centre changes velocity there at any contact speed above zero. Reference
/// evaluators: not for the cycle.
pub fn tool_rate(block: &CommandBlock, t: f64) -> [f64; 3] {
    let h = if t < 0.5 { 1e-7 } else { -1e-7 };
    let c = norm(contact(block, t, &surface_at(block, t)).d1);
    let (a, b) = (eval(block, t).p, eval(block, t + h).p);
    if c > 1e-12 {
        [0, 1, 2].map(|i| (b[i] - a[i]) / (h * c))
    } else {
        [0.0; 3]
    }
}

/// The second derivative of a surface block's tool reference point `M` with respect to
/// the contact path's length at `t` of its pass (`d²M/ds²`, 1/mm): the tool point's
/// acceleration per squared contact speed when the contact speed is steady. One-sided
/// differences into the block, second order (`(2M₀ − 5M₁ + 4M₂ − M₃)/h²`, and
/// `(−3x₀ + 4x₁ − x₂)/2h` for `M'` and the contact speed), with steps of 0.01 mm of the
/// contact path (at most a fifth of the pass), so rounding stays near 1e-8/mm; zero
/// where the contact point stands still. Where the surface is only C² (every knot of a
/// cubic) it jumps between two blocks that meet: `M` involves the normal, so its second
/// derivative involves the surface's third. Reference evaluators: not for the cycle.
pub fn tool_rate2(block: &CommandBlock, t: f64) -> [f64; 3] {
    let speed = |x: f64| norm(contact(block, x, &surface_at(block, x)).d1);
    let c0 = speed(t);
    if c0 <= 1e-12 {
        return [0.0; 3];
    }
    let h = (0.01 / c0).min(0.2) * if t < 0.5 { 1.0 } else { -1.0 };
    let (c1, c2) = (speed(t + h), speed(t + 2.0 * h));
    let m: [[f64; 3]; 4] = core::array::from_fn(|k| eval(block, t + k as f64 * h).p);
    let dc = (-3.0 * c0 + 4.0 * c1 - c2) / (2.0 * h);
    [0, 1, 2].map(|i| {
        let d1 = (-3.0 * m[0][i] + 4.0 * m[1][i] - m[2][i]) / (2.0 * h);
        let d2 = (2.0 * m[0][i] - 5.0 * m[1][i] + 4.0 * m[2][i] - m[3][i]) / (h * h);
        (d2 - d1 * dc / c0) / (c0 * c0)
    })
}

/// The surface point of a validated surface block's pass at `t` (standard algorithm:
/// not for the cycle, which keeps a moving-data evaluator).
pub fn surface_at(block: &CommandBlock, t: f64) -> SurfacePoint {
    let (uv, _) = pass_uv(block, t);
    nurbs::reference::piegl_tiller_surface(&patch(block), uv[0], uv[1])
}

/// The parameter domain `[u_start, u_end]` of a validated motion block (`[0, 1]` for a
/// surface block's pass).
pub fn domain(block: &CommandBlock) -> (f64, f64) {
    if block.is_surface() {
        return (0.0, 1.0);
    }
    let k = block.knots();
    (
        k.first().copied().unwrap_or(0.0),
        k.last().copied().unwrap_or(0.0),
    )
}

/// Point, first and second derivative of a validated motion block at `u`. For a surface
/// block: the tool reference point, with the contact path's derivatives (the normal's
/// turning is left out of them).
pub fn eval(block: &CommandBlock, u: f64) -> CurvePoint {
    if block.is_surface() {
        let s = surface_at(block, u);
        let mut e = contact(block, u, &s);
        e.p = tool_point(block, &s);
        return e;
    }
    let mut e = nurbs::eval(block.degree as usize, block.knots(), block.ctrl(), u);
    add_axial(block, u, &mut e);
    e
}

/// Completes an evaluation of the block's NURBS at `u` (by any evaluator) with the
/// block's helical axial motion, if it has one.
#[inline]
pub fn add_axial(block: &CommandBlock, u: f64, e: &mut CurvePoint) {
    if block.helix.axis != NO_AXIS {
        add_helix(&block.helix, block.ctrl(), u, e);
    }
}

fn add_helix(h: &Helix, ctrl: &[[f64; 4]], u: f64, e: &mut CurvePoint) {
    let n = h.axis as usize;
    let (i, k) = ((n + 1) % 3, (n + 2) % 3);
    let nseg = (ctrl.len() / 2).max(1);
    let j = (u.max(0.0) as usize).min(nseg - 1);
    let start = ctrl.get(2 * j).copied().unwrap_or([0.0; 4]);
    let c = h.center_mm;
    let dir = h.dir as f64;
    let (sx, sy) = (start[i] - c[i], start[k] - c[k]);
    let (ax, ay) = (e.p[i] - c[i], e.p[k] - c[k]);
    let phi = j as f64 * h.seg_rad + dir * (sx * ay - sy * ax).atan2(sx * ax + sy * ay);
    let (d1x, d1y, d2x, d2y) = (e.d1[i], e.d1[k], e.d2[i], e.d2[k]);
    let r2 = ax * ax + ay * ay;
    let cross1 = ax * d1y - ay * d1x;
    let dot1 = ax * d1x + ay * d1y;
    let dphi = dir * cross1 / r2;
    let ddphi = dir * ((ax * d2y - ay * d2x) / r2 - 2.0 * cross1 * dot1 / (r2 * r2));
    e.p[n] = h.start_mm + h.mm_per_rad * phi;
    e.d1[n] = h.mm_per_rad * dphi;
    e.d2[n] = h.mm_per_rad * ddphi;
}

/// `a - b`, axis by axis.
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Euclidean norm of a 3-vector.
pub fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Path length of a validated motion block.
pub fn length(block: &CommandBlock) -> f64 {
    // Exact to far below a micrometre (the profile lands stops on this length; 4 plain
    // pieces a span left 1e-4 mm on long rational spans): the adaptive rule, which
    // halves each of `LENGTH_PIECES` pieces a span until its rule agrees with its
    // halves' to 1e-12 (see `nurbs::arc_length_adaptive`).
    if block.is_surface() {
        return nurbs::arc_length_adaptive(&[0.0, 1.0], LENGTH_PIECES, |t| {
            norm(contact(block, t, &surface_at(block, t)).d1)
        });
    }
    // Points in order, most inside the span of the one before: the moving-data
    // evaluator (one span search and power form a span, then 10–15 ns a point instead of
    // 100–150), about the curve's own origin (see `nurbs::local`), gives them within
    // rounding of the general one.
    if let Ok(mut fast) =
        nurbs::local::LocalCurve::new(block.degree as usize, block.knots(), block.ctrl())
    {
        return nurbs::arc_length_adaptive(block.knots(), LENGTH_PIECES, |u| {
            let mut e = fast.eval(u);
            add_axial(block, u, &mut e);
            norm(e.d1)
        });
    }
    // The speed needs no second derivative: the same bits of it, for a third less work.
    nurbs::arc_length_adaptive(block.knots(), LENGTH_PIECES, |u| {
        let mut e = nurbs::eval_d1(block.degree as usize, block.knots(), block.ctrl(), u);
        add_axial(block, u, &mut e);
        norm(e.d1)
    })
}

/// Pieces a span (or a surface block's pass) that [`length`] starts its adaptive rule
/// from: each takes 15 points where its rule agrees with its halves' at once (60 a
/// span, against the 240 of the fixed 32-piece grid before).
const LENGTH_PIECES: usize = 4;

/// A surface block with a known closed form, for tests and benches: a quarter of the
/// cylinder `y² + z² = r²` (axis along X, from the top `z = r` round to the side `y = r`)
/// as a rational Bézier patch of degree 1 along X (0 to 10 mm) and 2 around, one pass
/// round it at `x = 5`, a ball of radius 3 with its reference point 40 above the tip,
/// on the outside; 1200 mm/min, 2000 mm/s², 50 000 mm/s³, its contact length set.
#[doc(hidden)]
pub fn quarter_cylinder_pass(r: f64) -> CommandBlock {
    use crate::protocol::{BlockKind, FLAG_SURFACE};
    let w = core::f64::consts::FRAC_1_SQRT_2;
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 1);
    b.flags = FLAG_SURFACE;
    b.degree = 1;
    b.surface.degree_v = 2;
    b.n_ctrl = 6;
    for (i, x) in [0.0, 10.0].into_iter().enumerate() {
        for (j, p) in [[x, 0.0, r, 1.0], [x, r, r, w], [x, r, 0.0, 1.0]]
            .into_iter()
            .enumerate()
        {
            if let Some(c) = b.ctrl.get_mut(3 * i + j) {
                *c = p;
            }
        }
    }
    b.surface.uv_start = [0.5, 0.0];
    b.surface.uv_end = [0.5, 1.0];
    b.surface.tool_radius_mm = 3.0;
    b.surface.tool_length_mm = 40.0;
    // S_u × S_v: at the top +X × +Y = +Z, out of the cylinder, where the tool is.
    b.surface.normal_sign = 1;
    b.feed_mm_per_min = 1200.0;
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b.length_mm = length(&b);
    b
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing)]
mod tests {
    use super::*;

    fn cylinder_pass(r: f64) -> CommandBlock {
        quarter_cylinder_pass(r)
    }

    #[test]
    fn surface_pass_contact_tool_point_and_length_on_a_cylinder() {
        let r = 20.0;
        let mut b = cylinder_pass(r);
        // S_u × S_v points inward here (x along u, then around to +y): the tool is outside.
        let s = surface_at(&b, 0.3);
        b.surface.normal_sign = if s.normal[2] + s.normal[1] < 0.0 {
            -1
        } else {
            1
        };
        b.length_mm = length(&b);
        assert!(b.validate().is_ok(), "{:?}", b.validate());
        // The contact path is a quarter circle of radius r.
        let quarter = core::f64::consts::FRAC_PI_2 * r;
        assert!((b.length_mm - quarter).abs() < 1e-9, "{}", b.length_mm);
        for k in 0..=10 {
            let t = k as f64 / 10.0;
            let s = surface_at(&b, t);
            let c = s.p;
            assert!((c[1].hypot(c[2]) - r).abs() < 1e-12 && (c[0] - 5.0).abs() < 1e-12);
            // The ball's centre is R further out along the radius; M is H - R above it.
            let m = eval(&b, t).p;
            let centre = [m[0], m[1], m[2] - (40.0 - 3.0)];
            assert!(
                (centre[1].hypot(centre[2]) - (r + 3.0)).abs() < 1e-12,
                "{m:?}"
            );
            // The contact rate agrees with a central difference.
            let h = 1e-6;
            let d = contact(&b, t, &s).d1;
            let (a, z) = (
                surface_at(&b, (t - h).max(0.0)).p,
                surface_at(&b, (t + h).min(1.0)).p,
            );
            let span = (t + h).min(1.0) - (t - h).max(0.0);
            for i in 0..3 {
                assert!((d[i] - (z[i] - a[i]) / span).abs() < 1e-5 * r, "{d:?}");
            }
        }
        assert_eq!(domain(&b), (0.0, 1.0));
    }

    /// The cylinder pass bent into a cubic `(u, v)` curve across the patch.
    fn cubic_pass() -> CommandBlock {
        let mut b = cylinder_pass(20.0);
        b.flags |= crate::protocol::FLAG_UV_CUBIC;
        b.surface.uv_start = [0.1, 0.0];
        b.surface.uv_inner = [[0.9, 0.2], [0.05, 0.7]];
        b.surface.uv_end = [0.6, 1.0];
        b.length_mm = length(&b);
        b
    }

    #[test]
    fn a_cubic_pass_runs_its_curve_with_the_chain_rule() {
        let b = cubic_pass();
        assert!(b.validate().is_ok(), "{:?}", b.validate());
        // Both ends exactly, bit for bit: neighbouring blocks join there.
        assert_eq!(pass_uv(&b, 0.0).0, b.surface.uv_start);
        assert_eq!(pass_uv(&b, 1.0).0, b.surface.uv_end);
        let h = 1e-6;
        for k in 1..20 {
            let t = k as f64 / 20.0;
            // The uv rate and the contact rate against central differences.
            let (uv_m, uv_p) = (pass_uv(&b, t - h).0, pass_uv(&b, t + h).0);
            let rate = pass_uv(&b, t).1;
            for i in 0..2 {
                assert!((rate[i] - (uv_p[i] - uv_m[i]) / (2.0 * h)).abs() < 1e-7);
            }
            let d = contact(&b, t, &surface_at(&b, t)).d1;
            let (a, z) = (surface_at(&b, t - h).p, surface_at(&b, t + h).p);
            for i in 0..3 {
                assert!((d[i] - (z[i] - a[i]) / (2.0 * h)).abs() < 1e-5, "{d:?}");
            }
            // On the cylinder whatever the (u, v).
            let c = surface_at(&b, t).p;
            assert!((c[1].hypot(c[2]) - 20.0).abs() < 1e-12);
        }
        // The fast evaluator of the pass gives the reference's points.
        let mut fast = pass_evaluator(&b).unwrap();
        for k in 0..=10 {
            let t = k as f64 / 10.0;
            let (uv, _) = pass_uv(&b, t);
            let (f, r) = (fast.eval(uv[0], uv[1]).p, surface_at(&b, t).p);
            assert!(norm([f[0] - r[0], f[1] - r[1], f[2] - r[2]]) < 1e-12);
        }
    }

    #[test]
    fn cubic_pass_points_are_validated() {
        let mut b = cubic_pass();
        b.surface.uv_inner[1] = [0.5, 1.2];
        assert!(b.validate().is_err());
        let mut b = cubic_pass();
        b.surface.uv_inner[0] = [f64::NAN, 0.5];
        assert!(b.validate().is_err());
        // Inner points without the flag would say two things: refused.
        let mut b = cylinder_pass(20.0);
        b.surface.uv_inner[0] = [0.5, 0.5];
        assert!(b.validate().is_err());
        // The flag on a curve block is refused too.
        let mut b = CommandBlock::empty(crate::protocol::BlockKind::Motion, 0, 1);
        b.flags = crate::protocol::FLAG_UV_CUBIC;
        b.degree = 1;
        b.n_ctrl = 2;
        b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
        b.ctrl[0] = [0.0, 0.0, 0.0, 1.0];
        b.ctrl[1] = [1.0, 0.0, 0.0, 1.0];
        b.feed_mm_per_min = 100.0;
        b.length_mm = 1.0;
        b.acc_mm_per_s2 = 1.0;
        b.jerk_mm_per_s3 = 1.0;
        assert!(b.validate().is_err());
        b.flags = 0;
        assert!(b.validate().is_ok(), "{:?}", b.validate());
    }

    #[test]
    fn surface_blocks_are_validated() {
        let good = cylinder_pass(20.0);
        assert!(good.validate().is_ok());
        let mut b = good;
        b.surface.uv_end = [0.5, 1.5];
        assert!(b.validate().is_err());
        let mut b = good;
        b.surface.tool_length_mm = 1.0;
        assert!(b.validate().is_err());
        let mut b = good;
        b.n_ctrl = 7;
        assert!(b.validate().is_err());
        let mut b = good;
        b.ctrl[2][3] = 0.0;
        assert!(b.validate().is_err());
        let mut b = good;
        b.surface.normal_sign = 0;
        assert!(b.validate().is_err());
        let mut b = good;
        b.surface.degree_v = 0;
        assert!(b.validate().is_err());
    }

    /// A motion block of a curve (no helix unless set after).
    fn curve_block(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> CommandBlock {
        use crate::protocol::BlockKind;
        let mut b = CommandBlock::empty(BlockKind::Motion, 0, 1);
        b.degree = degree as u32;
        b.n_ctrl = ctrl.len() as u32;
        b.ctrl[..ctrl.len()].copy_from_slice(ctrl);
        b.knots[..knots.len()].copy_from_slice(knots);
        b
    }

    /// The fixed rule of before ([`nurbs::arc_length`]: pieces checked a pair at a time,
    /// 32 a span), on the general evaluator, at 1024 pieces a span: the second algorithm.
    fn dense_length(b: &CommandBlock) -> f64 {
        nurbs::arc_length(b.knots(), 1024, |u| norm(eval(b, u).d1))
    }

    /// The adaptive length against closed forms: a line far from the origin (its chord),
    /// a semicircle of radius 7 in two rational quadratic spans (7π), the same arc as a
    /// helix rising 20 mm a radian (π·√(7² + 20²)), and a whole circle of radius 1000 in
    /// four spans (2000π), each to 1e-10 mm (the engine lands stops within 5e-8 mm; the
    /// rule's own tolerance is 1e-12 of the length plus 1e-11 mm a piece).
    #[test]
    fn length_matches_closed_forms() {
        use crate::protocol::Helix;
        let pi = core::f64::consts::PI;
        let line = curve_block(
            1,
            &[0.0, 0.0, 1.0, 1.0],
            &[[950.0, -3.0, 2.0, 1.0], [953.0, 1.0, 14.0, 1.0]],
        );
        assert!((length(&line) - 13.0).abs() < 1e-10, "{}", length(&line));
        let w = core::f64::consts::FRAC_1_SQRT_2;
        let r = 7.0;
        let semi = [
            [r, 0.0, 5.0, 1.0],
            [r, r, 5.0, w],
            [0.0, r, 5.0, 1.0],
            [-r, r, 5.0, w],
            [-r, 0.0, 5.0, 1.0],
        ];
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        let mut arc = curve_block(2, &knots, &semi);
        assert!((length(&arc) - r * pi).abs() < 1e-10, "{}", length(&arc));
        arc.helix = Helix {
            axis: 2,
            dir: 1,
            center_mm: [0.0, 0.0, 5.0],
            start_mm: 5.0,
            mm_per_rad: 20.0,
            seg_rad: core::f64::consts::FRAC_PI_2,
        };
        let helix = pi * (r * r + 20.0f64 * 20.0).sqrt();
        assert!(
            (length(&arc) - helix).abs() < 1e-10,
            "{} {helix}",
            length(&arc)
        );
        let big = 1000.0;
        let circle: Vec<[f64; 4]> = (0..9)
            .map(|i| {
                let a = i as f64 * pi / 4.0;
                let (s, c) = a.sin_cos();
                if i % 2 == 0 {
                    [big * c, big * s, 0.0, 1.0]
                } else {
                    [big * c / w, big * s / w, 0.0, w]
                }
            })
            .collect();
        let k = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 4.0, 4.0];
        let c = curve_block(2, &k, &circle);
        assert!((length(&c) - 2.0 * pi * big).abs() < 1e-9, "{}", length(&c));
    }

    /// The adaptive length against the fixed rule of before at 1024 pieces a span on 300
    /// random rational curves (degree 1 to 5, up to 12 control points, weights 0.2 to 5,
    /// coordinates up to ±500 mm; every fifth folds its polygon back on itself, a
    /// near-cusp): within 1e-11 of the length plus 1e-9 mm. (The same rule at its 32
    /// pieces, what `length` took before, is 4.5e-6 mm off on one of them, case 58.)
    #[test]
    fn length_agrees_with_the_dense_rule_on_random_curves() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut worst = 0.0f64;
        for case in 0..300 {
            let degree = 1 + case % 5;
            let n = degree + 1 + (rnd() * (12 - degree) as f64) as usize;
            // Clamped, the inner knots spread with a jitter (some spans 4 times others).
            let inner = n - degree - 1;
            let mut knots = vec![0.0; degree + 1];
            knots.extend((1..=inner).map(|i| (i as f64 + 0.6 * rnd() - 0.3) / (inner + 1) as f64));
            knots.extend(vec![1.0; degree + 1]);
            let mut ctrl: Vec<[f64; 4]> = (0..n)
                .map(|_| {
                    let w = 0.2 + 4.8 * rnd() * rnd();
                    [
                        1000.0 * rnd() - 500.0,
                        1000.0 * rnd() - 500.0,
                        100.0 * rnd() - 50.0,
                        w,
                    ]
                })
                .collect();
            if case % 5 == 0 && n >= 4 {
                // Fold back: the third point nearly on the second's way back.
                let (a, b) = (ctrl[1], ctrl[0]);
                ctrl[2] = [a[0] + 1e-3 * (b[0] - a[0]), a[1], a[2], a[3]];
            }
            let b = curve_block(degree, &knots, &ctrl);
            let valid = nurbs::validate(degree, &knots, &ctrl, nurbs::MAX_CTRL);
            assert!(valid.is_ok(), "case {case}: {valid:?}");
            let (got, want) = (length(&b), dense_length(&b));
            let err = (got - want).abs() / (1e-11 * want + 1e-9);
            worst = worst.max(err);
            assert!(err <= 1.0, "case {case}: {got} against {want}");
        }
        assert!(worst > 0.0);
    }
}
