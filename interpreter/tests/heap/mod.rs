//! What the tests of the report's and the page's memory share: a global allocator that
//! counts the bytes on the heap and their peak, and run directories of synthetic traces
//! of any length.

use std::alloc::{GlobalAlloc, Layout, System};
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Counts the bytes on the heap and their peak.
pub struct Counting;

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
pub fn peak_of<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let base = NOW.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let out = f();
    (out, PEAK.load(Ordering::Relaxed).saturating_sub(base))
}

/// A new empty folder for the test `name`.
pub fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("{name}-{}", std::process::id()));
    let _ = fs::remove_dir_all(&d);
    fs::create_dir_all(&d).unwrap();
    d
}

/// `cnc run --clock sim --no-report` of the program `prog` into `out`.
pub fn run_sim(prog: &Path, out: &Path) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(out)
        .arg(prog)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

/// `setpoints.csv` and `feedback.csv` of `n` cycles in `dir`, on circles of 10 mm about
/// the origin in XY: cycle `k`'s set-point at the angle and from the source line
/// `at(k)` gives, its measured position off the circle by a few µm that vary along it,
/// one cycle in a thousand without a set-point (a lost one).
pub fn write_traces(dir: &Path, n: u64, at: impl Fn(u64) -> (f64, u32)) {
    use std::fmt::Write as _;
    use std::io::Write as _;
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
        let (a, line) = at(k);
        let (c, s) = (a.cos(), a.sin());
        let t = k * 1_000_000;
        if k % 1000 != 999 {
            row.clear();
            let _ = writeln!(row, "{k},{t},{},{},0,{line}", 10.0 * c, 10.0 * s);
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
}
