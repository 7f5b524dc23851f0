//! The roundness plot: for a closed, circular cutting path, the radial deviation of the
//! measured positions about the best-fit centre, magnified like a ballbar or roundness
//! plot.
//!
//! When it is drawn: the feed moves (rapids left out) start and end at the same point
//! within 1 µm, and the set-points of those moves lie on one circle (a least-squares
//! circle fit leaves them within 2 % of the radius and they turn at least once around the
//! centre). The fit (Kåsa's algebraic fit, three normal equations) is made on the
//! *commanded* set-points, so the centre and radius are those the program asked for; the
//! deviation is then that of the *measured* positions (`feedback.csv`), plus the commanded
//! one dashed for comparison (its chord error).

use super::data::Run;
use super::path::{plane, sample};
use super::svg::{esc, fixed, nice_ceil, num, style_attrs, AXES};
use shared::protocol::FLAG_RAPID;
use std::collections::HashSet;
use std::f64::consts::PI;
use std::fmt::Write;

/// The result of a circle fit and the deviations about it.
pub struct Roundness {
    pub axes: (usize, usize),
    pub centre_mm: [f64; 2],
    pub radius_mm: f64,
    /// `(angle in rad, radial deviation in µm)` of the measured positions.
    pub measured: Vec<(f64, f64)>,
    /// The same for the commanded set-points.
    pub commanded: Vec<(f64, f64)>,
}

impl Roundness {
    /// Max minus min radial deviation of the measured positions, µm.
    pub fn circularity_um(&self) -> f64 {
        spread(&self.measured)
    }
}

fn spread(v: &[(f64, f64)]) -> f64 {
    let (lo, hi) = v
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.1), b.max(p.1))
        });
    if hi >= lo {
        hi - lo
    } else {
        0.0
    }
}

/// The roundness of the run's cutting path, or why there is none.
pub fn analyse(run: &Run) -> Result<Roundness, String> {
    let cutting: Vec<_> = run.motion().filter(|b| b.flags & FLAG_RAPID == 0).collect();
    let (Some(first), Some(last)) = (cutting.first(), cutting.last()) else {
        return Err("no feed moves".into());
    };
    let (u0, _) = shared::path::domain(first);
    let (_, u1) = shared::path::domain(last);
    let (p0, p1) = (
        shared::path::eval(first, u0).p,
        shared::path::eval(last, u1).p,
    );
    let gap = shared::path::norm([0, 1, 2].map(|k| p1[k] - p0[k]));
    if gap > 0.001 {
        return Err(format!(
            "the feed moves do not return to their start (end {:.3} mm from start)",
            gap
        ));
    }
    let coarse: Vec<[f64; 3]> = cutting.iter().flat_map(|b| sample(b, 16)).collect();
    let (a, b, _) = plane(&coarse);
    let Some(sp) = &run.setpoints else {
        return Err("setpoints.csv is unusable".into());
    };
    let rapid_lines: HashSet<u32> = run
        .motion()
        .filter(|b| b.flags & FLAG_RAPID != 0)
        .map(|b| b.source_line)
        .collect();
    let lines: HashSet<u32> = cutting
        .iter()
        .map(|b| b.source_line)
        .filter(|l| !rapid_lines.contains(l))
        .collect();
    let idx: Vec<usize> = (0..sp.line.len())
        .filter(|&i| lines.contains(&sp.line[i]))
        .collect();
    if idx.len() < 16 {
        return Err("too few set-points on the feed moves".into());
    }
    let pts: Vec<[f64; 2]> = idx
        .iter()
        .map(|&i| [sp.pos_mm[i][a], sp.pos_mm[i][b]])
        .collect();
    let (centre, r) = fit_circle(&pts).ok_or("no circle fits the path")?;
    let dev = |p: [f64; 2]| {
        let (dx, dy) = (p[0] - centre[0], p[1] - centre[1]);
        (dy.atan2(dx), ((dx * dx + dy * dy).sqrt() - r) * 1000.0)
    };
    let commanded: Vec<(f64, f64)> = pts.iter().map(|p| dev(*p)).collect();
    if commanded.iter().any(|d| d.1.abs() > 0.02 * r * 1000.0) {
        return Err("the feed moves are not one circle".into());
    }
    let mut turned = 0.0;
    for w in commanded.windows(2) {
        let mut d = w[1].0 - w[0].0;
        if d > PI {
            d -= 2.0 * PI;
        } else if d < -PI {
            d += 2.0 * PI;
        }
        turned += d;
    }
    if turned.abs() < 2.0 * PI * 0.98 {
        return Err("the path does not go once around a centre".into());
    }
    let cycles: HashSet<u64> = idx.iter().map(|&i| sp.cycle[i]).collect();
    let measured = run.feedback.as_ref().map_or_else(Vec::new, |fb| {
        (0..fb.cycle.len())
            .filter(|&i| cycles.contains(&fb.cycle[i]))
            .map(|i| dev([fb.pos_mm[i][a], fb.pos_mm[i][b]]))
            .collect()
    });
    Ok(Roundness {
        axes: (a, b),
        centre_mm: centre,
        radius_mm: r,
        measured,
        commanded,
    })
}

/// Least-squares circle through `pts` (Kåsa), in coordinates relative to the mean so the
/// normal equations stay well conditioned.
pub fn fit_circle(pts: &[[f64; 2]]) -> Option<([f64; 2], f64)> {
    let n = pts.len() as f64;
    let m = pts
        .iter()
        .fold([0.0, 0.0], |s, p| [s[0] + p[0] / n, s[1] + p[1] / n]);
    // Minimise Σ (x² + y² + D x + E y + F)²: A [D E F]ᵀ = rhs.
    let mut a = [[0.0f64; 3]; 3];
    let mut rhs = [0.0f64; 3];
    for p in pts {
        let (x, y) = (p[0] - m[0], p[1] - m[1]);
        let row = [x, y, 1.0];
        let z = -(x * x + y * y);
        for i in 0..3 {
            for j in 0..3 {
                a[i][j] += row[i] * row[j];
            }
            rhs[i] += row[i] * z;
        }
    }
    let [d, e, f] = solve3(a, rhs)?;
    let (cx, cy) = (-d / 2.0, -e / 2.0);
    let r2 = cx * cx + cy * cy - f;
    (r2 > 0.0 && r2.is_finite()).then(|| ([cx + m[0], cy + m[1]], r2.sqrt()))
}

/// Cramer's rule; `None` when singular.
fn solve3(a: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: [[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(a);
    if d.abs() < 1e-300 || !d.is_finite() {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut m = a;
        for i in 0..3 {
            m[i][k] = b[i];
        }
        *xk = det(m) / d;
    }
    Some(x)
}

/// Keeps at most the smallest and largest deviation per quarter degree, in order.
fn reduce(v: &[(f64, f64)]) -> Vec<(f64, f64)> {
    if v.len() <= 3000 {
        return v.to_vec();
    }
    let mut r = super::svg::Reducer::new(0.0, 1.0, 1440.0);
    // Unwrapped angle keeps the order of travel for the reducer's columns.
    for (i, p) in v.iter().enumerate() {
        r.push(i as f64 / v.len() as f64, p.1);
    }
    let flat: Vec<(f64, f64)> = r.finish().into_iter().flatten().collect();
    flat.iter()
        .map(|&(x, d)| {
            let i = ((x * v.len() as f64).round() as usize).min(v.len() - 1);
            (v[i].0, d)
        })
        .collect()
}

/// The roundness section, or a one-line note why the path gets none.
pub fn section(run: &Run, out: &mut String) {
    let r = match analyse(run) {
        Ok(r) => r,
        Err(why) => {
            let _ = write!(
                out,
                "<section id=\"roundness\"><h2>Roundness</h2><p class=\"note\">No roundness plot: {}. It is drawn for a closed circular path.</p></section>",
                esc(&why)
            );
            return;
        }
    };
    let name = ["X", "Y", "Z"];
    let (a, b) = r.axes;
    let src = if r.measured.is_empty() {
        &r.commanded
    } else {
        &r.measured
    };
    let maxabs = src.iter().map(|p| p.1.abs()).fold(0.0, f64::max).max(1e-3);
    let per_div = nice_ceil(maxabs / 3.0);
    let (cx, cy, base, div) = (280.0, 326.0, 150.0, 36.0);
    let _ = write!(
        out,
        r#"<section id="roundness"><h2>Roundness</h2><div class="row"><svg class="chart" id="polar-plot" viewBox="0 0 560 640" width="560" height="640" role="img" aria-labelledby="polar-t"><title id="polar-t">Radial deviation about the best-fit centre, magnified ({} µm per division)</title><text x="8" y="16" class="ttl">Radial deviation about the best-fit centre ({}{} plane)</text>"#,
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
        let _ = write!(
            out,
            r#"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" class="grid"/><text x="{:.1}" y="{:.1}" class="tx">{deg}°</text>"#,
            cx + r0 * t.cos(),
            cy - r0 * t.sin(),
            cx + r1 * t.cos(),
            cy - r1 * t.sin(),
            cx + (r1 + 12.0) * t.cos(),
            cy - (r1 + 12.0) * t.sin() + 4.0
        );
    }
    let plot = |v: &[(f64, f64)], st: &super::svg::Style, out: &mut String| {
        if v.is_empty() {
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
    plot(&r.commanded, &commanded_style, out);
    plot(&r.measured, &AXES[0], out);
    let _ = write!(out, r#"<line x1="10" y1="33" x2="38" y2="33""#);
    style_attrs(out, &AXES[0]);
    out.push_str(r#"/><text x="43" y="37" class="lg">measured (feedback.csv)</text><line x1="220" y1="33" x2="248" y2="33""#);
    style_attrs(out, &commanded_style);
    let _ = write!(
        out,
        r#"/><text x="253" y="37" class="lg">commanded (setpoints.csv)</text><text x="{cx}" y="{:.1}" class="xl">deviation (µm), {} µm per division; angle about the centre (°)</text></svg>"#,
        632.0,
        num(per_div)
    );
    let (lo, hi) = src
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
            (l.min(p.1), h.max(p.1))
        });
    let _ = write!(
        out,
        r#"<table class="figs"><tr><th>circularity (max − min radial deviation, measured)</th><td id="circularity">{:.2} µm</td></tr><tr><th>largest deviation outward / inward</th><td>{:+.2} µm / {:+.2} µm</td></tr><tr><th>commanded path circularity (chord error)</th><td>{:.3} µm</td></tr><tr><th>best-fit centre</th><td>{} {} mm, {} {} mm</td></tr><tr><th>best-fit radius</th><td>{:.4} mm</td></tr><tr><th>magnification</th><td>{} µm per division (rings); nominal circle bold</td></tr></table></div>"#,
        spread(src),
        hi,
        lo,
        spread(&r.commanded),
        name[a],
        fixed(r.centre_mm[0], 4),
        name[b],
        fixed(r.centre_mm[1], 4),
        r.radius_mm,
        num(per_div)
    );
    out.push_str("<p class=\"note\">The centre and radius are fitted (least squares) to the commanded set-points of the feed moves; the deviation of each measured position from that circle is drawn magnified around the nominal circle, as on a ballbar plot. It includes the acceleration from rest at the start of the circle.</p></section>");
}
