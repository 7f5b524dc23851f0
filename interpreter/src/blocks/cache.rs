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
//! Each curve block's [`samples`](super::samples) (its frames, curvature rates and their
//! places along it, as [`Figure`](super::Figure)s: a few kilobytes a block) are kept
//! too, within [`SAMPLES_BUDGET`] bytes: [`shape`](super::shape), [`relax`](super::relax)
//! in every round and the
//! braking search of the backward pass in every round took them afresh, four to five
//! times a curve block, and sampling was more than half of `cnc check` on curves. A plan
//! is one window of the program ([`crate::window`]), so the budget is rarely reached;
//! past it, the samples are taken afresh where asked, as before.

use super::{shape, shape_from, Geometry, Sampled, Shape};
use shared::path;
use shared::protocol::CommandBlock;
use shared::Machine;
use std::rc::Rc;

/// Most bytes of samples one plan keeps (see the module page).
pub(super) const SAMPLES_BUDGET: usize = 64 << 20;

/// See the module page.
pub(super) struct PlanCache {
    /// Each block's length (NaN until asked for), by its index in the plan.
    lengths: Vec<f64>,
    /// Each curve block's shapes asked for, with the feed (mm/s) and share each was
    /// worked out for (as bits).
    shapes: Vec<[Option<Box<Kept>>; 2]>,
    /// Each curve block's samples, taken with their places ([`Sampled::of`]).
    samples: Vec<Option<Rc<Sampled>>>,
    /// Bytes of the samples kept.
    kept_bytes: usize,
}

/// A shape with the feed (mm/s) and share it was worked out for, as bits.
type Kept = ([u64; 2], Shape);

impl PlanCache {
    /// A cache for a plan of `n` blocks (none: nothing is kept).
    pub(super) fn new(n: usize) -> Self {
        PlanCache {
            lengths: vec![f64::NAN; n],
            shapes: (0..n).map(|_| [None, None]).collect(),
            samples: vec![None; n],
            kept_bytes: 0,
        }
    }

    /// The samples of block `i`, whose curve is `c`, with their places ([`samples`]).
    pub(super) fn samples(&mut self, i: usize, c: &CommandBlock) -> Rc<Sampled> {
        if let Some(Some(kept)) = self.samples.get(i) {
            return Rc::clone(kept);
        }
        let taken = Rc::new(Sampled::of(c));
        let bytes = taken.bytes();
        if let Some(slot) = self.samples.get_mut(i) {
            if self.kept_bytes + bytes <= SAMPLES_BUDGET {
                self.kept_bytes += bytes;
                *slot = Some(Rc::clone(&taken));
            }
        }
        taken
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
        let found = match g {
            Geometry::Curve(c) if !c.is_surface() => {
                let sampled = self.samples(i, c);
                shape_from(g, Some(&sampled), machine, period_s, feed_mm_s, share)
            }
            _ => shape(g, machine, period_s, feed_mm_s, share),
        };
        let slots = &mut self.shapes[i];
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
