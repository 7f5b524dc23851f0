//! The whole stack on three threads of this one process, over iceoryx2's process-local
//! service type: the same `run` functions the processes use, generic over the transport.

use iceoryx2::prelude::local;
use interpolator::rt::sched::SchedMode;
use interpreter::checked::Checked;
use interpreter::process::Streaming;
use shared::clock::ClockMode;
use shared::Machine;
use std::path::Path;
use std::time::Duration;
use tests::{circle_errors, csv, temp_dir};

fn run_stack(
    dir: &Path,
    program: &str,
) -> (interpolator::summary::Summary, servo_sim::run::Summary) {
    let (i, ipol, servo) = start_stack(dir, program, Duration::from_secs(20), Streaming::default());
    let i = i.join().unwrap().unwrap();
    assert_eq!(i.outcome, "done", "{i:?}");
    (
        ipol.join().unwrap().unwrap(),
        servo.join().unwrap().unwrap(),
    )
}

type Joined<T, E> = std::thread::JoinHandle<Result<T, E>>;

/// The interpreter waits `hold` before it reads the program (a long plan).
fn held(hold: Duration) -> Streaming {
    Streaming {
        hold_before_reading: Some(hold),
        ..Default::default()
    }
}

/// The three roles on threads: the interpolator and the drives give up on a stack that
/// never starts after `start_timeout`; the interpreter streams as `streaming` says.
fn start_stack(
    dir: &Path,
    program: &str,
    start_timeout: Duration,
    streaming: Streaming,
) -> (
    Joined<interpreter::report::InterpreterSummary, String>,
    Joined<interpolator::summary::Summary, interpolator::rt::cycle::RunError>,
    Joined<servo_sim::run::Summary, shared::ipc::IpcError>,
) {
    let prog = dir.join("program.ngc");
    std::fs::write(&prog, program).unwrap();
    let prefix = format!(
        "thr{}_{}",
        std::process::id(),
        dir.file_name().unwrap().to_string_lossy()
    );
    let period_ns = 1_000_000;
    let servo_cfg = servo_sim::run::Config {
        prefix: prefix.clone(),
        out_dir: dir.to_path_buf(),
        period_ns,
        machine: Machine::default(),
        clock: ClockMode::Real,
        servo_clock: servo_sim::run::ServoClock::Lockstep,
        sched: SchedMode::Other,
        rt_priority: 1,
        start_timeout,
        idle_timeout: Duration::from_secs(5),
    };
    let ipol_cfg = interpolator::rt::cycle::Config {
        prefix: prefix.clone(),
        out_dir: dir.to_path_buf(),
        period_ns,
        machine: Machine::default(),
        sched: SchedMode::Other,
        rt_priority: interpolator::rt::sched::DEFAULT_PRIORITY,
        clock: ClockMode::Real,
        start_timeout,
    };
    let interp_cfg = interpreter::process::Config {
        prefix,
        out_dir: dir.to_path_buf(),
        period_ns,
        machine: Machine::default(),
        program: Some(prog),
        program_name: None,
        replay: None,
        salvage: false,
    };
    let servo = std::thread::spawn(move || servo_sim::run::run::<local::Service>(&servo_cfg));
    let ipol =
        std::thread::spawn(move || interpolator::rt::cycle::run::<local::Service>(&ipol_cfg));
    let interp = std::thread::spawn(move || {
        interpreter::process::run_streaming::<local::Service>(&interp_cfg, streaming)
    });
    (interp, ipol, servo)
}

#[test]
fn a_program_that_plans_longer_than_the_start_timeouts_still_runs() {
    // A program of 50 000 lines of curves plans for about 20 s, and the interpolator gave
    // up on its first block after 20 s ("timed out waiting for the first command block"):
    // such a program could not run at all. Here the plan takes 4 s against start
    // timeouts of 1 s.
    let dir = temp_dir("thr-long-plan");
    let (i, ipol, servo) = start_stack(
        &dir,
        "G1 X5 F3000\nM2\n",
        Duration::from_secs(1),
        held(Duration::from_secs(4)),
    );
    let i = i.join().unwrap().unwrap();
    assert_eq!(i.outcome, "done", "{i:?}");
    let ipol = ipol.join().unwrap().unwrap();
    assert_eq!(ipol.outcome, "done", "{:?}", ipol.fault);
    let servo = servo.join().unwrap().unwrap();
    assert_eq!(servo.outcome, "done", "{:?}", servo.fault);
    let (_, sp) = csv(&dir.join("setpoints.csv"));
    assert_eq!(sp.last().unwrap()[2], 5.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_interpreter_that_leaves_before_its_first_block_ends_the_wait_at_once() {
    // A program the interpreter refuses (`cnc run` checks it first; a role started by
    // hand does not): the interpolator and the drives wait for nothing, not for their
    // start timeouts (a minute here), and say why.
    let dir = temp_dir("thr-left");
    let t = std::time::Instant::now();
    let (i, ipol, servo) = start_stack(
        &dir,
        "G1 X5 F3000\nG1 X\nM2\n",
        Duration::from_secs(60),
        // (Long enough for the interpolator to see the interpreter come on a loaded machine.)
        held(Duration::from_secs(2)),
    );
    let e = i.join().unwrap().unwrap_err();
    assert!(e.contains(":2:"), "{e}");
    let e = ipol.join().unwrap().unwrap_err();
    assert!(e.to_string().starts_with("the interpreter left"), "{e}");
    let servo = servo.join().unwrap().unwrap();
    let f = servo.fault.unwrap_or_default();
    assert!(
        f.starts_with(
            "the interpolator is gone (its process ended or died) before its first set-point"
        ),
        "{f}"
    );
    // The drives look once every 20 ms; generous for a loaded machine.
    assert!(t.elapsed() < Duration::from_secs(20), "{:?}", t.elapsed());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The record `cnc run` writes of its check of `program` (`checked.json` in `dir`).
fn launchers_check(dir: &Path, program: &str) -> std::path::PathBuf {
    let machine = Machine::default();
    let opts = interpreter::program::Options::default();
    let planned = interpreter::process::check_windows(
        program,
        &opts,
        &machine,
        1_000_000,
        &mut |_, _| {},
        &mut |_, _| {},
    )
    .expect("the launcher checks a good program");
    let digest = interpreter::checked::digest(program.as_bytes(), &mut |_, _| {});
    let path = dir.join(interpreter::checked::FILE);
    Checked::of(&planned, digest, false, &machine, 1_000_000)
        .expect("no file read")
        .write(&path)
        .unwrap();
    path
}

#[test]
fn the_launchers_check_is_taken_for_the_text_it_checked() {
    let dir = temp_dir("thr-checked");
    let program = "(MSG, hello)\nG1 X5 F3000\nG1 Y5\nM2\n";
    let checked = launchers_check(&dir, program);
    let (i, ipol, servo) = start_stack(
        &dir,
        program,
        Duration::from_secs(20),
        Streaming {
            checked: Some(checked),
            ..Default::default()
        },
    );
    let i = i.join().unwrap().unwrap();
    assert_eq!(i.outcome, "done", "{i:?}");
    assert_eq!(i.checked_by.as_deref(), Some("launcher"));
    // What the check found, in the interpreter's summary as when it checks itself.
    assert_eq!(i.messages, vec![(1, "hello".to_string())]);
    assert_eq!((i.dialect.as_deref(), i.blocks), (Some("linuxcnc"), 3));
    assert_eq!(ipol.join().unwrap().unwrap().outcome, "done");
    assert_eq!(servo.join().unwrap().unwrap().outcome, "done");
    let (_, sp) = csv(&dir.join("setpoints.csv"));
    assert_eq!(&sp.last().unwrap()[2..4], &[5.0, 5.0]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_copy_that_is_not_the_text_checked_is_checked_again_before_any_motion() {
    // The launcher checked a good program; the interpreter's copy has since changed, and
    // a line far into it (past the first windows, each ending at a dwell) is bad. Taken
    // on trust, the first windows would move the machine and the bad line stop it
    // mid-program: the digest differs, so the interpreter checks the copy itself and
    // refuses it before anything is sent.
    let dir = temp_dir("thr-not-checked");
    let program = |last: &str| {
        let mut p = String::from("G1 X5 F3000\n");
        for i in 0..3000 {
            p.push_str(&format!("G1 Y{}\nG4 P0.01\n", (i % 2) * 5));
        }
        p.push_str(last);
        p.push_str("M2\n");
        p
    };
    let checked = launchers_check(&dir, &program("G1 X6\n"));
    let (i, ipol, servo) = start_stack(
        &dir,
        &program("G1 X\n"),
        Duration::from_secs(60),
        Streaming {
            checked: Some(checked),
            // (Long enough for the interpolator to see the interpreter come on a loaded
            // machine, as above.)
            ..held(Duration::from_secs(2))
        },
    );
    let e = i.join().unwrap().unwrap_err();
    assert!(e.contains(":6002:"), "{e}");
    assert!(!e.contains("read again"), "{e}");
    let e = ipol.join().unwrap().unwrap_err();
    assert!(e.to_string().starts_with("the interpreter left"), "{e}");
    let _ = servo.join().unwrap();
    let rows =
        std::fs::read_to_string(dir.join("setpoints.csv")).map_or(0, |t| t.lines().skip(1).count());
    assert_eq!(rows, 0, "set-points sent");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn long_line_runs_at_the_programmed_feed() {
    let dir = temp_dir("thr-line");
    let (ipol, servo) = run_stack(&dir, "G1 X200 F3000\nM2\n");
    assert_eq!(ipol.outcome, "done", "{:?}", ipol.fault);
    assert_eq!(servo.outcome, "done");
    assert_eq!(servo.lost_setpoints, 0);
    // 200 mm at 50 mm/s with two S-curve ramps (2000 mm/s², 50 000 mm/s³): each takes
    // 50/2000 + 2000/50000 = 65 ms over 25 mm/s · 65 ms = 1.625 mm, so the move takes
    // 2 · 0.065 + (200 - 3.25) / 50 = 4.065 s: an average of 2952.0 mm/min.
    let want = 200.0 / (2.0 * 0.065 + (200.0 - 3.25) / 50.0) * 60.0;
    assert!(
        (ipol.avg_feed_mm_per_min / want - 1.0).abs() < 0.002,
        "average feed {} against {want}",
        ipol.avg_feed_mm_per_min
    );
    let (_, sp) = csv(&dir.join("setpoints.csv"));
    // Away from the ramps, every step is exactly 0.05 mm (F3000 at 1 ms).
    let steps: Vec<f64> = sp.windows(2).map(|w| w[1][2] - w[0][2]).collect();
    let cruise = &steps[100..steps.len() - 100];
    assert!(
        cruise.iter().all(|s| (s - 0.05).abs() < 1e-9),
        "uneven cruise steps"
    );
    assert_eq!(sp.last().unwrap()[2], 200.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn helix_and_full_circle_in_one_process() {
    let dir = temp_dir("thr-helix");
    let (ipol, _) = run_stack(
        &dir,
        "G0 X5\nG3 X5 Y0 Z-1 I-5 J0 P2 F1200\nG3 X5 Y0 I-5 J0\nM2\n",
    );
    assert_eq!(ipol.outcome, "done", "{:?}", ipol.fault);
    let (_, sp) = csv(&dir.join("setpoints.csv"));
    let arcs: Vec<_> = sp.iter().filter(|r| r[5] == 2.0 || r[5] == 3.0).collect();
    let (radial, sagitta) = circle_errors(&arcs, [0.0, 0.0], 5.0);
    assert!(radial < 1e-6, "{radial}");
    assert!(sagitta < 0.001, "{sagitta}");
    // The helix goes down 1 mm over two turns, steadily; the circle after it stays there.
    let helix: Vec<f64> = sp.iter().filter(|r| r[5] == 2.0).map(|r| r[4]).collect();
    assert!(
        helix.windows(2).all(|w| w[1] <= w[0]),
        "z never rises on the way down"
    );
    assert!(
        sp.iter()
            .filter(|r| r[5] == 3.0)
            .all(|r| (r[4] + 1.0).abs() < 1e-9),
        "circle at Z-1"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
