//! The contract between the three processes: payload types and service names.
//!
//! Every payload is a fixed-size `#[repr(C)]` value written in place into iceoryx2 shared
//! memory. Enumerations travel as `u32` codes, never as Rust enums, so a corrupt or foreign
//! value is a validation error on receipt instead of undefined behaviour. Each payload
//! carries [`PROTOCOL_VERSION`] and a sequence or cycle number.

use crate::machine::{Axes, Machine};
use crate::nurbs::{self, CurveError, MAX_CTRL, MAX_KNOTS};
use crate::travel::TravelError;
use iceoryx2::prelude::ZeroCopySend;

/// Bumped whenever a payload's layout or meaning changes.
pub const PROTOCOL_VERSION: u32 = 4;

/// What a command block asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum BlockKind {
    /// Move along the block's curve (lines, arcs and NURBS are all NURBS here).
    Motion = 1,
    /// Stand still for `dwell_ns`.
    Dwell = 2,
    /// The program is over: stop at the end of the previous motion.
    ProgramEnd = 3,
}

impl BlockKind {
    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            1 => Some(Self::Motion),
            2 => Some(Self::Dwell),
            3 => Some(Self::ProgramEnd),
            _ => None,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Self::Motion => "motion",
            Self::Dwell => "dwell",
            Self::ProgramEnd => "end",
        }
    }
}

/// `CommandBlock::flags`: the motion is a rapid (G0) traverse.
pub const FLAG_RAPID: u32 = 1;

/// `CommandBlock::flags`: the machine stops at the end of this block (exact stop: `G61.1`,
/// or a programmed stop `M0`/`M1` follows).
pub const FLAG_STOP_AT_END: u32 = 2;

/// `CommandBlock::flags`: a surface block. The motion is the cutter-contact point moving
/// on a Bézier surface patch along a straight line of its `(u, v)` domain (or a cubic
/// curve, with [`FLAG_UV_CUBIC`]), and the set-point is the ball-nose tool's reference
/// point (see [`SurfacePass`]).
pub const FLAG_SURFACE: u32 = 4;

/// `CommandBlock::flags`, surface blocks only: the pass is the cubic Bézier curve with
/// control points `uv_start`, `uv_inner[0]`, `uv_inner[1]`, `uv_end` in the patch's
/// `(u, v)` domain (a `PLANE_CC_STRATEGY` pass: the intersection of the surface with a
/// plane) instead of the straight line from `uv_start` to `uv_end` (see [`SurfacePass`]).
pub const FLAG_UV_CUBIC: u32 = 8;

/// Axis code meaning "no helical axis".
pub const NO_AXIS: u32 = 3;

/// The linear part of a helical arc. The block's NURBS is the exact circular arc in the
/// plane normal to `axis` (its `axis` coordinate constant at `start_mm`); the `axis`
/// coordinate then moves in proportion to the angle travelled: `start_mm + mm_per_rad *
/// phi(u)`. The arc's rational quadratic segments each span `seg_rad`, segment `j` on
/// knot span `[j, j+1]`, so `phi` is recovered exactly from the evaluated point.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
pub struct Helix {
    /// Axis normal to the arc plane: 0 X, 1 Y, 2 Z, or [`NO_AXIS`] for a plain curve.
    pub axis: u32,
    /// +1 counter-clockwise about the positive `axis` (G3), -1 clockwise (G2), as `i32`.
    pub dir: i32,
    pub center_mm: [f64; 3],
    pub start_mm: f64,
    pub mm_per_rad: f64,
    pub seg_rad: f64,
}

/// The surface part of a surface block (`FLAG_SURFACE`; seed 000).
///
/// The block's curve fields then hold a rational Bézier patch instead of a curve: `degree`
/// is its degree `p` along `u`, [`degree_v`](Self::degree_v) its degree `q` along `v`,
/// `n_ctrl = (p + 1)(q + 1)` and `ctrl[i·(q + 1) + j]` (`i` along `u`) its control points
/// `[x, y, z, w]`; the patch's domain is `[0, 1]²` and its knots are not carried. The
/// cutter-contact point runs `C(t) = S(u(t), v(t))` for `t` in `[0, 1]`, with `(u, v)`
/// moving in a straight line from `uv_start` to `uv_end` or, with [`FLAG_UV_CUBIC`],
/// along the cubic Bézier curve `uv_start, uv_inner[0], uv_inner[1], uv_end` (its rate
/// `d(u, v)/dt` then changes along the pass: `C' = S_u·u' + S_v·v'`). A straight pass is
/// the cubic's collinear special case, carried without the flag (and with `uv_inner`
/// zero) so that it keeps the exact line and the iso-parametric evaluators; every
/// control point lies in `[0, 1]²`, so the whole curve does. `length_mm` and the feeds
/// are those of the contact point. The set-point is the tool reference point
/// `M = C + R·n + (H − R)·z`, with `n` the unit normal `normal_sign·(S_u × S_v)/|…|`
/// and `z` the tool axis `+Z` (3-axis machining).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
pub struct SurfacePass {
    /// Degree `q` along `v` (1..=[`MAX_SURF_DEGREE`](crate::nurbs::surface::MAX_SURF_DEGREE)).
    pub degree_v: u32,
    /// `+1` or `-1`: the side of the surface the tool is on, as a factor on `S_u × S_v`.
    pub normal_sign: i32,
    pub uv_start: [f64; 2],
    pub uv_end: [f64; 2],
    /// Ball radius `R`.
    pub tool_radius_mm: f64,
    /// Distance `H` from the ball's tip to the tool reference point (`H >= R`).
    pub tool_length_mm: f64,
    /// The inner control points of a cubic pass ([`FLAG_UV_CUBIC`]); zero otherwise.
    pub uv_inner: [[f64; 2]; 2],
}

impl SurfacePass {
    pub const NONE: SurfacePass = SurfacePass {
        degree_v: 0,
        normal_sign: 1,
        uv_start: [0.0; 2],
        uv_end: [0.0; 2],
        tool_radius_mm: 0.0,
        tool_length_mm: 0.0,
        uv_inner: [[0.0; 2]; 2],
    };
}

impl Helix {
    pub const NONE: Helix = Helix {
        axis: NO_AXIS,
        dir: 1,
        center_mm: [0.0; 3],
        start_mm: 0.0,
        mm_per_rad: 0.0,
        seg_rad: 0.0,
    };
}

/// One command from the interpreter to the interpolator.
#[repr(C)]
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[type_name("cnc::CommandBlockV4")]
pub struct CommandBlock {
    pub protocol: u32,
    /// A [`BlockKind`] code.
    pub kind: u32,
    /// 0, 1, 2, ... in sending order, without gaps.
    pub seq: u64,
    /// Line of the NC program this block comes from (1-based; 0 = generated).
    pub source_line: u32,
    /// `FLAG_*` bits.
    pub flags: u32,
    pub degree: u32,
    pub n_ctrl: u32,
    /// The highest feed allowed in this block: programmed feed (or rapid rate) reduced by
    /// the curvature limits the planner applied.
    pub feed_mm_per_min: f64,
    /// Planned feed at the start and at the end of the block (look-ahead result).
    pub start_feed_mm_per_min: f64,
    pub end_feed_mm_per_min: f64,
    /// Path length of the block's curve.
    pub length_mm: f64,
    /// Tangential (along the path) acceleration and jerk the speed profile may use in
    /// this block: the machine's path limits less what the block's curvature takes at
    /// the block's feed, and within every axis's share (set by the planner).
    pub acc_mm_per_s2: f64,
    pub jerk_mm_per_s3: f64,
    pub dwell_ns: u64,
    pub helix: Helix,
    pub knots: [f64; MAX_KNOTS],
    /// `[x, y, z, w]` in mm, weight `w > 0`.
    pub ctrl: [[f64; 4]; MAX_CTRL],
    /// Surface blocks only (`FLAG_SURFACE`), else [`SurfacePass::NONE`].
    pub surface: SurfacePass,
}

impl CommandBlock {
    /// A block of `kind` with every other field zero or empty.
    pub fn empty(kind: BlockKind, seq: u64, source_line: u32) -> Self {
        CommandBlock {
            protocol: PROTOCOL_VERSION,
            kind: kind as u32,
            seq,
            source_line,
            flags: 0,
            degree: 0,
            n_ctrl: 0,
            feed_mm_per_min: 0.0,
            start_feed_mm_per_min: 0.0,
            end_feed_mm_per_min: 0.0,
            length_mm: 0.0,
            acc_mm_per_s2: 0.0,
            jerk_mm_per_s3: 0.0,
            dwell_ns: 0,
            helix: Helix::NONE,
            knots: [0.0; MAX_KNOTS],
            ctrl: [[0.0; 4]; MAX_CTRL],
            surface: SurfacePass::NONE,
        }
    }

    /// Is this a surface block (`FLAG_SURFACE`)?
    pub fn is_surface(&self) -> bool {
        self.flags & FLAG_SURFACE != 0
    }

    /// The used knots (meaningful once validated).
    pub fn knots(&self) -> &[f64] {
        let n = (self.n_ctrl as usize + self.degree as usize + 1).min(MAX_KNOTS);
        &self.knots[..n]
    }

    /// The used control points (meaningful once validated).
    pub fn ctrl(&self) -> &[[f64; 4]] {
        &self.ctrl[..(self.n_ctrl as usize).min(MAX_CTRL)]
    }

    pub fn kind(&self) -> Option<BlockKind> {
        BlockKind::from_code(self.kind)
    }

    /// The curve of a motion block: counts within capacity, finite numbers, a valid NURBS.
    fn validate_curve(&self) -> Result<(), ProtocolError> {
        let (degree, n) = (self.degree as usize, self.n_ctrl as usize);
        if n > MAX_CTRL || degree > nurbs::MAX_DEGREE {
            let err = if n > MAX_CTRL {
                CurveError::TooManyControlPoints {
                    n_ctrl: self.n_ctrl,
                    max: MAX_CTRL as u32,
                }
            } else {
                CurveError::DegreeOutOfRange {
                    degree: self.degree,
                }
            };
            return Err(ProtocolError::Curve { seq: self.seq, err });
        }
        // Name the very number that is not finite (the curve check only says that
        // one is).
        let not_finite = |field: &'static str, index: usize| ProtocolError::NotFinite {
            seq: self.seq,
            field,
            index: index as u32,
        };
        if let Some(i) = self.knots().iter().position(|k| !k.is_finite()) {
            return Err(not_finite("knots", i));
        }
        if let Some(i) = self
            .ctrl()
            .iter()
            .position(|c| c.iter().any(|v| !v.is_finite()))
        {
            return Err(not_finite("ctrl", i));
        }
        nurbs::validate(degree, self.knots(), self.ctrl(), MAX_CTRL)
            .map_err(|err| ProtocolError::Curve { seq: self.seq, err })?;
        Ok(())
    }

    /// The patch and pass of a surface block (see [`SurfacePass`]).
    fn validate_patch(&self) -> Result<(), ProtocolError> {
        use crate::nurbs::surface::MAX_SURF_DEGREE;
        let bad = |field: &'static str| ProtocolError::BadField {
            seq: self.seq,
            field,
        };
        let sp = &self.surface;
        let (p, q) = (self.degree as usize, sp.degree_v as usize);
        if !(1..=MAX_SURF_DEGREE).contains(&p) || !(1..=MAX_SURF_DEGREE).contains(&q) {
            return Err(bad("degree"));
        }
        if self.n_ctrl as usize != (p + 1) * (q + 1) || self.n_ctrl as usize > MAX_CTRL {
            return Err(bad("n_ctrl"));
        }
        for (i, c) in self.ctrl().iter().enumerate() {
            if let Some(k) = c.iter().position(|v| !v.is_finite()) {
                return Err(ProtocolError::NotFinite {
                    seq: self.seq,
                    field: "ctrl",
                    index: (4 * i + k) as u32,
                });
            }
            if c[3] <= 0.0 {
                return Err(bad("ctrl weight"));
            }
        }
        let uv_ok = sp
            .uv_start
            .iter()
            .chain(sp.uv_end.iter())
            .all(|x| x.is_finite() && (0.0..=1.0).contains(x));
        let cubic = self.flags & FLAG_UV_CUBIC != 0;
        let inner_ok = sp
            .uv_inner
            .iter()
            .flatten()
            .all(|x| x.is_finite() && (0.0..=1.0).contains(x) && (cubic || *x == 0.0));
        if !uv_ok || !inner_ok {
            return Err(bad("surface uv"));
        }
        let (r, h) = (sp.tool_radius_mm, sp.tool_length_mm);
        if !(r.is_finite() && h.is_finite() && r > 0.0 && h >= r) {
            return Err(bad("surface tool"));
        }
        if sp.normal_sign != 1 && sp.normal_sign != -1 {
            return Err(bad("surface normal_sign"));
        }
        Ok(())
    }

    /// Checks everything a receiver relies on. Never panics, whatever the bytes.
    pub fn validate(&self) -> Result<BlockKind, ProtocolError> {
        if self.protocol != PROTOCOL_VERSION {
            return Err(ProtocolError::Version { got: self.protocol });
        }
        let kind = self.kind().ok_or(ProtocolError::UnknownKind {
            seq: self.seq,
            code: self.kind,
        })?;
        match kind {
            BlockKind::Motion => {
                if self.is_surface() {
                    self.validate_patch()?;
                } else {
                    self.validate_curve()?;
                }
                validate_plan(
                    self.seq,
                    [
                        self.feed_mm_per_min,
                        self.start_feed_mm_per_min,
                        self.end_feed_mm_per_min,
                    ],
                    self.length_mm,
                    [self.acc_mm_per_s2, self.jerk_mm_per_s3],
                )?;
                if self.flags & FLAG_UV_CUBIC != 0 && !self.is_surface() {
                    return Err(ProtocolError::BadField {
                        seq: self.seq,
                        field: "flags",
                    });
                }
                let h = &self.helix;
                if h.axis != NO_AXIS && self.is_surface() {
                    return Err(ProtocolError::BadField {
                        seq: self.seq,
                        field: "helix",
                    });
                }
                if h.axis != NO_AXIS {
                    let finite = h
                        .center_mm
                        .iter()
                        .chain([h.start_mm, h.mm_per_rad, h.seg_rad].iter())
                        .all(|v| v.is_finite());
                    if h.axis > NO_AXIS
                        || !finite
                        || h.seg_rad <= 0.0
                        || (h.dir != 1 && h.dir != -1)
                    {
                        return Err(ProtocolError::BadField {
                            seq: self.seq,
                            field: "helix",
                        });
                    }
                }
            }
            BlockKind::Dwell | BlockKind::ProgramEnd => {}
        }
        Ok(kind)
    }
}

/// The planned values of motion block `seq` as [`CommandBlock::validate`] checks them
/// (after its curve): the feed cap, start and end feeds (mm/min), the length, and the
/// profile's acceleration and jerk. For a holder of blocks in another form that must
/// refuse what a receiver would.
pub fn validate_plan(
    seq: u64,
    [feed, start_feed, end_feed]: [f64; 3],
    length_mm: f64,
    [acc, jerk]: [f64; 2],
) -> Result<(), ProtocolError> {
    let bad = |field: &'static str| Err(ProtocolError::BadField { seq, field });
    // The cap must be positive; the planned speeds may be zero (a stop).
    if !feed.is_finite() || feed <= 0.0 {
        return bad("feed_mm_per_min");
    }
    if !start_feed.is_finite() || start_feed < 0.0 {
        return bad("start_feed_mm_per_min");
    }
    if !end_feed.is_finite() || end_feed < 0.0 {
        return bad("end_feed_mm_per_min");
    }
    if !length_mm.is_finite() || length_mm < 0.0 {
        return bad("length_mm");
    }
    if !acc.is_finite() || acc <= 0.0 {
        return bad("acc_mm_per_s2");
    }
    if !jerk.is_finite() || jerk <= 0.0 {
        return bad("jerk_mm_per_s3");
    }
    Ok(())
}

/// How far a planned value may exceed the machine's limit it was planned under, relative:
/// rounding only (measured on the demo, the STEP-NC examples and the LinuxCNC suite: at
/// most `2.2e-16` above, one unit in the last place).
pub const PLAN_TOL: f64 = 1e-9;

/// The limits of the machine a receiver runs with, as it checks each block against them
/// ([`CommandBlock::validate_for`]). Plain `Copy` data, made once from the machine file.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MachineLimits {
    pub rapid_mm_per_min: f64,
    pub max_feed_mm_per_min: f64,
    pub path_acc_mm_per_s2: f64,
    pub path_jerk_mm_per_s3: f64,
    pub axes: Axes,
}

impl MachineLimits {
    pub fn of(m: &Machine) -> Self {
        MachineLimits {
            rapid_mm_per_min: m.rapid_mm_per_min,
            max_feed_mm_per_min: m.max_feed_mm_per_min,
            path_acc_mm_per_s2: m.path_acc_mm_per_s2,
            path_jerk_mm_per_s3: m.path_jerk_mm_per_s3,
            axes: m.axes,
        }
    }
}

impl CommandBlock {
    /// Checks a block that passed [`validate`](Self::validate) against the machine the
    /// receiver runs with: the feed cap within the machine's (`rapid_mm_per_min` for a
    /// rapid, else `max_feed_mm_per_min`), the planned start and end feeds within the
    /// cap, the profile's acceleration and jerk within `path_acc_mm_per_s2` and
    /// `path_jerk_mm_per_s3` (each to [`PLAN_TOL`]), the curve without a jump inside the
    /// block (an interior knot repeated more than the degree lets it break apart), and
    /// the exact path within the travel ([`crate::travel::check_block`]). Allocation-free
    /// and panic-free; the error names the block, its source line and the field.
    pub fn validate_for(&self, m: &MachineLimits) -> Result<(), ProtocolError> {
        if self.kind != BlockKind::Motion as u32 {
            return Ok(());
        }
        let (seq, line) = (self.seq, self.source_line);
        let over = |field: &'static str, value: f64, key: &'static str, limit: f64| {
            if value > limit * (1.0 + PLAN_TOL) {
                Err(ProtocolError::AboveMachine {
                    seq,
                    line,
                    field,
                    value,
                    key,
                    limit,
                })
            } else {
                Ok(())
            }
        };
        if self.flags & FLAG_RAPID != 0 {
            over(
                "feed_mm_per_min",
                self.feed_mm_per_min,
                "rapid_mm_per_min",
                m.rapid_mm_per_min,
            )?;
        } else {
            over(
                "feed_mm_per_min",
                self.feed_mm_per_min,
                "max_feed_mm_per_min",
                m.max_feed_mm_per_min,
            )?;
        }
        let cap = self.feed_mm_per_min;
        over(
            "start_feed_mm_per_min",
            self.start_feed_mm_per_min,
            "feed_mm_per_min",
            cap,
        )?;
        over(
            "end_feed_mm_per_min",
            self.end_feed_mm_per_min,
            "feed_mm_per_min",
            cap,
        )?;
        over(
            "acc_mm_per_s2",
            self.acc_mm_per_s2,
            "path_acc_mm_per_s2",
            m.path_acc_mm_per_s2,
        )?;
        over(
            "jerk_mm_per_s3",
            self.jerk_mm_per_s3,
            "path_jerk_mm_per_s3",
            m.path_jerk_mm_per_s3,
        )?;
        if !self.is_surface() {
            if let Some(j) =
                crate::travel::largest_jump(self.degree as usize, self.knots(), self.ctrl())
            {
                // NaN is a jump too (largest_jump gives infinity for it already).
                if j.gap_mm > JOIN_TOL_MM || j.gap_mm.is_nan() {
                    return Err(ProtocolError::CurveJump {
                        seq,
                        line,
                        knot: j.knot,
                        gap_mm: j.gap_mm,
                    });
                }
            }
        }
        crate::travel::check_block(self, &m.axes).map_err(|err| ProtocolError::Travel {
            seq,
            line,
            err,
        })
    }
}

/// How far a motion may start from where the one before it ended, and how far a curve
/// may jump at an interior knot, mm: rounding only. The largest gap measured between the
/// set-point paths of consecutive blocks on the demo, the STEP-NC examples, the LinuxCNC
/// suite, helices of 100 turns and arcs of radius 900 mm is 6.3e-13 mm (1.6e-14 mm on
/// all but the large arcs), 1600 times below this.
pub const JOIN_TOL_MM: f64 = 1e-9;

/// `Setpoint::flags`: this is the last set-point of the program (the machine is at rest).
pub const SETPOINT_LAST: u32 = 1;

/// One interpolated position per cycle, interpolator to servo-sim.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("cnc::SetpointV1")]
pub struct Setpoint {
    pub protocol: u32,
    pub flags: u32,
    pub cycle: u64,
    /// `cycle * period_ns`: time is an integer, never accumulated.
    pub t_ns: u64,
    pub block_seq: u64,
    pub source_line: u32,
    pub _reserved: u32,
    pub pos_mm: [f64; 3],
    /// Velocity and acceleration feed-forward.
    pub vel_mm_per_s: [f64; 3],
    pub acc_mm_per_s2: [f64; 3],
}

impl Setpoint {
    pub fn validate(&self) -> Result<(), ProtocolError> {
        if self.protocol != PROTOCOL_VERSION {
            return Err(ProtocolError::Version { got: self.protocol });
        }
        let all = self
            .pos_mm
            .iter()
            .chain(&self.vel_mm_per_s)
            .chain(&self.acc_mm_per_s2);
        if all.clone().any(|v| !v.is_finite()) {
            return Err(ProtocolError::BadField {
                seq: self.cycle,
                field: "set-point",
            });
        }
        Ok(())
    }
}

/// Drive states in [`Feedback::drive_state`].
pub const DRIVE_OK: u32 = 0;
/// The drive hit its torque limit in this cycle.
pub const DRIVE_SATURATED: u32 = 1;

/// What the drives report back for one set-point, servo-sim to interpolator.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("cnc::FeedbackV1")]
pub struct Feedback {
    pub protocol: u32,
    pub drive_state: u32,
    /// The cycle of the set-point this answers.
    pub cycle: u64,
    pub pos_mm: [f64; 3],
    /// Commanded minus actual (measured) position.
    pub ferr_mm: [f64; 3],
}

impl Feedback {
    pub fn validate(&self) -> Result<(), ProtocolError> {
        if self.protocol != PROTOCOL_VERSION {
            return Err(ProtocolError::Version { got: self.protocol });
        }
        if self
            .pos_mm
            .iter()
            .chain(&self.ferr_mm)
            .any(|v| !v.is_finite())
        {
            return Err(ProtocolError::BadField {
                seq: self.cycle,
                field: "feedback",
            });
        }
        Ok(())
    }
}

/// Interpolator states in [`Status::state`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RunState {
    Idle = 0,
    Running = 1,
    /// Out of blocks: stopped on the path, waiting for more.
    Starved = 2,
    Done = 3,
    Fault = 4,
}

impl RunState {
    pub fn from_code(code: u32) -> Option<Self> {
        [
            Self::Idle,
            Self::Running,
            Self::Starved,
            Self::Done,
            Self::Fault,
        ]
        .into_iter()
        .find(|s| *s as u32 == code)
    }
}

/// Interpolator to interpreter: where the execution is.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("cnc::StatusV1")]
pub struct Status {
    pub protocol: u32,
    /// A [`RunState`] code.
    pub state: u32,
    pub cycle: u64,
    /// Sequence number of the block being executed.
    pub block_seq: u64,
    pub source_line: u32,
    pub _reserved: u32,
    pub misses: u64,
    /// Blocks taken from the queue so far; `blocks_received - block_seq - 1` of them are
    /// waiting in the interpolator's look-ahead (the queue fill on its side).
    pub blocks_received: u64,
}

impl Status {
    pub fn validate(&self) -> Result<RunState, ProtocolError> {
        if self.protocol != PROTOCOL_VERSION {
            return Err(ProtocolError::Version { got: self.protocol });
        }
        RunState::from_code(self.state).ok_or(ProtocolError::BadField {
            seq: self.cycle,
            field: "status state",
        })
    }
}

/// What a receiver found wrong with a payload.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ProtocolError {
    Version {
        got: u32,
    },
    UnknownKind {
        seq: u64,
        code: u32,
    },
    Curve {
        seq: u64,
        err: CurveError,
    },
    BadField {
        seq: u64,
        field: &'static str,
    },
    /// `field[index]` is NaN or infinite.
    NotFinite {
        seq: u64,
        field: &'static str,
        index: u32,
    },
    /// Blocks must arrive as 0, 1, 2, ...
    OutOfSequence {
        expected: u64,
        got: u64,
    },
    /// A planned value above the machine's limit `key` ([`CommandBlock::validate_for`]).
    AboveMachine {
        seq: u64,
        line: u32,
        field: &'static str,
        value: f64,
        /// The machine-file key, or `feed_mm_per_min` for the block's own cap.
        key: &'static str,
        limit: f64,
    },
    /// The block's path leaves the machine's travel.
    Travel {
        seq: u64,
        line: u32,
        err: TravelError,
    },
    /// The block's curve breaks apart at the interior knot `knot`, by `gap_mm`.
    CurveJump {
        seq: u64,
        line: u32,
        knot: f64,
        gap_mm: f64,
    },
    /// The block starts `gap_mm` away from where the motion before it (block `prev`, or
    /// the machine's start when `None`) ended.
    StartGap {
        seq: u64,
        line: u32,
        prev: Option<u64>,
        gap_mm: f64,
    },
}

impl core::fmt::Display for ProtocolError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            ProtocolError::Version { got } => {
                write!(
                    f,
                    "protocol: version {got} received, this build speaks {PROTOCOL_VERSION}"
                )
            }
            ProtocolError::UnknownKind { seq, code } => {
                write!(f, "block {seq}: kind: unknown block kind {code}")
            }
            ProtocolError::Curve { seq, err } => {
                write!(f, "block {seq}: {}: {err}", curve_field(&err))
            }
            ProtocolError::NotFinite { seq, field, index } => {
                write!(f, "block {seq}: {field}[{index}]: not a finite number")
            }
            ProtocolError::BadField { seq, field } => {
                write!(f, "block/cycle {seq}: invalid {field}")
            }
            ProtocolError::OutOfSequence { expected, got } => {
                write!(
                    f,
                    "block {got} received where block {expected} was expected"
                )
            }
            ProtocolError::AboveMachine {
                seq,
                line,
                field,
                value,
                key,
                limit,
            } => {
                let whose = if key == "feed_mm_per_min" {
                    "the block's own"
                } else {
                    "the machine's"
                };
                write!(
                    f,
                    "block {seq} (line {line}): {field}: {value} is above {whose} {key} of \
                     {limit}: not planned for this machine"
                )
            }
            ProtocolError::Travel { seq, line, err } => {
                write!(f, "block {seq} (line {line}): path: {err}")
            }
            ProtocolError::CurveJump {
                seq,
                line,
                knot,
                gap_mm,
            } => write!(
                f,
                "block {seq} (line {line}): knots: the curve jumps {} mm at the knot {knot} \
                 (repeated more often than its degree): the path would jump",
                Mm(gap_mm)
            ),
            ProtocolError::StartGap {
                seq,
                line,
                prev,
                gap_mm,
            } => {
                let gap = Mm(gap_mm);
                write!(
                    f,
                    "block {seq} (line {line}): start: the path starts {gap} mm from "
                )?;
                match prev {
                    Some(p) => write!(f, "where block {p} ended")?,
                    None => write!(f, "the machine's position")?,
                }
                write!(f, " (more than {JOIN_TOL_MM:e} mm): the path would jump")
            }
        }
    }
}

/// A length in mm as a message shows it: to the µm, or in three significant digits below.
struct Mm(f64);

impl core::fmt::Display for Mm {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.0.abs() >= 1e-3 {
            write!(f, "{:.3}", self.0)
        } else {
            write!(f, "{:.3e}", self.0)
        }
    }
}

/// The block field a curve error is about, so a report names it.
fn curve_field(err: &CurveError) -> &'static str {
    match err {
        CurveError::DegreeOutOfRange { .. } => "degree",
        CurveError::TooFewControlPoints { .. } | CurveError::TooManyControlPoints { .. } => {
            "n_ctrl"
        }
        CurveError::KnotCount { .. }
        | CurveError::KnotsDecrease { .. }
        | CurveError::NotClamped
        | CurveError::EmptyDomain => "knots",
        CurveError::WeightNotPositive { .. } => "ctrl (weight)",
        CurveError::NotFinite => "knots or ctrl",
    }
}

/// The services of one stack. Every run uses its own `prefix`, so two stacks (or parallel
/// tests) never share a service.
#[derive(Debug, Clone)]
pub struct Services {
    pub prefix: String,
}

impl Services {
    pub fn new(prefix: impl Into<String>) -> Self {
        Services {
            prefix: prefix.into(),
        }
    }
    pub fn blocks(&self) -> String {
        format!("cnc/{}/blocks", self.prefix)
    }
    pub fn setpoints(&self) -> String {
        format!("cnc/{}/setpoints", self.prefix)
    }
    pub fn feedback(&self) -> String {
        format!("cnc/{}/feedback", self.prefix)
    }
    pub fn status(&self) -> String {
        format!("cnc/{}/status", self.prefix)
    }
}

/// Queue depth of the block service: how far the interpreter may run ahead.
pub const BLOCK_QUEUE: usize = 64;
/// Buffer of the set-point and feedback services. Lock-step consumers must never fall this
/// far behind; a gap in cycle numbers is detected and reported.
pub const CYCLE_QUEUE: usize = 1024;
