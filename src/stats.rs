//! Render statistics: timers and ray counters, per thread and total, written as JSON and into
//! the EXR header.

use crate::render::ThreadStats;
use serde::Serialize;

#[derive(Clone, Debug, Serialize)]
pub struct RayStats {
    pub primary: u64,
    pub shadow: u64,
    pub specular: u64,
    pub ambient: u64,
    pub total: u64,
}

#[derive(Clone, Debug, Serialize)]
pub struct ThreadReport {
    pub tiles: usize,
    pub busy_s: f64,
    pub rays: RayStats,
}

#[derive(Clone, Debug, Serialize)]
pub struct RenderStats {
    pub version: &'static str,
    pub scene: String,
    pub mode: &'static str,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub threads: usize,
    pub triangles: usize,
    pub dropped_triangles: usize,
    pub load_s: f64,
    pub build_s: f64,
    pub render_s: f64,
    pub wall_s: f64,
    pub rays: RayStats,
    pub mrays_per_s: f64,
    /// Contributions dropped for being NaN or infinite (should be 0).
    pub nonfinite_dropped: u64,
    pub layers: Vec<&'static str>,
    pub per_thread: Vec<ThreadReport>,
}

fn rays(c: &crate::shading::RayCounts) -> RayStats {
    RayStats {
        primary: c.primary,
        shadow: c.shadow,
        specular: c.specular,
        ambient: c.ambient,
        total: c.total(),
    }
}

pub fn per_thread(threads: &[ThreadStats]) -> (Vec<ThreadReport>, crate::shading::RayCounts) {
    let mut total = crate::shading::RayCounts::default();
    let reports = threads
        .iter()
        .map(|t| {
            total.add(&t.rays);
            ThreadReport {
                tiles: t.tiles,
                busy_s: t.busy_s,
                rays: rays(&t.rays),
            }
        })
        .collect();
    (reports, total)
}

pub fn ray_stats(c: &crate::shading::RayCounts) -> RayStats {
    rays(c)
}
