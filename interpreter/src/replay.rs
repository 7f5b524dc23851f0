//! `cnc replay` and `cnc log show`: the command log used without the NC program.
//!
//! A replay streams the logged blocks, byte for byte, through a fresh stack. The blocks,
//! the period (from the log's header) and the machine file (its hash must match the
//! header's) fully determine the set-points and, under the lock-step servo, the feedback:
//! so a replay reproduces the original `setpoints.csv` and `feedback.csv` exactly.

use crate::launch::{default_out_dir, Stack};
use serde::Serialize;
use shared::clock::ClockMode;
use shared::protocol::{BlockKind, CommandBlock, FLAG_RAPID, NO_AXIS};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

#[derive(Debug, Clone, clap::Args)]
pub struct ReplayArgs {
    /// A run directory (its commands.log and machine.toml are used) or a commands.log.
    pub source: PathBuf,
    /// Run directory for the replay [default: runs/<UTC timestamp>/]. It must be new or
    /// empty, unless --force.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Reuse a non-empty --out: the earlier run's files there are removed first (other
    /// files are kept). The source run directory itself is never reused.
    #[arg(long)]
    pub force: bool,
    /// Machine file; default: the machine.toml beside the log, else the built-in machine.
    /// It must be the machine the log was written with (its hash is in the header).
    #[arg(long)]
    pub machine: Option<PathBuf>,
    /// `real` or `sim` (see `cnc run --help`).
    #[arg(long, default_value_t = ClockMode::Real)]
    pub clock: ClockMode,
    /// Replay the intact blocks of a damaged log, then stop there.
    #[arg(long)]
    pub salvage: bool,
    /// Scheduling of the interpolator.
    #[arg(long, value_enum, default_value_t = interpolator::rt::sched::SchedMode::Auto)]
    pub sched: interpolator::rt::sched::SchedMode,
    /// SCHED_FIFO priority of the interpolator's cycle thread (1..=99) when it gets
    /// real-time scheduling; above most kernel threads and IRQ threads (50) by default.
    #[arg(long, default_value_t = interpolator::rt::sched::DEFAULT_PRIORITY, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: i32,
    /// Do not write report.html at the end.
    #[arg(long)]
    pub no_report: bool,
}

/// The log file of a run directory, or the file itself.
fn log_path(source: &Path) -> PathBuf {
    if source.is_dir() {
        source.join("commands.log")
    } else {
        source.to_path_buf()
    }
}

pub fn replay(args: &ReplayArgs) -> ExitCode {
    match replay_inner(args) {
        Ok(true) => ExitCode::SUCCESS,
        // 130/143 when the operator stopped it, as `cnc run`.
        Ok(false) => crate::launch::failure_code(),
        Err(e) => {
            eprintln!("cnc replay: {e}");
            ExitCode::FAILURE
        }
    }
}

fn replay_inner(args: &ReplayArgs) -> Result<bool, String> {
    let log = log_path(&args.source);
    // Refuse a damaged log (or announce the salvage) before anything starts.
    let header = crate::process::load_replay(&log, args.salvage)?.header;
    let beside = log
        .parent()
        .map(|d| d.join("machine.toml"))
        .filter(|p| p.exists());
    let machine_file = args.machine.clone().or(beside);
    let machine = shared::machine::load(machine_file.as_deref())?;
    shared::machine::log_in_force("cnc replay", machine_file.as_deref(), &machine);
    if machine.hash() != header.machine_hash {
        return Err(format!(
            "{}: written with another machine file (hash {:016x}, this one is {:016x}{}); pass --machine with the original run's machine.toml",
            log.display(),
            header.machine_hash,
            machine.hash(),
            machine_file.map(|p| format!(", {}", p.display())).unwrap_or_else(|| ", the built-in machine".into())
        ));
    }
    if !(100_000..=10_000_000).contains(&header.period_ns) || header.period_ns % 1000 != 0 {
        return Err(format!(
            "{}: period of {} ns is not a whole number of µs in 100..=10000 µs",
            log.display(),
            header.period_ns
        ));
    }
    let dir = args.out.clone().unwrap_or_else(default_out_dir);
    // Replaying into the directory the log is read from would remove the log itself.
    let same = |a: &Path, b: &Path| match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if let Some(src_dir) = log.parent().filter(|d| same(d, &dir)) {
        return Err(format!(
            "--out {}: that is the run directory being replayed ({}); choose another --out",
            dir.display(),
            src_dir.display()
        ));
    }
    crate::rundir::prepare(&dir, args.force)?;
    let mut input = vec!["--replay".to_string(), log.display().to_string()];
    if args.salvage {
        input.push("--salvage".into());
    }
    let expected_cycles = if crate::launch::progress_wanted() {
        let blocks = crate::process::load_replay(&log, args.salvage)?.blocks;
        crate::launch::expected_cycles(blocks.into_iter(), &machine, header.period_ns)
    } else {
        None
    };
    let stack = Stack {
        dir,
        machine,
        period_ns: header.period_ns,
        clock: args.clock,
        sched: args.sched,
        rt_priority: args.rt_priority,
        html: !args.no_report,
        expected_cycles,
        // A replay reproduces a run bit for bit: lock-step.
        servo_clock: servo_sim::run::ServoClock::Lockstep,
    };
    stack.launch(&header.program, input)
}

/// One block of a log, as `cnc log show --json` prints it.
#[derive(Debug, Clone, Serialize)]
pub struct BlockView {
    pub seq: u64,
    pub kind: &'static str,
    pub line: u32,
    pub rapid: bool,
    pub degree: u32,
    pub knots: Vec<f64>,
    /// `[x, y, z, w]` in mm.
    pub ctrl: Vec<[f64; 4]>,
    pub helix_axis: Option<u32>,
    pub feed_mm_per_min: f64,
    pub start_feed_mm_per_min: f64,
    pub end_feed_mm_per_min: f64,
    pub length_mm: f64,
    pub dwell_ns: u64,
}

impl From<&CommandBlock> for BlockView {
    fn from(b: &CommandBlock) -> Self {
        BlockView {
            seq: b.seq,
            kind: b.kind().map_or("?", BlockKind::name),
            line: b.source_line,
            rapid: b.flags & FLAG_RAPID != 0,
            degree: b.degree,
            knots: b.knots().to_vec(),
            ctrl: b.ctrl().to_vec(),
            helix_axis: (b.helix.axis != NO_AXIS).then_some(b.helix.axis),
            feed_mm_per_min: b.feed_mm_per_min,
            start_feed_mm_per_min: b.start_feed_mm_per_min,
            end_feed_mm_per_min: b.end_feed_mm_per_min,
            length_mm: b.length_mm,
            dwell_ns: b.dwell_ns,
        }
    }
}

/// A number as a person reads it in `cnc log show`: at most six decimals (a nanometre in
/// mm), no trailing zeros. (`--json` keeps every bit.)
fn short(v: f64) -> String {
    let s = format!("{v:.6}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}

fn line_of(b: &CommandBlock) -> String {
    let kind = b.kind().map_or("?", BlockKind::name);
    match b.kind() {
        Some(BlockKind::Motion) => {
            let pts: Vec<String> = b
                .ctrl()
                .iter()
                .map(|c| {
                    format!(
                        "({} {} {} w{})",
                        short(c[0]),
                        short(c[1]),
                        short(c[2]),
                        short(c[3])
                    )
                })
                .collect();
            format!(
                "{:>6} {}{} source line {} degree {} feed {} mm/min ({} -> {}) length {} mm{} ctrl {}",
                b.seq,
                kind,
                if b.flags & FLAG_RAPID != 0 { " rapid" } else { "" },
                b.source_line,
                b.degree,
                short(b.feed_mm_per_min),
                short(b.start_feed_mm_per_min),
                short(b.end_feed_mm_per_min),
                short(b.length_mm),
                if b.helix.axis != NO_AXIS { " helix" } else { "" },
                pts.join(" ")
            )
        }
        Some(BlockKind::Dwell) => format!(
            "{:>6} {kind} source line {} {} s",
            b.seq,
            b.source_line,
            short(b.dwell_ns as f64 * 1e-9)
        ),
        _ => format!("{:>6} {kind} source line {}", b.seq, b.source_line),
    }
}

/// `cnc log show`: every intact block, then the damage (if any) on stderr with exit 1.
pub fn show(source: &Path, json: bool) -> ExitCode {
    let log = log_path(source);
    let parsed = match shared::cmdlog::read(&log) {
        Ok(p) => p,
        Err(e) => {
            eprintln!("cnc log show: {e}");
            return ExitCode::FAILURE;
        }
    };
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if json {
        let views: Vec<BlockView> = parsed.blocks.iter().map(BlockView::from).collect();
        let doc = serde_json::json!({
            "program": parsed.header.program,
            "period_ns": parsed.header.period_ns,
            "machine_hash": format!("{:016x}", parsed.header.machine_hash),
            "protocol_version": parsed.header.protocol_version,
            "blocks": views,
            "damage": parsed.damage.as_ref().map(|d| d.to_string()),
        });
        let _ = writeln!(
            out,
            "{}",
            serde_json::to_string_pretty(&doc).unwrap_or_default()
        );
    } else {
        let _ = writeln!(
            out,
            "# {}: program {}, period {} ns, machine {:016x}, protocol {}",
            log.display(),
            parsed.header.program,
            parsed.header.period_ns,
            parsed.header.machine_hash,
            parsed.header.protocol_version
        );
        for b in &parsed.blocks {
            // A closed pipe (`| head`) ends the listing quietly.
            if writeln!(out, "{}", line_of(b)).is_err() {
                break;
            }
        }
    }
    match parsed.damage {
        Some(d) => {
            eprintln!("cnc log show: {}: {d}", log.display());
            ExitCode::FAILURE
        }
        None => ExitCode::SUCCESS,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `cnc log show` names the source line as such and prints numbers as a person reads
    /// them: a dwell in seconds, a coordinate to a nanometre without trailing zeros.
    #[test]
    fn log_lines_say_source_line_and_round_sensibly() {
        let mut d = CommandBlock::empty(BlockKind::Dwell, 7, 12);
        d.dwell_ns = 1_500_000_000;
        assert_eq!(line_of(&d), "     7 dwell source line 12 1.5 s");
        assert_eq!(short(20.000000003333), "20");
        assert_eq!(short(-0.0000001), "0");
        assert_eq!(short(1828.7999999999997), "1828.8");
        assert_eq!(short(0.125), "0.125");
    }
}
