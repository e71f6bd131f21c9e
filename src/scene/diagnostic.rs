//! A scene error as compilers show one (rustc's layout): what is wrong, then
//! `--> origin:line:column`, then the line itself with carets under the
//! text at fault. `SceneError`'s own `Display` stays one line, for JSON
//! fields and logs; this is for people at a terminal.

use super::{SceneError, SceneErrorKind};
use crate::limits;
use std::fmt;

/// A [`SceneError`] with where its text came from (`origin`: a path, or
/// `<stdin>`) and, when the caller still has it, the text of its line.
pub struct Diagnostic<'a> {
    error: &'a SceneError,
    origin: &'a str,
    source_line: Option<&'a str>,
}

impl<'a> Diagnostic<'a> {
    pub fn new(error: &'a SceneError, origin: &'a str, source_line: Option<&'a str>) -> Self {
        Diagnostic {
            error,
            origin,
            source_line,
        }
    }
}

impl fmt::Display for Diagnostic<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let SceneError { line, column, kind } = self.error;
        if !self.error.is_located() {
            return write!(f, "{}: {kind}", self.origin);
        }
        let gutter = line.to_string().len();
        write!(
            f,
            "{kind}\n{:gutter$}--> {}:{line}:{column}",
            "", self.origin
        )?;
        // Binary data shown as text is noise, and can upset the terminal.
        let binary = matches!(kind, SceneErrorKind::Binary { .. });
        let Some(text) = self.source_line.filter(|_| !binary) else {
            return Ok(());
        };
        let excerpt = Excerpt::new(text, *column);
        write!(
            f,
            "\n{:gutter$} |\n{line} | {}\n{:gutter$} | {:pad$}{}",
            "",
            excerpt.shown,
            "",
            "",
            "^".repeat(excerpt.carets),
            pad = excerpt.caret_at
        )
    }
}

/// The part of a line that is shown, and where the carets go under it.
struct Excerpt {
    shown: String,
    /// Display columns before the first caret.
    caret_at: usize,
    carets: usize,
}

impl Excerpt {
    /// `text` around `column` (1-based, in characters; one past the end
    /// points after the last character): at most [`limits::SNIPPET_CHARS`]
    /// of it, `...` where it is cut, TABs as spaces and other control
    /// characters as `�`, with carets under the token that starts at the
    /// column.
    fn new(text: &str, column: usize) -> Excerpt {
        let chars: Vec<char> = text.chars().collect();
        let at = column.saturating_sub(1).min(chars.len());
        let width = limits::SNIPPET_CHARS;
        let start = if chars.len() <= width {
            0
        } else {
            at.saturating_sub(width / 2).min(chars.len() - width)
        };
        let end = (start + width).min(chars.len());
        let mut shown = String::from(if start > 0 { "..." } else { "" });
        let mut caret_at = None;
        for (i, &c) in chars[start..end].iter().enumerate() {
            if start + i == at {
                caret_at = Some(shown.chars().count());
            }
            push_shown(&mut shown, c);
        }
        let caret_at = caret_at.unwrap_or_else(|| shown.chars().count());
        if end < chars.len() {
            shown.push_str("...");
        }
        let token = chars[at..end]
            .iter()
            .take_while(|c| !matches!(c, ' ' | '\t'))
            .count();
        Excerpt {
            shown,
            caret_at,
            carets: token.max(1),
        }
    }
}

/// Appends `c` as it takes one column or more on a terminal.
fn push_shown(shown: &mut String, c: char) {
    match c {
        '\t' => shown.extend(std::iter::repeat_n(' ', limits::SNIPPET_TAB_WIDTH)),
        c if c.is_control() => shown.push('\u{fffd}'),
        c => shown.push(c),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn excerpt(text: &str, column: usize) -> (String, usize, usize) {
        let e = Excerpt::new(text, column);
        (e.shown, e.caret_at, e.carets)
    }

    #[test]
    fn carets_cover_the_token_at_the_column() {
        assert_eq!(excerpt("RES 4 x4", 7), ("RES 4 x4".into(), 6, 2));
        assert_eq!(excerpt("LEFT", 5), ("LEFT".into(), 4, 1), "past the end");
        assert_eq!(excerpt("", 1), (String::new(), 0, 1));
    }

    #[test]
    fn tabs_widen_and_controls_are_replaced() {
        assert_eq!(excerpt("NEAR\tx", 6), ("NEAR    x".into(), 8, 1));
        assert_eq!(excerpt("# a\0b", 4), ("# a\u{fffd}b".into(), 3, 2));
    }

    #[test]
    fn long_lines_are_cut_around_the_column() {
        let line = format!("{}BAD{}", "a ".repeat(200), " b".repeat(200));
        let (shown, at, carets) = excerpt(&line, 401);
        assert_eq!(shown.chars().count(), 3 + limits::SNIPPET_CHARS + 3);
        assert!(shown.starts_with("...") && shown.ends_with("..."));
        assert_eq!(&shown[at..at + 3], "BAD");
        assert_eq!(carets, 3);
        // Near the end, the window ends at the line's end.
        let (shown, at, _) = excerpt(&line, line.len());
        assert!(shown.starts_with("...") && shown.ends_with(" b"));
        assert_eq!(at, 3 + limits::SNIPPET_CHARS - 1);
    }
}
