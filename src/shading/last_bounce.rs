//! The samples of the last bounce's grid (`irradiance::last_bounce`): from the first diffuse
//! surface seen through a pixel, cosine-weighted bounces down to the level whose indirect
//! light is the last bounce (-ab minus one), and there all the light the surface receives:
//! its direct light by one shadow ray and its indirect light as a path would sample it. These
//! are the surfaces a record's hemisphere rays meet, in proportion to how often they meet them
//! (seen from the surfaces the image shows).

use super::direct::{LightStrata, direct_light};
use super::{Integrator, PathState, Work};
use crate::irradiance::last_bounce::{GridSample, Reads, Received};
use crate::sampling::{Rng, cosine_hemisphere};
use crate::scene::material::SurfacePoint;
use crate::scene::view::Camera;
use crate::sys::embree::Coherence;
use crate::tracer::SurfaceHit;
use glam::Vec3;

/// Samples of the last bounce's light taken at each site. Measured on the conference room
/// (-ab 2, 320x240): see `irradiance::last_bounce`.
pub const SAMPLES_PER_SITE: u32 = 2;

/// Draws of direct light taken at each site where the grid holds direct light alone (-ab 1),
/// kept as one sample, their mean: each draw is one light pick and shadow ray, no path, so a
/// site's point takes more of them than the samples of -ab 2. Measured (8 Dec, one sample a draw,
/// -ab 1 against brute force, 10 seeds, the grid reading own cells): conference room 168x128
/// indirect bias +0.51 % (sd 0.58) with 2, +0.26 % (sd 0.40) with 4, +0.16 % (sd 0.48) with 8,
/// no grid +0.34 % (sd 0.66), relMSE 2.33-2.36e-3 in all four; 512x384 renders 4.57 s with 4
/// against 4.81 s with 8.
pub const DIRECT_DRAWS_PER_SITE: u32 = 4;

/// -ad from which every pixel starts two sites instead of one (`sites_per_pixel`).
const TWO_SITES_FROM_DIVISIONS: u32 = 256;

/// Sites started per pixel for records of `divisions` (-ad) hemisphere samples. A cell's mean
/// is read by every record's ray that meets the cell, so its noise is shared by all of them
/// where a record's own noise falls with its rays: at high -ad the grid's noise is what is
/// left. Measured (6 Dec, the peers bench's references, four seeds, CPU time; Sibenik nave and
/// aisle, conference room default and high corner) two sites a pixel against one: at
/// `-aa 0.15 -ad 256 --spp 16` 4x4 relMSE 0.96x, 0.81x, 0.92x, 0.92x for 0.99-1.04x the time,
/// at `-aa 0.1 -ad 512 --spp 16` 0.89x, 0.85x, 0.90x, 0.93x for 0.99-1.02x (fewer hits miss a
/// cell with a mean and trace their path); four sites lowered the error a little more at 256
/// and 512 but for 1.03-1.13x the time. Below: at -ad 128 (two seeds) 0.90x and 0.87x for
/// 1.07x and 1.13x the time, at -ad 32 and 64 the aisle's error 1.2x for 1.08-1.2x the time
/// (probably: more finest cells reach `MIN_SAMPLES` and answer with a noisier mean than the
/// coarser cell did). Two sites of one sample each (as many samples as one site of two) gained
/// about a third as much: it is more samples, spread apart, that count. Those runs shared one
/// grid across seeds (it did not follow the seed then); again with each seed its own grid, at
/// `-aa 0.1 -ad 512 --spp 16`, four seeds: 0.80x (aisle), 0.92x (conference room), 0.89x
/// (nave) for 0.95-0.98x the time.
pub fn sites_per_pixel(divisions: u32) -> u32 {
    if divisions >= TWO_SITES_FROM_DIVISIONS { 2 } else { 1 }
}

/// The direct light is sampled as a white diffuse surface would reflect it (irradiance over pi,
/// as the indirect part): the hit that reads the mean applies its own albedo.
const WHITE: SurfacePoint = SurfacePoint {
    diffuse: Vec3::ONE,
    specular: Vec3::ZERO,
    alpha: 0.0,
    opacity: 1.0,
};

/// The random streams of the sites: apart from every stream a pixel's samples and the
/// prepass's records use (those are below 2^33).
const SITE_STREAM: u64 = 1 << 40;

impl Integrator<'_> {
    /// The level whose light the grid holds: the last diffuse bounce but one at -ab 2 and more
    /// (-ab 2: the hits of a record's hemisphere rays, their direct and indirect light); at
    /// -ab 1 the hits of a record's rays too, their direct light alone (their indirect light is
    /// -av). Without it each of those hits picks a light and traces its shadow ray: at -ab 1
    /// that made a record dearer than at -ab 2, and -ab 1 the dearer setting (8 Dec, 512x384,
    /// one process: conference room 5.79 s against 4.22 s at -ab 2, Sibenik 7.15 s against
    /// 5.37 s). None at -ab 0.
    pub fn last_bounce_level(&self) -> Option<u32> {
        let bounces = self.options.ambient_bounces;
        (bounces >= 1).then(|| (bounces - 1).max(1))
    }

    /// Whether the grid's level is past the last bounce (-ab 1): its cells hold direct light
    /// alone, a sample is one shadow ray, and a hit the grid does not answer costs no more than
    /// a shadow ray.
    fn grid_holds_direct_alone(&self) -> bool {
        self.last_bounce_level()
            .is_some_and(|level| level >= self.options.ambient_bounces)
    }

    /// Which of the grid's cells answer a lookup (`Reads`): only a point's own cell where the
    /// grid holds direct light alone, else coarser cells too.
    pub fn last_bounce_reads(&self) -> Reads {
        match self.grid_holds_direct_alone() {
            true => Reads::OwnCell {
                draws: DIRECT_DRAWS_PER_SITE,
            },
            false => Reads::CoarserToo,
        }
    }

    /// What the grid holds for the point at `hit` (of `surface`) on a path at `state`: the
    /// light it receives (irradiance over pi), direct and indirect, where the surface is diffuse,
    /// the point at the grid's level and its cell sampled enough. None elsewhere: the point is
    /// shaded as a path.
    pub fn last_bounce_received(&self, hit: &SurfaceHit, surface: &SurfacePoint, state: PathState) -> Option<Received> {
        if surface.diffuse.max_element() <= 0.0 || Some(state.level) != self.last_bounce_level() {
            return None;
        }
        let grid = self.cache?.last_bounce()?;
        grid.lookup(hit.position, hit.normal)
    }

    /// The grid's samples from the sites of pixel (x, y), appended to `out`, from the render's
    /// `seed`: renders of different seeds are independent in their grids too (with one grid for
    /// every seed, its noise was shared by all of them, and averaging seeds did not average it).
    pub fn last_bounce_samples(
        &self,
        camera: &Camera,
        (x, y): (u32, u32),
        seed: u64,
        out: &mut Vec<GridSample>,
        counts: &mut Work<'_>,
    ) {
        let Some(level) = self.last_bounce_level() else {
            return;
        };
        let pixel = y as u64 * camera.width as u64 + x as u64;
        let mut rng = Rng::new(seed, SITE_STREAM + pixel);
        for site in 0..sites_per_pixel(self.options.ambient_divisions) {
            let (origin, dir) = camera.ray(x as f32 + rng.next_f32(), y as f32 + rng.next_f32());
            // The site's own rays count as the render's: a camera ray, then a path's segments.
            counts.primary += 1;
            let Some((mut hit, mut surface)) = self.first_surface(origin, dir, Coherence::Incoherent, 0.0, counts)
            else {
                continue;
            };
            let mut reached = true;
            for _ in 0..level {
                let wi = cosine_hemisphere(hit.normal, rng.next_f32(), rng.next_f32());
                if surface.diffuse.max_element() <= 0.0 || wi.dot(hit.facing_normal) <= 0.0 {
                    reached = false;
                    break;
                }
                let from = self.tracer.spawn_point(&hit, wi);
                counts.ambient += 1;
                match self.first_surface(from, wi, Coherence::Incoherent, 0.0, counts) {
                    Some(next) => (hit, surface) = next,
                    None => {
                        reached = false;
                        break;
                    }
                }
            }
            if !reached || surface.diffuse.max_element() <= 0.0 {
                continue;
            }
            // The site's samples from last frame, where its path ends where it did and the
            // moves did not reach (frames of a scene whose meshes move, `grid_memory`).
            let memory = self.cache.and_then(|c| c.grid_memory());
            let key = (pixel, site);
            if let Some((samples, rng_after)) = memory.and_then(|m| m.recall(key, hit.position, hit.normal)) {
                out.extend(samples);
                rng = rng_after;
                continue;
            }
            let first_sample = out.len();
            let state = PathState {
                level,
                specular_depth: 0,
                weight: 1.0,
                count_emission: false,
                first_emission_elsewhere: false,
                throughput: Vec3::ONE,
                albedo_chain: false,
                spread: 0.0,
            };
            if self.grid_holds_direct_alone() {
                // Direct light alone: the site's draws, averaged into one sample that stands for
                // all of them (`Reads::OwnCell`).
                let mut direct = Vec3::ZERO;
                for _ in 0..DIRECT_DRAWS_PER_SITE {
                    let strata = LightStrata::alone(1, &mut rng);
                    direct += direct_light(self, &hit, hit.normal, &WHITE, strata, &mut rng, counts).total();
                }
                out.push(GridSample {
                    position: hit.position,
                    normal: hit.normal,
                    received: Received {
                        direct: direct / DIRECT_DRAWS_PER_SITE as f32,
                        indirect: self.options.ambient_value,
                    },
                });
            } else {
                for _ in 0..SAMPLES_PER_SITE {
                    let indirect = self.brute_force_ambient(&hit, state, &mut rng, counts);
                    let strata = LightStrata::alone(1, &mut rng);
                    let direct = direct_light(self, &hit, hit.normal, &WHITE, strata, &mut rng, counts).total();
                    out.push(GridSample {
                        position: hit.position,
                        normal: hit.normal,
                        received: Received { direct, indirect },
                    });
                }
            }
            if let Some(memory) = memory {
                memory.keep(key, hit.position, hit.normal, &out[first_sample..], &rng);
            }
        }
    }
}
