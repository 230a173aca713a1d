//! `--checkpoint DIR`: renders killed with SIGKILL at moments spread over the render (the single
//! process; and under mpirun in component mode, the master, a PA, a PR or mpirun itself) and
//! started again with the same command resume: no finished tile is rendered again, and the
//! image matches an uninterrupted render within the cache's own error.

mod common;
use common::*;
use icrender::checkpoint;
use icrender::tiles::tiles;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant, SystemTime};

const KILLS: usize = 5;

/// How a render is started: in one process or under mpirun with `np` ranks.
#[derive(Clone, Copy)]
enum Launch {
    Single,
    Mpi(usize),
}

impl Launch {
    fn command(self, args: &[String]) -> Command {
        match self {
            Launch::Single => {
                let mut cmd = Command::new(binary());
                cmd.args(args);
                cmd
            }
            Launch::Mpi(np) => mpirun_command(np, args),
        }
    }
}

fn render_args(scene: &Path, out: &Path, stats: &Path, checkpoint: Option<&Path>, extra: &[&str]) -> Vec<String> {
    let mut args: Vec<String> = [
        "render",
        scene.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
        "-q",
        "--no-preview",
        "--timeout",
        "60",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    if let Some(dir) = checkpoint {
        args.extend(["--checkpoint".to_string(), dir.to_str().unwrap().to_string()]);
    }
    args.extend(extra.iter().map(|s| s.to_string()));
    args
}

fn finish(child: Child, what: &str) -> Output {
    let output = child.wait_with_output().unwrap();
    assert!(
        output.status.success(),
        "{what} failed:\n{}{}",
        stdout(&output),
        stderr(&output)
    );
    output
}

fn read_stats(path: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn tiles_rendered(stats: &Value) -> u64 {
    stats["per_rank"]
        .as_array()
        .map(|ranks| ranks.iter().map(|r| r["tiles"].as_u64().unwrap_or(0)).sum())
        .or_else(|| {
            stats["per_thread"]
                .as_array()
                .map(|t| t.iter().map(|r| r["tiles"].as_u64().unwrap_or(0)).sum())
        })
        .unwrap_or_else(|| panic!("no per-rank or per-thread tiles in {stats}"))
}

/// A pseudo-random fraction in [0, 1) that differs between runs (the kill moments are spread
/// over the render and jittered; the seed is printed so a failure can be retraced).
fn jitter() -> f64 {
    let nanos = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap()
        .subsec_nanos();
    (nanos % 1000) as f64 / 1000.0
}

/// The pid of the process to kill: the single process, or the rank's icrender process under
/// mpirun (rank `None`: mpirun itself), once it exists.
fn victim_pid(child: &Child, marker: &str, rank: Option<u32>, launch: Launch) -> u32 {
    let (Launch::Mpi(_), Some(rank)) = (launch, rank) else {
        return child.id();
    };
    let start = Instant::now();
    loop {
        assert!(start.elapsed() < Duration::from_secs(30), "rank {rank} never started");
        for entry in std::fs::read_dir("/proc").unwrap().flatten() {
            let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() else {
                continue;
            };
            let cmdline =
                String::from_utf8_lossy(&std::fs::read(entry.path().join("cmdline")).unwrap_or_default()).into_owned();
            if !cmdline.contains(marker) || !cmdline.starts_with(binary().to_str().unwrap()) {
                continue;
            }
            let environ = std::fs::read(entry.path().join("environ")).unwrap_or_default();
            let wanted = format!("OMPI_COMM_WORLD_RANK={rank}");
            if environ.split(|&b| b == 0).any(|v| v == wanted.as_bytes()) {
                return pid;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn any_process_with(marker: &str) -> bool {
    std::fs::read_dir("/proc").unwrap().flatten().any(|entry| {
        entry.file_name().to_string_lossy().parse::<u32>().is_ok() && {
            let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
            let cmdline = String::from_utf8_lossy(&cmdline);
            cmdline.contains(marker) && cmdline.starts_with(binary().to_str().unwrap())
        }
    })
}

/// Renders once uninterrupted, then KILLS times: start with a checkpoint, SIGKILL `victims[i]`
/// once the journal holds 10 % .. 80 % of the tiles as finished (spread, jittered), start again
/// with the same command, and check the result. `size` and `tile`: the image's and the tiles'
/// side in pixels, as `extra` gives them.
fn kill_and_resume(
    launch: Launch,
    scene: &Path,
    extra: &[&str],
    victims: &[(&str, Option<u32>)],
    size: u32,
    tile: u32,
) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let whole_out = d.join("whole.exr");
    let whole_stats = d.join("whole.json");
    let started = Instant::now();
    let whole_checkpoint = d.join("checkpoint-whole");
    let child = launch
        .command(&render_args(
            scene,
            &whole_out,
            &whole_stats,
            Some(&whole_checkpoint),
            extra,
        ))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    finish(child, "the uninterrupted render");
    let whole_s = started.elapsed().as_secs_f64();
    let whole = read_exr(&whole_out);
    let stats = read_stats(&whole_stats);
    let render_s = stats["render_s"].as_f64().unwrap();
    let all_tiles = tiles(size, size, tile, tile);
    let total_tiles = tiles_rendered(&stats);

    // The cache's own spread: the same job in another record order (another tile size would
    // change the job, so the check compares against a second uninterrupted run instead).
    let again_out = d.join("again.exr");
    let child = launch
        .command(&render_args(scene, &again_out, &d.join("again.json"), None, extra))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    finish(child, "the second uninterrupted render");
    let own = relmse(&read_exr(&again_out), &whole);
    let tolerance = (4.0 * own).max(1e-3);

    let mut resumed_with_work = 0;
    for (i, (victim_name, rank)) in victims.iter().enumerate().take(KILLS) {
        let marker = format!("killed-{i}.exr");
        let out = d.join(&marker);
        let stats_path = d.join(format!("killed-{i}.json"));
        let checkpoint = d.join(format!("checkpoint-{i}"));
        let args = render_args(scene, &out, &stats_path, Some(&checkpoint), extra);
        let mut child = launch
            .command(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Spread over the render by its progress (finished tiles, not the clock, which a
        // loaded machine stretches, nor the journal's size: in component mode tiles finish
        // only as the PAs' results come in, after most of the journal's bytes).
        let fraction = 0.1 + 0.7 * (i as f64 + jitter()) / KILLS as f64;
        let target = ((fraction * all_tiles.len() as f64).ceil() as usize).max(1);
        let pid = victim_pid(&child, &marker, *rank, launch);
        let waiting = Instant::now();
        while checkpoint::finished_tiles(
            &checkpoint,
            &all_tiles,
            icrender::image::window::PixelWindow::whole(size, size),
        ) < target
        {
            assert!(
                waiting.elapsed() < Duration::from_secs(60),
                "run {i}: the render does not progress"
            );
            std::thread::sleep(Duration::from_millis(2));
        }
        Command::new("kill").args(["-9", &pid.to_string()]).status().unwrap();
        let killed_at = Instant::now();
        let status = child.wait().unwrap();
        assert!(
            killed_at.elapsed() < Duration::from_secs(60),
            "the job did not end after its {victim_name} was killed"
        );
        // No rank outlives the job (a rank whose mpirun was killed ends with it), or it would
        // go on writing to the checkpoint beside the restarted job.
        let ending = Instant::now();
        while any_process_with(&marker) {
            assert!(
                ending.elapsed() < Duration::from_secs(20),
                "run {i}: ranks of the killed job are still running 20 s after the {victim_name} was killed"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        if status.success() {
            panic!("run {i}: the {victim_name} was killed at {fraction:.2} of the tiles but the job succeeded");
        }
        if out.exists() {
            // The kill landed after the job's work was done: the master had every tile and
            // every result and wrote the image (atomically) before mpirun ended the job. What a
            // killed render may leave is the whole image or none, never a part of one.
            let done = checkpoint::finished_tiles(
                &checkpoint,
                &all_tiles,
                icrender::image::window::PixelWindow::whole(size, size),
            );
            assert_eq!(
                done,
                all_tiles.len(),
                "run {i}: a killed render left an image with unfinished tiles"
            );
            let err = relmse(&read_exr(&out), &whole);
            assert!(
                err < tolerance,
                "run {i}: the image a killed render left is not the whole image (relMSE {err:.3e})"
            );
            // The statistics are written after the image: they may be there too, and the
            // restart would refuse to replace them.
            std::fs::remove_file(&out).unwrap();
            if stats_path.exists() {
                std::fs::remove_file(&stats_path).unwrap();
            }
        } else {
            assert!(
                !stats_path.exists(),
                "run {i}: a killed render left statistics without the image they describe"
            );
        }

        let child = launch
            .command(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        finish(child, &format!("run {i}: the restart after killing the {victim_name}"));
        let stats = read_stats(&stats_path);
        let restored = stats["tiles_restored"].as_u64().unwrap();
        let rendered = tiles_rendered(&stats);
        eprintln!(
            "run {i}: killed the {victim_name} at {fraction:.2} of the tiles (render {render_s:.2} s of {whole_s:.2} s); restart restored {restored} and rendered {rendered} of {total_tiles} tiles"
        );
        assert_eq!(
            restored + rendered,
            total_tiles,
            "run {i}: a finished tile was rendered again, or one was missed"
        );
        if restored > 0 && rendered > 0 {
            resumed_with_work += 1;
        }
        let err = relmse(&read_exr(&out), &whole);
        assert!(
            err < tolerance,
            "run {i}: relMSE {err:.3e} against the uninterrupted render (tolerance {tolerance:.3e})"
        );
    }
    assert!(
        resumed_with_work >= 3,
        "only {resumed_with_work} of {KILLS} kills landed between the first finished tile and the last"
    );
}

fn cornell() -> PathBuf {
    project_dir().join("scenes/cornell.gltf")
}

#[test]
fn a_killed_render_resumes_without_redoing_tiles() {
    // 32 samples a pixel make the tiles long enough to be killed among (about 0.9 s for the
    // 100 tiles after the prepass): at 1 they took 0.04 s, the kills often came only after the
    // last, and once just 2 of 5 landed between the first finished tile and the last.
    let extra = [
        "-x", "160", "-y", "160", "-ab", "2", "-ad", "256", "--tile", "16x16", "--spp", "32",
    ];
    let victims = [("process", None); KILLS];
    kill_and_resume(Launch::Single, &cornell(), &extra, &victims, 160, 16);
}

#[test]
fn a_killed_component_render_resumes_whoever_died() {
    let extra = [
        "-x",
        "128",
        "-y",
        "128",
        "-ab",
        "2",
        "-ad",
        "128",
        "--tile",
        "16x16",
        "--mode",
        "component",
        // Tiles long enough to be killed among, as in the single-process test (at 1 sample a
        // pixel the 64 tiles took 0.04 s, and only 3 of 5 kills landed among them).
        "--spp",
        "32",
    ];
    // 4 ranks: the master (0), one PA (1), two PRs (2, 3); and mpirun itself.
    let victims = [
        ("master", Some(0)),
        ("PA", Some(1)),
        ("PR", Some(3)),
        ("mpirun", None),
        ("PR", Some(2)),
    ];
    kill_and_resume(Launch::Mpi(4), &cornell(), &extra, &victims, 128, 16);
}

#[test]
fn a_checkpoint_of_another_job_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let checkpoint = d.join("cp");
    let scene = cornell();
    let small = ["-x", "32", "-y", "32", "-ad", "32"];
    let first = run_ok(
        &render_args(&scene, &d.join("a.exr"), &d.join("a.json"), Some(&checkpoint), &small)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    drop(first);
    let mut other: Vec<&str> = small.to_vec();
    other.extend(["-ab", "2"]);
    let refused = run(
        &render_args(&scene, &d.join("b.exr"), &d.join("b.json"), Some(&checkpoint), &other)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(!refused.status.success());
    let err = stderr(&refused);
    assert!(
        err.contains("cp/tiles.journal") && err.contains("another job"),
        "the error should name the journal and say why:\n{err}"
    );
    assert!(!d.join("b.exr").exists());
    // A finished checkpointed job run again restores every tile and renders none.
    let again = run(
        &render_args(&scene, &d.join("c.exr"), &d.join("c.json"), Some(&checkpoint), &small)
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(again.status.success(), "{}", stderr(&again));
    let stats = read_stats(&d.join("c.json"));
    assert_eq!(tiles_rendered(&stats), 0);
    assert_eq!(
        relmse(&read_exr(&d.join("c.exr")), &read_exr(&d.join("a.exr"))),
        0.0,
        "a fully restored image is the journalled one"
    );
}

/// A file system that fills up while the image is written (a 512 KiB tmpfs this test mounts and
/// unmounts; root only, as CI runs): one line naming the file and saying the file system is
/// full and what was kept, exit non-zero, no partial file and no preview (made beside the EXR,
/// it appears only with it); the checkpoint and the cache file,
/// elsewhere, stay whole, and the same command with room to write resumes every tile.
#[test]
fn a_full_disk_names_the_file_and_loses_neither_the_checkpoint_nor_the_cache() {
    let root = Command::new("id")
        .arg("-u")
        .output()
        .map(|o| o.stdout == b"0\n")
        .unwrap_or(false);
    if !root {
        eprintln!("skipped: mounting a small tmpfs needs root");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let small = dir.path().join("small");
    std::fs::create_dir(&small).unwrap();
    let mount = |size: &str| {
        let status = Command::new("mount")
            .args([
                "-t",
                "tmpfs",
                "-o",
                &format!("size={size}"),
                "tmpfs",
                small.to_str().unwrap(),
            ])
            .status()
            .unwrap();
        assert!(status.success(), "mount a tmpfs on {}", small.display());
    };
    let unmount = || {
        let _ = Command::new("umount").arg(&small).status();
    };
    let (journal, cache) = (dir.path().join("journal"), dir.path().join("cache.af"));
    let out = small.join("out.exr");
    let stats = dir.path().join("stats.json");
    let args: Vec<String> = [
        "render",
        cornell().to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "-x",
        "128",
        "-y",
        "128",
        "-q",
        "--checkpoint",
        journal.to_str().unwrap(),
        "-af",
        cache.to_str().unwrap(),
        "--stats",
        stats.to_str().unwrap(),
    ]
    .map(String::from)
    .to_vec();
    mount("256k");
    let full = Command::new(binary()).args(&args).output().unwrap();
    let left: Vec<_> = std::fs::read_dir(&small)
        .unwrap()
        .flatten()
        .map(|e| e.file_name())
        .collect();
    unmount();
    assert!(!full.status.success());
    let said = String::from_utf8_lossy(&full.stderr).to_string();
    assert_eq!(said.trim_end().lines().count(), 1, "{said}");
    assert!(
        said.contains(out.to_str().unwrap()) && said.contains("the file system is full"),
        "{said}"
    );
    assert!(said.contains(journal.to_str().unwrap()), "says what was kept: {said}");
    assert!(left.is_empty(), "left behind on the full disk: {left:?}");
    let cache_bytes = std::fs::metadata(&cache).unwrap().len();
    assert!(cache_bytes > 0);
    mount("16m");
    let again = Command::new(binary()).args(&args).output().unwrap();
    let written = out.exists();
    unmount();
    assert!(again.status.success(), "{}", String::from_utf8_lossy(&again.stderr));
    assert!(written);
    assert_eq!(
        tiles_rendered(&read_stats(&stats)),
        0,
        "every tile is resumed from the checkpoint"
    );
    assert!(std::fs::metadata(&cache).unwrap().len() >= cache_bytes);
}
