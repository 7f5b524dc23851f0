//! The blocks as the interpreter holds them from building to sending.
//!
//! A [`CommandBlock`] is the fixed 1.6 kB payload the interpolator receives, with room
//! for the largest NURBS. A program of plain `G1` lines needs a few numbers a block:
//! held whole, 100 000 of them are 160 MB the kernel must hand over page by page,
//! nearly all of it zeros. So a straight move is held as a [`Straight`], anything else
//! whole, and each becomes its [`CommandBlock`] only when it is sent or validated
//! ([`Block::command`]), the same block bit for bit as one built whole.

use super::{Geometry, Plannable};
use shared::profile::Limits as Jerk;
use shared::protocol::{
    validate_plan, BlockKind, CommandBlock, Helix, ProtocolError, FLAG_RAPID, FLAG_STOP_AT_END,
    FLAG_SURFACE,
};

/// A straight motion block (a `G0` or `G1` move): as a [`CommandBlock`], the degree-1
/// NURBS from `from` to `to` with unit weights on the knots `0 0 1 1`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Straight {
    pub source_line: u32,
    /// `FLAG_*` bits.
    pub flags: u32,
    pub from: [f64; 3],
    pub to: [f64; 3],
    /// The fields of the same names in [`CommandBlock`], set by the planner.
    pub feed_mm_per_min: f64,
    pub start_feed_mm_per_min: f64,
    pub end_feed_mm_per_min: f64,
    pub length_mm: f64,
    pub acc_mm_per_s2: f64,
    pub jerk_mm_per_s3: f64,
}

impl Straight {
    /// An unplanned straight move at the feed cap `feed_mm_per_min` (a rapid when
    /// `rapid`).
    pub fn new(
        source_line: u32,
        from: [f64; 3],
        to: [f64; 3],
        rapid: bool,
        feed_mm_per_min: f64,
    ) -> Self {
        Straight {
            source_line,
            flags: if rapid { FLAG_RAPID } else { 0 },
            from,
            to,
            feed_mm_per_min,
            start_feed_mm_per_min: 0.0,
            end_feed_mm_per_min: 0.0,
            length_mm: 0.0,
            acc_mm_per_s2: 0.0,
            jerk_mm_per_s3: 0.0,
        }
    }

    /// The chord, `to - from`.
    fn chord(&self) -> [f64; 3] {
        [
            self.to[0] - self.from[0],
            self.to[1] - self.from[1],
            self.to[2] - self.from[2],
        ]
    }

    /// What [`CommandBlock::validate`] says of [`command(seq)`](Self::command), without
    /// making the block: a degree-1 curve on the knots `0 0 1 1` with unit weights is
    /// valid when its end points are finite, and then its planned values are checked.
    pub fn validate(&self, seq: u64) -> Result<BlockKind, ProtocolError> {
        // Every number as it should be (nearly every block): valid, in one pass of
        // comparisons without a branch each, the checks below being their failures.
        // `x < ∞` is `is_finite` for the non-negative, and NaN fails every comparison.
        let below_infinity = |x: f64| x < f64::INFINITY;
        let points_finite = self
            .from
            .iter()
            .chain(&self.to)
            .fold(true, |ok, v| ok & v.is_finite());
        let plan_good = (self.feed_mm_per_min > 0.0)
            & below_infinity(self.feed_mm_per_min)
            & (self.start_feed_mm_per_min >= 0.0)
            & below_infinity(self.start_feed_mm_per_min)
            & (self.end_feed_mm_per_min >= 0.0)
            & below_infinity(self.end_feed_mm_per_min)
            & (self.length_mm >= 0.0)
            & below_infinity(self.length_mm)
            & (self.acc_mm_per_s2 > 0.0)
            & below_infinity(self.acc_mm_per_s2)
            & (self.jerk_mm_per_s3 > 0.0)
            & below_infinity(self.jerk_mm_per_s3);
        if self.flags & FLAG_SURFACE == 0 && points_finite && plan_good {
            return Ok(BlockKind::Motion);
        }
        if self.flags & FLAG_SURFACE != 0 {
            // Not a curve at all for a receiver: it says why.
            return self.command(seq).validate();
        }
        if let Some(i) = [self.from, self.to]
            .iter()
            .position(|p| p.iter().any(|v| !v.is_finite()))
        {
            return Err(ProtocolError::NotFinite {
                seq,
                field: "ctrl",
                index: i as u32,
            });
        }
        validate_plan(
            seq,
            [
                self.feed_mm_per_min,
                self.start_feed_mm_per_min,
                self.end_feed_mm_per_min,
            ],
            self.length_mm,
            [self.acc_mm_per_s2, self.jerk_mm_per_s3],
        )?;
        Ok(BlockKind::Motion)
    }

    /// The block as it is sent, numbered `seq`.
    pub fn command(&self, seq: u64) -> CommandBlock {
        let mut b = CommandBlock::empty(BlockKind::Motion, seq, self.source_line);
        b.degree = 1;
        b.n_ctrl = 2;
        b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
        let [x0, y0, z0] = self.from;
        let [x1, y1, z1] = self.to;
        b.ctrl[0] = [x0, y0, z0, 1.0];
        b.ctrl[1] = [x1, y1, z1, 1.0];
        b.helix = Helix::NONE;
        b.flags = self.flags;
        b.feed_mm_per_min = self.feed_mm_per_min;
        b.start_feed_mm_per_min = self.start_feed_mm_per_min;
        b.end_feed_mm_per_min = self.end_feed_mm_per_min;
        b.length_mm = self.length_mm;
        b.acc_mm_per_s2 = self.acc_mm_per_s2;
        b.jerk_mm_per_s3 = self.jerk_mm_per_s3;
        b
    }
}

/// A command block before it is sent: a straight move in its few numbers, any other
/// block (arcs, NURBS, dwells, the program end) whole.
#[derive(Debug, Clone)]
pub enum Block {
    Straight(Straight),
    Whole(Box<CommandBlock>),
}

impl From<CommandBlock> for Block {
    fn from(b: CommandBlock) -> Self {
        Block::Whole(Box::new(b))
    }
}

impl Block {
    /// `b` held as a [`Straight`] where that gives it back bit for bit (a straight move as
    /// the planner makes it: a command log of `G1` lines), else whole.
    pub fn compact(b: CommandBlock) -> Block {
        if b.kind == BlockKind::Motion as u32 && b.degree == 1 && b.n_ctrl == 2 {
            let [x0, y0, z0, _] = b.ctrl[0];
            let [x1, y1, z1, _] = b.ctrl[1];
            let s = Straight {
                source_line: b.source_line,
                flags: b.flags,
                from: [x0, y0, z0],
                to: [x1, y1, z1],
                feed_mm_per_min: b.feed_mm_per_min,
                start_feed_mm_per_min: b.start_feed_mm_per_min,
                end_feed_mm_per_min: b.end_feed_mm_per_min,
                length_mm: b.length_mm,
                acc_mm_per_s2: b.acc_mm_per_s2,
                jerk_mm_per_s3: b.jerk_mm_per_s3,
            };
            if shared::cmdlog::same_bits(&s.command(b.seq), &b) {
                return Block::Straight(s);
            }
        }
        Block::from(b)
    }
}

impl Block {
    /// The block as it is sent, numbered `seq`.
    pub fn command(&self, seq: u64) -> CommandBlock {
        match self {
            Block::Straight(s) => s.command(seq),
            Block::Whole(b) => CommandBlock { seq, ..**b },
        }
    }

    /// [`CommandBlock::validate`] of [`command(seq)`](Self::command).
    pub fn validate(&self, seq: u64) -> Result<BlockKind, ProtocolError> {
        match self {
            Block::Straight(s) => s.validate(seq),
            Block::Whole(_) => self.command(seq).validate(),
        }
    }

    pub fn source_line(&self) -> u32 {
        match self {
            Block::Straight(s) => s.source_line,
            Block::Whole(b) => b.source_line,
        }
    }

    /// Where a motion block starts and ends: its first and last control points (a
    /// block's knots are clamped); `None` for any other block.
    pub fn ends(&self) -> Option<([f64; 3], [f64; 3])> {
        match self {
            Block::Straight(s) => Some((s.from, s.to)),
            Block::Whole(b) if b.kind == BlockKind::Motion as u32 && b.n_ctrl >= 2 => {
                let xyz = |p: [f64; 4]| [p[0], p[1], p[2]];
                Some((xyz(b.ctrl[0]), xyz(b.ctrl[b.n_ctrl as usize - 1])))
            }
            Block::Whole(_) => None,
        }
    }

    /// The planned start and end feeds, mm/min, as they are sent.
    pub fn planned_feeds(&self) -> (f64, f64) {
        match self {
            Block::Straight(s) => (s.start_feed_mm_per_min, s.end_feed_mm_per_min),
            Block::Whole(b) => (b.start_feed_mm_per_min, b.end_feed_mm_per_min),
        }
    }

    /// The `FLAG_*` bits, to set or clear.
    pub fn flags_mut(&mut self) -> &mut u32 {
        match self {
            Block::Straight(s) => &mut s.flags,
            Block::Whole(b) => &mut b.flags,
        }
    }
}

/// The blocks as they are sent, numbered from 0.
pub fn commands(blocks: &[Block]) -> Vec<CommandBlock> {
    blocks
        .iter()
        .enumerate()
        .map(|(i, b)| b.command(i as u64))
        .collect()
}

/// The [`Plannable`] methods that read and write the planned fields, which
/// [`Straight`] names as [`CommandBlock`] does.
macro_rules! planned_fields {
    () => {
        fn feed_mm_per_min(&self) -> f64 {
            self.feed_mm_per_min
        }
        fn length_mm(&self) -> f64 {
            self.length_mm
        }
        fn limits(&self) -> Jerk {
            Jerk {
                acc: self.acc_mm_per_s2,
                jerk: self.jerk_mm_per_s3,
            }
        }
        fn set_caps(&mut self, length_mm: f64, feed_mm_per_min: f64, limits: Jerk) {
            self.length_mm = length_mm;
            self.feed_mm_per_min = feed_mm_per_min;
            self.acc_mm_per_s2 = limits.acc;
            self.jerk_mm_per_s3 = limits.jerk;
        }
        fn set_feeds(&mut self, start_mm_per_min: f64, end_mm_per_min: f64) {
            self.start_feed_mm_per_min = start_mm_per_min;
            self.end_feed_mm_per_min = end_mm_per_min;
        }
        fn planned_mm_s(&self) -> (f64, f64, f64) {
            (
                self.start_feed_mm_per_min / 60.0,
                self.end_feed_mm_per_min / 60.0,
                self.feed_mm_per_min / 60.0,
            )
        }
    };
}

impl Straight {
    /// [`Plannable::split_straight`].
    fn split(&self, t: f64) -> Option<(Straight, Straight)> {
        if !(t > 0.0 && t < 1.0) {
            return None;
        }
        let mid: [f64; 3] =
            core::array::from_fn(|i| self.from[i] + t * (self.to[i] - self.from[i]));
        let first = Straight {
            to: mid,
            flags: self.flags & !FLAG_STOP_AT_END,
            ..*self
        };
        let second = Straight { from: mid, ..*self };
        Some((first, second))
    }
}

impl Plannable for CommandBlock {
    fn is_motion(&self) -> bool {
        self.kind == BlockKind::Motion as u32
    }
    fn flags(&self) -> u32 {
        self.flags
    }
    fn geometry(&self) -> Geometry<'_> {
        match super::straight(self) {
            Some(chord) => Geometry::Straight(chord),
            None => Geometry::Curve(self),
        }
    }
    fn split_straight(&self, _t: f64) -> Option<(Self, Self)> {
        None
    }
    planned_fields!();
}

impl Plannable for Straight {
    fn is_motion(&self) -> bool {
        true
    }
    fn flags(&self) -> u32 {
        self.flags
    }
    fn geometry(&self) -> Geometry<'_> {
        Geometry::Straight(self.chord())
    }
    fn split_straight(&self, t: f64) -> Option<(Self, Self)> {
        self.split(t)
    }
    planned_fields!();
}

/// Each call handed on to the variant.
macro_rules! either {
    ($self:expr, $b:ident => $e:expr) => {
        match $self {
            Block::Straight($b) => $e,
            Block::Whole($b) => $e,
        }
    };
}

impl Plannable for Block {
    fn is_motion(&self) -> bool {
        either!(self, b => b.is_motion())
    }
    fn flags(&self) -> u32 {
        either!(self, b => b.flags)
    }
    fn geometry(&self) -> Geometry<'_> {
        either!(self, b => b.geometry())
    }
    fn feed_mm_per_min(&self) -> f64 {
        either!(self, b => b.feed_mm_per_min)
    }
    fn length_mm(&self) -> f64 {
        either!(self, b => b.length_mm)
    }
    fn limits(&self) -> Jerk {
        either!(self, b => b.limits())
    }
    fn set_caps(&mut self, length_mm: f64, feed_mm_per_min: f64, limits: Jerk) {
        either!(self, b => b.set_caps(length_mm, feed_mm_per_min, limits))
    }
    fn set_feeds(&mut self, start_mm_per_min: f64, end_mm_per_min: f64) {
        either!(self, b => b.set_feeds(start_mm_per_min, end_mm_per_min))
    }
    fn planned_mm_s(&self) -> (f64, f64, f64) {
        either!(self, b => b.planned_mm_s())
    }
    fn split_straight(&self, t: f64) -> Option<(Self, Self)> {
        match self {
            Block::Straight(s) => s
                .split(t)
                .map(|(a, b)| (Block::Straight(a), Block::Straight(b))),
            Block::Whole(_) => None,
        }
    }
}
