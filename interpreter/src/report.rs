//! `report.json`: one file per run that other tools and tests read, folded together from
//! what each process wrote (`interpreter.json`, `interpolator.json`, `servo.json`).

use interpolator::summary::Summary as InterpSummary;
use interpolator::timing::Percentiles;
use serde::{Deserialize, Serialize};
use servo_sim::run::Summary as ServoSummary;
use shared::clock::ClockMode;
use std::path::Path;

/// What the interpreter process reports.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct InterpreterSummary {
    pub outcome: String,
    pub fault: Option<String>,
    pub pid: u32,
    pub program: String,
    pub blocks: usize,
    pub messages: Vec<(u32, String)>,
    /// What the machine changed of what the program asked, by source line
    /// ([`crate::process::notes`]).
    #[serde(default)]
    pub notes: Vec<(u32, String)>,
    /// Set when a damaged command log was salvaged: what was wrong, what ran.
    #[serde(default)]
    pub salvaged: Option<String>,
    /// The NC dialect the program was read in (`linuxcnc` or `fanuc`); none for replays.
    #[serde(default)]
    pub dialect: Option<String>,
    /// A STEP-NC part's largest scallop height between passes (mm), as planned.
    #[serde(default)]
    pub max_scallop_mm: Option<f64>,
    /// A program sent as it is planned: the windows it was planned in, and how many of
    /// them were cut at speed (a stretch with no rest longer than the machine's
    /// `plan_window_moves`); none when it was held whole.
    #[serde(default)]
    pub windows: Option<usize>,
    #[serde(default)]
    pub windows_at_speed: Option<usize>,
    /// Of the windows cut at speed, those planned otherwise than the whole program
    /// would be at the seam ([`crate::window::Planned::rough_seams`]), and those shorter
    /// than the braking from the feed ([`crate::window::Planned::short_windows`]).
    #[serde(default)]
    pub rough_seams: Option<usize>,
    #[serde(default)]
    pub short_windows: Option<usize>,
    /// A program sent as it is planned: whose check it was sent on, `launcher` (the
    /// launcher's, taken: [`crate::checked`]) or `interpreter` (its own).
    #[serde(default)]
    pub checked_by: Option<String>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Process {
    pub role: String,
    pub pid: u32,
    /// Exit code, or the signal that ended it, in words.
    pub exit: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Report {
    pub outcome: String,
    pub fault: Option<String>,
    pub program: String,
    /// "real" or "sim". Under "sim" the timing figures below are null: not measured.
    pub clock: String,
    pub period_ns: u64,
    pub cycles: u64,
    pub misses: Option<u64>,
    pub wake_late_ns: Option<Percentiles>,
    pub compute_ns: Option<Percentiles>,
    pub publish_ns: Option<Percentiles>,
    pub path_length_mm: f64,
    pub time_s: f64,
    pub avg_feed_mm_per_min: f64,
    pub peak_feed_mm_per_min: f64,
    pub max_following_error_um: f64,
    pub max_following_error_axis_um: [f64; 3],
    /// RMS following error per axis over every cycle; null when the servo-sim wrote no
    /// summary.
    pub rms_following_error_axis_um: Option<[f64; 3]>,
    /// Largest contour error: distance from a measured position to the exact commanded
    /// path (not to that cycle's set-point), over the cycles on feed moves (rapids left
    /// out), computed after the run by [`crate::contour`]; null when not computed (no
    /// command log or traces, or no feed move).
    pub max_contour_error_um: Option<f64>,
    /// Cycle and source line of the largest contour error.
    pub max_contour_error_cycle: Option<u64>,
    pub max_contour_error_line: Option<u32>,
    pub rms_contour_error_um: Option<f64>,
    /// Largest chord error of the interpolation: distance from the middle of the straight
    /// line between two consecutive set-points to the exact commanded path, over feed
    /// moves ([`crate::contour`]); its cycle and source line. Null when not computed.
    #[serde(default)]
    pub max_chord_error_um: Option<f64>,
    #[serde(default)]
    pub max_chord_error_cycle: Option<u64>,
    #[serde(default)]
    pub max_chord_error_line: Option<u32>,
    /// For a closed circular path: roundness and best-fit circle of the measured
    /// positions; null when the path has none.
    pub roundness: Option<RoundnessFigures>,
    pub lost_setpoints: u64,
    /// Who paced the drives: `lockstep` or `own` (see `cnc run --servo-clock`).
    #[serde(default)]
    pub servo_clock: String,
    /// Own servo clock: drive ticks that held the last set-point (none new had come), and
    /// set-points overtaken before a drive tick used them.
    #[serde(default)]
    pub servo_held_ticks: u64,
    #[serde(default)]
    pub servo_skipped_setpoints: u64,
    pub blocks: usize,
    /// Replays of a damaged log (`--salvage`): what was wrong and what ran.
    pub salvaged: Option<String>,
    /// The NC dialect the program was read in (`linuxcnc`, `fanuc`); null for replays.
    #[serde(default)]
    pub dialect: Option<String>,
    /// What the machine changed of what the program asked (a feed above its limit),
    /// `[source line, note]`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<(u32, String)>,
    /// A STEP-NC part's largest scallop height between passes (mm), as the pass planner
    /// predicts it; absent for G-code.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_scallop_mm: Option<f64>,
    /// The largest scallop height the run left, measured after it from the machine's
    /// positions (the balls swept along the executed path, [`crate::scallop`]), and
    /// where on the surface; absent for G-code.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_max_scallop_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_max_scallop_at_mm: Option<[f64; 3]>,
    pub sched: Option<interpolator::rt::sched::SchedReport>,
    /// The servo-sim's drive loop scheduling (policy, priority, locked memory, warnings);
    /// null when it wrote no summary.
    #[serde(default)]
    pub servo_sched: Option<interpolator::rt::sched::SchedReport>,
    pub miss_list: Vec<interpolator::summary::MissEntry>,
    /// Misses per cause id (`late_wake`, `long_compute`, `publish_stall`,
    /// `downstream_lag`, `preempted`), every miss counted, not only those listed.
    #[serde(default)]
    pub misses_by_cause: Vec<(String, u64)>,
    pub processes: Vec<Process>,
    /// Times the interpolator ran out of blocks mid-program and waited at a stop.
    #[serde(default)]
    pub starvations: u64,
    /// Feed fluctuation: `|actual step / planned step - 1|`, largest and RMS.
    #[serde(default)]
    pub feed_fluctuation_max: f64,
    #[serde(default)]
    pub feed_fluctuation_rms: f64,
    /// The interpolator's fault in figures (kind, cycle, line, axis, peer, the stop).
    #[serde(default)]
    pub fault_info: Option<interpolator::summary::FaultInfo>,
    /// A process killed from outside: which, and at which cycle.
    #[serde(default)]
    pub dead_process: Option<crate::launch::DeadProcess>,
    /// Each process's resident memory at the start and end of the run.
    #[serde(default)]
    pub memory: Vec<crate::launch::ProcessMemory>,
}

/// The roundness of a closed circular path (see [`crate::contour`]).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct RoundnessFigures {
    /// Max − min radius of the measured positions about their least-squares centre.
    pub roundness_um: f64,
    /// Working plane: "XY", "XZ" or "YZ".
    pub plane: String,
    /// Least-squares centre and radius of the measured positions.
    pub centre_mm: [f64; 2],
    pub radius_mm: f64,
    /// Radius of the commanded circle.
    pub commanded_radius_mm: f64,
    /// `radius_mm − commanded_radius_mm` (negative: the circle came out small).
    pub radius_error_um: f64,
    /// Source lines of the circle's first and last block.
    pub lines: [u32; 2],
    /// Measured positions the figures come from.
    pub samples: usize,
}

impl RoundnessFigures {
    pub fn of(r: &crate::contour::RoundnessSummary) -> Self {
        let name = ["X", "Y", "Z"];
        RoundnessFigures {
            roundness_um: r.roundness_um,
            plane: format!("{}{}", name[r.axes.0], name[r.axes.1]),
            centre_mm: r.centre_mm,
            radius_mm: r.radius_mm,
            commanded_radius_mm: r.commanded_radius_mm,
            radius_error_um: r.radius_error_um(),
            lines: [r.lines.0, r.lines.1],
            samples: r.samples,
        }
    }
}

fn read<T: for<'de> Deserialize<'de>>(path: &Path) -> Option<T> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// A fault `kind` of `fault_info` in words, for the lines people read.
pub fn kind_words(kind: &str) -> &str {
    match kind {
        "following_error" => "following error over the limit",
        "peer_gone" => "a process ended or died",
        "peer_silent" => "the drives stopped answering",
        "bad_block" => "a bad command block",
        "bad_feedback" => "bad feedback from the drives",
        "stop_requested" => "stop requested",
        "launcher_gone" => "the launcher (cnc run) died",
        "stalled" => "the path stood still",
        other => other,
    }
}

/// What the traces say when a process's own summary is missing (it was killed): the
/// set-points' count, path length and peak speed, and the largest following error.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TraceFigures {
    pub cycles: u64,
    pub path_length_mm: f64,
    pub peak_speed_mm_per_s: f64,
    pub max_following_error_axis_um: [f64; 3],
    pub feedback_rows: u64,
}

/// Calls `row` with the numbers of each complete line of a CSV file's data rows, a line
/// at a time, up to the first that does not parse (a killed writer may leave a half line
/// at the end; it is left out). As `str::lines` of the text up to its last newline: the
/// last complete line keeps a carriage return before its newline (and so does not parse).
fn csv_rows(path: &Path, mut row: impl FnMut(&[f64])) {
    use std::io::BufRead;
    let Ok(f) = std::fs::File::open(path) else {
        return;
    };
    let mut input = std::io::BufReader::new(f);
    let mut line: Vec<u8> = Vec::new();
    // The header.
    if !(input.read_until(b'\n', &mut line).is_ok() && line.ends_with(b"\n")) {
        return;
    }
    let mut vals: Vec<f64> = Vec::new();
    // A complete line waits for the next one: only then is its carriage return cut.
    let mut pending: Option<Vec<u8>> = None;
    let mut parse = |l: &[u8], vals: &mut Vec<f64>| -> bool {
        let Ok(l) = std::str::from_utf8(l) else {
            return false;
        };
        vals.clear();
        for v in l.split(',') {
            match v.parse::<f64>() {
                Ok(x) => vals.push(x),
                Err(_) => return false,
            }
        }
        row(vals);
        true
    };
    loop {
        line.clear();
        let complete =
            matches!(input.read_until(b'\n', &mut line), Ok(n) if n > 0 && line.ends_with(b"\n"));
        if !complete {
            if let Some(p) = pending.take() {
                parse(&p, &mut vals);
            }
            return;
        }
        line.pop();
        if let Some(mut p) = pending.replace(line.clone()) {
            if p.ends_with(b"\r") {
                p.pop();
            }
            if !parse(&p, &mut vals) {
                return;
            }
        }
    }
}

impl TraceFigures {
    pub fn read(dir: &Path, period_ns: u64) -> TraceFigures {
        let mut t = TraceFigures::default();
        let dt = period_ns.max(1) as f64 * 1e-9;
        // The peak feed is over feed moves, as the interpolator counts it: the source
        // lines of rapids come from the command log.
        let rapid_lines: std::collections::HashSet<u32> =
            shared::cmdlog::read(&dir.join("commands.log"))
                .map(|log| {
                    log.blocks
                        .iter()
                        .filter(|b| b.flags & shared::protocol::FLAG_RAPID != 0)
                        .map(|b| b.source_line)
                        .collect()
                })
                .unwrap_or_default();
        let mut last = [0.0; 3];
        csv_rows(&dir.join("setpoints.csv"), |r| {
            t.cycles += 1;
            if r.len() < 6 {
                return;
            }
            let p = [r[2], r[3], r[4]];
            let d = shared::path::norm([p[0] - last[0], p[1] - last[1], p[2] - last[2]]);
            t.path_length_mm += d;
            if !rapid_lines.contains(&(r[5] as u32)) {
                t.peak_speed_mm_per_s = t.peak_speed_mm_per_s.max(d / dt);
            }
            last = p;
        });
        csv_rows(&dir.join("feedback.csv"), |r| {
            t.feedback_rows += 1;
            if r.len() < 8 {
                return;
            }
            for a in 0..3 {
                let e = r[5 + a].abs();
                if e.is_finite() {
                    t.max_following_error_axis_um[a] = t.max_following_error_axis_um[a].max(e);
                }
            }
        });
        t
    }
}

/// The most bytes of command log and traces that `report.html` and the measured scallop
/// read. The measured scallop holds a surface run's measured positions whole, and both
/// hold the command blocks whole, at about 1.25 times the log's size (before the page
/// read the traces into temporary files, a run of 100 000 lines of `G1`, 583 MB of
/// files, took the launcher to 720 MB; a million lines would be 7 GB). A longer run has
/// no page and no measured scallop rather than fail at its end; its traces are all on
/// disk. `report.json`'s contour, chord and roundness figures read the traces a batch of
/// rows at a time ([`crate::contour::figures_dir`]), whatever their size, and so does the
/// page but for its scallop map ([`crate::html`]).
pub const CONTOUR_MAX_BYTES: u64 = 2 << 30;

/// The measured scallop of a run of surface blocks ([`crate::scallop::measure`]), from
/// every measured position, held whole (as its index of ball centres holds them): only
/// for a run within [`CONTOUR_MAX_BYTES`]; `None` without surface blocks.
fn measured_scallop(dir: &Path) -> Option<crate::scallop::Scallop> {
    let blocks = crate::contour::read_blocks(dir).ok()?;
    if !blocks.iter().any(|b| b.is_surface()) || !contour_in_memory(dir) {
        return None;
    }
    let mut fb = crate::contour::CsvRows::feedback(dir).ok()?;
    let mut positions = Vec::new();
    while let Some(r) = fb.next_row() {
        positions.push([r[1], r[2], r[3]]);
    }
    crate::scallop::measure(&blocks, &positions)
}

/// A trace's last line torn by a process killed while writing it, cut off, once every
/// process has ended: the kernel may stop a write to a file part way when the writer
/// gets SIGKILL (between two pages of it), leaving a row half-written. The rows before
/// it are whole; the torn one is a warning naming the file and how many bytes it had.
/// Returns the bytes cut from each trace of `dir` (`setpoints.csv`, `feedback.csv`).
pub(crate) fn cut_torn_rows(dir: &Path) -> Vec<(&'static str, u64)> {
    use std::io::{Read, Seek, SeekFrom};
    let mut cut = Vec::new();
    for name in ["setpoints.csv", "feedback.csv"] {
        let path = dir.join(name);
        let Ok(mut f) = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
        else {
            continue;
        };
        let Ok(len) = f.metadata().map(|m| m.len()) else {
            continue;
        };
        // A row is a few hundred bytes: the last newline is within the last 64 KiB, or
        // the file holds no whole row (a header torn: nothing of it kept).
        let tail = len.min(64 << 10);
        let mut buf = vec![0u8; tail as usize];
        if f.seek(SeekFrom::Start(len - tail)).is_err() || f.read_exact(&mut buf).is_err() {
            continue;
        }
        if buf.last().is_none_or(|b| *b == b'\n') {
            continue;
        }
        let keep = match buf.iter().rposition(|b| *b == b'\n') {
            Some(i) => len - tail + i as u64 + 1,
            None if tail == len => 0,
            // (A row longer than 64 KiB is no row of a trace: left as it is.)
            None => continue,
        };
        if f.set_len(keep).is_ok() {
            tracing::warn!(
                "{}: its last row was torn ({} bytes, the process writing it was killed): cut off",
                path.display(),
                len - keep
            );
            cut.push((name, len - keep));
        }
    }
    cut
}

/// Whether the run in `dir` is short enough for the page and the measured scallop
/// ([`CONTOUR_MAX_BYTES`]).
pub(crate) fn contour_in_memory(dir: &Path) -> bool {
    let bytes: u64 = ["commands.log", "setpoints.csv", "feedback.csv"]
        .iter()
        .map(|f| std::fs::metadata(dir.join(f)).map_or(0, |m| m.len()))
        .sum();
    if bytes > CONTOUR_MAX_BYTES {
        tracing::warn!(
            "the run's command log and traces are {} MB, more than the report page and the measured scallop hold ({} MB): they are left out",
            bytes >> 20,
            CONTOUR_MAX_BYTES >> 20
        );
        return false;
    }
    true
}

/// Folds the per-process summaries of `dir` into a report. Missing parts (a process that
/// died before writing its summary) are taken from the traces where they can be (the
/// cycles, path and peak feed from `setpoints.csv`, the following error from
/// `feedback.csv`) and are named in `fault`.
///
/// `fault` names the first fault first: `primary` (the launcher's finding: the operator's
/// stop, a process suspended or killed), then the processes' own faults, the
/// interpolator's before the others' (they follow it), unless it stopped for a peer that
/// has a fault of its own; `exit_fault` (which process exited first, and how) only when
/// nothing else says why.
pub fn assemble(
    dir: &Path,
    program: &str,
    clock: ClockMode,
    period_ns: u64,
    processes: Vec<Process>,
    primary: Option<String>,
    exit_fault: Option<String>,
) -> Report {
    let interp: Option<InterpreterSummary> = read(&dir.join("interpreter.json"));
    let ipol: Option<InterpSummary> = read(&dir.join("interpolator.json"));
    let servo: Option<ServoSummary> = read(&dir.join("servo.json"));
    let ipol_kind = ipol
        .as_ref()
        .and_then(|s| s.fault_info.as_ref())
        .map(|f| (f.kind.clone(), f.peer.clone()));
    // A stop the launcher names itself (the operator, its own death) is not repeated.
    let stop_named = primary.is_some()
        && ipol_kind
            .as_ref()
            .is_some_and(|(k, _)| k == "stop_requested" || k == "launcher_gone");
    let mut order = vec!["interpolator", "servo-sim", "interpreter"];
    if let Some((k, Some(peer))) = &ipol_kind {
        let peer_fault = match peer.as_str() {
            "servo-sim" => servo.as_ref().is_some_and(|s| s.fault.is_some()),
            "interpreter" => interp.as_ref().is_some_and(|s| s.fault.is_some()),
            _ => false,
        };
        if (k == "peer_gone" || k == "peer_silent") && peer_fault {
            order.retain(|r| r != peer);
            order.insert(
                0,
                if peer == "servo-sim" {
                    "servo-sim"
                } else {
                    "interpreter"
                },
            );
        }
    }
    let ipol_faulted = ipol.as_ref().is_some_and(|s| s.fault.is_some());
    let mut faults: Vec<String> = primary.into_iter().collect();
    let mut missing: Vec<String> = Vec::new();
    for role in order {
        let outcome = match role {
            "interpreter" => interp.as_ref().map(|s| s.fault.clone()),
            "interpolator" => ipol.as_ref().map(|s| s.fault.clone()),
            _ => servo.as_ref().map(|s| s.fault.clone()),
        };
        match outcome {
            None => missing.push(format!("{role} wrote no summary")),
            Some(Some(_)) if stop_named && role != "servo-sim" => {}
            // The interpreter's "the interpolator stopped" says nothing the
            // interpolator's own fault does not.
            Some(Some(_)) if role == "interpreter" && ipol_faulted && interp_followed(&interp) => {}
            Some(Some(f)) => faults.push(format!("{role}: {f}")),
            Some(None) => {}
        }
    }
    if faults.is_empty() {
        faults.extend(exit_fault);
    }
    faults.extend(missing);
    faults.dedup();
    let fault = (!faults.is_empty()).then(|| faults.join("; "));
    let traced = (ipol.is_none() || servo.is_none()).then(|| TraceFigures::read(dir, period_ns));
    let i = ipol.as_ref();
    // After every process has ended: the traces are complete and nothing runs in real time.
    // They are read a row at a time, whatever the run's length.
    let contour = crate::contour::figures_dir(dir).ok();
    let scallop = contour.as_ref().and_then(|_| measured_scallop(dir));
    let worst = contour.as_ref().and_then(|c| c.max);
    let chord = contour.as_ref().and_then(|c| c.chord);
    let salvaged = interp.as_ref().and_then(|s| s.salvaged.clone());
    // A salvaged log ran only its intact blocks: never "done", whatever the processes say.
    let outcome = match (&fault, &salvaged) {
        (Some(_), _) => "fault",
        (None, Some(_)) => "salvaged",
        (None, None) => "done",
    };
    Report {
        outcome: outcome.into(),
        fault,
        program: program.to_string(),
        clock: clock.name().into(),
        period_ns,
        cycles: i.map_or(traced.map_or(0, |t| t.cycles), |s| s.cycles),
        misses: i.and_then(|s| s.misses),
        wake_late_ns: i.and_then(|s| s.wake_late_ns),
        compute_ns: i.and_then(|s| s.compute_ns),
        publish_ns: i.and_then(|s| s.publish_ns),
        path_length_mm: i.map_or(traced.map_or(0.0, |t| t.path_length_mm), |s| {
            s.path_length_mm
        }),
        // From the cycles, as the interpolator and `check --estimate` work it out: its
        // summary's figure has been through JSON text, whose parser may round the last
        // bit differently (12.453000000000001 came back 12.453).
        time_s: (i.map_or(traced.map_or(0, |t| t.cycles), |s| s.cycles) * period_ns) as f64 * 1e-9,
        avg_feed_mm_per_min: i.map_or(
            traced.map_or(0.0, |t| {
                let s = (t.cycles * period_ns) as f64 * 1e-9;
                if s > 0.0 {
                    t.path_length_mm / s * 60.0
                } else {
                    0.0
                }
            }),
            |s| s.avg_feed_mm_per_min,
        ),
        peak_feed_mm_per_min: i.map_or(traced.map_or(0.0, |t| t.peak_speed_mm_per_s * 60.0), |s| {
            s.peak_feed_mm_per_min
        }),
        max_following_error_um: servo.as_ref().map_or(
            traced.map_or(0.0, |t| {
                t.max_following_error_axis_um
                    .iter()
                    .fold(0.0, |a: f64, b| a.max(*b))
            }),
            |s| s.max_following_error_um,
        ),
        max_following_error_axis_um: servo.as_ref().map_or(
            traced.map_or([0.0; 3], |t| t.max_following_error_axis_um),
            |s| s.max_following_error_axis_um,
        ),
        servo_sched: servo.as_ref().and_then(|s| s.sched.clone()),
        rms_following_error_axis_um: servo.as_ref().map(|s| s.rms_following_error_axis_um),
        max_contour_error_um: worst.map(|w| w.um),
        max_contour_error_cycle: worst.map(|w| w.cycle),
        max_contour_error_line: worst.map(|w| w.line),
        rms_contour_error_um: contour.as_ref().and_then(|c| c.rms_um),
        max_chord_error_um: chord.map(|w| w.um),
        max_chord_error_cycle: chord.map(|w| w.cycle),
        max_chord_error_line: chord.map(|w| w.line),
        roundness: contour
            .as_ref()
            .and_then(|c| c.roundness.as_ref().ok())
            .map(RoundnessFigures::of),
        lost_setpoints: servo.as_ref().map_or(0, |s| s.lost_setpoints),
        servo_clock: servo
            .as_ref()
            .map_or_else(String::new, |s| s.servo_clock.clone()),
        servo_held_ticks: servo.as_ref().map_or(0, |s| s.held_ticks),
        servo_skipped_setpoints: servo.as_ref().map_or(0, |s| s.skipped_setpoints),
        blocks: interp.as_ref().map_or(0, |s| s.blocks),
        salvaged,
        dialect: interp.as_ref().and_then(|s| s.dialect.clone()),
        notes: interp.as_ref().map(|s| s.notes.clone()).unwrap_or_default(),
        max_scallop_mm: interp.as_ref().and_then(|s| s.max_scallop_mm),
        measured_max_scallop_mm: scallop.map(|s| s.max_mm),
        measured_max_scallop_at_mm: scallop.map(|s| s.at_mm),
        sched: i.map(|s| s.sched.clone()),
        miss_list: i.map(|s| s.miss_list.clone()).unwrap_or_default(),
        misses_by_cause: i.map(|s| s.misses_by_cause.clone()).unwrap_or_default(),
        processes,
        starvations: i.map_or(0, |s| s.starvations),
        feed_fluctuation_max: i.map_or(0.0, |s| s.feed_fluctuation_max),
        feed_fluctuation_rms: i.map_or(0.0, |s| s.feed_fluctuation_rms),
        fault_info: i.and_then(|s| s.fault_info.clone()),
        dead_process: None,
        memory: Vec::new(),
    }
}

/// The summary's timing figures, rounded as the deadline line rounds them
/// ([`interpolator::rt::latency::us`]), so that one figure reads the same in both.
fn timing_text(misses: u64, wake: &Percentiles, compute: &Percentiles) -> String {
    use interpolator::rt::latency::us;
    format!(
        "{misses} misses, wake-up late p50 {} p99 {} max {}, compute p99 {}",
        us(wake.p50),
        us(wake.p99),
        us(wake.max),
        us(compute.p99)
    )
}

impl Report {
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        std::fs::write(
            path,
            serde_json::to_string_pretty(self).map_err(std::io::Error::other)?,
        )
    }

    /// The short summary `cnc run` prints.
    pub fn summary_text(&self, dir: &Path) -> String {
        let timing = match (self.misses, self.wake_late_ns, self.compute_ns) {
            (Some(m), Some(w), Some(c)) => timing_text(m, &w, &c),
            _ => format!("not measured ({} clock)", self.clock),
        };
        let contour = match (self.max_contour_error_um, &self.roundness) {
            (Some(c), Some(r)) => format!(
                "max contour error {c:.2} µm, roundness {:.2} µm",
                r.roundness_um
            ),
            (Some(c), None) => format!("max contour error {c:.2} µm"),
            _ => "contour error not computed".into(),
        };
        let chord = match (self.max_chord_error_um, self.max_chord_error_line) {
            (Some(c), Some(line)) => format!(
                "  chord        max chord error {c:.3} µm between consecutive set-points (line {line})\n"
            ),
            _ => String::new(),
        };
        // A surface part's speeds are those of the tool's reference point.
        let centre = if self.max_scallop_mm.is_some() {
            " (tool centre)"
        } else {
            ""
        };
        let mut s = format!(
            "{}: {}\n  program      {}\n  period       {} µs, {} cycles, {:.3} s machining ({} clock)\n  path         {:.3} mm, average feed {:.1} mm/min, peak {:.1} mm/min{centre}\n{chord}  servo        max following error {:.2} µm, {contour}\n  timing       {timing}\n  run dir      {}\n",
            self.outcome,
            match (self.fault.as_deref(), self.salvaged.as_deref()) {
                (Some(f), _) => f,
                (None, Some(_)) =>
                    "only the intact blocks of a damaged command log ran, then a stop: not the whole program",
                (None, None) => "program completed",
            },
            self.program,
            self.period_ns / 1000,
            self.cycles,
            self.time_s,
            self.clock,
            self.path_length_mm,
            self.avg_feed_mm_per_min,
            self.peak_feed_mm_per_min,
            self.max_following_error_um,
            dir.display()
        );
        match (self.max_scallop_mm, self.measured_max_scallop_mm) {
            (Some(h), Some(m)) => s.push_str(&format!(
                "  surface      max scallop {:.2} µm measured from the machine's positions ({:.2} µm as the passes were planned)\n",
                m * 1e3,
                h * 1e3
            )),
            (Some(h), None) => s.push_str(&format!(
                "  surface      max scallop {:.2} µm (as the passes were planned; not measured)\n",
                h * 1e3
            )),
            // A replay has the blocks but not the planner's figure.
            (None, Some(m)) => s.push_str(&format!(
                "  surface      max scallop {:.2} µm measured from the machine's positions\n",
                m * 1e3
            )),
            (None, None) => {}
        }
        if let Some(note) = &self.salvaged {
            s.push_str(&format!("  warning      {note}\n"));
        }
        if let Some(sched) = &self.sched {
            for w in &sched.warnings {
                s.push_str(&format!("  warning      {w}\n"));
            }
        }
        if let Some(sched) = &self.servo_sched {
            for w in &sched.warnings {
                s.push_str(&format!("  warning      servo-sim: {w}\n"));
            }
        }
        s
    }
}

/// Whether the interpreter only followed the interpolator's stop (its fault says so).
fn interp_followed(interp: &Option<InterpreterSummary>) -> bool {
    interp
        .as_ref()
        .and_then(|s| s.fault.as_deref())
        .is_some_and(|f| f.starts_with("the interpolator stopped"))
}

/// When the launcher (`cnc run`) died: the interpreter, the survivor that runs this
/// crate, waits for the interpolator's and the servo-sim's summaries (they finish the
/// controlled stop after it has left) and writes `report.json` and `report.html` in the
/// launcher's place, so the run directory says why the run stopped.
pub fn write_orphan_report(dir: &Path, program: &str, period_ns: u64) -> Result<(), String> {
    let t = std::time::Instant::now();
    while t.elapsed() < std::time::Duration::from_secs(15)
        && !(dir.join("interpolator.json").exists() && dir.join("servo.json").exists())
    {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    // A summary is written in one call, but give a writer caught mid-write a moment.
    std::thread::sleep(std::time::Duration::from_millis(50));
    let ipol: Option<InterpSummary> = read(&dir.join("interpolator.json"));
    let clock = match ipol.as_ref().map(|s| s.clock.as_str()) {
        Some("sim") => ClockMode::Sim,
        _ => ClockMode::Real,
    };
    let primary = match ipol.as_ref().and_then(|s| s.fault.clone()) {
        Some(f) if f.starts_with("stopped: the launcher") => f,
        _ => "stopped: the launcher (cnc run) died; the interpolator's summary does not say when"
            .into(),
    };
    let processes = [
        ("interpreter", Some(std::process::id())),
        ("interpolator", ipol.as_ref().map(|s| s.pid)),
        (
            "servo-sim",
            read::<ServoSummary>(&dir.join("servo.json")).map(|s| s.pid),
        ),
    ]
    .into_iter()
    .filter_map(|(role, pid)| {
        Some(Process {
            role: role.into(),
            pid: pid?,
            exit: "unknown (the launcher that would have waited for it died)".into(),
        })
    })
    .collect();
    let mut rep = assemble(
        dir,
        program,
        clock,
        period_ns,
        processes,
        Some(format!("{primary} (report written by the interpreter)")),
        None,
    );
    rep.outcome = "fault".into();
    rep.write(&dir.join("report.json"))
        .map_err(|e| format!("writing report.json: {e}"))?;
    if contour_in_memory(dir) {
        crate::html::write(dir, None).map_err(|e| format!("writing report.html: {e}"))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A killed writer's torn last row is cut; whole traces, a missing one and a torn
    /// header (no whole row at all) are handled.
    #[test]
    fn a_torn_last_row_is_cut_and_whole_traces_are_left() {
        let dir = std::env::temp_dir().join(format!("cnc-torn-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("setpoints.csv"), "t,x\n1,2\n3,4").unwrap();
        std::fs::write(dir.join("feedback.csv"), "t,x\n1,2\n").unwrap();
        assert_eq!(cut_torn_rows(&dir), vec![("setpoints.csv", 3)]);
        assert_eq!(
            std::fs::read_to_string(dir.join("setpoints.csv")).unwrap(),
            "t,x\n1,2\n"
        );
        assert_eq!(
            std::fs::read_to_string(dir.join("feedback.csv")).unwrap(),
            "t,x\n1,2\n"
        );
        assert!(cut_torn_rows(&dir).is_empty());
        std::fs::write(dir.join("feedback.csv"), "t,").unwrap();
        std::fs::remove_file(dir.join("setpoints.csv")).unwrap();
        assert_eq!(cut_torn_rows(&dir), vec![("feedback.csv", 2)]);
        assert_eq!(std::fs::read(dir.join("feedback.csv")).unwrap().len(), 0);
        // A long trace: the newline is found in its last 64 KiB.
        let mut long = String::from("t,x\n");
        while long.len() < 200_000 {
            long.push_str("123456.789,-0.001\n");
        }
        let whole = long.len();
        long.push_str("12345");
        std::fs::write(dir.join("setpoints.csv"), &long).unwrap();
        assert_eq!(cut_torn_rows(&dir), vec![("setpoints.csv", 5)]);
        assert_eq!(
            std::fs::metadata(dir.join("setpoints.csv")).unwrap().len() as usize,
            whole
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A run whose log and traces are more than the analysis holds is not read (a
    /// million lines of `G1` took the launcher to 7.2 GB at the end of the run).
    #[test]
    fn a_run_too_long_to_hold_leaves_the_contour_out() {
        let dir = std::env::temp_dir().join(format!("cnc-contour-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("setpoints.csv"),
            "cycle,t_ns,x_mm,y_mm,z_mm,line\n",
        )
        .unwrap();
        assert!(contour_in_memory(&dir));
        // (Sparse: nothing is written.)
        let log = std::fs::File::create(dir.join("commands.log")).unwrap();
        log.set_len(CONTOUR_MAX_BYTES + 1).unwrap();
        assert!(!contour_in_memory(&dir));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A p99 of 278.6 µs reads 279 µs in the timing line, as in the deadline line (it
    /// read 278 there: cut, not rounded).
    #[test]
    fn timing_rounds_as_the_deadline_line() {
        let wake = Percentiles {
            p50: 36_400,
            p99: 278_600,
            max: 1_974_000,
            ..Percentiles::default()
        };
        let compute = Percentiles {
            p99: 8_200,
            ..Percentiles::default()
        };
        assert_eq!(
            timing_text(10, &wake, &compute),
            "10 misses, wake-up late p50 36 µs p99 279 µs max 1974 µs, compute p99 8.2 µs"
        );
        assert_eq!(interpolator::rt::latency::us(278_600), "279 µs");
    }
}
