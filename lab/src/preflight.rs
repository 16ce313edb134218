//! Preflight: every stimulus a study's plan can show, checked before any subject sees
//! anything (`study check`, `study simulate`, and the study window before Begin).
//!
//! A stimulus file deleted from a sweep folder, or cut short, would otherwise be found only
//! when its trial comes up, in the middle of a session. For each stimulus the plan can show
//! (MOS / DSCQS: every condition and familiarization stimulus and its reference, every
//! character of a crowd scene against the same character of the reference scene; a staircase:
//! every track's reference and every level's stimulus), the checks are:
//! - its files exist (motion file, ASF skeleton, bitstream), and the motion file parses;
//! - a test stimulus matches its reference: the same skeleton (joints, parents, channels,
//!   rest geometry), frame count and frame rate;
//! - its bitstream, when the manifest names one, is a valid container for that skeleton,
//!   frame count and rate, and decodes (with the codec its header names) to as many frames as
//!   the file holds. A `primitive` stream needs its database, which a stimulus manifest does
//!   not name: its container is checked, and it is counted as not decoded;
//! - its files are the ones the manifest was written with: their SHA-256 equal the
//!   manifest's `sha256` and `bitstream_sha256` where it records them (`study sweep` and
//!   `study crowd` do), so a file changed or swapped with another stimulus' since is found;
//! - its `bytes` and `achieved_cr` are its bitstream's (`4 × channels × frames / bytes`);
//! - a compressed stimulus is not byte-identical to its reference's file unless its metrics
//!   say it has no error (a lossless codec): otherwise the subject would be shown the
//!   reference twice while the analysis counts a compressed stimulus.
//!
//! A live staircase encodes per trial: its decoder context and reference clips are read
//! ([`LiveStimuli::from_study`]), and every clip is encoded and decoded once at the first
//! track's start level, which proves the codec takes the settings.
//!
//! Every problem is returned at once, each naming its file; nothing here draws or writes.

use std::collections::{HashMap, HashSet};
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use codecs::bitstream::Bitstream;
use codecs::codec::{self, CodecContext, CodecError};
use motion::{Clip, Skeleton};
use protocols::StudyError;
use protocols::manifest::Stimulus;

use crate::error::{LabError, Result, chain, refused};
use crate::live::LiveStimuli;
use crate::study::StudyFile;

/// One problem of one stimulus.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Problem {
    /// The file at fault (a live staircase's problems name the study file).
    pub file: PathBuf,
    /// Which stimulus (`stimulus "walk/spiht/cr20"`) or, for a live staircase, which key of
    /// the study file (`staircase.live.clips[0]`).
    pub about: String,
    /// What is wrong, starting with the file.
    pub message: String,
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ({})", self.message, self.about)
    }
}

/// What a preflight checked.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Checked {
    /// Stimuli checked (references included; live: the source clips).
    pub stimuli: usize,
    /// Bitstreams decoded.
    pub decoded: usize,
    /// Bitstreams whose container was checked but that could not be decoded without a
    /// decoder context the manifest does not name (a `primitive` database).
    pub not_decoded: usize,
    /// Live levels encoded and decoded (one per clip of a live staircase).
    pub encoded: usize,
}

impl fmt::Display for Checked {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.encoded > 0 {
            return write!(
                f,
                "{} source clips read, each encoded and decoded at the start level",
                self.stimuli
            );
        }
        write!(
            f,
            "{} stimuli read and matched to their references, {} bitstreams decoded",
            self.stimuli, self.decoded
        )?;
        if self.not_decoded > 0 {
            write!(
                f,
                ", {} checked without decoding (no primitive database)",
                self.not_decoded
            )?;
        }
        Ok(())
    }
}

/// The stimulus ids the plan of `study` can show, each with the reference it is shown
/// against (`None` for a reference), in plan order, each once; a crowd scene stands for its
/// characters' stimuli. Empty for a live staircase.
pub fn shown(study: &StudyFile) -> Vec<(String, Option<String>)> {
    let def = &study.definition;
    let mut out: Vec<(String, Option<String>)> = Vec::new();
    let mut seen = HashSet::new();
    let mut add = |id: &str, reference: Option<&str>| {
        if seen.insert(id.to_string()) {
            out.push((id.to_string(), reference.map(str::to_string)));
        }
    };
    for c in def.familiarization.iter().chain(&def.conditions) {
        // A crowd scene is its characters' stimuli, each against the same character's
        // stimulus in the reference scene.
        let scenes = def
            .manifest
            .get(&c.stimulus)
            .and_then(|s| s.scene.as_ref())
            .zip(
                def.manifest
                    .get(&c.reference)
                    .and_then(|s| s.scene.as_ref()),
            );
        if let Some((test, reference)) = scenes {
            for (t, r) in test.characters.iter().zip(&reference.characters) {
                add(&r.stimulus, None);
                add(&t.stimulus, Some(&r.stimulus));
            }
            continue;
        }
        add(&c.reference, None);
        add(&c.stimulus, Some(&c.reference));
    }
    if let Some(sc) = def.staircase.as_ref().filter(|s| s.live.is_none()) {
        for t in &sc.tracks {
            add(&t.reference, None);
            for (_, id) in &t.levels {
                add(id, Some(&t.reference));
            }
        }
    }
    out
}

/// How many steps [`check`] reports progress over for `study`.
pub fn steps(study: &StudyFile) -> usize {
    match study
        .definition
        .staircase
        .as_ref()
        .and_then(|s| s.live.as_ref())
    {
        Some(live) => live.clips.len() + 1,
        None => shown(study).len(),
    }
}

/// Checks every stimulus the plan of `study` can show; `progress(done, total)` is called
/// after each. Returns what was checked and every problem found.
pub fn check(study: &StudyFile, progress: &dyn Fn(usize, usize)) -> (Checked, Vec<Problem>) {
    let (checked, problems, _) = check_keeping(study, progress);
    (checked, problems)
}

/// The clips a preflight read, by stimulus id, in [`shown`] order.
pub type Clips = Vec<(String, Arc<Clip>)>;

/// [`check`], keeping the clips it read (those that could be read; none for a live
/// staircase, whose stimuli are made per trial): a runner that wants every stimulus in
/// memory before its first trial need not read them a second time.
pub fn check_keeping(
    study: &StudyFile,
    progress: &dyn Fn(usize, usize),
) -> (Checked, Vec<Problem>, Clips) {
    if study
        .definition
        .staircase
        .as_ref()
        .is_some_and(|s| s.live.is_some())
    {
        let (checked, problems) = check_live(study, progress);
        return (checked, problems, Vec::new());
    }
    let base = study.manifest_dir();
    let ids = shown(study);
    let total = ids.len();
    let mut checked = Checked::default();
    let mut problems = Vec::new();
    // Clips read so far (None: could not be read, already reported), and their files' SHA-256.
    let mut clips: HashMap<String, Option<Arc<Clip>>> = HashMap::new();
    let mut hashes: HashMap<String, String> = HashMap::new();
    let ctx = CodecContext::default();
    let manifest_basis = study.definition.manifest.cr_basis;
    for (done, (id, reference)) in ids.iter().enumerate() {
        let Some(st) = study.definition.manifest.get(id) else {
            // The study loader checks every id against the manifest.
            continue;
        };
        checked.stimuli += 1;
        let clip = read(&base, st, &mut problems).map(Arc::new);
        let file = base.join(&st.file);
        if clip.is_some() {
            let hash = hashed(&file, st.sha256.as_deref(), id, &mut problems);
            if let Some(h) = &hash {
                hashes.insert(id.clone(), h.clone());
            }
            if let (Some(h), Some(r)) = (&hash, reference)
                && hashes.get(r) == Some(h)
                && let Some(why) = same_as_reference(st)
            {
                problems.push(problem(
                    &file,
                    id,
                    format!("is byte-identical to the file of its reference {r:?}{why}"),
                ));
            }
        }
        if let (Some(clip), Some(r)) = (&clip, reference)
            && let Some(Some(reference)) = clips.get(r)
        {
            for message in mismatch(clip, reference, r) {
                problems.push(problem(&file, id, message));
            }
        }
        if let (Some(clip), Some(stream)) = (&clip, &st.bitstream) {
            let path = base.join(stream);
            match bitstream(&path, clip, &ctx) {
                Ok(decoded) => {
                    if decoded {
                        checked.decoded += 1;
                    } else {
                        checked.not_decoded += 1;
                    }
                    hashed(&path, st.bitstream_sha256.as_deref(), id, &mut problems);
                    for message in sizes(&path, clip, st, manifest_basis) {
                        problems.push(problem(&path, id, message));
                    }
                }
                Err(message) => problems.push(problem(&path, id, message)),
            }
        } else if clip.is_none()
            && let Some(stream) = &st.bitstream
        {
            let path = base.join(stream);
            if !path.is_file() {
                problems.push(problem(&path, id, missing("bitstream")));
            }
        }
        clips.insert(id.clone(), clip);
        progress(done + 1, total);
    }
    let kept = ids
        .into_iter()
        .filter_map(|(id, _)| {
            let clip = clips.remove(&id).flatten()?;
            Some((id, clip))
        })
        .collect();
    (checked, problems, kept)
}

/// [`check`] as one result: what was checked, or every problem in one error that names the
/// manifest and lists each problem with its file.
///
/// # Errors
/// [`LabError::Refused`] listing every problem.
pub fn verify(study: &StudyFile, progress: &dyn Fn(usize, usize)) -> Result<Checked> {
    verify_keeping(study, progress).map(|(checked, _)| checked)
}

/// [`verify`], keeping the clips it read ([`check_keeping`]).
///
/// # Errors
/// As [`verify`].
pub fn verify_keeping(
    study: &StudyFile,
    progress: &dyn Fn(usize, usize),
) -> Result<(Checked, Clips)> {
    let (checked, problems, clips) = check_keeping(study, progress);
    if problems.is_empty() {
        return Ok((checked, clips));
    }
    Err(refused(describe(study, &problems)))
}

/// The problems as one message: the manifest, how many, one line each.
pub fn describe(study: &StudyFile, problems: &[Problem]) -> String {
    let manifest = study.dir().join(&study.definition.stimuli_path);
    let mut text = format!(
        "{}: {} stimulus problem(s), found before any trial:",
        manifest.display(),
        problems.len()
    );
    for p in problems {
        text.push_str("\n  ");
        text.push_str(&p.to_string());
    }
    text
}

fn problem(file: &Path, id: &str, message: String) -> Problem {
    let shown = file.display().to_string();
    Problem {
        file: file.to_path_buf(),
        about: format!("stimulus {id:?}"),
        message: if message.starts_with(&shown) {
            message
        } else {
            format!("{shown}: {message}")
        },
    }
}

fn missing(what: &str) -> String {
    format!("missing (the manifest's {what})")
}

/// Reads a stimulus' clip, reporting missing and unreadable files.
fn read(base: &Path, st: &Stimulus, problems: &mut Vec<Problem>) -> Option<Clip> {
    let file = base.join(&st.file);
    let skeleton = st.skeleton.as_ref().map(|s| base.join(s));
    let mut ok = true;
    if !file.is_file() {
        problems.push(problem(&file, &st.id, missing("file")));
        ok = false;
    }
    if let Some(s) = &skeleton
        && !s.is_file()
    {
        problems.push(problem(s, &st.id, missing("skeleton")));
        ok = false;
    }
    if !ok {
        return None;
    }
    match motion::io::read_clip(skeleton.as_deref(), &file) {
        Ok(clip) => Some(clip),
        Err(e) => {
            problems.push(problem(&file, &st.id, chain(&e)));
            None
        }
    }
}

/// Largest joint error, cm, below which a compressed stimulus may be byte-identical to its
/// reference: a lossless codec's, or one whose error is below the digits the clip file keeps.
const IDENTICAL_MAX_CM: f64 = 1e-3;

/// The SHA-256 of the file at `path`, a problem where it is not `want` (the manifest's);
/// `None` where it cannot be read (reported by the reader).
fn hashed(
    path: &Path,
    want: Option<&str>,
    id: &str,
    problems: &mut Vec<Problem>,
) -> Option<String> {
    let got = crate::stimulus::sha256_file(path).ok()?;
    if let Some(want) = want
        && want != got
    {
        problems.push(problem(
            path,
            id,
            format!(
                "its content is not the file the manifest was written with (SHA-256 {}…, the \
                 manifest's {}…): changed, or swapped with another file, since",
                &got[..12],
                want.get(..12).unwrap_or(want)
            ),
        ));
    }
    Some(got)
}

/// Why a compressed stimulus must not be byte-identical to its reference (`None`: a
/// reference, or metrics that say it has no error).
fn same_as_reference(st: &Stimulus) -> Option<String> {
    if st.codec == protocols::manifest::REFERENCE_CODEC {
        return None;
    }
    match &st.metrics {
        Some(m) if m.max_cm <= IDENTICAL_MAX_CM => None,
        Some(m) => Some(format!(
            ", while the manifest gives it a largest error of {} cm: the subject would see the \
             reference where the analysis counts {} (a file copied or swapped)",
            m.max_cm, st.codec
        )),
        None => Some(format!(
            ": the subject would see the reference where the analysis counts {} (metrics \
             that say it has no error mark a lossless stimulus)",
            st.codec
        )),
    }
}

/// Where the manifest's `bytes` or `achieved_cr` are not the bitstream's at `path` (read
/// already: it parsed), its CR counted on the manifest's `basis`.
fn sizes(
    path: &Path,
    clip: &Clip,
    st: &Stimulus,
    basis: protocols::manifest::CrBasis,
) -> Vec<String> {
    let Ok(size) = std::fs::metadata(path).map(|m| m.len()) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    if st.bytes != size {
        out.push(format!(
            "bytes: the manifest says {}, the bitstream file holds {size}",
            st.bytes
        ));
    }
    let counting = crate::sweep::codec_basis(basis);
    let channels = match counting.channels(&clip.skeleton) {
        Ok(n) => n,
        Err(e) => {
            out.push(format!("achieved_cr: {e}"));
            return out;
        }
    };
    let raw = 4.0 * channels as f64 * clip.frames() as f64;
    let cr = raw / size.max(1) as f64;
    if st.achieved_cr.is_none_or(|a| (a - cr).abs() > 1e-6 * cr) {
        out.push(format!(
            "achieved_cr: the manifest says {}, the bitstream gives {cr:.4} (4 bytes × {channels} \
             channels ({} basis) × {} frames / {size} bytes)",
            st.achieved_cr
                .map_or_else(|| "null (unknown)".to_string(), |a| a.to_string()),
            counting.name(),
            clip.frames()
        ));
    }
    out
}

/// How `clip` differs from its reference: skeleton, frame count, frame rate.
pub(crate) fn mismatch(clip: &Clip, reference: &Clip, reference_id: &str) -> Vec<String> {
    let mut out = Vec::new();
    if let Some(why) = skeleton_difference(&clip.skeleton, &reference.skeleton) {
        out.push(format!(
            "its skeleton is not its reference's ({reference_id}): {why}"
        ));
    }
    if clip.frames() != reference.frames() {
        out.push(format!(
            "{} frames, its reference ({reference_id}) has {}",
            clip.frames(),
            reference.frames()
        ));
    }
    if !same_number(clip.frame_rate_hz, reference.frame_rate_hz) {
        out.push(format!(
            "{} Hz, its reference ({reference_id}) is {} Hz",
            clip.frame_rate_hz, reference.frame_rate_hz
        ));
    }
    out
}

fn same_number(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).max(1.0)
}

/// Why two skeletons are not the same one (a file written with limited precision reads back
/// within 1e-4 of its rest geometry), if they are not.
fn skeleton_difference(a: &Skeleton, b: &Skeleton) -> Option<String> {
    if a.joints.len() != b.joints.len() {
        return Some(format!("{} joints, not {}", a.joints.len(), b.joints.len()));
    }
    for (ja, jb) in a.joints.iter().zip(&b.joints) {
        if ja.name != jb.name || ja.parent != jb.parent {
            return Some(format!("joint `{}` where it has `{}`", ja.name, jb.name));
        }
        if ja.dofs != jb.dofs {
            return Some(format!("joint `{}` has other channels", ja.name));
        }
        let (va, vb) = (ja.rest.vector(), jb.rest.vector());
        let scale = va.iter().chain(&vb).fold(1.0_f64, |m, v| m.max(v.abs()));
        if va
            .iter()
            .zip(&vb)
            .any(|(x, y)| (x - y).abs() > 1e-4 * scale)
        {
            return Some(format!("joint `{}` has another rest pose", ja.name));
        }
    }
    None
}

/// Checks the stream at `path` against the clip its stimulus shows; `Ok(true)` when it was
/// decoded, `Ok(false)` when it needs a decoder context (a primitive database) not given.
fn bitstream(path: &Path, clip: &Clip, ctx: &CodecContext) -> std::result::Result<bool, String> {
    if !path.is_file() {
        return Err(missing("bitstream"));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    let stream = Bitstream::from_bytes(&bytes).map_err(|e| chain(&e))?;
    if stream.frames as usize != clip.frames() || stream.channels as usize != clip.channel_count() {
        return Err(format!(
            "the stream holds {} channels × {} frames, its decoded file {} × {}",
            stream.channels,
            stream.frames,
            clip.channel_count(),
            clip.frames()
        ));
    }
    if !same_number(stream.frame_rate_hz, clip.frame_rate_hz) {
        return Err(format!(
            "the stream is {} Hz, its decoded file {} Hz",
            stream.frame_rate_hz, clip.frame_rate_hz
        ));
    }
    match codec::decode_any_in(&stream, &clip.skeleton, ctx) {
        Ok(decoded) if decoded.frames() == clip.frames() => Ok(true),
        Ok(decoded) => Err(format!(
            "decodes to {} frames, its decoded file has {}",
            decoded.frames(),
            clip.frames()
        )),
        // Streams of the primitive codec without its database, or of a command-defined codec
        // the preflight does not run: their decoded files are checked, the streams not decoded.
        Err(CodecError::NoDatabase { .. } | CodecError::Undefined { .. }) => Ok(false),
        Err(e) => Err(format!("does not decode: {}", chain(&e))),
    }
}

/// A live staircase: the decoder context and source clips read, each clip encoded and
/// decoded once at the first track's start level.
fn check_live(study: &StudyFile, progress: &dyn Fn(usize, usize)) -> (Checked, Vec<Problem>) {
    let total = steps(study);
    let mut checked = Checked::default();
    let live = match LiveStimuli::from_study(study) {
        Ok(Some(live)) => live,
        Ok(None) => return (checked, Vec::new()),
        Err(e) => return (checked, live_problems(study, &e)),
    };
    progress(1, total);
    let level = study
        .definition
        .staircase
        .as_ref()
        .and_then(|s| s.tracks.first())
        .map_or(f64::NAN, |t| t.settings.start);
    let names: Vec<(String, String)> = live
        .clips()
        .map(|(c, r)| (c.to_string(), r.to_string()))
        .collect();
    let mut problems = Vec::new();
    for (i, (clip, reference)) in names.iter().enumerate() {
        checked.stimuli += 1;
        match live.at_level(i, level) {
            Ok(_) => checked.encoded += 1,
            Err(e) => problems.push(Problem {
                file: study.path.clone(),
                about: format!("stimulus {reference:?}"),
                message: format!(
                    "{}: clip {clip:?} at the start level {level}: {}",
                    study.path.display(),
                    chain(&e)
                ),
            }),
        }
        progress(i + 2, total);
    }
    (checked, problems)
}

/// A live staircase's loading errors, one problem per study file key.
fn live_problems(study: &StudyFile, e: &LabError) -> Vec<Problem> {
    let file = study.path.clone();
    if let LabError::Study(StudyError::Invalid { issues, .. }) = e {
        return issues
            .iter()
            .map(|issue| Problem {
                file: file.clone(),
                about: if issue.key.is_empty() {
                    "the study file".into()
                } else {
                    format!("key {}", issue.key)
                },
                message: format!("{}: {}", file.display(), issue.reason),
            })
            .collect();
    }
    vec![Problem {
        file: file.clone(),
        about: "the study file".into(),
        message: format!("{}: {}", file.display(), chain(e)),
    }]
}
