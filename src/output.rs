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
    /// PNG for `.png` (any case), PPM otherwise.
    pub fn from_path(path: &Path) -> Format {
        match path.extension().and_then(|e| e.to_str()) {
            Some(ext) if ext.eq_ignore_ascii_case("png") => Format::Png,
            _ => Format::Ppm,
        }
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
    fn ppm_header_and_png_round_trip() {
        let img = Image::from_rgb(2, 1, vec![255, 0, 0, 0, 0, 255]);
        assert_eq!(img.to_ppm(), b"P6\n2 1\n255\n\xff\x00\x00\x00\x00\xff");
        let png = image::load_from_memory(&img.to_png().unwrap())
            .unwrap()
            .to_rgb8();
        assert_eq!(png.as_raw(), &img.rgb);
    }
}
