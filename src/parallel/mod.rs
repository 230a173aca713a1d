//! Rendering under mpirun: a master controller on rank 0 hands out tiles on demand to worker
//! ranks, which share irradiance cache records in one of the paper's ways (section 4): not at
//! all, through the master, or by broadcast. The component-based mode (section 5) builds on
//! the same master, tiles and record transport.

pub mod comm;
pub mod master;
pub mod protocol;
pub mod worker;

use crate::cli::{ModeArg, RenderArgs};
use crate::commands::render::{producible_layers, Outputs};
use crate::commands::{warn, CommandError, CommandResult};
use crate::irradiance::IrradianceCache;
use crate::job::{validate, Job};
use crate::render::{tiles, RenderSettings, Tile};
use crate::scene::view::Camera;
use crate::scene::Scene;
use crate::shading::ShadingOptions;
use crate::stats::RenderStats;
use crate::tracer::Tracer;
use comm::{Comm, Counters};
use mpi::Threading;
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Serial,
    Noshare,
    Centralised,
    Broadcast,
    Component,
}

impl Mode {
    pub fn name(self) -> &'static str {
        match self {
            Mode::Serial => "serial",
            Mode::Noshare => "noshare",
            Mode::Centralised => "centralised",
            Mode::Broadcast => "broadcast",
            Mode::Component => "component",
        }
    }
}

impl From<ModeArg> for Mode {
    fn from(m: ModeArg) -> Mode {
        match m {
            ModeArg::Serial => Mode::Serial,
            ModeArg::Noshare => Mode::Noshare,
            ModeArg::Centralised => Mode::Centralised,
            ModeArg::Broadcast => Mode::Broadcast,
            ModeArg::Component => Mode::Component,
        }
    }
}

/// Whether this process was started by mpirun (Open MPI, MPICH or a PMIx launcher).
pub fn under_mpirun() -> bool {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"].iter().any(|v| std::env::var_os(v).is_some())
}

/// What a worker renders with.
pub struct WorkerSetup<'a> {
    pub scene: &'a Scene,
    pub tracer: &'a Tracer,
    pub shading: &'a ShadingOptions,
    pub camera: &'a Camera,
    pub settings: &'a RenderSettings,
    pub tiles: &'a [Tile],
    pub cache: Option<&'a IrradianceCache>,
}

fn threading_name(t: Threading) -> &'static str {
    match t {
        Threading::Single => "MPI_THREAD_SINGLE",
        Threading::Funneled => "MPI_THREAD_FUNNELED",
        Threading::Serialized => "MPI_THREAD_SERIALIZED",
        Threading::Multiple => "MPI_THREAD_MULTIPLE",
    }
}

/// Checks that the layout can work; the same answer on every rank, so every rank can stop on
/// its own and only rank 0 needs to say why.
fn check_layout(args: &RenderArgs, mode: Mode, size: i32, tile_count: usize, threads: usize) -> Result<(), String> {
    if size < 2 {
        return Err(format!(
            "--mode {} needs at least 2 MPI ranks (a master and a worker); got {size}",
            mode.name()
        ));
    }
    if args.sync == Some(0) {
        return Err("--sync must be at least 1".into());
    }
    let workers = (size - 1) as usize * threads;
    if workers > tile_count {
        return Err(format!(
            "{} rendering threads on {} worker rank(s) but only {tile_count} tiles: use smaller --tile or fewer ranks",
            workers,
            size - 1
        ));
    }
    Ok(())
}

pub fn run(args: &RenderArgs, mode: Mode) -> CommandResult {
    let wall = Instant::now();
    let Some((universe, granted)) = mpi::initialize_with_threading(Threading::Multiple) else {
        return Err(CommandError("MPI could not be initialised".into()));
    };
    let counters = Counters::default();
    let comm = Comm::new(&counters);
    let (rank, size) = (comm.rank(), comm.size());
    // Only rank 0 speaks; the others stop quietly with the same verdict.
    let fail = |message: String| -> CommandResult {
        if rank == 0 { Err(CommandError(message)) } else { Err(CommandError(String::new())) }
    };
    let threads = args.threads.unwrap_or(1);
    let needs_multiple = mode == Mode::Broadcast || mode == Mode::Component || threads > 1;
    if needs_multiple && granted != Threading::Multiple {
        return fail(format!(
            "--mode {} with {threads} thread(s) per rank needs MPI_THREAD_MULTIPLE, but the MPI library grants only {}",
            mode.name(),
            threading_name(granted)
        ));
    }
    if let Err(e) = validate(args) {
        return fail(e);
    }
    let (tile_width, tile_height) = crate::cli::parse_tile(&args.tile).map_err(CommandError)?;
    let all_tiles = tiles(args.width, args.height, tile_width, tile_height);
    if let Err(e) = check_layout(args, mode, size, all_tiles.len(), threads) {
        return fail(e);
    }
    let outputs = if rank == 0 { Some(Outputs::check(args)?) } else { None };

    // Every rank loads the scene; only the master opens the cache file.
    let mut rank_args = args.clone();
    rank_args.threads = Some(threads);
    if rank != 0 {
        rank_args.ambient_file = None;
    }
    let mut job = match Job::prepare(&rank_args) {
        Ok(job) => job,
        Err(e) if rank == 0 => return Err(e),
        Err(_) => return Err(CommandError(String::new())),
    };
    let sync = args.sync.unwrap_or(50).max(1) as usize;
    let persist_local = args.ambient_file.is_some();
    if rank != 0 {
        if let Some(cache) = job.cache.as_mut()
            && (mode != Mode::Noshare || persist_local)
        {
            cache.keep_outbox();
        }
        let setup = WorkerSetup {
            scene: &job.scene,
            tracer: &job.tracer,
            shading: &job.shading,
            camera: &job.camera,
            settings: &job.settings,
            tiles: &all_tiles,
            cache: job.cache.as_ref(),
        };
        worker::run(&setup, mode, sync, persist_local);
        drop(universe);
        return Ok(());
    }

    let timeout = Duration::from_secs_f64(args.timeout.max(1.0));
    let result = master::run(
        &comm,
        mode,
        &all_tiles,
        args.width,
        args.height,
        threads as u32,
        job.cache.as_ref(),
        timeout,
    );
    let result = match result {
        Ok(r) => r,
        Err(e) => {
            // Keep what the file already has, then stop every rank.
            if let Some(cache) = &job.cache {
                let _ = cache.finish();
            }
            eprintln!("icrender: error: {}", e.0);
            comm.abort(1);
        }
    };
    if let Some(cache) = &job.cache
        && let Err(e) = cache.finish()
    {
        warn(&format!("cache file not fully written: {e}"));
    }
    let mut stats = RenderStats {
        version: env!("CARGO_PKG_VERSION"),
        scene: args.scene.display().to_string(),
        mode: mode.name(),
        ranks: size as usize,
        width: args.width,
        height: args.height,
        spp: args.spp,
        threads,
        triangles: job.scene.triangle_count(),
        dropped_triangles: job.scene.dropped_triangles,
        load_s: job.load_s,
        build_s: job.build_s,
        render_s: result.render_s,
        layers: producible_layers(job.scene.needs(), &job.shading).iter().map(|l| l.name()).collect(),
        records_loaded: job.cache.as_ref().map_or(0, |c| c.load_report.loaded as u64),
        ..Default::default()
    };
    stats.add_ranks(result.ranks);
    stats.wall_s = wall.elapsed().as_secs_f64();
    let outputs = outputs.expect("rank 0 checked its outputs");
    outputs.write(args, &job, &result.frame, &stats)?;
    if !args.quiet {
        print_table(&stats);
    }
    drop(universe);
    Ok(())
}

/// The per-rank statistics as a table on stderr.
fn print_table(stats: &RenderStats) {
    eprintln!(
        "icrender: {} mode, {} ranks, {}x{} in {:.2} s",
        stats.mode, stats.ranks, stats.width, stats.height, stats.render_s
    );
    eprintln!(
        "{:>4} {:>6} {:>6} {:>9} {:>9} {:>8} {:>9} {:>8} {:>8} {:>11}",
        "rank", "role", "tiles", "records", "lookups", "T_amb", "T_notamb", "idle", "msgs", "bytes"
    );
    for r in &stats.per_rank {
        eprintln!(
            "{:>4} {:>6} {:>6} {:>9} {:>9} {:>8.2} {:>9.2} {:>8.2} {:>8} {:>11}",
            r.rank, r.role, r.tiles, r.records_computed, r.lookups, r.t_amb_s, r.t_notamb_s, r.idle_s, r.messages, r.bytes
        );
    }
    eprintln!(
        "{:>4} {:>6} {:>6} {:>9} {:>9} {:>8.2} {:>9.2} {:>8.2} {:>8} {:>11}",
        "all",
        "",
        stats.per_rank.iter().map(|r| r.tiles).sum::<usize>(),
        stats.records_computed,
        stats.lookups,
        stats.t_amb_s,
        stats.t_notamb_s,
        stats.idle_s,
        stats.messages,
        stats.bytes
    );
}
