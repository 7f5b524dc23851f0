//! The contour error and roundness the page draws, measured here from the same files as
//! `report.json`'s (so the plots and the summary agree) by [`crate::contour`], reading
//! the traces a batch of rows at a time. Each feedback row's contour error, which the
//! error plots read back in order, goes to a temporary file ([`crate::spill`]).

use super::data::Run;
use crate::contour::{Reached, RoundnessPlot, Worst};
use crate::spill::{Spill, Spilled};

/// What the page draws of the contour analysis.
pub struct Measure {
    pub max: Option<Worst>,
    /// Where the last set-point with a feedback row lies on the path.
    pub reached: Option<Reached>,
    /// The roundness, or why the path has none.
    pub roundness: Result<RoundnessPlot, String>,
    /// Each feedback row's contour error, µm; NaN where it is not counted.
    errors: Spilled<1>,
}

impl Measure {
    /// The run's measure; `None` without the traces or the command log (or where a
    /// temporary file cannot be written).
    pub fn of(run: &Run) -> Option<Measure> {
        let (sp, fb) = (run.setpoints.as_ref()?, run.feedback.as_ref()?);
        if run.blocks.is_empty() {
            return None;
        }
        let mut errors = Spill::<1>::new().ok()?;
        let mut ok = true;
        let mut put = |errors: &mut Spill<1>, um: Option<f64>| {
            ok &= errors.push([um.unwrap_or(f64::NAN)]).is_ok();
        };
        let m = crate::contour::measure_for_page(
            &run.blocks,
            sp.rows(),
            fb.rows().map(|(cycle, p, _)| (cycle, p)),
            &mut |i, um| {
                // The rows without a set-point before this one are not counted.
                while errors.len() < i {
                    put(&mut errors, None);
                }
                put(&mut errors, um);
            },
        );
        while errors.len() < fb.len() {
            put(&mut errors, None);
        }
        Some(Measure {
            max: m.max,
            reached: m.reached,
            roundness: m.roundness,
            errors: errors.finish().ok().filter(|_| ok)?,
        })
    }

    /// Each feedback row's contour error in µm, in order; `None` where it is not
    /// counted (no set-point that cycle, a set-point on a rapid, or no path).
    pub fn errors(&self) -> impl Iterator<Item = Option<f64>> + '_ {
        self.errors
            .records()
            .map(|[um]| Some(um).filter(|um| !um.is_nan()))
    }
}
