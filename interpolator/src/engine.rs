//! The per-cycle path stepper: a plain state machine over plain data, no I/O.
//!
//! Each [`Engine::tick`] advances the tool along the current block by one period at the
//! speed the profile allows, crossing into following blocks when one ends mid-period, and
//! returns the new set-point. The speed profile is acceleration-limited: speed rises by
//! at most `a·T` per cycle, never exceeds the block's feed, and is always low enough to
//! reach the block's planned end speed (zero when no next motion is known yet, so a
//! starved interpolator stops on the path instead of running off its end).
//!
//! A fault does not freeze the set-point where it is: [`Engine::stop`] starts a controlled
//! stop, as a real control does on a following-error or peer fault. From then on no block
//! is taken from the source, and the speed falls by `a·T` every cycle along the path
//! already in hand (crossing into a look-ahead block that is already validated), down to
//! zero ([`Engine::at_rest`]). The stop is bounded: at most `v/(a·T) + 1` cycles.
#![deny(
    clippy::indexing_slicing,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic
)]

use shared::nurbs::fast::FastCurve;
use shared::nurbs::CurvePoint;
use shared::path::{self, norm};
use shared::protocol::{BlockKind, CommandBlock, Feedback, ProtocolError, FLAG_RAPID};

/// Most blocks one cycle may pass through (tiny CAM segments shorter than one step).
const MAX_BLOCKS_PER_CYCLE: usize = 64;

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
}

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
            Fault::StopRequested => write!(f, "stopped on request (SIGTERM/SIGINT): holding position"),
            Fault::PeerSilent { cycle } => {
                write!(f, "cycle {cycle}: the servo-sim did not answer the set-point (dead or stalled)")
            }
            Fault::PeerGone { peer, cycle } => write!(
                f,
                "cycle {cycle}: the {} is gone (its process ended or died)",
                peer.name()
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

#[derive(Debug, Clone, Copy)]
struct Motion {
    block: CommandBlock,
    u: f64,
    /// The path (point and derivatives) at `u`, kept from the previous step.
    at: CurvePoint,
    u_end: f64,
    s_mm: f64,
    end_mm: [f64; 3],
    feed_mm_per_s: f64,
}

// The motion variant carries its whole block on purpose: boxing it would allocate.
#[allow(clippy::large_enum_variant)]
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
    pub path_acc_mm_per_s2: f64,
    pub max_following_error_mm: f64,
}

pub struct Engine {
    lim: Limits,
    /// The moving-data evaluator (seed 001 §3.3), loaded with each motion block's curve.
    curve: FastCurve,
    t_s: f64,
    cur: Current,
    next: Option<CommandBlock>,
    expected_seq: u64,
    speed: f64,
    pos: [f64; 3],
    vel: [f64; 3],
    line: u32,
    seq: u64,
    rapid: bool,
    end_received: bool,
    done: bool,
    /// A controlled stop is under way: no new blocks, speed only falls.
    stopping: bool,
    /// A fault found while taking a block in the middle of a tick, reported at the start
    /// of the next one (so that an `Err` from `tick` never leaves a half-made step).
    deferred: Option<Fault>,
    /// Times the engine came to a stop for want of a block (not counting the program end).
    starvations: u64,
    starved: bool,
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
            curve,
            t_s: lim.period_ns as f64 * 1e-9,
            cur: Current::None,
            next: None,
            expected_seq: 0,
            speed: 0.0,
            pos: start_mm,
            vel: [0.0; 3],
            line: 0,
            seq: 0,
            rapid: false,
            end_received: false,
            done: false,
            stopping: false,
            deferred: None,
            starvations: 0,
            starved: false,
        }
    }

    /// Starts a controlled stop: from the next tick on, no block is taken from the source
    /// and the speed only falls, by `a·T` per cycle, along the path already in hand.
    pub fn stop(&mut self) {
        self.stopping = true;
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
        self.expected_seq
    }

    pub fn position(&self) -> [f64; 3] {
        self.pos
    }

    /// True while the engine holds no look-ahead block and the program end has not been
    /// received yet (it will ask the source for one).
    pub fn wants_block(&self) -> bool {
        self.next.is_none() && !self.done && !self.end_received && !self.stopping
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

    fn fill(&mut self, src: &mut impl BlockSource) -> Result<(), Fault> {
        // Nothing follows the program end: never ask the source past it. A stopping
        // machine takes nothing more.
        if self.next.is_some() || self.done || self.end_received || self.stopping {
            return Ok(());
        }
        if let Some(b) = src.next_block() {
            b.validate().map_err(Fault::Protocol)?;
            if b.seq != self.expected_seq {
                return Err(Fault::Protocol(ProtocolError::OutOfSequence {
                    expected: self.expected_seq,
                    got: b.seq,
                }));
            }
            self.expected_seq += 1;
            self.end_received = b.kind == BlockKind::ProgramEnd as u32;
            self.next = Some(b);
        }
        Ok(())
    }

    fn start(&mut self, b: CommandBlock) -> Result<(), Fault> {
        self.line = b.source_line;
        self.seq = b.seq;
        self.cur = match b.kind() {
            Some(BlockKind::Motion) => {
                self.curve
                    .load(b.degree as usize, b.knots(), b.ctrl())
                    .map_err(|err| Fault::Protocol(ProtocolError::Curve { seq: b.seq, err }))?;
                let (u0, u1) = path::domain(&b);
                Current::Motion(Motion {
                    block: b,
                    u: u0,
                    u_end: u1,
                    s_mm: 0.0,
                    end_mm: eval(&mut self.curve, &b, u1).p,
                    at: eval(&mut self.curve, &b, u0),
                    feed_mm_per_s: b.feed_mm_per_min / 60.0,
                })
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

    /// Speed the next motion may be entered with: the planned end speed if the next block
    /// is a motion already in hand, otherwise zero.
    fn exit_speed(&self, m: &Motion) -> f64 {
        match &self.next {
            Some(n) if n.kind == BlockKind::Motion as u32 => m.block.end_feed_mm_per_min / 60.0,
            _ => 0.0,
        }
    }

    /// Advances one period. Allocation-free, panic-free.
    ///
    /// An `Err` is returned before anything moves: the engine is then exactly as after the
    /// previous tick, so the caller can [`stop`](Engine::stop) and keep ticking, and the
    /// set-points decelerate along the path from where they were.
    pub fn tick(&mut self, src: &mut impl BlockSource) -> Result<Tick, Fault> {
        if !self.stopping {
            if let Some(f) = self.deferred.take() {
                return Err(f);
            }
            self.fill(src)?;
        }
        let a = self.lim.path_acc_mm_per_s2;
        let t = self.t_s;
        let mut budget: Option<f64> = None;
        let prev_pos = self.pos;
        let mut state = TickState::Running;
        for pass in 0..MAX_BLOCKS_PER_CYCLE {
            // The first pass's block was asked for above, before anything moved.
            if pass > 0 {
                self.fill_or_defer(src);
            }
            if let Current::None = self.cur {
                match self.next.take() {
                    Some(b) => {
                        if let Err(f) = self.start(b) {
                            // Not loadable after all: stand still here, fault next tick.
                            self.deferred.get_or_insert(f);
                            self.cur = Current::None;
                            self.speed = 0.0;
                            state = TickState::Starved;
                            break;
                        }
                        self.fill_or_defer(src);
                    }
                    None => {
                        state = if self.done {
                            TickState::Done
                        } else {
                            TickState::Starved
                        };
                        self.speed = 0.0;
                        break;
                    }
                }
            }
            match self.cur {
                Current::None => {}
                Current::End { line, seq } => {
                    self.line = line;
                    self.seq = seq;
                    self.done = true;
                    self.speed = 0.0;
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
                    break;
                }
                Current::Motion(mut m) => {
                    self.line = m.block.source_line;
                    self.seq = m.block.seq;
                    self.rapid = m.block.flags & FLAG_RAPID != 0;
                    let v_exit = self.exit_speed(&m);
                    let s_rem = (m.block.length_mm - m.s_mm).max(dist(self.pos, m.end_mm));
                    let ds = match budget {
                        Some(d) => d,
                        None => {
                            // Fastest speed from which v_exit is still reachable at the end,
                            // accounting for the distance covered in this very cycle.
                            // When the block end is passed within this very cycle
                            // (s_rem < v_exit·T), the bound is v_exit itself.
                            let brake = (-a * t
                                + (a * a * t * t + v_exit * v_exit + 2.0 * a * s_rem).sqrt())
                            .max(v_exit);
                            // A controlled stop only ever slows down.
                            let up = if self.stopping {
                                self.speed - a * t
                            } else {
                                self.speed + a * t
                            };
                            let v = m.feed_mm_per_s.min(up).min(brake).max(0.0);
                            self.speed = v;
                            v * t
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
                        self.cur = Current::None;
                        if v_exit <= 0.0 {
                            // An exact stop: the next motion starts from rest, whatever
                            // the speed of this last, short step was.
                            self.speed = 0.0;
                            break;
                        }
                        budget = Some(ds - s_rem);
                        continue;
                    }
                    let (u, e) = advance(&mut self.curve, &m.block, &m.at, m.u, m.u_end, ds);
                    m.u = u;
                    m.at = e;
                    m.s_mm += ds;
                    self.pos = e.p;
                    self.cur = Current::Motion(m);
                    break;
                }
            }
        }
        // A starvation is a stop for want of a block mid-program, counted once per stop.
        let starved = state == TickState::Starved && !self.stopping;
        if starved && !self.starved {
            self.starvations += 1;
        }
        self.starved = starved;
        let vel = rate(self.pos, prev_pos, t);
        let acc = rate(vel, self.vel, t);
        self.vel = vel;
        Ok(Tick {
            pos_mm: self.pos,
            vel_mm_per_s: vel,
            acc_mm_per_s2: acc,
            speed_mm_per_s: self.speed,
            source_line: self.line,
            block_seq: self.seq,
            rapid: self.rapid,
            state,
        })
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

/// The parameter `ds` mm of path further on from `u`: the second-order Taylor step of
/// seed 001, `du = ds/|C'| - ds²(C'·C'')/(2|C'|⁴)`, then one Newton correction so the
/// chord actually covered matches `ds`.
fn advance(
    curve: &mut FastCurve,
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
    let e1 = eval(curve, block, u1);
    let sp1 = norm(e1.d1);
    if sp1 > 1e-12 {
        let chord = dist(e1.p, e.p);
        u1 = (u1 + (ds - chord) / sp1).clamp(u, u_end);
    }
    (u1, eval(curve, block, u1))
}

/// The block's path at `u`: its NURBS by the moving-data evaluator, plus any helix.
#[inline]
fn eval(curve: &mut FastCurve, block: &CommandBlock, u: f64) -> CurvePoint {
    let mut e = curve.eval(u);
    path::add_axial(block, u, &mut e);
    e
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests;
