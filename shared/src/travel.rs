//! Does a motion block's exact path stay within the machine's travel (its soft limits,
//! `axes.*.min_mm`/`max_mm` in the machine file)?
//!
//! Used by `cnc check` on every motion it plans and by the interpolator on every block it
//! receives, so both refuse the same paths. Allocation-free and panic-free: all scratch
//! lives in fixed-size stack arrays, every loop is bounded, and a call on a block that
//! passed [`CommandBlock::validate`] never formats or allocates (the error's `Display`
//! is for the caller, off the cycle).
//!
//! **Curves.** A rational B-spline with positive weights lies, over each knot span, in the
//! convex hull of that span's active control points, and more tightly in that of its
//! Bézier control points (taken in Cartesian coordinates). A span whose active control
//! points lie within the travel is accepted at once (nearly every span: a few ns each).
//! Any other span is extracted as a rational Bézier piece (by blossoming: de Boor's algorithm with
//! the span's end parameters as arguments, in homogeneous coordinates). Where a piece's
//! hull lies within the travel, the piece is accepted; where it crosses a limit, the piece
//! is halved (de Casteljau at its middle, in homogeneous coordinates) and each half judged
//! again, until either a point on the curve (a piece's end point) lies beyond the limit,
//! and the path is refused, or every hull lies inside. The hulls close in on the curve
//! quadratically, so a path that stays inside is proven so after a few levels even where
//! it touches a limit (a circle's top at 20 levels for a radius of a metre).
//!
//! **Tolerance.** The decision is exact to [`TRAVEL_TOL_MM`] (1e-9 mm): a path that
//! reaches no further than 1e-9 mm beyond a limit is accepted (a circle of radius 10 about
//! the origin with the travel ending at 10 mm is accepted, whatever the rounding of its
//! control points), one that reaches further is refused, and the reach the error states is
//! the path's extreme to within that tolerance. Pieces are halved at most [`MAX_DEPTH`]
//! times and at most [`MAX_PIECES`] pieces are examined per block; should either bound be
//! reached with a hull still beyond the limit by more than the tolerance (no real path
//! comes near: it takes a path that reaches the limit plus 1e-9 mm to within the
//! rounding of a double), the block is refused, conservatively, with the hull's reach
//! and [`TravelError::exact`] false.
//!
//! **Arcs** are rational quadratic NURBS here, so they get their exact extrema the same
//! way. **Helical blocks** ([`crate::protocol::Helix`]) move their linear axis as
//! `start_mm + mm_per_rad·phi` with `phi` monotonic along the arc: that axis's extremes
//! are the block's two end points; the other two axes are the arc's.
//!
//! **Surface blocks** (`FLAG_SURFACE`) publish the tool reference point
//! `M = C + R·n + (H − R)·z`, with `C` on the patch. The bound used is conservative: the
//! patch's control-point hull (which holds every `C`) widened by the ball radius `R` on
//! every axis (`|R·n| <= R`), plus `H − R` along Z. Where that bound crosses a limit, the
//! pass's end points are evaluated exactly: one beyond the limit refuses the block with
//! that reach; otherwise the block is refused on the bound alone (`exact` false: the
//! tool may stay inside, but that is not proven).
#![deny(
    clippy::indexing_slicing,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic
)]

use crate::machine::{Axes, AxisLimits};
use crate::nurbs::MAX_DEGREE;
use crate::path;
use crate::protocol::{BlockKind, CommandBlock, NO_AXIS};

/// How far beyond a limit a path may reach and still be accepted, mm.
pub const TRAVEL_TOL_MM: f64 = 1e-9;

/// Most halvings of one Bézier piece (a piece `2⁻⁴⁰` of its span: far below where the
/// hull of a double-precision curve stops shrinking).
pub const MAX_DEPTH: u32 = 40;

/// Most pieces examined for one block, over all its spans, axes and sides. A real path
/// needs a few dozen per place where it touches a limit; this caps the work a hostile
/// block can cause (about 2048 halvings of a degree-9 piece: well under a millisecond).
pub const MAX_PIECES: usize = 2048;

const ORD: usize = MAX_DEGREE + 1;

/// Homogeneous control point `[w·x, w·y, w·z, w]`.
type H = [f64; 4];

/// Which end of an axis's travel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// `min_mm`: the path goes below it.
    Min,
    /// `max_mm`: the path goes above it.
    Max,
}

impl Side {
    /// The machine-file key of this end.
    pub fn key(self) -> &'static str {
        match self {
            Side::Min => "min_mm",
            Side::Max => "max_mm",
        }
    }

    /// `+1` for max, `-1` for min: the factor that turns "beyond the limit" into "above".
    fn sign(self) -> f64 {
        match self {
            Side::Min => -1.0,
            Side::Max => 1.0,
        }
    }
}

/// A path that leaves the travel: on which axis, how far it reaches, and the limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TravelError {
    /// 0 X, 1 Y, 2 Z.
    pub axis: usize,
    pub side: Side,
    /// The path's extreme on that axis beyond the limit, mm (to [`TRAVEL_TOL_MM`]); when
    /// `exact` is false, a bound on it.
    pub reach_mm: f64,
    /// The limit passed: `axes.<axis>.min_mm` or `max_mm`.
    pub limit_mm: f64,
    /// `true`: a point of the path reaches `reach_mm`. `false`: only a bound of the path
    /// does (a surface block's tool, or a refinement that ran out of its budget).
    pub exact: bool,
}

impl TravelError {
    /// The axis letter, `X`, `Y` or `Z`.
    pub fn axis_name(&self) -> &'static str {
        ["X", "Y", "Z"].get(self.axis).copied().unwrap_or("?")
    }

    /// How far beyond the limit, mm (positive).
    pub fn excess_mm(&self) -> f64 {
        self.side.sign() * (self.reach_mm - self.limit_mm)
    }
}

/// `v` rounded to a nanometre for a message, unless that hides how it differs from `than`.
fn shown(v: f64, than: f64) -> f64 {
    let r = (v * 1e6).round() / 1e6;
    if r == than {
        v
    } else {
        r
    }
}

impl core::fmt::Display for TravelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let axis = self.axis_name();
        let (dir, past) = match self.side {
            Side::Max => ("up to", "above"),
            Side::Min => ("down to", "below"),
        };
        let reach = shown(self.reach_mm, self.limit_mm);
        let excess = self.excess_mm();
        let excess = if excess >= 1e-6 {
            (excess * 1e6).round() / 1e6
        } else {
            excess
        };
        let lower = ["x", "y", "z"].get(self.axis).copied().unwrap_or("?");
        let key = self.side.key();
        if self.exact {
            write!(
                f,
                "the path takes {axis} {dir} {reach} mm, {excess} mm {past} its travel limit \
                 of {} mm (axes.{lower}.{key} in the machine file)",
                self.limit_mm
            )
        } else {
            write!(
                f,
                "the tool may take {axis} {dir} {reach} mm (a bound of the path: the surface \
                 patch widened by the tool), {excess} mm {past} its travel limit of {} mm \
                 (axes.{lower}.{key} in the machine file)",
                self.limit_mm
            )
        }
    }
}

/// Is the point `p` within the travel of every axis, to [`TRAVEL_TOL_MM`]? The error
/// names the first axis it is not (with `reach_mm` the point's coordinate).
pub fn check_point(p: [f64; 3], axes: &Axes) -> Result<(), TravelError> {
    for (axis, (x, lim)) in p.iter().zip(axes.as_array()).enumerate() {
        for side in [Side::Max, Side::Min] {
            let (s, limit) = signed_limit(&lim, side);
            // NaN is never within.
            let within = s * x <= s * limit + TRAVEL_TOL_MM;
            if !within {
                return Err(TravelError {
                    axis,
                    side,
                    reach_mm: *x,
                    limit_mm: limit,
                    exact: true,
                });
            }
        }
    }
    Ok(())
}

fn signed_limit(lim: &AxisLimits, side: Side) -> (f64, f64) {
    match side {
        Side::Max => (1.0, lim.max_mm),
        Side::Min => (-1.0, lim.min_mm),
    }
}

/// Does the path of a motion block stay within the travel of `axes`? Blocks other than
/// motions have no path: `Ok`. The block must have passed [`CommandBlock::validate`]; on
/// one that has not, the answer is unspecified but never a panic.
pub fn check_block(block: &CommandBlock, axes: &Axes) -> Result<(), TravelError> {
    if block.kind != BlockKind::Motion as u32 {
        return Ok(());
    }
    if block.is_surface() {
        return check_surface(block, axes);
    }
    let helix_axis = (block.helix.axis != NO_AXIS).then_some(block.helix.axis as usize);
    check_curve_except(
        block.degree as usize,
        block.knots(),
        block.ctrl(),
        axes,
        helix_axis,
    )?;
    if let Some(axis) = helix_axis {
        // Linear in the angle, which only grows along the arc: the ends are its extremes.
        let (u0, u1) = path::domain(block);
        for u in [u0, u1] {
            let p = path::eval(block, u).p;
            if let Err(e) = check_point(p, axes) {
                if e.axis == axis {
                    return Err(e);
                }
            }
        }
    }
    Ok(())
}

/// Does the clamped NURBS `(degree, knots, ctrl)` (control points `[x, y, z, w]`, all
/// weights positive; as [`crate::nurbs::validate`] accepts) stay within the travel?
pub fn check_curve(
    degree: usize,
    knots: &[f64],
    ctrl: &[[f64; 4]],
    axes: &Axes,
) -> Result<(), TravelError> {
    check_curve_except(degree, knots, ctrl, axes, None)
}

/// The refusal of a curve that cannot be read (not a validated curve).
const UNREADABLE: TravelError = TravelError {
    axis: 0,
    side: Side::Max,
    reach_mm: f64::INFINITY,
    limit_mm: f64::NAN,
    exact: false,
};

fn check_curve_except(
    degree: usize,
    knots: &[f64],
    ctrl: &[[f64; 4]],
    axes: &Axes,
    skip_axis: Option<usize>,
) -> Result<(), TravelError> {
    if degree == 0 || degree > MAX_DEGREE || knots.len() != ctrl.len() + degree + 1 {
        return Err(UNREADABLE);
    }
    let mut budget = MAX_PIECES;
    let lims = axes.as_array();
    let mut bez = [[0.0; 4]; ORD];
    for k in degree..ctrl.len() {
        match (knots.get(k), knots.get(k + 1)) {
            (Some(a), Some(b)) if b > a => {}
            (Some(_), Some(_)) => continue,
            _ => return Err(UNREADABLE),
        }
        // The span lies in the hull of its active control points: when they are all
        // within the travel (nearly always), nothing needs extracting. Else its Bézier
        // piece's hull is tighter, and that is refined.
        let Some(active) = k.checked_sub(degree).and_then(|f| ctrl.get(f..=k)) else {
            return Err(UNREADABLE);
        };
        let inside = |axis: usize, s: f64, high: f64| {
            active.iter().all(|c| {
                let x = c.get(axis).copied().unwrap_or(f64::NAN);
                s * x <= high + TRAVEL_TOL_MM
            })
        };
        let mut extracted = false;
        for (axis, lim) in lims.iter().enumerate() {
            if skip_axis == Some(axis) {
                continue;
            }
            for side in [Side::Max, Side::Min] {
                let (s, limit) = signed_limit(lim, side);
                if inside(axis, s, s * limit) {
                    continue;
                }
                if !extracted {
                    if !span_bezier(degree, knots, ctrl, k, &mut bez) {
                        return Err(UNREADABLE);
                    }
                    extracted = true;
                }
                let at = Axis { axis, s };
                match judge(&bez, degree, at, s * limit, &mut budget) {
                    Verdict::Inside => {}
                    Verdict::Beyond | Verdict::Bound => {
                        let (reach, exact) = extreme(degree, knots, ctrl, at);
                        return Err(TravelError {
                            axis,
                            side,
                            reach_mm: s * reach,
                            limit_mm: limit,
                            exact,
                        });
                    }
                }
            }
        }
    }
    Ok(())
}

/// One axis, and the sign that makes the side judged the "high" one.
#[derive(Clone, Copy)]
struct Axis {
    axis: usize,
    s: f64,
}

impl Axis {
    /// The signed Cartesian coordinate of a homogeneous point.
    #[inline]
    fn of(self, h: &H) -> f64 {
        let x = h.get(self.axis).copied().unwrap_or(f64::NAN);
        self.s * x / h[3]
    }

    /// Highest signed coordinate of the first `n` points (NaN if any is NaN).
    fn hull_max(self, pts: &[H; ORD], n: usize) -> f64 {
        pts.iter().take(n).fold(f64::NEG_INFINITY, |m, h| {
            let v = self.of(h);
            if v.is_nan() || m.is_nan() {
                f64::NAN
            } else {
                m.max(v)
            }
        })
    }

    /// The higher signed coordinate of the piece's two end points (on the curve).
    fn ends_max(self, pts: &[H; ORD], degree: usize) -> f64 {
        let last = pts.get(degree).map_or(f64::NAN, |h| self.of(h));
        self.of(&pts[0]).max(last)
    }
}

enum Verdict {
    /// Every hull within the limit (plus the tolerance).
    Inside,
    /// A point of the curve beyond it.
    Beyond,
    /// Undecided at the depth or work bound: refused conservatively.
    Bound,
}

/// A Bézier piece and how many halvings made it.
#[derive(Clone, Copy)]
struct Piece {
    pts: [H; ORD],
    depth: u32,
}

/// Is the rational Bézier `bez` of `degree` within `high` (signed) on `at`?
fn judge(bez: &[H; ORD], degree: usize, at: Axis, high: f64, budget: &mut usize) -> Verdict {
    let n = degree + 1;
    let ok = |v: f64| v <= high + TRAVEL_TOL_MM;
    if ok(at.hull_max(bez, n)) {
        return Verdict::Inside;
    }
    let mut stack = [Piece {
        pts: [[0.0; 4]; ORD],
        depth: 0,
    }; MAX_DEPTH as usize + 2];
    stack[0].pts = *bez;
    let mut len = 1usize;
    while len > 0 {
        len -= 1;
        let Some(&piece) = stack.get(len) else {
            return Verdict::Bound;
        };
        if ok(at.hull_max(&piece.pts, n)) {
            continue;
        }
        let ends = at.ends_max(&piece.pts, degree);
        if !ok(ends) && !ends.is_nan() {
            return Verdict::Beyond;
        }
        if piece.depth >= MAX_DEPTH || *budget == 0 || len + 2 > stack.len() {
            return Verdict::Bound;
        }
        *budget -= 1;
        len = push_halves(&mut stack, len, &piece, degree);
    }
    Verdict::Inside
}

/// Halves `piece` (de Casteljau at its middle) and pushes both halves on `stack` above
/// its first `len` pieces, right below left so the left half is judged first; the new
/// length. The callers leave room for two.
fn push_halves(stack: &mut [Piece], len: usize, piece: &Piece, degree: usize) -> usize {
    let (l, r) = halve(&piece.pts, degree);
    let mut len = len;
    for half in [r, l] {
        if let Some(slot) = stack.get_mut(len) {
            *slot = Piece {
                pts: half,
                depth: piece.depth + 1,
            };
            len += 1;
        }
    }
    len
}

/// The curve's highest signed coordinate on `at`, to [`TRAVEL_TOL_MM`] (branch and bound
/// over the spans' Bézier pieces), and whether it is exact (`false`: the depth or work
/// bound was reached and the value is a bound from a hull). Only called for a refusal.
fn extreme(degree: usize, knots: &[f64], ctrl: &[[f64; 4]], at: Axis) -> (f64, bool) {
    let n = degree + 1;
    let mut best = f64::NEG_INFINITY;
    let mut bound = f64::NEG_INFINITY;
    let mut budget = MAX_PIECES;
    let mut bez = [[0.0; 4]; ORD];
    let mut stack = [Piece {
        pts: [[0.0; 4]; ORD],
        depth: 0,
    }; MAX_DEPTH as usize + 2];
    for k in degree..ctrl.len() {
        match (knots.get(k), knots.get(k + 1)) {
            (Some(a), Some(b)) if b > a => {}
            _ => continue,
        }
        if !span_bezier(degree, knots, ctrl, k, &mut bez) {
            return (f64::INFINITY, false);
        }
        stack[0] = Piece { pts: bez, depth: 0 };
        let mut len = 1usize;
        while len > 0 {
            len -= 1;
            let Some(&piece) = stack.get(len) else {
                break;
            };
            let hull = at.hull_max(&piece.pts, n);
            best = best.max(at.ends_max(&piece.pts, degree));
            if hull <= best + TRAVEL_TOL_MM {
                continue;
            }
            if piece.depth >= MAX_DEPTH || budget == 0 || len + 2 > stack.len() || hull.is_nan() {
                bound = bound.max(if hull.is_nan() { f64::INFINITY } else { hull });
                continue;
            }
            budget -= 1;
            len = push_halves(&mut stack, len, &piece, degree);
        }
    }
    if bound > best + TRAVEL_TOL_MM {
        (bound, false)
    } else {
        (best, true)
    }
}

/// Homogeneous form of `[x, y, z, w]`.
#[inline]
fn homogeneous(c: &[f64; 4]) -> H {
    [c[0] * c[3], c[1] * c[3], c[2] * c[3], c[3]]
}

#[inline]
fn lerp(a: &H, b: &H, t: f64) -> H {
    let s = 1.0 - t;
    [
        s * a[0] + t * b[0],
        s * a[1] + t * b[1],
        s * a[2] + t * b[2],
        s * a[3] + t * b[3],
    ]
}

/// The rational Bézier control points (homogeneous) of knot span `k` (`knots[k] <
/// knots[k + 1]`) of a clamped curve of `degree`, into `out[..=degree]`: point `j` is the
/// blossom `b(a, …, a, b, …, b)` with `j` arguments `b`, by de Boor's algorithm taking one
/// argument per level. Every blend is convex (the arguments lie in the span), so the
/// weights stay positive. `false` if the slices are too short for the span.
fn span_bezier(
    degree: usize,
    knots: &[f64],
    ctrl: &[[f64; 4]],
    k: usize,
    out: &mut [H; ORD],
) -> bool {
    let (Some(&a), Some(&b)) = (knots.get(k), knots.get(k + 1)) else {
        return false;
    };
    let Some(first) = k.checked_sub(degree) else {
        return false;
    };
    let Some(active) = ctrl.get(first..=k) else {
        return false;
    };
    for (j, slot) in out.iter_mut().take(degree + 1).enumerate() {
        let mut d = [[0.0; 4]; ORD];
        for (di, c) in d.iter_mut().zip(active) {
            *di = homogeneous(c);
        }
        for r in 1..=degree {
            let u = if r <= degree - j { a } else { b };
            // Descending, so that d[i - 1] still holds the previous level.
            for i in (r..=degree).rev() {
                let g = first + i;
                let (Some(&lo), Some(&hi)) = (knots.get(g), knots.get(g + degree + 1 - r)) else {
                    return false;
                };
                let alpha = if hi > lo { (u - lo) / (hi - lo) } else { 0.0 };
                let (Some(&prev), Some(&cur)) = (d.get(i - 1), d.get(i)) else {
                    return false;
                };
                if let Some(di) = d.get_mut(i) {
                    *di = lerp(&prev, &cur, alpha);
                }
            }
        }
        match d.get(degree) {
            Some(p) => *slot = *p,
            None => return false,
        }
    }
    true
}

/// De Casteljau at the middle of a rational Bézier of `degree` (homogeneous): the left and
/// the right half, each again of `degree`.
fn halve(pts: &[H; ORD], degree: usize) -> ([H; ORD], [H; ORD]) {
    let mut w = *pts;
    let mut left = [[0.0; 4]; ORD];
    let mut right = [[0.0; 4]; ORD];
    left[0] = w[0];
    if let (Some(r), Some(p)) = (right.get_mut(degree), w.get(degree)) {
        *r = *p;
    }
    for r in 1..=degree {
        for i in 0..=degree - r {
            if let (Some(&a), Some(&b)) = (w.get(i), w.get(i + 1)) {
                if let Some(x) = w.get_mut(i) {
                    *x = lerp(&a, &b, 0.5);
                }
            }
        }
        if let (Some(l), Some(p)) = (left.get_mut(r), w.first()) {
            *l = *p;
        }
        if let (Some(rt), Some(p)) = (right.get_mut(degree - r), w.get(degree - r)) {
            *rt = *p;
        }
    }
    (left, right)
}

/// Where a curve breaks apart: the interior knot and the distance between the curve's
/// end on the span before it and its start on the span after it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jump {
    pub knot: f64,
    pub gap_mm: f64,
}

/// The largest jump of the clamped NURBS `(degree, knots, ctrl)` at an interior knot, if
/// it has any knot that may break it: one repeated more than `degree` times (with at most
/// `degree` repeats a B-spline is continuous there by construction, and nothing is
/// computed). Allocation-free and panic-free; on a curve that is not valid, `None` or a
/// gap of infinity.
pub fn largest_jump(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> Option<Jump> {
    let n = ctrl.len();
    let mut worst: Option<Jump> = None;
    let mut bez = [[0.0; 4]; ORD];
    // The last non-empty span before the current knot run, and its end point.
    let mut prev: Option<usize> = None;
    for k in degree..n {
        let (Some(&a), Some(&b)) = (knots.get(k), knots.get(k + 1)) else {
            return None;
        };
        if b <= a {
            continue;
        }
        if let Some(pk) = prev {
            let mult = knots.iter().filter(|&&t| t == a).count();
            if mult > degree {
                let end = if span_bezier(degree, knots, ctrl, pk, &mut bez) {
                    bez.get(degree).map(cartesian)
                } else {
                    None
                };
                let start = if span_bezier(degree, knots, ctrl, k, &mut bez) {
                    Some(cartesian(&bez[0]))
                } else {
                    None
                };
                let gap = match (end, start) {
                    (Some(e), Some(s)) => path::norm([e[0] - s[0], e[1] - s[1], e[2] - s[2]]),
                    _ => f64::INFINITY,
                };
                let gap = if gap.is_nan() { f64::INFINITY } else { gap };
                if worst.is_none_or(|w| gap > w.gap_mm) {
                    worst = Some(Jump {
                        knot: a,
                        gap_mm: gap,
                    });
                }
            }
        }
        prev = Some(k);
    }
    worst
}

#[inline]
fn cartesian(h: &H) -> [f64; 3] {
    [h[0] / h[3], h[1] / h[3], h[2] / h[3]]
}

/// A surface block: the conservative bound of the module's page, then its exact ends.
fn check_surface(block: &CommandBlock, axes: &Axes) -> Result<(), TravelError> {
    let sp = &block.surface;
    let (r, h) = (sp.tool_radius_mm, sp.tool_length_mm);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for c in block.ctrl() {
        for (a, (l, u)) in lo.iter_mut().zip(hi.iter_mut()).enumerate() {
            let x = c.get(a).copied().unwrap_or(f64::NAN);
            *l = if x.is_nan() { f64::NAN } else { l.min(x) };
            *u = if x.is_nan() { f64::NAN } else { u.max(x) };
        }
    }
    let lims = axes.as_array();
    for (axis, lim) in lims.iter().enumerate() {
        let lift = if axis == 2 { h - r } else { 0.0 };
        let (Some(&l), Some(&u)) = (lo.get(axis), hi.get(axis)) else {
            continue;
        };
        for (side, bound) in [(Side::Max, u + r + lift), (Side::Min, l - r + lift)] {
            let (s, limit) = signed_limit(lim, side);
            if s * bound <= s * limit + TRAVEL_TOL_MM {
                continue;
            }
            // Beyond on the bound: an end of the tool's path beyond on this axis is exact.
            for t in [0.0, 1.0] {
                let p = path::eval(block, t).p;
                if let Err(e) = check_point(p, axes) {
                    if e.axis == axis && e.side == side {
                        return Err(e);
                    }
                }
            }
            return Err(TravelError {
                axis,
                side,
                reach_mm: bound,
                limit_mm: limit,
                exact: false,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests {
    use super::*;
    use crate::protocol::{Helix, FLAG_SURFACE};
    use core::f64::consts::FRAC_1_SQRT_2;

    fn axes(lo: f64, hi: f64) -> Axes {
        let mut a = Axes::default();
        for l in [&mut a.x, &mut a.y, &mut a.z] {
            l.min_mm = lo;
            l.max_mm = hi;
        }
        a
    }

    /// A full circle of radius `r` about `(cx, cy)` in the XY plane: four rational
    /// quadratic quarter arcs (as the interpreter builds arcs).
    fn circle(cx: f64, cy: f64, r: f64) -> (Vec<f64>, Vec<[f64; 4]>) {
        let w = FRAC_1_SQRT_2;
        let pts = [
            (1.0, 0.0, 1.0),
            (1.0, 1.0, w),
            (0.0, 1.0, 1.0),
            (-1.0, 1.0, w),
            (-1.0, 0.0, 1.0),
            (-1.0, -1.0, w),
            (0.0, -1.0, 1.0),
            (1.0, -1.0, w),
            (1.0, 0.0, 1.0),
        ];
        let ctrl = pts
            .iter()
            .map(|&(x, y, w)| [cx + r * x, cy + r * y, 0.0, w])
            .collect();
        let knots = vec![0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 4.0, 4.0];
        (knots, ctrl)
    }

    #[test]
    fn a_circle_reaches_exactly_its_radius() {
        // Centre (3, -2), radius 10: X spans [-7, 13], Y spans [-12, 8].
        let (k, c) = circle(3.0, -2.0, 10.0);
        let mut a = axes(-100.0, 100.0);
        assert_eq!(check_curve(2, &k, &c, &a), Ok(()));
        // Touching the limit exactly: accepted.
        a.x.max_mm = 13.0;
        a.x.min_mm = -7.0;
        a.y.min_mm = -12.0;
        a.y.max_mm = 8.0;
        assert_eq!(check_curve(2, &k, &c, &a), Ok(()));
        // The control points reach 13 too: a limit a hair inside must refine to decide.
        a.x.max_mm = 13.0 - 1e-6;
        let e = check_curve(2, &k, &c, &a).unwrap_err();
        assert_eq!((e.axis, e.side, e.exact), (0, Side::Max, true));
        assert!((e.reach_mm - 13.0).abs() <= TRAVEL_TOL_MM, "{e:?}");
        assert_eq!(e.limit_mm, 13.0 - 1e-6);
        let msg = e.to_string();
        assert!(
            msg.contains("X up to 13 mm") && msg.contains("axes.x.max_mm"),
            "{msg}"
        );
        // The lowest Y, where the hull's corners (±10, -10 about the centre) do not touch.
        a.x.max_mm = 100.0;
        a.y.min_mm = -11.5;
        let e = check_curve(2, &k, &c, &a).unwrap_err();
        assert_eq!((e.axis, e.side), (1, Side::Min));
        assert!((e.reach_mm + 12.0).abs() <= TRAVEL_TOL_MM, "{e:?}");
        assert!(e.to_string().contains("Y down to -12 mm"), "{e}");
    }

    #[test]
    fn a_rotated_arc_gets_its_exact_extreme_between_control_points() {
        // A quarter arc of radius 50 from 20° to 110° about the origin: its top (Y = 50 at
        // 90°) lies strictly inside the span, where no control point is.
        let (r, a0, a1) = (50.0f64, 20f64.to_radians(), 110f64.to_radians());
        let half = 0.5 * (a1 - a0);
        let mid = r / half.cos();
        let am = 0.5 * (a0 + a1);
        let ctrl = [
            [r * a0.cos(), r * a0.sin(), 0.0, 1.0],
            [mid * am.cos(), mid * am.sin(), 0.0, half.cos()],
            [r * a1.cos(), r * a1.sin(), 0.0, 1.0],
        ];
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let mut a = axes(-100.0, 100.0);
        a.y.max_mm = 50.0;
        assert_eq!(check_curve(2, &knots, &ctrl, &a), Ok(()));
        a.y.max_mm = 49.99;
        let e = check_curve(2, &knots, &ctrl, &a).unwrap_err();
        assert!((e.reach_mm - 50.0).abs() <= TRAVEL_TOL_MM, "{e:?}");
        assert!(e.exact);
    }

    #[test]
    fn a_line_reaches_its_end_points() {
        let ctrl = [[0.0, 0.0, 0.0, 1.0], [1000.5, -3.0, 7.0, 1.0]];
        let knots = [0.0, 0.0, 1.0, 1.0];
        let e = check_curve(1, &knots, &ctrl, &Axes::default()).unwrap_err();
        assert_eq!(
            (e.axis, e.side, e.reach_mm, e.limit_mm),
            (0, Side::Max, 1000.5, 1000.0)
        );
        assert!((e.excess_mm() - 0.5).abs() < 1e-12);
        let msg = e.to_string();
        assert!(
            msg.contains("X up to 1000.5 mm, 0.5 mm above its travel limit of 1000 mm"),
            "{msg}"
        );
        let ctrl = [[0.0, 0.0, 0.0, 1.0], [1000.0, -1000.0, 7.0, 1.0]];
        assert_eq!(check_curve(1, &knots, &ctrl, &Axes::default()), Ok(()));
    }

    #[test]
    fn a_hull_across_the_limit_with_the_curve_inside_is_accepted() {
        // The parabola (0,0) (5,10) (10,0): its top is y = 5, its hull reaches 10.
        let ctrl = [
            [0.0, 0.0, 0.0, 1.0],
            [5.0, 10.0, 0.0, 1.0],
            [10.0, 0.0, 0.0, 1.0],
        ];
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0];
        let mut a = axes(-100.0, 100.0);
        a.y.max_mm = 6.0;
        assert_eq!(check_curve(2, &knots, &ctrl, &a), Ok(()));
        a.y.max_mm = 5.0;
        assert_eq!(check_curve(2, &knots, &ctrl, &a), Ok(()));
        a.y.max_mm = 4.9;
        let e = check_curve(2, &knots, &ctrl, &a).unwrap_err();
        assert!((e.reach_mm - 5.0).abs() <= TRAVEL_TOL_MM, "{e:?}");
        // A heavy weight pulls a rational curve towards its control point: w = 4 on the
        // middle one gives a top of 2·w/(1 + w)·5 = 8.
        let ctrl = [
            [0.0, 0.0, 0.0, 1.0],
            [5.0, 10.0, 0.0, 4.0],
            [10.0, 0.0, 0.0, 1.0],
        ];
        a.y.max_mm = 8.0;
        assert_eq!(check_curve(2, &knots, &ctrl, &a), Ok(()));
        a.y.max_mm = 7.9;
        let e = check_curve(2, &knots, &ctrl, &a).unwrap_err();
        assert!((e.reach_mm - 8.0).abs() <= TRAVEL_TOL_MM, "{e:?}");
    }

    #[test]
    fn a_multi_span_cubic_is_judged_span_by_span() {
        // Uniform cubic B-spline whose control polygon pokes out at Z = 20 in the middle:
        // the curve itself reaches (1·0 + 4·20 + 1·0)/6 = 13.33… at the middle knot.
        let ctrl = [
            [0.0, 0.0, 0.0, 1.0],
            [1.0, 0.0, 0.0, 1.0],
            [2.0, 0.0, 0.0, 1.0],
            [3.0, 0.0, 20.0, 1.0],
            [4.0, 0.0, 0.0, 1.0],
            [5.0, 0.0, 0.0, 1.0],
            [6.0, 0.0, 0.0, 1.0],
        ];
        let knots = [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 4.0, 4.0, 4.0];
        let mut a = axes(-100.0, 100.0);
        a.z.max_mm = 40.0 / 3.0 + 1e-10;
        assert_eq!(check_curve(3, &knots, &ctrl, &a), Ok(()));
        a.z.max_mm = 13.3;
        let e = check_curve(3, &knots, &ctrl, &a).unwrap_err();
        assert!((e.reach_mm - 40.0 / 3.0).abs() <= TRAVEL_TOL_MM, "{e:?}");
        assert_eq!((e.axis, e.side), (2, Side::Max));
    }

    fn line_block(from: [f64; 3], to: [f64; 3]) -> CommandBlock {
        let mut b = CommandBlock::empty(BlockKind::Motion, 0, 1);
        b.degree = 1;
        b.n_ctrl = 2;
        b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
        b.ctrl[0] = [from[0], from[1], from[2], 1.0];
        b.ctrl[1] = [to[0], to[1], to[2], 1.0];
        b
    }

    #[test]
    fn a_helix_moves_its_axis_to_its_end() {
        // Half a turn of radius 5 about (0, 0) in XY, Z from 990 rising 20 mm per radian:
        // the end is at 990 + 20π = 1052.8.
        let w = FRAC_1_SQRT_2;
        let mut b = line_block([0.0; 3], [0.0; 3]);
        b.degree = 2;
        b.n_ctrl = 5;
        let k = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        b.knots[..8].copy_from_slice(&k);
        let pts = [
            [5.0, 0.0, 990.0, 1.0],
            [5.0, 5.0, 990.0, w],
            [0.0, 5.0, 990.0, 1.0],
            [-5.0, 5.0, 990.0, w],
            [-5.0, 0.0, 990.0, 1.0],
        ];
        b.ctrl[..5].copy_from_slice(&pts);
        b.helix = Helix {
            axis: 2,
            dir: 1,
            center_mm: [0.0, 0.0, 990.0],
            start_mm: 990.0,
            mm_per_rad: 20.0,
            seg_rad: core::f64::consts::FRAC_PI_2,
        };
        let e = check_block(&b, &Axes::default()).unwrap_err();
        assert_eq!((e.axis, e.side), (2, Side::Max));
        assert!((e.reach_mm - (990.0 + 20.0 * core::f64::consts::PI)).abs() < 1e-9);
        // Going down instead stays inside.
        b.helix.mm_per_rad = -20.0;
        assert_eq!(check_block(&b, &Axes::default()), Ok(()));
        // The arc's own Y extreme (5 at the quarter) is still the arc's.
        let mut a = Axes::default();
        a.y.max_mm = 4.5;
        let e = check_block(&b, &a).unwrap_err();
        assert_eq!(e.axis, 1);
        assert!((e.reach_mm - 5.0).abs() <= TRAVEL_TOL_MM);
    }

    #[test]
    fn blocks_other_than_motion_and_points() {
        let b = CommandBlock::empty(BlockKind::Dwell, 0, 1);
        assert_eq!(check_block(&b, &Axes::default()), Ok(()));
        let b = line_block([0.0, 0.0, -999.0], [0.0, 0.0, -1000.5]);
        let e = check_block(&b, &Axes::default()).unwrap_err();
        assert_eq!((e.axis, e.side, e.reach_mm), (2, Side::Min, -1000.5));
        assert!(e.to_string().contains("Z down to -1000.5 mm"), "{e}");
        assert_eq!(
            check_point([1000.0, -1000.0, 0.0], &Axes::default()),
            Ok(())
        );
        assert!(check_point([0.0, f64::NAN, 0.0], &Axes::default()).is_err());
        let e = check_point([0.0, 1000.001, 0.0], &Axes::default()).unwrap_err();
        assert_eq!((e.axis, e.side), (1, Side::Max));
    }

    #[test]
    fn a_surface_pass_is_bounded_by_its_patch_and_tool() {
        // The quarter cylinder of radius 20: patch Z in [0, 20], tool R 3, H 40: the
        // bound is 20 + 3 + 37 = 60; the tool point itself reaches 20 + 3 + 37 = 60 at
        // the top (the pass starts there), so the end is exact.
        let b = crate::path::quarter_cylinder_pass(20.0);
        assert_eq!(b.flags & FLAG_SURFACE, FLAG_SURFACE);
        assert_eq!(check_block(&b, &Axes::default()), Ok(()));
        let mut a = Axes::default();
        a.z.max_mm = 59.0;
        let e = check_block(&b, &a).unwrap_err();
        assert!(e.exact && (e.reach_mm - 60.0).abs() < 1e-9, "{e:?}");
        // Y: the patch reaches 20, the tool's ball 23 at the pass's end (exact).
        a.z.max_mm = 1000.0;
        a.y.max_mm = 22.0;
        let e = check_block(&b, &a).unwrap_err();
        assert!(e.exact && (e.reach_mm - 23.0).abs() < 1e-9, "{e:?}");
        // X: the patch spans 0..10 but the pass runs at x = 5; the bound (13) is refused
        // as a bound, and said to be one.
        a.y.max_mm = 1000.0;
        a.x.max_mm = 12.0;
        let e = check_block(&b, &a).unwrap_err();
        assert!(!e.exact && (e.reach_mm - 13.0).abs() < 1e-12, "{e:?}");
        assert!(e.to_string().contains("may take X up to 13 mm"), "{e}");
    }

    #[test]
    fn a_knot_repeated_more_than_the_degree_may_break_the_curve() {
        // Order 3, knots 0 0 0 1 1 1 2 2 2: two parabolas, the second starting 1.414 mm
        // from where the first ends (the LinuxCNC G6.2 of issue #22).
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        let ctrl = [
            [0.0, 0.0, 0.0, 1.0],
            [1.0, 1.0, 0.0, 1.0],
            [2.0, 0.0, 0.0, 1.0],
            [3.0, 1.0, 0.0, 1.0],
            [4.0, 0.0, 0.0, 1.0],
            [5.0, 1.0, 0.0, 1.0],
        ];
        let j = largest_jump(2, &knots, &ctrl).unwrap();
        assert_eq!(j.knot, 1.0);
        assert!((j.gap_mm - 2f64.sqrt()).abs() < 1e-12, "{j:?}");
        // Joined there (the second parabola starting at (2, 0)): no jump.
        let mut joined = ctrl;
        joined[3] = [2.0, 0.0, 0.0, 1.0];
        assert_eq!(largest_jump(2, &knots, &joined).unwrap().gap_mm, 0.0);
        // A knot repeated `degree` times is continuous by construction: not even looked at.
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        assert_eq!(largest_jump(2, &knots, &ctrl[..5]), None);
        // Weights count: the end of a rational span is its last control point.
        let knots = [0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0];
        let mut heavy = joined;
        heavy[1][3] = 5.0;
        heavy[4][3] = 0.2;
        assert_eq!(largest_jump(2, &knots, &heavy).unwrap().gap_mm, 0.0);
    }

    #[test]
    fn hostile_curves_end_in_bounded_work_without_panic() {
        // NaN, a zero-length slice, a degree past the capacity: refused, never a panic.
        let ctrl = [[f64::NAN, 0.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.0]];
        let knots = [0.0, 0.0, 1.0, 1.0];
        assert!(check_curve(1, &knots, &ctrl, &Axes::default()).is_err());
        assert!(check_curve(1, &knots[..3], &ctrl, &Axes::default()).is_err());
        assert!(check_curve(12, &knots, &ctrl, &Axes::default()).is_err());
        // A degree-9 curve wiggling along the limit: decided within the budget.
        let n = 36;
        let ctrl: Vec<[f64; 4]> = (0..n)
            .map(|i| {
                let y = if i % 2 == 0 { 1000.0 } else { 1000.0 + 1e-3 };
                [i as f64, y, 0.0, 1.0 + (i % 3) as f64]
            })
            .collect();
        let mut knots = vec![0.0; 10];
        knots.extend((1..n - 9).map(|i| i as f64));
        knots.extend(vec![(n - 9) as f64; 10]);
        assert!(check_curve(9, &knots, &ctrl, &Axes::default()).is_err());
    }
}
