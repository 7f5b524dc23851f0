//! Words that nothing on their line uses: refused, as LinuxCNC refuses them.
//!
//! `G1 X20 I5` is most likely a `G2` with a slip of the finger: read as written, it is a
//! straight line where a circle was meant. LinuxCNC's interpreter does not guess; it
//! refuses every argument word (`I J K R P Q L`) that no code of its line takes
//! (`check_other_codes` in rs274ngc), and so do we, naming the codes that would use it.
//! The motion a word belongs to is the line's own motion code, else the modal one where
//! the line has axis words, or centre offsets in arc mode (`I5` alone after a `G2` is a
//! full circle, in LinuxCNC as here).
//!
//! Lines inside an open curve (`G5.2 … G5.3`, `G6.2`, Fanuc `G06.2`) are read by their
//! own rules (weights `P`, orders `L`, knots `K`, `R` weights) before this is reached.

use super::{LineCodes, LineWords, Motion};
use crate::parse::Diagnostic;

/// Refuses the first word of `lw` that neither `motion` (the motion the line makes, if
/// any) nor its other codes use.
pub(super) fn check(
    lw: &LineWords,
    codes: &LineCodes,
    motion: Option<Motion>,
) -> Result<(), Diagnostic> {
    for w in lw.words {
        let (used, users) = match w.letter {
            'I' | 'J' => (
                matches!(
                    motion,
                    Some(Motion::Arc { .. } | Motion::Cubic | Motion::Quadratic)
                ),
                "G2, G3, G5 or G5.1",
            ),
            'K' => (matches!(motion, Some(Motion::Arc { .. })), "G2 or G3"),
            'R' => (matches!(motion, Some(Motion::Arc { .. })), "G2 or G3"),
            'P' => (
                matches!(motion, Some(Motion::Arc { .. } | Motion::Cubic))
                    || codes.dwell.is_some()
                    || codes.fanuc_mode.is_some()
                    || matches!(codes.path, Some((_, 640))),
                "G2, G3, G4, G5 or G64 (G05 in Fanuc programs)",
            ),
            'Q' => (
                matches!(motion, Some(Motion::Cubic))
                    || codes.fanuc_mode.is_some()
                    || matches!(codes.path, Some((_, 640))),
                "G5 or G64 (G05.1 in Fanuc programs)",
            ),
            'L' => (false, "G5.2"),
            _ => continue,
        };
        if !used {
            return Err(lw.err(
                "word",
                w.col,
                format!("{} word with no {users} to use it", w.letter),
            ));
        }
    }
    Ok(())
}
