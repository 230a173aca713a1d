//! The prepass pooled over several processes, without mpirun: each process is a thread with its
//! own job (scene, tracer, cache), and the pool hands parts over in memory the way an allgather
//! among the workers does; the master keeps the rounds the first worker hands it
//! (`keep_rounds`), as under mpirun. Every process must end with the record set one process
//! alone makes, record for record, in the same order, and the same pixel maps.

use super::*;
use crate::cli::{Cli, Command};
use crate::irradiance::record::Record;
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

/// A worker of the pool (slot k of the workers); the first also hands the master its rounds.
struct InMemory {
    slot: usize,
    share: Share,
    rounds: Arc<Gather<RoundRecords>>,
    sites: Arc<Gather<Vec<u32>>>,
    rows: Arc<Gather<PixelRows>>,
    grid: Arc<Gather<GridRows>>,
    to_master: Option<std::sync::mpsc::Sender<Kept>>,
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
        Ok(self.grid.all(self.slot, mine).concat())
    }

    fn pixel_rows(&mut self, mine: PixelRows) -> Result<PixelRows, Infallible> {
        Ok(self.rows.all(self.slot, mine).concat())
    }

    fn kept(&mut self, log: RoundLog, records: &[(u32, crate::irradiance::record::Record)]) -> Result<(), Infallible> {
        if let Some(to_master) = &self.to_master {
            to_master
                .send(Kept::Round(log, records.to_vec()))
                .expect("the master listens");
        }
        Ok(())
    }

    fn ended(&mut self, pixels_sampled: u64) -> Result<(), Infallible> {
        if let Some(to_master) = &self.to_master {
            to_master.send(Kept::End(pixels_sampled)).expect("the master listens");
        }
        Ok(())
    }

    fn keeps(&self) -> bool {
        self.to_master.is_some()
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
    let edges = outcome.edges.map(|e| e.to_bools());
    (cache.records(), outcome.record_pixels, edges)
}

/// What the master and each of `workers` workers made, the master's first (with no edge map:
/// it renders nothing).
fn pooled(workers: usize, extra: &[&str]) -> Vec<Made> {
    let (rounds, rows, grid) = (Gather::new(workers), Gather::new(workers), Gather::new(workers));
    let sites = Gather::new(workers);
    let (to_master, kept) = std::sync::mpsc::channel();
    std::thread::scope(|scope| {
        let master = scope.spawn(move || {
            let job = job(extra);
            let cache = job.cache.as_ref().expect("a cache");
            let Ok(outcome) = keep_rounds::<Infallible>(cache, &job.camera, &job.settings, || {
                Ok(kept.recv().expect("the first worker hands every round over"))
            });
            made(&job, outcome)
        });
        let processes: Vec<_> = (0..workers)
            .map(|slot| {
                let (rounds, rows, grid, sites) = (rounds.clone(), rows.clone(), grid.clone(), sites.clone());
                let to_master = (slot == 0).then(|| to_master.clone());
                scope.spawn(move || {
                    let job = job(extra);
                    let share = Share::Slice {
                        index: slot,
                        count: workers,
                    };
                    let mut pool = InMemory {
                        slot,
                        share,
                        rounds,
                        sites,
                        rows,
                        grid,
                        to_master,
                    };
                    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
                    let Ok(outcome) = run_shared(&integrator, &job.camera, &job.settings, &mut pool);
                    made(&job, outcome)
                })
            })
            .collect();
        drop(to_master);
        let mut made = vec![master.join().expect("the master")];
        made.extend(processes.into_iter().map(|p| p.join().expect("a process")));
        made
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
            if slot == 0 {
                // The master keeps the records for the cache file, which holds no curvature
                // (every process fits it from the records): it does not fit them, and so its
                // cache lists them in the order they were placed.
                let unfitted = |records: &[Record]| {
                    let mut records: Vec<String> = (records.iter())
                        .map(|r| {
                            format!(
                                "{:?}",
                                Record {
                                    curvature: 0.0,
                                    ..r.clone()
                                }
                            )
                        })
                        .collect();
                    records.sort();
                    records
                };
                assert!(process.0.iter().all(|r| r.curvature == 0.0));
                assert!(
                    unfitted(&process.0) == unfitted(&alone.0),
                    "{workers} workers: the master keeps other records"
                );
            } else {
                assert!(process.0 == alone.0, "{workers} workers, process {slot}: other records");
            }
            assert_eq!(process.1, alone.1, "{workers} workers, process {slot}: other pixels");
            // The master keeps the records and renders nothing: it has no edge map.
            if slot > 0 {
                assert_eq!(
                    process.2, alone.2,
                    "{workers} workers, process {slot}: another edge map"
                );
            }
        }
    }
}
