//! What `cnc check` costs on a large program (issue #5): 100 000 generated lines, read,
//! checked, built into blocks, planned and validated ([`process::check_with`], the
//! function `cnc check` calls), and read and checked only ([`program::interpret`]), in
//! lines per second.
//!
//! Five programs: plain `G1` lines, as CAM output for a 3-D surface is, a mix of
//! `G1`, `G2`, `G5.2 … G5.3` and `G6.2` blocks, and 50 000 lines of `G1`, `G2`, `G3`
//! and `G5.2` that LinuxCNC's `rs274` reads too, and one smooth spiral of short `G1`
//! lines with no rest in it (under `G64`, and a fifth as long under `G64 P0.01`).
//! `CHECK_BENCH_WRITE=DIR` also writes them
//! to DIR (for timing LinuxCNC's `rs274` on the same text; see BENCHMARKS.md).
//!
//! `CHECK_BENCH_PLAIN_LINES=N` makes `plain_g1` N lines long instead of 100 000 (`mixed`
//! walks off the longest travel beyond 136 000): `CHECK_BENCH_PLAIN_LINES=200000
//! CHECK_BENCH_WRITE=DIR cargo bench -p interpreter --bench check -- none` writes the
//! 200 000-line `plain_g1` that BENCHMARKS.md times against `rs274`, and benchmarks
//! nothing. `spiral` (100 000 lines) and `spiral_blended` (a fifth of it under `G64
//! P0.01`) are one smooth spiral with no rest, planned in windows cut at speed;
//! `CHECK_BENCH_SPIRAL_LINES=N` makes `spiral` N lines long (and the other N / 5).
//!
//! Run: `cargo bench -p interpreter --bench check`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use interpreter::process;
use interpreter::program::{self, Options};
use std::time::Duration;

mod programs;

const LINES: usize = 100_000;
const PERIOD_NS: u64 = 1_000_000;

fn bench(c: &mut Criterion) {
    let machine = programs::long_x_machine();
    let plain_lines = std::env::var("CHECK_BENCH_PLAIN_LINES")
        .map(|n| {
            n.parse()
                .unwrap_or_else(|e| panic!("CHECK_BENCH_PLAIN_LINES={n}: {e}"))
        })
        .unwrap_or(LINES);
    let spiral_lines = std::env::var("CHECK_BENCH_SPIRAL_LINES")
        .map(|n| {
            n.parse()
                .unwrap_or_else(|e| panic!("CHECK_BENCH_SPIRAL_LINES={n}: {e}"))
        })
        .unwrap_or(LINES);
    let mut programs = vec![
        ("plain_g1".to_string(), programs::plain_g1(plain_lines)),
        // No rest from end to end: planned in windows cut at speed.
        ("spiral".to_string(), programs::spiral(spiral_lines, None)),
        (
            "spiral_blended".to_string(),
            programs::spiral(spiral_lines / 5, Some(0.01)),
        ),
        ("mixed".to_string(), programs::mixed(LINES)),
        // What `rs274` reads too (issue #23's planning throughput), half as long: its
        // curves are planned block by block, a few seconds of it.
        ("curves".to_string(), programs::curves(LINES / 2)),
    ];
    // Programs of one's own beside the generated ones (as for `rs274`), named by their
    // file stems: `CHECK_BENCH_FILES=a.ngc:b.ngc`.
    if let Ok(files) = std::env::var("CHECK_BENCH_FILES") {
        for f in files.split(':').filter(|f| !f.is_empty()) {
            let path = std::path::Path::new(f);
            let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{f}: {e}"));
            let name = path
                .file_stem()
                .map_or(f.into(), |s| s.to_string_lossy().into());
            programs.push((name, text));
        }
    }
    if let Ok(dir) = std::env::var("CHECK_BENCH_WRITE") {
        for (name, text) in &programs {
            let path = std::path::Path::new(&dir).join(format!("{name}.ngc"));
            std::fs::write(&path, text).unwrap_or_else(|e| panic!("{path:?}: {e}"));
        }
    }
    let mut g = c.benchmark_group("check");
    g.sample_size(10).measurement_time(Duration::from_secs(20));
    for (name, text) in &programs {
        let lines = text.lines().count() as u64;
        // A program the checker refuses would measure the wrong thing.
        let blocks = process::check_with(text, &Options::default(), &machine, PERIOD_NS)
            .unwrap_or_else(|e| panic!("{name}: {:?}", &e[..e.len().min(3)]))
            .1
            .len();
        eprintln!("{name}: {lines} lines, {blocks} blocks");
        g.throughput(Throughput::Elements(lines));
        g.bench_function(format!("{name}/read"), |b| {
            b.iter(|| program::interpret(text).map(|p| p.moves.len()))
        });
        g.bench_function(format!("{name}/read+plan"), |b| {
            b.iter(|| {
                process::check_with(text, &Options::default(), &machine, PERIOD_NS)
                    .map(|(_, blocks)| blocks.len())
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
