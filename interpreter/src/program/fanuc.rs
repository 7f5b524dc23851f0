//! Fanuc's `G06.2` NURBS interpolation and the `G05`/`G05.1` contour-control switches
//! that usually wrap it, as the Fanuc manuals describe them:
//!
//! ```text
//! G05 P10000                          high-precision contour control on (accepted)
//! G06.2 [P_] [K_] [X_ Y_ Z_] [R_] F_  first control point (the current position)
//! K_ X_ Y_ Z_ [R_]                    one block per control point, with its knot
//! K_                                  `rank` knot-only blocks close the curve
//! G05 P0                              contour control off
//! ```
//!
//! `P` is the rank (the order, degree + 1): 2 to 4 on the standard option, up to 10
//! here (some controls allow more); 4 when left out. `R` is the weight, 1 when left out.
//! Any of X, Y and Z may be given (a 3-D curve); an axis left out keeps its value. There
//! are control points + rank knots, the first and the last `rank` of them equal (the
//! curve starts at its first control point and ends at its last). As Fanuc's extended
//! specification allows, a first block without coordinates takes the current position,
//! and a first block without `K` takes the knot of the next block.
//!
//! Mistakes are refused with the alarm Fanuc users know. The numbers below were
//! confirmed in the Fanuc Series 15i/150i-MA programming manual (B-63324EN, section
//! 4.17 "NURBS interpolation": its text on knots, control points and cutter
//! compensation, and its list of NURBS alarms). That the 30i/0i-F use the same numbers
//! is what users report, not something checked against their manuals here:
//! * PS1002: a control point block without its knot `K`;
//! * PS1004: fewer knot-only blocks than the rank before another command;
//! * PS1005: another command before any knot-only block (NURBS mode ended early);
//! * PS1006: `G06.2` while cutter compensation (`G41`/`G42`) or inverse time (`G93`)
//!   is active;
//! * PS1007: the first or last `rank` knots are not equal;
//! * PS1008: a knot repeated more than the rank allows inside the curve;
//! * PS1009: the first control point is not the current position.
//!
//! Not confirmed, so our messages name the rule without a number: the alarm for a rank
//! `P` outside the allowed range, for knots that decrease, and for a curve with fewer
//! control points than its rank.
//!
//! Numbers are read as a calculator does (`X10` is 10 mm), as on a Fanuc with parameter
//! DPI (No. 3401#0) set; a control without it would read `X10` as 10 µm.
//! `G05 P10000` and `G05.1 Q1` change how a Fanuc smooths its path; this stack always
//! runs the exact curve, so they are accepted and change nothing.

use super::{need_feed, target, LineCodes, LineWords, Motion, Move, State, AXES};
use crate::parse::{Diagnostic, Word};
use crate::program::Dialect;

/// Highest rank accepted (the shared block format's degree limit + 1).
const MAX_RANK: usize = shared::nurbs::MAX_DEGREE + 1;

/// How far the first control point may be from the current position.
const START_TOL_MM: f64 = 1e-6;

/// An open `G06.2` curve.
pub(super) struct FanucOpen {
    line: u32,
    rank: usize,
    ctrl: Vec<[f64; 4]>,
    knots: Vec<f64>,
    /// The first block had no `K`: the next knot given stands for it too.
    first_knot_missing: bool,
    /// Knot-only blocks so far; `rank` of them close the curve.
    closing: usize,
    /// An error was reported: the blocks are still taken, but no curve comes of them.
    broken: bool,
}

/// The last curve closed, for a knot-only block that comes after it.
#[derive(Clone, Copy)]
pub(super) struct Closed {
    line: u32,
    n_ctrl: usize,
    rank: usize,
}

impl FanucOpen {
    fn n_knots(&self) -> usize {
        self.knots.len() + usize::from(self.first_knot_missing)
    }

    /// The error for a curve that `what` (at `line:col`) ended before its closing knots:
    /// PS1005 when none was given, PS1004 when some were. `None` when the curve already
    /// had an error of its own.
    pub(super) fn unfinished(&self, line: u32, col: u32, what: &str) -> Option<Diagnostic> {
        if self.broken {
            return None;
        }
        let (n, k) = (self.ctrl.len(), self.rank);
        let alarm = if self.closing == 0 {
            "PS1005"
        } else {
            "PS1004"
        };
        Some(Diagnostic {
            file: None,
            line,
            col,
            rule: "G06.2",
            message: format!(
                "{} knots for {n} control points of rank {k}, expected {}: {what} came after {} of the {k} knot-only `K` blocks that close the curve of line {} (Fanuc alarm {alarm})",
                self.n_knots(),
                n + k,
                self.closing,
                self.line
            ),
        })
    }
}

/// Whether a `G5` (`code` 50) or `G5.1` (51) on this line is Fanuc's contour-control
/// switch (`G05 P…`, `G05.1 Q…`) rather than a LinuxCNC spline.
pub(super) fn is_precision_mode(lw: &LineWords, code: u32) -> bool {
    match code {
        50 => lw.get('P').is_some() && !lw.has_any("XYZIJQ"),
        _ => lw.get('Q').is_some() && !lw.has_any("XYZIJP"),
    }
}

/// Accepts `G05 P10000`/`G05 P0` and `G05.1 Q1`/`Q0`: they only make a Fanuc smooth
/// its path more or less, and this stack runs the exact path anyway.
pub(super) fn precision_mode(st: &mut State, lw: &LineWords, w: &Word) -> Result<(), Diagnostic> {
    let hpcc = w.value < 5.05;
    let (name, letter, allowed): (_, _, &[f64]) = if hpcc {
        ("G05 P…", 'P', &[0.0, 10000.0])
    } else {
        ("G05.1 Q…", 'Q', &[0.0, 1.0])
    };
    st.dialect.claim(Dialect::Fanuc, lw.line, w.col, name)?;
    match lw.get(letter) {
        Some(v) if allowed.contains(&v.value) => Ok(()),
        Some(v) if hpcc => Err(lw.err(
            "G05",
            v.col,
            format!(
                "P{}: only P10000 (high-precision contour control on) and P0 (off) are supported; G05 high-speed cycles are not",
                v.value
            ),
        )),
        Some(v) => Err(lw.err(
            "G05.1",
            v.col,
            format!(
                "Q{}: only Q1 (AI contour control on) and Q0 (off) are supported",
                v.value
            ),
        )),
        None => Err(lw.err(
            if hpcc { "G05" } else { "G05.1" },
            w.col,
            format!("{name} needs its {letter}"),
        )),
    }
}

/// Whether a `G6.2` on this line is Fanuc's: forced so, or (when not forced) without
/// LinuxCNC's method `Q`.
pub(super) fn is_fanuc_g62(st: &State, lw: &LineWords) -> bool {
    match st.dialect.forced() {
        Some(d) => d == Dialect::Fanuc,
        None => lw.get('Q').is_none(),
    }
}

/// Whether a line belongs to the open curve: nothing but words of NURBS blocks (a `G`,
/// `M`, `S` or `T` ends the curve).
pub(super) fn continues(lw: &LineWords, codes: &LineCodes) -> bool {
    codes.motion.is_none()
        && codes.g62.is_none()
        && !lw.words.iter().any(|w| "GMST".contains(w.letter))
}

/// Where a line that ends an open curve does so (its first G, M, S or T word), and the
/// block itself, to name it (`G5 P0`).
pub(super) fn interrupter(lw: &LineWords) -> (u32, String) {
    let col = lw
        .words
        .iter()
        .find(|w| "GMST".contains(w.letter))
        .map_or(lw.first_col(), |w| w.col);
    let block: Vec<String> = lw
        .words
        .iter()
        .filter(|w| w.letter != 'N')
        .map(|w| format!("{}{}", w.letter, w.value))
        .collect();
    (col, format!("`{}`", block.join(" ")))
}

/// Refuses the words no `G06.2` block has.
fn only_nurbs_words(lw: &LineWords, first: bool) -> Result<(), Diagnostic> {
    for w in lw.words {
        match w.letter {
            'N' | 'K' | 'X' | 'Y' | 'Z' | 'R' | 'G' => {}
            'P' | 'F' if first => {}
            'P' => {
                return Err(lw.err(
                    "G06.2",
                    w.col,
                    "the rank P belongs on the first block of the curve only",
                ))
            }
            'F' => {
                return Err(lw.err(
                    "G06.2",
                    w.col,
                    "the feed F belongs on the first block of the curve only",
                ))
            }
            c => {
                return Err(lw.err(
                    "G06.2",
                    w.col,
                    format!("{c} is not a word of a NURBS block (P K X Y Z R F)"),
                ))
            }
        }
    }
    Ok(())
}

fn weight(lw: &LineWords) -> Result<f64, Diagnostic> {
    match lw.get('R') {
        None => Ok(1.0),
        Some(r) if super::weight_ok(r.value) => Ok(r.value),
        Some(r) => Err(lw.err("G06.2", r.col, super::weight_rule('R'))),
    }
}

/// The first block of a curve (with `G06.2` at `g`, or the first control point block
/// of a new curve while `G06.2` is modal).
pub(super) fn open(st: &mut State, lw: &LineWords, g: &Word, unit: f64) -> Result<(), Diagnostic> {
    let modal = g.letter != 'G';
    let has_point = lw.has_any("XYZ");
    if modal && !has_point {
        let (col, k) = lw.get('K').map_or((g.col, 0.0), |k| (k.col, k.value));
        let Some(c) = st.fanuc_closed else {
            return Err(lw.err("G06.2", col, "knot-only block without a curve"));
        };
        return Err(lw.err("G06.2",
            col,
            format!(
                "knot K{k} after the curve of line {} was closed: its {} control points of rank {} take {} knots, the last {} on knot-only blocks",
                c.line,
                c.n_ctrl,
                c.rank,
                c.n_ctrl + c.rank,
                c.rank
            ),
        ));
    }
    if modal && lw.get('K').is_none() {
        return Err(lw.err("G06.2",
            lw.first_col(),
            "G06.2 is still the motion: a block with coordinates is the first control point of a new curve and needs its knot K (Fanuc alarm PS1002); give G1 or G0 for a straight move",
        ));
    }
    // (Read uncompensated, for the report's programmed path, a program that ran.)
    let comp_refused = st.cutter_comp && !st.fanuc_nurbs_comp && !st.uncompensated;
    if comp_refused || st.inverse_time {
        let why = if comp_refused {
            "cutter compensation (G41/G42) is active: cancel it with G40 first, or let this control offset the curve with --dialect-extension g06.2-comp"
        } else {
            "inverse-time feed (G93) is active: switch to G94 and give F in mm/min"
        };
        return Err(lw.err("G06.2", g.col, format!("{why} (Fanuc alarm PS1006)")));
    }
    only_nurbs_words(lw, true)?;
    let rank = match lw.get('P') {
        None => 4,
        Some(p) if p.value.fract() == 0.0 && (2.0..=MAX_RANK as f64).contains(&p.value) => {
            p.value as usize
        }
        Some(p) => {
            return Err(lw.err("G06.2",
                p.col,
                format!(
                    "rank P{} is out of range: give an integer from 2 to {MAX_RANK} (order = degree + 1; standard Fanuc option 2 to 4)",
                    p.value
                ),
            ))
        }
    };
    if let Some(f) = lw.get('F') {
        if f.value < 0.0 {
            return Err(lw.err("G06.2", f.col, "F must not be negative"));
        }
        st.feed = f.value * unit;
    }
    need_feed(st, lw, g.col)?;
    let w = weight(lw)?;
    let pt = target(st, lw, unit)?;
    let gap = shared::path::norm([pt[0] - st.pos[0], pt[1] - st.pos[1], pt[2] - st.pos[2]]);
    if gap > START_TOL_MM {
        let at = lw
            .words
            .iter()
            .find(|w| AXES.contains(&w.letter))
            .map_or(g.col, |w| w.col);
        return Err(lw.err("G06.2",
            at,
            format!(
                "the first control point must be the current position ({:.4}, {:.4}, {:.4}); it is {gap:.4} mm away (Fanuc alarm PS1009)",
                st.pos[0], st.pos[1], st.pos[2]
            ),
        ));
    }
    let knot = lw.get('K');
    st.fanuc = Some(FanucOpen {
        line: lw.line,
        rank,
        ctrl: vec![[st.pos[0], st.pos[1], st.pos[2], w]],
        knots: knot.map(|k| k.value).into_iter().collect(),
        first_knot_missing: knot.is_none(),
        closing: 0,
        broken: false,
    });
    st.motion = Motion::FanucNurbs;
    Ok(())
}

/// A block of an open curve: a control point with its knot, or a closing knot.
pub(super) fn block(
    st: &mut State,
    lw: &LineWords,
    unit: f64,
    moves: &mut Vec<Move>,
) -> Result<(), Diagnostic> {
    let result = block_inner(st, lw, unit, moves);
    if result.is_err() {
        if let Some(n) = st.fanuc.as_mut() {
            n.broken = true;
        }
    }
    result
}

fn block_inner(
    st: &mut State,
    lw: &LineWords,
    unit: f64,
    moves: &mut Vec<Move>,
) -> Result<(), Diagnostic> {
    let has_point = lw.has_any("XYZ");
    let knot = lw.get('K');
    if !has_point && knot.is_none() {
        if let Some(r) = lw.get('R') {
            return Err(lw.err("G06.2", r.col, "weight R without a control point"));
        }
        return Ok(()); // a comment or an N word alone
    }
    only_nurbs_words(lw, false)?;
    let pt = target(st, lw, unit)?;
    let w = weight(lw)?;
    let Some(n) = st.fanuc.as_mut() else {
        return Ok(());
    };
    let Some(k) = knot else {
        return Err(lw.err(
            "G06.2",
            lw.first_col(),
            "a control point block needs its knot K (Fanuc alarm PS1002)",
        ));
    };
    if has_point && n.closing > 0 {
        return Err(lw.err("G06.2",
            lw.first_col(),
            format!(
                "control point after {} of the closing knot-only blocks: all control points come first, then {} blocks of K alone",
                n.closing, n.rank
            ),
        ));
    }
    if n.first_knot_missing {
        n.knots.insert(0, k.value);
        n.first_knot_missing = false;
    }
    if let Some(&before) = n.knots.last() {
        if k.value < before {
            return Err(lw.err("G06.2",
                k.col,
                format!(
                    "knot K{} is smaller than the knot before it (K{before}); knots must not decrease",
                    k.value
                ),
            ));
        }
    }
    // The first `rank` knots must be equal: said at the first one that is not.
    if n.knots.len() < n.rank && n.knots.first().is_some_and(|&f| f != k.value) {
        return Err(lw.err("G06.2",
            k.col,
            format!(
                "knot K{} differs from the first knot K{}; a curve of rank {} starts with {} equal knots, so that it starts at its first control point (Fanuc alarm PS1007)",
                k.value, n.knots[0], n.rank, n.rank
            ),
        ));
    }
    n.knots.push(k.value);
    if has_point {
        n.ctrl.push([pt[0], pt[1], pt[2], w]);
        st.pos = pt;
        return Ok(());
    }
    n.closing += 1;
    if n.closing < n.rank {
        return Ok(());
    }
    let Some(n) = st.fanuc.take() else {
        return Ok(());
    };
    st.fanuc_closed = Some(Closed {
        line: n.line,
        n_ctrl: n.ctrl.len(),
        rank: n.rank,
    });
    if n.broken {
        return Ok(());
    }
    let curve = close(&n, st.feed).map_err(|m| lw.err("G06.2", k.col, m))?;
    moves.push(curve);
    Ok(())
}

/// Checks a complete curve's knots and makes it a move.
fn close(n: &FanucOpen, feed: f64) -> Result<Move, String> {
    let (k, count) = (n.rank, n.ctrl.len());
    let of_line = format!("the curve of line {}", n.line);
    if count < k {
        return Err(format!(
            "{of_line} has {count} control points, too few for rank {k} (at least {k})"
        ));
    }
    let knots = &n.knots;
    let (first, last) = (knots[0], knots[knots.len() - 1]);
    if knots[..k].iter().any(|&x| x != first) || knots[knots.len() - k..].iter().any(|&x| x != last)
    {
        return Err(format!(
            "{of_line} must start and end with {k} equal knots (its rank), so that it starts at its first control point and ends at its last; it has {:?} … {:?} (Fanuc alarm PS1007)",
            &knots[..k],
            &knots[knots.len() - k..]
        ));
    }
    if first == last {
        return Err(format!(
            "{of_line} has all knots equal ({first}): it spans no parameter range"
        ));
    }
    // Fanuc's PS1008 names a knot repeated more than the rank. Inside the curve exactly
    // the rank would cut it in two (at most rank − 1, a corner, keeps it in one piece),
    // so that is refused too.
    let mut i = 0;
    while i < knots.len() {
        let run = knots[i..].iter().take_while(|&&x| x == knots[i]).count();
        let inside = i > 0 && i + run < knots.len();
        if run > k || (inside && run == k) {
            return Err(format!(
                "knot {} appears {run} times in {of_line}; at most {k} (the rank) at its ends and {} inside (Fanuc alarm PS1008)",
                knots[i],
                k - 1
            ));
        }
        i += run;
    }
    shared::nurbs::validate(k - 1, knots, &n.ctrl, usize::MAX)
        .map_err(|e| format!("{of_line}: {e}"))?;
    Ok(Move::Nurbs {
        line: n.line,
        degree: k - 1,
        knots: n.knots.clone(),
        ctrl: n.ctrl.clone(),
        feed,
    })
}
