//! Set-point identity probe (not a test of behaviour): hashes the bits of every tick's
//! position, speed and path acceleration over several chains. Run with
//! `cargo test --release -p interpolator --test probe_hash -- --ignored --nocapture`.

use interpolator::engine::{BlockSource, Engine, Limits, TickState};
use shared::path;
use shared::profile::Limits as Jerk;
use shared::protocol::{BlockKind, CommandBlock, FLAG_SURFACE, FLAG_UV_CUBIC};

struct List {
    blocks: Vec<CommandBlock>,
    i: usize,
    repeat: bool,
    seq: u64,
}

impl BlockSource for List {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let n = self.blocks.len();
        if !self.repeat && self.i >= n {
            if self.i == n {
                self.i += 1;
                let e = CommandBlock::empty(BlockKind::ProgramEnd, self.seq, 9);
                self.seq += 1;
                return Some(e);
            }
            return None;
        }
        let mut b = *self.blocks.get(self.i % n)?;
        b.seq = self.seq;
        self.seq += 1;
        self.i += 1;
        Some(b)
    }
}

struct Tiny {
    stretch: Vec<CommandBlock>,
    seq: u64,
}

impl BlockSource for Tiny {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let n = self.stretch.len() as u64;
        let mut b = *self.stretch.get((self.seq % n) as usize)?;
        let shift = (self.seq / n) as f64 * n as f64 * 0.01;
        b.ctrl[0][0] += shift;
        b.ctrl[1][0] += shift;
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

fn line_x(x0: f64, x1: f64, s: f64, e: f64, feed: f64, acc: f64, jerk: f64) -> CommandBlock {
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 3);
    b.degree = 1;
    b.n_ctrl = 2;
    b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
    b.ctrl[0] = [x0, 0.0, 0.0, 1.0];
    b.ctrl[1] = [x1, 0.0, 0.0, 1.0];
    b.feed_mm_per_min = feed;
    b.start_feed_mm_per_min = s;
    b.end_feed_mm_per_min = e;
    b.length_mm = x1 - x0;
    b.acc_mm_per_s2 = acc;
    b.jerk_mm_per_s3 = jerk;
    b
}

fn tiny() -> Tiny {
    let j = Jerk {
        acc: 2000.0,
        jerk: 50_000.0,
    };
    let span = 200.0 * 0.01;
    let end_speed = |x: f64| {
        let v = j
            .reachable_speed(0.0, x)
            .min(j.reachable_speed(0.0, span - x));
        (v * 60.0).min(3000.0)
    };
    let stretch = (0..200)
        .map(|i| {
            let (a, b) = (i as f64 * 0.01, (i + 1) as f64 * 0.01);
            let end = if i + 1 == 200 { 0.0 } else { end_speed(b) };
            line_x(a, b, end_speed(a), end, 3000.0, 2000.0, 50_000.0)
        })
        .collect();
    Tiny { stretch, seq: 0 }
}

/// 1500 lines whose acc and jerk alternate sixfold, feeds in five steps, planned
/// backwards (each end reachable from the next under the next block's limits).
fn mixed() -> List {
    let n = 1500;
    let mut blocks = Vec::new();
    let mut x = 0.0;
    for i in 0..n {
        let len = 0.02 + 0.05 * ((i * 7919) % 13) as f64 / 13.0;
        let (acc, jerk) = if i % 2 == 0 {
            (2000.0, 50_000.0)
        } else {
            (2000.0 / 6.0, 50_000.0 / 6.0)
        };
        let feed = [3000.0, 1200.0, 2400.0, 600.0, 1800.0][(i / 40) % 5];
        blocks.push(line_x(x, x + len, 0.0, 0.0, feed, acc, jerk));
        x += len;
    }
    let mut next_start = 0.0f64; // mm/s at the start of block i+1
    for i in (0..n).rev() {
        let end = if i + 1 == n {
            0.0
        } else {
            let nb = blocks[i + 1];
            let f = nb.feed_mm_per_min / 60.0;
            next_start.min(f).min(blocks[i].feed_mm_per_min / 60.0)
        };
        let b = &mut blocks[i];
        b.end_feed_mm_per_min = end * 60.0;
        let j = Jerk {
            acc: b.acc_mm_per_s2,
            jerk: b.jerk_mm_per_s3,
        };
        next_start = j
            .reachable_speed(end, b.length_mm)
            .min(b.feed_mm_per_min / 60.0);
    }
    for i in 0..n {
        let s = if i == 0 {
            0.0
        } else {
            blocks[i - 1].end_feed_mm_per_min
        };
        blocks[i].start_feed_mm_per_min = s.min(blocks[i].feed_mm_per_min);
    }
    List {
        blocks,
        i: 0,
        repeat: false,
        seq: 0,
    }
}

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

fn cubic_pass(from: [f64; 2], p1: [f64; 2], p2: [f64; 2], to: [f64; 2]) -> CommandBlock {
    let mut b = patch_pass(from, to);
    b.flags |= FLAG_UV_CUBIC;
    b.surface.uv_inner = [p1, p2];
    b.length_mm = path::length(&b);
    b
}

fn run(name: &str, mut e: Engine, src: &mut impl BlockSource, cycles: u64, stop_at: Option<u64>) {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |x: u64| {
        for byte in x.to_le_bytes() {
            h ^= u64::from(byte);
            h = h.wrapping_mul(0x100_0000_01b3);
        }
    };
    let mut n = 0;
    for k in 0..cycles {
        if stop_at == Some(k) {
            e.stop();
        }
        let t = e.tick(src).expect("tick");
        for v in t.pos_mm {
            eat(v.to_bits());
        }
        eat(t.speed_mm_per_s.to_bits());
        eat(e.acc_mm_per_s2().to_bits());
        n += 1;
        if t.state == TickState::Done || e.at_rest() {
            break;
        }
    }
    println!(
        "{name}: {n} cycles, received {}, hash {h:016x}",
        e.blocks_received()
    );
}

#[test]
#[ignore]
fn probe_hashes() {
    run(
        "tiny 100us/256",
        Engine::new(lim(100_000, 256), [0.0; 3]),
        &mut tiny(),
        300_000,
        None,
    );
    run(
        "tiny 1ms/64",
        Engine::new(lim(1_000_000, 64), [0.0; 3]),
        &mut tiny(),
        60_000,
        None,
    );
    run(
        "tiny 100us/256 stop",
        Engine::new(lim(100_000, 256), [0.0; 3]),
        &mut tiny(),
        300_000,
        Some(123_457),
    );
    run(
        "mixed 100us/256",
        Engine::new(lim(100_000, 256), [0.0; 3]),
        &mut mixed(),
        2_000_000,
        None,
    );
    run(
        "mixed 1ms/16",
        Engine::new(lim(1_000_000, 16), [0.0; 3]),
        &mut mixed(),
        200_000,
        None,
    );
    run(
        "mixed 100us/16",
        Engine::new(lim(100_000, 16), [0.0; 3]),
        &mut mixed(),
        2_000_000,
        None,
    );
    let c = curve_deg5();
    let mut src = List {
        blocks: vec![c],
        i: 0,
        repeat: true,
        seq: 0,
    };
    run(
        "deg5 stop",
        Engine::new(lim(100_000, 16), path::eval(&c, 0.0).p),
        &mut src,
        300_000,
        Some(150_000),
    );
    let (a, b) = ([0.1, 0.2], [0.9, 0.8]);
    let there = patch_pass(a, b);
    let mut src = List {
        blocks: vec![there, patch_pass(b, a)],
        i: 0,
        repeat: true,
        seq: 0,
    };
    run(
        "surface",
        Engine::new(lim(100_000, 16), path::eval(&there, 0.0).p),
        &mut src,
        150_000,
        None,
    );
    let (p1, p2) = ([0.7, 0.1], [0.3, 0.9]);
    let there = cubic_pass(a, p1, p2, b);
    let mut src = List {
        blocks: vec![there, cubic_pass(b, p2, p1, a)],
        i: 0,
        repeat: true,
        seq: 0,
    };
    run(
        "surface cubic",
        Engine::new(lim(100_000, 16), path::eval(&there, 0.0).p),
        &mut src,
        150_000,
        None,
    );
}
