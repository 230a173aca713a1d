//! Regions of an image rendered as parts (`render --region`) and assembled again (`merge`):
//! the rectangle, its place in the EXR header, and the checks a set of parts must pass to
//! make one image (no overlaps, no holes).
//!
//! Pixel bounds are in the full image, origin at the top left, x1 and y1 exclusive: the part
//! `0 0 W H` is the whole image (OpenEXR's data window, `x0 y0` to `x1-1 y1-1`).

pub use super::seams::Region;

/// The header attribute naming a part's region, as `x0 y0 x1 y1`.
pub const REGION_ATTRIBUTE: &str = "icrender/region";
/// The header attribute holding the settings every part of one image must share
/// (`commands::render::part_settings`), `; `-separated items.
pub const SETTINGS_ATTRIBUTE: &str = "icrender/part_settings";
/// The header attribute of a merged image naming the parts it was assembled from.
pub const MERGED_ATTRIBUTE: &str = "icrender/merged_parts";

impl Region {
    pub fn whole(width: u32, height: u32) -> Region {
        Region {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }

    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }

    pub fn pixels(&self) -> usize {
        self.width() as usize * self.height() as usize
    }

    pub fn overlaps(&self, other: &Region) -> bool {
        self.x0 < other.x1 && other.x0 < self.x1 && self.y0 < other.y1 && other.y0 < self.y1
    }

    /// The pixels in both (empty, with x1 <= x0 or y1 <= y0, where they do not overlap).
    pub fn meet(&self, other: Region) -> Region {
        Region {
            x0: self.x0.max(other.x0),
            y0: self.y0.max(other.y0),
            x1: self.x1.min(other.x1),
            y1: self.y1.min(other.y1),
        }
    }

    /// `x0 y0 x1 y1`, as the option takes it and the header stores it.
    pub fn text(&self) -> String {
        format!("{} {} {} {}", self.x0, self.y0, self.x1, self.y1)
    }

    /// The inverse of `text`.
    pub fn parse(text: &str) -> Option<Region> {
        let v: Vec<u32> = text.split_whitespace().map(str::parse).collect::<Result<_, _>>().ok()?;
        match v[..] {
            [x0, y0, x1, y1] if x0 < x1 && y0 < y1 => Some(Region { x0, y0, x1, y1 }),
            _ => None,
        }
    }

    /// The values of `--region X0 Y0 X1 Y1` for an image of `width` x `height`: refused when
    /// empty or not inside the image.
    pub fn from_option(values: &[u32], width: u32, height: u32) -> Result<Region, String> {
        let [x0, y0, x1, y1] = values else {
            return Err("--region takes four numbers: X0 Y0 X1 Y1".into());
        };
        let (x0, y0, x1, y1) = (*x0, *y0, *x1, *y1);
        let shown = format!("--region {x0} {y0} {x1} {y1}");
        if x0 >= x1 || y0 >= y1 {
            return Err(format!(
                "{shown} is empty: X1 and Y1 are exclusive and must be larger than X0 and Y0"
            ));
        }
        if x1 > width || y1 > height {
            return Err(format!(
                "{shown} is not inside the {width}x{height} image (pixel bounds from the top left, \
                 X1 at most {width}, Y1 at most {height})"
            ));
        }
        Ok(Region { x0, y0, x1, y1 })
    }
}

/// Why a set of parts does not make one image.
#[derive(Debug, PartialEq, Eq)]
pub enum Tiling {
    /// Parts i and j share pixels.
    Overlap(usize, usize),
    /// No part has these pixels (a rectangle of them; there may be more).
    Uncovered(Region),
}

/// Whether `parts` cover the `width` x `height` image exactly once: the first overlapping pair,
/// else a rectangle no part covers (grown right, then down, from the first uncovered pixel in
/// scanline order).
pub fn check_tiling(width: u32, height: u32, parts: &[Region]) -> Result<(), Tiling> {
    for (i, a) in parts.iter().enumerate() {
        if let Some(j) = parts[i + 1..].iter().position(|b| a.overlaps(b)) {
            return Err(Tiling::Overlap(i, i + 1 + j));
        }
    }
    let mut covered = vec![false; width as usize * height as usize];
    for r in parts {
        for y in r.y0..r.y1.min(height) {
            for x in r.x0..r.x1.min(width) {
                covered[(y * width + x) as usize] = true;
            }
        }
    }
    let Some(first) = covered.iter().position(|c| !c) else {
        return Ok(());
    };
    let (x0, y0) = (first as u32 % width, first as u32 / width);
    let free = |x: u32, y: u32| !covered[(y * width + x) as usize];
    let mut x1 = x0 + 1;
    while x1 < width && free(x1, y0) {
        x1 += 1;
    }
    let mut y1 = y0 + 1;
    while y1 < height && (x0..x1).all(|x| free(x, y1)) {
        y1 += 1;
    }
    Err(Tiling::Uncovered(Region { x0, y0, x1, y1 }))
}

/// The first setting two parts' settings lines (`; `-separated items) disagree on: each
/// part's item (or "(absent)").
pub fn first_difference(a: &str, b: &str) -> Option<(String, String)> {
    let (ia, ib): (Vec<&str>, Vec<&str>) = (a.split("; ").collect(), b.split("; ").collect());
    (0..ia.len().max(ib.len())).find_map(|k| {
        let (x, y) = (ia.get(k).copied(), ib.get(k).copied());
        (x != y).then(|| (x.unwrap_or("(absent)").to_string(), y.unwrap_or("(absent)").to_string()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn r(x0: u32, y0: u32, x1: u32, y1: u32) -> Region {
        Region { x0, y0, x1, y1 }
    }

    #[test]
    fn option_values_are_checked_against_the_image() {
        assert_eq!(Region::from_option(&[0, 0, 8, 6], 8, 6), Ok(r(0, 0, 8, 6)));
        assert_eq!(Region::from_option(&[3, 2, 5, 4], 8, 6), Ok(r(3, 2, 5, 4)));
        assert!(Region::from_option(&[3, 2, 3, 4], 8, 6).unwrap_err().contains("empty"));
        assert!(Region::from_option(&[5, 2, 3, 4], 8, 6).unwrap_err().contains("empty"));
        assert!(
            Region::from_option(&[0, 0, 9, 6], 8, 6)
                .unwrap_err()
                .contains("not inside")
        );
        assert!(
            Region::from_option(&[0, 0, 8, 7], 8, 6)
                .unwrap_err()
                .contains("not inside")
        );
        assert_eq!(Region::parse(&r(1, 2, 3, 4).text()), Some(r(1, 2, 3, 4)));
        assert_eq!(Region::parse("1 2 1 4"), None);
        assert_eq!(Region::parse("1 2 3"), None);
    }

    #[test]
    fn tilings_are_checked_for_overlaps_and_holes() {
        // An uneven 2x2 split of 10x7 covers it exactly once, in any order.
        let split = [r(0, 0, 6, 4), r(6, 0, 10, 4), r(0, 4, 6, 7), r(6, 4, 10, 7)];
        assert_eq!(check_tiling(10, 7, &split), Ok(()));
        let mut reversed = split;
        reversed.reverse();
        assert_eq!(check_tiling(10, 7, &reversed), Ok(()));
        // One part left out: exactly its rectangle is uncovered.
        assert_eq!(check_tiling(10, 7, &split[..3]), Err(Tiling::Uncovered(r(6, 4, 10, 7))));
        // A hole shaped as an L: the rectangle found is its first row run, grown down.
        assert_eq!(
            check_tiling(10, 7, &[r(0, 0, 10, 2), r(0, 2, 4, 7), r(4, 5, 10, 7)]),
            Err(Tiling::Uncovered(r(4, 2, 10, 5)))
        );
        // Overlaps name both parts; touching edges are no overlap.
        assert_eq!(
            check_tiling(10, 7, &[r(0, 0, 6, 4), r(5, 0, 10, 4), r(0, 4, 10, 7)]),
            Err(Tiling::Overlap(0, 1))
        );
        assert!(!r(0, 0, 6, 4).overlaps(&r(6, 0, 10, 4)));
    }

    #[test]
    fn the_first_differing_setting_is_named() {
        assert_eq!(first_difference("-x 8; -aa 0.2; -ab 1", "-x 8; -aa 0.2; -ab 1"), None);
        assert_eq!(
            first_difference("-x 8; -aa 0.2; -ab 1", "-x 8; -aa 0.1; -ab 2"),
            Some(("-aa 0.2".into(), "-aa 0.1".into()))
        );
        assert_eq!(
            first_difference("-x 8", "-x 8; --half"),
            Some(("(absent)".into(), "--half".into()))
        );
    }
}
