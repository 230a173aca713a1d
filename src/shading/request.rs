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
}

/// Light computed for one request made elsewhere: added to `layer` at `pixel`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RequestResult {
    pub pixel: u32,
    pub layer: Layer,
    pub value: Vec3,
}
