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
    /// Path jerk: how fast the path acceleration may change (the S-curve of the profile),
    /// and the limit on the jerk that curvature adds at speed.
    pub path_jerk_mm_per_s3: f64,
    /// Largest allowed deviation of a chord between consecutive set-points from the curve.
    pub chord_tolerance_mm: f64,
    /// Corners sharper than this (between the tangents of consecutive blocks) are taken
    /// with an exact stop.
    pub corner_angle_deg: f64,
    /// Following error that stops the machine with a fault.
    pub max_following_error_mm: f64,
    /// Shortest and longest interpolation period this machine runs (`--period-us`).
    pub min_period_us: u64,
    pub max_period_us: u64,
    /// Look-ahead window of the interpolator, in blocks: it holds this many blocks ahead
    /// of the one it runs and always keeps a speed from which it can stop by the end of
    /// the last one it holds (the planner itself looks over the whole program).
    pub lookahead_blocks: u32,
    /// Per-axis limits: the planner keeps every axis's share of the path motion within
    /// them.
    pub axes: Axes,
    pub servo: Servo,
}

/// The three linear axes' limits.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Axes {
    pub x: AxisLimits,
    pub y: AxisLimits,
    pub z: AxisLimits,
}

impl Default for Axes {
    fn default() -> Self {
        Axes {
            x: AxisLimits::default(),
            y: AxisLimits::default(),
            z: AxisLimits {
                max_vel_mm_per_min: 10_000.0,
                max_acc_mm_per_s2: 2_000.0,
                max_jerk_mm_per_s3: 50_000.0,
                ..AxisLimits::default()
            },
        }
    }
}

impl Axes {
    pub fn as_array(&self) -> [AxisLimits; 3] {
        [self.x, self.y, self.z]
    }
}

/// One axis's velocity, acceleration and jerk limit, and its travel (soft limits).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AxisLimits {
    pub max_vel_mm_per_min: f64,
    pub max_acc_mm_per_s2: f64,
    pub max_jerk_mm_per_s3: f64,
    /// Soft limits, as LinuxCNC's `MIN_LIMIT`/`MAX_LIMIT`: the lowest and highest
    /// commanded position of this axis, in machine coordinates. `cnc check` refuses any
    /// motion whose exact path leaves them and the interpolator refuses such a block again.
    pub min_mm: f64,
    pub max_mm: f64,
}

impl AxisLimits {
    /// Whether `x_mm` lies within this axis's travel.
    pub fn within_travel(&self, x_mm: f64) -> bool {
        x_mm >= self.min_mm && x_mm <= self.max_mm
    }
}

impl Default for AxisLimits {
    fn default() -> Self {
        AxisLimits {
            max_vel_mm_per_min: 15_000.0,
            max_acc_mm_per_s2: 3_000.0,
            max_jerk_mm_per_s3: 100_000.0,
            min_mm: -1_000.0,
            max_mm: 1_000.0,
        }
    }
}

impl Default for Machine {
    fn default() -> Self {
        Machine {
            rapid_mm_per_min: 10_000.0,
            max_feed_mm_per_min: 10_000.0,
            path_acc_mm_per_s2: 2_000.0,
            path_jerk_mm_per_s3: 50_000.0,
            chord_tolerance_mm: 0.001,
            corner_angle_deg: 5.0,
            max_following_error_mm: 2.0,
            min_period_us: 100,
            max_period_us: 10_000,
            lookahead_blocks: 256,
            axes: Axes::default(),
            servo: Servo::default(),
        }
    }
}

/// The axis model: one for each of the three linear axes. A cascaded position loop (P,
/// gain Kv) and velocity loop (PI) over a rigid mass (motor inertia reflected to the axis
/// plus the load) with viscous and Coulomb friction, a drive force (torque/current) limit
/// and a quantised encoder, with velocity and acceleration feed-forward from the
/// set-points.
///
/// Units are in the names. Forces are at the axis: a motor torque `T` (N·m) on a ball
/// screw of lead `p` (mm per revolution) gives `F = T · 2π / (p / 1000)` N, and a rotor
/// inertia `J` (kg·m²) behaves like a mass `J · (2π / (p / 1000))²` kg on the axis.
///
/// The velocity loop's bandwidth is about `vel_kp_n_per_mm_s · 1000 / (motor_inertia_kg +
/// load_kg)` rad/s (2000 rad/s, 320 Hz, by default): 40 times the position loop's Kv, so
/// the position loop behaves as the textbook first-order lag `Kv / (s + Kv)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Servo {
    /// Position loop gain Kv in 1/s (velocity command per mm of following error, mm/s per
    /// mm). Without feed-forward the steady lag at speed `v` is `v / Kv`.
    pub kv_per_s: f64,
    /// Velocity loop proportional gain, in N of drive force per mm/s of velocity error.
    pub vel_kp_n_per_mm_s: f64,
    /// Velocity loop integral (reset) time in ms: the integral part adds `vel_kp` times the
    /// velocity error integrated over this time.
    pub vel_ti_ms: f64,
    /// Motor rotor (and screw, coupling) inertia reflected to the axis, as an equivalent
    /// mass in kg: `J · (2π / lead)²` with `J` in kg·m² and the lead in m.
    pub motor_inertia_kg: f64,
    /// Moving load in kg: table, saddle, fixture and part.
    pub load_kg: f64,
    /// Viscous friction in N per mm/s.
    pub viscous_n_per_mm_s: f64,
    /// Coulomb (dry) friction in N, against the direction of motion; also the stiction
    /// force the drive must exceed to start from rest.
    pub coulomb_n: f64,
    /// Drive force limit in N: the motor's torque (current) limit seen at the axis.
    pub force_limit_n: f64,
    /// Encoder resolution in mm: the measured position is the true one rounded to it.
    #[serde(alias = "encoder_mm")]
    pub encoder_resolution_mm: f64,
    /// Velocity feed-forward gain, 0 to 1: 0 = off, 1 = on (the set-point's velocity is
    /// added to the position loop's velocity command).
    pub vel_ff: f64,
    /// Acceleration feed-forward gain, 0 to 1: 0 = off, 1 = on (mass × the set-point's
    /// acceleration is added to the velocity loop's force command).
    pub acc_ff: f64,
    /// Simulation sub-steps per interpolation period (the loops and the mechanics are
    /// integrated at period / substeps).
    pub substeps: u32,
    /// Older machine files: the whole moving mass in kg. When present it replaces
    /// `motor_inertia_kg + load_kg`; new files leave it out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mass_kg: Option<f64>,
}

impl Servo {
    /// The moving mass the drive accelerates, kg.
    pub fn total_mass_kg(&self) -> f64 {
        self.mass_kg.unwrap_or(self.motor_inertia_kg + self.load_kg)
    }

    /// The velocity loop's bandwidth in rad/s: `vel_kp / mass` (its proportional part over
    /// a rigid mass).
    pub fn velocity_bandwidth_rad_per_s(&self) -> f64 {
        self.vel_kp_n_per_mm_s * 1e3 / self.total_mass_kg()
    }
}

impl Default for Servo {
    /// A stiff, well-tuned axis: Kv 50 1/s, a 2000 rad/s PI velocity loop (critically
    /// damped: `vel_ti = 4 / bandwidth`), 50 kg moving, 20 N dry friction. With both
    /// feed-forwards on it keeps a 20 mm circle at F3000 within 1 µm (the dry friction's
    /// quadrant glitches dominate: with `vel_kp` 20 and `vel_ti` 10 ms they reach 11 µm).
    fn default() -> Self {
        Servo {
            kv_per_s: 50.0,
            vel_kp_n_per_mm_s: 100.0,
            vel_ti_ms: 2.0,
            motor_inertia_kg: 20.0,
            load_kg: 30.0,
            viscous_n_per_mm_s: 0.05,
            coulomb_n: 20.0,
            force_limit_n: 5_000.0,
            encoder_resolution_mm: 0.000_1,
            vel_ff: 1.0,
            acc_ff: 1.0,
            substeps: 10,
            mass_kg: None,
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
            ("path_jerk_mm_per_s3", self.path_jerk_mm_per_s3),
            ("chord_tolerance_mm", self.chord_tolerance_mm),
            ("corner_angle_deg", self.corner_angle_deg),
            ("max_following_error_mm", self.max_following_error_mm),
            ("servo.kv_per_s", s.kv_per_s),
            ("servo.vel_kp_n_per_mm_s", s.vel_kp_n_per_mm_s),
            ("servo.vel_ti_ms", s.vel_ti_ms),
            ("servo.force_limit_n", s.force_limit_n),
            ("servo.encoder_resolution_mm", s.encoder_resolution_mm),
            (
                "servo motor_inertia_kg + load_kg (or mass_kg)",
                s.total_mass_kg(),
            ),
        ];
        let mut axis_named = vec![];
        for (axis, l) in ["x", "y", "z"].iter().zip(self.axes.as_array()) {
            axis_named.push((
                format!("axes.{axis}.max_vel_mm_per_min"),
                l.max_vel_mm_per_min,
            ));
            axis_named.push((
                format!("axes.{axis}.max_acc_mm_per_s2"),
                l.max_acc_mm_per_s2,
            ));
            axis_named.push((
                format!("axes.{axis}.max_jerk_mm_per_s3"),
                l.max_jerk_mm_per_s3,
            ));
        }
        let named = named.iter().map(|(n, v)| (n.to_string(), *v));
        for (name, v) in named.chain(axis_named) {
            if !v.is_finite() || v <= 0.0 {
                return Err(format!("{name} must be a positive number, got {v}"));
            }
        }
        for (axis, l) in ["x", "y", "z"].iter().zip(self.axes.as_array()) {
            if !l.min_mm.is_finite() || !l.max_mm.is_finite() || l.min_mm >= l.max_mm {
                return Err(format!(
                    "axes.{axis}: the travel min_mm ({}) must be below max_mm ({}), both \
                     finite",
                    l.min_mm, l.max_mm
                ));
            }
        }
        if self.min_period_us == 0 || self.min_period_us > self.max_period_us {
            return Err(format!(
                "min_period_us ({}) must be at least 1 and at most max_period_us ({})",
                self.min_period_us, self.max_period_us
            ));
        }
        if !(2..=4096).contains(&self.lookahead_blocks) {
            return Err(format!(
                "lookahead_blocks must be from 2 to 4096, got {}",
                self.lookahead_blocks
            ));
        }
        let non_negative = [
            ("servo.motor_inertia_kg", s.motor_inertia_kg),
            ("servo.load_kg", s.load_kg),
            ("servo.viscous_n_per_mm_s", s.viscous_n_per_mm_s),
            ("servo.coulomb_n", s.coulomb_n),
        ];
        for (name, v) in non_negative {
            if !v.is_finite() || v < 0.0 {
                return Err(format!("{name} must be zero or positive, got {v}"));
            }
        }
        for (name, v) in [("servo.vel_ff", s.vel_ff), ("servo.acc_ff", s.acc_ff)] {
            if !(0.0..=1.0).contains(&v) {
                return Err(format!(
                    "{name} is a feed-forward gain from 0 (off) to 1 (on), got {v}"
                ));
            }
        }
        if s.substeps == 0 {
            return Err("servo.substeps must be at least 1".into());
        }
        Ok(())
    }

    /// Checks that this machine runs at `period_us`; the error says the allowed range.
    pub fn check_period(&self, period_us: u64) -> Result<(), String> {
        if period_us < self.min_period_us || period_us > self.max_period_us {
            return Err(format!(
                "a period of {period_us} µs is outside this machine's range of {} to {} µs \
                 (min_period_us and max_period_us in the machine file)",
                self.min_period_us, self.max_period_us
            ));
        }
        Ok(())
    }

    /// The default machine file, as TOML, each key with a comment giving its meaning and
    /// unit (what `cnc machine` prints).
    pub fn default_toml() -> String {
        let mut out = String::from(
            "# cnc machine file: every key is optional (missing keys take these defaults).\n",
        );
        let mut section = "";
        for line in Machine::default().to_toml().lines() {
            if line.starts_with('[') {
                section = line.trim_matches(|c| c == '[' || c == ']');
                out.push('\n');
            }
            let key = line.split('=').next().unwrap_or("").trim();
            if let Some((_, doc)) = KEY_DOCS.iter().find(|(k, _)| {
                k.rsplit_once('.')
                    .map_or(section.is_empty() && *k == key, |(s, k)| {
                        s == section && k == key
                    })
            }) {
                out.push_str("# ");
                out.push_str(doc);
                out.push('\n');
            }
            out.push_str(line);
            out.push('\n');
        }
        out
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

/// One comment per key of the default machine file.
const KEY_DOCS: &[(&str, &str)] = &[
    (
        "rapid_mm_per_min",
        "rapid (G0) traverse rate along the path, mm/min",
    ),
    (
        "max_feed_mm_per_min",
        "highest programmable feed (larger F words are clamped), mm/min",
    ),
    (
        "path_acc_mm_per_s2",
        "path acceleration of the feed profile and curvature limit, mm/s²",
    ),
    (
        "path_jerk_mm_per_s3",
        "path jerk: rate of change of the path acceleration (S-curve), mm/s³",
    ),
    (
        "min_period_us",
        "shortest interpolation period this machine runs, µs",
    ),
    (
        "max_period_us",
        "longest interpolation period this machine runs, µs",
    ),
    (
        "lookahead_blocks",
        "blocks the interpolator holds ahead; it can always stop by the last one",
    ),
    ("axes.x.max_vel_mm_per_min", "X axis velocity limit, mm/min"),
    (
        "axes.x.max_acc_mm_per_s2",
        "X axis acceleration limit, mm/s²",
    ),
    ("axes.x.max_jerk_mm_per_s3", "X axis jerk limit, mm/s³"),
    (
        "axes.x.min_mm",
        "X soft limit: lowest commanded position (LinuxCNC MIN_LIMIT), mm",
    ),
    (
        "axes.x.max_mm",
        "X soft limit: highest commanded position (LinuxCNC MAX_LIMIT), mm",
    ),
    ("axes.y.max_vel_mm_per_min", "Y axis velocity limit, mm/min"),
    (
        "axes.y.max_acc_mm_per_s2",
        "Y axis acceleration limit, mm/s²",
    ),
    ("axes.y.max_jerk_mm_per_s3", "Y axis jerk limit, mm/s³"),
    (
        "axes.y.min_mm",
        "Y soft limit: lowest commanded position (LinuxCNC MIN_LIMIT), mm",
    ),
    (
        "axes.y.max_mm",
        "Y soft limit: highest commanded position (LinuxCNC MAX_LIMIT), mm",
    ),
    ("axes.z.max_vel_mm_per_min", "Z axis velocity limit, mm/min"),
    (
        "axes.z.max_acc_mm_per_s2",
        "Z axis acceleration limit, mm/s²",
    ),
    ("axes.z.max_jerk_mm_per_s3", "Z axis jerk limit, mm/s³"),
    (
        "axes.z.min_mm",
        "Z soft limit: lowest commanded position (LinuxCNC MIN_LIMIT), mm",
    ),
    (
        "axes.z.max_mm",
        "Z soft limit: highest commanded position (LinuxCNC MAX_LIMIT), mm",
    ),
    (
        "chord_tolerance_mm",
        "largest deviation of a set-point chord from the curve, mm",
    ),
    (
        "corner_angle_deg",
        "corners sharper than this are taken with an exact stop, degrees",
    ),
    (
        "max_following_error_mm",
        "following error that stops the machine with a fault, mm",
    ),
    (
        "servo.kv_per_s",
        "position loop gain Kv, 1/s (mm/s of velocity command per mm of error)",
    ),
    (
        "servo.vel_kp_n_per_mm_s",
        "velocity loop proportional gain, N per mm/s",
    ),
    ("servo.vel_ti_ms", "velocity loop integral time, ms"),
    (
        "servo.motor_inertia_kg",
        "motor (+ screw) inertia reflected to the axis, J·(2π/lead)², kg",
    ),
    ("servo.load_kg", "moving load (table, fixture, part), kg"),
    ("servo.viscous_n_per_mm_s", "viscous friction, N per mm/s"),
    ("servo.coulomb_n", "Coulomb (dry) friction and stiction, N"),
    (
        "servo.force_limit_n",
        "drive force limit at the axis (motor torque/current limit), N",
    ),
    ("servo.encoder_resolution_mm", "encoder resolution, mm"),
    (
        "servo.vel_ff",
        "velocity feed-forward gain: 0 = off, 1 = on",
    ),
    (
        "servo.acc_ff",
        "acceleration feed-forward gain: 0 = off, 1 = on",
    ),
    (
        "servo.substeps",
        "simulation sub-steps per interpolation period",
    ),
];

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_file_is_documented_and_reads_back_as_the_default() {
        let text = Machine::default_toml();
        assert_eq!(Machine::from_toml(&text).unwrap(), Machine::default());
        for (key, _) in KEY_DOCS {
            let name = key.rsplit('.').next().unwrap();
            assert!(text.contains(&format!("\n{name} = ")), "{key} missing");
        }
        assert_eq!(text.matches("\n# ").count(), KEY_DOCS.len(), "{text}");
    }

    #[test]
    fn older_servo_names_still_load() {
        let m = Machine::from_toml("[servo]\nmass_kg = 80.0\nencoder_mm = 0.001\n").unwrap();
        assert_eq!(m.servo.total_mass_kg(), 80.0);
        assert_eq!(m.servo.encoder_resolution_mm, 0.001);
        assert_eq!(Machine::default().servo.total_mass_kg(), 50.0);
    }

    #[test]
    fn travel_is_read_per_axis_and_must_be_an_interval() {
        let m = Machine::from_toml("[axes.x]\nmin_mm = -5.0\nmax_mm = 300.0\n").unwrap();
        assert_eq!((m.axes.x.min_mm, m.axes.x.max_mm), (-5.0, 300.0));
        assert_eq!(m.axes.y.min_mm, -1_000.0);
        assert!(m.axes.x.within_travel(300.0) && !m.axes.x.within_travel(300.001));
        let e = Machine::from_toml("[axes.z]\nmin_mm = 10.0\nmax_mm = 10.0\n").unwrap_err();
        assert!(e.contains("axes.z") && e.contains("min_mm"), "{e}");
    }

    #[test]
    fn feed_forward_gains_are_between_0_and_1() {
        let e = Machine::from_toml("[servo]\nvel_ff = 1.5\n").unwrap_err();
        assert!(e.contains("servo.vel_ff"), "{e}");
        assert!(Machine::from_toml("[servo]\nvel_ff = 0.0\nacc_ff = 0.5\n").is_ok());
    }
}
