//! The generated programs of `benches/check.rs`, shared with the test that holds their
//! blocks to golden values (`tests/check_golden.rs`), so both see the very same text.

use std::fmt::Write as _;

/// The built-in machine with X's travel as long as a machine file allows (±100 000 mm):
/// `mixed` walks along X, 73 m in 100 000 lines, past the built-in ±1000 mm.
pub fn long_x_machine() -> shared::Machine {
    let mut m = shared::Machine::default();
    m.axes.x.min_mm = -shared::machine::MAX_TRAVEL_MM;
    m.axes.x.max_mm = shared::machine::MAX_TRAVEL_MM;
    m
}

/// `G1` moves along a zig-zag with a wavy Z, as a surface finishing pass: every line
/// a new X Y Z, the feed on the first. `lines` lines in all.
pub fn plain_g1(lines: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z5\nG1 Z0 F1200\n");
    let mut i = 3;
    while i < lines - 1 {
        let (row, col) = (i / 200, i % 200);
        let x = if row % 2 == 0 { col } else { 199 - col } as f64 * 0.5;
        let y = row as f64 * 0.5;
        let z = -0.5 - 0.25 * (x * 0.1).sin() * (y * 0.07).cos();
        let _ = writeln!(s, "G1 X{x:.3} Y{y:.3} Z{z:.4}");
        i += 1;
    }
    s.push_str("M2\n");
    s
}

/// One smooth spiral of `lines` lines of `G1` under `G64` (or `G64 P<blend>`), each
/// about 0.05 mm long at F3000 and turning 1.1° at the start, less further out: no rest
/// from its first line to its last, so it is planned in windows cut at speed. A million
/// lines stay within ±30 mm. (Not among `tests/check_golden.rs`'s programs.)
#[allow(dead_code)]
pub fn spiral(lines: usize, blend: Option<f64>) -> String {
    let mode = blend.map_or("G64".to_string(), |p| format!("G64 P{p}"));
    let mut s = format!(
        "G21 G90 G17
G0 X0 Y0 Z0
{mode}
G1 F3000
"
    );
    for i in 1..lines.saturating_sub(4) {
        let t = i as f64 * 0.0005;
        let r = 2.0 + 0.05 * t;
        let _ = writeln!(
            s,
            "G1 X{:.4} Y{:.4}",
            r * (t * 40.0).cos(),
            r * (t * 40.0).sin()
        );
    }
    s.push_str("M2\n");
    s
}

/// Groups of a line, an arc, a `G5.2` NURBS of six lines and a `G6.2` NURBS of nine,
/// each group starting and ending on the X axis, shifted along it; at most `lines`
/// lines.
pub fn mixed(lines: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X0 Y0 Z0\nF1500\n");
    let mut n = 3;
    let mut x0 = 0.0f64;
    while n + 18 < lines {
        let _ = writeln!(s, "G1 X{:.3} Y0", x0 + 1.0);
        let _ = writeln!(s, "G2 X{:.3} Y0 I1 J0", x0 + 3.0);
        let _ = writeln!(s, "G5.2 X{:.3} Y1 P1 L4", x0 + 4.0);
        let _ = writeln!(s, "X{:.3} Y-1 P2", x0 + 5.0);
        let _ = writeln!(s, "X{:.3} Y1 P1", x0 + 6.0);
        let _ = writeln!(s, "X{:.3} Y0 P1", x0 + 7.0);
        s.push_str("G5.3\n");
        let b = x0 + 7.0;
        let _ = writeln!(s, "G6.2 X{b:.3} Y0 R1 K0 P3 Q1");
        let _ = writeln!(s, "X{:.3} Y1 R1 K0", b + 1.0);
        let _ = writeln!(s, "X{:.3} Y-1 R2 K0", b + 2.0);
        let _ = writeln!(s, "X{:.3} Y0 R1 K1", b + 3.0);
        s.push_str("G6.2 K2\nG6.2 K2\nG6.2 K2\n");
        // Back to the start of the next group's line.
        let _ = writeln!(s, "G1 X{:.3} Y0", b + 4.0);
        n += 15;
        x0 = b + 4.0;
    }
    s.push_str("M2\n");
    s
}

/// Groups of twelve lines that LinuxCNC's `rs274` reads too (no `G6.2`): a line, a
/// `G2` and a `G3` half circle, a cubic `G5.2` NURBS of six points with weights 1 to 3,
/// two lines; 13 mm along X each, in rows from X-900 Y-500, 5 mm apart in Y (a `G0`
/// between rows), inside the built-in travel. At most `lines` lines.
pub fn curves(lines: usize) -> String {
    let mut s = String::from("G21 G90 G17\nG0 X-900 Y-500 Z0\nF1500\n");
    let mut n = 3;
    let (mut x0, mut y0) = (-900.0f64, -500.0f64);
    let xy = |x0: f64, y0: f64, dx: f64, dy: f64| format!("X{:.3} Y{:.3}", x0 + dx, y0 + dy);
    while n + 16 < lines {
        let p = |dx, dy| xy(x0, y0, dx, dy);
        let _ = writeln!(s, "G1 {}", p(1.0, 0.0));
        let _ = writeln!(s, "G2 {} I1 J0", p(3.0, 0.0));
        let _ = writeln!(s, "G3 {} I1 J0", p(5.0, 0.0));
        let _ = writeln!(s, "G5.2 {} P1 L4", p(6.0, 1.0));
        let _ = writeln!(s, "{} P2", p(7.0, -1.0));
        let _ = writeln!(s, "{} P1", p(8.0, 1.5));
        let _ = writeln!(s, "{} P1", p(9.0, -0.5));
        let _ = writeln!(s, "{} P3", p(10.0, 0.8));
        let _ = writeln!(s, "{} P1", p(11.0, 0.0));
        s.push_str("G5.3\n");
        let _ = writeln!(s, "G1 {}", p(12.0, 0.5));
        let _ = writeln!(s, "G1 {}", p(13.0, 0.0));
        n += 12;
        x0 += 13.0;
        if x0 > 880.0 {
            (x0, y0) = (-900.0, y0 + 5.0);
            let _ = writeln!(s, "G0 {}", xy(x0, y0, 0.0, 0.0));
            n += 1;
        }
    }
    s.push_str("M2\n");
    s
}
