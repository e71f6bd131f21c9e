//! Where the scene is in a `POST /render` body: the body itself, or the one
//! part of a `multipart/form-data` form (`curl -F scene=@FILE`, a browser's
//! file upload); and what to tell a client whose body lost its line breaks.
//!
//! An `application/x-www-form-urlencoded` body is taken as it is, not
//! decoded: curl sends that type with `--data-binary @FILE` too, whose
//! bytes are the file's, and with `-d @FILE` the line breaks are gone
//! before anything is encoded, so decoding could not bring them back.

use super::header_params;
use super::http::RequestHead;
use super::multipart::{self, FormError};

/// Added to the message of a scene that does not parse when its body looks
/// like a scene file with its line breaks taken out, as `curl -d @FILE` does.
pub const NO_LINE_BREAKS_HINT: &str = "hint: the body has no line breaks; `curl -d` strips them: \
     send the file with `--data-binary @FILE`";

/// How many directives run into the number before them (`1LEFT`) make a
/// body without line breaks look like a flattened scene file.
const GLUED_DIRECTIVES: usize = 2;

/// The scene text of a render request's body.
pub fn scene_text<'a>(head: &RequestHead, body: &'a [u8]) -> Result<&'a [u8], FormError> {
    let Some(content_type) = head.header("content-type") else {
        return Ok(body);
    };
    let content_type = header_params::element(content_type);
    if !content_type
        .value
        .eq_ignore_ascii_case("multipart/form-data")
    {
        return Ok(body);
    }
    multipart::only_part(body, multipart::boundary(&content_type)?)
}

/// The hint for a scene text that failed to parse, if it looks as if its
/// line breaks were stripped: none in it, and directives run into the
/// numbers that ended the lines before them.
pub fn hint(text: &[u8]) -> Option<&'static str> {
    if text.iter().any(|b| matches!(b, b'\n' | b'\r')) {
        return None;
    }
    (glued_words(text) >= GLUED_DIRECTIVES).then_some(NO_LINE_BREAKS_HINT)
}

/// How many words of two or more letters follow a digit directly and end
/// at a space, a TAB or the end: `1LEFT` in `NEAR 1LEFT -1`. A number's
/// exponent (`1e5`) has one letter and is followed by digits.
fn glued_words(text: &[u8]) -> usize {
    let mut count = 0;
    for (i, _) in text.iter().enumerate().filter(|(_, b)| b.is_ascii_digit()) {
        let letters = text[i + 1..]
            .iter()
            .take_while(|b| b.is_ascii_alphabetic())
            .count();
        let end = text.get(i + 1 + letters);
        if letters >= 2 && end.is_none_or(|b| matches!(b, b' ' | b'\t')) {
            count += 1;
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    fn head(content_type: Option<&str>) -> RequestHead {
        RequestHead {
            method: "POST".into(),
            path: "/render".into(),
            query: String::new(),
            minor_version: 1,
            headers: content_type
                .map(|t| ("content-type".to_owned(), t.to_owned()))
                .into_iter()
                .collect(),
        }
    }

    #[test]
    fn only_a_form_is_unwrapped() {
        let raw: &[u8] = b"NEAR 1\n";
        assert_eq!(scene_text(&head(None), raw), Ok(raw));
        for plain in [
            "text/plain",
            "application/x-www-form-urlencoded",
            "multipart/mixed; boundary=b",
        ] {
            assert_eq!(scene_text(&head(Some(plain)), raw), Ok(raw), "{plain}");
        }
        let form = b"--b\r\nContent-Disposition: form-data; name=\"s\"; filename=\"a\"\r\n\r\nNEAR 1\n\r\n--b--\r\n";
        let typed = head(Some("Multipart/Form-Data; boundary=\"b\""));
        assert_eq!(scene_text(&typed, form), Ok(&b"NEAR 1\n"[..]));
        assert_eq!(
            scene_text(&head(Some("multipart/form-data")), form),
            Err(FormError::MissingBoundary)
        );
        assert!(scene_text(&head(Some("multipart/form-data; boundary=c")), form).is_err());
    }

    #[test]
    fn a_flattened_scene_file_gets_the_hint() {
        let file = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenes/testSample.txt"
        ))
        .unwrap();
        let flattened = file.replace(['\r', '\n'], "");
        assert_eq!(hint(flattened.as_bytes()), Some(NO_LINE_BREAKS_HINT));
        assert_eq!(hint(file.as_bytes()), None, "it has line breaks");
        assert_eq!(hint(b"NEAR 1LEFT"), None, "one glued word is no pattern");
        assert_eq!(hint(b"NEAR 1e5 LEFT 2e3 RES 10 10"), None);
        assert_eq!(hint(b"garbage here"), None);
        assert_eq!(hint(b"NEAR 1LEFT -1RIGHT 1"), Some(NO_LINE_BREAKS_HINT));
        assert_eq!(hint(b""), None);
    }
}
