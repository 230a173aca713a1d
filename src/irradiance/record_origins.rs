//! Where a sequence's records came from: the surface point each was made at and the random
//! state its hemisphere began from (`--frames` of a scene whose meshes or lights move). A record
//! the moves may have changed (`temporal::Disturbance`) is made again at the same point from the
//! same samples, before the frame's prepass, instead of being left for the prepass to place
//! anew: where the light did not change it comes back bit for bit, and where it did, it changes
//! by what changed, not by a new record's placement and noise (two records placed apart differ
//! by more than a small change of light: the conference room's ceiling flickered by relMSE 1e-4
//! to 4e-4 frame to frame where records were dropped and placed again).
//!
//! A record on a mesh that moved, or where a moved mesh now stands, is not made again: its
//! point is gone. The prepass adds what the moves left uncovered.

use super::record::{Record, RecordIdentity};
use super::temporal::Disturbance;
use crate::sampling::Rng;
use crate::tracer::SurfaceHit;
use std::collections::{HashMap, HashSet};
use std::sync::Mutex;

/// The point a record was made at and the random state its hemisphere began from.
#[derive(Clone, Debug)]
pub struct RecordOrigin {
    pub hit: SurfaceHit,
    pub rng: Rng,
}

#[derive(Debug, Default)]
pub struct RecordOrigins {
    by_record: Mutex<HashMap<RecordIdentity, RecordOrigin>>,
    to_remake: Mutex<Vec<RecordOrigin>>,
}

impl RecordOrigins {
    pub fn keep(&self, record: &Record, origin: RecordOrigin) {
        self.by_record
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(record.identity(), origin);
    }

    /// The records `dropped` by the moves: those whose point still stands are queued to be made
    /// again; the rest are forgotten.
    pub fn dropped(&mut self, dropped: &[Record], disturbance: &Disturbance) {
        let by_record = self.by_record.get_mut().unwrap_or_else(|e| e.into_inner());
        let to_remake = self.to_remake.get_mut().unwrap_or_else(|e| e.into_inner());
        for record in dropped {
            if let Some(origin) = by_record.remove(&record.identity())
                && !disturbance.on_moved_mesh(record.position)
            {
                to_remake.push(origin);
            }
        }
    }

    /// Forgets the origins of records not in `held` (the cache's).
    pub fn keep_only(&mut self, held: &HashSet<RecordIdentity>) {
        let by_record = self.by_record.get_mut().unwrap_or_else(|e| e.into_inner());
        by_record.retain(|id, _| held.contains(id));
    }

    /// The origins of the records to make again (made once: the queue empties).
    pub fn take_to_remake(&self) -> Vec<RecordOrigin> {
        std::mem::take(&mut *self.to_remake.lock().unwrap_or_else(|e| e.into_inner()))
    }
}
