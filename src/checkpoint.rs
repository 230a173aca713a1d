//! `--checkpoint DIR`: a journal of finished work, so that a render killed at any moment and
//! started again with the same command picks up where it stopped.
//!
//! `DIR/tiles.journal` is a header naming the job, then entries appended as work finishes:
//!
//! - `Start`: one per run of the command (an "attempt"); entries after it belong to it.
//! - `Tile`: a tile's pixels as its renderer made them, and how many indirect-diffuse requests
//!   it sent elsewhere (component mode; 0 everywhere else).
//! - `Results`: indirect light computed for such requests (pixel, layer, value).
//!
//! A tile counts as finished when one attempt journalled its pixels and as many results for
//! its pixels as it sent requests: then it is restored and not rendered again. Anything else
//! from an earlier attempt (a tile whose requests were still queued when the job died) is
//! dropped and the tile rendered again. Each entry is written with one `write` and carries a
//! checksum; the first entry that is cut short or fails its checksum ends the journal (a torn
//! last write) and is cut off, so entries appended later stay readable.
//!
//! The irradiance cache goes to `DIR/cache.icc` (unless `-af` names another file), so a resumed
//! render also starts with every record the killed one had written.

use crate::codec::pixels::{PIXEL_FLOATS, RESULT_BYTES, decode_pixels, encode_pixels, put_results, take_results};
use crate::codec::wire::Reader;
use crate::image::framebuffer::FrameBuffer;
use crate::image::framebuffer::PixelValue;
use crate::image::window::PixelWindow;
use crate::irradiance::codec::checksum;
pub use crate::shading::request::RequestResult;
use crate::tiles::Tile;
use std::fs::{File, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// The journal's format: 2 added the data layers to every pixel (`image::data`), 3 the
/// layers' noise among them (what `--denoise` weighs by).
const MAGIC: &[u8; 8] = b"ICRJRNL3";
/// The formats before and what they lack, refused with a message that says so.
const OLD_MAGICS: [(&[u8; 8], &str); 2] = [
    (b"ICRJRNL1", "without the data layers"),
    (b"ICRJRNL2", "without the pixels' noise estimates"),
];
const KIND_START: u8 = 0;
const KIND_TILE: u8 = 1;
const KIND_RESULTS: u8 = 2;
/// No entry is larger than a 16k x 16k tile's pixels; a longer length is damage.
const MAX_ENTRY: usize = 16384 * 16384 * PIXEL_FLOATS * 4;

/// What an earlier run finished: the frame with the finished tiles' pixels, and which they are.
pub struct Restored {
    pub frame: FrameBuffer,
    pub done: Vec<bool>,
    /// Torn or damaged bytes cut off the end of the journal.
    pub torn_bytes: usize,
}

impl Restored {
    pub fn count(&self) -> usize {
        self.done.iter().filter(|d| **d).count()
    }

    /// The tiles still to render, in order.
    pub fn unfinished(&self) -> Vec<usize> {
        (0..self.done.len()).filter(|&i| !self.done[i]).collect()
    }
}

/// The journal of this run, appended to from any thread.
pub struct Checkpoint {
    path: PathBuf,
    file: Mutex<File>,
    attempt: u32,
    /// The first write error, reported once: a render goes on without its journal.
    failed: Mutex<Option<String>>,
}

/// The cache file a checkpointed render uses when `-af` names none.
pub fn cache_file(dir: &Path) -> PathBuf {
    dir.join("cache.icc")
}

fn header(key: &str) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(&(key.len() as u32).to_le_bytes());
    out.extend_from_slice(key.as_bytes());
    out
}

fn entry(kind: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + 9);
    out.push(kind);
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(payload);
    let sum = checksum(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

fn u32_at(bytes: &[u8], offset: usize) -> Option<u32> {
    bytes
        .get(offset..offset + 4)
        .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
}

/// One decoded entry.
enum Entry {
    Start(u32),
    Tile {
        attempt: u32,
        tile: u32,
        requests: u32,
        pixels: Vec<PixelValue>,
    },
    Results {
        attempt: u32,
        results: Vec<RequestResult>,
    },
}

fn decode_entry(kind: u8, p: &[u8]) -> Option<Entry> {
    match kind {
        KIND_START if p.len() == 4 => Some(Entry::Start(u32_at(p, 0)?)),
        KIND_TILE => {
            let (attempt, tile, requests, count) = (u32_at(p, 0)?, u32_at(p, 4)?, u32_at(p, 8)?, u32_at(p, 12)?);
            let body = p.get(16..)?;
            if body.len() != (count as usize).checked_mul(PIXEL_FLOATS * 4)? {
                return None;
            }
            let pixels = decode_pixels(body);
            Some(Entry::Tile {
                attempt,
                tile,
                requests,
                pixels,
            })
        }
        KIND_RESULTS => {
            let (attempt, count) = (u32_at(p, 0)?, u32_at(p, 4)?);
            let body = p.get(8..)?;
            if body.len() != (count as usize).checked_mul(RESULT_BYTES)? {
                return None;
            }
            let results = take_results(&mut Reader::new(body, "journal results"), count as usize).ok()?;
            Some(Entry::Results { attempt, results })
        }
        _ => None,
    }
}

/// Reads the entries after the header; returns them and where the intact part ends.
fn read_entries(bytes: &[u8], mut at: usize) -> (Vec<Entry>, usize) {
    let mut entries = Vec::new();
    while let Some(len) = u32_at(bytes, at + 1).map(|l| l as usize).filter(|&l| l <= MAX_ENTRY) {
        let end = at + 5 + len;
        let (Some(body), Some(sum)) = (bytes.get(at..end), u32_at(bytes, end)) else {
            break;
        };
        if checksum(body) != sum {
            break;
        }
        let Some(entry) = decode_entry(body[0], &body[5..]) else {
            break;
        };
        entries.push(entry);
        at = end + 4;
    }
    (entries, at)
}

/// The tile each pixel of `window` belongs to (the window's pixels, row-major).
fn tile_of_pixel(tiles: &[Tile], window: PixelWindow) -> Vec<u32> {
    let mut owner = vec![u32::MAX; window.pixels()];
    for (index, t) in tiles.iter().enumerate() {
        for y in t.y0..t.y1 {
            for x in t.x0..t.x1 {
                if let Some(i) = window.index(x, y) {
                    owner[i] = index as u32;
                }
            }
        }
    }
    owner
}

/// Rebuilds the finished tiles from the entries, in a frame of `window` (the area the tiles
/// cover: a region task's region, or the whole image).
fn restore(entries: Vec<Entry>, tiles: &[Tile], window: PixelWindow) -> (FrameBuffer, Vec<bool>) {
    use std::collections::HashMap;
    let owner = tile_of_pixel(tiles, window);
    // Per (attempt, tile): the tile's pixels and request count, and the results for it.
    type Part = (u32, Vec<PixelValue>);
    let mut parts: HashMap<(u32, u32), Part> = HashMap::new();
    let mut results: HashMap<(u32, u32), Vec<RequestResult>> = HashMap::new();
    for e in entries {
        match e {
            Entry::Start(_) => {}
            Entry::Tile {
                attempt,
                tile,
                requests,
                pixels,
            } => {
                let fits = tiles
                    .get(tile as usize)
                    .is_some_and(|t| ((t.x1 - t.x0) * (t.y1 - t.y0)) as usize == pixels.len());
                if fits {
                    parts.insert((attempt, tile), (requests, pixels));
                }
            }
            Entry::Results { attempt, results: r } => {
                for result in r {
                    let tile = window
                        .index_of_pixel(result.pixel as usize)
                        .and_then(|i| owner.get(i).copied());
                    if let Some(tile) = tile.filter(|&t| t != u32::MAX) {
                        results.entry((attempt, tile)).or_default().push(result);
                    }
                }
            }
        }
    }
    let mut frame = FrameBuffer::windowed(window);
    let mut done = vec![false; tiles.len()];
    let mut finished: Vec<(&(u32, u32), &Part)> = parts.iter().collect();
    finished.sort_by_key(|(key, _)| **key);
    for (key, (requests, pixels)) in finished {
        let found = results.get(key).map_or(&[][..], Vec::as_slice);
        let tile = key.1 as usize;
        if done[tile] || found.len() != *requests as usize {
            continue;
        }
        let all_finite = pixels.iter().all(|p| {
            p.records.is_finite() && p.components.as_array().iter().all(|v| v.is_finite()) && p.data.healthy()
        }) && found.iter().all(|r| r.value.is_finite());
        if !all_finite {
            continue;
        }
        crate::tiles::store_tile(&mut frame, &tiles[tile], pixels);
        for r in found {
            frame.add(r.pixel as usize, r.layer, r.value);
        }
        done[tile] = true;
    }
    (frame, done)
}

impl Checkpoint {
    /// Opens (or starts) the journal in `dir` for the job `key` and returns what earlier runs
    /// finished, in a frame of `window` (the area `tiles` cover). A journal of another job is
    /// refused, not overwritten.
    pub fn open(dir: &Path, key: &str, tiles: &[Tile], window: PixelWindow) -> Result<(Checkpoint, Restored), String> {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: cannot create the directory: {e}", dir.display()))?;
        let path = dir.join("tiles.journal");
        let context = |e: std::io::Error| format!("{}: {e}", path.display());
        let mut bytes = Vec::new();
        if path.exists() {
            File::open(&path)
                .and_then(|mut f| f.read_to_end(&mut bytes))
                .map_err(context)?;
        }
        let ours = header(key);
        let (entries, intact) = if bytes.len() < ours.len() && ours.starts_with(&bytes) {
            // Empty, or the header itself was torn: nothing was journalled yet.
            std::fs::write(&path, &ours).map_err(context)?;
            bytes = ours.clone();
            (Vec::new(), ours.len())
        } else if let Some((_, lacks)) = OLD_MAGICS.iter().find(|(old, _)| bytes.starts_with(*old)) {
            return Err(format!(
                "{}: a checkpoint of an older icrender (journal format {}, {lacks}); \
                 it cannot be resumed by this version: delete it or give another --checkpoint directory",
                path.display(),
                char::from(bytes[7])
            ));
        } else if !bytes.starts_with(MAGIC) {
            return Err(format!("{}: not an icrender checkpoint journal", path.display()));
        } else if !bytes.starts_with(&ours) {
            let theirs_len = u32_at(&bytes, 8).unwrap_or(0) as usize;
            let theirs = bytes
                .get(12..12 + theirs_len)
                .map(String::from_utf8_lossy)
                .unwrap_or_default();
            return Err(format!(
                "{}: this checkpoint belongs to another job ({theirs}); this one is ({key}); \
                 give another --checkpoint directory or delete this one",
                path.display()
            ));
        } else {
            read_entries(&bytes, ours.len())
        };
        let torn_bytes = bytes.len() - intact;
        let attempt = entries
            .iter()
            .filter_map(|e| match e {
                Entry::Start(a) => Some(*a + 1),
                _ => None,
            })
            .max()
            .unwrap_or(0);
        let (frame, done) = restore(entries, tiles, window);
        let file = OpenOptions::new().write(true).open(&path).map_err(context)?;
        // Cut a torn tail so that appended entries follow the last intact one.
        file.set_len(intact as u64).map_err(context)?;
        let mut file = OpenOptions::new().append(true).open(&path).map_err(context)?;
        file.write_all(&entry(KIND_START, &attempt.to_le_bytes()))
            .map_err(context)?;
        Ok((
            Checkpoint {
                path,
                file: Mutex::new(file),
                attempt,
                failed: Mutex::new(None),
            },
            Restored {
                frame,
                done,
                torn_bytes,
            },
        ))
    }

    fn append(&self, kind: u8, payload: &[u8]) {
        let bytes = entry(kind, payload);
        let result = self.file.lock().unwrap_or_else(|e| e.into_inner()).write_all(&bytes);
        if let Err(e) = result {
            let mut failed = self.failed.lock().unwrap_or_else(|e| e.into_inner());
            if failed.is_none() {
                crate::diagnostics::warn(&format!(
                    "{}: cannot journal finished work ({e}); the render goes on, but a restart would redo it",
                    self.path.display()
                ));
                *failed = Some(e.to_string());
            }
        }
    }

    /// Journals a rendered tile; `requests` of its indirect light went to other ranks.
    pub fn tile(&self, index: u32, requests: u32, pixels: &[PixelValue]) {
        let mut p = Vec::with_capacity(16 + pixels.len() * PIXEL_FLOATS * 4);
        for w in [self.attempt, index, requests, pixels.len() as u32] {
            p.extend_from_slice(&w.to_le_bytes());
        }
        encode_pixels(pixels, &mut p);
        self.append(KIND_TILE, &p);
    }

    /// Journals indirect light computed for requests.
    pub fn results(&self, results: &[RequestResult]) {
        if results.is_empty() {
            return;
        }
        let mut p = Vec::with_capacity(8 + results.len() * RESULT_BYTES);
        p.extend_from_slice(&self.attempt.to_le_bytes());
        p.extend_from_slice(&(results.len() as u32).to_le_bytes());
        p.extend(encode_results(results));
        self.append(KIND_RESULTS, &p);
    }
}

/// How many tiles the journal in `dir` holds as finished, read without changing it (a journal
/// being written is read up to its last whole entry). For watching a render's progress.
pub fn finished_tiles(dir: &Path, tiles: &[Tile], window: PixelWindow) -> usize {
    let Ok(bytes) = std::fs::read(dir.join("tiles.journal")) else {
        return 0;
    };
    let header = 12 + u32_at(&bytes, 8).unwrap_or(0) as usize;
    if !bytes.starts_with(MAGIC) || bytes.len() < header {
        return 0;
    }
    let (entries, _) = read_entries(&bytes, header);
    restore(entries, tiles, window).1.iter().filter(|d| **d).count()
}

/// Results as bytes (the journal's form; the `Results` message adds a count).
pub fn encode_results(results: &[RequestResult]) -> Vec<u8> {
    let mut out = Vec::with_capacity(results.len() * RESULT_BYTES);
    put_results(&mut out, results);
    out
}

/// The inverse of [`encode_results`]; `None` for malformed bytes.
pub fn decode_results(bytes: &[u8]) -> Option<Vec<RequestResult>> {
    if !bytes.len().is_multiple_of(RESULT_BYTES) {
        return None;
    }
    let mut reader = Reader::new(bytes, "results");
    take_results(&mut reader, bytes.len() / RESULT_BYTES).ok()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::components::Components;
    use crate::image::framebuffer::Layer;
    use crate::tiles::tiles;
    use glam::Vec3;

    fn pixels(tile: &Tile, value: f32) -> Vec<PixelValue> {
        let n = ((tile.x1 - tile.x0) * (tile.y1 - tile.y0)) as usize;
        vec![
            PixelValue {
                components: Components {
                    emission: Vec3::splat(value),
                    direct: Vec3::new(value, 0.0, 1.0),
                    specular: Vec3::ZERO,
                    indirect: Vec3::splat(0.25),
                },
                records: 1.0,
                data: Default::default(),
            };
            n
        ]
    }

    #[test]
    fn finished_tiles_come_back_and_unfinished_ones_do_not() {
        let dir = tempfile::tempdir().unwrap();
        let all = tiles(8, 4, 4, 4);
        let (journal, restored) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(8, 4)).unwrap();
        assert_eq!(restored.count(), 0);
        journal.tile(0, 0, &pixels(&all[0], 2.0));
        // Tile 1 sent two requests; only one result arrives before the "kill".
        journal.tile(1, 2, &pixels(&all[1], 3.0));
        let pixel_of_tile1 = 4;
        journal.results(&[RequestResult {
            pixel: pixel_of_tile1,
            layer: Layer::Indirect,
            value: Vec3::ONE,
        }]);
        drop(journal);
        let (journal, restored) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(8, 4)).unwrap();
        assert_eq!(restored.done, vec![true, false]);
        assert_eq!(finished_tiles(dir.path(), &all, PixelWindow::whole(8, 4)), 1);
        assert_eq!(restored.frame.layer(Layer::Emission)[0], Vec3::splat(2.0));
        assert_eq!(
            restored.frame.layer(Layer::Emission)[pixel_of_tile1 as usize],
            Vec3::ZERO
        );
        // The second attempt finishes tile 1; the first attempt's lone result is not reused.
        journal.tile(1, 2, &pixels(&all[1], 3.0));
        let results: Vec<RequestResult> = [4u32, 5]
            .iter()
            .map(|&pixel| RequestResult {
                pixel,
                layer: Layer::Specular,
                value: Vec3::splat(0.5),
            })
            .collect();
        journal.results(&results);
        drop(journal);
        let (_, restored) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(8, 4)).unwrap();
        assert_eq!(restored.done, vec![true, true]);
        assert_eq!(restored.frame.layer(Layer::Specular)[4], Vec3::splat(0.5));
        assert_eq!(restored.frame.layer(Layer::Indirect)[4], Vec3::splat(0.25));
        assert_eq!(restored.frame.layer(Layer::Emission)[5], Vec3::splat(3.0));
    }

    /// A region's journal restores into a frame of the region only: its tiles' pixels and the
    /// results for them (named by the full image's pixel numbers) land where they belong.
    #[test]
    fn a_region_s_tiles_come_back_in_a_frame_of_the_region() {
        let dir = tempfile::tempdir().unwrap();
        let region = crate::image::region::Region {
            x0: 3,
            y0: 2,
            x1: 9,
            y1: 6,
        };
        let window = PixelWindow::new(region, 12, 8);
        let all = crate::tiles::tiles_in(12, 8, 4, 4, Some(region));
        assert_eq!(all.len(), 6);
        let (journal, _) = Checkpoint::open(dir.path(), "job", &all, window).unwrap();
        for (i, t) in all.iter().enumerate() {
            // Tile 1 (x 4..8, y 2..4) waits for one result; the others for none.
            journal.tile(i as u32, (i == 1) as u32, &pixels(t, i as f32));
        }
        let (x, y) = (5u32, 3u32);
        journal.results(&[RequestResult {
            pixel: y * 12 + x,
            layer: Layer::Specular,
            value: Vec3::ONE,
        }]);
        drop(journal);
        let (_, restored) = Checkpoint::open(dir.path(), "job", &all, window).unwrap();
        assert_eq!(restored.done, vec![true; 6]);
        assert_eq!(finished_tiles(dir.path(), &all, window), 6);
        let frame = &restored.frame;
        assert_eq!((frame.width, frame.height, frame.window()), (6, 4, window));
        for (i, t) in all.iter().enumerate() {
            for y in t.y0..t.y1 {
                for x in t.x0..t.x1 {
                    let at = window.index(x, y).unwrap();
                    assert_eq!(frame.layer(Layer::Emission)[at], Vec3::splat(i as f32), "({x}, {y})");
                }
            }
        }
        let specular: Vec<usize> = (0..window.pixels())
            .filter(|&i| frame.layer(Layer::Specular)[i] != Vec3::ZERO)
            .collect();
        assert_eq!(specular, vec![window.index(x, y).unwrap()]);
    }

    #[test]
    fn a_torn_last_entry_is_cut_and_later_entries_stay_readable() {
        let dir = tempfile::tempdir().unwrap();
        let all = tiles(8, 8, 4, 4);
        let (journal, _) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(8, 8)).unwrap();
        journal.tile(0, 0, &pixels(&all[0], 1.0));
        journal.tile(1, 0, &pixels(&all[1], 1.0));
        drop(journal);
        let path = dir.path().join("tiles.journal");
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 7]).unwrap();
        let (journal, restored) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(8, 8)).unwrap();
        assert_eq!(restored.done, vec![true, false, false, false]);
        assert!(restored.torn_bytes > 0);
        journal.tile(2, 0, &pixels(&all[2], 1.0));
        drop(journal);
        let (_, restored) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(8, 8)).unwrap();
        assert_eq!(restored.done, vec![true, false, true, false]);
        assert_eq!(restored.torn_bytes, 0);
    }

    #[test]
    fn every_cut_of_a_journal_opens() {
        let dir = tempfile::tempdir().unwrap();
        let all = tiles(4, 4, 2, 2);
        let (journal, _) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(4, 4)).unwrap();
        for (i, t) in all.iter().enumerate() {
            journal.tile(i as u32, 0, &pixels(t, i as f32));
        }
        drop(journal);
        let path = dir.path().join("tiles.journal");
        let whole = std::fs::read(&path).unwrap();
        let mut last = 0;
        for cut in 0..=whole.len() {
            std::fs::write(&path, &whole[..cut]).unwrap();
            let (_, restored) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(4, 4)).unwrap();
            assert!(restored.count() >= last, "a longer journal restored fewer tiles");
            last = restored.count();
        }
        assert_eq!(last, 4);
    }

    #[test]
    fn another_jobs_journal_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let all = tiles(4, 4, 4, 4);
        Checkpoint::open(dir.path(), "-x 4 -y 4", &all, PixelWindow::whole(4, 4)).unwrap();
        let err = Checkpoint::open(dir.path(), "-x 4 -y 4 -ab 2", &all, PixelWindow::whole(4, 4))
            .err()
            .unwrap();
        assert!(err.contains("another job"), "{err}");
        std::fs::write(dir.path().join("tiles.journal"), b"garbage that is long enough").unwrap();
        let err = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(4, 4))
            .err()
            .unwrap();
        assert!(err.contains("not an icrender checkpoint"), "{err}");
        // Journals of the formats before (the data layers, then the layers' noise): refused,
        // saying which and what they lack.
        for (magic, format, lacks) in [
            (b"ICRJRNL1", "format 1", "data layers"),
            (b"ICRJRNL2", "format 2", "noise"),
        ] {
            let mut old = magic.to_vec();
            old.extend_from_slice(&3u32.to_le_bytes());
            old.extend_from_slice(b"job");
            std::fs::write(dir.path().join("tiles.journal"), &old).unwrap();
            let err = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(4, 4))
                .err()
                .unwrap();
            assert!(
                err.contains("older icrender") && err.contains(format) && err.contains(lacks),
                "{err}"
            );
        }
    }

    #[test]
    fn data_layers_come_back_from_the_journal() {
        let dir = tempfile::tempdir().unwrap();
        let all = tiles(4, 4, 4, 4);
        let (journal, _) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(4, 4)).unwrap();
        let mut tile = pixels(&all[0], 1.0);
        let mut sum = crate::image::data::PixelDataSum::new(1);
        let hit = crate::image::data::SampleHit {
            position: Vec3::new(1.0, 2.0, 3.0),
            depth: 4.5,
            normal: Vec3::X,
            object: crate::image::cryptomatte::id_of("chair"),
            material: crate::image::cryptomatte::id_of("oak"),
        };
        sum.add(Vec3::splat(0.25), Some(hit));
        sum.set_noise(crate::image::data::LayerNoise {
            direct: 0.5,
            specular: 0.125,
            indirect: 2.0,
        });
        tile[5].data = sum.finish();
        journal.tile(0, 0, &tile);
        drop(journal);
        let (_, restored) = Checkpoint::open(dir.path(), "job", &all, PixelWindow::whole(4, 4)).unwrap();
        assert_eq!(restored.frame.data()[5], tile[5].data);
        assert_eq!(restored.frame.data()[4], tile[4].data);
    }

    #[test]
    fn results_round_trip() {
        let r = vec![RequestResult {
            pixel: 9,
            layer: Layer::Specular,
            value: Vec3::new(1.0, 2.0, 3.0),
        }];
        assert_eq!(decode_results(&encode_results(&r)).unwrap(), r);
        assert!(decode_results(&[0; 19]).is_none());
        let mut bad = encode_results(&r);
        bad[4] = 9;
        assert!(decode_results(&bad).is_none());
    }
}
