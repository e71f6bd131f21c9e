//! Scene text as lines: where they end, how the text is cut into chunks
//! for parallel parsing, and what a line must be before its tokens are read
//! (not too long, and near the start of the text, not binary).

use super::binary::{is_control, signature};
use super::{SceneError, SceneErrorKind};
use crate::limits;

/// Bytes per chunk of parallel parsing; smaller texts parse in one chunk.
pub(super) const CHUNK_BYTES: usize = 1 << 20;

/// Cuts `text` into chunks that end just after a newline (the last chunk
/// ends where the text does).
pub(super) fn split_chunks(text: &[u8]) -> Vec<&[u8]> {
    let mut chunks = Vec::with_capacity(text.len() / CHUNK_BYTES + 1);
    let mut rest = text;
    while rest.len() > CHUNK_BYTES {
        match rest[CHUNK_BYTES..].iter().position(|&b| b == b'\n') {
            Some(i) => {
                let (head, tail) = rest.split_at(CHUNK_BYTES + i + 1);
                chunks.push(head);
                rest = tail;
            }
            None => break,
        }
    }
    chunks.push(rest);
    chunks
}

/// The lines of `text`, without their LF or CRLF endings.
pub(super) fn split_lines(text: &[u8]) -> impl Iterator<Item = &[u8]> {
    let text = text.strip_suffix(b"\n").unwrap_or(text);
    // An empty input has no lines at all rather than one empty line.
    let mut rest = (!text.is_empty()).then_some(text);
    std::iter::from_fn(move || {
        let left = rest?;
        let line = match memchr::memchr(b'\n', left) {
            Some(end) => {
                rest = Some(&left[end + 1..]);
                &left[..end]
            }
            None => {
                rest = None;
                left
            }
        };
        Some(line.strip_suffix(b"\r").unwrap_or(line))
    })
}

/// The text of line `number` (from 1) of `text`, for an error message;
/// `None` past the last line.
/// At most [`limits::MAX_LINE_BYTES`] and one byte of it, as the parser
/// reads no more of a line.
pub fn line_text(text: &[u8], number: usize) -> Option<String> {
    let line = split_lines(text).nth(number.checked_sub(1)?)?;
    let line = &line[..line.len().min(limits::MAX_LINE_BYTES + 1)];
    Some(String::from_utf8_lossy(line).into_owned())
}

/// The 1-based character column of byte offset `offset` of `line`.
pub(super) fn column_of(line: &[u8], offset: usize) -> usize {
    String::from_utf8_lossy(&line[..offset.min(line.len())])
        .chars()
        .count()
        + 1
}

/// Checks line number `number`, which starts `start` bytes into the text
/// (a line so long that only its beginning has been read is judged on that).
pub(super) fn check_line(number: usize, start: usize, line: &[u8]) -> Result<(), SceneError> {
    let error = |offset: usize, kind| SceneError {
        line: number,
        column: column_of(line, offset),
        kind,
    };
    if let Some(format) = (start == 0).then(|| signature(line)).flatten() {
        let byte = line[0];
        let format = Some(format);
        return Err(error(0, SceneErrorKind::Binary { byte, format }));
    }
    if start < limits::BINARY_SNIFF_BYTES {
        let sniffed = &line[..line.len().min(limits::BINARY_SNIFF_BYTES - start)];
        if let Some(offset) = sniffed.iter().position(|&b| is_control(b)) {
            let byte = line[offset];
            let format = None;
            return Err(error(offset, SceneErrorKind::Binary { byte, format }));
        }
    }
    if line.len() > limits::MAX_LINE_BYTES {
        return Err(error(limits::MAX_LINE_BYTES, SceneErrorKind::LineTooLong));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn control_bytes_near_the_start_are_binary_and_point_at_the_byte() {
        let e = check_line(3, 40, b"SPHERE \x00\x00").unwrap_err();
        assert_eq!((e.line, e.column), (3, 8));
        assert_eq!(
            e.kind,
            SceneErrorKind::Binary {
                byte: 0,
                format: None
            }
        );
        assert!(check_line(1, 0, "NEAR\t1\r # é".as_bytes()).is_ok());
        let e = check_line(1, 0, b"\x1b[0m").unwrap_err();
        assert_eq!(
            e.kind,
            SceneErrorKind::Binary {
                byte: 0x1b,
                format: None
            }
        );
        // Past the first bytes, such bytes are left to the tokens.
        assert!(check_line(9, limits::BINARY_SNIFF_BYTES, b"NEAR \x00").is_ok());
        let straddling = [b'x'; 16];
        assert!(check_line(2, limits::BINARY_SNIFF_BYTES - 16, &straddling).is_ok());
    }

    #[test]
    fn lines_end_at_lf_or_crlf_and_a_last_newline_ends_no_empty_line() {
        fn lines(text: &str) -> Vec<&[u8]> {
            split_lines(text.as_bytes()).collect()
        }
        assert!(lines("").is_empty());
        assert!(lines("\n").is_empty());
        assert_eq!(lines("a"), [b"a"]);
        assert_eq!(lines("a\r\n\nb\r"), [&b"a"[..], b"", b"b"]);
        assert_eq!(lines("a\n\n"), [&b"a"[..], b""]);
        assert_eq!(lines("\r\r\n"), [b"\r"]);
    }

    proptest::proptest! {
        #[test]
        fn lines_are_the_pieces_between_newlines(text in "[a\r\n]{0,12}") {
            let text = text.as_bytes();
            let trimmed = text.strip_suffix(b"\n").unwrap_or(text);
            let pieces = trimmed.split(|&b| b == b'\n');
            let expected: Vec<&[u8]> = pieces
                .filter(|_| !trimmed.is_empty())
                .map(|l| l.strip_suffix(b"\r").unwrap_or(l))
                .collect();
            proptest::prop_assert_eq!(split_lines(text).collect::<Vec<_>>(), expected);
        }
    }

    #[test]
    fn long_lines_fail_just_past_the_limit() {
        let line = vec![b'#'; limits::MAX_LINE_BYTES + 1];
        let e = check_line(5, 1 << 20, &line).unwrap_err();
        assert_eq!((e.line, e.column), (5, limits::MAX_LINE_BYTES + 1));
        assert!(check_line(5, 1 << 20, &line[1..]).is_ok());
    }
}
