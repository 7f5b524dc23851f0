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
//! Windowed, the blocks are those of the whole program planned at once, bit for bit
//! (`tests::windows_plan_as_the_whole_program`, every program of the repository on both
//! machines, cut at every place it may be).
//!
//! # Windows cut at speed
//!
//! A stretch with no rest longer than the machine's look-ahead, `plan_window_moves`
//! (4096 moves built in: a smooth spiral of short lines, CAM output under `G64`), is
//! planned a window of that many moves at a time (`Windows::plan_at_speed`). Each
//! window is planned as if the machine stopped at its end, and handed on only up to a
//! seam the last quarter of the window or more before that end: a junction of two feed
//! blocks where the plan holds the speed the junction allows (its second block starts
//! below what braking within it allows), and whose second block starts where its move
//! starts (a line, an arc, a curve) or on a feed line that is the only move of its
//! source line (after a `G64 P` blend: a zigzag whose every corner is blended is all
//! blends, each starting on a line; `Anchor`). The backward pass there starts
//! from that junction speed whatever comes after. The next window plans again from
//! some way before the seam (`Windows::context_start`: 64 moves at least, and two
//! steps plus twice the stopping distance at the highest feed, so that the seam's
//! blocks have the same neighbours: a run of close kinks, a `G64 P` blend's weighing),
//! finds the seam's two blocks, and continues from them, its first block's start held
//! to the speed handed on.
//!
//! * The seam lies before the window's final braking (the blocks after the last one
//!   that does not slow down, each slowing for the stop at the window's end): a seam
//!   in it would be handed on slower than the whole plan, and each window would slow
//!   the next (20 000 lines of a spiral at F3000 on the built-in machine, whose jerk
//!   lets a 0.04 mm block change its speed by 1.5 mm/min only, took 16 % longer in
//!   windows of 512 moves and twice as long in windows of 64). Where the braking
//!   leaves no seam, the window grows (doubling, up to `GROW_MAX` = 16 times
//!   `plan_window_moves`) until it takes the braking in; past that, a seam in the
//!   braking or halfway is taken, handed on at the speed planned there, and counted
//!   ([`Planned::short_windows`]; `cnc check` and `cnc run` name the machine file's
//!   key).
//! * Where the next window has not the seam's two blocks (a corner next to it blended
//!   otherwise), or a pass read since comes back to the seam's move, the moves are
//!   planned again from the seam's move (a seam on a line: the line from the seam's
//!   point on), whose first block starts where the last one handed on ends. Such seams, and those whose two blocks are planned otherwise the
//!   second time, are counted ([`Planned::rough_seams`]).
//! * Where the window has no such seam (a single curve longer than the window, a
//!   program whose lines all repeat through O-words), it is planned again once it is
//!   twice as long; the interpolator may meanwhile come to the end of what it was
//!   handed and stop there on the path.
//! * Safety does not hang on the seam: the interpolator can always stop by the end of
//!   the last block it holds, so blocks that stop coming mid-motion make it stop on the
//!   path (a starvation, counted), and a lower speed ahead is braked for as any limit.
//!
//! The blocks before a seam are the whole program's bit for bit where nothing else
//! reaches across it: on lines, and on the chains of curves and of blends the tests
//! hold. The share rounds of curves near a seam, or a blend chain longer than the
//! context, may plan them otherwise than the whole program would (still a valid plan:
//! `tests::a_long_curve_and_a_chain_of_blends_are_cut_at_speed` has one such seam in
//! nine on a chain of curves, 0.9997 of the whole plan's time).
//!
//! Measured: every program of the repository fits a window (they are planned whole, as
//! before). A spiral of a million lines of `G1` (`cnc check --estimate`) is planned in
//! 26 MB instead of 211 MB, with the same `--estimate --json` byte for byte, as are
//! 200 000 lines of it under `G64 P0.01` and the 100 000-line `mixed` bench program
//! (BENCHMARKS.md). `tests::a_stretch_with_no_rest_is_cut_at_speed` holds the bit-for-bit
//! identity with a window of 1000 moves and the path's joins with one of 64.
//!
//! # On the machine's other cores
//!
//! Where the stream may use them ([`Stream::spare_cores`]: `cnc check` and the launcher's
//! check, before the stack runs; not the interpreter's plan in a run, beside the
//! interpolator's cycle), the program is read on a thread of its own, a few batches
//! ahead of the planning, and the windows of a batch that each follow a rest (planned
//! alike whatever came before them) are planned on two threads, the planning's own
//! from the first on and a helper from the last back, and handed on in order. Neither
//! waits for the other: where the planning comes to the window the helper is still on,
//! it plans it too, so another process holding the other core costs no more than
//! planning on one thread. Windows cut at speed stay one after the other: each
//! continues from the seam the one before it found. The blocks, problems and figures
//! are the same either way: every window test plans both ways and compares them bit
//! for bit. The helper's windows wait, planned, until the planning comes to them,
//! within a group of [`HELPER_GROUP`] windows.

use crate::blocks::{self, check::Checker, Block, Plannable};
use crate::parse::Diagnostic;
use crate::program::{self, Move, PathControl};
use shared::path::sub;
use shared::protocol::{FLAG_RAPID, FLAG_SURFACE};
use shared::Machine;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Mutex};

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
    /// How many of them ended at speed (a stretch with no rest longer than the
    /// machine's `plan_window_moves`).
    pub at_speed: usize,
    /// Of those, the ones where the next window's plan did not continue the plan handed
    /// on exactly (it was held to the speed handed on, or planned the seam's two blocks
    /// otherwise): the blocks there are not bit for bit those of the whole program.
    pub rough_seams: usize,
    /// Of the windows ended at speed, the ones cut in their final braking or halfway
    /// though grown to `GROW_MAX` times `plan_window_moves`: the braking from the feed
    /// takes more moves than that, so the feed drops towards each such window's end (a
    /// stop the window must allow) and the plan is slower than the whole program's.
    pub short_windows: usize,
    /// How many subroutine files it read ([`program::Program::subroutine_files`]).
    pub subroutine_files: usize,
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
    /// Use the machine's other cores: read on a thread of its own, a few batches ahead
    /// of the planning ([`READ_AHEAD_BATCHES`]), and plan the windows that follow a rest
    /// on two threads ([`Windows::plan_side_by_side`]). For `cnc check` and the
    /// launcher's check, not for the interpreter's plan in a run, which shares the
    /// machine with the interpolator's cycle. The same blocks, problems and figures
    /// either way.
    pub spare_cores: bool,
}

/// Batches the reading thread may hold ready for the planning ([`Stream::spare_cores`]):
/// enough to keep both busy, few enough to keep the memory within a few batches.
const READ_AHEAD_BATCHES: usize = 2;

/// The reading thread's stack: as the main thread's (the nesting of values and of
/// subroutine calls is bounded, within that).
const READER_STACK: usize = 8 << 20;

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
        spare_cores,
    } = stream;
    let read = Reading { every, spare_cores };
    let (planned, in_doubt) = plan_once(text, opts, machine, period_ns, read, hand, release)?;
    // A `G4 P` read as seconds before the program showed itself Fanuc's was
    // milliseconds: read again as Fanuc's (what is handed on starts again at block 0).
    if in_doubt && planned.dialect == program::Dialect::Fanuc && opts.dialect.is_none() {
        let fanuc = program::Options {
            dialect: Some(program::Dialect::Fanuc),
            ..opts.clone()
        };
        return plan_once(text, &fanuc, machine, period_ns, read, hand, release).map(|(p, _)| p);
    }
    Ok(planned)
}

/// How [`plan_once`] reads and plans: batches of `every` moves, and whether it may use
/// the machine's other cores ([`Stream::spare_cores`]).
#[derive(Clone, Copy)]
struct Reading {
    every: usize,
    spare_cores: bool,
}

/// [`plan`] read once as `opts` say; and whether a dwell in doubt was handed on.
fn plan_once(
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
    reading: Reading,
    hand: &mut dyn FnMut(Vec<Block>, usize),
    release: &mut dyn FnMut(usize, usize),
) -> Result<(Planned, bool), Vec<Diagnostic>> {
    std::thread::scope(|scope| {
        let mut w = Windows::new(text, machine, period_ns, hand);
        if reading.spare_cores {
            w.helper = Helper::start(scope, machine, period_ns);
        }
        let mut in_doubt = false;
        let read = {
            let mut sink = |moves: Vec<Move>, r: program::Read| {
                w.clean &= r.clean;
                in_doubt |= r.in_doubt;
                w.take(moves);
            };
            let batches = program::Batches {
                every: reading.every.max(1),
                sink: &mut sink,
                release,
            };
            if reading.spare_cores {
                read_ahead(text, opts, batches)
            } else {
                program::interpret_batched(text, opts, batches)
            }
        };
        let mut prog = read?;
        w.take(std::mem::take(&mut prog.moves));
        let held = w.cam.finish();
        if !held.is_empty() {
            w.take_merged(held);
        }
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
            notes: {
                let mut notes = w.feeds.finish("move");
                notes.extend(w.cam.note());
                notes
            },
            windows: w.windows,
            at_speed: w.at_speed,
            rough_seams: w.rough_seams,
            short_windows: w.short,
            subroutine_files: prog.subroutine_files,
        };
        Ok((planned, in_doubt))
    })
}

/// What the reading thread of [`read_ahead`] hands over, in order.
enum Got {
    /// A batch and what was read by then ([`program::Batches::sink`]).
    Moves(Vec<Move>, program::Read),
    /// A stretch of the text the reading is done with ([`program::Batches::release`]).
    Done(usize, usize),
}

/// [`program::interpret_batched`] on a thread of its own, its batches and releases
/// handed to `batches` on this one in the order it made them, at most
/// [`READ_AHEAD_BATCHES`] of them waiting. Where no thread can be started, read here.
fn read_ahead(
    text: &str,
    opts: &program::Options,
    batches: program::Batches<'_>,
) -> Result<program::Program, Vec<Diagnostic>> {
    let program::Batches {
        every,
        sink,
        release,
    } = batches;
    let (tx, rx) = std::sync::mpsc::sync_channel::<Got>(READ_AHEAD_BATCHES);
    std::thread::scope(|scope| {
        let reader = std::thread::Builder::new()
            .name("read".into())
            .stack_size(READER_STACK)
            .spawn_scoped(scope, move || {
                // (The planning gone has stopped: what is left is not wanted.)
                let send = |g: Got| drop(tx.send(g));
                program::interpret_batched(
                    text,
                    opts,
                    program::Batches {
                        every,
                        sink: &mut |moves, r| send(Got::Moves(moves, r)),
                        release: &mut |from, to| send(Got::Done(from, to)),
                    },
                )
            });
        let reader = match reader {
            Ok(r) => r,
            Err(_) => {
                let batches = program::Batches {
                    every,
                    sink,
                    release,
                };
                return program::interpret_batched(text, opts, batches);
            }
        };
        for got in rx {
            match got {
                Got::Moves(moves, r) => sink(moves, r),
                Got::Done(from, to) => release(from, to),
            }
        }
        reader
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
    })
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
    /// Where the last window handed on ended at speed: the next plan continues from it.
    seam: Option<Seam>,
    /// Moves `pending` holds, with no rest among them, before a window is cut at speed
    /// (the machine's `plan_window_moves`, more while no seam is found).
    at_speed_from: usize,
    at_speed: usize,
    rough_seams: usize,
    /// See [`Planned::short_windows`].
    short: usize,
    /// Plans windows that follow a rest beside this thread ([`Stream::spare_cores`]).
    helper: Option<Helper>,
    /// `G64 Q`'s merge of the moves read, before they are cut into windows.
    cam: blocks::naive_cam::NaiveCam,
}

/// The junction between two feed blocks where a window handed on ended at speed: the
/// last block handed on, and the first of those planned again.
struct Seam {
    before: Block,
    after: Block,
    /// The index in the moves held of the move the second is cut from, and how it is.
    move_at: usize,
    anchor: Anchor,
}

/// How a seam's second block lies on the move it is cut from: it starts where the move
/// starts (a feed line, an arc, a curve), or somewhere on a feed line, the only move of
/// its source line (a line whose start a `G64 P` blend rounds or split at a kink, or the
/// blend of its corner with the next, which carries its line). Either way a plan from
/// the block's own start point on (the line from that point on) is a plan of the rest
/// of the program.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Anchor {
    Start,
    On,
}

/// Where move `m` starts, with its line (the bits of the point): a feed line, an arc or
/// a curve.
fn start_of(m: &Move) -> Option<(u32, [u64; 3])> {
    let bits = |p: &[f64]| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()];
    match m {
        Move::Line {
            line,
            from,
            rapid: false,
            ..
        }
        | Move::Arc { line, from, .. } => Some((*line, bits(from))),
        Move::Nurbs { line, ctrl, .. } => ctrl.first().map(|c| (*line, bits(&c[..3]))),
        _ => None,
    }
}

/// Where block `b` starts, with its line, as [`start_of`] gives a move's.
fn block_start(b: &Block) -> Option<(u32, [u64; 3])> {
    b.ends()
        .map(|(from, _)| (b.source_line(), from.map(f64::to_bits)))
}

/// Whether `p` lies on the feed line `m` (within a nanometre), and not at its start.
fn inside_line(m: &Move, p: [f64; 3]) -> bool {
    let Move::Line {
        from,
        to,
        rapid: false,
        ..
    } = m
    else {
        return false;
    };
    let (d, q) = (sub(*to, *from), sub(p, *from));
    let len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if len2 <= 0.0 || p == *from {
        return false;
    }
    let t = (q[0] * d[0] + q[1] * d[1] + q[2] * d[2]) / len2;
    let off = sub(q, d.map(|x| x * t));
    (0.0..1.0).contains(&t) && shared::path::norm(off) < 1e-6
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

impl<'a, 'h> Windows<'a, 'h> {
    /// Nothing read yet of `text`; blocks handed to `hand`.
    fn new(
        text: &'a str,
        machine: &'a Machine,
        period_ns: u64,
        hand: &'h mut dyn FnMut(Vec<Block>, usize),
    ) -> Self {
        Windows {
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
            seam: None,
            at_speed_from: machine.plan_window_moves as usize,
            at_speed: 0,
            rough_seams: 0,
            short: 0,
            helper: None,
            cam: blocks::naive_cam::NaiveCam::new(machine),
        }
    }
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
        let moves = self.cam.take(moves);
        self.take_merged(moves);
    }

    /// [`Windows::take`] after the naive CAM merge.
    fn take_merged(&mut self, moves: Vec<Move>) {
        if self.pending.is_empty() {
            self.pending = moves;
        } else {
            self.pending.extend(moves);
        }
        self.look();
        let cuts = std::mem::take(&mut self.scan.cuts);
        let Some(&(last, _)) = cuts.last() else {
            self.plan_at_speed_while_long();
            return;
        };
        // Each window to its cut; what follows the last stays, the mode in force put
        // before it.
        let mode = cuts.last().and_then(|(_, m)| m.clone());
        let mut done = self.keep_from(last, mode);
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
        for (k, window) in windows.iter_mut().enumerate() {
            if let Some(Some(m)) = k.checked_sub(1).map(|c| cuts[c].1.clone()) {
                window.insert(0, m);
            }
        }
        let mut windows = windows.into_iter();
        // The first may continue a window cut at speed; those after it each follow a
        // rest, and plan alike whatever came before.
        if let Some(first) = windows.next() {
            self.plan(first);
        }
        if self.helper.is_some() {
            self.plan_side_by_side(windows.collect());
        } else {
            windows.for_each(|w| self.plan(w));
        }
        self.plan_at_speed_while_long();
    }

    /// Plans `windows`, each following a rest (no seam before any), with the
    /// [`Helper`], and hands them on in order as [`Windows::plan`] does. In each group
    /// of [`HELPER_GROUP`], this thread takes them from the first on, the helper from
    /// the last back; each takes those the other has not. Where this thread comes to
    /// the one the helper is still planning, it plans it too rather than wait: a helper
    /// put aside by a busy machine (another process on the other core) never holds the
    /// planning up, at the cost of at most one window a group planned twice.
    fn plan_side_by_side(&mut self, windows: Vec<Vec<Move>>) {
        debug_assert!(self.seam.is_none());
        let mut groups: Vec<Arc<Vec<Job>>> = Vec::new();
        let mut windows = windows.into_iter().peekable();
        while windows.peek().is_some() {
            let group = windows.by_ref().take(HELPER_GROUP).map(Job::new).collect();
            groups.push(Arc::new(group));
        }
        if let Some(h) = &self.helper {
            for g in groups.iter().filter(|g| g.len() > 1) {
                // (A helper gone leaves them all to this thread.)
                let _ = h.jobs.send(g.clone());
            }
        }
        for job in groups.iter().flat_map(|g| g.iter()) {
            if job.moves.is_empty() {
                continue;
            }
            let blocks = if job.claim() {
                planned_alone(&job.moves, self.machine, self.period_ns)
            } else {
                match job.take_done() {
                    Some(b) => b,
                    None => planned_alone(&job.moves, self.machine, self.period_ns),
                }
            };
            self.planned_on(blocks, 0, false);
        }
    }

    /// Keeps the moves held from `at` on, `mode` (the path mode in force there) put
    /// before them, what was looked at keeping its place (the motion last looked at is
    /// at `at` or after it); gives back the moves before `at`.
    fn keep_from(&mut self, at: usize, mode: Option<Move>) -> Vec<Move> {
        let mut rest = self.pending.split_off(at);
        let off = usize::from(mode.is_some());
        if let Some(m) = mode {
            rest.insert(0, m);
        }
        let shift = |i: usize| i - at + off;
        self.scan.upto = shift(self.scan.upto);
        self.scan.last = self.scan.last.map(|(i, m)| (shift(i), m));
        std::mem::replace(&mut self.pending, rest)
    }

    /// [`Windows::plan_at_speed`] for as long as the moves held (with no rest among
    /// them) are a window or more.
    fn plan_at_speed_while_long(&mut self) {
        while self.pending.len() >= self.at_speed_from {
            self.plan_at_speed();
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

    /// Builds, plans and checks one window of moves, ending at rest, and hands its
    /// blocks on.
    fn plan(&mut self, window: Vec<Move>) {
        if window.is_empty() {
            return;
        }
        let (blocks, from, rough) = self.planned(&window);
        drop(window);
        self.planned_on(blocks, from, rough);
    }

    /// A window's blocks as [`Windows::planned`] gives them, handed on from `from`.
    fn planned_on(&mut self, mut blocks: Vec<Block>, from: usize, rough: bool) {
        self.seam = None;
        self.rough_seams += usize::from(rough);
        self.at_speed_from = self.machine.plan_window_moves as usize;
        blocks.drain(..from);
        self.hand_on(blocks);
    }

    /// `moves` (the moves held, from their start) built and planned, the first block
    /// to hand on, and whether the seam before them is rough: where a window was cut at
    /// speed before them, the first is the seam's second block, continued from the
    /// block handed on before it ([`Windows::continue_at`]). Should the seam not be
    /// there (its corner blended otherwise, planned with less before it), the moves are
    /// planned again from the seam's move, whose first block starts where the last
    /// handed on ends (rough). The seam stays until what follows it is handed on.
    fn planned(&self, moves: &[Move]) -> (Vec<Block>, usize, bool) {
        let mut blocks = planned_alone(moves, self.machine, self.period_ns);
        let Some(seam) = &self.seam else {
            return (blocks, 0, false);
        };
        if let Some(j) = self.seam_in(&blocks, moves) {
            let exact = continue_at(seam, &mut blocks, j);
            return (blocks, j, !exact);
        }
        let at = seam.move_at.min(moves.len());
        let mut again: Vec<Move> = mode_before(moves, at).into_iter().collect();
        let first = again.len();
        again.extend_from_slice(&moves[at..]);
        // (A seam on a line: the line from the seam on.)
        if let (Anchor::On, Some(Move::Line { from, .. }), Some((start, _))) =
            (seam.anchor, again.get_mut(first), seam.after.ends())
        {
            *from = start;
        }
        (planned_alone(&again, self.machine, self.period_ns), 0, true)
    }

    /// Plans the moves held, a stretch with no rest in it as long as the machine's
    /// look-ahead, and hands on its blocks up to a seam between two feed blocks (the
    /// second starting a move or on a line: [`Anchor`]), the last quarter of the window or more before its end, where the plan
    /// holds the speed the junction allows (so that what follows the seam does not
    /// bear on it): the plan of the window's end, a stop, reaches no further back.
    /// The seam lies before the window's final braking; where none does, the window
    /// grows ([`Windows::seam_after`]). The moves from some way before the seam on
    /// ([`Windows::context_start`]) are held for the next window, which plans them
    /// again and continues from the seam ([`Windows::planned`]).
    ///
    /// Where the window has no such seam, it is planned again once it is twice as
    /// long.
    fn plan_at_speed(&mut self) {
        // (A batch read may hold more than a window.)
        let n = self.pending.len().min(self.at_speed_from);
        let moves = std::mem::take(&mut self.pending);
        let (mut blocks, from, rough) = self.planned(&moves[..n]);
        self.pending = moves;
        let Some((k, s, anchor, held)) = self.seam_after(&blocks, from, n) else {
            self.at_speed_from = n * 2;
            return;
        };
        let (before, after) = (blocks[k - 1].clone(), blocks[k].clone());
        blocks.truncate(k);
        blocks.drain(..from);
        self.hand_on(blocks);
        self.at_speed += 1;
        self.short += usize::from(!held);
        self.rough_seams += usize::from(rough);
        // The moves from the context's start on stay, the mode in force there first.
        let c = self.context_start(s);
        let mode = mode_before(&self.pending, c);
        let off = usize::from(mode.is_some());
        self.keep_from(c, mode);
        self.seam = Some(Seam {
            before,
            after,
            move_at: s - c + off,
            anchor,
        });
        // The next window holds half a window's moves beyond what this one planned.
        let window = self.machine.plan_window_moves as usize;
        self.at_speed_from = window.max(n - c + off + window / 2);
    }

    /// Where the moves the next window plans again begin, before the seam's move `s`:
    /// [`SEAM_CONTEXT`] moves back at least, and as far as the path reaches that bears
    /// on the seam's blocks: two steps at the highest feed (a run of close kinks) and
    /// twice the distance to stop from it (what a `G64 P` blend's weighing looks at).
    fn context_start(&self, s: usize) -> usize {
        let m = self.machine;
        let v = m.max_feed_mm_per_min / 60.0;
        let reach = 2.0 * v * self.period_ns as f64 * 1e-9 + v * v / m.path_acc_mm_per_s2;
        let mut length = 0.0;
        let mut c = s;
        while c > 1 && (s - c < SEAM_CONTEXT || length < reach) {
            c -= 1;
            // (The chord of an arc or a curve: never longer than its path.)
            let ends = match &self.pending[c] {
                Move::Line { from, to, .. } | Move::Arc { from, to, .. } => Some((*from, *to)),
                Move::Nurbs { ctrl, .. } => ctrl
                    .first()
                    .zip(ctrl.last())
                    .map(|(a, b)| ([a[0], a[1], a[2]], [b[0], b[1], b[2]])),
                _ => None,
            };
            if let Some((from, to)) = ends {
                length += shared::path::norm(sub(to, from));
            }
        }
        c
    }

    /// Where the seam is in `blocks`: the index of its second block, a block on the
    /// seam's line starting where the seam's did, after a block on the line before
    /// ending where the seam's first did.
    ///
    /// The seam's move is the only one of the moves held until then with its line and
    /// point ([`start_of`], or line alone: [`Anchor`]); should one read since have them too (a pass gone over
    /// again), the seam is not looked for: what is found could be that one, and the
    /// moves are planned again from the seam's.
    fn seam_in(&self, blocks: &[Block], moves: &[Move]) -> Option<usize> {
        let seam = self.seam.as_ref()?;
        let key = block_start(&seam.after)?;
        let again = moves
            .iter()
            .skip(seam.move_at + 1)
            .any(|m| match seam.anchor {
                Anchor::Start => start_of(m) == Some(key),
                Anchor::On => m.line() == key.0,
            });
        if again {
            return None;
        }
        let (start, end) = (seam.after.ends()?.0, seam.before.ends()?.1);
        (1..blocks.len()).find(|&j| {
            let (a, b) = (&blocks[j - 1], &blocks[j]);
            a.ends().is_some_and(|e| e.1 == end)
                && b.ends().is_some_and(|e| e.0 == start)
                && a.source_line() == seam.before.source_line()
                && b.source_line() == seam.after.source_line()
        })
    }

    /// A seam in `blocks` after block `from` (see [`Windows::plan_at_speed`]): the
    /// index of its second block, of the move that block is cut from, how, and whether
    /// the plan holds the junction's speed there (false: a seam halfway).
    fn seam_after(
        &self,
        blocks: &[Block],
        from: usize,
        moves: usize,
    ) -> Option<(usize, usize, Anchor, bool)> {
        let n = blocks.len();
        let (lo, hi) = (from + (n - from) / 4, from + (n - from) * 3 / 4);
        let feed = |b: &Block| b.is_motion() && b.flags() & (FLAG_RAPID | FLAG_SURFACE) == 0;
        // Two feed blocks meeting at `k`.
        let at = |k: usize| -> Option<&Block> {
            let (a, b) = (&blocks[k - 1], &blocks[k]);
            (feed(a) && feed(b) && a.ends()?.1 == b.ends()?.0).then_some(b)
        };
        // The moves by their start points and lines, and by their lines alone: the one
        // of each (none where a path is gone over again, as a repeated pass is).
        let mut starts: HashMap<(u32, [u64; 3]), Option<usize>> = HashMap::new();
        let mut lines: HashMap<u32, Option<usize>> = HashMap::new();
        for (i, m) in self.pending[..moves].iter().enumerate() {
            if let Some(key) = start_of(m) {
                starts
                    .entry(key)
                    .and_modify(|e| *e = None)
                    .or_insert(Some(i));
            }
            lines
                .entry(m.line())
                .and_modify(|e| *e = None)
                .or_insert(Some(i));
        }
        let move_of = |b: &Block| {
            let start = starts
                .get(&block_start(b)?)
                .copied()
                .flatten()
                .map(|s| (s, Anchor::Start));
            let on = || {
                let s = lines.get(&b.source_line()).copied().flatten()?;
                inside_line(&self.pending[s], b.ends()?.0).then_some((s, Anchor::On))
            };
            start.or_else(on).filter(|&(s, _)| s > SEAM_CONTEXT)
        };
        // The latest seam in `range` whose plan holds the junction's speed: its second
        // block starts below what braking within it to its end allows.
        let held = |range: std::ops::Range<usize>| {
            range.rev().find_map(|k| {
                let b = at(k)?;
                let (start, end, _) = b.planned_mm_s();
                let pinned = start < b.limits().reachable_speed(end, b.length_mm());
                pinned.then(|| move_of(b).map(|(s, a)| (k, s, a))).flatten()
            })
        };
        // The window's final braking: the blocks after the last one that does not slow
        // down, each slower at its end than at its start, down to the stop at the
        // window's end. A seam in it is handed on slower than the whole program's plan
        // would be there, and the next window, starting from that, brakes for its own
        // end sooner still.
        let braking = (from..n)
            .rev()
            .find(|&k| {
                let (start, end, _) = blocks[k].planned_mm_s();
                end >= start
            })
            .map_or(from, |k| k + 1);
        let first = lo.max(from + 1);
        if let Some((k, s, a)) = held(first..hi.min(braking)) {
            return Some((k, s, a, true));
        }
        // None before it: a longer window, up to [`GROW_MAX`] times the machine's, so
        // that the look-ahead takes the braking in; past that, a seam in the braking,
        // else halfway (a short window, counted).
        if moves < GROW_MAX * self.machine.plan_window_moves as usize {
            return None;
        }
        held(first..hi)
            .or_else(|| {
                (first..(from + (n - from) / 2).max(first))
                    .rev()
                    .find_map(|k| move_of(at(k)?).map(|(s, a)| (k, s, a)))
            })
            .map(|(k, s, a)| (k, s, a, false))
    }

    /// Checks `blocks`, the next of the program, and hands them on.
    fn hand_on(&mut self, blocks: Vec<Block>) {
        if blocks.is_empty() {
            return;
        }
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

/// Windows [`Windows::plan_side_by_side`] hands the helper at a time, each group taken
/// from its first on by the planning and from its last back by the helper: the helper's
/// blocks wait for the planning to come to them within one group, not a whole batch.
const HELPER_GROUP: usize = 32;

/// A window of moves that follows a rest, planned by whichever of the two threads of
/// [`Windows::plan_side_by_side`] claims it first.
struct Job {
    moves: Vec<Move>,
    claimed: AtomicBool,
    /// Its blocks, where the helper has planned it.
    done: Mutex<Option<Vec<Block>>>,
}

impl Job {
    fn new(moves: Vec<Move>) -> Self {
        Job {
            moves,
            claimed: AtomicBool::new(false),
            done: Mutex::new(None),
        }
    }

    /// The blocks the helper planned, if it has.
    fn take_done(&self) -> Option<Vec<Block>> {
        self.done
            .lock()
            .map_or_else(|e| e.into_inner().take(), |mut d| d.take())
    }

    /// The helper's blocks.
    fn set_done(&self, blocks: Vec<Block>) {
        let mut d = self.done.lock().unwrap_or_else(|e| e.into_inner());
        *d = Some(blocks);
    }

    /// Whether the caller is the first to claim it.
    fn claim(&self) -> bool {
        !self.claimed.swap(true, Ordering::AcqRel)
    }
}

/// A thread that plans windows beside the one that reads them in ([`Stream::spare_cores`]):
/// each batch's windows that follow a rest are sent to it, and it plans them from the
/// last back while they are unclaimed ([`Windows::plan_side_by_side`]). It lives as long
/// as the [`plan_once`] that started it.
struct Helper {
    jobs: mpsc::Sender<Arc<Vec<Job>>>,
}

impl Helper {
    /// Started in `scope`; `None` on a machine of one core, or where no thread starts.
    fn start<'s>(
        scope: &'s std::thread::Scope<'s, '_>,
        machine: &'s Machine,
        period_ns: u64,
    ) -> Option<Helper> {
        if std::thread::available_parallelism().map_or(1, |n| n.get()) < 2 {
            return None;
        }
        let (tx, rx) = mpsc::channel::<Arc<Vec<Job>>>();
        std::thread::Builder::new()
            .name("plan".into())
            .spawn_scoped(scope, move || {
                for jobs in rx {
                    for job in jobs.iter().rev() {
                        if job.claim() {
                            job.set_done(planned_alone(&job.moves, machine, period_ns));
                        } else {
                            // This thread has come to the windows the other has taken.
                            break;
                        }
                    }
                }
            })
            .ok()
            .map(|_| Helper { jobs: tx })
    }
}

/// `moves` built and planned on their own.
fn planned_alone(moves: &[Move], machine: &Machine, period_ns: u64) -> Vec<Block> {
    let mut blocks = blocks::build(moves, machine);
    blocks::plan_and(&mut blocks, machine, period_ns, |_, _| {});
    blocks
}

/// How many times the machine's `plan_window_moves` a window cut at speed may grow to
/// take in the plan's braking from the feed ([`Windows::seam_after`]).
const GROW_MAX: usize = 16;

/// The fewest moves before a seam that the next window plans again
/// ([`Windows::context_start`]).
const SEAM_CONTEXT: usize = 64;

/// Block `j` of `blocks`, the second of `seam`, continued from the block handed on
/// before it: its start held to the speed that one ends at. Whether the two blocks are
/// planned as in the window before (exact).
fn continue_at(seam: &Seam, blocks: &mut [Block], j: usize) -> bool {
    let handed_end = seam.before.planned_feeds().1;
    // The two blocks the same but for their planned start and end speeds.
    let same = |x: &Block, y: &Block| {
        let plan = |b: &Block| {
            let mut c = b.command(0);
            (c.start_feed_mm_per_min, c.end_feed_mm_per_min) = (0.0, 0.0);
            c
        };
        shared::cmdlog::same_bits(&plan(x), &plan(y))
    };
    let (start, end) = blocks[j].planned_feeds();
    let exact =
        same(&blocks[j - 1], &seam.before) && same(&blocks[j], &seam.after) && start == handed_end;
    // (What the interpolator runs by is the end speed of the block before: this keeps
    // the block's own figures consistent. It never passes a speed limit it holds and
    // can always stop by the end of what it holds, so a lower speed ahead is braked for
    // like any limit.)
    blocks[j].set_feeds(start.min(handed_end), end);
    exact
}

/// The path mode in force at move `at` of `moves` (the last set before it), if any.
fn mode_before(moves: &[Move], at: usize) -> Option<Move> {
    moves[..at]
        .iter()
        .rev()
        .find(|m| matches!(m, Move::PathMode { .. }))
        .cloned()
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

#[cfg(test)]
mod tests;
