//! LinuxCNC's "naive CAM detector", `G64 P<p> Q<q>`: a run of straight feed moves at
//! one feed whose points lie within `q` of one straight line is made that one line,
//! before the corners are blended ([`super::blend`]); or a stretch of such runs is made
//! one smooth curve within `p + q`; whichever of these and the moves as programmed is
//! quickest.
//!
//! CAM output writes curves as thousands of short chords, each vertex rounded to the
//! decimals of the post. Followed exactly, every vertex is a kink: the rounding alone
//! turns the path by tenths of a degree at every 20–50 µm, and no blend of half a chord
//! passes that at the feed. Merged within `q`, the chords become lines of a millimetre
//! or so, whose corners the `P` blends pass at the feed. LinuxCNC does this in its
//! canonical layer (`emccanon.cc`, before its planner) whenever it blends with a
//! tolerance, and a program written for it is timed and finished with it.
//!
//! # What is merged, as LinuxCNC merges
//!
//! * `Q` is `G64`'s `Q` word; without one, `P`'s value (a `G64 P0.01` merges within
//!   0.01 mm). A bare `G64`, `P0` without `Q`, `G61` and `G61.1` merge nothing.
//! * A run starts at a feed move's start `B`. Each next feed move at the same feed, its
//!   start the run's last point, joins the run while every point of the run so far (the
//!   ends of its moves) lies within `q` of the segment from `B` to the new move's end,
//!   and at most 101 points are joined (LinuxCNC's bound). Anything else (a rapid, an
//!   arc, a curve, a dwell, a stop, a spindle or path-mode change, a new feed, a move
//!   back to `B`) ends the run. (LinuxCNC also makes a small XY arc two lines that may
//!   join a run; not done here.)
//! * The run becomes one line from `B` to its last point, carrying the last move's
//!   source line: the lines it swallowed make no block of their own.
//!
//! The merged line and the programmed moves are within `q` of each other, both ways.
//! Every joined point lies within `q` of the segment, and so does every point of the
//! moves between them (the distance to a segment is convex). And the moves run from one
//! end of the segment to the other, so each point of the segment is the foot of some
//! point of the moves on it, within `q`. The `P` blend then keeps within `p` of the
//! merged path's corners: the tool is within `p + q` of the program, as on LinuxCNC.
//!
//! # Smoothed
//!
//! The merged lines' corners, blended within `p`, bring the curvature in bursts, and on
//! a machine with a jerk limit those bursts hold the feed down (R20 in 0.05 mm chords at
//! F6000 on the built-in machine: 2.868 s merged, 2.050 s for the same circle as one
//! `G3`). So a stretch of runs (a run may be a single move, where none merge) may also
//! be made the C2 cubic spline through the merged lines' vertices (programmed points),
//! by chord length: one cubic Bézier piece per run, carrying the run's last source
//! line, the pieces meeting in tangent and curvature ([`smoothed`]). It leaves in the
//! direction the curve handed out before it arrives in (one tangent across the seam),
//! or along Bessel's tangent with the line before it, and arrives along Bessel's
//! tangent with the next stretch's first point ([`NaiveCam::tangents`]); with nothing
//! before or after, along the programmed move. It is kept only where each piece and the
//! moves it replaces are within `p + q` of each other both ways, the same envelope,
//! certified by samples close enough that nothing between them can stray further
//! (2.155 s for that circle; `examples/cam-circle.ngc`, Ø20 in 100 chords of 0.63 mm
//! that merge nothing, 1.708 → 1.405 s).
//!
//! # The quickest kept
//!
//! LinuxCNC merges every run it can. Its machine has no jerk limit, and there the
//! merged lines always win. A machine with a jerk limit may pass the blends of the
//! unmerged chords quicker than those of the merged lines: R5 in 0.2 mm chords at F6000,
//! `P0.01`, takes 1.731 s merged on the built-in machine and 1.419 s not. `Q` is a
//! bound, not an order, so the ways are weighed. Adjacent runs are gathered into a
//! stretch about sixteen times as long as the machine needs to stop from their feed
//! ([`super::blend::stop_distance`]). A stretch is merged where every kink of the merged
//! lines is passed at the feed, and kept as programmed where every kink of the moves is
//! (the corner screen's bound, [`passed_at_feed`]). Otherwise the merged lines, the moves
//! and the smoothed curve are each stepped through the interpreter's engine from rest to
//! rest under the path mode in force, after the moves handed out just before and with
//! the start of the next stretch, as programmed, after them (what a way costs the
//! stretch after it counts too), blends decided as the planner decides them
//! ([`super::blend::cycles_of`]), and the quickest is kept (a tie to the merge).
//!
//! What was merged or smoothed, how many moves and within what envelope, is said once,
//! as a note at the first line changed ([`NaiveCam::note`], with `cnc check`'s feed
//! notes): the tool no longer passes every programmed vertex there.
//!
//! The merge is streamed ([`NaiveCam::take`]): a stretch is held back only while it may
//! still grow, so how a program is handed over in batches does not change the merge.

use super::blend::{
    cycles_of_quick, de_casteljau, decision_period, stop_distance, turn_between, weakest,
};
use super::{dot, unit_of};
use crate::program::{Move, PathControl};
use shared::path::{norm, sub};
use shared::Machine;

/// Most points LinuxCNC joins into one line (its `chained_points.size() > 100`).
const MAX_POINTS: usize = 101;

/// A stretch is weighed once it is this many times as long as the machine needs to
/// stop from its feed, and holds at least [`MIN_RUNS`] runs.
const STOPS_PER_STRETCH: f64 = 16.0;
/// Fewest runs a stretch is weighed with (unless it ends first).
const MIN_RUNS: usize = 4;
/// Most runs a stretch holds (what is held back stays bounded).
const MAX_RUNS: usize = 256;

/// A run of feed moves that may become one line: from `start`, through `points` (each
/// the end of a move, with its source line).
#[derive(Debug, Clone)]
struct Run {
    start: [f64; 3],
    feed: f64,
    points: Vec<([f64; 3], u32)>,
}

impl Run {
    fn end(&self) -> [f64; 3] {
        self.points.last().map_or(self.start, |p| p.0)
    }

    /// The moves as programmed.
    fn programmed(&self, out: &mut Vec<Move>) {
        let mut from = self.start;
        for &(to, line) in &self.points {
            out.push(line_move(line, from, to, self.feed));
            from = to;
        }
    }

    /// The one merged line.
    fn merged(&self, out: &mut Vec<Move>) {
        if let Some(&(to, line)) = self.points.last() {
            out.push(line_move(line, self.start, to, self.feed));
        }
    }
}

fn line_move(line: u32, from: [f64; 3], to: [f64; 3], feed: f64) -> Move {
    Move::Line {
        line,
        from,
        to,
        rapid: false,
        feed,
    }
}

/// What was merged and smoothed ([`NaiveCam::note`]): the first source line changed,
/// the moves replaced, the lines and curve pieces they became, and the widest envelope
/// they keep (mm).
#[derive(Debug, Default)]
struct Told {
    first: Option<u32>,
    moves: usize,
    lines: usize,
    pieces: usize,
    envelope: f64,
}

/// The merge as moves stream through it (see the module page).
#[derive(Debug)]
pub struct NaiveCam {
    machine: Machine,
    /// The path mode in force (its merge tolerance: [`tolerance`]).
    mode: Option<PathControl>,
    /// The run growing.
    run: Option<Run>,
    /// The runs before it, each starting where the one before ended: the stretch that
    /// is weighed whole.
    stretch: Vec<Run>,
    stretch_mm: f64,
    /// The stretch before, complete, waiting for the start of the next to be weighed
    /// with: what a merge costs the lines after it counts too.
    waiting: Vec<Run>,
    /// What was merged and smoothed, for [`NaiveCam::note`].
    told: Told,
    /// The end of the stretch handed out last, as handed out, where the stretch being
    /// gathered continues it: both ways are timed after it, so a stretch is weighed at
    /// the speed it is entered at, with the seam between them.
    lead: Vec<Move>,
}

impl NaiveCam {
    /// Nothing read yet, for `machine`.
    pub fn new(machine: &Machine) -> Self {
        NaiveCam {
            machine: machine.clone(),
            mode: None,
            run: None,
            stretch: Vec::new(),
            stretch_mm: 0.0,
            waiting: Vec::new(),
            told: Told::default(),
            lead: Vec::new(),
        }
    }

    /// The moves that follow those taken before, merged; a stretch that may still grow
    /// is held back for the next call (or [`NaiveCam::finish`]).
    pub fn take(&mut self, moves: Vec<Move>) -> Vec<Move> {
        if self.q().is_none()
            && self.run.is_none()
            && self.waiting.is_empty()
            && !moves.iter().any(is_mode)
        {
            return moves;
        }
        let mut out = Vec::with_capacity(moves.len());
        for m in moves {
            self.push(m, &mut out);
        }
        out
    }

    /// What a machinist is told once the program is read: where moves were merged or
    /// smoothed, how many, and within what of the program (a note at the first line
    /// changed), or nothing.
    pub fn note(&self) -> Option<(u32, String)> {
        let t = &self.told;
        let line = t.first?;
        let into = match (t.lines, t.pieces) {
            (l, 0) => format!("{l} merged lines"),
            (0, p) => format!("{p} smoothed curve pieces"),
            (l, p) => format!("{l} merged lines and {p} smoothed curve pieces"),
        };
        Some((
            line,
            format!(
                "G64 P: {} short moves from here on run as {into}, within P + Q of the program \
                 ({} mm at most here), where that is quicker (LinuxCNC's naive CAM merge: Q \
                 is P where no Q is given); G64 P<tol> Q0 follows every move as programmed",
                t.moves,
                crate::process::shown(t.envelope)
            ),
        ))
    }

    /// The stretch held back, if any.
    pub fn finish(&mut self) -> Vec<Move> {
        let mut out = Vec::new();
        self.flush(&mut out);
        out
    }

    fn push(&mut self, m: Move, out: &mut Vec<Move>) {
        if let (
            Some(q),
            Move::Line {
                line,
                from,
                to,
                rapid: false,
                feed,
            },
        ) = (self.q(), &m)
        {
            self.see(*line, *from, *to, *feed, q, out);
            return;
        }
        self.flush(out);
        if let Move::PathMode { control, .. } = &m {
            self.mode = Some(*control);
        }
        out.push(m);
    }

    /// A feed move from `from` to `to`: joins the run, or ends it and starts the next.
    fn see(
        &mut self,
        line: u32,
        from: [f64; 3],
        to: [f64; 3],
        feed: f64,
        q: f64,
        out: &mut Vec<Move>,
    ) {
        if let Some(run) = &mut self.run {
            let joins = run.feed == feed
                && run.end() == from
                && run.points.len() < MAX_POINTS
                && to != run.start
                && run
                    .points
                    .iter()
                    .all(|(p, _)| off_segment(*p, run.start, to) <= q);
            if joins {
                run.points.push((to, line));
                return;
            }
            self.end_run(out);
        }
        self.run = Some(Run {
            start: from,
            feed,
            points: vec![(to, line)],
        });
    }

    /// The run ended: into the stretch gathered, which is complete once it is long
    /// enough.
    fn end_run(&mut self, out: &mut Vec<Move>) {
        let Some(run) = self.run.take() else { return };
        if self.stretch.last().is_some_and(|r| r.end() != run.start) {
            self.complete(out);
            self.drain(out);
        }
        self.stretch_mm += norm(sub(run.end(), run.start));
        let v = run.feed / 60.0;
        self.stretch.push(run);
        let long = self.stretch_mm >= STOPS_PER_STRETCH * stop_distance(v, &self.machine)
            && self.stretch.len() >= MIN_RUNS;
        if long || self.stretch.len() >= MAX_RUNS {
            self.complete(out);
        }
    }

    fn flush(&mut self, out: &mut Vec<Move>) {
        self.end_run(out);
        self.complete(out);
        self.drain(out);
    }

    /// The stretch gathered is complete: the one waiting is weighed with it after it,
    /// and it waits for the next.
    fn complete(&mut self, out: &mut Vec<Move>) {
        let waiting = std::mem::take(&mut self.waiting);
        let stretch = std::mem::take(&mut self.stretch);
        self.weigh(&waiting, &stretch, out);
        self.waiting = stretch;
        self.stretch_mm = 0.0;
    }

    /// The stretch waiting, weighed with nothing after it.
    fn drain(&mut self, out: &mut Vec<Move>) {
        let waiting = std::mem::take(&mut self.waiting);
        self.weigh(&waiting, &[], out);
        self.lead.clear();
    }

    /// `stretch` out, merged if that is not slower (see the module page), timed between
    /// the lead and the start of `next`, as programmed.
    fn weigh(&mut self, stretch: &[Run], next: &[Run], out: &mut Vec<Move>) {
        let (Some(first), Some(last)) = (stretch.first(), stretch.last()) else {
            return;
        };
        let reach = 2.0 * stop_distance(first.feed / 60.0, &self.machine);
        if self.lead.last().and_then(end_of) != Some(first.start) {
            self.lead.clear();
        }
        let mut tail = Vec::new();
        if next.first().is_some_and(|n| n.start == last.end()) {
            let mut along = 0.0;
            for r in next {
                if along >= reach {
                    break;
                }
                along += norm(sub(r.end(), r.start));
                r.programmed(&mut tail);
            }
        }
        let mut programmed = Vec::new();
        stretch.iter().for_each(|r| r.programmed(&mut programmed));
        let single = stretch.iter().all(|r| r.points.len() == 1);
        let mut merged = Vec::new();
        if !single {
            stretch.iter().for_each(|r| r.merged(&mut merged));
        }
        // Merged, every kink passed at the feed: no slower, and fewer blocks. As
        // programmed, every kink passed at the feed: nothing to gain.
        let chosen = if !single && passed_at_feed(&merged, &self.machine) {
            merged
        } else if passed_at_feed(&programmed, &self.machine) {
            programmed
        } else {
            // Each way timed between the lead and the next stretch's start; the first of
            // the quickest kept (a tie to the merge, then to the program).
            let mut ways = Vec::with_capacity(3);
            if !single {
                ways.push(merged);
            }
            ways.push(programmed);
            let ends = self.tangents(stretch, next);
            if let Some(smooth) = self.budget().and_then(|b| smoothed(stretch, b, ends)) {
                ways.push(smooth);
            }
            if ways.len() == 1 {
                ways.swap_remove(0)
            } else {
                let cycles: Vec<Option<u64>> = ways
                    .iter()
                    .map(|w| self.time(&[&self.lead[..], w, &tail].concat()))
                    .collect();
                let best = (0..ways.len())
                    .filter(|&k| cycles[k].is_some())
                    .min_by_key(|&k| (cycles[k], k))
                    .unwrap_or(0);
                ways.swap_remove(best)
            }
        };
        // What the machinist is told ([`NaiveCam::note`]).
        let moves: usize = stretch.iter().map(|r| r.points.len()).sum();
        let pieces = chosen
            .iter()
            .filter(|m| matches!(m, Move::Nurbs { .. }))
            .count();
        if pieces > 0 || chosen.len() < moves {
            let envelope = match self.mode {
                Some(PathControl::Blend {
                    naive_cam_mm: Some(q),
                    ..
                }) => self.budget().unwrap_or(q),
                _ => 0.0,
            };
            let told = &mut self.told;
            told.first.get_or_insert(first.points[0].1);
            told.envelope = told.envelope.max(envelope);
            told.moves += moves;
            if pieces > 0 {
                told.pieces += pieces;
            } else {
                told.lines += chosen.len();
            }
        }
        // The lead for the next: the last moves, as long as the machine needs to stop.
        let mut along = 0.0;
        let keep = chosen
            .iter()
            .rev()
            .take_while(|m| {
                let more = along < reach;
                if let (Some(a), Some(b)) = (start_of(m), end_of(m)) {
                    along += norm(sub(b, a));
                }
                more
            })
            .count();
        self.lead = chosen[chosen.len() - keep..].to_vec();
        out.extend(chosen);
    }

    /// The directions a smoothed `stretch` leaves and arrives in, where the moves around
    /// it give them: leaving as the curve handed out before it arrives (one tangent), or
    /// along Bessel's tangent with the line before it; arriving along Bessel's tangent
    /// with the first point of `next`, when it follows. (Otherwise along the first and
    /// last programmed moves, [`smoothed`].)
    fn tangents(&self, stretch: &[Run], next: &[Run]) -> [Option<[f64; 3]>; 2] {
        let (Some(first), Some(last)) = (stretch.first(), stretch.last()) else {
            return [None, None];
        };
        let leave = match self.lead.last() {
            Some(Move::Nurbs { ctrl, .. }) if ctrl.len() >= 2 => {
                let (a, z) = (ctrl[ctrl.len() - 2], ctrl[ctrl.len() - 1]);
                unit_of(sub([z[0], z[1], z[2]], [a[0], a[1], a[2]]))
            }
            Some(Move::Line { from, .. }) => bessel(*from, first.start, first.end()),
            _ => None,
        };
        let before = stretch
            .len()
            .checked_sub(2)
            .map_or(first.start, |k| stretch[k].end());
        let arrive = next
            .first()
            .filter(|n| n.start == last.end())
            .and_then(|n| bessel(before, last.end(), n.end()));
        [leave, arrive]
    }

    /// The merge tolerance in force, where there is one.
    fn q(&self) -> Option<f64> {
        self.mode.as_ref().and_then(tolerance)
    }

    /// How far a smoothed stretch may stray from the programmed moves: `P + Q`, the
    /// envelope LinuxCNC's merge and blends keep.
    fn budget(&self) -> Option<f64> {
        match self.mode? {
            PathControl::Blend {
                tolerance_mm: Some(p),
                naive_cam_mm: Some(q),
            } if p > 0.0 && q > 0.0 => Some(p + q),
            _ => None,
        }
    }

    /// The cycles `moves` take from rest to rest under the path mode in force, moved to
    /// the origin, where the engine starts.
    fn time(&self, moves: &[Move]) -> Option<u64> {
        let o = moves.first().and_then(start_of)?;
        let mut w = Vec::with_capacity(moves.len() + 2);
        w.extend(self.mode.map(|control| Move::PathMode { line: 0, control }));
        w.extend(moves.iter().map(|m| moved(m, o)));
        w.push(Move::End { line: 0 });
        cycles_of_quick(&w, &self.machine, decision_period(&self.machine))
    }
}

/// Where a line or a curve starts.
fn start_of(m: &Move) -> Option<[f64; 3]> {
    match m {
        Move::Line { from, .. } => Some(*from),
        Move::Nurbs { ctrl, .. } => ctrl.first().map(|c| [c[0], c[1], c[2]]),
        _ => None,
    }
}

/// Where a line or a (polynomial) curve ends.
fn end_of(m: &Move) -> Option<[f64; 3]> {
    match m {
        Move::Line { to, .. } => Some(*to),
        Move::Nurbs { ctrl, .. } => ctrl.last().map(|c| [c[0], c[1], c[2]]),
        _ => None,
    }
}

/// A line or a polynomial curve moved by `-o`.
fn moved(m: &Move, o: [f64; 3]) -> Move {
    match m {
        Move::Line {
            line,
            from,
            to,
            feed,
            ..
        } => line_move(*line, sub(*from, o), sub(*to, o), *feed),
        Move::Nurbs {
            line,
            degree,
            knots,
            ctrl,
            feed,
        } => Move::Nurbs {
            line: *line,
            degree: *degree,
            knots: knots.clone(),
            ctrl: ctrl
                .iter()
                .map(|c| [c[0] - o[0], c[1] - o[1], c[2] - o[2], c[3]])
                .collect(),
            feed: *feed,
        },
        m => m.clone(),
    }
}

/// Whether the planner passes every kink of `lines` at its feed: every run of kinks
/// within two steps of each other at the feed turns, in all, less than the acceleration
/// it may take over two steps allows (as the corner screen of [`super::blend`] bounds
/// it, `run_at_feed`). Such a way gains nothing on the others but the few µm of path
/// they cut, and the stretch is not stepped every way: dense output of tiny turns (a
/// million lines of a spiral of 0.08 mm chords, `cnc check` 4.95 s without the merge)
/// took 23.5 s with every stretch stepped.
fn passed_at_feed(lines: &[Move], machine: &Machine) -> bool {
    let period_s = decision_period(machine) as f64 * 1e-9;
    let weakest = weakest(machine).acc;
    // Each line's unit direction, length and feed (mm/s).
    let mut dirs = Vec::with_capacity(lines.len());
    for m in lines {
        let Move::Line { from, to, feed, .. } = m else {
            return false;
        };
        let d = sub(*to, *from);
        let l = norm(d);
        if l.is_nan() || l <= 0.0 {
            return false;
        }
        dirs.push((
            d.map(|x| x / l),
            l,
            feed.min(machine.max_feed_mm_per_min) / 60.0,
        ));
    }
    let turn = |k: usize| turn_between(dirs[k - 1].0, dirs[k].0);
    // The kink between line k − 1 and line k, for k in 1..n.
    (1..dirs.len()).all(|k| {
        let v = dirs[k - 1].2.max(dirs[k].2);
        let reach = 2.0 * period_s * v;
        let mut sum = turn(k);
        let mut along = dirs[k - 1].1;
        let mut j = k - 1;
        while along < reach && j > 0 {
            sum += turn(j);
            j -= 1;
            along += dirs[j].1;
        }
        let mut along = dirs[k].1;
        let mut j = k;
        while along < reach && j + 1 < dirs.len() {
            sum += turn(j + 1);
            j += 1;
            along += dirs[j].1;
        }
        super::KINK_SHARE * weakest * period_s
            >= v * 2.0 * (0.5 * sum.min(std::f64::consts::PI)).sin()
    })
}

/// Most samples a smoothed piece is certified with: a piece that needs more is not
/// smoothed.
const MAX_SAMPLES: usize = 1 << 14;

/// The stretch smoothed: the C2 cubic spline through the ends of its runs (the merged
/// lines' vertices, each a programmed point), by chord length, leaving the first
/// programmed move's direction and arriving along the last's, one cubic Bézier curve per
/// run carrying the run's last source line. `None` unless every piece is within `tol` of
/// its run's programmed moves both ways, certified by samples: each piece's distance to
/// the moves, and each move's to the piece, at samples close enough that the distance
/// between them cannot grow by more than a tenth of `tol` (distances are 1-Lipschitz,
/// and the piece's speed is bounded by its control polygon's).
fn smoothed(stretch: &[Run], tol: f64, ends: [Option<[f64; 3]>; 2]) -> Option<Vec<Move>> {
    let feed = stretch.first()?.feed;
    if stretch.iter().any(|r| r.feed != feed) {
        return None;
    }
    let mut p = vec![stretch[0].start];
    p.extend(stretch.iter().map(Run::end));
    let m = p.len() - 1;
    let h: Vec<f64> = p.windows(2).map(|w| norm(sub(w[1], w[0]))).collect();
    if h.iter().any(|&x| x.is_nan() || x <= 0.0) {
        return None;
    }
    let first = &stretch[0];
    let last = &stretch[m - 1];
    let before_end = last
        .points
        .len()
        .checked_sub(2)
        .map_or(last.start, |k| last.points[k].0);
    let mut d = vec![[0.0; 3]; m + 1];
    d[0] = match ends[0] {
        Some(u) => u,
        None => unit_of(sub(first.points[0].0, first.start))?,
    };
    d[m] = match ends[1] {
        Some(u) => u,
        None => unit_of(sub(last.end(), before_end))?,
    };
    // C2 at each inner vertex i: h_i·D_{i-1} + 2(h_{i-1} + h_i)·D_i + h_{i-1}·D_{i+1} =
    // 3·(h_i/h_{i-1}·(P_i − P_{i-1}) + h_{i-1}/h_i·(P_{i+1} − P_i)); the ends given.
    // Tridiagonal and diagonally dominant: solved forward then back (Thomas).
    if m > 1 {
        let n = m - 1;
        let mut c = vec![0.0; n];
        let mut r = vec![[0.0; 3]; n];
        for k in 0..n {
            let i = k + 1;
            let (a, bb, cc) = (h[i], 2.0 * (h[i - 1] + h[i]), h[i - 1]);
            let mut rhs = [0.0; 3];
            for x in 0..3 {
                rhs[x] = 3.0
                    * (h[i] / h[i - 1] * (p[i][x] - p[i - 1][x])
                        + h[i - 1] / h[i] * (p[i + 1][x] - p[i][x]));
            }
            if k == 0 {
                for x in 0..3 {
                    rhs[x] -= a * d[0][x];
                }
            }
            if k == n - 1 {
                for x in 0..3 {
                    rhs[x] -= cc * d[m][x];
                }
            }
            let (lower, prev_c, prev_r) = if k == 0 {
                (0.0, 0.0, [0.0; 3])
            } else {
                (a, c[k - 1], r[k - 1])
            };
            let den = bb - lower * prev_c;
            c[k] = if k + 1 < n { cc / den } else { 0.0 };
            for x in 0..3 {
                r[k][x] = (rhs[x] - lower * prev_r[x]) / den;
            }
        }
        for k in (0..n).rev() {
            let next = if k + 1 < n { d[k + 2] } else { [0.0; 3] };
            for x in 0..3 {
                d[k + 1][x] = r[k][x] - c[k] * next[x];
            }
        }
    }
    let mut out = Vec::with_capacity(m);
    for (i, run) in stretch.iter().enumerate() {
        let b = [
            p[i],
            std::array::from_fn(|x| p[i][x] + h[i] * d[i][x] / 3.0),
            std::array::from_fn(|x| p[i + 1][x] - h[i] * d[i + 1][x] / 3.0),
            p[i + 1],
        ];
        if !within(&b, run, tol) {
            return None;
        }
        let line = run.points.last()?.1;
        out.push(Move::Nurbs {
            line,
            degree: 3,
            knots: vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
            ctrl: b.iter().map(|q| [q[0], q[1], q[2], 1.0]).collect(),
            feed,
        });
    }
    Some(out)
}

/// Bessel's tangent at `b` between `a` and `c`: the direction of the parabola through the
/// three, by chord length, at `b` (the slopes of the two chords, each weighted by the
/// other's length).
fn bessel(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> Option<[f64; 3]> {
    let (h0, h1) = (norm(sub(b, a)), norm(sub(c, b)));
    if h0.is_nan() || h1.is_nan() || h0 <= 0.0 || h1 <= 0.0 {
        return None;
    }
    let (w0, w1) = (h1 / (h0 + h1) / h0, h0 / (h0 + h1) / h1);
    unit_of(std::array::from_fn(|x| {
        w0 * (b[x] - a[x]) + w1 * (c[x] - b[x])
    }))
}

/// Whether the cubic `b` and the run's programmed moves are within `tol` of each other
/// both ways (see [`smoothed`]).
fn within(b: &[[f64; 3]; 4], run: &Run, tol: f64) -> bool {
    let slack = 0.1 * tol;
    let speed = 3.0
        * (0..3)
            .map(|k| norm(sub(b[k + 1], b[k])))
            .fold(0.0, f64::max);
    let n = (speed / (2.0 * slack)).ceil() as usize + 1;
    if !(speed.is_finite() && n <= MAX_SAMPLES) {
        return false;
    }
    let curve: Vec<[f64; 3]> = (0..=n)
        .map(|k| de_casteljau(*b, k as f64 / n as f64))
        .collect();
    let mut moves = Vec::with_capacity(run.points.len());
    let mut from = run.start;
    for &(to, _) in &run.points {
        moves.push((from, to));
        from = to;
    }
    // The curve to the moves: between samples at most `speed/(2n)` <= `slack` farther.
    let near = curve.iter().all(|c| {
        moves
            .iter()
            .any(|&(a, z)| off_segment(*c, a, z) <= tol - slack)
    });
    if !near {
        return false;
    }
    // The moves to the curve: each move at steps of `slack` (a point between two is at
    // most `slack` farther), each step's distance bounded by that to the samples near
    // the last one found nearest (any sample gives a bound).
    let mut at = 0;
    for &(a, z) in &moves {
        let len = norm(sub(z, a));
        let steps = (len / slack).ceil().max(1.0) as usize;
        if steps > MAX_SAMPLES {
            return false;
        }
        for j in 0..=steps {
            let t = j as f64 / steps as f64;
            let x: [f64; 3] = std::array::from_fn(|k| a[k] + t * (z[k] - a[k]));
            let dist = |k: usize| norm(sub(curve[k], x));
            while at + 1 < curve.len() && dist(at + 1) <= dist(at) {
                at += 1;
            }
            if dist(at) > tol - slack {
                return false;
            }
        }
    }
    true
}

/// The whole of `moves`, merged for `machine`.
pub fn merge(moves: Vec<Move>, machine: &Machine) -> Vec<Move> {
    let mut cam = NaiveCam::new(machine);
    let mut out = cam.take(moves);
    out.extend(cam.finish());
    out
}

fn is_mode(m: &Move) -> bool {
    matches!(m, Move::PathMode { .. })
}

/// The merge tolerance a path mode sets.
fn tolerance(control: &PathControl) -> Option<f64> {
    match control {
        PathControl::Blend {
            naive_cam_mm: Some(q),
            ..
        } if *q > 0.0 => Some(*q),
        _ => None,
    }
}

/// How far `p` lies from the segment `a`–`b`.
fn off_segment(p: [f64; 3], a: [f64; 3], b: [f64; 3]) -> f64 {
    let m = sub(b, a);
    let d = sub(p, a);
    let mm = dot(m, m);
    let t = if mm > 0.0 {
        (dot(d, m) / mm).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm([d[0] - t * m[0], d[1] - t * m[1], d[2] - t * m[2]])
}

#[cfg(test)]
mod tests;
