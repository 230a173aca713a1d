//! `icrender bench rays`: how fast Embree traces this scene's rays, outside the renderer, so the
//! renderer's own throughput has a ceiling to be compared with; with the load and BVH build
//! times and the process's peak memory, what instancing saves (`--flatten` for the copies). `icrender bench messages`: what
//! a message costs between two MPI ranks (link.rs: it talks MPI directly, for this command
//! alone, and shares nothing with the renderer's MPI modes).

mod link;

use super::{CommandError, CommandResult};
use crate::cli::{BenchArgs, BenchCommand, ViewArgs};
use crate::sampling::Rng;
use crate::scene::{LoadOptions, Scene};
use crate::sys::embree::Coherence;
use crate::tracer::Tracer;
use glam::Vec3;
use std::path::Path;
use std::time::Instant;

/// What one ray of a measurement asks Embree.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Query {
    /// The closest hit, with the given coherence.
    Closest(Coherence),
    /// Whether anything blocks the segment (a shadow ray): the ray's length is its direction's.
    Occluded,
}

/// What a measurement found: Mrays per second of wall clock, Mrays per second of the tracing
/// threads' CPU time (what a shared machine's other work disturbs least), and the fraction of
/// rays that hit (were blocked, for shadow rays).
struct Rate {
    wall: f64,
    cpu: f64,
    hit: f64,
}

/// Traces `make_ray(i)` for i = 0, 1, ... on `threads` threads for about `seconds`.
fn throughput(
    tracer: &Tracer,
    threads: usize,
    seconds: f64,
    query: Query,
    make_ray: &(dyn Fn(u64) -> (Vec3, Vec3) + Sync),
) -> Rate {
    let start = Instant::now();
    let results: Vec<(u64, u64, f64)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|t| {
                scope.spawn(move || {
                    let cpu = cpu_time::ThreadTime::now();
                    let (mut rays, mut hits) = (0u64, 0u64);
                    let mut i = t as u64 * (1 << 40);
                    while start.elapsed().as_secs_f64() < seconds {
                        for _ in 0..4096 {
                            let (o, d) = make_ray(i);
                            i += 1;
                            hits += match query {
                                Query::Closest(coherence) => tracer.raw_intersect(o, d, coherence).is_some(),
                                Query::Occluded => tracer.segment_blocked(o, o + d),
                            } as u64;
                        }
                        rays += 4096;
                    }
                    (rays, hits, cpu.elapsed().as_secs_f64())
                })
            })
            .collect();
        workers.into_iter().map(|w| w.join().unwrap_or((0, 0, 0.0))).collect()
    });
    let elapsed = start.elapsed().as_secs_f64();
    let rays: u64 = results.iter().map(|r| r.0).sum();
    let hits: u64 = results.iter().map(|r| r.1).sum();
    let cpu: f64 = results.iter().map(|r| r.2).sum();
    Rate {
        wall: rays as f64 / elapsed / 1e6,
        cpu: rays as f64 / cpu.max(1e-9) / 1e6,
        hit: hits as f64 / rays.max(1) as f64,
    }
}

pub fn run(args: &BenchArgs) -> CommandResult {
    match &args.which {
        BenchCommand::Rays {
            scene,
            seconds,
            threads,
            flatten,
            view,
            save_shadow_rays,
            shadow_rays,
        } => rays(
            scene,
            &RaysOptions {
                seconds: *seconds,
                threads: *threads,
                flatten: *flatten,
                view,
                save_shadow_rays: save_shadow_rays.as_deref(),
                shadow_rays: shadow_rays.as_deref(),
            },
        ),
        BenchCommand::Messages { sizes } => messages(sizes),
    }
}

fn messages(sizes: &str) -> CommandResult {
    let sizes = sizes
        .split(',')
        .map(|s| s.trim().parse::<usize>())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| CommandError::input(format!("--sizes {sizes:?}: {e} (bytes, comma-separated)")))?;
    // 4 MiB in 32 KiB messages: past a capped link's burst allowance, under the eager limit.
    let Some(measured) = link::measure(&sizes, 32 << 10, 128).map_err(CommandError::input)? else {
        return Ok(());
    };
    let fitted = link::fit(&measured);
    let report = serde_json::json!({
        "stream_bytes": measured.stream_bytes,
        "stream_s": measured.stream_s,
        "samples": measured.samples.iter().map(|s| serde_json::json!({"bytes": s.bytes, "round_trip_s": s.round_trip_s}))
            .collect::<Vec<_>>(),
        "latency_s": fitted.map(|f| f.latency_s),
        "bandwidth_bytes_per_s": fitted.map(|f| f.bandwidth),
    });
    println!("{report}");
    Ok(())
}

/// What `bench rays` was asked for beside the scene.
struct RaysOptions<'a> {
    seconds: f64,
    threads: Option<usize>,
    flatten: bool,
    view: &'a ViewArgs,
    save_shadow_rays: Option<&'a Path>,
    shadow_rays: Option<&'a Path>,
}

fn rays(path: &Path, options: &RaysOptions<'_>) -> CommandResult {
    let RaysOptions {
        seconds,
        threads,
        flatten,
        view,
        ..
    } = *options;
    let load_start = Instant::now();
    let load_options = LoadOptions {
        flatten,
        ..LoadOptions::default()
    };
    let scene = Scene::load(path, &load_options)?;
    let load_s = load_start.elapsed().as_secs_f64();
    let build_start = Instant::now();
    let tracer = Tracer::new(&scene)?;
    let build_s = build_start.elapsed().as_secs_f64();
    // Before any ray: what loading and building took at most.
    let peak = peak_memory();
    let (width, height) = (1024u32, 1024u32);
    let (view, _) = crate::commands::view::choose_view(&scene, &tracer, view, width, height, None)?;
    let camera = view.camera(width, height);
    let primary = |i: u64| {
        let p = i % (width as u64 * height as u64);
        camera.ray((p % width as u64) as f32 + 0.5, (p / width as u64) as f32 + 0.5)
    };
    let (lo, hi) = (scene.bounds_min, scene.bounds_max);
    let incoherent = |i: u64| {
        let mut rng = Rng::new(i, 99);
        let o = lo + (hi - lo) * Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32());
        let z = 2.0 * rng.next_f32() - 1.0;
        let phi = 2.0 * std::f32::consts::PI * rng.next_f32();
        let r = (1.0 - z * z).max(0.0).sqrt();
        (o, Vec3::new(r * phi.cos(), r * phi.sin(), z))
    };
    // Shadow rays as the renderer casts them: from the surfaces the view sees to a point on an
    // emitter the light tree picks for that surface, stopping short of the emitter (in a scene
    // lit by punctual lights alone, to each light in turn). Made before the clock starts:
    // picking through the light tree is not the ray's cost (x32's tree holds 32 times the
    // single room's emitters).
    let shading_points: Vec<(Vec3, Vec3)> = (0..4096u64)
        .filter_map(|i| {
            let (o, d) = primary(i.wrapping_mul(2_654_435_761) % (width as u64 * height as u64));
            let hit = tracer.intersect(&scene, o, d, Coherence::Incoherent)?;
            Some((tracer.spawn_point(&hit, hit.facing_normal), hit.facing_normal))
        })
        .collect();
    let segments: Vec<(Vec3, Vec3)> = match options.shadow_rays {
        Some(file) => read_segments(file)?,
        None => (0..(1u64 << 16))
            .filter_map(|i| {
                let (p, n) = *shading_points.get((i % shading_points.len().max(1) as u64) as usize)?;
                if scene.emitters.is_empty() {
                    return punctual_shadow_ray(&scene, p, n, i);
                }
                let mut rng = Rng::new(i, 7);
                let light = scene
                    .emitters
                    .sample(p, n, rng.next_f32(), rng.next_f32(), rng.next_f32())?;
                Some((p, (light.position - p) * 0.999))
            })
            .collect(),
    };
    if let Some(file) = options.save_shadow_rays {
        let bytes: Vec<u8> = (segments.iter())
            .flat_map(|(o, d)| [o.to_array(), d.to_array()])
            .flatten()
            .flat_map(f32::to_le_bytes)
            .collect();
        std::fs::write(file, bytes).map_err(|e| CommandError::failed(format!("{}: {e}", file.display())))?;
    }
    let shadow = |i: u64| segments[(i % segments.len() as u64) as usize];
    // Hemisphere rays as a record casts them: cosine-distributed rays from the surfaces the view
    // sees, eight from each point. They cost Embree more than the incoherent rays above, which
    // start anywhere in the bounds (on the conference room 0.75x their rate, on Sibenik 0.61x;
    // traced eight at a time as Embree packets, rtcIntersect8, they were no faster: 0.98x).
    let hemisphere = |i: u64| {
        let (p, n) = shading_points[((i / 8) % shading_points.len() as u64) as usize];
        let mut rng = Rng::new(i, 5);
        (p, crate::sampling::cosine_hemisphere(n, rng.next_f32(), rng.next_f32()))
    };
    let all = threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    println!(
        "scene        {} ({} triangles, {} stored{})",
        path.display(),
        scene.triangle_count(),
        scene.stored_triangle_count(),
        if flatten { ", --flatten" } else { "" }
    );
    if !scene.instancing.is_empty() {
        println!(
            "instancing   {} shared meshes in {} placements, {} Embree instances of {} prototypes",
            scene.instancing.meshes.len(),
            scene.instancing.placements.len(),
            scene.instancing.instances.len(),
            scene.instancing.prototypes.len()
        );
    }
    println!("embree       {} ", tracer.embree_version);
    println!("load         {load_s:.3} s");
    println!("bvh build    {build_s:.3} s");
    match peak {
        Some(bytes) => println!("peak memory  {:.1} MB (after the build)", bytes as f64 / 1e6),
        None => println!("peak memory  unknown (no /proc/self/status)"),
    }
    for t in [1, all] {
        let p = throughput(&tracer, t, seconds, Query::Closest(Coherence::Coherent), &primary);
        let r = throughput(&tracer, t, seconds, Query::Closest(Coherence::Incoherent), &incoherent);
        if !shading_points.is_empty() {
            let h = throughput(&tracer, t, seconds, Query::Closest(Coherence::Incoherent), &hemisphere);
            println!(
                "{t} thread(s)  hemisphere {:.2} Mrays/s ({:.0}% hit)",
                h.wall,
                h.hit * 100.0
            );
        }
        let shadows = (!segments.is_empty()).then(|| throughput(&tracer, t, seconds, Query::Occluded, &shadow));
        print!(
            "{t} thread(s)  primary {:.2} Mrays/s ({:.0}% hit)   incoherent {:.2} Mrays/s ({:.0}% hit)",
            p.wall,
            p.hit * 100.0,
            r.wall,
            r.hit * 100.0
        );
        match &shadows {
            Some(s) => println!("   shadow {:.2} Mrays/s ({:.0}% blocked)", s.wall, s.hit * 100.0),
            None => println!(),
        }
        print!(
            "{t} thread(s)  per CPU second: primary {:.2} Mrays   incoherent {:.2} Mrays",
            p.cpu, r.cpu
        );
        match &shadows {
            Some(s) => println!("   shadow {:.2} Mrays", s.cpu),
            None => println!(),
        }
        if all == 1 {
            break;
        }
    }
    Ok(())
}

/// A shadow ray from `p` (facing `n`) to punctual light number `i` (modulo their count), as
/// the renderer casts one: to the light's position, or for a directional light across the
/// scene. None where the light does not reach the point's front.
fn punctual_shadow_ray(scene: &Scene, p: Vec3, n: Vec3, i: u64) -> Option<(Vec3, Vec3)> {
    let lights = &scene.punctual_lights;
    let light = lights.get((i % lights.len().max(1) as u64) as usize)?;
    let sample = light.illuminate(p)?;
    if sample.to_light.dot(n) <= 0.0 {
        return None;
    }
    let across = (scene.bounds_max - scene.bounds_min).length() * 2.0;
    let reach = if sample.distance.is_finite() {
        sample.distance * 0.999
    } else {
        across
    };
    Some((p, sample.to_light * reach))
}

/// Shadow rays written by --save-shadow-rays.
fn read_segments(file: &Path) -> Result<Vec<(Vec3, Vec3)>, CommandError> {
    let bad = |why: String| CommandError::input(format!("{}: {why}", file.display()));
    let bytes = std::fs::read(file).map_err(|e| bad(e.to_string()))?;
    if bytes.is_empty() || !bytes.len().is_multiple_of(24) {
        return Err(bad(format!(
            "{} bytes is not a list of shadow rays (24 bytes each)",
            bytes.len()
        )));
    }
    let values: Vec<f32> = (bytes.chunks_exact(4))
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    Ok(values
        .chunks_exact(6)
        .map(|v| (Vec3::new(v[0], v[1], v[2]), Vec3::new(v[3], v[4], v[5])))
        .collect())
}

/// The process's peak resident memory so far (Linux's VmHWM), in bytes.
fn peak_memory() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}
