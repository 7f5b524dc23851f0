//! Which control a program was written for. RS274/NGC is common ground; the curves are
//! not, and a few codes mean different things:
//!
//! | code | LinuxCNC | Fanuc |
//! |---|---|---|
//! | `G5` | cubic spline (`I J P Q`) | `G05 P10000`/`P0`: high-precision contour control on/off |
//! | `G5.1` | quadratic spline (`I J`) | `G05.1 Q1`/`Q0`: AI contour control on/off |
//! | `G5.2`, `G5.3` | NURBS, clamped uniform knots | — |
//! | `G6.2` | NURBS with `P` order, `K` knots, `R` weights and a method `Q` | `G06.2` NURBS: `P` rank, `K`, `R`, no `Q` |
//!
//! The first of these codes in a program fixes its dialect (a `G6.2` with `Q` is
//! LinuxCNC's, without `Q` Fanuc's; a `G5` with `P` and none of `X Y I J Q` is Fanuc's
//! `G05 P…`); a later code of the other dialect is an error that names both lines. A
//! program with none of them is plain RS274/NGC and reads as LinuxCNC. The caller may
//! force a dialect instead (`--dialect`); codes of the other one are then errors.

use crate::parse::Diagnostic;

/// An NC dialect: whose codes a program uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Dialect {
    /// RS274/NGC as LinuxCNC reads it, with its `G5`…`G6.2` curves.
    #[default]
    LinuxCnc,
    /// Fanuc 0i/30i-style programs with `G06.2` NURBS and `G05 P10000`.
    Fanuc,
}

impl Dialect {
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Dialect::LinuxCnc => "linuxcnc",
            Dialect::Fanuc => "fanuc",
        }
    }
}

impl core::fmt::Display for Dialect {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl core::str::FromStr for Dialect {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "linuxcnc" => Ok(Dialect::LinuxCnc),
            "fanuc" => Ok(Dialect::Fanuc),
            other => Err(format!(
                "unknown dialect `{other}`: expected linuxcnc or fanuc"
            )),
        }
    }
}

/// What a program may ask of a dialect beyond its own control, named on the command line
/// (`--dialect-extension NAME`, given once for each): a code the dialect's control
/// refuses and this one can do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Extension {
    /// `g06.2-comp`: Fanuc's `G06.2` under cutter radius compensation (`G41`/`G42`) is
    /// offset as LinuxCNC's NURBS moves are (the fitted offset, see
    /// `program/comp.rs`), instead of alarm PS1006, which a Fanuc control gives and
    /// which a Fanuc user therefore gets without it.
    FanucNurbsComp,
}

impl Extension {
    /// Every extension, in the order `--help` lists them.
    pub const ALL: [Extension; 1] = [Extension::FanucNurbsComp];

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Extension::FanucNurbsComp => "g06.2-comp",
        }
    }
}

impl core::fmt::Display for Extension {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl core::str::FromStr for Extension {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let s = s.to_ascii_lowercase();
        Extension::ALL
            .into_iter()
            .find(|e| e.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Extension::ALL.iter().map(|e| e.name()).collect();
                format!(
                    "unknown dialect extension `{s}`: expected {}",
                    names.join(", ")
                )
            })
    }
}

/// The dialect as a program is read: forced, or found at a line by a code.
#[derive(Debug, Clone, Copy)]
pub(super) struct DialectState {
    forced: Option<Dialect>,
    found: Option<(Dialect, u32, &'static str)>,
}

impl DialectState {
    pub(super) fn new(forced: Option<Dialect>) -> Self {
        DialectState {
            forced,
            found: None,
        }
    }

    /// The dialect the caller forced, if any.
    pub(super) fn forced(&self) -> Option<Dialect> {
        self.forced
    }

    /// The dialect in force so far, if any.
    pub(super) fn known(&self) -> Option<Dialect> {
        self.forced.or(self.found.map(|f| f.0))
    }

    /// What the program was read as in the end.
    pub(super) fn resolved(&self) -> Dialect {
        self.known().unwrap_or_default()
    }

    /// Records that line `line` uses `what`, a code of dialect `d`; an error when the
    /// program is already another dialect's.
    pub(super) fn claim(
        &mut self,
        d: Dialect,
        line: u32,
        col: u32,
        what: &'static str,
    ) -> Result<(), Diagnostic> {
        let err = |message: String| Diagnostic {
            file: None,
            line,
            col,
            rule: "dialect",
            message,
        };
        if let Some(forced) = self.forced {
            if forced != d {
                return Err(err(format!(
                    "{what} is {d}'s, but the program is read as {forced} (--dialect {forced}); use --dialect {d} or drop the option"
                )));
            }
            return Ok(());
        }
        match self.found {
            None => {
                self.found = Some((d, line, what));
                Ok(())
            }
            Some((other, _, _)) if other == d => Ok(()),
            Some((other, at, by)) => Err(err(format!(
                "{what} is {d}'s, but line {at} already used {by} ({other}'s): a program speaks one dialect"
            ))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_code_decides_and_a_mix_names_both_lines() {
        let mut d = DialectState::new(None);
        assert_eq!(d.resolved(), Dialect::LinuxCnc);
        d.claim(Dialect::Fanuc, 3, 1, "G06.2").unwrap();
        d.claim(Dialect::Fanuc, 9, 1, "G05 P0").unwrap();
        let e = d.claim(Dialect::LinuxCnc, 12, 4, "G5.2").unwrap_err();
        assert_eq!((e.line, e.col), (12, 4));
        assert!(e.message.contains("line 3") && e.message.contains("G06.2"));
        assert_eq!(d.resolved(), Dialect::Fanuc);
        let mut forced = DialectState::new(Some(Dialect::LinuxCnc));
        let e = forced.claim(Dialect::Fanuc, 2, 1, "G06.2").unwrap_err();
        assert!(e.message.contains("--dialect"), "{}", e.message);
        assert_eq!("FANUC".parse::<Dialect>(), Ok(Dialect::Fanuc));
        assert!("haas".parse::<Dialect>().is_err());
    }
}
