//! A clip as the page draws it: joint positions by forward kinematics, in centimetres, as
//! little-endian `f32` (format `MCJP` version 1).
//!
//! ```text
//! offset  size            field
//! 0       4               magic "MCJP"
//! 4       2               version (1)
//! 6       2               joints J
//! 8       4               frames F
//! 12      4               frame rate, Hz (f32)
//! 16      2 * J           parent of each joint (i16, -1 for a root), skeleton order
//! ...     0 or 2          padding to a multiple of 4
//! ...     12 * J * F      x, y, z of every joint of every frame, cm (f32), frame-major
//! ```

use motion::Clip;

/// The format's magic bytes.
pub const MAGIC: &[u8; 4] = b"MCJP";

/// Encodes `clip`'s joint positions.
pub fn encode(clip: &Clip) -> Vec<u8> {
    let pos = motion::fk::positions(clip);
    let (j, f) = (pos.joint_count(), pos.frames());
    let header = 16 + 2 * j;
    let pad = (4 - header % 4) % 4;
    let mut out = Vec::with_capacity(header + pad + 12 * j * f);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&1u16.to_le_bytes());
    out.extend_from_slice(&(j.min(usize::from(u16::MAX)) as u16).to_le_bytes());
    out.extend_from_slice(&(f as u32).to_le_bytes());
    out.extend_from_slice(&(clip.frame_rate_hz as f32).to_le_bytes());
    for p in &pos.parents {
        let v: i16 = p.map_or(-1, |p| p as i16);
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.resize(out.len() + pad, 0);
    let k = pos.cm_per_unit;
    for frame in 0..f {
        for joint in 0..j {
            let p = pos.point(frame, joint);
            for v in p {
                out.extend_from_slice(&((v * k) as f32).to_le_bytes());
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::synth::{WalkParams, walking_clip};

    #[test]
    fn positions_round_trip_through_the_layout() {
        let clip = walking_clip(&WalkParams {
            duration_s: 0.2,
            frame_rate_hz: 30.0,
            ..WalkParams::default()
        });
        let bytes = encode(&clip);
        let pos = motion::fk::positions(&clip);
        let (j, f) = (pos.joint_count(), pos.frames());
        assert_eq!(&bytes[..4], MAGIC);
        assert_eq!(u16::from_le_bytes([bytes[6], bytes[7]]) as usize, j);
        assert_eq!(
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            f
        );
        let start = (16 + 2 * j).div_ceil(4) * 4;
        assert_eq!(bytes.len(), start + 12 * j * f);
        // The last joint's z in the last frame, in cm.
        let at = bytes.len() - 4;
        let z = f32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]);
        let want = pos.point(f - 1, j - 1)[2] * pos.cm_per_unit;
        assert!(
            (f64::from(z) - want).abs() < 1e-3 * want.abs().max(1.0),
            "{z} vs {want}"
        );
        // A parent of -1 only for the root.
        let parent0 = i16::from_le_bytes([bytes[16], bytes[17]]);
        assert_eq!(parent0, -1);
    }
}
