//! Cutter radius compensation, `G41`/`G42` (and LinuxCNC's `G41.1`/`G42.1`), on straight
//! moves and arcs in the XY plane, the way LinuxCNC 2.9's interpreter makes it, and on
//! NURBS moves, which LinuxCNC does not compensate.
//!
//! The tool's centre runs at the radius `r` to the left (`G41`) or right (`G42`) of the
//! programmed path, seen along the direction of travel:
//!
//! * **Entry** (the first move after `G41`/`G42`). A straight move ends at its programmed
//!   end moved by `r` square to the move; an arc ends at its end moved by `r` along the
//!   radius, on a circle through the tool's start whose centre lies on that radius. The
//!   move must be longer than `r`.
//! * **Convex corners** (the tool on the outside): an arc of radius `r` round the
//!   programmed corner joins the two offset moves.
//! * **Concave corners** (the tool on the inside): the move before is cut short where the
//!   two offset paths meet. That is only known when the next move comes, so the moves
//!   since the last corner stay open ([`Comp::queue`]) until it does, as LinuxCNC's own
//!   canon queue does. A corner the tool cannot reach without cutting back into the
//!   move before (the offset moves would reverse) is refused at the line that makes it.
//! * **Within about 3° of straight on** (`CORNER_TOL`) the next move starts where the
//!   last ended, with no arc.
//! * **Exit** (`G40`): the move after it goes straight from the offset point to its own
//!   programmed end, and must be a straight move.
//!
//! Every decision and every refusal is LinuxCNC's (`interp_convert.cc`:
//! `convert_straight_comp1/2`, `convert_arc_comp1/2`; `interp_queue.cc`:
//! `move_endpoint_and_flush`), so a program gives the same path and is refused at the
//! same line (`tests/rs274_differential.rs` holds us to it). The one difference: where
//! LinuxCNC would start an arc a little off its circle (a corner within `CORNER_TOL`
//! of tangent, a spiral of at most `r·(1 − cos 0.05)`), ours is the exact circle through
//! both ends, its centre moved onto their bisector; and where those ends are too close
//! for a bisector to be a guide (a full circle), a move of that size onto the circle
//! comes first. Every move of ours lies on the path it names. And a programmed full
//! circle stays a full circle where its offset's end comes out a little ahead of its
//! start (LinuxCNC then makes an arc of that little angle).
//!
//! **NURBS moves** (`G5.2`, `G6.2`; beyond LinuxCNC, which under `G5.2` loses the open
//! move before the curve and runs the curve uncompensated: `rs274 -g` prints no move
//! for it) are offset by [`nurbs`]: the corner into the curve is judged as into a
//! straight move along its first tangent and the corner out of it as out of a straight
//! move along its last (an arc round a convex one, on within [`CORNER_TOL`] of tangent),
//! and the curve's offset is fitted within the machine's chord tolerance
//! ([`super::offset`], which refuses a bend tighter than the tool on its side, an
//! offset that crosses itself and a corner inside the curve, naming the curve
//! parameter). At a concave corner the two offset paths are cut short where they meet,
//! as LinuxCNC cuts lines and arcs ([`super::meet`] finds the point): the move before
//! (a line or an arc still open, or a NURBS move's fitted offset, split there by knot
//! insertion) ends there and the move after starts there. So a NURBS move's offset
//! stays open at its end until the next move comes ([`Ended::Nurbs`]), like the queue.
//! Refused there: paths that never meet (the part between the two moves is thinner
//! than the tool), a meeting only at the far end of a curve (the whole curve would be
//! skipped), and two curves whose offsets cross more than once near the corner. Not
//! yet: a curve as the entry move (refused; the entry brings the tool onto the offset
//! along a line or an arc).
//!
//! Not here: the XZ and YZ planes (LinuxCNC compensates in XZ for lathes; this control
//! drives a mill), the `G5`/`G5.1` splines under compensation (refused, as LinuxCNC
//! does), Fanuc's `G06.2` unless asked for (alarm PS1006, as a Fanuc control gives;
//! `--dialect-extension g06.2-comp` offsets it as here), and `G93` inverse time with it
//! (a compensated move's length is not the programmed one, so `1/F` minutes would time
//! a different path).
//!
//! The radius: `G41.1`/`G42.1 D` give the diameter in the program's units; `G41`/`G42`
//! take it from the tool table ([`super::tools`]): `D<n>`'s tool, or without `D` the
//! tool in the spindle. Without a table they are refused rather than run with no
//! offset, and so is `G41` with no `D` and no tool changed in (LinuxCNC would offset
//! by the empty spindle's zero).

use super::{meet, LineWords, Move, Plane, State};
use crate::parse::Diagnostic;
use std::f64::consts::{FRAC_PI_2, PI};

/// Radians within which two directions count as the same at a corner (LinuxCNC's
/// `TOLERANCE_CONCAVE_CORNER`): no corner arc below it, and a turn back within it of a
/// half turn is a concave corner.
const CORNER_TOL: f64 = 0.05;

/// A cosine below this is zero (LinuxCNC 2.9's `TOLERANCE_EQUAL`; 1e-6 in its later
/// versions): an entry arc whose centre would lie that near infinity is refused.
const EQUAL_TOL: f64 = 1e-4;

/// How much further round (radians) a shortened arc may sweep than it did before
/// LinuxCNC calls it a gouge: its test, with these numbers, in mm and in inch programs.
const ARC_GROWTH_TOL: (f64, f64) = (0.0254, 0.001);

/// How far apart (mm) the radii at an arc's two ends may be before LinuxCNC calls the
/// compensation broken.
const RADII_TOL: f64 = 0.01;

/// The side of the programmed path the tool runs on, seen along the direction of travel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Side {
    Left,
    Right,
}

/// An open move of the queue, with what the corner after it is judged by.
#[derive(Clone, Copy, Debug)]
struct Queued {
    /// Its index in the program's moves.
    index: usize,
    /// A straight move: the direction it was made in (its end may not move back past its
    /// start). Zero for moves along Z only and for the entry move's check.
    dir: [f64; 2],
    /// An arc: the angle it swept when made (0 for a corner arc: never checked).
    sweep: f64,
}

/// Compensation while it is on.
#[derive(Clone, Debug)]
pub(super) struct Comp {
    side: Side,
    /// mm, never negative (a negative diameter turns the side).
    radius: f64,
    /// No move made since it was turned on: the next is the entry move.
    first: bool,
    /// Where the tool is, mm: `State::pos` is where the program is.
    tool: [f64; 3],
    /// The moves whose end may still move (the last corner not yet known).
    queued: Vec<Queued>,
    /// Where the first open move starts, while that is known (LinuxCNC's `endpoint`).
    endpoint: Option<[f64; 2]>,
    /// [`ARC_GROWTH_TOL`] in the program's units.
    growth_tol: f64,
    /// The last move in XY is not an open line or arc of the queue: a stop, after which
    /// a concave corner is refused, or a NURBS move, which one cuts short.
    ended: Option<Ended>,
}

/// How the last move in XY ended, where it is not an open line or arc.
#[derive(Clone, Copy, Debug)]
enum Ended {
    /// `M0`/`M1`: the open moves were closed where they were.
    Stop,
    /// The NURBS move `moves[index]`, its offset still open at its end (a
    /// concave corner after it cuts it short, [`Comp::cut_nurbs_end`]); `kappa`: its
    /// signed curvature at its end (+ turning left), for the corner after it.
    Nurbs { index: usize, kappa: f64 },
}

/// The compensation codes: `G41` 410, `G41.1` 411, `G42` 420, `G42.1` 421.
pub(super) fn turn_on(
    st: &mut State,
    lw: &LineWords,
    w: &crate::parse::Word,
    code: u32,
    unit: f64,
) -> Result<(), Diagnostic> {
    let name = super::shown(w.value);
    if st.plane != Plane::XY {
        return Err(lw.err(
            "G41/G42",
            w.col,
            format!("G{name}: cutter radius compensation works in the XY plane (G17) only here"),
        ));
    }
    if st.comp.is_some() {
        return Err(lw.err(
            "G41/G42",
            w.col,
            format!(
                "G{name}: cutter radius compensation is already on: turn it off with G40 first"
            ),
        ));
    }
    if st.inverse_time {
        return Err(lw.err(
            "G41/G42",
            w.col,
            format!("G{name} in inverse time (G93): a compensated move is not the programmed length, so 1/F minutes would time another path; use G94"),
        ));
    }
    if code % 10 == 1 {
        st.dialect
            .claim(super::Dialect::LinuxCnc, lw.line, w.col, "G41.1/G42.1")?;
    }
    let diameter = match (code, lw.get('D')) {
        (411 | 421, Some(d)) => d.value * unit,
        (411 | 421, None) => {
            return Err(lw.err(
                "G41/G42",
                w.col,
                format!("G{name} with no D word (the tool's diameter)"),
            ))
        }
        _ => {
            let Some(table) = &st.tools else {
                return Err(lw.err(
                    "G41/G42",
                    w.col,
                    format!(
                        "G{name} takes the tool's radius from a tool table: give one with --tool-table FILE, or the tool's diameter with G{}.1 D…",
                        code / 10
                    ),
                ));
            };
            // `D0`, as no `D`: the tool in the spindle (LinuxCNC's index 0).
            let n = match lw.get('D').filter(|d| d.value != 0.0) {
                Some(d) if d.value > 0.0 && d.value.fract() == 0.0 && d.value <= u32::MAX as f64 => {
                    d.value as u32
                }
                Some(d) => {
                    return Err(lw.err(
                        "G41/G42",
                        d.col,
                        format!("G{name} requires D word to be a whole number, 0 or more (a tool of the table)"),
                    ))
                }
                None if st.spindle_tool == 0 => {
                    return Err(lw.err(
                        "G41/G42",
                        w.col,
                        format!("G{name} with no tool in the spindle (T… M6) to take the radius of: name the tool with D"),
                    ))
                }
                None => st.spindle_tool,
            };
            match table.get(n) {
                Some(t) => t.diameter_mm,
                None => {
                    return Err(lw.err(
                        "G41/G42",
                        lw.get('D').map_or(w.col, |d| d.col),
                        format!("G{name}: tool T{n} is not in the tool table {}", table.file),
                    ))
                }
            }
        }
    };
    let mut side = if code / 10 == 41 {
        Side::Left
    } else {
        Side::Right
    };
    // A negative diameter (a tool smaller than the one the path was drawn for) offsets
    // the other way.
    if diameter < 0.0 {
        side = match side {
            Side::Left => Side::Right,
            Side::Right => Side::Left,
        };
    }
    st.comp = Some(Comp {
        side,
        radius: diameter.abs() / 2.0,
        first: true,
        // (After a `G40` the tool is still off the path, but LinuxCNC works out the
        // entry from the programmed point; the move starts from the tool.)
        tool: st.pos,
        queued: Vec::new(),
        endpoint: None,
        growth_tol: if st.inch {
            ARC_GROWTH_TOL.1
        } else {
            ARC_GROWTH_TOL.0
        },
        ended: None,
    });
    Ok(())
}

/// A concave corner after a move that has ended where it was: a stop (`M0`, `M1`).
/// (After `M0`/`M1` the move before is finished: it cannot be cut short. LinuxCNC reads
/// an empty queue here, undefined; the tool would gouge.)
fn ended_before_concave(lw: &LineWords) -> Diagnostic {
    lw.err(
        "G41/G42",
        lw.first_col(),
        "concave corner right after a stop (M0, M1): the move before it has ended where it was, and the tool cannot be brought into the corner without gouging; put the stop elsewhere",
    )
}

/// A NURBS move (`m`, as the program made it: its first control point where the
/// programmed path is) under compensation: its offset fitted within `tol`
/// ([`super::offset`]), and the corner into it judged as into a straight move along its
/// first tangent: an arc round a convex one; within [`CORNER_TOL`] of tangent, on; at a
/// concave one the move before and the offset are cut short where they meet. It ends
/// where its offset ends, open to be cut short by a concave corner after it.
pub(super) fn nurbs(
    st: &mut State,
    lw: &LineWords,
    m: Move,
    tol: f64,
    moves: &mut Vec<Move>,
) -> Result<(), Diagnostic> {
    let Move::Nurbs {
        line,
        degree,
        knots,
        ctrl,
        feed,
    } = m
    else {
        unreachable!("nurbs() takes NURBS moves");
    };
    let c = st.comp.as_mut().expect("compensation is on");
    let (r, side) = (c.radius, c.side);
    let cur = c.tool;
    // Refusals name the line that opened the curve.
    let refuse = |message: String| Diagnostic {
        file: None,
        line,
        col: 1,
        rule: "G41/G42",
        message,
    };
    if c.first {
        return Err(refuse("the entry move of cutter radius compensation must be a straight move or an arc (G0, G1, G2, G3), which brings the tool to the offset; it is a NURBS here".into()));
    }
    let d = if side == Side::Left { r } else { -r };
    let fitted =
        super::offset::offset(degree, &knots, &ctrl, d, tol).map_err(|e| refuse(e.message(tol)))?;
    debug_assert!(fitted.error <= tol);
    let first = shared::nurbs::eval(degree, &knots, &ctrl, knots[degree]);
    let op = [first.p[0], first.p[1]];
    let z = first.p[2];
    // (LinuxCNC's G5.2 takes no Z; a G6.2 or Fanuc's G06.2 can climb.)
    if let Some(p) = ctrl.iter().find(|p| p[2] != ctrl[0][2]) {
        return Err(refuse(format!(
            "a NURBS under cutter radius compensation must stay at one height: its control points go from Z{} to Z{}, and the offset is made in the XY plane only, so the tool would not follow the curve's Z; move along Z before or after the curve",
            ctrl[0][2], p[2]
        )));
    }
    let alpha = first.d1[1].atan2(first.d1[0]);
    let (_, beta, gamma) = corner(side, op, xy(cur), alpha);
    let mid = at(op, r, alpha + gamma);
    // As `straight()` judges a corner (the "h" after a bend turning away), and as
    // `arc()` does where the direction turns back on itself with the tool outside the
    // new bend.
    let kappa0 = curvature(&first);
    let concave = !(-CORNER_TOL..=PI + CORNER_TOL).contains(&beta)
        || (beta > PI - CORNER_TOL && turns_away(c, side, c.open_arc(moves)))
        || ((beta - PI).abs() < CORNER_TOL && d * kappa0 < 0.0);
    let n = fitted.ctrl.len();
    let mut knots_o = fitted.knots;
    let mut pts: Vec<[f64; 4]> = fitted.ctrl.iter().map(|p| [p[0], p[1], z, 1.0]).collect();
    // Where the curve's offset starts.
    let start;
    if concave {
        // The tool turns where the offset paths before and along the curve meet: the
        // move before is cut short there and the curve's offset starts there.
        let gouge = || {
            refuse("NURBS move in concave corner cannot be reached by the tool without gouging: the tool's path along the move before never meets its path along the curve".into())
        };
        let lo = knots_o[3];
        let (u, joint) = match c.ended {
            Some(Ended::Stop) => return Err(ended_before_concave(lw)),
            Some(Ended::Nurbs { index, .. }) => {
                let Move::Nurbs {
                    knots: ka,
                    ctrl: ca,
                    ..
                } = &moves[index]
                else {
                    unreachable!("an open NURBS is a NURBS move");
                };
                let a = meet::Spline {
                    knots: ka,
                    ctrl: ca,
                };
                let b = meet::Spline {
                    knots: &knots_o,
                    ctrl: &pts,
                };
                let (s, t) = match meet::splines(&a, &b) {
                    meet::Splines::At { s, t } => (s, t),
                    meet::Splines::Apart => return Err(gouge()),
                    meet::Splines::Tangled => return Err(refuse("NURBS move in concave corner after a NURBS move: the tool's paths along the two curves cross more than once near the corner, so where it should turn is not clear; join the curves tangentially or on the outside".into())),
                };
                let la = moves[index].line();
                let x = c.cut_nurbs_end(moves, index, s).ok_or_else(|| {
                    refuse(format!("NURBS move in concave corner cannot be reached by the tool without gouging: its path meets the path along the NURBS move of line {} only at that curve's start", la))
                })?;
                c.joined_at(moves, x);
                (t, Some(x))
            }
            None => {
                let other = match (c.open_arc(moves), c.queued.first()) {
                    (Some((pc, oldrad, _)), _) => meet::Other::Circle { c: pc, r: oldrad },
                    // The line through the tool square to where the programmed corner
                    // is: along the move before (and, after an entry move, as LinuxCNC
                    // moves its end).
                    (None, Some(_)) => meet::Other::Line {
                        p: xy(cur),
                        dir: [-(cur[1] - op[1]), cur[0] - op[0]],
                    },
                    (None, None) => return Err(ended_before_concave(lw)),
                };
                let b = meet::Spline {
                    knots: &knots_o,
                    ctrl: &pts,
                };
                (
                    meet::spline_other(&b, &other, true).ok_or_else(gouge)?,
                    None,
                )
            }
        };
        let hi = knots_o[n];
        if u >= hi {
            return Err(refuse("NURBS move in concave corner cannot be reached by the tool without gouging: the tool's path along the move before meets its path along the curve only at the curve's end".into()));
        }
        if u > lo {
            (knots_o, pts) = meet::piece(&knots_o, &pts, u, hi);
        }
        if polygon_length(&pts) < DEGENERATE_MM {
            return Err(refuse("NURBS move in concave corner cannot be reached by the tool without gouging: the tool's path along the move before meets its path along the curve only at the curve's end".into()));
        }
        start = match joint {
            Some(x) => x,
            None => {
                let x = [pts[0][0], pts[0][1]];
                c.end_open_at(moves, lw, x)?;
                x
            }
        };
        c.close();
    } else {
        c.end_open_at(moves, lw, xy(cur))?;
        c.close();
        if beta > CORNER_TOL {
            // Convex: round the programmed corner.
            let turn = if side == Side::Left { -1 } else { 1 };
            push_arc(moves, line, feed, cur, with_z(mid, cur[2]), op, turn);
            start = mid;
        } else if dist(mid, xy(cur)) > 1e-9 {
            // Straight on (within the tolerance): across the little gap.
            moves.push(Move::Line {
                line,
                from: cur,
                to: with_z(mid, cur[2]),
                rapid: false,
                feed,
            });
            start = mid;
        } else {
            // (Straight on, within a nanometre.)
            start = xy(cur);
        }
    }
    // The fit's ends are the offset's ends: the corner's end, to the bit.
    pts[0] = [start[0], start[1], z, 1.0];
    let last_pt = pts[pts.len() - 1];
    let end = [last_pt[0], last_pt[1], z];
    moves.push(Move::Nurbs {
        line,
        degree: 3,
        knots: knots_o,
        ctrl: pts,
        feed,
    });
    let last = shared::nurbs::eval(degree, &knots, &ctrl, knots[ctrl.len()]);
    c.endpoint = Some(xy(end));
    c.ended = Some(Ended::Nurbs {
        index: moves.len() - 1,
        kappa: curvature(&last),
    });
    c.tool = end;
    Ok(())
}

/// A NURBS offset whose control polygon is shorter than this (mm) is cut to nothing.
const DEGENERATE_MM: f64 = 1e-6;

/// The length of a control polygon, in XY.
fn polygon_length(ctrl: &[[f64; 4]]) -> f64 {
    ctrl.windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum()
}

/// LinuxCNC's angles at the corner `op` between the move the tool came along (it is at
/// `cur`, offset from `op`) and a new move leaving in the direction `alpha`: `theta`,
/// the direction from `op` to the tool; `beta`, how far the corner turns towards the
/// tool's side (convex from 0 to a half turn); `gamma`, the quarter turn from a move's
/// direction to the tool's side.
fn corner(side: Side, op: [f64; 2], cur: [f64; 2], alpha: f64) -> (f64, f64, f64) {
    let mut theta = angle(op, cur);
    let mut alpha = alpha;
    match side {
        Side::Left => {
            if theta < alpha {
                theta += 2.0 * PI;
            }
            (theta, theta - alpha - FRAC_PI_2, FRAC_PI_2)
        }
        Side::Right => {
            if alpha < theta {
                alpha += 2.0 * PI;
            }
            (theta, alpha - theta - FRAC_PI_2, -FRAC_PI_2)
        }
    }
}

/// The signed curvature of a curve point in XY (+ turning left).
fn curvature(e: &shared::nurbs::CurvePoint) -> f64 {
    let (d1, d2) = (e.d1, e.d2);
    (d1[0] * d2[1] - d1[1] * d2[0]) / d1[0].hypot(d1[1]).powi(3)
}

/// Whether the move before (an open arc, or a NURBS that has ended) bends away from the
/// tool's side: then a corner turning back on it (within [`CORNER_TOL`] of a half turn)
/// is concave, LinuxCNC's "h" case.
fn turns_away(c: &Comp, side: Side, open_arc: Option<([f64; 2], f64, i64)>) -> bool {
    let left = match (open_arc, c.ended) {
        (Some((_, _, turn)), _) => turn > 0,
        (None, Some(Ended::Nurbs { kappa, .. })) if kappa != 0.0 => kappa > 0.0,
        _ => return false,
    };
    (side == Side::Right && left) || (side == Side::Left && !left)
}

/// `G40`: the open moves end where they are (refused if that reverses one, see
/// [`settle`]), and the next move starts from the tool.
pub(super) fn turn_off(
    st: &mut State,
    lw: &LineWords,
    moves: &mut [Move],
) -> Result<(), Diagnostic> {
    settle(st, lw, moves)?;
    if let Some(c) = st.comp.take() {
        if c.radius > 0.0 && !c.first {
            st.exit_from = Some(c.tool);
        }
    }
    Ok(())
}

/// `G40`, `M0`, `M1`, `M2`: the open moves end where they are. As in LinuxCNC, that
/// is where a move whose start a concave corner moved past its end (a straight move
/// reversed, an arc sweeping further round than programmed) is found and refused.
pub(super) fn settle(st: &mut State, lw: &LineWords, moves: &mut [Move]) -> Result<(), Diagnostic> {
    if let Some(c) = &mut st.comp {
        let at = xy(c.tool);
        c.end_open_at(moves, lw, at)?;
        c.close();
        if !c.first {
            c.ended = Some(Ended::Stop);
        }
    }
    Ok(())
}

/// After a line's `G20`/`G21`: LinuxCNC's gouge test for arcs follows the units.
pub(super) fn units(st: &mut State) {
    let inch = st.inch;
    if let Some(c) = &mut st.comp {
        c.growth_tol = if inch {
            ARC_GROWTH_TOL.1
        } else {
            ARC_GROWTH_TOL.0
        };
    }
}

/// Whether moves are offset now.
pub(super) fn active(st: &State) -> bool {
    st.comp.as_ref().is_some_and(|c| c.radius > 0.0)
}

fn xy(p: [f64; 3]) -> [f64; 2] {
    [p[0], p[1]]
}

fn angle(from: [f64; 2], to: [f64; 2]) -> f64 {
    (to[1] - from[1]).atan2(to[0] - from[0])
}

fn at(p: [f64; 2], r: f64, a: f64) -> [f64; 2] {
    [p[0] + r * a.cos(), p[1] + r * a.sin()]
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

fn with_z(p: [f64; 2], z: f64) -> [f64; 3] {
    [p[0], p[1], z]
}

/// Whether the tool runs inside an arc turning `turn` (its sign: + counter-clockwise).
fn inside(side: Side, turn: i64) -> bool {
    (side == Side::Left && turn > 0) || (side == Side::Right && turn < 0)
}

/// The angle an arc turning `turn` times (signed, + counter-clockwise) sweeps from `a`
/// to `b` round `c` (LinuxCNC's `find_turn`).
fn sweep(a: [f64; 2], c: [f64; 2], turn: i64, b: [f64; 2]) -> f64 {
    if turn == 0 {
        return 0.0;
    }
    let (mut alpha, mut beta) = (angle(c, a), angle(c, b));
    if turn > 0 {
        if beta <= alpha {
            beta += 2.0 * PI;
        }
        beta - alpha + (turn - 1) as f64 * 2.0 * PI
    } else {
        if alpha <= beta {
            alpha += 2.0 * PI;
        }
        beta - alpha + (turn + 1) as f64 * 2.0 * PI
    }
}

impl Comp {
    /// The first open move, if it is an arc: its centre, radius at its end and turn.
    fn open_arc(&self, moves: &[Move]) -> Option<([f64; 2], f64, i64)> {
        let q = self.queued.first()?;
        match &moves[q.index] {
            Move::Arc {
                to,
                center,
                ccw,
                turns,
                ..
            } => Some((
                xy(*center),
                dist(xy(*center), xy(*to)),
                if *ccw {
                    *turns as i64
                } else {
                    -(*turns as i64)
                },
            )),
            _ => None,
        }
    }

    /// The open moves end at `p` (and those after the first start there), then close
    /// (LinuxCNC's `move_endpoint_and_flush`): refused where that reverses a straight
    /// move or makes an arc sweep further than it did.
    fn end_open_at(
        &mut self,
        moves: &mut [Move],
        lw: &LineWords,
        p: [f64; 2],
    ) -> Result<(), Diagnostic> {
        for (k, q) in self.queued.iter().enumerate() {
            let start = self.endpoint;
            match &mut moves[q.index] {
                Move::Line {
                    from, to, rapid, ..
                } => {
                    if let Some(e) = start {
                        let back = [p[0] - e[0], p[1] - e[1]];
                        if q.dir[0] * back[0] + q.dir[1] * back[1] < 0.0 {
                            let what = if *rapid {
                                "Straight traverse"
                            } else {
                                "Straight feed"
                            };
                            return Err(lw.err(
                                "G41/G42",
                                lw.first_col(),
                                format!("{what} in concave corner cannot be reached by the tool without gouging (the tool's offset path would run back over this move)"),
                            ));
                        }
                    }
                    to[0] = p[0];
                    to[1] = p[1];
                    if k > 0 {
                        from[0] = p[0];
                        from[1] = p[1];
                    }
                }
                Move::Arc {
                    from,
                    to,
                    center,
                    ccw,
                    turns,
                    ..
                } => {
                    let c = xy(*center);
                    let (r1, r2) = (dist(c, xy(*to)), dist(c, p));
                    if (r1 - r2).abs() > RADII_TOL {
                        return Err(lw.err(
                            "G41/G42",
                            lw.first_col(),
                            format!("cutter compensation made an arc whose radii differ: {r1:.4} and {r2:.4} mm"),
                        ));
                    }
                    let turn = if *ccw {
                        *turns as i64
                    } else {
                        -(*turns as i64)
                    };
                    if let Some(e) = start.filter(|_| q.sweep != 0.0) {
                        if sweep(e, c, turn, p).abs() > q.sweep.abs() + self.growth_tol {
                            return Err(lw.err(
                                "G41/G42",
                                lw.first_col(),
                                "Arc move in concave corner cannot be reached by the tool without gouging",
                            ));
                        }
                    }
                    to[0] = p[0];
                    to[1] = p[1];
                    if k > 0 {
                        from[0] = p[0];
                        from[1] = p[1];
                    }
                }
                _ => {}
            }
        }
        self.queued.clear();
        self.endpoint = Some(p);
        Ok(())
    }

    /// A straight move pushed to `moves` as an open one, made in the direction `dir`.
    fn open_line(&mut self, moves: &mut Vec<Move>, m: Move, dir: [f64; 2]) {
        // (A move along Z only leaves the move before as it ended.)
        if dir != [0.0; 2] {
            self.ended = None;
        }
        moves.push(m);
        self.queued.push(Queued {
            index: moves.len() - 1,
            dir,
            sweep: 0.0,
        });
    }

    /// The open NURBS move `moves[index]` (the last in XY) cut short at its offset's
    /// parameter `s`; where it ends now. `None` where that leaves nothing of it.
    fn cut_nurbs_end(&mut self, moves: &mut [Move], index: usize, s: f64) -> Option<[f64; 2]> {
        let Move::Nurbs { knots, ctrl, .. } = &mut moves[index] else {
            unreachable!("an open NURBS is a NURBS move");
        };
        let (lo, hi) = (knots[3], knots[ctrl.len()]);
        if s <= lo {
            return None;
        }
        if s < hi {
            (*knots, *ctrl) = meet::piece(knots, ctrl, lo, s);
        }
        let last = ctrl[ctrl.len() - 1];
        if polygon_length(ctrl) < DEGENERATE_MM {
            // Cut to nothing: a move of no length, dropped with the lines cut short to
            // nothing at the program's end.
            let (line, feed) = match &moves[index] {
                Move::Nurbs { line, feed, .. } => (*line, *feed),
                _ => unreachable!("an open NURBS is a NURBS move"),
            };
            let at = [last[0], last[1], last[2]];
            moves[index] = Move::Line {
                line,
                from: at,
                to: at,
                rapid: false,
                feed,
            };
        }
        Some([last[0], last[1]])
    }

    /// The moves along Z queued after a NURBS move cut short at `x` move there too; the
    /// next move starts there.
    fn joined_at(&mut self, moves: &mut [Move], x: [f64; 2]) {
        for q in &self.queued {
            if let Move::Line { from, to, .. } = &mut moves[q.index] {
                from[..2].copy_from_slice(&x);
                to[..2].copy_from_slice(&x);
            }
        }
        self.queued.clear();
        self.endpoint = Some(x);
    }

    /// Where a concave corner after the open NURBS move `moves[index]` turns: the
    /// curve's offset cut short where it meets `other` (the offset of the move after),
    /// and the moves along Z after it moved there. Refused where they never meet, or
    /// only at the curve's start.
    fn turn_after_nurbs(
        &mut self,
        moves: &mut [Move],
        lw: &LineWords,
        index: usize,
        other: &meet::Other,
        what: &str,
    ) -> Result<[f64; 2], Diagnostic> {
        let Move::Nurbs {
            knots, ctrl, line, ..
        } = &moves[index]
        else {
            unreachable!("an open NURBS is a NURBS move");
        };
        let l = *line;
        let s = meet::spline_other(&meet::Spline { knots, ctrl }, other, false);
        let x = s.and_then(|s| self.cut_nurbs_end(moves, index, s)).ok_or_else(|| {
            lw.err(
                "G41/G42",
                lw.first_col(),
                format!("{what} in concave corner after the NURBS move of line {l} cannot be reached by the tool without gouging: its offset path does not meet the tool's path along the curve before the curve's start"),
            )
        })?;
        self.joined_at(moves, x);
        Ok(x)
    }

    /// The open moves close where they end.
    fn close(&mut self) {
        self.queued.clear();
        self.endpoint = None;
    }
}

/// An arc from `from` to `to` round `center` (turning `turn`, signed), on the exact
/// circle through both ends: the centre onto their bisector where the two radii differ
/// (a corner within [`CORNER_TOL`] of tangent), or, where the ends are too close for
/// that (a full circle), a straight move first from `from` to the circle. Pushed with
/// the source line and feed of `line`/`feed`; returns the arc's index.
fn push_arc(
    moves: &mut Vec<Move>,
    line: u32,
    feed: f64,
    from: [f64; 3],
    to: [f64; 3],
    center: [f64; 2],
    turn: i64,
) -> usize {
    let (f, t) = (xy(from), xy(to));
    let (r0, r1) = (dist(center, f), dist(center, t));
    let mut c = center;
    let mut start = from;
    if (r0 - r1).abs() > 1e-12 * r1.max(1.0) {
        let chord = dist(f, t);
        if chord > 0.1 * r1 {
            // The nearest centre on the bisector of the chord.
            let m = [(f[0] + t[0]) / 2.0, (f[1] + t[1]) / 2.0];
            let n = [-(t[1] - f[1]) / chord, (t[0] - f[0]) / chord];
            let s = (center[0] - m[0]) * n[0] + (center[1] - m[1]) * n[1];
            c = [m[0] + s * n[0], m[1] + s * n[1]];
        } else {
            let a = angle(center, f);
            start = with_z(at(center, r1, a), from[2]);
            moves.push(Move::Line {
                line,
                from,
                to: start,
                rapid: false,
                feed,
            });
        }
    }
    moves.push(Move::Arc {
        line,
        from: start,
        to,
        center: with_z(c, from[2]),
        plane: Plane::XY,
        ccw: turn > 0,
        turns: turn.unsigned_abs() as u32,
        feed,
    });
    moves.len() - 1
}

/// A straight move (`G0` when `rapid`, else `G1`) to the programmed point `p` under
/// compensation.
pub(super) fn straight(
    st: &mut State,
    lw: &LineWords,
    p: [f64; 3],
    rapid: bool,
    moves: &mut Vec<Move>,
) -> Result<(), Diagnostic> {
    let feed = if rapid { 0.0 } else { st.feed };
    let op = st.pos;
    let exit = st.exit_from.take();
    let c = st.comp.as_mut().expect("compensation is on");
    let (r, side) = (c.radius, c.side);
    let cur = c.tool;
    let line = lw.line;
    if c.first {
        let d = dist(xy(p), xy(cur));
        if d <= r {
            return Err(lw.err(
                "G41/G42",
                lw.first_col(),
                format!("Length of cutter compensation entry move is not greater than the tool radius ({d:.4} mm, radius {r:.4} mm)"),
            ));
        }
        let a = angle(xy(cur), xy(p))
            + if side == Side::Left {
                FRAC_PI_2
            } else {
                -FRAC_PI_2
            };
        let end = with_z(at(xy(p), r, a), p[2]);
        c.endpoint = Some(xy(cur));
        let from = exit.unwrap_or(cur);
        c.open_line(
            moves,
            Move::Line {
                line,
                from,
                to: end,
                rapid,
                feed,
            },
            [a.cos(), a.sin()],
        );
        c.first = false;
        c.tool = end;
        return Ok(());
    }
    if p[0] == op[0] && p[1] == op[1] {
        // Along Z only: it joins the open moves, its XY where theirs ends.
        let end = [cur[0], cur[1], p[2]];
        c.open_line(
            moves,
            Move::Line {
                line,
                from: cur,
                to: end,
                rapid,
                feed,
            },
            [0.0; 2],
        );
        c.tool = end;
        return Ok(());
    }
    let alpha = angle(xy(op), xy(p));
    let (theta, beta, gamma) = corner(side, xy(op), xy(cur), alpha);
    let end = with_z(at(xy(p), r, alpha + gamma), p[2]);
    let open_arc = c.open_arc(moves);
    let concave = !(-CORNER_TOL..=PI + CORNER_TOL).contains(&beta)
        // An "h": the tool on the right going back along a half circle round to the
        // left, or the mirror case: kept on the side it was on.
        || (beta > PI - CORNER_TOL && turns_away(c, side, open_arc));
    let mut start = cur;
    if !concave && beta > CORNER_TOL {
        // Convex: round the programmed corner.
        let mid = at(xy(op), r, alpha + gamma);
        c.end_open_at(moves, lw, xy(cur))?;
        if rapid {
            moves.push(Move::Line {
                line,
                from: cur,
                to: with_z(mid, cur[2]),
                rapid,
                feed,
            });
        } else {
            let turn = if side == Side::Left { -1 } else { 1 };
            push_arc(moves, line, feed, cur, with_z(mid, cur[2]), xy(op), turn);
        }
        c.close();
        c.endpoint = Some(mid);
        start = with_z(mid, cur[2]);
    } else if concave {
        let mid = if let Some(Ended::Nurbs { index, .. }) = c.ended {
            let other = meet::Other::Line {
                p: xy(end),
                dir: [p[0] - op[0], p[1] - op[1]],
            };
            let what = if rapid {
                "Straight traverse"
            } else {
                "Straight feed"
            };
            c.turn_after_nurbs(moves, lw, index, &other, what)?
        } else {
            if c.queued.is_empty() || c.ended.is_some() {
                return Err(ended_before_concave(lw));
            }
            let mid = match open_arc {
                None => {
                    // Line to line: back along the offset path to where the two meet.
                    let half = (beta + PI) / 2.0;
                    if half == 0.0 {
                        return Err(lw.err(
                            "G41/G42",
                            lw.first_col(),
                            "Zero degree inside corner is invalid for cutter compensation",
                        ));
                    }
                    at(xy(cur), r / half.tan(), theta + gamma)
                }
                Some((pc, oldrad, pturn)) => {
                    // Arc to line: where the line's offset meets the arc's.
                    let base = angle(xy(op), xy(p));
                    let th = if pturn > 0 {
                        base + FRAC_PI_2
                    } else {
                        base - FRAC_PI_2
                    };
                    let phi = angle(xy(op), pc);
                    let tool_in = inside(side, pturn);
                    let uncomp = if tool_in { oldrad + r } else { oldrad - r };
                    let d = uncomp * (th - phi).cos();
                    let l = (if tool_in { d - r } else { d + r }) / oldrad;
                    if !(-1.0..=1.0).contains(&l) {
                        return Err(lw.err(
                        "G41/G42",
                        lw.first_col(),
                        "Arc to straight motion makes a corner the compensated tool can't fit in without gouging",
                    ));
                    }
                    let a = (if tool_in == (pturn > 0) {
                        -l.acos()
                    } else {
                        l.acos()
                    }) + th
                        + PI;
                    at(pc, oldrad, a)
                }
            };
            c.end_open_at(moves, lw, mid)?;
            mid
        };
        start = with_z(mid, cur[2]);
    } else {
        // Straight on (within the tolerance): no corner.
        c.close();
        c.endpoint = Some(xy(cur));
    }
    c.open_line(
        moves,
        Move::Line {
            line,
            from: start,
            to: end,
            rapid,
            feed,
        },
        [p[0] - op[0], p[1] - op[1]],
    );
    c.tool = end;
    Ok(())
}

/// An arc (`m`, as [`super::arc::arc`] made it from the programmed point, its centre
/// and turn the programmed ones) under compensation. `r_form`: the arc was given by `R`
/// (its `|R|`).
pub(super) fn arc(
    st: &mut State,
    lw: &LineWords,
    m: Move,
    r_form: Option<f64>,
    moves: &mut Vec<Move>,
) -> Result<(), Diagnostic> {
    let Move::Arc {
        to: end,
        center,
        ccw,
        turns,
        feed,
        ..
    } = m
    else {
        unreachable!("arc() makes arcs");
    };
    let op = st.pos;
    let line = lw.line;
    let c = st.comp.as_mut().expect("compensation is on");
    let (r, side) = (c.radius, c.side);
    let cur = c.tool;
    let turn = if ccw { turns as i64 } else { -(turns as i64) };
    let tool_in = inside(side, turn);
    let too_big = || {
        lw.err(
            "G41/G42",
            lw.first_col(),
            format!("Tool radius not less than arc radius with cutter radius compensation (tool radius {r:.4} mm)"),
        )
    };
    let centre = xy(center);
    let arc_radius = dist(centre, xy(end));
    if c.first {
        if dist(xy(end), xy(cur)) <= r {
            return Err(lw.err(
                "G41/G42",
                lw.first_col(),
                "Radius of cutter compensation entry arc is not greater than the tool radius",
            ));
        }
        if tool_in && r_form.unwrap_or(arc_radius) <= r {
            return Err(too_big());
        }
        let g = if tool_in {
            angle(xy(end), centre)
        } else {
            angle(centre, xy(end))
        };
        let e = at(xy(end), r, g);
        // The entry arc's own centre: on the line from its end to the programmed
        // centre, as far from its start as from its end.
        let b_len = dist(xy(cur), e) / 2.0;
        let ab = angle(e, centre);
        let a_ang = angle(e, xy(cur)) - ab;
        if a_ang.cos().abs() < EQUAL_TOL {
            return Err(too_big());
        }
        let cc = at(e, b_len / a_ang.cos(), ab);
        let e3 = with_z(e, end[2]);
        let i = push_arc(moves, line, feed, cur, e3, cc, turn);
        // (LinuxCNC marks no start here: a corner after an entry arc is not checked
        // for reversing it.)
        c.endpoint = None;
        c.queued.push(Queued {
            index: i,
            dir: [0.0; 2],
            sweep: sweep(xy(cur), cc, turn, e),
        });
        c.first = false;
        c.tool = e3;
        return Ok(());
    }
    let theta = angle(xy(op), xy(cur))
        + if side == Side::Left {
            -FRAC_PI_2
        } else {
            FRAC_PI_2
        };
    let mut delta = angle(xy(op), centre);
    let alpha = if ccw {
        delta - FRAC_PI_2
    } else {
        delta + FRAC_PI_2
    };
    let mut beta = if side == Side::Left {
        theta - alpha
    } else {
        alpha - theta
    };
    if beta > 1.5 * PI {
        beta -= 2.0 * PI;
    } else if beta < -FRAC_PI_2 {
        beta += 2.0 * PI;
    }
    let gamma = if tool_in {
        if arc_radius <= r {
            return Err(too_big());
        }
        angle(xy(end), centre)
    } else {
        delta += PI;
        angle(centre, xy(end))
    };
    let new_end = with_z(at(xy(end), r, gamma), end[2]);
    let programmed_sweep = sweep(xy(op), centre, turn, xy(end));
    let concave = !(-CORNER_TOL..=PI + CORNER_TOL).contains(&beta)
        || ((beta - PI).abs() < CORNER_TOL && !tool_in);
    let start;
    if concave {
        let mid = if let Some(Ended::Nurbs { index, .. }) = c.ended {
            let other = meet::Other::Circle {
                c: centre,
                r: dist(centre, xy(new_end)),
            };
            c.turn_after_nurbs(moves, lw, index, &other, "Arc move")?
        } else {
            if c.queued.is_empty() || c.ended.is_some() {
                return Err(ended_before_concave(lw));
            }
            let mid = match c.open_arc(moves) {
                None => {
                    // Line to arc: where the line's offset meets the arc's.
                    let cy = arc_radius * (beta - FRAC_PI_2).sin();
                    let (from_centre, toward) = if tool_in {
                        (arc_radius - r, cy + r)
                    } else {
                        (arc_radius + r, cy - r)
                    };
                    let l = toward / from_centre;
                    if !(-1.0..=1.0).contains(&l) {
                        return Err(lw.err(
                        "G41/G42",
                        lw.first_col(),
                        "Arc move in concave corner cannot be reached by the tool without gouging",
                    ));
                    }
                    let a = match (tool_in, turn > 0) {
                        (true, true) => theta + l.asin(),
                        (true, false) => theta - l.asin(),
                        (false, true) => theta + PI - l.asin(),
                        (false, false) => theta + PI + l.asin(),
                    };
                    at(centre, from_centre, a)
                }
                Some((pc, oldrad, pturn)) => {
                    // Arc to arc: where the two offset circles meet.
                    let newrad = if tool_in {
                        arc_radius - r
                    } else {
                        arc_radius + r
                    };
                    let cc = dist(pc, centre);
                    if oldrad == 0.0 || cc == 0.0 {
                        return Err(lw.err(
                            "G41/G42",
                            lw.first_col(),
                            "Arc to arc motion is invalid because the arcs have the same center",
                        ));
                    }
                    let a = (oldrad * oldrad + cc * cc - newrad * newrad) / (2.0 * oldrad * cc);
                    if !(-1.0..=1.0).contains(&a) {
                        return Err(lw.err(
                        "G41/G42",
                        lw.first_col(),
                        "Arc to arc motion makes a corner the compensated tool can't fit in without gouging",
                    ));
                    }
                    let pullback = a.acos();
                    let cc_dir = angle(pc, centre);
                    let dir = if inside(side, pturn) == (turn > 0) {
                        cc_dir + pullback
                    } else {
                        cc_dir - pullback
                    };
                    at(pc, oldrad, dir)
                }
            };
            c.end_open_at(moves, lw, mid)?;
            mid
        };
        start = with_z(mid, cur[2]);
    } else if beta > CORNER_TOL {
        // Convex: round the programmed corner first.
        let mid = with_z(at(xy(op), r, delta), cur[2]);
        c.close();
        let turn = if side == Side::Left { -1 } else { 1 };
        push_arc(moves, line, feed, cur, mid, xy(op), turn);
        c.endpoint = Some(xy(mid));
        start = mid;
    } else {
        c.close();
        c.endpoint = Some(xy(cur));
        start = cur;
    }
    // A full circle (its programmed end is its start) stays a full circle: where the
    // offset arc's end comes out a little ahead of its start (a rounding, or a corner
    // within `CORNER_TOL` of tangent), it goes once more round rather than that little
    // way. (LinuxCNC makes the little arc.)
    let mut turn = turn;
    let mut programmed_sweep = programmed_sweep;
    if xy(op) == xy(end) {
        let full = 2.0 * PI * turn.unsigned_abs() as f64;
        if sweep(xy(start), centre, turn, xy(new_end)).abs() < full - PI {
            turn += turn.signum();
            // (The gouge test at the next corner measures against the turn made.)
            programmed_sweep += turn.signum() as f64 * 2.0 * PI;
        }
    }
    let i = push_arc(moves, line, feed, start, new_end, centre, turn);
    c.ended = None;
    c.queued.push(Queued {
        index: i,
        dir: [0.0; 2],
        sweep: programmed_sweep,
    });
    c.tool = new_end;
    Ok(())
}
