//! The O-word flow of a running program: subroutine calls and returns, `if`/`elseif`/
//! `else`, `while`, `do … while`, `repeat`, `break` and `continue`, as LinuxCNC runs
//! them, over the program's lines and those of the subroutine files it calls joined
//! after them ([`super::subfile`]).

use super::subfile::Missing;
use crate::parse::{Diagnostic, Flow, OKind, OWord, Param, Params};

/// A subroutine call in progress.
struct Call {
    /// Line index to continue at after the return.
    ret: usize,
    /// The caller's `#1..#30`, restored on return as LinuxCNC does.
    saved: [f64; 30],
    /// Repeat counters of the caller's loops.
    repeats: usize,
}

/// Deepest subroutine nesting (LinuxCNC's call stack is of this size too).
const MAX_CALL_DEPTH: usize = 50;

/// Backward jumps (loop turns and calls) a program may make before `check` calls it
/// endless. LinuxCNC would run on forever; a checker must answer.
const MAX_JUMPS: u64 = 1_000_000;

/// Lines a program may run beyond its own length (lines run again by loops and calls).
/// Turns alone do not bound the work: a million turns of a loop with a hundred lines
/// in it would keep `check` busy for minutes. Five million lines take a few seconds.
const MAX_LINES_AGAIN: usize = 5_000_000;

/// The O-word flow of a running program: how its blocks connect (see [`Flow`]), and the
/// calls and repeat loops in progress.
pub(super) struct Runner {
    o_words: Vec<Option<Box<OWord>>>,
    /// The program's lines, its subroutine files' included.
    lines: usize,
    flow: Flow,
    calls: Vec<Call>,
    /// (repeat line, turns left) of the repeat loops being run.
    repeats: Vec<(usize, f64)>,
    /// The `elseif`/`else` line a false condition jumped to, to be tested or entered.
    branch: Option<usize>,
    jumps: u64,
    /// Lines run so far, the first time and again.
    lines_run: usize,
    /// Called labels no file defines, with why (see [`super::subfile::load`]).
    missing: Missing,
}

impl Runner {
    pub(super) fn new(
        o_words: Vec<Option<Box<OWord>>>,
        lines: usize,
        flow: Flow,
        missing: Missing,
    ) -> Self {
        Runner {
            o_words,
            lines,
            flow,
            calls: Vec::new(),
            repeats: Vec::new(),
            branch: None,
            jumps: 0,
            lines_run: 0,
            missing,
        }
    }

    /// The innermost line in progress before index `end`: a line there itself, or the
    /// call there that led to it (the program's own lines come before `end`).
    pub(super) fn line_before(&self, here: usize, end: usize) -> usize {
        if here < end {
            return here;
        }
        self.calls
            .iter()
            .rev()
            .map(|c| c.ret - 1)
            .find(|&call| call < end)
            .unwrap_or(here)
    }

    /// Counts line `here` (0-based) as run; the error that stops the program when it
    /// has run too many lines again (an endless loop, or one far too long to check).
    pub(super) fn count_line(&mut self, here: usize) -> Result<(), Diagnostic> {
        self.lines_run += 1;
        if self.lines_run <= self.lines.saturating_add(MAX_LINES_AGAIN) {
            return Ok(());
        }
        Err(Diagnostic {
            file: None,
            line: here as u32 + 1,
            col: 1,
            rule: "O-word",
            message: format!(
                "more than {MAX_LINES_AGAIN} lines run again by loops and calls: is a loop endless?"
            ),
        })
    }

    /// Where to go after line `here` (0-based) could not be read.
    pub(super) fn unreadable(&mut self, here: usize) -> usize {
        let mut pc = here + 1;
        // A line that cannot be read counts as false / zero turns, so that a
        // broken condition ends its loop instead of spinning.
        match (o_word(&self.o_words, here), self.flow.link(here)) {
            (Some(o), Some(to)) if o.kind == OKind::ElseIf && self.branch != Some(here) => {
                pc = endif_of(&self.o_words, &self.flow.link, here).map_or(to, |e| e + 1);
            }
            (Some(o), Some(to)) if o.kind == OKind::Sub => pc = to + 1,
            (Some(o), Some(to)) if matches!(o.kind, OKind::If | OKind::ElseIf) => {
                pc = to;
                self.branch = Some(to);
            }
            (Some(o), Some(to))
                if matches!(o.kind, OKind::While | OKind::Repeat) && !self.flow.closes_do(here) =>
            {
                pc = to + 1;
            }
            _ => {}
        }
        pc
    }

    /// Runs the O-word `o` of line `here` (0-based); returns the next line to run, or
    /// `None` when the program must stop.
    pub(super) fn step(
        &mut self,
        here: usize,
        o: &OWord,
        params: &mut Params,
        errors: &mut Vec<Diagnostic>,
    ) -> Option<usize> {
        let line = here as u32 + 1;
        let mut pc = here + 1;
        let link = self.flow.link(here);
        let cond = o.args.first().is_some_and(|v| *v != 0.0);
        let mut back = false;
        match o.kind {
            OKind::Sub => pc = link.map_or(pc, |e| e + 1),
            OKind::EndSub | OKind::Return => {
                if let Some(c) = self.calls.pop() {
                    for (i, v) in c.saved.iter().enumerate() {
                        params.set(&Param::Numbered(i as u32 + 1), *v);
                    }
                    params.pop_frame();
                    self.repeats.truncate(c.repeats);
                    if let Some(v) = o.args.first() {
                        params.set(&Param::Named("_value".into()), *v);
                    }
                    params.set(
                        &Param::Named("_value_returned".into()),
                        f64::from(u8::from(!o.args.is_empty())),
                    );
                    pc = c.ret;
                }
            }
            OKind::Call => match self.flow.subs.get(&o.label) {
                None => errors.push(Diagnostic {
                    file: None,
                    line,
                    col: o.col,
                    rule: "O-word",
                    message: match self.missing.get(&o.label) {
                        Some(why) => format!("o{} call: {why}", o.label),
                        None => {
                            format!("o{} call: no subroutine o{} in this file", o.label, o.label)
                        }
                    },
                }),
                Some(_) if self.calls.len() >= MAX_CALL_DEPTH => errors.push(Diagnostic {
                    file: None,
                    line,
                    col: o.col,
                    rule: "O-word",
                    message: format!("subroutines nested more than {MAX_CALL_DEPTH} deep"),
                }),
                Some(&sub) => {
                    let saved = core::array::from_fn(|i| params.numbered(i as u32 + 1));
                    self.calls.push(Call {
                        ret: pc,
                        saved,
                        repeats: self.repeats.len(),
                    });
                    params.push_frame();
                    for i in 0..30 {
                        params.set(
                            &Param::Numbered(i as u32 + 1),
                            o.args.get(i).copied().unwrap_or(0.0),
                        );
                    }
                    pc = sub + 1;
                    back = true;
                }
            },
            // Falling onto a later branch: the branch before it ran, the `if` is done.
            OKind::ElseIf | OKind::Else if self.branch != Some(here) => {
                pc = endif_of(&self.o_words, &self.flow.link, here).map_or(pc, |e| e + 1);
            }
            OKind::If | OKind::ElseIf => {
                if !cond {
                    pc = link.unwrap_or(pc);
                    self.branch = link;
                }
            }
            OKind::Else | OKind::EndIf | OKind::Do | OKind::ProgramNumber => {}
            OKind::While if self.flow.closes_do(here) => {
                if cond {
                    pc = link.map_or(pc, |d| d + 1);
                    back = true;
                }
            }
            OKind::While => {
                if !cond {
                    pc = link.map_or(pc, |e| e + 1);
                }
            }
            OKind::EndWhile => {
                pc = link.unwrap_or(pc);
                back = true;
            }
            OKind::Repeat => {
                let turns = o.args.first().copied().unwrap_or(0.0);
                if turns >= 1.0 {
                    self.repeats.push((here, turns));
                } else {
                    pc = link.map_or(pc, |e| e + 1);
                }
            }
            OKind::EndRepeat => {
                if let Some((head, left)) = self.repeats.last_mut() {
                    *left -= 1.0;
                    if *left >= 1.0 {
                        pc = *head + 1;
                        back = true;
                    } else {
                        self.repeats.pop();
                    }
                }
            }
            OKind::Break | OKind::Continue => {
                if let Some(head) = link {
                    let end = self.flow.link(head).unwrap_or(here);
                    // Repeat loops inside the loop left or restarted are done with
                    // (LinuxCNC lets break and continue reach out of them).
                    let floor = self.calls.last().map_or(0, |c| c.repeats);
                    while self.repeats.len() > floor
                        && self
                            .repeats
                            .last()
                            .is_some_and(|(h, _)| *h > head && *h < end)
                    {
                        self.repeats.pop();
                    }
                    if o.kind == OKind::Break {
                        pc = end + 1;
                    } else {
                        // `continue` goes to the loop's test: a while's head, a do's
                        // closing while.
                        let is_while = !self.flow.closes_do(end);
                        pc = if is_while { head } else { end };
                        back = true;
                    }
                }
            }
        }
        if back {
            self.jumps += 1;
            if self.jumps > MAX_JUMPS {
                errors.push(Diagnostic {
                    file: None,
                    line,
                    col: o.col,
                    rule: "O-word",
                    message: format!(
                        "more than {MAX_JUMPS} loop turns and calls: is this loop endless?"
                    ),
                });
                return None;
            }
        }
        Some(pc)
    }
}

/// The O-word of line `i` (a program without any has an empty list).
fn o_word(o_words: &[Option<Box<OWord>>], i: usize) -> Option<&OWord> {
    o_words.get(i).and_then(|o| o.as_deref())
}

/// The `endif` of the `if` block whose branch line is `at`.
fn endif_of(
    o_words: &[Option<Box<OWord>>],
    link: &[Option<usize>],
    mut at: usize,
) -> Option<usize> {
    // Branch links only go forward, so this ends.
    loop {
        let next = link.get(at).copied().flatten()?;
        if next <= at {
            return None;
        }
        if o_word(o_words, next).is_some_and(|o| o.kind == OKind::EndIf) {
            return Some(next);
        }
        at = next;
    }
}
