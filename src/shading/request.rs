//! An indirect diffuse value that one process needs and another computes (the component
//! mode's PR -> PA request, paper section 5.2): where, on which surface, how it reaches the
//! pixel (the rippled coefficient jT times the diffuse albedo), and everything needed to
//! rebuild the shading point without re-tracing the eye path.

use crate::image::framebuffer::Layer;
use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AmbientRequest {
    /// Pixel index (y * width + x) the value is added to.
    pub pixel: u32,
    /// The layer it belongs in: `Indirect` at a primary hit, `Specular` behind specular bounces.
    pub layer: Layer,
    /// Depth along the specular path (limits further specular rays inside the computation).
    pub specular_depth: u32,
    pub position: Vec3,
    /// The triangle's normal by its winding, and the shading normal (turned to the viewer).
    pub geometric_normal: Vec3,
    pub normal: Vec3,
    /// The geometric normal turned to the side the ray came from.
    pub facing_normal: Vec3,
    /// Multiplies the computed value (irradiance over pi) into the pixel: product of jT along
    /// the specular path, opacity, diffuse albedo and the pixel sample's share.
    pub coefficient: Vec3,
    /// Scalar path weight, for -lw inside the computation.
    pub weight: f32,
    /// Direction of the ray that hit the point (kept for checks and rebuilding).
    pub direction: Vec3,
    /// Material of the surface hit.
    pub material: u32,
    /// Random stream for the computation, so results do not depend on who computes them.
    pub stream: u64,
    /// The camera ray through the pixel's centre (origin, direction) where the pixel's samples
    /// share the cache's irradiance (`PixelIrradiance`; a primary hit in a pixel of several
    /// samples); None: the point is looked up alone. A PA that looked up each of an edge
    /// pixel's samples at its own point made records where the serial render's samples share
    /// the centre's value (one PA: 1,115 records against the serial render's 1,032).
    pub centre_ray: Option<(Vec3, Vec3)>,
    /// The camera ray's distance to the point (the pixel sharing's same-plane tolerance).
    pub distance: f32,
}

/// Light computed for one request made elsewhere: added to `layer` at `pixel`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RequestResult {
    pub pixel: u32,
    pub layer: Layer,
    pub value: Vec3,
}

/// The paper's request buffer: the indirect diffuse values a PR's cache could not give,
/// gathered as its pixels render until they are sent to a PA (`--send` at a time).
#[derive(Debug, Default)]
pub struct RequestBuffer(std::sync::Mutex<Vec<AmbientRequest>>);

impl RequestBuffer {
    fn requests(&self) -> std::sync::MutexGuard<'_, Vec<AmbientRequest>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn push(&self, request: AmbientRequest) {
        self.requests().push(request);
    }

    pub fn len(&self) -> usize {
        self.requests().len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Everything buffered, leaving the buffer empty.
    pub fn take(&self) -> Vec<AmbientRequest> {
        std::mem::take(&mut *self.requests())
    }
}
