//! Issue #22, the operator's side of a run that the other safety tests leave out: the
//! run directory is never silently overwritten, and a root run never locks other users
//! out of the stack. (Blocks the interpolator refuses: `safety_blocks.rs`; the launcher,
//! signals and faults: `safety_supervisor.rs`; a salvaged replay's outcome:
//! `processes.rs`.)

use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Output};
use tests::{cnc_exe, report, temp_dir};

fn run_sim(prog: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new(cnc_exe())
        .args(["run", "--clock", "sim"])
        .args(extra)
        .arg("--out")
        .arg(out)
        .arg(prog)
        .output()
        .unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `--out` onto a directory that holds an earlier run is refused before anything runs,
/// and nothing there is touched; `--force` replaces the earlier run's files, so a stale
/// `report.html` never stays beside the new run's data under `--no-report`.
#[test]
fn a_run_never_silently_overwrites_an_earlier_run_directory() {
    let dir = temp_dir("out-reuse");
    let prog = dir.join("line.ngc");
    std::fs::write(&prog, "G1 X5 F3000\nM2\n").unwrap();
    let out = dir.join("run");
    let first = run_sim(&prog, &out, &[]);
    assert!(first.status.success(), "{}", text(&first));
    assert!(out.join("report.html").exists());
    let before = std::fs::read(out.join("setpoints.csv")).unwrap();

    let other = dir.join("other.ngc");
    std::fs::write(&other, "G1 X9 F3000\nM2\n").unwrap();
    let again = run_sim(&other, &out, &["--no-report"]);
    assert_eq!(again.status.code(), Some(1), "{}", text(&again));
    let msg = String::from_utf8_lossy(&again.stderr);
    assert!(
        msg.contains("not empty") && msg.contains("--force"),
        "says why and what to do: {msg}"
    );
    assert_eq!(
        std::fs::read(out.join("setpoints.csv")).unwrap(),
        before,
        "the earlier run is left as it was"
    );

    std::fs::write(out.join("my-notes.txt"), "keep").unwrap();
    let forced = run_sim(&other, &out, &["--no-report", "--force"]);
    assert!(forced.status.success(), "{}", text(&forced));
    assert!(
        !out.join("report.html").exists(),
        "the earlier run's report.html is not left beside the new data"
    );
    assert_ne!(std::fs::read(out.join("setpoints.csv")).unwrap(), before);
    assert_eq!(
        std::fs::read_to_string(out.join("program.ngc")).unwrap(),
        "G1 X9 F3000\nM2\n"
    );
    assert_eq!(report(&out)["outcome"], "done");
    assert_eq!(
        std::fs::read_to_string(out.join("my-notes.txt")).unwrap(),
        "keep",
        "files no run writes are the user's"
    );

    // A replay is held to the same rule, and never into the run it reads.
    let replay = |to: &Path, force: bool| {
        let mut c = Command::new(cnc_exe());
        c.args(["replay", "--clock", "sim", "--no-report", "--out"])
            .arg(to)
            .arg(&out);
        if force {
            c.arg("--force");
        }
        c.output().unwrap()
    };
    let into_source = replay(&out, true);
    assert_eq!(into_source.status.code(), Some(1), "{}", text(&into_source));
    assert!(
        String::from_utf8_lossy(&into_source.stderr).contains("being replayed"),
        "{}",
        text(&into_source)
    );
    assert!(out.join("commands.log").exists());
    let copy = dir.join("replayed");
    assert!(replay(&copy, false).status.success());
    assert_eq!(replay(&copy, false).status.code(), Some(1));
    let _ = std::fs::remove_dir_all(&dir);
}

/// iceoryx2 creates its root directory 0750 for the first user; a root run used to lock
/// every other user out ("creating node: InternalError"). Each user now has a root of
/// their own. Needs root (to run as `nobody` after a root run); skipped with a reason
/// otherwise.
#[test]
fn a_root_run_does_not_lock_other_users_out() {
    // SAFETY: geteuid(2) cannot fail.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipped: needs root, to run the stack as another user after a root run");
        return;
    }
    let (uid, gid) = (65_534, 65_534); // nobody, nogroup
    let dir = temp_dir("users");
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).unwrap();
    let prog = dir.join("line.ngc");
    std::fs::write(&prog, "G1 X5 F3000\nM2\n").unwrap();
    std::fs::set_permissions(&prog, std::fs::Permissions::from_mode(0o644)).unwrap();
    // The test binary's own path must be reachable by that user, or nothing can be said.
    let probe = Command::new(cnc_exe())
        .arg("--version")
        .uid(uid)
        .gid(gid)
        .output();
    if !probe.as_ref().is_ok_and(|o| o.status.success()) {
        eprintln!(
            "skipped: {} cannot be run by uid {uid} ({probe:?})",
            cnc_exe().display()
        );
        return;
    }
    let as_root = run_sim(&prog, &dir.join("root"), &["--no-report"]);
    assert!(as_root.status.success(), "{}", text(&as_root));
    let as_nobody = Command::new(cnc_exe())
        .args(["run", "--clock", "sim", "--no-report", "--out"])
        .arg(dir.join("nobody"))
        .arg(&prog)
        .env("HOME", &dir)
        .uid(uid)
        .gid(gid)
        .output()
        .unwrap();
    assert!(
        as_nobody.status.success(),
        "another user's run after a root run: {}",
        text(&as_nobody)
    );
    assert_eq!(report(&dir.join("nobody"))["outcome"], "done");
    // And root again, after the other user (their files must not block root either).
    let again = run_sim(&prog, &dir.join("root-again"), &["--no-report"]);
    assert!(again.status.success(), "{}", text(&again));
    let _ = std::fs::remove_dir_all(&dir);
}
