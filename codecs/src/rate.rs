//! Rate control: reach a target compression ratio within ±2 %.
//!
//! CR is the seeds' definition, `4 × channels × frames / bitstream bytes`, counted on the whole
//! container ([`Bitstream::compression_ratio`]). SPIHT reaches a budget natively (its embedded
//! stream is cut at the budget). The wavelet codecs search α, the kept fraction (bytes grow
//! with it up to quantization noise); the `primitive` codec searches its error threshold
//! `t_l`, along which the CR grows instead ([`RateControl::SearchIncreasing`]).
//!
//! **The search.** Along `u = ln(value)` the CR is close to a power law of the parameter,
//! so the search works on `g(u) = ln(CR / target)`, which is close to a straight line:
//! 1. the first encode is at the parameter's value in the parameters (the codec's default
//!    unless given: α = 0.1, `t_l` = 0.012);
//! 2. the second steps by the parameter's typical slope `d ln CR / d ln value`
//!    ([`RateControl`]'s `slope`, measured on the shared clips);
//! 3. then secant steps through the last two encodes (doubled steps where the CR hardly
//!    moves); once encodes on both sides of the target are known, a step that would leave
//!    that bracket is replaced by regula falsi on it, or by bisection, so noise in the CR
//!    cannot throw the search out; a bracket that turns out to hold a jump of the CR ends
//!    the search at this QP.
//!
//! It ends at the first encode within ±2 % ([`CR_TOLERANCE`]). On the shared clips,
//! `wavelet-perceptual` takes 1-4 encodes from 10:1 to 60:1, `primitive` 1-4 wherever its
//! range reaches (`tests/codecs.rs` and `tests/primitive_codec.rs`,
//! `rate_search_needs_at_most_four_encodes`); the bisection on `[min, max]` it replaced took 2-8 and 7-41 at 60:1
//! (`wavelet-perceptual`), 3-7 (`primitive`), and 34 to find a target out of reach. When the
//! parameter's range cannot reach the target (the search stops at a bound, or at a jump),
//! the quantizer (QP) is stepped the needed way and the search runs again from the closest
//! value.
//!
//! A search encodes through [`Codec::rate_encoder`], which lets a codec do the work that
//! does not depend on the searched parameter once per search instead of once per encode.

use crate::bitstream::Bitstream;
use crate::codec::wavelet_codec::{QP_MAX, QP_MIN};
use crate::codec::{Codec, CodecError, Params, RateControl, RateEncoder, keys, merged};
use motion::clip::Clip;

/// Relative tolerance on the achieved CR.
pub const CR_TOLERANCE: f64 = 0.02;
/// Most encodes one search (at one QP) may run.
const MAX_ITERATIONS: usize = 48;
/// Most QP steps when the parameter's range cannot reach the target.
const MAX_QP_STEPS: usize = 13;
/// Largest step of `ln(value)` before the target is bracketed (a factor of 7.4): the
/// power law holds over a decade or so, not from one end of the range to the other.
const MAX_STEP: f64 = 2.0;
/// How far inside `[min, max]` the search stays (a factor of 1.001 from either bound). The
/// bounds themselves are not tried: at α = 1 the wavelet codecs keep every coefficient and
/// quantize with QP bits of the largest instead of at the selection threshold, so the CR
/// jumps back up there (40:1 at α = 1 against 5:1 at α = 0.7 on 131_01), and a search that
/// tried α = 1 would take a reachable target for an unreachable one.
const INSIDE_BOUNDS: f64 = 1e-3;
/// A bracket steeper than this many times the knob's typical slope may hold a jump of the
/// CR: the wavelet codecs' CR drops by ~11 % at one α near 60:1 (0.0626 on pirouette,
/// 61.4:1 to 55.1:1), where slices keep their first detail coefficient and refine their
/// step at once. The search then halves the bracket. At a jump the middle lands next to the
/// CR of one end, twice in a row ([`JUMP_NEAR_END`]); on a steep stretch (α near 1, where
/// the CR falls from 3.4:1 to 2.2:1 within 2 % of α) it does not, or not twice. A target in
/// a jump is out of reach at this QP and one near its edges costs a dozen encodes; another
/// QP moves the jump, so the search steps QP.
const JUMP_SLOPES: f64 = 3.0;
/// A middle within this fraction of the bracket's `ln CR` gap from one end's is "next to
/// it".
const JUMP_NEAR_END: f64 = 0.15;
/// A secant flatter than this fraction of the typical slope is a flat stretch (α past what
/// the clip has to keep): the next step doubles the last instead of following it.
const FLAT_SLOPES: f64 = 0.25;

/// A stream made by rate control, and how many encodes it took.
#[derive(Debug, Clone)]
pub struct Searched {
    /// The stream (CR within ±2 % of the target).
    pub stream: Bitstream,
    /// Encodes run to find it (1 for a codec that reaches the target natively).
    pub encodes: usize,
}

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
    search_to_cr(codec, clip, params, target).map(|s| s.stream)
}

/// [`encode_to_cr`], also saying how many encodes the search ran.
///
/// # Errors
/// As [`encode_to_cr`].
pub fn search_to_cr(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    target: f64,
) -> Result<Searched, CodecError> {
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
    if codec.rate_control() == RateControl::Native {
        return Ok(Searched {
            stream: codec.encode(clip, &p)?,
            encodes: 1,
        });
    }
    search(codec, clip, &merged(codec, &p)?, target)
}

/// The search used by codecs with [`RateControl::Search`] or
/// [`RateControl::SearchIncreasing`] (see the module docs); `params` holds every key of the
/// codec, `cr = target` among them.
///
/// # Errors
/// As [`encode_to_cr`].
pub(crate) fn search(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    target: f64,
) -> Result<Searched, CodecError> {
    let knob = match codec.rate_control() {
        RateControl::Search {
            key,
            min,
            max,
            slope,
        } => Knob {
            key,
            min,
            max,
            slope: -slope.abs(),
        },
        RateControl::SearchIncreasing {
            key,
            min,
            max,
            slope,
        } => Knob {
            key,
            min,
            max,
            slope: slope.abs(),
        },
        RateControl::Native | RateControl::None => {
            return Err(CodecError::Param {
                codec: codec.name(),
                key: keys::CR.into(),
                value: target,
                detail: "no searchable rate parameter".into(),
            });
        }
    };
    let mut encoder = codec.rate_encoder(clip)?;
    let mut p = params.clone();
    p.insert(keys::CR.into(), 0.0);
    let mut encodes = 0;
    let mut last = None;
    for _ in 0..MAX_QP_STEPS {
        match secant(&mut encoder, &p, knob, target, &mut encodes)? {
            Ok(stream) => return Ok(Searched { stream, encodes }),
            // When the parameter's range cannot reach the target, step the quantizer (QP)
            // the needed way and search again from the closest value.
            Err((closest, at)) => {
                last = Some(closest);
                let Some(&qp) = p.get(keys::QP) else { break };
                let next = if closest < target { qp - 1.0 } else { qp + 1.0 };
                if !(f64::from(QP_MIN)..=f64::from(QP_MAX)).contains(&next) {
                    break;
                }
                p.insert(keys::QP.into(), next);
                p.insert(knob.key.into(), at);
            }
        }
    }
    Err(CodecError::Rate {
        codec: codec.name(),
        target,
        closest: last.unwrap_or(0.0),
    })
}

/// The searched parameter, its range and its typical slope `d ln CR / d ln value` (negative
/// when the CR falls as it grows).
#[derive(Debug, Clone, Copy)]
struct Knob {
    key: &'static str,
    min: f64,
    max: f64,
    slope: f64,
}

/// An encode at `u = ln(value)`: where, and `g = ln(CR / target)`.
#[derive(Debug, Clone, Copy)]
struct Probe {
    u: f64,
    g: f64,
}

/// The search on the knob alone, from the knob's value in `params`: `Ok(Ok(stream))` within
/// tolerance, `Ok(Err((closest CR, its knob value)))` if the knob's range cannot reach it.
fn secant(
    encoder: &mut RateEncoder<'_>,
    params: &Params,
    knob: Knob,
    target: f64,
    encodes: &mut usize,
) -> Result<Result<Bitstream, (f64, f64)>, CodecError> {
    let (lo, hi) = (knob.min.ln() + INSIDE_BOUNDS, knob.max.ln() - INSIDE_BOUNDS);
    let start = params
        .get(knob.key)
        .copied()
        .filter(|v| v.is_finite() && *v > 0.0)
        .map_or(0.5 * (lo + hi), f64::ln)
        .clamp(lo, hi);
    let mut p = params.clone();
    // The closest stream so far: (stream, CR, knob value).
    let mut best: Option<(Bitstream, f64, f64)> = None;
    // The latest encodes below and above the target (CR too low, too high).
    let (mut below, mut above): (Option<Probe>, Option<Probe>) = (None, None);
    let mut prev: Option<Probe> = None;
    let mut slope = knob.slope;
    let mut u = start;
    // Encodes in a row on the same side of the target, and that side.
    let (mut run, mut side) = (0usize, false);
    // The ends (`g` below, above) of a bracket halved because it may hold a jump, and how
    // many such halvings in a row put their middle next to an end.
    let mut suspect: Option<(f64, f64)> = None;
    let mut jumpy = 0;
    for _ in 0..MAX_ITERATIONS {
        let value = u.exp();
        p.insert(knob.key.into(), value);
        let s = encoder(&p)?;
        *encodes += 1;
        let cr = s.compression_ratio();
        let error = (cr / target - 1.0).abs();
        if error <= CR_TOLERANCE {
            return Ok(Ok(s));
        }
        if best
            .as_ref()
            .is_none_or(|(_, b, _)| error < (b / target - 1.0).abs())
        {
            best = Some((s, cr, value));
        }
        let here = Probe {
            u,
            g: (cr / target).ln(),
        };
        // Toward the target: along the secant through the last two encodes where it slopes
        // the knob's way; twice the last step where it is flat (α past what the clip has
        // to keep).
        let mut next = here.u - here.g / slope;
        if let Some(q) = prev
            && (here.u - q.u).abs() > 1e-12
        {
            let s = (here.g - q.g) / (here.u - q.u);
            if s * knob.slope <= 0.0 {
                // The CR moved against the knob (noise, or the jump at α → 1): whatever lies
                // toward the target lies between the two. Bisect, keeping `q` as the
                // reference and leaving this encode out of the bracket.
                if (here.u - q.u).abs() < 1e-4 {
                    break;
                }
                u = 0.5 * (q.u + here.u);
                continue;
            }
            if s.abs() >= FLAT_SLOPES * knob.slope.abs() {
                slope = s;
                next = here.u - here.g / slope;
            } else {
                next = here.u + 2.0 * (here.u - q.u).abs() * (-here.g / knob.slope).signum();
            }
        }
        if here.g < 0.0 {
            below = Some(here);
        } else {
            above = Some(here);
        }
        run = if side == (here.g < 0.0) { run + 1 } else { 1 };
        side = here.g < 0.0;
        if let (Some(b), Some(a)) = (below, above) {
            let (l, h) = (b.u.min(a.u), b.u.max(a.u));
            let steepness = (a.g - b.g) / (h - l);
            if let Some((g_lo, g_hi)) = suspect.take() {
                let next_to_end =
                    (here.g - g_lo).min(g_hi - here.g) < JUMP_NEAR_END * (g_hi - g_lo);
                jumpy = if next_to_end { jumpy + 1 } else { 0 };
                if jumpy >= 2 {
                    break;
                }
            }
            if !(next > l && next < h) {
                // Regula falsi on the bracket.
                next = b.u - b.g * (a.u - b.u) / (a.g - b.g);
            }
            // Three encodes in a row on one side: the bracket shrinks from that side only;
            // halve it instead. A bracket that may hold a jump is halved too (see
            // JUMP_SLOPES).
            if steepness > JUMP_SLOPES * knob.slope.abs() {
                suspect = Some((b.g, a.g));
                next = 0.5 * (l + h);
            } else {
                jumpy = 0;
                if !(next > l && next < h) || run >= 3 {
                    next = 0.5 * (l + h);
                }
            }
        } else {
            next = next.clamp(here.u - MAX_STEP, here.u + MAX_STEP);
        }
        next = next.clamp(lo, hi);
        // At a bound that cannot reach the target: give up at this QP.
        if (next - here.u).abs() < 1e-12 {
            break;
        }
        prev = Some(here);
        u = next;
    }
    Ok(match best {
        Some((_, cr, value)) => Err((cr, value)),
        None => Err((0.0, start.exp())),
    })
}
