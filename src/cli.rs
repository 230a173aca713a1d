//! Command-line arguments. Radiance's option names (-ab, -vp, ...) are accepted as they are
//! written for rpict: they are rewritten to long options before clap sees them.

use crate::image::data::Aov;
use clap::{Args, Parser, Subcommand};
use std::path::PathBuf;

/// Radiance-style multi-letter options taking a single dash.
pub const RADIANCE_OPTIONS: &[&str] = &[
    "ab", "aa", "ad", "as", "ar", "af", "av", "st", "lr", "lw", "vp", "vd", "vu", "vh", "vv", "vtv", "vtl",
];

/// Turns `-ab 2` into `--ab 2` for every Radiance option name; everything else is untouched.
pub fn rewrite_radiance_options(args: impl IntoIterator<Item = String>) -> Vec<String> {
    args.into_iter()
        .map(|a| match a.strip_prefix('-') {
            Some(name) if !name.starts_with('-') && RADIANCE_OPTIONS.contains(&name) => {
                format!("--{name}")
            }
            _ => a,
        })
        .collect()
}

#[derive(Parser, Debug)]
#[command(
    name = "icrender",
    version,
    about = "Global illumination with Ward's irradiance cache, by components"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Render a glTF scene to a layered OpenEXR and a PNG preview (-o is optional: by default
    /// ./SCENE-NAME.exr and ./SCENE-NAME.png).
    #[command(override_usage = "icrender render <SCENE> [-o OUT.exr] [OPTIONS]")]
    Render(Box<RenderArgs>),
    /// Describe a scene: triangles, materials, lights, bounds, and the components it needs.
    Info(InfoArgs),
    /// Error of one EXR against another (RMSE and relative MSE per layer).
    Compare(CompareArgs),
    /// Tile seams of an EXR layer: mean step across tile borders over the mean step within.
    Seams(SeamsArgs),
    /// Benchmarks (print figures; not tests).
    Bench(BenchArgs),
    /// Render a converged reference: brute force, progressive, with its own noise estimate.
    Reference(Box<ReferenceArgs>),
    /// Write the scene as Radiance input (geometry, materials, light sources) for rpict.
    Export(ExportArgs),
    /// Run only the irradiance cache prepass for the image the same render options (or a
    /// --region) would make, and write its records to the -af file (no image): the shared
    /// cache of a farm's region or frame tasks (see docs/farms.md).
    #[command(override_usage = "icrender cache <SCENE> -af FILE [RENDER OPTIONS]")]
    Cache(Box<RenderArgs>),
    /// Assemble parts rendered with --region into the whole image: every layer and the header;
    /// parts made with other settings, overlapping parts and holes are refused.
    #[command(override_usage = "icrender merge OUT.exr PART.exr... [--overwrite]")]
    Merge(MergeArgs),
    /// Print docs/options.md, the options reference, from this definition (for maintainers:
    /// `cargo run --release -- help-reference > docs/options.md`).
    #[command(name = "help-reference", hide = true)]
    HelpReference,
}

#[derive(Args, Debug)]
pub struct MergeArgs {
    /// The whole image to write (.exr).
    pub output: PathBuf,
    /// The parts (EXRs written by `render --region`), in any order.
    #[arg(required = true, num_args = 1..)]
    pub parts: Vec<PathBuf>,
    /// Replace the output if it exists.
    #[arg(long = "overwrite")]
    pub overwrite: bool,
}

#[derive(Args, Debug, Clone)]
pub struct ReferenceArgs {
    /// The render to converge: scene, view, size and shading options as for `render`
    /// (-aa is ignored: a reference never uses the cache).
    #[command(flatten)]
    pub render: RenderArgs,
    /// Stop when the estimated relative noise (RMS, of the composite) falls below this.
    #[arg(long = "noise", default_value_t = 0.005, allow_negative_numbers = true)]
    pub noise: f64,
    /// Stop after this many seconds even if the noise target is not reached.
    #[arg(long = "max-seconds", default_value_t = 600.0, allow_negative_numbers = true)]
    pub max_seconds: f64,
}

#[derive(Args, Debug)]
pub struct ExportArgs {
    /// The glTF scene.
    pub scene: PathBuf,
    /// The Radiance scene file to write (.rad).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Every material becomes a Lambertian of its base colour, as `render --lambertian`.
    #[arg(long = "lambertian")]
    pub lambertian: bool,
    /// Let the scene read buffers and images outside its own folder (refused by default).
    #[arg(long = "allow-outside-refs")]
    pub allow_outside_refs: bool,
    /// Replace the output if it exists.
    #[arg(long = "overwrite")]
    pub overwrite: bool,
}

/// Defaults of options that a render in passes (`commands::render::passes`) starts from other
/// values when they are left as they are.
pub const DEFAULT_ACCURACY: f32 = 0.2;
pub const DEFAULT_DIVISIONS: u32 = 512;
pub const DEFAULT_SUPERSAMPLES: u32 = 128;
pub const DEFAULT_LIGHT_SAMPLES: u32 = 16;

#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// The glTF 2.0 scene (.gltf or .glb).
    pub scene: PathBuf,
    /// Output EXR, a name ending in .exr. Optional: by default the scene's file name with .exr,
    /// in the current directory (`icrender render dir/room.gltf` writes ./room.exr). The PNG
    /// preview is written beside it with the extension .png.
    #[arg(short = 'o', long = "output", value_name = "OUT.exr")]
    pub output: Option<PathBuf>,
    /// Image width in pixels.
    #[arg(short = 'x', default_value_t = 512, allow_negative_numbers = true)]
    pub width: u32,
    /// Image height in pixels.
    #[arg(short = 'y', default_value_t = 512, allow_negative_numbers = true)]
    pub height: u32,
    /// -ab: ambient (indirect diffuse) bounces.
    #[arg(long = "ab", default_value_t = 1, allow_negative_numbers = true)]
    pub ambient_bounces: u32,
    /// -aa: ambient accuracy; larger means larger record radii and fewer records. 0 turns the
    /// irradiance cache off (brute force at every point).
    #[arg(long = "aa", default_value_t = DEFAULT_ACCURACY, allow_negative_numbers = true)]
    pub ambient_accuracy: f32,
    /// -ad: hemisphere samples of a new record (brute force: at the first bounce).
    #[arg(long = "ad", default_value_t = DEFAULT_DIVISIONS, allow_negative_numbers = true)]
    pub ambient_divisions: u32,
    /// -as: extra hemisphere samples where the first ones vary most.
    #[arg(long = "as", default_value_t = DEFAULT_SUPERSAMPLES, allow_negative_numbers = true)]
    pub ambient_supersamples: u32,
    /// -ar: ambient resolution; the smallest record radius is the scene's cube size / ar, as in
    /// Radiance (0: no such limit, only --ic-min-pixels'). Off by default: a share of the whole
    /// scene suits some views and not others; the view's floor (--ic-min-pixels) follows the
    /// camera.
    #[arg(long = "ar", default_value_t = 0, allow_negative_numbers = true)]
    pub ambient_resolution: u32,
    /// The smallest record radius in pixels: a record is never smaller than this many pixel
    /// widths at its depth in the view (for a sequence, the first frame's view), nor than -ar's
    /// floor. -ar's floor is a share of the whole scene, whatever part the camera sees; this one
    /// follows the view. 0: -ar's floor alone (as Radiance).
    #[arg(long = "ic-min-pixels", default_value_t = 3.0, allow_negative_numbers = true)]
    pub ic_min_pixels: f32,
    /// How many times its placed radii each record is read over once the record set is
    /// complete (after the prepass): -aa sets how densely records are placed, this how many
    /// of them each point blends, which averages the records' own noise. 1 reads them as
    /// placed, as Radiance does (and as --ic-build progressive always does, having no moment
    /// when the set is complete). From 1 to 4.
    #[arg(long = "ic-blend", default_value_t = crate::irradiance::DEFAULT_BLEND, allow_negative_numbers = true)]
    pub ic_blend: f32,
    /// -af FILE: persistent irradiance cache, loaded at start and appended to while rendering.
    #[arg(long = "af")]
    pub ambient_file: Option<PathBuf>,
    /// Only read the -af file: records this render makes stay in memory and the file is never
    /// opened for writing (the file must exist). For tasks that share one file made by
    /// `icrender cache`, which must not append to it side by side.
    #[arg(long = "af-read-only", requires = "ambient_file")]
    pub af_read_only: bool,
    /// Render only the pixels X0 <= x < X1, Y0 <= y < Y1 of the -x by -y image (pixel bounds
    /// in the full image, origin at the top left, X1 and Y1 exclusive). Same camera, pixel
    /// positions and seeds as the whole render; the EXR's data window is the region inside the
    /// full display window, and the PNG preview shows the region only. `icrender merge`
    /// assembles the parts. One-process renders only.
    #[arg(long = "region", num_args = 4, value_names = ["X0", "Y0", "X1", "Y1"], allow_negative_numbers = true)]
    pub region: Option<Vec<u32>>,
    /// Record weighting: Radiance's Hessian-based error control, or Ward's 1988 split sphere.
    #[arg(long = "ic-metric", value_enum, default_value_t = MetricArg::Hessian)]
    pub ic_metric: MetricArg,
    /// How the irradiance cache is filled. prepass: every record the image needs is placed
    /// before any pixel is shaded, coarse to fine over the whole image, and the pixels only
    /// interpolate (the image does not depend on threads, tiles or timing, and has no tile
    /// seams); progressive: records are made as the pixels render, in tile order (the paper's
    /// setting, and what the MPI modes do).
    #[arg(long = "ic-build", value_enum)]
    pub ic_build: Option<CacheBuildArg>,
    /// The light at a record's hemisphere hits and beyond. grid (the default): each of a
    /// record's hemisphere rays continues as a path whose last bounce's surface reads the light
    /// it receives, direct and indirect, from a world-space grid sampled before the prepass (at
    /// -ab 1 the hits read their direct light from it; without a prepass, as paths); paths:
    /// the last bounce traced too, every hit its own shadow ray (unbiased, no deeper records);
    /// records: deeper bounces are cached records too, as in Radiance.
    #[arg(long = "ic-deep", value_enum, default_value_t = DeepArg::Grid)]
    pub ic_deep: DeepArg,
    /// How ranks share the work under mpirun (serial without mpirun).
    #[arg(long = "mode", value_enum)]
    pub mode: Option<ModeArg>,
    /// Records a rank gathers before it shares them (default: 50; 8 for PAs in component mode).
    #[arg(long = "sync", allow_negative_numbers = true)]
    pub sync: Option<u32>,
    /// Requests a PR gathers before it sends them to a PA (component mode).
    #[arg(long = "send", default_value_t = 32, allow_negative_numbers = true)]
    pub send: u32,
    /// Most requests a PA keeps queued (component mode); while its queue is this long it takes
    /// no more in, and a PR whose outbox fills computes its next batches itself (back-pressure
    /// instead of unbounded growth; `requests_kept` in --stats).
    /// The message that brings it there may overshoot it by up to --send plus a pixel's
    /// samples (a PR sends once a pixel's requests reach --send).
    #[arg(long = "pa-queue", default_value_t = 65536, allow_negative_numbers = true)]
    pub pa_queue: u32,
    /// Component mode: a PR whose outbox is full waits for room instead of computing the batch
    /// itself, as the paper's PRs (which compute no indirect light while tiles are left); the
    /// paper bench passes it.
    #[arg(long = "pr-waits")]
    pub pr_waits: bool,
    /// Ranks that act as PAs in component mode (default: half the workers).
    #[arg(long = "pa", allow_negative_numbers = true)]
    pub pa: Option<u32>,
    /// Seconds a rank may stay silent under mpirun (ranks send heartbeats every 2 s) before the
    /// master ends the job naming it, or a worker whose master is that silent ends itself; also
    /// how long the master waits for a rank to take one of its messages.
    #[arg(long = "timeout", default_value_t = 30.0, allow_negative_numbers = true)]
    pub timeout: f64,
    /// Add a debug layer `ic_records` counting the records each pixel made.
    #[arg(long = "ic-records")]
    pub ic_records: bool,
    /// -av r g b: radiance assumed past the last ambient bounce.
    #[arg(long = "av", num_args = 3, value_names = ["R", "G", "B"], allow_negative_numbers = true)]
    pub ambient_value: Option<Vec<f32>>,
    /// -st: specular threshold; no specular ray below this reflectance.
    #[arg(long = "st", default_value_t = crate::scene::material::DEFAULT_SPECULAR_THRESHOLD, allow_negative_numbers = true)]
    pub specular_threshold: f32,
    /// -lr: maximum specular path length.
    #[arg(long = "lr", default_value_t = 8, allow_negative_numbers = true)]
    pub max_specular_depth: u32,
    /// -lw: minimum path weight before a specular path is cut.
    #[arg(long = "lw", default_value_t = 1e-3, allow_negative_numbers = true)]
    pub min_weight: f32,
    /// Shadow rays to area emitters per shading point on the eye path (stratified). Shadow rays
    /// are cheap next to the noise one ray leaves in penumbrae and with many emitters.
    #[arg(long = "light-samples", default_value_t = DEFAULT_LIGHT_SAMPLES, allow_negative_numbers = true)]
    pub light_samples: u32,
    /// How area lights are integrated. analytic: their unshadowed irradiance exactly (Lambert's
    /// formula, in scenes with few emitting triangles) and the shadow rays only for how much of
    /// it gets through (that share pooled over a pixel's samples), so fully lit and fully
    /// shadowed points have no noise (in penumbrae consistent: its bias falls with the pixel's
    /// shadow rays); sampled: plain shadow-ray sampling, unbiased (what `reference` uses).
    #[arg(long = "direct", value_enum, default_value_t = DirectArg::Analytic)]
    pub direct: DirectArg,
    /// Samples per pixel (stratified over the pixel's area).
    #[arg(long = "spp", default_value_t = 1, allow_negative_numbers = true)]
    pub spp: u32,
    /// Extra primary rays per pixel gathering only the emission seen straight from the eye,
    /// in pixels where an emitter can appear (used when above --spp). They integrate a light's
    /// edges over the pixel's area at the cost of one ray each, without shading.
    #[arg(long = "emission-samples", default_value_t = 16, allow_negative_numbers = true)]
    pub emission_samples: u32,
    /// Samples per pixel in the pixels an edge crosses (their four corners do not all see one
    /// surface: a silhouette, a crease, where objects or materials meet), used when above
    /// --spp. One ray per pixel corner finds them; a box filter's error is largest there.
    /// 0: every pixel takes --spp. What it buys at each setting: docs/EDGES.md (bench/edges.py).
    #[arg(long = "edge-samples", default_value_t = 4, allow_negative_numbers = true)]
    pub edge_samples: u32,
    /// Before a tile's pixels, make the cache records that the first surfaces on a grid of
    /// this spacing (pixels) need; the pixels then interpolate between records on all their
    /// sides instead of extrapolating from the records earlier pixels made. 0: none. In
    /// component mode a PA computes its queued requests at this grid's pixels first instead
    /// (a PR's misses go to the PAs). Default 3.
    #[arg(long = "overture", allow_negative_numbers = true)]
    pub overture: Option<u32>,
    /// Render the image this many times over one record set, from independent samples, and
    /// average the passes: their noise falls as 1/N, the cache's error stays. What
    /// --target-error and --time-limit chose is rerun with it (the EXR's `icrender/command`).
    #[arg(long = "passes", default_value_t = 1, allow_negative_numbers = true)]
    pub passes: u32,
    /// Render in passes until the error estimate (the relMSE `icrender compare` would report
    /// against the converged image) is at most this, e.g. 1e-3: each pass renders the image
    /// again from independent samples and the passes are averaged; where the cache's own error
    /// dominates, the records are made again finer (-aa smaller). The image is written after
    /// every pass that lowers the estimate. With --time-limit: whichever comes first.
    #[arg(long = "target-error", allow_negative_numbers = true)]
    pub target_error: Option<f64>,
    /// Render in passes (as --target-error) for at most this many seconds of rendering, and
    /// keep the image with the lowest error estimate. The first pass always ends, however long
    /// it takes.
    #[arg(long = "time-limit", allow_negative_numbers = true)]
    pub time_limit: Option<f64>,
    /// Random seed; the same seed gives the same image.
    #[arg(long = "seed", default_value_t = 1, allow_negative_numbers = true, value_parser = whole_number::<u64>)]
    pub seed: u64,
    /// Tile size, WxH.
    #[arg(long = "tile", default_value = "32x32")]
    pub tile: String,
    /// Rendering threads (default: every core).
    #[arg(long = "threads", allow_negative_numbers = true, value_parser = whole_number::<usize>)]
    pub threads: Option<usize>,
    /// Every material becomes a two-sided Lambertian of its base colour (emitters unchanged).
    #[arg(long = "lambertian")]
    pub lambertian: bool,
    /// Let the scene read buffers and images outside its own folder (refused by default).
    #[arg(long = "allow-outside-refs")]
    pub allow_outside_refs: bool,
    /// Copy every placement of a mesh used by several nodes (or EXT_mesh_gpu_instancing) into
    /// world space instead of tracing it through Embree instances: the way meshes used once
    /// are held. For comparison; it takes more memory and a longer BVH build.
    #[arg(long = "flatten")]
    pub flatten: bool,
    /// Write statistics as JSON to this file.
    #[arg(long = "stats")]
    pub stats: Option<PathBuf>,
    /// Report the error against this reference EXR after rendering.
    #[arg(long = "reference")]
    pub reference: Option<PathBuf>,
    /// Serial mode: write every irradiance cache lookup and new record to this text file (for
    /// the bench's cluster simulation; see src/irradiance/trace.rs).
    #[arg(long = "trace-cache", hide = true)]
    pub trace_cache: Option<PathBuf>,
    /// Do not write the PNG preview.
    #[arg(long = "no-preview")]
    pub no_preview: bool,
    /// Replace output files that already exist (by default an existing file is never touched).
    #[arg(long = "overwrite")]
    pub overwrite: bool,
    /// Memory one process may use (MiB, or with a K, M, G or T suffix): a render estimated to
    /// need more is refused before it starts, with the estimate.
    #[arg(long = "max-memory", value_name = "SIZE", value_parser = parse_memory, allow_negative_numbers = true)]
    pub max_memory: Option<u64>,
    /// Journal finished tiles and the irradiance cache in DIR, so that a render killed at any
    /// moment and started again with the same command resumes instead of starting over.
    #[arg(long = "checkpoint", value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,
    /// Render frames A to B (both included) of the scene's glTF animations (cameras, meshes and
    /// lights), each to its own EXR: `-o out.####.exr` (or `%04d`) takes the zero-padded frame
    /// number; a name without one gets `.####` before its extension. Frame N is at time N /
    /// --fps. The irradiance cache is carried from frame to frame, less the records moving
    /// meshes or lights changed. One process only.
    #[arg(long = "frames", value_name = "A-B", value_parser = crate::frames::parse_range, conflicts_with = "frame")]
    pub frames: Option<crate::frames::FrameRange>,
    /// Render frame N of the animation alone (as --frames N-N).
    #[arg(long = "frame", value_name = "N", value_parser = whole_number::<u32>)]
    pub frame: Option<u32>,
    /// Frames per second of --frames and --frame: frame N is at time N / fps of the animation.
    #[arg(long = "fps", default_value_t = 24.0, allow_negative_numbers = true)]
    pub fps: f64,
    /// Store half floats in the EXR's light layers (default: full floats); data layers and
    /// Cryptomatte always stay full floats.
    #[arg(long = "half")]
    pub half: bool,
    /// The EXR's codec: zip (lossless, what Blender and Nuke write float layers with), piz
    /// (lossless, smaller for noisy light, slower), dwaa (lossy, for light alone: needs --aovs
    /// none), none.
    #[arg(long = "compression", value_enum, default_value_t = crate::image::output::ExrCompression::Zip)]
    pub compression: crate::image::output::ExrCompression,
    /// Data layers and Cryptomatte types to write, comma-separated: albedo, normal, depth,
    /// position, crypto_object, crypto_material; or none, or all (default: all but position).
    #[arg(long = "aovs", value_name = "LIST", value_parser = parse_aovs)]
    pub aovs: Option<AovList>,
    /// Denoise with Intel Open Image Denoise: each noisy lighting layer (direct, specular,
    /// indirect) is written again as `<layer>_denoised` beside the raw one, and their sum with
    /// the emission as the layer `denoised` (the PNG preview shows it). Needs the library
    /// scripts/install-deps.sh unpacks; without it the render stops before it starts.
    #[arg(long = "denoise")]
    pub denoise: bool,
    /// The denoiser's quality: fast, balanced or high (OIDN's trade of time against error).
    /// `fast` by default: in the peers bench its curve lies lowest (docs/layers.md, "Denoising").
    #[arg(long = "denoise-quality", value_enum, default_value_t = DenoiseQualityArg::Fast, requires = "denoise")]
    pub denoise_quality: DenoiseQualityArg,
    /// Prefilter the albedo and normal guides before they guide the filter (OIDN's way for
    /// noisy guides; icrender's come from the camera samples' first hits, free of Monte Carlo
    /// noise, and prefiltering them was worse, see docs/layers.md, "Denoising").
    #[arg(long = "denoise-prefilter", requires = "denoise")]
    pub denoise_prefilter: bool,
    /// No progress bar and no summary.
    #[arg(short = 'q', long = "quiet")]
    pub quiet: bool,
    /// How progress is shown: `bar` on a terminal's stderr, or `json`, one line per step on
    /// stdout for a farm manager (one-process renders; see docs/farms.md).
    #[arg(long = "progress", value_enum, default_value_t = ProgressArg::Bar)]
    pub progress: ProgressArg,
    #[command(flatten)]
    pub view: ViewArgs,
}

/// The `--aovs` list (a type of its own, so clap takes it as one value).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AovList(pub Vec<Aov>);

fn parse_aovs(text: &str) -> Result<AovList, String> {
    Aov::parse_list(text).map(AovList)
}

impl RenderArgs {
    /// The frames asked for (`--frames`, `--frame`), None for a still image.
    pub fn frames(&self) -> Result<Option<crate::frames::Frames>, String> {
        let range = match (self.frames, self.frame) {
            (Some(r), _) => r,
            (None, Some(n)) => crate::frames::FrameRange { first: n, last: n },
            (None, None) => return Ok(None),
        };
        crate::frames::Frames::new(range, self.fps).map(Some)
    }

    /// The data layers to write: `--aovs`, or the default set.
    pub fn aovs(&self) -> Vec<Aov> {
        self.aovs
            .as_ref()
            .map_or_else(|| Aov::DEFAULT.to_vec(), |l| l.0.clone())
    }
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProgressArg {
    /// A bar on stderr when it is a terminal (nothing otherwise, nor with --quiet).
    Bar,
    /// One JSON object per line on stdout: phase, fraction, elapsed and remaining seconds.
    Json,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DenoiseQualityArg {
    Fast,
    Balanced,
    High,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeArg {
    /// One process, threads over tiles (the default without mpirun).
    Serial,
    /// Every worker keeps a private cache.
    Noshare,
    /// Workers exchange records through the master controller (Robertson et al.).
    #[value(alias = "centralized")]
    Centralised,
    /// Workers send their records to every other rank (Koholka et al.).
    Broadcast,
    /// PRs render all but indirect diffuse; PAs own the cache (Debattista et al.).
    Component,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CacheBuildArg {
    Prepass,
    Progressive,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeepArg {
    Paths,
    Records,
    Grid,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirectArg {
    Analytic,
    Sampled,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum MetricArg {
    Hessian,
    Ward88,
}

#[derive(Args, Debug, Clone, Default)]
pub struct ViewArgs {
    /// -vp x y z: view point (read in double precision: a scene may sit far from the origin).
    #[arg(long = "vp", num_args = 3, allow_negative_numbers = true)]
    pub vp: Option<Vec<f64>>,
    /// -vd x y z: view direction.
    #[arg(long = "vd", num_args = 3, allow_negative_numbers = true)]
    pub vd: Option<Vec<f32>>,
    /// -vu x y z: view up.
    #[arg(long = "vu", num_args = 3, allow_negative_numbers = true)]
    pub vu: Option<Vec<f32>>,
    /// -vh: horizontal view angle in degrees (-vtl: width).
    #[arg(long = "vh", allow_negative_numbers = true)]
    pub vh: Option<f32>,
    /// -vv: vertical view angle in degrees (-vtl: height).
    #[arg(long = "vv", allow_negative_numbers = true)]
    pub vv: Option<f32>,
    /// -vtv: perspective view (default).
    #[arg(long = "vtv")]
    pub vtv: bool,
    /// -vtl: parallel (orthographic) view.
    #[arg(long = "vtl", conflicts_with = "vtv")]
    pub vtl: bool,
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    pub scene: PathBuf,
    /// Let the scene read buffers and images outside its own folder (refused by default).
    #[arg(long = "allow-outside-refs")]
    pub allow_outside_refs: bool,
    /// Describe the scene with every shared mesh copied per placement (as `render --flatten`).
    #[arg(long = "flatten")]
    pub flatten: bool,
    /// Print the description as JSON.
    #[arg(long = "json")]
    pub json: bool,
}

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The image to judge.
    pub image: PathBuf,
    /// The reference it is judged against.
    pub reference: PathBuf,
    /// Print the errors as JSON.
    #[arg(long = "json")]
    pub json: bool,
}

#[derive(Args, Debug)]
pub struct SeamsArgs {
    /// The image (an icrender EXR, or any RGB EXR).
    pub image: PathBuf,
    /// The tile grid to measure against, WxH (the render's own is in its header).
    #[arg(long = "tile", default_value = "32x32")]
    pub tile: String,
    /// The layer: indirect, direct, specular, emission, or composite.
    #[arg(long = "layer", default_value = "indirect")]
    pub layer: String,
    /// Only pixels in x0,y0,x1,y1 (a surface of interest, say a ceiling).
    #[arg(long = "region")]
    pub region: Option<String>,
    /// Print the report as JSON.
    #[arg(long = "json")]
    pub json: bool,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub which: BenchCommand,
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Embree ray throughput on a scene: load and BVH build time, primary and incoherent rays.
    Rays {
        scene: PathBuf,
        /// Seconds spent on each kind of ray.
        #[arg(long = "seconds", default_value_t = 2.0)]
        seconds: f64,
        /// Threads for the second, parallel measurement (default: every core).
        #[arg(long = "threads")]
        threads: Option<usize>,
        /// Copy every placement of shared meshes into world space instead of instancing them
        /// (as `render --flatten`).
        #[arg(long = "flatten")]
        flatten: bool,
        /// The view the primary rays (and the shadow rays' surfaces) come from, as for render
        /// (default: the automatic view).
        #[command(flatten)]
        view: ViewArgs,
        /// Write the shadow rays (origin and offset to the emitter point, or to the punctual
        /// light in a scene without emitters; 6 little-endian f32 each) to FILE, to trace the
        /// same rays in another scene with --shadow-rays.
        #[arg(long = "save-shadow-rays", value_name = "FILE")]
        save_shadow_rays: Option<PathBuf>,
        /// Trace the shadow rays saved in FILE (by --save-shadow-rays) instead of making them.
        #[arg(long = "shadow-rays", value_name = "FILE", conflicts_with = "save_shadow_rays")]
        shadow_rays: Option<PathBuf>,
    },
    /// Message cost between two MPI ranks (run under `mpirun -np 2`): round trips at several
    /// sizes, and the latency and bandwidth fitted to them, as JSON on rank 0. What the cluster
    /// simulation (bench/icsim.py) takes as a link's cost.
    Messages {
        /// Message sizes in bytes, comma-separated. The default stays below Open MPI's eager
        /// limit (64 KiB over TCP), where nearly all of the renderer's messages are: larger ones
        /// go by rendezvous, whose extra round trips would be fitted as bandwidth.
        #[arg(long = "sizes", default_value = "8,512,2048,8192,32768")]
        sizes: String,
    },
}

/// A count too large for u32 (seeds, threads): clap's own parser of these says only "invalid
/// digit", so the range is spelled out as clap does for the u32 options.
pub fn whole_number<T: std::str::FromStr + std::fmt::Display + num_bounds::Max>(text: &str) -> Result<T, String> {
    text.trim()
        .parse()
        .map_err(|_| format!("{text} is not in 0..={} (a whole number)", T::MAX))
}

mod num_bounds {
    /// The largest value of an unsigned count type.
    pub trait Max {
        const MAX: Self;
    }
    impl Max for u64 {
        const MAX: u64 = u64::MAX;
    }
    impl Max for usize {
        const MAX: usize = usize::MAX;
    }
    impl Max for u32 {
        const MAX: u32 = u32::MAX;
    }
}

/// A memory size in bytes from "512" (MiB), "512M", "1.5G", "800K" or "2T".
pub fn parse_memory(text: &str) -> Result<u64, String> {
    let text = text.trim();
    let (number, unit) = match text.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => (&text[..i], c.to_ascii_uppercase()),
        _ => (text, 'M'),
    };
    let scale: f64 = match unit {
        'K' => 1024.0,
        'M' => 1024.0 * 1024.0,
        'G' => 1024.0 * 1024.0 * 1024.0,
        'T' => 1024.0 * 1024.0 * 1024.0 * 1024.0,
        _ => return Err(format!("{text:?}: unknown unit (use K, M, G or T)")),
    };
    let value: f64 = number
        .trim()
        .parse()
        .map_err(|_| format!("{text:?} is not a memory size such as 512M or 4G"))?;
    let bytes = value * scale;
    if !(1.0..1e18).contains(&bytes) {
        return Err(format!("{text:?} is not a usable memory size"));
    }
    Ok(bytes as u64)
}

/// Parses "WxH" (or a single number for square tiles).
pub fn parse_tile(text: &str) -> Result<(u32, u32), String> {
    let bad = || format!("--tile {text}: expected WxH with positive whole numbers, e.g. 32x32");
    let (w, h) = match text.split_once(['x', 'X']) {
        Some((w, h)) => (
            w.trim().parse::<u32>().map_err(|_| bad())?,
            h.trim().parse::<u32>().map_err(|_| bad())?,
        ),
        None => {
            let n = text.trim().parse::<u32>().map_err(|_| bad())?;
            (n, n)
        }
    };
    if w == 0 || h == 0 {
        return Err(bad());
    }
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn memory_sizes() {
        assert_eq!(parse_memory("512").unwrap(), 512 << 20);
        assert_eq!(parse_memory("2G").unwrap(), 2 << 30);
        assert_eq!(parse_memory("1.5g").unwrap(), 3 << 29);
        assert_eq!(parse_memory("800K").unwrap(), 800 << 10);
        assert!(parse_memory("12Q").is_err());
        assert!(parse_memory("lots").is_err());
        assert!(parse_memory("0").is_err());
        assert!(parse_memory("-5G").is_err());
    }

    #[test]
    fn radiance_names_become_long_options() {
        let args = rewrite_radiance_options(
            [
                "icrender", "render", "s.gltf", "-ab", "2", "-vd", "0", "0", "-1", "-x", "8",
            ]
            .map(String::from),
        );
        assert_eq!(args[3], "--ab");
        assert_eq!(args[5], "--vd");
        assert_eq!(args[8], "-1");
        assert_eq!(args[9], "-x");
        let cli = Cli::try_parse_from(args).unwrap();
        let Command::Render(r) = cli.command else {
            panic!("not render")
        };
        assert_eq!(r.ambient_bounces, 2);
        assert_eq!(r.view.vd, Some(vec![0.0, 0.0, -1.0]));
        assert_eq!(r.width, 8);
    }

    #[test]
    fn tiles_parse() {
        assert_eq!(parse_tile("16x8"), Ok((16, 8)));
        assert_eq!(parse_tile("24"), Ok((24, 24)));
        assert!(parse_tile("0x8").is_err());
        assert!(parse_tile("axb").is_err());
    }
}
