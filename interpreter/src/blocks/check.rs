//! What `cnc check` asks of the planned blocks, the very ones that are sent, before
//! anything moves: each passes the receiver's validation, its exact path stays within
//! the machine's travel (the soft limits `axes.*.min_mm`/`max_mm`, judged by
//! [`shared::travel`], the same function the interpolator runs on every block it
//! receives, so the two agree exactly), and the program ends within a time a run can
//! count ([`MAX_PROGRAM_S`]). The machine's start position (the origin) must be within
//! the travel too.
//!
//! A refused block is named by its source line; a travel problem by the column of the
//! word of the axis that leaves the travel, where the line has one.

use super::Block;
use crate::parse::Diagnostic;
use shared::machine::{shown, MIN_FEED_MM_PER_MIN};
use shared::protocol::{BlockKind, FLAG_RAPID};
use shared::travel::{self, TravelError};
use shared::Machine;

/// The longest a program may take, s: ten years. A run counts its cycles and its time
/// in integer nanoseconds, 584 years at most; a program that takes longer than this (a
/// helix of ten thousand turns at the slowest feed) is surely a mistake.
pub const MAX_PROGRAM_S: f64 = 10.0 * 365.25 * 86_400.0;

/// Where the machine stands when a program starts (the interpreter's origin).
pub const START_MM: [f64; 3] = [0.0; 3];

/// Checks the blocks of a program one at a time, in program order (a problem of time
/// names the line by which the program has taken too long), and gives every problem
/// found as a [`Diagnostic`].
pub struct Checker<'a> {
    text: &'a str,
    machine: &'a Machine,
    /// The shortest time the blocks seen so far take, s: their lengths at their feed
    /// caps and their dwells.
    least_time_s: f64,
    time_reported: bool,
    /// Problems found, with the axis whose word names the column of a travel problem.
    found: Vec<(Diagnostic, Option<usize>)>,
}

impl<'a> Checker<'a> {
    /// A checker of the blocks of the program `text` (its diagnostics name its lines).
    pub fn new(text: &'a str, machine: &'a Machine) -> Self {
        let mut c = Checker {
            text,
            machine,
            least_time_s: 0.0,
            time_reported: false,
            found: Vec::new(),
        };
        if let Some(message) = start_outside(machine) {
            c.found.push((
                Diagnostic {
                    file: None,
                    line: 1,
                    col: 1,
                    rule: "travel",
                    message,
                },
                None,
            ));
        }
        c
    }

    /// Checks block `seq`, `b`, as planned.
    pub fn block(&mut self, seq: usize, b: &Block) {
        let line = b.source_line();
        let problem = |rule: &'static str, message: String| Diagnostic {
            file: None,
            line,
            col: 1,
            rule,
            message,
        };
        let kind = match b.validate(seq as u64) {
            Ok(k) => k,
            Err(e) => {
                self.found.push((problem("internal", e.to_string()), None));
                return;
            }
        };
        let travelled = match b {
            Block::Straight(s) => travel::check_point(s.from, &self.machine.axes)
                .and_then(|()| travel::check_point(s.to, &self.machine.axes)),
            Block::Whole(c) => travel::check_block(c, &self.machine.axes),
        };
        if let Err(e) = travelled {
            self.found
                .push((problem("travel", travel_message(&e, b)), Some(e.axis)));
        }
        let cap = match b {
            Block::Straight(s) => s.feed_mm_per_min,
            Block::Whole(c) => c.feed_mm_per_min,
        };
        if kind == BlockKind::Motion && (cap.is_nan() || cap < MIN_FEED_MM_PER_MIN) {
            self.found.push((
                problem(
                    "feed",
                    format!(
                        "the shape of this path lets the tool move at {} mm/min at most, \
                         below the slowest feed, {MIN_FEED_MM_PER_MIN} mm/min: it turns \
                         too sharply within too little length (a curve with a kink, or \
                         two knots nearly equal)",
                        shown(cap)
                    ),
                ),
                None,
            ));
            return;
        }
        self.least_time_s += match (kind, b) {
            (BlockKind::Dwell, Block::Whole(c)) => c.dwell_ns as f64 * 1e-9,
            (BlockKind::Motion, Block::Straight(s)) => least_time_s(s.length_mm, s.feed_mm_per_min),
            (BlockKind::Motion, Block::Whole(c)) => least_time_s(c.length_mm, c.feed_mm_per_min),
            _ => 0.0,
        };
        if (self.least_time_s.is_nan() || self.least_time_s > MAX_PROGRAM_S) && !self.time_reported
        {
            self.time_reported = true;
            self.found.push((
                problem(
                    "time",
                    format!(
                        "the program takes at least {} s up to here (at its feeds, \
                         without stops), longer than ten years ({} s): a feed too slow \
                         for the path, or a helix of too many turns",
                        shown(self.least_time_s),
                        shown(MAX_PROGRAM_S)
                    ),
                ),
                None,
            ));
        }
    }

    /// No problem found so far.
    pub fn is_clean(&self) -> bool {
        self.found.is_empty()
    }

    /// Every problem found, in the order of the lines (the start position first), each
    /// travel problem at the column of its axis word on its line when it has one.
    pub fn finish(self) -> Vec<Diagnostic> {
        let mut found = self.found;
        if found.is_empty() {
            return Vec::new();
        }
        found.sort_by_key(|(d, _)| d.line);
        let mut lines = self.text.split('\n');
        let mut at = 0u32;
        let mut current = "";
        found
            .into_iter()
            .map(|(mut d, axis)| {
                if let Some(axis) = axis {
                    while at < d.line {
                        current = lines.next().unwrap_or("");
                        at += 1;
                    }
                    d.col = axis_word_col(current, ['X', 'Y', 'Z'][axis.min(2)]);
                }
                d
            })
            .collect()
    }
}

/// Why the machine's start, the origin, is outside its travel, if it is.
pub fn start_outside(machine: &Machine) -> Option<String> {
    let e = travel::check_point(START_MM, &machine.axes).err()?;
    let lower = e.axis_name().to_ascii_lowercase();
    Some(format!(
        "the machine starts at the origin (0, 0, 0), {} mm {} the travel limit of {} \
         at {} mm (axes.{lower}.{} in the machine file): programs start there",
        e.excess_mm(),
        match e.side {
            travel::Side::Min => "below",
            travel::Side::Max => "above",
        },
        e.axis_name(),
        e.limit_mm,
        e.side.key()
    ))
}

/// The least time a motion of `length_mm` takes at `feed_mm_per_min`, s.
fn least_time_s(length_mm: f64, feed_mm_per_min: f64) -> f64 {
    length_mm / feed_mm_per_min * 60.0
}

/// What a travel problem says, with the kind of move it is.
fn travel_message(e: &TravelError, b: &Block) -> String {
    let rapid = match b {
        Block::Straight(s) => s.flags & FLAG_RAPID != 0,
        Block::Whole(c) => c.flags & FLAG_RAPID != 0,
    };
    let what = if rapid { "rapid move" } else { "move" };
    format!("this {what} leaves the machine's travel: {e}")
}

/// The 1-based column (in characters) of the word of `axis` on `line`: outside
/// comments and brackets, the letter in either case. The line's first word when it has
/// none (an arc's bulge beyond a limit on an axis it does not name), or 1.
fn axis_word_col(line: &str, axis: char) -> u32 {
    let line = line.strip_suffix('\r').unwrap_or(line);
    let mut depth = 0u32;
    let mut comment = false;
    let mut first = None;
    for (i, c) in line.chars().enumerate() {
        let col = i as u32 + 1;
        match c {
            '(' if depth == 0 => comment = true,
            ')' if comment => comment = false,
            ';' if !comment && depth == 0 => break,
            _ if comment => {}
            '[' => depth += 1,
            ']' => depth = depth.saturating_sub(1),
            _ if depth > 0 => {}
            c if c.is_ascii_alphabetic() => {
                first.get_or_insert(col);
                if c.to_ascii_uppercase() == axis {
                    return col;
                }
            }
            _ => {}
        }
    }
    first.unwrap_or(1)
}

#[cfg(test)]
mod tests {
    use super::axis_word_col;

    #[test]
    fn the_axis_word_is_found_outside_comments_and_brackets() {
        assert_eq!(axis_word_col("G0 X10 Y5", 'Y'), 8);
        assert_eq!(axis_word_col("G1 F[EXP[1]] x5", 'X'), 14);
        assert_eq!(axis_word_col("(X here) G0 X1", 'X'), 13);
        assert_eq!(axis_word_col("  G2 X1 I5", 'Y'), 3);
        assert_eq!(axis_word_col("", 'Z'), 1);
    }
}
