//! `G93` inverse-time feed: `F` says the move takes `1/F` minutes. The planner works in
//! mm/min, so each move gets the feed that covers its exact length in that time:
//! `length_mm × F`. Rapids keep their rapid rate.

use super::Move;
#[cfg(test)]
use super::Plane;
use shared::machine::MIN_FEED_MM_PER_MIN;
use shared::nurbs;
use shared::path::sub;

/// Turns the inverse-time `feed` (1/min) of each feed move into mm/min. A move whose
/// feed comes out below [`MIN_FEED_MM_PER_MIN`] is returned as its length and feed (the
/// first such): the caller refuses it.
pub(super) fn inverse_time(moves: &mut [Move]) -> Option<(f64, f64)> {
    let mut slow = None;
    for m in moves {
        let length = length_mm(m);
        match m {
            Move::Line {
                rapid: false, feed, ..
            }
            | Move::Arc { feed, .. }
            | Move::Nurbs { feed, .. } => {
                *feed *= length;
                if (feed.is_nan() || *feed < MIN_FEED_MM_PER_MIN) && slow.is_none() {
                    slow = Some((length, *feed));
                }
            }
            _ => {}
        }
    }
    slow
}

/// The exact length of a move's path (0 for moves that do not move).
pub(super) fn length_mm(m: &Move) -> f64 {
    match m {
        Move::Line { from, to, .. } => shared::path::norm(sub(*to, *from)),
        Move::Arc {
            from,
            to,
            center,
            plane,
            ccw,
            turns,
            ..
        } => {
            let sweep = crate::blocks::sweep_of(*from, *to, *center, *plane, *ccw, *turns).abs();
            let (a, b) = plane.axes();
            let r = (from[a] - center[a]).hypot(from[b] - center[b]);
            let n = plane.normal();
            (r * sweep).hypot(to[n] - from[n])
        }
        Move::Nurbs {
            degree,
            knots,
            ctrl,
            ..
        } => {
            let mut breaks = knots.clone();
            breaks.dedup();
            // The speed |C'(u)| is not a polynomial, so the quadrature is exact only
            // in the limit: 32 pieces per span put it far below a micrometre for any
            // curve a program holds.
            let subdiv = 32;
            nurbs::arc_length(&breaks, subdiv, |u| {
                shared::path::norm(nurbs::eval(*degree, knots, ctrl, u).d1)
            })
        }
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_of_a_quarter_circle_and_a_helix() {
        let quarter = Move::Arc {
            line: 1,
            from: [10.0, 0.0, 0.0],
            to: [0.0, 10.0, 0.0],
            center: [0.0; 3],
            plane: Plane::XY,
            ccw: true,
            turns: 1,
            feed: 1.0,
        };
        let l = length_mm(&quarter);
        assert!((l - 5.0 * core::f64::consts::PI).abs() < 1e-12, "{l}");
        let helix = Move::Arc {
            line: 1,
            from: [10.0, 0.0, 0.0],
            to: [10.0, 0.0, 3.0],
            center: [0.0; 3],
            plane: Plane::XY,
            ccw: false,
            turns: 2,
            feed: 1.0,
        };
        let expected = (40.0 * core::f64::consts::PI).hypot(3.0);
        assert!((length_mm(&helix) - expected).abs() < 1e-9);
    }
}
