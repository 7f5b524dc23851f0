//! The NC dialects (issue #5): Fanuc `G06.2` with its alarms, dialect detection and
//! forcing, LinuxCNC `G5`/`G5.1` splines, `G93` inverse time, path-control, spindle and
//! stop moves, long lines. Curves are checked against independent references: the
//! closed-form ellipse and Bézier, a de Boor evaluation written here from the file's
//! own numbers, lengths from fine polylines.

use interpreter::program::{
    interpret, interpret_with, Dialect, Move, Options, PathControl, SpindleDir, StopKind,
};

const NGC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ngc/");

fn fixture(name: &str) -> String {
    std::fs::read_to_string(format!("{NGC}{name}")).unwrap_or_else(|e| panic!("{name}: {e}"))
}

fn moves(text: &str) -> Vec<Move> {
    interpret(text).unwrap_or_else(|e| panic!("{e:?}")).moves
}

/// A program read in `dialect` (detected when none).
fn read_as(
    text: &str,
    dialect: Option<Dialect>,
) -> Result<interpreter::program::Program, Vec<interpreter::parse::Diagnostic>> {
    interpret_with(
        text,
        &Options {
            dialect,
            ..Options::default()
        },
    )
}

/// The errors of a program as `(line, col, "rule: message")`.
fn errors_as(text: &str, dialect: Option<Dialect>) -> Vec<(u32, u32, String)> {
    read_as(text, dialect)
        .expect_err("the program should be refused")
        .into_iter()
        .map(|d| (d.line, d.col, format!("{}: {}", d.rule, d.message)))
        .collect()
}

fn errors(text: &str) -> Vec<(u32, u32, String)> {
    errors_as(text, None)
}

/// A parsed curve: degree, knots, control points, feed, source line.
type Curve<'a> = (usize, &'a [f64], &'a [[f64; 4]], f64, u32);

fn curves(m: &[Move]) -> Vec<Curve<'_>> {
    m.iter()
        .filter_map(|m| match m {
            Move::Nurbs {
                degree,
                knots,
                ctrl,
                feed,
                line,
            } => Some((*degree, knots.as_slice(), ctrl.as_slice(), *feed, *line)),
            _ => None,
        })
        .collect()
}

/// A rational B-spline point by the textbook Cox–de Boor recursion, independent of the
/// crate's evaluators.
fn de_boor(degree: usize, knots: &[f64], ctrl: &[[f64; 4]], u: f64) -> [f64; 3] {
    fn basis(i: usize, p: usize, k: &[f64], u: f64, last: f64) -> f64 {
        if p == 0 {
            let inside = k[i] <= u && u < k[i + 1];
            // The end of the domain belongs to the last non-empty span.
            let at_end = u == last && k[i] < k[i + 1] && k[i + 1] == last;
            return f64::from(u8::from(inside || at_end));
        }
        let mut v = 0.0;
        if k[i + p] > k[i] {
            v += (u - k[i]) / (k[i + p] - k[i]) * basis(i, p - 1, k, u, last);
        }
        if k[i + p + 1] > k[i + 1] {
            v += (k[i + p + 1] - u) / (k[i + p + 1] - k[i + 1]) * basis(i + 1, p - 1, k, u, last);
        }
        v
    }
    let last = knots[knots.len() - 1];
    let (mut num, mut den) = ([0.0; 3], 0.0);
    for (i, c) in ctrl.iter().enumerate() {
        let b = basis(i, degree, knots, u, last) * c[3];
        for a in 0..3 {
            num[a] += b * c[a];
        }
        den += b;
    }
    num.map(|x| x / den)
}

fn samples(knots: &[f64], n: usize) -> impl Iterator<Item = f64> {
    let (lo, hi) = (knots[0], knots[knots.len() - 1]);
    (0..=n).map(move |i| lo + (hi - lo) * i as f64 / n as f64)
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

// ---------------------------------------------------------------- Fanuc G06.2

#[test]
fn fanuc_ellipse_is_the_exact_ellipse() {
    let prog = interpret(&fixture("fanuc_ellipse.ngc")).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(prog.dialect, Dialect::Fanuc);
    let c = curves(&prog.moves);
    assert_eq!(c.len(), 1);
    let (degree, knots, ctrl, feed, line) = c[0];
    assert_eq!((degree, line, feed), (2, 6, 1200.0));
    assert_eq!(knots.len(), ctrl.len() + 3);
    let (a, b) = (50.0, 30.0);
    let mut worst: f64 = 0.0;
    for u in samples(knots, 4000) {
        let p = de_boor(degree, knots, ctrl, u);
        // The curve is the unit circle scaled by (a, b): the nearest ellipse point in
        // that parametrisation is at the same angle.
        let theta = (p[1] / b).atan2(p[0] / a);
        let q = [a * theta.cos(), b * theta.sin(), -1.0];
        worst = worst.max(dist(p, q));
        // And the crate's own evaluator agrees with the textbook one.
        let fast = shared::nurbs::eval(degree, knots, ctrl, u).p;
        assert!(dist(fast, p) < 1e-9, "u={u}: {fast:?} vs {p:?}");
    }
    assert!(worst < 1e-9, "ellipse deviates by {worst} mm");
    // The line after G05 P0 starts where the curve ended.
    assert!(prog.moves.iter().any(|m| matches!(
        m,
        Move::Line { line: 19, from, to, .. } if dist(*from, [50.0, 0.0, -1.0]) < 1e-12 && to[0] == 60.0
    )));
}

#[test]
fn seed_004_table_as_printed_is_refused_like_a_control_would() {
    let e = errors(&fixture("seed004_table1.ngc"));
    assert_eq!(e.len(), 1, "{e:?}");
    let (line, col, msg) = &e[0];
    assert_eq!((*line, *col), (18, 1));
    assert!(
        msg.contains("13 knots for 12 control points of rank 5, expected 17"),
        "{msg}"
    );
    assert!(
        msg.contains("PS1004") && msg.contains("`G5 P0` came after 1 of the 5"),
        "{msg}"
    );
}

#[test]
fn seed_004_with_its_closing_knots_is_the_curve_in_the_file() {
    let text = fixture("seed004_fixed.ngc");
    let prog = interpret(&text).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(prog.dialect, Dialect::Fanuc);
    let c = curves(&prog.moves);
    let (degree, knots, ctrl, feed, _) = c[0];
    assert_eq!(
        (degree, ctrl.len(), knots.len(), feed),
        (4, 12, 17, 30000.0)
    );
    // Read the numbers back from the file independently of the interpreter.
    let mut file_ctrl = Vec::new();
    let mut file_knots = Vec::new();
    for l in text
        .lines()
        .filter(|l| l.starts_with('K') || l.starts_with("G06.2"))
    {
        let word = |c: char| {
            l.split_whitespace()
                .find_map(|w| w.strip_prefix(c))
                .map(|v| v.trim_end_matches('.').parse::<f64>().unwrap())
        };
        file_knots.push(word('K').unwrap());
        if let (Some(x), Some(y)) = (word('X'), word('Y')) {
            file_ctrl.push([x, y, 0.0, word('R').unwrap_or(1.0)]);
        }
    }
    assert_eq!(file_knots, knots);
    for u in samples(&file_knots, 500) {
        let want = de_boor(4, &file_knots, &file_ctrl, u);
        let got = shared::nurbs::eval(degree, knots, ctrl, u).p;
        assert!(dist(want, got) < 1e-9, "u={u}");
    }
    // A closed path around the origin, about the size the paper machined.
    let start = de_boor(4, &file_knots, &file_ctrl, 0.0);
    let end = de_boor(4, &file_knots, &file_ctrl, 8.0);
    assert!(dist(start, [0.0, -66.005, 0.0]) < 1e-12 && dist(end, start) < 1e-12);
}

#[test]
fn fanuc_3d_curve_default_rank_weight_and_modal_knots() {
    // Rank 4 by default, R 1 by default, Z moving, the first block without K takes the
    // next one's, and a second curve opens while G06.2 is modal.
    let m = moves(
        "G0 X1 Y2 Z3\nF500\nG06.2 X1 Y2 Z3\nK0 X2 Y2 Z4\nK0 X3 Y3 Z5\nK0 X4 Y2 Z6\nK1\nK1\nK1\nK1\n\
         P2 K0 X4 Y2 Z6\nK0 X5 Y5 Z5\nK1\nK1\nG1 X0\nM30\n",
    );
    let c = curves(&m);
    assert_eq!(c.len(), 2, "{m:?}");
    assert_eq!(c[0].0, 3);
    assert_eq!(c[0].1, &[0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0]);
    assert_eq!(c[0].2[0], [1.0, 2.0, 3.0, 1.0]);
    assert_eq!(c[0].2[3], [4.0, 2.0, 6.0, 1.0]);
    assert_eq!((c[1].0, c[1].2.len()), (1, 2));
    // Incremental: the first control point is zero travel, the others relative.
    let m =
        moves("G0 X1 Y2 Z3\nF500\nG91\nG06.2 P2 K0 X0 Y0 Z0\nK0 X1 Y0\nK0.5 X1 Y1 R2\nK1\nK1\n");
    let (_, knots, ctrl, _, _) = curves(&m)[0];
    assert_eq!(knots, &[0.0, 0.0, 0.5, 1.0, 1.0]);
    assert_eq!(
        ctrl,
        &[
            [1.0, 2.0, 3.0, 1.0],
            [2.0, 2.0, 3.0, 1.0],
            [3.0, 3.0, 3.0, 2.0]
        ]
    );
}

#[test]
fn fanuc_alarms_name_the_rule_the_number_and_the_place() {
    let cases: &[(&str, (u32, u32), &str)] = &[
        // knot missing on a control point block
        (
            "F100\nG06.2 P2 K0 X0 Y0\nX1 Y1\nK1 X2 Y0\nK1\nK1\n",
            (3, 1),
            "PS1002",
        ),
        // too few closing knots before another command
        (
            "F100\nG06.2 P3 K0 X0 Y0\nK0 X1 Y1\nK0 X2 Y0\nK1\nK1\nG1 X5\n",
            (7, 1),
            "PS1004",
        ),
        // no closing knot at all
        ("F100\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nM5\n", (4, 1), "PS1005"),
        // cutter compensation active
        (
            "F100\nG41\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK1\nK1\n",
            (3, 1),
            "PS1006",
        ),
        // inverse time active
        (
            "G93\nG06.2 P2 K0 X0 Y0 F1\nK0 X1 Y1\nK1\nK1\n",
            (2, 1),
            "PS1006",
        ),
        // start knots not repeated rank times (found at the first knot that differs)
        (
            "F100\nG06.2 P3 K0 X0 Y0\nK1 X1 Y1\nK2 X2 Y0\nK3\nK3\nK3\n",
            (3, 1),
            "PS1007",
        ),
        // end knots not repeated rank times
        (
            "F100\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK1 X2 Y0\nK1\nK2\n",
            (6, 1),
            "PS1007",
        ),
        // an inner knot repeated rank times
        (
            "F100\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK1 X2 Y0\nK1 X3 Y1\nK2\nK2\n",
            (7, 1),
            "PS1008",
        ),
        // first control point away from the current position
        (
            "F100\nG0 X1\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK1\nK1\n",
            (3, 13),
            "PS1009",
        ),
    ];
    for (text, at, alarm) in cases {
        let e = errors(text);
        let hit = e.iter().find(|e| e.2.contains(alarm));
        let Some((line, col, msg)) = hit else {
            panic!("{alarm} expected for {text:?}, got {e:?}");
        };
        assert_eq!((*line, *col), *at, "{alarm}: {msg}");
        assert!(msg.starts_with("G06.2: "), "{msg}");
    }
    // Rules whose alarm number the manuals at hand do not give: named without a number.
    let e = errors("F100\nG06.2 P11 K0 X0 Y0\n");
    assert_eq!((e[0].0, e[0].1), (2, 7));
    assert!(e[0].2.contains("rank P11 is out of range"), "{e:?}");
    let e = errors("F100\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK1 X2 Y0\nK0.5 X3 Y1\nK2\nK2\n");
    assert_eq!((e[0].0, e[0].1), (5, 1));
    assert!(e[0].2.contains("must not decrease"), "{e:?}");
    // Too many closing knots: the extra one is named, with the count the curve took.
    let e = errors("F100\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK1\nK1\nK1\n");
    assert_eq!((e[0].0, e[0].1), (6, 1));
    assert!(e[0].2.contains("take 4 knots"), "{e:?}");
    // G06.2 stays the motion after a curve: coordinates alone are a control point
    // without its knot.
    let e = errors("F100\nG06.2 P2 K0 X0 Y0\nK0 X1 Y1\nK1\nK1\nX5\n");
    assert_eq!((e[0].0, e[0].1), (6, 1));
    assert!(e[0].2.contains("PS1002"), "{e:?}");
}

#[test]
fn g05_switches_are_fanuc_and_checked() {
    let p = interpret("G05 P10000\nG1 X1 F100\nG05 P0\nG05.1 Q1\nG05.1 Q0\n").unwrap();
    assert_eq!(p.dialect, Dialect::Fanuc);
    let e = errors("G05 P3\n");
    assert!(e[0].2.contains("P10000"), "{e:?}");
}

// ---------------------------------------------------------------- dialects

#[test]
fn dialect_is_detected_forced_and_never_mixed() {
    let d = |t: &str| interpret(t).unwrap().dialect;
    assert_eq!(d("G1 X1 F100\n"), Dialect::LinuxCnc);
    assert_eq!(
        d("F100\nG5.2 P1 L3\nX1 Y1 P1\nX2 Y0 P1\nG5.3\n"),
        Dialect::LinuxCnc
    );
    assert_eq!(d("O1000\nG1 X1 F100\n"), Dialect::Fanuc);
    let forced = read_as("G1 X1 F100\n", Some(Dialect::Fanuc)).unwrap();
    assert_eq!(forced.dialect, Dialect::Fanuc);

    let e = errors("F100\nG5.2 P1 L3\nX1 Y1 P1\nX2 Y0 P1\nG5.3\nG05 P10000\n");
    assert_eq!((e[0].0, e[0].1), (6, 1));
    assert!(
        e[0].2.contains("line 2") && e[0].2.contains("G5.2"),
        "{e:?}"
    );

    let e = errors_as("F100\nG06.2 P2 K0 X0 Y0\n", Some(Dialect::LinuxCnc));
    assert!(
        e[0].2.contains("method Q") && e[0].2.contains("--dialect fanuc"),
        "{e:?}"
    );
    let e = errors_as("F100\nG5.2 X1 Y1 P1\nG5.3\n", Some(Dialect::Fanuc));
    assert_eq!((e[0].0, e[0].1), (2, 1));
    assert!(e[0].2.contains("--dialect linuxcnc"), "{e:?}");
    // The LinuxCNC peers stay LinuxCNC: a G6.2 with Q.
    assert_eq!(
        d("G0 X1 Y2\nF290\nG6.2 X1 Y2 R1 K0 P2 Q1\nX2 Y3 R1 K0\nG6.2 K1\nG6.2 K1\n"),
        Dialect::LinuxCnc
    );
}

// ---------------------------------------------------------------- LinuxCNC G5, G5.1

fn bezier(p: &[[f64; 2]], t: f64) -> [f64; 2] {
    let s = 1.0 - t;
    let w: Vec<f64> = match p.len() {
        3 => vec![s * s, 2.0 * s * t, t * t],
        _ => vec![s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t],
    };
    let mut out = [0.0; 2];
    for (c, wi) in p.iter().zip(w) {
        out[0] += wi * c[0];
        out[1] += wi * c[1];
    }
    out
}

#[test]
fn g5_and_g5_1_are_the_exact_bezier_curves() {
    let prog = interpret(&fixture("g5_splines.ngc")).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(prog.dialect, Dialect::LinuxCnc);
    let c = curves(&prog.moves);
    assert_eq!(c.len(), 3);
    // Control points by LinuxCNC's rule: start + IJ, end + PQ; the second G5 takes
    // I J = -(previous P Q), so the curves join with a common tangent.
    let expected: [&[[f64; 2]]; 3] = [
        &[[0.0, 0.0], [0.0, 3.0], [1.0, -2.0], [1.0, 1.0]],
        &[[1.0, 1.0], [1.0, 4.0], [2.0, -1.0], [2.0, 2.0]],
        &[[2.0, 2.0], [3.0, 2.0], [3.0, 3.0]],
    ];
    for ((degree, knots, ctrl, feed, _), want) in c.iter().zip(expected) {
        assert_eq!(*degree, want.len() - 1);
        assert_eq!(*feed, 600.0);
        assert!(ctrl.iter().all(|c| c[3] == 1.0 && c[2] == 0.0));
        for t in samples(knots, 200) {
            let got = shared::nurbs::eval(*degree, knots, ctrl, t).p;
            let b = bezier(want, t);
            assert!(
                dist(got, [b[0], b[1], 0.0]) < 1e-12,
                "t={t}: {got:?} vs {b:?}"
            );
        }
    }
}

#[test]
fn g5_rules_as_linuxcnc_states_them() {
    let e = errors("F100\nG5 P0 Q1 X1 Y1\n");
    assert!(e[0].2.contains("needs I and J"), "{e:?}");
    let e = errors("F100\nG5 I1 X1 Y1 P0 Q1\n");
    assert!(e[0].2.contains("both I and J"), "{e:?}");
    let e = errors("F100\nG5 I1 J0 X1 Y1\n");
    assert!(e[0].2.contains("P and Q"), "{e:?}");
    let e = errors("F100\nG18\nG5.1 I1 J1 X4 Z1\n");
    assert!(e[0].2.contains("XY plane"), "{e:?}");
    let e = errors("G5.1 I1 J1 X4 Y1\n");
    assert!(e[0].2.contains("feed"), "{e:?}");
    // G91: the end is relative, I J and P Q always are.
    let c = moves("F100\nG0 X1 Y1\nG91 G5.1 I1 J0 X2 Y2\n");
    let (_, _, ctrl, _, _) = curves(&c)[0];
    assert_eq!(ctrl[1], [2.0, 1.0, 0.0, 1.0]);
    assert_eq!(ctrl[2], [3.0, 3.0, 0.0, 1.0]);
}

// ---------------------------------------------------------------- G93

/// Length of a curve by a polyline of many chords (an independent reference).
fn polyline_length(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> f64 {
    let pts: Vec<[f64; 3]> = samples(knots, 20_000)
        .map(|u| de_boor(degree, knots, ctrl, u))
        .collect();
    pts.windows(2).map(|w| dist(w[0], w[1])).sum()
}

#[test]
fn g93_inverse_time_becomes_the_feed_that_takes_1_over_f_minutes() {
    let m = moves(
        "G21 G17\nG93 G1 X10 F2\nG2 X20 R5 F1\nG5 I0 J5 P0 Q5 X30 Y0 F4\nG0 X0\nG94 G1 Y1 F100\n",
    );
    let feeds: Vec<f64> = m
        .iter()
        .filter_map(|m| match m {
            Move::Line {
                feed, rapid: false, ..
            }
            | Move::Arc { feed, .. }
            | Move::Nurbs { feed, .. } => Some(*feed),
            _ => None,
        })
        .collect();
    // Line: 10 mm in 1/2 min.
    assert!((feeds[0] - 20.0).abs() < 1e-12);
    // Half circle of radius 5 in 1 min, as LinuxCNC's rs274 says (15.7080).
    assert!((feeds[1] - 5.0 * std::f64::consts::PI).abs() < 1e-12);
    // The cubic: its exact length in 1/4 min.
    let (degree, knots, ctrl, _, _) = curves(&m)[0];
    let len = polyline_length(degree, knots, ctrl);
    assert!((feeds[2] / 4.0 - len).abs() < 1e-6, "{} vs {len}", feeds[2]);
    // G94 again: an ordinary feed.
    assert_eq!(feeds[3], 100.0);
    // The rapid keeps no feed of its own.
    assert!(m
        .iter()
        .any(|m| matches!(m, Move::Line { rapid: true, feed, .. } if *feed == 0.0)));
}

#[test]
fn g93_needs_f_on_every_feed_move() {
    let e = errors("G93 G1 X10\n");
    assert_eq!((e[0].0, e[0].1), (1, 5));
    assert!(e[0].2.contains("F word missing"), "{e:?}");
    let e = errors("G93 G1 X10 F1\nX20\n");
    assert_eq!(e[0].0, 2);
    // Leaving G93 forgets its F, as LinuxCNC does.
    let e = errors("G93 G1 X10 F1\nG94 X20\n");
    assert!(e[0].2.contains("no feed rate"), "{e:?}");
}

// ---------------------------------------------------------------- modes, spindle, stops

#[test]
fn path_mode_spindle_and_stops_are_moves_in_program_order() {
    let m =
        moves("G64 P0.05 Q0.01\nM3 S12000\nG1 X1 F100\nG61\nM1\nG61.1 M5\nM0\nS500 M4\nG64\nM2\n");
    let kinds: Vec<String> = m
        .iter()
        .map(|m| match m {
            Move::PathMode { control, .. } => format!("{control:?}"),
            Move::Spindle { dir, rpm, .. } => format!("{dir:?} {rpm}"),
            Move::Stop { kind, .. } => format!("{kind:?}"),
            Move::Line { .. } => "line".into(),
            Move::End { .. } => "end".into(),
            other => format!("{other:?}"),
        })
        .collect();
    assert_eq!(
        kinds,
        [
            "Blend { tolerance_mm: Some(0.05), naive_cam_mm: Some(0.01) }",
            "Clockwise 12000",
            "line",
            "ExactPath",
            "OptionalPause",
            "Off 12000",
            "ExactStop",
            "Pause",
            "CounterClockwise 500",
            "Blend { tolerance_mm: None, naive_cam_mm: None }",
            "end",
        ]
    );
    assert!(matches!(
        m[1],
        Move::Spindle {
            line: 2,
            dir: SpindleDir::Clockwise,
            ..
        }
    ));
    assert!(m.contains(&Move::Stop {
        line: 7,
        kind: StopKind::Pause
    }));
    assert!(m.contains(&Move::PathMode {
        line: 4,
        control: PathControl::ExactPath
    }));
    // In inches, the tolerance is converted.
    let m = moves("G20 G64 P0.001\n");
    assert!(matches!(
        m[0],
        Move::PathMode { control: PathControl::Blend { tolerance_mm: Some(t), .. }, .. } if (t - 0.0254).abs() < 1e-15
    ));
    let e = errors("G64 P-1\n");
    assert_eq!((e[0].0, e[0].1), (1, 5));
}

#[test]
fn lines_longer_than_linuxcnc_reads_are_refused() {
    // rs274 2.9 reads lines of up to 252 characters and says "Command too long" after.
    let long = format!("G1 X1 F100 ({})\nG1 X2 F100\n", "x".repeat(300));
    let e = errors(&long);
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!((e[0].0, e[0].1), (1, 253));
    assert!(e[0].2.contains("252"), "{e:?}");
    let ok = format!("G1 X1 F100 ({})\n", "x".repeat(252 - 13));
    assert_eq!(ok.trim_end().len(), 252);
    assert!(interpret(&ok).is_ok());
    let over = format!("G1 X1 F100 ({})\n", "x".repeat(253 - 13));
    assert!(interpret(&over).is_err());
}

// ---------------------------------------------------------------- the command line

#[test]
fn cnc_check_says_the_dialect_and_honours_the_forced_one() {
    let cnc = env!("CARGO_BIN_EXE_cnc");
    let file = format!("{NGC}fanuc_ellipse.ngc");
    let out = std::process::Command::new(cnc)
        .args(["check", &file])
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("ok, fanuc dialect"), "{text}");
    let out = std::process::Command::new(cnc)
        .args(["check", "--dialect", "linuxcnc", &file])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let text = String::from_utf8_lossy(&out.stderr);
    assert!(
        text.contains(&format!("{file}:5:1: dialect: G05 P… is fanuc's")),
        "{text}"
    );
}

/// A fresh directory for one test's files.
fn temp_dir(test: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("cnc-subs-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    dir
}

fn write(dir: &std::path::Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).unwrap_or_else(|e| panic!("{name}: {e}"));
}

fn with_dirs(
    text: &str,
    dirs: &[&std::path::Path],
) -> Result<interpreter::program::Program, Vec<interpreter::parse::Diagnostic>> {
    interpret_with(
        text,
        &Options {
            subroutine_dirs: dirs.iter().map(|d| d.to_path_buf()).collect(),
            ..Options::default()
        },
    )
}

#[test]
fn subroutines_are_read_from_their_own_files() {
    let dir = temp_dir("found");
    // LinuxCNC lower-cases the name: o<Pocket> reads pocket.ngc.
    write(
        &dir,
        "pocket.ngc",
        "(a pocket)\no<pocket> sub\nG1 X#1 Y#2\no<corner> call\no<pocket> endsub\nM2\n%\n",
    );
    write(
        &dir,
        "corner.ngc",
        "o<corner> sub\nG1 X0 Y0\no<corner> endsub\n",
    );
    let p = with_dirs("G0 X1\nF100\no<Pocket> call [5] [6]\nG0 Z1\nM2\n", &[&dir])
        .unwrap_or_else(|e| panic!("{e:?}"));
    let ends: Vec<(u32, [f64; 3])> = p
        .moves
        .iter()
        .filter_map(|m| match m {
            Move::Line { line, to, .. } => Some((*line, *to)),
            _ => None,
        })
        .collect();
    // Moves made in a subroutine file carry the line of the call in the program.
    assert_eq!(
        ends,
        vec![
            (1, [1.0, 0.0, 0.0]),
            (3, [5.0, 6.0, 0.0]),
            (3, [0.0, 0.0, 0.0]),
            (4, [0.0, 0.0, 1.0]),
        ]
    );

    // A program that defines the subroutine itself does not read the file.
    let own = "F100\no<pocket> call [2]\nM2\no<pocket> sub\nG1 X#1\no<pocket> endsub\n";
    let p = with_dirs(own, &[&dir]).unwrap_or_else(|e| panic!("{e:?}"));
    assert!(matches!(
        p.moves[0],
        Move::Line {
            to: [2.0, 0.0, 0.0],
            ..
        }
    ));
}

#[test]
fn subroutine_path_directories_are_searched_in_order() {
    let (first, second) = (temp_dir("path1"), temp_dir("path2"));
    write(
        &second,
        "probe.ngc",
        "o<probe> sub\nG1 X7 F100\no<probe> endsub\n",
    );
    let p = with_dirs("o<probe> call\n", &[&first, &second]).unwrap_or_else(|e| panic!("{e:?}"));
    assert!(matches!(
        p.moves[0],
        Move::Line {
            to: [7.0, 0.0, 0.0],
            line: 1,
            ..
        }
    ));
    write(
        &first,
        "probe.ngc",
        "o<probe> sub\nG1 X3 F100\no<probe> endsub\n",
    );
    let p = with_dirs("o<probe> call\n", &[&first, &second]).unwrap_or_else(|e| panic!("{e:?}"));
    assert!(matches!(
        p.moves[0],
        Move::Line {
            to: [3.0, 0.0, 0.0],
            ..
        }
    ));
}

#[test]
fn errors_in_subroutine_files_name_the_file_and_its_line() {
    let dir = temp_dir("errors");
    write(
        &dir,
        "bad.ngc",
        "o<bad> sub\n\nG1 X[1/0] F100\no<bad> endsub\n",
    );
    write(
        &dir,
        "loose.ngc",
        "o<loose> sub\no2 endwhile\no<loose> endsub\n",
    );
    write(&dir, "other.ngc", "(no sub here)\nG1 X1\n");
    write(
        &dir,
        "deep.ngc",
        "o<deep> sub\no<deep> call\no<deep> endsub\n",
    );
    let text =
        "G0 X1\n  o<bad> call\no<missing> call\no<other> call\no<deep> call\no<loose> call\nM2\n";
    let e = with_dirs(text, &[&dir]).expect_err("refused");
    let shown = interpreter::process::format_diagnostics("main.ngc", &e);
    let bad = dir.join("bad.ngc").display().to_string();
    let deep = dir.join("deep.ngc").display().to_string();
    let loose = dir.join("loose.ngc").display().to_string();
    let lines: Vec<&str> = shown.lines().collect();
    assert!(
        lines.contains(
            &format!("{loose}:2:1: O-word: o2 endwhile does not match an open block").as_str()
        ),
        "{shown}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with(&format!("{bad}:3:")) && l.contains("expression")),
        "{shown}"
    );
    assert!(
        lines.iter().any(|l| l.starts_with("main.ngc:3:1: O-word: o<missing> call: no subroutine o<missing> in this file, and no missing.ngc in ")),
        "{shown}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("main.ngc:4:1: O-word: o<other> call: ")
                && l.ends_with("other.ngc does not define o<other> sub")),
        "{shown}"
    );
    // Endless recursion across files stops at the nesting limit, in the file.
    assert!(
        lines.contains(
            &format!("{deep}:2:1: O-word: subroutines nested more than 50 deep").as_str()
        ),
        "{shown}"
    );
    // A name that would leave the directories is refused, not looked up.
    let e = with_dirs("o<../deep> call\n", &[&dir]).expect_err("refused");
    assert!(e[0].message.contains("only letters, digits"), "{e:?}");
    // Without directories (the built-in demo, a program from memory) nothing is read.
    let e = errors("o<bad> call\n");
    assert_eq!(e[0].0, 1, "{e:?}");
    assert!(
        e[0].2.contains("no subroutine o<bad> in this file"),
        "{e:?}"
    );
}

/// Argument words that no code of their line uses are refused, as LinuxCNC's rs274ngc
/// refuses them (`check_other_codes`): `G1 X20 I5` is a slip for `G2`, not a line.
/// Messages and columns checked with `rs274 -g` (2.9), which names the same words.
#[test]
fn words_nothing_uses_are_refused_where_linuxcnc_refuses_them() {
    let head = "G21 G17 F100\nG1 X1\n";
    let first = |body: &str| {
        let e = errors(&format!("{head}{body}\nM2\n"));
        (e[0].0, e[0].1, e[0].2.clone())
    };
    // rs274: "I word with no G2, G3, G5, G5.1, G10, G33.1, G76, or G87 to use it"
    assert_eq!(
        first("G1 X20 I5"),
        (
            3,
            8,
            "word: I word with no G2, G3, G5 or G5.1 to use it".into()
        )
    );
    // A modal straight line takes no centre either (rs274: the same).
    assert_eq!(first("G1 X2\nJ1").0, 4);
    assert_eq!(
        first("G0 X2 K1").2,
        "word: K word with no G2 or G3 to use it"
    );
    // rs274: "R word with no g code that uses it"
    assert_eq!(
        first("G0 X2 R1"),
        (3, 7, "word: R word with no G2 or G3 to use it".into())
    );
    assert!(first("G1 X2 P1")
        .2
        .starts_with("word: P word with no G2, G3, G4, G5 or G64"));
    assert_eq!(
        first("G1 X2 Q1").2,
        "word: Q word with no G5 or G64 (G05.1 in Fanuc programs) to use it"
    );
    // G5.1 takes I and J only; L belongs to an open G5.2.
    assert_eq!(first("G5.1 X2 Y1 I1 J1 Q1").1, 18);
    assert_eq!(first("G1 X2 L3").2, "word: L word with no G5.2 to use it");
    // Words on a line without any motion: nothing uses them (rs274: the same).
    assert_eq!(first("P21 G90").1, 1);
    assert_eq!(first("G80 R1").1, 5);
    // Axis words with no motion are refused for that, not for the words beside them.
    assert!(errors("G80\nX1 R2\nM2\n")[0]
        .2
        .starts_with("modal: axis words without an active motion"),);
    // A bare G2 is an arc with neither a centre nor a radius (rs274: "R i j k words all
    // missing for arc").
    assert_eq!(first("G2").2, "arc: arc needs R or a centre (I and J)");
    // Every word where something uses it.
    let fine = "G21 G17 F100\nG1 X1\nG4 P0.5\nG64 P0.01 Q0.01\nG2 X3 Y0 R1\nG3 X1 Y0 I-1 J0 P2\n\
                G18 G2 X1 Z0 I1 K0\nG17 G5 X2 Y1 I0.5 J0 P0.5 Q0.5\nG5.1 X3 Y1 I0.5 J0\nM2\n";
    assert!(interpret(fine).is_ok(), "{:?}", interpret(fine).err());
}

/// An arc without axis words ends where it starts: in the centre form, `P` full circles
/// round the centre (LinuxCNC reads `G2 I5` so, and a lone `I5 J0` in arc mode too, as
/// another circle); in the radius form it is refused, a full circle having no centre
/// from `R`.
#[test]
fn an_arc_without_axis_words_is_a_full_circle_where_it_stands() {
    let m = moves("G21 G17 F100\nG1 X1 Y2 Z3\nG2 I5\nJ-2 P2\nG18 G3 K1\nM2\n");
    let arcs: Vec<_> = m
        .iter()
        .filter_map(|m| match m {
            Move::Arc {
                line,
                from,
                to,
                center,
                ccw,
                turns,
                ..
            } => Some((*line, *from, *to, *center, *ccw, *turns)),
            _ => None,
        })
        .collect();
    let p = [1.0, 2.0, 3.0];
    assert_eq!(
        arcs,
        [
            (3, p, p, [6.0, 2.0, 3.0], false, 1),
            (4, p, p, [1.0, 0.0, 3.0], false, 2),
            (5, p, p, [1.0, 2.0, 4.0], true, 1),
        ]
    );
    let e = errors("G21 G17 F100\nG1 X1\nG2 R5\nM2\n");
    assert_eq!(e[0].0, 3);
    assert!(
        e[0].2.contains("full circle needs the centre form"),
        "{e:?}"
    );
}

/// A full circle whose end is its start but for the last digit (`X10.000001` after
/// `X10`) is the programmed circle: its centre stays where `I J` put it (as `rs274`
/// prints it), the arc ends on it at the end's angle. The exact circle through both
/// points has its centre on the bisector of a 1.4 nm chord, which passes 3.5 mm from
/// the programmed centre: that would be another circle.
#[test]
fn a_full_circle_off_by_a_rounding_keeps_its_centre() {
    let m = moves("G21 G17 F100\nG0 X10 Y0\nG2 X10.000001 Y0.000001 I-5 J0 P2\nG1 X20\nM2\n");
    let (from, to, center, turns) = m
        .iter()
        .find_map(|m| match m {
            Move::Arc {
                from,
                to,
                center,
                turns,
                ..
            } => Some((*from, *to, *center, *turns)),
            _ => None,
        })
        .expect("an arc");
    assert_eq!(center, [5.0, 0.0, 0.0]);
    assert_eq!(turns, 2);
    // On the circle, and within the rounding of the programmed end.
    assert!((dist(to, center) - 5.0).abs() < 1e-12, "{to:?}");
    assert!(dist(to, [10.000001, 0.000001, 0.0]) < 1.5e-6, "{to:?}");
    assert_eq!(from, [10.0, 0.0, 0.0]);
    // The next move starts where the arc ends.
    let next = m.iter().find_map(|m| match m {
        Move::Line {
            from, rapid: false, ..
        } => Some(*from),
        _ => None,
    });
    assert_eq!(next, Some(to));
    // Arcs of ordinary chords still pass exactly through both programmed ends.
    let m = moves("G21 G17 F100\nG2 X10 Y0.0005 I5 J0\nM2\n");
    let Move::Arc { to, center, .. } = m[0] else {
        panic!("{m:?}")
    };
    assert_eq!(to, [10.0, 0.0005, 0.0]);
    assert!((dist(to, center) - dist([0.0; 3], center)).abs() < 1e-12);
}

/// `G4 P` is seconds in LinuxCNC and milliseconds in Fanuc (`G04 P500`: half a second,
/// not eight minutes); Fanuc's `G04 X` is seconds. A `G04 P` read before anything said
/// which dialect the program is takes the dialect the program turns out to be.
#[test]
fn a_dwell_lasts_what_its_dialect_says() {
    let dwells = |text: &str, dialect: Option<Dialect>| -> Vec<f64> {
        read_as(text, dialect)
            .unwrap_or_else(|e| panic!("{e:?}"))
            .moves
            .iter()
            .filter_map(|m| match m {
                Move::Dwell { seconds, .. } => Some(*seconds),
                _ => None,
            })
            .collect()
    };
    assert_eq!(dwells("G4 P0.5\nM2\n", None), [0.5]);
    assert_eq!(dwells("O1000\nG04 P500\nG04 X1.5\nM30\n", None), [0.5, 1.5]);
    assert_eq!(dwells("G04 P500\nM30\n", Some(Dialect::Fanuc)), [0.5]);
    // Fanuc found after the dwell (its G05 P10000), and LinuxCNC before it (G5.1).
    assert_eq!(
        dwells("G04 P250\nG05 P10000\nG1 X1 F100\nG05 P0\nM30\n", None),
        [0.25]
    );
    assert_eq!(dwells("F100\nG5.1 X1 Y1 I0.5 J0\nG4 P2\nM2\n", None), [2.0]);
    // `G04 X` is Fanuc's: refused in a program that is LinuxCNC's.
    let e = errors("F100\nG5.1 X1 Y1 I0.5 J0\nG04 X1\nM2\n");
    assert_eq!((e[0].0, e[0].1), (3, 5), "{e:?}");
    assert!(e[0].2.contains("G04 X"), "{e:?}");
    let e = errors("G4 P-1\nM2\n");
    assert_eq!(e[0].2, "G4: dwell time P must not be negative");
}

/// Issue #22: a LinuxCNC `G6.2` whose inner knot is repeated as often as the order is
/// two curves that need not meet (the run jumped 1.414 mm in one cycle); it is refused
/// at the knot that completes the run, as Fanuc's twin is (PS1008), whether the knot is
/// written out, computed, or read in a subroutine file. A knot repeated once less (a
/// corner) still reads, and so does a run of the order at the ends.
#[test]
fn g6_2_inner_knot_repeated_order_times_is_refused_at_that_knot() {
    let curve = |k: &str| {
        format!(
            "G1 F100\nG6.2 X0 Y0 R1 K0 P3 Q1\nX1 Y1 R1 K0\nX2 Y0 R1 K0\nX3 Y1 R1 K1\nX4 Y0 R1 {k}\nX5 Y1 R1 K1\nG6.2 K2\nG6.2 K2\nG6.2 K2\nM2\n"
        )
    };
    let e = errors(&curve("K1"));
    assert_eq!(e.len(), 1, "{e:?}");
    assert_eq!((e[0].0, e[0].1), (7, 10), "{e:?}");
    assert!(
        e[0].2
            .starts_with("G6.2: knot K1 is repeated 3 times inside the NURBS opened on line 2"),
        "{e:?}"
    );
    let e = errors(&curve("K[2/2]"));
    assert_eq!((e[0].0, e[0].1), (7, 10), "{e:?}");
    // Once less: a corner, one curve.
    let two = "G1 F100\nG6.2 X0 Y0 R1 K0 P3 Q1\nX1 Y1 R1 K0\nX2 Y0 R1 K0\nX3 Y1 R1 K1\nX4 Y0 R1 K1\nG6.2 K2\nG6.2 K2\nG6.2 K2\nM2\n";
    assert!(read_as(two, None).is_ok());
    // The order plus one at the start leaves the first control point out of the curve.
    let e =
        errors("G1 F100\nG6.2 X0 Y0 R1 K0 P2 Q1\nX1 Y1 R1 K0\nX2 Y0 R1 K0\nG6.2 K1\nG6.2 K1\nM2\n");
    assert_eq!((e[0].0, e[0].1), (4, 10), "{e:?}");
    assert!(e[0].2.contains("at an end"), "{e:?}");
    // A knot smaller than the one before it is named where it stands.
    let e =
        errors("G1 F100\nG6.2 X0 Y0 R1 K0 P2 Q1\nX1 Y1 R1 K2\nX2 Y0 R1 K1\nG6.2 K3\nG6.2 K3\nM2\n");
    assert_eq!((e[0].0, e[0].1), (4, 10), "{e:?}");
    assert!(e[0].2.contains("must not decrease"), "{e:?}");
    // In a subroutine file: named in that file, at its line.
    let dir = temp_dir("g62knot");
    write(
        &dir,
        "jump.ngc",
        "o<jump> sub\nG6.2 X0 Y0 R1 K0 P2 Q1\nX1 Y1 R1 K0\nX2 Y0 R1 K1\nX3 Y1 R1 K1\nG6.2 K2\nG6.2 K2\no<jump> endsub\n",
    );
    let e = with_dirs("G1 F100\no<jump> call\nM2\n", &[&dir]).expect_err("refused");
    let shown = interpreter::process::format_diagnostics("main.ngc", &e);
    let jump = dir.join("jump.ngc").display().to_string();
    assert!(
        shown.starts_with(&format!(
            "{jump}:5:10: G6.2: knot K1 is repeated 2 times inside"
        )),
        "{shown}"
    );
}
