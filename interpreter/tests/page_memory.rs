//! The page (`report.html`) reads the traces a batch of rows at a time and keeps what its
//! plots need per row in temporary files: its peak heap does not grow with the run's
//! length (issue #25). A one-hour run's traces are hundreds of megabytes; the page of one
//! used to hold them whole, with the contour analysis of every row beside them.

mod heap;

use heap::{peak_of, run_sim, scratch, write_traces};
use std::fs;
use std::path::{Path, PathBuf};

/// A circle, then the same circle the other way round: the polar plot overlays both.
const CIRCLES: &str =
    "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nG2 X10 Y0 I-10 J0 F3000\nM2\n";

/// A real run of the circles (its command log, machine and program), then traces of `n`
/// cycles ([`write_traces`]): `n / 2` round the first circle counter-clockwise, the rest
/// round the second clockwise.
fn run_of(base: &Path, name: &str, n: u64) -> PathBuf {
    let dir = base.join(name);
    fs::create_dir_all(&dir).unwrap();
    for f in ["commands.log", "machine.toml", "program.ngc"] {
        fs::copy(base.join("run").join(f), dir.join(f)).unwrap();
    }
    let half = n / 2;
    // Whole turns each way, so that each circle closes.
    let step = std::f64::consts::TAU * (half / 2000) as f64 / half as f64;
    write_traces(&dir, n, |k| {
        if k < half {
            (k as f64 * step, 3)
        } else {
            (-((k - half) as f64) * step, 4)
        }
    });
    dir
}

/// The page of the run in `dir`, with its peak heap.
fn page_of(dir: &Path) -> (String, usize) {
    let (page, peak) = peak_of(|| interpreter::html::render(dir));
    (page.unwrap(), peak)
}

#[test]
fn the_page_s_heap_is_flat_in_the_run_s_length() {
    let base = scratch("page-memory-flat");
    let prog = base.join("circles.ngc");
    fs::write(&prog, CIRCLES).unwrap();
    run_sim(&prog, &base.join("run"));
    let short = run_of(&base, "short", 50_000);
    let long = run_of(&base, "long", 500_000);
    // Warm up what is made once per process (thread locals, the allocator's own
    // tables): only the page is measured.
    let _ = page_of(&short);
    let (short_page, short_peak) = page_of(&short);
    let (long_page, long_peak) = page_of(&long);
    eprintln!("peak heap: {short_peak} B for 50 000 cycles, {long_peak} B for 500 000");
    // Every plot is drawn for both: the path by contour error, the feed and error
    // plots, the polar plot with the reverse run.
    for page in [&short_page, &long_page] {
        for id in [
            "id=\"path-error-plot\"",
            "id=\"feed-plot\"",
            "id=\"ferr-plot\"",
            "id=\"polar-plot\"",
            "id=\"reverse-run\"",
        ] {
            assert!(page.contains(id), "{id} missing");
        }
    }
    // Holding the traces whole and the contour analysis of every row took some 200
    // bytes a cycle (100 MB for the long run).
    assert!(
        (long_peak as f64) < 1.5 * short_peak as f64 + 2e6,
        "the page's peak heap grows with the run: {short_peak} B for 50 000 cycles, {long_peak} B for 500 000"
    );
    fs::remove_dir_all(&base).unwrap();
}
