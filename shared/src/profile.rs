//! Jerk-limited speed along a path: the closed forms the planner and the interpolator
//! share, so that what the planner promises the interpolator can keep.
//!
//! The state is the path speed `v` and the path (tangential) acceleration `a`; the
//! acceleration is limited to `|a| <= acc` and changes at most at `jerk` per second (an
//! S-curve). A speed change between two states of zero acceleration takes, with the
//! quickest jerk-limited profile, `T = dv/acc + acc/jerk` when `dv >= acc²/jerk` (the
//! acceleration saturates) and `T = 2·sqrt(dv/jerk)` otherwise; that profile is
//! point-symmetric in time, so the distance it covers is the mean speed times `T`.

/// Path acceleration and jerk limits, both positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limits {
    /// mm/s²
    pub acc: f64,
    /// mm/s³
    pub jerk: f64,
}

impl Limits {
    /// Time (s) of the quickest speed change `dv >= 0` from rest acceleration to rest
    /// acceleration.
    #[inline]
    pub fn change_time(&self, dv: f64) -> f64 {
        let dv = dv.max(0.0);
        if dv * self.jerk >= self.acc * self.acc {
            dv / self.acc + self.acc / self.jerk
        } else {
            2.0 * (dv / self.jerk).sqrt()
        }
    }

    /// Distance (mm) of the quickest speed change between `v0` and `v1`, with zero
    /// acceleration at both ends (it is the same going up or down).
    #[inline]
    pub fn change_distance(&self, v0: f64, v1: f64) -> f64 {
        0.5 * (v0 + v1) * self.change_time((v0 - v1).abs())
    }

    /// `change_distance(v0, v1) <= d` for speeds `v0, v1 >= 0`, without the square root
    /// and divisions (squared and multiplied out): the same answer up to rounding, for
    /// the searches that ask it many times a cycle.
    #[inline]
    pub fn change_within(&self, v0: f64, v1: f64, d: f64) -> bool {
        let (acc, jerk) = (self.acc, self.jerk);
        let dv = (v0 - v1).abs();
        let sum = v0 + v1;
        if dv * jerk >= acc * acc {
            // ½·sum·(dv/acc + acc/jerk) <= d
            0.5 * sum * (dv * jerk + acc * acc) <= d * (acc * jerk)
        } else {
            // sum·√(dv/jerk) <= d
            d >= 0.0 && sum * sum * dv <= d * d * jerk
        }
    }

    /// The highest speed (zero acceleration) from which `v_end` is reached within `d` mm,
    /// or equally the highest speed reachable from `v_end` within `d` mm: the inverse of
    /// [`change_distance`](Self::change_distance), in closed form (the planner calls it
    /// twice a block), a hair below the exact root so that the distance it needs never
    /// exceeds `d` by rounding.
    ///
    /// With `dv` the speed change: while the acceleration does not saturate
    /// (`dv < acc²/jerk`), `d = (2·v_end + dv)·sqrt(dv/jerk)`, a cubic in `s = sqrt(dv)`
    /// with one positive root; beyond, `d = (v_end + dv/2)·(dv/acc + acc/jerk)`, a
    /// quadratic in `dv`. Both are taken in forms free of cancellation.
    pub fn reachable_speed(&self, v_end: f64, d: f64) -> f64 {
        if d <= 0.0 || d.is_nan() {
            return v_end;
        }
        let (acc, jerk) = (self.acc, self.jerk);
        let dv_sat = acc * acc / jerk;
        let dv = if d < self.change_distance(v_end + dv_sat, v_end) {
            // s³ + p·s = q with p = 2·v_end, q = d·sqrt(jerk).
            let (p, q) = (2.0 * v_end, d * jerk.sqrt());
            let s = if p > 0.0 {
                let r = (p / 3.0).sqrt();
                2.0 * r * ((q / (2.0 * r * r * r)).asinh() / 3.0).sinh()
            } else {
                q.cbrt()
            };
            s * s
        } else {
            // dv² + b·dv + c = 0, c < 0 here: the positive root as -2c / (b + sqrt(b² - 4c)).
            let b = 2.0 * v_end + dv_sat;
            let c = 2.0 * v_end * dv_sat - 2.0 * acc * d;
            -2.0 * c / (b + (b * b - 4.0 * c).sqrt())
        };
        // The hair: relative to the speed, whose rounding would otherwise eat it.
        ((v_end + dv) * (1.0 - 1e-12)).max(v_end)
    }

    /// Can a machine at speed `v` and acceleration `a` (`|a| <= acc`) be at a speed of at
    /// most `v_end`, with its acceleration back to zero or below, within `d` mm, braking
    /// as hard as the limits allow? This is the test the interpolator makes every cycle
    /// against each speed limit ahead.
    #[inline]
    pub fn can_reach(&self, v: f64, a: f64, v_end: f64, d: f64) -> bool {
        let j = self.jerk;
        if a >= 0.0 {
            // Bring the acceleration down to zero first: the speed peaks on the way.
            let t = a / j;
            let peak = v + a * t * 0.5;
            if peak <= v_end {
                return true;
            }
            let d_up = v * t + a * t * t * 0.5 - j * t * t * t / 6.0;
            d_up + self.change_distance(peak, v_end) <= d
        } else {
            // Easing off from this braking would run the speed below zero: the path does
            // not reverse, so no limit ahead can be met from here.
            if v < a * a / (2.0 * j) {
                return false;
            }
            if v <= v_end {
                return true;
            }
            // Already braking with -a: this state lies on the quickest profile from the
            // speed `v0` where the braking began at zero acceleration, `t` seconds ago.
            let t = -a / j;
            let v0 = v + a * a / (2.0 * j);
            if v0 - v_end >= a * a / j {
                let behind = v0 * t - j * t * t * t / 6.0;
                self.change_distance(v0, v_end) - behind <= d
            } else {
                // Braking harder than this change needs: ease off at once; the speed
                // passes `v_end` before the acceleration is back to zero, after `t`
                // seconds with `v + a·t + j·t²/2 = v_end`.
                let disc = (a * a - 2.0 * j * (v - v_end)).max(0.0);
                let t = (-a - disc.sqrt()) / j;
                v * t + a * t * t * 0.5 + j * t * t * t / 6.0 <= d
            }
        }
    }
}

/// Where the machine is along the path: speed, acceleration and distance covered.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Motion {
    pub v: f64,
    pub a: f64,
    pub s: f64,
}

impl Motion {
    /// The motion `dt` seconds on, under constant jerk `j`.
    #[inline]
    pub fn after(self, j: f64, dt: f64) -> Motion {
        Motion {
            v: self.v + self.a * dt + 0.5 * j * dt * dt,
            a: self.a + j * dt,
            s: self.s + self.v * dt + 0.5 * self.a * dt * dt + j * dt * dt * dt / 6.0,
        }
    }
}

/// Up to three constant-jerk phases, `(jerk, duration)`; after the last the acceleration
/// is zero and the speed held.
pub type Phases = [(f64, f64); 3];

/// Where `phases` from `m` lead after `dt` seconds. Past their end the motion goes on at
/// the speed reached, without acceleration (never below standstill).
#[inline]
pub fn follow(m: Motion, phases: &Phases, dt: f64) -> Motion {
    let mut m = m;
    let mut left = dt;
    for &(j, d) in phases {
        if left <= 0.0 {
            break;
        }
        let step = d.min(left).max(0.0);
        m = m.after(j, step);
        left -= step;
    }
    if left > 0.0 {
        m.a = 0.0;
        m.v = m.v.max(0.0);
        m.s += m.v * left;
    }
    m
}

impl Limits {
    /// The quickest braking from `m` to the speed `v_end`, ending with zero acceleration:
    /// jerk `-J` down to the peak deceleration, held there if that is the limit, then `+J`
    /// back to zero. A machine that already brakes harder than that eases off at once
    /// (its speed then passes below `v_end`). Empty phases when no braking is needed.
    pub fn brake(&self, m: Motion, v_end: f64) -> Phases {
        let (j, acc) = (self.jerk, self.acc);
        let none = [(0.0, 0.0); 3];
        let peak = if m.a > 0.0 {
            m.v + m.a * m.a / (2.0 * j)
        } else {
            m.v
        };
        if peak <= v_end {
            // Only the acceleration needs to go.
            return if m.a > 0.0 {
                [(-j, m.a / j), (0.0, 0.0), (0.0, 0.0)]
            } else {
                none
            };
        }
        let ap2 = 0.5 * m.a * m.a + j * (m.v - v_end);
        let ap = ap2.max(0.0).sqrt();
        if m.a < 0.0 && -m.a >= ap {
            return [(j, -m.a / j), (0.0, 0.0), (0.0, 0.0)];
        }
        if ap <= acc {
            return [(-j, (m.a + ap) / j), (j, ap / j), (0.0, 0.0)];
        }
        // The deceleration saturates at `acc`: hold it in between. A machine braking
        // harder than `acc` (a block before allowed more) first eases off to it, with
        // `+J`: the phase's speed change is then `(acc² − a²)/2J`, the opposite sign of
        // the ramp down's formula, and its duration `|a + acc|/J` is never negative (a
        // negative one is skipped by `follow` but run backwards by `brake_distance`, so
        // the two would disagree).
        let (j1, dv1) = if m.a < -acc {
            (j, (acc * acc - m.a * m.a) / (2.0 * j))
        } else {
            (-j, (m.a * m.a - acc * acc) / (2.0 * j))
        };
        let dv3 = -acc * acc / (2.0 * j);
        let hold = ((m.v - v_end) + dv1 + dv3) / acc;
        [
            (j1, (m.a + acc).abs() / j),
            (0.0, hold.max(0.0)),
            (j, acc / j),
        ]
    }

    /// Distance the quickest braking from `m` to `v_end` covers (zero when none is
    /// needed).
    pub fn brake_distance(&self, m: Motion, v_end: f64) -> f64 {
        let end = self
            .brake(m, v_end)
            .iter()
            .fold(m, |m, &(j, d)| m.after(j, d));
        end.s - m.s
    }
}

impl Limits {
    /// A cheap, conservative `brake_distance(m, v_end) <= d`: true only where the
    /// quickest braking from `m` to `v_end` provably fits in `d` mm with a margin of
    /// `1e-9·(1 + |d|)` mm (far above the rounding of either computation); false where
    /// it does not fit, and wherever this test cannot tell (then ask
    /// [`brake_distance`](Self::brake_distance)). No square root, one division.
    ///
    /// Where the acceleration `a` lies between `-acc` and `+acc` and a braking is needed
    /// at all, that braking (see [`brake`](Self::brake)) passes through zero
    /// acceleration at the speed `v₀ = v + a·|a|/2J` (the peak for `a >= 0`, where a
    /// braking from zero acceleration began for `a < 0`), and from there on it is the
    /// quickest change from `v₀` to `v_end`, point-symmetric in time: its distance is
    /// the one [`change_within`](Self::change_within) tests. Before that point it covers
    /// `v·τ + a·τ²/2 − J·τ³/6` (`τ = a/J`, the ramp of `a` down to zero) for `a >= 0`;
    /// for `a < 0` that part lies behind, and its distance `v₀·τ − J·τ³/6` (`τ = −a/J`)
    /// is taken off. A state braking harder than this braking needs (it eases off at
    /// once and passes below `v_end`) or than `acc` is left to `brake_distance`.
    #[inline]
    pub fn brake_within(&self, m: Motion, v_end: f64, d: f64) -> bool {
        let (j, acc) = (self.jerk, self.acc);
        let (v, a) = (m.v, m.a);
        if a.is_nan() || a.abs() > acc {
            return false;
        }
        let tau = a.abs() / j;
        let half = 0.5 * a * tau;
        let margin = 1e-9 * (1.0 + d.abs());
        if a >= 0.0 {
            let peak = v + half;
            if peak <= v_end {
                // Only the acceleration is eased off: `brake_distance` covers that ramp.
                return false;
            }
            let up = tau * (v + half - j * tau * tau / 6.0);
            self.change_within(peak, v_end, d - up - margin)
        } else {
            // `a²/2 < J·(v − v_end)`: the braking goes on (it does not ease off at once).
            let room = j * (v - v_end);
            if room.is_nan() || 0.5 * a * a >= room {
                return false;
            }
            let v0 = v - half;
            let behind = tau * (v0 - j * tau * tau / 6.0);
            self.change_within(v0, v_end, d + behind - margin)
        }
    }
}

/// One cycle of the profile: the acceleration moves linearly from `a` to `a1` over the
/// period `t`. Returns the speed at its end and the distance covered.
#[inline]
pub fn integrate(v: f64, a: f64, a1: f64, t: f64) -> (f64, f64) {
    let v1 = v + 0.5 * (a + a1) * t;
    let ds = v * t + (2.0 * a + a1) * t * t / 6.0;
    (v1, ds)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIM: Limits = Limits {
        acc: 2000.0,
        jerk: 50_000.0,
    };

    /// Brakes from (v, a) to v_end with the quickest profile, simulated in tiny steps.
    fn simulate_brake(v: f64, a: f64, v_end: f64) -> f64 {
        let dt = 1e-6;
        let (mut v, mut a, mut s) = (v, a, 0.0);
        // Brake at -acc until easing off (raising the acceleration back to zero) would
        // land on v_end, then ease off; stop once the speed is down to v_end.
        let mut easing = false;
        // Ends when the ease-off is complete (the speed then is v_end to rounding; a test on
        // the speed alone would stop early on a step's rounding, where the speed is flat).
        // A state that already brakes harder than needed passes v_end with a slope: there
        // the speed alone ends it.
        while !(easing && a >= 0.0) && v > v_end - 1e-2 {
            let ease = if a < 0.0 {
                a * a / (2.0 * LIM.jerk)
            } else {
                0.0
            };
            easing |= a < 0.0 && v - ease <= v_end;
            let target = if easing { 0.0 } else { -LIM.acc };
            let a1 = if target > a {
                (a + LIM.jerk * dt).min(target)
            } else {
                (a - LIM.jerk * dt).max(target)
            };
            let (v1, ds) = integrate(v, a, a1, dt);
            v = v1;
            a = a1;
            s += ds;
        }
        s
    }

    #[test]
    fn change_distance_matches_a_simulated_profile() {
        for (v0, v1) in [(100.0, 0.0), (50.0, 10.0), (20.0, 0.0), (5.0, 4.0)] {
            let want = LIM.change_distance(v0, v1);
            let got = simulate_brake(v0, 0.0, v1);
            assert!(
                (got - want).abs() < 1e-3 * want + 1e-6,
                "{v0}->{v1}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn change_within_agrees_with_change_distance() {
        // Both branches, up and down, at and around the boundary: the same answer as the
        // closed form except within 1e-12 (relative) of `d`, where rounding decides.
        for lim in [
            LIM,
            Limits {
                acc: 118.1,
                jerk: 13_362.0,
            },
        ] {
            for v0 in [0.0, 1e-3, 0.7, 10.0, 26.2, 80.0, 500.0] {
                for v1 in [0.0, 0.5, 9.9, 40.0, 300.0] {
                    let cd = lim.change_distance(v0, v1);
                    for f in [0.0, 0.5, 0.999, 1.0 - 1e-9, 1.0, 1.0 + 1e-9, 1.001, 2.0] {
                        for d in [cd * f, cd * f - 1e-9, -1.0] {
                            let want = cd <= d;
                            if lim.change_within(v0, v1, d) != want {
                                assert!((cd - d).abs() <= 1e-12 * cd.max(1e-300), "{v0} {v1} {d}");
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn reachable_speed_inverts_change_distance() {
        // Both branches (saturated or not), from rest and from speed, tiny to huge moves.
        for v_end in [0.0, 1e-3, 10.0, 30.0, 500.0] {
            for d in [1e-9, 1e-4, 0.3, 4.5, 100.0, 1e5] {
                let v = LIM.reachable_speed(v_end, d);
                let got = LIM.change_distance(v, v_end);
                assert!(v >= v_end, "{v_end} {d}: {v}");
                assert!(got <= d, "{v_end} {d}: needs {got}");
                // And it is the highest such speed, to 1e-11 of itself.
                let above = LIM.change_distance(v * (1.0 + 1e-11) + 1e-300, v_end);
                assert!(above > d, "{v_end} {d}: {v} is not the highest");
            }
        }
        assert_eq!(LIM.reachable_speed(7.0, 0.0), 7.0);
    }

    #[test]
    fn can_reach_agrees_with_the_braking_distance_from_any_state() {
        // From a state with acceleration a, the quickest braking distance found by a
        // search over the distance d where can_reach flips equals the simulated one.
        for (v, a, v_end) in [
            (100.0, 0.0, 0.0),
            (60.0, 1500.0, 0.0),
            (60.0, -1500.0, 0.0),
            (60.0, -2000.0, 20.0),
            (40.0, -1800.0, 39.0),
        ] {
            let (mut lo, mut hi) = (0.0, 1000.0);
            for _ in 0..80 {
                let mid = 0.5 * (lo + hi);
                if LIM.can_reach(v, a, v_end, mid) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            let sim = simulate_brake(v, a, v_end);
            assert!(
                hi <= sim * (1.0 + 1e-3) + 1e-6,
                "{v} {a} -> {v_end}: {hi} vs {sim}"
            );
            assert!(
                hi >= sim * (1.0 - 1e-3) - 1e-3,
                "{v} {a} -> {v_end}: {hi} vs {sim}"
            );
        }
    }

    #[test]
    fn brake_lands_on_the_target_speed_with_zero_acceleration() {
        for (v, a, v_end) in [
            (100.0, 0.0, 0.0),
            (60.0, 1500.0, 0.0),
            (60.0, -1500.0, 0.0),
            (60.0, -2000.0, 20.0),
            (5.0, 300.0, 1.0),
        ] {
            let m = Motion { v, a, s: 0.0 };
            let ph = LIM.brake(m, v_end);
            let end = ph.iter().fold(m, |m, &(j, d)| m.after(j, d));
            assert!((end.v - v_end).abs() < 1e-9, "{v} {a}: {end:?}");
            assert!(end.a.abs() < 1e-9, "{end:?}");
            for &(j, d) in &ph {
                assert!(j.abs() <= LIM.jerk && d >= 0.0);
            }
            // The same distance as the closed form the cycle tests with.
            let d = LIM.brake_distance(m, v_end);
            assert!(LIM.can_reach(v, a, v_end, d * (1.0 + 1e-9) + 1e-12));
            assert!(!LIM.can_reach(v, a, v_end, d * (1.0 - 1e-6)));
        }
    }

    #[test]
    fn braking_harder_than_the_limit_eases_off_to_it_first() {
        // A block before allowed more deceleration than this limit: the braking eases
        // off to `-acc` with `+J`, holds it, and lands on the target speed at rest in
        // acceleration; `follow` (which skips negative durations) covers exactly the
        // distance `brake_distance` says.
        for (v, a, v_end) in [
            (100.0, -2500.0, 10.0),
            (41.2, -226.4, 4.5),
            (200.0, -3000.0, 0.0),
        ] {
            let lim = if a < -1000.0 {
                LIM
            } else {
                Limits {
                    acc: 118.1,
                    jerk: 13_362.0,
                }
            };
            let m = Motion { v, a, s: 0.0 };
            let ph = lim.brake(m, v_end);
            for &(j, d) in &ph {
                assert!(j.abs() <= lim.jerk && d >= 0.0, "{ph:?}");
            }
            let end = ph.iter().fold(m, |m, &(j, d)| m.after(j, d));
            assert!((end.v - v_end).abs() < 1e-9, "{v} {a}: {end:?}");
            assert!(end.a.abs() < 1e-9, "{end:?}");
            let total: f64 = ph.iter().map(|p| p.1).sum();
            let followed = follow(m, &ph, total);
            let d = lim.brake_distance(m, v_end);
            assert!(
                (followed.s - d).abs() < 1e-12 * d.max(1.0),
                "{} vs {d}",
                followed.s
            );
        }
    }

    #[test]
    fn brake_within_never_says_yes_where_the_braking_does_not_fit() {
        // Against `brake_distance` (the phases of `brake` followed: a second computation):
        // over states accelerating and braking, below and above the target, under two
        // sets of limits, `brake_within` is never true for a distance shorter than the
        // braking's, and it is true for every distance 1e-6 (relative) longer where the
        // acceleration is within `±acc` and the braking does not ease off at once.
        let mut yes = 0;
        for lim in [
            LIM,
            Limits {
                acc: 118.1,
                jerk: 13_362.0,
            },
        ] {
            for v in [0.0, 0.3, 5.0, 26.2, 80.0, 400.0] {
                for af in [-1.5, -1.0, -0.6, -0.2, 0.0, 0.1, 0.5, 1.0, 1.3] {
                    let a = af * lim.acc;
                    for v_end in [0.0, 1.0, 4.9, 25.0, 79.0] {
                        let m = Motion { v, a, s: 0.0 };
                        let bd = lim.brake_distance(m, v_end);
                        for f in [0.0, 0.5, 1.0 - 1e-12, 1.0, 1.0 + 1e-12] {
                            let d = bd * f;
                            assert!(!lim.brake_within(m, v_end, d), "{v} {a} {v_end} {d}");
                        }
                        let fits = lim.brake_within(m, v_end, bd * (1.0 + 1e-6) + 1e-6);
                        let regular = a.abs() <= lim.acc
                            && v + a * a.abs() / (2.0 * lim.jerk) > v_end
                            && (a >= 0.0 || 0.5 * a * a < lim.jerk * (v - v_end));
                        assert_eq!(fits, regular, "{v} {a} {v_end}: {bd}");
                        yes += fits as usize;
                    }
                }
            }
        }
        assert!(yes > 200, "{yes}");
    }

    #[test]
    fn integrate_is_exact_for_a_linear_acceleration() {
        let (v1, ds) = integrate(10.0, 100.0, 200.0, 0.01);
        assert!((v1 - 11.5).abs() < 1e-12);
        // s = v t + a t²/2 + j t³/6 with j = 10000.
        assert!((ds - (0.1 + 0.005 + 10000.0 * 1e-6 / 6.0)).abs() < 1e-12);
    }
}
