//! A whole number a user sets within bounds (samples per pixel, recursion
//! depth), and the one message for a value outside them, which the command
//! line's flags and the service's query parameters both give.

use std::fmt;
use std::ops::RangeInclusive;

/// `found` is not a whole number in `range` for the setting `name`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutOfRange {
    pub name: String,
    pub range: RangeInclusive<u32>,
    pub found: String,
}

impl fmt::Display for OutOfRange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} must be a whole number from {} to {}, found {:?}",
            self.name,
            self.range.start(),
            self.range.end(),
            self.found
        )
    }
}

impl std::error::Error for OutOfRange {}

/// `text` as a whole number in `range`, the value of the setting `name`.
///
/// ```
/// use voxtrace::bounded::parse;
/// assert_eq!(parse("spp", "4", 1..=1024), Ok(4));
/// let e = parse("spp", "0", 1..=1024).unwrap_err();
/// assert_eq!(e.to_string(), r#"spp must be a whole number from 1 to 1024, found "0""#);
/// ```
pub fn parse(name: &str, text: &str, range: RangeInclusive<u32>) -> Result<u32, OutOfRange> {
    text.parse::<u32>()
        .ok()
        .filter(|n| range.contains(n))
        .ok_or_else(|| OutOfRange {
            name: name.to_owned(),
            range,
            found: text.to_owned(),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_are_inclusive_and_junk_is_out() {
        assert_eq!(parse("depth", "0", 0..=64), Ok(0));
        assert_eq!(parse("depth", "64", 0..=64), Ok(64));
        for text in ["65", "-1", "1.5", "", "many", "99999999999"] {
            let e = parse("depth", text, 0..=64).unwrap_err();
            assert_eq!(e.found, text);
        }
    }
}
