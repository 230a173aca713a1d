//! `icrender bench messages` under `mpirun -np 2`: what a message costs between two ranks, measured
//! the way the renderer sends (rsmpi, byte buffers, the same MPI transport), so the cluster
//! simulation (bench/icsim.py) can be fed the latency and bandwidth of a real link instead of a
//! link's nominal rate. Rank 0 sends, rank 1 echoes. A rank waits by probing and yielding the
//! processor, never pausing, so the figures are the link's and MPI's, not the renderer's polling
//! pauses (the simulation models those apart); and never spinning inside a blocking MPI call,
//! which on a machine with fewer cores than processes would measure the scheduler's time slice.

use mpi::traits::*;
use std::time::Instant;

/// The next message from `source`, waiting by probing and yielding.
fn receive_from(world: &impl Communicator, source: i32) -> Vec<u8> {
    loop {
        if let Some(message) = world.process_at_rank(source).immediate_matched_probe() {
            return message.matched_receive_vec::<u8>().0;
        }
        std::thread::yield_now();
    }
}

/// Round trips per message size: the median of these is kept.
const ROUND_TRIPS: usize = 21;

/// One size's measurement: the median time of a round trip (there and back) of `bytes`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    pub bytes: usize,
    pub round_trip_s: f64,
}

/// Latency (seconds) and bandwidth (bytes per second) of a one-way message, so that one way
/// takes latency + bytes / bandwidth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkCost {
    pub latency_s: f64,
    pub bandwidth: f64,
}

/// What `measure` found: round trips by size, and a stream of messages sent back to back
/// (`stream_bytes` in all, `stream_s` until the receiver's acknowledgement came back).
#[derive(Clone, Debug, PartialEq)]
pub struct Measurement {
    pub samples: Vec<Sample>,
    pub stream_bytes: usize,
    pub stream_s: f64,
}

/// Latency from the smallest message's half round trip (most of the renderer's messages are
/// small); bandwidth from the stream, the sustained rate, which a rate-capped link (a token
/// bucket) shows only once its burst allowance is spent: single messages pass at line speed.
/// None without samples or when the stream took no longer than one latency.
pub fn fit(m: &Measurement) -> Option<LinkCost> {
    let smallest = m.samples.iter().min_by_key(|s| s.bytes)?;
    let latency_s = smallest.round_trip_s / 2.0;
    let transfer_s = m.stream_s - 2.0 * latency_s;
    if m.stream_bytes == 0 || transfer_s <= 0.0 {
        return None;
    }
    Some(LinkCost {
        latency_s,
        bandwidth: m.stream_bytes as f64 / transfer_s,
    })
}

/// Measures round trips between ranks 0 and 1 for each size, then a stream of `stream_count`
/// messages of `stream_size` bytes from 0 to 1 with one acknowledgement at the end; the other
/// ranks (if any) wait. Returns the measurement on rank 0, None elsewhere.
pub fn measure(sizes: &[usize], stream_size: usize, stream_count: usize) -> Result<Option<Measurement>, String> {
    let Some(universe) = mpi::initialize() else {
        return Err("MPI could not be initialised".into());
    };
    let world = universe.world();
    if world.size() < 2 {
        return Err(format!(
            "bench messages needs 2 MPI ranks (mpirun -np 2 ...); got {}",
            world.size()
        ));
    }
    let rank = world.rank();
    let mut samples = Vec::new();
    for &bytes in sizes {
        let message = vec![0u8; bytes];
        let mut times = Vec::with_capacity(ROUND_TRIPS);
        // One round trip first to set the connection up, not timed.
        for trip in 0..=ROUND_TRIPS {
            match rank {
                0 => {
                    let start = Instant::now();
                    world.process_at_rank(1).send(&message[..]);
                    let echo = receive_from(&world, 1);
                    if echo.len() != bytes {
                        return Err(format!("echo of {bytes} bytes came back with {}", echo.len()));
                    }
                    if trip > 0 {
                        times.push(start.elapsed().as_secs_f64());
                    }
                }
                1 => {
                    let data = receive_from(&world, 0);
                    world.process_at_rank(0).send(&data[..]);
                }
                _ => {}
            }
        }
        if rank == 0 {
            times.sort_by(f64::total_cmp);
            samples.push(Sample {
                bytes,
                round_trip_s: times[times.len() / 2],
            });
        }
    }
    let chunk = vec![0u8; stream_size];
    let mut stream_s = 0.0;
    match rank {
        0 => {
            let start = Instant::now();
            for _ in 0..stream_count {
                world.process_at_rank(1).send(&chunk[..]);
            }
            receive_from(&world, 1);
            stream_s = start.elapsed().as_secs_f64();
        }
        1 => {
            for _ in 0..stream_count {
                receive_from(&world, 0);
            }
            world.process_at_rank(0).send(&[1u8][..]);
        }
        _ => {}
    }
    world.barrier();
    Ok((rank == 0).then_some(Measurement {
        samples,
        stream_bytes: stream_size * stream_count,
        stream_s,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn measured(latency: f64, bandwidth: f64) -> Measurement {
        Measurement {
            samples: [8usize, 1024, 8192]
                .iter()
                .map(|&bytes| Sample {
                    bytes,
                    round_trip_s: 2.0 * (latency + bytes as f64 / bandwidth),
                })
                .collect(),
            stream_bytes: 1 << 22,
            stream_s: 2.0 * latency + (1 << 22) as f64 / bandwidth,
        }
    }

    #[test]
    fn the_fit_recovers_latency_and_bandwidth() {
        let (latency, bandwidth) = (40e-6, 1.25e8);
        let cost = fit(&measured(latency, bandwidth)).expect("a fit");
        // The smallest message's own transfer time is in its latency: 8 bytes at 1.25e8 B/s.
        assert!((cost.latency_s - latency).abs() < 1e-7, "{cost:?}");
        assert!((cost.bandwidth / bandwidth - 1.0).abs() < 1e-3, "{cost:?}");
    }

    #[test]
    fn no_fit_without_samples_or_a_stream() {
        let mut m = measured(40e-6, 1.25e8);
        m.stream_s = 1e-6;
        assert_eq!(fit(&m), None);
        m.samples.clear();
        assert_eq!(fit(&m), None);
    }
}
