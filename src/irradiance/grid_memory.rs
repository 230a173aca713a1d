//! The last-bounce grid's sites kept from frame to frame (`--frames` of a scene whose meshes
//! move): a site whose path ends where it ended last frame, at a point the moves did not
//! change (`temporal::Disturbance`), takes its samples from last frame instead of sampling
//! again, so a frame's grid costs only the sites the moves reach, as its records do.
//!
//! A site is its pixel and its index among the pixel's sites. Its path is traced again every
//! frame (a camera ray and a bounce or two, cheap against its samples' hemisphere): where it
//! meets the same point (the same bits) nothing along it moved. The random stream goes on from
//! the state the samples left, so the sites after it draw what they drew last frame.

use super::last_bounce::GridSample;
use super::temporal::Disturbance;
use crate::sampling::Rng;
use glam::Vec3;
use std::collections::HashMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

/// One site's end and samples.
#[derive(Clone, Debug)]
struct RememberedSite {
    end: [u32; 6],
    position: Vec3,
    normal: Vec3,
    samples: Vec<GridSample>,
    rng_after: Rng,
}

/// The sites of the last frame's grid, and this frame's reuse of them.
#[derive(Debug, Default)]
pub struct GridMemory {
    sites: Mutex<HashMap<(u64, u32), RememberedSite>>,
    reused: AtomicU64,
    sampled: AtomicU64,
}

fn end_bits(position: Vec3, normal: Vec3) -> [u32; 6] {
    let [a, b, c] = position.to_array().map(f32::to_bits);
    let [d, e, f] = normal.to_array().map(f32::to_bits);
    [a, b, c, d, e, f]
}

impl GridMemory {
    /// The samples site `key` took last frame and the random state after them, when its path
    /// ended at the same point.
    pub fn recall(&self, key: (u64, u32), position: Vec3, normal: Vec3) -> Option<(Vec<GridSample>, Rng)> {
        let sites = self.sites.lock().unwrap_or_else(|e| e.into_inner());
        let site = sites.get(&key).filter(|s| s.end == end_bits(position, normal))?;
        self.reused.fetch_add(1, Ordering::Relaxed);
        Some((site.samples.clone(), site.rng_after.clone()))
    }

    /// Keeps what site `key` sampled this frame.
    pub fn keep(&self, key: (u64, u32), position: Vec3, normal: Vec3, samples: &[GridSample], rng_after: &Rng) {
        self.sampled.fetch_add(1, Ordering::Relaxed);
        let site = RememberedSite {
            end: end_bits(position, normal),
            position,
            normal,
            samples: samples.to_vec(),
            rng_after: rng_after.clone(),
        };
        self.sites.lock().unwrap_or_else(|e| e.into_inner()).insert(key, site);
    }

    /// Drops the sites whose end the moves may have changed the light of (all of them when a
    /// light moved), and starts counting a new frame's reuse.
    pub fn forget_disturbed(&mut self, disturbance: &Disturbance) {
        let sites = self.sites.get_mut().unwrap_or_else(|e| e.into_inner());
        if disturbance.everywhere {
            sites.clear();
        } else if !disturbance.is_empty() {
            // A frame's grid has some 10^5 sites, each tested against every region: on every
            // core (0.16 s a frame on one for the conference room's 48 lamps).
            let ends: Vec<((u64, u32), Vec3, Vec3)> = sites.iter().map(|(k, s)| (*k, s.position, s.normal)).collect();
            let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
            let chunk = ends.len().div_ceil(threads).max(1);
            let disturbed: Vec<(u64, u32)> = std::thread::scope(|scope| {
                let workers: Vec<_> = ends
                    .chunks(chunk)
                    .map(|part| {
                        scope.spawn(move || {
                            part.iter()
                                .filter(|(_, p, n)| disturbance.disturbs_point(*p, *n, 0.0))
                                .map(|(k, _, _)| *k)
                                .collect::<Vec<_>>()
                        })
                    })
                    .collect();
                workers
                    .into_iter()
                    .flat_map(|w| w.join().expect("a grid test thread panicked"))
                    .collect()
            });
            for key in disturbed {
                sites.remove(&key);
            }
        }
        *self.reused.get_mut() = 0;
        *self.sampled.get_mut() = 0;
    }

    /// This frame's sites: (taken from last frame, sampled afresh).
    pub fn counts(&self) -> (u64, u64) {
        (
            self.reused.load(Ordering::Relaxed),
            self.sampled.load(Ordering::Relaxed),
        )
    }
}
