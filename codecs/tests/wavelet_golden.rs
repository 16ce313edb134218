//! Wavelet coefficients equal PyWavelets' (`scripts/golden/pywt_coeffs.py`) and the inverse
//! reconstructs the input.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use codecs::wavelet::{Transform, Wavelet, band_lengths, wavedec, waverec};

struct Case {
    wavelet: Wavelet,
    n: usize,
    level: usize,
    x: Vec<f64>,
    bands: Vec<Vec<f64>>,
}

fn parse(line: &str, skip: usize) -> Vec<f64> {
    line.split_whitespace()
        .skip(skip)
        .map(|t| t.parse::<f64>().unwrap())
        .collect()
}

fn cases() -> Vec<Case> {
    let text = include_str!("data/pywt_coeffs.txt");
    let mut out: Vec<Case> = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("case") => {
                let wavelet = Wavelet::from_name(it.next().unwrap()).unwrap();
                let n = it.next().unwrap().parse().unwrap();
                let level = it.next().unwrap().parse().unwrap();
                out.push(Case {
                    wavelet,
                    n,
                    level,
                    x: Vec::new(),
                    bands: Vec::new(),
                });
            }
            Some("x") => out.last_mut().unwrap().x = parse(line, 1),
            Some("c") => out.last_mut().unwrap().bands.push(parse(line, 2)),
            _ => {}
        }
    }
    out
}

#[test]
fn coefficients_equal_pywavelets() {
    let cases = cases();
    assert_eq!(cases.len(), 22, "11 lengths × 2 wavelets");
    for c in &cases {
        assert_eq!(c.x.len(), c.n);
        assert_eq!(
            c.level,
            c.wavelet.max_level(c.n),
            "{:?} n={}",
            c.wavelet,
            c.n
        );
        let lens: Vec<usize> = c.bands.iter().map(Vec::len).collect();
        assert_eq!(
            lens,
            band_lengths(c.n, c.level),
            "{:?} n={}",
            c.wavelet,
            c.n
        );
        let flat = wavedec(c.wavelet, &c.x, c.level);
        let want: Vec<f64> = c.bands.concat();
        assert_eq!(flat.len(), want.len());
        for (i, (a, b)) in flat.iter().zip(&want).enumerate() {
            assert!(
                (a - b).abs() <= 1e-9,
                "{:?} n={} coefficient {i}: {a} vs pywt {b}",
                c.wavelet,
                c.n
            );
        }
    }
}

#[test]
fn inverse_reconstructs_every_golden_signal() {
    for c in cases() {
        let flat = wavedec(c.wavelet, &c.x, c.level);
        let back = waverec(c.wavelet, &flat, c.n, c.level).unwrap();
        assert_eq!(back.len(), c.n);
        for (a, b) in back.iter().zip(&c.x) {
            assert!(
                (a - b).abs() <= 1e-9,
                "{:?} n={}: {a} vs {b}",
                c.wavelet,
                c.n
            );
        }
    }
}

#[test]
fn perfect_reconstruction_all_lengths_and_levels() {
    for w in Wavelet::ALL {
        let mut t = Transform::new(w);
        let (mut coeffs, mut back) = (Vec::new(), Vec::new());
        for n in 1..=300 {
            let x: Vec<f64> = (0..n)
                .map(|i| ((i * 37 % 101) as f64 - 50.0) * 0.7 + (i as f64 * 0.05).sin() * 90.0)
                .collect();
            for levels in 0..=w.max_level(n).max(1) {
                t.forward(&x, levels, &mut coeffs);
                t.inverse(&coeffs, n, levels, &mut back).unwrap();
                assert_eq!(back.len(), n, "{w:?} n={n} levels={levels}");
                let err = x
                    .iter()
                    .zip(&back)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(err <= 1e-9, "{w:?} n={n} levels={levels}: error {err}");
            }
        }
    }
}
