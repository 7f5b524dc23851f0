//! Faults, with the real processes: a process killed mid-run, bad blocks in shared memory,
//! a slow interpreter, excess following error, and long runs (`--repeat`).
//!
//! Nothing here asserts a duration: runs are waited for by their events (files growing,
//! processes ending), with generous limits that only catch a hang.

use iceoryx2::node::NodeView;
use iceoryx2::prelude::*;
use serde_json::Value;
use shared::protocol::{BlockKind, CommandBlock, RunState, Services};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;
use tests::{
    assert_decelerated_on_the_diagonal, cnc_exe, complete_csv, report, role_pids, steps, temp_dir,
    wait_until,
};

/// A straight feed move along `y = 0.75 x`: 150 mm at F3000, three seconds of motion.
const DIAGONAL: &str = "G21 G90\nG1 X120 Y90 F3000\nM2\n";

fn write_program(dir: &Path, text: &str) -> std::path::PathBuf {
    let p = dir.join("program.ngc");
    std::fs::write(&p, text).unwrap();
    p
}

fn wait_exit(child: &mut Child, what: &str) -> std::process::ExitStatus {
    let mut status = None;
    wait_until(what, Duration::from_secs(60), || {
        status = child.try_wait().unwrap();
        status.is_some()
    });
    status.unwrap()
}

/// After a killed run: a fresh run works, with nothing cleaned by hand, and no iceoryx2
/// node of the killed process is left.
fn next_run_works_and_the_dead_node_is_gone(dir: &Path, killed_pid: u32) {
    let prog = dir.join("again.ngc");
    std::fs::write(&prog, "G1 X5 F3000\nM2\n").unwrap();
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(dir.join("again"))
        .arg(&prog)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "the run after a killed one failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut left = vec![];
    Node::<ipc::Service>::list(shared::ipc::config(), |state| {
        let id = match &state {
            NodeState::Alive(v) => Some(*v.id()),
            NodeState::Dead(v) => Some(*v.id()),
            _ => None,
        };
        if let Some(pid) = id.and_then(|i| i.pid::<ipc::Service>().ok()) {
            if pid.value() as u32 == killed_pid {
                left.push(format!("{state:?}"));
            }
        }
        CallbackProgression::Continue
    })
    .unwrap();
    assert!(
        left.is_empty(),
        "nodes of the killed process remain: {left:?}"
    );
}

/// `cnc run` of `prog` into `run`, moving for a while (500 set-points written, 25 mm
/// along at F3000), then its `role` process killed without warning: the launcher and the
/// killed process's pid.
fn killed_mid_run(prog: &Path, run: &Path, role: &str) -> (Child, u32) {
    let child = Command::new(cnc_exe())
        .args(["run", "--sched", "other", "--no-report", "--out"])
        .arg(run)
        .arg(prog)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    wait_until("the run to move", Duration::from_secs(60), || {
        std::fs::metadata(run.join("setpoints.csv")).map_or(0, |m| m.len()) > 20_000
    });
    let pid = role_pids(child.id())
        .into_iter()
        .find(|(r, _)| r == role)
        .unwrap_or_else(|| panic!("no {role} process"))
        .1;
    // SAFETY: kill(2) on a process this test's child started.
    assert_eq!(unsafe { libc::kill(pid as i32, libc::SIGKILL) }, 0);
    (child, pid)
}

fn kill_mid_run(role: &str) {
    let dir = temp_dir(&format!("kill-{role}"));
    let prog = write_program(&dir, DIAGONAL);
    let run = dir.join("run");
    let (mut child, pid) = killed_mid_run(&prog, &run, role);
    let status = wait_exit(&mut child, "cnc run to end");
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(status.code(), Some(1), "{stdout}");

    let rep = report(&run);
    assert_eq!(rep["outcome"], "fault");
    let dead = &rep["dead_process"];
    assert_eq!(dead["role"], role, "{rep:#}");
    assert_eq!(dead["pid"], pid);
    assert_eq!(dead["exit"], "signal 9");
    let cycle = dead["cycle"].as_u64().expect("the cycle it died at");
    assert!(cycle > 100, "died mid-run, at cycle {cycle}");
    let fault = rep["fault"].as_str().unwrap();
    assert!(
        fault.starts_with(&format!("{role} failed (signal 9): died at cycle {cycle}")),
        "{fault}"
    );
    // The survivors stopped by themselves: nobody had to be stopped by the launcher.
    for p in rep["processes"].as_array().unwrap() {
        assert!(
            !p["exit"].as_str().unwrap().contains("launcher"),
            "{p} had to be stopped"
        );
    }
    // Everything written is intact: whole lines only, cycles in order.
    let sp = complete_csv(&run.join("setpoints.csv"));
    let fb = complete_csv(&run.join("feedback.csv"));
    for (k, r) in sp.iter().enumerate() {
        assert_eq!(r[0] as usize, k);
    }
    for (k, r) in fb.iter().enumerate() {
        assert_eq!(r[0] as usize, k);
    }
    // The command log reads clean whoever died: every record is handed to the kernel as
    // its block is sent, so even a killed interpreter leaves whole records only.
    let log = Command::new(cnc_exe())
        .args(["log", "show"])
        .arg(&run)
        .output()
        .unwrap();
    assert!(
        log.status.success(),
        "{role}: {}",
        String::from_utf8_lossy(&log.stderr)
    );
    assert!(
        String::from_utf8_lossy(&log.stdout).lines().count() > 1,
        "{role}: the log holds the blocks sent"
    );

    match role {
        "interpolator" => {
            // The drives held position after its last set-point, and said why.
            let servo: Value =
                serde_json::from_str(&std::fs::read_to_string(run.join("servo.json")).unwrap())
                    .unwrap();
            let f = servo["fault"].as_str().unwrap();
            assert!(f.contains("the interpolator is gone"), "{f}");
            assert!(f.contains(&format!("after set-point cycle {cycle}")), "{f}");
            assert_eq!(fb.last().unwrap()[0] as u64, cycle);
        }
        peer => {
            let info = &rep["fault_info"];
            assert_eq!(info["kind"], "peer_gone", "{rep:#}");
            assert_eq!(info["peer"], peer);
            assert_eq!(info["cycle"].as_u64(), Some(cycle));
            assert_eq!(rep["cycles"].as_u64().unwrap() as usize, sp.len());
            assert_decelerated_on_the_diagonal(&sp, info);
            if peer == "interpreter" {
                // The drives followed the stop to its end.
                assert_eq!(fb.len(), sp.len());
                let servo: Value =
                    serde_json::from_str(&std::fs::read_to_string(run.join("servo.json")).unwrap())
                        .unwrap();
                assert_eq!(servo["outcome"], "done", "{servo}");
            }
        }
    }
    next_run_works_and_the_dead_node_is_gone(&dir, pid);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn killed_interpreter_is_noticed_and_the_interpolator_stops_on_the_path() {
    kill_mid_run("interpreter");
}

#[test]
fn killed_servo_is_noticed_and_the_interpolator_stops_on_the_path() {
    kill_mid_run("servo-sim");
}

#[test]
fn killed_interpolator_is_noticed_and_the_drives_hold() {
    kill_mid_run("interpolator");
}

/// The interpreter's summary counts the blocks it sent when the sending ends in an error
/// (the interpolator killed while blocks were still to go): the blocks of the command log,
/// not the program's. It said the program's count, and its log `blocks_sent=0`.
#[test]
fn a_killed_interpolator_leaves_the_count_of_blocks_sent_in_the_interpreters_summary() {
    let dir = temp_dir("kill-count");
    // 3000 zigzag moves of about 1 mm at F3000: far more blocks than the queue holds.
    let mut text = String::from("G21 G90\nF3000\n");
    for i in 1..=3000 {
        text.push_str(&format!("G1 X{} Y{:.1}\n", i % 2, i as f64 * 0.2));
    }
    text.push_str("M2\n");
    let prog = write_program(&dir, &text);
    let run = dir.join("run");
    let (mut child, _) = killed_mid_run(&prog, &run, "interpolator");
    wait_exit(&mut child, "cnc run to end");
    let logged = shared::cmdlog::read(&run.join("commands.log"))
        .expect("the command log reads clean")
        .blocks
        .len();
    let interp: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("interpreter.json")).unwrap())
            .unwrap();
    assert_eq!(interp["outcome"], "fault", "{interp:#}");
    assert!(
        logged > 0 && logged < 3000,
        "killed with blocks still to send: {logged} logged"
    );
    assert_eq!(interp["blocks"].as_u64(), Some(logged as u64), "{interp:#}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// A valid one-block line from the origin, to be spoiled field by field.
fn good_block() -> CommandBlock {
    tests::line_block(0, 1)
}

/// What an injection left: the interpolator's exit status, its stderr and fault, its
/// final state and the set-point rows.
struct Injected {
    status: std::process::ExitStatus,
    text: String,
    last: RunState,
    sp: Vec<Vec<f64>>,
    summary: Value,
}

/// Starts a servo-sim and an interpolator on the simulated clock and publishes `blocks`
/// into shared memory as the interpreter would, but raw: nothing checks them on this side.
fn inject(tag: &str, blocks_to_send: &[CommandBlock]) -> Injected {
    let dir = temp_dir(&format!("inject-{tag}"));
    let prefix = format!("inj{}{tag}", std::process::id());
    let common = |role: &str| {
        let mut c = Command::new(cnc_exe());
        c.args(["role", role, "--prefix", &prefix, "--clock", "sim", "--out"])
            .arg(&dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        c
    };
    let mut servo = common("servo-sim").spawn().unwrap();
    let mut ipol = common("interpolator")
        .args(["--sched", "other"])
        .spawn()
        .unwrap();

    let svc = Services::new(&prefix);
    let node = shared::ipc::node::<ipc::Service>("test-injector").unwrap();
    let blocks = shared::ipc::blocks(&node, &svc).unwrap();
    let publisher = blocks.publisher_builder().create().unwrap();
    let status = shared::ipc::status(&node, &svc).unwrap();
    let status_sub = status.subscriber_builder().create().unwrap();
    for block in blocks_to_send {
        wait_until(
            "the interpolator to take the block",
            Duration::from_secs(60),
            || {
                let sample = publisher.loan_uninit().unwrap();
                sample.write_payload(*block).send().unwrap() > 0
            },
        );
    }
    let mut last = RunState::Idle;
    wait_until("a final status", Duration::from_secs(60), || {
        while let Some(s) = status_sub.receive().unwrap() {
            last = RunState::from_code(s.state).unwrap();
        }
        matches!(last, RunState::Fault | RunState::Done)
    });
    drop(publisher);
    let st = wait_exit(&mut ipol, "the interpolator to end");
    let mut err = String::new();
    use std::io::Read;
    ipol.stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    let servo_st = wait_exit(&mut servo, "the servo-sim to end");
    assert!(
        servo_st.success(),
        "{tag}: the drives end cleanly on the last set-point"
    );
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("interpolator.json")).unwrap())
            .unwrap();
    let sp = complete_csv(&dir.join("setpoints.csv"));
    let _ = std::fs::remove_dir_all(&dir);
    Injected {
        status: st,
        text: format!("{err}\n{}", summary["fault"]),
        last,
        sp,
        summary,
    }
}

#[test]
fn malformed_blocks_fault_cleanly_naming_the_field_and_never_move() {
    type Spoil = fn(&mut CommandBlock);
    let cases: [(&str, Spoil, &str); 6] = [
        ("version", |b| b.protocol = 99, "protocol: version 99"),
        (
            "capacity",
            |b| b.n_ctrl = 4000,
            "n_ctrl: 4000 control points exceed",
        ),
        (
            "nan",
            |b| b.ctrl[1][1] = f64::NAN,
            "ctrl[1]: not a finite number",
        ),
        (
            "nanknot",
            |b| b.knots[2] = f64::NAN,
            "knots[2]: not a finite number",
        ),
        (
            "knots",
            |b| b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 0.5]),
            "knots: knot 3 is smaller than knot 2",
        ),
        (
            "weight",
            |b| b.ctrl[1][3] = 0.0,
            "ctrl (weight): weight of control point 1",
        ),
    ];
    for (tag, spoil, message) in cases {
        let mut b = good_block();
        spoil(&mut b);
        let Injected {
            status,
            text,
            last,
            sp,
            summary,
        } = inject(tag, &[b]);
        // A clean fault: exit 1 with the message (a panic would exit 101, a signal none).
        assert_eq!(last, RunState::Fault, "{tag}: {text}");
        assert_eq!(status.code(), Some(1), "{tag}: {text}");
        assert_eq!(summary["fault_info"]["kind"], "bad_block", "{tag}");
        assert!(text.contains("bad command block"), "{tag}: {text}");
        assert!(text.contains(message), "{tag}: `{message}` not in {text}");
        assert!(!text.contains("panicked"), "{tag}: {text}");
        assert!(!sp.is_empty(), "{tag}: a last set-point was published");
        assert!(
            sp.iter().all(|r| r[2..5] == [0.0, 0.0, 0.0]),
            "{tag}: moved: {:?}",
            sp.iter().find(|r| r[2..5] != [0.0, 0.0, 0.0])
        );
    }
    // The unspoilt block, injected the same way, runs: the cases above failed for their
    // field alone.
    let good = inject(
        "good",
        &[
            good_block(),
            CommandBlock::empty(BlockKind::ProgramEnd, 1, 2),
        ],
    );
    assert_eq!(good.last, RunState::Done, "{}", good.text);
    assert!(good.status.success(), "{}", good.text);
    assert_eq!(good.sp.last().unwrap()[2..5], [10.0, 0.0, 0.0]);
}

#[test]
fn a_slow_interpreter_starves_the_interpolator_which_waits_on_the_path() {
    let dir = temp_dir("starve");
    // Five 1 mm moves in a row: the planner lets them flow into each other at speed, so the
    // interpolator needs each next block in time. With the interpreter throttled to one
    // block per 150 ms, it runs out of blocks after each one.
    let prog = write_program(&dir, "G21 G90\nG1 X1 F3000\nX2\nX3\nX4\nX5\nM2\n");
    let run = dir.join("run");
    let out = Command::new(cnc_exe())
        .args([
            "run",
            "--sched",
            "other",
            "--no-report",
            "--throttle-ms",
            "150",
            "--out",
        ])
        .arg(&run)
        .arg(&prog)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rep = report(&run);
    assert_eq!(rep["outcome"], "done");
    let n = rep["starvations"].as_u64().unwrap();
    // One wait after each block whose successor was late: up to 5 (the program end comes
    // late too); the interpolator may be lucky once or twice on a busy machine.
    assert!((3..=5).contains(&n), "{n} starvations for 5 blocks");
    let ipol: Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("interpolator.json")).unwrap())
            .unwrap();
    assert_eq!(ipol["starvations"].as_u64(), Some(n));
    assert!(String::from_utf8_lossy(&out.stdout).contains(&format!("starvation   {n} time")));
    // Every wait is at a block end, on the path, reached by slowing down: never mid-block.
    let sp = complete_csv(&run.join("setpoints.csv"));
    let d = steps(&sp);
    let mut waits = 0;
    let mut i = 1;
    while i < d.len() {
        if d[i] == 0.0 && d[i - 1] > 0.0 {
            let at = &sp[i + 1];
            assert!(
                (at[2] - at[2].round()).abs() < 1e-9 && at[3] == 0.0,
                "stopped off a block end: {at:?}"
            );
            assert!(
                d[i - 1] < 0.01,
                "arrived slowly, not at speed: {}",
                d[i - 1]
            );
            waits += 1;
        }
        i += 1;
    }
    assert!(waits as u64 >= n, "{waits} stops for {n} starvations");
    assert_eq!(sp.last().unwrap()[2], 5.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn excess_following_error_stops_the_machine_along_the_path() {
    let dir = temp_dir("ferr");
    let prog = write_program(&dir, DIAGONAL);
    // A limit so tight that the drives exceed it as soon as the axes are up to speed.
    let mut machine = String::from_utf8(
        Command::new(cnc_exe())
            .arg("machine")
            .output()
            .unwrap()
            .stdout,
    )
    .unwrap();
    machine = machine
        .lines()
        .map(|l| {
            if l.starts_with("max_following_error_mm") {
                "max_following_error_mm = 0.004".to_string()
            } else {
                l.to_string()
            }
        })
        .collect::<Vec<_>>()
        .join("\n");
    let mfile = dir.join("tight.toml");
    std::fs::write(&mfile, machine).unwrap();
    let run = dir.join("run");
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--machine"])
        .arg(&mfile)
        .arg("--out")
        .arg(&run)
        .arg(&prog)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let rep = report(&run);
    assert_eq!(rep["outcome"], "fault");
    let info = &rep["fault_info"];
    assert_eq!(info["kind"], "following_error", "{rep:#}");
    let axis = info["axis"].as_str().unwrap();
    assert!(axis == "X" || axis == "Y", "{axis}");
    assert_eq!(info["line"], 2, "the G1 on line 2");
    let cycle = info["cycle"].as_u64().unwrap();
    let fault = rep["fault"].as_str().unwrap();
    assert!(
        fault.contains(&format!("cycle {cycle}, line 2: following error on {axis}")),
        "{fault}"
    );
    let sp = complete_csv(&run.join("setpoints.csv"));
    let fb = complete_csv(&run.join("feedback.csv"));
    // The drives really were over the limit in that cycle, on that axis.
    let col = if axis == "X" { 5 } else { 6 };
    assert!(
        fb[cycle as usize][col].abs() > 4.0,
        "{:?}",
        fb[cycle as usize]
    );
    // Under the simulated clock the stop starts exactly 8 cycles (the interpolator's lead
    // over the drives) after the cycle the bad answer answers, however the processes were
    // scheduled: the same stop every run, and in a replay.
    assert_eq!(
        info["stop_from_cycle"].as_u64().unwrap(),
        cycle + 8,
        "{info:#}"
    );
    assert_decelerated_on_the_diagonal(&sp, info);
    // The drives followed the stop to its end (the servo is fine, only over the limit).
    assert_eq!(fb.len(), sp.len());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `cnc log show --json` of a run directory.
fn log_blocks(run: &Path) -> Vec<Value> {
    let out = Command::new(cnc_exe())
        .args(["log", "show", "--json"])
        .arg(run)
        .output()
        .unwrap();
    assert!(out.status.success());
    let doc: Value = serde_json::from_slice(&out.stdout).unwrap();
    doc["blocks"].as_array().unwrap().clone()
}

#[test]
fn repeat_runs_the_program_n_times_with_contiguous_sequence_numbers() {
    let dir = temp_dir("repeat");
    // Ends away from the start, so each repeat is joined by a rapid back to it.
    let prog = write_program(&dir, "G21 G90\nG1 X10 F3000\nG2 X20 Y0 R5\nG1 Y8\nM2\n");
    let runs: Vec<_> = [1u32, 3]
        .iter()
        .map(|n| {
            let run = dir.join(format!("x{n}"));
            let out = Command::new(cnc_exe())
                .args(["run", "--clock", "sim", "--no-report", "--repeat"])
                .arg(n.to_string())
                .arg("--out")
                .arg(&run)
                .arg(&prog)
                .output()
                .unwrap();
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            run
        })
        .collect();
    let (one, three) = (&runs[0], &runs[1]);
    let b1 = log_blocks(one);
    let b3 = log_blocks(three);
    let body = b1.len() - 1;
    assert_eq!(b3.len(), 3 * body + 2 + 1, "3 bodies, 2 returns, 1 end");
    for (i, b) in b3.iter().enumerate() {
        assert_eq!(b["seq"].as_u64(), Some(i as u64), "contiguous");
        let is_end = b["kind"] == "end";
        assert_eq!(is_end, i + 1 == b3.len(), "one program end, the last block");
    }
    let returns: Vec<_> = b3.iter().filter(|b| b["line"] == 0).collect();
    assert_eq!(returns.len(), 2);
    assert!(returns.iter().all(|b| b["rapid"] == true));
    let (r1, r3) = (report(one), report(three));
    assert_eq!(r3["outcome"], "done");
    assert_eq!(r3["blocks"].as_u64(), Some(b3.len() as u64));
    // Three times the program's path plus two returns of |(20, 8)|.
    let back = (20.0f64 * 20.0 + 8.0 * 8.0).sqrt();
    let want = 3.0 * r1["path_length_mm"].as_f64().unwrap() + 2.0 * back;
    let got = r3["path_length_mm"].as_f64().unwrap();
    assert!(
        (got - want).abs() < 1e-6,
        "path {got} mm, expected {want} mm"
    );
    // Every repeat traces the very same set-points as the single run.
    let s1 = complete_csv(&one.join("setpoints.csv"));
    let s3 = complete_csv(&three.join("setpoints.csv"));
    let pos = |r: &Vec<f64>| (r[2], r[3], r[4], r[5]);
    // (All but the single run's final cycle, at rest on its program end.)
    let first: Vec<_> = s1[..s1.len() - 1].iter().map(pos).collect();
    let starts: Vec<usize> = (0..s3.len())
        .filter(|&i| {
            s3[i..]
                .iter()
                .map(pos)
                .take(first.len())
                .eq(first.iter().copied())
        })
        .collect();
    assert_eq!(
        starts.len(),
        3,
        "the program's set-points appear {} times",
        starts.len()
    );
    // Memory of each process at start and end of the run.
    let mem = r3["memory"].as_array().unwrap();
    let roles: Vec<_> = mem.iter().map(|m| m["role"].as_str().unwrap()).collect();
    assert_eq!(roles, ["servo-sim", "interpolator", "interpreter"]);
    for m in mem {
        let (s, e, x) = (
            m["start_kib"].as_u64().unwrap(),
            m["end_kib"].as_u64().unwrap(),
            m["max_kib"].as_u64().unwrap(),
        );
        assert!(s > 0 && e > 0 && s <= x && e <= x, "{m}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn no_progress_bar_when_stderr_is_not_a_terminal() {
    let dir = temp_dir("progress");
    let prog = write_program(&dir, "G1 X5 F3000\nM2\n");
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(dir.join("run"))
        .arg(&prog)
        .output()
        .unwrap();
    assert!(out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !err.contains('\r') && !err.contains("\x1b["),
        "progress drawn into a pipe: {err:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
