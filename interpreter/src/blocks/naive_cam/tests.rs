use super::*;
use crate::blocks::{build, commands, plan};
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
    let mut blocks = build(ms, machine);
    plan(&mut blocks, machine, 1_000_000);
    crate::estimate::estimate(&commands(&blocks), machine, 1_000_000)
        .unwrap()
        .cycles
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
    // circle, LinuxCNC 2.383 s); merged within `Q` = `P` as LinuxCNC merges, at the feed.
    let machine = linuxcnc();
    let text = dense_arc(20.0, 0.05, 800, 6000, "G64 P0.01");
    let moves = interpret(&text).unwrap().moves;
    let merged = merge(moves.clone(), &machine);
    let (before, after) = (lines(&moves), lines(&merged));
    assert!(
        after.len() * 10 < before.len(),
        "{} of {} lines",
        after.len(),
        before.len()
    );
    let (slow, quick) = (cycles(&moves, &machine), cycles(&merged, &machine));
    assert!(quick * 5 < slow * 3, "{quick} cycles merged, {slow} not");
    // Each merged line runs from one programmed vertex to another, carries the last
    // merged line's number, and passes within `Q` of every vertex between (tolerance:
    // `Q` itself, 0.01 mm, plus 1e-12 mm of rounding).
    let mut k = 0;
    for (from, to, line, _) in &after {
        assert_eq!(*from, before[k].0);
        let skipped = before[k..].iter().position(|b| b.1 == *to).unwrap();
        assert_eq!(*line, before[k + skipped].2);
        assert!(skipped < MAX_POINTS);
        for b in &before[k..k + skipped] {
            assert!(off_segment(b.1, *from, *to) <= 0.01 + 1e-12);
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
