//! Subroutines in files of their own, as LinuxCNC finds them: `o<name> call` where the
//! program defines no `o<name> sub` reads `name.ngc` (the name lower case, as LinuxCNC
//! makes it) from the first directory of [`super::Options::subroutine_dirs`] that has
//! one. The file holds `o<name> sub … o<name> endsub`, which may be followed by `M2` or
//! `%` (never run: the return leaves the file first). As in LinuxCNC, such a name has
//! only letters, digits, `-` and `_`.
//!
//! The files are read before the program runs and their lines joined after the
//! program's own, so the O-word flow ([`super::flow`]) runs them as it runs a subroutine
//! of the program: nesting and loop limits apply across files alike. Each file's blocks
//! are matched on their own (labels of `if`/`while`/… are local to a file, as in
//! LinuxCNC); a problem in a file is reported with that file's path and line.

use std::collections::HashMap;
use std::path::PathBuf;

use crate::parse::{flow, o_word_of, Diagnostic, Flow, OKind, OWord};

/// A subroutine file found and read.
pub(super) struct SubFile {
    /// Its path as found, which its diagnostics show.
    pub path: String,
    pub text: String,
}

/// The O-words of `lines`, the lines of `text`: `None` for a line without one (or one
/// that cannot be read: running the line reports that); an empty list for a text
/// without any. Boxed: a list of a word a line would be 56 bytes a line, nearly all of
/// them `None`, for the kernel to hand over page by page.
pub(super) fn o_words_of(text: &str, lines: &[&str], first_line: u32) -> Vec<Option<Box<OWord>>> {
    // A text without an `o` anywhere (most CAM output) has none: one pass over its
    // bytes (a fold without an early exit, which the compiler vectorises) instead of a
    // look at each line, and no list at all (the flow, the subroutine files and the
    // runner then have nothing to look through).
    if !may_have_o_words(text) {
        return Vec::new();
    }
    lines
        .iter()
        .enumerate()
        .map(|(i, raw)| {
            o_word_of(raw, first_line + i as u32)
                .unwrap_or(None)
                .map(Box::new)
        })
        .collect()
}

/// Whether `text` has an `o` or `O` anywhere, which an O-word needs: one pass over its
/// bytes (a fold without an early exit, which the compiler vectorises).
pub(super) fn may_have_o_words(text: &str) -> bool {
    text.bytes().fold(false, |o, b| o | (b | 0x20 == b'o'))
}

/// Labels called and defined nowhere, with why no file supplied them.
pub(super) type Missing = HashMap<String, String>;

/// Every subroutine file the program calls, directly or from other subroutine files,
/// and for each called label that none supplied, why.
pub(super) fn load(main: &[Option<Box<OWord>>], dirs: &[PathBuf]) -> (Vec<SubFile>, Missing) {
    let mut files = Vec::new();
    let mut missing = Missing::new();
    let defined = |o_words: &[Option<Box<OWord>>], label: &str| {
        o_words
            .iter()
            .flatten()
            .any(|o| o.kind == OKind::Sub && o.label == label)
    };
    let mut known: Vec<String> = main
        .iter()
        .flatten()
        .filter(|o| o.kind == OKind::Sub)
        .map(|o| o.label.clone())
        .collect();
    let mut wanted: Vec<String> = calls(main);
    while let Some(label) = wanted.pop() {
        if known.contains(&label) || missing.contains_key(&label) {
            continue;
        }
        // Only named subroutines have files (`o<name>`); the label keeps its `< >`.
        let Some(name) = label.strip_prefix('<').and_then(|l| l.strip_suffix('>')) else {
            continue;
        };
        let name = name.to_string();
        // LinuxCNC's rule for these names; it also keeps the lookup inside the
        // directories (no `/`, no `..`).
        if !name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
        {
            missing.insert(
                label,
                format!("no subroutine o<{name}> in this file, and a subroutine file's name has only letters, digits, `-` and `_`"),
            );
            continue;
        }
        let file_name = format!("{name}.ngc");
        let Some(path) = dirs
            .iter()
            .map(|d| d.join(&file_name))
            .find(|p| p.is_file())
        else {
            if !dirs.is_empty() {
                // The directory of a program named without one is the current one, "".
                let searched: Vec<String> = dirs
                    .iter()
                    .map(|d| {
                        if d.as_os_str().is_empty() {
                            ".".to_string()
                        } else {
                            d.display().to_string()
                        }
                    })
                    .collect();
                missing.insert(
                    label,
                    format!(
                        "no subroutine o<{name}> in this file, and no {file_name} in {}",
                        searched.join(", ")
                    ),
                );
            }
            continue;
        };
        let text = match std::fs::read(&path) {
            Ok(bytes) => String::from_utf8_lossy(&bytes).into_owned(),
            Err(e) => {
                missing.insert(label, format!("{}: {e}", path.display()));
                continue;
            }
        };
        let lines: Vec<&str> = text.lines().collect();
        let o_words = o_words_of(&text, &lines, 1);
        if !defined(&o_words, &label) {
            missing.insert(
                label,
                format!("{} does not define o<{name}> sub", path.display()),
            );
            continue;
        }
        wanted.extend(calls(&o_words));
        known.extend(
            o_words
                .iter()
                .flatten()
                .filter(|o| o.kind == OKind::Sub)
                .map(|o| o.label.clone()),
        );
        files.push(SubFile {
            path: path.display().to_string(),
            text,
        });
    }
    (files, missing)
}

fn calls(o_words: &[Option<Box<OWord>>]) -> Vec<String> {
    o_words
        .iter()
        .flatten()
        .filter(|o| o.kind == OKind::Call)
        .map(|o| o.label.clone())
        .collect()
}

/// Where each file's lines start in the joined program.
#[derive(Default)]
pub(super) struct Units {
    /// (first line index, path) of each subroutine file, in order.
    files: Vec<(usize, String)>,
}

impl Units {
    /// Joins `o_words` of a file whose lines start at index `start` to the program's
    /// `flow`; the file's own block errors go to `errors`, already located.
    pub(super) fn append(
        &mut self,
        path: &str,
        start: usize,
        o_words: &[Option<Box<OWord>>],
        joined: &mut Flow,
        errors: &mut Vec<Diagnostic>,
    ) {
        let (f, file_errors) = flow(o_words);
        errors.extend(file_errors.into_iter().map(|mut d| {
            d.file = Some(path.to_string());
            d
        }));
        // The lists of a program (or file) without O-words are empty: filled up to the
        // file's first line, so that its links stand at its lines.
        joined.link.resize(start, None);
        joined.closes_do.resize(start, false);
        joined
            .link
            .extend(f.link.into_iter().map(|l| l.map(|i| i + start)));
        joined.closes_do.extend(f.closes_do);
        for (label, at) in f.subs {
            joined.subs.entry(label).or_insert(at + start);
        }
        self.files.push((start, path.to_string()));
    }

    /// Moves a diagnostic of the joined program (its line counted from the program's
    /// first) to its file and the line within it.
    pub(super) fn locate(&self, d: &mut Diagnostic) {
        if d.file.is_some() {
            return;
        }
        let index = d.line.saturating_sub(1) as usize;
        if let Some((start, path)) = self.files.iter().rev().find(|(s, _)| *s <= index) {
            d.file = Some(path.clone());
            d.line -= *start as u32;
        }
    }
}
