//! Cost of one interpolation cycle (path step + NURBS evaluation) on a long straight line
//! and on a NURBS curve. Run: cargo bench -p interpolator --bench cycle
use criterion::{criterion_group, criterion_main, Criterion};
use interpolator::engine::{BlockSource, Engine, Limits};
use shared::protocol::{BlockKind, CommandBlock};

struct Repeat(CommandBlock, u64);
impl BlockSource for Repeat {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let mut b = self.0;
        b.seq = self.1;
        self.1 += 1;
        Some(b)
    }
}

fn curve() -> CommandBlock {
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
    b.length_mm = shared::path::length(&b);
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b
}

fn bench(c: &mut Criterion) {
    let lim = Limits {
        period_ns: 1_000_000,
        path_acc_mm_per_s2: 2000.0,
        path_jerk_mm_per_s3: 50_000.0,
        lookahead_blocks: 16,
        max_following_error_mm: 1.0,
    };
    c.bench_function("tick_nurbs_deg3", |bch| {
        let mut src = Repeat(curve(), 0);
        let mut e = Engine::new(lim, [0.0; 3]);
        bch.iter(|| e.tick(&mut src).map(|t| t.pos_mm))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
