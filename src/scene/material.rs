//! glTF PBR materials mapped onto Radiance-style components.
//!
//! The mapping, per surface point (base colour C = baseColorFactor x texture, metallic m,
//! perceptual roughness r, KHR_materials_specular factor s and colour F):
//!
//! * dielectric reflectance at normal incidence  F0 = 0.04 * s * F   (glTF's default 4 %)
//! * specular reflectance   rho_s = m * C + (1 - m) * F0
//! * diffuse albedo         rho_d = (1 - m) * C * (1 - max(F0))      (energy left after F0)
//! * emission               L_e   = emissiveFactor * emissiveStrength (radiance, front side)
//! * glossy lobe roughness  alpha = r^2 (GGX), a mirror below alpha 1e-3
//!
//! Fresnel's angular variation is left out, as Radiance's plastic and metal leave it out.
//! Specular rays are traced only where they pay (Radiance's -st): when max(rho_s) of the
//! material's factors reaches the specular threshold and the lobe is not fully rough
//! (r < 1). Otherwise the specular reflectance is folded into the diffuse albedo as a
//! Lambertian term, so energy is kept and no specular ray is spent; this is what makes the
//! rough obj2gltf materials of the shared scenes (4 %, r >= 0.96) cost nothing extra.
//! A material with specularFactor 0 and metallic 0 is purely Lambertian: rho_d = C.
//!
//! Alpha: OPAQUE ignores alpha; MASK makes points with alpha < cutoff absent; BLEND lets the
//! fraction (1 - alpha) pass straight through as a specular transmission.

use super::texture::Texture;
use crate::sys::scene_io::{AlphaMode, GltfMaterial};
use glam::Vec3;

/// Default of Radiance's -st: below this specular reflectance no specular ray is traced.
pub const DEFAULT_SPECULAR_THRESHOLD: f32 = 0.15;
/// GGX alpha below which a lobe is treated as a perfect mirror.
const MIRROR_ALPHA: f32 = 1e-3;

#[derive(Clone, Debug)]
pub struct Material {
    pub name: String,
    base_color: Vec3,
    base_alpha: f32,
    pub base_color_texture: Option<usize>,
    metallic: f32,
    dielectric_f0: Vec3,
    pub alpha: f32,
    pub emission: Vec3,
    pub alpha_mode: AlphaMode,
    pub alpha_cutoff: f32,
    /// Whether specular rays are traced for this material (see the module notes).
    pub traces_specular: bool,
}

/// The components of a material at one surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub diffuse: Vec3,
    pub specular: Vec3,
    /// GGX alpha of the specular lobe; 0 for a mirror.
    pub alpha: f32,
    /// Fraction of light that interacts with the surface (1 opaque, <1 partly transparent).
    pub opacity: f32,
}

fn sanitize(v: f32, lo: f32, hi: f32, default: f32) -> f32 {
    if v.is_finite() { v.clamp(lo, hi) } else { default }
}

fn sanitize3(v: [f32; 3], hi: f32) -> Vec3 {
    Vec3::new(
        sanitize(v[0], 0.0, hi, 0.0),
        sanitize(v[1], 0.0, hi, 0.0),
        sanitize(v[2], 0.0, hi, 0.0),
    )
}

impl Material {
    /// glTF's default material (used by primitives without one): white, metallic 1,
    /// roughness 1, as the specification defines it.
    pub fn gltf_default() -> Material {
        Material::from_gltf(&Material::gltf_default_description(), DEFAULT_SPECULAR_THRESHOLD)
    }

    /// glTF's default material as a file would describe it (what `gltf_default` maps).
    pub fn gltf_default_description() -> GltfMaterial {
        GltfMaterial {
            name: "(default)".into(),
            base_color: [1.0; 4],
            base_color_texture: None,
            metallic: 1.0,
            roughness: 1.0,
            emissive: [0.0; 3],
            emissive_strength: 1.0,
            specular_factor: 1.0,
            specular_color: [1.0; 3],
            alpha_mode: AlphaMode::Opaque,
            alpha_cutoff: 0.5,
            double_sided: false,
        }
    }

    /// Maps a glTF material; out-of-range or non-finite factors are clamped to the valid range.
    pub fn from_gltf(m: &GltfMaterial, specular_threshold: f32) -> Material {
        let base_color = sanitize3([m.base_color[0], m.base_color[1], m.base_color[2]], 1.0);
        let base_alpha = sanitize(m.base_color[3], 0.0, 1.0, 1.0);
        let metallic = sanitize(m.metallic, 0.0, 1.0, 0.0);
        let roughness = sanitize(m.roughness, 0.0, 1.0, 1.0);
        let s = sanitize(m.specular_factor, 0.0, 1.0, 1.0);
        let dielectric_f0 = (0.04 * s * sanitize3(m.specular_color, 1.0 / 0.04)).min(Vec3::ONE);
        let strength = sanitize(m.emissive_strength, 0.0, f32::MAX, 1.0);
        let emission = sanitize3(m.emissive, f32::MAX) * strength;
        let emission = if emission.is_finite() { emission } else { Vec3::ZERO };
        let specular_at_factors = metallic * base_color + (1.0 - metallic) * dielectric_f0;
        let traces_specular = specular_at_factors.max_element() >= specular_threshold && roughness < 1.0;
        Material {
            name: m.name.clone(),
            base_color,
            base_alpha,
            base_color_texture: m.base_color_texture,
            metallic,
            dielectric_f0,
            alpha: roughness * roughness,
            emission,
            alpha_mode: m.alpha_mode,
            alpha_cutoff: sanitize(m.alpha_cutoff, 0.0, 1.0, 0.5),
            traces_specular,
        }
    }

    /// Every material becomes a two-sided Lambertian of its base colour (textures kept).
    pub fn make_lambertian(&mut self) {
        self.metallic = 0.0;
        self.dielectric_f0 = Vec3::ZERO;
        self.traces_specular = false;
    }

    pub fn is_emissive(&self) -> bool {
        self.emission.max_element() > 0.0
    }

    /// Whether any point of this material can let light through.
    pub fn may_be_transparent(&self) -> bool {
        match self.alpha_mode {
            AlphaMode::Opaque => false,
            AlphaMode::Mask | AlphaMode::Blend => self.base_alpha < 1.0 || self.base_color_texture.is_some(),
        }
    }

    /// Whether every point of it reflects only diffusely and lets no light through: what it
    /// sends back is its diffuse albedo times the light it receives, all of it (the last
    /// bounce's grid answers for such surfaces from the hit alone: `hemisphere_batch`).
    pub fn is_plain_diffuse(&self) -> bool {
        !self.traces_specular && !self.may_be_transparent()
    }

    /// Largest diffuse albedo any point can have (for telling whether a scene has diffuse
    /// surfaces at all).
    pub fn max_diffuse(&self) -> f32 {
        let probe = self.at_base(if self.base_color_texture.is_some() {
            Vec3::ONE
        } else {
            self.base_color
        });
        probe.diffuse.max_element()
    }

    /// The diffuse albedo of a plain diffuse material (`is_plain_diffuse`) where a hemisphere's
    /// cell ray meets it, its texture read over the ray's footprint as `Texture::sample_cell`
    /// reads it.
    pub fn cell_albedo(&self, uv: Option<[f32; 2]>, width: f32, textures: &[Texture]) -> Vec3 {
        let mut base = self.base_color;
        if let (Some(t), Some(uv)) = (self.texture(textures), uv) {
            base *= t.sample_cell(uv, width).truncate();
        }
        self.at_base(base).diffuse
    }

    /// Its base-colour texture among the scene's `textures`, if it has one that loaded.
    fn texture<'t>(&self, textures: &'t [Texture]) -> Option<&'t Texture> {
        self.base_color_texture.and_then(|i| textures.get(i))
    }

    fn at_base(&self, base: Vec3) -> SurfacePoint {
        let m = self.metallic;
        let f0 = self.dielectric_f0;
        let mut diffuse = (1.0 - m) * base * (1.0 - f0.max_element());
        let mut specular = m * base + (1.0 - m) * f0;
        if !self.traces_specular {
            diffuse += specular;
            specular = Vec3::ZERO;
        }
        let alpha = if self.alpha < MIRROR_ALPHA { 0.0 } else { self.alpha };
        SurfacePoint {
            diffuse: diffuse.min(Vec3::ONE),
            specular,
            alpha,
            opacity: 1.0,
        }
    }

    /// The material's components at a point with texture coordinates `uv`.
    pub fn at(&self, uv: Option<[f32; 2]>, textures: &[Texture]) -> SurfacePoint {
        self.over(uv, 0.0, textures)
    }

    /// The material's components averaged over a footprint `width` wide in texture
    /// coordinates around `uv` (`Texture::sample_footprint`; 0: at the point). An alpha mask
    /// is read at the point: averaged, its cut-outs would fill in or vanish.
    pub fn over(&self, uv: Option<[f32; 2]>, width: f32, textures: &[Texture]) -> SurfacePoint {
        let mut base = self.base_color;
        let mut alpha = self.base_alpha;
        if let (Some(t), Some(uv)) = (self.texture(textures), uv) {
            let texel = t.sample_footprint(uv, width);
            base *= texel.truncate();
            alpha *= if self.alpha_mode == AlphaMode::Mask && width > 0.0 {
                t.sample(uv).w
            } else {
                texel.w
            };
        }
        let mut point = self.at_base(base);
        point.opacity = match self.alpha_mode {
            AlphaMode::Opaque => 1.0,
            AlphaMode::Mask => {
                if alpha >= self.alpha_cutoff {
                    1.0
                } else {
                    0.0
                }
            }
            AlphaMode::Blend => alpha,
        };
        point
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gltf(metallic: f32, roughness: f32, specular_factor: f32) -> GltfMaterial {
        GltfMaterial {
            name: "m".into(),
            base_color: [0.5, 0.25, 0.125, 1.0],
            base_color_texture: None,
            metallic,
            roughness,
            emissive: [0.0; 3],
            emissive_strength: 1.0,
            specular_factor,
            specular_color: [1.0; 3],
            alpha_mode: AlphaMode::Opaque,
            alpha_cutoff: 0.5,
            double_sided: false,
        }
    }

    #[test]
    fn specular_factor_zero_and_dielectric_is_lambertian_with_base_colour() {
        let m = Material::from_gltf(&gltf(0.0, 0.2, 0.0), DEFAULT_SPECULAR_THRESHOLD);
        let p = m.at(None, &[]);
        assert!(!m.traces_specular);
        assert_eq!(p.specular, Vec3::ZERO);
        assert_eq!(p.diffuse, Vec3::new(0.5, 0.25, 0.125));
    }

    #[test]
    fn smooth_metal_is_a_mirror_of_its_base_colour() {
        let m = Material::from_gltf(&gltf(1.0, 0.0, 1.0), DEFAULT_SPECULAR_THRESHOLD);
        let p = m.at(None, &[]);
        assert!(m.traces_specular);
        assert_eq!(p.diffuse, Vec3::ZERO);
        assert_eq!(p.specular, Vec3::new(0.5, 0.25, 0.125));
        assert_eq!(p.alpha, 0.0);
    }

    #[test]
    fn weak_default_dielectric_specular_is_folded_into_diffuse() {
        // glTF's default 4 % is below the -st threshold: no specular rays, energy kept.
        let m = Material::from_gltf(&gltf(0.0, 0.5, 1.0), DEFAULT_SPECULAR_THRESHOLD);
        let p = m.at(None, &[]);
        assert!(!m.traces_specular);
        let expect = Vec3::new(0.5, 0.25, 0.125) * 0.96 + Vec3::splat(0.04);
        assert!((p.diffuse - expect).abs().max_element() < 1e-6);
        // With threshold 0 the same material traces a glossy lobe instead.
        let glossy = Material::from_gltf(&gltf(0.0, 0.5, 1.0), 0.0);
        assert!(glossy.traces_specular);
        assert!((glossy.at(None, &[]).specular - Vec3::splat(0.04)).abs().max_element() < 1e-6);
    }

    #[test]
    fn nonsense_factors_are_clamped() {
        let mut g = gltf(f32::NAN, -3.0, 7.0);
        g.base_color = [f32::INFINITY, -1.0, 2.0, f32::NAN];
        g.emissive = [f32::NAN, 1.0, -1.0];
        let m = Material::from_gltf(&g, DEFAULT_SPECULAR_THRESHOLD);
        let p = m.at(None, &[]);
        assert!(p.diffuse.is_finite() && p.specular.is_finite() && m.emission.is_finite());
        assert!(p.diffuse.min_element() >= 0.0 && p.diffuse.max_element() <= 1.0);
        assert_eq!(m.emission, Vec3::new(0.0, 1.0, 0.0));
    }
}
