//! The primitive database (thesis ch. 5.3.3) and its file format.
//!
//! Training: per joint, the normalized segments of every training clip are clustered by a
//! k-means++ variant in quaternion-segment space. The distance between segments is the largest
//! per-frame quaternion distance (eq. 5.3-5.4); a cluster's centre is built by weighted SLERP,
//! adding each member with weight 1 against the centre's weight M (the members so far); K
//! starts at 5 and grows until the clustering error (eq. 5.6, the largest member-to-centre
//! distance) is below the bound (0.01 rad) or K reaches 25. Seeding uses a SplitMix64 stream
//! from the given seed, so training is reproducible.
//!
//! File (little-endian): magic `MOCAPPDB`, format version `u32`, body length `u64`, body, then
//! CRC-32 of everything before it. Body: segment `min_frames u32`, `max_frames u32`, joint count
//! `u32`, and per joint: name length `u16` + UTF-8 name, K `u32`, clustering error `f64`
//! (radians), training segment count `u32`, then K × 16 quaternions as four `f32` (w, x, y, z).
//! Centres are rounded to `f32` when trained, so a database read back is the one that was
//! trained, bit for bit. Every count is checked against limits and the bytes present before
//! anything is allocated.

use std::path::{Path, PathBuf};

use crate::primitives::segment::{NORMALIZED_FRAMES, SegmentParams, segment_track};
use motion::clip::Clip;
use motion::quat::{Quat, to_quaternions};

/// Current database file version.
pub const DATABASE_VERSION: u32 = 1;
const MAGIC: &[u8; 8] = b"MOCAPPDB";
const MAX_JOINTS: u32 = 1024;
const MAX_PRIMITIVES: u32 = 4096;
const MAX_NAME: u16 = 256;

/// A normalized segment: 16 unit quaternions.
pub type Primitive = [Quat; NORMALIZED_FRAMES];

/// Training parameters (defaults: the thesis's values).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainParams {
    /// First K tried (5).
    pub k_start: usize,
    /// Largest K (25).
    pub k_max: usize,
    /// Clustering error bound in radians (0.01).
    pub error_bound_rad: f64,
    /// Segmentation of the training clips.
    pub segment: SegmentParams,
    /// Seed of the k-means++ seeding.
    pub seed: u64,
    /// Assignment passes per K before giving up on convergence.
    pub max_passes: usize,
}

impl Default for TrainParams {
    fn default() -> Self {
        TrainParams {
            k_start: 5,
            k_max: 25,
            error_bound_rad: 0.01,
            segment: SegmentParams::default(),
            seed: 0x5EED,
            max_passes: 10,
        }
    }
}

/// The primitives of one joint.
#[derive(Debug, Clone, PartialEq)]
pub struct JointPrimitives {
    /// Joint name, as in the training skeleton.
    pub joint: String,
    /// Cluster centres.
    pub primitives: Vec<Primitive>,
    /// Clustering error reached, radians (eq. 5.6).
    pub error_rad: f64,
    /// Number of training segments.
    pub segments: usize,
}

/// A trained primitive database.
#[derive(Debug, Clone, PartialEq)]
pub struct Database {
    /// Segmentation the database was trained with (the codec must segment alike).
    pub segment: SegmentParams,
    /// Per-joint primitives.
    pub joints: Vec<JointPrimitives>,
}

/// Why a database file could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DatabaseError {
    /// The file could not be read.
    #[error("{path}: {err}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        err: std::io::Error,
    },
    /// The file could not be written, or exists and was not to be replaced.
    #[error(transparent)]
    File(#[from] files::Error),
    /// Not a primitive database.
    #[error("{path}: not a primitive database (bad magic)")]
    BadMagic {
        /// The file.
        path: PathBuf,
    },
    /// A version this build cannot read.
    #[error(
        "{path}: database format version {version} is not supported (this build reads {DATABASE_VERSION})"
    )]
    Version {
        /// The file.
        path: PathBuf,
        /// Version found.
        version: u32,
    },
    /// Fewer bytes than the structure needs.
    #[error("{path}: truncated at byte {offset}: {what}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Byte offset.
        offset: usize,
        /// What was being read.
        what: String,
    },
    /// The checksum does not match: the file is corrupt.
    #[error(
        "{path}: checksum mismatch (stored {stored:08x}, computed {computed:08x}): the file is corrupt"
    )]
    Checksum {
        /// The file.
        path: PathBuf,
        /// CRC in the file.
        stored: u32,
        /// CRC of the bytes.
        computed: u32,
    },
    /// A count or value outside what the format allows.
    #[error("{path}: byte {offset}: {what}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Byte offset.
        offset: usize,
        /// What is wrong.
        what: String,
    },
}

/// Largest per-frame distance between two normalized segments (eq. 5.4).
pub fn segment_distance(a: &Primitive, b: &Primitive) -> f64 {
    // acos is decreasing, so the largest per-frame distance acos(2(q1·q2)² − 1) is the acos
    // of the smallest argument: one acos per segment pair instead of sixteen (the codec's
    // nearest-primitive search runs this K times per segment).
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let d = x.dot(*y);
            2.0 * d * d - 1.0
        })
        .fold(1.0, f64::min)
        .clamp(-1.0, 1.0)
        .acos()
}

/// SplitMix64: a tiny, well-known, seedable generator for reproducible seeding.
pub(crate) struct SplitMix(pub(crate) u64);

impl SplitMix {
    /// The next value, uniform in `[0, 1)`.
    pub(crate) fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn nearest(centres: &[Primitive], s: &Primitive) -> (usize, f64) {
    let mut best = (0, f64::INFINITY);
    for (k, c) in centres.iter().enumerate() {
        let d = segment_distance(c, s);
        if d < best.1 {
            best = (k, d);
        }
    }
    best
}

fn weighted_centre(members: impl Iterator<Item = Primitive>) -> Option<Primitive> {
    let mut centre: Option<Primitive> = None;
    let mut m = 0.0;
    for s in members {
        centre = Some(match centre {
            None => s,
            Some(mut c) => {
                // Weight M for the centre, 1 for the new segment (ch. 5.3.3).
                for (ci, si) in c.iter_mut().zip(&s) {
                    *ci = ci.slerp(*si, 1.0 / (m + 1.0));
                }
                c
            }
        });
        m += 1.0;
    }
    centre
}

/// Clusters `segs` into `k` primitives; returns the centres and the clustering error.
fn cluster(
    segs: &[Primitive],
    k: usize,
    params: &TrainParams,
    rng: &mut SplitMix,
) -> (Vec<Primitive>, f64) {
    if segs.len() <= k {
        return (segs.to_vec(), 0.0);
    }
    let mut centres: Vec<Primitive> = kmeanspp_seeds(segs.len(), k, rng, |a, b| {
        segment_distance(&segs[a], &segs[b]).powi(2)
    })
    .into_iter()
    .map(|i| segs[i])
    .collect();
    let mut assign = vec![usize::MAX; segs.len()];
    for _ in 0..params.max_passes.max(1) {
        let mut changed = false;
        for (i, s) in segs.iter().enumerate() {
            let (k, _) = nearest(&centres, s);
            changed |= assign[i] != k;
            assign[i] = k;
        }
        for (c, centre) in centres.iter_mut().enumerate() {
            let members = segs
                .iter()
                .zip(&assign)
                .filter(|(_, a)| **a == c)
                .map(|(s, _)| *s);
            if let Some(new) = weighted_centre(members) {
                *centre = new;
            }
        }
        if !changed {
            break;
        }
    }
    let error = segs
        .iter()
        .map(|s| nearest(&centres, s).1)
        .fold(0.0, f64::max);
    (centres, error)
}

/// k-means++ seeding (AV07) of `k` of `n` items (`k ≤ n`, `n ≥ 1`): the first uniformly, each
/// next one with probability ∝ `d2(seed, i)`, item `i`'s squared distance to the seed nearest
/// it so far (uniformly again once every item sits on a seed). Returns the seeds' indices.
pub(crate) fn kmeanspp_seeds(
    n: usize,
    k: usize,
    rng: &mut SplitMix,
    d2: impl Fn(usize, usize) -> f64,
) -> Vec<usize> {
    let uniform = |rng: &mut SplitMix| ((rng.next_f64() * n as f64) as usize).min(n - 1);
    let first = uniform(rng);
    let mut seeds = vec![first];
    let mut near: Vec<f64> = (0..n).map(|i| d2(first, i)).collect();
    while seeds.len() < k {
        let total: f64 = near.iter().sum();
        let pick = if total > 0.0 {
            let mut r = rng.next_f64() * total;
            let mut idx = n - 1;
            for (i, d) in near.iter().enumerate() {
                if r < *d {
                    idx = i;
                    break;
                }
                r -= d;
            }
            idx
        } else {
            uniform(rng)
        };
        seeds.push(pick);
        for (i, d) in near.iter_mut().enumerate() {
            *d = d.min(d2(pick, i));
        }
    }
    seeds
}

fn round_f32(p: &Primitive) -> Primitive {
    let mut out = *p;
    for q in &mut out {
        let r = |v: f64| f64::from(v as f32);
        *q = Quat {
            w: r(q.w),
            x: r(q.x),
            y: r(q.y),
            z: r(q.z),
        };
    }
    out
}

impl Database {
    /// Trains a database on clips. Joints are matched across clips by name; `progress` is
    /// called after each joint with (joints done, joints in all).
    pub fn train(
        clips: &[&Clip],
        params: &TrainParams,
        mut progress: impl FnMut(usize, usize),
    ) -> Database {
        let mut per_joint: Vec<(String, Vec<Primitive>)> = Vec::new();
        for clip in clips {
            let qc = to_quaternions(clip);
            for (k, &j) in qc.joints.iter().enumerate() {
                let name = &clip.skeleton.joints[j].name;
                let segs = segment_track(&qc.rotations[k], clip.frame_rate_hz, params.segment);
                let i = if let Some(i) = per_joint.iter().position(|(n, _)| n == name) {
                    i
                } else {
                    per_joint.push((name.clone(), Vec::new()));
                    per_joint.len() - 1
                };
                per_joint[i]
                    .1
                    .extend(segs.into_iter().map(|s| s.normalized));
            }
        }
        let total = per_joint.len();
        let mut rng = SplitMix(params.seed);
        let mut joints = Vec::with_capacity(total);
        for (done, (joint, segs)) in per_joint.into_iter().enumerate() {
            let mut k = params.k_start.max(1);
            let (mut centres, mut error) = cluster(&segs, k, params, &mut rng);
            while error >= params.error_bound_rad && k < params.k_max && k < segs.len() {
                k += 1;
                (centres, error) = cluster(&segs, k, params, &mut rng);
            }
            let primitives: Vec<Primitive> = centres.iter().map(round_f32).collect();
            let error_rad = segs
                .iter()
                .map(|s| nearest(&primitives, s).1)
                .fold(0.0, f64::max);
            joints.push(JointPrimitives {
                joint,
                primitives,
                error_rad,
                segments: segs.len(),
            });
            progress(done + 1, total);
        }
        Database {
            segment: params.segment,
            joints,
        }
    }

    /// The primitives of joint `name`.
    pub fn joint(&self, name: &str) -> Option<&JointPrimitives> {
        self.joints.iter().find(|j| j.joint == name)
    }

    /// The file bytes (see the module docs).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend_from_slice(&(self.segment.min_frames as u32).to_le_bytes());
        body.extend_from_slice(&(self.segment.max_frames as u32).to_le_bytes());
        body.extend_from_slice(&(self.joints.len() as u32).to_le_bytes());
        for j in &self.joints {
            let name = j.joint.as_bytes();
            body.extend_from_slice(&(name.len() as u16).to_le_bytes());
            body.extend_from_slice(name);
            body.extend_from_slice(&(j.primitives.len() as u32).to_le_bytes());
            body.extend_from_slice(&j.error_rad.to_le_bytes());
            body.extend_from_slice(&(j.segments as u32).to_le_bytes());
            for p in &j.primitives {
                for q in p {
                    for v in [q.w, q.x, q.y, q.z] {
                        body.extend_from_slice(&(v as f32).to_le_bytes());
                    }
                }
            }
        }
        let mut out = Vec::with_capacity(body.len() + 24);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&DATABASE_VERSION.to_le_bytes());
        out.extend_from_slice(&(body.len() as u64).to_le_bytes());
        out.extend_from_slice(&body);
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// The database's fingerprint: the CRC-32 of its file bytes (what a bitstream records).
    pub fn fingerprint(&self) -> u32 {
        let bytes = self.to_bytes();
        let n = bytes.len();
        u32::from_le_bytes([bytes[n - 4], bytes[n - 3], bytes[n - 2], bytes[n - 1]])
    }

    /// Parses database bytes; `path` names the source in errors.
    ///
    /// # Errors
    /// [`DatabaseError`] for a wrong magic or version, a checksum mismatch, truncation, or
    /// counts beyond the format's limits.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Database, DatabaseError> {
        let mut r = Reader {
            bytes,
            pos: 0,
            path,
        };
        let magic = r.take(8, "magic")?;
        if magic != MAGIC {
            return Err(DatabaseError::BadMagic {
                path: path.to_path_buf(),
            });
        }
        let version = r.u32("version")?;
        if version != DATABASE_VERSION {
            return Err(DatabaseError::Version {
                path: path.to_path_buf(),
                version,
            });
        }
        let body_len = r.u64("body length")?;
        let needed = 20u64.saturating_add(body_len).saturating_add(4);
        if needed != bytes.len() as u64 {
            return Err(DatabaseError::Invalid {
                path: path.to_path_buf(),
                offset: 12,
                what: format!(
                    "body length {body_len} does not match the file size {}",
                    bytes.len()
                ),
            });
        }
        let n = bytes.len();
        let stored = u32::from_le_bytes([bytes[n - 4], bytes[n - 3], bytes[n - 2], bytes[n - 1]]);
        let computed = crc32fast::hash(&bytes[..n - 4]);
        if stored != computed {
            return Err(DatabaseError::Checksum {
                path: path.to_path_buf(),
                stored,
                computed,
            });
        }
        let min_frames = r.u32("min_frames")? as usize;
        let max_frames = r.u32("max_frames")? as usize;
        if min_frames == 0 || max_frames < min_frames || max_frames > 1 << 16 {
            return Err(r.invalid(format!(
                "segment bounds {min_frames}..{max_frames} are not valid"
            )));
        }
        let count = r.u32("joint count")?;
        if count > MAX_JOINTS {
            return Err(r.invalid(format!("{count} joints exceeds the limit of {MAX_JOINTS}")));
        }
        let mut joints = Vec::with_capacity(count as usize);
        for _ in 0..count {
            joints.push(r.joint()?);
        }
        if r.remaining() != 4 {
            return Err(r.invalid("bytes left after the last joint".into()));
        }
        Ok(Database {
            segment: SegmentParams {
                min_frames,
                max_frames,
            },
            joints,
        })
    }

    /// Writes the database file, whole or not at all ([`files::write`]); an existing file is
    /// replaced only with [`files::Mode::Replace`].
    ///
    /// # Errors
    /// [`DatabaseError::File`] when the file cannot be written or exists under
    /// [`files::Mode::New`].
    pub fn write(&self, path: &Path, mode: files::Mode) -> Result<(), DatabaseError> {
        Ok(files::write(path, self.to_bytes(), mode)?)
    }

    /// Reads a database file.
    ///
    /// # Errors
    /// [`DatabaseError`] as for [`Database::from_bytes`], or when the file cannot be read.
    pub fn read(path: &Path) -> Result<Database, DatabaseError> {
        let bytes = std::fs::read(path).map_err(|err| DatabaseError::Io {
            path: path.to_path_buf(),
            err,
        })?;
        Database::from_bytes(&bytes, path)
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], DatabaseError> {
        if n > self.remaining() {
            return Err(DatabaseError::Truncated {
                path: self.path.to_path_buf(),
                offset: self.pos,
                what: what.to_string(),
            });
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N], DatabaseError> {
        let s = self.take(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    fn u16(&mut self, what: &str) -> Result<u16, DatabaseError> {
        Ok(u16::from_le_bytes(self.array(what)?))
    }

    fn u32(&mut self, what: &str) -> Result<u32, DatabaseError> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }

    fn u64(&mut self, what: &str) -> Result<u64, DatabaseError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    /// One joint's record (see the module docs).
    fn joint(&mut self) -> Result<JointPrimitives, DatabaseError> {
        let len = self.u16("name length")?;
        if len > MAX_NAME {
            return Err(self.invalid(format!("joint name of {len} bytes exceeds {MAX_NAME}")));
        }
        let name = std::str::from_utf8(self.take(len as usize, "joint name")?)
            .map_err(|_| self.invalid("joint name is not UTF-8".into()))?
            .to_string();
        let k = self.u32("primitive count")?;
        let error_rad = f64::from_le_bytes(self.array("clustering error")?);
        let segments = self.u32("segment count")? as usize;
        let per = NORMALIZED_FRAMES * 16;
        if k > MAX_PRIMITIVES || (k as usize) * per > self.remaining() {
            return Err(self.invalid(format!(
                "{k} primitives for {name} exceed the limit or the bytes present"
            )));
        }
        if !error_rad.is_finite() || error_rad < 0.0 {
            return Err(self.invalid(format!(
                "clustering error {error_rad} of {name} is not valid"
            )));
        }
        let mut primitives = Vec::with_capacity(k as usize);
        for _ in 0..k {
            let mut p = [Quat::IDENTITY; NORMALIZED_FRAMES];
            for q in &mut p {
                let mut v = [0.0; 4];
                for x in &mut v {
                    *x = f64::from(f32::from_le_bytes(self.array("quaternion")?));
                }
                *q = Quat {
                    w: v[0],
                    x: v[1],
                    y: v[2],
                    z: v[3],
                };
                let norm = q.dot(*q);
                if !norm.is_finite() || (norm - 1.0).abs() >= 1e-3 {
                    return Err(
                        self.invalid(format!("a primitive of {name} is not a unit quaternion"))
                    );
                }
            }
            primitives.push(p);
        }
        Ok(JointPrimitives {
            joint: name,
            primitives,
            error_rad,
            segments,
        })
    }

    fn invalid(&self, what: String) -> DatabaseError {
        DatabaseError::Invalid {
            path: self.path.to_path_buf(),
            offset: self.pos,
            what,
        }
    }
}

/// Index and distance of the primitive nearest to a segment.
pub fn nearest_primitive(joint: &JointPrimitives, seg: &Primitive) -> Option<(usize, f64)> {
    if joint.primitives.is_empty() {
        return None;
    }
    Some(nearest(&joint.primitives, seg))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn walk() -> Clip {
        motion::synth::walking_clip(&motion::synth::WalkParams::default())
    }

    #[test]
    fn training_meets_the_error_bound_or_stops_at_k_max() {
        let clip = walk();
        let params = TrainParams::default();
        let db = Database::train(&[&clip], &params, |_, _| {});
        assert!(!db.joints.is_empty());
        for j in &db.joints {
            let k = j.primitives.len();
            assert!(
                j.error_rad < params.error_bound_rad || k == params.k_max || k == j.segments,
                "{}: K = {k}, error {}",
                j.joint,
                j.error_rad
            );
            assert!(k >= params.k_start.min(j.segments));
        }
    }

    #[test]
    fn bytes_round_trip_and_corruption_is_detected() {
        let clip = walk();
        let params = TrainParams {
            k_max: 8,
            ..TrainParams::default()
        };
        let db = Database::train(&[&clip], &params, |_, _| {});
        let bytes = db.to_bytes();
        let p = Path::new("walk.pdb");
        assert_eq!(Database::from_bytes(&bytes, p).unwrap(), db);
        let mut bad = bytes.clone();
        bad[40] ^= 1;
        assert!(matches!(
            Database::from_bytes(&bad, p),
            Err(DatabaseError::Checksum { .. })
        ));
        let e = Database::from_bytes(&bytes[..bytes.len() - 9], p)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("walk.pdb") && e.contains("does not match the file size"),
            "{e}"
        );
        assert!(matches!(
            Database::from_bytes(b"NOTADB..", p),
            Err(DatabaseError::BadMagic { .. })
        ));
        // The same training gives the same database (seeded), hence the same fingerprint.
        assert_eq!(
            Database::train(&[&clip], &params, |_, _| {}).fingerprint(),
            db.fingerprint()
        );
    }

    #[test]
    fn a_training_segment_is_near_its_primitive() {
        let clip = walk();
        let db = Database::train(&[&clip], &TrainParams::default(), |_, _| {});
        let qc = to_quaternions(&clip);
        let k = qc
            .joints
            .iter()
            .position(|&j| clip.skeleton.joints[j].name == "lfemur")
            .unwrap();
        let segs = segment_track(&qc.rotations[k], clip.frame_rate_hz, db.segment);
        let jp = db.joint("lfemur").unwrap();
        for s in &segs {
            let (_, d) = nearest_primitive(jp, &s.normalized).unwrap();
            assert!(d <= jp.error_rad + 1e-9);
        }
    }
}
