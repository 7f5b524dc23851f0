//! The blend's shape chosen for the machine it runs on.
//!
//! [`super::RATIOS`] holds the shape that minimises the blend's peak rate of change of
//! curvature `dκ/ds` for its deviation: right where the jerk binds (the built-in machine,
//! 2 000 mm/s² and 50 000 mm/s³, at every tolerance measured). On a machine whose jerk is
//! high next to its acceleration (LinuxCNC's limits, 1 000 mm/s² and 1e6 mm/s³) the
//! curvature itself binds, and that shape's peak curvature is 1.7 times an arc's through
//! the same trim points (6.5° turn, legs used up): the blend is passed at 0.76 of the
//! speed a rounder one allows.
//!
//! So each corner of a turn up to [`ROUNDER_UP_TO_DEG`] takes, of a few shapes between
//! the table's and a rounder one ([`CANDIDATES`], the table's `c1, c2` plus a share of
//! [`ROUNDER`]), the one whose
//! speed bound is highest: `min(√(A·L/κ̂), ∛(J·L²/κ̂'))` with `κ̂ = κ·L` and
//! `κ̂' = dκ/ds·L²` the peaks of the blend of trim length 1 ([`figures`]), `L` the trim
//! length the shape's deviation and the legs allow, and `A`, `J` the machine's weakest
//! acceleration and jerk at the share the curvature gets (`NORMAL_SHARE`, the jerk
//! weighed down by [`JERK_WEIGHT`]). A tie keeps the table's shape. This only chooses;
//! the planner then plans the blend chosen like any other, and the deviation formula of
//! the module page holds for every shape (each candidate keeps `1 > c1 > c2 >= 0`).

use super::{mid_weight, peaks_of, ratios};
use std::sync::OnceLock;

/// How far the rounder end of the candidates moves `(c1, c2)` from the table's: more of
/// the blend's turn in its middle, a flatter peak of curvature. (Measured on LinuxCNC's
/// limits, 600 lines of 0.5–2 mm turning 3–10° at F6000 under `G64 P0.04`, one shape for
/// every corner: the table's 11.329 s, `+(0.02, 0.07)` 10.349 s, `+(0.06, 0.09)`
/// 10.288 s, `+(0.06, 0.13)` 10.494 s.)
const ROUNDER: (f64, f64) = (0.06, 0.09);

/// The largest turn (degrees) a rounder shape is tried at. Above it the table's is kept:
/// there a blend within a tolerance of hundredths of a millimetre is short next to what
/// the jerk allows, and on a raster of 90° corners (LinuxCNC's limits, `P0.01`, F3000,
/// 3 mm step-over) rounder blends were chosen over exact stops and took 3.384 s against
/// 3.373 s (`tests/blend_pays.rs`). Measured with 30°, 45° and 60° the same everywhere
/// else; 20° lost the 15–30° turns' gain (18.626 → 19.161 s).
const ROUNDER_UP_TO_DEG: f64 = 45.0;

/// The shares of [`ROUNDER`] tried, the table's shape first.
const CANDIDATES: [f64; 4] = [0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0];

/// The weight of the jerk's bound against the acceleration's in [`choose`]: the
/// planner holds the rate of the curvature *vector* (no less than `v³·dκ/ds`) and,
/// where the speed changes along the blend, the `3·v·κ·a` it adds, to the jerk's share,
/// so a shape whose `dκ/ds` is higher gives up more than `∛` of its ratio. Measured on
/// LinuxCNC's limits (sine polyline under a bare `G64` / 600 lines turning 3–10° under
/// `P0.04` / the same under `P0.01` / 15–30° turns): 1.0 gave 13.122 / 10.288 / 12.241 /
/// 18.626 s, 0.6 13.035 / 10.158 / 12.090 / 18.626 s, 0.25 13.038 / 10.662 / 12.638 /
/// 19.088 s (the table's shapes: 13.038 / 11.329 / 12.944 / 19.436 s).
pub(super) const JERK_WEIGHT: f64 = 0.6;

/// Samples of one blend in [`figures`].
const SAMPLES: usize = 128;

/// The highest turn (degrees) the figures are kept for: the whole degree past
/// [`ROUNDER_UP_TO_DEG`].
const LAST_DEG: usize = ROUNDER_UP_TO_DEG as usize + 1;

/// The peak curvature and peak rate of change of curvature (per arc length) of the
/// planar blend of trim length 1 through a turn of `theta` (radians) with the shape
/// `(c1, c2)`, from [`SAMPLES`] samples ([`peaks_of`], as the screen's speed bound).
pub(super) fn figures(c1: f64, c2: f64, theta: f64) -> (f64, f64) {
    let (kappa, rate, _) = peaks_of(control(c1, c2, theta), SAMPLES);
    (kappa, rate)
}

/// The control points of the planar blend of trim length 1 through a turn of `theta`,
/// its corner at the origin (see the module page of [`super`]).
fn control(c1: f64, c2: f64, theta: f64) -> [[f64; 3]; 6] {
    let (s, c) = theta.sin_cos();
    let on1 = |k: f64| [-k, 0.0, 0.0];
    let on2 = |k: f64| [c * k, s * k, 0.0];
    [on1(1.0), on1(c1), on1(c2), on2(c2), on2(c1), on2(1.0)]
}

/// Shape `k` of [`CANDIDATES`] at a turn of `theta_deg`.
fn candidate(theta_deg: f64, k: usize) -> (f64, f64) {
    let (c1, c2) = ratios(theta_deg);
    let share = CANDIDATES[k];
    (c1 + share * ROUNDER.0, c2 + share * ROUNDER.1)
}

/// [`figures`] of each candidate at every whole degree up to [`LAST_DEG`], worked out
/// once (about 24 000 points).
fn table() -> &'static [[(f64, f64); CANDIDATES.len()]] {
    static TABLE: OnceLock<Vec<[(f64, f64); CANDIDATES.len()]>> = OnceLock::new();
    TABLE.get_or_init(|| {
        (0..=LAST_DEG)
            .map(|d| {
                std::array::from_fn(|k| {
                    let (c1, c2) = candidate(d as f64, k);
                    figures(c1, c2, (d as f64).to_radians())
                })
            })
            .collect()
    })
}

/// The limits a blend's curvature may take (mm/s², mm/s³): the machine's weakest, at
/// the curvature's share.
#[derive(Debug, Clone, Copy)]
pub(super) struct Normal {
    pub acc: f64,
    pub jerk: f64,
}

/// The shape `(c1, c2)` and trim length for a turn of `theta` (radians, within
/// `MIN_TURN_RAD..=MAX_TURN_DEG`) within `tol`, its legs allowing at most `half` (half
/// the shorter line): the table's where `normal` is `None` (no machine), else the
/// candidate whose speed bound is highest (see the module page).
pub(super) fn choose(theta: f64, tol: f64, half: f64, normal: Option<Normal>) -> (f64, f64, f64) {
    let deg = theta.to_degrees();
    let trim =
        |c1: f64, c2: f64| (tol / (2.0 * mid_weight(c1, c2) * (0.5 * theta).sin())).min(half);
    let (c1, c2) = ratios(deg);
    let Some(n) = normal.filter(|_| deg <= ROUNDER_UP_TO_DEG) else {
        return (c1, c2, trim(c1, c2));
    };
    let rows = table();
    let lo = (deg.floor().max(0.0) as usize).min(LAST_DEG - 1);
    let f = (deg - lo as f64).clamp(0.0, 1.0);
    let mut best = (c1, c2, trim(c1, c2));
    let mut best_v = f64::NEG_INFINITY;
    for (k, (a, b)) in rows[lo].iter().zip(&rows[lo + 1]).enumerate() {
        let kappa = a.0 + f * (b.0 - a.0);
        let rate = a.1 + f * (b.1 - a.1);
        let (c1, c2) = candidate(deg, k);
        let l = trim(c1, c2);
        let by_acc = if kappa > 0.0 {
            (n.acc * l / kappa).sqrt()
        } else {
            f64::INFINITY
        };
        let by_jerk = if rate > 0.0 {
            (n.jerk * l * l / rate).cbrt()
        } else {
            f64::INFINITY
        };
        let v = by_acc.min(by_jerk);
        if v > best_v {
            best = (c1, c2, l);
            best_v = v;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Curvature of the plane quintic `(c1, c2)` of trim length 1 at `t`, from three
    /// points of the curve itself (the circle through them), not its derivatives.
    fn circle_curvature(c1: f64, c2: f64, theta: f64, t: f64) -> f64 {
        let p = control(c1, c2, theta);
        let h = 1e-4;
        let [a, b, q] = [t - h, t, t + h].map(|x| super::super::de_casteljau(p, x));
        let d = |u: [f64; 3], v: [f64; 3]| (u[0] - v[0]).hypot(u[1] - v[1]);
        let area2 = ((b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0])).abs();
        2.0 * area2 / (d(a, b) * d(b, q) * d(a, q))
    }

    #[test]
    fn the_peak_curvature_matches_a_second_way_of_working_it_out() {
        // Against the circle through three points, sampled 20 times as densely: within
        // 1 % (the peak between `figures`' samples, and the three points' own error).
        for deg in [0.5, 3.0, 10.0, 30.0, 45.0] {
            for k in 0..CANDIDATES.len() {
                let (c1, c2) = candidate(deg, k);
                let theta = f64::to_radians(deg);
                let (kappa, _) = figures(c1, c2, theta);
                let dense = (1..20 * SAMPLES)
                    .map(|i| circle_curvature(c1, c2, theta, i as f64 / (20 * SAMPLES) as f64))
                    .fold(0.0, f64::max);
                assert!(
                    (kappa / dense - 1.0).abs() < 0.01,
                    "{deg}° shape {k}: {kappa} against {dense}"
                );
            }
        }
    }

    #[test]
    fn every_candidate_keeps_the_deviation_formulas_conditions() {
        for d in 0..=LAST_DEG {
            for k in 0..CANDIDATES.len() {
                let (c1, c2) = candidate(d as f64, k);
                assert!(
                    1.0 > c1 && c1 > c2 && c2 >= 0.0,
                    "{d}° shape {k}: {c1} {c2}"
                );
            }
        }
    }

    #[test]
    fn the_table_s_shape_is_kept_where_the_jerk_binds_and_a_rounder_one_where_the_acceleration_does(
    ) {
        let theta = 6.5f64.to_radians();
        let table = ratios(6.5);
        // Without a machine, and on the built-in machine's limits (2 000 mm/s², 50 000
        // mm/s³ at half), the table's.
        let (c1, c2, _) = choose(theta, 0.04, 0.5, None);
        assert_eq!((c1, c2), table);
        let built_in = Normal {
            acc: 1000.0,
            jerk: JERK_WEIGHT * 25_000.0,
        };
        let (c1, c2, _) = choose(theta, 0.04, 0.5, Some(built_in));
        assert_eq!((c1, c2), table);
        // On LinuxCNC's (1 000 mm/s², 1e6 mm/s³ at half) a rounder one, with a lower
        // peak curvature for the same legs.
        let linuxcnc = Normal {
            acc: 500.0,
            jerk: JERK_WEIGHT * 500_000.0,
        };
        let (c1, c2, trim) = choose(theta, 0.04, 0.5, Some(linuxcnc));
        assert!(c1 > table.0 && c2 > table.1, "{c1} {c2}");
        assert_eq!(trim, 0.5);
        assert!(figures(c1, c2, theta).0 < 0.8 * figures(table.0, table.1, theta).0);
    }
}
