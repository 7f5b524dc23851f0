use super::*;
use crate::blocks::blend::cycles_of;
use crate::program::interpret;

fn example(name: &str) -> String {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../examples")
        .join(name);
    std::fs::read_to_string(path).unwrap()
}

fn linuxcnc() -> Machine {
    Machine::from_toml(&example("machine-linuxcnc-sim.toml")).unwrap()
}

/// An arc of radius `r` about (50, 50) in `n` chords of `chord` mm, its vertices
/// rounded to µm as a CAM post writes them, under `mode`, at `feed`.
fn dense_arc(r: f64, chord: f64, n: usize, feed: u32, mode: &str) -> String {
    let mut text = format!(
        "G21 G90 G17 {mode}\nG0 X{:.3} Y50 Z0\nG1 F{feed}\n",
        50.0 + r
    );
    for i in 1..=n {
        let a = i as f64 * chord / r;
        text += &format!("X{:.3} Y{:.3}\n", 50.0 + r * a.cos(), 50.0 + r * a.sin());
    }
    text + "M2\n"
}

/// The cycles a move list takes on `machine` at 1 ms, as `cnc check --estimate` steps it.
fn cycles(ms: &[Move], machine: &Machine) -> u64 {
    cycles_of(ms, machine, 1_000_000).unwrap()
}

fn lines(ms: &[Move]) -> Vec<([f64; 3], [f64; 3], u32, f64)> {
    ms.iter()
        .filter_map(|m| match m {
            Move::Line {
                line,
                from,
                to,
                rapid: false,
                feed,
            } => Some((*from, *to, *line, *feed)),
            _ => None,
        })
        .collect()
}

#[test]
fn dense_cam_chords_are_merged_within_q_where_that_is_quicker() {
    // R20 in 0.05 mm chords rounded to 1 µm at F6000 on LinuxCNC's limits: followed
    // chord by chord, the rounding's kinks hold the feed down (6.437 s for the whole
    // circle, LinuxCNC 2.383 s); merged within `Q` = `P` as LinuxCNC merges (2.342 s),
    // or smoothed, at the feed.
    let machine = linuxcnc();
    let text = dense_arc(20.0, 0.05, 800, 6000, "G64 P0.01");
    let moves = interpret(&text).unwrap().moves;
    let merged = merge(moves.clone(), &machine);
    let before = lines(&moves);
    let after: Vec<([f64; 3], [f64; 3], u32, bool)> = merged
        .iter()
        .filter_map(|m| match m {
            Move::Line {
                from,
                to,
                line,
                rapid: false,
                ..
            } => Some((*from, *to, *line, true)),
            Move::Nurbs { ctrl, line, .. } => {
                let (a, z) = (ctrl[0], ctrl[ctrl.len() - 1]);
                Some(([a[0], a[1], a[2]], [z[0], z[1], z[2]], *line, false))
            }
            _ => None,
        })
        .collect();
    assert!(
        after.len() * 10 < before.len(),
        "{} of {} moves",
        after.len(),
        before.len()
    );
    let (slow, quick) = (cycles(&moves, &machine), cycles(&merged, &machine));
    assert!(quick * 5 < slow * 3, "{quick} cycles merged, {slow} not");
    // Each merged line or smoothed piece runs from one programmed vertex to another,
    // replaces at most 101 moves and carries the last one's number; a line passes
    // within `Q` of every vertex between (tolerance: `Q` itself, 0.01 mm, plus 1e-12 mm
    // of rounding; the pieces' own test is the next).
    let mut k = 0;
    for (from, to, line, straight) in &after {
        assert_eq!(*from, before[k].0);
        let skipped = before[k..].iter().position(|b| b.1 == *to).unwrap();
        assert_eq!(*line, before[k + skipped].2);
        assert!(skipped < MAX_POINTS);
        if *straight {
            for b in &before[k..k + skipped] {
                assert!(off_segment(b.1, *from, *to) <= 0.01 + 1e-12);
            }
        }
        k += skipped + 1;
    }
    assert_eq!(k, before.len());
}

#[test]
fn q0_a_bare_g64_and_g61_merge_nothing() {
    let machine = linuxcnc();
    for mode in ["G64 P0.01 Q0", "G64", "G64 P0", "G61", "G61.1"] {
        let moves = interpret(&dense_arc(20.0, 0.05, 300, 6000, mode))
            .unwrap()
            .moves;
        assert_eq!(merge(moves.clone(), &machine), moves, "{mode}");
    }
    // `Q` is `P` without a `Q` (LinuxCNC's `convert_control_mode`), in the program's
    // units.
    let mode = |text: &str| {
        let moves = interpret(text).unwrap().moves;
        match moves.iter().rev().find(|m| is_mode(m)) {
            Some(Move::PathMode { control, .. }) => tolerance(control),
            m => panic!("{m:?}"),
        }
    };
    assert_eq!(mode("G64 P0.01\n"), Some(0.01));
    assert_eq!(mode("G64 P0.01 Q0.002\n"), Some(0.002));
    assert_eq!(mode("G64 P0 Q0.002\n"), Some(0.002));
    assert_eq!(mode("G64 P0.01 Q0\n"), None);
    assert!(mode("G20 G64 P0.001\n").is_some_and(|q| (q - 0.0254).abs() < 1e-15));
    // And `Q` merges within itself where it is given.
    let moves = interpret(&dense_arc(20.0, 0.05, 300, 6000, "G64 P0.01 Q0.005"))
        .unwrap()
        .moves;
    let merged = lines(&merge(moves.clone(), &machine));
    assert!(merged.len() < lines(&moves).len());
}

#[test]
fn a_feed_change_a_rapid_a_dwell_and_a_mode_change_end_a_run() {
    // Collinear chords, all within any Q of one line: merged but for what ends a run.
    let machine = linuxcnc();
    let mut text = String::from("G21 G90 G17 G64 P0.01\nG1 F3000\n");
    let mut x = 0.0;
    let mut step = |text: &mut String, extra: &str| {
        x += 0.05;
        *text += &format!("X{x:.2}{extra}\n");
    };
    for _ in 0..5 {
        step(&mut text, "");
    }
    step(&mut text, " F2000");
    for _ in 0..5 {
        step(&mut text, "");
    }
    text += "G4 P0.1\n";
    for _ in 0..5 {
        step(&mut text, "");
    }
    text += "G64 P0.02\n";
    for _ in 0..5 {
        step(&mut text, "");
    }
    text += "G0 X5\nM2\n";
    let moves = interpret(&text).unwrap().moves;
    let merged = merge(moves, &machine);
    let ends: Vec<(f64, u32, f64)> = lines(&merged).iter().map(|l| (l.1[0], l.2, l.3)).collect();
    // Lines 3-7 at F3000; 8 (F2000) starts the next run, to 13; the dwell on 14; 15-19;
    // the mode on 20; 21-25.
    let expect = [
        (0.25, 7, 3000.0),
        (0.55, 13, 2000.0),
        (0.8, 19, 2000.0),
        (1.05, 25, 2000.0),
    ];
    assert_eq!(ends.len(), expect.len(), "{ends:?}");
    for (got, want) in ends.iter().zip(expect) {
        assert!(
            (got.0 - want.0).abs() < 1e-9 && got.1 == want.1 && got.2 == want.2,
            "{ends:?}"
        );
    }
}

#[test]
fn a_run_joins_at_most_101_points() {
    let machine = linuxcnc();
    let mut text = String::from("G21 G90 G17 G64 P0.01\nG1 F3000\n");
    for i in 1..=250 {
        text += &format!("X{:.2}\n", i as f64 * 0.05);
    }
    text += "M2\n";
    let merged = lines(&merge(interpret(&text).unwrap().moves, &machine));
    let ends: Vec<f64> = merged.iter().map(|l| l.1[0]).collect();
    assert_eq!(ends.len(), 3, "{ends:?}");
    assert!((ends[0] - 101.0 * 0.05).abs() < 1e-9, "{ends:?}");
}

#[test]
fn how_the_moves_come_in_batches_does_not_change_the_merge() {
    let machine = linuxcnc();
    let moves = interpret(&dense_arc(20.0, 0.05, 1500, 6000, "G64 P0.01"))
        .unwrap()
        .moves;
    let whole = merge(moves.clone(), &machine);
    for every in [1, 7, 100, 1000] {
        let mut cam = NaiveCam::new(&machine);
        let mut out = Vec::new();
        for batch in moves.chunks(every) {
            out.extend(cam.take(batch.to_vec()));
        }
        out.extend(cam.finish());
        assert_eq!(out, whole, "batches of {every}");
    }
}

#[test]
fn where_merging_is_slower_the_chords_are_kept() {
    // R5 in 0.2 mm chords at F6000, P0.01, on the built-in machine (a jerk limit): the
    // merged lines' blends are slower than the chords' (1.731 s against 1.419 s for the
    // circle when every run was merged).
    let machine = Machine::default();
    let moves = interpret(&dense_arc(5.0, 0.2, 157, 6000, "G64 P0.01"))
        .unwrap()
        .moves;
    let merged = merge(moves.clone(), &machine);
    assert!(cycles(&merged, &machine) <= cycles(&moves, &machine));
    // Every run merged, by the tolerance alone: slower here.
    let forced = every_run_merged(&moves);
    assert!(cycles(&forced, &machine) > cycles(&moves, &machine));
}

/// `moves` with every run merged, as LinuxCNC merges them (no weighing).
fn every_run_merged(moves: &[Move]) -> Vec<Move> {
    let mut out = Vec::new();
    let mut run: Option<Run> = None;
    let q = 0.01;
    for m in moves {
        if let Move::Line {
            line,
            from,
            to,
            rapid: false,
            feed,
        } = m
        {
            if let Some(r) = &mut run {
                if r.end() == *from
                    && r.points.len() < MAX_POINTS
                    && r.points
                        .iter()
                        .all(|(p, _)| off_segment(*p, r.start, *to) <= q)
                {
                    r.points.push((*to, *line));
                    continue;
                }
                r.merged(&mut out);
            }
            run = Some(Run {
                start: *from,
                feed: *feed,
                points: vec![(*to, *line)],
            });
            continue;
        }
        if let Some(r) = run.take() {
            r.merged(&mut out);
        }
        out.push(m.clone());
    }
    out
}

/// The cubic pieces of `moves`, as Bézier control points.
fn pieces(moves: &[Move]) -> Vec<[[f64; 3]; 4]> {
    moves
        .iter()
        .filter_map(|m| match m {
            Move::Nurbs {
                degree: 3, ctrl, ..
            } if ctrl.len() == 4 => Some(std::array::from_fn(|k| {
                [ctrl[k][0], ctrl[k][1], ctrl[k][2]]
            })),
            _ => None,
        })
        .collect()
}

#[test]
fn smoothed_chords_stay_within_p_plus_q_both_ways_and_join_in_curvature() {
    // R20 in 0.05 mm chords at 1 µm, F6000, on the built-in machine (a jerk limit): the
    // merged lines' blends hold the feed down (2.868 s for the circle merged, 2.312 s
    // smoothed, 2.050 s as one G3), so stretches are smoothed.
    let machine = Machine::default();
    let text = dense_arc(20.0, 0.05, 1200, 6000, "G64 P0.01");
    let moves = interpret(&text).unwrap().moves;
    let out = merge(moves.clone(), &machine);
    let cubics = pieces(&out);
    assert!(cubics.len() > 10, "{} cubic pieces", cubics.len());
    let chosen = cycles(&out, &machine);
    assert!(chosen < cycles(&every_run_merged(&moves), &machine));
    assert!(chosen * 10 < cycles(&moves, &machine) * 7);
    // Independently of the certificate: each piece, at 2 000 samples (under 1 µm
    // apart), against every chord it replaces, and each of those chords, at 1 µm steps,
    // against every sample (tolerance `P + Q` = 0.02 mm, plus 1 µm of sampling).
    let chords = lines(&moves);
    let mut checked = 0;
    for b in &cubics {
        let k0 = chords.iter().position(|c| c.0 == b[0]).unwrap();
        let k1 = chords.iter().position(|c| c.1 == b[3]).unwrap();
        let run = &chords[k0..=k1];
        let curve: Vec<[f64; 3]> = (0..=2000)
            .map(|k| de_casteljau(*b, k as f64 / 2000.0))
            .collect();
        for x in &curve {
            let d = run
                .iter()
                .map(|c| off_segment(*x, c.0, c.1))
                .fold(f64::INFINITY, f64::min);
            assert!(d <= 0.02 + 1e-3, "a piece strays {d} mm");
        }
        for c in run {
            for j in 0..=50 {
                let t = j as f64 / 50.0;
                let x: [f64; 3] = std::array::from_fn(|i| c.0[i] + t * (c.1[i] - c.0[i]));
                let d = curve
                    .iter()
                    .map(|s| norm(sub(*s, x)))
                    .fold(f64::INFINITY, f64::min);
                assert!(d <= 0.02 + 1e-3, "a chord lies {d} mm from its piece");
            }
        }
        checked += run.len();
    }
    assert!(checked > 600, "{checked} chords smoothed");
    // One piece into the next: the same point and tangent (relative 1e-9); and, but
    // where one stretch ends and the next begins, the same curvature (a C2 spline).
    let mut jumps = 0;
    for w in cubics.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if a[3] != b[0] {
            continue;
        }
        let (la, lb) = (norm(sub(a[3], a[0])), norm(sub(b[3], b[0])));
        let (ta, tb) = (sub(a[3], a[2]), sub(b[1], b[0]));
        let (na, nb) = (norm(ta), norm(tb));
        for x in 0..3 {
            assert!((ta[x] / na - tb[x] / nb).abs() < 1e-9, "tangent");
        }
        let c2 = (0..3).all(|x| {
            let dda = (a[3][x] - 2.0 * a[2][x] + a[1][x]) / (la * la);
            let ddb = (b[2][x] - 2.0 * b[1][x] + b[0][x]) / (lb * lb);
            (dda - ddb).abs() < 1e-9 * (1.0 + dda.abs())
        });
        jumps += usize::from(!c2);
    }
    assert!(
        jumps * 5 <= cubics.len(),
        "{jumps} curvature jumps in {} pieces",
        cubics.len()
    );
}

#[test]
fn a_polygon_of_chords_that_merge_nothing_is_smoothed_where_that_is_quicker() {
    // `examples/cam-circle.ngc`: Ø20 in 100 chords of 0.63 mm, `G64 P0.01`, F3000. No
    // two chords merge within 0.01 mm; on the built-in machine the spline through the
    // vertices (within 5 µm of the chords) is quicker than the blended chords (1.405 s
    // against 1.708 s).
    let machine = Machine::default();
    let moves = interpret(&example("cam-circle.ngc")).unwrap().moves;
    let out = merge(moves.clone(), &machine);
    assert!(pieces(&out).len() > 50, "{} pieces", pieces(&out).len());
    let (before, after) = (cycles(&moves, &machine), cycles(&out, &machine));
    assert!(after * 100 < before * 90, "{after} cycles against {before}");
}

#[test]
fn the_machinist_is_told_where_moves_were_merged_or_smoothed() {
    let machine = linuxcnc();
    let told = |mode: &str| {
        let moves = interpret(&dense_arc(20.0, 0.05, 800, 6000, mode))
            .unwrap()
            .moves;
        let mut cam = NaiveCam::new(&machine);
        let _ = cam.take(moves);
        let _ = cam.finish();
        cam.note()
    };
    // The first chord is line 4 (after the mode, the rapid and the feed).
    let (line, text) = told("G64 P0.01").unwrap();
    assert_eq!(line, 4);
    assert!(
        text.contains("800 short moves") && text.contains("(0.02 mm at most here)"),
        "{text}"
    );
    assert_eq!(told("G64 P0.01 Q0"), None);
}
