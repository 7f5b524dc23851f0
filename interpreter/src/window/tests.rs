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
    let mut all = Vec::new();
    let mut seqs = Vec::new();
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
                    seqs.clear();
                }
                seqs.push((first, b.len()));
                all.append(&mut b);
            },
            release: &mut |_, _| {},
        },
    );
    // The windows follow each other, each numbered from the end of the one before.
    let mut next = 0;
    for (first, n) in &seqs {
        assert_eq!(*first, next, "windows out of order: {seqs:?}");
        next += n;
    }
    match got {
        Ok(p) => {
            assert_eq!(p.blocks, all.len());
            (commands(&all), Vec::new(), p.windows, p.notes)
        }
        Err(d) => (
            Vec::new(),
            d.iter().map(|d| d.to_string()).collect(),
            0,
            Vec::new(),
        ),
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
        ..opts.clone()
    };
    let shown = |d: Vec<Diagnostic>| d.iter().map(|d| d.to_string()).collect::<Vec<_>>();
    let prog = match program::interpret_with(text, &opts) {
        Ok(p) => p,
        Err(d) => return (Vec::new(), shown(d), Vec::new()),
    };
    let mut all = blocks::build(&prog.moves, machine);
    blocks::plan(&mut all, machine, PERIOD_NS);
    let mut check = Checker::new(text, machine);
    for (i, b) in all.iter().enumerate() {
        check.block(i, b);
    }
    let bad = check.finish();
    if !bad.is_empty() {
        return (Vec::new(), shown(bad), Vec::new());
    }
    (
        commands(&all),
        Vec::new(),
        crate::process::notes(&prog, machine),
    )
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
