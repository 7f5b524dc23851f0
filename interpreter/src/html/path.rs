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
pub const AXIS: [&str; 3] = ["X", "Y", "Z"];
/// Most points the path may hold: about 1.5 MB of coordinates at most.
const POINT_BUDGET: f64 = 120_000.0;
/// Most `<title>` groups: more blocks are grouped, each group naming its line range.
const GROUP_BUDGET: usize = 3_000;

/// How a point of the path is drawn: its two chart coordinates.
pub type Proj<'a> = &'a dyn Fn([f64; 3]) -> (f64, f64);

/// The plane to draw: the two axes with the largest extent of `pts` (X, Y for a flat XY
/// job), and whether `pts` leave that plane (then the plot is a projection).
pub fn plane(pts: &[[f64; 3]]) -> (usize, usize, bool) {
    plane_of(extent(pts))
}

/// [`plane`] of points whose extent is `ext`.
fn plane_of(ext: [(f64, f64); 3]) -> (usize, usize, bool) {
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

pub fn extent(pts: &[[f64; 3]]) -> [(f64, f64); 3] {
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
    sample_range(b, u0, u1, n)
}

/// Points on a block's curve at `n + 1` parameters evenly spaced over `[ua, ub]`.
fn sample_range(b: &CommandBlock, ua: f64, ub: f64, n: usize) -> Vec<[f64; 3]> {
    (0..=n)
        .map(|i| shared::path::eval(b, ua + (ub - ua) * i as f64 / n as f64).p)
        .collect()
}

pub fn is_rapid(b: &CommandBlock) -> bool {
    b.flags & FLAG_RAPID != 0
}

/// The highest feed limit of the cutting (non-rapid) blocks, for the colour scale.
pub fn top_feed(run: &Run) -> f64 {
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

/// Whether the run stopped before the end of its program (a fault, or a salvaged log).
pub fn stopped_early(run: &Run) -> bool {
    run.report
        .as_ref()
        .and_then(|r| r.outcome.as_deref())
        .is_some_and(|o| o != "done")
}

/// Where a run that stopped early stopped on its motion blocks `blocks`: the index of
/// the block and the parameter on it. What follows never ran. `None` for a run that ran
/// to its end, or when the traces cannot tell.
pub fn stop_point(
    run: &Run,
    contour: Option<&super::measure::Measure>,
    blocks: &[&CommandBlock],
) -> Option<(usize, f64)> {
    if !stopped_early(run) {
        return None;
    }
    let r = contour?.reached?;
    let i = blocks.iter().position(|b| b.seq == r.seq)?;
    Some((i, r.u))
}

/// The path's styles.
pub const RAPID: Style = Style {
    color: "#8a8a8a",
    width: 1.0,
    dash: "5 4",
};
pub const NOT_RUN: Style = Style {
    color: "#c4c4c4",
    width: 2.0,
    dash: "",
};
const PROGRAMMED: Style = Style {
    color: "#000000",
    width: 1.0,
    dash: "2 3",
};
pub const FEED: Style = Style {
    color: FEED_COLOURS[6],
    width: 2.0,
    dash: "",
};

/// Contour-error colours, from blue (small) to dark red (large).
pub const ERROR_COLOURS: [&str; 10] = [
    "#313695", "#4575b4", "#74add1", "#8fc3dc", "#d9c245", "#fdae61", "#f46d43", "#d73027",
    "#a50026", "#67001f",
];

/// The path section: the path coloured by planned feed and, where the traces allow, by
/// contour error (a switch without script), the colour scales and caption.
pub fn section(run: &Run, contour: Option<&super::measure::Measure>, out: &mut String) {
    out.push_str("<section id=\"path\"><h2>Path</h2>");
    let blocks: Vec<&CommandBlock> = run.motion().collect();
    let coarse: Vec<[f64; 3]> = blocks.iter().flat_map(|b| sample(b, 16)).collect();
    let from_setpoints = coarse.is_empty();
    // Without blocks the path is the set-points', read from their file as it is drawn.
    let setpoints = match (from_setpoints, &run.setpoints) {
        (false, _) => None,
        (true, Some(s)) => Some(s),
        (true, None) => {
            out.push_str("<p class=\"missing\">No path: commands.log and setpoints.csv are both unusable.</p></section>");
            return;
        }
    };
    let pts = coarse;
    let ext = setpoints.map_or_else(|| extent(&pts), |s| s.extent_mm);
    // The plane is the feed moves' (a rapid up to a safe height does not make a flat
    // part's plot a side view); their extent and the rapids' set the scale.
    let feed_pts: Vec<[f64; 3]> = blocks
        .iter()
        .filter(|b| !is_rapid(b))
        .flat_map(|b| sample(b, 16))
        .collect();
    let (a, b, _) = if feed_pts.is_empty() {
        plane_of(ext)
    } else {
        plane(&feed_pts)
    };
    let third = ext[3 - a - b];
    let projected = third.1 - third.0 > 1e-6;
    let (c, scale) = extent_chart(
        "path-plot",
        &format!(
            "Path in the {}{} plane{}, colour = planned feed",
            AXIS[a],
            AXIS[b],
            if projected { " (projection)" } else { "" }
        ),
        (a, b),
        ext,
        (760.0, 700.0),
    );
    let proj = move |p: [f64; 3]| (p[a], p[b]);
    let stop = stop_point(run, contour, &blocks);
    let top = top_feed(run);
    let errors = (!from_setpoints)
        .then(|| error_plot(run, contour, (a, b), &pts))
        .flatten();
    if errors.is_some() {
        out.push_str("<div class=\"switch\"><input type=\"radio\" name=\"path-colour\" id=\"path-by-feed\" checked><label for=\"path-by-feed\">colour = planned feed</label> <input type=\"radio\" name=\"path-colour\" id=\"path-by-error\"><label for=\"path-by-error\">colour = contour error</label>");
    }
    out.push_str("<div class=\"row by-feed\">");
    c.open(out);
    if let Some(s) = setpoints {
        draw_setpoints(&c, s, &proj, out);
    } else {
        draw_blocks(run, &c, &blocks, &proj, scale, top, stop, out);
    }
    let compensated = !from_setpoints && !run.programmed.is_empty();
    if compensated {
        draw_programmed(run, &c, &proj, scale, out);
    }
    let mut marks = String::new();
    markers(run, &c, &proj, &pts, &mut marks);
    let mut legend = vec![("feed move (colour = feed)", FEED), ("rapid (G0)", RAPID)];
    if compensated {
        legend.push(("as programmed (before cutter compensation)", PROGRAMMED));
    }
    if stop.is_some() {
        legend.push(("never ran (after the stop)", NOT_RUN));
    }
    c.close_with(out, &legend, &marks);
    colour_bar("feed (mm/min)", &FEED_COLOURS, top, out);
    out.push_str("</div>");
    let by_error = errors.is_some();
    if let Some(e) = errors {
        out.push_str(&e);
        out.push_str("</div>");
    }
    out.push_str("<p class=\"note\">");
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
    if stop.is_some() {
        out.push_str("The run stopped before the end of its program: the light grey rest of the path never ran. ");
    } else if stopped_early(run) && !from_setpoints {
        out.push_str("The run stopped before the end of its program, but the traces cannot tell where on the path: the whole program is drawn. ");
    }
    if projected {
        let _ = write!(
            out,
            "The path also moves in {}: this is its projection onto the {}{} plane (see the 3D view below). ",
            AXIS[3 - a - b],
            AXIS[a],
            AXIS[b]
        );
    }
    let _ = write!(
        out,
        "Feed colours are the planned speed along each block (feed limit, look-ahead start and end feeds, ramps at {} mm/s²).",
        num(run.machine.path_acc_mm_per_s2)
    );
    if by_error {
        out.push_str(" The contour-error colours are each cycle's measured position's distance to the commanded path (the figure of the summary), drawn at the measured position; a run of one colour spans at least a pixel and takes the largest error along it, so no single-cycle peak is lost.");
    }
    out.push_str("</p></section>");
}

/// A chart of the plane `(a, b)` at equal scale on both axes, its plot area at most
/// `max` px (and at least 160 px high, 420 px wide), framing `pts`; and its scale in
/// px per mm.
pub fn plane_chart(
    id: &str,
    title: &str,
    (a, b): (usize, usize),
    pts: &[[f64; 3]],
    max: (f64, f64),
) -> (Chart, f64) {
    extent_chart(id, title, (a, b), extent(pts), max)
}

/// [`plane_chart`] framing points whose extent is `ext`.
fn extent_chart(
    id: &str,
    title: &str,
    (a, b): (usize, usize),
    ext: [(f64, f64); 3],
    max: (f64, f64),
) -> (Chart, f64) {
    fit_chart(
        id,
        title,
        (&format!("{} (mm)", AXIS[a]), &format!("{} (mm)", AXIS[b])),
        (ext[a], ext[b]),
        max,
    )
}

/// A chart at equal scale on both axes framing the ranges `xr`, `yr`, its plot area at
/// most `max` px.
pub fn fit_chart(
    id: &str,
    title: &str,
    (xl, yl): (&str, &str),
    (xr, yr): ((f64, f64), (f64, f64)),
    max: (f64, f64),
) -> (Chart, f64) {
    let (mut xr, mut yr) = (pad_range(xr.0, xr.1, false), pad_range(yr.0, yr.1, false));
    let (ex, ey) = (xr.1 - xr.0, yr.1 - yr.0);
    let scale = (max.0 / ex).min(max.1 / ey);
    let (pw, ph) = ((ex * scale).max(max.0.min(420.0)), (ey * scale).max(160.0));
    let (cx, cy) = ((xr.0 + xr.1) / 2.0, (yr.0 + yr.1) / 2.0);
    let half = (pw / scale / 2.0, ph / scale / 2.0);
    xr = (cx - half.0, cx + half.0);
    yr = (cy - half.1, cy + half.1);
    let mut c = Chart::new(id, title, xl, yl, xr, yr);
    c.w = pw + c.ml + c.mr;
    c.h = ph + c.mt + c.mb;
    (c, scale)
}

/// The path coloured by contour error: the measured positions of the cycles counted,
/// with its own colour scale; `None` without a contour analysis or any counted cycle.
fn error_plot(
    run: &Run,
    contour: Option<&super::measure::Measure>,
    (a, b): (usize, usize),
    pts: &[[f64; 3]],
) -> Option<String> {
    let contour = contour?;
    let fb = run.feedback.as_ref()?;
    // Read three times over: once to size the cells, once for each cell's worst error,
    // once to draw.
    let top = contour.max.map(|w| w.um)?;
    let top = super::svg::nice_ceil(top.max(1e-3));
    let (c, _) = plane_chart(
        "path-error-plot",
        &format!(
            "Path in the {}{} plane, colour = contour error (measured positions)",
            AXIS[a], AXIS[b]
        ),
        (a, b),
        pts,
        (760.0, 700.0),
    );
    const CELL_PX: f64 = 1.5;
    const CELL_BUDGET: f64 = 40_000.0;
    let mut out = String::from("<div class=\"row by-error\">");
    c.open(&mut out);
    // Cells of 1.5 px (coarser on a path that covers much of the plot): each takes the
    // largest error of the cycles in it (so no single-cycle peak is lost), and is drawn
    // once, from the cycle before its first, in order of travel. The page grows with the
    // area the path covers, not the run's length: a circle run a thousand times draws as
    // once.
    let bin = |um: f64| ((um / top * 10.0).floor().max(0.0) as usize).min(9);
    let counted = || {
        fb.rows()
            .zip(contour.errors())
            .map(|((_, p, _), e)| e.map(|_| (c.px(p[a]), c.py(p[b]))))
    };
    // Cells of 1.5 px, coarser where the path covers more than CELL_BUDGET of them (a
    // raster over the whole part), so the plot stays within its share of the page.
    let cells_at = |size: f64| {
        counted()
            .flatten()
            .map(|(x, y)| ((x / size).floor() as i64, (y / size).floor() as i64))
            .collect::<std::collections::HashSet<_>>()
            .len()
    };
    let fine = cells_at(CELL_PX);
    let cell_px = CELL_PX * (fine as f64 / CELL_BUDGET).sqrt().max(1.0);
    let cell_of = |(x, y): (f64, f64)| ((x / cell_px).floor() as i64, (y / cell_px).floor() as i64);
    let mut worst: std::collections::HashMap<(i64, i64), usize> = Default::default();
    for (px, e) in counted().zip(contour.errors()) {
        if let (Some(px), Some(um)) = (px, e) {
            let w = worst.entry(cell_of(px)).or_insert(0);
            *w = (*w).max(bin(um));
        }
    }
    let mut drawn: std::collections::HashSet<(i64, i64)> = Default::default();
    let mut line: Vec<(f64, f64)> = Vec::new();
    let mut line_bin = 0usize;
    // The previous counted cycle's position and cell (None after a cycle not counted:
    // the path is not joined across a rapid).
    let mut prev: Option<((f64, f64), (i64, i64))> = None;
    let flush = |line: &mut Vec<(f64, f64)>, bin: usize, out: &mut String| {
        if line.len() >= 2 {
            let _ = write!(
                out,
                "<polyline stroke=\"{}\" class=\"feed\" points=\"",
                ERROR_COLOURS[bin]
            );
            for (x, y) in line.iter() {
                let _ = write!(out, "{x:.1},{y:.1} ");
            }
            out.pop();
            out.push_str("\"/>");
        }
        line.clear();
    };
    for px in counted() {
        let Some(px) = px else {
            flush(&mut line, line_bin, &mut out);
            prev = None;
            continue;
        };
        let cell = cell_of(px);
        let before = prev;
        prev = Some((px, cell));
        if before.is_some_and(|b| b.1 == cell) {
            continue;
        }
        if !drawn.insert(cell) {
            flush(&mut line, line_bin, &mut out);
            continue;
        }
        let k = worst[&cell];
        if line.is_empty() || k != line_bin {
            // A new line starts at the cycle before, so the path stays joined however
            // far apart two cycles are; a cell first reached alone is a short segment.
            flush(&mut line, line_bin, &mut out);
            line.push(before.map_or(px, |b| b.0));
            line_bin = k;
        }
        line.push(px);
    }
    flush(&mut line, line_bin, &mut out);
    let mut marks = String::new();
    markers(run, &c, &move |p: [f64; 3]| (p[a], p[b]), pts, &mut marks);
    c.close_with(
        &mut out,
        &[(
            "measured position (colour = contour error)",
            Style {
                color: ERROR_COLOURS[7],
                width: 2.0,
                dash: "",
            },
        )],
        &marks,
    );
    colour_bar("contour error (µm)", &ERROR_COLOURS, top, &mut out);
    out.push_str("</div>");
    Some(out)
}

/// Draws `blocks` in feed colours through `proj`; from `stop` on (a block and its
/// parameter), in the never-ran style.
#[allow(clippy::too_many_arguments)]
pub fn draw_blocks(
    run: &Run,
    c: &Chart,
    blocks: &[&CommandBlock],
    proj: Proj,
    scale: f64,
    top: f64,
    stop: Option<(usize, f64)>,
    out: &mut String,
) {
    draw_blocks_with(
        run,
        c,
        blocks,
        proj,
        (scale, top),
        stop,
        Detail::Tooltips,
        out,
    );
}

/// How much a drawing of the path holds.
#[derive(Clone, Copy, PartialEq)]
pub enum Detail {
    /// The path plot: a tooltip for each block (or group), [`POINT_BUDGET`] points.
    Tooltips,
    /// A smaller view (the 3D section's): no tooltips, a quarter of the points, runs of
    /// one style across blocks joined into one polyline, so the page does not grow by
    /// a polyline a block.
    Compact,
}

/// [`draw_blocks`] at a [`Detail`].
#[allow(clippy::too_many_arguments)]
pub fn draw_blocks_with(
    run: &Run,
    c: &Chart,
    blocks: &[&CommandBlock],
    proj: Proj,
    (scale, top): (f64, f64),
    stop: Option<(usize, f64)>,
    detail: Detail,
    out: &mut String,
) {
    let total_px: f64 = blocks.iter().map(|b| b.length_mm * scale).sum();
    let budget = match detail {
        Detail::Tooltips => POINT_BUDGET,
        Detail::Compact => POINT_BUDGET / 4.0,
    };
    let step_px = (total_px / budget).max(3.0);
    let acc = run.machine.path_acc_mm_per_s2;
    let ran = |i: usize| match stop {
        Some((at, _)) if i > at => Ran::Not,
        Some((at, u)) if i == at => Ran::Until(u),
        _ => Ran::All,
    };
    let d = Draw {
        c,
        proj,
        scale,
        step_px,
        top,
        acc,
    };
    if detail == Detail::Compact {
        let mut pen = Pen::joining();
        for (i, blk) in blocks.iter().enumerate() {
            d.block(blk, ran(i), &mut pen, out);
        }
        pen.flush(out);
        return;
    }
    let group = blocks.len().div_ceil(GROUP_BUDGET).max(1);
    for (g, chunk) in blocks.chunks(group).enumerate() {
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
        let mut pen = Pen::direct();
        for (k, blk) in chunk.iter().enumerate() {
            d.block(blk, ran(g * group + k), &mut pen, out);
        }
        out.push_str("</g>");
    }
}

/// How much of a block ran.
#[derive(Clone, Copy)]
enum Ran {
    All,
    Until(f64),
    Not,
}

/// Where a drawing's polylines go: straight out, or joined while their style stays the
/// same and each starts where the last ended.
struct Pen {
    join: bool,
    /// The open polyline's head (`<polyline … points="`) and its points, px.
    head: String,
    pts: Vec<(f64, f64)>,
}

impl Pen {
    fn direct() -> Self {
        Pen {
            join: false,
            head: String::new(),
            pts: Vec::new(),
        }
    }

    fn joining() -> Self {
        Pen {
            join: true,
            ..Pen::direct()
        }
    }

    /// A polyline through `xy` (data coordinates) opened by `head`.
    fn put(&mut self, c: &Chart, head: &str, xy: &[(f64, f64)], out: &mut String) {
        if !self.join {
            out.push_str(head);
            push_points(c, xy, out);
            out.push_str("\"/>");
            return;
        }
        let px: Vec<(f64, f64)> = xy.iter().map(|&(x, y)| (c.px(x), c.py(y))).collect();
        let joins = self.head == head
            && matches!((self.pts.last(), px.first()), (Some(a), Some(b)) if (a.0 - b.0).abs() < 0.5 && (a.1 - b.1).abs() < 0.5);
        if joins {
            self.pts.extend_from_slice(&px[1..]);
        } else {
            self.flush(out);
            self.head = head.to_string();
            self.pts = px;
        }
    }

    fn flush(&mut self, out: &mut String) {
        if self.pts.is_empty() {
            return;
        }
        out.push_str(&self.head);
        let n = self.pts.len();
        write_px(self.pts.drain(..), n, out);
        out.push_str("\"/>");
    }
}

/// What drawing a block needs.
struct Draw<'a> {
    c: &'a Chart,
    proj: Proj<'a>,
    scale: f64,
    step_px: f64,
    top: f64,
    acc: f64,
}

impl Draw<'_> {
    fn block(&self, blk: &CommandBlock, ran: Ran, pen: &mut Pen, out: &mut String) {
        let (u0, u1) = shared::path::domain(blk);
        let len_px = blk.length_mm * self.scale;
        let n_for = |share: f64| {
            let n = ((len_px * share / self.step_px).ceil() as usize).clamp(1, 600);
            if blk.degree > 1 || len_px * share > 12.0 {
                n.max(4)
            } else {
                n
            }
        };
        let (done, rest) = match ran {
            Ran::All => (Some((u0, u1)), None),
            Ran::Not => (None, Some((u0, u1))),
            Ran::Until(u) => (Some((u0, u)), Some((u, u1))),
        };
        let share = |(a, b): (f64, f64)| if u1 > u0 { (b - a) / (u1 - u0) } else { 1.0 };
        if let Some(r) = rest {
            let pts = sample_range(blk, r.0, r.1, n_for(share(r)));
            let xy: Vec<(f64, f64)> = pts.iter().map(|p| (self.proj)(*p)).collect();
            pen.put(self.c, "<polyline class=\"notrun\" points=\"", &xy, out);
        }
        let Some(d) = done else {
            return;
        };
        let pts = sample_range(blk, d.0, d.1, n_for(share(d)));
        if is_rapid(blk) {
            let xy: Vec<(f64, f64)> = pts.iter().map(|p| (self.proj)(*p)).collect();
            pen.put(self.c, "<polyline class=\"rapid\" points=\"", &xy, out);
            return;
        }
        // Arc length at each sample, scaled to the block's exact length (for a block cut
        // short, by its share of the parameter: near enough for a colour).
        let mut s = vec![0.0; pts.len()];
        for i in 1..pts.len() {
            let d = [0, 1, 2].map(|k| pts[i][k] - pts[i - 1][k]);
            s[i] = s[i - 1] + shared::path::norm(d);
        }
        let chord = s.last().copied().unwrap_or(0.0);
        let k = if chord > 0.0 {
            blk.length_mm * share(d) / chord
        } else {
            0.0
        };
        let bin = |i: usize| {
            let v = planned(blk, s[i] * k, blk.length_mm, self.acc) * 60.0;
            ((v / self.top * 10.0).floor().max(0.0) as usize).min(9)
        };
        let mut run_start = 0;
        let mut cur = bin(0).max(bin(1.min(pts.len() - 1)));
        for i in 1..pts.len() {
            // The colour of a segment is that of its faster end.
            let seg = bin(i - 1).max(bin(i));
            if seg != cur {
                self.emit(&pts[run_start..i], cur, pen, out);
                run_start = i - 1;
                cur = seg;
            }
        }
        self.emit(&pts[run_start..], cur, pen, out);
    }

    fn emit(&self, pts: &[[f64; 3]], bin: usize, pen: &mut Pen, out: &mut String) {
        let xy: Vec<(f64, f64)> = pts.iter().map(|p| (self.proj)(*p)).collect();
        let head = format!(
            "<polyline stroke=\"{}\" class=\"feed\" points=\"",
            FEED_COLOURS[bin]
        );
        pen.put(self.c, &head, &xy, out);
    }
}

/// Writes pixel coordinates, dropping points within half a pixel of the last one kept
/// (the last point is always kept so blocks join).
pub fn push_points(c: &Chart, xy: &[(f64, f64)], out: &mut String) {
    write_px(xy.iter().map(|&(x, y)| (c.px(x), c.py(y))), xy.len(), out);
}

/// Writes the `n` pixel coordinates `pts`, dropping points within half a pixel of the
/// last one kept (the last point is always kept).
fn write_px(pts: impl Iterator<Item = (f64, f64)>, n: usize, out: &mut String) {
    let mut last = (f64::NAN, f64::NAN);
    for (i, p) in pts.enumerate() {
        let near = (p.0 - last.0).abs() < 0.5 && (p.1 - last.1).abs() < 0.5;
        if near && i + 1 != n {
            continue;
        }
        let _ = write!(out, "{:.1},{:.1} ", p.0, p.1);
        last = p;
    }
    if n > 0 {
        out.pop();
    }
}

/// The programmed path of a compensated program ([`Run::programmed`]): its feed moves,
/// thin, black and dotted, over the tool's.
fn draw_programmed(run: &Run, c: &Chart, proj: Proj, scale: f64, out: &mut String) {
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
        let xy: Vec<(f64, f64)> = sample(blk, n).iter().map(|p| proj(*p)).collect();
        out.push_str("<polyline fill=\"none\" stroke=\"#000\" stroke-width=\"1\" stroke-dasharray=\"2 3\" points=\"");
        push_points(c, &xy, out);
        out.push_str("\"/>");
    }
    out.push_str("</g>");
}

fn draw_setpoints(c: &Chart, sp: &super::data::Setpoints, proj: Proj, out: &mut String) {
    let xy = sp.rows().map(|(_, p, _)| proj(p));
    out.push_str("<polyline class=\"feed\" stroke=\"#1f3b73\" points=\"");
    write_px(xy.map(|(x, y)| (c.px(x), c.py(y))), sp.len(), out);
    out.push_str("\"/>");
}

/// A label beside the point `(x, y)` (px) that stays inside the chart: to its right, or
/// to its left (anchored at its end) when the right half of the chart has no room.
fn label(c: &Chart, (x, y): (f64, f64), dy: f64, text: &str, out: &mut String) {
    let room = c.w - c.mr - x;
    let wide = 7.5 * text.chars().count() as f64 + 12.0;
    if room >= wide {
        let _ = write!(
            out,
            "<text x=\"{:.1}\" y=\"{:.1}\">{text}</text>",
            x + 9.0,
            y + dy
        );
    } else {
        let _ = write!(
            out,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">{text}</text>",
            x - 9.0,
            y + dy
        );
    }
}

/// Start (open circle), end (filled square), or where a run that stopped early stopped
/// (a cross).
pub fn markers(run: &Run, c: &Chart, proj: Proj, pts: &[[f64; 3]], out: &mut String) {
    let sp = run.setpoints.as_ref();
    let (Some(start), Some(end)) = (
        sp.map(|s| &s.first_mm).or(pts.first()),
        sp.map(|s| &s.last_mm).or(pts.last()),
    ) else {
        return;
    };
    let fault = stopped_early(run);
    let (s, e) = (proj(*start), proj(*end));
    let (sx, sy) = (c.px(s.0), c.py(s.1));
    let (ex, ey) = (c.px(e.0), c.py(e.1));
    // A mark outside the plot area (a view framed on the cut) is left out.
    let inside = |x: f64, y: f64| {
        (c.ml - 1.0..=c.w - c.mr + 1.0).contains(&x) && (c.mt - 1.0..=c.h - c.mb + 1.0).contains(&y)
    };
    if inside(sx, sy) {
        let _ = write!(
            out,
            r##"<g class="mark"><title>start</title><circle cx="{sx:.1}" cy="{sy:.1}" r="6" fill="none" stroke="#000" stroke-width="2"/>"##
        );
        label(c, (sx, sy), -8.0, "start", out);
        out.push_str("</g>");
    }
    if !inside(ex, ey) {
        return;
    }
    if fault {
        let _ = write!(
            out,
            r##"<g class="mark"><title>stopped here (fault)</title><path d="M{:.1} {:.1}l12 12m0 -12l-12 12" stroke="#b00020" stroke-width="3"/>"##,
            ex - 6.0,
            ey - 6.0,
        );
        label(c, (ex, ey), 16.0, "stopped (fault)", out);
        out.push_str("</g>");
    } else {
        let _ = write!(
            out,
            r##"<g class="mark"><title>end</title><rect x="{:.1}" y="{:.1}" width="9" height="9" fill="#000"/>"##,
            ex - 4.5,
            ey - 4.5,
        );
        label(c, (ex, ey), 16.0, "end", out);
        out.push_str("</g>");
    }
}

/// A vertical colour scale of `colours` from 0 to `top`, named `name` (with its unit).
pub fn colour_bar(name: &str, colours: &[&str; 10], top: f64, out: &mut String) {
    let (h, y0) = (300.0, 46.0);
    let _ = write!(
        out,
        r#"<svg class="chart" viewBox="0 0 130 380" width="130" height="380" role="img" aria-label="{name} colour scale"><text x="4" y="30" class="lg">{name}</text>"#
    );
    for (i, col) in colours.iter().enumerate() {
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
            if top >= 50.0 { num(v.round()) } else { num(v) }
        );
    }
    out.push_str("</svg>");
}
