//! A bare `G64` and the mode a program starts in (issue #23, programs nobody named):
//! LinuxCNC and Fanuc both start in `G64`, and LinuxCNC's bare `G64` (or `G64 P0`)
//! keeps "the best speed possible, however far from the programmed point". Here the
//! machine bounds it: `blend_tolerance_mm` in the machine file. With it, a bare `G64`,
//! `G64 P0` and a program with no path-mode word at all are planned exactly as the same
//! program under `G64 P<that tolerance> Q0` (no moves merged: LinuxCNC's bare `G64`
//! merges none either); without it (0, built in) they follow the
//! exact path as `G61` does, as before.
//!
//! The blocks are compared bit for bit (`Debug` of every command block: every float's
//! shortest round-trip digits), and the machining times are the engine's whole cycles
//! (`cnc check --estimate`), not a clock.

use interpreter::process::compile_source;
use interpreter::program::Options;
use shared::Machine;

const PERIOD_NS: u64 = 1_000_000;

/// LinuxCNC's simulated mill (`examples/machine-linuxcnc-sim.toml`), with `tol` as its
/// bare `G64`'s tolerance.
fn machine(tol: f64) -> Machine {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/machine-linuxcnc-sim.toml"
    ))
    .unwrap();
    let mut m = Machine::from_toml(&text).unwrap();
    m.blend_tolerance_mm = tol;
    m
}

/// A CAM-like polyline: 120 chords of 1 to 3 mm turning 3 to 10 degrees each (some
/// turns above the machine's 5° corner angle, an exact stop under `G61`), at F6000,
/// after a rapid and a plunge; `mode` is put on the first line.
fn polyline(mode: &str) -> String {
    let mut text = format!("G21 G90 G17 {mode}\nG0 X0 Y0 Z1\nG1 Z0 F1000\nG1 F6000\n");
    let (mut x, mut y, mut a) = (0.0f64, 0.0f64, 0.0f64);
    for i in 0..120u32 {
        // A fixed pseudo-random walk (no generator: the program is the same everywhere).
        let turn = 3.0 + f64::from((i * 37) % 8);
        a += turn.to_radians() * if i % 3 == 2 { -1.0 } else { 1.0 };
        let len = 1.0 + f64::from((i * 53) % 5) * 0.5;
        x += len * a.cos();
        y += len * a.sin();
        text += &format!("G1 X{x:.4} Y{y:.4}\n");
    }
    text + "M2\n"
}

/// The program's command blocks, each as its `Debug` text.
fn blocks(text: &str, machine: &Machine) -> Vec<String> {
    compile_source(
        "polyline.ngc",
        text,
        &Options::default(),
        machine,
        PERIOD_NS,
    )
    .unwrap_or_else(|e| panic!("{e}\n{text}"))
    .blocks
    .iter()
    .map(|b| format!("{b:?}"))
    .collect()
}

/// Machining time of the program, in cycles of the engine.
fn cycles(text: &str, machine: &Machine) -> u64 {
    let b = compile_source(
        "polyline.ngc",
        text,
        &Options::default(),
        machine,
        PERIOD_NS,
    )
    .unwrap()
    .blocks;
    interpreter::estimate::estimate(&b, machine, PERIOD_NS)
        .unwrap()
        .cycles
}

#[test]
fn a_bare_g64_and_the_starting_mode_blend_within_the_machines_tolerance() {
    let m = machine(0.05);
    // (`Q0`: a bare `G64` merges no moves, as LinuxCNC's does not; `G64 P` alone merges
    // within `P`, `blocks::naive_cam`.)
    let within = blocks(&polyline("G64 P0.05 Q0"), &m);
    for mode in ["", "G64", "G64 P0"] {
        assert_eq!(
            blocks(&polyline(mode), &m),
            within,
            "{mode:?} on a machine whose bare G64 blends within 0.05 mm"
        );
    }
    // Blended, and quicker.
    assert_ne!(within, blocks(&polyline("G61"), &m));
    let (blended, exact) = (cycles(&polyline(""), &m), cycles(&polyline("G61"), &m));
    let tighter = cycles(&polyline(""), &machine(0.01));
    println!("the polyline on LinuxCNC's machine: {exact} cycles exact (G61), {tighter} within 0.01 mm, {blended} within 0.05 mm");
    assert!(
        blended < exact,
        "blended {blended} cycles against {exact} exact"
    );
}

#[test]
fn a_tolerance_the_program_gives_is_kept() {
    let with = blocks(&polyline("G64 P0.02"), &machine(0.05));
    assert_eq!(with, blocks(&polyline("G64 P0.02"), &machine(0.0)));
    assert_ne!(with, blocks(&polyline("G64 P0.05 Q0"), &machine(0.0)));
}

#[test]
fn without_the_machines_tolerance_a_bare_g64_follows_the_exact_path() {
    let m = machine(0.0);
    let exact = blocks(&polyline("G61"), &m);
    for mode in ["", "G64", "G64 P0"] {
        assert_eq!(blocks(&polyline(mode), &m), exact, "{mode:?}");
    }
}

#[test]
fn the_fanuc_dialect_starts_blended_too() {
    // The same polyline with a Fanuc word (G05.1 Q0, which turns AI contour control off
    // and leaves the program Fanuc's): its corners blend as LinuxCNC's do.
    let fanuc = |mode: &str| polyline(mode).replacen("G21 G90 G17", "G21 G90 G17 G05.1 Q0", 1);
    let m = machine(0.05);
    let out = compile_source("f.ngc", &fanuc(""), &Options::default(), &m, PERIOD_NS).unwrap();
    assert_eq!(out.dialect, Some(interpreter::program::Dialect::Fanuc));
    assert_ne!(blocks(&fanuc(""), &m), blocks(&fanuc(""), &machine(0.0)));
    assert!(cycles(&fanuc(""), &m) < cycles(&fanuc(""), &machine(0.0)));
}
