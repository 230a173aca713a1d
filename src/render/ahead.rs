//! Pixels traced ahead of the record set: the component split as a pipeline (paper, section
//! 5). Only indirect diffuse light needs the irradiance cache; emission, direct and specular
//! light do not. While the prepass is still building the record set, a rank with nothing else
//! to do (waiting at a round's barrier for the other ranks) traces the eye paths of tiles it
//! will render: their light but the indirect diffuse, and where that is asked for
//! (`shading::deferred`). Once the set is complete the tile is finished from these traces
//! (`pixel::render_tile_from`), bit for bit the tile shaded in one go.

use super::edges;
use super::pixel::{PixelTrace, RenderSettings, pixel_order, trace_pixel};
use crate::scene::view::Camera;
use crate::shading::{Integrator, RayCounts, Work};
use crate::tiles::Tile;

/// A tile's first pixels (in its pixel order), traced, and the rays that took.
#[derive(Debug, Default)]
pub struct TileTrace {
    pixels: Vec<PixelTrace>,
    counts: RayCounts,
    /// Bytes the traces hold.
    bytes: usize,
}

impl TileTrace {
    /// The traces, in the tile's pixel order; the rays they took are added to `counts` (the
    /// rendering thread's, which finishes the tile).
    pub fn into_pixels(self, counts: &mut RayCounts) -> Vec<PixelTrace> {
        counts.add(&self.counts);
        self.pixels
    }

    pub fn len(&self) -> usize {
        self.pixels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.pixels.is_empty()
    }

    /// Bytes the traces hold.
    pub fn bytes(&self) -> usize {
        self.bytes
    }
}

/// Traces one tile's pixels a few at a time, in the order `render_tile` shades them.
pub struct TileTracer {
    order: Vec<(u32, u32)>,
    /// The pixels an edge crosses, by index in the tile (row-major); None: none take more.
    edges: Option<Vec<bool>>,
    trace: TileTrace,
    tile: Tile,
}

impl TileTracer {
    /// Starts on `tile`: finds its edge pixels from its own corner rays, as the final pass
    /// does without the prepass's map (`edges::edge_pixels`: the same rays, the same answer).
    pub fn new(integrator: &Integrator<'_>, camera: &Camera, settings: &RenderSettings, tile: Tile) -> Self {
        let mut counts = RayCounts::default();
        let edges = (settings.edge_samples > settings.spp.max(1))
            .then(|| edges::edge_pixels(integrator, camera, &tile, &mut Work::new(&mut counts)));
        TileTracer {
            order: pixel_order(&tile, 0),
            edges,
            trace: TileTrace {
                pixels: Vec::new(),
                counts,
                bytes: 0,
            },
            tile,
        }
    }

    /// Traces up to `pixels` more; answers whether the tile is traced whole.
    pub fn step(
        &mut self,
        integrator: &Integrator<'_>,
        camera: &Camera,
        settings: &RenderSettings,
        pixels: usize,
    ) -> bool {
        let width = (self.tile.x1 - self.tile.x0) as usize;
        for _ in 0..pixels {
            let Some(&(x, y)) = self.order.get(self.trace.pixels.len()) else {
                break;
            };
            let index = (y - self.tile.y0) as usize * width + (x - self.tile.x0) as usize;
            let counts = &mut self.trace.counts;
            let samples = match &self.edges {
                Some(edges) if edges[index] => {
                    counts.edge_pixels += 1;
                    settings.edge_samples
                }
                _ => settings.spp.max(1),
            };
            let trace = trace_pixel(integrator, camera, settings, (x, y), samples, true, counts);
            self.trace.bytes += trace.bytes();
            self.trace.pixels.push(trace);
        }
        self.done()
    }

    pub fn done(&self) -> bool {
        self.trace.pixels.len() == self.order.len()
    }

    /// Pixels traced so far.
    pub fn len(&self) -> usize {
        self.trace.pixels.len()
    }

    pub fn is_empty(&self) -> bool {
        self.trace.pixels.is_empty()
    }

    pub fn bytes(&self) -> usize {
        self.trace.bytes()
    }

    pub fn into_trace(self) -> TileTrace {
        self.trace
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Cli, Command};
    use crate::image::framebuffer::PixelValue;
    use crate::job::Job;
    use crate::render::pixel::{render_tile, render_tile_from};
    use clap::Parser;

    fn job() -> Job {
        let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/cornell.gltf");
        // Two bounces (the last bounce's grid), samples at edges and several a pixel (shared
        // lookups at the pixel's centre), and the mirror: indirect light seen through it goes
        // to the specular layer.
        let args = [
            "icrender",
            "render",
            scene,
            "-x",
            "48",
            "-y",
            "40",
            "-ad",
            "64",
            "-ab",
            "2",
            "--spp",
            "2",
            "--edge-samples",
            "5",
            "--threads",
            "1",
        ];
        let args = crate::cli::rewrite_radiance_options(args.into_iter().map(String::from));
        let Command::Render(args) = Cli::try_parse_from(args).expect("options").command else {
            panic!("not a render")
        };
        Job::prepare(&args, crate::memory::Role::Single).expect("the Cornell box loads")
    }

    /// Bits of every value of a tile, for an exact comparison (-0.0 apart from 0.0).
    fn bits(values: &[PixelValue]) -> Vec<String> {
        values.iter().map(|v| format!("{v:?}")).collect()
    }

    #[test]
    fn tiles_traced_before_the_record_set_exists_come_out_as_tiles_shaded_after_it() {
        let job = job();
        let cache = job.cache.as_ref().expect("a cache");
        let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, Some(cache));
        let (camera, settings) = (&job.camera, &job.settings);
        let tiles = crate::tiles::tiles(camera.width, camera.height, 16, 16);
        // Before the prepass (no record yet): one tile traced whole, one in part.
        assert!(cache.records().is_empty());
        let mut whole = TileTracer::new(&integrator, camera, settings, tiles[1]);
        while !whole.step(&integrator, camera, settings, 7) {}
        let mut part = TileTracer::new(&integrator, camera, settings, tiles[4]);
        part.step(&integrator, camera, settings, 100);
        assert!(!part.done() && part.len() == 100);
        assert!(cache.records().is_empty(), "tracing made records");
        let outcome = crate::prepass::run(&integrator, camera, settings, &|_, _| true);
        assert!(outcome.records > 20);
        let settings = RenderSettings {
            edge_map: outcome.edges.clone(),
            ..settings.clone()
        };
        let frozen = integrator.cache_frozen(true);
        let mut lookups = 0;
        for (tile, tracer) in [(tiles[1], whole), (tiles[4], part)] {
            let mut counts = RayCounts::default();
            let traced = render_tile_from(
                &frozen,
                camera,
                &settings,
                &tile,
                Some(tracer.into_trace()),
                &mut counts,
                |_| {},
            );
            let mut shaded_counts = RayCounts::default();
            let shaded = render_tile(&frozen, camera, &settings, &tile, &mut shaded_counts, |_| {});
            assert_eq!(bits(&traced), bits(&shaded), "tile {tile:?}");
            // The same rays and lookups, wherever they were traced, but for the corner rays
            // that found the traced tile's edges (the final pass has the prepass's map).
            let rays = |c: &RayCounts| (c.shadow, c.specular, c.ambient, c.continued);
            assert_eq!(rays(&counts), rays(&shaded_counts));
            assert!(counts.primary >= shaded_counts.primary);
            assert_eq!(
                (counts.lookups, counts.edge_pixels),
                (shaded_counts.lookups, shaded_counts.edge_pixels)
            );
            lookups += counts.lookups;
        }
        assert!(lookups > 0);
    }
}
