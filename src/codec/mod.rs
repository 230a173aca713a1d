//! The byte layouts shared by what crosses between processes and what is kept on disk: the
//! little-endian primitives every message and journal entry is built from (`wire`), and pixels
//! and request results (`pixels`). Below both the MPI protocol (`parallel::protocol`) and the
//! checkpoint journal (`checkpoint`), so that neither depends on the other.

pub mod pixels;
pub mod wire;

/// Bytes that cannot be read as what they should hold: too few, too many, or a value out of
/// range, said with what was being read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct DecodeError(pub String);
