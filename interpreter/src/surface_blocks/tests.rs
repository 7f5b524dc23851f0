//! Exact splitting and Bézier decomposition (pieces against the conventional evaluation
//! of the whole surface, 1e-9 mm) and the wire blocks of the examples and of a large
//! surface: one continuous tool point path that agrees with the original surface.

use super::*;
use crate::step::read_part;
use crate::surface_path::plan;
use shared::nurbs::reference::conventional_surface;
use shared::nurbs::surface::MAX_SURF_CTRL;
use shared::protocol::CommandBlock;

const SEED: &str = include_str!("../../../examples/seed-surface.stp");
const TORUS: &str = include_str!("../../../examples/torus-patch.stp");
const CUBIC: &str = include_str!("../../../examples/cubic-wave.stp");
const PLANECC: &str = include_str!("../../../examples/seed-surface-planecc.stp");

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// A bicubic 20 x 18 surface with uneven knots and weights: larger than a block.
fn big() -> OwnedSurface {
    let (n_u, n_v, p) = (20, 18, 3);
    let knots = |n: usize| -> Vec<f64> {
        let inner = n - p - 1;
        let mut k = vec![0.0; p + 1];
        k.extend((1..=inner).map(|i| (i as f64 / (inner + 1) as f64).powf(1.1)));
        k.extend(vec![1.0; p + 1]);
        k
    };
    let ctrl = (0..n_u * n_v)
        .map(|k| {
            let (i, j) = ((k / n_v) as f64, (k % n_v) as f64);
            [
                4.0 * i,
                3.0 * j,
                2.0 * (0.4 * i).sin() * (0.3 * j).cos(),
                1.0 + 0.2 * ((i + 2.0 * j) * 0.7).sin().abs(),
            ]
        })
        .collect();
    OwnedSurface {
        degree_u: p,
        degree_v: p,
        n_u,
        n_v,
        knots_u: knots(n_u),
        knots_v: knots(n_v),
        ctrl,
    }
}

#[test]
fn split_pieces_trace_the_same_surface() {
    let s = big();
    let pieces = split_surface(&s.data(), MAX_SURF_CTRL).unwrap();
    assert!(pieces.len() >= 4, "{} pieces", pieces.len());
    let mut worst: f64 = 0.0;
    for piece in &pieces {
        assert!(piece.n_u <= MAX_SURF_CTRL && piece.n_v <= MAX_SURF_CTRL);
        piece.data().validate(MAX_SURF_CTRL).unwrap();
        let (u0, u1, v0, v1) = piece.domain();
        for i in 0..=7 {
            for j in 0..=7 {
                let u = u0 + (u1 - u0) * i as f64 / 7.0;
                let v = v0 + (v1 - v0) * j as f64 / 7.0;
                let a = conventional_surface(&piece.data(), u, v).p;
                let b = conventional_surface(&s.data(), u, v).p;
                worst = worst.max(dist(a, b));
            }
        }
    }
    assert!(
        worst < 1e-9,
        "pieces differ from the surface by {worst:e} mm"
    );
    // The pieces tile the domain: their areas in (u, v) add up to the whole.
    let area: f64 = pieces
        .iter()
        .map(|p| {
            let (u0, u1, v0, v1) = p.domain();
            (u1 - u0) * (v1 - v0)
        })
        .sum();
    assert!((area - 1.0).abs() < 1e-12);
}

/// The global `(u, v)` of a patch-local point of block `b`: the patch is found among the
/// surface's Bézier patches by its control points.
fn global_uv(patches: &[OwnedSurface], b: &CommandBlock, local: [f64; 2]) -> (f64, f64) {
    let patch = patches
        .iter()
        .find(|p| p.ctrl.as_slice() == b.ctrl())
        .expect("the block's patch is one of the surface's");
    let (u0, u1, v0, v1) = patch.domain();
    (u0 + local[0] * (u1 - u0), v0 + local[1] * (v1 - v0))
}

/// Checks the blocks of one workingstep: every block validates, the tool point path is
/// continuous (1e-9 mm), every surface block's tool point at its ends and middle is the
/// one the original surface gives at the mapped `(u, v)` (reference evaluator, 1e-9 mm),
/// and the contact lengths add up to the path's.
fn check_blocks(step: &FreeformStep) -> Vec<CommandBlock> {
    let path = plan(step).unwrap();
    let machine = Machine::default();
    let (cmds, _) = surface_commands(step, &path, &machine, [0.0; 3]).unwrap();
    let whole = step.surface.data();
    let patches = bezier_patches(&whole).unwrap();
    let mut length = 0.0;
    let mut prev_end: Option<[f64; 3]> = None;
    let mut worst: f64 = 0.0;
    for (k, b) in cmds.iter().enumerate() {
        assert_eq!(b.validate(), Ok(BlockKind::Motion), "block {k}");
        let (start, end) = (path::eval(b, 0.0).p, path::eval(b, 1.0).p);
        if b.is_surface() {
            assert_eq!(b.source_line, step.line);
            length += b.length_mm;
            let sp = &b.surface;
            let (r, h, sign) = (sp.tool_radius_mm, sp.tool_length_mm, sp.normal_sign as f64);
            for t in [0.0, 0.5, 1.0] {
                let local =
                    core::array::from_fn(|i| sp.uv_start[i] + t * (sp.uv_end[i] - sp.uv_start[i]));
                let (u, v) = global_uv(&patches, b, local);
                let reference = tool_point(&whole, r, h, sign, u, v);
                worst = worst.max(dist(path::eval(b, t).p, reference));
                // The contact point lies on the original surface.
                let c = path::surface_at(b, t).p;
                worst = worst.max(dist(c, conventional_surface(&whole, u, v).p));
            }
        }
        // One continuous tool path.
        if let Some(p) = prev_end {
            assert!(
                dist(p, start) < 1e-9,
                "gap of {:e} mm before block {k}",
                dist(p, start)
            );
        }
        prev_end = Some(end);
    }
    assert!(
        worst < 1e-9,
        "tool points off the surface's by {worst:e} mm"
    );
    assert!(
        (length - path.length_mm).abs() < 1e-6 * path.length_mm,
        "{length} vs {}",
        path.length_mm
    );
    cmds
}

#[test]
fn bezier_patches_trace_the_same_surface() {
    let s = big();
    let patches = bezier_patches(&s.data()).unwrap();
    // 17 x 15 knot spans.
    assert_eq!(patches.len(), (s.n_u - 3) * (s.n_v - 3));
    let mut worst: f64 = 0.0;
    for patch in &patches {
        assert_eq!((patch.n_u, patch.n_v), (4, 4));
        let (u0, u1, v0, v1) = patch.domain();
        for i in 0..=4 {
            for j in 0..=4 {
                let u = u0 + (u1 - u0) * i as f64 / 4.0;
                let v = v0 + (v1 - v0) * j as f64 / 4.0;
                let a = conventional_surface(&patch.data(), u, v).p;
                let b = conventional_surface(&s.data(), u, v).p;
                worst = worst.max(dist(a, b));
            }
        }
    }
    assert!(
        worst < 1e-9,
        "patches differ from the surface by {worst:e} mm"
    );
}

fn surface_count(cmds: &[CommandBlock]) -> usize {
    cmds.iter().filter(|b| b.is_surface()).count()
}

#[test]
fn example_blocks_validate_and_join_up() {
    for text in [SEED, TORUS, CUBIC] {
        let step = read_part(text).unwrap().remove(0);
        let cmds = check_blocks(&step);
        let path = plan(&step).unwrap();
        let surf = surface_count(&cmds);
        let rapids = cmds.len() - surf;
        // At least one block per pass (and per link in zig-zag).
        match step.strategy.mode() {
            PathMode::Zigzag => {
                assert!(surf >= 2 * path.passes.len() - 1);
                // Up and across from the start, down, and up at the end.
                assert!(rapids <= 4, "{rapids} rapids");
            }
            PathMode::Forward => {
                assert!(surf >= path.passes.len());
                assert!(rapids <= 3 * path.passes.len() + 1, "{rapids} rapids");
            }
        }
    }
}

#[test]
fn a_large_surface_is_cut_per_patch() {
    let mut step = read_part(SEED).unwrap().remove(0);
    let b = big();
    step.surface.geometry = b;
    if let crate::step::Strategy::Uv(st) = &mut step.strategy {
        st.scallop_mm = 0.1;
    }
    let cmds = check_blocks(&step);
    let path = plan(&step).unwrap();
    let surf = surface_count(&cmds);
    assert!(
        surf > 10 * path.passes.len(),
        "{surf} blocks for {} passes",
        path.passes.len()
    );
}

#[test]
fn a_part_is_planned_within_its_caps() {
    let machine = Machine::default();
    let (blocks, scallop) = part_blocks(SEED, &machine, 1_000_000).unwrap();
    assert!(scallop > 0.0);
    assert_eq!(
        blocks.last().map(|b| b.kind),
        Some(BlockKind::ProgramEnd as u32)
    );
    let mut prev: Option<&CommandBlock> = None;
    for (k, b) in blocks.iter().enumerate() {
        assert_eq!(b.seq, k as u64);
        b.validate().unwrap();
        if b.kind != BlockKind::Motion as u32 {
            continue;
        }
        assert!(b.length_mm > 0.0);
        assert!(b.start_feed_mm_per_min <= b.feed_mm_per_min + 1e-9);
        assert!(b.end_feed_mm_per_min <= b.feed_mm_per_min + 1e-9);
        if let Some(p) = prev {
            assert_eq!(p.end_feed_mm_per_min, b.start_feed_mm_per_min);
        }
        prev = Some(b);
    }
    // Consecutive blocks of one pass are passed without a stop.
    let flowing = blocks
        .windows(2)
        .filter(|w| w[0].is_surface() && w[1].is_surface() && w[0].end_feed_mm_per_min > 0.0)
        .count();
    assert!(flowing > 0);
}

/// The set-points the interpolator's engine publishes for a part (stepped in-process, as
/// `cnc check --estimate` does) are tool points of the ORIGINAL surface: each is located
/// on its block's pass, the pass point mapped back to the surface's own `(u, v)`, and the
/// tool point there recomputed with the reference evaluator (1e-9 mm). On the
/// plane-parallel example (cubic `(u, v)` passes) the contact point under each set-point
/// lies in its block's plane, within the chordal tolerance.
#[test]
fn engine_set_points_are_tool_points_of_the_original_surface() {
    use interpolator::engine::{BlockSource, Engine, Limits, TickState};
    struct Slice<'a>(&'a [CommandBlock], usize);
    impl BlockSource for Slice<'_> {
        fn next_block(&mut self) -> Option<CommandBlock> {
            let b = self.0.get(self.1).copied();
            self.1 += usize::from(b.is_some());
            b
        }
    }
    for text in [SEED, TORUS, PLANECC] {
        let machine = Machine::default();
        let plane = match &read_part(text).unwrap()[0].strategy {
            crate::step::Strategy::PlaneCc(st) => Some((st.normal, st.chordal_mm)),
            crate::step::Strategy::Uv(_) => None,
        };
        let mut off_plane: f64 = 0.0;
        let step = read_part(text).unwrap().remove(0);
        let whole = step.surface.data();
        let patches = bezier_patches(&whole).unwrap();
        let (blocks, _) = part_blocks(text, &machine, 1_000_000).unwrap();
        let mut engine = Engine::new(Limits::new(&machine, 1_000_000), [0.0; 3]);
        let mut src = Slice(&blocks, 0);
        let (mut worst, mut checked, mut cycle) = (0.0f64, 0usize, 0usize);
        let (mut last_seq, mut last_t) = (u64::MAX, 0.0);
        loop {
            let tick = engine.tick(&mut src).unwrap();
            cycle += 1;
            if tick.state == TickState::Done {
                break;
            }
            assert_ne!(tick.state, TickState::Starved);
            let b = &blocks[tick.block_seq as usize];
            if !b.is_surface() || cycle % 5 != 0 {
                continue;
            }
            // Newton on (M(t) - p)·M'(t) from the last pass parameter; its root is exact
            // whatever the derivative's error, since the set-point is a point of M.
            let p = tick.pos_mm;
            let mut t = if tick.block_seq == last_seq {
                last_t
            } else {
                0.0
            };
            for _ in 0..30 {
                let e = crate::blocks::set_point_eval(b, t);
                let r = [e.p[0] - p[0], e.p[1] - p[1], e.p[2] - p[2]];
                let g = r[0] * e.d1[0] + r[1] * e.d1[1] + r[2] * e.d1[2];
                let dg = e.d1.iter().map(|x| x * x).sum::<f64>();
                let next = (t - g / dg).clamp(0.0, 1.0);
                if (next - t).abs() < 1e-15 {
                    break;
                }
                t = next;
            }
            (last_seq, last_t) = (tick.block_seq, t);
            let sp = &b.surface;
            let (u, v) = global_uv(&patches, b, path::pass_uv(b, t).0);
            if let (Some((n, _)), true) = (plane, path::is_cubic_pass(b)) {
                let f = |c: [f64; 3]| n[0] * c[0] + n[1] * c[1] + n[2] * c[2];
                let level = f(path::surface_at(b, 0.0).p);
                off_plane = off_plane.max((f(conventional_surface(&whole, u, v).p) - level).abs());
            }
            let m = tool_point(
                &whole,
                sp.tool_radius_mm,
                sp.tool_length_mm,
                sp.normal_sign as f64,
                u,
                v,
            );
            worst = worst.max(dist(m, p));
            checked += 1;
        }
        assert!(checked > 1000, "{checked} set-points checked");
        assert!(
            worst < 1e-9,
            "a set-point is {worst:e} mm off the original surface's tool point"
        );
        if let Some((_, tol)) = plane {
            assert!(
                off_plane <= tol,
                "a contact point {off_plane} mm off its plane"
            );
        }
    }
}
