//! What the processes of a run say on stderr (`RUST_LOG`): a small program through
//! `cnc run --clock sim`, read back as an integrator would. `info` has each process's
//! start-up (with its scheduling), the machine file in force with its hash, and how
//! each ended; `debug` adds the shared-memory services each opened and every block, as the
//! interpreter published it and as the interpolator received it. `cnc latency-test` into a
//! pipe prints plain progress lines while it measures.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const PROGRAM: &str = "G21 G90\nG1 X5 F1000\nG1 X5 Y5\nG1 X0 Y5\nM2\n";

fn scratch(name: &str) -> PathBuf {
    let d =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("logs-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

/// `cnc run --clock sim` of [`PROGRAM`] with `RUST_LOG=level`; its stderr.
fn run_logged(level: &str) -> String {
    let d = scratch(level);
    let prog = d.join("square.ngc");
    fs::write(&prog, PROGRAM).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(d.join("run"))
        .arg(&prog)
        .env("RUST_LOG", level)
        .env_remove("IOX2_LOG_LEVEL")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "cnc run failed:\n{err}");
    err
}

/// The lines of `log` that hold every one of `words`.
fn lines_with<'a>(log: &'a str, words: &[&str]) -> Vec<&'a str> {
    log.lines()
        .filter(|l| words.iter().all(|w| l.contains(w)))
        .collect()
}

#[test]
fn debug_logs_say_start_up_machine_services_and_every_block() {
    let log = run_logged("debug");
    assert!(!log.contains('\u{1b}'), "colour codes in a pipe: {log:?}");
    // Start-up, with the scheduling obtained (the simulated clock runs plain).
    for who in ["interpolator started", "servo-sim started"] {
        let l = lines_with(&log, &[" INFO ", who, "SCHED_OTHER"]);
        assert_eq!(l.len(), 1, "{who}:\n{log}");
    }
    assert_eq!(
        lines_with(&log, &[" INFO ", "interpreter started", "blocks=4 "]).len(),
        1,
        "{log}"
    );
    // The machine file in force, in every process, with the same hash: the launcher's is
    // the built-in one, each process reads the run directory's copy.
    let machine = lines_with(&log, &[" INFO ", "machine file in force"]);
    let hash = format!("hash={:016x}", shared::Machine::default().hash());
    for process in ["cnc run", "interpreter", "interpolator", "servo-sim"] {
        let of = format!("process={process} ");
        assert_eq!(
            machine
                .iter()
                .filter(|l| l.contains(&of) && l.contains(&hash))
                .count(),
            1,
            "{process}:\n{log}"
        );
    }
    assert!(machine.iter().any(|l| l.contains("machine=built-in")));
    assert_eq!(
        machine
            .iter()
            .filter(|l| l.contains("machine.toml"))
            .count(),
        3,
        "{log}"
    );
    // Services opened.
    for who in ["interpreter:", "interpolator:", "servo-sim:"] {
        assert_eq!(
            lines_with(&log, &[" DEBUG ", who, "shared-memory services open"]).len(),
            1,
            "{who}:\n{log}"
        );
    }
    // Every block, published and received (3 moves and the program end), in order.
    for what in ["block published", "block received"] {
        let seqs: Vec<&str> = lines_with(&log, &[" DEBUG ", what])
            .iter()
            .map(|l| {
                l.split("seq=")
                    .nth(1)
                    .and_then(|r| r.split(' ').next())
                    .unwrap_or("?")
            })
            .collect();
        assert_eq!(seqs, ["0", "1", "2", "3"], "{what}:\n{log}");
    }
    assert_eq!(
        lines_with(&log, &["block received", "seq=3", "kind=end", "line=5"]).len(),
        1,
        "{log}"
    );
    // How each ended.
    for end in [
        "interpolator stopped: program end reached",
        "servo-sim stopped: the last set-point is answered",
        "interpreter stopped: program end",
        "run over outcome=done",
    ] {
        assert_eq!(lines_with(&log, &[" INFO ", end]).len(), 1, "{end}:\n{log}");
    }
}

#[test]
fn info_logs_keep_the_debug_lines_out() {
    let log = run_logged("info");
    assert!(log.contains("interpolator started"), "{log}");
    assert!(log.contains("machine file in force"), "{log}");
    assert!(
        log.contains("interpolator stopped: program end reached"),
        "{log}"
    );
    for hidden in [
        " DEBUG ",
        "shared-memory services open",
        "block published",
        "block received",
    ] {
        assert!(!log.contains(hidden), "{hidden} at info:\n{log}");
    }
}

/// A fault is logged as an error naming its cause: with a following-error limit of 4 µm
/// the drives exceed it as soon as the axes are up to 3000 mm/min.
#[test]
fn a_fault_is_an_error_that_names_its_cause() {
    let d = scratch("fault");
    let prog = d.join("diagonal.ngc");
    fs::write(&prog, "G21 G90\nG1 X120 Y90 F3000\nM2\n").unwrap();
    let machine = d.join("tight.toml");
    fs::write(&machine, "max_following_error_mm = 0.004\n").unwrap();
    let o: Output = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "sim", "--no-report", "--machine"])
        .arg(&machine)
        .arg("--out")
        .arg(d.join("run"))
        .arg(&prog)
        .env("RUST_LOG", "info")
        .output()
        .unwrap();
    let log = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{log}");
    let faults = lines_with(&log, &[" ERROR ", "interpolator fault:", "following error"]);
    assert_eq!(faults.len(), 1, "{log}");
    assert!(faults[0].contains("kind=following_error"), "{log}");
    assert_eq!(
        lines_with(&log, &[" ERROR ", "run failed:"]).len(),
        1,
        "{log}"
    );
}

/// Into a pipe, `cnc latency-test` prints plain progress lines while it measures (here
/// only the last, with the final figures, as the test is shorter than a second) and then
/// its result, with no terminal escape codes.
#[test]
fn latency_test_into_a_pipe_prints_plain_progress_lines() {
    let d = scratch("latency");
    let out = d.join("latency.json");
    let o = Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args([
            "latency-test",
            "--seconds",
            "0.3",
            "--sched",
            "other",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(!text.contains('\u{1b}'), "escape codes in a pipe: {text:?}");
    let progress = lines_with(
        &text,
        &["latency-test ", " s of 0.3 s: ", "wake-ups", "max"],
    );
    assert!(!progress.is_empty(), "{text}");
    let last = progress.last().unwrap();
    assert!(
        last.starts_with("latency-test 0.3 s of 0.3 s: 300 wake-ups"),
        "{text}"
    );
    // The result follows, as before, and is written.
    assert!(text.contains("verdict"), "{text}");
    assert!(out.exists());
}
