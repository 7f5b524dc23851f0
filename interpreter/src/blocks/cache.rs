//! Each curve block's length and shapes, kept across [`plan_and`](super::plan_and)'s
//! planning rounds.
//!
//! A program with curves is planned in one to five rounds (see `plan_and`), and each
//! round took every curve block's length and [`shape`](super::shape) again, sampling its
//! curve each time, though neither changes from round to round: a block's length depends
//! on its curve alone, and its shape on its curve, its programmed feed and the share of
//! the limits its curvature may take, which is one of two
//! ([`NORMAL_SHARE`](super::NORMAL_SHARE) or [`VALLEY_SHARE`](super::VALLEY_SHARE)). So
//! each is worked out once and kept, for as long as the rounds last: 24 bytes a block (its
//! length and two slots), and each shape asked for (at most two a curve block) in about
//! 340 bytes. What is returned is the same as working it out again, bit for bit: the
//! cache changes the cost, never the plan.
//!
//! The samples themselves (a few kilobytes a block) are not kept: [`relax`](super::relax)
//! and the braking search still take them where they need them. Kept for those too
//! within a budget of 64 MiB, they saved a fifth more of `cnc check`'s time on the
//! bench's `curves` program but cost 128 MB more memory for 10 000 lines.

use super::{shape, Geometry, Shape};
use shared::path;
use shared::Machine;

/// See the module page.
pub(super) struct PlanCache {
    /// Each block's length (NaN until asked for), by its index in the plan.
    lengths: Vec<f64>,
    /// Each curve block's shapes asked for, with the feed (mm/s) and share each was
    /// worked out for (as bits).
    shapes: Vec<[Option<Box<Kept>>; 2]>,
}

/// A shape with the feed (mm/s) and share it was worked out for, as bits.
type Kept = ([u64; 2], Shape);

impl PlanCache {
    /// A cache for a plan of `n` blocks (none: nothing is kept).
    pub(super) fn new(n: usize) -> Self {
        PlanCache {
            lengths: vec![f64::NAN; n],
            shapes: (0..n).map(|_| [None, None]).collect(),
        }
    }

    /// The length of block `i`, whose curve is `c` ([`path::length`]).
    pub(super) fn length(&mut self, i: usize, c: &shared::protocol::CommandBlock) -> f64 {
        match self.lengths.get_mut(i) {
            Some(l) if !l.is_nan() => *l,
            Some(l) => {
                *l = path::length(c);
                *l
            }
            None => path::length(c),
        }
    }

    /// [`shape`] of block `i` (kept only for a curve).
    pub(super) fn shape(
        &mut self,
        i: usize,
        g: Geometry,
        machine: &Machine,
        period_s: f64,
        feed_mm_s: f64,
        share: f64,
    ) -> Shape {
        let Some(slots) = self
            .shapes
            .get_mut(i)
            .filter(|_| matches!(g, Geometry::Curve(_)))
        else {
            return shape(g, machine, period_s, feed_mm_s, share);
        };
        let key = [feed_mm_s.to_bits(), share.to_bits()];
        if let Some(kept) = slots.iter().flatten().find(|k| k.0 == key) {
            return kept.1;
        }
        let found = shape(g, machine, period_s, feed_mm_s, share);
        // An empty slot, else the first (a third key: never met, as a block's feed and
        // the two shares are all there are).
        let slot = match slots.iter().position(Option::is_none) {
            Some(free) => &mut slots[free],
            None => &mut slots[0],
        };
        *slot = Some(Box::new((key, found)));
        found
    }
}
