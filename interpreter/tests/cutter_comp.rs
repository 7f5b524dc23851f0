//! Cutter radius compensation (`G41.1`/`G42.1`, `G40`): the path against LinuxCNC's
//! `rs274` on the example, against closed forms on random convex polygons, and every
//! refusal at its line. (The random differential test against `rs274` itself is
//! `rs274_differential.rs`'s `compensated_programs_move_as_linuxcnc_moves_them`,
//! ignored where `rs274` is not installed.)

use interpreter::program::{interpret, Move};

/// A move as compared: `'L'` a feed line, `'R'` a rapid, `'A'` an arc; its end (mm); an
/// arc's centre and whether it runs counter-clockwise.
type Seen = (char, [f64; 3], Option<([f64; 2], bool)>);

/// A move as `rs274` prints it: kind, end, an arc's centre.
type Printed = (char, [f64; 3], Option<[f64; 2]>);

/// Each move starts where the one before it ended (the path never jumps).
fn continuous(moves: &[Move]) {
    let mut last: Option<[f64; 3]> = None;
    for m in moves {
        if let Move::Line { from, to, .. } | Move::Arc { from, to, .. } = m {
            if let Some(e) = last {
                assert_eq!(e, *from, "{m:?} does not start where the move before ended");
            }
            last = Some(*to);
        }
    }
}

/// The moves' end points (and arcs' centres and directions) in mm, as a list to compare;
/// the path checked for jumps.
fn path(text: &str) -> Vec<Seen> {
    let prog = interpret(text).unwrap_or_else(|e| panic!("refused: {:?}", e));
    continuous(&prog.moves);
    prog.moves
        .iter()
        .filter_map(|m| match m {
            Move::Line { to, rapid, .. } => Some((if *rapid { 'R' } else { 'L' }, *to, None)),
            Move::Arc {
                to, center, ccw, ..
            } => Some(('A', *to, Some(([center[0], center[1]], *ccw)))),
            _ => None,
        })
        .collect()
}

/// The example's path as LinuxCNC 2.9's `rs274 -g examples/cutter-comp.ngc` prints it
/// (four decimals): every straight move's and arc's end, and each arc's centre, all
/// arcs clockwise (`-1`).
#[test]
fn the_example_cuts_linuxcnc_s_path() {
    let text = include_str!("../../examples/cutter-comp.ngc");
    let theirs: &[Printed] = &[
        ('R', [-20.0, -20.0, 5.0], None),
        ('L', [-20.0, -20.0, -2.0], None),
        ('L', [-3.0, -8.1459, -2.0], None),
        ('L', [-3.0, 40.0, -2.0], None),
        ('A', [0.0, 43.0, -2.0], Some([0.0, 40.0])),
        ('L', [20.0, 43.0, -2.0], None),
        ('A', [23.0, 40.0, -2.0], Some([20.0, 40.0])),
        ('L', [23.0, 33.0, -2.0], None),
        ('L', [37.0, 33.0, -2.0], None),
        ('L', [37.0, 40.0, -2.0], None),
        ('A', [40.0, 43.0, -2.0], Some([40.0, 40.0])),
        ('L', [60.0, 43.0, -2.0], None),
        ('A', [63.0, 40.0, -2.0], Some([60.0, 40.0])),
        ('L', [63.0, 10.0, -2.0], None),
        ('A', [50.0, -3.0, -2.0], Some([50.0, 10.0])),
        ('L', [0.0, -3.0, -2.0], None),
        ('A', [-3.0, 0.0, -2.0], Some([0.0, 0.0])),
        ('L', [-3.0, 5.0, -2.0], None),
        ('L', [-20.0, -20.0, -2.0], None),
        ('R', [-20.0, -20.0, 5.0], None),
    ];
    let ours = path(text);
    assert_eq!(ours.len(), theirs.len(), "{ours:?}");
    // Half a unit in rs274's last printed decimal.
    const TOL: f64 = 0.5e-4;
    for (i, ((k0, to0, arc0), (k1, to1, c1))) in ours.iter().zip(theirs).enumerate() {
        assert_eq!(k0, k1, "move {i}");
        for a in 0..3 {
            assert!(
                (to0[a] - to1[a]).abs() <= TOL,
                "move {i}: {to0:?} against {to1:?}"
            );
        }
        if let (Some((c0, ccw)), Some(c1)) = (arc0, c1) {
            assert!(!ccw, "move {i}");
            assert!(
                (c0[0] - c1[0]).abs() <= TOL && (c0[1] - c1[1]).abs() <= TOL,
                "move {i}"
            );
        }
    }
}

/// xorshift64*.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Distance from `p` to the segment `a`–`b`.
fn to_segment(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let t = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / (d[0] * d[0] + d[1] * d[1]))
        .clamp(0.0, 1.0);
    (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1])
}

/// Outside a convex polygon, every point of the compensated path is exactly the tool's
/// radius from the polygon (the offset of a convex polygon is its edges moved out and
/// arcs round its corners), and the path closes on itself: checked at 50 points of
/// every move on 200 random polygons, both directions round (`G41.1` clockwise, `G42.1`
/// anticlockwise keep the tool outside), to 1e-9 mm.
#[test]
fn outside_a_convex_polygon_the_tool_keeps_its_radius_from_every_edge() {
    let mut rng = Rng(0x1234_5678_9abc_def1);
    for case in 0..200 {
        let n = 3 + (rng.unit() * 8.0) as usize;
        // Corners at increasing angles on an ellipse-ish curve: convex.
        let mut angles: Vec<f64> = (0..n).map(|_| rng.unit() * std::f64::consts::TAU).collect();
        angles.sort_by(f64::total_cmp);
        angles.dedup_by(|a, b| (*a - *b).abs() < 0.2);
        if angles.len() < 3 || angles[0] + std::f64::consts::TAU - angles[angles.len() - 1] < 0.2 {
            continue;
        }
        let (ax, by) = (20.0 + 30.0 * rng.unit(), 20.0 + 30.0 * rng.unit());
        let mut corners: Vec<[f64; 2]> = angles
            .iter()
            .map(|t| [ax * t.cos(), by * t.sin()])
            .collect();
        let left = case % 2 == 0;
        if left {
            corners.reverse(); // clockwise, the tool on the left: outside
        }
        let radius = 0.5 + 4.0 * rng.unit();
        let g = if left { "G41.1" } else { "G42.1" };
        // Enter along the first edge's line, from far before it, to its middle: the
        // entry ends on the offset of that edge (a straight move's entry ends square
        // to the entry move), so the moves after it all run on the offset path. Then
        // round once, along the first edge again to its middle, and leave.
        let (a, b) = (corners[0], corners[1]);
        let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
        let mut text = String::from("G21 G17 G90 G94 F1000\n");
        let len = (b[0] - a[0]).hypot(b[1] - a[1]);
        let far = [
            mid[0] - 60.0 * (b[0] - a[0]) / len,
            mid[1] - 60.0 * (b[1] - a[1]) / len,
        ];
        text += &format!(
            "G0 X{:.9} Y{:.9}\n{g} D{:.9}\n",
            far[0],
            far[1],
            2.0 * radius
        );
        text += &format!("G1 X{:.9} Y{:.9}\n", mid[0], mid[1]);
        for c in corners.iter().skip(1).chain(std::iter::once(&corners[0])) {
            text += &format!("G1 X{:.9} Y{:.9}\n", c[0], c[1]);
        }
        text += &format!(
            "G1 X{:.9} Y{:.9}\nG40 G1 X{:.9} Y{:.9}\nM2\n",
            mid[0], mid[1], far[0], far[1]
        );
        let prog = interpret(&text).unwrap_or_else(|e| panic!("case {case}: {e:?}\n{text}"));
        // The programmed polygon as the program has it (nine decimals).
        let poly: Vec<[f64; 2]> = corners
            .iter()
            .map(|c| {
                [
                    format!("{:.9}", c[0]).parse().unwrap(),
                    format!("{:.9}", c[1]).parse().unwrap(),
                ]
            })
            .collect();
        let dist = |p: [f64; 2]| {
            (0..poly.len())
                .map(|i| to_segment(p, poly[i], poly[(i + 1) % poly.len()]))
                .fold(f64::INFINITY, f64::min)
        };
        let moves: Vec<&Move> = prog
            .moves
            .iter()
            .filter(|m| matches!(m, Move::Line { .. } | Move::Arc { .. }))
            .collect();
        // The rapid to the start, the entry, ..., the exit: the moves in between run on
        // the offset path.
        let mut last_end: Option<[f64; 3]> = None;
        for (i, m) in moves.iter().enumerate() {
            let (from, to) = match m {
                Move::Line { from, to, .. } | Move::Arc { from, to, .. } => (*from, *to),
                _ => unreachable!(),
            };
            if let Some(e) = last_end {
                assert_eq!(e, from, "case {case}: move {i} starts where the last ended");
            }
            last_end = Some(to);
            if i < 2 || i + 1 == moves.len() {
                continue;
            }
            for k in 0..=50 {
                let t = k as f64 / 50.0;
                let p = match m {
                    Move::Line { from, to, .. } => [
                        from[0] + t * (to[0] - from[0]),
                        from[1] + t * (to[1] - from[1]),
                    ],
                    Move::Arc {
                        from,
                        to,
                        center,
                        ccw,
                        ..
                    } => {
                        let a0 = (from[1] - center[1]).atan2(from[0] - center[0]);
                        let mut a1 = (to[1] - center[1]).atan2(to[0] - center[0]);
                        if *ccw && a1 < a0 {
                            a1 += std::f64::consts::TAU;
                        }
                        if !*ccw && a1 > a0 {
                            a1 -= std::f64::consts::TAU;
                        }
                        let r = (from[0] - center[0]).hypot(from[1] - center[1]);
                        let a = a0 + t * (a1 - a0);
                        [center[0] + r * a.cos(), center[1] + r * a.sin()]
                    }
                    _ => unreachable!(),
                };
                let d = dist(p);
                assert!(
                    (d - radius).abs() < 1e-9,
                    "case {case}: move {i} at {t}: {d} mm from the polygon, radius {radius}\n{text}"
                );
            }
        }
    }
}

/// The first error's line and message for `text`.
fn refused(text: &str) -> (u32, String) {
    let e = interpret(text).expect_err("refused");
    let d = e.iter().min_by_key(|d| d.line).unwrap();
    (d.line, d.message.clone())
}

/// Each program a machinist could get wrong is refused at the line that goes wrong,
/// with LinuxCNC's reason (the lines and reasons `rs274 -g` gives, but for the two
/// cases the comments name; messages checked by a word or two).
#[test]
fn what_the_tool_cannot_cut_is_refused_at_its_line() {
    let head = "G21 G17 G90 G94 F500\nG0 X0 Y0\n";
    for (body, line, says) in [
        // The entry move no longer than the radius.
        ("G41.1 D10\nG1 X4 Y0\n", 4, "entry move"),
        // A slot narrower than the tool: the offset of its 2 mm wide end runs back past
        // its start.
        (
            "G42.1 D6\nG1 X20 Y0\nG1 X20 Y20\nG1 X22 Y20\nG1 X22 Y0\nG1 X40 Y0\nM2\n",
            7,
            "gouging",
        ),
        // An arc with the tool inside it, smaller than the tool.
        ("G41.1 D10\nG1 X20 Y0\nG3 X20 Y8 R4\n", 5, "arc radius"),
        // The plane changed while it is on.
        ("G41.1 D2\nG1 X20 Y0\nG18\n", 5, "planes"),
        // A Bézier spline while it is on (LinuxCNC refuses G5 too), a NURBS as the
        // entry move, and an arc just after G40.
        (
            "G41.1 D2\nG1 X20 Y0\nG5 X30 Y0 I5 J5 P5 Q-5\n",
            5,
            "G41/G42",
        ),
        (
            "G41.1 D2\nG5.2 L3 X20 Y5 P1\nX30 Y0 P1\nG5.3\n",
            4,
            "entry move",
        ),
        ("G41.1 D2\nG1 X20 Y0\nG40\nG2 X30 Y0 R5\n", 6, "straight"),
        // G41.1 without its diameter, a D word with nothing to use it, G41 on again,
        // outside the XY plane (LinuxCNC compensates in XZ for lathes; not here).
        ("G41.1\n", 3, "D word"),
        ("G1 X10 D3\n", 3, "D word"),
        ("G41.1 D2\nG1 X20 Y0\nG42.1 D2\n", 5, "already on"),
        ("G18\nG41.1 D2\n", 4, "XY plane"),
        // G41 takes its radius from a tool table, which this program was not given.
        ("G41 D1\n", 3, "tool table"),
        // A concave corner right after a stop: the move before has ended.
        (
            "G41.1 D10\nG1 X0 Y10\nG1 X20 Y10\nM0\nG1 X20 Y30\n",
            7,
            "after a stop",
        ),
        // Turned on inside an open curve.
        (
            "G5.2 L3 X10 Y10 P1\nG41.1 D2\nX20 Y0 P1\nG5.3\n",
            4,
            "open NURBS",
        ),
        // What LinuxCNC refuses while it is on: a tool change, a path mode, a
        // coordinate system, and a D word on G40.
        ("G41.1 D2\nG1 X20 Y0\nT1 M6\n", 5, "change tools"),
        ("G41.1 D2\nG1 X20 Y0\nG64 P0.1\n", 5, "path control"),
        ("G41.1 D2\nG1 X20 Y0\nG54\n", 5, "coordinate systems"),
        ("G41.1 D2\nG1 X20 Y0\nG40 D1\n", 5, "D word"),
    ] {
        let text = format!("{head}{body}");
        let (l, msg) = refused(&text);
        assert_eq!(l, line, "{body}: {msg}");
        assert!(msg.contains(says), "{body}: {msg}");
    }
}

/// A negative diameter (a tool smaller than the one the path was drawn for) offsets to
/// the other side; a zero diameter changes nothing; `G40` brings the tool back onto the
/// programmed point, from where it is.
#[test]
fn a_negative_diameter_offsets_the_other_way_and_g40_comes_back() {
    let left =
        path("G21 G17 G90 F500\nG0 X0 Y-10\nG41.1 D-4\nG1 X0 Y0\nG1 X20 Y0\nG40 G1 X20 Y-10\nM2\n");
    // Along +Y then +X with the tool on the right: the entry ends where the offsets of
    // the two edges meet (a concave corner), x = 2 and y = -2.
    let e = left[1].1;
    assert!(
        (e[0] - 2.0).abs() < 1e-12 && (e[1] + 2.0).abs() < 1e-12 && e[2] == 0.0,
        "{e:?}"
    );
    let after: Vec<_> = left.iter().map(|m| m.1).collect();
    assert_eq!(*after.last().unwrap(), [20.0, -10.0, 0.0]);
    let plain = path("G21 G17 G90 F500\nG0 X0 Y-10\nG41.1 D0\nG1 X0 Y0\nG1 X20 Y0\nG40\nM2\n");
    assert_eq!(
        plain.iter().map(|m| m.1).collect::<Vec<_>>(),
        vec![[0.0, -10.0, 0.0], [0.0, 0.0, 0.0], [20.0, 0.0, 0.0]]
    );
}

/// `G41`/`G42` take the diameter from the tool table: `D<n>`'s tool, or the tool in the
/// spindle (`T<n> M6`); the same path as `G41.1 D<its diameter>`. A tool not in the
/// table, no tool in the spindle, no table at all: refused at the line.
#[test]
fn g41_takes_the_radius_from_the_tool_table() {
    use interpreter::program::interpret_with;
    use interpreter::program::tools::ToolTable;
    use interpreter::program::Options;
    let table = ToolTable::parse("tool.tbl", "T1 P1 D6 ;6 mm\nT2 P2 D3.0 Z12\n").unwrap();
    let opts = Options {
        tools: Some(table),
        ..Options::default()
    };
    let contour =
        "G1 X0 Y-10 F800\nG1 X0 Y40\nG1 X20 Y40\nG1 X20 Y0\nG1 X0 Y0\nG40 G1 X-20 Y-20\nM2\n";
    let head = "G21 G17 G90\nG0 X-20 Y-20\n";
    let moves = |code: &str| {
        let text = format!("{head}{code}\n{contour}");
        interpret_with(&text, &opts)
            .unwrap_or_else(|e| panic!("{code}: {e:?}"))
            .moves
    };
    assert_eq!(moves("G41 D2"), moves("G41.1 D3"));
    assert_eq!(moves("T1 M6\nG42"), moves("T1 M6\nG42.1 D6"));
    assert_ne!(moves("G41 D2"), moves("G41.1 D6"));
    for (code, line, says) in [
        ("G41 D7", 3, "not in the tool table"),
        ("G41 D1.5", 3, "whole number"),
        ("G41", 3, "no tool in the spindle"),
    ] {
        let text = format!("{head}{code}\n{contour}");
        let e = interpret_with(&text, &opts).unwrap_err();
        assert_eq!(e[0].line, line, "{code}: {e:?}");
        assert!(e[0].message.contains(says), "{code}: {e:?}");
    }
    let (line, msg) = refused(&format!("{head}G41 D1\n{contour}"));
    assert_eq!(line, 3);
    assert!(msg.contains("--tool-table"), "{msg}");
}

/// A full circle under compensation stays a full circle, whether the offset arc's end
/// comes out a rounding ahead of its start or behind it, and so does one entered
/// within the corner tolerance of tangent (its end then a little ahead): the cut goes
/// all the way round, its length `2π·(R ± r)` and more, never a sliver.
#[test]
fn a_full_circle_stays_a_full_circle() {
    use std::f64::consts::PI;
    // Tangent entries along -Y at X = 10 into a circle of radius 10 about the origin,
    // the tool inside (G41, anticlockwise) and outside (G42); then one entered 0.02 rad
    // off tangent.
    for (code, r_tool, lead) in [
        ("G41.1 D2", -1.0, "G1 X10 Y-10 F500\nG1 X10 Y0\n"),
        ("G42.1 D2", 1.0, "G1 X10 Y-10 F500\nG1 X10 Y0\n"),
        ("G41.1 D2", -1.0, "G1 X10.4 Y-20 F500\nG1 X10 Y0\n"),
    ] {
        let text = format!(
            "G21 G17 G90\nG0 X10 Y-30\n{code}\n{lead}G3 I-10 J0\nG1 X10 Y5\nG40 G1 X20 Y5\nM2\n"
        );
        let prog = interpret(&text).unwrap_or_else(|e| panic!("{code}: {e:?}"));
        let arcs: f64 = prog
            .moves
            .iter()
            .filter_map(|m| match m {
                Move::Arc {
                    from,
                    to,
                    center,
                    ccw,
                    turns,
                    ..
                } => {
                    // The angle round from `from` to `to` in the arc's direction, in
                    // (0, 2π], and a whole turn for each further one.
                    let a0 = (from[1] - center[1]).atan2(from[0] - center[0]);
                    let a1 = (to[1] - center[1]).atan2(to[0] - center[0]);
                    let mut d = if *ccw { a1 - a0 } else { a0 - a1 };
                    while d <= 0.0 {
                        d += 2.0 * PI;
                    }
                    let sweep = d + 2.0 * PI * (*turns as f64 - 1.0);
                    let r = (from[0] - center[0]).hypot(from[1] - center[1]);
                    Some(r * sweep)
                }
                _ => None,
            })
            .sum();
        let circle = 2.0 * PI * (10.0 + r_tool);
        assert!(
            arcs >= circle - 1e-6,
            "{code}, {lead}: arcs {arcs} mm against a circle of {circle}"
        );
    }
}

/// Found in review, each a path that jumped or a wrong radius before its fix: a stop
/// or the end on the line of a compensated move comes after the move (LinuxCNC's
/// order), so the move is compensated and the path continuous; `T2 M6` on the line of
/// `G41` changes the tool first; `G41 D0` is the tool in the spindle (LinuxCNC's index
/// 0); a full circle given its extra turn does not make the next corner a gouge.
#[test]
fn stops_tool_changes_and_full_circles_on_the_line_of_a_compensated_move() {
    use interpreter::program::interpret_with;
    use interpreter::program::tools::ToolTable;
    use interpreter::program::Options;
    for end in ["M2", "M0", "M1", "M30"] {
        let text =
            format!("G21 G17 G90 F100\nG0 X-20 Y0\nG41.1 D10\nG1 X0 Y0\nG1 X20 Y0 {end}\nM2\n");
        let p = path(&text);
        // The move along Y = 0 runs at Y = 5 (the tool on the left), its start too.
        let last = p.iter().rev().find(|m| m.0 == 'L').unwrap();
        assert!(
            (last.1[0] - 20.0).abs() < 1e-9 && (last.1[1] - 5.0).abs() < 1e-9,
            "{end}: {p:?}"
        );
    }
    let table = ToolTable::parse("tool.tbl", "T1 D2\nT2 D6\n").unwrap();
    let opts = Options {
        tools: Some(table),
        ..Options::default()
    };
    // The path's end points (the source lines differ with the lines the codes take).
    let ends = |code: &str| -> Vec<[f64; 3]> {
        let text = format!(
            "G21 G17 G90 F100\nG0 X-20 Y0\n{code}\nG1 X0 Y0\nG1 X20 Y0\nG40 G1 X30 Y-20\nM2\n"
        );
        let prog = interpret_with(&text, &opts).unwrap_or_else(|e| panic!("{code}: {e:?}"));
        continuous(&prog.moves);
        prog.moves
            .iter()
            .filter_map(|m| match m {
                Move::Line { to, .. } | Move::Arc { to, .. } => Some(*to),
                _ => None,
            })
            .collect()
    };
    assert_eq!(ends("T2 M6 G41"), ends("G41.1 D6"));
    assert_eq!(ends("T1 M6\nG41 D0"), ends("G41.1 D2"));
    // The review's circle: entered a little off tangent, given its extra turn, then
    // left at a concave corner that LinuxCNC accepts (its sweep 6.176 rad).
    let p = path("G21 G17 G90 F100\nG0 X21 Y-30\nG41.1 D4\nG1 X20 Y0\nG3 I-20 J0\nG1 X0 Y0\nG40 G1 X-10 Y-10\nM2\n");
    assert!(p.iter().any(|m| m.0 == 'A'), "{p:?}");
}

/// The programmed NURBS (`ctrl` `[x, y, z, w]`) by the conventional Cox–de Boor
/// evaluator (`shared::nurbs::reference`, not the one the interpreter uses), with 4 000
/// samples for the nearest-point scan.
struct Programmed<'a> {
    degree: usize,
    knots: &'a [f64],
    ctrl: &'a [[f64; 4]],
    samples: Vec<(f64, [f64; 2])>,
}

impl<'a> Programmed<'a> {
    fn new(degree: usize, knots: &'a [f64], ctrl: &'a [[f64; 4]]) -> Self {
        let (lo, hi) = (knots[degree], knots[ctrl.len()]);
        let mut p = Programmed {
            degree,
            knots,
            ctrl,
            samples: Vec::new(),
        };
        p.samples = (0..=4000)
            .map(|k| {
                let u = lo + (hi - lo) * k as f64 / 4000.0;
                (u, p.at(u))
            })
            .collect();
        p
    }

    fn at(&self, u: f64) -> [f64; 2] {
        let p =
            shared::nurbs::reference::conventional_curve(self.degree, self.knots, self.ctrl, u).p;
        [p[0], p[1]]
    }

    /// The distance from `q`: the nearest sample refined by golden-section search.
    fn distance(&self, q: [f64; 2]) -> f64 {
        let d = |p: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
        let k = (0..self.samples.len())
            .min_by(|&i, &j| d(self.samples[i].1).total_cmp(&d(self.samples[j].1)))
            .unwrap();
        let last = self.samples.len() - 1;
        let (mut a, mut b) = (
            self.samples[k.saturating_sub(1)].0,
            self.samples[(k + 1).min(last)].0,
        );
        let g = (5f64.sqrt() - 1.0) / 2.0;
        for _ in 0..80 {
            let (x1, x2) = (b - g * (b - a), a + g * (b - a));
            if d(self.at(x1)) < d(self.at(x2)) {
                b = x2;
            } else {
                a = x1;
            }
        }
        d(self.at((a + b) / 2.0)).min(d(self.samples[k].1))
    }
}

/// The compensated NURBS moves of `text`, each sampled 500 times.
fn offset_points(text: &str) -> Vec<[f64; 2]> {
    let prog = interpret(text).unwrap_or_else(|e| panic!("refused: {e:?}"));
    let mut last: Option<[f64; 3]> = None;
    let mut out = Vec::new();
    for m in &prog.moves {
        let (from, to) = match m {
            Move::Line { from, to, .. } | Move::Arc { from, to, .. } => (*from, *to),
            Move::Nurbs {
                degree,
                knots,
                ctrl,
                ..
            } => {
                let (lo, hi) = (knots[*degree], knots[ctrl.len()]);
                for k in 0..=500 {
                    let u = lo + (hi - lo) * k as f64 / 500.0;
                    let p = shared::nurbs::eval(*degree, knots, ctrl, u).p;
                    out.push([p[0], p[1]]);
                }
                let (a, b) = (ctrl[0], ctrl[ctrl.len() - 1]);
                ([a[0], a[1], a[2]], [b[0], b[1], b[2]])
            }
            _ => continue,
        };
        if let Some(e) = last {
            assert_eq!(e, from, "{m:?} does not start where the move before ended");
        }
        last = Some(to);
    }
    assert!(!out.is_empty(), "no NURBS move in\n{text}");
    out
}

/// A NURBS move under `G41.1`/`G42.1`: the tool's path is continuous (the corner arcs
/// and lines meet the fitted offset exactly) and every point of the fitted offset is
/// the tool's radius from the programmed curve, within half the chord tolerance (1 µm,
/// the program read without a machine), on either side, for a polynomial `G5.2` and a
/// rational `G6.2`.
#[test]
fn nurbs_moves_are_offset_within_the_chord_tolerance() {
    let bump: Vec<[f64; 4]> = [
        [20.0, 0.0],
        [30.0, 0.0],
        [35.0, 10.0],
        [45.0, 10.0],
        [50.0, 0.0],
        [60.0, 0.0],
    ]
    .iter()
    .map(|p| [p[0], p[1], -1.0, 1.0])
    .collect();
    let bump_knots = [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 3.0, 3.0, 3.0];
    // A rational quadratic: a quarter of the circle of radius 15 round (20, 15), then a
    // freer end (weights pull the curve about).
    let (h, w) = (std::f64::consts::FRAC_1_SQRT_2, [1.0, 1.5, 0.7]);
    let arc: Vec<[f64; 4]> = vec![
        [20.0, 0.0, -1.0, 1.0],
        [35.0, 0.0, -1.0, h],
        [35.0, 15.0, -1.0, 1.0],
        [35.0, 25.0, -1.0, w[1]],
        [45.0, 30.0, -1.0, w[2]],
        [55.0, 30.0, -1.0, 1.0],
    ];
    let arc_knots = [0.0, 0.0, 0.0, 1.0, 1.0, 2.0, 3.0, 3.0, 3.0];
    let g5_2 = "G5.2 L4 X30 Y0 P1\nX35 Y10 P1\nX45 Y10 P1\nX50 Y0 P1\nX60 Y0 P1\nG5.3\nG1 X80 Y0\n";
    let g6_2 = format!(
        "G6.2 X20 Y0 R1 K0 P3 Q1\nX35 Y0 R{h} K0\nX35 Y15 R1 K0\nX35 Y25 R{} K1\nX45 Y30 R{} K1\nX55 Y30 R1 K2\nG6.2 K3\nG6.2 K3\nG6.2 K3\nG1 X80 Y30\n",
        w[1], w[2]
    );
    let tol = interpreter::program::DEFAULT_OFFSET_TOL_MM;
    for (curve, knots, ctrl, degree) in [
        (g5_2.to_string(), &bump_knots[..], &bump, 3),
        (g6_2, &arc_knots[..], &arc, 2),
    ] {
        for (code, d) in [("G41.1", 6.0), ("G42.1", 6.0), ("G41.1", 2.0)] {
            let text = format!(
                "G21 G17 G90 G94\nG0 X-10 Y-10 Z5\nG1 Z-1 F600\n{code} D{d}\nG1 X0 Y0\nG1 X20 Y0\n{curve}G40\nG1 X90 Y-10\nM2\n"
            );
            let r = d / 2.0;
            let programmed = Programmed::new(degree, knots, ctrl);
            let mut worst = 0.0f64;
            for q in offset_points(&text) {
                worst = worst.max((programmed.distance(q) - r).abs());
            }
            // (The fit takes half the chord tolerance, the chords the other half.)
            assert!(worst <= tol / 2.0, "{code} D{d}: {worst} mm\n{text}");
            println!("{code} D{d}, degree {degree}: worst {worst:.3e} mm from the radius");
        }
    }
}

/// What a NURBS offset cannot be: a bend tighter than the tool on its side (with the
/// parameter where), an offset that crosses itself, a corner inside the curve. (`G06.2` under compensation in a Fanuc
/// program stays Fanuc's alarm PS1006: `dialects.rs`.)
#[test]
fn nurbs_offsets_the_tool_cannot_cut_are_refused_at_their_line() {
    let head = "G21 G17 G90 G94 F500\nG0 X0 Y-10\nG41.1 D6\nG1 X0 Y0\nG1 X20 Y0\n";
    for (body, line, says) in [
        // A corner inside the curve (a knot twice in a quadratic).
        (
            "G6.2 X20 Y0 R1 K0 P3 Q1\nX30 Y0 R1 K0\nX40 Y0 R1 K0\nX40 Y10 R1 K1\nX40 Y20 R1 K1\nG6.2 K2\nG6.2 K2\nG6.2 K2\n",
            6,
            "corner of",
        ),
        // A loop whose offset crosses itself where its ends pass close by.
        (
            "G5.2 L4 X60 Y0 P1\nX60 Y40 P1\nX30 Y40 P1\nX30 Y2 P1\nX30 Y-20 P1\nG5.3\n",
            6,
            "crosses itself",
        ),
    ] {
        let text = format!("{head}{body}");
        let (l, msg) = refused(&text);
        assert_eq!(l, line, "{body}: {msg}");
        assert!(msg.contains(says), "{body}: {msg}");
    }
    // The bump's feet bend round radius 14 mm: too tight for a 30 mm tool inside.
    let gouge = "G21 G17 G90 G94 F500\nG0 X-30 Y-30\nG41.1 D30\nG1 X0 Y0\nG1 X20 Y0\n\
                 G5.2 L4 X30 Y0 P1\nX35 Y10 P1\nX45 Y10 P1\nX50 Y0 P1\nX60 Y0 P1\nG5.3\n";
    let (l, msg) = refused(gouge);
    assert_eq!(l, 6, "{msg}");
    assert!(
        msg.contains("bends tighter than the tool at its parameter u = 0.41")
            && msg.contains("radius of curvature 14.02"),
        "{msg}"
    );
}

/// The review's cases, each of which cut the part before it was mended: a concave
/// corner after `M0` (the move before cannot be cut short), a modal `G5` under
/// compensation (ran uncompensated; the next move jumped 10 mm), and a line followed by
/// a curve turning back into the side the tool is on (wrapped 180°, 3.2 mm on the wrong
/// side; the part between them is thinner than the tool). (Its cases of a move along Z
/// between a NURBS and a concave corner and of an "h" are cut as they should be now:
/// `concave_corners_at_nurbs_moves_cut_them_short_where_the_offsets_meet`.)
#[test]
fn nurbs_corners_the_review_found_wrong_are_refused() {
    for (text, line, says) in [
        (
            "G21 G17 G90 G94 F100\nG0 X-10 Y-10\nG41.1 D10\nG1 X0 Y10\nG1 X20 Y10\nM0\n\
             G1 Z-1\nG1 X20 Y30\n",
            8,
            "after a stop",
        ),
        (
            "G21 G17 G90 G94 F100\nG0 X0 Y0\nG5 I5 J5 P-5 Q5 X10 Y0\nG41.1 D4\nX20 Y0 P-5 Q5\n\
             G1 X30 Y10\nG40 G1 X40 Y0\nM2\n",
            5,
            "modal",
        ),
        (
            "G21 G17 G90 G94 F100\nG0 X-10 Y-10\nG42.1 D4\nG1 X-10 Y0\nG1 X0 Y0\n\
             G5.2 L3 X-10 Y0 P1\nX-20 Y-3 P1\nG5.3\n",
            6,
            "cannot be reached by the tool without gouging",
        ),
    ] {
        let (l, msg) = refused(text);
        assert_eq!(l, line, "{text}: {msg}");
        assert!(msg.contains(says), "{text}: {msg}");
    }
    // A NURBS entered exactly along the tangent of the line before: no line of a
    // rounding's length between them.
    let text = "G21 G17 G90 G94 F100\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0\nG1 X20 Y0\n\
                G5.2 L3 X30 Y0 P1\nX40 Y5 P1\nG5.3\nG40 G1 X50 Y-10\nM2\n";
    let prog = interpret(text).unwrap();
    let shortest = prog
        .moves
        .iter()
        .filter_map(|m| match m {
            Move::Line { from, to, .. } => Some((to[0] - from[0]).hypot(to[1] - from[1])),
            _ => None,
        })
        .fold(f64::INFINITY, f64::min);
    assert!(shortest > 1.0, "{shortest} mm: {:?}", prog.moves);
    offset_points(text);
}

/// A point of a move, `t` from its start (0) to its end (1), in XY; none for moves that
/// do not go anywhere in XY.
fn point_of(m: &Move, t: f64) -> Option<[f64; 2]> {
    match m {
        Move::Line { from, to, .. } => Some([
            from[0] + t * (to[0] - from[0]),
            from[1] + t * (to[1] - from[1]),
        ]),
        Move::Arc {
            from,
            to,
            center,
            ccw,
            turns,
            ..
        } => {
            let (a0, sweep) = arc_angles(*from, *to, *center, *ccw, *turns);
            let r = (from[0] - center[0]).hypot(from[1] - center[1]);
            let a = a0 + t * sweep;
            Some([center[0] + r * a.cos(), center[1] + r * a.sin()])
        }
        Move::Nurbs {
            degree,
            knots,
            ctrl,
            ..
        } => {
            let (lo, hi) = (knots[*degree], knots[ctrl.len()]);
            let p = shared::nurbs::reference::conventional_curve(
                *degree,
                knots,
                ctrl,
                lo + t * (hi - lo),
            )
            .p;
            Some([p[0], p[1]])
        }
        _ => None,
    }
}

/// An arc's start angle and signed sweep (radians, + anticlockwise).
fn arc_angles(from: [f64; 3], to: [f64; 3], c: [f64; 3], ccw: bool, turns: u32) -> (f64, f64) {
    use std::f64::consts::TAU;
    let a0 = (from[1] - c[1]).atan2(from[0] - c[0]);
    let a1 = (to[1] - c[1]).atan2(to[0] - c[0]);
    let mut s = if ccw { a1 - a0 } else { a0 - a1 };
    if s <= 0.0 {
        s += TAU;
    }
    s += (turns.max(1) - 1) as f64 * TAU;
    (a0, if ccw { s } else { -s })
}

/// A programmed move as the tool's path is measured against.
enum Shape<'a> {
    Segment([f64; 2], [f64; 2]),
    Arc {
        c: [f64; 2],
        r: f64,
        a0: f64,
        sweep: f64,
        ends: [[f64; 2]; 2],
    },
    Curve(Programmed<'a>),
}

impl Shape<'_> {
    /// The distance from `q`, or for a curve that of the nearest of every eighth sample
    /// (at most four samples' spacing above it).
    fn rough(&self, q: [f64; 2]) -> f64 {
        match self {
            Shape::Curve(p) => p
                .samples
                .iter()
                .step_by(8)
                .map(|s| (s.1[0] - q[0]).hypot(s.1[1] - q[1]))
                .fold(f64::INFINITY, f64::min),
            _ => self.distance(q),
        }
    }

    fn distance(&self, q: [f64; 2]) -> f64 {
        let d = |p: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
        match self {
            Shape::Segment(a, b) => to_segment(q, *a, *b),
            Shape::Arc {
                c,
                r,
                a0,
                sweep,
                ends,
            } => {
                let mut off = (q[1] - c[1]).atan2(q[0] - c[0]) - a0;
                if *sweep < 0.0 {
                    off = -off;
                }
                let off = off.rem_euclid(std::f64::consts::TAU);
                if off <= sweep.abs() {
                    (d(*c) - r).abs()
                } else {
                    d(ends[0]).min(d(ends[1]))
                }
            }
            Shape::Curve(p) => p.distance(q),
        }
    }
}

/// How far the tool's path strays from running the tool's radius `r` from the
/// programmed path, between the entry move (line `entry`) and the exit (line `exit`):
/// each move of the compensated path sampled 64 times, each point's distance to the
/// nearest programmed move between those lines (read uncompensated). Below `r`: the
/// tool cuts into the part; above: it leaves material where a move is. Also how many
/// NURBS moves were cut short at a corner.
fn departure(text: &str, r: f64, entry: u32, exit: u32) -> Result<(f64, usize), String> {
    const SAMPLES: usize = 64;
    use interpreter::program::{interpret_with, Options};
    let tool = interpret(text).map_err(|e| format!("{}: {}", e[0].line, e[0].message))?;
    let programmed = interpret_with(
        text,
        &Options {
            uncompensated: true,
            ..Options::default()
        },
    )
    .expect("the program reads uncompensated");
    let inside = |m: &Move| (entry + 1..exit).contains(&m.line());
    let shapes: Vec<Shape> = programmed
        .moves
        .iter()
        .filter(|m| inside(m))
        .filter_map(|m| match m {
            Move::Line { from, to, .. } if from[..2] != to[..2] => {
                Some(Shape::Segment([from[0], from[1]], [to[0], to[1]]))
            }
            Move::Arc {
                from,
                to,
                center,
                ccw,
                turns,
                ..
            } => {
                let (a0, sweep) = arc_angles(*from, *to, *center, *ccw, *turns);
                Some(Shape::Arc {
                    c: [center[0], center[1]],
                    r: (from[0] - center[0]).hypot(from[1] - center[1]),
                    a0,
                    sweep,
                    ends: [[from[0], from[1]], [to[0], to[1]]],
                })
            }
            Move::Nurbs {
                degree,
                knots,
                ctrl,
                ..
            } => Some(Shape::Curve(Programmed::new(*degree, knots, ctrl))),
            _ => None,
        })
        .collect();
    let curves: Vec<(f64, f64)> = programmed
        .moves
        .iter()
        .filter_map(|m| match m {
            Move::Nurbs {
                degree,
                knots,
                ctrl,
                ..
            } => Some((knots[*degree], knots[ctrl.len()])),
            _ => None,
        })
        .collect();
    let mut worst = 0.0f64;
    let mut cut_short = 0;
    for m in tool.moves.iter().filter(|m| inside(m)) {
        if let Move::Nurbs { knots, ctrl, .. } = m {
            let (lo, hi) = (knots[3], knots[ctrl.len()]);
            if !curves.iter().any(|&(a, b)| a == lo && b == hi) {
                cut_short += 1;
            }
        }
        for k in 0..=SAMPLES {
            let Some(q) = point_of(m, k as f64 / SAMPLES as f64) else {
                break;
            };
            // (Only the moves whose rough distance is near the least are refined.)
            let rough: Vec<f64> = shapes.iter().map(|s| s.rough(q)).collect();
            let least = rough.iter().copied().fold(f64::INFINITY, f64::min);
            let d = shapes
                .iter()
                .zip(&rough)
                .filter(|(_, &d)| d <= least + 0.05)
                .map(|(s, _)| s.distance(q))
                .fold(f64::INFINITY, f64::min);
            worst = worst.max((d - r).abs());
        }
    }
    Ok((worst, cut_short))
}

/// Concave corners into, out of and between NURBS moves (LinuxCNC refuses NURBS under
/// compensation; it cuts lines and arcs short where their offsets meet, and so do we
/// with the fitted offset): from a line, to a line, between two curves, from an arc, to
/// an arc, with a move along Z between, an "h" (a curve bending away, then a line back
/// along it) and a curve turning back from a line. Each is cut short at the corner, and
/// every point of the tool's path is the tool's radius from the part, within half the
/// chord tolerance (the fit's share; the corners themselves are exact).
#[test]
fn concave_corners_at_nurbs_moves_cut_them_short_where_the_offsets_meet() {
    let tol = interpreter::program::DEFAULT_OFFSET_TOL_MM / 2.0 + 1e-9;
    let left = "G21 G17 G90 G94 F500\nG0 X0 Y-10\nG41.1 D6\nG1 X0 Y0\nG1 X20 Y0\n";
    for (name, text, r, (entry, exit)) in [
        (
            "line into curve",
            format!("{left}G5.2 L3 X15 Y10 P1\nX10 Y20 P1\nG5.3\nG40 G1 X0 Y30\nM2\n"),
            3.0,
            (4, 9),
        ),
        (
            "curve into line",
            format!("{left}G5.2 L3 X30 Y0 P1\nX40 Y0 P1\nG5.3\nG1 X30 Y10\nG40 G1 X20 Y30\nM2\n"),
            3.0,
            (4, 10),
        ),
        (
            "curve into curve",
            format!("{left}G5.2 L3 X30 Y0 P1\nX40 Y0 P1\nG5.3\nG5.2 L3 X40 Y10 P1\nX30 Y20 P1\nG5.3\nG40 G1 X20 Y40\nM2\n"),
            3.0,
            (4, 12),
        ),
        (
            "arc into curve",
            format!("{left}G3 X30 Y10 I0 J10\nG5.2 L3 X20 Y15 P1\nX10 Y15 P1\nG5.3\nG40 G1 X0 Y30\nM2\n"),
            3.0,
            (4, 10),
        ),
        (
            "curve into arc",
            format!("{left}G5.2 L3 X30 Y0 P1\nX40 Y0 P1\nG5.3\nG2 X60 Y0 I10 J0\nG40 G1 X70 Y-20\nM2\n"),
            3.0,
            (4, 10),
        ),
        (
            "curve, move along Z, line",
            "G21 G17 G90 G94 F100\nG0 X-10 Y-10\nG41.1 D4\nG1 X0 Y0\nG1 X20 Y0\n\
             G5.2 L3 X30 Y-1 P1\nX40 Y0 P1\nG5.3\nG1 Z-1\nG1 X40 Y20\nG40 G1 X50 Y30\nM2\n"
                .to_string(),
            2.0,
            (4, 11),
        ),
        (
            "h: a curve bending away, a line back",
            "G21 G17 G90 G94 F100\nG0 X-10 Y20\nG42.1 D4\nG1 X-10 Y10\n\
             G5.2 L3 X-10 Y0 P0.70710678\nX0 Y0 P1\nG5.3\nG1 X-20 Y0\nG40 G1 X-30 Y-10\nM2\n"
                .to_string(),
            2.0,
            (4, 9),
        ),
    ] {
        let (worst, cut) = departure(&text, r, entry, exit)
            .unwrap_or_else(|e| panic!("{name}: refused at {e}\n{text}"));
        assert!(worst <= tol, "{name}: {worst} mm from the radius\n{text}");
        assert!(cut >= 1, "{name}: no NURBS move cut short\n{text}");
        println!("{name}: worst {worst:.3e} mm, {cut} curves cut short");
        offset_points(&text);
    }
}

/// Random open chains of lines, arcs and cubic NURBS moves (each 15 to 30 mm, corners
/// turning up to 100° either way but not within 0.1 rad of straight on or back, the
/// chain heading within 75° of +X so that it never comes back on itself), cut with tools of 2 to 8 mm on either side: every program
/// that is not refused keeps every point of the tool's path the tool's radius from the
/// part, within half the chord tolerance, through convex and concave corners alike;
/// most are not refused, and concave corners cut NURBS moves short in many of them.
#[test]
fn random_chains_of_lines_arcs_and_nurbs_keep_the_tool_its_radius_from_the_part() {
    use std::f64::consts::PI;
    let tol = interpreter::program::DEFAULT_OFFSET_TOL_MM / 2.0 + 1e-9;
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut cut, mut accepted, mut curves_cut) = (0, 0, 0);
    let cases = 150;
    for case in 0..cases {
        let d = 2.0 + 6.0 * rng.unit();
        let g = if case % 2 == 0 { "G41.1" } else { "G42.1" };
        let mut text = format!("G21 G17 G90 G94 F800\nG0 X-10 Y-30\n{g} D{d:.6}\nG1 X0 Y0\n");
        // (The entry move comes from (-10, -30).)
        let (mut p, mut heading, mut tangent) = ([0.0f64, 0.0], 0.0f64, 30f64.atan2(10.0));
        let n = 4 + (rng.unit() * 5.0) as usize;
        let mut made = 0;
        while made < n {
            let h = (heading + (rng.unit() - 0.5) * 2.0 * 100f64.to_radians())
                .clamp(-75f64.to_radians(), 75f64.to_radians());
            let len = 15.0 + 15.0 * rng.unit();
            let q = [p[0] + len * h.cos(), p[1] + len * h.sin()];
            let normal = [-h.sin(), h.cos()];
            // The move, and the directions it starts and ends in.
            let (code, start, end) = match (rng.unit() * 3.0) as u32 {
                0 => (format!("G1 X{:.6} Y{:.6}\n", q[0], q[1]), h, h),
                1 => {
                    // An arc of 20° to 120° on the chord, either way round (a clockwise
                    // one bulging to the chord's left).
                    let sweep = (20.0 + 100.0 * rng.unit()) * PI / 180.0;
                    let r = len / (2.0 * (sweep / 2.0).sin());
                    let (code, turn) = if rng.unit() < 0.5 {
                        ("G2", 1.0)
                    } else {
                        ("G3", -1.0)
                    };
                    (
                        format!("{code} X{:.6} Y{:.6} R{r:.6}\n", q[0], q[1]),
                        h + turn * sweep / 2.0,
                        h - turn * sweep / 2.0,
                    )
                }
                _ => {
                    let at = |f: f64, bulge: f64| {
                        [
                            p[0] + f * (q[0] - p[0]) + bulge * len * normal[0],
                            p[1] + f * (q[1] - p[1]) + bulge * len * normal[1],
                        ]
                    };
                    let b1 = at(1.0 / 3.0, (rng.unit() - 0.5) * 0.5);
                    let b2 = at(2.0 / 3.0, (rng.unit() - 0.5) * 0.5);
                    (
                        format!(
                            "G5.2 L4 X{:.6} Y{:.6} P1\nX{:.6} Y{:.6} P1\nX{:.6} Y{:.6} P1\nG5.3\n",
                            b1[0], b1[1], b2[0], b2[1], q[0], q[1]
                        ),
                        (b1[1] - p[1]).atan2(b1[0] - p[0]),
                        (q[1] - b2[1]).atan2(q[0] - b2[0]),
                    )
                }
            };
            // Not within 0.1 rad of straight on or of straight back: LinuxCNC runs on
            // across a corner within 0.05 rad (its `TOLERANCE_CONCAVE_CORNER`), a
            // little into the part where it is concave, and we with it.
            let turn = (start - tangent + PI).rem_euclid(2.0 * PI) - PI;
            if turn.abs() < 0.1 || turn.abs() > PI - 0.1 {
                continue;
            }
            text += &code;
            (p, heading, tangent) = (q, h, end);
            made += 1;
        }
        let exit = text.lines().count() as u32 + 1;
        text += &format!("G40 G1 X{:.6} Y{:.6}\nM2\n", p[0] + 10.0, p[1] - 30.0);
        if std::env::var("CASE").is_ok_and(|c| c != case.to_string()) {
            continue;
        }
        match departure(&text, d / 2.0, 4, exit) {
            Ok((worst, short)) => {
                assert!(
                    worst <= tol,
                    "case {case}: {worst} mm from the radius\n{text}"
                );
                accepted += 1;
                curves_cut += usize::from(short > 0);
                cut += short;
            }
            Err(e) => println!("case {case}: refused at {e}"),
        }
    }
    println!("{accepted} of {cases} cut; {curves_cut} with NURBS moves cut short ({cut} in all)");
    assert!(accepted * 2 > cases, "{accepted} of {cases}");
    assert!(curves_cut * 5 > accepted, "{curves_cut} of {accepted}");
}

/// Fanuc's `G06.2` under `G41`: alarm PS1006, as a Fanuc control gives, unless the
/// program is read with `--dialect-extension g06.2-comp`; then the curve is offset
/// exactly as the same curve written as LinuxCNC's `G5.2` is.
#[test]
fn fanuc_g06_2_under_compensation_is_offset_only_when_asked() {
    use interpreter::program::dialect::Extension;
    use interpreter::program::tools::ToolTable;
    use interpreter::program::{interpret_with, Options};
    let head = "G21 G17 G90 G94 F500\nG0 X0 Y-10\nG41 D1\nG1 X0 Y0\nG1 X20 Y0\n";
    let tail = "G1 X60 Y0\nG40 G1 X70 Y-10\nM30\n";
    let fanuc = format!(
        "{head}G06.2 P4 K0 X20 Y0\nK0 X30 Y0\nK0 X35 Y10\nK0 X45 Y10\nK1 X50 Y0\nK2\nK2\nK2\nK2\n{tail}"
    );
    let linuxcnc =
        format!("{head}G5.2 L4 X30 Y0 P1\nX35 Y10 P1\nX45 Y10 P1\nX50 Y0 P1\nG5.3\n{tail}");
    let tools = ToolTable::parse("tool.tbl", "T1 P1 D6 ;6 mm\n").unwrap();
    let plain = Options {
        tools: Some(tools),
        ..Options::default()
    };
    let extended = Options {
        extensions: vec![Extension::FanucNurbsComp],
        ..plain.clone()
    };
    let e = interpret_with(&fanuc, &plain).unwrap_err();
    assert_eq!(e[0].line, 6, "{e:?}");
    assert!(
        e[0].message.contains("PS1006") && e[0].message.contains("--dialect-extension g06.2-comp"),
        "{e:?}"
    );
    let ours = interpret_with(&fanuc, &extended).unwrap_or_else(|e| panic!("{e:?}"));
    let theirs = interpret_with(&linuxcnc, &plain).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(ours.dialect, interpreter::program::Dialect::Fanuc);
    let points = |p: &interpreter::program::Program| -> Vec<[f64; 3]> {
        p.moves
            .iter()
            .flat_map(|m| match m {
                Move::Line { to, .. } | Move::Arc { to, .. } => vec![*to],
                Move::Nurbs { ctrl, .. } => ctrl.iter().map(|c| [c[0], c[1], c[2]]).collect(),
                _ => Vec::new(),
            })
            .collect()
    };
    let (a, b) = (points(&ours), points(&theirs));
    assert!(ours.moves.iter().any(|m| matches!(m, Move::Nurbs { .. })));
    assert_eq!(a.len(), b.len(), "{:?}\n{:?}", ours.moves, theirs.moves);
    for (p, q) in a.iter().zip(&b) {
        assert!(
            (p[0] - q[0]).hypot(p[1] - q[1]) < 1e-9,
            "{p:?} against {q:?}"
        );
    }
    // The extension changes nothing in a LinuxCNC program.
    assert_eq!(
        interpret_with(&linuxcnc, &extended).unwrap().moves,
        theirs.moves
    );
}

/// The review's cases for concave corners at NURBS moves: an arc just larger than the
/// tool after a straight curve (the curve's offset passes in and out of the arc's small
/// offset circle between two of the search's samples: it was refused, where the same
/// program with a line is cut), the mirror case into a curve, a curve cut short to a
/// hundred-millionth of a millimetre (it was sent as a block of no length), and a
/// Fanuc `G06.2` that climbs in Z (its offset was flattened to its first Z; refused).
#[test]
fn concave_corners_at_nurbs_the_review_found_wrong() {
    use interpreter::program::dialect::Extension;
    use interpreter::program::tools::ToolTable;
    use interpreter::program::{interpret_with, Options};
    let tol = interpreter::program::DEFAULT_OFFSET_TOL_MM / 2.0 + 1e-9;
    let arc_after = "G21 G17 G90 G94 F500\nG0 X0 Y-10\nG41.1 D6\nG1 X0 Y0\n\
                     G5.2 L3 X10 Y0 P1\nX20 Y0 P1\nG5.3\n\
                     G3 X18.0635 Y6.1000 I-0.9682 J3.0500\nG40 G1 X8.0635 Y16.1000\nM2\n";
    let arc_before = "G21 G17 G90 G94 F500\nG0 X4.0635 Y20.1\nG42.1 D6\nG1 X8.0635 Y16.1\n\
                      G1 X18.0635 Y6.1000\nG2 X20 Y0 I0.9682 J-3.0500\n\
                      G5.2 L3 X10 Y0 P1\nX0 Y0 P1\nG5.3\nG40 G1 X0 Y-10\nM2\n";
    for (name, text, exit) in [("arc after", arc_after, 9), ("arc before", arc_before, 10)] {
        let (worst, cut) = departure(text, 3.0, 4, exit)
            .unwrap_or_else(|e| panic!("{name}: refused at {e}\n{text}"));
        assert!(worst <= tol, "{name}: {worst} mm\n{text}");
        assert!(cut >= 1, "{name}");
    }
    // A curve that the concave corner after it cuts to 1e-8 mm: no block of no length.
    let eps = 1e-8;
    let mut theta = 146.6f64.to_radians();
    for _ in 0..50 {
        // (−10 + ε)·sin θ − 3·cos θ = −3: the next line's offset through (20 + ε, 3).
        let f = (-10.0 + eps) * theta.sin() - 3.0 * theta.cos() + 3.0;
        let df = (-10.0 + eps) * theta.cos() + 3.0 * theta.sin();
        theta -= f / df;
    }
    let end = [30.0 + 20.0 * theta.cos(), 20.0 * theta.sin()];
    let text = format!(
        "G21 G17 G90 G94 F500\nG0 X0 Y-10\nG41.1 D6\nG1 X0 Y0\nG1 X20 Y0\n\
         G5.2 L3 X25 Y0 P1\nX30 Y0 P1\nG5.3\nG1 X{:.15} Y{:.15}\nG40 G1 X0 Y30\nM2\n",
        end[0], end[1]
    );
    let prog = interpret(&text).unwrap_or_else(|e| panic!("{e:?}\n{text}"));
    for m in &prog.moves {
        if let Move::Nurbs { ctrl, .. } = m {
            let length: f64 = ctrl
                .windows(2)
                .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
                .sum();
            assert!(length > 1e-6, "a NURBS block of {length} mm: {m:?}");
        }
    }
    // A climbing G06.2 under compensation is refused, not flattened.
    let climb = "G21 G17 G90 G94 F500\nG0 X0 Y-10 Z0\nG41 D1\nG1 X0 Y0\nG1 X20 Y0\n\
                 G06.2 P4 K0 X20 Y0 Z0\nK0 X30 Y0 Z-2\nK0 X35 Y10 Z-4\nK0 X45 Y10 Z-6\nK1 X50 Y0 Z-8\n\
                 K2\nK2\nK2\nK2\nG1 X60 Y0\nG40 G1 X70 Y-10\nM30\n";
    let opts = Options {
        tools: Some(ToolTable::parse("tool.tbl", "T1 P1 D6\n").unwrap()),
        extensions: vec![Extension::FanucNurbsComp],
        ..Options::default()
    };
    let e = interpret_with(climb, &opts).unwrap_err();
    assert_eq!(e[0].line, 6, "{e:?}");
    assert!(e[0].message.contains("stay at one height"), "{e:?}");
}
