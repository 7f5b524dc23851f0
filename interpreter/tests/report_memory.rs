//! The report's analysis of a run (`report.json`'s contour, chord and roundness figures,
//! and the figures taken from the traces when a summary is missing) reads the traces a
//! batch of rows at a time: its peak heap does not grow with the run's length (issue
//! #25), and its figures are those of the whole-trace analysis to the last bit.

mod heap;

use heap::{peak_of, run_sim, scratch, write_traces};
use std::fs;
use std::path::{Path, PathBuf};

const CIRCLE: &str = "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n";

/// A real run of the circle (its command log and summaries), then traces of `n` cycles
/// on that circle, round and round, the measured positions off it by a few µm that vary
/// along it, one cycle in a thousand without a set-point (a lost one).
fn run_of(base: &Path, name: &str, n: u64) -> PathBuf {
    let dir = base.join(name);
    fs::create_dir_all(&dir).unwrap();
    fs::copy(base.join("run/commands.log"), dir.join("commands.log")).unwrap();
    // No interpolator or servo summary: the report takes its cycles, path and following
    // error from the traces too.
    write_traces(&dir, n, |k| (k as f64 * 0.004, 3));
    dir
}

/// The report of the run in `dir`, with its peak heap.
fn report_of(dir: &Path) -> (interpreter::report::Report, usize) {
    peak_of(|| {
        interpreter::report::assemble(
            dir,
            "circle.ngc",
            shared::clock::ClockMode::Sim,
            1_000_000,
            Vec::new(),
            None,
            None,
        )
    })
}

#[test]
fn the_report_s_heap_is_flat_in_the_run_s_length_and_its_figures_are_the_whole_trace_s() {
    let base = scratch("report-memory-flat");
    let prog = base.join("circle.ngc");
    fs::write(&prog, CIRCLE).unwrap();
    run_sim(&prog, &base.join("run"));
    let short = run_of(&base, "short", 50_000);
    let long = run_of(&base, "long", 500_000);
    // Warm up what is made once per process (thread locals, the allocator's own
    // tables): only the analysis is measured.
    let _ = report_of(&short);
    let (short_rep, short_peak) = report_of(&short);
    let (long_rep, long_peak) = report_of(&long);
    eprintln!("peak heap: {short_peak} B for 50 000 cycles, {long_peak} B for 500 000");
    // A whole-trace analysis holds some 100 bytes a cycle (50 MB for the long run).
    assert!(
        (long_peak as f64) < 1.5 * short_peak as f64 + 2e6,
        "the report's peak heap grows with the run: {short_peak} B for 50 000 cycles, {long_peak} B for 500 000"
    );
    for (dir, rep, n) in [(&short, &short_rep, 50_000u64), (&long, &long_rep, 500_000)] {
        // The whole-trace analysis (`contour::analyse`), held in memory.
        let whole = interpreter::contour::analyse_dir(dir).unwrap();
        let streamed = interpreter::contour::figures_dir(dir).unwrap();
        assert_eq!(format!("{:?}", whole.figures()), format!("{streamed:?}"));
        assert_eq!(whole.figures(), streamed);
        let w = whole.max.unwrap();
        assert_eq!(
            (
                rep.max_contour_error_um.map(f64::to_bits),
                rep.max_contour_error_cycle,
                rep.rms_contour_error_um.map(f64::to_bits),
            ),
            (
                Some(w.um.to_bits()),
                Some(w.cycle),
                whole.rms_um.map(f64::to_bits)
            )
        );
        let round = whole.roundness.as_ref().unwrap();
        let figs = rep.roundness.as_ref().unwrap();
        assert_eq!(
            (figs.roundness_um.to_bits(), figs.samples),
            (round.roundness_um.to_bits(), round.measured.len())
        );
        // The figures taken from the traces (no interpolator or servo summary).
        assert_eq!(rep.cycles, n - n / 1000);
        assert!(rep.max_following_error_um > 1.9);
    }
    fs::remove_dir_all(&base).unwrap();
}
