//! Spatial index over record spheres, shared by all rendering threads: a multi-level hash grid.
//! A record of reach R lives at the level whose cells are at least 2R wide, in the cell holding
//! its position; a query then visits at most 2 x 2 x 2 cells per occupied level. Cells are
//! spread over many independently locked shards, so readers never wait for each other and a
//! writer holds one shard only for the moment of a push.

use super::record::Record;
use glam::{Vec3, Vec4};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};
use std::ops::ControlFlow;
use std::sync::RwLock;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

const SHARDS: usize = 64;
const MAX_LEVELS: u32 = 48;

type CellKey = (u32, i64, i64, i64);

/// Hashes cell keys by multiply and rotate. The default SipHash resists hostile keys, which
/// cell coordinates are not, and cost a third of a cached render's time in lookups (each
/// visits up to 8 cells per occupied level).
#[derive(Default)]
struct CellHasher(u64);

impl Hasher for CellHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }

    fn write_u32(&mut self, v: u32) {
        self.write_u64(v as u64);
    }

    fn write_i64(&mut self, v: i64) {
        self.write_u64(v as u64);
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (self.0.rotate_left(5) ^ v).wrapping_mul(0x517c_c1b7_2722_0a95);
    }

    fn finish(&self) -> u64 {
        // Fold the high bits down: the table takes its bucket from the low ones.
        self.0 ^ (self.0 >> 32)
    }
}

type CellMap = HashMap<CellKey, Vec<Record>, BuildHasherDefault<CellHasher>>;

/// The level whose cells (base x 2^level wide) are at least twice `reach`.
fn level_for(base_cell: f32, reach: f32) -> u32 {
    let ratio = (2.0 * reach / base_cell).max(1.0);
    (ratio.log2().ceil() as u32).min(MAX_LEVELS - 1)
}

fn cell_size(base_cell: f32, level: u32) -> f32 {
    base_cell * (1u64 << level) as f32
}

fn cell_of(p: Vec3, size: f32) -> (i64, i64, i64) {
    let c = (p / size).floor();
    (c.x as i64, c.y as i64, c.z as i64)
}

pub struct RecordIndex {
    base_cell: f32,
    shards: Vec<RwLock<CellMap>>,
    occupied_levels: AtomicU64,
    count: AtomicUsize,
    /// Times a reader or writer found its shard locked and had to wait.
    contention: AtomicU64,
}

fn shard_of(key: &CellKey) -> usize {
    let mut h = (key.0 as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    for v in [key.1, key.2, key.3] {
        h = (h ^ v as u64).wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 29;
    }
    (h % SHARDS as u64) as usize
}

impl RecordIndex {
    /// `smallest_reach` sizes the finest level; it need not be exact.
    pub fn new(smallest_reach: f32) -> RecordIndex {
        let base = if smallest_reach.is_finite() && smallest_reach > 0.0 {
            2.0 * smallest_reach
        } else {
            1e-6
        };
        RecordIndex {
            base_cell: base,
            shards: (0..SHARDS).map(|_| RwLock::new(CellMap::default())).collect(),
            occupied_levels: AtomicU64::new(0),
            count: AtomicUsize::new(0),
            contention: AtomicU64::new(0),
        }
    }

    fn level_for(&self, reach: f32) -> u32 {
        level_for(self.base_cell, reach)
    }

    fn cell_size(&self, level: u32) -> f32 {
        cell_size(self.base_cell, level)
    }

    fn cell_of(&self, p: Vec3, size: f32) -> (i64, i64, i64) {
        cell_of(p, size)
    }

    pub fn len(&self) -> usize {
        self.count.load(Ordering::Relaxed)
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn contention(&self) -> u64 {
        self.contention.load(Ordering::Relaxed)
    }

    /// Puts `new` in the place of a record equal to `old` (validation shrinks a record: its
    /// level and cell may change). False when no such record is held.
    pub fn replace(&self, old: &Record, new: Record) -> bool {
        let level = self.level_for(old.reach());
        let (x, y, z) = self.cell_of(old.position, self.cell_size(level));
        let key = (level, x, y, z);
        {
            let mut map = self.shards[shard_of(&key)].write().unwrap_or_else(|e| e.into_inner());
            let Some(records) = map.get_mut(&key) else {
                return false;
            };
            let Some(at) = records.iter().position(|r| r == old) else {
                return false;
            };
            records.swap_remove(at);
            if records.is_empty() {
                map.remove(&key);
            }
        }
        self.count.fetch_sub(1, Ordering::Relaxed);
        self.insert(new);
        true
    }

    /// Keeps the records `keep` says to and returns the rest, dropped.
    pub fn retain(&mut self, mut keep: impl FnMut(&Record) -> bool) -> Vec<Record> {
        let mut dropped = Vec::new();
        for shard in &mut self.shards {
            let map = shard.get_mut().unwrap_or_else(|e| e.into_inner());
            map.retain(|_, records| {
                let (kept, gone): (Vec<Record>, Vec<Record>) = std::mem::take(records).into_iter().partition(&mut keep);
                *records = kept;
                dropped.extend(gone);
                !records.is_empty()
            });
        }
        self.count.fetch_sub(dropped.len(), Ordering::Relaxed);
        dropped
    }

    pub fn insert(&self, record: Record) {
        let level = self.level_for(record.reach());
        let (x, y, z) = self.cell_of(record.position, self.cell_size(level));
        let key = (level, x, y, z);
        let shard = &self.shards[shard_of(&key)];
        let mut map = match shard.try_write() {
            Ok(map) => map,
            Err(_) => {
                self.contention.fetch_add(1, Ordering::Relaxed);
                shard.write().unwrap_or_else(|e| e.into_inner())
            }
        };
        map.entry(key).or_default().push(record);
        drop(map);
        self.occupied_levels.fetch_or(1 << level, Ordering::Relaxed);
        self.count.fetch_add(1, Ordering::Relaxed);
    }

    /// Calls `visit` for every record whose reach may cover `p` (a superset: the caller applies
    /// the exact test).
    pub fn for_each_near(&self, p: Vec3, mut visit: impl FnMut(&Record)) {
        let mut levels = self.occupied_levels.load(Ordering::Relaxed);
        while levels != 0 {
            let level = levels.trailing_zeros();
            levels &= levels - 1;
            let size = self.cell_size(level);
            // A record here reaches at most size/2, so its position lies within size/2 of p.
            let lo = self.cell_of(p - Vec3::splat(0.5 * size), size);
            let hi = self.cell_of(p + Vec3::splat(0.5 * size), size);
            for x in lo.0..=hi.0 {
                for y in lo.1..=hi.1 {
                    for z in lo.2..=hi.2 {
                        let key = (level, x, y, z);
                        let shard = &self.shards[shard_of(&key)];
                        let map = match shard.try_read() {
                            Ok(map) => map,
                            Err(_) => {
                                self.contention.fetch_add(1, Ordering::Relaxed);
                                shard.read().unwrap_or_else(|e| e.into_inner())
                            }
                        };
                        if let Some(records) = map.get(&key) {
                            records.iter().for_each(&mut visit);
                        }
                    }
                }
            }
        }
    }

    /// The read-only copy of this index a complete cache is looked up in (see `FrozenIndex`),
    /// its records in a canonical order (by their bits), so every process that holds the same
    /// records sums them in the same order, whatever order they arrived in.
    pub fn frozen(&self) -> FrozenIndex {
        FrozenIndex::of(self.base_cell, self.canonical())
    }

    /// Every record, in the canonical order (by their bits).
    fn canonical(&self) -> Vec<Record> {
        let mut records = self.all();
        records.sort_by_key(Record::identity);
        records
    }

    /// The records in `frozen`'s canonical order as they were placed, and the frozen index of
    /// them widened by `blend` (`Record::widened`), listed in that order.
    pub fn frozen_widened(&self, blend: f32) -> (Vec<Record>, FrozenIndex) {
        let placed = self.canonical();
        let read = placed.iter().map(|r| r.widened(blend)).collect();
        (placed, FrozenIndex::of(self.base_cell, read))
    }

    /// A read-only copy in no particular order, for lookups whose answer is only whether a
    /// record covers the point (the prepass's), extended with `FrozenIndex::push`.
    pub fn snapshot(&self) -> FrozenIndex {
        FrozenIndex::of(self.base_cell, self.all())
    }

    /// Every record, in no particular order.
    pub fn all(&self) -> Vec<Record> {
        let mut out = Vec::with_capacity(self.len());
        for shard in &self.shards {
            let map = shard.read().unwrap_or_else(|e| e.into_inner());
            for records in map.values() {
                out.extend(records.iter().cloned());
            }
        }
        out
    }
}

type FrozenCells = HashMap<CellKey, Vec<u32>, BuildHasherDefault<CellHasher>>;

/// A copy of a `RecordIndex` for reading without locks (see `RecordIndex::frozen`): the same
/// levels, but each record listed in every cell of its level its reach overlaps (at most 8),
/// so a query visits one cell per occupied level instead of eight.
pub struct FrozenIndex {
    base_cell: f32,
    occupied_levels: u64,
    cells: FrozenCells,
    records: Vec<Record>,
    /// Each record's position and squared reach, beside the records: a cell hands out a few
    /// records for each one that reaches the point, and testing those against 16 bytes each
    /// instead of a whole record keeps the test in the processor's caches.
    spheres: Vec<Vec4>,
}

impl FrozenIndex {
    /// The index of `records`, listed in the order given.
    fn of(base_cell: f32, records: Vec<Record>) -> FrozenIndex {
        let mut frozen = FrozenIndex {
            base_cell,
            occupied_levels: 0,
            cells: FrozenCells::default(),
            records: Vec::with_capacity(records.len()),
            spheres: Vec::with_capacity(records.len()),
        };
        records.into_iter().for_each(|r| frozen.push(r));
        frozen
    }

    /// Adds a record (the levels and cells are `RecordIndex`'s).
    pub fn push(&mut self, record: Record) {
        let level = level_for(self.base_cell, record.reach());
        let size = cell_size(self.base_cell, level);
        let reach = Vec3::splat(record.reach());
        let (lo, hi) = (
            cell_of(record.position - reach, size),
            cell_of(record.position + reach, size),
        );
        let index = self.records.len() as u32;
        for x in lo.0..=hi.0 {
            for y in lo.1..=hi.1 {
                for z in lo.2..=hi.2 {
                    self.cells.entry((level, x, y, z)).or_default().push(index);
                }
            }
        }
        self.occupied_levels |= 1 << level;
        self.spheres
            .push(record.position.extend(record.reach() * record.reach()));
        self.records.push(record);
    }

    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// A copy holding only the records at `picked` (places here), its k-th `picked[k]`.
    pub fn subset(&self, picked: &[usize]) -> FrozenIndex {
        FrozenIndex::of(
            self.base_cell,
            picked.iter().map(|&i| self.records[i].clone()).collect(),
        )
    }

    /// Puts `smaller`, record `index` with its radii shrunk, in its place. The record stays
    /// listed in the cells of its old reach, which hold its new one: a query still visits it
    /// once wherever it now reaches, and tests the new reach.
    pub fn shrink(&mut self, index: usize, smaller: Record) {
        let old = &self.records[index];
        assert!(
            smaller.position == old.position && smaller.reach() <= old.reach(),
            "a record may only shrink in place"
        );
        self.spheres[index] = smaller.position.extend(smaller.reach() * smaller.reach());
        self.records[index] = smaller;
    }

    /// Sets record `index`'s fitted curvature (which changes neither its reach nor its
    /// identity).
    pub fn set_curvature(&mut self, index: usize, curvature: f32) {
        self.records[index].curvature = curvature;
    }

    /// The records, in the order they were listed.
    pub fn records(&self) -> &[Record] {
        &self.records
    }

    /// `for_each_near` with each record's position in `records()`.
    pub fn for_each_near_indexed(&self, p: Vec3, mut visit: impl FnMut(usize, &Record)) {
        let _ = self.try_for_each_near_indexed(p, |i, r| {
            visit(i, r);
            ControlFlow::Continue(())
        });
    }

    /// `for_each_near_indexed` until `visit` breaks (whether it did).
    pub fn try_for_each_near_indexed(
        &self,
        p: Vec3,
        mut visit: impl FnMut(usize, &Record) -> ControlFlow<()>,
    ) -> ControlFlow<()> {
        let mut levels = self.occupied_levels;
        while levels != 0 {
            let level = levels.trailing_zeros();
            levels &= levels - 1;
            let (x, y, z) = cell_of(p, cell_size(self.base_cell, level));
            if let Some(list) = self.cells.get(&(level, x, y, z)) {
                for &i in list {
                    let sphere = self.spheres[i as usize];
                    if (sphere.truncate() - p).length_squared() <= sphere.w {
                        visit(i as usize, &self.records[i as usize])?;
                    }
                }
            }
        }
        ControlFlow::Continue(())
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Calls `visit` for every record whose reach covers `p` (the sphere of its largest radius;
    /// the caller applies the exact test), each once.
    pub fn for_each_near(&self, p: Vec3, mut visit: impl FnMut(&Record)) {
        self.for_each_near_indexed(p, |_, r| visit(r));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::record::tests::flat_record;
    use crate::sampling::Rng;

    /// A record replaced by a smaller one is found where the smaller one reaches only, and
    /// counted once.
    #[test]
    fn a_replaced_record_moves_to_its_new_reach() {
        let index = RecordIndex::new(0.01);
        let big = flat_record(1.0, 2.0);
        index.insert(big.clone());
        index.insert(flat_record(5.0, 0.1));
        let mut small = big.clone();
        small.radii = [0.2, 0.2];
        assert!(index.replace(&big, small.clone()));
        assert!(!index.replace(&big, small.clone()), "the old form is gone");
        assert_eq!(index.len(), 2);
        let mut values = Vec::new();
        index.for_each_near(Vec3::ZERO, |r| values.push((r.value.x, r.radii[0])));
        values.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert_eq!(values, [(1.0, 0.2), (5.0, 0.1)]);
        let mut far = 0;
        index.for_each_near(Vec3::new(1.5, 0.0, 0.0), |r| {
            far += usize::from((r.position - Vec3::new(1.5, 0.0, 0.0)).length() <= r.reach())
        });
        assert_eq!(far, 0);
    }

    /// `count` records scattered in the cube [-2, 2]^3, mostly small (radii up to 0.01 +
    /// `largest`), record k holding the value k.
    fn scattered(count: usize, largest: f32, rng: &mut Rng) -> RecordIndex {
        let index = RecordIndex::new(0.01);
        for k in 0..count {
            let mut r = flat_record(k as f32, 0.01 + largest * rng.next_f32().powi(3));
            r.position = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            index.insert(r);
        }
        index
    }

    /// Records shrunk in a snapshot (`FrozenIndex::shrink`, as the prepass does between
    /// rounds) leave it answering every query as a snapshot built afresh from the shrunk
    /// records does: each record that reaches the point, once, in its new form.
    #[test]
    fn a_snapshot_shrunk_in_place_answers_as_one_built_afresh() {
        let mut rng = Rng::new(7, 8);
        let index = scattered(1500, 0.5, &mut rng);
        let mut snapshot = index.snapshot();
        for i in (0..snapshot.len()).step_by(3) {
            let old = snapshot.records()[i].clone();
            let mut smaller = old.clone();
            // Down to a sixteenth: many move to a finer level of the index.
            smaller.radii = old.radii.map(|r| r * (0.0625 + 0.9 * rng.next_f32()));
            assert!(index.replace(&old, smaller.clone()));
            snapshot.shrink(i, smaller);
        }
        let afresh = index.snapshot();
        let found = |index: &FrozenIndex, p: Vec3| {
            let mut out = Vec::new();
            index.for_each_near(p, |r| out.push((r.value.x, r.radii[0].to_bits())));
            out.sort_by(|a, b| a.0.total_cmp(&b.0));
            out
        };
        let mut nonempty = 0;
        for _ in 0..2000 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            let ours = found(&snapshot, p);
            nonempty += usize::from(!ours.is_empty());
            assert_eq!(ours, found(&afresh, p), "at {p}");
        }
        assert!(nonempty > 500, "the queries reach records ({nonempty} of 2000)");
    }

    #[test]
    #[should_panic(expected = "only shrink")]
    fn a_snapshot_record_may_not_grow_in_place() {
        let index = RecordIndex::new(0.01);
        index.insert(flat_record(1.0, 0.1));
        let mut snapshot = index.snapshot();
        let mut larger = snapshot.records()[0].clone();
        larger.radii = [0.2, 0.2];
        snapshot.shrink(0, larger);
    }

    /// A subset finds, at every point, the records of the whole it holds, as the whole
    /// finds them (its k-th record is the whole's `picked[k]`).
    #[test]
    fn a_subset_finds_its_records_as_the_whole_does() {
        let mut rng = Rng::new(9, 10);
        let index = scattered(800, 0.4, &mut rng);
        let all = index.snapshot();
        let picked: Vec<usize> = (0..all.len()).filter(|i| i % 7 == 3).collect();
        let subset = all.subset(&picked);
        let mut found_some = 0;
        for _ in 0..4000 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            let mut expected = Vec::new();
            all.for_each_near_indexed(p, |i, _| expected.extend(picked.binary_search(&i).ok()));
            let mut found = Vec::new();
            subset.for_each_near_indexed(p, |k, r| {
                assert_eq!(r, &all.records()[picked[k]]);
                found.push(k);
            });
            expected.sort();
            found.sort();
            found_some += usize::from(!found.is_empty());
            assert_eq!(found, expected, "at {p}");
        }
        assert!(found_some > 100, "the subset reaches some points ({found_some})");
    }

    #[test]
    fn finds_every_record_whose_reach_covers_the_point() {
        let index = RecordIndex::new(0.01);
        let mut rng = Rng::new(1, 2);
        let mut records = Vec::new();
        for _ in 0..2000 {
            let mut r = flat_record(1.0, 0.01 + 0.5 * rng.next_f32().powi(3));
            r.position = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            index.insert(r.clone());
            records.push(r);
        }
        assert_eq!(index.len(), 2000);
        for _ in 0..500 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            let expected = records
                .iter()
                .filter(|r| (r.position - p).length() <= r.reach())
                .count();
            let mut found = 0;
            index.for_each_near(p, |r| {
                if (r.position - p).length() <= r.reach() {
                    found += 1;
                }
            });
            assert_eq!(found, expected);
        }
    }

    #[test]
    fn the_frozen_index_finds_the_same_records_once_each() {
        let index = RecordIndex::new(0.01);
        let mut rng = Rng::new(5, 6);
        for _ in 0..2000 {
            let mut r = flat_record(rng.next_f32(), 0.01 + 0.5 * rng.next_f32().powi(3));
            r.position = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            index.insert(r);
        }
        let frozen = index.frozen();
        assert_eq!(frozen.len(), 2000);
        let key = |r: &Record| r.position.to_array().map(f32::to_bits);
        for _ in 0..500 {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 4.0 - 2.0;
            let (mut live, mut frozen_found) = (Vec::new(), Vec::new());
            index.for_each_near(p, |r| {
                if (r.position - p).length() <= r.reach() {
                    live.push(key(r));
                }
            });
            frozen.for_each_near(p, |r| {
                if (r.position - p).length() <= r.reach() {
                    frozen_found.push(key(r));
                }
            });
            // No record twice, and the same set.
            let mut unique = frozen_found.clone();
            unique.sort();
            unique.dedup();
            assert_eq!(unique.len(), frozen_found.len());
            live.sort();
            assert_eq!(live, unique);
        }
        // The same records inserted in another order freeze to the same listing.
        let again = RecordIndex::new(0.01);
        let mut all = index.all();
        all.reverse();
        all.into_iter().for_each(|r| again.insert(r));
        let (a, b) = (index.frozen(), again.frozen());
        assert!(a.records == b.records);
    }

    #[test]
    fn lookups_stay_cheap_at_a_million_records() {
        // A million records on a unit square, sized so that about ten cover any point, as a
        // cache at moderate accuracy has them.
        let index = RecordIndex::new(0.001);
        let mut rng = Rng::new(3, 4);
        for _ in 0..1_000_000 {
            let mut r = flat_record(1.0, 0.001 + 0.002 * rng.next_f32());
            r.position = Vec3::new(rng.next_f32(), rng.next_f32(), 0.0);
            index.insert(r);
        }
        let start = std::time::Instant::now();
        let (mut candidates, mut covering) = (0usize, 0usize);
        let queries = 20_000;
        for _ in 0..queries {
            let p = Vec3::new(rng.next_f32(), rng.next_f32(), 0.0);
            index.for_each_near(p, |r| {
                candidates += 1;
                covering += ((r.position - p).length() <= r.reach()) as usize;
            });
        }
        let per_query = start.elapsed().as_secs_f64() / queries as f64;
        assert!(
            covering / queries >= 5,
            "{} covering records per query",
            covering / queries
        );
        // The grid hands out a bounded multiple of the records that really cover the point.
        assert!(
            candidates < 40 * covering,
            "{candidates} candidates for {covering} covering"
        );
        // Generous (debug builds, a busy machine): a query takes microseconds, not milliseconds.
        assert!(per_query < 1e-4, "{per_query} s per query");
    }
}
