//! Poses at arbitrary presentation times, for the runner's renderer.
//!
//! Playback is driven by presentation time, not frame count: the renderer asks for the pose at
//! `t` seconds and gets the clip's joints with every joint's local rotation interpolated by
//! SLERP between the two nearest frames and translations linearly, so a 120 Hz clip shown at
//! 60, 144 or 21 Hz (software rendering) moves at the right speed and both viewports of a
//! trial show the same instant.

use crate::clip::Clip;
use crate::fk::{Kinematics, LocalTransform};
use crate::math::{Mat3, Vec3};
use crate::quat::Quat;

/// Precomputed local rotations (as quaternions) and translations of every joint and frame.
#[derive(Debug, Clone)]
pub struct Sampler {
    kin: Kinematics,
    frames: usize,
    joints: usize,
    frame_rate_hz: f64,
    rotations: Vec<Quat>,
    translations: Vec<Vec3>,
}

/// What happens after the last frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndMode {
    /// Hold the last frame.
    Hold,
    /// Start again from the first frame.
    Loop,
}

impl Sampler {
    /// Prepares a clip for sampling (one FK local pass over every frame).
    pub fn new(clip: &Clip) -> Sampler {
        let kin = Kinematics::new(&clip.skeleton);
        let joints = kin.joint_count();
        let frames = clip.frames();
        let mut rotations = Vec::with_capacity(frames * joints);
        let mut translations = Vec::with_capacity(frames * joints);
        let mut values = Vec::new();
        let mut local = Vec::new();
        for f in 0..frames {
            clip.frame_into(f, &mut values);
            kin.local_transforms(&values, &mut local);
            for (j, lt) in local.iter().enumerate() {
                let mut q = Quat::from_mat3(&lt.rotation);
                // Keep each joint on one hemisphere over time so SLERP takes the short arc.
                if f > 0 && q.dot(rotations[(f - 1) * joints + j]) < 0.0 {
                    q = -q;
                }
                rotations.push(q);
                translations.push(lt.translation);
            }
        }
        Sampler {
            kin,
            frames,
            joints,
            frame_rate_hz: clip.frame_rate_hz,
            rotations,
            translations,
        }
    }

    /// Duration in seconds from the first to one frame past the last frame.
    pub fn duration_s(&self) -> f64 {
        self.frames as f64 / self.frame_rate_hz
    }

    /// Number of points a pose has.
    pub fn joint_count(&self) -> usize {
        self.joints
    }

    /// World points at presentation time `t_s` (seconds from the clip's start).
    pub fn pose_at(&self, t_s: f64, end: EndMode, points: &mut Vec<Vec3>) {
        let x = if t_s.is_finite() {
            t_s.max(0.0) * self.frame_rate_hz
        } else {
            0.0
        };
        let n = self.frames;
        let (i, next, u) = match end {
            // Looping: the last frame blends into the first across the seam.
            EndMode::Loop if n > 1 => {
                let x = x % n as f64;
                let i = (x.floor() as usize).min(n - 1);
                (i, (i + 1) % n, x - i as f64)
            }
            _ if x >= (n - 1) as f64 => (n - 1, n - 1, 0.0),
            _ => (x.floor() as usize, x.floor() as usize + 1, x.fract()),
        };
        let mut local: Vec<LocalTransform> = Vec::with_capacity(self.joints);
        for j in 0..self.joints {
            let (a, b) = (
                self.rotations[i * self.joints + j],
                self.rotations[next * self.joints + j],
            );
            let (ta, tb) = (
                self.translations[i * self.joints + j],
                self.translations[next * self.joints + j],
            );
            let q = if u > 0.0 { a.slerp(b, u) } else { a };
            let t = [
                ta[0] + u * (tb[0] - ta[0]),
                ta[1] + u * (tb[1] - ta[1]),
                ta[2] + u * (tb[2] - ta[2]),
            ];
            local.push(LocalTransform {
                rotation: q.to_mat3(),
                translation: t,
            });
        }
        let mut rotations: Vec<Mat3> = Vec::with_capacity(self.joints);
        self.kin.world(&local, points, &mut rotations);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fk::positions;
    use crate::synth::{WalkParams, walking_clip};

    #[test]
    fn at_frame_times_the_pose_is_the_frame() {
        let clip = walking_clip(&WalkParams {
            duration_s: 0.5,
            ..WalkParams::default()
        });
        let s = Sampler::new(&clip);
        let p = positions(&clip);
        let mut pts = Vec::new();
        for f in [0, 7, 59] {
            s.pose_at(f as f64 / clip.frame_rate_hz, EndMode::Hold, &mut pts);
            for (j, q) in pts.iter().enumerate() {
                let r = p.point(f, j);
                assert!(
                    (0..3).all(|k| (q[k] - r[k]).abs() < 1e-9),
                    "frame {f} joint {j}"
                );
            }
        }
    }

    #[test]
    fn between_frames_joints_move_between_their_neighbours() {
        let clip = walking_clip(&WalkParams {
            duration_s: 0.5,
            ..WalkParams::default()
        });
        let s = Sampler::new(&clip);
        let p = positions(&clip);
        let mut pts = Vec::new();
        s.pose_at(10.5 / clip.frame_rate_hz, EndMode::Hold, &mut pts);
        for (j, q) in pts.iter().enumerate() {
            let (a, b) = (p.point(10, j), p.point(11, j));
            for k in 0..3 {
                let (lo, hi) = (a[k].min(b[k]), a[k].max(b[k]));
                assert!(q[k] >= lo - 1e-3 && q[k] <= hi + 1e-3, "joint {j} axis {k}");
            }
        }
        // Past the end: hold the last frame, or wrap around when looping.
        s.pose_at(100.0, EndMode::Hold, &mut pts);
        let last = p.point(p.frames() - 1, 0);
        assert!((pts[0][2] - last[2]).abs() < 1e-9);
        s.pose_at(
            s.duration_s() + 5.0 / clip.frame_rate_hz,
            EndMode::Loop,
            &mut pts,
        );
        assert!((pts[0][2] - p.point(5, 0)[2]).abs() < 1e-9);
    }
}
