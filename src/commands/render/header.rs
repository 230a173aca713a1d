//! What the EXR header says about a render, for the user who opens it: a command line that
//! renders the image again, the settings every part of one image shares (as `key value`
//! items), the data layers written and how the denoiser ran.

use crate::cli::{DenoiseQualityArg, RenderArgs, ViewArgs};
use crate::image::data::{Aov, FAR_DEPTH};
use crate::image::denoise;
use crate::image::{cryptomatte, output};
use crate::scene::Scene;

/// The options as a Radiance-style line for the EXR header (and for giving rpict the same).
pub fn options_line(args: &RenderArgs) -> String {
    format!(
        "-x {} -y {} {} -st {} -lr {} -lw {} --ic-metric {} \
         --light-samples {} --direct {} --spp {} --seed {} --ic-build {} --ic-deep {} --ic-blend {}{}{}{}{}{}",
        args.width,
        args.height,
        crate::job::ambient_options(args),
        args.specular_threshold,
        args.max_specular_depth,
        args.min_weight,
        value_name(&args.ic_metric),
        args.light_samples,
        match args.direct {
            crate::cli::DirectArg::Analytic => "analytic",
            crate::cli::DirectArg::Sampled => "sampled",
        },
        args.spp,
        args.seed,
        match crate::job::cache_build(args) {
            crate::cli::CacheBuildArg::Prepass => "prepass",
            crate::cli::CacheBuildArg::Progressive => "progressive",
        },
        match args.ic_deep {
            crate::cli::DeepArg::Paths => "paths",
            crate::cli::DeepArg::Records => "records",
            crate::cli::DeepArg::Grid => "grid",
        },
        args.ic_blend,
        if args.ic_min_pixels > 0.0 {
            format!(" --ic-min-pixels {}", args.ic_min_pixels)
        } else {
            String::new()
        },
        args.overture.map(|n| format!(" --overture {n}")).unwrap_or_default(),
        if args.lambertian { " --lambertian" } else { "" },
        if args.flatten { " --flatten" } else { "" },
        if args.passes > 1 {
            format!(" --passes {}", args.passes)
        } else {
            String::new()
        }
    )
}

/// The items of an options line (`-x 64 -ab 1 -av 0 0 0 ...`), one per option with its
/// values: a new item starts at every token that is an option name (a dash and a letter, or
/// two dashes), not at a negative number.
fn option_items(line: &str) -> Vec<String> {
    let mut items: Vec<String> = Vec::new();
    for token in line.split_whitespace() {
        let name = token.starts_with("--")
            || (token.starts_with('-') && token[1..].starts_with(|c: char| c.is_ascii_alphabetic()));
        match items.last_mut() {
            Some(item) if !name => {
                item.push(' ');
                item.push_str(token);
            }
            _ => items.push(token.to_string()),
        }
    }
    items
}

/// What every part of one image must share (`icrender merge` refuses parts that differ),
/// `; `-separated so that merge can name the first setting that differs: the checkpoint's
/// key (scene, options, tiles, view) and what changes the file's layers. Not in it: --region,
/// the outputs, -af (its own settings check applies), --progress, --quiet, --stats,
/// --threads, --checkpoint.
pub fn part_settings(args: &RenderArgs) -> String {
    let scene = std::fs::canonicalize(&args.scene).unwrap_or_else(|_| args.scene.clone());
    let mut items = vec![format!("scene {}", scene.display())];
    items.extend(option_items(&options_line(args)));
    let aovs: Vec<&str> = args.aovs().iter().map(|a| a.name()).collect();
    items.extend([
        format!("--emission-samples {}", args.emission_samples),
        format!("--edge-samples {}", args.edge_samples),
        format!("--tile {}", args.tile),
        format!("view {}", view_text(&args.view)),
        format!(
            "--aovs {}",
            if aovs.is_empty() {
                "none".to_string()
            } else {
                aovs.join(",")
            }
        ),
        format!("--half {}", args.half),
        format!("--compression {}", args.compression.name()),
        format!("--ic-records {}", args.ic_records),
        format!("--denoise {}", if args.denoise { quality_name(args) } else { "off" }),
    ]);
    items.join("; ")
}

/// The header's account of the data layers: which were written (`icrender/aovs`, with what a
/// depth means where nothing is hit) and each Cryptomatte type's attributes and manifest.
pub fn data_attributes(aovs: &[Aov], scene: &Scene) -> Vec<(String, String)> {
    let names = &scene.names;
    let list: Vec<&str> = aovs.iter().map(|a| a.name()).collect();
    let mut out = vec![(
        "icrender/aovs".to_string(),
        if list.is_empty() {
            "none".to_string()
        } else {
            list.join(",")
        },
    )];
    if aovs.contains(&Aov::Depth) {
        out.push(("icrender/depth_far".to_string(), format!("{FAR_DEPTH:e}")));
    }
    if aovs.contains(&Aov::CryptoObject) {
        out.extend(cryptomatte::header_attributes(
            output::CRYPTO_OBJECT,
            names.objects.iter().map(String::as_str),
        ));
    }
    if aovs.contains(&Aov::CryptoMaterial) {
        // The materials some mesh uses (not glTF's default material when none does).
        let used = scene.used_materials();
        out.extend(cryptomatte::header_attributes(
            output::CRYPTO_MATERIAL,
            names
                .materials
                .iter()
                .zip(used)
                .filter(|(_, u)| *u)
                .map(|(n, _)| n.as_str()),
        ));
    }
    out
}

pub(super) fn quality_name(args: &RenderArgs) -> &'static str {
    match args.denoise_quality {
        DenoiseQualityArg::Fast => "fast",
        DenoiseQualityArg::Balanced => "balanced",
        DenoiseQualityArg::High => "high",
    }
}

pub(super) fn guides_text(d: &denoise::DenoisedFrame) -> &'static str {
    if d.prefiltered {
        "guided by the albedo and normal layers, prefiltered"
    } else if d.guided {
        "guided by the albedo and normal layers as rendered (given as guides that may be noisy: at a few samples a pixel their edges are as coarse as the light's)"
    } else {
        "no guides"
    }
}

/// "; specular left as rendered in specular_denoised (0.13 % of the measured noise, under 1 %)" for the
/// layers the denoiser wrote as rendered, with why (`denoise::LeftRaw`).
pub(super) fn left_raw_text(d: &denoise::DenoisedFrame) -> String {
    d.left_raw
        .iter()
        .map(|(layer, why)| {
            let why = match why {
                denoise::LeftRaw::NoNoise => "no Monte Carlo noise measured".to_string(),
                denoise::LeftRaw::Invisible(noise) => format!(
                    "noise {:.2} % of the light, under {:.1} %",
                    100.0 * noise.sqrt(),
                    100.0 * denoise::NEGLIGIBLE_RELATIVE_NOISE.sqrt()
                ),
                denoise::LeftRaw::SmallShare(share) => format!(
                    "{:.2} % of the measured noise, under {} %",
                    100.0 * share,
                    100.0 * denoise::NEGLIGIBLE_NOISE_SHARE
                ),
            };
            format!(
                "; {} left as rendered in {} ({why})",
                layer.name(),
                denoise::denoised_name(*layer),
            )
        })
        .collect()
}

/// The header's record of what was denoised, how, and the denoiser's time. Where no layer
/// needed the filter, it says so and names no filter settings or guides: none were used.
pub(super) fn denoise_attributes(d: &denoise::DenoisedFrame, args: &RenderArgs) -> Vec<(String, String)> {
    let filtered: Vec<&str> = d.filtered().iter().map(|l| l.name()).collect();
    const COMPOSITE: &str = "the composite R G B is raw, and `denoised` is the raw emission plus the \
                             denoised layers and any raw one (not the composite denoised itself)";
    let how = if filtered.is_empty() {
        format!(
            "{}; every noisy layer written as rendered into <layer>_denoised{}; {COMPOSITE}",
            d.denoiser,
            left_raw_text(d),
        )
    } else {
        format!(
            "{}, RT filter, quality {}, {}; layers {} each denoised into <layer>_denoised{} \
             (emission is not noisy and not denoised; indirect only where each pixel samples it, \
             -aa 0){}; {COMPOSITE}",
            d.denoiser,
            quality_name(args),
            guides_text(d),
            filtered.join(", "),
            weighing_text(d, args.spp),
            left_raw_text(d),
        ) + &patches_text(d)
    };
    vec![
        ("icrender/denoised".to_string(), d.names().join(" ")),
        ("icrender/denoise".to_string(), how),
        ("icrender/denoise_time_s".to_string(), format!("{:.3}", d.seconds)),
    ]
}

/// Where the filter ran, if not on every filtered layer's whole image: a layer whose pixels
/// measured their noise is filtered where that noise is (`image::noisy_patches`).
fn patches_text(d: &denoise::DenoisedFrame) -> String {
    let whole = d.composite.len() * d.filtered().len();
    if whole == 0 || d.filtered_pixels >= whole {
        return String::new();
    }
    format!(
        "; the filter ran where the measured noise is: {:.0} % of the filtered layers' pixels",
        100.0 * d.filtered_pixels as f64 / whole as f64
    )
}

/// How the filtered layers were weighed against the raw ones (`denoise::PixelSampling`).
fn weighing_text(d: &denoise::DenoisedFrame, spp: u32) -> String {
    let unweighed: Vec<String> = d
        .filtered()
        .into_iter()
        .filter(|l| !d.weighed.contains(l))
        .map(|l| l.name().to_string())
        .collect();
    match (d.weighed.is_empty(), unweighed.is_empty()) {
        (_, true) if spp >= 2 => {
            ", weighed against the raw layer by the noise each pixel's samples measured".to_string()
        }
        (_, true) => ", weighed against the raw layer by the noise each pixel's shadow rays measured".to_string(),
        (true, false) => " (one sample a pixel: no noise measured, the filter's output as it is)".to_string(),
        (false, false) => format!(
            ", direct weighed against the raw layer by the noise each pixel's shadow rays measured \
             ({} with one sample a pixel: no noise measured, the filter's output as it is)",
            unweighed.join(", ")
        ),
    }
}

/// An enumerated option's value as the command line takes it (`hessian`, not the Rust name).
fn value_name<T: clap::ValueEnum>(value: &T) -> String {
    value
        .to_possible_value()
        .map_or_else(String::new, |v| v.get_name().to_string())
}

/// The view options as given (`-vp 1 2 3 -vd 0 0 -1`), or where the view came from when none
/// were: the view is resolved from the scene again on a rerun, so the options are what
/// reproduce it, not the resolved numbers (which `icrender/view` holds).
fn view_text(view: &ViewArgs) -> String {
    let options = view_options(view);
    if options.is_empty() {
        "from the scene (its glTF camera, else the automatic view)".to_string()
    } else {
        options.join(" ")
    }
}

fn view_options(view: &ViewArgs) -> Vec<String> {
    let ViewArgs {
        vp,
        vd,
        vu,
        vh,
        vv,
        vtv,
        vtl,
    } = view;
    let mut out = Vec::new();
    let mut numbers = |name: &str, values: &[String]| {
        out.push(name.to_string());
        out.extend(values.iter().cloned());
    };
    if let Some(v) = vp {
        numbers("-vp", &v.iter().map(f64::to_string).collect::<Vec<_>>());
    }
    if let Some(v) = vd {
        numbers("-vd", &v.iter().map(f32::to_string).collect::<Vec<_>>());
    }
    if let Some(v) = vu {
        numbers("-vu", &v.iter().map(f32::to_string).collect::<Vec<_>>());
    }
    if let Some(v) = vh {
        numbers("-vh", &[v.to_string()]);
    }
    if let Some(v) = vv {
        numbers("-vv", &[v.to_string()]);
    }
    if *vtv {
        out.push("-vtv".to_string());
    }
    if *vtl {
        out.push("-vtl".to_string());
    }
    out
}

/// A word as a POSIX shell reads it back unchanged: as it is when it holds only characters no
/// shell treats specially, else in single quotes.
fn shell_word(word: &str) -> String {
    let plain = !word.is_empty()
        && word
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_@%+=:,./-".contains(c));
    if plain {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', "'\\''"))
    }
}

/// The command that renders this image again, for `icrender/command`: a user pastes it into a
/// shell (giving another -o, or removing the file: outputs are never overwritten unless asked)
/// and gets the same pixels. Every setting that changes the image is written out, defaults
/// included, so the line also documents the render; the scene is an absolute path so that it
/// runs from any folder.
///
/// Left out, as they do not change the pixels: threads, progress and quiet, statistics,
/// reference, checkpoint (and the cache file it keeps), memory limit, overwrite, and the MPI
/// mode and its tuning (with the default `--ic-build prepass` every mode makes the image one
/// process makes; the mode and ranks are in `icrender/mode` and `icrender/ranks`). A render
/// that loaded records from `-af` is rerun against that file, which may have grown since.
pub fn rerun_command(args: &RenderArgs) -> String {
    // Destructured field by field, with no `..`: an option added to RenderArgs does not
    // compile here until it is written out or said not to change the image.
    let RenderArgs {
        scene,
        output,
        width,
        height,
        ambient_bounces,
        ambient_accuracy,
        ambient_divisions,
        ambient_supersamples,
        ambient_resolution,
        ic_min_pixels,
        ic_blend,
        ambient_file,
        af_read_only,
        region,
        ic_metric,
        ic_build: _,
        ic_deep,
        mode: _,
        sync: _,
        send: _,
        pa_queue: _,
        pr_waits: _,
        pa: _,
        timeout: _,
        ic_records,
        ambient_value,
        specular_threshold,
        max_specular_depth,
        min_weight,
        light_samples,
        direct,
        spp,
        emission_samples,
        edge_samples,
        overture,
        passes,
        // Rerun as what they chose: the passes and the accuracy (`commands::render::passes`).
        target_error: _,
        time_limit: _,
        seed,
        tile,
        threads: _,
        lambertian,
        allow_outside_refs,
        flatten,
        stats: _,
        reference: _,
        trace_cache: _,
        no_preview,
        overwrite: _,
        max_memory: _,
        checkpoint,
        frames,
        frame,
        fps,
        half,
        compression,
        aovs: _,
        denoise,
        denoise_quality,
        denoise_prefilter,
        quiet: _,
        progress: _,
        view,
    } = args;
    let scene = std::fs::canonicalize(scene).unwrap_or_else(|_| scene.clone());
    let output = output.clone().unwrap_or_else(|| super::output_name(args));
    let av = ambient_value.as_deref().unwrap_or(&[0.0, 0.0, 0.0]);
    let mut words: Vec<String> = vec!["icrender".into(), "render".into(), scene.display().to_string()];
    let mut push = |items: &[&str]| words.extend(items.iter().map(|s| s.to_string()));
    push(&["-o", &output.display().to_string()]);
    push(&["-x", &width.to_string(), "-y", &height.to_string()]);
    push(&[
        "-ab",
        &ambient_bounces.to_string(),
        "-aa",
        &ambient_accuracy.to_string(),
    ]);
    push(&[
        "-ad",
        &ambient_divisions.to_string(),
        "-as",
        &ambient_supersamples.to_string(),
    ]);
    push(&["-ar", &ambient_resolution.to_string()]);
    push(&["-av", &av[0].to_string(), &av[1].to_string(), &av[2].to_string()]);
    push(&[
        "-st",
        &specular_threshold.to_string(),
        "-lr",
        &max_specular_depth.to_string(),
    ]);
    push(&["-lw", &min_weight.to_string()]);
    push(&[
        "--ic-metric",
        &value_name(ic_metric),
        "--ic-min-pixels",
        &ic_min_pixels.to_string(),
    ]);
    push(&["--ic-blend", &ic_blend.to_string()]);
    push(&["--ic-build", &value_name(&crate::job::cache_build(args))]);
    push(&["--ic-deep", &value_name(ic_deep)]);
    if let Some(n) = overture {
        push(&["--overture", &n.to_string()]);
    }
    push(&[
        "--light-samples",
        &light_samples.to_string(),
        "--direct",
        &value_name(direct),
    ]);
    push(&[
        "--spp",
        &spp.to_string(),
        "--emission-samples",
        &emission_samples.to_string(),
    ]);
    push(&["--edge-samples", &edge_samples.to_string()]);
    if *passes > 1 {
        push(&["--passes", &passes.to_string()]);
    }
    push(&["--seed", &seed.to_string(), "--tile", tile]);
    if let Some(file) = ambient_file {
        // The checkpoint's own cache file is the checkpoint's business, not the user's.
        let kept_by_checkpoint = checkpoint
            .as_deref()
            .is_some_and(|dir| *file == crate::checkpoint::cache_file(dir));
        if !kept_by_checkpoint {
            push(&["-af", &file.display().to_string()]);
            if *af_read_only {
                push(&["--af-read-only"]);
            }
        }
    }
    if let Some(r) = region {
        let r: Vec<String> = r.iter().map(u32::to_string).collect();
        words.push("--region".into());
        words.extend(r);
    }
    let mut push = |items: &[&str]| words.extend(items.iter().map(|s| s.to_string()));
    if let Some(r) = frames {
        push(&["--frames", &format!("{}-{}", r.first, r.last)]);
    }
    if let Some(n) = frame {
        push(&["--frame", &n.to_string()]);
    }
    if frames.is_some() || frame.is_some() {
        push(&["--fps", &fps.to_string()]);
    }
    let aovs: Vec<&str> = args.aovs().iter().map(|a| a.name()).collect();
    push(&[
        "--aovs",
        &if aovs.is_empty() {
            "none".to_string()
        } else {
            aovs.join(",")
        },
    ]);
    if *compression != crate::image::output::ExrCompression::Zip {
        push(&["--compression", compression.name()]);
    }
    for (on, name) in [
        (*half, "--half"),
        (*ic_records, "--ic-records"),
        (*lambertian, "--lambertian"),
        (*flatten, "--flatten"),
        (*allow_outside_refs, "--allow-outside-refs"),
        (*no_preview, "--no-preview"),
    ] {
        if on {
            push(&[name]);
        }
    }
    if *denoise {
        push(&["--denoise", "--denoise-quality", &value_name(denoise_quality)]);
        if *denoise_prefilter {
            push(&["--denoise-prefilter"]);
        }
    }
    words.extend(view_options(view));
    words.iter().map(|w| shell_word(w)).collect::<Vec<_>>().join(" ")
}
