//! The 3D view: for a path that moves in all three axes, and for every STEP-NC part, an
//! isometric projection and the three planes (top XY, front XZ, side YZ), in the path
//! plot's feed colours, with the part's surface as a wireframe for a STEP-NC part.
//!
//! Choices, and why:
//! * **Fixed projections in SVG, no script.** A machinist reads a part from the standard
//!   views of a drawing: the isometric and the three planes. They need no script, print,
//!   and keep the page self-contained; a rotating view would need an inline script and
//!   would still show nothing the four views do not.
//! * **The isometric is the south-east one** of CAD programs: X to the right and down, Y
//!   to the right and up, Z up, seen from the front right above, where a machinist
//!   stands at a vertical mill.
//! * **A STEP-NC part is drawn at the tool's tip.** Its blocks command the tool's
//!   reference point `M = C + R·n + (H − R)·z` ([`crate::scallop`]), a tool length `H`
//!   above the tip; the 3D views subtract `H` along Z from the whole path, so the passes
//!   lie on the part's surface (the tip `C + R·(n − z)` of a ball touches the surface
//!   where it is level and is within `√2·R` of it elsewhere) and the rapids show the
//!   true clearance.
//! * **The wireframe** is each distinct Bézier patch of the surface blocks, with a few
//!   iso-parameter lines, drawn under the path.

use super::data::Run;
use super::path::{self, Proj, AXIS, FEED, NOT_RUN, RAPID};
use super::svg::{esc, Chart, Style};
use shared::nurbs::reference::piegl_tiller_surface;
use shared::protocol::CommandBlock;
use std::fmt::Write;

/// `cos 30°` and `sin 30°`.
const C30: f64 = 0.866_025_403_784_438_6;
const S30: f64 = 0.5;
/// Iso-parameter lines a patch each way (edges included), and points on each.
const WIRES: usize = 5;
const WIRE_POINTS: usize = 24;
/// Most patches in the wireframe with inner lines: beyond, only their edges.
const WIRE_PATCHES: usize = 400;
/// Most patches drawn at all: a part of more is drawn without its surface.
const WIRE_PATCHES_MAX: usize = 4000;
/// Points of the wireframe in all, about.
const WIRE_BUDGET: usize = 40_000;

/// The south-east isometric projection: X right and down, Y right and up, Z up.
pub fn iso(p: [f64; 3]) -> (f64, f64) {
    ((p[0] + p[1]) * C30, (p[1] - p[0]) * S30 + p[2])
}

/// The wireframe's polylines (in part coordinates).
fn wireframe(patches: &[&CommandBlock]) -> Vec<Vec<[f64; 3]>> {
    if patches.len() > WIRE_PATCHES_MAX {
        return Vec::new();
    }
    let lines = if patches.len() > WIRE_PATCHES {
        2
    } else {
        WIRES
    };
    // Points a line: fewer on many patches, so the wireframe stays within its budget.
    let points = (WIRE_BUDGET / (patches.len() * lines * 2).max(1)).clamp(2, WIRE_POINTS);
    let mut out = Vec::new();
    for b in patches {
        let s = shared::path::patch(b);
        for i in 0..lines {
            let w = i as f64 / (lines - 1) as f64;
            for along_u in [true, false] {
                out.push(
                    (0..=points)
                        .map(|j| {
                            let t = j as f64 / points as f64;
                            let (u, v) = if along_u { (t, w) } else { (w, t) };
                            piegl_tiller_surface(&s, u, v).p
                        })
                        .collect(),
                );
            }
        }
    }
    out
}

/// The 3D section, or nothing for a path in one plane.
pub fn section(run: &Run, contour: Option<&super::measure::Measure>, out: &mut String) {
    let blocks: Vec<&CommandBlock> = run.motion().collect();
    let feed_pts: Vec<[f64; 3]> = blocks
        .iter()
        .filter(|b| !path::is_rapid(b))
        .flat_map(|b| path::sample(b, 16))
        .collect();
    let ext = path::extent(&feed_pts);
    let moves_in_3d = !feed_pts.is_empty() && ext.iter().all(|e| e.1 - e.0 > 1e-6);
    let patches = crate::scallop::distinct_patches(blocks.iter().copied());
    if !moves_in_3d && patches.is_empty() {
        return;
    }
    // The tool's length, when one tool cuts the whole part.
    let surface: Vec<&&CommandBlock> = blocks.iter().filter(|b| b.is_surface()).collect();
    let lift = surface.first().map_or(0.0, |b| b.surface.tool_length_mm);
    let one_tool = surface.iter().all(|b| b.surface.tool_length_mm == lift);
    let lift = if one_tool { lift } else { 0.0 };
    let tip = move |p: [f64; 3]| [p[0], p[1], p[2] - lift];
    // Commanded points (tool reference points) frame the views; the part's wires are
    // lifted by the tool length so that the one projection draws both at the tip.
    let all: Vec<[f64; 3]> = blocks.iter().flat_map(|b| path::sample(b, 16)).collect();
    let wires: Vec<Vec<[f64; 3]>> = wireframe(&patches)
        .into_iter()
        .map(|w| w.into_iter().map(|p| [p[0], p[1], p[2] + lift]).collect())
        .collect();
    // The views frame the cut and the part; a rapid from far away (the machine's home,
    // a tool change height) runs out of the frame.
    let framed: Vec<[f64; 3]> = feed_pts
        .iter()
        .chain(wires.iter().flatten())
        .copied()
        .collect();
    let stop = path::stop_point(run, contour, &blocks);
    let top = path::top_feed(run);

    out.push_str("<section id=\"view3d\"><h2>3D view</h2><div class=\"row\">");
    let proj = move |p: [f64; 3]| iso(tip(p));
    let (lo, hi) = framed.iter().map(|p| proj(*p)).fold(
        (
            (f64::INFINITY, f64::INFINITY),
            (f64::NEG_INFINITY, f64::NEG_INFINITY),
        ),
        |(lo, hi), p| {
            (
                (lo.0.min(p.0), lo.1.min(p.1)),
                (hi.0.max(p.0), hi.1.max(p.1)),
            )
        },
    );
    let (mut c, scale) = path::fit_chart(
        "iso-plot",
        "Isometric view, colour = planned feed",
        ("", ""),
        ((lo.0, hi.0), (lo.1, hi.1)),
        (760.0, 560.0),
    );
    c.ticks = false;
    draw(run, &c, &blocks, &proj, scale, top, stop, &wires, true, out);
    let mut extra = String::new();
    triad(&c, &mut extra);
    path::markers(run, &c, &proj, &all, &mut extra);
    c.close_with(out, &legend(&wires, stop), &extra);
    path::colour_bar("feed (mm/min)", &path::FEED_COLOURS, top, out);
    out.push_str("</div><div class=\"row\">");
    let tipped: Vec<[f64; 3]> = framed.iter().map(|p| tip(*p)).collect();
    for (id, name, (a, b)) in [
        ("plane-xy", "Top", (0, 1)),
        ("plane-xz", "Front", (0, 2)),
        ("plane-yz", "Side", (1, 2)),
    ] {
        let (c, scale) = path::plane_chart(
            id,
            &format!("{name} ({}{})", AXIS[a], AXIS[b]),
            (a, b),
            &tipped,
            (225.0, 220.0),
        );
        let proj = move |p: [f64; 3]| {
            let q = tip(p);
            (q[a], q[b])
        };
        draw(
            run, &c, &blocks, &proj, scale, top, stop, &wires, false, out,
        );
        let mut extra = String::new();
        path::markers(run, &c, &proj, &all, &mut extra);
        c.close_with(out, &[], &extra);
    }
    out.push_str("</div><p class=\"note\">");
    if !patches.is_empty() {
        if wires.is_empty() {
            let _ = write!(
                out,
                "The part's {} are too many to draw as a wireframe. ",
                count(patches.len())
            );
        } else {
            let _ = write!(
                out,
                "The part's surface is drawn as a wireframe of its {} in the isometric view. ",
                count(patches.len())
            );
        }
        if lift != 0.0 {
            let _ = write!(
                out,
                "The path is the tool's tip: the commanded tool reference point less the tool length, {} mm, along Z. ",
                super::svg::num(lift)
            );
        } else {
            out.push_str("Its passes use more than one tool, so the path is the commanded tool reference point, above the surface by each tool's length. ");
        }
    }
    out.push_str("The isometric view looks from the front right, above: X runs to the right and down, Y to the right and up, Z up. Each view keeps equal scales on its axes.</p></section>");
}

/// "1 patch", "12 patches".
fn count(n: usize) -> String {
    if n == 1 {
        "1 patch".into()
    } else {
        format!("{n} patches")
    }
}

fn legend(wires: &[Vec<[f64; 3]>], stop: Option<(usize, f64)>) -> Vec<(&'static str, Style)> {
    let mut legend = vec![("feed move", FEED), ("rapid", RAPID)];
    if !wires.is_empty() {
        legend.push((
            "part surface",
            Style {
                color: "#b9c4cf",
                width: 1.0,
                dash: "",
            },
        ));
    }
    if stop.is_some() {
        legend.push(("never ran", NOT_RUN));
    }
    legend
}

/// The wireframe under the path (in the isometric view only: the planes show the
/// part's extent by the path), then the path.
#[allow(clippy::too_many_arguments)]
fn draw(
    run: &Run,
    c: &Chart,
    blocks: &[&CommandBlock],
    proj: Proj,
    scale: f64,
    top: f64,
    stop: Option<(usize, f64)>,
    wires: &[Vec<[f64; 3]>],
    iso: bool,
    out: &mut String,
) {
    c.open(out);
    if iso && !wires.is_empty() {
        out.push_str("<g class=\"wire\"><title>part surface</title>");
        for w in wires {
            let xy: Vec<(f64, f64)> = w.iter().map(|p| proj(*p)).collect();
            out.push_str("<polyline points=\"");
            path::push_points(c, &xy, out);
            out.push_str("\"/>");
        }
        out.push_str("</g>");
    }
    path::draw_blocks_with(
        run,
        c,
        blocks,
        proj,
        (scale, top),
        stop,
        path::Detail::Compact,
        out,
    );
}

/// X, Y and Z arrows in the lower left corner of the isometric view.
fn triad(c: &Chart, out: &mut String) {
    let (x0, y0) = (c.ml + 34.0, c.h - c.mb - 34.0);
    for (k, name) in AXIS.iter().enumerate() {
        let mut e = [0.0; 3];
        e[k] = 1.0;
        let (dx, dy) = iso(e);
        let (x1, y1) = (x0 + dx * 26.0, y0 - dy * 26.0);
        let _ = write!(
            out,
            r##"<line x1="{x0:.1}" y1="{y0:.1}" x2="{x1:.1}" y2="{y1:.1}" stroke="#333" stroke-width="1.5"/><text x="{:.1}" y="{:.1}" class="tx">{}</text>"##,
            x0 + dx * 36.0,
            y0 - dy * 36.0 + 4.0,
            esc(name)
        );
    }
}
