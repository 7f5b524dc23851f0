//! The page: heading, what is missing, the summary table, then each section, with one
//! `<style>` block. Summary cells carry `data-key` attributes naming the `report.json`
//! field they show, so tools and tests can find a figure without parsing prose.

use super::data::{Report, Run};
use super::svg::{esc, num};
use super::{path, polar, scallop, series, timing, view3d};
use std::fmt::Write;

const CSS: &str = r#"
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;color:#111;margin:0;background:#f3f3f1}
main{max-width:1060px;margin:0 auto;padding:16px 24px 48px;background:#fff}
h1{font-size:22px;margin:8px 0 4px}h2{font-size:18px;border-bottom:2px solid #222;margin-top:32px}h3{font-size:15px}
.sub{color:#555;margin:0 0 12px}
.problems{border:2px solid #b00020;background:#fff3f3;padding:8px 16px;margin:12px 0}
.problems h2{border:0;margin:4px 0;color:#b00020}
.missing{border-left:4px solid #b00020;padding:6px 10px;background:#fff3f3}
.note{color:#333;font-size:13px}
table{border-collapse:collapse;margin:8px 0}
th,td{padding:3px 10px;border-bottom:1px solid #ddd;text-align:left;vertical-align:top}
td{font-variant-numeric:tabular-nums}
table.data td{text-align:right}table.data td:nth-child(4),table.data td:nth-child(5){text-align:left}
.bad{color:#b00020;font-weight:600}.good{color:#1b6e2f;font-weight:600}
.row{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}
svg.chart{display:block;max-width:100%;height:auto;margin:6px 0}
svg text{font-family:system-ui,sans-serif;fill:#111}
.ttl{font-size:14px;font-weight:600}.tx{font-size:11px;text-anchor:middle}.ty{font-size:11px;text-anchor:end}
.xl,.yl{font-size:12px;text-anchor:middle}.lg{font-size:12px}.lim{font-size:11px;text-anchor:end;fill:#b00020}
.area{fill:#fff;stroke:#444}.grid{stroke:#d8d8d8;stroke-width:.6}.ring0{stroke:#000;stroke-width:1.4}
.feed{fill:none;stroke-width:2;stroke-linejoin:round;stroke-linecap:round}
.rapid{fill:none;stroke:#8a8a8a;stroke-width:1;stroke-dasharray:5 4}
.notrun{fill:none;stroke:#c4c4c4;stroke-width:2;stroke-linejoin:round}
.wire{fill:none;stroke:#8fa3b8;stroke-width:.8}
.blk:hover .feed,.blk:hover .rapid{stroke-width:4}
.switch{margin:6px 0;font-size:14px}.switch label{margin:0 14px 0 4px}
.by-error{display:none}#path-by-error:checked~.by-error{display:flex}#path-by-error:checked~.by-feed{display:none}
.mark text{font-size:12px;font-weight:600}
@media print{body{background:#fff}main{padding:0}}
"#;

/// The whole page for `run`.
pub fn page(run: &Run) -> String {
    let mut body = String::new();
    let contour = super::measure::Measure::of(run);
    path::section(run, contour.as_ref(), &mut body);
    view3d::section(run, contour.as_ref(), &mut body);
    scallop::section(run, &mut body);
    series::motion(run, &mut body);
    let max_contour = series::errors(run, contour.as_ref(), &mut body);
    polar::section(contour.as_ref(), &mut body);
    timing::section(run, &mut body);

    let program = run
        .report
        .as_ref()
        .and_then(|r| r.program.clone())
        .unwrap_or_else(|| "(program unknown)".into());
    let mut out = String::with_capacity(body.len() + 16_384);
    let _ = write!(
        out,
        "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><meta name=\"viewport\" content=\"width=device-width, initial-scale=1\"><title>cnc run: {p}</title><style>{CSS}</style></head><body><main><h1>Run report: {p}</h1><p class=\"sub\">Run directory <code>{d}</code></p>",
        p = esc(&program),
        d = esc(&run.dir.display().to_string())
    );
    if !run.problems.is_empty() {
        out.push_str("<div class=\"problems\" id=\"problems\"><h2>Missing or damaged in this run directory</h2><ul>");
        for p in &run.problems {
            let _ = write!(out, "<li>{}</li>", esc(p));
        }
        out.push_str("</ul><p>Everything that could be read is drawn below; plots that need a missing file say so in place.</p></div>");
    }
    summary(run, max_contour, &mut out);
    out.push_str(&body);
    out.push_str("<p class=\"note\">Made by <code>cnc report</code>. Plots reduce the data to the minimum and maximum per pixel column, so no single-cycle spike is lost; the figures in the summary are those of report.json.</p></main></body></html>\n");
    out
}

fn row(out: &mut String, key: &str, name: &str, value: &str) {
    let _ = write!(
        out,
        "<tr><th>{name}</th><td data-key=\"{key}\">{value}</td></tr>"
    );
}

fn or_missing<T>(v: Option<T>, f: impl Fn(T) -> String) -> String {
    v.map_or_else(|| "<span class=\"bad\">not recorded</span>".into(), f)
}

fn summary(run: &Run, max_contour: Option<f64>, out: &mut String) {
    out.push_str("<section id=\"summary\"><h2>Summary</h2>");
    let Some(r) = &run.report else {
        out.push_str("<p class=\"missing\">No summary figures: report.json is missing or unusable (see above). The plots below are drawn from the other files.</p></section>");
        return;
    };
    out.push_str("<table class=\"figs\">");
    row(
        out,
        "program",
        "program",
        &or_missing(r.program.as_deref(), |p| match &r.dialect {
            Some(d) => format!("<code>{}</code> ({} dialect)", esc(p), esc(d)),
            None => format!("<code>{}</code>", esc(p)),
        }),
    );
    row(out, "outcome", "outcome", &outcome(r));
    if !r.notes.is_empty() {
        let notes: Vec<String> = r
            .notes
            .iter()
            .map(|(line, n)| format!("line {line}: {}", esc(n)))
            .collect();
        row(out, "notes", "notes", &notes.join("<br>"));
    }
    row(
        out,
        "period_ns",
        "interpolation period",
        &format!(
            "{} µs ({} Hz)",
            num(run.period_ns as f64 / 1000.0),
            num(1e9 / run.period_ns as f64)
        ),
    );
    row(
        out,
        "clock",
        "clock",
        &or_missing(r.clock.as_deref(), |c| match c {
            "real" => "real time (cycles released by the system clock)".into(),
            "sim" => "simulated (cycles run back to back, no sleeping; timing not measured)".into(),
            other => esc(other),
        }),
    );
    row(
        out,
        "sched",
        "scheduling in force",
        &or_missing(r.sched.as_ref(), |s| {
            let mut t = match s.policy.as_str() {
                "fifo" => format!("SCHED_FIFO (real-time) priority {}", s.priority),
                "other" => "SCHED_OTHER (ordinary time sharing, not real-time)".into(),
                p => esc(p),
            };
            t.push_str(if s.memory_locked {
                ", memory locked"
            } else {
                ", memory not locked"
            });
            for w in &s.warnings {
                let _ = write!(t, "<br><span class=\"bad\">warning: {}</span>", esc(w));
            }
            t
        }),
    );
    row(
        out,
        "time_s",
        "machining time",
        &or_missing(r.time_s, |v| format!("{v:.3} s")),
    );
    row(
        out,
        "cycles",
        "cycles",
        &or_missing(r.cycles, |v| v.to_string()),
    );
    row(
        out,
        "path_length_mm",
        "path length",
        &or_missing(r.path_length_mm, |v| format!("{v:.3} mm")),
    );
    row(
        out,
        "avg_feed_mm_per_min",
        "average feed",
        &or_missing(r.avg_feed_mm_per_min, |v| format!("{v:.1} mm/min")),
    );
    // A STEP-NC part's blocks command the tool's reference point, whose speed is the
    // feed's only where the surface is level: over a convex part it runs faster than F.
    let surface = run.motion().any(|b| b.is_surface());
    row(
        out,
        "peak_feed_mm_per_min",
        if surface {
            "peak feed (of the tool's centre)"
        } else {
            "peak feed"
        },
        &or_missing(r.peak_feed_mm_per_min, |v| {
            if surface {
                format!("{v:.1} mm/min (the tool's reference point; the programmed feed is the contact point's, so over a convex surface the centre runs faster)")
            } else {
                format!("{v:.1} mm/min")
            }
        }),
    );
    row(
        out,
        "max_following_error_um",
        "max following error",
        &or_missing(r.max_following_error_um, |v| {
            let axes = r.max_following_error_axis_um.map_or(String::new(), |a| {
                format!(" (X {:.2}, Y {:.2}, Z {:.2} µm)", a[0], a[1], a[2])
            });
            format!("{v:.2} µm{axes}")
        }),
    );
    row(
        out,
        "rms_following_error_axis_um",
        "RMS following error",
        &r.rms_following_error_axis_um.map_or_else(
            || "not recorded".into(),
            |a| format!("X {:.2}, Y {:.2}, Z {:.2} µm", a[0], a[1], a[2]),
        ),
    );
    let contour = match (r.max_contour_error_um, max_contour) {
        (Some(v), _) => {
            let at = match (r.max_contour_error_cycle, r.max_contour_error_line) {
                (Some(c), Some(l)) => format!(" at cycle {c}, line {l}"),
                _ => String::new(),
            };
            format!("{v:.2} µm{at}")
        }
        (None, Some(v)) => format!("{v:.2} µm (computed here; not in report.json)"),
        (None, None) => "not available".into(),
    };
    row(
        out,
        "max_contour_error_um",
        "max contour error (distance to the commanded path)",
        &contour,
    );
    row(
        out,
        "rms_contour_error_um",
        "RMS contour error",
        &r.rms_contour_error_um
            .map_or_else(|| "not available".into(), |v| format!("{v:.2} µm")),
    );
    row(
        out,
        "max_chord_error_um",
        "max chord error (set-point chords to the commanded path)",
        &r.max_chord_error_um.map_or_else(
            || "not available".into(),
            |v| {
                let at = r
                    .max_chord_error_line
                    .map_or(String::new(), |l| format!(" at line {l}"));
                format!("{v:.3} µm{at}")
            },
        ),
    );
    row(
        out,
        "roundness",
        "roundness (closed circle)",
        &r.roundness_um.map_or_else(
            || "no closed circular path".into(),
            |v| {
                let err = r
                    .roundness_radius_error_um
                    .map_or(String::new(), |e| format!(", radius error {e:+.2} µm"));
                format!("{v:.2} µm{err}")
            },
        ),
    );
    if r.max_scallop_mm.is_some() || r.measured_max_scallop_mm.is_some() {
        let at = r.measured_max_scallop_at_mm.map_or(String::new(), |p| {
            format!(" at X {:.3} Y {:.3} Z {:.3} mm", p[0], p[1], p[2])
        });
        let measured = r.measured_max_scallop_mm.map_or_else(
            || "not measured".into(),
            |m| format!("{:.2} µm{at}", m * 1e3),
        );
        let planned = r
            .max_scallop_mm
            .map_or_else(|| "not recorded".into(), |h| format!("{:.2} µm", h * 1e3));
        row(
            out,
            "max_scallop",
            "max scallop height (measured from the machine's positions; as planned)",
            &format!("{measured}; planned {planned}"),
        );
    }
    row(
        out,
        "chord_tolerance_mm",
        "chord tolerance (machine limit)",
        &format!("{} mm", num(run.machine.chord_tolerance_mm)),
    );
    let misses = match (r.misses, r.clock.as_deref()) {
        (Some(0), _) => "<span class=\"good\">0</span>".to_string(),
        (Some(m), _) => format!("<span class=\"bad\">{m}</span> (see Timing)"),
        (None, Some("sim")) => "not measured (simulated clock)".into(),
        (None, _) => "not recorded".into(),
    };
    row(out, "misses", "deadline misses", &misses);
    row(
        out,
        "blocks",
        "command blocks",
        &or_missing(r.blocks, |v| v.to_string()),
    );
    row(
        out,
        "lost_setpoints",
        "lost set-points",
        &or_missing(r.lost_setpoints, |v| {
            if v == 0 {
                "0".into()
            } else {
                format!("<span class=\"bad\">{v}</span>")
            }
        }),
    );
    out.push_str("</table></section>");
}

fn outcome(r: &Report) -> String {
    match (r.outcome.as_deref(), r.fault.as_deref()) {
        (Some("done"), _) => {
            "<span class=\"good\">completed</span>: the program ran to its end".into()
        }
        (Some("salvaged"), None) => "<span class=\"bad\">salvaged</span>: only the intact \
            blocks of a damaged command log ran, then a stop"
            .into(),
        (Some(_), Some(f)) => format!(
            "<span class=\"bad\">stopped with a fault</span>: {}",
            esc(f)
        ),
        (Some(o), None) => format!("<span class=\"bad\">{}</span>", esc(o)),
        (None, _) => "<span class=\"bad\">not recorded</span>".into(),
    }
}
