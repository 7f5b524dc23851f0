//! The machine's limits hold in every cycle: random NURBS and line programs are planned
//! and stepped through the interpolator's engine exactly as a run steps them, and the
//! set-points' own finite differences give path speed, acceleration and jerk, and the
//! chord error of each step (the sagitta of the circle through three set-points), which
//! must stay within the default machine's limits.

use interpolator::engine::{BlockSource, Engine, Limits, TickState};
use interpreter::blocks::{build, commands, plan};
use interpreter::program::interpret;
use proptest::prelude::*;
use shared::protocol::{BlockKind, CommandBlock};
use shared::Machine;
use std::collections::{HashMap, HashSet};

const PERIOD_NS: u64 = 1_000_000;
const T: f64 = 1e-3;

struct Slice(Vec<CommandBlock>, usize);
impl BlockSource for Slice {
    fn next_block(&mut self) -> Option<CommandBlock> {
        let b = self.0.get(self.1).copied();
        self.1 += usize::from(b.is_some());
        b
    }
}

/// One cycle as the test sees it: the set-point and the block it came from.
struct Cycle {
    p: [f64; 3],
    seq: u64,
}

fn step(text: &str, machine: &Machine) -> (Vec<CommandBlock>, Vec<Cycle>) {
    let program = interpret(text).unwrap_or_else(|e| panic!("{e:?}\n{text}"));
    // As the planner takes them: `G64 Q`'s runs merged or smoothed where that is quicker.
    let moves = interpreter::blocks::naive_cam::merge(program.moves, machine);
    let mut blocks = build(&moves, machine);
    plan(&mut blocks, machine, PERIOD_NS);
    step_blocks(commands(&blocks), machine)
}

/// [`step`] with every `G64 P` corner blended, whether the blend pays or not
/// (`blend::corners`; the planner keeps only those that pay, `blend::corners_on`): the
/// limits through every blend shape.
fn step_every_blend(text: &str, machine: &Machine) -> (Vec<CommandBlock>, Vec<Cycle>) {
    let program = interpret(text).unwrap_or_else(|e| panic!("{e:?}\n{text}"));
    let mut blocks = build(
        &interpreter::blocks::blend::corners(&program.moves),
        machine,
    );
    plan(&mut blocks, machine, PERIOD_NS);
    step_blocks(commands(&blocks), machine)
}

/// Planned blocks stepped through the engine from the origin, every cycle kept.
fn step_blocks(blocks: Vec<CommandBlock>, machine: &Machine) -> (Vec<CommandBlock>, Vec<Cycle>) {
    let mut engine = Engine::new(Limits::new(machine, PERIOD_NS), [0.0; 3]);
    let mut src = Slice(blocks.clone(), 0);
    let mut out = vec![Cycle {
        p: [0.0; 3],
        seq: 0,
    }];
    for _ in 0..2_000_000 {
        let t = engine.tick(&mut src).unwrap();
        out.push(Cycle {
            p: t.pos_mm,
            seq: t.block_seq,
        });
        if t.state == TickState::Done {
            return (blocks, out);
        }
        assert_eq!(t.state, TickState::Running, "starved in a slice run");
    }
    panic!("never done")
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn norm(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The largest of each figure over the run, each against its limit (ratio).
#[derive(Debug, Default)]
struct Worst {
    speed: f64,
    acc: f64,
    jerk: f64,
    chord: f64,
    /// The largest of each axis's velocity, acceleration and jerk (the jerk away from
    /// kinks) against that axis's own limit.
    axis: f64,
    /// The cycle of the largest jerk.
    jerk_cycle: usize,
}

/// Checks every cycle; cycles within two of a junction whose tangent turns (a kink,
/// which no finite jerk can follow exactly) are left out of the jerk check only.
fn check(blocks: &[CommandBlock], cycles: &[Cycle], machine: &Machine) -> Worst {
    let kinks: HashSet<u64> = blocks
        .windows(2)
        .filter(|w| w[0].kind == BlockKind::Motion as u32 && w[1].kind == BlockKind::Motion as u32)
        .filter(|w| {
            let (_, u1) = shared::path::domain(&w[0]);
            let (v0, _) = shared::path::domain(&w[1]);
            // Tangents just inside the blocks: at a cusp the derivative itself vanishes.
            let (u0, _) = shared::path::domain(&w[0]);
            let (_, v1) = shared::path::domain(&w[1]);
            let a = shared::path::eval(&w[0], u1 - 1e-9 * (u1 - u0)).d1;
            let b = shared::path::eval(&w[1], v0 + 1e-9 * (v1 - v0)).d1;
            let cos = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (norm(a) * norm(b));
            cos.is_nan() || cos < 1.0 - 1e-12
        })
        .map(|w| w[1].seq)
        .collect();
    check_with_kinks(blocks, cycles, machine, &kinks)
}

/// [`check`] with the kinks given: the sequence numbers of the blocks after them.
fn check_with_kinks(
    blocks: &[CommandBlock],
    cycles: &[Cycle],
    machine: &Machine,
    kinks: &HashSet<u64>,
) -> Worst {
    // A cycle whose step (or one of the two before) crossed into a block after a kink.
    let near_kink = |i: usize| {
        (i.saturating_sub(3).max(1)..=i)
            .any(|k| (cycles[k - 1].seq + 1..=cycles[k].seq).any(|s| kinks.contains(&s)))
    };
    let feeds: HashMap<u64, f64> = blocks
        .iter()
        .map(|b| (b.seq, b.feed_mm_per_min / 60.0))
        .collect();
    let mut w = Worst::default();
    let a_max = machine.path_acc_mm_per_s2;
    let j_max = machine.path_jerk_mm_per_s3;
    let axes = machine.axes.as_array();
    // The largest ratio of a per-axis figure to that axis's limit.
    let per_axis = |v: [f64; 3], limit: &dyn Fn(&shared::machine::AxisLimits) -> f64| {
        (0..3).fold(0.0f64, |m, k| m.max(v[k].abs() / limit(&axes[k])))
    };
    for i in 1..cycles.len() {
        let d1 = sub(cycles[i].p, cycles[i - 1].p);
        w.axis = w.axis.max(per_axis(d1.map(|x| x / T * 60.0), &|a| {
            a.max_vel_mm_per_min
        }));
        // The speed limit is the feed of the block the step ends in or began in.
        let feed = [cycles[i].seq, cycles[i - 1].seq]
            .iter()
            .filter_map(|s| feeds.get(s).copied())
            .fold(0.0, f64::max);
        if feed > 0.0 {
            w.speed = w.speed.max(norm(d1) / T / feed);
        }
        if i >= 2 {
            let d0 = sub(cycles[i - 1].p, cycles[i - 2].p);
            let acc = norm(sub(d1, d0)) / (T * T);
            w.acc = w.acc.max(acc / a_max);
            let acc_v = sub(d1, d0).map(|x| x / (T * T));
            w.axis = w.axis.max(per_axis(acc_v, &|a| a.max_acc_mm_per_s2));
            // Chord error: sagitta of the circle through the three set-points.
            let (a, b, c) = (norm(d0), norm(d1), norm(sub(cycles[i].p, cycles[i - 2].p)));
            let area2 = {
                let x = d0;
                let y = d1;
                norm([
                    x[1] * y[2] - x[2] * y[1],
                    x[2] * y[0] - x[0] * y[2],
                    x[0] * y[1] - x[1] * y[0],
                ])
            };
            if area2 > 1e-15 && !near_kink(i) {
                let r = a * b * c / (2.0 * area2);
                let chord = a.max(b);
                let sag = r - (r * r - chord * chord / 4.0).max(0.0).sqrt();
                w.chord = w.chord.max(sag / machine.chord_tolerance_mm);
            }
            if i >= 3 && !near_kink(i) {
                let dm = sub(cycles[i - 2].p, cycles[i - 3].p);
                let jv = sub(sub(d1, d0), sub(d0, dm)).map(|x| x / (T * T * T));
                let j = norm(jv);
                w.axis = w.axis.max(per_axis(jv, &|a| a.max_jerk_mm_per_s3));
                if j / j_max > w.jerk {
                    w.jerk = j / j_max;
                    w.jerk_cycle = i;
                }
            }
        }
    }
    w
}

fn fmt(v: f64) -> String {
    format!("{v:.4}")
}

/// A walk from the origin along legs `(length, turn from the last leg, weight)`: the
/// control polygon of a random curve, or the vertices of a random chain, weight 1 at the
/// start.
fn walk(legs: impl IntoIterator<Item = (f64, f64, f64)>) -> Vec<(f64, f64, f64)> {
    let mut pts = vec![(0.0, 0.0, 1.0)];
    let (mut x, mut y, mut heading) = (0.0f64, 0.0f64, 0.0f64);
    for (len, turn, w) in legs {
        heading += turn;
        x += len * heading.cos();
        y += len * heading.sin();
        pts.push((x, y, w));
    }
    pts
}

/// A chain of `G1` lines through the walk's points after the first.
fn chain_program(pts: &[(f64, f64, f64)], feed: f64) -> String {
    let mut text = format!("G21\nG1 F{feed}\n");
    for (x, y, _) in &pts[1..] {
        text += &format!("X{} Y{}\n", fmt(*x), fmt(*y));
    }
    text + "M2\n"
}

/// A LinuxCNC G5.2 NURBS through random control points with random weights and order,
/// after a rapid to its start.
fn nurbs_program(order: usize, pts: &[(f64, f64, f64)], feed: f64) -> String {
    let mut s = format!(
        "G21 G17\nG0 X{} Y{}\nG1 F{feed}\n",
        fmt(pts[0].0),
        fmt(pts[0].1)
    );
    s += &format!("G5.2 P{} L{order}\n", fmt(pts[0].2));
    for (x, y, w) in &pts[1..] {
        s += &format!("X{} Y{} P{}\n", fmt(*x), fmt(*y), fmt(*w));
    }
    s += "G5.3\nM2\n";
    s
}

proptest! {
    // A fixed seed, so CI runs the same 32 curves every time (raise `cases` and drop the
    // seed to explore further). A curve whose control polygon folds back nearly onto
    // itself (a turn of a few µm radius inside a span) once reached 5 times the jerk
    // limit: the planner's samples missed so narrow a peak of dk/ds (fixed: it searches
    // between them, `blocks::golden_max`; see `a_fold_of_the_control_polygon_keeps_the_jerk`).
    // Quadratic curves (L3), whose curvature jumps at every knot, once reached 1.01–1.19
    // times the jerk limit there: the junction speed gave the jump the whole jerk, as if
    // the profile's own jerk along the path were zero (fixed: `blocks::JUMP_SHARE`; see
    // `search_random_programs_for_broken_limits`).
    #![proptest_config(ProptestConfig {
        cases: 32,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed_0007),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_nurbs_keep_every_limit(
        order in 3usize..=6,
        // The control polygon as a walk: leg length, turn from the last leg, weight.
        legs in prop::collection::vec((1.0f64..25.0, -2.0f64..2.0, 0.5f64..2.0), 6..11),
        feed in prop::sample::select(vec![600.0, 3000.0, 6000.0]),
    ) {
        // No leg turns back by more than about 115° on the last: a curve that nearly
        // reverses stops and turns in a spot shorter than the planner's sampling of the
        // span sees (a known gap: the cap then misses the curvature peak).
        let pts = walk(legs);
        let machine = Machine::default();
        let text = nurbs_program(order, &pts, feed);
        let (blocks, cycles) = step(&text, &machine);
        let w = check(&blocks, &cycles, &machine);
        prop_assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}\n{text}");
        prop_assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}\n{text}");
        prop_assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?}\n{text}");
        prop_assert!(w.chord <= 1.0 + 1e-3, "chord {w:?}\n{text}");
    }

}

proptest! {
    // A fixed seed, so CI runs the same 32 chains every time. Kinks closer together than
    // two steps once reached up to 2.5 times the acceleration limit (fixed: see
    // `chains_that_once_broke_a_limit`). A kink passed while the profile accelerated at
    // the full limit along the path once added its direction change to it (1.03–1.05
    // times the limit at a 0.7° kink at F6000; fixed: `blocks::KINK_SHARE`).
    #![proptest_config(ProptestConfig {
        cases: 32,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed_0006),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_line_chains_keep_speed_acceleration_and_chord(
        steps in prop::collection::vec((0.01f64..5.0, -0.3f64..0.3), 5..60),
        feed in prop::sample::select(vec![600.0, 3000.0, 6000.0]),
    ) {
        // A polyline turning by small random angles (a CAM chain): tangent kinks at
        // every vertex, so jerk is not checked next to them.
        let machine = Machine::default();
        let text = chain_program(&walk(steps.iter().map(|&(len, turn)| (len, turn, 1.0))), feed);
        let (blocks, cycles) = step(&text, &machine);
        let w = check(&blocks, &cycles, &machine);
        prop_assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}\n{text}");
        prop_assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}\n{text}");
        prop_assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?}\n{text}");
    }
}

/// A random control polygon that folds back on itself: its curvature rate peaks in a few
/// µm of a 9 mm span, between the planner's samples (5.0 times the jerk limit before
/// they were searched between).
#[test]
fn a_fold_of_the_control_polygon_keeps_the_jerk() {
    let text = "G21 G17\nG0 X0 Y0\nG1 F600\nG5.2 P1.0000 L6\nX1.0000 Y0.0000 P0.5000\n\
        X2.0000 Y0.0000 P1.4934\nX16.4474 Y0.0000 P1.7151\nX17.2415 Y-0.6078 P0.7466\n\
        X16.8422 Y-2.0753 P0.5734\nX-0.0427 Y7.9946 P0.9017\nX-0.9016 Y8.5068 P0.5000\n\
        X-1.7604 Y9.0190 P0.5000\nG5.3\nM2\n";
    let machine = Machine::default();
    let (blocks, cycles) = step(text, &machine);
    let w = check(&blocks, &cycles, &machine);
    assert!(w.jerk <= 1.0 + 1e-2, "{w:?}");
    assert!(w.acc <= 1.0 + 1e-3 && w.speed <= 1.0 + 1e-6, "{w:?}");
}

/// Junctions passed at speed where the tool point's velocity per contact speed steps
/// (beyond the differences' noise, about 1e-7 of it): the sequence numbers after them.
fn tool_path_kinks(blocks: &[CommandBlock]) -> HashSet<u64> {
    blocks
        .windows(2)
        .filter(|w| w[0].is_surface() && w[1].is_surface() && w[0].end_feed_mm_per_min > 0.0)
        .filter(|w| {
            let (a, b) = (
                shared::path::tool_rate(&w[0], 1.0),
                shared::path::tool_rate(&w[1], 0.0),
            );
            norm(sub(a, b)) > 1e-5 * norm(a).max(norm(b))
        })
        .map(|w| w[1].seq)
        .collect()
}

/// The STEP-NC example parts (seed 000): every limit holds in every cycle of the tool
/// reference point's path as the engine steps it, the jerk away from its kinks. Where
/// passes cross the knot lines of a p = 2 surface, which is only C¹, the ball's centre
/// `M = C + R·n` has a kink: the normal turns at a rate that jumps there, so `M'` jumps
/// in direction and length (within the tangent plane) at any contact speed but zero. As
/// at a polyline's kinks, no finite jerk can follow it: the planner passes it with a
/// velocity step of at most one period's share of the acceleration, and the jerk is
/// checked everywhere else. The p = 3 part (C² surface) has no such kinks, and none is
/// left out there.
#[test]
fn surface_parts_keep_every_limit_away_from_tool_path_kinks() {
    let machine = Machine::default();
    let examples = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    for (name, kinked) in [
        ("seed-surface.stp", true),
        ("seed-surface-planecc.stp", true),
        ("torus-patch.stp", false),
        ("cubic-wave.stp", false),
        // A T-spline is C² across its patches as a bicubic NURBS is.
        ("tspline-bump.stp", false),
    ] {
        let text = std::fs::read_to_string(examples.join(name)).unwrap();
        let (blocks, _) =
            interpreter::surface_blocks::part_blocks(&text, &machine, PERIOD_NS).unwrap();
        let (blocks, cycles) = step_blocks(blocks, &machine);
        let kinks = tool_path_kinks(&blocks);
        let surface_blocks = blocks.iter().filter(|b| b.is_surface()).count();
        assert_eq!(!kinks.is_empty(), kinked, "{name}: {} kinks", kinks.len());
        let w = check_with_kinks(&blocks, &cycles, &machine, &kinks);
        println!(
            "{name}: {} cycles, {surface_blocks} surface blocks, {} tool path kinks; {w:?}",
            cycles.len(),
            kinks.len(),
        );
        // The speed is the contact point's (the feed), which the tool point's exceeds
        // on convex sections: not checked here.
        assert!(w.acc <= 1.0 + 1e-3, "{name}: acceleration {w:?}");
        // (Landings on the exact stops at the passes' ends once reached 1.033 times the
        // jerk limit here: the engine dropped what was left of the braking, up to 70
        // mm/s², within one period, and the next move started in the next cycle.)
        assert!(w.jerk <= 1.0 + 1e-2, "{name}: jerk {w:?}");
        assert!(w.chord <= 1.0 + 1e-3, "{name}: chord {w:?}");
    }
}

/// LinuxCNC's butterfly (`g5_butterfly-xy.ngc`) with its cutting feed `F300` replaced,
/// planned and stepped through the engine with the default machine.
struct Butterfly {
    text: String,
    machine: Machine,
    blocks: Vec<CommandBlock>,
    est: interpreter::estimate::Estimate,
}

impl Butterfly {
    fn at(feed_word: &str) -> Self {
        let peers =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../tests/peers/linuxcnc");
        let text = std::fs::read_to_string(peers.join("g5_butterfly-xy.ngc"))
            .unwrap()
            .replace("F300", feed_word);
        let machine = Machine::default();
        let program = interpret(&text).unwrap();
        let mut blocks = build(&program.moves, &machine);
        plan(&mut blocks, &machine, PERIOD_NS);
        let blocks = commands(&blocks);
        let est = interpreter::estimate::estimate(&blocks, &machine, PERIOD_NS).unwrap();
        Butterfly {
            text,
            machine,
            blocks,
            est,
        }
    }

    /// Is source line `line` one of the NURBS (`G5.2`) moves?
    fn is_nurbs_line(&self, line: u32) -> bool {
        self.text
            .lines()
            .nth(line as usize - 1)
            .is_some_and(|l| l.contains("G5.2"))
    }

    /// Path length and time over the NURBS moves.
    fn nurbs_length_and_time(&self) -> (f64, f64) {
        self.est
            .moves
            .iter()
            .filter(|m| self.is_nurbs_line(m.line))
            .fold((0.0, 0.0), |(l, t), m| (l + m.length_mm, t + m.time_s))
    }
}

/// The feed figure: LinuxCNC's butterfly at F600 with the default machine, average
/// feed over the NURBS moves, from the engine's own per-line time (what `cnc check
/// --estimate` prints). Printed with `--nocapture`.
#[test]
fn butterfly_at_f600_reaches_99_percent_of_the_feed() {
    let run = Butterfly::at("F600");
    let (len, time) = run.nurbs_length_and_time();
    let avg = len / time * 60.0;
    println!(
        "butterfly F600: {len:.2} mm of NURBS in {time:.3} s: average {avg:.1} mm/min ({:.2} %)",
        avg / 6.0
    );
    assert!(avg >= 0.99 * 600.0, "average feed {avg}");
}

/// The F6000 figure: the butterfly's NURBS at F6000 take their time against a
/// lower bound from the limits alone, `∫ ds / v_max(s)` with `v_max` the lowest of the
/// feed, the centripetal limit `√(A·ρ)` under the whole path acceleration, the chord
/// tolerance at this period, and each axis's velocity along the tangent (it leaves out
/// every speed change, so no profile can beat it). A time below it would mean a limit
/// broken.
#[test]
fn butterfly_at_f6000_against_the_lower_bound_from_the_limits() {
    let run = Butterfly::at("F6000");
    let (len, time) = run.nurbs_length_and_time();
    let (machine, blocks) = (&run.machine, &run.blocks);
    let nurbs_line = |line: u32| run.is_nurbs_line(line);
    let axes = machine.axes.as_array();
    let tol = machine.chord_tolerance_mm;
    let (mut bound, mut bound_len) = (0.0, 0.0);
    for b in blocks
        .iter()
        .filter(|b| b.kind == BlockKind::Motion as u32 && nurbs_line(b.source_line))
    {
        let (u0, u1) = shared::path::domain(b);
        let n = 4000;
        let h = (u1 - u0) / n as f64;
        for i in 0..n {
            let e = shared::path::eval(b, u0 + (i as f64 + 0.5) * h);
            let speed = norm(e.d1);
            let ds = speed * h;
            if ds <= 0.0 {
                continue;
            }
            let c = [
                e.d1[1] * e.d2[2] - e.d1[2] * e.d2[1],
                e.d1[2] * e.d2[0] - e.d1[0] * e.d2[2],
                e.d1[0] * e.d2[1] - e.d1[1] * e.d2[0],
            ];
            let rho = speed.powi(3) / norm(c);
            let mut v = 6000.0_f64.min(machine.max_feed_mm_per_min) / 60.0;
            v = v.min((machine.path_acc_mm_per_s2 * rho).sqrt());
            v = v.min(2.0 * (2.0 * rho * tol - tol * tol).max(0.0).sqrt() / T);
            for (k, ax) in axes.iter().enumerate() {
                let t = (e.d1[k] / speed).abs();
                if t > 0.0 {
                    v = v.min(ax.max_vel_mm_per_min / 60.0 / t);
                }
            }
            bound += ds / v;
            bound_len += ds;
        }
    }
    // The same integral over the planner's own per-block speed caps (which keep half
    // the path acceleration and jerk for the normal direction, and the jerk of the
    // curvature's change): how much of the gap the caps make, and how much the speed
    // changes between them.
    let capped: f64 = blocks
        .iter()
        .filter(|b| b.kind == BlockKind::Motion as u32 && nurbs_line(b.source_line))
        .map(|b| b.length_mm / (b.feed_mm_per_min / 60.0))
        .sum();
    println!(
        "butterfly F6000: {len:.2} mm of NURBS in {time:.3} s (average {:.0} mm/min); lower bound from the limits {bound:.3} s over {bound_len:.2} mm: {:.2} times the bound; at the planner's block caps without speed changes {capped:.3} s",
        len / time * 60.0,
        time / bound
    );
    assert!((len - bound_len).abs() < 1e-3 * len, "{len} vs {bound_len}");
    assert!(time >= bound, "{time} s beats the lower bound {bound} s");
}

fn dist_to_polyline(p: [f64; 3], pts: &[[f64; 3]]) -> f64 {
    pts.windows(2)
        .map(|w| {
            let d = sub(w[1], w[0]);
            let dd = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
            let q = sub(p, w[0]);
            let s = ((q[0] * d[0] + q[1] * d[1] + q[2] * d[2]) / dd).clamp(0.0, 1.0);
            norm(sub(q, d.map(|x| x * s)))
        })
        .fold(f64::INFINITY, f64::min)
}

/// CAM-like polylines: a zig-zag raster with 90° corners (40 mm passes, 1 mm apart)
/// and a 20 mm circle as 100 chords (3.6° turns), from the origin.
fn cam_polylines() -> Vec<(&'static str, Vec<[f64; 3]>)> {
    let mut zigzag = vec![[0.0; 3]];
    for k in 0..10 {
        let y = k as f64;
        let x = if k % 2 == 0 { 40.0 } else { 0.0 };
        zigzag.push([x, y, 0.0]);
        zigzag.push([x, y + 1.0, 0.0]);
    }
    let circle: Vec<[f64; 3]> = (0..=100)
        .map(|i| {
            let a = 2.0 * std::f64::consts::PI * i as f64 / 100.0;
            [10.0 * a.sin(), 10.0 - 10.0 * a.cos(), 0.0]
        })
        .collect();
    vec![("zig-zag", zigzag), ("circle", circle)]
}

fn polyline_program(mode: &str, feed: f64, pts: &[[f64; 3]]) -> String {
    let mut text = format!("G21 {mode}\nG1 F{feed}\n");
    for p in &pts[1..] {
        text += &format!("X{} Y{} Z{}\n", fmt(p[0]), fmt(p[1]), fmt(p[2]));
    }
    text + "M2\n"
}

/// `G64 P` blends every corner of a CAM polyline: speed, acceleration, jerk (now also
/// at the corners, which are smooth) and chord stay within the limits in every cycle,
/// and every set-point stays within the tolerance (plus the chord tolerance) of the
/// programmed polyline. The times against `G61` are printed with `--nocapture`.
#[test]
fn blended_corners_keep_every_limit_and_the_tolerance() {
    let machine = Machine::default();
    for (name, pts) in cam_polylines() {
        let pts: Vec<[f64; 3]> = pts
            .iter()
            .map(|p| p.map(|x| fmt(x).parse().unwrap()))
            .collect();
        for feed in [3000.0, 6000.0] {
            let (_, exact) = step(&polyline_program("G61", feed, &pts), &machine);
            for tol in [0.01, 0.1] {
                let text = polyline_program(&format!("G64 P{tol}"), feed, &pts);
                let (blocks, cycles) = step_every_blend(&text, &machine);
                let blends = blocks.iter().filter(|b| b.degree == 5).count();
                assert!(blends >= pts.len() - 2, "{name}: {blends} blends");
                let w = check(&blocks, &cycles, &machine);
                assert!(w.speed <= 1.0 + 1e-6, "{name} P{tol} F{feed}: speed {w:?}");
                assert!(
                    w.acc <= 1.0 + 1e-3,
                    "{name} P{tol} F{feed}: acceleration {w:?}"
                );
                assert!(w.jerk <= 1.0 + 1e-2, "{name} P{tol} F{feed}: jerk {w:?}");
                assert!(w.chord <= 1.0 + 1e-3, "{name} P{tol} F{feed}: chord {w:?}");
                let off = cycles
                    .iter()
                    .map(|c| dist_to_polyline(c.p, &pts))
                    .fold(0.0, f64::max);
                assert!(
                    off <= tol + machine.chord_tolerance_mm,
                    "{name} P{tol} F{feed}: {off} mm off the polyline"
                );
                println!(
                    "{name} F{feed}: G61 {:.3} s, G64 P{tol} {:.3} s; {off:.5} mm off the polyline at most; {w:?}",
                    exact.len() as f64 * T,
                    cycles.len() as f64 * T
                );
            }
        }
    }
}

proptest! {
    // A fixed seed, so CI runs the same 32 chains every time. Speed, acceleration, jerk
    // (also through the blended corners, which are smooth) and the tolerance hold as in
    // the other tests. (These chains once found the engine up to 3.6 % over a line's
    // feed: see `chains_that_once_broke_a_limit`. 900 unseeded cases found no
    // excess over 1e-6 since.)
    #![proptest_config(ProptestConfig {
        cases: 32,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed_0064),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_blended_line_chains_keep_every_limit(
        steps in prop::collection::vec((0.2f64..5.0, -2.0f64..2.0, -0.5f64..0.5), 5..40),
        feed in prop::sample::select(vec![600.0, 3000.0, 6000.0]),
        tol in prop::sample::select(vec![0.005, 0.05]),
    ) {
        // A 3-D polyline with turns of up to about 115°, blended under G64 P. Legs of
        // 0.2 mm or more: on shorter ones a step at F6000 crosses several blocks, and
        // the speed of a step is judged against the feeds of its first and last block
        // only (0.01 mm legs reach 1.00014 times that bound through the higher feed of a
        // block in between).
        let machine = Machine::default();
        let mut pts = vec![[0.0f64; 3]];
        let (mut heading, mut pitch) = (0.0f64, 0.0f64);
        for (len, turn, climb) in &steps {
            heading += turn;
            pitch = (pitch + climb).clamp(-1.0, 1.0);
            let last = pts[pts.len() - 1];
            let p = [
                last[0] + len * pitch.cos() * heading.cos(),
                last[1] + len * pitch.cos() * heading.sin(),
                last[2] + len * pitch.sin(),
            ];
            pts.push(p.map(|x| fmt(x).parse().unwrap()));
        }
        let text = polyline_program(&format!("G64 P{tol}"), feed, &pts);
        let (blocks, cycles) = step(&text, &machine);
        let w = check(&blocks, &cycles, &machine);
        prop_assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}\n{text}");
        prop_assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}\n{text}");
        prop_assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?}\n{text}");
        let off = cycles.iter().map(|c| dist_to_polyline(c.p, &pts)).fold(0.0, f64::max);
        prop_assert!(off <= tol + machine.chord_tolerance_mm, "{off} mm off\n{text}");
    }
}

/// Blended chains the random search found over their feed, each through a fault of the
/// engine's switch search, now kept to it:
/// * accelerating on a line towards a blend whose end speed could no longer be kept under
///   the blend's gentler jerk, the engine braked for that lost limit and never for the
///   line's own feed, which a limit lost later in the cycle would have kept (0.8 % over
///   at F3000 on the 3.7 mm line);
/// * a step leaving a blend for a faster line judged the feed only where it ended, in the
///   line: the speed rose over the blend's feed inside it and came back by its end
///   (0.02 % over);
/// * a step crossing a short line into the next blend took the line's feed, not the
///   blend's, for the rest of the cycle (0.01 % over).
///
/// And a line chain: a kink's junction speed and an exact stop 0.6 mm after it were both
/// lost at one moment of a cycle, and the switch search took turns between their brakings
/// until its rounds ran out, leaving the softer one: the stop was reached at 2.5 mm/s
/// (1.2 times the acceleration limit in one cycle, and a jump in speed). And kinks closer
/// together than two steps, each planned for its own turn alone (see
/// `blocks::CloseKinks`).
#[test]
fn chains_that_once_broke_a_limit() {
    let machine = Machine::default();
    for text in [
        "G21 G64 P0.005\nG1 F3000\nX0.1943 Z-0.0473\nX0.3458 Z-0.1778\n\
         X2.1958 Y1.3697 Z-3.2939\nX2.2826 Y1.434 Z-3.4622\nM2\n",
        "G21 G64 P0.005\nG1 F3000\nX0.1881 Y0.0000 Z0.0681\nX0.3662 Y0.0000 Z0.1591\n\
         X0.5378 Y0.0000 Z0.2619\nX0.7098 Y0.0000 Z0.3640\nX0.7818 Y0.1577 Z0.4637\n\
         X0.8607 Y0.3306 Z0.5260\nX-0.8750 Y0.9277 Z1.9542\nX-2.4328 Y2.5787 Z2.5101\n\
         X-2.5674 Y2.4847 Z2.6244\nM2\n",
        "G21 G64 P0.05\nG1 F6000\nX1.8410 Y0.0000 Z-0.4254\nX0.4834 Y-3.1265 Z-2.8258\n\
         X-0.9333 Y-6.3892 Z-4.3006\nX-1.0692 Y-6.7022 Z-4.4421\nX-1.9933 Y-6.3385 Z-5.5279\n\
         X-4.1296 Y-4.7946 Z-9.0868\nX-3.5938 Y-3.1439 Z-11.4301\nX-3.0318 Y-2.4684 Z-11.9471\n\
         X-2.2109 Y0.5552 Z-12.2872\nM2\n",
    ] {
        let (blocks, cycles) = step(text, &machine);
        let w = check(&blocks, &cycles, &machine);
        assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}\n{text}");
        assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}\n{text}");
        assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?}\n{text}");
    }
}

/// Junctions that took the whole limit for themselves while the profile along the path
/// took its own, found by `search_random_programs_for_broken_limits` (600 cases, seed 7)
/// before the junction shares (`blocks::KINK_SHARE`, `blocks::JUMP_SHARE`):
/// * a quadratic curve (L3), whose curvature jumps at every knot: 1.06 times the jerk
///   limit;
/// * a CAM chain at F6000 whose kinks were passed while the speed still rose: 1.05 times
///   the acceleration limit.
#[test]
fn junctions_leave_the_profile_its_share() {
    let machine = Machine::default();
    let quadratic = "G21 G17\nG0 X0.0000 Y0.0000\nG1 F3000\nG5.2 P1.0000 L3\n\
        X-1.1753 Y-6.0790 P1.9620\nX8.5117 Y-14.4551 P1.3739\nX20.9248 Y-26.9999 P1.5474\n\
        X33.7120 Y-30.9707 P1.3784\nX44.0931 Y-39.7382 P0.9880\nX47.6650 Y-43.8460 P1.3624\n\
        G5.3\nM2\n";
    let chain = "G21\nG1 F6000\nX1.1766 Y0.3209\nX5.9194 Y1.7297\nX10.2022 Y3.0006\n\
        X13.9088 Y3.4524\nX17.9734 Y5.0886\nX22.2038 Y6.3256\nX22.5901 Y6.5778\n\
        X22.6212 Y6.6049\nX25.5627 Y8.0224\nX27.2068 Y9.4514\nX28.6080 Y11.2476\n\
        X31.6455 Y14.7369\nX34.7548 Y18.2709\nX36.6256 Y20.0319\nX37.2274 Y20.8004\n\
        X37.4139 Y21.0686\nX38.1717 Y23.4025\nX38.8420 Y25.9389\nX40.9112 Y30.0606\n\
        X41.7833 Y34.4396\nX42.7690 Y36.3842\nX44.1468 Y39.7658\nX45.3310 Y41.2781\n\
        X47.3274 Y44.7181\nX47.4627 Y45.0651\nX48.3813 Y47.6892\nX49.4182 Y50.6809\n\
        X51.8245 Y54.5704\nX52.0637 Y55.3951\nM2\n";
    for text in [quadratic, chain] {
        let (blocks, cycles) = step(text, &machine);
        let w = check(&blocks, &cycles, &machine);
        assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}\n{text}");
        assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}\n{text}");
        assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?}\n{text}");
        assert!(w.chord <= 1.0 + 1e-3, "chord {w:?}\n{text}");
    }
}

/// A machine whose X axis is weaker than the path: its own limits bind along X. A
/// junction's share taken of the path's limits alone let the velocity step of a kink,
/// or the acceleration step of a curvature jump, fall mostly on X: 1.59 times X's
/// limits on a quadratic curve, 2.9 times on a CAM chain (300 random cases of each,
/// seed 7, about a quarter of them over). Now each axis's share is taken too.
#[test]
fn junctions_keep_each_axis_within_its_own_limits() {
    let machine = weak_x_machine();
    let quadratic = "G21 G17\nG0 X0.0000 Y0.0000\nG1 F6000\nG5.2 P1.0000 L3\n\
        X-0.3185 Y12.4071 P0.5770\nX1.1800 Y15.4795 P0.6820\nX21.7817 Y20.7683 P1.9069\n\
        X32.8243 Y3.5489 P1.2883\nX38.6931 Y-5.4037 P1.8284\nX49.1277 Y-13.9868 P1.5148\n\
        X68.3301 Y0.5884 P1.7342\nX76.3312 Y-0.3934 P0.6480\nX86.2960 Y-13.2641 P0.9760\n\
        X87.5091 Y-20.3717 P0.7785\nG5.3\nM2\n";
    // Along Y, zig-zagging a little in X: every kink's velocity step is along X.
    let mut chain = String::from("G21\nG1 F3000\n");
    for i in 1..40 {
        let x = if i % 2 == 0 { 0.0 } else { 0.05 };
        chain += &format!("X{x:.4} Y{:.4}\n", i as f64 * 1.5);
    }
    chain += "M2\n";
    for text in [quadratic, chain.as_str()] {
        let (blocks, cycles) = step(text, &machine);
        let w = check(&blocks, &cycles, &machine);
        assert!(w.axis <= 1.0 + 1e-3, "axis {w:?}\n{text}");
        assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}\n{text}");
        assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}\n{text}");
        assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?}\n{text}");
    }
}

/// The machine of `junctions_keep_each_axis_within_its_own_limits`: an X axis weaker than
/// the path.
fn weak_x_machine() -> Machine {
    let mut machine = Machine::default();
    machine.axes.x.max_vel_mm_per_min = 2400.0;
    machine.axes.x.max_acc_mm_per_s2 = 600.0;
    machine.axes.x.max_jerk_mm_per_s3 = 15_000.0;
    machine
}

proptest! {
    // A fixed seed, so CI runs the same 32 programs every time: random NURBS of order 3
    // to 6 and CAM chains on a machine whose X axis is weaker than the path, every axis
    // held to its own limits (before the per-axis junction shares, a quarter of such
    // programs broke X's, up to 2.9 times).
    #![proptest_config(ProptestConfig {
        cases: 32,
        rng_seed: proptest::test_runner::RngSeed::Fixed(0x5eed_00a5),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    #[test]
    fn random_programs_keep_a_weak_axis_within_its_limits(
        order in 3usize..=6,
        legs in prop::collection::vec((0.05f64..25.0, -2.0f64..2.0, 0.5f64..2.0), 6..30),
        feed in prop::sample::select(vec![600.0, 3000.0, 6000.0]),
        nurbs in any::<bool>(),
    ) {
        let machine = weak_x_machine();
        // Chains turn a little (a CAM polyline), curves' polygons a lot.
        let bend = if nurbs { 1.0 } else { 0.15 };
        let pts = walk(legs.iter().map(|&(len, turn, w)| (len, bend * turn, w)));
        let text = if nurbs {
            nurbs_program(order, &pts[..pts.len().min(11)], feed)
        } else {
            chain_program(&pts, feed)
        };
        let (blocks, cycles) = step(&text, &machine);
        let w = check(&blocks, &cycles, &machine);
        prop_assert!(w.axis <= 1.0 + 1e-2, "axis {w:?}\n{text}");
        prop_assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}\n{text}");
        prop_assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}\n{text}");
        prop_assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?}\n{text}");
    }
}

/// Two quadratic curves the random search (`search_random_programs_for_broken_limits`,
/// seed 7) found breaking a weak X axis once curves were split where their speed limit
/// changes: blocks of one curve then differ in jerk, and the engine eased a rising
/// speed off under the jerk of the block it was in, not the lower one of the block
/// beyond. The first went 1.07 % over X's velocity into a block of half the jerk (the
/// engine refused the step: `StepTooLarge`); in the second the end speed of such a block
/// was dropped from the look-ahead as if the blocks before could brake for it, and X's
/// jerk reached 1.75 times its limit.
#[test]
fn a_weak_axis_keeps_its_limits_where_a_curve_s_blocks_differ_in_jerk() {
    let programs = [
        "G21 G17\nG0 X0.0000 Y0.0000\nG1 F3000\nG5.2 P1.0000 L3\n\
         X-0.4904 Y3.3542 P1.6571\nX-17.2985 Y-2.8076 P1.4153\nX-18.6564 Y-21.6922 P0.9397\n\
         X-10.5138 Y-25.2817 P1.8559\nX6.3025 Y-35.6703 P0.7369\nX10.0737 Y-31.4768 P1.9130\n\
         X7.5989 Y-22.0503 P1.9049\nX-4.2770 Y-0.1283 P1.2695\nX11.6310 Y3.6515 P1.8747\n\
         X15.2712 Y-15.6448 P0.9763\nG5.3\nM2\n",
        "G21 G17\nG0 X0.0000 Y0.0000\nG1 F6000\nG5.2 P1.0000 L3\n\
         X1.6270 Y-2.4564 P1.7858\nX-18.4501 Y-7.5122 P1.6443\nX-29.0023 Y-26.5901 P1.4132\n\
         X-9.6571 Y-28.5149 P1.0944\nX-20.1033 Y-47.3921 P1.1471\nX-21.2807 Y-47.3459 P1.0028\n\
         X-20.4465 Y-62.8096 P1.2763\nX-25.8438 Y-79.4138 P1.6587\nX-31.9479 Y-94.8407 P0.6019\n\
         G5.3\nM2\n",
    ];
    let machine = weak_x_machine();
    for text in programs {
        let (blocks, cycles) = step(text, &machine);
        let w = check(&blocks, &cycles, &machine);
        // As the search judges a case.
        assert!(w.axis <= 1.0 + 1e-2, "{w:?}\n{text}");
        assert!(
            w.acc <= 1.0 + 1e-3 && w.speed <= 1.0 + 1e-6,
            "{w:?}\n{text}"
        );
    }
}

/// Random curves (`search_random_programs_for_broken_limits`) that broke limits once the
/// curvature took up to 0.9 of each acceleration where a curve's speed reaches its cap:
/// neighbouring blocks of one curve then differ up to sixfold in their tangential
/// limits. The first two broke them on the engine before `Engine::acc_ceiling`,
/// `Window::lowest` and `Engine::spare` (seed 7: 12 times the acceleration and 413 times
/// the jerk, a stop reached still fast; seed 11: 1.3 % over a block's feed); the third
/// (seed 5, weak X) on the planner's old floor under a block's tangential limits, a
/// twentieth of the path's, above what the curvature left the weak X (an X limit 1.08
/// times over).
#[test]
fn limits_hold_where_a_curve_s_blocks_differ_sixfold_in_their_limits() {
    let cases = [
        (
            "G21 G17\nG0 X0.0000 Y0.0000\nG1 F6000\nG5.2 P1.0000 L5\n\
             X-2.3386 Y6.3476 P0.9398\nX-5.8654 Y3.3681 P1.8918\nX6.3481 Y-3.7897 P1.5862\n\
             X16.8965 Y-8.8150 P1.8706\nX29.8602 Y-2.1246 P1.4522\nX29.2927 Y6.2773 P1.3470\n\
             X13.1278 Y19.4562 P1.7997\nX12.4259 Y20.5502 P1.3653\nX29.9258 Y23.2847 P1.8979\n\
             G5.3\nM2\n",
            Machine::default(),
        ),
        (
            "G21 G17\nG0 X0.0000 Y0.0000\nG1 F6000\nG5.2 P1.0000 L5\n\
             X10.4405 Y5.4089 P0.7215\nX3.3825 Y18.7263 P1.0106\nX12.3071 Y27.6621 P1.1889\n\
             X20.9384 Y11.7179 P0.9643\nX38.1360 Y6.5665 P1.9561\nX45.6845 Y2.6926 P1.9294\n\
             G5.3\nM2\n",
            Machine::default(),
        ),
        (
            "G21 G17\nG0 X0.0000 Y0.0000\nG1 F6000\nG5.2 P1.0000 L5\n\
             X5.7594 Y13.1912 P1.4697\nX3.4910 Y14.3158 P0.9777\nX-0.3102 Y12.5494 P1.1548\n\
             X-15.0334 Y22.6046 P0.9782\nX-15.2593 Y27.0411 P1.4148\nX2.3907 Y22.9922 P1.6480\n\
             G5.3\nM2\n",
            weak_x_machine(),
        ),
    ];
    for (text, machine) in cases {
        let (blocks, cycles) = step(text, &machine);
        let w = check(&blocks, &cycles, &machine);
        // As the search judges a case.
        assert!(w.axis <= 1.0 + 1e-2, "{w:?}\n{text}");
        assert!(
            w.acc <= 1.0 + 1e-3 && w.jerk <= 1.0 + 1e-2 && w.speed <= 1.0 + 1e-6,
            "{w:?}\n{text}"
        );
    }
}

/// A degree-5 curve whose control polygon nearly turns back (a near-cusp holds its last
/// span to 0.57 mm/s): its stop at the end once reached 1.19 times the jerk limit. The
/// span's length was measured 4.7e-5 mm long (the speed `|C'|` dips nearly to zero in
/// it, which 32 Gauss–Legendre pieces do not follow), so the braking still had that much
/// to go where the curve ended, and the engine dropped 59 mm/s² of deceleration in one
/// period (fixed: `shared::nurbs::arc_length` halves the pieces until they agree).
#[test]
fn a_near_cusp_span_lands_its_stop() {
    let text = "G21 G17\nG0 X0.0000 Y0.0000\nG1 F3000\nG5.2 P1.0000 L6\n\
        X21.0835 Y8.9963 P0.5964\nX23.0940 Y3.6389 P1.6911\nX36.8052 Y13.9383 P1.3610\n\
        X54.4620 Y-1.5084 P0.9276\nX54.6994 Y-2.5634 P1.6340\nX36.0415 Y-7.0921 P1.6229\n\
        X36.5474 Y-9.5268 P1.8650\nX54.0403 Y0.6353 P1.9294\nG5.3\nM2\n";
    let machine = Machine::default();
    let (blocks, cycles) = step(text, &machine);
    let w = check(&blocks, &cycles, &machine);
    assert!(w.jerk <= 1.0 + 1e-2, "{w:?}");
    assert!(w.acc <= 1.0 + 1e-3 && w.speed <= 1.0 + 1e-6, "{w:?}");
}

/// A larger random search than the fixed-seed tests above, for exploring: the worst
/// ratio of each figure to its limit, and how many cases broke one, over
/// `LIMITS_SEARCH_CASES` (default 300) random cases of each kind, from the seed
/// `LIMITS_SEARCH_SEED` (default 1). Printed, not asserted: run it with
/// `cargo test --release -p interpreter --test limits -- --ignored --nocapture search`.
#[test]
#[ignore]
fn search_random_programs_for_broken_limits() {
    let env = |name: &str, default: u64| {
        std::env::var(name)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let cases = env("LIMITS_SEARCH_CASES", 300);
    let mut state = env("LIMITS_SEARCH_SEED", 1).max(1);
    // xorshift64*: uniform in [lo, hi).
    let mut uniform = move |lo: f64, hi: f64| {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        let x = state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11;
        lo + (hi - lo) * (x as f64 / (1u64 << 53) as f64)
    };
    // The default machine, and one whose X axis is weaker than the path (its limits,
    // not the path's, bind along X).
    // (`LIMITS_SEARCH_LOOKAHEAD`: the engine's look-ahead, `lookahead_blocks`, of both
    // machines; the built-in's where not given.)
    let lookahead = env("LIMITS_SEARCH_LOOKAHEAD", 0) as u32;
    let with_lookahead = |mut m: Machine| {
        if lookahead > 0 {
            m.lookahead_blocks = lookahead;
        }
        m
    };
    let weak_x = with_lookahead(weak_x_machine());
    let feeds = [600.0, 3000.0, 6000.0];
    for (machine_name, machine, kind) in [
        ("default", with_lookahead(Machine::default()), "nurbs L3"),
        ("default", with_lookahead(Machine::default()), "nurbs L4-6"),
        ("default", with_lookahead(Machine::default()), "line chain"),
        ("weak X", weak_x.clone(), "nurbs L3"),
        ("weak X", weak_x.clone(), "nurbs L4-6"),
        ("weak X", weak_x, "line chain"),
    ] {
        let mut worst = Worst::default();
        let mut broken = 0;
        let mut worst_text = String::new();
        for _ in 0..cases {
            let feed = feeds[(uniform(0.0, 3.0) as usize).min(2)];
            let text = if kind.starts_with("nurbs") {
                let order = if kind == "nurbs L3" {
                    3
                } else {
                    4 + (uniform(0.0, 3.0) as usize).min(2)
                };
                let legs = 6 + uniform(0.0, 5.0) as usize;
                // Drawn in this order: turn, length, weight.
                let legs: Vec<_> = (0..legs)
                    .map(|_| {
                        let turn = uniform(-2.0, 2.0);
                        let len = uniform(1.0, 25.0);
                        (len, turn, uniform(0.5, 2.0))
                    })
                    .collect();
                nurbs_program(order, &walk(legs), feed)
            } else {
                let legs: Vec<_> = (0..(5 + uniform(0.0, 55.0) as usize))
                    .map(|_| {
                        let turn = uniform(-0.3, 0.3);
                        (uniform(0.01, 5.0), turn, 1.0)
                    })
                    .collect();
                chain_program(&walk(legs), feed)
            };
            let (blocks, cycles) = step(&text, &machine);
            let w = check(&blocks, &cycles, &machine);
            let over = w.speed > 1.0 + 1e-6
                || w.acc > 1.0 + 1e-3
                || w.jerk > 1.0 + 1e-2
                || w.chord > 1.0 + 1e-3
                || w.axis > 1.0 + 1e-2;
            broken += usize::from(over);
            if w.acc.max(w.jerk).max(w.axis) > worst.acc.max(worst.jerk).max(worst.axis) {
                worst_text = text.clone();
            }
            worst.axis = worst.axis.max(w.axis);
            worst.speed = worst.speed.max(w.speed);
            worst.acc = worst.acc.max(w.acc);
            worst.jerk = worst.jerk.max(w.jerk);
            worst.chord = worst.chord.max(w.chord);
        }
        println!(
            "{machine_name} machine, {kind}: {broken} of {cases} cases over a limit; worst {worst:?}"
        );
        if broken > 0 {
            println!("worst case:\n{worst_text}");
        }
    }
}

/// The seed's PLANE_CC part (`examples/seed-surface-planecc.stp`: its name and text) with
/// LinuxCNC's limits (`examples/machine-linuxcnc-sim.toml`).
fn planecc_on_linuxcnc_limits() -> (Machine, &'static str, String) {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let machine =
        shared::machine::load(Some(&root.join("examples/machine-linuxcnc-sim.toml"))).unwrap();
    let name = "seed-surface-planecc.stp";
    let text = std::fs::read_to_string(root.join("examples").join(name)).unwrap();
    (machine, name, text)
}

/// At a junction of surface blocks where the surface's curvature jumps, the tool point's
/// speed steps against the contact speed: `v·|m_b − m_a|` in one period, `m = dM/ds` of
/// the contact path. That step and each block's profile along the tool point's path
/// (`acc·|m|`) stay within the path acceleration together. LinuxCNC's limits on the
/// seed's PLANE_CC part once put 962 + 315 mm/s² on the tool point there (1.28 times the
/// limit; `blocks::surface_step_leaves`). `m` by central differences of 1e-7 in `t`
/// (tolerance 1e-6 relative).
#[test]
fn a_surface_junction_s_speed_step_leaves_the_profile_within_the_acceleration() {
    let (machine, name, text) = planecc_on_linuxcnc_limits();
    let opts = interpreter::program::Options::default();
    let blocks = interpreter::process::compile_source(name, &text, &opts, &machine, 1_000_000)
        .unwrap()
        .blocks;
    let mut steps = 0;
    for w in blocks.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        if !(a.is_surface() && b.is_surface()) || a.end_feed_mm_per_min <= 0.0 {
            continue;
        }
        let (ma, mb) = (
            shared::path::tool_rate(a, 1.0),
            shared::path::tool_rate(b, 0.0),
        );
        let v = a.end_feed_mm_per_min / 60.0;
        let step = v * shared::path::norm([mb[0] - ma[0], mb[1] - ma[1], mb[2] - ma[2]]) / 1e-3;
        if step > 1.0 {
            steps += 1;
        }
        for (blk, m) in [(a, ma), (b, mb)] {
            let total = blk.acc_mm_per_s2 * shared::path::norm(m) + step;
            assert!(
                total <= machine.path_acc_mm_per_s2 * (1.0 + 1e-6),
                "blocks {} and {}: {total} mm/s²",
                a.seq,
                b.seq
            );
        }
    }
    assert!(
        steps > 0,
        "no junction with a speed step: the test proves nothing"
    );
}

/// Inside a surface block the tool point's speed is `r·ṡ`, with `r` the ratio of its
/// speed to the contact speed `ṡ`, so its acceleration along its path is `r·s̈ + r'·ṡ²`:
/// the ratio's change adds to the profile's own. LinuxCNC's limits on the seed's PLANE_CC
/// part once put 1001.7 mm/s² on the tool point there, 1.0017 times the limit, inside a
/// pass planned at 964.8 mm/s² on the contact path (`blocks::shape` left `r'` out). The
/// whole part stepped through the engine, the set-points' second differences against
/// each limit away from the junctions' speed steps (tolerance 1e-4).
#[test]
fn the_tool_point_s_speed_ratio_changing_along_a_pass_stays_within_the_acceleration() {
    let (machine, _, text) = planecc_on_linuxcnc_limits();
    let (blocks, _) = interpreter::surface_blocks::part_blocks(&text, &machine, PERIOD_NS).unwrap();
    let (blocks, cycles) = step_blocks(blocks, &machine);
    let w = check_with_kinks(&blocks, &cycles, &machine, &tool_path_kinks(&blocks));
    assert!(w.acc <= 1.0 + 1e-4, "acceleration {w:?}");
}

/// A plan whose speeds brake across several blocks, into a block of far lower limits,
/// keeps its junction speeds through the engine. The random search's case below (seed 5,
/// weak X) was planned by a backward pass that let a block start above what it can brake
/// for within its own length, braking across up to 16 blocks (tried for the feed and not
/// kept). Every field stays within the caps and the machine. Before the engine kept each
/// block's entry by the block before it (`Engine::keep_chain`), the machine entered block
/// 17 at 2.50 mm/s where 1.18 is planned and X's jerk reached 1.65 times its limit: in
/// block 15 (acceleration 92.9 mm/s²) it slowed at about 47 mm/s² only and entered block
/// 16 (0.026 mm, 33.8 mm/s²) at 2.82 mm/s, where 1.77 was the most from which block 16
/// brakes to its end. The 1.18 had been judged from 1.08 mm back at 14.2 mm/s under the
/// lowest limits of the way (33.8 mm/s²), lost from first sight, and braked for at that.
/// (It needs blocks 26 to 40 raised too, which lowers the window's lowest jerk.) The
/// planned fields (seq, feed, start, end in mm/min; acc, jerk) overwrite the planner's on
/// the same blocks. Tolerance 1e-3 on each axis's limits, as the random search.
#[test]
fn a_plan_braking_across_blocks_into_weaker_ones_keeps_the_junction_speeds() {
    const PLAN: &str = "
    0 5.717953409656562e3 0e0 3.3025256496707393e3 1.4153518119257678e3 3.0287139868750404e4
    1 4.956691352096438e3 3.3025256496707393e3 1.8079591251441602e3 7.928316680210784e2 1.0180272321264725e4
    2 3.932593107398848e3 1.8079591251441602e3 1.5285681792439025e3 6.547213300655579e2 1.0537856547464888e4
    3 3.3014145153076724e3 1.5285681792439025e3 1.353400288312661e3 5.66707430890844e2 1.0866827298276967e4
    4 2.7137510547356596e3 1.353400288312661e3 1.2078985094802144e3 4.8214591884453523e2 1.1313056197983755e4
    5 2.1720725334935482e3 1.2078985094802144e3 1.1029734343858397e3 4.0128276465674196e2 1.195177202107432e4
    6 1.6794357997429026e3 1.1029734343858397e3 1.047700871248516e3 3.2446347833342094e2 1.2939454822740814e4
    7 1.4526616421616675e3 1.047700871248516e3 1.041182287710359e3 2.877207528277967e2 1.3666305206994715e4
    8 1.041182287710359e3 1.041182287710359e3 8.579153237844658e2 2.1797874201426126e2 1.6111546136109457e4
    9 8.579153237844658e2 8.579153237844658e2 6.908782889311358e2 3.3603385429273084e2 1.8403623232370217e4
    10 6.908782889311358e2 6.908782889311358e2 5.412754366320953e2 2.9471634391319105e2 2.256118922174113e4
    11 5.412754366320953e2 5.412754366320953e2 4.107323606373244e2 2.5280618758027825e2 3.2345218629716226e4
    12 4.107323606373244e2 4.107323606373244e2 3.533113357825481e2 1.5246121684327755e2 3.870547774970546e4
    13 3.533113357825481e2 3.533113357825481e2 3.0167584946745654e2 1.3635221566790634e2 3.864241751675369e4
    14 3.0167584946745654e2 3.0167584946745654e2 2.186451601188504e2 1.6136910077723138e2 3.8506395232925606e4
    15 2.186451601188504e2 2.186451601188504e2 1.760968500054712e2 9.293323764683187e1 1.7565288305207858e4
    16 1.760968500054712e2 1.760968500054712e2 7.070207322191013e1 3.3758969873920435e1 8.232417928042258e3
    17 2.943360706614861e2 7.070207322191013e1 2.943360706614861e2 6.335406818542589e1 6.894262810708319e3
    18 3.502624321301864e2 2.943360706614861e2 3.502624321301864e2 8.343740068182682e1 4.708518872720519e3
    19 4.8631610571347096e2 3.502624321301864e2 4.8631610571347096e2 1.4417863822957045e2 4.157753484083881e3
    20 5.826953299143859e2 4.8631610571347096e2 5.826953299143859e2 1.8880041202946376e2 4.0207915831765786e3
    21 6.991069355419372e2 5.826953299143859e2 6.991069355419372e2 2.4664396696477294e2 3.9302068462889756e3
    22 8.37039027597132e2 6.991069355419372e2 8.37039027597132e2 3.220063233456982e2 3.869279887914063e3
    23 1.1856632407925767e3 8.37039027597132e2 1.1856632407925767e3 3.19135027700856e2 5.415799858883626e3
    24 1.3641080759904844e3 1.1856632407925767e3 1.3641080759904844e3 3.2174297535050715e2 6.5610193822635565e3
    25 2.0602638743204348e3 1.3641080759904844e3 2.0602638743204348e3 5.856414061392463e2 2.5000000000000073e3
    26 2.458007554034879e3 2.0602638743204348e3 2.2469368195376337e3 6.11398353553652e2 1.1601554792234336e4
    27 2.45770880783478e3 2.2469368195376337e3 1.960838902742808e3 6.101922156155971e2 1.1601554792234336e4
    28 1.960838902742808e3 1.960838902742808e3 1.3218249143764137e3 5.340368545897207e2 7.723521667464427e2
    29 1.3218249143764137e3 1.3218249143764137e3 1.0848405724910433e3 3.311760818562162e2 3.9317509042900324e3
    30 1.0848405724910433e3 1.0848405724910433e3 8.181349923245793e2 2.452612125550496e2 4.0404448606945184e3
    31 8.181349923245793e2 8.181349923245793e2 7.514127857397642e2 1.5695021978657329e2 4.33278804082432e3
    32 7.514127857397642e2 7.514127857397642e2 7.929094609582049e1 1.978312049494989e2 4.487654574778002e3
    33 7.017549923641707e2 7.929094609582049e1 7.017549923641707e2 1.2741395289790731e2 4.490483424207196e3
    34 8.193705625755844e2 7.017549923641707e2 8.193705625755844e2 2.8201216669775806e2 6.495892487921807e3
    35 1.0375484221538143e3 8.193705625755844e2 1.0375484221538143e3 2.2258669388644628e2 6.171520317203335e3
    36 1.3208457412358302e3 1.0375484221538143e3 1.3208457412358302e3 2.122533547381706e2 9.95837188835033e3
    37 1.5954574387444277e3 1.3208457412358302e3 1.5954574387444277e3 2.6493503460627005e2 7.570477625647795e3
    38 2.0520408020102846e3 1.5954574387444277e3 2.0520408020102846e3 2.134849493597723e2 4.300302932129462e3
    39 3.074486781926196e3 2.0520408020102846e3 1.0133288792796085e3 6.32622350666099e2 3.81858624815848e3
    40 3.716092938992525e3 1.0133288792796085e3 3.716092938992525e3 8.159555543244934e2 1.7483409025644563e4
    41 3.8714664067793688e3 3.716092938992525e3 3.8714664067793688e3 8.444806170670863e2 1.9156317304980323e4
    42 4.8028901945980515e3 3.8714664067793688e3 4.8028901945980515e3 9.941409159936876e2 2.2113309831614526e4
    43 6e3 4.8028901945980515e3 1.2887297129399888e3 1.1189852449856048e3 9.83815005184151e3
    44 4.410525103929112e3 1.2887297129399888e3 3.4274255182638017e3 3.8511183912333274e2 9.83815005184151e3
    45 3.4274255182638017e3 3.4274255182638017e3 3.4274255182638017e3 3.248931927428848e2 3.449588766090763e4
    46 3.692481477532328e3 3.4274255182638017e3 3.1405006014287997e3 2.2353941039443293e2 3.692865414034159e4
    47 3.1405006014287997e3 3.1405006014287997e3 2.464330447361059e3 2.033556431771467e2 6.52347830757855e3
    48 2.464330447361059e3 2.464330447361059e3 2.4000060303379432e3 4.622064873372521e2 7.832678171837105e3
    49 2.4000060303379432e3 2.4000060303379432e3 0e0 5.995355710246583e2 1.4389398501401896e4
    50 0e0 0e0 0e0 0e0 0e0
    ";
    let text = "G21 G17\nG0 X0.0000 Y0.0000\nG1 F6000\nG5.2 P1.0000 L3\n\
                X7.0210 Y-15.1826 P0.9741\nX6.3357 Y-16.5219 P0.7344\n\
                X-12.2748 Y-12.0122 P0.7535\nX-14.7508 Y-13.6398 P1.1571\n\
                X-26.1475 Y-0.1673 P0.9107\nX-33.1193 Y21.6070 P0.8926\n\
                X-11.5733 Y21.6553 P0.5636\nG5.3\nM2\n";
    let machine = weak_x_machine();
    let opts = interpreter::program::Options::default();
    let mut blocks =
        interpreter::process::compile_source("c.ngc", text, &opts, &machine, PERIOD_NS)
            .unwrap()
            .blocks;
    let rows: Vec<Vec<f64>> = PLAN
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .map(|l| l.split(' ').map(|t| t.parse().unwrap()).collect())
        .collect();
    assert_eq!(
        rows.len(),
        blocks.len(),
        "the planner splits the program differently now"
    );
    for (b, v) in blocks.iter_mut().zip(&rows) {
        assert_eq!(v[0] as u64, b.seq);
        b.feed_mm_per_min = v[1];
        b.start_feed_mm_per_min = v[2];
        b.end_feed_mm_per_min = v[3];
        b.acc_mm_per_s2 = v[4];
        b.jerk_mm_per_s3 = v[5];
    }
    let (blocks, cycles) = step_blocks(blocks, &machine);
    let w = check(&blocks, &cycles, &machine);
    assert!(w.axis <= 1.0 + 1e-3, "{w:?}");
}

/// Known defect, not fixed (issue #23, 2026-11-26): with a short look-ahead window the
/// engine breaks a planned junction speed of the planner's own plan. Since 2026-11-28 a
/// machine file may not set fewer than 16 blocks (`shared::machine::LOOKAHEAD_MIN`; the
/// search with `LIMITS_SEARCH_LOOKAHEAD=16`, seeds 5 and 11, found none over; with 3,
/// seed 11, two cases, X's jerk 3.6 times its limit), and this test sets the field
/// directly. The random search with `lookahead_blocks` 2 to 4 finds such cases
/// on the weak-X machine (seed 11, 300 cases: X's jerk 3.8 times its limit at 3 blocks,
/// 1.3 times at 4; seeds 5 and 7: up to 2.0 times, and the feed 1.28 times); at 16 and
/// 256 blocks none. This one, at 3 blocks: block 19 (1.12 mm, 588 mm/s², 15 463 mm/s³)
/// must brake from about 25.4 to 7.87 mm/s, which it can under its own limits, but the
/// engine brakes for a block end under the lower jerk of the block beyond it
/// (`Ahead::easing`; block 20 has 5 410 mm/s³), under which the braking takes about 2 mm.
/// With three blocks in hand that end comes into view about 1.3 mm before it, already
/// lost, is braked for at 5 410 mm/s³, and the machine enters block 20 at 26.5 mm/s.
/// The planner plans each block's start under the block's own limits; the engine's
/// window-end stop is judged without the easing of a block it has not seen. A fix must
/// make the two agree (the stop at the end of a full window judged under the lowest jerk
/// a next block may bring, or the braking from above a block end under the block's own
/// jerk) and be judged by the random search at short windows. Tried: braking for a block
/// end under the way's own limits instead of the easing (`room`, the braking followed
/// and its cheap test) passes this case, but the random search at 256 blocks then finds
/// a weak X axis at 1.085 times its limit (seed 11, 600 cases, NURBS of order 4 to 6).
/// Not tried: a jerk floor validated on receipt, with the stop at the end of a window
/// that more blocks may follow judged under it, closes it by induction (whatever the next
/// block brings then eases the last block's end no more slowly than its stop was judged
/// under); but the planner lets a straight block's jerk go down to 1e-3 of its 5 % floor
/// (`StraightLimits`), and under so low a jerk the window's end would bind everywhere.
/// The planner and the engine must first agree on the jerk a block end is braked under.
/// Run with `--ignored`.
#[test]
#[ignore]
fn known_defect_a_short_window_loses_a_junction_speed_behind_a_block_of_lower_jerk() {
    let text = "G21 G17\nG0 X0.0000 Y0.0000\nG1 F3000\nG5.2 P1.0000 L3\n\
                X3.6480 Y-6.1761 P0.8033\nX3.8939 Y-7.2336 P1.9582\n\
                X1.6463 Y-15.3150 P0.5734\nX-2.7743 Y-14.7388 P1.2478\n\
                X-7.2364 Y-2.7328 P1.2595\nX-10.1829 Y-2.2547 P1.5538\n\
                X-10.3756 Y-3.8699 P1.1254\nX-12.2366 Y-4.0994 P1.7495\n\
                X-19.5379 Y12.1588 P0.6192\nX-21.7695 Y10.6865 P1.0306\nG5.3\nM2\n";
    let mut machine = weak_x_machine();
    machine.lookahead_blocks = 3;
    let (blocks, cycles) = step(text, &machine);
    let w = check(&blocks, &cycles, &machine);
    assert!(w.axis <= 1.0 + 1e-3, "{w:?}");
}

/// A stop between two moves in one direction keeps the jerk: the engine does not cut a
/// braking to a stop while it has acceleration to shed, so the next move does not start
/// while the braking's last jerk phase still runs. LinuxCNC's g6 chitarra (quadrant 3)
/// goes `G0 Z1` then `G1 Z-1 F500`, both down; its rapid's braking ended 5.2 µs into
/// the next period and was cut at the period, and the move down, whose jerk points the
/// same way, overlapped it for those 5.2 µs: 1.0026 times the jerk for a period, on the
/// built-in machine with the plan of this change (a plan's phases decide whether a stop
/// lands so). The whole program, every limit within 1e-4 ([`check`]).
#[test]
fn a_stop_between_two_moves_down_keeps_the_jerk() {
    let machine = Machine::default();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/peers/linuxcnc/g6_curva_chitarra_q3.ngc"
    ))
    .unwrap();
    let (blocks, cycles) = step(&text, &machine);
    let w = check(&blocks, &cycles, &machine);
    for (what, v) in [
        ("speed", w.speed),
        ("acc", w.acc),
        ("jerk", w.jerk),
        ("axis", w.axis),
    ] {
        assert!(v <= 1.0 + 1e-4, "{what} {v} times the limit: {w:?}");
    }
}

/// LinuxCNC's simulated mill (`examples/machine-linuxcnc-sim.toml`).
fn linuxcnc_machine() -> Machine {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../examples/machine-linuxcnc-sim.toml"
    );
    Machine::from_toml(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn alternating_kinks_close_together_are_passed_at_the_feed_within_the_limits() {
    // CAM output rounded to 0.1 µm on 20 µm chords: a straight cut whose every vertex is
    // off by the rounding, alternately, so each chord turns by ±0.3° and the turns cancel.
    // Two steps at F3000 cover five kinks; their turns summed (2·sin(Θ/2) ≈ 0.05) held the
    // run to 18 mm/s on LinuxCNC's limits, where the tangents' spread about their mean
    // (two of them, ±0.005 rad) allows the feed. Exact path, so every vertex is kept.
    let mut text = String::from("G21 G90 G61\nG1 F3000\n");
    for k in 1..=3000 {
        let y = if k % 2 == 1 { 0.0001 } else { 0.0 };
        text += &format!("X{:.4} Y{y:.4}\n", f64::from(k) * 0.02);
    }
    text += "M2\n";
    for machine in [linuxcnc_machine(), Machine::default()] {
        let (blocks, cycles) = step(&text, &machine);
        let w = check(&blocks, &cycles, &machine);
        assert!(w.speed <= 1.0 + 1e-6, "speed {w:?}");
        assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?}");
        assert!(w.axis <= 1.0 + 1e-3, "axis {w:?}");
        // Away from the ends, every junction at the feed.
        let middle = &blocks[blocks.len() / 3..2 * blocks.len() / 3];
        let slowest = middle
            .iter()
            .map(|b| b.end_feed_mm_per_min)
            .fold(f64::INFINITY, f64::min);
        assert!(slowest >= 0.999 * 3000.0, "a junction at {slowest} mm/min");
    }
}

/// Numbers in `[0, 1)` from `seed` (xorshift64, the top 53 bits).
fn uniform01(mut seed: u64) -> impl FnMut() -> f64 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[test]
fn jittery_cam_polylines_keep_every_limit() {
    // Arcs and straight cuts in chords of 10 to 100 µm, each vertex rounded to 0.1 µm or
    // 1 µm, at F1000 to F6000, exact and blended: where the rounding makes the turns
    // alternate, a run of close kinks is held by the tangents' spread about their mean
    // rather than by its summed turns; every limit must hold either way.
    let mut rnd = uniform01(0x2545_f491_4f6c_dd1d);
    for machine in [linuxcnc_machine(), Machine::default()] {
        for case in 0..12 {
            let chord = 0.01 + 0.09 * rnd();
            let radius = if case % 3 == 0 {
                f64::INFINITY
            } else {
                2.0 + 40.0 * rnd()
            };
            let decimals = if rnd() < 0.5 { 4 } else { 3 };
            let feed = 1000.0 + 5000.0 * rnd();
            let mode = if case % 2 == 0 { "G61" } else { "G64 P0.01" };
            let mut text = format!("G21 G90 {mode}\nG1 F{feed:.0}\n");
            for k in 1..=400 {
                let s = f64::from(k) * chord;
                let (x, y) = if radius.is_finite() {
                    let a = s / radius;
                    (radius * a.sin(), radius * (1.0 - a.cos()))
                } else {
                    (s * 0.8, s * 0.6)
                };
                text += &format!("X{x:.decimals$} Y{y:.decimals$}\n");
            }
            text += "M2\n";
            let (blocks, cycles) = step(&text, &machine);
            let w = check(&blocks, &cycles, &machine);
            let what = format!("case {case}: chord {chord:.3} R {radius:.1} F{feed:.0} {mode}");
            assert!(w.speed <= 1.0 + 1e-6, "speed {w:?} {what}");
            assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?} {what}");
            assert!(w.axis <= 1.0 + 1e-3, "axis {w:?} {what}");
        }
    }
}

#[test]
fn merged_and_smoothed_chords_keep_every_limit() {
    // Random walks of short chords (0.05 to 1 mm, turning a few degrees, rounded to
    // 1 µm) under `G64 P0.01` and `P0.05`, at F1000 to F6000: `G64 Q`'s runs merged, or
    // smoothed into cubic pieces, where that is quicker (`blocks::naive_cam`); every
    // limit must hold on what the planner keeps, and some cases must be smoothed.
    let mut rnd = uniform01(0x9e37_79b9_7f4a_7c15);
    let mut smoothed = 0;
    for machine in [linuxcnc_machine(), Machine::default()] {
        for case in 0..8 {
            let chord = 0.05 + 0.95 * rnd() * rnd();
            let bend = (0.5 + 4.0 * rnd()).to_radians();
            let feed = 1000.0 + 5000.0 * rnd();
            let mode = if case % 2 == 0 {
                "G64 P0.01"
            } else {
                "G64 P0.05"
            };
            let mut text = format!("G21 G90 {mode}\nG1 F{feed:.0}\n");
            let (mut x, mut y, mut a) = (0.0f64, 0.0f64, 0.0f64);
            for k in 0..300 {
                // Turning one way for a while, then the other.
                let sign = if (k / 60) % 2 == 0 { 1.0 } else { -1.0 };
                a += sign * bend * (0.5 + rnd());
                x += chord * a.cos();
                y += chord * a.sin();
                text += &format!("X{x:.3} Y{y:.3}\n");
            }
            text += "M2\n";
            let (blocks, cycles) = step(&text, &machine);
            smoothed += blocks.iter().filter(|b| b.degree == 3).count();
            let w = check(&blocks, &cycles, &machine);
            let what = format!("case {case}: chord {chord:.3} bend {bend:.4} F{feed:.0} {mode}");
            assert!(w.speed <= 1.0 + 1e-6, "speed {w:?} {what}");
            assert!(w.acc <= 1.0 + 1e-3, "acceleration {w:?} {what}");
            assert!(w.jerk <= 1.0 + 1e-2, "jerk {w:?} {what}");
            assert!(w.axis <= 1.0 + 1e-3, "axis {w:?} {what}");
        }
    }
    assert!(smoothed > 0, "no case was smoothed");
}
