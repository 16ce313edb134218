//! Thesis ch. 4: compression of rhythmic motion by spatial segmentation and temporal blending
//! (`rhythmic`, id 9).
//!
//! **Encoder.**
//! 1. *Spatial segmentation* (4.2.1): the clip becomes the root's position and one unit
//!    quaternion per rotating joint ([`to_quaternions`]), and is cut into whole-body segments
//!    of 15 to `s_m` frames at the minima of the body's speed
//!    ([`crate::primitives::segment_body`], the chopping rule the primitive codec uses per
//!    joint).
//! 2. Every segment is taken into its own frame: its first frame's horizontal root position
//!    moved to the origin and its heading (the root's twist about the vertical axis) turned to
//!    zero, so that the same move made elsewhere or facing elsewhere looks the same.
//! 3. *The primitive database* (4.2, 4.3): the segments are clustered by the distance map's
//!    measure (eq. 4.3: the sum over joints of squared position differences, here summed over
//!    the 16 frames of each segment resampled to 16, the primitive codec's normalized length);
//!    k-means++ seeding and Lloyd iterations find up to `k` clusters, and each cluster's
//!    primitive is its member nearest the cluster mean: a real move of the clip, not an
//!    average of poses. The primitives, each at its own length, are concatenated into one clip
//!    and coded by `wavelet-perceptual` at `db_cr`:1 (thesis: wavelet compression at 10:1, "a
//!    very low error level"); that container is the payload's database section.
//! 4. *The references*: per segment, the index of its primitive (the cluster it fell in), its
//!    length, and its anchor: the horizontal position and heading the decoder places the
//!    primitive at. With `anchor = 1` (default) the encoder fits the anchor to the segment (the
//!    least-squares rigid motion about the vertical axis between the primitive's and the
//!    segment's joint positions, every joint and frame) and sends it as a quantized change
//!    from the decoder's own prediction (0.5 cm, 0.5°); with `anchor = 0` only the first
//!    segment's anchor is sent and every later one is the prediction, the thesis's literal
//!    reading ("repositioning the root ... based on the root's velocity from one motion to the
//!    next"), whose path drifts away from the original's.
//!
//! **Decoder.** Each segment is its primitive resampled to the segment's length (SLERP per
//! joint, linear for translations) and placed at its anchor; the prediction of an anchor is the
//! previous piece's last root position and heading advanced by their last frame's change
//! (velocity). Then *temporal blending* (4.2.2) at every join: the distance map (eq. 4.3, FK
//! joint positions) between the last `M_A` frames of the piece before and the first `M_B` of
//! the piece after, `M = blend × the piece's length` (thesis: "about one quarter of the frames
//! in each segment", `blend = 0.25`), gives the most similar pair `(x, y)`; the frames strictly
//! between are replaced, at weight `t = (k − x)/(y − x)`, by the SLERP (eq. 4.2) of every joint's
//! rotation from frame `x` to frame `y`, and the root's horizontal position by the weighted
//! average (eq. 4.1) of the two pieces' positions adjusted by their velocities,
//! `(1 − t)(p_x + v_x(k − x)) + t(p_y − v_y(y − k))`; its height is interpolated linearly.
//!
//! **Readings of the text** (converted from PDF; see `docs/codecs.md`):
//! - Whole-body primitives. The text's cost model (a 4-byte reference per segment, a database of
//!   "20 primitives × 20 frames × 56 DOF") has one reference per segment for all 56 DOF, so a
//!   primitive is a whole-body move, not a per-joint one as in ch. 5.
//! - The database is made from the clip being coded and travels in the stream. Ch. 4's
//!   database "contains the basic moves of the rhythmic sequences that need to be compressed"
//!   and Table 4.1 counts it in the compressed size (wavelet-coded at 10:1); "more efficient if
//!   the primitive database already exists on the client side" is the ratio without it, which
//!   [`stream_parts`] reports ([`StreamParts::cr_without_database`]).
//! - Eq. 4.1's "position adjusted by velocity" is read as each piece's root position carried
//!   forward (the piece before) or back (the piece after) along its own velocity to the
//!   blended frame; "accounting for changes in its X and Z coordinates" limits it to the
//!   horizontal plane.
//! - Eq. 4.2 is SLERP along the shorter arc ([`Quat::slerp`]): `q` and `−q` are one rotation,
//!   and the printed formula without a sign check would blend the long way round half the time.
//! - Eq. 4.3's minimum over the map is searched in the last `M_A` frames of the piece before
//!   the join (rows) and the first `M_B` of the piece after (columns); ties go to the first in
//!   row-major order. [`Traced::joins`] reports every pair chosen.
//!
//! The stream is self-contained (no decoder context): payload format 1 is a version byte (1),
//! the database section's length (`u32` LE) and the section (a whole `wavelet-perceptual`
//! container of the primitives, CRC and all), then one range-coded stream: the primitive count
//! K − 1, each primitive's length − 1, and per segment the primitive index (when K > 1), the
//! length − 1 and the anchor (change in x and z in 0.5 cm steps, in heading in 0.5° steps; for
//! every segment with `anchor = 1`, for the first only with `anchor = 0`).

use std::ops::Range;

use super::wavelet_codec::{Selection, WaveletCodec};
use super::{
    Codec, CodecError, Params, RateControl, check_stream, header, int_param, keys, merged,
    params_of, real_param,
};
use crate::bitstream::Bitstream;
use crate::entropy::{EntropyError, IntModel, RangeDecoder, RangeEncoder, UintModel};
use crate::primitives::database::{SplitMix, kmeanspp_seeds};
use crate::primitives::segment::{NORMALIZED_FRAMES, SegmentParams, sample, segment_body};
use motion::clip::{Axis, ChannelKind, Clip, Skeleton, SkeletonFormat};
use motion::fk::{self, Positions};
use motion::math::{Vec3, euler_fixed};
use motion::quat::{Quat, QuatClip, from_quaternions, rotation_joints, to_quaternions};

/// Registry name.
pub const NAME: &str = "rhythmic";
/// Bitstream id.
pub const ID: u8 = 9;
/// Payload format version.
const PAYLOAD_VERSION: u8 = 1;
/// Shortest segment (thesis ch. 4: 15-30 frames for typical rhythmic motion; ch. 5: 15).
const MIN_FRAMES: usize = 15;
/// Largest `k` and `s_m` a stream may ask for.
const MAX_K: i64 = 256;
const MAX_SEGMENT: i64 = 256;
/// Anchor position step in cm (converted to the skeleton's units) and heading step in degrees.
const ANCHOR_STEP_CM: f64 = 0.5;
const HEADING_STEP_DEG: f64 = 0.5;
/// Largest |anchor change| in steps a decoder accepts.
const ANCHOR_LIMIT: i64 = 1 << 30;
/// Lloyd iterations of the clustering (it stops earlier once no segment changes cluster).
const LLOYD_PASSES: usize = 30;
/// Seed of the clustering's k-means++ seeding.
const SEED: u64 = 0x4348_3034; // "CH04"
/// Bytes a decoder may read past the payload before it gives up (the coder's flush is 5).
const OVERRUN_LIMIT: usize = 8;

/// The parameters of the `rhythmic` codec, read and range-checked once from [`Params`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct Settings {
    /// Most primitives ([`keys::K`], 1..=256; the thesis's example: 20).
    k: usize,
    /// Longest segment `S_M` in frames ([`keys::S_M`], 15..=256).
    s_m: usize,
    /// Share of each piece searched for blend points ([`keys::BLEND`], 0..=0.5; 0 = no
    /// blending).
    blend: f64,
    /// Whether every segment's anchor is sent ([`keys::ANCHOR`], 0 or 1).
    anchor: bool,
    /// Compression ratio of the database section ([`keys::DB_CR`], 1..=100).
    db_cr: f64,
}

impl Settings {
    const DEFAULT: Settings = Settings {
        k: 20,
        s_m: 32,
        blend: 0.25,
        anchor: true,
        db_cr: 10.0,
    };

    fn from_params(p: &Params) -> Result<Settings, CodecError> {
        Ok(Settings {
            k: int_param(NAME, p, keys::K, 1, MAX_K)? as usize,
            s_m: int_param(NAME, p, keys::S_M, MIN_FRAMES as i64, MAX_SEGMENT)? as usize,
            blend: real_param(NAME, p, keys::BLEND, 0.0, 0.5)?,
            anchor: int_param(NAME, p, keys::ANCHOR, 0, 1)? == 1,
            db_cr: real_param(NAME, p, keys::DB_CR, 1.0, 100.0)?,
        })
    }

    fn to_params(self) -> Params {
        params_of(&[
            (keys::K, self.k as f64),
            (keys::S_M, self.s_m as f64),
            (keys::BLEND, self.blend),
            (keys::ANCHOR, f64::from(u8::from(self.anchor))),
            (keys::DB_CR, self.db_cr),
        ])
    }

    fn segments(self) -> SegmentParams {
        SegmentParams {
            min_frames: MIN_FRAMES,
            max_frames: self.s_m,
        }
    }
}

/// The thesis ch. 4 codec (see the module docs).
#[derive(Debug, Clone, Copy, Default)]
pub struct RhythmicCodec;

/// The two parts of a `rhythmic` stream ([`stream_parts`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StreamParts {
    /// Bytes of the whole container.
    pub total_bytes: usize,
    /// Bytes of the database section (the primitives' `wavelet-perceptual` container) and
    /// its length field: what a decoder that already holds the database would not need.
    pub database_bytes: usize,
    /// Uncompressed size the seeds' CR counts: 4 bytes per channel and frame.
    pub raw_bytes: usize,
}

impl StreamParts {
    /// CR with the database in the stream (the container's CR; Table 4.1 counts it so).
    pub fn cr_with_database(&self) -> f64 {
        self.raw_bytes as f64 / self.total_bytes as f64
    }

    /// CR when the decoder already holds the database ("more efficient if the primitive
    /// database already exists on the client side"): the container without its database
    /// section.
    pub fn cr_without_database(&self) -> f64 {
        self.raw_bytes as f64 / (self.total_bytes - self.database_bytes) as f64
    }
}

/// The sizes of a `rhythmic` stream's parts.
///
/// # Errors
/// [`CodecError::WrongCodec`] for another codec's stream, [`CodecError::Payload`] when the
/// payload's header is malformed.
pub fn stream_parts(stream: &Bitstream) -> Result<StreamParts, CodecError> {
    if stream.codec_id != ID {
        return Err(CodecError::WrongCodec {
            codec: NAME,
            expected: ID,
            found: stream.codec_id,
        });
    }
    let (db, _) = split_payload(&stream.payload)?;
    Ok(StreamParts {
        total_bytes: stream.byte_len(),
        database_bytes: db.len() + 4,
        raw_bytes: 4 * stream.channels as usize * stream.frames as usize,
    })
}

/// One blended join ([`Traced::joins`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Join {
    /// First frame of the piece after the join.
    pub frame: usize,
    /// Blend start `x`: a frame of the piece before (row of the distance map).
    pub from: usize,
    /// Blend end `y`: a frame of the piece after (column of the distance map).
    pub to: usize,
    /// Eq. 4.3 at `(x, y)`: the sum over FK points of squared distances, file units².
    pub distance: f64,
}

/// A decode with what the decoder did on the way ([`RhythmicCodec::decode_traced`]).
#[derive(Debug, Clone)]
pub struct Traced {
    /// The decoded clip (what [`Codec::decode`] returns).
    pub clip: Clip,
    /// The placed pieces before blending.
    pub unblended: Clip,
    /// Each segment's frames.
    pub segments: Vec<Range<usize>>,
    /// Each segment's primitive.
    pub primitive_of: Vec<usize>,
    /// Number of primitives in the stream's database.
    pub primitives: usize,
    /// Every join the blending searched (none with `blend = 0`), in order.
    pub joins: Vec<Join>,
}

/// Where the codec finds the root and the translation channels of a skeleton.
struct Layout {
    /// Rotating joints (skeleton indices), the tracks of a [`Body`].
    joints: Vec<usize>,
    /// Channel index of each translation channel, the rows of [`Body::trans`].
    trans_channels: Vec<usize>,
    /// Position of the root in `joints`, if the root rotates.
    root_rot: Option<usize>,
    /// Rows of the root's X, Y and Z translation in [`Body::trans`].
    root_trans: [Option<usize>; 3],
    /// The root's ASF axis rotation `C` (world rotation `C·M`); identity for BVH.
    axis: Quat,
    /// The root's rest offset (its world position is this plus its translation).
    rest: Vec3,
    /// Length each rotating joint swings (the segmentation's weights).
    weights: Vec<f64>,
    /// File units per anchor step.
    anchor_step: f64,
}

impl Layout {
    fn new(skeleton: &Skeleton) -> Layout {
        let joints = rotation_joints(skeleton);
        let root = skeleton
            .joints
            .iter()
            .position(|j| j.parent.is_none())
            .unwrap_or(0);
        let mut trans_channels = Vec::new();
        let mut root_trans = [None; 3];
        for (c, ch) in skeleton.channel_layout().iter().enumerate() {
            if let ChannelKind::Translation(a) = ch.kind {
                if ch.joint == root && root_trans[a.index()].is_none() {
                    root_trans[a.index()] = Some(trans_channels.len());
                }
                trans_channels.push(c);
            }
        }
        let (axis, rest) = skeleton
            .joints
            .get(root)
            .map_or((Quat::IDENTITY, [0.0; 3]), |j| match skeleton.format {
                SkeletonFormat::Asf => (
                    Quat::from_mat3(&euler_fixed(&j.axis_order, &j.axis_deg)),
                    j.rest.vector(),
                ),
                SkeletonFormat::Bvh => (Quat::IDENTITY, j.rest.vector()),
            });
        let cm = skeleton.units.cm_per_unit;
        Layout {
            root_rot: joints.iter().position(|&j| j == root),
            weights: joints.iter().map(|&j| skeleton.swung_length(j)).collect(),
            joints,
            trans_channels,
            root_trans,
            axis,
            rest,
            anchor_step: if cm.is_finite() && cm > 0.0 {
                ANCHOR_STEP_CM / cm
            } else {
                ANCHOR_STEP_CM
            },
        }
    }

    /// The root's world position at frame `f` of `body`.
    fn root_position(&self, body: &Body, f: usize) -> Vec3 {
        let mut p = self.rest;
        for (a, row) in self.root_trans.iter().enumerate() {
            if let Some(r) = row {
                p[a] += body.trans[*r][f];
            }
        }
        p
    }

    /// The root's heading (twist about the vertical axis, radians) at frame `f` of `body`.
    fn heading(&self, body: &Body, f: usize) -> f64 {
        self.root_rot
            .map_or(0.0, |k| (self.axis * body.rot[k][f]).twist_rad(Axis::Y))
    }

    /// Applies the rigid motion "turn by `turn` radians about the vertical axis through
    /// `from`, then move `from` to `to`" (horizontal points) to every frame of `body`: the root's
    /// world rotation `C·M` becomes `Y(turn)·C·M` and its world position `p` becomes
    /// `Y(turn)(p − from) + to`. Every joint's world position moves the same way.
    fn move_body(&self, body: &mut Body, turn: f64, from: [f64; 2], to: [f64; 2]) {
        let yaw = Quat::from_axis(Axis::Y, turn.to_degrees());
        if let Some(k) = self.root_rot {
            let local = self.axis.conj() * yaw * self.axis;
            for q in &mut body.rot[k] {
                *q = (local * *q).normalized();
            }
        }
        for f in 0..body.frames {
            let p = self.root_position(body, f);
            let v = yaw.rotate([p[0] - from[0], p[1], p[2] - from[1]]);
            let moved = [v[0] + to[0], v[1], v[2] + to[1]];
            for (a, row) in self.root_trans.iter().enumerate() {
                if let Some(r) = row {
                    body.trans[*r][f] = moved[a] - self.rest[a];
                }
            }
        }
    }
}

/// A clip as the codec works on it: per rotating joint one unit quaternion per frame, and the
/// translation channels' values.
#[derive(Debug, Clone)]
struct Body {
    frames: usize,
    /// `rot[k][f]`: rotation of `Layout::joints[k]`.
    rot: Vec<Vec<Quat>>,
    /// `trans[t][f]`: translation channel `Layout::trans_channels[t]`.
    trans: Vec<Vec<f64>>,
}

impl Body {
    fn of(clip: &Clip, layout: &Layout) -> Body {
        Body {
            frames: clip.frames(),
            rot: to_quaternions(clip).rotations,
            trans: layout
                .trans_channels
                .iter()
                .map(|&c| clip.channel(c).to_vec())
                .collect(),
        }
    }

    fn empty(layout: &Layout) -> Body {
        Body {
            frames: 0,
            rot: vec![Vec::new(); layout.joints.len()],
            trans: vec![Vec::new(); layout.trans_channels.len()],
        }
    }

    /// Frames `r` of the body.
    fn slice(&self, r: Range<usize>) -> Body {
        Body {
            frames: r.len(),
            rot: self.rot.iter().map(|t| t[r.clone()].to_vec()).collect(),
            trans: self.trans.iter().map(|t| t[r.clone()].to_vec()).collect(),
        }
    }

    /// Appends `other`'s frames.
    fn extend(&mut self, other: &Body) {
        for (a, b) in self.rot.iter_mut().zip(&other.rot) {
            a.extend_from_slice(b);
        }
        for (a, b) in self.trans.iter_mut().zip(&other.trans) {
            a.extend_from_slice(b);
        }
        self.frames += other.frames;
    }

    /// The body resampled to `len` frames: frame `m` is source frame `m·(n − 1)/(len − 1)`,
    /// SLERP between neighbours for rotations, linear for translations (the primitive codec's
    /// denormalization).
    fn resampled(&self, len: usize) -> Body {
        let n = self.frames;
        let scale = if len > 1 {
            (n.max(1) - 1) as f64 / (len - 1) as f64
        } else {
            0.0
        };
        let at = |m: usize| m as f64 * scale;
        Body {
            frames: len,
            rot: self
                .rot
                .iter()
                .map(|t| (0..len).map(|m| sample(t, at(m))).collect())
                .collect(),
            trans: self
                .trans
                .iter()
                .map(|t| (0..len).map(|m| lerp_at(t, at(m))).collect())
                .collect(),
        }
    }

    /// The clip these values make on `skeleton` (rotations decomposed into each joint's own
    /// channels, [`from_quaternions`]).
    fn into_clip(
        self,
        skeleton: &Skeleton,
        layout: &Layout,
        rate: f64,
    ) -> Result<Clip, CodecError> {
        let frames = self.frames;
        let mut data = vec![0.0; skeleton.channel_count() * frames];
        for (&c, row) in layout.trans_channels.iter().zip(&self.trans) {
            data[c * frames..(c + 1) * frames].copy_from_slice(row);
        }
        let source = Clip::new(skeleton.clone(), rate, frames, data)?;
        Ok(from_quaternions(&QuatClip {
            source,
            joints: layout.joints.clone(),
            rotations: self.rot,
        }))
    }
}

/// `x` sampled at fractional frame `t` by linear interpolation (`x` not empty).
fn lerp_at(x: &[f64], t: f64) -> f64 {
    let last = x.len() - 1;
    let t = t.clamp(0.0, last as f64);
    let i = (t.floor() as usize).min(last);
    if i == last {
        return x[last];
    }
    x[i] + (t - i as f64) * (x[i + 1] - x[i])
}

/// Where a segment's piece is placed: its first frame's root, horizontally, and its heading.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Anchor {
    x: f64,
    z: f64,
    heading: f64,
}

/// Wraps an angle in radians into `(−π, π]`.
fn wrap_pi(a: f64) -> f64 {
    let w = a - std::f64::consts::TAU * (a / std::f64::consts::TAU).round();
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
    }
}

/// The anchor the decoder predicts for the piece after `prev`: its last root position and
/// heading advanced by their change over its last frame (the root's velocity).
fn predict(layout: &Layout, prev: Option<&Body>) -> Anchor {
    let Some(b) = prev.filter(|b| b.frames > 0) else {
        return Anchor {
            x: 0.0,
            z: 0.0,
            heading: 0.0,
        };
    };
    let last = b.frames - 1;
    let p = layout.root_position(b, last);
    let h = layout.heading(b, last);
    if last == 0 {
        return Anchor {
            x: p[0],
            z: p[2],
            heading: h,
        };
    }
    let q = layout.root_position(b, last - 1);
    let g = layout.heading(b, last - 1);
    Anchor {
        x: 2.0 * p[0] - q[0],
        z: 2.0 * p[2] - q[2],
        heading: wrap_pi(h + wrap_pi(h - g)),
    }
}

/// The anchor change from the prediction in steps (x, z, heading).
type AnchorSteps = [i64; 3];

fn anchor_from(layout: &Layout, pred: Anchor, steps: AnchorSteps) -> Anchor {
    Anchor {
        x: pred.x + steps[0] as f64 * layout.anchor_step,
        z: pred.z + steps[1] as f64 * layout.anchor_step,
        heading: wrap_pi(pred.heading + (steps[2] as f64 * HEADING_STEP_DEG).to_radians()),
    }
}

/// The piece of one segment: `prim` (in its own frame) resampled to `len` frames and placed
/// at `anchor`.
fn place(layout: &Layout, prim: &Body, len: usize, anchor: Anchor) -> Body {
    let mut piece = prim.resampled(len);
    layout.move_body(&mut piece, anchor.heading, [0.0, 0.0], [anchor.x, anchor.z]);
    piece
}

/// The payload's database section and range-coded references.
fn split_payload(payload: &[u8]) -> Result<(&[u8], &[u8]), CodecError> {
    let corrupt = |offset: usize, detail: &str| CodecError::Payload {
        codec: NAME,
        offset,
        detail: detail.into(),
    };
    let (&version, rest) = payload
        .split_first()
        .ok_or_else(|| corrupt(0, "empty payload"))?;
    if version != PAYLOAD_VERSION {
        return Err(corrupt(
            0,
            &format!(
                "payload format version {version} (this build reads {PAYLOAD_VERSION}): re-encode the clip"
            ),
        ));
    }
    let len_bytes: [u8; 4] = rest
        .get(..4)
        .and_then(|b| b.try_into().ok())
        .ok_or_else(|| corrupt(1, "database length"))?;
    let len = u32::from_le_bytes(len_bytes) as usize;
    let db = rest
        .get(4..4 + len)
        .ok_or_else(|| corrupt(5, "database section longer than the payload"))?;
    Ok((db, &rest[4 + len..]))
}

/// Squared distance between two feature rows.
fn sq_distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// The clustering of step 3 (module docs): up to `k` clusters of the feature rows; returns
/// the primitives (indices of the member nearest each cluster's mean, in order of first use)
/// and each row's primitive (its cluster's).
fn cluster(features: &[Vec<f64>], k: usize) -> (Vec<usize>, Vec<usize>) {
    let n = features.len();
    if n == 0 {
        return (Vec::new(), Vec::new());
    }
    let k = k.min(n);
    let mut rng = SplitMix(SEED);
    let seeds = kmeanspp_seeds(n, k, &mut rng, |a, b| {
        sq_distance(&features[a], &features[b])
    });
    let mut centres: Vec<Vec<f64>> = seeds.iter().map(|&i| features[i].clone()).collect();
    let nearest = |centres: &[Vec<f64>], row: &[f64]| -> usize {
        let mut best = (0, f64::INFINITY);
        for (c, centre) in centres.iter().enumerate() {
            let d = sq_distance(centre, row);
            if d < best.1 {
                best = (c, d);
            }
        }
        best.0
    };
    let mut assign = vec![usize::MAX; n];
    for _ in 0..LLOYD_PASSES {
        let mut changed = false;
        for (a, row) in assign.iter_mut().zip(features) {
            let c = nearest(&centres, row);
            changed |= *a != c;
            *a = c;
        }
        if !changed {
            break;
        }
        for (c, centre) in centres.iter_mut().enumerate() {
            let mut count = 0usize;
            let mut sum = vec![0.0; centre.len()];
            for (row, _) in features.iter().zip(&assign).filter(|(_, a)| **a == c) {
                for (s, v) in sum.iter_mut().zip(row) {
                    *s += v;
                }
                count += 1;
            }
            if count > 0 {
                for s in &mut sum {
                    *s /= count as f64;
                }
                *centre = sum;
            }
        }
    }
    // Each cluster's primitive: its member nearest the mean (clusters left empty drop out).
    let mut members: Vec<Option<(usize, f64)>> = vec![None; centres.len()];
    for (i, (row, &c)) in features.iter().zip(&assign).enumerate() {
        let d = sq_distance(row, &centres[c]);
        if members[c].is_none_or(|(_, best)| d < best) {
            members[c] = Some((i, d));
        }
    }
    // Number the primitives in order of first use.
    let mut number = vec![usize::MAX; centres.len()];
    let mut primitives = Vec::new();
    let mut of = Vec::with_capacity(n);
    for &c in &assign {
        if number[c] == usize::MAX {
            number[c] = primitives.len();
            primitives.push(members[c].map_or(0, |(i, _)| i));
        }
        of.push(number[c]);
    }
    (primitives, of)
}

/// The feature row of a segment (frames `r` of the clip): its FK points in the segment's own
/// frame (first frame's horizontal root position at the origin, heading zero), at 16 frames
/// resampled linearly over the segment.
fn features(positions: &Positions, r: &Range<usize>, root: usize, heading: f64) -> Vec<f64> {
    let n = positions.joint_count();
    let origin = positions.point(r.start, root);
    let turn = Quat::from_axis(Axis::Y, -heading.to_degrees());
    let span = (r.len() - 1) as f64;
    let mut out = Vec::with_capacity(NORMALIZED_FRAMES * n * 3);
    for m in 0..NORMALIZED_FRAMES {
        let t = r.start as f64 + m as f64 * span / (NORMALIZED_FRAMES - 1) as f64;
        let (i, w) = ((t.floor() as usize).min(r.end - 1), t - t.floor());
        let j = (i + 1).min(r.end - 1);
        for p in 0..n {
            let (a, b) = (positions.point(i, p), positions.point(j, p));
            let v = [
                a[0] + w * (b[0] - a[0]) - origin[0],
                a[1] + w * (b[1] - a[1]),
                a[2] + w * (b[2] - a[2]) - origin[2],
            ];
            out.extend_from_slice(&turn.rotate(v));
        }
    }
    out
}

/// The least-squares anchor of a piece (step 4, module docs): the turn about the vertical axis
/// and horizontal move that bring the points `local` (FK of the piece placed at the origin
/// with heading zero) closest to `world` (the segment's FK points), summed over every point
/// and frame; the 2-D Procrustes solution.
fn fit_anchor(local: &Positions, world: &Positions, start: usize) -> Anchor {
    let n = local.joint_count();
    let frames = local.frames();
    let count = (n * frames) as f64;
    let (mut cl, mut cw) = ([0.0; 2], [0.0; 2]);
    for f in 0..frames {
        for p in 0..n {
            let (a, b) = (local.point(f, p), world.point(start + f, p));
            cl[0] += a[0];
            cl[1] += a[2];
            cw[0] += b[0];
            cw[1] += b[2];
        }
    }
    for c in [&mut cl, &mut cw] {
        c[0] /= count;
        c[1] /= count;
    }
    // Y(θ) maps (x, z) to (x cos θ + z sin θ, −x sin θ + z cos θ); Σ w·Y(θ)u is
    // cos θ·Σ(wx ux + wz uz) + sin θ·Σ(wx uz − wz ux), largest at θ = atan2(S, C).
    let (mut c, mut s) = (0.0, 0.0);
    for f in 0..frames {
        for p in 0..n {
            let (a, b) = (local.point(f, p), world.point(start + f, p));
            let u = [a[0] - cl[0], a[2] - cl[1]];
            let w = [b[0] - cw[0], b[2] - cw[1]];
            c += w[0] * u[0] + w[1] * u[1];
            s += w[0] * u[1] - w[1] * u[0];
        }
    }
    let heading = if c == 0.0 && s == 0.0 {
        0.0
    } else {
        s.atan2(c)
    };
    let (sin, cos) = heading.sin_cos();
    Anchor {
        x: cw[0] - (cl[0] * cos + cl[1] * sin),
        z: cw[1] - (-cl[0] * sin + cl[1] * cos),
        heading,
    }
}

/// Adaptive models of the references.
struct Models {
    count: UintModel,
    prim_len: UintModel,
    index: UintModel,
    len: UintModel,
    pos: IntModel,
    heading: IntModel,
}

impl Models {
    fn new() -> Models {
        Models {
            count: UintModel::default(),
            prim_len: UintModel::default(),
            index: UintModel::default(),
            len: UintModel::default(),
            pos: IntModel::default(),
            heading: IntModel::default(),
        }
    }
}

fn coded(r: Result<(), EntropyError>) -> Result<(), CodecError> {
    r.map_err(|e| CodecError::Payload {
        codec: NAME,
        offset: 0,
        detail: e.to_string(),
    })
}

impl RhythmicCodec {
    /// The codec.
    pub fn new() -> RhythmicCodec {
        RhythmicCodec
    }

    /// The database section: the primitives (each segment of `primitives`, taken into its
    /// own frame) as one clip coded by `wavelet-perceptual` at `db_cr`:1, the container bytes
    /// and what the decoder will make of them.
    fn database(
        clip: &Clip,
        layout: &Layout,
        body: &Body,
        segments: &[Range<usize>],
        primitives: &[usize],
        db_cr: f64,
    ) -> Result<(Vec<u8>, Vec<Body>), CodecError> {
        let mut db = Body::empty(layout);
        let mut lens = Vec::with_capacity(primitives.len());
        for &s in primitives {
            let r = segments[s].clone();
            let mut piece = body.slice(r.clone());
            let p = layout.root_position(body, r.start);
            layout.move_body(
                &mut piece,
                -layout.heading(body, r.start),
                [p[0], p[2]],
                [0.0, 0.0],
            );
            lens.push(r.len());
            db.extend(&piece);
        }
        let db_clip = db.into_clip(&clip.skeleton, layout, clip.frame_rate_hz)?;
        let wavelet = WaveletCodec::new(Selection::Perceptual);
        // A tiny database may not reach db_cr:1 (too few frames for the wavelet's budget):
        // it is then coded at the wavelet codec's defaults.
        let stream = match crate::rate::encode_to_cr(&wavelet, &db_clip, &Params::new(), db_cr) {
            Err(CodecError::Rate { .. }) => wavelet.encode(&db_clip, &Params::new())?,
            other => other?,
        };
        let bytes = stream.to_bytes()?;
        let decoded = wavelet.decode(&stream, &clip.skeleton)?;
        Ok((bytes, split_database(&decoded, layout, &lens)))
    }

    /// Encodes with settings `s`.
    fn encode_with(self, clip: &Clip, s: Settings) -> Result<Bitstream, CodecError> {
        let layout = Layout::new(&clip.skeleton);
        let frames = clip.frames();
        let mut payload = vec![PAYLOAD_VERSION];
        if frames == 0 {
            payload.extend_from_slice(&0u32.to_le_bytes());
            return header(&self, clip, s.to_params(), payload);
        }
        let body = Body::of(clip, &layout);
        let segments = segment_body(
            &body.rot,
            &layout.weights,
            frames,
            clip.frame_rate_hz,
            s.segments(),
        );
        let positions = fk::positions(clip);
        let root = 0; // FK point 0 is the root.
        let rows: Vec<Vec<f64>> = segments
            .iter()
            .map(|r| features(&positions, r, root, layout.heading(&body, r.start)))
            .collect();
        let (primitives, primitive_of) = cluster(&rows, s.k);
        let (db_bytes, prims) =
            Self::database(clip, &layout, &body, &segments, &primitives, s.db_cr)?;
        let db_len = u32::try_from(db_bytes.len()).map_err(|_| CodecError::TooLarge {
            channels: clip.channel_count(),
            frames,
        })?;
        payload.extend_from_slice(&db_len.to_le_bytes());
        payload.extend_from_slice(&db_bytes);

        let mut enc = RangeEncoder::new();
        let mut m = Models::new();
        coded(m.count.encode(&mut enc, (prims.len() - 1) as u32))?;
        for p in &prims {
            coded(m.prim_len.encode(&mut enc, (p.frames - 1) as u32))?;
        }
        let mut prev: Option<Body> = None;
        for (r, &idx) in segments.iter().zip(&primitive_of) {
            if prims.len() > 1 {
                coded(m.index.encode(&mut enc, idx as u32))?;
            }
            coded(m.len.encode(&mut enc, (r.len() - 1) as u32))?;
            let pred = predict(&layout, prev.as_ref());
            let anchor = if s.anchor || prev.is_none() {
                let origin = Anchor {
                    x: 0.0,
                    z: 0.0,
                    heading: 0.0,
                };
                let local = place(&layout, &prims[idx], r.len(), origin).into_clip(
                    &clip.skeleton,
                    &layout,
                    clip.frame_rate_hz,
                )?;
                let fit = fit_anchor(&fk::positions(&local), &positions, r.start);
                let steps = [
                    ((fit.x - pred.x) / layout.anchor_step).round(),
                    ((fit.z - pred.z) / layout.anchor_step).round(),
                    (wrap_pi(fit.heading - pred.heading).to_degrees() / HEADING_STEP_DEG).round(),
                ];
                if steps
                    .iter()
                    .any(|v| !v.is_finite() || v.abs() > ANCHOR_LIMIT as f64)
                {
                    return Err(CodecError::Param {
                        codec: NAME,
                        key: clip.channel_name(layout.trans_channels.first().copied().unwrap_or(0)),
                        value: fit.x.hypot(fit.z),
                        detail: "root position beyond the format's range".into(),
                    });
                }
                let steps = steps.map(|v| v as i64);
                coded(m.pos.encode(&mut enc, steps[0]))?;
                coded(m.pos.encode(&mut enc, steps[1]))?;
                coded(m.heading.encode(&mut enc, steps[2]))?;
                anchor_from(&layout, pred, steps)
            } else {
                pred
            };
            prev = Some(place(&layout, &prims[idx], r.len(), anchor));
        }
        payload.extend_from_slice(&enc.finish());
        header(&self, clip, s.to_params(), payload)
    }

    /// Decodes `stream`, keeping what the decoder did (the pieces before blending, the
    /// segments, the blend points): for tests and figures.
    ///
    /// # Errors
    /// As [`Codec::decode`].
    pub fn decode_traced(
        &self,
        stream: &Bitstream,
        skeleton: &Skeleton,
    ) -> Result<Traced, CodecError> {
        check_stream(self, stream, skeleton)?;
        let mut p = self.default_params();
        p.extend(stream.params.iter().map(|(k, v)| (k.clone(), *v)));
        let s = Settings::from_params(&p)?;
        let layout = Layout::new(skeleton);
        let frames = stream.frames as usize;
        let rate = stream.frame_rate_hz;
        let (db_bytes, refs) = split_payload(&stream.payload)?;
        let mut r = RefsDecoder {
            dec: RangeDecoder::new(refs),
            m: Models::new(),
            base: stream.payload.len() - refs.len(),
        };
        if frames == 0 {
            if !db_bytes.is_empty() || !refs.is_empty() {
                return Err(r.corrupt("an empty clip with a database"));
            }
            let empty = Body::empty(&layout).into_clip(skeleton, &layout, rate)?;
            return Ok(Traced {
                clip: empty.clone(),
                unblended: empty,
                segments: Vec::new(),
                primitive_of: Vec::new(),
                primitives: 0,
                joins: Vec::new(),
            });
        }
        // Only the wavelet codec's streams: another id (this codec's own, nested) is corrupt.
        let db_clip = WaveletCodec::new(Selection::Perceptual)
            .decode(&Bitstream::from_bytes(db_bytes)?, skeleton)?;
        let prims = r.primitives(&db_clip, &layout, s)?;
        let Pieces {
            mut body,
            segments,
            primitive_of,
        } = r.pieces(&prims, &layout, s, frames)?;
        if r.dec.overrun() != 0 || r.dec.position() != refs.len() {
            return Err(r.corrupt("payload length does not match its content"));
        }
        let unblended = body.clone().into_clip(skeleton, &layout, rate)?;
        let joins = if s.blend > 0.0 {
            blend(
                &mut body,
                &layout,
                &segments,
                &fk::positions(&unblended),
                s.blend,
            )
        } else {
            Vec::new()
        };
        Ok(Traced {
            clip: body.into_clip(skeleton, &layout, rate)?,
            unblended,
            segments,
            primitive_of,
            primitives: prims.len(),
            joins,
        })
    }
}

/// The decoder of the references: the mirror of the encoder's half of
/// [`RhythmicCodec::encode_with`].
struct RefsDecoder<'a> {
    dec: RangeDecoder<'a>,
    m: Models,
    /// Offset of the references in the payload (for error messages).
    base: usize,
}

impl RefsDecoder<'_> {
    fn corrupt(&self, detail: &str) -> CodecError {
        CodecError::Payload {
            codec: NAME,
            offset: self.base + self.dec.position(),
            detail: detail.into(),
        }
    }

    /// The primitive count and lengths, and the primitives cut from the decoded database.
    fn primitives(
        &mut self,
        db_clip: &Clip,
        layout: &Layout,
        s: Settings,
    ) -> Result<Vec<Body>, CodecError> {
        let count = self
            .m
            .count
            .decode(&mut self.dec)
            .ok_or_else(|| self.corrupt("primitive count"))? as usize
            + 1;
        if count > s.k || count > db_clip.frames() {
            return Err(self.corrupt("more primitives than k or the database's frames"));
        }
        let mut lens = Vec::with_capacity(count);
        for _ in 0..count {
            let len = self
                .m
                .prim_len
                .decode(&mut self.dec)
                .ok_or_else(|| self.corrupt("primitive length"))? as usize
                + 1;
            if len > s.s_m {
                return Err(self.corrupt("primitive longer than S_M"));
            }
            lens.push(len);
        }
        if lens.iter().sum::<usize>() != db_clip.frames() {
            return Err(self.corrupt("primitive lengths do not add up to the database's frames"));
        }
        Ok(split_database(db_clip, layout, &lens))
    }

    /// Every segment's piece, placed (module docs), until `frames` are covered.
    fn pieces(
        &mut self,
        prims: &[Body],
        layout: &Layout,
        s: Settings,
        frames: usize,
    ) -> Result<Pieces, CodecError> {
        let mut body = Body::empty(layout);
        let mut segments = Vec::new();
        let mut primitive_of = Vec::new();
        let mut prev: Option<Body> = None;
        while body.frames < frames {
            let idx = if prims.len() > 1 {
                self.m
                    .index
                    .decode(&mut self.dec)
                    .ok_or_else(|| self.corrupt("primitive index"))? as usize
            } else {
                0
            };
            let prim = prims
                .get(idx)
                .ok_or_else(|| self.corrupt("primitive index beyond the database"))?;
            let len = self
                .m
                .len
                .decode(&mut self.dec)
                .ok_or_else(|| self.corrupt("segment length"))? as usize
                + 1;
            if len > s.s_m || body.frames + len > frames {
                return Err(self.corrupt("segment longer than S_M or the clip"));
            }
            let pred = predict(layout, prev.as_ref());
            let anchor = if s.anchor || prev.is_none() {
                let mut steps = [0i64; 3];
                for (i, v) in steps.iter_mut().enumerate() {
                    let model = if i < 2 {
                        &mut self.m.pos
                    } else {
                        &mut self.m.heading
                    };
                    *v = model
                        .decode(&mut self.dec)
                        .filter(|v| v.abs() <= ANCHOR_LIMIT)
                        .ok_or_else(|| self.corrupt("anchor"))?;
                }
                anchor_from(layout, pred, steps)
            } else {
                pred
            };
            if self.dec.overrun() > OVERRUN_LIMIT {
                return Err(self.corrupt("payload ends early"));
            }
            let piece = place(layout, prim, len, anchor);
            segments.push(body.frames..body.frames + len);
            primitive_of.push(idx);
            body.extend(&piece);
            prev = Some(piece);
        }
        Ok(Pieces {
            body,
            segments,
            primitive_of,
        })
    }
}

/// What [`RefsDecoder::pieces`] decodes.
struct Pieces {
    /// The placed pieces one after the other.
    body: Body,
    /// Each segment's frames.
    segments: Vec<Range<usize>>,
    /// Each segment's primitive.
    primitive_of: Vec<usize>,
}

/// The decoded database clip cut into its primitives (`lens` frames each, in order).
fn split_database(db: &Clip, layout: &Layout, lens: &[usize]) -> Vec<Body> {
    let body = Body::of(db, layout);
    let mut start = 0;
    lens.iter()
        .map(|&len| {
            let b = body.slice(start..start + len);
            start += len;
            b
        })
        .collect()
}

/// Frames searched for blend points on each side of a join: `blend` of the piece's length,
/// at most half of it (so the windows of a piece's two joins never overlap).
fn blend_window(len: usize, blend: f64) -> usize {
    ((blend * len as f64).round() as usize).min(len / 2)
}

/// Eq. 4.3 between frames `i` and `j`: the sum over FK points of squared distances.
fn frame_distance(positions: &Positions, i: usize, j: usize) -> f64 {
    positions
        .frame(i)
        .iter()
        .zip(positions.frame(j))
        .map(|(a, b)| {
            let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        })
        .sum()
}

/// Temporal blending of every join (module docs); `positions` are the FK points of `body`
/// before blending. Returns the joins with their blend points.
fn blend(
    body: &mut Body,
    layout: &Layout,
    segments: &[Range<usize>],
    positions: &Positions,
    share: f64,
) -> Vec<Join> {
    let src = body.clone();
    let mut joins = Vec::with_capacity(segments.len().saturating_sub(1));
    for pair in segments.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        let (ma, mb) = (blend_window(a.len(), share), blend_window(b.len(), share));
        if ma == 0 || mb == 0 {
            continue;
        }
        let e = b.start;
        let mut best = Join {
            frame: e,
            from: e - 1,
            to: e,
            distance: f64::INFINITY,
        };
        for x in e - ma..e {
            for y in e..e + mb {
                let d = frame_distance(positions, x, y);
                if d < best.distance {
                    (best.from, best.to, best.distance) = (x, y, d);
                }
            }
        }
        joins.push(best);
        let (x, y) = (best.from, best.to);
        if y - x < 2 {
            continue;
        }
        let span = (y - x) as f64;
        // Root velocities within each piece (eq. 4.1's adjustment), per frame.
        let px = layout.root_position(&src, x);
        let py = layout.root_position(&src, y);
        let vx = if x > a.start {
            let q = layout.root_position(&src, x - 1);
            [px[0] - q[0], px[2] - q[2]]
        } else {
            [0.0; 2]
        };
        let vy = if y + 1 < b.end {
            let q = layout.root_position(&src, y + 1);
            [q[0] - py[0], q[2] - py[2]]
        } else {
            [0.0; 2]
        };
        for k in x + 1..y {
            let t = (k - x) as f64 / span;
            for (out, track) in body.rot.iter_mut().zip(&src.rot) {
                out[k] = track[x].slerp(track[y], t);
            }
            for (out, row) in body.trans.iter_mut().zip(&src.trans) {
                out[k] = (1.0 - t) * row[x] + t * row[y];
            }
            let (before, after) = ((k - x) as f64, (y - k) as f64);
            let p = [
                (1.0 - t) * (px[0] + vx[0] * before) + t * (py[0] - vy[0] * after),
                (1.0 - t) * (px[2] + vx[1] * before) + t * (py[2] - vy[1] * after),
            ];
            for (axis, value) in [(0, p[0]), (2, p[1])] {
                if let Some(r) = layout.root_trans[axis] {
                    body.trans[r][k] = value - layout.rest[axis];
                }
            }
        }
    }
    joins
}

impl Codec for RhythmicCodec {
    fn name(&self) -> &'static str {
        NAME
    }

    fn id(&self) -> u8 {
        ID
    }

    fn description(&self) -> &'static str {
        "thesis ch. 4: whole-body segments as references to primitives of the clip, blended at the joins (SLERP, velocity-adjusted root, distance map)"
    }

    fn default_params(&self) -> Params {
        Settings::DEFAULT.to_params()
    }

    fn rate_control(&self) -> RateControl {
        // The rate follows from the clip's repetitions and `k`, not from a continuous knob.
        RateControl::None
    }

    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError> {
        let p = merged(self, params)?;
        (*self).encode_with(clip, Settings::from_params(&p)?)
    }

    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
        self.decode_traced(stream, skeleton).map(|t| t.clip)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_round_trip_through_params() {
        let p = Settings::DEFAULT.to_params();
        assert_eq!(Settings::from_params(&p).unwrap(), Settings::DEFAULT);
        let mut bad = p.clone();
        bad.insert(keys::BLEND.into(), 0.6);
        assert!(Settings::from_params(&bad).is_err());
        bad = p;
        bad.insert(keys::S_M.into(), 14.0);
        assert!(Settings::from_params(&bad).is_err());
    }

    #[test]
    fn wrap_pi_stays_in_its_interval() {
        use std::f64::consts::PI;
        for a in [-7.0, -PI, -3.0, 0.0, 3.0, PI, 7.0, 100.0] {
            let w = wrap_pi(a);
            assert!(w > -PI - 1e-12 && w <= PI + 1e-12, "{a}: {w}");
            assert!(((a - w) / std::f64::consts::TAU).fract().abs() < 1e-9);
        }
    }

    #[test]
    fn clustering_groups_repeated_rows() {
        // Three distinct rows, each repeated: three clusters, primitives numbered by first use.
        let a = vec![0.0; 6];
        let b = vec![10.0; 6];
        let c = vec![-10.0; 6];
        let rows = vec![a.clone(), b.clone(), a.clone(), c, b, a];
        let (prims, of) = cluster(&rows, 3);
        assert_eq!(of, vec![0, 1, 0, 2, 1, 0]);
        assert_eq!(prims.len(), 3);
        for (p, &row) in prims.iter().zip(&[0usize, 1, 3]) {
            assert_eq!(rows[*p], rows[row]);
        }
        assert_eq!(cluster(&rows, 1).1, vec![0; 6]);
    }
}
