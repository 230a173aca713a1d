//! What a render writes and where: the output names and their checks, the statistics of the
//! job, and the writing of the layered EXR (its header from `header`), the preview and the
//! statistics file.

use super::header::{
    data_attributes, denoise_attributes, guides_text, left_raw_text, options_line, part_settings, quality_name,
};
use super::{check_denoiser, denoise_quality};
use crate::cli::RenderArgs;
use crate::commands::CommandError;
use crate::frames::FrameTag;
use crate::image::denoise;
use crate::image::framebuffer::{FrameBuffer, Layer};
use crate::image::layered_exr::{self, ChannelPlan, ExrLayout, StreamedExr};
use crate::image::output::{self, StagedFile};
use crate::image::region::{REGION_ATTRIBUTE, SETTINGS_ATTRIBUTE};
use crate::image::window::PixelWindow;
use crate::job::Job;
use crate::scene::SceneNeeds;
use crate::shading::ShadingOptions;
use crate::stats::RenderStats;
use std::path::{Path, PathBuf};

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

/// The statistics of a render in one process: the job's, every thread's work (the prepass's
/// included) and the prepass's own account, reported as the one rank of `per_rank`.
pub fn one_process_stats(
    args: &RenderArgs,
    job: &Job,
    (render_s, wall_s): (f64, f64),
    threads: &[crate::render::ThreadStats],
    prepass: Option<&crate::prepass::PrepassOutcome>,
) -> RenderStats {
    let mut stats = job_stats(args, job, "serial", 1, render_s);
    stats.add_threads(threads);
    if let Some(prepass) = prepass {
        stats.add_prepass(prepass);
    }
    stats.wall_s = wall_s;
    stats.single_rank();
    stats
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

    /// How this render's EXR is laid out: the layers the scene can light, `extra` layers (the
    /// denoised ones), the data layers asked for, over `window`, in the render's tiles.
    pub fn layout(args: &RenderArgs, job: &Job, window: PixelWindow, extra: &[&str], ranks: usize) -> ExrLayout {
        let layers = producible_layers(job.scene.needs(), &job.shading);
        ExrLayout {
            // The statistics take about 12 KB and 1 KB more a rank; the command line, the
            // settings and Cryptomatte's manifests a few KB (a scene with many objects more:
            // then the file is copied under its header instead, `StreamedExr::finish`).
            header_room: (64 << 10) + (2 << 10) * ranks,
            plan: ChannelPlan::new(&layers, extra, args.ic_records, &args.aovs()),
            window,
            tile: (job.settings.tile_width.max(1), job.settings.tile_height.max(1)),
            half_float: args.half,
            compression: args.compression,
        }
    }

    /// The stream a one-process render writes its tiles into as they finish, or None where
    /// the frame must be held whole: `--denoise` filters every pixel with its neighbours.
    pub fn stream(&self, args: &RenderArgs, job: &Job, ranks: usize) -> Result<Option<StreamedExr>, CommandError> {
        if args.denoise {
            return Ok(None);
        }
        let layout = Outputs::layout(args, job, job.settings.window(&job.camera), &[], ranks);
        StreamedExr::open(&self.exr, layout, self.png.is_some())
            .map(Some)
            .map_err(|e| CommandError::failed(format!("{}: {e}", self.exr.display())))
    }

    /// The EXR's header: how to render it again, the settings parts of one image share, the
    /// data layers' manifests, the statistics and the denoiser's account.
    fn attributes(
        &self,
        args: &RenderArgs,
        job: &Job,
        stats: &RenderStats,
        denoised: Option<&denoise::DenoisedFrame>,
    ) -> Result<Vec<(String, String)>, CommandError> {
        let mut attributes = vec![
            (
                "Software".to_string(),
                format!("icrender {}", env!("CARGO_PKG_VERSION")),
            ),
            ("DateTime".to_string(), crate::sys::clock::local_date_time()),
            ("icrender/command".to_string(), super::rerun_command(args)),
            ("icrender/scene".to_string(), args.scene.display().to_string()),
            ("icrender/options".to_string(), options_line(args)),
            ("icrender/view".to_string(), job.view.radiance_options(job.scene.origin)),
            // OpenEXR's own attribute (a float: see cpp/image_io.cpp), for viewers and compositors.
            ("PixelAspectRatio".to_string(), job.camera.pixel_aspect().to_string()),
            ("icrender/mode".to_string(), stats.mode.to_string()),
            ("icrender/ranks".to_string(), stats.ranks.to_string()),
            ("icrender/render_time_s".to_string(), format!("{:.3}", stats.render_s)),
            ("icrender/statistics".to_string(), serde_json::to_string(stats)?),
            (
                "icrender/error_estimate".to_string(),
                serde_json::to_string(&stats.error_estimate)?,
            ),
        ];
        let settings = match &self.frame {
            Some(f) => format!("{}; frame {} at {} s", part_settings(args), f.number, f.time),
            None => part_settings(args),
        };
        attributes.push((SETTINGS_ATTRIBUTE.to_string(), settings));
        if let Some(f) = &self.frame {
            attributes.extend(f.attributes());
        }
        if let Some(r) = job.settings.region {
            attributes.push((REGION_ATTRIBUTE.to_string(), r.text()));
        }
        attributes.extend(data_attributes(&args.aovs(), &job.scene));
        if let Some(d) = denoised {
            attributes.extend(denoise_attributes(d, args));
        }
        Ok(attributes)
    }

    /// Writes what a one-process render made: finishes its stream, or writes the frame it held
    /// whole.
    pub fn save(
        &self,
        args: &RenderArgs,
        job: &Job,
        frame: Option<FrameBuffer>,
        streamed: Option<StreamedExr>,
        stats: &RenderStats,
    ) -> Result<(), CommandError> {
        match (streamed, frame) {
            (Some(streamed), _) => self.finish_stream(args, job, streamed, stats),
            (None, Some(frame)) => self.write(args, job, &frame, stats),
            (None, None) => Err(CommandError::failed(format!(
                "{}: the render held no frame and streamed none",
                self.exr.display()
            ))),
        }
    }

    /// Finishes a streamed render: the EXR with its header, the preview from the stream's
    /// reduced copy, the statistics.
    pub fn finish_stream(
        &self,
        args: &RenderArgs,
        job: &Job,
        streamed: StreamedExr,
        stats: &RenderStats,
    ) -> Result<(), CommandError> {
        let attributes = self.attributes(args, job, stats, None)?;
        // The preview is made while the EXR's tiles are copied under its header.
        let kept = streamed.take_preview();
        let (exr, png) = std::thread::scope(|scope| {
            let png = self.png.as_ref().zip(kept.as_ref()).map(|(png, kept)| {
                scope.spawn(move || {
                    output::stage_kept_preview(png, kept)
                        .map_err(|e| CommandError::failed(format!("{}: {e}", png.display())))
                })
            });
            let exr = streamed.finish(&attributes);
            (exr, png.map(|p| p.join().expect("the preview's thread panicked")))
        });
        let exr = exr.map_err(|e| self.exr_failed(args, e))?;
        self.place(exr, png, stats)
    }

    /// Writes a frame held whole: with --denoise, denoises first and writes the denoised layers
    /// too; the EXR (with header), the preview and the statistics.
    pub fn write(
        &self,
        args: &RenderArgs,
        job: &Job,
        frame: &FrameBuffer,
        stats: &RenderStats,
    ) -> Result<(), CommandError> {
        let layers = producible_layers(job.scene.needs(), &job.shading);
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
        let attributes = self.attributes(args, job, &stats, denoised.as_ref())?;
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
        let names: Vec<&str> = extra.iter().map(|(n, _)| n.as_str()).collect();
        let planes: Vec<&[glam::Vec3]> = extra.iter().map(|(_, p)| *p).collect();
        let layout = Outputs::layout(args, job, frame.window(), &names, stats.ranks);
        // The preview is made beside the EXR, on a thread of its own, and put in place only
        // once the EXR is: 0.5 s of a 1080p frame's writing no longer comes after it.
        let preview = |png: &std::path::PathBuf| {
            // The preview is for looking at: the denoised composite when there is one.
            let staged = match &denoised {
                Some(d) => output::stage_preview(png, frame.width, frame.height, |i| d.composite[i]),
                None => output::stage_preview(png, frame.width, frame.height, |i| frame.composite_at(i)),
            };
            staged.map_err(|e| CommandError::failed(format!("{}: {e}", png.display())))
        };
        let (exr, png) = std::thread::scope(|scope| {
            let png = self.png.as_ref().map(|png| scope.spawn(move || preview(png)));
            let exr = layered_exr::write_whole(&self.exr, layout, frame, &planes, &attributes);
            (exr, png.map(|p| p.join().expect("the preview's thread panicked")))
        });
        let exr = exr.map_err(|e| self.exr_failed(args, e))?;
        self.place(exr, png, &stats)?;
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

    /// What a failed EXR says: the file, the failure and what a rerun resumes.
    fn exr_failed(&self, args: &RenderArgs, e: String) -> CommandError {
        CommandError::failed(format!("{}: {e}; {}", self.exr.display(), super::kept_after_stop(args)))
    }

    /// Puts the finished EXR in place, then the preview (only once the EXR is), then writes the
    /// statistics.
    fn place(
        &self,
        exr: StagedFile,
        png: Option<Result<StagedFile, CommandError>>,
        stats: &RenderStats,
    ) -> Result<(), CommandError> {
        exr.place()
            .map_err(|e| CommandError::failed(format!("{}: {e}", self.exr.display())))?;
        if let (Some(staged), Some(png)) = (png, &self.png) {
            staged?
                .place()
                .map_err(|e| CommandError::failed(format!("{}: {e}", png.display())))?;
        }
        if let Some(path) = &self.stats {
            output::write_json(path, stats).map_err(|e| CommandError::failed(format!("{}: {e}", path.display())))?;
        }
        Ok(())
    }
}
