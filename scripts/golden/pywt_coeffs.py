#!/usr/bin/env python3
"""Golden wavelet coefficients for codecs/tests/wavelet_golden.rs.

Runs PyWavelets' multi-level DWT (`pywt.wavedec`, mode='periodization', default level =
`pywt.dwt_max_level`) on seeded signals of several lengths, including odd lengths and lengths that
are not powers of two, and also dumps the filters PyWavelets uses. Output is a plain text file so the
Rust test needs no JSON dependency:

    filter <wavelet> <dec_lo...>
    case <wavelet> <n> <level>
    x <values...>
    c <band index> <values...>        (pywt order: cA_n, cD_n, ..., cD_1)

Usage: python3 scripts/golden/pywt_coeffs.py > codecs/tests/data/pywt_coeffs.txt
Tested with PyWavelets 1.8.0 (pip package 1.9.0 reports 1.8.0), numpy 2.4.
"""
import numpy as np
import pywt

WAVELETS = ["db2", "bior4.4"]
LENGTHS = [2, 3, 8, 17, 37, 64, 100, 128, 255, 256, 343]


def fmt(values):
    return " ".join(repr(float(v)) for v in values)


def main():
    rng = np.random.default_rng(20111)
    print(f"# pywt {pywt.__version__}, mode=periodization")
    for name in WAVELETS:
        w = pywt.Wavelet(name)
        print("filter", name, fmt(w.dec_lo))
    for name in WAVELETS:
        w = pywt.Wavelet(name)
        for n in LENGTHS:
            # A smooth motion-like signal plus noise and an offset: wavelets see real structure.
            t = np.arange(n)
            x = 30.0 * np.sin(2 * np.pi * t / 97.0) + 5.0 * rng.standard_normal(n) + 12.5
            level = pywt.dwt_max_level(n, w.dec_len)
            coeffs = pywt.wavedec(x, w, mode="periodization", level=level)
            print("case", name, n, level)
            print("x", fmt(x))
            for i, c in enumerate(coeffs):
                print("c", i, fmt(c))


if __name__ == "__main__":
    main()
