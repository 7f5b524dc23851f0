//! The ISO 10303-21 exchange structure ("Part 21", the clear-text STEP file): a lexer and a
//! parser into plain instances, with the line each instance starts on.
//!
//! What it reads: the `ISO-10303-21;` envelope, the `HEADER;` section (only
//! `FILE_SCHEMA` is kept), and the `DATA;` section of simple instances
//! `#12=NAME(params);` and complex instances `#12=(A(params) B(params));`. Parameters are
//! integers, reals, strings (`''` for a quote; the `\X\`-style escapes are kept as
//! written), enumerations `.T.`, binaries `"0A"`, references `#7`, lists `( … )`, typed
//! parameters `NAME(value)`, unset `$` and derived `*`. Comments `/* … */` may stand
//! anywhere. Anything else is a syntax error with its line; the parser skips to the
//! next `;` and goes on, so one pass reports every broken instance.
//!
//! The meaning of entities is not known here: that is [`super::entities`]' job.

use std::collections::BTreeMap;

/// One parameter of a record.
#[derive(Debug, Clone, PartialEq)]
pub enum Param {
    Int(i64),
    Real(f64),
    Str(String),
    /// `.NAME.` without the dots.
    Enum(String),
    Binary(String),
    Ref(u64),
    List(Vec<Param>),
    /// `NAME(value)`: a value of a defined type, e.g. `LENGTH_MEASURE(2.5)`.
    Typed(String, Box<Param>),
    /// `$`.
    Unset,
    /// `*`.
    Derived,
}

/// `NAME(params)`: the whole of a simple instance, or one partial entity of a complex one.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub name: String,
    pub params: Vec<Param>,
}

/// `#id = …;`
#[derive(Debug, Clone, PartialEq)]
pub struct Instance {
    pub id: u64,
    /// Line of the `#id` that starts the instance (1-based).
    pub line: u32,
    /// One record for a simple instance; the partial entities of a complex one.
    pub records: Vec<Record>,
    pub complex: bool,
}

impl Instance {
    /// The record named `name` (the only one of a simple instance).
    pub fn record(&self, name: &str) -> Option<&Record> {
        self.records.iter().find(|r| r.name == name)
    }
    /// The entity name a message calls this instance by.
    pub fn type_name(&self) -> String {
        if self.complex {
            let names: Vec<&str> = self.records.iter().map(|r| r.name.as_str()).collect();
            format!("({})", names.join(" "))
        } else {
            self.records
                .first()
                .map(|r| r.name.clone())
                .unwrap_or_default()
        }
    }
}

/// A whole exchange file.
#[derive(Debug, Clone, Default)]
pub struct Exchange {
    /// The schema names of `FILE_SCHEMA`.
    pub schemas: Vec<String>,
    pub instances: BTreeMap<u64, Instance>,
}

/// A syntax error: line and, when inside one, the instance.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntaxError {
    pub line: u32,
    pub id: Option<u64>,
    pub message: String,
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Keyword(String),
    Ref(u64),
    Int(i64),
    Real(f64),
    Str(String),
    Enum(String),
    Binary(String),
    Open,
    Close,
    Comma,
    Semi,
    Equals,
    Dollar,
    Star,
}

/// Deeper nesting than this is refused rather than recursed into.
const MAX_DEPTH: usize = 64;

fn lex(text: &str, errs: &mut Vec<SyntaxError>) -> Vec<(Tok, u32)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut line = 1u32;
    let mut i = 0;
    let err = |errs: &mut Vec<SyntaxError>, line, message: String| {
        errs.push(SyntaxError {
            line,
            id: None,
            message,
        })
    };
    while i < b.len() {
        let c = b[i];
        match c {
            b'\n' => {
                line += 1;
                i += 1;
            }
            b' ' | b'\t' | b'\r' => i += 1,
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let start = line;
                i += 2;
                loop {
                    match b.get(i) {
                        None => {
                            err(errs, start, "comment is never closed (`*/`)".into());
                            break;
                        }
                        Some(b'*') if b.get(i + 1) == Some(&b'/') => {
                            i += 2;
                            break;
                        }
                        Some(b'\n') => {
                            line += 1;
                            i += 1;
                        }
                        Some(_) => i += 1,
                    }
                }
            }
            b'(' => {
                out.push((Tok::Open, line));
                i += 1;
            }
            b')' => {
                out.push((Tok::Close, line));
                i += 1;
            }
            b',' => {
                out.push((Tok::Comma, line));
                i += 1;
            }
            b';' => {
                out.push((Tok::Semi, line));
                i += 1;
            }
            b'=' => {
                out.push((Tok::Equals, line));
                i += 1;
            }
            b'$' => {
                out.push((Tok::Dollar, line));
                i += 1;
            }
            b'*' => {
                out.push((Tok::Star, line));
                i += 1;
            }
            b'\'' => {
                let start = line;
                let mut s = Vec::new();
                i += 1;
                let mut closed = false;
                while i < b.len() {
                    if b[i] == b'\'' {
                        if b.get(i + 1) == Some(&b'\'') {
                            s.push(b'\'');
                            i += 2;
                            continue;
                        }
                        i += 1;
                        closed = true;
                        break;
                    }
                    if b[i] == b'\n' {
                        line += 1;
                    }
                    s.push(b[i]);
                    i += 1;
                }
                if !closed {
                    err(errs, start, "string is never closed (`'`)".into());
                }
                out.push((Tok::Str(String::from_utf8_lossy(&s).into_owned()), start));
            }
            b'"' => {
                let start = i + 1;
                i += 1;
                while i < b.len() && b[i] != b'"' && b[i] != b'\n' {
                    i += 1;
                }
                if b.get(i) != Some(&b'"') {
                    err(errs, line, "binary is never closed (`\"`)".into());
                }
                let s = String::from_utf8_lossy(&b[start..i.min(b.len())]).into_owned();
                out.push((Tok::Binary(s), line));
                i = (i + 1).min(b.len());
            }
            b'#' => {
                let start = i + 1;
                i += 1;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
                match std::str::from_utf8(&b[start..i])
                    .ok()
                    .and_then(|s| s.parse::<u64>().ok())
                {
                    Some(n) => out.push((Tok::Ref(n), line)),
                    None => err(
                        errs,
                        line,
                        "`#` must be followed by an instance number".into(),
                    ),
                }
            }
            b'.' if b
                .get(i + 1)
                .is_some_and(|c| c.is_ascii_alphabetic() || *c == b'_') =>
            {
                let start = i + 1;
                i += 1;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_') {
                    i += 1;
                }
                let name = String::from_utf8_lossy(&b[start..i]).to_ascii_uppercase();
                if b.get(i) == Some(&b'.') {
                    i += 1;
                } else {
                    err(
                        errs,
                        line,
                        format!("enumeration `.{name}` lacks its closing `.`"),
                    );
                }
                out.push((Tok::Enum(name), line));
            }
            b'+' | b'-' | b'0'..=b'9' => {
                let start = i;
                i += 1;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
                let mut real = false;
                if b.get(i) == Some(&b'.') {
                    real = true;
                    i += 1;
                    while i < b.len() && b[i].is_ascii_digit() {
                        i += 1;
                    }
                }
                if matches!(b.get(i), Some(b'E' | b'e')) {
                    real = true;
                    i += 1;
                    if matches!(b.get(i), Some(b'+' | b'-')) {
                        i += 1;
                    }
                    while i < b.len() && b[i].is_ascii_digit() {
                        i += 1;
                    }
                }
                let s = std::str::from_utf8(&b[start..i]).unwrap_or("");
                let tok = if real {
                    s.parse::<f64>().ok().map(Tok::Real)
                } else {
                    s.parse::<i64>().ok().map(Tok::Int)
                };
                match tok {
                    Some(t) => out.push((t, line)),
                    None => err(errs, line, format!("`{s}` is not a number")),
                }
            }
            c if c.is_ascii_alphabetic() || c == b'_' || c == b'!' => {
                let start = i;
                i += 1;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || b[i] == b'_' || b[i] == b'-')
                {
                    i += 1;
                }
                let s = String::from_utf8_lossy(&b[start..i]).to_ascii_uppercase();
                out.push((Tok::Keyword(s), line));
            }
            _ => {
                let ch = text.get(i..).and_then(|s| s.chars().next()).unwrap_or('?');
                err(errs, line, format!("unexpected character `{ch}`"));
                i += ch.len_utf8().max(1);
            }
        }
    }
    out
}

struct Parser<'a> {
    toks: &'a [(Tok, u32)],
    pos: usize,
    id: Option<u64>,
    errs: Vec<SyntaxError>,
}

impl Parser<'_> {
    fn peek(&self) -> Option<&Tok> {
        self.toks.get(self.pos).map(|t| &t.0)
    }
    fn line(&self) -> u32 {
        self.toks
            .get(self.pos)
            .or(self.toks.last())
            .map_or(1, |t| t.1)
    }
    fn next(&mut self) -> Option<Tok> {
        let t = self.toks.get(self.pos).map(|t| t.0.clone());
        self.pos += 1;
        t
    }
    fn fail<T>(&self, message: impl Into<String>) -> Result<T, SyntaxError> {
        Err(SyntaxError {
            line: self.line(),
            id: self.id,
            message: message.into(),
        })
    }
    fn expect(&mut self, want: Tok, what: &str) -> Result<(), SyntaxError> {
        if self.peek() == Some(&want) {
            self.pos += 1;
            Ok(())
        } else {
            let found = describe(self.peek());
            self.fail(format!("expected {what}, found {found}"))
        }
    }
    /// Skips past the next `;` (error recovery).
    fn skip_statement(&mut self) {
        while let Some(t) = self.next() {
            if t == Tok::Semi {
                break;
            }
        }
    }

    /// `( p, p, … )` after the opening parenthesis has been seen.
    fn params(&mut self, depth: usize) -> Result<Vec<Param>, SyntaxError> {
        if depth > MAX_DEPTH {
            return self.fail(format!("lists nested deeper than {MAX_DEPTH}"));
        }
        self.expect(Tok::Open, "`(`")?;
        let mut out = Vec::new();
        if self.peek() == Some(&Tok::Close) {
            self.pos += 1;
            return Ok(out);
        }
        loop {
            out.push(self.param(depth)?);
            match self.next() {
                Some(Tok::Comma) => continue,
                Some(Tok::Close) => return Ok(out),
                t => {
                    self.pos -= 1;
                    return self.fail(format!(
                        "expected `,` or `)` in a parameter list, found {}",
                        describe(t.as_ref())
                    ));
                }
            }
        }
    }

    fn param(&mut self, depth: usize) -> Result<Param, SyntaxError> {
        let p = match self.peek() {
            Some(Tok::Open) => return self.params(depth + 1).map(Param::List),
            Some(Tok::Keyword(name)) => {
                let name = name.clone();
                self.pos += 1;
                let mut inner = self.params(depth + 1)?;
                if inner.len() != 1 {
                    return self.fail(format!(
                        "typed parameter {name}(…) must hold exactly one value"
                    ));
                }
                return Ok(Param::Typed(name, Box::new(inner.remove(0))));
            }
            Some(Tok::Ref(n)) => Param::Ref(*n),
            Some(Tok::Int(n)) => Param::Int(*n),
            Some(Tok::Real(x)) => Param::Real(*x),
            Some(Tok::Str(s)) => Param::Str(s.clone()),
            Some(Tok::Enum(s)) => Param::Enum(s.clone()),
            Some(Tok::Binary(s)) => Param::Binary(s.clone()),
            Some(Tok::Dollar) => Param::Unset,
            Some(Tok::Star) => Param::Derived,
            t => return self.fail(format!("expected a parameter, found {}", describe(t))),
        };
        self.pos += 1;
        Ok(p)
    }

    fn record(&mut self) -> Result<Record, SyntaxError> {
        match self.next() {
            Some(Tok::Keyword(name)) => {
                let params = self.params(0)?;
                Ok(Record { name, params })
            }
            t => {
                self.pos -= 1;
                self.fail(format!(
                    "expected an entity name, found {}",
                    describe(t.as_ref())
                ))
            }
        }
    }

    /// `#id = record;` or `#id = (record record …);` after `#id`.
    fn instance(&mut self, id: u64, line: u32) -> Result<Instance, SyntaxError> {
        self.expect(Tok::Equals, "`=` after the instance number")?;
        let (records, complex) = if self.peek() == Some(&Tok::Open) {
            self.pos += 1;
            let mut recs = Vec::new();
            while self.peek() != Some(&Tok::Close) {
                if self.peek().is_none() {
                    return self.fail("complex instance is never closed");
                }
                recs.push(self.record()?);
            }
            self.pos += 1;
            if recs.is_empty() {
                return self.fail("complex instance has no partial entities");
            }
            (recs, true)
        } else {
            (vec![self.record()?], false)
        };
        self.expect(Tok::Semi, "`;` at the end of the instance")?;
        Ok(Instance {
            id,
            line,
            records,
            complex,
        })
    }
}

fn describe(t: Option<&Tok>) -> String {
    match t {
        None => "the end of the file".into(),
        Some(Tok::Keyword(k)) => format!("`{k}`"),
        Some(Tok::Ref(n)) => format!("`#{n}`"),
        Some(Tok::Int(n)) => format!("`{n}`"),
        Some(Tok::Real(x)) => format!("`{x}`"),
        Some(Tok::Str(_)) => "a string".into(),
        Some(Tok::Enum(e)) => format!("`.{e}.`"),
        Some(Tok::Binary(_)) => "a binary".into(),
        Some(Tok::Open) => "`(`".into(),
        Some(Tok::Close) => "`)`".into(),
        Some(Tok::Comma) => "`,`".into(),
        Some(Tok::Semi) => "`;`".into(),
        Some(Tok::Equals) => "`=`".into(),
        Some(Tok::Dollar) => "`$`".into(),
        Some(Tok::Star) => "`*`".into(),
    }
}

/// Whether `text` starts (after blanks and comments) like a Part 21 file.
pub fn looks_like_part21(text: &str) -> bool {
    let mut rest = text.trim_start_matches('\u{feff}').trim_start();
    while let Some(r) = rest.strip_prefix("/*") {
        rest = r
            .split_once("*/")
            .map_or("", |(_, after)| after)
            .trim_start();
    }
    rest.starts_with("ISO-10303-21")
}

/// Reads an exchange file; every syntax error of the file, or the instances.
pub fn parse(text: &str) -> Result<Exchange, Vec<SyntaxError>> {
    let mut errs = Vec::new();
    let toks = lex(text, &mut errs);
    let mut p = Parser {
        toks: &toks,
        pos: 0,
        id: None,
        errs: Vec::new(),
    };
    let mut ex = Exchange::default();
    let kw = |p: &Parser, k: &str| matches!(p.peek(), Some(Tok::Keyword(s)) if s == k);
    if kw(&p, "ISO-10303-21") {
        p.pos += 1;
        if let Err(e) = p.expect(Tok::Semi, "`;` after ISO-10303-21") {
            p.errs.push(e);
        }
    } else {
        p.errs.push(SyntaxError {
            line: p.line(),
            id: None,
            message: "the file does not start with `ISO-10303-21;`".into(),
        });
    }
    let mut saw_data = false;
    let mut saw_end = false;
    while let Some(t) = p.peek().cloned() {
        match t {
            Tok::Keyword(k) if k == "HEADER" || k == "DATA" => {
                p.pos += 1;
                // `DATA` may carry parameters in edition 3: `DATA('name', ('schema'));`.
                if k == "DATA" {
                    saw_data = true;
                    if p.peek() == Some(&Tok::Open) {
                        if let Err(e) = p.params(0) {
                            p.errs.push(e);
                        }
                    }
                }
                if let Err(e) = p.expect(Tok::Semi, "`;`") {
                    p.errs.push(e);
                }
            }
            Tok::Keyword(k) if k == "ENDSEC" => {
                p.pos += 1;
                if let Err(e) = p.expect(Tok::Semi, "`;` after ENDSEC") {
                    p.errs.push(e);
                }
            }
            Tok::Keyword(k) if k == "END-ISO-10303-21" => {
                saw_end = true;
                p.pos += 1;
                if let Err(e) = p.expect(Tok::Semi, "`;` after END-ISO-10303-21") {
                    p.errs.push(e);
                }
                break;
            }
            Tok::Keyword(_) => {
                // A header entity.
                match p.record() {
                    Ok(r) => {
                        if r.name == "FILE_SCHEMA" {
                            if let Some(Param::List(l)) = r.params.first() {
                                ex.schemas.extend(l.iter().filter_map(|x| match x {
                                    Param::Str(s) => Some(s.clone()),
                                    _ => None,
                                }));
                            }
                        }
                        if let Err(e) = p.expect(Tok::Semi, "`;` after a header entity") {
                            p.errs.push(e);
                            p.skip_statement();
                        }
                    }
                    Err(e) => {
                        p.errs.push(e);
                        p.skip_statement();
                    }
                }
            }
            Tok::Ref(id) => {
                let line = p.line();
                p.pos += 1;
                p.id = Some(id);
                match p.instance(id, line) {
                    Ok(inst) => {
                        if let Some(prev) = ex.instances.get(&id) {
                            let message =
                                format!("instance #{id} is already defined on line {}", prev.line);
                            p.errs.push(SyntaxError {
                                line,
                                id: Some(id),
                                message,
                            });
                        } else {
                            ex.instances.insert(id, inst);
                        }
                    }
                    Err(e) => {
                        p.errs.push(e);
                        p.skip_statement();
                    }
                }
                p.id = None;
            }
            t => {
                let e = SyntaxError {
                    line: p.line(),
                    id: None,
                    message: format!("unexpected {}", describe(Some(&t))),
                };
                p.errs.push(e);
                p.skip_statement();
            }
        }
    }
    if !saw_data {
        p.errs.push(SyntaxError {
            line: p.line(),
            id: None,
            message: "no `DATA;` section".into(),
        });
    }
    if !saw_end {
        p.errs.push(SyntaxError {
            line: p.line(),
            id: None,
            message: "the file does not end with `END-ISO-10303-21;`".into(),
        });
    }
    errs.append(&mut p.errs);
    if errs.is_empty() {
        Ok(ex)
    } else {
        errs.sort_by_key(|e| e.line);
        Err(errs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: &str = "ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('x'),'2;1');\n\
FILE_SCHEMA(('MACHINING_SCHEMA'));\nENDSEC;\nDATA;\n/* a comment */\n\
#1=CARTESIAN_POINT('it''s',(1.,-2.5E1,3));\n#2=(A(1,$) B(*,.T.,#1) C());\n\
#3=X(LENGTH_MEASURE(2.),(),\"0F\");\nENDSEC;\nEND-ISO-10303-21;\n";

    #[test]
    fn reads_simple_complex_and_typed_instances_with_lines() {
        let ex = parse(SMALL).unwrap();
        assert_eq!(ex.schemas, vec!["MACHINING_SCHEMA".to_string()]);
        let p1 = &ex.instances[&1];
        assert_eq!(p1.line, 8);
        assert_eq!(
            p1.records[0].params,
            vec![
                Param::Str("it's".into()),
                Param::List(vec![Param::Real(1.0), Param::Real(-25.0), Param::Int(3)])
            ]
        );
        let p2 = &ex.instances[&2];
        assert!(p2.complex);
        assert_eq!(p2.record("B").unwrap().params[2], Param::Ref(1));
        assert_eq!(p2.record("B").unwrap().params[1], Param::Enum("T".into()));
        assert_eq!(p2.type_name(), "(A B C)");
        let p3 = &ex.instances[&3];
        assert_eq!(
            p3.records[0].params[0],
            Param::Typed("LENGTH_MEASURE".into(), Box::new(Param::Real(2.0)))
        );
        assert!(looks_like_part21(SMALL));
        assert!(!looks_like_part21("G1 X1\n"));
    }

    #[test]
    fn reports_every_broken_instance_with_its_line_and_id() {
        let text = "ISO-10303-21;\nDATA;\n#1=A(1,;\n#2=B(2);\n#3 C(3);\n#2=D();\nENDSEC;\n\
END-ISO-10303-21;\n";
        let errs = parse(text).unwrap_err();
        let got: Vec<(u32, Option<u64>)> = errs.iter().map(|e| (e.line, e.id)).collect();
        assert_eq!(
            got,
            vec![(3, Some(1)), (5, Some(3)), (6, Some(2))],
            "{errs:?}"
        );
    }

    #[test]
    fn deep_nesting_is_an_error_not_a_stack_overflow() {
        let text = format!(
            "ISO-10303-21;\nDATA;\n#1=A({}1{});\nENDSEC;\nEND-ISO-10303-21;\n",
            "(".repeat(10_000),
            ")".repeat(10_000)
        );
        let errs = parse(&text).unwrap_err();
        assert!(errs[0].message.contains("nested"), "{errs:?}");
    }
}
