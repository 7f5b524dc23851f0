//! The tool table `G41`/`G42` take the cutter's radius from: LinuxCNC's `.tbl` format,
//! one tool a line, `T<number> P<pocket> D<diameter> Z<length> ;comment`, in the
//! machine's units (mm here). Only `T` and `D` matter to this control; `P`, the offsets
//! `X Y Z A B C U V W`, the lathe words `I J Q` are read and ignored, as a LinuxCNC
//! user's file has them. A tool without `D` has diameter 0. Blank lines and lines
//! that are only a comment are skipped.
//!
//! `G41 D<n>` uses tool `n`'s diameter, `G41` alone the tool in the spindle (`T<n> M6`),
//! as LinuxCNC does. In Fanuc programs `D<n>` names offset `n`, read from the same
//! table. The table is given with `--tool-table FILE`; without one, `G41`/`G42` are
//! refused rather than run with no offset, and `G41.1`/`G42.1 D<diameter>` need none.

use crate::parse::Diagnostic;

/// One tool of the table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tool {
    pub number: u32,
    /// mm; negative for a tool smaller than the one the path was drawn for.
    pub diameter_mm: f64,
}

/// A tool table, read from its file.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ToolTable {
    /// Where it was read from, for messages.
    pub file: String,
    pub tools: Vec<Tool>,
}

impl ToolTable {
    /// The tool numbered `n`.
    pub fn get(&self, n: u32) -> Option<&Tool> {
        self.tools.iter().find(|t| t.number == n)
    }

    /// Reads `text` (the file `file`): every problem as `file:line:col`.
    pub fn parse(file: &str, text: &str) -> Result<Self, Vec<Diagnostic>> {
        let mut tools: Vec<Tool> = Vec::new();
        let mut errors = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = i as u32 + 1;
            let err = |col: usize, message: String| Diagnostic {
                file: Some(file.to_string()),
                line,
                col: col as u32 + 1,
                rule: "tool table",
                message,
            };
            let body = raw.split(';').next().unwrap_or("");
            let mut number = None;
            let mut diameter = 0.0;
            let mut bad = false;
            let mut pos = 0;
            for word in body.split_whitespace() {
                let col = pos + body[pos..].find(word).unwrap_or(0);
                pos = col + word.len();
                let mut chars = word.chars();
                let letter = chars.next().unwrap_or(' ').to_ascii_uppercase();
                let value: Option<f64> =
                    chars.as_str().parse().ok().filter(|v: &f64| v.is_finite());
                match (letter, value) {
                    ('T', Some(v)) if v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64 => {
                        number = Some(v as u32)
                    }
                    ('T', _) => {
                        errors.push(err(
                            col,
                            format!("{word}: a tool number is a whole number, 0 or more"),
                        ));
                        bad = true;
                    }
                    ('D', Some(v)) => diameter = v,
                    (
                        'P' | 'X' | 'Y' | 'Z' | 'A' | 'B' | 'C' | 'U' | 'V' | 'W' | 'I' | 'J' | 'Q',
                        Some(_),
                    ) => {}
                    _ => {
                        errors.push(err(col, format!("{word}: not a word of a LinuxCNC tool table (T P D X Y Z A B C U V W I J Q, then ; and a comment)")));
                        bad = true;
                    }
                }
            }
            if bad {
                continue;
            }
            match number {
                Some(n) => {
                    if tools.iter().any(|t| t.number == n) {
                        errors.push(err(0, format!("tool T{n} is in the table twice")));
                    } else {
                        tools.push(Tool {
                            number: n,
                            diameter_mm: diameter,
                        });
                    }
                }
                None if body.trim().is_empty() => {}
                None => errors.push(err(0, "a tool's line needs its number, T…".into())),
            }
        }
        if errors.is_empty() {
            Ok(ToolTable {
                file: file.to_string(),
                tools,
            })
        } else {
            Err(errors)
        }
    }

    /// Reads the file at `path`.
    pub fn load(path: &std::path::Path) -> Result<Self, String> {
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| format!("{name}: {e}"))?;
        Self::parse(&name, &text).map_err(|errors| {
            errors
                .iter()
                .map(|d| format!("{name}:{d}"))
                .collect::<Vec<_>>()
                .join("\n")
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_linuxcnc_s_format_and_names_what_is_wrong() {
        let t = ToolTable::parse(
            "tool.tbl",
            "T1 P1 D6.0 Z0.511 ;6 mm end mill\n\n;only a comment\nT2 P2 Z1 X0.1\nt3 p3 d-0.2\n",
        )
        .unwrap();
        assert_eq!(
            t.tools,
            vec![
                Tool {
                    number: 1,
                    diameter_mm: 6.0
                },
                Tool {
                    number: 2,
                    diameter_mm: 0.0
                },
                Tool {
                    number: 3,
                    diameter_mm: -0.2
                },
            ]
        );
        let e =
            ToolTable::parse("tool.tbl", "T1 D6\nT1.5 D2\nT2 D3 K7\nP3 D1\nT1 D4\n").unwrap_err();
        let at: Vec<_> = e.iter().map(|d| (d.line, d.col)).collect();
        assert_eq!(at, vec![(2, 1), (3, 7), (4, 1), (5, 1)], "{e:?}");
        assert!(e[3].message.contains("twice"));
    }
}
