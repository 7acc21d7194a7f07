//! Decimal number parsing for dump columns.
//!
//! How it works: [`parse_f64`] reads sign, up to 19 significant digits into a `u64`
//! mantissa and a decimal exponent in one pass over the bytes. When the mantissa is at most
//! 2^53 and the exponent within ±22, both the mantissa and the power of ten are exact
//! doubles, so one IEEE multiplication or division gives the correctly rounded result
//! (Clinger's fast path). This covers everything LAMMPS writes with its default `%g`
//! format. Anything else (17-digit mantissas, huge exponents, `nan`, `inf`, garbage) goes
//! to the standard library's `str::parse::<f64>`, so the result is always identical to
//! `str::parse` — bit for bit, and `None` exactly where `str::parse` fails.

/// The most digits the fast path reads; a longer number goes to the standard library.
/// (It keeps the digit count and the decimal exponent, one a digit, far from overflowing
/// their integers; dumps hold no such numbers.)
pub(crate) const MAX_FAST_DIGITS: u32 = 800;

/// Exact powers of ten representable as `f64`.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Parses a decimal number exactly as `str::parse::<f64>` would, but faster for the short
/// numbers dumps are made of. Returns `None` where `str::parse` returns an error.
pub fn parse_f64(s: &[u8]) -> Option<f64> {
    match parse_prefix(s) {
        Some((v, n)) if n == s.len() => Some(v),
        _ => parse_slow(s),
    }
}

/// The standard library's parse, for everything the fast path does not take.
#[cold]
pub(crate) fn parse_slow(s: &[u8]) -> Option<f64> {
    std::str::from_utf8(s).ok()?.parse::<f64>().ok()
}

/// The fast path: parses the longest prefix of `s` that looks like a decimal number and
/// returns its value and length. `None` means "ask the standard library", not "invalid";
/// the value is only meaningful when the prefix is the whole token.
#[inline]
pub(crate) fn parse_prefix(s: &[u8]) -> Option<(f64, usize)> {
    let mut i = 0;
    let negative = match s.first() {
        Some(b'-') => {
            i = 1;
            true
        }
        Some(b'+') => {
            i = 1;
            false
        }
        _ => false,
    };
    let mut mantissa: u64 = 0;
    let mut significant = 0u32;
    let mut exponent: i32 = 0;
    let mut digits = 0u32;
    while let Some(&c) = s.get(i) {
        let d = c.wrapping_sub(b'0');
        if d > 9 {
            break;
        }
        if digits == MAX_FAST_DIGITS {
            return None;
        }
        digits += 1;
        if mantissa != 0 || d != 0 {
            if significant == 19 {
                return None;
            }
            mantissa = mantissa * 10 + u64::from(d);
            significant += 1;
        }
        i += 1;
    }
    if s.get(i) == Some(&b'.') {
        i += 1;
        while let Some(&c) = s.get(i) {
            let d = c.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            if digits == MAX_FAST_DIGITS {
                return None;
            }
            digits += 1;
            if mantissa != 0 || d != 0 {
                if significant == 19 {
                    return None;
                }
                mantissa = mantissa * 10 + u64::from(d);
                significant += 1;
            }
            exponent -= 1;
            i += 1;
        }
    }
    if digits == 0 {
        return None;
    }
    if let Some(&(b'e' | b'E')) = s.get(i) {
        i += 1;
        let negative_exp = match s.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let start = i;
        let mut e: i32 = 0;
        while let Some(&c) = s.get(i) {
            let d = c.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            if e > 1000 {
                return None;
            }
            e = e * 10 + i32::from(d);
            i += 1;
        }
        if i == start {
            return None;
        }
        exponent += if negative_exp { -e } else { e };
    }
    let value = if mantissa == 0 {
        0.0
    } else if mantissa <= 1 << 53 && (-22..=22).contains(&exponent) {
        let m = mantissa as f64;
        if exponent >= 0 {
            m * POW10[exponent as usize]
        } else {
            m / POW10[(-exponent) as usize]
        }
    } else {
        return None;
    };
    Some((if negative { -value } else { value }, i))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn same_as_std(t: &str) {
        assert_eq!(
            parse_f64(t.as_bytes()).map(f64::to_bits),
            t.parse::<f64>().ok().map(f64::to_bits),
            "{} bytes",
            t.len()
        );
    }

    #[test]
    fn numbers_of_more_digits_than_the_fast_path_reads_go_to_the_standard_library() {
        let max = MAX_FAST_DIGITS as usize;
        // Every digit is counted, leading zeros too (a token of 2^32 of them overflowed
        // the counters): the fast path reads `max` digits, not one more.
        let at_most = format!("{}1.5", "0".repeat(max - 2));
        let past = format!("0{at_most}");
        assert_eq!(parse_prefix(at_most.as_bytes()), Some((1.5, max + 1)));
        assert_eq!(parse_prefix(past.as_bytes()), None);
        // Zeros after the point lower the exponent one a digit.
        let fraction = format!("0.{}1", "0".repeat(3 * max));
        let zeros = "0".repeat(3 * max);
        let negative = format!("-{past}e-3");
        for t in [&past, &fraction, &zeros, &negative] {
            assert_eq!(parse_prefix(t.as_bytes()), None, "{} bytes", t.len());
        }
        for t in [&at_most, &past, &fraction, &zeros, &negative] {
            same_as_std(t);
        }
    }
}
