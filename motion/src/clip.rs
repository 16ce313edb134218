//! The clip model shared by every reader, writer, codec and the renderer.
//!
//! A [`Clip`] is a [`Skeleton`] plus a channels × frames matrix of values in the file's units
//! (lengths in file units, angles in degrees) and a frame rate. The skeleton keeps enough of the
//! source format (ASF bone directions and axes, BVH offsets and channel orders) that a writer can
//! emit a file whose values read back identical.
//!
//! Values are stored as `f64`: the readers keep exactly the number the file printed (a CMU AMC
//! value has up to 7 significant digits, more than `f32` holds), and forward kinematics runs in
//! `f64`. Compression ratios are still counted against 4 bytes per value, as the seeds define them.

use std::fmt;

/// A coordinate axis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Axis {
    /// The x axis.
    X,
    /// The y axis (up in CMU and most BVH files).
    Y,
    /// The z axis.
    Z,
}

impl Axis {
    /// Index of the axis in an `[x, y, z]` array.
    pub fn index(self) -> usize {
        match self {
            Axis::X => 0,
            Axis::Y => 1,
            Axis::Z => 2,
        }
    }

    /// The axis letter in upper case.
    pub fn letter(self) -> char {
        match self {
            Axis::X => 'X',
            Axis::Y => 'Y',
            Axis::Z => 'Z',
        }
    }

    /// Parses `x`, `y` or `z` in either case.
    pub fn from_letter(c: char) -> Option<Axis> {
        match c.to_ascii_lowercase() {
            'x' => Some(Axis::X),
            'y' => Some(Axis::Y),
            'z' => Some(Axis::Z),
            _ => None,
        }
    }
}

/// What one channel of a joint moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ChannelKind {
    /// Translation along an axis, in the file's length units.
    Translation(Axis),
    /// Rotation about an axis, in degrees.
    Rotation(Axis),
}

impl ChannelKind {
    /// True for a rotation channel (angles in degrees, subject to Euler wraps).
    pub fn is_rotation(self) -> bool {
        matches!(self, ChannelKind::Rotation(_))
    }

    /// The ASF/AMC spelling: `tx`, `ry`, ...
    pub fn asf_name(self) -> String {
        match self {
            ChannelKind::Translation(a) => format!("t{}", a.letter().to_ascii_lowercase()),
            ChannelKind::Rotation(a) => format!("r{}", a.letter().to_ascii_lowercase()),
        }
    }

    /// The BVH spelling: `Xposition`, `Zrotation`, ...
    pub fn bvh_name(self) -> String {
        match self {
            ChannelKind::Translation(a) => format!("{}position", a.letter()),
            ChannelKind::Rotation(a) => format!("{}rotation", a.letter()),
        }
    }
}

/// The six kinematic chains of thesis ch. 6 (body-part score, eq. 6.2 depth).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BodyPart {
    /// Root, pelvis and spine up to the chest.
    Torso,
    /// Neck and head.
    Head,
    /// Left clavicle to fingers.
    LeftArm,
    /// Right clavicle to fingers.
    RightArm,
    /// Left hip to toes.
    LeftLeg,
    /// Right hip to toes.
    RightLeg,
}

impl BodyPart {
    /// All parts, in a fixed order.
    pub const ALL: [BodyPart; 6] = [
        BodyPart::Torso,
        BodyPart::Head,
        BodyPart::LeftArm,
        BodyPart::RightArm,
        BodyPart::LeftLeg,
        BodyPart::RightLeg,
    ];

    /// True for the two leg chains (the lower body of thesis ch. 5).
    pub fn is_leg(self) -> bool {
        matches!(self, BodyPart::LeftLeg | BodyPart::RightLeg)
    }

    /// A short lower-case name: `torso`, `left_arm`, ...
    pub fn name(self) -> &'static str {
        match self {
            BodyPart::Torso => "torso",
            BodyPart::Head => "head",
            BodyPart::LeftArm => "left_arm",
            BodyPart::RightArm => "right_arm",
            BodyPart::LeftLeg => "left_leg",
            BodyPart::RightLeg => "right_leg",
        }
    }
}

impl fmt::Display for BodyPart {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Which file format a skeleton came from; it decides the forward-kinematics convention.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SkeletonFormat {
    /// Acclaim ASF (with AMC motion): a joint is a bone, its point is the bone's end.
    Asf,
    /// BVH: a joint's point is its origin, an end site is a joint without channels.
    Bvh,
}

/// The rest geometry of a joint.
#[derive(Debug, Clone, PartialEq)]
pub enum Rest {
    /// ASF bone: unit direction in the world rest frame and length in file units.
    Bone {
        /// Direction of the bone from its start to its end, world rest frame.
        direction: [f64; 3],
        /// Length of the bone in file units.
        length: f64,
    },
    /// ASF root `position` or BVH `OFFSET`: vector from the parent's point, in file units.
    Offset([f64; 3]),
}

impl Rest {
    /// The rest vector in file units (`direction × length` or the offset).
    pub fn vector(&self) -> [f64; 3] {
        match self {
            Rest::Bone { direction, length } => [
                direction[0] * length,
                direction[1] * length,
                direction[2] * length,
            ],
            Rest::Offset(v) => *v,
        }
    }

    /// The length of the rest vector in file units.
    pub fn length(&self) -> f64 {
        match self {
            Rest::Bone { length, .. } => *length,
            Rest::Offset(v) => (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt(),
        }
    }
}

/// One joint (ASF bone, BVH joint or BVH end site) of a skeleton.
#[derive(Debug, Clone, PartialEq)]
pub struct Joint {
    /// Name as written in the file.
    pub name: String,
    /// Index of the parent joint, `None` for the root.
    pub parent: Option<usize>,
    /// Rest geometry (see [`Rest`]).
    pub rest: Rest,
    /// The joint's channels in file order (ASF `dof`/`order`, BVH `CHANNELS`).
    pub dofs: Vec<ChannelKind>,
    /// ASF `axis` (or root `orientation`) angles in degrees, in `axis_order`; zero for BVH.
    pub axis_deg: [f64; 3],
    /// Order of the `axis` angles, e.g. `[X, Y, Z]` for `XYZ`.
    pub axis_order: [Axis; 3],
    /// ASF `limits` per dof, in dof order (empty when the file gives none).
    pub limits: Vec<(f64, f64)>,
    /// ASF bone `id`, kept for the writer.
    pub id: Option<u32>,
    /// True for a BVH `End Site`.
    pub end_site: bool,
    /// Which kinematic chain the joint belongs to.
    pub body_part: BodyPart,
    /// Depth within its chain: each chain starts at 0 (thesis eq. 6.2).
    pub chain_depth: usize,
}

impl Joint {
    /// A joint with no ASF axis, limits or id, not an end site, in the torso chain at depth 0
    /// (readers then set what their format gives and [`crate::bodymap::assign`] the chain).
    pub fn new(name: String, parent: Option<usize>, rest: Rest, dofs: Vec<ChannelKind>) -> Joint {
        Joint {
            name,
            parent,
            rest,
            dofs,
            axis_deg: [0.0; 3],
            axis_order: [Axis::X, Axis::Y, Axis::Z],
            limits: Vec::new(),
            id: None,
            end_site: false,
            body_part: BodyPart::Torso,
            chain_depth: 0,
        }
    }
}

/// Length and angle units of a skeleton.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Units {
    /// Centimetres per file length unit (CMU ASF `length 0.45`: 2.54 / 0.45 = 5.644 cm).
    pub cm_per_unit: f64,
    /// The ASF `length` value as written (1.0 when the file gives none).
    pub asf_length: f64,
    /// The ASF `mass` value as written (1.0 when the file gives none).
    pub asf_mass: f64,
    /// True when the length unit was declared by the file; false when it was inferred.
    pub declared: bool,
}

impl Default for Units {
    fn default() -> Self {
        Units {
            cm_per_unit: 1.0,
            asf_length: 1.0,
            asf_mass: 1.0,
            declared: false,
        }
    }
}

/// A kinematic skeleton: joints in file order, parents before children.
#[derive(Debug, Clone, PartialEq)]
pub struct Skeleton {
    /// Name from the file (ASF `:name`, BVH root name).
    pub name: String,
    /// Source format; decides the FK convention.
    pub format: SkeletonFormat,
    /// Units of lengths; angles are always degrees.
    pub units: Units,
    /// Joints; index 0 is the root and every parent index is smaller than its child's.
    pub joints: Vec<Joint>,
    /// ASF `:documentation` lines and other header text kept for the writer.
    pub documentation: Vec<String>,
}

impl Skeleton {
    /// Index of the joint called `name`.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Total number of channels over all joints.
    pub fn channel_count(&self) -> usize {
        self.joints.iter().map(|j| j.dofs.len()).sum()
    }

    /// The channels of every joint in joint order, as the rows of a [`Clip`].
    pub fn channel_layout(&self) -> Vec<Channel> {
        let mut out = Vec::with_capacity(self.channel_count());
        for (joint, j) in self.joints.iter().enumerate() {
            for &kind in &j.dofs {
                out.push(Channel { joint, kind });
            }
        }
        out
    }

    /// Children of joint `i`, in file order.
    pub fn children(&self, i: usize) -> impl Iterator<Item = usize> + '_ {
        self.joints
            .iter()
            .enumerate()
            .filter(move |(_, j)| j.parent == Some(i))
            .map(|(k, _)| k)
    }

    /// Maximum chain depth `h` of a body part (thesis eq. 6.2), or `None` if no joint has it.
    pub fn chain_height(&self, part: BodyPart) -> Option<usize> {
        self.joints
            .iter()
            .filter(|j| j.body_part == part)
            .map(|j| j.chain_depth)
            .max()
    }

    /// Length in file units of the bone a joint's rotation swings.
    ///
    /// For ASF this is the joint's own bone (the root: its longest child bone). For BVH a
    /// joint's rotation moves its children, so this is the longest child offset (0 for end
    /// sites). A zero-length link (CMU BVH: `Hips` → `LHipJoint` at `OFFSET 0 0 0`) swings
    /// the bones below it, so it counts with the length those swing. The perceptual codecs
    /// weight a channel by this length (paper 000, step 3; thesis eq. 6.4 factor).
    pub fn swung_length(&self, i: usize) -> f64 {
        let through = |c: usize| {
            let l = self.joints[c].rest.length();
            if l > 0.0 { l } else { self.swung_length(c) }
        };
        let children = || self.children(i).map(through).fold(0.0, f64::max);
        match (self.format, self.joints[i].parent) {
            (SkeletonFormat::Asf, Some(_)) => through(i),
            (SkeletonFormat::Asf, None) | (SkeletonFormat::Bvh, _) => children(),
        }
    }

    /// A fingerprint of the skeleton's structure and rest geometry (FNV-1a over names,
    /// parents, dofs and the bit patterns of rest vectors), used by bitstreams to refuse a
    /// mismatched skeleton.
    pub fn fingerprint(&self) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |bytes: &[u8]| {
            for &b in bytes {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0100_0000_01b3);
            }
        };
        for j in &self.joints {
            eat(j.name.as_bytes());
            eat(&j.parent.map_or(u64::MAX, |p| p as u64).to_le_bytes());
            for d in &j.dofs {
                eat(d.asf_name().as_bytes());
            }
            for v in j.rest.vector() {
                eat(&v.to_bits().to_le_bytes());
            }
            for v in j.axis_deg {
                eat(&v.to_bits().to_le_bytes());
            }
        }
        h
    }
}

/// One row of a clip's channel matrix: which joint and what it moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Channel {
    /// Index of the joint in [`Skeleton::joints`].
    pub joint: usize,
    /// What the channel moves.
    pub kind: ChannelKind,
}

/// A motion clip: a skeleton and a channels × frames matrix of values.
#[derive(Debug, Clone, PartialEq)]
pub struct Clip {
    /// The skeleton the channels drive.
    pub skeleton: Skeleton,
    /// Frames per second.
    pub frame_rate_hz: f64,
    channels: Vec<Channel>,
    frames: usize,
    /// Channel-major values: `data[c * frames + f]`.
    data: Vec<f64>,
}

/// Why a channel matrix does not fit a skeleton.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ClipError {
    /// The matrix has the wrong number of values.
    #[error("channel matrix has {got} values, expected {channels} channels × {frames} frames")]
    Shape {
        /// Values supplied.
        got: usize,
        /// Channels of the skeleton.
        channels: usize,
        /// Frames requested.
        frames: usize,
    },
    /// The frame rate is not a positive finite number.
    #[error("frame rate {0} Hz is not a positive finite number")]
    FrameRate(f64),
}

impl Clip {
    /// Builds a clip from a channel-major matrix (`data[c * frames + f]`) in the skeleton's
    /// channel layout.
    ///
    /// # Errors
    /// [`ClipError::Shape`] when `data.len() != channels × frames`, [`ClipError::FrameRate`] when
    /// the rate is not positive and finite.
    pub fn new(
        skeleton: Skeleton,
        frame_rate_hz: f64,
        frames: usize,
        data: Vec<f64>,
    ) -> Result<Clip, ClipError> {
        let channels = skeleton.channel_layout();
        if !(frame_rate_hz.is_finite() && frame_rate_hz > 0.0) {
            return Err(ClipError::FrameRate(frame_rate_hz));
        }
        if channels.len().checked_mul(frames) != Some(data.len()) {
            return Err(ClipError::Shape {
                got: data.len(),
                channels: channels.len(),
                frames,
            });
        }
        Ok(Clip {
            skeleton,
            frame_rate_hz,
            channels,
            frames,
            data,
        })
    }

    /// Builds a clip whose matrix was sized from `skeleton.channel_layout()` by this crate.
    pub(crate) fn from_valid_parts(
        skeleton: Skeleton,
        frame_rate_hz: f64,
        frames: usize,
        data: Vec<f64>,
    ) -> Clip {
        let channels = skeleton.channel_layout();
        debug_assert_eq!(channels.len() * frames, data.len());
        debug_assert!(frame_rate_hz.is_finite() && frame_rate_hz > 0.0);
        Clip {
            skeleton,
            frame_rate_hz,
            channels,
            frames,
            data,
        }
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Channel rows of the matrix.
    pub fn channels(&self) -> &[Channel] {
        &self.channels
    }

    /// Number of channels.
    pub fn channel_count(&self) -> usize {
        self.channels.len()
    }

    /// Duration in seconds (`frames / rate`).
    pub fn duration_s(&self) -> f64 {
        self.frames as f64 / self.frame_rate_hz
    }

    /// A readable channel name: `lfemur.rx` or `Hips.Xposition`.
    pub fn channel_name(&self, c: usize) -> String {
        let ch = self.channels[c];
        let joint = &self.skeleton.joints[ch.joint].name;
        match self.skeleton.format {
            SkeletonFormat::Asf => format!("{joint}.{}", ch.kind.asf_name()),
            SkeletonFormat::Bvh => format!("{joint}.{}", ch.kind.bvh_name()),
        }
    }

    /// One channel over all frames.
    pub fn channel(&self, c: usize) -> &[f64] {
        &self.data[c * self.frames..(c + 1) * self.frames]
    }

    /// One channel over all frames, mutable.
    pub fn channel_mut(&mut self, c: usize) -> &mut [f64] {
        &mut self.data[c * self.frames..(c + 1) * self.frames]
    }

    /// Value of channel `c` at frame `f`.
    pub fn value(&self, c: usize, f: usize) -> f64 {
        self.data[c * self.frames + f]
    }

    /// The whole channel-major matrix.
    pub fn data(&self) -> &[f64] {
        &self.data
    }

    /// Copies frame `f` into `out` (one value per channel).
    pub fn frame_into(&self, f: usize, out: &mut Vec<f64>) {
        out.clear();
        out.extend((0..self.channels.len()).map(|c| self.data[c * self.frames + f]));
    }

    /// Frames `range` of the clip, cut to its length (an empty clip when the range lies past
    /// the end): the same skeleton and rate.
    #[must_use]
    pub fn excerpt(&self, range: std::ops::Range<usize>) -> Clip {
        let end = range.end.min(self.frames);
        let start = range.start.min(end);
        let mut data = Vec::with_capacity(self.channels.len() * (end - start));
        for c in 0..self.channels.len() {
            data.extend_from_slice(&self.channel(c)[start..end]);
        }
        Clip {
            skeleton: self.skeleton.clone(),
            frame_rate_hz: self.frame_rate_hz,
            channels: self.channels.clone(),
            frames: end - start,
            data,
        }
    }

    /// The same skeleton and rate with another matrix of the same shape.
    ///
    /// # Errors
    /// [`ClipError::Shape`] when the matrix does not have this clip's shape.
    pub fn with_data(&self, frames: usize, data: Vec<f64>) -> Result<Clip, ClipError> {
        Clip::new(self.skeleton.clone(), self.frame_rate_hz, frames, data)
    }
}
