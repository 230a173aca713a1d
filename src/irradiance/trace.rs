//! A text trace of what the irradiance cache does (hidden `--trace-cache FILE`, serial mode):
//! every lookup with its pixel, point, normal and outcome, and every new record with the
//! geometry that decides where it may be used. The bench's cluster simulation replays it.
//!
//! Lines, in the order the cache saw them (one thread gives a deterministic order):
//! `L pixel level hit x y z nx ny nz`, each followed by
//! `R pixel level x y z nx ny nz ux uy uz r0 r1 h0 .. h7 headroom`: the record the lookup made
//! (miss) or would have made (hit; sampled for the trace only, so a traced run is much slower):
//! position, normal, first principal axis, radii, leak-test horizon per sector (infinite as
//! `inf`) and headroom (the lookup point's too: the record is made there).
//! With -ab 1 the traced render is the same as without the trace; with more bounces the sampled
//! records' own bounces go through the cache and add to it.

use super::record::Record;
use glam::Vec3;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::Mutex;

pub struct CacheTrace {
    out: Mutex<BufWriter<File>>,
}

fn vec(v: Vec3) -> String {
    format!("{} {} {}", v.x, v.y, v.z)
}

/// One lookup's line.
pub fn lookup_line(pixel: u32, level: u32, hit: bool, point: Vec3, normal: Vec3) -> String {
    format!("L {pixel} {level} {} {} {}", u8::from(hit), vec(point), vec(normal))
}

/// One new record's line.
pub fn record_line(pixel: u32, r: &Record) -> String {
    let horizon: Vec<String> = r.horizon.iter().map(|h| h.to_string()).collect();
    format!(
        "R {pixel} {} {} {} {} {} {} {} {}",
        r.level,
        vec(r.position),
        vec(r.normal),
        vec(r.u_axis),
        r.radii[0],
        r.radii[1],
        horizon.join(" "),
        r.headroom
    )
}

impl CacheTrace {
    pub fn create(path: &Path) -> Result<CacheTrace, String> {
        let file = File::create(path).map_err(|e| format!("{}: {e}", path.display()))?;
        Ok(CacheTrace {
            out: Mutex::new(BufWriter::new(file)),
        })
    }

    pub fn write(&self, line: &str) {
        let mut out = self.out.lock().unwrap_or_else(|e| e.into_inner());
        // A trace is a debugging aid: a write error must not stop the render.
        let _ = writeln!(out, "{line}");
    }

    pub fn finish(&self) -> Result<(), String> {
        let mut out = self.out.lock().unwrap_or_else(|e| e.into_inner());
        out.flush().map_err(|e| e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::record::tests::flat_record;

    #[test]
    fn lines_carry_every_field() {
        let l = lookup_line(7, 0, true, Vec3::new(1.0, 2.0, 3.0), Vec3::Z);
        assert_eq!(l, "L 7 0 1 1 2 3 0 0 1");
        let r = record_line(7, &flat_record(1.0, 0.5));
        let fields: Vec<&str> = r.split_whitespace().collect();
        assert_eq!(fields.len(), 1 + 2 + 9 + 2 + 8 + 1);
        assert_eq!(fields[0], "R");
        assert_eq!(fields[12], "0.5");
        assert_eq!(fields[14], "inf");
        assert_eq!(fields[22], "100");
    }

    #[test]
    fn written_lines_reach_the_file() {
        let path = std::env::temp_dir().join(format!("icrender-trace-{}.txt", std::process::id()));
        let t = CacheTrace::create(&path).unwrap();
        t.write("L 0 0 0 0 0 0 0 0 1");
        t.finish().unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "L 0 0 0 0 0 0 0 0 1\n");
        let _ = std::fs::remove_file(&path);
    }
}
