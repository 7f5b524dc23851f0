//! Loading a run directory for the page, leniently.
//!
//! Every file is optional: what cannot be read becomes a *problem* (`file:line: message`)
//! that the page lists, and the loader keeps whatever came before the damage (a CSV cut
//! off mid-row by a crash still plots up to its last whole row). `report.json` is read
//! field by field from a JSON value rather than into the launcher's `Report` type, so a
//! report from an older or newer format still gives every figure it has, and an absent
//! figure is named instead of failing the whole page. The traces' rows go to temporary
//! files as they are read ([`Setpoints`], [`Feedback`]): the plots read them back.

use crate::spill::{Spill, Spilled};
use serde_json::Value;
use shared::protocol::{BlockKind, CommandBlock};
use shared::Machine;
use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// `{p50, p99, max}` of one timing figure, in ns.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pct {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

/// One deadline miss from `report.json`'s `miss_list`.
#[derive(Debug, Clone, PartialEq)]
pub struct Miss {
    pub cycle: u64,
    pub line: u64,
    pub cause: String,
    pub wake_late_ns: f64,
    pub compute_ns: f64,
    pub publish_ns: f64,
    pub overrun_ns: f64,
    /// How long the compute phase was off the CPU; 0 in reports older than that figure.
    pub preempted_ns: f64,
}

/// Scheduling in force, from `report.json`'s `sched`.
#[derive(Debug, Clone, PartialEq)]
pub struct Sched {
    pub policy: String,
    pub priority: i64,
    pub memory_locked: bool,
    pub warnings: Vec<String>,
}

/// The figures of `report.json`; `None` where the report has null (not measured) or lacks
/// the field (then a problem names it).
#[derive(Debug, Clone, Default)]
pub struct Report {
    pub outcome: Option<String>,
    pub fault: Option<String>,
    pub program: Option<String>,
    /// The NC dialect the program was read in; absent in older reports and replays.
    pub dialect: Option<String>,
    /// What the machine changed of what the program asked, by source line (a feed above
    /// its limit); absent in older reports.
    pub notes: Vec<(u32, String)>,
    pub clock: Option<String>,
    pub period_ns: Option<u64>,
    pub cycles: Option<u64>,
    pub misses: Option<u64>,
    pub wake_late_ns: Option<Pct>,
    pub compute_ns: Option<Pct>,
    pub publish_ns: Option<Pct>,
    pub path_length_mm: Option<f64>,
    pub time_s: Option<f64>,
    pub avg_feed_mm_per_min: Option<f64>,
    pub peak_feed_mm_per_min: Option<f64>,
    pub max_following_error_um: Option<f64>,
    pub max_following_error_axis_um: Option<[f64; 3]>,
    /// The servo and contour figures below are newer than the others: a report without
    /// them is not a problem, they show as not available.
    pub rms_following_error_axis_um: Option<[f64; 3]>,
    pub max_contour_error_um: Option<f64>,
    pub max_contour_error_cycle: Option<u64>,
    pub max_contour_error_line: Option<u64>,
    pub rms_contour_error_um: Option<f64>,
    /// The interpolation's chord error (newer still).
    pub max_chord_error_um: Option<f64>,
    pub max_chord_error_line: Option<u64>,
    pub roundness_um: Option<f64>,
    pub roundness_radius_error_um: Option<f64>,
    /// A STEP-NC part's largest scallop height (mm), as planned and as measured after the
    /// run, and where; absent for G-code and in older reports.
    pub max_scallop_mm: Option<f64>,
    pub measured_max_scallop_mm: Option<f64>,
    pub measured_max_scallop_at_mm: Option<[f64; 3]>,
    pub lost_setpoints: Option<u64>,
    pub blocks: Option<u64>,
    pub sched: Option<Sched>,
    pub miss_list: Vec<Miss>,
}

/// `setpoints.csv`'s rows (cycle, position, source line), in a temporary file
/// ([`crate::spill`]): a one-hour run has 3.6 million of them, which the page reads a
/// few times over but never holds.
#[derive(Debug)]
pub struct Setpoints {
    rows: Spilled<5>,
    /// The last row's cycle.
    pub last_cycle: u64,
    /// The first and the last set-point.
    pub first_mm: [f64; 3],
    pub last_mm: [f64; 3],
    /// The smallest and largest coordinate of the set-points, per axis.
    pub extent_mm: [(f64, f64); 3],
}

impl Setpoints {
    /// How many rows there are.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The rows in order: cycle, position (mm), source line.
    pub fn rows(&self) -> impl Iterator<Item = (u64, [f64; 3], u32)> + '_ {
        self.rows
            .records()
            .map(|r| (r[0] as u64, [r[1], r[2], r[3]], r[4] as u32))
    }
}

/// `feedback.csv`'s rows (cycle, measured position, following error), in a temporary
/// file as [`Setpoints`]'.
#[derive(Debug)]
pub struct Feedback {
    rows: Spilled<7>,
    /// The last row's cycle.
    pub last_cycle: u64,
}

impl Feedback {
    /// How many rows there are.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// The rows in order: cycle, measured position (mm), following error (µm, to `f32`
    /// precision: plenty for a plot).
    pub fn rows(&self) -> impl Iterator<Item = (u64, [f64; 3], [f64; 3])> + '_ {
        self.rows.records().map(|r| {
            (
                r[0] as u64,
                [r[1], r[2], r[3]],
                [r[4], r[5], r[6]].map(|e| f64::from(e as f32)),
            )
        })
    }
}

/// Everything the page draws from.
#[derive(Debug)]
pub struct Run {
    pub dir: PathBuf,
    pub report: Option<Report>,
    pub setpoints: Option<Setpoints>,
    pub feedback: Option<Feedback>,
    /// Validated command blocks in sending order (empty when the log is missing).
    pub blocks: Vec<CommandBlock>,
    /// The run's machine file, or the built-in machine (then a problem says so).
    pub machine: Machine,
    /// `program.ngc` by line (index 0 is line 1).
    pub program: Vec<String>,
    /// The path as programmed, where the program uses cutter radius compensation (the
    /// blocks are the tool centre's): `program.ngc` read again with `G41`/`G42` left
    /// unapplied. Empty otherwise, or where it cannot be read on its own (a subroutine
    /// file it calls is not in the run directory).
    pub programmed: Vec<CommandBlock>,
    /// The interpolation period in force, from the report or the CSV's `t_ns`.
    pub period_ns: u64,
    /// `deadline-misses.json`: histograms, every miss, runs, the latency floor (`None`
    /// when absent, as in run directories older than it, or unusable: then a problem).
    pub deadline: Option<interpolator::deadline::DeadlineReport>,
    /// What is missing or damaged, each `file[:line]: message`.
    pub problems: Vec<String>,
}

impl Run {
    pub fn load(dir: &Path) -> Run {
        let mut problems = Vec::new();
        let report = load_report(&dir.join("report.json"), &mut problems);
        // The two traces are read side by side (each is hundreds of MB on a long run) into
        // temporary files.
        let ((setpoints, sp_problems), (feedback, fb_problems)) = std::thread::scope(|scope| {
            let sp = scope.spawn(|| {
                let mut problems = Vec::new();
                let (mut first, mut last, mut last_cycle) = (None, [0.0; 3], 0);
                let mut extent = [(f64::INFINITY, f64::NEG_INFINITY); 3];
                let rows = load_csv(
                    &dir.join("setpoints.csv"),
                    &["cycle", "x_mm", "y_mm", "z_mm", "line"],
                    &mut problems,
                    |r: &[f64; 5]| {
                        let p = [r[1], r[2], r[3]];
                        first.get_or_insert(p);
                        last = p;
                        last_cycle = r[0] as u64;
                        for (e, x) in extent.iter_mut().zip(p) {
                            *e = (e.0.min(x), e.1.max(x));
                        }
                    },
                );
                let s = rows.map(|rows| Setpoints {
                    rows,
                    last_cycle,
                    first_mm: first.unwrap_or_default(),
                    last_mm: last,
                    extent_mm: extent,
                });
                (s, problems)
            });
            let mut problems = Vec::new();
            let mut last_cycle = 0;
            let rows = load_csv(
                &dir.join("feedback.csv"),
                &[
                    "cycle",
                    "x_mm",
                    "y_mm",
                    "z_mm",
                    "ferr_x_um",
                    "ferr_y_um",
                    "ferr_z_um",
                ],
                &mut problems,
                |r: &[f64; 7]| last_cycle = r[0] as u64,
            );
            let fb = (rows.map(|rows| Feedback { rows, last_cycle }), problems);
            (
                sp.join()
                    .unwrap_or_else(|_| (None, vec!["setpoints.csv: reader failed".into()])),
                fb,
            )
        });
        problems.extend(sp_problems);
        problems.extend(fb_problems);
        let log = dir.join("commands.log");
        let blocks = match shared::cmdlog::read(&log) {
            Ok(parsed) => {
                if let Some(d) = parsed.damage {
                    problems.push(format!("commands.log: {d}; blocks after it are not drawn"));
                }
                parsed
                    .blocks
                    .into_iter()
                    .filter(|b| b.validate().is_ok())
                    .collect::<Vec<_>>()
            }
            Err(e) => {
                problems.push(format!("{e} (no path plot)"));
                Vec::new()
            }
        };
        if let Some(r) = &report {
            let cycles = r.cycles.unwrap_or(0);
            let lost = r.lost_setpoints.unwrap_or(0);
            if let Some(s) = &setpoints {
                if (s.len() as u64) < cycles {
                    problems.push(format!(
                        "setpoints.csv: {} rows for the {cycles} cycles of report.json (file cut short?)",
                        s.len()
                    ));
                }
            }
            if let Some(f) = &feedback {
                if f.len() as u64 + lost < cycles {
                    problems.push(format!(
                        "feedback.csv: {} rows for the {cycles} cycles of report.json ({lost} set-points lost; file cut short?)",
                        f.len()
                    ));
                }
            }
        }
        let machine = load_machine(&dir.join("machine.toml"), &mut problems);
        let program = match std::fs::read_to_string(dir.join("program.ngc")) {
            Ok(t) => t.lines().map(str::to_owned).collect(),
            Err(e) => {
                problems.push(format!(
                    "program.ngc: {e} (tooltips show line numbers only)"
                ));
                Vec::new()
            }
        };
        let programmed = programmed_path(&program, &machine);
        let period_ns = report
            .as_ref()
            .and_then(|r| r.period_ns)
            .filter(|p| *p > 0)
            .or_else(|| period_from_csv(&dir.join("setpoints.csv")))
            .unwrap_or_else(|| {
                problems.push("period unknown (no report.json, no t_ns): assuming 1 ms".into());
                1_000_000
            });
        let deadline = load_deadline(dir, &mut problems);
        Run {
            dir: dir.to_path_buf(),
            deadline,
            report,
            setpoints,
            feedback,
            blocks,
            machine,
            program,
            programmed,
            period_ns,
            problems,
        }
    }

    /// Motion blocks only.
    pub fn motion(&self) -> impl Iterator<Item = &CommandBlock> {
        self.blocks
            .iter()
            .filter(|b| b.kind() == Some(BlockKind::Motion))
    }

    /// The text of source line `line` (1-based), trimmed, or "".
    pub fn source(&self, line: u32) -> &str {
        (line as usize)
            .checked_sub(1)
            .and_then(|i| self.program.get(i))
            .map_or("", |s| s.trim())
    }

    pub fn period_s(&self) -> f64 {
        self.period_ns as f64 * 1e-9
    }
}

/// `deadline-misses.json`, if there is a usable one. Its absence is not a problem (older
/// run directories, or an interpolator that died before the end): the timing section then
/// draws what report.json has.
/// The programmed path of a compensated program (see [`Run::programmed`]).
fn programmed_path(lines: &[String], machine: &Machine) -> Vec<CommandBlock> {
    let opts = crate::program::Options {
        uncompensated: true,
        ..Default::default()
    };
    match crate::program::interpret_with(&lines.join("\n"), &opts) {
        Ok(p) if p.compensated => crate::blocks::commands(&crate::blocks::build(&p.moves, machine)),
        _ => Vec::new(),
    }
}

fn load_deadline(
    dir: &Path,
    problems: &mut Vec<String>,
) -> Option<interpolator::deadline::DeadlineReport> {
    let name = interpolator::deadline::JSON_FILE;
    let text = std::fs::read_to_string(dir.join(name)).ok()?;
    match serde_json::from_str(&text) {
        Ok(d) => Some(d),
        Err(e) => {
            problems.push(format!(
                "{name}:{}:{}: {e} (timing histograms and the full miss list not drawn)",
                e.line(),
                e.column()
            ));
            None
        }
    }
}

fn load_machine(path: &Path, problems: &mut Vec<String>) -> Machine {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) => {
            problems.push(format!(
                "machine.toml: {e} (limits drawn from the built-in machine)"
            ));
            return Machine::default();
        }
    };
    Machine::from_toml(&text).unwrap_or_else(|e| {
        problems.push(format!(
            "machine.toml: {} (limits drawn from the built-in machine)",
            e.trim()
        ));
        Machine::default()
    })
}

/// `t_ns` of the second data row of a set-point CSV: the period, when the report is gone.
fn period_from_csv(path: &Path) -> Option<u64> {
    let f = File::open(path).ok()?;
    let mut lines = BufReader::new(f).lines();
    let header = lines.next()?.ok()?;
    let col = header.split(',').position(|h| h == "t_ns")?;
    let cyc = header.split(',').position(|h| h == "cycle")?;
    for l in lines.take(4) {
        let l = l.ok()?;
        let cells: Vec<&str> = l.split(',').collect();
        let c: u64 = cells.get(cyc)?.parse().ok()?;
        let t: u64 = cells.get(col)?.parse().ok()?;
        if let Some(p) = t.checked_div(c) {
            return Some(p);
        }
    }
    None
}

/// Reads the named columns of a CSV file into a temporary file, each row's values in
/// `want` order, handing each row to `row_out` too as it is read: a one-hour file has 3.6
/// million rows, so nothing is kept in memory and nothing is allocated per row. Stops at
/// the first bad row (recording a problem naming file and line), the rows before it
/// kept; `None` when the file or its header is unusable, it has no data rows or the
/// temporary file cannot be written.
fn load_csv<const N: usize>(
    path: &Path,
    want: &[&str; N],
    problems: &mut Vec<String>,
    mut row_out: impl FnMut(&[f64; N]),
) -> Option<Spilled<N>> {
    let name = file_name(path);
    let f = match File::open(path) {
        Ok(f) => f,
        Err(e) => {
            problems.push(format!("{name}: {e}"));
            return None;
        }
    };
    let mut reader = BufReader::with_capacity(1 << 20, f);
    let mut header = String::new();
    match reader.read_line(&mut header) {
        Ok(0) => {
            problems.push(format!("{name}:1: empty file, no header"));
            return None;
        }
        Ok(_) => {}
        Err(e) => {
            problems.push(format!("{name}:1: {e}"));
            return None;
        }
    }
    let cols: Vec<&str> = header.trim().split(',').collect();
    let mut idx = Vec::with_capacity(want.len());
    for w in want {
        match cols.iter().position(|c| c == w) {
            Some(i) => idx.push(i),
            None => {
                problems.push(format!(
                    "{name}:1: no column `{w}` in the header (older format?)"
                ));
                return None;
            }
        }
    }
    // The column each cell goes to (`usize::MAX`: not wanted).
    let mut slot = vec![usize::MAX; cols.len()];
    for (k, &c) in idx.iter().enumerate() {
        slot[c] = k;
    }
    let mut spill = match Spill::<N>::new() {
        Ok(s) => s,
        Err(e) => {
            problems.push(format!("{name}: temporary file: {e}"));
            return None;
        }
    };
    let mut buf: Vec<u8> = Vec::new();
    let mut row = [0.0f64; N];
    for lineno in 2.. {
        buf.clear();
        match reader.read_until(b'\n', &mut buf) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) => {
                problems.push(format!("{name}:{lineno}: {e}; rows from here on not drawn"));
                break;
            }
        }
        let Ok(l) = std::str::from_utf8(&buf) else {
            problems.push(format!(
                "{name}:{lineno}: stream did not contain valid UTF-8; rows from here on not drawn"
            ));
            break;
        };
        let l = l.trim();
        if l.is_empty() {
            continue;
        }
        // One pass over the cells; a wrong number of cells is reported before a bad value.
        let mut bad = None;
        let mut n_cells = 0;
        for cell in l.split(',') {
            let k = slot.get(n_cells).copied().unwrap_or(usize::MAX);
            n_cells += 1;
            if k == usize::MAX {
                continue;
            }
            match parse_f64(cell) {
                Some(v) if v.is_finite() => row[k] = v,
                _ => {
                    // The first bad value in `want` order, as the message names it.
                    if bad.is_none_or(|(b, _)| k < b) {
                        bad = Some((k, cell));
                    }
                }
            }
        }
        if n_cells != cols.len() {
            problems.push(format!(
                "{name}:{lineno}: {n_cells} of {} columns (row cut off?); rows from here on not drawn",
                cols.len()
            ));
            break;
        }
        if let Some((k, cell)) = bad {
            problems.push(format!(
                "{name}:{lineno}: column `{}`: `{cell}` is not a number; rows from here on not drawn",
                want[k]
            ));
            break;
        }
        if let Err(e) = spill.push(row) {
            problems.push(format!("{name}: temporary file: {e}"));
            return None;
        }
        row_out(&row);
    }
    if spill.len() == 0 {
        problems.push(format!("{name}: no data rows"));
        return None;
    }
    match spill.finish() {
        Ok(rows) => Some(rows),
        Err(e) => {
            problems.push(format!("{name}: temporary file: {e}"));
            None
        }
    }
}

/// `s` as an `f64`, exactly as `str::parse` reads it. Plain decimals of at most 15
/// significant digits and 22 decimals (every number the run writes) take a fast path: the
/// digits as an integer and the power of ten are both exact in an `f64`, so one division
/// rounds correctly, the same value the full parser gives. Anything else goes to it.
fn parse_f64(s: &str) -> Option<f64> {
    const POW10: [f64; 23] = [
        1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
        1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
    ];
    let b = s.as_bytes();
    let (neg, digits) = match b.first() {
        Some(b'-') => (true, &b[1..]),
        _ => (false, b),
    };
    let (mut m, mut n, mut frac, mut dot) = (0u64, 0usize, 0usize, false);
    for &c in digits {
        match c {
            b'0'..=b'9' => {
                m = m * 10 + u64::from(c - b'0');
                n += 1;
                if dot {
                    frac += 1;
                }
                if n > 15 {
                    return s.parse().ok();
                }
            }
            b'.' if !dot => dot = true,
            _ => return s.parse().ok(),
        }
    }
    if n == 0 || frac >= POW10.len() {
        return s.parse().ok();
    }
    let v = m as f64 / POW10[frac];
    Some(if neg { -v } else { v })
}

fn file_name(path: &Path) -> String {
    path.file_name().map_or_else(
        || path.display().to_string(),
        |n| n.to_string_lossy().into(),
    )
}

fn load_report(path: &Path, problems: &mut Vec<String>) -> Option<Report> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) => {
            problems.push(format!("report.json: {e} (no summary figures)"));
            return None;
        }
    };
    let v: Value = match serde_json::from_str(&text) {
        Ok(v) => v,
        Err(e) => {
            problems.push(format!(
                "report.json:{}:{}: {e} (no summary figures)",
                e.line(),
                e.column()
            ));
            return None;
        }
    };
    if !v.is_object() {
        problems.push("report.json:1: not a JSON object (no summary figures)".into());
        return None;
    }
    let mut f = Fields {
        v: &v,
        problems,
        absent: Vec::new(),
    };
    let r = Report {
        outcome: f.get("outcome", |x| x.as_str().map(str::to_owned)),
        fault: f.get("fault", |x| x.as_str().map(str::to_owned)),
        program: f.get("program", |x| x.as_str().map(str::to_owned)),
        dialect: v.get("dialect").and_then(Value::as_str).map(str::to_owned),
        notes: v
            .get("notes")
            .and_then(Value::as_array)
            .map(|a| {
                a.iter()
                    .filter_map(|n| {
                        let line = n.get(0)?.as_u64()? as u32;
                        Some((line, n.get(1)?.as_str()?.to_owned()))
                    })
                    .collect()
            })
            .unwrap_or_default(),
        clock: f.get("clock", |x| x.as_str().map(str::to_owned)),
        period_ns: f.get("period_ns", Value::as_u64),
        cycles: f.get("cycles", Value::as_u64),
        misses: f.get("misses", Value::as_u64),
        wake_late_ns: f.get("wake_late_ns", pct),
        compute_ns: f.get("compute_ns", pct),
        publish_ns: f.get("publish_ns", pct),
        path_length_mm: f.get("path_length_mm", Value::as_f64),
        time_s: f.get("time_s", Value::as_f64),
        avg_feed_mm_per_min: f.get("avg_feed_mm_per_min", Value::as_f64),
        peak_feed_mm_per_min: f.get("peak_feed_mm_per_min", Value::as_f64),
        max_following_error_um: f.get("max_following_error_um", Value::as_f64),
        max_following_error_axis_um: f.get("max_following_error_axis_um", triple),
        rms_following_error_axis_um: v.get("rms_following_error_axis_um").and_then(triple),
        max_contour_error_um: v.get("max_contour_error_um").and_then(Value::as_f64),
        max_contour_error_cycle: v.get("max_contour_error_cycle").and_then(Value::as_u64),
        max_contour_error_line: v.get("max_contour_error_line").and_then(Value::as_u64),
        rms_contour_error_um: v.get("rms_contour_error_um").and_then(Value::as_f64),
        max_chord_error_um: v.get("max_chord_error_um").and_then(Value::as_f64),
        max_chord_error_line: v.get("max_chord_error_line").and_then(Value::as_u64),
        max_scallop_mm: v.get("max_scallop_mm").and_then(Value::as_f64),
        measured_max_scallop_mm: v.get("measured_max_scallop_mm").and_then(Value::as_f64),
        measured_max_scallop_at_mm: v.get("measured_max_scallop_at_mm").and_then(triple),
        roundness_um: v
            .get("roundness")
            .and_then(|r| r.get("roundness_um"))
            .and_then(Value::as_f64),
        roundness_radius_error_um: v
            .get("roundness")
            .and_then(|r| r.get("radius_error_um"))
            .and_then(Value::as_f64),
        lost_setpoints: f.get("lost_setpoints", Value::as_u64),
        blocks: f.get("blocks", Value::as_u64),
        sched: f.get("sched", |x| {
            Some(Sched {
                policy: x.get("policy")?.as_str()?.to_owned(),
                priority: x.get("priority")?.as_i64()?,
                memory_locked: x.get("memory_locked")?.as_bool()?,
                warnings: x
                    .get("warnings")?
                    .as_array()?
                    .iter()
                    .filter_map(|w| w.as_str().map(str::to_owned))
                    .collect(),
            })
        }),
        miss_list: f
            .get("miss_list", |x| {
                x.as_array()?
                    .iter()
                    .map(|m| {
                        Some(Miss {
                            cycle: m.get("cycle")?.as_u64()?,
                            line: m.get("line")?.as_u64()?,
                            cause: m.get("cause")?.as_str()?.to_owned(),
                            wake_late_ns: m.get("wake_late_ns")?.as_f64()?,
                            compute_ns: m.get("compute_ns")?.as_f64()?,
                            publish_ns: m.get("publish_ns")?.as_f64()?,
                            overrun_ns: m.get("overrun_ns")?.as_f64()?,
                            preempted_ns: m
                                .get("preempted_ns")
                                .and_then(Value::as_f64)
                                .unwrap_or(0.0),
                        })
                    })
                    .collect::<Option<Vec<_>>>()
            })
            .unwrap_or_default(),
    };
    if !f.absent.is_empty() {
        let absent = f.absent.join(", ");
        f.problems.push(format!(
            "report.json: no usable {absent} (older format?); shown as \"not recorded\""
        ));
    }
    Some(r)
}

fn triple(x: &Value) -> Option<[f64; 3]> {
    let a = x.as_array()?;
    Some([
        a.first()?.as_f64()?,
        a.get(1)?.as_f64()?,
        a.get(2)?.as_f64()?,
    ])
}

fn pct(x: &Value) -> Option<Pct> {
    Some(Pct {
        p50: x.get("p50")?.as_f64()?,
        p99: x.get("p99")?.as_f64()?,
        max: x.get("max")?.as_f64()?,
    })
}

/// Reads fields of the report, collecting the names of those absent or malformed (null is
/// a value: "not measured").
struct Fields<'a> {
    v: &'a Value,
    problems: &'a mut Vec<String>,
    absent: Vec<&'static str>,
}

impl Fields<'_> {
    fn get<T>(&mut self, key: &'static str, conv: impl Fn(&Value) -> Option<T>) -> Option<T> {
        match self.v.get(key) {
            Some(Value::Null) => None,
            Some(x) => {
                let out = conv(x);
                if out.is_none() {
                    self.absent.push(key);
                }
                out
            }
            None => {
                self.absent.push(key);
                None
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::parse_f64;

    /// The fast path gives exactly what `str::parse` gives, and the rest goes to it.
    #[test]
    fn parse_f64_is_str_parse() {
        let cases = [
            "0",
            "-0",
            "-0.000000",
            "3",
            "1.",
            ".5",
            "10.000000",
            "-9.999999",
            "0.1",
            "0.3",
            "123456.789012",
            "9007199254740993",
            "1e-3",
            "-2.5E2",
            "inf",
            "NaN",
            "",
            "-",
            ".",
            "1.2.3",
            "+1",
            " 1",
            "0.0000000000000000000001",
            "999999999999999",
            "1234567890123456",
            "0.30000000000000004",
            "-7.071068",
        ];
        for c in cases {
            let want = c.parse::<f64>().ok();
            let got = parse_f64(c);
            assert_eq!(
                got.map(f64::to_bits),
                want.map(f64::to_bits),
                "{c:?}: {got:?} vs {want:?}"
            );
        }
        // Every 6-decimal number the traces hold, over a range.
        for k in -2_000_000i64..2_000_000 {
            let s = format!("{:.6}", k as f64 * 7.123e-4);
            assert_eq!(
                parse_f64(&s).map(f64::to_bits),
                s.parse::<f64>().ok().map(f64::to_bits),
                "{s}"
            );
        }
    }
}
