//! Forward kinematics: world positions of every joint for every frame, in `f64`.
//!
//! Conventions (checked against the CMU data: with the feet planted the toes do not slide):
//!
//! **ASF/AMC.** Axis and dof rotations are about fixed axes applied in the listed order, so
//! `XYZ` means `R = Rz·Ry·Rx` (column vectors). A bone with axis rotation `C` (its `axis`
//! line) and dof rotation `M` has local rotation `L = C·M·Cᵀ`; its world rotation is
//! `R_bone = R_parent·L`, and its end is `start + R_bone·(direction × length)`, where `start`
//! is the parent bone's end (or the root point). The root stands at `position + (TX, TY, TZ)`
//! with `R_0 = euler(orientation, axis order)·euler(root rotations)`. Points reported: the root
//! and the end of each bone (31 for CMU skeletons).
//!
//! **BVH.** A joint's local rotation is the product of its rotation channels in listed order
//! (`Zrotation Xrotation Yrotation` gives `Rz·Rx·Ry`); its local translation is `OFFSET` plus
//! its position channels. World rotation `R_j = R_parent·L_j`, world point
//! `p_j = p_parent + R_parent·t_j`. End sites are reported as `<parent>_End`.

use crate::clip::{ChannelKind, Clip, Skeleton, SkeletonFormat};
use crate::math::{IDENTITY, Mat3, Vec3, add, euler_fixed, mul, mul_vec, transpose};

/// World positions of every joint over a clip, frame-major, in file units.
#[derive(Debug, Clone, PartialEq)]
pub struct Positions {
    /// Joint names, one per point (skeleton order).
    pub names: Vec<String>,
    /// Parent of each point (draw a segment from the parent's point to the point).
    pub parents: Vec<Option<usize>>,
    /// Centimetres per file unit.
    pub cm_per_unit: f64,
    frames: usize,
    points: Vec<Vec3>,
}

impl Positions {
    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Number of points per frame.
    pub fn joint_count(&self) -> usize {
        self.names.len()
    }

    /// Position of `joint` at `frame`, file units.
    pub fn point(&self, frame: usize, joint: usize) -> Vec3 {
        self.points[frame * self.names.len() + joint]
    }

    /// All points of one frame.
    pub fn frame(&self, frame: usize) -> &[Vec3] {
        let n = self.names.len();
        &self.points[frame * n..(frame + 1) * n]
    }
}

/// Precomputed per-skeleton data for fast repeated FK.
#[derive(Debug, Clone)]
pub struct Kinematics {
    format: SkeletonFormat,
    parents: Vec<Option<usize>>,
    /// ASF: `C` and `Cᵀ` per joint (root: orientation matrix and identity).
    axis: Vec<(Mat3, Mat3)>,
    rest: Vec<Vec3>,
    /// First channel index of each joint and its channels.
    channels: Vec<(usize, Vec<ChannelKind>)>,
}

/// One joint's local transform for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalTransform {
    /// Local rotation `L` (ASF: `C·M·Cᵀ`, root: orientation·rotations; BVH: channel product).
    pub rotation: Mat3,
    /// Translation channels' values `(x, y, z)` in file units (zero when the joint has none).
    pub translation: Vec3,
}

impl Kinematics {
    /// Prepares FK for a skeleton.
    pub fn new(skeleton: &Skeleton) -> Kinematics {
        let mut first = 0;
        let mut channels = Vec::with_capacity(skeleton.joints.len());
        let mut axis = Vec::with_capacity(skeleton.joints.len());
        for j in &skeleton.joints {
            channels.push((first, j.dofs.clone()));
            first += j.dofs.len();
            let c = match skeleton.format {
                SkeletonFormat::Asf => euler_fixed(&j.axis_order, &j.axis_deg),
                SkeletonFormat::Bvh => IDENTITY,
            };
            axis.push((c, transpose(&c)));
        }
        Kinematics {
            format: skeleton.format,
            parents: skeleton.joints.iter().map(|j| j.parent).collect(),
            axis,
            rest: skeleton.joints.iter().map(|j| j.rest.vector()).collect(),
            channels,
        }
    }

    /// Number of joints.
    pub fn joint_count(&self) -> usize {
        self.parents.len()
    }

    /// Local transforms of every joint from one frame's channel values (skeleton layout).
    pub fn local_transforms(&self, values: &[f64], out: &mut Vec<LocalTransform>) {
        out.clear();
        for (j, (first, kinds)) in self.channels.iter().enumerate() {
            let mut m = IDENTITY;
            let mut t = [0.0; 3];
            for (k, kind) in kinds.iter().enumerate() {
                let v = values.get(first + k).copied().unwrap_or(0.0);
                match kind {
                    ChannelKind::Translation(a) => t[a.index()] += v,
                    ChannelKind::Rotation(a) => {
                        let r = crate::math::rot_axis(*a, v);
                        m = match self.format {
                            // ASF: fixed axes in listed order (pre-multiply).
                            SkeletonFormat::Asf => mul(&r, &m),
                            // BVH: product in listed order (post-multiply).
                            SkeletonFormat::Bvh => mul(&m, &r),
                        };
                    }
                }
            }
            let rotation = match (self.format, self.parents[j]) {
                (SkeletonFormat::Asf, None) => mul(&self.axis[j].0, &m),
                (SkeletonFormat::Asf, Some(_)) => mul(&mul(&self.axis[j].0, &m), &self.axis[j].1),
                (SkeletonFormat::Bvh, _) => m,
            };
            out.push(LocalTransform {
                rotation,
                translation: t,
            });
        }
    }

    /// World points (and, in `rotations`, world rotations) from local transforms.
    pub fn world(
        &self,
        local: &[LocalTransform],
        points: &mut Vec<Vec3>,
        rotations: &mut Vec<Mat3>,
    ) {
        points.clear();
        rotations.clear();
        for (j, lt) in local.iter().enumerate() {
            let (p, r) = match self.parents[j] {
                // The root stands at its rest offset plus its translation channels.
                None => (add(&self.rest[j], &lt.translation), lt.rotation),
                Some(parent) => {
                    let rp = rotations[parent];
                    let pp = points[parent];
                    match self.format {
                        SkeletonFormat::Asf => {
                            let r = mul(&rp, &lt.rotation);
                            (add(&pp, &mul_vec(&r, &self.rest[j])), r)
                        }
                        SkeletonFormat::Bvh => {
                            let t = add(&self.rest[j], &lt.translation);
                            (add(&pp, &mul_vec(&rp, &t)), mul(&rp, &lt.rotation))
                        }
                    }
                }
            };
            points.push(p);
            rotations.push(r);
        }
    }

    /// World points of one frame from its channel values.
    pub fn pose(&self, values: &[f64], points: &mut Vec<Vec3>) {
        let mut local = Vec::with_capacity(self.joint_count());
        let mut rotations = Vec::with_capacity(self.joint_count());
        self.local_transforms(values, &mut local);
        self.world(&local, points, &mut rotations);
    }
}

/// World positions of every joint for every frame of a clip.
pub fn positions(clip: &Clip) -> Positions {
    let kin = Kinematics::new(&clip.skeleton);
    let n = kin.joint_count();
    let mut points = Vec::with_capacity(n * clip.frames());
    let mut values = Vec::with_capacity(clip.channel_count());
    let mut local = Vec::with_capacity(n);
    let mut rotations = Vec::with_capacity(n);
    let mut frame_points = Vec::with_capacity(n);
    for f in 0..clip.frames() {
        clip.frame_into(f, &mut values);
        kin.local_transforms(&values, &mut local);
        kin.world(&local, &mut frame_points, &mut rotations);
        points.extend_from_slice(&frame_points);
    }
    Positions {
        names: clip
            .skeleton
            .joints
            .iter()
            .map(|j| j.name.clone())
            .collect(),
        parents: clip.skeleton.joints.iter().map(|j| j.parent).collect(),
        cm_per_unit: clip.skeleton.units.cm_per_unit,
        frames: clip.frames(),
        points,
    }
}
