//! The scallop map of a STEP-NC part: the material the run left between its passes,
//! measured over the part's surface from the machine's positions
//! ([`crate::scallop::map`], the measure of `report.json`'s `measured_max_scallop_mm`),
//! drawn over the part's top view (XY).
//!
//! The surface's grid points are gathered into cells of a few pixels, each coloured by
//! the largest height in it, so a ridge a cell wide still shows at its height and the
//! page's size is bounded by the plot's area. Points the cut does not surround (the
//! surface beyond the first and last passes, where nothing was cut on the far side) are
//! grey: there the height is not a scallop.

use super::data::Run;
use super::path::{colour_bar, plane_chart, ERROR_COLOURS};
use super::svg::{nice_ceil, num, Style};
use crate::scallop::MapPoint;
use std::collections::HashMap;
use std::fmt::Write;

/// Cell size in px.
const CELL_PX: f64 = 5.0;
const UNJUDGED: &str = "#e2e2e2";
/// Grid points of the map in all: fine enough that its grid does not alias with the
/// passes of a part of few patches.
const MAP_POINTS: usize = 40_000;

/// The scallop section, for a run with surface blocks; nothing for other runs.
pub fn section(run: &Run, out: &mut String) {
    if !run.motion().any(|b| b.is_surface()) {
        return;
    }
    out.push_str("<section id=\"scallop\"><h2>Scallop</h2>");
    let Some(fb) = run.feedback.as_ref() else {
        out.push_str("<p class=\"missing\">No scallop map: feedback.csv is missing or unusable.</p></section>");
        return;
    };
    // The map's index of ball centres holds every measured position (as the measured
    // scallop of report.json does): read here, for a run of surface blocks only.
    let positions: Vec<[f64; 3]> = fb.rows().map(|(_, p, _)| p).collect();
    let Some(map) = crate::scallop::map(&run.blocks, &positions, MAP_POINTS)
        .filter(|m| m.patches.iter().flatten().any(Option::is_some))
    else {
        out.push_str("<p class=\"note\">No scallop map: the part's passes use more than one tool, or no ball reached the surface.</p></section>");
        return;
    };
    let patches = &map.patches;
    let pts: Vec<[f64; 3]> = patches.iter().flatten().flatten().map(|p| p.0).collect();
    let highest = patches
        .iter()
        .flatten()
        .flatten()
        .filter_map(|p| p.1)
        .fold(0.0, f64::max);
    let top_um = nice_ceil((highest * 1e3).max(1e-3));
    let (c, _) = plane_chart(
        "scallop-map",
        "Scallop height over the part (top view), measured from the machine's positions",
        (0, 1),
        &pts,
        (700.0, 640.0),
    );
    // Each grid quad covers the cells of its box in the view, with the largest judged
    // height of its corners; a cell keeps the largest of the quads over it.
    let mut cells: HashMap<(i64, i64), Option<f64>> = HashMap::new();
    let g = map.grid;
    for grid in patches {
        for i in 0..g - 1 {
            for j in 0..g - 1 {
                let corners = [
                    grid[i * g + j],
                    grid[i * g + j + 1],
                    grid[(i + 1) * g + j],
                    grid[(i + 1) * g + j + 1],
                ];
                let Some(corners) = corners.into_iter().collect::<Option<Vec<MapPoint>>>() else {
                    continue;
                };
                let h = corners.iter().filter_map(|p| p.1).reduce(f64::max);
                let (mut lo, mut hi) = ((i64::MAX, i64::MAX), (i64::MIN, i64::MIN));
                for (p, _) in &corners {
                    let k = (
                        (c.px(p[0]) / CELL_PX).floor() as i64,
                        (c.py(p[1]) / CELL_PX).floor() as i64,
                    );
                    (lo, hi) = (
                        (lo.0.min(k.0), lo.1.min(k.1)),
                        (hi.0.max(k.0), hi.1.max(k.1)),
                    );
                }
                for x in lo.0..=hi.0 {
                    for y in lo.1..=hi.1 {
                        let cell = cells.entry((x, y)).or_insert(None);
                        if let Some(h) = h {
                            *cell = Some(cell.map_or(h, |c: f64| c.max(h)));
                        }
                    }
                }
            }
        }
    }
    let colour = |h: Option<f64>| match h {
        Some(h) => ERROR_COLOURS[((h * 1e3 / top_um * 10.0).floor().max(0.0) as usize).min(9)],
        None => UNJUDGED,
    };
    // Row by row, runs of one colour as one rectangle.
    let mut keys: Vec<(i64, i64)> = cells.keys().map(|k| (k.1, k.0)).collect();
    keys.sort();
    out.push_str("<div class=\"row\">");
    c.open(out);
    let mut k = 0;
    while k < keys.len() {
        let (y, x0) = keys[k];
        let col = colour(cells[&(x0, y)]);
        let mut x1 = x0;
        while k + 1 < keys.len() && keys[k + 1] == (y, x1 + 1) && colour(cells[&(x1 + 1, y)]) == col
        {
            x1 += 1;
            k += 1;
        }
        k += 1;
        let _ = write!(
            out,
            r#"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{CELL_PX}" fill="{col}"/>"#,
            x0 as f64 * CELL_PX,
            y as f64 * CELL_PX,
            (x1 - x0 + 1) as f64 * CELL_PX
        );
    }
    let report = run.report.as_ref();
    let mut marks = String::new();
    if let (Some(at), Some(m)) = (
        report.and_then(|r| r.measured_max_scallop_at_mm),
        report.and_then(|r| r.measured_max_scallop_mm),
    ) {
        let (x, y) = (c.px(at[0]), c.py(at[1]));
        let _ = write!(
            marks,
            r##"<g class="mark"><title>largest scallop, {h:.2} µm</title><path d="M{:.1} {:.1}l12 12m0 -12l-12 12" stroke="#000" stroke-width="2.5"/><text x="{:.1}" y="{:.1}"{anchor}>max {h:.2} µm</text></g>"##,
            x - 6.0,
            y - 6.0,
            if x > c.w / 2.0 { x - 9.0 } else { x + 9.0 },
            y - 8.0,
            h = m * 1e3,
            anchor = if x > c.w / 2.0 {
                " text-anchor=\"end\""
            } else {
                ""
            },
        );
    }
    c.close_with(
        out,
        &[(
            "not judged (beyond the outer passes)",
            Style {
                color: UNJUDGED,
                width: 6.0,
                dash: "",
            },
        )],
        &marks,
    );
    colour_bar("scallop (µm)", &ERROR_COLOURS, top_um, out);
    let planned = report
        .and_then(|r| r.max_scallop_mm)
        .map_or(String::new(), |h| {
            format!(
                " The passes were planned for at most {} µm.",
                num((h * 1e3 * 100.0).round() / 100.0)
            )
        });
    let _ = write!(
        out,
        "</div><p class=\"note\">At each point of a {g} × {g} grid on each of the surface's {}, the material left: how far along the surface's normal the nearest ball of the tool, at the machine's measured positions, begins. Each {CELL_PX} px cell shows the largest height of the grid's quads over it. The cross marks the largest scallop of the summary, found by refining the highest grid points, so it can lie above every cell's colour.{planned}</p></section>",
        if patches.len() == 1 {
            "1 patch".to_string()
        } else {
            format!("{} patches", patches.len())
        },
        g = map.grid
    );
}
