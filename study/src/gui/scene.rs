//! What the renderer draws, computed without a GPU: per-instance bone and joint shapes of a
//! posed skeleton, the camera that frames a clip, and the ground plane.
//!
//! A [`Figure`] turns a clip and a presentation time into instances (a unit cylinder per bone,
//! a unit sphere per joint, each with a position, rotation and scale). A [`View`] is the fixed
//! camera of one clip: it frames the bounding box of every pose of the clip, so the reference
//! and the test stimulus of a trial, drawn with the reference's view, appear at the same size
//! and place. The renderer knows nothing of trials; this module knows nothing of wgpu.

use motion::clip::Clip;
use motion::math::Vec3;
use motion::playback::{EndMode, Sampler};

/// A column-major 4×4 matrix (`m[column][row]`), as WGSL reads it.
pub type Mat4 = [[f32; 4]; 4];

/// One drawn shape: a unit mesh placed by position, rotation (unit quaternion x, y, z, w) and
/// per-axis scale, with a colour (linear 0-1 RGBA as written to the target).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Instance {
    /// World position of the mesh origin.
    pub position: [f32; 3],
    /// Rotation as a unit quaternion (x, y, z, w).
    pub rotation: [f32; 4],
    /// Scale along the mesh's own axes.
    pub scale: [f32; 3],
    /// Colour.
    pub color: [f32; 4],
}

impl Instance {
    /// Bytes per instance in the vertex buffer (14 floats).
    pub const BYTES: usize = 14 * 4;

    /// Appends the instance as little-endian floats in shader order.
    pub fn write(&self, out: &mut Vec<u8>) {
        for v in self
            .position
            .iter()
            .chain(&self.rotation)
            .chain(&self.scale)
            .chain(&self.color)
        {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// Bone colour (the same in both viewports: nothing tells the reference from the test).
pub const BONE_COLOR: [f32; 4] = [0.78, 0.80, 0.86, 1.0];
/// Joint colour.
pub const JOINT_COLOR: [f32; 4] = [0.93, 0.55, 0.22, 1.0];

/// Instances of one posed skeleton: bones first, then joints.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameShapes {
    /// Cylinders, one per bone of non-zero length.
    pub bones: Vec<Instance>,
    /// Spheres, one per joint.
    pub joints: Vec<Instance>,
}

/// A clip ready to be posed at any presentation time.
#[derive(Debug, Clone)]
pub struct Figure {
    sampler: Sampler,
    parents: Vec<Option<usize>>,
    bone_radius: f32,
    points: Vec<Vec3>,
}

impl Figure {
    /// Prepares `clip`; shapes are sized from `view`'s figure height so that the reference
    /// and the test stimulus are drawn alike.
    pub fn new(clip: &Clip, view: &View) -> Figure {
        Figure {
            sampler: Sampler::new(clip),
            parents: clip.skeleton.joints.iter().map(|j| j.parent).collect(),
            bone_radius: view.bone_radius,
            points: Vec::new(),
        }
    }

    /// Seconds from the first frame to one frame past the last.
    pub fn duration_s(&self) -> f64 {
        self.sampler.duration_s()
    }

    /// The shapes at presentation time `t_s` (held at the last frame past the end).
    pub fn shapes_at(&mut self, t_s: f64, out: &mut FrameShapes) {
        self.sampler.pose_at(t_s, EndMode::Hold, &mut self.points);
        out.bones.clear();
        out.joints.clear();
        let r = self.bone_radius;
        for (j, p) in self.points.iter().enumerate() {
            let pj = to_f32(*p);
            out.joints.push(Instance {
                position: pj,
                rotation: [0.0, 0.0, 0.0, 1.0],
                scale: [r * 1.45; 3],
                color: JOINT_COLOR,
            });
            let Some(parent) = self.parents.get(j).copied().flatten() else {
                continue;
            };
            let Some(pp) = self.points.get(parent).map(|p| to_f32(*p)) else {
                continue;
            };
            let d = sub(pj, pp);
            let len = norm(d);
            if len <= r * 0.05 {
                continue;
            }
            out.bones.push(Instance {
                position: pp,
                rotation: rotation_from_y(scale3(d, 1.0 / len)),
                scale: [r, len, r],
                color: BONE_COLOR,
            });
        }
    }
}

/// The fixed camera and ground of one clip.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Point looked at (centre of the clip's bounding box).
    pub target: [f32; 3],
    /// Camera position.
    pub eye: [f32; 3],
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Near and far planes.
    pub near: f32,
    /// Far plane.
    pub far: f32,
    /// Height of the ground plane (lowest point of the clip).
    pub ground_y: f32,
    /// Half the side of the drawn ground square.
    pub ground_half: f32,
    /// Grid spacing in clip units (one metre).
    pub grid: f32,
    /// Bone radius in clip units.
    pub bone_radius: f32,
}

impl View {
    /// Frames every pose of `clip` (y up), seen from the front-right and a little above.
    pub fn framing(clip: &Clip) -> View {
        let positions = motion::fk::positions(clip);
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        let mut tallest = 0.0f32;
        for f in 0..positions.frames() {
            let (mut flo, mut fhi) = (f32::INFINITY, f32::NEG_INFINITY);
            for p in positions.frame(f) {
                let p = to_f32(*p);
                if !p.iter().all(|v| v.is_finite()) {
                    continue;
                }
                for k in 0..3 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
                flo = flo.min(p[1]);
                fhi = fhi.max(p[1]);
            }
            if fhi > flo {
                tallest = tallest.max(fhi - flo);
            }
        }
        if !lo.iter().chain(&hi).all(|v| v.is_finite()) {
            lo = [-1.0; 3];
            hi = [1.0; 3];
        }
        let cm = clip.skeleton.units.cm_per_unit as f32;
        let metre = if cm.is_finite() && cm > 0.0 {
            100.0 / cm
        } else {
            1.0
        };
        let height = if tallest > 0.0 { tallest } else { metre * 1.7 };
        let target = [
            0.5 * (lo[0] + hi[0]),
            0.5 * (lo[1] + hi[1]),
            0.5 * (lo[2] + hi[2]),
        ];
        let half = scale3(sub(hi, lo), 0.5);
        let radius = norm(half).max(height * 0.5) * 1.08;
        let fov_y = 40f32.to_radians();
        let distance = radius / (0.5 * fov_y).sin();
        // Azimuth 30 degrees from +z towards +x, elevation 12 degrees.
        let (az, el) = (30f32.to_radians(), 12f32.to_radians());
        let dir = [az.sin() * el.cos(), el.sin(), az.cos() * el.cos()];
        let eye = add(target, scale3(dir, distance));
        View {
            target,
            eye,
            fov_y,
            near: (distance - 2.5 * radius).max(distance * 0.02),
            far: distance + 4.0 * radius,
            ground_y: lo[1],
            ground_half: radius * 2.5,
            grid: metre,
            bone_radius: height * 0.022,
        }
    }

    /// Projection × view for a viewport of aspect `width / height` (wgpu depth 0..1).
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        let aspect = if aspect.is_finite() && aspect > 0.0 {
            aspect
        } else {
            1.0
        };
        mul(
            &perspective(self.fov_y, aspect, self.near, self.far),
            &look_at(self.eye, self.target, [0.0, 1.0, 0.0]),
        )
    }
}

fn to_f32(p: Vec3) -> [f32; 3] {
    [p[0] as f32, p[1] as f32, p[2] as f32]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

fn scale3(a: [f32; 3], s: f32) -> [f32; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn norm(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

fn normalize(a: [f32; 3]) -> [f32; 3] {
    let n = norm(a);
    if n > 0.0 { scale3(a, 1.0 / n) } else { a }
}

/// The unit quaternion turning +y onto the unit vector `d`.
fn rotation_from_y(d: [f32; 3]) -> [f32; 4] {
    let c = d[1];
    if c < -0.999_999 {
        // Opposite: half a turn about x.
        return [1.0, 0.0, 0.0, 0.0];
    }
    // q = (y × d, 1 + y·d), normalised.
    let axis = [d[2], 0.0, -d[0]];
    let w = 1.0 + c;
    let n = (axis[0] * axis[0] + axis[2] * axis[2] + w * w).sqrt();
    [axis[0] / n, 0.0, axis[2] / n, w / n]
}

/// Column-major product `a × b`.
pub fn mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for (c, col) in m.iter_mut().enumerate() {
        for (r, v) in col.iter_mut().enumerate() {
            *v = (0..4).map(|k| a[k][r] * b[c][k]).sum();
        }
    }
    m
}

/// Right-handed perspective projection with depth mapped to 0..1.
pub fn perspective(fov_y: f32, aspect: f32, near: f32, far: f32) -> Mat4 {
    let f = 1.0 / (0.5 * fov_y).tan();
    let range = far / (near - far);
    [
        [f / aspect, 0.0, 0.0, 0.0],
        [0.0, f, 0.0, 0.0],
        [0.0, 0.0, range, -1.0],
        [0.0, 0.0, range * near, 0.0],
    ]
}

/// Right-handed view matrix looking from `eye` at `target`.
pub fn look_at(eye: [f32; 3], target: [f32; 3], up: [f32; 3]) -> Mat4 {
    let f = normalize(sub(target, eye));
    let s = normalize(cross(f, up));
    let u = cross(s, f);
    [
        [s[0], u[0], -f[0], 0.0],
        [s[1], u[1], -f[1], 0.0],
        [s[2], u[2], -f[2], 0.0],
        [-dot(s, eye), -dot(u, eye), dot(f, eye), 1.0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn transform(m: &Mat4, p: [f32; 3]) -> [f32; 3] {
        let v = [p[0], p[1], p[2], 1.0];
        let mut o = [0.0f32; 4];
        for (r, out) in o.iter_mut().enumerate() {
            *out = (0..4).map(|c| m[c][r] * v[c]).sum();
        }
        [o[0] / o[3], o[1] / o[3], o[2] / o[3]]
    }

    fn rotate(q: [f32; 4], v: [f32; 3]) -> [f32; 3] {
        let u = [q[0], q[1], q[2]];
        let t = scale3(cross(u, v), 2.0);
        add(add(v, scale3(t, q[3])), cross(u, t))
    }

    #[test]
    fn rotation_from_y_maps_y_onto_the_direction() {
        for d in [
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.3, -0.5, 0.81],
            [-0.6, 0.7, -0.2],
        ] {
            let d = normalize(d);
            let r = rotate(rotation_from_y(d), [0.0, 1.0, 0.0]);
            for k in 0..3 {
                assert!((r[k] - d[k]).abs() < 1e-5, "{d:?} -> {r:?}");
            }
        }
    }

    #[test]
    fn every_pose_of_the_walk_projects_inside_the_view() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let view = View::framing(&clip);
        let vp = view.view_proj(16.0 / 9.0);
        let positions = motion::fk::positions(&clip);
        for f in (0..positions.frames()).step_by(7) {
            for p in positions.frame(f) {
                let ndc = transform(&vp, to_f32(*p));
                assert!(ndc[0].abs() < 1.0 && ndc[1].abs() < 1.0, "{ndc:?}");
                assert!((0.0..1.0).contains(&ndc[2]), "depth {ndc:?}");
            }
        }
    }

    #[test]
    fn bones_join_parent_and_child_joints() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams::default());
        let view = View::framing(&clip);
        let mut fig = Figure::new(&clip, &view);
        let mut shapes = FrameShapes::default();
        fig.shapes_at(0.37, &mut shapes);
        assert_eq!(shapes.joints.len(), clip.skeleton.joints.len());
        assert!(shapes.bones.len() >= clip.skeleton.joints.len() / 2);
        for b in &shapes.bones {
            // The cylinder's far end is a joint.
            let end = add(b.position, rotate(b.rotation, [0.0, b.scale[1], 0.0]));
            let hit = shapes
                .joints
                .iter()
                .any(|j| norm(sub(j.position, end)) < 1e-3 * b.scale[1].max(1.0));
            assert!(hit, "bone ending at {end:?} meets no joint");
        }
        let mut bytes = Vec::new();
        shapes.bones[0].write(&mut bytes);
        assert_eq!(bytes.len(), Instance::BYTES);
    }
}
