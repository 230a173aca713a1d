//! Error of an image against a reference: RMSE and relative MSE per layer.
//!
//! relMSE = mean over pixels and channels of (x - r)^2 / (r^2 + 0.01), the usual relative
//! error of rendering papers; the 0.01 keeps black reference pixels from dominating.

use crate::image::data::is_data_layer;
use crate::sys::image_io::ImageData;
use serde::Serialize;

pub const REL_EPSILON: f64 = 0.01;

#[derive(Clone, Debug, Serialize)]
pub struct LayerError {
    /// "composite" for the plain R G B channels, else the layer name.
    pub layer: String,
    pub rmse: f64,
    pub rel_mse: f64,
    pub mean: f64,
    pub reference_mean: f64,
}

/// Light layers present in an image: "" (the plain R, G, B) and every `name` with name.R/G/B
/// that is not a data layer (an albedo is no light, and Cryptomatte's R and B are IDs).
pub fn rgb_layers(image: &ImageData) -> Vec<String> {
    let mut layers = Vec::new();
    for (name, _) in &image.channels {
        let prefix = match name.rsplit_once('.') {
            Some((p, "R")) if !is_data_layer(p) => p.to_string(),
            None if name == "R" => String::new(),
            _ => continue,
        };
        let has = |c: &str| {
            let full = if prefix.is_empty() {
                c.to_string()
            } else {
                format!("{prefix}.{c}")
            };
            image.channel(&full).is_some()
        };
        if has("G") && has("B") && !layers.contains(&prefix) {
            layers.push(prefix);
        }
    }
    layers
}

/// The reference layer a layer of the image is measured against: a denoised layer
/// (`<layer>_denoised`, or `denoised` for the composite; see image/denoise.rs; files of earlier
/// builds named them `<layer>.denoised`) against the reference's own layer, every other layer
/// against the layer of the same name.
pub fn reference_layer(layer: &str) -> &str {
    match layer.strip_suffix("denoised") {
        Some("") => "",
        Some(base) => base.strip_suffix(['_', '.']).unwrap_or(layer),
        None => layer,
    }
}

fn planes<'a>(image: &'a ImageData, layer: &str) -> [&'a [f32]; 3] {
    ["R", "G", "B"].map(|c| {
        let name = if layer.is_empty() {
            c.to_string()
        } else {
            format!("{layer}.{c}")
        };
        image.channel(&name).unwrap_or(&[])
    })
}

/// Error of one layer of `image` against the same layer of `reference`.
pub fn layer_error(image: &ImageData, reference: &ImageData, layer: &str) -> LayerError {
    let (a, b) = (planes(image, layer), planes(reference, reference_layer(layer)));
    let (mut se, mut rel, mut sum_a, mut sum_b, mut n) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0usize);
    for c in 0..3 {
        for (&x, &r) in a[c].iter().zip(b[c]) {
            let (x, r) = (x as f64, r as f64);
            let d = x - r;
            se += d * d;
            rel += d * d / (r * r + REL_EPSILON);
            sum_a += x;
            sum_b += r;
            n += 1;
        }
    }
    let n = n.max(1) as f64;
    LayerError {
        layer: if layer.is_empty() {
            "composite".into()
        } else {
            layer.into()
        },
        rmse: (se / n).sqrt(),
        rel_mse: rel / n,
        mean: sum_a / n,
        reference_mean: sum_b / n,
    }
}

/// Errors of every RGB layer the two images share, composite first; a denoised layer counts
/// as shared when the reference has the layer it denoises.
pub fn compare(image: &ImageData, reference: &ImageData) -> Result<Vec<LayerError>, String> {
    if (image.width, image.height) != (reference.width, reference.height) {
        return Err(format!(
            "image sizes differ: {}x{} against {}x{}",
            image.width, image.height, reference.width, reference.height
        ));
    }
    let theirs = rgb_layers(reference);
    let shared: Vec<String> = rgb_layers(image)
        .into_iter()
        .filter(|l| theirs.iter().any(|t| t == reference_layer(l)))
        .collect();
    if shared.is_empty() {
        return Err("the images share no R/G/B layer".into());
    }
    Ok(shared.iter().map(|l| layer_error(image, reference, l)).collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(values: &[(&str, f32)]) -> ImageData {
        ImageData {
            width: 2,
            height: 1,
            window: crate::sys::image_io::Window::whole(2, 1),
            channels: values.iter().map(|(n, v)| (n.to_string(), vec![*v, *v])).collect(),
            attributes: vec![],
        }
    }

    #[test]
    fn rmse_and_relative_error_of_a_constant_offset() {
        let a = image(&[
            ("R", 1.5),
            ("G", 1.5),
            ("B", 1.5),
            ("direct.R", 0.0),
            ("direct.G", 0.0),
            ("direct.B", 0.0),
        ]);
        let b = image(&[
            ("R", 1.0),
            ("G", 1.0),
            ("B", 1.0),
            ("direct.R", 0.0),
            ("direct.G", 0.0),
            ("direct.B", 0.0),
        ]);
        let errors = compare(&a, &b).unwrap();
        assert_eq!(errors.len(), 2);
        // Data layers are not light: not compared.
        let with_data = |img: &ImageData| {
            let mut channels = img.channels.clone();
            for c in [
                "albedo.R",
                "albedo.G",
                "albedo.B",
                "CryptoObject00.R",
                "CryptoObject00.G",
                "CryptoObject00.B",
            ] {
                channels.push((c.to_string(), vec![0.5, 0.5]));
            }
            ImageData {
                channels,
                ..img.clone_for_test()
            }
        };
        assert_eq!(compare(&with_data(&a), &with_data(&b)).unwrap().len(), 2);
        assert_eq!(errors[0].layer, "composite");
        assert!((errors[0].rmse - 0.5).abs() < 1e-12);
        assert!((errors[0].rel_mse - 0.25 / 1.01).abs() < 1e-12);
        assert_eq!(errors[1].rmse, 0.0);
    }

    #[test]
    fn denoised_layers_are_measured_against_the_references_raw_layers() {
        assert_eq!(reference_layer("direct_denoised"), "direct");
        assert_eq!(reference_layer("direct.denoised"), "direct");
        assert_eq!(reference_layer("denoised"), "");
        assert_eq!(reference_layer("direct"), "direct");
        assert_eq!(reference_layer("notdenoised"), "notdenoised");
        let a = image(&[
            ("R", 1.0),
            ("G", 1.0),
            ("B", 1.0),
            ("denoised.R", 1.25),
            ("denoised.G", 1.25),
            ("denoised.B", 1.25),
            ("direct_denoised.R", 0.5),
            ("direct_denoised.G", 0.5),
            ("direct_denoised.B", 0.5),
            ("specular_denoised.R", 0.5),
            ("specular_denoised.G", 0.5),
            ("specular_denoised.B", 0.5),
        ]);
        let b = image(&[
            ("R", 1.0),
            ("G", 1.0),
            ("B", 1.0),
            ("direct.R", 0.0),
            ("direct.G", 0.0),
            ("direct.B", 0.0),
        ]);
        let errors = compare(&a, &b).unwrap();
        let names: Vec<&str> = errors.iter().map(|e| e.layer.as_str()).collect();
        assert_eq!(names, ["composite", "denoised", "direct_denoised"]);
        assert!((errors[1].rmse - 0.25).abs() < 1e-12);
        assert!((errors[2].rmse - 0.5).abs() < 1e-12);
        assert_eq!(errors[2].reference_mean, 0.0);
    }

    #[test]
    fn refuses_different_sizes() {
        let a = image(&[("R", 1.0), ("G", 1.0), ("B", 1.0)]);
        let mut b = a.clone_for_test();
        b.width = 1;
        assert!(compare(&a, &b).is_err());
    }

    impl ImageData {
        fn clone_for_test(&self) -> ImageData {
            ImageData {
                width: self.width,
                height: self.height,
                window: self.window,
                channels: self.channels.clone(),
                attributes: vec![],
            }
        }
    }
}
