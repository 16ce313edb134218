//! The perceptual wavelet codec of paper 000 section III / thesis ch. 3, and its two baselines
//! from the same code path.
//!
//! Per slice of `W` frames (the last may be shorter, step 1) and per channel `i` of `N`:
//! 1. `l_i`: the length the channel's joint swings (`Skeleton::swung_length`) over the longest
//!    such length of the skeleton (step 3);
//! 2. `v_i = Σ_p |c_{i,p+1} − c_{i,p}| / W` over the slice (eq. 1 / 3.1);
//! 3. `A_i = l_i·v_i` (eq. 2 / 3.2) — [`Selection::Perceptual`]; `A_i = l_i` —
//!    [`Selection::BoneLength`]; `A_i = 1` — [`Selection::Standard`] (same share α for all);
//! 4. `K_i = max(α·A_i·N·W / Σ_j A_j, C)` (step 6), where `W` counts the slice's coefficients;
//!    the `K_i` largest coefficients are kept, the rest set to zero;
//! 5. linear quantization to QP bits: step `Δ = 2^(s/8)`, the smallest such step with
//!    `max |kept| / Δ ≤ 2^(QP−1) − 1` (sign included in the QP bits) (step 7);
//! 6. run-length coding of the zeros (pairs run, value in coarse-to-fine order) (step 8) and
//! 7. adaptive binary range coding ([`crate::entropy`]) with per-band contexts (step 9; the
//!    paper used LZW).
//!
//! Two things the text leaves open, decided here:
//!
//! **(a) Translation channels.** `v_i` of a root translation is in length units per frame while
//! rotations are in degrees per frame, so taken literally ([`TranslationRule::Literal`]) the rule
//! compares incomparable numbers; on CMU units (1 unit = 5.6 cm) it starves the root translation
//! and the whole body drifts by centimetres. [`TranslationRule::Comparable`] (default) converts a
//! translation's activity to the degree-equivalent on the skeleton's longest swung length:
//! a rotation error of `δ` degrees on a bone of length `L` moves its end by `L·δ·π/180`, so a
//! translation of `t` units counts as `t·180/(π·L_max)` degrees with `l_i = 1`. The same rule
//! gives translation channels 4 more quantization bits (`QP + 4`): a QP-bit step of a channel
//! that drifts by metres over a slice is itself centimetres. `tests/codecs.rs` shows the literal
//! rule's larger position error on a clip with root motion.
//!
//! **(b) Minimum kept coefficients.** `C` is raised to at least the size of the coarsest band
//! (the approximation band of the deepest level), and that band is always among the kept
//! coefficients (it ranks above every detail in the top-`K_i` selection): dropping an
//! approximation coefficient removes a whole stretch of the slice's low-pass content, not a
//! detail, and with periodization the slice mean lives only there.
//!
//! Rotation channels are unwrapped (jumps over 180° taken as wraps) before the transform and
//! wrapped back into (−180°, 180°] after decoding, for the channels where unwrapping changed
//! something (one flag per channel in the stream).

use super::prep::{channel_lengths, is_translation, unwrapped_matrix, wrap_flagged};
use super::{
    Codec, CodecError, Params, RateControl, check_stream, header, int_param, merged, real_param,
};
use crate::bitstream::Bitstream;
use crate::clip::{Clip, Skeleton};
use crate::entropy::{BitModel, IntModel, RangeDecoder, RangeEncoder, UintModel};
use crate::wavelet::{Transform, Wavelet, band_lengths};

/// How channels share the coefficient budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Selection {
    /// `A_i = l_i·v_i` (paper 000).
    Perceptual,
    /// Same share for every channel ("standard wavelet compression").
    Standard,
    /// `A_i = l_i` (bone length only).
    BoneLength,
}

/// How root translation channels enter the allocation (decision (a) in the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TranslationRule {
    /// Translation activity converted to degree-equivalents on the longest bone; QP + 4 bits.
    Comparable,
    /// The rule taken literally: units per frame as if degrees, root bone length, QP bits.
    Literal,
}

/// Extra quantization bits of translation channels under [`TranslationRule::Comparable`].
const TRANSLATION_EXTRA_QP: u32 = 4;
/// Contexts: one per band, deeper bands share the last.
const BAND_CONTEXTS: usize = 12;
/// Quantizer step exponent range (`Δ = 2^(s/8)`).
const STEP_MIN: i64 = -512;
const STEP_MAX: i64 = 512;

/// The paper-000 codec family.
#[derive(Debug, Clone, Copy)]
pub struct WaveletCodec {
    selection: Selection,
}

impl WaveletCodec {
    /// The codec with the given channel share rule.
    pub fn new(selection: Selection) -> WaveletCodec {
        WaveletCodec { selection }
    }
}

/// Parsed parameters.
#[derive(Debug, Clone, Copy)]
struct Settings {
    alpha: f64,
    qp: u32,
    window: usize,
    c_min: usize,
    wavelet: Wavelet,
    translation: TranslationRule,
}

fn settings(name: &'static str, p: &Params) -> Result<Settings, CodecError> {
    let alpha = real_param(name, p, "alpha", 0.0, 1.0)?;
    let qp = int_param(name, p, "qp", 4, 16)? as u32;
    let window = int_param(name, p, "window", 8, 4096)? as usize;
    let c_min = int_param(name, p, "c", 0, 4096)? as usize;
    let wavelet =
        Wavelet::from_id(int_param(name, p, "wavelet", 0, 1)? as u8).unwrap_or(Wavelet::D4);
    let translation = if int_param(name, p, "translation", 0, 1)? == 0 {
        TranslationRule::Comparable
    } else {
        TranslationRule::Literal
    };
    Ok(Settings {
        alpha,
        qp,
        window,
        c_min,
        wavelet,
        translation,
    })
}

/// Per-band context index of every coefficient position of a slice layout.
fn band_map(n: usize, levels: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(n);
    for (b, &len) in band_lengths(n, levels).iter().enumerate() {
        out.extend(std::iter::repeat_n(b.min(BAND_CONTEXTS - 1) as u8, len));
    }
    out
}

struct Models {
    run: Vec<UintModel>,
    value: Vec<IntModel>,
    nnz: UintModel,
    step: IntModel,
    flag: BitModel,
}

impl Models {
    fn new() -> Models {
        Models {
            run: vec![UintModel::default(); BAND_CONTEXTS],
            value: vec![IntModel::default(); BAND_CONTEXTS],
            nnz: UintModel::default(),
            step: IntModel::default(),
            flag: BitModel::default(),
        }
    }
}

fn slices(frames: usize, window: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..frames.div_ceil(window)).map(move |k| (k * window, window.min(frames - k * window)))
}

impl WaveletCodec {
    #[expect(
        clippy::too_many_lines,
        clippy::float_cmp,
        reason = "steps 3-9 of the paper in order; ties at the K-th magnitude are resolved exactly"
    )]
    fn encode_native(self, clip: &Clip, p: Params) -> Result<Bitstream, CodecError> {
        let s = settings(self.name(), &p)?;
        let frames = clip.frames();
        let n_ch = clip.channel_count();
        let (data, flags) = unwrapped_matrix(clip);
        let (lens, max_len) = channel_lengths(clip);
        let kinds: Vec<bool> = clip
            .channels()
            .iter()
            .map(|c| is_translation(c.kind))
            .collect();
        let rad = 180.0 / std::f64::consts::PI;

        let mut enc = RangeEncoder::new();
        let mut m = Models::new();
        for &f in &flags {
            enc.bit(&mut m.flag, f);
        }
        let mut t = Transform::new(s.wavelet);
        let mut coeffs: Vec<Vec<f64>> = vec![Vec::new(); n_ch];
        let mut prev_step = vec![0i64; n_ch];
        let mut weights = vec![0.0; n_ch];
        let mut mags = Vec::new();
        let mut q = Vec::new();
        for (start, len) in slices(frames, s.window) {
            let levels = s.wavelet.max_level(len);
            let bands = band_map(len, levels);
            let n_coef = bands.len();
            let n_approx = band_lengths(len, levels)[0];
            let c_eff = s.c_min.max(n_approx).min(n_coef);
            // Steps 3-5: importance of each channel.
            for c in 0..n_ch {
                let x = &data[c * frames + start..c * frames + start + len];
                t.forward(x, levels, &mut coeffs[c]);
                let v = x.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / len as f64;
                let (l, v) = match (kinds[c], s.translation) {
                    (true, TranslationRule::Comparable) => (1.0, v * rad / max_len),
                    _ => (lens[c] / max_len, v),
                };
                weights[c] = match self.selection {
                    Selection::Perceptual => l * v,
                    Selection::BoneLength => l,
                    Selection::Standard => 1.0,
                };
            }
            let sum_a: f64 = weights.iter().sum();
            let budget = s.alpha * (n_ch * n_coef) as f64;
            // Shares are rounded by carrying the remainder from channel to channel, so the slice
            // keeps round(α·N·W) coefficients in total and the rate moves smoothly with α.
            let mut acc = 0.0f64;
            for c in 0..n_ch {
                // Step 6: K_i = max(α A_i N W / Σ A_j, C).
                let share = if sum_a > 0.0 {
                    budget * weights[c] / sum_a
                } else {
                    s.alpha * n_coef as f64
                };
                let k_share = ((acc + share).round() - acc.round()).max(0.0) as usize;
                acc += share;
                let k = k_share.max(c_eff).min(n_coef);
                let co = &mut coeffs[c];
                if k < n_coef {
                    // The approximation band always survives (decision (b)): it ranks first.
                    let rank =
                        |i: usize, v: f64| if i < n_approx { f64::INFINITY } else { v.abs() };
                    mags.clear();
                    mags.extend(co.iter().enumerate().map(|(i, &v)| rank(i, v)));
                    let (_, &mut thr, _) = mags.select_nth_unstable_by(n_coef - k, f64::total_cmp);
                    let above = co
                        .iter()
                        .enumerate()
                        .filter(|&(i, &v)| rank(i, v) > thr)
                        .count();
                    let mut ties = k.saturating_sub(above);
                    for (i, v) in co.iter_mut().enumerate() {
                        let a = rank(i, *v);
                        if a < thr || (a == thr && ties == 0) {
                            *v = 0.0;
                        } else if a == thr {
                            ties -= 1;
                        }
                    }
                }
                // Step 7: linear quantization into QP bits.
                let qp = if kinds[c] && s.translation == TranslationRule::Comparable {
                    s.qp + TRANSLATION_EXTRA_QP
                } else {
                    s.qp
                };
                let qmax = f64::from((1u32 << (qp - 1)) - 1);
                let maxabs = co.iter().fold(0.0f64, |a, v| a.max(v.abs()));
                q.clear();
                let mut step_exp = prev_step[c];
                if maxabs > 0.0 {
                    step_exp = ((maxabs / qmax).log2() * 8.0).ceil() as i64;
                    step_exp = step_exp.clamp(STEP_MIN, STEP_MAX);
                    let step = (step_exp as f64 / 8.0).exp2();
                    q.extend(co.iter().map(|v| (v / step).round() as i64));
                } else {
                    q.resize(n_coef, 0);
                }
                // Steps 8-9: run-length of zeros, range coded.
                let nnz = q.iter().filter(|&&v| v != 0).count();
                m.nnz
                    .encode(&mut enc, nnz as u32)
                    .map_err(|e| self.enc_err(&e))?;
                if nnz == 0 {
                    continue;
                }
                m.step
                    .encode(&mut enc, step_exp - prev_step[c])
                    .map_err(|e| self.enc_err(&e))?;
                prev_step[c] = step_exp;
                let mut pos = 0usize;
                for (i, &v) in q.iter().enumerate() {
                    if v != 0 {
                        let ctx = usize::from(bands[pos]);
                        m.run[ctx]
                            .encode(&mut enc, (i - pos) as u32)
                            .map_err(|e| self.enc_err(&e))?;
                        m.value[usize::from(bands[i])]
                            .encode(&mut enc, v)
                            .map_err(|e| self.enc_err(&e))?;
                        pos = i + 1;
                    }
                }
            }
        }
        let mut out = p;
        out.remove("cr");
        header(&self, clip, out, enc.finish())
    }

    fn enc_err(self, e: &crate::entropy::EntropyError) -> CodecError {
        CodecError::Payload {
            codec: self.name(),
            offset: 0,
            detail: e.to_string(),
        }
    }
}

impl Codec for WaveletCodec {
    fn name(&self) -> &'static str {
        match self.selection {
            Selection::Perceptual => "wavelet-perceptual",
            Selection::Standard => "wavelet-standard",
            Selection::BoneLength => "wavelet-bone",
        }
    }

    fn id(&self) -> u8 {
        match self.selection {
            Selection::Perceptual => 3,
            Selection::Standard => 4,
            Selection::BoneLength => 5,
        }
    }

    fn description(&self) -> &'static str {
        match self.selection {
            Selection::Perceptual => {
                "paper 000: D4 wavelet, K_i ∝ bone length × variation, QP bits, RLE + range coder"
            }
            Selection::Standard => "paper 000 baseline: same coefficient share for every channel",
            Selection::BoneLength => "paper 000 baseline: coefficient share ∝ bone length only",
        }
    }

    fn default_params(&self) -> Params {
        [
            ("alpha", 0.1),
            ("qp", 10.0),
            ("window", 256.0),
            ("c", 0.0),
            ("wavelet", f64::from(Wavelet::D4.id())),
            ("translation", 0.0),
            ("cr", 0.0),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }

    fn rate_control(&self) -> RateControl {
        RateControl::Search {
            key: "alpha",
            min: 1e-4,
            max: 1.0,
        }
    }

    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError> {
        let p = merged(self, params)?;
        let target = p.get("cr").copied().unwrap_or(0.0);
        if target > 0.0 {
            return crate::rate::search(self, clip, &p, target);
        }
        self.encode_native(clip, p)
    }

    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
        check_stream(self, stream, skeleton)?;
        let name = self.name();
        let mut p = self.default_params();
        p.extend(stream.params.iter().map(|(k, v)| (k.clone(), *v)));
        let s = settings(name, &p)?;
        let frames = stream.frames as usize;
        let n_ch = stream.channels as usize;
        let corrupt = |dec: &RangeDecoder<'_>, detail: &str| CodecError::Payload {
            codec: name,
            offset: dec.position(),
            detail: detail.to_string(),
        };
        let mut data = vec![0.0; n_ch * frames];
        let mut dec = RangeDecoder::new(&stream.payload);
        let mut m = Models::new();
        let flags: Vec<bool> = (0..n_ch).map(|_| dec.bit(&mut m.flag)).collect();
        let kinds: Vec<bool> = skeleton
            .channel_layout()
            .iter()
            .map(|c| is_translation(c.kind))
            .collect();
        let mut t = Transform::new(s.wavelet);
        let mut co = Vec::new();
        let mut out = Vec::new();
        let mut prev_step = vec![0i64; n_ch];
        for (start, len) in slices(frames, s.window) {
            let levels = s.wavelet.max_level(len);
            let bands = band_map(len, levels);
            let n_coef = bands.len();
            for c in 0..n_ch {
                co.clear();
                co.resize(n_coef, 0.0);
                let nnz = m
                    .nnz
                    .decode(&mut dec)
                    .ok_or_else(|| corrupt(&dec, "count"))? as usize;
                if nnz > n_coef {
                    return Err(corrupt(&dec, "more coefficients than the slice has"));
                }
                if nnz > 0 {
                    let ds = m
                        .step
                        .decode(&mut dec)
                        .ok_or_else(|| corrupt(&dec, "step"))?;
                    let step_exp = prev_step[c].saturating_add(ds);
                    if !(STEP_MIN..=STEP_MAX).contains(&step_exp) {
                        return Err(corrupt(&dec, "quantizer step out of range"));
                    }
                    prev_step[c] = step_exp;
                    let step = (step_exp as f64 / 8.0).exp2();
                    let qp = if kinds[c] && s.translation == TranslationRule::Comparable {
                        s.qp + TRANSLATION_EXTRA_QP
                    } else {
                        s.qp
                    };
                    let qlim = i64::from(1u32 << (qp - 1));
                    let mut pos = 0usize;
                    for _ in 0..nnz {
                        let ctx = usize::from(
                            *bands
                                .get(pos)
                                .ok_or_else(|| corrupt(&dec, "run past the slice"))?,
                        );
                        let run = m.run[ctx]
                            .decode(&mut dec)
                            .ok_or_else(|| corrupt(&dec, "run"))?
                            as usize;
                        let i = pos + run;
                        let Some(&b) = bands.get(i) else {
                            return Err(corrupt(&dec, "run past the slice"));
                        };
                        let v = m.value[usize::from(b)]
                            .decode(&mut dec)
                            .ok_or_else(|| corrupt(&dec, "value"))?;
                        if v == 0 || v.abs() > qlim {
                            return Err(corrupt(&dec, "quantized value out of range"));
                        }
                        co[i] = v as f64 * step;
                        pos = i + 1;
                    }
                }
                t.inverse(&co, len, levels, &mut out)
                    .map_err(|e| corrupt(&dec, &e.to_string()))?;
                data[c * frames + start..c * frames + start + len].copy_from_slice(&out);
            }
            if dec.overrun() > 0 {
                return Err(corrupt(&dec, "payload ends early"));
            }
        }
        if dec.overrun() > 0 || dec.position() + 1 < stream.payload.len() {
            return Err(corrupt(&dec, "payload length does not match its content"));
        }
        wrap_flagged(&mut data, frames, &flags);
        Ok(Clip::new(
            skeleton.clone(),
            stream.frame_rate_hz,
            frames,
            data,
        )?)
    }
}
