//! The order in which a PA computes the requests queued on it: those whose pixel lies on a
//! coarse grid first, then those on the renderer's grid (--overture), then the rest, each group
//! oldest first.
//!
//! Why: in arrival order a PA meets a tile's requests in scanline order, so each new record is
//! made where the records before it run out and the next points extrapolate from one side, as a
//! serial render does without its overture (see `render_tile`). This does what the overture
//! does, over every tile in the queue: the records on an N-pixel grid first, then most other
//! requests interpolate between records on all sides (the paper credits such a reordering for
//! component mode's fewer cache misses than the serial run, section 6). But the queue is often
//! short (5 processes: empty at 55-93 % of a PA's syncs), and a PA can only reorder what has
//! arrived; so the PRs also render the grid's pixels first, and their requests arrive in order.
//!
//! The coarse grid (every COARSE-th point of the grid) goes first because a queue holds whole
//! tiles, often many: a few records spread over all of them make more of the grid's own points
//! interpolate. Cornell box, -ab 1 -aa 0.2 -ad 256, progressive, the same seeds with and without
//! it: fewer records in 24 of 33 pairs (one tie), e.g. 128x128 at 4 processes 1,017-1,041
//! against 1,026-1,090 (seeds 1-5), one PA alone (--pr-waits) 1,024-1,064 against 1,038-1,095;
//! at 256x256, 5 processes, no change (1,893-1,953 against 1,881-1,953). A single coarser grid
//! does not do it: the serial render makes 1,032 records with --overture 3, 1,068 with 4, 1,123
//! with 6.

use crate::render::pixel::on_image_grid;
use crate::shading::request::AmbientRequest;
use std::collections::VecDeque;

/// The coarse grid's spacing, in the grid's (the one at --overture's spacing; a subset of it).
const COARSE: u32 = 3;

/// A request waiting, with its place in the order of arrival.
type Entry = (u64, AmbientRequest);

pub struct RequestQueue {
    /// Requests on the coarse grid, on the grid (only), and the rest, each oldest first.
    groups: [VecDeque<Entry>; 3],
    /// Requests taken in so far: the next one's place in the order of arrival.
    arrived: u64,
    width: u32,
    /// The grid's spacing in pixels; 0 or 1: plain arrival order.
    stride: u32,
}

impl RequestQueue {
    pub fn new(width: u32, stride: u32) -> Self {
        RequestQueue {
            groups: Default::default(),
            arrived: 0,
            width: width.max(1),
            stride,
        }
    }

    /// Which group a pixel's request waits in. The grids are the image's, whose pixels the PRs
    /// render first (the serial overture counts its blocks from each tile's corner instead; a
    /// PA's queue mixes tiles); the coarse one's points are on the finer one (`on_image_grid`
    /// puts a grid's points at the middle of its blocks, and COARSE is odd).
    fn group(&self, pixel: u32) -> usize {
        let (x, y) = (pixel % self.width, pixel / self.width);
        if self.stride <= 1 {
            2
        } else if on_image_grid(x, y, self.stride * COARSE) {
            0
        } else if on_image_grid(x, y, self.stride) {
            1
        } else {
            2
        }
    }

    pub fn len(&self) -> usize {
        self.groups.iter().map(VecDeque::len).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn extend(&mut self, requests: impl IntoIterator<Item = AmbientRequest>) {
        for request in requests {
            let group = self.group(request.pixel);
            self.groups[group].push_back((self.arrived, request));
            self.arrived += 1;
        }
    }

    /// The next request to compute: the oldest of the first group that has one.
    pub fn pop(&mut self) -> Option<AmbientRequest> {
        self.groups.iter_mut().find_map(VecDeque::pop_front).map(|(_, r)| r)
    }

    /// Up to `count` requests for a helper: the newest to arrive, on a grid or not, in the
    /// order they arrived. They come from the last tiles' requests, a stretch of the image
    /// the PA has not reached yet, so the helper makes that stretch's records (its grids'
    /// first, see `help`) and the PA the older ones'. Taking the newest off-grid requests
    /// instead, so that the PA kept the grid, had the helper compute them before the PA's grid
    /// records for the same spots reached it (a helper syncs every --sync records): at 5
    /// processes (Cornell box 128x128) a helper made 118 records for 1,318 requests beside the
    /// PA's.
    pub fn take_newest(&mut self, count: usize) -> Vec<AmbientRequest> {
        let mut taken = Vec::with_capacity(count.min(self.len()));
        while taken.len() < count {
            let newest = self
                .groups
                .iter_mut()
                .filter(|g| !g.is_empty())
                .max_by_key(|g| g.back().map(|(at, _)| *at));
            let Some(group) = newest else { break };
            taken.extend(group.pop_back().map(|(_, r)| r));
        }
        taken.reverse();
        taken
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parallel::protocol::tests::sample_request as request;

    fn pixels(q: &mut RequestQueue) -> Vec<u32> {
        std::iter::from_fn(|| q.pop()).map(|r| r.pixel).collect()
    }

    #[test]
    fn grid_pixels_come_first_each_group_in_arrival_order() {
        // A 6-pixel-wide image, stride 3: the grid pixels are (1,1), (4,1), (1,4), (4,4).
        let mut q = RequestQueue::new(6, 3);
        q.extend([0, 7, 3, 10, 6, 8].map(request));
        assert_eq!(q.len(), 6);
        assert_eq!(pixels(&mut q), vec![7, 10, 0, 3, 6, 8]);
        assert!(q.is_empty());
    }

    #[test]
    fn the_coarse_grid_comes_before_the_grid() {
        // A 12-pixel-wide image, stride 2: grid pixels have odd x and y, the coarse grid (every
        // 6 pixels) x and y of 3 or 9.
        let mut q = RequestQueue::new(12, 2);
        let (rest, grid, coarse) = (0, 12 + 1, 3 * 12 + 3);
        q.extend([rest, grid, coarse, 12 * 9 + 9].map(request));
        assert_eq!(pixels(&mut q), vec![coarse, 12 * 9 + 9, grid, rest]);
    }

    #[test]
    fn stride_one_or_zero_keeps_arrival_order() {
        for stride in [0, 1] {
            let mut q = RequestQueue::new(6, stride);
            q.extend([5, 7, 0, 10].map(request));
            assert_eq!(pixels(&mut q), vec![5, 7, 0, 10]);
        }
    }

    #[test]
    fn helpers_get_the_newest_requests_grid_or_not_in_arrival_order() {
        // A 6-pixel-wide image, stride 3: pixels 7 and 10 are on the grid.
        let mut q = RequestQueue::new(6, 3);
        q.extend([7, 0, 10, 3, 6].map(request));
        let taken: Vec<u32> = q.take_newest(2).iter().map(|r| r.pixel).collect();
        assert_eq!(taken, vec![3, 6]);
        // The next newest include a grid request, kept in arrival order.
        let taken: Vec<u32> = q.take_newest(2).iter().map(|r| r.pixel).collect();
        assert_eq!(taken, vec![0, 10]);
        assert_eq!(pixels(&mut q), vec![7]);
        assert!(q.take_newest(5).is_empty());
        // Arrivals after a share keep counting from where they were.
        q.extend([1, 7].map(request));
        assert_eq!(q.take_newest(1).iter().map(|r| r.pixel).collect::<Vec<_>>(), vec![7]);
        assert_eq!(pixels(&mut q), vec![1]);
    }
}
