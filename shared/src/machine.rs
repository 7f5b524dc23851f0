//! The machine file: limits the planner and the interpolator respect and the model the
//! servo simulation plays. TOML, every field optional (defaults are a small, stiff
//! three-axis mill).

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Machine {
    /// Rapid (G0) traverse rate along the path.
    pub rapid_mm_per_min: f64,
    /// Highest programmable feed; larger F words are clamped to it (and reported).
    pub max_feed_mm_per_min: f64,
    /// Path acceleration used by the speed profile and the curvature limit.
    pub path_acc_mm_per_s2: f64,
    /// Largest allowed deviation of a chord between consecutive set-points from the curve.
    pub chord_tolerance_mm: f64,
    /// Corners sharper than this (between the tangents of consecutive blocks) are taken
    /// with an exact stop.
    pub corner_angle_deg: f64,
    /// Following error that stops the machine with a fault.
    pub max_following_error_mm: f64,
    pub servo: Servo,
}

impl Default for Machine {
    fn default() -> Self {
        Machine {
            rapid_mm_per_min: 10_000.0,
            max_feed_mm_per_min: 10_000.0,
            path_acc_mm_per_s2: 2_000.0,
            chord_tolerance_mm: 0.001,
            corner_angle_deg: 5.0,
            max_following_error_mm: 2.0,
            servo: Servo::default(),
        }
    }
}

/// One model for each of the three linear axes: a cascaded position (P) and velocity (PI)
/// loop over a rigid mass with viscous and Coulomb friction, a force limit and a
/// quantised encoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Servo {
    /// Position loop gain Kv in 1/s.
    pub kv_per_s: f64,
    /// Velocity loop proportional gain in N/(mm/s).
    pub vel_kp_n_per_mm_s: f64,
    /// Velocity loop integral time in ms.
    pub vel_ti_ms: f64,
    /// Moving mass of the axis (motor inertia reflected to the axis plus load) in kg.
    pub mass_kg: f64,
    /// Viscous friction in N/(mm/s).
    pub viscous_n_per_mm_s: f64,
    /// Coulomb friction in N.
    pub coulomb_n: f64,
    /// Drive force limit in N.
    pub force_limit_n: f64,
    /// Encoder resolution in mm.
    pub encoder_mm: f64,
    /// Velocity feed-forward gain (0 off, 1 full).
    pub vel_ff: f64,
    /// Acceleration feed-forward gain (0 off, 1 full).
    pub acc_ff: f64,
    /// Simulation sub-steps per interpolation period.
    pub substeps: u32,
}

impl Default for Servo {
    fn default() -> Self {
        Servo {
            kv_per_s: 50.0,
            vel_kp_n_per_mm_s: 20.0,
            vel_ti_ms: 10.0,
            mass_kg: 50.0,
            viscous_n_per_mm_s: 0.05,
            coulomb_n: 20.0,
            force_limit_n: 5_000.0,
            encoder_mm: 0.000_1,
            vel_ff: 1.0,
            acc_ff: 1.0,
            substeps: 10,
        }
    }
}

impl Machine {
    /// Reads a machine file; unknown keys are errors so a typo never passes silently.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        let m: Machine = toml::from_str(text).map_err(|e| e.to_string())?;
        m.check()?;
        Ok(m)
    }

    /// Every limit positive and finite.
    pub fn check(&self) -> Result<(), String> {
        let s = &self.servo;
        let named = [
            ("rapid_mm_per_min", self.rapid_mm_per_min),
            ("max_feed_mm_per_min", self.max_feed_mm_per_min),
            ("path_acc_mm_per_s2", self.path_acc_mm_per_s2),
            ("chord_tolerance_mm", self.chord_tolerance_mm),
            ("corner_angle_deg", self.corner_angle_deg),
            ("max_following_error_mm", self.max_following_error_mm),
            ("servo.kv_per_s", s.kv_per_s),
            ("servo.vel_kp_n_per_mm_s", s.vel_kp_n_per_mm_s),
            ("servo.vel_ti_ms", s.vel_ti_ms),
            ("servo.mass_kg", s.mass_kg),
            ("servo.force_limit_n", s.force_limit_n),
            ("servo.encoder_mm", s.encoder_mm),
        ];
        for (name, v) in named {
            if !v.is_finite() || v <= 0.0 {
                return Err(format!("{name} must be a positive number, got {v}"));
            }
        }
        if s.substeps == 0 {
            return Err("servo.substeps must be at least 1".into());
        }
        Ok(())
    }

    /// The default machine file, as TOML.
    pub fn default_toml() -> String {
        Machine::default().to_toml()
    }

    /// Fingerprint of this machine (FNV-1a of its canonical TOML): what a command log
    /// records, so a replay can tell it runs on the same machine.
    pub fn hash(&self) -> u64 {
        crate::cmdlog::fnv1a64(self.to_toml().as_bytes())
    }

    /// This machine as a TOML machine file.
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }
}

/// Loads the machine file at `path`, or the default machine when there is none. The error
/// names the file.
pub fn load(path: Option<&std::path::Path>) -> Result<Machine, String> {
    match path {
        None => Ok(Machine::default()),
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()))?;
            Machine::from_toml(&text).map_err(|e| format!("{}: {e}", p.display()))
        }
    }
}
