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
    /// The corner deviation (mm) that a bare `G64` (no `P`, or `P0`) blends the corners
    /// between feed lines within, and so the mode a program starts in (LinuxCNC and
    /// Fanuc both start in `G64`). LinuxCNC's bare `G64` keeps "the best speed possible,
    /// however far from the programmed point"; a tolerance with no bound is none, so here
    /// the machine builder bounds it (0.01 mm built in). 0: a bare `G64` follows the
    /// exact path as `G61` does. Written (and hashed) only when not the built-in value,
    /// so older runs' machines hash as before.
    #[serde(skip_serializing_if = "Machine::blend_tolerance_is_default")]
    pub blend_tolerance_mm: f64,
    /// Following error that stops the machine with a fault.
    pub max_following_error_mm: f64,
    /// Shortest and longest interpolation period this machine runs (`--period-us`).
    pub min_period_us: u64,
    pub max_period_us: u64,
    /// Look-ahead window of the interpolator, in blocks: it holds this many blocks ahead
    /// of the one it runs and always keeps a speed from which it can stop by the end of
    /// the last one it holds.
    pub lookahead_blocks: u32,
    /// The planner's look-ahead, in moves: a stretch of the program with no rest in it
    /// longer than this is planned about this many moves at a time, each window cut at
    /// speed where the plan allows (the interpreter's `window` module). Written (and
    /// hashed) only when not the built-in value, so older runs' machines hash as before.
    #[serde(skip_serializing_if = "Machine::plan_window_is_default")]
    pub plan_window_moves: u32,
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
    /// `[axes.x.servo]`: this axis's drive where it differs from the shared `[servo]`
    /// (real axes carry different masses and tunings); each key given replaces the
    /// shared one for this axis. Left out of the file (and so of the machine's hash)
    /// when empty, so machine files without it keep their hash and their replays.
    #[serde(default, skip_serializing_if = "ServoOverride::is_empty")]
    pub servo: ServoOverride,
}

/// One axis's changes to the shared servo model: each key given replaces the shared
/// value (see [`Servo`] for what each means). The simulation's `substeps` stays shared.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ServoOverride {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kv_per_s: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vel_kp_n_per_mm_s: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vel_ti_ms: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_inertia_kg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub load_kg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub viscous_n_per_mm_s: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coulomb_n: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub force_limit_n: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub encoder_resolution_mm: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub vel_ff: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub acc_ff: Option<f64>,
}

impl ServoOverride {
    /// Whether it changes nothing.
    pub fn is_empty(&self) -> bool {
        *self == ServoOverride::default()
    }

    /// `shared` with this axis's changes.
    pub fn apply(&self, shared: &Servo) -> Servo {
        let mut s = shared.clone();
        let pick = |o: Option<f64>, v: &mut f64| {
            if let Some(o) = o {
                *v = o;
            }
        };
        pick(self.kv_per_s, &mut s.kv_per_s);
        pick(self.vel_kp_n_per_mm_s, &mut s.vel_kp_n_per_mm_s);
        pick(self.vel_ti_ms, &mut s.vel_ti_ms);
        pick(self.viscous_n_per_mm_s, &mut s.viscous_n_per_mm_s);
        pick(self.coulomb_n, &mut s.coulomb_n);
        pick(self.force_limit_n, &mut s.force_limit_n);
        pick(self.encoder_resolution_mm, &mut s.encoder_resolution_mm);
        pick(self.vel_ff, &mut s.vel_ff);
        pick(self.acc_ff, &mut s.acc_ff);
        // A mass given for the axis replaces an older file's shared `mass_kg`.
        if self.motor_inertia_kg.is_some() || self.load_kg.is_some() {
            if let Some(total) = s.mass_kg.take() {
                // (Split as the shared mass was: all of it load, none motor.)
                s.motor_inertia_kg = 0.0;
                s.load_kg = total;
            }
        }
        pick(self.motor_inertia_kg, &mut s.motor_inertia_kg);
        pick(self.load_kg, &mut s.load_kg);
        s
    }
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
            servo: ServoOverride::default(),
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
            blend_tolerance_mm: BLEND_TOLERANCE_MM,
            max_following_error_mm: 2.0,
            min_period_us: 100,
            max_period_us: 10_000,
            lookahead_blocks: 256,
            plan_window_moves: PLAN_WINDOW_MOVES,
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

    /// Every number within the range a machine can have ([`RANGES`], [`MAX_TRAVEL_MM`],
    /// [`MAX_SUBSTEPS`]); the error names the key, the range and the value found.
    pub fn check(&self) -> Result<(), String> {
        let mut named: Vec<(String, f64, &Range)> = vec![
            ("rapid_mm_per_min".into(), self.rapid_mm_per_min, &FEED),
            (
                "max_feed_mm_per_min".into(),
                self.max_feed_mm_per_min,
                &FEED,
            ),
            ("path_acc_mm_per_s2".into(), self.path_acc_mm_per_s2, &ACC),
            (
                "path_jerk_mm_per_s3".into(),
                self.path_jerk_mm_per_s3,
                &JERK,
            ),
            ("chord_tolerance_mm".into(), self.chord_tolerance_mm, &CHORD),
            ("corner_angle_deg".into(), self.corner_angle_deg, &CORNER),
            (
                "blend_tolerance_mm".into(),
                self.blend_tolerance_mm,
                &BLEND_TOLERANCE,
            ),
            (
                "max_following_error_mm".into(),
                self.max_following_error_mm,
                &FOLLOWING,
            ),
        ];
        named.extend(servo_ranges("servo", &self.servo));
        for (axis, l) in ["x", "y", "z"].iter().zip(self.axes.as_array()) {
            if !l.servo.is_empty() {
                named.extend(servo_ranges(
                    &format!("axes.{axis}.servo"),
                    &l.servo.apply(&self.servo),
                ));
            }
        }
        for (axis, l) in ["x", "y", "z"].iter().zip(self.axes.as_array()) {
            named.push((
                format!("axes.{axis}.max_vel_mm_per_min"),
                l.max_vel_mm_per_min,
                &FEED,
            ));
            named.push((
                format!("axes.{axis}.max_acc_mm_per_s2"),
                l.max_acc_mm_per_s2,
                &ACC,
            ));
            named.push((
                format!("axes.{axis}.max_jerk_mm_per_s3"),
                l.max_jerk_mm_per_s3,
                &JERK,
            ));
            named.push((format!("axes.{axis}.min_mm"), l.min_mm, &TRAVEL));
            named.push((format!("axes.{axis}.max_mm"), l.max_mm, &TRAVEL));
        }
        for (name, v, range) in named {
            range.check(&name, v)?;
        }
        for (axis, l) in ["x", "y", "z"].iter().zip(self.axes.as_array()) {
            if l.min_mm >= l.max_mm {
                return Err(format!(
                    "axes.{axis}: the travel min_mm ({}) must be below max_mm ({})",
                    l.min_mm, l.max_mm
                ));
            }
        }
        if self.max_period_us > MAX_PERIOD_US {
            return Err(format!(
                "max_period_us must be at most {MAX_PERIOD_US} (a tenth of a second), got {}",
                self.max_period_us
            ));
        }
        if self.min_period_us == 0 || self.min_period_us > self.max_period_us {
            return Err(format!(
                "min_period_us ({}) must be at least 1 and at most max_period_us ({})",
                self.min_period_us, self.max_period_us
            ));
        }
        if !(LOOKAHEAD_MIN..=LOOKAHEAD_MAX).contains(&self.lookahead_blocks) {
            return Err(format!(
                "lookahead_blocks must be from {LOOKAHEAD_MIN} to {LOOKAHEAD_MAX}, got {} \
                 (with fewer blocks in hand the interpolator can break an axis's jerk)",
                self.lookahead_blocks
            ));
        }
        if !(PLAN_WINDOW_MIN..=PLAN_WINDOW_MAX).contains(&self.plan_window_moves) {
            return Err(format!(
                "plan_window_moves must be from {PLAN_WINDOW_MIN} to {PLAN_WINDOW_MAX}, got {}",
                self.plan_window_moves
            ));
        }
        let budget = (self.min_period_us * 1000 / 2 / SUBSTEP_NS).min(MAX_SUBSTEPS as u64);
        let s = &self.servo;
        if s.substeps == 0 || s.substeps as u64 > budget {
            return Err(format!(
                "servo.substeps must be from 1 to {budget}, got {}: the servo-sim integrates \
                 its axes substeps times a period, about {SUBSTEP_NS} ns each, and must \
                 answer within half of the shortest period (min_period_us = {} µs), and \
                 at most {MAX_SUBSTEPS}",
                s.substeps, self.min_period_us
            ));
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
        Machine::default().documented_toml(
            "# cnc machine file: every key is optional (missing keys take these defaults).\n",
            |_| Vec::new(),
        )
    }

    /// This machine as TOML after `header`, each key with a comment giving its meaning
    /// and unit, then the lines `notes` gives for it (by its dotted name,
    /// `axes.x.max_mm`), each a comment.
    pub fn documented_toml(&self, header: &str, notes: impl Fn(&str) -> Vec<String>) -> String {
        let mut out = String::from(header);
        let mut section = "";
        for line in self.to_toml().lines() {
            if line.starts_with('[') {
                section = line.trim_matches(|c| c == '[' || c == ']');
                out.push('\n');
            }
            let key = line.split('=').next().unwrap_or("").trim();
            let full = if section.is_empty() {
                key.to_string()
            } else {
                format!("{section}.{key}")
            };
            // (An axis's own servo key means what the shared one does, for that axis.)
            let (shared_key, axis) = match full.strip_prefix("axes.") {
                Some(rest) if rest.get(1..8) == Some(".servo.") => {
                    (format!("servo.{}", &rest[8..]), rest[..1].to_uppercase())
                }
                _ => (full.clone(), String::new()),
            };
            if let Some((_, doc)) = KEY_DOCS.iter().find(|(k, _)| *k == shared_key) {
                out.push_str("# ");
                if !axis.is_empty() {
                    out.push_str(&format!("{axis} axis only: "));
                }
                out.push_str(doc);
                out.push('\n');
            }
            if line.contains('=') {
                for n in notes(&full) {
                    out.push_str("# ");
                    out.push_str(&n);
                    out.push('\n');
                }
            }
            out.push_str(line);
            out.push('\n');
            // (Not written at the built-in value, which the file still shows.)
            if key == "lookahead_blocks" && Machine::plan_window_is_default(&self.plan_window_moves)
            {
                out.push_str(&format!("# {}\n", key_doc("plan_window_moves")));
                out.push_str(&format!("plan_window_moves = {PLAN_WINDOW_MOVES}\n"));
            }
            if key == "corner_angle_deg"
                && Machine::blend_tolerance_is_default(&self.blend_tolerance_mm)
            {
                out.push_str(&format!("# {}\n", key_doc("blend_tolerance_mm")));
                out.push_str(&format!("blend_tolerance_mm = {BLEND_TOLERANCE_MM}\n"));
            }
        }
        out
    }

    /// The servo model of axis `i` (0 X, 1 Y, 2 Z): the shared `[servo]` with the axis's
    /// own `[axes.*.servo]` keys.
    pub fn axis_servo(&self, i: usize) -> Servo {
        self.axes.as_array()[i].servo.apply(&self.servo)
    }

    fn plan_window_is_default(moves: &u32) -> bool {
        *moves == PLAN_WINDOW_MOVES
    }

    fn blend_tolerance_is_default(x: &f64) -> bool {
        *x == BLEND_TOLERANCE_MM
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

/// The slowest feed a program may command, mm/min: 0.1 mm/min, the floor LinuxCNC
/// 2.9 puts under an inverse-time feed (linuxcnc#2410). Slower, a move of a millimetre
/// takes more than ten minutes, and the step of a cycle shrinks towards the rounding of
/// a position (1e-11 mm at 100 m): the machine would stand still mid-move. The planner
/// refuses a slower feed, and so the fastest feeds of a machine file start above it.
pub const MIN_FEED_MM_PER_MIN: f64 = 0.1;

/// The largest travel limit, in mm either way: 100 m, longer than the longest machine
/// axes built. Positions stay where a `f64` resolves far below a nanometre.
pub const MAX_TRAVEL_MM: f64 = 100_000.0;

/// The ranges a servo model's numbers must lie in, each named `{prefix}.key`.
fn servo_ranges(prefix: &str, s: &Servo) -> Vec<(String, f64, &'static Range)> {
    vec![
        (format!("{prefix}.kv_per_s"), s.kv_per_s, &KV),
        (
            format!("{prefix}.vel_kp_n_per_mm_s"),
            s.vel_kp_n_per_mm_s,
            &VEL_KP,
        ),
        (format!("{prefix}.vel_ti_ms"), s.vel_ti_ms, &VEL_TI),
        (format!("{prefix}.force_limit_n"), s.force_limit_n, &FORCE),
        (
            format!("{prefix}.encoder_resolution_mm"),
            s.encoder_resolution_mm,
            &ENCODER,
        ),
        (
            format!("{prefix}.motor_inertia_kg"),
            s.motor_inertia_kg,
            &PART_MASS,
        ),
        (format!("{prefix}.load_kg"), s.load_kg, &PART_MASS),
        (
            format!("{prefix} motor_inertia_kg + load_kg (or mass_kg)"),
            s.total_mass_kg(),
            &MASS,
        ),
        (
            format!("{prefix}.viscous_n_per_mm_s"),
            s.viscous_n_per_mm_s,
            &VISCOUS,
        ),
        (format!("{prefix}.coulomb_n"), s.coulomb_n, &COULOMB),
        (format!("{prefix}.vel_ff"), s.vel_ff, &GAIN),
        (format!("{prefix}.acc_ff"), s.acc_ff, &GAIN),
    ]
}

/// Most servo-sim sub-steps per period.
pub const MAX_SUBSTEPS: u32 = 1000;

/// What one servo-sim sub-step of the three axes costs, ns: measured with `cnc run
/// --clock sim` of a 60 013-cycle line at `substeps` 1000 and 10, release build, on the
/// project's 2-vCPU VM: 3.83 s more user time for 59.4 million more sub-steps, 64 ns
/// each. The servo-sim must answer a set-point well within the shortest period the
/// machine runs, so `substeps` of them may take at most half of `min_period_us`: 769 at
/// the built-in 100 µs (10 built in).
pub const SUBSTEP_NS: u64 = 65;

/// The longest period a machine file may allow, µs (a tenth of a second).
pub const MAX_PERIOD_US: u64 = 100_000;

/// The values a number of the machine file may take: from `lo` (included unless
/// `lo_open`) to `hi` (included), finite.
pub struct Range {
    pub lo: f64,
    pub lo_open: bool,
    pub hi: f64,
    pub unit: &'static str,
}

/// `v` as a message shows it: in exponent form when very large or very small (a key
/// read as `1e-300` is not shown as three hundred zeros).
pub fn shown(v: f64) -> String {
    let a = v.abs();
    if a.is_finite() && (a >= 1e7 || (a < 1e-4 && a != 0.0)) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

impl Range {
    fn check(&self, name: &str, v: f64) -> Result<(), String> {
        let above_lo = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        if v.is_finite() && above_lo && v <= self.hi {
            return Ok(());
        }
        let from = if self.lo_open { "above" } else { "from" };
        Err(format!(
            "{name} must be {from} {} to {} {}, got {}",
            shown(self.lo),
            shown(self.hi),
            self.unit,
            shown(v)
        ))
    }
}

const fn range(lo: f64, hi: f64, unit: &'static str) -> Range {
    Range {
        lo,
        lo_open: false,
        hi,
        unit,
    }
}

const fn above(lo: f64, hi: f64, unit: &'static str) -> Range {
    Range {
        lo,
        lo_open: true,
        hi,
        unit,
    }
}

/// Feeds and velocities: 1 mm/min (ten times the slowest feed a program may use) to
/// 1 000 000 mm/min (1 km/min, five times the fastest linear-motor machines).
pub const FEED: Range = range(1.0, 1e6, "mm/min");
/// Accelerations: 1 mm/s² to 1e6 mm/s² (100 g).
pub const ACC: Range = range(1.0, 1e6, "mm/s²");
/// Jerks: 1 mm/s³ to 1e9 mm/s³ (a thousand times a stiff machine's).
pub const JERK: Range = range(1.0, 1e9, "mm/s³");
/// Chord tolerance: a nanometre to 10 mm.
pub const CHORD: Range = range(1e-6, 10.0, "mm");
/// Corner angle: more than 0 (every kink a stop would be 0) to 180 degrees (a reversal).
pub const CORNER: Range = above(0.0, 180.0, "degrees");
/// The built-in [`Machine::blend_tolerance_mm`], mm.
pub const BLEND_TOLERANCE_MM: f64 = 0.01;
/// Bare `G64`'s blend tolerance: 0 (the exact path) to 10 mm.
pub const BLEND_TOLERANCE: Range = range(0.0, 10.0, "mm");
/// Following-error limit: a nanometre to a metre.
pub const FOLLOWING: Range = range(1e-6, 1000.0, "mm");
/// Travel limits.
pub const TRAVEL: Range = range(-MAX_TRAVEL_MM, MAX_TRAVEL_MM, "mm");
const KV: Range = above(0.0, 10_000.0, "1/s");
const VEL_KP: Range = above(0.0, 1e9, "N per mm/s");
const VEL_TI: Range = above(0.0, 1e6, "ms");
const FORCE: Range = above(0.0, 1e9, "N");
const ENCODER: Range = range(1e-9, 1.0, "mm");
const PART_MASS: Range = range(0.0, 1e6, "kg");
const MASS: Range = range(1e-3, 1e6, "kg");
const VISCOUS: Range = range(0.0, 1e9, "N per mm/s");
const COULOMB: Range = range(0.0, 1e9, "N");
const GAIN: Range = range(0.0, 1.0, "(0 = off, 1 = on)");

/// The fewest blocks the interpolator may hold ahead ([`Machine::lookahead_blocks`]).
/// With fewer it brakes for the end of its window under limits that a block it has not
/// yet seen may lower, and can break an axis's jerk: the random search of
/// `interpreter/tests/limits.rs` (`LIMITS_SEARCH_LOOKAHEAD`) finds an X jerk 3.6 times
/// its limit at 3 blocks (seed 11, 300 cases a kind), none at 16 (seeds 5 and 11, 3 600
/// cases). (2 until 2026-11-28.)
pub const LOOKAHEAD_MIN: u32 = 16;
/// The most blocks the interpolator may hold ahead.
pub const LOOKAHEAD_MAX: u32 = 4096;

/// The planner's look-ahead built in, in moves ([`Machine::plan_window_moves`]): every
/// program of the repository has fewer between two rests, so they are planned whole.
pub const PLAN_WINDOW_MOVES: u32 = 4096;
/// The fewest and most moves a plan window may be set to.
pub const PLAN_WINDOW_MIN: u32 = 64;
pub const PLAN_WINDOW_MAX: u32 = 10_000_000;

fn key_doc(key: &str) -> &'static str {
    KEY_DOCS
        .iter()
        .find(|(k, _)| *k == key)
        .map_or("", |(_, d)| d)
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
    (
        "plan_window_moves",
        "moves the planner looks ahead over a stretch with no rest; a longer one is cut at speed",
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
        "blend_tolerance_mm",
        "corner deviation a bare G64 (the mode a program starts in) blends lines within; 0 = the exact path, mm",
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

/// Logs (info) the machine file `process` runs with: its path, or `built-in`, and its
/// hash, the fingerprint a command log records and a replay checks. Every process says it,
/// so a log shows at once whether the three agreed on one machine.
pub fn log_in_force(process: &str, path: Option<&std::path::Path>, machine: &Machine) {
    let file = path.map_or_else(|| "built-in".to_string(), |p| p.display().to_string());
    tracing::info!(
        process = %process,
        machine = %file,
        hash = %format_args!("{:016x}", machine.hash()),
        "machine file in force"
    );
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

    /// Fewer than 16 blocks in hand let the interpolator break an axis's jerk
    /// (`LOOKAHEAD_MIN`): such a machine file is refused, naming the key and why.
    #[test]
    fn a_look_ahead_too_short_to_keep_the_limits_is_refused() {
        for (n, ok) in [
            (2, false),
            (3, false),
            (15, false),
            (16, true),
            (4096, true),
        ] {
            let got = Machine::from_toml(&format!("lookahead_blocks = {n}\n"));
            assert_eq!(got.is_ok(), ok, "{n}: {got:?}");
            if let Err(e) = got {
                assert!(e.contains("lookahead_blocks must be from 16"), "{e}");
                assert!(e.contains("jerk"), "{e}");
            }
        }
    }

    #[test]
    fn an_axis_s_own_servo_keys_replace_the_shared_ones() {
        let m = Machine::from_toml(
            "[servo]\nkv_per_s = 40.0\nload_kg = 30.0\n\n[axes.z.servo]\nload_kg = 80.0\n",
        )
        .unwrap();
        assert_eq!(m.axis_servo(0), m.servo);
        assert_eq!(m.axis_servo(2).load_kg, 80.0);
        assert_eq!(m.axis_servo(2).kv_per_s, 40.0, "the rest from [servo]");
        assert_eq!(Machine::from_toml(&m.to_toml()).unwrap(), m);
        let doc = m.documented_toml("", |_| Vec::new());
        assert!(
            doc.contains("[axes.z.servo]\n# Z axis only: moving load (table, fixture, part), kg\nload_kg = 80.0"),
            "{doc}"
        );
        // A machine without them writes and hashes as before (replays of older runs
        // still find their machine): the built-in one's hash, pinned from before.
        assert!(!Machine::default().to_toml().contains(".servo]"));
        assert_eq!(Machine::default().hash(), 0x7b69_3019_0002_42d7);
        assert_ne!(
            m.hash(),
            Machine::from_toml("[servo]\nkv_per_s = 40.0\n")
                .unwrap()
                .hash()
        );
        // Checked like the shared section, named by the axis; the simulation's sub-steps
        // stay shared.
        let e = Machine::from_toml("[axes.y.servo]\nkv_per_s = -5.0\n").unwrap_err();
        assert!(e.contains("axes.y.servo.kv_per_s"), "{e}");
        let e = Machine::from_toml("[axes.y.servo]\nsubsteps = 5\n").unwrap_err();
        assert!(e.contains("unknown field `substeps`"), "{e}");
        // An older file's shared mass_kg gives way to an axis's own masses.
        let old = Machine::from_toml("[servo]\nmass_kg = 80.0\n\n[axes.x.servo]\nload_kg = 10.0\n")
            .unwrap();
        assert_eq!(old.axis_servo(0).total_mass_kg(), 10.0);
        assert_eq!(old.axis_servo(1).total_mass_kg(), 80.0);
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

    /// A bare `G64`'s tolerance: read, written only when not the built-in value (the
    /// machines of older runs hash as before), and shown in the default file with its
    /// meaning.
    #[test]
    fn the_blend_tolerance_is_read_and_written_only_when_set() {
        let m = Machine::from_toml("blend_tolerance_mm = 0.05\n").unwrap();
        assert_eq!(m.blend_tolerance_mm, 0.05);
        assert!(m.to_toml().contains("blend_tolerance_mm = 0.05"));
        assert_ne!(m.hash(), Machine::default().hash());
        assert!(!Machine::default().to_toml().contains("blend_tolerance_mm"));
        assert_eq!(Machine::from_toml(&m.to_toml()).unwrap(), m);
        let doc = Machine::default_toml();
        assert!(
            doc.contains(&format!("\nblend_tolerance_mm = {BLEND_TOLERANCE_MM}\n")),
            "{doc}"
        );
        // 0 (the exact path) is written, so it reads back as 0, not as the default.
        let exact = Machine::from_toml("blend_tolerance_mm = 0.0\n").unwrap();
        assert_eq!(
            Machine::from_toml(&exact.to_toml())
                .unwrap()
                .blend_tolerance_mm,
            0.0
        );
        assert!(doc.contains("bare G64"), "{doc}");
        assert_eq!(Machine::from_toml(&doc).unwrap(), Machine::default());
    }

    /// Issue #22: each of these passed the loader and faulted the run (a stall at a
    /// feed of 1e-300, a servo-sim late at its first cycle) or made no sense.
    #[test]
    fn every_key_has_a_range_and_the_error_names_it() {
        for (text, key) in [
            ("corner_angle_deg = 400.0\n", "corner_angle_deg"),
            ("corner_angle_deg = 0.0\n", "corner_angle_deg"),
            ("blend_tolerance_mm = -0.01\n", "blend_tolerance_mm"),
            ("blend_tolerance_mm = 11.0\n", "blend_tolerance_mm"),
            ("max_feed_mm_per_min = 1e-300\n", "max_feed_mm_per_min"),
            ("rapid_mm_per_min = 1e12\n", "rapid_mm_per_min"),
            ("path_jerk_mm_per_s3 = 1e300\n", "path_jerk_mm_per_s3"),
            ("chord_tolerance_mm = 1e-300\n", "chord_tolerance_mm"),
            ("max_period_us = 100000000\n", "max_period_us"),
            ("[axes.y]\nmax_mm = 1e9\n", "axes.y.max_mm"),
            (
                "[axes.z]\nmax_acc_mm_per_s2 = 0.5\n",
                "axes.z.max_acc_mm_per_s2",
            ),
            ("[servo]\nsubsteps = 10000\n", "servo.substeps"),
            ("[servo]\nsubsteps = 0\n", "servo.substeps"),
            (
                "[servo]\nencoder_resolution_mm = 1e-300\n",
                "servo.encoder_resolution_mm",
            ),
            ("[servo]\nkv_per_s = 1e300\n", "servo.kv_per_s"),
        ] {
            let e = Machine::from_toml(text).unwrap_err();
            assert!(e.starts_with(key), "{text}: {e}");
        }
        let e = Machine::from_toml("corner_angle_deg = 400.0\n").unwrap_err();
        assert_eq!(
            e,
            "corner_angle_deg must be above 0 to 180 degrees, got 400"
        );
        // Sub-steps: half of the shortest period at 65 ns each (769 at 100 µs).
        assert!(Machine::from_toml("[servo]\nsubsteps = 769\n").is_ok());
        assert!(Machine::from_toml("[servo]\nsubsteps = 770\n").is_err());
        let m = "min_period_us = 1000\n[servo]\nsubsteps = 1000\n";
        assert!(Machine::from_toml(m).is_ok());
        assert!(Machine::from_toml("corner_angle_deg = 180.0\n").is_ok());
    }

    #[test]
    fn feed_forward_gains_are_between_0_and_1() {
        let e = Machine::from_toml("[servo]\nvel_ff = 1.5\n").unwrap_err();
        assert!(e.contains("servo.vel_ff"), "{e}");
        assert!(Machine::from_toml("[servo]\nvel_ff = 0.0\nacc_ff = 0.5\n").is_ok());
    }
}
