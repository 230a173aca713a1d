//! How far a render is: a bar on a terminal (nothing when stderr is a pipe or a file: CI logs,
//! MPI), or JSON lines on stdout for a farm manager, which reads progress there and errors on
//! stderr.
//!
//! A render is the prepass's rounds, then the tiles. Their costs differ from scene to scene
//! (the prepass makes most records; the tiles mostly look them up), so the fraction gives each
//! phase half of the whole when there is a prepass: a coarse estimate, and the remaining time
//! (elapsed x (1 - fraction) / fraction) is only as good as it.

use crate::render::error_estimate::ErrorEstimate;
use std::io::{IsTerminal, Write};
use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Nothing (--quiet, or a bar where stderr is no terminal).
    Silent,
    Bar,
    Json,
}

impl Style {
    /// JSON lines when asked for (`--progress json`, whatever --quiet says); else a bar on a
    /// terminal's stderr, unless `quiet`; else nothing.
    pub fn chosen(json: bool, quiet: bool) -> Style {
        if json {
            Style::Json
        } else if !quiet && std::io::stderr().is_terminal() {
            Style::Bar
        } else {
            Style::Silent
        }
    }
}

/// The least time between two JSON lines, and the least change of the fraction, unless the
/// phase ends: a long render's thousands of tiles would otherwise flood the farm's log.
const JSON_EVERY: Duration = Duration::from_secs(1);
const JSON_STEP: f64 = 0.01;

/// A frame of a sequence (--frames): its number, its place among the sequence's frames, and
/// when the sequence began. Progress then counts over the whole sequence, and JSON lines carry
/// the frame.
#[derive(Clone, Copy, Debug)]
pub struct InSequence {
    pub frame: u32,
    pub index: usize,
    pub count: usize,
    pub start: Instant,
}

impl InSequence {
    fn overall(&self, fraction: f64) -> f64 {
        ((self.index as f64 + fraction) / self.count.max(1) as f64).min(1.0)
    }
}

pub struct Progress {
    sequence: Option<InSequence>,
    total: usize,
    done: AtomicUsize,
    rounds: AtomicUsize,
    rounds_done: AtomicUsize,
    style: Style,
    /// Only a prepass (`icrender cache`): its rounds are the whole fraction.
    prepass_only: bool,
    start: Instant,
    /// When the last line or bar was drawn, and the fraction it showed.
    last: Mutex<Option<(Instant, f64)>>,
}

impl Progress {
    /// A bar over `total` tiles (shown only on a terminal, and not when `quiet`).
    pub fn new(total: usize, quiet: bool) -> Progress {
        Progress::with_style(total, Style::chosen(false, quiet))
    }

    pub fn with_style(total: usize, style: Style) -> Progress {
        Progress {
            sequence: None,
            total: total.max(1),
            done: AtomicUsize::new(0),
            rounds: AtomicUsize::new(0),
            rounds_done: AtomicUsize::new(0),
            style,
            prepass_only: false,
            start: Instant::now(),
            last: Mutex::new(None),
        }
    }

    /// Progress of a prepass alone (`icrender cache`): no tiles follow it.
    pub fn prepass_only(style: Style) -> Progress {
        Progress {
            prepass_only: true,
            ..Progress::with_style(1, style)
        }
    }

    /// This progress is one frame's of a sequence (see `InSequence`).
    pub fn in_sequence(mut self, sequence: InSequence) -> Progress {
        self.start = sequence.start;
        self.sequence = Some(sequence);
        self
    }

    /// The prepass has `rounds` rounds in all (it learns of its sample rounds late: called
    /// again then with the new total).
    pub fn prepass_rounds(&self, rounds: usize) {
        self.rounds.store(rounds, Ordering::Relaxed);
    }

    pub fn prepass_round_done(&self) {
        self.rounds_done.fetch_add(1, Ordering::Relaxed);
        self.show("prepass", false);
    }

    pub fn advance(&self, n: usize) {
        self.done.fetch_add(n, Ordering::Relaxed);
        self.show("render", false);
    }

    /// The whole render's fraction done, 0 to 1.
    pub fn fraction(&self) -> f64 {
        let tiles = (self.done.load(Ordering::Relaxed) as f64 / self.total as f64).min(1.0);
        let rounds = self.rounds.load(Ordering::Relaxed);
        if rounds == 0 {
            return tiles;
        }
        let prepass = (self.rounds_done.load(Ordering::Relaxed) as f64 / rounds as f64).min(1.0);
        if self.prepass_only {
            return prepass;
        }
        0.5 * prepass + 0.5 * tiles
    }

    /// The fraction of all there is to do: of the sequence, for a frame of one.
    fn overall(&self) -> f64 {
        let own = self.fraction();
        self.sequence.map_or(own, |s| s.overall(own))
    }

    fn show(&self, phase: &str, force: bool) {
        if self.style == Style::Silent {
            return;
        }
        let fraction = self.overall();
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        let due = match (*last, self.style) {
            (None, _) => true,
            (Some((at, _)), Style::Bar) => at.elapsed() >= Duration::from_millis(100),
            (Some((at, shown)), _) => at.elapsed() >= JSON_EVERY || fraction - shown >= JSON_STEP,
        };
        if !(due || force || fraction >= 1.0) {
            return;
        }
        *last = Some((Instant::now(), fraction));
        let elapsed = self.start.elapsed().as_secs_f64();
        match self.style {
            Style::Bar => {
                let filled = ((fraction * 40.0) as usize).min(40);
                eprint!(
                    "\r[{}{}] {:5.1}%  {:.1}s",
                    "#".repeat(filled),
                    " ".repeat(40 - filled),
                    fraction * 100.0,
                    elapsed
                );
                let _ = std::io::stderr().flush();
            }
            Style::Json => self.json_line(phase, fraction, elapsed),
            Style::Silent => {}
        }
    }

    fn json_line(&self, phase: &str, fraction: f64, elapsed: f64) {
        let remaining = (fraction > 0.0).then(|| elapsed * (1.0 - fraction) / fraction);
        let mut line = serde_json::json!({
            "event": "progress",
            "phase": phase,
            "fraction": (fraction * 1e4).round() / 1e4,
            "elapsed_s": (elapsed * 1e3).round() / 1e3,
            "remaining_s": remaining.map(|r| (r * 1e3).round() / 1e3),
        });
        if let Some(s) = &self.sequence {
            line["frame"] = s.frame.into();
        }
        print_line(&line);
    }

    /// The tiles are done: the bar's line ends.
    pub fn finish(&self) {
        if self.style == Style::Bar {
            eprintln!();
        }
    }

    /// The outputs are written: with JSON, a last line, event `done`, naming the EXR; for a
    /// frame of a sequence, event `frame_done` with the frame and its EXR (a farm manager may
    /// pick the file up now: it is whole).
    pub fn done(&self, output: &std::path::Path, estimate: Option<&ErrorEstimate>) {
        self.done_with(output, estimate, None);
    }

    /// As `done`, with `records` (a frame's records kept, dropped, made again and made) in the
    /// line.
    pub fn done_with(
        &self,
        output: &std::path::Path,
        estimate: Option<&ErrorEstimate>,
        records: Option<serde_json::Value>,
    ) {
        if self.style != Style::Json {
            return;
        }
        let elapsed = (self.start.elapsed().as_secs_f64() * 1e3).round() / 1e3;
        let mut line = match &self.sequence {
            Some(s) => serde_json::json!({
                "event": "frame_done",
                "frame": s.frame,
                "fraction": (s.overall(1.0) * 1e4).round() / 1e4,
                "elapsed_s": elapsed,
                "output": output.display().to_string(),
            }),
            None => serde_json::json!({
                "event": "done",
                "fraction": 1.0,
                "elapsed_s": elapsed,
                "output": output.display().to_string(),
            }),
        };
        if let Some(estimate) = estimate {
            line["error_estimate"] = serde_json::to_value(estimate).unwrap_or_default();
        }
        if let Some(records) = records {
            line["records"] = records;
        }
        print_line(&line);
    }
}

/// With JSON, a line after each pass of a render in passes (`render::passes`), event `pass`:
/// its number, when it ended, the estimate of the passes' mean, and whether its image was
/// written to `output` (a farm manager may pick it up: it is whole).
pub fn pass_done(style: Style, log: &crate::render::passes::PassLog, output: &std::path::Path) {
    if style != Style::Json {
        return;
    }
    let mut line = serde_json::json!({"event": "pass", "output": output.display().to_string()});
    if let (Some(line), Ok(serde_json::Value::Object(fields))) = (line.as_object_mut(), serde_json::to_value(log)) {
        line.extend(fields);
    }
    print_line(&line);
}

/// The last line of a sequence's JSON progress: event `done`, the frames and their outputs'
/// name pattern (`#` for the digits).
pub fn sequence_done(style: Style, start: Instant, frames: &str, pattern: &str) {
    if style != Style::Json {
        return;
    }
    print_line(&serde_json::json!({
        "event": "done",
        "fraction": 1.0,
        "elapsed_s": (start.elapsed().as_secs_f64() * 1e3).round() / 1e3,
        "frames": frames,
        "output": pattern,
    }));
}

fn print_line(line: &serde_json::Value) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_prepass_and_the_tiles_each_make_half_of_the_fraction() {
        let p = Progress::with_style(10, Style::Silent);
        assert_eq!(p.fraction(), 0.0);
        p.advance(5);
        assert_eq!(p.fraction(), 0.5);
        let p = Progress::with_style(10, Style::Silent);
        p.prepass_rounds(4);
        p.prepass_round_done();
        assert_eq!(p.fraction(), 0.125);
        for _ in 0..3 {
            p.prepass_round_done();
        }
        assert_eq!(p.fraction(), 0.5);
        p.advance(10);
        assert_eq!(p.fraction(), 1.0);
        // More steps than announced never pass 1.
        p.advance(3);
        assert_eq!(p.fraction(), 1.0);
        // A frame of a sequence counts over the sequence.
        let p = Progress::with_style(4, Style::Silent).in_sequence(InSequence {
            frame: 12,
            index: 2,
            count: 4,
            start: Instant::now(),
        });
        p.advance(2);
        assert_eq!(p.fraction(), 0.5);
        assert_eq!(p.overall(), 0.625);
        // A prepass alone is the whole of its fraction.
        let p = Progress::prepass_only(Style::Silent);
        p.prepass_rounds(4);
        p.prepass_round_done();
        assert_eq!(p.fraction(), 0.25);
    }
}
