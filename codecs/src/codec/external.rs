//! A codec defined by two commands, a lab's own encoder and decoder (issue 38, item 2): the
//! project writes the clip to a file, runs the encode command, keeps the file it wrote as the
//! stream's payload, and for decoding writes that payload back, runs the decode command and
//! reads the clip it wrote. Everything else (rate control to a target CR, sweeps, live
//! staircases, the error metrics) is the project's, as for its own codecs.
//!
//! **Files.** Each call runs in a folder of its own under the system's temporary folder,
//! removed afterwards. A clip with an ASF skeleton is written as `input.amc` with its skeleton
//! `skeleton.asf`, and the decoder writes `output.amc`; a BVH clip is written as `input.bvh`,
//! the decoder gets `skeleton.bvh` (the hierarchy with one frame at rest) and writes
//! `output.bvh`. Placeholders in a command's arguments: `{input}`, `{output}`, `{skeleton}`,
//! `{frames}`, `{rate}` (frames per second) and `{NAME}` for each of the codec's parameters
//! (its default or the value asked for). A command is a program and its arguments, never a
//! shell line; it runs in the definition file's folder, so `python3 my_codec.py` finds the
//! script beside it.
//!
//! **Failures.** A command that exits non-zero, is killed, does not finish within its time
//! limit (it is killed then) or does not write its output is a [`CodecError::External`]
//! naming the codec, the command line and the end of its standard error. A decoded clip of
//! another skeleton or length is refused the same way.
//!
//! **The stream.** The container's codec id is [`ID`] for every command-defined codec; the
//! payload starts with the codec's name (one length byte, then the name) so that a stream
//! names the definition that decodes it, then holds the encoder's file byte for byte. The CR
//! counts the whole container, as for every codec.

use std::collections::BTreeSet;
use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use motion::clip::{Clip, Skeleton, SkeletonFormat};
use motion::error::Limits;

use super::{Codec, CodecError, Params, RateControl, check_stream, header, keys, merged};
use crate::bitstream::{Bitstream, StreamLimits};

/// The bitstream id of every command-defined codec (the payload names which one).
pub const ID: u8 = 255;

/// Longest name of a command-defined codec.
pub const MAX_NAME_LEN: usize = 32;

/// Bytes of a command's standard error kept for its error message (the last ones).
const STDERR_TAIL: usize = 2_000;

/// One codec made of an encode and a decode command.
#[derive(Debug, Clone, PartialEq)]
pub struct Definition {
    /// Its name (letters, digits, `-`, `_`; not a built-in codec's).
    pub name: String,
    /// One line for `study codecs`.
    pub description: String,
    /// The encode command: program, then arguments with placeholders.
    pub encode: Vec<String>,
    /// The decode command.
    pub decode: Vec<String>,
    /// The folder the commands run in (the definition file's).
    pub dir: PathBuf,
    /// Every parameter the codec takes, with its default.
    pub params: Params,
    /// How a target CR is reached ([`RateControl::None`] without a rate knob).
    pub rate: RateControl,
    /// Longest one command may run before it is killed.
    pub timeout: Duration,
}

/// A [`Definition`] as a [`Codec`].
#[derive(Debug, Clone)]
pub struct ExternalCodec {
    def: Arc<Definition>,
    /// The name and description, interned ([`Codec::name`] is `'static`).
    name: &'static str,
    description: &'static str,
}

/// Interns `s` as a `'static` string (what [`Codec::name`] and [`RateControl`]'s key are):
/// each distinct string is leaked once, so loading the same definitions again (a study
/// checked, then run) costs nothing more.
pub fn intern(s: &str) -> &'static str {
    static SEEN: Mutex<BTreeSet<&'static str>> = Mutex::new(BTreeSet::new());
    let mut seen = SEEN
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(&k) = seen.get(s) {
        return k;
    }
    let k: &'static str = Box::leak(s.to_owned().into_boxed_str());
    seen.insert(k);
    k
}

impl ExternalCodec {
    /// The codec of `def`.
    pub fn new(def: Arc<Definition>) -> ExternalCodec {
        ExternalCodec {
            name: intern(&def.name),
            description: intern(&def.description),
            def,
        }
    }

    /// Its definition.
    pub fn definition(&self) -> &Definition {
        &self.def
    }

    fn error(&self, command: &[String], detail: impl Into<String>) -> CodecError {
        CodecError::External {
            codec: self.name,
            command: command.join(" "),
            detail: detail.into(),
        }
    }

    /// Runs `command` (expanded) in the definition's folder within its time limit.
    fn run(&self, command: &[String], scratch: &Path) -> Result<(), CodecError> {
        let Some((program, args)) = command.split_first() else {
            return Err(self.error(command, "the command is empty"));
        };
        let stderr_path = scratch.join("stderr.txt");
        let stderr = std::fs::File::create(&stderr_path)
            .map_err(|e| self.error(command, format!("{}: {e}", stderr_path.display())))?;
        let mut child = Command::new(program)
            .args(args)
            .current_dir(&self.def.dir)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr)
            .spawn()
            .map_err(|e| {
                self.error(
                    command,
                    format!(
                        "cannot start `{program}` (in {}): {e}",
                        self.def.dir.display()
                    ),
                )
            })?;
        let start = Instant::now();
        let status = loop {
            match child.try_wait() {
                Ok(Some(status)) => break status,
                Ok(None) if start.elapsed() >= self.def.timeout => {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Err(self.error(
                        command,
                        format!(
                            "did not finish within {} s (killed){}",
                            self.def.timeout.as_secs_f64(),
                            stderr_tail(&stderr_path)
                        ),
                    ));
                }
                Ok(None) => std::thread::sleep(Duration::from_millis(2)),
                Err(e) => return Err(self.error(command, format!("waiting for it: {e}"))),
            }
        };
        if !status.success() {
            return Err(self.error(command, format!("{status}{}", stderr_tail(&stderr_path))));
        }
        Ok(())
    }
}

/// The end of a command's standard error, as `: …` (empty when it wrote nothing).
fn stderr_tail(path: &Path) -> String {
    let mut bytes = Vec::new();
    let Ok(f) = std::fs::File::open(path) else {
        return String::new();
    };
    let len = f.metadata().map_or(0, |m| m.len());
    let skip = len.saturating_sub(STDERR_TAIL as u64);
    let mut f = f;
    if std::io::Seek::seek(&mut f, std::io::SeekFrom::Start(skip)).is_err()
        || f.take(STDERR_TAIL as u64).read_to_end(&mut bytes).is_err()
    {
        return String::new();
    }
    let text = String::from_utf8_lossy(&bytes);
    let text = text.trim();
    if text.is_empty() {
        String::new()
    } else {
        let cut = if skip > 0 { "…" } else { "" };
        format!("; its standard error ends: {cut}{text}")
    }
}

/// A folder of one call, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(codec: &str) -> std::io::Result<Scratch> {
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let dir =
            std::env::temp_dir().join(format!("study-codec-{codec}-{}-{n}", std::process::id()));
        // A folder left by a killed process of the same id is stale.
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir(&dir)?;
        Ok(Scratch(dir))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// The files of one call.
struct CallFiles {
    input: PathBuf,
    output: PathBuf,
    skeleton: PathBuf,
    frames: usize,
    rate: f64,
}

impl CallFiles {
    /// `command` with its placeholders replaced.
    fn expand(&self, command: &[String], params: &Params) -> Vec<String> {
        command
            .iter()
            .map(|arg| {
                let mut a = arg
                    .replace("{input}", &self.input.display().to_string())
                    .replace("{output}", &self.output.display().to_string())
                    .replace("{skeleton}", &self.skeleton.display().to_string())
                    .replace("{frames}", &self.frames.to_string())
                    .replace("{rate}", &self.rate.to_string());
                for (k, v) in params {
                    a = a.replace(&format!("{{{k}}}"), &v.to_string());
                }
                a
            })
            .collect()
    }

    /// The names for a clip of `format`: the encoder reads `input`, the decoder writes
    /// `output`.
    fn new(dir: &Path, format: SkeletonFormat, frames: usize, rate: f64, encode: bool) -> Self {
        let ext = match format {
            SkeletonFormat::Asf => "amc",
            SkeletonFormat::Bvh => "bvh",
        };
        let skeleton = match format {
            SkeletonFormat::Asf => dir.join("skeleton.asf"),
            SkeletonFormat::Bvh => dir.join("skeleton.bvh"),
        };
        let (input, output) = if encode {
            (dir.join(format!("input.{ext}")), dir.join("stream.bin"))
        } else {
            (dir.join("stream.bin"), dir.join(format!("output.{ext}")))
        };
        CallFiles {
            input,
            output,
            skeleton,
            frames,
            rate,
        }
    }
}

/// Writes the skeleton file a decoder is given: the ASF, or a BVH of one frame at rest.
fn write_skeleton(skeleton: &Skeleton, files: &CallFiles, rate: f64) -> Result<(), String> {
    let path = &files.skeleton;
    let text = match skeleton.format {
        SkeletonFormat::Asf => motion::asf::write_asf(skeleton, path),
        SkeletonFormat::Bvh => {
            let rest = Clip::new(
                skeleton.clone(),
                rate,
                1,
                vec![0.0; skeleton.channel_count()],
            )
            .map_err(|e| e.to_string())?;
            motion::bvh::write_bvh(&rest, path)
        }
    }
    .map_err(|e| e.to_string())?;
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

impl Codec for ExternalCodec {
    fn name(&self) -> &'static str {
        self.name
    }
    fn id(&self) -> u8 {
        ID
    }
    fn description(&self) -> &'static str {
        self.description
    }
    fn default_params(&self) -> Params {
        self.def.params.clone()
    }
    fn rate_control(&self) -> RateControl {
        self.def.rate
    }

    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError> {
        let p = merged(self, params)?;
        // A target `cr` (a live staircase's level) is reached as for the built-in codecs: the
        // rate search runs the command at each value of the knob it tries.
        let target = p.get(keys::CR).copied().unwrap_or(0.0);
        if target > 0.0 {
            return crate::rate::search(self, clip, &p, target).map(|s| s.stream);
        }
        let cmd = &self.def.encode;
        let scratch = Scratch::new(self.name).map_err(|e| self.error(cmd, e.to_string()))?;
        let files = CallFiles::new(
            &scratch.0,
            clip.skeleton.format,
            clip.frames(),
            clip.frame_rate_hz,
            true,
        );
        let asf = (clip.skeleton.format == SkeletonFormat::Asf).then_some(files.skeleton.as_path());
        motion::io::write_clip(clip, &files.input, asf, files::Mode::New)
            .map_err(|e| self.error(cmd, format!("writing its input: {e}")))?;
        if clip.skeleton.format == SkeletonFormat::Bvh {
            // The encoder's {skeleton} is the decoder's: the hierarchy at rest.
            write_skeleton(&clip.skeleton, &files, clip.frame_rate_hz)
                .map_err(|e| self.error(cmd, format!("writing its skeleton: {e}")))?;
        }
        let mut p = p;
        // A target is no parameter of the stream (the knob's value is), as for the built-in
        // codecs.
        p.remove(keys::CR);
        let expanded = files.expand(cmd, &p);
        self.run(&expanded, &scratch.0)?;
        let max = u64::from(StreamLimits::default().max_payload);
        let bytes = read_bounded(&files.output, max)
            .map_err(|e| self.error(&expanded, format!("its output {e}")))?;
        let len = u8::try_from(self.name.len())
            .map_err(|_| self.error(cmd, format!("a name of over {MAX_NAME_LEN} bytes")))?;
        let mut payload = Vec::with_capacity(1 + self.name.len() + bytes.len());
        payload.push(len);
        payload.extend_from_slice(self.name.as_bytes());
        payload.extend_from_slice(&bytes);
        header(self, clip, p, payload)
    }

    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
        check_stream(self, stream, skeleton)?;
        let data = payload_of(self.name, stream)?;
        let cmd = &self.def.decode;
        let scratch = Scratch::new(self.name).map_err(|e| self.error(cmd, e.to_string()))?;
        let frames = stream.frames as usize;
        let rate = stream.frame_rate_hz;
        let files = CallFiles::new(&scratch.0, skeleton.format, frames, rate, false);
        std::fs::write(&files.input, data)
            .map_err(|e| self.error(cmd, format!("{}: {e}", files.input.display())))?;
        write_skeleton(skeleton, &files, rate)
            .map_err(|e| self.error(cmd, format!("writing its skeleton: {e}")))?;
        let p = merged(self, &stream.params)?;
        let expanded = files.expand(cmd, &p);
        self.run(&expanded, &scratch.0)?;
        let bad = |detail: String| self.error(&expanded, detail);
        if !files.output.exists() {
            return Err(bad(format!("it wrote no {}", files.output.display())));
        }
        let limits = Limits::default();
        let decoded = match skeleton.format {
            SkeletonFormat::Asf => {
                motion::amc::read_amc_with(&files.output, skeleton, rate, &limits)
                    .map_err(|e| bad(format!("its output: {e}")))?
            }
            SkeletonFormat::Bvh => {
                let c = motion::bvh::read_bvh_with(&files.output, &limits)
                    .map_err(|e| bad(format!("its output: {e}")))?;
                let names = |s: &Skeleton| -> Vec<String> {
                    s.joints.iter().map(|j| j.name.clone()).collect()
                };
                if names(&c.skeleton) != names(skeleton)
                    || c.skeleton.channel_count() != skeleton.channel_count()
                {
                    return Err(bad(
                        "its output has another hierarchy than the skeleton it was given".into(),
                    ));
                }
                c
            }
        };
        if decoded.frames() != frames {
            return Err(bad(format!(
                "its output has {} frames, the stream {frames}",
                decoded.frames()
            )));
        }
        Ok(Clip::new(
            skeleton.clone(),
            rate,
            frames,
            decoded.data().to_vec(),
        )?)
    }
}

/// The name a stream's payload starts with and the encoder's bytes after it; `None` for a
/// payload shorter than the name it announces (an empty one included).
fn split_payload(stream: &Bitstream) -> Option<(&[u8], &[u8])> {
    let (&len, rest) = stream.payload.split_first()?;
    let len = usize::from(len);
    (rest.len() >= len).then(|| rest.split_at(len))
}

/// The encoder's bytes in `stream`, after the name it must carry.
fn payload_of<'a>(name: &'static str, stream: &'a Bitstream) -> Result<&'a [u8], CodecError> {
    let corrupt = |detail: String| CodecError::Payload {
        codec: name,
        offset: 0,
        detail,
    };
    let Some((own, data)) = split_payload(stream) else {
        return Err(corrupt(if stream.payload.is_empty() {
            "empty payload".into()
        } else {
            "the payload is shorter than the codec name it starts with".into()
        }));
    };
    if own != name.as_bytes() {
        return Err(corrupt(format!(
            "the stream was made by codec `{}`",
            String::from_utf8_lossy(own)
        )));
    }
    Ok(data)
}

/// The name of the command-defined codec that made `stream`, if it is one.
pub fn stream_codec_name(stream: &Bitstream) -> Option<String> {
    if stream.codec_id != ID {
        return None;
    }
    let (name, _) = split_payload(stream)?;
    Some(String::from_utf8_lossy(name).into_owned())
}

/// Reads the file at `path`, refusing one over `max` bytes.
fn read_bounded(path: &Path, max: u64) -> Result<Vec<u8>, String> {
    let f = std::fs::File::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let mut bytes = Vec::new();
    f.take(max + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if bytes.len() as u64 > max {
        return Err(format!("{} is over {max} bytes", path.display()));
    }
    Ok(bytes)
}
