//! One bit for each pixel of a window: which pixels an edge crosses, which need their samples'
//! own records. A bit, not a `bool`'s byte: the maps live through the render, and at 8K two
//! maps of bytes were 66 MB.

/// A set of the window's pixels, by their row-major index in the window.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PixelMap {
    words: Vec<u64>,
    len: usize,
}

impl PixelMap {
    /// `len` pixels, none in the set.
    pub fn new(len: usize) -> PixelMap {
        PixelMap {
            words: vec![0; len.div_ceil(64)],
            len,
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether pixel `i` is in the set (false past the end).
    pub fn get(&self, i: usize) -> bool {
        i < self.len && self.words[i / 64] >> (i % 64) & 1 == 1
    }

    /// Puts pixel `i` in the set, or takes it out.
    pub fn set(&mut self, i: usize, on: bool) {
        assert!(i < self.len, "pixel {i} of a map of {}", self.len);
        let bit = 1u64 << (i % 64);
        if on {
            self.words[i / 64] |= bit;
        } else {
            self.words[i / 64] &= !bit;
        }
    }

    /// Sets the pixels from `start` on as `flags` says.
    pub fn set_run(&mut self, start: usize, flags: &[bool]) {
        for (k, &on) in flags.iter().enumerate() {
            self.set(start + k, on);
        }
    }

    /// How many pixels are in the set.
    pub fn count(&self) -> usize {
        self.words.iter().map(|w| w.count_ones() as usize).sum()
    }

    /// The map as one `bool` a pixel.
    pub fn to_bools(&self) -> Vec<bool> {
        (0..self.len).map(|i| self.get(i)).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_map_holds_what_was_set_and_nothing_else() {
        let flags: Vec<bool> = (0..200).map(|i| i % 3 == 0 || i == 127).collect();
        let mut map = PixelMap::new(203);
        map.set_run(2, &flags);
        assert_eq!(map.len(), 203);
        for i in 0..203 {
            let expected = (2..202).contains(&i) && flags[i - 2];
            assert_eq!(map.get(i), expected, "pixel {i}");
        }
        assert!(!map.get(500));
        assert_eq!(map.count(), flags.iter().filter(|&&f| f).count());
        map.set(2, false);
        assert!(!map.get(2));
        assert_eq!(map.to_bools().len(), 203);
    }
}
