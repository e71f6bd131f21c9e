//! What `voxtrace render` refuses to do, though the arguments parse: each is
//! a usage error (exit code 2) with its reason.

use crate::output::Format;
use crate::scene::TooLarge;
use std::fmt;
use std::path::PathBuf;

#[derive(Debug, PartialEq)]
pub enum Refusal {
    /// The scene file is larger than `--max-scene-bytes`.
    TooLarge { scene: String, error: TooLarge },
    /// The image would go over the scene file itself.
    OverwritesScene { output: PathBuf, scene: PathBuf },
    /// `-o -` with standard output on a terminal.
    Terminal,
    /// `-o` names a file whose extension is no format voxtrace writes.
    UnknownFormat { output: PathBuf },
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Refusal::TooLarge { scene, error } => {
                write!(f, "{scene}: {error}; --max-scene-bytes raises the limit")
            }
            Refusal::OverwritesScene { output, scene } => write!(
                f,
                "{} is the scene file {} itself: refusing to write the image over it",
                output.display(),
                scene.display()
            ),
            Refusal::UnknownFormat { output } => write!(
                f,
                "{}: cannot tell the image format from the name; voxtrace writes {} (or PNG to standard output with -o -)",
                output.display(),
                Format::extensions()
            ),
            Refusal::Terminal => write!(
                f,
                "standard output is a terminal: redirect it (`-o - > image.png`) or name a file with -o"
            ),
        }
    }
}
