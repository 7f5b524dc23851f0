//! `cnc cam`: part programs of exact NURBS moves from geometry, the step before the
//! control (seeds 002 and 004).
//!
//! * [`ellipse`]: an ellipse as an exact rational quadratic NURBS, or its offset fitted
//!   within a tolerance (seed 004, `cnc cam ellipse`).
//! * [`curves`]: the curves of a CAD STEP file, each written as the NURBS move that is
//!   the curve itself (seed 002's CAD export, `cnc cam curves`).
//!
//! Both write through [`program`]: a header saying what was written, the tool down to
//! the depth at each start that does not continue the cut before, each curve as
//! LinuxCNC's `G5.2` when its knots are the clamped uniform ones `G5.2` implies, `G6.2`
//! with its `K` knots and `R` weights otherwise, or Fanuc's `G06.2`. Numbers are printed
//! so that they read back as the same doubles, so the program holds the curve itself.

pub mod curves;
pub mod ellipse;

pub use ellipse::{ellipse_program, EllipseJob};

use std::fmt::Write as _;

/// A NURBS in the XY plane: degree, knots, control points `[x, y, w]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Curve {
    pub degree: usize,
    pub knots: Vec<f64>,
    pub ctrl: Vec<[f64; 3]>,
}

/// Clamped uniform knots for `n` control points of `degree` on `[0, 1, …]` (LinuxCNC's
/// `G5.2` knots).
fn uniform_knots(degree: usize, n: usize) -> Vec<f64> {
    let spans = n - degree;
    (0..n + degree + 1)
        .map(|i| (i as f64 - degree as f64).clamp(0.0, spans as f64))
        .collect()
}

/// The curve's point at `u`.
fn point(c: &Curve, u: f64) -> [f64; 2] {
    let ctrl: Vec<[f64; 4]> = c.ctrl.iter().map(|p| [p[0], p[1], 0.0, p[2]]).collect();
    let e = shared::nurbs::eval(c.degree, &c.knots, &ctrl, u);
    [e.p[0], e.p[1]]
}

/// The arc `centre + cos t·x + sin t·y` for `t` from `t0` to `t1` (either way round; `x`
/// and `y` need not be square or of one length, so this is an elliptic arc as well) as
/// an exact rational quadratic NURBS: equal pieces of at most a quarter turn, each with
/// its middle control point where the piece's end tangents meet, weighted by the cosine
/// of half the piece's angle; knots `0 0 0 1 1 2 2 … n n n`.
fn conic_arc(centre: [f64; 2], x: [f64; 2], y: [f64; 2], t0: f64, t1: f64) -> Curve {
    let sweep = t1 - t0;
    let n = ((sweep.abs() / std::f64::consts::FRAC_PI_2 - 1e-9).ceil() as usize).max(1);
    let half = sweep / n as f64 / 2.0;
    let at = |t: f64, r: f64| {
        let (s, c) = t.sin_cos();
        [
            centre[0] + r * (c * x[0] + s * y[0]),
            centre[1] + r * (c * x[1] + s * y[1]),
        ]
    };
    let w = half.cos();
    let mut ctrl = Vec::with_capacity(2 * n + 1);
    let p = at(t0, 1.0);
    ctrl.push([p[0], p[1], 1.0]);
    let mut knots = vec![0.0; 3];
    for i in 0..n {
        let mid = t0 + (2 * i + 1) as f64 * half;
        let end = if i + 1 == n {
            t1
        } else {
            t0 + (2 * i + 2) as f64 * half
        };
        let m = at(mid, 1.0 / w);
        let e = at(end, 1.0);
        ctrl.push([m[0], m[1], w]);
        ctrl.push([e[0], e[1], 1.0]);
        let k = (i + 1) as f64;
        let times = if i + 1 == n { 3 } else { 2 };
        knots.extend(std::iter::repeat_n(k, times));
    }
    Curve {
        degree: 2,
        knots,
        ctrl,
    }
}

/// How a program cuts: feed, the depth of the cut, the dialect.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// mm/min.
    pub feed: f64,
    /// Z of the cut; the tool comes down from `depth + 5` and goes back there.
    pub depth: f64,
    pub fanuc: bool,
}

/// One move of a cut.
#[derive(Debug, Clone, PartialEq)]
pub enum Piece {
    Nurbs(Curve),
    /// Straight moves through the points, the first being where it starts.
    Lines(Vec<[f64; 2]>),
}

impl Piece {
    fn start(&self) -> [f64; 2] {
        match self {
            Piece::Nurbs(c) => [c.ctrl[0][0], c.ctrl[0][1]],
            Piece::Lines(p) => p[0],
        }
    }
    fn end(&self) -> [f64; 2] {
        match self {
            Piece::Nurbs(c) => {
                let p = c.ctrl[c.ctrl.len() - 1];
                [p[0], p[1]]
            }
            Piece::Lines(p) => p[p.len() - 1],
        }
    }
}

/// A piece with the comment written before it.
#[derive(Debug, Clone, PartialEq)]
pub struct Cut {
    pub note: Option<String>,
    pub piece: Piece,
}

impl Cut {
    pub fn whole(c: Curve) -> Cut {
        Cut {
            note: None,
            piece: Piece::Nurbs(c),
        }
    }
}

/// Ends closer than this are one point: the cut goes on without lifting, over a short
/// straight move where they are not the same point (a CAD model's curves meet within its
/// modelling tolerance, commonly 1e-6 m).
pub const JOIN_MM: f64 = 1e-3;

/// A number as it reads back to the same double, in the plain decimals a G-code word
/// takes (no exponent).
fn num(v: f64) -> String {
    let v = if v == 0.0 { 0.0 } else { v };
    let s = format!("{v:?}");
    if !s.contains('e') {
        return s;
    }
    let s = format!("{v:.30}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Whether `c`'s knots are the clamped uniform ones LinuxCNC's `G5.2` gives a curve of its
/// order and count (up to scale and shift, which leave the curve as it is; to a relative
/// 1e-13, the rounding of a CAD system's printed knots). `G5.2` takes orders 3 to 10.
fn g5_2_knots(c: &Curve) -> bool {
    let (p, n) = (c.degree, c.ctrl.len());
    let k = &c.knots;
    let (a, b) = (k[0], k[k.len() - 1]);
    let h = (b - a) / (n - p) as f64;
    (2..=9).contains(&p)
        && b > a
        && uniform_knots(p, n)
            .iter()
            .zip(k)
            .all(|(u, k)| (a + u * h - k).abs() <= 1e-13 * (b - a))
}

/// Writes `c` as a NURBS move from where the tool is (its first control point).
fn write_nurbs(s: &mut String, c: &Curve, fanuc: bool) {
    let order = c.degree + 1;
    if fanuc {
        for (i, p) in c.ctrl.iter().enumerate() {
            let head = if i == 0 {
                format!("G06.2 P{order} ")
            } else {
                String::new()
            };
            let (k, x, y, w) = (num(c.knots[i]), num(p[0]), num(p[1]), num(p[2]));
            writeln!(s, "{head}K{k} X{x} Y{y} R{w}").unwrap();
        }
        for k in &c.knots[c.ctrl.len()..] {
            writeln!(s, "K{}", num(*k)).unwrap();
        }
    } else if g5_2_knots(c) {
        // LinuxCNC's G5.2: the current position is the first control point; its weight,
        // when not 1, on a line of its own.
        let w0 = c.ctrl[0][2];
        if w0 != 1.0 {
            writeln!(s, "G5.2 P{} L{order}", num(w0)).unwrap();
        }
        for (i, p) in c.ctrl.iter().enumerate().skip(1) {
            let head = if i == 1 && w0 == 1.0 {
                format!("G5.2 L{order} ")
            } else {
                String::new()
            };
            writeln!(s, "{head}X{} Y{} P{}", num(p[0]), num(p[1]), num(p[2])).unwrap();
        }
        writeln!(s, "G5.3").unwrap();
    } else {
        for (i, p) in c.ctrl.iter().enumerate() {
            let head = if i == 0 { "G6.2 " } else { "" };
            let tail = if i == 0 {
                format!(" P{order} Q1")
            } else {
                String::new()
            };
            let (x, y, w, k) = (num(p[0]), num(p[1]), num(p[2]), num(c.knots[i]));
            writeln!(s, "{head}X{x} Y{y} R{w} K{k}{tail}").unwrap();
        }
        for k in &c.knots[c.ctrl.len()..] {
            writeln!(s, "G6.2 K{}", num(*k)).unwrap();
        }
    }
}

/// The part program cutting `cuts` in order at `job`'s depth and feed, with a header
/// saying what it is (`what`). The tool goes down at the first cut's start and stays
/// down while each cut starts where the one before ended (within [`JOIN_MM`]); between
/// others it goes up to `depth + 5`, across at rapid, and down again.
pub fn program(job: &Job, what: &str, cuts: &[Cut]) -> String {
    let mut s = String::new();
    let safe = num(job.depth + 5.0);
    for line in what.lines() {
        writeln!(s, "({line})").unwrap();
    }
    if job.fanuc {
        writeln!(s, "G21 G17 G90 G94").unwrap();
    } else {
        writeln!(s, "G21 G17 G90 G94 G40").unwrap();
    }
    writeln!(s, "G0 Z{safe}").unwrap();
    let mut at: Option<[f64; 2]> = None;
    for cut in cuts {
        if let Some(note) = &cut.note {
            writeln!(s, "({note})").unwrap();
        }
        let start = cut.piece.start();
        match at {
            // Ends a nanometre apart are one point: the curve starts where the tool is.
            Some(p) if (p[0] - start[0]).hypot(p[1] - start[1]) <= 1e-6 * JOIN_MM => {}
            Some(p) if (p[0] - start[0]).hypot(p[1] - start[1]) <= JOIN_MM => {
                writeln!(s, "G1 X{} Y{}", num(start[0]), num(start[1])).unwrap();
            }
            _ => {
                if at.is_some() {
                    writeln!(s, "G0 Z{safe}").unwrap();
                }
                writeln!(s, "G0 X{} Y{}", num(start[0]), num(start[1])).unwrap();
                writeln!(s, "G1 Z{} F{}", num(job.depth), num(job.feed)).unwrap();
            }
        }
        match &cut.piece {
            Piece::Nurbs(c) => write_nurbs(&mut s, c, job.fanuc),
            Piece::Lines(pts) => {
                for p in &pts[1..] {
                    writeln!(s, "G1 X{} Y{}", num(p[0]), num(p[1])).unwrap();
                }
            }
        }
        at = Some(cut.piece.end());
    }
    let up = if job.fanuc { "G00" } else { "G0" };
    writeln!(s, "{up} Z{safe}").unwrap();
    writeln!(s, "M2").unwrap();
    s
}
