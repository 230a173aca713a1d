//! The last bounce's grid: a world-space average of the light that surfaces at the last
//! bounce's level receive, so that the rays leaving a record at -ab 2 and beyond need not
//! each pick a light, trace a shadow ray and one more path segment (the idea of V-Ray's light
//! cache, in its simplest form, direct light stored with the indirect as it does by default).
//!
//! A record's hemisphere rays at -ab 2 end on surfaces whose light is what the record averages:
//! shaded as a path, each hit pays a light pick, a shadow ray, a second ray and its own shadow
//! ray, and brings one noisy sample of its direct and of its indirect light, the noise that
//! sets the records' error there. The grid holds, per cell of space and side a surface faces,
//! the mean of many such samples of both (irradiance over pi) taken before the prepass
//! (`shading::last_bounce` places them); a hemisphere ray's hit reads its cell's mean and
//! applies its own albedo instead. What it gives up is detail finer than a cell in the light
//! arriving at the surfaces a record sees, seen through the record's whole hemisphere.
//! Measured against the grid of indirect light alone (conference room and Sibenik, -ab 2,
//! the peers bench's settings, two seeds, 4 Dec): the render 0.72-0.86x the time, the
//! indirect layer's 4x4 error against brute force about halved on the conference room's
//! default view at the middle setting (1.0e-3 -> 5.2e-4), and the composite's error at equal
//! or lower levels in 5 of 6 comparisons (the sixth 1.3x higher at 0.77x the time).
//!
//! The mean is made in the order the samples are given (the builder gives them in site order),
//! so every process and thread count builds the same grid.

use glam::{DVec3, Vec3};
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A cell's mean is used only once this many samples made it: below that a hit traces its
/// path as without the grid (at the image's edge, on surfaces seldom seen).
pub const MIN_SAMPLES: u32 = 8;

/// Cells per scene size along each axis.
pub const CELLS_PER_SIZE: f32 = 128.0;

/// The finest cells' side for grid samples at `positions` in a scene whose bounding box's
/// diagonal is `scene_size`: `CELLS_PER_SIZE` cells across the diagonal of the box the samples
/// span, or of the scene's where that is smaller. The scene's box is blind to where the camera
/// stands: a room seen from inside, in a scene whose far speck makes its box 75 times the
/// room, had cells of most of the room's size: at -ab 1 (the grid holding the direct light)
/// the indirect light's error against brute force was 4.75e-2 with them, 5.3e-3 with the
/// samples' box, 6.8e-3 without a grid (the room of tests/cache_prepass.rs, 4x4 blocks).
/// Where the samples span the scene, the cells are about as the scene's box gives them (8 Dec:
/// 2.5-3.6 % smaller on the peers bench's views; conference room at -ab 2, 512x384, 0.99x the
/// time by pair medians).
pub fn cell_side(scene_size: f32, positions: impl IntoIterator<Item = Vec3>) -> f32 {
    let (low, high) = positions
        .into_iter()
        .filter(|p| p.is_finite())
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(low, high), p| {
            (low.min(p), high.max(p))
        });
    let spanned = (high - low).length();
    let size = match spanned.is_finite() && spanned > 0.0 {
        true => spanned.min(scene_size),
        false => scene_size,
    };
    snapped(size.max(f32::MIN_POSITIVE) / CELLS_PER_SIZE)
}

/// Steps of the cells' side per octave (`snapped`): 1.1 % apart.
const SIDE_STEPS_PER_OCTAVE: f32 = 64.0;

/// `side` moved to the nearest of the sizes 1/64 of an octave apart (2^(k/64), at most 0.55 %
/// away): the samples' box, and so the side, moves by a rounding when the same surfaces are
/// placed another way (an instance's hits are intersected in its own space), and every cell
/// boundary with it, so two renders that should agree to a rounding read different cells
/// everywhere (tests/instancing.rs, the instances far from the origin: the indirect layer's
/// means 1.6e-4 apart). On the steps only a side within a rounding of a step's midpoint tips.
fn snapped(side: f32) -> f32 {
    let steps = (SIDE_STEPS_PER_OCTAVE * side.log2()).round();
    (steps / SIDE_STEPS_PER_OCTAVE).exp2()
}

/// Most pixels that start sites: a larger image starts them on a sparser lattice
/// (`site_stride`). About a quarter of a million sites hold the conference room's grid many
/// times over (320x240 takes 76,800).
pub const MAX_SITE_PIXELS: u64 = 1 << 18;

/// The spacing of the pixels that start sites in a `width` x `height` image: 1 up to
/// `MAX_SITE_PIXELS` pixels, else the smallest that keeps them within it.
pub fn site_stride(width: u32, height: u32) -> u32 {
    let mut stride = 1u64;
    while (width as u64).div_ceil(stride) * (height as u64).div_ceil(stride) > MAX_SITE_PIXELS {
        stride += 1;
    }
    stride as u32
}

/// Which cell a point and the side it faces fall in: the cell's integer coordinates (20 bits
/// each, wrapping far out, where cells a million apart share a key) and the normal's dominant
/// axis and sign (6 sides: the floor and the ceiling above it never share a mean).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct CellKey(u64);

/// The grid: for each of `LEVELS` cell sizes (the finest `cell`, each next one twice as
/// large), each well-sampled cell's mean. A lookup reads the finest cell that has one: where
/// the sites are dense (the surfaces near the camera) the cells are small, where they are
/// sparse the light is averaged over more space rather than traced again.
///
/// Most lookups land in a finest cell some sample fell in, but one with too few samples for a
/// mean of its own (on Sibenik at -ab 2, 37 % of lookups were answered a level up, 85 % of
/// those from such a cell): each then paid a failed probe per level before the one that
/// answered. So every finest cell a sample fell in holds its answer, resolved when the grid is
/// built (`resolved`), and only a lookup in a cell no sample fell in tries the coarser levels
/// in turn: the same answers, four lookups in five one probe.
#[derive(Clone, Debug, Default)]
pub struct LastBounceGrid {
    cell: f32,
    /// Each finest cell some sample fell in, with the mean of the finest cell around it that
    /// has one (if any has).
    resolved: CellTable,
    /// The coarser levels' cells with a mean, level 1 first (the finest level's are all in
    /// `resolved`).
    coarser: Vec<CellTable>,
    /// How many finest cells have a mean of their own.
    finest_cells: usize,
    samples: u64,
}

/// Each level's cells with a mean (the finest first), each finest cell a sample fell in with
/// its keys at every level (as the first sample in it gave them), and the samples counted.
struct LevelMeans {
    levels: Vec<CellTable>,
    ancestors: HashMap<CellKey, [CellKey; LEVELS], BuildHasherDefault<KeyHasher>>,
    samples: u64,
}

impl LevelMeans {
    /// The means of `samples` in cells of side `cell` and its coarser levels (`levels` in all,
    /// at most `LEVELS`), summed in the order given; cells with fewer than `least` samples are
    /// left out, and non-finite samples. With one level no finest cell's keys are kept (no
    /// coarser level is searched): building the grid is serial, and at -ab 1 (four samples a
    /// site) the levels a lookup never reads were 1.5 % of the render's samples (perf).
    fn of(cell: f32, samples: impl IntoIterator<Item = GridSample>, levels: usize, least: u32) -> LevelMeans {
        type Sums = HashMap<CellKey, (DVec3, DVec3, u32), BuildHasherDefault<KeyHasher>>;
        let mut sums: Vec<Sums> = (0..levels.clamp(1, LEVELS)).map(|_| Sums::default()).collect();
        let mut ancestors: HashMap<CellKey, [CellKey; LEVELS], BuildHasherDefault<KeyHasher>> = HashMap::default();
        let mut count = 0;
        for sample in samples {
            let Received { direct, indirect } = sample.received;
            if !direct.is_finite() || !indirect.is_finite() {
                continue;
            }
            let place = Place::of(cell, sample.position, sample.normal);
            if sums.len() > 1 {
                ancestors
                    .entry(place.key(0))
                    .or_insert_with(|| std::array::from_fn(|level| place.key(level)));
            }
            for (level, sums) in sums.iter_mut().enumerate() {
                let key = place.key(level);
                let entry = sums.entry(key).or_insert((DVec3::ZERO, DVec3::ZERO, 0));
                entry.0 += direct.as_dvec3();
                entry.1 += indirect.as_dvec3();
                entry.2 += 1;
            }
            count += 1;
        }
        let levels = sums
            .into_iter()
            .map(|sums| {
                sums.into_iter()
                    .filter(|(_, (_, _, n))| *n >= least)
                    .map(|(key, (direct, indirect, n))| {
                        let mean = |sum: DVec3| (sum / n as f64).as_vec3();
                        let received = Received {
                            direct: mean(direct),
                            indirect: mean(indirect),
                        };
                        (key, received)
                    })
                    .collect::<Vec<_>>()
            })
            .map(|cells| CellTable::new(&cells))
            .collect();
        LevelMeans {
            levels,
            ancestors,
            samples: count,
        }
    }

    /// The means of the finest level around (p, normal) that has one: the levels searched in
    /// turn.
    #[cfg(test)]
    fn search(&self, cell: f32, p: Vec3, normal: Vec3) -> Option<Received> {
        let place = Place::of(cell, p, normal);
        (self.levels.iter().enumerate()).find_map(|(level, means)| means.get(place.key(level)))
    }
}

/// A cell's means (irradiance over pi): the direct and the indirect light its samples
/// received.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Received {
    pub direct: Vec3,
    pub indirect: Vec3,
}

/// Cell sizes, each twice the one before.
pub const LEVELS: usize = 4;

/// Which cells answer a lookup.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reads {
    /// The finest cell with a mean around the point, up to `LEVELS - 1` levels coarser: where
    /// a hit the grid does not answer traces a path (-ab 2 and more), a coarser mean is worth
    /// its blur.
    CoarserToo,
    /// Only a finest cell with a mean of its own: where a hit the grid does not answer costs
    /// one shadow ray (-ab 1, the grid holding direct light alone), a coarser cell's blur is
    /// not worth saving it. Measured (8 Dec, conference room 168x128, -ab 1, 10 seeds against
    /// brute force): with coarser cells too the indirect layer's relMSE 2.66e-3 (median), the
    /// finest alone 2.35e-3, no grid 2.33e-3. Each sample is the mean of `draws` draws taken at
    /// its point (a site's direct light samples), and a cell answers from `MIN_SAMPLES` draws:
    /// one sample a site instead of one a draw holds the same means in a quarter of the memory
    /// (a region task of a 20000x20000 frame, whose grid is the whole frame's, peaked at
    /// 184 MiB with a sample a draw and 149 MiB with one a site, against 131 MiB for a 32x32
    /// image, tests/regions.rs; the images agree within 2e-6, the order of the sums apart).
    OwnCell { draws: u32 },
}

/// One sample of the light a surface at the last bounce's level receives: where it was taken,
/// the side the surface faces there, and the value (direct and indirect irradiance over pi).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridSample {
    pub position: Vec3,
    pub normal: Vec3,
    pub received: Received,
}

impl LastBounceGrid {
    /// The grid with finest cells of side `cell` from `samples`, summed in the order given,
    /// read as `reads` says; cells with fewer than `MIN_SAMPLES` draws are left out (a sample is
    /// one draw but where `Reads::OwnCell` says). Non-finite samples are dropped.
    pub fn from_samples(cell: f32, samples: impl IntoIterator<Item = GridSample>, reads: Reads) -> LastBounceGrid {
        let (levels_read, least) = match reads {
            Reads::CoarserToo => (LEVELS, MIN_SAMPLES),
            Reads::OwnCell { draws } => (1, MIN_SAMPLES.div_ceil(draws.max(1))),
        };
        let LevelMeans {
            mut levels,
            ancestors,
            samples,
        } = LevelMeans::of(cell, samples, levels_read, least);
        if levels_read == 1 {
            let finest = levels.remove(0);
            return LastBounceGrid {
                cell,
                finest_cells: finest.len,
                resolved: finest,
                coarser: Vec::new(),
                samples,
            };
        }
        let resolved: Vec<(CellKey, Received)> = ancestors
            .iter()
            .filter_map(|(&key, chain)| {
                let received = levels.iter().zip(chain).find_map(|(table, &key)| table.get(key))?;
                Some((key, received))
            })
            .collect();
        let finest = levels.remove(0);
        LastBounceGrid {
            cell,
            resolved: CellTable::new(&resolved),
            coarser: levels,
            finest_cells: finest.len,
            samples,
        }
    }

    /// The finest cells' side.
    pub fn cell(&self) -> f32 {
        self.cell
    }

    /// The means of the finest cell `p` falls in on the side `normal` faces that was sampled
    /// enough, if any.
    pub fn lookup(&self, p: Vec3, normal: Vec3) -> Option<Received> {
        let place = Place::of(self.cell, p, normal);
        if let Some(received) = self.resolved.get(place.key(0)) {
            return Some(received);
        }
        // A finest cell no sample fell in (or none around it has a mean): the coarser levels.
        (1..)
            .zip(&self.coarser)
            .find_map(|(level, means)| means.get(place.key(level)))
    }

    /// Starts loading what `lookup(p, normal)` will read first (the resolved finest cell) and
    /// next (the level above), so a batch of hits can have the grid's cache misses under way
    /// together.
    #[inline]
    pub fn prefetch(&self, p: Vec3, normal: Vec3) {
        let place = Place::of(self.cell, p, normal);
        self.resolved.prefetch(place.key(0));
        if let Some(above) = self.coarser.first() {
            above.prefetch(place.key(1));
        }
    }

    /// Cells with a mean, at every level.
    pub fn cells(&self) -> usize {
        self.finest_cells + self.coarser.iter().map(|l| l.len).sum::<usize>()
    }

    /// Samples the grid was built from.
    pub fn samples(&self) -> u64 {
        self.samples
    }
}

/// Where a point falls: its finest cell's integer coordinates and the side it faces. A coarser
/// level's cell is the finest one's coordinates shifted right by the level, the same cell as
/// dividing by the level's side (a power of two times the finest) would give, for one division
/// and one rounding a lookup instead of one per level tried.
///
/// The lattice lies half a finest cell behind the surface: a wall at a multiple of the cell
/// (x = 1 in cells of 1/32) then keeps at least half a cell from every level's cell boundaries,
/// where float error would otherwise split its points between the cells on either side, leaving
/// each with half the samples (measured as -2.2 % of indirect light in tests/cache_prepass.rs
/// when hits took their points along the ray).
#[derive(Clone, Copy)]
struct Place {
    cell: [i64; 3],
    side: u64,
}

impl Place {
    fn of(cell: f32, p: Vec3, normal: Vec3) -> Place {
        let p = (p - normal * (0.5 * cell)) / cell;
        let a = normal.abs();
        let axis = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        Place {
            cell: [p.x, p.y, p.z].map(|v| v.floor() as i64),
            side: (axis * 2) as u64 + (normal[axis] < 0.0) as u64,
        }
    }

    /// The key of the cell at `level`: coordinates of 20 bits each, wrapping far out (cells a
    /// million apart share a key), and the side.
    fn key(&self, level: usize) -> CellKey {
        let [x, y, z] = self.cell.map(|c| ((c >> level) as u64) & 0xF_FFFF);
        CellKey(x | y << 20 | z << 40 | self.side << 60)
    }
}

/// One level's cells and their means: an open-addressed table (linear probing, at most half
/// full) of 32-byte slots, two to a cache line, whose slot for a key a caller can ask to be
/// loaded ahead of the lookup (`prefetch`): a hash map's would be hidden behind its API, and
/// a lookup's time is the one cache miss on its slot.
#[derive(Clone, Debug, Default)]
struct CellTable {
    slots: Vec<Slot>,
    /// Slots minus one (their count is a power of two).
    mask: usize,
    /// Cells held.
    len: usize,
}

#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
struct Slot {
    key: u64,
    received: Received,
}

/// No key is this: a key's side (bits 60 and up) is at most 5.
const EMPTY: u64 = u64::MAX;

impl CellTable {
    fn new(cells: &[(CellKey, Received)]) -> CellTable {
        let size = (2 * cells.len()).next_power_of_two().max(2);
        let empty = Slot {
            key: EMPTY,
            received: Received::default(),
        };
        let mut table = CellTable {
            slots: vec![empty; size],
            mask: size - 1,
            len: cells.len(),
        };
        for &(key, received) in cells {
            let mut i = table.home(key);
            while table.slots[i].key != EMPTY {
                i = (i + 1) & table.mask;
            }
            table.slots[i] = Slot { key: key.0, received };
        }
        table
    }

    /// Where a key's probe starts: the top bits of its mixed value.
    #[inline]
    fn home(&self, key: CellKey) -> usize {
        let mut hasher = KeyHasher::default();
        hasher.write_u64(key.0);
        (hasher.finish() >> 32) as usize & self.mask
    }

    #[inline]
    fn get(&self, key: CellKey) -> Option<Received> {
        if self.slots.is_empty() {
            return None;
        }
        let mut i = self.home(key);
        loop {
            let slot = &self.slots[i];
            if slot.key == key.0 {
                return Some(slot.received);
            }
            if slot.key == EMPTY {
                return None;
            }
            i = (i + 1) & self.mask;
        }
    }

    #[inline]
    fn prefetch(&self, key: CellKey) {
        let Some(slot) = self.slots.get(self.home(key)) else {
            return;
        };
        crate::sys::prefetch::prefetch(slot);
    }
}

/// The keys are already spread over 64 bits; one multiply mixes them enough for the table.
#[derive(Default)]
pub struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x100_0000_01b3);
        }
    }

    fn write_u64(&mut self, v: u64) {
        self.0 = (v ^ (v >> 29)).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(p: Vec3, n: Vec3, v: f32) -> GridSample {
        GridSample {
            position: p,
            normal: n,
            // The direct light ten times the indirect, to tell them apart.
            received: Received {
                direct: Vec3::splat(10.0 * v),
                indirect: Vec3::splat(v),
            },
        }
    }

    #[test]
    fn the_cell_table_finds_every_key_it_holds_and_no_other() {
        // Keys as a grid makes them: neighbouring cells, every side, so many share a home.
        let mut cells = Vec::new();
        for x in 0..40u64 {
            for y in 0..30u64 {
                let key = CellKey(x | y << 20 | (x % 6) << 60);
                let value = (x * 100 + y) as f32;
                cells.push((
                    key,
                    Received {
                        direct: Vec3::splat(value),
                        indirect: Vec3::splat(-value),
                    },
                ));
            }
        }
        let table = CellTable::new(&cells);
        assert_eq!(table.len, cells.len());
        assert!(table.slots.len() >= 2 * cells.len());
        for (key, received) in &cells {
            assert_eq!(table.get(*key), Some(*received));
            table.prefetch(*key);
        }
        for x in 40..80u64 {
            assert_eq!(table.get(CellKey(x | 5 << 20)), None);
        }
        assert_eq!(CellTable::new(&[]).get(CellKey(0)), None);
    }

    #[test]
    fn a_cell_reads_the_mean_of_its_samples_once_it_has_enough() {
        let p = Vec3::new(0.5, 0.5, 0.5);
        let few: Vec<_> = (0..MIN_SAMPLES - 1).map(|_| at(p, Vec3::Y, 1.0)).collect();
        assert_eq!(
            LastBounceGrid::from_samples(1.0, few, Reads::CoarserToo)
                .lookup(Vec3::splat(0.2), Vec3::Y)
                .map(|l| l.indirect),
            None
        );
        let many: Vec<_> = (0..2 * MIN_SAMPLES).map(|i| at(p, Vec3::Y, (i % 2) as f32)).collect();
        let grid = LastBounceGrid::from_samples(1.0, many, Reads::CoarserToo);
        assert_eq!(
            grid.lookup(Vec3::splat(0.9), Vec3::Y).map(|l| l.indirect),
            Some(Vec3::splat(0.5))
        );
        assert_eq!(grid.cells(), LEVELS);
    }

    #[test]
    fn the_resolved_finest_cells_answer_as_the_levels_searched_in_turn() {
        // Samples clustered unevenly on the six sides of a few walls, so that cells of every
        // level have a mean or lack one; lookups everywhere, in cells samples fell in and not.
        let mut rng = crate::sampling::Rng::new(3, 1);
        let normals = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        let mut samples = Vec::new();
        for cluster in 0..60 {
            let centre = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 8.0;
            let spread = [0.05, 0.5, 2.0][cluster % 3];
            let normal = normals[cluster % 6];
            for _ in 0..(1 + cluster % 20) {
                let offset = Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * spread;
                samples.push(at(centre + offset, normal, rng.next_f32()));
            }
        }
        let grid = LastBounceGrid::from_samples(0.25, samples.iter().copied(), Reads::CoarserToo);
        let means = LevelMeans::of(0.25, samples.iter().copied(), LEVELS, MIN_SAMPLES);
        let by_levels = |p: Vec3, n: Vec3| means.search(0.25, p, n);
        let mut answered = [0; 2];
        for k in 0..20_000 {
            let (p, n) = if k % 2 == 0 {
                let s = &samples[k / 2 % samples.len()];
                (
                    s.position + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 0.3,
                    s.normal,
                )
            } else {
                (
                    Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 9.0,
                    normals[k % 6],
                )
            };
            let found = grid.lookup(p, n);
            assert_eq!(found, by_levels(p, n), "{p} {n}");
            answered[found.is_some() as usize] += 1;
        }
        assert!(answered[0] > 1000 && answered[1] > 1000, "{answered:?}");
        // A cell some sample fell in answers in one probe, whichever level its answer is from.
        let mut coarser = 0;
        for sample in &samples {
            let place = Place::of(grid.cell, sample.position, sample.normal);
            let answer = by_levels(sample.position, sample.normal);
            assert_eq!(grid.resolved.get(place.key(0)), answer);
            coarser += (answer.is_some() && means.levels[0].get(place.key(0)).is_none()) as usize;
        }
        assert!(
            coarser > 50,
            "only {coarser} samples' cells answered from a coarser level"
        );
    }

    #[test]
    fn cells_are_sized_by_what_the_samples_span_at_most_the_scene() {
        // Samples in a room of diagonal 3 (a 1 x 2 x 2 box) in a scene of diagonal 300.
        // Sides are snapped to 1/64 octaves: within 0.55 % of the size over CELLS_PER_SIZE.
        let near = |side: f32, size: f32| {
            let ratio = side / (size / CELLS_PER_SIZE);
            let steps = SIDE_STEPS_PER_OCTAVE * side.log2();
            ratio > 0.9945 && ratio < 1.0055 && (steps - steps.round()).abs() < 1e-3
        };
        let room = [Vec3::ZERO, Vec3::new(1.0, 2.0, 2.0), Vec3::new(0.5, 1.0, 0.2)];
        assert!(near(cell_side(300.0, room), 3.0));
        // Samples wider than the scene's box (a point past it by a rounding): the scene's.
        assert_eq!(cell_side(2.0, room), cell_side(2.0, []));
        assert!(near(cell_side(2.0, []), 2.0));
        // No samples, one, or none finite: the scene's.
        assert!(near(cell_side(300.0, []), 300.0));
        assert_eq!(cell_side(300.0, [Vec3::ONE]), cell_side(300.0, []));
        assert_eq!(cell_side(300.0, [Vec3::NAN, Vec3::INFINITY]), cell_side(300.0, []));
        // A box moved by roundings gives the same side.
        let moved = room.map(|p| p * (1.0 + 3e-7) + Vec3::splat(1e-6));
        assert_eq!(cell_side(300.0, moved), cell_side(300.0, room));
    }

    /// Enough samples in the 2x2x2 block [0, 2)^3 (y in [0.5, 2.5): the lattice lies half a
    /// cell behind surfaces facing +y), each unit cell too few alone but two.
    fn two_full_cells_and_a_sparse_one() -> Vec<GridSample> {
        let mut samples: Vec<_> = (0..MIN_SAMPLES)
            .map(|_| at(Vec3::new(0.5, 1.0, 0.5), Vec3::Y, 4.0))
            .collect();
        samples.extend((0..MIN_SAMPLES).map(|_| at(Vec3::new(1.5, 2.0, 1.5), Vec3::Y, 0.0)));
        samples.push(at(Vec3::new(1.5, 1.0, 0.5), Vec3::Y, 2.0));
        samples
    }

    #[test]
    fn reading_own_cells_leaves_a_sparse_cell_unanswered() {
        // The cells with enough samples answer as with coarser cells read too, the sparse one
        // and an empty one not at all.
        let grid = LastBounceGrid::from_samples(1.0, two_full_cells_and_a_sparse_one(), Reads::OwnCell { draws: 1 });
        let read = |p: Vec3| grid.lookup(p, Vec3::Y).map(|l| l.indirect);
        assert_eq!(read(Vec3::new(0.4, 0.9, 0.4)), Some(Vec3::splat(4.0)));
        assert_eq!(read(Vec3::new(1.4, 1.9, 1.4)), Some(Vec3::splat(0.0)));
        assert_eq!(read(Vec3::new(1.5, 1.0, 0.5)), None);
        assert_eq!(read(Vec3::new(0.5, 1.9, 1.5)), None);
        assert_eq!(grid.cells(), 2);
        // Samples that each stand for 4 draws: two make a cell's mean, one does not.
        let p = Vec3::new(0.5, 1.0, 0.5);
        let pair = [at(p, Vec3::Y, 1.0), at(p, Vec3::Y, 3.0)];
        let grid = LastBounceGrid::from_samples(1.0, pair, Reads::OwnCell { draws: 4 });
        let near = Vec3::new(0.4, 0.9, 0.4);
        assert_eq!(grid.lookup(near, Vec3::Y).map(|l| l.indirect), Some(Vec3::splat(2.0)));
        let grid = LastBounceGrid::from_samples(1.0, [pair[0]], Reads::OwnCell { draws: 4 });
        assert_eq!(grid.lookup(near, Vec3::Y), None);
    }

    #[test]
    fn a_sparse_cell_reads_the_coarser_cell_around_it() {
        let grid = LastBounceGrid::from_samples(1.0, two_full_cells_and_a_sparse_one(), Reads::CoarserToo);
        assert_eq!(
            grid.lookup(Vec3::new(0.4, 0.9, 0.4), Vec3::Y).map(|l| l.indirect),
            Some(Vec3::splat(4.0))
        );
        assert_eq!(
            grid.lookup(Vec3::new(1.4, 1.9, 1.4), Vec3::Y).map(|l| l.indirect),
            Some(Vec3::splat(0.0))
        );
        let block = (8.0 * 4.0 + 2.0) / (2 * MIN_SAMPLES + 1) as f32;
        assert_eq!(
            grid.lookup(Vec3::new(1.5, 1.0, 0.5), Vec3::Y).map(|l| l.indirect),
            Some(Vec3::splat(block))
        );
        assert_eq!(
            grid.lookup(Vec3::new(1.5, 1.0, 0.5), -Vec3::Y).map(|l| l.indirect),
            None
        );
        // The direct light's mean beside the indirect light's.
        assert_eq!(
            grid.lookup(Vec3::new(0.4, 0.9, 0.4), Vec3::Y).map(|l| l.direct),
            Some(Vec3::splat(40.0))
        );
        let direct = grid.lookup(Vec3::new(1.5, 1.0, 0.5), Vec3::Y).map(|l| l.direct);
        assert_eq!(direct, Some(Vec3::splat(10.0 * block)));
    }

    #[test]
    fn neighbouring_cells_and_opposite_sides_have_their_own_keys() {
        let key = |p: Vec3, n: Vec3| Place::of(2.0, p, n).key(0);
        let p = Vec3::new(1.0, 1.0, 1.0);
        // Both half a cell (1.0) behind along their normals: in the cell [0, 2)^3.
        assert_eq!(key(p, Vec3::Y), key(Vec3::new(1.9, 1.9, 1.5), Vec3::new(0.3, 0.9, 0.1)));
        assert_ne!(key(p, Vec3::Y), key(p, -Vec3::Y));
        assert_ne!(key(p, Vec3::Y), key(p, Vec3::X));
        assert_ne!(key(p, Vec3::Y), key(Vec3::new(2.1, 1.0, 1.0), Vec3::Y));
        assert_ne!(key(p, Vec3::Y), key(Vec3::new(-1.0, 1.0, 1.0), Vec3::Y));
        assert_ne!(key(p, Vec3::Y), key(Vec3::new(1.0, 1.0, -1.0), Vec3::Y));
    }

    #[test]
    fn a_wall_on_a_cell_boundary_keeps_its_points_in_one_cell_at_every_level() {
        // A wall at x = 1 facing -x, in cells of 1/32: its points lie a float step either side.
        let cell = 1.0 / 32.0;
        let (below, above) = (
            f32::from_bits(1.0f32.to_bits() - 1),
            f32::from_bits(1.0f32.to_bits() + 1),
        );
        for level in 0..LEVELS {
            let key = |x: f32| Place::of(cell, Vec3::new(x, 0.3, 0.3), -Vec3::X).key(level);
            assert_eq!(key(below), key(1.0), "level {level}");
            assert_eq!(key(above), key(1.0), "level {level}");
        }
    }

    #[test]
    fn large_images_start_sites_on_a_sparser_lattice() {
        assert_eq!(site_stride(320, 240), 1);
        assert_eq!(site_stride(512, 512), 1);
        assert_eq!(site_stride(513, 512), 2);
        assert_eq!(site_stride(1920, 1080), 3);
        for (w, h) in [(7680, 4320), (20000, 20000), (1, 1_000_000)] {
            let s = site_stride(w, h) as u64;
            assert!(
                (w as u64).div_ceil(s) * (h as u64).div_ceil(s) <= MAX_SITE_PIXELS,
                "{w}x{h}"
            );
            assert!(
                (w as u64).div_ceil(s - 1) * (h as u64).div_ceil(s - 1) > MAX_SITE_PIXELS,
                "{w}x{h}"
            );
        }
    }

    #[test]
    fn non_finite_samples_are_dropped() {
        let mut samples: Vec<_> = (0..MIN_SAMPLES).map(|_| at(Vec3::splat(0.5), Vec3::Z, 2.0)).collect();
        samples.push(at(Vec3::splat(0.5), Vec3::Z, f32::NAN));
        samples.push(GridSample {
            received: Received {
                direct: Vec3::splat(f32::INFINITY),
                indirect: Vec3::ONE,
            },
            ..at(Vec3::splat(0.5), Vec3::Z, 0.0)
        });
        samples.push(at(Vec3::splat(0.5), Vec3::Z, f32::INFINITY));
        let grid = LastBounceGrid::from_samples(1.0, samples, Reads::CoarserToo);
        assert_eq!(
            grid.lookup(Vec3::splat(0.5), Vec3::Z).map(|l| l.indirect),
            Some(Vec3::splat(2.0))
        );
        assert_eq!(grid.samples(), MIN_SAMPLES as u64);
    }
}
