//! The servo-sim process loop. In lock-step (the default) it sleeps on the set-point
//! wake-up event, steps the three axes once per set-point in cycle order, and answers
//! each with feedback: the output depends only on the set-points, never on when they
//! arrive. On its own clock ([`ServoClock::Own`]) it keeps its own period, as real drives
//! do: each tick it takes the newest set-point that has arrived; when none has, it holds
//! the last position command (with no feed-forward: the command did not move), and the
//! effect shows in the following and contour errors.

use crate::axis::Axis;
use iceoryx2::prelude::*;
use serde::{Deserialize, Serialize};
use shared::clock::{spin_then_block, ClockMode};
use shared::ipc::{self, err, IpcError};
use shared::machine::Servo;
use shared::protocol::{
    Feedback, Services, Setpoint, DRIVE_OK, DRIVE_SATURATED, PROTOCOL_VERSION, SETPOINT_LAST,
};
use shared::trace::TraceWriter;
use shared::Machine;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Who paces the drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ServoClock {
    /// One drive step per set-point, in cycle order: deterministic.
    #[default]
    Lockstep,
    /// The drives' own period (real clock only): late set-points are held.
    Own,
}

impl std::fmt::Display for ServoClock {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            ServoClock::Lockstep => "lockstep",
            ServoClock::Own => "own",
        })
    }
}

#[derive(Debug, Clone)]
pub struct Config {
    pub prefix: String,
    pub out_dir: PathBuf,
    pub period_ns: u64,
    pub machine: Machine,
    pub clock: ClockMode,
    pub servo_clock: ServoClock,
    /// Scheduling of the drive loop under the real clock (the simulated clock runs plain,
    /// as the interpolator does: it spins, and spinning at SCHED_FIFO invites throttling).
    pub sched: interpolator::rt::sched::SchedMode,
    /// SCHED_FIFO priority when real-time scheduling is granted.
    pub rt_priority: i32,
    /// How long to wait for the first set-point while no interpolator is there (one that
    /// is there is waited for as long as it stays: it waits for its first block).
    pub start_timeout: Duration,
    /// Silence after which the interpolator is taken for dead (drives hold position).
    pub idle_timeout: Duration,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    pub outcome: String,
    pub fault: Option<String>,
    pub pid: u32,
    /// Drive steps taken: one per set-point in lock-step, one per tick on the own clock.
    pub setpoints: u64,
    /// Set-points that never arrived (gaps in the cycle numbers).
    pub lost_setpoints: u64,
    pub max_following_error_um: f64,
    pub max_following_error_axis_um: [f64; 3],
    /// Root mean square of the following error over every set-point, per axis.
    #[serde(default)]
    pub rms_following_error_axis_um: [f64; 3],
    pub saturated_cycles: u64,
    pub trace_dropped: u64,
    /// `lockstep` or `own`.
    #[serde(default)]
    pub servo_clock: String,
    /// Own clock only: drive ticks with no new set-point, which held the last command.
    #[serde(default)]
    pub held_ticks: u64,
    /// Own clock only: set-points overtaken by a newer one before a tick used them.
    #[serde(default)]
    pub skipped_setpoints: u64,
    /// The drive loop's scheduling as granted (policy, priority, locked memory, warnings);
    /// null in files older than it.
    #[serde(default)]
    pub sched: Option<interpolator::rt::sched::SchedReport>,
}

#[derive(Debug, Clone, Copy)]
struct FeedbackRec {
    cycle: u64,
    t_ns: u64,
    pos: [f64; 3],
    ferr_um: [f64; 3],
}

/// `{},{},{},{},{},{},{},{}` of the fields, written by [`shared::decimal`] (the same
/// text, a fraction of the CPU: the writer thread shares the cores with the drive loop).
fn format_feedback(r: &FeedbackRec, out: &mut String) {
    use shared::decimal::{push_f64, push_u64};
    push_u64(out, r.cycle);
    out.push(',');
    push_u64(out, r.t_ns);
    for v in r.pos.iter().chain(&r.ferr_um) {
        out.push(',');
        push_f64(out, *v);
    }
}

/// The three axes and their bookkeeping; no I/O.
pub struct Drives {
    axes: [Axis; 3],
    /// Each axis's servo model: the shared one with its own `[axes.*.servo]` keys.
    servos: [Servo; 3],
    dt_s: f64,
    expected_cycle: u64,
    pub lost: u64,
    pub saturated_cycles: u64,
    pub max_ferr_mm: [f64; 3],
    /// Sum of the squared following errors and the number of set-points summed, for the
    /// RMS.
    sum_sq_ferr_mm2: [f64; 3],
    ferr_samples: u64,
}

impl Drives {
    pub fn new(machine: Machine, period_ns: u64) -> Self {
        Drives {
            axes: [Axis::at(0.0); 3],
            servos: [0, 1, 2].map(|i| machine.axis_servo(i)),
            dt_s: period_ns as f64 * 1e-9,
            expected_cycle: 0,
            lost: 0,
            saturated_cycles: 0,
            max_ferr_mm: [0.0; 3],
            sum_sq_ferr_mm2: [0.0; 3],
            ferr_samples: 0,
        }
    }

    /// RMS following error per axis so far, mm.
    pub fn rms_ferr_mm(&self) -> [f64; 3] {
        let n = self.ferr_samples.max(1) as f64;
        self.sum_sq_ferr_mm2.map(|s| (s / n).sqrt())
    }

    /// Steps every axis through one set-point and returns the feedback for it.
    pub fn step(&mut self, sp: &Setpoint) -> Feedback {
        if sp.cycle > self.expected_cycle {
            self.lost += sp.cycle - self.expected_cycle;
        }
        self.expected_cycle = sp.cycle + 1;
        self.drive(sp)
    }

    /// One drive period with `sp` as the command, whatever its cycle (the own clock:
    /// it may be a held or a newer set-point).
    pub fn drive(&mut self, sp: &Setpoint) -> Feedback {
        let mut fb = Feedback {
            protocol: PROTOCOL_VERSION,
            drive_state: DRIVE_OK,
            cycle: sp.cycle,
            ..Feedback::default()
        };
        for (i, ax) in self.axes.iter_mut().enumerate() {
            let p = &self.servos[i];
            ax.step(
                p,
                self.dt_s,
                sp.pos_mm[i],
                sp.vel_mm_per_s[i],
                sp.acc_mm_per_s2[i],
            );
            let x = ax.measured_mm(p);
            fb.pos_mm[i] = x;
            fb.ferr_mm[i] = sp.pos_mm[i] - x;
            self.max_ferr_mm[i] = self.max_ferr_mm[i].max(fb.ferr_mm[i].abs());
            self.sum_sq_ferr_mm2[i] += fb.ferr_mm[i] * fb.ferr_mm[i];
            if ax.saturated {
                fb.drive_state = DRIVE_SATURATED;
            }
        }
        self.ferr_samples += 1;
        if fb.drive_state == DRIVE_SATURATED {
            self.saturated_cycles += 1;
        }
        fb
    }
}

/// Before the first set-point: how often to look whether the interpolator is there
/// (about 55 µs of CPU a look).
const START_LIVENESS_EVERY: Duration = Duration::from_millis(20);

/// Runs the servo-sim until the last set-point, and writes `feedback.csv` and
/// `servo.json` into the run directory.
pub fn run<S: Service>(cfg: &Config) -> Result<Summary, IpcError> {
    if cfg.servo_clock == ServoClock::Own && cfg.clock == ClockMode::Sim {
        return Err(IpcError(
            "--servo-clock own needs the real clock: under the simulated clock nothing is late"
                .into(),
        ));
    }
    let io = |e: std::io::Error| IpcError(format!("writing the run directory: {e}"));
    let svc = Services::new(&cfg.prefix);
    // The interpolator creates the services these open: opening them at the same moment
    // would cost iceoryx2's 25 ms tick (`ipc::await_created`).
    ipc::await_created::<S>(
        &[
            (&svc.feedback(), MessagingPattern::PublishSubscribe),
            (&svc.feedback(), MessagingPattern::Event),
            (&svc.setpoints(), MessagingPattern::PublishSubscribe),
            (&svc.setpoints(), MessagingPattern::Event),
        ],
        ipc::CREATOR_WAIT,
    );
    let node = ipc::node::<S>("servo-sim")?;
    let feedback = ipc::feedback(&node, &svc)?;
    let fb_pub = feedback
        .publisher_builder()
        .create()
        .map_err(|e| err("feedback publisher", e))?;
    let sp_event = ipc::wakeup(&node, &svc.setpoints())?;
    let listener = sp_event
        .listener_builder()
        .create()
        .map_err(|e| err("set-point listener", e))?;
    let setpoints = ipc::setpoints(&node, &svc)?;
    let fb_event = ipc::wakeup(&node, &svc.feedback())?;
    let fb_notify = fb_event
        .notifier_builder()
        .create()
        .map_err(|e| err("feedback notifier", e))?;
    let sim = cfg.clock == ClockMode::Sim;
    let sp_sub = setpoints
        .subscriber_builder()
        .create()
        .map_err(|e| err("set-point subscriber", e))?;
    tracing::debug!(
        setpoints = %svc.setpoints(),
        feedback = %svc.feedback(),
        "servo-sim: shared-memory services open (set-points and their wake-up in, feedback and its wake-up out)"
    );

    let mut trace = TraceWriter::create(
        &cfg.out_dir.join("feedback.csv"),
        "cycle,t_ns,x_mm,y_mm,z_mm,ferr_x_um,ferr_y_um,ferr_z_um",
        1 << 16,
        format_feedback,
        cfg.clock == ClockMode::Real,
    )
    .map_err(io)?;
    let mut drives = Drives::new(cfg.machine.clone(), cfg.period_ns);
    // The drive loop gets the interpolator's real-time set-up (unpinned, a priority
    // below its): starved of the CPU, the drives would go silent and fault a healthy run.
    // Its trace writer, started above, stays SCHED_OTHER.
    let sched_mode = if sim {
        interpolator::rt::sched::SchedMode::Other
    } else {
        cfg.sched
    };
    let sched = interpolator::rt::sched::setup_with(sched_mode, cfg.rt_priority, false);
    for w in &sched.warnings {
        tracing::warn!("servo-sim: {w}");
    }
    tracing::info!(
        period_us = cfg.period_ns / 1000,
        clock = %cfg.clock.name(),
        servo_clock = %cfg.servo_clock,
        "servo-sim started: drive loop {}",
        interpolator::rt::sched::words(&sched)
    );
    let mut fault: Option<String> = None;
    // The fault is a stop someone asked for (SIGTERM), not a failure.
    let mut asked_to_stop = false;
    let mut count = 0u64;
    let mut last_seen = Instant::now();
    let mut last_cycle: Option<u64> = None;
    // A silent interpolator may be dead, and iceoryx2 knows for sure (the kernel released
    // its liveness lock): asked after 5 periods of silence, at most once a period. Only a
    // dead one is acted on this early; a live but stalled one gets `idle_timeout`, since
    // this VM's scheduling stalls alone can reach several periods.
    let period = Duration::from_nanos(cfg.period_ns);
    let mut last_check = Instant::now();
    // Before the first set-point: whether the interpolator's port was there when last
    // looked at.
    let mut interpolator_there = false;
    let mut done = false;
    let own = cfg.servo_clock == ServoClock::Own;
    // Own clock: the tick schedule, the command in force and how it came to be.
    let t0 = shared::clock::now_ns();
    let mut tick = 0u64;
    let mut command: Option<Setpoint> = None;
    let (mut held_ticks, mut skipped) = (0u64, 0u64);
    while !done {
        if own {
            tick += 1;
            shared::clock::sleep_until_ns(t0 + tick * cfg.period_ns);
            let mut fresh: Option<Setpoint> = None;
            while let Ok(Some(sample)) = sp_sub.receive() {
                let sp = *sample.payload();
                if let Err(e) = sp.validate() {
                    fault = Some(format!("bad set-point: {e}"));
                    done = true;
                    break;
                }
                if fresh.is_some() {
                    skipped += 1;
                }
                fresh = Some(sp);
            }
            if done {
                break;
            }
            let sp = match (fresh, command) {
                (Some(sp), _) => {
                    last_seen = Instant::now();
                    last_cycle = Some(sp.cycle);
                    Some(sp)
                }
                (None, Some(mut held)) => {
                    held_ticks += 1;
                    held.vel_mm_per_s = [0.0; 3];
                    held.acc_mm_per_s2 = [0.0; 3];
                    Some(held)
                }
                // Nothing yet: the start wait below applies.
                (None, None) => None,
            };
            if let Some(sp) = sp {
                command = Some(sp);
                let fb = drives.drive(&sp);
                count += 1;
                let _ = fb_pub.send_copy(fb);
                trace.push(FeedbackRec {
                    cycle: fb.cycle,
                    t_ns: tick * cfg.period_ns,
                    pos: fb.pos_mm,
                    ferr_um: fb.ferr_mm.map(|e| e * 1e3),
                });
                if fresh.is_some_and(|f| f.flags & SETPOINT_LAST != 0) {
                    done = true;
                }
            }
        } else if sim {
            // The interpolator waits for this answer: spin briefly, then sleep on the event.
            spin_then_block(
                200_000,
                50_000_000,
                || sp_sub.has_samples().unwrap_or(false),
                |d| {
                    let _ = listener.timed_wait(|_| {}, d);
                },
            );
        } else {
            let _ = listener.timed_wait(|_| {}, period);
        }
        // Lock-step: every set-point that has arrived, in order (the own clock took its
        // set-points above).
        let mut answered = false;
        while let Some(sample) = if own {
            None
        } else {
            sp_sub.receive().ok().flatten()
        } {
            let sp = *sample.payload();
            last_seen = Instant::now();
            last_cycle = Some(sp.cycle);
            if let Err(e) = sp.validate() {
                // A set-point we cannot trust: hold position, report, stop.
                fault = Some(format!("bad set-point: {e}"));
                done = true;
                break;
            }
            let fb = drives.step(&sp);
            count += 1;
            let _ = fb_pub.send_copy(fb);
            answered = true;
            trace.push(FeedbackRec {
                cycle: fb.cycle,
                t_ns: sp.t_ns,
                pos: fb.pos_mm,
                ferr_um: fb.ferr_mm.map(|e| e * 1e3),
            });
            if sp.flags & SETPOINT_LAST != 0 {
                done = true;
                break;
            }
        }
        // Under the simulated clock the interpolator may be asleep on these answers: one
        // wake-up for all of them.
        if sim && answered {
            let _ = fb_notify.notify();
        }
        // Only SIGTERM stops the drives here: on a SIGINT (a terminal's Ctrl-C reaches
        // every process) or the launcher's death the interpolator brakes on the path, and
        // the drives follow it to its last set-point.
        if !done && shared::stop::terminate_requested() {
            asked_to_stop = true;
            fault = Some(format!(
                "stopped on request (SIGTERM) after {count} set-points; drives hold position"
            ));
            done = true;
        }
        if !done && count > 0 && last_seen.elapsed() >= 5 * period && last_check.elapsed() >= period
        {
            last_check = Instant::now();
            let _ = setpoints.try_cleanup_dead_nodes();
            if setpoints.dynamic_config().number_of_publishers() == 0 {
                fault = Some(format!(
                    "the interpolator is gone (its process ended or died) after set-point cycle {}; drives hold position",
                    last_cycle.unwrap_or(0)
                ));
                done = true;
            }
        }
        let limit = if count == 0 {
            cfg.start_timeout
        } else {
            cfg.idle_timeout
        };
        // Before the first set-point, an interpolator that is there is waiting for its
        // first block (the interpreter may read and plan for many seconds): waited for
        // as long as it stays, past the start timeout too. One that came and left before
        // it moved ends the wait at once.
        if !done && count == 0 && last_check.elapsed() >= START_LIVENESS_EVERY {
            last_check = Instant::now();
            let _ = setpoints.try_cleanup_dead_nodes();
            let there = setpoints.dynamic_config().number_of_publishers() > 0;
            if interpolator_there && !there && !sp_sub.has_samples().unwrap_or(false) {
                fault = Some(
                    "the interpolator is gone (its process ended or died) before its first set-point; drives hold position"
                        .into(),
                );
                done = true;
            }
            interpolator_there = there;
        }
        if !done && last_seen.elapsed() > limit && !(count == 0 && interpolator_there) {
            fault = Some(if count == 0 {
                format!(
                    "no set-point came in the {:.1} s since the start, and no interpolator is there (it never came, or ended before it moved); drives hold position",
                    last_seen.elapsed().as_secs_f64()
                )
            } else {
                format!(
                    "the interpolator sent no set-point for {:.1} s after set-point cycle {} although its process is alive: it was starved of CPU time (this machine is too loaded) or suspended; drives hold position. Check the machine with `cnc latency-test`, or run with `--clock sim`",
                    limit.as_secs_f64(),
                    last_cycle.unwrap_or(0)
                )
            });
            done = true;
        }
    }
    let trace_dropped = trace.dropped();
    trace.finish().map_err(io)?;
    let max_axis = drives.max_ferr_mm.map(|e| e * 1e3);
    let max_um = max_axis.iter().fold(0.0, |a: f64, b| a.max(*b));
    match &fault {
        None => tracing::info!(
            setpoints = count,
            lost_setpoints = drives.lost,
            max_following_error_um = %format_args!("{max_um:.1}"),
            "servo-sim stopped: the last set-point is answered"
        ),
        Some(f) if asked_to_stop => tracing::info!(setpoints = count, "servo-sim {f}"),
        Some(f) => tracing::error!(setpoints = count, "servo-sim fault: {f}"),
    }
    let summary = Summary {
        outcome: if fault.is_some() { "fault" } else { "done" }.into(),
        fault,
        pid: std::process::id(),
        setpoints: count,
        lost_setpoints: drives.lost,
        max_following_error_um: max_um,
        max_following_error_axis_um: max_axis,
        rms_following_error_axis_um: drives.rms_ferr_mm().map(|e| e * 1e3),
        saturated_cycles: drives.saturated_cycles,
        trace_dropped,
        servo_clock: cfg.servo_clock.to_string(),
        held_ticks,
        skipped_setpoints: skipped,
        sched: Some(sched),
    };
    let text = serde_json::to_string_pretty(&summary).map_err(|e| IpcError(e.to_string()))?;
    std::fs::write(cfg.out_dir.join("servo.json"), text).map_err(io)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use shared::protocol::Setpoint;

    /// `[axes.z.servo]` gives Z its own drive: with no feed-forward, X and Y (the shared
    /// `kv_per_s` 40) lag a 30 mm/s ramp by v/Kv = 0.75 mm, and Z (its own Kv 20) by
    /// 1.5 mm, at steady state (closed form of the P position loop).
    #[test]
    fn each_axis_runs_its_own_servo_model() {
        let machine = Machine::from_toml(
            "[servo]\nkv_per_s = 40\nvel_ff = 0\nacc_ff = 0\n\n[axes.z.servo]\nkv_per_s = 20\n",
        )
        .unwrap();
        let mut drives = Drives::new(machine, 1_000_000);
        let v = 30.0;
        let mut fb = None;
        for k in 0..3000u64 {
            let x = v * k as f64 * 1e-3;
            let sp = Setpoint {
                protocol: PROTOCOL_VERSION,
                cycle: k,
                t_ns: k * 1_000_000,
                pos_mm: [x; 3],
                vel_mm_per_s: [v; 3],
                ..Setpoint::default()
            };
            fb = Some(drives.step(&sp));
        }
        let e = fb.unwrap().ferr_mm;
        for (axis, lag) in [(0, 0.75), (1, 0.75), (2, 1.5)] {
            assert!(
                (e[axis] - lag).abs() < 0.01,
                "axis {axis}: {} mm, expected {lag}",
                e[axis]
            );
        }
    }

    /// A line of `feedback.csv` is the `{}` text of its fields, as it always was.
    #[test]
    fn a_feedback_line_is_the_display_text_of_its_fields() {
        let r = FeedbackRec {
            cycle: 72_277,
            t_ns: 72_277_000_000,
            pos: [0.1 + 0.2, -0.0, 1_658_206_780_088_562.0 + 0.25],
            ferr_um: [0.008333333333387927, 1e-7, -16.68],
        };
        let mut got = String::new();
        format_feedback(&r, &mut got);
        assert_eq!(
            got,
            format!(
                "{},{},{},{},{},{},{},{}",
                r.cycle,
                r.t_ns,
                r.pos[0],
                r.pos[1],
                r.pos[2],
                r.ferr_um[0],
                r.ferr_um[1],
                r.ferr_um[2]
            )
        );
    }
}
