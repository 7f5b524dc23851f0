use super::*;
use crate::blocks::{build, commands, plan};
use crate::program::interpret;
use shared::nurbs::{self, CurvePoint};
use shared::protocol::BlockKind;
use shared::Machine;

fn moves(text: &str) -> Vec<Move> {
    interpret(text).unwrap().moves
}

fn blended(text: &str) -> Vec<Move> {
    corners(&moves(text)).into_owned()
}

/// The blends of a move list: (source line, control points, feed).
fn blends(ms: &[Move]) -> Vec<(u32, Vec<[f64; 4]>, f64)> {
    ms.iter()
        .filter_map(|m| match m {
            Move::Nurbs {
                line,
                degree: 5,
                ctrl,
                feed,
                ..
            } => Some((*line, ctrl.clone(), *feed)),
            _ => None,
        })
        .collect()
}

const KNOTS: [f64; 12] = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0];

fn at(ctrl: &[[f64; 4]], t: f64) -> CurvePoint {
    nurbs::eval(5, &KNOTS, ctrl, t)
}

fn unit(v: [f64; 3]) -> [f64; 3] {
    let n = norm(v);
    v.map(|x| x / n)
}

fn curvature(e: &CurvePoint) -> f64 {
    norm(cross(e.d1, e.d2)) / norm(e.d1).powi(3)
}

fn dist_to_segment(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let d = sub(b, a);
    let s = (dot(sub(p, a), d) / dot(d, d)).clamp(0.0, 1.0);
    norm(sub(p, add(a, d.map(|x| x * s))))
}

fn dist_to_polyline(p: [f64; 3], pts: &[[f64; 3]]) -> f64 {
    pts.windows(2)
        .map(|w| dist_to_segment(p, w[0], w[1]))
        .fold(f64::INFINITY, f64::min)
}

fn fmt(v: f64) -> String {
    format!("{v:.6}")
}

/// Start, end and unit direction of a motion move (lines and blends).
/// Start, end, start tangent, end tangent.
type Ends = ([f64; 3], [f64; 3], [f64; 3], [f64; 3]);

fn ends(m: &Move) -> Option<Ends> {
    match m {
        Move::Line { from, to, .. } => {
            let u = unit(sub(*to, *from));
            Some((*from, *to, u, u))
        }
        Move::Nurbs { ctrl, .. } => {
            let (a, b) = (at(ctrl, 0.0), at(ctrl, 1.0));
            Some((a.p, b.p, unit(a.d1), unit(b.d1)))
        }
        _ => None,
    }
}

/// Every blend joins what comes before and after it at the very same point, with the
/// same tangent (1e-12) and zero curvature (relative to its size).
fn assert_g2_joins(ms: &[Move]) {
    let motion: Vec<&Move> = ms.iter().filter(|m| ends(m).is_some()).collect();
    for w in motion.windows(2) {
        let (_, end, _, t_end) = ends(w[0]).unwrap();
        let (start, _, t_start, _) = ends(w[1]).unwrap();
        assert_eq!(end, start, "{:?} then {:?}", w[0], w[1]);
        let is_blend = |m: &Move| matches!(m, Move::Nurbs { .. });
        if is_blend(w[0]) || is_blend(w[1]) {
            assert!(
                norm(sub(t_end, t_start)) < 1e-12,
                "tangent {t_end:?} {t_start:?}"
            );
        }
    }
    for (_, ctrl, _) in blends(ms) {
        let size = norm(sub(
            [ctrl[5][0], ctrl[5][1], ctrl[5][2]],
            [ctrl[0][0], ctrl[0][1], ctrl[0][2]],
        ));
        for t in [0.0, 1.0] {
            let k = curvature(&at(&ctrl, t));
            assert!(k * size < 1e-12, "curvature {k} at t = {t}, size {size}");
        }
    }
}

/// A corner of `turn_deg` between two lines of `leg` mm, under `G64 P<tol>`.
fn corner_program(turn_deg: f64, leg: f64, tol: f64) -> (String, [[f64; 3]; 3]) {
    let t = turn_deg.to_radians();
    let c = [leg, 0.0, 0.0];
    let e = [leg + leg * t.cos(), leg * t.sin(), 0.0];
    let text = format!(
        "G21 G64 P{tol}\nG1 X{} F3000\nX{} Y{}\nM2\n",
        fmt(leg),
        fmt(e[0]),
        fmt(e[1])
    );
    (
        text,
        [
            [0.0; 3],
            c,
            [fmt(e[0]).parse().unwrap(), fmt(e[1]).parse().unwrap(), 0.0],
        ],
    )
}

/// Largest distance from the blend (sampled) to the polyline, and from the polyline
/// near the corner to the blend (sampled): both ways of the Hausdorff distance.
fn deviations(ctrl: &[[f64; 4]], poly: &[[f64; 3]]) -> (f64, f64) {
    let n = 4000;
    let pts: Vec<[f64; 3]> = (0..=n).map(|i| at(ctrl, i as f64 / n as f64).p).collect();
    let out = pts
        .iter()
        .map(|p| dist_to_polyline(*p, poly))
        .fold(0.0, f64::max);
    // The polyline's points between the trim points: the two trimmed pieces.
    let (s, e) = (
        [ctrl[0][0], ctrl[0][1], ctrl[0][2]],
        [ctrl[5][0], ctrl[5][1], ctrl[5][2]],
    );
    let c = poly[1];
    let m = 400;
    let back = (0..=2 * m)
        .map(|i| {
            let x = if i <= m {
                add(s, sub(c, s).map(|v| v * i as f64 / m as f64))
            } else {
                add(c, sub(e, c).map(|v| v * (i - m) as f64 / m as f64))
            };
            let (k, _) = pts
                .iter()
                .enumerate()
                .map(|(k, p)| (k, norm(sub(*p, x))))
                .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
            // Refine between the neighbouring samples (the distance is unimodal there).
            let d = |t: f64| norm(sub(at(ctrl, t).p, x));
            let (mut lo, mut hi) = (
                (k.max(1) - 1) as f64 / n as f64,
                ((k + 1).min(n)) as f64 / n as f64,
            );
            for _ in 0..100 {
                let (m1, m2) = (lo + (hi - lo) / 3.0, hi - (hi - lo) / 3.0);
                if d(m1) < d(m2) {
                    hi = m2;
                } else {
                    lo = m1;
                }
            }
            d(0.5 * (lo + hi))
        })
        .fold(0.0, f64::max);
    (out, back)
}

#[test]
fn blend_meets_each_line_with_its_tangent_and_zero_curvature() {
    for turn in [1.0, 30.0, 90.0, 135.0, 170.0] {
        let (text, _) = corner_program(turn, 10.0, 0.01);
        let ms = blended(&text);
        assert_eq!(blends(&ms).len(), 1, "{turn}°");
        assert_g2_joins(&ms);
        // The lines are trimmed, not dropped: line, blend, line.
        let kinds: Vec<_> = ms
            .iter()
            .filter(|m| ends(m).is_some())
            .map(|m| matches!(m, Move::Nurbs { .. }))
            .collect();
        assert_eq!(kinds, [false, true, false], "{turn}°");
    }
}

#[test]
fn deviation_is_within_the_tolerance_and_reaches_it_on_long_legs() {
    for tol in [0.01, 0.1] {
        for turn in [1.0, 10.0, 45.0, 90.0, 120.0, 150.0, 170.0] {
            let (text, poly) = corner_program(turn, 200.0, tol);
            let ms = blended(&text);
            let b = blends(&ms);
            assert_eq!(b.len(), 1);
            let (out, back) = deviations(&b[0].1, &poly);
            // The tool never leaves the programmed lines by more than tol·cos(θ/2)
            // (the closed form), the corner is missed by tol: the two paths are tol
            // apart (Hausdorff), to the sampling's accuracy.
            let half = (0.5 * turn).to_radians();
            assert!(out <= tol * (1.0 + 1e-9), "{turn}° P{tol}: out {out}");
            assert!(
                (out - tol * half.cos()).abs() < 1e-6 * tol,
                "{turn}° P{tol}: out {out} vs {}",
                tol * half.cos()
            );
            assert!(back <= tol * (1.0 + 1e-9), "{turn}° P{tol}: back {back}");
            assert!(back >= (1.0 - 1e-9) * tol, "{turn}° P{tol}: back {back}");
            // And the corner point itself is tol from the blend's middle.
            let mid = at(&b[0].1, 0.5).p;
            assert!((norm(sub(mid, poly[1])) - tol).abs() < 1e-12, "{mid:?}");
        }
    }
}

#[test]
fn short_legs_shrink_the_blend_to_half_of_each() {
    // 90° with P1 would need legs of 2 × 3.3 mm; 2 mm legs give half of each.
    let (text, poly) = corner_program(90.0, 2.0, 1.0);
    let b = blends(&blended(&text));
    let start = [b[0].1[0][0], b[0].1[0][1], b[0].1[0][2]];
    assert!(norm(sub(start, [1.0, 0.0, 0.0])) < 1e-12, "{start:?}");
    let (c1, c2) = ratios(90.0);
    let h = 2.0 * mid_weight(c1, c2) * 1.0 * (45.0f64).to_radians().sin();
    let (out, back) = deviations(&b[0].1, &poly);
    assert!(h < 0.35, "{h}");
    assert!(
        (out - h * (45.0f64).to_radians().cos()).abs() < 1e-9,
        "{out} vs {h}"
    );
    assert!((back - h).abs() < 1e-9 * h, "{back} vs {h}");
    // Two corners on one short leg share it: the leg is used up, the blends meet at its
    // middle with one tangent and zero curvature, and never overlap.
    let ms = blended("G64 P1\nG1 X10 F3000\nY1\nX0\nM2\n");
    let b = blends(&ms);
    assert_eq!(b.len(), 2);
    assert_eq!(b[0].1[5], b[1].1[0]);
    assert_eq!(b[0].1[5], [10.0, 0.5, 0.0, 1.0]);
    assert_g2_joins(&ms);
    assert_eq!(
        ms.iter().filter(|m| matches!(m, Move::Line { .. })).count(),
        2
    );
}

#[test]
fn no_blend_without_a_tolerance_or_outside_g64_p() {
    for mode in [
        "",
        "G61\n",
        "G61.1\n",
        "G64\n",
        "G64 P0\n",
        "G64 P0.01\nG61\n",
    ] {
        let m = moves(&format!("{mode}G1 X10 F3000\nY10\nX0\nM2\n"));
        let out = corners(&m);
        assert!(matches!(out, Cow::Borrowed(_)), "{mode:?}");
        assert_eq!(&*out, &m[..]);
    }
    // The mode in force for the move that ends at the corner decides: the first corner
    // is under G61, the second under G64 P.
    let ms = blended("G61\nG1 X10 F3000\nG64 P0.01\nY10\nG61\nX0\nM2\n");
    let b = blends(&ms);
    assert_eq!(b.len(), 1);
    assert_eq!(b[0].0, 4, "the blend carries the line of Y10");
    assert_g2_joins(&ms);
}

#[test]
fn collinear_and_nearly_collinear_legs_need_no_blend() {
    assert!(blends(&blended("G64 P0.01\nG1 X10 F3000\nX20\nM2\n")).is_empty());
    // A turn of 5e-5 rad: below MIN_TURN_RAD.
    let y = 10.0 * (5e-5f64).tan();
    let text = format!("G64 P0.01\nG1 X10 F3000\nX20 Y{y:.9}\nM2\n");
    assert!(blends(&blended(&text)).is_empty());
    // 2e-4 rad: blended, over half of each leg (the tolerance would allow far more).
    let y = 10.0 * (2e-4f64).tan();
    let text = format!("G64 P0.01\nG1 X10 F3000\nX20 Y{y:.9}\nM2\n");
    let ms = blended(&text);
    let b = blends(&ms);
    assert_eq!(b.len(), 1);
    assert!((b[0].1[0][0] - 5.0).abs() < 1e-12);
    assert_g2_joins(&ms);
}

#[test]
fn degenerate_legs_are_not_blended() {
    // The interpreter drops a move to where the tool already is: the corner around it
    // is one corner, and blended.
    let ms = blended("G64 P0.01\nG1 X10 F3000\nX10\nY10\nM2\n");
    assert_eq!(blends(&ms).len(), 1);
    // A zero-length or sub-micrometre leg handed to the pass: no blend at its corners.
    let line = |from: [f64; 3], to: [f64; 3]| Move::Line {
        line: 1,
        from,
        to,
        rapid: false,
        feed: 3000.0,
    };
    let mode = Move::PathMode {
        line: 1,
        control: PathControl::Blend {
            tolerance_mm: Some(0.01),
            naive_cam_mm: None,
        },
    };
    let (a, b, c) = ([10.0, 0.0, 0.0], [10.0, 5e-7, 0.0], [10.0, 10.0, 0.0]);
    for mid in [a, b] {
        let ms = vec![
            mode.clone(),
            line([0.0; 3], a),
            line(a, mid),
            line(mid, c),
            line(c, [0.0, 10.0, 0.0]),
        ];
        let out = corners(&ms);
        // Only the corner at (10, 10) between two real legs is blended.
        assert_eq!(blends(&out).len(), 1, "{mid:?}");
        assert_eq!(blends(&out)[0].1[5][1], 10.0);
        assert_g2_joins(&out);
    }
}

#[test]
fn reversals_stop_exactly() {
    for turn in [180.0, 175.0] {
        let (text, _) = corner_program(turn, 10.0, 0.01);
        let ms = moves(&text);
        assert!(matches!(corners(&ms), Cow::Borrowed(_)), "{turn}°");
        let machine = Machine::default();
        let mut b = commands(&build(&ms, &machine));
        plan(&mut b, &machine, 1_000_000);
        assert_eq!(b[0].end_feed_mm_per_min, 0.0, "{turn}°: exact stop");
    }
    let (text, _) = corner_program(165.0, 10.0, 0.01);
    assert_eq!(blends(&blended(&text)).len(), 1);
}

#[test]
fn rapids_are_not_blended() {
    for text in [
        "G64 P0.01\nG0 X10\nY10\nM2\n",
        "G64 P0.01\nG0 X10\nG1 Y10 F3000\nM2\n",
        "G64 P0.01\nG1 X10 F3000\nG0 Y10\nM2\n",
    ] {
        assert!(blends(&blended(text)).is_empty(), "{text}");
    }
}

#[test]
fn non_planar_corners_in_3d() {
    let text = "G64 P0.05\nG1 X10 F2000\nY10\nZ10\nX0 Y0 Z0\nX5 Y1 Z-3\nM2\n";
    let ms = blended(text);
    let b = blends(&ms);
    assert_eq!(b.len(), 4);
    assert_g2_joins(&ms);
    let poly: Vec<[f64; 3]> = vec![
        [0.0; 3],
        [10.0, 0.0, 0.0],
        [10.0, 10.0, 0.0],
        [10.0, 10.0, 10.0],
        [0.0; 3],
        [5.0, 1.0, -3.0],
    ];
    for (k, (_, ctrl, _)) in b.iter().enumerate() {
        let corner = poly[k + 1];
        let (out, back) = deviations(ctrl, &poly[k..k + 3]);
        assert!(out <= 0.05 * (1.0 + 1e-9), "corner {k}: {out}");
        assert!(back <= 0.05 * (1.0 + 1e-9), "corner {k}: {back}");
        // Each blend lies in the plane of its two legs.
        let n = unit(cross(sub(corner, poly[k]), sub(poly[k + 2], corner)));
        for p in ctrl {
            assert!(dot(sub([p[0], p[1], p[2]], corner), n).abs() < 1e-12);
        }
    }
}

#[test]
fn the_planner_passes_a_blended_corner_without_stopping() {
    let machine = Machine::default();
    // Every corner blended (`corners`), whether or not the blend pays here (at 90° and
    // `P0.01` it does not: `corners_on` leaves it exact).
    let planned = |text: &str| {
        let mut b = commands(&build(&corners(&moves(text)), &machine));
        plan(&mut b, &machine, 1_000_000);
        b
    };
    let exact = planned("G61\nG1 X10 F3000\nY10\nM2\n");
    assert_eq!(exact[0].end_feed_mm_per_min, 0.0, "90° corner: exact stop");
    let b = planned("G64 P0.01\nG1 X10 F3000\nY10 F2000\nM2\n");
    let motion: Vec<_> = b
        .iter()
        .filter(|b| b.kind == BlockKind::Motion as u32)
        .collect();
    assert_eq!(motion.len(), 3);
    let (line, blend, next) = (motion[0], motion[1], motion[2]);
    assert_eq!(blend.degree, 5);
    assert_eq!(blend.source_line, 2);
    // The blend's curvature sets its cap, below both feeds; the junctions line→blend→line
    // are smooth: passed at that cap, not reduced as kinks.
    let cap = blend.feed_mm_per_min;
    assert!(cap > 0.0 && cap < 2000.0, "{cap}");
    assert!((line.end_feed_mm_per_min - cap).abs() < 1e-9 * cap);
    assert!((blend.end_feed_mm_per_min - cap).abs() < 1e-9 * cap);
    assert!((next.start_feed_mm_per_min - cap).abs() < 1e-9 * cap);
}

#[test]
fn the_blend_feed_is_the_lower_of_the_two() {
    let b = blends(&blended("G64 P0.01\nG1 X10 F3000\nY10 F1000\nM2\n"));
    assert_eq!(b[0].2, 1000.0);
    assert_eq!(b[0].0, 2);
}

#[test]
fn ratios_follow_the_table() {
    assert_eq!(ratios(0.0), (0.6, 0.15));
    assert_eq!(ratios(90.0), (0.616, 0.278));
    let (c1, c2) = ratios(95.0);
    assert!((c1 - 0.6265).abs() < 1e-12 && (c2 - 0.289).abs() < 1e-12);
    for d in 0..=170 {
        let (c1, c2) = ratios(d as f64);
        assert!(0.0 <= c2 && c2 < c1 && c1 < 1.0);
    }
}

/// The polygon of the README (`examples/cam-polygon.ngc`, 6° turns), its raster
/// (`examples/cam-zigzag.ngc`, 90° corners) and both in one program.
fn example(name: &str) -> String {
    std::fs::read_to_string(format!("{}/../examples/{name}", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

/// Exact path (`G61`) path-mode changes in a move list.
fn exact_marks(ms: &[Move]) -> usize {
    ms.iter()
        .filter(|m| {
            matches!(
                m,
                Move::PathMode {
                    control: PathControl::ExactPath,
                    ..
                }
            )
        })
        .count()
}

#[test]
fn blends_that_do_not_pay_are_left_exact_under_g61() {
    let machine = Machine::default();
    // 90° at P0.01 on the built-in machine: the blend would be passed at about 2 mm/s
    // over its whole length, slower than stopping exactly (README, path control).
    let zig = moves(&example("cam-zigzag.ngc"));
    let corners_in = plan_corners(&zig, None).iter().flatten().count();
    assert_eq!(corners_in, 39);
    let kept = corners_on(&zig, &machine);
    assert!(blends(&kept).is_empty());
    assert_eq!(exact_marks(&kept), corners_in);
    // Each line that ends at such a corner runs under G61, and the mode comes back.
    for w in kept.windows(3) {
        if let [Move::PathMode {
            control: PathControl::ExactPath,
            ..
        }, Move::Line { .. }, after] = w
        {
            assert!(matches!(
                after,
                Move::PathMode {
                    control: PathControl::Blend {
                        tolerance_mm: Some(_),
                        ..
                    },
                    ..
                }
            ));
        }
    }
    // The same lines, in the same order.
    let lines = |ms: &[Move]| -> Vec<Move> {
        ms.iter()
            .filter(|m| matches!(m, Move::Line { .. }))
            .cloned()
            .collect()
    };
    assert_eq!(lines(&kept), lines(&zig));
}

#[test]
fn blends_that_pay_are_kept() {
    // 6° turns at P0.01: passed far faster than the exact path's stops.
    for machine in [Machine::default(), linuxcnc()] {
        let poly = moves(&example("cam-polygon.ngc"));
        assert_eq!(corners_on(&poly, &machine), all_blended(&poly, &machine));
    }
}

/// Every eligible corner of `ms` blended, shaped for `machine` as [`corners_on`] shapes
/// them (what [`corners`] gives with the table's shapes).
fn all_blended(ms: &[Move], machine: &Machine) -> Vec<Move> {
    emit(ms, &eligible(ms, Some(normal_of(machine))).unwrap())
}

fn linuxcnc() -> Machine {
    Machine::from_toml(&example("machine-linuxcnc-sim.toml")).unwrap()
}

#[test]
fn the_choice_is_final() {
    // What `corners_on` returns, `corners` and `corners_on` return unchanged: the blends
    // it kept join lines to curves, and the corners it left exact run under G61.
    for machine in [Machine::default(), linuxcnc()] {
        for text in [
            example("cam-zigzag.ngc"),
            example("cam-polygon.ngc"),
            example("cam-circle.ngc"),
            "G64 P0.05\nG1 X10 F3000\nX20 Y1\nY10\nX19 Y12\nX0 F600\nG61\nY0\nG64 P0.2\nX-5\nY5\nM2\n".into(),
        ] {
            let ms = moves(&text);
            let once = corners_on(&ms, &machine).into_owned();
            assert_eq!(corners_on(&once, &machine), once);
            assert_eq!(corners(&once), once);
        }
    }
}

#[test]
fn a_blend_is_known_by_its_shape() {
    // Every blend `corners` makes, and not a programmed curve.
    let blended = corners(&moves("G64 P0.05\nG1 X10 F3000\nY10\nX0 Z3\nM2\n")).into_owned();
    let mut n = 0;
    for m in &blended {
        if let Move::Nurbs {
            degree,
            knots,
            ctrl,
            ..
        } = m
        {
            assert!(is_blend_shape(*degree, knots, ctrl));
            n += 1;
        }
    }
    assert_eq!(n, 2);
    let program = moves(
        "G1 F3000\nG5.2 P1 L6\nX1 Y2 P1\nX3 Y-1 P1\nX4 Y4 P1\nX6 Y0 P1\nX8 Y1 P1\nX9 Y3 P1\nG5.3\nM2\n",
    );
    let curve = program
        .iter()
        .find_map(|m| match m {
            Move::Nurbs {
                degree,
                knots,
                ctrl,
                ..
            } => Some((*degree, knots.clone(), ctrl.clone())),
            _ => None,
        })
        .unwrap();
    assert!(!is_blend_shape(curve.0, &curve.1, &curve.2));
}

/// The cycles a move list takes on `machine` at 1 ms, as `cnc check --estimate` steps it.
fn cycles(ms: &[Move], machine: &Machine) -> u64 {
    let mut blocks = build(ms, machine);
    plan(&mut blocks, machine, 1_000_000);
    crate::estimate::estimate(&commands(&blocks), machine, 1_000_000)
        .unwrap()
        .cycles
}

/// A zigzag of `n` lines of 0.5 mm turning 22.6° at `P0.01`, F3000 (no program end).
fn zigzag(n: u32) -> String {
    let mut text = String::from("G21 G90 G64 P0.01\nG1 F3000\n");
    for k in 1..=n {
        let y = if k % 2 == 1 { 0.1 } else { 0.0 };
        text += &format!("X{} Y{y}\n", f64::from(k) * 0.5);
    }
    text
}

#[test]
fn a_chain_of_close_corners_is_weighed_whole() {
    // A zigzag of 0.5 mm lines turning 22.6° at P0.01, F3000: one blend among exact stops
    // does not pay, the chain blended does. Weighed corner by corner (each with the
    // corners after it exact) every corner was left exact: 4.141 s here, against 2.528 s
    // blended.
    let text = zigzag(60) + "M2\n";
    let machine = Machine::default();
    let ms = moves(&text);
    let chosen = cycles(&corners_on(&ms, &machine), &machine);
    let blended = cycles(&corners(&ms), &machine);
    let exact = cycles(&moves(&text.replace("G64 P0.01", "G61")), &machine);
    assert!(
        chosen <= blended && chosen <= exact,
        "chosen {chosen} cycles, all blended {blended}, all exact {exact}"
    );
}

#[test]
fn a_corner_passed_at_the_feed_is_left_exact_without_weighing_the_blend() {
    // A polygon of 0.5° turns at F3000: the exact corner is passed at the feed, so the
    // screen leaves it exact (no blend can be quicker), and the choice costs what
    // planning two lines does.
    let mut text = String::from("G21 G90 G64 P0.01\nG1 X50 Y0 F3000\n");
    for k in 1..=200 {
        let a = (f64::from(k) * 0.5).to_radians();
        text += &format!("X{:.4} Y{:.4}\n", 50.0 * a.cos(), 50.0 * a.sin());
    }
    text += "M2\n";
    let machine = Machine::default();
    let ms = moves(&text);
    let plans = plan_corners(&ms, Some(normal_of(&machine)));
    for i in 2..190 {
        if plans[i].is_some() {
            assert_eq!(
                screen(&ms, &plans, i, &machine, 1_000_000),
                Some(false),
                "corner {i}"
            );
        }
    }
    chosen_no_slower_than_blended(&ms, &machine);
}

/// The corners [`corners_on`] chooses take no more cycles than every corner blended.
fn chosen_no_slower_than_blended(ms: &[Move], machine: &Machine) {
    chosen_within_of_blended(ms, machine, 0);
}

/// The corners [`corners_on`] chooses take at most `spare` cycles more than every corner
/// blended.
fn chosen_within_of_blended(ms: &[Move], machine: &Machine, spare: u64) {
    let chosen = cycles(&corners_on(ms, machine), machine);
    let blended = cycles(&all_blended(ms, machine), machine);
    assert!(
        chosen <= blended + spare,
        "chosen {chosen} cycles, all blended {blended}"
    );
}

#[test]
fn dense_chords_of_tiny_turns_are_left_exact_without_weighing_each_corner() {
    // CAM output of a circle of R40 in 0.08 mm chords (0.11° turns) at F3000: each
    // corner's kinks within two steps are passed at the feed as a run, so the screen
    // leaves every corner exact. Stepped both ways instead, each corner cost about
    // 95 µs of `cnc check` (a million such lines: 79 s). And exact is no slower than
    // blended: the run's direction change takes what it does at the lines' feed, not
    // the whole acceleration (reserved whole, exact took 9 % longer than blended on
    // LinuxCNC's limits).
    let mut text = String::from("G21 G90 G64 P0.01\nG1 X40 Y0 F3000\n");
    for k in 1..=600 {
        let a = f64::from(k) * 0.002;
        text += &format!("X{:.4} Y{:.4}\n", 40.0 * a.cos(), 40.0 * a.sin());
    }
    text += "M2\n";
    let ms = moves(&text);
    for machine in [Machine::default(), linuxcnc()] {
        let plans = plan_corners(&ms, Some(normal_of(&machine)));
        let mut open = 0;
        // (Not the first chords: the line in meets them at 90°, and the walk counts that
        // turn too while it is within reach.)
        for i in 8..ms.len() {
            if plans[i].is_some() {
                open += 1;
                assert_eq!(
                    screen(&ms, &plans, i, &machine, 1_000_000),
                    Some(false),
                    "corner {i}"
                );
            }
        }
        assert!(open > 550, "{open} corners weighed");
        // Exact is no slower than blended but where the machine speeds up from rest and
        // slows down to it at the ends: there the run's direction change takes a little
        // of the acceleration, which round blends do not. On LinuxCNC's limits, with the
        // blends shaped for them, that is 3 cycles of 1 878 (0.16 %); the screen leaves
        // such corners exact without weighing them (see `screen`).
        chosen_within_of_blended(&ms, &machine, 4);
    }
}

#[test]
fn the_kinks_within_two_steps_are_summed_up_to_a_rest() {
    // Lines of 0.1 mm turning about 1° each way at F3000 (50 mm/s), a dwell after the
    // fourth: the walk sums the turns within reach (the window at the feed) on either
    // side, widens it where a line there is faster, and stops at the dwell.
    let lines_of = |text: &str| {
        let ms = moves(text);
        let lines: Vec<usize> = (0..ms.len())
            .filter(|&k| matches!(ms[k], Move::Line { .. }))
            .collect();
        (ms, lines)
    };
    let text = "G21 G90 G64 P0.01\nG1 X0.1 F3000\nX0.2 Y0.0017\nX0.3 Y0.0017\n\
                X0.4 Y0.0052\nG4 P0.1\nX0.5 Y0.0052\nM2\n";
    let (ms, lines) = lines_of(text);
    let cos = |a: [f64; 2], b: [f64; 2]| {
        (a[0] * b[0] + a[1] * b[1]) / (a[0].hypot(a[1]) * b[0].hypot(b[1]))
    };
    let d = [[0.1, 0.0], [0.1, 0.0017], [0.1, 0.0], [0.1, 0.0035]];
    let turns: Vec<f64> = (0..3)
        .map(|k| cos(d[k], d[k + 1]).clamp(-1.0, 1.0).acos())
        .collect();
    let all: f64 = turns.iter().sum();
    let m = Machine::default();
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    // The corner at the end of the second line: within 3 ms at 50 mm/s (0.15 mm), its own
    // turn, the one 0.1 mm back and the one 0.1 mm on; within 1 ms, its own alone.
    let (i, next) = (lines[1], lines[2]);
    let near = turns_within(&ms, i, next, 3e-3, &m).unwrap();
    assert!(close(near, all), "{near} {turns:?}");
    let own = turns_within(&ms, i, next, 1e-3, &m).unwrap();
    assert!(close(own, turns[1]), "{own} {turns:?}");
    // Past the dwell nothing is summed, however far the reach.
    let far = turns_within(&ms, lines[2], lines[3], 1.0, &m).unwrap();
    assert!(close(far, all), "{far} {turns:?}");
    // A faster line within reach widens it: from the first corner, 1.5 ms at 50 mm/s
    // holds its own turn alone, at 150 mm/s (the first line at F9000, within the
    // built-in machine's highest feed) the third corner too.
    let first = turns_within(&ms, lines[0], lines[1], 1.5e-3, &m).unwrap();
    assert!(close(first, turns[0]), "{first} {turns:?}");
    let fast = text.replace("G1 X0.1 F3000\nX0.2", "G1 X0.1 F9000\nF3000 X0.2");
    let (ms, lines) = lines_of(&fast);
    assert!(m.max_feed_mm_per_min >= 9_000.0);
    let first = turns_within(&ms, lines[0], lines[1], 1.5e-3, &m).unwrap();
    assert!(close(first, all), "{first} {turns:?}");
}

/// A random unit direction in space and the same turned by `theta` (radians) towards
/// another random direction.
fn turned(next: &mut impl FnMut() -> f64, theta: f64) -> ([f64; 3], [f64; 3]) {
    let mut random = || unit([2.0 * next() - 1.0, 2.0 * next() - 1.0, 2.0 * next() - 1.0]);
    let (u1, w) = (random(), random());
    let across = unit(sub(w, u1.map(|x| x * dot(w, u1))));
    (
        u1,
        [0, 1, 2].map(|k| theta.cos() * u1[k] + theta.sin() * across[k]),
    )
}

#[test]
fn a_corner_surely_at_feed_is_planned_at_feed() {
    // `surely_at_feed` spares the screen planning the exact corner: wherever it says the
    // corner is passed at the feed, the two lines planned pass it at the feed. Random
    // directions in space, turns from 1e-4 rad to about 10°, feeds from a fiftieth of
    // the machine's highest to past it, tolerances 1 µm to 1 mm, on both machines.
    let mut next = crate::blocks::tests::uniforms(11);
    let mut sure = 0;
    let mut not_sure = 0;
    for machine in [Machine::default(), linuxcnc()] {
        let period_ns = decision_period(&machine);
        let period_s = period_ns as f64 * 1e-9;
        for _ in 0..1500 {
            let theta = 10f64.powf(-4.0 + 2.8 * next());
            let (u1, u2) = turned(&mut next, theta);
            let f = machine.max_feed_mm_per_min * (0.02 + 1.1 * next());
            let tol = 10f64.powf(-3.0 + 3.0 * next());
            let normal = Some(normal_of(&machine));
            let Some(c) = corner(u1.map(|x| -x), [0.0; 3], [0.0; 3], u2, tol, normal) else {
                continue;
            };
            let f = f.min(machine.max_feed_mm_per_min);
            if !surely_at_feed(&c, f / 60.0, &machine, period_s) {
                not_sure += 1;
                continue;
            }
            sure += 1;
            let v_e = exact_corner_speed(&c, f, &machine, period_ns);
            // (At the feed within its rounding: the planner's speeds go through mm/s.)
            assert!(
                v_e >= f * (1.0 - 1e-12),
                "turn {theta} rad at F{f}, tolerance {tol}: said at the feed, planned at F{v_e}"
            );
        }
    }
    assert!(sure > 1000 && not_sure > 300, "{sure} sure, {not_sure} not");
}

#[test]
fn a_chain_is_weighed_only_where_its_two_ways_differ() {
    // 100 lines of 1 mm; the ways differ at the corners after lines 10, 11 and 80.
    let segs: Vec<([f64; 3], [f64; 3], f64)> = (0..100)
        .map(|k| {
            (
                [f64::from(k), 0.0, 0.0],
                [f64::from(k + 1), 0.0, 0.0],
                3000.0,
            )
        })
        .collect();
    let c = corner(
        [0.0; 3],
        [1.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [2.0, 1.0, 0.0],
        0.01,
        None,
    );
    let a: Vec<Option<Corner>> = (0..100)
        .map(|k| c.filter(|_| k % 2 == 0 || k == 11))
        .collect();
    let mut b = a.clone();
    for k in [10, 11, 80] {
        b[k] = if a[k].is_some() { None } else { c };
    }
    let trims = vec![0.2; 100];
    let st = differing_stretches(&segs, &a, &b, &trims, 2.5);
    // Corners at 11, 12 (ends of lines 10, 11) joined: lines 8.5..14.5, that is 8 to 14,
    // the first kept for 0.5 mm, the last for 0.5 mm; and 78.5..83.5 about corner 81.
    assert_eq!(st.len(), 2, "{st:?}");
    assert_eq!((st[0].lo, st[0].hi), (8, 14));
    assert!((st[0].first_len - 0.5).abs() < 1e-12 && (st[0].last_len - 0.5).abs() < 1e-12);
    assert_eq!((st[1].lo, st[1].hi), (78, 83));
    // A cut never leaves less than the blend at the line's inner end takes (twice its
    // trim), and never more than the line.
    let st = differing_stretches(&segs, &a, &b, &vec![0.4; 100], 2.5);
    assert!((st[0].first_len - 0.8).abs() < 1e-12 && (st[0].last_len - 0.8).abs() < 1e-12);
    let st = differing_stretches(&segs, &a, &b, &vec![0.9; 100], 2.5);
    assert_eq!((st[0].first_len, st[0].last_len), (1.0, 1.0));
    // Where the ways are the same, nothing is weighed.
    assert!(differing_stretches(&segs, &a, &a, &trims, 2.5).is_empty());
}

#[test]
fn a_blends_speed_bound_is_no_lower_than_its_planned_cap() {
    // `blend_speed_bound` spares the screen planning a blend that clearly loses: its
    // speed may only be above the cap the planner gives the blend, its length only
    // below the blend's. Random corners in space, turns from 1e-4 rad to 170°, legs and
    // tolerances from 1 µm to 1 mm, feeds up to past the highest, both machines.
    let mut next = crate::blocks::tests::uniforms(5);
    let (mut n, mut binding, mut tightest) = (0, 0, 0.0f64);
    for machine in [Machine::default(), linuxcnc()] {
        let period_ns = decision_period(&machine);
        for _ in 0..400 {
            let theta = if next() < 0.5 {
                10f64.powf(-4.0 + 3.0 * next())
            } else {
                MAX_TURN_DEG.to_radians() * next()
            };
            let (u1, u2) = turned(&mut next, theta);
            let (l1, l2) = (
                10f64.powf(-3.0 + 4.0 * next()),
                10f64.powf(-3.0 + 4.0 * next()),
            );
            let tol = 10f64.powf(-3.0 + 3.0 * next());
            let Some(c) = corner(
                u1.map(|x| -x * l1),
                [0.0; 3],
                [0.0; 3],
                u2.map(|x| x * l2),
                tol,
                Some(normal_of(&machine)),
            ) else {
                continue;
            };
            let f = machine.max_feed_mm_per_min * (0.02 + 1.1 * next());
            let f = f.min(machine.max_feed_mm_per_min);
            let (v_up, len_down) = blend_speed_bound(&c, f / 60.0, &machine);
            let (cap, len) = blend_alone(&c, f, &machine, period_ns);
            assert!(
                cap / 60.0 <= v_up && len_down <= len,
                "turn {theta} rad, legs {l1} {l2}, tolerance {tol}, F{f}: bound {v_up} mm/s \
                 over {len_down} mm, planned {} mm/s over {len} mm",
                cap / 60.0
            );
            n += 1;
            if v_up < f / 60.0 {
                binding += 1;
                tightest = tightest.max(cap / 60.0 / v_up);
            }
        }
    }
    // (Not a bound that never binds: in most corners it is below the feed, and in some
    // the planned cap comes within 30 % of it: 0.79 of it in this stream at its closest,
    // 0.97 in another.)
    assert!(
        n > 600 && binding > n / 2 && tightest > 0.7,
        "{n} corners, {binding} bound, cap/bound up to {tightest}"
    );
}

#[test]
fn open_corners_close_together_are_weighed_as_one_cluster_when_asked() {
    // A zigzag whose corners the screen leaves open, each within the reach of the next,
    // then two corners 36 mm apart: weighed in clusters (how a way is timed before it is
    // planned), the zigzag's corners are blended or left exact together, none weighed
    // alone, and the two lone corners are each weighed alone. (The corner out of the
    // zigzag into the long line is in no cluster's stretch of the chain's stepping: it
    // is decided by its own, and was blended with the zigzag's only while a stretch also
    // decided the corner at the end of its last line, which it does not step.)
    let text = zigzag(40) + "X60 Y0\nX90 Y20\nX120 Y20\nM2\n";
    let ms = moves(&text);
    for machine in [Machine::default(), linuxcnc()] {
        let plans = plan_corners(&ms, Some(normal_of(&machine)));
        let period_ns = decision_period(&machine);
        let screened: Vec<Option<bool>> = (0..ms.len())
            .map(|i| screen(&ms, &plans, i, &machine, period_ns))
            .collect();
        let mut prev = vec![None; ms.len()];
        for (i, c) in plans.iter().enumerate() {
            if let Some(c) = c {
                prev[c.next] = Some(i);
            }
        }
        let open: Vec<usize> = (0..ms.len())
            .filter(|&i| plans[i].is_some() && screened[i].is_none())
            .collect();
        let beside: Vec<bool> = open
            .iter()
            .map(|&i| open_beside(&ms, &plans, &screened, &prev, i, &machine))
            .collect();
        // The lone corners (the last two open) have no open corner within their reach.
        assert!(open.len() >= 30, "{} corners left open", open.len());
        let n = beside.len();
        assert!(
            beside[..n - 2].iter().all(|b| *b) && !beside[n - 2] && !beside[n - 1],
            "{beside:?}"
        );
        let clustered = corners_weighed(&ms, &machine, Weighing::Clusters);
        let zigzag = &clustered[..clustered
            .iter()
            .position(|m| matches!(m, Move::Line { from, to, .. } if to[0] - from[0] > 10.0))
            .unwrap()];
        // The corners between the zigzag's own lines: not the one out of its last line into
        // the long line, which the chain's stepping weighs in a stretch of its own.
        let last = zigzag
            .iter()
            .rposition(|m| matches!(m, Move::Line { .. }))
            .unwrap();
        let mut inner = &zigzag[..last];
        while let [rest @ .., Move::PathMode { .. }] = inner {
            inner = rest;
        }
        let (blended, exact) = (blends(inner).len(), exact_marks(inner));
        assert!(
            blended + exact >= 38 && (blended == 0 || exact == 0),
            "{blended} blends and {exact} exact corners in one cluster"
        );
    }
}
