//! LinuxCNC's curves: `G5` (cubic) and `G5.1` (quadratic) Bézier splines, `G5.2 … G5.3`
//! NURBS with clamped uniform knots, and `G6.2` NURBS with programmed knots. All become
//! the exact curve they describe ([`Move::Nurbs`]), never LinuxCNC's biarcs.

use super::{need_feed, target, LineWords, Motion, Move, State, AXES};
use crate::parse::{Diagnostic, Word};

/// Points of an open G5.2 block.
pub(super) struct NurbsOpen {
    pub line: u32,
    pub col: u32,
    order: usize,
    ctrl: Vec<[f64; 4]>,
}

/// An open G6.2 NURBS: control points with their knots, then the closing knots.
pub(super) struct G62Open {
    pub line: u32,
    pub col: u32,
    pub order: usize,
    ctrl: Vec<[f64; 4]>,
    knots: Vec<f64>,
    /// Where each knot's `K` word stands (line, column), to name it when it is wrong.
    knot_at: Vec<(u32, u32)>,
    /// Knot-only lines seen so far; `order` of them close the curve.
    pub closing: usize,
}

/// A `G5` cubic or `G5.1` quadratic Bézier from the current position to `to`, as an
/// exact polynomial NURBS (unit weights, one span, knots 0 and 1 repeated `order` times).
///
/// As LinuxCNC 2.9 runs them: XY plane only; `I J` is the offset of the first inner
/// control point from the start, `P Q` (G5 only) the offset of the second from the end.
/// A G5 may leave out `I J` right after another G5: the curves then join smoothly
/// (`I J` = minus the previous `P Q`). LinuxCNC also accepts that after other moves,
/// reusing a stale `P Q`; that is surely a mistake, so here it is an error.
pub(super) fn bezier(
    st: &mut State,
    lw: &LineWords,
    to: [f64; 3],
    cubic: bool,
    unit: f64,
    col: u32,
) -> Result<Move, Diagnostic> {
    let name = if cubic { "G5" } else { "G5.1" };
    if st.plane != super::Plane::XY {
        return Err(lw.err(
            name,
            col,
            format!("{name} splines must be in the XY plane (G17), as in LinuxCNC 2.9"),
        ));
    }
    if let Some(z) = lw.get('Z') {
        return Err(lw.err(
            name,
            z.col,
            format!("{name} spline in the XY plane cannot move Z; move Z on its own line"),
        ));
    }
    if let Some(w) = lw.words.iter().find(|w| "KRL".contains(w.letter)) {
        return Err(lw.err(name, w.col, format!("{} is not a word of {name}", w.letter)));
    }
    let from = st.pos;
    let ij = match (lw.get('I'), lw.get('J')) {
        (Some(i), Some(j)) => [i.value * unit, j.value * unit],
        (None, None) if cubic => st.g5_tangent.ok_or_else(|| {
            lw.err(name,
                col,
                "G5 needs I and J (offset of its first control point from the start); only a G5 right after another G5 may leave them out",
            )
        })?,
        (Some(w), None) | (None, Some(w)) => {
            return Err(lw.err(name,
                w.col,
                format!("{name} needs both I and J, or neither (G5 after G5 only)"),
            ))
        }
        (None, None) => {
            return Err(lw.err(name,
                col,
                "G5.1 needs I and J (offset of its control point from the start)",
            ))
        }
    };
    let p1 = [from[0] + ij[0], from[1] + ij[1], from[2], 1.0];
    let ij_col = lw.get('I').map_or(col, |w| w.col);
    super::within_reach(
        lw,
        ij_col,
        "the first inner control point (I J)",
        [p1[0], p1[1], p1[2]],
    )?;
    let (ctrl, knots) = if cubic {
        let (Some(p), Some(q)) = (lw.get('P'), lw.get('Q')) else {
            return Err(lw.err(
                name,
                col,
                "G5 needs both P and Q (offset of its second control point from the end)",
            ));
        };
        let pq = [p.value * unit, q.value * unit];
        st.g5_tangent = Some([-pq[0], -pq[1]]);
        let p2 = [to[0] + pq[0], to[1] + pq[1], from[2], 1.0];
        super::within_reach(
            lw,
            p.col,
            "the second inner control point (P Q)",
            [p2[0], p2[1], p2[2]],
        )?;
        (
            vec![
                [from[0], from[1], from[2], 1.0],
                p1,
                p2,
                [to[0], to[1], to[2], 1.0],
            ],
            vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
        )
    } else {
        if let Some(w) = lw.words.iter().find(|w| "PQ".contains(w.letter)) {
            return Err(lw.err(name, w.col, format!("{} is not a word of G5.1", w.letter)));
        }
        (
            vec![
                [from[0], from[1], from[2], 1.0],
                p1,
                [to[0], to[1], to[2], 1.0],
            ],
            vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        )
    };
    Ok(Move::Nurbs {
        line: lw.line,
        degree: knots.len() / 2 - 1,
        knots,
        ctrl,
        feed: st.feed,
    })
}

#[allow(clippy::too_many_arguments)]
pub(super) fn nurbs_line(
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
            "G5.2",
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
            "G5.2",
            col,
            "program end inside a G5.2 NURBS: close it with G5.3 first",
        ));
    }
    if let Some(w) = open {
        if st.nurbs.is_some() {
            return Err(lw.err("G5.2", w.col, "G5.2 inside an open G5.2 NURBS"));
        }
        need_feed(st, lw, w.col)?;
        let order = match lw.get('L') {
            None => 3,
            Some(l) if l.value.fract() == 0.0 && l.value >= 2.0 && l.value <= 10.0 => {
                (l.value as usize).max(3)
            }
            Some(l) => {
                return Err(lw.err(
                    "G5.2",
                    l.col,
                    "NURBS order L must be an integer from 2 to 10",
                ))
            }
        };
        let has_point = lw.get(AXES[a]).is_some() || lw.get(AXES[b]).is_some();
        // `G5.2 P.. L..` alone: P is the weight of the first control point (the current
        // position); with coordinates, the line is already the second control point.
        let w0 = match (has_point, lw.get('P')) {
            (false, Some(p)) => p.value,
            _ => 1.0,
        };
        if !super::weight_ok(w0) {
            return Err(lw.err(
                "G5.2",
                lw.get('P').map(|p| p.col).unwrap_or(w.col),
                super::weight_rule('P'),
            ));
        }
        let p = st.pos;
        // Room for the points a curve of this order usually has, so that the list is
        // not grown (copied) point by point.
        let mut ctrl = Vec::with_capacity(2 * order);
        ctrl.push([p[0], p[1], p[2], w0]);
        st.nurbs = Some(NurbsOpen {
            line: lw.line,
            col: w.col,
            order,
            ctrl,
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
            "G5.2",
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
                    "G5.2",
                    lw.words[0].col,
                    "every NURBS control point needs its weight P",
                )
            })?;
            if !super::weight_ok(p.value) {
                return Err(lw.err("G5.2", p.col, super::weight_rule('P')));
            }
            // The normal axis word was refused above, so this moves only the plane's two.
            let pt = target(st, lw, unit)?;
            if let Some(n) = st.nurbs.as_mut() {
                n.ctrl.push([pt[0], pt[1], pt[2], p.value]);
            }
            st.pos = pt;
        }
        (Some(w), None) | (None, Some(w)) => {
            return Err(lw.err(
                "G5.2",
                w.col,
                format!("NURBS control point needs both {} and {}", AXES[a], AXES[b]),
            ));
        }
        (None, None) => {}
    }
    if let Some(w) = close {
        let Some(n) = st.nurbs.take() else {
            return Err(lw.err("G5.2", w.col, "no G5.2 NURBS is open for G5.3 to close"));
        };
        let count = n.ctrl.len();
        if count < n.order {
            return Err(lw.err(
                "G5.2",
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

pub(super) fn g62_line(
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
            "G6.2",
            m.col,
            format!(
                "G{} inside a G6.2 NURBS: give its closing knots first",
                m.value
            ),
        ));
    }
    if end {
        return Err(lw.err(
            "G6.2",
            first_col,
            "program end inside a G6.2 NURBS: give its closing knots first",
        ));
    }
    let point = lw.get(AXES[a]).is_some() || lw.get(AXES[b]).is_some();
    if let Some(w) = lw.get(AXES[st.plane.normal()]) {
        return Err(lw.err(
            "G6.2",
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
            Some(p) => {
                return Err(lw.err("G6.2", p.col, "order P must be an integer from 2 to 10"))
            }
            None => return Err(lw.err("G6.2", g.col, "the first G6.2 block needs the order P")),
        };
        match lw.get('Q') {
            Some(q) if [1.0, 2.0, 3.0].contains(&q.value) => {} // LinuxCNC's method; we run the exact curve
            Some(q) => return Err(lw.err("G6.2", q.col, "method Q must be 1, 2 or 3")),
            None => {
                return Err(lw.err("G6.2",
                    g.col,
                    "the first G6.2 block needs the method Q (1, 2 or 3); a Fanuc G06.2 has none: read it with --dialect fanuc",
                ))
            }
        }
        if !point {
            return Err(lw.err(
                "G6.2",
                g.col,
                "the first G6.2 block needs its first control point",
            ));
        }
        st.g62 = Some(G62Open {
            line: lw.line,
            col: g.col,
            order,
            ctrl: vec![],
            knots: vec![],
            knot_at: vec![],
            closing: 0,
        });
    }
    let knot = lw.get('K');
    if point {
        let (Some(_), Some(_)) = (lw.get(AXES[a]), lw.get(AXES[b])) else {
            return Err(lw.err(
                "G6.2",
                first_col,
                format!("control point needs both {} and {}", AXES[a], AXES[b]),
            ));
        };
        let k = knot.ok_or_else(|| lw.err("G6.2", first_col, "control point needs its knot K"))?;
        let weight = lw.get('R').map_or(1.0, |r| r.value);
        if !super::weight_ok(weight) {
            return Err(lw.err(
                "G6.2",
                lw.get('R').map_or(first_col, |r| r.col),
                super::weight_rule('R'),
            ));
        }
        // The normal axis word was refused above, so this moves only the plane's two.
        let pt = target(st, lw, unit)?;
        let Some(n) = st.g62.as_mut() else {
            return Ok(());
        };
        if n.closing > 0 {
            return Err(lw.err("G6.2", first_col, "control point after the closing knots"));
        }
        if n.ctrl.is_empty() {
            let gap = ((pt[a] - st.pos[a]).powi(2) + (pt[b] - st.pos[b]).powi(2)).sqrt();
            if gap > 1e-6 {
                return Err(lw.err("G6.2",
                    first_col,
                    format!("the first G6.2 control point must be the current position (it is {gap:.4} mm away)"),
                ));
            }
        }
        n.ctrl.push([pt[0], pt[1], pt[2], weight]);
        n.knots.push(k.value);
        n.knot_at.push((lw.line, k.col));
        st.pos = pt;
    } else if let Some(k) = knot {
        let Some(n) = st.g62.as_mut() else {
            return Ok(());
        };
        n.knots.push(k.value);
        n.knot_at.push((lw.line, k.col));
        n.closing += 1;
        if n.closing == n.order {
            let n = st.g62.take().unwrap_or_else(|| unreachable!());
            let degree = n.order - 1;
            if let Some(bad) = bad_knot(&n.knots, n.order) {
                let (line, col) = n.knot_at[bad.index];
                return Err(Diagnostic {
                    file: None,
                    line,
                    col,
                    rule: "G6.2",
                    message: bad.message(&n.knots, n.order, n.line),
                });
            }
            if let Err(e) = shared::nurbs::validate(degree, &n.knots, &n.ctrl, usize::MAX) {
                return Err(lw.err(
                    "G6.2",
                    k.col,
                    format!("NURBS opened on line {}: {e}", n.line),
                ));
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

/// A knot a curve of order `order` must not have, found by [`bad_knot`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct BadKnot {
    /// The knot's index in the list: the first that decreases, or the one whose run of
    /// equal knots has become too long.
    pub index: usize,
    /// How many equal knots the run holds (0 for a decreasing knot).
    pub run: usize,
    /// The run is inside the curve (neither its first nor its last knots).
    pub inside: bool,
}

impl BadKnot {
    /// What is wrong with it, in words, for the curve opened on line `opened`.
    pub fn message(&self, knots: &[f64], order: usize, opened: u32) -> String {
        let k = knots[self.index];
        if self.run == 0 {
            return format!(
                "knot K{k} is smaller than knot K{}, the one before it, in the NURBS opened on line {opened}; knots must not decrease",
                knots[self.index - 1]
            );
        }
        if self.inside {
            format!(
                "knot K{k} is repeated {} times inside the NURBS opened on line {opened}; at most {} (the order {order} less one) inside: {order} equal knots cut the curve in two and the tool would jump from one piece to the other",
                self.run,
                order - 1
            )
        } else {
            format!(
                "knot K{k} is repeated {} times at an end of the NURBS opened on line {opened}; at most {order} (its order) there: more would leave a control point out of the curve, which would not start or end where its points say",
                self.run
            )
        }
    }
}

/// The first knot that makes `knots` unfit for one continuous curve of order `order`: a
/// knot smaller than the one before it, or a run of equal knots longer than the order
/// (at an end) or as long as the order (inside: the curve falls in two pieces that need
/// not meet). The knot named is the one that makes the run too long, the first that
/// may be removed to mend it.
pub(super) fn bad_knot(knots: &[f64], order: usize) -> Option<BadKnot> {
    let mut start = 0;
    for i in 0..knots.len() {
        if i > 0 && knots[i] < knots[i - 1] {
            return Some(BadKnot {
                index: i,
                run: 0,
                inside: true,
            });
        }
        if i > 0 && knots[i] != knots[i - 1] {
            start = i;
        }
        let run = i + 1 - start;
        // Whether the run can still be the last one: every knot after it equal to it.
        let at_end = knots[i..].iter().all(|&k| k == knots[i]);
        let inside = start > 0 && !at_end;
        if run > order || (inside && run == order) {
            return Some(BadKnot {
                index: i,
                run: knots[start..]
                    .iter()
                    .take_while(|&&k| k == knots[i])
                    .count(),
                inside,
            });
        }
    }
    None
}

#[cfg(test)]
mod knot_tests {
    use super::bad_knot;

    #[test]
    fn runs_as_long_as_the_order_only_at_the_ends() {
        assert_eq!(bad_knot(&[0., 0., 0., 1., 1., 1.], 3), None);
        assert_eq!(bad_knot(&[0., 0., 0., 0.5, 0.5, 1., 1., 1.], 3), None);
        let b = bad_knot(&[0., 0., 0., 0.5, 0.5, 0.5, 1., 1., 1.], 3).unwrap();
        assert_eq!((b.index, b.run, b.inside), (5, 3, true));
        let b = bad_knot(&[0., 0., 0., 0., 1., 1., 1.], 3).unwrap();
        assert_eq!((b.index, b.run, b.inside), (3, 4, false));
        let b = bad_knot(&[0., 0., 0., 1., 1., 1., 1.], 3).unwrap();
        assert_eq!((b.index, b.inside), (6, false));
        let b = bad_knot(&[0., 0., 0., 2., 1., 3., 3., 3.], 3).unwrap();
        assert_eq!((b.index, b.run), (4, 0));
    }
}
