//! Centre-of-rotation estimators: the closed-form GDKE (seed 003, eq. 1-6) and an iterative
//! Levenberg-Marquardt least-squares sphere fit (the approach of O'Brien et al., seed 003
//! ref. 19) for comparison.
//!
//! ```
//! use markers::gdke::{gdke, GdkeOptions, JointKind};
//! // Points on a sphere of radius 2 about (1, 2, 3).
//! let mut pts = Vec::new();
//! for i in 0..40 {
//!     let (t, p) = (i as f64 * 0.37, i as f64 * 0.11);
//!     pts.push([1.0 + 2.0 * t.cos() * p.sin(), 2.0 + 2.0 * t.sin() * p.sin(), 3.0 + 2.0 * p.cos()]);
//! }
//! let fit = gdke(&pts, &GdkeOptions::default()).unwrap();
//! assert!(matches!(fit.kind, JointKind::Spherical));
//! assert!((fit.centre[0] - 1.0).abs() < 1e-9 && (fit.radius - 2.0).abs() < 1e-9);
//! ```

use nalgebra::{Matrix3, Matrix4, SymmetricEigen, Vector3, Vector4};

use super::MarkerError;

/// Minimum number of samples for a centre fit (seed 003, section 2: "at least 4 positions").
pub const MIN_SAMPLES: usize = 4;

/// How a joint moves, as read from the covariance of the marker positions.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JointKind {
    /// Motion on a sphere (2-3 DOF): the centre is eq. 5.
    Spherical,
    /// Planar motion on a circle (1 DOF, hinge): the centre is eq. 6 and `axis` is the unit
    /// null vector `n` of the covariance (the hinge axis), in the input frame.
    Hinge {
        /// Unit normal of the plane of motion.
        axis: [f64; 3],
    },
    /// The marker does not move relative to the parent: no centre can be estimated.
    NotMoving,
}

/// Thresholds of the GDKE classification (seed 003, section 2.3, steps 4-5).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GdkeOptions {
    /// Condition number `λ_max/λ_min` of `C` above which the motion is planar (hinge).
    pub hinge_condition: f64,
    /// Standard deviation (input units) of the positions along their widest direction at or
    /// below which the joint counts as not moving.
    pub still_std: f64,
}

impl Default for GdkeOptions {
    fn default() -> Self {
        GdkeOptions {
            hinge_condition: 1e3,
            still_std: 1e-9,
        }
    }
}

/// The result of a centre fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CentreFit {
    /// Centre of rotation in the input frame; for [`JointKind::NotMoving`] the mean position.
    pub centre: [f64; 3],
    /// Root-mean-square distance of the samples from the centre (0 when not moving).
    pub radius: f64,
    /// The classification.
    pub kind: JointKind,
    /// Condition number `λ_max/λ_min` of `C` (`f64::INFINITY` when `λ_min` is 0).
    pub condition: f64,
    /// Samples used.
    pub samples: usize,
}

fn check(points: &[[f64; 3]], what: &str) -> Result<(), MarkerError> {
    if points.len() < MIN_SAMPLES {
        return Err(MarkerError::TooFewSamples {
            what: what.to_string(),
            got: points.len(),
            needed: MIN_SAMPLES,
        });
    }
    if let Some(index) = points.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(MarkerError::NonFinite { index });
    }
    Ok(())
}

/// Moments of eq. 2-4: mean `x̄` (eq. 3), covariance `C` (eq. 2) and third-moment vector `S`
/// (eq. 4), both with the `1/(N−1)` normalisation of the paper.
fn raw_moments(points: &[[f64; 3]]) -> (Vector3<f64>, Matrix3<f64>, Vector3<f64>) {
    let n = points.len() as f64;
    // Eq. 3.
    let mut mean = Vector3::zeros();
    for p in points {
        mean += Vector3::new(p[0], p[1], p[2]);
    }
    mean /= n;
    // Eq. 2 and 4 in one pass over the centred points.
    let mut c = Matrix3::zeros();
    let mut s = Vector3::zeros();
    for p in points {
        let d = Vector3::new(p[0], p[1], p[2]) - mean;
        let dd = d * d.transpose();
        c += dd;
        s += d * d.norm_squared();
    }
    c /= n - 1.0;
    s /= n - 1.0;
    (mean, c, s)
}

/// Which classification to use: automatic (section 2.3 step 5) or imposed by the caller
/// (a lab that knows the knee is a hinge).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum KindHint {
    /// Decide by the condition number.
    #[default]
    Auto,
    /// Always eq. 5 (falls back to eq. 6 when `C` is singular).
    Spherical,
    /// Always eq. 6.
    Hinge,
}

/// GDKE centre of rotation of points `x_i` given in the parent's frame (seed 003, section 2.3).
///
/// Steps: moments (eq. 2-4); eigen-decomposition of the symmetric `C` gives its condition
/// number and null vector `n` (for a symmetric positive semi-definite matrix the SVD and the
/// eigen-decomposition coincide); when the condition number is at most
/// [`GdkeOptions::hinge_condition`] the centre is eq. 5 solved by Cholesky, otherwise the
/// planar centre of eq. 6, `c' = c + n·nᵀ(x̄ − c)`, computed as
/// `x̄ + ½·Σ_{k≠n} e_k·e_kᵀ·S/λ_k`, which is eq. 6 with `C⁻¹` written in its eigenbasis and
/// stays finite when `C` is exactly singular.
///
/// # Errors
/// [`MarkerError::TooFewSamples`] for fewer than 4 points, [`MarkerError::NonFinite`].
pub fn gdke(points: &[[f64; 3]], options: &GdkeOptions) -> Result<CentreFit, MarkerError> {
    gdke_pooled(&[points], options, KindHint::Auto)
}

/// GDKE over several markers of one segment sharing a centre: the sum over markers of the
/// eq. 1 variances is minimised, whose gradient (section 2.1) gives
/// `(Σ_m C_m)·c = Σ_m (C_m·x̄_m + ½·S_m)` (with unnormalised sums `C_m`, `S_m`); for one marker
/// this is eq. 5. Classification and the planar case (eq. 6, centre in the plane through the
/// mean of the marker means) work on `Σ_m C_m` as in [`gdke`]. Markers with fewer than 4
/// samples are skipped.
///
/// # Errors
/// [`MarkerError::TooFewSamples`] when no marker has 4 samples, [`MarkerError::NonFinite`].
pub fn gdke_pooled(
    markers: &[&[[f64; 3]]],
    options: &GdkeOptions,
    hint: KindHint,
) -> Result<CentreFit, MarkerError> {
    let mut c_tot = Matrix3::zeros();
    let mut b = Vector3::zeros();
    let mut mean_of_means = Vector3::zeros();
    let mut used = 0usize;
    let mut samples = 0usize;
    let mut most = 0usize;
    for pts in markers {
        most = most.max(pts.len());
        if pts.len() < MIN_SAMPLES {
            continue;
        }
        check(pts, "points")?;
        let (mean, c, s) = raw_moments(pts);
        let w = pts.len() as f64 - 1.0;
        c_tot += c * w;
        b += (c * mean + 0.5 * s) * w;
        mean_of_means += mean;
        used += 1;
        samples += pts.len();
    }
    if used == 0 {
        return Err(MarkerError::TooFewSamples {
            what: "points".into(),
            got: most,
            needed: MIN_SAMPLES,
        });
    }
    mean_of_means /= used as f64;
    let c = c_tot / (samples - used) as f64;
    let r = (b - c_tot * mean_of_means) / (samples - used) as f64;
    let eig = SymmetricEigen::new(c);
    let (mut imax, mut imin) = (0, 0);
    for k in 1..3 {
        if eig.eigenvalues[k] > eig.eigenvalues[imax] {
            imax = k;
        }
        if eig.eigenvalues[k] < eig.eigenvalues[imin] {
            imin = k;
        }
    }
    let lmax = eig.eigenvalues[imax].max(0.0);
    let lmin = eig.eigenvalues[imin].max(0.0);
    let condition = if lmin > 0.0 {
        lmax / lmin
    } else {
        f64::INFINITY
    };
    let scale = mean_of_means.norm().max(1.0);
    if lmax.sqrt() <= options.still_std.max(1e-12 * scale) {
        return Ok(CentreFit {
            centre: [mean_of_means.x, mean_of_means.y, mean_of_means.z],
            radius: 0.0,
            kind: JointKind::NotMoving,
            condition,
            samples,
        });
    }
    let want_sphere = match hint {
        KindHint::Auto => condition <= options.hinge_condition,
        KindHint::Spherical => true,
        KindHint::Hinge => false,
    };
    let spherical = if want_sphere {
        // Eq. 5 by Cholesky: C is positive definite here.
        c.cholesky().map(|ch| mean_of_means + ch.solve(&r))
    } else {
        None
    };
    let (centre, kind) = if let Some(centre) = spherical {
        (centre, JointKind::Spherical)
    } else {
        // Eq. 6 in the eigenbasis: drop the null direction n from C⁻¹·r.
        let mut centre = mean_of_means;
        for k in (0..3).filter(|&k| k != imin) {
            let e = eig.eigenvectors.column(k);
            let l = eig.eigenvalues[k];
            if l > 0.0 {
                centre += e * (e.dot(&r) / l);
            }
        }
        let n = eig.eigenvectors.column(imin).normalize();
        (
            centre,
            JointKind::Hinge {
                axis: [n.x, n.y, n.z],
            },
        )
    };
    let radius = markers
        .iter()
        .filter(|p| p.len() >= MIN_SAMPLES)
        .map(|p| rms_radius(p, &centre))
        .sum::<f64>()
        / used as f64;
    Ok(CentreFit {
        centre: [centre.x, centre.y, centre.z],
        radius,
        kind,
        condition,
        samples,
    })
}

fn rms_radius(points: &[[f64; 3]], centre: &Vector3<f64>) -> f64 {
    let sum: f64 = points
        .iter()
        .map(|p| (Vector3::new(p[0], p[1], p[2]) - centre).norm_squared())
        .sum();
    (sum / points.len() as f64).sqrt()
}

/// Options of the iterative least-squares sphere fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LsqOptions {
    /// Maximum Levenberg-Marquardt iterations.
    pub max_iterations: usize,
    /// Stop when a step moves the centre by less than this (input units).
    pub tolerance: f64,
}

impl Default for LsqOptions {
    fn default() -> Self {
        LsqOptions {
            max_iterations: 200,
            tolerance: 1e-12,
        }
    }
}

/// The result of the least-squares sphere fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereFit {
    /// Centre.
    pub centre: [f64; 3],
    /// Radius.
    pub radius: f64,
    /// Iterations taken.
    pub iterations: usize,
    /// True when the step fell below the tolerance before the iteration limit.
    pub converged: bool,
}

/// Geometric least-squares sphere fit, minimising `Σ (|x_i − c| − r)²` by Levenberg-Marquardt
/// from an initial centre (the points' mean when `None`, which must then not lie on the
/// sphere's centre plane of symmetry for the iteration to find the right side).
///
/// # Errors
/// [`MarkerError::TooFewSamples`] for fewer than 4 points, [`MarkerError::NonFinite`].
pub fn least_squares_sphere(
    points: &[[f64; 3]],
    initial: Option<[f64; 3]>,
    options: &LsqOptions,
) -> Result<SphereFit, MarkerError> {
    check(points, "points")?;
    let pts: Vec<Vector3<f64>> = points
        .iter()
        .map(|p| Vector3::new(p[0], p[1], p[2]))
        .collect();
    let n = pts.len() as f64;
    let mean = pts.iter().sum::<Vector3<f64>>() / n;
    let mut c = initial.map_or(mean, |p| Vector3::new(p[0], p[1], p[2]));
    let mut r = pts.iter().map(|p| (p - c).norm()).sum::<f64>() / n;
    let cost = |c: &Vector3<f64>, r: f64| -> f64 {
        pts.iter()
            .map(|p| {
                let e = (p - c).norm() - r;
                e * e
            })
            .sum()
    };
    let mut current = cost(&c, r);
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    while iterations < options.max_iterations {
        iterations += 1;
        // Residual e_i = |x_i − c| − r; Jacobian row [−(x_i − c)ᵀ/|x_i − c|, −1].
        let mut jtj = Matrix4::zeros();
        let mut jte = Vector4::zeros();
        for p in &pts {
            let d = p - c;
            let dist = d.norm();
            if dist <= 0.0 {
                continue;
            }
            let row = Vector4::new(-d.x / dist, -d.y / dist, -d.z / dist, -1.0);
            jtj += row * row.transpose();
            jte += row * (dist - r);
        }
        let mut accepted = false;
        for _ in 0..30 {
            let mut a = jtj;
            for k in 0..4 {
                a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
            }
            let Some(ch) = a.cholesky() else {
                lambda *= 10.0;
                continue;
            };
            let step = ch.solve(&(-jte));
            let c_new = c + Vector3::new(step[0], step[1], step[2]);
            let r_new = r + step[3];
            let trial = cost(&c_new, r_new);
            if trial <= current {
                let moved = (c_new - c).norm();
                c = c_new;
                r = r_new;
                current = trial;
                lambda = (lambda * 0.1).max(1e-12);
                accepted = true;
                if moved < options.tolerance * (1.0 + c.norm()) {
                    converged = true;
                }
                break;
            }
            lambda *= 10.0;
        }
        if !accepted {
            // No step lowers the cost: a minimum to machine precision.
            converged = true;
        }
        if converged {
            break;
        }
    }
    Ok(SphereFit {
        centre: [c.x, c.y, c.z],
        radius: r.abs(),
        iterations,
        converged,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sphere(centre: [f64; 3], r: f64, n: usize) -> Vec<[f64; 3]> {
        (0..n)
            .map(|i| {
                let t = i as f64 * 2.399_963;
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let s = (1.0 - z * z).sqrt();
                [
                    centre[0] + r * s * t.cos(),
                    centre[1] + r * s * t.sin(),
                    centre[2] + r * z,
                ]
            })
            .collect()
    }

    fn dist3(a: [f64; 3], b: [f64; 3]) -> f64 {
        ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
    }

    #[test]
    fn too_few_and_non_finite_are_errors() {
        let o = GdkeOptions::default();
        assert!(matches!(
            gdke(&[[0.0; 3]; 3], &o),
            Err(MarkerError::TooFewSamples { got: 3, .. })
        ));
        let mut p = sphere([0.0; 3], 1.0, 10);
        p[4][1] = f64::NAN;
        assert!(matches!(
            gdke(&p, &o),
            Err(MarkerError::NonFinite { index: 4 })
        ));
    }

    #[test]
    fn still_points_are_not_moving() {
        let fit = gdke(&[[1.0, 2.0, 3.0]; 6], &GdkeOptions::default()).unwrap();
        assert_eq!(fit.kind, JointKind::NotMoving);
        assert!(dist3(fit.centre, [1.0, 2.0, 3.0]) < 1e-12);
    }

    #[test]
    fn least_squares_matches_gdke_on_exact_sphere() {
        let pts = sphere([0.3, -0.2, 0.9], 0.4, 50);
        let g = gdke(&pts, &GdkeOptions::default()).unwrap();
        let l = least_squares_sphere(&pts, None, &LsqOptions::default()).unwrap();
        for k in 0..3 {
            assert!((g.centre[k] - l.centre[k]).abs() < 1e-9);
        }
        assert!((l.radius - 0.4).abs() < 1e-9 && l.converged);
    }
}
