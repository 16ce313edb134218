//! Unit quaternions and the quaternion form of a clip.
//!
//! Thesis ch. 4-5 work on joint rotations as unit quaternions (SLERP blending, the segment
//! distance `d(q1, q2) = acos(2(q1·q2)² − 1)`, angular velocity `ω = 2·log(q(i−1)⁻¹·q(i))`), and
//! the renderer interpolates 120 Hz frames to the display by SLERP. [`QuatClip`] holds, per
//! joint with rotation channels, the rotation those channels make (ASF: the dof rotation `M` in
//! the bone's axis frame; BVH: the channel product `L`), hemisphere-consistent over time, and
//! keeps translation channels as they are. Converting back decomposes each rotation into the
//! joint's own channel order and unwraps each angle to the one nearest the previous frame, so
//! Euler wraps do not come back as 360° jumps.

use crate::clip::{Axis, ChannelKind, Clip, Skeleton, SkeletonFormat};
use crate::math::{Mat3, Vec3};

/// A quaternion `w + xi + yj + zk`; rotations use unit quaternions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quat {
    /// Scalar part.
    pub w: f64,
    /// i component.
    pub x: f64,
    /// j component.
    pub y: f64,
    /// k component.
    pub z: f64,
}

impl Quat {
    /// The identity rotation.
    pub const IDENTITY: Quat = Quat {
        w: 1.0,
        x: 0.0,
        y: 0.0,
        z: 0.0,
    };

    /// Rotation by `angle_deg` about a coordinate axis.
    pub fn from_axis(axis: Axis, angle_deg: f64) -> Quat {
        let (s, c) = (angle_deg.to_radians() / 2.0).sin_cos();
        match axis {
            Axis::X => Quat {
                w: c,
                x: s,
                y: 0.0,
                z: 0.0,
            },
            Axis::Y => Quat {
                w: c,
                x: 0.0,
                y: s,
                z: 0.0,
            },
            Axis::Z => Quat {
                w: c,
                x: 0.0,
                y: 0.0,
                z: s,
            },
        }
    }

    /// The rotation of a proper rotation matrix (Shepperd's method, stable for all angles).
    pub fn from_mat3(m: &Mat3) -> Quat {
        let tr = m[0][0] + m[1][1] + m[2][2];
        let q = if tr > 0.0 {
            let s = (tr + 1.0).sqrt() * 2.0;
            Quat {
                w: 0.25 * s,
                x: (m[2][1] - m[1][2]) / s,
                y: (m[0][2] - m[2][0]) / s,
                z: (m[1][0] - m[0][1]) / s,
            }
        } else if m[0][0] > m[1][1] && m[0][0] > m[2][2] {
            let s = (1.0 + m[0][0] - m[1][1] - m[2][2]).sqrt() * 2.0;
            Quat {
                w: (m[2][1] - m[1][2]) / s,
                x: 0.25 * s,
                y: (m[0][1] + m[1][0]) / s,
                z: (m[0][2] + m[2][0]) / s,
            }
        } else if m[1][1] > m[2][2] {
            let s = (1.0 + m[1][1] - m[0][0] - m[2][2]).sqrt() * 2.0;
            Quat {
                w: (m[0][2] - m[2][0]) / s,
                x: (m[0][1] + m[1][0]) / s,
                y: 0.25 * s,
                z: (m[1][2] + m[2][1]) / s,
            }
        } else {
            let s = (1.0 + m[2][2] - m[0][0] - m[1][1]).sqrt() * 2.0;
            Quat {
                w: (m[1][0] - m[0][1]) / s,
                x: (m[0][2] + m[2][0]) / s,
                y: (m[1][2] + m[2][1]) / s,
                z: 0.25 * s,
            }
        };
        q.normalized()
    }

    /// The rotation matrix.
    pub fn to_mat3(self) -> Mat3 {
        let Quat { w, x, y, z } = self;
        [
            [
                1.0 - 2.0 * (y * y + z * z),
                2.0 * (x * y - w * z),
                2.0 * (x * z + w * y),
            ],
            [
                2.0 * (x * y + w * z),
                1.0 - 2.0 * (x * x + z * z),
                2.0 * (y * z - w * x),
            ],
            [
                2.0 * (x * z - w * y),
                2.0 * (y * z + w * x),
                1.0 - 2.0 * (x * x + y * y),
            ],
        ]
    }

    /// Conjugate (the inverse of a unit quaternion).
    #[must_use]
    pub fn conj(self) -> Quat {
        Quat {
            w: self.w,
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }

    /// 4-D dot product.
    pub fn dot(self, o: Quat) -> f64 {
        self.w * o.w + self.x * o.x + self.y * o.y + self.z * o.z
    }

    /// Scaled to unit length (the identity if the length is zero or not finite).
    #[must_use]
    pub fn normalized(self) -> Quat {
        let n = self.dot(self).sqrt();
        if n.is_finite() && n > 0.0 {
            Quat {
                w: self.w / n,
                x: self.x / n,
                y: self.y / n,
                z: self.z / n,
            }
        } else {
            Quat::IDENTITY
        }
    }

    /// Spherical linear interpolation from `self` (t = 0) to `o` (t = 1) along the shorter arc.
    #[must_use]
    pub fn slerp(self, o: Quat, t: f64) -> Quat {
        let mut d = self.dot(o);
        let o = if d < 0.0 {
            d = -d;
            -o
        } else {
            o
        };
        if d > 1.0 - 1e-12 {
            // Nearly the same rotation: linear interpolation is exact to rounding.
            return Quat {
                w: self.w + t * (o.w - self.w),
                x: self.x + t * (o.x - self.x),
                y: self.y + t * (o.y - self.y),
                z: self.z + t * (o.z - self.z),
            }
            .normalized();
        }
        let theta = d.clamp(-1.0, 1.0).acos();
        let s = theta.sin();
        let a = ((1.0 - t) * theta).sin() / s;
        let b = (t * theta).sin() / s;
        Quat {
            w: a * self.w + b * o.w,
            x: a * self.x + b * o.x,
            y: a * self.y + b * o.y,
            z: a * self.z + b * o.z,
        }
    }

    /// Logarithm of a unit quaternion: the rotation vector divided by two (radians).
    pub fn log(self) -> Vec3 {
        let q = if self.w < 0.0 { -self } else { self };
        let v = (q.x * q.x + q.y * q.y + q.z * q.z).sqrt();
        if v < 1e-15 {
            return [q.x, q.y, q.z];
        }
        let half = v.atan2(q.w);
        [q.x / v * half, q.y / v * half, q.z / v * half]
    }

    /// Exponential of a pure quaternion `(0, v)`: the inverse of [`Quat::log`].
    pub fn exp(v: Vec3) -> Quat {
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if n < 1e-15 {
            return Quat {
                w: 1.0,
                x: v[0],
                y: v[1],
                z: v[2],
            }
            .normalized();
        }
        let s = n.sin() / n;
        Quat {
            w: n.cos(),
            x: v[0] * s,
            y: v[1] * s,
            z: v[2] * s,
        }
    }

    /// The distance of thesis eq. 5.3, `acos(2(q1·q2)² − 1)`: the rotation angle between the
    /// two orientations in radians, in `[0, π]`, the same for `q` and `−q`.
    pub fn distance(self, o: Quat) -> f64 {
        let d = self.dot(o);
        (2.0 * d * d - 1.0).clamp(-1.0, 1.0).acos()
    }

    /// The vector `v` rotated by this unit quaternion (`q·v·q⁻¹`, the same as
    /// `to_mat3()·v`).
    pub fn rotate(self, v: Vec3) -> Vec3 {
        // v + 2w(u × v) + 2u × (u × v), u the vector part.
        let u = [self.x, self.y, self.z];
        let c = cross(u, v);
        let cc = cross(u, c);
        [
            v[0] + 2.0 * (self.w * c[0] + cc[0]),
            v[1] + 2.0 * (self.w * c[1] + cc[1]),
            v[2] + 2.0 * (self.w * c[2] + cc[2]),
        ]
    }

    /// The angle in radians, in `(−π, π]`, of this rotation's twist about a coordinate axis
    /// (swing-twist decomposition `q = swing·twist` with the twist about `axis`): for the
    /// vertical axis, the heading of a body whose root has this world rotation. 0 where the
    /// twist is undefined (a half turn about an axis perpendicular to `axis`).
    pub fn twist_rad(self, axis: Axis) -> f64 {
        let a = match axis {
            Axis::X => self.x,
            Axis::Y => self.y,
            Axis::Z => self.z,
        };
        // q and −q are the same rotation: take the twist of the one with w ≥ 0 so that the
        // angle lands in (−π, π].
        let (w, a) = if self.w < 0.0 {
            (-self.w, -a)
        } else {
            (self.w, a)
        };
        if w == 0.0 && a == 0.0 {
            return 0.0;
        }
        2.0 * a.atan2(w)
    }
}

fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Hamilton product `a · b` (apply `b` first).
impl std::ops::Mul for Quat {
    type Output = Quat;

    fn mul(self, o: Quat) -> Quat {
        Quat {
            w: self.w * o.w - self.x * o.x - self.y * o.y - self.z * o.z,
            x: self.w * o.x + self.x * o.w + self.y * o.z - self.z * o.y,
            y: self.w * o.y - self.x * o.z + self.y * o.w + self.z * o.x,
            z: self.w * o.z + self.x * o.y - self.y * o.x + self.z * o.w,
        }
    }
}

/// Negation: the same rotation on the other hemisphere.
impl std::ops::Neg for Quat {
    type Output = Quat;

    fn neg(self) -> Quat {
        Quat {
            w: -self.w,
            x: -self.x,
            y: -self.y,
            z: -self.z,
        }
    }
}

/// Decomposes a rotation into angles (degrees) about `axes`, composed in listed order:
/// `R = R(a1)·R(a2)·R(a3)`. For a rotation that such channels made, this recovers it exactly
/// (up to Euler equivalence; with three axes the middle angle is in [−90°, 90°], see
/// [`decompose_listed_near`] for the other solution).
pub fn decompose_listed(r: &Mat3, axes: &[Axis]) -> Vec<f64> {
    let mut out = vec![0.0; axes.len()];
    decompose_into(r, axes, &mut out);
    out
}

/// [`decompose_listed`] into `out` (one angle per axis), without allocating.
fn decompose_into(r: &Mat3, axes: &[Axis], out: &mut [f64]) {
    match (axes, &mut *out) {
        ([], _) => {}
        ([a], [o]) => {
            let (j, k) = cyclic_after(*a);
            *o = r[k][j].atan2(r[j][j]).to_degrees();
        }
        ([a, b], [o1, o2]) if a != b => {
            // R = Ra(α)·Rb(β): column b of R is Ra(α)·e_b, row a is e_aᵀ·Rb(β).
            let (i, j) = (a.index(), b.index());
            let k = 3 - i - j;
            let s = if (j + 3 - i) % 3 == 1 { 1.0 } else { -1.0 };
            *o1 = (s * r[k][j]).atan2(r[j][j]).to_degrees();
            *o2 = (s * r[i][k]).atan2(r[i][i]).to_degrees();
        }
        ([a, b, c], [o1, o2, o3]) if a != b && b != c && a != c => {
            let (i, j, k) = (a.index(), b.index(), c.index());
            let s = if (j + 3 - i) % 3 == 1 { 1.0 } else { -1.0 };
            let beta = (s * r[i][k]).clamp(-1.0, 1.0).asin();
            let (alpha, gamma) = if (s * r[i][k]).abs() > 1.0 - 1e-12 {
                // Gimbal lock: only alpha ± gamma is defined; put it all in alpha.
                ((s * r[k][j]).atan2(r[j][j]), 0.0)
            } else {
                ((-s * r[j][k]).atan2(r[k][k]), (-s * r[i][j]).atan2(r[i][i]))
            };
            (*o1, *o2, *o3) = (alpha.to_degrees(), beta.to_degrees(), gamma.to_degrees());
        }
        // Repeated axes (proper Euler, e.g. ZXZ) or more than three do not occur in mocap
        // files; fit each axis alone, which is exact when only one angle is non-zero.
        _ => {
            for (&a, o) in axes.iter().zip(out.iter_mut()) {
                decompose_into(r, &[a], std::slice::from_mut(o));
            }
        }
    }
}

/// Like [`decompose_listed`], but of the equivalent angle sets (for three distinct axes both
/// Tait–Bryan solutions `(α, β, γ)` and `(α+180°, 180°−β, γ+180°)`, each angle shifted by whole
/// turns) returns the one nearest `reference`, so that decoded channels stay continuous.
pub fn decompose_listed_near(r: &Mat3, axes: &[Axis], reference: &[f64]) -> Vec<f64> {
    let first = decompose_listed(r, axes);
    let near = |v: &[f64]| -> Vec<f64> {
        v.iter()
            .zip(reference)
            .map(|(&a, &re)| unwrap_near(a, re))
            .collect()
    };
    let cost = |v: &[f64]| -> f64 { v.iter().zip(reference).map(|(a, b)| (a - b).abs()).sum() };
    let a = near(&first);
    let distinct3 = matches!(axes, [x, y, z] if x != y && y != z && x != z);
    if !distinct3 || reference.len() < 3 {
        return a;
    }
    let b = near(&[first[0] + 180.0, 180.0 - first[1], first[2] + 180.0]);
    if cost(&b) < cost(&a) { b } else { a }
}

fn cyclic_after(a: Axis) -> (usize, usize) {
    match a {
        Axis::X => (1, 2),
        Axis::Y => (2, 0),
        Axis::Z => (0, 1),
    }
}

/// The angle `a + 360°·k` nearest to `reference`.
pub fn unwrap_near(a: f64, reference: f64) -> f64 {
    a + 360.0 * ((reference - a) / 360.0).round()
}

/// The axes of a joint's rotation channels, in listed (channel) order.
pub fn rotation_axes(skeleton: &Skeleton, joint: usize) -> Vec<Axis> {
    skeleton.joints[joint]
        .dofs
        .iter()
        .filter_map(|d| match d {
            ChannelKind::Rotation(a) => Some(*a),
            ChannelKind::Translation(_) => None,
        })
        .collect()
}

/// The joints of a skeleton that have rotation channels, in skeleton order (the joints of a
/// [`QuatClip`]).
pub fn rotation_joints(skeleton: &Skeleton) -> Vec<usize> {
    (0..skeleton.joints.len())
        .filter(|&j| skeleton.joints[j].dofs.iter().any(|d| d.is_rotation()))
        .collect()
}

/// The rotation that [`from_quaternions`] writes for `q` on a joint whose rotation channels
/// are `axes`: `q` itself for three distinct axes, otherwise the rotation the joint's fewer
/// channels make from the decomposed angles (a 1- or 2-dof joint cannot hold an arbitrary
/// rotation, so a decoded quaternion off that manifold is projected onto it). A codec that
/// bounds the error of its output checks this projection, not `q`.
pub fn project_to_channels(format: SkeletonFormat, axes: &[Axis], q: Quat) -> Quat {
    if matches!(axes, [x, y, z] if x != y && y != z && x != z) {
        return q;
    }
    let m = q.to_mat3();
    // Encoders check this for every frame of every try (the primitive codec's bound): the
    // usual one or two axes are decomposed on the stack.
    let n = axes.len();
    if n <= 3 {
        let mut angles = [0.0; 3];
        match format {
            SkeletonFormat::Asf => {
                let mut order = [Axis::X; 3];
                for (o, a) in order.iter_mut().zip(axes.iter().rev()) {
                    *o = *a;
                }
                decompose_into(&m, &order[..n], &mut angles[..n]);
                angles[..n].reverse();
            }
            SkeletonFormat::Bvh => decompose_into(&m, axes, &mut angles[..n]),
        }
        return channel_rotation(format, axes, &angles[..n]);
    }
    let angles = match format {
        SkeletonFormat::Asf => {
            let order: Vec<Axis> = axes.iter().rev().copied().collect();
            let mut a = decompose_listed(&m, &order);
            a.reverse();
            a
        }
        SkeletonFormat::Bvh => decompose_listed(&m, axes),
    };
    channel_rotation(format, axes, &angles)
}

/// A clip with every joint's rotation channels replaced by one unit quaternion per frame.
#[derive(Debug, Clone, PartialEq)]
pub struct QuatClip {
    /// The source clip's skeleton, rate and translation channels; its rotation values are the
    /// ones the quaternions were made from.
    pub source: Clip,
    /// Joints that have rotation channels, in skeleton order.
    pub joints: Vec<usize>,
    /// `rotations[k][f]`: rotation of `joints[k]` at frame `f`.
    pub rotations: Vec<Vec<Quat>>,
}

/// The rotation channels of a joint (axes in listed order) and their channel rows.
fn rotation_channels(clip: &Clip, joint: usize) -> (Vec<Axis>, Vec<usize>) {
    let mut axes = Vec::new();
    let mut rows = Vec::new();
    for (c, ch) in clip.channels().iter().enumerate() {
        if let (true, ChannelKind::Rotation(a)) = (ch.joint == joint, ch.kind) {
            axes.push(a);
            rows.push(c);
        }
    }
    (axes, rows)
}

/// Rotation made by channel values `angles` about `axes` under the skeleton's convention.
fn channel_rotation(format: SkeletonFormat, axes: &[Axis], angles: &[f64]) -> Quat {
    let mut q = Quat::IDENTITY;
    for (&a, &v) in axes.iter().zip(angles) {
        let r = Quat::from_axis(a, v);
        q = match format {
            // ASF: fixed axes in listed order, each new rotation applied on the left.
            SkeletonFormat::Asf => r * q,
            // BVH: product in listed order.
            SkeletonFormat::Bvh => q * r,
        };
    }
    q
}

/// Converts a clip's rotation channels to hemisphere-consistent unit quaternions.
pub fn to_quaternions(clip: &Clip) -> QuatClip {
    let mut joints = Vec::new();
    let mut rotations = Vec::new();
    let mut angles = Vec::with_capacity(3);
    for j in 0..clip.skeleton.joints.len() {
        let (axes, rows) = rotation_channels(clip, j);
        if axes.is_empty() {
            continue;
        }
        let mut track = Vec::with_capacity(clip.frames());
        let mut prev = Quat::IDENTITY;
        for f in 0..clip.frames() {
            angles.clear();
            angles.extend(rows.iter().map(|&c| clip.value(c, f)));
            let mut q = channel_rotation(clip.skeleton.format, &axes, &angles);
            if f > 0 && q.dot(prev) < 0.0 {
                q = -q;
            }
            prev = q;
            track.push(q);
        }
        joints.push(j);
        rotations.push(track);
    }
    QuatClip {
        source: clip.clone(),
        joints,
        rotations,
    }
}

/// Converts back to Euler channels in each joint's own order, unwrapping every angle to the
/// value nearest the previous frame (the first frame: nearest the source's first value).
pub fn from_quaternions(qc: &QuatClip) -> Clip {
    let clip = &qc.source;
    let frames = clip.frames();
    let mut data = clip.data().to_vec();
    for (k, &j) in qc.joints.iter().enumerate() {
        let (axes, rows) = rotation_channels(clip, j);
        // ASF composes fixed axes in listed order = listed-order product of the reversed list.
        let (order, rev): (Vec<Axis>, bool) = match clip.skeleton.format {
            SkeletonFormat::Asf => (axes.iter().rev().copied().collect(), true),
            SkeletonFormat::Bvh => (axes.clone(), false),
        };
        let mut reference = vec![0.0; rows.len()];
        for f in 0..frames {
            for (n, &c) in rows.iter().enumerate() {
                reference[n] = if f == 0 {
                    clip.value(c, 0)
                } else {
                    data[c * frames + f - 1]
                };
            }
            if rev {
                reference.reverse();
            }
            let m = qc.rotations[k][f].to_mat3();
            let mut a = decompose_listed_near(&m, &order, &reference);
            if rev {
                a.reverse();
            }
            for (n, &c) in rows.iter().enumerate() {
                data[c * frames + f] = a[n];
            }
        }
    }
    Clip::from_valid_parts(clip.skeleton.clone(), clip.frame_rate_hz, frames, data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{euler_listed, rot_axis};

    fn close(a: &Mat3, b: &Mat3, tol: f64) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() < tol))
    }

    #[test]
    fn matrix_round_trip_and_axis_rotations_agree() {
        for &(a, v) in &[
            (Axis::X, 30.0),
            (Axis::Y, -170.0),
            (Axis::Z, 179.9),
            (Axis::X, 0.0),
        ] {
            let q = Quat::from_axis(a, v);
            assert!(close(&q.to_mat3(), &rot_axis(a, v), 1e-12));
            let back = Quat::from_mat3(&q.to_mat3());
            assert!(back.distance(q) < 1e-7, "{a:?} {v}");
        }
    }

    #[test]
    fn rotate_is_the_matrix_product_and_twist_recovers_a_heading() {
        use crate::math::mul_vec;
        let q = Quat::from_mat3(&euler_listed(
            &[Axis::Y, Axis::X, Axis::Z],
            &[70.0, 25.0, -40.0],
        ));
        let v = [0.3, -1.2, 2.5];
        let (a, b) = (q.rotate(v), mul_vec(&q.to_mat3(), &v));
        assert!((0..3).all(|i| (a[i] - b[i]).abs() < 1e-12), "{a:?} {b:?}");
        // A heading of h about Y applied after a tilt about any horizontal axis: the twist
        // about Y is h (for q and −q alike).
        for h in [-179.0, -90.0, -10.0, 0.0, 45.0, 135.0, 179.5] {
            for (tilt, dir) in [(0.0, 0.0), (20.0, 0.3), (-35.0, 2.0), (80.0, -1.0)] {
                let (s, c) = (0.5 * f64::to_radians(tilt)).sin_cos();
                let swing = Quat {
                    w: c,
                    x: s * f64::cos(dir),
                    y: 0.0,
                    z: s * f64::sin(dir),
                };
                let r = Quat::from_axis(Axis::Y, h) * swing;
                for r in [r, -r] {
                    let t = r.twist_rad(Axis::Y).to_degrees();
                    assert!((t - h).abs() < 1e-9, "{h} {tilt}: {t}");
                }
            }
        }
        assert!(Quat::from_axis(Axis::X, 180.0).twist_rad(Axis::Y).abs() < 1e-12);
    }

    #[test]
    fn every_tait_bryan_order_decomposes_exactly() {
        use Axis::{X, Y, Z};
        let orders = [
            [X, Y, Z],
            [X, Z, Y],
            [Y, X, Z],
            [Y, Z, X],
            [Z, X, Y],
            [Z, Y, X],
        ];
        for order in orders {
            for angles in [
                [10.0, 20.0, 30.0],
                [-150.0, 60.0, 100.0],
                [5.0, -85.0, -170.0],
            ] {
                let r = euler_listed(&order, &angles);
                let got = decompose_listed(&r, &order);
                assert!(
                    close(&euler_listed(&order, &got), &r, 1e-12),
                    "{order:?} {angles:?}"
                );
            }
            let r = euler_listed(&order[..2], &[33.0, -144.0]);
            let got = decompose_listed(&r, &order[..2]);
            assert!(
                close(&euler_listed(&order[..2], &got), &r, 1e-12),
                "{order:?} two axes"
            );
        }
        let r = rot_axis(Y, -123.0);
        assert!((decompose_listed(&r, &[Y])[0] + 123.0).abs() < 1e-12);
    }

    #[test]
    fn slerp_moves_at_constant_angular_speed() {
        let a = Quat::from_axis(Axis::Z, 10.0);
        let b = Quat::from_axis(Axis::Z, 110.0);
        let m = a.slerp(b, 0.25);
        assert!(m.distance(Quat::from_axis(Axis::Z, 35.0)) < 1e-9);
        // Takes the short way round even when b is given on the other hemisphere.
        assert!(a.slerp(-b, 0.5).distance(Quat::from_axis(Axis::Z, 60.0)) < 1e-9);
    }

    #[test]
    fn projection_matches_what_euler_channels_hold() {
        use crate::clip::SkeletonFormat::{Asf, Bvh};
        let q = Quat::from_axis(Axis::X, 20.0) * Quat::from_axis(Axis::Z, -35.0);
        let off = q * Quat::from_axis(Axis::Y, 3.0);
        for format in [Asf, Bvh] {
            // Three distinct axes hold any rotation.
            assert_eq!(
                project_to_channels(format, &[Axis::Z, Axis::X, Axis::Y], off),
                off
            );
            // One axis: the projection stays on that axis.
            let p = project_to_channels(format, &[Axis::X], off);
            assert!(p.y.abs() < 1e-12 && p.z.abs() < 1e-12, "{p:?}");
        }
        // A rotation the channels can make comes back unchanged; one off the manifold moves.
        let rx_rz = [Axis::X, Axis::Z];
        let on = channel_rotation(Bvh, &rx_rz, &[20.0, -35.0]);
        assert!(project_to_channels(Bvh, &rx_rz, on).distance(on) < 1e-7);
        let on = channel_rotation(Asf, &rx_rz, &[20.0, -35.0]);
        assert!(project_to_channels(Asf, &rx_rz, on).distance(on) < 1e-7);
        assert!(
            project_to_channels(Asf, &rx_rz, on * Quat::from_axis(Axis::Y, 5.0)).distance(on)
                > 1e-3
        );
    }

    #[test]
    fn log_exp_and_distance_are_consistent() {
        let q = Quat::from_axis(Axis::Y, 50.0);
        let v = q.log();
        assert!((v[1] - 25f64.to_radians()).abs() < 1e-12);
        assert!(Quat::exp(v).distance(q) < 1e-9);
        assert!((Quat::IDENTITY.distance(q) - 50f64.to_radians()).abs() < 1e-9);
        assert!((q.distance(-q)).abs() < 1e-7);
        assert!((unwrap_near(-179.0, 179.0) - 181.0).abs() < 1e-12);
    }
}
