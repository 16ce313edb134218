//! A solved (BVH-style) clip re-expressed as an Acclaim ASF skeleton with AMC motion, so that
//! a skeleton solved from markers can be written as ASF/AMC as well as BVH.
//!
//! A BVH joint's rotation moves all of its children, while an ASF bone carries one vector
//! (its `direction × length`) and every child bone starts at its end. The conversion keeps
//! every BVH point by adding bones without dofs where a BVH joint has more than one child:
//!
//! - the ASF root is the BVH root: `position` = its `OFFSET`, `order TX TY TZ RX RY RZ`,
//!   `orientation 0 0 0`;
//! - each other BVH joint `j` becomes the bone `j` with axis `0 0 0 XYZ`, dofs `rx ry rz`
//!   (none when the BVH joint has no rotation channels) and the vector to its first child
//!   (an end site or a joint) as `direction × length`;
//! - every further child `c` of `j` (every child of the root with a non-zero offset) is reached
//!   through a bone `c_link` without dofs, child of bone `j` (of the root), whose vector is
//!   `offset(c) − vector(j)` (`offset(c)`): a bone without dofs turns with its parent
//!   (`L = C·I·Cᵀ = I`), so its end is the BVH point of `c`.
//!
//! With axis `C = I` every ASF bone's world rotation is the BVH joint's world rotation, and the
//! AMC values are the BVH joint's local rotation `L_j = Rz·Ry·Rx` split as fixed-axis `rx ry
//! rz` (same matrix: seed conventions in [`motion::fk`]). Every BVH point is an ASF point
//! ([`AsfSolved::asf_point_of`]), and forward kinematics of the two agree to rounding.

use motion::clip::{Axis, ChannelKind, Clip, Joint, Rest, Skeleton, SkeletonFormat, Units};
use motion::fk::Kinematics;
use motion::math::to_euler_zyx_deg;

use super::MarkerError;

/// An ASF/AMC clip made from a BVH clip, with the map between their points.
#[derive(Debug, Clone)]
pub struct AsfSolved {
    /// The ASF skeleton and AMC channel matrix (frame rate kept from the BVH clip).
    pub clip: Clip,
    /// For each BVH joint (skeleton index, end sites included), the ASF point (root or bone
    /// end, skeleton index) at the same place.
    pub asf_point_of: Vec<usize>,
}

/// Centimetres per inch: ASF `units length l` means `2.54 / l` cm per file unit.
const CM_PER_INCH: f64 = 2.54;

const ROOT_DOFS: [ChannelKind; 6] = [
    ChannelKind::Translation(Axis::X),
    ChannelKind::Translation(Axis::Y),
    ChannelKind::Translation(Axis::Z),
    ChannelKind::Rotation(Axis::X),
    ChannelKind::Rotation(Axis::Y),
    ChannelKind::Rotation(Axis::Z),
];

const BONE_DOFS: [ChannelKind; 3] = [
    ChannelKind::Rotation(Axis::X),
    ChannelKind::Rotation(Axis::Y),
    ChannelKind::Rotation(Axis::Z),
];

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Exactly zero: a link of any length, however small, keeps its point; only a child at the
/// very same point attaches without one.
fn is_zero(v: [f64; 3]) -> bool {
    v.iter().all(|&x| x == 0.0)
}

fn bone_rest(v: [f64; 3]) -> Rest {
    let length = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    let direction = if length > 0.0 {
        [v[0] / length, v[1] / length, v[2] / length]
    } else {
        // A zero-length bone (a joint with no child): its end is its start.
        [0.0, 1.0, 0.0]
    };
    Rest::Bone { direction, length }
}

/// `name`, or `name` followed by underscores until no joint in `taken` has it (ASF names
/// must be unique, and `root` is the root's).
fn unique(name: &str, taken: &[String]) -> String {
    let mut n = name.to_string();
    while n == "root" || taken.contains(&n) {
        n.push('_');
    }
    n
}

fn bad(clip: &Clip, reason: String) -> MarkerError {
    MarkerError::Solve {
        segment: clip
            .skeleton
            .joints
            .first()
            .map_or_else(String::new, |j| j.name.clone()),
        reason,
    }
}

/// Converts a BVH clip (such as [`super::segments::Solved::clip`]) to ASF/AMC with the same
/// joint positions (see the module docs).
///
/// # Errors
/// [`MarkerError::Solve`] when the clip is not a BVH clip, a joint other than the root has
/// translation channels (ASF bones only rotate), a name contains whitespace (ASF names are
/// one word), or the matrix cannot be built.
pub fn bvh_to_asf(clip: &Clip) -> Result<AsfSolved, MarkerError> {
    let sk = &clip.skeleton;
    if sk.format != SkeletonFormat::Bvh {
        return Err(bad(clip, "ASF conversion expects a BVH clip".into()));
    }
    if sk.joints.is_empty() {
        return Err(bad(clip, "the skeleton has no joints".into()));
    }
    for j in &sk.joints {
        if j.name.is_empty() || j.name.chars().any(char::is_whitespace) {
            return Err(bad(
                clip,
                format!(
                    "joint name {:?} is not one word, as ASF names must be",
                    j.name
                ),
            ));
        }
        if j.parent.is_some() && j.dofs.iter().any(|d| !d.is_rotation()) {
            return Err(bad(
                clip,
                format!(
                    "joint {} has translation channels; ASF bones only rotate",
                    j.name
                ),
            ));
        }
    }
    let (skeleton, bone_of, asf_point_of) = asf_skeleton(sk);
    if asf_point_of.contains(&usize::MAX) {
        return Err(bad(clip, "a joint is not reachable from the root".into()));
    }
    let frames = clip.frames();
    let layout = skeleton.channel_layout();
    // Channel row of each ASF joint's first channel.
    let mut first_channel = vec![0usize; skeleton.joints.len()];
    let mut c = 0;
    for (i, j) in skeleton.joints.iter().enumerate() {
        first_channel[i] = c;
        c += j.dofs.len();
    }
    let mut data = vec![0.0; layout.len() * frames];
    let kin = Kinematics::new(sk);
    let (mut values, mut local) = (Vec::new(), Vec::new());
    for f in 0..frames {
        clip.frame_into(f, &mut values);
        kin.local_transforms(&values, &mut local);
        for (b, lt) in local.iter().enumerate() {
            let a = bone_of[b];
            if a == usize::MAX || skeleton.joints[a].dofs.is_empty() {
                continue;
            }
            // L = Rz·Ry·Rx: BVH `Zrotation Yrotation Xrotation` read in listed order, ASF
            // `rx ry rz` read as fixed axes (motion::math::euler_fixed).
            let [z, y, x] = to_euler_zyx_deg(&lt.rotation);
            let mut row = first_channel[a];
            if a == 0 {
                for k in 0..3 {
                    data[(row + k) * frames + f] = lt.translation[k];
                }
                row += 3;
            }
            for (k, angle) in [x, y, z].into_iter().enumerate() {
                data[(row + k) * frames + f] = angle;
            }
        }
    }
    let asf = Clip::new(skeleton, clip.frame_rate_hz, frames, data)
        .map_err(|e| bad(clip, format!("cannot build the ASF clip: {e}")))?;
    Ok(AsfSolved {
        clip: asf,
        asf_point_of,
    })
}

/// The ASF skeleton of a BVH skeleton (module docs), the ASF bone carrying each BVH joint's
/// rotation (`usize::MAX` for end sites) and the ASF point of each BVH point (`usize::MAX`
/// for a joint not reachable from the root).
fn asf_skeleton(sk: &Skeleton) -> (Skeleton, Vec<usize>, Vec<usize>) {
    let n = sk.joints.len();
    let children: Vec<Vec<usize>> = (0..n).map(|i| sk.children(i).collect()).collect();
    // Depth-first pre-order, so that every ASF parent precedes its children in file order
    // (the ASF reader then keeps the order) and AMC channels follow the hierarchy.
    let mut order = Vec::with_capacity(n);
    let mut stack = vec![0usize];
    while let Some(j) = stack.pop() {
        order.push(j);
        stack.extend(children[j].iter().rev());
    }
    let mut joints: Vec<Joint> = Vec::with_capacity(2 * n);
    let mut names: Vec<String> = Vec::with_capacity(2 * n);
    // ASF bone carrying each BVH joint's rotation (root: 0), and the ASF point of each BVH
    // point.
    let mut bone_of = vec![usize::MAX; n];
    let mut asf_point_of = vec![usize::MAX; n];
    let mut root = Joint::new(
        "root".into(),
        None,
        Rest::Offset(sk.joints[0].rest.vector()),
        ROOT_DOFS.to_vec(),
    );
    root.body_part = sk.joints[0].body_part;
    joints.push(root);
    names.push("root".into());
    bone_of[0] = 0;
    asf_point_of[0] = 0;
    let mut push = |joints: &mut Vec<Joint>, name: &str, parent: usize, v: [f64; 3], dofs: bool| {
        let name = unique(name, &names);
        names.push(name.clone());
        let mut j = Joint::new(
            name,
            Some(parent),
            bone_rest(v),
            if dofs { BONE_DOFS.to_vec() } else { Vec::new() },
        );
        j.id = u32::try_from(joints.len()).ok();
        joints.push(j);
        joints.len() - 1
    };
    for &j in &order {
        if sk.joints[j].end_site {
            continue;
        }
        let kids = &children[j];
        // The root has no bone (its point is its end); another joint's bone starts where the
        // joint is, at the point set when its parent was visited (pre-order), and ends at its
        // first child.
        let (base, v) = if j == 0 {
            (0, [0.0; 3])
        } else {
            let v = kids
                .first()
                .map_or([0.0; 3], |&c| sk.joints[c].rest.vector());
            let bone = push(
                &mut joints,
                &sk.joints[j].name,
                asf_point_of[j],
                v,
                !sk.joints[j].dofs.is_empty(),
            );
            bone_of[j] = bone;
            (bone, v)
        };
        // A child at the bone's end (the first child: `o − o` is exactly zero) starts there;
        // any other is reached through a link bone without dofs.
        for &c in kids {
            let d = sub(sk.joints[c].rest.vector(), v);
            asf_point_of[c] = if is_zero(d) {
                base
            } else {
                let name = format!("{}_link", sk.joints[c].name);
                push(&mut joints, &name, base, d, false)
            };
        }
    }
    let asf_length = CM_PER_INCH / sk.units.cm_per_unit;
    let mut skeleton = Skeleton {
        name: sk.name.clone(),
        format: SkeletonFormat::Asf,
        units: Units {
            cm_per_unit: sk.units.cm_per_unit,
            asf_length,
            asf_mass: 1.0,
            declared: true,
        },
        joints,
        documentation: sk.documentation.clone(),
    };
    motion::bodymap::assign(&mut skeleton);
    (skeleton, bone_of, asf_point_of)
}
