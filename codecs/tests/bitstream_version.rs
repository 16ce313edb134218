//! The container's format version field (`docs/bitstream.md`: offset 4, `u16` LE, = 1): every
//! codec's stream carries the current version and round-trips; a stream from another version
//! (older, or one a future build writes) is refused with an error that names that version,
//! even when the rest of the stream, CRC included, is well formed.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use codecs::bitstream::{Bitstream, BitstreamError, FORMAT_VERSION};
use codecs::codec::{self, Params};
use motion::Clip;
use motion::synth::{WalkParams, walking_clip};

/// Where the version lives, as documented.
const VERSION_AT: usize = 4;

fn clip() -> Clip {
    walking_clip(&WalkParams {
        duration_s: 0.5,
        ..WalkParams::default()
    })
}

/// Every codec's stream of `clip`, serialized: (codec name, bytes).
fn streams(clip: &Clip) -> Vec<(String, Vec<u8>)> {
    codec::registry()
        .iter()
        .map(|c| {
            let mut p = Params::new();
            if c.name().starts_with("wavelet") {
                p.insert("window".into(), 64.0);
            }
            let bytes = c.encode(clip, &p).unwrap().to_bytes().unwrap();
            (c.name().to_owned(), bytes)
        })
        .collect()
}

/// `bytes` with the version field set to `version` and the CRC recomputed, so that only the
/// version differs from a valid stream.
fn with_version(bytes: &[u8], version: u16) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[VERSION_AT..VERSION_AT + 2].copy_from_slice(&version.to_le_bytes());
    let body = b.len() - 4;
    let crc = crc32fast::hash(&b[..body]);
    b[body..].copy_from_slice(&crc.to_le_bytes());
    b
}

#[test]
fn every_codec_writes_the_current_version_and_round_trips() {
    assert_eq!(FORMAT_VERSION, 1, "docs/bitstream.md documents version 1");
    let clip = clip();
    let all = streams(&clip);
    assert!(all.len() >= 7, "every registered codec: {}", all.len());
    for (name, bytes) in &all {
        assert_eq!(
            bytes[VERSION_AT..VERSION_AT + 2],
            FORMAT_VERSION.to_le_bytes(),
            "{name}: version field"
        );
        let parsed = Bitstream::from_bytes(bytes).unwrap();
        assert_eq!(
            &parsed.to_bytes().unwrap(),
            bytes,
            "{name}: bytes round-trip"
        );
        assert_eq!(
            with_version(bytes, FORMAT_VERSION),
            *bytes,
            "{name}: rewriting the current version changes nothing"
        );
        let decoded = codec::decode_any(&parsed, &clip.skeleton).unwrap();
        assert_eq!(decoded.frames(), clip.frames(), "{name}");
    }
}

#[test]
fn another_version_is_refused_naming_it() {
    let clip = clip();
    for (name, bytes) in &streams(&clip) {
        for version in [0, 2, 3, 0x00ff, 0x0100, 0x0201, u16::MAX] {
            let b = with_version(bytes, version);
            match Bitstream::from_bytes(&b) {
                Err(e @ BitstreamError::Version(v)) => {
                    assert_eq!(v, version, "{name}");
                    let msg = e.to_string();
                    assert!(msg.contains(&format!("version {version}")), "{name}: {msg}");
                }
                other => panic!("{name}: version {version} gave {other:?}"),
            }
        }
    }
}
