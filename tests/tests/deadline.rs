//! The deadline-miss report of real runs: misses injected as long computes (every Nth
//! cycle computes for 1.5 periods, `CNC_INJECT_LONG_COMPUTE=N`) are counted and classified
//! exactly; the report agrees with report.json and with what `cnc run` prints; the latency
//! test's floor is found and compared; the simulated clock says "not measured".
//!
//! No test here asserts a latency bound: these machines are noisy. Misses that the noise
//! itself causes (late wake-ups, a drive that lags) are allowed beside the injected ones;
//! only the injected cycles may carry the cause `long_compute`.

use serde_json::Value;
use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;
use tests::{cnc_exe, report, temp_dir};

const CIRCLE: &str = "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n";
const EVERY: u64 = 100;

fn deadline(dir: &Path) -> Value {
    let text = std::fs::read_to_string(dir.join("deadline-misses.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// `cnc run` of the circle into `out`; returns its stdout.
fn run(dir: &Path, out: &str, clock: &str, inject: Option<u64>, floor: &Path) -> String {
    let prog = dir.join("circle.ngc");
    std::fs::write(&prog, CIRCLE).unwrap();
    let mut cmd = Command::new(cnc_exe());
    cmd.args(["run", "--no-report", "--clock", clock, "--out"])
        .arg(dir.join(out))
        .arg(&prog)
        .env("CNC_LATENCY_FILE", floor)
        .env_remove("CNC_INJECT_LONG_COMPUTE");
    if let Some(n) = inject {
        cmd.env("CNC_INJECT_LONG_COMPUTE", n.to_string());
    }
    let o = cmd.output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout).to_string();
    assert!(
        o.status.success(),
        "cnc run failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

/// The report is consistent in itself, with report.json and with the printed line.
fn check_agreement(dir: &Path, stdout: &str) -> Value {
    let d = deadline(dir);
    let rep = report(dir);
    assert_eq!(d["format"], "cnc deadline-misses v1");
    assert_eq!(d["measured"], true);
    assert_eq!(d["period_ns"], rep["period_ns"]);
    assert_eq!(d["cycles"], rep["cycles"]);
    let misses = d["misses"].as_u64().unwrap();
    assert_eq!(rep["misses"].as_u64(), Some(misses), "report.json agrees");
    let list = d["miss_list"].as_array().unwrap();
    assert_eq!(
        list.len() as u64 + d["lost"].as_u64().unwrap(),
        misses,
        "every miss is listed or counted as lost"
    );
    let by_cause: u64 = d["misses_by_cause"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c[1].as_u64().unwrap())
        .sum();
    assert_eq!(by_cause, misses);
    // report.json lists the same misses (up to its cap).
    assert_eq!(
        &rep["miss_list"].as_array().unwrap()[..],
        &list[..list.len().min(4096)]
    );
    // The printed line is the report's summary.
    let summary = d["summary"].as_str().unwrap();
    assert!(summary.starts_with(&format!("{misses} deadline misses in ")));
    assert!(
        stdout.contains(&format!("  deadlines    {summary}\n")),
        "printed: {stdout}"
    );
    // Histograms hold every cycle; percentiles are ordered.
    let cycles = d["cycles"].as_u64().unwrap();
    for k in ["wake_late_ns", "compute_ns", "publish_ns"] {
        let n: u64 = d[k]["histogram"]
            .as_array()
            .unwrap()
            .iter()
            .map(|b| b["count"].as_u64().unwrap())
            .sum();
        assert_eq!(n, cycles, "{k}");
        let p = &d[k]["percentiles"];
        let v: Vec<u64> = ["p50", "p90", "p99", "p999", "max"]
            .iter()
            .map(|q| p[q].as_u64().unwrap())
            .collect();
        assert!(v.windows(2).all(|w| w[0] <= w[1]), "{k}: {v:?}");
    }
    // Runs of consecutive misses are exactly those of the list.
    let cyc: Vec<u64> = list.iter().map(|m| m["cycle"].as_u64().unwrap()).collect();
    let mut runs = Vec::new();
    let mut i = 0;
    while i < cyc.len() {
        let mut j = i;
        while j + 1 < cyc.len() && cyc[j + 1] == cyc[j] + 1 {
            j += 1;
        }
        if j > i {
            runs.push((cyc[i], (j - i + 1) as u64));
        }
        i = j + 1;
    }
    let got: Vec<(u64, u64)> = d["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["start_cycle"].as_u64().unwrap(),
                r["length"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(got, runs);
    let text = std::fs::read_to_string(dir.join("deadline-misses.txt")).unwrap();
    assert!(text.contains(summary));
    assert!(text.contains(&format!("every miss ({} recorded", list.len())));
    d
}

#[test]
fn injected_long_computes_are_exactly_the_long_compute_misses() {
    let dir = temp_dir("deadline");
    let floor = dir.join("latency-test.json");
    let stdout = run(&dir, "inject", "real", Some(EVERY), &floor);
    let d = check_agreement(&dir.join("inject"), &stdout);
    let cycles = d["cycles"].as_u64().unwrap();
    let injected: BTreeSet<u64> = (1..)
        .map(|k| k * EVERY)
        .take_while(|c| *c < cycles)
        .collect();
    assert!(injected.len() >= 10, "{cycles} cycles");
    let list = d["miss_list"].as_array().unwrap();
    let (_, sp) = tests::csv(&dir.join("inject").join("setpoints.csv"));
    let mut noise = 0;
    for c in &injected {
        let m = list
            .iter()
            .find(|m| m["cycle"] == *c)
            .unwrap_or_else(|| panic!("injected cycle {c} is not listed"));
        let (wake, compute) = (
            m["wake_late_ns"].as_u64().unwrap(),
            m["compute_ns"].as_u64().unwrap(),
        );
        assert!(compute >= 1_500_000, "cycle {c} computed {compute} ns");
        assert!(m["overrun_ns"].as_u64().unwrap() > 0);
        // The source line and block of the set-point that cycle sent.
        let row = &sp[*c as usize];
        assert_eq!(m["line"].as_f64(), Some(row[5]), "cycle {c}");
        if m["cause"] != "long_compute" {
            // Only a wake-up later still than the long compute may take the blame.
            assert!(wake > compute, "cycle {c}: {m}");
            noise += 1;
        }
    }
    // A cycle the kernel preempted in the middle of its compute (a loaded machine: seen
    // once while another build ran) computed long by the clock, and the report is right
    // to call it a long compute; such strays are counted and shown, and must stay few.
    let (long, stray): (Vec<_>, Vec<_>) = list
        .iter()
        .filter(|m| m["cause"] == "long_compute")
        .partition(|m| injected.contains(&m["cycle"].as_u64().unwrap()));
    assert!(
        stray.len() <= injected.len() / 4,
        "{} long computes that were not injected: {stray:?}",
        stray.len()
    );
    assert_eq!(long.len() + noise, injected.len());
    println!(
        "{} injected, {} classified long compute, {} long computes not injected; {} misses \
         in all",
        injected.len(),
        long.len(),
        stray.len(),
        d["misses"]
    );
    // No latency test was there to compare with, and the report says so.
    assert!(d["floor"].is_null());
    assert!(d["vs_floor"]
        .as_str()
        .unwrap()
        .starts_with("no latency test measured"));
    assert!(d["summary"]
        .as_str()
        .unwrap()
        .contains("no latency test to compare with"));
}

#[test]
fn a_latency_test_becomes_the_floor_runs_compare_with() {
    let dir = temp_dir("floor");
    let floor = dir.join("latency-test.json");
    let o = Command::new(cnc_exe())
        .args(["latency-test", "--seconds", "0.3", "--out"])
        .arg(&floor)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{stdout}");
    for word in ["p50", "p99", "max", "verdict", "written to"] {
        assert!(stdout.contains(word), "{word}: {stdout}");
    }
    let f: Value = serde_json::from_str(&std::fs::read_to_string(&floor).unwrap()).unwrap();
    assert_eq!(f["cycles"], 300);
    assert!(
        ["very_good", "good", "needs_care", "unusable"].contains(&f["verdict"].as_str().unwrap())
    );

    let stdout = run(&dir, "real", "real", None, &floor);
    let d = check_agreement(&dir.join("real"), &stdout);
    assert_eq!(d["floor"]["wake_late_ns"], f["wake_late_ns"]);
    let vs = d["vs_floor"].as_str().unwrap();
    assert!(vs.contains("against this machine's floor"), "{vs}");
    assert!(d["summary"]
        .as_str()
        .unwrap()
        .contains("(machine floor p99 "));

    // The simulated clock measures nothing, and both files say so.
    let stdout = run(&dir, "sim", "sim", Some(EVERY), &floor);
    let sim = dir.join("sim");
    let d = deadline(&sim);
    assert_eq!(d["measured"], false);
    assert!(d["misses"].is_null() && d["miss_list"].as_array().unwrap().is_empty());
    assert!(report(&sim)["misses"].is_null());
    let text = std::fs::read_to_string(sim.join("deadline-misses.txt")).unwrap();
    assert!(text.contains("timing not measured"));
    assert!(stdout.contains("  deadlines    not measured (sim clock)"));
}
