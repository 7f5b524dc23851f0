//! The roundness as the page's polar plot draws it, measured from the cycles on the
//! circle kept in temporary files ([`crate::spill`]) rather than in memory: a circle run
//! for an hour has millions of them. The points are read back a pass at a time (the
//! fit, the turn, the ramps' steady step, the deviations), so every figure is
//! [`super::Roundness`]'s to the last bit, and the plot's points are handed out a pass at
//! a time too ([`Deviations`]).

use super::stream::{measure, FbRow, SpRow};
use super::{
    circle_run, fit_circle_by, main_circle, radius, segs_of, turning_by, CircleRun, Reached,
    RoundnessSummary, Seg, Worst,
};
use crate::spill::{Spill, Spilled};
use shared::protocol::CommandBlock;
use std::cell::Cell;
use std::f64::consts::PI;

/// What the page measures of a run ([`measure_for_page`]).
pub struct PageMeasure {
    pub max: Option<Worst>,
    pub reached: Option<Reached>,
    /// The roundness, or why the path has none.
    pub roundness: Result<RoundnessPlot, String>,
}

/// [`super::Roundness`] with its points in a temporary file.
pub struct RoundnessPlot {
    /// The figures (`samples`: the cycles on the circle).
    pub figures: RoundnessSummary,
    pub commanded_roundness_um: f64,
    /// [`super::Roundness::steady_roundness_um`].
    pub steady_roundness_um: f64,
    /// The smallest and the largest deviation of the measured positions, µm.
    pub deviation_um: (f64, f64),
    pub ramps_left_out: (usize, usize),
    /// The measured and commanded positions' deviations.
    pub points: Deviations,
    pub reverse: Option<ReversePlot>,
}

/// [`super::ReverseRun`] with its points in a temporary file.
pub struct ReversePlot {
    pub lines: (u32, u32),
    pub roundness_um: f64,
    pub radius_offset_um: f64,
    pub ramps_left_out: (usize, usize),
    /// Its measured positions' deviations about the first run's circle.
    pub points: Deviations,
}

/// The cycles on a circle (measured, then commanded position in its plane), and the
/// circle their deviations are taken about.
pub struct Deviations {
    points: Spilled<4>,
    centre: [f64; 2],
    r: f64,
    ramps: (usize, usize),
}

impl Deviations {
    /// The cycles drawn: all but the ramps (all of them if that leaves none).
    fn steady(&self) -> std::ops::Range<usize> {
        let (n, (head, tail)) = (self.points.len(), self.ramps);
        if head + tail < n {
            head..n - tail
        } else {
            0..n
        }
    }

    /// How many cycles are drawn (see [`Deviations::each_steady`]).
    pub fn steady_len(&self) -> usize {
        self.steady().len()
    }

    /// `(angle about the centre in rad, radius − the circle's in µm)` of the measured
    /// (or, `commanded`, the commanded) position of each cycle drawn, in order. Ends
    /// early where the temporary file cannot be read.
    pub fn each_steady(&self, commanded: bool, f: &mut dyn FnMut((f64, f64))) {
        let range = self.steady();
        let k = if commanded { 2 } else { 0 };
        for q in self.points.records().take(range.end).skip(range.start) {
            f(self.dev([q[k], q[k + 1]]));
        }
    }

    fn dev(&self, p: [f64; 2]) -> (f64, f64) {
        let c = self.centre;
        (
            (p[1] - c[1]).atan2(p[0] - c[0]),
            (radius(p, c) - self.r) * 1e3,
        )
    }
}

/// The figures of [`super::analyse`] the page shows, each feedback row's contour error
/// handed to `on_error` as [`super::stream::measure`] does, and the roundness with the
/// points its plot draws; the traces read a batch of rows at a time.
pub fn measure_for_page(
    blocks: &[CommandBlock],
    sp: impl IntoIterator<Item = SpRow>,
    fb: impl IntoIterator<Item = FbRow>,
    on_error: &mut dyn FnMut(usize, Option<f64>),
) -> PageMeasure {
    let segs = segs_of(blocks);
    let circles = plot_circles(&segs);
    let m = measure(&segs, circles.as_deref().unwrap_or(&[]), sp, fb, on_error);
    PageMeasure {
        max: m.max,
        reached: m.reached,
        roundness: circles.and_then(|c| roundness_plot(&segs, &c, m.points)),
    }
}

/// The circle [`super::roundness`] measures, then each run of the same circle the other
/// way round after it ([`super::roundness`]'s candidates for its reverse run).
fn plot_circles(segs: &[Seg]) -> Result<Vec<CircleRun>, String> {
    let (runs, k, c) = main_circle(segs)?;
    let (first, last) = (c.first, c.last);
    let mut out = Vec::new();
    for &run in &runs[k + 1..] {
        let Ok(o) = circle_run(segs, run) else {
            continue;
        };
        let apart = o.last < first || o.first > last;
        let same = apart
            && o.axes == c.axes
            && o.ccw != c.ccw
            && radius(o.centre, c.centre) <= 1e-3 + 1e-3 * c.radius
            && (o.radius - c.radius).abs() <= 1e-3 + 1e-3 * c.radius;
        if same {
            out.push(o);
        }
    }
    out.insert(0, c);
    Ok(out)
}

/// Calls `f` with every record of `s`; a read that fails sets `failed`.
fn each(s: &Spilled<4>, failed: &Cell<bool>, mut f: impl FnMut([f64; 4])) {
    let mut recs = s.records();
    for q in &mut recs {
        f(q);
    }
    if recs.failed().is_some() {
        failed.set(true);
    }
}

/// The measured positions of `s`, a pass over them for each call.
fn measured<'a>(
    s: &'a Spilled<4>,
    failed: &'a Cell<bool>,
) -> impl FnMut(&mut dyn FnMut([f64; 2])) + 'a {
    move |f| each(s, failed, |q| f([q[0], q[1]]))
}

/// The roundness of `circles[0]` (and its reverse run among the others) from the
/// cycles on each, `points`, as [`super::roundness`] works them out.
fn roundness_plot(
    segs: &[Seg],
    circles: &[CircleRun],
    points: Vec<Result<Spill<4>, String>>,
) -> Result<RoundnessPlot, String> {
    let failed = Cell::new(false);
    let mut points = points.into_iter();
    let c = &circles[0];
    let main = points
        .next()
        .unwrap_or_else(|| Err("no measured positions".into()))?
        .finish()
        .map_err(|e| format!("temporary file: {e}"))?;
    let n = main.len();
    if n < 16 {
        return Err(format!("only {n} measured positions on the circle"));
    }
    let (centre, r) = fit_circle_by(n, measured(&main, &failed))
        .ok_or("no circle fits the measured positions")?;
    // A run stopped part of the way round has no roundness: an arc's fit is not the
    // circle's.
    if turning_by(measured(&main, &failed), c.centre).0.abs() < 2.0 * PI * 0.98 {
        return Err("the run stopped before it went round the circle".into());
    }
    let reverse = circles[1..].iter().zip(points).find_map(|(o, p)| {
        let m = p.ok()?.finish().ok()?;
        let (oc, or) = fit_circle_by(m.len(), measured(&m, &failed))?;
        // Cut short by a stop: an arc's fit is not the circle's.
        if m.len() < 16 || turning_by(measured(&m, &failed), o.centre).0.abs() < 2.0 * PI * 0.98 {
            return None;
        }
        let own = min_max(|f| each(&m, &failed, |q| f(radius([q[0], q[1]], oc) - or)));
        let ramps = ramps(&m, &failed);
        Some(ReversePlot {
            lines: (segs[o.first].b.source_line, segs[o.last].b.source_line),
            roundness_um: spread(own) * 1e3,
            radius_offset_um: (or - r) * 1e3,
            ramps_left_out: ramps,
            points: Deviations {
                points: m,
                centre,
                r,
                ramps,
            },
        })
    });
    let (cc, cr) = (c.centre, c.radius);
    let about_commanded =
        min_max(|f| each(&main, &failed, |q| f((radius([q[2], q[3]], cc) - cr) * 1e3)));
    let ramps = ramps(&main, &failed);
    let points = Deviations {
        points: main,
        centre,
        r,
        ramps,
    };
    let deviation_um = min_max(|f| {
        each(&points.points, &failed, |q| f(points.dev([q[0], q[1]]).1));
    });
    let steady = min_max(|f| points.each_steady(false, &mut |d| f(d.1)));
    if failed.get() {
        return Err("temporary file: a read failed".into());
    }
    Ok(RoundnessPlot {
        figures: RoundnessSummary {
            axes: c.axes,
            centre_mm: centre,
            radius_mm: r,
            commanded_centre_mm: cc,
            commanded_radius_mm: cr,
            roundness_um: spread(deviation_um),
            lines: (segs[c.first].b.source_line, segs[c.last].b.source_line),
            samples: n,
            ccw: c.ccw,
        },
        commanded_roundness_um: spread(about_commanded),
        steady_roundness_um: spread(steady),
        deviation_um,
        ramps_left_out: ramps,
        points,
        reverse,
    })
}

/// The smallest and largest of the values `each` gives (infinities for none).
fn min_max(each: impl FnOnce(&mut dyn FnMut(f64))) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    each(&mut |d| (lo, hi) = (lo.min(d), hi.max(d)));
    (lo, hi)
}

/// `hi − lo`, 0 for none ([`super::spread`]).
fn spread((lo, hi): (f64, f64)) -> f64 {
    if hi >= lo {
        hi - lo
    } else {
        0.0
    }
}

/// The commanded steps between consecutive cycles on the circle, in order.
fn steps(s: &Spilled<4>, failed: &Cell<bool>, mut f: impl FnMut(f64)) {
    let mut prev: Option<[f64; 2]> = None;
    each(s, failed, |q| {
        let p = [q[2], q[3]];
        if let Some(a) = prev.replace(p) {
            f((p[0] - a[0]).hypot(p[1] - a[1]));
        }
    });
}

/// How many cycles at each end of the circle are its ramps from and to rest (as
/// [`super::circle_cycles`] counts them): the commanded steps below 98 % of the steady
/// step, the steps' 90th percentile.
fn ramps(s: &Spilled<4>, failed: &Cell<bool>) -> (usize, usize) {
    let n_steps = s.len().saturating_sub(1);
    let steady = if n_steps == 0 {
        0.0
    } else {
        nth_smallest(n_steps * 9 / 10, |f| steps(s, failed, f))
    };
    let slow = |d: f64| d < 0.98 * steady;
    let (mut head, mut tail, mut leading) = (0, 0, true);
    steps(s, failed, |d| {
        if slow(d) {
            head += usize::from(leading);
            tail += 1;
        } else {
            leading = false;
            tail = 0;
        }
    });
    if steady > 0.0 && head + tail + 16 < s.len() {
        (head, tail)
    } else {
        (0, 0)
    }
}

/// The `k`-th smallest (from 0, in [`f64::total_cmp`]'s order) of the values `each`
/// gives, in four passes over them and 512 KiB: a radix selection on 16 bits of the
/// value's order key per pass. What sorting them all would give.
fn nth_smallest(mut k: usize, mut each: impl FnMut(&mut dyn FnMut(f64))) -> f64 {
    // The order key: the bits, sign flipped for a positive number and all flipped for a
    // negative one, compare as unsigned integers as `total_cmp` compares the numbers.
    let key = |x: f64| {
        let b = x.to_bits();
        if b >> 63 == 1 {
            !b
        } else {
            b | 1 << 63
        }
    };
    let mut prefix = 0u64;
    let mut hist = vec![0usize; 1 << 16];
    for shift in [48u32, 32, 16, 0] {
        hist.iter_mut().for_each(|h| *h = 0);
        each(&mut |x| {
            let q = key(x);
            if q.checked_shr(shift + 16).unwrap_or(0) == prefix {
                hist[(q >> shift & 0xffff) as usize] += 1;
            }
        });
        let mut digit = 0;
        for (d, &h) in hist.iter().enumerate() {
            digit = d as u64;
            if k < h {
                break;
            }
            k -= h;
        }
        prefix = prefix << 16 | digit;
    }
    f64::from_bits(if prefix >> 63 == 1 {
        prefix & !(1 << 63)
    } else {
        !prefix
    })
}

#[cfg(test)]
mod tests {
    use super::{measure_for_page, nth_smallest};
    use crate::contour::tests::blocks_of;
    use crate::contour::{analyse, steady, Traces};
    use shared::protocol::BlockKind;

    /// A circle run one way then the other, each from rest to rest: the page's measure
    /// is the whole-trace analysis's, every figure and every point drawn to the last bit.
    #[test]
    fn the_page_s_roundness_is_the_whole_trace_s() {
        let blocks = blocks_of(
            "G21 G17 G90\nG0 X10 Y0\nG3 X10 Y0 I-10 J0 F3000\nG2 X10 Y0 I-10 J0 F3000\nM2\n",
        );
        let (mut sp, mut line) = (Vec::new(), Vec::new());
        for b in blocks
            .iter()
            .filter(|b| b.kind() == Some(BlockKind::Motion))
        {
            let (u0, u1) = shared::path::domain(b);
            let n = 4000;
            for i in 1..=n {
                // Eased in and out: ramps from and to rest at each end.
                let x = i as f64 / n as f64;
                let s = x * x * (3.0 - 2.0 * x);
                sp.push(crate::blocks::set_point_eval(b, u0 + (u1 - u0) * s).p);
                line.push(b.source_line);
            }
        }
        let fb: Vec<[f64; 3]> = sp
            .iter()
            .map(|p| {
                let t = p[1].atan2(p[0]);
                let r = p[0].hypot(p[1]) + 0.003 * (3.0 * t).sin() - 0.002;
                [r * t.cos(), r * t.sin(), p[2]]
            })
            .collect();
        let cycles: Vec<u64> = (0..sp.len() as u64).collect();
        // One set-point in 500 lost.
        let keep: Vec<usize> = (0..sp.len()).filter(|i| i % 500 != 499).collect();
        let sp_cycle: Vec<u64> = keep.iter().map(|&i| cycles[i]).collect();
        let sp_pos: Vec<[f64; 3]> = keep.iter().map(|&i| sp[i]).collect();
        let sp_line: Vec<u32> = keep.iter().map(|&i| line[i]).collect();
        let whole = analyse(
            &blocks,
            &Traces {
                sp_cycle: &sp_cycle,
                sp_pos_mm: &sp_pos,
                sp_line: &sp_line,
                fb_cycle: &cycles,
                fb_pos_mm: &fb,
            },
        );
        let mut errors = vec![None; fb.len()];
        let page = measure_for_page(
            &blocks,
            (0..sp_cycle.len()).map(|i| (sp_cycle[i], sp_pos[i], sp_line[i])),
            cycles.iter().zip(&fb).map(|(c, p)| (*c, *p)),
            &mut |i, um| errors[i] = um,
        );
        assert_eq!(errors, whole.error_um);
        assert_eq!((page.max, page.reached), (whole.max, whole.reached));
        let (w, p) = (whole.roundness.unwrap(), page.roundness.ok().unwrap());
        assert_eq!(p.figures, w.summary());
        assert_ne!(w.ramps_left_out, (0, 0));
        let bits = |v: &[(f64, f64)]| -> Vec<(u64, u64)> {
            v.iter().map(|(a, d)| (a.to_bits(), d.to_bits())).collect()
        };
        let drawn = |d: &super::Deviations, commanded: bool| {
            let mut v = Vec::new();
            d.each_steady(commanded, &mut |p| v.push(p));
            bits(&v)
        };
        assert_eq!(
            (
                p.ramps_left_out,
                p.commanded_roundness_um.to_bits(),
                p.steady_roundness_um.to_bits(),
            ),
            (
                w.ramps_left_out,
                w.commanded_roundness_um.to_bits(),
                w.steady_roundness_um().to_bits(),
            )
        );
        assert_eq!(
            drawn(&p.points, false),
            bits(steady(&w.measured, w.ramps_left_out))
        );
        assert_eq!(
            drawn(&p.points, true),
            bits(steady(&w.commanded, w.ramps_left_out))
        );
        let (wr, pr) = (w.reverse.unwrap(), p.reverse.unwrap());
        assert_eq!(
            (
                pr.lines,
                pr.roundness_um.to_bits(),
                pr.radius_offset_um.to_bits(),
                pr.ramps_left_out
            ),
            (
                wr.lines,
                wr.roundness_um.to_bits(),
                wr.radius_offset_um.to_bits(),
                wr.ramps_left_out
            )
        );
        assert_eq!(
            drawn(&pr.points, false),
            bits(steady(&wr.measured, wr.ramps_left_out))
        );
    }

    #[test]
    fn nth_smallest_is_the_sorted_list_s() {
        let mut v: Vec<f64> = (0..5000)
            .map(|i| ((i * 7919) % 5003) as f64 * 0.013 - 20.0)
            .chain([0.0, -0.0, 1e-300, -1e300, 3.5, 3.5, 3.5])
            .collect();
        let each = |v: &Vec<f64>| {
            let v = v.clone();
            move |f: &mut dyn FnMut(f64)| v.iter().for_each(|x| f(*x))
        };
        let mut sorted = v.clone();
        sorted.sort_by(f64::total_cmp);
        for k in [0, 1, 17, 2500, 4500, v.len() - 1] {
            assert_eq!(
                nth_smallest(k, each(&v)).to_bits(),
                sorted[k].to_bits(),
                "{k}"
            );
        }
        v.truncate(1);
        assert_eq!(nth_smallest(0, each(&v)), v[0]);
    }
}
