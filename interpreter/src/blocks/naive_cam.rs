//! LinuxCNC's "naive CAM detector", `G64 P<p> Q<q>`: a run of straight feed moves at
//! one feed whose points lie within `q` of one straight line is made that one line,
//! before the corners are blended ([`super::blend`]), where that is not slower.
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
//!   arc that is not merged, a curve, a dwell, a stop, a spindle or path-mode change, a
//!   new feed, a move back to `B`) ends the run.
//! * The run becomes one line from `B` to its last point, carrying the last move's
//!   source line: the lines it swallowed make no block of their own.
//!
//! # The path it leaves
//!
//! The merged line and the programmed moves are within `q` of each other, both ways.
//! Every joined point lies within `q` of the segment, and so does every point of the
//! moves between them (the distance to a segment is convex). And the moves run from one
//! end of the segment to the other, so each point of the segment is the foot of some
//! point of the moves on it, within `q`. The `P` blend then keeps within `p` of the
//! merged path's corners: the tool is within `p + q` of the program, as on LinuxCNC.
//!
//! # Merged where it pays
//!
//! LinuxCNC merges every run it can. Its machine has no jerk limit, and there the
//! merged lines always win: the kinks that rounded vertices put every few µm cost more
//! than the merged corners, blended. A machine with a jerk limit may pass the blends
//! of the unmerged chords quicker than those of the merged lines, whose curvature comes
//! in bursts at each corner: R5 in 0.2 mm chords at F6000, `P0.01`, takes 1.731 s
//! merged on the built-in machine and 1.419 s not. `Q` is a bound, not an order, so the
//! runs are weighed: adjacent runs are gathered into a stretch about four times as long
//! as the machine needs to stop from their feed ([`super::blend::stop_distance`]), and
//! the stretch is stepped through the interpreter's engine both ways, from rest to rest
//! under the path mode in force, blends decided as the planner decides them
//! ([`super::blend::cycles_of`]); it is merged only if that is not slower.
//!
//! The merge is streamed ([`NaiveCam::take`]): a stretch is held back only while it may
//! still grow, so how a program is handed over in batches does not change the merge.

use super::blend::{cycles_of, decision_period, stop_distance};
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

/// The merge as moves stream through it (see the module page).
#[derive(Debug)]
pub struct NaiveCam {
    machine: Machine,
    /// The path mode in force, and the merge tolerance it sets, where it sets one.
    mode: Option<PathControl>,
    q: Option<f64>,
    /// The run growing.
    run: Option<Run>,
    /// The runs before it, each starting where the one before ended: the stretch that
    /// is weighed whole.
    stretch: Vec<Run>,
    stretch_mm: f64,
    /// The stretch before, complete, waiting for the start of the next to be weighed
    /// with: what a merge costs the lines after it counts too.
    waiting: Vec<Run>,
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
            q: None,
            run: None,
            stretch: Vec::new(),
            stretch_mm: 0.0,
            waiting: Vec::new(),
            lead: Vec::new(),
        }
    }

    /// The moves that follow those taken before, merged; a stretch that may still grow
    /// is held back for the next call (or [`NaiveCam::finish`]).
    pub fn take(&mut self, moves: Vec<Move>) -> Vec<Move> {
        if self.q.is_none()
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
        ) = (self.q, &m)
        {
            self.see(*line, *from, *to, *feed, q, out);
            return;
        }
        self.flush(out);
        if let Move::PathMode { control, .. } = &m {
            self.mode = Some(*control);
            self.q = tolerance(control);
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
        self.weigh(&waiting, &self.stretch.clone(), out);
        self.waiting = std::mem::take(&mut self.stretch);
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
        if self
            .lead
            .last()
            .is_some_and(|m| !matches!(m, Move::Line { to, .. } if *to == first.start))
        {
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
        let lead = self.lead.len();
        let mut programmed = self.lead.clone();
        stretch.iter().for_each(|r| r.programmed(&mut programmed));
        let ends = programmed.len();
        let chosen = if stretch.iter().all(|r| r.points.len() == 1) {
            programmed
        } else {
            let mut merged = self.lead.clone();
            stretch.iter().for_each(|r| r.merged(&mut merged));
            let ends_merged = merged.len();
            // Merged, every kink passed at the feed: no slower, and fewer blocks.
            if passed_at_feed(&merged[lead..], &self.machine) {
                merged
            } else if passed_at_feed(&programmed[lead..], &self.machine) {
                programmed
            } else {
                merged.extend_from_slice(&tail);
                programmed.extend_from_slice(&tail);
                if self.quicker(&merged, &programmed) {
                    merged.truncate(ends_merged);
                    merged
                } else {
                    programmed.truncate(ends);
                    programmed
                }
            }
        };
        // The lead for the next: the last lines, as long as the machine needs to stop.
        let mut along = 0.0;
        let keep = chosen[lead..]
            .iter()
            .rev()
            .take_while(|m| {
                let more = along < reach;
                if let Move::Line { from, to, .. } = m {
                    along += norm(sub(*to, *from));
                }
                more
            })
            .count();
        self.lead = chosen[chosen.len() - keep..].to_vec();
        out.extend_from_slice(&chosen[lead..]);
    }

    /// Whether the lines `a` take no more cycles than `b`, from rest to rest under the
    /// path mode in force (`a` where either cannot be timed: it is what LinuxCNC runs).
    fn quicker(&self, a: &[Move], b: &[Move]) -> bool {
        let period_ns = decision_period(&self.machine);
        let time = |lines: &[Move]| {
            let Some(Move::Line { from: o, .. }) = lines.first() else {
                return None;
            };
            let o = *o;
            let mut w = Vec::with_capacity(lines.len() + 2);
            w.extend(self.mode.map(|control| Move::PathMode { line: 0, control }));
            w.extend(lines.iter().map(|m| match m {
                Move::Line {
                    line,
                    from,
                    to,
                    feed,
                    ..
                } => line_move(*line, sub(*from, o), sub(*to, o), *feed),
                m => m.clone(),
            }));
            w.push(Move::End { line: 0 });
            cycles_of(&w, &self.machine, period_ns)
        };
        match (time(a), time(b)) {
            (Some(ta), Some(tb)) => ta <= tb,
            _ => true,
        }
    }
}

/// Whether the planner passes every kink of `lines` at its feed: every run of kinks
/// within two steps of each other at the feed turns, in all, less than the acceleration
/// it may take over two steps allows (as the corner screen of [`super::blend`] bounds
/// it, `run_at_feed`). Then merging cannot be quicker but for the few µm of path it cuts,
/// and the stretch is not stepped both ways: dense output of tiny turns (a million
/// lines of a spiral of 0.08 mm chords, `cnc check` 4.95 s without the merge) took
/// 23.5 s with every stretch stepped.
fn passed_at_feed(lines: &[Move], machine: &Machine) -> bool {
    let period_s = decision_period(machine) as f64 * 1e-9;
    let weakest = machine
        .axes
        .as_array()
        .iter()
        .map(|x| x.max_acc_mm_per_s2)
        .fold(machine.path_acc_mm_per_s2, f64::min);
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
    let turn = |k: usize| {
        let (a, b) = (dirs[k - 1].0, dirs[k].0);
        let cos = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        2.0 * super::half_turn_sin(cos).min(1.0).asin()
    };
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
    let mm = m[0] * m[0] + m[1] * m[1] + m[2] * m[2];
    let t = if mm > 0.0 {
        ((d[0] * m[0] + d[1] * m[1] + d[2] * m[2]) / mm).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm([d[0] - t * m[0], d[1] - t * m[1], d[2] - t * m[2]])
}

#[cfg(test)]
mod tests;
