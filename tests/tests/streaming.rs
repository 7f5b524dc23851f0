//! Long programs through the real stack (issue #25): read, planned and sent window by
//! window, every block sent once and in order, the run's time that of `cnc check
//! --estimate`, and the processes' memory bounded whatever the program's length.

use std::fmt::Write;
use std::path::Path;
use std::process::Command;
use tests::{cnc_exe, estimate_json, report, temp_dir};

/// A raster of `lines` lines of `G1` (rows of 200 short moves over a wavy Z, a 90°
/// turn at each row's ends: a window ends at each of them).
fn raster(lines: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z0 F1200\n");
    for i in 3..lines.saturating_sub(1) {
        let (row, col) = (i / 200, i % 200);
        let x = if row % 2 == 0 { col } else { 199 - col } as f64 * 0.5;
        let y = (row % 400) as f64 * 0.5;
        let z = -0.5 - 0.25 * (x * 0.1).sin() * (y * 0.07).cos();
        let _ = writeln!(s, "G1 X{x:.3} Y{y:.3} Z{z:.4}");
    }
    s.push_str("M2\n");
    s
}

/// `cnc check --estimate --json`'s cycles and `cnc check`'s block count.
fn checked(prog: &Path) -> (u64, u64) {
    let est = estimate_json(prog);
    let out = Command::new(cnc_exe())
        .arg("check")
        .arg(prog)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let blocks = text
        .split(", ")
        .find_map(|w| w.strip_suffix(" blocks\n").and_then(|n| n.parse().ok()))
        .unwrap_or_else(|| panic!("no block count in {text:?}"));
    (est["cycles"].as_u64().unwrap(), blocks)
}

/// Runs `prog` with the simulated clock; the run directory's report.
fn run_sim(prog: &Path, dir: &Path) -> serde_json::Value {
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--force", "--out"])
        .arg(dir)
        .arg(prog)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "the run failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    report(dir)
}

/// The run ended well, as long as `--estimate` said (`cycles`), every block sent.
fn ran_as_checked(rep: &serde_json::Value, cycles: u64, blocks: u64) {
    assert_eq!(rep["outcome"], "done", "{rep}");
    assert_eq!(
        rep["cycles"].as_u64(),
        Some(cycles),
        "run against --estimate"
    );
    assert_eq!(rep["blocks"].as_u64(), Some(blocks), "{rep}");
}

/// The most resident memory (MiB) `report.json` saw `role` use.
fn max_mib(rep: &serde_json::Value, role: &str) -> f64 {
    rep["memory"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["role"] == role)
        .unwrap_or_else(|| panic!("no memory of {role}: {}", rep["memory"]))["max_kib"]
        .as_u64()
        .unwrap() as f64
        / 1024.0
}

/// 30 000 lines (150 windows) through the stack: every block sent once, in order, and
/// logged; the run as long as the estimate, to the cycle.
#[test]
fn a_program_of_many_windows_runs_whole_and_in_order() {
    let dir = temp_dir("stream-30k");
    let prog = dir.join("raster.ngc");
    std::fs::write(&prog, raster(30_000)).unwrap();
    let (cycles, blocks) = checked(&prog);
    let rep = run_sim(&prog, &dir.join("run"));
    ran_as_checked(&rep, cycles, blocks);
    let log = shared::cmdlog::read(&dir.join("run/commands.log")).unwrap();
    assert_eq!(log.blocks.len() as u64, blocks);
    for (i, b) in log.blocks.iter().enumerate() {
        assert_eq!(b.seq, i as u64, "block {i} of the log");
    }
    assert_eq!(rep["starvations"].as_u64(), Some(0), "{rep}");
    // Sent on the launcher's check, not checked twice (`interpreter::checked`).
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run/interpreter.json")).unwrap())
            .unwrap();
    assert_eq!(summary["checked_by"], "launcher", "{summary:#}");
}

/// A million lines through the stack (about 2.5 minutes here, release build):
///
/// ```sh
/// cargo test --release -p tests --test streaming -- --ignored --nocapture
/// ```
///
/// The interpreter, the interpolator and the servo-sim each stay under 100 MB resident.
/// (The launcher is not held to it: after the run it folds the traces into the report,
/// which still reads them whole.)
#[test]
#[ignore]
fn a_million_lines_run_in_bounded_memory() {
    let dir = temp_dir("stream-1m");
    let prog = dir.join("raster.ngc");
    std::fs::write(&prog, raster(1_000_000)).unwrap();
    let (cycles, blocks) = checked(&prog);
    let rep = run_sim(&prog, &dir.join("run"));
    ran_as_checked(&rep, cycles, blocks);
    for role in ["interpreter", "interpolator", "servo-sim"] {
        let mib = max_mib(&rep, role);
        println!("{role}: {mib:.1} MiB at most");
        assert!(mib < 100.0, "{role} used {mib:.1} MiB");
    }
}

/// 8 000 short lines of one smooth spiral with no rest between them, run with a plan
/// window of 1 000 moves (cut at speed, 8 to 10 times) and with one holding the whole
/// program: the same blocks logged and the same set-points, bit for bit, and the run
/// as long as the estimate.
#[test]
fn a_stretch_with_no_rest_runs_cut_at_speed_as_planned_whole() {
    let dir = temp_dir("stream-at-speed");
    let prog = dir.join("spiral.ngc");
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z0\nG64\nG1 F3000\n");
    for i in 1..=8000 {
        let t = f64::from(i) * 0.015;
        let r = 3.0 + 0.4 * t;
        let _ = writeln!(
            s,
            "G1 X{:.4} Y{:.4} Z{:.4}",
            r * t.cos(),
            r * t.sin(),
            -0.001 * t
        );
    }
    s.push_str("M2\n");
    std::fs::write(&prog, s).unwrap();
    let mut runs = Vec::new();
    for (name, moves) in [("window", 1000), ("whole", 10_000_000)] {
        let machine = dir.join(format!("{name}.toml"));
        std::fs::write(&machine, format!("plan_window_moves = {moves}\n")).unwrap();
        let run = dir.join(name);
        let out = Command::new(cnc_exe())
            .args([
                "run",
                "--clock",
                "sim",
                "--no-report",
                "--force",
                "--machine",
            ])
            .arg(&machine)
            .arg("--out")
            .arg(&run)
            .arg(&prog)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let rep = report(&run);
        assert_eq!(rep["outcome"], "done", "{rep}");
        assert_eq!(rep["starvations"].as_u64(), Some(0), "{rep}");
        let interp: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(run.join("interpreter.json")).unwrap())
                .unwrap();
        let at_speed = interp["windows_at_speed"].as_u64().unwrap();
        assert!(
            if moves == 1000 {
                (8..=12).contains(&at_speed)
            } else {
                at_speed == 0
            },
            "{name}: {interp}"
        );
        let log = shared::cmdlog::read(&run.join("commands.log")).unwrap();
        let setpoints = std::fs::read(run.join("setpoints.csv")).unwrap();
        runs.push((rep["cycles"].as_u64().unwrap(), log.blocks, setpoints));
    }
    let (window, whole) = (&runs[0], &runs[1]);
    assert_eq!(window.0, whole.0, "cycles");
    assert_eq!(window.1.len(), whole.1.len(), "blocks");
    for (i, (a, b)) in window.1.iter().zip(&whole.1).enumerate() {
        assert!(shared::cmdlog::same_bits(a, b), "block {i}:\n{a:?}\n{b:?}");
    }
    assert!(window.2 == whole.2, "the set-points differ");
}
