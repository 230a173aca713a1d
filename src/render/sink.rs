//! Where finished tiles go, in one process and on an MPI master alike: into the EXR's stream as
//! they come (`image::layered_exr`), or into a frame held whole when the outputs need every
//! pixel at the end (`--denoise`) or a pixel's light may come after its tile (the progressive
//! modes under mpirun).

use crate::checkpoint::Restored;
use crate::image::framebuffer::{FrameBuffer, PixelValue};
use crate::image::layered_exr::{EncodedTile, StreamedExr};
use crate::prepass::PrepassOutcome;
use crate::tiles::{Tile, store_tile};
use std::collections::HashMap;
use std::sync::Mutex;

pub enum TileSink<'a> {
    Held(Mutex<FrameBuffer>),
    Streamed {
        stream: &'a StreamedExr,
        /// The prepass's records by pixel, for the `ic_records` layer (a held frame adds them
        /// at the end, `into_frame`; a streamed tile leaves before then).
        prepass_records: Option<PrepassRecords>,
    },
}

impl<'a> TileSink<'a> {
    /// Tiles go to a frame held whole, starting from `frame` (an empty one, or what a
    /// checkpoint restored).
    pub fn held(frame: FrameBuffer) -> TileSink<'a> {
        TileSink::Held(Mutex::new(frame))
    }

    /// Tiles go to `stream`; those an earlier run finished (`restored`, of `tiles`) go first.
    pub fn streamed(
        stream: &'a StreamedExr,
        prepass: Option<&PrepassOutcome>,
        restored: Option<(&[Tile], &Restored)>,
    ) -> TileSink<'a> {
        let sink = TileSink::Streamed {
            stream,
            prepass_records: prepass
                .filter(|_| stream.layout().plan.counts_records())
                .map(PrepassRecords::of),
        };
        if let Some((tiles, restored)) = restored {
            for (tile, _) in tiles.iter().zip(&restored.done).filter(|(_, done)| **done) {
                sink.store(tile, restored.frame.tile_values(tile));
            }
        }
        sink
    }

    /// Stores a tile a worker encoded into the file's chunks (only where the tiles are streamed).
    pub fn store_encoded(&self, tile: &Tile, encoded: &EncodedTile) -> Result<(), String> {
        match self {
            TileSink::Streamed { stream, .. } => {
                stream.store_encoded(tile, encoded);
                Ok(())
            }
            TileSink::Held(_) => Err("an encoded tile for a frame held whole".to_string()),
        }
    }

    /// Stores a finished tile's pixels (see `tiles::store_tile` for a held frame).
    pub fn store(&self, tile: &Tile, mut values: Vec<PixelValue>) {
        match self {
            TileSink::Held(frame) => store_tile(&mut frame.lock().unwrap_or_else(|e| e.into_inner()), tile, &values),
            TileSink::Streamed {
                stream,
                prepass_records,
            } => {
                if let Some(records) = prepass_records {
                    records.add_to(tile, &mut values);
                }
                stream.store(tile, &values);
            }
        }
    }

    /// The frame held whole, for light that comes apart from its tile; None when streaming.
    pub fn held_mut(&mut self) -> Option<&mut FrameBuffer> {
        match self {
            TileSink::Held(frame) => Some(frame.get_mut().unwrap_or_else(|e| e.into_inner())),
            TileSink::Streamed { .. } => None,
        }
    }

    /// The frame held whole, with the prepass's records counted in its `ic_records` layer;
    /// None when the tiles were streamed.
    pub fn into_frame(self, prepass: Option<&PrepassOutcome>) -> Option<FrameBuffer> {
        match self {
            TileSink::Held(frame) => {
                let mut frame = frame.into_inner().unwrap_or_else(|e| e.into_inner());
                if let Some(prepass) = prepass {
                    add_prepass_records(&mut frame, prepass);
                }
                Some(frame)
            }
            TileSink::Streamed { .. } => None,
        }
    }
}

/// Counts the records the prepass made for each pixel in the frame's `ic_records` layer.
fn add_prepass_records(frame: &mut FrameBuffer, prepass: &PrepassOutcome) {
    for ((x, y), count) in prepass.records_per_pixel() {
        frame.add_records(x, y, count as f32);
    }
}

/// How many records the prepass made at each pixel that has any, for the `ic_records` layer of
/// tiles that are streamed.
pub struct PrepassRecords(HashMap<(u32, u32), f32>);

impl PrepassRecords {
    pub fn of(prepass: &PrepassOutcome) -> PrepassRecords {
        let mut counts = HashMap::new();
        for pixel in prepass.records_per_pixel() {
            *counts.entry(pixel.0).or_insert(0.0) += pixel.1 as f32;
        }
        PrepassRecords(counts)
    }

    /// A tile's pixels with the counts added.
    pub fn counted(&self, tile: &Tile, mut values: Vec<PixelValue>) -> Vec<PixelValue> {
        self.add_to(tile, &mut values);
        values
    }

    /// Adds the counts to a tile's pixels (row-major over the tile).
    pub fn add_to(&self, tile: &Tile, values: &mut [PixelValue]) {
        if self.0.is_empty() {
            return;
        }
        let positions = (tile.y0..tile.y1).flat_map(|y| (tile.x0..tile.x1).map(move |x| (x, y)));
        for (value, at) in values.iter_mut().zip(positions) {
            if let Some(count) = self.0.get(&at) {
                value.records += count;
            }
        }
    }
}
