//! Numbers written into the traces (`setpoints.csv`, `feedback.csv`) exactly as Rust's
//! `{}` (`Display`) writes them, only faster.
//!
//! The traces are compared byte for byte between runs and between the two clocks, so
//! their text must never change. `Display` for `f64` writes the shortest digits that read
//! back as the same number (the closest of them to it), always in positional notation
//! (`0.0000001`, never `1e-7`; `3`, never `3.0`). [`zmij`] finds the same shortest
//! digits several times faster, but writes them its own way (`1e-7`, `3.0`): [`push_f64`]
//! takes its digits and decimal exponent and lays them out as `Display` does. The tests
//! hold the two to the same text over every kind of value.
//!
//! Measured: formatting was the trace writers' whole cost, and on a 2-core machine
//! under `--clock sim` those threads take CPU from the cycle and the drives.

/// Appends `v` to `out` as `format!("{v}")` would.
pub fn push_f64(out: &mut String, v: f64) {
    if !v.is_finite() {
        // NaN, inf, -inf: rare, and Display's own words.
        use core::fmt::Write;
        let _ = write!(out, "{v}");
        return;
    }
    let mut buf = zmij::Buffer::new();
    let text = buf.format_finite(v);
    let (negative, text) = match text.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, text),
    };
    // Split zmij's text into its digits and the power of ten that follows them.
    let (mantissa, exp10) = match text.split_once('e') {
        Some((m, e)) => (m, e.parse::<i32>().unwrap_or(0)),
        None => (text, 0),
    };
    let mut digits = [0u8; 40];
    let mut n = 0usize;
    // Where the decimal point stands, counted in digits from the left.
    let mut point: i32 = mantissa.len() as i32;
    for b in mantissa.bytes() {
        if b == b'.' {
            point = n as i32;
        } else if n < digits.len() {
            digits[n] = b;
            n += 1;
        }
    }
    point += exp10;
    // Leading zeros ("0.00123") and trailing zeros ("120.0") carry no digit.
    let lead = digits[..n].iter().take_while(|d| **d == b'0').count();
    let trail = digits[lead..n]
        .iter()
        .rev()
        .take_while(|d| **d == b'0')
        .count();
    let sig = &digits[lead..n - trail];
    point -= lead as i32;
    if negative {
        out.push('-');
    }
    if sig.is_empty() {
        // Zero (Display writes `-0` for negative zero, as the sign above did).
        out.push('0');
        return;
    }
    let len = sig.len() as i32;
    // A tie: `v` lies exactly halfway between the written number and its neighbour at the
    // last digit, both read back as `v`, and zmij rounds such a tie to even where Display
    // rounds it up (1658206780088562.25 is `…562.2` to one, `…562.3` to the other). It
    // happens only when `v`'s lowest set bit is worth exactly half a unit of the last
    // digit written, 2^-(k+1) for k fractional digits; then Display writes it itself.
    let frac_digits = (len - point).max(0);
    if lowest_bit_exp(v) == -(frac_digits + 1) {
        out.truncate(out.len() - usize::from(negative));
        use core::fmt::Write;
        let _ = write!(out, "{v}");
        return;
    }
    if point <= 0 {
        out.push_str("0.");
        for _ in 0..-point {
            out.push('0');
        }
        push_ascii(out, sig);
    } else if point >= len {
        push_ascii(out, sig);
        for _ in 0..point - len {
            out.push('0');
        }
    } else {
        let (int, frac) = sig.split_at(point as usize);
        push_ascii(out, int);
        out.push('.');
        push_ascii(out, frac);
    }
}

/// The power of two of `v`'s lowest set bit (`v` finite and not zero): `v = odd · 2^q`.
fn lowest_bit_exp(v: f64) -> i32 {
    let bits = v.to_bits();
    let biased = ((bits >> 52) & 0x7ff) as i32;
    let fraction = bits & ((1u64 << 52) - 1);
    let (m, q) = if biased == 0 {
        (fraction, -1074)
    } else {
        (fraction | (1u64 << 52), biased - 1075)
    };
    q + m.trailing_zeros() as i32
}

/// Appends `v` to `out` as `format!("{v}")` would.
pub fn push_u64(out: &mut String, v: u64) {
    let mut buf = [0u8; 20];
    let mut i = buf.len();
    let mut v = v;
    loop {
        i -= 1;
        buf[i] = b'0' + (v % 10) as u8;
        v /= 10;
        if v == 0 {
            break;
        }
    }
    push_ascii(out, &buf[i..]);
}

fn push_ascii(out: &mut String, digits: &[u8]) {
    // Only ASCII digits reach here, from zmij or from `push_u64`.
    for &d in digits {
        out.push(d as char);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn same(v: f64) {
        let mut got = String::new();
        push_f64(&mut got, v);
        assert_eq!(got, format!("{v}"), "bits {:#018x}", v.to_bits());
    }

    /// A small fixed-seed generator, so a failure names the same values every run.
    struct XorShift(u64);
    impl XorShift {
        fn next(&mut self) -> u64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            self.0
        }
    }

    #[test]
    fn special_values_and_integers_read_as_display_writes_them() {
        for v in [
            0.0,
            -0.0,
            1.0,
            -1.0,
            10.0,
            100.0,
            0.1,
            0.5,
            -0.5,
            123.456,
            1e-7,
            1.5e-7,
            1e15,
            1e16,
            1e17,
            1.2345e21,
            1e22,
            1e23,
            9007199254740993.0,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            f64::EPSILON,
            5e-324,
            -5e-324,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            0.000008333333333387927,
            0.0666666666665483,
        ] {
            same(v);
        }
        for k in -1000i64..=1000 {
            same(k as f64);
            same(k as f64 * 1e-3);
            same(k as f64 * 1e-7);
        }
    }

    #[test]
    fn every_power_of_ten_and_its_neighbours() {
        for e in -324..=308 {
            let v: f64 = format!("1e{e}").parse().unwrap();
            for bits in [v.to_bits().saturating_sub(1), v.to_bits(), v.to_bits() + 1] {
                same(f64::from_bits(bits));
                same(-f64::from_bits(bits));
            }
        }
    }

    #[test]
    fn random_bit_patterns() {
        let mut rng = XorShift(0x9e37_79b9_7f4a_7c15);
        for _ in 0..300_000 {
            same(f64::from_bits(rng.next()));
        }
    }

    /// Halfway cases, where the two ways of rounding a tie part: large numbers with a
    /// quarter or an eighth, and the one random bits found first.
    #[test]
    fn ties_read_as_display_writes_them() {
        same(f64::from_bits(0x4317_9085_685d_83c9));
        same(1_658_206_780_088_562.0 + 0.25);
        let mut rng = XorShift(777);
        for _ in 0..100_000 {
            let n = (rng.next() >> 11) as f64;
            for scale in [0.5, 0.25, 0.125, 0.0625, 2.0, 1.0 / 1024.0] {
                same(n * scale);
                same(-n * scale);
            }
        }
    }

    /// What the traces hold: positions of a few hundred mm and following errors of a few
    /// µm, on the set-point grid and off it.
    #[test]
    fn trace_sized_values() {
        let mut rng = XorShift(12345);
        for _ in 0..300_000 {
            let unit = (rng.next() >> 11) as f64 / (1u64 << 53) as f64;
            same(unit * 1000.0 - 500.0);
            same(unit * 0.02);
            same((unit * 1e6).round() * 1e-4);
            same((unit * 2e5).round() / 1e4);
        }
    }

    #[test]
    fn integers_as_display_writes_them() {
        for v in [0u64, 1, 9, 10, 99, 100, 72_277, 1_000_000, u64::MAX] {
            let mut got = String::new();
            push_u64(&mut got, v);
            assert_eq!(got, v.to_string());
        }
    }
}
