//! Differential test against LinuxCNC's own interpreter: random programs of straight
//! moves and arcs in all three planes, in millimetres and inches, absolute and
//! incremental, with centre offsets absolute and incremental, the radius form both ways
//! round and multi-turn helices, read by `rs274 -g` (Debian's `linuxcnc-uspace`) and by
//! us, move by move, with feeds in `G94` and inverse time (`G93`). What `rs274` prints is
//! the reference: the end point and feed of every move, the centre, direction and turns
//! of every arc. One program in four has a line LinuxCNC refuses (a word nothing uses,
//! an arc end off its circle or beyond its radius's reach, a `G93` move without `F`):
//! we must refuse the program at the same line.
//!
//! A second test does the same for cutter radius compensation (`G41`/`G42` with a tool
//! table, `G41.1`/`G42.1`, `G40`) on random contours of lines and arcs in the XY plane.
//!
//! Ignored by default: `rs274` is not installed by the project (it is a 200 MB package
//! with a real-time stack). Run them where it is installed, one at a time (two `rs274`
//! at once share the files it writes where it runs, and refuse programs at line 0):
//!
//! ```sh
//! cargo test --release -p interpreter --test rs274_differential -- --ignored --nocapture --test-threads 1
//! RS274_PROGRAMS=2000 RS274_SEED=7 cargo test ...   # more programs, another seed
//! ```
//!
//! `rs274` prints four decimals in the program's units at the time: the comparison's
//! tolerance is half a unit in the last of them (1.27 µm in inches); an arc's centre
//! may be off by what ours may move to put both programmed end points on its circle
//! (the radius tolerance).

use interpreter::program::tools::{Tool, ToolTable};
use interpreter::program::{interpret_with, Move, Options, PathControl, Plane, SpindleDir};
use std::fmt::Write as _;
use std::process::Command;

/// xorshift64*: the programs are the same for a seed wherever the test runs.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
}

const MM_PER_INCH: f64 = 25.4;

/// The program's modal state as the generator writes it, and where the tool is (mm).
struct Writer {
    text: String,
    n: u32,
    inch: bool,
    incremental: bool,
    arc_absolute: bool,
    plane: Plane,
    pos: [f64; 3],
    /// `G93`: every feed move carries its own `F`, the inverse of its time in minutes.
    inverse: bool,
    /// Back in `G94` the feed is forgotten (LinuxCNC): the next feed move needs an `F`.
    need_feed: bool,
}

impl Writer {
    /// An empty program in absolute mode and the XY plane, at the origin.
    fn new(inch: bool) -> Self {
        Writer {
            text: String::new(),
            n: 0,
            inch,
            incremental: false,
            arc_absolute: false,
            plane: Plane::XY,
            pos: [0.0; 3],
            inverse: false,
            need_feed: false,
        }
    }

    fn scale(&self) -> f64 {
        if self.inch {
            MM_PER_INCH
        } else {
            1.0
        }
    }

    /// A word's value for a length of `mm`, as written (six decimals in the program's
    /// units), and the length in mm that the written value stands for.
    fn length(&self, mm: f64) -> (String, f64) {
        let s = format!("{:.6}", mm / self.scale());
        let back = s.parse::<f64>().unwrap() * self.scale();
        (s, back)
    }

    /// The `F` word of a feed move, where it needs or draws one.
    fn feed(&mut self, rng: &mut Rng) -> String {
        if self.inverse {
            format!(" F{:.3}", rng.range(0.5, 20.0))
        } else if self.need_feed || rng.chance(0.2) {
            self.need_feed = false;
            format!(" F{:.1}", rng.range(50.0, 3000.0))
        } else {
            String::new()
        }
    }

    fn line(&mut self, words: &str) {
        self.n += 1;
        writeln!(self.text, "N{} {words}", self.n).unwrap();
    }

    /// The axis words for a move to `target` (mm) on the axes `which`, absolute or
    /// incremental as the mode is; the tool's new position.
    fn axes(&mut self, target: [f64; 3], which: [bool; 3]) -> String {
        let mut words = String::new();
        for axis in 0..3 {
            if !which[axis] {
                continue;
            }
            let (s, mm) = if self.incremental {
                let (s, d) = self.length(target[axis] - self.pos[axis]);
                (s, self.pos[axis] + d)
            } else {
                self.length(target[axis])
            };
            write!(words, " {}{s}", ['X', 'Y', 'Z'][axis]).unwrap();
            self.pos[axis] = mm;
        }
        words
    }
}

fn plane_axes(p: Plane) -> (usize, usize, usize) {
    let (a, b) = p.axes();
    (a, b, p.normal())
}

const OFFSET: [char; 3] = ['I', 'J', 'K'];

/// One random program of `lines` moves and mode changes.
fn program(rng: &mut Rng, lines: usize) -> String {
    let mut w = Writer::new(false);
    // One program in four gets one line LinuxCNC refuses, somewhere: both must refuse
    // the program at that line.
    let mut bad_line = rng.chance(0.25).then(|| rng.below(lines as u64) as usize);
    w.line("G21 G17 G90 G91.1 G94 F600");
    w.line("G0 X0 Y0 Z0");
    for k in 0..lines {
        if bad_line == Some(k) {
            bad_line = None;
            refused_line(rng, &mut w);
            continue;
        }
        match rng.below(25) {
            0 => {
                w.plane = [Plane::XY, Plane::ZX, Plane::YZ][rng.below(3) as usize];
                let g = match w.plane {
                    Plane::XY => "G17",
                    Plane::ZX => "G18",
                    Plane::YZ => "G19",
                };
                w.line(g);
            }
            1 => {
                w.inch = rng.chance(0.5);
                w.line(if w.inch { "G20" } else { "G21" });
            }
            2 => {
                w.incremental = rng.chance(0.5);
                w.line(if w.incremental { "G91" } else { "G90" });
            }
            3 => {
                w.arc_absolute = rng.chance(0.5);
                w.line(if w.arc_absolute { "G90.1" } else { "G91.1" });
            }
            4..=11 => {
                let rapid = rng.below(20) < 6;
                let mut which = [rng.chance(0.7), rng.chance(0.7), rng.chance(0.4)];
                if which == [false; 3] {
                    which[0] = true;
                }
                let target = [
                    rng.range(-60.0, 60.0),
                    rng.range(-60.0, 60.0),
                    rng.range(-20.0, 20.0),
                ];
                let words = w.axes(target, which);
                let g = if rapid { "G0" } else { "G1" };
                let f = if rapid { String::new() } else { w.feed(rng) };
                w.line(&format!("{g}{words}{f}"));
            }
            12..=16 => {
                // Centre form: a centre at a random offset, the end on its circle.
                let (a, b, n) = plane_axes(w.plane);
                let ccw = rng.chance(0.5);
                let r = rng.range(0.5, 30.0);
                let start_angle = rng.range(0.0, std::f64::consts::TAU);
                let (ca, cb) = (
                    w.pos[a] - r * start_angle.cos(),
                    w.pos[b] - r * start_angle.sin(),
                );
                let full = rng.chance(0.1);
                let end_angle = if full {
                    start_angle
                } else {
                    rng.range(0.0, std::f64::consts::TAU)
                };
                let mut target = w.pos;
                if !full {
                    target[a] = ca + r * end_angle.cos();
                    target[b] = cb + r * end_angle.sin();
                }
                let helix = rng.chance(0.3);
                if helix {
                    target[n] = w.pos[n] + rng.range(-10.0, 10.0);
                }
                let from = w.pos;
                let mut which = [false; 3];
                which[a] = !full || rng.chance(0.5);
                which[b] = !full;
                which[n] = helix;
                let words = w.axes(target, which);
                let (ia, ib) = if w.arc_absolute {
                    (ca, cb)
                } else {
                    (ca - from[a], cb - from[b])
                };
                let (ia, _) = w.length(ia);
                let (ib, _) = w.length(ib);
                let p = if full || (helix && rng.chance(0.5)) {
                    format!(" P{}", 1 + rng.below(3))
                } else {
                    String::new()
                };
                let g = if ccw { "G3" } else { "G2" };
                let f = w.feed(rng);
                w.line(&format!(
                    "{g}{words} {}{ia} {}{ib}{p}{f}",
                    OFFSET[a], OFFSET[b]
                ));
            }
            18 => {
                let p = rng.range(0.0, 2.0);
                w.line(&format!("G4 P{p:.3}"));
            }
            19 => {
                let s = if rng.chance(0.7) {
                    format!("S{:.0} ", rng.range(100.0, 24000.0))
                } else {
                    String::new()
                };
                let m = ["M3", "M4", "M5", ""][rng.below(4) as usize];
                w.line(&format!("{s}{m}"));
            }
            20 => {
                let tol = |rng: &mut Rng| w.length(rng.range(0.001, 0.5)).0;
                let p = match rng.below(5) {
                    0 => "G61".to_string(),
                    1 => "G61.1".to_string(),
                    2 => "G64".to_string(),
                    3 => format!("G64 P{}", tol(rng)),
                    _ => format!("G64 P{} Q{}", tol(rng), tol(rng)),
                };
                w.line(&p);
            }
            17 => {
                w.inverse = !w.inverse;
                w.need_feed = !w.inverse;
                w.line(if w.inverse { "G93" } else { "G94" });
            }
            _ => {
                // Radius form: an end within reach, the short or (R < 0) the long way.
                let (a, b, n) = plane_axes(w.plane);
                let mut target = w.pos;
                let chord = rng.range(1.0, 40.0);
                let dir = rng.range(0.0, std::f64::consts::TAU);
                target[a] += chord * dir.cos();
                target[b] += chord * dir.sin();
                if rng.chance(0.3) {
                    target[n] += rng.range(-5.0, 5.0);
                }
                let which = [true; 3];
                let from = w.pos;
                let words = w.axes(target, which);
                // The chord as written, so that R is never short of reaching.
                let written = ((w.pos[a] - from[a]).powi(2) + (w.pos[b] - from[b]).powi(2)).sqrt();
                let r = written / 2.0 * rng.range(1.01, 3.0);
                let (r, _) = w.length(if rng.chance(0.3) { -r } else { r });
                let g = if rng.chance(0.5) { "G3" } else { "G2" };
                let f = w.feed(rng);
                w.line(&format!("{g}{words} R{r}{f}"));
            }
        }
    }
    w.line("M2");
    w.text
}

/// A line LinuxCNC refuses: a word nothing uses, an arc whose end is off its circle or
/// out of its radius's reach, a feed move without its `F` in `G93`.
fn refused_line(rng: &mut Rng, w: &mut Writer) {
    let (a, b, _) = plane_axes(w.plane);
    let mut target = w.pos;
    match rng.below(4) {
        0 => {
            let words = w.axes([rng.range(-60.0, 60.0), 0.0, 0.0], [true, false, false]);
            let word = ["I1.5", "J-2", "R3", "P2", "Q1", "L3"][rng.below(6) as usize];
            w.line(&format!("G1{words} {word}"));
        }
        1 => {
            // The end 0.1 to 1 mm off the circle its centre gives: beyond 2 µm and 0.1 %.
            let r = rng.range(1.0, 30.0);
            let angle = rng.range(0.5, 3.0);
            let off = r + rng.range(0.1, 1.0);
            target[a] = w.pos[a] + r + off * angle.cos();
            target[b] = w.pos[b] + off * angle.sin();
            let (ia, _) = w.length(r);
            let mut which = [false; 3];
            which[a] = true;
            which[b] = true;
            let words = w.axes(target, which);
            w.line(&format!("G2{words} {}{ia} {}0", OFFSET[a], OFFSET[b]));
        }
        2 => {
            // R shorter than half the chord, by more than the tolerance.
            target[a] += 20.0;
            let mut which = [false; 3];
            which[a] = true;
            let words = w.axes(target, which);
            w.line(&format!("G3{words} R{}", w.length(5.0).0));
        }
        _ => {
            if !w.inverse {
                w.line("G93");
                w.inverse = true;
            }
            let words = w.axes([rng.range(-60.0, 60.0), 0.0, 0.0], [true, false, false]);
            w.line(&format!("G1{words}"));
        }
    }
}

/// A motion as both sides give it, in mm: the end point, and for an arc its plane,
/// centre (in-plane coordinates), direction and turns.
#[derive(Debug, Clone, PartialEq)]
enum Motion {
    Line {
        rapid: bool,
        to: [f64; 3],
        /// mm/min; none for a rapid.
        feed: Option<f64>,
    },
    /// `G4`: seconds.
    Dwell(f64),
    /// `G61` (0), `G61.1` (1), `G64` (2) with its tolerance (mm; 0 for none).
    Path(u8, f64),
    /// The spindle's direction (1 `M3`, -1 `M4`, 0 off) and speed (rpm), each time
    /// either changes.
    Spindle(i8, f64),
    Arc {
        to: [f64; 3],
        feed: f64,
        plane: Plane,
        center: [f64; 2],
        ccw: bool,
        turns: u32,
    },
}

/// The motions `rs274 -g` prints for `file`, or the line (its `N` number) it refuses
/// and why.
fn rs274(file: &std::path::Path) -> Result<Vec<Motion>, (u32, String)> {
    let mut cmd = Command::new("rs274");
    // A tool table beside the program, for `G41`/`G42` (see `TOOLS`).
    let table = file.with_extension("tbl");
    if table.exists() {
        cmd.arg("-t").arg(&table);
    }
    let out = cmd.arg("-g").arg(file).output().expect("rs274 runs");
    let text = String::from_utf8_lossy(&out.stdout);
    let errors = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        // The message, then the line it refuses, `N…` first.
        let line = errors
            .lines()
            .find_map(|l| l.strip_prefix('N')?.split(' ').next()?.parse().ok())
            .unwrap_or(0);
        return Err((line, errors.trim().replace('\n', " / ")));
    }
    let mut scale = 1.0;
    // The feed (mm/min): set in the units of its time, kept through a change of units.
    let mut feed = 0.0;
    let mut plane = Plane::XY;
    let mut motions = Vec::new();
    // Where the tool is, as printed (in mm).
    let mut at = [0.0; 3];
    let mut spindle = (0i8, 0.0f64);
    let mut spindle_line = String::new();
    for line in text.lines() {
        // Every line of ours has its `N`: `N.....` are the calls of the start and of the
        // program end's reset (which stops the spindle), not of a line.
        if line.split_whitespace().nth(1) == Some("N.....") {
            continue;
        }
        let Some(call) = line.split_whitespace().nth(2) else {
            continue;
        };
        let rest: String = line
            .split_whitespace()
            .skip(2)
            .collect::<Vec<_>>()
            .join(" ");
        let args = |s: &str| -> Vec<f64> {
            let inner = &s[s.find('(').unwrap() + 1..s.rfind(')').unwrap()];
            inner
                .split(',')
                .filter_map(|v| v.trim().parse::<f64>().ok())
                .collect()
        };
        let spindle_was = spindle;
        if call.starts_with("SET_G5X_OFFSET(") {
            // `M2`'s reset (offsets, feed mode, the spindle stopped): the program's end,
            // which is no change the program asked for (the generator writes no G54…).
            break;
        } else if call.starts_with("SET_FEED_RATE(") {
            feed = args(&rest)[0] * scale;
        } else if call.starts_with("DWELL(") {
            motions.push(Motion::Dwell(args(&rest)[0]));
        } else if call.starts_with("SET_MOTION_CONTROL_MODE(") {
            motions.push(match call {
                c if c.contains("EXACT_PATH") => Motion::Path(0, 0.0),
                c if c.contains("EXACT_STOP") => Motion::Path(1, 0.0),
                _ => Motion::Path(2, args(&rest)[0] * scale),
            });
        } else if call.starts_with("SET_SPINDLE_SPEED(") {
            spindle.1 = args(&rest)[1];
        } else if call.starts_with("START_SPINDLE_CLOCKWISE(") {
            spindle.0 = 1;
        } else if call.starts_with("START_SPINDLE_COUNTERCLOCKWISE(") {
            spindle.0 = -1;
        } else if call.starts_with("STOP_SPINDLE_TURNING(") {
            spindle.0 = 0;
        } else if call.starts_with("USE_LENGTH_UNITS(") {
            scale = if call.contains("INCHES") {
                MM_PER_INCH
            } else {
                1.0
            };
        } else if call.starts_with("SELECT_PLANE(") {
            plane = match call {
                c if c.contains("XY") => Plane::XY,
                c if c.contains("XZ") => Plane::ZX,
                _ => Plane::YZ,
            };
        } else if call.starts_with("STRAIGHT_TRAVERSE(") || call.starts_with("STRAIGHT_FEED(") {
            let v = args(&rest);
            let to = [v[0] * scale, v[1] * scale, v[2] * scale];
            // A move to where the tool is moves nothing: we make no block of it.
            if to != at {
                let rapid = call.starts_with("STRAIGHT_TRAVERSE");
                motions.push(Motion::Line {
                    rapid,
                    to,
                    feed: (!rapid).then_some(feed),
                });
            }
            at = to;
        } else if call.starts_with("ARC_FEED(") {
            let v = args(&rest);
            let (a, b, n) = plane_axes(plane);
            let mut to = [0.0; 3];
            to[a] = v[0] * scale;
            to[b] = v[1] * scale;
            to[n] = v[5] * scale;
            let rotation = v[4] as i64;
            at = to;
            motions.push(Motion::Arc {
                to,
                feed,
                plane,
                center: [v[2] * scale, v[3] * scale],
                ccw: rotation > 0,
                turns: rotation.unsigned_abs() as u32,
            });
        }
        if spindle != spindle_was {
            // One change a line: `S1000 M3` sets the speed, then starts the spindle.
            let n = line.split_whitespace().nth(1).unwrap_or("");
            if spindle_line == n && matches!(motions.last(), Some(Motion::Spindle(..))) {
                motions.pop();
            }
            spindle_line = n.to_string();
            motions.push(Motion::Spindle(spindle.0, spindle.1));
        }
    }
    Ok(motions)
}

/// The tool table of the compensated programs: tool number and diameter (mm).
const TOOLS: [(u32, f64); 3] = [(1, 1.0), (2, 4.0), (3, -2.0)];

/// Our motions for the same program, or the first line we refuse and why.
fn ours(text: &str) -> Result<Vec<Motion>, (u32, String)> {
    let tools = ToolTable {
        file: "tools".into(),
        tools: TOOLS
            .iter()
            .map(|&(number, diameter_mm)| Tool {
                number,
                diameter_mm,
            })
            .collect(),
    };
    let opts = Options {
        tools: Some(tools),
        ..Options::default()
    };
    let prog = interpret_with(text, &opts).map_err(|d| {
        let first = d.iter().min_by_key(|d| d.line).expect("a refusal says why");
        (first.line, first.to_string())
    })?;
    Ok(prog
        .moves
        .iter()
        .filter_map(|m| match m {
            Move::Line {
                to, rapid, feed, ..
            } => Some(Motion::Line {
                rapid: *rapid,
                to: *to,
                feed: (!rapid).then_some(*feed),
            }),
            Move::Arc {
                to,
                center,
                plane,
                ccw,
                turns,
                feed,
                ..
            } => {
                let (a, b, _) = plane_axes(*plane);
                Some(Motion::Arc {
                    to: *to,
                    feed: *feed,
                    plane: *plane,
                    center: [center[a], center[b]],
                    ccw: *ccw,
                    turns: *turns,
                })
            }
            Move::Dwell { seconds, .. } => Some(Motion::Dwell(*seconds)),
            Move::PathMode { control, .. } => Some(match control {
                PathControl::ExactPath => Motion::Path(0, 0.0),
                PathControl::ExactStop => Motion::Path(1, 0.0),
                PathControl::Blend { tolerance_mm, .. } => {
                    Motion::Path(2, tolerance_mm.unwrap_or(0.0))
                }
            }),
            Move::Spindle { dir, rpm, .. } => Some(Motion::Spindle(
                match dir {
                    SpindleDir::Clockwise => 1,
                    SpindleDir::CounterClockwise => -1,
                    SpindleDir::Off => 0,
                },
                *rpm,
            )),
            _ => None,
        })
        .collect())
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol)
}

/// Where `ours` and `theirs` differ beyond the printing's rounding, if they do.
fn first_difference(ours: &[Motion], theirs: &[Motion]) -> Option<String> {
    // Four decimals of an inch, and the arc centre moved onto the chord's bisector.
    const TOL: f64 = 0.5e-4 * MM_PER_INCH + 1e-4;
    // Four decimals of a unit a minute, and our feed in G93 from the exact move length.
    // LinuxCNC 2.9 sets no inverse-time feed below 0.1 units a minute (a guard against
    // the zero feed of a zero-length move, linuxcnc#2410): a move of 0.0015 in at
    // `F10.95` then takes 0.9 s, not the 5.5 s its `F` asks for. We give it its time.
    let same_feed = |f0: f64, f1: f64| {
        let floor = [0.1, 0.1 * MM_PER_INCH]
            .iter()
            .any(|m| (f1 - m).abs() < 1e-9);
        (f0 - f1).abs() <= 1e-4 * f1.abs() + 0.5e-4 * MM_PER_INCH || (floor && f0 < f1)
    };
    // How far an arc of ours has ended from the programmed end (on the programmed
    // circle, see below): an axis the program does not name again stays that far off.
    let mut carried = 0.0f64;
    for (i, (o, t)) in ours.iter().zip(theirs).enumerate() {
        let same = match (o, t) {
            (
                Motion::Line {
                    rapid: r0,
                    to: a,
                    feed: f0,
                },
                Motion::Line {
                    rapid: r1,
                    to: b,
                    feed: f1,
                },
            ) => {
                r0 == r1
                    && close(a, b, TOL + carried)
                    && match (f0, f1) {
                        (Some(f0), Some(f1)) => same_feed(*f0, *f1),
                        (f0, f1) => f0.is_none() && f1.is_none(),
                    }
            }
            (
                Motion::Arc {
                    to: a,
                    feed: f0,
                    plane: p0,
                    center: c0,
                    ccw: d0,
                    turns: n0,
                },
                Motion::Arc {
                    to: b,
                    feed: f1,
                    plane: p1,
                    center: c1,
                    ccw: d1,
                    turns: n1,
                },
            ) => {
                // Our centre may move onto the chord's bisector by as much as the radius
                // may differ between the ends (`program::arc`): 0.002·√2 in, or 0.1 %.
                // Where it would move further, ours ends on the programmed circle
                // instead, as far from the programmed end as the radii differ.
                let (i, j, _) = plane_axes(*p1);
                let r = (b[i] - c1[0]).hypot(b[j] - c1[1]);
                let centre_tol =
                    TOL + (0.002 * std::f64::consts::SQRT_2 * MM_PER_INCH).max(1e-3 * r);
                let ends_near = close(a, b, centre_tol + carried);
                let off = a
                    .iter()
                    .zip(b)
                    .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
                carried = carried.max(off - TOL);
                ends_near
                    && same_feed(*f0, *f1)
                    && p0 == p1
                    && close(c0, c1, centre_tol)
                    && d0 == d1
                    && n0 == n1
            }
            (Motion::Dwell(a), Motion::Dwell(b)) => (a - b).abs() <= 0.5e-4,
            (Motion::Path(k0, t0), Motion::Path(k1, t1)) => {
                k0 == k1 && (t0 - t1).abs() <= 0.5e-6 * MM_PER_INCH
            }
            (Motion::Spindle(d0, s0), Motion::Spindle(d1, s1)) => {
                d0 == d1 && (s0 - s1).abs() <= 0.5e-4
            }
            _ => false,
        };
        if !same {
            return Some(format!("motion {i}: ours {o:?}, rs274 {t:?}"));
        }
    }
    (ours.len() != theirs.len())
        .then(|| format!("{} motions ours, {} rs274", ours.len(), theirs.len()))
}

fn env_or(name: &str, default: u64) -> u64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Reads `RS274_PROGRAMS` programs of `make`'s (default `default`) with us and with
/// `rs274`, and fails on the first ten that differ (kept in a temporary directory).
fn compare(name: &str, default: u64, make: impl Fn(&mut Rng) -> String) {
    let programs = env_or("RS274_PROGRAMS", default);
    let seed = env_or("RS274_SEED", 1);
    let dir = std::env::temp_dir().join(format!("rs274-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut failures = Vec::new();
    let mut motions = 0;
    let mut refused = 0;
    for k in 0..programs {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ (seed << 32) ^ (k + 1));
        let text = make(&mut rng);
        let file = dir.join(format!("p{k}.ngc"));
        std::fs::write(&file, &text).unwrap();
        // Standalone rs274 reads a tool table's diameters in inches.
        let table: String = TOOLS
            .iter()
            .map(|(t, d)| format!("T{t} P{t} D{:.9}\n", d / MM_PER_INCH))
            .collect();
        std::fs::write(file.with_extension("tbl"), table).unwrap();
        let verdict = match (ours(&text), rs274(&file)) {
            (Ok(o), Ok(t)) => {
                motions += t.len();
                first_difference(&o, &t)
            }
            (Err(o), Err(t)) => {
                refused += 1;
                (o.0 != t.0).then(|| {
                    format!(
                        "we refuse line {}: {}; rs274 line {}: {}",
                        o.0, o.1, t.0, t.1
                    )
                })
            }
            (Err(o), Ok(_)) => Some(format!("we refuse what rs274 reads: line {}: {}", o.0, o.1)),
            (Ok(_), Err(t)) => Some(format!("rs274 refuses what we read: line {}: {}", t.0, t.1)),
        };
        match verdict {
            Some(why) => failures.push(format!("{}: {why}", file.display())),
            None => {
                std::fs::remove_file(&file).unwrap();
                std::fs::remove_file(file.with_extension("tbl")).unwrap();
            }
        }
    }
    eprintln!(
        "{programs} programs, {motions} motions compared with rs274; {refused} programs \
         refused by both at the same line"
    );
    assert!(
        failures.is_empty(),
        "{} of {programs} programs differ (kept in {}):\n{}",
        failures.len(),
        dir.display(),
        failures[..failures.len().min(10)].join("\n")
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
#[ignore = "needs LinuxCNC's rs274 (Debian's linuxcnc-uspace), which the project does not install"]
fn random_programs_move_as_linuxcnc_moves_them() {
    compare("diff", 300, |rng| program(rng, 40));
}

/// One random program with cutter radius compensation: contours of straight moves and
/// arcs (both forms, both ways round, some along Z or helical, some rapid) in the XY
/// plane, each entered with `G41.1`/`G42.1 D…` (a diameter, now and then negative: the
/// other side) and left with `G40`, in millimetres or inches. The tool is small next to
/// the moves, but corners are random: many programs have a concave corner the tool
/// cannot reach, or an arc it does not fit in, which both must refuse at the same line.
fn comp_program(rng: &mut Rng, contours: usize) -> String {
    let mut w = Writer::new(rng.chance(0.3));
    // (The units on a line of their own: rs274 prints a line's feed before its units.)
    w.line(if w.inch { "G20" } else { "G21" });
    w.line(if w.inch {
        "G17 G90 G91.1 G94 F20"
    } else {
        "G17 G90 G91.1 G94 F600"
    });
    w.line("G0 X0 Y0 Z0");
    for _ in 0..contours {
        let dia = rng.range(0.2, 6.0) * if rng.chance(0.1) { -1.0 } else { 1.0 };
        let side = if rng.chance(0.5) { "G41" } else { "G42" };
        // The diameter on the line (`G41.1 D…`) or a tool of the table (`G41 D…`).
        let code = if rng.chance(0.7) {
            format!("{side}.1 D{}", w.length(dia).0)
        } else {
            format!("{side} D{}", TOOLS[rng.below(3) as usize].0)
        };
        // The entry move on the line of its G41.1, or on the next.
        let mut on_line = if rng.chance(0.5) {
            Some(code)
        } else {
            w.line(&code);
            None
        };
        let moves = 2 + rng.below(10);
        for k in 0..moves {
            let prefix = on_line.take().map(|s| s + " ").unwrap_or_default();
            match rng.below(10) {
                0..=4 => {
                    let rapid = rng.below(10) == 0;
                    let len = rng.range(3.0, 40.0);
                    let dir = rng.range(0.0, std::f64::consts::TAU);
                    let mut target = w.pos;
                    target[0] += len * dir.cos();
                    target[1] += len * dir.sin();
                    let mut which = [true, true, false];
                    if rng.chance(0.2) {
                        target[2] = rng.range(-10.0, 10.0);
                        which[2] = true;
                    }
                    let words = w.axes(target, which);
                    let g = if rapid { "G0" } else { "G1" };
                    w.line(&format!("{prefix}{g}{words}"));
                }
                5 if k > 0 => {
                    // Along Z only, by a millimetre at least (rs274 prints four
                    // decimals: a smaller step may print as no move).
                    let dz = rng.range(1.0, 10.0) * if rng.chance(0.5) { -1.0 } else { 1.0 };
                    let z = w.pos[2] + dz;
                    let words = w.axes([0.0, 0.0, z], [false, false, true]);
                    w.line(&format!("{prefix}G1{words}"));
                }
                5 | 6 => {
                    // Radius form, the short way (at most a half circle).
                    let chord = rng.range(2.0, 40.0);
                    let dir = rng.range(0.0, std::f64::consts::TAU);
                    let mut target = w.pos;
                    target[0] += chord * dir.cos();
                    target[1] += chord * dir.sin();
                    let from = w.pos;
                    let words = w.axes(target, [true, true, false]);
                    let written = (w.pos[0] - from[0]).hypot(w.pos[1] - from[1]);
                    let r = written / 2.0 * rng.range(1.01, 3.0);
                    let (r, _) = w.length(r);
                    let g = if rng.chance(0.5) { "G3" } else { "G2" };
                    w.line(&format!("{prefix}{g}{words} R{r}"));
                }
                7 => {
                    w.line(&format!("{prefix}G4 P{:.3}", rng.range(0.0, 1.0)));
                }
                _ => {
                    // Centre form, less than 300 degrees round.
                    let ccw = rng.chance(0.5);
                    let r = rng.range(2.0, 30.0);
                    let start = rng.range(0.0, std::f64::consts::TAU);
                    let (ca, cb) = (w.pos[0] - r * start.cos(), w.pos[1] - r * start.sin());
                    let turn = rng.range(0.2, 5.2) * if ccw { 1.0 } else { -1.0 };
                    let mut target = w.pos;
                    target[0] = ca + r * (start + turn).cos();
                    target[1] = cb + r * (start + turn).sin();
                    let mut which = [true, true, false];
                    if rng.chance(0.2) {
                        target[2] = w.pos[2] + rng.range(-5.0, 5.0);
                        which[2] = true;
                    }
                    let from = w.pos;
                    let words = w.axes(target, which);
                    let (ia, _) = w.length(ca - from[0]);
                    let (ib, _) = w.length(cb - from[1]);
                    let g = if ccw { "G3" } else { "G2" };
                    w.line(&format!("{prefix}{g}{words} I{ia} J{ib}"));
                }
            }
        }
        // The exit: `G40` and a straight move back onto the path, on one line or two.
        let len = rng.range(3.0, 30.0);
        let dir = rng.range(0.0, std::f64::consts::TAU);
        let target = [
            w.pos[0] + len * dir.cos(),
            w.pos[1] + len * dir.sin(),
            w.pos[2],
        ];
        let words = w.axes(target, [true, true, false]);
        if rng.chance(0.5) {
            w.line(&format!("G40 G1{words}"));
        } else {
            w.line("G40");
            w.line(&format!("G1{words}"));
        }
    }
    w.line("M2");
    w.text
}

#[test]
#[ignore = "needs LinuxCNC's rs274 (Debian's linuxcnc-uspace), which the project does not install"]
fn compensated_programs_move_as_linuxcnc_moves_them() {
    compare("comp", 300, |rng| comp_program(rng, 3));
}
