//! The report's analysis of a run (`report.json`'s contour, chord and roundness figures,
//! and the figures taken from the traces when a summary is missing) reads the traces a
//! batch of rows at a time: its peak heap does not grow with the run's length (issue
//! #25), and its figures are those of the whole-trace analysis to the last bit.

use std::alloc::{GlobalAlloc, Layout, System};
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Counts the bytes on the heap and their peak.
struct Counting;

static NOW: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(l) };
        if !p.is_null() {
            let now = NOW.fetch_add(l.size(), Ordering::Relaxed) + l.size();
            PEAK.fetch_max(now, Ordering::Relaxed);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        unsafe { System.dealloc(p, l) };
        NOW.fetch_sub(l.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, new: usize) -> *mut u8 {
        let q = unsafe { System.realloc(p, l, new) };
        if !q.is_null() {
            if new >= l.size() {
                let now = NOW.fetch_add(new - l.size(), Ordering::Relaxed) + new - l.size();
                PEAK.fetch_max(now, Ordering::Relaxed);
            } else {
                NOW.fetch_sub(l.size() - new, Ordering::Relaxed);
            }
        }
        q
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The peak heap `f` takes above what was on the heap when it started, bytes.
fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = NOW.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed).saturating_sub(base))
}

const CIRCLE: &str = "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n";

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("report-memory-{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

/// A real run of the circle (its command log and summaries), then traces of `n` cycles
/// on that circle, round and round, the measured positions off it by a few µm that vary
/// along it, one cycle in a thousand without a set-point (a lost one).
fn run_of(base: &Path, name: &str, n: u64) -> PathBuf {
    use std::fmt::Write as _;
    use std::io::Write as _;
    let dir = base.join(name);
    fs::create_dir_all(&dir).unwrap();
    fs::copy(base.join("run/commands.log"), dir.join("commands.log")).unwrap();
    // No interpolator or servo summary: the report takes its cycles, path and following
    // error from the traces too.
    let mut sp = std::io::BufWriter::new(fs::File::create(dir.join("setpoints.csv")).unwrap());
    let mut fb = std::io::BufWriter::new(fs::File::create(dir.join("feedback.csv")).unwrap());
    writeln!(sp, "cycle,t_ns,x_mm,y_mm,z_mm,line").unwrap();
    writeln!(
        fb,
        "cycle,t_ns,x_mm,y_mm,z_mm,ferr_x_um,ferr_y_um,ferr_z_um"
    )
    .unwrap();
    let mut row = String::new();
    for k in 0..n {
        let a = k as f64 * 0.004;
        let (c, s) = (a.cos(), a.sin());
        let t = k * 1_000_000;
        if k % 1000 != 999 {
            row.clear();
            let _ = writeln!(row, "{k},{t},{},{},0,3", 10.0 * c, 10.0 * s);
            sp.write_all(row.as_bytes()).unwrap();
        }
        let r = 10.0 + 0.002 * (3.0 * a).sin() + 0.001 * (a * 0.01).cos();
        row.clear();
        let _ = writeln!(
            row,
            "{k},{t},{},{},0,{},{},0",
            r * c,
            r * s,
            2.0 * (5.0 * a).sin(),
            -1.5 * a.cos()
        );
        fb.write_all(row.as_bytes()).unwrap();
    }
    sp.flush().unwrap();
    fb.flush().unwrap();
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
    let base = scratch("flat");
    let prog = base.join("circle.ngc");
    fs::write(&prog, CIRCLE).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(base.join("run"))
        .arg(&prog)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
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
        // The whole-trace analysis, as the page still measures it.
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
