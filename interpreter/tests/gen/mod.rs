//! Generators of programs for the property tests: pieces of G-code words assembled at
//! random, plausible programs (well-formed lines with random numbers), and the real
//! LinuxCNC programs of `tests/peers/linuxcnc` with byte-level mutations. Shared by
//! `robustness.rs` (never a panic, every diagnostic located) and `check_runs.rs` (what
//! `check` accepts runs to its end).

#![allow(dead_code)]

use proptest::prelude::*;

/// Words and pieces of words that reach every corner of the reader and the modal state
/// machine: motions, curves, flow, parameters, expressions, numbers large and small.
pub const PIECES: &[&str] = &[
    "G0",
    "G1",
    "G2",
    "G3",
    "G4",
    "G5",
    "G5.1",
    "G5.2",
    "G5.3",
    "G6.2",
    "G06.2",
    "G05",
    "G17",
    "G18",
    "G19",
    "G20",
    "G21",
    "G40",
    "G41",
    "G61",
    "G64",
    "G90",
    "G91",
    "G90.1",
    "G91.1",
    "G93",
    "G94",
    "M2",
    "M3",
    "M0",
    "M30",
    "X",
    "Y",
    "Z",
    "I",
    "J",
    "K",
    "R",
    "P",
    "Q",
    "L",
    "F",
    "S",
    "N",
    "A",
    "1",
    "0",
    "-1",
    "2.5",
    "10",
    "1000",
    "4",
    "3",
    "0.0001",
    "1e5",
    "99999999999",
    "100000000000000000000000000000000000000000000000000",
    ".",
    "-",
    "+",
    "*",
    "/",
    "**",
    "MOD",
    "[",
    "]",
    "#1",
    "#5399",
    "#<a>",
    "#<_g>",
    "=",
    "SIN",
    "ATAN",
    "SQRT",
    "EXISTS",
    "EQ",
    "AND",
    " ",
    " ",
    "(",
    ")",
    "(MSG,hi)",
    ";",
    "/",
    "%",
    "O1",
    "o<s>",
    "sub",
    "endsub",
    "call",
    "return",
    "if",
    "elseif",
    "else",
    "endif",
    "while",
    "endwhile",
    "do",
    "repeat",
    "endrepeat",
    "break",
    "continue",
    "\t",
    "\u{0}",
    "é",
    "\u{FFFD}",
];

pub fn piece() -> impl Strategy<Value = &'static str> {
    (0..PIECES.len()).prop_map(|i| PIECES[i])
}

pub fn token_program() -> impl Strategy<Value = String> {
    proptest::collection::vec(proptest::collection::vec(piece(), 0..14), 0..24).prop_map(|lines| {
        lines
            .iter()
            .map(|l| l.concat())
            .collect::<Vec<_>>()
            .join("\n")
    })
}

/// Plausible programs: every line a well-formed move or a curve block with random
/// numbers, so that the checks behind the reader (arcs, curves, planning) run too.
pub fn plausible_program() -> impl Strategy<Value = String> {
    let num = prop_oneof![
        4 => (-100i32..100).prop_map(|v| v.to_string()),
        1 => (-1e6f64..1e6).prop_map(|v| format!("{v:.4}")),
        1 => Just("0".to_string()),
        1 => Just("1".repeat(40)),
    ];
    let line =
        (0usize..12, num.clone(), num.clone(), num.clone(), num).prop_map(|(kind, a, b, c, d)| {
            match kind {
                0 => format!("G1 X{a} Y{b} Z{c} F{d}"),
                1 => format!("G2 X{a} Y{b} I{c} J{d}"),
                2 => format!("G3 X{a} Y{b} R{c} P{d}"),
                3 => format!("G5.2 X{a} Y{b} P{c} L{d}"),
                4 => format!("X{a} Y{b} P{c}"),
                5 => "G5.3".to_string(),
                6 => format!("G6.2 X{a} Y{b} R1 K{c} P{d} Q1"),
                7 => format!("G06.2 P{d} K{c} X{a} Y{b}"),
                8 => format!("K{a}"),
                9 => format!("G5 X{a} Y{b} I{c} J{d} P{a} Q{b}"),
                10 => format!("G93 G1 X{a} F{d}"),
                _ => format!("G4 P{a}"),
            }
        });
    proptest::collection::vec(line, 0..16).prop_map(|l| format!("F100\n{}\n", l.join("\n")))
}

/// The LinuxCNC programs shipped with the project (`tests/peers/linuxcnc`).
pub fn peers() -> &'static [(String, String)] {
    static PEERS: std::sync::OnceLock<Vec<(String, String)>> = std::sync::OnceLock::new();
    PEERS.get_or_init(|| {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/peers/linuxcnc");
        let mut out: Vec<(String, String)> = std::fs::read_dir(dir)
            .unwrap_or_else(|e| panic!("{dir}: {e}"))
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "ngc"))
            .map(|p| {
                let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{p:?}: {e}"));
                (p.display().to_string(), text)
            })
            .collect();
        out.sort();
        assert!(out.len() >= 20, "peer programs missing in {dir}");
        out
    })
}

/// One edit of a program's bytes, at a position given as a fraction of its length.
#[derive(Debug, Clone)]
pub enum Mutation {
    Delete(f64),
    Duplicate(f64),
    Swap(f64),
    /// A digit becomes another digit.
    Digit(f64, u8),
    /// A word (a letter and the number after it) disappears.
    DropWord(f64),
    InsertLetter(f64, u8),
    /// A whole line is repeated (loops of curve blocks, duplicate knots).
    DuplicateLine(f64),
}

pub fn mutation() -> impl Strategy<Value = Mutation> {
    let at = 0.0f64..1.0;
    prop_oneof![
        at.clone().prop_map(Mutation::Delete),
        at.clone().prop_map(Mutation::Duplicate),
        at.clone().prop_map(Mutation::Swap),
        (at.clone(), 0u8..10).prop_map(|(a, d)| Mutation::Digit(a, d)),
        at.clone().prop_map(Mutation::DropWord),
        (at.clone(), 0u8..26).prop_map(|(a, l)| Mutation::InsertLetter(a, l)),
        at.prop_map(Mutation::DuplicateLine),
    ]
}

pub fn apply(text: &mut Vec<u8>, m: &Mutation) {
    let n = text.len();
    if n == 0 {
        return;
    }
    let pos = |f: f64| ((f * n as f64) as usize).min(n - 1);
    match *m {
        Mutation::Delete(f) => {
            text.remove(pos(f));
        }
        Mutation::Duplicate(f) => {
            let i = pos(f);
            text.insert(i, text[i]);
        }
        Mutation::Swap(f) => {
            let i = pos(f).min(n.saturating_sub(2));
            if i + 1 < n {
                text.swap(i, i + 1);
            }
        }
        Mutation::Digit(f, d) => {
            // The first digit at or after the position.
            if let Some(i) = (pos(f)..n).find(|&i| text[i].is_ascii_digit()) {
                text[i] = b'0' + d;
            }
        }
        Mutation::DropWord(f) => {
            if let Some(i) = (pos(f)..n).find(|&i| text[i].is_ascii_alphabetic()) {
                let end = (i + 1..n)
                    .find(|&j| !matches!(text[j], b'0'..=b'9' | b'.' | b'-' | b'+'))
                    .unwrap_or(n);
                text.drain(i..end);
            }
        }
        Mutation::InsertLetter(f, l) => text.insert(pos(f), b'A' + l),
        Mutation::DuplicateLine(f) => {
            let i = pos(f);
            let start = text[..i]
                .iter()
                .rposition(|&c| c == b'\n')
                .map_or(0, |s| s + 1);
            let end = (i..n).find(|&j| text[j] == b'\n').map_or(n, |e| e + 1);
            let line: Vec<u8> = text[start..end].to_vec();
            text.splice(end..end, line);
        }
    }
}

/// Peer program `which` with `edits` applied, as bytes.
pub fn mutated_peer(which: proptest::sample::Index, edits: &[Mutation]) -> Vec<u8> {
    let peers = peers();
    let (_, text) = &peers[which.index(peers.len())];
    let mut bytes = text.clone().into_bytes();
    for m in edits {
        apply(&mut bytes, m);
    }
    bytes
}

/// Cases per property: modest for CI; `ROBUSTNESS_CASES=100000` for a deep search.
pub fn cases(ci: u32) -> ProptestConfig {
    let n = std::env::var("ROBUSTNESS_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(ci);
    ProptestConfig::with_cases(n)
}
