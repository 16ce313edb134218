//! Multi-level 1-D discrete wavelet transforms that match PyWavelets exactly.
//!
//! Two wavelets, as the seeds use them:
//! - [`Wavelet::D4`]: Daubechies D4 (4 taps), PyWavelets `db2`. Paper 000 / thesis ch. 3 use it.
//! - [`Wavelet::Cdf97`]: Cohen–Daubechies–Feauveau 9/7, PyWavelets `bior4.4` (filters padded to
//!   10 taps). The usual choice for SPIHT (thesis ch. 6).
//!
//! # Boundary handling
//! Both are computed as periodic filter banks with PyWavelets' `mode='periodization'`: a level of
//! length `n` gives `ceil(n / 2)` approximation and `ceil(n / 2)` detail coefficients. An odd
//! length is first extended by repeating its last sample (PyWavelets does the same), so a window
//! whose length is not a power of two — the last short slice of a clip, say 343 frames — is
//! transformed without padding to a power of two; the inverse drops the extra sample again.
//! Coefficients agree with `pywt.wavedec(x, w, mode='periodization', level=L)` to 1e-12 (see
//! `tests/wavelet_golden.rs` and `scripts/golden/pywt_coeffs.py`), and the inverse reconstructs
//! the input to rounding error (D4 is orthogonal; PyWavelets' bior4.4 filters are printed to 17
//! digits and reconstruct to ~1e-12).
//!
//! Analysis, as PyWavelets computes it (`N` the even, extended length, `L` the filter length):
//! `a[i] = Σ_j dec_lo[j] · x[(2i + L/2 − j) mod N]`, and the same with `dec_hi` for `d[i]`.
//! Synthesis is the transpose with the reconstruction filters.
//!
//! # Layout
//! A decomposition of `levels` levels is one flat buffer in PyWavelets' order
//! `[cA_L, cD_L, cD_{L-1}, …, cD_1]`; [`band_lengths`] gives the band sizes.

/// A wavelet filter bank.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Wavelet {
    /// Daubechies D4 (PyWavelets `db2`), orthogonal, 4 taps.
    D4,
    /// CDF 9/7 (PyWavelets `bior4.4`), biorthogonal, 9/7 taps padded to 10.
    Cdf97,
}

/// A filter bank of `L` taps; the decomposition filters are stored reversed (`rdec_lo[m] =
/// dec_lo[L − 1 − m]`) so that analysis is a forward dot product over a window.
struct Filters<const L: usize> {
    rdec_lo: [f64; L],
    rdec_hi: [f64; L],
    rec_lo: [f64; L],
    rec_hi: [f64; L],
}

const fn reversed<const L: usize>(f: [f64; L]) -> [f64; L] {
    let mut out = [0.0; L];
    let mut i = 0;
    while i < L {
        out[i] = f[L - 1 - i];
        i += 1;
    }
    out
}

// Filter values exactly as PyWavelets 1.8 prints them (`pywt.Wavelet(name).dec_lo` ...).
static D4_FILTERS: Filters<4> = Filters {
    rdec_lo: reversed([
        -0.129_409_522_551_260_37,
        0.224_143_868_042_013_4,
        0.836_516_303_737_807_9,
        0.482_962_913_144_534_16,
    ]),
    rdec_hi: reversed([
        -0.482_962_913_144_534_16,
        0.836_516_303_737_807_9,
        -0.224_143_868_042_013_4,
        -0.129_409_522_551_260_37,
    ]),
    rec_lo: [
        0.482_962_913_144_534_16,
        0.836_516_303_737_807_9,
        0.224_143_868_042_013_4,
        -0.129_409_522_551_260_37,
    ],
    rec_hi: [
        -0.129_409_522_551_260_37,
        -0.224_143_868_042_013_4,
        0.836_516_303_737_807_9,
        -0.482_962_913_144_534_16,
    ],
};

static CDF97_FILTERS: Filters<10> = Filters {
    rdec_lo: reversed([
        0.0,
        0.037_828_455_507_264_04,
        -0.023_849_465_019_556_843,
        -0.110_624_404_418_437_18,
        0.377_402_855_612_830_66,
        0.852_698_679_008_893_8,
        0.377_402_855_612_830_66,
        -0.110_624_404_418_437_18,
        -0.023_849_465_019_556_843,
        0.037_828_455_507_264_04,
    ]),
    rdec_hi: reversed([
        0.0,
        -0.064_538_882_628_697_06,
        0.040_689_417_609_164_06,
        0.418_092_273_221_617_24,
        -0.788_485_616_405_582_9,
        0.418_092_273_221_617_24,
        0.040_689_417_609_164_06,
        -0.064_538_882_628_697_06,
        0.0,
        0.0,
    ]),
    rec_lo: [
        0.0,
        -0.064_538_882_628_697_06,
        -0.040_689_417_609_164_06,
        0.418_092_273_221_617_24,
        0.788_485_616_405_582_9,
        0.418_092_273_221_617_24,
        -0.040_689_417_609_164_06,
        -0.064_538_882_628_697_06,
        0.0,
        0.0,
    ],
    rec_hi: [
        0.0,
        -0.037_828_455_507_264_04,
        -0.023_849_465_019_556_843,
        0.110_624_404_418_437_18,
        0.377_402_855_612_830_66,
        -0.852_698_679_008_893_8,
        0.377_402_855_612_830_66,
        0.110_624_404_418_437_18,
        -0.023_849_465_019_556_843,
        -0.037_828_455_507_264_04,
    ],
};

impl Wavelet {
    /// Both wavelets.
    pub const ALL: [Wavelet; 2] = [Wavelet::D4, Wavelet::Cdf97];

    /// Short name used on the command line and in parameters: `d4`, `cdf97`.
    pub fn name(self) -> &'static str {
        match self {
            Wavelet::D4 => "d4",
            Wavelet::Cdf97 => "cdf97",
        }
    }

    /// The PyWavelets name: `db2`, `bior4.4`.
    pub fn pywt_name(self) -> &'static str {
        match self {
            Wavelet::D4 => "db2",
            Wavelet::Cdf97 => "bior4.4",
        }
    }

    /// Parses [`Wavelet::name`] or [`Wavelet::pywt_name`].
    pub fn from_name(name: &str) -> Option<Wavelet> {
        Wavelet::ALL
            .into_iter()
            .find(|w| w.name() == name || w.pywt_name() == name)
    }

    /// A one-byte id for bitstreams.
    pub fn id(self) -> u8 {
        match self {
            Wavelet::D4 => 0,
            Wavelet::Cdf97 => 1,
        }
    }

    /// The wavelet with bitstream id `id`.
    pub fn from_id(id: u8) -> Option<Wavelet> {
        Wavelet::ALL.into_iter().find(|w| w.id() == id)
    }

    /// Length of the decomposition filters (PyWavelets `dec_len`): 4 or 10.
    pub fn filter_len(self) -> usize {
        match self {
            Wavelet::D4 => 4,
            Wavelet::Cdf97 => 10,
        }
    }

    /// Deepest useful level for a signal of `n` samples, as `pywt.dwt_max_level(n, dec_len)`:
    /// `floor(log2(n / (dec_len − 1)))`, 0 when `n < dec_len − 1`.
    pub fn max_level(self, n: usize) -> usize {
        let f = self.filter_len() - 1;
        if n < f {
            return 0;
        }
        // floor(log2(n / f)) with integers: the largest k with f · 2^k <= n.
        let mut k = 0;
        while f.checked_shl(k as u32 + 1).is_some_and(|v| v <= n) {
            k += 1;
        }
        k
    }
}

/// Band sizes of a `levels`-level decomposition of `n` samples in PyWavelets order
/// `[cA_L, cD_L, …, cD_1]`; each level halves with rounding up.
pub fn band_lengths(n: usize, levels: usize) -> Vec<usize> {
    let mut per_level = Vec::with_capacity(levels);
    let mut m = n;
    for _ in 0..levels {
        m = m.div_ceil(2);
        per_level.push(m);
    }
    let mut out = Vec::with_capacity(levels + 1);
    out.push(if levels == 0 { n } else { m });
    out.extend(per_level.iter().rev());
    out
}

/// Total number of coefficients of a `levels`-level decomposition of `n` samples.
pub fn coefficient_count(n: usize, levels: usize) -> usize {
    // Detail bands ceil(n/2), ..., ceil(n/2^L), then the approximation ceil(n/2^L) again.
    (1..=levels).map(|k| approx_len(n, k)).sum::<usize>() + approx_len(n, levels)
}

/// Length of the level-`k` approximation of `n` samples: `ceil(n / 2^k)` (repeated halving
/// with rounding up).
fn approx_len(n: usize, k: usize) -> usize {
    if k >= usize::BITS as usize {
        usize::from(n > 0)
    } else {
        n.div_ceil(1usize << k)
    }
}

/// One analysis level: `x` (any length ≥ 1) into `a` and `d` of length `ceil(n / 2)` each.
///
/// `x` is first copied into `ext`, periodically extended by `L/2 − 1` samples on each side
/// (after the odd-length extension), so that every output is a branch-free dot product over a
/// contiguous window: `a[i] = Σ_m dec_lo[L−1−m] · ext[2i + m]`.
fn analysis_step<const L: usize>(
    f: &Filters<L>,
    x: &[f64],
    ext: &mut Vec<f64>,
    a: &mut [f64],
    d: &mut [f64],
) {
    let n = x.len();
    let big_n = n + (n & 1);
    let pad = L / 2 - 1;
    periodic_extend(x, big_n, pad, ext);
    for ((w, ai), di) in ext
        .windows(L)
        .step_by(2)
        .zip(a.iter_mut())
        .zip(d.iter_mut())
    {
        let (mut sa, mut sd) = (0.0, 0.0);
        for ((&v, &lo), &hi) in w.iter().zip(&f.rdec_lo).zip(&f.rdec_hi) {
            sa += lo * v;
            sd += hi * v;
        }
        *ai = sa;
        *di = sd;
    }
}

/// `ext[u] = x̃[(u − pad) mod big_n]` for `u` in `0..big_n + 2·pad`, where `x̃` is `x` with its
/// last sample repeated up to `big_n` samples.
fn periodic_extend(x: &[f64], big_n: usize, pad: usize, ext: &mut Vec<f64>) {
    let n = x.len();
    ext.clear();
    if pad <= n && (n..=n + 1).contains(&big_n) {
        // The usual case, without a division per sample: x̃ = x (+ its last sample), whose
        // last `pad` samples go in front and first `pad` behind. The primitive codec's
        // bound search runs this on 15-32-sample windows hundreds of thousands of times.
        let odd = big_n > n;
        let front = pad - usize::from(odd && pad > 0);
        ext.extend_from_slice(&x[n - front..]);
        if odd && pad > 0 {
            ext.push(x[n - 1]);
        }
        ext.extend_from_slice(x);
        if odd {
            ext.push(x[n - 1]);
        }
        ext.extend_from_slice(&x[..pad]);
        return;
    }
    let at = |k: usize| x[k.min(n - 1)];
    ext.extend((0..pad).map(|u| at((u + big_n * pad - pad) % big_n)));
    ext.extend_from_slice(x);
    if big_n > n {
        ext.push(x[n - 1]);
    }
    ext.extend((0..pad).map(|u| at(u % big_n)));
}

/// One synthesis level: `a`, `d` (length `h`) into `out` of length `n` with `ceil(n/2) == h`.
///
/// The transpose of [`analysis_step`] in gather form: position `k` of the (even) output
/// collects `rec_lo[m]·a[i] + rec_hi[m]·d[i]` over `2i + m = k + L/2 − 1` (indices of `a`, `d`
/// taken modulo `h`). Both outputs `e = 2q` and `2q + 1` (with `e = k + L/2 − 1`) read the same
/// `L/2` padded coefficients `i = q − L/2 + 1 ..= q`, so they are computed together from one
/// window. `ae`, `de` are scratch for the periodically padded coefficients, `full` for the
/// outputs before the phase shift.
fn synthesis_step<const L: usize>(
    f: &Filters<L>,
    a: &[f64],
    d: &[f64],
    scratch: &mut [Vec<f64>; 3],
    out: &mut [f64],
) {
    let [ae, de, full] = scratch;
    let h = a.len();
    let n = out.len();
    let half = L / 2;
    let pad = half - 1;
    // i ranges over (k + pad − m)/2 for k in 0..2h, m in 0..L: from −⌈(L − 1 − pad)/2⌉ to
    // h − 1 + ⌈pad/2⌉.
    let left = (L - pad).div_ceil(2);
    let right = pad.div_ceil(2) + 1;
    periodic_extend(a, h, left, ae);
    ae.extend((0..right.saturating_sub(left)).map(|u| a[(u + left) % h]));
    periodic_extend(d, h, left, de);
    de.extend((0..right.saturating_sub(left)).map(|u| d[(u + left) % h]));
    // Taps per window position u (coefficient i = q − half + 1 + u, t = half − 1 − u).
    let mut taps = [[0.0f64; 4]; 8];
    for (u, tap) in taps.iter_mut().enumerate().take(half) {
        let t = half - 1 - u;
        *tap = [
            f.rec_lo[2 * t],
            f.rec_hi[2 * t],
            f.rec_lo[2 * t + 1],
            f.rec_hi[2 * t + 1],
        ];
    }
    let taps = &taps[..half];
    let q_first = pad / 2;
    let q_last = (pad + n - 1) / 2;
    let start = left + q_first + 1 - half;
    full.resize(2 * (q_last + 1 - q_first), 0.0);
    for ((pair, wa), wd) in full
        .chunks_exact_mut(2)
        .zip(ae[start..].windows(half))
        .zip(de[start..].windows(half))
    {
        let (mut even, mut odd) = (0.0, 0.0);
        for ((&x, &y), tap) in wa.iter().zip(wd).zip(taps) {
            even += tap[0] * x + tap[1] * y;
            odd += tap[2] * x + tap[3] * y;
        }
        pair[0] = even;
        pair[1] = odd;
    }
    let off = pad % 2;
    out.copy_from_slice(&full[off..off + n]);
}

/// A reusable multi-level transform: keeps its scratch buffers between calls so a codec can
/// transform thousands of windows without allocating.
#[derive(Debug, Clone)]
pub struct Transform {
    wavelet: Wavelet,
    buf_a: Vec<f64>,
    buf_b: Vec<f64>,
    ext: Vec<f64>,
    /// Synthesis scratch: padded approximation, padded detail, outputs.
    syn: [Vec<f64>; 3],
}

impl Transform {
    /// A transform for `wavelet`.
    pub fn new(wavelet: Wavelet) -> Transform {
        Transform {
            wavelet,
            buf_a: Vec::new(),
            buf_b: Vec::new(),
            ext: Vec::new(),
            syn: [Vec::new(), Vec::new(), Vec::new()],
        }
    }

    /// The wavelet.
    pub fn wavelet(&self) -> Wavelet {
        self.wavelet
    }

    /// Forward transform of `x` with `levels` levels into `out` (cleared first), flat in
    /// PyWavelets order `[cA_L, cD_L, …, cD_1]`; equals `pywt.wavedec(x, w,
    /// mode='periodization', level=levels)` concatenated. `levels == 0` copies `x`.
    pub fn forward(&mut self, x: &[f64], levels: usize, out: &mut Vec<f64>) {
        match self.wavelet {
            Wavelet::D4 => self.forward_with(&D4_FILTERS, x, levels, out),
            Wavelet::Cdf97 => self.forward_with(&CDF97_FILTERS, x, levels, out),
        }
    }

    fn forward_with<const L: usize>(
        &mut self,
        f: &Filters<L>,
        x: &[f64],
        levels: usize,
        out: &mut Vec<f64>,
    ) {
        let total = coefficient_count(x.len(), levels);
        out.clear();
        out.resize(total, 0.0);
        if levels == 0 || x.is_empty() {
            out.copy_from_slice(x);
            return;
        }
        // cD_1 sits at the end; walk the detail bands backwards. The approximation of each
        // level is written just before its detail band and read from there by the next level.
        let mut end = total;
        let mut m = x.len();
        let h = m.div_ceil(2);
        {
            let (head, d) = out.split_at_mut(end - h);
            analysis_step(f, x, &mut self.ext, &mut head[end - 2 * h..], d);
        }
        end -= h;
        m = h;
        for _ in 1..levels {
            let h = m.div_ceil(2);
            self.buf_a.clear();
            self.buf_a.extend_from_slice(&out[end - m..end]);
            let (head, d) = out[..end].split_at_mut(end - h);
            analysis_step(f, &self.buf_a, &mut self.ext, &mut head[end - 2 * h..], d);
            end -= h;
            m = h;
        }
        debug_assert_eq!(end, m);
    }

    /// Inverse of [`Transform::forward`]: `coeffs` of a `levels`-level decomposition of an
    /// `n`-sample signal into `out` (cleared first, length `n`).
    ///
    /// # Errors
    /// [`WaveletError::Length`] when `coeffs` is not `coefficient_count(n, levels)` long.
    pub fn inverse(
        &mut self,
        coeffs: &[f64],
        n: usize,
        levels: usize,
        out: &mut Vec<f64>,
    ) -> Result<(), WaveletError> {
        match self.wavelet {
            Wavelet::D4 => self.inverse_with(&D4_FILTERS, coeffs, n, levels, out),
            Wavelet::Cdf97 => self.inverse_with(&CDF97_FILTERS, coeffs, n, levels, out),
        }
    }

    fn inverse_with<const L: usize>(
        &mut self,
        f: &Filters<L>,
        coeffs: &[f64],
        n: usize,
        levels: usize,
        out: &mut Vec<f64>,
    ) -> Result<(), WaveletError> {
        let total = coefficient_count(n, levels);
        if coeffs.len() != total {
            return Err(WaveletError::Length {
                expected: total,
                got: coeffs.len(),
            });
        }
        out.clear();
        if levels == 0 || n == 0 {
            out.extend_from_slice(coeffs);
            return Ok(());
        }
        // Lengths of the approximation at each level: n_0 = n, n_k = ceil(n_{k-1}/2).
        let sizes = |k: usize| approx_len(n, k);
        let mut start = sizes(levels);
        self.buf_a.clear();
        self.buf_a.extend_from_slice(&coeffs[..start]);
        for k in (2..=levels).rev() {
            let h = sizes(k);
            let m = sizes(k - 1);
            let d = &coeffs[start..start + h];
            start += h;
            self.buf_b.resize(m, 0.0);
            synthesis_step(f, &self.buf_a[..h], d, &mut self.syn, &mut self.buf_b[..m]);
            std::mem::swap(&mut self.buf_a, &mut self.buf_b);
        }
        out.resize(n, 0.0);
        let h = sizes(1);
        synthesis_step(
            f,
            &self.buf_a[..h],
            &coeffs[start..start + h],
            &mut self.syn,
            out,
        );
        Ok(())
    }
}

/// Why an inverse transform was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum WaveletError {
    /// The coefficient buffer does not match the signal length and level count.
    #[error("wavelet coefficients: expected {expected}, got {got}")]
    Length {
        /// Coefficients a decomposition of that shape has.
        expected: usize,
        /// Coefficients supplied.
        got: usize,
    },
}

/// Convenience: `pywt.wavedec(x, w, mode='periodization', level=levels)`, flat.
pub fn wavedec(wavelet: Wavelet, x: &[f64], levels: usize) -> Vec<f64> {
    let mut out = Vec::new();
    Transform::new(wavelet).forward(x, levels, &mut out);
    out
}

/// Convenience: inverse of [`wavedec`].
///
/// # Errors
/// [`WaveletError::Length`] when `coeffs` does not fit `n` and `levels`.
pub fn waverec(
    wavelet: Wavelet,
    coeffs: &[f64],
    n: usize,
    levels: usize,
) -> Result<Vec<f64>, WaveletError> {
    let mut out = Vec::new();
    Transform::new(wavelet).inverse(coeffs, n, levels, &mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The slice-copy path of `periodic_extend` writes what the index formula of its docs
    /// says, for every length, padding and odd extension it takes.
    #[test]
    fn periodic_extend_matches_its_formula() {
        let mut ext = Vec::new();
        for n in 1..40usize {
            let x: Vec<f64> = (0..n).map(|i| i as f64 + 0.5).collect();
            for big_n in [n, n + (n & 1)] {
                for pad in 0..8 {
                    periodic_extend(&x, big_n, pad, &mut ext);
                    let want: Vec<f64> = (0..big_n + 2 * pad)
                        .map(|u| x[((u + big_n * pad - pad) % big_n).min(n - 1)])
                        .collect();
                    assert_eq!(ext, want, "n {n} big_n {big_n} pad {pad}");
                }
            }
        }
    }

    #[test]
    fn max_level_matches_pywt() {
        // pywt.dwt_max_level(256, 4) == 6, (256, 10) == 4, (100, 4) == 5, (2, 4) == 0.
        assert_eq!(Wavelet::D4.max_level(256), 6);
        assert_eq!(Wavelet::Cdf97.max_level(256), 4);
        assert_eq!(Wavelet::D4.max_level(100), 5);
        assert_eq!(Wavelet::D4.max_level(2), 0);
        assert_eq!(Wavelet::D4.max_level(3), 0);
        assert_eq!(Wavelet::Cdf97.max_level(9), 0);
    }

    #[test]
    fn band_lengths_match_pywt() {
        // [len(c) for c in pywt.wavedec(np.zeros(100), 'db2', mode='periodization')]
        assert_eq!(band_lengths(100, 5), vec![4, 4, 7, 13, 25, 50]);
    }

    #[test]
    fn wrong_length_is_an_error() {
        assert!(waverec(Wavelet::D4, &[1.0; 5], 8, 1).is_err());
    }
}
