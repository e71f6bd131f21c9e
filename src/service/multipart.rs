//! A `multipart/form-data` body (RFC 7578), framed as RFC 2046 §5.1.1 says:
//! parts between `--BOUNDARY` lines, each with its own headers, the last
//! closed by `--BOUNDARY--`. This is what `curl -F scene=@FILE` and a
//! browser's file upload send; the scene is the form's one part.
//!
//! Written by hand: the maintained multipart parsers are asynchronous
//! (`multer` runs on tokio streams) and the synchronous `multipart` crate
//! is unmaintained, while here the whole body is already in memory, bounded
//! by `--max-body`. Finding the delimiters is one linear `memchr` search
//! each; a part's headers are read by `httparse`, as the request's are.

use super::header_params;
use crate::limits;
use memchr::memmem;
use std::fmt;

/// Why a form body holds no scene to render.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FormError {
    /// `Content-Type: multipart/form-data` without `boundary=`.
    MissingBoundary,
    /// A boundary that RFC 2046 does not allow.
    BadBoundary,
    /// No `--BOUNDARY` line anywhere in the body.
    NoDelimiter { boundary: String },
    /// The body ends before the closing `--BOUNDARY--` line.
    Unterminated { boundary: String },
    /// A `--BOUNDARY` line with more on it than the boundary.
    BadDelimiter { boundary: String },
    /// A part's headers are malformed or do not end with a blank line
    /// (`part` counts from 1).
    PartHead { part: usize, why: String },
    /// More than [`limits::MAX_FORM_PARTS`] parts.
    TooManyParts,
    /// The form has no part at all.
    NoParts,
    /// More than one part is a file: which is the scene would be a guess.
    SeveralFiles { names: Vec<Option<String>> },
    /// Fields beside the one file: parameters belong in the query string.
    ExtraFields { names: Vec<Option<String>> },
    /// Several fields and no file among them.
    SeveralFields { names: Vec<Option<String>> },
}

impl fmt::Display for FormError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use FormError::*;
        match self {
            MissingBoundary => write!(
                f,
                "a multipart/form-data body needs a boundary= parameter in its Content-Type"
            ),
            BadBoundary => write!(
                f,
                "the form's boundary must be 1 to 70 letters, digits or '()+_,-./:=? and spaces, \
                 not ending in a space (RFC 2046)"
            ),
            NoDelimiter { boundary } => write!(
                f,
                "the form body has no line \"--{boundary}\" that starts a part"
            ),
            Unterminated { boundary } => write!(
                f,
                "the form body ends inside a part: its closing line \"--{boundary}--\" is missing"
            ),
            BadDelimiter { boundary } => write!(
                f,
                "a line \"--{boundary}\" of the form body goes on past its boundary"
            ),
            PartHead { part, why } => write!(f, "part {part} of the form: {why}"),
            TooManyParts => write!(
                f,
                "the form has more than {} parts; send the scene as its one part",
                limits::MAX_FORM_PARTS
            ),
            NoParts => write!(
                f,
                "the form has no parts; send the scene as a file part (curl -F scene=@FILE)"
            ),
            SeveralFiles { names } => write!(
                f,
                "the form has {} file parts ({}); send the scene as its one part",
                names.len(),
                Names(names)
            ),
            ExtraFields { names } => write!(
                f,
                "the form has fields beside the scene file ({}); send the scene alone, \
                 with parameters in the query string (/render?spp=4)",
                Names(names)
            ),
            SeveralFields { names } => write!(
                f,
                "the form has {} fields ({}) and no file; send the scene as its one part \
                 (curl -F scene=@FILE)",
                names.len(),
                Names(names)
            ),
        }
    }
}

/// Part names as a message lists them.
struct Names<'a>(&'a [Option<String>]);

impl fmt::Display for Names<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, name) in self.0.iter().enumerate() {
            if i > 0 {
                write!(f, ", ")?;
            }
            match name {
                Some(name) => write!(f, "{name:?}")?,
                None => write!(f, "an unnamed part")?,
            }
        }
        Ok(())
    }
}

/// One part of a form.
#[derive(Debug)]
struct Part<'a> {
    /// Its `Content-Disposition`'s `name`.
    name: Option<String>,
    /// Whether its `Content-Disposition` has a `filename`: an uploaded file.
    is_file: bool,
    content: &'a [u8],
}

/// The boundary a `multipart/form-data` Content-Type names, checked.
pub fn boundary<'a>(content_type: &'a header_params::Element<'_>) -> Result<&'a str, FormError> {
    let boundary = content_type
        .param("boundary")
        .ok_or(FormError::MissingBoundary)?;
    let allowed = |b: u8| b.is_ascii_alphanumeric() || b"'()+_,-./:=? ".contains(&b);
    let valid = (1..=70).contains(&boundary.len())
        && boundary.bytes().all(allowed)
        && !boundary.ends_with(' ');
    valid.then_some(boundary).ok_or(FormError::BadBoundary)
}

/// The content of the form's one part (its headers set aside), or why the
/// form is not one part.
pub fn only_part<'a>(body: &'a [u8], boundary: &str) -> Result<&'a [u8], FormError> {
    let parts = parts(body, boundary)?;
    if let [only] = parts.as_slice() {
        return Ok(only.content);
    }
    let names = |files: bool| -> Vec<Option<String>> {
        parts
            .iter()
            .filter(|p| p.is_file == files)
            .map(|p| p.name.clone())
            .collect()
    };
    let files = parts.iter().filter(|p| p.is_file).count();
    Err(match files {
        _ if parts.is_empty() => FormError::NoParts,
        0 => FormError::SeveralFields {
            names: names(false),
        },
        1 => FormError::ExtraFields {
            names: names(false),
        },
        _ => FormError::SeveralFiles { names: names(true) },
    })
}

/// The parts between the first `--BOUNDARY` line and the closing one; the
/// preamble before and the epilogue after are ignored, as RFC 2046 says.
fn parts<'a>(body: &'a [u8], boundary: &str) -> Result<Vec<Part<'a>>, FormError> {
    let boundary_owned = || boundary.to_owned();
    let dash_boundary = format!("--{boundary}");
    let delimiter = format!("\r\n{dash_boundary}");
    let finder = memmem::Finder::new(delimiter.as_bytes());
    let mut at = if body.starts_with(dash_boundary.as_bytes()) {
        dash_boundary.len()
    } else {
        let found = finder.find(body).ok_or_else(|| FormError::NoDelimiter {
            boundary: boundary_owned(),
        })?;
        found + delimiter.len()
    };
    let mut parts = Vec::new();
    loop {
        let rest = &body[at..];
        if rest.starts_with(b"--") {
            return Ok(parts);
        }
        let start = at + line_end_after_delimiter(rest, boundary)?;
        let length = finder
            .find(&body[start..])
            .ok_or_else(|| FormError::Unterminated {
                boundary: boundary_owned(),
            })?;
        if parts.len() == limits::MAX_FORM_PARTS {
            return Err(FormError::TooManyParts);
        }
        parts.push(part(&body[start..start + length], parts.len() + 1)?);
        at = start + length + delimiter.len();
    }
}

/// How many bytes after a delimiter's boundary end its line: optional
/// spaces and tabs (RFC 2046's transport padding), then CRLF.
fn line_end_after_delimiter(rest: &[u8], boundary: &str) -> Result<usize, FormError> {
    let padding = rest
        .iter()
        .take_while(|b| matches!(b, b' ' | b'\t'))
        .count();
    match &rest[padding..] {
        [b'\r', b'\n', ..] => Ok(padding + 2),
        [] | [b'\r'] => Err(FormError::Unterminated {
            boundary: boundary.to_owned(),
        }),
        _ => Err(FormError::BadDelimiter {
            boundary: boundary.to_owned(),
        }),
    }
}

/// One part: its headers, read for its name and whether it is a file, and
/// its content.
fn part(raw: &[u8], number: usize) -> Result<Part<'_>, FormError> {
    let mut headers = [httparse::EMPTY_HEADER; limits::MAX_PART_HEADERS];
    let bad = |why: String| FormError::PartHead { part: number, why };
    let (length, headers) = match httparse::parse_headers(raw, &mut headers) {
        Ok(httparse::Status::Complete(parsed)) => parsed,
        Ok(httparse::Status::Partial) => {
            return Err(bad("its headers do not end with a blank line".into()))
        }
        Err(httparse::Error::TooManyHeaders) => {
            return Err(bad(format!(
                "more than {} header lines",
                limits::MAX_PART_HEADERS
            )))
        }
        Err(e) => return Err(bad(format!("malformed headers: {e}"))),
    };
    let disposition = headers
        .iter()
        .find(|h| h.name.eq_ignore_ascii_case("content-disposition"))
        .map(|h| String::from_utf8_lossy(h.value).into_owned());
    let element = disposition.as_deref().map(header_params::element);
    let param = |name: &str| element.as_ref().and_then(|e| e.param(name));
    Ok(Part {
        name: param("name").map(str::to_owned),
        is_file: param("filename").is_some() || param("filename*").is_some(),
        content: &raw[length..],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const B: &str = "------------------------a6abca43715a41";

    /// A body as curl -F writes it: each part's headers, a blank line, its
    /// content, then the next delimiter.
    fn form(parts: &[(&str, &[u8])]) -> Vec<u8> {
        let mut body = Vec::new();
        for (headers, content) in parts {
            body.extend_from_slice(format!("--{B}\r\n{headers}\r\n\r\n").as_bytes());
            body.extend_from_slice(content);
            body.extend_from_slice(b"\r\n");
        }
        body.extend_from_slice(format!("--{B}--\r\n").as_bytes());
        body
    }

    const FILE: &str =
        "Content-Disposition: form-data; name=\"scene\"; filename=\"s.txt\"\r\nContent-Type: text/plain";

    #[test]
    fn the_one_part_is_the_content_whatever_its_headers() {
        let scene: &[u8] = b"NEAR 1\r\nLEFT -1\n\r\n--not-the-boundary\r\n";
        assert_eq!(only_part(&form(&[(FILE, scene)]), B), Ok(scene));
        let field = "Content-Disposition: form-data; name=\"scene\"";
        assert_eq!(only_part(&form(&[(field, b"x")]), B), Ok(&b"x"[..]));
        let odd = "X-Whatever: 1\r\nContent-Type: application/octet-stream";
        assert_eq!(only_part(&form(&[(odd, b"")]), B), Ok(&b""[..]));
    }

    #[test]
    fn preamble_padding_and_epilogue_are_skipped() {
        let body =
            format!("a preamble\r\n--{B} \t\r\n{FILE}\r\n\r\nNEAR 1\r\n--{B}--\r\nan epilogue");
        assert_eq!(only_part(body.as_bytes(), B), Ok(&b"NEAR 1"[..]));
    }

    #[test]
    fn more_than_one_part_is_refused_with_their_names() {
        let other = "Content-Disposition: form-data; name=\"b\"; filename*=UTF-8''b.txt";
        let two_files = form(&[(FILE, b"x"), (other, b"y")]);
        assert_eq!(
            only_part(&two_files, B),
            Err(FormError::SeveralFiles {
                names: vec![Some("scene".into()), Some("b".into())]
            })
        );
        let spp = "Content-Disposition: form-data; name=\"spp\"";
        let with_field = form(&[(FILE, b"x"), (spp, b"4")]);
        let error = only_part(&with_field, B).unwrap_err();
        assert_eq!(
            error,
            FormError::ExtraFields {
                names: vec![Some("spp".into())]
            }
        );
        assert!(error.to_string().contains("(\"spp\")"), "{error}");
        let fields = form(&[(spp, b"4"), ("X-A: 1", b"")]);
        assert_eq!(
            only_part(&fields, B).unwrap_err().to_string(),
            "the form has 2 fields (\"spp\", an unnamed part) and no file; send the scene as \
             its one part (curl -F scene=@FILE)"
        );
        assert_eq!(only_part(&form(&[]), B), Err(FormError::NoParts));
    }

    #[test]
    fn broken_framing_is_named() {
        let good = form(&[(FILE, b"NEAR 1")]);
        let cut = &good[..good.len() - B.len() - 10];
        let boundary = || B.to_owned();
        assert_eq!(
            only_part(cut, B),
            Err(FormError::Unterminated {
                boundary: boundary()
            })
        );
        assert_eq!(
            only_part(b"NEAR 1\nLEFT -1\n", B),
            Err(FormError::NoDelimiter {
                boundary: boundary()
            })
        );
        let glued = format!("--{B}x\r\n{FILE}\r\n\r\nNEAR 1\r\n--{B}--");
        assert_eq!(
            only_part(glued.as_bytes(), B),
            Err(FormError::BadDelimiter {
                boundary: boundary()
            })
        );
        let headless = format!("--{B}\r\n{FILE}\r\nNEAR 1\r\n--{B}--");
        assert!(matches!(
            only_part(headless.as_bytes(), B),
            Err(FormError::PartHead { part: 1, .. })
        ));
        assert_eq!(
            only_part(format!("--{B}").as_bytes(), B),
            Err(FormError::Unterminated {
                boundary: boundary()
            })
        );
    }

    #[test]
    fn parts_past_the_limit_are_refused() {
        let many: Vec<(&str, &[u8])> = vec![(FILE, b"x"); limits::MAX_FORM_PARTS + 1];
        assert_eq!(only_part(&form(&many), B), Err(FormError::TooManyParts));
        let most: Vec<(&str, &[u8])> = vec![(FILE, b"x"); limits::MAX_FORM_PARTS];
        assert!(matches!(
            only_part(&form(&most), B),
            Err(FormError::SeveralFiles { .. })
        ));
    }

    #[test]
    fn boundaries_follow_rfc_2046() {
        let of = |ct: &str| {
            let element = header_params::element(ct);
            boundary(&element).map(str::to_owned)
        };
        assert_eq!(
            of(&format!("multipart/form-data; boundary={B}")),
            Ok(B.into())
        );
        assert_eq!(
            of("multipart/form-data; boundary=\"a b:c\""),
            Ok("a b:c".into())
        );
        assert_eq!(of("multipart/form-data"), Err(FormError::MissingBoundary));
        for bad in ["\"\"", "\"a \"", "a@b", &"x".repeat(71), "\"a\\\"b\""] {
            assert_eq!(
                of(&format!("multipart/form-data; boundary={bad}")),
                Err(FormError::BadBoundary),
                "{bad}"
            );
        }
    }
}
