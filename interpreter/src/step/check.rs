//! `cnc check part.stp`: what the file holds and what the planner makes of it.

use super::{format_errors, read_part, PathMode, StepError, Strategy};
use crate::surface_path::SurfacePath;
use crate::surface_plane::PlanePath;
use shared::nurbs::surface::Passes;
use std::fmt::Write;

/// The planned passes of a workingstep, by strategy.
#[derive(Debug, Clone, PartialEq)]
pub enum PlannedPath {
    Uv(SurfacePath),
    Plane(PlanePath),
}

impl PlannedPath {
    /// The largest scallop height the planner predicts.
    pub fn predicted_scallop_mm(&self) -> f64 {
        match self {
            PlannedPath::Uv(p) => p.predicted_scallop_mm,
            PlannedPath::Plane(p) => p.predicted_scallop_mm,
        }
    }
    pub fn length_mm(&self) -> f64 {
        match self {
            PlannedPath::Uv(p) => p.length_mm,
            PlannedPath::Plane(p) => p.length_mm,
        }
    }
    pub fn uv(&self) -> Option<&SurfacePath> {
        match self {
            PlannedPath::Uv(p) => Some(p),
            PlannedPath::Plane(_) => None,
        }
    }
    pub fn plane(&self) -> Option<&PlanePath> {
        match self {
            PlannedPath::Uv(_) => None,
            PlannedPath::Plane(p) => Some(p),
        }
    }
}

/// Plans a workingstep with the planner of its strategy.
pub fn plan_step(step: &super::FreeformStep) -> Result<PlannedPath, StepError> {
    match &step.strategy {
        Strategy::Uv(_) => crate::surface_path::plan(step).map(PlannedPath::Uv),
        Strategy::PlaneCc(_) => crate::surface_plane::plan(step).map(PlannedPath::Plane),
    }
}

/// Whether `name` or `text` says the file is a STEP exchange file rather than G-code.
pub fn is_step_file(name: &str, text: &str) -> bool {
    let lower = name.to_ascii_lowercase();
    [".stp", ".step", ".p21"].iter().any(|e| lower.ends_with(e)) || super::looks_like_part21(text)
}

/// Every free-form workingstep of the file with its plan, as [`check_part`] describes it.
pub fn plan_part(text: &str) -> Result<Vec<(super::FreeformStep, PlannedPath)>, Vec<StepError>> {
    let steps = read_part(text)?;
    let mut out = Vec::new();
    let mut errs = Vec::new();
    for s in steps {
        match plan_step(&s) {
            Ok(p) => out.push((s, p)),
            Err(e) => errs.push(e),
        }
    }
    if errs.is_empty() {
        Ok(out)
    } else {
        Err(errs)
    }
}

/// What the machine changes of what the part asks ([`crate::process::notes`]): a
/// workingstep's feed above `max_feed_mm_per_min` runs at that limit. None for a part
/// that cannot be read (its errors are told elsewhere).
pub fn part_notes(text: &str, machine: &shared::Machine) -> Vec<(u32, String)> {
    read_part(text).map_or_else(
        |_| Vec::new(),
        |steps| {
            crate::process::feed_notes(
                steps.iter().map(|s| (s.line, s.technology.feed_mm_per_min)),
                machine,
                "workingstep",
            )
        },
    )
}

/// The report `cnc check` prints for a STEP file, or every error as
/// `FILE:LINE: #ID: rule: message` lines.
pub fn check_part(name: &str, text: &str, machine: &shared::Machine) -> Result<String, String> {
    let planned = plan_part(text).map_err(|e| format_errors(name, &e))?;
    let mut o = String::new();
    let n = planned.len();
    let _ = writeln!(
        o,
        "{name}: ok, STEP-NC, {n} free-form workingstep{}",
        if n == 1 { "" } else { "s" }
    );
    // The passes from where the machine stands, each workingstep from where the last
    // ended, as `part_blocks` joins them for a run: none may leave the travel.
    let mut pos = crate::blocks::check::START_MM;
    let mut travel: Vec<_> = crate::surface_blocks::start_travel_error(machine)
        .into_iter()
        .collect();
    let mut all = Vec::new();
    for (s, p) in &planned {
        let (cmds, end) = crate::surface_blocks::step_commands(s, p, machine, pos)
            .map_err(|e| format_errors(name, &[e]))?;
        travel.extend(crate::surface_blocks::travel_errors(s, &cmds, machine));
        pos = end;
        all.push(cmds);
    }
    if !travel.is_empty() {
        return Err(format_errors(name, &travel));
    }
    for ((s, p), cmds) in planned.iter().zip(all) {
        let n_surf = cmds.iter().filter(|c| c.is_surface()).count();
        let sf = &s.surface;
        let _ = writeln!(o, "  #{} '{}' (line {}):", s.id, s.name, s.line);
        if let Some(t) = &sf.t_spline {
            let _ = writeln!(
                o,
                "    surface #{}: T-spline, degree 3, {} control points, {} T-junction{}; \
                 T-region {} of {}: {} x {} Bézier patches",
                sf.id,
                t.points,
                t.t_junctions,
                if t.t_junctions == 1 { "" } else { "s" },
                t.region,
                t.regions,
                t.cells.0,
                t.cells.1
            );
        }
        let _ = writeln!(
            o,
            "    {}: {}B-spline, degrees p={} q={}, {} x {} control points, knots {} + {}",
            if sf.t_spline.is_some() {
                "its patches as one surface".to_string()
            } else {
                format!("surface #{}", sf.id)
            },
            if sf.rational { "rational " } else { "" },
            sf.geometry.degree_u,
            sf.geometry.degree_v,
            sf.geometry.n_u,
            sf.geometry.n_v,
            sf.geometry.knots_u.len(),
            sf.geometry.knots_v.len()
        );
        let _ = writeln!(
            o,
            "    tool #{} '{}': ball end mill D {} mm (R {} mm), length H {} mm",
            s.tool.id,
            s.tool.name,
            s.tool.diameter_mm,
            s.tool.radius_mm(),
            s.tool.length_mm
        );
        let spindle = s
            .technology
            .spindle_rpm
            .map_or("unset".to_string(), |r| format!("{r:.0} rpm"));
        let _ = writeln!(
            o,
            "    feed {:.1} mm/min, spindle {spindle}",
            s.technology.feed_mm_per_min
        );
        match (&s.strategy, p) {
            (Strategy::Uv(st), PlannedPath::Uv(p)) => {
                let _ = writeln!(
                    o,
                    "    strategy #{}: UV {}, passes along {}, scallop tolerance {} mm, stepover \
                     cap {}",
                    st.id,
                    mode_name(st.mode),
                    match st.passes {
                        Passes::AlongU => "u",
                        Passes::AlongV => "v",
                    },
                    st.scallop_mm,
                    st.stepover_mm
                        .map_or("none".to_string(), |c| format!("{c} mm"))
                );
                let minutes = p.length_mm / s.technology.feed_mm_per_min;
                let _ = writeln!(
                    o,
                    "    {} passes, spacing {:.3}..{:.3} mm, predicted scallop {:.2} µm; path \
                     {:.3} mm, {:.1} s at the programmed feed",
                    p.passes.len(),
                    p.min_spacing_mm,
                    p.max_spacing_mm,
                    p.predicted_scallop_mm * 1e3,
                    p.length_mm,
                    minutes * 60.0
                );
            }
            (Strategy::PlaneCc(st), PlannedPath::Plane(p)) => {
                let n = st.normal;
                let _ = writeln!(
                    o,
                    "    strategy #{}: PLANE_CC {}, planes normal to ({:.4}, {:.4}, {:.4}), \
                     scallop tolerance {} mm, chordal tolerance {} mm, stepover cap {}",
                    st.id,
                    mode_name(st.mode),
                    n[0],
                    n[1],
                    n[2],
                    st.scallop_mm,
                    st.chordal_mm,
                    st.stepover_mm
                        .map_or("none".to_string(), |c| format!("{c} mm"))
                );
                let length: f64 = cmds
                    .iter()
                    .filter(|c| c.is_surface())
                    .map(|c| c.length_mm)
                    .sum();
                let minutes = length / s.technology.feed_mm_per_min;
                let _ = writeln!(
                    o,
                    "    {} planes, {} passes{}, plane step {:.3}..{:.3} mm, predicted scallop \
                     {:.2} µm; path {:.3} mm, {:.1} s at the programmed feed",
                    p.planes,
                    p.passes.len(),
                    if p.boundary.is_empty() {
                        String::new()
                    } else {
                        // Where the passes meet the edges: see surface_plane's "Edges".
                        format!(
                            " and a boundary pass (passes meet the edges at up to {:.2}x \
                             the scallop between them)",
                            p.edge_factor
                        )
                    },
                    p.min_step_mm,
                    p.max_step_mm,
                    p.predicted_scallop_mm * 1e3,
                    length,
                    minutes * 60.0
                );
            }
            _ => {}
        }
        let _ = writeln!(
            o,
            "    {} blocks: {n_surf} surface blocks, {} rapid lines",
            cmds.len(),
            cmds.len() - n_surf
        );
    }
    Ok(o)
}

fn mode_name(m: PathMode) -> &'static str {
    match m {
        PathMode::Zigzag => "zig-zag",
        PathMode::Forward => "forward",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn check_reports_the_example_and_the_errors() {
        let text = include_str!("../../../examples/seed-surface.stp");
        let out = check_part("seed-surface.stp", text, &shared::Machine::default()).unwrap();
        assert!(out.starts_with("seed-surface.stp: ok, STEP-NC, 1 free-form workingstep\n"));
        assert!(
            out.contains("degrees p=2 q=2, 10 x 10 control points"),
            "{out}"
        );
        assert!(out.contains("D 6 mm (R 3 mm), length H 100 mm"), "{out}");
        let bad = text.replace("BALL_ENDMILL(", "BALL_ENDMILL(#999,");
        let err = check_part("x.stp", &bad, &shared::Machine::default()).unwrap_err();
        assert!(err.starts_with("x.stp:"), "{err}");
        assert!(is_step_file("a.STP", ""));
        assert!(is_step_file("a", text));
        assert!(!is_step_file("a.ngc", "G1 X1\n"));
    }
}
