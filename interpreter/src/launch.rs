//! `cnc run`: check the program, start the three processes (this same executable in each
//! role), supervise them, and fold their summaries into `report.json`.
//!
//! If one process fails, the others are stopped at once: a control never keeps moving
//! with a dead peer. The servo-sim starts first, then the interpolator, then the
//! interpreter, so every consumer exists before its producer sends.

use crate::process::{self, Source};
use crate::report::{self, Process};
use shared::clock::ClockMode;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Set by SIGINT/SIGTERM: the operator wants the run stopped.
static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_interrupt(_signal: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// Catch Ctrl-C and SIGTERM so the launcher outlives its children and still writes the
/// report. A handler (unlike "ignore") is reset by exec, so the children keep the default.
fn catch_interrupts() {
    let handler = on_interrupt as extern "C" fn(libc::c_int);
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGINT, handler as libc::sighandler_t);
        libc::signal(libc::SIGTERM, handler as libc::sighandler_t);
    }
}

#[derive(Debug, Clone, clap::Args)]
pub struct RunArgs {
    /// The NC program (RS274/NGC with LinuxCNC G5.2 NURBS); the built-in demo when absent.
    pub program: Option<PathBuf>,
    /// Run directory [default: runs/<UTC timestamp>/].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Interpolation period in µs (100..=10000).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(100..=10_000))]
    pub period_us: u64,
    /// Machine file (TOML); see `cnc machine` for the built-in default.
    #[arg(long)]
    pub machine: Option<PathBuf>,
    /// `real`: cycles on wall time, timing measured. `sim`: the same set-points as fast as
    /// the processes go (machining-time estimates, tests); timing not measured.
    #[arg(long, default_value_t = ClockMode::Real)]
    pub clock: ClockMode,
    /// Scheduling of the interpolator: `auto` tries SCHED_FIFO and falls back with a warning.
    #[arg(long, value_enum, default_value_t = interpolator::rt::sched::SchedMode::Auto)]
    pub sched: interpolator::rt::sched::SchedMode,
    /// Do not write report.html at the end (see `cnc report`).
    #[arg(long)]
    pub no_report: bool,
}

/// `YYYYMMDDTHHMMSSZ` for a Unix time (UTC, proleptic Gregorian).
pub fn utc_stamp(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // Civil-from-days (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!(
        "{y:04}{m:02}{d:02}T{:02}{:02}{:02}Z",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

pub fn default_out_dir() -> PathBuf {
    let secs = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    let base = PathBuf::from("runs").join(utc_stamp(secs));
    let mut dir = base.clone();
    let mut n = 1;
    while dir.exists() {
        dir = PathBuf::from(format!("{}-{n}", base.display()));
        n += 1;
    }
    dir
}

struct Role {
    name: &'static str,
    child: Child,
    exit: Option<std::process::ExitStatus>,
}

fn exit_text(s: Option<std::process::ExitStatus>) -> String {
    use std::os::unix::process::ExitStatusExt;
    match s {
        None => "killed by the launcher".into(),
        Some(s) => match (s.code(), s.signal()) {
            (Some(c), _) => format!("exit {c}"),
            (None, Some(sig)) => format!("signal {sig}"),
            _ => "unknown".into(),
        },
    }
}

fn spawn(exe: &Path, role: &str, args: &[String]) -> std::io::Result<Child> {
    Command::new(exe)
        .arg("role")
        .arg(role)
        .args(args)
        .stdin(Stdio::null())
        .spawn()
}

/// Runs a program end to end. Exit code 0 when it completed, 1 otherwise.
pub fn run(args: &RunArgs) -> ExitCode {
    match run_inner(args) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("cnc run: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run_inner(args: &RunArgs) -> Result<bool, String> {
    let machine = shared::machine::load(args.machine.as_deref())?;
    let src = Source::load(args.program.as_deref())?;
    let period_ns = args.period_us * 1000;
    // Bad input is rejected before any process starts, let alone any motion.
    if let Err(diags) = process::compile(&src.text, &machine, period_ns) {
        eprint!("{}", process::format_diagnostics(&src.name, &diags));
        return Ok(false);
    }
    let dir = args.out.clone().unwrap_or_else(default_out_dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    // The run directory keeps the exact program and machine it ran.
    let program_copy = dir.join("program.ngc");
    std::fs::write(&program_copy, &src.text)
        .map_err(|e| format!("{}: {e}", program_copy.display()))?;
    let input = vec![
        "--program".into(),
        program_copy.display().to_string(),
        "--program-name".into(),
        src.name.clone(),
    ];
    let stack = Stack {
        dir,
        machine,
        period_ns,
        clock: args.clock,
        sched: args.sched,
        html: !args.no_report,
    };
    stack.launch(&src.name, input)
}

/// Everything `cnc run` and `cnc replay` share: a run directory, a machine, a period, a
/// clock, and the three processes to start and watch.
pub struct Stack {
    pub dir: PathBuf,
    pub machine: shared::Machine,
    pub period_ns: u64,
    pub clock: ClockMode,
    pub sched: interpolator::rt::sched::SchedMode,
    /// Write report.html after report.json (after every process has ended, so it never
    /// touches a cycle).
    pub html: bool,
}

impl Stack {
    /// Starts the processes (the interpreter with `input`, its program or log arguments),
    /// supervises them, writes `report.json` and prints the summary. `Ok(true)` when the
    /// program completed.
    pub fn launch(&self, program_name: &str, input: Vec<String>) -> Result<bool, String> {
        let dir = &self.dir;
        let machine_copy = dir.join("machine.toml");
        std::fs::write(&machine_copy, toml_of(&self.machine))
            .map_err(|e| format!("{}: {e}", machine_copy.display()))?;
        let exe =
            std::env::current_exe().map_err(|e| format!("cannot find my own executable: {e}"))?;
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let prefix = format!("cnc{}_{nanos}", std::process::id());
        let common = vec![
            "--prefix".to_string(),
            prefix,
            "--out".into(),
            dir.display().to_string(),
            "--period-us".into(),
            (self.period_ns / 1000).to_string(),
            "--machine".into(),
            machine_copy.display().to_string(),
            "--clock".into(),
            self.clock.to_string(),
        ];
        catch_interrupts();
        let mut roles: Vec<Role> = Vec::new();
        let mut start = |name: &'static str, extra: Vec<String>| -> Result<(), String> {
            let mut a = common.clone();
            a.extend(extra);
            let child = spawn(&exe, name, &a).map_err(|e| format!("starting the {name}: {e}"))?;
            roles.push(Role {
                name,
                child,
                exit: None,
            });
            Ok(())
        };
        let sched = match self.sched {
            interpolator::rt::sched::SchedMode::Auto => "auto",
            interpolator::rt::sched::SchedMode::Other => "other",
        };
        let started = start("servo-sim", vec![])
            .and_then(|_| start("interpolator", vec!["--sched".into(), sched.into()]))
            .and_then(|_| start("interpreter", input));
        let mut launcher_fault = started.err();
        if launcher_fault.is_none() {
            launcher_fault = supervise(&mut roles);
        } else {
            stop_all(&mut roles);
        }
        let processes = roles
            .iter()
            .map(|r| Process {
                role: r.name.into(),
                pid: r.child.id(),
                exit: exit_text(r.exit),
            })
            .collect();
        let rep = report::assemble(
            dir,
            program_name,
            self.clock,
            self.period_ns,
            processes,
            launcher_fault,
        );
        rep.write(&dir.join("report.json"))
            .map_err(|e| format!("writing report.json: {e}"))?;
        print!("{}", rep.summary_text(dir));
        if self.html {
            match crate::html::write(dir, None) {
                Ok(page) => println!("  report page  {}", page.display()),
                Err(e) => eprintln!("cnc: report.html not written: {e}"),
            }
        }
        Ok(rep.outcome == "done")
    }
}

fn toml_of(m: &shared::Machine) -> String {
    format!(
        "# the machine this run used\n{}",
        shared::Machine::to_toml(m)
    )
}

/// Asks every live process to stop (SIGTERM: each holds position, writes its summary and
/// exits), then kills whatever is still there after a grace period.
fn stop_all(roles: &mut [Role]) {
    for r in roles.iter().filter(|r| r.exit.is_none()) {
        // SAFETY: plain kill(2) on a child we started and have not reaped.
        unsafe { libc::kill(r.child.id() as libc::pid_t, libc::SIGTERM) };
    }
    let deadline = Instant::now() + Duration::from_secs(3);
    while Instant::now() < deadline && roles.iter().any(|r| r.exit.is_none()) {
        for r in roles.iter_mut().filter(|r| r.exit.is_none()) {
            if let Ok(Some(status)) = r.child.try_wait() {
                r.exit = Some(status);
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    for r in roles.iter_mut().filter(|r| r.exit.is_none()) {
        let _ = r.child.kill();
        r.exit = r.child.wait().ok();
    }
}

/// Waits for all processes; the first failure stops the others. Returns the failure.
fn supervise(roles: &mut [Role]) -> Option<String> {
    let mut fault = None;
    let mut last_exit: Option<Instant> = None;
    loop {
        for r in roles.iter_mut().filter(|r| r.exit.is_none()) {
            if let Ok(Some(status)) = r.child.try_wait() {
                r.exit = Some(status);
                last_exit = Some(Instant::now());
                if !status.success() && fault.is_none() {
                    fault = Some(format!("{} failed ({})", r.name, exit_text(Some(status))));
                }
            }
        }
        if roles.iter().all(|r| r.exit.is_some()) {
            return fault;
        }
        if INTERRUPTED.load(Ordering::SeqCst) {
            stop_all(roles);
            return Some(
                "interrupted by the operator (SIGINT/SIGTERM); all processes stopped".into(),
            );
        }
        // A failure stops the rest; after a clean exit the others get a grace period to
        // finish their part of the shutdown handshake.
        let overdue = last_exit.is_some_and(|t| t.elapsed() > Duration::from_secs(10));
        if fault.is_some() || overdue {
            if fault.is_none() {
                fault = Some("a process did not finish after its peers had".into());
            }
            stop_all(roles);
            return fault;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn utc_stamps() {
        assert_eq!(super::utc_stamp(0), "19700101T000000Z");
        assert_eq!(super::utc_stamp(1_795_381_520), "20261122T210520Z");
        assert_eq!(super::utc_stamp(951_782_400), "20000229T000000Z");
    }
}
