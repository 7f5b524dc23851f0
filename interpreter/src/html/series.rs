//! Plots over time: path speed against the feed limits, path acceleration and jerk against
//! the machine's limits, following and contour error.
//!
//! Speed, acceleration and jerk are finite differences of consecutive set-points (first,
//! second and third, divided by the period's powers): the motion the drives were asked
//! for, including the centripetal part on curves. A gap in cycle numbers (a lost row)
//! breaks the line instead of inventing a difference across it. Every series goes through
//! [`Reducer`], so a one-hour run draws as quickly and as small as a one-second one.

use super::data::Run;
use super::measure::Measure;
use super::svg::{num, pad_range, y_extent, Chart, Reducer, Style, AXES, LIMIT, SOLID};
use shared::path::norm;
use std::collections::HashMap;
use std::fmt::Write;

/// The time axis shared by every plot over time: `(0, last cycle × period)` in s.
pub fn time_range(run: &Run) -> (f64, f64) {
    let last_sp = run.setpoints.as_ref().map(|s| s.last_cycle);
    let last_fb = run.feedback.as_ref().map(|f| f.last_cycle);
    let last = last_sp.max(last_fb).unwrap_or(0).max(1);
    (0.0, last as f64 * run.period_s())
}

fn chart(id: &str, title: &str, y_label: &str, t: (f64, f64), y: (f64, f64)) -> Chart {
    Chart::new(id, title, "time (s)", y_label, t, y)
}

fn draw(c: &Chart, segs: &[Vec<(f64, f64)>], st: &Style, out: &mut String) {
    for s in segs {
        c.line(out, s, st);
    }
}

/// The feed, acceleration and jerk plots.
pub fn motion(run: &Run, out: &mut String) {
    out.push_str("<section id=\"feed\"><h2>Feed, acceleration and jerk</h2>");
    let Some(sp) = &run.setpoints else {
        out.push_str("<p class=\"missing\">Not drawn: setpoints.csv is missing or unusable (see the problems above).</p></section>");
        return;
    };
    let tr = time_range(run);
    let cols = chart("x", "", "", tr, (0.0, 1.0)).plot_w();
    let period = run.period_s();
    // The feed limit of each source line: its feed moves' highest, or where it has only
    // rapids, theirs. (A STEP-NC part's surface paths share their line with the rapids
    // between them: the rapid rate would be drawn over every pass.) Lines with rapids
    // only are told apart, for the scale below.
    let mut limit_of_line: HashMap<u32, (f64, bool)> = HashMap::new();
    for b in run.motion() {
        let rapid = b.flags & shared::protocol::FLAG_RAPID != 0;
        let e = limit_of_line.entry(b.source_line).or_insert((0.0, true));
        match (rapid, e.1) {
            (false, true) => *e = (b.feed_mm_per_min, false),
            (false, false) | (true, true) => e.0 = e.0.max(b.feed_mm_per_min),
            (true, false) => {}
        }
    }
    // The highest speed and limit of the feed moves alone.
    let mut feed_hi = 0.0f64;
    let [mut speed, mut limit, mut acc, mut jerk] = [0; 4].map(|_| Reducer::new(tr.0, tr.1, cols));
    // Positions of the last four consecutive cycles, newest first.
    let mut hist: Vec<[f64; 3]> = Vec::with_capacity(4);
    let mut prev_cycle: Option<u64> = None;
    for (cyc, p, line) in sp.rows() {
        let t = cyc as f64 * period;
        if prev_cycle.is_some_and(|c| c + 1 != cyc) {
            hist.clear();
            for r in [&mut speed, &mut acc, &mut jerk, &mut limit] {
                r.gap();
            }
        }
        prev_cycle = Some(cyc);
        hist.insert(0, p);
        hist.truncate(4);
        // The feed limit of a line with feed moves, if it has any.
        let line_limit = limit_of_line.get(&line).copied();
        let feeding = line_limit.and_then(|(f, rapid_only)| (!rapid_only).then_some(f));
        if let Some((f, _)) = line_limit {
            limit.push(t, f);
        }
        let d = |k: usize| [0, 1, 2].map(|j| hist[k][j] - hist[k + 1][j]);
        if hist.len() >= 2 {
            let v = norm(d(0)) / period * 60.0;
            speed.push(t, v);
            // (A cycle of a line with feed moves may be one of its rapids: for the scale
            // it counts up to a quarter above the feed limit, which covers the tool
            // centre running faster than the contact point on a surface.)
            if let Some(f) = feeding {
                feed_hi = feed_hi.max(f).max(v.min(1.25 * f));
            }
        }
        if hist.len() >= 3 {
            let (a, b) = (d(0), d(1));
            acc.push(t, norm([0, 1, 2].map(|j| a[j] - b[j])) / (period * period));
        }
        if hist.len() >= 4 {
            let (a, b, c) = (d(0), d(1), d(2));
            let j3 = [0, 1, 2].map(|j| a[j] - 2.0 * b[j] + c[j]);
            jerk.push(t, norm(j3) / (period * period * period));
        }
    }
    let (speed, limit, acc, jerk) = (speed.finish(), limit.finish(), acc.finish(), jerk.finish());

    let peak = run.report.as_ref().and_then(|r| r.peak_feed_mm_per_min);
    let (lo, hi) = y_extent(&speed);
    let (_, lhi) = y_extent(&limit);
    let all_hi = hi.max(if lhi.is_finite() { lhi } else { hi });
    // Where the rapids are more than twice as fast as anything the feed moves do, the
    // feed moves set the scale and the rapids run off the top (clipped): at F300 with
    // 10 000 mm/min rapids the feed would otherwise be a flat line at the bottom.
    let rapids_clipped = feed_hi > 0.0 && all_hi > 2.0 * feed_hi;
    let y = pad_range(
        lo.min(0.0),
        if rapids_clipped { feed_hi } else { all_hi },
        true,
    );
    let c = chart(
        "feed-plot",
        "Path speed over time: measured from the set-points, against the block's feed limit",
        "feed (mm/min)",
        tr,
        y,
    );
    c.open(out);
    let limit_style = Style {
        dash: "7 4",
        ..LIMIT
    };
    draw(&c, &limit, &limit_style, out);
    draw(&c, &speed, &SOLID, out);
    c.close(
        out,
        &[
            ("path speed |Δp|/T", SOLID),
            (
                "feed limit of the block (programmed F or rapid, lowered by curvature)",
                limit_style,
            ),
        ],
    );
    let _ = write!(
        out,
        "<p class=\"note\">The feed limit is the block's planned maximum (the programmed feed, or the rapid rate for G0, reduced where the curvature demands it), drawn for the source line of each cycle (a line with both feed moves and rapids: its feed moves').{}{}</p>",
        if rapids_clipped {
            format!(
                " The scale is the feed moves': rapids, up to {} mm/min, run off the top.",
                num(all_hi.round())
            )
        } else {
            String::new()
        },
        peak.map_or(String::new(), |p| format!(
            " Peak feed reported by the interpolator: {} mm/min{}.",
            num(p.round()),
            if run.motion().any(|b| b.is_surface()) {
                ", the speed of the tool's reference point (the programmed feed is the contact point's: over a convex surface the centre runs faster)"
            } else {
                ""
            }
        ))
    );

    let amax = run.machine.path_acc_mm_per_s2;
    let (_, ahi) = y_extent(&acc);
    let c = chart(
        "acc-plot",
        "Path acceleration over time (second difference of the set-points), with the machine limit",
        "acceleration (mm/s²)",
        tr,
        pad_range(0.0, ahi.max(amax * 1.05), true),
    );
    c.open(out);
    draw(&c, &acc, &SOLID, out);
    c.hline(
        out,
        amax,
        &LIMIT,
        &format!("path_acc_mm_per_s2 = {}", num(amax)),
    );
    c.close(
        out,
        &[
            ("|a| of the set-points (tangential and centripetal)", SOLID),
            ("machine limit path_acc_mm_per_s2", LIMIT),
        ],
    );

    let jmax = run.machine.path_jerk_mm_per_s3;
    let (_, jhi) = y_extent(&jerk);
    let c = chart(
        "jerk-plot",
        "Path jerk over time (third difference of the set-points), with the machine limit",
        "jerk (mm/s³)",
        tr,
        pad_range(0.0, jhi.max(jmax * 1.05), true),
    );
    c.open(out);
    draw(&c, &jerk, &SOLID, out);
    c.hline(
        out,
        jmax,
        &LIMIT,
        &format!("path_jerk_mm_per_s3 = {}", num(jmax)),
    );
    c.close(
        out,
        &[
            ("|j| of the set-points", SOLID),
            ("machine limit path_jerk_mm_per_s3", LIMIT),
        ],
    );
    out.push_str("<p class=\"note\">The profile is jerk-limited (an S-curve along the path). Jerk can still peak above the limit where the path itself has a kink (a corner taken at speed, whose direction no finite jerk can follow exactly). Each pixel column shows the minimum and maximum of the cycles in it, so no single-cycle spike is hidden.</p></section>");
}

/// Following error per axis and the contour error (distance from the measured position to
/// the exact commanded path, from [`crate::contour`]). Returns the largest contour error in
/// µm, when it could be computed.
pub fn errors(run: &Run, contour: Option<&Measure>, out: &mut String) -> Option<f64> {
    out.push_str("<section id=\"errors\"><h2>Following and contour error</h2>");
    let Some(fb) = &run.feedback else {
        out.push_str("<p class=\"missing\">Not drawn: feedback.csv is missing or unusable (see the problems above).</p></section>");
        return None;
    };
    let tr = time_range(run);
    let cols = chart("x", "", "", tr, (0.0, 1.0)).plot_w();
    let period = run.period_s();
    let mut axes = [0; 3].map(|_| Reducer::new(tr.0, tr.1, cols));
    let mut creduce = Reducer::new(tr.0, tr.1, cols);
    let mut prev: Option<u64> = None;
    let mut contour_prev = false;
    // Without a contour measure, no row has a contour error.
    let mut errors = contour.map(|c| c.errors());
    for (cyc, _, e) in fb.rows() {
        let t = cyc as f64 * period;
        if prev.is_some_and(|c| c + 1 != cyc) {
            for r in axes.iter_mut() {
                r.gap();
            }
        }
        prev = Some(cyc);
        for (r, v) in axes.iter_mut().zip(e) {
            r.push(t, v);
        }
        // Cycles on rapids have no contour error: a gap in its line.
        match errors.as_mut().and_then(|e| e.next().flatten()) {
            Some(n) => {
                creduce.push(t, n);
                contour_prev = true;
            }
            None if contour_prev => {
                creduce.gap();
                contour_prev = false;
            }
            None => {}
        }
    }
    let axes = axes.map(Reducer::finish);
    let cline = creduce.finish();
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for s in axes.iter().chain([&cline]) {
        let (a, b) = y_extent(s);
        lo = lo.min(a);
        hi = hi.max(b);
    }
    let c = chart(
        "ferr-plot",
        "Following error per axis (commanded − measured) and contour error, over time",
        "error (µm)",
        tr,
        pad_range(lo, hi, false),
    );
    c.open(out);
    for (k, s) in axes.iter().enumerate() {
        draw(&c, s, &AXES[k], out);
    }
    draw(&c, &cline, &AXES[3], out);
    c.close(
        out,
        &[
            ("X", AXES[0]),
            ("Y", AXES[1]),
            ("Z", AXES[2]),
            ("contour error (distance to the path)", AXES[3]),
        ],
    );
    let max = contour.and_then(|c| c.max);
    let worst = match max {
        Some(w) => format!(
            "Largest contour error: <b id=\"max-contour\">{:.2} µm</b> at cycle {} (line {}{}).",
            w.um,
            w.cycle,
            w.line,
            match run.source(w.line) {
                "" => String::new(),
                src => format!(": <code>{}</code>", super::svg::esc(src)),
            }
        ),
        None => "No contour error: it needs commands.log, setpoints.csv and a feed move.".into(),
    };
    let _ = write!(
        out,
        "<p class=\"note\">Contour error is the distance from each measured position to the exact commanded path (the closest point on the curves of commands.log near that cycle's set-point), not to the set-point: lagging along the path is following error, leaving the path is contour error, the error that shows on the part. Cycles on rapids (G0) are left out. {worst}</p></section>"
    );
    max.map(|w| w.um)
}
