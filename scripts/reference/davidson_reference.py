#!/usr/bin/env python3
"""Independent maximum-likelihood fit of Davidson's (1970) model for pair comparisons with
ties, for analysis/tests/davidson_interop.rs to check `analysis::bradley_terry::fit_with_ties`
against.

The model: item i has strength p_i = exp(s_i), and with a tie parameter nu > 0, in one
comparison of i and j

    P(i preferred) = p_i / D,  P(j preferred) = p_j / D,  P(tie) = nu * sqrt(p_i p_j) / D,
    D = p_i + p_j + nu * sqrt(p_i p_j).

Written from the model alone (not from the project's code):

- parameters x = (s without the anchor's, whose value is fixed at 0; theta = ln nu);
- log-likelihood sum over pairs of w_ij ln P(i) + w_ji ln P(j) + t_ij ln P(tie), every
  ln P computed as (its log numerator) - logsumexp(s_i, s_j, theta + (s_i + s_j) / 2) with
  scipy.special.logsumexp;
- its analytic gradient (d ln D / d s_i = P(i) + P(tie) / 2, d ln D / d theta = P(tie));
- minimised with scipy.optimize.minimize(method="BFGS", gtol=1e-11) from s = 0 and nu from
  the share of ties, then polished by up to five Newton steps with the Hessian below, each
  kept only where it shrinks the largest component of the gradient (BFGS alone can stop
  where rounding stalls its line search, about 1e-8 from the optimum);
- standard errors: the square roots of the diagonal of the inverse of the negative Hessian
  of the log-likelihood in x, the Hessian by central differences (step 1e-5) of the analytic
  gradient, symmetrised, inverted with numpy.linalg.inv; the interval s +- z * SE with
  z = scipy.stats.norm.ppf(0.5 + confidence / 2); the SE of nu by the delta method from
  theta, nu * SE(theta).

Input on stdin: {"n": N, "anchor": A, "wins": N x N (row preferred over column), "ties": N x N
(symmetric), "confidence": 0.95}, or a JSON list of such objects.
Output on stdout: {"scale", "se", "lower", "upper" (lists of N, the anchor's 0), "nu",
"nu_se", "log_nu", "log_nu_se", "log_likelihood", "gradient_norm" (the largest absolute
component of the gradient at the estimate), "bfgs_message", "bfgs_offset" (how far the
Newton polish moved BFGS's answer), "versions"}, or a list of them.

Install: pip install numpy scipy (the tests use target/bayes-env, pinned in
scripts/reference/bayes-requirements.txt)
Run: echo '{"n": 2, "anchor": 0, "wins": [[0, 3], [5, 0]], "ties": [[0, 2], [2, 0]],
"confidence": 0.95}' | python3 scripts/reference/davidson_reference.py
"""
import json
import sys

import numpy as np
import scipy
from scipy import optimize, special, stats


def pairs_of(wins, ties):
    """Arrays (i, j, w_ij, w_ji, t_ij) of the pairs i < j compared at least once."""
    n = wins.shape[0]
    rows = [
        (i, j, wins[i, j], wins[j, i], ties[i, j])
        for i in range(n)
        for j in range(i + 1, n)
        if wins[i, j] + wins[j, i] + ties[i, j] > 0
    ]
    a = np.array(rows, dtype=float).reshape(-1, 5)
    return a[:, 0].astype(int), a[:, 1].astype(int), a[:, 2], a[:, 3], a[:, 4]


class Davidson:
    def __init__(self, n, anchor, wins, ties):
        self.n = n
        self.anchor = anchor
        self.free = [k for k in range(n) if k != anchor]
        self.i, self.j, self.wij, self.wji, self.tij = pairs_of(wins, ties)
        self.nij = self.wij + self.wji + self.tij

    def unpack(self, x):
        s = np.zeros(self.n)
        s[self.free] = x[:-1]
        return s, x[-1]

    def log_probs(self, x):
        s, theta = self.unpack(x)
        si, sj = s[self.i], s[self.j]
        st = theta + (si + sj) / 2
        log_d = special.logsumexp(np.stack([si, sj, st]), axis=0)
        return si - log_d, sj - log_d, st - log_d

    def loglik(self, x):
        li, lj, lt = self.log_probs(x)
        return float(np.sum(self.wij * li + self.wji * lj + self.tij * lt))

    def gradient(self, x):
        li, lj, lt = self.log_probs(x)
        pi, pj, pt = np.exp(li), np.exp(lj), np.exp(lt)
        # d/ds_i of w_ij s_i + w_ji s_j + t_ij (theta + (s_i + s_j) / 2) - n_ij ln D.
        gi = self.wij + self.tij / 2 - self.nij * (pi + pt / 2)
        gj = self.wji + self.tij / 2 - self.nij * (pj + pt / 2)
        gs = np.zeros(self.n)
        np.add.at(gs, self.i, gi)
        np.add.at(gs, self.j, gj)
        gtheta = np.sum(self.tij - self.nij * pt)
        return np.concatenate([gs[self.free], [gtheta]])

    def hessian(self, x, h=1e-5):
        """Central differences of the analytic gradient, symmetrised."""
        m = len(x)
        out = np.empty((m, m))
        for k in range(m):
            e = np.zeros(m)
            e[k] = h
            out[:, k] = (self.gradient(x + e) - self.gradient(x - e)) / (2 * h)
        return (out + out.T) / 2


def fit(case):
    n = int(case["n"])
    anchor = int(case["anchor"])
    wins = np.array(case["wins"], dtype=float)
    ties = np.array(case["ties"], dtype=float)
    confidence = float(case.get("confidence", 0.95))
    model = Davidson(n, anchor, wins, ties)
    total_ties = np.sum(model.tij)
    total = np.sum(model.nij)
    share = total_ties / total
    x0 = np.zeros(n)
    x0[-1] = np.log(2 * share / (1 - share))
    res = optimize.minimize(
        lambda x: -model.loglik(x),
        x0,
        jac=lambda x: -model.gradient(x),
        method="BFGS",
        options={"gtol": 1e-11, "maxiter": 100000},
    )
    x = res.x
    for _ in range(5):
        step = np.linalg.solve(-model.hessian(x), model.gradient(x))
        if np.max(np.abs(model.gradient(x + step))) >= np.max(np.abs(model.gradient(x))):
            break
        x = x + step
    cov = np.linalg.inv(-model.hessian(x))
    se_free = np.sqrt(np.diag(cov))
    s, theta = model.unpack(x)
    se = np.zeros(n)
    se[model.free] = se_free[:-1]
    z = stats.norm.ppf(0.5 + confidence / 2)
    nu = float(np.exp(theta))
    return {
        "scale": s.tolist(),
        "se": se.tolist(),
        "lower": (s - z * se).tolist(),
        "upper": (s + z * se).tolist(),
        "nu": nu,
        "nu_se": nu * float(se_free[-1]),
        "log_nu": float(theta),
        "log_nu_se": float(se_free[-1]),
        "log_likelihood": model.loglik(x),
        "gradient_norm": float(np.max(np.abs(model.gradient(x)))),
        "bfgs_message": str(res.message),
        "bfgs_offset": float(np.max(np.abs(res.x - x))),
        "versions": {"numpy": np.__version__, "scipy": scipy.__version__},
    }


def main():
    data = json.load(sys.stdin)
    out = [fit(c) for c in data] if isinstance(data, list) else fit(data)
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main()
