//! `cnc machine --from-ini` on LinuxCNC's own sample configurations
//! (`tests/data/linuxcnc-ini/`, from its `configs/sim/axis/`): each becomes a machine
//! file this control loads, with the limits the INI gives in mm, and the keys with no
//! counterpart warned about.

use shared::machine::Machine;
use shared::machine_ini::{from_ini, FromIni};
use std::path::Path;

fn read(name: &str) -> FromIni {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/linuxcnc-ini");
    let text = std::fs::read_to_string(dir.join(name)).unwrap();
    let include = |n: &str| std::fs::read_to_string(dir.join(n)).map_err(|e| e.to_string());
    let f = from_ini(&text, name, &include).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(
        Machine::from_toml(&f.toml).as_ref(),
        Ok(&f.machine),
        "{name}"
    );
    f
}

/// `axis_mm.ini`: the metric simulated mill (30.48 mm/s and 508 mm/s² per axis, a
/// 53.34 mm/s path, Z from -50.8 to 101.6 mm, FERROR 1.27 mm, 1 ms servo period).
#[test]
fn axis_mm() {
    let f = read("axis_mm.ini");
    let m = &f.machine;
    assert_eq!(m.max_feed_mm_per_min, 53.34 * 60.0);
    assert_eq!(m.path_acc_mm_per_s2, 508.0);
    assert_eq!(m.min_period_us, 1000);
    assert_eq!(m.max_following_error_mm, 1.27);
    for a in m.axes.as_array() {
        assert_eq!((a.max_vel_mm_per_min, a.max_acc_mm_per_s2), (1828.8, 508.0));
        assert_eq!(a.max_jerk_mm_per_s3, 508_000.0);
    }
    assert_eq!((m.axes.z.min_mm, m.axes.z.max_mm), (-50.8, 101.6));
    assert!(f
        .warnings
        .iter()
        .any(|w| w.contains("[JOINT_0]MIN_FERROR = .254")));
    assert!(f.warnings.iter().any(|w| w.contains("[DISPLAY]: ")));
}

/// `axis.ini`: the same mill in inches (5 in/s path, 100 in/s², Z up to 0.12 in).
#[test]
fn axis_inch() {
    let m = read("axis.ini").machine;
    assert_eq!(m.max_feed_mm_per_min, 7620.0);
    assert_eq!(m.path_acc_mm_per_s2, 2540.0);
    assert_eq!(m.axes.z.max_mm, 3.048);
}

/// `gantry_mm.ini`: Y driven by joints 1 and 2 (`coordinates=xyyz`), the axis slower
/// than its joints: the axis's limits hold.
#[test]
fn gantry() {
    let m = read("gantry_mm.ini").machine;
    assert_eq!(m.axes.y.max_vel_mm_per_min, 1800.0);
    assert_eq!(m.axes.y.max_acc_mm_per_s2, 200.0);
    assert_eq!((m.axes.y.min_mm, m.axes.y.max_mm), (0.0, 2000.0));
}

/// `corexy_by_kins.ini`: its limits in an `#INCLUDE`d file, and kinematics whose joints
/// are not axes (warned; the axes' own limits read).
#[test]
fn corexy_with_an_include() {
    let f = read("corexy_by_kins.ini");
    assert!(f
        .warnings
        .iter()
        .any(|w| w.contains("corexykins: not trivkins")));
    assert_eq!(f.machine.axes.x.max_vel_mm_per_min, 3048.0);
    assert_eq!(f.machine.min_period_us, 1000);
}
