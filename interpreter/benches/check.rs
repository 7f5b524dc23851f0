//! What `cnc check` costs on a large program (issue #5): 100 000 generated lines, read,
//! checked, built into blocks and planned ([`process::compile_with`], the function
//! `cnc check` calls), and read and checked only ([`program::interpret`]), in lines per
//! second.
//!
//! Two programs: plain `G1` lines, as CAM output for a 3-D surface is, and a mix of
//! `G1`, `G2`, `G5.2 … G5.3` and `G6.2` blocks. `CHECK_BENCH_WRITE=DIR` also writes them
//! to DIR (for timing LinuxCNC's `rs274` on the same text; see BENCHMARKS.md).
//!
//! Run: `cargo bench -p interpreter --bench check`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use interpreter::process;
use interpreter::program::{self, Options};
use shared::Machine;
use std::fmt::Write as _;
use std::time::Duration;

const LINES: usize = 100_000;
const PERIOD_NS: u64 = 1_000_000;

/// `G1` moves along a zig-zag with a wavy Z, as a surface finishing pass: every line
/// a new X Y Z, the feed on the first.
fn plain_g1() -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z0 F1200\n");
    let mut i = 3;
    while i < LINES - 1 {
        let (row, col) = (i / 200, i % 200);
        let x = if row % 2 == 0 { col } else { 199 - col } as f64 * 0.5;
        let y = row as f64 * 0.5;
        let z = -0.5 - 0.25 * (x * 0.1).sin() * (y * 0.07).cos();
        let _ = writeln!(s, "G1 X{x:.3} Y{y:.3} Z{z:.4}");
        i += 1;
    }
    s.push_str("M2\n");
    s
}

/// Groups of a line, an arc, a `G5.2` NURBS of six lines and a `G6.2` NURBS of nine,
/// each group starting and ending on the X axis, shifted along it.
fn mixed() -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z0\nF1500\n");
    let mut lines = 3;
    let mut x0 = 0.0f64;
    while lines + 18 < LINES {
        let _ = writeln!(s, "G1 X{:.3} Y0", x0 + 1.0);
        let _ = writeln!(s, "G2 X{:.3} Y0 I1 J0", x0 + 3.0);
        let _ = writeln!(s, "G5.2 X{:.3} Y1 P1 L4", x0 + 4.0);
        let _ = writeln!(s, "X{:.3} Y-1 P2", x0 + 5.0);
        let _ = writeln!(s, "X{:.3} Y1 P1", x0 + 6.0);
        let _ = writeln!(s, "X{:.3} Y0 P1", x0 + 7.0);
        s.push_str("G5.3\n");
        let b = x0 + 7.0;
        let _ = writeln!(s, "G6.2 X{b:.3} Y0 R1 K0 P3 Q1");
        let _ = writeln!(s, "X{:.3} Y1 R1 K0", b + 1.0);
        let _ = writeln!(s, "X{:.3} Y-1 R2 K0", b + 2.0);
        let _ = writeln!(s, "X{:.3} Y0 R1 K1", b + 3.0);
        s.push_str("G6.2 K2\nG6.2 K2\nG6.2 K2\n");
        // Back to the start of the next group's line.
        let _ = writeln!(s, "G1 X{:.3} Y0", b + 4.0);
        lines += 15;
        x0 = b + 4.0;
    }
    s.push_str("M2\n");
    s
}

fn bench(c: &mut Criterion) {
    let machine = Machine::default();
    let programs = [("plain_g1", plain_g1()), ("mixed", mixed())];
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
        let blocks = process::compile_with(text, &Options::default(), &machine, PERIOD_NS)
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
                process::compile_with(text, &Options::default(), &machine, PERIOD_NS)
                    .map(|(_, blocks)| blocks.len())
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
