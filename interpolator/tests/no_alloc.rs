//! The cycle's own work never allocates: engine tick, the read of the thread's CPU time,
//! timing record (histograms, the miss ring, every miss cause), feed statistics and the
//! trace push, over more than 100 000 cycles and many block changes, counted by a global
//! allocator that counts only on the measuring thread (the trace writer, the miss log's
//! drain thread and the preemptor test aid allocate freely, off the cycle).

use interpolator::engine::{BlockSource, Engine, Fault, Limits, TickState};
use interpolator::rt::latency::{Live, Tally, LIVE_BINS};
use interpolator::rt::preempt::Preemptor;
use interpolator::rt::received::{self, Receipts};
use interpolator::summary::{FaultRecord, FeedStats};
use interpolator::timing::{CycleTimes, MissCause, Timing, MISS_RING};
use shared::alloc_count::{arm, count, Counting};
use shared::clock::thread_cpu_ns;
use shared::protocol::{BlockKind, CommandBlock};
use shared::trace::TraceWriter;

#[global_allocator]
static GLOBAL: Counting = Counting;

/// A rational cubic, re-sent with rising sequence numbers (it ends where it starts), then
/// the program end. A surface pass (which does not end where it starts) is sent there
/// and back: every other block runs it backwards, so each starts where the last ended,
/// as the engine checks.
struct Loop {
    block: CommandBlock,
    next_seq: u64,
    count: u64,
    /// Each block handed out is noted for the received-block log, as the cycle's source
    /// does.
    receipts: Receipts,
}

impl BlockSource for Loop {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let seq = self.next_seq;
        if seq > self.count {
            return None;
        }
        self.next_seq += 1;
        if seq == self.count {
            let end = CommandBlock::empty(BlockKind::ProgramEnd, seq, 99);
            self.receipts.note(&end, seq);
            return Some(end);
        }
        let mut b = self.block;
        b.seq = seq;
        if b.is_surface() && seq % 2 == 1 {
            let sp = &mut b.surface;
            (sp.uv_start, sp.uv_end) = (sp.uv_end, sp.uv_start);
            sp.uv_inner = [sp.uv_inner[1], sp.uv_inner[0]];
        }
        self.receipts.note(&b, seq);
        Some(b)
    }
}

fn closed_curve() -> CommandBlock {
    let pts = [
        [0.0, 0.0],
        [10.0, 5.0],
        [20.0, -5.0],
        [30.0, 10.0],
        [20.0, 25.0],
        [-5.0, 10.0],
        [0.0, 0.0],
    ];
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 7);
    b.degree = 3;
    b.n_ctrl = pts.len() as u32;
    let knots = [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 4.0, 4.0, 4.0];
    b.knots[..knots.len()].copy_from_slice(&knots);
    for (i, p) in pts.iter().enumerate() {
        b.ctrl[i] = [p[0], p[1], 0.0, if i % 2 == 0 { 1.0 } else { 0.7 }];
    }
    b.feed_mm_per_min = 3000.0;
    b.start_feed_mm_per_min = 600.0;
    b.end_feed_mm_per_min = 600.0;
    b.length_mm = shared::path::length(&b);
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b
}

#[derive(Clone, Copy)]
struct Rec(u64, [f64; 3]);

#[test]
fn cycle_work_does_not_allocate() {
    let lim = Limits {
        lookahead_blocks: 16,
        max_following_error_mm: 1.0,
        ..Limits::new(&shared::Machine::default(), 1_000_000)
    };
    let mut engine = Engine::new(lim, [0.0; 3]);
    let (receipts, receipt_log) = received::start().unwrap();
    let mut src = Loop {
        block: closed_curve(),
        next_seq: 0,
        count: 400,
        receipts,
    };
    let (mut timing, mut miss_log) = Timing::new(1_000_000, MISS_RING);
    miss_log.start().unwrap();
    let mut feed = FeedStats::default();
    let path = std::env::temp_dir().join(format!("cnc-noalloc-{}.csv", std::process::id()));
    let mut trace = TraceWriter::create(
        &path,
        "cycle,x",
        1 << 12,
        |r: &Rec, s: &mut String| {
            s.push_str(&format!("{},{}", r.0, r.1[0]));
        },
        true,
    )
    .unwrap();
    // The preemption test aid's kick runs inside the cycle too; the preemptor needs
    // SCHED_FIFO (root), and without it that part is left out.
    // SAFETY: a plain syscall.
    let cpu = usize::try_from(unsafe { libc::sched_getcpu() }).unwrap_or(0);
    let preemptor = Preemptor::start(cpu, 1, 10_000)
        .map_err(|why| println!("preemptor kicks not counted: {why}"))
        .ok();
    let mut cpu_mark = thread_cpu_ns();
    arm(true);
    let mut cycles = 0u64;
    loop {
        if let Some(p) = &preemptor {
            if cycles % 100 == 50 {
                p.kick();
            }
        }
        let t = engine.tick(&mut src).unwrap();
        // The thread's CPU time, read and differenced as the loop does.
        let cpu_now = thread_cpu_ns();
        let cpu_ns = match (cpu_mark, cpu_now) {
            (Some(from), Some(to)) => Some(to.saturating_sub(from)),
            _ => None,
        };
        cpu_mark = cpu_now;
        feed.add(&t, 1_000_000);
        // Every 100th cycle is a miss, of each cause in turn, so the miss ring and its
        // drain are exercised too.
        let mut times = CycleTimes {
            cycle: cycles,
            block_seq: t.block_seq,
            source_line: t.source_line,
            wake_late_ns: 10_000,
            compute_ns: 5_000,
            publish_ns: 1_000,
            unanswered: 0,
            cpu_ns,
        };
        if cycles.is_multiple_of(100) {
            match (cycles / 100) % 5 {
                0 => times.wake_late_ns = 1_200_000,
                1 => (times.compute_ns, times.cpu_ns) = (2_000_000, Some(2_000_000)),
                2 => times.publish_ns = 1_100_000,
                3 => times.unanswered = 3,
                _ => (times.compute_ns, times.cpu_ns) = (2_000_000, Some(30_000)),
            }
        }
        timing.record(&times);
        trace.push(Rec(cycles, t.pos_mm));
        cycles += 1;
        if t.state == TickState::Done {
            break;
        }
        if cycles.is_multiple_of(1024) {
            // Let the writer keep up, without counting what sleeping may allocate: wait
            // until it holds at most a quarter of its ring, however long a loaded
            // machine keeps it from running (a fixed 6 ms sleep once let it fall a
            // whole ring behind under load, and records were dropped).
            arm(false);
            let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
            while trace.queued() > 1024 && std::time::Instant::now() < deadline {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            arm(true);
        }
    }
    arm(false);
    let allocs = count();
    drop(preemptor);
    assert_eq!(trace.dropped(), 0);
    trace.finish().unwrap();
    let _ = std::fs::remove_file(&path);
    let misses = miss_log.finish();
    // Every block taken reached the received-block log's thread.
    assert_eq!(receipt_log.finish(&src.receipts), src.next_seq);
    assert_eq!(src.receipts.lost(), 0);
    assert!(cycles >= 100_000, "only {cycles} cycles");
    assert_eq!(allocs, 0, "{allocs} allocations in {cycles} cycles");
    // Every miss was kept, each with its cause.
    assert_eq!(timing.misses, cycles.div_ceil(100));
    assert_eq!(timing.lost, 0);
    assert_eq!(misses.len() as u64, timing.misses);
    for m in &misses {
        let want = [
            MissCause::LateWake,
            MissCause::LongCompute,
            MissCause::PublishStall,
            MissCause::DownstreamLag,
            MissCause::Preempted,
        ][((m.cycle / 100) % 5) as usize];
        assert_eq!((m.cycle % 100, m.cause), (0, want));
    }
}

/// `cnc latency-test`'s measuring loop keeps the result's histogram and the live figures
/// the display reads, per wake-up, without allocating.
#[test]
fn latency_test_wake_ups_do_not_allocate() {
    let live = std::sync::Arc::new(Live::default());
    let mut tally = Tally::new(1_000_000, live.clone());
    arm(true);
    for k in 0..100_000u64 {
        // Lateness across every live bin, up to 10 ms.
        tally.record((k * 7_919) % 10_000_000);
    }
    arm(false);
    let allocs = count();
    let f = live.snapshot();
    assert_eq!(f.wakeups, 100_000);
    assert_eq!(f.bins.iter().sum::<u64>(), 100_000);
    assert!(f.bins.iter().all(|n| *n > 0), "{:?}", f.bins);
    assert_eq!(f.bins.len(), LIVE_BINS);
    assert_eq!(allocs, 0, "{allocs} allocations in 100 000 wake-ups");
}

#[test]
fn controlled_stop_does_not_allocate() {
    let lim = Limits {
        lookahead_blocks: 16,
        max_following_error_mm: 1.0,
        ..Limits::new(&shared::Machine::default(), 1_000_000)
    };
    let mut engine = Engine::new(lim, [0.0; 3]);
    let mut src = Loop {
        block: closed_curve(),
        next_seq: 0,
        count: 40,
        receipts: Receipts::off(),
    };
    // The peer watch the cycle reads (its thread allocates freely, off the cycle).
    let prefix = format!("noalloc{}", std::process::id());
    let svc = shared::protocol::Services::new(&prefix);
    let node = shared::ipc::node::<iceoryx2::prelude::local::Service>("noalloc").unwrap();
    let blocks = shared::ipc::blocks(&node, &svc).unwrap();
    let _publisher = blocks.publisher_builder().create().unwrap();
    let setpoints = shared::ipc::setpoints(&node, &svc).unwrap();
    let _subscriber = setpoints.subscriber_builder().create().unwrap();
    let watch = interpolator::rt::watch::PeerWatch::start::<iceoryx2::prelude::local::Service>(
        &prefix,
        std::time::Duration::from_millis(1),
    )
    .unwrap();
    // The watch is running (its first look is done) before the cycle work is measured.
    while watch.polls() == 0 {
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    let mut feed = FeedStats::default();
    arm(true);
    let mut record = None;
    let mut cycles = 0u64;
    loop {
        if cycles == 3000 {
            let f = watch
                .gone()
                .map(|peer| Fault::PeerGone {
                    peer,
                    cycle: cycles,
                })
                .unwrap_or(Fault::StopRequested);
            record = Some(FaultRecord::at(f, cycles, &engine, Some(cycles - 1)));
            engine.stop();
        }
        let t = engine.tick(&mut src).unwrap();
        feed.add(&t, 1_000_000);
        cycles += 1;
        if engine.at_rest() || t.state == TickState::Done {
            break;
        }
    }
    arm(false);
    let allocs = count();
    assert!(
        record.is_some_and(|r| r.speed_mm_per_s > 0.0),
        "stopped from speed"
    );
    assert!(engine.at_rest() && cycles > 3001, "{cycles} cycles");
    assert_eq!(watch.gone(), None, "both ports are still there");
    assert_eq!(allocs, 0, "{allocs} allocations in a controlled stop");
}

/// One pass over a quarter cylinder (a rational Bézier patch), as a surface block, a
/// little slanted across the patch.
fn cylinder_pass() -> CommandBlock {
    let mut b = shared::path::quarter_cylinder_pass(20.0);
    b.source_line = 9;
    b.surface.uv_start = [0.3, 0.0];
    b.surface.uv_end = [0.7, 1.0];
    b.length_mm = shared::path::length(&b);
    b
}

/// The same pass bent into a cubic `(u, v)` curve (a `PLANE_CC_STRATEGY` block).
fn cubic_cylinder_pass() -> CommandBlock {
    let mut b = cylinder_pass();
    b.flags |= shared::protocol::FLAG_UV_CUBIC;
    b.surface.uv_start = [0.2, 0.0];
    b.surface.uv_inner = [[0.8, 0.3], [0.1, 0.6]];
    b.surface.uv_end = [0.7, 1.0];
    b.length_mm = shared::path::length(&b);
    b
}

#[test]
fn surface_cycles_do_not_allocate() {
    for block in [cylinder_pass(), cubic_cylinder_pass()] {
        surface_cycles_of(block);
    }
}

fn surface_cycles_of(block: CommandBlock) {
    let lim = Limits {
        lookahead_blocks: 16,
        max_following_error_mm: 1.0,
        ..Limits::new(&shared::Machine::default(), 1_000_000)
    };
    block.validate().unwrap();
    let mut engine = Engine::new(lim, shared::path::eval(&block, 0.0).p);
    let mut src = Loop {
        block,
        next_seq: 0,
        count: 70,
        receipts: Receipts::off(),
    };
    arm(true);
    let mut cycles = 0u64;
    loop {
        let t = engine.tick(&mut src).unwrap();
        cycles += 1;
        if t.state == TickState::Done {
            break;
        }
    }
    arm(false);
    let allocs = count();
    assert!(cycles >= 100_000, "only {cycles} cycles");
    assert_eq!(allocs, 0, "{allocs} allocations in {cycles} cycles");
}

/// The checks of every block against the machine and the last guard on each set-point,
/// including their refusals and the stop after them, allocate nothing: a run of the closed
/// curve is fed a bad block (a curve broken at a knot, one starting 5 mm away, a feed of
/// 1e6 mm/min, a path out of travel that must be refined and its reach found), or made to
/// trip the step guard, and stopped to rest.
#[test]
fn block_checks_and_refusals_do_not_allocate() {
    let good = closed_curve();
    let mut broken = CommandBlock::empty(BlockKind::Motion, 0, 8);
    broken.degree = 1;
    broken.n_ctrl = 4;
    broken.knots[..6].copy_from_slice(&[0.0, 0.0, 1.0, 1.0, 2.0, 2.0]);
    for (i, p) in [[0.0, 0.0], [10.0, 0.0], [10.0, 5.0], [0.0, 0.0]]
        .iter()
        .enumerate()
    {
        broken.ctrl[i] = [p[0], p[1], 0.0, 1.0];
    }
    broken.feed_mm_per_min = 3000.0;
    broken.length_mm = 30.0;
    broken.acc_mm_per_s2 = 2000.0;
    broken.jerk_mm_per_s3 = 50_000.0;
    let mut away = good;
    for c in away.ctrl.iter_mut().take(7) {
        c[1] += 5.0;
    }
    let mut fast = good;
    fast.feed_mm_per_min = 1e6;
    let base = Limits {
        lookahead_blocks: 4,
        max_following_error_mm: 1.0,
        ..Limits::new(&shared::Machine::default(), 1_000_000)
    };
    let mut narrow = base;
    narrow.machine.axes.x.max_mm = 22.0;
    narrow.machine.axes.y.min_mm = -1.5;
    let mut slow_axis = base;
    slow_axis.max_step_mm[1] = 0.001;
    let cases = [
        (base, Some(broken)),
        (base, Some(away)),
        (base, Some(fast)),
        (narrow, None),
        (slow_axis, None),
    ];
    for (lim, bad) in cases {
        let mut engine = Engine::new(lim, [0.0; 3]);
        let mut src = Bad {
            good,
            bad,
            at: 3,
            next_seq: 0,
        };
        let mut faults = 0;
        arm(true);
        for _ in 0..100_000 {
            match engine.tick(&mut src) {
                Ok(t) => {
                    if engine.at_rest() || t.state == TickState::Done {
                        break;
                    }
                }
                Err(_) => {
                    faults += 1;
                    engine.stop();
                }
            }
        }
        arm(false);
        assert_eq!(faults, 1, "{bad:?}");
        assert!(engine.at_rest());
        assert_eq!(count(), 0, "allocations");
    }
}

/// The good block re-sent, with the bad one (if any) in place of block `at`.
struct Bad {
    good: CommandBlock,
    bad: Option<CommandBlock>,
    at: u64,
    next_seq: u64,
}

impl BlockSource for Bad {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let seq = self.next_seq;
        self.next_seq += 1;
        let mut b = match self.bad {
            Some(bad) if seq == self.at => bad,
            _ => self.good,
        };
        b.seq = seq;
        Some(b)
    }
}
