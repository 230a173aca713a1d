//! The options that decide how each component is computed, gathered from the command line
//! once per job.

use glam::Vec3;

/// The options that decide how each component is computed (Radiance names where they exist).
#[derive(Clone, Debug)]
pub struct ShadingOptions {
    /// -ab: diffuse bounces.
    pub ambient_bounces: u32,
    /// -ad: hemisphere samples at the first diffuse bounce.
    pub ambient_divisions: u32,
    /// -av: radiance assumed past the last bounce.
    pub ambient_value: Vec3,
    /// -lr: longest specular path.
    pub max_specular_depth: u32,
    /// -lw: a specular path stops when its weight jT falls below this.
    pub min_weight: f32,
    /// Shadow rays to area emitters per shading point on the eye path.
    pub light_samples: u32,
    /// Area lights' unshadowed irradiance computed exactly (Lambert's formula) and the shadow
    /// rays used only for the share that gets through; false: plain sampling (unbiased, for
    /// references).
    pub analytic_direct: bool,
    /// Past a record's bounce (-ab 2 and more), each hemisphere ray continues as one path
    /// instead of looking up records of deeper levels (`--ic-deep paths`).
    pub deep_paths: bool,
    /// Those paths' last bounce reads the last bounce's grid where it has a mean
    /// (`--ic-deep grid`; `irradiance::last_bounce`).
    pub last_bounce_grid: bool,
}

impl Default for ShadingOptions {
    fn default() -> Self {
        ShadingOptions {
            ambient_bounces: 1,
            ambient_divisions: 512,
            ambient_value: Vec3::ZERO,
            max_specular_depth: 8,
            min_weight: 1e-3,
            light_samples: 1,
            analytic_direct: true,
            deep_paths: true,
            last_bounce_grid: false,
        }
    }
}
