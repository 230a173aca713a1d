//! A record's hemisphere rays at the level whose hits read the last bounce's grid (-ab 2 and
//! up: the rays of every record the image's points make), traced as one batch.
//!
//! Such a hit costs little besides Embree's ray: the surface point made from the triangle
//! (`Tracer::surface_hit`) and one read of the grid (`LastBounceGrid::lookup`). Both are loads
//! that miss the caches, one after the other (the triangle's corner indices, then its corners;
//! the grid's slot), and a ray at a time pays them in turn between Embree's calls: on the
//! conference room at the ray-rate bench's settings (one thread) they were 5.4 % and 7.2 % of
//! the render. A batch asks for each load well before it is made, so the misses of many hits
//! are under way together:
//!   1. every ray's direction, then Embree's hit, and a prefetch of the triangle's indices;
//!   2. the surface points, each prefetching the corners of a triangle `AHEAD` hits on and the
//!      grid's slots for its own point;
//!   3. the grid's reads;
//!   4. the shading, as `trace` shades a surface it found (`Integrator::light_from`).
//!
//! Measured there (farm-bench, 7 pairs): the render 0.95x the time; surface points 5.4 -> 3.2 %
//! of it, grid reads 7.2 -> 3.1 %. The values are a ray-at-a-time record's, but the random
//! numbers are drawn in another order (every direction's first, then what shading draws: a
//! path where a grid cell was seldom sampled, glossy highlights, transparency), so images
//! differ from the unbatched order's by that noise; they still depend on nothing but the seed.
//! Without a grid (`--ic-deep paths`) nothing is batched: every hit traces a path, whose loads
//! are not the ones that dominate.
//!
//! Since then, between passes 1 and 2, the hits on plain diffuse surfaces the grid covers are
//! answered from the hit alone (`plain_reads`), and only the others go on to passes 2-4.

use super::{GridRead, Integrator, PathState, Work, footprint_width};
use crate::image::components::Components;
use crate::irradiance::hemisphere::{CellSample, Frame, cell_direction};
use crate::irradiance::last_bounce::Received;
use crate::sampling::Rng;
use crate::scene::material::SurfacePoint;
use crate::sys::embree::{self, Coherence};
use crate::tracer::SurfaceHit;
use glam::Vec3;

/// How many hits ahead the surface points' pass asks for a triangle's corners: enough for
/// the loads to arrive before they are read, few enough that they are still cached then.
const AHEAD: usize = 8;

/// One ray of the batch: where it starts, where it goes, and what Embree found.
struct BatchRay {
    origin: Vec3,
    direction: Vec3,
    /// False for a direction below the true surface (a bent shading normal): not traced,
    /// and nothing arrives from it.
    traced: bool,
    found: Option<embree::RayHit>,
    /// The light of a hit on a plain diffuse surface the grid answered for (`plain_reads`),
    /// summed (`Components::total`), and the distance to it; the hit (`found`) is then taken,
    /// so no later pass reads it.
    plain: Option<(Vec3, f32)>,
}

impl Integrator<'_> {
    /// The samples of `cells` (ring, sector) of the n x n hemisphere of the record at `hit`,
    /// in their order, as `compute_record`'s one-ray sample gives them; `next` is the state of
    /// the rays' paths, whose level reads the grid.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn grid_level_samples(
        &self,
        hit: &SurfaceHit,
        frame: Frame,
        n: usize,
        cells: &[(usize, usize)],
        next: PathState,
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec<CellSample> {
        let mut rays = self.trace_batch(hit, frame, n, cells, rng, counts);
        self.plain_reads(&mut rays, next);
        let surfaces = self.batch_surfaces(&rays, next, counts);
        let reads = self.batch_grid_reads(&surfaces, next);
        let floor = self.tracer.epsilon_at(hit.position);
        rays.iter()
            .zip(&surfaces)
            .zip(reads)
            .map(|((ray, surface), read)| {
                let (light, distance) = match (ray.plain, surface) {
                    (Some((light, distance)), _) => (light, distance.max(floor)),
                    (None, Some(found)) if ray.traced => {
                        let (hit, surface) = (&found.0, &found.1);
                        let grid = GridRead::Read(read);
                        let (c, distance) =
                            self.light_from(ray.origin, ray.direction, (hit, surface), next, grid, rng, counts);
                        (c.total(), distance.max(floor))
                    }
                    // Nothing found, or not traced: no light, from no distance.
                    _ => (Vec3::ZERO, f32::INFINITY),
                };
                CellSample {
                    radiance: light,
                    distance,
                    direction: ray.direction,
                }
            })
            .collect()
    }

    /// Pass 1: each cell's direction and Embree's hit along it.
    fn trace_batch(
        &self,
        hit: &SurfaceHit,
        frame: Frame,
        n: usize,
        cells: &[(usize, usize)],
        rng: &mut Rng,
        counts: &mut Work<'_>,
    ) -> Vec<BatchRay> {
        cells
            .iter()
            .map(|&cell| {
                let direction = cell_direction(frame, n, cell, (rng.next_f32(), rng.next_f32()));
                if direction.dot(hit.facing_normal) <= 0.0 {
                    return BatchRay {
                        origin: hit.position,
                        direction,
                        traced: false,
                        found: None,
                        plain: None,
                    };
                }
                counts.ambient += 1;
                let origin = self.tracer.spawn_point(hit, direction);
                let found = self.tracer.nearest_hit(origin, direction, Coherence::Incoherent);
                if let Some(found) = &found {
                    self.tracer.prefetch_triangle(self.scene, found);
                }
                BatchRay {
                    origin,
                    direction,
                    traced: true,
                    found,
                    plain: None,
                }
            })
            .collect()
    }

    /// Pass 1b: the hits on plain diffuse surfaces (`Material::is_plain_diffuse`: all they
    /// send back is their albedo times what they receive) that the grid covers, answered from
    /// Embree's hit and the few per-corner data they need (`Tracer::plain_hit`: the point
    /// along the ray, the shading normal; the texture coordinates where a texture reads them),
    /// without the corners' positions, the material's other parts or the path's further
    /// steps that the full point reads (passes 2-4). The light is what shading the full point
    /// gives (`light_from` at the grid's level: albedo times the grid's direct and indirect
    /// means, summed as `Components::total` sums them), for the point taken along the ray
    /// (a rounding apart) and Embree's distance, but for the texture: one texel of the
    /// footprint's level (`Texture::sample_cell`) where the full point blends four. A black
    /// surface sends back nothing, as shading it gives. A hit the grid does not cover goes on
    /// to the full point.
    ///
    /// Measured (6 Dec, `bench/ray_rate.py`'s render, one thread, alternating runs): Sibenik
    /// (textured) renders in 0.963x the time (4 pairs), the conference room (untextured)
    /// 0.960x (3 pairs). The images differ from the full point's by those roundings, whose
    /// effect is a change of noise: Sibenik's nave view at the peers bench's fastest setting,
    /// 4x4 relMSE over six seeds 1.194e-3 against 1.198e-3; the conference room's two views,
    /// errors within 0.3 % at every peers setting. The triangle's own normal for the shading one
    /// saved another 0.5 %; an albedo averaged over the triangle instead of the texture's
    /// footprint saved 6 % more but raised the aisle view's 4x4 error 33 %. The one texel (with
    /// the footprint's level found from the float's bits) took 0.968x the time (4 pairs) for
    /// errors within their noise (Sibenik, six seeds at the peers bench's fastest setting: nave
    /// relMSE 0.99x, 4x4 0.96x; aisle 0.97x and 0.95x).
    fn plain_reads(&self, rays: &mut [BatchRay], next: PathState) {
        // A record's rays do not count the emission they meet (direct lighting has it), which
        // is what lets a hit's light be its albedo times the grid's.
        debug_assert!(!next.count_emission);
        let Some(grid) = self.cache.and_then(|cache| cache.last_bounce()) else {
            return;
        };
        let scene = self.scene;
        // The albedo and the grid's place of each plain hit, the grid's slot asked for ahead.
        let plain: Vec<Option<(Vec3, Vec3, Vec3, f32)>> = rays
            .iter()
            .map(|ray| {
                let found = ray.found.as_ref()?;
                let hit = self.tracer.plain_hit(scene, found, ray.origin, ray.direction)?;
                let material = &scene.materials[hit.material as usize];
                if !material.is_plain_diffuse() {
                    return None;
                }
                // Texture coordinates only where a texture reads them (`plain_texcoords`).
                let texcoords = self.tracer.plain_texcoords(scene, found);
                let (uv, width) = texcoords.map_or((None, 0.0), |(uv, uv_per_length)| {
                    let cosine = ray.direction.dot(hit.facing_normal);
                    (
                        Some(uv),
                        footprint_width(next.spread, hit.distance, uv_per_length, cosine),
                    )
                });
                let albedo = material.cell_albedo(uv, width, &scene.textures);
                grid.prefetch(hit.position, hit.normal);
                Some((albedo, hit.position, hit.normal, hit.distance))
            })
            .collect();
        for (ray, plain) in rays.iter_mut().zip(plain) {
            let Some((albedo, position, normal, distance)) = plain else {
                continue;
            };
            let light = if albedo.max_element() <= 0.0 {
                Components::default()
            } else if let Some(received) = grid.lookup(position, normal) {
                Components {
                    direct: albedo * received.direct,
                    indirect: albedo * received.indirect,
                    ..Components::default()
                }
            } else {
                // A cell the grid does not cover: the full point, and its path.
                continue;
            };
            ray.found = None;
            ray.plain = Some((light.total(), distance));
        }
    }

    /// Pass 2: the surface each ray stops at (past fully transparent ones, as `first_surface`).
    fn batch_surfaces(
        &self,
        rays: &[BatchRay],
        next: PathState,
        counts: &mut Work<'_>,
    ) -> Vec<Option<(SurfaceHit, SurfacePoint)>> {
        let grid = self.cache.and_then(|cache| cache.last_bounce());
        let corners = |ray: &BatchRay| {
            if let Some(found) = &ray.found {
                self.tracer.prefetch_corners(self.scene, found);
            }
        };
        rays.iter().take(AHEAD).for_each(corners);
        rays.iter()
            .enumerate()
            .map(|(k, ray)| {
                if let Some(ahead) = rays.get(k + AHEAD) {
                    corners(ahead);
                }
                let hit = self.tracer.surface_hit(self.scene, ray.found.as_ref()?, ray.direction);
                if let Some(grid) = grid {
                    grid.prefetch(hit.position, hit.normal);
                }
                self.first_surface_from(hit, ray.direction, Coherence::Incoherent, next.spread, counts)
            })
            .collect()
    }

    /// Pass 3: the grid's cell for each diffuse surface, as shading would read it.
    fn batch_grid_reads(
        &self,
        surfaces: &[Option<(SurfaceHit, SurfacePoint)>],
        next: PathState,
    ) -> Vec<Option<Received>> {
        surfaces
            .iter()
            .map(|found| {
                let (hit, surface) = found.as_ref()?;
                self.last_bounce_received(hit, surface, next)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::last_bounce::{GridSample, LastBounceGrid};
    use crate::irradiance::record::Metric;
    use crate::irradiance::{CacheSettings, IrradianceCache};
    use crate::sampling::basis;
    use crate::scene::material::Material;
    use crate::scene::{Scene, WorldMesh};
    use crate::shading::{RayCounts, ShadingOptions};
    use crate::tracer::Tracer;

    /// The closed box [0, 1]^3, one mesh of two triangles per wall, white Lambertian walls
    /// (their hits draw no random numbers where the grid answers) of `opacity` (below 1 a
    /// ray also passes through, out of the box).
    fn closed_box(opacity: f32) -> Scene {
        let mut description = Material::gltf_default_description();
        description.base_color[3] = opacity;
        if opacity < 1.0 {
            description.alpha_mode = crate::sys::scene_io::AlphaMode::Blend;
        }
        let mut white = Material::from_gltf(&description, crate::scene::material::DEFAULT_SPECULAR_THRESHOLD);
        white.make_lambertian();
        let corner = |i: u32| [(i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2 & 1) as f32];
        let walls: [[u32; 4]; 6] = [
            [0, 1, 3, 2],
            [4, 6, 7, 5],
            [0, 4, 5, 1],
            [2, 3, 7, 6],
            [0, 2, 6, 4],
            [1, 5, 7, 3],
        ];
        let meshes = walls
            .iter()
            .map(|w| WorldMesh {
                positions: w.iter().map(|&i| corner(i)).collect(),
                normals: None,
                texcoords: None,
                indices: vec![[0, 1, 2], [0, 2, 3]],
                material: 0,
                object: 0,
            })
            .collect();
        Scene::of_parts(vec![white], meshes, Vec::new())
    }

    /// Off the eye path a partly transparent surface passes its ray on by Russian roulette
    /// (`Integrator::transmit`): each ray brings all the light behind or none, and their mean
    /// is what the eye path's ray brings every time, jT times that light. A black pane of
    /// opacity 0.7 in front of an emitter, a ray straight through both.
    #[test]
    fn the_roulette_at_a_partly_transparent_surface_keeps_the_mean() {
        let quad = |z: f32, material: u32| WorldMesh {
            positions: vec![[-1.0, -1.0, z], [1.0, -1.0, z], [1.0, 1.0, z], [-1.0, 1.0, z]],
            normals: None,
            texcoords: None,
            indices: vec![[0, 2, 1], [0, 3, 2]],
            material,
            object: material,
        };
        let mut pane = Material::gltf_default_description();
        pane.base_color = [0.0, 0.0, 0.0, 0.7];
        pane.alpha_mode = crate::sys::scene_io::AlphaMode::Blend;
        let mut lamp = Material::gltf_default_description();
        lamp.base_color = [0.0, 0.0, 0.0, 1.0];
        lamp.emissive = [2.0, 2.0, 2.0];
        let materials = [pane, lamp]
            .iter()
            .map(|d| {
                let mut m = Material::from_gltf(d, crate::scene::material::DEFAULT_SPECULAR_THRESHOLD);
                m.make_lambertian();
                m
            })
            .collect();
        let scene = Scene::of_parts(materials, vec![quad(1.0, 0), quad(2.0, 1)], Vec::new());
        let tracer = Tracer::new(&scene).unwrap();
        let options = ShadingOptions::default();
        let integrator = Integrator::new(&scene, &tracer, &options, None);
        let mut totals = RayCounts::default();
        let mut counts = Work::new(&mut totals);
        let ray = |level: u32, rng: &mut Rng, counts: &mut Work<'_>| {
            let state = PathState {
                level,
                count_emission: true,
                ..PathState::eye(false)
            };
            let (light, _) = integrator.trace(Vec3::ZERO, Vec3::Z, state, Coherence::Incoherent, rng, counts);
            light.total().x
        };
        let jt = 1.0 - 0.7;
        let eye = ray(0, &mut Rng::new(1, 1), &mut counts);
        assert!((eye - jt * 2.0).abs() < 1e-5, "the eye path's ray: {eye}");
        let mut rng = Rng::new(1, 2);
        let n = 20_000;
        let rays: Vec<f32> = (0..n).map(|_| ray(1, &mut rng, &mut counts)).collect();
        assert!(
            rays.iter().all(|&l| l == 0.0 || (l - 2.0).abs() < 1e-5),
            "all the light or none"
        );
        let mean = rays.iter().sum::<f32>() / n as f32;
        // Three standard deviations of the mean of n such rays: 2 sqrt(jt (1 - jt) / n).
        let tolerance = 3.0 * 2.0 * (jt * (1.0 - jt) / n as f32).sqrt();
        assert!(
            (mean - eye).abs() < tolerance,
            "mean {mean} against {eye} (tolerance {tolerance})"
        );
        // Most rays stop at the pane: the roulette's point.
        assert!(
            counts.specular < n as u64 / 2,
            "{} of {n} rays went on",
            counts.specular
        );
    }

    /// A grid over every wall of the box, each cell sampled enough, its light varying with
    /// the position (so that reading another cell than the hit's would show).
    fn grid_over_the_walls(cell: f32) -> LastBounceGrid {
        let steps = (1.0 / cell * 4.0) as u32;
        let mut samples = Vec::new();
        for axis in 0..3 {
            for side in [0.0f32, 1.0] {
                let mut normal = Vec3::ZERO;
                normal[axis] = if side == 0.0 { 1.0 } else { -1.0 };
                for a in 0..steps {
                    for b in 0..steps {
                        let (u, v) = ((a as f32 + 0.5) / steps as f32, (b as f32 + 0.5) / steps as f32);
                        let mut p = Vec3::splat(0.0);
                        p[axis] = side;
                        p[(axis + 1) % 3] = u;
                        p[(axis + 2) % 3] = v;
                        for _ in 0..crate::irradiance::last_bounce::MIN_SAMPLES {
                            samples.push(GridSample {
                                position: p,
                                normal,
                                received: Received {
                                    direct: Vec3::new(u, v, 0.5),
                                    indirect: Vec3::splat(0.1 + u * v),
                                },
                            });
                        }
                    }
                }
            }
        }
        LastBounceGrid::from_samples(cell, samples, crate::irradiance::last_bounce::Reads::CoarserToo)
    }

    #[test]
    fn a_batch_gives_each_cell_what_its_ray_traced_alone_gives() {
        // Opaque walls: the grid's read is all of a hit's light; partly transparent ones: the
        // ray also passes through, out of the box.
        for opacity in [1.0, 0.9] {
            batch_against_rays_alone(closed_box(opacity));
        }
    }

    /// The hits on the opaque walls, plain Lambertian, are answered from the hit alone, with
    /// the light the full point's shading gives; the partly transparent walls' go on to it.
    #[test]
    fn hits_on_plain_walls_the_grid_covers_are_answered_from_the_hit_alone() {
        for (opacity, plain) in [(1.0, true), (0.9, false)] {
            with_a_floor_record(&closed_box(opacity), |integrator, _, hit, frame, next| {
                let n = 12;
                let mut totals = RayCounts::default();
                let mut counts = Work::new(&mut totals);
                let cells: Vec<_> = (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).collect();
                let mut rays = integrator.trace_batch(hit, frame, n, &cells, &mut Rng::new(7, 11), &mut counts);
                let found = rays.iter().filter(|r| r.found.is_some()).count();
                integrator.plain_reads(&mut rays, next);
                let answered = rays.iter().filter(|r| r.plain.is_some()).count();
                if plain {
                    assert_eq!(answered, n * n, "every ray meets a plain wall the grid covers");
                    assert!(rays.iter().all(|r| r.found.is_none()));
                } else {
                    assert_eq!((answered, found), (0, n * n));
                }
            });
        }
    }

    /// Hands `check` an integrator at -ab 2 over `scene` (the closed box) with the grid over
    /// its walls, a record's hit on the floor, off centre, its frame, and the state of its
    /// rays' paths for 12 x 12 cells.
    fn with_a_floor_record(scene: &Scene, check: impl FnOnce(&Integrator<'_>, &Tracer, &SurfaceHit, Frame, PathState)) {
        let tracer = Tracer::new(scene).unwrap();
        let options = ShadingOptions {
            ambient_bounces: 2,
            last_bounce_grid: true,
            ..ShadingOptions::default()
        };
        let cache = IrradianceCache::new(CacheSettings::new(0.1, 64, 0, 0, Metric::Hessian, 1.0));
        cache.set_last_bounce(grid_over_the_walls(1.0 / 16.0));
        let integrator = Integrator::new(scene, &tracer, &options, Some(&cache));
        let hit = tracer
            .intersect(scene, Vec3::new(0.3, 0.5, 0.6), Vec3::NEG_Y, Coherence::Incoherent)
            .unwrap();
        let (tangent, bitangent) = basis(hit.normal);
        let frame = Frame {
            normal: hit.normal,
            tangent,
            bitangent,
        };
        let next = PathState {
            level: 1,
            count_emission: false,
            spread: super::super::cell_spread(12),
            ..PathState::eye(false)
        };
        check(&integrator, &tracer, &hit, frame, next);
    }

    fn batch_against_rays_alone(scene: Scene) {
        with_a_floor_record(&scene, |integrator, tracer, hit, frame, next| {
            let n = 12;
            let mut totals = RayCounts::default();
            let mut counts = Work::new(&mut totals);
            assert_eq!(integrator.last_bounce_level(), Some(next.level));
            let cells: Vec<_> = (0..n).flat_map(|i| (0..n).map(move |j| (i, j))).collect();
            let mut batch_rng = Rng::new(7, 11);
            let batch = integrator.grid_level_samples(hit, frame, n, &cells, next, &mut batch_rng, &mut counts);
            // The batch draws every cell's direction first, then what each hit's shading draws
            // (the roulette at a partly transparent wall), cell by cell: so does the reference.
            let mut alone_rng = Rng::new(7, 11);
            let directions: Vec<Vec3> = cells
                .iter()
                .map(|&cell| cell_direction(frame, n, cell, (alone_rng.next_f32(), alone_rng.next_f32())))
                .collect();
            let floor = tracer.epsilon_at(hit.position);
            for ((&cell, got), &direction) in cells.iter().zip(&batch).zip(&directions) {
                let origin = tracer.spawn_point(hit, direction);
                let (light, distance) = integrator.trace(
                    origin,
                    direction,
                    next,
                    Coherence::Incoherent,
                    &mut alone_rng,
                    &mut counts,
                );
                assert_eq!(got.direction, direction);
                assert_eq!(got.radiance, light.total(), "cell {cell:?}");
                // A hit on a plain wall takes Embree's distance, the full point's distance from
                // the corners: a rounding apart.
                let expected = distance.max(floor);
                assert!(
                    (got.distance - expected).abs() <= 1e-6 * expected,
                    "cell {cell:?}: {} against {expected}",
                    got.distance
                );
                assert!(
                    got.radiance.min_element() > 0.0,
                    "every ray meets a wall the grid covers"
                );
            }
            // Both drew the same random numbers.
            assert_eq!(batch_rng.next_f32(), alone_rng.next_f32());
            // The batch counted its rays (the reference loop above counts none).
            assert_eq!(counts.ambient, (n * n) as u64);
        });
    }
}
