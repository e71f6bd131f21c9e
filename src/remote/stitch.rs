//! Tiles back into one image.

use crate::output::Image;
use crate::render::Region;

/// The pixels of a binary PPM that the service wrote for `region`: its
/// header must name the region's size and 255 levels, and the pixels fill
/// the rest exactly. `None` for anything else.
pub fn decode_tile(ppm: &[u8], region: &Region) -> Option<Vec<u8>> {
    let header = format!("P6\n{} {}\n255\n", region.width(), region.height());
    let pixels = ppm.strip_prefix(header.as_bytes())?;
    (pixels.len() as u64 == 3 * region.pixels()).then(|| pixels.to_vec())
}

/// Copies a tile's pixels (`rgb`, its rows top first) into `image` at `region`.
pub fn paste(image: &mut Image, region: &Region, rgb: &[u8]) {
    let row_bytes = 3 * region.width() as usize;
    for (i, row) in rgb.chunks_exact(row_bytes).enumerate() {
        let y = region.y0 as usize + i;
        let at = 3 * (y * image.width as usize + region.x0 as usize);
        image.rgb[at..at + row_bytes].copy_from_slice(row);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tile_decodes_only_at_its_own_size_and_pastes_in_place() {
        let region = Region {
            x0: 1,
            y0: 1,
            x1: 3,
            y1: 2,
        };
        let mut ppm = b"P6\n2 1\n255\n".to_vec();
        ppm.extend([1, 2, 3, 4, 5, 6]);
        let rgb = decode_tile(&ppm, &region).unwrap();
        assert_eq!(decode_tile(&ppm[..ppm.len() - 1], &region), None);
        assert_eq!(decode_tile(&ppm, &Region { x1: 2, ..region }), None);
        let mut image = Image::from_rgb(3, 2, vec![0; 18]);
        paste(&mut image, &region, &rgb);
        assert_eq!(&image.rgb[9..], &[0, 0, 0, 1, 2, 3, 4, 5, 6]);
        assert!(image.rgb[..9].iter().all(|&b| b == 0));
    }
}
