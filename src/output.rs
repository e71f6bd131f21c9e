//! The framebuffer and its encodings.

use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder};
use std::fmt;
use std::path::Path;

/// An 8-bit RGB image, top row first.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

/// The file formats voxtrace writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Binary PPM (P6).
    Ppm,
    Png,
}

impl Format {
    pub const ALL: [Format; 2] = [Format::Png, Format::Ppm];

    /// The format `path`'s extension names (`.png`, `.ppm`, any case), if any.
    pub fn from_extension(path: &Path) -> Option<Format> {
        let extension = path.extension()?.to_str()?;
        Format::ALL
            .into_iter()
            .find(|f| extension.eq_ignore_ascii_case(f.extension()))
    }

    /// PNG for `.png` (any case), PPM otherwise: for a name that must end
    /// in one of the two whatever it says (a scene's OUTPUT).
    pub fn from_path(path: &Path) -> Format {
        Format::from_extension(path).unwrap_or(Format::Ppm)
    }

    /// `.png and .ppm`: the extensions voxtrace writes, for messages.
    pub fn extensions() -> String {
        let names: Vec<String> = Format::ALL
            .iter()
            .map(|f| format!(".{}", f.extension()))
            .collect();
        names.join(" and ")
    }

    pub fn mime_type(self) -> &'static str {
        match self {
            Format::Ppm => "image/x-portable-pixmap",
            Format::Png => "image/png",
        }
    }

    pub fn extension(self) -> &'static str {
        match self {
            Format::Ppm => "ppm",
            Format::Png => "png",
        }
    }
}

#[derive(Debug)]
pub struct EncodeError(image::ImageError);

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cannot encode the image: {}", self.0)
    }
}

impl std::error::Error for EncodeError {}

impl Image {
    pub fn from_rgb(width: u32, height: u32, rgb: Vec<u8>) -> Self {
        assert_eq!(
            rgb.len(),
            width as usize * height as usize * 3,
            "RGB buffer size"
        );
        Image { width, height, rgb }
    }

    pub fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// `P6\n<W> <H>\n255\n` then the pixels. Written by hand because the
    /// format's reference header puts maxval on its own line, which the
    /// `image` crate's encoder does not.
    pub fn to_ppm(&self) -> Vec<u8> {
        let mut out = format!("P6\n{} {}\n255\n", self.width, self.height).into_bytes();
        out.extend_from_slice(&self.rgb);
        out
    }

    pub fn to_png(&self) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::with_capacity(self.rgb.len() / 4 + 1024);
        PngEncoder::new(&mut out)
            .write_image(&self.rgb, self.width, self.height, ExtendedColorType::Rgb8)
            .map_err(EncodeError)?;
        Ok(out)
    }

    pub fn encode(&self, format: Format) -> Result<Vec<u8>, EncodeError> {
        match format {
            Format::Ppm => Ok(self.to_ppm()),
            Format::Png => self.to_png(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extensions_name_formats_in_any_case_and_others_none() {
        let of = |p: &str| Format::from_extension(Path::new(p));
        assert_eq!(of("a.png"), Some(Format::Png));
        assert_eq!(of("a.PPM"), Some(Format::Ppm));
        assert_eq!(of("a.jpg"), None);
        assert_eq!(of("png"), None, "a name, not an extension");
        assert_eq!(Format::from_path(Path::new("a.jpg")), Format::Ppm);
        assert_eq!(Format::extensions(), ".png and .ppm");
    }

    #[test]
    fn ppm_header_and_png_round_trip() {
        let img = Image::from_rgb(2, 1, vec![255, 0, 0, 0, 0, 255]);
        assert_eq!(img.to_ppm(), b"P6\n2 1\n255\n\xff\x00\x00\x00\x00\xff");
        let png = image::load_from_memory(&img.to_png().unwrap())
            .unwrap()
            .to_rgb8();
        assert_eq!(png.as_raw(), &img.rgb);
    }
}
