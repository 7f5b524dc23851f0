use super::*;
use crate::blocks::commands;
use crate::program::Options;
use shared::protocol::CommandBlock;
use std::fmt::Write;
use std::path::{Path, PathBuf};

const PERIOD_NS: u64 = 1_000_000;

/// The blocks, the problems, the number of windows and the notes of a program.
type Outcome = (Vec<CommandBlock>, Vec<String>, usize, Vec<(u32, String)>);

/// The blocks and the problems of `text` read `every` moves at a time, and the number of
/// windows it was planned in.
fn planned(text: &str, opts: &Options, machine: &Machine, every: usize) -> Outcome {
    match planned_at(text, opts, machine, every) {
        (blocks, bad, Some((p, _))) => (blocks, bad, p.windows, p.notes),
        (blocks, bad, None) => (blocks, bad, 0, Vec::new()),
    }
}

/// `text` read, built, planned and checked whole, as before windows: the blocks, the
/// problems and the notes.
fn whole(
    text: &str,
    opts: &Options,
    machine: &Machine,
) -> (Vec<CommandBlock>, Vec<String>, Vec<(u32, String)>) {
    let opts = Options {
        offset_tolerance_mm: Some(machine.chord_tolerance_mm),
        blend_tolerance_mm: machine.blend_tolerance_mm,
        ..opts.clone()
    };
    let shown = |d: Vec<Diagnostic>| d.iter().map(|d| d.to_string()).collect::<Vec<_>>();
    let prog = match program::interpret_with(text, &opts) {
        Ok(p) => p,
        Err(d) => return (Vec::new(), shown(d), Vec::new()),
    };
    // (`G64 Q`'s merge runs on the moves as they are read, before any window.)
    let mut cam = blocks::naive_cam::NaiveCam::new(machine);
    let mut moves = cam.take(prog.moves.clone());
    moves.extend(cam.finish());
    let mut all = blocks::build(&moves, machine);
    blocks::plan(&mut all, machine, PERIOD_NS);
    let mut check = Checker::new(text, machine);
    for (i, b) in all.iter().enumerate() {
        check.block(i, b);
    }
    let bad = check.finish();
    if !bad.is_empty() {
        return (Vec::new(), shown(bad), Vec::new());
    }
    (commands(&all), Vec::new(), {
        let mut notes = crate::process::notes(&prog, machine);
        notes.extend(cam.note());
        notes
    })
}

/// `text` planned whole (as [`whole`]), in the smallest windows it can be, and in
/// batches of [`BATCH_MOVES`]: the same blocks bit for bit, the same problems and
/// notes. Returns the number of windows.
fn same_windowed(name: &str, text: &str, opts: &Options, machine: &Machine) -> usize {
    let (whole, whole_bad, whole_notes) = whole(text, opts, machine);
    let (batched, batched_bad, _, _) = planned(text, opts, machine, BATCH_MOVES);
    assert_eq!(whole_bad, batched_bad, "{name}: problems in batches");
    assert_eq!(whole.len(), batched.len(), "{name}: block count in batches");
    let (cut, cut_bad, windows, cut_notes) = planned(text, opts, machine, 1);
    assert_eq!(whole_bad, cut_bad, "{name}: problems");
    assert_eq!(whole_notes, cut_notes, "{name}: notes");
    assert_eq!(whole.len(), cut.len(), "{name}: block count");
    for (i, (a, b)) in whole.iter().zip(&cut).enumerate() {
        assert!(
            shared::cmdlog::same_bits(a, b),
            "{name}: block {i} (line {}) differs planned in windows:\n{a:?}\n{b:?}",
            a.source_line
        );
    }
    windows
}

fn programs(dir: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "ngc"))
        .collect();
    out.sort();
    out
}

fn machines() -> Vec<(&'static str, Machine)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let sim = shared::machine::load(Some(&root.join("examples/machine-linuxcnc-sim.toml")))
        .expect("LinuxCNC's machine");
    vec![("built-in", Machine::default()), ("linuxcnc-sim", sim)]
}

/// Every G-code program of the repository, on the built-in machine and LinuxCNC's: the
/// same planned in windows as whole. (Release build: about a minute in the debug one.)
#[test]
fn windows_plan_as_the_whole_program() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files = programs(&root.join("examples"));
    files.extend(programs(&root.join("tests/peers/linuxcnc")));
    assert!(files.len() > 20, "{files:?}");
    let mut cut_somewhere = 0;
    for (mname, machine) in machines() {
        for f in &files {
            let text = std::fs::read_to_string(f).unwrap();
            let opts = Options {
                subroutine_dirs: f.parent().map(Path::to_path_buf).into_iter().collect(),
                ..Options::default()
            };
            let name = format!("{} on {mname}", f.display());
            if same_windowed(&name, &text, &opts, &machine) > 1 {
                cut_somewhere += 1;
            }
        }
    }
    // Most are one smooth path from rest to rest; the CAM examples stop at corners.
    assert!(
        cut_somewhere >= 4,
        "{cut_somewhere} programs planned in windows"
    );
}

/// A program made to be cut everywhere it may and nowhere it may not: a raster with
/// corners, rapids, dwells, stops, `G61.1`, `G64 P` blends (whose corners must not be
/// cut), arcs and a curve next to corners, a Fanuc dwell in doubt, and compensation.
#[test]
fn each_kind_of_rest_is_cut_and_the_plan_stays_the_same() {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z0 F1200\n");
    for row in 0..6 {
        let y = row as f64 * 2.0;
        let (a, b) = if row % 2 == 0 {
            (0.0, 30.0)
        } else {
            (30.0, 0.0)
        };
        for k in 0..10 {
            let x = a + (b - a) * (k as f64 + 1.0) / 10.0;
            let _ = writeln!(s, "G1 X{x:.3} Y{y:.3} Z{:.3}", 0.1 * (k as f64).sin());
        }
        let _ = writeln!(s, "G1 Y{:.3}", y + 2.0);
        match row {
            1 => s.push_str("G4 P0.2\n"),
            2 => s.push_str("M0\n"),
            3 => s.push_str("G64 P0.05\n"),
            4 => s.push_str("G61.1\n"),
            5 => s.push_str("G61\nG2 X5 Y12 I2.5 J0\nG1 X40\n"),
            _ => {}
        }
    }
    s.push_str(
        "G0 Z5\nG0 X50 Y50\nG1 Z0\nG5.2 X50 Y50 P1 L3\nX52 Y53 P1\nX55 Y50 P1\nX60 Y50 P1\nG5.3\n",
    );
    s.push_str("G1 X70 Y50\nG1 X70 Y60\nG0 Z5\nM2\n");
    let mut total = 0;
    for (mname, machine) in machines() {
        let w = same_windowed(
            &format!("raster on {mname}"),
            &s,
            &Options::default(),
            &machine,
        );
        assert!(w >= 8, "{w} windows on {mname}");
        total += w;
    }
    assert!(total > 0);
    // Compensation holds its moves until its corners are known: cut only outside it.
    let comp = "G21 G90 G17\nG0 X0 Y0\nG1 F600\nG41.1 D2 X10 Y0\nG1 X20\nG1 Y10\nG1 X10\n\
                G40 X0 Y0\nG1 X5 Y-5\nG1 X0 Y-10\nM2\n";
    same_windowed(
        "compensated",
        comp,
        &Options::default(),
        &Machine::default(),
    );
    // A Fanuc dwell read before the dialect is known: the batch waits for it.
    let fanuc = "G21 G90\nG1 X10 F600\nG4 P500\nG1 X0\nG1 Y10\nG04 X1\nG1 X10\nM30\n";
    same_windowed(
        "fanuc dwell",
        fanuc,
        &Options::default(),
        &Machine::default(),
    );
}

/// A program with a problem far down is refused with the same problems read in windows,
/// and the windows before it are handed on (only while nothing is wrong).
#[test]
fn a_problem_far_down_is_found_the_same() {
    let mut s = String::from("G21 G90\nG1 F600\n");
    for i in 0..200 {
        let _ = writeln!(s, "G1 X{} Y{}", (i % 2) * 10, i);
    }
    s.push_str("G1 X1 Y1 Q\nG1 X100000\nM2\n");
    let (_, whole, _) = whole(&s, &Options::default(), &Machine::default());
    let (_, cut, ..) = planned(&s, &Options::default(), &Machine::default(), 1);
    assert!(!whole.is_empty());
    assert_eq!(whole, cut);
}

/// [`planned`] with the [`Planned`] it returned and the most blocks handed on at once:
/// on one thread, and with the reading and the windows after a rest on threads of their
/// own ([`Stream::spare_cores`]), which must give the same blocks bit for bit, the same
/// problems and the same figures.
fn planned_at(
    text: &str,
    opts: &Options,
    machine: &Machine,
    every: usize,
) -> (Vec<CommandBlock>, Vec<String>, Option<(Planned, usize)>) {
    let here = planned_way(text, opts, machine, every, false);
    let ahead = planned_way(text, opts, machine, every, true);
    assert_eq!(here.0.len(), ahead.0.len(), "blocks read ahead");
    for (a, b) in here.0.iter().zip(&ahead.0) {
        assert!(
            shared::cmdlog::same_bits(a, b),
            "block {} differs read ahead",
            a.seq
        );
    }
    assert_eq!(here.1, ahead.1, "problems read ahead");
    assert_eq!(
        format!("{:?}", here.2),
        format!("{:?}", ahead.2),
        "figures read ahead"
    );
    here
}

/// [`planned_at`] read one way.
fn planned_way(
    text: &str,
    opts: &Options,
    machine: &Machine,
    every: usize,
    spare_cores: bool,
) -> (Vec<CommandBlock>, Vec<String>, Option<(Planned, usize)>) {
    let mut all = Vec::new();
    let mut most = 0;
    let got = crate::process::check_streaming(
        text,
        opts,
        machine,
        PERIOD_NS,
        Stream {
            every,
            blocks: &mut |mut b, first| {
                // Read again from the start (a Fanuc program's dwell in doubt).
                if first == 0 {
                    all.clear();
                }
                // The windows follow each other, each numbered from the end of the one
                // before.
                assert_eq!(first, all.len(), "windows out of order");
                most = most.max(b.len());
                all.append(&mut b);
            },
            release: &mut |_, _| {},
            spare_cores,
        },
    );
    match got {
        Ok(p) => {
            assert_eq!(p.blocks, all.len());
            (commands(&all), Vec::new(), Some((p, most)))
        }
        Err(d) => (Vec::new(), d.iter().map(|d| d.to_string()).collect(), None),
    }
}

/// Each motion block starts where the one before ended.
fn continuous(blocks: &[CommandBlock]) {
    let mut at: Option<[f64; 3]> = None;
    for b in blocks {
        if b.kind != shared::protocol::BlockKind::Motion as u32 {
            continue;
        }
        let p = |c: [f64; 4]| [c[0] / c[3], c[1] / c[3], c[2] / c[3]];
        let (first, last) = (p(b.ctrl[0]), p(b.ctrl[b.n_ctrl as usize - 1]));
        if let Some(a) = at {
            let d = shared::path::norm([first[0] - a[0], first[1] - a[1], first[2] - a[2]]);
            assert!(
                d < 1e-9,
                "block {} starts {d} mm from where the one before ended",
                b.seq
            );
        }
        at = Some(last);
    }
}

/// A smooth spiral of `n` short lines at `feed`, after `head` (a path mode).
fn spiral(n: usize, head: &str) -> String {
    let mut s = format!("G21 G90 G17\nG0 X0 Y0 Z0\n{head}\nG1 F3000\n");
    for i in 1..=n {
        let t = i as f64 * 0.02;
        let r = 2.0 + 0.5 * t;
        let _ = writeln!(s, "G1 X{:.4} Y{:.4}", r * t.cos(), r * t.sin());
    }
    s.push_str("M2\n");
    s
}

/// `text` planned in windows of `moves` on `machine`, against the whole plan: the path
/// joins, and what [`Planned`] says, the most blocks handed on at once, how many blocks
/// differ from the whole plan's, and the machining time against the whole plan's.
struct AtSpeed {
    blocks: usize,
    at_speed: usize,
    rough: usize,
    short: usize,
    most: usize,
    differ: usize,
    time_ratio: f64,
}

fn at_speed(text: &str, machine: &Machine, moves: u32) -> AtSpeed {
    let mut m = machine.clone();
    m.plan_window_moves = moves;
    let (whole, whole_bad, _) = whole(text, &Options::default(), &m);
    let (cut, cut_bad, p) = planned_at(text, &Options::default(), &m, 1);
    assert_eq!(whole_bad, cut_bad);
    assert!(whole_bad.is_empty(), "{whole_bad:?}");
    let mut differ = whole.len().abs_diff(cut.len());
    for (a, b) in whole.iter().zip(&cut) {
        differ += usize::from(!shared::cmdlog::same_bits(a, b));
    }
    continuous(&cut);
    let t = |b: &[CommandBlock]| {
        crate::estimate::estimate(b, &m, PERIOD_NS)
            .expect("the estimate")
            .time_s
    };
    let (p, most) = p.expect("planned");
    AtSpeed {
        blocks: cut.len(),
        at_speed: p.at_speed,
        rough: p.rough_seams,
        short: p.short_windows,
        most,
        differ,
        time_ratio: t(&cut) / t(&whole),
    }
}

/// A stretch with no rest far longer than the plan window (a spiral of short lines,
/// each turning below the corner angle, or blended under `G64 P`) is planned a window
/// at a time, each cut at speed where the plan holds its junction's speed, before the
/// window's final braking: the blocks are the whole program's bit for bit. Where the
/// braking takes more moves than the window (3000 lines of 0.2 mm on the built-in
/// machine, whose jerk lets a block of 0.04 mm change its speed by 1.5 mm/min), the
/// window grows until it takes the braking in, up to `GROW_MAX` times: before, a seam
/// was taken inside the braking, each window slowed the next, and the plan of a window
/// of 64 moves was 7.7 % slower than the whole one (20 000 lines in windows of 512:
/// 16 %; of 64: 102 %).
#[test]
fn a_stretch_with_no_rest_is_cut_at_speed() {
    let g64 = spiral(3000, "G64");
    for (mname, machine) in machines() {
        let a = at_speed(&g64, &machine, 1000);
        assert!(a.at_speed >= 1, "{mname}: {} windows at speed", a.at_speed);
        assert!(
            a.most <= GROW_MAX * 1000,
            "{mname}: {} blocks at once",
            a.most
        );
        assert_eq!((a.rough, a.differ, a.short), (0, 0, 0), "{mname}");
    }
    let (_, builtin) = &machines()[0];
    let a = at_speed(&g64, builtin, 64);
    assert!(a.at_speed >= 1, "{} windows at speed", a.at_speed);
    // (The next window holds half a window beyond the last: at most two grown ones.)
    assert!(a.most <= 2 * GROW_MAX * 64, "{} blocks at once", a.most);
    assert_eq!((a.rough, a.differ), (0, 0), "the whole plan's blocks");
    assert_eq!(a.time_ratio, 1.0);
    // LinuxCNC's machine (no jerk limit) brakes within a few moves: its windows of 64
    // stay short.
    let (_, lcnc) = &machines()[1];
    let a = at_speed(&g64, lcnc, 64);
    assert!(a.at_speed >= 40, "{} windows at speed", a.at_speed);
    // (A seam keeps 64 moves before it to plan again: a window this short waits for
    // twice as many.)
    assert!(a.most <= 128, "{} blocks at once", a.most);
    assert_eq!((a.rough, a.differ, a.short), (0, 0, 0));
    // Blended corners: a seam only where two lines meet unblended. (`Q0`: the chords
    // are not merged, `blocks::naive_cam`.)
    let a = at_speed(&spiral(1500, "G64 P0.01 Q0"), lcnc, 256);
    assert!(a.blocks > 2000, "{} blocks: blends kept", a.blocks);
    assert!(a.at_speed >= 1, "{} windows at speed", a.at_speed);
    assert_eq!((a.rough, a.differ), (0, 0));
}

/// A contour gone over again and again with no rest (an O-word `repeat`): a seam is
/// chosen only where its move's start and line are its own among the moves read so
/// far, and a later pass may come back to it. The next window then does not look for
/// it (what it found could be the later pass) and plans again from the seam's move:
/// the path joins, the seam is rough, and the plan differs from the whole one only
/// there.
#[test]
fn a_pass_gone_over_again_is_never_taken_for_the_seam() {
    let mut s = String::from("G21 G90 G17\nG0 X2 Y0 Z0\nG64\nG1 F3000\no100 repeat [12]\n");
    for i in 1..=100 {
        let t = f64::from(i) * std::f64::consts::TAU / 100.0;
        let _ = writeln!(s, "G1 X{:.4} Y{:.4}", 2.0 * t.cos(), 2.0 * t.sin());
    }
    s.push_str("o100 endrepeat\nM2\n");
    let (_, machine) = &machines()[0];
    let a = at_speed(&s, machine, 64);
    assert!(a.at_speed >= 1, "{} at speed", a.at_speed);
    assert_eq!(a.rough, a.at_speed);
    assert!(a.differ <= 2 * a.at_speed, "{} blocks differ", a.differ);
}

/// Where the next window has not the seam's two blocks (its corner blended otherwise),
/// the moves are planned again from the seam's move: the blocks handed on start where
/// the last handed on ended, and the seam is counted rough.
/// Windows over `text` handing their blocks to `hand`, none planned at speed unless a
/// test plans it.
fn windows_of<'a, 'h>(
    text: &'a str,
    machine: &'a Machine,
    hand: &'h mut dyn FnMut(Vec<Block>, usize),
) -> Windows<'a, 'h> {
    Windows {
        at_speed_from: usize::MAX,
        ..Windows::new(text, machine, PERIOD_NS, hand)
    }
}

#[test]
fn a_seam_not_found_again_is_planned_from_its_move() {
    let text = spiral(400, "G64");
    let machine = Machine::default();
    let prog = program::interpret(&text).unwrap();
    let moves = prog.moves;
    let mut handed: Vec<Block> = Vec::new();
    let mut hand = |b: Vec<Block>, _| handed.extend(b);
    let mut w = windows_of(&text, &machine, &mut hand);
    // A seam whose blocks are nowhere (their line numbers are not the program's), at
    // the move of index 150.
    let Move::Line { from, .. } = moves[150].clone() else {
        panic!("{:?}", moves[150])
    };
    let ghost = blocks::Straight::new(99_999, from, from, false, 1000.0);
    w.seam = Some(Seam {
        before: Block::Straight(ghost),
        after: Block::Straight(ghost),
        move_at: 150,
        anchor: Anchor::Start,
    });
    w.plan(moves.clone());
    assert_eq!(w.rough_seams, 1);
    assert!(w.seam.is_none());
    drop(w);
    let Block::Straight(first) = &handed[0] else {
        panic!("{:?}", handed[0])
    };
    assert_eq!(
        first.from, from,
        "the first block starts at the seam's move"
    );
    let whole = {
        let mut b = blocks::build(&moves[150..], &machine);
        blocks::plan(&mut b, &machine, PERIOD_NS);
        b
    };
    assert_eq!(handed.len(), whole.len());
}

/// A chain of `n` cubic `G5.2` curves along a sine wave, each its own move, joined with
/// the same tangent (no rest, no straight move anywhere).
fn wave(n: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z0\nG64\nF3000\n");
    let y = |x: f64| (0.7 * x).sin();
    let dy = |x: f64| 0.7 * (0.7 * x).cos();
    for i in 0..n {
        let (x0, x1) = (i as f64 * 0.5, i as f64 * 0.5 + 0.5);
        let h = 0.5 / 3.0;
        let _ = writeln!(s, "G5.2 X{:.6} Y{:.6} P1 L4", x0 + h, y(x0) + h * dy(x0));
        let _ = writeln!(s, "X{:.6} Y{:.6} P1", x1 - h, y(x1) - h * dy(x1));
        let _ = writeln!(s, "X{:.6} Y{:.6} P1", x1, y(x1));
        s.push_str("G5.3\n");
    }
    s.push_str("M2\n");
    s
}

/// A zigzag of `n` lines turning 60° at each corner, every corner blended under
/// `G64 P0.05`: no two straight moves meet whole anywhere.
fn zigzag(n: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z0\nG64 P0.05\nG1 F3000\n");
    for i in 1..=n {
        let _ = writeln!(s, "G1 X{:.4} Y{:.4}", i as f64 * 0.3, (i % 2) as f64 * 0.2);
    }
    s.push_str("M2\n");
    s
}

/// Stretches with no rest where no two straight moves meet whole: a chain of curves
/// (each its own move, joined with the same tangent), and a zigzag whose every corner
/// `G64 P` blends (each line a blend of its corner with the next, cut where the next
/// blend starts). Each is cut at speed, at the start of a curve or on a line, a window
/// at a time, the blocks the whole program's bit for bit but where a seam is rough.
/// Before, either was held whole (one window of 801 and 1 002 blocks).
#[test]
fn a_long_curve_and_a_chain_of_blends_are_cut_at_speed() {
    for (mname, machine) in machines() {
        for (pname, text) in [("wave", wave(800)), ("zigzag", zigzag(1000))] {
            let a = at_speed(&text, &machine, 200);
            assert!(a.at_speed >= 4, "{mname} {pname}: {} at speed", a.at_speed);
            assert!(a.most <= 200, "{mname} {pname}: {} blocks at once", a.most);
            // Curves' share rounds may reach across a seam: a rough seam there plans a
            // few blocks otherwise (one of nine on the wave on the built-in machine, 22
            // blocks, 0.9997 of the time), still a plan of its own, the path joined.
            assert!(a.rough <= 1, "{mname} {pname}: {} rough seams", a.rough);
            assert!(a.differ == 0 || a.rough > 0, "{mname} {pname}");
            assert!(
                (a.time_ratio - 1.0).abs() < 1e-3,
                "{mname} {pname}: {} of the whole plan's time",
                a.time_ratio
            );
        }
    }
}

/// Where the next window has not the seam's two blocks and the seam lies on a line (a
/// blend starting inside it), the moves are planned again from the seam on: the line
/// from the seam's point, then the rest. The blocks handed on start there.
#[test]
fn a_seam_on_a_line_not_found_again_is_planned_from_its_point() {
    let text = zigzag(400);
    let machine = Machine::default();
    let moves = program::interpret(&text).unwrap().moves;
    let mut handed: Vec<Block> = Vec::new();
    let mut hand = |b: Vec<Block>, _| handed.extend(b);
    let mut w = windows_of(&text, &machine, &mut hand);
    // A seam a third of the way along the line of move 150, whose blocks are nowhere
    // (their line numbers are not the program's).
    let Move::Line { from, to, .. } = moves[150].clone() else {
        panic!("{:?}", moves[150])
    };
    let p = [0, 1, 2].map(|i| from[i] + (to[i] - from[i]) / 3.0);
    let ghost = Block::Straight(blocks::Straight::new(99_999, p, p, false, 1000.0));
    w.seam = Some(Seam {
        before: ghost.clone(),
        after: ghost,
        move_at: 150,
        anchor: Anchor::On,
    });
    w.plan(moves.clone());
    assert_eq!(w.rough_seams, 1);
    drop(w);
    assert_eq!(
        handed[0].ends().map(|e| e.0),
        Some(p),
        "the first block starts at the seam's point"
    );
    let mut rest = vec![mode_before(&moves, 150).unwrap()];
    let mut on = moves[150].clone();
    if let Move::Line { from, .. } = &mut on {
        *from = p;
    }
    rest.push(on);
    rest.extend_from_slice(&moves[151..]);
    let mut whole = blocks::build(&rest, &machine);
    blocks::plan(&mut whole, &machine, PERIOD_NS);
    let (a, b) = (commands(&handed), commands(&whole));
    assert_eq!(a.len(), b.len());
    assert!(a
        .iter()
        .zip(&b)
        .all(|(x, y)| shared::cmdlog::same_bits(x, y)));
}

/// The planning never waits for its helper: with a helper that claims the last window
/// of each group and never plans it (a thread put aside by a busy machine for as long as
/// the check runs), every window is still planned, on the planning's own thread, in
/// order, and the blocks are those planned without a helper. (A planning that waited
/// for the windows the helper claimed would never end.)
#[test]
fn the_planning_never_waits_for_its_helper() {
    let mut s = String::from("G21 G90 G17\nG1 F1200\n");
    for row in 0..200 {
        let y = row as f64;
        let _ = writeln!(
            s,
            "G1 X{} Y{y}\nG1 X{} Y{y}",
            row % 2 * 30,
            (row + 1) % 2 * 30
        );
    }
    s.push_str("M2\n");
    let machine = Machine::default();
    let moves = crate::program::interpret(&s).expect("a good program").moves;
    let plan = |stuck_helper: bool| {
        let mut all = Vec::new();
        let (tx, rx) = mpsc::channel::<Arc<Vec<Job>>>();
        let (claimed_tx, claimed_rx) = mpsc::channel::<()>();
        // The second window handed on (the first of the groups) is handed once the
        // helper has claimed the last window of the first group: the claim comes first,
        // whatever the scheduling.
        let mut handed = 0;
        let mut hand = |mut b: Vec<Block>, _| {
            handed += 1;
            if handed == 2 && stuck_helper {
                let wait = std::time::Duration::from_secs(60);
                claimed_rx.recv_timeout(wait).expect("the helper's claim");
            }
            all.append(&mut b)
        };
        let mut claimed = 0;
        std::thread::scope(|scope| {
            let stuck = scope.spawn(move || {
                let mut n = 0;
                for group in rx {
                    if group.last().is_some_and(Job::claim) {
                        n += 1;
                        let _ = claimed_tx.send(());
                    }
                }
                n
            });
            {
                let mut w = Windows::new(&s, &machine, PERIOD_NS, &mut hand);
                // (Without the helper, its channel closed at once.)
                w.helper = stuck_helper.then_some(Helper { jobs: tx });
                w.take(moves.clone());
                let rest = std::mem::take(&mut w.pending);
                w.plan(rest);
                assert!(w.windows > 100, "{} windows: too few for groups", w.windows);
            }
            claimed = stuck.join().expect("the stuck helper");
        });
        (commands(&all), claimed)
    };
    let ((alone, _), (stuck, claimed)) = (plan(false), plan(true));
    assert!(claimed > 0, "the helper claimed no window");
    assert_eq!(alone.len(), stuck.len());
    for (a, b) in alone.iter().zip(&stuck) {
        assert!(shared::cmdlog::same_bits(a, b), "block {} differs", a.seq);
    }
}
