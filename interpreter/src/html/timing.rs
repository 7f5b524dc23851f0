//! The timing section: what the interpolator measured about its own deadlines.
//!
//! From `deadline-misses.json` (written by the interpolator at the end of every run): the
//! log-bucketed histograms of wake-up lateness, compute time and publish time, drawn on
//! log-log axes with the period marked (and this machine's floor from `cnc latency-test`,
//! when there is one), the percentiles, every miss on the time axis (marker shape and
//! colour by cause: late wake-up, long compute, preempted mid-compute, publish stall,
//! downstream lag), the runs of consecutive misses and a table of the misses, worst first,
//! with how long each compute phase was off the CPU (what tells a preempted cycle from a
//! slow one), listing every one of them up to [`MAX_ROWS`]. Run directories older than that file have
//! only report.json's p50/p99/max and the first misses; then those are drawn as bars and
//! the page says why there is no histogram. Under the simulated clock nothing was measured,
//! and the page says that instead.

use super::data::{Miss, Pct, Run};
use super::series::time_range;
use super::svg::{esc, num, pad_range, Chart, LIMIT};
use interpolator::deadline::{cause_words, DeadlineReport, Figure};
use std::collections::HashSet;
use std::fmt::Write;

/// Most rows in the miss table (worst first); a run with more misses lists them all in
/// deadline-misses.json, and the page says how many it leaves out.
pub const MAX_ROWS: usize = 1000;

/// Rows of the miss table shown at once; the rest fold away under a `<details>` (no
/// script: the browser opens it), so that a run with hundreds of misses does not fill
/// the page with them.
pub const SHOWN_ROWS: usize = 20;

/// Marker colour, SVG shape and words for a miss cause.
fn cause(c: &str) -> (&'static str, &'static str, &'static str) {
    match c {
        "late_wake" => (
            "#1f3b73",
            "circle",
            "late wake-up (the OS woke the loop late)",
        ),
        "long_compute" | "compute" => (
            "#c05a00",
            "square",
            "long compute (stepping the path took too long)",
        ),
        "publish_stall" | "publish" => (
            "#2a7f3f",
            "triangle",
            "publish stall (handing the set-point over took too long)",
        ),
        "downstream_lag" => (
            "#7a1f7a",
            "cross",
            "downstream not consuming (the drives answered late)",
        ),
        "preempted" => (
            "#0e7c86",
            "diamond",
            "preempted mid-compute (the OS took the CPU away while the path was computed: the machine's real-time set-up, not the path evaluation)",
        ),
        _ => ("#555555", "cross", "other"),
    }
}

fn marker(out: &mut String, shape: &str, x: f64, y: f64, col: &str) {
    let _ = match shape {
        "circle" => write!(
            out,
            r#"<circle cx="{x:.1}" cy="{y:.1}" r="4" fill="none" stroke="{col}" stroke-width="1.6"/>"#
        ),
        "square" => write!(
            out,
            r#"<rect x="{:.1}" y="{:.1}" width="7" height="7" fill="{col}"/>"#,
            x - 3.5,
            y - 3.5
        ),
        "triangle" => write!(
            out,
            r#"<path d="M{x:.1} {:.1}l4.5 8h-9z" fill="{col}"/>"#,
            y - 5.0
        ),
        "diamond" => write!(
            out,
            r#"<path d="M{x:.1} {:.1}l5 5l-5 5l-5 -5z" fill="none" stroke="{col}" stroke-width="1.6"/>"#,
            y - 5.0
        ),
        _ => write!(
            out,
            r#"<path d="M{:.1} {:.1}l8 8m0 -8l-8 8" stroke="{col}" stroke-width="1.6"/>"#,
            x - 4.0,
            y - 4.0
        ),
    };
}

pub fn section(run: &Run, out: &mut String) {
    out.push_str("<section id=\"timing\"><h2>Timing</h2>");
    match &run.deadline {
        Some(d) if !d.measured => not_measured(d.clock == "sim", out),
        Some(d) => measured(run, d, out),
        None => from_report(run, out),
    }
    out.push_str("</section>");
}

fn not_measured(sim: bool, out: &mut String) {
    let why = if sim {
        "Timing was not measured: this run used the simulated clock (each cycle starts as soon as the drives answered the cycles a few before it, without sleeping), so wake-up lateness, compute time and deadline misses have no meaning here. Run with <code>--clock real</code> to measure them."
    } else {
        "Timing was not recorded for this run."
    };
    let _ = write!(
        out,
        "<p class=\"note\" id=\"timing-not-measured\">{why}</p>"
    );
}

/// The full picture, from deadline-misses.json.
fn measured(run: &Run, d: &DeadlineReport, out: &mut String) {
    let _ = write!(
        out,
        "<p id=\"deadline-summary\"><b>{}</b></p><p class=\"note\" id=\"floor-compare\">Against this machine's own floor (<code>cnc latency-test</code>): {}.</p>",
        esc(&d.summary),
        esc(&d.vs_floor)
    );
    let figs: Vec<(&str, &Figure)> = [
        ("wake-up late", d.wake_late_ns.as_ref()),
        ("compute", d.compute_ns.as_ref()),
        ("publish", d.publish_ns.as_ref()),
    ]
    .into_iter()
    .filter_map(|(n, f)| f.map(|f| (n, f)))
    .collect();
    out.push_str("<table class=\"figs\" id=\"timing-table\"><tr><th></th><th>min</th><th>mean</th><th>p50</th><th>p90</th><th>p99</th><th>p99.9</th><th>max</th></tr>");
    for (name, f) in &figs {
        let p = f.percentiles;
        let us = |ns: u64| format!("{:.1}", ns as f64 / 1000.0);
        let _ = write!(
            out,
            "<tr><th>{name} (µs)</th><td>{}</td><td>{:.1}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            us(f.min_ns),
            f.mean_ns / 1000.0,
            us(p.p50),
            us(p.p90),
            us(p.p99),
            us(p.p999),
            us(p.max)
        );
    }
    out.push_str("</table>");
    let floor = d.floor.as_ref().map(|f| f.wake_late_ns);
    let hists = [
        ("wake-hist", "wake-up lateness"),
        ("compute-hist", "compute time"),
        ("publish-hist", "publish time"),
    ];
    for ((id, name), (_, f)) in hists.iter().zip(&figs) {
        let floor = if *id == "wake-hist" { floor } else { None };
        histogram(id, name, f, run.period_ns, floor, out);
    }
    let list: Vec<Miss> = d
        .miss_list
        .iter()
        .map(|m| Miss {
            cycle: m.cycle,
            line: u64::from(m.line),
            cause: m.cause.clone(),
            wake_late_ns: m.wake_late_ns as f64,
            compute_ns: m.compute_ns as f64,
            publish_ns: m.publish_ns as f64,
            overrun_ns: m.overrun_ns as f64,
            preempted_ns: m.preempted_ns as f64,
        })
        .collect();
    if d.lost > 0 {
        let _ = write!(
            out,
            "<p class=\"bad\">{} miss records were lost (the interpolator's miss log fell a whole ring behind); they are counted, not listed.</p>",
            d.lost
        );
    }
    misses(run, &list, d.misses, out);
    if !d.runs.is_empty() {
        let mut runs = d.runs.clone();
        runs.sort_by(|a, b| {
            b.length
                .cmp(&a.length)
                .then(a.start_cycle.cmp(&b.start_cycle))
        });
        let shown = runs.len().min(50);
        let _ = write!(
            out,
            "<h3>Runs of consecutive misses</h3><p class=\"note\">{} run(s) of two or more missed cycles in a row; the longest {shown} here, all in deadline-misses.json.</p><table class=\"data\" id=\"runs-table\"><tr><th>first cycle</th><th>time (s)</th><th>cycles</th></tr>",
            runs.len()
        );
        for r in &runs[..shown] {
            let _ = write!(
                out,
                "<tr><td>{}</td><td>{:.3}</td><td>{}</td></tr>",
                r.start_cycle,
                r.start_cycle as f64 * run.period_s(),
                r.length
            );
        }
        out.push_str("</table>");
    }
}

/// Older run directories: report.json's percentiles and misses only.
fn from_report(run: &Run, out: &mut String) {
    let Some(rep) = &run.report else {
        out.push_str(
            "<p class=\"missing\">Timing unknown: report.json is missing or unusable.</p>",
        );
        return;
    };
    let pcts = (rep.wake_late_ns, rep.compute_ns, rep.publish_ns);
    let (Some(wake), Some(comp), Some(publ)) = pcts else {
        not_measured(rep.clock.as_deref() == Some("sim"), out);
        return;
    };
    let period_us = run.period_ns as f64 / 1000.0;
    percentiles(
        &[("wake-up late", wake), ("compute", comp), ("publish", publ)],
        period_us,
        out,
    );
    misses(run, &rep.miss_list, rep.misses, out);
}

/// One histogram on log-log axes: cycles per bucket over time per cycle, with the
/// period (and the machine's floor) marked.
fn histogram(
    id: &str,
    name: &str,
    f: &Figure,
    period_ns: u64,
    floor: Option<interpolator::timing::Percentiles>,
    out: &mut String,
) {
    let period_us = period_ns as f64 / 1000.0;
    let lo_us = f
        .histogram
        .first()
        .map_or(1.0, |b| (b.lo_ns.max(1) as f64 / 1000.0).max(0.01));
    let hi_us = f
        .histogram
        .last()
        .map_or(period_us, |b| b.hi_ns as f64 / 1000.0)
        .max(period_us * 1.5);
    let x = (
        10f64.powf(lo_us.log10().floor()),
        10f64.powf(hi_us.log10().ceil()),
    );
    let top = f
        .histogram
        .iter()
        .map(|b| b.count)
        .max()
        .unwrap_or(1)
        .max(1) as f64;
    let y = (0.5, 10f64.powf((top * 1.5).log10().ceil()));
    let mut c = Chart::new(
        id,
        &format!("Histogram of the {name} of each cycle (log-log), with the period"),
        &format!("{name} (µs, log scale)"),
        "cycles (log scale)",
        x,
        y,
    );
    c.x_log = true;
    c.y_log = true;
    c.h = 260.0;
    c.open(out);
    let base = c.py(y.0);
    for b in &f.histogram {
        let (x0, x1) = (
            c.px((b.lo_ns as f64 / 1000.0).max(x.0)),
            c.px(b.hi_ns as f64 / 1000.0),
        );
        let top = c.py(b.count as f64);
        let _ = write!(
            out,
            r##"<rect x="{x0:.1}" y="{top:.1}" width="{:.1}" height="{:.1}" fill="#9a9a9a" stroke="#222" stroke-width="0.4"><title>{:.2}–{:.2} µs: {} cycles</title></rect>"##,
            (x1 - x0).max(0.8),
            (base - top).max(0.5),
            b.lo_ns as f64 / 1000.0,
            b.hi_ns as f64 / 1000.0,
            b.count
        );
    }
    let mut marks = String::new();
    let mut vline = |v_us: f64, label: &str, dash: &str, color: &str, row: f64| {
        let xp = c.px(v_us);
        let _ = write!(
            marks,
            r#"<line x1="{xp:.1}" y1="{:.1}" x2="{xp:.1}" y2="{base:.1}" stroke="{color}" stroke-width="1.5" stroke-dasharray="{dash}"/><text x="{:.1}" y="{:.1}" class="lim" style="fill:{color}">{label}</text>"#,
            c.mt,
            xp - 4.0,
            c.mt + 12.0 + row * 13.0,
        );
    };
    vline(
        period_us,
        &format!("period {} µs", num(period_us)),
        LIMIT.dash,
        LIMIT.color,
        0.0,
    );
    if let Some(fl) = floor {
        let v = fl.max as f64 / 1000.0;
        if v > x.0 {
            vline(
                v,
                &format!("machine floor max {} µs", num(v)),
                "2 3",
                "#1f3b73",
                1.0,
            );
        }
    }
    c.close_with(out, &[], &marks);
}

fn percentiles(figs: &[(&str, Pct)], period_us: f64, out: &mut String) {
    out.push_str("<table class=\"figs\" id=\"timing-table\"><tr><th></th><th>p50</th><th>p99</th><th>max</th></tr>");
    for (name, p) in figs {
        let _ = write!(
            out,
            "<tr><th>{name} (µs)</th><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr>",
            p.p50 / 1000.0,
            p.p99 / 1000.0,
            p.max / 1000.0
        );
    }
    out.push_str("</table>");
    let hi = figs
        .iter()
        .map(|f| f.1.max / 1000.0)
        .fold(period_us, f64::max)
        * 2.0;
    let lo = figs
        .iter()
        .map(|f| f.1.p50 / 1000.0)
        .filter(|v| *v > 0.0)
        .fold(period_us, f64::min)
        / 2.0;
    let lo = 10f64.powf(lo.max(0.01).log10().floor());
    let mut c = Chart::new(
        "pct-plot",
        "Timing percentiles per cycle (p50, p99, max), log scale, with the period",
        "time per cycle (µs, log scale)",
        "",
        (lo, 10f64.powf(hi.log10().ceil())),
        (0.0, figs.len() as f64),
    );
    c.x_log = true;
    c.h = 60.0 + 46.0 * figs.len() as f64;
    c.ml = 110.0;
    c.y_cats = figs.iter().rev().map(|f| f.0.to_string()).collect();
    c.open(out);
    let fills = [("p50", "#d9d9d9"), ("p99", "#8c8c8c"), ("max", "#262626")];
    for (i, (_, p)) in figs.iter().enumerate() {
        let row = (figs.len() - 1 - i) as f64;
        for (k, v) in [p.p50, p.p99, p.max].into_iter().enumerate() {
            let y0 = c.py(row + 0.85 - k as f64 * 0.25);
            let x1 = c.px((v / 1000.0).max(lo));
            let _ = write!(
                out,
                r##"<rect x="{:.1}" y="{y0:.1}" width="{:.1}" height="{:.1}" fill="{}" stroke="#000" stroke-width="0.5"><title>{} {}: {:.1} µs</title></rect>"##,
                c.ml,
                (x1 - c.ml).max(0.5),
                (c.py(0.0) - c.py(0.22)).abs(),
                fills[k].1,
                figs[i].0,
                fills[k].0,
                v / 1000.0
            );
        }
    }
    let xp = c.px(period_us);
    let _ = write!(
        out,
        r#"<line x1="{xp:.1}" y1="{:.1}" x2="{xp:.1}" y2="{:.1}" stroke="{}" stroke-width="1.5" stroke-dasharray="{}"/>"#,
        c.mt,
        c.py(0.0),
        LIMIT.color,
        LIMIT.dash
    );
    let mut legend = String::new();
    let mut x = c.ml + 200.0;
    for (name, fill) in fills {
        let _ = write!(
            legend,
            r##"<rect x="{x:.1}" y="27" width="14" height="10" fill="{fill}" stroke="#000" stroke-width="0.5"/><text x="{:.1}" y="36" class="lg">{name}</text>"##,
            x + 18.0
        );
        x += 60.0;
    }
    let _ = write!(
        legend,
        r#"<text x="{:.1}" y="{:.1}" class="lim">period {} µs</text>"#,
        xp + 4.0,
        c.mt + 12.0,
        num(period_us)
    );
    c.close_with(out, &[], &legend);
    out.push_str("<p class=\"note\">This run directory has no deadline-misses.json (it is older than that file), only p50, p99 and the maximum of each figure in report.json, so these three values are drawn instead of a histogram.</p>");
}

fn misses(run: &Run, list: &[Miss], count: Option<u64>, out: &mut String) {
    let total = count.unwrap_or(list.len() as u64);
    if total == 0 {
        out.push_str("<p class=\"note\" id=\"no-misses\">No deadline misses: every cycle finished within its period.</p>");
        return;
    }
    let tr = time_range(run);
    let period = run.period_s();
    let top = list
        .iter()
        .map(|m| m.overrun_ns / 1000.0)
        .fold(0.0, f64::max);
    let c = Chart::new(
        "miss-plot",
        "Deadline misses over time: how late each missed cycle was, by cause",
        "time (s)",
        "late by (µs)",
        tr,
        pad_range(0.0, top, true),
    );
    c.open(out);
    // One marker per pixel and cause is enough: a long burst stays visible but bounded.
    let mut seen = HashSet::new();
    for m in list {
        let (col, shape, _) = cause(&m.cause);
        let (x, y) = (c.px(m.cycle as f64 * period), c.py(m.overrun_ns / 1000.0));
        if seen.insert((x as i64, y as i64, shape)) {
            marker(out, shape, x, y, col);
        }
    }
    let mut legend = String::new();
    let mut x = c.ml;
    for name in [
        "late_wake",
        "long_compute",
        "preempted",
        "publish_stall",
        "downstream_lag",
    ] {
        let (col, shape, words) = cause(name);
        marker(&mut legend, shape, x + 5.0, 32.0, col);
        let short = words.split(" (").next().unwrap_or(words);
        let _ = write!(
            legend,
            r#"<text x="{:.1}" y="36" class="lg">{short}</text>"#,
            x + 14.0
        );
        x += 30.0 + 6.5 * short.len() as f64;
    }
    c.close_with(out, &[], &legend);
    let mut worst: Vec<&Miss> = list.iter().collect();
    worst.sort_by(|a, b| {
        b.overrun_ns
            .total_cmp(&a.overrun_ns)
            .then(a.cycle.cmp(&b.cycle))
    });
    worst.truncate(MAX_ROWS);
    let listed = if worst.len() as u64 == total {
        format!("Every one of the {total} misses, worst first.")
    } else if (list.len() as u64) < total && worst.len() == list.len() {
        format!(
            "The {} misses recorded in full of {total}, worst first.",
            list.len()
        )
    } else {
        format!(
            "The {} worst of {total} misses; every miss is in deadline-misses.json.",
            worst.len()
        )
    };
    let head = "<tr><th>cycle</th><th>time (s)</th><th>line</th><th>source</th><th>cause</th><th>wake-up late (µs)</th><th>compute (µs)</th><th>off the CPU (µs)</th><th>publish (µs)</th><th>late by (µs)</th></tr>";
    let _ = write!(
        out,
        "<h3>Misses</h3><p class=\"note\">{listed} Late by: finish minus deadline (downstream: how long the drives' answer is overdue). Off the CPU: the part of the compute time the interpolator's thread was not running (compute time minus the thread's own CPU time); when that is the largest part of the cycle, the cause is a preemption, not slow path evaluation.</p><table class=\"data\" id=\"miss-table\">{head}"
    );
    let rest = worst.len().saturating_sub(SHOWN_ROWS);
    for (k, m) in worst.into_iter().enumerate() {
        if k == SHOWN_ROWS {
            let _ = write!(
                out,
                "</table><details><summary>The other {rest} {} listed</summary><table class=\"data\" id=\"miss-table-more\">{head}",
                if rest == 1 { "miss" } else { "misses" }
            );
        }
        let _ = write!(
            out,
            "<tr><td>{}</td><td>{:.3}</td><td>{}</td><td><code>{}</code></td><td>{}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr>",
            m.cycle,
            m.cycle as f64 * period,
            m.line,
            esc(run.source(m.line.min(u32::MAX as u64) as u32)),
            esc(cause_words(&m.cause)),
            m.wake_late_ns / 1000.0,
            m.compute_ns / 1000.0,
            m.preempted_ns / 1000.0,
            m.publish_ns / 1000.0,
            m.overrun_ns / 1000.0
        );
    }
    out.push_str("</table>");
    if rest > 0 {
        out.push_str("</details>");
    }
}
