//! Cost of one interpolation cycle. Run: `cargo bench -p interpolator --bench cycle`
//! (results and how to read them: `interpolator/BENCHMARKS.md`).
//!
//! * `tick_nurbs_deg3`: the engine's tick alone (path step + NURBS evaluation) on a cubic,
//!   1 ms period.
//! * `cycle/nurbs_deg5_publish`: one full cycle at a 100 µs period, as the real-time loop
//!   runs it: engine tick on a degree-5 rational NURBS (step, evaluation), the set-point
//!   built and published by loan / write / send into an iceoryx2 `ipc::Service` (shared
//!   memory, the service type the interpolator binary uses) with a subscriber attached.
//! * `cycle/surface_p3q3`: the same over a rational bicubic Bézier patch (surface blocks:
//!   contact path stepped, tool point `M = C + R·n + (H − R)·z` published), passes back
//!   and forth.
//! * `cycle/surface_cubic`: the same with the passes bent into cubic `(u, v)` curves
//!   (`FLAG_UV_CUBIC`, as `PLANE_CC_STRATEGY` blocks are): the uv rate changes along the
//!   pass.
//! * `clock/now_ns`, `clock/thread_cpu_ns`: a read of the wall clock and of the
//!   thread's own CPU time, as the cycle reads them.
//! * `cycle/profile_worst`: the same on a chain of 0.01 mm lines whose planned end speeds
//!   fall to a stop every 2 mm, look-ahead window 256: every cycle has many speed limits
//!   ahead, the most expensive path of the engine's profile step.
//!
//! Criterion reports mean times. The hard-timing target is a percentile (p99 of one
//! cycle), so the same binary then times 200 000 single cycles per case with
//! `std::time::Instant` and prints p50 / p90 / p99 / p99.9 / max, together with the cost
//! of the timer itself, in 5 runs: pooled, and as the minimum per cycle over the runs
//! (the cycles are deterministic, so that takes out most of the machine's noise).
//! `CYCLE_PCT_N` sets the count (0 skips it), `CYCLE_PCT_REPEATS` the runs and
//! `CYCLE_CRITERION=0` leaves criterion out.
//!
//! The subscriber takes every set-point after its cycle, as the servo-sim does each
//! period (so the publisher gets one sample back per cycle, as in the machine), outside
//! the timed part: in the machine it is another process's work. Criterion therefore
//! also times each cycle on its own and sums, which adds one timer pair per cycle.

use criterion::Criterion;
use iceoryx2::node::Node;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::ipc;
use interpolator::engine::{BlockSource, Engine, Limits, TickState};
use shared::ipc::PubSub;
use shared::path;
use shared::profile::Limits as Jerk;
use shared::protocol::{
    BlockKind, CommandBlock, Services, Setpoint, FLAG_SURFACE, PROTOCOL_VERSION,
};
use std::hint::black_box;
use std::time::{Duration, Instant};

/// The period of issue #6's target: a 100 µs cycle.
const PERIOD_NS: u64 = 100_000;

/// Cycles run before any measurement: connections made, caches warm, past the first
/// block's start.
const WARMUP_CYCLES: u64 = 20_000;

/// Cycles a case runs (untimed) to check that it measures what it claims.
const SURVEY_CYCLES: u64 = 100_000;

/// Default count of individually timed cycles per case.
const PCT_N: usize = 200_000;

/// Blocks re-sent back to back with rising sequence numbers, cycling through `blocks`.
struct Repeat {
    blocks: Vec<CommandBlock>,
    seq: u64,
}

impl BlockSource for Repeat {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let i = (self.seq % self.blocks.len() as u64) as usize;
        let mut b = *self.blocks.get(i)?;
        b.seq = self.seq;
        self.seq += 1;
        Some(b)
    }
}

fn lim(period_ns: u64, lookahead_blocks: usize) -> Limits {
    let mut l = Limits {
        lookahead_blocks,
        max_following_error_mm: 1.0,
        ..Limits::new(&shared::Machine::default(), period_ns)
    };
    // The worst case's stretches march on along X for as long as it is timed: a travel
    // without end (the set-point's travel check costs the same).
    for a in [
        &mut l.machine.axes.x,
        &mut l.machine.axes.y,
        &mut l.machine.axes.z,
    ] {
        a.min_mm = -1e12;
        a.max_mm = 1e12;
    }
    l
}

fn curve_deg3() -> CommandBlock {
    // A degree-3 NURBS with 8 control points, re-run back to back (closed so it chains).
    let pts = [
        [0.0, 0.0],
        [10.0, 5.0],
        [20.0, -5.0],
        [30.0, 10.0],
        [20.0, 25.0],
        [10.0, 15.0],
        [-5.0, 10.0],
        [0.0, 0.0],
    ];
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 1);
    b.degree = 3;
    b.n_ctrl = pts.len() as u32;
    let knots = [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 5.0, 5.0, 5.0];
    b.knots[..knots.len()].copy_from_slice(&knots);
    for (i, p) in pts.iter().enumerate() {
        b.ctrl[i] = [p[0], p[1], 0.0, if i % 2 == 0 { 1.0 } else { 0.8 }];
    }
    b.feed_mm_per_min = 3000.0;
    b.start_feed_mm_per_min = 0.0;
    b.end_feed_mm_per_min = 0.0;
    b.length_mm = path::length(&b);
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b
}

/// A closed degree-5 rational NURBS (10 control points, non-unit weights, in 3D). Its end
/// tangent is its start tangent (`P8`, `P9 = P0`, `P1` in line), so the repeats chain at
/// a planned junction speed of 20 mm/s instead of stopping.
fn curve_deg5() -> CommandBlock {
    let pts: [[f64; 4]; 10] = [
        [0.0, 0.0, 0.0, 1.0],
        [15.0, 0.0, 0.0, 0.9],
        [35.0, 10.0, 2.0, 1.2],
        [40.0, 30.0, 4.0, 0.8],
        [25.0, 45.0, 5.0, 1.1],
        [5.0, 45.0, 5.0, 1.3],
        [-15.0, 35.0, 3.0, 0.7],
        [-25.0, 15.0, 1.0, 1.0],
        [-15.0, 0.0, 0.0, 0.9],
        [0.0, 0.0, 0.0, 1.0],
    ];
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 1);
    b.degree = 5;
    b.n_ctrl = pts.len() as u32;
    let knots = [
        0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 5.0, 5.0, 5.0, 5.0, 5.0,
    ];
    b.knots[..knots.len()].copy_from_slice(&knots);
    b.ctrl[..pts.len()].copy_from_slice(&pts);
    b.feed_mm_per_min = 3000.0;
    b.start_feed_mm_per_min = 1200.0;
    b.end_feed_mm_per_min = 1200.0;
    b.length_mm = path::length(&b);
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b
}

/// A rational bicubic Bézier patch (p = q = 3, 16 control points, weights 0.8..1.3), a
/// 40 × 40 mm bump, as a surface block: one diagonal pass from `from` to `to` in `(u, v)`,
/// ball tool R 3 mm, H 40 mm, on the upper side. Stops at its end (the next pass turns
/// back).
fn patch_pass(from: [f64; 2], to: [f64; 2]) -> CommandBlock {
    let z = [
        [0.0, 2.0, 3.0, 0.5],
        [1.5, 9.0, 7.0, 2.0],
        [2.5, 6.0, 10.0, 3.0],
        [0.0, 2.5, 3.5, 1.0],
    ];
    let w = [
        [1.0, 0.9, 1.1, 1.0],
        [1.2, 0.8, 1.3, 0.9],
        [0.9, 1.25, 0.85, 1.1],
        [1.0, 1.1, 0.95, 1.0],
    ];
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 2);
    b.flags = FLAG_SURFACE;
    b.degree = 3;
    b.surface.degree_v = 3;
    b.n_ctrl = 16;
    for i in 0..4 {
        for j in 0..4 {
            let (x, y) = (40.0 * i as f64 / 3.0, 40.0 * j as f64 / 3.0);
            b.ctrl[4 * i + j] = [x, y, z[i][j], w[i][j]];
        }
    }
    b.surface.uv_start = from;
    b.surface.uv_end = to;
    b.surface.tool_radius_mm = 3.0;
    b.surface.tool_length_mm = 40.0;
    b.surface.normal_sign = 1;
    if path::surface_at(&b, 0.5).normal[2] < 0.0 {
        b.surface.normal_sign = -1;
    }
    b.feed_mm_per_min = 2400.0;
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b.length_mm = path::length(&b);
    b
}

/// The straight line `x0 → x1` along X.
fn line_x(x0: f64, x1: f64, start_mm_per_min: f64, end_mm_per_min: f64) -> CommandBlock {
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 3);
    b.degree = 1;
    b.n_ctrl = 2;
    b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
    b.ctrl[0] = [x0, 0.0, 0.0, 1.0];
    b.ctrl[1] = [x1, 0.0, 0.0, 1.0];
    b.feed_mm_per_min = 3000.0;
    b.start_feed_mm_per_min = start_mm_per_min;
    b.end_feed_mm_per_min = end_mm_per_min;
    b.length_mm = x1 - x0;
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b
}

/// Segment length and stop spacing of `profile_worst`.
const TINY_MM: f64 = 0.01;
const STOP_EVERY: usize = 200;

/// Tiny segments along X, a stop every `STOP_EVERY` of them, their end speeds planned as
/// a planner's forward and backward passes would (the highest speed from which the
/// stops on both sides can be kept under the block's jerk limits): past the middle of each
/// stretch every segment ends slower than the one before.
struct Tiny {
    /// One stretch, from x = 0; repeats are shifted along X.
    stretch: Vec<CommandBlock>,
    seq: u64,
}

impl Tiny {
    fn new() -> Self {
        let j = Jerk {
            acc: 2000.0,
            jerk: 50_000.0,
        };
        let span = STOP_EVERY as f64 * TINY_MM;
        let end_speed = |x: f64| {
            let v = j
                .reachable_speed(0.0, x)
                .min(j.reachable_speed(0.0, span - x));
            (v * 60.0).min(3000.0)
        };
        let stretch = (0..STOP_EVERY)
            .map(|i| {
                let (a, b) = (i as f64 * TINY_MM, (i + 1) as f64 * TINY_MM);
                let end = if i + 1 == STOP_EVERY {
                    0.0
                } else {
                    end_speed(b)
                };
                line_x(a, b, end_speed(a), end)
            })
            .collect();
        Tiny { stretch, seq: 0 }
    }
}

impl BlockSource for Tiny {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let n = STOP_EVERY as u64;
        let mut b = *self.stretch.get((self.seq % n) as usize)?;
        let shift = (self.seq / n) as f64 * STOP_EVERY as f64 * TINY_MM;
        b.ctrl[0][0] += shift;
        b.ctrl[1][0] += shift;
        b.seq = self.seq;
        self.seq += 1;
        Some(b)
    }
}

/// What a stretch of cycles did, to show that a case measures what it claims.
#[derive(Debug)]
struct Survey {
    cycles: u64,
    top_mm_per_s: f64,
    blocks: u64,
    stops: u64,
}

/// One case: the engine, its blocks, and the set-point service with a subscriber.
struct Case<Src: BlockSource> {
    engine: Engine,
    src: Src,
    cycle: u64,
    publisher: Publisher<ipc::Service, Setpoint, ()>,
    subscriber: Subscriber<ipc::Service, Setpoint, ()>,
    _service: PubSub<ipc::Service, Setpoint>,
    _node: Node<ipc::Service>,
}

impl<Src: BlockSource> Case<Src> {
    fn new(tag: &str, lim: Limits, start_mm: [f64; 3], src: Src) -> Self {
        // A service name of its own per run and case: parallel runs never meet.
        let svc = Services::new(format!("bench{}{tag}", std::process::id()));
        let node = shared::ipc::node::<ipc::Service>("cycle-bench").expect("node");
        let service = shared::ipc::setpoints(&node, &svc).expect("set-point service");
        let publisher = service.publisher_builder().create().expect("publisher");
        let subscriber = service.subscriber_builder().create().expect("subscriber");
        let mut case = Case {
            engine: Engine::new(lim, start_mm),
            src,
            cycle: 0,
            publisher,
            subscriber,
            _service: service,
            _node: node,
        };
        for _ in 0..WARMUP_CYCLES {
            case.step();
            assert_eq!(case.drain(), 1, "the subscriber receives every set-point");
        }
        case
    }

    /// Runs `n` cycles (no publishing) and says what they did: top path speed, blocks
    /// taken and stops. Every cycle must be running (never starved, never done).
    fn survey(&mut self, n: u64) -> Survey {
        let (mut top, mut stops, mut was_moving) = (0.0f64, 0, false);
        let blocks0 = self.engine.blocks_received();
        for _ in 0..n {
            let t = self.engine.tick(&mut self.src).expect("tick");
            assert_eq!(t.state, TickState::Running, "cycle {}", self.cycle);
            top = top.max(t.speed_mm_per_s);
            let moving = t.speed_mm_per_s > 0.0;
            stops += (was_moving && !moving) as u64;
            was_moving = moving;
            self.cycle += 1;
        }
        Survey {
            cycles: n,
            top_mm_per_s: top,
            blocks: self.engine.blocks_received() - blocks0,
            stops,
        }
    }

    /// `n` publishes alone (loan, write, send), timed one by one (ns each).
    fn publish_only(&mut self, n: usize) -> Vec<u64> {
        let sp = Setpoint {
            protocol: PROTOCOL_VERSION,
            ..Setpoint::default()
        };
        let mut ns = Vec::with_capacity(n);
        for _ in 0..n {
            let t0 = Instant::now();
            if let Ok(s) = self.publisher.loan_uninit() {
                let _ = black_box(s.write_payload(sp).send());
            }
            ns.push(t0.elapsed().as_nanos() as u64);
            self.drain();
        }
        ns
    }

    /// One full cycle: tick, set-point, publish. What the real-time loop does between
    /// reading its inputs and writing its status.
    #[inline]
    fn step(&mut self) {
        let t = match self.engine.tick(&mut self.src) {
            Ok(t) => t,
            Err(f) => panic!("cycle {}: {f}", self.cycle),
        };
        let sp = Setpoint {
            protocol: PROTOCOL_VERSION,
            flags: 0,
            cycle: self.cycle,
            t_ns: self.cycle * PERIOD_NS,
            block_seq: t.block_seq,
            source_line: t.source_line,
            _reserved: 0,
            pos_mm: t.pos_mm,
            vel_mm_per_s: t.vel_mm_per_s,
            acc_mm_per_s2: t.acc_mm_per_s2,
        };
        if let Ok(s) = self.publisher.loan_uninit() {
            let _ = black_box(s.write_payload(sp).send());
        }
        self.cycle += 1;
    }

    /// Empties the subscriber's queue; how many set-points it held.
    fn drain(&mut self) -> u64 {
        let mut n = 0;
        while let Ok(Some(s)) = self.subscriber.receive() {
            black_box(s.payload().cycle);
            n += 1;
        }
        n
    }

    /// `iters` cycles, each timed on its own so that the subscriber's drain after it is
    /// left out (one timer pair per cycle is included: see the timer overhead row).
    fn timed(&mut self, iters: u64) -> Duration {
        let mut total = Duration::ZERO;
        for _ in 0..iters {
            let t0 = Instant::now();
            self.step();
            total += t0.elapsed();
            self.drain();
        }
        total
    }

    /// `n` cycles timed one by one (ns each).
    fn each(&mut self, n: usize) -> Vec<u64> {
        let mut ns = Vec::with_capacity(n);
        for _ in 0..n {
            let t0 = Instant::now();
            self.step();
            ns.push(t0.elapsed().as_nanos() as u64);
            self.drain();
        }
        ns
    }
}

fn deg5_case() -> (Survey, Case<Repeat>) {
    let b = curve_deg5();
    let src = Repeat {
        blocks: vec![b],
        seq: 0,
    };
    let mut case = Case::new("deg5", lim(PERIOD_NS, 16), path::eval(&b, 0.0).p, src);
    // At feed, through block junctions at speed: no stop after the start.
    let s = case.survey(SURVEY_CYCLES);
    assert!(
        s.top_mm_per_s > 49.9 && s.blocks >= 3 && s.stops == 0,
        "{s:?}"
    );
    (s, case)
}

fn surface_case() -> (Survey, Case<Repeat>) {
    let (a, b) = ([0.1, 0.2], [0.9, 0.8]);
    let there = patch_pass(a, b);
    let back = patch_pass(b, a);
    let src = Repeat {
        blocks: vec![there, back],
        seq: 0,
    };
    let mut case = Case::new("surf", lim(PERIOD_NS, 16), path::eval(&there, 0.0).p, src);
    // Back and forth at feed, turning at each end.
    let s = case.survey(SURVEY_CYCLES);
    assert!(
        s.top_mm_per_s > 39.9 && s.blocks >= 4 && s.stops >= 4,
        "{s:?}"
    );
    (s, case)
}

/// [`patch_pass`] bent into the cubic `(u, v)` curve with inner points `p1`, `p2`.
fn cubic_pass(from: [f64; 2], p1: [f64; 2], p2: [f64; 2], to: [f64; 2]) -> CommandBlock {
    let mut b = patch_pass(from, to);
    b.flags |= shared::protocol::FLAG_UV_CUBIC;
    b.surface.uv_inner = [p1, p2];
    b.length_mm = path::length(&b);
    b
}

fn surface_cubic_case() -> (Survey, Case<Repeat>) {
    let (a, p1, p2, b) = ([0.1, 0.2], [0.7, 0.1], [0.3, 0.9], [0.9, 0.8]);
    let there = cubic_pass(a, p1, p2, b);
    let back = cubic_pass(b, p2, p1, a);
    let src = Repeat {
        blocks: vec![there, back],
        seq: 0,
    };
    let mut case = Case::new("surfc", lim(PERIOD_NS, 16), path::eval(&there, 0.0).p, src);
    let s = case.survey(SURVEY_CYCLES);
    assert!(
        s.top_mm_per_s > 39.9 && s.blocks >= 4 && s.stops >= 4,
        "{s:?}"
    );
    (s, case)
}

fn worst_case() -> (Survey, Case<Tiny>) {
    let mut case = Case::new("worst", lim(PERIOD_NS, 256), [0.0; 3], Tiny::new());
    // Back to rest at the end of every stretch. (The planned top speed of a stretch is
    // 34.8 mm/s; the engine reaches 27.2 mm/s, see BENCHMARKS.md.)
    let s = case.survey(SURVEY_CYCLES);
    assert!(
        s.top_mm_per_s > 5.0 && s.blocks >= 2000 && s.stops >= 10,
        "{s:?}"
    );
    (s, case)
}

fn criterion_benches(c: &mut Criterion) {
    c.bench_function("tick_nurbs_deg3", |bch| {
        let mut src = Repeat {
            blocks: vec![curve_deg3()],
            seq: 0,
        };
        let mut e = Engine::new(lim(1_000_000, 16), [0.0; 3]);
        bch.iter(|| e.tick(&mut src).map(|t| t.pos_mm))
    });
    // What checking one block against the machine costs as it enters the window (once per
    // block, not per cycle): inside the travel at once, a travel that the curve touches
    // (its hull crosses the limit: the refinement must prove the curve inside), a surface
    // pass, and a block refused with its exact reach found. Measured (release, a loaded
    // 2-core VM): 0.30 µs, 5.8 µs, 8.3 µs and 0.15 µs.
    let mut g = c.benchmark_group("block_check");
    let machine = shared::protocol::MachineLimits::of(&shared::Machine::default());
    let deg5 = curve_deg5();
    g.bench_function("deg5_inside", |bch| {
        bch.iter(|| black_box(&deg5).validate_for(&machine))
    });
    let mut touching = machine;
    touching.axes.x.max_mm = 0.0;
    let reach = match shared::travel::check_block(&deg5, &touching.axes) {
        Err(e) => e.reach_mm,
        Ok(()) => unreachable!("the curve reaches past X = 0"),
    };
    touching.axes.x.max_mm = reach;
    assert!(deg5.validate_for(&touching).is_ok());
    g.bench_function("deg5_touching", |bch| {
        bch.iter(|| black_box(&deg5).validate_for(&touching))
    });
    let mut refused = touching;
    refused.axes.x.max_mm = reach - 1e-3;
    assert!(deg5.validate_for(&refused).is_err());
    g.bench_function("deg5_refused", |bch| {
        bch.iter(|| black_box(&deg5).validate_for(&refused))
    });
    let pass = patch_pass([0.1, 0.2], [0.9, 0.8]);
    g.bench_function("surface_p3q3", |bch| {
        bch.iter(|| black_box(&pass).validate_for(&machine))
    });
    g.finish();
    let mut g = c.benchmark_group("cycle");
    g.bench_function("nurbs_deg5_publish", |bch| {
        let (_, mut case) = deg5_case();
        bch.iter_custom(|iters| case.timed(iters))
    });
    g.bench_function("surface_p3q3", |bch| {
        let (_, mut case) = surface_case();
        bch.iter_custom(|iters| case.timed(iters))
    });
    g.bench_function("surface_cubic", |bch| {
        let (_, mut case) = surface_cubic_case();
        bch.iter_custom(|iters| case.timed(iters))
    });
    g.bench_function("profile_worst", |bch| {
        let (_, mut case) = worst_case();
        bch.iter_custom(|iters| case.timed(iters))
    });
    g.finish();
    // A read of each clock the cycle reads: the wall clock (vDSO) three times a cycle,
    // the thread's own CPU time (a system call) once, for the `preempted` cause.
    let mut g = c.benchmark_group("clock");
    g.bench_function("now_ns", |bch| bch.iter(shared::clock::now_ns));
    g.bench_function("thread_cpu_ns", |bch| {
        bch.iter(shared::clock::thread_cpu_ns)
    });
    g.finish();
}

/// The value at quantile `q` of sorted `v` (nearest rank).
fn quantile(v: &[u64], q: f64) -> u64 {
    if v.is_empty() {
        return 0;
    }
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

fn print_row(name: &str, mut ns: Vec<u64>) {
    ns.sort_unstable();
    let mean = ns.iter().sum::<u64>() as f64 / ns.len().max(1) as f64;
    println!(
        "{name:<26} {:>8} {:>7.0} {:>7} {:>7} {:>7} {:>8} {:>9}",
        ns.len(),
        mean,
        quantile(&ns, 0.50),
        quantile(&ns, 0.90),
        quantile(&ns, 0.99),
        quantile(&ns, 0.999),
        ns.last().copied().unwrap_or(0),
    );
}

/// The filter criterion was given (its first positional argument), if any.
fn filter() -> Option<String> {
    const WITH_VALUE: [&str; 14] = [
        "--save-baseline",
        "--baseline",
        "--load-baseline",
        "--sample-size",
        "--warm-up-time",
        "--measurement-time",
        "--nresamples",
        "--noise-threshold",
        "--confidence-level",
        "--significance-level",
        "--profile-time",
        "--output-format",
        "--color",
        "--plotting-backend",
    ];
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        if WITH_VALUE.contains(&a.as_str()) {
            args.next();
        } else if !a.starts_with('-') {
            return Some(a);
        }
    }
    None
}

/// A count from the environment, or `default`.
fn env_count(var: &str, default: usize) -> usize {
    std::env::var(var)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

/// Times `n` cycles of a case made afresh `repeats` times. The cycles are deterministic
/// (the same work at the same index in every run), so the minimum per index over the
/// runs is the cycle's own cost with most of the machine's noise (preemption,
/// interrupts, the other builders) taken out; the pooled runs are what the machine gave.
fn measure<Src: BlockSource>(
    name: &str,
    make: impl Fn() -> (Survey, Case<Src>),
    n: usize,
    repeats: usize,
) -> Survey {
    let mut runs = Vec::with_capacity(repeats);
    let mut survey = None;
    for _ in 0..repeats {
        let (s, mut case) = make();
        runs.push(case.each(n));
        survey = Some(s);
    }
    let min: Vec<u64> = (0..n)
        .map(|k| runs.iter().filter_map(|r| r.get(k)).copied().min())
        .map(|m| m.unwrap_or(0))
        .collect();
    print_row(name, runs.concat());
    print_row(&format!("  min of {repeats} per cycle"), min);
    survey.expect("at least one run")
}

fn percentiles() {
    let args: Vec<String> = std::env::args().collect();
    if args.iter().any(|a| a == "--list") {
        return;
    }
    // Under `cargo test` (no `--bench`) a short run only proves the code works.
    let bench = args.iter().any(|a| a == "--bench");
    let n = env_count("CYCLE_PCT_N", if bench { PCT_N } else { 2_000 });
    let repeats = env_count("CYCLE_PCT_REPEATS", if bench { 5 } else { 2 }).max(1);
    if n == 0 {
        return;
    }
    let wanted = |name: &str| filter().is_none_or(|f| name.contains(&f));
    println!();
    println!(
        "Per-cycle percentiles (ns): {n} single cycles per case and run, {repeats} runs, \
         period {PERIOD_NS} ns, each cycle timed with std::time::Instant"
    );
    println!(
        "{:<26} {:>8} {:>7} {:>7} {:>7} {:>7} {:>8} {:>9}",
        "case", "cycles", "mean", "p50", "p90", "p99", "p99.9", "max"
    );
    // What one `Instant::now()` .. `elapsed()` pair costs with nothing between: it is
    // included in every figure below.
    let timer: Vec<u64> = (0..n * repeats)
        .map(|_| {
            let t0 = black_box(Instant::now());
            t0.elapsed().as_nanos() as u64
        })
        .collect();
    print_row("timer overhead (empty)", timer);
    let mut surveys = Vec::new();
    if wanted("cycle/nurbs_deg5_publish") {
        let (_, mut case) = deg5_case();
        print_row("publish alone (loan+send)", case.publish_only(n * repeats));
        drop(case);
        let s = measure("cycle/nurbs_deg5_publish", deg5_case, n, repeats);
        surveys.push(("cycle/nurbs_deg5_publish", s));
    }
    if wanted("cycle/surface_p3q3") {
        let s = measure("cycle/surface_p3q3", surface_case, n, repeats);
        surveys.push(("cycle/surface_p3q3", s));
    }
    if wanted("cycle/surface_cubic") {
        let s = measure("cycle/surface_cubic", surface_cubic_case, n, repeats);
        surveys.push(("cycle/surface_cubic", s));
    }
    if wanted("cycle/profile_worst") {
        let s = measure("cycle/profile_worst", worst_case, n, repeats);
        surveys.push(("cycle/profile_worst", s));
    }
    println!("target (issue #6): p99 <= 2000 ns; period 100 000 ns");
    println!();
    println!("What each case ran (an untimed survey before the timing):");
    for (name, s) in surveys {
        println!(
            "{name:<26} {} cycles: top path speed {:.1} mm/s, {} blocks, {} stops",
            s.cycles, s.top_mm_per_s, s.blocks, s.stops
        );
    }
}

fn main() {
    // CYCLE_CRITERION=0: the percentiles alone.
    if env_count("CYCLE_CRITERION", 1) != 0 {
        let mut c = Criterion::default().configure_from_args();
        criterion_benches(&mut c);
        c.final_summary();
    }
    percentiles();
}
