//! The path plot: the exact commanded curves of `commands.log`, in the program's plane.
//!
//! Each motion block is evaluated along its own NURBS ([`shared::path::eval`]), so the
//! plot shows the curve the interpolator followed, not a polyline through set-points. Feed
//! colours follow the *planned* speed along each block: its feed limit, the look-ahead's
//! start and end feeds and ramps at the machine's path acceleration, which is the profile
//! the interpolator steps along (the feed plot below shows the measured speed). Colours
//! come from a viridis-like scale whose lightness rises with feed, so the plot still reads
//! in grey; rapids are grey and dashed. One SVG `<title>` per block (or per group of
//! blocks when there are thousands) names the source line and its text.

use super::data::Run;
use super::svg::{esc, num, pad_range, Chart, Style};
use shared::protocol::{CommandBlock, FLAG_RAPID};
use std::fmt::Write;

/// Lightness rises monotonically from dark to light: readable in black and white.
pub const FEED_COLOURS: [&str; 10] = [
    "#440154", "#482878", "#3e4989", "#31688e", "#26828e", "#1f9e89", "#35b779", "#6ece58",
    "#9fd838", "#c9e020",
];
const AXIS: [&str; 3] = ["X", "Y", "Z"];
/// Most points the path may hold: about 1.5 MB of coordinates at most.
const POINT_BUDGET: f64 = 120_000.0;
/// Most `<title>` groups: more blocks are grouped, each group naming its line range.
const GROUP_BUDGET: usize = 3_000;

/// The plane to draw: the two axes with the largest extent (X, Y for a flat XY job), and
/// whether the path leaves that plane (then the plot is a projection).
pub fn plane(pts: &[[f64; 3]]) -> (usize, usize, bool) {
    let ext = extent(pts);
    let e = |i: usize| ext[i].1 - ext[i].0;
    let mut order = [0usize, 1, 2];
    // stable: X before Y before Z among equal extents, so flat XY jobs stay XY.
    order.sort_by(|a, b| {
        e(*b)
            .partial_cmp(&e(*a))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    let (mut a, mut b) = (order[0], order[1]);
    if a > b {
        std::mem::swap(&mut a, &mut b);
    }
    let third = order[2];
    (a, b, e(third) > 1e-6)
}

fn extent(pts: &[[f64; 3]]) -> [(f64, f64); 3] {
    let mut ext = [(f64::INFINITY, f64::NEG_INFINITY); 3];
    for p in pts {
        for i in 0..3 {
            ext[i] = (ext[i].0.min(p[i]), ext[i].1.max(p[i]));
        }
    }
    ext
}

/// Points on a block's curve at `n + 1` parameters evenly spaced over its domain.
pub fn sample(b: &CommandBlock, n: usize) -> Vec<[f64; 3]> {
    let (u0, u1) = shared::path::domain(b);
    (0..=n)
        .map(|i| shared::path::eval(b, u0 + (u1 - u0) * i as f64 / n as f64).p)
        .collect()
}

fn is_rapid(b: &CommandBlock) -> bool {
    b.flags & FLAG_RAPID != 0
}

/// The highest feed limit of the cutting (non-rapid) blocks, for the colour scale.
fn top_feed(run: &Run) -> f64 {
    let f = run
        .motion()
        .filter(|b| !is_rapid(b))
        .map(|b| b.feed_mm_per_min)
        .fold(0.0, f64::max);
    if f > 0.0 {
        f
    } else {
        run.machine.max_feed_mm_per_min
    }
}

/// Planned speed in mm/s at arc length `s` of a block of length `l`.
fn planned(b: &CommandBlock, s: f64, l: f64, acc: f64) -> f64 {
    let (vs, ve, vf) = (
        b.start_feed_mm_per_min / 60.0,
        b.end_feed_mm_per_min / 60.0,
        b.feed_mm_per_min / 60.0,
    );
    let up = (vs * vs + 2.0 * acc * s.max(0.0)).sqrt();
    let down = (ve * ve + 2.0 * acc * (l - s).max(0.0)).sqrt();
    vf.min(up).min(down)
}

/// The path section: plot, colour scale and caption.
pub fn section(run: &Run, out: &mut String) {
    out.push_str("<section id=\"path\"><h2>Path</h2>");
    let blocks: Vec<&CommandBlock> = run.motion().collect();
    let coarse: Vec<[f64; 3]> = blocks.iter().flat_map(|b| sample(b, 16)).collect();
    let from_setpoints = coarse.is_empty();
    let pts = if from_setpoints {
        match &run.setpoints {
            Some(s) => s.pos_mm.clone(),
            None => {
                out.push_str("<p class=\"missing\">No path: commands.log and setpoints.csv are both unusable.</p></section>");
                return;
            }
        }
    } else {
        coarse
    };
    let (a, b, projected) = plane(&pts);
    let ext = extent(&pts);
    let (mut xr, mut yr) = (
        pad_range(ext[a].0, ext[a].1, false),
        pad_range(ext[b].0, ext[b].1, false),
    );
    // Equal scale on both axes, plot area at most 760 × 700 px and at least 160 px high.
    let (ex, ey) = (xr.1 - xr.0, yr.1 - yr.0);
    let scale = (760.0 / ex).min(700.0 / ey);
    let (pw, ph) = (ex * scale, (ey * scale).max(160.0));
    let (pw, ph) = (pw.max(420.0), ph);
    let (cx, cy) = ((xr.0 + xr.1) / 2.0, (yr.0 + yr.1) / 2.0);
    let half = (pw / scale / 2.0, ph / scale / 2.0);
    xr = (cx - half.0, cx + half.0);
    yr = (cy - half.1, cy + half.1);
    let title = format!(
        "Path in the {}{} plane{}, colour = planned feed",
        AXIS[a],
        AXIS[b],
        if projected { " (projection)" } else { "" }
    );
    let mut c = Chart::new(
        "path-plot",
        &title,
        &format!("{} (mm)", AXIS[a]),
        &format!("{} (mm)", AXIS[b]),
        xr,
        yr,
    );
    c.w = pw + c.ml + c.mr;
    c.h = ph + c.mt + c.mb;
    out.push_str("<div class=\"row\">");
    c.open(out);
    let top = top_feed(run);
    if from_setpoints {
        draw_setpoints(&c, &pts, (a, b), out);
    } else {
        draw_blocks(run, &c, &blocks, (a, b), scale, top, out);
    }
    let programmed = Style {
        color: "#000000",
        width: 1.0,
        dash: "2 3",
    };
    let compensated = !from_setpoints && !run.programmed.is_empty();
    if compensated {
        draw_programmed(run, &c, (a, b), scale, out);
    }
    let mut marks = String::new();
    markers(run, &c, (a, b), &pts, &mut marks);
    let rapid = Style {
        color: "#8a8a8a",
        width: 1.0,
        dash: "5 4",
    };
    let feed = Style {
        color: FEED_COLOURS[6],
        width: 2.0,
        dash: "",
    };
    let mut legend = vec![("feed move (colour = feed)", feed), ("rapid (G0)", rapid)];
    if compensated {
        legend.push(("as programmed (before cutter compensation)", programmed));
    }
    c.close_with(out, &legend, &marks);
    colour_bar(top, out);
    out.push_str("</div><p class=\"note\">");
    if from_setpoints {
        out.push_str("commands.log is unusable, so the path is drawn through the set-points, without feed colours or source-line tooltips. ");
    } else {
        let _ = write!(
            out,
            "{} motion blocks, each evaluated on its exact curve. Hover a block for its source line. ",
            blocks.len()
        );
    }
    if compensated {
        out.push_str("The program uses cutter radius compensation (G41/G42): the coloured path is the tool's centre, offset from the path as programmed, which the dotted black line shows. ");
    }
    if projected {
        let _ = write!(
            out,
            "The path also moves in {}: this is its projection onto the {}{} plane, the plane with the largest extent. ",
            AXIS[3 - a - b],
            AXIS[a],
            AXIS[b]
        );
    }
    let _ = write!(
        out,
        "Feed colours are the planned speed along each block (feed limit, look-ahead start and end feeds, ramps at {} mm/s²).</p></section>",
        num(run.machine.path_acc_mm_per_s2)
    );
}

fn draw_blocks(
    run: &Run,
    c: &Chart,
    blocks: &[&CommandBlock],
    (a, b): (usize, usize),
    scale: f64,
    top: f64,
    out: &mut String,
) {
    let total_px: f64 = blocks.iter().map(|b| b.length_mm * scale).sum();
    let step_px = (total_px / POINT_BUDGET).max(3.0);
    let group = blocks.len().div_ceil(GROUP_BUDGET).max(1);
    let acc = run.machine.path_acc_mm_per_s2;
    for chunk in blocks.chunks(group) {
        let (first, last) = (chunk[0], chunk[chunk.len() - 1]);
        out.push_str("<g class=\"blk\"><title>");
        if chunk.len() == 1 {
            let _ = write!(
                out,
                "line {}: {} | {}, feed limit {} mm/min, {:.3} mm",
                first.source_line,
                esc(run.source(first.source_line)),
                if is_rapid(first) { "rapid" } else { "feed" },
                num(first.feed_mm_per_min.round()),
                first.length_mm
            );
        } else {
            let _ = write!(
                out,
                "lines {}–{} ({} blocks): {} … {}",
                first.source_line,
                last.source_line,
                chunk.len(),
                esc(run.source(first.source_line)),
                esc(run.source(last.source_line))
            );
        }
        out.push_str("</title>");
        for blk in chunk {
            draw_block(c, blk, (a, b), scale, step_px, top, acc, out);
        }
        out.push_str("</g>");
    }
}

#[allow(clippy::too_many_arguments)]
fn draw_block(
    c: &Chart,
    blk: &CommandBlock,
    (a, b): (usize, usize),
    scale: f64,
    step_px: f64,
    top: f64,
    acc: f64,
    out: &mut String,
) {
    let len_px = blk.length_mm * scale;
    let n = ((len_px / step_px).ceil() as usize).clamp(1, 600);
    let n = if blk.degree > 1 || len_px > 12.0 {
        n.max(4)
    } else {
        n
    };
    let pts = sample(blk, n);
    if is_rapid(blk) {
        let xy: Vec<(f64, f64)> = pts.iter().map(|p| (p[a], p[b])).collect();
        out.push_str("<polyline class=\"rapid\" points=\"");
        push_points(c, &xy, out);
        out.push_str("\"/>");
        return;
    }
    // Arc length at each sample, scaled to the block's exact length.
    let mut s = vec![0.0; pts.len()];
    for i in 1..pts.len() {
        let d = [0, 1, 2].map(|k| pts[i][k] - pts[i - 1][k]);
        s[i] = s[i - 1] + shared::path::norm(d);
    }
    let chord = s.last().copied().unwrap_or(0.0);
    let k = if chord > 0.0 {
        blk.length_mm / chord
    } else {
        0.0
    };
    let bin = |i: usize| {
        let v = planned(blk, s[i] * k, blk.length_mm, acc) * 60.0;
        ((v / top * 10.0).floor().max(0.0) as usize).min(9)
    };
    let mut run_start = 0;
    let mut cur = bin(0).max(bin(1.min(pts.len() - 1)));
    for i in 1..pts.len() {
        // The colour of a segment is that of its faster end.
        let seg = bin(i - 1).max(bin(i));
        if seg != cur {
            emit(c, &pts[run_start..i], (a, b), cur, out);
            run_start = i - 1;
            cur = seg;
        }
    }
    emit(c, &pts[run_start..], (a, b), cur, out);
}

fn emit(c: &Chart, pts: &[[f64; 3]], (a, b): (usize, usize), bin: usize, out: &mut String) {
    let xy: Vec<(f64, f64)> = pts.iter().map(|p| (p[a], p[b])).collect();
    let _ = write!(
        out,
        "<polyline stroke=\"{}\" class=\"feed\" points=\"",
        FEED_COLOURS[bin]
    );
    push_points(c, &xy, out);
    out.push_str("\"/>");
}

/// Writes pixel coordinates, dropping points within half a pixel of the last one kept
/// (the last point is always kept so blocks join).
fn push_points(c: &Chart, xy: &[(f64, f64)], out: &mut String) {
    let mut last = (f64::NAN, f64::NAN);
    for (i, &(x, y)) in xy.iter().enumerate() {
        let p = (c.px(x), c.py(y));
        let near = (p.0 - last.0).abs() < 0.5 && (p.1 - last.1).abs() < 0.5;
        if near && i + 1 != xy.len() {
            continue;
        }
        let _ = write!(out, "{:.1},{:.1} ", p.0, p.1);
        last = p;
    }
    if out.ends_with(' ') {
        out.pop();
    }
}

/// The programmed path of a compensated program ([`Run::programmed`]): its feed moves,
/// thin, black and dotted, over the tool's.
fn draw_programmed(run: &Run, c: &Chart, (a, b): (usize, usize), scale: f64, out: &mut String) {
    let total_px: f64 = run.programmed.iter().map(|b| b.length_mm * scale).sum();
    let step_px = (total_px / POINT_BUDGET).max(3.0);
    out.push_str(
        "<g class=\"programmed\"><title>as programmed, before cutter radius compensation</title>",
    );
    for blk in run
        .programmed
        .iter()
        .filter(|b| b.kind() == Some(shared::protocol::BlockKind::Motion) && !is_rapid(b))
    {
        let least = if blk.degree > 1 { 32 } else { 1 };
        let n = ((blk.length_mm * scale / step_px).ceil() as usize).clamp(least, 600);
        let xy: Vec<(f64, f64)> = sample(blk, n).iter().map(|p| (p[a], p[b])).collect();
        out.push_str("<polyline fill=\"none\" stroke=\"#000\" stroke-width=\"1\" stroke-dasharray=\"2 3\" points=\"");
        push_points(c, &xy, out);
        out.push_str("\"/>");
    }
    out.push_str("</g>");
}

fn draw_setpoints(c: &Chart, pts: &[[f64; 3]], (a, b): (usize, usize), out: &mut String) {
    let xy: Vec<(f64, f64)> = pts.iter().map(|p| (p[a], p[b])).collect();
    out.push_str("<polyline class=\"feed\" stroke=\"#1f3b73\" points=\"");
    push_points(c, &xy, out);
    out.push_str("\"/>");
}

/// Start (open circle), end (filled square), or where a faulted run stopped (a cross).
fn markers(run: &Run, c: &Chart, (a, b): (usize, usize), pts: &[[f64; 3]], out: &mut String) {
    let sp = run
        .setpoints
        .as_ref()
        .map(|s| s.pos_mm.as_slice())
        .unwrap_or(&[]);
    let (Some(start), Some(end)) = (sp.first().or(pts.first()), sp.last().or(pts.last())) else {
        return;
    };
    let fault = run
        .report
        .as_ref()
        .and_then(|r| r.outcome.as_deref())
        .is_some_and(|o| o != "done");
    let (sx, sy) = (c.px(start[a]), c.py(start[b]));
    let (ex, ey) = (c.px(end[a]), c.py(end[b]));
    let _ = write!(
        out,
        r##"<g class="mark"><title>start</title><circle cx="{sx:.1}" cy="{sy:.1}" r="6" fill="none" stroke="#000" stroke-width="2"/><text x="{:.1}" y="{:.1}">start</text></g>"##,
        sx + 9.0,
        sy - 8.0
    );
    if fault {
        let _ = write!(
            out,
            r##"<g class="mark"><title>stopped here (fault)</title><path d="M{:.1} {:.1}l12 12m0 -12l-12 12" stroke="#b00020" stroke-width="3"/><text x="{:.1}" y="{:.1}">stopped (fault)</text></g>"##,
            ex - 6.0,
            ey - 6.0,
            ex + 9.0,
            ey + 16.0
        );
    } else {
        let _ = write!(
            out,
            r##"<g class="mark"><title>end</title><rect x="{:.1}" y="{:.1}" width="9" height="9" fill="#000"/><text x="{:.1}" y="{:.1}">end</text></g>"##,
            ex - 4.5,
            ey - 4.5,
            ex + 9.0,
            ey + 16.0
        );
    }
}

/// A vertical colour scale labelled in mm/min.
fn colour_bar(top: f64, out: &mut String) {
    let (h, y0) = (300.0, 46.0);
    let _ = write!(
        out,
        r#"<svg class="chart" viewBox="0 0 130 380" width="130" height="380" role="img" aria-label="feed colour scale"><text x="4" y="30" class="lg">feed (mm/min)</text>"#
    );
    for (i, col) in FEED_COLOURS.iter().enumerate() {
        let y = y0 + h - (i as f64 + 1.0) * h / 10.0;
        let _ = write!(
            out,
            r#"<rect x="10" y="{y:.1}" width="24" height="{:.1}" fill="{col}"/>"#,
            h / 10.0 + 0.5
        );
    }
    for i in 0..=5 {
        let v = top * i as f64 / 5.0;
        let y = y0 + h - h * i as f64 / 5.0;
        let _ = write!(
            out,
            r##"<line x1="34" y1="{y:.1}" x2="40" y2="{y:.1}" stroke="#000"/><text x="44" y="{:.1}" class="lg">{}</text>"##,
            y + 4.0,
            num(v.round())
        );
    }
    out.push_str("</svg>");
}
