//! The shape several request headers share (RFC 9110 §5.6): a list of
//! elements split by commas, each a value followed by `; name=value`
//! parameters whose values may be quoted strings. `Accept`, `Content-Type`
//! and a form part's `Content-Disposition` are read through it.
//!
//! Written by hand: the crates that parse media types (`mime`, `mediatype`)
//! do not read `Content-Disposition`, which is no media type, and this is
//! the one tokenizer all three headers need.

/// One element: its value (trimmed, as sent) and its parameters, names in
/// lower case, quoted values unquoted.
#[derive(Debug, PartialEq, Eq)]
pub struct Element<'a> {
    pub value: &'a str,
    pub params: Vec<(String, String)>,
}

impl Element<'_> {
    /// The value of the parameter `name` (lower case), if given.
    pub fn param(&self, name: &str) -> Option<&str> {
        self.params
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }
}

/// The elements of a comma-separated list, empty ones left out.
pub fn list(header: &str) -> Vec<Element<'_>> {
    split_outside_quotes(header, ',')
        .filter(|e| !e.trim().is_empty())
        .map(element)
        .collect()
}

/// One element: `value; name=value; name="quoted"`. A parameter without
/// `=` is left out: no header read here gives one a meaning.
pub fn element(text: &str) -> Element<'_> {
    let mut pieces = split_outside_quotes(text, ';');
    let value = pieces.next().unwrap_or("").trim();
    let params = pieces
        .filter_map(|p| p.split_once('='))
        .map(|(name, value)| (name.trim().to_ascii_lowercase(), unquote(value.trim())))
        .collect();
    Element { value, params }
}

/// The pieces of `text` between `separator`s that are not inside a quoted
/// string (where a backslash escapes the next character).
fn split_outside_quotes(text: &str, separator: char) -> impl Iterator<Item = &str> {
    let mut in_quotes = false;
    let mut escaped = false;
    let mut start = 0;
    let mut cuts = Vec::new();
    for (i, c) in text.char_indices() {
        match c {
            _ if escaped => escaped = false,
            '\\' if in_quotes => escaped = true,
            '"' => in_quotes = !in_quotes,
            c if c == separator && !in_quotes => {
                cuts.push(&text[start..i]);
                start = i + c.len_utf8();
            }
            _ => {}
        }
    }
    cuts.push(&text[start..]);
    cuts.into_iter()
}

/// A quoted string's content with its escapes undone; any other value as it is.
fn unquote(value: &str) -> String {
    let Some(inner) = value
        .strip_prefix('"')
        .and_then(|v| v.strip_suffix('"'))
        .filter(|_| value.len() >= 2)
    else {
        return value.to_owned();
    };
    let mut out = String::with_capacity(inner.len());
    let mut chars = inner.chars();
    while let Some(c) = chars.next() {
        match c {
            '\\' => out.extend(chars.next()),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn elements_split_on_commas_outside_quotes() {
        let elements = list(r#"image/png;q=0.5, , text/x;name="a,b;c", */*"#);
        let values: Vec<&str> = elements.iter().map(|e| e.value).collect();
        assert_eq!(values, ["image/png", "text/x", "*/*"]);
        assert_eq!(elements[0].param("q"), Some("0.5"));
        assert_eq!(elements[1].param("name"), Some("a,b;c"));
        assert_eq!(elements[2].param("q"), None);
    }

    #[test]
    fn parameters_are_unquoted_and_their_names_lower_cased() {
        let e = element(r#"form-data; NAME="sc\"ene" ; filename = "a b.txt"; bare"#);
        assert_eq!(e.value, "form-data");
        assert_eq!(
            e.params,
            [
                ("name".to_owned(), "sc\"ene".to_owned()),
                ("filename".to_owned(), "a b.txt".to_owned())
            ]
        );
        let e = element("multipart/form-data; boundary=----abc");
        assert_eq!(e.param("boundary"), Some("----abc"));
        assert_eq!(element(r#"x; a=""#).param("a"), Some("\""));
    }
}
