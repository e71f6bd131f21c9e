//! How far an image is from its reference, in the 8-bit levels a viewer sees.

use crate::output::Image;

/// The error of one image against a reference of the same size.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ImageError {
    /// Root mean square difference over every channel of every pixel, in levels.
    pub rmse: f64,
    /// Largest difference in any channel, in levels.
    pub max_diff: u8,
    /// Share of pixels with some channel off by more than one level.
    pub off_by_more_than_one: f64,
    /// Share of pixels that differ at all.
    pub changed: f64,
    /// Share of eye rays whose nearest sphere differs from the reference's,
    /// where the variant's eye rays are the reference's (one sample per pixel).
    pub hit_mismatch: Option<f64>,
}

impl ImageError {
    pub fn between(image: &Image, reference: &Image) -> ImageError {
        assert_eq!(
            (image.width, image.height),
            (reference.width, reference.height),
            "images of different sizes"
        );
        let mut squares = 0u64;
        let mut max_diff = 0u8;
        let mut off = 0usize;
        let mut changed = 0usize;
        for (a, b) in image.rgb.chunks_exact(3).zip(reference.rgb.chunks_exact(3)) {
            let mut worst = 0;
            for (x, y) in a.iter().zip(b) {
                let d = x.abs_diff(*y);
                squares += u64::from(d) * u64::from(d);
                worst = worst.max(d);
            }
            max_diff = max_diff.max(worst);
            off += usize::from(worst > 1);
            changed += usize::from(worst > 0);
        }
        let pixels = (image.rgb.len() / 3).max(1);
        ImageError {
            rmse: (squares as f64 / (3 * pixels) as f64).sqrt(),
            max_diff,
            off_by_more_than_one: off as f64 / pixels as f64,
            changed: changed as f64 / pixels as f64,
            hit_mismatch: None,
        }
    }

    /// Peak signal-to-noise ratio in dB: `20·log10(255 / RMSE)`, infinite
    /// for identical images.
    pub fn psnr(&self) -> f64 {
        if self.rmse == 0.0 {
            f64::INFINITY
        } else {
            20.0 * (255.0 / self.rmse).log10()
        }
    }

    pub fn is_exact(&self) -> bool {
        self.max_diff == 0 && self.hit_mismatch.unwrap_or(0.0) == 0.0
    }
}

/// Share of entries that differ between two nearest-sphere maps.
pub fn mismatch_rate(map: &[Option<u32>], reference: &[Option<u32>]) -> f64 {
    assert_eq!(map.len(), reference.len(), "maps of different sizes");
    let differ = map.iter().zip(reference).filter(|(a, b)| a != b).count();
    differ as f64 / map.len().max(1) as f64
}

/// The median of a non-empty list of durations, in seconds.
pub fn median(mut seconds: Vec<f64>) -> f64 {
    seconds.sort_by(f64::total_cmp);
    let n = seconds.len();
    if n % 2 == 1 {
        seconds[n / 2]
    } else {
        (seconds[n / 2 - 1] + seconds[n / 2]) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(rgb: Vec<u8>) -> Image {
        Image::from_rgb(2, 1, rgb)
    }

    #[test]
    fn identical_images_have_no_error_and_infinite_psnr() {
        let a = image(vec![1, 2, 3, 4, 5, 6]);
        let e = ImageError::between(&a, &a);
        assert_eq!((e.rmse, e.max_diff, e.off_by_more_than_one), (0.0, 0, 0.0));
        assert!(e.psnr().is_infinite() && e.is_exact());
    }

    #[test]
    fn error_counts_levels_and_pixels() {
        // Pixel 0 off by 1 in one channel, pixel 1 off by 4 in one channel.
        let e = ImageError::between(
            &image(vec![1, 2, 3, 4, 5, 6]),
            &image(vec![2, 2, 3, 4, 9, 6]),
        );
        assert_eq!(e.max_diff, 4);
        assert_eq!((e.off_by_more_than_one, e.changed), (0.5, 1.0));
        assert!((e.rmse - (17.0f64 / 6.0).sqrt()).abs() < 1e-12);
        assert!((e.psnr() - 20.0 * (255.0 / e.rmse).log10()).abs() < 1e-12);
    }

    #[test]
    fn mismatch_rate_and_median() {
        assert_eq!(
            mismatch_rate(
                &[Some(1), None, Some(2), None],
                &[Some(1), Some(0), Some(2), None]
            ),
            0.25
        );
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
    }
}
