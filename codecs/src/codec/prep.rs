//! Preparation shared by the wavelet codecs: Euler unwrapping, channel lengths and the
//! channels' first-order effect on joint positions.

use motion::clip::{ChannelKind, Clip, Skeleton, SkeletonFormat};
use motion::fk::Kinematics;
use motion::math::{Vec3, euler_fixed};

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

/// Length each channel swings, in file units ([`motion::Skeleton::swung_length`]), and the longest
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

/// First-order position sensitivity of every channel at the rest pose: how far, RMS over all
/// FK points of the skeleton, the points move per unit of the channel (per degree of a
/// rotation, per file unit of a translation), in file units.
///
/// A rotation by `δ` about the world axis `u` of a channel moves each point `k` that the joint
/// carries by `|u × r_k|·δ·π/180`, `r_k = p_k − o`, with `o` the pivot (ASF: the start of the
/// joint's bone, the parent's point; BVH and roots: the joint's own point). The axis moves with
/// the pose (Euler channels compose), so the squared displacement is taken half at the rest-pose
/// axis (ASF: the joint's `axis` frame; BVH: the world axes) and half as its expectation over a
/// uniformly random axis, `2/3·|r_k|²`: a twist channel whose rest axis runs along the bone
/// moves nothing at rest but does in other poses. A root translation moves every point by its
/// own amount. The sensitivity is `sqrt(Σ_k displacement_k² / J)`, so that a channel error `e`
/// adds about `(s·e)²` to the squared joint RMS error that [`crate::metrics::compare`] reports.
/// Channels that move no point get 0.
pub(crate) fn position_sensitivity(skeleton: &Skeleton) -> Vec<f64> {
    let kin = Kinematics::new(skeleton);
    let joints = &skeleton.joints;
    let n = joints.len();
    let mut points: Vec<Vec3> = Vec::with_capacity(n);
    kin.pose(&vec![0.0; skeleton.channel_count()], &mut points);
    // carried[j]: j and its descendants (parents come before children).
    let mut carried: Vec<Vec<usize>> = (0..n).map(|j| vec![j]).collect();
    for k in (0..n).rev() {
        if let Some(p) = joints[k].parent {
            let below = std::mem::take(&mut carried[k]);
            carried[p].extend_from_slice(&below);
            carried[k] = below;
        }
    }
    let mut out = Vec::with_capacity(skeleton.channel_count());
    for (j, joint) in joints.iter().enumerate() {
        let frame = match skeleton.format {
            SkeletonFormat::Asf => euler_fixed(&joint.axis_order, &joint.axis_deg),
            SkeletonFormat::Bvh => motion::math::IDENTITY,
        };
        let pivot = match (skeleton.format, joint.parent) {
            (SkeletonFormat::Asf, Some(p)) => points.get(p).copied(),
            _ => points.get(j).copied(),
        }
        .unwrap_or([0.0; 3]);
        for kind in &joint.dofs {
            let s = match kind {
                ChannelKind::Translation(_) => 1.0,
                ChannelKind::Rotation(a) => {
                    let i = a.index();
                    let u = [frame[0][i], frame[1][i], frame[2][i]];
                    let sum: f64 = carried[j]
                        .iter()
                        .filter_map(|&k| points.get(k))
                        .map(|p| {
                            let r = [p[0] - pivot[0], p[1] - pivot[1], p[2] - pivot[2]];
                            let c = [
                                u[1] * r[2] - u[2] * r[1],
                                u[2] * r[0] - u[0] * r[2],
                                u[0] * r[1] - u[1] * r[0],
                            ];
                            let aware = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
                            let iso = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]) * 2.0 / 3.0;
                            0.5 * (aware + iso)
                        })
                        .sum();
                    (sum / points.len().max(1) as f64).sqrt() * std::f64::consts::PI / 180.0
                }
            };
            out.push(s);
        }
    }
    out
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
