//! A light tree: a binary hierarchy over emissive triangles that picks one for a shading point
//! in proportion to an estimate of what each part of the tree gives there (its power over its
//! squared distance). With hundreds of emitters spread over many rooms, picking by power alone
//! sends most shadow rays to lights behind walls; the tree sends them to the near ones, at a
//! cost of one importance test per level.
//!
//! Parts of the tree that cannot light the point at all get no picks: a node whose bounds lie
//! wholly behind the shading point's tangent plane, and an emitter whose front the point is
//! behind (emitters shine from their front side only). Everything else keeps a non-zero
//! probability wherever it is (the estimate never says zero), so the estimate stays unbiased:
//! the pick's probability is the product of the choices made on the way down, and the shading
//! divides by exactly that. On the conference room at -ab 2 a third of the hemisphere rays end
//! on the ceiling, beside and behind its lamps, where every pick used to be a wasted ray.

use glam::Vec3;

#[derive(Clone, Debug)]
struct Node {
    centre: Vec3,
    /// Half the extent of the node's bounds along each axis.
    half: Vec3,
    /// Squared half-diagonal of the node's bounds: the distance estimate never goes below it,
    /// so a point inside or next to a large cluster does not see an infinite importance.
    radius2: f32,
    power: f64,
    /// Inner node: index of the second child (the first follows the node). Leaf: the triangle.
    second: u32,
    triangle: u32,
    /// Leaf: a point of the emitter and its front-facing normal (zero for inner nodes).
    anchor: Vec3,
    front: Vec3,
    leaf: bool,
}

#[derive(Clone, Debug, Default)]
pub struct LightTree {
    nodes: Vec<Node>,
}

/// What the tree is built from: each emitter's bounds, power, a point of it and the normal of
/// the side it shines from.
#[derive(Clone, Copy, Debug)]
pub struct Item {
    pub lo: Vec3,
    pub hi: Vec3,
    pub power: f64,
    pub anchor: Vec3,
    pub front: Vec3,
}

/// Where the pick stands at a shading point: its position and unit shading normal.
#[derive(Clone, Copy, Debug)]
pub struct Receiver {
    pub point: Vec3,
    pub normal: Vec3,
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
        let leaf = order.len() == 1;
        let first = &items[order[0] as usize];
        self.nodes.push(Node {
            centre: 0.5 * (lo + hi),
            half: 0.5 * (hi - lo),
            radius2: (0.5 * (hi - lo)).length_squared(),
            power,
            second: 0,
            triangle: order[0],
            anchor: if leaf { first.anchor } else { Vec3::ZERO },
            front: if leaf { first.front } else { Vec3::ZERO },
            leaf,
        });
        if !leaf {
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

    /// Whether nothing in `node` can light the receiver: its bounds lie wholly behind the
    /// receiver's tangent plane (no point of them makes a positive cosine there), or, for an
    /// emitter, the receiver is behind its front. Either way the node's light there is zero (up
    /// to the rounding of the points sampled on it: a cosine of 1e-7), so no pick goes to it.
    /// An inner node whose emitters all face away still gets picks, which then end in no emitter:
    /// the estimate loses no light by that, only the ray.
    fn dark_at(&self, node: usize, at: Receiver) -> bool {
        let n = &self.nodes[node];
        let nearest_front = (n.centre - at.point).dot(at.normal) + n.half.dot(at.normal.abs());
        nearest_front <= 0.0 || (n.leaf && (at.point - n.anchor).dot(n.front) <= 0.0)
    }

    /// What a node is estimated to give at the receiver, power over squared distance (the
    /// distance kept at least the node's half-diagonal), as the pair (power, squared distance)
    /// so that comparing two nodes takes one division, not three (`first_child_probability`:
    /// the divisions' latency was most of `pick`'s time, 18 % of an -ab 2 render's).
    fn importance(&self, node: usize, at: Receiver) -> (f64, f64) {
        let n = &self.nodes[node];
        let d2 = (n.centre - at.point).length_squared().max(n.radius2) as f64;
        (n.power, if d2 > 0.0 && d2.is_finite() { d2 } else { 1.0 })
    }

    /// The probability of going to the first child of inner node `node`; None where neither
    /// child can light the receiver. A child that is dark there or has no power gets nothing.
    fn first_child_probability(&self, node: usize, at: Receiver) -> Option<f64> {
        let (left, right) = (node + 1, self.nodes[node].second as usize);
        let lit = |child: usize| {
            (self.nodes[child].power > 0.0 && !self.dark_at(child, at)).then(|| self.importance(child, at))
        };
        match (lit(left), lit(right)) {
            (None, None) => None,
            (Some(_), None) => Some(1.0),
            (None, Some(_)) => Some(0.0),
            (Some((pl, dl)), Some((pr, dr))) => {
                // (pl / dl) / (pl / dl + pr / dr), multiplied through by dl dr.
                let (wl, wr) = (pl * dr, pr * dl);
                let p = wl / (wl + wr);
                // Estimates that overflow or vanish: an even split.
                Some(if p.is_finite() && p > 0.0 && p < 1.0 { p } else { 0.5 })
            }
        }
    }

    /// Picks an emitter for the receiver with the uniform `u` (stratified `u` stay stratified:
    /// each level splits the interval of `u` left to it in the ratio of the children's
    /// probabilities, the usual rescaling of `u` without its divisions); returns its index and
    /// the probability of having picked it. None where nothing can light the receiver.
    pub fn pick(&self, at: Receiver, u: f64) -> Option<(usize, f64)> {
        if self.nodes.is_empty() || self.dark_at(0, at) {
            return None;
        }
        let mut node = 0usize;
        let mut probability = 1.0f64;
        let (mut lo, mut width) = (0.0f64, 1.0f64);
        while !self.nodes[node].leaf {
            let p_left = self.first_child_probability(node, at)?;
            let split = lo + width * p_left;
            if u < split {
                width = split - lo;
                probability *= p_left;
                node += 1;
            } else {
                width = lo + width - split;
                lo = split;
                probability *= 1.0 - p_left;
                node = self.nodes[node].second as usize;
            }
        }
        // A dark or powerless leaf is only reached with probability zero (its parent gives it
        // none); the root, a leaf itself for one emitter, was tested above.
        (probability > 0.0).then_some((self.nodes[node].triangle as usize, probability))
    }

    /// The probability that `pick` at the receiver returns emitter `target` (walks every path:
    /// for tests and checks, not for rendering).
    pub fn probability(&self, at: Receiver, target: usize) -> f64 {
        fn walk(tree: &LightTree, node: usize, at: Receiver, target: usize, p: f64) -> f64 {
            let n = &tree.nodes[node];
            if n.leaf {
                return if n.triangle as usize == target { p } else { 0.0 };
            }
            let Some(p_left) = tree.first_child_probability(node, at) else {
                return 0.0;
            };
            walk(tree, node + 1, at, target, p * p_left) + walk(tree, n.second as usize, at, target, p * (1.0 - p_left))
        }
        if self.nodes.is_empty() || self.dark_at(0, at) {
            0.0
        } else {
            walk(self, 0, at, target, 1.0)
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

    /// A small emitter in the z = 0 plane shining up (+z).
    fn item(x: f32, power: f64) -> Item {
        Item {
            lo: Vec3::new(x, 0.0, 0.0),
            hi: Vec3::new(x + 0.1, 0.1, 0.0),
            power,
            anchor: Vec3::new(x, 0.0, 0.0),
            front: Vec3::Z,
        }
    }

    /// A receiver above the emitters' plane, facing down at them.
    fn above(x: f32, y: f32) -> Receiver {
        Receiver {
            point: Vec3::new(x, y, 0.5),
            normal: -Vec3::Z,
        }
    }

    #[test]
    fn probabilities_sum_to_one_and_match_the_picks() {
        let items: Vec<Item> = (0..37).map(|i| item(i as f32 * 0.7, 1.0 + (i % 5) as f64)).collect();
        let tree = LightTree::new(&items);
        let at = above(3.0, 1.0);
        let total: f64 = (0..items.len()).map(|i| tree.probability(at, i)).sum();
        assert!((total - 1.0).abs() < 1e-9, "total {total}");
        // Frequencies of picks over a fine stratified sweep of u match the probabilities.
        let n = 200_000;
        let mut counts = vec![0u32; items.len()];
        for k in 0..n {
            let (i, p) = tree.pick(at, (k as f64 + 0.5) / n as f64).unwrap();
            assert!((p - tree.probability(at, i)).abs() < 1e-9);
            counts[i] += 1;
        }
        for (i, &c) in counts.iter().enumerate() {
            let expected = tree.probability(at, i) * n as f64;
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
        let near: f64 = (0..10).map(|i| tree.probability(above(1.0, 1.0), i)).sum();
        assert!(near > 0.9, "near lights get {near} of the picks (by power alone: 0.01)");
        assert!((0..items.len()).all(|i| tree.probability(above(0.0, 0.0), i) > 0.0));
    }

    #[test]
    fn lights_behind_the_tangent_plane_or_facing_away_get_no_picks() {
        // Emitters along x from 0 to 9.8, shining up; the receiver stands at x = 5.
        let items: Vec<Item> = (0..50).map(|i| item(i as f32 * 0.2, 1.0)).collect();
        let tree = LightTree::new(&items);
        // A wall facing +x at x = 5: only the emitters reaching beyond it can light it.
        let wall = Receiver {
            point: Vec3::new(5.0, 0.05, 0.5),
            normal: Vec3::X,
        };
        let lit = |i: usize| items[i].hi.x > 5.0;
        for (i, it) in items.iter().enumerate() {
            let p = tree.probability(wall, i);
            assert_eq!(p > 0.0, lit(i), "emitter {i} at x {}: probability {p}", it.lo.x);
        }
        let total: f64 = (0..items.len()).map(|i| tree.probability(wall, i)).sum();
        assert!((total - 1.0).abs() < 1e-9, "the lit emitters share every pick: {total}");
        for k in 0..1000 {
            let (i, _) = tree.pick(wall, (k as f64 + 0.5) / 1000.0).unwrap();
            assert!(lit(i), "picked emitter {i}, which cannot light the wall");
        }
        // Below the emitters (behind their fronts), facing up at them: nothing can light it.
        let below = Receiver {
            point: Vec3::new(5.0, 0.05, -0.5),
            normal: Vec3::Z,
        };
        assert!(tree.pick(below, 0.3).is_none());
        assert!((0..items.len()).all(|i| tree.probability(below, i) == 0.0));
        // Above them but facing away (a ceiling lit from below would face down): nothing either.
        let facing_away = Receiver {
            point: Vec3::new(5.0, 0.05, 0.5),
            normal: Vec3::Z,
        };
        assert!(tree.pick(facing_away, 0.3).is_none());
        // In the emitters' own plane (a ceiling with lamps flush in it): nothing.
        let flush = Receiver {
            point: Vec3::new(20.0, 0.05, 0.0),
            normal: -Vec3::Z,
        };
        assert!(tree.pick(flush, 0.3).is_none());
    }

    #[test]
    fn single_and_zero_power_emitters() {
        let tree = LightTree::new(&[item(0.0, 2.0)]);
        assert_eq!(tree.pick(above(0.0, 0.0), 0.7), Some((0, 1.0)));
        let tree = LightTree::new(&[item(0.0, 0.0), item(1.0, 3.0)]);
        assert_eq!(tree.pick(above(0.0, 0.0), 0.1).map(|p| p.0), Some(1));
        assert!(LightTree::new(&[]).pick(above(0.0, 0.0), 0.5).is_none());
    }
}
