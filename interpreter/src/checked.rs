//! The launcher's check of a program, handed to the interpreter process (`cnc run`).
//!
//! `cnc run` checks the whole program before any process starts (nothing moves before
//! a program is known good), then starts the interpreter process on the run
//! directory's copy of it. That process used to check its copy again before planning
//! the first window: on ten million lines about 3 s more before the first set-point,
//! on 50 000 lines of curves about 20 s.
//!
//! Now the launcher writes what its check found (`checked.json` in the run directory,
//! [`Checked`]) with the digest of the bytes it checked, and the interpreter process
//! takes it instead of checking again, but only where that holds for its own reading:
//!
//! * its copy of the program has the same digest (XXH3, 64 bits, over every byte: any
//!   change to the copy between the two readings shows; the digest guards against
//!   accidents, not against someone forging a copy, who could as well forge the check);
//! * it runs under the same machine (the machine's hash, [`shared::Machine::hash`]) and
//!   the same period, which the check planned for;
//! * the check read no subroutine file and had no tool table: both are files beside the
//!   program that could change in between. Where a program calls no file the
//!   interpreter reads it with no subroutine directory at all, so a file that appears
//!   in between is never read either.
//!
//! Anything else (no record, a record that cannot be read, a different digest, machine
//! or period) and the interpreter checks its copy itself, as before, and says why in
//! its log. The streaming reading still validates every block of every window before it
//! is sent ([`crate::window`]): a copy the record does not describe could only stop the
//! machine at the end of the last good window, never move it wrongly.

use crate::window::Planned;
use serde::{Deserialize, Serialize};
use shared::Machine;
use std::path::Path;

/// The file the launcher writes in the run directory.
pub const FILE: &str = "checked.json";

/// How much of a text is digested between two calls to `release` ([`digest`]).
const STRETCH: usize = 4 << 20;

/// What the launcher's check found, and what it checked.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Checked {
    /// XXH3-64 of the program's bytes, 16 hex digits.
    pub digest: String,
    /// The machine it was checked for ([`shared::Machine::hash`]).
    pub machine_hash: u64,
    pub period_ns: u64,
    /// The dialect it was read in.
    pub dialect: String,
    pub messages: Vec<(u32, String)>,
    pub notes: Vec<(u32, String)>,
    pub compensated: bool,
    pub blocks: usize,
    pub windows: usize,
    pub windows_at_speed: usize,
    pub rough_seams: usize,
    /// ([`Planned::short_windows`]; absent in records older than it.)
    #[serde(default)]
    pub short_windows: usize,
}

/// The digest of `bytes` (see the module page), `release` told of each stretch of them
/// done with.
pub fn digest(bytes: &[u8], release: &mut dyn FnMut(usize, usize)) -> u64 {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    for (k, chunk) in bytes.chunks(STRETCH).enumerate() {
        h.update(chunk);
        release(k * STRETCH, k * STRETCH + chunk.len());
    }
    h.digest()
}

/// The digest of a program's text: `mapped`'s (its pages given back behind) where the
/// file is mapped, else `text`'s.
pub(crate) fn digest_of(mapped: Option<&crate::mapped::MappedText>, text: &str) -> u64 {
    mapped.map_or_else(|| digest(text.as_bytes(), &mut |_, _| {}), |m| m.digest())
}

fn hex(digest: u64) -> String {
    format!("{digest:016x}")
}

impl Checked {
    /// The record of a check that found the program good (`planned`), of a text of
    /// `digest`; `None` where the interpreter could not take it: the check read
    /// subroutine files or a tool table (`tools`).
    pub fn of(
        planned: &Planned,
        digest: u64,
        tools: bool,
        machine: &Machine,
        period_ns: u64,
    ) -> Option<Checked> {
        (planned.subroutine_files == 0 && !tools).then(|| Checked {
            digest: hex(digest),
            machine_hash: machine.hash(),
            period_ns,
            dialect: planned.dialect.name().to_string(),
            messages: planned.messages.clone(),
            notes: planned.notes.clone(),
            compensated: planned.compensated,
            blocks: planned.blocks,
            windows: planned.windows,
            windows_at_speed: planned.at_speed,
            rough_seams: planned.rough_seams,
            short_windows: planned.short_windows,
        })
    }

    pub fn write(&self, path: &Path) -> Result<(), String> {
        let text = serde_json::to_string_pretty(self).map_err(|e| e.to_string())?;
        std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
    }

    pub fn read(path: &Path) -> Result<Checked, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The check's findings for a reading of a text of `digest` under `machine` and
    /// `period_ns`, or why they are not its (then the reader checks for itself).
    pub fn planned_for(
        &self,
        digest: u64,
        machine: &Machine,
        period_ns: u64,
    ) -> Result<Planned, String> {
        if self.digest != hex(digest) {
            return Err(format!(
                "the program's copy (digest {}) is not the text the launcher checked (digest {})",
                hex(digest),
                self.digest
            ));
        }
        if self.machine_hash != machine.hash() {
            return Err(format!(
                "the machine (hash {:016x}) is not the one the launcher checked for ({:016x})",
                machine.hash(),
                self.machine_hash
            ));
        }
        if self.period_ns != period_ns {
            return Err(format!(
                "the period ({period_ns} ns) is not the one the launcher checked for ({} ns)",
                self.period_ns
            ));
        }
        Ok(Planned {
            dialect: self.dialect.parse()?,
            messages: self.messages.clone(),
            compensated: self.compensated,
            blocks: self.blocks,
            notes: self.notes.clone(),
            windows: self.windows,
            at_speed: self.windows_at_speed,
            rough_seams: self.rough_seams,
            short_windows: self.short_windows,
            subroutine_files: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::process::check_windows;

    const PROGRAM: &str = "(MSG, start)\nG21 G90 G17\nG1 X10 Y0 F600\nG5.2 X20 Y10 P1\nX30 Y0 P1\nX40 Y10 P1\nG5.3\nG1 X0 Y0 F90000\nM2\n";

    fn planned(text: &str, machine: &Machine) -> Planned {
        let opts = crate::program::Options::default();
        check_windows(
            text,
            &opts,
            machine,
            1_000_000,
            &mut |_, _| {},
            &mut |_, _| {},
        )
        .expect("a good program")
    }

    #[test]
    fn the_check_is_taken_for_the_same_text_machine_and_period_only() {
        let machine = Machine::default();
        let p = planned(PROGRAM, &machine);
        let d = digest(PROGRAM.as_bytes(), &mut |_, _| {});
        let c = Checked::of(&p, d, false, &machine, 1_000_000).expect("no files read");
        // Through the file, as the processes hand it on.
        let dir = std::env::temp_dir().join(format!("checked-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        c.write(&dir.join(FILE)).unwrap();
        let c = Checked::read(&dir.join(FILE)).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        let taken = c
            .planned_for(d, &machine, 1_000_000)
            .expect("the same reading");
        assert_eq!(taken.dialect, p.dialect);
        assert_eq!(taken.messages, vec![(1, "start".to_string())]);
        assert_eq!(
            (
                taken.notes.clone(),
                taken.blocks,
                taken.windows,
                taken.at_speed
            ),
            (p.notes.clone(), p.blocks, p.windows, p.at_speed)
        );
        assert!(
            !taken.notes.is_empty(),
            "F90000 is above the built-in machine's feed"
        );
        // One character changed (a digit of a coordinate): the copy is not what was checked.
        let changed = PROGRAM.replace("X30", "X31");
        let why = c
            .planned_for(
                digest(changed.as_bytes(), &mut |_, _| {}),
                &machine,
                1_000_000,
            )
            .unwrap_err();
        assert!(why.contains("not the text the launcher checked"), "{why}");
        let mut other = machine.clone();
        other.path_acc_mm_per_s2 *= 2.0;
        let why = c.planned_for(d, &other, 1_000_000).unwrap_err();
        assert!(why.contains("machine"), "{why}");
        let why = c.planned_for(d, &machine, 500_000).unwrap_err();
        assert!(why.contains("period"), "{why}");
        // A tool table, or a subroutine file read: no record to take.
        assert!(Checked::of(&p, d, true, &machine, 1_000_000).is_none());
        let with_file = Planned {
            subroutine_files: 1,
            ..p
        };
        assert!(Checked::of(&with_file, d, false, &machine, 1_000_000).is_none());
    }

    #[test]
    fn the_digest_is_of_every_byte_and_tells_of_each_stretch_done() {
        let text = vec![b'G'; 2 * STRETCH + 17];
        let mut told = Vec::new();
        let d = digest(&text, &mut |a, b| told.push((a, b)));
        assert_eq!(
            told,
            vec![
                (0, STRETCH),
                (STRETCH, 2 * STRETCH),
                (2 * STRETCH, 2 * STRETCH + 17)
            ]
        );
        assert_eq!(d, xxhash_rust::xxh3::xxh3_64(&text));
        let mut last_changed = text.clone();
        *last_changed.last_mut().unwrap() = b'H';
        assert_ne!(d, digest(&last_changed, &mut |_, _| {}));
    }
}
