//! Cryptomatte (Psyop's specification, version 1.1.0): ID mattes a compositor extracts by name.
//!
//! A name (a glTF node's or material's) becomes an ID by MurmurHash3's 32-bit x86 variant with
//! seed 0 over its UTF-8 bytes; the ID is stored as the float with the same bits, except that
//! the exponent is clamped to [1, 254] so that no ID is zero, denormal, infinite or NaN (the
//! specification's `uint32_to_float32` conversion). Each pixel keeps the IDs its camera samples
//! hit with their coverage (the share of the pixel's filter weight, here the box filter's equal
//! weights), ranked by coverage: `{type}00.R` is the most covering ID, `.G` its coverage, `.B`
//! and `.A` the second; `{type}01` the third and fourth, and so on for `RANKS` ranks (the
//! specification's suggested 6, three RGBA layers). Samples that hit nothing add to no ID, so
//! a pixel's coverages sum to the share of its samples that hit something. Unused ranks are
//! ID 0 with coverage 0 (the specification's "no object").
//!
//! The header carries, per type, `cryptomatte/<key>/name`, `hash`, `conversion` and the
//! `manifest` (JSON: name -> 8 hex digits of the ID's float bits), where `<key>` is the first
//! 7 hex digits of the MurmurHash3 of the type's name.

use serde_json::{Map, Value};

/// Ranks kept per pixel (the specification's suggested default): `RANKS / 2` RGBA layers.
pub const RANKS: usize = 6;

/// MurmurHash3_x86_32 (Austin Appleby's public-domain hash) of `bytes` with `seed`.
pub fn murmur3_32(bytes: &[u8], seed: u32) -> u32 {
    const C1: u32 = 0xcc9e_2d51;
    const C2: u32 = 0x1b87_3593;
    let mix = |k: u32| k.wrapping_mul(C1).rotate_left(15).wrapping_mul(C2);
    let mut h = seed;
    let blocks = bytes.chunks_exact(4);
    let tail = blocks.remainder();
    for block in blocks {
        let k = u32::from_le_bytes(block.try_into().expect("4 bytes"));
        h ^= mix(k);
        h = h.rotate_left(13).wrapping_mul(5).wrapping_add(0xe654_6b64);
    }
    if !tail.is_empty() {
        // The last 1-3 bytes, little-endian, mixed without the rotation of h.
        let k = tail.iter().rev().fold(0u32, |k, &b| (k << 8) | b as u32);
        h ^= mix(k);
    }
    h ^= bytes.len() as u32;
    // Final avalanche.
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^= h >> 16;
    h
}

/// The bits of the float a hash is stored as: sign and mantissa kept, the exponent clamped to
/// [1, 254] (never zero or denormal, never Inf or NaN).
pub fn hash_to_float_bits(hash: u32) -> u32 {
    let exponent = ((hash >> 23) & 0xff).clamp(1, 254);
    (hash & 0x8000_0000) | (exponent << 23) | (hash & 0x007f_ffff)
}

/// A name's ID as stored in the pixels: the bits of a finite, non-zero f32.
pub fn id_of(name: &str) -> u32 {
    hash_to_float_bits(murmur3_32(name.as_bytes(), 0))
}

/// The 7 hex digits that key a Cryptomatte type's header attributes.
pub fn layer_key(type_name: &str) -> String {
    format!("{:08x}", murmur3_32(type_name.as_bytes(), 0))[..7].to_string()
}

/// The manifest as the specification writes it: a JSON object, name -> ID's float bits as 8
/// lowercase hex digits (keys sorted; a name given twice appears once).
pub fn manifest<'a>(names: impl IntoIterator<Item = &'a str>) -> String {
    let mut map = Map::new();
    let mut sorted: Vec<&str> = names.into_iter().collect();
    sorted.sort_unstable();
    for name in sorted {
        map.insert(name.to_string(), Value::String(format!("{:08x}", id_of(name))));
    }
    Value::Object(map).to_string()
}

/// The header attributes of one Cryptomatte type.
pub fn header_attributes<'a>(type_name: &str, names: impl IntoIterator<Item = &'a str>) -> Vec<(String, String)> {
    let key = layer_key(type_name);
    let attribute = |what: &str, value: String| (format!("cryptomatte/{key}/{what}"), value);
    vec![
        attribute("name", type_name.to_string()),
        attribute("hash", "MurmurHash3_32".into()),
        attribute("conversion", "uint32_to_float32".into()),
        attribute("manifest", manifest(names)),
    ]
}

/// One rank of a pixel: an ID (float bits; 0: none) and its coverage.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Entry {
    pub id: u32,
    pub coverage: f32,
}

/// A pixel's ranked IDs, most covering first; unused ranks are `Entry::default()`.
pub type Ranks = [Entry; RANKS];

/// Ranks weighted IDs: the weights of equal IDs are summed, then the IDs are ordered by
/// coverage (ties by ID, so the order never depends on the input's) and the first `RANKS` kept.
pub fn rank(weighted: impl IntoIterator<Item = Entry>) -> Ranks {
    let mut sums: Vec<Entry> = Vec::new();
    for e in weighted {
        if e.id == 0 || e.coverage <= 0.0 {
            continue;
        }
        match sums.iter_mut().find(|s| s.id == e.id) {
            Some(s) => s.coverage += e.coverage,
            None => sums.push(e),
        }
    }
    sums.sort_by(|a, b| b.coverage.total_cmp(&a.coverage).then(a.id.cmp(&b.id)));
    let mut out = Ranks::default();
    for (slot, e) in out.iter_mut().zip(sums) {
        *slot = e;
    }
    out
}

/// Two pixels' ranks as one (coverages of equal IDs added), e.g. frames summed across ranks.
pub fn merge(a: &Ranks, b: &Ranks) -> Ranks {
    rank(a.iter().chain(b.iter()).copied())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn murmur3_matches_published_vectors() {
        // SMHasher's MurmurHash3_x86_32 on empty input and on 0-3 tail bytes, and the widely
        // quoted vectors with seed 0x9747b28c.
        assert_eq!(murmur3_32(b"", 0), 0);
        assert_eq!(murmur3_32(b"", 1), 0x514e_28b7);
        assert_eq!(murmur3_32(b"", 0xffff_ffff), 0x81f1_6f39);
        assert_eq!(murmur3_32(&[0, 0, 0, 0], 0), 0x2362_f9de);
        assert_eq!(murmur3_32(b"aaaa", 0x9747_b28c), 0x5a97_808a);
        assert_eq!(murmur3_32(b"aaa", 0x9747_b28c), 0x283e_0130);
        assert_eq!(murmur3_32(b"aa", 0x9747_b28c), 0x5d21_1726);
        assert_eq!(murmur3_32(b"a", 0x9747_b28c), 0x7fa0_9ea6);
        assert_eq!(murmur3_32(b"Hello, world!", 0x9747_b28c), 0x2488_4cba);
        assert_eq!(
            murmur3_32(b"The quick brown fox jumps over the lazy dog", 0x9747_b28c),
            0x2fa8_26cd
        );
    }

    #[test]
    fn ids_match_the_specifications_manifest_examples() {
        // The specification's example manifests (names and the hex of their float IDs).
        assert_eq!(format!("{:08x}", id_of("bunny")), "13851a76");
        assert_eq!(format!("{:08x}", id_of("default")), "42c9679f");
        assert_eq!(format!("{:08x}", id_of("bunny_porcelain_mat")), "b24b26d4");
    }

    #[test]
    fn conversion_clamps_the_exponent_and_keeps_the_rest() {
        for hash in [
            0u32,
            0x0000_0001,
            0x8000_0000,
            0x807f_ffff,
            0x7f80_0000,
            0xffff_ffff,
            0x3f80_0000,
        ] {
            let f = f32::from_bits(hash_to_float_bits(hash));
            assert!(f.is_finite() && f.is_normal(), "{hash:08x} -> {f}");
            assert_eq!(hash_to_float_bits(hash) & 0x807f_ffff, hash & 0x807f_ffff);
        }
        // Exponents inside [1, 254] pass unchanged.
        assert_eq!(hash_to_float_bits(0x3f80_0000), 0x3f80_0000);
        assert_eq!(hash_to_float_bits(0x0000_0000), 0x0080_0000);
        assert_eq!(hash_to_float_bits(0xff80_0001), 0xff00_0001);
    }

    #[test]
    fn layer_keys_are_seven_hex_digits_of_the_name_hash() {
        let key = layer_key("CryptoObject");
        assert_eq!(key.len(), 7);
        assert_eq!(key, format!("{:08x}", murmur3_32(b"CryptoObject", 0))[..7]);
        assert_ne!(key, layer_key("CryptoMaterial"));
    }

    #[test]
    fn manifest_is_json_of_names_to_ids() {
        let text = manifest(["b", "a", "b", "with \"quote\""]);
        let parsed: Map<String, Value> = serde_json::from_str(&text).unwrap();
        assert_eq!(parsed.len(), 3);
        for (name, hex) in &parsed {
            assert_eq!(hex.as_str().unwrap(), format!("{:08x}", id_of(name)));
        }
    }

    #[test]
    fn ranking_sums_equal_ids_and_sorts_by_coverage() {
        let e = |id, coverage| Entry { id, coverage };
        let r = rank([e(5, 0.25), e(7, 0.25), e(5, 0.25), e(0, 0.2), e(9, 0.05)]);
        assert_eq!(r[0], e(5, 0.5));
        assert_eq!(r[1], e(7, 0.25));
        assert_eq!(r[2], e(9, 0.05));
        assert!(r[3..].iter().all(|x| *x == Entry::default()));
        // More IDs than ranks: the least covering are dropped.
        let many = rank((1..=10).map(|i| e(i, i as f32)));
        assert_eq!(many.map(|x| x.id), [10, 9, 8, 7, 6, 5]);
        // Merging is the ranking of both.
        let m = merge(&rank([e(1, 0.5)]), &rank([e(2, 0.3), e(1, 0.1)]));
        assert_eq!(m[0], e(1, 0.6));
        assert_eq!(m[1], e(2, 0.3));
    }
}
