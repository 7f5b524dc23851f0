//! One curve block evaluated many times over: the planner's samples, peak searches and
//! length take a thousand points or more of each curved block, nearly all of them inside
//! the span of the one before.
//!
//! [`shared::path::eval`] finds the knot span and runs the basis-function table afresh at
//! every point (100–150 ns); the interpolator's moving-data evaluator
//! ([`FastCurve`]) loads a span's power form once, on entering it, and then takes
//! three Horner chains and the quotient rule a point (10–15 ns). [`BlockEval`] gives
//! the planner the latter, with the block's helical axial motion added as
//! `path::eval` adds it, about the curve's own origin ([`LocalCurve`]).
//!
//! Both agree within rounding, and this one is the closer to the curve: far from the
//! origin, on a narrow span, `path::eval`'s second derivative loses the rounding of the
//! coordinates (on LinuxCNC's delfino at 98 mm, spans of 1/64: 2e-9 of a curvature of
//! 0.08), which the planner's `dk/ds` (a difference of curvatures over 1e-4 of a span)
//! magnified to 3e-4 of a jerk-bound cap. The tests hold this evaluator to the general
//! one run on the curve moved to its first control point (exact: a rational curve moved
//! is the curve moved), to 1e-12 of each derivative's size.
//!
//! Surface blocks, and any curve the fast evaluator refuses (it validates again), are
//! evaluated by `path::eval` as before.

use shared::nurbs::local::LocalCurve;
use shared::nurbs::CurvePoint;
use shared::path;
use shared::protocol::CommandBlock;
use std::cell::RefCell;

/// A block's set-point path with its first two derivatives, for many evaluations.
pub(crate) struct BlockEval<'a> {
    block: &'a CommandBlock,
    /// The moving-data evaluator (its registers change with the span, hence the cell: the
    /// planner's searches take `Fn` measures); `None`: `path::eval`.
    fast: Option<RefCell<LocalCurve>>,
}

impl<'a> BlockEval<'a> {
    pub(crate) fn new(block: &'a CommandBlock) -> Self {
        let fast = if block.is_surface() {
            None
        } else {
            LocalCurve::new(block.degree as usize, block.knots(), block.ctrl())
                .ok()
                .map(RefCell::new)
        };
        BlockEval { block, fast }
    }

    /// What [`path::eval`] gives at `u`, within rounding.
    #[inline(always)]
    pub(crate) fn eval(&self, u: f64) -> CurvePoint {
        match &self.fast {
            Some(f) => {
                let mut e = f.borrow_mut().eval(u);
                path::add_axial(self.block, u, &mut e);
                e
            }
            None => path::eval(self.block, u),
        }
    }
}

impl BlockEval<'_> {
    /// [`Self::eval`] with the third derivative, where the moving-data evaluator takes
    /// the block and it has no helical axial motion (whose third derivative is not
    /// worked out); `None` elsewhere. (For `blocks::rate_at`, not used by the planner
    /// yet.)
    #[allow(dead_code)]
    pub(crate) fn eval_d3(&self, u: f64) -> Option<(CurvePoint, [f64; 3])> {
        if self.block.helix.axis != shared::protocol::Helix::NONE.axis {
            return None;
        }
        self.fast.as_ref().map(|f| f.borrow_mut().eval_d3(u))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared::nurbs::MAX_CTRL;
    use shared::protocol::{BlockKind, Helix};

    /// A small deterministic generator (xorshift64*), so the curves are the same at
    /// every run.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// The general evaluator on the block moved to its first control point, the point
    /// moved back: the reference (see the module's page).
    fn moved_eval(b: &CommandBlock, u: f64) -> CurvePoint {
        let o = b.ctrl()[0];
        let moved: Vec<[f64; 4]> = b
            .ctrl()
            .iter()
            .map(|c| [c[0] - o[0], c[1] - o[1], c[2] - o[2], c[3]])
            .collect();
        let mut e = shared::nurbs::eval(b.degree as usize, b.knots(), &moved, u);
        for (p, o) in e.p.iter_mut().zip(o) {
            *p += o;
        }
        e
    }

    fn block(degree: usize, knots: &[f64], ctrl: &[[f64; 4]]) -> CommandBlock {
        let mut b = CommandBlock::empty(BlockKind::Motion, 0, 1);
        b.degree = degree as u32;
        b.n_ctrl = ctrl.len() as u32;
        b.ctrl[..ctrl.len()].copy_from_slice(ctrl);
        b.knots[..knots.len()].copy_from_slice(knots);
        b
    }

    /// Random rational curves of degree 1 to 9 (random clamped knots, some repeated,
    /// weights 0.2 to 5, coordinates up to ±1000 mm, or every point within 0.05 mm of
    /// one up to 1000 mm from the origin: a small curve far out): the fast evaluation
    /// agrees with the general one (about the first control point) at random parameters, visited in random order (span jumps back and
    /// forth) and at every knot, to 1e-12 of the scale of each quantity (the point's to
    /// the curve's size, each derivative's to the largest magnitude of that derivative
    /// seen on the curve; the power form's rounding grows with the degree and the span's
    /// share of the domain, and stays far below that).
    #[test]
    fn the_fast_evaluation_agrees_with_the_general_one_on_random_curves() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let mut worst = [0.0f64; 3];
        for case in 0..400 {
            let degree = 1 + case % 9;
            let n = (degree + 1 + (rng.next() * (MAX_CTRL - degree) as f64) as usize).min(MAX_CTRL);
            // Every other curve small and far out.
            let (far, size) = if case % 2 == 0 {
                ([0.0; 3], 1000.0)
            } else {
                ([0.0; 3].map(|_| (rng.next() - 0.5) * 2000.0), 0.05)
            };
            let ctrl: Vec<[f64; 4]> = (0..n)
                .map(|_| {
                    [
                        far[0] + (rng.next() - 0.5) * 2.0 * size,
                        far[1] + (rng.next() - 0.5) * 2.0 * size,
                        far[2] + (rng.next() - 0.5) * 0.2 * size,
                        0.2 + 4.8 * rng.next(),
                    ]
                })
                .collect();
            let inner = n - degree - 1;
            let mut knots = vec![0.0; degree + 1];
            let mut u = 0.0;
            for _ in 0..inner {
                // Now and then a repeated knot (a span of zero length).
                if rng.next() > 0.15 {
                    u += 0.05 + rng.next();
                }
                knots.push(u);
            }
            u += 0.05 + rng.next();
            knots.extend(std::iter::repeat_n(u, degree + 1));
            let b = block(degree, &knots, &ctrl);
            let ev = BlockEval::new(&b);
            assert!(
                ev.fast.is_some(),
                "case {case}: the fast evaluator refused it"
            );
            let mut us: Vec<f64> = (0..200).map(|_| rng.next() * u).collect();
            us.extend(knots.iter().copied());
            let refs: Vec<CurvePoint> = us.iter().map(|&x| moved_eval(&b, x)).collect();
            let scale = |f: fn(&CurvePoint) -> [f64; 3]| {
                refs.iter()
                    .flat_map(f)
                    .fold(0.0f64, |m, x| m.max(x.abs()))
                    .max(1e-300)
            };
            let scales = [scale(|e| e.p), scale(|e| e.d1), scale(|e| e.d2)];
            for (&x, r) in us.iter().zip(&refs) {
                let e = ev.eval(x);
                for (k, (a, b)) in [(e.p, r.p), (e.d1, r.d1), (e.d2, r.d2)]
                    .into_iter()
                    .enumerate()
                {
                    let err = (0..3).fold(0.0f64, |m, i| m.max((a[i] - b[i]).abs())) / scales[k];
                    worst[k] = worst[k].max(err);
                    assert!(
                        err <= 1e-12,
                        "case {case}, degree {degree}, u {x}: derivative {k} off by {err:e} of its scale"
                    );
                }
            }
        }
        eprintln!("worst relative differences (point, d1, d2): {worst:?}");
    }

    /// `path::length` (the adaptive quadrature on the fast evaluator, 4 pieces a span)
    /// against the same quadrature on the general evaluator about the first control
    /// point, on random curves of degree 1 to 9, half of them small (0.05 mm) and up to
    /// 1000 mm out: within 1e-12 of the length, plus 1e-15 mm (the pieces' sums round).
    #[test]
    fn block_lengths_agree_with_the_general_evaluator() {
        let mut rng = Rng(0x2545_f491_4f6c_dd1d);
        for case in 0..200 {
            let degree = 1 + case % 9;
            let n = degree + 1 + (rng.next() * 8.0) as usize;
            let size = if case % 2 == 0 { 100.0 } else { 0.05 };
            let far = [0.0; 3].map(|_| (rng.next() - 0.5) * 2000.0);
            let ctrl: Vec<[f64; 4]> = (0..n)
                .map(|_| {
                    let r = [0.0; 3].map(|_| (rng.next() - 0.5) * 2.0 * size);
                    [
                        far[0] + r[0],
                        far[1] + r[1],
                        far[2] + r[2],
                        0.5 + rng.next(),
                    ]
                })
                .collect();
            let mut knots = vec![0.0; degree + 1];
            for i in 1..n - degree {
                knots.push(i as f64 + 0.5 * rng.next());
            }
            knots.extend(std::iter::repeat_n((n - degree) as f64, degree + 1));
            let b = block(degree, &knots, &ctrl);
            let got = path::length(&b);
            let want = shared::nurbs::arc_length_adaptive(b.knots(), 4, |u| {
                path::norm(moved_eval(&b, u).d1)
            });
            assert!(
                (got - want).abs() <= 1e-12 * want + 1e-15,
                "case {case}, degree {degree}: {got} against {want}"
            );
        }
    }

    /// A helical block (an arc with an axial lead) gets its axial motion as `path::eval`
    /// gives it.
    #[test]
    fn a_helix_gets_its_axial_motion() {
        let machine = shared::Machine::default();
        let moves = crate::program::interpret("G17 G1 X10 Y0 Z0 F600\nG2 X0 Y10 Z-3 I-10 J0\n")
            .expect("reads")
            .moves;
        let blocks = crate::blocks::commands(&crate::blocks::build(&moves, &machine));
        let mut seen = 0;
        for b in blocks.iter().filter(|b| b.helix.axis != Helix::NONE.axis) {
            let ev = BlockEval::new(b);
            let (u0, u1) = path::domain(b);
            for i in 0..=50 {
                let u = u0 + (u1 - u0) * i as f64 / 50.0;
                let (a, r) = (ev.eval(u), path::eval(b, u));
                for (x, y) in
                    a.p.iter()
                        .chain(&a.d1)
                        .chain(&a.d2)
                        .zip(r.p.iter().chain(&r.d1).chain(&r.d2))
                {
                    assert!(
                        (x - y).abs() <= 1e-9 * (1.0 + y.abs()),
                        "u {u}: {x} against {y}"
                    );
                }
            }
            seen += 1;
        }
        assert!(seen > 0, "no helical block built");
    }
}
