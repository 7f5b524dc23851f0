//! The deadline-miss report of real runs: misses injected as long computes (every Nth
//! cycle burns 1.5 periods of its own CPU time, `CNC_INJECT_LONG_COMPUTE=N`) and as
//! preemptions (every Nth cycle is preempted mid-compute for 1.5 periods by a thread at a
//! higher real-time priority on its CPU, `CNC_INJECT_PREEMPTION=N`) are counted and
//! classified exactly; the report agrees with report.json and with what `cnc run` prints;
//! the latency test's floor is found and compared; the simulated clock says "not measured".
//!
//! No test here asserts a latency bound: these machines are noisy. Misses that the noise
//! itself causes (late wake-ups, preemptions, a drive that lags) are allowed beside the
//! injected ones, but every miss must carry the cause its own figures give by the rule
//! (`interpolator::timing::MissCause`), and only an injected cycle may be a long compute:
//! the thread's CPU time tells a compute the OS interrupted from a slow one.

use serde_json::Value;
use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;
use tests::{cnc_exe, report, temp_dir};

const CIRCLE: &str = "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nM2\n";
const EVERY: u64 = 100;
const INJECT_LONG_COMPUTE: &str = "CNC_INJECT_LONG_COMPUTE";
const INJECT_PREEMPTION: &str = "CNC_INJECT_PREEMPTION";

fn deadline(dir: &Path) -> Value {
    let text = std::fs::read_to_string(dir.join("deadline-misses.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

/// `cnc run` of the circle into `out`, with the test aid `inject` (an environment
/// variable) set to every `EVERY`th cycle; returns its stdout.
fn run(dir: &Path, out: &str, clock: &str, inject: Option<&str>, floor: &Path) -> String {
    let prog = dir.join("circle.ngc");
    std::fs::write(&prog, CIRCLE).unwrap();
    let mut cmd = Command::new(cnc_exe());
    cmd.args(["run", "--no-report", "--clock", clock, "--out"])
        .arg(dir.join(out))
        .arg(&prog)
        .env("CNC_LATENCY_FILE", floor)
        .env_remove(INJECT_LONG_COMPUTE)
        .env_remove(INJECT_PREEMPTION);
    if let Some(var) = inject {
        cmd.env(var, EVERY.to_string());
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

fn ns(m: &Value, k: &str) -> u64 {
    m[k].as_u64().unwrap_or_else(|| panic!("no {k} in {m}"))
}

/// The cause a miss's own figures give, by the rule as `MissCause` states it (written
/// out again here, so that the report is checked against the rule and not against
/// itself): a cycle that finished late is cut into wake-up lateness, compute on the CPU,
/// compute off the CPU (`compute − cpu`) and publish, and the largest part is the cause,
/// the earlier on a tie; a cycle on time is a downstream lag.
fn by_the_rule(m: &Value, period_ns: u64) -> &'static str {
    let (wake, compute, publish) = (
        ns(m, "wake_late_ns"),
        ns(m, "compute_ns"),
        ns(m, "publish_ns"),
    );
    if wake + compute + publish <= period_ns {
        return "downstream_lag";
    }
    let off = m["cpu_ns"]
        .as_u64()
        .map_or(0, |cpu| compute.saturating_sub(cpu));
    let mut best = (wake, "late_wake");
    for part in [
        (compute - off, "long_compute"),
        (off, "preempted"),
        (publish, "publish_stall"),
    ] {
        if part.0 > best.0 {
            best = part;
        }
    }
    best.1
}

/// Every miss carries the thread's CPU time, the time its compute spent off the CPU, and
/// the cause those figures give.
fn check_causes(d: &Value) {
    let period = ns(d, "period_ns");
    for m in d["miss_list"].as_array().unwrap() {
        let cpu = m["cpu_ns"].as_u64();
        assert!(cpu.is_some(), "the thread's CPU time was read: {m}");
        let off = ns(m, "compute_ns").saturating_sub(cpu.unwrap_or(0));
        assert_eq!(ns(m, "preempted_ns"), off, "{m}");
        assert_eq!(m["cause"], by_the_rule(m, period), "{m}");
    }
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
    assert_eq!(
        rep["misses_by_cause"], d["misses_by_cause"],
        "report.json agrees"
    );
    let ids: Vec<&str> = d["misses_by_cause"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c[0].as_str().unwrap())
        .collect();
    assert_eq!(
        ids,
        [
            "late_wake",
            "long_compute",
            "publish_stall",
            "downstream_lag",
            "preempted"
        ]
    );
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

/// The cycles every `EVERY`th, up to the run's end.
fn injected_cycles(d: &Value) -> BTreeSet<u64> {
    let cycles = ns(d, "cycles");
    let injected: BTreeSet<u64> = (1..)
        .map(|k| k * EVERY)
        .take_while(|c| *c < cycles)
        .collect();
    assert!(injected.len() >= 10, "{cycles} cycles");
    injected
}

/// The miss of cycle `c`, which must be listed, sending the set-point line it ran.
fn listed<'a>(d: &'a Value, c: u64, setpoints: &[Vec<f64>]) -> &'a Value {
    let m = d["miss_list"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["cycle"] == c)
        .unwrap_or_else(|| panic!("injected cycle {c} is not listed"));
    assert!(ns(m, "overrun_ns") > 0);
    assert_eq!(
        m["line"].as_f64(),
        Some(setpoints[c as usize][5]),
        "cycle {c}"
    );
    m
}

/// Misses by cause, in words for a message.
fn tally<'a>(list: impl Iterator<Item = &'a Value>) -> std::collections::BTreeMap<String, usize> {
    let mut t = std::collections::BTreeMap::new();
    for m in list {
        *t.entry(m["cause"].as_str().unwrap().to_string())
            .or_default() += 1;
    }
    t
}

#[test]
fn injected_long_computes_are_exactly_the_long_compute_misses() {
    let dir = temp_dir("deadline");
    let floor = dir.join("latency-test.json");
    let stdout = run(&dir, "inject", "real", Some(INJECT_LONG_COMPUTE), &floor);
    let d = check_agreement(&dir.join("inject"), &stdout);
    check_causes(&d);
    let injected = injected_cycles(&d);
    let list = d["miss_list"].as_array().unwrap();
    let (_, sp) = tests::csv(&dir.join("inject").join("setpoints.csv"));
    let mut outweighed = Vec::new();
    for c in &injected {
        let m = listed(&d, *c, &sp);
        // The cycle burned 1.5 periods of its own CPU time, within its compute phase.
        let (compute, cpu, off) = (ns(m, "compute_ns"), ns(m, "cpu_ns"), ns(m, "preempted_ns"));
        assert!(cpu >= 1_500_000, "cycle {c} ran {cpu} ns: {m}");
        assert!(
            compute - off >= 1_500_000,
            "cycle {c} computed on the CPU: {m}"
        );
        if m["cause"] != "long_compute" {
            // Only a part longer still than those 1.5 periods (a later wake-up, a longer
            // preemption) may take the blame; check_causes holds it to the rule.
            assert!(
                ns(m, "wake_late_ns").max(off).max(ns(m, "publish_ns")) >= compute - off,
                "cycle {c}: {m}"
            );
            outweighed.push(m);
        }
    }
    // Every cycle that was not injected ran its compute in tens of microseconds: where it
    // was late, something else took its time. A cycle preempted mid-compute (a loaded
    // machine: once seen while another build ran) used to be taken for a long compute
    // by the wall clock; its CPU time now names it `preempted`. Some strays may still
    // be: on these kernels (no IRQ_TIME_ACCOUNTING) an interrupt storm is charged to the
    // thread as its own CPU time, and a noisy neighbour can slow the CPU itself. Such
    // strays are shown and must stay few; none were seen in 5 loaded runs.
    let (long, stray): (Vec<&Value>, Vec<&Value>) = list
        .iter()
        .filter(|m| m["cause"] == "long_compute")
        .partition(|m| injected.contains(&ns(m, "cycle")));
    if !stray.is_empty() {
        println!(
            "{} long computes that were not injected: {stray:?}",
            stray.len()
        );
    }
    assert!(
        stray.len() <= injected.len() / 4,
        "{} long computes that were not injected: {stray:?}",
        stray.len()
    );
    assert_eq!(long.len() + outweighed.len(), injected.len());
    println!(
        "{} injected, {} classified long compute, {} outweighed ({:?}); {} misses in all, \
         by cause {:?}",
        injected.len(),
        long.len(),
        outweighed.len(),
        tally(outweighed.iter().copied()),
        d["misses"],
        tally(list.iter())
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

/// A real preemption: every `EVERY`th cycle, a thread pinned to the interpolator's CPU
/// one SCHED_FIFO priority above it is woken from the cycle's compute phase and holds the
/// CPU for 1.5 periods. Those cycles computed long by the wall clock but ran only tens of
/// microseconds: each must be a miss, and `preempted` (never `long_compute`) unless
/// another part of it was longer still. Without real-time priorities nothing can preempt
/// the cycle on cue, and the test says so and checks nothing more.
#[test]
fn injected_preemptions_are_preempted_misses_not_long_computes() {
    let dir = temp_dir("preempt");
    let floor = dir.join("latency-test.json");
    let stdout = run(&dir, "preempt", "real", Some(INJECT_PREEMPTION), &floor);
    let out = dir.join("preempt");
    let d = check_agreement(&out, &stdout);
    check_causes(&d);
    let sched = &report(&out)["sched"];
    let refused = sched["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .find(|w| w.contains("no preemption injected"));
    if sched["policy"] != "fifo" || sched["cpu"].is_null() || refused.is_some() {
        println!(
            "SKIPPED injected_preemptions_are_preempted_misses_not_long_computes: real \
             preemption needs the cycle at SCHED_FIFO on a pinned CPU and a higher \
             real-time priority for the competitor; this run had {sched}"
        );
        return;
    }
    let injected = injected_cycles(&d);
    let (_, sp) = tests::csv(&out.join("setpoints.csv"));
    let (mut preempted, mut held) = (0, 0);
    for c in &injected {
        let m = listed(&d, *c, &sp);
        // Held off its CPU for 1.5 periods; its own CPU time over the cycle (compute,
        // wake-up and the previous publish) is far below the period. Counted, not
        // required of each: on a loaded machine a cycle woken late (1.7 ms in one CI
        // run) meets the competitor part-way through its hold, and only the rest of it
        // (0.76 ms there) falls in the cycle.
        if ns(m, "preempted_ns") >= 1_000_000 {
            held += 1;
        }
        assert_ne!(m["cause"], "long_compute", "cycle {c}: {m}");
        if m["cause"] == "preempted" {
            preempted += 1;
        }
    }
    let list = d["miss_list"].as_array().unwrap();
    println!(
        "{} preemptions injected, {preempted} classified preempted; {} misses in all, by \
         cause {:?}",
        injected.len(),
        d["misses"],
        tally(list.iter())
    );
    // A late wake-up longer than the preemption may take the blame now and then; most
    // injected cycles are preempted and named so.
    assert!(
        preempted * 2 >= injected.len(),
        "{preempted} of {injected:?}"
    );
    assert!(
        held * 2 >= injected.len(),
        "{held} of {injected:?} held off the CPU for 1 ms or more"
    );
    // A stray long compute elsewhere (an interrupt storm is charged to the thread as
    // CPU time on these kernels) is counted, not forbidden: a timing test must not
    // assert zero on a shared machine. It must stay under a quarter of the injected
    // preemptions, as the stray long computes of the test above.
    let long = list.iter().filter(|m| m["cause"] == "long_compute").count();
    assert!(
        long * 4 < injected.len().max(1),
        "{long} long computes against {} injected preemptions",
        injected.len()
    );
    assert!(d["summary"]
        .as_str()
        .unwrap()
        .contains(" preempted mid-compute"));
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
    let stdout = run(&dir, "sim", "sim", Some(INJECT_LONG_COMPUTE), &floor);
    let sim = dir.join("sim");
    let d = deadline(&sim);
    assert_eq!(d["measured"], false);
    assert!(d["misses"].is_null() && d["miss_list"].as_array().unwrap().is_empty());
    assert!(report(&sim)["misses"].is_null());
    let text = std::fs::read_to_string(sim.join("deadline-misses.txt")).unwrap();
    assert!(text.contains("timing not measured"));
    assert!(stdout.contains("  deadlines    not measured (sim clock)"));
}
