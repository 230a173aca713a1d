//! A PA rank: owns indirect diffuse work. A communicating thread (the paper's communicator
//! process) queues the PRs' request buffers and carries out the master's forward orders; the
//! computing thread takes requests (grid pixels first, see `order`) and computes each into the
//! PA's own image (`compute_request`). Every --sync new records, and whenever its queue runs
//! dry, it syncs with the master, reporting its queue length and how many it has computed.

use super::order::RequestQueue;
use super::{compute_request, send_results};
use crate::irradiance::IrradianceCache;
use crate::parallel::comm::{Comm, Counters, kind};
use crate::parallel::protocol::{Kind, Message, Records, Requests};
use crate::parallel::{Intake, Setup, send_report};
use crate::render::{ThreadClock, ThreadStats};
use std::sync::atomic::AtomicU64;
use std::sync::atomic::Ordering::{AcqRel, Acquire, Relaxed};
use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

struct Queued {
    requests: RequestQueue,
    finish: bool,
    longest: usize,
}

/// What the communicating thread and the computing thread share.
struct Shared<'a> {
    /// The queue, and the signal that requests (or FINISH) came.
    queued: Mutex<Queued>,
    ready: Condvar,
    /// Requests handed to helpers, and requests (or whole batches) refused as malformed.
    forwarded: AtomicU64,
    rejected: AtomicU64,
    /// Nanoseconds spent decoding arriving request batches and queueing them.
    handling_ns: AtomicU64,
    /// Where the master's replies to this PA's statuses (the records it lacks) go. The PA does
    /// not wait for them (one that did spent its time polling MPI, as CPU outside L_a and as
    /// idle time): the communicating thread takes them in as they come, the computing thread
    /// what is still owed at the end. Promptly: a large reply goes by rendezvous, and the
    /// master's send blocks until this rank receives it.
    cache: Option<&'a IrradianceCache>,
    /// Statuses sent whose reply has not been taken in.
    pending: AtomicU64,
    intake: Intake,
}

impl Shared<'_> {
    fn lock(&self) -> MutexGuard<'_, Queued> {
        self.queued.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Waits (as idle time) for a request or FINISH; whether the PA is done (FINISH, nothing left).
    fn wait(&self, idle_ns: &AtomicU64) -> bool {
        let mut q = self.lock();
        let waited = Instant::now();
        while q.requests.is_empty() && !q.finish {
            q = self
                .ready
                .wait_timeout(q, Duration::from_millis(20))
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        idle_ns.fetch_add(waited.elapsed().as_nanos() as u64, Relaxed);
        q.requests.is_empty() && q.finish
    }

    fn take_reply(&self, records: Records) {
        self.pending.fetch_sub(1, AcqRel);
        if let Some(cache) = self.cache {
            self.intake.take(cache, records);
        }
    }
}

/// The communicating thread: requests in, forward orders out, the master's replies into the
/// cache, until FINISH. While the queue holds `bound` requests or more, no request batch is
/// taken in: the PRs' synchronous sends then wait (back-pressure). A share goes out on a thread
/// of its own, so this thread never waits in a send: a share too large to go eagerly waits for
/// its receiver, and two PAs ordered to feed each other each waited in its send for the other
/// (seen once in the paper bench: conference room, 4 workers, the job hung).
fn communicate(counters: &Counters, shared: &Shared<'_>, pixels: u32, bound: usize) {
    let comm = Comm::new(counters);
    // The master's messages (replies, forward orders, FINISH) through one filter for any tag,
    // so they are taken in the order they were sent: FINISH comes after every reply and order
    // the master sent before it. Filters per tag, tried in turn, took a FINISH while an earlier
    // forward order still waited, which was then never received (tests/mpi.rs, 1 run in many:
    // one message more sent than received).
    let filters = [
        (Some(0), None),
        kind(None, Kind::Requests),
        // A share of another PA's queue, when this one ran dry (see component::balancer).
        kind(None, Kind::Forwarded),
    ];
    std::thread::scope(|senders| {
        loop {
            let full = shared.lock().requests.len() >= bound;
            // Full: only the master's messages, looking again at the queue every few milliseconds.
            let (accepted, wait) = if full {
                (&filters[..1], Some(Duration::from_millis(2)))
            } else {
                (&filters[..], None)
            };
            let Some(msg) = comm.receive(accepted, wait) else {
                continue;
            };
            match msg.message {
                Ok(Message::RecordsDown { records, .. }) => shared.take_reply(records),
                Ok(Message::Requests(decoded)) | Ok(Message::Forwarded(decoded)) => {
                    let handling = Instant::now();
                    // Refused requests still count as done, so the master's totals close.
                    let (inside, outside): (Vec<_>, Vec<_>) =
                        decoded.requests.into_iter().partition(|r| r.pixel < pixels);
                    let refused = decoded.rejected + outside.len();
                    shared.rejected.fetch_add(refused as u64, Relaxed);
                    let mut q = shared.lock();
                    q.requests.extend(inside);
                    q.longest = q.longest.max(q.requests.len());
                    drop(q);
                    shared.ready.notify_one();
                    let spent = handling.elapsed().as_nanos() as u64;
                    shared.handling_ns.fetch_add(spent, Relaxed);
                }
                Ok(Message::ForwardOrder { to, count, to_pa }) => {
                    // A PR waits for its share, empty or not; a PA that ran dry does not, and an
                    // empty share sent to it could arrive after FINISH. The newest requests go
                    // (see RequestQueue::take_newest).
                    let share = shared.lock().requests.take_newest(count as usize);
                    shared.forwarded.fetch_add(share.len() as u64, Relaxed);
                    if !(to_pa && share.is_empty()) {
                        // Every share is received before the job ends (a PR waits for its own; a
                        // PA's are requests the master waits for), so the scope never waits on one.
                        let message = Message::Forwarded(Requests::from(share));
                        senders.spawn(move || Comm::new(counters).send(to as i32, &message));
                    }
                }
                Ok(Message::Finish) => {
                    shared.lock().finish = true;
                    shared.ready.notify_all();
                    break;
                }
                // A batch that cannot be read: counted, never trusted.
                Err(_) => {
                    shared.rejected.fetch_add(1, Relaxed);
                }
                // Nothing else comes to this thread (the initial records were taken before it
                // started, a heartbeat is noted by `receive`).
                Ok(_) => {}
            }
        }
    });
}

pub fn run(setup: &Setup<'_>) {
    let counters = Counters::default();
    let comm_counters = Counters::default();
    let comm = Comm::new(&counters);
    let (width, height) = (setup.job.camera.width, setup.job.camera.height);
    let cache = setup.cache();
    let shared = Shared {
        queued: Mutex::new(Queued {
            // The overture's grid orders the queue (see `order`; 0: arrival order). A PR makes
            // no records before its pixels (its misses go to the PAs): it renders the grid's
            // pixels first instead, so that their requests reach the PA first (`render_tile`).
            requests: RequestQueue::new(width, setup.job.settings.overture),
            finish: false,
            longest: 0,
        }),
        ready: Condvar::new(),
        forwarded: AtomicU64::new(0),
        rejected: AtomicU64::new(0),
        handling_ns: AtomicU64::new(0),
        cache,
        pending: AtomicU64::new(0),
        intake: Intake::default(),
    };

    if let Some(initial) = comm.receive(&[kind(Some(0), Kind::InitialRecords)], None)
        && let (Some(cache), Ok(Message::InitialRecords(batch))) = (cache, initial.message)
    {
        batch.records.into_iter().for_each(|r| cache.insert_shared(r));
    }

    let seed = setup.job_in.seed;
    let bound = setup.job_in.pa_queue.max(1) as usize;
    let mut stats = ThreadStats::default();
    let (mut computed, mut reported) = (0u64, u64::MAX);
    let mut queue_samples = Vec::new();
    let mut results = Vec::new();
    std::thread::scope(|scope| {
        let comm_thread = scope.spawn(|| communicate(&comm_counters, &shared, width * height, bound));
        let integrator = setup.integrator();
        let clock = ThreadClock::start();
        loop {
            let next = shared.lock().requests.pop();
            // The queue length to report: a sync every --sync new records, and before going idle,
            // when the master must know everything done so far (a forward order may also have
            // emptied the queue while a request was computed).
            let left = match next {
                Some(request) => {
                    compute_request(&integrator, &request, seed, &mut stats, &mut results);
                    computed += 1;
                    if cache.map_or(0, |c| c.outbox_len()) < setup.sync {
                        continue;
                    }
                    shared.lock().requests.len()
                }
                None if computed == reported => {
                    if shared.wait(&counters.idle_ns) {
                        break;
                    }
                    continue;
                }
                None => 0,
            };
            // The sync: new records, the queue length and the count of computed requests (for
            // the master's termination check); the results go first, as the status counts them
            // done, and the reply is not waited for (see `Shared`).
            send_results(&comm, &mut results);
            shared.pending.fetch_add(1, AcqRel);
            // Refused requests count as done: the PR counted them as sent.
            let (queue, done) = (left as u64, computed + shared.rejected.load(Relaxed));
            let records = Records::from(cache.map_or_else(Vec::new, |c| c.take_outbox()));
            comm.send(0, &Message::PaStatus { queue, done, records });
            queue_samples.push((setup.start.elapsed().as_secs_f64(), left as u32));
            reported = computed;
        }
        clock.stop(&mut stats);
        let _ = comm_thread.join();
    });
    // A status sent after FINISH (the last sync) still has its reply coming: the master answers
    // every status, also after FINISH.
    let down = [kind(Some(0), Kind::RecordsDown)];
    while shared.pending.load(Acquire) > 0
        && let Some(Ok(Message::RecordsDown { records, .. })) = comm.receive(&down, None).map(|r| r.message)
    {
        shared.take_reply(records);
    }

    let mut report = setup.report(&comm, "pa", vec![stats], &comm_counters);
    report.records_received = shared.intake.totals().0;
    report.records_rejected = shared.rejected.load(Relaxed);
    report.requests_computed = computed;
    report.requests_forwarded = shared.forwarded.load(Relaxed);
    report.request_handling_s = shared.handling_ns.load(Relaxed) as f64 * 1e-9;
    report.queue_lengths = queue_samples;
    report.queue_max = shared.lock().longest as u64;
    send_report(&comm, report);
}
