//! Exact splitting (pieces against the conventional evaluation of the whole surface,
//! 1e-9 mm) and the blocks of the examples and of a surface larger than a block.

use super::*;
use crate::step::read_part;
use crate::surface_path::plan;
use shared::nurbs::reference::conventional_surface;

const SEED: &str = include_str!("../../../examples/seed-surface.stp");
const TORUS: &str = include_str!("../../../examples/torus-patch.stp");
const CUBIC: &str = include_str!("../../../examples/cubic-wave.stp");

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

fn check_blocks(step: &FreeformStep) -> Vec<SurfaceCommand> {
    let path = plan(step).unwrap();
    let machine = Machine::default();
    let cmds = surface_commands(step, &path, &machine).unwrap();
    let whole = step.surface.data();
    let mut length = 0.0;
    let mut prev_end: Option<[f64; 3]> = None;
    for (k, c) in cmds.iter().enumerate() {
        let (start, end) = match c {
            SurfaceCommand::Surface(b) => {
                assert_eq!(b.validate(), Ok(()));
                assert_eq!(b.path.seq, k as u64);
                length += b.path.length_mm;
                let (a, e) = (b.path.ctrl[0], b.path.ctrl[1]);
                // The block's own section gives the same tool point as the whole surface.
                let sec = b.surface.data().unwrap();
                for (u, v) in [
                    (a[0], a[1]),
                    (e[0], e[1]),
                    (0.5 * (a[0] + e[0]), 0.5 * (a[1] + e[1])),
                ] {
                    let mine = tool_point(&sec, &b.tool, u, v);
                    let reference = {
                        let r = conventional_surface(&whole, u, v);
                        let (rr, h, s) = (b.tool.radius_mm, b.tool.length_mm, b.tool.normal_sign);
                        core::array::from_fn(|x| {
                            r.p[x] + rr * s * r.normal[x] + (h - rr) * b.tool.axis[x]
                        })
                    };
                    assert!(dist(mine, reference) < 1e-9, "{:e}", dist(mine, reference));
                }
                (
                    tool_point(&sec, &b.tool, a[0], a[1]),
                    tool_point(&sec, &b.tool, e[0], e[1]),
                )
            }
            SurfaceCommand::Motion(b) => {
                b.validate().unwrap();
                assert_eq!(b.seq, k as u64);
                let (a, e) = (b.ctrl[0], b.ctrl[1]);
                ([a[0], a[1], a[2]], [e[0], e[1], e[2]])
            }
        };
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
        (length - path.length_mm).abs() < 1e-6 * path.length_mm,
        "{length} vs {}",
        path.length_mm
    );
    cmds
}

#[test]
fn example_blocks_validate_and_join_up() {
    for text in [SEED, TORUS, CUBIC] {
        let step = read_part(text).unwrap().remove(0);
        let cmds = check_blocks(&step);
        let surf = cmds
            .iter()
            .filter(|c| matches!(c, SurfaceCommand::Surface(_)))
            .count();
        let path = plan(&step).unwrap();
        match step.strategy.mode {
            // One block per pass and per link, two rapids (approach, retract).
            PathMode::Zigzag => {
                assert_eq!(surf, 2 * path.passes.len() - 1);
                assert_eq!(cmds.len(), surf + 2);
            }
            // One block per pass, each with its own approach and retract, plus the
            // traverse between them.
            PathMode::Forward => {
                assert_eq!(surf, path.passes.len());
                assert_eq!(cmds.len(), surf + 3 * path.passes.len() - 1);
            }
        }
    }
}

#[test]
fn a_surface_larger_than_a_block_is_cut_per_piece() {
    let mut step = read_part(SEED).unwrap().remove(0);
    let b = big();
    step.surface.degree_u = b.degree_u;
    step.surface.degree_v = b.degree_v;
    step.surface.n_u = b.n_u;
    step.surface.n_v = b.n_v;
    step.surface.knots_u = b.knots_u.clone();
    step.surface.knots_v = b.knots_v.clone();
    step.surface.ctrl = b.ctrl.clone();
    step.strategy.scallop_mm = 0.1;
    let cmds = check_blocks(&step);
    let path = plan(&step).unwrap();
    let surf = cmds
        .iter()
        .filter(|c| matches!(c, SurfaceCommand::Surface(_)))
        .count();
    assert!(
        surf > 2 * path.passes.len(),
        "{surf} blocks for {} passes",
        path.passes.len()
    );
}
