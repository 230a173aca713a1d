//! Measures the irradiance cache's spatial index (a multi-level hash grid, src/irradiance/index.rs)
//! against a loose octree, the structure Ward's cache classically uses, on the same records and
//! queries: build time, time per lookup and how many candidates each hands out per record that
//! really covers the point. A measurement, not a test:
//!
//!     cargo run --release --example index_vs_octree
//!
//! Records lie on the six faces of a room (a cache's records lie on surfaces), with reaches
//! spread log-uniformly over a factor of 32 (the range -ar and the gradient clamp allow);
//! queries are random points on the same faces. The octree is written here for the comparison
//! only: each record goes to the deepest node whose cell is at least twice its reach (a loose
//! octree, cells grown by half their size on each side), and a lookup descends every child
//! whose grown cell holds the point. Times are this thread's CPU time.

use glam::Vec3;
use icrender::irradiance::index::RecordIndex;
use icrender::irradiance::record::{HORIZON_SECTORS, Record};
use icrender::sampling::Rng;
// CPU time of this thread, so that other work on the machine does not count.
use cpu_time::ThreadTime as Instant;

fn record(position: Vec3, normal: Vec3, reach: f32) -> Record {
    Record {
        position,
        normal,
        u_axis: normal.any_orthonormal_vector(),
        radii: [reach, reach],
        harmonic_distance: reach / 0.2,
        level: 0,
        weight: 1.0,
        value: Vec3::ONE,
        translation_gradient: Vec3::ZERO,
        rotation_gradient: Vec3::ZERO,
        horizon: [f32::INFINITY; HORIZON_SECTORS],
        headroom: reach / 0.2,
        curvature: 0.0,
    }
}

/// A point on one of the faces of the cube [-1, 1]^3, and the face's inward normal.
fn on_room(rng: &mut Rng) -> (Vec3, Vec3) {
    let face = (rng.next_f32() * 6.0) as usize % 6;
    let (a, b) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
    let axis = face / 2;
    let sign = if face.is_multiple_of(2) { -1.0 } else { 1.0 };
    let mut p = [a, b, a];
    p[axis] = sign;
    p[(axis + 1) % 3] = a;
    p[(axis + 2) % 3] = b;
    let mut n = [0.0; 3];
    n[axis] = -sign;
    (Vec3::from_array(p), Vec3::from_array(n))
}

struct Node {
    center: Vec3,
    half: f32,
    records: Vec<u32>,
    children: [Option<Box<Node>>; 8],
}

impl Node {
    fn new(center: Vec3, half: f32) -> Node {
        Node {
            center,
            half,
            records: Vec::new(),
            children: Default::default(),
        }
    }

    fn insert(&mut self, id: u32, p: Vec3, reach: f32, depth: u32) {
        let child_half = 0.5 * self.half;
        if child_half < reach || depth >= 24 {
            self.records.push(id);
            return;
        }
        let octant = (p.x >= self.center.x) as usize
            | ((p.y >= self.center.y) as usize) << 1
            | ((p.z >= self.center.z) as usize) << 2;
        let offset = Vec3::new(
            if octant & 1 != 0 { child_half } else { -child_half },
            if octant & 2 != 0 { child_half } else { -child_half },
            if octant & 4 != 0 { child_half } else { -child_half },
        );
        let child = self.children[octant].get_or_insert_with(|| Box::new(Node::new(self.center + offset, child_half)));
        child.insert(id, p, reach, depth + 1);
    }

    fn near(&self, p: Vec3, visit: &mut impl FnMut(u32)) {
        self.records.iter().for_each(|&id| visit(id));
        for child in self.children.iter().flatten() {
            // A record in the child lies in its cell and reaches at most its half size.
            if ((p - child.center).abs() - Vec3::splat(2.0 * child.half)).max_element() <= 0.0 {
                child.near(p, visit);
            }
        }
    }
}

fn main() {
    let smallest = 0.0006f32;
    println!(
        "{:>9} {:>8} {:>12} {:>12} {:>14} {:>14} {:>11} {:>11}",
        "records", "covering", "grid build", "octree build", "grid lookup", "octree lookup", "grid cand.", "oct. cand."
    );
    for count in [10_000usize, 100_000, 1_000_000] {
        // Reaches shrink with the count so that about the same number cover a point.
        let scale = (1_000_000.0 / count as f32).sqrt();
        let mut rng = Rng::new(7, count as u64);
        let records: Vec<Record> = (0..count)
            .map(|_| {
                let (p, n) = on_room(&mut rng);
                let reach = smallest * scale * 32f32.powf(rng.next_f32());
                record(p, n, reach)
            })
            .collect();
        let queries: Vec<Vec3> = (0..100_000).map(|_| on_room(&mut rng).0).collect();

        let start = Instant::now();
        let grid = RecordIndex::new(smallest * scale);
        for r in &records {
            grid.insert(r.clone());
        }
        let grid_build = start.elapsed().as_secs_f64();

        let start = Instant::now();
        let mut octree = Node::new(Vec3::ZERO, 1.01);
        for (id, r) in records.iter().enumerate() {
            octree.insert(id as u32, r.position, r.reach(), 0);
        }
        let octree_build = start.elapsed().as_secs_f64();

        let (mut grid_candidates, mut covering) = (0usize, 0usize);
        let start = Instant::now();
        for &p in &queries {
            grid.for_each_near(p, |r| {
                grid_candidates += 1;
                covering += ((r.position - p).length() <= r.reach()) as usize;
            });
        }
        let grid_lookup = start.elapsed().as_secs_f64() / queries.len() as f64;

        let (mut octree_candidates, mut octree_covering) = (0usize, 0usize);
        let start = Instant::now();
        for &p in &queries {
            octree.near(p, &mut |id| {
                let r = &records[id as usize];
                octree_candidates += 1;
                octree_covering += ((r.position - p).length() <= r.reach()) as usize;
            });
        }
        let octree_lookup = start.elapsed().as_secs_f64() / queries.len() as f64;
        assert_eq!(covering, octree_covering, "both must find every covering record");

        let per = |n: usize| n as f64 / covering.max(1) as f64;
        println!(
            "{:>9} {:>8.1} {:>10.3} s {:>10.3} s {:>11.0} ns {:>11.0} ns {:>10.1}x {:>10.1}x",
            count,
            covering as f64 / queries.len() as f64,
            grid_build,
            octree_build,
            grid_lookup * 1e9,
            octree_lookup * 1e9,
            per(grid_candidates),
            per(octree_candidates)
        );
    }
    println!("(candidates: records handed out per record that covers the point)");
}
