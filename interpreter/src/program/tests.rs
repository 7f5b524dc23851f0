use super::*;

fn moves(text: &str) -> Vec<Move> {
    interpret(text).unwrap_or_else(|e| panic!("{e:?}")).moves
}

fn errors(text: &str) -> Vec<(u32, u32, String)> {
    interpret(text)
        .unwrap_err()
        .into_iter()
        .map(|d| (d.line, d.col, d.message))
        .collect()
}

#[test]
fn lines_modal_words_and_units() {
    let m = moves("G21 G90 F600\nG1 X10\nY5\nG91 X1\nG20 G90 X1\nM2\nG1 X99\n");
    assert_eq!(m.len(), 5);
    assert_eq!(
        m[0],
        Move::Line {
            line: 2,
            from: [0.0; 3],
            to: [10.0, 0.0, 0.0],
            rapid: false,
            feed: 600.0
        }
    );
    assert!(matches!(
        m[2],
        Move::Line {
            to: [11.0, 5.0, 0.0],
            ..
        }
    ));
    assert!(matches!(
        m[3],
        Move::Line {
            to: [25.4, 5.0, 0.0],
            ..
        }
    ));
    assert_eq!(m[4], Move::End { line: 6 });
}

#[test]
fn full_circle_and_r_form() {
    let m = moves("G0 X10\nG3 X10 Y0 I-10 J0 F3000\nG2 X0 Y10 R10\n");
    match &m[1] {
        Move::Arc {
            center,
            ccw: true,
            turns: 1,
            ..
        } => assert_eq!(*center, [0.0; 3]),
        other => panic!("{other:?}"),
    }
    match &m[2] {
        // Clockwise quarter from (10,0) to (0,10) with R10: centre at (10,10).
        Move::Arc {
            center, ccw: false, ..
        } => {
            assert!(
                (center[0] - 10.0).abs() < 1e-12 && (center[1] - 10.0).abs() < 1e-12,
                "{center:?}"
            )
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn g5_2_nurbs_as_linuxcnc_builds_it() {
    let m = moves("F100\nG5.2 P1 L3\nX0 Y1 P1\nX2 Y2 P1\nX2 Y0 P1\nX0 Y0 P2\nG5.3\n");
    match &m[0] {
        Move::Nurbs {
            line: 2,
            degree: 2,
            knots,
            ctrl,
            ..
        } => {
            assert_eq!(knots, &vec![0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 3.0, 3.0]);
            assert_eq!(ctrl.len(), 5);
            assert_eq!(ctrl[4], [0.0, 0.0, 0.0, 2.0]);
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn every_problem_is_reported_with_its_column() {
    let e = errors("G1 X10\nG2 X5 Y5\nG1 X1 X2 F10\nG5.3\nG7 X1\nF100 G1 Q1 Y$\n");
    assert_eq!(e[0].0, 1);
    assert_eq!(e[0].1, 1);
    assert!(e[0].2.contains("feed"), "{}", e[0].2);
    assert_eq!((e[1].0, e[1].1), (2, 1));
    assert_eq!((e[2].0, e[2].1), (3, 7));
    assert_eq!((e[3].0, e[3].1), (4, 1));
    assert_eq!((e[4].0, e[4].1), (5, 1));
    assert_eq!((e[5].0, e[5].1), (6, 13));
    assert_eq!(e.len(), 6);
}

#[test]
fn nurbs_needs_order_many_points_and_weights() {
    let e = errors("F100\nG5.2 L4\nX1 Y1 P1\nX2 Y0 P1\nG5.3\n");
    assert!(e[0].2.contains("order 4"), "{e:?}");
    let e = errors("F100\nG5.2\nX1 Y1\nG5.3\n");
    assert!(e[0].2.contains("weight"), "{e:?}");
    let e = errors("F100\nG5.2\nX1 Y1 P0\nG5.3\n");
    assert!(e[0].2.contains("> 0"), "{e:?}");
}

#[test]
fn arc_radius_mismatch_is_an_error() {
    let e = errors("F100\nG0 X10\nG3 X0 Y10.5 I-10 J0\n");
    assert!(e[0].2.contains("differs"), "{e:?}");
}

#[test]
fn g6_2_nurbs_as_the_linuxcnc_programs_write_it() {
    let m = moves(
        "G0 X1 Y2\nF290\nG6.2 X1 Y2 R1 K0 P3 Q1\nX4 Y6 R2 K0\nX8 Y2 R1 K0\nX9 Y0 R1 K1\nG6.2 K2\nG6.2 K2\nG6.2 K2\nG1 X0\n",
    );
    match &m[1] {
        Move::Nurbs {
            line: 3,
            degree: 2,
            knots,
            ctrl,
            feed,
        } => {
            assert_eq!(knots, &vec![0.0, 0.0, 0.0, 1.0, 2.0, 2.0, 2.0]);
            assert_eq!(ctrl[1], [4.0, 6.0, 0.0, 2.0]);
            assert_eq!(*feed, 290.0);
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        m[2],
        Move::Line {
            from: [9.0, 0.0, 0.0],
            ..
        }
    ));
}

#[test]
fn g6_2_errors_name_the_rule() {
    // 13 knots for 12 control points of order 5 (seed 004's table): never closed.
    let e = errors("F100\nG6.2 X0 Y0 R1 K0 P3 Q1\nX1 Y1 R1 K0\nX2 Y0 R1 K0\nG6.2 K1\nG6.2 K1\n");
    assert!(e[0].2.contains("never closed"), "{e:?}");
    let e = errors("F100\nG6.2 X5 Y0 R1 K0 P2 Q1\nX1 Y1 R1 K1\nG6.2 K1\nG6.2 K1\n");
    assert!(e[0].2.contains("current position"), "{e:?}");
    let e = errors("F100\nG6.2 X0 Y0 R1 K0 P2 Q1\nX1 Y1 R1 K2\nX2 Y0 R1 K1\nG6.2 K2\nG6.2 K2\n");
    assert!(e[0].2.contains("smaller than knot"), "{e:?}");
    // Without Q, a G6.2 is Fanuc's G06.2 unless the dialect is forced to LinuxCNC.
    let forced = Options {
        dialect: Some(Dialect::LinuxCnc),
        ..Options::default()
    };
    let e = interpret_with("F100\nG6.2 X0 Y0 R1 K0 P2\n", &forced).unwrap_err();
    assert!(e[0].message.contains("method Q"), "{e:?}");
    let e = errors("F100\nG6.2 X0 Y0 R1 K0 P2\n");
    assert!(e[0].2.contains("PS1005"), "{e:?}");
}

proptest::proptest! {
    /// `lines_of` gives what `str::lines` gives, on texts of short lines of letters,
    /// blanks, `\r` and `\n` (alone, doubled, at either end), and non-ASCII characters.
    #[test]
    fn lines_of_is_str_lines(text in "([a-z \\r\\né€]{0,20}\\n?){0,12}[\\r\\n]{0,2}") {
        let ours = lines_of(&text);
        let std: Vec<&str> = text.lines().collect();
        proptest::prop_assert_eq!(line_count(&text), std.len());
        proptest::prop_assert_eq!(ours, std);
    }
}

#[test]
fn lines_of_ends_and_blanks() {
    for text in [
        "",
        "\n",
        "\r\n",
        "a",
        "a\r",
        "a\n\r",
        "a\r\r\n",
        "\n\nb\r\n",
        "x\ry\n",
    ] {
        assert_eq!(lines_of(text), text.lines().collect::<Vec<_>>(), "{text:?}");
    }
    let long = "G1 X1.5 Y-2 Z0.25\r\n".repeat(40) + "M2";
    assert_eq!(lines_of(&long), long.lines().collect::<Vec<_>>());
    // Read in order (no O-words) or listed (an O-word), a program's lines are the same:
    // CR LF endings, a blank line, a last line without its end.
    let plain = "G1 X1 F100\r\n\r\nG1 X2\r\nG1 X3";
    let with_o = format!("{plain}\r\no1 if [0]\r\no1 endif");
    let (a, b) = (moves(plain), moves(&with_o));
    // The same moves, to the program's end on its own last line.
    assert_eq!(a[..a.len() - 1], b[..b.len() - 1]);
    assert_eq!(a[a.len() - 1], Move::End { line: 4 });
    assert_eq!(
        errors("G1 X1 F100\r\n\nG1 E2\r"),
        errors("G1 X1 F100\r\n\nG1 E2\r\n(o)")
    );
}

#[test]
fn newline_mask_is_exact() {
    // Every byte value at every place, with `\n` and neighbours that could carry.
    for b in 0..=255u8 {
        for at in 0..8 {
            let mut w = [b'\n', 0x0b, 0x09, 0xff, 0x00, 0x8a, b'\n', 0x0b];
            w[at] = b;
            let expect = w.iter().enumerate().fold(0u64, |m, (i, &x)| {
                m | if x == b'\n' { 0x80 << (8 * i) } else { 0 }
            });
            assert_eq!(newline_mask(w), expect, "{w:?}");
        }
    }
}

#[test]
fn newlines_counts_every_one() {
    // Past the 255 words a lane may count before it is summed, with every lane full.
    for n in [0, 1, 7, 8, 9, 2039, 2040, 2041, 5000] {
        let all = vec![b'\n'; n];
        assert_eq!(newlines(&all), n);
        let some: Vec<u8> = (0..n)
            .map(|i| if i % 3 == 0 { b'\n' } else { b'x' })
            .collect();
        assert_eq!(newlines(&some), n.div_ceil(3));
    }
}

/// `gcode` as it was: every value, whole tenths or not, gives the same code.
#[test]
fn gcode_whole_tenths_as_rounded() {
    let before = |v: f64| {
        let tenths = (v * 10.0).round();
        ((tenths - v * 10.0).abs() < 1e-6 && tenths >= 0.0).then_some(tenths as u32)
    };
    let values = [
        0.0,
        -0.0,
        1.0,
        5.2,
        5.3,
        6.2,
        64.0,
        61.1,
        0.1,
        0.25,
        1.00000001,
        2.9999999,
        -1.0,
        -0.04,
        4e8,
        4.2e8,
        1e300,
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        429496729.5,
        429496729.6,
    ];
    for v in values
        .into_iter()
        .chain((0..20_000).map(|i| i as f64 * 0.013 - 7.0))
    {
        let w = Word {
            letter: 'G',
            value: v,
            col: 1,
        };
        assert_eq!(gcode(&w), before(v), "{v}");
    }
}

proptest::proptest! {
    /// [`LineWords`] answers from the letters a line has: each word found as a look
    /// through the words finds it, and the two checks of `execute` (a letter twice, a
    /// letter not known) pass exactly where [`check_letters`] passes.
    #[test]
    fn line_letters_answer_as_the_words_do(
        letters in proptest::collection::vec(
            proptest::sample::select(b"ABCDEFGHIJKLMNOPQRSTUVWXYZ%e".to_vec()),
            0..8,
        )
    ) {
        let words: Vec<Word> = letters
            .iter()
            .enumerate()
            .map(|(i, &l)| Word { letter: char::from(l), value: i as f64, col: i as u32 + 1 })
            .collect();
        let lw = LineWords::new(&words, 1);
        for letter in ('A'..='Z').chain(['%', 'e', 'é']) {
            let found = words.iter().find(|w| w.letter == letter);
            proptest::prop_assert_eq!(lw.get(letter), found);
        }
        for set in ["XYZ", "IJKR", "XYZK", "XYZIJQ", "GM"] {
            let any = words.iter().any(|w| set.contains(w.letter));
            proptest::prop_assert_eq!(lw.has_any(set), any);
        }
        let quick = !lw.repeated && lw.letters & !KNOWN_LETTERS == 0;
        proptest::prop_assert_eq!(quick, check_letters(&lw).is_ok());
    }
}

/// Lines for [`the_short_way_reads_as_the_general_way`]: mostly plain straight moves,
/// with their near misses and the codes that change what they do.
fn line_strategy() -> impl proptest::strategy::Strategy<Value = String> {
    use proptest::prelude::*;
    let value = prop_oneof![
        8 => (-2000i32..2000).prop_map(|v| format!("{:.3}", f64::from(v) * 0.123)),
        2 => proptest::sample::select(vec!["0", "-0", "+3", ".25", "-.5", "1.", "7", "0.01"])
            .prop_map(String::from),
        1 => proptest::sample::select(vec![
            "200000", "-100000.001", "1..2", "", " 1", "[1]", "#1", "1e3", "-5",
        ])
        .prop_map(String::from),
    ];
    let axis = (
        proptest::sample::select(vec!['X', 'Y', 'Z', 'x', 'z']),
        value.clone(),
    )
        .prop_map(|(l, v)| format!("{l}{v}"));
    let plain = (
        proptest::sample::select(vec![
            "", "", "G1", "G0", "G01", "G1.0", "g00", "G0.0", "G+1",
        ]),
        proptest::collection::vec(axis, 0..4),
        proptest::option::weighted(0.3, value.prop_map(|v| format!("F{v}"))),
        proptest::sample::select(vec![" ", ""]),
    )
        .prop_map(|(g, axes, f, sep)| {
            let mut words = vec![g.to_string()];
            words.extend(axes);
            words.extend(f);
            words.join(sep)
        });
    let other = proptest::sample::select(vec![
        "G91",
        "G90",
        "G20",
        "G21",
        "G93 G1 X1 F2",
        "G94 F300",
        "G2 X1 Y1 I0.5 J0.5",
        "G5.2 X1 Y1 P1 L3\nX2 Y0 P1\nG5.3",
        "M3 S100",
        "M5",
        "F100",
        "F0.01",
        "G1",
        "G0",
        "N5 G1 X2",
        "G1 X1 (c)",
        "G1 X2 ;c",
        "#1=2",
        "G1 X#1",
        "/G1 X3",
        "%",
        "G1 X1 é",
        "G61.1",
        "G64 P0.1",
        "G18",
        "G17",
        "G1 X1 X2",
        "G1 G0 X1",
        "G1 X1 I1",
        "G80 X1",
        "G4 P0.1",
        "M2",
        "",
        "G5 X2 Y2 I0.5 J0 P0.5 Q0",
        "G5 X3 Y1 P0.5 Q0",
    ])
    .prop_map(String::from);
    (
        proptest::sample::select(vec!["", "", " ", "\t"]),
        prop_oneof![3 => plain, 1 => other],
        proptest::sample::select(vec!["\n", "\n", "\r\n", " \n"]),
    )
        .prop_map(|(lead, line, end)| format!("{lead}{line}{end}"))
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(1000))]
    /// The short way through plain straight moves ([`plain`]) gives the very moves,
    /// messages, dialect and errors the general way gives, on programs of plain moves,
    /// their near misses and the codes that change what they do; with O-words too (the
    /// lines then listed), and without a last `\n`; mostly after a feed (a feed move
    /// without one is an error, and a program with an error gives no moves). Every start of the program is read
    /// (all but its first lines cut off), so that the moves before an error are compared
    /// too.
    #[test]
    fn the_short_way_reads_as_the_general_way(
        lines in proptest::collection::vec(line_strategy(), 1..24),
        o_words in proptest::bool::ANY,
        feed in proptest::bool::weighted(0.8),
        cut_end in proptest::bool::ANY,
    ) {
        let head = if o_words { "o1 sub\nG1 X1\no1 endsub\n" } else { "" };
        for n in 1..=lines.len() {
            let mut text = String::from(head);
            if feed {
                text.push_str("F100\n");
            }
            text.extend(lines[..n].iter().map(String::as_str));
            if cut_end {
                text.pop();
            }
            let read = |way| match interpret_lines(&text, &Options::default(), way, None) {
                Ok(p) => Ok((p.moves, p.messages, p.dialect)),
                Err(e) => Err(e),
            };
            proptest::prop_assert_eq!(read(Way::Short), read(Way::General), "{:?}", text);
        }
    }
}

/// [`the_short_way_reads_as_the_general_way`] on cases chance seldom builds: a plain
/// move between two `G5` forgets the first one's tangent, inch and incremental moves,
/// inverse time, a curve open around plain lines, lines too long.
#[test]
fn the_short_way_on_chosen_cases() {
    let long = format!("G1 X1{}\n", " ".repeat(260));
    for text in [
        "F100\nG5 X2 Y2 I0.5 J0 P0.5 Q0\nG1 X3 Y3\nG5 X4 Y4 P0.5 Q0\n",
        "F100\nG5 X2 Y2 I0.5 J0 P0.5 Q0\nG5 X4 Y4 P0.5 Q0\nG1 X5\n",
        "G20 G91 F4\nG1 X1 Y1\nX1\nG0 Z1\nG90 G21 X2 Y2 Z2 F0.09\nG1 X1\n",
        "G93 G1 X1 F2\nG1 X2\nX3 F4\nG94 G1 X4\n",
        "F100\nG5.2 X1 Y1 P1 L3\nX2 Y0 P1\nG1 X3 Y1\nG5.3\nG1 X4\n",
        "F100\nG1 X1\n",
        long.as_str(),
        "F100\nG1 X1\nM2\nG1 X-1e6\n",
    ] {
        let read = |way| match interpret_lines(text, &Options::default(), way, None) {
            Ok(p) => Ok((p.moves, p.messages, p.dialect)),
            Err(e) => Err(e),
        };
        assert_eq!(read(Way::Short), read(Way::General), "{text:?}");
    }
}
