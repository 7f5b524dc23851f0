//! Values in RS274/NGC as LinuxCNC reads them: numbers, parameters (`#12`, `##1`,
//! `#[1+2]`, `#<name>`), unary signs, functions (`SIN[30]`, `ATAN[1]/[2]`,
//! `EXISTS[#<name>]`) and `[ ]` expressions with binary operators.
//!
//! The vocabulary follows LinuxCNC's rs274ngc:
//! * a *real value* is a number, a parameter, a signed real value, a function call or a
//!   bracketed expression; it may stand wherever a number may (word values, parameter
//!   numbers, assignments, function arguments);
//! * binary operators bind, from tightest to loosest: `**`; `* / MOD`; `+ -`;
//!   `EQ NE GT GE LT LE`; `AND OR XOR`, all left to right (`2**3**2` is 64);
//! * a sign belongs to the value it stands before (`-2**2` is 4);
//! * angles are in degrees, in and out;
//! * `EQ`/`NE` compare with LinuxCNC's tolerance of 0.0001, the other comparisons exactly;
//! * every operation that yields NaN or infinity is an error.
//!
//! Reading and evaluating happen in one pass, left to right, so the first error met is
//! the one reported, at the column of the token that caused it.

use crate::parse::{Diagnostic, Param, Params};

/// Deepest nesting of brackets, signs and indirections (`##…`) in one value. LinuxCNC
/// has fixed-size stacks too; here the limit keeps a hostile line from overflowing ours.
const MAX_DEPTH: u32 = 64;

/// LinuxCNC's `TOLERANCE_EQUAL`: how close two values must be for `EQ`.
const TOLERANCE_EQUAL: f64 = 0.0001;

/// How far from a whole number a value may be and still count as an integer
/// (a parameter number), as LinuxCNC's `read_integer_value`.
const TOLERANCE_INTEGER: f64 = 0.0001;

/// Highest numbered parameter a program may read or set.
pub const MAX_NUMBERED: u32 = 5399;

/// The characters of one line with their 1-based columns: comments and whitespace
/// removed, letters upper-cased (LinuxCNC's `close_and_downcase`, in upper case).
#[derive(Default)]
pub(crate) struct Cursor {
    pub chars: Vec<(char, u32)>,
    pub pos: usize,
    pub line: u32,
}

impl Cursor {
    pub fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).map(|c| c.0)
    }

    /// Column of the next character, or one past the last at the end of the line.
    pub fn col(&self) -> u32 {
        match self.chars.get(self.pos) {
            Some(c) => c.1,
            None => self.chars.last().map_or(1, |c| c.1 + 1),
        }
    }

    pub fn err(&self, rule: &'static str, col: u32, message: impl Into<String>) -> Diagnostic {
        Diagnostic {
            file: None,
            line: self.line,
            col,
            rule,
            message: message.into(),
        }
    }

    /// Whether the rest of the line starts with `word` (upper case).
    pub fn at(&self, word: &str) -> bool {
        let mut i = self.pos;
        for w in word.chars() {
            match self.chars.get(i) {
                Some((c, _)) if *c == w => i += 1,
                _ => return false,
            }
        }
        true
    }

    /// Consumes `c` or says what was found instead.
    pub fn expect(&mut self, c: char, what: &str) -> Result<(), Diagnostic> {
        match self.peek() {
            Some(found) if found == c => {
                self.pos += 1;
                Ok(())
            }
            Some(found) => Err(self.err(
                "syntax",
                self.col(),
                format!("expected {what}, found `{found}`"),
            )),
            None => Err(self.err(
                "syntax",
                self.col(),
                format!("expected {what}, found the end of the line"),
            )),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum BinOp {
    Pow,
    Mul,
    Div,
    Mod,
    Add,
    Sub,
    Eq,
    Ne,
    Gt,
    Ge,
    Lt,
    Le,
    And,
    Or,
    Xor,
}

/// Spellings, longest first where one is a prefix of another (`**` before `*`).
const BINARY: [(&str, BinOp); 15] = [
    ("**", BinOp::Pow),
    ("*", BinOp::Mul),
    ("/", BinOp::Div),
    ("MOD", BinOp::Mod),
    ("+", BinOp::Add),
    ("-", BinOp::Sub),
    ("EQ", BinOp::Eq),
    ("NE", BinOp::Ne),
    ("GT", BinOp::Gt),
    ("GE", BinOp::Ge),
    ("LT", BinOp::Lt),
    ("LE", BinOp::Le),
    ("AND", BinOp::And),
    ("OR", BinOp::Or),
    ("XOR", BinOp::Xor),
];

impl BinOp {
    fn precedence(self) -> u8 {
        match self {
            BinOp::Pow => 4,
            BinOp::Mul | BinOp::Div | BinOp::Mod => 3,
            BinOp::Add | BinOp::Sub => 2,
            BinOp::Eq | BinOp::Ne | BinOp::Gt | BinOp::Ge | BinOp::Lt | BinOp::Le => 1,
            BinOp::And | BinOp::Or | BinOp::Xor => 0,
        }
    }

    fn apply(self, a: f64, b: f64) -> Result<f64, &'static str> {
        let truth = |t: bool| if t { 1.0 } else { 0.0 };
        let v = match self {
            BinOp::Pow => {
                if a < 0.0 && b.fract() != 0.0 {
                    return Err("Attempt to raise negative to non integer power");
                }
                a.powf(b)
            }
            BinOp::Mul => a * b,
            BinOp::Div => {
                if b == 0.0 {
                    return Err("Attempt to divide by zero");
                }
                a / b
            }
            BinOp::Mod => {
                // C's fmod, then moved into [0, |b|) as LinuxCNC does.
                let r = a % b;
                if r < 0.0 {
                    r + b.abs()
                } else {
                    r
                }
            }
            BinOp::Add => a + b,
            BinOp::Sub => a - b,
            BinOp::Eq => truth((a - b).abs() < TOLERANCE_EQUAL),
            BinOp::Ne => truth((a - b).abs() >= TOLERANCE_EQUAL),
            BinOp::Gt => truth(a > b),
            BinOp::Ge => truth(a >= b),
            BinOp::Lt => truth(a < b),
            BinOp::Le => truth(a <= b),
            BinOp::And => truth(a != 0.0 && b != 0.0),
            BinOp::Or => truth(a != 0.0 || b != 0.0),
            BinOp::Xor => truth((a != 0.0) != (b != 0.0)),
        };
        finite(v)
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Func {
    Abs,
    Acos,
    Asin,
    Atan,
    Cos,
    Exists,
    Exp,
    Fix,
    Fup,
    Ln,
    Round,
    Sin,
    Sqrt,
    Tan,
}

/// Function names; none is a prefix of another, so matching by prefix is unambiguous.
const FUNCTIONS: [(&str, Func); 14] = [
    ("ABS", Func::Abs),
    ("ACOS", Func::Acos),
    ("ASIN", Func::Asin),
    ("ATAN", Func::Atan),
    ("COS", Func::Cos),
    ("EXISTS", Func::Exists),
    ("EXP", Func::Exp),
    ("FIX", Func::Fix),
    ("FUP", Func::Fup),
    ("LN", Func::Ln),
    ("ROUND", Func::Round),
    ("SIN", Func::Sin),
    ("SQRT", Func::Sqrt),
    ("TAN", Func::Tan),
];

impl Func {
    fn apply(self, x: f64) -> Result<f64, &'static str> {
        let v = match self {
            Func::Abs => x.abs(),
            Func::Acos => {
                if !(-1.0..=1.0).contains(&x) {
                    return Err("Argument to acos out of range");
                }
                x.acos().to_degrees()
            }
            Func::Asin => {
                if !(-1.0..=1.0).contains(&x) {
                    return Err("Argument to asin out of range");
                }
                x.asin().to_degrees()
            }
            Func::Cos => x.to_radians().cos(),
            Func::Exp => x.exp(),
            Func::Fix => x.floor(),
            Func::Fup => x.ceil(),
            Func::Ln => {
                if x <= 0.0 {
                    return Err("Zero or negative argument to ln");
                }
                x.ln()
            }
            // Half away from zero, like C's round and LinuxCNC.
            Func::Round => x.round(),
            Func::Sin => x.to_radians().sin(),
            Func::Sqrt => {
                if x < 0.0 {
                    return Err("Negative argument to sqrt");
                }
                x.sqrt()
            }
            Func::Tan => x.to_radians().tan(),
            // Both have their own syntax and are handled by the reader.
            Func::Atan | Func::Exists => x,
        };
        finite(v)
    }
}

fn finite(v: f64) -> Result<f64, &'static str> {
    if v.is_nan() {
        Err("Calculation resulted in 'not a number'")
    } else if v.is_infinite() {
        Err("Calculation resulted in 'infinity'")
    } else {
        Ok(v)
    }
}

/// Reads one real value at the cursor and returns what it is worth.
pub(crate) fn real_value(cur: &mut Cursor, params: &Params) -> Result<f64, Diagnostic> {
    value(cur, params, 0)
}

/// Reads the parameter after a `#` (already consumed): `#<name>` or a real value that
/// must be a whole number in `1..=5399`.
pub(crate) fn param_ref(cur: &mut Cursor, params: &Params) -> Result<Param, Diagnostic> {
    param(cur, params, 0)
}

fn value(cur: &mut Cursor, params: &Params, depth: u32) -> Result<f64, Diagnostic> {
    let col = cur.col();
    if depth > MAX_DEPTH {
        return Err(cur.err(
            "expression",
            col,
            format!("value nested more than {MAX_DEPTH} deep (brackets, signs or #)"),
        ));
    }
    match cur.peek() {
        None => Err(cur.err("syntax", col, "expected a value, found the end of the line")),
        Some('[') => {
            cur.pos += 1;
            bracketed(cur, params, col, depth + 1)
        }
        Some('#') => {
            cur.pos += 1;
            match param(cur, params, depth + 1)? {
                Param::Numbered(n) => Ok(params.numbered(n)),
                Param::Named(name) => params.named(&name).ok_or_else(|| {
                    cur.err(
                        "parameter",
                        col,
                        format!("Named parameter #<{name}> not defined"),
                    )
                }),
            }
        }
        Some('-') => {
            cur.pos += 1;
            Ok(-value(cur, params, depth + 1)?)
        }
        Some('+') => {
            cur.pos += 1;
            value(cur, params, depth + 1)
        }
        Some('A'..='Z') => function(cur, params, depth + 1),
        Some('0'..='9' | '.') => number(cur),
        Some(c) => Err(cur.err("syntax", col, format!("expected a value, found `{c}`"))),
    }
}

/// The rest of a `[ … ]` whose `[` (at `open_col`) is consumed.
fn bracketed(
    cur: &mut Cursor,
    params: &Params,
    open_col: u32,
    depth: u32,
) -> Result<f64, Diagnostic> {
    let v = binary(cur, params, 0, depth)?;
    match cur.peek() {
        Some(']') => {
            cur.pos += 1;
            Ok(v)
        }
        Some(c) => Err(cur.err(
            "syntax",
            cur.col(),
            format!("expected an operator or `]`, found `{c}`"),
        )),
        None => Err(cur.err(
            "syntax",
            open_col,
            "`[` is not closed with `]` before the end of the line",
        )),
    }
}

/// Precedence climbing: operands and operators until one binds looser than `min`.
fn binary(cur: &mut Cursor, params: &Params, min: u8, depth: u32) -> Result<f64, Diagnostic> {
    let mut lhs = value(cur, params, depth)?;
    loop {
        let Some(&(text, op)) = BINARY.iter().find(|(text, _)| cur.at(text)) else {
            return Ok(lhs);
        };
        if op.precedence() < min {
            return Ok(lhs);
        }
        let col = cur.col();
        cur.pos += text.len();
        let rhs = binary(cur, params, op.precedence() + 1, depth)?;
        lhs = op
            .apply(lhs, rhs)
            .map_err(|m| cur.err("expression", col, m))?;
    }
}

/// Whether a function name starts at the cursor.
pub(crate) fn at_function(cur: &Cursor) -> bool {
    FUNCTIONS.iter().any(|(name, _)| cur.at(name))
}

fn function(cur: &mut Cursor, params: &Params, depth: u32) -> Result<f64, Diagnostic> {
    let col = cur.col();
    let Some(&(name, f)) = FUNCTIONS.iter().find(|(name, _)| cur.at(name)) else {
        let word: String = cur.chars[cur.pos..]
            .iter()
            .map(|c| c.0)
            .take_while(char::is_ascii_uppercase)
            .collect();
        return Err(cur.err("syntax", col, format!("unknown function or value `{word}`")));
    };
    cur.pos += name.len();
    let open = cur.col();
    if cur.peek() != Some('[') {
        return Err(cur.err("syntax", open, format!("`[` missing after {name}")));
    }
    cur.pos += 1;
    match f {
        Func::Exists => {
            cur.expect('#', "`#` parameter in EXISTS[ ]")?;
            let p = param(cur, params, depth + 1)?;
            cur.expect(']', "`]` closing EXISTS[")?;
            Ok(match p {
                Param::Numbered(_) => 1.0,
                Param::Named(name) => {
                    if params.named(&name).is_some() {
                        1.0
                    } else {
                        0.0
                    }
                }
            })
        }
        Func::Atan => {
            let y = bracketed(cur, params, open, depth + 1)?;
            if cur.peek() != Some('/') {
                return Err(cur.err("syntax", cur.col(), "ATAN needs two arguments: ATAN[y]/[x]"));
            }
            cur.pos += 1;
            let open_x = cur.col();
            if cur.peek() != Some('[') {
                return Err(cur.err(
                    "syntax",
                    open_x,
                    "`[` missing after the slash of ATAN[y]/[x]",
                ));
            }
            cur.pos += 1;
            let x = bracketed(cur, params, open_x, depth + 1)?;
            Ok(y.atan2(x).to_degrees())
        }
        _ => {
            let x = bracketed(cur, params, open, depth + 1)?;
            f.apply(x).map_err(|m| cur.err("expression", col, m))
        }
    }
}

fn param(cur: &mut Cursor, params: &Params, depth: u32) -> Result<Param, Diagnostic> {
    let col = cur.col();
    if cur.peek() != Some('<') {
        let v = value(cur, params, depth)?;
        let n = whole(v).ok_or_else(|| {
            cur.err(
                "parameter",
                col,
                format!("parameter number {v} is not a whole number"),
            )
        })?;
        if !(1.0..=MAX_NUMBERED as f64).contains(&n) {
            return Err(cur.err(
                "parameter",
                col,
                format!("parameter number {n} is outside #1..#{MAX_NUMBERED}"),
            ));
        }
        return Ok(Param::Numbered(n as u32));
    }
    cur.pos += 1;
    let mut name = String::new();
    loop {
        match cur.peek() {
            Some('>') => {
                cur.pos += 1;
                break;
            }
            Some(c) => {
                name.push(c.to_ascii_lowercase());
                cur.pos += 1;
            }
            None => {
                return Err(cur.err("parameter", col, "named parameter is not closed with `>`"))
            }
        }
    }
    if name.is_empty() {
        return Err(cur.err("parameter", col, "empty parameter name `#<>`"));
    }
    Ok(Param::Named(name))
}

/// The whole number `v` stands for, within LinuxCNC's tolerance, or `None`.
pub(crate) fn whole(v: f64) -> Option<f64> {
    let f = v.floor();
    let d = v - f;
    if d > 1.0 - TOLERANCE_INTEGER {
        Some(f + 1.0)
    } else if d > TOLERANCE_INTEGER {
        None
    } else {
        Some(f)
    }
}

/// Powers of ten that are exact in an `f64`.
const EXACT_POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The usual number (`12.345`) from what [`number`] gathers of its digits: an integer
/// below 2^53 over an exact power of ten is one correctly rounded division, the same
/// value `str::parse` gives; `None` for any other (then `str::parse` reads the text).
fn exact_decimal(mantissa: u64, decimals: usize, digits: usize, points: usize) -> Option<f64> {
    (digits > 0 && points <= 1 && mantissa < 1 << 53 && decimals < EXACT_POW10.len())
        .then(|| mantissa as f64 / EXACT_POW10[decimals])
}

/// A number at the start of `bytes` (digits and points, no sign), read as [`number`]
/// reads the same characters, with how many bytes it takes; `None` where [`number`]
/// would need `str::parse` or report an error, and for numbers of more than
/// [`PLAIN_DIGITS`] digits (which [`number`] reads the same: the caller then reads the
/// line the general way).
// Inlined into the plain-word reader (its one caller there), the number's value and
// length stay in registers instead of going through memory.
#[inline]
pub(crate) fn plain_number(bytes: &[u8]) -> Option<(f64, usize)> {
    let digit = |at: usize| {
        bytes
            .get(at)
            .map(|b| b.wrapping_sub(b'0'))
            .filter(|d| *d < 10)
    };
    // Digits into one integer; with at most `PLAIN_DIGITS` of them it cannot overflow,
    // so each digit costs a multiply-add and no overflow check.
    let mut mantissa = 0u64;
    let mut at = 0;
    while let Some(d) = digit(at) {
        if at == PLAIN_DIGITS {
            return None;
        }
        mantissa = mantissa * 10 + u64::from(d);
        at += 1;
    }
    let whole = at;
    let mut decimals = 0;
    if bytes.get(at) == Some(&b'.') {
        at += 1;
        while let Some(d) = digit(at) {
            if at > PLAIN_DIGITS {
                return None;
            }
            mantissa = mantissa * 10 + u64::from(d);
            at += 1;
        }
        decimals = at - whole - 1;
        // A second point: [`number`] would read on and find it no number it can take.
        if bytes.get(at) == Some(&b'.') {
            return None;
        }
    }
    // A number needs a digit (a point alone is none); below 2^53 and over an exact power
    // of ten (at most 19 decimals here), one correctly rounded division gives what
    // `str::parse` gives. (Whole numbers and zeros after the point, `Y125.000`, divide
    // exactly: the same bits as the integer itself.)
    (whole + decimals > 0 && mantissa < 1 << 53)
        .then(|| (mantissa as f64 / EXACT_POW10[decimals], at))
}

/// The most digits (the point not counted) [`plain_number`] reads: their integer stays
/// below 10^19 < 2^64.
const PLAIN_DIGITS: usize = 19;

fn number(cur: &mut Cursor) -> Result<f64, Diagnostic> {
    let col = cur.col();
    let start = cur.pos;
    // Digits as an integer and the count of those after the point, while exact.
    let (mut mantissa, mut decimals, mut digits, mut points) = (0u64, 0usize, 0usize, 0usize);
    let len = cur.chars[start..]
        .iter()
        .take_while(|c| matches!(c.0, '0'..='9' | '.'))
        .count();
    for &(c, _) in &cur.chars[start..start + len] {
        match c.to_digit(10) {
            Some(d) => {
                digits += 1;
                decimals += usize::from(points > 0);
                mantissa = mantissa.saturating_mul(10).saturating_add(u64::from(d));
            }
            None => points += 1,
        }
    }
    cur.pos += len;
    if let Some(v) = exact_decimal(mantissa, decimals, digits, points) {
        return Ok(v);
    }
    let text: String = cur.chars[start..cur.pos].iter().map(|c| c.0).collect();
    if digits == 0 {
        return Err(cur.err("syntax", col, format!("`{text}` is not a number")));
    }
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(cur.err("syntax", col, "number is too large")),
        Err(_) => Err(cur.err("syntax", col, format!("`{text}` is not a number"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cursor(text: &str) -> Cursor {
        Cursor {
            chars: text
                .chars()
                .zip(1..)
                .filter(|(c, _)| !c.is_whitespace())
                .map(|(c, col)| (c.to_ascii_uppercase(), col))
                .collect(),
            pos: 0,
            line: 1,
        }
    }

    fn eval(text: &str) -> f64 {
        let mut cur = cursor(text);
        let v = real_value(&mut cur, &Params::default()).unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(cur.pos, cur.chars.len(), "{text} not read to its end");
        v
    }

    fn fail(text: &str) -> (u32, String) {
        let e = real_value(&mut cursor(text), &Params::default()).unwrap_err();
        (e.col, e.message)
    }

    proptest::proptest! {
        /// [`plain_number`] reads what [`number`] reads, to the bit, wherever it reads
        /// anything: up to its digit limit and beyond, with zeros leading and trailing,
        /// points anywhere, and what follows the number.
        #[test]
        fn plain_numbers_read_as_number_reads_them(
            text in "0{0,12}[0-9]{0,12}\\.?[0-9]{0,12}0{0,12}[.0-9]{0,2}[ XE]?"
        ) {
            let run = text
                .bytes()
                .take_while(|b| b.is_ascii_digit() || *b == b'.')
                .count();
            if let Some((v, len)) = plain_number(text.as_bytes()) {
                proptest::prop_assert_eq!(len, run);
                let mut cur = cursor(&text[..run]);
                proptest::prop_assert_eq!(number(&mut cur).map(f64::to_bits), Ok(v.to_bits()));
                proptest::prop_assert_eq!(text[..run].parse::<f64>().map(f64::to_bits), Ok(v.to_bits()));
            }
        }
    }

    #[test]
    fn precedence_and_association() {
        assert_eq!(eval("[1 + 2 * 3]"), 7.0);
        assert_eq!(eval("[2 ** 3 ** 2]"), 64.0);
        assert_eq!(eval("[10 - 4 - 3]"), 3.0);
        assert_eq!(eval("[3 - 2 - 1 + 4 / 2 / 2]"), 1.0);
        assert_eq!(eval("[10 MOD 3 ** 2]"), 1.0);
        assert_eq!(eval("[5 GT 3 + 4]"), 0.0);
        assert_eq!(eval("[1 OR 0 AND 0]"), 0.0);
        assert_eq!(eval("[-2 ** 2]"), 4.0);
        assert_eq!(eval("--2"), 2.0);
        assert_eq!(eval("-+2"), -2.0);
    }

    #[test]
    fn tolerances() {
        assert_eq!(eval("[1 EQ 1.00009]"), 1.0);
        assert_eq!(eval("[1 EQ 1.001]"), 0.0);
        assert_eq!(eval("[1 LT 1.00001]"), 1.0);
        assert_eq!(whole(1.00001), Some(1.0));
        assert_eq!(whole(0.99995), Some(1.0));
        assert_eq!(whole(1.0002), None);
    }

    #[test]
    fn error_columns() {
        assert_eq!(fail("[1/0]"), (3, "Attempt to divide by zero".into()));
        assert_eq!(fail("[1 + SQRT[-1]]").0, 6);
        assert_eq!(fail("[1 + 2").0, 1);
        assert_eq!(fail("[1 + 2 F").0, 8);
        assert_eq!(fail("[FOO[1]]").0, 2);
        assert_eq!(fail(&"[".repeat(1000)).0, 66);
    }

    #[test]
    fn numbers_read_as_str_parse_reads_them() {
        for text in [
            "0",
            "1.",
            ".5",
            "12.345",
            "0.1",
            "0.3",
            "-0",
            "007.250",
            "123456789.123456789",
            "9007199254740993",
            "0.00000000000000000000001",
            "1.7976931348623157",
            "99999999999999999999999",
        ] {
            let digits = text.trim_start_matches('-');
            let mut cur = cursor(digits);
            assert_eq!(number(&mut cur).ok(), digits.parse::<f64>().ok(), "{text}");
            assert_eq!(cur.pos, digits.len());
        }
        for text in [
            "0",
            "1.",
            ".5",
            "12.345",
            "007.250",
            "9007199254740991",
            "1.2.3",
            ".",
            "",
            "123456789.123456789",
            "0.00000000000000000000001",
            "1234567890123456789",
            "12345678901234567890",
            "123456789012345678901234",
            "0000000000000000000000000012.5",
            "125.000",
            "5.",
            ".000",
            "0.0",
            "9007199254740991.0",
            "900719925474099.10",
            "12.0000000000000000000000",
            "12x",
            "3.5 ",
        ] {
            let run = text
                .bytes()
                .take_while(|b| b.is_ascii_digit() || *b == b'.')
                .count();
            let mut cur = cursor(&text[..run]);
            match plain_number(text.as_bytes()) {
                Some((v, len)) => {
                    assert_eq!(len, run, "{text}");
                    assert_eq!(
                        number(&mut cur).map(f64::to_bits),
                        Ok(v.to_bits()),
                        "{text}"
                    );
                }
                // Left to `number`: the slow way or an error.
                None => assert!(
                    run == 0 || number(&mut cur).map_or(true, |v| text[..run].parse() == Ok(v)),
                    "{text}"
                ),
            }
        }
        for bad in [".", "1.2.3", ".."] {
            let e = number(&mut cursor(bad)).unwrap_err();
            assert!(
                e.message.contains("is not a number"),
                "{bad}: {}",
                e.message
            );
        }
    }
}
