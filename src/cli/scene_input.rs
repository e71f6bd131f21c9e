//! Reading the scene of `voxtrace render`, from a file or from standard
//! input (`-`), within bounds: a regular file larger than the limit is
//! refused before a byte is read, and any other input (a pipe, a device) is
//! refused once it goes past it; the text is parsed as it streams in (see
//! `scene::read`).

use super::refusal::Refusal;
use super::CliError;
use crate::limits;
use crate::scene::{self, Diagnostic, ReadError, Scene, SceneError, TooLarge};
use std::fmt;
use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// How messages name standard input, as compilers and ripgrep do.
const STDIN_ORIGIN: &str = "<stdin>";

/// Whether the scene argument `-` names standard input.
pub fn is_stdin(path: &Path) -> bool {
    path == Path::new("-")
}

/// The scene's name in messages.
fn origin(path: &Path) -> String {
    if is_stdin(path) {
        STDIN_ORIGIN.to_owned()
    } else {
        path.display().to_string()
    }
}

/// Reads and parses the scene at `path` (`-`: standard input), at most
/// `max_bytes` of it.
pub fn read_scene(path: &Path, max_bytes: u64) -> Result<Scene, CliError> {
    let origin = origin(path);
    let result = if is_stdin(path) {
        scene::read(std::io::stdin().lock(), max_bytes)
    } else {
        let file = open_within(path, &origin, max_bytes)?;
        // A regular file's size tells the parser how many spheres to expect.
        let size = file
            .metadata()
            .ok()
            .filter(|m| m.is_file())
            .map(|m| m.len());
        scene::read_expecting(file, max_bytes, size)
    };
    result.map_err(|e| match e {
        ReadError::Io(error) => cannot_read(&origin, error),
        ReadError::TooLarge(e) => too_large(&origin, e),
        ReadError::Scene { error, source_line } => {
            // Past the part of a large file still in memory, the line is read again.
            let source_line = source_line.or_else(|| reread_line(path, &error));
            scene_error(origin, error, source_line)
        }
    })
}

/// Reads the scene at `path` (`-`: standard input) whole, at most
/// `max_bytes` of it, and parses it: the text to send on as it is, and
/// what it says.
pub fn read_scene_text(path: &Path, max_bytes: u64) -> Result<(Vec<u8>, Scene), CliError> {
    let origin = origin(path);
    let mut text = Vec::new();
    let limited = max_bytes.saturating_add(1);
    let read = if is_stdin(path) {
        std::io::stdin().lock().take(limited).read_to_end(&mut text)
    } else {
        let file = open_within(path, &origin, max_bytes)?;
        file.take(limited).read_to_end(&mut text)
    };
    read.map_err(|error| cannot_read(&origin, error))?;
    if text.len() as u64 > max_bytes {
        let limit = max_bytes;
        return Err(too_large(&origin, TooLarge { size: None, limit }));
    }
    match scene::parse(&text) {
        Ok(scene) => Ok((text, scene)),
        Err(error) => {
            let source_line = scene::line_text(&text, error.line);
            Err(scene_error(origin, error, source_line))
        }
    }
}

/// The file at `path`, opened, unless it is a regular file larger than
/// `max_bytes`.
fn open_within(path: &Path, origin: &str, max_bytes: u64) -> Result<File, CliError> {
    let file = File::open(path).map_err(|error| cannot_read(origin, error))?;
    let metadata = file
        .metadata()
        .map_err(|error| cannot_read(origin, error))?;
    if metadata.is_file() && metadata.len() > max_bytes {
        let size = Some(metadata.len());
        return Err(too_large(
            origin,
            TooLarge {
                size,
                limit: max_bytes,
            },
        ));
    }
    Ok(file)
}

/// The text of `error`'s line, read again from the regular file at `path`;
/// `None` for standard input, other kinds of file, or a file changed since.
fn reread_line(path: &Path, error: &SceneError) -> Option<String> {
    if is_stdin(path) || !error.is_located() || !std::fs::metadata(path).ok()?.is_file() {
        return None;
    }
    let mut reader = BufReader::new(File::open(path).ok()?);
    let mut line = Vec::new();
    for _ in 0..error.line {
        line.clear();
        // No line before the error's is longer than the limit; its own may be.
        let bound = limits::MAX_LINE_BYTES as u64 + 1;
        if (&mut reader)
            .take(bound)
            .read_until(b'\n', &mut line)
            .ok()?
            == 0
        {
            return None;
        }
    }
    scene::line_text(&line, 1)
}

/// A scene that does not parse, with what its message shows.
#[derive(Debug)]
pub struct BadScene {
    /// The scene's name: its path, or `<stdin>`.
    pub origin: String,
    pub error: SceneError,
    /// The text of the error's line, when it could be had.
    pub source_line: Option<String>,
}

impl fmt::Display for BadScene {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let diagnostic = Diagnostic::new(&self.error, &self.origin, self.source_line.as_deref());
        write!(f, "{diagnostic}")
    }
}

fn scene_error(origin: String, error: SceneError, source_line: Option<String>) -> CliError {
    CliError::Scene(Box::new(BadScene {
        origin,
        error,
        source_line,
    }))
}

fn cannot_read(origin: &str, error: std::io::Error) -> CliError {
    CliError::Read {
        what: origin.to_owned(),
        error,
    }
}

fn too_large(origin: &str, error: TooLarge) -> CliError {
    CliError::Refused(Refusal::TooLarge {
        scene: origin.to_owned(),
        error,
    })
}
