//! What `cnc check` accepts runs to its end (issue #22): for programs assembled at
//! random, with numbers from the tiny to the huge, and for the real LinuxCNC programs
//! mutated, a program the check accepts (read, checked, built, planned, every block
//! validated and within the machine's travel: [`process::compile_with`]) is stepped
//! through the interpolator's own engine ([`estimate::estimate_up_to`], what `cnc check
//! --estimate` runs), and the engine must not fault: no stall, no block it refuses.
//!
//! Each program is stepped for at most [`MAX_CYCLES`] cycles (a minute of motion at the
//! 1 ms period): a fault that would come later is out of reach, but every fault seen
//! before the fixes came at the first cycles of the block that caused it (a stall
//! two seconds in). Each case runs on a watched thread, as in `robustness.rs`.

use interpreter::estimate;
use interpreter::process;
use interpreter::program::Options;
use proptest::prelude::*;
use shared::Machine;
use std::sync::mpsc;
use std::time::Duration;

mod gen;
use gen::*;

const PERIOD_NS: u64 = 1_000_000;

/// Cycles stepped at most per program.
const MAX_CYCLES: u64 = 60_000;

/// Longer than any case could take unless it hangs.
const HANG: Duration = Duration::from_secs(120);

/// What became of a program: refused by the check, or how far it ran.
#[derive(Debug, PartialEq)]
enum Outcome {
    Refused,
    Ran,
    Faulted(String),
}

/// Checks `text` on the built-in machine and, when accepted, steps its blocks.
fn check_then_run(text: &str) -> Outcome {
    check_then_run_on(text, Machine::default())
}

fn check_then_run_on(text: &str, machine: Machine) -> Outcome {
    let owned = text.to_string();
    let (tx, rx) = mpsc::channel();
    let worker = std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || {
            let out = match process::compile_with(&owned, &Options::default(), &machine, PERIOD_NS)
            {
                Err(_) => Outcome::Refused,
                Ok((_, blocks)) => {
                    match estimate::estimate_up_to(&blocks, &machine, PERIOD_NS, MAX_CYCLES) {
                        Ok(_) => Outcome::Ran,
                        Err(e) => Outcome::Faulted(e),
                    }
                }
            };
            let _ = tx.send(out);
        })
        .expect("spawn a worker thread");
    match rx.recv_timeout(HANG) {
        Ok(o) => {
            let _ = worker.join();
            o
        }
        Err(mpsc::RecvTimeoutError::Disconnected) => match worker.join() {
            Err(p) => std::panic::resume_unwind(p),
            Ok(()) => panic!("worker ended without an answer"),
        },
        Err(mpsc::RecvTimeoutError::Timeout) => {
            panic!("still busy after {HANG:?}: a hang on {text:?}")
        }
    }
}

fn assert_runs(text: &str) -> Result<(), TestCaseError> {
    let o = check_then_run(text);
    prop_assert!(
        !matches!(o, Outcome::Faulted(_)),
        "accepted by check, faulted in the run: {o:?}\n{text}"
    );
    Ok(())
}

/// Numbers from the smallest to the largest a program can write, either sign, with
/// ordinary ones most often.
fn number() -> impl Strategy<Value = String> {
    prop_oneof![
        6 => (-200i32..200).prop_map(|v| v.to_string()),
        2 => (-50.0f64..50.0).prop_map(|v| format!("{v:.4}")),
        1 => prop::sample::select(vec![
            "0", "0.0000001", "-0.0000001", "0.001", "0.09", "0.1", "1000", "-1000", "999.9999",
            "1e5", "99999", "1000000", "[10**-300]", "[10**-20]", "[10**20]", "[10**200]",
            "[-10**300]", "[10**300]", "[1/3]",
        ])
        .prop_map(str::to_string),
    ]
}

/// Lines of every motion with such numbers: lines, arcs (centre and radius, turns),
/// Bézier splines, both NURBS forms, inverse time, dwells, blending, units, modes.
fn hostile_program() -> impl Strategy<Value = String> {
    let line =
        (0usize..22, number(), number(), number(), number()).prop_map(|(kind, a, b, c, d)| {
            match kind {
                0 => format!("G0 X{a} Y{b} Z{c}"),
                1 => format!("G1 X{a} Y{b} F{d}"),
                2 => format!("G1 Z{c}"),
                3 => format!("G2 X{a} Y{b} I{c} J{d}"),
                4 => format!("G3 X{a} Y{b} R{c}"),
                5 => format!("G2 X{a} Y{b} Z{c} I{d} J0 P2"),
                6 => format!("G5 X{a} Y{b} I{c} J{d} P{a} Q{b}"),
                7 => format!("G5.1 X{a} Y{b} I{c} J{d}"),
                8 => format!("G5.2 X{a} Y{b} P{c} L3"),
                9 => format!("X{a} Y{b} P{c}"),
                10 => "G5.3".to_string(),
                11 => format!("G6.2 X{a} Y{b} R1 K0 P3 Q1"),
                12 => format!("X{a} Y{b} R{c} K{d}"),
                13 => format!("G6.2 K{d}"),
                14 => format!("G93 G1 X{a} Y{b} F{d}"),
                15 => "G94".to_string(),
                16 => format!("G4 P{d}"),
                17 => format!("G64 P{c} Q{d}"),
                18 => "G61".to_string(),
                19 => format!("F{d}"),
                20 => "G91".to_string(),
                _ => "G90".to_string(),
            }
        });
    proptest::collection::vec(line, 0..12).prop_map(|l| format!("F600\n{}\nM2\n", l.join("\n")))
}

proptest! {
    #![proptest_config(cases(120))]

    /// Plausible programs: well-formed lines with random numbers.
    #[test]
    fn plausible_programs_that_check_run(text in plausible_program()) {
        assert_runs(&text)?;
    }

    /// Every motion with numbers from the tiny to the huge.
    #[test]
    fn hostile_programs_that_check_run(text in hostile_program()) {
        assert_runs(&text)?;
    }
}

proptest! {
    #![proptest_config(cases(40))]

    /// The real programs, mutated: what still checks must still run.
    #[test]
    fn mutated_peer_programs_that_check_run(
        which in any::<prop::sample::Index>(),
        edits in proptest::collection::vec(mutation(), 1..6),
    ) {
        let bytes = mutated_peer(which, &edits);
        assert_runs(&String::from_utf8_lossy(&bytes))?;
    }
}

/// The cases of issue #22, each refused by the check now; before, each passed the check
/// and then faulted the run (a stall, an engine refusal) or answered "internal".
#[test]
fn the_reported_inputs_are_refused_by_the_check() {
    for (text, rule) in [
        ("G1 X1 F[10**-300]\nM2\n", "feed"),
        ("G1 X1 F0.05\nM2\n", "feed"),
        ("G93 G1 X0.000001 F1\nM2\n", "G93"),
        ("G0 X[10**300]\nM2\n", "range"),
        ("G91 G0 X90000\nX90000\nM2\n", "range"),
        ("G1 F100\nG5 X1 Y1 I[10**200] J0 P0 Q1\nM2\n", "range"),
        ("G1 F100\nG2 X1 Y0 I[10**200] J0\nM2\n", "range"),
        ("G0 X10000\nM2\n", "travel"),
        ("G4 P[10**80]\nM2\n", "G4"),
    ] {
        let machine = Machine::default();
        let d = process::compile_with(text, &Options::default(), &machine, PERIOD_NS)
            .err()
            .unwrap_or_else(|| panic!("{text:?} passed the check"));
        assert_eq!(d[0].rule, rule, "{text:?}: {d:?}");
        assert!(d.iter().all(|d| d.rule != "internal"), "{text:?}: {d:?}");
    }
}

/// A helix of ten thousand turns of a metre's circle at the slowest feed would take
/// over ten years: refused for its time, not left to run for ever.
#[test]
fn a_program_too_long_to_count_is_refused() {
    let text = "G1 X-900 F600\nG2 X-900 Y0 Z100 I900 J0 P10000 F0.1\nM2\n";
    let d = process::compile_with(text, &Options::default(), &Machine::default(), PERIOD_NS)
        .expect_err("a helix of ten years");
    assert_eq!(d[0].rule, "time", "{d:?}");
    assert_eq!(d[0].line, 2, "{d:?}");
}

/// The machine's travel (`axes.*.min_mm`/`max_mm`): `check` refuses a path that leaves
/// it, judged on the exact path of the blocks that are sent (an arc by its extreme, a
/// helix's axis by its end), names the axis word's column, how far the path reaches and
/// the key; a circle that only touches a limit passes.
#[test]
fn paths_beyond_the_travel_are_refused_where_they_are_written() {
    let machine = Machine::default();
    let refused = |text: &str, m: &Machine| {
        let d = process::compile_with(text, &Options::default(), m, PERIOD_NS)
            .expect_err("beyond the travel");
        process::format_diagnostics("p.ngc", &d)
    };
    assert_eq!(
        refused("G0 X10000\nM2\n", &machine),
        "p.ngc:1:4: travel: this rapid move leaves the machine's travel: the path takes X up \
         to 10000 mm, 9000 mm above its travel limit of 1000 mm (axes.x.max_mm in the machine \
         file)\n"
    );
    // An arc whose ends are inside but whose bulge is not: at its extreme, 1200 mm.
    let shown = refused("G1 F1000\nG2 X0 Y0 I600 J0\nM2\n", &machine);
    assert!(
        shown.starts_with("p.ngc:2:4: travel: this move leaves the machine's travel: the path takes X up to 1200 mm, 200 mm above"),
        "{shown}"
    );
    // A helix's axis at its end; the axis word's column.
    let shown = refused("G1 F1000\nG2 X0 Y0 I5 J0 Z-1500\nM2\n", &machine);
    assert!(
        shown.starts_with("p.ngc:2:16: travel: this move leaves the machine's travel: the path takes Z down to -1500 mm"),
        "{shown}"
    );
    // Touching a limit is within it: a circle of radius 500 from the origin reaches
    // exactly X 1000.
    let ok = "G1 F1000\nG2 X0 Y0 I500 J0\nM2\n";
    assert!(process::compile_with(ok, &Options::default(), &machine, PERIOD_NS).is_ok());
    // A smaller travel, and a start outside it.
    let small = Machine::from_toml("[axes.x]\nmin_mm = 10.0\nmax_mm = 50.0\n").unwrap();
    let shown = refused("G0 X20\nM2\n", &small);
    assert!(
        shown.starts_with("p.ngc:1:1: travel: the machine starts at the origin (0, 0, 0), 10 mm below the travel limit of X at 10 mm (axes.x.min_mm in the machine file)"),
        "{shown}"
    );
}

/// A STEP-NC part whose passes (the tool reference point, 100 mm above the contact
/// point for its tool) leave the travel is refused by `cnc check` and by what a run
/// sends, naming the workingstep.
#[test]
fn a_part_beyond_the_travel_is_refused() {
    let text = include_str!("../../examples/seed-surface.stp");
    let low = Machine::from_toml("[axes.z]\nmin_mm = -100.0\nmax_mm = 50.0\n").unwrap();
    let e = interpreter::step::check::check_part("s.stp", text, &low).unwrap_err();
    assert!(e.starts_with("s.stp:129: #122: travel: "), "{e}");
    assert!(e.contains("axes.z.max_mm"), "{e}");
    let e = interpreter::surface_blocks::part_blocks(text, &low, PERIOD_NS).unwrap_err();
    assert_eq!(e[0].rule, "travel");
    assert!(interpreter::step::check::check_part("s.stp", text, &Machine::default()).is_ok());
}
