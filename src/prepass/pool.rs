//! How the processes of one prepass pool their work. Every list the prepass works through (the
//! last bounce's rows of sites, the rows of the pixel maps, each round's sites) is cut the same
//! way: a process computes its `Share` of the items, and the pool hands every process the
//! results of all of them. One process alone (`Alone`) pools nothing; under mpirun the pool is
//! a collective among the ranks (`parallel::prepass`). The prepass itself never knows which.

use super::RoundLog;
use crate::irradiance::last_bounce::GridSample;
use crate::irradiance::record::Record;
use std::convert::Infallible;

/// Which of a list's items a process computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Share {
    /// Every item (one process).
    All,
    /// Items `index`, `index + count`, `index + 2 count`, ... (one of `count` workers):
    /// interleaved, so that the costly parts of a list (a window, a bright wall) are spread.
    Slice { index: usize, count: usize },
    /// None: a process that only keeps the records (an MPI master, which renders no pixel and
    /// so builds no last bounce's grid either).
    Nothing,
}

impl Share {
    /// This process's items of a list of `items`.
    pub fn indices(self, items: usize) -> Vec<u32> {
        match self {
            Share::All => (0..items as u32).collect(),
            Share::Slice { index, count } => (index..items).step_by(count.max(1)).map(|i| i as u32).collect(),
            Share::Nothing => Vec::new(),
        }
    }

    /// Whether this process shades pixels (and so needs what only shading reads).
    pub fn renders(self) -> bool {
        self != Share::Nothing
    }
}

/// A round's records, each with the index of the site it was made for, in site order.
pub type RoundRecords = Vec<(u32, Record)>;

/// Rows of the last bounce's grid samples: the row's pixel y and its samples in order.
pub type GridRows = Vec<(u32, Vec<GridSample>)>;

/// Rows (or strips of rows) of a per-pixel flag map: the first row's y and the flags of the
/// rows, row-major over the area's width.
pub type PixelRows = Vec<(u32, Vec<bool>)>;

/// What the prepass asks of its processes' pool. Each call is made by every process at the
/// same point with its own part and answers with every process's parts (in any order: the
/// prepass puts them in order itself); an error ends the prepass.
pub trait Pool {
    type Error;
    /// This process's share of every list.
    fn share(&self) -> Share;
    /// A round's records.
    fn round(&mut self, mine: RoundRecords) -> Result<RoundRecords, Self::Error>;
    /// Indices of a round's sites (those of its share that lack records).
    fn sites(&mut self, mine: Vec<u32>) -> Result<Vec<u32>, Self::Error>;
    /// The last bounce's rows (only processes that render build the grid, and only they call).
    fn grid_rows(&mut self, mine: GridRows) -> Result<GridRows, Self::Error>;
    /// Rows of a pixel map.
    fn pixel_rows(&mut self, mine: PixelRows) -> Result<PixelRows, Self::Error>;
    /// Bytes this process has taken in from the others so far (for the rounds' log).
    fn bytes_received(&self) -> u64 {
        0
    }
    /// A round as it joined the record set: its log and its records in order, each with its
    /// site's pixel (y * width + x), for a process that keeps the records without taking part
    /// in the rounds (an MPI master: `parallel::prepass`).
    fn kept(&mut self, _log: RoundLog, _records: &[(u32, Record)]) -> Result<(), Self::Error> {
        Ok(())
    }
    /// The rounds are over; `pixels_sampled` pixels had their samples visited one by one.
    fn ended(&mut self, _pixels_sampled: u64) -> Result<(), Self::Error> {
        Ok(())
    }
    /// Whether anybody hears of `kept` (the records are cloned for it only then).
    fn keeps(&self) -> bool {
        false
    }
}

/// One process: every item is its own, nothing to pool.
pub struct Alone;

impl Pool for Alone {
    type Error = Infallible;

    fn share(&self) -> Share {
        Share::All
    }

    fn round(&mut self, mine: RoundRecords) -> Result<RoundRecords, Infallible> {
        Ok(mine)
    }

    fn sites(&mut self, mine: Vec<u32>) -> Result<Vec<u32>, Infallible> {
        Ok(mine)
    }

    fn grid_rows(&mut self, mine: GridRows) -> Result<GridRows, Infallible> {
        Ok(mine)
    }

    fn pixel_rows(&mut self, mine: PixelRows) -> Result<PixelRows, Infallible> {
        Ok(mine)
    }
}

/// A pool that counts the seconds spent in it (handing over and waiting: under mpirun the
/// rounds' barriers), for the report.
pub struct Timed<'p, P> {
    pool: &'p mut P,
    pub seconds: f64,
}

impl<'p, P: Pool> Timed<'p, P> {
    pub fn new(pool: &'p mut P) -> Self {
        Timed { pool, seconds: 0.0 }
    }

    fn time<T>(&mut self, call: impl FnOnce(&mut P) -> T) -> T {
        let start = std::time::Instant::now();
        let out = call(self.pool);
        self.seconds += start.elapsed().as_secs_f64();
        out
    }
}

impl<P: Pool> Pool for Timed<'_, P> {
    type Error = P::Error;

    fn share(&self) -> Share {
        self.pool.share()
    }

    fn round(&mut self, mine: RoundRecords) -> Result<RoundRecords, P::Error> {
        self.time(|p| p.round(mine))
    }

    fn sites(&mut self, mine: Vec<u32>) -> Result<Vec<u32>, P::Error> {
        self.time(|p| p.sites(mine))
    }

    fn grid_rows(&mut self, mine: GridRows) -> Result<GridRows, P::Error> {
        self.time(|p| p.grid_rows(mine))
    }

    fn pixel_rows(&mut self, mine: PixelRows) -> Result<PixelRows, P::Error> {
        self.time(|p| p.pixel_rows(mine))
    }

    fn bytes_received(&self) -> u64 {
        self.pool.bytes_received()
    }

    fn kept(&mut self, log: RoundLog, records: &[(u32, Record)]) -> Result<(), P::Error> {
        self.time(|p| p.kept(log, records))
    }

    fn ended(&mut self, pixels_sampled: u64) -> Result<(), P::Error> {
        self.time(|p| p.ended(pixels_sampled))
    }

    fn keeps(&self) -> bool {
        self.pool.keeps()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slices_of_a_list_cover_it_once_and_interleave() {
        for items in [0, 1, 7, 64] {
            for count in 1..5 {
                let mut seen = vec![0; items];
                for index in 0..count {
                    let mine = Share::Slice { index, count }.indices(items);
                    assert!(mine.windows(2).all(|w| w[1] - w[0] == count as u32));
                    mine.iter().for_each(|&i| seen[i as usize] += 1);
                }
                assert!(seen.iter().all(|&n| n == 1), "{items} items, {count} slices");
            }
            assert_eq!(Share::All.indices(items).len(), items);
            assert!(Share::Nothing.indices(items).is_empty());
        }
    }
}
