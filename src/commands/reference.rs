//! `icrender reference`: a converged image to measure renders against. Brute force (no cache),
//! rendered in passes with different seeds until its own estimated noise is below a target.
//! The noise is estimated from two independent halves of the passes: their difference has
//! twice the variance of each half, so the combined image's standard error is RMS(A - B) / 2.

use super::render::{Outputs, job_stats, output_name};
use super::{CommandError, CommandResult};
use crate::cli::ReferenceArgs;
use crate::frames::{FrameTag, NamePattern};
use crate::image::framebuffer::FrameBuffer;
use crate::image::metrics;
use crate::job::{Job, validate};
use crate::progress::Progress;
use crate::render::pixel::ThreadStats;
use crate::render::render;
use crate::shading::Integrator;
use crate::stats::RenderStats;
use std::time::Instant;

/// Estimated relative noise of the mean of two independent half-images: the square root of
/// the mean of var / (value^2 + 0.01), the same normalisation as `compare`'s relative MSE,
/// so the reference's own noise is directly comparable with the errors measured against it.
pub fn noise_of_halves(a: &FrameBuffer, b: &FrameBuffer) -> f64 {
    let (ca, cb) = (a.composite(), b.composite());
    let mut sum = 0.0f64;
    for (x, y) in ca.iter().zip(&cb) {
        for c in 0..3 {
            let d = (x[c] - y[c]) as f64;
            let m = 0.5 * (x[c] + y[c]) as f64;
            sum += d * d / 4.0 / (m * m + metrics::REL_EPSILON);
        }
    }
    (sum / (ca.len() * 3).max(1) as f64).sqrt()
}

pub fn run(args: &ReferenceArgs) -> CommandResult {
    let wall = Instant::now();
    let mut render_args = args.render.clone();
    render_args.ambient_accuracy = 0.0;
    render_args.ambient_file = None;
    // The ratio estimator's penumbra bias does not average away over passes: a reference
    // samples plainly.
    render_args.direct = crate::cli::DirectArg::Sampled;
    validate(&render_args)?;
    if render_args.denoise {
        return Err(CommandError::input(
            "--denoise: a reference is converged brute force, to measure renders (and denoised ones) against; \
             denoising it would make it something else"
                .into(),
        ));
    }
    if !(args.noise > 0.0 && args.max_seconds > 0.0) {
        return Err(CommandError::input("--noise and --max-seconds must be positive".into()));
    }
    // One frame of the camera's animation (--frame N) is one image; a sequence is not.
    let outputs = match render_args.frames()? {
        Some(frames) if frames.count() > 1 => {
            return Err(CommandError::input(
                "--frames: a reference is one image: give --frame N for one frame of the animation".into(),
            ));
        }
        Some(frames) => {
            let n = frames.range.first;
            let name = |p: &std::path::Path| NamePattern::new(p, 1).map(|pattern| pattern.path(n));
            let exr = name(&output_name(&render_args)).map_err(|e| CommandError::input(format!("-o {e}")))?;
            let stats = (render_args.stats.as_deref().map(name).transpose())
                .map_err(|e| CommandError::input(format!("--stats {e}")))?;
            Outputs::checked(&render_args, exr, stats, Some(FrameTag::of(&frames, n)))?
        }
        None => Outputs::check(&render_args)?,
    };
    let mut job = Job::prepare(&render_args, crate::memory::Role::Single)?;
    // Every pass places its samples anew over each pixel: the reference integrates the pixel's
    // area, as a box-filtered render converges to.
    job.settings.jitter = true;
    // Points: a footprint would blur what the passes' mean integrates exactly.
    job.settings.texture_footprint = false;
    // Every pixel alike: the passes' mean is the box filter's integral with no pixel weighed
    // by more samples than its neighbours.
    job.settings.edge_samples = 0;
    let base_seed = job.settings.seed;
    let (w, h) = (render_args.width, render_args.height);
    let mut halves = [FrameBuffer::new(w, h), FrameBuffer::new(w, h)];
    let mut counts = [0u32; 2];
    let mut thread_stats: Vec<ThreadStats> = Vec::new();
    let mut noise = f64::INFINITY;
    let render_start = Instant::now();
    let mut pass = 0u64;
    while pass < 2 || (noise > args.noise && render_start.elapsed().as_secs_f64() < args.max_seconds) {
        job.settings.seed = base_seed.wrapping_add(pass.wrapping_mul(0x9e37_79b9));
        let integrator = Integrator::new(&job.scene, &job.tracer, &job.shading, None);
        let progress = Progress::new(0, true);
        let rendered = render(&integrator, &job.camera, &job.settings, &progress);
        let frame = rendered.frame.expect("a render without a stream holds its frame");
        add_pass(&mut thread_stats, &rendered.threads);
        let half = (pass % 2) as usize;
        halves[half].accumulate(&frame);
        counts[half] += 1;
        pass += 1;
        if counts[0] > 0 && counts[1] > 0 {
            let mut a = halves[0].clone();
            a.scale(1.0 / counts[0] as f32);
            let mut b = halves[1].clone();
            b.scale(1.0 / counts[1] as f32);
            noise = noise_of_halves(&a, &b);
        }
        if !render_args.quiet {
            eprintln!(
                "icrender: reference pass {pass}: estimated noise {:.3}% after {:.1} s",
                noise * 100.0,
                render_start.elapsed().as_secs_f64()
            );
        }
    }
    let render_s = render_start.elapsed().as_secs_f64();
    let [mut frame, second] = halves;
    frame.accumulate(&second);
    frame.scale(1.0 / pass as f32);

    let mut stats = RenderStats {
        spp: render_args.spp * pass as u32,
        reference_noise: Some(noise),
        reference_passes: Some(pass),
        ..job_stats(&render_args, &job, "reference", 1, render_s)
    };
    stats.add_threads(&thread_stats);
    stats.wall_s = wall.elapsed().as_secs_f64();
    outputs.write(&render_args, &job, &frame, &stats)?;
    if !render_args.quiet {
        eprintln!(
            "icrender: reference {}x{}: {} passes, {} samples per pixel, estimated noise {:.3}% in {:.1} s -> {}",
            w,
            h,
            pass,
            stats.spp,
            noise * 100.0,
            render_s,
            outputs.exr.display()
        );
    }
    Ok(())
}

/// Adds a pass's threads to the reference's, thread by thread: the statistics list each thread
/// once with all its passes' work, not once a pass (a reference of 380 passes on 2 threads
/// wrote 760 entries, 200 KB of the EXR's header).
fn add_pass(threads: &mut Vec<ThreadStats>, pass: &[ThreadStats]) {
    for (i, t) in pass.iter().enumerate() {
        match threads.get_mut(i) {
            Some(total) => {
                total.absorb(t);
                total.tiles += t.tiles;
            }
            None => threads.push(t.clone()),
        }
    }
}
