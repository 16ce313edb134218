//! Small dense linear algebra for the mixed models ([`crate::mixed`], [`crate::clmm`]):
//! square matrices stored row-major, a Cholesky factor and the solves and inverses over it.
//! The models are a lab study's size (a few hundred random effects at most), so nothing here
//! is sparse or blocked.

// Matrix code indexes rows and columns by number, as the equations do.
#![allow(clippy::needless_range_loop)]

/// A dense `n × m` matrix, row-major.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Matrix {
    pub(crate) rows: usize,
    pub(crate) cols: usize,
    pub(crate) data: Vec<f64>,
}

impl Matrix {
    /// An `rows × cols` matrix of zeros.
    pub(crate) fn zeros(rows: usize, cols: usize) -> Self {
        Self {
            rows,
            cols,
            data: vec![0.0; rows * cols],
        }
    }

    /// Element `(i, j)`.
    pub(crate) fn at(&self, i: usize, j: usize) -> f64 {
        self.data[i * self.cols + j]
    }

    /// Element `(i, j)`, mutably.
    pub(crate) fn at_mut(&mut self, i: usize, j: usize) -> &mut f64 {
        &mut self.data[i * self.cols + j]
    }
}

/// The lower-triangular Cholesky factor `L` of a symmetric positive definite matrix
/// (`A = L Lᵀ`). Row `i` of `L` is zero left of row `i` of `A`'s first nonzero (the
/// envelope: a Cholesky factor fills in only within it), so the factorization and the solves
/// skip those columns; the zeros they skip would add nothing, so the result is the dense
/// algorithm's to the last bit. The mixed models' matrices are block diagonal with a border
/// (subjects, then clips), which makes this nearly linear in the order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Cholesky {
    l: Matrix,
    /// Per row, its first nonzero column.
    first: Vec<usize>,
}

impl Cholesky {
    /// Factors `a` (only its lower triangle is read); `None` when `a` is not square or not
    /// positive definite to working precision (a pivot ≤ 1e-12 times the largest diagonal
    /// element).
    pub(crate) fn new(a: &Matrix) -> Option<Self> {
        let n = a.rows;
        if a.cols != n {
            return None;
        }
        let scale = (0..n).map(|i| a.at(i, i).abs()).fold(0.0, f64::max);
        let first: Vec<usize> = (0..n)
            .map(|i| (0..i).find(|&j| a.at(i, j) != 0.0).unwrap_or(i))
            .collect();
        let mut l = Matrix::zeros(n, n);
        for j in 0..n {
            let mut d = a.at(j, j);
            for k in first[j]..j {
                d -= l.at(j, k) * l.at(j, k);
            }
            if d.is_nan() || d <= 1e-12 * scale || !d.is_finite() {
                return None;
            }
            let d = d.sqrt();
            *l.at_mut(j, j) = d;
            for i in j + 1..n {
                if first[i] > j {
                    continue;
                }
                let mut s = a.at(i, j);
                for k in first[i].max(first[j])..j {
                    s -= l.at(i, k) * l.at(j, k);
                }
                *l.at_mut(i, j) = s / d;
            }
        }
        Some(Self { l, first })
    }

    /// The order of the matrix.
    pub(crate) fn n(&self) -> usize {
        self.l.rows
    }

    /// log det L = ½ log det A.
    pub(crate) fn log_det_l(&self) -> f64 {
        (0..self.n()).map(|i| self.l.at(i, i).ln()).sum()
    }

    /// Solves `L x = b` in place.
    pub(crate) fn solve_l(&self, b: &mut [f64]) {
        for i in 0..self.n() {
            let mut s = b[i];
            for k in self.first[i]..i {
                s -= self.l.at(i, k) * b[k];
            }
            b[i] = s / self.l.at(i, i);
        }
    }

    /// Solves `Lᵀ x = b` in place.
    pub(crate) fn solve_lt(&self, b: &mut [f64]) {
        let n = self.n();
        for i in (0..n).rev() {
            let mut s = b[i];
            for k in i + 1..n {
                if self.first[k] <= i {
                    s -= self.l.at(k, i) * b[k];
                }
            }
            b[i] = s / self.l.at(i, i);
        }
    }

    /// Solves `A x = b` in place.
    pub(crate) fn solve(&self, b: &mut [f64]) {
        self.solve_l(b);
        self.solve_lt(b);
    }

    /// `A⁻¹`.
    pub(crate) fn inverse(&self) -> Matrix {
        let n = self.n();
        let mut inv = Matrix::zeros(n, n);
        let mut e = vec![0.0; n];
        for j in 0..n {
            e.fill(0.0);
            e[j] = 1.0;
            self.solve(&mut e);
            for i in 0..n {
                *inv.at_mut(i, j) = e[i];
            }
        }
        inv
    }
}

/// Minimizes `f` by Nelder-Mead within the box `lower ≤ x` (a vertex outside is projected
/// onto it), from `start` with initial steps `step`; stops when the simplex's values agree to
/// `ftol` (relative, plus 1e-12 absolute) and its vertices to `xtol`, or after `max_evals`
/// evaluations. Restarts from the best vertex until a restart no longer improves the value
/// by more than `ftol` (at most 10 restarts), the standard guard against a collapsed simplex.
/// Returns (best point, its value, evaluations, converged).
pub(crate) fn nelder_mead(
    f: &mut dyn FnMut(&[f64]) -> f64,
    start: &[f64],
    lower: &[f64],
    step: f64,
    tolerances: (f64, f64),
    max_evals: usize,
) -> (Vec<f64>, f64, usize, bool) {
    let (ftol, xtol) = tolerances;
    let mut evals = 0;
    let mut best = start.to_vec();
    let mut best_f = f64::INFINITY;
    let mut converged = false;
    for _restart in 0..=10 {
        let (x, fx, used, done) = nelder_mead_once(
            f,
            &best,
            lower,
            step,
            (ftol, xtol),
            max_evals - evals.min(max_evals),
        );
        evals += used;
        let improved = best_f - fx > ftol * (fx.abs() + 1.0);
        if fx <= best_f {
            best = x;
            best_f = fx;
        }
        converged = done;
        if !done || !improved || evals >= max_evals {
            break;
        }
    }
    (best, best_f, evals, converged)
}

fn project(x: &mut [f64], lower: &[f64]) {
    for (v, lo) in x.iter_mut().zip(lower) {
        if *v < *lo || v.is_nan() {
            *v = *lo;
        }
    }
}

fn nelder_mead_once(
    f: &mut dyn FnMut(&[f64]) -> f64,
    start: &[f64],
    lower: &[f64],
    step: f64,
    (ftol, xtol): (f64, f64),
    max_evals: usize,
) -> (Vec<f64>, f64, usize, bool) {
    let n = start.len();
    let mut evals = 0;
    let mut eval = |x: &[f64], evals: &mut usize| {
        *evals += 1;
        let v = f(x);
        if v.is_nan() { f64::INFINITY } else { v }
    };
    let mut simplex: Vec<Vec<f64>> = Vec::with_capacity(n + 1);
    simplex.push(start.to_vec());
    for i in 0..n {
        let mut v = start.to_vec();
        let h = if v[i].abs() > 1e-8 {
            step * v[i].abs().max(0.05)
        } else {
            step
        };
        v[i] += h;
        simplex.push(v);
    }
    let mut values: Vec<f64> = simplex.iter().map(|v| eval(v, &mut evals)).collect();
    let mut converged = false;
    while evals < max_evals {
        let mut order: Vec<usize> = (0..=n).collect();
        order.sort_by(|&a, &b| values[a].total_cmp(&values[b]));
        simplex = order.iter().map(|&i| simplex[i].clone()).collect();
        values = order.iter().map(|&i| values[i]).collect();
        let spread = values[n] - values[0];
        let size = simplex[1..]
            .iter()
            .flat_map(|v| v.iter().zip(&simplex[0]).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max);
        if spread <= ftol * (values[0].abs() + 1.0) + 1e-12 && size <= xtol {
            converged = true;
            break;
        }
        let centroid: Vec<f64> = (0..n)
            .map(|j| simplex[..n].iter().map(|v| v[j]).sum::<f64>() / n as f64)
            .collect();
        let along = |t: f64| -> Vec<f64> {
            let mut x: Vec<f64> = centroid
                .iter()
                .zip(&simplex[n])
                .map(|(c, w)| c + t * (w - c))
                .collect();
            project(&mut x, lower);
            x
        };
        let reflected = along(-1.0);
        let fr = eval(&reflected, &mut evals);
        if fr < values[0] {
            let expanded = along(-2.0);
            let fe = eval(&expanded, &mut evals);
            if fe < fr {
                simplex[n] = expanded;
                values[n] = fe;
            } else {
                simplex[n] = reflected;
                values[n] = fr;
            }
        } else if fr < values[n - 1] {
            simplex[n] = reflected;
            values[n] = fr;
        } else {
            let (contracted, fc) = if fr < values[n] {
                let c = along(-0.5);
                let fc = eval(&c, &mut evals);
                (c, fc)
            } else {
                let c = along(0.5);
                let fc = eval(&c, &mut evals);
                (c, fc)
            };
            if fc < values[n].min(fr) {
                simplex[n] = contracted;
                values[n] = fc;
            } else {
                for i in 1..=n {
                    let shrunk: Vec<f64> = simplex[0]
                        .iter()
                        .zip(&simplex[i])
                        .map(|(b, v)| b + 0.5 * (v - b))
                        .collect();
                    values[i] = eval(&shrunk, &mut evals);
                    simplex[i] = shrunk;
                }
            }
        }
    }
    let best = (0..=n)
        .min_by(|&a, &b| values[a].total_cmp(&values[b]))
        .unwrap_or(0);
    (simplex[best].clone(), values[best], evals, converged)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_and_inverts() {
        let a = Matrix {
            rows: 3,
            cols: 3,
            data: vec![4.0, 2.0, 0.6, 2.0, 2.0, 0.5, 0.6, 0.5, 3.0],
        };
        let c = Cholesky::new(&a).unwrap();
        let mut b = vec![1.0, 2.0, 3.0];
        c.solve(&mut b);
        for i in 0..3 {
            let row: f64 = (0..3).map(|j| a.at(i, j) * b[j]).sum();
            assert!((row - [1.0, 2.0, 3.0][i]).abs() < 1e-12);
        }
        let inv = c.inverse();
        assert!((inv.at(0, 0) * 4.0 + inv.at(0, 1) * 2.0 + inv.at(0, 2) * 0.6 - 1.0).abs() < 1e-12);
        // det = 4(6 - .25) - 2(6 - .3) + .6(1 - 1.2) = 23 - 11.4 - 0.12
        assert!((2.0 * c.log_det_l() - (23.0f64 - 11.4 - 0.12).ln()).abs() < 1e-12);
        let singular = Matrix {
            rows: 2,
            cols: 2,
            data: vec![1.0, 1.0, 1.0, 1.0],
        };
        assert!(Cholesky::new(&singular).is_none());
    }

    #[test]
    fn nelder_mead_finds_a_bounded_minimum() {
        let mut f = |x: &[f64]| (x[0] - 1.0).powi(2) + (x[1] + 2.0).powi(2) + x[0] * x[1] * 0.1;
        let (x, _, _, ok) =
            nelder_mead(&mut f, &[0.5, 0.5], &[0.0, 0.0], 0.25, (1e-14, 1e-9), 5000);
        assert!(ok);
        // x[1] is held at its bound 0; then x[0] = 1.
        assert!(x[1].abs() < 1e-8 && (x[0] - 1.0).abs() < 1e-6, "{x:?}");
    }
}
