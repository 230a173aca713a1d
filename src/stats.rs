//! Render statistics: timers, ray counters and irradiance cache traffic, per thread and total,
//! written as JSON (`--stats`) and into the EXR header. The top-level keys `records_computed`,
//! `lookups`, `hits`, `t_amb_s`, `t_notamb_s` and `wall_s` are relied on by scripts.

use crate::render::error_estimate::{ErrorEstimate, ErrorTally};
use crate::render::pixel::ThreadStats;
use crate::shading::RayCounts;
use serde::Serialize;

#[derive(Clone, Debug, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct RayStats {
    pub primary: u64,
    pub shadow: u64,
    pub specular: u64,
    pub ambient: u64,
    /// Rays traced on past a surface they passed through (`RayCounts::continued`).
    #[serde(default)]
    pub continued: u64,
    pub total: u64,
}

impl RayStats {
    /// The sum of several.
    pub fn sum<'a>(all: impl IntoIterator<Item = &'a RayStats>) -> RayStats {
        all.into_iter().fold(RayStats::default(), |a, b| RayStats {
            primary: a.primary + b.primary,
            shadow: a.shadow + b.shadow,
            specular: a.specular + b.specular,
            ambient: a.ambient + b.ambient,
            continued: a.continued + b.continued,
            total: a.total + b.total,
        })
    }
}

impl From<&RayCounts> for RayStats {
    fn from(c: &RayCounts) -> Self {
        RayStats {
            primary: c.primary,
            shadow: c.shadow,
            specular: c.specular,
            ambient: c.ambient,
            continued: c.continued,
            total: c.total(),
        }
    }
}

/// One thread's share.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ThreadReport {
    pub tiles: usize,
    pub busy_s: f64,
    pub cpu_s: f64,
    pub records_computed: u64,
    pub lookups: u64,
    pub hits: u64,
    pub duplicates: u64,
    pub gap_records: u64,
    pub edge_pixels: u64,
    /// Time computing indirect diffuse light (the paper's T_amb) and the rest (T_notamb).
    pub t_amb_s: f64,
    pub t_notamb_s: f64,
    pub rays: RayStats,
}

impl ThreadReport {
    /// A thread's report. T_amb and T_notamb are CPU seconds, so that aggregated figures mean
    /// the same on an oversubscribed machine as on a cluster: T_amb is timed by the wall clock
    /// (cheap enough to read at every lookup) and scaled by the share of its active wall time
    /// the thread really ran; `idle_s` is the wall time it spent waiting for messages.
    pub fn new(t: &ThreadStats, idle_s: f64) -> Self {
        let c = &t.rays;
        let active = (t.busy_s - idle_s).max(1e-9);
        let running = (t.cpu_s / active).clamp(0.0, 1.0);
        let t_amb_s = (c.t_amb * running).min(t.cpu_s);
        ThreadReport {
            tiles: t.tiles,
            busy_s: t.busy_s,
            cpu_s: t.cpu_s,
            records_computed: c.records_computed,
            lookups: c.lookups,
            hits: c.hits,
            duplicates: c.duplicates,
            gap_records: c.gap_records,
            edge_pixels: c.edge_pixels,
            t_amb_s,
            t_notamb_s: (t.cpu_s - t_amb_s).max(0.0),
            rays: RayStats::from(c),
        }
    }
}

impl From<&ThreadStats> for ThreadReport {
    fn from(t: &ThreadStats) -> Self {
        ThreadReport::new(t, 0.0)
    }
}

/// One rank's share of an MPI render (the serial mode reports itself as one rank too).
#[derive(Clone, Debug, Default, PartialEq, Serialize, serde::Deserialize)]
pub struct RankReport {
    pub rank: u32,
    /// "serial", "mc" (master controller), "worker", "pr" or "pa".
    pub role: String,
    pub threads: usize,
    pub tiles: usize,
    pub records_computed: u64,
    /// Records made after a prepass for one pixel's own use (see `RenderStats::gap_records`).
    #[serde(default)]
    pub gap_records: u64,
    /// Pixels that took `--edge-samples` (see `RenderStats::edge_pixels`).
    #[serde(default)]
    pub edge_pixels: u64,
    pub lookups: u64,
    pub hits: u64,
    pub t_amb_s: f64,
    pub t_notamb_s: f64,
    /// Time waiting for work or messages.
    pub idle_s: f64,
    /// Messages and bytes this rank sent (its heartbeats apart: see `heartbeats`).
    pub messages: u64,
    pub bytes: u64,
    pub messages_received: u64,
    pub bytes_received: u64,
    /// Records that arrived from other ranks, and those refused as invalid.
    pub records_received: u64,
    pub records_rejected: u64,
    pub wall_s: f64,
    /// Component mode: L_a requests this rank sent (PR), computed (PA, or PR helping), and
    /// handed on to an idle PR by load balancing (PA); a PA's queue length over time.
    #[serde(default)]
    pub requests_sent: u64,
    #[serde(default)]
    pub requests_computed: u64,
    #[serde(default)]
    pub requests_forwarded: u64,
    /// Component mode, PR: requests it computed itself because its outbox was full (its PA's
    /// queue: back-pressure), never sent, so in neither count above.
    #[serde(default)]
    pub requests_kept: u64,
    /// Component mode: seconds this rank spent handling requests as messages, timed where it
    /// happens: a PR encoding and queueing its batches, a PA decoding and queueing what arrives.
    /// What a request costs beyond the indirect light it asks for.
    #[serde(default)]
    pub request_handling_s: f64,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub queue_lengths: Vec<(f64, u32)>,
    /// PA: the longest its request queue ever was.
    pub queue_max: u64,
    /// Rays this rank traced (its prepass share included).
    #[serde(default)]
    pub rays: RayStats,
    /// Heartbeats this rank sent (one byte and MPI's envelope each, every 2 s; see
    /// `parallel::liveness`). Not in `messages`: a rank's last heartbeats may still be on their
    /// way when the reports are added up.
    #[serde(default)]
    pub heartbeats: u64,
    /// The prepass on this rank: seconds in all, and of those the seconds in its pool's
    /// collectives (handing its share over and waiting for the other ranks': the rounds'
    /// barriers).
    #[serde(default)]
    pub prepass_s: f64,
    #[serde(default)]
    pub prepass_pool_s: f64,
    /// Of `prepass_s`, the seconds fitting and freezing the complete record set.
    #[serde(default)]
    pub prepass_fit_s: f64,
    /// Component mode under a prepass: the pixels this worker traced ahead of the record set
    /// (`parallel::ahead`), the tiles they began, and the seconds of its waits in the rounds'
    /// collectives it filled so (part of `prepass_pool_s`; the rest was idle).
    #[serde(default)]
    pub ahead_pixels: u64,
    #[serde(default)]
    pub ahead_tiles: u64,
    #[serde(default)]
    pub ahead_s: f64,
    /// The last bounce's grid as this rank built it (the same cells and samples on every
    /// worker) and the rays of the rows it sampled (the workers share the rows).
    #[serde(default)]
    pub last_bounce_cells: u64,
    #[serde(default)]
    pub last_bounce_samples: u64,
    #[serde(default)]
    pub last_bounce_rays: RayStats,
    /// The master: the finished tiles' bytes it received (their values, or the file's chunks a
    /// worker encoded, with their preview pixels), and the seconds it spent storing them (into
    /// the file's stream or the frame it holds).
    #[serde(default)]
    pub tile_bytes: u64,
    #[serde(default)]
    pub tiles_s: f64,
    /// What the render's error estimate is summed from, over this rank's tiles.
    #[serde(default)]
    pub error: ErrorTally,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct RenderStats {
    pub version: &'static str,
    pub scene: String,
    pub mode: &'static str,
    pub ranks: usize,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub threads: usize,
    /// The overture's grid spacing in pixels (0: none).
    pub overture: u32,
    /// How the cache was filled: "prepass" (every record placed before shading) or
    /// "progressive" (records made as pixels render).
    pub cache_build: &'static str,
    /// The prepass: seconds, rounds, sites looked at and records made (all in the totals too).
    pub prepass_s: f64,
    /// Of `prepass_s`, the seconds fitting and freezing the complete record set.
    pub prepass_fit_s: f64,
    pub prepass_rounds: u64,
    pub prepass_sites: u64,
    pub prepass_records: u64,
    /// Pixels whose every sample the prepass visited (edges; the others' samples share their
    /// centre's records).
    pub prepass_pixels_sampled: u64,
    /// The last bounce's grid (`--ic-deep grid`): cells with a mean, and the samples taken.
    pub last_bounce_cells: u64,
    pub last_bounce_samples: u64,
    /// The rays the grid's samples traced (part of `rays`).
    pub last_bounce_rays: RayStats,
    /// Each prepass round as this process (rank 0 under mpirun) saw it.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub prepass_round_log: Vec<crate::prepass::RoundLog>,
    /// Records pixels had to make after the prepass, each for its own use (a gap it left).
    pub gap_records: u64,
    /// Pixels an edge crosses, which took `--edge-samples` samples instead of `--spp`.
    pub edge_pixels: u64,
    pub triangles: usize,
    pub dropped_triangles: usize,
    pub load_s: f64,
    pub build_s: f64,
    pub render_s: f64,
    pub wall_s: f64,
    /// New records made by this run (cache misses).
    pub records_computed: u64,
    /// Records read from the -af file at start.
    pub records_loaded: u64,
    /// Records in the cache at the end.
    pub cache_records: u64,
    /// Tiles taken from the --checkpoint journal of an earlier run instead of rendered.
    pub tiles_restored: u64,
    /// Tiles the workers sent the master as the file's compressed chunks (under mpirun, where
    /// the master streams the file); the others came as their pixels' values.
    pub tiles_encoded: u64,
    pub lookups: u64,
    pub hits: u64,
    /// Records computed while another thread's new record already covered the point.
    pub duplicates: u64,
    /// Times a thread found a cache shard locked and waited.
    pub lock_contention: u64,
    pub t_amb_s: f64,
    pub t_notamb_s: f64,
    /// Summed over ranks: time waiting, messages and bytes sent, invalid records refused.
    pub idle_s: f64,
    pub messages: u64,
    pub bytes: u64,
    pub records_rejected: u64,
    /// Component mode: requests sent by PRs, computed by PAs and helping PRs, forwarded.
    pub requests_sent: u64,
    pub requests_computed: u64,
    pub requests_forwarded: u64,
    /// Component mode: requests PRs computed themselves, their outboxes full.
    pub requests_kept: u64,
    /// Component mode: seconds all ranks spent handling requests as messages.
    pub request_handling_s: f64,
    pub rays: RayStats,
    pub mrays_per_s: f64,
    /// Contributions dropped for being NaN or infinite (should be 0).
    pub nonfinite_dropped: u64,
    pub layers: Vec<&'static str>,
    /// For `icrender reference`: its estimated relative noise (RMS) and number of passes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_noise: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_passes: Option<u64>,
    /// With `--denoise`: the EXR layers the denoiser wrote, and its own time (its device, the
    /// guides' prefiltering and every filter; not in `render_s` or `wall_s`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub denoised_layers: Vec<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub denoise_s: Option<f64>,
    /// The pixels the filter ran on over all layers filtered (`image::noisy_patches`: where the
    /// pixels measured their noise, only where it is).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub denoise_filtered_pixels: Option<usize>,
    /// With --frames or --frame: the frame, its scene time (seconds) and the records the cache
    /// held when the frame began (read from -af and made for earlier frames: carried).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub frame_time_s: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub records_before: Option<u64>,
    /// With frames of animations that move meshes or lights: the records the moves since the
    /// last frame changed, dropped before this frame's prepass (`records_before` is what they
    /// left).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub records_invalidated: Option<u64>,
    /// The seconds this frame spent placing the meshes again and building their BVH.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pose_s: Option<f64>,
    /// Of the records dropped, those made again at their own points by the prepass before its
    /// rounds (`irradiance::record_origins`; counted in `records_computed` too).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub records_remade: Option<u64>,
    /// With -ab 2 and up, the last-bounce grid's sites this frame took from the last one (the
    /// moves did not reach them) and sampled afresh.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_bounce_sites_kept: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub last_bounce_sites_sampled: Option<u64>,
    /// The process's peak resident memory when the render ended, before the files were written
    /// (rank 0's under mpirun; Linux's VmHWM, absent where the system does not report it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub peak_memory_bytes: Option<u64>,
    /// The relMSE this render is estimated to have against the converged image, made without
    /// one (`render::error_estimate`); None where no pixel was rendered.
    pub error_estimate: Option<ErrorEstimate>,
    /// With --passes, --target-error or --time-limit: the passes, and the estimate after each.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub passes: Option<crate::render::passes::PassesReport>,
    pub per_thread: Vec<ThreadReport>,
    pub per_rank: Vec<RankReport>,
}

impl RenderStats {
    /// Fills the totals from the threads' reports.
    pub fn add_prepass(&mut self, prepass: &crate::prepass::PrepassOutcome) {
        self.cache_build = "prepass";
        self.prepass_s = prepass.seconds;
        self.prepass_fit_s = prepass.fit_s;
        self.prepass_rounds = prepass.rounds as u64;
        self.prepass_sites = prepass.sites;
        self.prepass_records = prepass.records;
        self.prepass_pixels_sampled = prepass.pixels_sampled;
        self.last_bounce_cells = prepass.last_bounce_cells;
        self.last_bounce_samples = prepass.last_bounce_samples;
        self.last_bounce_rays = RayStats::from(&prepass.last_bounce_rays);
        self.prepass_round_log = prepass.round_log.clone();
        // Under mpirun the master builds no grid (it renders nothing): the workers say what
        // theirs holds, and each sampled its share of the rows.
        if prepass.last_bounce_samples == 0 && self.per_rank.iter().any(|r| r.last_bounce_samples > 0) {
            self.last_bounce_cells = self.per_rank.iter().map(|r| r.last_bounce_cells).max().unwrap_or(0);
            self.last_bounce_samples = self.per_rank.iter().map(|r| r.last_bounce_samples).max().unwrap_or(0);
            self.last_bounce_rays = RayStats::sum(self.per_rank.iter().map(|r| &r.last_bounce_rays));
        }
    }

    pub fn add_threads(&mut self, threads: &[ThreadStats]) {
        let mut total = RayCounts::default();
        let mut error = ErrorTally::default();
        for t in threads {
            total.add(&t.rays);
            error.merge(&t.error);
            self.per_thread.push(ThreadReport::from(t));
        }
        self.error_estimate = error.estimate();
        self.records_computed = total.records_computed;
        self.lookups = total.lookups;
        self.hits = total.hits;
        self.duplicates = total.duplicates;
        self.gap_records = total.gap_records;
        self.edge_pixels = total.edge_pixels;
        self.t_amb_s = self.per_thread.iter().map(|t| t.t_amb_s).sum();
        self.t_notamb_s = self.per_thread.iter().map(|t| t.t_notamb_s).sum();
        self.rays = RayStats::from(&total);
        self.nonfinite_dropped = total.nonfinite;
        self.mrays_per_s = total.total() as f64 / self.render_s.max(1e-9) / 1e6;
    }

    /// The serial render as the one rank of `per_rank`, so every mode writes the same keys.
    pub fn single_rank(&mut self) {
        self.per_rank = vec![RankReport {
            rank: 0,
            role: "serial".into(),
            threads: self.threads,
            tiles: self.per_thread.iter().map(|t| t.tiles).sum(),
            records_computed: self.records_computed,
            gap_records: self.gap_records,
            edge_pixels: self.edge_pixels,
            lookups: self.lookups,
            hits: self.hits,
            t_amb_s: self.t_amb_s,
            t_notamb_s: self.t_notamb_s,
            wall_s: self.wall_s,
            rays: self.rays.clone(),
            ..Default::default()
        }];
    }

    /// Totals over the ranks' reports.
    pub fn add_ranks(&mut self, ranks: Vec<RankReport>) {
        self.records_computed = ranks.iter().map(|r| r.records_computed).sum();
        self.gap_records = ranks.iter().map(|r| r.gap_records).sum();
        self.edge_pixels = ranks.iter().map(|r| r.edge_pixels).sum();
        self.lookups = ranks.iter().map(|r| r.lookups).sum();
        self.hits = ranks.iter().map(|r| r.hits).sum();
        self.t_amb_s = ranks.iter().map(|r| r.t_amb_s).sum();
        self.t_notamb_s = ranks.iter().map(|r| r.t_notamb_s).sum();
        self.idle_s = ranks.iter().map(|r| r.idle_s).sum();
        self.messages = ranks.iter().map(|r| r.messages).sum();
        self.bytes = ranks.iter().map(|r| r.bytes).sum();
        self.records_rejected = ranks.iter().map(|r| r.records_rejected).sum();
        self.requests_sent = ranks.iter().map(|r| r.requests_sent).sum();
        self.requests_computed = ranks.iter().map(|r| r.requests_computed).sum();
        self.requests_forwarded = ranks.iter().map(|r| r.requests_forwarded).sum();
        self.requests_kept = ranks.iter().map(|r| r.requests_kept).sum();
        self.request_handling_s = ranks.iter().map(|r| r.request_handling_s).sum();
        self.rays = RayStats::sum(ranks.iter().map(|r| &r.rays));
        self.mrays_per_s = self.rays.total as f64 / self.render_s.max(1e-9) / 1e6;
        let mut error = ErrorTally::default();
        ranks.iter().for_each(|r| error.merge(&r.error));
        self.error_estimate = error.estimate();
        self.per_rank = ranks;
    }
}
