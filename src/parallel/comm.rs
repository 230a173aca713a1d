//! Point-to-point messages between ranks, counted (messages, bytes) and timed (idle), over the
//! `mpi` crate. Every wait (a receive, a send that waits for its receiver, a collective) polls
//! with a growing pause instead of blocking in MPI, because Open MPI's blocking calls spin (and
//! call sched_yield in a loop where ranks outnumber cores): a waiting rank would steal the core
//! from the rank it waits for. Open MPI 4 has no wait that sleeps until a message comes (its
//! poll-when-idle proposal was never merged), so a paused poll is the nearest thing to blocking.

pub use super::counters::Counters;
use super::liveness::Silence;
use super::protocol::{Kind, Message, ProtocolError, empty_requests};
use mpi::Tag;
use mpi::point_to_point::{Destination, MatchedReceiveVec, Source};
use mpi::request::{Request, Scope, StaticScope};
use mpi::topology::{Communicator, SimpleCommunicator};
use std::convert::Infallible;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Longest pause between polls: bounds the latency a waiting rank adds.
const MAX_PAUSE: Duration = Duration::from_micros(500);
/// The master's (rank 0's) longest pause. Every tile request and every cache sync is a round
/// trip through the master, and a worker waits for it; a master asleep for up to MAX_PAUSE
/// added ~0.25 ms to each, about half of a PR's time on a 16x16 tile. The master renders
/// nothing, so polling more often costs only its own processor.
const MASTER_MAX_PAUSE: Duration = Duration::from_micros(100);
/// A wait that has lasted this long is not a reply on its way but a rank with nothing to do
/// (a PR waiting for FINISH or a share, a PA for requests, a master between phases): it polls
/// every LONG_WAIT_PAUSE, since each poll is a round of system calls in MPI's progress engine.
/// Component mode, 4 ranks on 2 cores, Cornell box 512x512 -ab 2 -aa 0.1 -ad 1024, three runs:
/// system time 1.41-2.09 s -> 1.18-1.27 s, wall 2.66-3.27 s -> 2.53-2.83 s (centralised and
/// broadcast unchanged within noise).
const LONG_WAIT: Duration = Duration::from_millis(20);
const LONG_WAIT_PAUSE: Duration = Duration::from_millis(5);

/// The longest pause of a wait in a collective in the prepass: a long wait there is a round
/// whose slowest rank is still computing, and every rank's part moves only while its rank polls
/// (a large part goes by rendezvous), so the rank that comes last to a round would otherwise
/// wait up to LONG_WAIT_PAUSE for each of the round's collectives to move.
const COLLECTIVE_MAX_PAUSE: Duration = Duration::from_micros(200);

/// Whether the request in `pending` has completed (it is then gone); a request still in flight
/// stays there.
fn completed<'a, D: ?Sized, S: Scope<'a>>(pending: &mut Option<Request<'a, D, S>>) -> Option<()> {
    match pending.take()?.test() {
        Ok(_) => Some(()),
        Err(still) => {
            *pending = Some(still);
            None
        }
    }
}

/// A synchronous send in flight (see `Comm::send_marker`); it must be waited for.
pub struct Marker(Request<'static, [u8], StaticScope>);

/// A received message, or why its bytes could not be read.
#[derive(Debug)]
pub struct Envelope {
    pub source: i32,
    pub message: Result<Message, ProtocolError>,
}

/// Which messages a receive takes: from a rank (None: any) with a tag (None: any).
pub type Filter = (Option<i32>, Option<Tag>);

/// A filter for messages of one kind (thread 0's tag for the per-thread kinds).
pub fn kind(source: Option<i32>, kind: Kind) -> Filter {
    (source, Some(kind.tag()))
}

/// Every rank's host name, by rank, for the messages that name a rank.
pub struct Hosts(Vec<String>);

impl Hosts {
    /// The host of `rank` ("?" if there is no such rank).
    pub fn of(&self, rank: i32) -> &str {
        self.0.get(rank as usize).map_or("?", String::as_str)
    }
}

/// The world communicator, seen from one thread. Cheap to make; every thread makes its own
/// (the handle is not shared across threads).
pub struct Comm<'c> {
    world: SimpleCommunicator,
    pub counters: &'c Counters,
    max_pause: Duration,
}

impl<'c> Comm<'c> {
    pub fn new(counters: &'c Counters) -> Self {
        let world = SimpleCommunicator::world();
        let max_pause = if world.rank() == 0 { MASTER_MAX_PAUSE } else { MAX_PAUSE };
        Comm {
            world,
            counters,
            max_pause,
        }
    }

    pub fn rank(&self) -> i32 {
        self.world.rank()
    }

    pub fn size(&self) -> i32 {
        self.world.size()
    }

    /// Sends and waits until the message has left (at once for one small enough to go eagerly;
    /// a larger one waits for its receiver to take it, polling with pauses, not spinning).
    pub fn send(&self, dest: i32, message: &Message) {
        self.send_until(dest, message, None, || {
            unreachable!("a send without a limit never stalls")
        });
    }

    fn count_sent(&self, bytes: usize) {
        self.counters.messages_sent.fetch_add(1, Ordering::Relaxed);
        self.counters.bytes_sent.fetch_add(bytes as u64, Ordering::Relaxed);
    }

    /// Sends like `send`, but waits at most `limit` for the message to leave: one too large to
    /// go eagerly waits until its receiver takes it, and a receiver whose host is gone never
    /// does. Past the limit `stalled` is called, which ends the job (it cannot return): the
    /// send is still in flight and MPI owns `data` until it completes.
    pub fn send_within(&self, dest: i32, message: &Message, limit: Duration, stalled: impl FnOnce() -> Infallible) {
        self.send_until(dest, message, Some(limit), stalled);
    }

    fn send_until(&self, dest: i32, message: &Message, limit: Option<Duration>, stalled: impl FnOnce() -> Infallible) {
        let (tag, data) = (message.tag(), message.encode());
        let data = data.as_slice();
        mpi::request::scope(|scope| {
            let request = self
                .world
                .process_at_rank(dest)
                .immediate_send_with_tag(scope, data, tag);
            let mut pending = Some(request);
            let sent = self.poll_with_pauses(limit, || completed(&mut pending));
            if sent.is_none() {
                match stalled() {}
            }
        });
        self.count_sent(data.len());
    }

    /// Sends an empty request buffer as a marker, with a synchronous send: it completes only
    /// once the receiver has taken it in, and so (messages between two ranks keep their order)
    /// every request buffer sent before it. `wait_marker` waits for that.
    pub fn send_marker(&self, dest: i32) -> Marker {
        let (tag, marker) = (Kind::Requests.tag(), empty_requests());
        let request = self
            .world
            .process_at_rank(dest)
            .immediate_synchronous_send_with_tag(StaticScope, marker, tag);
        self.count_sent(marker.len());
        Marker(request)
    }

    /// Waits until the marker's receiver has taken it in, polling with pauses like `receive`
    /// rather than spinning in MPI.
    pub fn wait_marker(&self, marker: Marker) {
        let mut pending = Some(marker.0);
        self.poll_with_pauses(None, || completed(&mut pending));
    }

    /// Polls until `poll` gives a value or `limit` (None: never) has passed, sleeping between
    /// polls with pauses that double up to this rank's longest: a waiting rank neither spins
    /// (Open MPI's blocking calls do) nor sleeps long past what it waits for.
    fn poll_with_pauses<T>(&self, limit: Option<Duration>, mut poll: impl FnMut() -> Option<T>) -> Option<T> {
        let start = Instant::now();
        let mut pause = Duration::from_micros(5);
        loop {
            if let Some(value) = poll() {
                return Some(value);
            }
            if limit.is_some_and(|l| start.elapsed() >= l) {
                return None;
            }
            std::thread::sleep(pause);
            let cap = match start.elapsed() >= LONG_WAIT {
                true => LONG_WAIT_PAUSE,
                false => self.max_pause,
            };
            pause = (pause * 2).min(cap);
        }
    }

    /// A message with `tag` (any tag when None) from `source` (anyone when None), if one is
    /// waiting now.
    pub fn try_receive(&self, source: Option<i32>, tag: Option<Tag>) -> Option<Envelope> {
        let probe = match (source, tag) {
            (Some(s), Some(t)) => self.world.process_at_rank(s).immediate_matched_probe_with_tag(t),
            (Some(s), None) => self.world.process_at_rank(s).immediate_matched_probe(),
            (None, Some(t)) => self.world.any_process().immediate_matched_probe_with_tag(t),
            (None, None) => self.world.any_process().immediate_matched_probe(),
        };
        probe.map(|matched| {
            let (data, status) = matched.matched_receive_vec::<u8>();
            // Heartbeats are counted apart, whoever takes them in (see `liveness`).
            let counters = match super::liveness::counters() {
                Some(pulse) if status.tag() == Kind::Heartbeat.tag() => pulse,
                _ => self.counters,
            };
            counters.messages_received.fetch_add(1, Ordering::Relaxed);
            counters.bytes_received.fetch_add(data.len() as u64, Ordering::Relaxed);
            super::liveness::heard(status.source_rank());
            Envelope {
                source: status.source_rank(),
                message: Message::decode(status.tag(), &data),
            }
        })
    }

    /// Waits for the first message matching any of the filters, tried in order at every poll,
    /// pausing between polls; the wait counts as idle time. Gives up after `timeout` (None:
    /// never) and returns None. A heartbeat a filter for any tag takes is noted, not returned.
    pub fn receive(&self, filters: &[Filter], timeout: Option<Duration>) -> Option<Envelope> {
        let poll = || {
            filters
                .iter()
                .find_map(|&(source, tag)| self.try_receive(source, tag))
                .filter(|envelope| !matches!(envelope.message, Ok(Message::Heartbeat)))
        };
        if let Some(r) = poll() {
            return Some(r);
        }
        let start = Instant::now();
        let result = self.poll_with_pauses(timeout, poll);
        self.counters
            .idle_ns
            .fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        result
    }

    /// Like `receive`, for a master that must notice a lost rank: every second without
    /// a message it checks whether a rank `awaited` holds true for has been silent for `limit`
    /// (see `liveness`), and gives up with that rank if so.
    pub fn receive_live(
        &self,
        filters: &[Filter],
        limit: Duration,
        awaited: impl Fn(i32) -> bool,
    ) -> Result<Envelope, Silence> {
        loop {
            if let Some(envelope) = self.receive(filters, Some(limit.min(Duration::from_secs(1)))) {
                return Ok(envelope);
            }
            if let Some(silence) = super::liveness::lost(self.size(), limit, &awaited) {
                return Err(silence);
            }
        }
    }

    /// The ranks for which `member` holds, as a communicator of their own (ranked among
    /// themselves in their world order); None on the others. A collective: every rank calls it.
    pub fn split(&self, member: bool) -> Option<Comm<'c>> {
        use mpi::topology::Color;
        let color = if member {
            Color::with_value(0)
        } else {
            Color::undefined()
        };
        let sub = self.world.split_by_color(color)?;
        Some(Comm {
            world: sub,
            counters: self.counters,
            max_pause: self.max_pause,
        })
    }

    /// Every rank's host (MPI processor) name, by rank. A collective: every rank calls it.
    pub fn host_names(&self) -> Hosts {
        const LEN: usize = 64;
        let name = mpi::environment::processor_name().unwrap_or_else(|_| "?".into());
        let mut mine = [0u8; LEN];
        let bytes = name.as_bytes();
        mine[..bytes.len().min(LEN)].copy_from_slice(&bytes[..bytes.len().min(LEN)]);
        let mut all = vec![0u8; LEN * self.size() as usize];
        self.all_gather(&mine[..], &mut all[..]);
        Hosts(
            all.chunks_exact(LEN)
                .map(|c| String::from_utf8_lossy(&c[..c.iter().position(|&b| b == 0).unwrap_or(LEN)]).into_owned())
                .collect(),
        )
    }

    /// Waits until every rank has come here. A collective: every rank calls it.
    pub fn barrier(&self) {
        use mpi::collective::CommunicatorCollectives;
        let mut pending = Some(self.world.immediate_barrier());
        self.poll_with_pauses(None, || completed(&mut pending));
    }

    /// Every rank's flag, by rank. A collective: every rank calls it.
    pub fn all_flags(&self, flag: bool) -> Vec<bool> {
        let mut all = vec![0u8; self.size() as usize];
        self.all_gather(&[flag as u8][..], &mut all[..]);
        all.into_iter().map(|f| f != 0).collect()
    }

    /// Every rank's `mine`, by rank, into `all` (`mine`'s length times the ranks); waits with
    /// pauses, since ranks come to it at different times (one still building its scene).
    fn all_gather(&self, mine: &[u8], all: &mut [u8]) {
        use mpi::collective::CommunicatorCollectives;
        mpi::request::scope(|scope| {
            let mut pending = Some(self.world.immediate_all_gather_into(scope, mine, all));
            self.poll_with_pauses(None, || completed(&mut pending));
        });
    }

    /// Every rank's `mine`, by rank: a collective every rank calls with its own bytes (any
    /// length, empty included). The lengths go round first (MPI_Iallgather), then the bytes
    /// (MPI_Iallgatherv), so no rank relays another's through its own code: each rank's traffic
    /// grows with what all of them hold together, not with the ranks times that. Both are
    /// polled with pauses like every wait here (the time counts as idle). About once a second
    /// `watch` is called, which may end the job (a rank that can no longer come); it cannot
    /// give up the wait otherwise, since MPI owns the buffers of a collective in flight.
    /// Err (on every rank alike, from the lengths all of them see): the parts add up to more
    /// than one collective can carry (MPI's 32-bit counts).
    ///
    /// `fill` is work to do instead of pausing: it does a little (a fraction of a millisecond)
    /// and answers whether there was any; its time is not idle time.
    pub fn all_gather_bytes(
        &self,
        mine: &[u8],
        mut watch: impl FnMut(),
        mut fill: impl FnMut() -> bool,
    ) -> Result<Vec<Vec<u8>>, String> {
        use mpi::collective::CommunicatorCollectives;
        use mpi::datatype::PartitionMut;
        let start = Instant::now();
        let mut filled = Duration::ZERO;
        let mut wait = |pending: &mut dyn FnMut() -> Option<()>| {
            let mut watched = Instant::now();
            let mut pause = Duration::from_micros(5);
            while pending().is_none() {
                if watched.elapsed() >= Duration::from_secs(1) {
                    watch();
                    watched = Instant::now();
                }
                let filling = Instant::now();
                if fill() {
                    filled += filling.elapsed();
                    pause = Duration::from_micros(5);
                    continue;
                }
                std::thread::sleep(pause);
                pause = (pause * 2).min(COLLECTIVE_MAX_PAUSE);
            }
        };
        let own = [mine.len() as u64];
        let mut lengths = vec![0u64; self.size() as usize];
        mpi::request::scope(|scope| {
            let mut pending = Some(self.world.immediate_all_gather_into(scope, &own[..], &mut lengths[..]));
            wait(&mut || completed(&mut pending));
        });
        let total = lengths.iter().sum::<u64>();
        if total > mpi::Count::MAX as u64 {
            return Err(format!(
                "{total} bytes to gather in one collective, more than MPI's limit of {}",
                mpi::Count::MAX
            ));
        }
        let counts: Vec<mpi::Count> = lengths.iter().map(|&n| n as mpi::Count).collect();
        let displs: Vec<mpi::Count> = (counts.iter())
            .scan(0, |at: &mut mpi::Count, &n| {
                let here = *at;
                *at += n;
                Some(here)
            })
            .collect();
        let mut all = vec![0u8; total as usize];
        {
            let mut partition = PartitionMut::new(&mut all[..], counts, &displs[..]);
            mpi::request::scope(|scope| {
                let mut pending = Some(
                    self.world
                        .immediate_all_gather_varcount_into(scope, mine, &mut partition),
                );
                wait(&mut || completed(&mut pending));
            });
        }
        let idle = start.elapsed().saturating_sub(filled);
        self.counters
            .idle_ns
            .fetch_add(idle.as_nanos() as u64, Ordering::Relaxed);
        self.counters
            .filled_ns
            .fetch_add(filled.as_nanos() as u64, Ordering::Relaxed);
        // What this rank gave and took, counted as if it had sent its part to each other rank
        // and been sent each of theirs: the library relays parts by its own algorithm (a ring,
        // recursive doubling), which moves parts through ranks, but every algorithm delivers
        // each rank the others' parts, so over all ranks what is counted sent is what is
        // counted received, and is what the wire carries.
        let others = lengths.len() as u64 - 1;
        self.counters.messages_sent.fetch_add(others, Ordering::Relaxed);
        self.counters
            .bytes_sent
            .fetch_add(mine.len() as u64 * others, Ordering::Relaxed);
        self.counters.messages_received.fetch_add(others, Ordering::Relaxed);
        self.counters
            .bytes_received
            .fetch_add(total - mine.len() as u64, Ordering::Relaxed);
        let mut at = 0;
        Ok((lengths.iter())
            .map(|&n| {
                let part = all[at..at + n as usize].to_vec();
                at += n as usize;
                part
            })
            .collect())
    }

    /// Ends the whole job (every rank) with an error code.
    pub fn abort(&self, code: i32) -> ! {
        self.world.abort(code)
    }
}
