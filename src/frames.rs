//! Frame sequences: which frames a render makes (`--frames A-B`, `--frame N`), the scene time
//! of each, and each frame's file name.
//!
//! Frame N is at time N / fps seconds of the glTF animations (`--fps`, 24 by default as farm
//! tools assume), so frame 0 is time 0, where a glTF animation's keys start, and Blender's
//! frame numbers carry over unchanged: its glTF exporter writes the key of its frame f at f /
//! fps (unless told to slide the animation to time 0).
//!
//! A file name takes the frame number where it holds a placeholder, as farm managers write
//! them: a run of `#` (`out.####.exr`: the number zero-padded to as many digits as there are
//! `#`) or printf's `%d` / `%0Nd` (`out.%04d.exr`). A name without one, for more than one
//! frame, gets `.####` before its extension (`out.exr` -> `out.0001.exr`); for one frame it is
//! used as it is. A number wider than its padding is written in full.

use std::ffi::{OsStr, OsString};
use std::os::unix::ffi::{OsStrExt, OsStringExt};
use std::path::{Path, PathBuf};

/// `--frames A-B`: first and last frame, both rendered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameRange {
    pub first: u32,
    pub last: u32,
}

/// Parses `A-B` (or `N`, one frame).
pub fn parse_range(text: &str) -> Result<FrameRange, String> {
    let number = |t: &str| {
        t.trim()
            .parse::<u32>()
            .map_err(|_| format!("{text}: expected A-B with whole frame numbers from 0, e.g. 1-250"))
    };
    let (first, last) = match text.split_once('-') {
        Some((a, b)) => (number(a)?, number(b)?),
        None => {
            let n = number(text)?;
            (n, n)
        }
    };
    if first > last {
        return Err(format!("{text}: the first frame is after the last"));
    }
    Ok(FrameRange { first, last })
}

/// The frames a command makes and the time of each.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frames {
    pub range: FrameRange,
    pub fps: f64,
}

impl Frames {
    /// `--frames` or `--frame`, with `--fps` (checked: finite and positive).
    pub fn new(range: FrameRange, fps: f64) -> Result<Frames, String> {
        if !(fps.is_finite() && fps > 0.0) {
            return Err(format!("--fps {fps}: frames per second must be a positive number"));
        }
        Ok(Frames { range, fps })
    }

    pub fn numbers(&self) -> std::ops::RangeInclusive<u32> {
        self.range.first..=self.range.last
    }

    pub fn count(&self) -> usize {
        (self.range.last - self.range.first) as usize + 1
    }

    /// The scene time of frame `n`, seconds.
    pub fn time(&self, n: u32) -> f64 {
        n as f64 / self.fps
    }

    /// `A-B`, or `N` for one frame.
    pub fn text(&self) -> String {
        if self.range.first == self.range.last {
            self.range.first.to_string()
        } else {
            format!("{}-{}", self.range.first, self.range.last)
        }
    }
}

/// One frame of a sequence as its outputs record it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameTag {
    pub number: u32,
    /// Scene time, seconds.
    pub time: f64,
    pub fps: f64,
}

impl FrameTag {
    pub fn of(frames: &Frames, number: u32) -> FrameTag {
        FrameTag {
            number,
            time: frames.time(number),
            fps: frames.fps,
        }
    }

    /// The EXR header's account of the frame.
    pub fn attributes(&self) -> Vec<(String, String)> {
        vec![
            ("icrender/frame".to_string(), self.number.to_string()),
            ("icrender/frame_time_s".to_string(), self.time.to_string()),
            ("icrender/fps".to_string(), self.fps.to_string()),
        ]
    }
}

/// Where the frame number goes in a file name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NamePattern {
    /// The path up to the placeholder, and after it (the whole path when `width` is None).
    before: Vec<u8>,
    after: Vec<u8>,
    /// Digits the number is padded to; None: no placeholder, the name is used as it is.
    width: Option<usize>,
}

/// The placeholders of a file name: (start, end, width) of each.
fn placeholders(name: &[u8]) -> Vec<(usize, usize, usize)> {
    let mut found = Vec::new();
    let mut i = 0;
    while i < name.len() {
        if name[i] == b'#' {
            let start = i;
            while i < name.len() && name[i] == b'#' {
                i += 1;
            }
            found.push((start, i, i - start));
            continue;
        }
        if name[i] == b'%' {
            // %d, or %0Nd (N digits), as printf pads with zeros.
            let mut j = i + 1;
            let zero = name.get(j) == Some(&b'0');
            if zero {
                j += 1;
            }
            let digits_start = j;
            while j < name.len() && name[j].is_ascii_digit() {
                j += 1;
            }
            let digits = &name[digits_start..j];
            if name.get(j) == Some(&b'd') && (digits.is_empty() != zero) {
                let width = std::str::from_utf8(digits)
                    .ok()
                    .and_then(|d| d.parse().ok())
                    .unwrap_or(1);
                found.push((i, j + 1, width));
                i = j + 1;
                continue;
            }
        }
        i += 1;
    }
    found
}

/// The most digits a placeholder may ask for (a longer run is surely a mistake).
const MAX_WIDTH: usize = 16;

impl NamePattern {
    /// The pattern of `path` for `frames` frames. Only the file name (not its folders) may hold
    /// the placeholder, and at most one.
    pub fn new(path: &Path, frames: usize) -> Result<NamePattern, String> {
        let name = path
            .file_name()
            .ok_or_else(|| format!("{}: not a file name", path.display()))?
            .as_bytes();
        let folder_len = path.as_os_str().as_bytes().len() - name.len();
        let whole = path.as_os_str().as_bytes();
        let found = placeholders(name);
        match found.as_slice() {
            [] if frames <= 1 => Ok(NamePattern {
                before: whole.to_vec(),
                after: Vec::new(),
                width: None,
            }),
            [] => {
                // `.####` before the extension (at the end when there is none).
                let dot = name.iter().rposition(|&c| c == b'.').filter(|&i| i > 0);
                let cut = folder_len + dot.unwrap_or(name.len());
                let mut before = whole[..cut].to_vec();
                before.push(b'.');
                Ok(NamePattern {
                    before,
                    after: whole[cut..].to_vec(),
                    width: Some(4),
                })
            }
            [(start, end, width)] => {
                if *width > MAX_WIDTH {
                    return Err(format!(
                        "{}: a frame number of {width} digits (at most {MAX_WIDTH})",
                        path.display()
                    ));
                }
                Ok(NamePattern {
                    before: whole[..folder_len + start].to_vec(),
                    after: whole[folder_len + end..].to_vec(),
                    width: Some(*width),
                })
            }
            _ => Err(format!(
                "{}: the file name holds {} frame number placeholders (a run of # or %04d); give one",
                path.display(),
                found.len()
            )),
        }
    }

    /// Frame `n`'s path.
    pub fn path(&self, n: u32) -> PathBuf {
        let mut bytes = self.before.clone();
        if let Some(width) = self.width {
            bytes.extend_from_slice(format!("{n:0width$}").as_bytes());
        }
        bytes.extend_from_slice(&self.after);
        PathBuf::from(OsString::from_vec(bytes))
    }

    /// The pattern as a farm manager would write it, with `#` for the digits.
    pub fn text(&self) -> String {
        let mut bytes = self.before.clone();
        if let Some(width) = self.width {
            bytes.extend(std::iter::repeat_n(b'#', width));
        }
        bytes.extend_from_slice(&self.after);
        OsStr::from_bytes(&bytes).to_string_lossy().into_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn name(pattern: &str, frames: usize, n: u32) -> String {
        NamePattern::new(Path::new(pattern), frames)
            .unwrap()
            .path(n)
            .display()
            .to_string()
    }

    #[test]
    fn ranges_parse() {
        assert_eq!(parse_range("1-250"), Ok(FrameRange { first: 1, last: 250 }));
        assert_eq!(parse_range("7"), Ok(FrameRange { first: 7, last: 7 }));
        assert_eq!(parse_range(" 0 - 3 "), Ok(FrameRange { first: 0, last: 3 }));
        assert!(parse_range("5-2").is_err());
        assert!(parse_range("-3").is_err());
        assert!(parse_range("a-b").is_err());
        assert!(parse_range("1-2-3").is_err());
    }

    #[test]
    fn frame_n_is_at_n_over_fps() {
        let f = Frames::new(parse_range("0-48").unwrap(), 24.0).unwrap();
        assert_eq!(f.time(0), 0.0);
        assert_eq!(f.time(12), 0.5);
        assert_eq!(f.count(), 49);
        assert_eq!(f.text(), "0-48");
        assert!(Frames::new(f.range, 0.0).is_err());
        assert!(Frames::new(f.range, f64::NAN).is_err());
    }

    #[test]
    fn hashes_are_replaced_by_the_padded_number() {
        assert_eq!(name("out.####.exr", 5, 1), "out.0001.exr");
        assert_eq!(name("shots/s#/out.####.exr", 5, 42), "shots/s#/out.0042.exr");
        assert_eq!(name("out_#.exr", 5, 7), "out_7.exr");
        assert_eq!(name("out.##.exr", 200, 123), "out.123.exr");
    }

    #[test]
    fn printf_placeholders_are_replaced_too() {
        assert_eq!(name("out.%04d.exr", 5, 12), "out.0012.exr");
        assert_eq!(name("out.%d.exr", 5, 12), "out.12.exr");
        // Not a placeholder: printf's space padding, or a lone %.
        assert_eq!(name("100%.exr", 1, 3), "100%.exr");
        assert_eq!(name("a%4d.exr", 1, 3), "a%4d.exr");
    }

    #[test]
    fn a_name_without_a_placeholder_gets_one_before_its_extension_when_there_are_frames() {
        assert_eq!(name("render/out.exr", 3, 2), "render/out.0002.exr");
        assert_eq!(name("out", 3, 2), "out.0002");
        assert_eq!(name("out.exr", 1, 2), "out.exr");
        assert_eq!(
            NamePattern::new(Path::new("a/out.exr"), 3).unwrap().text(),
            "a/out.####.exr"
        );
    }

    #[test]
    fn two_placeholders_are_refused() {
        let e = NamePattern::new(Path::new("out.##.%04d.exr"), 2).unwrap_err();
        assert!(e.contains("2 frame number placeholders"), "{e}");
        assert!(NamePattern::new(Path::new(&format!("o{}.exr", "#".repeat(17))), 2).is_err());
    }
}
