//! Choosing the image type of a render from the request's `Accept` header
//! (RFC 9110 §12.5.1): media ranges with q-values, the most specific range
//! that matches a type giving its weight, `q=0` ruling a type out.
//!
//! Written by hand: it is a few lines over [`header_params`], and the
//! crates that parse `Accept` bring media-type machinery this one header
//! with two offered types does not need.
//!
//! `application/json` is set aside: in this service it asks for errors as
//! JSON (see `RequestHead::accepts_json`), not for the image's type, so a
//! client that lists only it gets the default image.

use super::header_params;
use crate::output::Format;
use std::fmt;

/// The types a render offers, in the order ties are settled (the first is
/// the default).
pub const OFFERED: [Format; 2] = [Format::Png, Format::Ppm];

/// Nothing the client accepts is offered.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NotAcceptable;

impl fmt::Display for NotAcceptable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let offered: Vec<&str> = OFFERED.iter().map(|t| t.mime_type()).collect();
        write!(
            f,
            "Accept names no type this route sends; it sends {} (or ask with ?format=png|ppm)",
            offered.join(", ")
        )
    }
}

/// One media range of `Accept` and its weight, in thousandths.
struct Range<'a> {
    kind: &'a str,
    subtype: &'a str,
    weight: u16,
}

/// The offered type the client prefers (the first offered one among equals),
/// the default when `accept` is absent or names nothing but JSON errors.
pub fn choose(accept: Option<&str>) -> Result<Format, NotAcceptable> {
    let ranges: Vec<Range> = accept.map(ranges).unwrap_or_default();
    if ranges.is_empty() {
        return Ok(OFFERED[0]);
    }
    let mut best: Option<(u16, Format)> = None;
    for offered in OFFERED {
        let weight = weight_of(&ranges, offered.mime_type());
        if weight > 0 && best.is_none_or(|(w, _)| weight > w) {
            best = Some((weight, offered));
        }
    }
    best.map(|(_, format)| format).ok_or(NotAcceptable)
}

/// The ranges of an `Accept` value, but `application/json` and those that
/// are no `type/subtype` or have a malformed weight.
fn ranges(accept: &str) -> Vec<Range<'_>> {
    header_params::list(accept)
        .into_iter()
        .filter_map(|element| {
            let (kind, subtype) = element.value.split_once('/')?;
            let weight = match element.param("q") {
                Some(q) => parse_weight(q)?,
                None => 1000,
            };
            Some(Range {
                kind: kind.trim(),
                subtype: subtype.trim(),
                weight,
            })
        })
        .filter(|r| {
            !(r.kind.eq_ignore_ascii_case("application") && r.subtype.eq_ignore_ascii_case("json"))
        })
        .collect()
}

/// The weight the most specific range matching `mime` gives it (0 if none).
fn weight_of(ranges: &[Range], mime: &str) -> u16 {
    let (kind, subtype) = mime.split_once('/').unwrap_or((mime, ""));
    ranges
        .iter()
        .filter_map(|r| {
            let specificity = match (r.kind, r.subtype) {
                ("*", "*") => 0,
                (k, "*") if k.eq_ignore_ascii_case(kind) => 1,
                (k, s) if k.eq_ignore_ascii_case(kind) && s.eq_ignore_ascii_case(subtype) => 2,
                _ => return None,
            };
            Some((specificity, r.weight))
        })
        .max_by_key(|&(specificity, _)| specificity)
        .map_or(0, |(_, weight)| weight)
}

/// A q-value (RFC 9110 §12.4.2: `0` to `1` with at most three decimals) in
/// thousandths.
fn parse_weight(q: &str) -> Option<u16> {
    let (whole, fraction) = q.split_once('.').unwrap_or((q, ""));
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    if whole.len() != 1 || fraction.len() > 3 || !digits(whole) || !digits(fraction) {
        return None;
    }
    let thousandths = format!("{whole}{fraction:0<3}").parse::<u16>().ok()?;
    (thousandths <= 1000).then_some(thousandths)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pick(accept: &str) -> Result<Format, NotAcceptable> {
        choose(Some(accept))
    }

    #[test]
    fn no_preference_means_png() {
        assert_eq!(choose(None), Ok(Format::Png));
        assert_eq!(pick(""), Ok(Format::Png));
        assert_eq!(pick("*/*"), Ok(Format::Png));
        assert_eq!(pick("image/*"), Ok(Format::Png));
        assert_eq!(pick("application/json"), Ok(Format::Png));
    }

    #[test]
    fn the_named_type_and_the_higher_weight_win() {
        assert_eq!(pick("image/x-portable-pixmap"), Ok(Format::Ppm));
        assert_eq!(pick("IMAGE/X-Portable-Pixmap"), Ok(Format::Ppm));
        assert_eq!(
            pick("image/x-portable-pixmap, application/json"),
            Ok(Format::Ppm)
        );
        assert_eq!(
            pick("image/png;q=0.5, image/x-portable-pixmap;q=0.9"),
            Ok(Format::Ppm)
        );
        assert_eq!(pick("image/png;q=0.9, */*;q=0.1"), Ok(Format::Png));
        assert_eq!(
            pick("image/*;q=0.2, image/x-portable-pixmap"),
            Ok(Format::Ppm)
        );
    }

    #[test]
    fn q_zero_rules_a_type_out_and_nothing_left_is_not_acceptable() {
        assert_eq!(pick("image/png;q=0, */*"), Ok(Format::Ppm));
        assert_eq!(pick("image/*, image/png;q=0.000"), Ok(Format::Ppm));
        assert_eq!(pick("text/html"), Err(NotAcceptable));
        assert_eq!(pick("text/html, application/json"), Err(NotAcceptable));
        assert_eq!(pick("image/*;q=0"), Err(NotAcceptable));
        assert_eq!(pick("image/gif"), Err(NotAcceptable));
    }

    #[test]
    fn malformed_ranges_are_left_out() {
        assert_eq!(
            pick("image/png;q=2, image/x-portable-pixmap"),
            Ok(Format::Ppm)
        );
        assert_eq!(
            pick("garbage, image/x-portable-pixmap;q=0.5"),
            Ok(Format::Ppm)
        );
        assert_eq!(pick("image/png;q=abc"), Ok(Format::Png));
        for bad in ["1.0001", "1.5", "01", "-0", "", "."] {
            assert_eq!(parse_weight(bad), None, "{bad}");
        }
        assert_eq!(parse_weight("0.5"), Some(500));
        assert_eq!(parse_weight("1."), Some(1000));
        assert_eq!(parse_weight("0.125"), Some(125));
    }

    #[test]
    fn the_refusal_lists_what_is_offered() {
        let message = NotAcceptable.to_string();
        assert!(
            message.contains("image/png, image/x-portable-pixmap"),
            "{message}"
        );
    }
}
