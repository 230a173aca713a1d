//! `icrender render`: prepare the job, trace, write the layered EXR, the preview and the
//! statistics, and report the error against a reference if one is given.

use super::{CommandError, CommandResult, warn};
use crate::checkpoint::{self, Checkpoint, Restored};
use crate::cli::RenderArgs;
use crate::cli::{DenoiseQualityArg, ModeArg, ProgressArg};
use crate::frames::FrameTag;
use crate::image::data::{Aov, FAR_DEPTH};
use crate::image::denoise;
use crate::image::denoise::Quality;
use crate::image::framebuffer::{FrameBuffer, Layer};
use crate::image::region::{REGION_ATTRIBUTE, Region, SETTINGS_ATTRIBUTE};
use crate::image::window::PixelWindow;
use crate::image::{cryptomatte, metrics, output};
use crate::job::{Job, validate};
use crate::parallel::{JobHost, Mode, ParallelJob, under_mpirun};
use crate::progress::{self, Progress};
use crate::render::render_resumable;
use crate::scene::{Scene, SceneNeeds};
use crate::shading::{Integrator, ShadingOptions};
use crate::stats::RenderStats;
use crate::sys::image_io;
use crate::sys::image_io::Window;
use crate::tiles::{Tile, tiles_in};
use std::path::{Path, PathBuf};
use std::time::Instant;

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

/// The EXR name -o gives, or the default (for frames, a pattern: see `frames::NamePattern`).
pub fn output_name(args: &RenderArgs) -> PathBuf {
    args.output.clone().unwrap_or_else(|| default_output(&args.scene))
}

fn default_output(scene: &Path) -> PathBuf {
    let stem = scene
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "render".into());
    PathBuf::from(format!("{stem}.exr"))
}

/// The render is always a layered OpenEXR, and its preview takes the same name with .png: any
/// other extension would either put the preview over the EXR (`-o out.png`) or write an EXR
/// under a name that says it is something else (`-o out.jpg`), so only .exr is accepted.
fn check_exr_name(exr: &Path) -> Result<(), CommandError> {
    let extension = exr.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
    if extension.as_deref() == Some("exr") {
        return Ok(());
    }
    let suggestion = exr.with_extension("exr");
    let why = match extension.as_deref() {
        Some("png") => "the PNG preview is written beside the EXR under the .png name, so the EXR would be lost",
        Some(_) => "the render is written as a layered OpenEXR whatever the name says",
        None => "the render is a layered OpenEXR and its name must say so",
    };
    Err(CommandError::input(format!(
        "-o {}: the output must end in .exr ({why}); give -o {} (the preview goes beside it as .png)",
        exr.display(),
        suggestion.display()
    )))
}

/// A file this command is about to write: not a directory, not an existing file unless
/// `overwrite`, and writable here (checked before any work, so nothing fails at the end).
pub fn check_new_output(path: &Path, overwrite: bool) -> Result<(), CommandError> {
    not_a_directory(path)?;
    if path.exists() && !overwrite {
        return Err(CommandError::input(format!(
            "{}: already exists (give --overwrite to replace it)",
            path.display()
        )));
    }
    output::check_writable(path).map_err(|e| CommandError::input(format!("{}: {e}", path.display())))
}

/// A directory is never replaced, with or without --overwrite: said before anything else.
fn not_a_directory(path: &Path) -> Result<(), CommandError> {
    if path.is_dir() {
        return Err(CommandError::input(format!(
            "{}: is a directory; give a file name (e.g. {})",
            path.display(),
            path.join("render.exr").display()
        )));
    }
    Ok(())
}

/// Two names for one file (the same path, or the same file through links).
fn same_file(a: &Path, b: &Path) -> bool {
    if a == b {
        return true;
    }
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// The options as a Radiance-style line for the EXR header (and for giving rpict the same).
pub fn options_line(args: &RenderArgs) -> String {
    let av = args.ambient_value.as_deref().unwrap_or(&[0.0, 0.0, 0.0]);
    format!(
        "-x {} -y {} -ab {} -aa {} -ad {} -as {} -ar {} -av {} {} {} -st {} -lr {} -lw {} --ic-metric {:?} \
         --light-samples {} --direct {} --spp {} --seed {} --ic-build {} --ic-deep {} --ic-blend {}{}{}{}{}",
        args.width,
        args.height,
        args.ambient_bounces,
        args.ambient_accuracy,
        args.ambient_divisions,
        args.ambient_supersamples,
        args.ambient_resolution,
        av[0],
        av[1],
        av[2],
        args.specular_threshold,
        args.max_specular_depth,
        args.min_weight,
        args.ic_metric,
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
        if args.flatten { " --flatten" } else { "" }
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
        format!("view {:?}", args.view),
        format!(
            "--aovs {}",
            if aovs.is_empty() {
                "none".to_string()
            } else {
                aovs.join(",")
            }
        ),
        format!("--half {}", args.half),
        format!("--ic-records {}", args.ic_records),
        format!("--denoise {}", if args.denoise { quality_name(args) } else { "off" }),
    ]);
    items.join("; ")
}

/// The statistics every way of rendering reports about the job itself; the caller adds what
/// its threads or ranks did.
pub fn job_stats(args: &RenderArgs, job: &Job, mode: &'static str, ranks: usize, render_s: f64) -> RenderStats {
    let cache = job.cache.as_ref();
    RenderStats {
        version: env!("CARGO_PKG_VERSION"),
        scene: args.scene.display().to_string(),
        mode,
        ranks,
        width: args.width,
        height: args.height,
        spp: args.spp,
        threads: job.settings.threads,
        overture: job.settings.overture,
        cache_build: if job.settings.prepass { "prepass" } else { "progressive" },
        triangles: job.scene.triangle_count(),
        dropped_triangles: job.scene.dropped_triangles,
        load_s: job.load_s,
        build_s: job.build_s,
        render_s,
        layers: producible_layers(job.scene.needs(), &job.shading)
            .iter()
            .map(|l| l.name())
            .collect(),
        records_loaded: cache.map_or(0, |c| c.load_report.loaded as u64),
        cache_records: cache.map_or(0, |c| c.len() as u64),
        lock_contention: cache.map_or(0, |c| c.contention()),
        peak_memory_bytes: crate::memory::peak_resident_bytes(),
        ..Default::default()
    }
}

/// Where the results go, checked writable before any work is done.
pub struct Outputs {
    pub exr: PathBuf,
    pub png: Option<PathBuf>,
    pub stats: Option<PathBuf>,
    /// The frame of a sequence these are (--frames, --frame): said in the header, and part of
    /// the settings parts of one image share (`icrender merge` refuses parts of other frames).
    pub frame: Option<FrameTag>,
}

impl Outputs {
    pub fn check(args: &RenderArgs) -> Result<Outputs, CommandError> {
        if args.denoise {
            check_denoiser(args)?;
        }
        Outputs::checked(args, output_name(args), args.stats.clone(), None)
    }

    /// The outputs of one frame of a sequence, or of a still image when `frame` is None: the
    /// EXR at `exr` (a name ending in .exr), its preview beside it, the statistics at `stats`.
    pub fn checked(
        args: &RenderArgs,
        exr: PathBuf,
        stats: Option<PathBuf>,
        frame: Option<FrameTag>,
    ) -> Result<Outputs, CommandError> {
        not_a_directory(&exr)?;
        check_exr_name(&exr)?;
        let png = (!args.no_preview).then(|| exr.with_extension("png"));
        let outputs = Outputs { exr, png, stats, frame };
        if let Some(stats) = &outputs.stats
            && (same_file(stats, &outputs.exr) || outputs.png.as_deref().is_some_and(|png| same_file(stats, png)))
        {
            return Err(CommandError::input(format!(
                "--stats {}: is also an image output of this render; give the statistics a name of their own (e.g. .json)",
                stats.display()
            )));
        }
        for path in std::iter::once(&outputs.exr)
            .chain(outputs.png.iter())
            .chain(outputs.stats.iter())
        {
            check_new_output(path, args.overwrite)?;
        }
        Ok(outputs)
    }

    /// Writes the EXR (with header), the preview and the statistics; with --denoise, denoises
    /// first and writes the denoised layers too.
    pub fn write(
        &self,
        args: &RenderArgs,
        job: &Job,
        frame: &FrameBuffer,
        stats: &RenderStats,
    ) -> Result<(), CommandError> {
        let layers = producible_layers(job.scene.needs(), &job.shading);
        // The frame holds the pixels rendered: a part (--region) its region's only, written as
        // the data window inside the whole image's display window.
        let region = job.settings.region;
        let held = frame.window();
        let window = Window {
            x: held.area.x0,
            y: held.area.y0,
            full_width: held.full_width,
            full_height: held.full_height,
        };
        let denoised = if args.denoise {
            let quality = denoise_quality(args);
            Some(
                // Without the cache each pixel samples its own hemisphere: its indirect light
                // is Monte Carlo noise too. (Read from the options: an MPI master holds no
                // cache of its own whatever the mode.)
                denoise::denoise_frame(
                    frame,
                    &layers,
                    !crate::job::uses_cache(args, &job.scene),
                    denoise::PixelSampling {
                        samples: args.spp,
                        shadow_rays: args.light_samples,
                        edge_samples: args.edge_samples,
                    },
                    quality,
                    args.threads,
                    args.denoise_prefilter,
                )
                .map_err(CommandError::failed)?,
            )
        } else {
            None
        };
        let mut stats = stats.clone();
        if let Some(d) = &denoised {
            stats.denoised_layers = d.names();
            stats.denoise_s = Some(d.seconds);
            stats.denoise_filtered_pixels = Some(d.filtered_pixels);
        }
        let stats_json = serde_json::to_string(&stats)?;
        let command_line: Vec<String> = std::env::args().collect();
        let attributes = vec![
            (
                "Software".to_string(),
                format!("icrender {}", env!("CARGO_PKG_VERSION")),
            ),
            ("icrender/command".to_string(), command_line.join(" ")),
            ("icrender/scene".to_string(), args.scene.display().to_string()),
            ("icrender/options".to_string(), options_line(args)),
            ("icrender/view".to_string(), job.view.radiance_options(job.scene.origin)),
            // OpenEXR's own attribute (a float: see cpp/image_io.cpp), for viewers and compositors.
            ("PixelAspectRatio".to_string(), job.camera.pixel_aspect().to_string()),
            ("icrender/mode".to_string(), stats.mode.to_string()),
            ("icrender/ranks".to_string(), stats.ranks.to_string()),
            ("icrender/render_time_s".to_string(), format!("{:.3}", stats.render_s)),
            ("icrender/statistics".to_string(), stats_json),
        ];
        let aovs = args.aovs();
        let mut attributes = attributes;
        let settings = match &self.frame {
            Some(f) => format!("{}; frame {} at {} s", part_settings(args), f.number, f.time),
            None => part_settings(args),
        };
        attributes.push((SETTINGS_ATTRIBUTE.to_string(), settings));
        if let Some(f) = &self.frame {
            attributes.extend(f.attributes());
        }
        if let Some(r) = region {
            attributes.push((REGION_ATTRIBUTE.to_string(), r.text()));
        }
        attributes.extend(data_attributes(&aovs, &job.scene));
        if let Some(d) = &denoised {
            attributes.extend(denoise_attributes(d, args));
        }
        let extra: Vec<(String, &[glam::Vec3])> = denoised.as_ref().map_or_else(Vec::new, |d| {
            d.layers
                .iter()
                .map(|(l, plane)| (denoise::denoised_name(*l), plane.as_slice()))
                .chain(std::iter::once((
                    denoise::DENOISED_COMPOSITE.to_string(),
                    d.composite.as_slice(),
                )))
                .collect()
        });
        let extra: Vec<(&str, &[glam::Vec3])> = extra.iter().map(|(n, p)| (n.as_str(), *p)).collect();
        output::write_exr(
            &self.exr,
            frame,
            window,
            &layers,
            &aovs,
            &extra,
            &attributes,
            args.half,
            args.ic_records,
        )
        .map_err(|e| CommandError::failed(format!("{}: {e}", self.exr.display())))?;
        if let Some(png) = &self.png {
            // The preview is for looking at: the denoised composite when there is one.
            let composite = denoised
                .as_ref()
                .map_or_else(|| frame.composite(), |d| d.composite.clone());
            output::write_preview(png, frame.width, frame.height, &composite)
                .map_err(|e| CommandError::failed(format!("{}: {e}", png.display())))?;
        }
        if let Some(path) = &self.stats {
            output::write_json(path, &stats).map_err(|e| CommandError::failed(format!("{}: {e}", path.display())))?;
        }
        if let Some(d) = &denoised
            && !args.quiet
        {
            let what: Vec<&str> = d.filtered().iter().map(|l| l.name()).collect();
            if what.is_empty() {
                eprintln!(
                    "icrender: --denoise ran no filter: no layer needed it{}; layer `denoised` holds the raw layers' sum ({:.3} s)",
                    left_raw_text(d),
                    d.seconds
                );
            } else {
                eprintln!(
                    "icrender: denoised {} (and their sum with the emission, layer `denoised`) in {:.3} s ({}, quality {}, {}){}",
                    what.join(", "),
                    d.seconds,
                    d.denoiser,
                    quality_name(args),
                    guides_text(d),
                    left_raw_text(d)
                );
            }
        }
        Ok(())
    }
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

fn denoise_quality(args: &RenderArgs) -> Quality {
    match args.denoise_quality {
        DenoiseQualityArg::Fast => Quality::Fast,
        DenoiseQualityArg::Balanced => Quality::Balanced,
        DenoiseQualityArg::High => Quality::High,
    }
}

fn quality_name(args: &RenderArgs) -> &'static str {
    match args.denoise_quality {
        DenoiseQualityArg::Fast => "fast",
        DenoiseQualityArg::Balanced => "balanced",
        DenoiseQualityArg::High => "high",
    }
}

fn guides_text(d: &denoise::DenoisedFrame) -> &'static str {
    if d.prefiltered {
        "guided by the albedo and normal layers, prefiltered"
    } else if d.guided {
        "guided by the albedo and normal layers as rendered (given as guides that may be noisy: at a few samples a pixel their edges are as coarse as the light's)"
    } else {
        "no guides"
    }
}

/// `--denoise` needs the library and a working device: checked before anything is rendered
/// or written, so a render never runs for minutes only to fail at the end.
pub(crate) fn check_denoiser(args: &RenderArgs) -> Result<(), CommandError> {
    denoise::Denoiser::new(denoise_quality(args), args.threads)
        .map(|_| ())
        .map_err(|e| CommandError::input(format!("--denoise: {e}")))
}

/// "; specular left as rendered in specular.denoised (0.13 % of the measured noise, under 1 %)" for the
/// layers the denoiser wrote as rendered, with why (`denoise::LeftRaw`).
fn left_raw_text(d: &denoise::DenoisedFrame) -> String {
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
fn denoise_attributes(d: &denoise::DenoisedFrame, args: &RenderArgs) -> Vec<(String, String)> {
    let filtered: Vec<&str> = d.filtered().iter().map(|l| l.name()).collect();
    const COMPOSITE: &str = "the composite R G B is raw, and `denoised` is the raw emission plus the \
                             denoised layers and any raw one (not the composite denoised itself)";
    let how = if filtered.is_empty() {
        format!(
            "{}; every noisy layer written as rendered into <layer>.denoised{}; {COMPOSITE}",
            d.denoiser,
            left_raw_text(d),
        )
    } else {
        format!(
            "{}, RT filter, quality {}, {}; layers {} each denoised into <layer>.denoised{} \
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

/// With --checkpoint, the cache goes to the checkpoint directory (which `open_checkpoint` has
/// made) unless -af names a file, so a resumed render starts with the records the killed one
/// wrote.
pub fn with_checkpoint_cache(args: &RenderArgs) -> RenderArgs {
    let mut args = args.clone();
    if let Some(dir) = &args.checkpoint
        && args.ambient_file.is_none()
    {
        args.ambient_file = Some(checkpoint::cache_file(dir));
    }
    args
}

/// What identifies a job to its checkpoint: everything that changes the image or the tiles.
/// (The mode, ranks, threads and output names do not: a render may resume in another mode.)
pub fn checkpoint_key(args: &RenderArgs) -> String {
    let scene = std::fs::canonicalize(&args.scene).unwrap_or_else(|_| args.scene.clone());
    let key = format!(
        "scene {}; {}; tile {}; view {:?}",
        scene.display(),
        options_line(args),
        args.tile,
        args.view
    );
    // A part journals its own tiles (keys of whole renders stay as they were).
    match &args.region {
        Some(r) => format!("{key}; region {r:?}"),
        None => key,
    }
}

/// The --region option's rectangle, if given.
fn region_of(args: &RenderArgs) -> Result<Option<Region>, CommandError> {
    args.region
        .as_deref()
        .map(|v| Region::from_option(v, args.width, args.height))
        .transpose()
        .map_err(CommandError::input)
}

/// The tiles this render makes: the whole image's, or those of its --region.
pub fn render_tiles(args: &RenderArgs) -> Result<Vec<Tile>, CommandError> {
    let (tile_width, tile_height) = crate::cli::parse_tile(&args.tile).map_err(CommandError::input)?;
    Ok(tiles_in(
        args.width,
        args.height,
        tile_width,
        tile_height,
        region_of(args)?,
    ))
}

/// The pixels this render's frame holds: its --region, or the whole image.
pub fn render_window(args: &RenderArgs) -> Result<PixelWindow, CommandError> {
    let area = region_of(args)?.unwrap_or_else(|| Region::whole(args.width, args.height));
    Ok(PixelWindow::new(area, args.width, args.height))
}

/// Opens the --checkpoint journal (if asked for) and says what an earlier run left.
/// Opened before the scene is loaded, so another job's checkpoint is refused at once.
pub fn open_checkpoint(args: &RenderArgs, all_tiles: &[Tile]) -> Result<Option<(Checkpoint, Restored)>, CommandError> {
    let Some(dir) = &args.checkpoint else {
        return Ok(None);
    };
    let (journal, restored) =
        Checkpoint::open(dir, &checkpoint_key(args), all_tiles, render_window(args)?).map_err(CommandError::input)?;
    if restored.torn_bytes > 0 {
        warn(&format!(
            "{}: dropped {} bytes of a torn last journal entry",
            dir.display(),
            restored.torn_bytes
        ));
    }
    if !args.quiet && restored.count() > 0 {
        eprintln!(
            "icrender: resuming from {}: {} of {} tiles are already finished",
            dir.display(),
            restored.count(),
            all_tiles.len()
        );
    }
    Ok(Some((journal, restored)))
}

/// Prints the error of the written image against the reference, next to the run time.
pub fn report_error(
    exr: &Path,
    reference: &image_io::ImageData,
    reference_path: &Path,
    seconds: f64,
) -> Result<(), CommandError> {
    let written = image_io::read_image(exr, &[]).map_err(|e| CommandError::input(format!("{}: {e}", exr.display())))?;
    let errors = metrics::compare(&written, reference)
        .map_err(|e| CommandError::input(format!("{}: {e}", reference_path.display())))?;
    for e in &errors {
        println!(
            "error {:<17} rmse {:.6e}  relmse {:.6e}  time {:.3} s",
            e.layer, e.rmse, e.rel_mse, seconds
        );
    }
    Ok(())
}

fn mode_of(arg: ModeArg) -> Mode {
    match arg {
        ModeArg::Serial => Mode::Serial,
        ModeArg::Noshare => Mode::Noshare,
        ModeArg::Centralised => Mode::Centralised,
        ModeArg::Broadcast => Mode::Broadcast,
        ModeArg::Component => Mode::Component,
    }
}

/// The render command's side of a run under mpirun: its options, outputs and checkpoint.
struct RenderHost<'a> {
    args: &'a RenderArgs,
    /// Rank 0's outputs, once checked.
    outputs: std::sync::OnceLock<Outputs>,
}

impl JobHost for RenderHost<'_> {
    fn validate(&self) -> Result<(), String> {
        validate(self.args)
    }

    fn check_outputs(&self) -> Result<(), String> {
        let outputs = Outputs::check(self.args).map_err(|e| e.message)?;
        let _ = self.outputs.set(outputs);
        Ok(())
    }

    fn open_checkpoint(&self, tiles: &[Tile]) -> Result<Option<(Checkpoint, Restored)>, String> {
        open_checkpoint(self.args, tiles).map_err(|e| e.message)
    }

    fn prepare(&self, master: bool, threads: usize) -> Result<Job, String> {
        // Only the master keeps the cache file (beside the checkpoint with --checkpoint).
        let mut args = if master {
            with_checkpoint_cache(self.args)
        } else {
            self.args.clone()
        };
        args.threads = Some(threads);
        if !master {
            args.ambient_file = None;
        }
        Job::prepare(&args, crate::memory::Role::AnyRank).map_err(|e| e.message)
    }

    fn job_stats(&self, job: &Job, mode: &'static str, ranks: usize, render_s: f64) -> RenderStats {
        job_stats(self.args, job, mode, ranks, render_s)
    }

    fn write(&self, job: &Job, frame: &FrameBuffer, stats: &RenderStats) -> Result<(), String> {
        let outputs = self.outputs.get().ok_or("the outputs were not checked")?;
        outputs.write(self.args, job, frame, stats).map_err(|e| e.message)
    }
}

fn run_parallel(args: &RenderArgs, mode: Mode) -> CommandResult {
    if args.progress == ProgressArg::Json {
        warn("--progress json reports one-process renders only: under mpirun the master prints its table at the end");
    }
    let host = RenderHost {
        args,
        outputs: std::sync::OnceLock::new(),
    };
    let tile = crate::cli::parse_tile(&args.tile).map_err(CommandError::input)?;
    crate::parallel::run(&ParallelJob {
        mode,
        width: args.width,
        height: args.height,
        tile,
        threads: args.threads,
        sync: args.sync,
        send: args.send,
        pa: args.pa,
        pa_queue: args.pa_queue,
        pr_waits: args.pr_waits,
        silence_limit: std::time::Duration::from_secs_f64(args.timeout.max(1.0)),
        seed: args.seed,
        cache_file: args.ambient_file.is_some(),
        quiet: args.quiet,
        host: &host,
    })
}

/// What a render stopped by `signal` says: nothing was written, and what a rerun resumes.
fn interrupted(args: &RenderArgs, signal: i32) -> CommandError {
    CommandError {
        message: format!(
            "stopped by {}: no image written; {}",
            crate::sys::signals::name(signal),
            kept_after_stop(args)
        ),
        exit: super::Exit::Interrupted(signal),
    }
}

/// What a stopped render leaves for the next run: the checkpoint, or the cache file, or nothing.
pub(crate) fn kept_after_stop(args: &RenderArgs) -> String {
    match (&args.checkpoint, &args.ambient_file) {
        (Some(dir), _) => format!(
            "the finished tiles and the cache are kept in {}: the same command resumes",
            dir.display()
        ),
        (None, Some(file)) => format!("the cache's records are kept in {}", file.display()),
        (None, None) => "nothing is kept (--checkpoint DIR would keep the finished tiles)".into(),
    }
}

/// Renders a frame sequence (`--frames`, `--frame`) once the checks common to every render have
/// passed: `commands::frames::run`, handed in by `main`, so that this module, which
/// the sequence renders each frame through, does not depend on it in turn.
pub type SequenceRenderer = fn(&RenderArgs, crate::frames::Frames) -> CommandResult;

pub fn run(args: &RenderArgs, sequence: SequenceRenderer) -> CommandResult {
    let mode = match args.mode {
        Some(m) => mode_of(m),
        None if under_mpirun() => Mode::Component,
        None => Mode::Serial,
    };
    if mode != Mode::Serial {
        if args.frames.is_some() || args.frame.is_some() {
            return Err(CommandError::input(
                "--frames and --frame render in one process (no mpirun, no --mode): a farm runs one task per \
                 chunk of frames; under mpirun render one image at a time"
                    .into(),
            ));
        }
        if args.region.is_some() {
            return Err(CommandError::input(
                "--region renders in one process (no mpirun, no --mode): run one task per region and \
                 `icrender merge` the parts"
                    .into(),
            ));
        }
        if args.trace_cache.is_some() {
            return Err(CommandError::input("--trace-cache traces the serial mode only".into()));
        }
        return run_parallel(args, mode);
    }
    let wall = Instant::now();
    validate(args)?;
    if args.region.is_some() && args.reference.is_some() {
        return Err(CommandError::input(
            "--reference compares whole images: render the regions, merge them, and `icrender compare` the merged image"
                .into(),
        ));
    }
    if let Some(frames) = args.frames()? {
        return sequence(args, frames);
    }
    let outputs = Outputs::check(args)?;
    image_io::open_in_background();
    let reference = match &args.reference {
        Some(path) => {
            Some(image_io::read_image(path, &[]).map_err(|e| CommandError::input(format!("{}: {e}", path.display())))?)
        }
        None => None,
    };
    let all_tiles = render_tiles(args)?;
    let (journal, restored) = open_checkpoint(args, &all_tiles)?.map_or((None, None), |(j, r)| (Some(j), Some(r)));
    let job = Job::prepare(&with_checkpoint_cache(args), crate::memory::Role::Single)?;
    let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, job.cache.as_ref());
    let s = &job.settings;
    let tiles_restored = restored.as_ref().map_or(0, Restored::count);
    let progress = Progress::with_style(
        all_tiles.len(),
        progress::Style::chosen(args.progress == ProgressArg::Json, args.quiet),
    );
    // From here a SIGTERM or SIGINT stops the render cleanly (see sys::signals).
    crate::sys::signals::catch_termination().map_err(CommandError::failed)?;
    let render_start = Instant::now();
    let rendered = render_resumable(&integrator, &job.camera, s, &progress, journal.as_ref().zip(restored));
    let (frame, thread_stats) = (rendered.frame, rendered.threads);
    let render_s = render_start.elapsed().as_secs_f64();
    if let Some(cache) = &job.cache
        && let Err(e) = cache.finish()
    {
        warn(&format!(
            "{}: cache file not fully written: {e}",
            args.ambient_file.as_deref().unwrap_or(Path::new("")).display()
        ));
    }
    if let Some(signal) = crate::sys::signals::received() {
        return Err(interrupted(args, signal));
    }

    let mut stats = job_stats(args, &job, "serial", 1, render_s);
    stats.tiles_restored = tiles_restored as u64;
    stats.add_threads(&thread_stats);
    if let Some(prepass) = &rendered.prepass {
        stats.add_prepass(prepass);
    }
    if stats.nonfinite_dropped > 0 {
        warn(&format!(
            "{} non-finite contribution(s) were dropped",
            stats.nonfinite_dropped
        ));
    }
    stats.wall_s = wall.elapsed().as_secs_f64();
    stats.single_rank();
    outputs.write(args, &job, &frame, &stats)?;
    progress.done(&outputs.exr);
    if !args.quiet {
        eprintln!(
            "icrender: {}{}x{} in {:.2} s ({:.1} Mrays/s, {} threads, {} records, {:.0}% of lookups hit) -> {}",
            job.settings
                .region
                .map_or_else(String::new, |r| format!("region {} of ", r.text())),
            args.width,
            args.height,
            render_s,
            stats.mrays_per_s,
            s.threads,
            stats.records_computed,
            100.0 * stats.hits as f64 / stats.lookups.max(1) as f64,
            outputs.exr.display()
        );
    }
    if let (Some(reference), Some(path)) = (&reference, &args.reference) {
        report_error(&outputs.exr, reference, path, render_s)?;
    }
    Ok(())
}
