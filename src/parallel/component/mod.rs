//! The component-based parallel irradiance cache (Debattista, Santos & Chalmers 2006, section
//! 5): PR ranks render everything except indirect diffuse light and send the cache misses as
//! requests to PA ranks, which own the indirect diffuse work; the master hands out tiles,
//! relays records, balances load by giving idle PRs (and PAs that ran dry, beyond the paper) a
//! share of the longest PA queue, and sums every rank's image at the end.

pub mod master;
pub mod order;
pub mod pa;
pub mod pr;
pub mod requests;

use crate::checkpoint::{RequestResult, encode_results};
use crate::image::framebuffer::FrameBuffer;
use crate::image::framebuffer::PixelValue;
use crate::irradiance::record::Record;
use crate::parallel::comm::Comm;
use crate::parallel::protocol::{
    Batch, ProtocolError, decode_batch, decode_work_request, encode_batch, encode_work_request,
};
use crate::sampling::Rng;
use crate::shading::request::AmbientRequest;
use crate::shading::{Integrator, RayCounts};
use mpi::Tag;

/// PR -> MC: give me a tile.
pub const TAG_PR_WORK_REQUEST: Tag = 20;
/// MC -> PR: a tile or none, with the records the PR lacks.
pub const TAG_PR_WORK: Tag = 21;
/// PR -> PA: a buffer of L_a requests.
pub const TAG_REQUESTS: Tag = 22;
/// PR -> MC: no tile left; my totals (requests sent, computed as a helper) and new records.
pub const TAG_PR_IDLE: Tag = 23;
/// PA -> MC: queue length, totals, new records; the MC answers with records the PA lacks.
pub const TAG_PA_STATUS: Tag = 24;
pub const TAG_PA_STATUS_REPLY: Tag = 25;
/// MC -> PA: hand this many queued requests to that PR (or PA, with FORWARD_TO_PA after them).
pub const TAG_FORWARD_ORDER: Tag = 26;
/// The third word of a forward order whose receiver is a PA: an empty share is not sent.
pub const FORWARD_TO_PA: u32 = 1;
/// PA -> PR: the forwarded requests (possibly none).
pub const TAG_FORWARDED: Tag = 27;
/// MC -> every worker: all requests are computed; send your image and statistics.
pub const TAG_FINISH: Tag = 28;
/// Worker -> MC: the rank's image, every layer.
pub const TAG_IMAGE: Tag = 29;
/// MC -> PR, answering every idle report: the records the PR lacks, so that a helping PR
/// works with a cache as fresh as the PAs' and does not repeat their records.
pub const TAG_PR_CATCH_UP: Tag = 30;
/// PR -> MC while helping: new records every --sync of them; answered by TAG_PR_CATCH_UP.
pub const TAG_PR_SYNC: Tag = 31;

/// With --checkpoint only: PA (or helping PR) -> MC, the indirect light computed for requests
/// since the last such message, sent before the sync that counts them, so the master's journal
/// holds every result of a finished render.
pub const TAG_RESULTS: Tag = 32;

/// With --checkpoint only, the PR's work request carries the tile it just finished: its pixels
/// (everything but the indirect light sent away) and how many requests it sent for it.
pub fn encode_tile_report(tile: u32, requests: u32, pixels: &[PixelValue]) -> Vec<u8> {
    // The general work request's layout, with the request count where a thread index goes.
    encode_work_request(requests, Some((tile, pixels)))
}

/// The finished tile of a work request, if it carries one: (tile, requests, pixels).
pub fn decode_tile_report(bytes: &[u8]) -> Result<Option<(u32, u32, Vec<PixelValue>)>, ProtocolError> {
    if bytes.is_empty() {
        return Ok(None);
    }
    match decode_work_request(bytes)? {
        (requests, Some((tile, pixels))) => Ok(Some((tile, requests, pixels))),
        (_, None) => Err(ProtocolError("a tile report without a tile".into())),
    }
}

/// Computes one request's indirect light (from the rank's cache or as a new record), adds it
/// times the request's coefficient to the rank's image at the request's pixel, and keeps it in
/// `results` for the master's --checkpoint journal when given.
pub fn compute_request(
    integrator: &Integrator<'_>,
    request: &AmbientRequest,
    seed: u64,
    counts: &mut RayCounts,
    frame: &mut FrameBuffer,
    results: Option<&mut Vec<RequestResult>>,
) {
    let mut rng = Rng::new(seed, request.stream);
    let light = integrator.ambient_for_request(request, &mut rng, counts) * request.coefficient;
    frame.add(request.pixel as usize, request.layer, light);
    if let Some(results) = results {
        results.push(RequestResult {
            pixel: request.pixel,
            layer: request.layer,
            value: light,
        });
    }
}

/// With --checkpoint: sends the results gathered since the last call to the master (before
/// the message that counts them as done), leaving `results` empty.
pub fn send_results(comm: &Comm<'_>, results: &mut Vec<RequestResult>) {
    if !results.is_empty() {
        comm.send(0, TAG_RESULTS, &encode_results(&std::mem::take(results)));
    }
}

/// The roles of the ranks: 0 is the master, then the PAs, then the PRs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Roles {
    pub pas: Vec<i32>,
    pub prs: Vec<i32>,
}

impl Roles {
    /// `pa`: the requested number of PAs (default half the workers, at least one); `needed`:
    /// whether the scene has indirect diffuse work at all (without it, every worker is a PR).
    pub fn choose(size: i32, pa: Option<u32>, needed: bool) -> Result<Roles, String> {
        let workers = size - 1;
        if workers < 1 {
            return Err(format!(
                "--mode component needs at least 2 MPI ranks (a master and a PR); got {size}"
            ));
        }
        let count = if !needed {
            0
        } else {
            match pa {
                Some(n) => n as i32,
                None => (workers / 2).max(1),
            }
        };
        if needed && count < 1 {
            return Err("--pa 0 leaves no PA to compute indirect diffuse light".into());
        }
        if count >= workers {
            return Err(format!(
                "{count} PA(s) on {workers} worker rank(s) leaves no PR to render: use fewer --pa or more ranks"
            ));
        }
        Ok(Roles {
            pas: (1..=count).collect(),
            prs: (count + 1..size).collect(),
        })
    }

    pub fn describe(&self) -> String {
        let list = |r: &[i32]| r.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(",");
        if self.pas.is_empty() {
            format!(
                "component mode: master on rank 0, {} PR(s) on ranks {}, no PA",
                self.prs.len(),
                list(&self.prs)
            )
        } else {
            format!(
                "component mode: master on rank 0, {} PA(s) on ranks {}, {} PR(s) on ranks {}",
                self.pas.len(),
                list(&self.pas),
                self.prs.len(),
                list(&self.prs)
            )
        }
    }
}

fn u64_at(bytes: &[u8], offset: usize) -> Result<u64, ProtocolError> {
    bytes
        .get(offset..offset + 8)
        .map(|b| u64::from_le_bytes(b.try_into().expect("8 bytes")))
        .ok_or_else(|| ProtocolError("message too short".into()))
}

/// Numbers followed by a record batch: the shape of the idle and status messages.
pub fn encode_counts_and_records(counts: &[u64], records: &[Record]) -> Vec<u8> {
    let mut out: Vec<u8> = counts.iter().flat_map(|c| c.to_le_bytes()).collect();
    out.extend(encode_batch(records, 0));
    out
}

pub fn decode_counts_and_records(bytes: &[u8], n: usize) -> Result<(Vec<u64>, Batch), ProtocolError> {
    let counts = (0..n).map(|i| u64_at(bytes, 8 * i)).collect::<Result<Vec<_>, _>>()?;
    Ok((counts, decode_batch(&bytes[8 * n..])?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roles_default_to_half_and_refuse_impossible_layouts() {
        assert_eq!(
            Roles::choose(5, None, true).unwrap(),
            Roles {
                pas: vec![1, 2],
                prs: vec![3, 4]
            }
        );
        assert_eq!(
            Roles::choose(4, None, true).unwrap(),
            Roles {
                pas: vec![1],
                prs: vec![2, 3]
            }
        );
        assert_eq!(
            Roles::choose(3, Some(1), true).unwrap(),
            Roles {
                pas: vec![1],
                prs: vec![2]
            }
        );
        assert!(Roles::choose(3, Some(2), true).is_err());
        assert!(Roles::choose(4, Some(0), true).is_err());
        assert!(Roles::choose(2, None, true).is_err());
        assert!(Roles::choose(1, None, true).is_err());
        // Nothing for PAs to do: every worker renders.
        assert_eq!(
            Roles::choose(4, None, false).unwrap(),
            Roles {
                pas: vec![],
                prs: vec![1, 2, 3]
            }
        );
    }

    #[test]
    fn tile_reports_round_trip() {
        assert!(decode_tile_report(&[]).unwrap().is_none());
        let pixels = vec![PixelValue::default(); 3];
        let (tile, requests, back) = decode_tile_report(&encode_tile_report(7, 11, &pixels))
            .unwrap()
            .unwrap();
        assert_eq!((tile, requests, back.len()), (7, 11, 3));
        assert!(decode_tile_report(&[1, 2, 3]).is_err());
        assert!(decode_tile_report(&11u32.to_le_bytes()).is_err());
    }

    #[test]
    fn counts_and_records_round_trip() {
        let bytes = encode_counts_and_records(&[3, 9], &[]);
        let (counts, batch) = decode_counts_and_records(&bytes, 2).unwrap();
        assert_eq!(counts, vec![3, 9]);
        assert!(batch.records.is_empty());
        assert!(decode_counts_and_records(&bytes[..5], 2).is_err());
    }
}
