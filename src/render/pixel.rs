//! One pixel and one tile of the image: where a pixel's samples fall, the components they
//! gather, and a tile's pixels in order (with the overture's records first, if asked). What
//! every renderer shares, the one-process renderer, the prepass and the MPI workers alike.

use crate::image::components::Components;
use crate::image::data::{PixelData, PixelDataSum, SampleHit};
use crate::image::framebuffer::PixelValue;
use crate::render::edges;
use crate::render::noise::PixelNoise;
use crate::sampling::Rng;
use crate::scene::footprint::EmitterFootprint;
use crate::scene::view::Camera;
use crate::shading::deferred::DeferredIndirect;
use crate::shading::direct::ShadowRatio;
use crate::shading::{Integrator, RayCounts, SampleContext, SampleData, Work};
use crate::tiles::Tile;
use std::sync::Arc;
use std::time::Instant;

#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub spp: u32,
    pub seed: u64,
    pub tile_width: u32,
    pub tile_height: u32,
    pub threads: usize,
    /// Jitter even a single sample over the pixel (a reference's passes then integrate the
    /// pixel's area); otherwise one sample is the pixel's centre, as rpict -pj 0 takes it.
    pub jitter: bool,
    /// Camera rays read textures averaged over their share of the pixel (`Camera::sample_spread`),
    /// as mip-mapping does: at a few samples a pixel a textured surface is then the pixel's
    /// average of its texture, not one texel of it. Off for a reference, whose passes
    /// integrate the pixel's area by points.
    pub texture_footprint: bool,
    /// Extra primary rays per pixel that gather only the emission seen first, in the pixels
    /// where an emitter can be seen (`emission_footprint`): a light's edges are where a box
    /// filter's error is largest, and these rays cost no shading. Used when it exceeds `spp`.
    pub emission_samples: u32,
    pub emission_footprint: Option<Arc<EmitterFootprint>>,
    /// Samples in the pixels an edge crosses (`edges`), used when it exceeds `spp`.
    pub edge_samples: u32,
    /// Those pixels of `window`, row-major, as the prepass found them (`PrepassOutcome::edges`);
    /// None: each tile finds its own from the same corner rays.
    pub edge_map: Option<Arc<crate::image::pixel_map::PixelMap>>,
    /// Spacing in pixels of the overture's grid (see `Integrator::prepare_records`); 0: none.
    pub overture: u32,
    /// Place every cache record before shading (`prepass`); the pixels then only read the
    /// cache. False: records are made as pixels render (with the overture, if any).
    pub prepass: bool,
    /// Render only these pixels of the image (`--region`); None: every pixel. The camera,
    /// pixel indices and seeds stay those of the whole image.
    pub region: Option<crate::image::region::Region>,
}

impl RenderSettings {
    /// The pixels to render: the region, or the whole image.
    pub fn area(&self, camera: &Camera) -> crate::image::region::Region {
        self.region
            .unwrap_or_else(|| crate::image::region::Region::whole(camera.width, camera.height))
    }

    /// The area to render inside the full image: what a frame of this render holds.
    pub fn window(&self, camera: &Camera) -> crate::image::window::PixelWindow {
        crate::image::window::PixelWindow::new(self.area(camera), camera.width, camera.height)
    }
}

/// What one thread did.
#[derive(Clone, Debug, Default)]
pub struct ThreadStats {
    pub rays: RayCounts,
    /// Wall-clock time the thread existed, and the CPU time it used.
    pub busy_s: f64,
    pub cpu_s: f64,
    pub tiles: usize,
    /// What the render's error estimate is summed from, over this thread's tiles.
    pub error: super::error_estimate::ErrorTally,
}

impl ThreadStats {
    /// Adds another stretch of this thread's work (rays, counters, times and error tally; not
    /// its tiles).
    pub fn absorb(&mut self, other: &ThreadStats) {
        self.rays.add(&other.rays);
        self.busy_s += other.busy_s;
        self.cpu_s += other.cpu_s;
        self.error.merge(&other.error);
    }
}

/// Measures a thread's wall-clock and CPU time from now on.
pub struct ThreadClock {
    wall: Instant,
    cpu: cpu_time::ThreadTime,
}

impl ThreadClock {
    pub fn start() -> ThreadClock {
        ThreadClock {
            wall: Instant::now(),
            cpu: cpu_time::ThreadTime::now(),
        }
    }

    /// Stores the elapsed times into `stats`.
    pub fn stop(&self, stats: &mut ThreadStats) {
        stats.busy_s = self.wall.elapsed().as_secs_f64();
        stats.cpu_s = self.cpu.elapsed().as_secs_f64();
    }
}

/// The grid a pixel's `samples` are stratified over: `columns x rows == samples` exactly, as
/// close to square as `samples`' divisors allow. Every cell has the same area and gets one
/// sample, so the mean is an unbiased estimate of the pixel's area integral for any count (a
/// square grid with cells left empty, as 8 samples on 3 x 3 would leave, is not).
pub fn pixel_strata(samples: u32) -> (u32, u32) {
    let samples = samples.max(1);
    let mut rows = (samples as f64).sqrt() as u32;
    while rows > 1 && !samples.is_multiple_of(rows) {
        rows -= 1;
    }
    let rows = rows.max(1);
    (samples / rows, rows)
}

/// Where in the pixel (both in [0, 1)) sample `s` of `samples` falls: a jittered point in its
/// own cell of the strata grid, or the centre when one unjittered sample is asked for.
pub fn pixel_offset(s: u32, samples: u32, jitter: bool, rng: &mut Rng) -> (f32, f32) {
    if samples <= 1 && !jitter {
        return (0.5, 0.5);
    }
    let (columns, rows) = pixel_strata(samples);
    let (i, j) = (s % columns, (s / columns) % rows);
    (
        (i as f32 + rng.next_f32()) / columns as f32,
        (j as f32 + rng.next_f32()) / rows as f32,
    )
}

/// The footprint a camera ray of one of `samples` samples in its pixel reads textures over
/// (`RenderSettings::texture_footprint`; the prepass's sites take the same).
pub fn eye_spread(camera: &Camera, settings: &RenderSettings, dir: glam::Vec3, samples: u32) -> f32 {
    if settings.texture_footprint {
        camera.sample_spread(dir, samples)
    } else {
        0.0
    }
}

/// What a sample's camera ray hit, as the data layers take it (world-space point, view-axis
/// depth, Cryptomatte IDs).
fn sample_hit(integrator: &Integrator<'_>, camera: &Camera, data: &SampleData) -> Option<SampleHit> {
    let hit = data.first?;
    let scene = integrator.scene;
    Some(SampleHit {
        position: scene.to_world(hit.position).as_vec3(),
        depth: camera.view_depth(hit.position),
        normal: hit.normal,
        object: scene.names.object_id(hit.object),
        material: scene.names.material_id(hit.material),
    })
}

/// What a pixel's samples traced (`trace_pixel`): each sample's light but the indirect diffuse
/// light its eye path asks for where that is deferred (`shading::deferred`), and what the
/// pixel's data layers and noise take from its rays. `finish_pixel` makes the pixel of it.
#[derive(Clone, Debug)]
pub struct PixelTrace {
    pub(super) pixel: (u32, u32),
    samples: Vec<SampleTrace>,
    /// The direct light's ratio estimate's parts over all the pixel's camera-ray hits.
    shadow_ratio: ShadowRatio,
    /// The first-hit emission over the pixel's area by rays of its own (`emission_samples`).
    split_emission: Option<glam::Vec3>,
}

/// One sample of a `PixelTrace`.
#[derive(Clone, Debug)]
struct SampleTrace {
    components: Components,
    /// Its share of the pixel's shadow-ray pool, its exact direct light and its measured noise
    /// (`render::noise`).
    pooled: ShadowRatio,
    exact: glam::Vec3,
    sampled_noise: f32,
    albedo: glam::Vec3,
    hit: Option<SampleHit>,
    /// Where its eye path asks for indirect diffuse light, in the order it got there.
    deferred: Vec<DeferredIndirect>,
}

impl PixelTrace {
    /// Bytes it holds (for the bound on pixels traced ahead: `parallel::pipeline`).
    pub fn bytes(&self) -> usize {
        std::mem::size_of::<PixelTrace>()
            + (self.samples.iter())
                .map(|s| {
                    std::mem::size_of::<SampleTrace>() + s.deferred.len() * std::mem::size_of::<DeferredIndirect>()
                })
                .sum::<usize>()
    }
}

/// The pixel's sample context for sample 0 (the shadow rays' offsets from the pixel's own
/// stream, which no sample uses).
fn sample_context(camera: &Camera, settings: &RenderSettings, (x, y): (u32, u32), samples: u32) -> SampleContext {
    let pixel_index = y as u64 * camera.width as u64 + x as u64;
    let mut pixel_rng = Rng::for_sample(settings.seed, pixel_index, u32::MAX as u64 + 1);
    SampleContext {
        pixel: pixel_index as u32,
        index: 0,
        weight: 1.0 / samples as f32,
        pixel_samples: samples,
        light_offset: pixel_rng.next_u32(),
        light_cell_offset: pixel_rng.next_u32(),
        centre_ray: (samples > 1).then(|| camera.ray(x as f32 + 0.5, y as f32 + 0.5)),
        eye_spread: 0.0,
    }
}

/// The components of one pixel: the mean of its `samples`, each with its own primary ray, direct
/// light and cache lookup (a box filter over the pixel's area); and its data layers, from the
/// same samples' camera rays. Once a prepass has made the record set, in two steps (each
/// sample's indirect diffuse light looked up after its path is traced: `shading::deferred`),
/// as the pixels traced ahead of the set (`trace_pixel`) are; else in one.
pub fn render_pixel(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    pixel: (u32, u32),
    samples: u32,
    counts: &mut RayCounts,
) -> (Components, PixelData) {
    let deferring = integrator.frozen && integrator.cache.is_some() && integrator.defer.is_none();
    let trace = trace_pixel(integrator, camera, settings, pixel, samples, deferring, counts);
    finish_pixel(integrator, camera, settings, trace, counts)
}

/// Traces a pixel's samples: all their light, but with `deferring` the indirect diffuse light
/// their eye paths ask for is left for `finish_pixel` (which reads only the cache for it).
pub fn trace_pixel(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    (x, y): (u32, u32),
    samples: u32,
    deferring: bool,
    counts: &mut RayCounts,
) -> PixelTrace {
    let samples = samples.max(1);
    let pixel_index = y as u64 * camera.width as u64 + x as u64;
    // Only worth it when the extra rays outnumber the pixel samples, which see emission anyway.
    let split_emission = settings.emission_samples > samples
        && settings
            .emission_footprint
            .as_ref()
            .is_some_and(|footprint| footprint.covers(x, y));
    let mut work = Work::new(counts);
    work.sample = sample_context(camera, settings, (x, y), samples);
    let mut traced = Vec::with_capacity(samples as usize);
    for s in 0..samples {
        let mut rng = Rng::for_sample(settings.seed, pixel_index, s as u64);
        let (jx, jy) = pixel_offset(s, samples, settings.jitter, &mut rng);
        let (origin, dir) = camera.ray(x as f32 + jx, y as f32 + jy);
        work.sample.index = s;
        work.sample.eye_spread = eye_spread(camera, settings, dir, samples);
        work.data = SampleData::default();
        work.sample_exact_direct = glam::Vec3::ZERO;
        work.sample_sampled_noise = 0.0;
        work.deferred_indirect = deferring.then(Vec::new);
        // The sample's own share of the pixel's shadow-ray pool, for its noise.
        let pool = std::mem::take(&mut work.pixel_shadow_ratio);
        let components = if split_emission {
            integrator.primary_without_first_emission(origin, dir, &mut rng, &mut work)
        } else {
            integrator.primary(origin, dir, &mut rng, &mut work)
        };
        let pooled = std::mem::replace(&mut work.pixel_shadow_ratio, pool);
        work.pixel_shadow_ratio += pooled;
        traced.push(SampleTrace {
            components,
            pooled,
            exact: work.sample_exact_direct,
            sampled_noise: work.sample_sampled_noise,
            albedo: work.data.albedo,
            hit: sample_hit(integrator, camera, &work.data),
            deferred: work.deferred_indirect.take().unwrap_or_default(),
        });
    }
    let split_emission = split_emission.then(|| {
        // The first-hit emission over the pixel's area by its own stratified rays (own streams,
        // after the pixel samples'): the two parts are estimated apart and add up to the pixel.
        let extra = settings.emission_samples;
        let mut emission = glam::Vec3::ZERO;
        for s in 0..extra {
            let mut rng = Rng::for_sample(settings.seed, pixel_index, (samples + s) as u64);
            let (jx, jy) = pixel_offset(s, extra, true, &mut rng);
            let (origin, dir) = camera.ray(x as f32 + jx, y as f32 + jy);
            emission += integrator.first_emission(origin, dir, &mut work);
        }
        emission / extra as f32
    });
    PixelTrace {
        pixel: (x, y),
        samples: traced,
        shadow_ratio: work.pixel_shadow_ratio,
        split_emission,
    }
}

/// The pixel from its trace: each sample's deferred lookups read from the cache (complete by
/// now) and added to its light, then the samples' mean, noise and data layers.
pub fn finish_pixel(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    trace: PixelTrace,
    counts: &mut RayCounts,
) -> (Components, PixelData) {
    let samples = trace.samples.len().max(1) as u32;
    let mut work = Work::new(counts);
    work.sample = sample_context(camera, settings, trace.pixel, samples);
    let mut sum = Components::default();
    let mut data = PixelDataSum::new(samples);
    let mut noise = PixelNoise::default();
    for (s, sample) in (0..).zip(trace.samples) {
        let mut components = sample.components;
        if !sample.deferred.is_empty() {
            work.sample.index = s;
            integrator.add_deferred(settings.seed, s, &sample.deferred, &mut components, &mut work);
        }
        noise.add(&components, sample.pooled, sample.exact, sample.sampled_noise);
        sum += components;
        data.add(sample.albedo, sample.hit);
    }
    data.set_noise(noise.finish());
    let mut pixel = sum * (1.0 / samples as f32);
    // The direct light's ratio estimate with its share taken over all the pixel's rays.
    pixel.direct += trace.shadow_ratio.estimate() / samples as f32;
    if let Some(emission) = trace.split_emission {
        pixel.emission += emission;
    }
    (pixel, data.finish())
}

/// Whether a pixel is on the overture's grid in the image's own coordinates: the centre of its
/// stride x stride block of the image (the grid a component-mode PA computes first,
/// `parallel::component::order`).
pub fn on_image_grid(x: u32, y: u32, stride: u32) -> bool {
    stride > 1 && x % stride == stride / 2 && y % stride == stride / 2
}

/// The order in which a tile's pixels render: scanline order, or with `grid_stride` > 1 the
/// pixels on the image's grid of that spacing (`on_image_grid`) first, then the others, each
/// group in scanline order.
pub fn pixel_order(tile: &Tile, grid_stride: u32) -> Vec<(u32, u32)> {
    let pixels = (tile.y0..tile.y1).flat_map(|y| (tile.x0..tile.x1).map(move |x| (x, y)));
    let (mut first, rest): (Vec<_>, Vec<_>) = pixels.partition(|&(x, y)| on_image_grid(x, y, grid_stride));
    first.extend(rest);
    first
}

/// Renders a tile's pixels in scanline order, each with `--spp` samples, or `--edge-samples`
/// where an edge crosses it (`edges`: the prepass's map, else the tile's own corner rays first).
/// `after_pixel` runs after each pixel (the MPI modes share cache records there).
///
/// With the overture on, a rank with a cache of its own first makes the records at the tile's
/// grid pixels (`Integrator::prepare_records`). A rank that defers its misses (a component-mode
/// PR, whose misses become requests to a PA) has no records to make; it renders the pixels on
/// the image's grid first instead, then the others, so that its PA receives the grid's requests
/// first and computes them first even when its queue holds little else (the PA's own reordering
/// only reorders what has arrived: measured on the 128x128 Cornell box at 5 processes, 32x32
/// tiles, the PAs' queues were empty at 58-81 % of their syncs and the overture saved component
/// mode 3.5 % of its records against 9 % for broadcast and centralised).
pub fn render_tile(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    tile: &Tile,
    counts: &mut RayCounts,
    after_pixel: impl FnMut(&mut RayCounts),
) -> Vec<PixelValue> {
    render_tile_from(integrator, camera, settings, tile, None, counts, after_pixel)
}

/// As `render_tile`, for a tile whose first pixels (in its order) were traced ahead of the
/// record set (`ahead::TileTrace`): those are finished from their traces, the others shaded.
/// The tile comes out as `render_tile` would have made it, bit for bit.
pub fn render_tile_from(
    integrator: &Integrator<'_>,
    camera: &Camera,
    settings: &RenderSettings,
    tile: &Tile,
    traced: Option<super::ahead::TileTrace>,
    counts: &mut RayCounts,
    mut after_pixel: impl FnMut(&mut RayCounts),
) -> Vec<PixelValue> {
    let width = (tile.x1 - tile.x0) as usize;
    let mut values = vec![PixelValue::default(); width * (tile.y1 - tile.y0) as usize];
    let stride = settings.overture;
    let grid_first = stride > 1 && integrator.defer.is_some();
    if stride > 0 && !grid_first {
        for y in (tile.y0..tile.y1).skip((stride / 2) as usize).step_by(stride as usize) {
            for x in (tile.x0..tile.x1).skip((stride / 2) as usize).step_by(stride as usize) {
                let before = counts.records_level0;
                let pixel_index = y as u64 * camera.width as u64 + x as u64;
                // A stream of its own, after every stream the pixel's samples use.
                let mut rng = Rng::for_sample(settings.seed, pixel_index, u32::MAX as u64 + 2);
                let (origin, dir) = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
                let mut work = Work::new(counts);
                work.sample.pixel = pixel_index as u32;
                integrator.prepare_records(origin, dir, &mut rng, &mut work);
                let index = (y - tile.y0) as usize * width + (x - tile.x0) as usize;
                values[index].records += (counts.records_level0 - before) as f32;
            }
        }
    }
    let spp = settings.spp.max(1);
    let edges = (settings.edge_samples > spp).then(|| match &settings.edge_map {
        Some(map) => {
            let window = settings.window(camera);
            let pixels = (tile.y0..tile.y1).flat_map(|y| (tile.x0..tile.x1).map(move |x| (x, y)));
            pixels
                .map(|(x, y)| window.index(x, y).is_some_and(|i| map.get(i)))
                .collect()
        }
        None => edges::edge_pixels(integrator, camera, tile, &mut Work::new(counts)),
    });
    let mut traced = traced.map(|t| t.into_pixels(counts)).unwrap_or_default().into_iter();
    for (x, y) in pixel_order(tile, if grid_first { stride } else { 0 }) {
        let before = counts.records_level0;
        let index = (y - tile.y0) as usize * width + (x - tile.x0) as usize;
        let (components, data) = match traced.next() {
            Some(trace) => {
                debug_assert_eq!(trace.pixel, (x, y), "a tile's traces follow its pixel order");
                finish_pixel(integrator, camera, settings, trace, counts)
            }
            None => {
                let samples = match &edges {
                    Some(edges) if edges[index] => {
                        counts.edge_pixels += 1;
                        settings.edge_samples
                    }
                    _ => spp,
                };
                render_pixel(integrator, camera, settings, (x, y), samples, counts)
            }
        };
        let value = &mut values[index];
        value.components = components;
        value.data = data;
        value.records += (counts.records_level0 - before) as f32;
        after_pixel(counts);
    }
    values
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_order_puts_the_image_grid_first() {
        // Columns 2..7 and rows 1..4 of an image; stride 3: the grid is x, y = 1, 4, 7, ...
        let tile = Tile {
            x0: 2,
            y0: 1,
            x1: 7,
            y1: 4,
        };
        let scanline: Vec<(u32, u32)> = (1..4).flat_map(|y| (2..7).map(move |x| (x, y))).collect();
        assert_eq!(pixel_order(&tile, 0), scanline);
        assert_eq!(pixel_order(&tile, 1), scanline);
        let order = pixel_order(&tile, 3);
        assert_eq!(&order[..1], &[(4, 1)]);
        assert_eq!(order.len(), scanline.len());
        let rest: Vec<(u32, u32)> = scanline.into_iter().filter(|&p| p != (4, 1)).collect();
        assert_eq!(&order[1..], &rest[..]);
        // Every grid pixel before every other, in scanline order, over a larger tile.
        let tile = Tile {
            x0: 0,
            y0: 0,
            x1: 16,
            y1: 16,
        };
        let order = pixel_order(&tile, 3);
        let grid = order.iter().take_while(|&&(x, y)| on_image_grid(x, y, 3)).count();
        assert_eq!(grid, 25);
        assert!(order[grid..].iter().all(|&(x, y)| !on_image_grid(x, y, 3)));
        assert!(order[..grid].windows(2).all(|w| (w[0].1, w[0].0) < (w[1].1, w[1].0)));
    }

    #[test]
    fn strata_tile_the_pixel_for_any_count() {
        for samples in 1..=64u32 {
            let (columns, rows) = pixel_strata(samples);
            assert_eq!(columns * rows, samples);
            assert!(columns >= rows);
            // Every cell holds exactly one sample.
            let mut seen = vec![0u32; samples as usize];
            let mut rng = Rng::new(3, samples as u64);
            for s in 0..samples {
                let (x, y) = pixel_offset(s, samples, true, &mut rng);
                assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
                let (i, j) = ((x * columns as f32) as u32, (y * rows as f32) as u32);
                seen[(j * columns + i) as usize] += 1;
            }
            assert!(seen.iter().all(|&c| c == 1), "{samples} samples: {seen:?}");
        }
        assert_eq!(pixel_strata(8), (4, 2));
        assert_eq!(pixel_strata(16), (4, 4));
        assert_eq!(pixel_strata(7), (7, 1));
    }

    #[test]
    fn one_unjittered_sample_is_the_centre() {
        let mut rng = Rng::new(1, 1);
        assert_eq!(pixel_offset(0, 1, false, &mut rng), (0.5, 0.5));
        let (x, y) = pixel_offset(0, 1, true, &mut rng);
        assert!((x, y) != (0.5, 0.5) && (0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
    }

    #[test]
    fn jittered_samples_integrate_a_step_over_the_pixel() {
        // The fraction of a pixel left of x = 0.3, estimated with 8 stratified samples (4 x 2),
        // averaged over many pixels: the box filter's exact answer is 0.3.
        let (pixels, samples) = (20_000u64, 8u32);
        let mut total = 0.0f64;
        for p in 0..pixels {
            let mut rng = Rng::for_sample(5, p, 0);
            let covered = (0..samples)
                .filter(|&s| pixel_offset(s, samples, true, &mut rng).0 < 0.3)
                .count();
            total += covered as f64 / samples as f64;
        }
        let mean = total / pixels as f64;
        assert!((mean - 0.3).abs() < 2e-3, "mean coverage {mean}");
    }
}
