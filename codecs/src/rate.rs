//! Rate control: reach a target compression ratio within ±2 %.
//!
//! CR is the seeds' definition, `4 × channels × frames / bitstream bytes`, counted on the whole
//! container ([`Bitstream::compression_ratio`]). SPIHT reaches a budget natively (its embedded
//! stream is cut at the budget); the wavelet codecs bisect α on a log scale (the kept fraction;
//! bytes grow monotonically with it up to quantization noise); the `primitive` codec bisects its
//! error threshold `t_l`, along which the CR grows instead ([`RateControl::SearchIncreasing`]).

use crate::bitstream::Bitstream;
use crate::codec::wavelet_codec::{QP_MAX, QP_MIN};
use crate::codec::{Codec, CodecError, Params, RateControl, keys};
use motion::clip::Clip;

/// Relative tolerance on the achieved CR.
pub const CR_TOLERANCE: f64 = 0.02;
/// Most encodes one search may run.
const MAX_ITERATIONS: usize = 48;

/// Encodes `clip` with `codec` at compression ratio `target` (±2 %), keeping the other
/// parameters in `params`.
///
/// # Errors
/// [`CodecError::Param`] when the codec has no rate control (lossless, raw),
/// [`CodecError::Rate`] when the target cannot be reached, or any encode error.
pub fn encode_to_cr(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    target: f64,
) -> Result<Bitstream, CodecError> {
    if !(target.is_finite() && target > 0.0) || codec.rate_control() == RateControl::None {
        return Err(CodecError::Param {
            codec: codec.name(),
            key: keys::CR.into(),
            value: target,
            detail: "this codec takes no target rate (or the target is not positive)".into(),
        });
    }
    let mut p = params.clone();
    p.insert(keys::CR.into(), target);
    codec.encode(clip, &p)
}

/// The bisection used by codecs with [`RateControl::Search`] or
/// [`RateControl::SearchIncreasing`]; `params` holds `cr = target`.
///
/// # Errors
/// As [`encode_to_cr`].
pub(crate) fn search(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    target: f64,
) -> Result<Bitstream, CodecError> {
    let (key, min, max, increasing) = match codec.rate_control() {
        RateControl::Search { key, min, max } => (key, min, max, false),
        RateControl::SearchIncreasing { key, min, max } => (key, min, max, true),
        RateControl::Native | RateControl::None => {
            return Err(CodecError::Param {
                codec: codec.name(),
                key: keys::CR.into(),
                value: target,
                detail: "no searchable rate parameter".into(),
            });
        }
    };
    let knob = Knob {
        key,
        min,
        max,
        increasing,
    };
    let mut p = params.clone();
    p.insert(keys::CR.into(), 0.0);
    // When the parameter's range cannot reach the target, step the quantizer (QP) the
    // needed way and search again.
    let mut last = None;
    for _ in 0..13 {
        match bisect(codec, clip, &p, knob, target)? {
            Ok(s) => return Ok(s),
            Err(closest) => {
                last = Some(closest);
                let Some(&qp) = p.get(keys::QP) else { break };
                let next = if closest < target { qp - 1.0 } else { qp + 1.0 };
                if !(f64::from(QP_MIN)..=f64::from(QP_MAX)).contains(&next) {
                    break;
                }
                p.insert(keys::QP.into(), next);
            }
        }
    }
    Err(CodecError::Rate {
        codec: codec.name(),
        target,
        closest: last.unwrap_or(0.0),
    })
}

/// The searched parameter and the direction the CR moves in as it grows.
#[derive(Debug, Clone, Copy)]
struct Knob {
    key: &'static str,
    min: f64,
    max: f64,
    increasing: bool,
}

/// Bisection of the knob alone: `Ok(Ok(stream))` within tolerance, `Ok(Err(closest CR))` if
/// not.
fn bisect(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    knob: Knob,
    target: f64,
) -> Result<Result<Bitstream, f64>, CodecError> {
    let Knob {
        key,
        min,
        max,
        increasing,
    } = knob;
    let mut p = params.clone();
    let mut run = |x: f64| -> Result<(Bitstream, f64), CodecError> {
        p.insert(key.into(), x);
        let s = codec.encode(clip, &p)?;
        let cr = s.compression_ratio();
        Ok((s, cr))
    };
    let (mut lo, mut hi) = (min.ln(), max.ln());
    let mut best: Option<(Bitstream, f64)> = None;
    let better = |best: &Option<(Bitstream, f64)>, cr: f64| {
        best.as_ref()
            .is_none_or(|(_, b)| (cr / target - 1.0).abs() < (b / target - 1.0).abs())
    };
    for _ in 0..MAX_ITERATIONS {
        let mid = 0.5 * (lo + hi);
        let (s, cr) = run(mid.exp())?;
        let done = (cr / target - 1.0).abs() <= CR_TOLERANCE;
        if better(&best, cr) {
            best = Some((s, cr));
        }
        if done {
            break;
        }
        // Search: CR falls as the parameter grows, so too high a CR asks for a larger value;
        // SearchIncreasing: the other way round.
        if (cr > target) == increasing {
            hi = mid;
        } else {
            lo = mid;
        }
        if hi - lo < 1e-9 {
            break;
        }
    }
    Ok(match best {
        Some((s, cr)) if (cr / target - 1.0).abs() <= CR_TOLERANCE => Ok(s),
        Some((_, cr)) => Err(cr),
        None => Err(0.0),
    })
}
