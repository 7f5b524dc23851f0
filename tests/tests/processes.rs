//! The real three processes, started by `cnc run`, end to end.

use std::process::Command;
use tests::{circle_errors, cnc_exe, csv, report, temp_dir};

#[test]
fn demo_runs_in_three_processes_and_leaves_a_run_directory() {
    let dir = temp_dir("demo");
    let out = Command::new(cnc_exe())
        .args(["run", "--out"])
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cnc run failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let rep = report(&dir);
    assert_eq!(rep["outcome"], "done", "{rep:#}");
    assert!(rep["fault"].is_null());
    assert_eq!(rep["program"], "demo.ngc");
    assert_eq!(rep["period_ns"], 1_000_000);
    for key in ["wake_late_ns", "compute_ns"] {
        for p in ["p50", "p99", "max"] {
            assert!(rep[key][p].is_u64(), "{key}.{p}");
        }
    }
    let procs = rep["processes"].as_array().unwrap();
    let roles: Vec<_> = procs.iter().map(|p| p["role"].as_str().unwrap()).collect();
    assert_eq!(roles, ["servo-sim", "interpolator", "interpreter"]);
    let mut pids: Vec<_> = procs.iter().map(|p| p["pid"].as_u64().unwrap()).collect();
    pids.push(std::process::id() as u64);
    pids.sort();
    pids.dedup();
    assert_eq!(pids.len(), 4, "three separate processes besides this test");

    let (h, sp) = csv(&dir.join("setpoints.csv"));
    assert_eq!(h, "cycle,t_ns,x_mm,y_mm,z_mm,line");
    let (h, fb) = csv(&dir.join("feedback.csv"));
    assert_eq!(h, "cycle,t_ns,x_mm,y_mm,z_mm,ferr_x_um,ferr_y_um,ferr_z_um");
    let cycles = rep["cycles"].as_u64().unwrap() as usize;
    assert_eq!(sp.len(), cycles);
    assert_eq!(fb.len(), cycles, "the drives answered every set-point");
    for (k, row) in sp.iter().enumerate() {
        assert_eq!(row[0] as usize, k);
        assert_eq!(row[1] as u64, k as u64 * 1_000_000, "t_ns = cycle x period");
    }
    // The program's path length: the demo ends where it started, at rest.
    let last = sp.last().unwrap();
    assert_eq!(&last[2..5], &[0.0, 0.0, 5.0]);
    assert!(rep["path_length_mm"].as_f64().unwrap() > 400.0);
    assert!(std::fs::metadata(dir.join("commands.log")).unwrap().len() > 16);

    // The simulated clock gives the very same set-points and feedback, byte for byte.
    let sim = dir.join("sim");
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--out"])
        .arg(&sim)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rep_sim = report(&sim);
    assert_eq!(rep_sim["clock"], "sim");
    assert!(
        rep_sim["misses"].is_null() && rep_sim["wake_late_ns"].is_null(),
        "timing is not measured"
    );
    assert_eq!(rep_sim["time_s"], rep["time_s"]);
    for f in ["setpoints.csv", "feedback.csv"] {
        assert!(
            std::fs::read(dir.join(f)).unwrap() == std::fs::read(sim.join(f)).unwrap(),
            "{f} differs"
        );
    }
    // Replaying the real run's command log (here on the simulated clock) reproduces it.
    let rep_dir = dir.join("replay");
    let out = Command::new(cnc_exe())
        .args(["replay", "--clock", "sim", "--out"])
        .arg(&rep_dir)
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for f in ["setpoints.csv", "feedback.csv", "commands.log"] {
        let same = std::fs::read(dir.join(f)).unwrap() == std::fs::read(rep_dir.join(f)).unwrap();
        assert!(same, "replay: {f} differs");
    }
    // And `cnc check --estimate` predicts that machining time to the cycle.
    let out = Command::new(cnc_exe())
        .args(["check", "--estimate", "--json"])
        .arg(dir.join("program.ngc"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let est: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(est["cycles"], rep["cycles"]);
    assert_eq!(est["time_s"], rep["time_s"]);
    let moves = est["moves"].as_array().unwrap();
    let per_line: u64 = moves.iter().map(|m| m["cycles"].as_u64().unwrap()).sum();
    assert_eq!(per_line, rep["cycles"].as_u64().unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn nurbs_program_is_bit_identical_under_both_clocks() {
    let prog =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("peers/linuxcnc/g5_nurbs-xy.ngc");
    let dir = temp_dir("nurbs-clocks");
    for clock in ["real", "sim"] {
        let out = Command::new(cnc_exe())
            .args(["run", "--clock", clock, "--out"])
            .arg(dir.join(clock))
            .arg(&prog)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{clock}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    for f in ["setpoints.csv", "feedback.csv"] {
        let (a, b) = (
            std::fs::read(dir.join("real").join(f)).unwrap(),
            std::fs::read(dir.join("sim").join(f)).unwrap(),
        );
        assert!(a.len() > 1000 && a == b, "{f} differs between the clocks");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn full_circle_is_exact_to_a_nanometre_with_chords_within_tolerance() {
    let dir = temp_dir("circle");
    let prog = dir.join("circle.ngc");
    std::fs::write(
        &prog,
        "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n",
    )
    .unwrap();
    let out = Command::new(cnc_exe())
        .arg("run")
        .arg(&prog)
        .arg("--out")
        .arg(dir.join("run"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rep = report(&dir.join("run"));
    assert_eq!(rep["outcome"], "done");
    let (_, sp) = csv(&dir.join("run/setpoints.csv"));
    let on_arc: Vec<_> = sp.iter().filter(|r| r[5] == 3.0).collect();
    assert!(
        on_arc.len() > 1000,
        "{} set-points on the circle",
        on_arc.len()
    );
    let (radial, sagitta) = circle_errors(&on_arc, [0.0, 0.0], 10.0);
    assert!(radial < 1e-6, "set-point off the circle by {radial} mm");
    assert!(sagitta < 0.001, "chord deviates {sagitta} mm from the arc");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn check_reports_every_problem_with_file_line_and_column() {
    let dir = temp_dir("check");
    let prog = dir.join("bad.ngc");
    std::fs::write(&prog, "G21\nG1 X10\nG2 X5 Y5 F100\nG1 X1 X2\nG5.3\n").unwrap();
    let out = Command::new(cnc_exe())
        .arg("check")
        .arg(&prog)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<_> = err.lines().collect();
    let name = prog.display().to_string();
    assert_eq!(lines.len(), 4, "{err}");
    assert!(
        lines[0].starts_with(&format!("{name}:2:1: feed: ")),
        "{err}"
    );
    assert!(lines[1].starts_with(&format!("{name}:3:1: arc: ")), "{err}");
    assert!(
        lines[2].starts_with(&format!("{name}:4:7: word: ")),
        "{err}"
    );
    assert!(
        lines[3].starts_with(&format!("{name}:5:1: G5.3: ")),
        "{err}"
    );

    let good = dir.join("good.ngc");
    std::fs::write(&good, "G1 X1 F100\nM2\n").unwrap();
    let out = Command::new(cnc_exe())
        .arg("check")
        .arg(&good)
        .output()
        .unwrap();
    assert!(out.status.success());

    // `cnc run` refuses a bad program before starting anything.
    let out = Command::new(cnc_exe())
        .arg("run")
        .arg(&prog)
        .arg("--out")
        .arg(dir.join("run"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(
        !dir.join("run").exists(),
        "no run directory for a rejected program"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn damaged_log_is_refused_with_record_and_offset_or_salvaged() {
    let dir = temp_dir("damaged");
    let prog = dir.join("square.ngc");
    std::fs::write(&prog, "G1 X10 F3000\nY10\nX0\nY0\nM2\n").unwrap();
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--out"])
        .arg(dir.join("run"))
        .arg(&prog)
        .output()
        .unwrap();
    assert!(out.status.success());
    let mut log = std::fs::read(dir.join("run/commands.log")).unwrap();
    let len = log.len();
    // Flip one byte in the middle of the third record.
    let record = 8 + std::mem::size_of::<shared::protocol::CommandBlock>();
    let header = len - 5 * record;
    log[header + 2 * record + 100] ^= 0x10;
    let bad = dir.join("bad.log");
    std::fs::write(&bad, &log).unwrap();
    let out = Command::new(cnc_exe())
        .args(["replay", "--clock", "sim"])
        .arg(&bad)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!("record 2 at byte {}", header + 2 * record)),
        "{err}"
    );
    let out = Command::new(cnc_exe())
        .args(["log", "show"])
        .arg(&bad)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stdout).lines().count(),
        3,
        "header line and the 2 intact blocks"
    );

    let out = Command::new(cnc_exe())
        .args(["replay", "--clock", "sim", "--salvage", "--machine"])
        .arg(dir.join("run/machine.toml"))
        .arg("--out")
        .arg(dir.join("salvaged"))
        .arg(&bad)
        .output()
        .unwrap();
    // Only part of the program ran: not a success, and the summary says so.
    assert_eq!(
        out.status.code(),
        Some(1),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        text.starts_with("salvaged: only the intact blocks of a damaged command log ran"),
        "{text}"
    );
    let rep = report(&dir.join("salvaged"));
    assert_eq!(rep["outcome"], "salvaged", "{rep:#}");
    assert!(
        rep["salvaged"].as_str().unwrap().contains("record 2"),
        "{rep:#}"
    );
    // The two intact lines ran, then the machine stopped at (10, 10).
    let (_, sp) = csv(&dir.join("salvaged/setpoints.csv"));
    assert_eq!(&sp.last().unwrap()[2..4], &[10.0, 10.0]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_killed_servo_stops_the_stack_and_the_report_says_so() {
    let dir = temp_dir("kill");
    let mut child = Command::new(cnc_exe())
        .args(["run", "--out"])
        .arg(&dir)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Wait until the stack is moving, then kill the drives without warning.
    let t = std::time::Instant::now();
    while std::fs::metadata(dir.join("feedback.csv")).map_or(0, |m| m.len()) < 20_000 {
        assert!(t.elapsed().as_secs() < 30, "the run never started");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let killed = Command::new("pkill")
        .args([
            "-9",
            "-f",
            &format!("cnc role servo-sim --prefix cnc{}_", child.id()),
        ])
        .status()
        .unwrap();
    assert!(killed.success());
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(1));
    let rep = report(&dir);
    assert_eq!(rep["outcome"], "fault");
    let fault = rep["fault"].as_str().unwrap();
    assert!(fault.starts_with("servo-sim failed (signal 9)"), "{fault}");
    // The survivors stopped in order and kept what they had measured.
    let procs = rep["processes"].as_array().unwrap();
    assert!(
        procs.iter().all(|p| p["exit"] != "killed by the launcher"),
        "{procs:?}"
    );
    let (_, sp) = csv(&dir.join("setpoints.csv"));
    assert_eq!(sp.len() as u64, rep["cycles"].as_u64().unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn run_reads_subroutines_from_their_own_files() {
    // `o<square> call` of a subroutine the program does not define: `cnc run` finds
    // `square.ngc` in a `--subroutine-path`, although the interpreter process reads the
    // run directory's copy of the program; without the path it refuses the call before
    // anything starts, naming the program's line and column.
    let dir = temp_dir("subfile");
    std::fs::create_dir_all(dir.join("lib")).unwrap();
    std::fs::write(
        dir.join("lib/square.ngc"),
        "o<square> sub\nG1 X#1 F600\nG1 Y#1\nG1 X0\nG1 Y0\no<square> endsub\nM2\n",
    )
    .unwrap();
    let main = dir.join("main.ngc");
    std::fs::write(&main, "G21 G90\no<square> call [5]\nM2\n").unwrap();
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(dir.join("without"))
        .arg(&main)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("main.ngc:2:1: O-word:"), "{err}");
    let run = dir.join("with");
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--subroutine-path"])
        .arg(dir.join("lib"))
        .arg("--out")
        .arg(&run)
        .arg(&main)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cnc run failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    let rep = report(&run);
    assert_eq!(rep["outcome"], "done", "{rep:#}");
    let len = rep["path_length_mm"].as_f64().unwrap();
    assert!((len - 20.0).abs() < 1e-9, "a 5 mm square: {len} mm");
    // A file beside the program could change between the launcher's check and the
    // interpreter's reading: the interpreter checks for itself (`interpreter::checked`).
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("interpreter.json")).unwrap())
            .unwrap();
    assert_eq!(summary["checked_by"], "interpreter", "{summary:#}");
    assert!(!run.join("checked.json").exists());
}
