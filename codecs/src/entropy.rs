//! Adaptive binary range coder (the LZMA design: 32-bit range, 11-bit probabilities, shift 5)
//! and adaptive Exp-Golomb integer models built on it.
//!
//! Paper 000 step 9 only says "use an entropy coding method" (the authors used LZW). An adaptive
//! binary arithmetic coder is the usual modern choice for sparse quantized wavelet data: runs and
//! magnitudes are coded as Exp-Golomb prefixes and suffixes whose every bit has its own adaptive
//! probability, so the coder learns the distribution of each band without side information.
//!
//! The decoder never panics on arbitrary input: reading past the end yields zero bytes and is
//! recorded, so a caller can refuse a payload with [`RangeDecoder::overrun`].

const PROB_BITS: u32 = 11;
const PROB_ONE: u16 = 1 << PROB_BITS;
const MOVE_BITS: u32 = 5;
const TOP: u32 = 1 << 24;
/// Most direct bits coded in one range division (the range stays ≥ 2^8 after it).
pub const DIRECT_CHUNK: u32 = 16;

/// An adaptive probability that the next bit is 0, in 1/2048.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BitModel(u16);

impl Default for BitModel {
    fn default() -> Self {
        BitModel(PROB_ONE / 2)
    }
}

/// Range encoder writing into a byte vector.
#[derive(Debug, Clone)]
pub struct RangeEncoder {
    low: u64,
    range: u32,
    cache: u8,
    cache_size: u64,
    out: Vec<u8>,
}

impl Default for RangeEncoder {
    fn default() -> Self {
        RangeEncoder::new()
    }
}

impl RangeEncoder {
    /// An empty encoder.
    pub fn new() -> RangeEncoder {
        RangeEncoder {
            low: 0,
            range: u32::MAX,
            cache: 0,
            cache_size: 1,
            out: Vec::new(),
        }
    }

    fn shift_low(&mut self) {
        if (self.low as u32) < 0xFF00_0000 || (self.low >> 32) != 0 {
            let carry = (self.low >> 32) as u8;
            let mut temp = self.cache;
            loop {
                self.out.push(temp.wrapping_add(carry));
                temp = 0xFF;
                self.cache_size -= 1;
                if self.cache_size == 0 {
                    break;
                }
            }
            self.cache = ((self.low >> 24) & 0xFF) as u8;
        }
        self.cache_size += 1;
        self.low = (self.low & 0x00FF_FFFF) << 8;
    }

    fn normalize(&mut self) {
        while self.range < TOP {
            self.range <<= 8;
            self.shift_low();
        }
    }

    /// Codes one bit with an adaptive model.
    #[inline]
    pub fn bit(&mut self, model: &mut BitModel, bit: bool) {
        let bound = (self.range >> PROB_BITS) * u32::from(model.0);
        if bit {
            self.low += u64::from(bound);
            self.range -= bound;
            model.0 -= model.0 >> MOVE_BITS;
        } else {
            self.range = bound;
            model.0 += (PROB_ONE - model.0) >> MOVE_BITS;
        }
        self.normalize();
    }

    /// Codes `count` (≤ 32) low bits of `value`, most significant first, at probability 1/2.
    ///
    /// Up to [`DIRECT_CHUNK`] bits go in one step (the range is divided by `2^n` once rather
    /// than halved `n` times).
    pub fn direct(&mut self, value: u32, count: u32) {
        let mut left = count.min(32);
        while left > 0 {
            let n = left.min(DIRECT_CHUNK);
            left -= n;
            let chunk = (value >> left) & ((1u32 << n) - 1);
            self.range >>= n;
            self.low += u64::from(self.range) * u64::from(chunk);
            self.normalize();
        }
    }

    /// Flushes and returns the coded bytes.
    pub fn finish(mut self) -> Vec<u8> {
        for _ in 0..5 {
            self.shift_low();
        }
        self.out
    }

    /// Information coded so far in bits, fractional: the bytes shifted out (8 bits each)
    /// plus what the current range has used of its 32 bits. The final size is this rounded
    /// up to bytes plus at most the 5 bytes of the flush; the difference of two readings is
    /// what the symbols coded in between cost (for measuring a stream's parts).
    pub fn bits(&self) -> f64 {
        8.0 * (self.out.len() as f64 + self.cache_size as f64 - 1.0) + 32.0
            - f64::from(self.range).log2()
    }

    /// Bytes written so far (a lower bound of the final size).
    pub fn len(&self) -> usize {
        self.out.len() + self.cache_size as usize + 4
    }

    /// True when nothing has been coded.
    pub fn is_empty(&self) -> bool {
        self.out.is_empty() && self.low == 0
    }
}

/// Range decoder over a byte slice.
#[derive(Debug, Clone)]
pub struct RangeDecoder<'a> {
    data: &'a [u8],
    pos: usize,
    range: u32,
    code: u32,
    overrun: usize,
}

impl<'a> RangeDecoder<'a> {
    /// Starts decoding `data` (as produced by [`RangeEncoder::finish`]).
    pub fn new(data: &'a [u8]) -> RangeDecoder<'a> {
        let mut d = RangeDecoder {
            data,
            pos: 0,
            range: u32::MAX,
            code: 0,
            overrun: 0,
        };
        for _ in 0..5 {
            d.code = (d.code << 8) | u32::from(d.next_byte());
        }
        d
    }

    fn next_byte(&mut self) -> u8 {
        if let Some(&b) = self.data.get(self.pos) {
            self.pos += 1;
            b
        } else {
            self.overrun += 1;
            0
        }
    }

    fn normalize(&mut self) {
        while self.range < TOP {
            self.range <<= 8;
            self.code = (self.code << 8) | u32::from(self.next_byte());
        }
    }

    /// Decodes one bit with an adaptive model (the encoder's twin).
    #[inline]
    pub fn bit(&mut self, model: &mut BitModel) -> bool {
        let bound = (self.range >> PROB_BITS) * u32::from(model.0);
        let bit = if self.code < bound {
            self.range = bound;
            model.0 += (PROB_ONE - model.0) >> MOVE_BITS;
            false
        } else {
            self.code -= bound;
            self.range -= bound;
            model.0 -= model.0 >> MOVE_BITS;
            true
        };
        self.normalize();
        bit
    }

    /// Decodes `count` (≤ 32) direct bits.
    pub fn direct(&mut self, count: u32) -> u32 {
        let mut v: u32 = 0;
        let mut left = count.min(32);
        while left > 0 {
            let n = left.min(DIRECT_CHUNK);
            left -= n;
            self.range >>= n;
            // A valid stream gives a chunk below 2^n; corrupt input is clamped, not trusted.
            let chunk = (self.code / self.range).min((1u32 << n) - 1);
            self.code -= chunk * self.range;
            v = (v << n) | chunk;
            self.normalize();
        }
        v
    }

    /// Bytes read past the end of the input (0 for a well-formed stream).
    pub fn overrun(&self) -> usize {
        self.overrun
    }

    /// Bytes of input consumed so far.
    pub fn position(&self) -> usize {
        self.pos
    }
}

/// Longest Exp-Golomb prefix: values up to `2^31 − 2`.
const MAX_EXP: usize = 31;
/// Suffix bits below the exponent that get adaptive models; the rest are direct.
const MODELLED_SUFFIX: u32 = 3;

/// An adaptive model for unsigned integers: Exp-Golomb code of `v + 1` whose unary exponent
/// bits and top suffix bits are each adaptively modelled.
#[derive(Debug, Clone)]
pub struct UintModel {
    exp: [BitModel; MAX_EXP],
    suffix: [[BitModel; 8]; MAX_EXP + 1],
}

impl Default for UintModel {
    fn default() -> Self {
        UintModel {
            exp: [BitModel::default(); MAX_EXP],
            suffix: [[BitModel::default(); 8]; MAX_EXP + 1],
        }
    }
}

/// Why an integer could not be coded or decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum EntropyError {
    /// The value does not fit the Exp-Golomb range.
    #[error("value {0} exceeds the entropy coder's range")]
    TooLarge(u64),
    /// Zero given to a model of nonzero values.
    #[error("zero given to a model of nonzero values")]
    Zero,
}

impl UintModel {
    /// Largest value the model can code.
    pub const MAX: u32 = (1u32 << MAX_EXP) - 2;

    /// Codes `v`.
    ///
    /// # Errors
    /// [`EntropyError::TooLarge`] above [`UintModel::MAX`].
    pub fn encode(&mut self, enc: &mut RangeEncoder, v: u32) -> Result<(), EntropyError> {
        if v > Self::MAX {
            return Err(EntropyError::TooLarge(u64::from(v)));
        }
        let x = v + 1;
        let k = x.ilog2(); // x in [2^k, 2^(k+1))
        for i in 0..k as usize {
            enc.bit(&mut self.exp[i], true);
        }
        if (k as usize) < MAX_EXP {
            enc.bit(&mut self.exp[k as usize], false);
        }
        self.suffix_bits(enc, x, k);
        Ok(())
    }

    fn suffix_bits(&mut self, enc: &mut RangeEncoder, x: u32, k: u32) {
        // Modelled top bits with a small binary-tree context (node index within 8).
        let m = k.min(MODELLED_SUFFIX);
        let mut node = 1usize;
        for i in 0..m {
            let b = (x >> (k - 1 - i)) & 1 == 1;
            enc.bit(&mut self.suffix[k as usize][node], b);
            node = node * 2 + usize::from(b);
        }
        if k > m {
            enc.direct(x, k - m);
        }
    }

    /// Decodes one value; `None` never happens for in-range streams, but corrupt input can ask
    /// for an exponent beyond the range, which is reported as `None`.
    pub fn decode(&mut self, dec: &mut RangeDecoder<'_>) -> Option<u32> {
        let mut k = 0usize;
        while k < MAX_EXP && dec.bit(&mut self.exp[k]) {
            k += 1;
        }
        if k >= MAX_EXP {
            return None;
        }
        let k = k as u32;
        let m = k.min(MODELLED_SUFFIX);
        let mut x: u32 = 1;
        let mut node = 1usize;
        for _ in 0..m {
            let b = dec.bit(&mut self.suffix[k as usize][node]);
            node = node * 2 + usize::from(b);
            x = (x << 1) | u32::from(b);
        }
        if k > m {
            x = (x << (k - m)) | dec.direct(k - m);
        }
        Some(x - 1)
    }
}

/// Signed integers: zero flag, sign, magnitude − 1 with a [`UintModel`].
#[derive(Debug, Clone, Default)]
pub struct IntModel {
    zero: BitModel,
    sign: BitModel,
    mag: UintModel,
}

impl IntModel {
    /// Codes `v`.
    ///
    /// # Errors
    /// [`EntropyError::TooLarge`] when `|v| − 1` exceeds [`UintModel::MAX`].
    pub fn encode(&mut self, enc: &mut RangeEncoder, v: i64) -> Result<(), EntropyError> {
        enc.bit(&mut self.zero, v == 0);
        if v == 0 {
            return Ok(());
        }
        enc.bit(&mut self.sign, v < 0);
        let m = v.unsigned_abs() - 1;
        let m32 = u32::try_from(m).map_err(|_| EntropyError::TooLarge(m))?;
        self.mag.encode(enc, m32)
    }

    /// Decodes one value (`None` on an out-of-range exponent).
    pub fn decode(&mut self, dec: &mut RangeDecoder<'_>) -> Option<i64> {
        if dec.bit(&mut self.zero) {
            return Some(0);
        }
        let neg = dec.bit(&mut self.sign);
        let m = i64::from(self.mag.decode(dec)?) + 1;
        Some(if neg { -m } else { m })
    }
}

/// Nonzero signed integers (a run-length coder's values): sign as a direct bit (wavelet signs
/// are close to a coin toss), `|v| − 1` with a [`UintModel`]. One decision fewer per value than
/// [`IntModel`], which also codes a zero flag.
#[derive(Debug, Clone, Default)]
pub struct NonzeroModel {
    mag: UintModel,
}

impl NonzeroModel {
    /// Codes `v`.
    ///
    /// # Errors
    /// [`EntropyError::Zero`] for 0, [`EntropyError::TooLarge`] when `|v| − 1` exceeds [`UintModel::MAX`].
    pub fn encode(&mut self, enc: &mut RangeEncoder, v: i64) -> Result<(), EntropyError> {
        if v == 0 {
            return Err(EntropyError::Zero);
        }
        let m = v.unsigned_abs() - 1;
        let m32 = u32::try_from(m).map_err(|_| EntropyError::TooLarge(m))?;
        self.mag.encode(enc, m32)?;
        enc.direct(u32::from(v < 0), 1);
        Ok(())
    }

    /// Decodes one value (`None` on an out-of-range exponent); never 0.
    pub fn decode(&mut self, dec: &mut RangeDecoder<'_>) -> Option<i64> {
        let m = i64::from(self.mag.decode(dec)?) + 1;
        Some(if dec.direct(1) == 1 { -m } else { m })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `bits` tracks the size: n bits of a fair coin cost n bits, and the final stream is
    /// `bits` rounded up plus at most the flush.
    #[test]
    fn bits_measure_what_was_coded() {
        let mut enc = RangeEncoder::new();
        assert!(enc.bits().abs() < 1e-9);
        enc.direct(0xABCD, 16);
        // Integer range arithmetic loses a little: 16 bits to within 10⁻³.
        assert!((enc.bits() - 16.0).abs() < 1e-3, "{}", enc.bits());
        // A skewed source: 1000 zeros after adaptation cost far less than a bit each.
        let mut m = BitModel::default();
        let before = enc.bits();
        for _ in 0..1000 {
            enc.bit(&mut m, false);
        }
        let cost = enc.bits() - before;
        assert!(cost > 0.0 && cost < 100.0, "{cost}");
        let total = enc.bits();
        let bytes = enc.finish().len() as f64;
        assert!(
            bytes * 8.0 >= total && bytes * 8.0 <= total + 8.0 * 6.0,
            "{bytes} {total}"
        );
    }

    #[test]
    fn integers_round_trip() {
        let values: Vec<i64> = (0..5000)
            .map(|i: i64| ((i * 7919) % 613 - 300) * ((i % 5) + 1))
            .collect();
        let uvals: Vec<u32> = (0..3000u32)
            .map(|i| i.wrapping_mul(2_654_435_761u32) >> (i % 32))
            .map(|v| v.min(UintModel::MAX))
            .collect();
        let mut enc = RangeEncoder::new();
        let (mut im, mut um, mut b) = (
            IntModel::default(),
            UintModel::default(),
            BitModel::default(),
        );
        for &v in &values {
            im.encode(&mut enc, v).unwrap();
        }
        for &v in &uvals {
            um.encode(&mut enc, v).unwrap();
            enc.bit(&mut b, v % 3 == 0);
        }
        let mut nz = NonzeroModel::default();
        for &v in values.iter().filter(|&&v| v != 0) {
            nz.encode(&mut enc, v).unwrap();
        }
        assert_eq!(nz.encode(&mut enc, 0), Err(EntropyError::Zero));
        for k in 0..=32 {
            enc.direct(0x9E37_79B9u32.rotate_left(k), k);
        }
        enc.direct(0xDEAD_BEEF, 32);
        let bytes = enc.finish();
        let mut dec = RangeDecoder::new(&bytes);
        let (mut im, mut um, mut b) = (
            IntModel::default(),
            UintModel::default(),
            BitModel::default(),
        );
        for &v in &values {
            assert_eq!(im.decode(&mut dec), Some(v));
        }
        for &v in &uvals {
            assert_eq!(um.decode(&mut dec), Some(v));
            assert_eq!(dec.bit(&mut b), v % 3 == 0);
        }
        let mut nz = NonzeroModel::default();
        for &v in values.iter().filter(|&&v| v != 0) {
            assert_eq!(nz.decode(&mut dec), Some(v));
        }
        for k in 0..=32u32 {
            let want = 0x9E37_79B9u32.rotate_left(k);
            let mask = if k == 32 { u32::MAX } else { (1u32 << k) - 1 };
            assert_eq!(dec.direct(k), want & mask, "{k} direct bits");
        }
        assert_eq!(dec.direct(32), 0xDEAD_BEEF);
        assert_eq!(dec.overrun(), 0);
        assert_eq!(dec.position(), bytes.len());
    }

    #[test]
    fn skewed_bits_compress() {
        let mut enc = RangeEncoder::new();
        let mut m = BitModel::default();
        for i in 0..80_000 {
            enc.bit(&mut m, i % 100 == 0);
        }
        let bytes = enc.finish();
        // Entropy of p = 0.01 is 0.081 bit: 80k bits -> ~810 bytes; adaptive overhead allowed.
        assert!(bytes.len() < 1100, "{} bytes", bytes.len());
    }

    #[test]
    fn garbage_never_panics() {
        let data: Vec<u8> = (0..64u32).map(|i| (i * 97 % 251) as u8).collect();
        let mut dec = RangeDecoder::new(&data);
        let mut um = UintModel::default();
        for _ in 0..1000 {
            let _ = um.decode(&mut dec);
        }
        assert!(dec.overrun() > 0);
    }
}
