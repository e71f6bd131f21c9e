//! `voxtrace render --size`: the image's size for this render, in place of
//! the scene's RES, for quick previews (POV-Ray's `+W`/`+H`).
//!
//! The camera's window (LEFT, RIGHT, BOTTOM, TOP at NEAR) is kept, so the
//! field of view is the scene's and only the pixel count changes; a size of
//! another aspect than RES's stretches the image, as POV-Ray's does when
//! `+W`/`+H` change and its camera does not. `--size W` alone keeps RES's
//! aspect. One value (`WxH`), not two: a second would swallow the scene's
//! path in `render --size 200 scene.txt`.

use crate::scene::{image_side, SceneErrorKind, COLUMNS_FIELD, ROWS_FIELD};
use std::fmt;
use std::str::FromStr;

/// `W` or `WxH`, each side a whole number from 1 to `limits::MAX_RESOLUTION`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Size {
    width: u32,
    height: Option<u32>,
}

/// A side of `--size` that is no image side: the same message as RES's.
#[derive(Clone, Debug, PartialEq)]
pub struct SizeError(SceneErrorKind);

impl fmt::Display for SizeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.0)
    }
}

impl std::error::Error for SizeError {}

fn side(field: &'static str, text: &str) -> Result<u32, SizeError> {
    let value = text.trim().parse::<f64>().map_err(|_| {
        SizeError(SceneErrorKind::NotWhole {
            field,
            found: text.to_owned(),
        })
    })?;
    image_side(field, value).map_err(SizeError)
}

impl FromStr for Size {
    type Err = SizeError;

    fn from_str(text: &str) -> Result<Size, SizeError> {
        match text.split_once(['x', 'X', '×']) {
            Some((w, h)) => Ok(Size {
                width: side(COLUMNS_FIELD, w)?,
                height: Some(side(ROWS_FIELD, h)?),
            }),
            None => Ok(Size {
                width: side(COLUMNS_FIELD, text)?,
                height: None,
            }),
        }
    }
}

impl Size {
    /// The size to render a scene of RES `columns` × `rows` at: the height
    /// given, or the one that keeps RES's aspect (rounded, at least 1).
    pub fn apply(self, columns: u32, rows: u32) -> Result<(u32, u32), SizeError> {
        let height = match self.height {
            Some(height) => height,
            None => {
                let kept = (f64::from(self.width) * f64::from(rows) / f64::from(columns)).round();
                image_side(ROWS_FIELD, kept.max(1.0)).map_err(SizeError)?
            }
        };
        Ok((self.width, height))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_sides_or_the_width_alone() {
        let size: Size = "320x200".parse().unwrap();
        assert_eq!(size.apply(600, 600), Ok((320, 200)));
        let size: Size = "300".parse().unwrap();
        assert_eq!(size.apply(600, 400), Ok((300, 200)));
        assert_eq!(size.apply(16384, 1), Ok((300, 1)), "at least one row");
        assert_eq!("64×48".parse::<Size>().unwrap().apply(1, 1), Ok((64, 48)));
    }

    #[test]
    fn sides_are_refused_as_res_refuses_them() {
        let message = |text: &str| text.parse::<Size>().unwrap_err().to_string();
        assert_eq!(
            message("0x10"),
            "the number of columns must be between 1 and 16384, found 0"
        );
        assert_eq!(
            message("10x20000"),
            "the number of rows must be between 1 and 16384, found 20000"
        );
        assert_eq!(
            message("10xabc"),
            "the number of rows must be a whole number, found \"abc\""
        );
        assert_eq!(
            message("1.5"),
            "the number of columns must be a whole number, found \"1.5\""
        );
        let tall: Size = "16384".parse().unwrap();
        assert!(
            tall.apply(1, 2).is_err(),
            "the kept aspect is past the limit"
        );
    }
}
