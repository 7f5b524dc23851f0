//! `cnc cam curves`: the curves of a CAD STEP file as a part program of exact NURBS moves
//! (seed 002, Leto et al.: CAD curves exported straight to `G5.2` instead of thousands of
//! short lines).
//!
//! Each curve [`crate::step::curves`] reads becomes the NURBS that *is* it, with no
//! fitting:
//! * a B-spline keeps its control points, weights and knots; an unclamped one is clamped
//!   to its domain and a trimmed one cut at its trims, both by knot insertion (Boehm's
//!   algorithm on the weighted points), which leaves the curve as it was;
//! * a circle or an ellipse (trimmed or whole) becomes rational quadratic arcs of at
//!   most a quarter turn each ([`super::conic_arc`]);
//! * a trimmed line and a polyline become straight moves.
//!
//! A piece against its basis curve's direction is the same NURBS reversed (points and
//! knots mirrored). Trims given as points are turned into parameters by the nearest
//! point of the curve (64 samples a knot span, refined by Brent's search), and
//! refused when that is farther than [`super::JOIN_MM`] from the point.
//!
//! The cut is a profile at `--depth`: every curve must lie in one plane parallel to XY
//! (its control points' Z within [`FLAT_MM`]), since `G5.2`/`G6.2` move in the XY plane.
//! With `--project` a curve out of that plane is cut as its projection onto XY, which
//! is exact too (an affine image of a NURBS is the NURBS of the images of its points).
//! Weights are scaled to a geometric mean of 1 (the curve does not change), and a curve
//! whose heaviest weight is more than 1e6 times its lightest is refused, as the
//! interpreter refuses weights outside 1e-3 to 1e3.

use super::{conic_arc, g5_2_knots, program, Curve, Cut, Job, Piece};
use crate::step::curves::{Bound, CadCurve, CadCurves, Shape};
use crate::step::StepError;
use std::f64::consts::TAU;

/// Control points' Z may differ by this much in a flat profile (mm).
pub const FLAT_MM: f64 = 1e-6;

/// What `cnc cam curves` is asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct CurvesJob {
    pub cut: Job,
    /// Cut curves out of the XY plane as their projection onto it.
    pub project: bool,
}

/// A NURBS in space: control points `[x, y, z, w]`.
#[derive(Debug, Clone, PartialEq)]
struct Spline {
    degree: usize,
    knots: Vec<f64>,
    ctrl: Vec<[f64; 4]>,
}

impl Spline {
    fn domain(&self) -> (f64, f64) {
        (self.knots[self.degree], self.knots[self.ctrl.len()])
    }

    /// Inserts the knot `u` once (Boehm), in homogeneous coordinates.
    fn insert(&mut self, u: f64) {
        let p = self.degree as isize;
        let m = self.knots.len() - 1;
        let k = (0..m).rev().find(|&i| self.knots[i] <= u).unwrap_or(0) as isize;
        let s = self.knots.iter().filter(|&&x| x == u).count() as isize;
        let h = |q: [f64; 4]| [q[0] * q[3], q[1] * q[3], q[2] * q[3], q[3]];
        let mut out = Vec::with_capacity(self.ctrl.len() + 1);
        for i in 0..=self.ctrl.len() as isize {
            let q = if i <= k - p {
                h(self.ctrl[i as usize])
            } else if i > k - s {
                h(self.ctrl[i as usize - 1])
            } else {
                let (ui, uip) = (self.knots[i as usize], self.knots[(i + p) as usize]);
                let a = (u - ui) / (uip - ui);
                let (pi, pm) = (h(self.ctrl[i as usize]), h(self.ctrl[i as usize - 1]));
                std::array::from_fn(|j| a * pi[j] + (1.0 - a) * pm[j])
            };
            out.push(q);
        }
        self.ctrl = out
            .into_iter()
            .map(|q| [q[0] / q[3], q[1] / q[3], q[2] / q[3], q[3]])
            .collect();
        self.knots.insert(k as usize + 1, u);
    }

    /// A knot within a rounding of `u`, or `u`.
    /// The nearest knot of the domain within a rounding of `u`, or `u`.
    fn snap(&self, u: f64) -> f64 {
        let (lo, hi) = self.domain();
        let tiny = 1e-12 * (hi - lo);
        self.knots
            .iter()
            .copied()
            .filter(|k| (lo..=hi).contains(k) && (k - u).abs() <= tiny)
            .min_by(|x, y| (x - u).abs().total_cmp(&(y - u).abs()))
            .unwrap_or(u)
    }

    /// The curve from `a` to `b` (both in the domain) as a clamped NURBS of its own, by
    /// inserting each end until it is `degree` times a knot; `None` where that leaves
    /// nothing (`a` not before `b` once each is put on a knot it rounds to).
    fn piece(&self, a: f64, b: f64) -> Option<Spline> {
        let p = self.degree;
        let mut s = self.clone();
        let (lo, hi) = self.domain();
        let (a, b) = (s.snap(a.clamp(lo, hi)), s.snap(b.clamp(lo, hi)));
        if a.is_nan() || b.is_nan() || a >= b {
            return None;
        }
        for u in [a, b] {
            while s.knots.iter().filter(|&&k| k == u).count() < p {
                s.insert(u);
            }
        }
        let ia = s.knots.iter().position(|&k| k == a).unwrap_or(0);
        let sa = s.knots.iter().filter(|&&k| k == a).count();
        let ib = s
            .knots
            .iter()
            .position(|&k| k == b)
            .unwrap_or(s.knots.len());
        let first = (ia + sa).checked_sub(p + 1)?;
        if ia + sa > ib || ib > s.ctrl.len() {
            return None;
        }
        let mut knots = vec![a; p + 1];
        knots.extend_from_slice(&s.knots[ia + sa..ib]);
        knots.extend(std::iter::repeat_n(b, p + 1));
        Some(Spline {
            degree: p,
            knots,
            ctrl: s.ctrl[first..ib].to_vec(),
        })
    }

    fn reversed(&self) -> Spline {
        let b = self.knots[self.knots.len() - 1];
        Spline {
            degree: self.degree,
            knots: self.knots.iter().rev().map(|k| b - k).collect(),
            ctrl: self.ctrl.iter().rev().copied().collect(),
        }
    }

    /// The point at `u` of a clamped spline.
    fn at(&self, u: f64) -> [f64; 3] {
        shared::nurbs::eval(self.degree, &self.knots, &self.ctrl, u).p
    }

    /// The parameter of the point of a clamped spline nearest `q`, and its distance.
    fn nearest(&self, q: [f64; 3]) -> (f64, f64) {
        let d = |u: f64| dist(self.at(u), q);
        let mut best = (self.knots[0], f64::INFINITY, 0.0);
        for w in self.knots.windows(2) {
            if w[1] <= w[0] {
                continue;
            }
            for i in 0..=64 {
                let u = w[0] + (w[1] - w[0]) * i as f64 / 64.0;
                let e = d(u);
                if e < best.1 {
                    best = (u, e, (w[1] - w[0]) / 64.0);
                }
            }
        }
        let (lo0, hi0) = (self.knots[0], self.knots[self.knots.len() - 1]);
        crate::brent::refine_min(
            (best.0 - best.2).max(lo0),
            (best.0 + best.2).min(hi0),
            best.0,
            d,
        )
    }
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

fn fail(c: &CadCurve, rule: &'static str, message: String) -> StepError {
    StepError {
        line: c.line,
        id: Some(c.id),
        rule,
        message,
    }
}

/// How a trim's point is found on its curve: the parameter of the nearest point and its
/// distance; and the point at a parameter.
struct OnCurve<'f> {
    locate: &'f dyn Fn([f64; 3]) -> (f64, f64),
    at: &'f dyn Fn(f64) -> [f64; 3],
}

/// The parameter a trim gives: its parameter, or its point's on the curve (nearest
/// within [`super::JOIN_MM`]) where only a point is given or the points rule. Where
/// both are given they must agree (a file whose angles are in another unit than it
/// says would trim elsewhere than its points).
fn trim_param(
    c: &CadCurve,
    b: &Bound,
    by_point: bool,
    what: &str,
    on: &OnCurve,
) -> Result<f64, StepError> {
    if b.param.is_some_and(|u| u.is_nan() || u.abs() > 1e9) {
        return Err(fail(c, "trim", format!("{what}'s parameter is beyond 1e9")));
    }
    if let (Some(u), Some(q)) = (b.param, b.point) {
        let d = dist((on.at)(u), q);
        if d.is_nan() || d > super::JOIN_MM {
            return Err(fail(
                c,
                "trim",
                format!(
                    "{what}'s parameter {u} and its point ({}, {}, {}) are {d:.6} mm apart; they must name one point (are the file's angle or length units the ones its trims are in?)",
                    q[0], q[1], q[2]
                ),
            ));
        }
    }
    match (b.param, b.point) {
        (Some(u), None) => Ok(u),
        (Some(u), Some(_)) if !by_point => Ok(u),
        (_, Some(q)) => {
            let (u, d) = (on.locate)(q);
            if d.is_nan() || d > super::JOIN_MM {
                return Err(fail(
                    c,
                    "trim",
                    format!(
                        "{what}'s point ({}, {}, {}) is {d:.6} mm from the curve (at most {} mm)",
                        q[0],
                        q[1],
                        q[2],
                        super::JOIN_MM
                    ),
                ));
            }
            Ok(u)
        }
        (None, None) => Err(fail(c, "trim", format!("{what} is empty"))),
    }
}

/// The pieces of a parameter range on a curve whose domain is `[lo, hi]`: from `t0` to
/// `t1` along the curve (`forward`) or against it, through the seam of a closed curve
/// where the range wraps. Each is `(from, to)` with `from < to` and whether it runs
/// reversed.
fn ranges(
    c: &CadCurve,
    (lo, hi): (f64, f64),
    (t0, t1): (f64, f64),
    forward: bool,
    closed: bool,
) -> Result<Vec<(f64, f64, bool)>, StepError> {
    let span = hi - lo;
    let tiny = 1e-12 * span;
    for t in [t0, t1] {
        if t < lo - tiny || t > hi + tiny {
            return Err(fail(
                c,
                "trim",
                format!("trim parameter {t} is outside the curve's domain [{lo}, {hi}]"),
            ));
        }
    }
    let (t0, t1) = (t0.clamp(lo, hi), t1.clamp(lo, hi));
    let (from, to) = if forward { (t0, t1) } else { (t1, t0) };
    if to - from > tiny {
        return Ok(vec![(from, to, !forward)]);
    }
    if !closed {
        let why = if (t1 - t0).abs() <= tiny {
            "trim_1 and trim_2 are the same point of an open curve: the piece is empty".to_string()
        } else {
            format!(
                "trim_1 {t0} to trim_2 {t1} runs {} the curve's direction off its end: the curve is not closed",
                if forward { "along" } else { "against" }
            )
        };
        return Err(fail(c, "trim", why));
    }
    // Through the seam: from `from` to the end, then from the start to `to`.
    let mut out = Vec::new();
    if hi - from > tiny {
        out.push((from, hi, false));
    }
    if to - lo > tiny {
        out.push((lo, to, false));
    }
    if out.is_empty() {
        out.push((lo, hi, false));
    }
    if !forward {
        out.reverse();
        out.iter_mut().for_each(|r| r.2 = true);
    }
    Ok(out)
}

/// The exact pieces of one CAD curve, in space (`[x, y, z, w]` NURBS or points).
enum Spatial {
    Nurbs(Spline),
    Lines(Vec<[f64; 3]>),
    /// `centre + cos t·x + sin t·y` from `t0` to `t1`.
    Conic {
        centre: [f64; 3],
        x: [f64; 3],
        y: [f64; 3],
        t0: f64,
        t1: f64,
    },
}

fn pieces(c: &CadCurve) -> Result<Vec<Spatial>, StepError> {
    let trim = c.trim.as_ref();
    match &c.shape {
        Shape::BSpline {
            degree,
            knots,
            ctrl,
            // Not trusted: through the seam only where the ends meet.
            closed: _,
        } => {
            let whole = Spline {
                degree: *degree,
                knots: knots.clone(),
                ctrl: ctrl.clone(),
            };
            let (lo, hi) = whole.domain();
            let empty = || fail(c, "trim", "the piece is empty".into());
            let clamped = whole.piece(lo, hi).ok_or_else(empty)?;
            let closed = dist(clamped.at(lo), clamped.at(hi)) <= super::JOIN_MM;
            let (t0, t1) = match trim {
                None => (lo, hi),
                Some(t) => {
                    let on = OnCurve {
                        locate: &|q| clamped.nearest(q),
                        at: &|u: f64| clamped.at(u.clamp(lo, hi)),
                    };
                    (
                        trim_param(c, &t.start, t.by_point, "trim_1", &on)?,
                        trim_param(c, &t.end, t.by_point, "trim_2", &on)?,
                    )
                }
            };
            let rs = if trim.is_none() {
                vec![(lo, hi, !c.forward)]
            } else {
                ranges(c, (lo, hi), (t0, t1), c.forward, closed)?
            };
            rs.into_iter()
                .map(|(a, b, rev)| {
                    let s = clamped.piece(a, b).ok_or_else(empty)?;
                    Ok(Spatial::Nurbs(if rev { s.reversed() } else { s }))
                })
                .collect()
        }
        Shape::Conic { place, a, b } => {
            let col = |j: usize, s: f64| [0, 1, 2].map(|r| place.rot[r][j] * s);
            let (x, y) = (col(0, *a), col(1, *b));
            let centre = place.origin;
            let at = |t: f64| {
                let (s, co) = t.sin_cos();
                [0, 1, 2].map(|r| centre[r] + co * x[r] + s * y[r])
            };
            let (t0, t1) = match trim {
                None => (0.0, TAU),
                Some(t) => {
                    let locate = |q: [f64; 3]| {
                        let d = [0, 1, 2].map(|r| q[r] - centre[r]);
                        let dot = |v: [f64; 3]| d[0] * v[0] + d[1] * v[1] + d[2] * v[2];
                        let u = (dot(y) / (b * b)).atan2(dot(x) / (a * a));
                        (u, dist(at(u), q))
                    };
                    let on = OnCurve {
                        locate: &locate,
                        at: &at,
                    };
                    let t0 = trim_param(c, &t.start, t.by_point, "trim_1", &on)?;
                    let t1 = trim_param(c, &t.end, t.by_point, "trim_2", &on)?;
                    // The way round from t0 to t1 in the direction of travel, more than
                    // nothing and at most a whole turn (equal trims: a whole turn).
                    let tiny = 1e-12 * t0.abs().max(1.0);
                    let way = if c.forward { t1 - t0 } else { t0 - t1 };
                    let mut way = way.rem_euclid(TAU);
                    if way <= tiny || TAU - way <= tiny {
                        way = TAU;
                    }
                    (t0, if c.forward { t0 + way } else { t0 - way })
                }
            };
            let (t0, t1) = if trim.is_none() && !c.forward {
                (t1, t0)
            } else {
                (t0, t1)
            };
            Ok(vec![Spatial::Conic {
                centre,
                x,
                y,
                t0,
                t1,
            }])
        }
        Shape::Line { origin, dir } => {
            let at = |u: f64| [0, 1, 2].map(|r| origin[r] + u * dir[r]);
            let Some(t) = trim else {
                return Err(fail(c, "curve", "a LINE is infinite: trim it".into()));
            };
            let l2 = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
            let locate = |q: [f64; 3]| {
                let u = [0, 1, 2]
                    .iter()
                    .map(|&r| (q[r] - origin[r]) * dir[r])
                    .sum::<f64>()
                    / l2;
                (u, dist(at(u), q))
            };
            let on = OnCurve {
                locate: &locate,
                at: &at,
            };
            let u0 = trim_param(c, &t.start, t.by_point, "trim_1", &on)?;
            let u1 = trim_param(c, &t.end, t.by_point, "trim_2", &on)?;
            if dist(at(u0), at(u1)).is_nan() || dist(at(u0), at(u1)) == 0.0 {
                return Err(fail(
                    c,
                    "trim",
                    "trim_1 and trim_2 are the same point".into(),
                ));
            }
            Ok(vec![Spatial::Lines(vec![at(u0), at(u1)])])
        }
        Shape::Polyline(pts) => {
            let mut pts = pts.clone();
            if !c.forward {
                pts.reverse();
            }
            Ok(vec![Spatial::Lines(pts)])
        }
    }
}

/// The Z range of a piece's points (for a conic: of the plane it spans).
fn z_range(s: &Spatial) -> (f64, f64) {
    let mut r = (f64::INFINITY, f64::NEG_INFINITY);
    let mut add = |z: f64| r = (r.0.min(z), r.1.max(z));
    match s {
        Spatial::Nurbs(n) => n.ctrl.iter().for_each(|p| add(p[2])),
        Spatial::Lines(p) => p.iter().for_each(|p| add(p[2])),
        Spatial::Conic { centre, x, y, .. } => {
            let e = x[2].hypot(y[2]);
            add(centre[2] - e);
            add(centre[2] + e);
        }
    }
    r
}

/// The piece in XY (dropping Z: the projection, exact for a NURBS), its weights scaled
/// to a geometric mean of 1.
fn flat(c: &CadCurve, s: Spatial) -> Result<Piece, StepError> {
    Ok(match s {
        Spatial::Lines(p) => Piece::Lines(p.iter().map(|q| [q[0], q[1]]).collect()),
        Spatial::Conic {
            centre,
            x,
            y,
            t0,
            t1,
        } => Piece::Nurbs(conic_arc(
            [centre[0], centre[1]],
            [x[0], x[1]],
            [y[0], y[1]],
            t0,
            t1,
        )),
        Spatial::Nurbs(n) => {
            let (lo, hi) = n.ctrl.iter().fold((f64::INFINITY, 0.0f64), |(l, h), p| {
                (l.min(p[3]), h.max(p[3]))
            });
            // (A hair inside the interpreter's 1e6, so that the scaled weights' roundings
            // stay within its 1e-3 to 1e3.)
            if hi.is_nan() || hi > 0.999e6 * lo {
                return Err(fail(
                    c,
                    "weights",
                    format!(
                        "its weights run from {lo} to {hi}, more than 1e6 apart; the program's weights must lie from 1e-3 to 1e3"
                    ),
                ));
            }
            let scale = if lo == 1.0 && hi == 1.0 {
                1.0
            } else {
                1.0 / (lo * hi).sqrt()
            };
            Piece::Nurbs(Curve {
                degree: n.degree,
                knots: n.knots,
                ctrl: n.ctrl.iter().map(|p| [p[0], p[1], p[3] * scale]).collect(),
            })
        }
    })
}

/// The cuts of `curves` for `job`, or every curve's error.
pub fn cuts(curves: &CadCurves, job: &CurvesJob) -> Result<Vec<Cut>, Vec<StepError>> {
    let mut out = Vec::new();
    let mut errs = Vec::new();
    let mut plane: Option<(f64, &CadCurve)> = None;
    for c in &curves.curves {
        let ps = match pieces(c) {
            Ok(p) => p,
            Err(e) => {
                errs.push(e);
                continue;
            }
        };
        let mut note =
            Some(format!("#{} {}, line {}", c.id, c.entity, c.line).replace(['(', ')'], ""));
        for s in ps {
            let (zl, zh) = z_range(&s);
            if !job.project {
                if zh - zl > FLAT_MM {
                    errs.push(fail(
                        c,
                        "plane",
                        format!(
                            "the curve leaves the XY plane (Z from {zl} to {zh} mm); cnc cam curves cuts a profile at --depth: give --project to cut its projection onto XY"
                        ),
                    ));
                    break;
                }
                match plane {
                    Some((z, first)) if (z - zl).abs() > FLAT_MM => {
                        errs.push(fail(
                            c,
                            "plane",
                            format!(
                                "the curve lies at Z {zl} mm, #{} (line {}) at Z {z} mm; cnc cam curves cuts one profile at --depth: give --project to cut both",
                                first.id, first.line
                            ),
                        ));
                        break;
                    }
                    Some(_) => {}
                    None => plane = Some((zl, c)),
                }
            }
            match flat(c, s) {
                Ok(piece) => out.push(Cut {
                    note: note.take(),
                    piece,
                }),
                Err(e) => {
                    errs.push(e);
                    break;
                }
            }
        }
    }
    if errs.is_empty() {
        Ok(out)
    } else {
        errs.dedup();
        Err(errs)
    }
}

/// The program cutting the curves of the STEP file `text` (named `file` in messages),
/// and a line for the user on what was written; or every error, one a line.
pub fn curves_program(text: &str, file: &str, job: &CurvesJob) -> Result<(String, String), String> {
    if !(job.cut.feed.is_finite() && job.cut.feed > 0.0) {
        return Err("--feed must be a positive number".into());
    }
    if !job.cut.depth.is_finite() {
        return Err("--depth must be a finite number".into());
    }
    let curves =
        crate::step::curves::read_curves(text).map_err(|e| crate::step::format_errors(file, &e))?;
    let cuts = cuts(&curves, job).map_err(|e| crate::step::format_errors(file, &e))?;
    let (mut g5_2, mut g6_2, mut lines) = (0, 0, 0);
    for c in &cuts {
        match &c.piece {
            Piece::Nurbs(n) if !job.cut.fanuc && g5_2_knots(n) => g5_2 += 1,
            Piece::Nurbs(_) => g6_2 += 1,
            Piece::Lines(_) => lines += 1,
        }
    }
    let nurbs = if job.cut.fanuc {
        format!("{g6_2} as G06.2")
    } else {
        format!("{g5_2} as G5.2, {g6_2} as G6.2")
    };
    let edges = if curves.edges > 0 {
        format!(
            "; the file's {} EDGE_CURVEs (a solid's edges) are not cut",
            curves.edges
        )
    } else {
        String::new()
    };
    let summary = format!(
        "{} curves of {file}: {nurbs}, {lines} as straight moves{edges}",
        curves.curves.len()
    );
    // (A parenthesis in the file's name would close the comment it is written in.)
    let what = format!("{summary}\nwritten by cnc cam curves").replace(['(', ')'], "");
    Ok((program(&job.cut, &what, &cuts), summary))
}
