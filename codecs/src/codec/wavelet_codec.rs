//! The perceptual wavelet codec of paper 000 section III / thesis ch. 3, and its two baselines
//! from the same code path.
//!
//! Per slice of `W` frames (the last may be shorter, step 1; see (d)) and per channel `i` of
//! `N`:
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
//! What the text leaves open, decided here:
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
//! **(d) The short last slice** (a clip whose length is not a multiple of `W`) is coded at the
//! previous slice's operating point, not at its own share of α alone: under
//! [`Allocation::Position`] it keeps every coefficient the previous slice's threshold keeps (or
//! what its own share keeps, where that is more) and takes the previous slice's step (no coarser
//! than the threshold, floored for its own value range); under the printed rule each channel also
//! keeps every detail at least as large as `√(n/W)` times the smallest that channel kept in the
//! previous slice (QP bits per channel as before). Its own share broke it: a slice of `n` frames
//! has fewer levels, so its always-kept approximation band is a large part of `α·N·n` (6 of 22
//! coefficients per channel with D4), which at 20:1 leaves no detail budget; the step then came
//! from the largest weighted approximation coefficient (the root translation's) and every
//! low-sensitivity channel's mean rounded to zero (a 1 558-frame clip: 37 of 62 channels at exactly
//! 0 in its 22-frame tail). The same threshold and step is the same slope on the rate-distortion
//! curve, so the tail gets the bits its content needs at the clip's quality and the rate search
//! moves α for the rest. Merging the tail into the previous slice (the last slice `W..2W−1` frames)
//! was measured too: lower clip RMS, but the clip's last frames then lie at the periodized edge of
//! a long slice (a 2-frame tail up to 2.9× the clip's RMS at 60:1); overlapping windows code up to
//! `W − 1` frames twice. Nothing in the payload changes (a slice's step and counts were in the
//! stream already), so every decoder reads these streams.
//!
//! The printed rule's thresholds are per channel, so a channel that drifts through a short tail
//! (the root moving forward, a limb turning) kept only its approximation band at the unscaled
//! threshold, and the periodized ramp's edges then carried the tail's whole error:
//! `wavelet-standard` at 48:1 on 268- and 280-frame cuts of the synthetic walk had tails of
//! 3.0-3.2× the clip's RMS where no stretch of the same length inside the clip exceeded 1.2×
//! (`tests/short_window.rs` found it). The scale makes a dropped detail cost the same error per
//! frame as in the previous slice (its energy spreads over `n` frames, not `W`); it costs the
//! baselines' clip RMS between −12 % and +16 % at 20:1 on the shared clips (up to +24 % at 40:1 on
//! pirouette, where a 79-frame tail takes a larger part of a small budget). Under
//! [`Allocation::Position`] the same scale was measured too and left out: it brought the worst tail
//! from 2.25× to 1.07× but raised the clip RMS by up to 5 %.
//!
//! Rotation channels are unwrapped (jumps over 180° taken as wraps) before the transform and
//! wrapped back into (−180°, 180°] after decoding, for the channels where unwrapping changed
//! something (one flag per channel in the stream).
//!
//! Payload (format version [`PAYLOAD_VERSION`]): one version byte, the number of lanes `G`
//! (2, or 1 for a one-channel clip), the byte length of lanes 1..G−1 (`u32` LE each; the
//! last lane takes the rest), then the lanes. Lane `g` holds channels `⌈g·N/G⌉..⌈(g+1)·N/G⌉`
//! as one range-coded stream with its own models: their unwrap flags; per slice (position
//! allocation: the slice's step exponent, delta-coded, repeated in every lane) and per channel
//! the nonzero count, (printed rule: the channel's step exponent,) then (run, value) pairs with
//! per-band contexts; values are sign (direct bit) and `|v| − 1` (adaptive Exp-Golomb). Lanes
//! decode independently, on one thread each once the clip or its payload is large enough to
//! pay for it (see `decode_on_two_threads`). Streams of another version are refused.

use super::prep::{
    channel_lengths, is_translation, position_sensitivity, unwrapped_matrix, wrap_flagged,
};
use super::{
    Codec, CodecError, Params, RateControl, check_stream, decode_on_two_threads, header, int_param,
    keys, merged, params_of, real_param,
};
use crate::bitstream::Bitstream;
use crate::entropy::{
    BitModel, EntropyError, IntModel, NonzeroModel, RangeDecoder, RangeEncoder, UintModel,
};
use crate::wavelet::{Transform, Wavelet, band_lengths};
use motion::clip::{Clip, Skeleton};

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
/// always 0, the range coder's initial cache byte) and version 2 (one range-coded stream, no
/// lanes) are refused with a clear error.
pub const PAYLOAD_VERSION: u8 = 3;
/// Lanes the encoder splits the channels into: independent range-coded streams that a decoder
/// decodes on as many threads (a near-lossless 10 s clip holds ~10⁶ adaptive decisions, more
/// than one core decodes in 5 ms). Each lane's models learn on their own, which costs a few
/// dozen bytes per lane.
const LANES: usize = 2;
/// Most lanes a stream may declare.
const MAX_LANES: usize = 64;

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

/// Smallest and largest QP (`qp`): the rate search steps the quantizer within them too.
pub(crate) const QP_MIN: u32 = 4;
/// See [`QP_MIN`].
pub(crate) const QP_MAX: u32 = 16;

/// The parameters of a wavelet codec, read and range-checked once from [`Params`].
#[derive(Debug, Clone, Copy, PartialEq)]
struct WaveletSettings {
    /// Kept fraction α of the coefficients ([`keys::ALPHA`], 0..=1).
    alpha: f64,
    /// Quantization bits ([`keys::QP`], [`QP_MIN`]..=[`QP_MAX`]).
    qp: u32,
    /// Slice length in frames ([`keys::WINDOW`], 8..=4096).
    window: usize,
    /// Minimum kept coefficients per channel and slice ([`keys::C_MIN`], 0..=4096).
    c_min: usize,
    /// [`keys::WAVELET`].
    wavelet: Wavelet,
    /// [`keys::TRANSLATION`]: 0 comparable, 1 literal.
    translation: TranslationRule,
    /// [`keys::ALLOCATION`]: 0 position, 1 paper; `None` where the parameters lack the key
    /// (the baselines, which are the paper's rules).
    allocation: Option<Allocation>,
}

impl WaveletSettings {
    /// The defaults of the codec with `selection` (only `wavelet-perceptual` has an
    /// allocation, the position-aware one).
    fn defaults(selection: Selection) -> WaveletSettings {
        WaveletSettings {
            alpha: 0.1,
            qp: 10,
            window: 256,
            c_min: 0,
            wavelet: Wavelet::D4,
            translation: TranslationRule::Comparable,
            allocation: (selection == Selection::Perceptual).then_some(Allocation::Position),
        }
    }

    /// Reads the settings of codec `codec` from `p`, every key within its range (keys the
    /// codec does not know are not looked at).
    fn from_params(codec: &'static str, p: &Params) -> Result<WaveletSettings, CodecError> {
        let alpha = real_param(codec, p, keys::ALPHA, 0.0, 1.0)?;
        let qp = int_param(codec, p, keys::QP, QP_MIN.into(), QP_MAX.into())? as u32;
        let window = int_param(codec, p, keys::WINDOW, 8, 4096)? as usize;
        let c_min = int_param(codec, p, keys::C_MIN, 0, 4096)? as usize;
        let wavelet = Wavelet::from_id(int_param(codec, p, keys::WAVELET, 0, 1)? as u8)
            .unwrap_or(Wavelet::D4);
        let translation = if int_param(codec, p, keys::TRANSLATION, 0, 1)? == 0 {
            TranslationRule::Comparable
        } else {
            TranslationRule::Literal
        };
        let allocation = if p.contains_key(keys::ALLOCATION) {
            Some(if int_param(codec, p, keys::ALLOCATION, 0, 1)? == 0 {
                Allocation::Position
            } else {
                Allocation::Paper
            })
        } else {
            None
        };
        Ok(WaveletSettings {
            alpha,
            qp,
            window,
            c_min,
            wavelet,
            translation,
            allocation,
        })
    }

    /// The parameters a stream records (every key but [`keys::CR`]).
    fn to_params(self) -> Params {
        let translation = match self.translation {
            TranslationRule::Comparable => 0.0,
            TranslationRule::Literal => 1.0,
        };
        let mut p = params_of(&[
            (keys::ALPHA, self.alpha),
            (keys::QP, f64::from(self.qp)),
            (keys::WINDOW, self.window as f64),
            (keys::C_MIN, self.c_min as f64),
            (keys::WAVELET, f64::from(self.wavelet.id())),
            (keys::TRANSLATION, translation),
        ]);
        if let Some(a) = self.allocation {
            let code = match a {
                Allocation::Position => 0.0,
                Allocation::Paper => 1.0,
            };
            p.insert(keys::ALLOCATION.to_string(), code);
        }
        p
    }

    /// How the channels share coefficients and steps: [`Allocation::Paper`] without the key.
    fn allocation(self) -> Allocation {
        self.allocation.unwrap_or(Allocation::Paper)
    }
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

/// The lane (independent range-coded stream) of channel `c` of `n_ch` in `lanes` lanes:
/// contiguous, near-equal ranges of channels.
fn lane_of(c: usize, n_ch: usize, lanes: usize) -> usize {
    (c * lanes) / n_ch.max(1)
}

/// The channels of lane `g`: those `c` with `⌊c·lanes/n_ch⌋ = g` ([`lane_of`]), that is
/// `⌈g·n_ch/lanes⌉..⌈(g+1)·n_ch/lanes⌉`.
fn lane_channels(g: usize, n_ch: usize, lanes: usize) -> std::ops::Range<usize> {
    let bound = |g: usize| (g * n_ch).div_ceil(lanes.max(1)).min(n_ch);
    bound(g)..bound(g + 1)
}

/// One lane's range coder and models.
struct Lane {
    enc: RangeEncoder,
    m: Models,
}

/// Scratch and state of one encode.
struct Encoder {
    lanes: Vec<Lane>,
    t: Transform,
    coeffs: Vec<Vec<f64>>,
    prev_step: Vec<i64>,
    /// The previous slice's selection thresholds, which a short last slice is coded with
    /// (decision (d)): [`Allocation::Position`] uses entry 0 (the slice's threshold on
    /// `s_i·|c|`), the printed rule one per channel (the smallest kept detail magnitude,
    /// infinite where only the approximation band was kept).
    prev_thr: Vec<f64>,
    /// [`Allocation::Position`]: the previous slice's step before the floor that keeps every
    /// value within `MAX_VALUE_BITS` (each slice applies that floor for its own values).
    prev_delta: f64,
    mags: Vec<f64>,
    q: Vec<i64>,
    bands: Vec<u8>,
}

impl WaveletCodec {
    fn encode_native(self, clip: &Clip, s: &WaveletSettings) -> Result<Bitstream, CodecError> {
        let frames = clip.frames();
        let n_ch = clip.channel_count();
        let (data, flags) = unwrapped_matrix(clip);
        let kinds: Vec<bool> = clip
            .channels()
            .iter()
            .map(|c| is_translation(c.kind))
            .collect();
        let lanes = LANES.min(n_ch).max(1);
        let mut e = Encoder {
            lanes: (0..lanes)
                .map(|_| Lane {
                    enc: RangeEncoder::new(),
                    m: Models::new(),
                })
                .collect(),
            t: Transform::new(s.wavelet),
            coeffs: vec![Vec::new(); n_ch],
            prev_step: vec![0i64; n_ch],
            prev_thr: vec![f64::INFINITY; n_ch],
            prev_delta: 0.0,
            mags: Vec::new(),
            q: Vec::new(),
            bands: Vec::new(),
        };
        for (c, &f) in flags.iter().enumerate() {
            let l = &mut e.lanes[lane_of(c, n_ch, lanes)];
            l.enc.bit(&mut l.m.flag, f);
        }
        let weights = match (self.selection, s.allocation()) {
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
            // Decision (d): a short last slice is coded at its predecessor's thresholds.
            let borrow = len < s.window && start > 0;
            for c in 0..n_ch {
                let x = &data[c * frames + start..c * frames + start + len];
                e.t.forward(x, levels, &mut e.coeffs[c]);
                if weights.is_none() {
                    importance[c] = self.paper_importance(s, x, kinds[c], lens[c], max_len);
                }
            }
            match &weights {
                Some(w) => self.slice_position(s, &mut e, w, n_approx, c_eff, borrow)?,
                None => {
                    self.slice_paper(s, &mut e, &importance, &kinds, n_approx, c_eff, borrow)?;
                }
            }
        }
        // Version, lane count, the byte length of every lane but the last, the lanes.
        let coded: Vec<Vec<u8>> = e.lanes.into_iter().map(|l| l.enc.finish()).collect();
        let mut payload = vec![PAYLOAD_VERSION, lanes as u8];
        for lane in &coded[..lanes - 1] {
            let n = u32::try_from(lane.len())
                .map_err(|_| self.enc_err(&EntropyError::TooLarge(lane.len() as u64)))?;
            payload.extend_from_slice(&n.to_le_bytes());
        }
        for lane in &coded {
            payload.extend_from_slice(lane);
        }
        header(&self, clip, s.to_params(), payload)
    }

    /// Steps 2-3: `A_i` of one channel over a slice.
    fn paper_importance(
        self,
        s: &WaveletSettings,
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

    /// Steps 6-9 as printed: `K_i` per channel, QP bits per channel. With `borrow` (a short
    /// last slice, decision (d)) channel `i` also keeps every detail at least as large as the
    /// smallest it kept in the previous slice.
    #[expect(
        clippy::too_many_arguments,
        reason = "one slice's inputs; grouping them would only rename them"
    )]
    fn slice_paper(
        self,
        s: &WaveletSettings,
        e: &mut Encoder,
        importance: &[f64],
        kinds: &[bool],
        n_approx: usize,
        c_eff: usize,
        borrow: bool,
    ) -> Result<(), CodecError> {
        let n_ch = importance.len();
        let n_coef = e.bands.len();
        let sum_a: f64 = importance.iter().sum();
        let budget = s.alpha * (n_ch * n_coef) as f64;
        // Decision (d), printed rule: the previous slice's thresholds scaled by √(n/W).
        let tail_scale = (n_coef as f64 / s.window as f64).sqrt();
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
            let co = &mut e.coeffs[c];
            let k_share = if borrow {
                let thr = e.prev_thr[c] * tail_scale;
                k_share.max(n_approx + co[n_approx..].iter().filter(|v| v.abs() >= thr).count())
            } else {
                k_share
            };
            let k = k_share.max(c_eff).min(n_coef);
            // The approximation band always survives (decision (b)): it ranks first.
            keep_top(
                co,
                k,
                |i, v| if i < n_approx { f64::INFINITY } else { v.abs() },
                &mut e.mags,
            );
            e.prev_thr[c] = co[n_approx..]
                .iter()
                .filter(|v| **v != 0.0)
                .fold(f64::INFINITY, |a, v| a.min(v.abs()));
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
            let lanes = e.lanes.len();
            let l = &mut e.lanes[lane_of(c, n_ch, lanes)];
            l.m.nnz.encode(&mut l.enc, nnz as u32).map_err(err)?;
            if nnz > 0 {
                l.m.step
                    .encode(&mut l.enc, step_exp - e.prev_step[c])
                    .map_err(err)?;
                e.prev_step[c] = step_exp;
                code_pairs(&mut l.enc, &mut l.m, &e.q, &e.bands).map_err(err)?;
            }
        }
        Ok(())
    }

    /// Decision (c), [`Allocation::Position`]: one threshold and one step per slice in position
    /// units. With `borrow` (a short last slice, decision (d)) the threshold is the previous
    /// slice's where that one is lower, and the step the previous slice's, no coarser than the
    /// threshold.
    fn slice_position(
        self,
        s: &WaveletSettings,
        e: &mut Encoder,
        w: &[f64],
        n_approx: usize,
        c_eff: usize,
        borrow: bool,
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
        let mut thr = if k_detail == 0 {
            f64::INFINITY
        } else if k_detail >= n_detail {
            0.0
        } else {
            *e.mags
                .select_nth_unstable_by(n_detail - k_detail, f64::total_cmp)
                .1
        };
        if borrow {
            // Decision (d): the previous slice's threshold where it keeps more (it always
            // does where this slice's own share leaves no detail).
            thr = thr.min(e.prev_thr[0]);
        }
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
        if borrow {
            // Decision (d): the previous slice's step, no coarser than the threshold.
            delta = e.prev_delta;
            if thr.is_finite() && thr > 0.0 {
                delta = delta.min(STEP_OVER_THRESHOLD * thr);
            }
        }
        e.prev_thr[0] = thr;
        e.prev_delta = delta;
        // A threshold near zero (α ≈ 1 with near-constant channels) must not ask for more than
        // MAX_VALUE_BITS bits of any value.
        delta = delta.max(ymax.max(amax) * (-f64::from(MAX_VALUE_BITS)).exp2());
        let step_exp = if delta > 0.0 {
            ((delta.log2() * 8.0).floor() as i64).clamp(STEP_MIN, STEP_MAX)
        } else {
            e.prev_step[0]
        };
        // Every lane carries the slice's step, so each decodes on its own.
        for l in &mut e.lanes {
            l.m.step
                .encode(&mut l.enc, step_exp - e.prev_step[0])
                .map_err(|err| self.enc_err(&err))?;
        }
        e.prev_step[0] = step_exp;
        let delta = step_of(step_exp);
        for (c, &wc) in w.iter().enumerate() {
            let inv = wc / delta;
            e.q.clear();
            e.q.extend(e.coeffs[c].iter().map(|&v| round_i64(v * inv)));
            let nnz = e.q.iter().filter(|&&v| v != 0).count();
            let err = |err| self.enc_err(&err);
            let lanes = e.lanes.len();
            let l = &mut e.lanes[lane_of(c, n_ch, lanes)];
            l.m.nnz.encode(&mut l.enc, nnz as u32).map_err(err)?;
            if nnz > 0 {
                code_pairs(&mut l.enc, &mut l.m, &e.q, &e.bands).map_err(err)?;
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
        let mut p = WaveletSettings::defaults(self.selection).to_params();
        p.insert(keys::CR.to_string(), 0.0);
        p
    }

    fn rate_control(&self) -> RateControl {
        RateControl::Search {
            key: keys::ALPHA,
            min: 1e-4,
            max: 1.0,
            // ln CR falls by 0.9 per ln α between 10:1 and 60:1 on the shared clips.
            slope: 0.9,
        }
    }

    fn encode(&self, clip: &Clip, params: &Params) -> Result<Bitstream, CodecError> {
        let p = merged(self, params)?;
        // The rate search sets the knob (α) itself: the settings are read per encode it runs.
        let target = p.get(keys::CR).copied().unwrap_or(0.0);
        if target > 0.0 {
            return crate::rate::search(self, clip, &p, target).map(|s| s.stream);
        }
        self.encode_native(clip, &WaveletSettings::from_params(self.name(), &p)?)
    }

    fn decode(&self, stream: &Bitstream, skeleton: &Skeleton) -> Result<Clip, CodecError> {
        self.decode_lanes(stream, skeleton, decode_on_two_threads(stream))
    }
}

impl WaveletCodec {
    /// Decodes `stream`, its lanes on threads of their own when `threads` is set.
    fn decode_lanes(
        self,
        stream: &Bitstream,
        skeleton: &Skeleton,
        threads: bool,
    ) -> Result<Clip, CodecError> {
        check_stream(&self, stream, skeleton)?;
        let name = self.name();
        let mut p = self.default_params();
        p.extend(stream.params.iter().map(|(k, v)| (k.clone(), *v)));
        let s = WaveletSettings::from_params(name, &p)?;
        let frames = stream.frames as usize;
        let n_ch = stream.channels as usize;
        let at = |offset: usize, detail: &str| CodecError::Payload {
            codec: name,
            offset,
            detail: detail.to_string(),
        };
        let pl = &stream.payload;
        match pl.first() {
            Some(&PAYLOAD_VERSION) => {}
            Some(&v) => {
                return Err(at(
                    0,
                    &format!(
                        "payload format version {v}, this build reads version {PAYLOAD_VERSION} \
                         only (streams from before the version byte start with 0: re-encode the clip)"
                    ),
                ));
            }
            None => return Err(at(0, "empty payload")),
        }
        let spans = lane_spans(name, pl, n_ch)?;
        let lanes = spans.len();
        let weights = match (self.selection, s.allocation()) {
            (Selection::Perceptual, Allocation::Position) => {
                Some(channel_weights(skeleton, s.translation))
            }
            _ => None,
        };
        let kinds: Vec<bool> = skeleton
            .channel_layout()
            .iter()
            .map(|c| is_translation(c.kind))
            .collect();
        let ctx = LaneContext {
            codec: &self,
            s: &s,
            frames,
            weights: weights.as_deref(),
            kinds: &kinds,
        };
        // Each lane owns a contiguous block of channel rows.
        let mut data = vec![0.0; n_ch * frames];
        let mut jobs = Vec::with_capacity(lanes);
        let mut rest: &mut [f64] = &mut data;
        for (g, span) in spans.into_iter().enumerate() {
            let channels = lane_channels(g, n_ch, lanes);
            let (rows, tail) = std::mem::take(&mut rest).split_at_mut(channels.len() * frames);
            rest = tail;
            jobs.push((channels, span, rows));
        }
        let decode_lane = |(channels, span, rows): (
            std::ops::Range<usize>,
            std::ops::Range<usize>,
            &mut [f64],
        )| { ctx.lane(&pl[span.clone()], span.start, channels, rows) };
        let flags: Vec<Vec<bool>> = if lanes > 1 && threads {
            std::thread::scope(|scope| {
                let mut jobs = jobs.into_iter();
                let first = jobs.next();
                let handles: Vec<_> = jobs.map(|j| scope.spawn(move || decode_lane(j))).collect();
                let mut out = vec![first.map_or(Ok(Vec::new()), decode_lane)];
                for h in handles {
                    out.push(
                        h.join().unwrap_or_else(|_| {
                            Err(at(0, "a lane's decoder stopped unexpectedly"))
                        }),
                    );
                }
                out.into_iter().collect::<Result<Vec<_>, _>>()
            })?
        } else {
            jobs.into_iter()
                .map(decode_lane)
                .collect::<Result<Vec<_>, _>>()?
        };
        let flags: Vec<bool> = flags.into_iter().flatten().collect();
        wrap_flagged(&mut data, frames, &flags);
        Ok(Clip::new(
            skeleton.clone(),
            stream.frame_rate_hz,
            frames,
            data,
        )?)
    }
}

/// The byte ranges of a version-3 payload's lanes (after the version byte): the lane count,
/// checked against the channels, and every lane's extent, checked against the payload.
fn lane_spans(
    name: &'static str,
    pl: &[u8],
    n_ch: usize,
) -> Result<Vec<std::ops::Range<usize>>, CodecError> {
    let at = |offset: usize, detail: &str| CodecError::Payload {
        codec: name,
        offset,
        detail: detail.to_string(),
    };
    // Lanes: count, the lengths of all but the last, the streams.
    let lanes = usize::from(*pl.get(1).ok_or_else(|| at(1, "no lane count"))?);
    if lanes == 0 || lanes > MAX_LANES || lanes > n_ch.max(1) {
        return Err(at(1, &format!("{lanes} lanes for {n_ch} channels")));
    }
    let mut spans = Vec::with_capacity(lanes);
    let mut start = 2 + 4 * (lanes - 1);
    if start > pl.len() {
        return Err(at(2, "lane lengths truncated"));
    }
    for g in 0..lanes {
        let end = if g + 1 < lanes {
            let b = &pl[2 + 4 * g..6 + 4 * g];
            let n = u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize;
            start
                .checked_add(n)
                .filter(|&e| e <= pl.len())
                .ok_or_else(|| at(2 + 4 * g, "lane longer than the payload"))?
        } else {
            pl.len()
        };
        spans.push(start..end);
        start = end;
    }
    Ok(spans)
}

/// What every lane's decoder shares.
struct LaneContext<'a> {
    codec: &'a WaveletCodec,
    s: &'a WaveletSettings,
    frames: usize,
    weights: Option<&'a [f64]>,
    kinds: &'a [bool],
}

impl LaneContext<'_> {
    /// Decodes one lane (`body`, at byte `offset` of the payload) into the rows of its
    /// `channels`; returns their unwrap flags.
    fn lane(
        &self,
        body: &[u8],
        offset: usize,
        channels: std::ops::Range<usize>,
        rows: &mut [f64],
    ) -> Result<Vec<bool>, CodecError> {
        let (s, frames, name) = (self.s, self.frames, self.codec.name());
        let corrupt = |dec: &RangeDecoder<'_>, detail: &str| CodecError::Payload {
            codec: name,
            offset: offset + dec.position(),
            detail: detail.to_string(),
        };
        let mut dec = RangeDecoder::new(body);
        let mut m = Models::new();
        let flags: Vec<bool> = channels.clone().map(|_| dec.bit(&mut m.flag)).collect();
        let mut t = Transform::new(s.wavelet);
        let mut co = Vec::new();
        let mut out = Vec::new();
        let mut bands = Vec::new();
        let mut prev_step = vec![0i64; channels.len()];
        let mut slice_prev = 0i64;
        for (start, len) in slices(frames, s.window) {
            let levels = s.wavelet.max_level(len);
            band_map(len, levels, &mut bands);
            let n_coef = bands.len();
            let mut slice_step = 0.0;
            if self.weights.is_some() {
                let ds = m
                    .step
                    .decode(&mut dec)
                    .ok_or_else(|| corrupt(&dec, "step"))?;
                let step_exp = slice_prev.saturating_add(ds);
                if !(STEP_MIN..=STEP_MAX).contains(&step_exp) {
                    return Err(corrupt(&dec, "quantizer step out of range"));
                }
                slice_prev = step_exp;
                slice_step = step_of(step_exp);
            }
            for (r, c) in channels.clone().enumerate() {
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
                    let (step, qlim) = if let Some(w) = self.weights {
                        (slice_step / w[c], i64::from(UintModel::MAX) + 1)
                    } else {
                        let ds = m
                            .step
                            .decode(&mut dec)
                            .ok_or_else(|| corrupt(&dec, "step"))?;
                        let step_exp = prev_step[r].saturating_add(ds);
                        if !(STEP_MIN..=STEP_MAX).contains(&step_exp) {
                            return Err(corrupt(&dec, "quantizer step out of range"));
                        }
                        prev_step[r] = step_exp;
                        let qp = if self.kinds[c] && s.translation == TranslationRule::Comparable {
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
                rows[r * frames + start..r * frames + start + len].copy_from_slice(&out);
            }
            if dec.overrun() > 0 {
                return Err(corrupt(&dec, "payload ends early"));
            }
        }
        if dec.overrun() > 0 || dec.position() + 1 < body.len() {
            return Err(corrupt(&dec, "lane length does not match its content"));
        }
        Ok(flags)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::synth::{WalkParams, walking_clip};

    /// The settings read back what they record, and the defaults are the default parameters.
    #[test]
    fn settings_round_trip_through_params() {
        for selection in [
            Selection::Perceptual,
            Selection::Standard,
            Selection::BoneLength,
        ] {
            let c = WaveletCodec::new(selection);
            let mut defaults = c.default_params();
            assert_eq!(defaults.remove(keys::CR), Some(0.0));
            let s = WaveletSettings::from_params(c.name(), &defaults).unwrap();
            assert_eq!(s, WaveletSettings::defaults(selection));
            assert_eq!(s.to_params(), defaults);
            let other = WaveletSettings {
                alpha: 0.37,
                qp: 13,
                window: 64,
                c_min: 5,
                wavelet: Wavelet::Cdf97,
                translation: TranslationRule::Literal,
                allocation: s.allocation.map(|_| Allocation::Paper),
            };
            let back = WaveletSettings::from_params(c.name(), &other.to_params()).unwrap();
            assert_eq!(back, other);
        }
    }

    #[test]
    fn lane_channels_are_the_channels_lane_of_assigns() {
        for n_ch in 1..40 {
            for lanes in 1..=n_ch.min(MAX_LANES) {
                for g in 0..lanes {
                    let want: Vec<usize> = (0..n_ch)
                        .filter(|&c| lane_of(c, n_ch, lanes) == g)
                        .collect();
                    let got: Vec<usize> = lane_channels(g, n_ch, lanes).collect();
                    assert_eq!(got, want, "{n_ch} channels, {lanes} lanes, lane {g}");
                }
            }
        }
    }

    /// The lanes are independent: decoding them on threads (forced here; `decode` does it for
    /// clips of 16 Ki values or payloads of 16 KiB) gives exactly what decoding them one after
    /// the other gives.
    #[test]
    fn lanes_on_threads_decode_exactly_as_in_sequence() {
        let clip = walking_clip(&WalkParams {
            duration_s: 8.0,
            ..WalkParams::default()
        });
        let c = WaveletCodec::new(Selection::Perceptual);
        let mut p = Params::new();
        p.insert(keys::ALPHA.into(), 1.0);
        p.insert(keys::QP.into(), 12.0);
        let s = c.encode(&clip, &p).unwrap();
        assert_eq!(s.payload[1], 2);
        let threaded = c.decode_lanes(&s, &clip.skeleton, true).unwrap();
        let sequential = c.decode_lanes(&s, &clip.skeleton, false).unwrap();
        assert_eq!(threaded.data(), sequential.data());
    }
}
