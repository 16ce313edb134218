//! The primitive database file against corruption: every mutated file is refused with a
//! message naming the file, never a panic or a huge allocation.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::Path;
use std::sync::OnceLock;

use codecs::primitives::{Database, TrainParams};
use proptest::prelude::*;

fn db_bytes() -> &'static Vec<u8> {
    static B: OnceLock<Vec<u8>> = OnceLock::new();
    B.get_or_init(|| {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let params = TrainParams {
            k_max: 6,
            ..TrainParams::default()
        };
        Database::train(&[&clip], &params, |_, _| {}).to_bytes()
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1000, failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"))), ..ProptestConfig::default() })]

    #[test]
    fn corrupt_databases_are_refused(
        flips in prop::collection::vec((any::<usize>(), 1u8..=255), 1..4),
        cut in prop::option::of(any::<usize>()),
    ) {
        let mut b = db_bytes().clone();
        for (i, x) in &flips {
            let k = i % b.len();
            b[k] ^= x;
        }
        if let Some(c) = cut {
            b.truncate(c % b.len());
        }
        let p = Path::new("mutated.pdb");
        // Any change at all must be caught (CRC-32 detects all 1-3 byte errors in this size).
        let e = Database::from_bytes(&b, p).expect_err("a corrupted database was accepted");
        prop_assert!(e.to_string().contains("mutated.pdb"), "{e}");
    }
}

#[test]
fn declared_counts_beyond_the_bytes_are_refused_before_allocating() {
    let mut b = db_bytes().clone();
    // The body length field (bytes 12..20) claims a huge body.
    b[12..20].copy_from_slice(&u64::MAX.to_le_bytes());
    let e = Database::from_bytes(&b, Path::new("x.pdb"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("does not match the file size"), "{e}");
}
