//! Conversion between skeleton conventions.
//!
//! ASF → BVH is exact up to Euler decomposition: each ASF bone becomes a BVH joint placed at
//! the bone's start, carrying the bone's local rotation `L = C·M·Cᵀ` as `Zrotation Yrotation
//! Xrotation`; its `OFFSET` is the parent bone's vector (zero under the root), and a leaf bone
//! gets an `End Site` at its own vector. The BVH root carries position and `R_0`. Bones without
//! dofs get no channels. Every ASF point (root and bone ends) is a BVH point of the result.
//!
//! BVH → ASF is not offered: a BVH joint's rotation moves all of its children at once, while an
//! ASF bone carries only its own, so a faithful ASF would need invented bones.

use crate::clip::{Axis, ChannelKind, Clip, ClipError, Joint, Rest, Skeleton, SkeletonFormat};
use crate::fk::Kinematics;
use crate::math::to_euler_zyx_deg;

const ZYX: [ChannelKind; 3] = [
    ChannelKind::Rotation(Axis::Z),
    ChannelKind::Rotation(Axis::Y),
    ChannelKind::Rotation(Axis::X),
];

/// Converts an ASF/AMC clip to a BVH clip with the same joint positions.
///
/// # Errors
/// [`ClipError`] only if the built matrix does not fit (a bug, reported rather than hidden).
/// A clip that is already BVH is returned unchanged.
pub fn asf_to_bvh(clip: &Clip) -> Result<Clip, ClipError> {
    let sk = &clip.skeleton;
    if sk.format == SkeletonFormat::Bvh {
        return Ok(clip.clone());
    }
    let mut joints: Vec<Joint> = Vec::with_capacity(sk.joints.len() * 2);
    // Map from ASF joint to BVH joint (same index), then end sites appended per leaf in DFS
    // order so that parents precede children and channel order follows the hierarchy.
    let mut order = Vec::with_capacity(sk.joints.len());
    dfs(sk, 0, &mut order);
    let mut bvh_index = vec![0; sk.joints.len()];
    for &i in &order {
        let j = &sk.joints[i];
        let parent = j.parent.map(|p| bvh_index[p]);
        let offset = match j.parent {
            None => j.rest.vector(),
            Some(p) if sk.joints[p].parent.is_none() => [0.0; 3],
            Some(p) => sk.joints[p].rest.vector(),
        };
        let dofs = if j.parent.is_none() {
            let mut d: Vec<ChannelKind> = j
                .dofs
                .iter()
                .copied()
                .filter(|k| !k.is_rotation())
                .collect();
            d.extend(ZYX);
            d
        } else if j.dofs.is_empty() {
            Vec::new()
        } else {
            ZYX.to_vec()
        };
        bvh_index[i] = joints.len();
        let mut joint = Joint::new(j.name.clone(), parent, Rest::Offset(offset), dofs);
        joint.body_part = j.body_part;
        joint.chain_depth = j.chain_depth;
        joints.push(joint);
        if j.parent.is_some() && sk.children(i).next().is_none() {
            let name = format!("{}_End", j.name);
            let mut end = Joint::new(
                name,
                Some(bvh_index[i]),
                Rest::Offset(j.rest.vector()),
                vec![],
            );
            end.end_site = true;
            end.body_part = j.body_part;
            end.chain_depth = j.chain_depth + 1;
            joints.push(end);
        }
    }
    let skeleton = Skeleton {
        name: sk.name.clone(),
        format: SkeletonFormat::Bvh,
        units: sk.units,
        joints,
        documentation: Vec::new(),
    };
    let layout = skeleton.channel_layout();
    let frames = clip.frames();
    let mut data = vec![0.0; layout.len() * frames];
    let kin = Kinematics::new(sk);
    let mut values = Vec::new();
    let mut local = Vec::new();
    for f in 0..frames {
        clip.frame_into(f, &mut values);
        kin.local_transforms(&values, &mut local);
        let mut c = 0;
        for &i in &order {
            let bj = &skeleton.joints[bvh_index[i]];
            if bj.dofs.is_empty() {
                continue;
            }
            let lt = &local[i];
            let zyx = to_euler_zyx_deg(&lt.rotation);
            let mut rot = 0;
            for kind in &bj.dofs {
                data[c * frames + f] = match kind {
                    ChannelKind::Translation(a) => lt.translation[a.index()],
                    ChannelKind::Rotation(_) => {
                        rot += 1;
                        zyx[rot - 1]
                    }
                };
                c += 1;
            }
        }
    }
    Clip::new(skeleton, clip.frame_rate_hz, frames, data)
}

fn dfs(sk: &Skeleton, i: usize, out: &mut Vec<usize>) {
    out.push(i);
    for c in sk.children(i).collect::<Vec<_>>() {
        dfs(sk, c, out);
    }
}
