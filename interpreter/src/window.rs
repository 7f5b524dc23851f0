//! A program read, built, planned and checked window by window, so that a long one is
//! never held whole: the reader hands its moves over in batches
//! ([`program::interpret_batched`]), and each window of moves, cut where the machine is
//! at rest whatever comes before or after, is blended, built into blocks, planned and
//! checked on its own, then handed on and dropped.
//!
//! # Where a window may end
//!
//! The plan of a block depends on its neighbours only through the junctions the machine
//! passes without stopping: a junction speed, the loads of close kinks, a curve run's
//! share rounds, a `G64 P` blend and the chain of corners it is weighed with. At a rest
//! the plan is cut in two already: the speed there is 0 from both sides, the backward
//! pass starts again from it, runs of kinks end there. So a window ends only right
//! before a straight move whose junction with the motion before it is a rest the plan
//! does not choose, known from the two moves alone:
//!
//! * a dwell (a block that does not move) or a programmed stop (`M0`, `M1`) lies between;
//! * a rapid meets a feed move (the planner stops between them);
//! * the mode is `G61.1` (every move ends at rest);
//! * the two are straight and turn by more than the machine's `corner_angle_deg` (by a
//!   margin, so rounding cannot make it a kink in the plan), and no `G64 P` blend can be
//!   put there (only between two feed lines under a tolerance, with nothing but
//!   path-mode changes between them: [`crate::blocks::blend`]).
//!
//! The path mode in force where a window starts is put before its moves (a path-mode
//! change makes no block), so that it blends and stops as the whole program would.
//!
//! A program with no such place for a long stretch (a smooth spiral of short lines, a
//! long curve) is held as one window over that stretch: bounded memory there needs a
//! window cut at speed, which this does not do yet.
//!
//! Windowed, the blocks are those of the whole program planned at once, bit for bit
//! (`tests::windows_plan_as_the_whole_program`, every program of the repository on both
//! machines, cut at every place it may be).

use crate::blocks::{self, check::Checker, Block};
use crate::parse::Diagnostic;
use crate::program::{self, Move, PathControl};
use shared::Machine;

/// Moves read before the reader hands them over, and about the fewest a window holds
/// (it ends at the last place it may in what has been read).
pub const BATCH_MOVES: usize = 4096;

/// A program read, checked and planned ([`plan`]): what the reports say about it.
#[derive(Debug, Clone, Default)]
pub struct Planned {
    /// The dialect it was read in ([`program::Program::dialect`]).
    pub dialect: program::Dialect,
    /// Its `(MSG, …)` texts with their lines.
    pub messages: Vec<(u32, String)>,
    /// It turns cutter radius compensation on ([`program::Program::compensated`]).
    pub compensated: bool,
    /// How many blocks it is.
    pub blocks: usize,
    /// What the machine changes of what the program asks ([`crate::process::notes`]).
    pub notes: Vec<(u32, String)>,
    /// How many windows it was planned in.
    pub windows: usize,
}

/// How [`plan`] reads and where it hands the blocks.
pub struct Stream<'a> {
    /// Moves to read before a window is looked for ([`BATCH_MOVES`]).
    pub every: usize,
    /// Takes each window's planned and checked blocks, in program order, with the
    /// sequence number of its first: only while nothing wrong has been found, so what
    /// it is handed is good so far (the program as a whole is good only once [`plan`]
    /// returns it so). Block 0 handed again means the program is being read again from
    /// its start, and what came before is to be dropped: a `G4 P` dwell read before the
    /// program showed itself Fanuc's was in milliseconds.
    pub blocks: &'a mut dyn FnMut(Vec<Block>, usize),
    /// Told of the stretches of the text the reading is done with
    /// ([`program::Batches::release`]).
    pub release: &'a mut dyn FnMut(usize, usize),
}

/// Reads, checks, builds and plans `text` window by window (see the module page),
/// handing the blocks on as [`Stream`] says; every problem of the program, as
/// [`crate::process::check_with`] finds them.
pub fn plan(
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
    stream: Stream<'_>,
) -> Result<Planned, Vec<Diagnostic>> {
    let Stream {
        every,
        blocks: hand,
        release,
    } = stream;
    let (planned, in_doubt) = plan_once(text, opts, machine, period_ns, every, hand, release)?;
    // A `G4 P` read as seconds before the program showed itself Fanuc's was
    // milliseconds: read again as Fanuc's (what is handed on starts again at block 0).
    if in_doubt && planned.dialect == program::Dialect::Fanuc && opts.dialect.is_none() {
        let fanuc = program::Options {
            dialect: Some(program::Dialect::Fanuc),
            ..opts.clone()
        };
        return plan_once(text, &fanuc, machine, period_ns, every, hand, release).map(|(p, _)| p);
    }
    Ok(planned)
}

/// [`plan`] read once as `opts` say; and whether a dwell in doubt was handed on.
fn plan_once(
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
    every: usize,
    hand: &mut dyn FnMut(Vec<Block>, usize),
    release: &mut dyn FnMut(usize, usize),
) -> Result<(Planned, bool), Vec<Diagnostic>> {
    let mut w = Windows {
        machine,
        period_ns,
        pending: Vec::new(),
        scan: Scan::default(),
        seq: 0,
        windows: 0,
        checker: Checker::new(text, machine),
        feeds: crate::process::FeedNotes::new(machine),
        hand,
        clean: true,
    };
    let mut in_doubt = false;
    let read = {
        let mut sink = |moves: Vec<Move>, r: program::Read| {
            w.clean &= r.clean;
            in_doubt |= r.in_doubt;
            w.take(moves);
        };
        program::interpret_batched(
            text,
            opts,
            program::Batches {
                every: every.max(1),
                sink: &mut sink,
                release,
            },
        )
    };
    let mut prog = read?;
    w.take(std::mem::take(&mut prog.moves));
    let rest = std::mem::take(&mut w.pending);
    w.plan(rest);
    let bad = w.checker.finish();
    if !bad.is_empty() {
        return Err(bad);
    }
    let planned = Planned {
        dialect: prog.dialect,
        messages: prog.messages,
        compensated: prog.compensated,
        blocks: w.seq,
        notes: w.feeds.finish("move"),
        windows: w.windows,
    };
    Ok((planned, in_doubt))
}

/// The moves read and not yet planned, and where the windows go.
struct Windows<'a, 'h> {
    machine: &'a Machine,
    period_ns: u64,
    /// Moves read and not yet planned; the first may be the path mode in force before
    /// them (put there when the window before was cut).
    pending: Vec<Move>,
    scan: Scan,
    /// Blocks planned so far: the sequence number of the next.
    seq: usize,
    windows: usize,
    checker: Checker<'a>,
    feeds: crate::process::FeedNotes,
    hand: &'h mut dyn FnMut(Vec<Block>, usize),
    /// Nothing wrong found so far (by the reader or the checks).
    clean: bool,
}

/// What the look for a window's end knows of the moves looked at so far.
#[derive(Default)]
struct Scan {
    /// Moves of `pending` looked at.
    upto: usize,
    /// The path mode in force after them (none: none asked for yet).
    mode: Option<Move>,
    /// The last motion (a line, an arc, a curve or a dwell) looked at, its index in
    /// `pending`, and the mode in force at it.
    last: Option<(usize, Option<PathControl>)>,
    /// Only path-mode changes since that motion (a `G64 P` blend may join it to the
    /// next line).
    only_modes: bool,
    /// A programmed stop since that motion.
    stopped: bool,
    /// The places a window may end, in order (indices of `pending`), each with the path
    /// mode in force there.
    cuts: Vec<(usize, Option<Move>)>,
}

impl Windows<'_, '_> {
    /// Takes the moves read next, and plans every window they complete.
    fn take(&mut self, moves: Vec<Move>) {
        for m in &moves {
            if let Move::Line {
                line,
                feed,
                rapid: false,
                ..
            }
            | Move::Arc { line, feed, .. }
            | Move::Nurbs { line, feed, .. } = m
            {
                self.feeds.push(*line, *feed);
            }
        }
        if self.pending.is_empty() {
            self.pending = moves;
        } else {
            self.pending.extend(moves);
        }
        self.look();
        let cuts = std::mem::take(&mut self.scan.cuts);
        let Some(&(last, _)) = cuts.last() else {
            return;
        };
        // Each window to its cut; what follows the last stays, the mode in force put
        // before it.
        let mut rest = self.pending.split_off(last);
        let mut done = std::mem::take(&mut self.pending);
        let mut windows = Vec::with_capacity(cuts.len());
        for &(at, _) in cuts.iter().rev() {
            windows.push(done.split_off(at));
        }
        windows.push(done);
        windows.reverse();
        // (The last, from the last cut on, is empty: what follows it is `rest`.)
        windows.pop();
        // `windows[0]` is what came before the first cut, `windows[k]` starts at cut
        // `k - 1`.
        let mode = cuts.last().and_then(|(_, m)| m.clone());
        let off = usize::from(mode.is_some());
        if let Some(m) = mode {
            rest.insert(0, m);
        }
        // What was looked at keeps its place in what is left (the motion last looked
        // at is at the last cut or after it).
        let shift = |i: usize| i - last + off;
        self.scan.upto = shift(self.scan.upto);
        self.scan.last = self.scan.last.map(|(i, c)| (shift(i), c));
        self.pending = rest;
        for (k, mut window) in windows.into_iter().enumerate() {
            if let Some(Some(m)) = k.checked_sub(1).map(|c| cuts[c].1.clone()) {
                window.insert(0, m);
            }
            self.plan(window);
        }
    }

    /// Looks through the moves not yet looked at for the places a window may end.
    fn look(&mut self) {
        let corner_cos = self.machine.corner_angle_deg.to_radians().cos();
        let s = &mut self.scan;
        for k in s.upto..self.pending.len() {
            let m = &self.pending[k];
            match m {
                Move::PathMode { .. } => {
                    s.mode = Some(m.clone());
                    continue;
                }
                Move::Stop { .. } => {
                    s.stopped = true;
                    s.only_modes = false;
                    continue;
                }
                Move::Spindle { .. } => {
                    s.only_modes = false;
                    continue;
                }
                Move::End { .. } => continue,
                _ => {}
            }
            let mode = s.mode.as_ref().and_then(|m| match m {
                Move::PathMode { control, .. } => Some(*control),
                _ => None,
            });
            if let (Move::Line { .. }, Some((p, p_mode))) = (m, s.last) {
                if at_rest(
                    &self.pending[p],
                    m,
                    p_mode,
                    s.only_modes,
                    s.stopped,
                    corner_cos,
                ) {
                    s.cuts.push((k, s.mode.clone()));
                }
            }
            s.last = Some((k, mode));
            s.only_modes = true;
            s.stopped = false;
        }
        s.upto = self.pending.len();
    }

    /// Builds, plans and checks one window of moves, and hands its blocks on.
    fn plan(&mut self, window: Vec<Move>) {
        if window.is_empty() {
            return;
        }
        let mut blocks = blocks::build(&window, self.machine);
        drop(window);
        if blocks.is_empty() {
            return;
        }
        blocks::plan_and(&mut blocks, self.machine, self.period_ns, |_, _| {});
        for (i, b) in blocks.iter().enumerate() {
            self.checker.block(self.seq + i, b);
        }
        self.clean &= self.checker.is_clean();
        let first = self.seq;
        self.seq += blocks.len();
        self.windows += 1;
        if self.clean {
            (self.hand)(blocks, first);
        }
    }
}

/// Is the junction between motion `p` (in path mode `p_mode`) and the straight move
/// `k` after it a rest of every plan? `only_modes`: only path-mode changes lie between
/// them; `stopped`: a programmed stop does.
fn at_rest(
    p: &Move,
    k: &Move,
    p_mode: Option<PathControl>,
    only_modes: bool,
    stopped: bool,
    corner_cos: f64,
) -> bool {
    let Move::Line {
        from: k0,
        to: k1,
        rapid: k_rapid,
        ..
    } = k
    else {
        return false;
    };
    if stopped || matches!(p, Move::Dwell { .. }) {
        return true;
    }
    if p_mode == Some(PathControl::ExactStop) {
        return true;
    }
    let Move::Line {
        from: p0,
        to: p1,
        rapid: p_rapid,
        ..
    } = p
    else {
        return false;
    };
    if p_rapid != k_rapid {
        return true;
    }
    let blendable = !p_rapid
        && only_modes
        && matches!(
            p_mode,
            Some(PathControl::Blend { tolerance_mm: Some(t), .. }) if t > 0.0
        );
    if blendable {
        return false;
    }
    let (a, b) = (sub(*p1, *p0), sub(*k1, *k0));
    let (la, lb) = (shared::path::norm(a), shared::path::norm(b));
    if !(la > 0.0 && lb > 0.0) {
        return false;
    }
    let cos = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (la * lb);
    // (The planner's own test is `cos < corner_cos` on the blocks' tangents, each a
    // rounding or two from these.)
    cos < corner_cos - 1e-9
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[cfg(test)]
mod tests;
