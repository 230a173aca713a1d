//! The data layers a compositor and a denoiser read beside the light: what the camera rays
//! hit, not what light they carry. All come from the hits the beauty's own camera samples
//! make (no extra rays):
//!
//! - `albedo`: the reflectance (diffuse albedo, plus the specular reflectance of glossy lobes)
//!   of the first surface that is not a perfect mirror, following mirror reflections and
//!   transparency the way the integrator does (as Open Image Denoise recommends; a mirror's
//!   specular colour and a surface's opacity weigh what is seen through them), averaged over
//!   the pixel's samples like the beauty (box filter). Samples that hit nothing add 0.
//! - `normal`: the world-space unit shading normal at the first hit, turned towards the camera
//!   (the side the ray came from), averaged like the beauty (so an edge pixel's normal is
//!   shorter than 1; a pixel that sees nothing is 0).
//! - `depth`: distance from the camera along the view axis (the camera's forward direction,
//!   not along the ray) of the nearest first hit among the pixel's samples, in scene units; a
//!   depth is never averaged across an edge into a distance where nothing is. `FAR_DEPTH` where
//!   no sample hits anything.
//! - `position`: world-space point of that nearest first hit (0 where nothing is hit).
//! - Cryptomatte object and material IDs (`cryptomatte`).

use super::cryptomatte::{self, Entry, Ranks};
use glam::Vec3;

/// Depth where nothing is hit: finite (no Inf may reach a file), far beyond any scene (no
/// coordinate exceeds `scene::MAX_COORDINATE` = 1e15), and exactly representable in half.
pub const FAR_DEPTH: f32 = 1e30;

/// A pixel's data layers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelData {
    pub albedo: Vec3,
    pub normal: Vec3,
    pub depth: f32,
    pub position: Vec3,
    pub object: Ranks,
    pub material: Ranks,
    /// How noisy the pixel's light layers are (`render::noise`): what `--denoise` weighs its
    /// filter's output by. Not written as a layer.
    pub noise: LayerNoise,
}

/// The variance of each noisy layer's pixel value (its luminance), from the pixel's samples:
/// direct, specular, indirect. With a single sample only the direct light's, from its shadow
/// rays (`render::noise`); zero where nothing measured it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LayerNoise {
    pub direct: f32,
    pub specular: f32,
    pub indirect: f32,
}

impl LayerNoise {
    fn as_array(&self) -> [f32; 3] {
        [self.direct, self.specular, self.indirect]
    }

    fn from_array([direct, specular, indirect]: [f32; 3]) -> LayerNoise {
        LayerNoise {
            direct,
            specular,
            indirect,
        }
    }
}

impl PixelData {
    /// The share of the pixel's samples that hit a surface: 0 where none did (its depth is
    /// `FAR_DEPTH`), else the object ranks' coverage (at most 1; a pixel seeing more objects
    /// than the ranks hold reads a little less).
    pub fn covered(&self) -> f32 {
        if self.depth >= FAR_DEPTH {
            return 0.0;
        }
        self.object.iter().map(|e| e.coverage).sum::<f32>().min(1.0)
    }
}

impl Default for PixelData {
    fn default() -> Self {
        PixelData {
            albedo: Vec3::ZERO,
            normal: Vec3::ZERO,
            depth: FAR_DEPTH,
            position: Vec3::ZERO,
            object: Ranks::default(),
            material: Ranks::default(),
            noise: LayerNoise::default(),
        }
    }
}

/// Floats (4-byte values) of one pixel's data: albedo, normal, depth, position, the layers'
/// noise, and an ID and a coverage per rank of both Cryptomatte types.
pub const DATA_VALUES: usize = RANKS_AT + 4 * cryptomatte::RANKS;

/// Where the Cryptomatte ranks start among a pixel's data values.
const RANKS_AT: usize = 13;

impl PixelData {
    /// The data of two partial frames as one (component mode's ranks, a reference's passes):
    /// averaged layers add, the nearer hit wins, coverages of equal IDs add.
    pub fn merge(&self, other: &PixelData) -> PixelData {
        let nearer = if other.depth < self.depth { other } else { self };
        PixelData {
            albedo: self.albedo + other.albedo,
            normal: self.normal + other.normal,
            depth: nearer.depth,
            position: nearer.position,
            object: cryptomatte::merge(&self.object, &other.object),
            material: cryptomatte::merge(&self.material, &other.material),
            // Parts of one pixel's light from different ranks or passes are independent:
            // their variances add.
            noise: {
                let (a, b) = (self.noise.as_array(), other.noise.as_array());
                LayerNoise::from_array(std::array::from_fn(|i| a[i] + b[i]))
            },
        }
    }

    /// Scales what is averaged (the reference's mean of passes).
    pub fn scale(&mut self, factor: f32) {
        self.albedo *= factor;
        self.normal *= factor;
        for e in self.object.iter_mut().chain(self.material.iter_mut()) {
            e.coverage *= factor;
        }
        // The light scaled by `factor`, its variance by its square.
        self.noise = LayerNoise::from_array(self.noise.as_array().map(|v| v * factor * factor));
    }

    /// Whether the values could have come from a renderer: finite, non-negative albedo and
    /// depth, coverages in [0, 1] (with a rounding margin), IDs that are finite floats.
    pub fn healthy(&self) -> bool {
        let ranks_ok = |ranks: &Ranks| {
            ranks.iter().all(|e| {
                (e.id == 0 || f32::from_bits(e.id).is_normal())
                    && e.coverage.is_finite()
                    && (0.0..=1.001).contains(&e.coverage)
            })
        };
        self.albedo.is_finite()
            && self.albedo.min_element() >= 0.0
            && self.normal.is_finite()
            && self.depth.is_finite()
            && self.depth >= 0.0
            && self.position.is_finite()
            && ranks_ok(&self.object)
            && ranks_ok(&self.material)
            && self.noise.as_array().iter().all(|v| v.is_finite() && *v >= 0.0)
    }

    /// The values in a fixed order, IDs as their bits (for the wire and the journal).
    pub fn to_words(&self) -> [u32; DATA_VALUES] {
        let mut out = [0u32; DATA_VALUES];
        let floats = self
            .albedo
            .to_array()
            .into_iter()
            .chain(self.normal.to_array())
            .chain([self.depth])
            .chain(self.position.to_array())
            .chain(self.noise.as_array());
        for (slot, f) in out.iter_mut().zip(floats) {
            *slot = f.to_bits();
        }
        for (i, e) in self.object.iter().chain(self.material.iter()).enumerate() {
            out[RANKS_AT + 2 * i] = e.id;
            out[RANKS_AT + 1 + 2 * i] = e.coverage.to_bits();
        }
        out
    }

    /// The inverse of `to_words`.
    pub fn from_words(w: &[u32; DATA_VALUES]) -> PixelData {
        let f = |i: usize| f32::from_bits(w[i]);
        let v = |i: usize| Vec3::new(f(i), f(i + 1), f(i + 2));
        let ranks = |first: usize| -> Ranks {
            std::array::from_fn(|r| Entry {
                id: w[RANKS_AT + 2 * (first + r)],
                coverage: f(RANKS_AT + 1 + 2 * (first + r)),
            })
        };
        PixelData {
            albedo: v(0),
            normal: v(3),
            depth: f(6),
            position: v(7),
            object: ranks(0),
            material: ranks(cryptomatte::RANKS),
            noise: LayerNoise::from_array([f(10), f(11), f(12)]),
        }
    }
}

/// What one camera sample's first hit was (see `shading::SampleData`), in the form a pixel
/// accumulates: world-space point, view-axis depth, normal, the reflectance along its mirror
/// chain, and the Cryptomatte IDs of the surface.
#[derive(Clone, Copy, Debug)]
pub struct SampleHit {
    pub position: Vec3,
    pub depth: f32,
    pub normal: Vec3,
    pub object: u32,
    pub material: u32,
}

/// Sums a pixel's samples into its data: each sample of `samples` weighs 1 / samples (the box
/// filter the beauty uses).
pub struct PixelDataSum {
    weight: f32,
    data: PixelData,
    objects: Vec<Entry>,
    materials: Vec<Entry>,
}

impl PixelDataSum {
    pub fn new(samples: u32) -> PixelDataSum {
        PixelDataSum {
            weight: 1.0 / samples.max(1) as f32,
            data: PixelData::default(),
            objects: Vec::new(),
            materials: Vec::new(),
        }
    }

    /// Adds one sample: its albedo (0 when it hit nothing) and its first hit, if any.
    pub fn add(&mut self, albedo: Vec3, hit: Option<SampleHit>) {
        self.data.albedo += albedo * self.weight;
        let Some(hit) = hit else {
            return;
        };
        self.data.normal += hit.normal * self.weight;
        if hit.depth < self.data.depth {
            self.data.depth = hit.depth;
            self.data.position = hit.position;
        }
        let entry = |id| Entry {
            id,
            coverage: self.weight,
        };
        self.objects.push(entry(hit.object));
        self.materials.push(entry(hit.material));
    }

    /// The pixel's layers' noise, as its samples measured it.
    pub fn set_noise(&mut self, noise: LayerNoise) {
        self.data.noise = noise;
    }

    pub fn finish(mut self) -> PixelData {
        self.data.object = cryptomatte::rank(self.objects);
        self.data.material = cryptomatte::rank(self.materials);
        self.data
    }
}

/// Whether an EXR layer name is one of the data layers or a Cryptomatte rank layer (values
/// that are not light: no error metric or non-negativity applies to them).
pub fn is_data_layer(layer: &str) -> bool {
    let crypto_rank = |prefix: &str| {
        layer
            .strip_prefix(prefix)
            .is_some_and(|n| n.len() == 2 && n.bytes().all(|b| b.is_ascii_digit()))
    };
    matches!(layer, "albedo" | "normal" | "depth" | "position")
        || crypto_rank("CryptoObject")
        || crypto_rank("CryptoMaterial")
}

/// The data layers and Cryptomatte types a render may write (`--aovs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Aov {
    Albedo,
    Normal,
    Depth,
    Position,
    CryptoObject,
    CryptoMaterial,
}

impl Aov {
    pub const ALL: [Aov; 6] = [
        Aov::Albedo,
        Aov::Normal,
        Aov::Depth,
        Aov::Position,
        Aov::CryptoObject,
        Aov::CryptoMaterial,
    ];
    /// Written when `--aovs` is not given: all but `position` (a compositor rarely needs it,
    /// and it is three more full-float planes).
    pub const DEFAULT: [Aov; 5] = [
        Aov::Albedo,
        Aov::Normal,
        Aov::Depth,
        Aov::CryptoObject,
        Aov::CryptoMaterial,
    ];

    /// The name `--aovs` takes.
    pub fn name(self) -> &'static str {
        match self {
            Aov::Albedo => "albedo",
            Aov::Normal => "normal",
            Aov::Depth => "depth",
            Aov::Position => "position",
            Aov::CryptoObject => "crypto_object",
            Aov::CryptoMaterial => "crypto_material",
        }
    }

    /// Parses `--aovs`: a comma-separated list of names, `none`, or `all`.
    pub fn parse_list(text: &str) -> Result<Vec<Aov>, String> {
        match text.trim() {
            "none" | "" => return Ok(Vec::new()),
            "all" => return Ok(Aov::ALL.to_vec()),
            _ => {}
        }
        let mut out = Vec::new();
        for name in text.split(',').map(str::trim) {
            let aov = Aov::ALL.into_iter().find(|a| a.name() == name).ok_or_else(|| {
                let names: Vec<&str> = Aov::ALL.iter().map(|a| a.name()).collect();
                format!(
                    "--aovs: unknown layer '{name}' (known: {}, or none, or all)",
                    names.join(", ")
                )
            })?;
            if !out.contains(&aov) {
                out.push(aov);
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hit on object `n` (IDs made valid floats as the renderer's are).
    fn hit(depth: f32, n: u32) -> SampleHit {
        SampleHit {
            position: Vec3::splat(depth),
            depth,
            normal: Vec3::Z,
            object: id(n),
            material: id(n + 100),
        }
    }

    fn id(n: u32) -> u32 {
        cryptomatte::hash_to_float_bits(n)
    }

    #[test]
    fn samples_average_and_the_nearest_hit_gives_depth() {
        let mut sum = PixelDataSum::new(4);
        sum.add(Vec3::ONE, Some(hit(3.0, 1)));
        sum.add(Vec3::ONE, Some(hit(2.0, 1)));
        sum.add(Vec3::ONE, Some(hit(5.0, 2)));
        sum.add(Vec3::ZERO, None);
        let d = sum.finish();
        assert_eq!(d.albedo, Vec3::splat(0.75));
        assert_eq!(d.normal, Vec3::Z * 0.75);
        assert_eq!(d.depth, 2.0);
        assert_eq!(d.position, Vec3::splat(2.0));
        assert_eq!(
            d.object[0],
            Entry {
                id: id(1),
                coverage: 0.5
            }
        );
        assert_eq!(
            d.object[1],
            Entry {
                id: id(2),
                coverage: 0.25
            }
        );
        assert_eq!(d.material[0].id, id(101));
        let empty = PixelDataSum::new(2).finish();
        assert_eq!(empty.depth, FAR_DEPTH);
        assert!(empty.healthy() && d.healthy());
    }

    #[test]
    fn words_round_trip_and_merge_has_an_identity() {
        let mut sum = PixelDataSum::new(2);
        sum.add(Vec3::new(0.1, 0.2, 0.3), Some(hit(1.5, 7)));
        sum.add(Vec3::ZERO, Some(hit(2.5, 8)));
        sum.set_noise(LayerNoise {
            direct: 0.5,
            specular: 0.25,
            indirect: 2.0,
        });
        let d = sum.finish();
        assert_eq!(PixelData::from_words(&d.to_words()), d);
        assert_eq!(d.merge(&PixelData::default()), d);
        assert_eq!(PixelData::default().merge(&d), d);
    }

    #[test]
    fn independent_parts_add_their_noise_and_a_scaled_pixel_scales_it_squared() {
        let part = |v| PixelData {
            noise: LayerNoise {
                direct: v,
                specular: 2.0 * v,
                indirect: 3.0 * v,
            },
            ..Default::default()
        };
        let mut both = part(1.0).merge(&part(3.0));
        assert_eq!(both.noise, part(4.0).noise);
        // The mean of the two: a quarter of the sum's variance.
        both.scale(0.5);
        assert_eq!(both.noise, part(1.0).noise);
        let negative = part(-1.0);
        assert!(!negative.healthy(), "a negative variance is damage");
    }

    #[test]
    fn unhealthy_data_is_recognised() {
        let bad = [
            PixelData {
                depth: f32::INFINITY,
                ..Default::default()
            },
            PixelData {
                albedo: Vec3::new(-1.0, 0.0, 0.0),
                ..Default::default()
            },
            PixelData {
                object: [Entry { id: 1, coverage: 0.5 }; cryptomatte::RANKS],
                ..Default::default()
            },
        ];
        assert!(bad.iter().all(|d| !d.healthy()));
    }

    #[test]
    fn data_layers_are_told_from_light() {
        for l in [
            "albedo",
            "normal",
            "depth",
            "position",
            "CryptoObject00",
            "CryptoMaterial02",
        ] {
            assert!(is_data_layer(l), "{l}");
        }
        for l in ["", "direct", "indirect", "CryptoObject", "CryptoObjectAB", "ic_records"] {
            assert!(!is_data_layer(l), "{l}");
        }
    }

    #[test]
    fn aov_lists_parse() {
        assert_eq!(Aov::parse_list("none").unwrap(), vec![]);
        assert_eq!(Aov::parse_list("all").unwrap(), Aov::ALL.to_vec());
        assert_eq!(
            Aov::parse_list("depth, albedo,depth").unwrap(),
            vec![Aov::Depth, Aov::Albedo]
        );
        assert!(Aov::parse_list("albedo,colour").unwrap_err().contains("colour"));
    }
}
