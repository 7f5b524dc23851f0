use super::*;
use crate::program::interpret;

fn planned(text: &str) -> Vec<CommandBlock> {
    let machine = Machine::default();
    let mut b = build(&interpret(text).unwrap().moves, &machine);
    plan(&mut b, &machine, 1_000_000);
    commands(&b)
}

#[test]
fn full_circle_is_exact_and_closed() {
    let b = planned("G0 X10\nG3 X10 Y0 I-10 J0 F3000\n");
    let arc = &b[1];
    assert_eq!(arc.degree, 2);
    assert_eq!(arc.n_ctrl, 9);
    for i in 0..=4000 {
        let (u0, u1) = path::domain(arc);
        let p = path::eval(arc, u0 + (u1 - u0) * i as f64 / 4000.0).p;
        assert!((p[0].hypot(p[1]) - 10.0).abs() < 1e-12);
    }
    assert!(
        (arc.length_mm - 20.0 * PI).abs() < 1e-9,
        "{}",
        arc.length_mm
    );
}

#[test]
fn helix_rises_with_the_angle() {
    let b = planned("G0 X10\nG17 G3 X-10 Y0 Z6 I-10 J0 F1000\n");
    let h = &b[1];
    assert_eq!(h.helix.axis, 2);
    let (u0, u1) = path::domain(h);
    for i in 0..=100 {
        let e = path::eval(h, u0 + (u1 - u0) * i as f64 / 100.0);
        let angle = e.p[1].atan2(e.p[0]).rem_euclid(2.0 * PI);
        let angle = if i == 100 { PI } else { angle };
        assert!(
            (e.p[2] - 6.0 * angle / PI).abs() < 1e-9,
            "z {} at {angle}",
            e.p[2]
        );
        // Derivative of z matches a finite difference.
        if i > 0 && i < 100 {
            let du = 1e-6;
            let (m, p) = (
                path::eval(h, e_u(u0, u1, i) - du),
                path::eval(h, e_u(u0, u1, i) + du),
            );
            assert!(((p.p[2] - m.p[2]) / (2.0 * du) - e.d1[2]).abs() < 1e-5);
        }
    }
    // Length of a helix: sqrt((r·θ)² + h²).
    let want = ((10.0 * PI).powi(2) + 36.0f64).sqrt();
    assert!(
        (h.length_mm - want).abs() < 1e-6,
        "{} vs {want}",
        h.length_mm
    );
}

fn e_u(u0: f64, u1: f64, i: usize) -> f64 {
    u0 + (u1 - u0) * i as f64 / 100.0
}

#[test]
fn multi_turn_circle_splits_into_blocks() {
    let b = planned("G0 X5\nG2 X5 Y0 I-5 J0 P10 F500\n");
    let arcs: Vec<_> = b
        .iter()
        .filter(|b| b.kind == BlockKind::Motion as u32 && b.degree == 2)
        .collect();
    assert!(arcs.len() >= 3);
    assert!(arcs.iter().all(|a| a.n_ctrl as usize <= MAX_CTRL));
    let total: f64 = arcs.iter().map(|a| a.length_mm).sum();
    assert!((total - 10.0 * 10.0 * PI).abs() < 1e-8);
}

#[test]
fn plan_stops_at_corners_and_flows_through_tangent_joins() {
    let b = planned("G1 X10 F3000\nY10\nG3 X0 Y20 I-10 J0\nM2\n");
    assert_eq!(b[0].start_feed_mm_per_min, 0.0);
    assert_eq!(b[0].end_feed_mm_per_min, 0.0, "90° corner: exact stop");
    assert!(
        b[1].end_feed_mm_per_min > 0.0,
        "the line runs tangentially into the arc"
    );
    assert_eq!(b[2].end_feed_mm_per_min, 0.0, "program end");
    for x in &b[..3] {
        assert!(x.validate().is_ok());
    }
}

#[test]
fn a_kink_lowers_the_acceleration_only_next_to_it() {
    // Two 50 mm lines meeting at a 1.1° kink (below the 5° corner angle): the kink's
    // share of the acceleration holds the stretch on either side of it, and the rest of
    // each line keeps the acceleration of a line alone.
    let alone = planned("G1 X50 F3000\nM2\n")[0].acc_mm_per_s2;
    let b = planned("G1 X50 F3000\nX100 Y1\nM2\n");
    let motion: Vec<&CommandBlock> = b.iter().filter(|x| x.is_motion()).collect();
    assert_eq!(motion.len(), 4, "each line split once, beside the kink");
    let [body_a, tail, head, body_b] = [motion[0], motion[1], motion[2], motion[3]];
    assert!(
        tail.end_feed_mm_per_min > 0.0,
        "the kink is passed at speed"
    );
    assert_eq!(body_a.acc_mm_per_s2, alone);
    assert_eq!(body_b.acc_mm_per_s2, alone);
    assert!(tail.acc_mm_per_s2 < alone && head.acc_mm_per_s2 < alone);
    // Each stretch is 4 steps at the kink's highest speed (here the feed, 50 mm/s) plus
    // the path covered while 2000 mm/s² eases down at 50 000 mm/s³: 50·(0.004 + 0.04)
    // = 2.2 mm. The pieces join exactly on the programmed lines.
    for x in [tail, head] {
        assert!((x.length_mm - 2.2).abs() < 1e-9, "{}", x.length_mm);
    }
    let end = |x: &CommandBlock| x.ctrl()[1];
    let start = |x: &CommandBlock| x.ctrl()[0];
    assert_eq!(end(body_a), start(tail));
    assert_eq!(end(tail)[..3], [50.0, 0.0, 0.0]);
    assert_eq!(end(head), start(body_b));
    assert_eq!(end(body_b)[..3], [100.0, 1.0, 0.0]);
    assert_eq!(end(body_a)[1], 0.0, "on the first line");
    let p = end(head);
    assert!(
        (p[1] - (p[0] - 50.0) / 50.0).abs() < 1e-15,
        "on the second line"
    );
    for x in &motion {
        assert!(x.validate().is_ok());
    }
}

#[test]
fn curvature_limits_the_feed() {
    // r = 1 mm at 6000 mm/min (100 mm/s) needs 10 000 mm/s² centripetal. The planner
    // gives the curvature half the path acceleration (v²/r <= 1000 mm/s²: 31.6 mm/s)
    // and half the jerk; on a circle the jerk at constant speed is v³/r² <= 25 000
    // mm/s³: 29.24 mm/s, the lower.
    // Where the planned time is shorter so, the planner gives the curvature
    // `VALLEY_SHARE` (0.95) instead (`blocks::shares`), and lowers that cap by fifths
    // until the profile keeps its floor: here the block starts and ends at rest, the
    // tangential limits that leaves are higher, and it takes 0.8 of that share's cap
    // (28.97 mm/s).
    let b = planned("G0 X1\nG3 X1 Y0 I-1 J0 F6000\n");
    let cap = |share: f64| {
        (share * 2000.0f64 * 1.0)
            .sqrt()
            .min((share * 50_000.0f64 * 1.0).cbrt())
    };
    let got = b[1].feed_mm_per_min / 60.0;
    let valley = 0.8 * cap(VALLEY_SHARE);
    assert!(
        (got - cap(0.5)).abs() < 0.01 || (got - valley).abs() < 0.01,
        "{got} mm/s: neither {} nor {valley}",
        cap(0.5)
    );
}

#[test]
fn exact_stop_mode_and_programmed_stops_end_moves_at_rest() {
    // Three collinear moves flow through their joins under G64...
    let flow = planned("G64\nG1 X10 F3000\nX20\nX30\nM2\n");
    assert!(flow[0].end_feed_mm_per_min > 0.0 && flow[1].end_feed_mm_per_min > 0.0);
    // ...stop at each under G61.1 (every move, including the NURBS pieces' last)...
    let stops = planned("G61.1\nG1 X10 F3000\nX20\nX30\nM2\n");
    assert_eq!(stops[0].end_feed_mm_per_min, 0.0);
    assert_eq!(stops[1].end_feed_mm_per_min, 0.0);
    // ...and at an M0 or M1 only where it stands.
    let m0 = planned("G1 X10 F3000\nM0\nX20\nX30\nM2\n");
    assert_eq!(m0[0].end_feed_mm_per_min, 0.0);
    assert!(m0[1].end_feed_mm_per_min > 0.0);
}

proptest::proptest! {
    /// A compact straight block validates as the block it stands for, whatever its
    /// numbers (NaN, infinities, negative or zero feeds, lengths and limits) and flags.
    #[test]
    fn straight_validates_as_its_command_block(
        from in proptest::array::uniform3(number()),
        to in proptest::array::uniform3(number()),
        plan in proptest::array::uniform6(number()),
        flags in 0u32..8,
        seq in 0u64..1000,
    ) {
        let s = Straight {
            source_line: 7,
            flags,
            from,
            to,
            feed_mm_per_min: plan[0],
            start_feed_mm_per_min: plan[1],
            end_feed_mm_per_min: plan[2],
            length_mm: plan[3],
            acc_mm_per_s2: plan[4],
            jerk_mm_per_s3: plan[5],
        };
        proptest::prop_assert_eq!(s.validate(seq), s.command(seq).validate());
        let b = Block::Straight(s);
        proptest::prop_assert_eq!(b.validate(seq), b.command(seq).validate());
    }
}

/// Numbers a planner might leave in a block, good and bad.
fn number() -> impl proptest::strategy::Strategy<Value = f64> {
    use proptest::prelude::*;
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-0.0),
        -1e3..1e3f64,
        1e-9..1e6f64,
    ]
}

/// A shape's numbers as bits, to compare two shapes exactly.
fn shape_bits(s: &Shape) -> Vec<u64> {
    [s.v_cap, s.acc, s.jerk]
        .iter()
        .chain(&s.t_start)
        .chain(&s.t_end)
        .chain(&s.k_start)
        .chain(&s.k_end)
        .chain(&s.surface_ratio.into_iter().collect::<Vec<_>>())
        .map(|x| x.to_bits())
        .collect()
}

/// Chord components: axis-aligned, tiny, huge and ordinary.
fn component() -> impl proptest::strategy::Strategy<Value = f64> {
    use proptest::prelude::*;
    prop_oneof![
        Just(0.0),
        Just(-0.0),
        Just(1e-13),
        Just(-3e-14),
        -1e3..1e3f64,
        -1e-6..1e-6f64,
        1e6..1e9f64,
    ]
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(2000))]
    /// The planner's shortcut for lines gives `shape`'s very bits, on the default machine
    /// and on one whose axes differ, for any chord and feed it takes.
    #[test]
    fn straight_shape_is_the_general_shape(
        d in proptest::array::uniform3(component()),
        feed in proptest::prop_oneof![0.0..20_000.0f64, 1e-9..1e-3f64, number()],
        odd in proptest::bool::ANY,
    ) {
        let mut machine = Machine::default();
        if odd {
            machine.axes.x.max_vel_mm_per_min = 1234.5;
            machine.axes.y.max_acc_mm_per_s2 = 77.7;
            machine.axes.z.max_jerk_mm_per_s3 = 3.0e6;
        }
        let lim = StraightLimits::new(&machine).expect("usable limits");
        let general = shape(Geometry::Straight(d), &machine, 1e-3, feed, NORMAL_SHARE);
        if let Some(fast) = shape_straight(d, &lim, feed) {
            proptest::prop_assert_eq!(shape_bits(&fast), shape_bits(&general), "{:?} {}", d, feed);
        }
    }
}

/// A junction's load as bits, to compare two exactly.
fn load_bits(l: &Load) -> Vec<u64> {
    [l.turn, l.kappa, l.jump, l.acc_kappa3, l.dk]
        .iter()
        .flatten()
        .map(|x| x.to_bits())
        .collect()
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(2000))]
    /// `Load::of` between lines gives the bits the general form works out, for any
    /// tangents, accelerations (good and bad) and periods; and between a line and an arc
    /// it is the general form.
    #[test]
    fn line_junction_load_is_the_general_load(
        da in proptest::array::uniform3(component()),
        db in proptest::array::uniform3(component()),
        acc in proptest::array::uniform2(proptest::prop_oneof![number(), 1e-3..1e5f64]),
        period_s in proptest::prop_oneof![proptest::strategy::Just(1e-3), number()],
        arc in proptest::bool::ANY,
    ) {
        let unit = |d: [f64; 3]| {
            let n = path::norm(d);
            d.map(|x| x / n)
        };
        let line = |d: [f64; 3], acc: f64| Shape {
            v_cap: 100.0,
            acc,
            jerk: 1e4,
            t_start: unit(d),
            t_end: unit(d),
            k_start: [0.0; 3],
            k_end: [-0.0, 0.0, -0.0],
            dk_start: [0.0; 3],
            dk_end: [0.0; 3],
            surface_ratio: None,
            m_start: None,
            m_end: None,
            m2_start: None,
            m2_end: None,
        };
        let a = line(da, acc[0]);
        let mut b = line(db, acc[1]);
        if arc {
            b.k_start = [0.0, 0.1, 0.0];
        }
        let turn = sub(b.t_start, a.t_end);
        let turn = [0, 1, 2].map(|i| turn[i].abs() / period_s);
        let turn = [turn[0], turn[1], turn[2], path::norm(sub(b.t_start, a.t_end)) / period_s];
        proptest::prop_assert_eq!(
            load_bits(&Load::of(&a, &b, period_s)),
            load_bits(&Load::general(&a, &b, turn, period_s))
        );
    }
}

#[test]
fn straight_limits_refuse_a_machine_they_cannot_shortcut() {
    let mut machine = Machine::default();
    assert!(StraightLimits::new(&machine).is_some());
    machine.axes.y.max_jerk_mm_per_s3 = f64::INFINITY;
    assert!(StraightLimits::new(&machine).is_none());
    machine = Machine::default();
    machine.path_acc_mm_per_s2 = 0.0;
    assert!(StraightLimits::new(&machine).is_none());
}

/// [`find_cusp`] as it was before the speed bound ([`hodograph`]) let it skip parts
/// of the curve: every pair of samples looked at, every sample evaluated twice.
fn find_cusp_everywhere(c: &SplitCurve, machine: &Machine) -> Option<f64> {
    const N: usize = 64;
    let (u0, u1) = (c.knots[0], c.knots[c.knots.len() - 1]);
    let at = |i: usize| u0 + (u1 - u0) * i as f64 / N as f64;
    let d1 = |u: f64| nurbs::eval(c.degree, &c.knots, &c.ctrl, u).d1;
    let cos_corner = machine.corner_angle_deg.to_radians().cos();
    for i in 1..N {
        let (a, b) = (d1(at(i - 1)), d1(at(i + 1)));
        let (na, nb) = (path::norm(a), path::norm(b));
        if na < 1e-12 || nb < 1e-12 {
            continue;
        }
        if dot(a, b) / (na * nb) >= cos_corner {
            continue;
        }
        let (mut lo, mut hi) = (at(i - 1), at(i + 1));
        for _ in 0..100 {
            let m1 = lo + (hi - lo) / 3.0;
            let m2 = hi - (hi - lo) / 3.0;
            if path::norm(d1(m1)) < path::norm(d1(m2)) {
                hi = m2;
            } else {
                lo = m1;
            }
        }
        let u = 0.5 * (lo + hi);
        let len = path::norm(d1(u0)).max(path::norm(d1(u1))).max(1e-9);
        if path::norm(d1(u)) <= 1e-6 * len && u > u0 + 1e-9 * (u1 - u0) && u < u1 - 1e-9 * (u1 - u0)
        {
            return Some(u);
        }
    }
    None
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(1000))]
    /// The cusp search finds what looking everywhere finds, to the bit: on Bézier spans
    /// made to have a cusp (their derivative zero at `t0`), on zig-zag polygons, with
    /// weights or without.
    #[test]
    fn cusps_are_found_where_looking_everywhere_finds_them(
        degree in 2usize..=4,
        pts in proptest::collection::vec((-20.0f64..20.0, -20.0f64..20.0, -2.0f64..2.0), 5),
        weights in proptest::collection::vec(0.3f64..3.0, 5),
        rational in proptest::bool::ANY,
        cusp in proptest::bool::ANY,
        t0 in 0.1f64..0.6,
        u0 in -2.0f64..2.0,
        width in 0.1f64..5.0,
    ) {
        let mut ctrl: Vec<[f64; 4]> = pts[..=degree]
            .iter()
            .zip(&weights)
            .map(|(&(x, y, z), &w)| [x, y, z, if rational { w } else { 1.0 }])
            .collect();
        if cusp && degree == 3 {
            // C'(t0) = 0 for a polynomial cubic: solve for P2 (weights one).
            let s = 1.0 - t0;
            for c in ctrl.iter_mut() {
                c[3] = 1.0;
            }
            let (p0, p1, p3) = (ctrl[0], ctrl[1], ctrl[3]);
            let k = 2.0 * t0 * s - t0 * t0;
            for x in 0..3 {
                ctrl[2][x] = (-(s * s) * (p1[x] - p0[x]) + 2.0 * t0 * s * p1[x] - t0 * t0 * p3[x]) / k;
            }
        }
        let mut knots = vec![u0; degree + 1];
        knots.extend(std::iter::repeat_n(u0 + width, degree + 1));
        let c = SplitCurve { degree, knots, ctrl };
        let machine = Machine::default();
        let want = find_cusp_everywhere(&c, &machine);
        let got = find_cusp(&c, &machine);
        proptest::prop_assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits));
    }
}

#[test]
fn a_cusp_of_a_cubic_is_found_as_before() {
    // C'(1/2) = 0: out and back with a turn, the textbook cusp.
    let ctrl = vec![
        [0.0, 0.0, 0.0, 1.0],
        [1.0, 1.0, 0.0, 1.0],
        [0.0, 1.0, 0.0, 1.0],
        [1.0, 0.0, 0.0, 1.0],
    ];
    let c = SplitCurve {
        degree: 3,
        knots: vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
        ctrl,
    };
    let machine = Machine::default();
    let u = find_cusp(&c, &machine).expect("a cusp");
    assert!((u - 0.5).abs() < 1e-6, "{u}");
    assert_eq!(Some(u), find_cusp_everywhere(&c, &machine));
}

/// The largest of a measure over a block, looked for everywhere: 40 001 points evenly
/// spaced in the parameter, then golden section around the best (the reference for
/// [`samples`], which takes a few dozen points and searches between them).
fn largest_everywhere(b: &CommandBlock, m: impl Fn(f64) -> Option<f64>) -> f64 {
    let (u0, u1) = path::domain(b);
    const N: usize = 40_000;
    let u = |i: usize| u0 + (u1 - u0) * i as f64 / N as f64;
    let (mut best, mut at) = (f64::NEG_INFINITY, 0);
    for i in 0..=N {
        if let Some(x) = m(u(i)) {
            if x > best {
                (best, at) = (x, i);
            }
        }
    }
    let (lo, hi) = (u(at.saturating_sub(1)), u((at + 1).min(N)));
    golden_max(lo, hi, &m)
        .and_then(&m)
        .map_or(best, |x| x.max(best))
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(100))]
    /// Each axis's share of the tangent reaches its largest value among the planner's
    /// samples (it sets that axis's velocity bound), as a search everywhere finds it, to
    /// 1e-6: on random curves of one span and of several, rational or not, and on curves
    /// with a bend of a few µm (a control point pulled close to its neighbour), where
    /// the tangent swings through X between two samples. Before the tangent's peaks
    /// were searched, such a bend at a split block's end broke a weak X axis's velocity
    /// by 1 % in the random search of `limits.rs`.
    #[test]
    fn samples_hold_each_axis_tangent_peak(
        degree in 2usize..=5,
        extra in 0usize..3,
        pts in proptest::collection::vec((-20.0f64..20.0, -20.0f64..20.0, -2.0f64..2.0), 9),
        weights in proptest::collection::vec(0.3f64..3.0, 9),
        rational in proptest::bool::ANY,
        bend in proptest::prop_oneof![proptest::strategy::Just(None), proptest::strategy::Strategy::prop_map(1e-4f64..1e-2, Some)],
    ) {
        let n = degree + 1 + extra;
        let mut ctrl: Vec<[f64; 4]> = pts[..n]
            .iter()
            .zip(&weights)
            .map(|(&(x, y, z), &w)| [x, y, z, if rational { w } else { 1.0 }])
            .collect();
        if let Some(e) = bend {
            // A tight bend: the middle control point next to the one before it.
            let k = n / 2;
            let p = ctrl[k - 1];
            ctrl[k] = [p[0] + e, p[1] - e, p[2], ctrl[k][3]];
        }
        let mut knots = vec![0.0; degree + 1];
        knots.extend((1..=extra).map(|i| i as f64 * 0.7));
        knots.extend(std::iter::repeat_n(extra as f64 * 0.7 + 1.3, degree + 1));
        let b = curve_block(3, &SplitCurve { degree, knots, ctrl }, Helix::NONE, 900.0);
        let (pts, _, _, _) = samples(&b, false);
        for i in 0..3 {
            let sampled = pts.iter().map(|(t, _)| t[i].abs()).fold(0.0f64, f64::max);
            let everywhere = largest_everywhere(&b, |u| frame(&b, u).map(|(t, _)| t[i].abs()));
            proptest::prop_assert!(
                sampled >= everywhere - 1e-6,
                "axis {}: the samples' largest |T| {} below {} found everywhere",
                i, sampled, everywhere
            );
        }
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(5000))]
    /// `min_cbrt` is `v.min(x.cbrt())` bit for bit, close to the root and far from it.
    #[test]
    fn min_cbrt_is_the_minimum_with_the_cube_root(
        v in proptest::prop_oneof![number(), 1e-120..1e-90f64, 1e100..1e110f64],
        x in proptest::prop_oneof![number(), 1e-310..1e-300f64, 1e300..f64::MAX],
        near in proptest::prop_oneof![proptest::strategy::Just(None), proptest::strategy::Strategy::prop_map(-1e-5..1e-5f64, Some)],
    ) {
        // Close to the root too: x within a few millionths of v³.
        let x = near.map_or(x, |e| v * v * v * (1.0 + e));
        proptest::prop_assert_eq!(min_cbrt(v, x).to_bits(), v.min(x.cbrt()).to_bits(), "{} {}", v, x);
    }
}

/// A cubic whose bend tightens towards its end, entered at its cap and left at a fifth
/// of it: [`relaxed_limits`] gives the profile more acceleration and more jerk than
/// [`shape`]'s worst case at the cap (it failed before each relaxation: the block kept
/// `shape`'s), and what it gives keeps the path's and each axis's acceleration and jerk
/// at each of 4000 points, checked with the general evaluator (`path::eval`), the arc
/// length by the trapezoid rule and `dk/ds` by differences, at the highest speed the
/// block can have there. Tolerance: 1e-9 relative on the acceleration, 1e-3 on the jerk (the
/// differences' error).
#[test]
fn a_block_left_slowly_may_change_speed_faster_where_it_is_straighter() {
    let m = Machine::default();
    let c = SplitCurve {
        degree: 3,
        knots: vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
        ctrl: vec![
            [0.0, 0.0, 0.0, 1.0],
            [2.0, 0.0, 0.0, 1.0],
            [3.0, 0.3, 0.0, 1.0],
            [3.3, 1.2, 0.0, 1.0],
        ],
    };
    let b = curve_block(1, &c, Helix::NONE, 3000.0);
    let len = path::length(&b);
    let s = shape(Geometry::Curve(&b), &m, 1e-3, 50.0, NORMAL_SHARE);
    let lim = Jerk {
        acc: s.acc,
        jerk: s.jerk,
    };
    let (cap, start, end) = (s.v_cap, s.v_cap, 0.0);
    let none = Jerk {
        acc: f64::INFINITY,
        jerk: f64::INFINITY,
    };
    let relaxed = relaxed_limits(&b, &m, cap, lim, (start, end), len, none);
    let acc = relaxed.acc;
    assert!(acc > 1.2 * lim.acc, "{acc} against {}", lim.acc);
    assert!(
        relaxed.jerk > 1.2 * lim.jerk,
        "{} against {}",
        relaxed.jerk,
        lim.jerk
    );
    println!("relaxed {relaxed:?} from {lim:?}");
    keeps_limits(&b, &m, (cap, start, end), relaxed);
}

/// Panics unless `lim` keeps the path's and each axis's acceleration and jerk at each of
/// 4000 points of `b`, checked with the general evaluator (`path::eval`), the arc length
/// by the trapezoid rule and `dk/ds` by differences, at the highest speed the block can
/// have there: within `cap`, from `start` and down to `end` (mm/s) changing its speed
/// by `lim.acc` at most. Tolerance: 1e-9 relative on the acceleration, 1e-3 on the jerk
/// (the differences' error).
fn keeps_limits(b: &CommandBlock, m: &Machine, (cap, start, end): (f64, f64, f64), lim: Jerk) {
    const N: usize = 4000;
    let (u0, u1) = path::domain(b);
    let pts: Vec<_> = (0..=N)
        .map(|i| path::eval(b, u0 + (u1 - u0) * i as f64 / N as f64))
        .collect();
    let du = (u1 - u0) / N as f64;
    let mut at = vec![0.0; N + 1];
    for i in 1..=N {
        at[i] = at[i - 1] + 0.5 * du * (path::norm(pts[i].d1) + path::norm(pts[i - 1].d1));
    }
    let frames: Vec<([f64; 3], [f64; 3])> = pts
        .iter()
        .map(|e| {
            let sp = path::norm(e.d1);
            let t = e.d1.map(|x| x / sp);
            let along = dot(e.d2, t);
            (t, [0, 1, 2].map(|i| (e.d2[i] - along * t[i]) / (sp * sp)))
        })
        .collect();
    let acc = lim.acc;
    for i in 1..N {
        let (t, k) = frames[i];
        let dk =
            [0, 1, 2].map(|c| (frames[i + 1].1[c] - frames[i - 1].1[c]) / (at[i + 1] - at[i - 1]));
        let x = at[i];
        let v = cap
            .min((start * start + 2.0 * acc * x).sqrt())
            .min((end * end + 2.0 * acc * (at[N] - x)).sqrt());
        let kappa = path::norm(k);
        let a_path = (acc * acc + (v * v * kappa).powi(2)).sqrt();
        assert!(
            a_path <= m.path_acc_mm_per_s2 * (1.0 + 1e-9),
            "point {i}: {a_path}"
        );
        let jerk = lim.jerk + 3.0 * v * acc * kappa + v.powi(3) * path::norm(dk);
        assert!(
            jerk <= m.path_jerk_mm_per_s3 * (1.0 + 1e-3),
            "point {i}: {jerk}"
        );
        for (c, ax) in m.axes.as_array().iter().enumerate() {
            let a = acc * t[c].abs() + v * v * k[c].abs();
            assert!(
                a <= ax.max_acc_mm_per_s2 * (1.0 + 1e-9),
                "point {i} axis {c}: {a}"
            );
            let j = lim.jerk * t[c].abs() + 3.0 * v * acc * k[c].abs() + v.powi(3) * dk[c].abs();
            assert!(
                j <= ax.max_jerk_mm_per_s3 * (1.0 + 1e-3),
                "point {i} axis {c}: jerk {j}"
            );
        }
    }
}

/// [`SAMPLED_STEP`]: a step `Δa` of the acceleration at `τ` (the motion
/// `Δa/2·(t − τ)²` after it, nothing before) moves the set-points' third difference,
/// over `T³`, by at most `0.75·Δa/T` wherever `τ` falls between set-points, and by that
/// much halfway between two (closed form; tolerance 1e-9 relative).
#[test]
fn an_acceleration_step_moves_the_sampled_jerk_by_three_quarters_at_most() {
    let (t, da) = (1e-3, 800.0);
    let p = |x: f64, tau: f64| {
        if x > tau {
            0.5 * da * (x - tau).powi(2)
        } else {
            0.0
        }
    };
    let mut worst: f64 = 0.0;
    for i in 0..=1000 {
        let tau = 5.0 * t + t * i as f64 / 1000.0;
        let pos: Vec<f64> = (0..12).map(|n| p(n as f64 * t, tau)).collect();
        for w in pos.windows(4) {
            let jerk = (w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0]) / t.powi(3);
            worst = worst.max(jerk.abs());
        }
    }
    let bound = SAMPLED_STEP * da / t;
    assert!(worst <= bound * (1.0 + 1e-9), "{worst} > {bound}");
    assert!(worst >= bound * (1.0 - 1e-9), "{worst} < {bound}");
}

/// A curvature jump without a kink (a line running tangentially into an arc, a
/// quadratic's knot) is passed at the highest speed whose acceleration step, with the
/// normal jerk there, stays within `JUMP_SHARE` of the jerk (`Load::jerk_speed`), not
/// at what the blocks' own profiles have left of it: the step is normal to the path and
/// the profiles beside it are left what it leaves (`junction_leaves`). Closed form on
/// the default machine (path and axis jerk J = 50 000 mm/s³, period T = 1 ms): a line
/// into an arc of radius r = 5 mm at `v` steps the acceleration by `v²/r`, which the
/// set-points show as `SAMPLED_STEP·v²/(r·T)`, and the arc's tangential acceleration
/// `a` adds `3·a·v/r`; so `v` is the root of `0.75·v²/(r·T) + 3·a·v/r = 0.8·J`, between
/// its value at the machine's whole acceleration (`a` = 2000 mm/s², the lowest) and at
/// the arc's own (`a` its planned acceleration, the highest). Tolerance 1e-9 relative.
/// (Before, the jump's speed was also held to the blocks' leftover jerk: 10.93 mm/s here.)
#[test]
fn a_curvature_jump_is_passed_at_the_speed_its_share_of_the_jerk_allows() {
    let b = planned("G1 X10 F6000\nG3 X10 Y10 I0 J5\nM2\n");
    let m = Machine::default();
    let (r, t, j) = (5.0, 1e-3, m.path_jerk_mm_per_s3);
    let root = |a: f64| {
        let (c2, c1) = (SAMPLED_STEP / (r * t), 3.0 * a / r);
        (-c1 + (c1 * c1 + 4.0 * c2 * JUMP_SHARE * j).sqrt()) / (2.0 * c2)
    };
    let v = b[0].end_feed_mm_per_min / 60.0;
    let (lo, hi) = (root(m.path_acc_mm_per_s2), root(b[1].acc_mm_per_s2));
    println!("junction {v} mm/s, closed form between {lo} and {hi}");
    assert!(
        v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9),
        "{v} not in [{lo}, {hi}]"
    );
}

/// [`braking_relaxed`]: a chain of short blends braking to a stop (the end of the CAM
/// circle, `examples/cam-circle.ngc`, 0.63 mm blends at 40 mm/s on the built-in
/// machine) brakes by the jerk its speeds leave, not by the jerk its cap leaves (at the
/// cap the curvature's `v³·|dk/ds|` takes 95 % of it). Each curve block that brakes
/// below its cap starts at the highest speed from which it can brake to its end under
/// the limits it is given (no higher, and lower by 0.1 % at most; before, the chain's speeds were planned under the
/// cap's jerk and the last relaxation raised the jerk afterwards, so each block started
/// up to 1 % below that speed, and the chain braked from 40 mm/s over its last 30 mm
/// instead of 11), and those
/// limits keep the path's and each axis's acceleration and jerk at 4000 points of the
/// block at the highest speed it can have there (tolerances as in
/// `a_block_left_slowly_may_change_speed_faster_where_it_is_straighter`).
#[test]
fn a_chain_of_short_blends_brakes_by_the_jerk_its_speeds_leave() {
    let m = Machine::default();
    let text = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/cam-circle.ngc"),
    )
    .unwrap();
    let opts = crate::program::Options::default();
    let blocks = crate::process::compile_source("cam-circle.ngc", &text, &opts, &m, 1_000_000)
        .unwrap()
        .blocks;
    let mut braking = 0;
    for b in &blocks {
        let (start, end, cap) = (
            b.start_feed_mm_per_min / 60.0,
            b.end_feed_mm_per_min / 60.0,
            b.feed_mm_per_min / 60.0,
        );
        if b.kind != BlockKind::Motion as u32
            || straight(b).is_some()
            || start <= end
            || start > 0.98 * cap
            || b.length_mm < 0.1
        {
            continue;
        }
        braking += 1;
        let lim = Jerk {
            acc: b.acc_mm_per_s2,
            jerk: b.jerk_mm_per_s3,
        };
        let reach = lim.reachable_speed(end, b.length_mm);
        assert!(
            start >= 0.999 * reach && start <= reach * (1.0 + 1e-9),
            "block {}: starts at {start} mm/s, its limits {lim:?} brake from {reach}",
            b.seq
        );
        keeps_limits(b, &m, (cap, start, end), lim);
    }
    assert!(braking >= 10, "only {braking} braking blends");
}

#[test]
fn the_plan_cache_gives_each_shape_and_length_as_worked_out_anew() {
    // A block's shape is kept per feed and share: asked again for either, or for a
    // third pair (which takes a slot), it is what `shape` works out, bit for bit.
    let m = Machine::default();
    let c = SplitCurve {
        degree: 3,
        knots: vec![0.0, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 1.0],
        ctrl: vec![
            [0.0, 0.0, 0.0, 1.0],
            [2.0, 0.0, 0.0, 1.0],
            [3.0, 0.3, 0.0, 1.0],
            [3.3, 1.2, 0.0, 1.0],
        ],
    };
    let b = curve_block(1, &c, Helix::NONE, 3000.0);
    let g = Geometry::Curve(&b);
    let line = Geometry::Straight([3.0, 4.0, 0.0]);
    let mut cache = cache::PlanCache::new(3);
    let asks = [
        (0, g, 50.0, NORMAL_SHARE),
        (0, g, 50.0, VALLEY_SHARE),
        (0, g, 50.0, NORMAL_SHARE),
        (0, g, 20.0, NORMAL_SHARE),
        (0, g, 50.0, VALLEY_SHARE),
        (1, g, 50.0, VALLEY_SHARE),
        (2, line, 50.0, NORMAL_SHARE),
        (2, line, 20.0, NORMAL_SHARE),
        // Past the cache's blocks: worked out, not kept.
        (7, g, 50.0, NORMAL_SHARE),
    ];
    for (i, g, feed, share) in asks {
        let kept = cache.shape(i, g, &m, 1e-3, feed, share);
        let anew = shape(g, &m, 1e-3, feed, share);
        assert_eq!(shape_bits(&kept), shape_bits(&anew), "{i} {feed} {share}");
    }
    // The two shares give different shapes here, so a key without the share fails.
    let (n, v) = (
        shape(g, &m, 1e-3, 50.0, NORMAL_SHARE),
        shape(g, &m, 1e-3, 50.0, VALLEY_SHARE),
    );
    assert_ne!(shape_bits(&n), shape_bits(&v));
    let len = path::length(&b);
    for i in [0, 0, 7] {
        assert_eq!(cache.length(i, &b).to_bits(), len.to_bits());
    }
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(200))]
    /// The curvature's rate from the third derivative (`rate_at`) against central
    /// differences of the curvature vector along the arc (the general evaluator,
    /// Richardson-extrapolated from steps `h` and `h/2`), inside a span of random curves,
    /// rational or not: to 1e-5 of the larger of `|dk/ds|` and `κ² + κ/L` (`L` the
    /// control polygon's size), plus four times the reference's own error, estimated as
    /// the difference of its values from `h = 1e-3` and `5e-4` of the span (where the
    /// curvature changes fast, as beside control points that coincide, the difference
    /// itself is off by 6e-4 of it at the larger step: a CI run found one).
    #[test]
    fn the_curvature_rate_is_the_rate_of_the_curvature(
        degree in 3usize..=5,
        pts in proptest::collection::vec((-20.0f64..20.0, -20.0f64..20.0, -2.0f64..2.0), 6),
        weights in proptest::collection::vec(0.3f64..3.0, 6),
        rational in proptest::bool::ANY,
        t in 0.1f64..0.9,
    ) {
        let n = degree + 1;
        let ctrl: Vec<[f64; 4]> = pts[..n]
            .iter()
            .zip(&weights)
            .map(|(&(x, y, z), &w)| [x, y, z, if rational { w } else { 1.0 }])
            .collect();
        let mut knots = vec![0.0; degree + 1];
        knots.extend(std::iter::repeat_n(1.0, degree + 1));
        let b = curve_block(3, &SplitCurve { degree, knots, ctrl }, Helix::NONE, 900.0);
        let ev = eval::BlockEval::new(&b);
        let Some((e, d3)) = ev.eval_d3(t) else {
            return Err(proptest::test_runner::TestCaseError::fail("no third derivative"));
        };
        let got = rate_at(&e, d3);
        let diff = |h: f64| -> Option<[f64; 3]> {
            let (a, c) = (path::eval(&b, t - h), path::eval(&b, t + h));
            let ((_, ka), (_, kc)) = (frame_at(&a)?, frame_at(&c)?);
            let ds = path::norm(sub(c.p, a.p));
            Some(sub(kc, ka).map(|x| x / ds))
        };
        let richardson = |h: f64| -> Option<[f64; 3]> {
            let (d1, d2) = (diff(h)?, diff(0.5 * h)?);
            Some(std::array::from_fn(|i| (4.0 * d2[i] - d1[i]) / 3.0))
        };
        let (Some(coarse), Some(want)) = (richardson(1e-3), richardson(5e-4)) else {
            return Ok(());
        };
        let own = path::norm(sub(coarse, want));
        let Some((_, k)) = frame_at(&e) else { return Ok(()); };
        let kappa = path::norm(k);
        let size = pts.iter().fold(1.0f64, |m, p| m.max(p.0.abs()).max(p.1.abs()));
        let scale = path::norm(want).max(kappa * kappa + kappa / size);
        let err = (path::norm(sub(got, want)) - 4.0 * own).max(0.0) / scale;
        proptest::prop_assert!(err < 1e-5, "{:?} vs {:?}: {:e}", got, want, err);
    }
}

/// On a circle of radius `r` the curvature vector turns with the tangent: `dk/ds =
/// −T/r²`, of length `1/r²`. The rational quadratic quarter circle, to 1e-12 of it.
#[test]
fn the_curvature_rate_of_a_circle_is_its_closed_form() {
    let (r, w) = (7.0, std::f64::consts::FRAC_1_SQRT_2);
    let c = SplitCurve {
        degree: 2,
        knots: vec![0.0, 0.0, 0.0, 1.0, 1.0, 1.0],
        ctrl: vec![[r, 0.0, 0.0, 1.0], [r, r, 0.0, w], [0.0, r, 0.0, 1.0]],
    };
    let b = curve_block(1, &c, Helix::NONE, 900.0);
    let ev = eval::BlockEval::new(&b);
    for u in [0.0, 0.2, 0.5, 0.77, 1.0] {
        let (e, d3) = ev.eval_d3(u).expect("a plain curve");
        let (t, _) = frame_at(&e).expect("moving");
        let got = rate_at(&e, d3);
        let want = t.map(|x| -x / (r * r));
        let err = path::norm(sub(got, want)) * r * r;
        assert!(err < 1e-12, "{u}: {got:?} vs {want:?} ({err:e})");
    }
}

/// Machining time of `text` on the built-in machine, planned whole (`cnc check
/// --estimate`).
fn time_s(text: &str) -> f64 {
    let b = planned(text);
    crate::estimate::estimate(&b, &Machine::default(), 1_000_000)
        .expect("the estimate")
        .time_s
}

/// A braking over many short blocks is one braking, as the interpolator runs it with its
/// acceleration carried across their ends, not a braking from rest acceleration to rest
/// acceleration in each block: 40 mm of `G1` at F3000 cut into 1000 collinear lines of
/// 0.04 mm takes within 6 % of the one line's time (0.908 s against 0.865 s measured;
/// the rest is the interpolator folding the limits beyond its 16 nearest into one). Each
/// block braking by itself (the built-in machine's jerk lets a 0.04 mm block at 28 mm/s
/// change its speed by 1.5 mm/min) made it 1.563 s.
#[test]
fn a_braking_over_short_lines_is_one_braking() {
    let one = time_s("G21 G90\nG1 X0 Y0 F3000\nG1 X40\nM2\n");
    let mut cut = String::from("G21 G90\nG1 X0 Y0 F3000\n");
    for i in 1..=1000 {
        cut.push_str(&format!("G1 X{:.4}\n", i as f64 * 0.04));
    }
    cut.push_str("M2\n");
    let chopped = time_s(&cut);
    assert!(
        chopped <= 1.06 * one,
        "1000 lines {chopped} s, one line {one} s"
    );
}

/// A plain, reproducible stream of uniforms in `[0, 1)` from `seed` (xorshift64*), for
/// the planner's property tests.
pub(super) fn uniforms(seed: u64) -> impl FnMut() -> f64 {
    let mut x = seed | 1;
    move || {
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        (x.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Figures of a made-up curve block for [`Envelope`]: `n` samples whose curvature, rate
/// and axis shares spread over three orders of magnitude about the built-in machine's
/// limits at tens of mm/s, so that different samples bind at different accelerations;
/// some repeated, as an arc's are.
fn made_up_figures(seed: u64, n: usize) -> Vec<Figure> {
    let mut next = uniforms(seed);
    let mut out: Vec<Figure> = Vec::with_capacity(n);
    for _ in 0..n {
        if next() < 0.2 {
            if let Some(&f) = out.last() {
                out.push(f);
                continue;
            }
        }
        let scale = 10f64.powf(3.0 * next() - 4.0);
        let lo = next();
        out.push(Figure {
            kappa: scale * next(),
            dkn: 0.1 * scale * next(),
            t: [next(), next(), next()],
            k: [scale * next(), scale * next(), scale * next()],
            dk: [0.1 * scale * next(), 0.0, 0.1 * scale * next()],
            lo,
            hi: lo + (1.0 - lo) * next(),
        });
    }
    out
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(3000))]
    /// [`Envelope::highest_acc`] takes the same bisection steps as asking every sample at
    /// every step: the same bits. (Of these cases about two thirds end between the
    /// bisection's ends, the rest at its low end.)
    #[test]
    fn the_acceleration_asked_of_the_binding_samples_is_the_bisection_of_all(
        seed in 0u64..u64::MAX,
        n in 0usize..80,
        cap in 1.0..300.0f64,
        ends in (0.0..1.0f64, 0.0..1.0f64),
        len in 0.001..20.0f64,
        low in 1.0..1500.0f64,
        j in 1.0..40_000.0f64,
        halvings in proptest::prop_oneof![proptest::strategy::Just(20usize), 1usize..64],
    ) {
        let m = Machine::default();
        let figures = made_up_figures(seed, n);
        let env = Envelope {
            figures: &figures,
            machine: &m,
            cap,
            ends: (ends.0 * cap, ends.1 * cap),
            len,
        };
        let top = 4000.0;
        let all = highest_fitting(low, top, halvings, |a| env.fits(a, j));
        let asked = env.highest_acc(low, top, halvings, j);
        proptest::prop_assert_eq!(asked.to_bits(), all.to_bits(), "{} against {}", asked, all);
    }
}

#[test]
fn a_chain_of_blends_is_known_and_a_lone_blend_or_a_programmed_curve_is_not() {
    // A zigzag of equal legs (1, ±0.1) turning 11.4° under `P0.04`: each blend uses up
    // half of both lines, so the blends follow one another with no line between them.
    let mut text = String::from("G21 G90 G64 P0.04 Q0\nG1 F3000 X0 Y0\n");
    for k in 1..=8 {
        text += &format!("X{k} Y{}\n", if k % 2 == 1 { "0.1" } else { "0" });
    }
    text += "M2\n";
    let machine = Machine::default();
    let blocks = build(&interpret(&text).unwrap().moves, &machine);
    let motion: Vec<Block> = blocks.into_iter().filter(|b| b.is_motion()).collect();
    let curves: Vec<usize> = (0..motion.len())
        .filter(|&i| matches!(motion[i].geometry(), Geometry::Curve(_)))
        .collect();
    assert!(curves.len() >= 4, "{} blends", curves.len());
    let (a, b) = (curves[1], curves[2]);
    assert_eq!(b, a + 1, "two blends in a row");
    assert!(chain_of_blends(&motion[a..=b]));
    // One blend alone is no chain; nor is a run with a line in it.
    assert!(!chain_of_blends(&motion[a..=a]));
    let with_line = (0..motion.len() - 1)
        .find(|&i| matches!(motion[i].geometry(), Geometry::Straight(_)))
        .unwrap();
    assert!(!chain_of_blends(&motion[with_line..=with_line + 1]));
    // A programmed quadratic NURBS is not a blend, however short.
    let curve = build(
        &interpret("G21 G90 G1 X0 Y0 F600\nG5.2 X1 Y0 P1 L3\nX2 Y1 P1\nX3 Y0 P1\nG5.3\nM2\n")
            .unwrap()
            .moves,
        &machine,
    );
    let curve: Vec<Block> = curve
        .into_iter()
        .filter(|b| b.is_motion() && matches!(b.geometry(), Geometry::Curve(_)))
        .collect();
    assert!(curve.len() >= 2);
    assert!(!chain_of_blends(&curve[..2]));
}
