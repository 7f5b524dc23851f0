//! The interpreter process: read and check the program, build and plan the blocks, log
//! and publish them, report.

use crate::blocks::{self, Block};
use crate::parse::Diagnostic;
use crate::program;
use crate::publish::{send, Finish, Link, Pace};
use crate::report::InterpreterSummary;
use crate::window::{self, Planned};
use iceoryx2::prelude::{MessagingPattern, Service};
use shared::cmdlog::CommandLog;
use shared::ipc::IpcError;
use shared::protocol::{BlockKind, CommandBlock, FLAG_RAPID};
use shared::Machine;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The built-in demonstration program.
pub const DEMO: &str = include_str!("demo.ngc");
/// The name the demo goes by in reports and messages.
pub const DEMO_NAME: &str = "demo.ngc";

/// A program's text and the name its diagnostics use.
pub struct Source {
    pub name: String,
    pub text: String,
}

impl Source {
    /// The file at `path`, or the built-in demo when there is none.
    pub fn load(path: Option<&Path>) -> Result<Source, String> {
        match path {
            None => Ok(Source {
                name: DEMO_NAME.into(),
                text: DEMO.into(),
            }),
            Some(p) => read_file(p)
                .map_err(|e| format!("{}: {e}", p.display()))
                .map(|bytes| Source {
                    name: p.display().to_string(),
                    // Valid UTF-8 (nearly every program) is taken as it is, not copied.
                    text: String::from_utf8(bytes)
                        .unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned()),
                }),
        }
    }
}

/// The bytes of the file at `path`, into a buffer that asks for huge pages (a long
/// program is megabytes: see [`crate::pages`]). What is not a regular file (a pipe, a
/// device) is read as a stream, within bounds ([`read_stream`]): `cnc check /dev/zero`
/// grew to 5.9 GB in 5 s.
fn read_file(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return read_stream(&mut file, STREAM_MAX_BYTES);
    }
    let len = meta.len();
    let mut bytes = Vec::with_capacity(usize::try_from(len).unwrap_or(0).saturating_add(1));
    crate::pages::prefer_huge_pages(&bytes);
    file.read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// The longest line a program read from a stream may have: far above G-code's 252 bytes
/// (a longer G-code line is refused by the check, at its column), and above the longest
/// line of a STEP-NC part (an entity on one line: 4 391 bytes in
/// `examples/tspline-bump.stp`).
const STREAM_MAX_LINE: usize = 1 << 20;

/// The most of a stream read as one program: it is read whole before anything runs
/// (192 MB for 8 million lines of `G1`). Larger programs are read from a file.
const STREAM_MAX_BYTES: usize = 512 << 20;

/// A stream's bytes to its end, refused with an error naming the line where one has no
/// end within [`STREAM_MAX_LINE`] bytes (`/dev/zero`) or where the stream passes `most`
/// bytes (`/dev/urandom`, `yes`), neither read further. Whether a stream is refused
/// does not depend on the size of its reads.
fn read_stream(r: &mut impl std::io::Read, most: usize) -> std::io::Result<Vec<u8>> {
    use std::io::{Error, ErrorKind};
    let mut bytes = Vec::new();
    let mut chunk = vec![0u8; 64 * 1024];
    // Where the line being read starts, and its number.
    let (mut line, mut number) = (0usize, 1usize);
    loop {
        let n = match r.read(&mut chunk) {
            Ok(0) => return Ok(bytes),
            Ok(n) => n,
            Err(e) if e.kind() == ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        let from = bytes.len();
        bytes.extend_from_slice(&chunk[..n]);
        for (i, &b) in bytes[from..].iter().enumerate() {
            let at = from + i;
            if b == b'\n' {
                (line, number) = (at + 1, number + 1);
            } else if at - line >= STREAM_MAX_LINE {
                return Err(Error::new(
                    ErrorKind::InvalidData,
                    format!(
                        "line {number} has no end within {} MiB: not a program (nothing after it read)",
                        STREAM_MAX_LINE >> 20
                    ),
                ));
            }
        }
        if bytes.len() > most {
            return Err(Error::new(
                ErrorKind::InvalidData,
                format!(
                    "more than {} MiB from a pipe or a device (stopped at line {number}): a program read whole before it runs; write it to a file",
                    most >> 20
                ),
            ));
        }
    }
}

/// Every problem of a program as `NAME:LINE:COL: RULE: message` lines; `NAME` is the
/// program's, or the subroutine file's for a problem in one.
pub fn format_diagnostics(name: &str, diags: &[Diagnostic]) -> String {
    diags
        .iter()
        .map(|d| format!("{}:{d}\n", d.file.as_deref().unwrap_or(name)))
        .collect()
}

/// Reads, checks, builds and plans: the blocks as they will be sent.
pub fn compile(
    text: &str,
    machine: &Machine,
    period_ns: u64,
) -> Result<(Planned, Vec<CommandBlock>), Vec<Diagnostic>> {
    compile_with(text, &program::Options::default(), machine, period_ns)
}

/// [`compile`], reading the program as `opts` say (a forced dialect).
pub fn compile_with(
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
) -> Result<(Planned, Vec<CommandBlock>), Vec<Diagnostic>> {
    check_with(text, opts, machine, period_ns).map(|(prog, b)| (prog, blocks::commands(&b)))
}

/// A program read, checked, built and planned as `cnc check` does it, every block
/// validated as it will be sent; the blocks as [`blocks::build`] holds them (straight
/// moves compact), [`blocks::commands`] turns them into those [`compile_with`] gives.
/// Planned window by window ([`crate::window`]), the blocks gathered.
pub fn check_with(
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
) -> Result<(Planned, Vec<Block>), Vec<Diagnostic>> {
    let mut all = Vec::new();
    let mut gather = |mut b: Vec<Block>, first: usize| {
        // (From block 0 again: the program is read again, see `window::plan`.)
        if first == 0 {
            all.clear();
        }
        all.append(&mut b)
    };
    // (On one thread: the interpreter compiles this way in a run, beside the
    // interpolator's cycle.)
    let stream = window::Stream {
        every: window::BATCH_MOVES,
        blocks: &mut gather,
        release: &mut |_, _| {},
        spare_cores: false,
    };
    let planned = check_streaming(text, opts, machine, period_ns, stream)?;
    Ok((planned, all))
}

/// [`check_streaming`] a window of [`window::BATCH_MOVES`] at a time: each window's blocks
/// handed to `blocks` (see [`window::Stream`]), `release` told of the text read, the
/// machine's other cores used ([`window::Stream::spare_cores`]): for `cnc check` and
/// the launcher, before any process of the stack runs.
pub fn check_windows(
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
    blocks: &mut dyn FnMut(Vec<Block>, usize),
    release: &mut dyn FnMut(usize, usize),
) -> Result<Planned, Vec<Diagnostic>> {
    let stream = window::Stream {
        every: window::BATCH_MOVES,
        blocks,
        release,
        spare_cores: true,
    };
    check_streaming(text, opts, machine, period_ns, stream)
}

/// [`check_with`], the blocks handed on window by window as [`window::Stream`] says
/// instead of gathered: a long program is never held whole.
pub fn check_streaming(
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
    stream: window::Stream<'_>,
) -> Result<Planned, Vec<Diagnostic>> {
    // NURBS offsets under G41/G42 are fitted within the machine's chord tolerance.
    let opts = program::Options {
        offset_tolerance_mm: opts
            .offset_tolerance_mm
            .or(Some(machine.chord_tolerance_mm)),
        // A bare G64, and the mode a program starts in, blend within the machine's.
        blend_tolerance_mm: machine.blend_tolerance_mm,
        ..opts.clone()
    };
    // Nothing leaves this process unless a receiver would accept it: every block is
    // validated, and kept within the machine's travel, as soon as its window is planned.
    window::plan(text, &opts, machine, period_ns, stream)
}

/// A program's machining time, or why the engine could not step it.
pub type EstimateOrWhy = Result<crate::estimate::Estimate, String>;

/// `cnc check --estimate` (and the launcher's progress bar): the program checked and planned window by window, each
/// window's blocks stepped through the interpolator's engine on a thread of its own as
/// they come (the two run side by side, on two cores where there are two). The estimate
/// is there only when the program is good; the time of each source line only if
/// `per_line` (`--json`).
pub fn check_estimated(
    text: &str,
    opts: &crate::program::Options,
    machine: &shared::Machine,
    period_ns: u64,
    per_line: bool,
    release: &mut dyn FnMut(usize, usize),
) -> Result<(Planned, Option<EstimateOrWhy>), Vec<Diagnostic>> {
    // A few windows ahead of the engine at most.
    let (tx, rx) = std::sync::mpsc::sync_channel::<(Vec<crate::blocks::Block>, usize)>(2);
    std::thread::scope(|scope| {
        // A program found bad stops coming: the engine starves, and the estimate is
        // not wanted then.
        let stepping = scope
            .spawn(move || crate::estimate::estimate_windows(&rx, machine, period_ns, per_line));
        // (The engine gone means it failed: its error is what is reported.)
        let mut hand = |blocks, first| drop(tx.send((blocks, first)));
        let planned = check_windows(text, opts, machine, period_ns, &mut hand, release);
        drop(tx);
        let est = stepping
            .join()
            .unwrap_or_else(|_| Err("the estimate's thread panicked".to_string()));
        planned.map(|p| (p, Some(est)))
    })
}

/// What the machine changes of what a program asks, each at the first source line
/// that asks it: a feed above `max_feed_mm_per_min` runs at that limit (the planner
/// clamps it). One note for each feed asked for, with how many more moves ask it.
pub fn notes(prog: &program::Program, machine: &Machine) -> Vec<(u32, String)> {
    let feeds = prog.moves.iter().filter_map(|m| match m {
        program::Move::Line {
            line,
            feed,
            rapid: false,
            ..
        }
        | program::Move::Arc { line, feed, .. }
        | program::Move::Nurbs { line, feed, .. } => Some((*line, *feed)),
        _ => None,
    });
    feed_notes(feeds, machine, "move")
}

/// [`notes`] of the feeds `(source line, mm/min)` asked for by things a user calls
/// `what` (a move, a workingstep).
pub fn feed_notes(
    feeds: impl IntoIterator<Item = (u32, f64)>,
    machine: &Machine,
    what: &str,
) -> Vec<(u32, String)> {
    let mut over = FeedNotes::new(machine);
    for (line, feed) in feeds {
        over.push(line, feed);
    }
    over.finish(what)
}

/// [`feed_notes`] gathered as the feeds come (a program read in windows).
#[derive(Debug, Clone)]
pub struct FeedNotes {
    /// The machine's `max_feed_mm_per_min`.
    max: f64,
    /// Each feed above it as shown, with the first line that asks it and how many do.
    over: Vec<(f64, u32, usize)>,
}

impl FeedNotes {
    pub fn new(machine: &Machine) -> Self {
        FeedNotes {
            max: machine.max_feed_mm_per_min,
            over: Vec::new(),
        }
    }

    /// The feed `feed` (mm/min) asked for at source line `line`.
    pub fn push(&mut self, line: u32, feed: f64) {
        // (A rounding above the limit is the limit: an inch F at the limit converts to
        // a hair over it.)
        if feed <= self.max * (1.0 + 1e-9) {
            return;
        }
        // One note for each feed as it is shown.
        match self.over.iter_mut().find(|o| shown(o.0) == shown(feed)) {
            Some(o) => o.2 += 1,
            None => self.over.push((feed, line, 1)),
        }
    }

    /// The notes, one for each feed above the machine's as it is shown.
    pub fn finish(self, what: &str) -> Vec<(u32, String)> {
        let max = self.max;
        self.over
            .into_iter()
            .map(|(feed, line, n)| {
                let who = match n {
                    1 => format!("the {what} runs"),
                    2 => format!("this {what} and 1 more at that feed run"),
                    n => format!("this {what} and {} more at that feed run", n - 1),
                };
                (
                    line,
                    format!(
                        "feed {} mm/min is above the machine's max_feed_mm_per_min: {who} at {} mm/min",
                        shown(feed),
                        shown(max)
                    ),
                )
            })
            .collect()
    }
}

/// A figure as a user reads it: at most three decimals, no trailing zeros.
pub(crate) fn shown(v: f64) -> String {
    let s = format!("{v:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// `notes` as `cnc check` prints them: `NAME:LINE: note: …`, one a line.
pub fn format_notes(name: &str, notes: &[(u32, String)]) -> String {
    notes
        .iter()
        .map(|(line, n)| format!("{name}:{line}: note: {n}\n"))
        .collect()
}

/// What the planning in windows says to the user: where the machine's look-ahead
/// (`plan_window_moves`) is too short for the feed ([`Planned::short_windows`]), a
/// note naming the machine file's key; nothing otherwise.
pub fn format_windows(name: &str, planned: &Planned, machine: &Machine) -> String {
    if planned.short_windows == 0 {
        return String::new();
    }
    format!(
        "{name}: note: the look-ahead (plan_window_moves = {} in the machine file) is shorter than the braking from the feed in {} of the {} windows planned at speed: the feed drops towards the end of each so the machine can stop within what it holds, and the program takes longer than with a longer look-ahead\n",
        machine.plan_window_moves, planned.short_windows, planned.at_speed
    )
}

/// A program ready to send: its blocks and what the reports say about it. The blocks are
/// [`CommandBlock`]s for [`compile_source`], and held compact ([`Block`]: a straight move
/// in its few numbers, not the 1.6 kB payload) for [`compile_compact`], which the
/// launcher and the interpreter process use: 8 million lines of `G1` made each of them
/// 13 GB of command blocks.
#[derive(Debug, Clone)]
pub struct Compiled<B = CommandBlock> {
    pub blocks: Vec<B>,
    /// The NC dialect a G-code program was read in; none for a STEP-NC part.
    pub dialect: Option<program::Dialect>,
    pub messages: Vec<(u32, String)>,
    /// What the machine changes of what the program asks ([`notes`]).
    pub notes: Vec<(u32, String)>,
    /// The largest scallop height of a STEP-NC part's surface paths (as planned).
    pub max_scallop_mm: Option<f64>,
}

/// Reads, checks, builds and plans a G-code program or a STEP-NC part (told apart by
/// [`crate::step::check::is_step_file`]); every problem as `NAME:LINE:...` lines.
pub fn compile_source(
    name: &str,
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
) -> Result<Compiled, String> {
    let c = compile_compact(name, text, opts, machine, period_ns)?;
    Ok(Compiled {
        blocks: blocks::commands(&c.blocks),
        dialect: c.dialect,
        messages: c.messages,
        notes: c.notes,
        max_scallop_mm: c.max_scallop_mm,
    })
}

/// [`compile_source`], the blocks held compact: each becomes its [`CommandBlock`] when
/// it is sent ([`repeated`]), the same bit for bit.
pub fn compile_compact(
    name: &str,
    text: &str,
    opts: &program::Options,
    machine: &Machine,
    period_ns: u64,
) -> Result<Compiled<Block>, String> {
    if crate::step::check::is_step_file(name, text) {
        let (blocks, scallop) = crate::surface_blocks::part_blocks(text, machine, period_ns)
            .map_err(|e| crate::step::format_errors(name, &e))?;
        return Ok(Compiled {
            blocks: blocks.into_iter().map(Block::compact).collect(),
            dialect: None,
            messages: Vec::new(),
            notes: crate::step::check::part_notes(text, machine),
            max_scallop_mm: Some(scallop),
        });
    }
    let (prog, blocks) =
        check_with(text, opts, machine, period_ns).map_err(|d| format_diagnostics(name, &d))?;
    Ok(Compiled {
        blocks,
        dialect: Some(prog.dialect),
        notes: prog.notes,
        messages: prog.messages,
        max_scallop_mm: None,
    })
}

#[derive(Debug, Clone)]
pub struct Config {
    pub prefix: String,
    pub out_dir: PathBuf,
    pub period_ns: u64,
    pub machine: Machine,
    pub program: Option<PathBuf>,
    /// Name to report the program under (the launcher passes the user's path).
    pub program_name: Option<String>,
    /// Replay this command log instead of reading a program.
    pub replay: Option<PathBuf>,
    /// With `replay`: run the intact records of a damaged log, then stop.
    pub salvage: bool,
}

/// A command log ready to replay.
pub struct Replay {
    pub header: shared::cmdlog::Header,
    pub blocks: Vec<CommandBlock>,
    /// What was wrong with a salvaged log: its intact blocks run, then a program end.
    pub salvaged: Option<String>,
}

/// The blocks of a command log to replay. A damaged log is refused, unless `salvage`:
/// then its intact records run, followed by a program end so the machine stops there.
pub fn load_replay(path: &Path, salvage: bool) -> Result<Replay, String> {
    let parsed = shared::cmdlog::read(path)?;
    let mut blocks = parsed.blocks;
    let salvaged = match parsed.damage {
        None => None,
        Some(damage) if !salvage => {
            return Err(format!(
                "{}: {damage}; nothing replayed (--salvage replays the {} intact blocks before it)",
                path.display(),
                blocks.len()
            ))
        }
        Some(damage) => {
            if blocks
                .last()
                .is_some_and(|b| b.kind == BlockKind::ProgramEnd as u32)
            {
                blocks.pop();
            }
            let note = format!(
                "salvaged {}: {damage}; the {} intact blocks before it ran, then a stop",
                path.display(),
                blocks.len()
            );
            blocks.push(CommandBlock::empty(
                BlockKind::ProgramEnd,
                blocks.len() as u64,
                0,
            ));
            Some(note)
        }
    };
    Ok(Replay {
        header: parsed.header,
        blocks,
        salvaged,
    })
}

/// How a run streams its program beyond the plain case.
#[derive(Debug, Clone)]
pub struct Streaming {
    /// Run the program this many times in one go (soak tests): one stream of blocks with
    /// sequence numbers that keep counting, a rapid back to the start between repeats
    /// when the program ends elsewhere, and one program end after the last repeat.
    pub repeat: u32,
    /// Test aid: wait this long before each block (a slow interpreter).
    pub throttle: Option<Duration>,
    /// Test aid: wait this long before reading the program (a long plan).
    pub hold_before_reading: Option<Duration>,
    /// Read the program in this dialect instead of detecting it (`--dialect`).
    pub dialect: Option<program::Dialect>,
    /// Where subroutine files are looked for, in order (see [`program::Options`]).
    pub subroutine_dirs: Vec<PathBuf>,
    /// The tool table file `G41`/`G42` take radii from (`--tool-table`).
    pub tool_table: Option<PathBuf>,
    /// What the program may do beyond its dialect (`--dialect-extension`).
    pub extensions: Vec<program::dialect::Extension>,
    /// The launcher's check of the program ([`crate::checked`]), taken instead of
    /// checking again where it holds for this reading.
    pub checked: Option<PathBuf>,
}

impl Default for Streaming {
    fn default() -> Self {
        Streaming {
            repeat: 1,
            throttle: None,
            hold_before_reading: None,
            dialect: None,
            subroutine_dirs: Vec::new(),
            tool_table: None,
            extensions: Vec::new(),
            checked: None,
        }
    }
}

/// A rapid (G0) straight move from `from` back to the machine's start, the origin, with a
/// stop at both ends; `None` when `from` is the origin already.
fn return_to_start(from: [f64; 3], machine: &Machine) -> Option<CommandBlock> {
    let length = shared::path::norm(from);
    if length < 1e-9 {
        return None;
    }
    let mut b = CommandBlock::empty(BlockKind::Motion, 0, 0);
    b.flags = FLAG_RAPID;
    b.degree = 1;
    b.n_ctrl = 2;
    b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
    b.ctrl[0] = [from[0], from[1], from[2], 1.0];
    b.ctrl[1] = [0.0, 0.0, 0.0, 1.0];
    b.length_mm = length;
    // A straight line: the planner's limits for it are the machine's.
    crate::blocks::plan_alone(&mut b, machine, machine.rapid_mm_per_min);
    Some(b)
}

/// The blocks of `repeat` runs of a compiled program as one stream, numbered 0, 1, 2, ...
/// Lazy, so a soak of any length holds one copy of the program, and each block becomes
/// its [`CommandBlock`] only as it is taken.
pub fn repeated<'a>(
    blocks: &'a [Block],
    repeat: u32,
    machine: &Machine,
) -> impl Iterator<Item = CommandBlock> + 'a {
    let kind = |b: &Block| match b {
        Block::Straight(_) => BlockKind::Motion as u32,
        Block::Whole(w) => w.kind,
    };
    let (body, end) = match blocks.split_last() {
        Some((last, body)) if kind(last) == BlockKind::ProgramEnd as u32 => {
            (body, Some(last.command(0)))
        }
        _ => (blocks, None),
    };
    let end_pos = body
        .iter()
        .rev()
        .find(|b| kind(b) == BlockKind::Motion as u32)
        .map(|b| {
            let b = b.command(0);
            shared::path::eval(&b, shared::path::domain(&b).1).p
        });
    let back = end_pos.and_then(|p| return_to_start(p, machine));
    let repeat = repeat.max(1);
    (0..repeat)
        .flat_map(move |r| {
            let between = if r + 1 < repeat { back } else { None };
            body.iter().map(|b| b.command(0)).chain(between)
        })
        .chain(end)
        .enumerate()
        .map(|(i, mut b)| {
            b.seq = i as u64;
            b
        })
}

/// How often reading and planning look for a stop request or an interpolator that left.
const PLAN_WATCH_EVERY: Duration = Duration::from_millis(10);

/// `work` (reading and planning) on a thread of its own, given up (with nothing sent, so
/// nothing moved) on a stop request or when the interpolator, once there, has left: a
/// program of many curves plans for tens of seconds, and the operator's Ctrl-C must not
/// wait for it. Given up, the thread is left to end with the process. `hold` is a test
/// aid (a long plan).
fn watched<S: Service, R: Send + 'static>(
    link: &Link<S>,
    hold: Option<Duration>,
    work: impl FnOnce() -> Result<R, String> + Send + 'static,
) -> Result<R, String> {
    let planner = std::thread::Builder::new()
        .name("plan".into())
        .spawn(move || {
            if let Some(d) = hold {
                std::thread::sleep(d);
            }
            work()
        })
        .map_err(|e| format!("starting the planning thread: {e}"))?;
    let mut came = false;
    while !planner.is_finished() {
        std::thread::sleep(PLAN_WATCH_EVERY);
        if shared::stop::launcher_gone() {
            return Err("the launcher (cnc run) died while the program was read and planned; nothing was sent".into());
        }
        if shared::stop::requested() {
            return Err(
                "stopped on request while the program was read and planned; nothing was sent"
                    .into(),
            );
        }
        let there = link.interpolator_there();
        if came && !there {
            return Err("the interpolator is gone (its process ended or died) while the program was read and planned; nothing was sent".into());
        }
        came |= there;
    }
    planner
        .join()
        .map_err(|_| "the planning thread panicked".to_string())?
}

/// The blocks a run sends: held (a replay, a STEP-NC part, a program run more than
/// once) or planned window by window as they are sent.
enum Sent {
    Held(Vec<Block>),
    /// A G-code program checked whole (`planned`), to be read and planned again as it
    /// is sent, in the dialect it was found to be in.
    Streamed {
        text: std::sync::Arc<ProgramText>,
        opts: program::Options,
        planned: Box<Planned>,
    },
}

/// A program's text: the file mapped where it can be (given back as it is read), else
/// read.
pub struct ProgramText {
    mapped: Option<crate::mapped::MappedText>,
    read: String,
}

impl ProgramText {
    /// The program file at `path`.
    pub fn load(path: &Path) -> Result<ProgramText, String> {
        Ok(match crate::mapped::MappedText::open(path) {
            Some(m) => ProgramText {
                mapped: Some(m),
                read: String::new(),
            },
            None => ProgramText {
                mapped: None,
                read: Source::load(Some(path))?.text,
            },
        })
    }

    /// The text as it is (the built-in demo).
    pub fn of(text: String) -> ProgramText {
        ProgramText {
            mapped: None,
            read: text,
        }
    }

    pub fn as_str(&self) -> &str {
        self.mapped
            .as_ref()
            .map_or(self.read.as_str(), |m| m.as_str())
    }

    /// Its [`crate::checked::digest`].
    pub fn digest(&self) -> u64 {
        crate::checked::digest_of(self.mapped.as_ref(), &self.read)
    }

    /// Gives back the pages of bytes `from..to` (see
    /// [`crate::mapped::MappedText::release`]).
    pub fn release(&self, from: usize, to: usize) {
        if let Some(m) = &self.mapped {
            m.release(from, to);
        }
    }
}

/// Runs the interpreter until the interpolator reports the end; writes `commands.log` and
/// `interpreter.json`.
pub fn run<S: Service>(cfg: &Config) -> Result<InterpreterSummary, String> {
    run_streaming::<S>(cfg, Streaming::default())
}

/// [`run`], repeating or pacing the program as `streaming` says.
pub fn run_streaming<S: Service>(
    cfg: &Config,
    streaming: Streaming,
) -> Result<InterpreterSummary, String> {
    // The ports first: the interpolator waits for the first block as long as they are
    // there, however long the program takes to read and plan. The interpolator creates
    // them: opening them at the same moment would cost iceoryx2's 25 ms tick
    // (`ipc::await_created`).
    let svc = shared::protocol::Services::new(&cfg.prefix);
    shared::ipc::await_created::<S>(
        &[
            (&svc.blocks(), MessagingPattern::PublishSubscribe),
            (&svc.status(), MessagingPattern::PublishSubscribe),
        ],
        shared::ipc::CREATOR_WAIT,
    );
    let link = Link::<S>::open(&cfg.prefix).map_err(|e| e.to_string())?;
    let mut salvaged = None;
    let mut dialect = None;
    let mut max_scallop_mm = None;
    let mut notes = Vec::new();
    let mut windows = (None, None);
    let mut seams = (None, None);
    let mut checked_by = None;
    let (name, sent_blocks, messages) = match &cfg.replay {
        Some(log) => {
            let r = load_replay(log, cfg.salvage)?;
            salvaged = r.salvaged;
            // Straight moves compact (112 bytes, not 1.6 kB), the rest whole: while they
            // are made the log's own list is still there, so a log of curves is held
            // twice for that moment, one of lines about once.
            let blocks = r.blocks.into_iter().map(Block::compact).collect();
            (r.header.program, Sent::Held(blocks), Vec::new())
        }
        None => {
            let src_name = cfg
                .program
                .as_deref()
                .map_or(DEMO_NAME.to_string(), |p| p.display().to_string());
            let name = cfg.program_name.clone().unwrap_or(src_name);
            let text = std::sync::Arc::new(match cfg.program.as_deref() {
                Some(p) => ProgramText::load(p)?,
                None => ProgramText::of(DEMO.to_string()),
            });
            let opts = program::Options {
                dialect: streaming.dialect,
                subroutine_dirs: streaming.subroutine_dirs.clone(),
                tools: streaming
                    .tool_table
                    .as_deref()
                    .map(program::tools::ToolTable::load)
                    .transpose()?,
                offset_tolerance_mm: None,
                uncompensated: false,
                // (The machine's, set where the program is checked.)
                blend_tolerance_mm: 0.0,
                extensions: streaming.extensions.clone(),
            };
            let hold = streaming.hold_before_reading;
            let (machine, period_ns) = (cfg.machine.clone(), cfg.period_ns);
            let step = crate::step::check::is_step_file(&name, text.as_str());
            if step || streaming.repeat > 1 {
                // Held whole: a STEP-NC part is planned whole, and a program run more
                // than once is sent again from what is held.
                let (t, n, o) = (text.clone(), name.clone(), opts.clone());
                let c = watched(&link, hold, move || {
                    compile_compact(&n, t.as_str(), &o, &machine, period_ns)
                })
                .map_err(|e| nothing_sent(cfg, &name, e))?;
                dialect = c.dialect.map(|d| d.name().to_string());
                max_scallop_mm = c.max_scallop_mm;
                notes = c.notes;
                (name, Sent::Held(c.blocks), c.messages)
            } else {
                // Checked whole first, window by window (nothing moves before the
                // program is known good), then read and planned again as it is sent.
                // The launcher's check is taken instead where it holds for this text.
                let trusted = streaming
                    .checked
                    .as_deref()
                    .filter(|_| opts.tools.is_none())
                    .and_then(|path| {
                        let taken = crate::checked::Checked::read(path).and_then(|c| {
                            c.planned_for(text.digest(), &machine, period_ns)
                        });
                        match taken {
                            Ok(p) => {
                                tracing::info!(
                                    "the launcher's check of the program taken: its copy is the text checked"
                                );
                                Some(p)
                            }
                            Err(why) => {
                                tracing::warn!(
                                    "the launcher's check not taken, the program is checked again: {why}"
                                );
                                None
                            }
                        }
                    });
                checked_by = Some(if trusted.is_some() {
                    "launcher"
                } else {
                    "interpreter"
                });
                // (Read with no subroutine directory: the check read no file.)
                let opts = match trusted {
                    Some(_) => program::Options {
                        subroutine_dirs: Vec::new(),
                        ..opts
                    },
                    None => opts,
                };
                let planned = match trusted {
                    Some(p) => p,
                    None => {
                        let (t, n, o) = (text.clone(), name.clone(), opts.clone());
                        watched(&link, hold, move || {
                            let mut release = |from, to| t.release(from, to);
                            check_streaming(
                                t.as_str(),
                                &o,
                                &machine,
                                period_ns,
                                window::Stream {
                                    every: window::BATCH_MOVES,
                                    blocks: &mut |_, _| {},
                                    release: &mut release,
                                    // (The interpolator is cycling already.)
                                    spare_cores: false,
                                },
                            )
                            .map_err(|d| format_diagnostics(&n, &d))
                        })
                        .map_err(|e| nothing_sent(cfg, &name, e))?
                    }
                };
                dialect = Some(planned.dialect.name().to_string());
                notes = planned.notes.clone();
                windows = (Some(planned.windows), Some(planned.at_speed));
                seams = (Some(planned.rough_seams), Some(planned.short_windows));
                let messages = planned.messages.clone();
                let opts = program::Options {
                    dialect: Some(planned.dialect),
                    ..opts
                };
                (
                    name,
                    Sent::Streamed {
                        text,
                        opts,
                        planned: Box::new(planned),
                    },
                    messages,
                )
            }
        }
    };
    let block_count = match &sent_blocks {
        Sent::Held(b) => b.len(),
        Sent::Streamed { planned, .. } => planned.blocks,
    };
    tracing::info!(
        program = %name,
        blocks = block_count,
        repeat = streaming.repeat,
        period_us = cfg.period_ns / 1000,
        "interpreter started"
    );
    for (line, m) in &messages {
        tracing::info!("{name}:{line}: MSG {m}");
    }
    let mut log = CommandLog::create(
        &cfg.out_dir.join("commands.log"),
        cfg.period_ns,
        cfg.machine.hash(),
        &name,
    )
    .map_err(|e| format!("creating commands.log: {e}"))?;
    let pace = Pace {
        throttle: streaming.throttle,
    };
    let result = match &sent_blocks {
        Sent::Held(blocks) => send(
            &link,
            repeated(blocks, streaming.repeat, &cfg.machine),
            Some(&mut log),
            Duration::from_secs(20),
            pace,
        ),
        Sent::Streamed { text, opts, .. } => send_streamed::<S>(
            &link,
            (&name, text, opts),
            (&cfg.machine, cfg.period_ns),
            &mut log,
            pace,
        ),
    };
    // What was sent before an error ended the sending: the blocks logged, each as it went.
    let logged = log.blocks();
    log.finish()
        .map_err(|e| format!("writing commands.log: {e}"))?;
    let interpolator_stopped = matches!(result, Ok((Finish::Fault, _)));
    let (fault, sent) = match result {
        Ok((Finish::Done, n)) => (None, n),
        Ok((Finish::Fault, n)) => (Some("the interpolator stopped with a fault".to_string()), n),
        Err(e) => (Some(e.to_string()), logged),
    };
    match &fault {
        None => tracing::info!(
            blocks_sent = sent,
            "interpreter stopped: program end, the interpolator reported done"
        ),
        // The interpolator's own log names the cause (an operator's stop, a fault).
        Some(_) if interpolator_stopped => tracing::warn!(
            blocks_sent = sent,
            "interpreter stopped: the interpolator stopped before the program end"
        ),
        Some(f) if shared::stop::terminate_requested() => {
            tracing::info!(blocks_sent = sent, "interpreter stopped: {f}")
        }
        Some(f) => tracing::error!(blocks_sent = sent, "interpreter fault: {f}"),
    }
    let summary = InterpreterSummary {
        outcome: if fault.is_some() { "fault" } else { "done" }.into(),
        fault,
        pid: std::process::id(),
        program: name,
        // Every block sent (all repeats); the blocks of one run when nothing was sent.
        blocks: if sent > 0 { sent as usize } else { block_count },
        messages,
        notes,
        salvaged,
        dialect,
        max_scallop_mm,
        windows: windows.0,
        windows_at_speed: windows.1,
        rough_seams: seams.0,
        short_windows: seams.1,
        checked_by: checked_by.map(str::to_string),
    };
    write_summary(cfg, &summary)?;
    Ok(summary)
}

/// Reads and plans the program (checked already) window by window on a thread of its
/// own, and sends each window's blocks as they come: the planning runs at most a few
/// windows ahead of the sending. A window ends where the machine is at rest, or at
/// speed within a long stretch with no rest ([`crate::window`]); a plan that falls
/// behind there makes the interpolator stop on the path by the end of the last block
/// it holds (a starvation, counted), never run off it. Should the blocks stop coming
/// before the program's end (a stop asked for, the launcher or the interpolator gone
/// while a window is planned, or the second reading refused), a program end follows
/// the last window sent, which the machine stops by, and the planning is left to end
/// with the process.
fn send_streamed<S: Service>(
    link: &Link<S>,
    (name, text, opts): (&str, &std::sync::Arc<ProgramText>, &program::Options),
    (machine, period_ns): (&Machine, u64),
    log: &mut CommandLog,
    pace: Pace,
) -> Result<(Finish, u64), IpcError> {
    let (tx, rx) = std::sync::mpsc::sync_channel::<(Vec<Block>, usize)>(2);
    let (text, opts, machine) = (text.clone(), opts.clone(), machine.clone());
    let planner = std::thread::Builder::new()
        .name("plan".into())
        .spawn(move || {
            check_streaming(
                text.as_str(),
                &opts,
                &machine,
                period_ns,
                window::Stream {
                    every: window::BATCH_MOVES,
                    blocks: &mut |blocks, first| {
                        // (The sending gone has stopped: the rest is not wanted.)
                        let _ = tx.send((blocks, first));
                    },
                    release: &mut |from, to| text.release(from, to),
                    // (The interpolator's cycle may need the other core.)
                    spare_cores: false,
                },
            )
        })
        .map_err(|e| IpcError(format!("starting the planning thread: {e}")))?;
    // The next window as it comes; none once a stop is asked for, or the launcher or the
    // interpolator is gone, while a long window is still being planned.
    let mut came = false;
    let windows = std::iter::from_fn(|| loop {
        match rx.recv_timeout(PLAN_WATCH_EVERY) {
            Ok(w) => return Some(w),
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => return None,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                let there = link.interpolator_there();
                if shared::stop::requested() || shared::stop::launcher_gone() || (came && !there) {
                    return None;
                }
                came |= there;
            }
        }
    });
    // The last block sent: its number, its line, and whether it ends the program.
    let last: std::cell::Cell<Option<(u64, u32, bool)>> = std::cell::Cell::new(None);
    let blocks = windows
        .flat_map(|(blocks, first)| {
            blocks
                .into_iter()
                .enumerate()
                .map(move |(i, b)| b.command((first + i) as u64))
        })
        .inspect(|b| {
            let end = b.kind() == Some(BlockKind::ProgramEnd);
            last.set(Some((b.seq, b.source_line, end)));
        });
    let cut_short = std::iter::from_fn(|| match last.take() {
        Some((seq, line, false)) => Some(CommandBlock::empty(BlockKind::ProgramEnd, seq + 1, line)),
        _ => None,
    });
    let sent = send(
        link,
        blocks.chain(cut_short),
        Some(log),
        Duration::from_secs(20),
        pace,
    );
    let ended = matches!(sent, Ok((Finish::Done, _)));
    // Finished, the planning has handed its last window on: its answer is at hand.
    if ended || planner.is_finished() {
        match planner.join() {
            // Checked once already: a second reading that is refused is a fault of ours.
            Ok(Err(d)) => {
                return Err(IpcError(format!(
                    "the program, checked, was refused when read again to be sent (the machine stopped at the end of the last good stretch): {}",
                    format_diagnostics(name, &d[..d.len().min(1)]).trim_end()
                )))
            }
            Err(_) => return Err(IpcError("the planning thread panicked".into())),
            Ok(Ok(_)) => {}
        }
    }
    sent
}

/// Writes `interpreter.json`, and the report when the launcher is dead (nobody else will
/// fold the summaries into one).
fn write_summary(cfg: &Config, summary: &InterpreterSummary) -> Result<(), String> {
    let text = serde_json::to_string_pretty(summary).map_err(|e| e.to_string())?;
    std::fs::write(cfg.out_dir.join("interpreter.json"), text)
        .map_err(|e| format!("writing interpreter.json: {e}"))?;
    if shared::stop::launcher_gone() {
        crate::report::write_orphan_report(&cfg.out_dir, &summary.program, cfg.period_ns)?;
    }
    Ok(())
}

/// The planning given up (`why`) before anything was sent: with the launcher dead, its
/// summary and the report are still written, as after a run.
fn nothing_sent(cfg: &Config, program: &str, why: String) -> String {
    if shared::stop::launcher_gone() {
        let summary = InterpreterSummary {
            outcome: "fault".into(),
            fault: Some(why.clone()),
            pid: std::process::id(),
            program: program.to_string(),
            blocks: 0,
            messages: Vec::new(),
            notes: Vec::new(),
            salvaged: None,
            dialect: None,
            max_scallop_mm: None,
            windows: None,
            windows_at_speed: None,
            rough_seams: None,
            short_windows: None,
            checked_by: None,
        };
        if let Err(e) = write_summary(cfg, &summary) {
            tracing::error!("{e}");
        }
    }
    why
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn compact_blocks_are_sent_as_the_whole_ones_bit_for_bit() {
        // Lines, rapids, an arc, a NURBS, a dwell and the end, twice over with the return
        // to the start between: what the launcher and the interpreter hold compact is
        // what was sent when they held every block whole.
        let text = "G21 G90 G17\nG0 X1 Y1\nG1 X10 F600\nG2 X12 Y3 I0 J2\nG4 P0.1\n\
                    G5.2 X14 Y3 P1 L4\nX16 Y5 P1\nX18 Y3 P1\nG5.3\nG1 X20 Y0\nM2\n";
        let machine = Machine::default();
        let opts = program::Options::default();
        let whole = compile_source("p.ngc", text, &opts, &machine, 1_000_000).unwrap();
        let compact = compile_compact("p.ngc", text, &opts, &machine, 1_000_000).unwrap();
        assert!(compact
            .blocks
            .iter()
            .any(|b| matches!(b, Block::Straight(_))));
        let mut all = whole.blocks.clone();
        for (i, b) in all.iter_mut().enumerate() {
            b.seq = i as u64;
        }
        let body = &all[..all.len() - 1];
        let sent: Vec<String> = repeated(&compact.blocks, 2, &machine)
            .map(|b| format!("{b:?}"))
            .collect();
        // Two runs, the way back between them, the end.
        assert_eq!(sent.len(), 2 * body.len() + 2);
        for (k, b) in body.iter().enumerate() {
            for (run, at) in [(0, k), (1, body.len() + 1 + k)] {
                let mut want = *b;
                want.seq = at as u64;
                assert_eq!(sent[at], format!("{want:?}"), "run {run}, block {k}");
            }
        }
        let mut end = all[all.len() - 1];
        end.seq = (sent.len() - 1) as u64;
        assert_eq!(sent[sent.len() - 1], format!("{end:?}"));
        // The estimate of either form is the same.
        let a = crate::estimate::estimate(&all, &machine, 1_000_000).unwrap();
        let b = crate::estimate::estimate_of(
            repeated(&compact.blocks, 1, &machine),
            &machine,
            1_000_000,
            u64::MAX,
        )
        .unwrap()
        .unwrap();
        assert_eq!(a, b);
        assert!(a.moves.iter().any(|m| m.rapid));
        // A logged block (a replay's) held compact where that gives it back bit for bit:
        // the lines and rapids, not the arcs, NURBS, dwell or end.
        for b in &all {
            let c = Block::compact(*b);
            assert!(shared::cmdlog::same_bits(&c.command(b.seq), b));
            let straight = b.kind == BlockKind::Motion as u32 && b.degree == 1;
            assert_eq!(matches!(c, Block::Straight(_)), straight, "{b:?}");
        }
        // A degree-1 block that is not as the planner makes one (a weight) stays whole.
        let mut odd = *all.iter().find(|b| b.degree == 1).unwrap();
        odd.ctrl[1][3] = 2.0;
        assert!(matches!(Block::compact(odd), Block::Whole(_)));
    }

    /// A reader that hands out its bytes `step` at a time.
    struct Trickle<'a>(&'a [u8], usize);
    impl Read for Trickle<'_> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.1.min(buf.len()).min(self.0.len());
            buf[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    #[test]
    fn a_stream_is_read_within_its_bounds_whatever_the_size_of_its_reads() {
        // `/dev/zero` as a program: 10 MB of it was read whole (and the device itself,
        // without end, until memory ran out); now refused at its first line.
        let e = read_stream(&mut std::io::repeat(0).take(10_000_000), 1 << 30).unwrap_err();
        assert!(
            e.to_string().starts_with("line 1 has no end within 1 MiB"),
            "{e}"
        );
        // The same line found whatever the reads' size: after 3 good lines.
        let mut long = "G1 X1\n".repeat(3).into_bytes();
        long.extend(std::iter::repeat_n(b'X', 3 << 20));
        for step in [1000, 4096, 65536, 1 << 20] {
            let e = read_stream(&mut Trickle(&long, step), 1 << 30).unwrap_err();
            assert!(
                e.to_string().starts_with("line 4 has no end"),
                "{step}: {e}"
            );
        }
        // Lines of a program come whole, up to the stream's end, however they are read;
        // a long line (a STEP entity) too.
        let text = "G1 X1 F100\n".repeat(20_000) + &"#1=(".repeat(20_000) + "\nM2";
        for step in [7, 4096, 65536] {
            let read = read_stream(&mut Trickle(text.as_bytes(), step), 1 << 30).unwrap();
            assert_eq!(read, text.as_bytes());
        }
        // Short lines without end (`yes`, `/dev/urandom`) stop at the bound.
        let e = read_stream(&mut std::io::repeat(b'\n').take(5_000_000), 1 << 20).unwrap_err();
        assert!(
            e.to_string().starts_with("more than 1 MiB from a pipe"),
            "{e}"
        );
    }

    #[test]
    fn a_device_as_a_program_is_refused_at_its_first_line() {
        let e = Source::load(Some(Path::new("/dev/zero")))
            .err()
            .unwrap_or_default();
        assert_eq!(
            e,
            "/dev/zero: line 1 has no end within 1 MiB: not a program (nothing after it read)"
        );
    }
}
