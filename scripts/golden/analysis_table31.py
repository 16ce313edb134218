#!/usr/bin/env python3
"""Re-derives the confidence intervals of thesis Table 3.1 (seed 001, §3.3).

For every row: which CI formula (normal z = 1.96 S/sqrt(N) as in BT.500, or Student t with
N-1 df) and which panel size N reproduce the printed half width to its 3 decimals, allowing
the printed SD to be anywhere in its rounding interval [SD - 0.0005, SD + 0.0005]. Then: which
numbers of ratings n and SD divisors (n-1 sample, n population) can produce the printed mean
and SD from scores on a 0.5 grid (single ratings) or 0.25 grid (two ratings averaged).

Run: python3 scripts/golden/analysis_table31.py   (prints the table used in docs/analysis.md)
"""
import math

from scipy import stats

ROWS = [  # clip, CR, mean, SD, CI as printed
    ("2_2", 20, 4.705, 0.437, 0.238), ("2_2", 25, 4.545, 0.450, 0.245), ("2_2", 30, 4.159, 0.525, 0.285),
    ("2_2", 35, 3.886, 0.444, 0.241), ("2_2", 40, 3.727, 0.445, 0.242),
    ("49_14", 20, 4.885, 0.288, 0.199), ("49_14", 25, 4.615, 0.487, 0.337), ("49_14", 30, 4.115, 0.211, 0.146),
    ("49_14", 35, 3.923, 0.385, 0.267), ("49_14", 40, 3.404, 0.455, 0.315),
]


def ci_matches(sd, ci):
    out = []
    for n in range(2, 41):
        for method in ("z", "t"):
            q = stats.norm.ppf(0.975) if method == "z" else stats.t.ppf(0.975, n - 1)
            exact = round(q * sd / math.sqrt(n), 3) == ci
            lo, hi = q * (sd - 0.0005) / math.sqrt(n), q * (sd + 0.0005) / math.sqrt(n)
            if exact:
                out.append(f"{method} N={n}")
            elif lo - 0.0005 <= ci <= hi + 0.0005:
                out.append(f"{method} N={n} (within SD rounding)")
    return out


def feasible(m, sd, n, ddof, step):
    k = round(1 / step)  # scores are integers / k
    for s in range(k * n, 5 * k * n + 1):  # s = k * sum
        total = s / k
        if round(total / n, 3) != m:
            continue
        # q = k^2 * sum of squares, an integer with q ≡ s (mod 2) for the 0.5 grid
        target_lo = ((sd - 0.0005) ** 2 * (n - ddof) + total * total / n) * k * k
        target_hi = ((sd + 0.0005) ** 2 * (n - ddof) + total * total / n) * k * k
        for q in range(max(0, math.ceil(target_lo)), math.floor(target_hi) + 1):
            if k == 2 and (q - s) % 2:
                continue
            return True
    return False


print("| Clip | CR | Mean | SD | CI | CI reproduced by | mean·22 | mean·26 | n/divisor feasible (0.5 grid) | (0.25 grid) |")
print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
for clip, cr, m, sd, ci in ROWS:
    f05 = [f"{n}/{'n' if d == 0 else 'n-1'}" for n in (15, 22, 26) for d in (0, 1) if feasible(m, sd, n, d, 0.5)]
    f025 = [f"{n}/{'n' if d == 0 else 'n-1'}" for n in (11, 13, 15, 22, 26) for d in (0, 1) if feasible(m, sd, n, d, 0.25)]
    print(f"| {clip} | {cr}:1 | {m} | {sd} | {ci} | {', '.join(ci_matches(sd, ci))} | {m * 22:.2f} | {m * 26:.2f} | {', '.join(f05) or 'none'} | {', '.join(f025) or 'none'} |")
