//! `cnc run`: check the program, start the three processes (this same executable in each
//! role), supervise them, and fold their summaries into `report.json`.
//!
//! If one process fails, the others stop too: a control never keeps moving with a dead
//! peer. Each survivor notices a dead peer by itself (iceoryx2 liveness, within a few
//! periods) and stops its own way: the interpolator decelerates along the path, the drives
//! hold position. The launcher gives them [`SURVIVOR_GRACE`] to do so and to write their
//! summaries, then asks any that are left to stop (SIGTERM, and SIGCONT for a suspended
//! one), and kills what is still there after that. The report names the first fault: an
//! operator's stop, a suspended process, a process that died and the cycle it died at,
//! else the fault the processes' own summaries give. The servo-sim starts first, then the
//! interpolator, then the interpreter, so every consumer exists before its producer sends.
//!
//! The operator's Ctrl-C (SIGINT) or SIGTERM is passed on to the interpolator alone: it
//! brakes on the path, the drives follow it to its last set-point, then all exit, and
//! `cnc run` exits 128 + the signal (130, 143). Each process is started with the kernel's
//! parent-death signal ([`shared::stop::die_with_parent`]): should the launcher itself
//! die, the interpolator brakes on the path, the others follow, and the interpreter (the
//! last to finish) writes `report.json` in its place. Nothing is printed with `print!`:
//! a closed stdout or stderr (`cnc run | head -1`) must not stop the run or its reports.

use crate::process::{self, Source};
use crate::report::{self, Process};
use serde::{Deserialize, Serialize};
use shared::clock::ClockMode;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::sync::atomic::{AtomicI32, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Set by SIGINT/SIGTERM: the operator wants the run stopped (the first signal; 0: none).
static INTERRUPTED: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_interrupt(signal: libc::c_int) {
    let _ = INTERRUPTED.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
}

/// The signal the operator stopped the run with (SIGINT, SIGTERM), if any.
pub fn interrupted() -> Option<i32> {
    Some(INTERRUPTED.load(Ordering::SeqCst)).filter(|s| *s != 0)
}

/// How long after the operator's stop the processes get to brake, follow and write their
/// summaries before the launcher stops what is left.
pub const OPERATOR_STOP_GRACE: Duration = Duration::from_secs(10);

/// Writes to stdout, quietly: a closed pipe (`cnc run | head -1`) or a full disk must not
/// stop the run or keep its reports from being written.
pub fn say(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = out.write_all(text.as_bytes());
    let _ = out.flush();
}

/// [`say`] on stderr.
pub fn say_err(text: &str) {
    use std::io::Write;
    let _ = std::io::stderr().write_all(text.as_bytes());
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
    /// The NC program (RS274/NGC with LinuxCNC's G5.2/G6.2 NURBS, or Fanuc's G06.2), or a
    /// STEP-NC part (`.stp`, `.step`, `.p21`: ISO 14649 free-form workingsteps); the
    /// built-in demo when absent.
    pub program: Option<PathBuf>,
    /// Run directory [default: runs/<UTC timestamp>/]. It must be new or empty, unless
    /// --force.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Reuse a non-empty --out: the earlier run's files there are removed first (other
    /// files are kept).
    #[arg(long)]
    pub force: bool,
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
    /// SCHED_FIFO priority of the interpolator's cycle thread (1..=99) when it gets
    /// real-time scheduling; above most kernel threads and IRQ threads (50) by default.
    #[arg(long, default_value_t = interpolator::rt::sched::DEFAULT_PRIORITY, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: i32,
    /// Do not write report.html at the end (see `cnc report`).
    #[arg(long)]
    pub no_report: bool,
    /// Who paces the drives: `lockstep` (default: one drive step per set-point,
    /// deterministic, what replay reproduces) or `own` (the servo-sim keeps its own period
    /// like real drives; a late or missing set-point is held, and the report counts the
    /// held ticks). `own` needs `--clock real`.
    #[arg(long, value_enum, default_value_t = servo_sim::run::ServoClock::Lockstep)]
    pub servo_clock: servo_sim::run::ServoClock,
    /// Run the program N times in one stack (soak test): one stream of blocks whose
    /// sequence numbers keep counting, with a rapid back to the start between runs when
    /// the program ends elsewhere. report.json has each process's memory at start and end.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub repeat: u32,
    /// Test aid: the interpreter waits this many ms before each block (starves the
    /// interpolator on purpose).
    #[arg(long, hide = true)]
    pub throttle_ms: Option<u64>,
    /// Read the program as `linuxcnc` or `fanuc` instead of detecting the dialect from
    /// its codes (G5.x/G6.2 with Q: LinuxCNC; G06.2, G05 P10000: Fanuc).
    #[arg(long)]
    pub dialect: Option<crate::program::Dialect>,
    /// A directory to look for subroutine files in (`o<name> call` of a subroutine the
    /// program does not define reads `name.ngc`), after the program's own directory;
    /// may be given more than once.
    #[arg(long)]
    pub subroutine_path: Vec<PathBuf>,
    /// The tool table `G41`/`G42` take the cutter's radius from: LinuxCNC's `.tbl`
    /// format (`T1 P1 D6.0 Z0 ;6 mm end mill`, diameters in mm). `G41.1`/`G42.1 D…`
    /// (the diameter on the line) need none. The run directory keeps a copy.
    #[arg(long, value_name = "FILE")]
    pub tool_table: Option<PathBuf>,
    /// Allow what the dialect's own control refuses; may be given more than once.
    /// `g06.2-comp`: a Fanuc `G06.2` NURBS under cutter compensation (`G41`/`G42`) is
    /// offset as a LinuxCNC `G5.2`/`G6.2` is (fitted within the chord tolerance),
    /// instead of Fanuc's alarm PS1006.
    #[arg(long = "dialect-extension", value_name = "NAME")]
    pub extensions: Vec<crate::program::dialect::Extension>,
}

/// How long the survivors of a failed process get to stop by themselves.
pub const SURVIVOR_GRACE: Duration = Duration::from_secs(3);

/// A process that died (killed by a signal from outside the stack), for the report.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct DeadProcess {
    pub role: String,
    pub pid: u32,
    /// The signal, in words (`signal 9`).
    pub exit: String,
    /// The cycle it died at: for the servo-sim or the interpreter, the interpolator cycle
    /// in which its death was noticed; for the interpolator, its last set-point (the last
    /// cycle the drives answered).
    pub cycle: Option<u64>,
    /// How the cycle was found, in words.
    pub detail: String,
}

/// A process's resident memory (VmRSS) as the launcher sampled it every 100 ms.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ProcessMemory {
    pub role: String,
    pub pid: u32,
    /// The first sample after the process had run for a second (its set-up done), or its
    /// first sample if it ran for less.
    pub start_kib: u64,
    /// The last sample before it ended.
    pub end_kib: u64,
    pub max_kib: u64,
    pub samples: u64,
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
    /// The launcher had to stop it (SIGTERM, then SIGKILL).
    stopped: bool,
    spawned: Instant,
    memory: Option<ProcessMemory>,
    start_settled: bool,
    /// Seen suspended (state `T`: SIGSTOP, Ctrl-Z) while the launcher watched, and when.
    suspended_at: Option<Instant>,
}

/// Whether a live process is suspended (state `T` in /proc: SIGSTOP, SIGTSTP).
fn is_suspended(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .ok()
        .and_then(|s| {
            let after = &s[s.rfind(')')? + 1..];
            after.split_whitespace().next().map(|st| st == "T")
        })
        .unwrap_or(false)
}

/// VmRSS of a live process in KiB, from /proc.
fn rss_kib(pid: u32) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with("VmRSS:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

impl Role {
    fn new(name: &'static str, child: Child) -> Role {
        Role {
            name,
            child,
            exit: None,
            stopped: false,
            spawned: Instant::now(),
            memory: None,
            start_settled: false,
            suspended_at: None,
        }
    }

    fn sample_memory(&mut self) {
        let Some(kib) = rss_kib(self.child.id()) else {
            return;
        };
        let m = self.memory.get_or_insert(ProcessMemory {
            role: self.name.into(),
            pid: self.child.id(),
            start_kib: kib,
            end_kib: kib,
            max_kib: kib,
            samples: 0,
        });
        // The start figure is the first sample after set-up (iceoryx2, rings, mlock).
        if !self.start_settled && self.spawned.elapsed() >= Duration::from_secs(1) {
            self.start_settled = true;
            m.start_kib = kib;
        }
        m.end_kib = kib;
        m.max_kib = m.max_kib.max(kib);
        m.samples += 1;
    }
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

/// The exit code of a run that did not complete: 128 + the signal when the operator
/// stopped it (130 for Ctrl-C, 143 for SIGTERM, the shell's convention), else 1. For
/// `cnc run` and whatever else launches a [`Stack`] (`cnc replay`).
pub fn failure_code() -> ExitCode {
    match interrupted() {
        Some(sig) => ExitCode::from((128 + sig).clamp(0, 255) as u8),
        None => ExitCode::FAILURE,
    }
}

/// Starts `exe` in `role`. The child asks the kernel for the launcher's death signal
/// right after the fork (see [`shared::stop::die_with_parent`]); it is spawned from the
/// launcher's main thread, which lives until the run is over (the parent-death signal
/// follows the thread that forked, not the process).
fn spawn(exe: &Path, role: &str, args: &[String]) -> std::io::Result<Child> {
    use std::os::unix::process::CommandExt;
    let launcher = std::process::id() as libc::pid_t;
    let mut cmd = Command::new(exe);
    cmd.arg("role").arg(role).args(args).stdin(Stdio::null());
    // SAFETY: the closure runs between fork and exec and makes only async-signal-safe
    // calls (prctl, getppid), allocating nothing.
    unsafe {
        cmd.pre_exec(move || shared::stop::die_with_parent(launcher));
    }
    cmd.spawn()
}

/// Runs a program end to end. Exit code 0 when it completed, 128 + the signal when the
/// operator stopped it (130 for Ctrl-C, 143 for SIGTERM), 1 otherwise.
pub fn run(args: &RunArgs) -> ExitCode {
    match run_inner(args) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => failure_code(),
        Err(e) => {
            say_err(&format!("cnc run: {e}\n"));
            ExitCode::FAILURE
        }
    }
}

fn run_inner(args: &RunArgs) -> Result<bool, String> {
    if args.servo_clock == servo_sim::run::ServoClock::Own && args.clock == ClockMode::Sim {
        return Err(
            "--servo-clock own needs --clock real: under the simulated clock no set-point is ever late"
                .into(),
        );
    }
    let machine = shared::machine::load(args.machine.as_deref())?;
    shared::machine::log_in_force("cnc run", args.machine.as_deref(), &machine);
    machine.check_period(args.period_us)?;
    // A regular file is mapped, not read into memory (see `crate::mapped`), and checked
    // window by window: a program of any length is never held whole here.
    let mapped = args
        .program
        .as_deref()
        .and_then(crate::mapped::MappedText::open);
    let src = match (&mapped, args.program.as_deref()) {
        (Some(_), Some(p)) => Source {
            name: p.display().to_string(),
            text: String::new(),
        },
        _ => Source::load(args.program.as_deref())?,
    };
    let text = mapped.as_ref().map_or(src.text.as_str(), |m| m.as_str());
    let period_ns = args.period_us * 1000;
    // Bad input is rejected before any process starts, let alone any motion.
    // Subroutine files are looked for beside the program first, as LinuxCNC looks in
    // the directory of the program it opened, then in each `--subroutine-path`. The
    // interpreter process reads the run directory's copy, so it is told where they are.
    let beside = args
        .program
        .as_deref()
        .and_then(std::path::Path::parent)
        .map(|d| {
            if d.as_os_str().is_empty() {
                std::path::Path::new(".")
            } else {
                d
            }
        })
        .and_then(|d| std::fs::canonicalize(d).ok());
    let subroutine_dirs: Vec<PathBuf> = beside
        .into_iter()
        .chain(args.subroutine_path.iter().cloned())
        .collect();
    let tools = args
        .tool_table
        .as_deref()
        .map(crate::program::tools::ToolTable::load)
        .transpose()?;
    let opts = crate::program::Options {
        dialect: args.dialect,
        subroutine_dirs: subroutine_dirs.clone(),
        tools,
        offset_tolerance_mm: None,
        uncompensated: false,
        // (The machine's, set where the program is checked.)
        blend_tolerance_mm: 0.0,
        extensions: args.extensions.clone(),
    };
    // The run's length in cycles for a progress bar, only where one is drawn: the
    // engine stepped along as the program is checked (a STEP-NC part is planned whole).
    let progress = progress_wanted();
    let repeat = u64::from(args.repeat.max(1));
    // What the interpreter process may take instead of checking again (a program sent as
    // it is planned: not a STEP-NC part, not repeated).
    let mut handed = None;
    let checked: Result<Option<u64>, String> = if crate::step::check::is_step_file(&src.name, text)
    {
        process::compile_compact(&src.name, text, &opts, &machine, period_ns).map(|c| {
            eprint!("{}", process::format_notes(&src.name, &c.notes));
            progress
                .then(|| {
                    expected_cycles(
                        process::repeated(&c.blocks, args.repeat, &machine),
                        &machine,
                        period_ns,
                    )
                })
                .flatten()
        })
    } else {
        let mut release = |from: usize, to: usize| {
            if let Some(m) = &mapped {
                m.release(from, to);
            }
        };
        let planned = if progress {
            process::check_estimated(text, &opts, &machine, period_ns, false, &mut release)
                // (The return moves between repeats left out of the bar's length.)
                .map(|(p, e)| (p, e.and_then(|e| e.ok()).map(|e| e.cycles * repeat)))
        } else {
            process::check_windows(
                text,
                &opts,
                &machine,
                period_ns,
                &mut |_, _| {},
                &mut release,
            )
            .map(|p| (p, None))
        };
        planned
            .map(|(p, cycles)| {
                eprint!("{}", process::format_notes(&src.name, &p.notes));
                eprint!("{}", process::format_windows(&src.name, &p, &machine));
                if args.repeat <= 1 {
                    let digest = crate::checked::digest_of(mapped.as_ref(), text);
                    handed = crate::checked::Checked::of(
                        &p,
                        digest,
                        opts.tools.is_some(),
                        &machine,
                        period_ns,
                    );
                }
                cycles
            })
            .map_err(|d| process::format_diagnostics(&src.name, &d))
    };
    let expected_cycles = match checked {
        Ok(c) => c,
        Err(errors) => {
            say_err(&errors);
            return Ok(false);
        }
    };
    let dir = args.out.clone().unwrap_or_else(default_out_dir);
    crate::rundir::prepare(&dir, args.force)?;
    // The run directory keeps the exact program and machine it ran (a STEP-NC part too:
    // the interpreter process knows it by its content, the report page reads its lines).
    let program_copy = dir.join("program.ngc");
    match (&mapped, args.program.as_deref()) {
        (Some(_), Some(p)) => std::fs::copy(p, &program_copy).map(drop),
        _ => std::fs::write(&program_copy, &src.text),
    }
    .map_err(|e| format!("{}: {e}", program_copy.display()))?;
    let mut input = vec![
        "--program".into(),
        program_copy.display().to_string(),
        "--program-name".into(),
        src.name.clone(),
        "--repeat".into(),
        args.repeat.to_string(),
    ];
    if let Some(ms) = args.throttle_ms {
        input.extend(["--throttle-ms".into(), ms.to_string()]);
    }
    if let Some(d) = args.dialect {
        input.extend(["--dialect".into(), d.to_string()]);
    }
    for d in &subroutine_dirs {
        input.extend(["--subroutine-path".into(), d.display().to_string()]);
    }
    for e in &args.extensions {
        input.extend(["--dialect-extension".into(), e.to_string()]);
    }
    if let Some(c) = &handed {
        let path = dir.join(crate::checked::FILE);
        c.write(&path)?;
        input.extend(["--checked".into(), path.display().to_string()]);
    }
    if let Some(path) = &args.tool_table {
        let copy = dir.join("tool.tbl");
        std::fs::copy(path, &copy).map_err(|e| format!("{}: {e}", copy.display()))?;
        input.extend(["--tool-table".into(), copy.display().to_string()]);
    }
    // The text is not needed while the stack runs (the interpreter process reads the
    // run directory's copy).
    let name = src.name;
    drop(src.text);
    drop(mapped);
    let stack = Stack {
        dir,
        machine,
        period_ns,
        clock: args.clock,
        sched: args.sched,
        rt_priority: args.rt_priority,
        html: !args.no_report,
        expected_cycles,
        servo_clock: args.servo_clock,
    };
    stack.launch(&name, input)
}

/// Everything `cnc run` and `cnc replay` share: a run directory, a machine, a period, a
/// clock, and the three processes to start and watch.
pub struct Stack {
    pub dir: PathBuf,
    pub machine: shared::Machine,
    pub period_ns: u64,
    pub clock: ClockMode,
    pub sched: interpolator::rt::sched::SchedMode,
    pub rt_priority: i32,
    /// Write report.html after report.json (after every process has ended, so it never
    /// touches a cycle).
    pub html: bool,
    /// The run's length in cycles, for the progress bar (`None`: no bar).
    pub expected_cycles: Option<u64>,
    pub servo_clock: servo_sim::run::ServoClock,
}

/// A progress bar is drawn only for a person watching: stderr a terminal, not CI.
pub fn progress_wanted() -> bool {
    use std::io::IsTerminal;
    std::io::stderr().is_terminal() && std::env::var_os("CI").is_none()
}

/// The cycles a run of `blocks` takes: the interpolator's own engine, stepped in-process.
pub fn expected_cycles(
    blocks: impl Iterator<Item = shared::protocol::CommandBlock>,
    machine: &shared::Machine,
    period_ns: u64,
) -> Option<u64> {
    crate::estimate::estimate_of(blocks, machine, period_ns, u64::MAX)
        .ok()
        .flatten()
        .map(|e| e.cycles)
}

/// Runs shorter than this get no progress bar (it would only flash).
const PROGRESS_AFTER: Duration = Duration::from_secs(2);

/// The run's progress from the interpolator's status (cycle numbers), drawn on stderr once
/// the run has lasted [`PROGRESS_AFTER`].
struct Progress {
    total: u64,
    started: Instant,
    _node: iceoryx2::node::Node<iceoryx2::prelude::ipc::Service>,
    sub: iceoryx2::port::subscriber::Subscriber<
        iceoryx2::prelude::ipc::Service,
        shared::protocol::Status,
        (),
    >,
    cycle: u64,
    /// When the first status came (the first cycle ran).
    moving_since: Option<Instant>,
    bar: Option<indicatif::ProgressBar>,
}

impl Progress {
    fn new(prefix: &str, total: u64) -> Option<Progress> {
        let svc = shared::protocol::Services::new(prefix);
        let node = shared::ipc::node::<iceoryx2::prelude::ipc::Service>("launcher").ok()?;
        let status = shared::ipc::status(&node, &svc).ok()?;
        let sub = status.subscriber_builder().create().ok()?;
        Some(Progress {
            total,
            started: Instant::now(),
            _node: node,
            sub,
            cycle: 0,
            moving_since: None,
            bar: None,
        })
    }

    fn update(&mut self) {
        while let Ok(Some(s)) = self.sub.receive() {
            self.cycle = s.cycle;
            self.moving_since.get_or_insert_with(Instant::now);
        }
        if self.bar.is_none() && self.started.elapsed() >= PROGRESS_AFTER {
            // The clock starts with the run, not with the bar.
            let bar = indicatif::ProgressBar::new(self.total).with_elapsed(self.started.elapsed());
            bar.set_style(
                indicatif::ProgressStyle::with_template(
                    "{elapsed_precise} [{bar:40}] {pos}/{len} cycles ({percent}%), {msg}",
                )
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
            );
            self.bar = Some(bar);
        }
        if let Some(bar) = &self.bar {
            let done = self.cycle.min(self.total);
            bar.set_position(done);
            // Time left at the pace so far (the real clock's pace is the period's).
            if let Some(t) = self.moving_since.filter(|_| done > 0) {
                let left = t.elapsed().as_secs_f64() * (self.total - done) as f64 / done as f64;
                bar.set_message(format!("{left:.0} s left"));
            }
        }
    }

    fn finish(self) {
        if let Some(bar) = self.bar {
            bar.finish_and_clear();
        }
    }
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
        let mut progress = self
            .expected_cycles
            .and_then(|total| Progress::new(&prefix, total));
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
            tracing::debug!(process = %name, pid = child.id(), "process started");
            roles.push(Role::new(name, child));
            Ok(())
        };
        let sched = match self.sched {
            interpolator::rt::sched::SchedMode::Auto => "auto",
            interpolator::rt::sched::SchedMode::Other => "other",
        };
        let started = start(
            "servo-sim",
            vec![
                "--servo-clock".into(),
                self.servo_clock.to_string(),
                "--sched".into(),
                sched.into(),
                "--rt-priority".into(),
                interpolator::rt::sched::servo_priority(self.rt_priority).to_string(),
            ],
        )
        .and_then(|_| {
            start(
                "interpolator",
                vec![
                    "--sched".into(),
                    sched.into(),
                    "--rt-priority".into(),
                    self.rt_priority.to_string(),
                ],
            )
        })
        .and_then(|_| start("interpreter", input));
        let start_failed = started.err();
        let mut exit_fault = None;
        if start_failed.is_none() {
            exit_fault = supervise(&mut roles, progress.as_mut());
        } else {
            stop_all(&mut roles);
        }
        if let Some(p) = progress {
            p.finish();
        }
        let processes = roles
            .iter()
            .map(|r| Process {
                role: r.name.into(),
                pid: r.child.id(),
                exit: if r.stopped {
                    format!("{} (stopped by the launcher)", exit_text(r.exit))
                } else {
                    exit_text(r.exit)
                },
            })
            .collect();
        // The first fault is the one named: the operator's stop, a process that could not
        // start, one found suspended, one killed from outside (which, at which cycle);
        // else what the processes' own summaries say, and the exit codes last.
        // Every process has ended: a row a killed one was writing is cut off whole.
        report::cut_torn_rows(dir);
        let dead = dead_process(dir, &roles);
        let primary = interrupted()
            .map(|sig| operator_stop_text(dir, sig))
            .or(start_failed)
            .or_else(|| suspended_text(dir, &roles))
            .or_else(|| {
                dead.as_ref().map(|d| {
                    format!(
                        "{} failed ({}): died at cycle {}: {}",
                        d.role,
                        d.exit,
                        d.cycle.map_or("?".to_string(), |c| c.to_string()),
                        d.detail
                    )
                })
            });
        let mut rep = report::assemble(
            dir,
            program_name,
            self.clock,
            self.period_ns,
            processes,
            primary,
            exit_fault,
        );
        rep.dead_process = dead;
        rep.memory = roles.iter().filter_map(|r| r.memory.clone()).collect();
        rep.write(&dir.join("report.json"))
            .map_err(|e| format!("writing report.json: {e}"))?;
        match (&rep.fault, interrupted()) {
            (None, _) => tracing::info!(outcome = %rep.outcome, "run over"),
            (Some(f), Some(_)) => tracing::info!(outcome = %rep.outcome, "run stopped: {f}"),
            (Some(f), None) => tracing::error!(outcome = %rep.outcome, "run failed: {f}"),
        }
        say(&rep.summary_text(dir));
        if let Some(line) = interpolator::deadline::summary_line(dir) {
            say(&format!("  deadlines    {line}\n"));
        }
        if rep.starvations > 0 {
            say(&format!(
                "  starvation   {} time(s) the interpolator ran out of blocks, stopped on the path and waited\n",
                rep.starvations
            ));
        }
        if let Some(f) = &rep.fault_info {
            say(&format!(
                "  stop         {} at cycle {} (line {}{}): decelerated from {:.1} mm/min, at rest in cycle {}\n",
                report::kind_words(&f.kind),
                f.cycle,
                f.line,
                f.axis.as_deref().map(|a| format!(", axis {a}")).unwrap_or_default(),
                f.speed_at_fault_mm_per_min,
                f.stopped_cycle
            ));
        }
        if self.html && !report::contour_in_memory(dir) {
            say_err(&format!(
                "cnc: report.html not written: the run's command log and traces are more than the page reads ({} MB); report.json has the run's figures\n",
                report::CONTOUR_MAX_BYTES >> 20
            ));
        } else if self.html {
            match crate::html::write(dir, None) {
                Ok(page) => say(&format!("  report page  {}\n", page.display())),
                Err(e) => say_err(&format!("cnc: report.html not written: {e}\n")),
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

/// The last cycle number in a CSV trace (its last complete line), read from its end: a
/// long run's trace is gigabytes.
fn last_cycle_in(path: &Path) -> Option<u64> {
    use std::io::{Read, Seek, SeekFrom};
    let mut f = std::fs::File::open(path).ok()?;
    let len = f.metadata().ok()?.len();
    // A row is well under a kilobyte: the last complete one lies in the last few.
    let from = len.saturating_sub(64 << 10);
    f.seek(SeekFrom::Start(from)).ok()?;
    let mut tail = Vec::new();
    f.read_to_end(&mut tail).ok()?;
    let text = String::from_utf8_lossy(&tail);
    let complete = &text[..text.rfind('\n')?];
    let last = complete.lines().last()?;
    // (A tail that holds only the header, or begins inside a row: that row is cut.)
    if from > 0 && !complete.contains('\n') {
        return None;
    }
    last.split(',').next()?.parse().ok()
}

/// The process that was killed by a signal from outside (not by the launcher), if any,
/// with the cycle it died at, from what the survivors wrote.
fn dead_process(dir: &Path, roles: &[Role]) -> Option<DeadProcess> {
    use std::os::unix::process::ExitStatusExt;
    let r = roles
        .iter()
        .find(|r| !r.stopped && r.exit.is_some_and(|s| s.signal().is_some()))?;
    let ipol: Option<interpolator::summary::Summary> =
        std::fs::read_to_string(dir.join("interpolator.json"))
            .ok()
            .and_then(|t| serde_json::from_str(&t).ok());
    let noticed = ipol
        .as_ref()
        .and_then(|s| s.fault_info.as_ref())
        .filter(|f| f.kind == "peer_gone" && f.peer.as_deref() == Some(r.name));
    let (cycle, detail) = match (r.name, noticed) {
        ("interpolator", _) => {
            let c = last_cycle_in(&dir.join("feedback.csv"))
                .or_else(|| last_cycle_in(&dir.join("setpoints.csv")));
            (c, "its last set-point the drives answered".to_string())
        }
        (_, Some(f)) => (
            Some(f.cycle),
            format!(
                "the interpolator noticed in cycle {}{}, decelerated along the path and stood still in cycle {}",
                f.cycle,
                f.last_feedback_cycle
                    .map(|c| format!(" (last drive answer: cycle {c})"))
                    .unwrap_or_default(),
                f.stopped_cycle
            ),
        ),
        (_, None) => (
            last_cycle_in(&dir.join("setpoints.csv")),
            "the last set-point written".to_string(),
        ),
    };
    Some(DeadProcess {
        role: r.name.into(),
        pid: r.child.id(),
        exit: exit_text(r.exit),
        cycle,
        detail,
    })
}

/// The interpolator's summary, if it wrote one.
fn interpolator_summary(dir: &Path) -> Option<interpolator::summary::Summary> {
    std::fs::read_to_string(dir.join("interpolator.json"))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
}

/// The report's fault after the operator stopped the run with `sig`.
fn operator_stop_text(dir: &Path, sig: i32) -> String {
    let how = match sig {
        libc::SIGINT => "Ctrl-C, SIGINT".to_string(),
        libc::SIGTERM => "SIGTERM".to_string(),
        other => format!("signal {other}"),
    };
    let info = interpolator_summary(dir).and_then(|s| s.fault_info);
    let followed = last_cycle_in(&dir.join("feedback.csv"))
        .map(|c| format!("; the drives followed to cycle {c}"))
        .unwrap_or_default();
    match info {
        Some(i) => format!(
            "stopped by the operator at line {} ({how}): the interpolator braked on the path from {:.1} mm/min in cycle {} and was at rest in cycle {}{followed}",
            i.line, i.speed_at_fault_mm_per_min, i.stop_from_cycle, i.stopped_cycle
        ),
        None => format!("stopped by the operator ({how}){followed}"),
    }
}

/// The report's fault when a process was found suspended (SIGSTOP, Ctrl-Z) mid-run: the
/// first one seen, and the last cycle it had a part in.
fn suspended_text(dir: &Path, roles: &[Role]) -> Option<String> {
    let r = roles
        .iter()
        .filter(|r| r.suspended_at.is_some())
        .min_by_key(|r| r.suspended_at)?;
    let what = format!(
        "the {} was suspended (stopped by SIGSTOP or Ctrl-Z: its process was alive but did not run)",
        r.name
    );
    Some(match r.name {
        "servo-sim" => format!(
            "{what} and stopped answering after set-point cycle {}; the interpolator braked on the path",
            // What the interpolator had seen when it stopped: a suspended drive that is
            // resumed later answers the rest from its queue.
            interpolator_summary(dir)
                .and_then(|s| s.fault_info)
                .and_then(|f| f.last_feedback_cycle)
                .or_else(|| last_cycle_in(&dir.join("feedback.csv")))
                .map_or("?".into(), |c| c.to_string())
        ),
        "interpolator" => format!(
            "{what}: the drives' last set-point was cycle {}, then they held position",
            last_cycle_in(&dir.join("feedback.csv")).map_or("?".into(), |c| c.to_string())
        ),
        _ => format!("{what}; the interpolator stopped on the path"),
    })
}

/// Asks every live process to stop (SIGTERM: each stops its own way, writes its summary
/// and exits; SIGCONT, so that a suspended one can), then kills whatever is still there
/// after a grace period.
fn stop_all(roles: &mut [Role]) {
    for r in roles.iter_mut().filter(|r| r.exit.is_none()) {
        r.stopped = true;
        // SAFETY: plain kill(2) on a child we started and have not reaped.
        unsafe {
            libc::kill(r.child.id() as libc::pid_t, libc::SIGTERM);
            libc::kill(r.child.id() as libc::pid_t, libc::SIGCONT);
        }
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
        tracing::error!(
            process = %r.name,
            "process did not stop within 3 s of SIGTERM: killed"
        );
        let _ = r.child.kill();
        r.exit = r.child.wait().ok();
    }
}

/// Waits for all processes; after the first failure the others get [`SURVIVOR_GRACE`] to
/// stop by themselves, then are stopped. Returns the failure.
fn supervise(roles: &mut [Role], mut progress: Option<&mut Progress>) -> Option<String> {
    let mut fault = None;
    let mut failed_at: Option<Instant> = None;
    let mut last_exit: Option<Instant> = None;
    let mut last_sample: Option<Instant> = None;
    let mut operator_stop: Option<Instant> = None;
    let exits = Exits::open(roles);
    loop {
        if let Some(p) = progress.as_deref_mut() {
            p.update();
        }
        if last_sample.is_none_or(|t| t.elapsed() >= Duration::from_millis(100)) {
            last_sample = Some(Instant::now());
            for r in roles.iter_mut().filter(|r| r.exit.is_none()) {
                r.sample_memory();
            }
        }
        for r in roles.iter_mut().filter(|r| r.exit.is_none()) {
            if r.suspended_at.is_none() && is_suspended(r.child.id()) {
                r.suspended_at = Some(Instant::now());
            }
            if let Ok(Some(status)) = r.child.try_wait() {
                r.exit = Some(status);
                last_exit = Some(Instant::now());
                if status.success() {
                    tracing::debug!(process = %r.name, "process finished");
                } else {
                    tracing::warn!(
                        process = %r.name,
                        exit = %exit_text(Some(status)),
                        "process failed; the others stop by themselves"
                    );
                }
                if !status.success() && fault.is_none() {
                    fault = Some(format!("{} failed ({})", r.name, exit_text(Some(status))));
                    failed_at = Some(Instant::now());
                }
            }
        }
        if roles.iter().all(|r| r.exit.is_some()) {
            return fault;
        }
        // The operator's stop goes to the interpolator alone: it brakes on the path, the
        // drives follow it to its last set-point, the interpreter sees it end; then all
        // exit by themselves. Without an interpolator there is nothing moving to brake.
        if let (Some(sig), None) = (interrupted(), operator_stop) {
            operator_stop = Some(Instant::now());
            tracing::info!(
                signal = sig,
                "operator stop (signal {sig}): passed to the interpolator, which brakes on the path"
            );
            match roles
                .iter()
                .find(|r| r.name == "interpolator" && r.exit.is_none())
            {
                // SAFETY: plain kill(2) on a child we started and have not reaped.
                Some(r) => unsafe {
                    libc::kill(r.child.id() as libc::pid_t, sig);
                },
                None => {
                    stop_all(roles);
                    return fault;
                }
            }
        }
        if operator_stop.is_some_and(|t| t.elapsed() > OPERATOR_STOP_GRACE) {
            stop_all(roles);
            return fault;
        }
        // After a failure the survivors stop by themselves (they watch each other); after a
        // clean exit the others get a grace period to finish the shutdown handshake.
        let overdue = last_exit.is_some_and(|t| t.elapsed() > Duration::from_secs(10));
        let grace_over = failed_at.is_some_and(|t| t.elapsed() > SURVIVOR_GRACE);
        if grace_over || overdue {
            if fault.is_none() {
                fault = Some("a process did not finish after its peers had".into());
            }
            tracing::error!(
                "{} still running {} s after {}: stopping it",
                roles
                    .iter()
                    .filter(|r| r.exit.is_none())
                    .map(|r| r.name)
                    .collect::<Vec<_>>()
                    .join(" and "),
                if grace_over {
                    SURVIVOR_GRACE.as_secs()
                } else {
                    10
                },
                if grace_over {
                    "a peer failed"
                } else {
                    "a peer finished"
                }
            );
            stop_all(roles);
            return fault;
        }
        exits.wait(roles, Duration::from_millis(10));
    }
}

/// The running processes' pidfds, to sleep between the supervisor's looks until one of
/// them ends or the look is due: a run's end is seen when it happens, not up to a look
/// later (10 ms of every `--clock sim` run's wall time, against a loop of 0.3 s).
struct Exits {
    fds: Vec<(u32, libc::c_int)>,
}

impl Exits {
    fn open(roles: &[Role]) -> Exits {
        let fds = roles
            .iter()
            .filter_map(|r| {
                let pid = r.child.id();
                // SAFETY: pidfd_open(2) with a pid of our own unreaped child and no flags;
                // returns a new fd or -1.
                let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) };
                (fd >= 0).then_some((pid, fd as libc::c_int))
            })
            .collect();
        Exits { fds }
    }

    /// Sleeps for `most` or until a process still running ends. Without pidfds (an old
    /// kernel) a plain sleep.
    fn wait(&self, roles: &[Role], most: Duration) {
        let mut polled: Vec<libc::pollfd> = self
            .fds
            .iter()
            .filter(|(pid, _)| {
                roles
                    .iter()
                    .any(|r| r.child.id() == *pid && r.exit.is_none())
            })
            .map(|(_, fd)| libc::pollfd {
                fd: *fd,
                events: libc::POLLIN,
                revents: 0,
            })
            .collect();
        if polled.is_empty() {
            std::thread::sleep(most);
            return;
        }
        // SAFETY: `polled` is a valid array of that many pollfds for the call's length.
        unsafe {
            libc::poll(
                polled.as_mut_ptr(),
                polled.len() as libc::nfds_t,
                most.as_millis() as libc::c_int,
            )
        };
    }
}

impl Drop for Exits {
    fn drop(&mut self) {
        for (_, fd) in &self.fds {
            // SAFETY: an fd this struct opened and closes once.
            unsafe { libc::close(*fd) };
        }
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

    /// The last complete row of a trace, read from its end: past a cut last row, in a
    /// trace longer than the tail read, and none in one with no rows.
    #[test]
    fn the_last_cycle_of_a_trace_is_read_from_its_end() {
        use std::fmt::Write;
        let dir = std::env::temp_dir().join(format!("cnc-lastcycle-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("setpoints.csv");
        let mut s = String::from("cycle,t_ns,x_mm,y_mm,z_mm,line\n");
        for c in 0..20_000 {
            let _ = writeln!(s, "{c},{},1.000000,2.000000,3.000000,7", c * 1000);
        }
        std::fs::write(&f, format!("{s}20000,2000")).unwrap();
        assert!(s.len() > 64 << 10);
        assert_eq!(super::last_cycle_in(&f), Some(19_999));
        std::fs::write(&f, "cycle,t_ns,x_mm,y_mm,z_mm,line\n").unwrap();
        assert_eq!(super::last_cycle_in(&f), None);
        std::fs::write(&f, "cycle,t_ns,x_mm,y_mm,z_mm,line\n0,0,0,0,0,1\n").unwrap();
        assert_eq!(super::last_cycle_in(&f), Some(0));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
