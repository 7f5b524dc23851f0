//! Chart primitives: a framed chart with ticks and axis labels, polylines in line styles
//! that survive black-and-white printing, and the min/max reduction per pixel column.
//!
//! Coordinates are written with one decimal (0.1 px): finer is invisible and only makes the
//! page bigger.

use std::fmt::Write;

/// Escapes text for HTML and SVG content and attributes.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c if c.is_control() => o.push(' '),
            c => o.push(c),
        }
    }
    o
}

/// A number for a tick label: no trailing zeros, exponent form when very large or small.
pub fn num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e6).contains(&a) {
        let e = a.log10().floor();
        let m = v / 10f64.powf(e);
        return format!("{}e{}", trim(format!("{m:.2}")), e as i32);
    }
    let decimals = (3.0 - a.log10().floor()).clamp(0.0, 6.0) as usize;
    trim(format!("{v:.decimals$}"))
}

/// `v` with `d` decimals, without the "-0.000" of a tiny negative number.
pub fn fixed(v: f64, d: usize) -> String {
    let s = format!("{v:.d$}");
    if s.starts_with('-') && s[1..].chars().all(|c| c == '0' || c == '.') {
        s[1..].to_string()
    } else {
        s
    }
}

fn trim(s: String) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// A 1-2-5 step giving about `n` intervals over `range`.
pub fn nice_step(range: f64, n: f64) -> f64 {
    if !range.is_finite() || range <= 0.0 {
        return 1.0;
    }
    let raw = range / n;
    let mag = 10f64.powf(raw.log10().floor());
    let f = raw / mag;
    mag * if f < 1.5 {
        1.0
    } else if f < 3.5 {
        2.0
    } else if f < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// The smallest 1-2-5 number (times a power of ten) at least `x`.
pub fn nice_ceil(x: f64) -> f64 {
    if !x.is_finite() || x <= 0.0 {
        return 1.0;
    }
    let mag = 10f64.powf(x.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|f| f * mag)
        .find(|v| *v >= x * (1.0 - 1e-12))
        .unwrap_or(10.0 * mag)
}

/// `(lo, hi)` widened to a non-empty range with a little room, for data in `[lo, hi]`.
pub fn pad_range(lo: f64, hi: f64, from_zero: bool) -> (f64, f64) {
    let (mut lo, hi) = if lo.is_finite() && hi.is_finite() && lo <= hi {
        (lo, hi)
    } else {
        (0.0, 1.0)
    };
    if from_zero && lo >= 0.0 {
        lo = 0.0;
    }
    if hi - lo < 1e-12 {
        let d = if hi.abs() > 1e-9 { hi.abs() * 0.1 } else { 1.0 };
        return (lo - d, hi + d);
    }
    let m = (hi - lo) * 0.05;
    (if from_zero && lo == 0.0 { 0.0 } else { lo - m }, hi + m)
}

/// A line style: colour for the screen, dash pattern and width for black and white.
#[derive(Debug, Clone, Copy)]
pub struct Style {
    pub color: &'static str,
    pub width: f64,
    /// SVG `stroke-dasharray`, "" for solid.
    pub dash: &'static str,
}

pub const SOLID: Style = Style {
    color: "#1f3b73",
    width: 1.2,
    dash: "",
};
pub const LIMIT: Style = Style {
    color: "#b00020",
    width: 1.2,
    dash: "8 4",
};
/// Three axes and a fourth trace, told apart by dash pattern as well as colour.
pub const AXES: [Style; 4] = [
    Style {
        color: "#1f3b73",
        width: 1.2,
        dash: "",
    },
    Style {
        color: "#c05a00",
        width: 1.2,
        dash: "6 3",
    },
    Style {
        color: "#2a7f3f",
        width: 1.4,
        dash: "1.5 2.5",
    },
    Style {
        color: "#6d2f8f",
        width: 1.0,
        dash: "9 3 2 3",
    },
];

/// A framed x/y chart.
pub struct Chart {
    pub id: String,
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x: (f64, f64),
    pub y: (f64, f64),
    pub x_log: bool,
    /// Log scale on y (decade ticks); the range must be positive.
    pub y_log: bool,
    /// Category names for a bar chart: category `i` is centred on `y = i + 0.5` and these
    /// names replace the numeric y ticks.
    pub y_cats: Vec<String>,
    /// Grid, ticks and axis labels (off for a projection whose axes are not the chart's).
    pub ticks: bool,
    pub w: f64,
    pub h: f64,
    pub ml: f64,
    pub mr: f64,
    pub mt: f64,
    pub mb: f64,
}

impl Chart {
    /// A 980 × 300 chart; change the public fields before [`Chart::open`] for others.
    pub fn new(
        id: &str,
        title: &str,
        x_label: &str,
        y_label: &str,
        x: (f64, f64),
        y: (f64, f64),
    ) -> Chart {
        Chart {
            id: id.into(),
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            x,
            y,
            x_log: false,
            y_log: false,
            y_cats: Vec::new(),
            ticks: true,
            w: 980.0,
            h: 300.0,
            ml: 78.0,
            mr: 20.0,
            mt: 46.0,
            mb: 44.0,
        }
    }

    /// Plot-area width in px: the number of columns a series should be reduced to.
    pub fn plot_w(&self) -> f64 {
        self.w - self.ml - self.mr
    }

    fn fx(&self, x: f64) -> f64 {
        if self.x_log {
            x.max(1e-300).log10()
        } else {
            x
        }
    }

    pub fn px(&self, x: f64) -> f64 {
        let (a, b) = (self.fx(self.x.0), self.fx(self.x.1));
        self.ml + (self.fx(x) - a) / (b - a) * self.plot_w()
    }

    fn fy(&self, y: f64) -> f64 {
        if self.y_log {
            y.max(1e-300).log10()
        } else {
            y
        }
    }

    pub fn py(&self, y: f64) -> f64 {
        let ph = self.h - self.mt - self.mb;
        let (a, b) = (self.fy(self.y.0), self.fy(self.y.1));
        self.mt + ph - (self.fy(y) - a) / (b - a) * ph
    }

    /// The SVG header, frame, grid, ticks, axis labels and title; data drawn after this is
    /// clipped to the plot area until [`Chart::close`].
    pub fn open(&self, out: &mut String) {
        let (w, h, ml, mt) = (self.w, self.h, self.ml, self.mt);
        let (pw, ph) = (self.plot_w(), h - mt - self.mb);
        let _ = write!(
            out,
            r#"<svg class="chart" id="{id}" viewBox="0 0 {w} {h}" width="{w}" height="{h}" role="img" aria-labelledby="{id}-t"><title id="{id}-t">{t}</title><defs><clipPath id="{id}-c"><rect x="{ml}" y="{mt}" width="{pw}" height="{ph}"/></clipPath></defs><rect x="{ml}" y="{mt}" width="{pw}" height="{ph}" class="area"/><text x="{ml}" y="16" class="ttl">{t}</text>"#,
            id = self.id,
            t = esc(&self.title)
        );
        if !self.ticks {
            let _ = write!(out, r#"<g clip-path="url(#{}-c)">"#, self.id);
            return;
        }
        let yb = mt + ph;
        for t in self.x_ticks() {
            let x = self.px(t);
            let _ = write!(
                out,
                r#"<line x1="{x:.1}" y1="{mt}" x2="{x:.1}" y2="{yb}" class="grid"/><text x="{x:.1}" y="{:.1}" class="tx">{}</text>"#,
                yb + 15.0,
                num(t)
            );
        }
        for (i, name) in self.y_cats.iter().enumerate() {
            let _ = write!(
                out,
                r#"<text x="{:.1}" y="{:.1}" class="ty">{}</text>"#,
                ml - 5.0,
                self.py(i as f64 + 0.5) + 4.0,
                esc(name)
            );
        }
        if self.y_log && self.y_cats.is_empty() {
            let (a, b) = (self.fy(self.y.0).ceil(), self.fy(self.y.1).floor());
            for e in a as i32..=b as i32 {
                let y = self.py(10f64.powi(e));
                let _ = write!(
                    out,
                    r#"<line x1="{ml}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" class="grid"/><text x="{:.1}" y="{:.1}" class="ty">{}</text>"#,
                    ml + pw,
                    ml - 5.0,
                    y + 4.0,
                    num(10f64.powi(e))
                );
            }
        }
        let step = nice_step(self.y.1 - self.y.0, (ph / 45.0).max(2.0));
        let mut t = (self.y.0 / step).ceil() * step;
        while self.y_cats.is_empty() && !self.y_log && t <= self.y.1 + step * 1e-9 {
            let y = self.py(t);
            let _ = write!(
                out,
                r#"<line x1="{ml}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" class="grid"/><text x="{:.1}" y="{:.1}" class="ty">{}</text>"#,
                ml + pw,
                ml - 5.0,
                y + 4.0,
                num(if t.abs() < step * 1e-9 { 0.0 } else { t })
            );
            t += step;
        }
        let _ = write!(
            out,
            r#"<text x="{:.1}" y="{:.1}" class="xl">{}</text><text transform="translate(14 {:.1}) rotate(-90)" class="yl">{}</text><g clip-path="url(#{}-c)">"#,
            ml + pw / 2.0,
            h - 6.0,
            esc(&self.x_label),
            mt + ph / 2.0,
            esc(&self.y_label),
            self.id
        );
    }

    fn x_ticks(&self) -> Vec<f64> {
        if self.x_log {
            let (a, b) = (self.fx(self.x.0).ceil(), self.fx(self.x.1).floor());
            return (a as i32..=b as i32).map(|e| 10f64.powi(e)).collect();
        }
        let step = nice_step(self.x.1 - self.x.0, (self.plot_w() / 90.0).max(2.0));
        let mut v = Vec::new();
        let mut t = (self.x.0 / step).ceil() * step;
        while t <= self.x.1 + step * 1e-9 && v.len() < 200 {
            v.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
            t += step;
        }
        v
    }

    /// A polyline through `pts` (data coordinates).
    pub fn line(&self, out: &mut String, pts: &[(f64, f64)], st: &Style) {
        if pts.is_empty() {
            return;
        }
        out.push_str(r#"<polyline points=""#);
        for (x, y) in pts {
            let _ = write!(out, "{:.1},{:.1} ", self.px(*x), self.py(*y));
        }
        out.pop();
        out.push('"');
        style_attrs(out, st);
        out.push_str("/>");
    }

    /// A horizontal line at `y` across the plot, labelled at its right end.
    pub fn hline(&self, out: &mut String, y: f64, st: &Style, label: &str) {
        if y < self.y.0 || y > self.y.1 {
            return;
        }
        let (x0, x1, py) = (self.ml, self.ml + self.plot_w(), self.py(y));
        let _ = write!(
            out,
            r#"<line x1="{x0}" y1="{py:.1}" x2="{x1:.1}" y2="{py:.1}""#
        );
        style_attrs(out, st);
        let _ = write!(
            out,
            r#"/><text x="{:.1}" y="{:.1}" class="lim">{}</text>"#,
            x1 - 4.0,
            py - 4.0,
            esc(label)
        );
    }

    /// Ends the clipped group, draws the legend (a sample of each style with its name)
    /// and closes the SVG.
    pub fn close(&self, out: &mut String, legend: &[(&str, Style)]) {
        self.close_with(out, legend, "");
    }

    /// [`Chart::close`] with `extra` SVG drawn unclipped after the data (own legends).
    pub fn close_with(&self, out: &mut String, legend: &[(&str, Style)], extra: &str) {
        out.push_str("</g>");
        out.push_str(extra);
        let mut x = self.ml;
        for (name, st) in legend {
            let _ = write!(
                out,
                r#"<line x1="{x:.1}" y1="33" x2="{:.1}" y2="33""#,
                x + 28.0
            );
            style_attrs(out, st);
            let _ = write!(
                out,
                r#"/><text x="{:.1}" y="37" class="lg">{}</text>"#,
                x + 33.0,
                esc(name)
            );
            x += 45.0 + 6.2 * name.chars().count() as f64;
        }
        out.push_str("</svg>");
    }
}

pub fn style_attrs(out: &mut String, st: &Style) {
    let _ = write!(
        out,
        r#" fill="none" stroke="{}" stroke-width="{}""#,
        st.color, st.width
    );
    if !st.dash.is_empty() {
        let _ = write!(out, r#" stroke-dasharray="{}""#, st.dash);
    }
}

/// Reduces a series sorted by `x` to at most two points per pixel column, the minimum
/// and the maximum in the order they occurred, so a one-sample spike keeps its height.
/// Non-finite values and [`Reducer::gap`] break the line into segments.
pub struct Reducer {
    x0: f64,
    scale: f64,
    col: i64,
    lo: Option<(f64, f64, u64)>,
    hi: Option<(f64, f64, u64)>,
    n: u64,
    segs: Vec<Vec<(f64, f64)>>,
    cur: Vec<(f64, f64)>,
}

impl Reducer {
    pub fn new(x0: f64, x1: f64, cols: f64) -> Reducer {
        let span = if x1 > x0 { x1 - x0 } else { 1.0 };
        Reducer {
            x0,
            scale: cols.max(1.0) / span,
            col: i64::MIN,
            lo: None,
            hi: None,
            n: 0,
            segs: Vec::new(),
            cur: Vec::new(),
        }
    }

    pub fn push(&mut self, x: f64, y: f64) {
        if !x.is_finite() || !y.is_finite() {
            self.gap();
            return;
        }
        let col = ((x - self.x0) * self.scale).floor() as i64;
        if col != self.col {
            self.flush();
            self.col = col;
        }
        self.n += 1;
        if self.lo.is_none_or(|(_, ly, _)| y < ly) {
            self.lo = Some((x, y, self.n));
        }
        if self.hi.is_none_or(|(_, hy, _)| y > hy) {
            self.hi = Some((x, y, self.n));
        }
    }

    fn flush(&mut self) {
        match (self.lo.take(), self.hi.take()) {
            (Some(a), Some(b)) if a.2 != b.2 => {
                let (p, q) = if a.2 < b.2 { (a, b) } else { (b, a) };
                self.cur.push((p.0, p.1));
                self.cur.push((q.0, q.1));
            }
            (Some(a), _) => self.cur.push((a.0, a.1)),
            _ => {}
        }
    }

    /// Ends the current segment: the next point starts a new line.
    pub fn gap(&mut self) {
        self.flush();
        self.col = i64::MIN;
        if !self.cur.is_empty() {
            self.segs.push(std::mem::take(&mut self.cur));
        }
    }

    pub fn finish(mut self) -> Vec<Vec<(f64, f64)>> {
        self.gap();
        self.segs
    }
}

/// The smallest and largest `y` over reduced segments.
pub fn y_extent(segs: &[Vec<(f64, f64)>]) -> (f64, f64) {
    segs.iter()
        .flatten()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.1), b.max(p.1))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reducer_keeps_a_single_spike() {
        let mut r = Reducer::new(0.0, 1_000_000.0, 100.0);
        for i in 0..1_000_000u64 {
            r.push(i as f64, if i == 123_457 { 99.0 } else { 1.0 });
        }
        let segs = r.finish();
        let pts: usize = segs.iter().map(Vec::len).sum();
        assert!(pts <= 200, "{pts}");
        assert_eq!(y_extent(&segs), (1.0, 99.0));
    }

    #[test]
    fn numbers_and_steps() {
        assert_eq!(num(2500.0), "2500");
        assert_eq!(num(0.25), "0.25");
        assert_eq!(num(2e6), "2e6");
        assert_eq!(nice_step(10.0, 5.0), 2.0);
        assert_eq!(esc("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }
}
