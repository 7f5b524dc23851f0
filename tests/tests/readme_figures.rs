//! The figures the README quotes for its programs (block counts, machining times, path
//! lengths), computed here as `cnc check --estimate` computes them: the README's table
//! between its `figures` markers must be exactly what this test makes, so a change to
//! the planner or to a program cannot leave it stale. To renew it after such a change:
//!
//! ```sh
//! README_FIGURES=write cargo test -p tests --test readme_figures
//! ```
//!
//! Machining time is a count of 1 ms cycles of the interpolator's engine stepped in this
//! process (`interpreter::estimate`), the same on every computer: no timing is asserted.

use shared::machine::Machine;
use std::path::{Path, PathBuf};

const PERIOD_NS: u64 = 1_000_000;
const BEGIN: &str = "<!-- figures: made by tests/tests/readme_figures.rs; do not edit by hand -->";
const END: &str = "<!-- end of figures -->";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The table: each program on the built-in machine and on LinuxCNC's limits.
fn table() -> String {
    let linuxcnc =
        shared::machine::load(Some(&root().join("examples/machine-linuxcnc-sim.toml"))).unwrap();
    let machines = [
        ("built-in", Machine::default()),
        ("LinuxCNC's limits", linuxcnc),
    ];
    let read = |p: &str| std::fs::read_to_string(root().join(p)).unwrap();
    let programs = [
        (
            "the built-in demo (`interpreter/src/demo.ngc`)",
            interpreter::process::DEMO.to_string(),
        ),
        (
            "LinuxCNC's butterfly (`tests/peers/linuxcnc/g5_butterfly-xy.ngc`)",
            read("tests/peers/linuxcnc/g5_butterfly-xy.ngc"),
        ),
        ("`examples/cam-circle.ngc`", read("examples/cam-circle.ngc")),
    ];
    let mut t = String::from(
        "| program | machine | blocks | machining time | path length |\n|---|---|---|---|---|\n",
    );
    for (name, text) in &programs {
        for (mname, m) in &machines {
            let opts = interpreter::program::Options::default();
            let blocks = interpreter::process::compile_source(name, text, &opts, m, PERIOD_NS)
                .unwrap()
                .blocks;
            let e = interpreter::estimate::estimate(&blocks, m, PERIOD_NS).unwrap();
            t.push_str(&format!(
                "| {name} | {mname} | {} | {:.3} s | {:.3} mm |\n",
                blocks.len(),
                e.time_s,
                e.path_length_mm
            ));
        }
    }
    t
}

#[test]
fn the_readme_s_figures_are_today_s() {
    let path = root().join("README.md");
    let readme = std::fs::read_to_string(&path).unwrap();
    let at = readme
        .find(BEGIN)
        .expect("the README's figures begin marker")
        + BEGIN.len()
        + 1;
    let end = readme[at..]
        .find(END)
        .expect("the README's figures end marker")
        + at;
    let now = table();
    if std::env::var("README_FIGURES").as_deref() == Ok("write") {
        assert!(
            std::env::var_os("CI").is_none(),
            "README_FIGURES=write under CI would pass without checking"
        );
        let mut new = readme[..at].to_string();
        new.push_str(&now);
        new.push_str(&readme[end..]);
        std::fs::write(&path, new).unwrap();
        return;
    }
    assert_eq!(
        readme[at..end],
        now,
        "the README's figures are stale: renew them with README_FIGURES=write cargo test -p tests --test readme_figures"
    );
}
