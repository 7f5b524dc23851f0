//! Loading a run directory for the page, leniently.
//!
//! Every file is optional: what cannot be read becomes a *problem* (`file:line: message`)
//! that the page lists, and the loader keeps whatever came before the damage (a CSV cut
//! off mid-row by a crash still plots up to its last whole row). `report.json` is read
//! field by field from a JSON value rather than into the launcher's `Report` type, so a
//! report from an older or newer format still gives every figure it has, and an absent
//! figure is named instead of failing the whole page.

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
    pub roundness_um: Option<f64>,
    pub roundness_radius_error_um: Option<f64>,
    pub lost_setpoints: Option<u64>,
    pub blocks: Option<u64>,
    pub sched: Option<Sched>,
    pub miss_list: Vec<Miss>,
}

/// `setpoints.csv` as columns.
#[derive(Debug, Clone, Default)]
pub struct Setpoints {
    pub cycle: Vec<u64>,
    pub pos_mm: Vec<[f64; 3]>,
    pub line: Vec<u32>,
}

/// `feedback.csv` as columns (following error kept as `f32` µm: plenty for a plot, and a
/// third less memory on a one-hour run).
#[derive(Debug, Clone, Default)]
pub struct Feedback {
    pub cycle: Vec<u64>,
    pub pos_mm: Vec<[f64; 3]>,
    pub ferr_um: Vec<[f32; 3]>,
}

/// Everything the page draws from.
#[derive(Debug, Clone)]
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
        let setpoints = load_csv(
            &dir.join("setpoints.csv"),
            &["cycle", "x_mm", "y_mm", "z_mm", "line"],
            &mut problems,
        )
        .map(|rows| {
            let mut s = Setpoints::default();
            for r in rows.chunks_exact(5) {
                s.cycle.push(r[0] as u64);
                s.pos_mm.push([r[1], r[2], r[3]]);
                s.line.push(r[4] as u32);
            }
            s
        });
        let feedback = load_csv(
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
        )
        .map(|rows| {
            let mut f = Feedback::default();
            for r in rows.chunks_exact(7) {
                f.cycle.push(r[0] as u64);
                f.pos_mm.push([r[1], r[2], r[3]]);
                f.ferr_um.push([r[4] as f32, r[5] as f32, r[6] as f32]);
            }
            f
        });
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
            let rows = |c: &Vec<u64>| c.len() as u64;
            if let Some(s) = &setpoints {
                if rows(&s.cycle) < cycles {
                    problems.push(format!(
                        "setpoints.csv: {} rows for the {cycles} cycles of report.json (file cut short?)",
                        rows(&s.cycle)
                    ));
                }
            }
            if let Some(f) = &feedback {
                if rows(&f.cycle) + lost < cycles {
                    problems.push(format!(
                        "feedback.csv: {} rows for the {cycles} cycles of report.json ({lost} set-points lost; file cut short?)",
                        rows(&f.cycle)
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

/// Reads the named columns of a CSV file. Stops at the first bad row (recording a problem
/// naming file and line) and returns the rows before it, flat (`want.len()` values per
/// row); `None` when the file or its header is unusable.
fn load_csv(path: &Path, want: &[&str], problems: &mut Vec<String>) -> Option<Vec<f64>> {
    let name = file_name(path);
    let f = match File::open(path) {
        Ok(f) => f,
        Err(e) => {
            problems.push(format!("{name}: {e}"));
            return None;
        }
    };
    let mut reader = BufReader::new(f);
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
    // One reused line buffer and cell list, a flat output: a one-hour file has 3.6
    // million rows, so no allocation per row.
    let mut rows: Vec<f64> = Vec::new();
    let mut buf = String::new();
    let mut cells: Vec<(usize, usize)> = Vec::with_capacity(cols.len() + 1);
    let mut row = Vec::with_capacity(want.len());
    for lineno in 2.. {
        buf.clear();
        match reader.read_line(&mut buf) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) => {
                problems.push(format!("{name}:{lineno}: {e}; rows from here on not drawn"));
                break;
            }
        }
        let l = buf.trim();
        if l.is_empty() {
            continue;
        }
        cells.clear();
        let mut at = 0;
        for part in l.split(',') {
            cells.push((at, at + part.len()));
            at += part.len() + 1;
        }
        if cells.len() != cols.len() {
            problems.push(format!(
                "{name}:{lineno}: {} of {} columns (row cut off?); rows from here on not drawn",
                cells.len(),
                cols.len()
            ));
            break;
        }
        row.clear();
        for &c in &idx {
            let (a, b) = cells[c];
            match l[a..b].parse::<f64>() {
                Ok(v) if v.is_finite() => row.push(v),
                _ => break,
            }
        }
        if row.len() != want.len() {
            let bad = want[row.len()];
            let (a, b) = cells[idx[row.len()]];
            problems.push(format!(
                "{name}:{lineno}: column `{bad}`: `{}` is not a number; rows from here on not drawn",
                &l[a..b]
            ));
            break;
        }
        rows.extend_from_slice(&row);
    }
    if rows.is_empty() {
        problems.push(format!("{name}: no data rows"));
        return None;
    }
    Some(rows)
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
