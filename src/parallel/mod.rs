//! Rendering under mpirun: a master on rank 0 hands out tiles on demand to worker ranks, which
//! share cache records in one of the paper's ways (section 4): not at all, through the master,
//! or by broadcast. Component mode (section 5) builds on the same master, tiles and transport.

pub mod ahead;
pub mod comm;
pub mod component;
pub mod counters;
pub mod error;
pub mod liveness;
pub mod master;
pub mod prepass;
pub mod protocol;
pub mod pulse;
pub mod relay;
pub mod transport;
pub mod worker;

use crate::checkpoint::{Checkpoint, Restored};
use crate::image::framebuffer::FrameBuffer;
use crate::image::framebuffer::PixelValue;
use crate::image::layered_exr::{ExrLayout, StreamedExr, TileChunks};
use crate::irradiance::IrradianceCache;
use crate::job::Job;
use crate::prepass::PrepassOutcome;
use crate::render::ThreadStats;
use crate::render::sink::PrepassRecords;
use crate::shading::Integrator;
use crate::stats::{RankReport, RenderStats, ThreadReport};
use crate::tiles::{Tile, tiles};
use comm::{Comm, Counters, Hosts};
use component::Roles;
pub use error::{ParallelError, ParallelResult};
use mpi::Threading;
use protocol::{FinishedTile, Kind, Message, Records, TilePixels};
use std::sync::Mutex;
use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::Relaxed;
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

    /// The paper's synchronisation threshold without --sync: new records a rank gathers before
    /// sharing them. In the traditional modes every share is a round trip through the master (or
    /// a message to every rank), paid out of rendering time; component mode's PAs and helping
    /// PRs make every record and share sooner, so the others work with fresher caches.
    fn default_sync(self) -> usize {
        if self == Mode::Component { 8 } else { 50 }
    }
}

/// What the command that starts a parallel run gives it: typed settings, and its own work behind
/// `JobHost`.
pub struct ParallelJob<'a> {
    pub mode: Mode,
    pub width: u32,
    pub height: u32,
    pub tile: (u32, u32),
    /// Rendering threads per rank (None: 1).
    pub threads: Option<usize>,
    /// --sync, --send, --pa, --pa-queue (see `Mode::default_sync` and component mode).
    pub sync: Option<u32>,
    pub send: u32,
    pub pa: Option<u32>,
    pub pa_queue: u32,
    /// --pr-waits: a PR whose outbox is full waits (the paper's PRs) rather than compute.
    pub pr_waits: bool,
    /// How long a rank may be silent before it counts as lost (see `liveness`).
    pub silence_limit: Duration,
    pub seed: u64,
    /// -af: the master keeps a cache file (noshare workers send their records at the end).
    pub cache_file: bool,
    pub quiet: bool,
    pub host: &'a dyn JobHost,
}

/// The command's side of a parallel run: what only it knows how to do.
pub trait JobHost: Sync {
    /// Checks the options (every rank, the same verdict).
    fn validate(&self) -> Result<(), String>;
    /// Rank 0: checks that the outputs can be written, before any work.
    fn check_outputs(&self) -> Result<(), String>;
    /// Rank 0: opens the --checkpoint journal, if any, and what an earlier run finished.
    fn open_checkpoint(&self, tiles: &[Tile]) -> Result<Option<(Checkpoint, Restored)>, String>;
    /// Loads the scene and prepares this rank's job (only the master's with the cache file).
    fn prepare(&self, master: bool, threads: usize) -> Result<Job, String>;
    /// Rank 0: the statistics of the job itself, for `ranks` ranks and `render_s` seconds.
    fn job_stats(&self, job: &Job, mode: &'static str, ranks: usize, render_s: f64) -> RenderStats;
    /// Rank 0: writes the image, its preview and the statistics.
    fn write(&self, job: &Job, frame: &FrameBuffer, stats: &RenderStats) -> Result<(), String>;
    /// The layout of the file rank 0 streams, in which the workers encode their tiles (every
    /// rank, the same answer); None where rank 0 takes the tiles' values: it holds the frame
    /// whole (--denoise) or journals them (--checkpoint).
    fn tile_layout(&self, job: &Job, ranks: usize) -> Option<ExrLayout>;
    /// Rank 0: the stream the tiles go into as they come, or None if the frame must be held
    /// whole (the command's outputs need every pixel at the end: --denoise).
    fn stream(&self, job: &Job, ranks: usize) -> Result<Option<StreamedExr>, String>;
    /// Rank 0: finishes the stream: the image, its preview and the statistics.
    fn finish_stream(&self, job: &Job, streamed: StreamedExr, stats: &RenderStats) -> Result<(), String>;
}

/// A rank's report of its messages and waiting alone: the master's.
pub fn traffic_report(rank: i32, role: &str, counters: &[&Counters], idle_s: f64) -> RankReport {
    let sum = |f: &dyn Fn(&Counters) -> u64| counters.iter().map(|c| f(c)).sum::<u64>();
    RankReport {
        rank: rank as u32,
        role: role.into(),
        idle_s,
        messages: sum(&|c| c.messages_sent.load(Relaxed)),
        bytes: sum(&|c| c.bytes_sent.load(Relaxed)),
        messages_received: sum(&|c| c.messages_received.load(Relaxed)),
        bytes_received: sum(&|c| c.bytes_received.load(Relaxed)),
        heartbeats: liveness::counters().map_or(0, |c| c.messages_sent.load(Relaxed)),
        ..Default::default()
    }
}

/// Sends the rank's statistics to the master, counting this last message in them too (its
/// length is part of what it reports, so the count is settled over a few serialisations).
pub fn send_report(comm: &Comm<'_>, mut report: RankReport) {
    report.messages += 1;
    let before = report.bytes;
    for _ in 0..4 {
        let total = before + Message::Stats(Box::new(report.clone())).encode().len() as u64;
        if report.bytes == total {
            break;
        }
        report.bytes = total;
    }
    comm.send(0, &Message::Stats(Box::new(report)));
}

/// Whether this process was started by mpirun (Open MPI, MPICH or a PMIx launcher).
pub fn under_mpirun() -> bool {
    ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_RANK"]
        .iter()
        .any(|v| std::env::var_os(v).is_some())
}

/// The pid of the process that started this rank (mpirun, or Open MPI's daemon on a remote
/// host), from the session directory Open MPI names after it: `.../pid.NNN/...`.
fn pid_in_session_dir(dir: &str) -> Option<u32> {
    dir.split('/')
        .find_map(|part| part.strip_prefix("pid.").and_then(|p| p.parse().ok()))
}

/// The records a worker took in from other ranks, and those it refused, for its report.
#[derive(Default)]
pub struct Intake {
    received: AtomicU64,
    rejected: AtomicU64,
}

impl Intake {
    /// Counts `records` (and those refused on arrival) and adds them to the rank's cache.
    pub fn take(&self, cache: &IrradianceCache, records: Records) {
        self.received.fetch_add(records.records.len() as u64, Relaxed);
        self.reject(records.rejected);
        records.records.into_iter().for_each(|r| cache.insert_shared(r));
    }

    /// A sync of rendering thread `thread` through the master (centralised mode, helping PRs).
    pub fn sync(&self, comm: &Comm<'_>, thread: u32, cache: &IrradianceCache) {
        let records = Records::from(cache.take_outbox());
        comm.send(0, &Message::RecordsUp { thread, records });
        let reply = comm.receive(&[(Some(0), Some(Kind::RecordsDown.for_thread(thread)))], None);
        if let Some(Ok(Message::RecordsDown { records, .. })) = reply.map(|r| r.message) {
            self.take(cache, records);
        }
    }

    pub fn reject(&self, count: usize) {
        self.rejected.fetch_add(count as u64, Relaxed);
    }

    pub fn totals(&self) -> (u64, u64) {
        (self.received.load(Relaxed), self.rejected.load(Relaxed))
    }
}

/// This rank's part of the job once the prepass (if any) is done, master or worker.
pub struct Setup<'a> {
    pub job_in: &'a ParallelJob<'a>,
    pub job: Job,
    pub tiles: Vec<Tile>,
    /// Each rank's host, for messages that name a rank.
    pub hosts: Hosts,
    pub prepass: Option<PrepassOutcome>,
    /// The master's --checkpoint journal and what an earlier run finished.
    pub checkpoint: Option<(Checkpoint, Restored)>,
    /// New records a rank gathers before sharing them (--sync, at least 1, or the mode's default).
    pub sync: usize,
    /// Messages this rank sent and received before its role began (the prepass's), for its report.
    pub traffic_before: &'a Counters,
    /// When the role began: its report's wall time.
    pub start: Instant,
    /// The tiles each rank began during the prepass (by rank), which the master hands it first,
    /// and this worker's traces of its own (`ahead`).
    pub claims: Vec<Vec<u32>>,
    pub traced: Mutex<ahead::TracedTiles>,
    /// What tracing ahead did on this worker.
    pub ahead: ahead::AheadReport,
    /// A worker's encoder of the file's tiles, where the master streams the file (the prepass
    /// build) and takes them encoded (`JobHost::tile_layout`).
    pub chunks: Option<(TileChunks, Option<PrepassRecords>)>,
}

impl Setup<'_> {
    pub fn cache(&self) -> Option<&IrradianceCache> {
        self.job.cache.as_ref()
    }

    /// The integrator of every worker: the rank's cache, read only after a prepass.
    pub fn integrator(&self) -> Integrator<'_> {
        let job = &self.job;
        Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref()).cache_frozen(job.settings.prepass)
    }

    /// A finished tile for the master: encoded into the file's chunks where the worker can (its
    /// tile lies on the file's tile grid), else its pixels' values.
    pub fn finished_tile(&self, tile: u32, requests: u32, pixels: Vec<PixelValue>) -> FinishedTile {
        let encoded = self.chunks.as_ref().and_then(|(chunks, records)| {
            let at = &self.tiles[tile as usize];
            // The file's count of records at each pixel, which the master adds to values.
            let counted;
            let values = match records {
                Some(records) => {
                    counted = records.counted(at, pixels.clone());
                    &counted
                }
                None => &pixels,
            };
            // A tile the encoder fails on goes as values: the master's writer says what is wrong.
            chunks.encode(at, values).ok().flatten()
        });
        let pixels = match encoded {
            Some(encoded) => TilePixels::Encoded(encoded),
            None => TilePixels::Values(pixels),
        };
        FinishedTile { tile, requests, pixels }
    }

    /// The records of the cache file the workers do not hold yet (after a prepass they do).
    pub fn initial_records(&self) -> Records {
        match self.cache() {
            Some(c) if self.prepass.is_none() => Records::from(c.records()),
            _ => Records::default(),
        }
    }

    /// A worker's report: what its rendering `threads` did (with its share of the prepass), the
    /// messages of `comm`, its `helper` thread and the prepass, and as idle time the rendering
    /// threads' waiting on `comm` (not the helper's, which waits by design).
    pub fn report(&self, comm: &Comm<'_>, role: &str, mut threads: Vec<ThreadStats>, helper: &Counters) -> RankReport {
        crate::render::add_prepass_work(&mut threads, &self.job.prepass_threads);
        let idle_s = comm.counters.idle_s();
        // Waiting is counted per rank; each rendering thread waited for its own replies.
        let idle_per_thread = idle_s / threads.len().max(1) as f64;
        let reports: Vec<ThreadReport> = threads.iter().map(|t| ThreadReport::new(t, idle_per_thread)).collect();
        RankReport {
            threads: threads.len(),
            tiles: reports.iter().map(|t| t.tiles).sum(),
            records_computed: reports.iter().map(|t| t.records_computed).sum(),
            gap_records: reports.iter().map(|t| t.gap_records).sum(),
            edge_pixels: reports.iter().map(|t| t.edge_pixels).sum(),
            lookups: reports.iter().map(|t| t.lookups).sum(),
            hits: reports.iter().map(|t| t.hits).sum(),
            t_amb_s: reports.iter().map(|t| t.t_amb_s).sum(),
            t_notamb_s: reports.iter().map(|t| t.t_notamb_s).sum(),
            rays: crate::stats::RayStats::sum(reports.iter().map(|t| &t.rays)),
            wall_s: self.start.elapsed().as_secs_f64(),
            prepass_s: self.prepass.as_ref().map_or(0.0, |p| p.seconds),
            prepass_pool_s: self.prepass.as_ref().map_or(0.0, |p| p.pool_s),
            prepass_fit_s: self.prepass.as_ref().map_or(0.0, |p| p.fit_s),
            ahead_pixels: self.ahead.pixels,
            ahead_tiles: self.ahead.tiles,
            ahead_s: self.ahead.seconds,
            last_bounce_cells: self.prepass.as_ref().map_or(0, |p| p.last_bounce_cells),
            last_bounce_samples: self.prepass.as_ref().map_or(0, |p| p.last_bounce_samples),
            last_bounce_rays: self
                .prepass
                .as_ref()
                .map_or_else(Default::default, |p| crate::stats::RayStats::from(&p.last_bounce_rays)),
            error: threads.iter().fold(Default::default(), |mut sum, t| {
                sum.merge(&t.error);
                sum
            }),
            ..traffic_report(comm.rank(), role, &[comm.counters, helper, self.traffic_before], idle_s)
        }
    }
}

/// Whether a worker traces its tiles ahead while it waits in the prepass's rounds
/// (`ahead`): component mode's split of the components, when the pixels only read a record set
/// the prepass makes (not with the overture, which makes records as tiles render).
fn traces_ahead(mode: Mode, job: &Job) -> bool {
    mode == Mode::Component
        && job.settings.prepass
        && job.settings.overture == 0
        && job.cache.is_some()
        && job.shading.ambient_bounces > 0
}

/// Checks that MPI gives the threads the mode needs.
fn check_threads(mode: Mode, threads: usize, granted: Threading) -> Result<(), String> {
    if mode == Mode::Component && threads != 1 {
        return Err(
            "--mode component runs one rendering thread per rank (as in the paper): leave out --threads".into(),
        );
    }
    let needs_multiple = mode == Mode::Broadcast || mode == Mode::Component || threads > 1;
    if needs_multiple && granted != Threading::Multiple {
        return Err(format!(
            "--mode {} with {threads} thread(s) per rank needs MPI_THREAD_MULTIPLE, but the MPI library grants only {}",
            mode.name(),
            format!("MPI_THREAD_{granted:?}").to_uppercase()
        ));
    }
    Ok(())
}

/// Checks that the layout can work: every rank alike, so only rank 0 needs to say why.
fn check_layout(job: &ParallelJob<'_>, size: i32, tile_count: usize, threads: usize) -> Result<(), String> {
    if size < 2 {
        return Err(format!(
            "--mode {} needs at least 2 MPI ranks (a master and a worker); got {size}",
            job.mode.name()
        ));
    }
    if job.sync == Some(0) {
        return Err("--sync must be at least 1".into());
    }
    let workers = (size - 1) as usize * threads;
    if workers > tile_count {
        return Err(format!(
            "{workers} rendering threads on {} worker rank(s) but only {tile_count} tiles: use smaller --tile or fewer ranks",
            size - 1
        ));
    }
    Ok(())
}

/// Ends a job that every rank stops together: each rank says its `line` if it has one (for a
/// verdict all ranks share, rank 0 alone), then all meet at a barrier before any exits: a rank
/// exiting with an error first makes mpirun kill the job, rank 0 included, before its line is out.
fn stop_together(comm: &Comm<'_>, line: Option<&str>) -> ParallelError {
    if let Some(line) = line {
        crate::diagnostics::error(line);
    }
    comm.barrier();
    ParallelError::Input(String::new())
}

pub fn run(job_in: &ParallelJob<'_>) -> ParallelResult {
    let wall = Instant::now();
    let host = job_in.host;
    // A rank never outlives its launcher (see sys::process).
    let session_dir = std::env::var("PMIX_SERVER_TMPDIR").or_else(|_| std::env::var("OMPI_FILE_LOCATION"));
    let launcher = session_dir.ok().as_deref().and_then(pid_in_session_dir);
    crate::sys::process::die_with_parent(launcher).map_err(ParallelError::Input)?;
    if let Some(pml) = transport::this_host_asks_for() {
        crate::sys::process::set_before_threads(transport::PML_VARIABLE, pml);
    }
    let Some((universe, granted)) = mpi::initialize_with_threading(Threading::Multiple) else {
        return Err(ParallelError::Failed("MPI could not be initialised".into()));
    };
    let counters = Counters::default();
    let comm = Comm::new(&counters);
    let (rank, size) = (comm.rank(), comm.size());
    let fail = |message: String| stop_together(&comm, (rank == 0).then_some(message.as_str()));
    let threads = job_in.threads.unwrap_or(1);
    check_threads(job_in.mode, threads, granted)
        .and_then(|()| host.validate())
        .map_err(&fail)?;
    let all_tiles = tiles(job_in.width, job_in.height, job_in.tile.0, job_in.tile.1);
    check_layout(job_in, size, all_tiles.len(), threads).map_err(&fail)?;
    let hosts = comm.host_names();
    // Heartbeats from here on (see `liveness`): every rank hears from its master and the master
    // from every rank while the job runs (the pulse needs MPI_THREAD_MULTIPLE). The pulse stops
    // before MPI is finalized (a tuple's fields drop in order): no thread may use MPI then.
    liveness::begin(size as usize);
    let (own_host, master_host, seconds) = (hosts.of(rank), hosts.of(0), job_in.silence_limit.as_secs_f64());
    let lost_master = format!(
        "rank {rank} on {own_host}: no word from the master (rank 0 on {master_host}) for {seconds:.0} s: it is \
         gone or hangs; this rank ends"
    );
    let pulse = (granted == Threading::Multiple).then(|| pulse::Pulse::start(job_in.silence_limit, lost_master));
    let session = (pulse, universe);
    // From here on a failure may hit one rank only (its files, its file system): that rank says
    // why and ends the whole job, or the others would wait for it for ever. Every rank loads the
    // scene; only the master opens the cache file (with --checkpoint, beside its journal).
    let checkpoint = if rank == 0 {
        host.check_outputs().unwrap_or_else(|e| end_job(&comm, None, &e));
        host.open_checkpoint(&all_tiles)
            .unwrap_or_else(|e| end_job(&comm, None, &e))
    } else {
        None
    };
    // Every rank checks --max-memory for the hungriest role, so they all reach one verdict.
    let prepared = host.prepare(rank == 0, threads);
    // If rank 0 could not prepare, it alone says why (the others most likely failed the same
    // way); else each failing rank does. All then stop.
    let failed = comm.all_flags(prepared.is_err());
    let mut job = match prepared {
        Ok(job) if !failed.contains(&true) => job,
        outcome => {
            let line = match outcome {
                Err(e) if rank == 0 => Some(e),
                Err(e) if !failed[0] => Some(format!("rank {rank}: {e}")),
                _ => None,
            };
            return Err(stop_together(&comm, line.as_deref()));
        }
    };
    // Rank 0 alone writes images; the other ranks never open the image library. It opens it
    // now, while the workers start the prepass, not while it loads the scene: the opening holds
    // the dynamic loader's lock, which the scene load's first calls into its libraries wait for
    // (the master's load took 0.48 s against the workers' 0.23 s, and the prepass's first
    // exchange waited for it: conference room, 3 ranks on 2 cores).
    if rank == 0 {
        crate::sys::image_io::open_in_background();
    }
    // Every rank ends the prepass with the same cache; the modes then only read it (a gap's
    // record stays with the pixel that needed it).
    let prepassed = job.settings.prepass.then(|| {
        let ahead = (rank != 0 && traces_ahead(job_in.mode, &job)).then(|| {
            let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
            let worker = ((rank - 1) as usize, (size - 1) as usize);
            ahead::TracingAhead::new(
                integrator,
                &job.camera,
                &job.settings,
                &all_tiles,
                worker,
                ahead::TRACE_BYTES_LIMIT,
            )
        });
        prepass::run(&comm, &job, job_in.silence_limit, &hosts, ahead)
            .unwrap_or_else(|e| end_job(&comm, job.cache.as_ref(), &e))
    });
    let (prepass, claims, traced, ahead) = match prepassed {
        Some(p) => (Some(p.outcome), p.claims, p.traced, p.ahead),
        None => Default::default(),
    };
    job.prepass_threads = prepass.as_ref().map(|p| p.threads.clone()).unwrap_or_default();
    // The tiles take the prepass's edge pixels instead of tracing their corners again.
    job.settings.edge_map = prepass.as_ref().and_then(|p| p.edges.clone());
    // Component mode's PAs and PRs: every rank chooses alike from the same scene and options.
    // After a prepass the record set is complete and only read: no pixel misses the cache (the
    // rare gap's record is made by the pixel that needs it), so no request would reach a PA,
    // which would sit idle through the final pass (conference room 640x360, -ab 2, 3 ranks: the
    // PA idle for 3.2 s of a 3.4 s final pass). The set's indirect diffuse work was the
    // prepass, which every worker shared; every worker then renders as a PR.
    let set_complete = prepass.is_some();
    let roles = (job_in.mode == Mode::Component).then(|| {
        let diffuse_work = job.cache.is_some() || (job.shading.ambient_bounces > 0 && job.scene.needs().diffuse);
        let roles = Roles::choose(size, job_in.pa, diffuse_work)?;
        Ok::<_, String>(if set_complete {
            roles.every_worker_renders()
        } else {
            roles
        })
    });
    let roles = roles.transpose().map_err(&fail)?;
    // A worker that shares its records, or sends them for the -af file, keeps those it makes.
    if rank != 0
        && (job_in.mode != Mode::Noshare || job_in.cache_file)
        && let Some(cache) = job.cache.as_mut()
    {
        cache.keep_outbox();
    }
    // Where the master streams the file (the prepass build, `master::run`), a worker encodes
    // its tiles into the file's chunks: the master only writes them.
    let chunks = prepass.as_ref().filter(|_| rank != 0).and_then(|outcome| {
        let layout = host.tile_layout(&job, size as usize)?;
        let records = layout.plan.counts_records().then(|| PrepassRecords::of(outcome));
        Some((TileChunks::new(layout).ok()?, records))
    });
    let setup = Setup {
        job_in,
        job,
        tiles: all_tiles,
        hosts,
        prepass,
        checkpoint,
        sync: job_in.sync.map_or(job_in.mode.default_sync(), |n| n.max(1) as usize),
        traffic_before: &counters,
        start: Instant::now(),
        claims,
        traced: Mutex::new(traced),
        ahead,
        chunks,
    };
    match roles {
        _ if rank == 0 => {
            let mut sharing: Box<dyn master::Sharing> = match roles {
                None => Box::<worker::TraditionalSharing>::default(),
                Some(roles) => {
                    if !job_in.quiet {
                        eprintln!("icrender: {}", roles.describe());
                        if roles.pas.is_empty() && set_complete {
                            eprintln!(
                                "icrender: the prepass built every record the image reads: no PA is needed, every \
                                 worker renders"
                            );
                        } else if roles.pas.is_empty() {
                            eprintln!(
                                "icrender: the scene has no indirect diffuse work (-ab 0 or no diffuse surface): no PA \
                                 is needed"
                            );
                        }
                    }
                    Box::new(component::master::ComponentSharing::new(roles))
                }
            };
            master::run(&comm, &setup, sharing.as_mut(), wall)?
        }
        None => worker::run(&setup),
        Some(roles) if roles.pas.contains(&rank) => component::pa::run(&setup),
        Some(roles) => component::pr::run(&setup, &roles),
    }
    drop(session);
    Ok(())
}

/// The master's end of a failed job: keeps what the cache file has, says why, stops every rank.
pub(crate) fn end_job(comm: &Comm<'_>, cache: Option<&IrradianceCache>, message: &str) -> ! {
    if let Some(cache) = cache {
        let _ = cache.finish();
    }
    crate::diagnostics::error(message);
    comm.abort(1)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_launcher_is_found_in_open_mpis_session_directory() {
        assert_eq!(super::pid_in_session_dir("/tmp/ompi.vm.0/pid.12368/0/0"), Some(12368));
        assert_eq!(super::pid_in_session_dir("/tmp/ompi.vm.0/pid.77"), Some(77));
        assert_eq!(super::pid_in_session_dir("/tmp/elsewhere"), None);
        assert_eq!(super::pid_in_session_dir("/tmp/pid.x/1"), None);
    }
}
