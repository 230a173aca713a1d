//! The persistent cache file (-af) reader: bytes -> file -> `CacheFile::open` with fixed
//! settings. Bit 0 of byte 0 asks for the record checksums to be repaired first (so the fuzzer
//! also reaches record validation); the rest is the file. Whatever the file holds, opening it
//! must not panic, must account for every byte, and must leave a file that opens again cleanly.

#![no_main]

use icrender::irradiance::codec::{RECORD_BYTES, checksum};
use icrender::irradiance::persist::CacheFile;
use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;

/// What the seeds' headers say; any other settings line is refused by design.
const SETTINGS: &str = "-aa 0.1 -ar 64 -ad 512 -as 0 -ab 1 -lr 8 -lw 0.001 -st 0.15";

fn work_dir() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("icrender-fuzz-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        dir
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&mode, file)) = data.split_first() else { return };
    let mut bytes = file.to_vec();
    if mode & 1 == 1 && bytes.len() >= 16 {
        let len = u32::from_le_bytes(bytes[12..16].try_into().unwrap()) as usize;
        if let Some(start) = 16usize.checked_add(len).filter(|&s| s <= bytes.len()) {
            for record in bytes[start..].chunks_exact_mut(RECORD_BYTES) {
                let sum = checksum(&record[..RECORD_BYTES - 4]);
                record[RECORD_BYTES - 4..].copy_from_slice(&sum.to_le_bytes());
            }
        }
    }
    let path = work_dir().join("cache.icc");
    std::fs::write(&path, &bytes).expect("write");
    if let Ok((file, records, report)) = CacheFile::open(&path, SETTINGS) {
        drop(file);
        assert_eq!(report.loaded, records.len());
        let after = std::fs::read(&path).expect("read back");
        // Only a torn tail is cut, nothing else changes.
        if bytes.is_empty() {
            assert!(after.starts_with(b"ICRCACHE"));
        } else {
            assert_eq!(after.len(), bytes.len() - report.torn_bytes);
            assert_eq!(after[..], bytes[..after.len()]);
        }
        // The repaired file opens again with the same records, the same damage counted, and
        // nothing more to cut (a run of bad records at the end is cut at once).
        let (_, again, report2) = CacheFile::open(&path, SETTINGS).expect("reopen");
        assert_eq!(again, records);
        assert_eq!((report2.torn_bytes, report2.corrupt), (0, report.corrupt));
    }
});
