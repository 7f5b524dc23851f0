//! The jerk-limited time-optimal reference ([`tests::topp3`]) against closed forms and
//! against the acceleration-only reference ([`tests::topp`]). Each case states its
//! tolerance; the grid is the table's ([`DEFAULT_STEP_MM`]) unless said.

use shared::Machine;
use tests::topp::{self, DEFAULT_STEP_MM};
use tests::topp3::{self, JerkLimits, JerkOptimum};

const PERIOD_NS: u64 = 1_000_000;

/// A machine with path acceleration `acc` and path jerk `jerk`, axis limits that never
/// bind, feed `feed` mm/min.
fn machine(acc: f64, jerk: f64, feed: f64) -> Machine {
    let mut m = Machine {
        path_acc_mm_per_s2: acc,
        path_jerk_mm_per_s3: jerk,
        max_feed_mm_per_min: feed,
        rapid_mm_per_min: feed,
        ..Machine::default()
    };
    for a in [&mut m.axes.x, &mut m.axes.y, &mut m.axes.z] {
        a.max_vel_mm_per_min = 1e6;
        a.max_acc_mm_per_s2 = 1e7;
        a.max_jerk_mm_per_s3 = 1e10;
    }
    m
}

fn optimum_at(text: &str, m: &Machine, step: f64) -> JerkOptimum {
    let blocks = interpreter::process::compile(text, m, PERIOD_NS)
        .unwrap_or_else(|e| panic!("{e:?}"))
        .1;
    let feeds = topp::programmed_feeds("t.ngc", text, m, PERIOD_NS, &blocks).unwrap();
    topp3::optimum(&blocks, &feeds, &JerkLimits::of(m, PERIOD_NS), step).unwrap()
}

fn assert_rel(what: &str, got: f64, want: f64, tol: f64) {
    let rel = (got - want).abs() / want;
    println!("{what}: reference {got:.6}, expected {want:.6}, relative {rel:.1e}");
    assert!(
        rel <= tol,
        "{what}: {got} vs {want} ({rel:.2e} > {tol:.0e})"
    );
}

/// Time of the symmetric S-curve from rest to `v` (jerk `j`, acceleration `a`).
fn ramp_time(v: f64, a: f64, j: f64) -> f64 {
    if v * j >= a * a {
        v / a + a / j
    } else {
        2.0 * (v / j).sqrt()
    }
}

/// The classical 7-phase S-curve, rest to rest over `d` under `vmax`, `a`, `j`: the
/// ramps reach `vmax` (and `a` if `vmax·j ≥ a²`) and cruise between; if `d` is shorter
/// than the two ramps, the peak speed `vp` solves `d = vp·ramp_time(vp)` (bisection).
fn s_curve_time(d: f64, vmax: f64, a: f64, j: f64) -> f64 {
    let ramp = ramp_time(vmax, a, j);
    if d >= vmax * ramp {
        return 2.0 * ramp + (d - vmax * ramp) / vmax;
    }
    let (mut lo, mut hi) = (0.0, vmax);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if mid * ramp_time(mid, a, j) < d {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    2.0 * ramp_time(lo, a, j)
}

/// Rest to rest on a straight line equals the 7-phase S-curve: 100 mm at F6000 (A and
/// F reached), 10 and 5 mm (A reached, not F) and 0.2 mm (neither: `4·(d/2J)^(1/3)`),
/// with A 1000 mm/s², J 50 000 mm/s³, on grids of 0.1, 0.08, 0.02 and 0.02 mm.
/// Tolerance 1e-2: the jerk is by differences over cells, and the start from rest is
/// resolved to the first cells (measured: 2.8e-4 on 100 mm, 2.8e-4 on 10 mm, 3.5e-3 on
/// 5 mm, 7.1e-3 on 0.2 mm: a finer grid puts more cells where `v ∝ s^(2/3)` near rest,
/// where the differences overstate the jerk). The kept profile's own jerk is within
/// `KEEP_JERK` (10 %) of the limit (measured 0.986 to 1.041).
#[test]
fn a_line_rest_to_rest_is_the_seven_phase_s_curve() {
    let m = machine(1000.0, 50_000.0, 6000.0);
    for (d, step) in [
        (100.0, 0.1),
        (10.0, 0.08),
        (5.0, DEFAULT_STEP_MM),
        (0.2, 0.02),
    ] {
        let o = optimum_at(&format!("G1 X{d} F6000\nM2\n"), &m, step);
        println!(
            "{d} mm: {o:.3?}",
            o = (
                o.time_s,
                o.acc_only_s,
                o.rounds,
                o.last_change,
                o.jerk_ratio
            )
        );
        assert_rel(
            &format!("{d} mm"),
            o.time_s,
            s_curve_time(d, 100.0, 1000.0, 50_000.0),
            1e-2,
        );
        assert!(o.jerk_ratio <= topp3::KEEP_JERK, "{}", o.jerk_ratio);
    }
}

/// A circle cruises at the speed where the jerk of its centripetal acceleration,
/// `v³/r²`, is the limit: `v = (J r²)^(1/3)` (r 10 mm, J 50 000 mm/s³: 171.0 mm/s;
/// acceleration, chord and feed do not bind: A 1e5 mm/s², F 20 000 mm/min). Tolerance
/// 1e-3 (the curvature's rate is the difference over a window of `v·T`, 0.17 mm, which
/// on a circle of 10 mm is within 1e-4 of the derivative; measured 4.5e-4). The whole
/// time is above the acceleration-only optimum's. The profile's own jerk (with its own
/// speeds, not `v̄`) is within `KEEP_JERK` (10 %) of the limit: measured 1.089, on the ramps from and to
/// rest, where the linearization has not settled (open).
#[test]
fn a_circle_cruises_where_the_centripetal_jerk_is_the_limit() {
    let m = machine(1e5, 50_000.0, 20_000.0);
    let r: f64 = 10.0;
    let o = optimum_at("G2 X0 Y0 I10 J0 F20000\nM2\n", &m, 0.1);
    let top = o.speed.iter().cloned().fold(0.0, f64::max);
    println!(
        "circle: {:.4?}",
        (
            o.time_s,
            o.acc_only_s,
            o.rounds,
            o.last_change,
            o.jerk_ratio
        )
    );
    assert_rel("cruise speed", top, (50_000.0 * r * r).cbrt(), 1e-3);
    assert!(o.time_s > o.acc_only_s);
    assert!(o.jerk_ratio <= topp3::KEEP_JERK, "{}", o.jerk_ratio);
}

/// With a jerk limit that never binds (1e9 mm/s³) the jerk-limited reference is the
/// acceleration-only one: on a line and a circle at A 1000 mm/s² within 1e-3 (the
/// cells' times: the second-order reference times each cell with its own acceleration
/// switch, this one with `x` linear over the cell).
#[test]
fn without_a_binding_jerk_it_is_the_acceleration_only_optimum() {
    let m = machine(1000.0, 1e9, 6000.0);
    for text in ["G1 X20 F6000\nM2\n", "G2 X0 Y0 I10 J0 F6000\nM2\n"] {
        let o = optimum_at(text, &m, 0.05);
        assert_rel(text.lines().next().unwrap(), o.time_s, o.acc_only_s, 1e-3);
    }
}

/// On LinuxCNC's NURBS program on the built-in machine (curves, corners; jerk 50 000
/// mm/s³): the jerk-limited optimum is above the acceleration-only one (the grid's
/// same), its profile keeps the jerk to 1e-2 (measured 0.9998 to 1.0041), and halving
/// the grid (0.25 to 0.125 mm, the feed table's, and 0.1 to 0.05 mm) changes it by less
/// than 1 % (measured 6.0e-4 and 4.3e-3).
#[test]
fn on_a_nurbs_program_it_is_above_the_acceleration_only_optimum_and_converges() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(dir.join("peers/linuxcnc/g5_nurbs-xy.ngc")).unwrap();
    let m = Machine::default();
    let grids = [0.25, 0.125, 0.1, 0.05];
    let o: Vec<JerkOptimum> = grids.iter().map(|&g| optimum_at(&text, &m, g)).collect();
    for (g, o) in grids.iter().zip(&o) {
        print!("at {g} mm ");
        println!(
            "nurbs-xy: {:.4?}",
            (
                o.time_s,
                o.acc_only_s,
                o.s.len(),
                o.rounds,
                o.last_change,
                o.jerk_ratio
            )
        );
        assert!(o.time_s >= o.acc_only_s, "{} {}", o.time_s, o.acc_only_s);
        assert!(o.jerk_ratio <= 1.0 + 1e-2, "{}", o.jerk_ratio);
    }
    for (a, b) in [(&o[0], &o[1]), (&o[2], &o[3])] {
        let rel = (a.time_s - b.time_s).abs() / b.time_s;
        println!("halving the grid: {rel:.1e}");
        assert!(rel < 1e-2, "{rel}");
    }
}

/// The known limit of the module page: a 0.2 mm move on ever finer grids (0.02, 0.01,
/// 0.004 mm). Prints the time and the profile's own jerk; asserts nothing (on 0.004 mm
/// the linearization does not settle: its jerk 2.2 × the limit).
#[test]
#[ignore = "prints the known limit of the linearization on fine grids"]
fn on_fine_grids_near_rest_the_linearization_may_not_settle() {
    let m = machine(1000.0, 50_000.0, 6000.0);
    for step in [0.02, 0.01, 0.004] {
        let o = optimum_at("G1 X0.2 F6000\nM2\n", &m, step);
        println!(
            "0.2 mm at {step} mm: {} nodes, {:.5?}",
            o.s.len(),
            (
                o.time_s,
                o.acc_only_s,
                o.rounds,
                o.last_change,
                o.jerk_ratio
            )
        );
    }
}
