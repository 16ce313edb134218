//! A fast hasher for the maps a report fills once per rating (stimulus ids, score texts):
//! std's SipHash, built to resist keys chosen to collide, was a visible share of a
//! million-rating report. The keys here come from the study's own files, read by the lab that
//! reports on them, so collision resistance buys nothing; a word-at-a-time multiply-rotate
//! (the FxHash scheme) finished by MurmurHash3's 64-bit mixer, so that keys differing only in
//! their high bits (floats such as 4.5 and 5.0) still differ in the low bits the tables
//! index by and in the high bits they tag entries with, is enough.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A `HashMap` with [`WordHasher`].
pub(crate) type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<WordHasher>>;

/// Multiply-rotate hashing, eight bytes at a time.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct WordHasher(u64);

const K: u64 = 0xf135_7aea_2e62_a9c5;

impl Hasher for WordHasher {
    fn write(&mut self, bytes: &[u8]) {
        let mut words = bytes.chunks_exact(8);
        for chunk in words.by_ref() {
            let mut word = [0; 8];
            word.copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
        let mut tail = [0; 8];
        let rest = words.remainder();
        tail[..rest.len()].copy_from_slice(rest);
        // The length tells "a" from "a\0".
        self.write_u64(u64::from_le_bytes(tail) ^ ((rest.len() as u64) << 59));
    }

    fn write_u8(&mut self, x: u8) {
        self.write_u64(u64::from(x));
    }

    fn write_u32(&mut self, x: u32) {
        self.write_u64(u64::from(x));
    }

    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(K);
    }

    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }

    fn finish(&self) -> u64 {
        // MurmurHash3's fmix64: every bit of the state reaches every bit of the hash.
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
}

#[cfg(test)]
mod tests {
    use std::hash::{BuildHasher, BuildHasherDefault};

    use super::WordHasher;

    /// Keys alike but for a byte, a length or their high bits (floats of few significant
    /// digits) spread over the low bits the tables index by and over the top seven they tag
    /// entries with: 1000 such keys take at least 600 of the 1024 values of the low 10 bits (a
    /// uniform hash gives about 630) and at least 120 of the 128 values of the top 7.
    #[test]
    fn similar_keys_spread_over_the_bits_tables_use() {
        let build = BuildHasherDefault::<WordHasher>::default();
        let spread = |hashes: &[u64], bits: fn(u64) -> u64| {
            let mut seen: Vec<u64> = hashes.iter().map(|&h| bits(h)).collect();
            seen.sort_unstable();
            seen.dedup();
            seen.len()
        };
        let ids = (0..1000)
            .map(|i| build.hash_one(format!("walk/wavelet-perceptual/cr{i}")))
            .collect();
        let floats = (0..1000)
            .map(|i| build.hash_one((1.0 + f64::from(i) / 2.0).to_bits()))
            .collect();
        // Three significant bits and 125 exponents: keys that differ in the high bits only.
        let scale = (0..1000_i32)
            .map(|i| build.hash_one((f64::from(8 + i % 8) * 2f64.powi(i / 8 - 60)).to_bits()))
            .collect();
        let lengths = (0..1000).map(|i| build.hash_one("a".repeat(i))).collect();
        let sets: [(&str, Vec<u64>); 4] = [
            ("ids", ids),
            ("floats", floats),
            ("exponents", scale),
            ("lengths", lengths),
        ];
        for (what, hashes) in sets {
            let low = spread(&hashes, |h| h & 1023);
            let top = spread(&hashes, |h| h >> 57);
            assert!(low >= 600, "{what}: {low} of 1024 low-bit values");
            assert!(top >= 120, "{what}: {top} of 128 top-bit values");
        }
    }
}
