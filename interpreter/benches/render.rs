//! Rendering `report.html` for a one-hour run at 1 ms: 3.6 million set-points and feedback
//! rows, a deadline report with a thousand misses. The run directory is generated once
//! under the target directory (about 450 MB of CSV) from a real run of a circle on the
//! simulated clock, its traces stretched to an hour of the circle traced over and over.
//!
//! Run: `cargo bench -p interpreter --bench render`. Each sample renders the whole page
//! (loading every file, the contour analysis, the plots), so it takes seconds.
//!
//! Measured with `/usr/bin/time cnc report DIR --out page.html` on this directory (release
//! build, 2-core VM with a CI run beside it): 45 s wall / 39 s CPU / 680 MB resident before
//! the contour analysis stopped re-evaluating each block's coarse samples per feedback row;
//! 5.2–7 s wall / 4.7–6.5 s CPU / 570 MB after, the same 510 KB page.
use criterion::{criterion_group, criterion_main, Criterion};
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::Duration;

const CYCLES: u64 = 3_600_000;
const MISSES: u64 = 1000;
const CIRCLE: &str = "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n";

/// The generated run directory (made once; later benches reuse it).
fn one_hour_run() -> PathBuf {
    let base = Path::new(env!("CARGO_TARGET_TMPDIR")).join("render-bench");
    let dir = base.join("hour");
    let done = dir.join(".complete");
    // A directory left by an older build (its commands.log in an older protocol) would
    // render without the path and the contour analysis, and time the wrong thing.
    if done.exists() && shared::cmdlog::read(&dir.join("commands.log")).is_ok() {
        return dir;
    }
    let _ = std::fs::remove_dir_all(&base);
    std::fs::create_dir_all(&base).unwrap();
    let prog = base.join("circle.ngc");
    std::fs::write(&prog, CIRCLE).unwrap();
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_cnc"))
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(&dir)
        .arg(&prog)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    write_traces(&dir);
    let misses = miss_list();
    // report.json and deadline-misses.json as a real-clock hour would leave them.
    let mut rep = read_json(&dir.join("report.json"));
    rep["cycles"] = CYCLES.into();
    rep["time_s"] = (CYCLES as f64 * 1e-3).into();
    rep["clock"] = "real".into();
    rep["misses"] = MISSES.into();
    let p = serde_json::json!({"p50": 14000, "p90": 30000, "p99": 47000, "p999": 120000, "max": 2100000});
    for k in ["wake_late_ns", "compute_ns", "publish_ns"] {
        rep[k] = p.clone();
    }
    rep["miss_list"] = misses.clone().into();
    std::fs::write(dir.join("report.json"), rep.to_string()).unwrap();
    let mut h = interpolator::timing::Histogram::new();
    for k in 0..CYCLES {
        // A long-tailed spread of lateness, deterministic.
        let spike = if k % 10_007 == 0 { 900_000 } else { 0 };
        h.record(8_000 + (k * 7919 % 10_000) + spike);
    }
    let fig = serde_json::to_value(interpolator::deadline::Figure::of(&h)).unwrap();
    let mut d = read_json(&dir.join("deadline-misses.json"));
    for k in ["wake_late_ns", "compute_ns", "publish_ns"] {
        d[k] = fig.clone();
    }
    d["measured"] = true.into();
    d["clock"] = "real".into();
    d["not_measured"] = serde_json::Value::Null;
    d["cycles"] = CYCLES.into();
    d["misses"] = MISSES.into();
    d["miss_list"] = misses.into();
    d["summary"] = format!("{MISSES} deadline misses in {CYCLES} cycles").into();
    std::fs::write(dir.join("deadline-misses.json"), d.to_string()).unwrap();
    std::fs::write(&done, "").unwrap();
    dir
}

fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// An hour of the circle (line 3), with a little following error.
fn write_traces(dir: &Path) {
    let create =
        |name: &str| std::io::BufWriter::new(std::fs::File::create(dir.join(name)).unwrap());
    let (mut sp, mut fb) = (create("setpoints.csv"), create("feedback.csv"));
    writeln!(sp, "cycle,t_ns,x_mm,y_mm,z_mm,line").unwrap();
    writeln!(
        fb,
        "cycle,t_ns,x_mm,y_mm,z_mm,ferr_x_um,ferr_y_um,ferr_z_um"
    )
    .unwrap();
    let mut line = String::new();
    for k in 0..CYCLES {
        let a = k as f64 * 0.005;
        let (x, y) = (10.0 * a.cos(), 10.0 * a.sin());
        let t = k * 1_000_000;
        line.clear();
        let _ = writeln!(line, "{k},{t},{x:.6},{y:.6},0,3");
        sp.write_all(line.as_bytes()).unwrap();
        line.clear();
        let (ex, ey) = (2.0 * a.sin(), -2.0 * a.cos());
        let _ = writeln!(
            line,
            "{k},{t},{:.6},{:.6},0,{ex:.3},{ey:.3},0",
            x - ex * 1e-3,
            y - ey * 1e-3
        );
        fb.write_all(line.as_bytes()).unwrap();
    }
    sp.flush().unwrap();
    fb.flush().unwrap();
}

/// Misses spread over the hour, every cause in turn.
fn miss_list() -> Vec<serde_json::Value> {
    let causes = [
        "late_wake",
        "long_compute",
        "publish_stall",
        "downstream_lag",
        "preempted",
    ];
    (0..MISSES)
        .map(|i| {
            let cycle = i * 3571 + 17;
            serde_json::json!({"cycle": cycle, "t_ns": cycle * 1_000_000, "line": 3,
                "block_seq": 1, "cause": causes[(i % 5) as usize],
                "wake_late_ns": 1_200_000, "compute_ns": 5_000, "publish_ns": 9_000,
                "overrun_ns": 200_000 + i * 1000, "unanswered": 0})
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let dir = one_hour_run();
    let mut g = c.benchmark_group("report_page");
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(60));
    g.bench_function("render_one_hour_run", |b| {
        b.iter(|| {
            let page = interpreter::html::render(&dir).unwrap();
            assert!(page.len() < 5_000_000);
            page.len()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
