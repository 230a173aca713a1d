//! The indirect diffuse light of a pixel's eye paths, left for later: the component split of
//! the paper (section 5) inside one process. Once a prepass builds the record set, a pixel is
//! shaded in two steps: its eye paths are traced for emission, direct and specular light
//! (nothing of which reads the cache), and each point where they ask for L_a is kept as a
//! `DeferredIndirect`; the points are then looked up in the complete cache, in the order the
//! paths reached them, and added to the sample's layers.
//!
//! Every mode shades every pixel this way, so a pixel traced while the prepass was still
//! running (under mpirun, in the idle time at its rounds' barriers) and looked up after it is
//! bit for bit the pixel one process shades in one go.

use super::{Integrator, PathState, Work, sanitize_value};
use crate::image::components::Components;
use crate::sampling::Rng;
use crate::tracer::SurfaceHit;
use glam::Vec3;

/// The first random stream of the records that deferred lookups make where the complete set
/// leaves a gap (`Integrator::frozen`): past every stream a pixel's samples, its light strata
/// and the prepass's sites use (see `prepass::LATTICE_STREAM`). Lookup `q` of sample `s` takes
/// stream `GAP_STREAM + (s << 16 | q)`: its own, so a gap's record does not depend on when the
/// lookup is made.
const GAP_STREAM: u64 = 1 << 48;

/// A point on a sample's eye path whose indirect diffuse light is looked up later.
#[derive(Clone, Copy, Debug)]
pub struct DeferredIndirect {
    hit: SurfaceHit,
    state: PathState,
    /// What the point's value (irradiance over pi) is multiplied by to reach the sample: the
    /// diffuse albedo, the surface's opacity and the path's rippled jT.
    coefficient: Vec3,
}

impl DeferredIndirect {
    pub(super) fn new(hit: SurfaceHit, state: PathState, coefficient: Vec3) -> Self {
        DeferredIndirect {
            hit,
            state,
            coefficient,
        }
    }
}

impl Integrator<'_> {
    /// Adds the deferred lookups of sample `sample` to its `components`, in order: at a camera
    /// ray's own hit to the indirect layer, behind a specular bounce to the specular layer (as
    /// the path's other light there). `work` is the pixel's, with the sample's context.
    pub fn add_deferred(
        &self,
        seed: u64,
        sample: u32,
        lookups: &[DeferredIndirect],
        components: &mut Components,
        work: &mut Work<'_>,
    ) {
        for (q, lookup) in lookups.iter().enumerate() {
            let stream = GAP_STREAM + ((sample as u64) << 16 | q as u64);
            let mut rng = Rng::for_sample(seed, work.sample.pixel as u64, stream);
            let value = self.ambient_radiance(&lookup.hit, lookup.state, &mut rng, work);
            let light = sanitize_value(lookup.coefficient * value, work);
            if lookup.state.specular_depth == 0 {
                components.indirect += light;
            } else {
                components.specular += light;
            }
        }
    }
}
