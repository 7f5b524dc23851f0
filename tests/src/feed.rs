//! The feed table's measurements: a program planned and stepped through the
//! interpolator's engine in this process, as `cnc check --estimate` does, and its
//! set-points measured cycle by cycle against the machine's limits, next to the
//! time-optimal references of [`crate::topp`] and (jerk-limited) [`crate::topp3`].
//!
//! From the set-points alone (backward differences, `T` the period): each axis's velocity
//! `Δp/T`, acceleration `Δ²p/T²` and jerk `Δ³p/T³` against that axis's limits, and the
//! path's acceleration and jerk (the vectors' norms) against `path_acc_mm_per_s2` and
//! `path_jerk_mm_per_s3`. The jerk leaves out the three cycles after a junction whose
//! tangent turns, or where a surface's tool point steps its speed (a kink, which no
//! finite jerk follows; as `interpreter/tests/limits.rs` does; the acceleration is
//! measured there too). The chord: each set-point is projected onto the exact curve of the block the
//! engine reports (Gauss–Newton from the previous foot point), and the exact curve
//! between two consecutive feet (eight intervals on each block it crosses, block ends
//! included) is measured against the straight step: the largest distance, against
//! `chord_tolerance_mm`. A second algorithm to the sagitta of `limits.rs`.

use crate::topp::{self, RefLimits};
use crate::topp3::{self, JerkLimits};
use interpolator::engine::{BlockSource, Engine, Limits, Tick, TickState};
use shared::path;
use shared::protocol::{BlockKind, CommandBlock, FLAG_RAPID};
use shared::Machine;
use std::collections::HashSet;

/// The worst of each figure over a run, in units of its limit.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Worst {
    /// Largest axis velocity / that axis's limit.
    pub vel: f64,
    /// Largest of path acceleration / `path_acc` and axis acceleration / the axis's.
    pub acc: f64,
    /// The same for jerk (away from kinks).
    pub jerk: f64,
    /// Largest distance of the exact curve from a set-point step / `chord_tolerance_mm`.
    pub chord: f64,
    /// Largest distance of a set-point from the exact curve, mm.
    pub off_curve_mm: f64,
    /// Where the worst acceleration and jerk were: cycle (from 1) and source line.
    pub acc_at: (u64, u32),
    pub jerk_at: (u64, u32),
}

/// One run measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measured {
    pub cycles: u64,
    pub time_s: f64,
    pub worst: Worst,
}

struct Slice<'a>(&'a [CommandBlock], usize);

impl BlockSource for Slice<'_> {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let b = self.0.get(self.1).copied();
        self.1 += usize::from(b.is_some());
        b
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Point and parametric derivative of the set-point path (differences for a surface
/// block, whose [`path::eval`] derivative is the contact point's).
fn point_d1(b: &CommandBlock, u: f64) -> ([f64; 3], [f64; 3]) {
    let e = path::eval(b, u);
    if !b.is_surface() {
        return (e.p, e.d1);
    }
    let h = 1e-6;
    let (a, c) = ((u - h).max(0.0), (u + h).min(1.0));
    let (pa, pc) = (path::eval(b, a).p, path::eval(b, c).p);
    (e.p, sub(pc, pa).map(|x| x / (c - a)))
}

/// The foot of `p` on block `b`, from the guess `u`, within the block's domain:
/// Gauss–Newton, stepping off a point where the parametric speed vanishes; if that ends
/// off the curve, the nearest of 256 samples from the guess on, refined the same way.
fn project(b: &CommandBlock, p: [f64; 3], u: f64) -> (f64, f64) {
    let (u0, u1) = path::domain(b);
    let (u, dist) = newton(b, p, u);
    if dist <= 1e-9 {
        return (u, dist);
    }
    let n = 256;
    let best = (0..=n)
        .map(|j| u + (u1 - u) * j as f64 / n as f64)
        .map(|x| (x, path::norm(sub(path::eval(b, x).p, p))))
        .fold((u, f64::INFINITY), |a, c| if c.1 < a.1 { c } else { a });
    let (v, d) = newton(b, p, best.0.max(u0));
    if d < dist {
        (v, d)
    } else {
        (u, dist)
    }
}

fn newton(b: &CommandBlock, p: [f64; 3], mut u: f64) -> (f64, f64) {
    let (u0, u1) = path::domain(b);
    let width = (u1 - u0).max(1e-300);
    for _ in 0..40 {
        let (q, d1) = point_d1(b, u);
        let r = sub(q, p);
        if path::norm(r) == 0.0 {
            break;
        }
        let g = dot(d1, d1);
        let next = if g <= 1e-24 {
            // The parametric speed vanishes here (a repeated control point): step off.
            (u + 1e-7 * width).min(u1)
        } else {
            (u - dot(r, d1) / g).clamp(u0, u1)
        };
        let done = (next - u).abs() <= 1e-15 * width.max(1.0);
        u = next;
        if done {
            break;
        }
    }
    (u, path::norm(sub(path::eval(b, u).p, p)))
}

/// Distance of `q` from the segment `a`–`c`.
fn seg_dist(q: [f64; 3], a: [f64; 3], c: [f64; 3]) -> f64 {
    let d = sub(c, a);
    let l2 = dot(d, d);
    let t = if l2 > 0.0 {
        (dot(sub(q, a), d) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    path::norm(sub(q, [a[0] + t * d[0], a[1] + t * d[1], a[2] + t * d[2]]))
}

/// The sequence numbers of the blocks after a junction whose tangent turns, or, between
/// two surface blocks passed at speed, where the tool point's velocity per unit of
/// contact speed steps in length or direction (beyond the differences' noise, 1e-5 of
/// it): where a surface is only C¹, the ball's centre moves faster or slower for the same
/// feed on either side, a step of its speed in one period that no finite jerk follows.
fn kinks(blocks: &[CommandBlock]) -> HashSet<u64> {
    let motion = |b: &CommandBlock| b.kind == BlockKind::Motion as u32;
    blocks
        .windows(2)
        .filter(|w| motion(&w[0]) && motion(&w[1]))
        .filter(|w| {
            let (u0, u1) = path::domain(&w[0]);
            let (v0, v1) = path::domain(&w[1]);
            let a = point_d1(&w[0], u1 - 1e-9 * (u1 - u0)).1;
            let b = point_d1(&w[1], v0 + 1e-9 * (v1 - v0)).1;
            let cos = dot(a, b) / (path::norm(a) * path::norm(b));
            let turns = cos.is_nan() || cos < 1.0 - 1e-12;
            let steps =
                w[0].is_surface() && w[1].is_surface() && w[0].end_feed_mm_per_min > 0.0 && {
                    let (ra, rb) = (path::tool_rate(&w[0], 1.0), path::tool_rate(&w[1], 0.0));
                    path::norm(sub(ra, rb)) > 1e-5 * path::norm(ra).max(path::norm(rb))
                };
            turns || steps
        })
        .map(|w| w[1].seq)
        .collect()
}

/// Steps `blocks` (planned, numbered from 0) through the engine from the origin to the
/// program's end, handing `each` every cycle's output.
fn run(
    blocks: &[CommandBlock],
    machine: &Machine,
    period_ns: u64,
    mut each: impl FnMut(&Tick),
) -> Result<(), String> {
    let mut engine = Engine::new(Limits::new(machine, period_ns), [0.0; 3]);
    let mut src = Slice(blocks, 0);
    loop {
        let t = engine.tick(&mut src).map_err(|f| f.to_string())?;
        each(&t);
        match t.state {
            TickState::Done => return Ok(()),
            TickState::Running => {}
            TickState::Starved => return Err("the program has no end block".into()),
        }
    }
}

/// Steps `blocks` (planned, numbered from 0) through the engine from the origin and
/// measures every cycle (see the module page).
pub fn measure(
    blocks: &[CommandBlock],
    machine: &Machine,
    period_ns: u64,
) -> Result<Measured, String> {
    let t_s = period_ns as f64 * 1e-9;
    let by_seq: std::collections::HashMap<u64, usize> =
        blocks.iter().enumerate().map(|(i, b)| (b.seq, i)).collect();
    let index = |seq: u64| by_seq.get(&seq).copied();
    let kinks = kinks(blocks);
    let axes = machine.axes.as_array();
    let mut w = Worst::default();
    // The last four set-points (newest last) and the blocks of the last four cycles.
    let mut p = [[0.0; 3]; 4];
    let mut seqs = [0u64; 4];
    let mut foot: Option<(usize, f64)> = None;
    let mut cycles = 0u64;
    run(blocks, machine, period_ns, |t| {
        cycles += 1;
        p.rotate_left(1);
        p[3] = t.pos_mm;
        seqs.rotate_left(1);
        seqs[3] = t.block_seq;
        let n = cycles as usize;
        // Backward differences.
        let d1 = sub(p[3], p[2]);
        for k in 0..3 {
            w.vel = w
                .vel
                .max(d1[k].abs() / t_s / (axes[k].max_vel_mm_per_min / 60.0));
        }
        if n >= 2 {
            let d2 = sub(d1, sub(p[2], p[1]));
            let acc = d2.map(|x| x / (t_s * t_s));
            let a = (0..3).fold(path::norm(acc) / machine.path_acc_mm_per_s2, |m, k| {
                m.max(acc[k].abs() / axes[k].max_acc_mm_per_s2)
            });
            if a > w.acc {
                w.acc = a;
                w.acc_at = (cycles, t.source_line);
            }
            let near_kink = (1..4).any(|k| (seqs[k - 1] + 1..=seqs[k]).any(|s| kinks.contains(&s)));
            if n >= 3 && !near_kink {
                let d3 = sub(d2, sub(sub(p[2], p[1]), sub(p[1], p[0])));
                let jerk = d3.map(|x| x / (t_s * t_s * t_s));
                let j = (0..3).fold(path::norm(jerk) / machine.path_jerk_mm_per_s3, |m, k| {
                    m.max(jerk[k].abs() / axes[k].max_jerk_mm_per_s3)
                });
                if j > w.jerk {
                    w.jerk = j;
                    w.jerk_at = (cycles, t.source_line);
                }
            }
        }
        // The chord against the exact curve.
        if let Some(bi) = index(t.block_seq) {
            let b = &blocks[bi];
            if b.kind == BlockKind::Motion as u32 {
                let (u0, _) = path::domain(b);
                let guess = match foot {
                    Some((fb, fu)) if fb == bi => fu,
                    _ => u0,
                };
                let (u, dist) = project(b, p[3], guess);
                w.off_curve_mm = w.off_curve_mm.max(dist);
                if let Some((fb, fu)) = foot {
                    let dev = chord_deviation(blocks, (fb, fu), (bi, u), p[2], p[3]);
                    w.chord = w.chord.max(dev / machine.chord_tolerance_mm);
                }
                foot = Some((bi, u));
            }
        }
    })?;
    Ok(Measured {
        cycles,
        time_s: (cycles * period_ns) as f64 * 1e-9,
        worst: w,
    })
}

/// The largest distance of the exact curve from `from` (block `a` at `ua`) to `to`
/// (block `c` at `uc`) from the straight step `pa`–`pc`.
fn chord_deviation(
    blocks: &[CommandBlock],
    (a, ua): (usize, f64),
    (c, uc): (usize, f64),
    pa: [f64; 3],
    pc: [f64; 3],
) -> f64 {
    const N: usize = 8;
    let mut worst: f64 = 0.0;
    let mut piece = |b: &CommandBlock, x0: f64, x1: f64| {
        for j in 0..=N {
            let u = x0 + (x1 - x0) * j as f64 / N as f64;
            worst = worst.max(seg_dist(path::eval(b, u).p, pa, pc));
        }
    };
    if a == c {
        if uc > ua {
            piece(&blocks[a], ua, uc);
        }
        return worst;
    }
    for (i, b) in blocks.iter().enumerate().take(c + 1).skip(a) {
        if b.kind != BlockKind::Motion as u32 {
            continue;
        }
        let (u0, u1) = path::domain(b);
        let x0 = if i == a { ua } else { u0 };
        let x1 = if i == c { uc } else { u1 };
        piece(b, x0, x1);
    }
    worst
}

/// The most cells [`row`] puts on a path at its coarser grid (by length).
pub const MAX_CELLS: f64 = 100_000.0;

/// The grid step of the jerk-limited optimum in the table, mm, and the most cells it
/// puts on a path (by length; the curvature refinement adds its own): the conic solves
/// take seconds per thousand cells. `tests/tests/topp3.rs` measures its convergence on
/// LinuxCNC's NURBS program (halving 0.25 mm and 0.1 mm).
pub const JERK_STEP_MM: f64 = 0.25;
pub const JERK_MAX_CELLS: f64 = 1_000.0;

/// Cells of the jerk-limited optimum's grid on the shortest curved block, at least
/// (within [`JERK_MAX_CELLS`]): the reference's curvature rate is a difference over at
/// least a cell on each side, so a curve shorter than a few cells has its rate smoothed
/// and its jerk understated. On the CAM circle (`examples/cam-circle.ngc`, blends of
/// 0.63 mm) the optimum was 1.546 s at 0.25 mm, 1.568 s at 0.1 mm and 1.570 s at
/// 0.05 mm.
pub const JERK_CELLS_PER_CURVE: f64 = 8.0;

/// The grid step of the jerk-limited optimum for `blocks`: [`JERK_STEP_MM`], finer where
/// a curved block is shorter than [`JERK_CELLS_PER_CURVE`] of it, coarser where the path
/// is longer than [`JERK_MAX_CELLS`] of it.
pub fn jerk_step_mm(blocks: &[CommandBlock]) -> f64 {
    let length: f64 = blocks.iter().map(|b| b.length_mm).sum();
    let shortest_curve = blocks
        .iter()
        .filter(|b| {
            b.kind == BlockKind::Motion as u32
                && b.flags & FLAG_RAPID == 0
                && b.length_mm > 0.0
                && (b.is_surface() || b.degree > 1)
        })
        .map(|b| b.length_mm)
        .fold(f64::INFINITY, f64::min);
    JERK_STEP_MM
        .min(shortest_curve / JERK_CELLS_PER_CURVE)
        .max(length / JERK_MAX_CELLS)
}

/// The jerk-limited optimum of a row ([`topp3`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JerkColumn {
    pub step_mm: f64,
    pub optimum_s: f64,
    /// The acceleration-only optimum on the same (coarser) grid.
    pub acc_only_s: f64,
    /// The profile's own worst jerk in units of its limit (see [`topp3::JerkOptimum`]).
    pub jerk_ratio: f64,
}

/// One program on one machine: our time (the engine, as `cnc check --estimate`), the
/// acceleration-only optimum at the grid step and at half of it, and the worst figures.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// The grid step used, mm (see [`row`]).
    pub step_mm: f64,
    pub time_s: f64,
    pub optimum_s: f64,
    /// The optimum on the grid of half the step.
    pub optimum_half_s: f64,
    pub grid_points: usize,
    pub length_mm: f64,
    pub worst: Worst,
    /// The jerk-limited optimum, when asked for ([`row`]'s `jerk`).
    pub jerk: Option<Result<JerkColumn, String>>,
}

impl Row {
    /// Our time over the optimum (at the finer grid).
    pub fn ratio(&self) -> f64 {
        self.time_s / self.optimum_half_s
    }

    /// Relative change of the optimum from the grid step to half of it.
    pub fn grid_change(&self) -> f64 {
        (self.optimum_s - self.optimum_half_s).abs() / self.optimum_half_s
    }
}

/// Compiles `text` (G-code or STEP-NC, told apart by its name and text) for `machine`,
/// steps it, measures it and computes its optimum on a grid of `step_mm`, or of
/// [`MAX_CELLS`] cells over the path if that is coarser (a long part's grid stays
/// affordable; the table reports the step and the change at half of it). With `jerk`,
/// also the jerk-limited optimum on the grid of [`jerk_step_mm`].
pub fn row(
    name: &str,
    text: &str,
    machine: &Machine,
    period_ns: u64,
    step_mm: f64,
    jerk: bool,
) -> Result<Row, String> {
    let opts = interpreter::program::Options::default();
    let blocks =
        interpreter::process::compile_source(name, text, &opts, machine, period_ns)?.blocks;
    let est = interpreter::estimate::estimate(&blocks, machine, period_ns)?;
    let m = measure(&blocks, machine, period_ns)?;
    if m.cycles != est.cycles {
        return Err(format!(
            "{name}: the measured run took {} cycles, the estimate {}",
            m.cycles, est.cycles
        ));
    }
    let feeds = topp::programmed_feeds(name, text, machine, period_ns, &blocks)?;
    let lim = RefLimits::of(machine, period_ns);
    let length: f64 = blocks.iter().map(|b| b.length_mm).sum();
    let step_mm = step_mm.max(length / MAX_CELLS);
    let coarse = topp::optimum(&blocks, &feeds, &lim, step_mm);
    let fine = topp::optimum(&blocks, &feeds, &lim, step_mm / 2.0);
    let jerk = jerk.then(|| {
        let step = jerk_step_mm(&blocks);
        let jl = JerkLimits::of(machine, period_ns);
        topp3::optimum(&blocks, &feeds, &jl, step).map(|o| JerkColumn {
            step_mm: step,
            optimum_s: o.time_s,
            acc_only_s: o.acc_only_s,
            jerk_ratio: o.jerk_ratio,
        })
    });
    Ok(Row {
        step_mm,
        time_s: est.time_s,
        optimum_s: coarse.time_s,
        optimum_half_s: fine.time_s,
        grid_points: fine.grid.len(),
        length_mm: fine.length_mm,
        worst: m.worst,
        jerk,
    })
}

/// Where a program's time goes against the jerk-limited optimum, block by block
/// ([`losses`]): the block, its planned figures and the two times spent in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BlockLoss {
    pub seq: u64,
    pub source_line: u32,
    /// Where the block starts along the path, and its length, mm.
    pub start_mm: f64,
    pub length_mm: f64,
    /// Its feed cap and planned start and end speeds, mm/s.
    pub cap_mm_s: f64,
    pub start_mm_s: f64,
    pub end_mm_s: f64,
    /// The tangential acceleration and jerk its profile may use.
    pub acc: f64,
    pub jerk: f64,
    /// Our time in it (its cycles) and the optimum's (its nodes inside it), s.
    pub ours_s: f64,
    pub optimum_s: f64,
    /// The highest and lowest speed of our cycles in it and of the optimum's nodes in
    /// it, mm/s (infinite lowest where none fell in it). On a surface pass ours are
    /// the engine's path speed, the contact point's, and the optimum's the tool
    /// point's: only the times compare there.
    pub ours_mm_s: (f64, f64),
    pub optimum_mm_s: (f64, f64),
}

/// Each motion block's time in our run (the engine stepped as in [`measure`]: the cycles
/// that report the block) against the time the optimum profile `(s, speed)` (arc length
/// in mm from the path's start, mm/s; as [`topp3::JerkOptimum`] gives it) spends over its
/// length (along the set-point path, as the optimum's arc length: a surface pass's tool
/// point, whose length is not the block's `length_mm`). The optimum's time over a cell is its length over the mean of the speeds at
/// its ends (exact where the speed changes at a constant rate). A diagnostic for finding
/// where a plan is slow, not a figure of the table: dwells are left out, and our cycles
/// are counted whole to the block they end in.
pub fn losses(
    blocks: &[CommandBlock],
    machine: &Machine,
    period_ns: u64,
    (s, speed): (&[f64], &[f64]),
) -> Result<Vec<BlockLoss>, String> {
    let mut out = Vec::new();
    let mut at = std::collections::HashMap::new();
    let mut start = 0.0;
    for b in blocks.iter().filter(|b| b.kind == BlockKind::Motion as u32) {
        at.insert(b.seq, out.len());
        out.push(BlockLoss {
            seq: b.seq,
            source_line: b.source_line,
            start_mm: start,
            length_mm: b.length_mm,
            cap_mm_s: b.feed_mm_per_min / 60.0,
            start_mm_s: b.start_feed_mm_per_min / 60.0,
            end_mm_s: b.end_feed_mm_per_min / 60.0,
            acc: b.acc_mm_per_s2,
            jerk: b.jerk_mm_per_s3,
            ours_s: 0.0,
            optimum_s: 0.0,
            ours_mm_s: (0.0, f64::INFINITY),
            optimum_mm_s: (0.0, f64::INFINITY),
        });
        start += topp::set_point_length(b);
    }
    let t_s = period_ns as f64 * 1e-9;
    run(blocks, machine, period_ns, |t| {
        if let Some(&i) = at.get(&t.block_seq) {
            let l = &mut out[i];
            l.ours_s += t_s;
            let v = t.speed_mm_per_s;
            l.ours_mm_s = (l.ours_mm_s.0.max(v), l.ours_mm_s.1.min(v));
        }
    })?;
    let starts: Vec<f64> = out.iter().map(|l| l.start_mm).collect();
    for (w, v) in s.windows(2).zip(speed.windows(2)) {
        let (ds, mean) = (w[1] - w[0], 0.5 * (v[0] + v[1]));
        if ds <= 0.0 || mean <= 0.0 {
            continue;
        }
        let mid = 0.5 * (w[0] + w[1]);
        let i = starts.partition_point(|&x| x <= mid).saturating_sub(1);
        if let Some(l) = out.get_mut(i) {
            l.optimum_s += ds / mean;
            let (hi, lo) = (v[0].max(v[1]), v[0].min(v[1]));
            l.optimum_mm_s = (l.optimum_mm_s.0.max(hi), l.optimum_mm_s.1.min(lo));
        }
    }
    Ok(out)
}
