//! The ISO 14649-10/11 subset a free-form finishing job needs, read from the instances of
//! [`super::p21`]. Attribute positions follow the standards' inheritance order; the
//! module docs of [`super`] list each entity as read.

use super::p21::{Exchange, Instance, Param, Record};
use super::{
    BallEndmill, FreeformStep, PathMode, Placement, PlaneCcStrategy, StepError, StepSurface,
    Strategy, Technology, UvStrategy,
};
use crate::surface_blocks::OwnedSurface;
use shared::nurbs::surface::Passes;

/// Surfaces larger than this in either direction are refused by the reader (the planner
/// and the block splitter allocate per control point).
pub const MAX_READ_CTRL: usize = 1024;

pub(super) struct Ctx<'a> {
    pub(super) ex: &'a Exchange,
    pub(super) errs: Vec<StepError>,
}

pub(super) type R<T> = Result<T, StepError>;

/// What the knot attributes of a B-spline are called in its messages.
pub(super) struct KnotNames<'n> {
    pub multiplicities: &'n str,
    pub knots: &'n str,
    /// Put before `knot`: `"u "` for a surface's u knots, empty for a curve's.
    pub label: &'n str,
    /// `surface` or `curve`.
    pub shape: &'n str,
}

pub(super) fn err(inst: &Instance, rule: &'static str, message: impl Into<String>) -> StepError {
    StepError {
        line: inst.line,
        id: Some(inst.id),
        rule,
        message: message.into(),
    }
}

/// Strips `NAME(…)` typing from a parameter.
pub(super) fn untyped(p: &Param) -> &Param {
    match p {
        Param::Typed(_, inner) => untyped(inner),
        other => other,
    }
}

pub(super) fn num(p: &Param) -> Option<f64> {
    match untyped(p) {
        Param::Real(x) if x.is_finite() => Some(*x),
        Param::Int(n) => Some(*n as f64),
        _ => None,
    }
}

impl<'a> Ctx<'a> {
    pub(super) fn attr<'r>(
        &self,
        inst: &Instance,
        rec: &'r Record,
        i: usize,
        what: &str,
    ) -> R<&'r Param> {
        rec.params.get(i).map(untyped).ok_or_else(|| {
            err(
                inst,
                "attributes",
                format!(
                    "{} has {} attributes, {what} is attribute {} (ISO 14649 order)",
                    rec.name,
                    rec.params.len(),
                    i + 1
                ),
            )
        })
    }

    pub(super) fn real(&self, inst: &Instance, rec: &Record, i: usize, what: &str) -> R<f64> {
        let p = self.attr(inst, rec, i, what)?;
        num(p).ok_or_else(|| err(inst, "type", format!("{what} must be a finite number")))
    }

    pub(super) fn opt_real(
        &self,
        inst: &Instance,
        rec: &Record,
        i: usize,
        what: &str,
    ) -> R<Option<f64>> {
        match rec.params.get(i).map(untyped) {
            None | Some(Param::Unset) => Ok(None),
            Some(_) => self.real(inst, rec, i, what).map(Some),
        }
    }

    pub(super) fn int(&self, inst: &Instance, rec: &Record, i: usize, what: &str) -> R<i64> {
        match self.attr(inst, rec, i, what)? {
            Param::Int(n) => Ok(*n),
            _ => Err(err(inst, "type", format!("{what} must be an integer"))),
        }
    }

    pub(super) fn enumv(&self, inst: &Instance, rec: &Record, i: usize, what: &str) -> R<String> {
        match self.attr(inst, rec, i, what)? {
            Param::Enum(e) => Ok(e.clone()),
            _ => Err(err(
                inst,
                "type",
                format!("{what} must be an enumeration `.X.`"),
            )),
        }
    }

    pub(super) fn text(&self, rec: &Record, i: usize) -> String {
        match rec.params.get(i).map(untyped) {
            Some(Param::Str(s)) => s.clone(),
            _ => String::new(),
        }
    }

    pub(super) fn list<'r>(
        &self,
        inst: &Instance,
        rec: &'r Record,
        i: usize,
        what: &str,
    ) -> R<&'r [Param]> {
        match self.attr(inst, rec, i, what)? {
            Param::List(l) => Ok(l),
            _ => Err(err(inst, "type", format!("{what} must be a list `( … )`"))),
        }
    }

    /// The instance `p` refers to, which must have one of the entity names `want`
    /// (simple) or contain a partial entity of that name (complex).
    pub(super) fn deref(
        &self,
        from: &Instance,
        p: &Param,
        what: &str,
        want: &[&str],
    ) -> R<&'a Instance> {
        let id = match untyped(p) {
            Param::Ref(id) => *id,
            Param::Unset => {
                return Err(err(from, "missing", format!("{what} is unset (`$`)")));
            }
            _ => {
                return Err(err(
                    from,
                    "type",
                    format!("{what} must be a reference `#n`"),
                ))
            }
        };
        let inst = self.ex.instances.get(&id).ok_or_else(|| {
            err(
                from,
                "reference",
                format!("{what} refers to #{id}, which the file does not define"),
            )
        })?;
        if want.is_empty() || inst.records.iter().any(|r| want.contains(&r.name.as_str())) {
            Ok(inst)
        } else {
            Err(err(
                from,
                "reference",
                format!(
                    "{what} refers to #{id}, a {}, where {} is expected",
                    inst.type_name(),
                    want.join(" or ")
                ),
            ))
        }
    }

    pub(super) fn first_record<'r>(&self, inst: &'r Instance, names: &[&str]) -> &'r Record {
        inst.records
            .iter()
            .find(|r| names.contains(&r.name.as_str()))
            .unwrap_or(&inst.records[0])
    }

    pub(super) fn point(&self, inst: &Instance) -> R<[f64; 3]> {
        let rec = self.first_record(inst, &["CARTESIAN_POINT"]);
        let l = self.list(inst, rec, 1, "coordinates")?;
        if !(1..=3).contains(&l.len()) {
            return Err(err(inst, "point", "a point has 1 to 3 coordinates"));
        }
        let mut out = [0.0; 3];
        for (o, c) in out.iter_mut().zip(l) {
            *o = num(c).ok_or_else(|| err(inst, "type", "coordinates must be finite numbers"))?;
        }
        Ok(out)
    }

    pub(super) fn direction(&self, inst: &Instance) -> R<Vec<f64>> {
        let rec = self.first_record(inst, &["DIRECTION"]);
        let l = self.list(inst, rec, 1, "direction ratios")?;
        let v: Option<Vec<f64>> = l.iter().map(num).collect();
        let v = v.ok_or_else(|| err(inst, "type", "direction ratios must be finite numbers"))?;
        if v.is_empty() || v.len() > 3 || v.iter().all(|x| *x == 0.0) {
            return Err(err(
                inst,
                "direction",
                "a direction has 1 to 3 ratios, not all zero",
            ));
        }
        Ok(v)
    }

    /// The knots of a B-spline, expanded from its multiplicities and values (attributes
    /// `at.0` and `at.1` of `kn`), checked: increasing, multiplicities within the degree
    /// inside and the order at the ends, as many as `n` control points of degree `deg`
    /// take.
    pub(super) fn knot_vector(
        &self,
        inst: &Instance,
        kn: &Record,
        at: (usize, usize),
        names: &KnotNames,
        n: usize,
        deg: usize,
    ) -> R<Vec<f64>> {
        let mult = self.list(inst, kn, at.0, names.multiplicities)?;
        let vals = self.list(inst, kn, at.1, names.knots)?;
        if mult.len() != vals.len() {
            return Err(err(
                inst,
                "knots",
                format!(
                    "{} {} for {} {}",
                    mult.len(),
                    names.multiplicities,
                    vals.len(),
                    names.knots
                ),
            ));
        }
        let mut out = Vec::new();
        let last = mult.len().saturating_sub(1);
        for (i, (m, k)) in mult.iter().zip(vals).enumerate() {
            let m = match untyped(m) {
                Param::Int(m) if (1..=64).contains(m) => *m as usize,
                _ => {
                    return Err(err(
                        inst,
                        "knots",
                        format!("{} must be integers in 1..=64", names.multiplicities),
                    ))
                }
            };
            let k = num(k).ok_or_else(|| {
                err(
                    inst,
                    "knots",
                    format!("{} must be finite numbers", names.knots),
                )
            })?;
            // A knot as often as the order inside cuts the shape in two along it
            // (the tool would jump); more at an edge leaves control points out.
            let inside = i > 0 && i < last;
            if (inside && m > deg) || m > deg + 1 {
                return Err(err(
                    inst,
                    "knots",
                    format!(
                        "{}knot {k} has multiplicity {m}; at most {deg} (the degree) \
                         inside the {}, where {} would cut it in two, and {} at its \
                         edges",
                        names.label,
                        names.shape,
                        deg + 1,
                        deg + 1
                    ),
                ));
            }
            if out.last().is_some_and(|&before| k <= before) {
                return Err(err(
                    inst,
                    "knots",
                    format!(
                        "{} must increase, and {k} follows {}",
                        names.knots,
                        out[out.len() - 1]
                    ),
                ));
            }
            out.extend(std::iter::repeat_n(k, m));
        }
        if out.len() != n + deg + 1 {
            return Err(err(
                inst,
                "knot count",
                format!(
                    "{} {}knots (sum of multiplicities) for {n} control points of degree \
                     {deg}, expected {}",
                    out.len(),
                    names.label,
                    n + deg + 1
                ),
            ));
        }
        Ok(out)
    }

    pub(super) fn placement(&self, from: &Instance, p: &Param, what: &str) -> R<Placement> {
        let inst = self.deref(from, p, what, &["AXIS2_PLACEMENT_3D"])?;
        let rec = self.first_record(inst, &["AXIS2_PLACEMENT_3D"]);
        let loc_p = self.attr(inst, rec, 1, "location")?;
        let loc = self.point(self.deref(inst, loc_p, "location", &["CARTESIAN_POINT"])?)?;
        let dir3 = |i: usize, what: &str, default: [f64; 3]| -> R<[f64; 3]> {
            match rec.params.get(i).map(untyped) {
                None | Some(Param::Unset) => Ok(default),
                Some(p) => {
                    let d = self.direction(self.deref(inst, p, what, &["DIRECTION"])?)?;
                    let mut out = [0.0; 3];
                    for (o, x) in out.iter_mut().zip(&d) {
                        *o = *x;
                    }
                    Ok(out)
                }
            }
        };
        let z = dir3(2, "axis", [0.0, 0.0, 1.0])?;
        // ISO 10303-42's default reference direction: x, or y where the axis is x.
        let along_x = z[1] == 0.0 && z[2] == 0.0;
        let x = dir3(
            3,
            "ref_direction",
            if along_x {
                [0.0, 1.0, 0.0]
            } else {
                [1.0, 0.0, 0.0]
            },
        )?;
        Placement::from_axes(loc, z, x)
            .ok_or_else(|| err(inst, "placement", "axis and ref_direction are parallel"))
    }

    fn surface(&self, inst: &Instance, to_machine: &Placement) -> R<StepSurface> {
        // Simple form: all attributes in B_SPLINE_SURFACE_WITH_KNOTS (name first);
        // complex form: B_SPLINE_SURFACE, B_SPLINE_SURFACE_WITH_KNOTS and
        // RATIONAL_B_SPLINE_SURFACE each with their own attributes.
        let (bs, bs0, kn, kn0) = if inst.complex {
            let bs = inst.record("B_SPLINE_SURFACE").ok_or_else(|| {
                err(
                    inst,
                    "surface",
                    "complex surface lacks its B_SPLINE_SURFACE part",
                )
            })?;
            let kn = inst.record("B_SPLINE_SURFACE_WITH_KNOTS").ok_or_else(|| {
                err(
                    inst,
                    "surface",
                    "complex surface lacks its B_SPLINE_SURFACE_WITH_KNOTS part",
                )
            })?;
            (bs, 0, kn, 0)
        } else {
            let r = &inst.records[0];
            if r.name != "B_SPLINE_SURFACE_WITH_KNOTS" {
                return Err(err(
                    inst,
                    "surface",
                    format!(
                        "{} is not supported; the surface must be a B_SPLINE_SURFACE_WITH_KNOTS",
                        r.name
                    ),
                ));
            }
            (r, 1, r, 8)
        };
        let deg = |i: usize, what: &str| -> R<usize> {
            let d = self.int(inst, bs, bs0 + i, what)?;
            if (1..=shared::nurbs::surface::MAX_SURF_DEGREE as i64).contains(&d) {
                Ok(d as usize)
            } else {
                Err(err(
                    inst,
                    "degree",
                    format!(
                        "{what} {d} is outside 1..={}",
                        shared::nurbs::surface::MAX_SURF_DEGREE
                    ),
                ))
            }
        };
        let p = deg(0, "u_degree")?;
        let q = deg(1, "v_degree")?;
        let rows = self.list(inst, bs, bs0 + 2, "control_points_list")?;
        let n_u = rows.len();
        let mut n_v = 0;
        let mut pts = Vec::new();
        for (i, row) in rows.iter().enumerate() {
            let Param::List(row) = untyped(row) else {
                return Err(err(
                    inst,
                    "type",
                    "control_points_list must be a list of lists",
                ));
            };
            if i == 0 {
                n_v = row.len();
            } else if row.len() != n_v {
                return Err(err(
                    inst,
                    "control points",
                    format!(
                        "row {} has {} control points, row 1 has {n_v}",
                        i + 1,
                        row.len()
                    ),
                ));
            }
            for c in row {
                let cp = self.deref(inst, c, "control point", &["CARTESIAN_POINT"])?;
                pts.push(self.point(cp)?);
            }
        }
        if n_u > MAX_READ_CTRL || n_v > MAX_READ_CTRL {
            return Err(err(
                inst,
                "control points",
                format!("{n_u} x {n_v} control points exceed {MAX_READ_CTRL} per direction"),
            ));
        }
        let knots = |mi: usize, ki: usize, dir: &str, n: usize, deg: usize| -> R<Vec<f64>> {
            let names = KnotNames {
                multiplicities: &format!("{dir}_multiplicities"),
                knots: &format!("{dir}_knots"),
                label: &format!("{dir} "),
                shape: "surface",
            };
            self.knot_vector(inst, kn, (kn0 + mi, kn0 + ki), &names, n, deg)
        };
        let knots_u = knots(0, 2, "u", n_u, p)?;
        let knots_v = knots(1, 3, "v", n_v, q)?;
        let mut weights = vec![1.0; pts.len()];
        let rational = inst.record("RATIONAL_B_SPLINE_SURFACE");
        if let Some(rat) = rational {
            let w = self.list(inst, rat, 0, "weights_data")?;
            let mut k = 0;
            let shape_ok = w.len() == n_u
                && w.iter()
                    .all(|r| matches!(untyped(r), Param::List(l) if l.len() == n_v));
            if !shape_ok {
                return Err(err(
                    inst,
                    "weights",
                    format!("weights_data must be {n_u} lists of {n_v} weights"),
                ));
            }
            for r in w {
                if let Param::List(l) = untyped(r) {
                    for x in l {
                        weights[k] = num(x).ok_or_else(|| {
                            err(inst, "weights", "weights must be finite numbers")
                        })?;
                        k += 1;
                    }
                }
            }
        }
        let ctrl: Vec<[f64; 4]> = pts
            .iter()
            .zip(&weights)
            .map(|(pt, w)| {
                let m = to_machine.apply(*pt);
                [m[0], m[1], m[2], *w]
            })
            .collect();
        let s = StepSurface {
            id: inst.id,
            line: inst.line,
            geometry: OwnedSurface {
                degree_u: p,
                degree_v: q,
                n_u,
                n_v,
                knots_u,
                knots_v,
                ctrl,
            },
            rational: rational.is_some(),
            workpiece: to_machine.clone(),
            t_spline: None,
        };
        s.data()
            .validate(MAX_READ_CTRL)
            .map_err(|e| err(inst, "surface", e.to_string()))?;
        Ok(s)
    }

    fn tool(&self, from: &Instance, p: &Param) -> R<BallEndmill> {
        let inst = self.deref(from, p, "its_tool", &["CUTTING_TOOL"])?;
        let rec = self.first_record(inst, &["CUTTING_TOOL"]);
        let body_p = self.attr(inst, rec, 1, "its_tool_body")?;
        let body = self.deref(inst, body_p, "its_tool_body", &[])?;
        let brec = &body.records[0];
        if brec.name != "BALL_ENDMILL" {
            return Err(err(
                body,
                "tool",
                format!(
                    "{} cannot finish a free-form surface here; a BALL_ENDMILL is needed",
                    body.type_name()
                ),
            ));
        }
        let dim_p = self.attr(body, brec, 0, "dimension")?;
        let dim = self.deref(body, dim_p, "dimension", &["MILLING_TOOL_DIMENSION"])?;
        let diameter_mm = self.real(dim, &dim.records[0], 0, "diameter")?;
        if diameter_mm <= 0.0 {
            return Err(err(dim, "tool", "diameter must be > 0"));
        }
        let length_mm = self
            .opt_real(inst, rec, 3, "overall_assembly_length")?
            .ok_or_else(|| {
                err(
                    inst,
                    "tool",
                    "overall_assembly_length is unset: the tool length H is needed for the \
                     length compensation",
                )
            })?;
        if length_mm <= diameter_mm / 2.0 {
            return Err(err(
                inst,
                "tool",
                format!(
                    "overall_assembly_length {length_mm} mm is not longer than the ball radius"
                ),
            ));
        }
        Ok(BallEndmill {
            id: inst.id,
            name: self.text(rec, 0),
            diameter_mm,
            length_mm,
        })
    }

    fn technology(&self, from: &Instance, p: &Param) -> R<Technology> {
        let inst = self.deref(from, p, "its_technology", &["MILLING_TECHNOLOGY"])?;
        let rec = self.first_record(inst, &["MILLING_TECHNOLOGY"]);
        let feed = self
            .opt_real(inst, rec, 0, "feedrate")?
            .ok_or_else(|| err(inst, "feed", "feedrate is unset"))?;
        if feed <= 0.0 {
            return Err(err(inst, "feed", "feedrate must be > 0"));
        }
        let spindle = self.opt_real(inst, rec, 3, "spindle")?;
        Ok(Technology {
            feed_mm_per_min: feed * 60.0,
            spindle_rpm: spindle.map(|s| s * 60.0),
        })
    }

    /// `UV_STRATEGY` or `PLANE_CC_STRATEGY`; `to_machine` turns the plane normal (a
    /// direction in the feature's coordinates, like the surface's points) into machine
    /// coordinates.
    fn strategy(&self, from: &Instance, p: &Param, to_machine: &Placement) -> R<Strategy> {
        let inst = self.deref(
            from,
            p,
            "its_machining_strategy",
            &["UV_STRATEGY", "PLANE_CC_STRATEGY"],
        )?;
        let rec = &inst.records[0];
        if rec.name == "PLANE_CC_STRATEGY" {
            return self.plane_cc(inst, rec, to_machine).map(Strategy::PlaneCc);
        }
        if rec.name != "UV_STRATEGY" {
            return Err(err(
                inst,
                "strategy",
                format!(
                    "{} is not supported; use UV_STRATEGY or PLANE_CC_STRATEGY",
                    inst.type_name()
                ),
            ));
        }
        self.uv(inst, rec).map(Strategy::Uv)
    }

    /// The attributes every `FREEFORM_STRATEGY` has: pathmode, (cutmode,)
    /// its_milling_tolerances, stepover, as (mode, chordal, scallop, stepover cap).
    fn freeform_common(
        &self,
        inst: &Instance,
        rec: &Record,
    ) -> R<(PathMode, f64, f64, Option<f64>)> {
        let mode = match self.enumv(inst, rec, 0, "pathmode")?.as_str() {
            "FORWARD" => PathMode::Forward,
            "ZIGZAG" => PathMode::Zigzag,
            other => {
                return Err(err(
                    inst,
                    "strategy",
                    format!("pathmode .{other}. is neither .FORWARD. nor .ZIGZAG."),
                ))
            }
        };
        let tol_p = self.attr(inst, rec, 2, "its_milling_tolerances")?;
        let tol = self.deref(inst, tol_p, "its_milling_tolerances", &["TOLERANCES"])?;
        let chordal_mm = self.real(tol, &tol.records[0], 0, "chordal_tolerance")?;
        let scallop_mm = self.real(tol, &tol.records[0], 1, "scallop_height")?;
        if chordal_mm <= 0.0 || scallop_mm <= 0.0 {
            return Err(err(tol, "tolerance", "both tolerances must be > 0"));
        }
        let stepover_mm = self.opt_real(inst, rec, 3, "stepover")?;
        if stepover_mm.is_some_and(|s| s <= 0.0) {
            return Err(err(inst, "strategy", "stepover must be > 0"));
        }
        Ok((mode, chordal_mm, scallop_mm, stepover_mm))
    }

    /// `PLANE_CC_STRATEGY(pathmode, cutmode, its_milling_tolerances, stepover,
    /// its_plane_normal)`.
    fn plane_cc(
        &self,
        inst: &Instance,
        rec: &Record,
        to_machine: &Placement,
    ) -> R<PlaneCcStrategy> {
        let (mode, chordal_mm, scallop_mm, stepover_mm) = self.freeform_common(inst, rec)?;
        let p = self.attr(inst, rec, 4, "its_plane_normal")?;
        let d_inst = self.deref(inst, p, "its_plane_normal", &["DIRECTION"])?;
        let d = self.direction(d_inst)?;
        let mut local = [0.0; 3];
        for (o, x) in local.iter_mut().zip(&d) {
            *o = *x;
        }
        // A direction turns with the placement; its origin does not move it.
        let mut n = [0.0; 3];
        for (r, o) in n.iter_mut().enumerate() {
            *o = (0..3).map(|c| to_machine.rot[r][c] * local[c]).sum();
        }
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        Ok(PlaneCcStrategy {
            id: inst.id,
            normal_id: d_inst.id,
            normal_line: d_inst.line,
            mode,
            normal: n.map(|x| x / len),
            stepover_mm,
            scallop_mm,
            chordal_mm,
        })
    }

    fn uv(&self, inst: &Instance, rec: &Record) -> R<UvStrategy> {
        let (mode, chordal_mm, scallop_mm, stepover_mm) = self.freeform_common(inst, rec)?;
        let dir = |i: usize, what: &str| -> R<(usize, f64)> {
            let p = self.attr(inst, rec, i, what)?;
            let d_inst = self.deref(inst, p, what, &["DIRECTION"])?;
            let d = self.direction(d_inst)?;
            let nonzero: Vec<usize> = (0..d.len().min(2)).filter(|&k| d[k] != 0.0).collect();
            match nonzero.as_slice() {
                [k] if d.get(2).is_none_or(|z| *z == 0.0) => Ok((*k, d[*k].signum())),
                _ => Err(err(
                    d_inst,
                    "strategy",
                    format!(
                        "{what} must be along u (1,0) or v (0,1) in the surface's parameter plane \
                         (iso-parametric passes only)"
                    ),
                )),
            }
        };
        let (fwd_axis, forward_sign) = dir(4, "forward_direction")?;
        let (side_axis, sideward_sign) = dir(5, "sideward_direction")?;
        if fwd_axis == side_axis {
            return Err(err(
                inst,
                "strategy",
                "forward_direction and sideward_direction are parallel",
            ));
        }
        Ok(UvStrategy {
            id: inst.id,
            mode,
            passes: if fwd_axis == 0 {
                Passes::AlongU
            } else {
                Passes::AlongV
            },
            forward_sign,
            sideward_sign,
            stepover_mm,
            scallop_mm,
            chordal_mm,
        })
    }

    /// The workpiece placement of `workpiece` in `setup`: setup origin, then the workpiece
    /// setup's origin.
    fn setup_placement(&self, setup: &Instance, workpiece: u64) -> R<Placement> {
        let rec = &setup.records[0];
        let origin_p = self.attr(setup, rec, 1, "its_origin")?;
        let origin = self.placement(setup, origin_p, "its_origin")?;
        let wps = self.list(setup, rec, 3, "its_workpiece_setup")?;
        for wp in wps {
            let wps_inst = self.deref(setup, wp, "its_workpiece_setup", &["WORKPIECE_SETUP"])?;
            let wrec = &wps_inst.records[0];
            if matches!(self.attr(wps_inst, wrec, 0, "its_workpiece")?, Param::Ref(id) if *id == workpiece)
            {
                let wp_origin_p = self.attr(wps_inst, wrec, 1, "its_origin")?;
                let wp_origin = self.placement(wps_inst, wp_origin_p, "its_origin")?;
                return Ok(origin.then(&wp_origin));
            }
        }
        Err(err(
            setup,
            "setup",
            format!("no WORKPIECE_SETUP of the setup places workpiece #{workpiece}"),
        ))
    }

    /// The operation, the placement into machine coordinates and the surface instance.
    fn workingstep_head(
        &self,
        ws: &Instance,
        setup: &Instance,
    ) -> R<(&'a Instance, Placement, &'a Instance)> {
        let rec = &ws.records[0];
        let op_p = self.attr(ws, rec, 3, "its_operation")?;
        let op = self.deref(ws, op_p, "its_operation", &[])?;
        if op.records[0].name != "FREEFORM_OPERATION" {
            return Err(err(
                op,
                "operation",
                format!(
                    "{} is not supported; free-form workingsteps need a FREEFORM_OPERATION",
                    op.type_name()
                ),
            ));
        }
        let feat_p = self.attr(ws, rec, 2, "its_feature")?;
        let feat = self.deref(ws, feat_p, "its_feature", &["REGION_SURFACE_LIST"])?;
        let frec = &feat.records[0];
        let workpiece = match self.attr(feat, frec, 1, "its_workpiece")? {
            Param::Ref(id) => {
                self.deref(feat, &Param::Ref(*id), "its_workpiece", &["WORKPIECE"])?;
                *id
            }
            _ => return Err(err(feat, "type", "its_workpiece must be a reference")),
        };
        let place_p = self.attr(feat, frec, 3, "feature_placement")?;
        let feature_place = self.placement(feat, place_p, "feature_placement")?;
        let to_machine = self.setup_placement(setup, workpiece)?.then(&feature_place);
        let surfaces = self.list(feat, frec, 5, "surface_list")?;
        let [surf_p] = surfaces else {
            return Err(err(
                feat,
                "feature",
                format!(
                    "surface_list holds {} surfaces; one surface per feature is supported",
                    surfaces.len()
                ),
            ));
        };
        let surf_inst = self.deref(
            feat,
            surf_p,
            "surface_list",
            &["B_SPLINE_SURFACE_WITH_KNOTS", "T_SPLINE_SURFACE"],
        )?;
        Ok((op, to_machine, surf_inst))
    }

    /// A workingstep; a T-spline surface gives one per T-region.
    fn workingstep(
        &self,
        ws: &Instance,
        setup: &Instance,
    ) -> Result<Vec<FreeformStep>, Vec<StepError>> {
        let (op, to_machine, surf_inst) = self.workingstep_head(ws, setup).map_err(|e| vec![e])?;
        let rec = &ws.records[0];
        let orec = &op.records[0];
        // FREEFORM_OPERATION: its_toolpath, its_tool_direction, its_id, retract_plane,
        // start_point, its_tool, its_technology, its_machine_functions, overcut_length,
        // approach, retract, its_machining_strategy.
        let (tool, tech, strategy) = (
            self.attr(op, orec, 5, "its_tool")
                .and_then(|p| self.tool(op, p)),
            self.attr(op, orec, 6, "its_technology")
                .and_then(|p| self.technology(op, p)),
            self.attr(op, orec, 11, "its_machining_strategy")
                .and_then(|p| self.strategy(op, p, &to_machine)),
        );
        let surfaces = if !surf_inst.complex && surf_inst.records[0].name == "T_SPLINE_SURFACE" {
            // Seed 003: row strips when the passes run along s, column strips along t.
            let along_s = strategy
                .as_ref()
                .ok()
                .and_then(Strategy::uv)
                .is_none_or(|u| u.passes == Passes::AlongU);
            self.t_spline_regions(surf_inst, &to_machine, along_s)
        } else {
            self.surface(surf_inst, &to_machine)
                .map(|s| vec![s])
                .map_err(|e| vec![e])
        };
        // Every part's error is reported, not only the first one's.
        let mut errs: Vec<StepError> = Vec::new();
        let surfaces = surfaces.map_err(|e| errs.extend(e)).ok();
        let tool = tool.map_err(|e| errs.push(e)).ok();
        let tech = tech.map_err(|e| errs.push(e)).ok();
        let strategy = strategy.map_err(|e| errs.push(e)).ok();
        match (surfaces, tool, tech, strategy) {
            (Some(surfaces), Some(tool), Some(technology), Some(strategy)) => {
                let name = self.text(rec, 0);
                Ok(surfaces
                    .into_iter()
                    .map(|surface| FreeformStep {
                        id: ws.id,
                        line: ws.line,
                        name: match &surface.t_spline {
                            Some(t) if t.regions > 1 => {
                                format!("{name} (T-region {} of {})", t.region, t.regions)
                            }
                            _ => name.clone(),
                        },
                        surface,
                        tool: tool.clone(),
                        technology: technology.clone(),
                        strategy: strategy.clone(),
                    })
                    .collect())
            }
            _ => Err(errs),
        }
    }
}

/// Reads every machining workingstep of the file's workplans.
pub fn read(ex: &Exchange) -> Result<Vec<FreeformStep>, Vec<StepError>> {
    let mut cx = Ctx {
        ex,
        errs: Vec::new(),
    };
    let mut steps = Vec::new();
    let plans: Vec<&Instance> = ex
        .instances
        .values()
        .filter(|i| !i.complex && i.records[0].name == "WORKPLAN")
        .collect();
    if plans.is_empty() {
        cx.errs.push(StepError {
            line: ex.instances.values().next().map_or(1, |i| i.line),
            id: None,
            rule: "workplan",
            message: "the file has no WORKPLAN, so it is no STEP-NC part; a CAD file's curves are made into a program by `cnc cam curves FILE`".into(),
        });
    }
    for plan in plans {
        let rec = &plan.records[0];
        let setup = cx
            .attr(plan, rec, 3, "its_setup")
            .and_then(|p| cx.deref(plan, p, "its_setup", &["SETUP"]));
        let elements = cx.list(plan, rec, 1, "its_elements");
        let (setup, elements) = match (setup, elements) {
            (Ok(s), Ok(e)) => (s, e),
            (s, e) => {
                cx.errs.extend(s.err());
                cx.errs.extend(e.err());
                continue;
            }
        };
        let mut found = 0;
        for el in elements {
            let ws = match cx.deref(plan, el, "its_elements", &[]) {
                Ok(ws) => ws,
                Err(e) => {
                    cx.errs.push(e);
                    continue;
                }
            };
            if ws.records[0].name != "MACHINING_WORKINGSTEP" {
                continue;
            }
            found += 1;
            match cx.workingstep(ws, setup) {
                Ok(s) => steps.extend(s),
                Err(e) => cx.errs.extend(e),
            }
        }
        if found == 0 {
            cx.errs.push(err(
                plan,
                "workplan",
                "the workplan has no MACHINING_WORKINGSTEP",
            ));
        }
    }
    if cx.errs.is_empty() {
        Ok(steps)
    } else {
        cx.errs.sort_by_key(|e| (e.line, e.id));
        cx.errs.dedup();
        Err(cx.errs)
    }
}
