//! Everything a render needs, prepared from the command line once: the scene, its Embree
//! BVH, the shading options, the view, and the irradiance cache (with its file). Every way of
//! rendering (serial now, the MPI modes later) starts from a Job.

use crate::cli::{CacheBuildArg, MetricArg, RenderArgs, parse_tile};
use crate::commands::{CommandError, warn};
use crate::frames::Frames;
use crate::irradiance::record::Metric;
use crate::irradiance::temporal::{Disturbance, Invalidation};
use crate::irradiance::{CacheSettings, IrradianceCache};
use crate::memory;
use crate::render::pixel::RenderSettings;
use crate::scene::animation::FramesPlan;
use crate::scene::footprint::EmitterFootprint;
use crate::scene::view::{Camera, View};
use crate::scene::{LoadOptions, Scene};
use crate::shading::ShadingOptions;
use crate::shading::last_bounce::sites_per_pixel;
use crate::tracer::Tracer;
use glam::Vec3;
use std::time::Instant;

pub struct Job {
    pub scene: Scene,
    pub tracer: Tracer,
    pub shading: ShadingOptions,
    pub view: View,
    pub camera: Camera,
    pub settings: RenderSettings,
    pub cache: Option<IrradianceCache>,
    pub load_s: f64,
    pub build_s: f64,
    /// What each thread did in an MPI prepass (see `parallel::prepass`), for the rank's report.
    pub prepass_threads: Vec<crate::render::pixel::ThreadStats>,
    /// With --frames or --frame: the frames, and what the animations do (the view above is the
    /// first frame's; `at_time` moves it).
    pub frames: Option<(Frames, FramesPlan)>,
}

/// Largest image side we accept: beyond it framebuffers stop fitting in memory sensibly.
const MAX_IMAGE_SIDE: u32 = 65_536;

/// The overture's grid spacing. Measured at -ab 1 -aa 0.2 against converged
/// references: on the 256x256 Cornell box it cut the indirect layer's bias from +4.4 % to
/// +2.4 %, its relMSE from 6.6e-4 to 4.7e-4 and the records from 1527 to 1333; on the 320x240
/// conference room relMSE 1.6e-2 to 1.1e-2 and records 3345 to 3148. Spacings 2 and 4 did
/// about as well; 1 (every pixel twice) made no fewer records.
const DEFAULT_OVERTURE: u32 = 3;

/// How the cache is filled: `--ic-build`, by default the prepass in every mode (the image then
/// depends neither on tiles, threads nor timing, and has no tile seams); `progressive` makes
/// records as pixels render, as the paper's modes do.
pub fn cache_build(args: &RenderArgs) -> CacheBuildArg {
    args.ic_build.unwrap_or(CacheBuildArg::Prepass)
}

/// Refuses option values that cannot work, before anything is loaded.
pub fn validate(args: &RenderArgs) -> Result<(), String> {
    if args.width == 0 || args.height == 0 || args.width > MAX_IMAGE_SIDE || args.height > MAX_IMAGE_SIDE {
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
    if !(args.ambient_accuracy.is_finite() && args.ambient_accuracy >= 0.0) {
        return Err("-aa must be a finite, non-negative number".into());
    }
    if !(args.ic_min_pixels.is_finite() && args.ic_min_pixels >= 0.0) {
        return Err("--ic-min-pixels must be a finite, non-negative number".into());
    }
    if !(args.ic_blend.is_finite() && (1.0..=4.0).contains(&args.ic_blend)) {
        return Err("--ic-blend must be a number from 1 to 4".into());
    }
    if args.threads == Some(0) {
        return Err("--threads must be at least 1".into());
    }
    if args.passes == 0 {
        return Err("--passes must be at least 1".into());
    }
    for (name, value) in [("--target-error", args.target_error), ("--time-limit", args.time_limit)] {
        if let Some(v) = value
            && !(v.is_finite() && v > 0.0)
        {
            return Err(format!("{name} must be a finite number above 0 (got {v})"));
        }
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
    if args.ambient_file.is_some() && args.ambient_accuracy == 0.0 {
        return Err("-af needs the irradiance cache, which -aa 0 turns off".into());
    }
    if args.trace_cache.is_some() && cache_build(args) == CacheBuildArg::Prepass {
        return Err(
            "--trace-cache traces the lookups of records made as pixels render: add --ic-build progressive".into(),
        );
    }
    parse_tile(&args.tile)?;
    if let Some(values) = &args.region {
        crate::image::region::Region::from_option(values, args.width, args.height)?;
    }
    if args.af_read_only && args.ambient_file.is_none() {
        return Err("--af-read-only needs a cache file to read: give -af FILE".into());
    }
    if args.compression == crate::image::output::ExrCompression::Dwaa && (!args.aovs().is_empty() || args.ic_records) {
        // OpenEXR's DWA codec is lossy on every channel it takes for colour (named R, G, B or
        // Y), whatever its type: it would blur Cryptomatte's IDs and the data layers.
        return Err(
            "--compression dwaa is lossy on every channel named R, G, B or Y, the data layers' and \
                    Cryptomatte's too: give --aovs none (and no --ic-records) with it, or a lossless codec (zip, piz)"
                .into(),
        );
    }
    args.frames()?;
    Ok(())
}

fn shading_options(args: &RenderArgs) -> ShadingOptions {
    ShadingOptions {
        ambient_bounces: args.ambient_bounces,
        ambient_divisions: args.ambient_divisions,
        ambient_value: args
            .ambient_value
            .as_deref()
            .map_or(Vec3::ZERO, |v| Vec3::new(v[0], v[1], v[2])),
        max_specular_depth: args.max_specular_depth,
        min_weight: args.min_weight,
        light_samples: args.light_samples.max(1),
        analytic_direct: args.direct == crate::cli::DirectArg::Analytic,
        deep_paths: args.ic_deep != crate::cli::DeepArg::Records,
        last_bounce_grid: args.ic_deep == crate::cli::DeepArg::Grid,
    }
}

/// The irradiance cache's options as Radiance writes them: `-ab N -aa A -ad N -as N -ar N -av R G
/// B` (in the EXR header's options and in a cache file's settings, which must stay as files
/// already hold them).
pub fn ambient_options(args: &RenderArgs) -> String {
    let av = args.ambient_value.as_deref().unwrap_or(&[0.0, 0.0, 0.0]);
    format!(
        "-ab {} -aa {} -ad {} -as {} -ar {} -av {} {} {}",
        args.ambient_bounces,
        args.ambient_accuracy,
        args.ambient_divisions,
        args.ambient_supersamples,
        args.ambient_resolution,
        av[0],
        av[1],
        av[2]
    )
}

/// What a cache file must agree on to be reused: everything that changes a record's value,
/// radius or meaning.
pub fn cache_settings_line(args: &RenderArgs, scene: &Scene) -> String {
    format!(
        "scene {} size {:.6e}; {}; -st {}; metric {:?}; lambertian {}{}{}",
        scene
            .path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        scene.size(),
        ambient_options(args),
        args.specular_threshold,
        args.ic_metric,
        args.lambertian,
        // Deeper bounces by paths change what a record holds; the default keeps the line that
        // files made before the option had.
        match args.ic_deep {
            crate::cli::DeepArg::Paths if args.ambient_bounces > 1 => "; deep paths",
            crate::cli::DeepArg::Grid if args.ambient_bounces > 1 => "; deep paths, last bounce grid",
            _ => "",
        },
        // Said only when set, so that files made before the option keep their line.
        if args.ic_min_pixels > 0.0 {
            format!("; min radius {} pixels", args.ic_min_pixels)
        } else {
            String::new()
        }
    )
}

/// Whether the job keeps an irradiance cache: indirect diffuse light to compute (-ab above 0 and a
/// diffuse surface) and an accuracy that allows reuse (-aa above 0; -aa 0 is brute force).
pub fn uses_cache(args: &RenderArgs, scene: &Scene) -> bool {
    args.ambient_accuracy > 0.0 && args.ambient_bounces > 0 && scene.needs().diffuse
}

/// The cache's settings from the options.
fn cache_settings(args: &RenderArgs, scene: &Scene, camera: &Camera) -> CacheSettings {
    let metric = match args.ic_metric {
        MetricArg::Hessian => Metric::Hessian,
        MetricArg::Ward88 => Metric::Ward88,
    };
    CacheSettings::new(
        args.ambient_accuracy,
        args.ambient_divisions,
        args.ambient_supersamples,
        args.ambient_resolution,
        metric,
        scene.cube_size(),
    )
    .with_view_floor(camera, args.ic_min_pixels)
    .with_blend(args.ic_blend)
}

/// Refuses a job whose estimated memory exceeds --max-memory, before the BVH and the render.
fn check_memory(args: &RenderArgs, scene: &Scene, role: memory::Role, limit: u64) -> Result<(), CommandError> {
    let component = matches!(args.mode, Some(crate::cli::ModeArg::Component) | None);
    // A region task holds and renders its region's pixels only.
    let (width, height) = match args.region.as_deref() {
        Some(v) => {
            let r = crate::image::region::Region::from_option(v, args.width, args.height)?;
            (r.width(), r.height())
        }
        None => (args.width, args.height),
    };
    let estimate = memory::Estimate::of(
        scene,
        &memory::Job {
            width,
            height,
            spp: args.spp,
            ambient_bounces: args.ambient_bounces,
            cache: uses_cache(args, scene),
            pa_queue: (role != memory::Role::Single && component).then_some(args.pa_queue),
            role,
        },
    );
    if estimate.total() > limit {
        return Err(CommandError::input(format!(
            "{}: this render would need about {} per process, more than --max-memory {}",
            args.scene.display(),
            estimate.describe(),
            memory::human(limit)
        )));
    }
    Ok(())
}

impl Job {
    /// Replaces the cache with an empty one as `args` make it (a refined record set for
    /// `--target-error`, `render::passes`), kept in memory only, and the shading options with
    /// those `args` make (-ad sets the last-bounce grid's sites too). The grid of the cache it
    /// replaces is kept where it has as many sites a pixel (it does not depend on the records'
    /// other settings), so the image is the one `args` render from scratch. Nothing without a
    /// cache.
    pub fn refine_records(&mut self, args: &RenderArgs) {
        let same_grid = sites_per_pixel(self.shading.ambient_divisions) == sites_per_pixel(args.ambient_divisions);
        let Some(old) = self.cache.as_mut() else {
            return;
        };
        let grid = old.take_last_bounce().filter(|_| same_grid);
        self.shading = shading_options(args);
        let cache = IrradianceCache::new(cache_settings(args, &self.scene, &self.camera));
        if let Some(grid) = grid {
            cache.set_last_bounce(grid);
        }
        self.cache = Some(cache);
    }

    /// Loads the scene, checks the job fits --max-memory (as a process in `role`), builds the
    /// BVH, chooses the view and opens the cache.
    pub fn prepare(args: &RenderArgs, role: memory::Role) -> Result<Job, CommandError> {
        let load_start = Instant::now();
        let material_options = LoadOptions {
            specular_threshold: args.specular_threshold,
            lambertian: args.lambertian,
            allow_outside_refs: args.allow_outside_refs,
            max_memory: args.max_memory,
            flatten: args.flatten,
            keep_pose_source: args.frames.is_some() || args.frame.is_some(),
        };
        let mut scene = Scene::load(&args.scene, &material_options)?;
        if let Some(limit) = args.max_memory {
            check_memory(args, &scene, role, limit)?;
        }
        let load_s = load_start.elapsed().as_secs_f64();
        for w in &scene.warnings {
            warn(&format!("{}: {w}", args.scene.display()));
        }
        let shading = shading_options(args);
        if !scene.has_lights() && shading.ambient_value.max_element() <= 0.0 {
            return Err(CommandError::input(format!(
                "{}: the scene has no light sources (no emissive material, no KHR_lights_punctual light); \
                 it would render black (give -av for an ambient-only render)",
                args.scene.display()
            )));
        }
        let frames = match args.frames()? {
            Some(frames) => Some((frames, plan_frames(args, &scene, frames)?)),
            None => None,
        };
        let time = frames.as_ref().map(|(f, _)| f.time(f.range.first));
        match (&frames, time) {
            // The meshes and lights where the first frame has them, before the BVH is built.
            (Some((_, plan)), Some(time)) if plan.meshes_animated || plan.lights_animated => {
                scene.pose_at(time);
            }
            _ => scene.pose_source = None,
        }
        let build_start = Instant::now();
        let tracer = Tracer::new(&scene).map_err(|e| CommandError::input(format!("{}: {e}", args.scene.display())))?;
        let build_s = build_start.elapsed().as_secs_f64();
        let (view, view_note) =
            crate::commands::view::choose_view(&scene, &tracer, &args.view, args.width, args.height, time)
                .map_err(|e| CommandError::input(format!("{}: view: {e}", args.scene.display())))?;
        if let Some(note) = view_note {
            warn(&format!("{}: {note}", args.scene.display()));
        }
        let camera = view.camera(args.width, args.height);
        let (tile_width, tile_height) = parse_tile(&args.tile)?;
        let threads = args
            .threads
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
        let prepass = cache_build(args) == CacheBuildArg::Prepass;
        let region = args
            .region
            .as_deref()
            .map(|v| crate::image::region::Region::from_option(v, args.width, args.height))
            .transpose()?;
        let window = crate::image::window::PixelWindow::new(
            region.unwrap_or_else(|| crate::image::region::Region::whole(args.width, args.height)),
            args.width,
            args.height,
        );
        let settings = RenderSettings {
            spp: args.spp,
            seed: args.seed,
            tile_width,
            tile_height,
            threads,
            jitter: false,
            texture_footprint: true,
            emission_samples: args.emission_samples,
            edge_samples: args.edge_samples,
            edge_map: None,
            // In every mode; in component mode the grid orders each PA's queue instead
            // (parallel::component::order). The prepass places every record before the
            // pixels, which leaves an overture nothing to do.
            overture: if prepass {
                0
            } else {
                args.overture.unwrap_or(DEFAULT_OVERTURE)
            },
            prepass,
            region,
            emission_footprint: (args.emission_samples > 0 && !scene.emitters.is_empty())
                .then(|| std::sync::Arc::new(EmitterFootprint::new(&scene.emitters, &camera, window))),
        };
        let cache = if uses_cache(args, &scene) {
            let cache = IrradianceCache::new(cache_settings(args, &scene, &camera));
            let cache = match &args.ambient_file {
                Some(path) => {
                    let line = cache_settings_line(args, &scene);
                    let cache = if args.af_read_only {
                        cache.with_records_from(path, &line)
                    } else {
                        cache.with_file(path, &line)
                    }
                    .map_err(|e| CommandError::input(format!("{}: {e}", path.display())))?;
                    let report = &cache.load_report;
                    if report.torn_bytes > 0 || report.corrupt > 0 {
                        warn(&format!(
                            "{}: dropped a torn last record ({} bytes) and {} damaged record(s)",
                            path.display(),
                            report.torn_bytes,
                            report.corrupt
                        ));
                    }
                    cache
                }
                None => cache,
            };
            Some(match &args.trace_cache {
                Some(path) => cache.with_trace(path).map_err(CommandError::input)?,
                None => cache,
            })
        } else {
            None
        };
        Ok(Job {
            scene,
            tracer,
            shading,
            view,
            camera,
            settings,
            cache,
            load_s,
            build_s,
            prepass_threads: Vec::new(),
            frames,
        })
    }

    /// Moves the meshes, lights and view to where the animations put them at `time` (a
    /// frame's), with what depends on them: the BVH is built again when a mesh moved, and the
    /// cache drops the records the moves changed (`irradiance::temporal`), keeping the rest for
    /// this frame's prepass to add to; what it kept and dropped is returned (None without
    /// a cache).
    pub fn at_time(&mut self, args: &RenderArgs, time: f64) -> Result<Option<Invalidation>, CommandError> {
        let change = self.scene.pose_at(time);
        if !change.is_empty() {
            let build_start = Instant::now();
            self.tracer = Tracer::new(&self.scene)
                .map_err(|e| CommandError::input(format!("{}: at {time} s: {e}", args.scene.display())))?;
            self.build_s = build_start.elapsed().as_secs_f64();
        }
        let disturbance = Disturbance::of(&change, &self.scene);
        let invalidation = self.cache.as_mut().map(|c| c.forget_disturbed(&disturbance));
        let (view, _) = crate::commands::view::choose_view(
            &self.scene,
            &self.tracer,
            &args.view,
            args.width,
            args.height,
            Some(time),
        )
        .map_err(|e| CommandError::input(format!("{}: view at {time} s: {e}", args.scene.display())))?;
        self.camera = view.camera(args.width, args.height);
        self.view = view;
        if self.settings.emission_footprint.is_some() {
            self.settings.emission_footprint = Some(std::sync::Arc::new(EmitterFootprint::new(
                &self.scene.emitters,
                &self.camera,
                self.settings.window(&self.camera),
            )));
        }
        Ok(invalidation)
    }
}

/// What rendering `frames` of this scene means: refused when its animations deform meshes (see
/// `Rig::plan_frames`), and with a cache file (-af, or --checkpoint's) when they move meshes or
/// lights (a file holds the records of one still scene); said on stderr when the frames will all
/// be alike (nothing animates, or -vp -vd -vu override the camera and nothing else moves) or run
/// past the animations' end.
fn plan_frames(args: &RenderArgs, scene: &Scene, frames: Frames) -> Result<FramesPlan, CommandError> {
    let camera = scene.cameras.first().map(|c| c.node);
    let plan = scene
        .rig
        .plan_frames(camera)
        .map_err(|e| CommandError::input(format!("{}: {e}", args.scene.display())))?;
    for note in &plan.notes {
        warn(&format!("{}: {note}", args.scene.display()));
    }
    let scene_moves = plan.meshes_animated || plan.lights_animated;
    if scene_moves {
        let file = if args.checkpoint.is_some() {
            Some("--checkpoint (its frames share a cache file)")
        } else if args.ambient_file.is_some() {
            Some("-af")
        } else {
            None
        };
        if let Some(file) = file {
            return Err(CommandError::input(format!(
                "{}: its animations move meshes or lights, so no one set of records holds for every frame: \
                 {file} cannot be used for its frames (each frame keeps what the moves left of the last one's \
                 records in memory)",
                args.scene.display()
            )));
        }
    }
    let v = &args.view;
    let overridden = v.vp.is_some() && v.vd.is_some() && v.vu.is_some();
    if frames.count() > 1 && !args.quiet && !scene_moves {
        let why = if camera.is_none() {
            Some("the scene has no camera, so every frame has the same automatic view")
        } else if !plan.camera_animated {
            Some("no animation moves the scene's camera, so every frame shows the same view")
        } else if overridden {
            Some("-vp, -vd and -vu replace the animated camera, so every frame shows the same view")
        } else {
            None
        };
        if let Some(why) = why {
            warn(&format!("{}: --frames {}: {why}", args.scene.display(), frames.text()));
        } else if let Some((_, end)) = plan.keys
            && frames.time(frames.range.last) > end
        {
            warn(&format!(
                "{}: the camera's animation ends at {end} s (frame {:.1} at {} fps): later frames hold its last pose",
                args.scene.display(),
                end * frames.fps,
                frames.fps
            ));
        }
    }
    Ok(plan)
}
