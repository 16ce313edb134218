#!/usr/bin/env python3
"""Re-derives thesis Tables 3.2 and 3.3 (seed 001, §3.3) from their published numbers.

The tables print the mean of the proposed method, the mean of the comparison method (standard
wavelet, Table 3.2; bone lengths only, Table 3.3) and a "1-tailed T-test" p value. The
proposed method's SD is in Table 3.1; the comparison method's SD is printed nowhere, nor is n
(15 subjects are reported; the means imply 22 ratings per condition for clip 2_2 and 26 for
49_14; the CI column of Table 3.1 is reproduced with N = 13 and N = 8, see docs/analysis.md).

For every row and each candidate n this prints: the t the printed p implies (Student, df =
2n - 2), the comparison SD that reproduces the printed p under Welch and under Student (both
as one-tailed, and Welch read as two-tailed), the largest SD any sample on the 1-5 scale with
that mean can have (Bhatia-Davis), the one-tailed p range for a comparison SD from 0.3 to 1.0,
the SD at which p = 0.05, and for a paired test the SD of the differences the printed p implies
and the p at zero correlation with comparison SD 1.0. All p values come from
scipy.stats.ttest_ind_from_stats(..., equal_var=False/True, alternative="greater"); paired
from scipy.stats.t.sf. analysis/tests/thesis_tables.rs asserts the same numbers with the
crate's own ttest::*_from_summary.

Run: python3 scripts/reference/thesis_tables.py   (needs scipy; prints the numbers used in
docs/analysis.md)
"""
import math

from scipy import optimize, stats

T31 = {  # clip, CR -> proposed-method mean, SD (Table 3.1)
    ("2_2", 30): (4.159, 0.525), ("2_2", 35): (3.886, 0.444), ("2_2", 40): (3.727, 0.445),
    ("49_14", 30): (4.115, 0.211), ("49_14", 35): (3.923, 0.385), ("49_14", 40): (3.404, 0.455),
}
ROWS = [  # table, clip, CR, proposed mean, comparison mean, printed p
    ("3.2", "2_2", 30, 4.159, 3.773, 0.053), ("3.2", "2_2", 35, 3.886, 3.182, 0.016),
    ("3.2", "2_2", 40, 3.727, 2.364, 1.07e-6), ("3.2", "49_14", 30, 4.115, 3.692, 0.005),
    ("3.2", "49_14", 35, 3.923, 2.962, 0.004), ("3.2", "49_14", 40, 3.404, 2.308, 0.008),
    ("3.3", "2_2", 30, 4.159, 3.568, 0.010), ("3.3", "2_2", 35, 3.886, 3.182, 0.016),
    ("3.3", "2_2", 40, 3.727, 3.227, 0.022), ("3.3", "49_14", 30, 4.115, 3.538, 0.005),
    ("3.3", "49_14", 35, 3.923, 3.308, 0.004), ("3.3", "49_14", 40, 3.404, 2.769, 0.008),
]
RATINGS = {"2_2": 22, "49_14": 26}
CI_N = {"2_2": 13, "49_14": 8}
LO, HI = 0.3, 1.0


def p_two(m1, s1, m2, s2, n, equal_var, alternative="greater"):
    return stats.ttest_ind_from_stats(m1, s1, n, m2, s2, n, equal_var=equal_var,
                                      alternative=alternative).pvalue


def solve_sd(m1, s1, m2, n, target, equal_var, alternative="greater"):
    return optimize.brentq(lambda s2: p_two(m1, s1, m2, s2, n, equal_var, alternative) - target,
                           0.01, 10.0, xtol=1e-12)


def max_sd(m, n):
    """Largest sample SD (divisor n - 1) of n scores in [1, 5] with mean m (Bhatia-Davis)."""
    return math.sqrt((m - 1.0) * (5.0 - m) * n / (n - 1))


def row(table, clip, cr, m1, m2, p, n):
    s1 = T31[(clip, cr)][1]
    t = stats.t.isf(p, 2 * n - 2)
    welch = solve_sd(m1, s1, m2, n, p, False)
    student = solve_sd(m1, s1, m2, n, p, True)
    welch2 = solve_sd(m1, s1, m2, n, p, False, "two-sided")
    lo = p_two(m1, s1, m2, LO, n, False)
    hi = p_two(m1, s1, m2, HI, n, False)
    slo = p_two(m1, s1, m2, LO, n, True)
    shi = p_two(m1, s1, m2, HI, n, True)
    crit = solve_sd(m1, s1, m2, n, 0.05, False)
    sd_d = (m1 - m2) * math.sqrt(n) / stats.t.isf(p, n - 1)
    paired_worst = stats.t.sf((m1 - m2) * math.sqrt(n) / math.hypot(s1, HI), n - 1)
    if max(hi, shi) < 0.05:
        call = "significant for any SD"
    elif min(lo, slo) >= 0.05:
        call = "not significant for any SD"
    else:
        call = f"depends (significant iff SD < {crit:.2f})"
    return (f"| {table} | {clip} | {cr}:1 | {n} | {m1 - m2:.3f} | {p:g} | {t:.3f} | {welch:.2f} | "
            f"{student:.2f} | {welch2:.2f} | {max_sd(m2, n):.2f} | {lo:.2g} – {hi:.2g} | "
            f"{slo:.2g} – {shi:.2g} | {call} | {sd_d:.2f} | {paired_worst:.2g} |")


print("| Table | Clip | CR | n | Δ | p printed | t (Student) | SD Welch | SD Student | "
      "SD Welch 2-tailed | SD max | p Welch, SD 0.3 – 1.0 | p Student | call at 0.05 | "
      "paired S_d | paired p, ρ = 0 |")
print("| --- " * 16 + "|")
for which in (RATINGS, {"2_2": 15, "49_14": 15}, CI_N):
    for r in ROWS:
        print(row(*r, which[r[1]]))

# Population SD in Table 3.1 (docs/analysis.md): the sample SD is larger by sqrt(n/(n-1)).
print()
print("calls with the Table 3.1 SD read as a population SD (x sqrt(n/(n-1))):")
for which in (RATINGS, {"2_2": 15, "49_14": 15}, CI_N):
    for table, clip, cr, m1, m2, p in ROWS:
        n = which[clip]
        s1 = T31[(clip, cr)][1] * math.sqrt(n / (n - 1))
        hi = max(p_two(m1, s1, m2, HI, n, False), p_two(m1, s1, m2, HI, n, True))
        lo = min(p_two(m1, s1, m2, LO, n, False), p_two(m1, s1, m2, LO, n, True))
        print(table, clip, cr, n, f"{lo:.2g} – {hi:.2g}")
