//! The short way through a plain straight move: a line of nothing but an optional `G0`
//! or `G1`, axis words `X Y Z` and an optional `F`, each a letter and a plain number
//! (`G1 X12.5 Y-3 Z.25 F800`, nearly every line of CAM output for a 3-D surface).
//!
//! Such a line is read from its bytes and made into its move at once, without the word
//! list, the letter and modal-group checks and the motion dispatch a general line goes
//! through ([`super::execute`]): on `plain_g1` those cost about as much as reading the
//! numbers. The result is the very one the general way gives (the same numbers from the
//! same [`plain_number`], the same state changes, the same move); any line it is not
//! certain of, and any line with an error, it leaves untouched (nothing of the state
//! changed) for the general way to read from its start and report as it does.

use super::{Motion, Move, State, MAX_LINE_BYTES, MAX_POSITION_MM};
use crate::expr::plain_number;
use shared::machine::MIN_FEED_MM_PER_MIN;

/// What a plain line says, before it is applied.
struct Words {
    /// `G0` (`Some(Rapid)`) or `G1` (`Some(Linear)`), if the line names either.
    motion: Option<Motion>,
    axes: [Option<f64>; 3],
    feed: Option<f64>,
}

/// Runs the plain straight move at the start of `bytes` (a line, or the rest of the
/// text from a line's start, its end at the first `\n`) with the modal state `st`:
/// its move (if it moves) pushed to `moves` as from source line `line`, `st` updated.
/// Returns how many bytes the line has before its `\n` (or the end of `bytes`); `None`,
/// with `st` and `moves` as they were, for any line this does not take (see the page
/// above).
pub(super) fn run(st: &mut State, bytes: &[u8], line: u32, moves: &mut Vec<Move>) -> Option<usize> {
    // Only a state in which such a line is a plain straight move: no curve open (its
    // lines are control points), no inverse time (its F is a time, needed on every
    // move), no Fanuc curve after which axis words open another, no cutter compensation
    // (on, or just turned off: its move starts off the programmed path).
    if st.fanuc.is_some()
        || st.g62.is_some()
        || st.nurbs.is_some()
        || st.inverse_time
        || st.comp.is_some()
        || st.exit_from.is_some()
    {
        return None;
    }
    let (words, len) = words(bytes)?;
    // A line longer than LinuxCNC reads is refused the general way.
    if len > MAX_LINE_BYTES {
        return None;
    }
    let motion = match words.motion {
        Some(m) => m,
        None if matches!(st.motion, Motion::Rapid | Motion::Linear) => st.motion,
        None => return None,
    };
    // A line without axis words moves nothing (it sets a mode or a feed): rare, left to
    // the general way.
    if words.axes.iter().all(Option::is_none) {
        return None;
    }
    let unit = if st.inch { 25.4 } else { 1.0 };
    // As `execute` sets the feed (never negative) before the move needs it.
    let feed = match words.feed {
        Some(f) if f < 0.0 => return None,
        Some(f) => f * unit,
        None => st.feed,
    };
    // `need_feed`: above zero and not below the slowest feed (a feed is never NaN: no
    // value read is).
    if motion == Motion::Linear && feed < MIN_FEED_MM_PER_MIN {
        return None;
    }
    // As `target` computes it, refused (by the general way) beyond the travel.
    let mut to = st.pos;
    for (i, v) in words.axes.iter().enumerate() {
        if let Some(v) = v {
            to[i] = if st.absolute {
                v * unit
            } else {
                st.pos[i] + v * unit
            };
            if to[i].is_nan() || to[i].abs() > MAX_POSITION_MM {
                return None;
            }
        }
    }
    // Nothing can fail any more: the line's effects, in `execute`'s order.
    st.feed = feed;
    st.motion = motion;
    st.g5_tangent = None;
    let rapid = motion == Motion::Rapid;
    if st.pos != to {
        moves.push(Move::Line {
            line,
            from: st.pos,
            to,
            rapid,
            feed: if rapid { 0.0 } else { st.feed },
        });
    }
    st.pos = to;
    Some(len)
}

/// The words of a plain straight-move line at the start of `bytes`, and the length of
/// the line (up to its `\n` or the end of `bytes`); `None` for any other line. Blanks
/// and letters as [`crate::parse`]'s plain-word reader takes them (a `\r` before the
/// `\n` is a blank there too), each letter once.
fn words(bytes: &[u8]) -> Option<(Words, usize)> {
    // `char::is_whitespace` in ASCII but the line's end.
    let blank = |c: u8| matches!(c, b' ' | b'\t' | b'\x0b'..=b'\r');
    let mut w = Words {
        motion: None,
        axes: [None; 3],
        feed: None,
    };
    let mut g = false;
    let mut i = 0;
    loop {
        while bytes.get(i).is_some_and(|&c| blank(c)) {
            i += 1;
        }
        let letter = match bytes.get(i) {
            None | Some(b'\n') => return Some((w, i)),
            Some(&c) => c.to_ascii_uppercase(),
        };
        i += 1;
        let sign = bytes.get(i).copied().filter(|c| matches!(c, b'-' | b'+'));
        i += usize::from(sign.is_some());
        let (value, len) = plain_number(bytes.get(i..)?)?;
        i += len;
        let value = if sign == Some(b'-') { -value } else { value };
        let slot = match letter {
            b'X' => &mut w.axes[0],
            b'Y' => &mut w.axes[1],
            b'Z' => &mut w.axes[2],
            b'F' => &mut w.feed,
            b'G' if !g => {
                g = true;
                // `G0`, `G00`, `G0.0` and `G1`, `G01`, `G1.0`; any other code (and a
                // signed one, which no code is) the general way reads.
                w.motion = match (sign, value) {
                    (None, 0.0) => Some(Motion::Rapid),
                    (None, 1.0) => Some(Motion::Linear),
                    _ => return None,
                };
                continue;
            }
            _ => return None,
        };
        if slot.is_some() {
            return None;
        }
        *slot = Some(value);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_lines_and_their_ends() {
        let (w, len) = words(b"G1 X12.5 Y-3 Z.25 F800\nG0 X0").unwrap();
        assert_eq!(len, 22);
        assert_eq!(w.motion, Some(Motion::Linear));
        assert_eq!(w.axes, [Some(12.5), Some(-3.0), Some(0.25)]);
        assert_eq!(w.feed, Some(800.0));
        let (w, len) = words(b"  g00x1y+2\r\n").unwrap();
        assert_eq!(
            (w.motion, w.axes, len),
            (Some(Motion::Rapid), [Some(1.0), Some(2.0), None], 11)
        );
        let (w, len) = words(b"X1").unwrap();
        assert_eq!((w.motion, w.axes[0], len), (None, Some(1.0), 2));
        // Anything else is left to the general way.
        for other in [
            "G2 X1 Y1 I1",
            "G1 G1 X1",
            "G-1 X1",
            "G1 X1 X2",
            "G1 X1 (comment)",
            "G1 X[1]",
            "G1 X#1",
            "N10 G1 X1",
            "G1 X1 M3",
            "G1 X 1",
            "G1 X1..2",
            "/G1 X1",
            "%",
            "G1 X1 Y2 é",
        ] {
            assert!(words(other.as_bytes()).is_none(), "{other}");
        }
    }
}
