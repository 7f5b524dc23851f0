//! Reading one line of RS274/NGC into words: case-insensitive, spaces allowed anywhere
//! (outside comments), `( )` and `;` comments, `(MSG, …)`, block delete `/`, and values
//! as LinuxCNC reads them ([`crate::expr`]: numbers, `[ ]` expressions, functions,
//! numbered and named parameters), in words and in `#n = value` assignments.
//! Every error carries the 1-based column of the token that caused it.

use std::collections::HashMap;

use crate::expr::{at_function, param_ref, plain_number, real_value, Cursor, MAX_NUMBERED};

/// One problem in a program, at `line:col` (both 1-based), shown as
/// `line:col: rule: message` (after the file name in `cnc check`).
#[derive(Debug, Clone, PartialEq)]
pub struct Diagnostic {
    /// The file the problem is in when it is not the program itself: a subroutine file
    /// it calls (`o<name> call` reading `name.ngc`), as its path was found.
    pub file: Option<String>,
    pub line: u32,
    pub col: u32,
    /// What the program broke, in the words of the manual a machinist would open: the
    /// code whose rules it is (`G2`…: `arc`, `G5`, `G5.2`, `G6.2`, `G06.2`, `G64`, `G93`,
    /// …), or `syntax` (characters that make no words), `expression` (arithmetic that
    /// fails), `parameter`, `word` (unknown or repeated words), `modal` (codes that
    /// conflict or are not supported), `feed`, `O-word` (subroutines and control flow),
    /// `dialect`, `line-length`, `internal` (a block this program made that the
    /// interpolator would refuse: a bug here, not in the program).
    pub rule: &'static str,
    pub message: String,
}

impl core::fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{}:{}: {}: {}",
            self.line, self.col, self.rule, self.message
        )
    }
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

/// The parameter table: numbered `#1..#5399`, global named `#<_name>` and local named
/// `#<name>` parameters. Locals live in one frame per subroutine call level (frame 0 is
/// the main program), as in LinuxCNC.
#[derive(Debug, Clone)]
pub struct Params {
    numbered: Vec<f64>,
    globals: HashMap<String, f64>,
    locals: Vec<HashMap<String, f64>>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            numbered: vec![0.0; MAX_NUMBERED as usize + 1],
            globals: HashMap::new(),
            locals: vec![HashMap::new()],
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
                let map = if name.starts_with('_') {
                    &mut self.globals
                } else {
                    match self.locals.last_mut() {
                        Some(frame) => frame,
                        None => &mut self.globals,
                    }
                };
                map.insert(name.clone(), v);
            }
        }
    }

    /// A numbered parameter; unset ones (and numbers out of range) read 0, as in LinuxCNC.
    pub fn numbered(&self, n: u32) -> f64 {
        self.numbered.get(n as usize).copied().unwrap_or(0.0)
    }

    /// A named parameter (lower case, without spaces), or `None` when it was never set
    /// in this scope.
    pub fn named(&self, name: &str) -> Option<f64> {
        if name.starts_with('_') {
            self.globals.get(name).copied()
        } else {
            self.locals.last().and_then(|f| f.get(name)).copied()
        }
    }

    /// Enters a subroutine: a fresh frame of local named parameters.
    pub fn push_frame(&mut self) {
        self.locals.push(HashMap::new());
    }

    /// Leaves a subroutine; the main program's frame is never dropped.
    pub fn pop_frame(&mut self) {
        if self.locals.len() > 1 {
            self.locals.pop();
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
    /// The line's O-word (`o100 call [1] [2]`), with its bracketed values read.
    pub o_word: Option<OWord>,
}

/// What an O-word line does (LinuxCNC's subroutines and control flow).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OKind {
    Sub,
    EndSub,
    Call,
    Return,
    If,
    ElseIf,
    Else,
    EndIf,
    Do,
    While,
    EndWhile,
    Repeat,
    EndRepeat,
    Break,
    Continue,
    /// A Fanuc program number: `O1234` alone on its line (LinuxCNC has none).
    ProgramNumber,
}

/// Keywords, each before any other it is a prefix of (`ELSEIF` before `ELSE`).
const O_KEYWORDS: [(&str, OKind); 15] = [
    ("ENDSUB", OKind::EndSub),
    ("ENDWHILE", OKind::EndWhile),
    ("ENDIF", OKind::EndIf),
    ("ENDREPEAT", OKind::EndRepeat),
    ("ELSEIF", OKind::ElseIf),
    ("ELSE", OKind::Else),
    ("SUB", OKind::Sub),
    ("CALL", OKind::Call),
    ("RETURN", OKind::Return),
    ("IF", OKind::If),
    ("DO", OKind::Do),
    ("WHILE", OKind::While),
    ("REPEAT", OKind::Repeat),
    ("BREAK", OKind::Break),
    ("CONTINUE", OKind::Continue),
];

/// An O-word: its label (`100` or a lower-case `<name>`), keyword and bracketed values
/// (call arguments, a condition, a repeat count, a return value).
#[derive(Debug, Clone, PartialEq)]
pub struct OWord {
    pub label: String,
    pub kind: OKind,
    /// Column of the `O`.
    pub col: u32,
    pub args: Vec<f64>,
}

impl OKind {
    /// How many bracketed values the keyword takes, at least and at most.
    fn arity(self) -> (usize, usize) {
        match self {
            OKind::Call => (0, 30),
            OKind::If | OKind::ElseIf | OKind::While | OKind::Repeat => (1, 1),
            OKind::EndSub | OKind::Return => (0, 1),
            _ => (0, 0),
        }
    }
}

/// The characters of a line that carry meaning, with their columns, and its messages:
/// comments taken out, whitespace dropped (LinuxCNC ignores it everywhere outside
/// comments, even inside numbers and parameter names), letters upper-cased.
fn significant(text: &str, line: u32, messages: &mut Vec<String>) -> Result<Cursor, Diagnostic> {
    let mut cur = Cursor::default();
    cur.fill(text, line, messages)?;
    Ok(cur)
}

impl Cursor {
    /// Makes this cursor [`significant`]'s of `text`, reusing its buffer.
    fn fill(
        &mut self,
        text: &str,
        line: u32,
        messages: &mut Vec<String>,
    ) -> Result<(), Diagnostic> {
        self.chars.clear();
        self.chars.reserve(text.len());
        self.pos = 0;
        self.line = line;
        // Most lines are ASCII words without a comment: each byte is a character that is
        // either dropped (whitespace) or kept, at the column after its index. A comment
        // or a character beyond ASCII sends the line the long way, from its start.
        for (i, &b) in text.as_bytes().iter().enumerate() {
            match b {
                b'(' | b';' | 0x80.. => {
                    self.chars.clear();
                    return significant_chars(text.chars(), line, &mut self.chars, messages);
                }
                // `char::is_whitespace` in ASCII
                b' ' | b'\t'..=b'\r' => {}
                b'%' if self.chars.is_empty() => {} // tape start/end marker
                _ => self
                    .chars
                    .push((char::from(b.to_ascii_uppercase()), i as u32 + 1)),
            }
        }
        Ok(())
    }
}

/// [`significant`] over the characters of a line, into `chars`.
fn significant_chars(
    mut it: impl Iterator<Item = char>,
    line: u32,
    chars: &mut Vec<(char, u32)>,
    messages: &mut Vec<String>,
) -> Result<(), Diagnostic> {
    let mut col = 0u32;
    while let Some(c) = it.next() {
        col += 1;
        match c {
            ';' => {
                let rest: String = it.by_ref().collect();
                take_message(rest.trim(), messages);
                break;
            }
            '(' => {
                let start = col;
                let mut comment = String::new();
                let mut closed = false;
                for c in it.by_ref() {
                    col += 1;
                    if c == ')' {
                        closed = true;
                        break;
                    }
                    if c == '(' {
                        return Err(Diagnostic {
                            file: None,
                            line,
                            col,
                            rule: "syntax",
                            message: "comment opened inside a comment".into(),
                        });
                    }
                    comment.push(c);
                }
                if !closed {
                    return Err(Diagnostic {
                        file: None,
                        line,
                        col: start,
                        rule: "syntax",
                        message: "comment is not closed with `)`".into(),
                    });
                }
                take_message(comment.trim(), messages);
            }
            c if c.is_whitespace() => {}
            '%' if chars.is_empty() => {} // tape start/end marker
            c => chars.push((c.to_ascii_uppercase(), col)),
        }
    }
    Ok(())
}

/// Reads the lines of a program one after the other into the same buffers, so that no
/// line costs an allocation once they have grown to the longest.
#[derive(Default)]
pub struct LineReader {
    cur: Cursor,
    out: Line,
}

impl LineReader {
    /// [`read_line`], into this reader's buffers.
    pub fn read(&mut self, text: &str, line: u32, params: &Params) -> Result<&Line, Diagnostic> {
        read_into(&mut self.cur, &mut self.out, text, line, params)?;
        Ok(&self.out)
    }
}

/// Reads one source line. `params` supplies the values of `#` references; the line's own
/// assignments are returned, not applied (LinuxCNC applies them after the whole line).
pub fn read_line(text: &str, line: u32, params: &Params) -> Result<Line, Diagnostic> {
    let mut reader = LineReader::default();
    reader.read(text, line, params)?;
    Ok(reader.out)
}

/// [`read_line`] with `cur` and `out` as buffers.
fn read_into(
    cur: &mut Cursor,
    out: &mut Line,
    text: &str,
    line: u32,
    params: &Params,
) -> Result<(), Diagnostic> {
    out.words.clear();
    out.assignments.clear();
    out.messages.clear();
    out.block_delete = false;
    out.o_word = None;
    if plain_words(text, &mut out.words) {
        return Ok(());
    }
    out.words.clear();
    cur.fill(text, line, &mut out.messages)?;
    if let Some('/') = cur.peek() {
        out.block_delete = true;
        cur.pos += 1;
    }
    while let Some(c) = cur.peek() {
        let col = cur.col();
        cur.pos += 1;
        match c {
            'O' => {
                if out.words.iter().any(|w| w.letter != 'N') || out.o_word.is_some() {
                    return Err(cur.err(
                        "O-word",
                        col,
                        "an O-word must start its line (after N at most)",
                    ));
                }
                let mut o = o_head(cur, col)?;
                let (least, most) = o.kind.arity();
                while let Some('[') = cur.peek() {
                    if o.args.len() == most {
                        return Err(cur.err(
                            "O-word",
                            cur.col(),
                            format!("too many values for O {:?} (at most {most})", o.kind),
                        ));
                    }
                    o.args.push(real_value(cur, params)?);
                }
                if let Some(c) = cur.peek() {
                    return Err(cur.err(
                        "O-word",
                        cur.col(),
                        format!("`{c}` after an O-word: nothing but [values] may follow it"),
                    ));
                }
                if o.args.len() < least {
                    return Err(cur.err(
                        "O-word",
                        cur.col(),
                        format!("O {:?} needs its value in [ ]", o.kind),
                    ));
                }
                out.o_word = Some(o);
            }
            'A'..='Z' => {
                // A letter right after a word letter is a function (`XSIN[30]`) only
                // when it spells one; otherwise the word simply lacks its value.
                let starts_value = match cur.peek() {
                    None => false,
                    Some('A'..='Z') => at_function(cur),
                    Some(_) => true,
                };
                if !starts_value {
                    return Err(cur.err("syntax", col, format!("{c} word has no value")));
                }
                let value = real_value(cur, params)?;
                out.words.push(Word {
                    letter: c,
                    value,
                    col,
                });
            }
            '#' => {
                let p = param_ref(cur, params)?;
                match cur.peek() {
                    Some('=') => cur.pos += 1,
                    _ => {
                        return Err(cur.err(
                            "parameter",
                            col,
                            "parameter without `=`: a parameter alone is not a word",
                        ))
                    }
                }
                let v = real_value(cur, params)?;
                out.assignments.push((p, v));
            }
            '[' => {
                return Err(cur.err(
                    "syntax",
                    col,
                    "expression where a word is expected: give it a letter, as in X[1+2]",
                ))
            }
            _ => return Err(cur.err("syntax", col, format!("unexpected `{c}`"))),
        }
    }
    Ok(())
}

/// The words of a line that is nothing but words of a letter and a plain number
/// (`G1 X12.5 Y-3 Z.25 F800`, as CAM output is), read straight from its bytes into
/// `words`, as [`read_into`] reads them; `false` (with `words` partly filled) for any
/// other line, which [`read_into`] then reads the general way from its start: a
/// comment, a parameter, an expression, an O-word, a block delete, a blank inside a
/// word, a number `str::parse` must read, anything beyond ASCII, any error.
fn plain_words(text: &str, words: &mut Vec<Word>) -> bool {
    let b = text.as_bytes();
    // `char::is_whitespace` in ASCII, as `Cursor::fill` drops them.
    let blank = |c: u8| matches!(c, b' ' | b'\t'..=b'\r');
    let mut i = 0;
    while b.get(i).is_some_and(|&c| blank(c)) {
        i += 1;
    }
    // Each word starts at a letter; the blanks after it are passed with it. Anything
    // else where a word must start (a digit or point after blanks, which would belong
    // to the number before, a sign, a `#`) is not a plain line.
    while let Some(&first) = b.get(i) {
        let letter = first.to_ascii_uppercase();
        if !letter.is_ascii_uppercase() || letter == b'O' {
            return false;
        }
        // Every byte so far is ASCII: the column is the byte's.
        let col = i as u32 + 1;
        i += 1;
        let sign = b.get(i).copied();
        if matches!(sign, Some(b'-' | b'+')) {
            i += 1;
        }
        let Some((value, len)) = plain_number(&b[i..]) else {
            return false;
        };
        i += len;
        while b.get(i).is_some_and(|&c| blank(c)) {
            i += 1;
        }
        words.push(Word {
            letter: char::from(letter),
            value: if sign == Some(b'-') { -value } else { value },
            col,
        });
    }
    true
}

/// The label and keyword of an O-word whose `O` (at `col`) is consumed.
fn o_head(cur: &mut Cursor, col: u32) -> Result<OWord, Diagnostic> {
    let mut label = String::new();
    if cur.peek() == Some('<') {
        cur.pos += 1;
        loop {
            match cur.peek() {
                Some('>') => break,
                Some(c) => label.push(c.to_ascii_lowercase()),
                None => return Err(cur.err("O-word", col, "O-word name is not closed with `>`")),
            }
            cur.pos += 1;
        }
        cur.pos += 1;
        if label.is_empty() {
            return Err(cur.err("O-word", col, "empty O-word name `o<>`"));
        }
        label = format!("<{label}>");
    } else {
        while let Some(c @ '0'..='9') = cur.peek() {
            label.push(c);
            cur.pos += 1;
        }
        if label.is_empty() {
            return Err(cur.err("O-word", col, "O-word needs a number or a <name>"));
        }
        // `o0100` and `o100` are the same label.
        label = match label.trim_start_matches('0') {
            "" => "0".to_string(),
            digits => digits.to_string(),
        };
    }
    let at = cur.col();
    if cur.peek().is_none() && !label.starts_with('<') {
        return Ok(OWord {
            label,
            kind: OKind::ProgramNumber,
            col,
            args: Vec::new(),
        });
    }
    let Some(&(text, kind)) = O_KEYWORDS.iter().find(|(k, _)| cur.at(k)) else {
        return Err(cur.err("O-word",
            at,
            "O-word needs sub, endsub, call, return, if, elseif, else, endif, do, while, endwhile, repeat, endrepeat, break or continue",
        ));
    };
    cur.pos += text.len();
    Ok(OWord {
        label,
        kind,
        col,
        args: Vec::new(),
    })
}

/// The O-word of a line, read without evaluating its values (to learn a program's
/// structure before running it), or `None` for a line without one.
pub fn o_word_of(text: &str, line: u32) -> Result<Option<OWord>, Diagnostic> {
    // Most lines have no `O` at all: no need to read them into a cursor.
    // (`b | 0x20` is `o` for `o` and `O` only; a fold without an early exit runs
    // over many bytes at once.)
    if !text.bytes().fold(false, |o, b| o | (b | 0x20 == b'o')) {
        return Ok(None);
    }
    let mut cur = significant(text, line, &mut Vec::new())?;
    if let Some('/') = cur.peek() {
        cur.pos += 1;
    }
    if cur.peek() == Some('N') {
        cur.pos += 1;
        while let Some('0'..='9' | '.') = cur.peek() {
            cur.pos += 1;
        }
    }
    if cur.peek() != Some('O') {
        return Ok(None);
    }
    let col = cur.col();
    cur.pos += 1;
    o_head(&mut cur, col).map(Some)
}

/// How the O-word lines of a program connect, by 0-based line index.
#[derive(Debug, Clone, Default)]
pub struct Flow {
    /// For each line: `if`/`elseif`/`else` → its next branch (`elseif`, `else` or `endif`);
    /// `while`/`do`/`repeat` → the line closing the loop; the closing line (`endwhile`, the
    /// `while` of a `do`, `endrepeat`), `break` and `continue` → the loop's head;
    /// `sub` → its `endsub`.
    pub link: Vec<Option<usize>>,
    /// `while` lines that close a `do` loop rather than open a loop of their own.
    pub closes_do: Vec<bool>,
    /// Subroutine label → index of its `sub` line.
    pub subs: HashMap<String, usize>,
}

impl Flow {
    /// `link` of line `i` (`None` past the list's end: a program without O-words has
    /// an empty list).
    pub fn link(&self, i: usize) -> Option<usize> {
        self.link.get(i).copied().flatten()
    }

    /// `closes_do` of line `i` (`false` past the list's end).
    pub fn closes_do(&self, i: usize) -> bool {
        self.closes_do.get(i).copied().unwrap_or(false)
    }
}

/// Matches the O-words of a whole program (one per line, `None` for other lines) into
/// blocks, as LinuxCNC requires: labels match, blocks nest, a label opens one block only.
pub fn flow(o_words: &[Option<Box<OWord>>]) -> (Flow, Vec<Diagnostic>) {
    struct Open<'a> {
        kind: OKind,
        label: &'a str,
        at: usize,
        branch: usize,
        had_else: bool,
    }
    let n = o_words.len();
    // A program without O-words (most CAM output) has no links: its lists stay empty
    // (read as `None` and `false` past their ends) instead of 17 bytes a line to write.
    let n_linked = if o_words.iter().any(Option::is_some) {
        n
    } else {
        0
    };
    let mut f = Flow {
        link: crate::pages::filled(n_linked, None),
        closes_do: vec![false; n_linked],
        subs: HashMap::new(),
    };
    let mut errors = Vec::new();
    let mut open: Vec<Open> = Vec::new();
    let mut used: HashMap<&str, usize> = HashMap::new();
    for (i, o) in o_words.iter().enumerate() {
        let Some(o) = o else { continue };
        let err = |m: String| Diagnostic {
            file: None,
            line: i as u32 + 1,
            col: o.col,
            rule: "O-word",
            message: m,
        };
        let name = format!("o{} {:?}", o.label, o.kind).to_lowercase();
        let top = open.last_mut().filter(|t| t.label == o.label);
        // LinuxCNC's break and continue leave or restart `while` and `do` loops only
        // (rs274 2.9 refuses them in a `repeat`: "no matching while/do label").
        let is_loop = |k: OKind| matches!(k, OKind::While | OKind::Do);
        let opens_block = match o.kind {
            OKind::While => !matches!(&top, Some(t) if t.kind == OKind::Do),
            k => matches!(k, OKind::Sub | OKind::If | OKind::Do | OKind::Repeat),
        };
        if opens_block {
            if let Some(first) = used.insert(o.label.as_str(), i) {
                errors.push(err(format!(
                    "duplicate O-word label o{}: already used on line {}",
                    o.label,
                    first + 1
                )));
                used.insert(o.label.as_str(), first);
                continue;
            }
            if o.kind == OKind::Sub && !open.is_empty() {
                errors.push(err(format!("{name} inside another block")));
                continue;
            }
            open.push(Open {
                kind: o.kind,
                label: &o.label,
                at: i,
                branch: i,
                had_else: false,
            });
            continue;
        }
        let closes = |k: OKind| match o.kind {
            OKind::EndSub => k == OKind::Sub,
            OKind::ElseIf | OKind::Else | OKind::EndIf => k == OKind::If,
            OKind::While => k == OKind::Do,
            OKind::EndWhile => k == OKind::While,
            OKind::EndRepeat => k == OKind::Repeat,
            _ => false,
        };
        match o.kind {
            OKind::Call | OKind::ProgramNumber => {}
            OKind::Return => {
                if !open
                    .iter()
                    .any(|t| t.kind == OKind::Sub && t.label == o.label)
                {
                    errors.push(err(format!("{name} outside subroutine o{}", o.label)));
                }
            }
            OKind::Break | OKind::Continue => {
                let head = open
                    .iter()
                    .rev()
                    .take_while(|t| t.kind != OKind::Sub)
                    .find(|t| is_loop(t.kind) && t.label == o.label);
                match head {
                    Some(t) => f.link[i] = Some(t.at),
                    None => errors.push(err(format!(
                        "{name} outside a while or do loop o{} (LinuxCNC has no break or continue for repeat)",
                        o.label
                    ))),
                }
            }
            _ => match top {
                Some(t) if closes(t.kind) && !(t.had_else && o.kind != OKind::EndIf) => {
                    f.link[t.branch] = Some(i);
                    if matches!(o.kind, OKind::ElseIf | OKind::Else) {
                        t.branch = i;
                        t.had_else = o.kind == OKind::Else;
                        continue;
                    }
                    if o.kind != OKind::EndIf {
                        f.link[i] = Some(t.at);
                    }
                    f.closes_do[i] = o.kind == OKind::While;
                    if o.kind == OKind::EndSub {
                        f.subs.insert(o.label.clone(), t.at);
                    }
                    open.pop();
                }
                _ => errors.push(err(format!("{name} does not match an open block"))),
            },
        }
    }
    for t in open {
        errors.push(Diagnostic {
            file: None,
            line: t.at as u32 + 1,
            col: o_words[t.at].as_ref().map_or(1, |o| o.col),
            rule: "O-word",
            message: format!("o{} {:?} is never closed", t.label, t.kind).to_lowercase(),
        });
    }
    (f, errors)
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

    proptest::proptest! {
        /// Lines of words with plain numbers take a shorter path still
        /// ([`plain_words`]); any line, plain or nearly, reads as the general reader
        /// (a comment at its end sends it that way) reads it, errors included.
        #[test]
        fn plain_lines_read_as_the_general_reader_reads_them(
            text in "[GXYZOFNgxo0-9.+\\- \t#\\[\\]eE/]{0,24}"
        ) {
            let p = Params::default();
            let fast = read_line(&text, 1, &p);
            let general = read_line(&format!("{text}(c)"), 1, &p);
            proptest::prop_assert_eq!(fast, general);
        }
    }

    proptest::proptest! {
        /// Lines of plain words, as CAM writes them and nearly so (long numbers,
        /// leading and trailing zeros, blanks of every kind, lower case, a stray
        /// character), read as the general reader reads them.
        #[test]
        fn plain_word_lines_read_as_the_general_reader_reads_them(
            text in "([ \t\x0b\x0c\r]{0,2}[GXYZIJKFPgxyzo][+\\-]?[0-9]{0,22}\\.?[0-9]{0,22}[ .#]?){0,6}"
        ) {
            let p = Params::default();
            let fast = read_line(&text, 1, &p);
            let general = read_line(&format!("{text}(c)"), 1, &p);
            proptest::prop_assert_eq!(fast, general);
        }
    }

    #[test]
    fn lines_with_and_without_comments_read_alike() {
        // A line without a comment takes a shorter path; a comment at its end sends it
        // the long way, which must find the same words at the same columns.
        for text in [
            "g1 x1\ty2 \x0bz-.5\x0c f100\r",
            "%G0 X1",
            "G0 %X1",
            "n10 g1 x 1 0.5 y-[1+2]",
            "#<a>=1 #2=[#<a>*2]",
            "X",
            "G1 X1 Y$",
            "",
            "   ",
            "G1 X12.5 Y-3 Z.25 F800",
            "g1x1y2z3",
            "X1 2",
            "X1 .5",
            "X-.5E3",
            "X+7. Y--1",
            "X1.2.3",
            "X123456789012345678901",
            "o100 sub",
            "X1 o2",
            "/G1 X1",
            "N10 G1 X1 Y2 #1=3",
            "X-",
            "G1 X1 é",
        ] {
            let p = Params::default();
            let plain = read_line(text, 1, &p);
            let commented = read_line(&format!("{text}(c)"), 1, &p);
            assert_eq!(plain, commented, "{text:?}");
        }
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
        // Columns count characters, not bytes.
        let e = read_line("G1 (é) X$", 1, &Params::default()).unwrap_err();
        assert_eq!(
            (e.col, e.message.as_str()),
            (9, "expected a value, found `$`")
        );
        let e = read_line("G1 (open", 3, &Params::default()).unwrap_err();
        assert_eq!((e.line, e.col), (3, 4));
        let e = read_line("G1 X[1+2 Y1", 1, &Params::default()).unwrap_err();
        assert_eq!(e.col, 10);
        let e = read_line("G1 X Y1", 1, &Params::default()).unwrap_err();
        assert_eq!((e.col, e.message.as_str()), (4, "X word has no value"));
        let e = read_line("F#<nope>", 1, &Params::default()).unwrap_err();
        assert!(e.message.contains("#<nope>"), "{}", e.message);
    }

    #[test]
    fn o_words_and_their_structure() {
        let o = |t: &str| o_word_of(t, 1).unwrap().unwrap();
        assert_eq!(
            (o("o0100 SUB").label, o("o0100 SUB").kind),
            ("100".into(), OKind::Sub)
        );
        assert_eq!(o("N5 O<My Sub> call [1]").label, "<mysub>");
        assert_eq!(o("o1 elseif [1]").kind, OKind::ElseIf);
        assert_eq!(o_word_of("G1 X1", 1).unwrap(), None);
        let l = read_line("o7 call [1] [2+3] [#1]", 1, &Params::default()).unwrap();
        assert_eq!(l.o_word.unwrap().args, vec![1.0, 5.0, 0.0]);
        let e = read_line("o7 if", 1, &Params::default()).unwrap_err();
        assert_eq!(e.col, 6);
        let e = read_line("G1 o7 if [1]", 1, &Params::default()).unwrap_err();
        assert_eq!(e.col, 4);

        let lines = [
            "o1 if [1]",
            "o1 elseif [2]",
            "o1 else",
            "o1 endif",
            "o2 do",
            "o2 while [1]",
        ];
        let words: Vec<_> = lines
            .iter()
            .map(|t| o_word_of(t, 1).unwrap().map(Box::new))
            .collect();
        let (f, errors) = flow(&words);
        assert!(errors.is_empty(), "{errors:?}");
        assert_eq!(&f.link[..4], &[Some(1), Some(2), Some(3), None]);
        assert_eq!(
            (f.link[4], f.link[5], f.closes_do[5]),
            (Some(5), Some(4), true)
        );
        let words = [o_word_of("o3 else", 1).unwrap().map(Box::new)];
        assert_eq!(flow(&words).1.len(), 1);
    }

    #[test]
    fn msg_comments_are_kept() {
        let l = read_line("(MSG, Tool change!)", 1, &Params::default()).unwrap();
        assert_eq!(l.messages, vec!["Tool change!".to_string()]);
    }
}
