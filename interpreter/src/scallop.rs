//! The scallop height the executed tool path of a STEP-NC part left on its surface
//! (issue #8), measured after the run from the machine's positions: what the run report
//! gives beside the pass planner's prediction.
//!
//! Each cycle's ball centre is the position less `(H − R)` along the tool axis Z (the
//! tool reference point is `M = C + R·n + (H − R)·z`, seed 000 §3); between two cycles'
//! balls the swept one could cut deeper by at most `(s/2)²/(2R)` for a step `s` (0.06 µm
//! for a 3 mm ball at 2200 mm/min and 1 ms), which is left out. Every Bézier patch the
//! surface blocks carry is sampled on a grid; at a sample point `P` with unit normal `n`
//! (to the tool's side) the material left is how far along `n` from `P` the nearest ball
//! begins: the least `t ≥ 0` with `|P + t·n − c| ≤ R` over the centres `c`. Only points
//! the cut surrounds count: the centres near `P + R·n`, seen in the tangent plane at `P`,
//! leave no angular gap of half a turn or more around it. That leaves out the surface's
//! edges outside its first and last passes and beyond the passes' ends, where nothing
//! was cut on the far side. The largest heights on the grid are then refined by a
//! pattern search over the patch, since a scallop's ridge is a sharp crest between
//! two balls that a grid point rarely hits.
//!
//! One tool a part: the radius and length of the first surface block are taken for all
//! (a part whose surface blocks disagree on them gives no figure).

use shared::nurbs::reference::piegl_tiller_surface;
use shared::path;
use shared::path::sub;
use shared::protocol::CommandBlock;
use std::collections::HashMap;

/// The measured scallop.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Scallop {
    /// The largest height of material left between passes, mm.
    pub max_mm: f64,
    /// Where on the surface.
    pub at_mm: [f64; 3],
    /// Grid points of the surface measured (a ball reached them along the normal).
    pub points: usize,
}

/// Sample points a patch along each of its parameters.
const GRID: usize = 32;
/// Radius about `P + R·n` within which centres are looked for, mm: a ball whose centre
/// is farther to the side leaves `P` more than about `ρ²/(2R)` (over 0.1 mm for a 3 mm
/// ball) of material, far beyond any scallop; and the cut around `P` is judged from them.
const REACH_MM: f64 = 1.0;
/// Grid points refined by the pattern search, the highest first.
const REFINED: usize = 24;

/// The ball centres in a uniform grid of cells of [`REACH_MM`].
struct Centres {
    cells: HashMap<[i64; 3], Vec<[f64; 3]>>,
}

impl Centres {
    fn new(centres: impl Iterator<Item = [f64; 3]>) -> Self {
        let mut cells: HashMap<[i64; 3], Vec<[f64; 3]>> = HashMap::new();
        for c in centres {
            cells.entry(cell(c)).or_default().push(c);
        }
        Centres { cells }
    }

    /// Every centre within [`REACH_MM`] of `q`.
    fn near(&self, q: [f64; 3], out: &mut Vec<[f64; 3]>) {
        out.clear();
        let k = cell(q);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(v) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        out.extend(v.iter().filter(|c| dist(**c, q) <= REACH_MM));
                    }
                }
            }
        }
    }
}

fn cell(p: [f64; 3]) -> [i64; 3] {
    p.map(|x| (x / REACH_MM).floor() as i64)
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn dist(a: [f64; 3], b: [f64; 3]) -> f64 {
    path::norm(sub(a, b))
}

/// The material left at surface point `p` (unit normal `n` to the tool's side) by balls
/// of radius `r` about `near` (the centres near `p + r·n`); `None` where no ball reaches
/// along the normal.
fn left_at(p: [f64; 3], n: [f64; 3], r: f64, near: &[[f64; 3]]) -> Option<f64> {
    let mut best = f64::INFINITY;
    for c in near {
        let w = sub(p, *c);
        let (b, cc) = (dot(n, w), dot(w, w) - r * r);
        if cc <= 0.0 {
            best = 0.0;
            continue;
        }
        let disc = b * b - cc;
        if disc >= 0.0 {
            let t = -b - disc.sqrt();
            if t >= 0.0 {
                best = best.min(t);
            }
        }
    }
    best.is_finite().then_some(best)
}

/// Do the centres `near`, seen in the tangent plane at `p` from above `p + r·n`, leave
/// no angular gap of half a turn or more?
fn surrounded(p: [f64; 3], n: [f64; 3], r: f64, near: &[[f64; 3]]) -> bool {
    let q = [p[0] + r * n[0], p[1] + r * n[1], p[2] + r * n[2]];
    // Two directions in the tangent plane.
    let a = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let e1 = {
        let d = dot(a, n);
        let v = [a[0] - d * n[0], a[1] - d * n[1], a[2] - d * n[2]];
        let l = path::norm(v);
        v.map(|x| x / l)
    };
    let e2 = [
        n[1] * e1[2] - n[2] * e1[1],
        n[2] * e1[0] - n[0] * e1[2],
        n[0] * e1[1] - n[1] * e1[0],
    ];
    let mut angles: Vec<f64> = near
        .iter()
        .filter_map(|c| {
            let d = sub(*c, q);
            let (x, y) = (dot(d, e1), dot(d, e2));
            (x.hypot(y) > 1e-9).then(|| y.atan2(x))
        })
        .collect();
    if angles.len() < 3 {
        return false;
    }
    angles.sort_by(f64::total_cmp);
    let wrap = angles[0] + std::f64::consts::TAU - angles[angles.len() - 1];
    let widest = angles.windows(2).map(|w| w[1] - w[0]).fold(wrap, f64::max);
    widest < std::f64::consts::PI
}

/// The surface blocks of `blocks`, each patch once (its control points and the side the
/// tool is on): the passes of a part share their patches.
pub fn distinct_patches<'a>(
    blocks: impl IntoIterator<Item = &'a CommandBlock>,
) -> Vec<&'a CommandBlock> {
    let mut seen = std::collections::HashSet::new();
    blocks
        .into_iter()
        .filter(|b| b.is_surface())
        .filter(|b| {
            let key: Vec<u64> = b
                .ctrl()
                .iter()
                .flatten()
                .map(|x| x.to_bits())
                .chain([b.degree as u64, b.surface.degree_v as u64])
                .chain([b.surface.normal_sign as u64])
                .collect();
            seen.insert(key)
        })
        .collect()
}

/// What the measurement needs: the tool, the ball centres and the distinct patches.
struct Setup<'a> {
    r: f64,
    centres: Centres,
    patches: Vec<&'a CommandBlock>,
}

impl<'a> Setup<'a> {
    /// `None` for a run without surface blocks, or with more than one tool.
    fn new(blocks: &'a [CommandBlock], positions: &[[f64; 3]]) -> Option<Self> {
        let surface: Vec<&CommandBlock> = blocks.iter().filter(|b| b.is_surface()).collect();
        let first = surface.first()?;
        let (r, h) = (first.surface.tool_radius_mm, first.surface.tool_length_mm);
        if surface
            .iter()
            .any(|b| b.surface.tool_radius_mm != r || b.surface.tool_length_mm != h)
            || r <= 0.0
        {
            return None;
        }
        let lift = h - r;
        let ball = |m: [f64; 3]| [m[0], m[1], m[2] - lift];
        let centres = Centres::new(positions.iter().map(|m| ball(*m)));
        let patches = distinct_patches(surface.iter().copied());
        Some(Setup {
            r,
            centres,
            patches,
        })
    }

    /// The height at `(u, v)` of patch `b` and the point, where a ball reaches along the
    /// normal; with `judge`, only where the cut surrounds the point.
    fn height(
        &self,
        b: &CommandBlock,
        uv: (f64, f64),
        judge: bool,
        near: &mut Vec<[f64; 3]>,
    ) -> Option<(f64, [f64; 3])> {
        let (t, p, n) = self.probe(b, uv, near)?;
        (!judge || surrounded(p, n, self.r, near)).then_some((t, p))
    }

    /// The height at `(u, v)` of patch `b`, the point and its normal (to the tool's
    /// side), where a ball reaches along the normal; `near` is left holding the centres
    /// near the point.
    fn probe(
        &self,
        b: &CommandBlock,
        (u, v): (f64, f64),
        near: &mut Vec<[f64; 3]>,
    ) -> Option<(f64, [f64; 3], [f64; 3])> {
        let r = self.r;
        let e = piegl_tiller_surface(&path::patch(b), u, v);
        let sign = f64::from(b.surface.normal_sign);
        let n = e.normal.map(|x| x * sign);
        if path::norm(n) < 0.5 {
            return None;
        }
        self.centres.near(
            [e.p[0] + r * n[0], e.p[1] + r * n[1], e.p[2] + r * n[2]],
            near,
        );
        Some((left_at(e.p, n, r, near)?, e.p, n))
    }

    /// The grid: `(u, v)` of each of its points on a patch.
    fn grid() -> impl Iterator<Item = (f64, f64)> {
        (0..=GRID)
            .flat_map(|i| (0..=GRID).map(move |j| (i as f64 / GRID as f64, j as f64 / GRID as f64)))
    }
}

/// The measured scallop of a run whose command log holds `blocks`, from the machine's
/// positions (tool reference points) every cycle; `None` for a run without surface
/// blocks, or with more than one tool.
pub fn measure(blocks: &[CommandBlock], positions: &[[f64; 3]]) -> Option<Scallop> {
    let setup = Setup::new(blocks, positions)?;
    let patches = &setup.patches;
    let mut near = Vec::new();
    // The grid: (height, patch, u, v) of every point a ball reaches.
    let mut found: Vec<(f64, usize, f64, f64)> = Vec::new();
    for (k, b) in patches.iter().enumerate() {
        for (u, v) in Setup::grid() {
            if let Some((t, _)) = setup.height(b, (u, v), false, &mut near) {
                found.push((t, k, u, v));
            }
        }
    }
    let points = found.len();
    // The highest grid points the cut surrounds (judged only for those, highest first:
    // the judgement sorts the centres around the point), then the crest near each by a
    // pattern search over (u, v), its step halved whenever no neighbour is higher.
    found.sort_by(|a, b| b.0.total_cmp(&a.0));
    let mut worst: Option<Scallop> = None;
    let mut refined = 0;
    for &(_, k, u0, v0) in &found {
        if refined == REFINED {
            break;
        }
        let b = patches[k];
        let Some((t0, p0)) = setup.height(b, (u0, v0), true, &mut near) else {
            continue;
        };
        refined += 1;
        let (mut best, mut at, mut u, mut v) = (t0, p0, u0, v0);
        let mut step = 1.0 / GRID as f64;
        while step > 1e-7 {
            let mut moved = false;
            for (du, dv) in [(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)] {
                let (uu, vv) = (u + du * step, v + dv * step);
                if !(0.0..=1.0).contains(&uu) || !(0.0..=1.0).contains(&vv) {
                    continue;
                }
                if let Some((t, p)) = setup.height(b, (uu, vv), true, &mut near) {
                    if t > best {
                        (best, at, u, v) = (t, p, uu, vv);
                        moved = true;
                    }
                }
            }
            if !moved {
                step *= 0.5;
            }
        }
        if worst.is_none_or(|w| best > w.max_mm) {
            worst = Some(Scallop {
                max_mm: best,
                at_mm: at,
                points,
            });
        }
    }
    worst
}

/// One point of the scallop map: a grid point of the surface and the material left
/// there (mm), `None` where the cut does not surround the point (the surface's edges
/// outside the first and last passes), which is not judged.
pub type MapPoint = ([f64; 3], Option<f64>);

/// The scallop over the whole surface ([`map`]).
#[derive(Debug, Clone)]
pub struct ScallopMap {
    /// Points a patch's grid has along each parameter.
    pub grid: usize,
    /// For each distinct patch, its `grid × grid` points row by row in `u` (`None` where
    /// no ball reached along the normal).
    pub patches: Vec<Vec<Option<MapPoint>>>,
}

/// The scallop over the whole surface, on a grid of about `budget` points in all (at
/// least 9 × 9 a patch, at most 129 × 129): what the page draws as a map. The same
/// measure as [`measure`]'s, not refined, so its largest value on [`measure`]'s grid is
/// at most [`measure`]'s.
pub fn map(blocks: &[CommandBlock], positions: &[[f64; 3]], budget: usize) -> Option<ScallopMap> {
    let setup = Setup::new(blocks, positions)?;
    let per_patch = budget / setup.patches.len().max(1);
    let grid = ((per_patch as f64).sqrt() as usize).clamp(9, 129);
    let mut near = Vec::new();
    let mut patches = Vec::new();
    for b in &setup.patches {
        patches.push(
            (0..grid * grid)
                .map(|k| {
                    let uv = (
                        (k / grid) as f64 / (grid - 1) as f64,
                        (k % grid) as f64 / (grid - 1) as f64,
                    );
                    let (t, p, n) = setup.probe(b, uv, &mut near)?;
                    Some((p, surrounded(p, n, setup.r, &near).then_some(t)))
                })
                .collect(),
        );
    }
    Some(ScallopMap { grid, patches })
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared::protocol::{BlockKind, FLAG_SURFACE};

    /// A flat patch `z = 0` over `[0, 20]²` (bilinear), tool on top.
    fn flat_patch(r: f64, h: f64) -> CommandBlock {
        let mut b = CommandBlock::empty(BlockKind::Motion, 0, 1);
        b.flags = FLAG_SURFACE;
        b.degree = 1;
        b.surface.degree_v = 1;
        b.n_ctrl = 4;
        for (i, x) in [0.0, 20.0].into_iter().enumerate() {
            for (j, y) in [0.0, 20.0].into_iter().enumerate() {
                b.ctrl[2 * i + j] = [x, y, 0.0, 1.0];
            }
        }
        b.surface.uv_start = [0.5, 0.0];
        b.surface.uv_end = [0.5, 1.0];
        b.surface.tool_radius_mm = r;
        b.surface.tool_length_mm = h;
        b.surface.normal_sign = 1;
        b
    }

    /// The tool reference points of 20 passes along Y, `w` apart in X from X4, a step
    /// of 0.04 mm, with the tool of length `h`.
    fn parallel_passes(w: f64, h: f64) -> Vec<[f64; 3]> {
        (0..20)
            .flat_map(|k| (0..=500).map(move |s| [4.0 + k as f64 * w, s as f64 * 0.04, h]))
            .collect()
    }

    /// Passes along Y, `w` apart in X, over a flat surface: the scallop between two is
    /// `R − √(R² − (w/2)²)` exactly (the balls' crest halfway), and the measurement
    /// finds it from the tool reference points of a step of 0.04 mm.
    #[test]
    fn parallel_passes_on_a_plane_leave_the_closed_form_scallop() {
        let (r, h, w) = (3.0, 40.0, 0.6);
        let b = flat_patch(r, h);
        let positions = parallel_passes(w, h);
        let got = measure(&[b], &positions).unwrap();
        let exact = r - (r * r - (w / 2.0).powi(2)).sqrt();
        // Between consecutive cycles' balls the sweep could cut the crest lower by at
        // most 0.02²/(2·3) mm, 0.07 µm, which the measurement leaves out.
        assert!(
            (got.max_mm - exact).abs() < 1e-4,
            "measured {} mm, exact {exact} mm",
            got.max_mm
        );
        assert!(got.points > 500, "{got:?}");
        // The crest lies between two passes, not at the edges outside them.
        assert!(
            got.at_mm[0] > 4.0 && got.at_mm[0] < 4.0 + 19.0 * w,
            "{got:?}"
        );
    }

    /// The map of the same passes: its judged heights reach the closed form between
    /// passes without passing the measured maximum, and the surface outside the first
    /// and last passes is not judged.
    #[test]
    fn the_map_of_parallel_passes_judges_only_between_them() {
        let (r, h, w) = (3.0, 40.0, 0.6);
        let b = flat_patch(r, h);
        let positions = parallel_passes(w, h);
        let blocks = [b];
        let worst = measure(&blocks, &positions).unwrap();
        let map = map(&blocks, &positions, 40_000).unwrap();
        assert_eq!(map.patches.len(), 1);
        assert_eq!(map.grid, 129);
        let exact = r - (r * r - (w / 2.0).powi(2)).sqrt();
        let points: Vec<MapPoint> = map.patches[0].iter().flatten().copied().collect();
        let judged: Vec<(f64, f64)> = points
            .iter()
            .filter_map(|(p, t)| t.map(|t| (p[0], t)))
            .collect();
        let highest = judged.iter().map(|j| j.1).fold(0.0, f64::max);
        assert!(
            highest <= worst.max_mm + 1e-12,
            "{highest} above {}",
            worst.max_mm
        );
        // The grid (20/128 mm) falls within 0.08 mm of a crest: the height there is at
        // least the crest's less that step's drop on the ball, (0.08)²/(2·3) mm.
        assert!(highest > exact - 0.0011, "{highest} against {exact}");
        for (x, _) in &judged {
            assert!(*x > 4.0 && *x < 4.0 + 19.0 * w, "judged at x {x}");
        }
        // Beyond the outer passes (x < 3.5 or x > 15.9) the balls reach the plane along
        // its normal only within their radius: reached, but not judged.
        assert!(points
            .iter()
            .any(|(p, t)| t.is_none() && (p[0] < 3.9 || p[0] > 15.5)));
    }

    /// Without positions near the surface nothing is surrounded: no figure.
    #[test]
    fn a_run_that_never_cuts_measures_nothing() {
        let b = flat_patch(3.0, 40.0);
        let positions: Vec<[f64; 3]> = (0..100).map(|i| [i as f64 * 0.1, 5.0, 90.0]).collect();
        assert_eq!(measure(&[b], &positions), None);
        assert_eq!(measure(&[], &positions), None);
    }
}
