//! From lines of words to moves: the modal state machine of RS274/NGC (the subset this
//! stack runs so far) and LinuxCNC's G5.2/G5.3 NURBS. Positions are in mm whatever the
//! program's units; the machine starts at the origin.
//!
//! Every problem found is collected with its line and column; the whole program is read
//! even after an error, so `cnc check` can report everything at once.
//!
//! Parameters are set after their whole line is read, as LinuxCNC does. O-word
//! subroutines (`sub`/`endsub`/`call`/`return`) and control flow (`if`/`elseif`/`else`,
//! `while`, `do … while`, `repeat`, `break`, `continue`) run within the one file: lines
//! are read again, with the parameters of the moment, each time the flow reaches them.

mod flow;

use crate::parse::{flow, o_word_of, read_line, Diagnostic, OWord, Params, Word};
use flow::Runner;

/// The plane of arcs and NURBS, by the axis normal to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    XY,
    ZX,
    YZ,
}

impl Plane {
    /// Axis normal to the plane (0 X, 1 Y, 2 Z).
    pub fn normal(self) -> usize {
        match self {
            Plane::XY => 2,
            Plane::ZX => 1,
            Plane::YZ => 0,
        }
    }
    /// The two in-plane axes, ordered so that (first × second) points along the normal.
    pub fn axes(self) -> (usize, usize) {
        let n = self.normal();
        ((n + 1) % 3, (n + 2) % 3)
    }
}

/// One thing the machine does, in mm and mm/min.
#[derive(Debug, Clone, PartialEq)]
pub enum Move {
    Line {
        line: u32,
        from: [f64; 3],
        to: [f64; 3],
        rapid: bool,
        feed: f64,
    },
    Arc {
        line: u32,
        from: [f64; 3],
        to: [f64; 3],
        center: [f64; 3],
        plane: Plane,
        ccw: bool,
        turns: u32,
        feed: f64,
    },
    Nurbs {
        line: u32,
        degree: usize,
        knots: Vec<f64>,
        ctrl: Vec<[f64; 4]>,
        feed: f64,
    },
    Dwell {
        line: u32,
        seconds: f64,
    },
    End {
        line: u32,
    },
}

/// A whole program, read and checked.
#[derive(Debug, Clone, Default)]
pub struct Program {
    pub moves: Vec<Move>,
    /// `(MSG, …)` texts with their lines.
    pub messages: Vec<(u32, String)>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    None,
    Rapid,
    Linear,
    Arc { ccw: bool },
}

/// Points of an open G5.2 block.
struct NurbsOpen {
    line: u32,
    col: u32,
    order: usize,
    ctrl: Vec<[f64; 4]>,
}

/// An open G6.2 NURBS: control points with their knots, then the closing knots.
struct G62Open {
    line: u32,
    col: u32,
    order: usize,
    ctrl: Vec<[f64; 4]>,
    knots: Vec<f64>,
    /// Knot-only lines seen so far; `order` of them close the curve.
    closing: usize,
}

struct State {
    pos: [f64; 3],
    g62: Option<G62Open>,
    motion: Motion,
    plane: Plane,
    inch: bool,
    absolute: bool,
    arc_absolute: bool,
    feed: f64,
    nurbs: Option<NurbsOpen>,
    ended: bool,
}

/// Radius mismatch LinuxCNC accepts between the start and end of a centre-format arc.
const ARC_RADIUS_TOL_MM: f64 = 0.002;
const ARC_RADIUS_TOL_REL: f64 = 0.001;

const AXES: [char; 3] = ['X', 'Y', 'Z'];
const OFFSETS: [char; 3] = ['I', 'J', 'K'];

struct LineWords<'a> {
    words: &'a [Word],
    line: u32,
}

impl LineWords<'_> {
    fn get(&self, letter: char) -> Option<&Word> {
        self.words.iter().find(|w| w.letter == letter)
    }
    fn value(&self, letter: char) -> Option<f64> {
        self.get(letter).map(|w| w.value)
    }
    fn err(&self, col: u32, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            line: self.line,
            col,
            message: message.into(),
        }
    }
}

/// Reads and checks a whole program. All problems are returned, not only the first.
///
/// O-word subroutines and control flow run as LinuxCNC runs them, within this file:
/// a `sub … endsub` is skipped where it stands and entered by `call`, conditions are
/// evaluated when their line is reached, and a line is read again (with the parameters
/// of that moment) each time the flow comes back to it.
pub fn interpret(text: &str) -> Result<Program, Vec<Diagnostic>> {
    let mut st = State {
        pos: [0.0; 3],
        g62: None,
        motion: Motion::None,
        plane: Plane::XY,
        inch: false,
        absolute: true,
        arc_absolute: false,
        feed: 0.0,
        nurbs: None,
        ended: false,
    };
    let mut params = Params::default();
    let mut prog = Program::default();
    let mut errors = Vec::new();
    let lines: Vec<&str> = text.lines().collect();
    let o_words: Vec<Option<OWord>> = lines
        .iter()
        .enumerate()
        .map(|(i, raw)| o_word_of(raw, i as u32 + 1).unwrap_or(None))
        .collect();
    let (flow, flow_errors) = flow(&o_words);
    errors.extend(flow_errors);
    let mut run = Runner::new(o_words, flow);
    let last_line = lines.len() as u32;
    let mut pc = 0;
    while pc < lines.len() {
        let line = pc as u32 + 1;
        if st.ended {
            break; // LinuxCNC ignores everything after M2/M30.
        }
        let here = pc;
        pc += 1;
        let parsed = match read_line(lines[here], line, &params) {
            Ok(l) => l,
            Err(d) => {
                errors.push(d);
                pc = run.unreadable(here);
                continue;
            }
        };
        for m in &parsed.messages {
            prog.messages.push((line, m.clone()));
        }
        if let Some(o) = &parsed.o_word {
            match run.step(here, o, &mut params, &mut errors) {
                Some(next) => pc = next,
                None => break,
            }
            continue;
        }
        if let Err(d) = execute(
            &mut st,
            &LineWords {
                words: &parsed.words,
                line,
            },
            &mut prog.moves,
        ) {
            errors.push(d);
        }
        for (p, v) in &parsed.assignments {
            params.set(p, *v);
        }
    }
    // A line read again and again (in a loop) reports its problem once.
    let mut seen = std::collections::HashSet::new();
    errors.retain(|d: &Diagnostic| seen.insert((d.line, d.col, d.message.clone())));
    if let Some(n) = &st.g62 {
        errors.push(Diagnostic {
            line: n.line,
            col: n.col,
            message: format!(
                "G6.2 NURBS is never closed: {} knot-only `G6.2 K…` lines of {} follow its control points",
                n.closing, n.order
            ),
        });
    }
    if let Some(n) = &st.nurbs {
        errors.push(Diagnostic {
            line: n.line,
            col: n.col,
            message: "G5.2 NURBS is never closed with G5.3".into(),
        });
    }
    if !st.ended {
        prog.moves.push(Move::End { line: last_line });
    }
    if errors.is_empty() {
        Ok(prog)
    } else {
        Err(errors)
    }
}

fn gcode(w: &Word) -> Option<u32> {
    let tenths = (w.value * 10.0).round();
    ((tenths - w.value * 10.0).abs() < 1e-6 && tenths >= 0.0).then_some(tenths as u32)
}

fn execute(st: &mut State, lw: &LineWords, moves: &mut Vec<Move>) -> Result<(), Diagnostic> {
    // One value per letter (G and M may repeat, for different groups).
    for (i, w) in lw.words.iter().enumerate() {
        if w.letter != 'G' && w.letter != 'M' && lw.words[..i].iter().any(|o| o.letter == w.letter)
        {
            return Err(lw.err(
                w.col,
                format!("{} word appears twice on one line", w.letter),
            ));
        }
        match w.letter {
            'G' | 'M' | 'X' | 'Y' | 'Z' | 'I' | 'J' | 'K' | 'R' | 'F' | 'P' | 'L' | 'N' | 'S'
            | 'T' | 'Q' => {}
            'A' | 'B' | 'C' | 'U' | 'V' | 'W' => {
                return Err(lw.err(
                    w.col,
                    format!("{} axis: this machine has only X, Y and Z", w.letter),
                ))
            }
            c => return Err(lw.err(w.col, format!("{c} word is not supported"))),
        }
    }
    let mut motion_word: Option<(&Word, Motion)> = None;
    let mut nurbs_open: Option<&Word> = None;
    let mut nurbs_close: Option<&Word> = None;
    let mut g62_word: Option<&Word> = None;
    let mut dwell: Option<&Word> = None;
    let mut groups: Vec<(u8, &Word)> = Vec::new();
    for w in lw.words.iter().filter(|w| w.letter == 'G') {
        let code =
            gcode(w).ok_or_else(|| lw.err(w.col, format!("G{} is not a G-code", w.value)))?;
        let group = match code {
            0 | 10 | 20 | 30 | 52 | 53 | 62 | 800 => 1,
            40 => 0,
            170 | 180 | 190 => 2,
            200 | 210 => 6,
            900 | 910 => 3,
            901 | 911 => 4,
            930 | 940 => 5,
            400 => 7,
            490 => 8,
            540..=590 => 12,
            610 | 611 | 640 => 13,
            960 | 970 => 14,
            _ => return Err(lw.err(w.col, format!("G{} is not supported", w.value))),
        };
        if let Some((_, other)) = groups.iter().find(|(g, _)| *g == group && group != 0) {
            return Err(lw.err(
                w.col,
                format!(
                    "G{} and G{} are in the same modal group",
                    other.value, w.value
                ),
            ));
        }
        groups.push((group, w));
        match code {
            0 => motion_word = Some((w, Motion::Rapid)),
            10 => motion_word = Some((w, Motion::Linear)),
            20 => motion_word = Some((w, Motion::Arc { ccw: false })),
            30 => motion_word = Some((w, Motion::Arc { ccw: true })),
            52 => nurbs_open = Some(w),
            53 => nurbs_close = Some(w),
            62 => g62_word = Some(w),
            800 => motion_word = Some((w, Motion::None)),
            40 => dwell = Some(w),
            170 => st.plane = Plane::XY,
            180 => st.plane = Plane::ZX,
            190 => st.plane = Plane::YZ,
            200 => st.inch = true,
            210 => st.inch = false,
            900 => st.absolute = true,
            910 => st.absolute = false,
            901 => st.arc_absolute = true,
            911 => st.arc_absolute = false,
            940 => {}
            930 => return Err(lw.err(w.col, "G93 inverse-time feed is not supported yet")),
            _ => {} // G40, G49, G54..G59 (zero offsets), G61/G61.1/G64: accepted, no effect yet
        }
    }
    // G20/G21 on this line already apply to its own numbers.
    let unit = if st.inch { 25.4 } else { 1.0 };
    if let Some(f) = lw.get('F') {
        if f.value < 0.0 {
            return Err(lw.err(f.col, "F must not be negative"));
        }
        st.feed = f.value * unit;
    }
    let mut end = false;
    for w in lw.words.iter().filter(|w| w.letter == 'M') {
        match gcode(w) {
            Some(20) | Some(300) => end = true,
            // stops, spindle, tool change, coolant: accepted, carried in a later version
            Some(0 | 10 | 30 | 40 | 50 | 60 | 70 | 80 | 90) => {}
            _ => return Err(lw.err(w.col, format!("M{} is not supported", w.value))),
        }
    }

    // G6.2: control points with their knots, then `order` knot-only lines close it.
    if st.g62.is_some() || g62_word.is_some() {
        return g62_line(st, lw, g62_word, motion_word.map(|m| m.0), unit, moves, end);
    }
    // Inside an open G5.2 block every line is a control point (or the G5.3 that closes it).
    if st.nurbs.is_some() || nurbs_open.is_some() {
        return nurbs_line(
            st,
            lw,
            nurbs_open,
            nurbs_close,
            motion_word.map(|m| m.0),
            unit,
            moves,
            end,
        );
    }
    if let Some(w) = nurbs_close {
        return Err(lw.err(w.col, "G5.3 without an open G5.2 NURBS"));
    }
    if let Some(w) = dwell {
        let p = lw
            .value('P')
            .ok_or_else(|| lw.err(w.col, "G4 dwell needs P (seconds)"))?;
        if p < 0.0 {
            return Err(lw.err(w.col, "G4 dwell time P must not be negative"));
        }
        moves.push(Move::Dwell {
            line: lw.line,
            seconds: p,
        });
    }
    if let Some((_, m)) = motion_word {
        st.motion = m;
    }
    let has_axis = AXES.iter().any(|a| lw.get(*a).is_some());
    if has_axis && dwell.is_none() {
        let target = target(st, lw, unit);
        let col = motion_word
            .map(|m| m.0.col)
            .or_else(|| lw.words.first().map(|w| w.col))
            .unwrap_or(1);
        match st.motion {
            Motion::None => {
                return Err(lw.err(col, "axis words without an active motion (G0, G1, G2, G3)"))
            }
            Motion::Rapid => push_line(moves, lw.line, st.pos, target, true, 0.0),
            Motion::Linear => {
                need_feed(st, lw, col)?;
                push_line(moves, lw.line, st.pos, target, false, st.feed)
            }
            Motion::Arc { ccw } => {
                need_feed(st, lw, col)?;
                moves.push(arc(st, lw, target, ccw, unit, col)?);
            }
        }
        st.pos = target;
    } else if let Some((w, Motion::Arc { .. } | Motion::Linear | Motion::Rapid)) = motion_word {
        if lw
            .words
            .iter()
            .any(|w| matches!(w.letter, 'I' | 'J' | 'K' | 'R'))
        {
            return Err(lw.err(w.col, "arc without any axis word for its end point"));
        }
    }
    if end {
        moves.push(Move::End { line: lw.line });
        st.ended = true;
    }
    Ok(())
}

fn need_feed(st: &State, lw: &LineWords, col: u32) -> Result<(), Diagnostic> {
    if st.feed <= 0.0 {
        return Err(lw.err(
            col,
            "feed move with no feed rate: program F before (or on) this line",
        ));
    }
    Ok(())
}

fn target(st: &State, lw: &LineWords, unit: f64) -> [f64; 3] {
    core::array::from_fn(|i| match lw.value(AXES[i]) {
        Some(v) if st.absolute => v * unit,
        Some(v) => st.pos[i] + v * unit,
        None => st.pos[i],
    })
}

fn push_line(
    moves: &mut Vec<Move>,
    line: u32,
    from: [f64; 3],
    to: [f64; 3],
    rapid: bool,
    feed: f64,
) {
    if from != to {
        moves.push(Move::Line {
            line,
            from,
            to,
            rapid,
            feed,
        });
    }
}

fn arc(
    st: &State,
    lw: &LineWords,
    to: [f64; 3],
    ccw: bool,
    unit: f64,
    col: u32,
) -> Result<Move, Diagnostic> {
    let (a, b) = st.plane.axes();
    let n = st.plane.normal();
    let from = st.pos;
    if let Some(w) = lw.get(OFFSETS[n]) {
        return Err(lw.err(
            w.col,
            format!(
                "{} offset given for an arc in the {:?} plane",
                OFFSETS[n], st.plane
            ),
        ));
    }
    let turns = match lw.get('P') {
        None => 1,
        Some(p) if p.value >= 1.0 && p.value.fract() == 0.0 => p.value as u32,
        Some(p) => return Err(lw.err(p.col, "arc turn count P must be a positive integer")),
    };
    let (da, db) = (to[a] - from[a], to[b] - from[b]);
    let chord = (da * da + db * db).sqrt();
    let mut center = [0.0; 3];
    center[n] = from[n];
    if let Some(rw) = lw.get('R') {
        if lw.get(OFFSETS[a]).is_some() || lw.get(OFFSETS[b]).is_some() {
            return Err(lw.err(rw.col, "arc has both R and centre offsets; give one form"));
        }
        let r = rw.value * unit;
        if chord < 1e-9 {
            return Err(lw.err(rw.col, "R-form arc with its end at its start: a full circle needs the centre form (I, J, K)"));
        }
        let half = chord / 2.0;
        if r.abs() < half - ARC_RADIUS_TOL_MM {
            return Err(lw.err(
                rw.col,
                format!(
                    "arc radius {:.4} mm is too small to reach an end point {:.4} mm away",
                    r.abs(),
                    chord
                ),
            ));
        }
        let h = (r * r - half * half).max(0.0).sqrt();
        // Centre on the left of the chord for a short counter-clockwise arc; R < 0 asks
        // for the long way round, which puts it on the other side.
        let side = if ccw { 1.0 } else { -1.0 } * r.signum();
        let (ua, ub) = (da / chord, db / chord);
        center[a] = from[a] + da / 2.0 - side * h * ub;
        center[b] = from[b] + db / 2.0 + side * h * ua;
    } else {
        let (ia, ib) = (lw.value(OFFSETS[a]), lw.value(OFFSETS[b]));
        if ia.is_none() && ib.is_none() {
            return Err(lw.err(
                col,
                format!(
                    "arc needs R or a centre ({} and {})",
                    OFFSETS[a], OFFSETS[b]
                ),
            ));
        }
        let (ia, ib) = (ia.unwrap_or(0.0) * unit, ib.unwrap_or(0.0) * unit);
        let (ca, cb) = if st.arc_absolute {
            (ia, ib)
        } else {
            (from[a] + ia, from[b] + ib)
        };
        let r0 = ((from[a] - ca).powi(2) + (from[b] - cb).powi(2)).sqrt();
        let r1 = ((to[a] - ca).powi(2) + (to[b] - cb).powi(2)).sqrt();
        if r0 < 1e-9 {
            return Err(lw.err(col, "arc centre coincides with its start point"));
        }
        let diff = (r1 - r0).abs();
        if diff > ARC_RADIUS_TOL_MM && diff > ARC_RADIUS_TOL_REL * r0 {
            return Err(lw.err(
                col,
                format!("radius to the end of the arc ({r1:.4} mm) differs from the radius to its start ({r0:.4} mm)"),
            ));
        }
        if chord < 1e-9 {
            center[a] = ca;
            center[b] = cb;
        } else {
            // Within tolerance: move the centre to the nearest point of the chord's
            // bisector, so the exact circle passes through both programmed end points.
            let (ma, mb) = (from[a] + da / 2.0, from[b] + db / 2.0);
            let (na, nb) = (-db / chord, da / chord);
            let t = (ca - ma) * na + (cb - mb) * nb;
            center[a] = ma + t * na;
            center[b] = mb + t * nb;
        }
    }
    Ok(Move::Arc {
        line: lw.line,
        from,
        to,
        center,
        plane: st.plane,
        ccw,
        turns,
        feed: st.feed,
    })
}

#[allow(clippy::too_many_arguments)]
fn nurbs_line(
    st: &mut State,
    lw: &LineWords,
    open: Option<&Word>,
    close: Option<&Word>,
    motion: Option<&Word>,
    unit: f64,
    moves: &mut Vec<Move>,
    end: bool,
) -> Result<(), Diagnostic> {
    let (a, b) = st.plane.axes();
    if let Some(m) = motion {
        return Err(lw.err(
            m.col,
            format!("G{} inside a G5.2 NURBS: close it with G5.3 first", m.value),
        ));
    }
    if end {
        let col = lw
            .words
            .iter()
            .find(|w| w.letter == 'M')
            .map(|w| w.col)
            .unwrap_or(1);
        return Err(lw.err(
            col,
            "program end inside a G5.2 NURBS: close it with G5.3 first",
        ));
    }
    if let Some(w) = open {
        if st.nurbs.is_some() {
            return Err(lw.err(w.col, "G5.2 inside an open G5.2 NURBS"));
        }
        need_feed(st, lw, w.col)?;
        let order = match lw.get('L') {
            None => 3,
            Some(l) if l.value.fract() == 0.0 && l.value >= 2.0 && l.value <= 10.0 => {
                (l.value as usize).max(3)
            }
            Some(l) => return Err(lw.err(l.col, "NURBS order L must be an integer from 2 to 10")),
        };
        let has_point = lw.get(AXES[a]).is_some() || lw.get(AXES[b]).is_some();
        // `G5.2 P.. L..` alone: P is the weight of the first control point (the current
        // position); with coordinates, the line is already the second control point.
        let w0 = match (has_point, lw.get('P')) {
            (false, Some(p)) => p.value,
            _ => 1.0,
        };
        if w0 <= 0.0 {
            return Err(lw.err(
                lw.get('P').map(|p| p.col).unwrap_or(w.col),
                "weight P must be > 0",
            ));
        }
        let p = st.pos;
        st.nurbs = Some(NurbsOpen {
            line: lw.line,
            col: w.col,
            order,
            ctrl: vec![[p[0], p[1], p[2], w0]],
        });
        if !has_point {
            return Ok(());
        }
    }
    let has_a = lw.get(AXES[a]);
    let has_b = lw.get(AXES[b]);
    let normal = st.plane.normal();
    if let Some(w) = lw.get(AXES[normal]) {
        return Err(lw.err(
            w.col,
            format!(
                "{} is not a word of the NURBS plane {:?}",
                AXES[normal], st.plane
            ),
        ));
    }
    match (has_a, has_b) {
        (Some(_), Some(_)) => {
            let p = lw.get('P').ok_or_else(|| {
                lw.err(
                    lw.words[0].col,
                    "every NURBS control point needs its weight P",
                )
            })?;
            if p.value <= 0.0 {
                return Err(lw.err(p.col, "weight P must be > 0"));
            }
            // The normal axis word was refused above, so this moves only the plane's two.
            let pt = target(st, lw, unit);
            if let Some(n) = st.nurbs.as_mut() {
                n.ctrl.push([pt[0], pt[1], pt[2], p.value]);
            }
            st.pos = pt;
        }
        (Some(w), None) | (None, Some(w)) => {
            return Err(lw.err(
                w.col,
                format!("NURBS control point needs both {} and {}", AXES[a], AXES[b]),
            ));
        }
        (None, None) => {}
    }
    if let Some(w) = close {
        let Some(n) = st.nurbs.take() else {
            return Err(lw.err(w.col, "G5.3 without an open G5.2 NURBS"));
        };
        let count = n.ctrl.len();
        if count < n.order {
            return Err(lw.err(
                w.col,
                format!(
                    "NURBS of order {} needs at least {} control points, got {count}",
                    n.order, n.order
                ),
            ));
        }
        // Clamped uniform integer knots, as LinuxCNC makes them.
        let k = n.order;
        let knots: Vec<f64> = (0..count + k)
            .map(|i| {
                if i < k {
                    0.0
                } else if i < count {
                    (i - k + 1) as f64
                } else {
                    (count - k + 1) as f64
                }
            })
            .collect();
        moves.push(Move::Nurbs {
            line: n.line,
            degree: k - 1,
            knots,
            ctrl: n.ctrl,
            feed: st.feed,
        });
        st.motion = Motion::None;
    }
    Ok(())
}

fn g62_line(
    st: &mut State,
    lw: &LineWords,
    open: Option<&Word>,
    motion: Option<&Word>,
    unit: f64,
    moves: &mut Vec<Move>,
    end: bool,
) -> Result<(), Diagnostic> {
    let (a, b) = st.plane.axes();
    let first_col = lw.words.first().map_or(1, |w| w.col);
    if let Some(m) = motion {
        return Err(lw.err(
            m.col,
            format!(
                "G{} inside a G6.2 NURBS: give its closing knots first",
                m.value
            ),
        ));
    }
    if end {
        return Err(lw.err(
            first_col,
            "program end inside a G6.2 NURBS: give its closing knots first",
        ));
    }
    let point = lw.get(AXES[a]).is_some() || lw.get(AXES[b]).is_some();
    if let Some(w) = lw.get(AXES[st.plane.normal()]) {
        return Err(lw.err(
            w.col,
            format!(
                "{} is not a word of the NURBS plane {:?}",
                w.letter, st.plane
            ),
        ));
    }
    if st.g62.is_none() {
        let Some(g) = open else { return Ok(()) };
        need_feed(st, lw, g.col)?;
        let order = match lw.get('P') {
            Some(p) if p.value.fract() == 0.0 && (2.0..=10.0).contains(&p.value) => {
                p.value as usize
            }
            Some(p) => return Err(lw.err(p.col, "G6.2 order P must be an integer from 2 to 10")),
            None => return Err(lw.err(g.col, "the first G6.2 block needs the order P")),
        };
        match lw.get('Q') {
            Some(q) if [1.0, 2.0, 3.0].contains(&q.value) => {} // LinuxCNC's method; we run the exact curve
            Some(q) => return Err(lw.err(q.col, "G6.2 method Q must be 1, 2 or 3")),
            None => {
                return Err(lw.err(g.col, "the first G6.2 block needs the method Q (1, 2 or 3)"))
            }
        }
        if !point {
            return Err(lw.err(g.col, "the first G6.2 block needs its first control point"));
        }
        st.g62 = Some(G62Open {
            line: lw.line,
            col: g.col,
            order,
            ctrl: vec![],
            knots: vec![],
            closing: 0,
        });
    }
    let knot = lw.get('K');
    if point {
        let (Some(_), Some(_)) = (lw.get(AXES[a]), lw.get(AXES[b])) else {
            return Err(lw.err(
                first_col,
                format!("G6.2 control point needs both {} and {}", AXES[a], AXES[b]),
            ));
        };
        let k = knot.ok_or_else(|| lw.err(first_col, "G6.2 control point needs its knot K"))?;
        let weight = lw.get('R').map_or(1.0, |r| r.value);
        if weight <= 0.0 {
            return Err(lw.err(
                lw.get('R').map_or(first_col, |r| r.col),
                "G6.2 weight R must be > 0",
            ));
        }
        // The normal axis word was refused above, so this moves only the plane's two.
        let pt = target(st, lw, unit);
        let Some(n) = st.g62.as_mut() else {
            return Ok(());
        };
        if n.closing > 0 {
            return Err(lw.err(first_col, "G6.2 control point after the closing knots"));
        }
        if n.ctrl.is_empty() {
            let gap = ((pt[a] - st.pos[a]).powi(2) + (pt[b] - st.pos[b]).powi(2)).sqrt();
            if gap > 1e-6 {
                return Err(lw.err(
                    first_col,
                    format!("the first G6.2 control point must be the current position (it is {gap:.4} mm away)"),
                ));
            }
        }
        n.ctrl.push([pt[0], pt[1], pt[2], weight]);
        n.knots.push(k.value);
        st.pos = pt;
    } else if let Some(k) = knot {
        let Some(n) = st.g62.as_mut() else {
            return Ok(());
        };
        n.knots.push(k.value);
        n.closing += 1;
        if n.closing == n.order {
            let n = st.g62.take().unwrap_or_else(|| unreachable!());
            let degree = n.order - 1;
            if let Err(e) = shared::nurbs::validate(degree, &n.knots, &n.ctrl, usize::MAX) {
                return Err(lw.err(k.col, format!("G6.2 NURBS opened on line {}: {e}", n.line)));
            }
            moves.push(Move::Nurbs {
                line: n.line,
                degree,
                knots: n.knots,
                ctrl: n.ctrl,
                feed: st.feed,
            });
            st.motion = Motion::None;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
