//! The run directory a `cnc run` or `cnc replay` writes: created when missing, refused
//! when it already holds something, so a new run never mixes its files with an older
//! one's (a stale `report.html` beside new traces) nor overwrites a run someone kept.
//!
//! `--force` lets a run reuse a directory: the files a run writes (the [`RUN_FILES`]) are
//! removed first, so none of the old run's is left beside the new one; anything else in
//! the directory is the user's and stays where it is (a `--force` onto the wrong
//! directory must never delete what no run wrote).

use std::path::Path;

/// Every file a run writes into its directory.
pub const RUN_FILES: &[&str] = &[
    "report.json",
    "report.html",
    "setpoints.csv",
    "feedback.csv",
    "commands.log",
    "deadline-misses.json",
    "deadline-misses.txt",
    "program.ngc",
    "machine.toml",
    "interpreter.json",
    "interpolator.json",
    "servo.json",
];

/// Makes `dir` ready for a new run: creates it if missing; if it exists and holds
/// anything, refuses (naming what is there) unless `force`, which removes the old run's
/// files and keeps everything else.
pub fn prepare(dir: &Path, force: bool) -> Result<(), String> {
    let shown = dir.display();
    if dir.exists() && !dir.is_dir() {
        return Err(format!("--out {shown}: exists and is not a directory"));
    }
    if !dir.exists() {
        return std::fs::create_dir_all(dir).map_err(|e| format!("--out {shown}: {e}"));
    }
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map_err(|e| format!("--out {shown}: {e}"))?
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    if names.is_empty() {
        return Ok(());
    }
    names.sort();
    if !force {
        let listed = names.iter().take(4).cloned().collect::<Vec<_>>().join(", ");
        let more = if names.len() > 4 {
            format!(" and {} more", names.len() - 4)
        } else {
            String::new()
        };
        return Err(format!(
            "--out {shown}: the directory is not empty (it holds {listed}{more}); a new run \
             there would overwrite an earlier run's files or leave stale ones beside its own. \
             Choose another --out (or none: runs/<UTC time>/), or pass --force to replace \
             the earlier run's files (other files are kept)"
        ));
    }
    for name in RUN_FILES {
        let path = dir.join(name);
        if path.is_file() {
            std::fs::remove_file(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("cnc-rundir-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_missing_or_empty_directory_is_used() {
        let dir = scratch("missing").join("a/b");
        prepare(&dir, false).unwrap();
        assert!(dir.is_dir());
        prepare(&dir, false).unwrap();
        let _ = std::fs::remove_dir_all(dir.parent().unwrap().parent().unwrap());
    }

    #[test]
    fn a_directory_holding_a_run_is_refused_without_force() {
        let dir = scratch("full");
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("report.html"), "old").unwrap();
        let e = prepare(&dir, false).unwrap_err();
        assert!(e.contains("not empty") && e.contains("report.html") && e.contains("--force"));
        assert!(
            dir.join("report.html").exists(),
            "nothing removed without --force"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn force_removes_the_old_runs_files_and_keeps_the_users() {
        let dir = scratch("force");
        std::fs::create_dir_all(&dir).unwrap();
        for f in RUN_FILES {
            std::fs::write(dir.join(f), "old").unwrap();
        }
        std::fs::write(dir.join("notes.txt"), "mine").unwrap();
        prepare(&dir, true).unwrap();
        for f in RUN_FILES {
            assert!(!dir.join(f).exists(), "{f} left behind");
        }
        assert_eq!(
            std::fs::read_to_string(dir.join("notes.txt")).unwrap(),
            "mine"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_file_is_not_a_run_directory() {
        let dir = scratch("file");
        std::fs::write(&dir, "x").unwrap();
        assert!(prepare(&dir, true).unwrap_err().contains("not a directory"));
        let _ = std::fs::remove_file(&dir);
    }
}
