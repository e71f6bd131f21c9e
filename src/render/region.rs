//! A rectangle of the image to render on its own, as render farms split a
//! frame (POV-Ray's `+SR/+ER`, Blender's border render).

use std::fmt;
use std::ops::Range;
use std::str::FromStr;

/// Pixels `x0..x1` × `y0..y1` of the output image: origin top left, the
/// ends exclusive. Every pixel is sampled exactly as in the whole image
/// (the jitter is seeded by the pixel), so a region's bytes are the crop
/// of the full render's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

/// Why a region cannot be rendered.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RegionError {
    /// Not four whole numbers separated by commas.
    Malformed(String),
    /// X1 ≤ X0 or Y1 ≤ Y0: no pixel at all.
    Empty(Region),
    /// Reaches past the image's edge.
    Outside {
        region: Region,
        width: u32,
        height: u32,
    },
}

impl fmt::Display for RegionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RegionError::Malformed(text) => write!(
                f,
                "a region is X0,Y0,X1,Y1 (four whole numbers, X1 and Y1 exclusive), found {text:?}"
            ),
            RegionError::Empty(r) => write!(
                f,
                "the region {r} is empty: X1 must exceed X0 and Y1 must exceed Y0"
            ),
            RegionError::Outside {
                region,
                width,
                height,
            } => write!(
                f,
                "the region {region} reaches outside the {width}×{height} image"
            ),
        }
    }
}

impl std::error::Error for RegionError {}

impl fmt::Display for Region {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{},{}", self.x0, self.y0, self.x1, self.y1)
    }
}

impl FromStr for Region {
    type Err = RegionError;

    /// `X0,Y0,X1,Y1`; whether it fits an image is [`Region::within`]'s to say.
    fn from_str(text: &str) -> Result<Region, RegionError> {
        let malformed = || RegionError::Malformed(text.to_owned());
        let numbers: Vec<u32> = text
            .split(',')
            .map(|n| n.trim().parse::<u32>().map_err(|_| malformed()))
            .collect::<Result<_, _>>()?;
        let [x0, y0, x1, y1] = numbers[..] else {
            return Err(malformed());
        };
        Ok(Region { x0, y0, x1, y1 })
    }
}

impl Region {
    /// The whole of a `width` × `height` image.
    pub fn whole(width: u32, height: u32) -> Region {
        Region {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    /// The region, if it holds a pixel and lies inside a `width` × `height` image.
    pub fn within(self, width: u32, height: u32) -> Result<Region, RegionError> {
        if self.x1 <= self.x0 || self.y1 <= self.y0 {
            return Err(RegionError::Empty(self));
        }
        if self.x1 > width || self.y1 > height {
            return Err(RegionError::Outside {
                region: self,
                width,
                height,
            });
        }
        Ok(self)
    }

    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }

    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }

    pub fn pixels(&self) -> u64 {
        u64::from(self.width()) * u64::from(self.height())
    }

    pub fn columns(&self) -> Range<u32> {
        self.x0..self.x1
    }

    pub fn rows(&self) -> Range<u32> {
        self.y0..self.y1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_four_numbers_and_checks_them_against_the_image() {
        let r: Region = "1, 2,30,40".parse().unwrap();
        assert_eq!(
            r,
            Region {
                x0: 1,
                y0: 2,
                x1: 30,
                y1: 40
            }
        );
        assert_eq!((r.width(), r.height(), r.pixels()), (29, 38, 29 * 38));
        assert_eq!(r.within(30, 40), Ok(r));
        assert_eq!(r.to_string(), "1,2,30,40");
        for bad in ["", "1,2,3", "1,2,3,4,5", "a,0,1,1", "-1,0,1,1", "0.5,0,1,1"] {
            assert!(
                matches!(bad.parse::<Region>(), Err(RegionError::Malformed(_))),
                "{bad}"
            );
        }
        let empty: Region = "5,0,5,10".parse().unwrap();
        assert_eq!(empty.within(10, 10), Err(RegionError::Empty(empty)));
        let outside = r.within(29, 40).unwrap_err();
        assert!(
            outside.to_string().contains("outside the 29×40 image"),
            "{outside}"
        );
    }
}
