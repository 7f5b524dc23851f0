//! The LinuxCNC compatibility suite (programs from LinuxCNC's distribution, unchanged):
//! every one checks clean, runs to done through the real processes and replays from its
//! command log to the same set-points and feedback, all on the simulated clock so the
//! suite takes seconds, not the half hour of machining it describes.

use std::path::Path;
use std::process::Command;
use tests::{cnc_exe, csv, report, temp_dir};

/// `g5_curva_stella.ngc` opens its NURBS with `G2.2`, a G-code that does not exist (the
/// `G5.3` on line 31 closes a `G5.2` that was meant). A control must refuse it; we do,
/// before any motion, naming the line.
const BROKEN: &[(&str, &str)] = &[("g5_curva_stella.ngc", ":12:1: modal: G2.2 is not supported")];

#[test]
fn every_linuxcnc_program_checks_clean_and_runs() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("peers/linuxcnc");
    let mut programs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ngc"))
        .collect();
    programs.sort();
    assert_eq!(programs.len(), 29);
    let runs = temp_dir("peers");
    let mut failures = Vec::new();
    for prog in &programs {
        let name = prog.file_name().unwrap().to_string_lossy().to_string();
        let check = Command::new(cnc_exe())
            .arg("check")
            .arg(prog)
            .output()
            .unwrap();
        if let Some((_, msg)) = BROKEN.iter().find(|(n, _)| *n == name) {
            let err = String::from_utf8_lossy(&check.stderr);
            assert_eq!(check.status.code(), Some(1), "{name} must be refused");
            assert!(err.contains(msg), "{name}: {err}");
            continue;
        }
        if !check.status.success() {
            failures.push(format!(
                "{name}: check: {}",
                String::from_utf8_lossy(&check.stderr)
            ));
            continue;
        }
        let out = runs.join(&name);
        let run = Command::new(cnc_exe())
            .args(["run", "--clock", "sim", "--no-report", "--out"])
            .arg(&out)
            .arg(prog)
            .output()
            .unwrap();
        let rep = report(&out);
        if !run.status.success() || rep["outcome"] != "done" {
            failures.push(format!(
                "{name}: run: {} {}",
                rep["fault"],
                String::from_utf8_lossy(&run.stderr)
            ));
            continue;
        }
        // Ran to rest, and the drives answered every cycle.
        let (_, sp) = csv(&out.join("setpoints.csv"));
        let (_, fb) = csv(&out.join("feedback.csv"));
        assert_eq!(sp.len(), fb.len(), "{name}");
        assert_eq!(rep["lost_setpoints"], 0, "{name}");
        // The command log replays to the very same set-points and feedback.
        let again = runs.join(format!("{name}.replay"));
        let replay = Command::new(cnc_exe())
            .args(["replay", "--clock", "sim", "--no-report", "--out"])
            .arg(&again)
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            replay.status.success(),
            "{name}: replay: {}",
            String::from_utf8_lossy(&replay.stderr)
        );
        for f in ["setpoints.csv", "feedback.csv"] {
            let same = std::fs::read(out.join(f)).unwrap() == std::fs::read(again.join(f)).unwrap();
            assert!(same, "{name}: replayed {f} differs");
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    let _ = std::fs::remove_dir_all(&runs);
}
