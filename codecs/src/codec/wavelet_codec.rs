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
//! **(c) Position-aware allocation** ([`Allocation::Position`], `allocation = 0`, the default of
//! `wavelet-perceptual`). The paper's `l_i` stands for how much a channel's error moves the
//! body; [`Allocation::Position`] measures that directly: `s_i`, the channel's first-order
//! position sensitivity (RMS displacement of all FK points per degree or per unit, from the
//! skeleton's rest geometry, so the decoder derives the same numbers). A coefficient `c` of
//! channel `i` then removes about `(s_i·c)²` of squared joint error (D4 is orthonormal), so the
//! slice keeps its `K = α·N·W` coefficients with the largest `s_i·|c|` (approximation bands and
//! the minimum `C` per channel first, as in (b)), which makes each `K_i` the share that equalises
//! the position error removed per coefficient across channels, and it quantizes all channels
//! with one step `Δ` in position units (`Δ/s_i` per channel): the largest detail takes QP bits
//! and `Δ` is never coarser than the selection threshold. Root translations enter with their
//! true sensitivity (1), which settles (a) without the degree conversion; `translation = 1`
//! treats their units as degrees of the root's rotation instead. On the shared clips this
//! halves the joint RMS error of the printed rule at 20:1 and 40:1 (`docs/codecs.md`;
//! `tests/codecs.rs::position_allocation_beats_the_printed_rule`). The printed rule stays as
//! `allocation = 1`; `wavelet-standard` and `wavelet-bone` are always the printed baselines.
//!
//! Rotation channels are unwrapped (jumps over 180° taken as wraps) before the transform and
//! wrapped back into (−180°, 180°] after decoding, for the channels where unwrapping changed
//! something (one flag per channel in the stream).
//!
//! Payload (format version [`PAYLOAD_VERSION`]): one version byte, then one range-coded stream:
//! unwrap flags; per slice (position allocation: the slice's step exponent, delta-coded) and per
//! channel the nonzero count, (printed rule: the channel's step exponent,) then (run, value)
//! pairs with per-band contexts; values are sign (direct bit) and `|v| − 1` (adaptive
//! Exp-Golomb). Streams of another version are refused.

use super::prep::{
    channel_lengths, is_translation, position_sensitivity, unwrapped_matrix, wrap_flagged,
};
use super::{
    Codec, CodecError, Params, RateControl, check_stream, header, int_param, merged, real_param,
};
use crate::bitstream::Bitstream;
use crate::clip::{Clip, Skeleton};
use crate::entropy::{
    BitModel, EntropyError, IntModel, NonzeroModel, RangeDecoder, RangeEncoder, UintModel,
};
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

/// How [`Selection::Perceptual`] turns the importance of a channel into kept coefficients and
/// quantizer steps (the `allocation` parameter; decision (c) in the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Allocation {
    /// `l_i` is the channel's first-order position sensitivity `s_i`; coefficients are kept by
    /// the position error they remove (`|c|·s_i` against one threshold per slice) and quantized
    /// with one step per slice in position units (`Δ/s_i` per channel). Default.
    Position,
    /// The paper as printed: `K_i = max(α·A_i·N·W / ΣA_j, C)`, `A_i = l_i·v_i` with the
    /// normalized bone length, QP bits per channel.
    Paper,
}

/// Payload format version (first payload byte). Version 1 (no version byte; its first byte is
/// always 0, the range coder's initial cache byte) is refused with a clear error.
pub const PAYLOAD_VERSION: u8 = 2;
/// Extra quantization bits of translation channels under [`TranslationRule::Comparable`].
const TRANSLATION_EXTRA_QP: u32 = 4;
/// Contexts: one per band, deeper bands share the last.
const BAND_CONTEXTS: usize = 12;
/// Quantizer step exponent range (`Δ = 2^(s/8)`).
const STEP_MIN: i64 = -512;
const STEP_MAX: i64 = 512;
/// [`Allocation::Position`]: quantizer step over the slice's selection threshold.
const STEP_OVER_THRESHOLD: f64 = 1.0;
/// [`Allocation::Position`]: the step is never finer than the slice's largest weighted value
/// over `2^MAX_VALUE_BITS`, so every quantized value fits the entropy coder.
const MAX_VALUE_BITS: u32 = 28;
/// [`Allocation::Position`]: sensitivities are floored at this fraction of the largest, so a
/// channel that moves no joint (at the rest pose) is still coded, coarsely.
const SENSITIVITY_FLOOR: f64 = 1e-3;

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
    allocation: Allocation,
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
    // Only wavelet-perceptual has the key; the baselines are the paper's rules.
    let allocation = if p.contains_key("allocation") && int_param(name, p, "allocation", 0, 1)? == 0
    {
        Allocation::Position
    } else {
        Allocation::Paper
    };
    Ok(Settings {
        alpha,
        qp,
        window,
        c_min,
        wavelet,
        translation,
        allocation,
    })
}

/// Per-band context index of every coefficient position of a slice layout.
fn band_map(n: usize, levels: usize, out: &mut Vec<u8>) {
    out.clear();
    for (b, &len) in band_lengths(n, levels).iter().enumerate() {
        out.extend(std::iter::repeat_n(b.min(BAND_CONTEXTS - 1) as u8, len));
    }
}

struct Models {
    run: Vec<UintModel>,
    value: Vec<NonzeroModel>,
    nnz: UintModel,
    step: IntModel,
    flag: BitModel,
}

impl Models {
    fn new() -> Models {
        Models {
            run: vec![UintModel::default(); BAND_CONTEXTS],
            value: vec![NonzeroModel::default(); BAND_CONTEXTS],
            nnz: UintModel::default(),
            step: IntModel::default(),
            flag: BitModel::default(),
        }
    }
}

fn slices(frames: usize, window: usize) -> impl Iterator<Item = (usize, usize)> {
    (0..frames.div_ceil(window)).map(move |k| (k * window, window.min(frames - k * window)))
}

/// [`Allocation::Position`] weights: position sensitivity per channel (translations taken
/// literally get the root rotation's sensitivity, as if their units were degrees), floored.
fn channel_weights(skeleton: &Skeleton, rule: TranslationRule) -> Vec<f64> {
    let mut w = position_sensitivity(skeleton);
    let layout = skeleton.channel_layout();
    if rule == TranslationRule::Literal {
        for (c, ch) in layout.iter().enumerate() {
            if is_translation(ch.kind) {
                w[c] = layout
                    .iter()
                    .zip(&position_sensitivity(skeleton))
                    .filter(|(o, _)| o.joint == ch.joint && o.kind.is_rotation())
                    .map(|(_, &s)| s)
                    .fold(0.0, f64::max);
            }
        }
    }
    let max = w.iter().copied().fold(0.0, f64::max);
    let floor = if max > 0.0 {
        max * SENSITIVITY_FLOOR
    } else {
        1.0
    };
    w.iter().map(|&v| v.max(floor)).collect()
}

/// Rounds half away from zero without a libm call.
#[inline]
fn round_i64(v: f64) -> i64 {
    (v + 0.5f64.copysign(v)) as i64
}

/// Step `2^(e/8)`.
fn step_of(e: i64) -> f64 {
    (e as f64 / 8.0).exp2()
}

/// Zeroes all but the `k` largest coefficients of `co` by `rank` (exact count, ties in order).
#[expect(
    clippy::float_cmp,
    reason = "ties at the K-th rank are resolved exactly"
)]
fn keep_top(co: &mut [f64], k: usize, rank: impl Fn(usize, f64) -> f64, mags: &mut Vec<f64>) {
    let n = co.len();
    if k >= n {
        return;
    }
    mags.clear();
    mags.extend(co.iter().enumerate().map(|(i, &v)| rank(i, v)));
    let (_, &mut thr, _) = mags.select_nth_unstable_by(n - k, f64::total_cmp);
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

/// Steps 8-9 for one channel of a slice: (run of zeros, value) pairs, after its nonzero count.
fn code_pairs(
    enc: &mut RangeEncoder,
    m: &mut Models,
    q: &[i64],
    bands: &[u8],
) -> Result<(), EntropyError> {
    let mut pos = 0usize;
    for (i, &v) in q.iter().enumerate() {
        if v != 0 {
            m.run[usize::from(bands[pos])].encode(enc, (i - pos) as u32)?;
            m.value[usize::from(bands[i])].encode(enc, v)?;
            pos = i + 1;
        }
    }
    Ok(())
}

/// Scratch and state of one encode.
struct Encoder {
    enc: RangeEncoder,
    m: Models,
    t: Transform,
    coeffs: Vec<Vec<f64>>,
    prev_step: Vec<i64>,
    mags: Vec<f64>,
    q: Vec<i64>,
    bands: Vec<u8>,
}

impl WaveletCodec {
    fn encode_native(self, clip: &Clip, p: Params) -> Result<Bitstream, CodecError> {
        let s = settings(self.name(), &p)?;
        let frames = clip.frames();
        let n_ch = clip.channel_count();
        let (data, flags) = unwrapped_matrix(clip);
        let kinds: Vec<bool> = clip
            .channels()
            .iter()
            .map(|c| is_translation(c.kind))
            .collect();
        let mut e = Encoder {
            enc: RangeEncoder::new(),
            m: Models::new(),
            t: Transform::new(s.wavelet),
            coeffs: vec![Vec::new(); n_ch],
            prev_step: vec![0i64; n_ch],
            mags: Vec::new(),
            q: Vec::new(),
            bands: Vec::new(),
        };
        for &f in &flags {
            e.enc.bit(&mut e.m.flag, f);
        }
        let weights = match (self.selection, s.allocation) {
            (Selection::Perceptual, Allocation::Position) => {
                Some(channel_weights(&clip.skeleton, s.translation))
            }
            _ => None,
        };
        let (lens, max_len) = channel_lengths(clip);
        let mut importance = vec![0.0; n_ch];
        for (start, len) in slices(frames, s.window) {
            let levels = s.wavelet.max_level(len);
            band_map(len, levels, &mut e.bands);
            let n_coef = e.bands.len();
            let n_approx = band_lengths(len, levels)[0];
            let c_eff = s.c_min.max(n_approx).min(n_coef);
            for c in 0..n_ch {
                let x = &data[c * frames + start..c * frames + start + len];
                e.t.forward(x, levels, &mut e.coeffs[c]);
                if weights.is_none() {
                    importance[c] = self.paper_importance(&s, x, kinds[c], lens[c], max_len);
                }
            }
            match &weights {
                Some(w) => self.slice_position(&s, &mut e, w, n_approx, c_eff)?,
                None => self.slice_paper(&s, &mut e, &importance, &kinds, n_approx, c_eff)?,
            }
        }
        let mut payload = vec![PAYLOAD_VERSION];
        payload.extend_from_slice(&e.enc.finish());
        let mut out = p;
        out.remove("cr");
        header(&self, clip, out, payload)
    }

    /// Steps 2-3: `A_i` of one channel over a slice.
    fn paper_importance(
        self,
        s: &Settings,
        x: &[f64],
        translation: bool,
        len: f64,
        max_len: f64,
    ) -> f64 {
        let v = x.windows(2).map(|w| (w[1] - w[0]).abs()).sum::<f64>() / x.len() as f64;
        let (l, v) = match (translation, s.translation) {
            (true, TranslationRule::Comparable) => {
                (1.0, v * 180.0 / std::f64::consts::PI / max_len)
            }
            _ => (len / max_len, v),
        };
        match self.selection {
            Selection::Perceptual => l * v,
            Selection::BoneLength => l,
            Selection::Standard => 1.0,
        }
    }

    /// Steps 6-9 as printed: `K_i` per channel, QP bits per channel.
    fn slice_paper(
        self,
        s: &Settings,
        e: &mut Encoder,
        importance: &[f64],
        kinds: &[bool],
        n_approx: usize,
        c_eff: usize,
    ) -> Result<(), CodecError> {
        let n_ch = importance.len();
        let n_coef = e.bands.len();
        let sum_a: f64 = importance.iter().sum();
        let budget = s.alpha * (n_ch * n_coef) as f64;
        // Shares are rounded by carrying the remainder from channel to channel, so the slice
        // keeps round(α·N·W) coefficients in total and the rate moves smoothly with α.
        let mut acc = 0.0f64;
        for c in 0..n_ch {
            // Step 6: K_i = max(α A_i N W / Σ A_j, C).
            let share = if sum_a > 0.0 {
                budget * importance[c] / sum_a
            } else {
                s.alpha * n_coef as f64
            };
            let k_share = ((acc + share).round() - acc.round()).max(0.0) as usize;
            acc += share;
            let k = k_share.max(c_eff).min(n_coef);
            let co = &mut e.coeffs[c];
            // The approximation band always survives (decision (b)): it ranks first.
            keep_top(
                co,
                k,
                |i, v| if i < n_approx { f64::INFINITY } else { v.abs() },
                &mut e.mags,
            );
            // Step 7: linear quantization into QP bits.
            let qp = if kinds[c] && s.translation == TranslationRule::Comparable {
                s.qp + TRANSLATION_EXTRA_QP
            } else {
                s.qp
            };
            let qmax = f64::from((1u32 << (qp - 1)) - 1);
            let maxabs = co.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            e.q.clear();
            let mut step_exp = e.prev_step[c];
            if maxabs > 0.0 {
                step_exp = (((maxabs / qmax).log2() * 8.0).ceil() as i64).clamp(STEP_MIN, STEP_MAX);
                let inv = 1.0 / step_of(step_exp);
                e.q.extend(co.iter().map(|&v| round_i64(v * inv)));
            } else {
                e.q.resize(n_coef, 0);
            }
            // Steps 8-9: nonzero count, step, run-length of zeros, range coded.
            let nnz = e.q.iter().filter(|&&v| v != 0).count();
            let err = |err| self.enc_err(&err);
            e.m.nnz.encode(&mut e.enc, nnz as u32).map_err(err)?;
            if nnz > 0 {
                e.m.step
                    .encode(&mut e.enc, step_exp - e.prev_step[c])
                    .map_err(err)?;
                e.prev_step[c] = step_exp;
                code_pairs(&mut e.enc, &mut e.m, &e.q, &e.bands).map_err(err)?;
            }
        }
        Ok(())
    }

    /// Decision (c), [`Allocation::Position`]: one threshold and one step per slice in position
    /// units.
    fn slice_position(
        self,
        s: &Settings,
        e: &mut Encoder,
        w: &[f64],
        n_approx: usize,
        c_eff: usize,
    ) -> Result<(), CodecError> {
        let n_ch = w.len();
        let n_coef = e.bands.len();
        // Threshold: the K-th largest position-weighted detail, K = α·N·W less the
        // approximation bands (always kept, decision (b)).
        let k_total = (s.alpha * (n_ch * n_coef) as f64).round() as usize;
        let k_detail = k_total.saturating_sub(n_ch * n_approx);
        e.mags.clear();
        for (co, &wc) in e.coeffs.iter().zip(w) {
            e.mags.extend(co[n_approx..].iter().map(|v| v.abs() * wc));
        }
        let n_detail = e.mags.len();
        let thr = if k_detail == 0 {
            f64::INFINITY
        } else if k_detail >= n_detail {
            0.0
        } else {
            *e.mags
                .select_nth_unstable_by(n_detail - k_detail, f64::total_cmp)
                .1
        };
        let (mut ymax, mut amax) = (0.0f64, 0.0f64);
        for (c, &wc) in w.iter().enumerate() {
            let co = &mut e.coeffs[c];
            let kept = co[n_approx..]
                .iter()
                .filter(|v| v.abs() * wc >= thr)
                .count();
            if kept + n_approx < c_eff {
                keep_top(
                    co,
                    c_eff,
                    |i, v| if i < n_approx { f64::INFINITY } else { v.abs() },
                    &mut e.mags,
                );
            } else {
                for v in &mut co[n_approx..] {
                    if v.abs() * wc < thr {
                        *v = 0.0;
                    }
                }
            }
            ymax = co[n_approx..].iter().fold(ymax, |a, v| a.max(v.abs() * wc));
            amax = co[..n_approx].iter().fold(amax, |a, v| a.max(v.abs() * wc));
        }
        // Step 7 in position units: QP bits for the slice's largest weighted detail (the
        // approximation band when no detail is kept), no coarser than the selection threshold.
        // The approximation band (a slice's mean and slow drift: metres of root travel) may take
        // more than QP bits; the entropy coder has no fixed width.
        let qmax = f64::from((1u32 << (s.qp - 1)) - 1);
        let mut delta = if ymax > 0.0 { ymax } else { amax } / qmax;
        if thr.is_finite() && thr > 0.0 {
            delta = delta.min(STEP_OVER_THRESHOLD * thr);
        }
        // A threshold near zero (α ≈ 1 with near-constant channels) must not ask for more than
        // MAX_VALUE_BITS bits of any value.
        delta = delta.max(ymax.max(amax) * (-f64::from(MAX_VALUE_BITS)).exp2());
        let step_exp = if delta > 0.0 {
            ((delta.log2() * 8.0).floor() as i64).clamp(STEP_MIN, STEP_MAX)
        } else {
            e.prev_step[0]
        };
        e.m.step
            .encode(&mut e.enc, step_exp - e.prev_step[0])
            .map_err(|err| self.enc_err(&err))?;
        e.prev_step[0] = step_exp;
        let delta = step_of(step_exp);
        for (c, &wc) in w.iter().enumerate() {
            let inv = wc / delta;
            e.q.clear();
            e.q.extend(e.coeffs[c].iter().map(|&v| round_i64(v * inv)));
            let nnz = e.q.iter().filter(|&&v| v != 0).count();
            let err = |err| self.enc_err(&err);
            e.m.nnz.encode(&mut e.enc, nnz as u32).map_err(err)?;
            if nnz > 0 {
                code_pairs(&mut e.enc, &mut e.m, &e.q, &e.bands).map_err(err)?;
            }
        }
        Ok(())
    }

    fn enc_err(self, e: &EntropyError) -> CodecError {
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
        let mut p: Params = [
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
        .collect();
        if self.selection == Selection::Perceptual {
            p.insert("allocation".into(), 0.0);
        }
        p
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

    #[expect(
        clippy::too_many_lines,
        reason = "mirrors the encoder's two allocations step by step"
    )]
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
            offset: 1 + dec.position(),
            detail: detail.to_string(),
        };
        match stream.payload.first() {
            Some(&PAYLOAD_VERSION) => {}
            Some(&v) => {
                return Err(CodecError::Payload {
                    codec: name,
                    offset: 0,
                    detail: format!(
                        "payload format version {v}, this build reads version {PAYLOAD_VERSION} \
                         only (streams from before the version byte start with 0: re-encode the clip)"
                    ),
                });
            }
            None => {
                return Err(CodecError::Payload {
                    codec: name,
                    offset: 0,
                    detail: "empty payload".into(),
                });
            }
        }
        let body = &stream.payload[1..];
        let mut data = vec![0.0; n_ch * frames];
        let mut dec = RangeDecoder::new(body);
        let mut m = Models::new();
        let flags: Vec<bool> = (0..n_ch).map(|_| dec.bit(&mut m.flag)).collect();
        let kinds: Vec<bool> = skeleton
            .channel_layout()
            .iter()
            .map(|c| is_translation(c.kind))
            .collect();
        let weights = match (self.selection, s.allocation) {
            (Selection::Perceptual, Allocation::Position) => {
                Some(channel_weights(skeleton, s.translation))
            }
            _ => None,
        };
        let mut t = Transform::new(s.wavelet);
        let mut co = Vec::new();
        let mut out = Vec::new();
        let mut bands = Vec::new();
        let mut prev_step = vec![0i64; n_ch];
        for (start, len) in slices(frames, s.window) {
            let levels = s.wavelet.max_level(len);
            band_map(len, levels, &mut bands);
            let n_coef = bands.len();
            let mut slice_step = 0.0;
            if weights.is_some() {
                let ds = m
                    .step
                    .decode(&mut dec)
                    .ok_or_else(|| corrupt(&dec, "step"))?;
                let step_exp = prev_step[0].saturating_add(ds);
                if !(STEP_MIN..=STEP_MAX).contains(&step_exp) {
                    return Err(corrupt(&dec, "quantizer step out of range"));
                }
                prev_step[0] = step_exp;
                slice_step = step_of(step_exp);
            }
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
                    let (step, qlim) = if let Some(w) = &weights {
                        (slice_step / w[c], i64::from(UintModel::MAX) + 1)
                    } else {
                        let ds = m
                            .step
                            .decode(&mut dec)
                            .ok_or_else(|| corrupt(&dec, "step"))?;
                        let step_exp = prev_step[c].saturating_add(ds);
                        if !(STEP_MIN..=STEP_MAX).contains(&step_exp) {
                            return Err(corrupt(&dec, "quantizer step out of range"));
                        }
                        prev_step[c] = step_exp;
                        let qp = if kinds[c] && s.translation == TranslationRule::Comparable {
                            s.qp + TRANSLATION_EXTRA_QP
                        } else {
                            s.qp
                        };
                        (step_of(step_exp), i64::from(1u32 << (qp - 1)))
                    };
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
                        if v.abs() > qlim {
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
        if dec.overrun() > 0 || dec.position() + 1 < body.len() {
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
