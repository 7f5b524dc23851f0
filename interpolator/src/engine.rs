//! The per-cycle path stepper: a plain state machine over plain data, no I/O.
//!
//! Each [`Engine::tick`] advances the tool along the current block by one period at the
//! speed the profile allows, crossing into following blocks when one ends mid-period, and
//! returns the new set-point.
//!
//! The speed profile is jerk-limited (an S-curve along the arc length): the engine keeps
//! the path speed `v` and the path acceleration `a`, and each cycle changes `a` by at most
//! `J·T` within `±A`, where `A` and `J` are the block's tangential limits (the planner's
//! share of the machine's limits that the block's curvature leaves). It follows its
//! preferred motion (accelerate at `+J` up to `A`) for as long as the quickest braking
//! can still keep every speed limit ahead, and from the last such moment inside the
//! cycle (found by Newton's method or bisection, to `SWITCH_RESOLUTION`) that braking
//! ([`Engine::profile_step`]). The limits ahead are the current block's feed, the planned end speed
//! of every block in the look-ahead window (a ring of `lookahead_blocks`, filled from the
//! source every cycle), and a stop at the end of the last block held: the machine can
//! always stop on the known path, so a starved interpolator stops on the path instead of
//! running off its end. The test of each limit is the closed form of
//! [`shared::profile::Limits::can_reach`]. A speed eased off onto a block end's limit
//! may still be rising when it passes it, so each block end is braked for under the
//! lower jerk of its two blocks ([`Ahead::easing`]), and a block end no lower than a
//! nearer one is still kept where the block beyond it has a lower jerk than any kept
//! (a curve split where its speed limit changes has blocks of different jerks; eased
//! under the higher one, a weak axis went 1.07 % over its velocity). A block is never
//! entered with more acceleration than it allows: the acceleration the profile rises to
//! is held under each block ahead's limit plus what the lower jerk can shed before it is
//! reached ([`Engine::acc_ceiling`]). The walk reaches as far as the lowest limits of
//! every block in hand could need to stop from the highest speed and acceleration this
//! cycle can reach (its acceleration raised by one period's jerk, not the block's whole
//! limit: that reached three to four times too far), and a limit beyond a low is left
//! to that low only where the easing of what the low may be passed with still keeps it
//! ([`Engine::spare`]); blocks of one curve whose limits differ sixfold once broke each
//! of these. Up to `MAX_AHEAD` limits are tested one by one; the further ones are
//! folded into the last of them. The walk that finds them reads each block's few
//! figures from a packed array beside the ring (not from its 1.5 KB block), and its
//! tests use square-root-free comparisons ([`shared::profile::Limits::change_within`],
//! [`Engine::spare_exceeds`]) and a branch-free bisection: on a window of hundreds of
//! tiny blocks this walk was two thirds of a cycle's cost (`cycle/profile_worst` in
//! `benches/cycle.rs`, `BENCHMARKS.md`).
//!
//! The engine trusts no block it was not built to: each block is validated, then checked
//! against the machine it runs with ([`CommandBlock::validate_for`]: feeds, profile
//! limits, a curve without jumps, the exact path within travel) and for a start where the
//! previous motion ended, before it enters the window; a refused block is a fault raised
//! before anything moves, so the window holds only blocks the machine can run and the
//! stop ends on the good path. (Cost, once per block: 0.3 µs for a degree-5 block inside
//! the travel, 6 to 8 µs when its control polygon crosses a limit; `block_check/*` in
//! `benches/cycle.rs`.) The last guard, every cycle: a set-point that would step an axis
//! further than its velocity allows in a period, or leave the travel, is never
//! published (the engine holds the last one). A plan valid field by field may still
//! brake across several blocks into one of far lower limits, which the limits ahead,
//! braked for under the lowest limits of the way, cannot keep: each block taken lowers
//! the end speed before it, where it has lower limits than the block before and cannot
//! brake from that end to its own by itself ([`Engine::keep_chain`]; the planner's plans
//! never need it).
//!
//! A cycle that crosses a block end does the most besides the profile step: the next
//! block's start, and a new block taken into the window. So the next block's evaluators
//! are loaded ahead, in a cycle that crossed no block end, into a spare [`Geometry`]
//! swapped in at its start ([`Engine::preload`]), and in a later such cycle the block
//! that will replace it in the window is taken from the source and checked ahead
//! ([`Engine::stage`]); the block being run is kept beside
//! [`Current`], not copied out of it and back every cycle; and the lowest limits held are
//! counted, not walked for at every block taken. (On `cycle/profile_worst`: its own p99
//! 4.0 → 2.8 µs, the same set-points.)
//!
//! A fault does not freeze the set-point where it is: [`Engine::stop`] starts a controlled
//! stop, as a real control does on a following-error or peer fault. From then on no block
//! is taken from the source; any positive acceleration is dropped at once, so the speed
//! never rises again, and the speed falls under the machine's path acceleration and jerk
//! along the path already in hand (crossing into look-ahead blocks that are already
//! validated), down to zero ([`Engine::at_rest`]). The stop is bounded: the quickest
//! jerk-limited stop from the speed at the fault, plus one cycle.
#![deny(
    clippy::indexing_slicing,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic
)]

use shared::nurbs::fast::FastCurve;
use shared::nurbs::surface::FastSurface;
use shared::nurbs::CurvePoint;
use shared::path::{self, norm};
use shared::profile::{self, Limits as Jerk};
use shared::protocol::{
    BlockKind, CommandBlock, Feedback, MachineLimits, ProtocolError, FLAG_RAPID, JOIN_TOL_MM,
};
use shared::travel::{self, TravelError};
use shared::Machine;

/// Most blocks one cycle may pass through (tiny CAM segments shorter than one step).
const MAX_BLOCKS_PER_CYCLE: usize = 64;

/// Most evaluations spent finding the end of one cycle's step on the curve (Newton
/// steps, and bisections where Newton fails: 64 halvings exhaust an `f64` interval).
const MAX_CHORD_STEPS: usize = 80;

/// Seconds a motion may stand still mid-block, not stopping, before the watchdog calls
/// it a [`Fault::Stalled`].
pub const STALL_SECONDS: u64 = 2;

/// Most speed limits ahead tested per cycle; further ones are merged into the last kept
/// (its distance with the lower speed: stricter than both).
const MAX_AHEAD: usize = 16;

/// Resolution of the moment in a cycle where braking must begin, or a limit is passed,
/// as a fraction of the period: `T/2³⁰` (what 30 halvings of the period give).
const SWITCH_RESOLUTION: f64 = 1.0 / (1u64 << 30) as f64;

/// Most evaluations [`latest_ok`] spends on one moment: regula falsi steps, then halvings
/// if those have not closed the bracket (62 halvings exhaust any bracket in the period).
const SWITCH_STEPS: usize = 24;
const SWITCH_HALVINGS: usize = 62;

/// Where the blocks come from: the iceoryx2 subscriber in a run, a slice in tests.
pub trait BlockSource {
    fn next_block(&mut self) -> Option<CommandBlock>;
}

/// Why the engine stopped the machine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    Protocol(ProtocolError),
    FollowingError {
        cycle: u64,
        axis: usize,
        ferr_mm: f64,
        limit_mm: f64,
        /// Source line of the set-point the drives were answering.
        line: u32,
    },
    Feedback(ProtocolError),
    /// The drives did not answer this cycle's set-point in time (dead or stalled).
    PeerSilent {
        cycle: u64,
    },
    /// A peer process is gone: iceoryx2 found its node dead (the kernel released its
    /// liveness lock) or its port left the service before the program end. `cycle` is the
    /// cycle in which the interpolator noticed.
    PeerGone {
        peer: Peer,
        cycle: u64,
    },
    /// SIGTERM/SIGINT: the launcher stops the stack (a peer failed) or the operator did.
    StopRequested,
    /// The engine's own watchdog: in the middle of a motion block the set-point has not
    /// moved for [`STALL_SECONDS`] although nothing asked it to stop. A planning error
    /// (a profile that cannot reach its next limit) would otherwise hold the machine
    /// there for ever; as a fault it ends the run with a report that names the block.
    Stalled {
        line: u32,
        seq: u64,
    },
    /// The last guard: the next set-point would move `axis` by `step_mm` in one period,
    /// more than its `max_vel_mm_per_min` allows (`limit_mm`, with [`STEP_MARGIN`]). It is
    /// not published: the engine holds the last set-point (the path ahead is not to be
    /// trusted, so it does not brake along it). Every block is checked on receipt so that
    /// this cannot happen; it guards against what those checks miss.
    StepTooLarge {
        line: u32,
        seq: u64,
        axis: usize,
        step_mm: f64,
        limit_mm: f64,
    },
    /// The last guard on travel: the next set-point would leave it. Not published; the
    /// engine holds the last set-point, as for [`Fault::StepTooLarge`].
    OutOfTravel {
        line: u32,
        seq: u64,
        err: TravelError,
    },
}

/// How much a set-point step may exceed `max_vel·period` on an axis, relative: what the
/// planner's per-axis shares are held to. The property test of a weak axis
/// (`interpreter/tests/limits.rs`) holds every axis figure within 1 % and its velocity
/// reached `1 + 5.0e-5` times the limit (found by this guard when its margin was 1e-6);
/// on the demo, the STEP-NC examples and the LinuxCNC suite, at 1 ms and 250 µs, on the
/// default machine and one with 30 000 mm/min rapids, the largest step was `1 + 2.3e-13`
/// times `max_vel·period` (rapids along Z at its velocity limit). A jump is many times
/// the limit (the G6.2 of issue #22: 1.414 mm against 0.25 mm).
pub const STEP_MARGIN: f64 = 1e-2;

/// The processes the interpolator watches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Peer {
    Interpreter,
    ServoSim,
}

impl Peer {
    pub fn name(self) -> &'static str {
        match self {
            Peer::Interpreter => "interpreter",
            Peer::ServoSim => "servo-sim",
        }
    }
}

/// Axis letter of an axis index.
pub fn axis_name(axis: usize) -> &'static str {
    ["X", "Y", "Z"].get(axis).copied().unwrap_or("?")
}

impl Fault {
    /// A short, stable name for reports and tests.
    pub fn kind(&self) -> &'static str {
        match self {
            Fault::Protocol(_) => "bad_block",
            Fault::FollowingError { .. } => "following_error",
            Fault::Feedback(_) => "bad_feedback",
            Fault::PeerSilent { .. } => "peer_silent",
            Fault::PeerGone { .. } => "peer_gone",
            Fault::StopRequested => "stop_requested",
            Fault::Stalled { .. } => "stalled",
            Fault::StepTooLarge { .. } => "step_too_large",
            Fault::OutOfTravel { .. } => "out_of_travel",
        }
    }
}

impl core::fmt::Display for Fault {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Fault::Protocol(e) => write!(f, "bad command block: {e}"),
            Fault::FollowingError {
                cycle,
                axis,
                ferr_mm,
                limit_mm,
                line,
            } => write!(
                f,
                "cycle {cycle}, line {line}: following error on {} is {:.4} mm, above the limit of {limit_mm} mm",
                axis_name(*axis),
                ferr_mm
            ),
            Fault::Feedback(e) => write!(f, "bad feedback: {e}"),
            Fault::Stalled { line, seq } => write!(
                f,
                "line {line} (block {seq}): the path stood still for {STALL_SECONDS} s inside a motion block (an interpolator error: please report the program)"
            ),
            Fault::StopRequested => write!(f, "stopped on request (SIGTERM/SIGINT): holding position"),
            Fault::PeerSilent { cycle } => {
                write!(f, "cycle {cycle}: the servo-sim did not answer the set-point (dead or stalled)")
            }
            Fault::PeerGone { peer, cycle } => write!(
                f,
                "cycle {cycle}: the {} is gone (its process ended or died)",
                peer.name()
            ),
            Fault::StepTooLarge {
                line,
                seq,
                axis,
                step_mm,
                limit_mm,
            } => write!(
                f,
                "line {line} (block {seq}): the next set-point would move {} by {step_mm:.4} mm \
                 in one period, more than its max_vel_mm_per_min allows ({limit_mm:.4} mm): \
                 not sent, the machine holds the last set-point",
                axis_name(*axis)
            ),
            Fault::OutOfTravel { line, seq, err } => write!(
                f,
                "line {line} (block {seq}): the next set-point is out of travel: {err}: not \
                 sent, the machine holds the last set-point"
            ),
        }
    }
}

/// What the machine is doing after a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TickState {
    Running,
    /// No block to run and the program is not over: standing still on the path.
    Starved,
    /// Program end reached; the set-point is the final one.
    Done,
}

/// One cycle's output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tick {
    pub pos_mm: [f64; 3],
    pub vel_mm_per_s: [f64; 3],
    pub acc_mm_per_s2: [f64; 3],
    /// Path speed the profile commanded for this cycle.
    pub speed_mm_per_s: f64,
    pub source_line: u32,
    pub block_seq: u64,
    /// The block being run is a rapid (G0) traverse.
    pub rapid: bool,
    pub state: TickState,
}

/// Where the motion being run is in its block ([`Engine::block`], kept apart: a tick
/// copies this out of [`Current`] and back, and with the 1.5 KB block inside those copies
/// were 5 % of `cycle/profile_worst`'s time).
#[derive(Debug, Clone, Copy)]
struct Motion {
    u: f64,
    /// The path (point and derivatives) at `u`, kept from the previous step.
    at: CurvePoint,
    u_end: f64,
    s_mm: f64,
    end_mm: [f64; 3],
    /// The set-point at the block's end.
    end_out: [f64; 3],
    feed_mm_per_s: f64,
}

#[derive(Debug, Clone, Copy)]
enum Current {
    None,
    Motion(Motion),
    Dwell {
        cycles_left: u64,
        line: u32,
        seq: u64,
    },
    End {
        line: u32,
        seq: u64,
    },
}

/// Machine limits the engine obeys.
#[derive(Debug, Clone, Copy)]
pub struct Limits {
    pub period_ns: u64,
    /// Path acceleration and jerk of a controlled stop (blocks carry their own for the
    /// program's motion).
    pub path_acc_mm_per_s2: f64,
    pub path_jerk_mm_per_s3: f64,
    pub max_following_error_mm: f64,
    /// Blocks held ahead of the one being run.
    pub lookahead_blocks: usize,
    /// What every block is checked against as it enters the look-ahead window.
    pub machine: MachineLimits,
    /// The largest set-point step each axis may make in one period: `max_vel·period`,
    /// plus [`STEP_MARGIN`].
    pub max_step_mm: [f64; 3],
}

impl Limits {
    /// The limits of `machine` at `period_ns`.
    pub fn new(machine: &Machine, period_ns: u64) -> Self {
        let t = period_ns as f64 * 1e-9;
        let axes = machine.axes.as_array();
        Limits {
            period_ns,
            path_acc_mm_per_s2: machine.path_acc_mm_per_s2,
            path_jerk_mm_per_s3: machine.path_jerk_mm_per_s3,
            max_following_error_mm: machine.max_following_error_mm,
            lookahead_blocks: machine.lookahead_blocks as usize,
            machine: MachineLimits::of(machine),
            max_step_mm: axes.map(|a| a.max_vel_mm_per_min / 60.0 * t * (1.0 + STEP_MARGIN)),
        }
    }
}

/// The validated blocks in hand after the current one, oldest first: a ring allocated
/// once, when the engine is made. Beside each block, the few figures the profile step
/// reads of every block ahead in every cycle ([`BlockFigs`]), packed together: walking a
/// hundred blocks' figures then touches a few cache lines, not a few hundred.
struct Window {
    /// The ring: `cap` blocks held and one spare slot after the last, where the next
    /// block may be staged while the window is full ([`Window::stage`]).
    buf: Vec<CommandBlock>,
    cap: usize,
    /// The figures of the block in slot `k` of `buf`, twice: at `k` and at `k + buf.len()`.
    /// The figures held are then one plain slice from `head` on, whichever way the ring
    /// wraps ([`Window::held`]), walked without a ring index per block.
    figs: Vec<BlockFigs>,
    head: usize,
    len: usize,
    /// The lowest acceleration and jerk of the motions held (infinite when none), and
    /// how many of those motions have each: the lowest is walked for again only when
    /// the last block with it leaves (on a chain of equal limits, never; the walk over
    /// a full window at every block taken was 4 % of `cycle/profile_worst`).
    lowest: Jerk,
    at_lowest: [usize; 2],
}

/// What the profile step needs of a block in the window.
#[derive(Debug, Clone, Copy)]
struct BlockFigs {
    motion: bool,
    length_mm: f64,
    feed_mm_per_s: f64,
    end_mm_per_s: f64,
    lim: Jerk,
}

impl BlockFigs {
    fn of(b: &CommandBlock) -> Self {
        BlockFigs {
            motion: is_motion(b),
            length_mm: b.length_mm,
            feed_mm_per_s: b.feed_mm_per_min / 60.0,
            end_mm_per_s: b.end_feed_mm_per_min / 60.0,
            lim: block_jerk(b),
        }
    }
}

impl Window {
    fn new(capacity: usize) -> Self {
        let empty = CommandBlock::empty(BlockKind::ProgramEnd, 0, 0);
        let cap = capacity.max(1);
        Window {
            buf: vec![empty; cap + 1],
            cap,
            figs: vec![BlockFigs::of(&empty); 2 * (cap + 1)],
            head: 0,
            len: 0,
            lowest: NO_LIMIT,
            at_lowest: [0; 2],
        }
    }

    fn is_full(&self) -> bool {
        self.len >= self.cap
    }

    /// The ring index of the `i`-th block held (`i < len`): no division in the cycle.
    #[inline]
    fn slot(&self, i: usize) -> usize {
        let k = self.head + i;
        if k >= self.buf.len() {
            k - self.buf.len()
        } else {
            k
        }
    }

    fn get(&self, i: usize) -> Option<&CommandBlock> {
        if i < self.len {
            self.buf.get(self.slot(i))
        } else {
            None
        }
    }

    /// The figures of the `i`-th block held.
    #[inline]
    fn fig(&self, i: usize) -> Option<&BlockFigs> {
        if i < self.len {
            self.figs.get(self.head + i)
        } else {
            None
        }
    }

    /// The figures of the `i`-th block held if it is a motion.
    #[inline]
    fn motion(&self, i: usize) -> Option<&BlockFigs> {
        self.fig(i).filter(|f| f.motion)
    }

    fn push(&mut self, b: CommandBlock) {
        if self.is_full() {
            return;
        }
        self.stage(b);
        self.take_staged();
    }

    /// Writes `b` into the spare slot after the last block held, not held yet: the block
    /// [`Window::take_staged`] takes in (a full window has that slot free too).
    fn stage(&mut self, b: CommandBlock) {
        let k = self.slot(self.len);
        if let Some(slot) = self.buf.get_mut(k) {
            *slot = b;
        }
    }

    /// Holds the block in the spare slot (see [`Window::stage`]) as the last one, if there
    /// is room; returns its kind.
    fn take_staged(&mut self) -> Option<u32> {
        if self.is_full() {
            return None;
        }
        let k = self.slot(self.len);
        let twin = k + self.buf.len();
        if let (Some(b), Some(fig)) = (self.buf.get(k), self.figs.get_mut(k)) {
            *fig = BlockFigs::of(b);
            let fig = *fig;
            if let Some(t) = self.figs.get_mut(twin) {
                *t = fig;
            }
            if fig.motion {
                let lim = fig.lim;
                for (lo, (n, v)) in [&mut self.lowest.acc, &mut self.lowest.jerk]
                    .into_iter()
                    .zip(self.at_lowest.iter_mut().zip([lim.acc, lim.jerk]))
                {
                    if v < *lo {
                        *lo = v;
                        *n = 1;
                    } else if v == *lo {
                        *n += 1;
                    }
                }
            }
            self.len += 1;
            return Some(b.kind);
        }
        None
    }

    /// Lowers the planned end speed of the `i`-th block held to `v` mm/s (see
    /// [`Engine::keep_chain`]).
    fn lower_end(&mut self, i: usize, v: f64) {
        if i >= self.len {
            return;
        }
        let k = self.slot(i);
        if let (Some(b), Some(fig)) = (self.buf.get_mut(k), self.figs.get_mut(k)) {
            fig.end_mm_per_s = v;
            b.end_feed_mm_per_min = v * 60.0;
        }
        if let Some(twin) = self.figs.get_mut(k + self.buf.len()) {
            twin.end_mm_per_s = v;
        }
    }

    /// Takes the oldest block held into `into`; false (and `into` untouched) when none.
    fn pop_into(&mut self, into: &mut CommandBlock) -> bool {
        let k = self.head;
        let (Some(b), Some(fig)) = (self.buf.get(k), self.figs.get(k).copied()) else {
            return false;
        };
        if self.len == 0 {
            return false;
        }
        *into = *b;
        self.head = self.slot(1);
        self.len -= 1;
        if fig.motion {
            let mut gone = false;
            for (n, (v, lo)) in self.at_lowest.iter_mut().zip([
                (fig.lim.acc, self.lowest.acc),
                (fig.lim.jerk, self.lowest.jerk),
            ]) {
                if v == lo {
                    *n = n.saturating_sub(1);
                    gone |= *n == 0;
                }
            }
            if gone {
                self.find_lowest();
            }
        }
        true
    }

    /// The figures of the blocks held, oldest first, as one slice: the `i`-th is
    /// `fig(i)`. (The walk of [`Engine::limits_ahead`] visits up to a few hundred every
    /// cycle.)
    #[inline]
    fn held(&self) -> &[BlockFigs] {
        self.figs
            .get(self.head..self.head + self.len)
            .unwrap_or(&[])
    }

    /// [`Window::lowest`] and its counts found afresh: a walk over the figures held.
    fn find_lowest(&mut self) {
        let all = self.held();
        let held = || all.iter().filter(|f| f.motion);
        let lowest = held().fold(NO_LIMIT, |lo, f| min_lim(lo, f.lim));
        let mut at_lowest = [0; 2];
        for f in held() {
            at_lowest[0] += usize::from(f.lim.acc == lowest.acc);
            at_lowest[1] += usize::from(f.lim.jerk == lowest.jerk);
        }
        self.lowest = lowest;
        self.at_lowest = at_lowest;
    }
}

/// No limit: the lowest of no blocks.
const NO_LIMIT: Jerk = Jerk {
    acc: f64::INFINITY,
    jerk: f64::INFINITY,
};

/// A speed limit ahead: at most `v` mm/s, `d` mm further on, reached under `lim`.
#[derive(Debug, Clone, Copy)]
struct Ahead {
    d: f64,
    v: f64,
    lim: Jerk,
    /// The limits of the block beyond the point: the speed reached there must not rise
    /// above `v` afterwards either, with the acceleration it carries over that block's
    /// jerk.
    next: Jerk,
}

impl Ahead {
    /// The limits to brake for this point under: the acceleration of the blocks before
    /// it, and the lower jerk of those and the block beyond. A braking that eases a
    /// rising speed off onto `v` may go on past the point, and there the later block's
    /// jerk holds: eased under the higher jerk before it, the speed entered a block of
    /// a lower one still rising, and rose over its feed (a weak axis 1.07 % over its
    /// velocity in the random search of the planner's `limits.rs`).
    ///
    /// A stop (`v` = 0) is braked for under the limits before it alone: the braking ends
    /// at rest on the point, and nothing of it goes on past it. (Under the lower jerk
    /// of a weak block beyond the stop, a 20 mm line before it took 696 cycles instead
    /// of 464.)
    fn easing(&self) -> Jerk {
        if self.v <= 0.0 {
            return self.lim;
        }
        eased(self.lim, self.next)
    }
}

/// Limits `lim` with the jerk lowered to `beyond`'s where that is lower (see
/// [`Ahead::easing`]).
fn eased(lim: Jerk, beyond: Jerk) -> Jerk {
    Jerk {
        acc: lim.acc,
        jerk: lim.jerk.min(beyond.jerk),
    }
}

/// Writes `a` into the next free slot of `out`; false when every slot is taken.
fn keep(out: &mut [Ahead; MAX_AHEAD], n: &mut usize, a: Ahead) -> bool {
    match out.get_mut(*n) {
        Some(slot) => {
            *slot = a;
            *n += 1;
            true
        }
        None => false,
    }
}

/// A low passed on the way to a limit further on (see [`Engine::spare`]).
#[derive(Debug, Clone, Copy)]
struct Low {
    /// Where it is (mm ahead) and its speed.
    d: f64,
    v: f64,
    /// The highest acceleration the machine may carry there.
    acc: f64,
    /// The jerk of the block beyond it: the one that eases off what it carries.
    jerk: f64,
}

impl Low {
    /// The highest acceleration it may be passed with.
    fn passing_acc(&self) -> f64 {
        self.acc.min((2.0 * self.jerk * self.v.max(0.0)).sqrt())
    }

    /// The highest speed the easing of that acceleration reaches under the jerk `j`
    /// (no higher than the jerk beyond the low): passed at `v` with `a`,
    /// `v + a²/2·jerk ≤ low.v`, the speed rises to `v + a²/2j`, highest where `a` is.
    /// (`a` is [`Low::passing_acc`], found once by the caller: it takes a square root.)
    #[inline]
    fn peak(&self, a: f64, j: f64) -> f64 {
        let rise = a * a / (2.0 * self.jerk);
        (self.v - rise).max(0.0) + a * a / (2.0 * j)
    }

    /// The highest speed to pass the low with so that the easing under `j` stays
    /// within `r` (the inverse of [`Low::peak`]; `low.v` if that is already so), `peak`
    /// being `self.peak(self.passing_acc(), j)`.
    fn passed_below(&self, peak: f64, r: f64, j: f64) -> f64 {
        if peak <= r {
            return self.v;
        }
        self.passed_from(r, j)
    }

    /// [`Low::passed_below`] where the peak is above `r`: the speed to pass the low with
    /// so that the easing under `j` stays within `r`, no higher than `low.v`.
    #[inline]
    fn passed_from(&self, r: f64, j: f64) -> f64 {
        let a2 = self.acc * self.acc;
        // Passed at its full acceleration: `v - a²/2jerk + a²/2j = r`; where that is
        // slower than the acceleration allows (`a² = 2·jerk·v`): `v·jerk/j = r`.
        // (Two of its divisions are the same in every fold under one set of limits; kept
        // from fold to fold they made `cycle/profile_worst`'s p99 slower, 2654 against
        // 2444–2533 ns: the divisions run beside the rest, the look-up did not.)
        let full = r + a2 / (2.0 * self.jerk) - a2 / (2.0 * j);
        let root = r * j / self.jerk;
        let v = if 2.0 * self.jerk * root <= a2 {
            root
        } else {
            full
        };
        v.clamp(0.0, self.v)
    }
}

fn is_motion(b: &CommandBlock) -> bool {
    b.kind == BlockKind::Motion as u32
}

/// The tangential limits a block's profile may use.
fn block_jerk(b: &CommandBlock) -> Jerk {
    Jerk {
        acc: b.acc_mm_per_s2,
        jerk: b.jerk_mm_per_s3,
    }
}

/// A speed (zero acceleration) from which `v` is reached within `d` mm under `lim`: the
/// highest such to within an eighth of a per cent, never above it (a few steps of
/// bisection on the closed-form distance; cheap enough for the cycle). The search stops
/// as soon as it finds one no lower than `enough` (for a caller that only asks whether
/// `enough` is within reach).
fn reach_within(lim: Jerk, v: f64, d: f64, enough: f64) -> f64 {
    if d <= 0.0 || v >= enough {
        return v;
    }
    // Upper bracket: the speed change whose distance alone at the higher speed is `d`
    // cannot exceed reaching it at jerk and acceleration limits from rest.
    // (The cube root, costly, only where it is the larger: rooms over `8·acc³/jerk²`.)
    let (sat, cub) = ((2.0 * lim.acc * d).sqrt(), lim.jerk * d * d);
    let (mut lo, mut hi) = (
        v,
        v + if sat * sat * sat >= cub {
            sat
        } else {
            cub.cbrt()
        },
    );
    // Ten steps, two at a time: the second step's midpoint is one of two known ahead
    // (`up` where the first succeeds, `down` where it fails), so both are tested beside
    // the first instead of after it. The same midpoints and tests as one step at a time,
    // so the same answer to the bit, in a shorter chain of dependent operations: the folds
    // of `limits_ahead`, some fifteen in a cycle that crosses a block end of
    // `cycle/profile_worst`, each wait on theirs.
    for _ in 0..5 {
        let mid = 0.5 * (lo + hi);
        let (up, down) = (0.5 * (mid + hi), 0.5 * (lo + mid));
        // (Selected, not branched on: the outcome of each step is a coin toss.)
        let ok = change_within(lim, mid, v, d);
        let (ok_up, ok_down) = (change_within(lim, up, v, d), change_within(lim, down, v, d));
        lo = if ok { mid } else { lo };
        hi = if ok { hi } else { mid };
        if lo >= enough {
            break;
        }
        let (mid, ok) = if ok { (up, ok_up) } else { (down, ok_down) };
        lo = if ok { mid } else { lo };
        hi = if ok { hi } else { mid };
        if lo >= enough {
            break;
        }
    }
    lo
}

/// [`shared::profile::Limits::change_within`], the same arithmetic with both branches
/// evaluated and one selected (no branch to mispredict in a bisection).
#[inline]
fn change_within(lim: Jerk, v0: f64, v1: f64, d: f64) -> bool {
    let (acc, jerk) = (lim.acc, lim.jerk);
    let dv = (v0 - v1).abs();
    let sum = v0 + v1;
    let sat = dv * jerk >= acc * acc;
    let within_sat = 0.5 * sum * (dv * jerk + acc * acc) <= d * (acc * jerk);
    let within = (d >= 0.0) & (sum * sum * dv <= d * d * jerk);
    (sat & within_sat) | (!sat & within)
}

fn min_lim(a: Jerk, b: Jerk) -> Jerk {
    Jerk {
        acc: a.acc.min(b.acc),
        jerk: a.jerk.min(b.jerk),
    }
}

/// The evaluators of the motion being run, loaded at each block's start: the moving-data
/// curve evaluator of seed 001 (§3.3) for curves, and for surface passes the moving-data
/// surface evaluator of seed 000 (`S`, `S_u`, `S_v` and the normal every cycle).
struct Geometry {
    curve: FastCurve,
    surf: Option<FastSurface>,
}

impl Geometry {
    /// Loads the evaluators of `b`, a block of the window: validated when it was taken
    /// in ([`Engine::intake`]), so its curve is not checked a second time
    /// ([`FastCurve::load_valid`]).
    fn load(&mut self, b: &CommandBlock) -> Result<(), Fault> {
        if b.is_surface() {
            let s = path::pass_evaluator(b).map_err(|_| {
                Fault::Protocol(ProtocolError::BadField {
                    seq: b.seq,
                    field: "surface patch",
                })
            })?;
            self.surf = Some(s);
            return Ok(());
        }
        self.surf = None;
        self.curve
            .load_valid(b.degree as usize, b.knots(), b.ctrl())
            .map_err(|err| Fault::Protocol(ProtocolError::Curve { seq: b.seq, err }))
    }

    /// The path the profile steps along at `u`: the curve, or a surface pass's
    /// cutter-contact point (where the feed is programmed).
    #[inline]
    fn eval(&mut self, block: &CommandBlock, u: f64) -> CurvePoint {
        match &mut self.surf {
            Some(s) if block.is_surface() => {
                let (uv, rate) = path::pass_uv(block, u);
                path::contact_at_rate(rate, &s.eval(uv[0], uv[1]))
            }
            _ => {
                let mut e = self.curve.eval(u);
                path::add_axial(block, u, &mut e);
                e
            }
        }
    }

    /// The set-point at `u`, where the path point `e` was evaluated: the path point itself,
    /// or over a surface the ball-nose tool's reference point `M = C + R·n + (H − R)·z`.
    #[inline]
    fn set_point(&mut self, block: &CommandBlock, u: f64, e: &CurvePoint) -> [f64; 3] {
        match &mut self.surf {
            Some(s) if block.is_surface() => {
                let (uv, _) = path::pass_uv(block, u);
                path::tool_point(block, &s.eval(uv[0], uv[1]))
            }
            _ => e.p,
        }
    }
}

/// Loads `b`'s evaluators into `geom`: the motion at its start.
fn load_motion(geom: &mut Geometry, b: &CommandBlock) -> Result<Motion, Fault> {
    geom.load(b)?;
    let (u0, u1) = path::domain(b);
    let end = geom.eval(b, u1);
    let at = geom.eval(b, u0);
    Ok(Motion {
        u: u0,
        u_end: u1,
        s_mm: 0.0,
        end_mm: end.p,
        end_out: geom.set_point(b, u1, &end),
        at,
        feed_mm_per_s: b.feed_mm_per_min / 60.0,
    })
}

pub struct Engine {
    lim: Limits,
    geom: Box<Geometry>,
    /// The evaluators of the next block held, loaded ahead in a cycle that crossed no
    /// block end, and that block's start ([`Engine::preload`]): swapped in when the block
    /// starts (boxed, so the swap moves two pointers, not two 4 KB evaluators).
    next_geom: Box<Geometry>,
    preloaded: Option<(u64, Motion)>,
    t_s: f64,
    cur: Current,
    /// The block last taken from the window: the motion's while [`Current::Motion`].
    block: CommandBlock,
    window: Window,
    expected_seq: u64,
    speed: f64,
    /// Path (tangential) acceleration of the profile.
    acc: f64,
    /// Controlled stop: the distance left to the point where it ends at rest.
    stop_left_mm: f64,
    /// Where the path point is (the contact point on a surface pass).
    pos: [f64; 3],
    /// The set-point published: `pos`, or over a surface the tool reference point.
    out: [f64; 3],
    vel: [f64; 3],
    line: u32,
    seq: u64,
    rapid: bool,
    end_received: bool,
    done: bool,
    /// A controlled stop is under way: no new blocks, speed only falls.
    stopping: bool,
    /// A set-point step failed the last guard: the set-point is held where it was.
    halted: bool,
    /// Where the set-point path of the last motion block taken into the window ends (the
    /// machine's start before the first), and that block's sequence number: the next
    /// motion must start there.
    joint_mm: [f64; 3],
    joint_seq: Option<u64>,
    /// A fault found while taking a block in the middle of a tick, reported at the start
    /// of the next one (so that an `Err` from `tick` never leaves a half-made step).
    deferred: Option<Fault>,
    /// The next block, taken from the source and checked ahead while the window was
    /// full, in a cycle that crossed no block end ([`Engine::stage`]): `Ok` when it waits
    /// in the window's spare slot, `Err` with the fault its intake found; handed over
    /// where [`Engine::fill`] would have taken it from the source.
    staged: Option<Result<(), Fault>>,
    /// Tests only: take no block ahead, as before [`Engine::stage`] (the reference its
    /// test compares with).
    #[cfg(test)]
    no_staging: bool,
    /// Times the engine came to a stop for want of a block (not counting the program end).
    starvations: u64,
    starved: bool,
    /// Consecutive ticks a motion stood still mid-block while not stopping.
    still_ticks: u64,
    /// Feed fluctuation: relative difference of the chord actually stepped and the step
    /// the profile planned, over the cycles that stay inside one block.
    fluct_max: f64,
    fluct_sum_sq: f64,
    fluct_n: u64,
}

/// How closely the set-point steps follow the planned ones (seed 001's feed fluctuation).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Fluctuation {
    /// Largest `|chord / planned step - 1|`.
    pub max: f64,
    pub rms: f64,
    /// Cycles measured (moving, inside one block).
    pub cycles: u64,
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]])
}

/// Backward difference `(a - b) / t`.
fn rate(a: [f64; 3], b: [f64; 3], t: f64) -> [f64; 3] {
    [(a[0] - b[0]) / t, (a[1] - b[1]) / t, (a[2] - b[2]) / t]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

impl Engine {
    /// A stopped machine at `start_mm`.
    pub fn new(lim: Limits, start_mm: [f64; 3]) -> Self {
        // Any valid curve will do until the first motion block is loaded.
        let curve = match FastCurve::new(
            1,
            &[0.0, 0.0, 1.0, 1.0],
            &[[0.0; 3], [1.0, 0.0, 0.0]].map(|p| [p[0], p[1], p[2], 1.0]),
        ) {
            Ok(c) => c,
            Err(_) => unreachable!("a unit line is a valid curve"),
        };
        Engine {
            lim,
            geom: Box::new(Geometry {
                curve: curve.clone(),
                surf: None,
            }),
            next_geom: Box::new(Geometry { curve, surf: None }),
            preloaded: None,
            t_s: lim.period_ns as f64 * 1e-9,
            cur: Current::None,
            block: CommandBlock::empty(BlockKind::ProgramEnd, 0, 0),
            window: Window::new(lim.lookahead_blocks),
            expected_seq: 0,
            speed: 0.0,
            acc: 0.0,
            stop_left_mm: f64::INFINITY,
            pos: start_mm,
            out: start_mm,
            vel: [0.0; 3],
            line: 0,
            seq: 0,
            rapid: false,
            end_received: false,
            done: false,
            stopping: false,
            halted: false,
            joint_mm: start_mm,
            joint_seq: None,
            deferred: None,
            staged: None,
            #[cfg(test)]
            no_staging: false,
            starvations: 0,
            starved: false,
            still_ticks: 0,
            fluct_max: 0.0,
            fluct_sum_sq: 0.0,
            fluct_n: 0,
        }
    }

    /// Feed fluctuation over the run so far.
    pub fn fluctuation(&self) -> Fluctuation {
        Fluctuation {
            max: self.fluct_max,
            rms: if self.fluct_n > 0 {
                (self.fluct_sum_sq / self.fluct_n as f64).sqrt()
            } else {
                0.0
            },
            cycles: self.fluct_n,
        }
    }

    /// Path acceleration of the profile in the last tick.
    pub fn acc_mm_per_s2(&self) -> f64 {
        self.acc
    }

    /// Starts a controlled stop: from the next tick on, no block is taken from the source
    /// and the speed only falls, by `a·T` per cycle, along the path already in hand.
    pub fn stop(&mut self) {
        if !self.stopping {
            self.stopping = true;
            // The reaction: no more acceleration. Then the quickest stop from here.
            self.acc = self.acc.min(0.0);
            let lim = self.stop_limits();
            let (mut lo, mut hi) = (0.0, 1.0);
            while !lim.can_reach(self.speed, self.acc, 0.0, hi) && hi < 1e9 {
                lo = hi;
                hi *= 2.0;
            }
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if lim.can_reach(self.speed, self.acc, 0.0, mid) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            self.stop_left_mm = hi;
        }
    }

    fn stop_limits(&self) -> Jerk {
        Jerk {
            acc: self.lim.path_acc_mm_per_s2,
            jerk: self.lim.path_jerk_mm_per_s3,
        }
    }

    /// A controlled stop is under way (or over).
    pub fn stopping(&self) -> bool {
        self.stopping
    }

    /// The controlled stop is complete: the machine stands still on the path.
    pub fn at_rest(&self) -> bool {
        self.stopping && self.speed <= 0.0
    }

    /// Times the engine ran out of blocks mid-program and stopped on the path to wait.
    pub fn starvations(&self) -> u64 {
        self.starvations
    }

    /// Path speed commanded in the last tick.
    pub fn speed_mm_per_s(&self) -> f64 {
        self.speed
    }

    /// Source line of the block being run.
    pub fn source_line(&self) -> u32 {
        self.line
    }

    /// Blocks taken from the source so far.
    pub fn blocks_received(&self) -> u64 {
        // (A block staged is not taken yet: see `Engine::stage`.)
        self.expected_seq - u64::from(matches!(self.staged, Some(Ok(()))))
    }

    /// The set-point: where the machine is commanded to be.
    pub fn position(&self) -> [f64; 3] {
        self.out
    }

    /// True while the engine holds no look-ahead block and the program end has not been
    /// received yet (it will ask the source for one).
    pub fn wants_block(&self) -> bool {
        !self.window.is_full() && !self.done && !self.end_received && !self.stopping
    }

    /// Takes the next block into the look-ahead slot if there is room. A bad block is
    /// never taken; its fault is kept for the start of the next tick.
    fn fill_or_defer(&mut self, src: &mut impl BlockSource) {
        if self.deferred.is_some() {
            return;
        }
        if let Err(f) = self.fill(src) {
            self.deferred = Some(f);
        }
    }

    /// Takes blocks from the source until the window is full or the source has none.
    fn fill(&mut self, src: &mut impl BlockSource) -> Result<(), Fault> {
        // Nothing follows the program end: never ask the source past it. A stopping
        // machine takes nothing more.
        while self.wants_block() {
            match self.staged.take() {
                Some(Ok(())) => {
                    let kind = self.window.take_staged();
                    self.end_received = kind == Some(BlockKind::ProgramEnd as u32);
                    self.keep_chain();
                    continue;
                }
                Some(Err(f)) => return Err(f),
                None => {}
            }
            let Some(b) = src.next_block() else {
                break;
            };
            self.intake(&b)?;
            self.end_received = b.kind == BlockKind::ProgramEnd as u32;
            self.window.push(b);
            self.keep_chain();
        }
        Ok(())
    }

    /// The checks of a block taken from the source, in order: [`CommandBlock::validate`],
    /// its sequence number, and [`Engine::check_against_machine`]. Counts it taken.
    fn intake(&mut self, b: &CommandBlock) -> Result<(), Fault> {
        b.validate().map_err(Fault::Protocol)?;
        if b.seq != self.expected_seq {
            return Err(Fault::Protocol(ProtocolError::OutOfSequence {
                expected: self.expected_seq,
                got: b.seq,
            }));
        }
        self.check_against_machine(b)?;
        self.expected_seq += 1;
        Ok(())
    }

    /// Takes the next block from the source ahead, while the window is full, and checks
    /// it ([`Engine::intake`]) into the window's spare slot (or keeps the fault found):
    /// [`Engine::fill`] then hands it over where it would have taken it from the source,
    /// in the cycle that crosses a block end, with nothing left to check there. Called at
    /// the end of a cycle that crossed no block end and loaded nothing ahead: the intake
    /// (about 0.4 µs in the dearest cycles of `cycle/profile_worst`) moves out of the
    /// cycles that cross a block end, the dearest, and does not stack onto the preload.
    /// The window the profile sees is the same, so are the set-points; a fault is
    /// reported in the same tick as before.
    fn stage(&mut self, src: &mut impl BlockSource) {
        #[cfg(test)]
        if self.no_staging {
            return;
        }
        if self.staged.is_some()
            || self.deferred.is_some()
            || !self.window.is_full()
            || self.done
            || self.end_received
            || self.stopping
        {
            return;
        }
        let Some(b) = src.next_block() else {
            return;
        };
        let taken = self.intake(&b);
        if taken.is_ok() {
            self.window.stage(b);
        }
        self.staged = Some(taken);
    }

    /// Lowers the planned end speed before the block just taken where that block has
    /// lower limits than the one before it and cannot brake from that end speed to its
    /// own within its length under them ([`shared::profile::Limits::reachable_speed`],
    /// the function the planner uses, so its plans stay bit for bit as they are); and so
    /// on back while an end is lowered. A plan that brakes across several blocks is valid
    /// on the wire, but each limit ahead is braked for under the lowest limits of the way
    /// to it: a low behind a block of far lower limits looked lost from the moment it came
    /// into view, was braked for at that block's acceleration, too gently, and the
    /// machine entered the block at 2.5 mm/s where 1.18 was planned, a weak axis's jerk
    /// 1.65 times its limit (`limits.rs` in the planner's tests). With its entry kept by
    /// the block before, that low follows from the nearer one, as on the planner's own
    /// plans. Across blocks of equal limits, judging under the lowest limits is exact, and
    /// a chain of tiny blocks braking together keeps its speed (entered at zero
    /// acceleration each, it would crawl). At most one pass over the window a block; on
    /// the planner's plans, one test.
    fn keep_chain(&mut self) {
        let mut i = self.window.len;
        while let Some(fig) = i
            .checked_sub(1)
            .and_then(|k| self.window.motion(k))
            .copied()
        {
            i -= 1;
            let before = match i.checked_sub(1) {
                Some(k) => self.window.motion(k).map(|f| (f.end_mm_per_s, f.lim)),
                None => matches!(self.cur, Current::Motion(_)).then(|| {
                    (
                        self.block.end_feed_mm_per_min / 60.0,
                        block_jerk(&self.block),
                    )
                }),
            };
            let Some((v, lim)) = before else {
                return;
            };
            if fig.lim.acc >= lim.acc && fig.lim.jerk >= lim.jerk {
                return;
            }
            let entry = fig.lim.reachable_speed(fig.end_mm_per_s, fig.length_mm);
            // (A rounding's difference is no defect: the planner's plans stay untouched.)
            if v <= entry * (1.0 + 1e-9) {
                return;
            }
            match i.checked_sub(1) {
                Some(k) => self.window.lower_end(k, entry),
                None => {
                    self.block.end_feed_mm_per_min = entry * 60.0;
                    return;
                }
            }
        }
    }

    /// The checks of a valid block against the machine, before it enters the window (so
    /// the window only ever holds blocks the machine can run, and the machine can always
    /// stop by the end of the last good one): [`CommandBlock::validate_for`] (feeds and
    /// profile limits, a curve without jumps, the path within travel), and a motion must
    /// start where the one before it ended, to [`JOIN_TOL_MM`], comparing set-point paths
    /// (a surface pass's tool point). Once per block: no allocation, no panic.
    fn check_against_machine(&mut self, b: &CommandBlock) -> Result<(), Fault> {
        b.validate_for(&self.lim.machine).map_err(Fault::Protocol)?;
        if b.kind != BlockKind::Motion as u32 {
            return Ok(());
        }
        let (u0, u1) = path::domain(b);
        let start = path::eval(b, u0).p;
        let gap = dist(start, self.joint_mm);
        if gap > JOIN_TOL_MM || gap.is_nan() {
            return Err(Fault::Protocol(ProtocolError::StartGap {
                seq: b.seq,
                line: b.source_line,
                prev: self.joint_seq,
                gap_mm: gap,
            }));
        }
        self.joint_mm = path::eval(b, u1).p;
        self.joint_seq = Some(b.seq);
        Ok(())
    }

    /// The last guard before a set-point is published: no axis steps further than its
    /// velocity limit allows in one period, and the set-point is within travel. Returns
    /// the fault of the first that fails.
    fn guard(&self, from: [f64; 3], to: [f64; 3]) -> Result<(), Fault> {
        for (axis, ((a, b), limit)) in from.iter().zip(&to).zip(&self.lim.max_step_mm).enumerate() {
            let step = (b - a).abs();
            if step > *limit || step.is_nan() {
                return Err(Fault::StepTooLarge {
                    line: self.line,
                    seq: self.seq,
                    axis,
                    step_mm: step,
                    limit_mm: *limit,
                });
            }
        }
        travel::check_point(to, &self.lim.machine.axes).map_err(|err| Fault::OutOfTravel {
            line: self.line,
            seq: self.seq,
            err,
        })
    }

    /// Starts the block just taken from the window ([`Engine::block`]).
    fn start(&mut self) -> Result<(), Fault> {
        let b = &self.block;
        self.line = b.source_line;
        self.seq = b.seq;
        self.cur = match b.kind() {
            Some(BlockKind::Motion) => {
                let m = match self.preloaded.take() {
                    Some((seq, m)) if seq == b.seq => {
                        core::mem::swap(&mut self.geom, &mut self.next_geom);
                        m
                    }
                    _ => load_motion(&mut self.geom, b)?,
                };
                if b.is_surface() || self.out != self.pos {
                    // Into or out of a surface pass: the path point jumps between the
                    // contact point and the tool point (the set-point does not).
                    self.pos = m.at.p;
                }
                Current::Motion(m)
            }
            Some(BlockKind::Dwell) => Current::Dwell {
                cycles_left: b.dwell_ns.div_ceil(self.lim.period_ns.max(1)),
                line: b.source_line,
                seq: b.seq,
            },
            Some(BlockKind::ProgramEnd) | None => Current::End {
                line: b.source_line,
                seq: b.seq,
            },
        };
        Ok(())
    }

    /// Loads the evaluators of the next block held, if a motion not loaded yet, into the
    /// spare [`Geometry`], with its start, so that the cycle that crosses into it does
    /// not (what [`Engine::start`] would do there, the same arithmetic on an evaluator
    /// loaded afresh: the same set-points). Called at the end of a cycle that crossed no
    /// block end: a block's load (half a microsecond for a line) then no longer adds to
    /// the dearest cycles, those that cross a block end and take the next block in. A
    /// block that fails to load is left to [`Engine::start`], which faults as before.
    /// Returns whether it loaded one.
    fn preload(&mut self) -> bool {
        let Some(b) = self.window.get(0) else {
            return false;
        };
        if !is_motion(b) || self.preloaded.is_some_and(|(seq, _)| seq == b.seq) {
            return false;
        }
        self.preloaded = load_motion(&mut self.next_geom, b).ok().map(|m| (b.seq, m));
        true
    }

    /// Speed the next motion may be entered with: the planned end speed if the next block
    /// is a motion already in hand, otherwise zero.
    fn exit_speed(&self) -> f64 {
        match self.window.fig(0) {
            Some(n) if n.motion => self.block.end_feed_mm_per_min / 60.0,
            _ => 0.0,
        }
    }

    /// The speed limits ahead of the current motion `m`, nearest first, that can bind a
    /// machine at speed `v_top` or below: each block end's planned speed (zero where no
    /// motion follows in hand), keeping only those lower than every nearer one, up to the
    /// distance in which the machine can stop anyway, found from `v_top` and the motion's
    /// own limits `top` (an acceleration eased off further under a lower jerk ahead).
    /// Returns how many were written.
    fn limits_ahead(
        &self,
        m: &Motion,
        v_top: f64,
        top: Jerk,
        out: &mut [Ahead; MAX_AHEAD],
    ) -> usize {
        let mut lim = block_jerk(&self.block);
        let mut d = if m.u >= m.u_end {
            0.0
        } else {
            (self.block.length_mm - m.s_mm).max(dist(self.pos, m.end_mm))
        };
        let mut v = self.exit_speed();
        let mut n = 0usize;
        let mut lowest = f64::INFINITY;
        // The last low seen (distance, speed) and the limits of the blocks since it: a
        // lower limit further on that those blocks alone can brake for from the last low
        // needs no braking before it (keeping the last low keeps it too), so it is left
        // out (when there is room to spare: see `spare`). Without this, its braking would be judged under the lowest limits of the
        // whole way, including blocks before the last low where the machine may brake
        // harder, and could look lost long before it is.
        let mut last_low: Option<Low> = None;
        let mut since_low: Option<Jerk> = None;
        // The highest acceleration the machine may carry up to the point reached: its
        // own, and each block's limit on the way (a block of a lower limit is entered
        // with the acceleration of the one before and comes down to its own inside it).
        let mut acc_hi = self.acc.abs().max(lim.acc);
        // Beyond the stopping distance nothing can bind: from `v_top` to rest, after
        // this cycle and after the time it takes to bring a positive acceleration back to
        // zero, under the lowest limits of the motion and every block in hand. (Under
        // the limits met so far, a block of far lower ones further on was looked at too
        // late: its end speed first showed where it could no longer be braked for, and a
        // curve's junction was passed at six times its speed.)
        let reach_d = {
            let braking = min_lim(min_lim(lim, top), self.window.lowest);
            // The highest acceleration of this cycle: the motion's, raised by its jerk
            // for at most one period, up to its limit (a braking only lowers it). The
            // speed rises in the cycle by at most `v_top - v` plus `J·T²/2` under the
            // jerk, and a rising speed eased off from there under the lowest jerk rises
            // further by `a²/2j`, taking `a/j`. (Taken
            // as the whole limit, the walk reached three to four times as far as any
            // limit could bind: 2 mm, 200 blocks, at 26 mm/s on the chain of
            // `cycle/profile_worst`, every limit past the 16th folded into it.)
            let a_top = self
                .acc
                .max((self.acc + top.jerk * self.t_s).min(top.acc))
                .max(0.0);
            let v_peak =
                v_top + 0.5 * top.jerk * self.t_s * self.t_s + a_top * a_top / (2.0 * braking.jerk);
            let easing = a_top / braking.jerk;
            braking.change_distance(v_peak, 0.0) + v_peak * (self.t_s + easing)
        };
        // The lowest jerk of the blocks beyond the limits kept so far.
        let mut kept_next_jerk = f64::INFINITY;
        // The last fold's spare and what it was found from (see `fold_full`).
        let mut fold_memo = None;
        let mut held = self.window.held().iter();
        // The figures of the block beyond the point reached, if a motion (the walk ends
        // at the first that is not).
        let mut beyond = held.next().filter(|f| f.motion);
        loop {
            let next = beyond.map_or(lim, |f| f.lim);
            if v >= lowest
                && next.jerk < kept_next_jerk
                && v.is_finite()
                && !self.implied(last_low, since_low, next, v, d)
            {
                // Not lower than a nearer limit, but the block beyond it eases a rising
                // speed off more slowly than any beyond those: a speed passed under a
                // nearer one may still be rising here, and rise over this one after it
                // (its `next`). Kept as it is; it does not take the place of the lowest.
                // Unless the last low keeps it ([`Engine::implied`]): kept, a chain of
                // blends at one speed whose jerks differ in the last digit had the line
                // before it brake for the chain's far end under the chain's acceleration,
                // a third of the line's (a raster's 20 mm pass 32 cycles slower).
                kept_next_jerk = next.jerk;
                if !keep(out, &mut n, Ahead { d, v, lim, next }) {
                    if let Some(last) = out.get_mut(MAX_AHEAD - 1) {
                        last.next = min_lim(last.next, next);
                    }
                }
            }
            if v < lowest {
                lowest = v;
                let implied = self.implied(last_low, since_low, next, v, d);
                last_low = Some(Low {
                    d,
                    v,
                    acc: acc_hi,
                    jerk: next.jerk,
                });
                since_low = None;
                let a = Ahead { d, v, lim, next };
                if implied {
                    // Kept by keeping the last low.
                } else if keep(out, &mut n, a) {
                    kept_next_jerk = kept_next_jerk.min(next.jerk);
                } else if let Some(last) = out.get_mut(MAX_AHEAD - 1) {
                    // No room for it: the last kept limit takes it over, lowered to the
                    // highest speed from which this one can still be kept between the two
                    // (found conservatively, with time to spare: see `spare`). Lowering
                    // it to this one's speed would be safe too, but on a long chain of
                    // tiny blocks slowing down to a stop it makes the machine crawl.
                    let easing = eased(lim, next);
                    let low = Low {
                        d: last.d,
                        v: last.v,
                        acc: acc_hi,
                        jerk: last.next.jerk,
                    };
                    last.v = last
                        .v
                        .min(self.folded(low, easing, v, d - last.d, &mut fold_memo));
                    last.lim = min_lim(last.lim, lim);
                    last.next = min_lim(last.next, next);
                    kept_next_jerk = kept_next_jerk.min(next.jerk);
                }
            }
            // Beyond the stopping distance nothing can bind, and nothing is below zero.
            if v <= 0.0 {
                break;
            }
            if d > reach_d {
                break;
            }
            let Some(b) = beyond else {
                break;
            };
            lim = min_lim(lim, b.lim);
            acc_hi = acc_hi.max(b.lim.acc);
            since_low = Some(since_low.map_or(b.lim, |l| min_lim(l, b.lim)));
            d += b.length_mm;
            beyond = held.next().filter(|f| f.motion);
            v = match beyond {
                Some(_) => b.end_mm_per_s,
                None => 0.0,
            };
        }
        n
    }

    /// The speed a kept limit `low` (as a [`Low`]: its place and speed, the acceleration
    /// the machine may carry there and the jerk of the block beyond it) is lowered to when
    /// a lower limit `v`, `gap` mm beyond it, braked for under `easing`, is folded into it
    /// (see [`Engine::limits_ahead`]; `memo` keeps the last spare found).
    ///
    /// The usual case first, without the spare's square root and divisions: on a chain of
    /// tiny blocks braking at speed (some forty folds in a cycle of `cycle/profile_worst`
    /// at its p99, each waiting on the last) the spare past the low alone exceeds the gap
    /// ([`Engine::spare_exceeds`]), so the room is negative and the search gives `v`
    /// itself; and `v` is below `low.v` by more than rounding, so below the easing's peak
    /// (never under `low.v` by more than an ulp: the easing under a jerk no higher than
    /// the low's rises at least as far as it falls). The low is then passed below from
    /// `v`: the arithmetic [`Engine::fold_full`] does in that case, so the same bits.
    #[inline]
    fn folded(
        &self,
        low: Low,
        easing: Jerk,
        v: f64,
        gap: f64,
        memo: &mut Option<([u64; 4], (f64, f64))>,
    ) -> f64 {
        if v < low.v * (1.0 - 1e-12) && self.spare_exceeds(low, easing.jerk, gap) {
            return low.passed_from(v, easing.jerk.min(low.jerk));
        }
        self.fold_full(low, easing, v, gap, memo)
    }

    /// [`Engine::folded`] the long way: the spare past the low, the highest speed from
    /// which `v` is reached in the room left, and the low passed below that.
    fn fold_full(
        &self,
        low: Low,
        easing: Jerk,
        v: f64,
        gap: f64,
        memo: &mut Option<([u64; 4], (f64, f64))>,
    ) -> f64 {
        // (Folds in a row into an unchanged limit, under unchanged limits, find the same
        // spare: kept, not found again.)
        let key = [low.v, low.acc, low.jerk, easing.jerk].map(f64::to_bits);
        let (peak, spare) = match *memo {
            Some((k, found)) if k == key => found,
            _ => {
                let found = self.spare(low, easing);
                *memo = Some((key, found));
                found
            }
        };
        let room = gap - spare;
        // (The search ends once it shows the low's easing, `peak`, within reach: the low
        // is then kept as it is, whatever the rest finds.)
        let r = reach_within(easing, v, room, peak);
        low.passed_below(peak, r, easing.jerk.min(low.jerk))
    }

    /// Whether the limit `v`, `d` mm ahead with the block `next` beyond it, is kept by
    /// keeping the last low (`last_low`, the blocks since it having the limits
    /// `since_low`): those blocks alone can brake from what the low may be passed with
    /// to `v` within the distance between them, with two cycles' travel to spare (the
    /// braking for it then starts a full cycle after the low is passed, not inside the
    /// cycle that crosses it), under the jerk of the block beyond it too (see
    /// [`Ahead::easing`]).
    #[inline]
    fn implied(
        &self,
        last_low: Option<Low>,
        since_low: Option<Jerk>,
        next: Jerk,
        v: f64,
        d: f64,
    ) -> bool {
        let (Some(low), Some(seg)) = (last_low, since_low) else {
            return false;
        };
        // (The spare first: on tiny blocks it alone exceeds the room.)
        if self.spare_exceeds(low, seg.jerk.min(next.jerk), d - low.d) {
            return false;
        }
        let seg = eased(seg, next);
        let (peak, spare) = self.spare(low, seg);
        let room = d - low.d - spare;
        room >= 0.0 && seg.change_within(v, peak, room)
    }

    /// The highest speed, and the distance to allow for, past a low `low` before the
    /// braking for a limit beyond it can begin, the blocks between having the limits
    /// `seg` (their lowest).
    ///
    /// The low is passed no faster than `low.v`, with an acceleration `a` that the
    /// block beyond it eases off within it (`v + a²/2j ≤ low.v`, `j` that block's jerk)
    /// and no higher than the machine may carry there (`low.acc`). Under the lower jerk
    /// of the blocks after it the same easing rises further, by `a²/2·seg.jerk` (a
    /// lower limit beyond a short fast stretch, judged from `low.v` alone, was reached
    /// with 1.1 times the speed its braking was planned from, and lost). The braking may
    /// only begin in the cycle after the one that crosses the low (two periods), and
    /// easing the acceleration off takes `a/seg.jerk` seconds at up to that speed. (The
    /// rise inside those two periods is left out, as before this was written: counted
    /// too, a chain of 0.01 mm lines slowing to a stop topped at 51 % of its planned
    /// speed instead of 61 %, and the random search finds no limit broken without it.)
    fn spare(&self, low: Low, seg: Jerk) -> (f64, f64) {
        let j_s = seg.jerk.min(low.jerk);
        let a = low.passing_acc();
        let peak = low.peak(a, j_s);
        (peak, peak * (2.0 * self.t_s + a / j_s))
    }

    /// True only where `gap` is shorter than the distance [`Engine::spare`] allows past
    /// `low` under the jerk `seg_jerk` (so a limit `gap` beyond the low is not implied by
    /// it): shown without its square root and divisions, from `peak >= low.v` (the easing
    /// under a jerk no higher than the low's own rises at least as far as it falls), with
    /// a relative margin of `1e-6` that rounding cannot cross. False where it cannot
    /// tell; the full test then decides. (On a chain slowing down to a stop, every block
    /// end is a new low 10 µm past the last, with a spare of about half a millimetre:
    /// `cycle/profile_worst`'s dearest cycles made about 90 such tests.)
    #[inline]
    fn spare_exceeds(&self, low: Low, seg_jerk: f64, gap: f64) -> bool {
        let w = low.v;
        let j_s = seg_jerk.min(low.jerk);
        if !(w >= 0.0 && j_s > 0.0) {
            return false;
        }
        // gap·(1 + 1e-6) < w·(2T + passing_acc/j_s), with passing_acc² = min(acc², 2·jerk·w).
        let x = gap * (1.0 + 1e-6) - 2.0 * self.t_s * w;
        if x < 0.0 {
            return true;
        }
        let pa2 = (low.acc * low.acc).min(2.0 * low.jerk * w);
        let lhs = x * j_s;
        lhs * lhs < w * w * pa2
    }

    /// The highest acceleration the motion `m` may rise to now: its block's own limit,
    /// and each block ahead's, raised by what the lower jerk of the two can shed before
    /// the machine (at up to `v_top` plus the rise of that acceleration) gets there. A
    /// block is then entered with no more acceleration than it allows: entered with
    /// more, it came down to its own only inside it, and along a curve whose limits
    /// leave the tangent little of an axis's share that broke the axis's (X's jerk at
    /// 4.3 times its limit in the planner's random search).
    fn acc_ceiling(&self, m: &Motion, own: Jerk, v_top: f64) -> f64 {
        let mut ceiling = own.acc;
        // No block in hand allows less: nothing to walk for (a chain of equal blocks).
        if self.window.lowest.acc >= ceiling {
            return ceiling;
        }
        let v_max = v_top + own.acc * own.acc / (2.0 * own.jerk) + 1e-9;
        let mut d = if m.u >= m.u_end {
            0.0
        } else {
            (self.block.length_mm - m.s_mm).max(0.0)
        };
        // Two periods' travel first: the step that crosses into a block, and the one
        // before it that could not yet see it.
        let lead = 2.0 * self.t_s * v_max;
        // Where even the lowest jerk in hand sheds all of it, nothing further binds.
        let j_lo = own.jerk.min(self.window.lowest.jerk);
        // Nor past a block planned to end at rest: the machine comes to rest there with
        // no acceleration, whatever the blocks after it allow. (Walked past it, a blend's
        // low limits 30 mm beyond an exact stop held the line before the stop to a
        // fraction of its acceleration.)
        let mut at_rest = self.block.end_feed_mm_per_min <= 0.0;
        for b in self.window.held().iter().take_while(|f| f.motion) {
            if at_rest {
                break;
            }
            at_rest = b.end_mm_per_s <= 0.0;
            let tau = (d - lead).max(0.0) / v_max;
            if j_lo * tau >= ceiling {
                break;
            }
            let shed = own.jerk.min(b.lim.jerk) * tau;
            ceiling = ceiling.min(b.lim.acc + shed);
            d += b.length_mm;
        }
        ceiling
    }

    /// The cycle's profile step in motion `m`: the new speed and acceleration and the
    /// distance covered.
    ///
    /// The machine follows its preferred motion (accelerate: jerk `+J` up to the block's
    /// acceleration, then hold it; in a controlled stop, the quickest braking to rest)
    /// for as long as every limit ahead can still be kept by the quickest braking to it,
    /// and from the last such moment inside the cycle it follows that braking. Once
    /// braking, the next cycle finds no moment to spare and follows the same braking on:
    /// the profile tracks the continuous time-optimal one, switching inside cycles, and
    /// lands exactly on each stop.
    ///
    /// The moments are found to `T·`[`SWITCH_RESOLUTION`]: a limit's by regula falsi on
    /// its room ([`latest_ok`], on a margin without jumps), the moment a point is passed
    /// by Newton's method ([`crossing`]). Most limits ahead are shown kept at the end of
    /// a piece by a test without a square root
    /// ([`shared::profile::Limits::brake_within`]) before their braking distance is
    /// asked. (On the tiny segments of `cycle/profile_worst`, per cycle in its 0.1 %
    /// dearest cycles: 60 braking distances, 54 search steps, became 2 and 6.)
    fn profile_step(&self, m: &Motion) -> (f64, f64, f64) {
        let t = self.t_s;
        let own = if self.stopping {
            self.stop_limits()
        } else {
            block_jerk(&self.block)
        };
        let x0 = profile::Motion {
            v: self.speed,
            a: self.acc,
            s: 0.0,
        };
        // The speed reached before a braking can begin: this cycle's rise, then an
        // acceleration eased off (further under a lower jerk ahead: `limits_ahead`).
        let v_top = x0.v + x0.a.abs() * t;
        let mut ahead = [Ahead {
            d: 0.0,
            v: 0.0,
            lim: own,
            next: own,
        }; MAX_AHEAD];
        let mut n = self.limits_ahead(m, v_top, own, &mut ahead);
        if self.stopping {
            // The stop point, unless a limit of the path ends the stop sooner.
            if let Some(slot) = ahead.get_mut(n.min(MAX_AHEAD - 1)) {
                *slot = Ahead {
                    d: self.stop_left_mm,
                    v: 0.0,
                    lim: own,
                    next: own,
                };
                n = (n + 1).min(MAX_AHEAD);
            }
        }
        let cap = m.feed_mm_per_s;
        // Past the end of this block (a step that crosses it), the feed and limits of the
        // block the motion is in cap the speed for the rest of the cycle: the next one,
        // or one further on when the step crosses short blocks (a blend's entry speed
        // kept on passing into it is no bound on the speed rising later in it).
        let end_here = ahead
            .get(..n)
            .and_then(|a| a.first())
            .map_or(f64::INFINITY, |l| l.d);
        let cap_at = |x: &profile::Motion| {
            if x.s <= end_here {
                return (cap, own);
            }
            let mut d = end_here;
            let mut i = 0;
            while let Some(b) = self.window.motion(i) {
                d += b.length_mm;
                let last = self.window.motion(i + 1).is_none();
                if x.s <= d || last {
                    return (b.feed_mm_per_s, b.lim);
                }
                i += 1;
            }
            (0.0, own)
        };
        let ceiling = self.acc_ceiling(m, own, v_top);
        let preferred: profile::Phases = if self.stopping {
            own.brake(x0, 0.0)
        } else if x0.a <= ceiling {
            [
                (own.jerk, (ceiling - x0.a) / own.jerk),
                (0.0, f64::INFINITY),
                (0.0, 0.0),
            ]
        } else {
            // A block with a lower acceleration limit than the last, or one ahead: come
            // down to it.
            [
                (-own.jerk, (x0.a - ceiling) / own.jerk),
                (0.0, f64::INFINITY),
                (0.0, 0.0),
            ]
        };
        // Room left for limit `c` (0 = the feed cap, then the limits ahead) at the motion
        // `x`: negative when the quickest braking from there can no longer keep it.
        let room = |c: usize, x: profile::Motion| -> f64 {
            if c == 0 {
                let (cap, lim) = cap_at(&x);
                return cap - (x.v + x.a.max(0.0).powi(2) / (2.0 * lim.jerk));
            }
            match ahead.get(c - 1) {
                // A limit passed in this cycle was kept on passing (the room was not
                // negative before): it binds no more.
                Some(l) if x.s > l.d => f64::INFINITY,
                // Easing off now keeps the speed below it for good: no hurry. (The
                // acceleration need not be back to zero where a limit is passed: what
                // follows it has limits of its own. The easing may go on past it, so
                // under the lower jerk of the blocks before and after it: a block with
                // a smaller jerk budget, as a curve after a line, would otherwise be
                // entered too fast to ease off within its feed.)
                Some(l)
                    if x.v + x.a.max(0.0).powi(2) / (2.0 * l.lim.jerk.min(l.next.jerk)) <= l.v =>
                {
                    f64::INFINITY
                }
                Some(l) => l.d - x.s - l.easing().brake_distance(x, l.v),
                None => f64::INFINITY,
            }
        };
        // The room as the search for the moment a limit is lost sees it: where easing
        // off keeps the speed below the limit (the room is unbounded there), the speed
        // left to spare before that is no longer so, times the period (mm, as the room).
        // Same sign everywhere, but no jump where the limit stops being kept by easing
        // off: a limit lost right there (its braking no longer fits once the speed's
        // peak reaches it, as on a chain of tiny blocks) is found in a few secant steps,
        // not in the 30 halvings a jump from an unbounded margin takes.
        let margin = |c: usize, x: profile::Motion| -> f64 {
            if let Some(l) = c.checked_sub(1).and_then(|i| ahead.get(i)) {
                let peak = x.v + x.a.max(0.0).powi(2) / (2.0 * l.lim.jerk.min(l.next.jerk));
                if x.s <= l.d && peak <= l.v {
                    return t * (l.v - peak);
                }
            }
            room(c, x)
        };
        let brake_for =
            |c: usize, x: profile::Motion| match c.checked_sub(1).and_then(|i| ahead.get(i)) {
                Some(l) => l.easing().brake(x, l.v),
                None => {
                    let (cap, lim) = cap_at(&x);
                    lim.brake(x, cap)
                }
            };
        // A cheap proof that limit `c` (one ahead, not the feed cap) is kept from `x`:
        // true only where `room(c, x)` is not negative (see
        // [`shared::profile::Limits::brake_within`]); false where it cannot tell.
        let kept = |c: usize, x: profile::Motion| match c.checked_sub(1).and_then(|i| ahead.get(i))
        {
            Some(l) => l.easing().brake_within(x, l.v, l.d - x.s),
            None => false,
        };
        let eps = 1e-12;
        let tol = t * SWITCH_RESOLUTION;
        // The feed cap over a piece of the cycle's motion that ends at `end`: each block's
        // is judged where the motion leaves it, the last one's at the end. (Judged only at
        // the end, a step into a faster block would let the speed rise over the feed of
        // the block it leaves, and come back down before its end.) Returns the moment
        // judged and the room there. Along an accelerating piece the room only shrinks,
        // along a braking one it only grows, so those moments are where it is least.
        let cap_left = |at: &dyn Fn(f64) -> profile::Motion,
                        cross: &dyn Fn(f64) -> f64,
                        t0: f64,
                        end: profile::Motion| {
            let from = at(t0).s;
            let mut d = end_here;
            let mut i = 0;
            while end.s > d {
                if d >= from {
                    let tc = cross(d);
                    let r = room(0, at(tc));
                    if r < -eps {
                        return (tc, r);
                    }
                }
                match self.window.motion(i) {
                    Some(b) => d += b.length_mm,
                    None => break,
                }
                i += 1;
            }
            (t, room(0, end))
        };
        // The cycle's motion is pieced together: the preferred motion, and from the first
        // moment a limit would be lost, the quickest braking for it; along that braking
        // another limit may bind later in the cycle, and so on.
        let (mut t0, mut x_start, mut phases) = (0.0, x0, preferred);
        let mut braking_for: Option<usize> = None;
        for _ in 0..=n + 1 {
            let at = |tau: f64| profile::follow(x_start, &phases, tau - t0);
            let end = at(t);
            // When the motion of this round passes the point `d` mm on: the feed cap and
            // the limit at a block end both ask it, so the last few answers are kept.
            let crossed = core::cell::Cell::new([(f64::NAN, 0.0); 4]);
            let cross = |d: f64| {
                let mut memo = crossed.get();
                if let Some(&(_, tau)) = memo.iter().find(|m| m.0 == d) {
                    return tau;
                }
                let tau = crossing(t0, t, tol, d, at);
                memo.rotate_right(1);
                if let Some(first) = memo.first_mut() {
                    *first = (d, tau);
                }
                crossed.set(memo);
                tau
            };
            // The limit found first so far: its index, the moment its braking begins,
            // where that braking is at the end of the cycle, and the braking itself.
            let mut first: Option<(usize, f64, f64, profile::Motion, profile::Phases)> = None;
            for c in 0..=n {
                if braking_for == Some(c) {
                    // Followed already, as hard as it goes: it is kept along this braking
                    // if it can be kept at all.
                    continue;
                }
                // A limit the motion passes in this cycle is judged where it is passed:
                // there the speed, and the peak its acceleration still adds, must be
                // within it. (After it, the next block's own limits apply.)
                let passed = c
                    .checked_sub(1)
                    .and_then(|i| ahead.get(i))
                    .filter(|l| end.s > l.d)
                    .map(|l| {
                        let lo = cross(l.d);
                        let x = at(lo);
                        let peak = x.v + x.a.max(0.0).powi(2) / (2.0 * l.next.jerk);
                        (lo, l.v - peak)
                    });
                // The room at the end of the piece, where it is the room function itself
                // (kept for the search below, which would evaluate it again).
                let (t_end, room_end, f_end) = match passed {
                    Some((tp, r)) => (tp, r, None),
                    None if c == 0 => {
                        let (tc, r) = cap_left(&at, &cross, t0, end);
                        (tc, r, Some(r + eps))
                    }
                    // Most limits are far from binding: a cheap test proves it first.
                    None if kept(c, end) => continue,
                    None => {
                        let r = room(c, end);
                        (t, r, Some(r + eps))
                    }
                };
                if room_end >= -eps {
                    continue;
                }
                let x0 = at(t0);
                let k0 = kept(c, x0);
                let r0 = if k0 { 0.0 } else { room(c, x0) };
                let tau = if r0 < -eps {
                    t0
                } else {
                    // A limit still kept at the earliest moment found so far for another
                    // cannot be the first lost: no need to find its own moment.
                    let (hi, f_hi) = match first {
                        Some((_, tb, ..)) if tb < t_end => {
                            let xb = at(tb);
                            if kept(c, xb) {
                                continue;
                            }
                            let r = room(c, xb);
                            if r >= -eps {
                                continue;
                            }
                            (tb, Some(r + eps))
                        }
                        _ => (t_end, f_end),
                    };
                    // (Where the room at `t0` was proven by the cheap test, the search
                    // finds its value itself.)
                    let f_lo = (!k0 && r0.is_finite()).then_some(r0 + eps);
                    latest_ok(t0, hi, tol, f_lo, f_hi, |tau| margin(c, at(tau)) + eps)
                };
                let x = at(tau);
                let ph = brake_for(c, x);
                let s_end = profile::follow(x, &ph, t - tau).s;
                // Braking for another limit already, and this one lost where (or just
                // after) that braking began: the two cannot both be kept from here, and
                // braking for this one helps only if it brakes harder. Otherwise it is
                // left to the braking followed, and the search goes on for limits lost
                // later in the cycle, which can still be kept. (Before, a lost far limit
                // won over them: a line ran 0.8 % over its feed while braking, under a
                // blend's gentler jerk, for the blend's lost end speed. And two limits
                // lost at one moment took turns until the rounds ran out: the softer
                // braking, for a junction speed, could be left in force and lose an
                // exact stop 0.6 mm further on, reached at 2.5 mm/s.)
                if braking_for.is_some() && tau <= t0 + tol && s_end >= end.s {
                    continue;
                }
                // Ties (limits already lost together) go to the harder braking.
                let better = match first {
                    None => true,
                    Some((_, tb, sb, ..)) => tau < tb || (tau == tb && s_end < sb),
                };
                if better {
                    first = Some((c, tau, s_end, x, ph));
                }
            }
            let Some((c, tau, _, x, ph)) = first else {
                break;
            };
            t0 = tau;
            x_start = x;
            phases = ph;
            braking_for = Some(c);
        }
        let x1 = profile::follow(x_start, &phases, t - t0);
        (x1.v.max(0.0), x1.a, x1.s.max(0.0))
    }

    /// Advances one period. Allocation-free, panic-free.
    ///
    /// An `Err` is returned before anything moves: the engine is then exactly as after the
    /// previous tick, so the caller can [`stop`](Engine::stop) and keep ticking, and the
    /// set-points decelerate along the path from where they were.
    pub fn tick(&mut self, src: &mut impl BlockSource) -> Result<Tick, Fault> {
        if self.halted {
            return Ok(self.held());
        }
        if !self.stopping {
            if let Some(f) = self.deferred.take() {
                return Err(f);
            }
            if self.still_ticks as f64 * self.t_s >= STALL_SECONDS as f64 {
                self.still_ticks = 0;
                return Err(Fault::Stalled {
                    line: self.line,
                    seq: self.seq,
                });
            }
            self.fill(src)?;
        }
        let t = self.t_s;
        let mut budget: Option<f64> = None;
        let mut planned = 0.0;
        let mut crossed = false;
        let prev_pos = self.pos;
        let prev_out = self.out;
        let mut state = TickState::Running;
        for pass in 0..MAX_BLOCKS_PER_CYCLE {
            // The first pass's block was asked for above, before anything moved.
            if pass > 0 {
                self.fill_or_defer(src);
            }
            if let Current::None = self.cur {
                if self.window.pop_into(&mut self.block) {
                    // A step from a block's start measures no fluctuation: the path
                    // point may jump there (onto or off a surface's contact path).
                    crossed = true;
                    if let Err(f) = self.start() {
                        // Not loadable after all: stand still here, fault next tick.
                        self.deferred.get_or_insert(f);
                        self.cur = Current::None;
                        self.speed = 0.0;
                        self.acc = 0.0;
                        state = TickState::Starved;
                        break;
                    }
                    self.fill_or_defer(src);
                } else {
                    state = if self.done {
                        TickState::Done
                    } else {
                        TickState::Starved
                    };
                    self.speed = 0.0;
                    self.acc = 0.0;
                    break;
                }
            }
            match self.cur {
                Current::None => {}
                Current::End { line, seq } => {
                    self.line = line;
                    self.seq = seq;
                    self.done = true;
                    self.speed = 0.0;
                    self.acc = 0.0;
                    state = TickState::Done;
                    break;
                }
                Current::Dwell {
                    cycles_left,
                    line,
                    seq,
                } => {
                    self.line = line;
                    self.seq = seq;
                    if self.stopping {
                        // Already at rest: a stop ends the dwell.
                        self.cur = Current::Dwell {
                            cycles_left: 0,
                            line,
                            seq,
                        };
                        self.speed = 0.0;
                        self.acc = 0.0;
                        break;
                    }
                    if cycles_left == 0 {
                        self.cur = Current::None;
                        continue;
                    }
                    self.cur = Current::Dwell {
                        cycles_left: cycles_left - 1,
                        line,
                        seq,
                    };
                    self.speed = 0.0;
                    self.acc = 0.0;
                    break;
                }
                Current::Motion(mut m) => {
                    self.line = self.block.source_line;
                    self.seq = self.block.seq;
                    self.rapid = self.block.flags & FLAG_RAPID != 0;
                    let v_exit = self.exit_speed();
                    // At the end parameter the block is done, whatever the quadrature of
                    // its length says (near a cusp the two differ in the last digits).
                    let s_rem = if m.u >= m.u_end {
                        0.0
                    } else {
                        (self.block.length_mm - m.s_mm).max(dist(self.pos, m.end_mm))
                    };
                    let ds = match budget {
                        Some(d) => d,
                        None => {
                            let (v1, a1, mut ds) = self.profile_step(&m);
                            // Arriving at a stop: land on it exactly rather than creep
                            // the last fraction of a jerk step: within a thousandth of
                            // a jerk step's distance, when the speed left is a hundredth
                            // of one step's and the acceleration a thousandth (the jump
                            // dropping it adds a thousandth of the jerk for a period:
                            // with a hundredth, the next move starting in the next
                            // cycle overlapped this braking's last jerk phase, 1.0026
                            // times the jerk at a `G0 Z1`/`G1 Z-1` reversal of
                            // LinuxCNC's g6 chitarra). A landing with
                            // more left (the braking ends a fraction of a period into
                            // the next cycle) runs on: dropped at once, it put up to 70
                            // mm/s² into one period, and a next move starting in the
                            // next cycle added its own jerk to it (1.03 times the limit
                            // at a pass end of a surface part).
                            let snap = 1e-3
                                * self.block.jerk_mm_per_s3.max(self.lim.path_jerk_mm_per_s3)
                                * t
                                * t
                                * t;
                            // (The acceleration a landing may drop: `snap / T²`.)
                            let shed = snap / (t * t);
                            let (mut v1, mut a1) = (v1, a1);
                            if v_exit <= 0.0
                                && s_rem - ds <= snap
                                && v1 <= 10.0 * snap / t
                                && a1.abs() <= shed
                            {
                                ds = s_rem;
                                v1 = 0.0;
                                a1 = 0.0;
                            }
                            // Nor is one cut by the block-end test below (within 1e-9
                            // mm of the end) while it has more acceleration left: the
                            // step stops short by its last nanometres, and the next
                            // cycle ends the braking and the block (once: with 10 nm
                            // or less left the block ends, whatever the braking still
                            // holds, or a braking that cannot shed it in a period, on
                            // a chain of 10 µm blocks at 100 µs, never ended).
                            if v_exit <= 0.0
                                && !self.stopping
                                && s_rem > 1e-8
                                && ds >= s_rem - 1e-9
                                && a1.abs() > shed
                            {
                                ds = (s_rem - 2e-9).max(0.0);
                            }
                            if self.stopping {
                                self.stop_left_mm -= ds;
                                if v1 <= 1e3 * snap / t {
                                    v1 = 0.0;
                                    a1 = 0.0;
                                }
                            }
                            self.speed = v1;
                            self.acc = a1;
                            planned = ds;
                            ds
                        }
                    };
                    if ds <= 0.0 && self.stopping {
                        // Stopped inside the block: stay exactly where the last step ended.
                        self.cur = Current::Motion(m);
                        break;
                    }
                    if ds >= s_rem - 1e-9 {
                        // The block ends inside this period; carry the rest into the next.
                        self.pos = m.end_mm;
                        self.out = m.end_out;
                        self.cur = Current::None;
                        crossed = true;
                        if v_exit <= 0.0 {
                            // An exact stop: the next motion starts from rest.
                            self.speed = 0.0;
                            self.acc = 0.0;
                            break;
                        }
                        budget = Some(ds - s_rem);
                        continue;
                    }
                    let (u, e) = advance(&mut self.geom, &self.block, &m.at, m.u, m.u_end, ds);
                    m.u = u;
                    m.at = e;
                    m.s_mm += ds;
                    self.pos = e.p;
                    self.out = self.geom.set_point(&self.block, u, &e);
                    self.cur = Current::Motion(m);
                    break;
                }
            }
        }
        if !crossed && planned > 1e-9 {
            let f = (dist(self.pos, prev_pos) / planned - 1.0).abs();
            self.fluct_max = self.fluct_max.max(f);
            self.fluct_sum_sq += f * f;
            self.fluct_n += 1;
        }
        let stood_still = self.pos == prev_pos
            && matches!(self.cur, Current::Motion(_))
            && state == TickState::Running
            && !self.stopping;
        self.still_ticks = if stood_still { self.still_ticks + 1 } else { 0 };
        // A starvation is a stop for want of a block mid-program, counted once per stop.
        let starved = state == TickState::Starved && !self.stopping;
        if starved && !self.starved {
            self.starvations += 1;
        }
        self.starved = starved;
        if let Err(f) = self.guard(prev_out, self.out) {
            // Not published: back to the last set-point, and held there.
            self.pos = prev_pos;
            self.out = prev_out;
            self.halted = true;
            self.speed = 0.0;
            self.acc = 0.0;
            self.vel = [0.0; 3];
            return Err(f);
        }
        if !crossed && !self.preload() {
            self.stage(src);
        }
        let vel = rate(self.out, prev_out, t);
        let acc = rate(vel, self.vel, t);
        self.vel = vel;
        Ok(Tick {
            pos_mm: self.out,
            vel_mm_per_s: vel,
            acc_mm_per_s2: acc,
            speed_mm_per_s: self.speed,
            source_line: self.line,
            block_seq: self.seq,
            rapid: self.rapid,
            state,
        })
    }

    /// The tick of a halted engine: the last set-point, standing still.
    fn held(&self) -> Tick {
        Tick {
            pos_mm: self.out,
            vel_mm_per_s: [0.0; 3],
            acc_mm_per_s2: [0.0; 3],
            speed_mm_per_s: 0.0,
            source_line: self.line,
            block_seq: self.seq,
            rapid: self.rapid,
            state: TickState::Running,
        }
    }

    /// Checks the drives' answer; excess following error is a fault, as on a real control.
    pub fn on_feedback(&self, fb: &Feedback) -> Result<(), Fault> {
        fb.validate().map_err(Fault::Feedback)?;
        for (axis, e) in fb.ferr_mm.iter().enumerate() {
            if e.abs() > self.lim.max_following_error_mm {
                return Err(Fault::FollowingError {
                    cycle: fb.cycle,
                    axis,
                    ferr_mm: *e,
                    limit_mm: self.lim.max_following_error_mm,
                    line: self.line,
                });
            }
        }
        Ok(())
    }
}

/// The latest moment in `[lo, hi]` at which the margin `f` is still `>= 0`, given
/// `f(hi) < 0`, to within `tol`: `lo` itself when `f(lo) < 0` already.
///
/// The margins here (room left before a limit, distance left to a block end) are smooth
/// between the profile's phase changes, so regula falsi with the Illinois correction
/// closes in on the sign change in a handful of evaluations where halving the period
/// takes 30; a step that would not land strictly inside the bracket (an infinite margin,
/// a flat one) halves it instead, and once [`SWITCH_STEPS`] are spent only halvings
/// follow. Whatever the path, the moment returned is one where `f >= 0` was seen (or
/// `lo`), as with plain bisection, so a limit found kept there is kept. `f_lo` and
/// `f_hi` are `f(lo)` and `f(hi)` where the caller has them already (`None`: evaluated
/// here).
fn latest_ok(
    lo: f64,
    hi: f64,
    tol: f64,
    f_lo: Option<f64>,
    f_hi: Option<f64>,
    f: impl Fn(f64) -> f64,
) -> f64 {
    let (mut a, mut b) = (lo, hi);
    let mut fa = f_lo.unwrap_or_else(|| f(a));
    if fa.is_nan() || fa < 0.0 {
        return lo;
    }
    let mut fb = f_hi.unwrap_or_else(|| f(b));
    // Which end moved last: +1 the ok end, -1 the other (Illinois halves the stale one).
    let mut moved = 0i8;
    for step in 0..SWITCH_STEPS + SWITCH_HALVINGS {
        if b - a <= tol {
            break;
        }
        let secant = b - fb * (b - a) / (fb - fa);
        let c = if step < SWITCH_STEPS && secant > a && secant < b {
            secant
        } else {
            0.5 * (a + b)
        };
        let fc = f(c);
        if fc >= 0.0 {
            a = c;
            fa = fc;
            if moved == 1 {
                fb *= 0.5;
            }
            moved = 1;
        } else {
            b = c;
            fb = fc;
            if moved == -1 {
                fa *= 0.5;
            }
            moved = -1;
        }
    }
    a
}

/// The latest moment in `[lo, hi]` at which the motion `at` has not yet passed the
/// point `d` mm on (`at(τ).s <= d`), to within `tol`, given that it has passed it by
/// `hi`: `lo` itself when it has passed it there already. As [`latest_ok`] with the
/// margin `d - s(τ)`, but by Newton's method: the distance is a piecewise cubic in time
/// whose slope is the speed, so a step `(d - s)/v` lands next to the moment at once and
/// a few more close in on it (where regula falsi took a dozen). A step that would leave
/// the bracket halves it instead; once a step is within a fraction of `tol` of one end
/// the point `tol/2` past it is tried, so that the bracket closes from both sides. Only
/// a moment where `s <= d` was seen is returned.
fn crossing(lo: f64, hi: f64, tol: f64, d: f64, at: impl Fn(f64) -> profile::Motion) -> f64 {
    let (mut a, mut b) = (lo, hi);
    let x = at(a);
    let mut f = d - x.s;
    if f.is_nan() || f < 0.0 {
        return lo;
    }
    let (mut tau, mut v) = (a, x.v);
    for step in 0..SWITCH_STEPS + SWITCH_HALVINGS {
        if b - a <= tol {
            break;
        }
        let newton = tau + f / v;
        // A step to just past an end (rounding, or the curvature of `s` on the last
        // step) says the moment is next to that end.
        let near = newton > 2.0 * a - b && newton < 2.0 * b - a;
        let c = if step >= SWITCH_STEPS || !near {
            0.5 * (a + b)
        } else if newton - a < 0.25 * tol {
            // Close the bracket from the far side too: a landing this near one end
            // means the moment is within `tol/2` of it.
            a + 0.5 * tol
        } else if b - newton < 0.25 * tol {
            b - 0.5 * tol
        } else {
            newton
        };
        let inside = c > a && c < b;
        if !inside {
            break;
        }
        let x = at(c);
        (tau, f, v) = (c, d - x.s, x.v);
        if f >= 0.0 {
            a = c;
        } else {
            b = c;
        }
    }
    a
}

/// The parameter `ds` mm of path further on from `u`: the second-order Taylor step of
/// seed 001, `du = ds/|C'| - ds²(C'·C'')/(2|C'|⁴)`, then one Newton correction so the
/// chord actually covered matches `ds`.
fn advance(
    geom: &mut Geometry,
    block: &CommandBlock,
    e: &CurvePoint,
    u: f64,
    u_end: f64,
    ds: f64,
) -> (f64, CurvePoint) {
    let sp = norm(e.d1);
    let du = if sp > 1e-12 {
        ds / sp - ds * ds * dot(e.d1, e.d2) / (2.0 * sp.powi(4))
    } else {
        // A cusp-like start (coincident control points): C' = 0, use the C'' term.
        let acc = norm(e.d2);
        if acc > 1e-12 {
            (2.0 * ds / acc).sqrt()
        } else {
            (u_end - u) * 1e-3
        }
    };
    let mut u1 = (u + du.max(0.0)).min(u_end);
    // The profile plans arc length; the chord of an arc `ds` on curvature `κ` is
    // `ds·(1 - (ds·κ)²/24)` to fourth order. Stepping the arc keeps the distances the
    // profile brakes on exact over thousands of cycles (a chord per cycle would fall
    // behind by `ds³κ²/24` each).
    let kappa = if sp > 1e-12 {
        let c = [
            e.d1[1] * e.d2[2] - e.d1[2] * e.d2[1],
            e.d1[2] * e.d2[0] - e.d1[0] * e.d2[2],
            e.d1[0] * e.d2[1] - e.d1[1] * e.d2[0],
        ];
        norm(c) / (sp * sp * sp)
    } else {
        0.0
    };
    let ds = ds * (1.0 - (ds * kappa).powi(2) / 24.0).max(0.5);
    // Newton on the chord itself, f(u) = |C(u) - P| - ds with f' = (C - P)·C' / |C - P|,
    // kept inside a bracket [lo, hi] with f(lo) < 0 < f(hi) and bisecting whenever a
    // Newton step would leave it: usually one step brings the chord within 1e-10 of the
    // plan, a few more where the curvature changes fast inside the step, and where the
    // curve (nearly) stands still (a cusp, where C' is no guide) bisection still makes
    // progress. Never steps further than planned: unconverged, it keeps `lo`.
    let (mut lo, mut e_lo) = (u, *e);
    let mut hi = u_end;
    let mut e1 = geom.eval(block, u1);
    for _ in 0..MAX_CHORD_STEPS {
        let r = [e1.p[0] - e.p[0], e1.p[1] - e.p[1], e1.p[2] - e.p[2]];
        let chord = norm(r);
        if (chord - ds).abs() <= 1e-10 * ds + 1e-13 {
            return (u1, e1);
        }
        if chord < ds {
            if u1 >= u_end {
                // The block ends within the step.
                return (u1, e1);
            }
            lo = u1;
            e_lo = e1;
        } else {
            hi = u1;
        }
        let slope = if chord > 0.0 {
            dot(r, e1.d1) / chord
        } else {
            0.0
        };
        let newton = u1 + (ds - chord) / slope;
        let next = if slope > 1e-12 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if next <= lo || next >= hi {
            break;
        }
        u1 = next;
        e1 = geom.eval(block, u1);
    }
    (lo, e_lo)
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests;
