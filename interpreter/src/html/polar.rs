//! The roundness plot: for a closed, circular cutting path, the radial deviation of the
//! measured positions about their best-fit circle, magnified like a ballbar or roundness
//! plot.
//!
//! What is closed and circular, the fit and the figures are [`crate::contour`]'s, so the
//! page shows the `roundness` of `report.json`: the least-squares circle is fitted to the
//! *measured* positions (`feedback.csv`) of the cycles on the circle, and roundness is
//! max − min of their radii about its centre. The commanded set-points are drawn dashed
//! about the same circle, so a circle that came out small (no feed-forward: `v²/(2·R·Kv²)`)
//! shows as the commanded line lying outside by that much.

use super::measure::Measure;
use super::svg::{esc, fixed, nice_ceil, num, style_attrs, AXES};
use crate::contour::Deviations;
use std::fmt::Write;

/// The `len` points `each` gives (angle, deviation), as drawn.
type Points<'a> = (usize, &'a dyn Fn(&mut dyn FnMut((f64, f64))));

/// Keeps at most the smallest and largest deviation per quarter degree, in order, of the
/// `len` points `each` gives (read twice: the deviations, then the angles of those kept).
fn reduce((len, each): Points) -> Vec<(f64, f64)> {
    if len <= 3000 {
        let mut v = Vec::with_capacity(len);
        each(&mut |p| v.push(p));
        return v;
    }
    let mut r = super::svg::Reducer::new(0.0, 1.0, 1440.0);
    // Unwrapped angle keeps the order of travel for the reducer's columns.
    let mut i = 0usize;
    each(&mut |p| {
        r.push(i as f64 / len as f64, p.1);
        i += 1;
    });
    let flat: Vec<(f64, f64)> = r.finish().into_iter().flatten().collect();
    // The point each kept one stands for (in order, as the reducer keeps them).
    let at: Vec<usize> = flat
        .iter()
        .map(|&(x, _)| ((x * len as f64).round() as usize).min(len - 1))
        .collect();
    let mut angle = vec![0.0; at.len()];
    let (mut i, mut k) = (0usize, 0usize);
    each(&mut |p| {
        while at.get(k) == Some(&i) {
            angle[k] = p.0;
            k += 1;
        }
        i += 1;
    });
    angle
        .into_iter()
        .zip(flat)
        .map(|(t, (_, d))| (t, d))
        .collect()
}

/// The roundness section, or a one-line note why the path gets none.
pub fn section(contour: Option<&Measure>, out: &mut String) {
    let why_none = "feedback.csv, setpoints.csv or commands.log is unusable".to_string();
    let r = match contour.map_or(Err(&why_none), |c| c.roundness.as_ref()) {
        Ok(r) => r,
        Err(why) => {
            let _ = write!(
                out,
                "<section id=\"roundness\"><h2>Roundness</h2><p class=\"note\">No roundness plot: {}. It is drawn for a closed circular path.</p></section>",
                esc(why)
            );
            return;
        }
    };
    let name = ["X", "Y", "Z"];
    let (a, b) = r.figures.axes;
    // The points drawn: the measured and commanded positions of the first run, the
    // measured of the reverse run, each read from its temporary file as it is drawn.
    let measured = |f: &mut dyn FnMut((f64, f64))| r.points.each_steady(false, f);
    let commanded = |f: &mut dyn FnMut((f64, f64))| r.points.each_steady(true, f);
    let reverse = |f: &mut dyn FnMut((f64, f64))| {
        if let Some(v) = &r.reverse {
            v.points.each_steady(false, f);
        }
    };
    let len = |d: &Deviations| d.steady_len();
    let mut maxabs = 0.0f64;
    for each in [
        &measured as &dyn Fn(&mut dyn FnMut((f64, f64))),
        &commanded,
        &reverse,
    ] {
        each(&mut |p| maxabs = maxabs.max(p.1.abs()));
    }
    let maxabs = maxabs.max(1e-3);
    let per_div = nice_ceil(maxabs / 3.0);
    let (cx, cy, base, div) = (310.0, 326.0, 150.0, 36.0);
    let _ = write!(
        out,
        r#"<section id="roundness"><h2>Roundness</h2><div class="row"><svg class="chart" id="polar-plot" viewBox="0 0 620 640" width="620" height="640" role="img" aria-labelledby="polar-t"><title id="polar-t">Radial deviation about the best-fit centre, magnified ({} µm per division)</title><text x="8" y="16" class="ttl">Radial deviation about the best-fit centre ({}{} plane)</text>"#,
        num(per_div),
        name[a],
        name[b]
    );
    for k in -3i32..=3 {
        let rr = base + k as f64 * div;
        let cls = if k == 0 { "ring0" } else { "grid" };
        let _ = write!(
            out,
            r#"<circle cx="{cx}" cy="{cy}" r="{rr}" class="{cls}" fill="none"/><text x="{:.1}" y="{:.1}" class="ty">{}{} µm</text>"#,
            cx + rr * std::f64::consts::FRAC_1_SQRT_2 + 3.0,
            cy - rr * std::f64::consts::FRAC_1_SQRT_2 - 3.0,
            if k > 0 { "+" } else { "" },
            num(per_div * k as f64)
        );
    }
    for deg in (0..360).step_by(30) {
        let t = (deg as f64).to_radians();
        let (r0, r1) = (base - 3.0 * div, base + 3.0 * div + 6.0);
        // Labels on the left and right run away from the circle, so they stay inside.
        let anchor = match t.cos() {
            c if c > 0.3 => "start",
            c if c < -0.3 => "end",
            _ => "middle",
        };
        let _ = write!(
            out,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" class="grid"/><text x="{:.1}" y="{:.1}" class="tx" style="text-anchor:{anchor}">{deg}°</text>"#,
            cx + r0 * t.cos(),
            cy - r0 * t.sin(),
            cx + r1 * t.cos(),
            cy - r1 * t.sin(),
            cx + (r1 + 4.0) * t.cos(),
            cy - (r1 + 10.0) * t.sin() + 4.0
        );
    }
    let plot = |v: Points, st: &super::svg::Style, out: &mut String| {
        if v.0 == 0 {
            return;
        }
        out.push_str("<polyline points=\"");
        for (t, d) in reduce(v) {
            let rr = (base + d / per_div * div).max(0.0);
            let _ = write!(out, "{:.1},{:.1} ", cx + rr * t.cos(), cy - rr * t.sin());
        }
        out.pop();
        out.push('"');
        style_attrs(out, st);
        out.push_str("/>");
    };
    let commanded_style = AXES[1];
    let reverse_style = super::svg::Style {
        color: "#c0392b",
        width: 1.3,
        dash: "",
    };
    plot((len(&r.points), &commanded), &commanded_style, out);
    if let Some(rev) = &r.reverse {
        plot((len(&rev.points), &reverse), &reverse_style, out);
    }
    plot((len(&r.points), &measured), &AXES[0], out);
    let way = |ccw: bool| {
        if ccw {
            "counter-clockwise"
        } else {
            "clockwise"
        }
    };
    let first = if r.reverse.is_some() {
        format!("measured, {}", way(r.figures.ccw))
    } else {
        "measured (feedback.csv)".into()
    };
    let mut legend = vec![(first, AXES[0])];
    if r.reverse.is_some() {
        legend.push((format!("measured, {}", way(!r.figures.ccw)), reverse_style));
    }
    legend.push(("commanded (setpoints.csv)".into(), commanded_style));
    let mut x = 10.0;
    for (name, st) in &legend {
        let _ = write!(out, r#"<line x1="{x}" y1="33" x2="{}" y2="33""#, x + 28.0);
        style_attrs(out, st);
        let _ = write!(
            out,
            r#"/><text x="{}" y="37" class="lg">{}</text>"#,
            x + 33.0,
            esc(name)
        );
        x += 45.0 + 6.2 * name.chars().count() as f64;
    }
    let _ = write!(
        out,
        r#"<text x="{cx}" y="{:.1}" class="xl">deviation (µm), {} µm per division; angle about the centre (°)</text></svg>"#,
        632.0,
        num(per_div)
    );
    let (lo, hi) = r.deviation_um;
    let _ = write!(
        out,
        r#"<table class="figs"><tr><th>roundness (max − min radius of the measured positions about their best-fit centre)</th><td id="circularity">{:.2} µm</td></tr><tr><th>roundness at steady speed (the ramps from and to rest left out, as drawn)</th><td id="steady-roundness">{:.2} µm</td></tr><tr><th>largest deviation outward / inward</th><td>{:+.2} µm / {:+.2} µm</td></tr><tr><th>best-fit centre (measured)</th><td>{} {} mm, {} {} mm</td></tr><tr><th>best-fit radius (measured)</th><td>{:.4} mm</td></tr><tr><th>commanded circle</th><td>centre {} {} mm, {} {} mm, radius {:.4} mm</td></tr><tr><th>radius error (measured − commanded)</th><td id="radius-error">{:+.2} µm</td></tr><tr><th>commanded set-points' roundness about the commanded centre (chord error)</th><td>{:.3} µm</td></tr><tr><th>lines</th><td>{}–{}</td></tr><tr><th>magnification</th><td>{} µm per division (rings); best-fit circle bold</td></tr></table>"#,
        r.figures.roundness_um,
        r.steady_roundness_um,
        hi,
        lo,
        name[a],
        fixed(r.figures.centre_mm[0], 4),
        name[b],
        fixed(r.figures.centre_mm[1], 4),
        r.figures.radius_mm,
        name[a],
        fixed(r.figures.commanded_centre_mm[0], 4),
        name[b],
        fixed(r.figures.commanded_centre_mm[1], 4),
        r.figures.commanded_radius_mm,
        r.figures.radius_error_um(),
        r.commanded_roundness_um,
        r.figures.lines.0,
        r.figures.lines.1,
        num(per_div)
    );
    if let Some(rev) = &r.reverse {
        let _ = write!(
            out,
            r#"<table class="figs" id="reverse-run"><tr><th>the same circle {}, lines {}–{}: roundness about its own best-fit centre</th><td>{:.2} µm</td></tr><tr><th>its best-fit radius less the {} run's</th><td>{:+.2} µm</td></tr></table>"#,
            way(!r.figures.ccw),
            rev.lines.0,
            rev.lines.1,
            rev.roundness_um,
            way(r.figures.ccw),
            rev.radius_offset_um
        );
    }
    out.push_str("</div>");
    let _ = write!(
        out,
        "<p class=\"note\">The circle is fitted (least squares) to the measured positions of the cycles on it; each measured position's radius minus the fitted radius is drawn magnified around the bold best-fit circle, as on a ballbar or roundness plot, and the commanded set-points dashed about the same circle (outside it by the radius error when the circle came out small). The plot leaves out the ramps from rest at the start of the circle and to rest at its end (the cycles below 98 % of its steady speed: {} and {} here), as a ballbar test leaves out its feed-in and feed-out arcs; the figures above are report.json's <code>roundness</code>, over every cycle on the circle, ramps included, beside the roundness at steady speed. {}</p></section>",
        r.ramps_left_out.0,
        r.ramps_left_out.1,
        if r.reverse.is_some() {
            "The program runs the same circle both ways: the other direction's measured positions are drawn about the same centre and radius, so a difference between the two traces (a reversal, backlash or a servo mismatch) shows as on a ballbar report. "
        } else {
            ""
        }
    );
}
