//! The timing section: what the interpolator measured about its own deadlines.
//!
//! The run directory holds, per timing figure, only p50, p99 and the maximum (the
//! interpolator keeps its histogram in memory and reports percentiles), plus each miss in
//! full up to a capacity. So this section draws exactly those: the percentiles as bars on
//! a log scale with the period marked, every recorded miss on the time axis (marker shape
//! and colour by cause), and a table of the worst misses with their source line. No
//! per-cycle histogram is drawn because no per-cycle timing was recorded; the page says
//! so. Under the simulated clock nothing was measured, and the page says that instead.

use super::data::{Miss, Pct, Run};
use super::series::time_range;
use super::svg::{esc, num, pad_range, Chart, LIMIT};
use std::collections::HashSet;
use std::fmt::Write;

/// Rows in the table of worst misses.
const WORST: usize = 25;

/// Marker colour, SVG shape and words for a miss cause.
fn cause(c: &str) -> (&'static str, &'static str, &'static str) {
    match c {
        "late_wake" => (
            "#1f3b73",
            "circle",
            "late wake-up (the OS woke the loop late)",
        ),
        "compute" => (
            "#c05a00",
            "square",
            "compute (stepping the path took too long)",
        ),
        "publish" => (
            "#2a7f3f",
            "triangle",
            "publish (handing the set-point over took too long)",
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
    let Some(rep) = &run.report else {
        out.push_str("<p class=\"missing\">Timing unknown: report.json is missing or unusable.</p></section>");
        return;
    };
    let pcts = (rep.wake_late_ns, rep.compute_ns, rep.publish_ns);
    let (Some(wake), Some(comp), Some(publ)) = pcts else {
        let why = if rep.clock.as_deref() == Some("sim") {
            "Timing was not measured: this run used the simulated clock (each cycle starts as soon as the drives answered the previous one, without sleeping), so wake-up lateness, compute time and deadline misses have no meaning here. Run with <code>--clock real</code> to measure them."
        } else {
            "Timing was not recorded in report.json for this run."
        };
        let _ = write!(
            out,
            "<p class=\"note\" id=\"timing-not-measured\">{why}</p></section>"
        );
        return;
    };
    let period_us = run.period_ns as f64 / 1000.0;
    percentiles(
        &[("wake-up late", wake), ("compute", comp), ("publish", publ)],
        period_us,
        out,
    );
    misses(run, &rep.miss_list, rep.misses, out);
    out.push_str("</section>");
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
    out.push_str("<p class=\"note\">The run directory records p50, p99 and the maximum of each figure, not every cycle, so these three values are drawn instead of a histogram.</p>");
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
        "Deadline misses over time: how late each missed cycle finished, by cause",
        "time (s)",
        "overrun (µs)",
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
    for name in ["late_wake", "compute", "publish"] {
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
    worst.sort_by(|a, b| b.overrun_ns.total_cmp(&a.overrun_ns));
    worst.truncate(WORST);
    let _ = write!(
        out,
        "<h3>Worst misses</h3><p class=\"note\">{} of {} misses, by overrun{}.</p><table class=\"data\" id=\"miss-table\"><tr><th>cycle</th><th>time (s)</th><th>line</th><th>source</th><th>cause</th><th>wake-up late (µs)</th><th>compute (µs)</th><th>publish (µs)</th><th>overrun (µs)</th></tr>",
        worst.len(),
        total,
        if total > list.len() as u64 {
            format!(" ({} recorded in full in report.json; later ones only counted)", list.len())
        } else {
            String::new()
        }
    );
    for m in worst {
        let _ = write!(
            out,
            "<tr><td>{}</td><td>{:.3}</td><td>{}</td><td><code>{}</code></td><td>{}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1}</td></tr>",
            m.cycle,
            m.cycle as f64 * period,
            m.line,
            esc(run.source(m.line.min(u32::MAX as u64) as u32)),
            match cause(&m.cause).2 {
                "other" => esc(&m.cause),
                words => words.to_string(),
            },
            m.wake_late_ns / 1000.0,
            m.compute_ns / 1000.0,
            m.publish_ns / 1000.0,
            m.overrun_ns / 1000.0
        );
    }
    out.push_str("</table>");
}
