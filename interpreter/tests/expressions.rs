//! Parameters and `[ ]` expressions as LinuxCNC's rs274ngc reads them.
//!
//! Expected values are what LinuxCNC 2.9's standalone interpreter prints for the same
//! program (`rs274 -g FILE.ngc`, the `STRAIGHT_FEED(x, y, z, …)` lines); each test quotes
//! them. Error columns are ours (rs274 names only the line).

use interpreter::parse::{read_line, Params};
use interpreter::program::{interpret, Move};
use proptest::prelude::*;

/// End points of the feed and rapid moves of a program that must be fine.
fn ends(text: &str) -> Vec<[f64; 3]> {
    interpret(text)
        .unwrap_or_else(|e| panic!("{text}\n{e:?}"))
        .moves
        .iter()
        .filter_map(|m| match m {
            Move::Line { to, .. } => Some(*to),
            _ => None,
        })
        .collect()
}

/// The first error of a program that must fail: (line, column, message).
fn error(text: &str) -> (u32, u32, String) {
    let e = interpret(text).expect_err(text);
    (e[0].line, e[0].col, e[0].message.clone())
}

fn close(a: [f64; 3], b: [f64; 3]) {
    for i in 0..3 {
        assert!((a[i] - b[i]).abs() < 5e-5, "{a:?} != {b:?}");
    }
}

/// Starts every move from a point none of them reaches, so no move is dropped as empty.
const FROM: &str = "G0 X-1 Y-1 Z-1\nF100\n";

fn moves_to(body: &str) -> Vec<[f64; 3]> {
    let mut v = ends(&format!("{FROM}{body}M2\n"));
    v.remove(0);
    v
}

#[test]
fn operators_bind_and_associate_as_in_linuxcnc() {
    // rs274: STRAIGHT_FEED(7, 64, 3), then [-7 MOD 3] is 2, (0, 1, 1) and (1, 0, 1)
    let m = moves_to(
        "#1 = [1 + 2 * 3]\n#2 = [2 ** 3 ** 2]\n#3 = [10 - 4 - 3]\n\
         G1 X#1 Y#2 Z#3\n\
         G1 X[1 + 2 EQ 3] Y[7 MOD 3] Z[-7 MOD 3 + 1]\n\
         G1 X[1 OR 0 AND 0] Y[1 EQ 1 EQ 1] Z[3 - 2 - 1 + 4 / 2 / 2]\n\
         G1 X[0.5 XOR 0] Y[5 GT 3 + 4] Z[10 MOD 3 ** 2]\n",
    );
    close(m[0], [7.0, 64.0, 3.0]);
    close(m[1], [1.0, 1.0, 3.0]);
    close(m[2], [0.0, 1.0, 1.0]);
    close(m[3], [1.0, 0.0, 1.0]);
}

#[test]
fn signs_belong_to_the_value_they_precede() {
    // rs274: X--2 is 2, X-+2 is -2, [-2 ** 2] is 4, [1+-2] is -1, X-[1+2] is -3
    let m = moves_to("G1 X--2 Y-+2 Z[-2 ** 2]\nG1 X[1+-2] Y-[1+2] Z+[2]\n");
    close(m[0], [2.0, -2.0, 4.0]);
    close(m[1], [-1.0, -3.0, 2.0]);
}

#[test]
fn modulo_and_comparisons_follow_linuxcnc() {
    // rs274: [7 MOD -3] 1, [-7 MOD -3] 2, [7.5 MOD 2] 1.5
    close(
        moves_to("G1 X[7 MOD -3] Y[-7 MOD -3] Z[7.5 MOD 2]\n")[0],
        [1.0, 2.0, 1.5],
    );
    // rs274: EQ within 0.0001 ((1, 1, 0) for EQ 1.0001, EQ 1.00009, NE 1.00001) ...
    close(
        moves_to("G1 X[1 EQ 1.0001] Y[1 EQ 1.00009] Z[1 NE 1.00001]\n")[0],
        [1.0, 1.0, 0.0],
    );
    // ... but LT GT GE LE exact: (1, 0, 0) and (1, 0, 1)
    let m = moves_to(
        "G1 X[1 LT 1.00001] Y[1 GE 1.00001] Z[1 LE 0.99999]\n\
         G1 X[1 GT 0.99999] Y[1.00001 LE 1] Z[1 LT 1.0001]\n",
    );
    close(m[0], [1.0, 0.0, 0.0]);
    close(m[1], [1.0, 0.0, 1.0]);
    // rs274: [2 AND 3] 1, [0 OR 0] 0, [1 XOR 1] 0
    close(
        moves_to("G1 X[2 AND 3] Y[0 OR 0] Z[1 XOR 1]\n")[0],
        [1.0, 0.0, 0.0],
    );
}

#[test]
fn functions_work_in_degrees() {
    // rs274: ATAN[1]/[1] 45, SIN[30] 0.5, ROUND[2.5] 3; ROUND[-2.5] -3, FIX -3, FUP -2
    let m = moves_to(
        "G1 X[ATAN[1]/[1]] Y[SIN[30]] Z[ROUND[2.5]]\n\
         G1 X[ROUND[-2.5]] Y[FIX[-2.5]] Z[FUP[-2.5]]\n\
         G1 X[ATAN[-1]/[-1]] Y[ACOS[0.5]] Z[ROUND[-0.4]]\n\
         G1 X[ABS[-2]] Y[EXP[1]] Z[LN[2.718281828459045]]\n\
         G1 X[ASIN[1]] Y[COS[60]] Z[TAN[45]]\n\
         G1 X[SQRT[2]] Y[2 ** 0.5] Z[2**-1]\n",
    );
    close(m[0], [45.0, 0.5, 3.0]);
    close(m[1], [-3.0, -3.0, -2.0]);
    close(m[2], [-135.0, 60.0, 0.0]);
    close(m[3], [2.0, std::f64::consts::E, 1.0]);
    close(m[4], [90.0, 0.5, 1.0]);
    close(m[5], [2f64.sqrt(), 2f64.sqrt(), 0.5]);
}

#[test]
fn functions_stand_without_brackets_too() {
    // rs274: XSIN[30] is 0.5, X-SIN[30] is -0.5, XEXISTS[#<a>] is 0
    close(
        moves_to("G1 XSIN[30] Y-SIN[30] ZEXISTS[#<a>]\n")[0],
        [0.5, -0.5, 0.0],
    );
}

#[test]
fn numbered_parameters_direct_and_indirect() {
    // rs274: ##1 and #[1+1] both read #2 = 3; #1.00001 is #1.
    let m = moves_to("#1=2\n#2=3\nG1 X##1 Y#[1+1] Z#3\n#1.00001=4\nG1 X#1\n");
    close(m[0], [3.0, 3.0, 0.0]); // unset #3 reads 0
    close(m[1], [4.0, 3.0, 0.0]);
    // #5399 is the last one we hold
    close(moves_to("#5399=6\nG1 X#5399\n")[0], [6.0, -1.0, -1.0]);
}

#[test]
fn settings_take_effect_after_the_line() {
    // rs274: `#1=5 #2=#1` then `#1=7`: X#1 is 7 and Y#2 the old #1, 0.
    close(
        moves_to("#1=5 #2=#1\n#1=7\nG1 X#1 Y#2 Z1\n")[0],
        [7.0, 0.0, 1.0],
    );
    // A word reads the value from before its own line's setting.
    let m = moves_to("#1=3\n#1=9 G1 X#1\nG1 Y#1\n");
    close(m[0], [3.0, -1.0, -1.0]);
    close(m[1], [3.0, 9.0, -1.0]);
    // The last of two settings of one parameter wins (rs274: 2).
    close(moves_to("#<a>=1 #<a>=2\nG1 X#<a>\n")[0], [2.0, -1.0, -1.0]);
}

#[test]
fn named_parameters_ignore_case_and_spaces() {
    // rs274: #<my var> is #<MYVAR>; EXISTS of an unset name 0, of a set one 1.
    let m = moves_to(
        "#<my var> = 5\n#<_g lob> = 3\n#<x> = [EXISTS[#<_glob>]]\n\
         G1 X#<MYVAR> Y#<x> Z[EXISTS[#<nope>]]\nG1 X#<_GLOB> Y[EXISTS[#1]]\n",
    );
    close(m[0], [5.0, 1.0, 0.0]);
    close(m[1], [3.0, 1.0, 0.0]);
}

#[test]
fn domain_errors_name_their_column() {
    // Messages as rs274's; the column is that of the operator or function at fault.
    let cases: [(&str, u32, &str); 9] = [
        ("G1 X[1/0] F1", 7, "Attempt to divide by zero"),
        ("G1 X[1 + SQRT[-1]] F1", 10, "Negative argument to sqrt"),
        ("G1 X[LN[0]] F1", 6, "Zero or negative argument to ln"),
        ("G1 X[ASIN[2]] F1", 6, "Argument to asin out of range"),
        ("G1 X[ACOS[-2]] F1", 6, "Argument to acos out of range"),
        (
            "G1 X[7 MOD 0] F1",
            8,
            "Calculation resulted in 'not a number'",
        ),
        (
            "G1 X[EXP[1000]] F1",
            6,
            "Calculation resulted in 'infinity'",
        ),
        ("G1 X[0**-1] F1", 7, "Calculation resulted in 'infinity'"),
        (
            "G1 X[-2**0.5] F1",
            8,
            "Attempt to raise negative to non integer power",
        ),
    ];
    for (text, col, message) in cases {
        assert_eq!(
            error(&format!("\n{text}\nM2\n")),
            (2, col, message.to_string()),
            "{text}"
        );
    }
}

#[test]
fn syntax_errors_name_their_column() {
    let col = |text: &str| {
        let (line, col, _) = error(&format!("F1\n{text}\nM2\n"));
        assert_eq!(line, 2, "{text}");
        col
    };
    assert_eq!(col("G1 X#<nope>"), 5); // rs274: Named parameter #<nope> not defined
    assert!(error("G1 X#<nope>").2.contains("#<nope> not defined"));
    assert_eq!(col("G1 X[ATAN[1]]"), 13); // rs274: Slash missing after first atan argument
    assert_eq!(col("G1 X[ATAN[1]/2]"), 14); // rs274: Left bracket missing after slash
    assert_eq!(col("G1 X[1 + 2 Y1"), 12); // rs274: Unknown operation
    assert_eq!(col("G1 X[1 + 2"), 5); // the `[` never closed
    assert_eq!(col("G1 X[1]]"), 8); // rs274: Bad character ']' used
    assert_eq!(col("G1 X[]"), 6); // rs274: bad number format parsing ''
    assert_eq!(col("G1 X[FOO[1]]"), 6); // rs274: Unknown word starting with f
    assert_eq!(col("G1 X[SIN 30]"), 10); // rs274: Left bracket missing after unary op
    assert_eq!(col("G1 X[EXISTS[1]]"), 13); // rs274: Expected # reading parameter
    assert_eq!(col("G1 X[EXISTS[#<a]"), 14); // rs274: Named parameter not terminated
    assert_eq!(col("#1=1+2"), 5); // rs274: Bad character '+' used
    assert_eq!(col("#1.5=1"), 2); // rs274: Non integer value for integer
    assert_eq!(col("#1.0002=1"), 2); // rs274: Non integer value for integer
    assert_eq!(col("#0=1"), 2); // rs274: Parameter number out of range
    assert_eq!(col("#5400=1"), 2); // rs274: Parameter is readonly
    assert_eq!(col("G1 X#-1"), 6); // rs274: Parameter number out of range
    assert_eq!(col("#1="), 4); // rs274: No characters found in reading real value
    assert_eq!(col("[1+2]"), 1); // rs274: Bad character '[' used
    assert_eq!(col("#1=1 G1 X#1#1"), 12); // rs274: Equal sign missing
    assert_eq!(col("G1 X1.2.3"), 5); // rs274: bad number format (trailing characters)
    assert_eq!(col("G1 X."), 5); // rs274: bad number format parsing '.'
    assert_eq!(col("G1 X"), 4);
}

#[test]
fn errors_do_not_stop_the_check_of_later_lines() {
    let e = interpret("F1\nG1 X[1/0]\nG1 Y[SQRT[-4]]\nG1 Z#<u>\nM2\n").unwrap_err();
    let at: Vec<(u32, u32)> = e.iter().map(|d| (d.line, d.col)).collect();
    assert_eq!(at, vec![(2, 7), (3, 6), (4, 5)]);
}

#[test]
fn deep_nesting_is_an_error_not_a_crash() {
    let deep = format!("G1 X{}1{} F1", "[".repeat(5000), "]".repeat(5000));
    assert!(read_line(&deep, 1, &Params::default()).is_err());
    let signs = format!("G1 X{}1 F1", "-".repeat(5000));
    assert!(read_line(&signs, 1, &Params::default()).is_err());
    let hashes = format!("G1 X{}1 F1", "#".repeat(5000));
    assert!(read_line(&hashes, 1, &Params::default()).is_err());
    // Within the limit, nesting is fine: 60 brackets read 1.
    let ok = format!("G1 X{}1{}", "[".repeat(60), "]".repeat(60));
    assert_eq!(
        read_line(&ok, 1, &Params::default()).unwrap().words[1].value,
        1.0
    );
}

#[test]
fn subroutines_take_arguments_and_restore_the_callers_parameters() {
    // rs274: (1, 3, 0) inside the sub, then (11, 7, 0): #1..#30 and the caller's local
    // #<loc> are back after the call.
    let m = ends(
        "o100 sub\nG1 X#1 Y#2 Z#3\n#<loc>=5\n#1=99\no100 endsub\n\
         #<loc>=7\n#1=11\nF100\no100 call [1] [2+1]\nG1 X#1 Y#<loc>\nM2\n",
    );
    assert_eq!(m, vec![[1.0, 3.0, 0.0], [11.0, 7.0, 0.0]]);
    // rs274: arguments not given read 0 in the sub, even if the caller had set them.
    assert_eq!(
        ends("#2=5\no100 sub\nG1 X#1 Y#2\no100 endsub\nF100\no100 call [1]\nM2\n"),
        vec![[1.0, 0.0, 0.0]]
    );
    // rs274: `return [7]` sets #<_value>; a sub may stand after its call.
    assert_eq!(
        ends("o100 sub\no100 return [7]\no100 endsub\nF100\no100 call\nG1 X#<_value>\nM2\n"),
        vec![[7.0, 0.0, 0.0]]
    );
    assert_eq!(
        ends("F100\no100 call\nM2\no100 sub\nG1 X5\no100 endsub\n"),
        vec![[5.0, 0.0, 0.0]]
    );
    // rs274: "Named parameter #<loc> not defined": locals stay in their call level ...
    assert_eq!(
        error("#<loc>=7\no100 sub\nG1 X#<loc>\no100 endsub\nF100\no100 call\nM2\n"),
        (3, 5, "Named parameter #<loc> not defined".to_string())
    );
    // ... globals do not: (7, 0, 0) then (7, 3, 0).
    assert_eq!(
        ends(
            "#<_g>=7\no100 sub\nG1 X#<_g>\n#<_g>=3\no100 endsub\nF100\no100 call\nG1 Y#<_g>\nM2\n"
        ),
        vec![[7.0, 0.0, 0.0], [7.0, 3.0, 0.0]]
    );
}

#[test]
fn loops_and_branches_run_as_in_linuxcnc() {
    // rs274: while: X0, X1, X2 (the first move, to X0, is empty and dropped here).
    assert_eq!(
        ends("F100\n#1=0\no101 while [#1 LT 3]\nG1 X#1\n#1=[#1+1]\no101 endwhile\nM2\n"),
        vec![[1.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    );
    // rs274: do runs its body once even when the test is false.
    assert_eq!(
        ends("F100\n#1=0\no101 do\nG1 X[#1+5]\n#1=[#1+1]\no101 while [#1 LT 0]\nM2\n"),
        vec![[5.0, 0.0, 0.0]]
    );
    // rs274: repeat [3] of an incremental X1: X1, X2, X3.
    assert_eq!(
        ends("F100\no102 repeat [3]\nG91 G1 X1\no102 endrepeat\nM2\n"),
        vec![[1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]]
    );
    // rs274: if/elseif/else takes the first true branch only: X2.
    let chain = |v: u32| {
        ends(&format!(
            "F100\n#1={v}\no103 if [#1 EQ 1]\nG1 X1\no103 elseif [#1 EQ 2]\nG1 X2\n\
             o103 else\nG1 X3\no103 endif\nG1 Y1\nM2\n"
        ))
    };
    assert_eq!(chain(1), vec![[1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]);
    assert_eq!(chain(2), vec![[2.0, 0.0, 0.0], [2.0, 1.0, 0.0]]);
    assert_eq!(chain(7), vec![[3.0, 0.0, 0.0], [3.0, 1.0, 0.0]]);
    // break and continue: X1 X3 (2 skipped, the loop left at 4).
    assert_eq!(
        ends(
            "F100\n#1=0\no101 while [#1 LT 5]\n#1=[#1+1]\no102 if [#1 EQ 2]\no101 continue\n\
             o102 endif\no103 if [#1 EQ 4]\no101 break\no103 endif\nG1 X#1\no101 endwhile\nM2\n"
        ),
        vec![[1.0, 0.0, 0.0], [3.0, 0.0, 0.0]]
    );
    // rs274: a break reaches out of a repeat (or inner while) to its own while: X1 Y1 only.
    for inner in ["o301 repeat [2]", "o301 while [1]"] {
        let end = inner
            .replace("repeat [2]", "endrepeat")
            .replace("while [1]", "endwhile");
        assert_eq!(
            ends(&format!(
                "F100\n#1=0\no300 while [#1 LT 3]\n#1=[#1+1]\n{inner}\nG1 X#1 Y#1\n\
                 o300 break\n{end}\no300 endwhile\nG1 X5\nM2\n"
            )),
            vec![[1.0, 1.0, 0.0], [5.0, 1.0, 0.0]]
        );
    }
    // rs274 2.9 has no break or continue for repeat: "no matching while/do label".
    let (line, col, message) = error(
        "F100\n#1=0\no1 repeat [10]\n#1=[#1+1]\no2 if [#1 EQ 2]\no1 break\no2 endif\no1 endrepeat\nM2\n",
    );
    assert_eq!((line, col), (6, 1));
    assert!(message.contains("while or do"), "{message}");
}

#[test]
fn o_word_program_moves_as_rs274() {
    // `rs274 -g tests/ngc/o_words.ngc`: the X and Y of its 13 STRAIGHT_FEEDs.
    let rs274: [[f64; 2]; 13] = [
        [3.0, 0.0],
        [2.0, 1.0],
        [1.0, 2.0],
        [10.0, 103.0],
        [20.0, 103.0],
        [30.0, 103.0],
        [2.0, 51.0],
        [4.0, 52.0],
        [6.0, 53.0],
        [8.0, 54.0],
        [1.0, -1.0],
        [3.0, -3.0],
        [5.0, -5.0],
    ];
    let text = include_str!("ngc/o_words.ngc");
    let got: Vec<[f64; 2]> = ends(text).iter().map(|p| [p[0], p[1]]).collect();
    assert_eq!(got, rs274);
}

#[test]
fn o_word_structure_errors() {
    // rs274: "duplicate O-word label - already defined in line 5"
    let (line, col, message) = error("F1\no1 if [1]\no1 endif\no1 if [1]\no1 endif\nM2\n");
    assert_eq!((line, col), (4, 1));
    assert!(message.contains("line 2"), "{message}");
    assert_eq!(error("F1\no1 endwhile\nM2\n").0, 2);
    assert_eq!(error("F1\no1 while [1]\nM2\n").0, 2);
    assert_eq!(error("F1\no9 call\nM2\n").1, 1);
    assert_eq!(error("F1\no1 if [1] G1 X1\no1 endif\nM2\n").1, 11);
    // A loop that never ends is an error here (LinuxCNC would run forever).
    let (line, _, message) = error("F1\no1 while [1]\no1 endwhile\nM2\n");
    assert_eq!(line, 3);
    assert!(message.contains("endless"), "{message}");
    // Errors in a loop body are reported once, not once per turn.
    let e = interpret("F1\no1 repeat [5]\nG1 X[1/0]\no1 endrepeat\nM2\n").unwrap_err();
    assert_eq!(e.len(), 1);
    assert_eq!((e[0].line, e[0].col), (3, 7));
}

/// Lines the mutations start from: a bit of everything the reader knows.
const SEEDS: [&str; 13] = [
    "G1 X[1 + 2 * 3] Y#<a> Z-#1 F[100 / 2]",
    "#1 = [2 ** 3 ** 2] #<_g> = [ATAN[1]/[-1]]",
    "G1 X[SIN[30] EQ 0.5 AND [1 LT 2]] (c) ; tail",
    "G5.2 P1 L4 (MSG, hello)",
    "#[1+1] = ##1 G1 X[EXISTS[#<a>]] Y[7 MOD -3]",
    "N10 G2 X1 Y1 I.5 J-0.5 F#<_f>",
    "/G0 XSQRT[2] Y[ROUND[-2.5]] Z[FUP[FIX[1.5]]]",
    "G1 X[1/0] Y[LN[0]] Z[ACOS[2]]",
    "#<my var> = [-2 ** 0.5 XOR 1 NE 2 GE 3 LE 4 GT 5]",
    "G1 X1.2.3 Y. Z[] #0=1 #5400=2",
    "o100 call [1] [#<a>] [2]",
    "o<name> while [#1 LT 3]",
    "o1 endrepeat",
];

/// Characters worth mutating with: all the syntax and some that are not.
const ALPHABET: &[char] = &[
    '[', ']', '#', '<', '>', '=', '+', '-', '*', '/', '.', '0', '1', '9', 'X', 'G', 'A', 'E', 'Q',
    'M', 'O', 'D', 'S', 'I', 'N', '(', ')', ';', ' ', '%', '_', 'é', '\t', '\u{0}',
];

fn params() -> Params {
    let mut p = Params::default();
    for line in ["#1=2", "#2=3", "#<a>=1", "#<_g>=4", "#<_f>=100"] {
        for (param, v) in read_line(line, 1, &p).unwrap().assignments {
            p.set(&param, v);
        }
    }
    p
}

fn mutated() -> impl Strategy<Value = String> {
    (
        0..SEEDS.len(),
        proptest::collection::vec((any::<usize>(), 0u8..3, 0..ALPHABET.len()), 0..8),
    )
        .prop_map(|(seed, edits)| {
            let mut chars: Vec<char> = SEEDS[seed].chars().collect();
            for (at, kind, c) in edits {
                let at = at % (chars.len() + 1);
                match kind {
                    0 => chars.insert(at, ALPHABET[c]),
                    1 if at < chars.len() => {
                        chars.remove(at);
                    }
                    _ if at < chars.len() => chars[at] = ALPHABET[c],
                    _ => chars.push(ALPHABET[c]),
                }
            }
            chars.into_iter().collect()
        })
}

fn random_line() -> impl Strategy<Value = String> {
    proptest::collection::vec(
        prop_oneof![
            4 => (0..ALPHABET.len()).prop_map(|i| ALPHABET[i]),
            1 => any::<char>(),
        ],
        0..60,
    )
    .prop_map(|v| v.into_iter().collect())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Any line reads to words or to one error inside the line (or just past its end).
    #[test]
    fn reader_never_panics(line in prop_oneof![mutated(), random_line()]) {
        let p = params();
        match read_line(&line, 3, &p) {
            Ok(l) => {
                for w in &l.words {
                    prop_assert!(w.value.is_finite());
                }
                for (_, v) in &l.assignments {
                    prop_assert!(v.is_finite());
                }
            }
            Err(e) => {
                prop_assert_eq!(e.line, 3);
                let len = line.chars().count() as u32;
                prop_assert!(e.col >= 1 && e.col <= len + 1, "col {} of {} in {:?}", e.col, len, line);
                prop_assert!(!e.message.is_empty());
            }
        }
    }

    /// Whole programs of such lines are checked without panicking.
    #[test]
    fn interpreter_never_panics(lines in proptest::collection::vec(prop_oneof![mutated(), random_line()], 0..6)) {
        let text = lines.join("\n");
        if let Err(errors) = interpret(&text) {
            prop_assert!(!errors.is_empty());
        }
    }
}
