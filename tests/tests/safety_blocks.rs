//! The interpolator trusts no block it was not built to: with the real processes, command
//! logs edited after the fact (their CRCs recomputed, so only the interpolator's own
//! checks against its machine can catch them) and a discontinuous G6.2 curve as a
//! command block. Each fails on the engine before issue #22: the feed ran at 35 623
//! mm/min against 10 000, the edited start jumped 5 mm in one cycle, the G6.2 1.414 mm.
//!
//! Nothing here asserts a duration.

use serde_json::Value;
use shared::cmdlog::{self, CommandLog};
use shared::machine::Machine;
use shared::path;
use shared::protocol::{BlockKind, CommandBlock, FLAG_RAPID};
use std::path::{Path, PathBuf};
use std::process::Command;
use tests::{cnc_exe, csv, report, temp_dir};

/// A square of 60 by 40 mm at F3000 from the origin, one block per side.
const SQUARE: &str = "G21 G90\nG1 X60 F3000\nG1 Y40\nG1 X0\nG1 Y0\nM2\n";

/// Runs `program` (simulated clock) into `dir/run` and returns its command log's blocks
/// and header.
fn run_and_log(dir: &Path, program: &str) -> cmdlog::Parsed {
    let prog = dir.join("program.ngc");
    std::fs::write(&prog, program).unwrap();
    let run = dir.join("run");
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(&run)
        .arg(&prog)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "the unedited run: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let parsed = cmdlog::read(&run.join("commands.log")).unwrap();
    assert!(parsed.damage.is_none());
    parsed
}

/// Writes `blocks` as a command log with a valid header and every record's CRC computed
/// afresh, as a hand edit that knows the format would.
fn write_log(path: &Path, header: &cmdlog::Header, blocks: &[CommandBlock]) {
    let mut log =
        CommandLog::create(path, header.period_ns, header.machine_hash, &header.program).unwrap();
    for b in blocks {
        log.append(b).unwrap();
    }
    log.finish().unwrap();
}

/// Replays `log` (simulated clock) into `dir/replay`: the exit code, the fault the report
/// names, and the set-points `[x, y, z]`.
fn replay(dir: &Path, log: &Path) -> (Option<i32>, String, Vec<[f64; 3]>) {
    let out_dir = dir.join("replay");
    let out = Command::new(cnc_exe())
        .args(["replay", "--clock", "sim", "--no-report", "--out"])
        .arg(&out_dir)
        .arg(log)
        .output()
        .unwrap();
    let rep: Value = report(&out_dir);
    let fault = rep["fault"].as_str().unwrap_or_default().to_string();
    let (_, rows) = csv(&out_dir.join("setpoints.csv"));
    let sp = rows.iter().map(|r| [r[2], r[3], r[4]]).collect();
    (out.status.code(), fault, sp)
}

/// The largest set-point step on each axis, mm.
fn largest_steps(sp: &[[f64; 3]]) -> [f64; 3] {
    let mut m = [0.0f64; 3];
    for w in sp.windows(2) {
        for a in 0..3 {
            m[a] = m[a].max((w[1][a] - w[0][a]).abs());
        }
    }
    m
}

/// `max_vel·period` of each axis of the default machine at 1 ms, mm.
fn max_axis_steps() -> [f64; 3] {
    Machine::default()
        .axes
        .as_array()
        .map(|a| a.max_vel_mm_per_min / 60.0 * 1e-3 * (1.0 + 1e-9))
}

/// No set-point step of `sp` is larger than an axis of the default machine can make in
/// one 1 ms period.
fn assert_no_step_beyond_the_axes(sp: &[[f64; 3]]) {
    let (most, allowed) = (largest_steps(sp), max_axis_steps());
    for a in 0..3 {
        assert!(
            most[a] <= allowed[a],
            "axis {a}: {most:?} against {allowed:?}"
        );
    }
}

#[test]
fn a_log_edited_to_feed_1e6_is_refused_naming_the_block_and_field() {
    let dir = temp_dir("safety-feed");
    let parsed = run_and_log(&dir, SQUARE);
    let mut blocks = parsed.blocks.clone();
    // The third side (block 2, line 4) at 1e6 mm/min.
    assert_eq!(blocks[2].source_line, 4);
    blocks[2].feed_mm_per_min = 1e6;
    let log = dir.join("edited.log");
    write_log(&log, &parsed.header, &blocks);
    let (code, fault, sp) = replay(&dir, &log);
    assert_eq!(code, Some(1), "refused: {fault}");
    assert!(
        fault.contains(
            "block 2 (line 4): feed_mm_per_min: 1000000 is above the machine's \
             max_feed_mm_per_min of 10000"
        ),
        "{fault}"
    );
    // Never faster than the machine's feed: 10 000 mm/min is 0.1667 mm per 1 ms cycle.
    let feed_step = 10_000.0 / 60.0 * 1e-3 * (1.0 + 1e-9);
    for w in sp.windows(2) {
        let d = path::norm([w[1][0] - w[0][0], w[1][1] - w[0][1], w[1][2] - w[0][2]]);
        assert!(d <= feed_step, "a step of {d} mm in one cycle: {w:?}");
    }
    // And it never ran the edited side (X back from 60 towards 0 at Y = 40).
    assert!(
        sp.iter().all(|p| p[1] < 40.0 || p[0] == 60.0),
        "ran block 2"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_log_edited_to_start_5_mm_away_is_refused_before_the_jump() {
    let dir = temp_dir("safety-gap");
    let parsed = run_and_log(&dir, SQUARE);
    let mut blocks = parsed.blocks.clone();
    // The second side (block 1, line 3) moved 5 mm along X: it starts at (65, 0).
    assert_eq!(blocks[1].source_line, 3);
    let n = blocks[1].n_ctrl as usize;
    for c in blocks[1].ctrl.iter_mut().take(n) {
        c[0] += 5.0;
    }
    let log = dir.join("edited.log");
    write_log(&log, &parsed.header, &blocks);
    let (code, fault, sp) = replay(&dir, &log);
    assert_eq!(code, Some(1), "refused: {fault}");
    assert!(
        fault
            .contains("block 1 (line 3): start: the path starts 5.000 mm from where block 0 ended"),
        "{fault}"
    );
    assert_no_step_beyond_the_axes(&sp);
    assert!(
        sp.iter().all(|p| p[0] <= 60.0 && p[1] == 0.0),
        "left the first side"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_g62_curve_broken_at_a_knot_is_refused_as_a_command_block() {
    // The LinuxCNC G6.2 of issue #22 as the interpreter sends it, order 3 with the knots
    // 0 0 0 1 1 1 2 2 2: two parabolas, the second starting (1, 1) mm from where the
    // first ends, after a line to its start. Made by hand, whatever `cnc check` thinks.
    let dir = temp_dir("safety-g62");
    let machine = Machine::default();
    let mut line = tests::line_block(0, 2);
    line.end_feed_mm_per_min = 3000.0;
    let mut g62 = line;
    g62.seq = 1;
    g62.source_line = 3;
    g62.degree = 2;
    g62.n_ctrl = 6;
    g62.knots[..9].copy_from_slice(&[0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 2.0, 2.0]);
    for (i, (x, y)) in [
        (10.0, 0.0),
        (11.0, 0.5),
        (12.0, 0.0),
        (13.0, 1.0),
        (14.0, 1.5),
        (15.0, 1.0),
    ]
    .into_iter()
    .enumerate()
    {
        g62.ctrl[i] = [x, y, 0.0, 1.0];
    }
    g62.start_feed_mm_per_min = 3000.0;
    g62.end_feed_mm_per_min = 0.0;
    g62.length_mm = 5.0;
    let blocks = [g62, CommandBlock::empty(BlockKind::ProgramEnd, 2, 4)];
    let blocks = [&[line][..], &blocks[..]].concat();
    for b in &blocks {
        b.validate().unwrap();
    }
    let header = cmdlog::Header {
        format_version: cmdlog::FORMAT_VERSION,
        protocol_version: shared::protocol::PROTOCOL_VERSION,
        period_ns: 1_000_000,
        machine_hash: machine.hash(),
        program: "g62-broken.ngc".into(),
    };
    let log = dir.join("commands.log");
    write_log(&log, &header, &blocks);
    let (code, fault, sp) = replay(&dir, &log);
    assert_eq!(code, Some(1), "refused: {fault}");
    assert!(
        fault.contains("block 1 (line 3): knots: the curve jumps 1.414 mm at the knot 1"),
        "{fault}"
    );
    assert_no_step_beyond_the_axes(&sp);
    assert!(
        sp.iter().all(|p| p[0] <= 10.0 && p[1] == 0.0),
        "left the line"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The real programs the tolerances are measured on: the demo, the STEP-NC examples and
/// the LinuxCNC suite.
fn real_programs() -> Vec<(String, String)> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut files: Vec<PathBuf> = vec![root.join("interpreter/src/demo.ngc")];
    for dir in ["examples", "tests/peers/linuxcnc"] {
        let mut more: Vec<PathBuf> = std::fs::read_dir(root.join(dir))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "ngc" || x == "stp"))
            .collect();
        more.sort();
        files.extend(more);
    }
    let mut programs: Vec<(String, String)> = files
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(&p).unwrap();
            (p.file_name().unwrap().to_string_lossy().into_owned(), text)
        })
        .collect();
    // Helices of many turns, arcs by radius, and a Fanuc program.
    programs.push((
        "helices.ngc".into(),
        "G21 G90 G17\nG0 X10 Y0 Z0\nG2 X10 Y0 Z-50 I-10 J0 P100 F2000\nG3 X-10 Y0 Z-20 \
         I-10 J0 P7 F3000\nG18 G2 X30 Z-20 I20 K0 P3 Y40\nG19 G3 Y70 Z-20 J15 K0 P2 X-5\nM2\n"
            .into(),
    ));
    programs.push((
        "radius-arcs.ngc".into(),
        "G21 G90 G17\nG1 X0 Y0 F4000\nG2 X300.123456 Y7.654321 R500\nG3 X0.1 Y0.2 R-900\n\
         G2 X0.100001 Y0.2 I450 J-3\nM2\n"
            .into(),
    ));
    programs
}

/// Measures, on every real program: the largest gap between a motion block's start and
/// where the previous one ended (set-points: the tool point of surface blocks), the
/// largest set-point step per axis against `max_vel·period`, and the planned values
/// against the machine's limits. Not a check: the figures behind the tolerances
/// (`cargo test --release -p tests --test safety_blocks -- --ignored --nocapture`).
#[test]
#[ignore]
fn measure_gaps_and_steps_on_real_programs() {
    let fast = "rapid_mm_per_min = 30000.0\nmax_feed_mm_per_min = 20000.0\n";
    for machine in [Machine::default(), Machine::from_toml(fast).unwrap()] {
        for period_ns in [1_000_000u64, 250_000] {
            println!(
                "machine rapid {} max_feed {}, period {period_ns} ns",
                machine.rapid_mm_per_min, machine.max_feed_mm_per_min
            );
            measure(&machine, period_ns);
        }
    }
}

fn measure(machine: &Machine, period_ns: u64) {
    use interpolator::engine::{BlockSource, Engine, Limits, TickState};
    struct Slice<'a>(&'a [CommandBlock], usize);
    impl BlockSource for Slice<'_> {
        fn next_block(&mut self) -> Option<CommandBlock> {
            let b = self.0.get(self.1).copied();
            self.1 += usize::from(b.is_some());
            b
        }
    }
    let t = period_ns as f64 * 1e-9;
    let vmax: Vec<f64> = machine
        .axes
        .as_array()
        .iter()
        .map(|a| a.max_vel_mm_per_min / 60.0)
        .collect();
    let (mut worst_gap, mut worst_step, mut worst_plan) = (0.0f64, 0.0f64, 0.0f64);
    for (name, text) in real_programs() {
        let compiled = interpreter::process::compile_source(
            &name,
            &text,
            &Default::default(),
            machine,
            period_ns,
        );
        let blocks = match compiled {
            Ok(c) => c.blocks,
            Err(e) => {
                println!("{name}: not compiled: {e}");
                continue;
            }
        };
        let mut at = [0.0f64; 3];
        let (mut gap, mut plan) = (0.0f64, 0.0f64);
        for b in blocks.iter().filter(|b| b.kind == BlockKind::Motion as u32) {
            let (u0, u1) = path::domain(b);
            let p0 = path::eval(b, u0).p;
            gap = gap.max(path::norm([p0[0] - at[0], p0[1] - at[1], p0[2] - at[2]]));
            at = path::eval(b, u1).p;
            let cap = if b.flags & FLAG_RAPID != 0 {
                machine.rapid_mm_per_min
            } else {
                machine.max_feed_mm_per_min
            };
            for r in [
                b.feed_mm_per_min / cap,
                b.start_feed_mm_per_min / b.feed_mm_per_min,
                b.end_feed_mm_per_min / b.feed_mm_per_min,
                b.acc_mm_per_s2 / machine.path_acc_mm_per_s2,
                b.jerk_mm_per_s3 / machine.path_jerk_mm_per_s3,
            ] {
                plan = plan.max(r);
            }
        }
        // The travel widened: the R-900 arc bulges out to X = 1028 mm (a refusal of
        // its own, not what is measured here).
        let mut lim = Limits::new(machine, period_ns);
        for a in [
            &mut lim.machine.axes.x,
            &mut lim.machine.axes.y,
            &mut lim.machine.axes.z,
        ] {
            (a.min_mm, a.max_mm) = (-1e5, 1e5);
        }
        let mut engine = Engine::new(lim, [0.0; 3]);
        let mut src = Slice(&blocks, 0);
        let mut last = engine.position();
        let mut step = 0.0f64;
        let mut fault = None;
        for _ in 0..100_000_000u64 {
            match engine.tick(&mut src) {
                Ok(tick) => {
                    for a in 0..3 {
                        step = step.max((tick.pos_mm[a] - last[a]).abs() / (vmax[a] * t));
                    }
                    last = tick.pos_mm;
                    if tick.state == TickState::Done {
                        break;
                    }
                }
                Err(f) => {
                    fault = Some(f.to_string());
                    break;
                }
            }
        }
        println!(
            "{name}: {} blocks, largest start gap {gap:.3e} mm, largest axis step 1{:+.3e} of \
             max_vel·period, planned values at most 1{:+.3e} of the machine's{}",
            blocks.len(),
            step - 1.0,
            plan - 1.0,
            fault.map(|f| format!(", FAULT {f}")).unwrap_or_default()
        );
        worst_gap = worst_gap.max(gap);
        worst_step = worst_step.max(step);
        worst_plan = worst_plan.max(plan);
    }
    println!(
        "all: largest start gap {worst_gap:.3e} mm, largest axis step 1{:+.3e} of \
         max_vel·period, planned values at most 1{:+.3e} of the machine's",
        worst_step - 1.0,
        worst_plan - 1.0
    );
}

/// The program of issue #22 itself: a LinuxCNC G6.2 of order 3 whose interior knot is
/// repeated 3 times, the control points jumping there. Before, `cnc check` passed it and
/// `cnc run --clock sim` moved 1.414 mm in one 1 ms cycle and reported done. Now it is
/// refused, by `cnc check` or by the interpolator (the interpreter sends each knot span as
/// a block, so the second starts 1.414 mm from where the first ended), and nothing jumps.
#[test]
fn the_broken_g62_program_never_jumps() {
    let dir = temp_dir("safety-g62-program");
    let prog = dir.join("g62.ngc");
    std::fs::write(
        &prog,
        "G21 G90 G17\nG1 X0 Y0 F3000\nG6.2 X0 Y0 R1 K0 P3 Q1\nG6.2 X1 Y0.5 R1 K0\n\
         G6.2 X2 Y0 R1 K0\nG6.2 X3 Y1 R1 K1\nG6.2 X4 Y1.5 R1 K1\nG6.2 X5 Y1 R1 K1\n\
         G6.2 K2\nG6.2 K2\nG6.2 K2\nM2\n",
    )
    .unwrap();
    let run = dir.join("run");
    let out = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(&run)
        .arg(&prog)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(out.status.code(), Some(1), "refused: {text}");
    // Refused by the interpolator: it stood still. (Refused by `cnc check`: no run.)
    if run.join("setpoints.csv").exists() {
        let (_, rows) = csv(&run.join("setpoints.csv"));
        let sp: Vec<[f64; 3]> = rows.iter().map(|r| [r[2], r[3], r[4]]).collect();
        assert_no_step_beyond_the_axes(&sp);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
