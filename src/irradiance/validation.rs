//! Records checked against the records around them.
//!
//! A record's value is carried to the points around it by its gradients: a first-order
//! (tangent) extrapolation. Irradiance is mostly concave where it changes (a bright patch's
//! peak, the fall into a contact shadow), and a tangent lies above a concave function, so
//! the extrapolated light overshoots, most at the record's edge: the cached indirect light
//! read 1-2 % above brute force (Cornell box, corridor, conference room at -ab 1), and a
//! record's extrapolation at the positions of the records inside its reach read 3-12 % above
//! their values. The Hessian-derived radii allow for the second-order error in size but not
//! in sign.
//!
//! Other records inside a record's reach measure what the tangent misses, at no cost, and the
//! prepass uses them twice:
//! - **Shrinking** (after each round but the finest level's): a record whose extrapolation
//!   misses a neighbour's value by so much that, growing with the squared distance, the miss
//!   would pass `SHRINK_TOLERANCE` before its edge shrinks to where it reaches it; the gaps
//!   this opens are filled by the finer rounds that follow.
//! - **Curvature** (once the record set is complete): the overshoot measured at a record's
//!   neighbours, fitted by least squares as a multiple of `t2` (the squared distance in units
//!   of the radii), is subtracted from its extrapolation (`Record::curvature`).
//!
//! Both are functions of the record set alone, in a canonical order, so every process that
//! holds the same records makes the same changes.

use super::index::FrozenIndex;
use super::record::{Metric, Record, under_one_roof};
use crate::scene::light::luminance;

/// The largest miss of a record's extrapolation at its edge, relative to the larger of the
/// two values, that leaves it its size (from a neighbour's miss, growing with the squared
/// distance). Measured at -ab 1 over three seeds, with the fitted curvature (indirect relMSE
/// against brute force; records): Cornell box 9.6e-5 -> 6.8e-5 with 20 % more records,
/// corridor 9.4e-5 -> 6.6e-5 (+16 %), conference room 1.15e-2 -> 9.9e-3 (+23 %); 0.05
/// gained a little more for 50 % more records (measured with a shrink that started at the
/// neighbour, not at the edge).
pub const SHRINK_TOLERANCE: f32 = 0.1;
/// A record shrinks to no less than this share of its radii in one step.
const SMALLEST_SHRINK: f32 = 0.25;
/// The largest fitted overshoot at the edge, either sign: a few records' neighbours disagree
/// with them for other reasons than curvature (noise, a shadow's edge between them).
const MAX_CURVATURE: f32 = 0.3;

/// A record `a` and a neighbouring record `b` whose position lies in `a`'s reach, where `a`
/// may be used: `b`'s squared distance in `a`'s radii, `a`'s first-order extrapolation there
/// and `b`'s value (luminances).
struct Neighbour {
    t2: f32,
    predicted: f32,
    actual: f32,
    /// `b`'s share of the surface: the product of its radii.
    area: f32,
}

/// Calls `visit(i, neighbour)` for every pair of records of `frozen` (`i` indexes the record
/// whose reach holds the other) where `wanted(i, j)`, in `frozen`'s order.
fn for_each_pair(
    frozen: &FrozenIndex,
    metric: Metric,
    accuracy: f32,
    wanted: impl Fn(usize, usize) -> bool,
    mut visit: impl FnMut(usize, Neighbour),
) {
    for (j, b) in frozen.records().iter().enumerate() {
        frozen.for_each_near_indexed(b.position, |i, a| {
            if i != j
                && wanted(i, j)
                && let Some(n) = neighbour(a, b, metric, accuracy)
            {
                visit(i, n);
            }
        });
    }
}

/// `b` as `a`'s neighbour: where `b` lies in `a`'s reach, at its level, and `a` may be used.
fn neighbour(a: &Record, b: &Record, metric: Metric, accuracy: f32) -> Option<Neighbour> {
    if a.level != b.level {
        return None;
    }
    let (reach, distance_squared) = (a.reach(), (b.position - a.position).length_squared());
    if distance_squared > reach * reach
        || a.weight_at(b.position, b.normal, a.level, metric, accuracy).is_none()
        || under_one_roof(a.headroom, b.headroom, distance_squared.sqrt()) <= 0.0
    {
        return None;
    }
    Some(Neighbour {
        t2: a.t2(b.position),
        predicted: luminance(a.first_order(b.position, b.normal)),
        actual: luminance(b.value),
        area: b.radii[0] * b.radii[1],
    })
}

/// The factor a record's radii shrink by for its neighbour `n` (1: none). The miss grows with
/// the squared distance: where it would pass the tolerance before the record's edge, the
/// record shrinks to where it reaches it. The factor is 1 exactly where shrinking starts, so a
/// miss that rounding moves across the threshold moves the radius by a rounding too, not by a
/// step.
fn shrink_for(n: &Neighbour) -> f32 {
    let miss = (n.predicted - n.actual).abs() / n.predicted.max(n.actual).max(f32::MIN_POSITIVE);
    let factor = (n.t2 * SHRINK_TOLERANCE / miss.max(f32::MIN_POSITIVE)).sqrt();
    if factor < 1.0 { factor.max(SMALLEST_SHRINK) } else { 1.0 }
}

/// For each record of `frozen`, the factor its radii shrink by (1: none): only records where
/// `revisable` says so, checked against neighbours of which at least one is `fresh` (the others
/// were checked before).
pub fn shrink_factors(
    frozen: &FrozenIndex,
    metric: Metric,
    accuracy: f32,
    revisable: &[bool],
    fresh: &[bool],
) -> Vec<f32> {
    let mut factors = vec![1.0f32; frozen.len()];
    let mut shrink = |i: usize, n: Neighbour| factors[i] = factors[i].min(shrink_for(&n));
    // A fresh record is checked against every revisable record whose reach holds it; one that
    // is not (all the rounds' before) only against the fresh revisable records, which are
    // indexed apart (a round's few) and looked up alone. Each record's factor is the smallest
    // its pairs ask for, so the order they come in does not matter.
    let picked: Vec<usize> = (0..frozen.len()).filter(|&i| fresh[i] && revisable[i]).collect();
    let fresh_ones = frozen.subset(&picked);
    for (j, b) in frozen.records().iter().enumerate() {
        if fresh[j] {
            frozen.for_each_near_indexed(b.position, |i, a| {
                if i != j
                    && revisable[i]
                    && let Some(n) = neighbour(a, b, metric, accuracy)
                {
                    shrink(i, n);
                }
            });
        } else {
            fresh_ones.for_each_near_indexed(b.position, |k, a| {
                if let Some(n) = neighbour(a, b, metric, accuracy) {
                    shrink(picked[k], n);
                }
            });
        }
    }
    factors
}

/// For each record of `frozen`, its overshoot per unit `t2` fitted by weighted least squares
/// through the origin from its neighbours (0 with fewer than two).
pub fn fit_curvatures(frozen: &FrozenIndex, metric: Metric, accuracy: f32) -> Vec<f32> {
    let records = frozen.records();
    let mut sums = vec![(0.0f32, 0.0f32, 0u32); records.len()];
    for_each_pair(
        frozen,
        metric,
        accuracy,
        |_, _| true,
        |i, n| {
            let value = luminance(records[i].value).max(f32::MIN_POSITIVE);
            let overshoot = (n.predicted - n.actual) / value;
            let s = &mut sums[i];
            // Weighed as a lookup weighs the record there (the kernel `(1 - t2)^2`), so the
            // fit matters where the record is read most, and by the area the neighbour stands
            // for (its radii's product): records crowd where the light changes fast (a
            // contact, a corner), and counted alike those few places ruled the fit, which
            // then took off too much everywhere else. Read 1.3 times as wide (`--ic-blend`),
            // `bench/bias.py` (three seeds, the cached light's mean against brute force):
            // unweighed the Cornell box read -0.72 % (-0.22 % as placed), with the kernel
            // -0.65 %, with the kernel and the area -0.19 %; the corridor -0.23, -0.17 and
            // +0.05 %; the conference room -0.15, +0.01 and +0.08 %; every indirect relMSE the
            // lowest of the three with both. With every curvature 0 the tangent's overshoot
            // read +1.11 % on the Cornell box: the unweighed fit took 1.8 points off it.
            let w = (1.0 - n.t2).max(0.0).powi(2) * n.area;
            s.0 += w * n.t2 * overshoot;
            s.1 += w * n.t2 * n.t2;
            s.2 += 1;
        },
    );
    sums.into_iter()
        .map(|(xy, xx, n)| {
            if n >= 2 && xx > 0.0 {
                (xy / xx).clamp(-MAX_CURVATURE, MAX_CURVATURE)
            } else {
                0.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::index::RecordIndex;
    use crate::irradiance::record::Record;
    use crate::irradiance::record::tests::flat_record;
    use glam::Vec3;

    /// Records on the plane z = 0 at `xs` along x, of radius `radius`, each holding a light
    /// `light(x)` with its exact gradient `slope(x)`.
    fn records_of(xs: &[f32], radius: f32, light: impl Fn(f32) -> f32, slope: impl Fn(f32) -> f32) -> Vec<Record> {
        xs.iter()
            .map(|&x| {
                let mut r = flat_record(light(x), radius);
                r.position = Vec3::new(x, 0.0, 0.0);
                r.translation_gradient = Vec3::new(slope(x) / light(x), 0.0, 0.0);
                r
            })
            .collect()
    }

    fn frozen(records: &[Record]) -> FrozenIndex {
        let index = RecordIndex::new(0.01);
        records.iter().cloned().for_each(|r| index.insert(r));
        index.frozen()
    }

    /// E(x) = 1 - k x^2 (a concave peak): a record at 0 has no gradient, so at distance d its
    /// tangent overshoots by k d^2, which is k R^2 per unit t2; the fit finds exactly that.
    #[test]
    fn the_fitted_curvature_is_a_concave_peaks_overshoot() {
        let (k, radius) = (0.2f32, 1.0f32);
        let xs = [0.0, 0.85, -0.9, 2.5];
        let records = records_of(&xs, radius, |x| 1.0 - k * x * x, |x| -2.0 * k * x);
        let frozen = frozen(&records);
        let fitted = fit_curvatures(&frozen, Metric::Hessian, 0.2);
        let centre = frozen.records().iter().position(|r| r.position == Vec3::ZERO).unwrap();
        assert!(
            (fitted[centre] - k * radius * radius).abs() < 1e-4,
            "{}",
            fitted[centre]
        );
        // A record with one neighbour in reach or none is not fitted.
        let far = frozen.records().iter().position(|r| r.position.x == 2.5).unwrap();
        assert_eq!(fitted[far], 0.0);
    }

    /// The fit weighs a neighbour by the area it stands for: where records crowd (a contact,
    /// where the light changes fast), four small records at a spot count as the one large
    /// record they replace. Light that falls steeply past x = 0.6 and is flat before; the
    /// centre's curvature is the same whether the steep spot holds one record of radius 0.4
    /// or four of radius 0.2; counted alike, the four took it from 0.21 to the clamp, 0.3.
    #[test]
    fn crowded_neighbours_count_by_the_area_they_stand_for() {
        let light = |x: f32| if x > 0.6 { 1.0 - 2.0 * (x - 0.6) } else { 1.0 };
        let slope = |x: f32| if x > 0.6 { -2.0 } else { 0.0 };
        let fitted = |crowd: &[f32], radius: f32| {
            let mut records = records_of(&[0.0, -0.5, -0.7, 0.3], 1.0, light, slope);
            records[0].translation_gradient = Vec3::ZERO;
            for mut r in records_of(crowd, radius, light, slope) {
                r.radii = [radius, radius];
                records.push(r);
            }
            let frozen = frozen(&records);
            let centre = frozen.records().iter().position(|r| r.position == Vec3::ZERO).unwrap();
            fit_curvatures(&frozen, Metric::Hessian, 0.2)[centre]
        };
        let one = fitted(&[0.8], 0.4);
        let four = fitted(&[0.8, 0.8001, 0.8002, 0.8003], 0.2);
        assert!(one > 0.0, "the drop is an overshoot: {one}");
        assert!(
            (four - one).abs() <= 0.01 * one,
            "one record {one}, four of a quarter the area {four}"
        );
    }

    /// On a linear ramp the tangents are exact: nothing to fit, nothing to shrink.
    #[test]
    fn a_linear_ramp_needs_no_correction() {
        let xs = [0.0, 0.8, -0.85, 0.4, -0.3];
        let records = records_of(&xs, 1.0, |x| 1.0 + 0.3 * x, |_| 0.3);
        let frozen = frozen(&records);
        assert!(
            fit_curvatures(&frozen, Metric::Hessian, 0.2)
                .iter()
                .all(|c| c.abs() < 1e-5)
        );
        let all = vec![true; records.len()];
        assert!(
            shrink_factors(&frozen, Metric::Hessian, 0.2, &all, &all)
                .iter()
                .all(|&f| f == 1.0)
        );
    }

    /// The factors are those of every pair a search of all the records for neighbours finds
    /// (`for_each_pair`), though the records that are not fresh are only looked up among the
    /// fresh ones: bit for bit, on 2,000 records of varying light and size of which some are
    /// fresh, as after a prepass round.
    #[test]
    fn looking_only_among_fresh_records_misses_no_pair() {
        let mut rng = crate::sampling::Rng::new(3, 4);
        let records: Vec<Record> = (0..2000)
            .map(|_| {
                let (x, y) = (rng.next_f32() * 8.0, rng.next_f32() * 8.0);
                let light = 1.0 + (x * 1.3).sin() * (y * 0.7).cos() * 0.6;
                let mut r = flat_record(light, 0.15 + 0.3 * rng.next_f32());
                r.position = Vec3::new(x, y, 0.0);
                r.translation_gradient = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 0.0);
                r
            })
            .collect();
        let frozen = frozen(&records);
        let revisable: Vec<bool> = (0..records.len()).map(|i| i % 3 != 0).collect();
        for share in [2, 50] {
            let fresh: Vec<bool> = (0..records.len()).map(|i| i % share == 1).collect();
            let factors = shrink_factors(&frozen, Metric::Hessian, 0.2, &revisable, &fresh);
            let mut all = vec![1.0f32; records.len()];
            let wanted = |i: usize, j: usize| revisable[i] && (fresh[i] || fresh[j]);
            for_each_pair(&frozen, Metric::Hessian, 0.2, wanted, |i, n| {
                all[i] = all[i].min(shrink_for(&n))
            });
            assert!(
                all.iter().filter(|&&f| f < 1.0).count() > 20,
                "records shrink (1 in {share} fresh)"
            );
            let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&factors), bits(&all), "1 in {share} fresh");
        }
    }

    /// A record whose tangent misses its neighbour by 30 % shrinks so that the miss, growing
    /// with the squared distance, is the tolerance at its new edge; a record whose own
    /// extrapolation is right keeps its size.
    #[test]
    fn a_record_that_misses_its_neighbour_shrinks_to_where_it_holds() {
        let mut a = flat_record(1.0, 1.0);
        a.translation_gradient = Vec3::new(0.3 / 0.9, 0.0, 0.0);
        let mut b = flat_record(1.0, 0.5);
        b.position = Vec3::new(0.9, 0.0, 0.0);
        let frozen = frozen(&[a.clone(), b.clone()]);
        let at = |r: &Record| frozen.records().iter().position(|x| x == r).unwrap();
        let all = vec![true; 2];
        let factors = shrink_factors(&frozen, Metric::Hessian, 0.2, &all, &all);
        // a predicts 1.3 where b holds 1: a miss of 0.3 / 1.3.
        let miss = 0.3f32 / 1.3;
        let expected = 0.9 * (SHRINK_TOLERANCE / miss).sqrt();
        assert!(
            (factors[at(&a)] - expected).abs() < 1e-4,
            "{} vs {expected}",
            factors[at(&a)]
        );
        assert_eq!(factors[at(&b)], 1.0, "b's reach does not hold a");
        // Just past where shrinking starts (a miss whose growth reaches the tolerance just
        // inside the edge), the record shrinks by as little: no step at the threshold.
        let mut slight = a.clone();
        slight.translation_gradient = Vec3::new(0.09 / 0.9, 0.0, 0.0);
        let frozen = super::tests::frozen(&[slight.clone(), b.clone()]);
        let factors = shrink_factors(&frozen, Metric::Hessian, 0.2, &all, &all);
        let i = frozen.records().iter().position(|x| *x == slight).unwrap();
        let expected = (0.81 * SHRINK_TOLERANCE / (0.09f32 / 1.09)).sqrt();
        assert!(expected > 0.98 && expected < 1.0);
        assert!((factors[i] - expected).abs() < 1e-4, "{} vs {expected}", factors[i]);
        // Not revisable, or no fresh record in the pair: left alone.
        let none = vec![false; 2];
        assert!(
            shrink_factors(&frozen, Metric::Hessian, 0.2, &none, &all)
                .iter()
                .all(|&f| f == 1.0)
        );
        assert!(
            shrink_factors(&frozen, Metric::Hessian, 0.2, &all, &none)
                .iter()
                .all(|&f| f == 1.0)
        );
    }

    /// With the fitted curvature, records of a concave peak interpolate it closer than their
    /// tangents alone: the overshoot between them is gone.
    #[test]
    fn the_curvature_takes_the_overshoot_out_of_the_interpolation() {
        let k = 0.1f32;
        let xs: Vec<f32> = (-6..=6).map(|i| i as f32 * 0.5).collect();
        let light = |x: f32| 2.0 - k * x * x;
        let mut records = records_of(&xs, 1.0, light, |x| -2.0 * k * x);
        let fitted = {
            let frozen = frozen(&records);
            let c = fit_curvatures(&frozen, Metric::Hessian, 0.2);
            frozen
                .records()
                .iter()
                .zip(c)
                .map(|(r, c)| (r.identity(), c))
                .collect::<Vec<_>>()
        };
        let interpolate = |records: &[Record], x: f32| {
            let p = Vec3::new(x, 0.0, 0.0);
            let (mut sum, mut total) = (0.0f32, 0.0f32);
            for r in records {
                if let Some(w) = r.weight_at(p, Vec3::Z, 0, Metric::Hessian, 0.2) {
                    sum += r.extrapolate(p, Vec3::Z).x * w;
                    total += w;
                }
            }
            sum / total
        };
        let error = |records: &[Record]| {
            (0..100)
                .map(|i| -2.0 + i as f32 * 0.04)
                .map(|x| interpolate(records, x) - light(x))
                .sum::<f32>()
                / 100.0
        };
        let before = error(&records);
        for r in &mut records {
            r.curvature = fitted.iter().find(|(id, _)| *id == r.identity()).unwrap().1;
        }
        let after = error(&records);
        assert!(before > 0.005, "tangents overshoot a concave peak: mean error {before}");
        assert!(after.abs() < 0.2 * before, "mean error {before} -> {after}");
    }
}
