//! Reading the scene file of `voxtrace render`, within bounds: a regular file
//! larger than the limit is refused before a byte is read, and any other
//! input (a pipe, a device) is refused once it goes past it; the text is
//! parsed as it streams in (see `scene::read`).

use super::refusal::Refusal;
use super::CliError;
use crate::scene::{self, ReadError, Scene};
use std::fs::File;
use std::path::Path;

/// Reads and parses the scene at `path`, at most `max_bytes` of it.
pub fn read_scene(path: &Path, max_bytes: u64) -> Result<Scene, CliError> {
    let (file, display) = open_within(path, max_bytes)?;
    scene::read(file, max_bytes).map_err(|e| match e {
        ReadError::Io(error) => cannot_read(&display, error),
        ReadError::TooLarge { limit } => too_large(&display, limit),
        ReadError::Scene(error) => CliError::Scene {
            path: display.clone(),
            error,
        },
    })
}

/// Reads the scene at `path` whole, at most `max_bytes` of it, and parses
/// it: the text to send on as it is, and what it says.
pub fn read_scene_text(path: &Path, max_bytes: u64) -> Result<(Vec<u8>, Scene), CliError> {
    use std::io::Read;
    let (file, display) = open_within(path, max_bytes)?;
    let mut text = Vec::new();
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut text)
        .map_err(|error| cannot_read(&display, error))?;
    if text.len() as u64 > max_bytes {
        return Err(too_large(&display, max_bytes));
    }
    let scene = scene::parse(&text).map_err(|error| CliError::Scene {
        path: display.clone(),
        error,
    })?;
    Ok((text, scene))
}

/// The file at `path`, opened, unless it is a regular file larger than
/// `max_bytes`; and its name for messages.
fn open_within(path: &Path, max_bytes: u64) -> Result<(File, String), CliError> {
    let display = path.display().to_string();
    let file = File::open(path).map_err(|error| cannot_read(&display, error))?;
    let metadata = file
        .metadata()
        .map_err(|error| cannot_read(&display, error))?;
    if metadata.is_file() && metadata.len() > max_bytes {
        return Err(too_large(&display, max_bytes));
    }
    Ok((file, display))
}

fn cannot_read(display: &str, error: std::io::Error) -> CliError {
    CliError::Read {
        what: display.to_owned(),
        error,
    }
}

fn too_large(display: &str, limit: u64) -> CliError {
    CliError::Refused(Refusal::TooLarge {
        scene: display.to_owned(),
        limit,
    })
}
