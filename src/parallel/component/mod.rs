//! The component-based parallel irradiance cache (Debattista, Santos & Chalmers 2006, section
//! 5): PR ranks render all but indirect diffuse light and send their cache misses as requests
//! to PA ranks; the master hands out tiles, relays records, gives idle PRs (and dry PAs, beyond
//! the paper) shares of the longest PA queue, and puts the PRs' tiles and the requests' results
//! (indirect light for a pixel) together into the image.

pub mod balancer;
pub mod ledger;
pub mod master;
pub mod order;
pub mod pa;
pub mod pr;

use crate::parallel::comm::Comm;
use crate::parallel::protocol::Message;
use crate::render::ThreadStats;
use crate::sampling::Rng;
use crate::shading::request::{AmbientRequest, RequestResult};
use crate::shading::{Integrator, Work};

/// Computes one request's indirect light (from the rank's cache or as a new record) times its
/// coefficient, as a result for the master to add to the request's pixel.
pub fn compute_request(
    integrator: &Integrator<'_>,
    request: &AmbientRequest,
    seed: u64,
    stats: &mut ThreadStats,
    results: &mut Vec<RequestResult>,
) {
    let mut rng = Rng::new(seed, request.stream);
    let mut work = Work::new(&mut stats.rays);
    work.sample.pixel = request.pixel;
    // The pixel's samples share the cache's value at its centre, as in the serial render.
    work.sample.centre_ray = request.centre_ray;
    let (pixel, layer) = (request.pixel, request.layer);
    let value = integrator.ambient_for_request(request, &mut rng, &mut work) * request.coefficient;
    results.push(RequestResult { pixel, layer, value });
}

/// Sends the results gathered so far to the master (before the message that counts them done).
pub fn send_results(comm: &Comm<'_>, results: &mut Vec<RequestResult>) {
    if !results.is_empty() {
        comm.send(0, &Message::Results(std::mem::take(results)));
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
    /// Too few ranks leave no PR (`check_layout` has said so already).
    pub fn choose(size: i32, pa: Option<u32>, needed: bool) -> Result<Roles, String> {
        let workers = size - 1;
        let count = match pa {
            _ if !needed => 0,
            Some(n) => n as i32,
            None => (workers / 2).max(1),
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

    /// Every worker a PR (no PA): for a final pass after a prepass, which leaves no request.
    pub fn every_worker_renders(self) -> Roles {
        let mut prs = self.pas;
        prs.extend(self.prs);
        Roles { pas: Vec::new(), prs }
    }

    /// The roles, each named before its ranks: "rank 0: master; PA: rank 1; PR: ranks 2, 3".
    pub fn describe(&self) -> String {
        let ranks = |what: &str, r: &[i32]| match r {
            [] => format!("no {what}"),
            [one] => format!("{what}: rank {one}"),
            many => format!(
                "{what}: ranks {}",
                many.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(", ")
            ),
        };
        let (pas, prs) = (ranks("PA", &self.pas), ranks("PR", &self.prs));
        format!("component mode: rank 0: master; {pas}; {prs}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_banner_names_each_role_before_its_ranks() {
        let roles = Roles::choose(4, None, true).unwrap();
        assert_eq!(
            roles.describe(),
            "component mode: rank 0: master; PA: rank 1; PR: ranks 2, 3"
        );
        let roles = Roles::choose(5, None, true).unwrap();
        assert_eq!(
            roles.describe(),
            "component mode: rank 0: master; PA: ranks 1, 2; PR: ranks 3, 4"
        );
        let roles = Roles::choose(3, None, false).unwrap();
        assert_eq!(
            roles.describe(),
            "component mode: rank 0: master; no PA; PR: ranks 1, 2"
        );
    }

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
        // After a prepass every worker renders.
        assert_eq!(
            Roles::choose(5, None, true).unwrap().every_worker_renders(),
            Roles {
                pas: vec![],
                prs: vec![1, 2, 3, 4]
            }
        );
        // Nothing for PAs to do: every worker renders.
        assert_eq!(
            Roles::choose(4, None, false).unwrap(),
            Roles {
                pas: vec![],
                prs: vec![1, 2, 3]
            }
        );
    }
}
