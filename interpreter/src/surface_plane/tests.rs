//! Plane-parallel paths and their blocks against independent references:
//!
//! * every contact point of every published cubic block, sampled densely, lies within the
//!   chordal tolerance of its plane and on the original surface (the block's patch at
//!   its `(u, v)` against the conventional method on the whole surface, 1e-9 mm);
//! * the blocks validate and join up into one continuous tool path;
//! * scallop height: measured numerically from the balls swept along the published
//!   blocks of two neighbouring planes (the ridge height along the surface normal,
//!   bisection and golden-section searches on the standard evaluator), never from the
//!   spacing formula; it must stay within the strategy's tolerance.

use super::*;
use crate::step::{format_errors, read_part};
use crate::surface_blocks::{bezier_patches, plane_commands, OwnedSurface};
use shared::nurbs::reference::conventional_surface;
use shared::path;
use shared::protocol::{BlockKind, CommandBlock};
use shared::Machine;

const PLANECC: &str = include_str!("../../../examples/seed-surface-planecc.stp");
const SEED: &str = include_str!("../../../examples/seed-surface.stp");
const TORUS: &str = include_str!("../../../examples/torus-patch.stp");
const CUBIC: &str = include_str!("../../../examples/cubic-wave.stp");

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    norm([a[0] - b[0], a[1] - b[1], a[2] - b[2]])
}

/// A UV example turned into a plane-parallel one: its UV strategy line replaced.
fn with_planes(text: &str, mode: &str, normal: [f64; 3], scallop: Option<f64>) -> String {
    let line = text.lines().find(|l| l.contains("=UV_STRATEGY(")).unwrap();
    let id: u64 = line[1..line.find('=').unwrap()].parse().unwrap();
    let tol = line.split(',').nth(2).unwrap().to_string();
    let mut out = text.replace(
        line,
        &format!(
            "#{id}=PLANE_CC_STRATEGY(.{mode}.,.CLIMB.,{tol},$,#990001);\n\
             #990001=DIRECTION('',({},{},{}));",
            normal[0], normal[1], normal[2]
        ),
    );
    if let Some(h) = scallop {
        let tl = out
            .lines()
            .find(|l| l.contains("=TOLERANCES("))
            .unwrap()
            .to_string();
        let head = &tl[..tl.find('(').unwrap()];
        out = out.replace(&tl, &format!("{head}(0.001,{h});"));
    }
    out
}

fn step_of(text: &str) -> FreeformStep {
    read_part(text).unwrap().remove(0)
}

fn global_uv(patches: &[OwnedSurface], b: &CommandBlock, local: [f64; 2]) -> (f64, f64) {
    let patch = patches
        .iter()
        .find(|p| p.ctrl.as_slice() == b.ctrl())
        .expect("the block's patch is one of the surface's");
    let (u0, u1, v0, v1) = patch.domain();
    (u0 + local[0] * (u1 - u0), v0 + local[1] * (v1 - v0))
}

/// The planned path, its blocks, and which plane each cubic block's contact points lie in
/// (`None` for the straight links and rapids). Checks what holds for every block.
fn checked_blocks(step: &FreeformStep) -> (PlanePath, Vec<CommandBlock>, Vec<Option<usize>>) {
    let p = plan(step).unwrap();
    let (cmds, _) = plane_commands(step, &p, &Machine::default(), [0.0; 3]).unwrap();
    let whole = step.surface.data();
    let patches = bezier_patches(&whole).unwrap();
    let levels: Vec<f64> = {
        let mut l: Vec<f64> = p.passes.iter().map(|x| x.level_mm).collect();
        l.dedup();
        l
    };
    let n = p.normal;
    let (mut off_plane, mut off_surface): (f64, f64) = (0.0, 0.0);
    let mut prev_end: Option<[f64; 3]> = None;
    let mut planes = Vec::new();
    let mut cubic = 0;
    for (k, b) in cmds.iter().enumerate() {
        assert_eq!(b.validate(), Ok(BlockKind::Motion), "block {k}");
        let (start, end) = (path::eval(b, 0.0).p, path::eval(b, 1.0).p);
        if let Some(e) = prev_end {
            assert!(
                dist(e, start) < 1e-9,
                "gap of {:e} mm before block {k}",
                dist(e, start)
            );
        }
        prev_end = Some(end);
        if !path::is_cubic_pass(b) {
            planes.push(None);
            continue;
        }
        cubic += 1;
        let c0 = path::surface_at(b, 0.0).p;
        let f0 = dot(n, c0);
        let (plane, level) = levels
            .iter()
            .enumerate()
            .min_by(|x, y| (x.1 - f0).abs().total_cmp(&(y.1 - f0).abs()))
            .map(|(i, l)| (i, *l))
            .unwrap();
        planes.push(Some(plane));
        for i in 0..=512 {
            let t = i as f64 / 512.0;
            let c = path::surface_at(b, t).p;
            off_plane = off_plane.max((dot(n, c) - level).abs());
            let (uv, _) = path::pass_uv(b, t);
            let (u, v) = global_uv(&patches, b, uv);
            off_surface = off_surface.max(dist(c, conventional_surface(&whole, u, v).p));
        }
    }
    eprintln!(
        "{cubic} cubic blocks of {}: contact points off their plane by at most {off_plane:e} \
         mm (tolerance {} mm), off the surface by {off_surface:e} mm",
        cmds.len(),
        p.chordal_mm
    );
    assert!(cubic > 0);
    assert!(off_plane <= p.chordal_mm, "off the plane by {off_plane} mm");
    assert!(off_surface < 1e-9, "off the surface by {off_surface:e} mm");
    (p, cmds, planes)
}

#[test]
fn the_example_reads_with_its_plane_normal() {
    let s = step_of(PLANECC);
    let Strategy::PlaneCc(st) = &s.strategy else {
        panic!("{:?}", s.strategy)
    };
    let want = [-0.5, 3f64.sqrt() / 2.0, 0.0];
    assert!(dist(st.normal, want) < 1e-12, "{:?}", st.normal);
    assert_eq!(
        (st.mode, st.scallop_mm, st.chordal_mm),
        (PathMode::Zigzag, 0.02, 0.001)
    );
    assert_eq!(st.stepover_mm, None);
}

#[test]
fn example_blocks_lie_on_their_planes_and_on_the_surface() {
    let (p, cmds, _) = checked_blocks(&step_of(PLANECC));
    assert!(p.planes > 50, "{} planes", p.planes);
    // Zig-zag: the passes of neighbouring planes run opposite ways.
    let along = cross(p.normal, [0.0, 0.0, 1.0]);
    let s = step_of(PLANECC);
    let at = |q: (f64, f64)| eval2(&s.surface.data(), q.0, q.1).p;
    for w in p.passes.windows(2) {
        let dir = |x: &PlanePass| {
            let (a, b) = (at(x.uv[0]), at(x.uv[x.uv.len() - 1]));
            dot([b[0] - a[0], b[1] - a[1], b[2] - a[2]], along).signum()
        };
        if w[0].plane != w[1].plane {
            assert_eq!(dir(&w[0]), -dir(&w[1]));
        }
    }
    // Most neighbours are joined along the boundary, not lifted.
    let rapids = cmds.iter().filter(|b| !b.is_surface()).count();
    assert!(rapids < p.passes.len() / 2, "{rapids} rapids");
}

#[test]
fn tilted_planes_on_the_other_surfaces_hold_too() {
    // Planes tilted off the vertical make truly curved (u, v) passes; the torus is
    // rational and placed, the cubic wave has p = q = 3; forward mode lifts between.
    for (text, mode, n) in [
        (SEED, "FORWARD", [0.6, 0.0, 0.8]),
        (TORUS, "ZIGZAG", [0.9, 0.0, 0.25]),
        (CUBIC, "ZIGZAG", [0.3, 0.9, 0.3]),
    ] {
        let step = step_of(&with_planes(text, mode, n, Some(0.05)));
        let (p, cmds, _) = checked_blocks(&step);
        assert!(p.planes >= 3, "{} planes", p.planes);
        if mode == "FORWARD" {
            let rapids = cmds.iter().filter(|b| !b.is_surface()).count();
            assert!(rapids >= 2 * p.passes.len(), "{rapids} rapids");
        }
    }
}

fn golden_min(mut lo: f64, mut hi: f64, iters: usize, f: impl Fn(f64) -> f64) -> f64 {
    let g = 0.5 * (5f64.sqrt() - 1.0);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..iters {
        if f1 < f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - g * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + g * (hi - lo);
            f2 = f(x2);
        }
    }
    f1.min(f2)
}

/// The ball centre over the contact point at `t` of a surface block.
fn centre(b: &CommandBlock, t: f64) -> [f64; 3] {
    let e = path::surface_at(b, t);
    let k = b.surface.tool_radius_mm * b.surface.normal_sign as f64;
    [
        e.p[0] + k * e.normal[0],
        e.p[1] + k * e.normal[1],
        e.p[2] + k * e.normal[2],
    ]
}

/// Height of the material left above the surface point `q` (normal `nq`, towards the
/// tool) by the balls swept along `blocks`.
fn left_by(q: [f64; 3], nq: [f64; 3], r: f64, blocks: &[&CommandBlock]) -> f64 {
    let near: Vec<&CommandBlock> = blocks
        .iter()
        .copied()
        .filter(|b| (0..=16).any(|i| dist(q, path::surface_at(b, i as f64 / 16.0).p) < 4.0 * r))
        .collect();
    let gap = |t: f64| {
        let x = [q[0] + t * nq[0], q[1] + t * nq[1], q[2] + t * nq[2]];
        near.iter()
            .map(|b| golden_min(0.0, 1.0, 60, |s| dist(x, centre(b, s))))
            .fold(f64::INFINITY, f64::min)
            - r
    };
    let (mut t0, mut t1) = (0.0, 1.0);
    if gap(t0) <= 0.0 {
        return 0.0;
    }
    if gap(t1) > 0.0 {
        return t1;
    }
    for _ in 0..40 {
        let t = 0.5 * (t0 + t1);
        if gap(t) > 0.0 {
            t0 = t;
        } else {
            t1 = t;
        }
    }
    0.5 * (t0 + t1)
}

/// The largest scallop measured between a few pairs of neighbouring planes, at a few
/// places along each: from a point of the lower plane's pass across the strip (along
/// the gradient of `n·S` in `(u, v)`) to the next plane, the ridge searched for.
fn measured_scallop(step: &FreeformStep) -> (f64, f64) {
    let (p, cmds, planes) = checked_blocks(step);
    let s = step.surface.data();
    let n = p.normal;
    let levels: Vec<f64> = {
        let mut l: Vec<f64> = p.passes.iter().map(|x| x.level_mm).collect();
        l.dedup();
        l
    };
    let of_plane = |k: usize| -> Vec<&CommandBlock> {
        cmds.iter()
            .zip(&planes)
            .filter(|(_, pl)| **pl == Some(k))
            .map(|(b, _)| b)
            .collect()
    };
    let (u0, u1, v0, v1) = step.surface.geometry.domain();
    let m = levels.len();
    assert!(m >= 4, "{m} planes");
    let mut worst: f64 = 0.0;
    let mut measured = 0;
    let pairs = 4.min(m - 2);
    for i in 0..pairs {
        // Inner pairs (the first and last gaps close the extent and are narrower).
        let k = 1 + i * (m - 3) / (pairs - 1).max(1);
        let (lo, hi) = (of_plane(k), of_plane(k + 1));
        let pass = p.passes.iter().find(|x| x.level_mm == levels[k]).unwrap();
        for f in [0.1, 0.2, 0.35, 0.5, 0.65, 0.8, 0.9] {
            let start = pass.uv[((pass.uv.len() - 1) as f64 * f) as usize];
            // The point of the strip at level `c` on the line along the gradient.
            let at_level = |c: f64| {
                let d = eval2(&s, start.0, start.1);
                let g = [dot(n, d.su), dot(n, d.sv)];
                let g2 = g[0] * g[0] + g[1] * g[1];
                let (mut a, mut b) = (0.0, 3.0 * (levels[k + 1] - levels[k]) / g2);
                let pt = |x: f64| {
                    (
                        (start.0 + x * g[0]).clamp(u0, u1),
                        (start.1 + x * g[1]).clamp(v0, v1),
                    )
                };
                for _ in 0..60 {
                    let mid = 0.5 * (a + b);
                    let q = pt(mid);
                    if dot(n, eval2(&s, q.0, q.1).p) < c {
                        a = mid;
                    } else {
                        b = mid;
                    }
                }
                pt(0.5 * (a + b))
            };
            let h = |c: f64| {
                let q = at_level(c);
                let e = shared::nurbs::reference::piegl_tiller_surface(&s, q.0, q.1);
                let nq = e.normal.map(|x| x * p.normal_sign);
                left_by(e.p, nq, p.radius_mm, &lo).min(left_by(e.p, nq, p.radius_mm, &hi))
            };
            // Interior strips only: where passes meet the boundary obliquely there is no
            // pass beyond it (no overcut), and the ridge there is an edge effect.
            let clear = |q: (f64, f64)| {
                let d = eval2(&s, q.0, q.1);
                let (su, sv) = (norm(d.su), norm(d.sv));
                [
                    (q.0 - u0) * su,
                    (u1 - q.0) * su,
                    (q.1 - v0) * sv,
                    (v1 - q.1) * sv,
                ]
                .into_iter()
                .fold(f64::INFINITY, f64::min)
            };
            let ends = [at_level(levels[k]), at_level(levels[k + 1])];
            if ends.iter().any(|q| clear(*q) < p.radius_mm) {
                continue;
            }
            measured += 1;
            let hk = -golden_min(levels[k], levels[k + 1], 20, |c| -h(c));
            worst = worst.max(hk);
        }
    }
    assert!(measured >= 6, "{measured} places measured");
    (worst, p.predicted_scallop_mm)
}

#[test]
fn measured_scallop_stays_within_tolerance() {
    for (name, text) in [
        ("seed planecc", PLANECC.to_string()),
        (
            "torus tilted",
            with_planes(TORUS, "ZIGZAG", [0.9, 0.0, 0.25], None),
        ),
    ] {
        let step = step_of(&text);
        let tol = step.strategy.scallop_mm();
        let (measured, predicted) = measured_scallop(&step);
        eprintln!(
            "{name}: measured scallop {:.3} um, predicted {:.3} um, tolerance {:.3} um",
            measured * 1e3,
            predicted * 1e3,
            tol * 1e3
        );
        assert!(measured <= tol, "{name}: scallop {measured} mm > {tol} mm");
        // Not wastefully fine either: the spacing uses the tolerance.
        assert!(
            measured > 0.5 * tol,
            "{name}: scallop {measured} mm, far below {tol} mm"
        );
    }
}

#[test]
fn planes_tangent_to_the_surface_are_refused_naming_the_direction() {
    // Horizontal planes on the seed surface, which has a level spot.
    let text = with_planes(SEED, "ZIGZAG", [0.0, 0.0, 1.0], None);
    let errs = plan(&step_of(&text)).unwrap_err();
    let shown = format_errors("part.stp", &[errs]);
    let line = text
        .lines()
        .position(|l| l.starts_with("#990001="))
        .unwrap()
        + 1;
    assert!(
        shown.starts_with(&format!("part.stp:{line}: #990001: strategy: the planes")),
        "{shown}"
    );
    assert!(shown.contains("parallel"), "{shown}");
}

#[test]
fn a_zero_plane_normal_is_refused_by_the_reader() {
    let text = with_planes(SEED, "ZIGZAG", [0.0, 0.0, 0.0], None);
    let errs = read_part(&text).unwrap_err();
    let shown = format_errors("part.stp", &errs);
    assert!(shown.contains("#990001: direction:"), "{shown}");
}

#[test]
fn a_plane_that_misses_the_surface_gives_no_pass_and_one_that_cuts_twice_gives_two() {
    let step = step_of(PLANECC);
    let Strategy::PlaneCc(st) = &step.strategy else {
        unreachable!()
    };
    let s = step.surface.data();
    let g = grid(&s, st, 3.0, 1.0);
    let (lo, hi) =
        g.f.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                (a.min(x), b.max(x))
            });
    assert!(plane_pieces(&s, &g, st.normal, 0, lo - 1.0).is_empty());
    assert!(plane_pieces(&s, &g, st.normal, 0, hi + 1.0).is_empty());
    let mid = plane_pieces(&s, &g, st.normal, 0, 0.5 * (lo + hi));
    assert_eq!(mid.len(), 1);
    assert!(!mid[0].closed && mid[0].start_edge.is_some() && mid[0].end_edge.is_some());
    // Horizontal planes through the seed surface's bump and wave: several pieces, some
    // closed, each exactly on its plane.
    let zst = PlaneCcStrategy {
        normal: [0.0, 0.0, 1.0],
        ..st.clone()
    };
    let gz = grid(&s, &zst, 3.0, 1.0);
    let level = 3.0;
    let pieces = plane_pieces(&s, &gz, zst.normal, 0, level);
    assert!(pieces.len() >= 2, "{} pieces", pieces.len());
    for piece in &pieces {
        for q in &piece.uv {
            assert!((eval2(&s, q.0, q.1).p[2] - level).abs() < 1e-10);
        }
        if piece.closed {
            assert_eq!(piece.uv.first(), piece.uv.last());
        }
    }
}

#[test]
fn the_stepover_caps_the_spacing() {
    let free = plan(&step_of(PLANECC)).unwrap();
    let mut step = step_of(PLANECC);
    if let Strategy::PlaneCc(st) = &mut step.strategy {
        st.stepover_mm = Some(0.3);
    }
    let capped = plan(&step).unwrap();
    // The planes are vertical and the surface nearly level across them: a plane step is
    // at most the spacing on the surface.
    assert!(capped.max_step_mm <= 0.3 + 1e-12, "{}", capped.max_step_mm);
    assert!(
        capped.planes > 2 * free.planes - 10,
        "{} vs {}",
        capped.planes,
        free.planes
    );
    assert!(capped.predicted_scallop_mm < free.predicted_scallop_mm);
}

/// The whole part's scallop as [`crate::scallop`] measures a run's, from tool points
/// sampled along the surface blocks every 0.04 mm at most (a cycle's step at 2400 mm/min).
fn part_scallop(step: &FreeformStep, p: &PlanePath) -> crate::scallop::Scallop {
    let (cmds, _) = plane_commands(step, p, &Machine::default(), [0.0; 3]).unwrap();
    let mut points = Vec::new();
    for b in cmds.iter().filter(|b| b.is_surface()) {
        let n = (b.length_mm / 0.04).ceil().max(1.0) as usize;
        points.extend((0..=n).map(|i| path::eval(b, i as f64 / n as f64).p));
    }
    crate::scallop::measure(&cmds, &points).unwrap()
}

/// The example's passes meet the domain's edges at about 30°, where a band 1.8 times the
/// scallop between passes is left between their ends; the boundary pass that follows
/// the last one takes it down to the passes' own. Measured over the whole part, edges
/// included, with and without it.
#[test]
fn the_boundary_pass_keeps_the_bands_along_the_edges_within_tolerance() {
    let step = step_of(PLANECC);
    let tol = step.strategy.scallop_mm();
    let p = plan(&step).unwrap();
    // Once round from where the last pass ends, through the four corners.
    let last = p.passes.last().unwrap();
    assert_eq!(p.boundary.first(), last.uv.last());
    assert_eq!(p.boundary.first(), p.boundary.last());
    let (u0, u1, v0, v1) = OwnedSurface::from_data(&step.surface.data()).domain();
    for corner in [(u0, v0), (u1, v0), (u1, v1), (u0, v1)] {
        assert!(p.boundary.contains(&corner), "{corner:?}: {:?}", p.boundary);
    }
    assert!(
        p.edge_factor > 1.7 && p.edge_factor * p.predicted_scallop_mm > tol,
        "{}",
        p.edge_factor
    );
    let with = part_scallop(&step, &p);
    let mut bare = p.clone();
    bare.boundary.clear();
    let without = part_scallop(&step, &bare);
    eprintln!("with the boundary pass {with:?}, without {without:?}");
    assert!(with.max_mm <= tol, "{with:?}");
    assert!(
        with.max_mm >= 0.95 * p.predicted_scallop_mm,
        "{with:?} against {} mm predicted",
        p.predicted_scallop_mm
    );
    // Without it, the band along an edge: the factor's share of it, at the boundary.
    assert!(without.max_mm > 1.5 * p.predicted_scallop_mm, "{without:?}");
    let s = step.surface.data();
    let at_edge = [u0, u1]
        .iter()
        .flat_map(|&u| (0..=200).map(move |k| (u, v0 + (v1 - v0) * k as f64 / 200.0)))
        .chain(
            [v0, v1]
                .iter()
                .flat_map(|&v| (0..=200).map(move |k| (u0 + (u1 - u0) * k as f64 / 200.0, v))),
        )
        .map(|(u, v)| dist(eval2(&s, u, v).p, without.at_mm))
        .fold(f64::INFINITY, f64::min);
    assert!(at_edge < 1.0, "{without:?} is {at_edge} mm from the edges");
}

/// Passes that meet the edges square leave no wider band there: no boundary pass.
#[test]
fn passes_square_to_the_edges_need_no_boundary_pass() {
    // Planes x = c cross the seed surface's edges y = 0 and y = 60 at right angles
    // (its control net is a square grid in x and y).
    let step = step_of(&with_planes(SEED, "ZIGZAG", [1.0, 0.0, 0.0], None));
    let p = plan(&step).unwrap();
    assert!(p.edge_factor < 1.1, "{}", p.edge_factor);
    assert!(p.boundary.is_empty(), "{:?}", p.boundary);
}

/// For exploring: the whole-part scallop (edges included) of plane paths at many plane
/// directions on the example surfaces, printed against the tolerance. Run with
/// `cargo test --release -p interpreter --lib -- --ignored --nocapture plane_directions`.
#[test]
#[ignore]
fn search_plane_directions_for_scallops_beyond_tolerance() {
    let mut over = 0;
    for (name, text, h) in [
        ("seed", SEED, 0.02),
        ("torus", TORUS, 0.05),
        ("cubic", CUBIC, 0.05),
    ] {
        for k in 0..12 {
            let a = (k as f64 * 15.0 + 7.0).to_radians();
            for tilt in [0.0, 0.4] {
                let n = [a.cos(), a.sin(), tilt];
                let step = step_of(&with_planes(text, "ZIGZAG", n, Some(h)));
                let Ok(p) = plan(&step) else {
                    eprintln!("{name} {:.0}° tilt {tilt}: refused", a.to_degrees());
                    continue;
                };
                let got = part_scallop(&step, &p);
                let bad = got.max_mm > h;
                over += usize::from(bad);
                eprintln!(
                    "{name} {:.0}° tilt {tilt}: measured {:.2} µm, predicted {:.2} µm, tolerance {:.0} µm, edge factor {:.2}, boundary pass {}{}",
                    a.to_degrees(),
                    got.max_mm * 1e3,
                    p.predicted_scallop_mm * 1e3,
                    h * 1e3,
                    p.edge_factor,
                    !p.boundary.is_empty(),
                    if bad { "  OVER" } else { "" }
                );
            }
        }
    }
    eprintln!("{over} over the tolerance");
}
