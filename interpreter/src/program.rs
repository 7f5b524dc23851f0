//! From lines of words to moves: the modal state machine of RS274/NGC (the subset this
//! stack runs so far), LinuxCNC's splines and NURBS (`G5`, `G5.1`, `G5.2/G5.3`, `G6.2`)
//! and Fanuc's `G06.2` NURBS. Positions are in mm whatever the program's units; the
//! machine starts at the origin.
//!
//! Every problem found is collected with its line and column; the whole program is read
//! even after an error, so `cnc check` can report everything at once.
//!
//! Parameters are set after their whole line is read, as LinuxCNC does. O-word
//! subroutines (`sub`/`endsub`/`call`/`return`) and control flow (`if`/`elseif`/`else`,
//! `while`, `do … while`, `repeat`, `break`, `continue`) run as in LinuxCNC: lines are
//! read again, with the parameters of the moment, each time the flow reaches them. A
//! subroutine the program does not define is read from its own file ([`subfile`]);
//! the moves made in it carry the line of the call in the program (a move's `line` is
//! always a line of the program's own file), its errors name the file and its line.
//!
//! The program's [`Dialect`] (LinuxCNC or Fanuc) is detected from the codes only one of
//! them has, or forced by the caller; see [`dialect`].
//!
//! Vocabulary: a *move* is one thing the machine does ([`Move`]); besides motion, the
//! path-control mode (`G61`, `G61.1`, `G64 P Q`), the spindle (`M3 M4 M5 S`) and the
//! program stops (`M0 M1`) are moves too, so the planner and the reports can see them.

mod arc;
mod comp;
pub mod dialect;
mod fanuc;
mod feed;
mod flow;
mod linuxcnc;
mod meet;
mod offset;
mod plain;
mod subfile;
pub mod tools;
mod usage;

use crate::parse::{flow, Diagnostic, LineReader, OKind, Params, Word};
pub use dialect::Dialect;
use dialect::DialectState;
use flow::Runner;
use shared::machine::{shown, MIN_FEED_MM_PER_MIN};

/// The plane of arcs and NURBS, by the axis normal to it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Plane {
    XY,
    ZX,
    YZ,
}

impl Plane {
    /// Axis normal to the plane (0 X, 1 Y, 2 Z).
    pub fn normal(self) -> usize {
        match self {
            Plane::XY => 2,
            Plane::ZX => 1,
            Plane::YZ => 0,
        }
    }
    /// The two in-plane axes, ordered so that (first × second) points along the normal.
    pub fn axes(self) -> (usize, usize) {
        let n = self.normal();
        ((n + 1) % 3, (n + 2) % 3)
    }
}

/// How consecutive moves join (RS274/NGC modal group 13).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PathControl {
    /// `G61`: follow the programmed path exactly, slowing as much as corners need.
    ExactPath,
    /// `G61.1`: come to a stop at the end of every move.
    ExactStop,
    /// `G64 [P…] [Q…]`: blend corners, within `tolerance_mm` of the path when given
    /// (`P`); `naive_cam_mm` is LinuxCNC's tolerance for merging nearly collinear short
    /// moves (`Q`, else `P`; none for a bare `G64`), see `blocks::naive_cam`.
    Blend {
        tolerance_mm: Option<f64>,
        naive_cam_mm: Option<f64>,
    },
}

/// Which way the spindle turns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpindleDir {
    /// `M3`
    Clockwise,
    /// `M4`
    CounterClockwise,
    /// `M5`
    Off,
}

/// A programmed stop of the whole program.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopKind {
    /// `M0`: stop until the operator resumes.
    Pause,
    /// `M1`: stop only when the operator's optional-stop switch is on.
    OptionalPause,
}

/// One thing the machine does, in mm and mm/min.
#[derive(Debug, Clone, PartialEq)]
pub enum Move {
    Line {
        line: u32,
        from: [f64; 3],
        to: [f64; 3],
        rapid: bool,
        feed: f64,
    },
    Arc {
        line: u32,
        from: [f64; 3],
        to: [f64; 3],
        center: [f64; 3],
        plane: Plane,
        ccw: bool,
        turns: u32,
        feed: f64,
    },
    Nurbs {
        line: u32,
        degree: usize,
        knots: Vec<f64>,
        ctrl: Vec<[f64; 4]>,
        feed: f64,
    },
    Dwell {
        line: u32,
        seconds: f64,
    },
    End {
        line: u32,
    },
    /// The path-control mode changes (`G61`, `G61.1`, `G64`) for the moves after it.
    PathMode {
        line: u32,
        control: PathControl,
    },
    /// The spindle starts, stops, reverses or changes speed (`M3`, `M4`, `M5`, `S`).
    Spindle {
        line: u32,
        dir: SpindleDir,
        rpm: f64,
    },
    /// A programmed stop (`M0`, `M1`); the program goes on when resumed.
    Stop {
        line: u32,
        kind: StopKind,
    },
}

impl Move {
    /// The source line the move carries.
    pub fn line(&self) -> u32 {
        match self {
            Move::Line { line, .. }
            | Move::Arc { line, .. }
            | Move::Nurbs { line, .. }
            | Move::Dwell { line, .. }
            | Move::End { line }
            | Move::PathMode { line, .. }
            | Move::Spindle { line, .. }
            | Move::Stop { line, .. } => *line,
        }
    }

    /// The source line the move carries, to change.
    fn line_mut(&mut self) -> &mut u32 {
        match self {
            Move::Line { line, .. }
            | Move::Arc { line, .. }
            | Move::Nurbs { line, .. }
            | Move::Dwell { line, .. }
            | Move::End { line }
            | Move::PathMode { line, .. }
            | Move::Spindle { line, .. }
            | Move::Stop { line, .. } => line,
        }
    }
}

/// A whole program, read and checked.
#[derive(Debug, Clone, Default)]
pub struct Program {
    pub moves: Vec<Move>,
    /// `(MSG, …)` texts with their lines.
    pub messages: Vec<(u32, String)>,
    /// The dialect the program was read in: forced by the caller, else detected from
    /// the codes it uses, else LinuxCNC (plain RS274/NGC).
    pub dialect: Dialect,
    /// The program turns cutter radius compensation on (`G41`, `G42`, `G41.1`,
    /// `G42.1`; under [`Options::uncompensated`] too, though it was not applied).
    pub compensated: bool,
    /// How many subroutine files it read (called by O-words, found in
    /// [`Options::subroutine_dirs`]).
    pub subroutine_files: usize,
}

/// How to read a program beyond its text.
#[derive(Debug, Clone, Default)]
pub struct Options {
    /// Read the program in this dialect instead of detecting it (`--dialect`).
    pub dialect: Option<Dialect>,
    /// Where `o<name> call` looks for `name.ngc` when the program does not define
    /// `o<name>` itself, in this order: the program's own directory first, then those
    /// of `--subroutine-path` (see [`subfile`]). Empty: no files are looked for.
    pub subroutine_dirs: Vec<std::path::PathBuf>,
    /// The tool table `G41`/`G42` take the radius from (`--tool-table`, see [`tools`]).
    pub tools: Option<tools::ToolTable>,
    /// How far (mm) the fitted offset of a NURBS move under `G41`/`G42` may stray from
    /// the true one: the machine's chord tolerance, [`DEFAULT_OFFSET_TOL_MM`] when not
    /// given.
    pub offset_tolerance_mm: Option<f64>,
    /// Read `G41`/`G42` but leave the moves where the program puts them: the programmed
    /// path of a compensated program, which the report draws beside the tool's.
    pub uncompensated: bool,
    /// The machine's `blend_tolerance_mm`: the tolerance a bare `G64` (no `P`, or `P0`)
    /// blends within, and the program's starting mode; 0 (the default) leaves both the
    /// exact path.
    pub blend_tolerance_mm: f64,
    /// What the program may do beyond its dialect's control (`--dialect-extension`).
    pub extensions: Vec<dialect::Extension>,
}

/// The offset tolerance of a program read without a machine: the built-in machine's
/// chord tolerance.
pub const DEFAULT_OFFSET_TOL_MM: f64 = 0.001;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    None,
    Rapid,
    Linear,
    Arc {
        ccw: bool,
    },
    /// LinuxCNC `G5`: a cubic Bézier per line.
    Cubic,
    /// LinuxCNC `G5.1`: a quadratic Bézier per line.
    Quadratic,
    /// Fanuc `G06.2` after a curve has closed: the next control point block opens
    /// another curve.
    FanucNurbs,
}

struct State {
    pos: [f64; 3],
    g62: Option<linuxcnc::G62Open>,
    fanuc: Option<fanuc::FanucOpen>,
    motion: Motion,
    plane: Plane,
    inch: bool,
    absolute: bool,
    arc_absolute: bool,
    /// The programmed feed in mm/min; in `G93` the last F (per minute, 1/time).
    feed: f64,
    /// `G93`: F on each feed move says in how many minutes⁻¹ the move is done.
    inverse_time: bool,
    /// `G41`/`G42` is active (or was asked for and refused: remembered so that `G06.2`
    /// can say PS1006).
    cutter_comp: bool,
    /// Cutter radius compensation while it is on (see [`comp`]).
    comp: Option<comp::Comp>,
    /// [`Options::offset_tolerance_mm`], mm.
    offset_tol: f64,
    /// [`Options::blend_tolerance_mm`], mm.
    blend_tol: f64,
    /// [`Options::uncompensated`].
    uncompensated: bool,
    /// [`dialect::Extension::FanucNurbsComp`]: `G06.2` under compensation is offset.
    fanuc_nurbs_comp: bool,
    /// [`Program::compensated`].
    compensated: bool,
    /// After `G40`: where the tool is, off the programmed point by the radius, for the
    /// move that takes it back to the programmed path.
    exit_from: Option<[f64; 3]>,
    /// Compensation made a move (see the end of [`interpret_lines`]).
    comp_used: bool,
    /// The tool table, if the program was given one.
    tools: Option<tools::ToolTable>,
    /// The tool the last `T` word selected, and the one in the spindle (`M6`; 0: none).
    selected_tool: Option<u32>,
    spindle_tool: u32,
    nurbs: Option<linuxcnc::NurbsOpen>,
    /// After a `G5`: the offset of the next `G5`'s first control point from its start
    /// (minus the last `P Q`), used when that `G5` leaves out `I J`.
    g5_tangent: Option<[f64; 2]>,
    spindle: (SpindleDir, f64),
    dialect: DialectState,
    /// The last Fanuc curve closed (for a knot block that comes after it).
    fanuc_closed: Option<fanuc::Closed>,
    /// Errors found on a line that still runs (a Fanuc curve it ended).
    deferred: Vec<Diagnostic>,
    ended: bool,
    /// The moves of `G4 P` dwells read before the program's dialect was known: seconds
    /// in LinuxCNC, milliseconds in Fanuc, so made a thousandth if it ends up Fanuc.
    dwells_in_doubt: Vec<usize>,
}

/// The longest line LinuxCNC reads, in bytes without the newline: its `fgets` buffer is
/// `LINELEN` = 255 bytes, and a line that fills it (253 bytes and the newline) is
/// refused as "Command too long" (checked with rs274 2.9: 252 pass, 253 fail).
const MAX_LINE_BYTES: usize = 252;

const AXES: [char; 3] = ['X', 'Y', 'Z'];

/// The longest dwell, s: a day. Longer is surely a mistake (a `G4 P` in milliseconds
/// read as seconds), and a dwell becomes a whole number of nanoseconds: 584 years at
/// most.
const MAX_DWELL_S: f64 = 86_400.0;
const OFFSETS: [char; 3] = ['I', 'J', 'K'];

struct LineWords<'a> {
    words: &'a [Word],
    line: u32,
    /// The letters the line has words of, a bit each ([`letter_bit`]): most letters a
    /// line is asked about it does not have, and those are answered without a look
    /// through its words.
    letters: u32,
    /// A letter other than `G` and `M` has two words or more (an error `execute` names).
    repeated: bool,
}

/// The bit of `letter` in [`LineWords::letters`]: `A` to `Z` are bits 0 to 25, anything
/// else (no word has it) bit 31.
const fn letter_bit(letter: char) -> u32 {
    if letter.is_ascii_uppercase() {
        1 << (letter as u32 - 'A' as u32)
    } else {
        1 << 31
    }
}

/// The bits of all of `letters` ([`letter_bit`]).
const fn letter_bits(letters: &str) -> u32 {
    let b = letters.as_bytes();
    let mut bits = 0;
    let mut i = 0;
    while i < b.len() {
        bits |= letter_bit(b[i] as char);
        i += 1;
    }
    bits
}

impl<'a> LineWords<'a> {
    fn new(words: &'a [Word], line: u32) -> Self {
        let mut letters = 0;
        let mut repeated = false;
        for w in words {
            let bit = letter_bit(w.letter);
            repeated |= letters & bit & !letter_bits("GM") != 0;
            letters |= bit;
        }
        LineWords {
            words,
            line,
            letters,
            repeated,
        }
    }
}

impl LineWords<'_> {
    fn get(&self, letter: char) -> Option<&Word> {
        if self.letters & letter_bit(letter) == 0 {
            return None;
        }
        self.words.iter().find(|w| w.letter == letter)
    }
    fn value(&self, letter: char) -> Option<f64> {
        self.get(letter).map(|w| w.value)
    }
    fn has_any(&self, letters: &str) -> bool {
        self.letters & letter_bits(letters) != 0
    }
    fn first_col(&self) -> u32 {
        self.words.first().map_or(1, |w| w.col)
    }
    fn err(&self, rule: &'static str, col: u32, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            file: None,
            line: self.line,
            col,
            rule,
            message: message.into(),
        }
    }
}

/// Reads and checks a whole program, detecting its dialect. All problems are returned,
/// not only the first.
///
/// O-word subroutines and control flow run as LinuxCNC runs them, within this file:
/// a `sub … endsub` is skipped where it stands and entered by `call`, conditions are
/// evaluated when their line is reached, and a line is read again (with the parameters
/// of that moment) each time the flow comes back to it.
pub fn interpret(text: &str) -> Result<Program, Vec<Diagnostic>> {
    interpret_with(text, &Options::default())
}

/// [`interpret`], with the dialect forced or other options.
pub fn interpret_with(text: &str, opts: &Options) -> Result<Program, Vec<Diagnostic>> {
    interpret_lines(text, opts, Way::Short, None)
}

/// Where [`interpret_batched`] hands the moves over as it reads.
pub struct Batches<'f> {
    /// Moves to gather before a batch is handed over (more where a batch cannot end
    /// yet: see [`interpret_batched`]).
    pub every: usize,
    /// Takes each batch, in program order, and what was read by then.
    pub sink: &'f mut dyn FnMut(Vec<Move>, Read),
    /// Told of each stretch of the text, as byte offsets `from..to`, that the reading
    /// is done with for now (it may come back to it only to name a problem's column): a
    /// program read in order (without O-words) is looked through once for its lines
    /// and then read, a stretch at a time. A mapped file can give those pages back.
    pub release: &'f mut dyn FnMut(usize, usize),
}

/// What the reading had got to when a batch was handed over.
#[derive(Debug, Clone, Copy)]
pub struct Read {
    /// No problem found in the lines read so far.
    pub clean: bool,
    /// The batch has a `G4 P` dwell read before the dialect was known, in seconds: if
    /// the program turns out to be Fanuc's, it was milliseconds (and the program must
    /// be read again as Fanuc's).
    pub in_doubt: bool,
}

/// [`interpret_with`], handing the moves over in batches as the program is read, so
/// that a long one need not be held whole: the moves handed to `batches` and then those
/// of the returned program (the last, ending with its end) are, in order, the moves
/// [`interpret_with`] gives, bit for bit, and the problems are the same.
///
/// A batch ends between lines, and never while a move already made may still change
/// (while cutter compensation is on, its last moves wait for the next corner). A `G4 P`
/// dwell read before the dialect was known is handed over in seconds, and the batch
/// says so ([`Read::in_doubt`]): should the program turn out to be Fanuc's, those are
/// the only moves that differ, and the caller reads it again as Fanuc's. The program's
/// own facts (its dialect, its messages) are in the returned program, as is every
/// problem found.
pub fn interpret_batched(
    text: &str,
    opts: &Options,
    batches: Batches<'_>,
) -> Result<Program, Vec<Diagnostic>> {
    interpret_lines(text, opts, Way::Short, Some(batches))
}

/// How [`interpret_lines`] reads plain straight moves.
#[derive(Clone, Copy, PartialEq)]
enum Way {
    /// The short way ([`plain`]), the general one for every other line.
    Short,
    /// Every line the general way: what the short way is held to (tests).
    #[cfg_attr(not(test), allow(dead_code))]
    General,
}

/// [`interpret_with`], reading plain straight moves as `way` says.
fn interpret_lines(
    text: &str,
    opts: &Options,
    way: Way,
    mut batches: Option<Batches<'_>>,
) -> Result<Program, Vec<Diagnostic>> {
    let mut st = State {
        pos: [0.0; 3],
        g62: None,
        fanuc: None,
        motion: Motion::None,
        plane: Plane::XY,
        inch: false,
        absolute: true,
        arc_absolute: false,
        feed: 0.0,
        inverse_time: false,
        cutter_comp: false,
        comp: None,
        offset_tol: opts.offset_tolerance_mm.unwrap_or(DEFAULT_OFFSET_TOL_MM),
        blend_tol: opts.blend_tolerance_mm,
        uncompensated: opts.uncompensated,
        fanuc_nurbs_comp: opts
            .extensions
            .contains(&dialect::Extension::FanucNurbsComp),
        compensated: false,
        exit_from: None,
        comp_used: false,
        tools: opts.tools.clone(),
        selected_tool: None,
        spindle_tool: 0,
        nurbs: None,
        g5_tangent: None,
        spindle: (SpindleDir::Off, 0.0),
        dialect: DialectState::new(opts.dialect),
        fanuc_closed: None,
        deferred: Vec::new(),
        ended: false,
        dwells_in_doubt: Vec::new(),
    };
    let mut params = Params::default();
    let mut prog = Program::default();
    let mut errors = Vec::new();
    // A program without O-words (most CAM output) runs its lines in order, each once:
    // they are split off the text as they are read, without a list of them (16 bytes
    // a line). Any other is listed, for its flow to jump about in.
    let (listed, counted) = match &mut batches {
        None => (subfile::may_have_o_words(text), None),
        Some(b) => {
            let (o, n) = looked_through(text, b.release);
            (o, Some(n))
        }
    };
    let mut lines = if listed { lines_of(text) } else { Vec::new() };
    let mut in_order = (!listed).then(|| LineSplitter::new(text));
    let own_lines = if listed {
        lines.len()
    } else {
        counted.unwrap_or_else(|| line_count(text))
    };
    // The text read and given back (batches of a program read in order).
    let mut released = 0;
    // (Without an `o` anywhere there are none: not looked for again.)
    let mut o_words = if listed {
        subfile::o_words_of(text, &lines, 1)
    } else {
        Vec::new()
    };
    let (mut flow, flow_errors) = flow(&o_words);
    errors.extend(flow_errors);
    // Subroutine files join the program after its own lines.
    let (files, missing) = subfile::load(&o_words, &opts.subroutine_dirs);
    prog.subroutine_files = files.len();
    // About a move a line in the programs that are long (CAM output): one allocation,
    // not a list copied each time it doubles (mapped at once, see `pages`).
    match &batches {
        None => {
            prog.moves.reserve(own_lines);
            crate::pages::prefer_huge_pages(&prog.moves);
        }
        Some(b) => prog.moves.reserve(batch_room(b.every, own_lines)),
    }
    // LinuxCNC and Fanuc both start in `G64`: a bare one, within the machine's tolerance.
    if let Some(control) = bare_g64(st.blend_tol, None) {
        prog.moves.push(Move::PathMode { line: 1, control });
    }
    let mut units = subfile::Units::default();
    for f in &files {
        let start = lines.len();
        let file_lines = lines_of(&f.text);
        let file_o_words = subfile::o_words_of(&f.text, &file_lines, 1);
        units.append(&f.path, start, &file_o_words, &mut flow, &mut errors);
        lines.extend(file_lines);
        // A list without O-words is empty: filled up to the file's first line.
        o_words.resize_with(start, || None);
        o_words.extend(file_o_words);
    }
    // Files come only with O-words (their calls), so only a listed program has any.
    let all_lines = if listed { lines.len() } else { own_lines };
    let mut run = Runner::new(o_words, all_lines, flow, missing);
    let last_line = own_lines as u32;
    let mut pc = 0;
    let mut reader = LineReader::default();
    // The program ends at its own last line; the files after it run only when called.
    while pc < all_lines && pc != own_lines {
        let line = pc as u32 + 1;
        if st.ended {
            break; // LinuxCNC ignores everything after M2/M30.
        }
        if let Some(b) = &mut batches {
            if prog.moves.len() >= b.every && st.comp.is_none() {
                if st.comp_used {
                    drop_empty_lines(&mut prog.moves);
                }
                if let Some(at) = in_order.as_ref().map(|s| s.at) {
                    (b.release)(released, at);
                    released = at;
                }
                let read = Read {
                    clean: errors.is_empty(),
                    in_doubt: !st.dwells_in_doubt.is_empty(),
                };
                st.dwells_in_doubt.clear();
                let next = Vec::with_capacity(batch_room(b.every, own_lines));
                (b.sink)(std::mem::replace(&mut prog.moves, next), read);
            }
        }
        let here = pc;
        pc += 1;
        if let Err(d) = run.count_line(here) {
            errors.push(d);
            break;
        }
        // A plain straight move (most lines of CAM output) the short way; a line of the
        // program's own (not of a subroutine file) carries its own number.
        let plain = match &mut in_order {
            _ if way == Way::General => None,
            Some(split) => {
                plain::run(&mut st, split.rest(), line, &mut prog.moves).map(|len| split.pass(len))
            }
            None if here < own_lines => {
                plain::run(&mut st, lines[here].as_bytes(), line, &mut prog.moves).map(drop)
            }
            None => None,
        };
        if plain.is_some() {
            continue;
        }
        // Without O-words nothing jumps: line `here` is the next one split off.
        let raw = match &mut in_order {
            Some(split) => split.next().unwrap_or_default(),
            None => lines[here],
        };
        if raw.len() > MAX_LINE_BYTES {
            let col = raw
                .char_indices()
                .take_while(|(b, _)| *b < MAX_LINE_BYTES)
                .count();
            errors.push(Diagnostic {
                file: None,
                line,
                col: col as u32 + 1,
                rule: "line-length",
                message: format!(
                    "line longer than {MAX_LINE_BYTES} characters (LinuxCNC's limit, \"Command too long\"): split it"
                ),
            });
            pc = run.unreadable(here);
            continue;
        }
        let parsed = match reader.read(raw, line, &params) {
            Ok(l) => l,
            Err(d) => {
                errors.push(d);
                pc = run.unreadable(here);
                continue;
            }
        };
        // Moves and messages of a subroutine file carry the line of its call in the
        // program: a block's source line is a line of the program's own file.
        let shown_line = run.line_before(here, own_lines) as u32 + 1;
        for m in &parsed.messages {
            prog.messages.push((shown_line, m.clone()));
        }
        if let Some(o) = &parsed.o_word {
            if o.kind == OKind::ProgramNumber {
                if let Err(d) = st
                    .dialect
                    .claim(Dialect::Fanuc, line, o.col, "a program number O…")
                {
                    errors.push(d);
                }
                continue;
            }
            match run.step(here, o, &mut params, &mut errors) {
                Some(next) => pc = next,
                None => break,
            }
            continue;
        }
        let lw = LineWords::new(&parsed.words, line);
        let before = prog.moves.len();
        if let Err(d) = execute(&mut st, &lw, &mut prog.moves) {
            // After a compensated move is refused the tool's place is not known: the
            // moves until `G40` run uncompensated, rather than each be refused again
            // for where the refused one left the tool.
            if d.rule == "G41/G42" {
                st.comp = None;
            }
            errors.push(d);
        }
        if shown_line != line {
            prog.moves[before..]
                .iter_mut()
                .for_each(|m| *m.line_mut() = shown_line);
        }
        errors.append(&mut st.deferred);
        if st.inverse_time {
            if let Some((length, mm_per_min)) = feed::inverse_time(&mut prog.moves[before..]) {
                errors.push(lw.err(
                    "G93",
                    lw.get('F').map_or(lw.first_col(), |f| f.col),
                    format!(
                        "inverse time: this {} mm move in 1/F minutes is a feed of \
                         {} mm/min, below the slowest feed, {MIN_FEED_MM_PER_MIN} \
                         mm/min (LinuxCNC raises such a feed to its floor of 0.1 units a \
                         minute; here F must ask for it): raise F or merge the move",
                        shown(length),
                        shown(mm_per_min)
                    ),
                ));
            }
        }
        for (p, v) in &parsed.assignments {
            params.set(p, *v);
        }
    }
    // A line read again and again (in a loop) reports its problem once.
    let mut seen = std::collections::HashSet::new();
    errors.retain(|d: &Diagnostic| seen.insert((d.file.clone(), d.line, d.col, d.message.clone())));
    if let Some(n) = &st.g62 {
        errors.push(Diagnostic {
            file: None,
            line: n.line,
            col: n.col,
            rule: "G6.2",
            message: format!(
                "G6.2 NURBS is never closed: {} knot-only `G6.2 K…` lines of {} follow its control points",
                n.closing, n.order
            ),
        });
    }
    if let Some(n) = st.fanuc.take() {
        errors.extend(n.unfinished(last_line.max(1), 1, "the end of the program"));
    }
    if let Some(n) = &st.nurbs {
        errors.push(Diagnostic {
            file: None,
            line: n.line,
            col: n.col,
            rule: "G5.2",
            message: "G5.2 NURBS is never closed with G5.3".into(),
        });
    }
    if !st.ended {
        prog.moves.push(Move::End { line: last_line });
    }
    prog.dialect = st.dialect.resolved();
    prog.compensated = st.compensated;
    if prog.dialect == Dialect::Fanuc {
        for &i in &st.dwells_in_doubt {
            if let Move::Dwell { seconds, .. } = &mut prog.moves[i] {
                *seconds /= 1000.0;
            }
        }
    }
    if st.comp_used {
        drop_empty_lines(&mut prog.moves);
    }
    errors.iter_mut().for_each(|d| units.locate(d));
    if errors.is_empty() {
        Ok(prog)
    } else {
        Err(errors)
    }
}

/// Room for a batch of `every` moves (a line may make a few) in a program of `lines`.
fn batch_room(every: usize, lines: usize) -> usize {
    every.min(lines).saturating_add(every.min(lines) / 8)
}

/// A compensated move cut short to nothing at a concave corner: LinuxCNC sends it, it
/// moves nothing, and a block must have a length. (Only compensation makes such moves.)
fn drop_empty_lines(moves: &mut Vec<Move>) {
    moves.retain(|m| !matches!(m, Move::Line { from, to, .. } if from == to));
}

/// The lines of `text`, as `str::lines` gives them (split at `\n`, a `\r` before it
/// dropped, no empty line after a final `\n`), in a list sized once ([`LineSplitter`]).
/// `str::lines` looks for each line's end with a search set up afresh for every line,
/// and the list it is collected into doubles and copies as it grows: for 100 000 short
/// lines of CAM output, a seventh of `cnc check`'s instructions.
fn lines_of(text: &str) -> Vec<&str> {
    let mut lines = Vec::with_capacity(line_count(text));
    crate::pages::prefer_huge_pages(&lines);
    lines.extend(LineSplitter::new(text));
    lines
}

/// How many lines [`lines_of`] finds in `text`: one a `\n`, and the last one without.
/// Whether `text` may have O-words ([`subfile::may_have_o_words`]) and its
/// [`line_count`], looked through a stretch at a time, each `release`d behind.
fn looked_through(text: &str, release: &mut dyn FnMut(usize, usize)) -> (bool, usize) {
    const STRETCH: usize = 1 << 22;
    let bytes = text.as_bytes();
    let (mut o_words, mut newlines_seen) = (false, 0);
    for (k, chunk) in bytes.chunks(STRETCH).enumerate() {
        // (`may_have_o_words` looks at bytes: a stretch may end inside a character.)
        o_words |= chunk.iter().any(|b| b | 0x20 == b'o');
        newlines_seen += newlines(chunk);
        release(k * STRETCH, k * STRETCH + chunk.len());
    }
    let n = newlines_seen + usize::from(!text.is_empty() && !text.ends_with('\n'));
    (o_words, n)
}

fn line_count(text: &str) -> usize {
    newlines(text.as_bytes()) + usize::from(!text.is_empty() && !text.ends_with('\n'))
}

/// The lines of a text one after the other, as `str::lines` gives them. The text is
/// looked at eight bytes at a time, as one 64-bit word whose `\n` bytes come out as a
/// bit mask ([`newline_mask`]), so a line's end is found without a look at each byte.
struct LineSplitter<'a> {
    text: &'a str,
    /// Where the next line starts.
    at: usize,
}

impl<'a> LineSplitter<'a> {
    fn new(text: &'a str) -> Self {
        LineSplitter { text, at: 0 }
    }

    /// The text from the next line's start to the end.
    fn rest(&self) -> &'a [u8] {
        &self.text.as_bytes()[self.at..]
    }

    /// Passes the next line, `len` bytes before its `\n` (or the text's end), as
    /// [`Iterator::next`] would.
    fn pass(&mut self, len: usize) {
        self.at = (self.at + len + 1).min(self.text.len());
    }
}

impl<'a> Iterator for LineSplitter<'a> {
    type Item = &'a str;

    fn next(&mut self) -> Option<&'a str> {
        let bytes = self.text.as_bytes();
        if self.at >= bytes.len() {
            return None;
        }
        let mut end = self.at;
        let newline = loop {
            let Some(word) = bytes.get(end..end + 8) else {
                break bytes[end..]
                    .iter()
                    .position(|&b| b == b'\n')
                    .map(|i| end + i);
            };
            let mask = newline_mask(word.try_into().expect("8 bytes"));
            if mask != 0 {
                break Some(end + mask.trailing_zeros() as usize / 8);
            }
            end += 8;
        };
        // `\n` and `\r` are ASCII: slicing at them keeps the text's characters whole.
        let line = match newline {
            Some(nl) => {
                let line = &self.text[self.at..nl];
                self.at = nl + 1;
                line.strip_suffix('\r').unwrap_or(line)
            }
            // The last line, when the text does not end with `\n`, keeps a final `\r`.
            None => {
                let line = &self.text[self.at..];
                self.at = bytes.len();
                line
            }
        };
        Some(line)
    }
}

/// The high bit of each byte of `word` (little-endian) that is `\n`, the others zero.
/// Exact for every byte: each is compared on its own low seven bits, with no carry into
/// the next (the usual "has a zero byte" test flags some bytes after a zero as zeros).
fn newline_mask(word: [u8; 8]) -> u64 {
    const LOW7: u64 = 0x7f7f_7f7f_7f7f_7f7f;
    let x = u64::from_le_bytes(word) ^ 0x0a0a_0a0a_0a0a_0a0a;
    // A byte's high bit ends up set where its low seven bits carry into it (they are not
    // all zero) or it was set itself: where the byte is not zero.
    !(((x & LOW7) + LOW7) | x | LOW7)
}

/// How many `\n` bytes `bytes` holds: [`newline_mask`]s added up a byte lane each
/// (the mask's bit moved to the lane's lowest), 255 words at most before a lane could
/// overflow, then the eight lanes summed.
fn newlines(bytes: &[u8]) -> usize {
    const LANES_PER_SUM: usize = 255 * 8;
    let whole = bytes.len() / 8 * 8;
    let mut total = bytes[whole..].iter().filter(|&&b| b == b'\n').count();
    for block in bytes[..whole].chunks(LANES_PER_SUM) {
        let lanes = block.chunks_exact(8).fold(0u64, |sum, word| {
            sum + (newline_mask(word.try_into().expect("8 bytes")) >> 7)
        });
        // Eight counts of at most 255, as four of at most 510, summed in the top 16 bits.
        const EVEN: u64 = 0x00ff_00ff_00ff_00ff;
        let fours = (lanes & EVEN) + ((lanes >> 8) & EVEN);
        total += (fours.wrapping_mul(0x0001_0001_0001_0001) >> 48) as usize;
    }
    total
}

fn gcode(w: &Word) -> Option<u32> {
    // A whole number of tenths (`G1`, `G64`, `G5.2`: nearly every code) is its own
    // rounding, so the `round` below (a call into libm) would give it back unchanged.
    let t = w.value * 10.0;
    if (0.0..4e9).contains(&t) && f64::from(t as u32) == t {
        return Some(t as u32);
    }
    let tenths = t.round();
    ((tenths - t).abs() < 1e-6 && tenths >= 0.0).then_some(tenths as u32)
}

/// The G-codes of a line that start or shape motion, by kind.
#[derive(Default)]
struct LineCodes<'a> {
    motion: Option<(&'a Word, Motion)>,
    nurbs_open: Option<&'a Word>,
    nurbs_close: Option<&'a Word>,
    g62: Option<&'a Word>,
    dwell: Option<&'a Word>,
    /// Fanuc `G05`/`G05.1` (high-precision / AI contour control on or off).
    fanuc_mode: Option<&'a Word>,
    path: Option<(&'a Word, u32)>,
    /// `G40`, `G41`, `G41.1`, `G42`, `G42.1`.
    comp: Option<(&'a Word, u32)>,
}

fn execute(st: &mut State, lw: &LineWords, moves: &mut Vec<Move>) -> Result<(), Diagnostic> {
    // One value per letter (G and M may repeat, for different groups), of the letters
    // this stack knows. Most lines pass both checks, which the letters the line has
    // answer at once; any other is looked through for the first word that fails.
    if lw.repeated || lw.letters & !KNOWN_LETTERS != 0 {
        check_letters(lw)?;
    }
    // Filled where it stays: returned inside a `Result`, its 100 bytes were copied
    // field by field, then read back as wider words than were written, which the
    // processor cannot forward from its stores (a stall of its own, every line).
    let mut codes = LineCodes::default();
    let (plane, inverse) = (st.plane, st.inverse_time);
    g_codes(st, lw, &mut codes)?;
    // G20/G21 on this line already apply to its own numbers.
    let unit = if st.inch { 25.4 } else { 1.0 };
    comp_codes(st, lw, &codes, plane, inverse, unit, moves)?;

    // An open Fanuc curve takes its control point and knot blocks; any other command
    // ends it (an alarm), and the line then runs as it would have.
    if st.fanuc.is_some() {
        if fanuc::continues(lw, &codes) {
            let before = moves.len();
            fanuc::block(st, lw, unit, moves)?;
            return compensate_curve(st, lw, moves, before);
        }
        let (col, what) = fanuc::interrupter(lw);
        if let Some(n) = st.fanuc.take() {
            st.deferred.extend(n.unfinished(lw.line, col, &what));
            st.motion = Motion::None;
        }
    }
    if let Some(f) = lw.get('F') {
        if f.value < 0.0 {
            return Err(lw.err("feed", f.col, "F must not be negative"));
        }
        // In G93, F is the inverse of the move's time: no length unit.
        st.feed = if st.inverse_time {
            f.value
        } else {
            f.value * unit
        };
    }
    let mut end = false;
    let mut stop = None;
    let mut spindle = st.spindle;
    if let Some(s) = lw.get('S') {
        if s.value < 0.0 {
            return Err(lw.err("spindle", s.col, "S (spindle speed) must not be negative"));
        }
        spindle.1 = s.value;
    }
    for w in lw.words.iter().filter(|w| w.letter == 'M') {
        match gcode(w) {
            Some(20) | Some(300) => end = true,
            Some(0) => stop = Some(StopKind::Pause),
            Some(10) => stop = Some(StopKind::OptionalPause),
            Some(30) => spindle.0 = SpindleDir::Clockwise,
            Some(40) => spindle.0 = SpindleDir::CounterClockwise,
            Some(50) => spindle.0 = SpindleDir::Off,
            // The tool change (read before the compensation codes, see `comp_codes`);
            // coolant: accepted, nothing of ours depends on it.
            Some(60 | 70 | 80 | 90) => {}
            _ => return Err(lw.err("modal", w.col, format!("M{} is not supported", w.value))),
        }
    }
    let curve_open = st.g62.is_some() || st.nurbs.is_some();
    if curve_open && (spindle != st.spindle || stop.is_some() || codes.path.is_some()) {
        return Err(lw.err(
            "NURBS",
            lw.first_col(),
            "spindle, stop or path-mode change inside an open NURBS: close the curve first",
        ));
    }
    if spindle != st.spindle {
        st.spindle = spindle;
        moves.push(Move::Spindle {
            line: lw.line,
            dir: spindle.0,
            rpm: spindle.1,
        });
    }
    if let Some((w, code)) = codes.path {
        moves.push(Move::PathMode {
            line: lw.line,
            control: path_control(lw, w, code, unit, st.blend_tol)?,
        });
    }
    if let Some(w) = codes.fanuc_mode {
        fanuc::precision_mode(st, lw, w)?;
    }
    motion(st, lw, &codes, unit, moves, end)?;
    // A stop or the end, after the line's motion (as LinuxCNC): the open moves end
    // where they are; at the end compensation is off.
    if stop.is_some() || end {
        comp::settle(st, lw, moves)?;
    }
    if end {
        st.comp = None;
        st.cutter_comp = false;
    }
    if let Some(kind) = stop {
        moves.push(Move::Stop {
            line: lw.line,
            kind,
        });
    }
    if end {
        moves.push(Move::End { line: lw.line });
        st.ended = true;
    }
    Ok(())
}

/// The letters of the words [`check_letters`] lets pass.
const KNOWN_LETTERS: u32 = letter_bits("GMXYZIJKRFPLNSTQD");

/// The first word of a letter met before on its line (`G` and `M` aside), or of a letter
/// this stack does not know, as an error.
fn check_letters(lw: &LineWords) -> Result<(), Diagnostic> {
    for (i, w) in lw.words.iter().enumerate() {
        if w.letter != 'G' && w.letter != 'M' && lw.words[..i].iter().any(|o| o.letter == w.letter)
        {
            return Err(lw.err(
                "word",
                w.col,
                format!("{} word appears twice on one line", w.letter),
            ));
        }
        match w.letter {
            'G' | 'M' | 'X' | 'Y' | 'Z' | 'I' | 'J' | 'K' | 'R' | 'F' | 'P' | 'L' | 'N' | 'S'
            | 'T' | 'Q' | 'D' => {}
            'A' | 'B' | 'C' | 'U' | 'V' | 'W' => {
                return Err(lw.err(
                    "word",
                    w.col,
                    format!("{} axis: this machine has only X, Y and Z", w.letter),
                ))
            }
            c => return Err(lw.err("word", w.col, format!("{c} word is not supported"))),
        }
    }
    Ok(())
}

/// Reads the G-codes of a line into `c`: modal groups checked, modal state set.
fn g_codes<'a>(st: &mut State, lw: &'a LineWords, c: &mut LineCodes<'a>) -> Result<(), Diagnostic> {
    // The word of each modal group met so far (group 0, the non-modal codes, may repeat).
    let mut groups: [Option<&Word>; 15] = [None; 15];
    for w in lw.words.iter().filter(|w| w.letter == 'G') {
        let code = gcode(w)
            .ok_or_else(|| lw.err("modal", w.col, format!("G{} is not a G-code", w.value)))?;
        let group = match code {
            0 | 10 | 20 | 30 | 52 | 53 | 62 | 800 => 1,
            // G5 and G5.1 are motions in LinuxCNC, one-shot mode switches in Fanuc.
            50 | 51 if fanuc::is_precision_mode(lw, code) => 0,
            50 | 51 => 1,
            40 => 0,
            170 | 180 | 190 => 2,
            200 | 210 => 6,
            900 | 910 => 3,
            901 | 911 => 4,
            930 | 940 => 5,
            400 | 410 | 411 | 420 | 421 => 7,
            490 => 8,
            540..=590 => 12,
            610 | 611 | 640 => 13,
            960 | 970 => 14,
            _ => return Err(lw.err("modal", w.col, format!("G{} is not supported", w.value))),
        };
        if let Some(other) = groups[group].filter(|_| group != 0) {
            return Err(lw.err(
                "modal",
                w.col,
                format!(
                    "G{} and G{} are in the same modal group",
                    other.value, w.value
                ),
            ));
        }
        groups[group] = Some(w);
        match code {
            0 => c.motion = Some((w, Motion::Rapid)),
            10 => c.motion = Some((w, Motion::Linear)),
            20 => c.motion = Some((w, Motion::Arc { ccw: false })),
            30 => c.motion = Some((w, Motion::Arc { ccw: true })),
            50 | 51 if group == 0 => c.fanuc_mode = Some(w),
            50 => c.motion = Some((w, Motion::Cubic)),
            51 => c.motion = Some((w, Motion::Quadratic)),
            52 => c.nurbs_open = Some(w),
            53 => c.nurbs_close = Some(w),
            62 => c.g62 = Some(w),
            800 => c.motion = Some((w, Motion::None)),
            40 => c.dwell = Some(w),
            170 => st.plane = Plane::XY,
            180 => st.plane = Plane::ZX,
            190 => st.plane = Plane::YZ,
            200 => st.inch = true,
            210 => st.inch = false,
            900 => st.absolute = true,
            910 => st.absolute = false,
            901 => st.arc_absolute = true,
            911 => st.arc_absolute = false,
            930 | 940 => {
                // LinuxCNC forgets the feed when the feed mode changes.
                let inverse = code == 930;
                if inverse != st.inverse_time {
                    st.feed = 0.0;
                }
                st.inverse_time = inverse;
            }
            400 | 410 | 411 | 420 | 421 => c.comp = Some((w, code)),
            610 | 611 | 640 => c.path = Some((w, code)),
            _ => {} // G49, G54..G59 (zero offsets), G96/G97: accepted, no effect yet
        }
    }
    Ok(())
}

/// A bare `G64` (no tolerance, or `P0`) on a machine whose `blend_tolerance_mm` is
/// `blend_tol`: a blend within it; `None` where it is 0 (the exact path, as before).
fn bare_g64(blend_tol: f64, naive_cam_mm: Option<f64>) -> Option<PathControl> {
    (blend_tol > 0.0).then_some(PathControl::Blend {
        tolerance_mm: Some(blend_tol),
        naive_cam_mm,
    })
}

fn path_control(
    lw: &LineWords,
    w: &Word,
    code: u32,
    unit: f64,
    blend_tol: f64,
) -> Result<PathControl, Diagnostic> {
    let tol = |letter: char| -> Result<Option<f64>, Diagnostic> {
        match lw.get(letter) {
            Some(p) if p.value < 0.0 => Err(lw.err(
                "G64",
                p.col,
                format!("{letter} (a tolerance) must not be negative"),
            )),
            Some(p) => Ok(Some(p.value * unit)),
            None => Ok(None),
        }
    };
    Ok(match code {
        610 => PathControl::ExactPath,
        611 => PathControl::ExactStop,
        _ => {
            let tolerance_mm = tol('P')?;
            let naive_cam_mm = tol('Q')?;
            if naive_cam_mm.is_some() && tolerance_mm.is_none() {
                return Err(lw.err("G64", w.col, "Q needs P too (Q is only read after P)"));
            }
            // Without `Q`, LinuxCNC merges within `P` (`crate::blocks::naive_cam`).
            let naive_cam_mm = naive_cam_mm.or(tolerance_mm).filter(|q| *q > 0.0);
            // (LinuxCNC's `P0` is its bare `G64`.)
            let bare = tolerance_mm.is_none_or(|t| t == 0.0);
            match bare.then(|| bare_g64(blend_tol, naive_cam_mm)).flatten() {
                Some(blend) => blend,
                None => PathControl::Blend {
                    tolerance_mm,
                    naive_cam_mm,
                },
            }
        }
    })
}

/// A NURBS move this line closed (the moves from `before` on) made into its offset, when
/// cutter radius compensation is on.
fn compensate_curve(
    st: &mut State,
    lw: &LineWords,
    moves: &mut Vec<Move>,
    before: usize,
) -> Result<(), Diagnostic> {
    if !comp::active(st) || moves.len() == before {
        return Ok(());
    }
    if !matches!(moves.last(), Some(Move::Nurbs { .. })) {
        return Ok(());
    }
    let m = moves.pop().unwrap_or_else(|| unreachable!());
    let tol = st.offset_tol;
    comp::nurbs(st, lw, m, tol, moves)?;
    st.comp_used = true;
    Ok(())
}

/// The motion of a line: curves opened or continued, dwell, straight and arc moves.
fn motion(
    st: &mut State,
    lw: &LineWords,
    codes: &LineCodes,
    unit: f64,
    moves: &mut Vec<Move>,
    end: bool,
) -> Result<(), Diagnostic> {
    let motion_word = codes.motion.map(|m| m.0);
    let curve = codes.g62.or(codes.nurbs_open).or(match codes.motion {
        Some((w, Motion::Cubic | Motion::Quadratic)) => Some(w),
        _ => None,
    });
    // NURBS moves are compensated (`comp::nurbs`); the Bézier splines are not, as in
    // LinuxCNC.
    let spline_only = match codes.motion {
        Some((w, Motion::Cubic | Motion::Quadratic)) => Some(w),
        _ => None,
    };
    let refused = if st.exit_from.is_some() {
        curve
    } else if st.comp.is_some() {
        spline_only
    } else {
        None
    };
    if let Some(w) = refused {
        let why = if st.comp.is_some() {
            "cutter radius compensation is on (G41/G42): it works on straight moves, arcs and NURBS (G5.2, G6.2); turn it off with G40 first"
        } else {
            "the move just after G40 must be straight (G0 or G1): it takes the tool from its offset path back to the programmed one"
        };
        return Err(lw.err(
            "G41/G42",
            w.col,
            format!("G{} curve while {why}", shown(w.value)),
        ));
    }
    // G6.2 is LinuxCNC's NURBS with a method Q, or Fanuc's G06.2.
    if st.g62.is_none() {
        let fanuc_open = match codes.g62 {
            Some(g) => fanuc::is_fanuc_g62(st, lw).then_some(g),
            None if st.motion == Motion::FanucNurbs
                && codes.motion.is_none()
                && lw.has_any("XYZK") =>
            {
                lw.words.first()
            }
            None => None,
        };
        if let Some(g) = fanuc_open {
            st.dialect.claim(Dialect::Fanuc, lw.line, g.col, "G06.2")?;
            return fanuc::open(st, lw, g, unit);
        }
    }
    // G6.2: control points with their knots, then `order` knot-only lines close it.
    if st.g62.is_some() || codes.g62.is_some() {
        if let (None, Some(g)) = (&st.g62, codes.g62) {
            st.dialect
                .claim(Dialect::LinuxCnc, lw.line, g.col, "G6.2 with Q")?;
        }
        let before = moves.len();
        linuxcnc::g62_line(st, lw, codes.g62, motion_word, unit, moves, end)?;
        return compensate_curve(st, lw, moves, before);
    }
    // Inside an open G5.2 block every line is a control point (or the G5.3 that closes it).
    if st.nurbs.is_some() || codes.nurbs_open.is_some() {
        if let Some(g) = codes.nurbs_open {
            st.dialect
                .claim(Dialect::LinuxCnc, lw.line, g.col, "G5.2")?;
        }
        let before = moves.len();
        linuxcnc::nurbs_line(
            st,
            lw,
            codes.nurbs_open,
            codes.nurbs_close,
            motion_word,
            unit,
            moves,
            end,
        )?;
        return compensate_curve(st, lw, moves, before);
    }
    if let Some(w) = codes.nurbs_close {
        return Err(lw.err("G5.3", w.col, "no G5.2 NURBS is open for it to close"));
    }
    if let Some(w) = codes.dwell {
        // LinuxCNC: `G4 P` in seconds. Fanuc: `G04 X` in seconds, `G04 P` in
        // milliseconds (its P takes no decimal point): `G04 P500` is half a second, not
        // eight minutes.
        let (seconds, word) = if let Some(x) = lw.get('X') {
            st.dialect
                .claim(Dialect::Fanuc, lw.line, x.col, "G04 X (a dwell in seconds)")?;
            (x.value, x)
        } else {
            let p = lw.get('P').ok_or_else(|| {
                lw.err(
                    "G4",
                    w.col,
                    "dwell needs P (seconds; in Fanuc programs milliseconds, or X in seconds)",
                )
            })?;
            match st.dialect.known() {
                Some(Dialect::Fanuc) => (p.value / 1000.0, p),
                Some(Dialect::LinuxCnc) => (p.value, p),
                None => {
                    st.dwells_in_doubt.push(moves.len());
                    (p.value, p)
                }
            }
        };
        if seconds < 0.0 {
            return Err(lw.err(
                "G4",
                word.col,
                format!("dwell time {} must not be negative", word.letter),
            ));
        }
        // A `G4 P` read before the dialect is known may yet be milliseconds.
        let least = if st.dwells_in_doubt.last() == Some(&moves.len()) {
            seconds / 1000.0
        } else {
            seconds
        };
        if least.is_nan() || least > MAX_DWELL_S {
            return Err(lw.err(
                "G4",
                word.col,
                format!(
                    "dwell of {} s is longer than a day ({MAX_DWELL_S} s)",
                    shown(seconds)
                ),
            ));
        }
        moves.push(Move::Dwell {
            line: lw.line,
            seconds,
        });
    }
    if let Some((w, m)) = codes.motion {
        if matches!(m, Motion::Cubic | Motion::Quadratic) {
            st.dialect
                .claim(Dialect::LinuxCnc, lw.line, w.col, "G5/G5.1")?;
        }
        st.motion = m;
    }
    let has_axis = AXES.iter().any(|a| lw.get(*a).is_some());
    // The motion the line makes, as LinuxCNC decides it (see `usage`).
    let here = match codes.motion {
        Some((_, m)) => Some(m),
        None if has_axis || (matches!(st.motion, Motion::Arc { .. }) && lw.has_any("IJK")) => {
            Some(st.motion)
        }
        None => None,
    };
    // Axis words with no motion to make are refused below, for what they are.
    if !(has_axis && matches!(here, Some(Motion::None | Motion::FanucNurbs))) {
        usage::check(lw, codes, here)?;
    }
    // An arc without axis words ends where it starts: a full circle (or `P` of them) in
    // the centre form, refused by `arc` in the radius form or with neither.
    let arc_in_place = !has_axis && matches!(here, Some(Motion::Arc { .. }));
    if (has_axis || arc_in_place) && codes.dwell.is_none() {
        let mut target = target(st, lw, unit)?;
        let col = motion_word.map_or_else(|| lw.first_col(), |m| m.col);
        if !matches!(st.motion, Motion::Cubic) {
            st.g5_tangent = None;
        }
        match st.motion {
            Motion::None | Motion::FanucNurbs => {
                return Err(lw.err(
                    "modal",
                    col,
                    "axis words without an active motion (G0, G1, G2, G3)",
                ))
            }
            Motion::Rapid | Motion::Linear => {
                let rapid = st.motion == Motion::Rapid;
                let feed = if rapid {
                    0.0
                } else {
                    need_feed(st, lw, col)?;
                    st.feed
                };
                if comp::active(st) {
                    comp::straight(st, lw, target, rapid, moves)?;
                    st.comp_used = true;
                } else {
                    let from = st.exit_from.take().unwrap_or(st.pos);
                    push_line(moves, lw.line, from, target, rapid, feed);
                }
            }
            Motion::Arc { ccw } => {
                need_feed(st, lw, col)?;
                if st.exit_from.is_some() {
                    return Err(lw.err(
                        "G41/G42",
                        col,
                        "the move just after G40 must be straight (G0 or G1), not an arc: it takes the tool from its offset path back to the programmed one",
                    ));
                }
                let m = arc::arc(st, lw, target, ccw, unit, col)?;
                // The arc may end a rounding off the programmed end (see `arc`): the
                // next move starts where it ends.
                if let Move::Arc { to, .. } = m {
                    target = to;
                }
                if comp::active(st) {
                    let r_form = lw.get('R').map(|w| (w.value * unit).abs());
                    comp::arc(st, lw, m, r_form, moves)?;
                    st.comp_used = true;
                } else {
                    moves.push(m);
                }
            }
            Motion::Cubic | Motion::Quadratic => {
                // (A modal G5/G5.1 under compensation, or right after G40: refused as
                // on the line that names it, see `motion`.)
                if st.comp.is_some() || st.exit_from.is_some() {
                    let name = if st.motion == Motion::Cubic {
                        "G5"
                    } else {
                        "G5.1"
                    };
                    return Err(lw.err(
                        "G41/G42",
                        col,
                        format!("{name} spline (modal) while cutter radius compensation is on or just after G40: Bézier splines are not compensated, as in LinuxCNC; turn it off with G40 and move straight first"),
                    ));
                }
                need_feed(st, lw, col)?;
                let cubic = st.motion == Motion::Cubic;
                moves.push(linuxcnc::bezier(st, lw, target, cubic, unit, col)?);
            }
        }
        st.pos = target;
    } else if let Some((w, Motion::Cubic | Motion::Quadratic)) = codes.motion {
        return Err(lw.err(
            "spline",
            w.col,
            format!("G{} spline without its end point (X and Y)", w.value),
        ));
    }
    Ok(())
}

/// The line's compensation code (`G40`, `G41`, `G42`, `G41.1`, `G42.1`) and what may
/// not change while compensation is on (the plane, the feed mode), in LinuxCNC's
/// order: plane first, then compensation. `plane` and `inverse`
/// are as they were before the line.
fn comp_codes(
    st: &mut State,
    lw: &LineWords,
    codes: &LineCodes,
    plane: Plane,
    inverse: bool,
    unit: f64,
    moves: &mut [Move],
) -> Result<(), Diagnostic> {
    // The tool (`T`, `M6`) first, as LinuxCNC changes it before compensation starts:
    // `T2 M6 G41` offsets by tool 2.
    if let Some(t) = lw.get('T') {
        if t.value >= 0.0 && t.value.fract() == 0.0 && t.value <= u32::MAX as f64 {
            st.selected_tool = Some(t.value as u32);
        }
    }
    if let Some(m6) = lw
        .words
        .iter()
        .find(|w| w.letter == 'M' && gcode(w) == Some(60))
    {
        if st.comp.is_some() {
            return Err(lw.err(
                "G41/G42",
                m6.col,
                "cannot change tools with cutter radius compensation on: turn it off with G40 first",
            ));
        }
        if let Some(t) = st.selected_tool {
            st.spindle_tool = t;
        }
    }
    if codes.comp.is_some() && (st.g62.is_some() || st.nurbs.is_some() || st.fanuc.is_some()) {
        let w = codes.comp.map_or(lw.first_col(), |(w, _)| w.col);
        return Err(lw.err(
            "G41/G42",
            w,
            "cutter radius compensation turned on or off inside an open NURBS: close the curve first",
        ));
    }
    if st.comp.is_some() {
        let g = |codes: &[u32]| {
            lw.words
                .iter()
                .find(|w| w.letter == 'G' && gcode(w).is_some_and(|c| codes.contains(&c)))
                .map_or(lw.first_col(), |w| w.col)
        };
        // (The units may change: LinuxCNC 2.9 scales the radius; ours is in mm.)
        comp::units(st);
        if st.plane != plane {
            return Err(lw.err(
                "G41/G42",
                g(&[170, 180, 190]),
                "cannot change planes with cutter radius compensation on: turn it off with G40 first",
            ));
        }
        // LinuxCNC refuses these too while it is on (the path mode would apply to the
        // open move, which is still to be cut short).
        if let Some((w, _)) = codes.path {
            return Err(lw.err(
                "G41/G42",
                w.col,
                "cannot change the path control mode (G61, G61.1, G64) with cutter radius compensation on: turn it off with G40 first",
            ));
        }
        if lw
            .words
            .iter()
            .any(|w| w.letter == 'G' && matches!(gcode(w), Some(540..=590)))
        {
            return Err(lw.err(
                "G41/G42",
                g(&[540, 550, 560, 570, 580, 590]),
                "cannot change coordinate systems with cutter radius compensation on: turn it off with G40 first",
            ));
        }
        if st.inverse_time && !inverse {
            return Err(lw.err(
                "G41/G42",
                g(&[930]),
                "inverse time (G93) with cutter radius compensation on: a compensated move is not the programmed length, so 1/F minutes would time another path",
            ));
        }
    }
    match codes.comp {
        Some((_, 400)) if lw.get('D').is_some() => {
            let d = lw.get('D').map_or(lw.first_col(), |d| d.col);
            return Err(lw.err(
                "word",
                d,
                "D word with no G41, G41.1, G42 or G42.1 to use it",
            ));
        }
        Some((_, 400)) => {
            st.cutter_comp = false;
            comp::turn_off(st, lw, moves)?;
        }
        Some((w, code)) => {
            // Remembered, even if refused, so that a G06.2 can name Fanuc's PS1006.
            st.cutter_comp = true;
            st.compensated = true;
            if !st.uncompensated {
                comp::turn_on(st, lw, w, code, unit)?;
            }
        }
        None => {
            if let Some(d) = lw.get('D') {
                return Err(lw.err(
                    "word",
                    d.col,
                    "D word with no G41, G41.1, G42 or G42.1 to use it",
                ));
            }
        }
    }
    Ok(())
}

/// A feed move needs a feed: a modal F in G94, its own F on the line in G93.
fn need_feed(st: &State, lw: &LineWords, col: u32) -> Result<(), Diagnostic> {
    if st.inverse_time {
        match lw.get('F') {
            Some(f) if f.value > 0.0 => return Ok(()),
            Some(f) => {
                return Err(lw.err("G93",
                    f.col,
                    "inverse time: F must be > 0 (the move takes 1/F minutes)",
                ))
            }
            None => {
                return Err(lw.err("G93",
                    col,
                    "inverse time: F word missing on this feed move (in G93 every feed move needs its own F; the move takes 1/F minutes)",
                ))
            }
        }
    }
    if st.feed <= 0.0 {
        return Err(lw.err(
            "feed",
            col,
            "feed move with no feed rate: program F before (or on) this line",
        ));
    }
    if st.feed < MIN_FEED_MM_PER_MIN {
        return Err(lw.err(
            "feed",
            lw.get('F').map_or(col, |f| f.col),
            format!(
                "feed {} mm/min is below the slowest feed, {MIN_FEED_MM_PER_MIN} mm/min \
                 (LinuxCNC's floor): a millimetre would take over ten minutes",
                shown(st.feed)
            ),
        ));
    }
    Ok(())
}

/// The farthest from the origin a position the program names may be, mm: the longest
/// travel any machine file may give ([`shared::machine::MAX_TRAVEL_MM`]). The machine's
/// own travel is checked on the blocks; this bound keeps every number the planner sees
/// far from where a `f64` overflows or stops resolving a micrometre.
pub const MAX_POSITION_MM: f64 = shared::machine::MAX_TRAVEL_MM;

/// The farthest from the origin an arc centre or a curve's control point may be, mm:
/// ten times [`MAX_POSITION_MM`] (a flat arc's centre, a control point that pulls a
/// curve, may lie off the travel while the path stays on it).
pub const MAX_REACH_MM: f64 = 10.0 * MAX_POSITION_MM;

/// Where the line's axis words take the tool; refused beyond [`MAX_POSITION_MM`], at
/// the axis word that goes too far.
fn target(st: &State, lw: &LineWords, unit: f64) -> Result<[f64; 3], Diagnostic> {
    let mut to = st.pos;
    for (i, axis) in AXES.iter().enumerate() {
        if let Some(w) = lw.get(*axis) {
            to[i] = if st.absolute {
                w.value * unit
            } else {
                st.pos[i] + w.value * unit
            };
            if to[i].is_nan() || to[i].abs() > MAX_POSITION_MM {
                return Err(lw.err(
                    "range",
                    w.col,
                    format!(
                        "{axis} takes the tool to {} mm, beyond the ±{MAX_POSITION_MM} mm any machine's travel may have",
                        shown(to[i])
                    ),
                ));
            }
        }
    }
    Ok(to)
}

/// The lightest and the heaviest weight of a NURBS control point. A weight pulls the
/// curve towards its point against its neighbours'; a million times another's (1e300
/// against 1e-300 made the path NaN) is no curve CAM writes or a machine can follow.
const WEIGHTS: (f64, f64) = (1e-3, 1e3);

fn weight_ok(w: f64) -> bool {
    (WEIGHTS.0..=WEIGHTS.1).contains(&w)
}

/// The rule a weight word `letter` broke.
fn weight_rule(letter: char) -> String {
    format!(
        "weight {letter} must be > 0, from {} to {} (its pull on the curve against the other points')",
        WEIGHTS.0, WEIGHTS.1
    )
}

/// Refuses a point (an arc centre, a control point) farther than [`MAX_REACH_MM`] from
/// the origin, at column `col`.
fn within_reach(lw: &LineWords, col: u32, what: &str, p: [f64; 3]) -> Result<(), Diagnostic> {
    if p.iter().all(|v| v.abs() <= MAX_REACH_MM) {
        return Ok(());
    }
    Err(lw.err(
        "range",
        col,
        format!(
            "{what} lies at ({}, {}, {}) mm, beyond ±{MAX_REACH_MM} mm: no machine's path reaches out there",
            shown(p[0]),
            shown(p[1]),
            shown(p[2])
        ),
    ))
}

fn push_line(
    moves: &mut Vec<Move>,
    line: u32,
    from: [f64; 3],
    to: [f64; 3],
    rapid: bool,
    feed: f64,
) {
    if from != to {
        moves.push(Move::Line {
            line,
            from,
            to,
            rapid,
            feed,
        });
    }
}

#[cfg(test)]
mod tests;
