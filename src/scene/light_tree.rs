//! A light tree: a binary hierarchy over emissive triangles that picks one for a shading point
//! in proportion to an estimate of what each part of the tree gives there (its power over its
//! squared distance). With hundreds of emitters spread over many rooms, picking by power alone
//! sends most shadow rays to lights behind walls; the tree sends them to the near ones, at a
//! cost of one importance test per level.
//!
//! Every emitter keeps a non-zero probability wherever it is (the estimate never says zero),
//! so the estimate stays unbiased: the pick's probability is the product of the choices made on
//! the way down, and the shading divides by exactly that.

use glam::Vec3;

#[derive(Clone, Debug)]
struct Node {
    centre: Vec3,
    /// Squared half-diagonal of the node's bounds: the distance estimate never goes below it,
    /// so a point inside or next to a large cluster does not see an infinite importance.
    radius2: f32,
    power: f64,
    /// Inner node: index of the second child (the first follows the node). Leaf: the triangle.
    second: u32,
    triangle: u32,
    leaf: bool,
}

#[derive(Clone, Debug, Default)]
pub struct LightTree {
    nodes: Vec<Node>,
}

/// What the tree is built from: each emitter's bounds and power.
#[derive(Clone, Copy, Debug)]
pub struct Item {
    pub lo: Vec3,
    pub hi: Vec3,
    pub power: f64,
}

impl LightTree {
    pub fn new(items: &[Item]) -> LightTree {
        let mut tree = LightTree { nodes: Vec::new() };
        if !items.is_empty() {
            let mut order: Vec<u32> = (0..items.len() as u32).collect();
            tree.build(items, &mut order);
        }
        tree
    }

    fn build(&mut self, items: &[Item], order: &mut [u32]) -> usize {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        let (mut clo, mut chi) = (lo, hi);
        let mut power = 0.0;
        for &i in order.iter() {
            let it = &items[i as usize];
            lo = lo.min(it.lo);
            hi = hi.max(it.hi);
            let c = 0.5 * (it.lo + it.hi);
            clo = clo.min(c);
            chi = chi.max(c);
            power += it.power;
        }
        let index = self.nodes.len();
        self.nodes.push(Node {
            centre: 0.5 * (lo + hi),
            radius2: (0.5 * (hi - lo)).length_squared(),
            power,
            second: 0,
            triangle: order[0],
            leaf: order.len() == 1,
        });
        if order.len() > 1 {
            // Split at the middle of the centroids' widest extent, which keeps separate
            // clusters (rooms) apart; at the median when that leaves one side empty.
            let extent = chi - clo;
            let axis = if extent.x >= extent.y && extent.x >= extent.z {
                0
            } else if extent.y >= extent.z {
                1
            } else {
                2
            };
            let key = |i: &u32| {
                let it = &items[*i as usize];
                (it.lo + it.hi)[axis] * 0.5
            };
            let middle = 0.5 * (clo[axis] + chi[axis]);
            let mut mid = partition(order, |i| key(i) < middle);
            if mid == 0 || mid == order.len() {
                mid = order.len() / 2;
                order.select_nth_unstable_by(mid, |a, b| key(a).total_cmp(&key(b)));
            }
            let (left, right) = order.split_at_mut(mid);
            self.build(items, left);
            let second = self.build(items, right);
            self.nodes[index].second = second as u32;
        }
        index
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// What a node is estimated to give at `point`: power over squared distance, the distance
    /// kept at least the node's half-diagonal.
    fn importance(&self, node: usize, point: Vec3) -> f64 {
        let n = &self.nodes[node];
        let d2 = (n.centre - point).length_squared().max(n.radius2) as f64;
        if d2 > 0.0 && d2.is_finite() {
            n.power / d2
        } else {
            n.power
        }
    }

    /// The probability of going to the first child of inner node `node` from `point`.
    fn first_child_probability(&self, node: usize, point: Vec3) -> f64 {
        let (left, right) = (node + 1, self.nodes[node].second as usize);
        let (wl, wr) = (self.importance(left, point), self.importance(right, point));
        let p = wl / (wl + wr);
        if p.is_finite() && p > 0.0 && p < 1.0 {
            return p;
        }
        // Degenerate estimates (zero or overflowing power): an even split, unless one side
        // truly has no power at all.
        let (pl, pr) = (self.nodes[left].power, self.nodes[right].power);
        if pl > 0.0 && pr <= 0.0 {
            1.0
        } else if pr > 0.0 && pl <= 0.0 {
            0.0
        } else {
            0.5
        }
    }

    /// Picks an emitter for `point` with the uniform `u` (reused down the tree, so stratified
    /// `u` stay stratified); returns its index and the probability of having picked it.
    pub fn pick(&self, point: Vec3, mut u: f64) -> Option<(usize, f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut node = 0usize;
        let mut probability = 1.0f64;
        while !self.nodes[node].leaf {
            let p_left = self.first_child_probability(node, point);
            if u < p_left {
                u /= p_left;
                probability *= p_left;
                node += 1;
            } else {
                u = (u - p_left) / (1.0 - p_left);
                probability *= 1.0 - p_left;
                node = self.nodes[node].second as usize;
            }
            u = u.clamp(0.0, 1.0 - f64::EPSILON);
        }
        (probability > 0.0).then_some((self.nodes[node].triangle as usize, probability))
    }

    /// The probability that `pick` at `point` returns emitter `target` (walks every path: for
    /// tests and checks, not for rendering).
    pub fn probability(&self, point: Vec3, target: usize) -> f64 {
        fn walk(tree: &LightTree, node: usize, point: Vec3, target: usize, p: f64) -> f64 {
            let n = &tree.nodes[node];
            if n.leaf {
                return if n.triangle as usize == target { p } else { 0.0 };
            }
            let p_left = tree.first_child_probability(node, point);
            walk(tree, node + 1, point, target, p * p_left)
                + walk(tree, n.second as usize, point, target, p * (1.0 - p_left))
        }
        if self.nodes.is_empty() {
            0.0
        } else {
            walk(self, 0, point, target, 1.0)
        }
    }
}

/// Moves the elements for which `first` holds to the front; returns how many there are.
fn partition(items: &mut [u32], first: impl Fn(&u32) -> bool) -> usize {
    let mut next = 0;
    for i in 0..items.len() {
        if first(&items[i]) {
            items.swap(i, next);
            next += 1;
        }
    }
    next
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(x: f32, power: f64) -> Item {
        Item {
            lo: Vec3::new(x, 0.0, 0.0),
            hi: Vec3::new(x + 0.1, 0.1, 0.0),
            power,
        }
    }

    #[test]
    fn probabilities_sum_to_one_and_match_the_picks() {
        let items: Vec<Item> = (0..37).map(|i| item(i as f32 * 0.7, 1.0 + (i % 5) as f64)).collect();
        let tree = LightTree::new(&items);
        let point = Vec3::new(3.0, 1.0, 0.5);
        let total: f64 = (0..items.len()).map(|i| tree.probability(point, i)).sum();
        assert!((total - 1.0).abs() < 1e-9, "total {total}");
        // Frequencies of picks over a fine stratified sweep of u match the probabilities.
        let n = 200_000;
        let mut counts = vec![0u32; items.len()];
        for k in 0..n {
            let (i, p) = tree.pick(point, (k as f64 + 0.5) / n as f64).unwrap();
            assert!((p - tree.probability(point, i)).abs() < 1e-9);
            counts[i] += 1;
        }
        for (i, &c) in counts.iter().enumerate() {
            let expected = tree.probability(point, i) * n as f64;
            assert!(
                (c as f64 - expected).abs() <= 2.0,
                "emitter {i}: {c} picks, expected {expected}"
            );
        }
    }

    #[test]
    fn near_lights_get_most_picks() {
        // Ten lights at the origin, a thousand of the same power a hundred units away.
        let mut items: Vec<Item> = (0..10).map(|i| item(i as f32 * 0.2, 1.0)).collect();
        items.extend((0..1000).map(|i| item(100.0 + i as f32 * 0.01, 1.0)));
        let tree = LightTree::new(&items);
        let near: f64 = (0..10).map(|i| tree.probability(Vec3::new(1.0, 1.0, 0.0), i)).sum();
        assert!(near > 0.9, "near lights get {near} of the picks (by power alone: 0.01)");
        assert!((0..items.len()).all(|i| tree.probability(Vec3::ZERO, i) > 0.0));
    }

    #[test]
    fn single_and_zero_power_emitters() {
        let tree = LightTree::new(&[item(0.0, 2.0)]);
        assert_eq!(tree.pick(Vec3::ONE, 0.7), Some((0, 1.0)));
        let tree = LightTree::new(&[item(0.0, 0.0), item(1.0, 3.0)]);
        assert_eq!(tree.pick(Vec3::ONE, 0.1).map(|p| p.0), Some(1));
        assert!(LightTree::new(&[]).pick(Vec3::ONE, 0.5).is_none());
    }
}
