//! Preparation shared by the wavelet codecs: Euler unwrapping and channel lengths.

use crate::clip::{ChannelKind, Clip};

/// Unwraps an angle channel in degrees in place: every frame-to-frame jump larger than 180° is
/// taken as a wrap and removed by adding a multiple of 360°. Returns true if anything changed.
/// A wavelet sees a 360° jump as a huge edge; unwrapped, the channel is smooth again.
pub fn unwrap_degrees(x: &mut [f64]) -> bool {
    let mut offset = 0.0;
    let mut changed = false;
    let Some(&mut first) = x.first_mut() else {
        return false;
    };
    let mut prev_raw = first;
    for v in x.iter_mut().skip(1) {
        let raw = *v;
        let d = raw - prev_raw;
        if d.abs() > 180.0 {
            offset -= 360.0 * (d / 360.0).round();
            changed = true;
        }
        prev_raw = raw;
        *v = raw + offset;
    }
    changed
}

/// Wraps angles in degrees into (−180°, 180°]: the inverse of [`unwrap_degrees`] for channels
/// whose source stays within that interval (all CMU AMC and BVH data).
pub fn wrap_degrees(x: &mut [f64]) {
    for v in x {
        if *v > 180.0 || *v <= -180.0 {
            let w = *v - 360.0 * (*v / 360.0).round();
            *v = if w <= -180.0 { w + 360.0 } else { w };
        }
    }
}

/// The decoder's inverse of [`unwrapped_matrix`]: wraps the flagged channels of a
/// channel-major matrix back into (−180°, 180°].
pub(crate) fn wrap_flagged(data: &mut [f64], frames: usize, flags: &[bool]) {
    for (c, &f) in flags.iter().enumerate() {
        if f {
            wrap_degrees(&mut data[c * frames..(c + 1) * frames]);
        }
    }
}

/// Channel-major copy of a clip with rotation channels unwrapped, and a flag per channel that
/// says whether unwrapping changed it (those are wrapped back after decoding).
pub(crate) fn unwrapped_matrix(clip: &Clip) -> (Vec<f64>, Vec<bool>) {
    let mut data = clip.data().to_vec();
    let frames = clip.frames();
    let mut flags = Vec::with_capacity(clip.channel_count());
    for (c, ch) in clip.channels().iter().enumerate() {
        let row = &mut data[c * frames..(c + 1) * frames];
        flags.push(ch.kind.is_rotation() && unwrap_degrees(row));
    }
    (data, flags)
}

/// Length each channel swings, in file units ([`crate::Skeleton::swung_length`]), and the longest
/// over the skeleton (paper 000 step 3 normalizes by it).
pub(crate) fn channel_lengths(clip: &Clip) -> (Vec<f64>, f64) {
    let sk = &clip.skeleton;
    let lens: Vec<f64> = clip
        .channels()
        .iter()
        .map(|ch| sk.swung_length(ch.joint))
        .collect();
    let max = (0..sk.joints.len())
        .map(|j| sk.swung_length(j))
        .fold(0.0, f64::max);
    (lens, if max > 0.0 { max } else { 1.0 })
}

/// True for root translation channels.
pub(crate) fn is_translation(kind: ChannelKind) -> bool {
    matches!(kind, ChannelKind::Translation(_))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unwrap_then_wrap_restores() {
        let src = [170.0, 178.0, -176.0, -170.0, 179.0, -179.5, 10.0];
        let mut x = src;
        assert!(unwrap_degrees(&mut x));
        assert!((x[2] - 184.0).abs() < 1e-12);
        for w in x.windows(2) {
            assert!((w[1] - w[0]).abs() <= 180.0 || w == [x[5], x[6]]);
        }
        wrap_degrees(&mut x);
        for (a, b) in x.iter().zip(&src) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }
}
