//! Where `voxtrace render` writes its image, and what it refuses to write
//! over or to.

use super::refusal::Refusal;
use super::scene_input::is_stdin;
use super::CliError;
use crate::output::Format;
use crate::scene::Scene;
use std::fs;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Longest file stem taken from a scene's OUTPUT name, as the service's.
const MAX_STEM_CHARS: usize = 100;

/// Where the image goes.
#[derive(Debug, PartialEq)]
pub enum Destination {
    /// `-o -`: PNG on standard output.
    Stdout,
    File {
        path: PathBuf,
        format: Format,
    },
}

impl Destination {
    /// `-o` as given: `-` for standard output, else a file whose extension
    /// names the format. Any other extension is refused rather than guessed:
    /// `x.jpg` holding a PPM would be a file no viewer opens.
    pub fn given(path: &Path) -> Result<Destination, CliError> {
        if path == Path::new("-") {
            return Ok(Destination::Stdout);
        }
        match Format::from_extension(path) {
            Some(format) => Ok(Destination::File {
                path: path.to_owned(),
                format,
            }),
            None => Err(CliError::Refused(Refusal::UnknownFormat {
                output: path.to_owned(),
            })),
        }
    }

    /// Without `-o`: the scene's OUTPUT name (reduced by [`output_name`]),
    /// else the scene file's stem with `.ppm` (`render.ppm` for standard
    /// input), in the current directory.
    pub fn default_for(scene: &Scene, scene_path: &Path) -> Destination {
        let path = scene
            .output
            .as_deref()
            .and_then(output_name)
            .unwrap_or_else(|| stem_name(scene_path));
        let format = Format::from_path(&path);
        Destination::File { path, format }
    }

    /// The destination's name in messages.
    pub fn name(&self) -> String {
        match self {
            Destination::Stdout => "<stdout>".to_owned(),
            Destination::File { path, .. } => path.display().to_string(),
        }
    }

    pub fn format(&self) -> Format {
        match self {
            Destination::Stdout => Format::Png,
            Destination::File { format, .. } => *format,
        }
    }
}

/// A file name from a scene's OUTPUT, reduced as the service reduces its
/// download names, since the scene may come from anyone: the name's stem,
/// without any directory, of ASCII letters, digits, `-`, `_` and `.` only
/// (others become `_`), at most [`MAX_STEM_CHARS`]; `.png` if the name
/// ends so (any case), else `.ppm`. So OUTPUT can name neither a path, nor
/// standard output, nor a file with control characters, nor the scene
/// file itself (which is not a `.ppm` or `.png`, unless it is, see
/// [`refuse_overwriting`]). `None` when nothing is left.
pub fn output_name(name: &str) -> Option<PathBuf> {
    let path = Path::new(name);
    let stem: String = path
        .file_stem()?
        .to_string_lossy()
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .take(MAX_STEM_CHARS)
        .collect();
    if stem.trim_matches('.').is_empty() {
        return None;
    }
    let format = Format::from_path(path);
    Some(PathBuf::from(format!("{stem}.{}", format.extension())))
}

/// The scene file's stem with `.ppm`: the user's own choice of name;
/// `render.ppm` for standard input, as the service names its downloads.
fn stem_name(scene_path: &Path) -> PathBuf {
    let stem = match scene_path.file_stem() {
        Some(stem) if !is_stdin(scene_path) => stem,
        _ => "render".as_ref(),
    };
    PathBuf::from(stem).with_extension("ppm")
}

/// A PNG on a terminal is noise that can upset it: `-o -` wants a pipe or a file.
pub fn refuse_terminal(destination: &Destination) -> Result<(), CliError> {
    if *destination == Destination::Stdout && std::io::stdout().is_terminal() {
        return Err(CliError::Refused(Refusal::Terminal));
    }
    Ok(())
}

/// Refuses to write the image over the scene file, whatever the path says
/// (another spelling, a link): the same file is the same device and inode.
pub fn refuse_overwriting(destination: &Destination, scene_path: &Path) -> Result<(), CliError> {
    let Destination::File { path: output, .. } = destination else {
        return Ok(());
    };
    if same_file(output, scene_path) {
        return Err(CliError::Refused(Refusal::OverwritesScene {
            output: output.clone(),
            scene: scene_path.to_owned(),
        }));
    }
    Ok(())
}

/// Whether both paths exist and name one file.
fn same_file(a: &Path, b: &Path) -> bool {
    let (Ok(a_meta), Ok(b_meta)) = (fs::metadata(a), fs::metadata(b)) else {
        return false;
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        a_meta.dev() == b_meta.dev() && a_meta.ino() == b_meta.ino()
    }
    #[cfg(not(unix))]
    {
        let _ = (a_meta, b_meta);
        matches!((fs::canonicalize(a), fs::canonicalize(b)), (Ok(x), Ok(y)) if x == y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_names_keep_a_safe_stem_and_an_image_extension() {
        let name = |n: &str| output_name(n).map(|p| p.to_string_lossy().into_owned());
        assert_eq!(name("testSample.ppm").as_deref(), Some("testSample.ppm"));
        assert_eq!(name("shot.PNG").as_deref(), Some("shot.png"));
        assert_eq!(name("a\rb.ppm").as_deref(), Some("a_b.ppm"));
        assert_eq!(
            name("../../etc/pass\"wd x.ppm").as_deref(),
            Some("pass_wd_x.ppm")
        );
        assert_eq!(name("self.txt").as_deref(), Some("self.ppm"));
        assert_eq!(
            name("-").as_deref(),
            Some("-.ppm"),
            "a file, not standard output"
        );
        assert_eq!(name("/"), None);
        assert_eq!(name(".."), None);
        let long = "x".repeat(300);
        assert_eq!(name(&long).unwrap().len(), MAX_STEM_CHARS + ".ppm".len());
    }

    #[test]
    fn given_names_need_an_image_extension() {
        assert_eq!(
            Destination::given(Path::new("-")).unwrap(),
            Destination::Stdout
        );
        let png = Destination::given(Path::new("x.PNG")).unwrap();
        assert_eq!(png.format(), Format::Png);
        for name in ["x.jpg", "x", "x.png.bak"] {
            assert!(
                matches!(
                    Destination::given(Path::new(name)),
                    Err(CliError::Refused(Refusal::UnknownFormat { .. }))
                ),
                "{name}"
            );
        }
        assert_eq!(stem_name(Path::new("-")), PathBuf::from("render.ppm"));
        assert_eq!(stem_name(Path::new("a/b.txt")), PathBuf::from("b.ppm"));
    }

    #[test]
    fn the_same_file_under_another_path_is_the_same_file() {
        let dir = std::env::temp_dir().join(format!("voxtrace-same-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let scene = dir.join("scene.txt");
        fs::write(&scene, "NEAR 1\n").unwrap();
        let other = dir.join("other.ppm");
        assert!(same_file(&scene, &dir.join(".").join("scene.txt")));
        assert!(!same_file(&scene, &other), "does not exist");
        fs::write(&other, "").unwrap();
        assert!(!same_file(&scene, &other));
        #[cfg(unix)]
        {
            let link = dir.join("link.ppm");
            std::os::unix::fs::symlink(&scene, &link).unwrap();
            assert!(same_file(&scene, &link));
        }
        fs::remove_dir_all(&dir).unwrap();
    }
}
