//! The MPI wire decoders: what one rank accepts from another. Byte 0 picks the decoder, bit 0 of
//! byte 1 asks for the record checksums to be repaired first (so the fuzzer also reaches the
//! validation behind them), the rest is the message. Besides "no panic, no huge allocation",
//! every accepted message must survive a re-encode and decode unchanged.

#![no_main]

use icrender::irradiance::codec::{RECORD_BYTES, checksum};
use icrender::parallel::component::requests;
use icrender::parallel::component::{decode_counts_and_records, encode_counts_and_records};
use icrender::parallel::protocol::{
    decode_batch, decode_work, decode_work_request, encode_batch, encode_work, encode_work_request,
};
use libfuzzer_sys::fuzz_target;

/// Image size handed to the request decoder (pixels outside it must be refused).
const PIXELS: u32 = 64 * 64;

/// Rewrites the checksum of every whole record after `start`.
fn repair_checksums(bytes: &mut [u8], start: usize) {
    if start > bytes.len() {
        return;
    }
    for record in bytes[start..].chunks_exact_mut(RECORD_BYTES) {
        let sum = checksum(&record[..RECORD_BYTES - 4]);
        record[RECORD_BYTES - 4..].copy_from_slice(&sum.to_le_bytes());
    }
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let (which, repair) = (data[0] % 5, data[1] & 1 == 1);
    let mut msg = data[2..].to_vec();
    match which {
        0 => {
            if repair {
                repair_checksums(&mut msg, 16);
            }
            if let Ok(batch) = decode_batch(&msg) {
                assert_eq!(batch.records.len() + batch.rejected, (msg.len() - 16) / RECORD_BYTES);
                let again = decode_batch(&encode_batch(&batch.records, batch.flags)).expect("re-encoded batch decodes");
                assert_eq!(again.records, batch.records);
                assert_eq!((again.rejected, again.flags), (0, batch.flags));
            }
        }
        1 => {
            if let Ok((thread, finished)) = decode_work_request(&msg) {
                let encoded = encode_work_request(thread, finished.as_ref().map(|(t, p)| (*t, p.as_slice())));
                // Pixels are fixed-size floats: the encoding is canonical.
                assert_eq!(encoded, msg);
            }
        }
        2 => {
            if let Ok(work) = decode_work(&msg) {
                // A work message is exactly its encoding (trailing bytes were once accepted;
                // see docs/FUZZING.md).
                assert_eq!(encode_work(work), msg);
            }
        }
        3 => {
            if let Ok(decoded) = requests::decode(&msg, PIXELS) {
                assert_eq!(decoded.requests.len() + decoded.rejected, (msg.len() - 12) / requests::REQUEST_BYTES);
                assert!(decoded.requests.iter().all(|r| r.pixel < PIXELS));
                let again = requests::decode(&requests::encode(&decoded.requests), PIXELS).expect("re-encoded");
                assert_eq!(again.requests, decoded.requests);
                assert_eq!(again.rejected, 0);
            }
        }
        _ => {
            // The idle/status messages: counts, then a record batch.
            let n = (msg.first().copied().unwrap_or(0) % 4) as usize;
            let body = msg.get(1..).unwrap_or(&[]).to_vec();
            let mut body = body;
            if repair {
                repair_checksums(&mut body, 8 * n + 16);
            }
            if let Ok((counts, batch)) = decode_counts_and_records(&body, n) {
                assert_eq!(counts.len(), n);
                let again = encode_counts_and_records(&counts, &batch.records);
                let (c2, b2) = decode_counts_and_records(&again, n).expect("re-encoded");
                assert_eq!((c2, b2.records), (counts, batch.records));
            }
        }
    }
});
