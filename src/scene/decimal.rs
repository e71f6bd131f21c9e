//! The plain decimals scene files are made of (`-12.375`, `0.5`, `7`), read
//! without `str::parse`: in one pass over a line that also finds where the
//! token ends ([`scan_decimal`]), or from a token already cut out
//! ([`fast_decimal`]). Both give `str::parse`'s value, bit for bit, or
//! nothing, and leave anything else to it.

/// Powers of ten that f64 holds exactly.
const EXACT_POWERS_OF_TEN: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// The most digits a plain decimal may have: 10^15 < 2^53, so its digits
/// read as an integer are exact in f64.
const MAX_DIGITS: usize = 15;

/// Clinger's fast path: when the digits, read as an integer m, fit in 53
/// bits and there are at most 22 after the point, m and 10^k are exact in f64
/// and one correctly rounded division gives the correctly rounded value.
#[inline]
fn value(negative: bool, mantissa: u64, after_point: usize) -> f64 {
    // Below 10^15 the signed conversion is the same and one instruction.
    let value = mantissa as i64 as f64 / EXACT_POWERS_OF_TEN[after_point];
    if negative {
        -value
    } else {
        value
    }
}

/// `token` as a plain decimal: an optional sign, then 1 to [`MAX_DIGITS`]
/// digits with at most one point among them. Anything else (exponents,
/// long mantissas, junk) is `None`, for `str::parse`. The rule of
/// [`scan_decimal`], over the whole token.
#[inline]
pub(super) fn fast_decimal(token: &[u8]) -> Option<f64> {
    scan_decimal(token, 0)
        .filter(|&(_, end)| end == token.len())
        .map(|(value, _)| value)
}

/// The plain decimal (as [`fast_decimal`] reads one) that starts at byte
/// `start` of `line` and ends at the next blank or at the line's end, and
/// that end; `None` when the token there is anything else.
#[inline]
pub(super) fn scan_decimal(line: &[u8], start: usize) -> Option<(f64, usize)> {
    let negative = line.get(start) == Some(&b'-');
    let mut pos = start + usize::from(matches!(line.get(start), Some(b'-' | b'+')));
    let (mut mantissa, whole) = digits(line, &mut pos, 0);
    let mut fraction = 0;
    if line.get(pos) == Some(&b'.') {
        pos += 1;
        (mantissa, fraction) = digits(line, &mut pos, mantissa);
    }
    let seen = whole + fraction;
    let ends = line.get(pos).is_none_or(|&b| matches!(b, b' ' | b'\t'));
    (ends && (1..=MAX_DIGITS).contains(&seen)).then(|| (value(negative, mantissa, fraction), pos))
}

/// Reads the digits from `*pos` on into `mantissa`, moving `*pos` past
/// them; returns the mantissa and how many there were. Past
/// [`MAX_DIGITS`] the mantissa wraps, and the caller discards it.
#[inline(always)]
fn digits(line: &[u8], pos: &mut usize, mut mantissa: u64) -> (u64, usize) {
    let start = *pos;
    while let Some(digit) = line
        .get(*pos)
        .map(|b| b.wrapping_sub(b'0'))
        .filter(|&d| d < 10)
    {
        mantissa = mantissa.wrapping_mul(10).wrapping_add(u64::from(digit));
        *pos += 1;
    }
    (mantissa, *pos - start)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn fast_decimals_match_the_standard_parser() {
        for token in [
            "0",
            "-0",
            "+7",
            "12.375",
            "-0.1",
            ".5",
            "1.",
            "0.30000000000000004",
            "123456789012345",
            "1234567890123456",
            "9007199254740993",
            "0.000001234",
            "1e5",
            "-",
            ".",
            "1.2.3",
            "",
            "nan",
            "inf",
        ] {
            let fast = fast_decimal(token.as_bytes());
            let std = token.parse::<f64>().ok();
            if let Some(v) = fast {
                assert_eq!(Some(v.to_bits()), std.map(f64::to_bits), "{token}");
            }
        }
        assert_eq!(
            fast_decimal(b"1e5"),
            None,
            "exponents go to the standard parser"
        );
    }

    /// What the scan replaces: the token up to the next blank, read by
    /// [`fast_decimal`].
    fn cut_then_read(line: &[u8], start: usize) -> Option<(f64, usize)> {
        let end = line[start..]
            .iter()
            .position(|&b| matches!(b, b' ' | b'\t'))
            .map_or(line.len(), |i| start + i);
        fast_decimal(&line[start..end]).map(|v| (v, end))
    }

    #[test]
    fn scans_stop_at_blanks_and_refuse_what_follows_a_number() {
        let scan = |line: &str, start| scan_decimal(line.as_bytes(), start);
        assert_eq!(scan("1.5 2", 0), Some((1.5, 3)));
        assert_eq!(scan("x -2\t", 2), Some((-2.0, 4)));
        assert_eq!(scan("x +.5", 2), Some((0.5, 5)));
        assert_eq!(
            scan("-0", 0).map(|(v, _)| v.to_bits()),
            Some((-0.0f64).to_bits())
        );
        assert_eq!(scan("1.5x 2", 0), None);
        assert_eq!(scan("1e5", 0), None);
        assert_eq!(scan("1.2.3", 0), None);
        assert_eq!(scan("- 1", 0), None);
        assert_eq!(scan(". 1", 0), None);
        assert_eq!(scan("--1", 0), None);
        assert_eq!(scan("1234567890123456", 0), None);
        assert_eq!(scan("123456789012345", 0), Some((123456789012345.0, 15)));
        // Past the wrap of the mantissa's 64 bits.
        assert_eq!(scan("99999999999999999999999", 0), None);
    }

    /// Tokens drawn from the bytes numbers are made of, and a few others.
    fn token_bytes() -> impl Strategy<Value = Vec<u8>> {
        let byte = prop_oneof![
            8 => b'0'..=b'9',
            2 => Just(b'.'),
            1 => Just(b'-'),
            1 => Just(b'+'),
            1 => Just(b'e'),
            1 => Just(b' '),
            1 => Just(b'\t'),
            1 => any::<u8>(),
        ];
        proptest::collection::vec(byte, 0..24)
    }

    proptest! {
        #[test]
        fn fast_decimal_is_correctly_rounded(int in 0u64..10_000_000_000, frac in 0usize..12, neg: bool) {
            let digits = int.to_string();
            let cut = digits.len().saturating_sub(frac);
            let token = format!("{}{}.{}", if neg { "-" } else { "" }, &digits[..cut], &digits[cut..]);
            let fast = fast_decimal(token.as_bytes()).unwrap();
            prop_assert_eq!(fast.to_bits(), token.parse::<f64>().unwrap().to_bits(), "{}", token);
        }

        #[test]
        fn scanning_reads_what_cutting_then_reading_does(head in token_bytes(), tail in token_bytes()) {
            // A token starts after blanks, at the start of the line or after a blank.
            let line = [&head[..], b" ", &tail[..]].concat();
            let after = if head.is_empty() { 0 } else { head.len() + 1 };
            let blanks = line[after..].iter().take_while(|&&b| matches!(b, b' ' | b'\t')).count();
            let start = after + blanks;
            prop_assume!(start < line.len());
            let scanned = scan_decimal(&line, start).map(|(v, end)| (v.to_bits(), end));
            let cut = cut_then_read(&line, start).map(|(v, end)| (v.to_bits(), end));
            prop_assert_eq!(scanned, cut);
            if let Some((bits, end)) = scanned {
                let std: f64 = std::str::from_utf8(&line[start..end]).unwrap().parse().unwrap();
                prop_assert_eq!(bits, std.to_bits());
            }
        }
    }
}
