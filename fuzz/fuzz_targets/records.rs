//! The MPI wire codec: what one rank accepts from another. Byte 0 picks the message kind (its
//! tag), bit 0 of byte 1 asks for the record checksums to be repaired first (so the fuzzer also
//! reaches the validation behind them), the rest is the message. Besides "no panic, no huge
//! allocation", every accepted message must re-encode to bytes that decode to the same message,
//! and a message with nothing refused in it must be exactly its own encoding.

#![no_main]

use icrender::irradiance::codec::{RECORD_BYTES, checksum};
use icrender::parallel::protocol::{Kind, Message};
use libfuzzer_sys::fuzz_target;

/// Every kind's tag (the per-thread kinds for thread 3), and where its records start, if it
/// carries a record batch (version byte, fields, count).
const KINDS: [(Kind, usize); 19] = [
    (Kind::Heartbeat, 0),
    (Kind::InitialRecords, 5),
    (Kind::PrepassStart, 5),
    (Kind::PrepassRound, 0),
    (Kind::WorkRequest, 0),
    (Kind::RecordsUp, 9),
    (Kind::RecordsBroadcast, 6),
    (Kind::FinalRecords, 5),
    (Kind::Stats, 0),
    (Kind::Requests, 0),
    (Kind::Forwarded, 0),
    (Kind::Idle, 21),
    (Kind::PaStatus, 21),
    (Kind::ForwardOrder, 0),
    (Kind::Finish, 0),
    (Kind::Results, 0),
    (Kind::Work, 10),
    (Kind::RecordsDown, 5),
];

/// Rewrites the checksum of every whole record after `start`.
fn repair_checksums(bytes: &mut [u8], start: usize) {
    if start == 0 || start > bytes.len() {
        return;
    }
    for record in bytes[start..].chunks_exact_mut(RECORD_BYTES) {
        let sum = checksum(&record[..RECORD_BYTES - 4]);
        record[RECORD_BYTES - 4..].copy_from_slice(&sum.to_le_bytes());
    }
}

/// How many records or requests the message refused.
fn refused(message: &Message) -> usize {
    match message {
        Message::InitialRecords(r) | Message::PrepassStart(r) | Message::FinalRecords(r) => r.rejected,
        Message::Work { records, .. }
        | Message::RecordsUp { records, .. }
        | Message::RecordsDown { records, .. }
        | Message::RecordsBroadcast { records, .. }
        | Message::Idle { records, .. }
        | Message::PaStatus { records, .. } => records.rejected,
        Message::Requests(r) | Message::Forwarded(r) => r.rejected,
        _ => 0,
    }
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 2 {
        return;
    }
    let (kind, records_at) = KINDS[data[0] as usize % KINDS.len()];
    let tag = match kind {
        Kind::Work | Kind::RecordsDown => kind.for_thread(3),
        _ => kind.tag(),
    };
    let mut bytes = data[2..].to_vec();
    if data[1] & 1 == 1 {
        repair_checksums(&mut bytes, records_at);
    }
    if let Ok(message) = Message::decode(tag, &bytes) {
        assert_eq!(message.tag(), tag);
        let encoded = message.encode();
        let again = Message::decode(tag, &encoded).expect("a re-encoded message decodes");
        assert_eq!(again.encode(), encoded);
        // JSON statistics have many spellings; every other message has one.
        if refused(&message) == 0 && kind != Kind::Stats {
            assert_eq!(encoded, bytes, "accepted bytes that are not the message's encoding");
        }
    }
});
