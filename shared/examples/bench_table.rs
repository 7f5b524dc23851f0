//! Prints the table of `shared/BENCHMARKS.md` from criterion's results of the `eval` bench:
//! nanoseconds per point (the median of each benchmark divided by its point count) and the
//! ratios the issue sets targets for, all from one run.
//!
//! ```sh
//! cargo bench -p shared --bench eval
//! cargo run -p shared --release --example bench_table [CRITERION_DIR]
//! ```
//!
//! `CRITERION_DIR` defaults to `$CARGO_TARGET_DIR/criterion`, else `target/criterion`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Seed 001, Table 1: the conventional method's time over the proposed one's, degrees 1..=5.
const SEED_SPEEDUP: [f64; 5] = [
    22.0 / 4.0,
    49.0 / 8.0,
    110.0 / 11.0,
    214.0 / 16.0,
    434.0 / 21.0,
];

const FUNCTIONS: [&str; 6] = [
    "extended",
    "extended_recurrence",
    "extended_no_reuse",
    "piegl_tiller",
    "curvo",
    "conventional",
];

fn ns_per_point(dir: &Path) -> Option<f64> {
    let read = |name: &str| -> Option<serde_json::Value> {
        serde_json::from_str(&std::fs::read_to_string(dir.join("new").join(name)).ok()?).ok()
    };
    let bench = read("benchmark.json")?;
    let est = read("estimates.json")?;
    let points = bench["throughput"]["Elements"].as_f64()?;
    Some(est["median"]["point_estimate"].as_f64()? / points)
}

fn main() {
    let root = std::env::args()
        .nth(1)
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let target = std::env::var("CARGO_TARGET_DIR").unwrap_or_else(|_| "target".into());
            Path::new(&target).join("criterion")
        });
    // group id -> function -> ns per point
    let mut groups: BTreeMap<String, BTreeMap<String, f64>> = BTreeMap::new();
    let Ok(entries) = std::fs::read_dir(&root) else {
        eprintln!("bench_table: no criterion results in {}", root.display());
        std::process::exit(1);
    };
    for group in entries.flatten() {
        let Ok(functions) = std::fs::read_dir(group.path()) else {
            continue;
        };
        for f in functions.flatten() {
            let bench: Option<serde_json::Value> =
                std::fs::read_to_string(f.path().join("new/benchmark.json"))
                    .ok()
                    .and_then(|t| serde_json::from_str(&t).ok());
            let (Some(bench), Some(ns)) = (bench, ns_per_point(&f.path())) else {
                continue;
            };
            let (Some(g), Some(func)) = (bench["group_id"].as_str(), bench["function_id"].as_str())
            else {
                continue;
            };
            if g.starts_with("curve_eval/") || g.starts_with("surface_eval/") {
                groups
                    .entry(g.to_string())
                    .or_default()
                    .insert(func.to_string(), ns);
            }
        }
    }
    let cell = |v: Option<&f64>| v.map_or("–".to_string(), |x| format!("{x:.1}"));
    let ratio = |a: Option<&f64>, b: Option<&f64>| match (a, b) {
        (Some(a), Some(b)) => format!("{:.1}×", a / b),
        _ => "–".to_string(),
    };
    println!("ns per point (median):\n");
    println!("| group | {} |", FUNCTIONS.join(" | "));
    println!("|---|{}", "---:|".repeat(FUNCTIONS.len()));
    let mut order: Vec<&String> = groups.keys().collect();
    // p9 after p5, not after p1.
    order.sort_by_key(|g| (g.starts_with("surface"), g.len(), g.to_string()));
    for g in &order {
        let row = &groups[*g];
        let cells: Vec<String> = FUNCTIONS.iter().map(|f| cell(row.get(*f))).collect();
        println!("| `{g}` | {} |", cells.join(" | "));
    }
    println!("\nRatios (time of the other method / time of `extended`):\n");
    println!("| group | piegl_tiller | curvo | conventional | 10 × seed's speed-up |");
    println!("|---|---:|---:|---:|---:|");
    for g in &order {
        let row = &groups[*g];
        let ext = row.get("extended");
        let seed = g
            .strip_prefix("curve_eval/p")
            .and_then(|d| d.parse::<usize>().ok())
            .filter(|d| (1..=5).contains(d))
            .map_or("–".to_string(), |d| {
                format!("{:.0}×", 10.0 * SEED_SPEEDUP[d - 1])
            });
        println!(
            "| `{g}` | {} | {} | {} | {seed} |",
            ratio(row.get("piegl_tiller"), ext),
            ratio(row.get("curvo"), ext),
            ratio(row.get("conventional"), ext),
        );
    }
}
