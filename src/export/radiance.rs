//! The scene as a Radiance scene description (`.rad`), for rendering the same scene with
//! `oconv` + `rpict` and comparing.
//!
//! What is written, and how closely it follows icrender's own reading of the scene:
//!
//! * Geometry: every world-space triangle becomes a `polygon` with its three vertices in the
//!   same order. Radiance takes a polygon's front by the right-hand rule, as glTF does, so the
//!   side an emitter lights is the same in both renderers. Radiance's plastic and metal are
//!   shaded from both sides, as icrender shades every surface.
//! * Materials: one per icrender material, from its components averaged over the surface
//!   (see [`average_surface`]):
//!   - no specular part (Lambertian, or a weak specular part folded into the diffuse albedo,
//!     as icrender does below -st): `plastic` with the diffuse albedo, specularity 0, roughness 0;
//!   - an uncoloured specular part (dielectrics, grey metals): `plastic`, whose highlight is
//!     uncoloured: specularity s = the specular reflectance, colour = albedo / (1 - s), so
//!     Radiance's diffuse part colour x (1 - s) is the albedo;
//!   - a coloured specular part (coloured metals): `metal`, whose diffuse part is
//!     colour x (1 - s) and specular part colour x s: colour = albedo + specular reflectance,
//!     s = luminance(specular) / luminance(colour). Exact for pure metals (s = 1); a mixture
//!     of the two keeps the total reflectance but shares it between the parts by luminance;
//!   - roughness: Radiance's roughness is the RMS slope of Ward's Gaussian lobe, icrender's
//!     the GGX alpha (r^2 of glTF's perceptual roughness); the two are written as equal, which
//!     matches the lobes' width near the peak (GGX has the longer tail); a mirror is 0.
//!     Neither renderer has a Fresnel term in these materials;
//!   - emissive materials: `light` with the emitted radiance as is (icrender's emission is
//!     radiance, W/sr/m^2, as Radiance's). A Radiance `light` does not reflect, and its back is
//!     black; icrender's emitters also reflect with their albedo (a small difference);
//!   - partly transparent materials (alpha BLEND, MASK): a `mixfunc` of the material with
//!     `void` whose coefficient is the mean opacity, so that fraction of rays stops there.
//!   - textures: Radiance export drops them: a textured material gets the components averaged
//!     over the texture's area (uniform grid in texture space, each point through
//!     `Material::at`), i.e. the texture's mean colour times the factors. MASK cut-outs become
//!     their covered fraction.
//! * Punctual lights (KHR_lights_punctual; icrender treats intensity as W/sr, directional
//!   intensity as irradiance in W/m^2):
//!   - point: a `light` sphere of radius r = 1e-3 x scene size (bounding-box diagonal). Its
//!     projected area is pi r^2 from any side, so its intensity is I = L pi r^2: L = I / (pi r^2).
//!     Unlike icrender's point lights, the sphere can be seen: an eye ray that hits it shows L;
//!   - spot: a `spotlight` sphere of the same radius and L, pointing along the light. Radiance's
//!     spotlight has a hard edge, glTF's falls off as t^2 between the outer and inner cones
//!     (t linear in the cosine). The written cone keeps the emitted flux: the falloff band
//!     carries 2 pi (cos_i - cos_o) / 3, so the hard cone has cos = (2 cos_i + cos_o) / 3;
//!   - directional: a `source` of full angle 0.5 degrees towards the light, solid angle
//!     Omega = 2 pi (1 - cos(angle / 2)), radiance L = E / Omega so the irradiance matches;
//!   - glTF's `range` (a smooth cut-off icrender applies) has no Radiance equivalent: dropped.

use crate::image::output::write_atomically;
use crate::scene::light::{PunctualLight, luminance};
use crate::scene::material::{Material, SurfacePoint};
use crate::scene::texture::Texture;
use crate::scene::view::world_coordinate;
use crate::scene::{Scene, WorldMesh};
use crate::sys::scene_io::LightType;
use glam::{DVec3, Vec3};
use std::f64::consts::PI;
use std::io::{self, BufWriter, Write};
use std::path::Path;

/// Radius of the sphere standing for a point or spot light, as a fraction of the scene size.
pub const POINT_LIGHT_RADIUS_FRACTION: f32 = 1e-3;
/// Length of a spotlight's direction vector (Radiance's focal distance) relative to its radius.
const SPOT_FOCAL_FRACTION: f32 = 1e-3;
/// Full angle of the disc standing for a directional light, in degrees.
pub const DISTANT_SOURCE_ANGLE_DEG: f64 = 0.5;
/// Texture-space grid (n x n points) over which a textured material's components are averaged.
const TEXTURE_GRID: u32 = 256;
/// Specular reflectances whose channels differ by less than this are written as uncoloured.
const GREY_TOLERANCE: f32 = 1e-4;

/// What was written, for the command's report.
#[derive(Clone, Debug, Default)]
pub struct ExportSummary {
    pub materials: usize,
    pub polygons: usize,
    pub light_sources: usize,
    /// Approximations the user should know about (textures averaged, ranges dropped, ...).
    pub notes: Vec<String>,
}

/// Radius of the sphere standing for a point or spot light.
pub fn point_light_radius(scene_size: f32) -> f32 {
    POINT_LIGHT_RADIUS_FRACTION * scene_size
}

/// Radiance of a sphere of `radius` whose intensity (W/sr) is `intensity`: I = L pi r^2.
pub fn sphere_radiance_for_intensity(intensity: Vec3, radius: f32) -> Vec3 {
    let area = PI * radius as f64 * radius as f64;
    (intensity.as_dvec3() / area).as_vec3()
}

/// Solid angle of a distant disc of full angle `full_angle_deg`: 2 pi (1 - cos(half angle)),
/// written as 4 pi sin^2(half / 2) to stay exact for small angles.
pub fn distant_solid_angle(full_angle_deg: f64) -> f64 {
    let quarter = full_angle_deg.to_radians() * 0.25;
    4.0 * PI * quarter.sin() * quarter.sin()
}

/// Radiance of a distant disc of full angle `full_angle_deg` giving irradiance `irradiance` on
/// a surface facing it: E = L Omega.
pub fn distant_radiance_for_irradiance(irradiance: Vec3, full_angle_deg: f64) -> Vec3 {
    (irradiance.as_dvec3() / distant_solid_angle(full_angle_deg)).as_vec3()
}

/// Full angle in degrees of the hard-edged cone that emits the same flux as glTF's spot with
/// cosines `cos_inner` >= `cos_outer` and icrender's t^2 falloff between them.
pub fn spot_cone_angle_deg(cos_inner: f32, cos_outer: f32) -> f64 {
    let (ci, co) = (cos_inner as f64, cos_outer as f64);
    let cos_equal_flux = ((2.0 * ci.max(co) + co) / 3.0).clamp(-1.0, 1.0);
    2.0 * cos_equal_flux.acos().to_degrees()
}

/// A Radiance material (the primitive types this exporter writes).
#[derive(Clone, Debug, PartialEq)]
pub enum RadMaterial {
    Plastic {
        color: Vec3,
        specularity: f32,
        roughness: f32,
    },
    Metal {
        color: Vec3,
        specularity: f32,
        roughness: f32,
    },
    Light {
        radiance: Vec3,
    },
}

/// The material's components averaged over its surface: its factors if untextured, else the
/// mean of `Material::at` over a uniform grid of texture coordinates covering the texture once.
pub fn average_surface(material: &Material, textures: &[Texture]) -> SurfacePoint {
    let untextured = material.at(None, textures);
    if material.base_color_texture.and_then(|i| textures.get(i)).is_none() {
        return untextured;
    }
    let n = TEXTURE_GRID;
    let (mut diffuse, mut specular, mut opacity) = (DVec3::ZERO, DVec3::ZERO, 0.0f64);
    for j in 0..n {
        for i in 0..n {
            let uv = [(i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32];
            let p = material.at(Some(uv), textures);
            diffuse += p.diffuse.as_dvec3();
            specular += p.specular.as_dvec3();
            opacity += p.opacity as f64;
        }
    }
    let count = (n * n) as f64;
    SurfacePoint {
        diffuse: (diffuse / count).as_vec3(),
        specular: (specular / count).as_vec3(),
        alpha: untextured.alpha,
        opacity: (opacity / count) as f32,
    }
}

/// The Radiance material closest to icrender's material with components `p` (see the module
/// notes for the mapping).
pub fn radiance_material(material: &Material, p: &SurfacePoint) -> RadMaterial {
    if material.is_emissive() {
        return RadMaterial::Light {
            radiance: material.emission,
        };
    }
    let specular = p.specular.max(Vec3::ZERO);
    if specular.max_element() <= 0.0 {
        return RadMaterial::Plastic {
            color: p.diffuse,
            specularity: 0.0,
            roughness: 0.0,
        };
    }
    let roughness = p.alpha.max(0.0);
    if specular.max_element() - specular.min_element() <= GREY_TOLERANCE * specular.max_element() {
        let s = (specular.x + specular.y + specular.z) / 3.0;
        let color = if s < 1.0 {
            (p.diffuse / (1.0 - s)).min(Vec3::ONE)
        } else {
            Vec3::ZERO
        };
        return RadMaterial::Plastic {
            color,
            specularity: s.min(1.0),
            roughness,
        };
    }
    let color = (p.diffuse + specular).min(Vec3::ONE);
    let total = luminance(color);
    let s = if total > 0.0 {
        (luminance(specular) / total).clamp(0.0, 1.0)
    } else {
        1.0
    };
    RadMaterial::Metal {
        color,
        specularity: s,
        roughness,
    }
}

/// A Radiance identifier: no white space (nor anything a shell or a reader might trip on).
fn identifier(prefix: &str, name: &str) -> String {
    let clean: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect();
    if clean.is_empty() {
        prefix.to_string()
    } else {
        format!("{prefix}_{clean}")
    }
}

fn write_material(out: &mut impl Write, name: &str, m: &RadMaterial) -> io::Result<()> {
    match m {
        RadMaterial::Plastic {
            color: c,
            specularity,
            roughness,
        } => writeln!(
            out,
            "void plastic {name}\n0\n0\n5 {} {} {} {specularity} {roughness}\n",
            c.x, c.y, c.z
        ),
        RadMaterial::Metal {
            color: c,
            specularity,
            roughness,
        } => writeln!(
            out,
            "void metal {name}\n0\n0\n5 {} {} {} {specularity} {roughness}\n",
            c.x, c.y, c.z
        ),
        RadMaterial::Light { radiance: l } => writeln!(out, "void light {name}\n0\n0\n3 {} {} {}\n", l.x, l.y, l.z),
    }
}

/// Writes one punctual light; false if it gives no light (nothing written).
/// `origin`: the scene's tracing origin; what is written is in world coordinates.
fn write_punctual(
    out: &mut impl Write,
    index: usize,
    light: &PunctualLight,
    radius: f32,
    origin: DVec3,
) -> io::Result<bool> {
    if light.intensity.max_element() <= 0.0 {
        return Ok(false);
    }
    let name = identifier(&format!("light{index}"), &light.name);
    let p = origin + light.position.as_dvec3();
    let p = p.to_array().map(world_coordinate);
    match light.kind {
        LightType::Point | LightType::Spot => {
            let l = sphere_radiance_for_intensity(light.intensity, radius);
            if light.kind == LightType::Point {
                writeln!(out, "# point light: intensity {} W/sr = L pi r^2", light.intensity)?;
                writeln!(out, "void light {name}\n0\n0\n3 {} {} {}\n", l.x, l.y, l.z)?;
            } else {
                let angle = spot_cone_angle_deg(light.cos_inner, light.cos_outer);
                // The direction's length is Radiance's focal distance behind the centre, from
                // where its 1/d^2 falloff is measured: a thousandth of the (already tiny) radius
                // keeps that within 1e-6 relative of icrender's (a length of r made it 1% dim).
                let d = light.direction * (radius * SPOT_FOCAL_FRACTION);
                writeln!(
                    out,
                    "# spot light: intensity {} W/sr = L pi r^2, equal-flux hard cone",
                    light.intensity
                )?;
                writeln!(
                    out,
                    "void spotlight {name}\n0\n0\n7 {} {} {} {angle} {} {} {}\n",
                    l.x, l.y, l.z, d.x, d.y, d.z
                )?;
            }
            writeln!(
                out,
                "{name} sphere {name}.sphere\n0\n0\n4 {} {} {} {radius}\n",
                p[0], p[1], p[2]
            )?;
        }
        LightType::Directional => {
            let l = distant_radiance_for_irradiance(light.intensity, DISTANT_SOURCE_ANGLE_DEG);
            let towards = -light.direction;
            writeln!(
                out,
                "# directional light: irradiance {} W/m^2 = L x solid angle",
                light.intensity
            )?;
            writeln!(out, "void light {name}\n0\n0\n3 {} {} {}\n", l.x, l.y, l.z)?;
            writeln!(
                out,
                "{name} source {name}.source\n0\n0\n4 {} {} {} {DISTANT_SOURCE_ANGLE_DEG}\n",
                towards.x, towards.y, towards.z
            )?;
        }
    }
    Ok(true)
}

/// Writes the whole scene description to `out` (buffer it: big scenes give big files).
pub fn write_scene(scene: &Scene, out: &mut impl Write) -> io::Result<ExportSummary> {
    let mut summary = ExportSummary::default();
    writeln!(
        out,
        "# Radiance scene written by icrender {} export",
        env!("CARGO_PKG_VERSION")
    )?;
    writeln!(out, "# from {}", scene.path.display())?;
    writeln!(
        out,
        "# {} triangles, {} materials, {} punctual lights",
        scene.triangle_count(),
        scene.materials.len(),
        scene.punctual_lights.len()
    )?;
    writeln!(
        out,
        "# materials and lights are approximations of icrender's: see src/export/radiance.rs\n"
    )?;

    let mut names = Vec::with_capacity(scene.materials.len());
    for (index, material) in scene.materials.iter().enumerate() {
        let name = identifier(&format!("m{index}"), &material.name);
        let point = average_surface(material, &scene.textures);
        let rad = radiance_material(material, &point);
        if material.base_color_texture.is_some() {
            writeln!(out, "# {name}: base-colour texture dropped, its mean colour is used")?;
            summary.notes.push(format!(
                "material '{}': texture replaced by its mean colour",
                material.name
            ));
        }
        let transparent = point.opacity < 1.0 && !matches!(rad, RadMaterial::Light { .. });
        if transparent {
            let surface = format!("{name}.surface");
            write_material(out, &surface, &rad)?;
            writeln!(
                out,
                "# mean opacity {}: the rest of the rays pass through",
                point.opacity
            )?;
            writeln!(
                out,
                "void mixfunc {name}\n4 {surface} void A1 .\n0\n1 {}\n",
                point.opacity.max(0.0)
            )?;
        } else {
            write_material(out, &name, &rad)?;
        }
        names.push(name);
        summary.materials += 1;
    }

    let radius = point_light_radius(scene.size());
    for (index, light) in scene.punctual_lights.iter().enumerate() {
        if light.range > 0.0 && light.kind != LightType::Directional {
            summary.notes.push(format!(
                "light '{}': range {} ignored (Radiance has none)",
                light.name, light.range
            ));
        }
        if light.kind == LightType::Spot && light.cos_inner > light.cos_outer {
            summary.notes.push(format!(
                "light '{}': spot falloff written as a hard cone of equal flux",
                light.name
            ));
        }
        if write_punctual(out, index, light, radius, scene.origin)? {
            summary.light_sources += 1;
        } else {
            summary
                .notes
                .push(format!("light '{}': no intensity, not written", light.name));
        }
    }

    // Radiance gets every placement of a shared mesh as its own polygons (its `instance`
    // primitive needs octree files): the same triangles the renderer traces.
    let mut mesh_index = 0usize;
    let mut written: std::io::Result<()> = Ok(());
    scene.each_placed_mesh(|mesh| {
        if written.is_ok() {
            written = write_mesh(
                out,
                mesh_index,
                mesh,
                &names[mesh.material as usize],
                scene,
                &mut summary,
            );
        }
        mesh_index += 1;
    });
    written?;
    Ok(summary)
}

/// One placed mesh's triangles as Radiance polygons of `material`.
fn write_mesh(
    out: &mut impl Write,
    mesh_index: usize,
    mesh: &WorldMesh,
    material: &str,
    scene: &Scene,
    summary: &mut ExportSummary,
) -> std::io::Result<()> {
    writeln!(out, "# mesh {mesh_index}: {} triangles", mesh.indices.len())?;
    for (tri, &[a, b, c]) in mesh.indices.iter().enumerate() {
        let [pa, pb, pc] = [a, b, c].map(|i| {
            scene
                .to_world(Vec3::from(mesh.positions[i as usize]))
                .to_array()
                .map(world_coordinate)
        });
        writeln!(
            out,
            "{material} polygon t{mesh_index}.{tri}\n0\n0\n9 {} {} {}\n  {} {} {}\n  {} {} {}",
            pa[0], pa[1], pa[2], pb[0], pb[1], pb[2], pc[0], pc[1], pc[2]
        )?;
        summary.polygons += 1;
    }
    Ok(())
}

/// Writes the scene to `path` through a temporary file beside it (renamed when complete).
pub fn export(scene: &Scene, path: &Path) -> Result<ExportSummary, String> {
    let mut summary = None;
    write_atomically(path, |tmp| {
        let file = std::fs::File::create(tmp).map_err(|e| format!("cannot create: {e}"))?;
        let mut out = BufWriter::with_capacity(1 << 20, file);
        summary = Some(write_scene(scene, &mut out).map_err(|e| format!("cannot write: {e}"))?);
        let file = out.into_inner().map_err(|e| format!("cannot write: {}", e.error()))?;
        file.sync_all().map_err(|e| format!("cannot write: {e}"))
    })?;
    Ok(summary.unwrap_or_default())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::material::DEFAULT_SPECULAR_THRESHOLD;
    use crate::sys::scene_io::{AlphaMode, GltfMaterial};

    fn gltf_material(name: &str, base: [f32; 3], metallic: f32, roughness: f32, specular: f32) -> GltfMaterial {
        GltfMaterial {
            name: name.into(),
            base_color: [base[0], base[1], base[2], 1.0],
            base_color_texture: None,
            metallic,
            roughness,
            emissive: [0.0; 3],
            emissive_strength: 1.0,
            specular_factor: specular,
            specular_color: [1.0; 3],
            alpha_mode: AlphaMode::Opaque,
            alpha_cutoff: 0.5,
            double_sided: false,
        }
    }

    fn material(g: &GltfMaterial) -> Material {
        Material::from_gltf(g, DEFAULT_SPECULAR_THRESHOLD)
    }

    /// A unit quad in the z = 0 plane, counter-clockwise seen from +Z (front faces +Z).
    fn quad(material: u32) -> WorldMesh {
        WorldMesh {
            positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]],
            normals: None,
            texcoords: None,
            indices: vec![[0, 1, 2], [0, 2, 3]],
            material,
            object: 0,
        }
    }

    fn text(scene: &Scene) -> (String, ExportSummary) {
        let mut out = Vec::new();
        let summary = write_scene(scene, &mut out).unwrap();
        (String::from_utf8(out).unwrap(), summary)
    }

    /// One parsed primitive: modifier, type, identifier, string, integer and real arguments.
    #[derive(Debug)]
    struct Primitive {
        modifier: String,
        kind: String,
        id: String,
        strings: Vec<String>,
        reals: Vec<f64>,
    }

    /// A strict reader of the subset written: comments dropped, counts checked, every modifier
    /// defined before use, every identifier unique.
    fn parse(text: &str) -> Vec<Primitive> {
        let words: Vec<&str> = text
            .lines()
            .filter(|l| !l.trim_start().starts_with('#'))
            .flat_map(|l| l.split_whitespace())
            .collect();
        let mut it = words.into_iter();
        let mut out: Vec<Primitive> = Vec::new();
        let mut defined = std::collections::HashSet::new();
        while let Some(modifier) = it.next() {
            let kind = it.next().unwrap().to_string();
            let id = it.next().unwrap().to_string();
            let n: usize = it.next().unwrap().parse().unwrap();
            let strings: Vec<String> = (0..n).map(|_| it.next().unwrap().to_string()).collect();
            let ints: usize = it.next().unwrap().parse().unwrap();
            assert_eq!(ints, 0);
            let n: usize = it.next().unwrap().parse().unwrap();
            let reals: Vec<f64> = (0..n).map(|_| it.next().unwrap().parse().unwrap()).collect();
            assert!(
                modifier == "void" || defined.contains(modifier),
                "{modifier} used before definition"
            );
            for s in strings.iter().filter(|_| kind == "mixfunc").take(2) {
                assert!(
                    s == "void" || defined.contains(s.as_str()),
                    "{s} used before definition"
                );
            }
            assert!(defined.insert(id.clone()), "identifier {id} defined twice");
            out.push(Primitive {
                modifier: modifier.into(),
                kind,
                id,
                strings,
                reals,
            });
        }
        out
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-5 * a.abs().max(b.abs()).max(1e-12)
    }

    #[test]
    fn sphere_radiance_gives_the_intensity_back() {
        let intensity = Vec3::new(300.0, 150.0, 30.0);
        let r = point_light_radius(20.0);
        assert!((r - 0.02).abs() < 1e-7);
        let l = sphere_radiance_for_intensity(intensity, r);
        let back = l.as_dvec3() * PI * (r as f64).powi(2);
        assert!(close(back.x, 300.0) && close(back.y, 150.0) && close(back.z, 30.0));
    }

    #[test]
    fn distant_radiance_times_solid_angle_is_the_irradiance() {
        let omega = distant_solid_angle(DISTANT_SOURCE_ANGLE_DEG);
        // Small cone: close to pi (half angle)^2.
        let half = (DISTANT_SOURCE_ANGLE_DEG / 2.0).to_radians();
        assert!((omega / (PI * half * half) - 1.0).abs() < 1e-4);
        // Exact against the textbook form at a large angle, where cancellation is no issue.
        assert!(close(
            distant_solid_angle(120.0),
            2.0 * PI * (1.0 - 60f64.to_radians().cos())
        ));
        let l = distant_radiance_for_irradiance(Vec3::splat(2.0), DISTANT_SOURCE_ANGLE_DEG);
        assert!(close(l.x as f64 * omega, 2.0));
    }

    #[test]
    fn spot_cone_keeps_the_flux_of_the_smooth_falloff() {
        // Without a falloff band the cone is the outer cone.
        let c = 30f32.to_radians().cos();
        assert!((spot_cone_angle_deg(c, c) - 60.0).abs() < 1e-3);
        // With one: integrate icrender's t^2 falloff over the sphere numerically.
        let (ci, co) = (20f32.to_radians().cos() as f64, 40f32.to_radians().cos() as f64);
        let steps = 200_000;
        let mut flux = 0.0;
        for k in 0..steps {
            let cos = -1.0 + 2.0 * (k as f64 + 0.5) / steps as f64;
            let t = ((cos - co) / (ci - co)).clamp(0.0, 1.0);
            flux += t * t * 2.0 * PI * (2.0 / steps as f64);
        }
        let half = (spot_cone_angle_deg(ci as f32, co as f32) / 2.0).to_radians();
        let hard = 2.0 * PI * (1.0 - half.cos());
        assert!((hard / flux - 1.0).abs() < 1e-4, "{hard} vs {flux}");
        assert!(half.to_degrees() > 20.0 && half.to_degrees() < 40.0);
    }

    #[test]
    fn lambertian_quad_is_a_plastic_of_its_colour_with_the_same_winding() {
        let m = material(&gltf_material("white wall", [0.5, 0.25, 0.125], 0.0, 0.9, 0.0));
        let (text, summary) = text(&Scene::of_parts(vec![m], vec![quad(0)], vec![]));
        let prims = parse(&text);
        assert_eq!(summary.materials, 1);
        assert_eq!(summary.polygons, 2);
        let plastic = &prims[0];
        assert_eq!((plastic.modifier.as_str(), plastic.kind.as_str()), ("void", "plastic"));
        assert_eq!(plastic.id, "m0_white_wall");
        assert_eq!(plastic.reals, vec![0.5, 0.25, 0.125, 0.0, 0.0]);
        let polygons: Vec<&Primitive> = prims.iter().filter(|p| p.kind == "polygon").collect();
        assert_eq!(polygons.len(), 2);
        assert!(polygons.iter().all(|p| p.modifier == "m0_white_wall"));
        assert_eq!(polygons[0].reals, vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0]);
        assert_eq!(polygons[1].reals, vec![0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0]);
        // Right-hand rule on the written vertices: the front faces +Z as in the glTF.
        for p in polygons {
            let v = |i: usize| DVec3::new(p.reals[3 * i], p.reals[3 * i + 1], p.reals[3 * i + 2]);
            assert!((v(1) - v(0)).cross(v(2) - v(0)).z > 0.0);
        }
    }

    #[test]
    fn weak_default_specular_is_folded_like_the_renderer_does() {
        // glTF's default 4 % dielectric, rough: icrender folds it into the diffuse albedo.
        let m = material(&gltf_material("wall", [0.5, 0.5, 0.5], 0.0, 0.99, 1.0));
        let p = average_surface(&m, &[]);
        match radiance_material(&m, &p) {
            RadMaterial::Plastic { color, specularity, .. } => {
                assert_eq!(specularity, 0.0);
                assert!((color - Vec3::splat(0.5 * 0.96 + 0.04)).abs().max_element() < 1e-6);
            }
            other => panic!("expected plastic, got {other:?}"),
        }
    }

    #[test]
    fn metals_and_glossy_dielectrics() {
        let gold = material(&gltf_material("gold", [1.0, 0.8, 0.3], 1.0, 0.3, 1.0));
        match radiance_material(&gold, &average_surface(&gold, &[])) {
            RadMaterial::Metal {
                color,
                specularity,
                roughness,
            } => {
                assert_eq!(color, Vec3::new(1.0, 0.8, 0.3));
                assert_eq!(specularity, 1.0);
                assert!((roughness - 0.09).abs() < 1e-6);
            }
            other => panic!("expected metal, got {other:?}"),
        }
        // A smooth dielectric traced with threshold 0: white 4 % highlight over the albedo.
        let varnish = Material::from_gltf(&gltf_material("varnish", [0.5, 0.2, 0.1], 0.0, 0.0, 1.0), 0.0);
        let p = average_surface(&varnish, &[]);
        match radiance_material(&varnish, &p) {
            RadMaterial::Plastic {
                color,
                specularity,
                roughness,
            } => {
                assert!((specularity - 0.04).abs() < 1e-6);
                assert_eq!(roughness, 0.0);
                // Radiance's diffuse part colour x (1 - s) is icrender's albedo.
                assert!((color * (1.0 - specularity) - p.diffuse).abs().max_element() < 1e-6);
            }
            other => panic!("expected plastic, got {other:?}"),
        }
    }

    #[test]
    fn emitter_is_a_light_of_its_radiance_facing_the_same_way() {
        let mut g = gltf_material("lamp", [0.8, 0.8, 0.8], 0.0, 1.0, 1.0);
        g.emissive = [1.0, 0.5, 0.25];
        g.emissive_strength = 17.0;
        let (text, _) = text(&Scene::of_parts(vec![material(&g)], vec![quad(0)], vec![]));
        let prims = parse(&text);
        assert_eq!(prims[0].kind, "light");
        assert_eq!(prims[0].reals, vec![17.0, 8.5, 4.25]);
        let first = prims.iter().find(|p| p.kind == "polygon").unwrap();
        assert_eq!(first.modifier, prims[0].id);
        assert_eq!(first.reals[3..6], [1.0, 0.0, 0.0]);
    }

    #[test]
    fn punctual_lights_and_transparency_parse_back() {
        let mut glass = gltf_material("glass", [0.9, 0.9, 0.9], 0.0, 1.0, 0.0);
        glass.alpha_mode = AlphaMode::Blend;
        glass.base_color[3] = 0.25;
        let light = |kind, name: &str| PunctualLight {
            name: name.into(),
            kind,
            intensity: Vec3::new(10.0, 10.0, 5.0),
            position: Vec3::new(0.5, 0.5, 2.0),
            direction: -Vec3::Z,
            range: 0.0,
            cos_inner: 0.9,
            cos_outer: 0.8,
        };
        let lights = vec![
            light(LightType::Point, "bulb"),
            light(LightType::Spot, "spot"),
            light(LightType::Directional, "sun"),
        ];
        let s = Scene::of_parts(vec![material(&glass)], vec![quad(0)], lights);
        let (text, summary) = text(&s);
        assert_eq!(summary.light_sources, 3);
        let prims = parse(&text);
        let mix = prims.iter().find(|p| p.kind == "mixfunc").unwrap();
        assert_eq!(mix.id, "m0_glass");
        assert_eq!(mix.strings, vec!["m0_glass.surface", "void", "A1", "."]);
        assert_eq!(mix.reals, vec![0.25]);
        let r = point_light_radius(s.size()) as f64;
        let spheres: Vec<&Primitive> = prims.iter().filter(|p| p.kind == "sphere").collect();
        assert_eq!(spheres.len(), 2);
        assert!(
            spheres
                .iter()
                .all(|p| close(p.reals[3], r) && p.reals[..3] == [0.5, 0.5, 2.0])
        );
        let bulb = prims.iter().find(|p| p.id == spheres[0].modifier).unwrap();
        assert!(close(bulb.reals[0] * PI * r * r, 10.0));
        let spot = prims.iter().find(|p| p.kind == "spotlight").unwrap();
        assert_eq!(spot.reals.len(), 7);
        assert!(spot.reals[6] < 0.0, "spot points down");
        // Radiance measures the falloff from a focus that far behind the centre: keep it tiny.
        let focal = DVec3::new(spot.reals[4], spot.reals[5], spot.reals[6]).length();
        assert!(focal > 0.0 && focal < 1e-2 * r);
        let source = prims.iter().find(|p| p.kind == "source").unwrap();
        assert_eq!(
            source.reals,
            vec![0.0, 0.0, 1.0, DISTANT_SOURCE_ANGLE_DEG],
            "points towards the sun"
        );
        let sun = prims.iter().find(|p| p.id == source.modifier).unwrap();
        assert!(close(sun.reals[2] * distant_solid_angle(DISTANT_SOURCE_ANGLE_DEG), 5.0));
    }

    #[test]
    fn export_writes_atomically_and_names_failures() {
        let dir = tempfile::tempdir().unwrap();
        let m = material(&gltf_material("wall", [0.5, 0.5, 0.5], 0.0, 1.0, 0.0));
        let s = Scene::of_parts(vec![m], vec![quad(0)], vec![]);
        let path = dir.path().join("scene.rad");
        let summary = export(&s, &path).unwrap();
        assert_eq!(summary.polygons, 2);
        assert_eq!(parse(&std::fs::read_to_string(&path).unwrap()).len(), 3);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary left");
        assert!(export(&s, &dir.path().join("missing/scene.rad")).is_err());
    }
}
