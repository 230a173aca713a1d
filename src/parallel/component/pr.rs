//! A PR rank: renders the tiles the master hands out, everything but indirect diffuse light.
//! Indirect diffuse values its local cache (records relayed by the master) can give are used at
//! once; the others become requests, buffered and sent to the PAs in turn (--send at a time).
//! With no tile left it flushes its buffer and, when the master asks, computes requests
//! forwarded from a loaded PA. Its image goes to the master only at the end.

use super::*;
use crate::checkpoint::{RequestResult, encode_results};
use crate::image::framebuffer::FrameBuffer;
use crate::parallel::comm::{Comm, Counters};
use crate::parallel::protocol::{TAG_STATS, decode_work};
use crate::parallel::{WorkerSetup, rank_report};
use crate::render::{ThreadClock, ThreadStats, render_tile, store_tile};
use crate::sampling::Rng;
use crate::shading::Integrator;
use crate::shading::request::AmbientRequest;
use std::sync::Mutex;
use std::time::Instant;

struct Sender<'c> {
    comm: &'c Comm<'c>,
    pas: &'c [i32],
    next: usize,
    sent: u64,
}

impl Sender<'_> {
    /// Sends the buffered requests to the next PA in turn.
    fn send(&mut self, sink: &Mutex<Vec<AmbientRequest>>) {
        let batch = std::mem::take(&mut *sink.lock().unwrap_or_else(|e| e.into_inner()));
        if batch.is_empty() || self.pas.is_empty() {
            return;
        }
        let pa = self.pas[self.next % self.pas.len()];
        self.next += 1;
        self.sent += batch.len() as u64;
        self.comm.send(pa, TAG_REQUESTS, &requests::encode(&batch));
    }
}

/// Sends the records made here and takes in those the master has from others.
fn sync_records(
    comm: &Comm<'_>,
    cache: &crate::irradiance::IrradianceCache,
    up: Vec<crate::irradiance::record::Record>,
    received: &mut u64,
    rejected: &mut u64,
) {
    comm.send(0, TAG_PR_SYNC, &encode_batch(&up, 0));
    if let Some(reply) = comm.receive(Some(0), Some(TAG_PR_CATCH_UP), None)
        && let Ok(batch) = decode_batch(&reply.data)
    {
        *received += batch.records.len() as u64;
        *rejected += batch.rejected as u64;
        batch.records.into_iter().for_each(|r| cache.insert_shared(r));
    }
}

/// `journal`: --checkpoint is on, so finished tiles and computed requests are reported to the
/// master as they finish.
pub fn run(setup: &WorkerSetup<'_>, roles: &Roles, send_at: usize, sync: usize, seed: u64, journal: bool) {
    let counters = Counters::default();
    let comm = Comm::new(&counters);
    let start = Instant::now();
    let (width, height) = (setup.camera.width, setup.camera.height);
    let mut frame = FrameBuffer::new(width, height);
    let sink = Mutex::new(Vec::new());
    let mut integrator = Integrator::new(setup.scene, setup.tracer, setup.shading, setup.cache);
    if !roles.pas.is_empty() {
        integrator = integrator.deferring(&sink);
    }
    let mut stats = ThreadStats::default();
    let clock = ThreadClock::start();
    let mut sender = Sender {
        comm: &comm,
        pas: &roles.pas,
        next: 0,
        sent: 0,
    };
    let (mut received, mut rejected) = (0u64, 0u64);

    // Tiles until the master has none left.
    let mut finished_tile: Vec<u8> = Vec::new();
    loop {
        comm.send(0, TAG_PR_WORK_REQUEST, &std::mem::take(&mut finished_tile));
        let Some(reply) = comm.receive(Some(0), Some(TAG_PR_WORK), None) else {
            break;
        };
        let work_len = reply
            .data
            .get(..4)
            .map_or(0, |b| u32::from_le_bytes(b.try_into().expect("4 bytes")) as usize);
        let work = reply.data.get(4..4 + work_len).map(decode_work);
        if let (Some(cache), Some(Ok(batch))) = (setup.cache, reply.data.get(4 + work_len..).map(decode_batch)) {
            received += batch.records.len() as u64;
            rejected += batch.rejected as u64;
            batch.records.into_iter().for_each(|r| cache.insert_shared(r));
        }
        let Some(Ok(Some(index))) = work else { break };
        let tile = &setup.tiles[index as usize];
        let pending = |sender: &Sender<'_>| sender.sent + sink.lock().map_or(0, |s| s.len() as u64);
        let requests_before = pending(&sender);
        let pixels = render_tile(&integrator, setup.camera, setup.settings, tile, &mut stats.rays, |_| {
            if sink.lock().map_or(0, |s| s.len()) >= send_at {
                sender.send(&sink);
            }
        });
        if journal {
            let requests = (pending(&sender) - requests_before) as u32;
            finished_tile = encode_tile_report(index, requests, &pixels);
        }
        store_tile(&mut frame, tile, &pixels);
        stats.tiles += 1;
    }
    sender.send(&sink);
    let mut results: Vec<RequestResult> = Vec::new();
    let report_results = |results: &mut Vec<RequestResult>| {
        if journal && !results.is_empty() {
            comm.send(0, TAG_RESULTS, &encode_results(&std::mem::take(results)));
        }
    };

    // Helping: compute what the master has a PA forward, until it says everything is done.
    let mut helped = 0u64;
    loop {
        let records = setup.cache.map_or_else(Vec::new, |c| c.take_outbox());
        report_results(&mut results);
        comm.send(
            0,
            TAG_PR_IDLE,
            &encode_counts_and_records(&[sender.sent, helped], &records),
        );
        let Some(msg) = wait_for_forward_or_finish(&comm) else {
            break;
        };
        if msg.tag == TAG_FINISH {
            break;
        }
        match requests::decode(&msg.data, width * height) {
            Ok(decoded) => {
                for request in &decoded.requests {
                    let mut rng = Rng::new(seed, request.stream);
                    let value = integrator.ambient_for_request(request, &mut rng, &mut stats.rays);
                    let light = value * request.coefficient;
                    frame.add(request.pixel as usize, request.layer, light);
                    if journal {
                        results.push(RequestResult {
                            pixel: request.pixel,
                            layer: request.layer,
                            value: light,
                        });
                    }
                    // A helper shares its records as often as a PA does.
                    if let Some(cache) = setup.cache
                        && cache.outbox_len() >= sync
                    {
                        report_results(&mut results);
                        sync_records(&comm, cache, cache.take_outbox(), &mut received, &mut rejected);
                    }
                }
                // Refused requests are counted as computed (with nothing added) so the totals
                // still close; the refusal is reported in the statistics.
                helped += (decoded.requests.len() + decoded.rejected) as u64;
                rejected += decoded.rejected as u64;
            }
            Err(_) => rejected += 1,
        }
    }
    clock.stop(&mut stats);

    comm.send(
        0,
        TAG_IMAGE,
        &frame
            .to_floats()
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect::<Vec<u8>>(),
    );
    let mut report = rank_report(comm.rank(), "pr", &[stats.clone()], &[&counters], counters.idle_s());
    report.records_received = received;
    report.records_rejected = rejected;
    report.requests_sent = sender.sent;
    report.requests_computed = helped;
    report.wall_s = start.elapsed().as_secs_f64();
    comm.send(0, TAG_STATS, &serde_json::to_vec(&report).unwrap_or_default());
}

/// Waits for forwarded requests from any PA or the master's FINISH.
fn wait_for_forward_or_finish(comm: &Comm<'_>) -> Option<crate::parallel::comm::Received> {
    comm.receive_one_of(&[(Some(0), Some(TAG_FINISH)), (None, Some(TAG_FORWARDED))], None)
}
