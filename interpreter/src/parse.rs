//! Reading one line of RS274/NGC into words: case-insensitive, spaces allowed anywhere
//! (outside comments), `( )` and `;` comments, `(MSG, …)`, block delete `/`, numbered and
//! named parameters (`#12`, `#<name>`) as values and as `#n = value` assignments.
//! Every error carries the 1-based column it was found at.

use std::collections::HashMap;

/// One problem in a program, at `line:col` (both 1-based).
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnostic {
    pub line: u32,
    pub col: u32,
    pub message: String,
}

/// One word: a letter and its value, with the column of the letter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Word {
    pub letter: char,
    pub value: f64,
    pub col: u32,
}

/// A parameter assignment on a line; it takes effect after the whole line is read.
#[derive(Debug, Clone, PartialEq)]
pub enum Param {
    Numbered(u32),
    Named(String),
}

/// The parameter table.
#[derive(Debug, Clone)]
pub struct Params {
    numbered: Vec<f64>,
    named: HashMap<String, f64>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            numbered: vec![0.0; 5400],
            named: HashMap::new(),
        }
    }
}

impl Params {
    pub fn set(&mut self, p: &Param, v: f64) {
        match p {
            Param::Numbered(n) => {
                if let Some(slot) = self.numbered.get_mut(*n as usize) {
                    *slot = v;
                }
            }
            Param::Named(name) => {
                self.named.insert(name.clone(), v);
            }
        }
    }
}

/// A line read into words.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Line {
    pub words: Vec<Word>,
    pub assignments: Vec<(Param, f64)>,
    /// `(MSG, text)` comments, shown to the operator.
    pub messages: Vec<String>,
    pub block_delete: bool,
}

struct Cursor<'a> {
    chars: Vec<(char, u32)>,
    pos: usize,
    line: u32,
    _src: &'a str,
}

impl Cursor<'_> {
    fn peek(&self) -> Option<(char, u32)> {
        self.chars.get(self.pos).copied()
    }
    fn col(&self) -> u32 {
        self.peek()
            .map(|c| c.1)
            .unwrap_or_else(|| self.chars.last().map(|c| c.1 + 1).unwrap_or(1))
    }
    fn err(&self, col: u32, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            line: self.line,
            col,
            message: message.into(),
        }
    }

    fn number(&mut self) -> Result<f64, Diagnostic> {
        let start = self.col();
        let mut text = String::new();
        if let Some((c @ ('+' | '-'), _)) = self.peek() {
            text.push(c);
            self.pos += 1;
        }
        let mut digits = 0;
        while let Some((c, _)) = self.peek() {
            if c.is_ascii_digit() {
                digits += 1;
            } else if c != '.' {
                break;
            }
            text.push(c);
            self.pos += 1;
        }
        if digits == 0 {
            return Err(self.err(start, "expected a number"));
        }
        text.parse::<f64>()
            .map_err(|_| self.err(start, format!("`{text}` is not a number")))
    }

    fn param_ref(&mut self) -> Result<Param, Diagnostic> {
        // after '#'
        let col = self.col();
        match self.peek() {
            Some(('<', _)) => {
                self.pos += 1;
                let mut name = String::new();
                loop {
                    match self.peek() {
                        Some(('>', _)) => {
                            self.pos += 1;
                            break;
                        }
                        Some((c, _)) => {
                            name.push(c.to_ascii_lowercase());
                            self.pos += 1;
                        }
                        None => {
                            return Err(self.err(col, "named parameter is missing its closing `>`"))
                        }
                    }
                }
                if name.is_empty() {
                    return Err(self.err(col, "empty parameter name `#<>`"));
                }
                Ok(Param::Named(name))
            }
            _ => {
                let v = self.value_with(&Params::default(), true)?;
                if v.fract() != 0.0 || !(1.0..=5399.0).contains(&v) {
                    return Err(self.err(col, format!("parameter number {v} is outside #1..#5399")));
                }
                Ok(Param::Numbered(v as u32))
            }
        }
    }

    fn value(&mut self, params: &Params) -> Result<f64, Diagnostic> {
        self.value_with(params, false)
    }

    fn value_with(&mut self, params: &Params, literal_only: bool) -> Result<f64, Diagnostic> {
        let col = self.col();
        match self.peek() {
            Some(('#', _)) if !literal_only => {
                self.pos += 1;
                match self.param_ref()? {
                    Param::Numbered(n) => {
                        Ok(params.numbered.get(n as usize).copied().unwrap_or(0.0))
                    }
                    Param::Named(name) => params.named.get(&name).copied().ok_or_else(|| {
                        self.err(col, format!("parameter #<{name}> is used before it is set"))
                    }),
                }
            }
            Some(('[', _)) => Err(self.err(col, "expressions in [ ] are not supported yet")),
            _ => self.number(),
        }
    }
}

/// Reads one source line. `params` supplies the values of `#` references.
pub fn read_line(text: &str, line: u32, params: &Params) -> Result<Line, Diagnostic> {
    let mut out = Line::default();
    let mut chars = Vec::new();
    let mut it = text.char_indices().peekable();
    let mut col = 0u32;
    while let Some((_, c)) = it.next() {
        col += 1;
        match c {
            ';' => {
                let rest: String = it.by_ref().map(|(_, c)| c).collect();
                take_message(rest.trim(), &mut out.messages);
                break;
            }
            '(' => {
                let start = col;
                let mut comment = String::new();
                let mut closed = false;
                for (_, c) in it.by_ref() {
                    col += 1;
                    if c == ')' {
                        closed = true;
                        break;
                    }
                    if c == '(' {
                        return Err(Diagnostic {
                            line,
                            col,
                            message: "comment opened inside a comment".into(),
                        });
                    }
                    comment.push(c);
                }
                if !closed {
                    return Err(Diagnostic {
                        line,
                        col: start,
                        message: "comment is not closed with `)`".into(),
                    });
                }
                take_message(comment.trim(), &mut out.messages);
            }
            c if c.is_whitespace() => {}
            '%' if chars.is_empty() => {} // tape start/end marker
            c => chars.push((c.to_ascii_uppercase(), col)),
        }
    }
    let mut cur = Cursor {
        chars,
        pos: 0,
        line,
        _src: text,
    };
    if let Some(('/', _)) = cur.peek() {
        out.block_delete = true;
        cur.pos += 1;
    }
    while let Some((c, col)) = cur.peek() {
        cur.pos += 1;
        match c {
            'A'..='Z' => {
                let value = cur.value(params)?;
                if !value.is_finite() {
                    return Err(cur.err(col, format!("{c} word is not a finite number")));
                }
                out.words.push(Word {
                    letter: c,
                    value,
                    col,
                });
            }
            '#' => {
                let p = cur.param_ref()?;
                match cur.peek() {
                    Some(('=', _)) => cur.pos += 1,
                    _ => return Err(cur.err(cur.col(), "expected `=` after the parameter")),
                }
                let v = cur.value(params)?;
                out.assignments.push((p, v));
            }
            _ => return Err(cur.err(col, format!("unexpected `{c}`"))),
        }
    }
    Ok(out)
}

fn take_message(comment: &str, messages: &mut Vec<String>) {
    let upper = comment.to_ascii_uppercase();
    if let Some(rest) = upper.strip_prefix("MSG,") {
        let start = comment.len() - rest.len();
        messages.push(comment[start..].trim().to_string());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn words(text: &str) -> Vec<(char, f64)> {
        read_line(text, 1, &Params::default())
            .unwrap()
            .words
            .iter()
            .map(|w| (w.letter, w.value))
            .collect()
    }

    #[test]
    fn words_with_spaces_case_and_comments() {
        assert_eq!(
            words("g1 x 1 0.5 Y-.5 (move) f100 ; rest"),
            vec![('G', 1.0), ('X', 10.5), ('Y', -0.5), ('F', 100.0)]
        );
        assert_eq!(
            words("N10 G5.2 P1 L4"),
            vec![('N', 10.0), ('G', 5.2), ('P', 1.0), ('L', 4.0)]
        );
    }

    #[test]
    fn parameters_are_read_before_they_are_set() {
        let mut p = Params::default();
        let l = read_line("#10=290", 1, &p).unwrap();
        for (param, v) in &l.assignments {
            p.set(param, *v);
        }
        assert_eq!(read_line("F#10", 2, &p).unwrap().words[0].value, 290.0);
        let l = read_line("#<feed> = 12.5", 3, &p).unwrap();
        p.set(&l.assignments[0].0, l.assignments[0].1);
        assert_eq!(read_line("F#<FEED>", 4, &p).unwrap().words[0].value, 12.5);
    }

    #[test]
    fn errors_carry_columns() {
        let e = read_line("G1 X1 Y$", 7, &Params::default()).unwrap_err();
        assert_eq!((e.line, e.col), (7, 8));
        let e = read_line("G1 (open", 3, &Params::default()).unwrap_err();
        assert_eq!((e.line, e.col), (3, 4));
        let e = read_line("G1 X[1+2]", 1, &Params::default()).unwrap_err();
        assert_eq!(e.col, 5);
        let e = read_line("F#<nope>", 1, &Params::default()).unwrap_err();
        assert!(e.message.contains("#<nope>"), "{}", e.message);
    }

    #[test]
    fn msg_comments_are_kept() {
        let l = read_line("(MSG, Tool change!)", 1, &Params::default()).unwrap();
        assert_eq!(l.messages, vec!["Tool change!".to_string()]);
    }
}
