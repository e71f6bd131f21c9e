//! Reading a scene from a stream, within bounds: the text is parsed piece by
//! piece as it arrives, so memory holds one piece rather than the file, an
//! error near the start ends the read there, and a stream that never ends
//! a line, or goes on past a size limit, is refused as soon as it does.

use super::lines::{line_text, CHUNK_BYTES};
use super::parse::Parser;
use super::{Scene, SceneError};
use std::fmt;
use std::io::{self, Read};

/// Bytes read and parsed at a time: enough chunks to keep every core busy
/// parsing, little enough that an early error ends the read early.
const PIECE_BYTES: usize = 8 * CHUNK_BYTES;

#[derive(Debug)]
pub enum ReadError {
    Io(io::Error),
    /// The text goes on past its limit.
    TooLarge(TooLarge),
    /// The text is not a scene; `source_line` is the text of the error's
    /// line when it was still in memory (always, for a text of less than
    /// [`PIECE_BYTES`]).
    Scene {
        error: SceneError,
        source_line: Option<String>,
    },
}

impl fmt::Display for ReadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ReadError::Io(e) => write!(f, "{e}"),
            ReadError::TooLarge(e) => write!(f, "{e}"),
            ReadError::Scene { error, .. } => write!(f, "{error}"),
        }
    }
}

impl std::error::Error for ReadError {}

/// A scene text larger than the limit it is read under: the one wording of
/// the command line's `--max-scene-bytes` and the service's `--max-body`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TooLarge {
    /// Its size, when known before it is read (a file's, a `Content-Length`).
    pub size: Option<u64>,
    pub limit: u64,
}

impl fmt::Display for TooLarge {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.size {
            Some(size) => write!(
                f,
                "the scene has {size} bytes, more than the limit of {}",
                self.limit
            ),
            None => write!(
                f,
                "the scene has more than the limit of {} bytes",
                self.limit
            ),
        }
    }
}

/// Reads and parses the scene text of `source`, at most `max_bytes` of it.
/// The scene, or the error, is the one `scene::parse` gives on the whole
/// text, except that a text past `max_bytes` is [`ReadError::TooLarge`].
pub fn read(source: impl Read, max_bytes: u64) -> Result<Scene, ReadError> {
    read_expecting(source, max_bytes, None)
}

/// [`read`] of a text expected to be `expected` bytes long (a regular
/// file's size, known before a byte is read): once its first piece is
/// parsed, the scene's spheres get room for the whole text at the rate that
/// piece holds them ([`Parser::expect_bytes`]), so that they are written
/// once into pages faulted in once, rather than copied each time their
/// vector doubles. The result does not depend on it.
pub fn read_expecting(
    mut source: impl Read,
    max_bytes: u64,
    mut expected: Option<u64>,
) -> Result<Scene, ReadError> {
    let mut parser = Parser::new();
    let mut piece = Vec::with_capacity(PIECE_BYTES);
    let mut total = 0u64;
    loop {
        // One byte more than the limit allows tells a text past it.
        let room = max_bytes.saturating_sub(total).saturating_add(1);
        let want = (PIECE_BYTES.saturating_sub(piece.len()) as u64).clamp(1, room);
        let got = source
            .by_ref()
            .take(want)
            .read_to_end(&mut piece)
            .map_err(ReadError::Io)? as u64;
        total += got;
        if total > max_bytes {
            let limit = max_bytes;
            return Err(ReadError::TooLarge(TooLarge { size: None, limit }));
        }
        // The piece's lines are numbered from here on.
        let first = parser.next_line();
        let in_piece = |error: SceneError| {
            let source_line = error
                .line
                .checked_sub(first)
                .and_then(|i| line_text(&piece, i + 1));
            ReadError::Scene { error, source_line }
        };
        if got < want {
            return parser
                .feed(&piece)
                .and_then(|()| parser.finish())
                .map_err(in_piece);
        }
        // Whole lines go to the parser; the start of the next waits for its end.
        let cut = piece.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
        parser.feed(&piece[..cut]).map_err(in_piece)?;
        if let Some(total) = expected.take() {
            // No more than the limit is ever read.
            parser.expect_bytes(total.min(max_bytes));
        }
        parser.check_unfinished(&piece[cut..]).map_err(in_piece)?;
        piece.drain(..cut);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::limits;
    use crate::scene::{parse, SceneErrorKind};

    const HEAD: &str = "NEAR 1\nLEFT -1\nRIGHT 1\nBOTTOM -1\nTOP 1\nRES 4 4\n";

    /// A text of several pieces, read in reads of every size, gives what
    /// `parse` gives on the whole of it.
    #[test]
    fn pieces_read_like_the_whole_text() {
        let mut text = String::from(HEAD);
        let mut i = 0;
        while text.len() < 2 * PIECE_BYTES + 12345 {
            text += &format!("SPHERE s{i} {i} 0 -5 1 1 1 0.5 0.5 0.5 1 1 1 0 50\r\n");
            i += 1;
        }
        text += "LIGHT l 0 0 0 1 1 1"; // no newline at the end
        let whole = parse(&text).unwrap();
        let read = read(text.as_bytes(), u64::MAX).unwrap();
        assert_eq!(read, whole);
        // An error far in is found at the same line and column.
        let bad = format!("{text}\nNEAR 2\n");
        let expected = parse(&bad).unwrap_err();
        match super::read(bad.as_bytes(), u64::MAX) {
            Err(ReadError::Scene { error, source_line }) => {
                assert_eq!(error, expected);
                assert_eq!(source_line.as_deref(), Some("NEAR 2"));
            }
            other => panic!("{other:?}"),
        }
    }

    /// A text's expected length changes nothing it says, whether right,
    /// short or far off; right, it gives the spheres their room at once
    /// (grown piece by piece, the vector would double past them).
    #[test]
    fn the_expected_length_is_only_a_hint() {
        let mut text = String::from(HEAD);
        let mut i = 0;
        while text.len() < 2 * PIECE_BYTES + PIECE_BYTES / 2 {
            text += &format!("SPHERE s{i} {i} 0 -5 1 1 1 0.5 0.5 0.5 1 1 1 0 50\n");
            i += 1;
        }
        let whole = parse(&text).unwrap();
        let length = text.len() as u64;
        for expected in [
            None,
            Some(0),
            Some(length / 3),
            Some(length),
            Some(10 * length),
        ] {
            let read = read_expecting(text.as_bytes(), u64::MAX, expected).unwrap();
            assert_eq!(read, whole, "{expected:?}");
            if expected == Some(length) {
                let (len, room) = (read.spheres.len(), read.spheres.capacity());
                assert!(room >= len && room <= len + len / 8, "{room} for {len}");
            }
        }
    }

    /// Reads that return a few bytes at a time, as a pipe's do.
    struct Trickle<'a>(&'a [u8]);

    impl Read for Trickle<'_> {
        fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
            let n = out.len().min(self.0.len()).min(7);
            out[..n].copy_from_slice(&self.0[..n]);
            self.0 = &self.0[n..];
            Ok(n)
        }
    }

    #[test]
    fn short_reads_change_nothing() {
        let text = format!("{HEAD}SPHERE s 0 0 -5 1 1 1 0.5 0.5 0.5 1 1 1 0 50\n");
        assert_eq!(
            read(Trickle(text.as_bytes()), u64::MAX).unwrap(),
            parse(&text).unwrap()
        );
    }

    /// An endless stream of zeros, or of one endless line, ends at once.
    #[test]
    fn endless_streams_are_refused_on_their_first_line() {
        match read(io::repeat(0), u64::MAX) {
            Err(ReadError::Scene { error: e, .. }) => {
                assert_eq!(
                    (e.line, e.column, e.kind),
                    (
                        1,
                        1,
                        SceneErrorKind::Binary {
                            byte: 0,
                            format: None
                        }
                    )
                )
            }
            other => panic!("{other:?}"),
        }
        let endless = b"# a comment".chain(io::repeat(b'x'));
        match read(endless, u64::MAX) {
            Err(ReadError::Scene { error: e, .. }) => {
                assert_eq!((e.line, e.kind), (1, SceneErrorKind::LineTooLong));
                assert_eq!(e.column, limits::MAX_LINE_BYTES + 1);
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_size_limit_admits_its_own_size_and_no_byte_more() {
        let text = format!("{HEAD}# padding\n");
        let size = text.len() as u64;
        assert!(read(text.as_bytes(), size).is_ok());
        assert!(matches!(
            read(text.as_bytes(), size - 1),
            Err(ReadError::TooLarge(TooLarge { size: None, limit })) if limit == size - 1
        ));
    }
}
