//! The persistent cache file (-af), like Radiance's ambient file: loaded at start, appended to
//! as records are made (flushed in small batches, so a crash loses at most the last batch), and
//! reusable by a later run with the same settings. The header carries the settings the records
//! were made with; a file made with other settings is refused rather than silently mixed in.
//! A torn last record (the writer was killed mid-write) is dropped and cut off, not fatal.

use super::codec::{self, CODEC_VERSION, DecodeError, RECORD_BYTES};
use super::record::Record;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

const MAGIC: &[u8; 8] = b"ICRCACHE";
/// Records written between flushes: what a crash can lose at most.
pub const FLUSH_BATCH: usize = 16;

struct Writer {
    file: BufWriter<File>,
    pending: usize,
    error: Option<String>,
}

pub struct CacheFile {
    path: PathBuf,
    writer: Mutex<Writer>,
}

/// What loading found.
#[derive(Debug, Default, Clone)]
pub struct LoadReport {
    pub loaded: usize,
    /// Bytes of a torn last record that were cut off.
    pub torn_bytes: usize,
    /// Records inside the file that failed their checksum or validation and were skipped.
    pub corrupt: usize,
}

fn header(settings: &str) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&CODEC_VERSION.to_le_bytes());
    out.extend_from_slice(&(settings.len() as u32).to_le_bytes());
    out.extend_from_slice(settings.as_bytes());
    out
}

/// Splits a file's bytes into its settings line and the records after it.
fn parse_header(bytes: &[u8]) -> Result<(String, usize), String> {
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err("not an icrender cache file".into());
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if version != CODEC_VERSION {
        return Err(format!(
            "cache file version {version}; this icrender reads version {CODEC_VERSION}"
        ));
    }
    let len = u32::from_le_bytes(bytes[12..16].try_into().expect("4 bytes")) as usize;
    let end = 16usize
        .checked_add(len)
        .filter(|&e| e <= bytes.len())
        .ok_or("cache file header is truncated")?;
    let settings = std::str::from_utf8(&bytes[16..end])
        .map_err(|_| "cache file header is not text")?
        .to_string();
    Ok((settings, end))
}

/// The records of a whole file's bytes made with `settings` (refused otherwise), and how many
/// bytes at its end are a torn write (to cut when appending; `report` counts them).
fn decode_file(bytes: &[u8], settings: &str, report: &mut LoadReport) -> Result<(Vec<Record>, usize), String> {
    let (theirs, start) = parse_header(bytes)?;
    if theirs != settings {
        return Err(format!(
            "was made with other settings ({theirs}); this render uses ({settings}); \
             use the same settings or another file"
        ));
    }
    let body = &bytes[start..];
    let whole = body.len() / RECORD_BYTES;
    let record = |i: usize| codec::decode(&body[i * RECORD_BYTES..]);
    // A run of bad records at the end is a torn write (a batch is flushed as one write,
    // so a crash can tear several records); a bad record inside the file is damage.
    // Cutting the whole run at once means a second open finds nothing more to cut.
    let mut intact = whole;
    while intact > 0 && matches!(record(intact - 1), Err(DecodeError::Checksum)) {
        intact -= 1;
    }
    let torn = (whole - intact) * RECORD_BYTES;
    let mut records: Vec<Record> = Vec::with_capacity(intact);
    // A record the prepass shrank is appended again (`shrink_where_neighbours_disagree`):
    // the later form replaces the earlier one, in the earlier one's place.
    let mut seen = std::collections::HashMap::new();
    for i in 0..intact {
        match record(i) {
            Ok(r) => match seen.entry(r.identity()) {
                std::collections::hash_map::Entry::Occupied(at) => records[*at.get()] = r,
                std::collections::hash_map::Entry::Vacant(slot) => {
                    slot.insert(records.len());
                    records.push(r);
                }
            },
            Err(_) => report.corrupt += 1,
        }
    }
    let cut = torn + body.len() % RECORD_BYTES;
    report.torn_bytes += cut;
    Ok((records, cut))
}

/// Reads a file's records without opening it for writing (`--af-read-only`): the file must
/// exist and was made with `settings`; a torn tail is skipped, not cut, and the file is left
/// exactly as it is (several tasks may read it at once).
pub fn read_only(path: &Path, settings: &str) -> Result<(Vec<Record>, LoadReport), String> {
    let bytes = std::fs::read(path).map_err(|e| match e.kind() {
        std::io::ErrorKind::NotFound => "no such cache file (--af-read-only reads a file made before, \
             e.g. by `icrender cache`)"
            .to_string(),
        _ => format!("cannot read: {e}"),
    })?;
    let mut report = LoadReport::default();
    let (records, _) = decode_file(&bytes, settings, &mut report)?;
    report.loaded = records.len();
    Ok((records, report))
}

impl CacheFile {
    /// Opens (or creates) the file; returns it with the records it already holds.
    pub fn open(path: &Path, settings: &str) -> Result<(CacheFile, Vec<Record>, LoadReport), String> {
        let mut records = Vec::new();
        let mut report = LoadReport::default();
        let mut bytes = Vec::new();
        if path.exists() {
            File::open(path)
                .and_then(|mut f| f.read_to_end(&mut bytes))
                .map_err(|e| format!("cannot read: {e}"))?;
        }
        let mut keep = bytes.len();
        if bytes.is_empty() {
            std::fs::write(path, header(settings)).map_err(|e| format!("cannot write: {e}"))?;
        } else {
            let (found, cut) = decode_file(&bytes, settings, &mut report)?;
            records = found;
            keep -= cut;
        }
        report.loaded = records.len();
        let file = OpenOptions::new()
            .write(true)
            .open(path)
            .map_err(|e| format!("cannot write: {e}"))?;
        if keep < bytes.len() {
            // Cut the torn tail so appended records stay aligned.
            file.set_len(keep as u64)
                .map_err(|e| format!("cannot repair the torn tail: {e}"))?;
        }
        let mut file = BufWriter::new(file);
        use std::io::Seek;
        file.seek(std::io::SeekFrom::End(0))
            .map_err(|e| format!("cannot write: {e}"))?;
        let writer = Writer {
            file,
            pending: 0,
            error: None,
        };
        Ok((
            CacheFile {
                path: path.to_path_buf(),
                writer: Mutex::new(writer),
            },
            records,
            report,
        ))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends a record; flushes every FLUSH_BATCH records. The first write error is kept and
    /// reported by `finish` (the render goes on; only persistence is lost).
    pub fn append(&self, record: &Record) {
        let mut bytes = Vec::with_capacity(RECORD_BYTES);
        codec::encode(record, &mut bytes);
        let mut w = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        if w.error.is_some() {
            return;
        }
        let mut result = w.file.write_all(&bytes);
        w.pending += 1;
        if result.is_ok() && w.pending >= FLUSH_BATCH {
            result = w.file.flush();
            w.pending = 0;
        }
        if let Err(e) = result {
            w.error = Some(e.to_string());
        }
    }

    /// Flushes what is pending; returns the first write error, if any.
    pub fn finish(&self) -> Result<(), String> {
        let mut w = self.writer.lock().unwrap_or_else(|e| e.into_inner());
        if let Err(e) = w.file.flush() {
            w.error.get_or_insert(e.to_string());
        }
        w.pending = 0;
        match &w.error {
            Some(e) => Err(e.clone()),
            None => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::record::tests::flat_record;

    #[test]
    fn records_survive_a_reopen_and_other_settings_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.icc");
        let (file, loaded, _) = CacheFile::open(&path, "-aa 0.2").unwrap();
        assert!(loaded.is_empty());
        for i in 0..40 {
            file.append(&flat_record(i as f32, 1.0));
        }
        // Two full batches reach the disk before finish; the rest only at finish.
        let (_, seen, _) = CacheFile::open(&path, "-aa 0.2").unwrap();
        assert!(seen.len() >= 2 * FLUSH_BATCH && seen.len() < 40);
        file.finish().unwrap();
        let (_, all, report) = CacheFile::open(&path, "-aa 0.2").unwrap();
        assert_eq!(all.len(), 40);
        assert_eq!(report.loaded, 40);
        let err = CacheFile::open(&path, "-aa 0.1").err().unwrap();
        assert!(err.contains("other settings"), "{err}");
    }

    /// A file of settings "s" holding `n` records of values 1, 2, ...
    fn write_records(path: &Path, n: usize) {
        let (file, _, _) = CacheFile::open(path, "s").unwrap();
        for i in 0..n {
            file.append(&flat_record(i as f32 + 1.0, 1.0));
        }
        file.finish().unwrap();
    }

    /// A record appended again with smaller radii (the prepass shrank it) loads once, in its
    /// later form and its first place; read-only loading agrees.
    #[test]
    fn a_revised_record_replaces_its_first_form() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.icc");
        write_records(&path, 3);
        let (file, _, _) = CacheFile::open(&path, "s").unwrap();
        let mut revised = flat_record(2.0, 1.0);
        revised.radii = [0.5, 0.25];
        file.append(&revised);
        file.finish().unwrap();
        let (_, records, report) = CacheFile::open(&path, "s").unwrap();
        let (read, _) = read_only(&path, "s").unwrap();
        for records in [records, read] {
            assert_eq!(records.iter().map(|r| r.value.x).collect::<Vec<_>>(), [1.0, 2.0, 3.0]);
            assert_eq!(records[1].radii, [0.5, 0.25]);
        }
        assert_eq!(report.loaded, 3);
    }

    #[test]
    fn torn_tail_is_dropped_and_cut_then_appending_works() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.icc");
        write_records(&path, 3);
        // A killed writer leaves half a record.
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.truncate(bytes.len() - 50);
        std::fs::write(&path, &bytes).unwrap();
        let (file, records, report) = CacheFile::open(&path, "s").unwrap();
        assert_eq!(records.len(), 2);
        assert_eq!(report.torn_bytes, RECORD_BYTES - 50);
        file.append(&flat_record(9.0, 1.0));
        file.finish().unwrap();
        let (_, records, report) = CacheFile::open(&path, "s").unwrap();
        assert_eq!(records.len(), 3);
        assert_eq!(records[2].value.x, 9.0);
        assert_eq!(report.torn_bytes, 0);
    }

    #[test]
    fn damage_inside_is_counted_and_a_torn_run_at_the_end_is_cut_in_one_open() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.icc");
        write_records(&path, 5);
        let mut bytes = std::fs::read(&path).unwrap();
        let body = bytes.len() - 5 * RECORD_BYTES;
        // Record 1 damaged inside the file; records 3 and 4 torn (a batch cut mid-write).
        for i in [1usize, 3, 4] {
            bytes[body + i * RECORD_BYTES + 7] ^= 0x5a;
        }
        std::fs::write(&path, &bytes).unwrap();
        let (file, records, report) = CacheFile::open(&path, "s").unwrap();
        drop(file);
        assert_eq!(records.len(), 2);
        assert_eq!(report.corrupt, 1);
        assert_eq!(report.torn_bytes, 2 * RECORD_BYTES);
        let (_, again, report) = CacheFile::open(&path, "s").unwrap();
        assert_eq!(again, records);
        assert_eq!((report.corrupt, report.torn_bytes), (1, 0));
    }

    #[test]
    fn read_only_loads_without_touching_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.icc");
        assert!(read_only(&path, "s").unwrap_err().contains("no such cache file"));
        write_records(&path, 3);
        // A torn tail is skipped but stays in the file.
        let mut bytes = std::fs::read(&path).unwrap();
        bytes.truncate(bytes.len() - 10);
        std::fs::write(&path, &bytes).unwrap();
        let (records, report) = read_only(&path, "s").unwrap();
        assert_eq!(records.len(), 2);
        assert_eq!(report.loaded, 2);
        assert_eq!(report.torn_bytes, RECORD_BYTES - 10);
        assert_eq!(std::fs::read(&path).unwrap(), bytes);
        assert!(read_only(&path, "t").unwrap_err().contains("other settings"));
    }

    #[test]
    fn garbage_is_not_a_cache_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g");
        std::fs::write(&path, b"hello world, this is not a cache").unwrap();
        assert!(
            CacheFile::open(&path, "s")
                .err()
                .unwrap()
                .contains("not an icrender cache file")
        );
    }
}
