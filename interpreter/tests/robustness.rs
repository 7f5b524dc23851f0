//! What `cnc check` does with input it was never meant to see (issue #5): arbitrary
//! bytes, programs assembled from random G-code words, and the real LinuxCNC programs of
//! `tests/peers/linuxcnc` mutated character by character. Whatever comes in, the checker
//! (read, check, build blocks, plan: [`process::compile_with`]) must answer without
//! panicking and without hanging, and every diagnostic it gives must point into the
//! input: a 1-based line that exists and a 1-based column within that line (or just
//! past its end), with a rule and a message.
//!
//! A hang would stall CI until its own limit and say nothing; so each case runs on a
//! worker thread watched by [`HANG`], far above what any case takes (milliseconds). That
//! is a liveness check, not a speed assertion: speed is measured in `benches/check.rs`.
//!
//! The regression tests at the end are the cases these properties found, each fixed in
//! the interpreter.

use interpreter::parse::Diagnostic;
use interpreter::process;
use interpreter::program::Options;
use proptest::prelude::*;
use shared::Machine;
use std::sync::mpsc;
use std::time::Duration;

mod gen;

/// Longer than any case could take unless it hangs.
const HANG: Duration = Duration::from_secs(60);

const PERIOD_NS: u64 = 1_000_000;

/// Checks `text` as `cnc check` does, on a watched thread; the diagnostics, or none.
fn check(text: &str) -> Vec<Diagnostic> {
    let owned = text.to_string();
    let (tx, rx) = mpsc::channel();
    let worker = std::thread::Builder::new()
        .stack_size(8 << 20)
        .spawn(move || {
            let machine = Machine::default();
            let r = process::compile_with(&owned, &Options::default(), &machine, PERIOD_NS);
            let _ = tx.send(r.err().unwrap_or_default());
        })
        .expect("spawn a checker thread");
    match rx.recv_timeout(HANG) {
        Ok(d) => {
            let _ = worker.join();
            d
        }
        Err(mpsc::RecvTimeoutError::Disconnected) => {
            // The worker died without answering: it panicked; re-raise its panic here so
            // proptest shrinks the input.
            match worker.join() {
                Err(p) => std::panic::resume_unwind(p),
                Ok(()) => panic!("checker thread ended without an answer"),
            }
        }
        Err(mpsc::RecvTimeoutError::Timeout) => {
            panic!("checker still busy after {HANG:?}: a hang on {text:?}")
        }
    }
}

/// Every diagnostic points into `text`: the line exists, the column is within the line
/// or one past its end, and there is a rule and a message. The program's text is read
/// as `cnc check` reads a file (lossy UTF-8) and split as the interpreter splits it.
fn assert_located(text: &str, diags: &[Diagnostic]) -> Result<(), TestCaseError> {
    let lines: Vec<&str> = text.lines().collect();
    for d in diags {
        let n = lines.len().max(1) as u32;
        prop_assert!(d.line >= 1 && d.line <= n, "line {} of {n}: {d:?}", d.line);
        let len = lines
            .get(d.line as usize - 1)
            .map_or(0, |l| l.chars().count()) as u32;
        prop_assert!(
            d.col >= 1 && d.col <= len + 1,
            "col {} of a {len}-character line: {d:?}",
            d.col
        );
        prop_assert!(!d.rule.is_empty() && !d.message.is_empty(), "{d:?}");
        let shown = process::format_diagnostics("p.ngc", std::slice::from_ref(d));
        let prefix = format!("p.ngc:{}:{}: {}: ", d.line, d.col, d.rule);
        prop_assert!(shown.starts_with(&prefix), "{shown}");
    }
    Ok(())
}

fn check_bytes(bytes: &[u8]) -> Result<(), TestCaseError> {
    let text = String::from_utf8_lossy(bytes);
    let diags = check(&text);
    assert_located(&text, &diags)
}

// The generators and mutations live in `gen` (shared with `check_runs.rs`).
use gen::*;

proptest! {
    #![proptest_config(cases(400))]

    /// Arbitrary bytes: invalid UTF-8, NULs, control characters, anything.
    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        check_bytes(&bytes)?;
    }

    /// Lines assembled from G-code pieces: brackets, parameters, flow, curves, all mixed.
    #[test]
    fn random_words_never_panic(text in token_program()) {
        check_bytes(text.as_bytes())?;
    }

    /// Well-formed lines with random numbers: arcs, curves and the planner get them.
    #[test]
    fn plausible_programs_never_panic(text in plausible_program()) {
        check_bytes(text.as_bytes())?;
    }
}

proptest! {
    #![proptest_config(cases(300))]

    /// The real programs, mutated: deleted, repeated and swapped characters, changed
    /// digits, dropped words, inserted letters, repeated lines.
    #[test]
    fn mutated_peer_programs_never_panic(
        which in any::<prop::sample::Index>(),
        edits in proptest::collection::vec(mutation(), 1..6),
    ) {
        let bytes = mutated_peer(which, &edits);
        check_bytes(&bytes)?;
    }
}

/// The unmutated peers check clean (the mutation test starts from working programs),
/// but for the one that uses LinuxCNC's `G2.2`, which this stack refuses.
#[test]
fn peers_check_clean() {
    for (name, text) in peers() {
        let d = check(text);
        if name.ends_with("g5_curva_stella.ngc") {
            assert_eq!(d[0].to_string(), "12:1: modal: G2.2 is not supported");
            continue;
        }
        assert!(d.is_empty(), "{name}: {d:?}");
    }
}

/// Deep brackets, long runs of signs and of `#`, and the longest lines, everywhere a
/// value may stand.
#[test]
fn deep_nesting_is_an_error_not_a_crash() {
    for text in [
        format!("G1 X{}1", "[".repeat(250)),
        format!("G1 X{}1{}", "[".repeat(120), "]".repeat(120)),
        format!("G1 X{}1", "-".repeat(250)),
        format!("#1={}1", "#".repeat(250)),
        format!("G1 XSIN{}", "[SIN".repeat(60)),
        "[".repeat(100_000),
        "(".repeat(100_000),
        "\u{0}".repeat(10_000),
        format!("{}\n", "G1 X1\n".repeat(20_000)),
    ] {
        let d = check(&text);
        assert_located(&text, &d).unwrap_or_else(|e| panic!("{e}"));
    }
}

/// Found by `plausible_programs_never_panic`: an arc of `P99999999` turns became
/// hundreds of millions of blocks and kept the checker busy for hours.
#[test]
fn arc_turn_count_is_bounded() {
    let text = "G2 X0 Y0 I1 J0 P99999999 F100\n";
    let d = check(text);
    assert_eq!(
        d[0].to_string(),
        "1:16: arc: arc turn count P must be a whole number from 1 to 10000"
    );
    assert!(check("G2 X0 Y0 I1 J0 P10000 F100\n").is_empty());
}

/// A loop that never ends stops at a bound on the lines it runs again, not only on its
/// turns: a million turns of a long body would keep `check` busy for minutes.
#[test]
fn endless_loops_with_long_bodies_stop() {
    let body = "#1=[#1+1]\n".repeat(200);
    let text = format!("o1 while [1]\n{body}o1 endwhile\n");
    let d = check(&text);
    assert_eq!(d.len(), 1, "{d:?}");
    assert_eq!(d[0].rule, "O-word");
    assert!(d[0].message.contains("is a loop endless?"), "{d:?}");
    assert_located(&text, &d).unwrap_or_else(|e| panic!("{e}"));
}

/// Numbers at the ends of what a line can hold are answered, not crashed on.
#[test]
fn huge_and_tiny_numbers_are_answered() {
    let big = format!("1{}", "0".repeat(80));
    let tiny = format!("0.{}1", "0".repeat(80));
    for text in [
        format!("G1 X{big} F100\n"),
        format!("G1 X1 F{tiny}\n"),
        format!("G4 P{big}\n"),
        format!("G93 G1 X1 F{big}\n"),
        format!("G2 X1 Y0 R0.5 F{big}\n"),
        format!("G2 X{big} Y0 R-{big} F100\n"),
        format!(
            "F100\nG5.2 P1 L10\nX1 Y1 P{tiny}\nX2 Y0 P{big}\n{}G5.3\n",
            "X3 Y1 P1\n".repeat(9)
        ),
        format!(
            "F100\nG6.2 X0 Y0 R1 K0 P4 Q1\nX1 Y1 R1 K0\nX2 Y1 R1 K0\nX3 Y0 R1 K0\n{}",
            format!("G6.2 K{big}\n").repeat(4)
        ),
        "F100\nG06.2 P3 K0 X0 Y0\nK0 X1 Y1\nK0 X1 Y1\nK0.0000000000001 X1 Y1\nK1\nK1\nK1\n"
            .to_string(),
        "F100\nG5 X0 Y0 I0 J0 P0 Q0\n".to_string(),
    ] {
        let d = check(&text);
        assert_located(&text, &d).unwrap_or_else(|e| panic!("{e}"));
    }
}
