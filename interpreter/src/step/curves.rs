//! The curves of a CAD STEP file (ISO 10303-42 geometry in any application protocol:
//! AP203, AP214, AP242), read for `cnc cam curves` (seed 002: CAD curves straight into
//! NURBS part programs).
//!
//! # Which curves
//! The *free-standing* ones: each curve entity that no other curve, edge or surface is
//! built on. A `TRIMMED_CURVE`'s basis is cut as the trimmed piece only; a curve under a
//! solid's `EDGE_CURVE`, a `PCURVE` or a surface is part of a B-rep and not cut (those
//! edges are counted, so the user hears they were left). The curves listed by the file's
//! `GEOMETRIC_CURVE_SET`s and `GEOMETRIC_SET`s come first, in their order; the rest
//! follow by instance number.
//!
//! # The entities, attribute by attribute (ISO 10303-42 order)
//! * `B_SPLINE_CURVE_WITH_KNOTS(name, degree, control_points_list, curve_form,
//!   closed_curve, self_intersect, knot_multiplicities, knots, knot_spec)`, or the
//!   complex instance with `B_SPLINE_CURVE(degree, control_points_list, curve_form,
//!   closed_curve, self_intersect)`, `B_SPLINE_CURVE_WITH_KNOTS(knot_multiplicities,
//!   knots, knot_spec)` and `RATIONAL_B_SPLINE_CURVE(weights_data)`. Degree 1 to
//!   [`shared::nurbs::MAX_DEGREE`]; the knots may be unclamped (the curve is then its
//!   domain `[u_p, u_n]`).
//! * `CIRCLE(name, position, radius)` and `ELLIPSE(name, position, semi_axis_1,
//!   semi_axis_2)`: `position` an `AXIS2_PLACEMENT_3D` or `_2D`; the point at `t` is
//!   `c + r·(cos t·x + sin t·y)` (ellipse: `a cos t·x + b sin t·y`), `t` in the file's
//!   plane angle unit.
//! * `LINE(name, pnt, dir)` with `dir` a `VECTOR(name, orientation, magnitude)`: the
//!   point at `u` is `pnt + u·magnitude·orientation`. Infinite, so only trimmed.
//! * `POLYLINE(name, points)`: straight moves through the points.
//! * `TRIMMED_CURVE(name, basis_curve, trim_1, trim_2, sense_agreement,
//!   master_representation)` of any of the above but a polyline: each trim a set of a
//!   `CARTESIAN_POINT` and/or a `PARAMETER_VALUE`; `master_representation` says which
//!   rules when both are given (`.CARTESIAN.`, else the parameter). With
//!   `sense_agreement` false the piece runs from `trim_1` to `trim_2` against the basis
//!   curve's direction; on a closed curve (circle, ellipse, a B-spline whose ends meet:
//!   its `closed_curve` flag is not trusted) it runs through the seam when it must. A
//!   trim giving both a parameter and a point must name one point.
//! * `COMPOSITE_CURVE(name, segments, self_intersect)` of
//!   `COMPOSITE_CURVE_SEGMENT(transition, same_sense, parent_curve)`: its segments in
//!   order, each reversed when `same_sense` is false (a trimmed one then runs from its
//!   `trim_2` to its `trim_1`).
//!
//! Curve sets an annotation draws (AP242 graphical PMI: `ANNOTATION_CURVE_OCCURRENCE`,
//! `DRAUGHTING_MODEL`, …) are not cut, and a file placing geometry by a transform
//! (`MAPPED_ITEM`, …) is refused, since the transform is not applied.
//!
//! # Units
//! Lengths are converted to mm and plane angles to radians from the file's
//! `LENGTH_UNIT` and `PLANE_ANGLE_UNIT` its contexts assign (`GLOBAL_UNIT_ASSIGNED_CONTEXT`;
//! an `SI_UNIT` with its prefix, or a
//! `CONVERSION_BASED_UNIT` such as the inch or the degree). Without them: mm and
//! radians. Units that disagree between two contexts of one file are refused.

use super::entities::{err, num, untyped, Ctx, KnotNames, R};
use super::p21::{Exchange, Instance, Param};
use super::{Placement, StepError};
use std::collections::{BTreeMap, BTreeSet};

/// A curve's geometry, lengths in mm.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// Control points `[x, y, z, w]`; `closed` as the file says (`closed_curve`).
    BSpline {
        degree: usize,
        knots: Vec<f64>,
        ctrl: Vec<[f64; 4]>,
        closed: bool,
    },
    /// `centre + a·cos t·x + b·sin t·y` (a circle has `a = b`); `place` gives the centre
    /// and the axes.
    Conic {
        place: Placement,
        a: f64,
        b: f64,
    },
    /// `origin + u·dir`.
    Line {
        origin: [f64; 3],
        dir: [f64; 3],
    },
    Polyline(Vec<[f64; 3]>),
}

/// One end of a trimmed curve: its parameter (radians for circles and ellipses) and/or
/// its point (mm).
#[derive(Debug, Clone, PartialEq)]
pub struct Bound {
    pub param: Option<f64>,
    pub point: Option<[f64; 3]>,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Trim {
    pub start: Bound,
    pub end: Bound,
    /// `master_representation` is `.CARTESIAN.`: the points rule where both are given.
    pub by_point: bool,
}

/// One curve to cut.
#[derive(Debug, Clone, PartialEq)]
pub struct CadCurve {
    /// The instance: a trimmed curve, or the curve itself.
    pub id: u64,
    pub line: u32,
    /// The entity, as a message calls it (`TRIMMED_CURVE of CIRCLE`).
    pub entity: String,
    pub shape: Shape,
    pub trim: Option<Trim>,
    /// Runs along its basis curve's direction (false: against it).
    pub forward: bool,
}

/// What [`read`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct CadCurves {
    pub curves: Vec<CadCurve>,
    /// `EDGE_CURVE`s of the file (a solid's edges, not cut).
    pub edges: usize,
}

/// Curve entities a free-standing curve may be.
const READ: &[&str] = &[
    "B_SPLINE_CURVE_WITH_KNOTS",
    "B_SPLINE_CURVE",
    "TRIMMED_CURVE",
    "CIRCLE",
    "ELLIPSE",
    "LINE",
    "POLYLINE",
    "COMPOSITE_CURVE",
];

/// Curve entities of ISO 10303-42 this reader does not take: found free-standing, they
/// are refused rather than left out.
const NOT_READ: &[&str] = &[
    "BEZIER_CURVE",
    "UNIFORM_CURVE",
    "QUASI_UNIFORM_CURVE",
    "PARABOLA",
    "HYPERBOLA",
    "OFFSET_CURVE_2D",
    "OFFSET_CURVE_3D",
    "CURVE_REPLICA",
    "CLOTHOID",
    "CIRCULAR_INVOLUTE",
    "SURFACE_CURVE",
    "INTERSECTION_CURVE",
    "SEAM_CURVE",
];

/// Instances that build on the curves they refer to: a curve one of them refers to is
/// part of something else, not a curve of its own.
const BUILT_ON: &[&str] = &[
    "TRIMMED_CURVE",
    "COMPOSITE_CURVE_SEGMENT",
    "COMPOSITE_CURVE",
    "EDGE_CURVE",
    "SURFACE_CURVE",
    "SEAM_CURVE",
    "INTERSECTION_CURVE",
    "PCURVE",
    "DEFINITIONAL_REPRESENTATION",
    "OFFSET_CURVE_2D",
    "OFFSET_CURVE_3D",
    "CURVE_REPLICA",
    "SURFACE_OF_LINEAR_EXTRUSION",
    "SURFACE_OF_REVOLUTION",
    "BOUNDARY_CURVE",
    "OUTER_BOUNDARY_CURVE",
    "COMPOSITE_CURVE_ON_SURFACE",
    "SWEPT_DISK_SOLID",
    "FIXED_REFERENCE_SWEPT_SURFACE",
    "SURFACE_CURVE_SWEPT_AREA_SOLID",
];

/// What a message calls a curve instance: its entity name, a complex B-spline by its
/// leaf (`B_SPLINE_CURVE_WITH_KNOTS, rational`).
fn curve_name(inst: &Instance) -> String {
    if !inst.complex {
        return inst.type_name();
    }
    let leaf = if has(inst, &["B_SPLINE_CURVE_WITH_KNOTS"]) {
        "B_SPLINE_CURVE_WITH_KNOTS"
    } else {
        "B_SPLINE_CURVE"
    };
    if has(inst, &["RATIONAL_B_SPLINE_CURVE"]) {
        format!("{leaf}, rational")
    } else {
        leaf.to_string()
    }
}

/// What draws a drawing's annotation (AP242 graphical PMI: dimension text, leaders) or
/// places geometry elsewhere: the curve sets under them are no part's outline.
const ANNOTATION: &[&str] = &[
    "ANNOTATION_CURVE_OCCURRENCE",
    "ANNOTATION_OCCURRENCE",
    "DRAUGHTING_ANNOTATION_OCCURRENCE",
    "ANNOTATION_PLACEHOLDER_OCCURRENCE",
    "ANNOTATION_FILL_AREA_OCCURRENCE",
    "DRAUGHTING_MODEL",
    "DRAUGHTING_CALLOUT",
];

/// Entities that place a representation's geometry by a transform, which this reader
/// does not apply.
const TRANSFORMS: &[&str] = &[
    "MAPPED_ITEM",
    "REPRESENTATION_RELATIONSHIP_WITH_TRANSFORMATION",
    "ITEM_DEFINED_TRANSFORMATION",
];

fn has(inst: &Instance, names: &[&str]) -> bool {
    inst.records
        .iter()
        .any(|r| names.contains(&r.name.as_str()))
}

fn refs(p: &Param, out: &mut Vec<u64>) {
    match p {
        Param::Ref(id) => out.push(*id),
        Param::List(l) => l.iter().for_each(|q| refs(q, out)),
        Param::Typed(_, inner) => refs(inner, out),
        _ => {}
    }
}

/// The scale of one kind of unit (`LENGTH_UNIT`: mm per unit; `PLANE_ANGLE_UNIT`: radians
/// per unit) the file's representation contexts assign (`GLOBAL_UNIT_ASSIGNED_CONTEXT`),
/// if they assign one.
fn unit_scale(cx: &Ctx, kind: &str, base: &str, base_scale: f64) -> R<Option<f64>> {
    let mut found: Option<(f64, &Instance)> = None;
    let assigned = cx
        .ex
        .instances
        .values()
        .filter_map(|c| Some((c, c.record("GLOBAL_UNIT_ASSIGNED_CONTEXT")?)));
    let mut units = Vec::new();
    for (c, rec) in assigned {
        for u in cx.list(c, rec, 0, "units")? {
            let inst = cx.deref(c, u, "units", &[])?;
            if inst.record(kind).is_some() {
                units.push(inst);
            }
        }
    }
    for inst in units {
        let s = scale_of(cx, inst, base, base_scale, 0)?;
        match found {
            Some((f, first)) if (f - s).abs() > 1e-12 * f.abs() => {
                return Err(err(
                    inst,
                    "unit",
                    format!(
                        "this {kind} differs from #{}'s ({s} against {f} {}): the file's curves must share one unit",
                        first.id,
                        if base == "METRE" { "mm" } else { "rad" }
                    ),
                ));
            }
            Some(_) => {}
            None => found = Some((s, inst)),
        }
    }
    Ok(found.map(|(s, _)| s))
}

/// An `SI_UNIT` with its prefix, or a `CONVERSION_BASED_UNIT` through its measure.
fn scale_of(cx: &Ctx, inst: &Instance, base: &str, base_scale: f64, depth: usize) -> R<f64> {
    if let Some(si) = inst.record("SI_UNIT") {
        let prefix = match si.params.first().map(untyped) {
            Some(Param::Enum(p)) => p.as_str(),
            _ => "",
        };
        let factor = match prefix {
            "" => 1.0,
            "KILO" => 1e3,
            "HECTO" => 1e2,
            "DECA" => 1e1,
            "DECI" => 1e-1,
            "CENTI" => 1e-2,
            "MILLI" => 1e-3,
            "MICRO" => 1e-6,
            "NANO" => 1e-9,
            other => {
                return Err(err(
                    inst,
                    "unit",
                    format!("SI prefix .{other}. is not read"),
                ));
            }
        };
        match si.params.get(1).map(untyped) {
            Some(Param::Enum(n)) if n == base => return Ok(factor * base_scale),
            Some(Param::Enum(n)) if n == "STERADIAN" => {}
            _ => {
                return Err(err(
                    inst,
                    "unit",
                    format!("the SI unit must be .{base}. here"),
                ))
            }
        }
    }
    if let (Some(conv), true) = (inst.record("CONVERSION_BASED_UNIT"), depth < 4) {
        let m = cx.attr(inst, conv, 1, "conversion_factor")?;
        let measure = cx.deref(inst, m, "conversion_factor", &[])?;
        let rec = &measure.records[0];
        let value = cx.real(measure, rec, 0, "value_component")?;
        let unit = cx.deref(
            measure,
            cx.attr(measure, rec, 1, "unit_component")?,
            "unit_component",
            &[],
        )?;
        let s = value * scale_of(cx, unit, base, base_scale, depth + 1)?;
        if !(s > 0.0 && s.is_finite()) {
            return Err(err(
                measure,
                "unit",
                "a unit's conversion factor must be a positive number",
            ));
        }
        return Ok(s);
    }
    Err(err(
        inst,
        "unit",
        "a unit must be an SI_UNIT or a CONVERSION_BASED_UNIT",
    ))
}

struct Reader<'a> {
    cx: Ctx<'a>,
    mm: f64,
    rad: f64,
}

impl<'a> Reader<'a> {
    fn point(&self, from: &Instance, p: &Param, what: &str) -> R<[f64; 3]> {
        let inst = self.cx.deref(from, p, what, &["CARTESIAN_POINT"])?;
        let q = self.cx.point(inst)?.map(|x| x * self.mm);
        let reach = crate::program::MAX_REACH_MM;
        if q.iter().any(|x| x.is_nan() || x.abs() > reach) {
            return Err(err(
                inst,
                "point",
                format!("a coordinate is beyond {reach} mm"),
            ));
        }
        Ok(q)
    }

    fn direction3(&self, from: &Instance, p: &Param, what: &str) -> R<[f64; 3]> {
        let d = self
            .cx
            .direction(self.cx.deref(from, p, what, &["DIRECTION"])?)?;
        let mut out = [0.0; 3];
        out.iter_mut().zip(&d).for_each(|(o, x)| *o = *x);
        Ok(out)
    }

    /// An `AXIS2_PLACEMENT_3D` or `_2D`, its origin in mm.
    fn placement(&self, from: &Instance, p: &Param, what: &str) -> R<Placement> {
        let inst = self
            .cx
            .deref(from, p, what, &["AXIS2_PLACEMENT_3D", "AXIS2_PLACEMENT_2D"])?;
        let mut pl = if inst.record("AXIS2_PLACEMENT_2D").is_some() {
            let rec = &inst.records[0];
            let loc = self.cx.point(self.cx.deref(
                inst,
                self.cx.attr(inst, rec, 1, "location")?,
                "location",
                &["CARTESIAN_POINT"],
            )?)?;
            let x = match rec.params.get(2).map(untyped) {
                None | Some(Param::Unset) => [1.0, 0.0, 0.0],
                Some(q) => self.direction3(inst, q, "ref_direction")?,
            };
            Placement::from_axes(loc, [0.0, 0.0, 1.0], x)
                .ok_or_else(|| err(inst, "placement", "ref_direction is zero"))?
        } else {
            self.cx.placement(from, p, what)?
        };
        pl.origin = pl.origin.map(|x| x * self.mm);
        Ok(pl)
    }

    fn positive(&self, inst: &Instance, i: usize, what: &str) -> R<f64> {
        let rec = &inst.records[0];
        let v = self.cx.real(inst, rec, i, what)? * self.mm;
        if v > 0.0 {
            Ok(v)
        } else {
            Err(err(inst, "curve", format!("{what} must be positive")))
        }
    }

    /// The geometry of a basic curve (not trimmed, not composite).
    fn shape(&self, inst: &Instance) -> R<Shape> {
        if has(inst, &["B_SPLINE_CURVE_WITH_KNOTS", "B_SPLINE_CURVE"]) {
            return self.bspline(inst);
        }
        let rec = &inst.records[0];
        match rec.name.as_str() {
            "CIRCLE" | "ELLIPSE" => {
                let place =
                    self.placement(inst, self.cx.attr(inst, rec, 1, "position")?, "position")?;
                let (a, b) = if rec.name == "CIRCLE" {
                    let r = self.positive(inst, 2, "radius")?;
                    (r, r)
                } else {
                    (
                        self.positive(inst, 2, "semi_axis_1")?,
                        self.positive(inst, 3, "semi_axis_2")?,
                    )
                };
                Ok(Shape::Conic { place, a, b })
            }
            "LINE" => {
                let origin = self.point(inst, self.cx.attr(inst, rec, 1, "pnt")?, "pnt")?;
                let v =
                    self.cx
                        .deref(inst, self.cx.attr(inst, rec, 2, "dir")?, "dir", &["VECTOR"])?;
                let vr = &v.records[0];
                let o =
                    self.direction3(v, self.cx.attr(v, vr, 1, "orientation")?, "orientation")?;
                let m = self.cx.real(v, vr, 2, "magnitude")? * self.mm;
                let l = (o[0] * o[0] + o[1] * o[1] + o[2] * o[2]).sqrt();
                if m <= 0.0 {
                    return Err(err(
                        v,
                        "curve",
                        "a line's vector must have a positive magnitude",
                    ));
                }
                Ok(Shape::Line {
                    origin,
                    dir: o.map(|x| x / l * m),
                })
            }
            "POLYLINE" => {
                let pts = self.cx.list(inst, rec, 1, "points")?;
                if pts.len() < 2 {
                    return Err(err(inst, "curve", "a polyline needs at least two points"));
                }
                let pts = pts
                    .iter()
                    .map(|p| self.point(inst, p, "points"))
                    .collect::<R<Vec<_>>>()?;
                Ok(Shape::Polyline(pts))
            }
            other => Err(err(
                inst,
                "curve",
                format!(
                    "{other} is not a curve cnc cam curves reads ({})",
                    READ.join(", ")
                ),
            )),
        }
    }

    fn bspline(&self, inst: &Instance) -> R<Shape> {
        let cx = &self.cx;
        let (bs, bs0, kn, kn0) = if inst.complex {
            let need = |name: &str| {
                inst.record(name).ok_or_else(|| {
                    err(
                        inst,
                        "curve",
                        format!("complex curve lacks its {name} part"),
                    )
                })
            };
            (
                need("B_SPLINE_CURVE")?,
                0,
                need("B_SPLINE_CURVE_WITH_KNOTS")?,
                0,
            )
        } else {
            let r = &inst.records[0];
            if r.name != "B_SPLINE_CURVE_WITH_KNOTS" {
                return Err(err(
                    inst,
                    "curve",
                    format!(
                        "{} is not read; give the curve as a B_SPLINE_CURVE_WITH_KNOTS",
                        r.name
                    ),
                ));
            }
            (r, 1, r, 6)
        };
        let degree = cx.int(inst, bs, bs0, "degree")?;
        let max = shared::nurbs::MAX_DEGREE as i64;
        if !(1..=max).contains(&degree) {
            return Err(err(
                inst,
                "degree",
                format!("degree {degree} is outside 1..={max} (G6.2's orders 2 to 10)"),
            ));
        }
        let degree = degree as usize;
        let pts = cx.list(inst, bs, bs0 + 1, "control_points_list")?;
        if pts.len() <= degree {
            return Err(err(
                inst,
                "control points",
                format!(
                    "{} control points for degree {degree}; at least {}",
                    pts.len(),
                    degree + 1
                ),
            ));
        }
        let closed =
            matches!(cx.attr(inst, bs, bs0 + 3, "closed_curve")?, Param::Enum(e) if e == "T");
        let names = KnotNames {
            multiplicities: "knot_multiplicities",
            knots: "knots",
            label: "",
            shape: "curve",
        };
        let knots = cx.knot_vector(inst, kn, (kn0, kn0 + 1), &names, pts.len(), degree)?;
        if knots[degree] >= knots[pts.len()] {
            return Err(err(
                inst,
                "knots",
                format!(
                    "the curve's domain, from knot {} to knot {}, is empty",
                    knots[degree],
                    knots[pts.len()]
                ),
            ));
        }
        let mut weights = vec![1.0; pts.len()];
        if let Some(rat) = inst.record("RATIONAL_B_SPLINE_CURVE") {
            let w = cx.list(inst, rat, 0, "weights_data")?;
            if w.len() != pts.len() {
                return Err(err(
                    inst,
                    "weights",
                    format!("{} weights for {} control points", w.len(), pts.len()),
                ));
            }
            for (o, x) in weights.iter_mut().zip(w) {
                *o = num(x)
                    .filter(|w| *w > 0.0)
                    .ok_or_else(|| err(inst, "weights", "weights must be positive numbers"))?;
            }
        }
        let ctrl = pts
            .iter()
            .zip(&weights)
            .map(|(p, w)| {
                let q = self.point(inst, p, "control point")?;
                Ok([q[0], q[1], q[2], *w])
            })
            .collect::<R<Vec<_>>>()?;
        Ok(Shape::BSpline {
            degree,
            knots,
            ctrl,
            closed,
        })
    }

    fn bound(&self, inst: &Instance, p: &Param, what: &str, angle: bool) -> R<Bound> {
        let Param::List(items) = untyped(p) else {
            return Err(err(inst, "type", format!("{what} must be a set `( … )`")));
        };
        let mut b = Bound {
            param: None,
            point: None,
        };
        for item in items {
            match item {
                Param::Typed(name, v) if name == "PARAMETER_VALUE" => {
                    let v = num(v).ok_or_else(|| {
                        err(
                            inst,
                            "trim",
                            format!("{what}: PARAMETER_VALUE must be a finite number"),
                        )
                    })?;
                    b.param = Some(if angle { v * self.rad } else { v });
                }
                Param::Ref(_) => b.point = Some(self.point(inst, item, what)?),
                _ => {
                    return Err(err(
                        inst,
                        "trim",
                        format!("{what} holds a CARTESIAN_POINT and/or a PARAMETER_VALUE(…)"),
                    ))
                }
            }
        }
        if b.param.is_none() && b.point.is_none() {
            return Err(err(inst, "trim", format!("{what} is empty")));
        }
        Ok(b)
    }

    /// The curves `inst` is: one, or a composite's segments.
    fn curve(&self, inst: &Instance, depth: usize) -> R<Vec<CadCurve>> {
        if depth > 8 {
            return Err(err(inst, "curve", "curves nested deeper than 8"));
        }
        let rec = &inst.records[0];
        let name = curve_name(inst);
        match rec.name.as_str() {
            "TRIMMED_CURVE" if !inst.complex => {
                let basis = self.cx.deref(
                    inst,
                    self.cx.attr(inst, rec, 1, "basis_curve")?,
                    "basis_curve",
                    &[],
                )?;
                if has(basis, &["TRIMMED_CURVE", "COMPOSITE_CURVE", "POLYLINE"]) {
                    return Err(err(
                        inst,
                        "trim",
                        format!(
                            "a trimmed {} is not read; trim a B-spline, circle, ellipse or line",
                            basis.type_name()
                        ),
                    ));
                }
                let shape = self.shape(basis)?;
                let angle = matches!(shape, Shape::Conic { .. });
                let start =
                    self.bound(inst, self.cx.attr(inst, rec, 2, "trim_1")?, "trim_1", angle)?;
                let end =
                    self.bound(inst, self.cx.attr(inst, rec, 3, "trim_2")?, "trim_2", angle)?;
                let forward = match self.cx.attr(inst, rec, 4, "sense_agreement")? {
                    Param::Enum(e) if e == "T" => true,
                    Param::Enum(e) if e == "F" => false,
                    _ => return Err(err(inst, "type", "sense_agreement must be .T. or .F.")),
                };
                let by_point = matches!(rec.params.get(5).map(untyped), Some(Param::Enum(e)) if e == "CARTESIAN");
                Ok(vec![CadCurve {
                    id: inst.id,
                    line: inst.line,
                    entity: format!("TRIMMED_CURVE of {} #{}", curve_name(basis), basis.id),
                    shape,
                    trim: Some(Trim {
                        start,
                        end,
                        by_point,
                    }),
                    forward,
                }])
            }
            "COMPOSITE_CURVE" if !inst.complex => {
                let segs = self.cx.list(inst, rec, 1, "segments")?;
                let mut out = Vec::new();
                for s in segs {
                    let seg = self
                        .cx
                        .deref(inst, s, "segments", &["COMPOSITE_CURVE_SEGMENT"])?;
                    let sr = &seg.records[0];
                    let same = match self.cx.attr(seg, sr, 1, "same_sense")? {
                        Param::Enum(e) if e == "T" => true,
                        Param::Enum(e) if e == "F" => false,
                        _ => return Err(err(seg, "type", "same_sense must be .T. or .F.")),
                    };
                    let parent = self.cx.deref(
                        seg,
                        self.cx.attr(seg, sr, 2, "parent_curve")?,
                        "parent_curve",
                        &[],
                    )?;
                    let mut part = self.curve(parent, depth + 1)?;
                    if !same {
                        part.reverse();
                        for c in &mut part {
                            // Against the segment: from its end to its start.
                            c.forward = !c.forward;
                            if let Some(t) = &mut c.trim {
                                std::mem::swap(&mut t.start, &mut t.end);
                            }
                        }
                    }
                    let n = segs.len();
                    for c in &mut part {
                        c.entity = format!(
                            "{}, segment {} of {n} of COMPOSITE_CURVE #{}",
                            c.entity,
                            out.len() + 1,
                            inst.id
                        );
                    }
                    out.extend(part);
                }
                if out.is_empty() {
                    return Err(err(inst, "curve", "a composite curve without segments"));
                }
                Ok(out)
            }
            _ => {
                let shape = self.shape(inst)?;
                if matches!(shape, Shape::Line { .. }) {
                    return Err(err(
                        inst,
                        "curve",
                        "a LINE is infinite: cut it as a TRIMMED_CURVE of the line",
                    ));
                }
                Ok(vec![CadCurve {
                    id: inst.id,
                    line: inst.line,
                    entity: name,
                    shape,
                    trim: None,
                    forward: true,
                }])
            }
        }
    }
}

/// The free-standing curves of `ex`, in cutting order (module page), or every error.
pub fn read(ex: &Exchange) -> Result<CadCurves, Vec<StepError>> {
    let cx = Ctx {
        ex,
        errs: Vec::new(),
    };
    let mut errs = Vec::new();
    let mm = unit_scale(&cx, "LENGTH_UNIT", "METRE", 1000.0)
        .map_err(|e| vec![e.clone()])?
        .unwrap_or(1.0);
    let rad = unit_scale(&cx, "PLANE_ANGLE_UNIT", "RADIAN", 1.0)
        .map_err(|e| vec![e.clone()])?
        .unwrap_or(1.0);
    let reader = Reader { cx, mm, rad };
    // Who refers to whom.
    let mut users: BTreeMap<u64, Vec<u64>> = BTreeMap::new();
    for inst in ex.instances.values() {
        let mut out = Vec::new();
        for r in &inst.records {
            r.params.iter().for_each(|p| refs(p, &mut out));
        }
        for id in out {
            users.entry(id).or_default().push(inst.id);
        }
    }
    let is_curve = |i: &Instance| has(i, READ) || has(i, NOT_READ);
    let used_by = |i: &Instance, names: &[&str]| {
        users.get(&i.id).is_some_and(|us| {
            us.iter()
                .any(|u| ex.instances.get(u).is_some_and(|u| has(u, names)))
        })
    };
    let sets = ["GEOMETRIC_CURVE_SET", "GEOMETRIC_SET"];
    // A set an annotation draws.
    let annotation = |set: &Instance| has(set, &sets) && used_by(set, ANNOTATION);
    let free = |i: &Instance| {
        is_curve(i)
            && !has(i, &["COMPOSITE_CURVE_SEGMENT"])
            && !used_by(i, BUILT_ON)
            && !used_by(i, ANNOTATION)
            && !users.get(&i.id).is_some_and(|us| {
                us.iter()
                    .any(|u| ex.instances.get(u).is_some_and(annotation))
            })
    };
    if let Some(t) = ex.instances.values().find(|i| has(i, TRANSFORMS)) {
        return Err(vec![err(
            t,
            "transform",
            format!(
                "{} places geometry by a transform, which cnc cam curves does not apply: export the part's curves on their own, in place",
                t.type_name()
            ),
        )]);
    }
    let mut order: Vec<&Instance> = Vec::new();
    let mut seen = BTreeSet::new();
    for set in ex.instances.values() {
        if !has(set, &sets) || set.complex || annotation(set) {
            continue;
        }
        let mut items = Vec::new();
        if let Some(p) = set.records[0].params.get(1) {
            refs(p, &mut items);
        }
        for id in items {
            if let Some(i) = ex.instances.get(&id) {
                if free(i) && seen.insert(id) {
                    order.push(i);
                }
            }
        }
    }
    for i in ex.instances.values() {
        if free(i) && seen.insert(i.id) {
            order.push(i);
        }
    }
    let mut curves = Vec::new();
    for inst in order {
        if has(inst, NOT_READ) && !has(inst, READ) {
            errs.push(err(
                inst,
                "curve",
                format!(
                    "{} is not a curve cnc cam curves reads ({})",
                    inst.type_name(),
                    READ.join(", ")
                ),
            ));
            continue;
        }
        match reader.curve(inst, 0) {
            Ok(c) => curves.extend(c),
            Err(e) => errs.push(e),
        }
    }
    let edges = ex
        .instances
        .values()
        .filter(|i| has(i, &["EDGE_CURVE"]))
        .count();
    if errs.is_empty() && curves.is_empty() {
        errs.push(StepError {
            line: ex.instances.values().next().map_or(1, |i| i.line),
            id: None,
            rule: "curves",
            message: if edges > 0 {
                format!("no free-standing curves to cut; the file's {edges} EDGE_CURVEs are a solid's edges: export the curves themselves (a wireframe or GEOMETRIC_CURVE_SET)")
            } else {
                "the file has no curves to cut".into()
            },
        });
    }
    if errs.is_empty() {
        Ok(CadCurves { curves, edges })
    } else {
        errs.sort_by_key(|e| (e.line, e.id));
        errs.dedup();
        Err(errs)
    }
}

/// Reads a STEP file's curves (parse and [`read`]).
pub fn read_curves(text: &str) -> Result<CadCurves, Vec<StepError>> {
    read(&super::parse(text)?)
}
