//! Thesis ch. 5.3.4: the primitive-database codec with incremental encoding (`primitive`, id 8).
//!
//! Each joint's quaternion track is cut by [`segment_track`] with the database's segmentation
//! (15 frames at least, `S_M` at most). Per segment:
//! 1. the segment length is coded (the decoder cannot derive the cuts);
//! 2. the segment's 16-frame normalized form picks the nearest primitive of the joint
//!    (eq. 5.3-5.4), whose index is coded;
//! 3. the primitive is denormalized (SLERP) back to the segment's length; if it stays within
//!    the joint's threshold `t_j` of the source at every frame, nothing else is sent;
//! 4. otherwise the difference `diff = p⁻¹·q` (eq. 5.7), as its logarithm (three channels,
//!    half the rotation vector), on the 16 normalized frames where those hold the segment
//!    within `t_j` once denormalized, else at the segment's own frames (a flag says which),
//!    gets a 4-level CDF 9/7 transform; the coefficients are
//!    quantized to 10 bits (step `2^(s/8)` with `max|c|/step ≤ 511`, or coarser, down to
//!    `step ≥ step_floor·t_j`, where the threshold allows), and the smallest are zeroed: a
//!    bisection on the number kept finds the fewest whose reconstruction `q̂ = p·exp(v̂)`
//!    (eq. 5.8) stays within `t_j` at every frame; the kept values are run-length coded and
//!    everything is range coded ([`crate::entropy`]).
//!
//! `t_j = t_L` for leg joints ([`motion::BodyPart::is_leg`]) and `t_U = upper_ratio·t_L`
//! (thesis: 2) for every other joint. Translation channels (the root's) are cut into 32-frame
//! windows; each window's mean is sent in 1/1024 units, the rest gets a 4-level CDF 9/7
//! transform whose smallest 50 % of coefficients are zeroed and the others quantized to 10 bits.
//!
//! Decisions (see `docs/primitive-codec.md`):
//! - The difference is coded on the 16 normalized frames (the thesis: "all the segments are
//!   normalized to 16 frames", the 4-level transform of "the difference") against the
//!   primitive itself, and the reconstruction denormalized (SLERP) to the segment's length, but
//!   only where the 16 frames can hold the segment: if the source's own normalized form,
//!   denormalized, already misses `t_j` at some frame (resampling alone moves it), no
//!   coefficient choice can meet the bound there, and that segment's difference is coded at its
//!   own length against the denormalized primitive instead (the wavelet handles any length by
//!   periodization). Either way the bound "every decoded frame within `t_j`" is checked on the
//!   frames the decoder outputs. On the shared clips 89-97 % of the coded differences are on
//!   the 16 frames and the streams are 6-18 % smaller than coding every difference at its own
//!   length (`normalized = 0`, the only grid before issue 21; streams without the key decode
//!   that way), at 18-22 % more encoder instructions.
//! - The bound is checked on what the decoded clip holds: for a joint with fewer than three
//!   rotation channels the Euler channels cannot hold an arbitrary rotation, so the encoder
//!   checks [`project_to_channels`] of the reconstruction.
//! - `step_floor` (default 0.5): the thesis quantizes to 10 bits of the segment's range, which
//!   at `t_L = 0.01` resolves differences to ~1e-4 rad, far below the threshold the search
//!   then enforces anyway. Letting the step grow to `t_j/2` keeps every value within 10 bits
//!   and the same bound, and codes 26-32 % fewer bytes on the shared clips; `step_floor = 0`
//!   is the thesis's literal quantizer.
//! - When 10 bits cannot meet `t_j` even with every coefficient kept (very small `t_L`), the
//!   step is halved until they can: the bound is the codec's contract, 10 bits its default.
//! - A joint the database does not know (another skeleton's names) is coded against a "hold"
//!   reference: the previous segment's last decoded rotation held constant.
//! - Smoothing of segment joins (the 5.3.4 procedure, `smooth = M` frames, default off) runs
//!   in the decoder: in the last `M` frames of a segment and the first `M` of the next it picks
//!   the closest pair (the distance map of ch. 4) and replaces the frames between them by a
//!   SLERP. It changes frames after the encoder's check, so the `t_j` bound holds only with
//!   `smooth = 0`.
//!
//! The database is the decoder's context: its fingerprint is the stream's `db` parameter, and
//! a stream decoded with another database is refused ([`CodecError::DatabaseMismatch`]).

use std::collections::BTreeMap;
use std::sync::Arc;

use super::{
    Codec, CodecError, Params, RateControl, RateEncoder, check_stream, header, int_param, keys,
    merged, params_of, real_param,
};
use crate::bitstream::Bitstream;
use crate::entropy::{BitModel, EntropyError, IntModel, RangeDecoder, RangeEncoder, UintModel};
use crate::primitives::database::{Database, Primitive, segment_distance};
use crate::primitives::segment::{NORMALIZED_FRAMES, Segment, denormalize, segment_track};
use crate::wavelet::{Transform, Wavelet, band_lengths};
use motion::clip::{Axis, Clip, Skeleton, SkeletonFormat};
use motion::quat::{
    Quat, QuatClip, from_quaternions, project_to_channels, rotation_axes, rotation_joints,
    to_quaternions,
};

/// Registry name.
pub const NAME: &str = "primitive";
/// Bitstream id.
pub const ID: u8 = 8;
/// Levels of the CDF 9/7 transform (thesis: 4).
const LEVELS: usize = 4;
const BANDS: usize = LEVELS + 1;
/// Root translation window in frames (thesis: 32).
const ROOT_WINDOW: usize = 32;
/// Largest quantized magnitude at 10 bits (signed).
const QUANT_MAX: f64 = 511.0;
/// Quantizer step exponents: `step = 2^(s/8)`, from 2^-30 to 2^20.
const STEP_MIN: i64 = -240;
const STEP_MAX: i64 = 160;
/// Translation means are sent in 1/1024 of the file's length unit.
const MEAN_SCALE: f64 = 1024.0;
/// Largest |quantized mean| a decoder accepts (2^50 / 1024 length units).
const MEAN_LIMIT: i64 = 1 << 50;
/// Largest |quantized coefficient| a decoder accepts.
const VALUE_LIMIT: i64 = 1 << 30;
/// Bytes a decoder may read past the payload before it gives up (the coder's flush is 5).
const OVERRUN_LIMIT: usize = 8;

/// The primitive-database codec. Without a database it is still listed (so `study codecs`
/// shows it) but encode and decode return [`CodecError::NoDatabase`].
#[derive(Debug, Clone)]
pub struct PrimitiveCodec {
    db: Option<Arc<Database>>,
    fingerprint: u32,
    /// Each joint's primitives, renormalized to unit length (the file stores `f32`, whose
    /// rounding alone would put `acos` distances near 1e-3 rad).
    joints: BTreeMap<String, Vec<Primitive>>,
}

/// The parameters of the `primitive` codec, read and range-checked once from [`Params`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct PrimitiveSettings {
    /// The leg joints' threshold `t_L` in radians ([`keys::T_L`], 1e-4..=1).
    t_l: f64,
    /// `t_U / t_L` ([`keys::UPPER_RATIO`], 1..=10).
    upper_ratio: f64,
    /// Frames smoothed each side of a join ([`keys::SMOOTH`], 0..=16).
    smooth: usize,
    /// Coarsest step over the threshold ([`keys::STEP_FLOOR`], 0..=4).
    step_floor: f64,
    /// Differences coded on the 16 normalized frames where that meets `t_j`
    /// ([`keys::NORMALIZED`], 0 or 1).
    normalized: bool,
    /// Fingerprint of the primitive database ([`keys::DB`]).
    db: u32,
}

impl PrimitiveSettings {
    /// The defaults, with the database of fingerprint `db`.
    fn defaults(db: u32) -> PrimitiveSettings {
        PrimitiveSettings {
            t_l: 0.012,
            upper_ratio: 2.0,
            smooth: 0,
            step_floor: 0.5,
            normalized: true,
            db,
        }
    }

    /// Reads the settings from `p`: first that [`keys::DB`] names the database of
    /// fingerprint `fingerprint` ([`CodecError::DatabaseMismatch`] otherwise), then every
    /// other key within its range.
    fn from_params(p: &Params, fingerprint: u32) -> Result<PrimitiveSettings, CodecError> {
        let v = p.get(keys::DB).copied().unwrap_or(f64::NAN);
        if v.fract() != 0.0 || !(0.0..=f64::from(u32::MAX)).contains(&v) {
            return Err(CodecError::Param {
                codec: NAME,
                key: keys::DB.into(),
                value: v,
                detail: "must be a database fingerprint (an integer in 0..=4294967295)".into(),
            });
        }
        let db = v as u32;
        if db != fingerprint {
            return Err(CodecError::DatabaseMismatch {
                codec: NAME,
                stream: db,
                given: fingerprint,
            });
        }
        Ok(PrimitiveSettings {
            t_l: real_param(NAME, p, keys::T_L, 1e-4, 1.0)?,
            upper_ratio: real_param(NAME, p, keys::UPPER_RATIO, 1.0, 10.0)?,
            smooth: int_param(NAME, p, keys::SMOOTH, 0, 16)? as usize,
            step_floor: real_param(NAME, p, keys::STEP_FLOOR, 0.0, 4.0)?,
            normalized: int_param(NAME, p, keys::NORMALIZED, 0, 1)? == 1,
            db,
        })
    }

    /// The parameters a stream records (every key but [`keys::CR`]).
    fn to_params(self) -> Params {
        params_of(&[
            (keys::T_L, self.t_l),
            (keys::UPPER_RATIO, self.upper_ratio),
            (keys::SMOOTH, self.smooth as f64),
            (keys::STEP_FLOOR, self.step_floor),
            (keys::NORMALIZED, f64::from(u8::from(self.normalized))),
            (keys::DB, f64::from(self.db)),
        ])
    }

    /// The threshold `t_j` of joint `joint`: `t_L` on the legs, `t_U` elsewhere.
    fn threshold(self, skeleton: &Skeleton, joint: usize) -> f64 {
        if skeleton.joints[joint].body_part.is_leg() {
            self.t_l
        } else {
            self.upper_ratio * self.t_l
        }
    }
}

/// Adaptive models of the payload.
struct Models {
    len: UintModel,
    index: Vec<UintModel>,
    coded: Vec<BitModel>,
    normalized: Vec<BitModel>,
    step: IntModel,
    nnz: UintModel,
    run: [UintModel; BANDS],
    value: [IntModel; BANDS],
    mean: IntModel,
    t_step: IntModel,
    t_nnz: UintModel,
    t_run: [UintModel; BANDS],
    t_value: [IntModel; BANDS],
}

impl Models {
    fn new(joints: usize) -> Models {
        Models {
            len: UintModel::default(),
            index: vec![UintModel::default(); joints],
            coded: vec![BitModel::default(); joints],
            normalized: vec![BitModel::default(); joints],
            step: IntModel::default(),
            nnz: UintModel::default(),
            run: std::array::from_fn(|_| UintModel::default()),
            value: std::array::from_fn(|_| IntModel::default()),
            mean: IntModel::default(),
            t_step: IntModel::default(),
            t_nnz: UintModel::default(),
            t_run: std::array::from_fn(|_| UintModel::default()),
            t_value: std::array::from_fn(|_| IntModel::default()),
        }
    }
}

/// Band index of every coefficient of a `channels × len` block (coarse to fine per channel).
fn band_map(len: usize, channels: usize) -> Vec<u8> {
    let mut one = Vec::new();
    for (b, &n) in band_lengths(len, LEVELS).iter().enumerate() {
        one.extend(std::iter::repeat_n(b as u8, n));
    }
    let mut out = Vec::with_capacity(one.len() * channels);
    for _ in 0..channels {
        out.extend_from_slice(&one);
    }
    out
}

/// Band maps by segment length, built on first use.
#[derive(Default)]
struct BandCache(BTreeMap<(usize, usize), Vec<u8>>);

impl BandCache {
    fn get(&mut self, len: usize, channels: usize) -> &[u8] {
        self.0
            .entry((len, channels))
            .or_insert_with(|| band_map(len, channels))
    }
}

/// What "within the threshold" means for one joint.
struct Check<'a> {
    format: SkeletonFormat,
    axes: &'a [Axis],
    /// Three distinct rotation axes: the channels hold any rotation.
    full: bool,
    /// `cos²(t_j/2)`: `d(a, b) ≤ t_j` ⇔ `(a·b)² ≥ cos²(t_j/2)` for unit quaternions, since
    /// eq. 5.3's `acos(2(a·b)² − 1)` is `2·acos(|a·b|)`.
    cos2: f64,
    /// Smallest quantizer step exponent the threshold calls for (`step ≥ t_j·step_floor`).
    step_floor_exp: i64,
    /// The threshold `t_j` in radians.
    t_rad: f64,
}

impl Check<'_> {
    fn new<'a>(skeleton: &'a Skeleton, axes: &'a [Axis], t_rad: f64, step_floor: f64) -> Check<'a> {
        let half = 0.5 * t_rad.min(std::f64::consts::PI);
        let step_floor_exp = if step_floor > 0.0 {
            ((8.0 * (t_rad * step_floor).log2()).floor() as i64).clamp(STEP_MIN, STEP_MAX)
        } else {
            STEP_MIN
        };
        Check {
            format: skeleton.format,
            axes,
            full: matches!(axes, [x, y, z] if x != y && y != z && x != z),
            cos2: half.cos().powi(2),
            step_floor_exp,
            t_rad,
        }
    }

    /// The largest eq. 5.3 distance between `out` (as the clip holds it) and `src`.
    fn largest_distance(&self, out: &[Quat], src: &[Quat]) -> f64 {
        out.iter()
            .zip(src)
            .map(|(o, s)| {
                let o = if self.full {
                    *o
                } else {
                    project_to_channels(self.format, self.axes, *o)
                };
                o.distance(*s)
            })
            .fold(0.0, f64::max)
    }

    fn within(&self, out: &[Quat], src: &[Quat]) -> bool {
        out.iter().zip(src).all(|(o, s)| {
            let o = if self.full {
                *o
            } else {
                project_to_channels(self.format, self.axes, *o)
            };
            let d = o.dot(*s);
            d * d >= self.cos2
        })
    }
}

/// Scratch buffers of the difference coder, reused across segments.
#[derive(Debug)]
struct Work {
    transform: Transform,
    coef: Vec<f64>,
    order: Vec<usize>,
    q: Vec<i64>,
    signal: Vec<f64>,
    deq: Vec<f64>,
    chan: [Vec<f64>; 3],
    reference: Vec<Quat>,
    out: Vec<Quat>,
    /// The reference at the 16 normalized frames (the primitive, or the held rotation).
    reference16: Primitive,
    /// A reconstruction at the 16 normalized frames.
    out16: Vec<Quat>,
    /// `log(reference⁻¹·source)` per frame of the segment being coded.
    logs: Vec<[f64; 3]>,
    /// One channel's coefficients.
    one: Vec<f64>,
}

impl Work {
    fn new() -> Work {
        Work {
            transform: Transform::new(Wavelet::Cdf97),
            coef: Vec::new(),
            order: Vec::new(),
            q: Vec::new(),
            signal: Vec::new(),
            deq: Vec::new(),
            chan: [Vec::new(), Vec::new(), Vec::new()],
            reference: Vec::new(),
            out: Vec::new(),
            reference16: [Quat::IDENTITY; NORMALIZED_FRAMES],
            out16: Vec::new(),
            logs: Vec::new(),
            one: Vec::new(),
        }
    }
}

fn step_of(exp: i64) -> f64 {
    (exp as f64 / 8.0).exp2()
}

/// The smallest step exponent whose step keeps `max_abs` within 10 bits.
fn step_exp_for(max_abs: f64) -> i64 {
    if !(max_abs > 0.0 && max_abs.is_finite()) {
        return 0;
    }
    let s = (8.0 * (max_abs / QUANT_MAX).log2()).ceil();
    (s as i64).clamp(STEP_MIN, STEP_MAX)
}

/// `reference[m]·exp(v(m))` for the dequantized coefficients `q·step`: the decoder's
/// reconstruction of a coded segment (the encoder runs the same code when it searches).
fn reconstruct(
    transform: &mut Transform,
    chan: &mut [Vec<f64>; 3],
    deq: &mut Vec<f64>,
    q: &[i64],
    step: f64,
    reference: &[Quat],
    out: &mut Vec<Quat>,
) {
    let len = reference.len();
    let n = q.len() / 3;
    for (c, ch) in chan.iter_mut().enumerate() {
        deq.clear();
        deq.extend(q[c * n..(c + 1) * n].iter().map(|&v| v as f64 * step));
        // The block always has coefficient_count(len, LEVELS) values per channel.
        if transform.inverse(deq, len, LEVELS, ch).is_err() {
            ch.clear();
            ch.resize(len, 0.0);
        }
    }
    out.clear();
    out.extend(
        reference
            .iter()
            .enumerate()
            .map(|(m, r)| (*r * Quat::exp([chan[0][m], chan[1][m], chan[2][m]])).normalized()),
    );
}

/// The frames a difference is coded at.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Grid {
    /// The segment's own frames, against `Work::reference`.
    Own,
    /// The 16 normalized frames, against `Work::reference16`; the reconstruction is then
    /// denormalized (SLERP) to the segment's length.
    Normalized,
}

impl Grid {
    /// Frames of the coded block for a segment of `len` frames.
    fn frames(self, len: usize) -> usize {
        match self {
            Grid::Own => len,
            Grid::Normalized => NORMALIZED_FRAMES,
        }
    }
}

/// The decoder's reconstruction of a coded `len`-frame segment from `w.q` at `step` on
/// `grid`, into `w.out` (the encoder runs the same code when it searches).
fn rebuild(w: &mut Work, grid: Grid, step: f64, len: usize) {
    match grid {
        Grid::Own => reconstruct(
            &mut w.transform,
            &mut w.chan,
            &mut w.deq,
            &w.q,
            step,
            &w.reference,
            &mut w.out,
        ),
        Grid::Normalized => {
            reconstruct(
                &mut w.transform,
                &mut w.chan,
                &mut w.deq,
                &w.q,
                step,
                &w.reference16,
                &mut w.out16,
            );
            let n: Primitive = std::array::from_fn(|i| w.out16[i]);
            denormalize(&n, len, &mut w.out);
        }
    }
}

/// Codes `(run, value)` pairs of the nonzero entries of `q` after their count.
fn put_sparse(
    enc: &mut RangeEncoder,
    nnz_model: &mut UintModel,
    run: &mut [UintModel; BANDS],
    value: &mut [IntModel; BANDS],
    q: &[i64],
    bands: &[u8],
) -> Result<(), EntropyError> {
    let nnz = q.iter().filter(|&&v| v != 0).count();
    nnz_model.encode(enc, nnz as u32)?;
    let mut pos = 0;
    for (i, &v) in q.iter().enumerate() {
        if v != 0 {
            run[usize::from(bands[pos])].encode(enc, (i - pos) as u32)?;
            value[usize::from(bands[i])].encode(enc, v)?;
            pos = i + 1;
        }
    }
    Ok(())
}

/// Reads what [`put_sparse`] wrote into `q` (zeroed first, length fixed by the caller).
fn get_sparse(
    dec: &mut RangeDecoder<'_>,
    nnz_model: &mut UintModel,
    run: &mut [UintModel; BANDS],
    value: &mut [IntModel; BANDS],
    q: &mut [i64],
    bands: &[u8],
) -> Result<(), &'static str> {
    q.fill(0);
    let nnz = nnz_model.decode(dec).ok_or("coefficient count")? as usize;
    if nnz > q.len() {
        return Err("more coefficients than the block has");
    }
    let mut pos = 0;
    for _ in 0..nnz {
        let r = run[usize::from(bands[pos.min(q.len() - 1)])]
            .decode(dec)
            .ok_or("zero run")? as usize;
        let i = pos
            .checked_add(r)
            .filter(|&i| i < q.len())
            .ok_or("zero run past the block")?;
        let v = value[usize::from(bands[i])]
            .decode(dec)
            .ok_or("coefficient")?;
        if v == 0 || v.abs() > VALUE_LIMIT {
            return Err("coefficient value out of range");
        }
        q[i] = v;
        pos = i + 1;
    }
    Ok(())
}

impl PrimitiveCodec {
    /// The codec with a primitive database (the decoder must be given the same one).
    pub fn new(db: Arc<Database>) -> PrimitiveCodec {
        let fingerprint = db.fingerprint();
        let joints = db
            .joints
            .iter()
            .map(|j| {
                let prims = j
                    .primitives
                    .iter()
                    .map(|p| {
                        let mut p = *p;
                        for q in &mut p {
                            *q = q.normalized();
                        }
                        p
                    })
                    .collect();
                (j.joint.clone(), prims)
            })
            .collect();
        PrimitiveCodec {
            db: Some(db),
            fingerprint,
            joints,
        }
    }

    /// The codec without a database: listed, but every encode and decode is refused with
    /// [`CodecError::NoDatabase`].
    pub fn without_database() -> PrimitiveCodec {
        PrimitiveCodec {
            db: None,
            fingerprint: 0,
            joints: BTreeMap::new(),
        }
    }

    /// The database, if any.
    pub fn database(&self) -> Option<&Arc<Database>> {
        self.db.as_ref()
    }

    /// The database's fingerprint ([`Database::fingerprint`]), if there is a database.
    pub fn fingerprint(&self) -> Option<u32> {
        self.db.as_ref().map(|_| self.fingerprint)
    }

    fn require_db(&self) -> Result<&Database, CodecError> {
        self.db
            .as_deref()
            .ok_or(CodecError::NoDatabase { codec: NAME })
    }

    fn primitives_of(&self, name: &str) -> &[Primitive] {
        self.joints.get(name).map_or(&[], Vec::as_slice)
    }

    fn enc_err(e: &EntropyError) -> CodecError {
        CodecError::Payload {
            codec: NAME,
            offset: 0,
            detail: e.to_string(),
        }
    }

    /// Encodes with settings `s`: every rotation joint's segments, then the translation
    /// channels' windows, in one range-coded payload.
    fn encode_native(&self, clip: &Clip, s: &PrimitiveSettings) -> Result<Bitstream, CodecError> {
        self.encode_prepared(clip, &self.prepare(clip)?, s)
    }

    /// Steps 1-2 of the module docs, which do not depend on the thresholds: each rotation
    /// joint's quaternion track, its segments, their nearest primitives and those
    /// primitives denormalized to the segments' lengths.
    fn prepare(&self, clip: &Clip) -> Result<Prepared, CodecError> {
        let db = self.require_db()?;
        let qc = to_quaternions(clip);
        let skeleton = &clip.skeleton;
        let mut joints = Vec::with_capacity(qc.joints.len());
        let mut one = Vec::new();
        for (&j, track) in qc.joints.iter().zip(qc.rotations) {
            let prims = self.primitives_of(&skeleton.joints[j].name);
            let segments = segment_track(&track, clip.frame_rate_hz, db.segment);
            let mut nearest_primitive = Vec::new();
            let mut reference = Vec::new();
            if !prims.is_empty() {
                nearest_primitive.reserve(segments.len());
                reference.reserve(track.len());
                for seg in &segments {
                    let idx = nearest(prims, &seg.normalized);
                    denormalize(&prims[idx], seg.len(), &mut one);
                    nearest_primitive.push(idx);
                    reference.extend_from_slice(&one);
                }
            }
            joints.push(PreparedJoint {
                joint: j,
                track,
                segments,
                nearest: nearest_primitive,
                reference,
            });
        }
        Ok(Prepared { joints })
    }

    /// Encodes `clip`, prepared as `prep`, with settings `s`.
    fn encode_prepared(
        &self,
        clip: &Clip,
        prep: &Prepared,
        s: &PrimitiveSettings,
    ) -> Result<Bitstream, CodecError> {
        self.encode_measured(clip, prep, s, None).map(|(b, _)| b)
    }

    /// Encodes `clip` with `params` and measures what each part of the stream costs and how
    /// far each segment's reference is from the source (`docs/primitive-codec.md`).
    ///
    /// # Errors
    /// As [`Codec::encode`]; a `cr` target is refused (measure at a `t_l`).
    pub fn costs(&self, clip: &Clip, params: &Params) -> Result<(Bitstream, Costs), CodecError> {
        self.require_db()?;
        let p = merged(self, params)?;
        let s = PrimitiveSettings::from_params(&p, self.fingerprint)?;
        if p.get(keys::CR).copied().unwrap_or(0.0) > 0.0 {
            return Err(CodecError::Param {
                codec: NAME,
                key: keys::CR.into(),
                value: p[keys::CR],
                detail: "costs are measured at a given t_l".into(),
            });
        }
        let (b, c) =
            self.encode_measured(clip, &self.prepare(clip)?, &s, Some(Costs::default()))?;
        Ok((b, c.unwrap_or_default()))
    }

    /// [`PrimitiveCodec::encode_prepared`], measuring into `costs` when given.
    fn encode_measured(
        &self,
        clip: &Clip,
        prep: &Prepared,
        s: &PrimitiveSettings,
        costs: Option<Costs>,
    ) -> Result<(Bitstream, Option<Costs>), CodecError> {
        let skeleton = &clip.skeleton;
        let max_len = self.require_db()?.segment.max_frames;
        let mut e = PayloadEncoder {
            enc: RangeEncoder::new(),
            m: Models::new(prep.joints.len()),
            w: Work::new(),
            bands: BandCache::default(),
            costs,
        };
        for (k, pj) in prep.joints.iter().enumerate() {
            let prims = self.primitives_of(&skeleton.joints[pj.joint].name);
            let axes = rotation_axes(skeleton, pj.joint);
            let check = Check::new(
                skeleton,
                &axes,
                s.threshold(skeleton, pj.joint),
                s.step_floor,
            );
            e.joint(k, prims, &check, pj, s.normalized, max_len)?;
        }
        for (c, ch) in clip.channels().iter().enumerate() {
            if !ch.kind.is_rotation() {
                e.translation(clip, c)?;
            }
        }
        let costs = e.costs.take();
        Ok((header(self, clip, s.to_params(), e.enc.finish())?, costs))
    }
}

/// What [`PrimitiveCodec::prepare`] makes of a clip: one entry per rotation joint.
struct Prepared {
    joints: Vec<PreparedJoint>,
}

/// One rotation joint of a [`Prepared`] clip.
struct PreparedJoint {
    /// The joint (skeleton index).
    joint: usize,
    /// Its rotation per frame.
    track: Vec<Quat>,
    /// Its segments (they tile the track).
    segments: Vec<Segment>,
    /// Per segment, the nearest primitive (eq. 5.4); empty when the database has none for
    /// the joint (its segments are coded against the held rotation).
    nearest: Vec<usize>,
    /// Per frame, the nearest primitive of its segment denormalized to the segment's length;
    /// empty as `nearest` is.
    reference: Vec<Quat>,
}

/// An entropy-coder result as a codec error.
fn coded(r: Result<(), EntropyError>) -> Result<(), CodecError> {
    r.map_err(|e| PrimitiveCodec::enc_err(&e))
}

/// The encoder's range coder, models and buffers.
struct PayloadEncoder {
    enc: RangeEncoder,
    m: Models,
    w: Work,
    bands: BandCache,
    /// What each part costs, when measured ([`PrimitiveCodec::costs`]).
    costs: Option<Costs>,
}

/// What each part of a `primitive` stream costs, and how the references fit
/// ([`PrimitiveCodec::costs`]; the measurements of `docs/primitive-codec.md`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Costs {
    /// Rotation segments (joints × segments).
    pub segments: usize,
    /// Segments with a coded difference.
    pub coded: usize,
    /// Coded segments whose difference is on the 16 normalized frames.
    pub normalized: usize,
    /// Nonzero coefficients over every coded difference.
    pub coefficients: usize,
    /// Rotation segments as long as the database's `S_M` allows.
    pub at_max: usize,
    /// Frames over every rotation segment.
    pub segment_frames: usize,
    /// Bits of each part, indexed by [`Part`].
    pub bits: [f64; Part::COUNT],
    /// Per rotation segment, the largest eq. 5.3 distance between its reference (the
    /// primitive at the segment's length, or the held rotation) and the source, over the
    /// joint's threshold `t_j`: at most 1 where nothing needs coding.
    pub reference_error: Vec<f64>,
}

/// The parts of a `primitive` stream [`Costs::bits`] counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// Segment lengths.
    Length,
    /// Primitive indices.
    Index,
    /// "Coded" flags.
    Flag,
    /// Quantizer steps of the differences.
    Step,
    /// Coefficient counts, zero runs and values of the differences.
    Coefficients,
    /// The translation channels.
    Translation,
}

impl Part {
    /// Number of parts.
    pub const COUNT: usize = 6;
    /// Every part, in [`Costs::bits`] order.
    pub const ALL: [Part; Part::COUNT] = [
        Part::Length,
        Part::Index,
        Part::Flag,
        Part::Step,
        Part::Coefficients,
        Part::Translation,
    ];

    /// A short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Part::Length => "lengths",
            Part::Index => "indices",
            Part::Flag => "flags",
            Part::Step => "steps",
            Part::Coefficients => "coefficients",
            Part::Translation => "translation",
        }
    }
}

impl PayloadEncoder {
    /// Charges what was coded since the reading `since` of [`RangeEncoder::bits`] to `part`.
    fn charge(&mut self, part: Part, since: f64) {
        if let Some(c) = &mut self.costs {
            c.bits[part as usize] += self.enc.bits() - since;
        }
    }

    /// Steps 1-4 of the module docs for each segment of the `k`-th rotation joint `pj`
    /// (with `prims` primitives, its threshold in `check`): the length, the nearest
    /// primitive (or the held rotation), and the difference where the primitive misses `t_j`.
    fn joint(
        &mut self,
        k: usize,
        prims: &[Primitive],
        check: &Check<'_>,
        pj: &PreparedJoint,
        normalized: bool,
        max_len: usize,
    ) -> Result<(), CodecError> {
        let mut hold = Quat::IDENTITY;
        let mut prev_step = 0i64;
        for (n, seg) in pj.segments.iter().enumerate() {
            let len = seg.len();
            let t = self.enc.bits();
            coded(self.m.len.encode(&mut self.enc, (len - 1) as u32))?;
            self.charge(Part::Length, t);
            self.w.reference.clear();
            if let Some(&idx) = pj.nearest.get(n) {
                self.w.reference16 = prims[idx];
                if prims.len() > 1 {
                    let t = self.enc.bits();
                    coded(self.m.index[k].encode(&mut self.enc, idx as u32))?;
                    self.charge(Part::Index, t);
                }
                self.w
                    .reference
                    .extend_from_slice(&pj.reference[seg.start..seg.end]);
            } else {
                self.w.reference.resize(len, hold);
                self.w.reference16 = [hold; NORMALIZED_FRAMES];
            }
            let src = &pj.track[seg.start..seg.end];
            if let Some(c) = &mut self.costs {
                c.segments += 1;
                c.segment_frames += len;
                c.at_max += usize::from(len == max_len);
                c.reference_error
                    .push(check.largest_distance(&self.w.reference, src) / check.t_rad);
            }
            let t = self.enc.bits();
            if check.within(&self.w.reference, src) {
                self.enc.bit(&mut self.m.coded[k], false);
                self.charge(Part::Flag, t);
                hold = self.w.reference[len - 1];
                continue;
            }
            self.enc.bit(&mut self.m.coded[k], true);
            // The normalized grid where the 16 frames hold the segment within t_j (they
            // cannot where resampling alone moves a frame further: then the own frames).
            let grid = if normalized {
                denormalize(&seg.normalized, len, &mut self.w.out);
                let fits = check.within(&self.w.out, src);
                self.enc.bit(&mut self.m.normalized[k], fits);
                if fits { Grid::Normalized } else { Grid::Own }
            } else {
                Grid::Own
            };
            self.charge(Part::Flag, t);
            let step_exp = code_difference(&mut self.w, src, &seg.normalized, check, grid);
            let t = self.enc.bits();
            coded(self.m.step.encode(&mut self.enc, step_exp - prev_step))?;
            self.charge(Part::Step, t);
            prev_step = step_exp;
            let b = self.bands.get(grid.frames(len), 3);
            let m = &mut self.m;
            let t = self.enc.bits();
            coded(put_sparse(
                &mut self.enc,
                &mut m.nnz,
                &mut m.run,
                &mut m.value,
                &self.w.q,
                b,
            ))?;
            self.charge(Part::Coefficients, t);
            if let Some(c) = &mut self.costs {
                c.coded += 1;
                c.normalized += usize::from(grid == Grid::Normalized);
                c.coefficients += self.w.q.iter().filter(|&&v| v != 0).count();
            }
            hold = self.w.out[len - 1];
        }
        Ok(())
    }

    /// Translation channel `c` of `clip`, window by window of [`ROOT_WINDOW`] frames.
    fn translation(&mut self, clip: &Clip, c: usize) -> Result<(), CodecError> {
        let t = self.enc.bits();
        self.translation_windows(clip, c)?;
        self.charge(Part::Translation, t);
        Ok(())
    }

    /// [`PayloadEncoder::translation`] without the measuring.
    fn translation_windows(&mut self, clip: &Clip, c: usize) -> Result<(), CodecError> {
        let (frames, x) = (clip.frames(), clip.channel(c));
        let mut prev = Previous::default();
        let mut start = 0;
        while start < frames {
            let end = (start + ROOT_WINDOW).min(frames);
            let win = &x[start..end];
            let mean = win.iter().sum::<f64>() / win.len() as f64;
            let mq = (mean * MEAN_SCALE).round();
            if !mq.is_finite() || mq.abs() >= MEAN_LIMIT as f64 {
                return Err(CodecError::Param {
                    codec: NAME,
                    key: clip.channel_name(c),
                    value: mean,
                    detail: "translation beyond the format's range".into(),
                });
            }
            self.translation_window(win, mq as i64, &mut prev)?;
            start = end;
        }
        Ok(())
    }

    /// One translation window `win` with quantized mean `mq`: the mean (change), then the
    /// largest 50 % of its wavelet coefficients at 10 bits (thesis 5.4) and their step.
    fn translation_window(
        &mut self,
        win: &[f64],
        mq: i64,
        prev: &mut Previous,
    ) -> Result<(), CodecError> {
        coded(self.m.mean.encode(&mut self.enc, mq - prev.mean))?;
        prev.mean = mq;
        let base = mq as f64 / MEAN_SCALE;
        let w = &mut self.w;
        w.signal.clear();
        w.signal.extend(win.iter().map(|v| v - base));
        w.transform.forward(&w.signal, LEVELS, &mut w.coef);
        let n = w.coef.len();
        w.order.clear();
        w.order.extend(0..n);
        w.order
            .sort_unstable_by(|&a, &b| w.coef[b].abs().total_cmp(&w.coef[a].abs()));
        // Thesis 5.4: the smallest 50 % of the coefficients are zeroed.
        let keep = n - n / 2;
        let step_exp = step_exp_for(w.coef[w.order[0]].abs());
        let step = step_of(step_exp);
        w.q.clear();
        w.q.resize(n, 0);
        for &i in &w.order[..keep] {
            w.q[i] = (w.coef[i] / step).round() as i64;
        }
        let b = self.bands.get(win.len(), 1);
        let m = &mut self.m;
        coded(put_sparse(
            &mut self.enc,
            &mut m.t_nnz,
            &mut m.t_run,
            &mut m.t_value,
            &self.w.q,
            b,
        ))?;
        if self.w.q.iter().any(|&v| v != 0) {
            coded(self.m.t_step.encode(&mut self.enc, step_exp - prev.step))?;
            prev.step = step_exp;
        }
        Ok(())
    }
}

/// The previous translation window's quantized mean and step exponent, which a window's are
/// coded against.
#[derive(Debug, Default)]
struct Previous {
    mean: i64,
    step: i64,
}

/// Index of the primitive nearest to a normalized segment (eq. 5.4).
fn nearest(prims: &[Primitive], seg: &Primitive) -> usize {
    let mut best = (0, f64::INFINITY);
    for (k, p) in prims.iter().enumerate() {
        let d = segment_distance(p, seg);
        if d < best.1 {
            best = (k, d);
        }
    }
    best.0
}

/// Codes the difference of `src` to `w.reference` (see the module docs): fills `w.q` with the
/// quantized coefficients and `w.out` with the reconstruction; returns the step exponent.
fn code_difference(
    w: &mut Work,
    src: &[Quat],
    normalized: &Primitive,
    check: &Check<'_>,
    grid: Grid,
) -> i64 {
    let len = src.len();
    w.coef.clear();
    w.logs.clear();
    let (reference, target): (&[Quat], &[Quat]) = match grid {
        Grid::Own => (&w.reference, src),
        Grid::Normalized => (&w.reference16, normalized),
    };
    w.logs.extend(
        reference
            .iter()
            .zip(target)
            .map(|(r, q)| (r.conj() * *q).log()),
    );
    for c in 0..3 {
        w.signal.clear();
        w.signal.extend(w.logs.iter().map(|l| l[c]));
        w.transform.forward(&w.signal, LEVELS, &mut w.one);
        w.coef.extend_from_slice(&w.one);
    }
    let n = w.coef.len();
    w.order.clear();
    w.order.extend(0..n);
    w.order
        .sort_unstable_by(|&a, &b| w.coef[b].abs().total_cmp(&w.coef[a].abs()));
    // 10 bits of the largest coefficient, or coarser where the threshold allows.
    let mut step_exp = step_exp_for(w.coef[w.order[0]].abs()).max(check.step_floor_exp);
    // Keeps the `kept` largest coefficients at `step_exp` and reconstructs into `w.out`.
    let try_keep = |w: &mut Work, kept: usize, step_exp: i64| -> bool {
        let step = step_of(step_exp);
        w.q.clear();
        w.q.resize(n, 0);
        for &i in &w.order[..kept] {
            w.q[i] = (w.coef[i] / step).round() as i64;
        }
        rebuild(w, grid, step, len);
        check.within(&w.out, src)
    };
    // Finer steps only when even every coefficient at this step misses the bound (tiny t_j).
    while !try_keep(w, n, step_exp) && step_exp > STEP_MIN {
        step_exp = (step_exp - 8).max(STEP_MIN);
    }
    // Bisection on the count kept: `hi` always meets the bound (or is `n` when nothing
    // does), `lo` never does.
    let (mut lo, mut hi) = (0, n);
    // Whether `w` holds the coding of `hi` (the last try kept `n`, or the last bisection
    // step met the bound), so that it need not be tried again.
    let mut holds_hi = true;
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        holds_hi = try_keep(w, mid, step_exp);
        if holds_hi {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    if !holds_hi {
        try_keep(w, hi, step_exp);
    }
    debug_assert_eq!(w.out.len(), len);
    step_exp
}

/// Thesis 5.3.4 smoothing of the join at frame `e` of `track` between a segment starting at
/// `s0` and one ending at `e1`, over at most `m` frames each side.
fn smooth_join(track: &mut [Quat], s0: usize, e: usize, e1: usize, m: usize) {
    let mm = m.min((e - s0) / 2).min((e1 - e) / 2);
    if mm == 0 {
        return;
    }
    // The closest pair of the distance map between A = Q1's tail and B = Q2's head.
    let (mut x, mut y, mut best) = (e - 1, e, f64::INFINITY);
    for a in e - mm..e {
        for b in e..e + mm {
            let d = track[a].distance(track[b]);
            if d < best {
                (x, y, best) = (a, b, d);
            }
        }
    }
    let (qa, qb) = (track[x], track[y]);
    let span = (y - x) as f64;
    for (k, q) in track.iter_mut().enumerate().take(y).skip(x + 1) {
        *q = qa.slerp(qb, (k - x) as f64 / span);
    }
}

impl Codec for PrimitiveCodec {
    fn name(&self) -> &'static str {
        NAME
    }

    fn id(&self) -> u8 {
        ID
    }

    fn description(&self) -> &'static str {
        "thesis ch. 5: primitive database + incremental CDF 9/7 difference, t_L knob (needs --db)"
    }

    fn default_params(&self) -> Params {
        let mut p = PrimitiveSettings::defaults(self.fingerprint).to_params();
        p.insert(keys::CR.to_string(), 0.0);
        p
    }

    fn rate_control(&self) -> RateControl {
        RateControl::SearchIncreasing {
            key: keys::T_L,
            min: 1e-4,
            max: 1.0,
            // ln CR grows by 0.4-0.55 per ln t_L between 8:1 and 40:1 on the shared clips.
            slope: 0.5,
        }
    }

    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError> {
        self.require_db()?;
        let p = merged(self, params)?;
        let s = PrimitiveSettings::from_params(&p, self.fingerprint)?;
        // The rate search sets the knob (t_L) itself: the settings are read per encode it runs.
        let target = p.get(keys::CR).copied().unwrap_or(0.0);
        if target > 0.0 {
            return crate::rate::search(self, clip, &p, target).map(|s| s.stream);
        }
        self.encode_native(clip, &s)
    }

    /// Prepares the clip once (`PrimitiveCodec::prepare`: quaternions, segments, nearest
    /// primitives) for every `t_l` the search tries.
    fn rate_encoder<'a>(&'a self, clip: &'a Clip) -> Result<RateEncoder<'a>, CodecError> {
        let prep = self.prepare(clip)?;
        Ok(Box::new(move |params: &Params| {
            let p = merged(self, params)?;
            let s = PrimitiveSettings::from_params(&p, self.fingerprint)?;
            if p.get(keys::CR).copied().unwrap_or(0.0) > 0.0 {
                return self.encode(clip, params);
            }
            self.encode_prepared(clip, &prep, &s)
        }))
    }

    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
        check_stream(self, stream, skeleton)?;
        let db = self.require_db()?;
        let mut p = self.default_params();
        // A stream must name its database: no default.
        p.insert(keys::DB.into(), f64::NAN);
        // Streams from before `normalized` existed code every difference at its own length.
        p.insert(keys::NORMALIZED.into(), 0.0);
        p.extend(stream.params.iter().map(|(k, v)| (k.clone(), *v)));
        let s = PrimitiveSettings::from_params(&p, self.fingerprint)?;
        let frames = stream.frames as usize;
        let joints = rotation_joints(skeleton);
        let mut d = PayloadDecoder {
            dec: RangeDecoder::new(&stream.payload),
            m: Models::new(joints.len()),
            w: Work::new(),
            bands: BandCache::default(),
        };
        let mut rotations = Vec::with_capacity(joints.len());
        let mut cuts = Vec::new();
        for (k, &j) in joints.iter().enumerate() {
            let prims = self.primitives_of(&skeleton.joints[j].name);
            let mut track = d.joint(k, prims, frames, &s, db.segment.max_frames, &mut cuts)?;
            if s.smooth > 0 {
                cuts.push(frames);
                for c in cuts.windows(3) {
                    smooth_join(&mut track, c[0], c[1], c[2], s.smooth);
                }
            }
            rotations.push(track);
        }
        let mut data = vec![0.0; skeleton.channel_count() * frames];
        for (c, ch) in skeleton.channel_layout().iter().enumerate() {
            if !ch.kind.is_rotation() {
                d.translation(&mut data[c * frames..(c + 1) * frames])?;
            }
        }
        if d.dec.overrun() != 0 || d.dec.position() != stream.payload.len() {
            return Err(d.corrupt("payload length does not match its content"));
        }
        let source = Clip::new(skeleton.clone(), stream.frame_rate_hz, frames, data)?;
        Ok(from_quaternions(&QuatClip {
            source,
            joints,
            rotations,
        }))
    }
}

/// The decoder's range decoder, models and buffers: the mirror of [`PayloadEncoder`].
struct PayloadDecoder<'a> {
    dec: RangeDecoder<'a>,
    m: Models,
    w: Work,
    bands: BandCache,
}

impl PayloadDecoder<'_> {
    /// A corrupt payload at the decoder's position.
    fn corrupt(&self, detail: &str) -> CodecError {
        CodecError::Payload {
            codec: NAME,
            offset: self.dec.position(),
            detail: detail.to_string(),
        }
    }

    /// Mirror of [`PayloadEncoder::joint`]: the `k`-th rotation joint's `frames` rotations,
    /// segment by segment (at most `max_len` frames each); `cuts` gets each segment's first
    /// frame.
    fn joint(
        &mut self,
        k: usize,
        prims: &[Primitive],
        frames: usize,
        s: &PrimitiveSettings,
        max_len: usize,
        cuts: &mut Vec<usize>,
    ) -> Result<Vec<Quat>, CodecError> {
        let mut track: Vec<Quat> = Vec::with_capacity(frames);
        let mut hold = Quat::IDENTITY;
        let mut prev_step = 0i64;
        cuts.clear();
        while track.len() < frames {
            let len = self
                .m
                .len
                .decode(&mut self.dec)
                .ok_or_else(|| self.corrupt("segment length"))? as usize
                + 1;
            if len > max_len || track.len() + len > frames {
                return Err(self.corrupt("segment longer than S_M or the clip"));
            }
            let held = self.reference(k, prims, hold)?;
            cuts.push(track.len());
            let coded = self.dec.bit(&mut self.m.coded[k]);
            let grid = if coded && s.normalized && self.dec.bit(&mut self.m.normalized[k]) {
                Grid::Normalized
            } else {
                Grid::Own
            };
            // A difference on the 16 frames does not need the reference at the segment's
            // length: it is denormalized only for the other two cases.
            if grid == Grid::Own {
                if held {
                    self.w.reference.clear();
                    self.w.reference.resize(len, hold);
                } else {
                    denormalize(&self.w.reference16, len, &mut self.w.reference);
                }
            }
            if coded {
                self.difference(len, grid, &mut prev_step)?;
                track.extend_from_slice(&self.w.out);
            } else {
                track.extend_from_slice(&self.w.reference);
            }
            hold = track[track.len() - 1];
            if self.dec.overrun() > OVERRUN_LIMIT {
                return Err(self.corrupt("payload ends early"));
            }
        }
        Ok(track)
    }

    /// A segment's reference at the 16 normalized frames into `w.reference16`: the coded
    /// primitive, or `hold` held for a joint the database does not know (then `true`).
    fn reference(&mut self, k: usize, prims: &[Primitive], hold: Quat) -> Result<bool, CodecError> {
        if prims.is_empty() {
            self.w.reference16 = [hold; NORMALIZED_FRAMES];
            return Ok(true);
        }
        let idx = if prims.len() > 1 {
            self.m.index[k]
                .decode(&mut self.dec)
                .ok_or_else(|| self.corrupt("primitive index"))? as usize
        } else {
            0
        };
        let prim = prims
            .get(idx)
            .ok_or_else(|| self.corrupt("primitive index beyond the database"))?;
        self.w.reference16 = *prim;
        Ok(false)
    }

    /// A coded difference of a `len`-frame segment on `grid`: its step (change from
    /// `prev_step`) and coefficients, reconstructed against the reference into `w.out`.
    fn difference(
        &mut self,
        len: usize,
        grid: Grid,
        prev_step: &mut i64,
    ) -> Result<(), CodecError> {
        let ds = self
            .m
            .step
            .decode(&mut self.dec)
            .ok_or_else(|| self.corrupt("step"))?;
        let step_exp = prev_step.saturating_add(ds);
        if !(STEP_MIN..=STEP_MAX).contains(&step_exp) {
            return Err(self.corrupt("quantizer step out of range"));
        }
        *prev_step = step_exp;
        let b = self.bands.get(grid.frames(len), 3);
        let (m, w) = (&mut self.m, &mut self.w);
        w.q.clear();
        w.q.resize(b.len(), 0);
        if let Err(d) = get_sparse(
            &mut self.dec,
            &mut m.nnz,
            &mut m.run,
            &mut m.value,
            &mut w.q,
            b,
        ) {
            return Err(self.corrupt(d));
        }
        rebuild(w, grid, step_of(step_exp), len);
        Ok(())
    }

    /// Mirror of [`PayloadEncoder::translation`]: one translation channel's row `out`.
    fn translation(&mut self, out: &mut [f64]) -> Result<(), CodecError> {
        let frames = out.len();
        let mut prev = Previous::default();
        let mut start = 0;
        while start < frames {
            let end = (start + ROOT_WINDOW).min(frames);
            self.translation_window(&mut out[start..end], &mut prev)?;
            if self.dec.overrun() > OVERRUN_LIMIT {
                return Err(self.corrupt("payload ends early"));
            }
            start = end;
        }
        Ok(())
    }

    /// Mirror of [`PayloadEncoder::translation_window`] into `out`.
    fn translation_window(
        &mut self,
        out: &mut [f64],
        prev: &mut Previous,
    ) -> Result<(), CodecError> {
        let dm = self
            .m
            .mean
            .decode(&mut self.dec)
            .ok_or_else(|| self.corrupt("translation mean"))?;
        let mq = prev.mean.saturating_add(dm);
        if mq.abs() > MEAN_LIMIT {
            return Err(self.corrupt("translation mean out of range"));
        }
        prev.mean = mq;
        let b = self.bands.get(out.len(), 1);
        let (m, w) = (&mut self.m, &mut self.w);
        w.q.clear();
        w.q.resize(b.len(), 0);
        if let Err(d) = get_sparse(
            &mut self.dec,
            &mut m.t_nnz,
            &mut m.t_run,
            &mut m.t_value,
            &mut w.q,
            b,
        ) {
            return Err(self.corrupt(d));
        }
        let base = mq as f64 / MEAN_SCALE;
        if !self.w.q.iter().any(|&v| v != 0) {
            out.fill(base);
            return Ok(());
        }
        let ds = self
            .m
            .t_step
            .decode(&mut self.dec)
            .ok_or_else(|| self.corrupt("translation step"))?;
        let step_exp = prev.step.saturating_add(ds);
        if !(STEP_MIN..=STEP_MAX).contains(&step_exp) {
            return Err(self.corrupt("quantizer step out of range"));
        }
        prev.step = step_exp;
        let step = step_of(step_exp);
        let w = &mut self.w;
        w.deq.clear();
        w.deq.extend(w.q.iter().map(|&v| v as f64 * step));
        if let Err(e) = w
            .transform
            .inverse(&w.deq, out.len(), LEVELS, &mut w.signal)
        {
            return Err(self.corrupt(&e.to_string()));
        }
        for (o, v) in out.iter_mut().zip(&self.w.signal) {
            *o = base + v;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The settings read back what they record, the defaults are the default parameters, and
    /// a stream of another database is refused before any other key is read.
    #[test]
    fn settings_round_trip_through_params() {
        let c = PrimitiveCodec::without_database();
        let mut defaults = c.default_params();
        assert_eq!(defaults.remove(keys::CR), Some(0.0));
        let s = PrimitiveSettings::from_params(&defaults, 0).unwrap();
        assert_eq!(s, PrimitiveSettings::defaults(0));
        assert_eq!(s.to_params(), defaults);
        let other = PrimitiveSettings {
            t_l: 0.02,
            upper_ratio: 3.0,
            smooth: 4,
            step_floor: 0.0,
            normalized: true,
            db: 0xDEAD_BEEF,
        };
        let p = other.to_params();
        assert_eq!(
            PrimitiveSettings::from_params(&p, 0xDEAD_BEEF).unwrap(),
            other
        );
        let mut bad = p.clone();
        bad.insert(keys::T_L.into(), 5.0);
        assert!(matches!(
            PrimitiveSettings::from_params(&bad, 1),
            Err(CodecError::DatabaseMismatch {
                stream: 0xDEAD_BEEF,
                given: 1,
                ..
            })
        ));
    }
}
