//! The whole stack on three threads of this one process, over iceoryx2's process-local
//! service type: the same `run` functions the processes use, generic over the transport.

use iceoryx2::prelude::local;
use interpolator::rt::sched::SchedMode;
use shared::clock::ClockMode;
use shared::Machine;
use std::path::Path;
use std::time::Duration;
use tests::{circle_errors, csv, temp_dir};

fn run_stack(
    dir: &Path,
    program: &str,
) -> (interpolator::summary::Summary, servo_sim::run::Summary) {
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
        start_timeout: Duration::from_secs(20),
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
        start_timeout: Duration::from_secs(20),
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
    let servo =
        std::thread::spawn(move || servo_sim::run::run::<local::Service>(&servo_cfg).unwrap());
    let ipol = std::thread::spawn(move || {
        interpolator::rt::cycle::run::<local::Service>(&ipol_cfg).unwrap()
    });
    let interp = std::thread::spawn(move || {
        interpreter::process::run::<local::Service>(&interp_cfg).unwrap()
    });
    let i = interp.join().unwrap();
    assert_eq!(i.outcome, "done", "{i:?}");
    (ipol.join().unwrap(), servo.join().unwrap())
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
