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

struct Filters {
    dec_lo: &'static [f64],
    dec_hi: &'static [f64],
    rec_lo: &'static [f64],
    rec_hi: &'static [f64],
}

// Filter values exactly as PyWavelets 1.8 prints them (`pywt.Wavelet(name).dec_lo` ...).
static D4_FILTERS: Filters = Filters {
    dec_lo: &[
        -0.129_409_522_551_260_37,
        0.224_143_868_042_013_4,
        0.836_516_303_737_807_9,
        0.482_962_913_144_534_16,
    ],
    dec_hi: &[
        -0.482_962_913_144_534_16,
        0.836_516_303_737_807_9,
        -0.224_143_868_042_013_4,
        -0.129_409_522_551_260_37,
    ],
    rec_lo: &[
        0.482_962_913_144_534_16,
        0.836_516_303_737_807_9,
        0.224_143_868_042_013_4,
        -0.129_409_522_551_260_37,
    ],
    rec_hi: &[
        -0.129_409_522_551_260_37,
        -0.224_143_868_042_013_4,
        0.836_516_303_737_807_9,
        -0.482_962_913_144_534_16,
    ],
};

static CDF97_FILTERS: Filters = Filters {
    dec_lo: &[
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
    ],
    dec_hi: &[
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
    ],
    rec_lo: &[
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
    rec_hi: &[
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

    fn filters(self) -> &'static Filters {
        match self {
            Wavelet::D4 => &D4_FILTERS,
            Wavelet::Cdf97 => &CDF97_FILTERS,
        }
    }

    /// Length of the decomposition filters (PyWavelets `dec_len`): 4 or 10.
    pub fn filter_len(self) -> usize {
        self.filters().dec_lo.len()
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
    band_lengths(n, levels).iter().sum()
}

/// One analysis level: `x` (any length ≥ 1) into `a` and `d` of length `ceil(n / 2)` each.
fn analysis_step(f: &Filters, x: &[f64], a: &mut [f64], d: &mut [f64]) {
    let n = x.len();
    let big_n = n + (n & 1);
    let l = f.dec_lo.len();
    let half = l / 2;
    let get = |idx: isize| -> f64 {
        let m = idx.rem_euclid(big_n as isize) as usize;
        // The odd-length extension repeats the last sample (PyWavelets periodization).
        if m >= n { x[n - 1] } else { x[m] }
    };
    for i in 0..big_n / 2 {
        let base = 2 * i + half;
        let (mut sa, mut sd) = (0.0, 0.0);
        if base + 1 >= l && base < n {
            // Interior: indices base - j for j in 0..l are all in 0..n.
            let window = &x[base + 1 - l..=base];
            for j in 0..l {
                let v = window[l - 1 - j];
                sa += f.dec_lo[j] * v;
                sd += f.dec_hi[j] * v;
            }
        } else {
            for j in 0..l {
                let v = get(base as isize - j as isize);
                sa += f.dec_lo[j] * v;
                sd += f.dec_hi[j] * v;
            }
        }
        a[i] = sa;
        d[i] = sd;
    }
}

/// One synthesis level: `a`, `d` (length `h`) into `out` of length `n` with `ceil(n/2) == h`;
/// `full` is scratch of length `2h`.
fn synthesis_step(f: &Filters, a: &[f64], d: &[f64], full: &mut [f64], out: &mut [f64]) {
    let big_n = full.len();
    let l = f.rec_lo.len();
    let half = l / 2;
    full.fill(0.0);
    for i in 0..a.len() {
        let base = 2 * i + half;
        let (ai, di) = (a[i], d[i]);
        if base + 1 >= l && base < big_n {
            let window = &mut full[base + 1 - l..=base];
            for j in 0..l {
                window[l - 1 - j] += ai * f.rec_lo[l - 1 - j] + di * f.rec_hi[l - 1 - j];
            }
        } else {
            for j in 0..l {
                let m = (base as isize - j as isize).rem_euclid(big_n as isize) as usize;
                full[m] += ai * f.rec_lo[l - 1 - j] + di * f.rec_hi[l - 1 - j];
            }
        }
    }
    let n = out.len();
    out.copy_from_slice(&full[..n]);
}

/// A reusable multi-level transform: keeps its scratch buffers between calls so a codec can
/// transform thousands of windows without allocating.
#[derive(Debug, Clone)]
pub struct Transform {
    wavelet: Wavelet,
    buf_a: Vec<f64>,
    buf_b: Vec<f64>,
    full: Vec<f64>,
}

impl Transform {
    /// A transform for `wavelet`.
    pub fn new(wavelet: Wavelet) -> Transform {
        Transform {
            wavelet,
            buf_a: Vec::new(),
            buf_b: Vec::new(),
            full: Vec::new(),
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
        let f = self.wavelet.filters();
        let lens = band_lengths(x.len(), levels);
        let total: usize = lens.iter().sum();
        out.clear();
        out.resize(total, 0.0);
        if levels == 0 || x.is_empty() {
            out.copy_from_slice(x);
            return;
        }
        self.buf_a.clear();
        self.buf_a.extend_from_slice(x);
        // cD_1 sits at the end; walk the detail bands backwards.
        let mut end = total;
        let mut m = x.len();
        for _ in 0..levels {
            let h = m.div_ceil(2);
            self.buf_b.resize(h, 0.0);
            let d = &mut out[end - h..end];
            analysis_step(f, &self.buf_a[..m], &mut self.buf_b[..h], d);
            end -= h;
            std::mem::swap(&mut self.buf_a, &mut self.buf_b);
            m = h;
        }
        out[..m].copy_from_slice(&self.buf_a[..m]);
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
        let lens = band_lengths(n, levels);
        let total: usize = lens.iter().sum();
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
        let f = self.wavelet.filters();
        // Lengths of the approximation at each level: n_0 = n, n_k = ceil(n_{k-1}/2).
        let mut sizes = Vec::with_capacity(levels + 1);
        sizes.push(n);
        for k in 0..levels {
            sizes.push(sizes[k].div_ceil(2));
        }
        let mut start = lens[0];
        self.buf_a.clear();
        self.buf_a.extend_from_slice(&coeffs[..lens[0]]);
        for k in (1..=levels).rev() {
            let h = sizes[k];
            let m = sizes[k - 1];
            let d = &coeffs[start..start + h];
            start += h;
            self.full.resize(2 * h, 0.0);
            self.buf_b.resize(m, 0.0);
            synthesis_step(f, &self.buf_a[..h], d, &mut self.full, &mut self.buf_b[..m]);
            std::mem::swap(&mut self.buf_a, &mut self.buf_b);
        }
        out.extend_from_slice(&self.buf_a[..n]);
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
