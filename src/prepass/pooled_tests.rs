//! The prepass pooled over several processes, without mpirun: each process is a thread with its
//! own job (scene, tracer, cache), and the pool hands parts over in memory the way an allgather
//! does. Every process must end with the record set one process alone makes, record for
//! record, in the same order, and the same pixel maps.

use super::*;
use crate::cli::{Cli, Command};
use crate::job::Job;
use clap::Parser;
use std::sync::{Arc, Barrier};

/// An allgather among `parties` threads: each puts its part in its slot, and once all have,
/// each takes a copy of every slot; a second barrier keeps the slots until all have read them.
struct Gather<T> {
    slots: Mutex<Vec<Option<T>>>,
    barrier: Barrier,
}

impl<T: Clone> Gather<T> {
    fn new(parties: usize) -> Arc<Self> {
        Arc::new(Gather {
            slots: Mutex::new(vec![None; parties]),
            barrier: Barrier::new(parties),
        })
    }

    fn all(&self, slot: usize, mine: T) -> Vec<T> {
        self.slots.lock().unwrap()[slot] = Some(mine);
        self.barrier.wait();
        let all = self
            .slots
            .lock()
            .unwrap()
            .iter()
            .map(|p| p.clone().expect("every part"))
            .collect();
        self.barrier.wait();
        all
    }
}

/// One process of the pool: the master (slot 0, no share, not among the grid's workers) or a
/// worker.
struct InMemory {
    slot: usize,
    share: Share,
    rounds: Arc<Gather<RoundRecords>>,
    sites: Arc<Gather<Vec<u32>>>,
    rows: Arc<Gather<PixelRows>>,
    grid: Arc<Gather<GridRows>>,
}

impl Pool for InMemory {
    type Error = Infallible;

    fn share(&self) -> Share {
        self.share
    }

    fn round(&mut self, mine: RoundRecords) -> Result<RoundRecords, Infallible> {
        Ok(self.rounds.all(self.slot, mine).concat())
    }

    fn sites(&mut self, mine: Vec<u32>) -> Result<Vec<u32>, Infallible> {
        Ok(self.sites.all(self.slot, mine).concat())
    }

    fn grid_rows(&mut self, mine: GridRows) -> Result<GridRows, Infallible> {
        assert_ne!(
            self.share,
            Share::Nothing,
            "a process that renders nothing builds no grid"
        );
        Ok(self.grid.all(self.slot - 1, mine).concat())
    }

    fn pixel_rows(&mut self, mine: PixelRows) -> Result<PixelRows, Infallible> {
        Ok(self.rows.all(self.slot, mine).concat())
    }
}

use std::convert::Infallible;

fn job(extra: &[&str]) -> Job {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/cornell.gltf");
    let args = [
        &["icrender", "render", scene, "-x", "40", "-y", "32", "-ad", "64"],
        extra,
    ]
    .concat()
    .into_iter();
    let args = crate::cli::rewrite_radiance_options(args.map(String::from));
    let Command::Render(args) = Cli::try_parse_from(args).expect("options").command else {
        panic!("not a render")
    };
    Job::prepare(&args, crate::memory::Role::Single).expect("the Cornell box loads")
}

/// What a prepass left: its cache's records in order, each record's pixel, and the edge map.
type Made = (
    Vec<crate::irradiance::record::Record>,
    Vec<(u32, u32)>,
    Option<Vec<bool>>,
);

fn made(job: &Job, outcome: PrepassOutcome) -> Made {
    let cache = job.cache.as_ref().expect("a cache");
    let edges = outcome.edges.map(|e| e.as_ref().clone());
    (cache.records(), outcome.record_pixels, edges)
}

fn pooled(workers: usize, extra: &[&str]) -> Vec<Made> {
    let parties = workers + 1;
    let (rounds, rows, grid) = (Gather::new(parties), Gather::new(parties), Gather::new(workers));
    let sites = Gather::new(parties);
    std::thread::scope(|scope| {
        let processes: Vec<_> = (0..parties)
            .map(|slot| {
                let (rounds, rows, grid, sites) = (rounds.clone(), rows.clone(), grid.clone(), sites.clone());
                scope.spawn(move || {
                    let job = job(extra);
                    let share = match slot {
                        0 => Share::Nothing,
                        k => Share::Slice {
                            index: k - 1,
                            count: workers,
                        },
                    };
                    let mut pool = InMemory {
                        slot,
                        share,
                        rounds,
                        sites,
                        rows,
                        grid,
                    };
                    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
                    let Ok(outcome) = run_shared(&integrator, &job.camera, &job.settings, &mut pool);
                    made(&job, outcome)
                })
            })
            .collect();
        processes.into_iter().map(|p| p.join().expect("a process")).collect()
    })
}

#[test]
fn every_pooled_process_ends_with_the_record_set_of_one_process() {
    // Two bounces (the last bounce's grid), samples at edges and at pixels that need them
    // (both pixel maps), so every list the pool shares is exercised.
    let extra = ["-ab", "2", "--spp", "2", "--edge-samples", "5", "--threads", "1"];
    let alone = {
        let job = job(&extra);
        let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
        let outcome = run(&integrator, &job.camera, &job.settings, &|_, _| true);
        assert!(outcome.last_bounce_samples > 0 && outcome.pixels_sampled > 0);
        made(&job, outcome)
    };
    assert!(alone.0.len() > 20, "{} records", alone.0.len());
    for workers in [1, 2, 3] {
        for (slot, process) in pooled(workers, &extra).into_iter().enumerate() {
            assert!(process.0 == alone.0, "{workers} workers, process {slot}: other records");
            assert_eq!(process.1, alone.1, "{workers} workers, process {slot}: other pixels");
            assert_eq!(
                process.2, alone.2,
                "{workers} workers, process {slot}: another edge map"
            );
        }
    }
}
