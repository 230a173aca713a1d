//! The primitives every message is built from: little-endian numbers written to a byte vector,
//! and a reader that refuses to read past the end (a truncated message is an error, never a
//! shorter value) and, at the end, refuses bytes left over.

use super::DecodeError;
use glam::Vec3;

/// Appends little-endian values.
pub trait Put: Extend<u8> {
    fn put_u8(&mut self, v: u8) {
        self.extend([v]);
    }
    fn put_u32(&mut self, v: u32) {
        self.extend(v.to_le_bytes());
    }
    fn put_u64(&mut self, v: u64) {
        self.extend(v.to_le_bytes());
    }
    fn put_f32(&mut self, v: f32) {
        self.extend(v.to_le_bytes());
    }
    fn put_vec3(&mut self, v: Vec3) {
        v.to_array().into_iter().for_each(|c| self.put_f32(c));
    }
}

impl Put for Vec<u8> {}

/// Reads a message front to back.
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    /// What is being read, for errors.
    what: &'static str,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8], what: &'static str) -> Self {
        Reader { bytes, at: 0, what }
    }

    pub fn error(&self, problem: impl std::fmt::Display) -> DecodeError {
        DecodeError(format!("{}: {problem}", self.what))
    }

    pub fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let (len, at) = (self.bytes.len(), self.at);
        let Some(end) = at.checked_add(n).filter(|&end| end <= len) else {
            return Err(self.error(format_args!("ends after {len} bytes, {n} more needed at byte {at}")));
        };
        let slice = &self.bytes[self.at..end];
        self.at = end;
        Ok(slice)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        Ok(self.take(N)?.try_into().expect("N bytes"))
    }

    pub fn u8(&mut self) -> Result<u8, DecodeError> {
        Ok(self.array::<1>()?[0])
    }

    pub fn u32(&mut self) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.array()?))
    }

    pub fn u64(&mut self) -> Result<u64, DecodeError> {
        Ok(u64::from_le_bytes(self.array()?))
    }

    pub fn f32(&mut self) -> Result<f32, DecodeError> {
        Ok(f32::from_le_bytes(self.array()?))
    }

    pub fn vec3(&mut self) -> Result<Vec3, DecodeError> {
        Ok(Vec3::new(self.f32()?, self.f32()?, self.f32()?))
    }

    pub fn flag(&mut self) -> Result<bool, DecodeError> {
        match self.u8()? {
            0 => Ok(false),
            1 => Ok(true),
            other => Err(self.error(format_args!("flag byte {other}"))),
        }
    }

    /// A count of items of `item_bytes` each that must fit in what is left (so a damaged
    /// count cannot make the reader allocate for items that are not there).
    pub fn count(&mut self, item_bytes: usize) -> Result<usize, DecodeError> {
        let count = self.u32()? as usize;
        let left = self.bytes.len() - self.at;
        if count.saturating_mul(item_bytes) > left {
            return Err(self.error(format_args!("says {count} items but holds {left} bytes")));
        }
        Ok(count)
    }

    /// Everything not read yet.
    pub fn rest(&mut self) -> &'a [u8] {
        self.take(self.bytes.len() - self.at).expect("what is left")
    }

    /// The message must have been read exactly.
    pub fn finish(self) -> Result<(), DecodeError> {
        match self.bytes.len() - self.at {
            0 => Ok(()),
            left => Err(self.error(format_args!("{left} bytes too many"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_round_trip_and_reading_past_the_end_fails() {
        let mut out = Vec::new();
        out.put_u8(1);
        out.put_u32(7);
        out.put_u64(1 << 40);
        out.put_vec3(Vec3::new(1.0, -2.0, 0.5));
        let mut r = Reader::new(&out, "test");
        assert!(r.flag().unwrap());
        assert_eq!(r.u32().unwrap(), 7);
        assert_eq!(r.u64().unwrap(), 1 << 40);
        assert_eq!(r.vec3().unwrap(), Vec3::new(1.0, -2.0, 0.5));
        assert!(r.u8().is_err());
        let mut r = Reader::new(&out, "test");
        r.u8().unwrap();
        assert!(r.finish().is_err(), "bytes left over are an error");
    }

    #[test]
    fn a_count_must_fit_in_the_message() {
        let mut out = Vec::new();
        out.put_u32(3);
        out.extend_from_slice(&[0; 8]);
        assert!(Reader::new(&out, "t").count(4).is_err());
        assert_eq!(Reader::new(&out, "t").count(2).unwrap(), 3);
        let mut huge = Vec::new();
        huge.put_u32(u32::MAX);
        assert!(Reader::new(&huge, "t").count(usize::MAX / 2).is_err());
    }
}
