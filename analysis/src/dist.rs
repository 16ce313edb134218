//! Thin wrappers over `statrs` distributions: quantiles polished to full double precision and
//! the noncentral t distribution, which `statrs` lacks.

use statrs::distribution::{Continuous, ContinuousCDF, Normal, StudentsT};
use statrs::function::beta::beta_reg;
use statrs::function::gamma::ln_gamma;

/// A standard Student t with `df` degrees of freedom (`df` > 0 and finite, checked by callers).
fn students_t(df: f64) -> Option<StudentsT> {
    StudentsT::new(0.0, 1.0, df).ok()
}

/// P(T ≤ t) for Student's t.
pub(crate) fn t_cdf(t: f64, df: f64) -> Option<f64> {
    let dist = students_t(df)?;
    Some(if t <= 0.0 {
        dist.cdf(t)
    } else {
        1.0 - dist.sf(t)
    })
}

/// P(T ≥ t) for Student's t, computed without cancellation in the upper tail.
pub(crate) fn t_sf(t: f64, df: f64) -> Option<f64> {
    let dist = students_t(df)?;
    Some(dist.sf(t))
}

/// Polishes `dist.inverse_cdf(p)` with Newton steps on the CDF, working in the tail nearer to
/// `p` to avoid cancellation (statrs' inverses are good to roughly 1e-10; the golden tests ask
/// for 1e-9 relative). `None` unless 0 < p < 1.
fn polished_quantile<D>(dist: &D, p: f64) -> Option<f64>
where
    D: Continuous<f64, f64> + ContinuousCDF<f64, f64>,
{
    if !(p > 0.0 && p < 1.0) {
        return None;
    }
    let mut x = dist.inverse_cdf(p);
    for _ in 0..3 {
        let density = dist.pdf(x);
        if density.is_nan() || density <= 0.0 {
            break;
        }
        let err = if p < 0.5 {
            dist.cdf(x) - p
        } else {
            (1.0 - p) - dist.sf(x)
        };
        let step = err / density;
        if !step.is_finite() {
            break;
        }
        x -= step;
    }
    Some(x)
}

/// The `p` quantile of Student's t.
pub(crate) fn t_quantile(p: f64, df: f64) -> Option<f64> {
    polished_quantile(&students_t(df)?, p)
}

/// The `p` quantile of the standard normal.
pub(crate) fn z_quantile(p: f64) -> Option<f64> {
    polished_quantile(&Normal::new(0.0, 1.0).ok()?, p)
}

/// Standard normal upper tail P(Z ≥ z).
pub(crate) fn z_sf(z: f64) -> f64 {
    Normal::new(0.0, 1.0).map_or(f64::NAN, |d| d.sf(z))
}

/// P(T ≤ t) for the noncentral t with `df` degrees of freedom and noncentrality `delta`.
///
/// Algorithm AS 243 (Lenth 1989, Applied Statistics 38:185-189): a series in incomplete beta
/// functions, summed until the error bound falls below 1e-15. Used for power analysis only,
/// where |delta| stays below ~40, which the series handles.
pub(crate) fn nct_cdf(t: f64, df: f64, delta: f64) -> f64 {
    const ERRMAX: f64 = 1e-15;
    const ITRMAX: u32 = 2000;
    let ln_sqrt_pi = 0.5 * std::f64::consts::PI.ln();
    let sqrt_2_over_pi = std::f64::consts::FRAC_2_SQRT_PI * std::f64::consts::FRAC_1_SQRT_2;
    let (tt, del, negdel) = if t < 0.0 {
        (-t, -delta, true)
    } else {
        (t, delta, false)
    };
    let x = tt * tt / (tt * tt + df);
    let mut tnc = 0.0;
    if x > 0.0 {
        let lambda = del * del;
        let mut p = 0.5 * (-0.5 * lambda).exp();
        let mut q = sqrt_2_over_pi * p * del;
        let mut s = 0.5 - p;
        let mut a = 0.5;
        let b = 0.5 * df;
        let rxb = (1.0 - x).powf(b);
        let albeta = ln_sqrt_pi + ln_gamma(b) - ln_gamma(a + b);
        let mut xodd = beta_reg(a, b, x);
        let mut godd = 2.0 * rxb * (a * x.ln() - albeta).exp();
        let mut xeven = 1.0 - rxb;
        let mut geven = b * x * rxb;
        tnc = p * xodd + q * xeven;
        let mut en = 1.0;
        for _ in 0..ITRMAX {
            a += 1.0;
            xodd -= godd;
            xeven -= geven;
            godd *= x * (a + b - 1.0) / a;
            geven *= x * (a + b - 0.5) / (a + 0.5);
            p *= lambda / (2.0 * en);
            q *= lambda / (2.0 * en + 1.0);
            s -= p;
            en += 1.0;
            tnc += p * xodd + q * xeven;
            let errbd = 2.0 * s * (xodd - godd);
            if errbd.abs() <= ERRMAX {
                break;
            }
        }
    }
    tnc += z_sf(del);
    let cdf = if negdel { 1.0 - tnc } else { tnc };
    cdf.clamp(0.0, 1.0)
}
