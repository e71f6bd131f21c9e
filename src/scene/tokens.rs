//! The tokens of one line: numbers read and checked field by field, each
//! error placed at its column.

use super::bounds::{self, Extremes, Located};
use super::decimal::{fast_decimal, scan_decimal};
use super::error::Length;
use super::lines::column_of;
use super::{Dialect, SceneError, SceneErrorKind};
use glam::DVec3;

/// Reads the tokens of one line, remembering where each starts.
pub(super) struct Tokens<'a> {
    line: &'a [u8],
    number: usize,
    pos: usize,
    /// The lengths read so far, this line's and those before it in its
    /// chunk: a length that is no new extreme costs two comparisons.
    extremes: &'a mut Extremes,
}

impl<'a> Tokens<'a> {
    pub(super) fn new(number: usize, line: &'a [u8], extremes: &'a mut Extremes) -> Self {
        // `#` comments run to the end of the line.
        let line = match memchr::memchr(b'#', line) {
            Some(hash) => &line[..hash],
            None => line,
        };
        Tokens {
            line,
            number,
            pos: 0,
            extremes,
        }
    }

    fn skip_blanks(&mut self) {
        while self.pos < self.line.len() && matches!(self.line[self.pos], b' ' | b'\t') {
            self.pos += 1;
        }
    }

    /// The next token and its byte offset.
    pub(super) fn next(&mut self) -> Option<(usize, &'a [u8])> {
        self.skip_blanks();
        let start = self.pos;
        while self.pos < self.line.len() && !matches!(self.line[self.pos], b' ' | b'\t') {
            self.pos += 1;
        }
        (self.pos > start).then(|| (start, &self.line[start..self.pos]))
    }

    pub(super) fn peek(&mut self) -> Option<&'a [u8]> {
        let saved = self.pos;
        let token = self.next().map(|(_, t)| t);
        self.pos = saved;
        token
    }

    /// The rest of the line after the blanks that follow the keyword, trimmed.
    pub(super) fn rest(&mut self) -> (usize, &'a [u8]) {
        self.skip_blanks();
        let start = self.pos;
        let mut rest = &self.line[start..];
        while let [head @ .., b' ' | b'\t'] = rest {
            rest = head;
        }
        self.pos = self.line.len();
        (start, rest)
    }

    /// The 1-based character column of byte offset `offset`.
    pub(super) fn column(&self, offset: usize) -> usize {
        column_of(self.line, offset)
    }

    /// Counts a length for the scene-wide bounds. Where it was given is
    /// worked out only when it is a new extreme.
    fn count(&mut self, field: &'static str, value: f64, offset: usize, scale: bool) {
        let Tokens {
            line,
            number,
            extremes,
            ..
        } = self;
        let at = || Located {
            length: Length {
                field,
                value,
                line: *number,
            },
            column: column_of(line, offset),
        };
        if scale {
            extremes.scale(value, at);
        } else {
            extremes.length(value, at);
        }
    }

    /// An error located at byte offset `offset` of this line.
    pub(super) fn error_at(&self, offset: usize, kind: SceneErrorKind) -> SceneError {
        SceneError {
            line: self.number,
            column: self.column(offset),
            kind,
        }
    }

    /// The next token as a number, and its byte offset. Inlined, like the
    /// field readers built on it, so that a plain decimal costs no call and
    /// no large `Result` to move; the rest is [`Tokens::unusual_number`].
    #[inline(always)]
    pub(super) fn number(&mut self, field: &'static str) -> Result<(f64, usize), SceneError> {
        self.skip_blanks();
        let start = self.pos;
        match scan_decimal(self.line, start) {
            Some((value, end)) => {
                self.pos = end;
                Ok((value, start))
            }
            None => self.unusual_number(field),
        }
    }

    /// [`Tokens::number`] for a token that is no plain decimal: an exponent,
    /// many digits, or no number at all.
    #[cold]
    #[inline(never)]
    fn unusual_number(&mut self, field: &'static str) -> Result<(f64, usize), SceneError> {
        let Some((offset, token)) = self.next() else {
            let end = self.line.len();
            return Err(self.error_at(end, SceneErrorKind::MissingField { field }));
        };
        let found = || {
            String::from_utf8_lossy(token)
                .chars()
                .take(40)
                .collect::<String>()
        };
        let value: f64 = fast_decimal(token)
            .or_else(|| std::str::from_utf8(token).ok()?.parse().ok())
            .ok_or_else(|| {
                self.error_at(
                    offset,
                    SceneErrorKind::ExpectedNumber {
                        field,
                        found: found(),
                    },
                )
            })?;
        if !value.is_finite() {
            return Err(self.error_at(
                offset,
                SceneErrorKind::NotFinite {
                    field,
                    found: found(),
                },
            ));
        }
        Ok((value, offset))
    }

    /// A number that must satisfy `ok`, which `rule` describes.
    #[inline(always)]
    pub(super) fn checked(
        &mut self,
        field: &'static str,
        ok: fn(f64) -> bool,
        rule: &'static str,
    ) -> Result<f64, SceneError> {
        let (value, offset) = self.number(field)?;
        if ok(value) {
            Ok(value)
        } else {
            Err(self.error_at(offset, SceneErrorKind::OutOfRange { field, value, rule }))
        }
    }

    #[inline(always)]
    pub(super) fn non_negative(&mut self, field: &'static str) -> Result<f64, SceneError> {
        self.checked(field, |v| v >= 0.0, "≥ 0")
    }

    /// A coordinate or camera value, within what the renderer can represent.
    #[inline(always)]
    pub(super) fn length(&mut self, field: &'static str) -> Result<f64, SceneError> {
        let (value, offset) = self.number(field)?;
        self.length_at(field, value, offset)?;
        Ok(value)
    }

    /// Checks and counts a length already read.
    #[inline(always)]
    pub(super) fn length_at(
        &mut self,
        field: &'static str,
        value: f64,
        offset: usize,
    ) -> Result<(), SceneError> {
        bounds::check_length(field, value).map_err(|kind| self.error_at(offset, kind))?;
        self.count(field, value, offset, false);
        Ok(())
    }

    /// An ellipsoid's scale vector: non-zero, within the bounds, its axes
    /// not too unequal.
    pub(super) fn scales(&mut self, fields: &[&'static str]) -> Result<DVec3, SceneError> {
        let mut axes = [(0.0, "", 0); 3];
        for (axis, &field) in axes.iter_mut().zip(fields) {
            let (value, offset) = self.number(field)?;
            if value == 0.0 {
                let kind = SceneErrorKind::OutOfRange {
                    field,
                    value,
                    rule: "non-zero",
                };
                return Err(self.error_at(offset, kind));
            }
            bounds::check_scale(field, value).map_err(|kind| self.error_at(offset, kind))?;
            self.count(field, value, offset, true);
            *axis = (value, field, offset);
        }
        bounds::check_axes(axes).map_err(|(offset, kind)| self.error_at(offset, kind))?;
        Ok(DVec3::new(axes[0].0, axes[1].0, axes[2].0))
    }

    #[inline(always)]
    pub(super) fn vector(
        &mut self,
        fields: &[&'static str],
        check: fn(&mut Self, &'static str) -> Result<f64, SceneError>,
    ) -> Result<DVec3, SceneError> {
        Ok(DVec3::new(
            check(self, fields[0])?,
            check(self, fields[1])?,
            check(self, fields[2])?,
        ))
    }

    pub(super) fn end(&mut self) -> Result<(), SceneError> {
        match self.next() {
            None => Ok(()),
            Some((offset, token)) => {
                let found = String::from_utf8_lossy(token).chars().take(40).collect();
                Err(self.error_at(offset, SceneErrorKind::ExtraToken { found }))
            }
        }
    }
}

/// A token names a sphere or light unless it reads as a number (or starts like one).
pub(super) fn looks_numeric(token: &[u8]) -> bool {
    match token.first() {
        Some(b'0'..=b'9' | b'+' | b'-' | b'.') => true,
        // Past those, only `inf`, `infinity` and `nan` (in any case) are numbers.
        Some(b'i' | b'I' | b'n' | b'N') => {
            std::str::from_utf8(token).is_ok_and(|s| s.parse::<f64>().is_ok())
        }
        _ => false,
    }
}

/// Consumes the name of a classic SPHERE/LIGHT line, if there is one, and tells the dialect.
pub(super) fn named_dialect(tokens: &mut Tokens) -> Dialect {
    let before = tokens.pos;
    match tokens.next() {
        Some((_, token)) if !looks_numeric(token) => Dialect::Classic,
        _ => {
            tokens.pos = before;
            Dialect::Browser
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Only a token that starts like a number or like `inf`/`nan` is
        /// handed to `str::parse` to tell whether it is one.
        #[test]
        fn looks_numeric_is_what_str_parse_says(token in "[iInNfFaAtTyYsS0-9+.eE-]{0,9}|\\PC{0,4}") {
            let parses = token.parse::<f64>().is_ok();
            let starts_like_one = matches!(token.bytes().next(), Some(b'0'..=b'9' | b'+' | b'-' | b'.'));
            prop_assert_eq!(looks_numeric(token.as_bytes()), starts_like_one || parses, "{}", token);
        }
    }

    #[test]
    fn names_that_read_as_numbers_are_numbers() {
        for token in ["inf", "Infinity", "NaN", "nan", "iNf", "+inf", "-nan", "7"] {
            assert!(looks_numeric(token.as_bytes()), "{token}");
        }
        for token in ["in", "infinit", "nana", "s0", "ball", "N", "e5", "é"] {
            assert!(!looks_numeric(token.as_bytes()), "{token}");
        }
    }
}
