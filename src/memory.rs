//! `--max-memory`: what a render will need, estimated before the expensive parts start, so a
//! job that cannot fit is refused with the estimate instead of being killed hours in.
//!
//! The figures per item were measured on this project's scenes (see the comments); the
//! estimate is per process, since that is what a cluster's scheduler limits.

use crate::scene::Scene;

/// Private memory of the runtime before any scene: heaps and pools of Embree, Open MPI and
/// OpenImageIO, thread stacks (a 300x300 render of the Cornell box: 48 MB private dirty pages;
/// the shared libraries' pages are shared and reclaimable, so they are not counted).
const RUNTIME_BYTES: u64 = 48 << 20;
/// Embree's BVH per triangle (the conference room: about 100 bytes per triangle in the process's
/// peak memory after the build; rounded up), with the tracer's own 4 bytes a textured
/// triangle (`Tracer`'s `uv_per_length`) inside the rounding.
const BVH_BYTES_PER_TRIANGLE: u64 = 128;
/// One pixel of a frame: four RGB float layers, the records plane and the data layers.
const FRAME_BYTES_PER_PIXEL: u64 = 4 * 12 + 4 + 4 * crate::image::data::DATA_VALUES as u64;
/// One record in the cache with its place in the index.
const RECORD_BYTES: u64 = 320;
/// One queued L_a request on a PA.
const REQUEST_BYTES: u64 = 160;

/// How a process takes part in the render, which decides how many copies of the frame it holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// One process: its frame and the planes written out.
    Single,
    /// An MPI master: its frame, and a worker's frame as received, decoded and summed.
    Master,
    /// An MPI worker: its frame, and the same as floats and bytes when it is sent.
    Worker,
    /// Any rank of an MPI job: the larger of the master's and a worker's needs, so that every
    /// rank reaches the same verdict.
    AnyRank,
}

/// The estimate, by item.
#[derive(Clone, Copy, Debug, Default)]
pub struct Estimate {
    pub runtime: u64,
    pub scene: u64,
    pub bvh: u64,
    pub images: u64,
    pub cache: u64,
    pub queue: u64,
}

/// What the estimate needs to know about the job beyond the scene.
#[derive(Clone, Copy)]
pub struct Job {
    /// The pixels rendered: the image's, or a --region task's region's (its frame holds no more).
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub ambient_bounces: u32,
    /// Whether an irradiance cache is used at all.
    pub cache: bool,
    /// The bound of a PA's request queue, when a worker may be a PA (a master never is).
    pub pa_queue: Option<u32>,
    pub role: Role,
}

/// Records a render makes per sample, by -ab: measured on the Cornell box at -aa 0.2, 1.4 % of
/// the samples at -ab 1 and 17 % at -ab 2 (each bounce makes records at the points the
/// previous level's hemisphere rays reach); taken as 3 % and six times more per further bounce.
fn records_per_sample(bounces: u32) -> f64 {
    if bounces == 0 {
        return 0.0;
    }
    let per = 0.03 * 6f64.powi(bounces as i32 - 1);
    // A record per sample and level at most (an -aa so small that nothing is reused).
    per.min(bounces as f64)
}

impl Estimate {
    pub fn of(scene: &Scene, job: &Job) -> Estimate {
        if job.role == Role::AnyRank {
            let as_role = |role| Estimate::of(scene, &Job { role, ..*job });
            let (master, worker) = (as_role(Role::Master), as_role(Role::Worker));
            return if master.total() >= worker.total() {
                master
            } else {
                worker
            };
        }
        let pixels = job.width as u64 * job.height as u64;
        let frames = match job.role {
            Role::Single => 2,
            Role::Master => 4,
            Role::Worker | Role::AnyRank => 3,
        };
        let samples = pixels as f64 * job.spp.max(1) as f64;
        Estimate {
            runtime: RUNTIME_BYTES,
            scene: scene.memory_bytes(),
            bvh: scene.stored_triangle_count() as u64 * BVH_BYTES_PER_TRIANGLE,
            images: frames * pixels * FRAME_BYTES_PER_PIXEL,
            cache: if job.cache {
                (samples * records_per_sample(job.ambient_bounces)) as u64 * RECORD_BYTES
            } else {
                0
            },
            queue: match job.role {
                Role::Master | Role::Single => 0,
                _ => job.pa_queue.map_or(0, |q| q as u64 * REQUEST_BYTES),
            },
        }
    }

    pub fn total(&self) -> u64 {
        self.runtime + self.scene + self.bvh + self.images + self.cache + self.queue
    }

    /// "1.2 GiB (runtime 48.0 MiB, scene ..., ...)".
    pub fn describe(&self) -> String {
        let mut parts = vec![
            format!("runtime {}", human(self.runtime)),
            format!("scene {}", human(self.scene)),
            format!("BVH {}", human(self.bvh)),
            format!("images {}", human(self.images)),
        ];
        if self.cache > 0 {
            parts.push(format!("irradiance cache {}", human(self.cache)));
        }
        if self.queue > 0 {
            parts.push(format!("PA request queue {}", human(self.queue)));
        }
        format!("{} ({})", human(self.total()), parts.join(", "))
    }
}

/// The process's peak resident memory so far (Linux's `VmHWM` in /proc/self/status): what a
/// farm task needs to be given. None where the system does not say.
pub fn peak_resident_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find_map(|l| l.strip_prefix("VmHWM:"))?;
    let kib: u64 = line.trim().strip_suffix("kB")?.trim().parse().ok()?;
    Some(kib * 1024)
}

/// Bytes in binary units with one decimal.
pub fn human(bytes: u64) -> String {
    let units = ["bytes", "KiB", "MiB", "GiB", "TiB"];
    let mut value = bytes as f64;
    let mut unit = 0;
    while value >= 1024.0 && unit + 1 < units.len() {
        value /= 1024.0;
        unit += 1;
    }
    if unit == 0 {
        format!("{bytes} bytes")
    } else {
        format!("{value:.1} {}", units[unit])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_grow_with_bounces_but_stay_bounded() {
        assert_eq!(records_per_sample(0), 0.0);
        assert!((records_per_sample(1) - 0.03).abs() < 1e-12);
        assert!((records_per_sample(2) - 0.18).abs() < 1e-12);
        assert!(records_per_sample(8) <= 8.0);
    }

    #[test]
    fn the_peak_resident_memory_holds_what_was_touched() {
        // 64 MiB written, so resident; the peak can only be at least that while it is held.
        let held = vec![1u8; 64 << 20];
        let peak = peak_resident_bytes().expect("Linux reports VmHWM");
        assert!(peak >= 64 << 20, "peak {peak} bytes while 64 MiB are resident");
        assert_eq!(held.iter().map(|&b| b as usize).sum::<usize>(), 64 << 20);
    }

    #[test]
    fn human_units() {
        assert_eq!(human(512), "512 bytes");
        assert_eq!(human(1536), "1.5 KiB");
        assert_eq!(human(3 << 30), "3.0 GiB");
    }
}
