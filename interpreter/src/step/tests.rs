//! The example parts read as written, broken files name file, line, instance and rule,
//! and no byte-level mutation of an example makes the reader panic.

use super::*;
use proptest::prelude::*;

const SEED: &str = include_str!("../../../examples/seed-surface.stp");
const TORUS: &str = include_str!("../../../examples/torus-patch.stp");
const CUBIC: &str = include_str!("../../../examples/cubic-wave.stp");

/// The line of `text` starting `#id=`, as (line number, text).
fn instance_line(text: &str, prefix: &str) -> (usize, String) {
    text.lines()
        .enumerate()
        .find(|(_, l)| l.contains(prefix))
        .map(|(i, l)| (i + 1, l.to_string()))
        .unwrap()
}

fn id_of(line: &str) -> u64 {
    line[1..line.find('=').unwrap()].parse().unwrap()
}

/// `text` with attribute `index` (top level, 0-based) of the instance on the line that
/// contains `prefix` replaced by `value`.
fn set_attr(text: &str, prefix: &str, index: usize, value: &str) -> String {
    let (_, line) = instance_line(text, prefix);
    let open = line.find('(').unwrap();
    let body = &line[open + 1..line.len() - 2];
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0, 0);
    for (i, c) in body.char_indices() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' if depth == 0 => {
                parts.push(&body[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    parts.push(&body[start..]);
    let mut parts: Vec<String> = parts.into_iter().map(String::from).collect();
    parts[index] = value.to_string();
    let new = format!("{}({});", &line[..open], parts.join(","));
    text.replace(&line, &new)
}

#[test]
fn seed_surface_reads_as_the_seed_describes_it() {
    let steps = read_part(SEED).unwrap();
    assert_eq!(steps.len(), 1);
    let s = &steps[0];
    assert_eq!(
        (s.surface.geometry.degree_u, s.surface.geometry.degree_v),
        (2, 2)
    );
    assert_eq!((s.surface.geometry.n_u, s.surface.geometry.n_v), (10, 10));
    let k: Vec<f64> = [0.0, 0.0, 0.0]
        .into_iter()
        .chain((1..8).map(|i| i as f64 / 8.0))
        .chain([1.0, 1.0, 1.0])
        .collect();
    assert_eq!(s.surface.geometry.knots_u, k);
    assert_eq!(s.surface.geometry.knots_v, k);
    assert!(s.surface.geometry.ctrl.iter().all(|c| c[3] == 1.0));
    assert!(!s.surface.rational);
    assert_eq!(s.tool.diameter_mm, 6.0);
    assert_eq!(s.tool.length_mm, 100.0);
    assert!((s.technology.feed_mm_per_min - 2400.0).abs() < 1e-9);
    assert!((s.technology.spindle_rpm.unwrap() - 4485.0).abs() < 1e-9);
    let st = s.strategy.uv().unwrap();
    assert_eq!(st.mode, PathMode::Zigzag);
    assert_eq!(st.passes, Passes::AlongU);
    assert_eq!(st.scallop_mm, 0.02);
    assert_eq!(st.stepover_mm, None);
}

#[test]
fn rational_torus_and_cubic_examples_read() {
    let t = &read_part(TORUS).unwrap()[0];
    assert!(t.surface.rational);
    assert_eq!((t.surface.geometry.n_u, t.surface.geometry.n_v), (3, 3));
    let c = std::f64::consts::FRAC_1_SQRT_2;
    assert!((t.surface.geometry.ctrl[4][3] - 0.5).abs() < 1e-15);
    assert!((t.surface.geometry.ctrl[1][3] - c).abs() < 1e-15);
    assert_eq!(t.strategy.stepover_mm(), Some(2.0));
    // Setup origin (0,0,-20), then the workpiece at (20,10,5) turned 30° about z.
    let p0 = t.surface.workpiece.apply([0.0; 3]);
    assert!((p0[0] - 20.0).abs() < 1e-12 && (p0[1] - 10.0).abs() < 1e-12);
    assert!((p0[2] + 15.0).abs() < 1e-12);
    let q = &read_part(CUBIC).unwrap()[0];
    assert_eq!(
        (q.surface.geometry.degree_u, q.surface.geometry.degree_v),
        (3, 3)
    );
    let qs = q.strategy.uv().unwrap();
    assert_eq!(qs.mode, PathMode::Forward);
    assert_eq!(qs.passes, Passes::AlongV);
    assert_eq!(qs.sideward_sign, -1.0);
    // Feature placement (5, 5, 0): the first control point moves by it.
    assert_eq!(
        q.surface.geometry.ctrl[0][..3],
        [5.0, 5.0, 5.0 * 0.0 + q.surface.geometry.ctrl[0][2]]
    );
}

#[test]
fn a_dangling_reference_names_file_line_instance_and_rule() {
    let (line, op) = instance_line(SEED, "FREEFORM_OPERATION(");
    let bad = set_attr(SEED, "FREEFORM_OPERATION(", 6, "#9999");
    let errs = read_part(&bad).unwrap_err();
    let text = format_errors("part.stp", &errs);
    let want = format!(
        "part.stp:{line}: #{}: reference: its_technology refers to #9999",
        id_of(&op)
    );
    assert!(text.starts_with(&want), "{text}");
    assert_eq!(errs.len(), 1, "{text}");
}

#[test]
fn a_wrong_knot_count_is_reported_on_the_surface() {
    let (line, surf) = instance_line(SEED, "B_SPLINE_SURFACE_WITH_KNOTS(");
    let bad = set_attr(
        SEED,
        "B_SPLINE_SURFACE_WITH_KNOTS(",
        8,
        "(2,1,1,1,1,1,1,1,3)",
    );
    let errs = read_part(&bad).unwrap_err();
    let text = format_errors("part.stp", &errs);
    let want = format!(
        "part.stp:{line}: #{}: knot count: 12 u knots (sum of multiplicities) for 10 control \
         points of degree 2, expected 13",
        id_of(&surf)
    );
    assert_eq!(text.trim_end(), want);
}

#[test]
fn a_missing_tool_and_a_non_ball_tool_are_errors() {
    let (line, op) = instance_line(SEED, "FREEFORM_OPERATION(");
    let bad = set_attr(SEED, "FREEFORM_OPERATION(", 5, "$");
    let text = format_errors("p.stp", &read_part(&bad).unwrap_err());
    assert_eq!(
        text.trim_end(),
        format!(
            "p.stp:{line}: #{}: missing: its_tool is unset (`$`)",
            id_of(&op)
        )
    );
    let flat = SEED.replace("BALL_ENDMILL(", "ENDMILL(");
    let text = format_errors("p.stp", &read_part(&flat).unwrap_err());
    assert!(text.contains(": tool: ENDMILL cannot finish"), "{text}");
    let no_len = set_attr(SEED, "CUTTING_TOOL(", 3, "$");
    let text = format_errors("p.stp", &read_part(&no_len).unwrap_err());
    assert!(text.contains("overall_assembly_length is unset"), "{text}");
}

#[test]
fn every_error_of_a_file_comes_in_one_pass() {
    let bad = set_attr(
        SEED,
        "B_SPLINE_SURFACE_WITH_KNOTS(",
        9,
        "(3,1,1,1,1,1,1,1,2)",
    );
    let bad = set_attr(&bad, "FREEFORM_OPERATION(", 5, "#4242");
    let bad = set_attr(&bad, "UV_STRATEGY(", 0, ".SPIRAL.");
    let errs = read_part(&bad).unwrap_err();
    let rules: Vec<&str> = errs.iter().map(|e| e.rule).collect();
    assert_eq!(errs.len(), 3, "{errs:?}");
    assert!(
        rules.contains(&"knot count") && rules.contains(&"reference"),
        "{errs:?}"
    );
    assert!(rules.contains(&"strategy"));
    // Syntax errors are collected the same way, each with its line.
    let broken = SEED.replacen("#5=CARTESIAN_POINT('',(", "#5=CARTESIAN_POINT('',((", 1);
    let broken = broken.replacen("#7=CARTESIAN_POINT", "#7 CARTESIAN_POINT", 1);
    let errs = read_part(&broken).unwrap_err();
    assert_eq!(errs.len(), 2, "{errs:?}");
    assert!(errs.iter().all(|e| e.rule == "syntax"));
    assert_eq!(errs[0].id, Some(5));
}

#[test]
fn plane_cc_strategy_reads_and_names_a_bad_normal() {
    // The UV strategy's attributes as a PLANE_CC_STRATEGY: its_plane_normal is the
    // forward direction #114, (1, 0), read as the plane normal (1, 0, 0).
    let planes = SEED.replace("UV_STRATEGY(", "PLANE_CC_STRATEGY(");
    let s = &read_part(&planes).unwrap()[0];
    let super::Strategy::PlaneCc(st) = &s.strategy else {
        panic!("{:?}", s.strategy)
    };
    assert_eq!((st.normal, st.normal_id), ([1.0, 0.0, 0.0], 114));
    let (line, strat) = instance_line(SEED, "UV_STRATEGY(");
    let bad = planes.replace("#113,$,#114,#115)", "#113,$,#113)");
    let text = format_errors("p.stp", &read_part(&bad).unwrap_err());
    let want = format!(
        "p.stp:{line}: #{}: reference: its_plane_normal refers to #113, a TOLERANCES, where \
         DIRECTION is expected",
        id_of(&strat)
    );
    assert!(text.starts_with(&want), "{text}");
}

#[test]
fn oblique_uv_directions_are_refused() {
    let (_, strat) = instance_line(SEED, "UV_STRATEGY(");
    let fwd = strat
        .split(',')
        .nth(4)
        .unwrap()
        .trim_start_matches('#')
        .to_string();
    let bad = SEED.replace(
        &format!("#{fwd}=DIRECTION('',(1.0,0.0));"),
        &format!("#{fwd}=DIRECTION('',(1.0,1.0));"),
    );
    assert_ne!(bad, SEED);
    let text = format_errors("p.stp", &read_part(&bad).unwrap_err());
    assert!(text.contains("iso-parametric passes only"), "{text}");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]
    /// Any few bytes of an example overwritten: an answer, never a panic.
    #[test]
    fn mutated_bytes_never_panic(
        edits in proptest::collection::vec((0usize..200_000, any::<u8>()), 1..6),
        which in 0usize..3,
    ) {
        let base = [SEED, TORUS, CUBIC][which];
        let mut bytes = base.as_bytes().to_vec();
        for (pos, b) in edits {
            let i = pos % bytes.len();
            bytes[i] = b;
        }
        let text = String::from_utf8_lossy(&bytes);
        match read_part(&text) {
            Ok(steps) => prop_assert!(!steps.is_empty()),
            Err(errs) => {
                prop_assert!(!errs.is_empty());
                prop_assert!(errs.iter().all(|e| e.line >= 1));
            }
        }
    }

    /// Truncated anywhere: an answer, never a panic; an error unless all that was cut
    /// is the final line break (a cut at the file's last byte, once drawn at random).
    #[test]
    fn truncated_files_never_panic(cut in 0usize..100_000) {
        let cut = cut % SEED.len();
        let text = SEED.get(..cut).unwrap_or("");
        let whole = SEED.get(cut..).is_some_and(|rest| rest.trim().is_empty());
        prop_assert_eq!(read_part(text).is_err(), !whole, "cut at {}", cut);
    }
}

/// Issue #22: an inner knot as often as the order cuts the surface in two along it, and
/// a pass across would jump: refused on the surface, as a G-code curve's is.
#[test]
fn an_inner_knot_as_often_as_the_order_is_refused_on_the_surface() {
    let (line, surf) = instance_line(SEED, "B_SPLINE_SURFACE_WITH_KNOTS(");
    let bad = set_attr(SEED, "B_SPLINE_SURFACE_WITH_KNOTS(", 8, "(3,1,1,3,1,1,3)");
    let bad = set_attr(
        &bad,
        "B_SPLINE_SURFACE_WITH_KNOTS(",
        10,
        "(0.0,0.125,0.25,0.5,0.625,0.75,1.0)",
    );
    let text = format_errors("part.stp", &read_part(&bad).unwrap_err());
    let want = format!(
        "part.stp:{line}: #{}: knots: u knot 0.5 has multiplicity 3; at most 2 (the degree) \
         inside the surface",
        id_of(&surf)
    );
    assert!(text.starts_with(&want), "{text}");
    let ok = set_attr(SEED, "B_SPLINE_SURFACE_WITH_KNOTS(", 8, "(3,1,1,2,1,1,1,3)");
    let ok = set_attr(
        &ok,
        "B_SPLINE_SURFACE_WITH_KNOTS(",
        10,
        "(0.0,0.125,0.25,0.375,0.5,0.75,0.875,1.0)",
    );
    assert!(read_part(&ok).is_ok());
}
