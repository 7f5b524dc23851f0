//! The periodic loop: cycle k is released at `t0 + k·period` (absolute sleeps on
//! CLOCK_MONOTONIC, never accumulated), and in each cycle it runs the fixed sequence
//! inputs (feedback) → faults → command (engine tick) → outputs (set-point, wake-up,
//! status) → measurement. Nothing in the loop allocates, locks, logs or formats; the
//! set-point trace goes to a wait-free ring drained by a writer thread, and so, when the
//! debug log is on, does a note of each block received ([`crate::rt::received`]): the log
//! line is written by a thread of its own. Start-up, services and the end of the run are
//! logged before and after the loop. Besides the wall
//! clock it reads the thread's own CPU time once a cycle, at the end of the compute phase,
//! so that a compute phase the OS interrupted is told from a slow one (see
//! [`crate::timing::MissCause`]).
//!
//! Under the simulated clock ([`ClockMode::Sim`]) the loop does not sleep: cycle k+1
//! starts as soon as the drives' feedback for cycle k+1-[`SIM_AHEAD`] is in (a few cycles
//! ahead of the drives, never more), and a block that is late
//! from the interpreter is waited for rather than run short of. Cycle k is still stamped
//! `k·period`, so the set-points are the same as under the real clock.
//!
//! Faults (a dead or silent peer, excess following error, a bad block, a stop request)
//! never freeze the set-point: the engine makes a controlled stop along the path, the
//! loop keeps publishing until it is at rest, and that last set-point ends the run. Peer
//! deaths come from [`PeerWatch`] (iceoryx2 liveness, off the cycle); a drive that stays
//! silent while alive is caught by the feedback watchdog below.

use crate::deadline::DeadlineReport;
use crate::engine::{BlockSource, Engine, Fault, Limits, TickState};
use crate::rt::preempt::Preemptor;
use crate::rt::received::{self, Receipts};
use crate::rt::sched::{self, SchedMode, SchedReport};
use crate::rt::watch::PeerWatch;
use crate::summary::{FaultInfo, FaultRecord, FeedStats, Summary};
use crate::timing::{CycleTimes, Timing, MISS_RING};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use shared::clock::{now_ns, sleep_until_ns, spin_then_block, thread_cpu_ns, ClockMode};
use shared::ipc::{self, err, IpcError};
use shared::protocol::{
    CommandBlock, Feedback, RunState, Services, Setpoint, Status, PROTOCOL_VERSION, SETPOINT_LAST,
};
use shared::trace::TraceWriter;
use shared::Machine;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Everything one interpolator run needs.
#[derive(Debug, Clone)]
pub struct Config {
    pub prefix: String,
    pub out_dir: PathBuf,
    pub period_ns: u64,
    pub machine: Machine,
    pub sched: SchedMode,
    /// SCHED_FIFO priority when real-time scheduling is granted.
    pub rt_priority: i32,
    pub clock: ClockMode,
    /// How long to wait for the servo-sim, and for an interpreter to come, before giving
    /// up. An interpreter that is there is waited for as long as it reads and plans
    /// ([`wait_for_first_block`]).
    pub start_timeout: Duration,
}

/// Test aids that change what a cycle does; none in normal runs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Hooks {
    /// Every Nth cycle (N, 2N, …) spins in its compute phase for 1.5 periods of its own
    /// CPU time: a long compute that must be reported as exactly those misses, with cause
    /// `long_compute` (`cnc run --inject-long-compute N`). CPU time, not wall time: were
    /// the spin preempted, it would run on for longer rather than end early, so the cycle
    /// stays a long compute by the thread's own measure.
    pub long_compute_every: Option<u64>,
    /// Every Nth cycle (N, 2N, …) wakes a thread pinned to its CPU at a higher SCHED_FIFO
    /// priority from the middle of its compute phase, which holds the CPU for 1.5 periods
    /// ([`Preemptor`]): a real preemption, which must be reported as `preempted`
    /// (`cnc run --inject-preemption N`). Needs SCHED_FIFO and a pinned cycle; without
    /// them a warning says so and nothing is injected.
    pub preempt_every: Option<u64>,
}

/// Spins until this thread has run `ns` more of its own CPU time (of the wall clock's,
/// should its CPU clock fail).
fn burn_cpu_ns(ns: u64) {
    match thread_cpu_ns() {
        Some(start) => {
            while thread_cpu_ns().is_some_and(|t| t < start + ns) {
                core::hint::spin_loop();
            }
        }
        None => {
            let until = now_ns() + ns;
            while now_ns() < until {
                core::hint::spin_loop();
            }
        }
    }
}

/// Under the simulated clock: how long to spin for an answer before sleeping on the
/// wake-up event, and how long a peer may stay silent before it is taken for dead.
const SIM_SPIN_NS: u64 = 200_000;
/// Under the simulated clock: how many cycles the interpolator may run ahead of the
/// drives' answers (cycle k waits for the answer to cycle k - SIM_AHEAD). The two
/// processes then work side by side instead of in turns: the butterfly's loop took 0.53 s
/// answer by answer, 0.32 s with 8 ahead (4, 16 and 64 measured the same). The set-points
/// do not change: feedback only ever brings a fault, and a fault in the drives' answer to
/// cycle j is acted on in cycle j + SIM_AHEAD exactly instead of j + 1, whatever the
/// scheduling ([`Answers::due`]; the real clock allows an answer 100 cycles late,
/// [`feedback_lag_limit`]).
const SIM_AHEAD: u64 = 8;
const SIM_TIMEOUT_NS: u64 = 5_000_000_000;

/// Source lines of the most recent cycles, so a fault found in feedback (which answers an
/// earlier cycle) names the line that cycle ran.
const LINE_RING: usize = 256;

/// Real clock: the feedback watchdog's limit in cycles. A dead servo-sim is found by
/// [`PeerWatch`] within a period or two; this limit is only for a drive that is alive but
/// silent, and it must ride out the multi-millisecond stalls of a busy VM (measured tails
/// of 2 to 29 ms, `../shared/notes/iceoryx2.md` §5): 100 ms, and never fewer than 5 cycles.
pub fn feedback_lag_limit(period_ns: u64) -> u64 {
    (100_000_000 / period_ns.max(1)).max(5)
}

/// How often [`PeerWatch`] wakes without an event. A death wakes it at once (pidfd), so
/// this only paces its look at the port counts (a peer that left cleanly) and, where no
/// pidfd could be had, its iceoryx2 dead-node checks: one peer per wake-up, about 55 µs of
/// CPU each in a release build, so faster polling would take a noticeable share of a
/// core. Measured: a killed servo-sim is noticed 1 to 5 cycles after its last answer at
/// 1 ms (the kernel's own tear-down of the process takes 1 to 3.5 ms of that).
pub const WATCH_INTERVAL: Duration = Duration::from_millis(1);

/// Why a run could not even produce a report.
#[derive(Debug)]
pub enum RunError {
    Ipc(IpcError),
    Io(std::io::Error),
    Timeout(&'static str),
    /// The interpreter was there and left (its process ended or died) before it sent
    /// anything.
    InterpreterLeft,
    /// A stop was asked for before the first block came: nothing moved.
    StoppedBeforeStart,
}

impl core::fmt::Display for RunError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            RunError::Ipc(e) => write!(f, "{e}"),
            RunError::Io(e) => write!(f, "writing the run directory: {e}"),
            RunError::Timeout(what) => write!(f, "timed out waiting for {what}"),
            RunError::InterpreterLeft => write!(
                f,
                "the interpreter left (its process ended or died) before it sent the first command block; nothing moved"
            ),
            RunError::StoppedBeforeStart => write!(
                f,
                "stopped on request before the first command block; nothing moved"
            ),
        }
    }
}
impl std::error::Error for RunError {}
impl From<IpcError> for RunError {
    fn from(e: IpcError) -> Self {
        RunError::Ipc(e)
    }
}
impl From<std::io::Error> for RunError {
    fn from(e: std::io::Error) -> Self {
        RunError::Io(e)
    }
}

/// One line of `setpoints.csv`.
#[derive(Debug, Clone, Copy)]
struct SetpointRec {
    cycle: u64,
    t_ns: u64,
    pos: [f64; 3],
    line: u32,
}

/// `{},{},{},{},{},{}` of the fields, written by [`shared::decimal`] (the same text, a
/// fraction of the CPU: the writer thread shares the cores with the cycle).
fn format_setpoint(r: &SetpointRec, out: &mut String) {
    use shared::decimal::{push_f64, push_u64};
    push_u64(out, r.cycle);
    out.push(',');
    push_u64(out, r.t_ns);
    for v in r.pos {
        out.push(',');
        push_f64(out, v);
    }
    out.push(',');
    push_u64(out, u64::from(r.line));
}

/// Blocks straight from the subscriber, with one block that may have been taken early.
/// Under the simulated clock a block that is not there yet is waited for (time stands
/// still), so the interpreter's pace never changes the path.
struct Source<'a, S: Service> {
    sub: &'a Subscriber<S, CommandBlock, ()>,
    first: Option<CommandBlock>,
    wait: bool,
    /// A dead interpreter sends nothing more: stop waiting for it.
    watch: &'a PeerWatch,
    /// Each block taken is noted here for the debug log, off the cycle.
    receipts: Receipts,
    /// The cycle running, for the notes.
    cycle: u64,
}

impl<S: Service> BlockSource for Source<'_, S> {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let got = self.receive();
        if let Some(b) = &got {
            self.receipts.note(b, self.cycle);
        }
        got
    }
}

impl<S: Service> Source<'_, S> {
    fn receive(&mut self) -> Option<CommandBlock> {
        if let Some(b) = self.first.take() {
            return Some(b);
        }
        let mut got = None;
        let mut take = || {
            got = match self.sub.receive() {
                Ok(Some(sample)) => Some(*sample.payload()),
                _ => None,
            };
            got.is_some()
        };
        if self.wait {
            let watch = self.watch;
            spin_then_block(
                SIM_SPIN_NS,
                SIM_TIMEOUT_NS,
                || take() || watch.gone().is_some(),
                |_| std::thread::sleep(Duration::from_micros(50)),
            );
        } else {
            take();
        }
        got
    }
}

fn wait_for(
    what: &'static str,
    timeout: Duration,
    mut ready: impl FnMut() -> bool,
) -> Result<(), RunError> {
    let t = Instant::now();
    while !ready() {
        if t.elapsed() > timeout {
            return Err(RunError::Timeout(what));
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    Ok(())
}

/// How often a wait for the first block asks iceoryx2 to remove dead nodes.
const FIRST_BLOCK_LIVENESS_EVERY: Duration = Duration::from_millis(20);

/// Waits for the first command block (`take` takes it) for as long as an interpreter is
/// there to send it: a program of many curves takes tens of seconds to read and plan, and
/// the interpreter opens its block port before it starts reading. `timeout` holds only
/// while no interpreter has come. One that leaves (its process ended, or died and its node
/// is found dead) ends the wait at once, and so does a stop request: nothing has moved.
fn wait_for_first_block<S: Service>(
    blocks: &shared::ipc::PubSub<S, CommandBlock>,
    timeout: Duration,
    mut take: impl FnMut() -> bool,
) -> Result<(), RunError> {
    let start = Instant::now();
    let mut last_check = start;
    let mut came = false;
    while !take() {
        if shared::stop::requested() {
            return Err(RunError::StoppedBeforeStart);
        }
        if last_check.elapsed() >= FIRST_BLOCK_LIVENESS_EVERY {
            last_check = Instant::now();
            let _ = blocks.try_cleanup_dead_nodes();
        }
        let there = blocks.dynamic_config().number_of_publishers() > 0;
        if came && !there {
            // Its last block may have come as it left.
            return if take() {
                Ok(())
            } else {
                Err(RunError::InterpreterLeft)
            };
        }
        came |= there;
        if !came && start.elapsed() > timeout {
            return Err(RunError::Timeout(
                "an interpreter to send the first command block",
            ));
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    Ok(())
}

/// The drives' answers as they come in.
#[derive(Default)]
struct Answers {
    last_cycle: Option<u64>,
    max_ferr_mm: f64,
    /// The first bad answer's fault and the cycle it answers, until it is due.
    pending: Option<(u64, Fault)>,
    /// How many cycles after the cycle it answers a bad answer is acted on: none under
    /// the real clock (at once), [`SIM_AHEAD`] under the simulated one.
    delay: u64,
}

impl Answers {
    fn new(delay: u64) -> Self {
        Answers {
            delay,
            ..Answers::default()
        }
    }

    /// Takes every feedback sample waiting; the first bad one is kept for [`Self::due`].
    fn drain<S: Service>(
        &mut self,
        sub: &Subscriber<S, Feedback, ()>,
        engine: &Engine,
        lines: &[u32; LINE_RING],
    ) {
        while let Ok(Some(fb)) = sub.receive() {
            if let Err(mut f) = engine.on_feedback(&fb) {
                if let Fault::FollowingError { cycle, line, .. } = &mut f {
                    if let Some(l) = lines.get((*cycle % LINE_RING as u64) as usize) {
                        *line = *l;
                    }
                }
                self.pending.get_or_insert((fb.cycle, f));
            }
            self.last_cycle = Some(fb.cycle);
            self.max_ferr_mm = fb
                .ferr_mm
                .iter()
                .fold(self.max_ferr_mm, |m, e| m.max(e.abs()));
        }
    }

    /// The bad answer's fault once cycle `now` is due to act on it. Under the simulated
    /// clock that is the cycle it answers plus [`SIM_AHEAD`], whenever it came in: by
    /// then it has surely come (cycle k waits for the answer to k - SIM_AHEAD), so the
    /// stop starts in the same cycle however the two processes were scheduled, and a
    /// replay of the run stops there too.
    fn due(&mut self, now: u64) -> Option<Fault> {
        match self.pending {
            Some((answers, f)) if now >= answers + self.delay => {
                self.pending = None;
                Some(f)
            }
            _ => None,
        }
    }

    fn has(&self, cycle: u64) -> bool {
        self.last_cycle.is_some_and(|c| c >= cycle)
    }
}

/// Runs the interpolator until the program end or a fault, and writes
/// `setpoints.csv`, `interpolator.json` and the deadline-miss report
/// (`deadline-misses.json`, `deadline-misses.txt`) into the run directory.
pub fn run<S: Service>(cfg: &Config) -> Result<Summary, RunError> {
    run_with::<S>(cfg, Hooks::default())
}

/// [`run`] with test aids.
pub fn run_with<S: Service>(cfg: &Config, hooks: Hooks) -> Result<Summary, RunError> {
    let sim = cfg.clock == ClockMode::Sim;
    let svc = Services::new(&cfg.prefix);
    let node = ipc::node::<S>("interpolator")?;
    let blocks = ipc::blocks(&node, &svc)?;
    let block_sub = blocks
        .subscriber_builder()
        .create()
        .map_err(|e| err("block subscriber", e))?;
    let setpoints = ipc::setpoints(&node, &svc)?;
    let sp_pub = setpoints
        .publisher_builder()
        .create()
        .map_err(|e| err("set-point publisher", e))?;
    let sp_event = ipc::wakeup(&node, &svc.setpoints())?;
    let sp_notify = sp_event
        .notifier_builder()
        .create()
        .map_err(|e| err("set-point notifier", e))?;
    let feedback = ipc::feedback(&node, &svc)?;
    let fb_sub = feedback
        .subscriber_builder()
        .create()
        .map_err(|e| err("feedback subscriber", e))?;
    let fb_event = ipc::wakeup(&node, &svc.feedback())?;
    let fb_listener = fb_event
        .listener_builder()
        .create()
        .map_err(|e| err("feedback listener", e))?;
    let status = ipc::status(&node, &svc)?;
    let st_pub = status
        .publisher_builder()
        .create()
        .map_err(|e| err("status publisher", e))?;
    tracing::debug!(
        blocks = %svc.blocks(),
        setpoints = %svc.setpoints(),
        feedback = %svc.feedback(),
        status = %svc.status(),
        "interpolator: shared-memory services open (blocks and feedback in, set-points, their wake-up and status out)"
    );

    // Every port exists before the loop: iceoryx2 connects new ports lazily inside send()
    // and receive(), which must not happen for the first time in a hard cycle.
    wait_for(
        "the servo-sim to subscribe to set-points",
        cfg.start_timeout,
        || setpoints.dynamic_config().number_of_subscribers() >= 1,
    )?;
    let mut first = None;
    wait_for_first_block(&blocks, cfg.start_timeout, || {
        first = block_sub.receive().ok().flatten().map(|s| *s.payload());
        first.is_some()
    })?;

    let lim = Limits::new(&cfg.machine, cfg.period_ns);
    let mut engine = Engine::new(lim, [0.0; 3]);
    // Both peers are connected now (the servo subscribed, the interpreter sent a block):
    // from here on, a port that leaves or a node that dies is a fault.
    let watch = PeerWatch::start::<S>(&cfg.prefix, WATCH_INTERVAL)?;
    // The received-block log: a ring and a thread of its own, only when it is wanted.
    let (receipts, receipt_log) = received::start_if_logged();
    let mut src = Source {
        sub: &block_sub,
        first,
        wait: sim,
        watch: &watch,
        receipts,
        cycle: 0,
    };
    let mut trace = TraceWriter::create(
        &cfg.out_dir.join("setpoints.csv"),
        "cycle,t_ns,x_mm,y_mm,z_mm,line",
        1 << 16,
        format_setpoint,
        !sim,
    )?;
    // Misses go through a pre-allocated ring to a thread that keeps them all.
    let (mut timing, mut miss_log) = Timing::new(cfg.period_ns, MISS_RING);
    if !sim {
        miss_log.start()?;
    }
    let inject_every = hooks.long_compute_every.filter(|n| *n > 0);
    let mut feed = FeedStats::starting_at(engine.position());
    // Spinning at SCHED_FIFO invites RT throttling: the simulated clock runs plain.
    let sched_mode = if sim { SchedMode::Other } else { cfg.sched };
    let mut sched_report: SchedReport = sched::setup(sched_mode, cfg.rt_priority);
    let preempt_every = hooks.preempt_every.filter(|n| *n > 0 && !sim);
    let preemptor = preempt_every.and_then(|_| {
        let started = match sched_report.cpu {
            Some(cpu) if sched_report.policy == "fifo" => {
                Preemptor::start(cpu, sched_report.priority, cfg.period_ns * 3 / 2)
            }
            _ => Err("the cycle is not pinned at SCHED_FIFO".into()),
        };
        started
            .map_err(|why| {
                sched_report
                    .warnings
                    .push(format!("test aid: no preemption injected: {why}"));
            })
            .ok()
    });
    for w in &sched_report.warnings {
        tracing::warn!("{w}");
    }
    tracing::info!(
        period_us = cfg.period_ns / 1000,
        clock = %cfg.clock.name(),
        "interpolator started: cycle thread {}",
        crate::rt::sched::words(&sched_report)
    );

    let mut fault: Option<Fault> = None;
    let mut info: Option<FaultRecord> = None;
    // Whether the servo-sim's process was found gone when the stop began (a silent one
    // that is alive was starved or suspended).
    let mut servo_dead = false;
    let mut answers = Answers::new(if sim { SIM_AHEAD } else { 0 });
    let mut lines = [0u32; LINE_RING];
    // Under the simulated clock: once the drives are gone or silent, stop waiting for them.
    let mut servo_lost = false;
    let lag_limit = feedback_lag_limit(cfg.period_ns);
    // The thread's CPU time at the end of the last compute phase (or now, before the
    // first): each cycle's CPU time is counted from there.
    let mut cpu_mark = if sim { None } else { thread_cpu_ns() };
    let t0 = now_ns() + cfg.period_ns;
    let mut cycle: u64 = 0;
    loop {
        let release = t0 + cycle * cfg.period_ns;
        src.cycle = cycle;
        if sim {
            if cycle >= SIM_AHEAD && !servo_lost {
                let answered = spin_then_block(
                    SIM_SPIN_NS,
                    SIM_TIMEOUT_NS,
                    || {
                        answers.drain(&fb_sub, &engine, &lines);
                        answers.has(cycle - SIM_AHEAD) || watch.servo_gone()
                    },
                    |d| {
                        let _ = fb_listener.timed_wait(|_| {}, d);
                    },
                );
                if !answered {
                    fault.get_or_insert(Fault::PeerSilent {
                        cycle: cycle - SIM_AHEAD,
                    });
                    servo_lost = true;
                }
            }
        } else {
            sleep_until_ns(release);
        }
        let wake = now_ns();

        // inputs → faults
        answers.drain(&fb_sub, &engine, &lines);
        if let Some(f) = answers.due(cycle) {
            fault.get_or_insert(f);
        }
        // Set-points sent (cycles 0..cycle) that the drives have not answered yet; once
        // they are gone that is the fault's business, not a miss.
        let unanswered = if servo_lost || watch.servo_gone() {
            0
        } else {
            answers
                .last_cycle
                .map_or(cycle, |c| cycle.saturating_sub(c + 1))
        };
        if shared::stop::requested() {
            fault.get_or_insert(Fault::StopRequested);
        }
        if let Some(peer) = watch.gone() {
            fault.get_or_insert(Fault::PeerGone { peer, cycle });
        }
        servo_lost |= watch.servo_gone();
        if !sim && cycle > lag_limit && !answers.has(cycle - lag_limit) {
            fault.get_or_insert(Fault::PeerSilent {
                cycle: cycle - lag_limit,
            });
        }
        // command: a fault turns the run into a controlled stop along the path
        let mut begin_stop = |f: Fault, engine: &mut Engine| {
            if !engine.stopping() {
                info = Some(FaultRecord::at(f, cycle, engine, answers.last_cycle));
                servo_dead = watch.servo_gone();
                engine.stop();
            }
        };
        if let Some(f) = fault {
            begin_stop(f, &mut engine);
        }
        if let (Some(p), Some(n)) = (&preemptor, preempt_every) {
            if cycle > 0 && cycle.is_multiple_of(n) {
                p.kick();
            }
        }
        let tick = match engine.tick(&mut src) {
            Err(f) => {
                // A bad block: nothing moved; stop from where the last cycle left off.
                fault.get_or_insert(f);
                begin_stop(f, &mut engine);
                engine.tick(&mut src)
            }
            ok => ok,
        };
        if let Some(n) = inject_every {
            if cycle > 0 && cycle.is_multiple_of(n) {
                burn_cpu_ns(cfg.period_ns * 3 / 2);
            }
        }
        let computed = now_ns();
        // Read after `computed`, so the CPU time's window holds the whole compute phase and
        // what is counted off the CPU is never more than the truth; its own 0.5 µs lands
        // in the publish phase. One system call a cycle, and none under the simulated
        // clock, which measures nothing.
        let cpu_now = if sim { None } else { thread_cpu_ns() };
        let cpu_ns = match (cpu_mark, cpu_now) {
            (Some(from), Some(to)) => Some(to.saturating_sub(from)),
            _ => None,
        };
        cpu_mark = cpu_now;
        let (sp, state) = match tick {
            Ok(t) => {
                feed.add(&t, cfg.period_ns);
                let last = t.state == TickState::Done || engine.at_rest();
                let sp = Setpoint {
                    protocol: PROTOCOL_VERSION,
                    flags: if last { SETPOINT_LAST } else { 0 },
                    cycle,
                    t_ns: cycle * cfg.period_ns,
                    block_seq: t.block_seq,
                    source_line: t.source_line,
                    _reserved: 0,
                    pos_mm: t.pos_mm,
                    vel_mm_per_s: t.vel_mm_per_s,
                    acc_mm_per_s2: t.acc_mm_per_s2,
                };
                let state = match (fault.is_some(), t.state) {
                    (true, _) => RunState::Fault,
                    (false, TickState::Running) => RunState::Running,
                    (false, TickState::Starved) => RunState::Starved,
                    (false, TickState::Done) => RunState::Done,
                };
                (sp, state)
            }
            Err(f) => {
                // Cannot even stop along the path: hold the last commanded position.
                fault.get_or_insert(f);
                let sp = Setpoint {
                    protocol: PROTOCOL_VERSION,
                    flags: SETPOINT_LAST,
                    cycle,
                    t_ns: cycle * cfg.period_ns,
                    pos_mm: engine.position(),
                    ..Setpoint::default()
                };
                (sp, RunState::Fault)
            }
        };
        if let Some(l) = lines.get_mut((cycle % LINE_RING as u64) as usize) {
            *l = sp.source_line;
        }
        // outputs
        if let Ok(s) = sp_pub.loan_uninit() {
            let _ = s.write_payload(sp).send();
        }
        let _ = sp_notify.notify();
        let _ = st_pub.send_copy(Status {
            protocol: PROTOCOL_VERSION,
            state: state as u32,
            cycle,
            block_seq: sp.block_seq,
            source_line: sp.source_line,
            _reserved: 0,
            misses: timing.misses,
            blocks_received: engine.blocks_received(),
        });
        let finished = now_ns();
        // measurement (meaningless under the simulated clock, so not taken)
        if !sim {
            timing.record(&CycleTimes {
                cycle,
                block_seq: sp.block_seq,
                source_line: sp.source_line,
                wake_late_ns: wake.saturating_sub(release),
                compute_ns: computed - wake,
                publish_ns: finished - computed,
                unanswered,
                cpu_ns,
            });
        }
        trace.push(SetpointRec {
            cycle,
            t_ns: sp.t_ns,
            pos: sp.pos_mm,
            line: sp.source_line,
        });
        if sp.flags & SETPOINT_LAST != 0 {
            break;
        }
        cycle += 1;
    }

    // Let the drives answer the last set-point, so the report covers every cycle (unless
    // they are gone).
    let _ = wait_for("final feedback", Duration::from_secs(2), || {
        answers.drain(&fb_sub, &engine, &lines);
        answers.has(cycle) || watch.servo_gone()
    });
    // A bad answer to the last cycles, too late to stop for (the run is at rest): the
    // run's fault all the same, recorded at its end.
    if let Some((_, f)) = answers.pending.take() {
        if fault.is_none() {
            fault = Some(f);
            info = Some(FaultRecord::at(f, cycle, &engine, answers.last_cycle));
        }
    }
    // Stay until the interpreter has seen the final status and left (it keeps the blocks'
    // memory alive until then), so neither side sees the other vanish mid-handshake.
    let _ = wait_for("the interpreter to leave", Duration::from_secs(2), || {
        blocks.dynamic_config().number_of_publishers() == 0
    });
    let blocks_logged = receipt_log.map(|l| l.finish(&src.receipts));
    drop(watch);
    drop(preemptor);
    let dropped = trace.dropped();
    trace.finish()?;
    let misses = miss_log.finish();
    let deadline = if sim {
        DeadlineReport::not_measured(cfg.clock.name(), cfg.period_ns, cycle + 1)
    } else {
        DeadlineReport::measured(
            cfg.period_ns,
            cycle + 1,
            &sched_report,
            &timing,
            &misses,
            &crate::rt::latency::default_path(),
        )
    };
    deadline.write(&cfg.out_dir)?;
    // The fault in words, after the loop (who asked for a stop, a starved drive).
    let request = shared::stop::request();
    let fault_info = info.map(|r| {
        let mut i = FaultInfo::new(&r, cycle);
        i.kind = crate::rt::words::kind(&r.fault, request).into();
        i
    });
    let silence_ns = if sim {
        SIM_TIMEOUT_NS
    } else {
        lag_limit * cfg.period_ns
    };
    let fault_text = fault.map(|f| {
        crate::rt::words::fault_text(
            &f,
            fault_info.as_ref(),
            request,
            servo_dead,
            silence_ns / 1_000_000,
            cfg.period_ns,
        )
    });
    crate::rt::words::log_end(&crate::rt::words::End {
        fault: fault.as_ref(),
        kind: fault_info.as_ref().map(|i| i.kind.as_str()),
        text: fault_text.as_deref(),
        cycles: cycle + 1,
        period_ns: cfg.period_ns,
        blocks: engine.blocks_received(),
        misses: (!sim).then_some(timing.misses),
        starvations: engine.starvations(),
    });
    if let Some(n) = blocks_logged {
        tracing::debug!("{n} received blocks logged");
    }
    let summary = Summary::new(
        cfg,
        cycle + 1,
        (!sim).then_some((&timing, &misses[..])),
        &feed,
        fault_text,
        sched_report,
        dropped,
        answers.max_ferr_mm,
    )
    .with_faults(fault_info, engine.starvations())
    .with_fluctuation(engine.fluctuation());
    summary.write(&cfg.out_dir.join("interpolator.json"))?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A line of `setpoints.csv` is the `{}` text of its fields, as it always was.
    #[test]
    fn a_setpoint_line_is_the_display_text_of_its_fields() {
        let r = SetpointRec {
            cycle: 3,
            t_ns: 3_000_000,
            pos: [0.000008333333333387927, -250.5, 1e21],
            line: 89,
        };
        let mut got = String::new();
        format_setpoint(&r, &mut got);
        assert_eq!(
            got,
            format!(
                "{},{},{},{},{},{}",
                r.cycle, r.t_ns, r.pos[0], r.pos[1], r.pos[2], r.line
            )
        );
    }
}
