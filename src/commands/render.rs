//! `icrender render`: load, trace, write the layered EXR, the preview and the statistics.

use super::{CommandError, CommandResult, warn};
use crate::cli::{RenderArgs, parse_tile};
use crate::image::framebuffer::Layer;
use crate::image::{metrics, output};
use crate::progress::Progress;
use crate::render::{RenderSettings, render, tiles};
use crate::scene::{MaterialOptions, Scene, SceneNeeds};
use crate::shading::{Integrator, ShadingOptions};
use crate::stats::{RenderStats, per_thread, ray_stats};
use crate::sys::image_io;
use crate::tracer::Tracer;
use glam::Vec3;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Largest image side we accept: beyond it framebuffers stop fitting in memory sensibly.
const MAX_IMAGE_SIDE: u32 = 65_536;

fn validate(args: &RenderArgs) -> Result<(), String> {
    if args.width == 0
        || args.height == 0
        || args.width > MAX_IMAGE_SIDE
        || args.height > MAX_IMAGE_SIDE
    {
        return Err(format!(
            "image size -x {} -y {} must be between 1 and {MAX_IMAGE_SIDE}",
            args.width, args.height
        ));
    }
    if args.spp == 0 {
        return Err("--spp must be at least 1".into());
    }
    if args.ambient_divisions == 0 {
        return Err("-ad must be at least 1".into());
    }
    if args.threads == Some(0) {
        return Err("--threads must be at least 1".into());
    }
    if let Some(av) = &args.ambient_value
        && av.iter().any(|v| !v.is_finite() || *v < 0.0)
    {
        return Err("-av values must be finite and not negative".into());
    }
    if !(args.specular_threshold.is_finite() && args.specular_threshold >= 0.0) {
        return Err("-st must be a finite, non-negative number".into());
    }
    if !(args.min_weight.is_finite() && args.min_weight >= 0.0) {
        return Err("-lw must be a finite, non-negative number".into());
    }
    parse_tile(&args.tile)?;
    Ok(())
}

/// The layers this scene can put light in; the others are not written.
pub fn producible_layers(needs: SceneNeeds, shading: &ShadingOptions) -> Vec<Layer> {
    let ambient_light = shading.ambient_bounces > 0 || shading.ambient_value.max_element() > 0.0;
    Layer::ALL
        .into_iter()
        .filter(|layer| match layer {
            Layer::Emission => needs.emission,
            Layer::Direct => needs.direct,
            Layer::Specular => needs.specular,
            Layer::Indirect => needs.diffuse && ambient_light,
        })
        .collect()
}

fn default_output(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "render".into());
    PathBuf::from(format!("{stem}.exr"))
}

/// The options as a Radiance-style line for the EXR header (and for giving rpict the same).
fn options_line(args: &RenderArgs, shading: &ShadingOptions) -> String {
    let av = shading.ambient_value;
    format!(
        "-x {} -y {} -ab {} -ad {} -av {} {} {} -st {} -lr {} -lw {} --light-samples {} --spp {} --seed {}{}",
        args.width,
        args.height,
        shading.ambient_bounces,
        shading.ambient_divisions,
        av.x,
        av.y,
        av.z,
        args.specular_threshold,
        shading.max_specular_depth,
        shading.min_weight,
        shading.light_samples,
        args.spp,
        args.seed,
        if args.lambertian { " --lambertian" } else { "" }
    )
}

pub fn run(args: &RenderArgs) -> CommandResult {
    let wall = Instant::now();
    validate(args)?;
    let output = args
        .output
        .clone()
        .unwrap_or_else(|| default_output(&args.scene));
    let preview = (!args.no_preview).then(|| output.with_extension("png"));
    // Fail before rendering, not after, if a result could not be written.
    for path in std::iter::once(&output)
        .chain(preview.iter())
        .chain(args.stats.iter())
    {
        output::check_writable(path)
            .map_err(|e| CommandError(format!("{}: {e}", path.display())))?;
    }
    let reference = match &args.reference {
        Some(path) => Some(
            image_io::read_image(path, &[])
                .map_err(|e| CommandError(format!("{}: {e}", path.display())))?,
        ),
        None => None,
    };

    let load_start = Instant::now();
    let material_options = MaterialOptions {
        specular_threshold: args.specular_threshold,
        lambertian: args.lambertian,
    };
    let scene = Scene::load(&args.scene, &material_options)?;
    let load_s = load_start.elapsed().as_secs_f64();
    for w in &scene.warnings {
        warn(&format!("{}: {w}", args.scene.display()));
    }
    let shading = ShadingOptions {
        ambient_bounces: args.ambient_bounces,
        ambient_divisions: args.ambient_divisions,
        ambient_value: args
            .ambient_value
            .as_deref()
            .map_or(Vec3::ZERO, |v| Vec3::new(v[0], v[1], v[2])),
        max_specular_depth: args.max_specular_depth,
        min_weight: args.min_weight,
        light_samples: args.light_samples.max(1),
    };
    if !scene.has_lights() && shading.ambient_value.max_element() <= 0.0 {
        return Err(CommandError(format!(
            "{}: the scene has no light sources (no emissive material, no KHR_lights_punctual light); \
             it would render black (give -av for an ambient-only render)",
            args.scene.display()
        )));
    }

    let build_start = Instant::now();
    let tracer =
        Tracer::new(&scene).map_err(|e| CommandError(format!("{}: {e}", args.scene.display())))?;
    let build_s = build_start.elapsed().as_secs_f64();
    let view = super::view::choose_view(&scene, &tracer, &args.view, args.width, args.height)
        .map_err(|e| CommandError(format!("view: {e}")))?;
    let camera = view.camera(args.width, args.height);

    let (tile_width, tile_height) = parse_tile(&args.tile)?;
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let settings = RenderSettings {
        spp: args.spp,
        seed: args.seed,
        tile_width,
        tile_height,
        threads,
    };
    let integrator = Integrator::new(&scene, &tracer, &shading);
    let progress = Progress::new(
        tiles(args.width, args.height, tile_width, tile_height).len(),
        args.quiet,
    );
    let render_start = Instant::now();
    let (frame, thread_stats) = render(&integrator, &camera, &settings, &progress);
    let render_s = render_start.elapsed().as_secs_f64();

    let layers = producible_layers(scene.needs(), &shading);
    let (per_thread, total_rays) = per_thread(&thread_stats);
    let mut stats = RenderStats {
        version: env!("CARGO_PKG_VERSION"),
        scene: args.scene.display().to_string(),
        mode: "serial",
        width: args.width,
        height: args.height,
        spp: args.spp,
        threads,
        triangles: scene.triangle_count(),
        dropped_triangles: scene.dropped_triangles,
        load_s,
        build_s,
        render_s,
        wall_s: 0.0,
        rays: ray_stats(&total_rays),
        mrays_per_s: total_rays.total() as f64 / render_s.max(1e-9) / 1e6,
        nonfinite_dropped: total_rays.nonfinite,
        layers: layers.iter().map(|l| l.name()).collect(),
        per_thread,
    };
    if total_rays.nonfinite > 0 {
        warn(&format!(
            "{} non-finite contribution(s) were dropped",
            total_rays.nonfinite
        ));
    }
    stats.wall_s = wall.elapsed().as_secs_f64();
    let stats_json = serde_json::to_string(&stats)?;
    let command_line: Vec<String> = std::env::args().collect();
    let attributes = vec![
        (
            "Software".to_string(),
            format!("icrender {}", env!("CARGO_PKG_VERSION")),
        ),
        ("icrender/command".to_string(), command_line.join(" ")),
        (
            "icrender/scene".to_string(),
            args.scene.display().to_string(),
        ),
        ("icrender/options".to_string(), options_line(args, &shading)),
        ("icrender/view".to_string(), view.radiance_options()),
        ("icrender/mode".to_string(), "serial".to_string()),
        (
            "icrender/render_time_s".to_string(),
            format!("{render_s:.3}"),
        ),
        ("icrender/statistics".to_string(), stats_json.clone()),
    ];
    output::write_exr(&output, &frame, &layers, &attributes, args.half)
        .map_err(|e| CommandError(format!("{}: {e}", output.display())))?;
    if let Some(png) = &preview {
        output::write_preview(png, &frame)
            .map_err(|e| CommandError(format!("{}: {e}", png.display())))?;
    }
    if let Some(path) = &args.stats {
        output::write_atomically(path, |tmp| {
            std::fs::write(
                tmp,
                serde_json::to_string_pretty(&stats).map_err(|e| e.to_string())? + "\n",
            )
            .map_err(|e| e.to_string())
        })
        .map_err(|e| CommandError(format!("{}: {e}", path.display())))?;
    }
    if !args.quiet {
        eprintln!(
            "icrender: {}x{} in {:.2} s ({:.1} Mrays/s, {} threads) -> {}",
            args.width,
            args.height,
            render_s,
            stats.mrays_per_s,
            threads,
            output.display()
        );
    }
    if let (Some(reference), Some(path)) = (&reference, &args.reference) {
        let written = image_io::read_image(&output, &[])
            .map_err(|e| CommandError(format!("{}: {e}", output.display())))?;
        let errors = metrics::compare(&written, reference)
            .map_err(|e| CommandError(format!("{}: {e}", path.display())))?;
        for e in &errors {
            println!(
                "error {:<10} rmse {:.6e}  relmse {:.6e}  time {:.3} s",
                e.layer, e.rmse, e.rel_mse, render_s
            );
        }
    }
    Ok(())
}
