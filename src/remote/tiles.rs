//! Cutting a frame into tiles.

use crate::render::Region;

/// About `n` tiles covering a `width` × `height` image exactly once, row by
/// row: a grid of columns and rows chosen so that tiles are near square
/// (which keeps the eye-ray packets inside a tile full), with edges split
/// as evenly as whole pixels allow. About `n` of them, never more than
/// twice as many, and fewer when the image has fewer pixels.
pub fn plan(width: u32, height: u32, n: u32) -> Vec<Region> {
    let n = f64::from(n.max(1));
    let aspect = f64::from(width) / f64::from(height);
    // Never more columns than tiles: a wide, short image gets a row of them.
    let columns = ((n * aspect).sqrt().round() as u32).clamp(1, width.min(n as u32));
    let rows = ((n / f64::from(columns)).round() as u32).clamp(1, height);
    let cut =
        |i: u32, parts: u32, side: u32| (u64::from(i) * u64::from(side) / u64::from(parts)) as u32;
    let mut tiles = Vec::with_capacity((columns * rows) as usize);
    for r in 0..rows {
        for c in 0..columns {
            tiles.push(Region {
                x0: cut(c, columns, width),
                y0: cut(r, rows, height),
                x1: cut(c + 1, columns, width),
                y1: cut(r + 1, rows, height),
            });
        }
    }
    tiles
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiles_cover_the_image_once_and_are_about_as_many_as_asked() {
        for (w, h, n) in [
            (600, 600, 16),
            (4096, 4096, 7),
            (37, 5, 100),
            (1, 1, 9),
            (1000, 10, 4),
        ] {
            let tiles = plan(w, h, n);
            let mut seen = vec![0u8; (w * h) as usize];
            for t in &tiles {
                assert_eq!(t.within(w, h), Ok(*t), "{w}×{h} / {n}: {t}");
                for y in t.rows() {
                    for x in t.columns() {
                        seen[(y * w + x) as usize] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&s| s == 1), "{w}×{h} / {n}");
            assert!(
                tiles.len() as u32 <= (w * h).min(2 * n),
                "{w}×{h} / {n}: {}",
                tiles.len()
            );
        }
        assert_eq!(plan(600, 600, 16).len(), 16);
    }
}
