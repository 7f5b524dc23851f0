//! The supervisor and the operator (issue #22, items 5 to 8 and 11), with the real
//! processes: the launcher killed, Ctrl-C and SIGTERM, a suspended or killed process and
//! what the report names, a closed stdout, and the drives' real-time set-up.
//!
//! Nothing here asserts a duration: runs are waited for by their events (files growing,
//! processes ending), with generous limits that only catch a hang.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;
use tests::{
    assert_decelerated_on_the_diagonal, cnc_exe, complete_csv, process_ended, report, role_pids,
    signal, steps, temp_dir, wait_until,
};

/// A straight feed move along `y = 0.75 x`: 600 mm at F3000, twelve seconds of motion,
/// so that every stop below comes long before the program's end.
const LONG_DIAGONAL: &str = "G21 G90\nG1 X480 Y360 F3000\nM2\n";
/// Cycles of the whole program: 12 s at 1 ms, and more for the ramps.
const FULL_PROGRAM_CYCLES: usize = 12_000;
/// The feed of the move, as a step per 1 ms cycle (mm).
const MAX_STEP_MM: f64 = 3000.0 / 60.0 * 1e-3;

fn write_program(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("program.ngc");
    std::fs::write(&p, text).unwrap();
    p
}

/// `cnc run` of the long diagonal on the real clock, into `dir/run`.
fn start_run(dir: &Path, extra: &[&str]) -> (Child, PathBuf) {
    let prog = write_program(dir, LONG_DIAGONAL);
    let run = dir.join("run");
    let child = Command::new(cnc_exe())
        .arg("run")
        .args(extra)
        .args(["--no-report", "--out"])
        .arg(&run)
        .arg(&prog)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    (child, run)
}

/// Waits until the run is moving (500 set-points written, 25 mm along), then returns the
/// pid of each role.
fn moving(child: &Child, run: &Path) -> Vec<(String, u32)> {
    wait_until("the run to move", Duration::from_secs(60), || {
        std::fs::metadata(run.join("setpoints.csv")).map_or(0, |m| m.len()) > 20_000
    });
    let roles = role_pids(child.id());
    assert_eq!(roles.len(), 3, "{roles:?}");
    roles
}

fn pid_of(roles: &[(String, u32)], role: &str) -> u32 {
    roles
        .iter()
        .find(|(r, _)| r == role)
        .unwrap_or_else(|| panic!("no {role} process"))
        .1
}

/// Waits for `cnc run` to end; its exit status and stdout.
fn finish(child: Child) -> (std::process::ExitStatus, String) {
    let mut child = child;
    let mut status = None;
    wait_until("cnc run to end", Duration::from_secs(60), || {
        status = child.try_wait().unwrap();
        status.is_some()
    });
    let out = child.wait_with_output().unwrap();
    (
        status.unwrap(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

fn json(path: &Path) -> Value {
    serde_json::from_str(
        &std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The whole set-point trace: on the diagonal, never a step above the feed, and from the
/// cycle the stop began to the end slowing every cycle down to standing still, long
/// before the program's end.
fn assert_braked_on_the_path(sp: &[Vec<f64>], info: &Value) {
    assert!(
        sp.len() < FULL_PROGRAM_CYCLES / 2,
        "stopped early, not after the whole program: {} set-points",
        sp.len()
    );
    for (k, r) in sp.iter().enumerate() {
        assert_eq!(r[0] as usize, k, "cycles in order");
        assert!(
            (r[3] - 0.75 * r[2]).abs() < 1e-9,
            "set-point off the path: {r:?}"
        );
    }
    let all = steps(sp);
    let biggest = all.iter().cloned().fold(0.0, f64::max);
    assert!(
        biggest <= MAX_STEP_MM * (1.0 + 1e-9),
        "a step of {biggest} mm in one cycle, above the feed's {MAX_STEP_MM}"
    );
    assert_decelerated_on_the_diagonal(sp, info);
    println!(
        "braked on the path from {:.1} mm/min in cycle {} to rest in cycle {}",
        info["speed_at_fault_mm_per_min"]
            .as_f64()
            .unwrap_or(f64::NAN),
        info["stop_from_cycle"],
        info["stopped_cycle"]
    );
}

/// Item 5: `kill -9` of `cnc run` mid-run. Before, its three processes went on as
/// orphans, machined the whole program and wrote no report.
#[test]
fn a_killed_launcher_makes_the_stack_brake_on_the_path_and_say_why() {
    let dir = temp_dir("kill-launcher");
    let (child, run) = start_run(&dir, &["--sched", "other"]);
    let roles = moving(&child, &run);
    signal(child.id(), libc::SIGKILL);
    let killed = std::time::Instant::now();
    let _ = finish(child);
    // All three end by themselves, well before the program would have.
    for (role, pid) in &roles {
        wait_until(
            &format!("the {role} to end after its launcher died"),
            Duration::from_secs(8),
            || process_ended(*pid),
        );
    }
    // A figure for the README (`--nocapture`), never asserted: timing is noisy here.
    println!(
        "every process gone {:.2} s after the launcher's kill (at most, polled)",
        killed.elapsed().as_secs_f64()
    );
    // The interpolator said why, and so does the report the interpreter wrote in the
    // launcher's place.
    let ipol = json(&run.join("interpolator.json"));
    let fault = ipol["fault"].as_str().unwrap_or_default();
    assert!(
        fault.starts_with("stopped: the launcher (cnc run) died at cycle"),
        "{ipol:#}"
    );
    let info = &ipol["fault_info"];
    assert_eq!(info["kind"], "launcher_gone", "{info}");
    let cycle = info["cycle"].as_u64().unwrap();
    assert!(
        fault.contains(&format!("died at cycle {cycle} ")),
        "{fault}"
    );
    wait_until("report.json", Duration::from_secs(20), || {
        run.join("report.json").exists()
    });
    let rep = report(&run);
    assert_eq!(rep["outcome"], "fault");
    assert!(
        rep["fault"].as_str().unwrap().starts_with(&format!(
            "stopped: the launcher (cnc run) died at cycle {cycle}"
        )),
        "{rep:#}"
    );
    // Every process left its own summary and traces.
    for f in [
        "interpreter.json",
        "servo.json",
        "setpoints.csv",
        "feedback.csv",
    ] {
        assert!(run.join(f).exists(), "{f} missing");
    }
    let sp = complete_csv(&run.join("setpoints.csv"));
    let fb = complete_csv(&run.join("feedback.csv"));
    assert_braked_on_the_path(&sp, info);
    // The drives followed the stop to its end.
    assert_eq!(fb.last().unwrap()[0], sp.last().unwrap()[0]);
    assert_eq!(json(&run.join("servo.json"))["outcome"], "done");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Item 6: the operator's stop. Before, every process got SIGTERM at once: the drives
/// stopped following while the interpolator still braked, and `cnc run` exited 1.
fn operator_stop(sig: i32, code: i32, how: &str) {
    let dir = temp_dir(&format!("operator-{sig}"));
    let (child, run) = start_run(&dir, &["--sched", "other"]);
    moving(&child, &run);
    signal(child.id(), sig);
    let (status, stdout) = finish(child);
    assert_eq!(status.code(), Some(code), "{stdout}");
    let rep = report(&run);
    let fault = rep["fault"].as_str().unwrap();
    assert!(
        fault.starts_with(&format!("stopped by the operator at line 2 ({how})")),
        "{fault}"
    );
    assert!(
        stdout.contains("stopped by the operator at line 2"),
        "{stdout}"
    );
    let info = &rep["fault_info"];
    assert_eq!(info["kind"], "stop_requested", "{info}");
    let sp = complete_csv(&run.join("setpoints.csv"));
    let fb = complete_csv(&run.join("feedback.csv"));
    assert_braked_on_the_path(&sp, info);
    // The drives answered every set-point until rest, then ended on their own.
    assert!(
        fb.last().unwrap()[0] >= sp.last().unwrap()[0],
        "the drives stopped following at cycle {} while the set-points went on to {}",
        fb.last().unwrap()[0],
        sp.last().unwrap()[0]
    );
    assert_eq!(fb.len(), sp.len());
    assert_eq!(json(&run.join("servo.json"))["outcome"], "done");
    for p in rep["processes"].as_array().unwrap() {
        assert!(
            !p["exit"].as_str().unwrap().contains("launcher"),
            "{p} had to be stopped"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_brakes_on_the_path_the_drives_follow_and_the_exit_code_is_130() {
    operator_stop(libc::SIGINT, 130, "Ctrl-C, SIGINT");
}

#[test]
fn sigterm_to_the_launcher_is_the_same_controlled_stop_with_exit_code_143() {
    operator_stop(libc::SIGTERM, 143, "SIGTERM");
}

/// Item 7: a process suspended mid-run (SIGSTOP) is the one named, not the first one to
/// exit after it; the words are a machinist's, not the fault's internal kind.
fn suspended(role: &str) -> (Value, String) {
    let dir = temp_dir(&format!("stop-{role}"));
    let (child, run) = start_run(&dir, &["--sched", "other"]);
    let roles = moving(&child, &run);
    signal(pid_of(&roles, role), libc::SIGSTOP);
    let (status, stdout) = finish(child);
    assert_eq!(status.code(), Some(1), "{stdout}");
    let rep = report(&run);
    let fault = rep["fault"].as_str().unwrap();
    assert!(
        fault.starts_with(&format!("the {role} was suspended")),
        "{fault}"
    );
    for internal in ["peer_silent", "peer_gone", "stop_requested"] {
        assert!(!stdout.contains(internal), "{internal} in\n{stdout}");
    }
    let ipol = run
        .join("interpolator.json")
        .exists()
        .then(|| json(&run.join("interpolator.json")));
    let _ = std::fs::remove_dir_all(&dir);
    (ipol.unwrap_or(Value::Null), stdout)
}

#[test]
fn a_suspended_interpolator_is_named_not_the_servo_that_noticed() {
    suspended("interpolator");
}

/// Item 7 and 11: a drive silent while its process lives is named, and the interpolator
/// says in words that the machine's load (or a suspension) did it and what to try.
#[test]
fn a_suspended_servo_is_named_and_its_silence_is_put_in_words() {
    let (ipol, _) = suspended("servo-sim");
    let f = ipol["fault"].as_str().unwrap_or_default();
    assert_eq!(ipol["fault_info"]["kind"], "peer_silent", "{ipol:#}");
    for words in [
        "although its process is alive",
        "too loaded",
        "cnc latency-test",
        "--clock sim",
    ] {
        assert!(f.contains(words), "`{words}` not in: {f}");
    }
}

/// Item 7: a killed process's summary is missing; the report takes its figures from the
/// traces it left instead of reporting zeros.
fn killed(role: &str) -> (Value, Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let dir = temp_dir(&format!("kill9-{role}"));
    let (child, run) = start_run(&dir, &["--sched", "other"]);
    let roles = moving(&child, &run);
    signal(pid_of(&roles, role), libc::SIGKILL);
    let (status, stdout) = finish(child);
    assert_eq!(status.code(), Some(1), "{stdout}");
    let rep = report(&run);
    assert!(
        rep["fault"]
            .as_str()
            .unwrap()
            .starts_with(&format!("{role} failed (signal 9)")),
        "{rep:#}"
    );
    let sp = complete_csv(&run.join("setpoints.csv"));
    let fb = complete_csv(&run.join("feedback.csv"));
    let _ = std::fs::remove_dir_all(&dir);
    (rep, sp, fb)
}

#[test]
fn a_killed_servo_leaves_its_following_error_in_the_report() {
    let (rep, _, fb) = killed("servo-sim");
    let traced = fb
        .iter()
        .flat_map(|r| r[5..8].iter().map(|e| e.abs()))
        .fold(0.0, f64::max);
    assert!(traced > 0.1, "the drives lagged while moving: {traced} µm");
    let reported = rep["max_following_error_um"].as_f64().unwrap();
    assert!(
        (reported - traced).abs() < 1e-6,
        "report {reported} µm, feedback.csv {traced} µm"
    );
}

#[test]
fn a_killed_interpolator_leaves_its_cycles_and_path_in_the_report() {
    let (rep, sp, _) = killed("interpolator");
    assert_eq!(
        rep["cycles"].as_u64().unwrap() as usize,
        sp.len(),
        "{rep:#}"
    );
    let path: f64 = steps(&sp).iter().sum::<f64>() + (sp[0][2].powi(2) + sp[0][3].powi(2)).sqrt();
    let reported = rep["path_length_mm"].as_f64().unwrap();
    assert!(
        path > 10.0 && (reported - path).abs() < 1e-6,
        "{reported} vs {path}"
    );
    assert!(rep["time_s"].as_f64().unwrap() > 0.0);
    let peak = rep["peak_feed_mm_per_min"].as_f64().unwrap();
    assert!((peak - 3000.0).abs() < 1.0, "peak feed {peak}");
}

/// Item 8: `cnc run … | head -1`, and the reader gone before the first line: the run goes
/// on to its end, quietly, and writes its reports.
#[test]
fn a_closed_stdout_and_stderr_do_not_stop_the_run_or_its_reports() {
    closed_pipes_run("closed-pipe", None);
}

/// The same with every process logging (`RUST_LOG=info`: each one's start-up, the
/// machine in force, its end) into the closed stderr: the lines are lost, the run is not.
/// (tracing reported each failed write on stderr itself, and that write's failure
/// panicked: the servo-sim and the interpreter aborted at their first line, and the run
/// stopped with exit code 101 or a signal.)
#[test]
fn a_log_nobody_reads_does_not_stop_the_run() {
    closed_pipes_run("closed-log", Some("info"));
}

fn closed_pipes_run(tag: &str, rust_log: Option<&str>) {
    let dir = temp_dir(tag);
    let prog = write_program(&dir, "G21 G90\nG1 X5 Y3 F3000\nM2\n");
    let run = dir.join("run");
    let mut cmd = Command::new(cnc_exe());
    match rust_log {
        Some(level) => cmd.env("RUST_LOG", level),
        None => cmd.env_remove("RUST_LOG"),
    };
    let mut child = cmd
        .args(["run", "--clock", "sim", "--out"])
        .arg(&run)
        .arg(&prog)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Close the read ends before anything is written.
    drop(child.stdout.take());
    drop(child.stderr.take());
    let mut status = None;
    wait_until("cnc run to end", Duration::from_secs(60), || {
        status = child.try_wait().unwrap();
        status.is_some()
    });
    assert_eq!(status.unwrap().code(), Some(0));
    assert_eq!(report(&run)["outcome"], "done");
    assert!(run.join("report.html").exists(), "no report.html");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Item 11: the drives get the interpolator's real-time set-up when the system allows
/// it, at a lower priority, and the report says what they got.
#[test]
fn the_servo_sim_gets_real_time_scheduling_when_allowed() {
    let dir = temp_dir("servo-sched");
    let prog = write_program(&dir, "G21 G90\nG1 X5 Y3 F3000\nM2\n");
    let run = dir.join("run");
    let out = Command::new(cnc_exe())
        .args(["run", "--no-report", "--out"])
        .arg(&run)
        .arg(&prog)
        .output()
        .unwrap();
    let rep = report(&run);
    assert!(out.status.success(), "{rep:#}");
    let ipol = &rep["sched"];
    let servo = &rep["servo_sched"];
    assert!(servo.is_object(), "no servo sched report: {rep:#}");
    assert_eq!(json(&run.join("servo.json"))["sched"], *servo);
    if ipol["policy"] == "fifo" {
        assert_eq!(servo["policy"], "fifo", "{servo}");
        let (p, s) = (
            ipol["priority"].as_i64().unwrap(),
            servo["priority"].as_i64().unwrap(),
        );
        assert!(s < p && s > 50, "servo-sim at {s}, interpolator at {p}");
        assert_eq!(servo["memory_locked"], true, "{servo}");
        assert!(servo["cpu"].is_null(), "the drives are not pinned: {servo}");
    } else {
        // Not allowed here: the drives say so as the interpolator does.
        assert_eq!(servo["policy"], "other");
        assert!(
            servo["warnings"]
                .as_array()
                .unwrap()
                .iter()
                .any(|w| w.as_str().unwrap().contains("SCHED_FIFO refused")),
            "{servo}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
