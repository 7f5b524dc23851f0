//! One linear axis: a cascaded position loop (P, gain Kv) and velocity loop (PI) driving a
//! rigid mass (motor inertia reflected to the axis plus load) with viscous and Coulomb
//! friction, a force limit and a quantised encoder, with velocity and acceleration
//! feed-forward. Integrated with semi-implicit Euler in fixed sub-steps, so the result
//! depends only on the set-points (deterministic: the same set-points give bit-identical
//! feedback).
//!
//! The feed-forward values are held over the period, as the set-point gives them: the
//! interpolator's velocity is the period's chord over the period, which is exactly the slope
//! of the linear position interpolation the drive makes within the period, so holding it
//! keeps position command and velocity feed-forward consistent.

use shared::machine::Servo;

#[derive(Debug, Clone, Copy, Default)]
pub struct Axis {
    /// True position and velocity of the load (mm, mm/s).
    pub x_mm: f64,
    pub v_mm_per_s: f64,
    integral: f64,
    /// The last set-point, interpolated from within a period.
    last_cmd_mm: f64,
    /// The drive sat at its force limit in the last step.
    pub saturated: bool,
}

impl Axis {
    pub fn at(x_mm: f64) -> Self {
        Axis {
            x_mm,
            last_cmd_mm: x_mm,
            ..Axis::default()
        }
    }

    /// Measured position: what the encoder reports.
    pub fn measured_mm(&self, p: &Servo) -> f64 {
        (self.x_mm / p.encoder_resolution_mm).round() * p.encoder_resolution_mm
    }

    /// Advances one interpolation period of `dt_s` towards the set-point `cmd_mm`, with
    /// velocity and acceleration feed-forward.
    pub fn step(&mut self, p: &Servo, dt_s: f64, cmd_mm: f64, vel_ff: f64, acc_ff: f64) {
        let n = p.substeps.max(1);
        let h = dt_s / n as f64;
        let ti_s = p.vel_ti_ms * 1e-3;
        let mass_kg = p.total_mass_kg();
        self.saturated = false;
        for i in 1..=n {
            // The drive interpolates the set-point linearly across the period.
            let frac = i as f64 / n as f64;
            let cmd = self.last_cmd_mm + (cmd_mm - self.last_cmd_mm) * frac;
            let v_cmd = p.kv_per_s * (cmd - self.measured_mm(p)) + p.vel_ff * vel_ff;
            let ev = v_cmd - self.v_mm_per_s;
            let mut force = p.vel_kp_n_per_mm_s * (ev + self.integral / ti_s)
                + p.acc_ff * mass_kg * acc_ff * 1e-3;
            if force.abs() > p.force_limit_n {
                force = force.signum() * p.force_limit_n;
                self.saturated = true;
            } else {
                // Anti-windup: integrate only while the drive is not saturated.
                self.integral += ev * h;
            }
            let friction =
                p.viscous_n_per_mm_s * self.v_mm_per_s + p.coulomb_n * self.v_mm_per_s.signum();
            let net = force - friction;
            // Stiction: at rest, Coulomb friction holds the axis until the force exceeds it.
            if self.v_mm_per_s == 0.0 && force.abs() <= p.coulomb_n {
                continue;
            }
            // F = m·a with a in mm/s²: a = F / m · 1000.
            let v_new = self.v_mm_per_s + net / mass_kg * 1e3 * h;
            // Friction cannot reverse the motion within a step.
            self.v_mm_per_s = if self.v_mm_per_s != 0.0
                && v_new.signum() != self.v_mm_per_s.signum()
                && force.abs() <= p.coulomb_n
            {
                0.0
            } else {
                v_new
            };
            self.x_mm += self.v_mm_per_s * h;
        }
        self.last_cmd_mm = cmd_mm;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(p: &Servo, v: f64, cycles: usize) -> (Axis, f64) {
        let mut ax = Axis::at(0.0);
        let dt = 1e-3;
        let mut max_err = 0.0f64;
        for k in 1..=cycles {
            let cmd = v * k as f64 * dt;
            ax.step(p, dt, cmd, v, 0.0);
            max_err = max_err.max((cmd - ax.measured_mm(p)).abs());
        }
        (ax, max_err)
    }

    #[test]
    fn follows_a_step_and_settles() {
        let p = Servo::default();
        let mut ax = Axis::at(0.0);
        for _ in 0..1000 {
            ax.step(&p, 1e-3, 1.0, 0.0, 0.0);
        }
        assert!(
            (ax.measured_mm(&p) - 1.0).abs() <= 2.0 * p.encoder_resolution_mm,
            "x = {}",
            ax.x_mm
        );
    }

    #[test]
    fn feed_forward_shrinks_following_error() {
        let with = Servo::default();
        let without = Servo {
            vel_ff: 0.0,
            acc_ff: 0.0,
            ..Servo::default()
        };
        let (_, e_ff) = ramp(&with, 50.0, 2000);
        let (_, e_no) = ramp(&without, 50.0, 2000);
        // Without feed-forward a P position loop lags by v/Kv = 50/50 = 1 mm at steady state.
        assert!((e_no - 1.0).abs() < 0.1, "lag without FF {e_no}");
        assert!(e_ff < e_no / 10.0, "with FF {e_ff} vs without {e_no}");
    }

    /// Without feed-forward and with a velocity loop far faster than Kv, the position loop
    /// is the first-order lag `Kv / (s + Kv)`: a sine of angular frequency ω comes out
    /// with amplitude `Kv / √(Kv² + ω²)` (closed form) once the start has died out.
    #[test]
    fn without_feed_forward_the_position_loop_is_a_first_order_lag() {
        let p = Servo {
            vel_ff: 0.0,
            acc_ff: 0.0,
            coulomb_n: 0.0,
            encoder_resolution_mm: 1e-7,
            ..Servo::default()
        };
        assert!(p.velocity_bandwidth_rad_per_s() >= 40.0 * p.kv_per_s);
        let (amp, w, dt) = (10.0, 20.0, 1e-3);
        let mut ax = Axis::at(0.0);
        let mut peak = 0.0f64;
        for k in 1..=3000 {
            let t = k as f64 * dt;
            ax.step(&p, dt, amp * (w * t).sin(), 0.0, 0.0);
            if t > 1.0 {
                peak = peak.max(ax.x_mm.abs());
            }
        }
        let expected = amp * p.kv_per_s / (p.kv_per_s.powi(2) + w * w).sqrt();
        assert!(
            (peak - expected).abs() < 0.005 * amp,
            "peak {peak} mm, first-order lag gives {expected} mm"
        );
    }

    #[test]
    fn deterministic() {
        let p = Servo::default();
        let (a, _) = ramp(&p, 33.3, 500);
        let (b, _) = ramp(&p, 33.3, 500);
        assert_eq!(a.x_mm.to_bits(), b.x_mm.to_bits());
    }
}
