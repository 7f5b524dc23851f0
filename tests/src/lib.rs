//! Helpers for the end-to-end tests: finding (or building) the `cnc` executable, fresh
//! run directories, and reading what a run leaves behind; and the feed table's
//! time-optimal reference ([`topp`]) and measurements ([`feed`]).

pub mod feed;
pub mod topp;
pub mod topp3;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

/// The `cnc` executable of this build, built first if needed. `CARGO_BIN_EXE_cnc` exists
/// only for tests of the package that owns the binary, so this asks Cargo (a no-op when
/// it is up to date) and takes the file from the target directory of this test binary.
///
/// `CNC_EXE=/path/to/cnc` runs the tests against another build instead (to check that a
/// test fails on an older one).
pub fn cnc_exe() -> PathBuf {
    static EXE: OnceLock<PathBuf> = OnceLock::new();
    EXE.get_or_init(|| {
        if let Some(exe) = std::env::var_os("CNC_EXE") {
            return PathBuf::from(exe);
        }
        let me = std::env::current_exe().expect("test executable path");
        // target/<profile>/deps/<test> -> target/<profile>
        let profile_dir = me
            .parent()
            .and_then(Path::parent)
            .expect("target profile dir")
            .to_path_buf();
        let release = profile_dir.file_name().is_some_and(|n| n == "release");
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.args(["build", "--quiet", "-p", "interpreter", "--bin", "cnc"]);
        if release {
            cmd.arg("--release");
        }
        let status = cmd
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .status()
            .expect("running cargo build");
        assert!(status.success(), "cargo build --bin cnc failed");
        let exe = profile_dir.join("cnc");
        assert!(exe.exists(), "{} not found after building", exe.display());
        exe
    })
    .clone()
}

/// A fresh, empty directory for one test.
pub fn temp_dir(tag: &str) -> PathBuf {
    static COUNTER: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("cnc-test-{tag}-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("creating a temp dir");
    dir
}

/// `report.json` of a run directory.
pub fn report(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("report.json")).expect("report.json");
    serde_json::from_str(&text).expect("report.json is JSON")
}

/// A CSV file as its header and rows of numbers.
pub fn csv(path: &Path) -> (String, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = lines.next().unwrap_or_default().to_string();
    let rows = lines
        .map(|l| {
            l.split(',')
                .map(|v| v.parse::<f64>().expect("a number"))
                .collect()
        })
        .collect();
    (header, rows)
}

/// Largest distance of the set-points of a circle from it, and the largest sagitta of the
/// chords between consecutive set-points, both in mm. `rows` are `setpoints.csv` rows.
pub fn circle_errors(rows: &[&Vec<f64>], center: [f64; 2], r: f64) -> (f64, f64) {
    let mut radial = 0.0f64;
    let mut sagitta = 0.0f64;
    for (i, row) in rows.iter().enumerate() {
        let (x, y) = (row[2] - center[0], row[3] - center[1]);
        radial = radial.max(((x * x + y * y).sqrt() - r).abs());
        if let Some(next) = rows.get(i + 1) {
            let s = ((next[2] - row[2]).powi(2) + (next[3] - row[3]).powi(2)).sqrt();
            sagitta = sagitta.max(r - (r * r - s * s / 4.0).max(0.0).sqrt());
        }
    }
    (radial, sagitta)
}

/// The `cnc role …` processes a `cnc run` (pid `launcher`) has started, as (role, pid),
/// read from /proc (the launcher's children and their command lines).
pub fn role_pids(launcher: u32) -> Vec<(String, u32)> {
    let children = std::fs::read_to_string(format!("/proc/{launcher}/task/{launcher}/children"))
        .unwrap_or_default();
    children
        .split_whitespace()
        .filter_map(|p| p.parse::<u32>().ok())
        .filter_map(|pid| {
            let cmd = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
            let args: Vec<String> = cmd
                .split(|b| *b == 0)
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect();
            let i = args.iter().position(|a| a == "role")?;
            Some((args.get(i + 1)?.clone(), pid))
        })
        .collect()
}

/// Polls `ready` every 5 ms until it holds; panics with `what` after `timeout`.
pub fn wait_until(what: &str, timeout: std::time::Duration, mut ready: impl FnMut() -> bool) {
    let t = std::time::Instant::now();
    while !ready() {
        assert!(t.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// Lines of a CSV file that ends with a newline and whose every line has the header's
/// number of fields: nothing half-written. Returns the data rows.
pub fn complete_csv(path: &Path) -> Vec<Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    assert!(
        text.ends_with('\n'),
        "{}: last line incomplete",
        path.display()
    );
    let mut lines = text.lines();
    let fields = lines.next().expect("a header").split(',').count();
    lines
        .enumerate()
        .map(|(i, l)| {
            let row: Vec<f64> = l
                .split(',')
                .map(|v| {
                    v.parse::<f64>()
                        .unwrap_or_else(|_| panic!("{}:{}: `{l}`", path.display(), i + 2))
                })
                .collect();
            assert_eq!(row.len(), fields, "{}:{}: `{l}`", path.display(), i + 2);
            row
        })
        .collect()
}

/// Whether the process `pid` has ended (gone, or a zombie waiting to be reaped).
pub fn process_ended(pid: u32) -> bool {
    match std::fs::read_to_string(format!("/proc/{pid}/stat")) {
        Err(_) => true,
        Ok(stat) => stat
            .rfind(')')
            .and_then(|i| stat[i + 1..].split_whitespace().next())
            .is_none_or(|state| state == "Z" || state == "X"),
    }
}

/// Sends `signal` to `pid`; panics if that fails.
pub fn signal(pid: u32, signal: i32) {
    // SAFETY: kill(2) on a process the test started (or one of its children).
    assert_eq!(
        unsafe { libc::kill(pid as libc::pid_t, signal) },
        0,
        "kill({pid}, {signal})"
    );
}

/// A valid command block: the 10 mm line from the origin along X at F3000 (the built-in
/// machine's path acceleration and jerk), block `seq` of source line `source_line`, from
/// rest to rest. Tests spoil or extend it field by field.
pub fn line_block(seq: u64, source_line: u32) -> shared::protocol::CommandBlock {
    use shared::protocol::{BlockKind, CommandBlock};
    let mut b = CommandBlock::empty(BlockKind::Motion, seq, source_line);
    b.degree = 1;
    b.n_ctrl = 2;
    b.knots[..4].copy_from_slice(&[0.0, 0.0, 1.0, 1.0]);
    b.ctrl[0] = [0.0, 0.0, 0.0, 1.0];
    b.ctrl[1] = [10.0, 0.0, 0.0, 1.0];
    b.feed_mm_per_min = 3000.0;
    b.length_mm = 10.0;
    b.acc_mm_per_s2 = 2000.0;
    b.jerk_mm_per_s3 = 50_000.0;
    b
}

/// Path speed per cycle (mm per cycle) from set-point rows.
pub fn steps(rows: &[Vec<f64>]) -> Vec<f64> {
    rows.windows(2)
        .map(|w| ((w[1][2] - w[0][2]).powi(2) + (w[1][3] - w[0][3]).powi(2)).sqrt())
        .collect()
}

/// The set-points from the cycle the stop began to the end: on the diagonal, moving at
/// first, then slowing every cycle down to standing still.
pub fn assert_decelerated_on_the_diagonal(sp: &[Vec<f64>], info: &serde_json::Value) {
    let from = info["stop_from_cycle"].as_u64().unwrap() as usize;
    let to = info["stopped_cycle"].as_u64().unwrap() as usize;
    assert_eq!(
        to + 1,
        sp.len(),
        "the stop's last cycle is the last set-point"
    );
    assert!(
        info["speed_at_fault_mm_per_min"].as_f64().unwrap() > 100.0,
        "moving when the fault or stop came: {info}"
    );
    let tail = &sp[from.saturating_sub(1)..];
    for r in tail {
        assert!(
            (r[3] - 0.75 * r[2]).abs() < 1e-9,
            "set-point off the path: {r:?}"
        );
    }
    let d = steps(tail);
    assert!(
        d.len() > 3,
        "a controlled stop takes cycles, not an instant hold: {d:?}"
    );
    assert!(d[0] > 0.0);
    for w in d.windows(2) {
        assert!(w[1] <= w[0] + 1e-12, "speed rose during the stop: {w:?}");
    }
    // The jerk-limited stop ends inside a cycle: the last step is what is left of it.
    assert!(*d.last().unwrap() < 1e-3, "ends standing still: {d:?}");
}

/// `cnc check --estimate --json PROGRAM`'s answer, the command having succeeded.
pub fn estimate_json(program: &Path) -> serde_json::Value {
    let out = Command::new(cnc_exe())
        .args(["check", "--estimate", "--json"])
        .arg(program)
        .output()
        .expect("running cnc check");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("the estimate as JSON")
}
