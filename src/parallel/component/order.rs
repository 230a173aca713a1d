//! The order in which a PA computes the requests queued on it: those whose pixel lies on a
//! coarse grid first, then the rest, each group oldest first.
//!
//! Why: in arrival order a PA meets a tile's requests in scanline order, so each new record is
//! made where the records before it run out and the next points extrapolate from one side, as a
//! serial render does without its overture (see `render_tile`). This does what the overture
//! does, over every tile in the queue: the records on an N-pixel grid first, then most other
//! requests interpolate between records on all sides (the paper credits such a reordering for
//! component mode's fewer cache misses than the serial run, section 6). But the queue is often
//! short (5 processes: empty at 55-93 % of a PA's syncs), and a PA can only reorder what has
//! arrived; so the PRs also render the grid's pixels first, and their requests arrive in order.

use crate::render::pixel::on_image_grid;
use crate::shading::request::AmbientRequest;
use std::collections::VecDeque;

pub struct RequestQueue {
    /// Requests at grid pixels, oldest first, each with its place in the order of arrival.
    grid: VecDeque<(u64, AmbientRequest)>,
    /// The others, oldest first, likewise.
    rest: VecDeque<(u64, AmbientRequest)>,
    /// Requests taken in so far: the next one's place in the order of arrival.
    arrived: u64,
    width: u32,
    /// The grid's spacing in pixels; 0 or 1: plain arrival order.
    stride: u32,
}

impl RequestQueue {
    pub fn new(width: u32, stride: u32) -> Self {
        RequestQueue {
            grid: VecDeque::new(),
            rest: VecDeque::new(),
            arrived: 0,
            width: width.max(1),
            stride,
        }
    }

    /// Whether the pixel is on the image's grid, whose pixels the PRs render first (the serial
    /// overture counts its blocks from each tile's corner instead; a PA's queue mixes tiles).
    fn on_grid(&self, pixel: u32) -> bool {
        on_image_grid(pixel % self.width, pixel / self.width, self.stride)
    }

    pub fn len(&self) -> usize {
        self.grid.len() + self.rest.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn extend(&mut self, requests: impl IntoIterator<Item = AmbientRequest>) {
        for request in requests {
            let entry = (self.arrived, request);
            self.arrived += 1;
            if self.on_grid(request.pixel) {
                self.grid.push_back(entry);
            } else {
                self.rest.push_back(entry);
            }
        }
    }

    /// The next request to compute: the oldest grid request, else the oldest other one.
    pub fn pop(&mut self) -> Option<AmbientRequest> {
        self.grid.pop_front().or_else(|| self.rest.pop_front()).map(|(_, r)| r)
    }

    /// Up to `count` requests for a helper: the newest to arrive, grid and off-grid alike, in
    /// the order they arrived. They come from the last tiles' requests, a stretch of the image
    /// the PA has not reached yet, so the helper makes that stretch's records (its grid's first,
    /// see `help`) and the PA the older ones'. Taking the newest off-grid requests instead, so
    /// that the PA kept the grid, had the helper compute them before the PA's grid records for
    /// the same spots reached it (a helper syncs every --sync records): at 5 processes (Cornell
    /// box 128x128) a helper made 118 records for 1,318 requests beside the PA's.
    pub fn take_newest(&mut self, count: usize) -> Vec<AmbientRequest> {
        let mut taken = Vec::with_capacity(count.min(self.len()));
        while taken.len() < count {
            let newer_grid = match (self.grid.back(), self.rest.back()) {
                (Some(g), Some(r)) => g.0 > r.0,
                (Some(_), None) => true,
                (None, Some(_)) => false,
                (None, None) => break,
            };
            let group = if newer_grid { &mut self.grid } else { &mut self.rest };
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
