//! Error-bounded encoding: the smallest stream of a codec whose largest joint position error
//! stays within a bound, as production animation codecs are driven (ACL's error threshold)
//! instead of a compression ratio.
//!
//! The search runs over the codec's rate knob, the parameter its [`RateControl`] names
//! (`alpha` for the wavelet codecs, `t_l` for `primitive`, the target ratio `cr` itself for
//! SPIHT, which reaches it natively), on a log scale between the knob's ends, and measures
//! every probe as a stimulus is measured ([`stimulus::make`]: encode, decode, FK error):
//!
//! 1. bracketing: the knob's small-stream end, which is the answer if it is within the bound
//!    (the codec's minimum); then its large-stream end, and the bound is unreachable if even
//!    that exceeds it;
//! 2. bisection between the last probe within the bound and the last one beyond it, until the
//!    two knob values are within [`KNOB_STEP`] (1 %) of each other.
//!
//! Every codec's knob spans a factor of 10⁴ (ln 10⁴ = 9.21), so one knob search takes
//! 2 + ⌈log₂(9.21 / ln 1.01)⌉ = 12 encodes (each with its decode and measurement), 2 when the
//! bound is unreachable, 1 when the smallest stream is within it. A codec that reaches ratios
//! natively (SPIHT) refuses its knob's end, 10 000:1, on a clip whose side information alone
//! exceeds that budget, naming the largest ratio it reaches; that becomes the end (a narrower
//! span, so no more bisections), and the refused try is one more encode: [`MAX_KNOB_ENCODES`]
//! = 13. The stream returned is the last one within the bound; the last one beyond it, one
//! step (≤ 1 % of the knob) toward smaller streams, is reported as [`Bounded::smaller`]. The
//! search assumes max error falls as the stream grows, as it does along every codec's knob up
//! to quantisation noise; where it does not, the stream returned is still within the bound
//! (only probes measured within it are ever returned), but a smaller one may exist.
//!
//! The wavelet codecs' error has a floor set by their quantiser (QP bits): at the default
//! QP 10 even α = 1 leaves 2-9 cm of max error on the shared CMU clips. When `qp` is not
//! given, the search therefore also walks QP ([`QP_RANGE`]): from the default up until the
//! bound is reachable, then one step at a time in the direction that makes the stream
//! smaller, while it does (a knob search per QP; the smallest stream found wins, assuming
//! size is unimodal along QP). That is 12 encodes per reachable QP tried and 2 per
//! unreachable one; on the shared clips at 0.5-1 cm, 3-5 QPs. A `qp` given (`--param qp=12`,
//! a sweep variant) is kept, so a stimulus is made with the parameters it is labelled with.
//! The other parameters are always kept as given.

use std::time::Instant;

use codecs::codec::{Codec, CodecError, Params, RateControl, keys};
use motion::Clip;

use crate::error::{LabError, Result, refused};
use crate::stimulus::{self, Made, Request};

/// Relative width of the final bracket on the knob: the stream returned and
/// [`Bounded::smaller`] differ by at most this factor in the knob.
pub const KNOB_STEP: f64 = 0.01;

/// Most encodes one knob search runs (see the module docs): 12, and one more for a codec
/// that reaches ratios natively.
pub const MAX_KNOB_ENCODES: usize = 13;

/// The quantiser bits the wavelet codecs take ([`keys::QP`], 4..=16), which the search walks
/// when `qp` is not given.
pub const QP_RANGE: (u32, u32) = (4, 16);

/// The knob of SPIHT-like codecs that reach a target ratio natively: the ratio itself, from
/// 1:1 (a float32 per value) to 10 000:1.
const NATIVE_CR: (f64, f64) = (1.0, 10_000.0);

/// The parameter an error-bounded search moves, and where its streams are largest and
/// smallest.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knob {
    /// Parameter name (one of [`keys`]).
    pub key: &'static str,
    /// The value that gives the largest stream (least error).
    pub largest: f64,
    /// The value that gives the smallest stream (most error).
    pub smallest: f64,
}

impl Knob {
    /// The knob of `codec`, from its rate control; `None` for a codec without one (lossless,
    /// raw).
    pub fn of(codec: &dyn Codec) -> Option<Knob> {
        match codec.rate_control() {
            // CR falls as the parameter grows: its largest value makes the largest stream.
            RateControl::Search { key, min, max, .. } => Some(Knob {
                key,
                largest: max,
                smallest: min,
            }),
            RateControl::SearchIncreasing { key, min, max, .. } => Some(Knob {
                key,
                largest: min,
                smallest: max,
            }),
            RateControl::Native => Some(Knob {
                key: keys::CR,
                largest: NATIVE_CR.0,
                smallest: NATIVE_CR.1,
            }),
            RateControl::None => None,
        }
    }

    /// The value at `u` along the log scale from [`Knob::largest`] (0) to [`Knob::smallest`]
    /// (1).
    fn at(self, u: f64) -> f64 {
        // The ends exactly (exp(ln x) may round past a codec's range check).
        if u <= 0.0 {
            return self.largest;
        }
        if u >= 1.0 {
            return self.smallest;
        }
        let (a, b) = (self.largest.ln(), self.smallest.ln());
        let (lo, hi) = if a < b {
            (self.largest, self.smallest)
        } else {
            (self.smallest, self.largest)
        };
        (a + u * (b - a)).exp().clamp(lo, hi)
    }

    /// `ln(smallest / largest)` in absolute value: the knob's span on its log scale.
    fn span(self) -> f64 {
        (self.smallest.ln() - self.largest.ln()).abs()
    }
}

/// A probe of the search that exceeded the bound.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Probe {
    /// The knob's value.
    pub value: f64,
    /// Bitstream bytes.
    pub bytes: usize,
    /// Its largest joint position error, cm.
    pub max_cm: f64,
}

/// The result of an error-bounded search.
#[derive(Debug, Clone)]
pub struct Bounded {
    /// The stream found, measured. Its `encode_ms` is the whole search (every probe's
    /// encode, decode and measurement); its `decode_ms` the decode of this stream.
    pub made: Made,
    /// The knob searched.
    pub knob: Knob,
    /// The knob's value for [`Bounded::made`].
    pub value: f64,
    /// The probe one step toward smaller streams, which exceeds the bound; `None` when
    /// [`Bounded::made`] is the codec's smallest stream (the knob's end).
    pub smaller: Option<Probe>,
    /// Encodes run, over every QP tried.
    pub encodes: usize,
    /// The QPs tried when the search walked the quantiser (module docs), in order, each with
    /// the bytes of its smallest stream within the bound (`None`: unreachable at that QP);
    /// empty when it did not.
    pub qp_tried: Vec<(u32, Option<usize>)>,
}

/// Checks `params` leave the knob to the search: neither the target ratio nor the knob may
/// be given.
///
/// # Errors
/// [`LabError::Refused`] naming the parameter, or a codec without rate control.
pub fn check_params(codec: &dyn Codec, params: &Params) -> Result<Knob> {
    let Some(knob) = Knob::of(codec) else {
        return Err(refused(format!(
            "codec `{}` has no rate knob to bound its error with (it is lossless or raw)",
            codec.name()
        )));
    };
    for key in [keys::CR, knob.key] {
        if params.contains_key(key) {
            return Err(refused(format!(
                "--param {key}: an error-bounded encode of `{}` sets {} itself",
                codec.name(),
                knob.key
            )));
        }
    }
    Ok(knob)
}

/// The smallest stream of `codec` for `clip` (other parameters `params`) whose largest joint
/// position error is at most `max_error_cm`, by the search of the module docs.
///
/// # Errors
/// A bound that is not positive and finite, parameters [`check_params`] refuses,
/// [`LabError::BoundUnreachable`] when even the knob's largest stream exceeds the bound (at
/// every QP, where QP is walked), or any error of encoding, decoding or measuring.
pub fn make_within(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    max_error_cm: f64,
) -> Result<Bounded> {
    if !(max_error_cm.is_finite() && max_error_cm > 0.0) {
        return Err(refused(format!(
            "--max-error-cm {max_error_cm}: the bound must be a positive number of cm"
        )));
    }
    let knob = check_params(codec, params)?;
    let t0 = Instant::now();
    let walk_qp = !params.contains_key(keys::QP);
    let default_qp = codec
        .default_params()
        .get(keys::QP)
        .copied()
        .filter(|_| walk_qp);
    let mut best = match default_qp {
        None => search_knob(codec, clip, params, knob, max_error_cm)?,
        Some(qp) => search_qp(codec, clip, params, knob, max_error_cm, qp as u32)?,
    };
    best.made.encode_ms = t0.elapsed().as_secs_f64() * 1e3;
    Ok(best)
}

/// The QP walk of the module docs, from `start`.
fn search_qp(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    knob: Knob,
    max_error_cm: f64,
    start: u32,
) -> Result<Bounded> {
    let (lo, hi) = QP_RANGE;
    let mut encodes = 0;
    let mut tried = Vec::new();
    // The knob search at `qp`: `Ok(Err(_))` when the bound is out of its reach.
    let mut at = |qp: u32| -> Result<Result<Bounded, LabError>> {
        let mut p = params.clone();
        p.insert(keys::QP.into(), f64::from(qp));
        match search_knob(codec, clip, &p, knob, max_error_cm) {
            Ok(b) => {
                encodes += b.encodes;
                tried.push((qp, Some(b.made.bytes.len())));
                Ok(Ok(b))
            }
            Err(e @ LabError::BoundUnreachable { .. }) => {
                // Its two ends were encoded.
                encodes += 2;
                tried.push((qp, None));
                Ok(Err(e))
            }
            Err(e) => Err(e),
        }
    };
    // Up from the start until the bound is reachable: more bits, a lower error floor.
    let start = start.clamp(lo, hi);
    let mut qp = start;
    let mut best = loop {
        match at(qp)? {
            Ok(b) => break b,
            Err(e) if qp == hi => return Err(e),
            Err(_) => qp += 1,
        }
    };
    // Then toward smaller streams, one QP at a time while the stream shrinks: down (only
    // from the start: below a QP that had to be stepped up the bound is out of reach), and
    // up unless down was smaller.
    let found = qp;
    let directions: &[i32] = if found == start { &[-1, 1] } else { &[1] };
    let mut improved = false;
    for &d in directions {
        if improved {
            break;
        }
        let mut q = found;
        while let Some(next) = q.checked_add_signed(d).filter(|n| (lo..=hi).contains(n)) {
            q = next;
            match at(q)? {
                Ok(b) if b.made.bytes.len() < best.made.bytes.len() => {
                    best = b;
                    improved = true;
                }
                _ => break,
            }
        }
    }
    best.encodes = encodes;
    best.qp_tried = tried;
    Ok(best)
}

/// One knob search (bracketing and bisection of the module docs) at fixed `params`.
fn search_knob(
    codec: &dyn Codec,
    clip: &Clip,
    params: &Params,
    mut knob: Knob,
    max_error_cm: f64,
) -> Result<Bounded> {
    let mut encodes = 0;
    let mut probe = |knob: Knob, u: f64| -> Result<(f64, Made)> {
        let value = knob.at(u);
        let mut p = params.clone();
        p.insert(knob.key.into(), value);
        encodes += 1;
        Ok((
            value,
            stimulus::make(
                codec,
                clip,
                &Request {
                    params: p,
                    target_cr: None,
                },
            )?,
        ))
    };
    let (v1, small) = match probe(knob, 1.0) {
        // A codec that reaches ratios natively refuses one whose budget its side information
        // alone exceeds (SPIHT on a short clip at 10 000:1), naming the largest it reaches:
        // that is its smallest stream.
        Err(LabError::Codec(CodecError::Rate { closest, .. }))
            if knob.key == keys::CR && closest.is_finite() && closest > knob.largest =>
        {
            knob.smallest = (closest * (1.0 - 1e-6)).max(knob.largest);
            probe(knob, 1.0)?
        }
        r => r?,
    };
    let within = |m: &Made| m.metrics.max_cm <= max_error_cm;
    let (value, made, smaller) = if within(&small) {
        (v1, small, None)
    } else {
        let beyond = |value: f64, m: &Made| Probe {
            value,
            bytes: m.bytes.len(),
            max_cm: m.metrics.max_cm,
        };
        let mut hi = (1.0, beyond(v1, &small));
        let (v0, large) = probe(knob, 0.0)?;
        if !within(&large) {
            let qp = params
                .get(keys::QP)
                .map_or_else(String::new, |q| format!(", qp = {q}"));
            return Err(LabError::BoundUnreachable {
                codec: codec.name().to_string(),
                max_error_cm,
                closest_cm: large.metrics.max_cm,
                knob: format!("{} = {v0}{qp}", knob.key),
            });
        }
        let mut lo = (0.0, v0, large);
        while (hi.0 - lo.0) * knob.span() > KNOB_STEP.ln_1p() {
            let u = 0.5 * (lo.0 + hi.0);
            let (v, m) = probe(knob, u)?;
            if within(&m) {
                lo = (u, v, m);
            } else {
                hi = (u, beyond(v, &m));
            }
        }
        (lo.1, lo.2, Some(hi.1))
    };
    Ok(Bounded {
        made,
        knob,
        value,
        smaller,
        encodes,
        qp_tried: Vec::new(),
    })
}

impl Bounded {
    /// What the search for a max error within `bound` cm found, in one line (`study encode
    /// --max-error-cm`).
    pub fn describe(&self, bound: f64) -> String {
        let key = self.knob.key;
        let next = match &self.smaller {
            Some(p) => format!(
                "one step smaller ({key} {:.6}, {} bytes) has max {:.3} cm",
                p.value, p.bytes, p.max_cm
            ),
            None => format!("the codec's smallest stream along {key}"),
        };
        let qp = if self.qp_tried.is_empty() {
            String::new()
        } else {
            let tried: Vec<String> = self
                .qp_tried
                .iter()
                .map(|(q, bytes)| match bytes {
                    Some(n) => format!("{q}: {n} bytes"),
                    None => format!("{q}: out of reach"),
                })
                .collect();
            let kept = self
                .made
                .stream
                .params
                .get(codecs::codec::keys::QP)
                .copied()
                .unwrap_or(f64::NAN);
            format!(" at qp {kept} (tried {})", tried.join(", "))
        };
        format!(
            "max error ≤ {bound} cm: {key} {:.6}{qp} after {} encodes; {next}",
            self.value, self.encodes
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`QP_RANGE`] is what the wavelet codecs take (codecs::codec::keys::QP); lab cannot
    /// see the codecs' own constants.
    #[test]
    fn qp_range_is_the_wavelet_codecs() {
        let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
            duration_s: 0.5,
            ..motion::synth::WalkParams::default()
        });
        let codec = codecs::codec::by_name("wavelet-perceptual").unwrap();
        let encode = |qp: u32| {
            let p: Params = [(keys::QP.to_string(), f64::from(qp))].into();
            codec.encode(&clip, &p)
        };
        let (lo, hi) = QP_RANGE;
        assert!(encode(lo).is_ok() && encode(hi).is_ok());
        assert!(encode(lo - 1).is_err() && encode(hi + 1).is_err());
        assert!(codec.default_params().contains_key(keys::QP));
    }

    /// The documented count: 2 bracketing encodes and the bisections a span of 10⁴ needs to
    /// come within 1 %.
    #[test]
    fn max_encodes_is_what_the_bisection_takes() {
        let span = 1e4f64.ln();
        let bisections = (span / KNOB_STEP.ln_1p()).log2().ceil() as usize;
        assert_eq!(1 + 2 + bisections, MAX_KNOB_ENCODES);
        for codec in codecs::codec::registry() {
            if let Some(k) = Knob::of(codec.as_ref()) {
                assert!((k.span() - span).abs() < 1e-9, "{}", codec.name());
                assert_eq!((k.at(0.0), k.at(1.0)), (k.largest, k.smallest));
            }
        }
    }
}
