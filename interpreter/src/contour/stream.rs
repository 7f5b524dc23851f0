//! The figures of [`super::analyse`] measured reading the traces row by row, in batches,
//! in bounded memory: a one-hour run's traces are hundreds of megabytes. Every sum runs
//! in the same order as there, so every figure is the same to the last bit. The points
//! of the circle the roundness is measured on (every cycle of it: millions on a long
//! circle) go to a temporary file ([`crate::spill`]) and are read back once per pass of
//! the fit. The command blocks are held whole (they are what the path is measured to).
//! The page's measure ([`super::polar`]) is the same pass, handing on each row's contour
//! error and keeping the cycles on more than one circle.

use super::{
    contour_distance, dist3, distance, fit_circle_by, locate, main_circle, radius, segs_of,
    threads, turning_by, CircleRun, CsvRows, Figures, Reached, RoundnessSummary, Seg, Worst,
    ON_PATH_MM,
};
use crate::spill::Spill;
use shared::protocol::CommandBlock;
use std::f64::consts::PI;

/// A set-point row: cycle, position (mm), source line.
pub type SpRow = (u64, [f64; 3], u32);
/// A feedback row: cycle, measured position (mm).
pub type FbRow = (u64, [f64; 3]);

/// Feedback rows with a set-point measured at a time.
const BATCH: usize = 1 << 15;

/// [`super::analyse_dir`]'s figures ([`figures`]), reading `setpoints.csv` and
/// `feedback.csv` a row at a time; the same errors as [`super::read_dir`].
pub fn figures_dir(dir: &std::path::Path) -> Result<Figures, String> {
    let blocks = super::read_blocks(dir)?;
    let mut sp = CsvRows::setpoints(dir)?;
    let mut fb = CsvRows::feedback(dir)?;
    let sp_rows = std::iter::from_fn(move || {
        sp.next_row()
            .map(|r| (r[0] as u64, [r[1], r[2], r[3]], r[4] as u32))
    });
    let fb_rows =
        std::iter::from_fn(move || fb.next_row().map(|r| (r[0] as u64, [r[1], r[2], r[3]])));
    Ok(figures(&blocks, sp_rows, fb_rows))
}

/// A feedback row with the set-point of its cycle.
struct Row {
    /// Its index among the feedback rows.
    fb_i: usize,
    /// Its block.
    at: usize,
    p: [f64; 3],
    s: [f64; 3],
    fb_cycle: u64,
    sp_line: u32,
    /// Following error (mm), then contour error (µm); `None` on a rapid.
    err: Option<f64>,
}

/// The middle of a chord, its second set-point's block, its length (mm; then its
/// distance to the path, µm) and the cycle of its feedback row.
type Chord = ([f64; 3], usize, f64, u64);

/// What [`figures`] adds up as the batches go by.
struct Tally<'a, 'e> {
    segs: &'a [Seg<'a>],
    /// Each row's contour error (µm; `None` on a rapid) by its feedback row's index.
    on_error: &'e mut dyn FnMut(usize, Option<f64>),
    worst: Option<Worst>,
    sum_sq: f64,
    count: u64,
    chord: Option<Worst>,
}

impl Tally<'_, '_> {
    /// Measures a batch (spread over the cores) and adds it, in order.
    fn add(&mut self, rows: &mut [Row], chords: &mut [Chord]) {
        let segs = self.segs;
        let each = |rows: &mut [Row]| {
            for r in rows {
                if let Some(ferr) = r.err {
                    r.err = Some(contour_distance(segs, r.at, r.p, r.s, ferr) * 1e3);
                }
            }
        };
        let each_chord = |chords: &mut [Chord]| {
            for (mid, at, len, _) in chords {
                // The window reaches back over the first set-point's block.
                *len = distance(segs, *at, *mid, *len) * 1e3;
            }
        };
        let n = threads();
        std::thread::scope(|scope| {
            for part in rows.chunks_mut(rows.len().div_ceil(n).max(1024)) {
                scope.spawn(move || each(part));
            }
            for part in chords.chunks_mut(chords.len().div_ceil(n).max(1024)) {
                scope.spawn(move || each_chord(part));
            }
        });
        for &(_, at, um, cycle) in chords.iter() {
            let c = Worst {
                um,
                cycle,
                line: segs[at].b.source_line,
            };
            self.chord = Some(self.chord.filter(|w| w.um >= c.um).unwrap_or(c));
        }
        for r in rows.iter() {
            (self.on_error)(r.fb_i, r.err);
            if let Some(um) = r.err {
                self.sum_sq += um * um;
                self.count += 1;
                if self.worst.is_none_or(|w| um > w.um) {
                    self.worst = Some(Worst {
                        um,
                        cycle: r.fb_cycle,
                        line: r.sp_line,
                    });
                }
            }
        }
    }
}

/// The figures of [`super::analyse`] of the traces `sp` and `fb` (each in cycle order, as
/// the columns of [`super::Traces`]), every one the same to the last bit, holding a batch
/// of rows at a time.
pub fn figures(
    blocks: &[CommandBlock],
    sp: impl IntoIterator<Item = SpRow>,
    fb: impl IntoIterator<Item = FbRow>,
) -> Figures {
    let segs = segs_of(blocks);
    // The circle is found from the blocks alone; its measured positions are gathered as
    // the rows go by.
    let circle = main_circle(&segs).map(|(_, _, c)| c);
    let circles = circle.as_ref().map_or(&[][..], std::slice::from_ref);
    let m = measure(&segs, circles, sp, fb, &mut |_, _| {});
    let roundness = match (circle, m.points.into_iter().next()) {
        (Err(e), _) => Err(e),
        (Ok(c), Some(Ok(mut spill))) => roundness(&segs, &c, &mut spill),
        (Ok(_), Some(Err(e))) => Err(e),
        (Ok(_), None) => Err("no measured positions".into()),
    };
    Figures {
        max: m.max,
        rms_um: m.rms_um,
        chord: m.chord,
        roundness,
        reached: m.reached,
    }
}

/// What [`measure`] measures: the figures but the roundness, and the cycles on each
/// circle it was given.
pub(super) struct Measured {
    pub max: Option<Worst>,
    pub rms_um: Option<f64>,
    pub chord: Option<Worst>,
    pub reached: Option<Reached>,
    /// Per circle, the measured then the commanded position (in its plane) of each cycle
    /// whose set-point lies on it, in order; or why they could not be kept.
    pub points: Vec<Result<Spill<4>, String>>,
}

/// Measures the traces `sp` and `fb` against the path `segs` a batch of rows at a time,
/// handing each feedback row's contour error to `on_error` in order (its index among the
/// feedback rows, `None` on a rapid; rows without a set-point are not handed over), and
/// gathering the cycles on each of `circles` to a temporary file.
pub(super) fn measure(
    segs: &[Seg],
    circles: &[CircleRun],
    sp: impl IntoIterator<Item = SpRow>,
    fb: impl IntoIterator<Item = FbRow>,
    on_error: &mut dyn FnMut(usize, Option<f64>),
) -> Measured {
    let mut points: Vec<Result<Spill<4>, String>> = circles
        .iter()
        .map(|_| Spill::new().map_err(|e| format!("temporary file: {e}")))
        .collect();
    let mut tally = Tally {
        segs,
        on_error,
        worst: None,
        sum_sq: 0.0,
        count: 0,
        chord: None,
    };
    let mut last_u: Vec<f64> = segs.iter().map(|g| g.u0).collect();
    let mut cursor = 0usize;
    // The last set-point with a feedback row: its index, cycle, position and block.
    let mut prev: Option<(usize, u64, [f64; 3], usize)> = None;
    let (mut rows, mut chords): (Vec<Row>, Vec<Chord>) = (Vec::new(), Vec::new());
    if !segs.is_empty() {
        let mut sp = sp.into_iter().enumerate();
        let mut cur = sp.next();
        for (fb_i, (fb_cycle, p)) in fb.into_iter().enumerate() {
            while cur.as_ref().is_some_and(|(_, r)| r.0 < fb_cycle) {
                cur = sp.next();
            }
            let Some(&(sp_i, (sp_cycle, s, line))) = cur.as_ref().filter(|(_, r)| r.0 == fb_cycle)
            else {
                continue;
            };
            cursor = locate(segs, &mut last_u, cursor, s, line);
            let rapid = segs[cursor].rapid;
            if let Some((p_i, p_cycle, a, p_seg)) = prev {
                let next = p_i + 1 == sp_i && p_cycle + 1 == sp_cycle;
                if next && !rapid && !segs[p_seg].rapid {
                    let mid = [
                        0.5 * (a[0] + s[0]),
                        0.5 * (a[1] + s[1]),
                        0.5 * (a[2] + s[2]),
                    ];
                    chords.push((mid, cursor, dist3(a, s), fb_cycle));
                }
            }
            prev = Some((sp_i, sp_cycle, s, cursor));
            for (c, spill) in circles.iter().zip(points.iter_mut()) {
                if let (true, Ok(into)) = ((c.first..=c.last).contains(&cursor), &mut *spill) {
                    let (a, b) = c.axes;
                    if let Err(e) = into.push([p[a], p[b], s[a], s[b]]) {
                        *spill = Err(format!("temporary file: {e}"));
                    }
                }
            }
            rows.push(Row {
                fb_i,
                at: cursor,
                p,
                s,
                fb_cycle,
                sp_line: line,
                err: (!rapid).then(|| dist3(p, s)),
            });
            if rows.len() == BATCH {
                tally.add(&mut rows, &mut chords);
                rows.clear();
                chords.clear();
            }
        }
        tally.add(&mut rows, &mut chords);
    }
    let reached = prev.map(|(_, _, s, at)| {
        let mut u = last_u[at];
        if !segs[at].near_last(s, ON_PATH_MM, &mut u) {
            u = segs[at].closest(s).1;
        }
        Reached {
            seq: segs[at].b.seq,
            u,
        }
    });
    Measured {
        max: tally.worst,
        rms_um: (tally.count > 0).then(|| (tally.sum_sq / tally.count as f64).sqrt()),
        chord: tally.chord,
        reached,
        points,
    }
}

/// The roundness figures of the circle `c` from its measured positions in `spill` (as
/// [`super::roundness`] works them out).
fn roundness(
    segs: &[Seg],
    c: &CircleRun,
    spill: &mut Spill<4>,
) -> Result<RoundnessSummary, String> {
    let n = spill.len();
    if n < 16 {
        return Err(format!("only {n} measured positions on the circle"));
    }
    let mut failed: Option<std::io::Error> = None;
    let mut pass = |f: &mut dyn FnMut([f64; 2])| {
        if let Err(e) = spill.for_each(|r| f([r[0], r[1]])) {
            failed.get_or_insert(e);
        }
    };
    let fit = fit_circle_by(n, &mut pass);
    // A run stopped part of the way round has no roundness: an arc's fit is not the
    // circle's.
    let turn = fit.map(|_| turning_by(&mut pass, c.centre).0);
    // The spread of the radii about the fitted centre, as `spread` of the deviations.
    let radii = fit.map(|(centre, r)| {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        pass(&mut |p| {
            let d = (radius(p, centre) - r) * 1e3;
            (lo, hi) = (lo.min(d), hi.max(d));
        });
        if hi >= lo {
            hi - lo
        } else {
            0.0
        }
    });
    if let Some(e) = failed {
        return Err(format!("temporary file: {e}"));
    }
    let (centre, r) = fit.ok_or("no circle fits the measured positions")?;
    if turn.is_some_and(|t| t.abs() < 2.0 * PI * 0.98) {
        return Err("the run stopped before it went round the circle".into());
    }
    Ok(RoundnessSummary {
        axes: c.axes,
        centre_mm: centre,
        radius_mm: r,
        commanded_centre_mm: c.centre,
        commanded_radius_mm: c.radius,
        roundness_um: radii.unwrap_or(0.0),
        lines: (segs[c.first].b.source_line, segs[c.last].b.source_line),
        samples: n,
        ccw: c.ccw,
    })
}
