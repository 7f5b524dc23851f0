//! STEP-NC input: ISO 10303-21 exchange files holding the ISO 14649-10/11 subset a
//! free-form finishing job needs (seed 000: the surface itself goes to the control).
//!
//! [`p21`] reads the exchange structure (instances with their lines); [`entities`] gives
//! the subset its meaning ([`curves`] reads a CAD file's curves instead, for
//! `cnc cam curves`); [`read_part`] does both and hands back every free-form
//! workingstep with its surface already placed in machine coordinates, or every error of
//! the file as `FILE:LINE: #ID: rule: message` ([`format_errors`]).
//!
//! # The subset, attribute by attribute (ISO 14649 inheritance order)
//!
//! * `WORKPLAN(its_id, its_elements, its_channel, its_setup, its_effect)`: every
//!   workplan of the file; its `MACHINING_WORKINGSTEP` elements in order (other
//!   elements are skipped).
//! * `SETUP(its_id, its_origin, its_secplane, its_workpiece_setup)` and
//!   `WORKPIECE_SETUP(its_workpiece, its_origin, its_offset, its_restricted_area,
//!   its_instructions)`: machine coordinates = setup origin ∘ workpiece setup origin ∘
//!   feature placement, each an `AXIS2_PLACEMENT_3D(name, location, axis, ref_direction)`
//!   (`$` axis = z, `$` ref_direction = x).
//! * `MACHINING_WORKINGSTEP(its_id, its_secplane, its_feature, its_operation, its_effect)`.
//! * `REGION_SURFACE_LIST(its_id, its_workpiece, its_operations, feature_placement, depth,
//!   surface_list)` with one surface.
//! * The surface: `B_SPLINE_SURFACE_WITH_KNOTS(name, u_degree, v_degree,
//!   control_points_list, surface_form, u_closed, v_closed, self_intersect,
//!   u_multiplicities, v_multiplicities, u_knots, v_knots, knot_spec)`, or the complex
//!   instance with `B_SPLINE_SURFACE(u_degree, v_degree, control_points_list, …)`,
//!   `B_SPLINE_SURFACE_WITH_KNOTS(u_multiplicities, v_multiplicities, u_knots, v_knots,
//!   knot_spec)` and `RATIONAL_B_SPLINE_SURFACE(weights_data)`. `control_points_list[i][j]`
//!   is `P_ij`, `i` along `u`; points are `CARTESIAN_POINT(name, (x, y, z))` in mm.
//! * Or the surface: `T_SPLINE_SURFACE(name, s_degree, t_degree, s_knot_lines,
//!   t_knot_lines, s_segments, t_segments, control_points, weights, anchors,
//!   s_local_knots, t_local_knots)`, the project's own form (seed 003 names the entity
//!   but prints no attributes), read by [`tspline`]: it becomes one free-form workingstep
//!   per T-region, each a tensor-product surface of its Bézier patches.
//! * `FREEFORM_OPERATION(its_toolpath, its_tool_direction, its_id, retract_plane,
//!   start_point, its_tool, its_technology, its_machine_functions, overcut_length,
//!   approach, retract, its_machining_strategy)`.
//! * `UV_STRATEGY(pathmode, cutmode, its_milling_tolerances, stepover, forward_direction,
//!   sideward_direction)`: pathmode `.FORWARD.` or `.ZIGZAG.`; the directions are
//!   `DIRECTION`s in the surface's parameter plane, `(1,0)` = along `u`, `(0,1)` = along
//!   `v` (a third ratio, if given, must be 0), the sign says which way; `stepover`, when
//!   set, caps the pass spacing (mm on the surface). `TOLERANCES(chordal_tolerance,
//!   scallop_height)` gives the scallop-height tolerance the planner keeps.
//! * `PLANE_CC_STRATEGY(pathmode, cutmode, its_milling_tolerances, stepover,
//!   its_plane_normal)` (ISO 14649-11: a `FREEFORM_STRATEGY` whose cutter-contact paths
//!   are the surface's intersections with parallel planes): the first four as for
//!   `UV_STRATEGY`; `its_plane_normal` is a `DIRECTION` in the feature's coordinates
//!   (like the surface's points; turned into machine coordinates by the same placements,
//!   a missing third ratio read as 0). The chordal tolerance bounds how far a contact
//!   point may leave its plane ([`crate::surface_plane`]); a zero normal is refused here,
//!   one the surface comes near parallel to by the planner.
//! * The tool: `CUTTING_TOOL(its_id, its_tool_body, its_cutting_edge,
//!   overall_assembly_length)` whose body is `BALL_ENDMILL(dimension, …)` with
//!   `MILLING_TOOL_DIMENSION(diameter, …)`; the overall assembly length is the tool
//!   length `H` of seed 000's compensation `M = P_a + R·n + (H − R)·z`.
//! * `MILLING_TECHNOLOGY(feedrate, feedrate_reference, cutspeed, spindle, …)`: feedrate
//!   in mm/s and spindle in revolutions/s (ISO 14649's SI-style measures with the mm as
//!   length unit); reported in mm/min and rpm.

pub mod check;
pub mod curves;
pub mod entities;
pub mod p21;
pub mod tspline;

use crate::surface_blocks::OwnedSurface;
use shared::nurbs::surface::{Passes, SurfaceData};

/// One problem of a STEP file: where, which instance, which rule.
#[derive(Debug, Clone, PartialEq)]
pub struct StepError {
    pub line: u32,
    /// The instance, when the problem belongs to one.
    pub id: Option<u64>,
    /// A short name of the rule broken (`syntax`, `reference`, `knot count`, `tool`, …).
    pub rule: &'static str,
    pub message: String,
}

impl StepError {
    /// `FILE:LINE: #ID: rule: message`.
    pub fn display(&self, file: &str) -> String {
        match self.id {
            Some(id) => format!(
                "{file}:{}: #{id}: {}: {}",
                self.line, self.rule, self.message
            ),
            None => format!("{file}:{}: {}: {}", self.line, self.rule, self.message),
        }
    }
}

/// Every error, one line each.
pub fn format_errors(file: &str, errs: &[StepError]) -> String {
    errs.iter().map(|e| e.display(file) + "\n").collect()
}

/// A rigid placement: `x_outer = origin + rot · x_inner` (columns of `rot` are the axes).
#[derive(Debug, Clone, PartialEq)]
pub struct Placement {
    pub origin: [f64; 3],
    /// `rot[r][c]`: row `r`, column `c`; column 0 = x axis, 1 = y, 2 = z.
    pub rot: [[f64; 3]; 3],
}

fn unit(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (l > 0.0 && l.is_finite()).then(|| [v[0] / l, v[1] / l, v[2] / l])
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

impl Placement {
    pub const IDENTITY: Placement = Placement {
        origin: [0.0; 3],
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };

    /// ISO 10303-42's axis2_placement_3d: z = axis, x = ref_direction made orthogonal.
    pub fn from_axes(origin: [f64; 3], axis: [f64; 3], ref_dir: [f64; 3]) -> Option<Placement> {
        let z = unit(axis)?;
        let d = ref_dir[0] * z[0] + ref_dir[1] * z[1] + ref_dir[2] * z[2];
        let x = unit([
            ref_dir[0] - d * z[0],
            ref_dir[1] - d * z[1],
            ref_dir[2] - d * z[2],
        ])?;
        let l = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
        if l < 1e-12 {
            return None;
        }
        let y = cross(z, x);
        let mut rot = [[0.0; 3]; 3];
        for r in 0..3 {
            rot[r] = [x[r], y[r], z[r]];
        }
        Some(Placement { origin, rot })
    }

    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        let mut out = self.origin;
        for (r, o) in out.iter_mut().enumerate() {
            *o += self.rot[r][0] * p[0] + self.rot[r][1] * p[1] + self.rot[r][2] * p[2];
        }
        out
    }

    /// `self ∘ inner`: first `inner`, then `self`.
    pub fn then(&self, inner: &Placement) -> Placement {
        let mut rot = [[0.0; 3]; 3];
        for (r, row) in rot.iter_mut().enumerate() {
            for (c, x) in row.iter_mut().enumerate() {
                *x = (0..3).map(|k| self.rot[r][k] * inner.rot[k][c]).sum();
            }
        }
        Placement {
            origin: self.apply(inner.origin),
            rot,
        }
    }
}

/// A NURBS surface as read, control points in machine coordinates (mm).
#[derive(Debug, Clone, PartialEq)]
pub struct StepSurface {
    pub id: u64,
    pub line: u32,
    /// Control points `[x, y, z, w]` (row-major `ctrl[i * n_v + j]`) in machine
    /// coordinates.
    pub geometry: OwnedSurface,
    pub rational: bool,
    /// Workpiece (file) coordinates to machine coordinates, as applied to `ctrl`.
    pub workpiece: Placement,
    /// Set when the surface is one T-region of a `T_SPLINE_SURFACE` (its Bézier patches
    /// joined, [`crate::tspline`]).
    pub t_spline: Option<TSplineRegion>,
}

/// Where a T-spline's region comes from, for `cnc check`.
#[derive(Debug, Clone, PartialEq)]
pub struct TSplineRegion {
    /// Control points of the whole T-spline.
    pub points: usize,
    pub t_junctions: usize,
    /// This region's place (1-based) among `regions`.
    pub region: usize,
    pub regions: usize,
    /// T-cells along `s` and `t` (each one Bézier patch).
    pub cells: (usize, usize),
}

impl StepSurface {
    pub fn data(&self) -> SurfaceData<'_> {
        self.geometry.data()
    }
}

/// A ball-nose end mill.
#[derive(Debug, Clone, PartialEq)]
pub struct BallEndmill {
    pub id: u64,
    pub name: String,
    pub diameter_mm: f64,
    /// Overall assembly length: `H` of the length compensation.
    pub length_mm: f64,
}

impl BallEndmill {
    pub fn radius_mm(&self) -> f64 {
        self.diameter_mm / 2.0
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Technology {
    pub feed_mm_per_min: f64,
    pub spindle_rpm: Option<f64>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PathMode {
    /// Every pass in the forward direction (a lift and return between passes).
    Forward,
    /// Passes alternate direction, joined along the domain boundary.
    Zigzag,
}

#[derive(Debug, Clone, PartialEq)]
pub struct UvStrategy {
    pub id: u64,
    pub mode: PathMode,
    /// Which parameter the passes run along.
    pub passes: Passes,
    /// +1: the first pass runs towards increasing parameter; -1: decreasing.
    pub forward_sign: f64,
    /// +1: passes follow one another towards increasing cross parameter.
    pub sideward_sign: f64,
    /// Upper bound of the pass spacing on the surface.
    pub stepover_mm: Option<f64>,
    pub scallop_mm: f64,
    pub chordal_mm: f64,
}

/// `PLANE_CC_STRATEGY`: the cutter-contact points of each pass lie in one of a family of
/// parallel planes (the passes are the surface's intersections with them).
#[derive(Debug, Clone, PartialEq)]
pub struct PlaneCcStrategy {
    pub id: u64,
    /// The `DIRECTION` instance of `its_plane_normal` and its line (for errors).
    pub normal_id: u64,
    pub normal_line: u32,
    pub mode: PathMode,
    /// Unit normal of the planes in machine coordinates (the placements applied).
    pub normal: [f64; 3],
    /// Upper bound of the pass spacing on the surface.
    pub stepover_mm: Option<f64>,
    pub scallop_mm: f64,
    pub chordal_mm: f64,
}

/// How a free-form surface is covered with passes.
#[derive(Debug, Clone, PartialEq)]
pub enum Strategy {
    Uv(UvStrategy),
    PlaneCc(PlaneCcStrategy),
}

impl Strategy {
    pub fn id(&self) -> u64 {
        match self {
            Strategy::Uv(s) => s.id,
            Strategy::PlaneCc(s) => s.id,
        }
    }
    pub fn mode(&self) -> PathMode {
        match self {
            Strategy::Uv(s) => s.mode,
            Strategy::PlaneCc(s) => s.mode,
        }
    }
    pub fn scallop_mm(&self) -> f64 {
        match self {
            Strategy::Uv(s) => s.scallop_mm,
            Strategy::PlaneCc(s) => s.scallop_mm,
        }
    }
    pub fn stepover_mm(&self) -> Option<f64> {
        match self {
            Strategy::Uv(s) => s.stepover_mm,
            Strategy::PlaneCc(s) => s.stepover_mm,
        }
    }
    pub fn chordal_mm(&self) -> f64 {
        match self {
            Strategy::Uv(s) => s.chordal_mm,
            Strategy::PlaneCc(s) => s.chordal_mm,
        }
    }
    /// The UV strategy, if it is one.
    pub fn uv(&self) -> Option<&UvStrategy> {
        match self {
            Strategy::Uv(s) => Some(s),
            Strategy::PlaneCc(_) => None,
        }
    }
}

/// A free-form finishing workingstep, ready for the planner.
#[derive(Debug, Clone, PartialEq)]
pub struct FreeformStep {
    pub id: u64,
    pub line: u32,
    pub name: String,
    pub surface: StepSurface,
    pub tool: BallEndmill,
    pub technology: Technology,
    pub strategy: Strategy,
}

/// Reads a STEP-NC file: its free-form workingsteps, or every error.
pub fn read_part(text: &str) -> Result<Vec<FreeformStep>, Vec<StepError>> {
    entities::read(&parse(text)?)
}

/// The exchange structure of `text`, its syntax errors as [`StepError`]s.
pub fn parse(text: &str) -> Result<p21::Exchange, Vec<StepError>> {
    p21::parse(text).map_err(|errs| {
        errs.into_iter()
            .map(|e| StepError {
                line: e.line,
                id: e.id,
                rule: "syntax",
                message: e.message,
            })
            .collect()
    })
}

pub use p21::looks_like_part21;

#[cfg(test)]
mod tests;
