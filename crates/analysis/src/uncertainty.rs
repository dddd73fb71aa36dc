//! Measurement uncertainty as the GUM (JCGM 100) forms it: standard
//! uncertainties from the data (Type A, with their degrees of freedom)
//! and from what is known of the bench (Type B: certificates, datasheets,
//! alignment records), combined by root sum of squares (the law of
//! propagation with sensitivity coefficients already applied), the
//! effective degrees of freedom by Welch-Satterthwaite, and the expanded
//! uncertainty `U = k u` with `k` the Student t factor for 95.45 %
//! coverage at those degrees of freedom (2 when they are many).
//!
//! Pure math: a contribution arrives in the figure's own unit.

use serde::{Deserialize, Serialize};

/// How a contribution was evaluated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Evaluation {
    /// From the statistics of the run's own data.
    A,
    /// From other knowledge (a certificate, a datasheet, a record).
    B,
}

/// One line of an uncertainty budget, in the figure's unit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Contribution {
    /// What it is (`noise of 12 block means`, `table rate accuracy`).
    pub source: String,
    /// Type A or Type B.
    #[serde(rename = "type")]
    pub evaluation: Evaluation,
    /// Standard uncertainty it adds, in the figure's unit (sensitivity
    /// coefficient applied).
    pub u: f64,
    /// Its degrees of freedom (none: known well, infinite).
    pub dof: Option<f64>,
    /// Where the value comes from and how it was turned into `u`.
    pub basis: String,
}

impl Contribution {
    /// A Type A contribution with `dof` degrees of freedom.
    pub fn type_a(source: &str, u: f64, dof: f64, basis: impl Into<String>) -> Self {
        Self {
            source: source.to_owned(),
            evaluation: Evaluation::A,
            u: u.abs(),
            dof: Some(dof),
            basis: basis.into(),
        }
    }

    /// A Type B contribution (infinite degrees of freedom: the bound is
    /// taken as known).
    pub fn type_b(source: &str, u: f64, basis: impl Into<String>) -> Self {
        Self {
            source: source.to_owned(),
            evaluation: Evaluation::B,
            u: u.abs(),
            dof: None,
            basis: basis.into(),
        }
    }
}

/// Coverage the expanded uncertainty aims at: 95.45 %, that of k = 2 for
/// a normal distribution (GUM 6.2.2, ILAC P14).
pub const COVERAGE: f64 = 0.9545;

/// A combined and expanded uncertainty with its budget.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Uncertainty {
    /// Combined standard uncertainty, in the figure's unit.
    pub u: f64,
    /// Expanded uncertainty `k u`.
    #[serde(rename = "U")]
    pub expanded: f64,
    /// Coverage factor.
    pub k: f64,
    /// Effective degrees of freedom (Welch-Satterthwaite; none: infinite).
    pub dof: Option<f64>,
    /// The contributions, largest first.
    pub budget: Vec<Contribution>,
}

/// An uncertainty as a record keeps it: `u`, `U` and `k`, without the
/// budget (the log's measurement and the results store).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Expanded {
    /// Combined standard uncertainty.
    pub u: f64,
    /// Expanded uncertainty `k u`.
    #[serde(rename = "U")]
    pub expanded: f64,
    /// Coverage factor.
    pub k: f64,
}

impl Uncertainty {
    /// `u`, `U` and `k`.
    pub fn brief(&self) -> Expanded {
        Expanded {
            u: self.u,
            expanded: self.expanded,
            k: self.k,
        }
    }

    /// Combine `budget` (root sum of squares) and expand it to 95.45 %
    /// coverage; none when nothing contributes or a contribution is not
    /// finite.
    pub fn combine(mut budget: Vec<Contribution>) -> Option<Self> {
        if budget.is_empty() || budget.iter().any(|c| !c.u.is_finite()) {
            return None;
        }
        budget.sort_by(|a, b| b.u.total_cmp(&a.u));
        let u = budget.iter().map(|c| c.u * c.u).sum::<f64>().sqrt();
        let dof = effective_dof(&budget, u);
        let k = coverage_factor(dof);
        Some(Self {
            u,
            expanded: k * u,
            k,
            dof,
            budget,
        })
    }
}

/// Welch-Satterthwaite: `u^4 / sum(u_i^4 / nu_i)` over the contributions
/// with finite degrees of freedom (none when every one is infinite, or
/// the combined uncertainty is zero).
pub fn effective_dof(budget: &[Contribution], u: f64) -> Option<f64> {
    if u <= 0.0 {
        return None;
    }
    let denom: f64 = budget
        .iter()
        .filter_map(|c| Some(c.u.powi(4) / c.dof.filter(|d| *d > 0.0)?))
        .sum();
    (denom > 0.0).then(|| u.powi(4) / denom)
}

/// The Student t factor for [`COVERAGE`] at `dof` degrees of freedom
/// (at least 1); 2 for infinite degrees of freedom (GUM's convention for
/// k = 2, which 95.45 % is).
pub fn coverage_factor(dof: Option<f64>) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    match dof {
        None => 2.0,
        Some(d) => {
            let d = d.max(1.0);
            match StudentsT::new(0.0, 1.0, d) {
                // Beyond ~1e4 degrees of freedom t is 2 to four digits.
                Ok(t) if d < 1e4 => t.inverse_cdf(0.5 + COVERAGE / 2.0),
                _ => 2.0,
            }
        }
    }
}

/// The standard uncertainty of a rectangular distribution of half-width
/// `a`: `a / sqrt(3)` (GUM 4.3.7).
pub fn rectangular(a: f64) -> f64 {
    a.abs() / 3f64.sqrt()
}

/// Relative standard uncertainty of a sample standard deviation of `n`
/// normal values, `1 / sqrt(2 (n - 1))` (GUM E.4.3), and its degrees of
/// freedom `n - 1`; none below two values.
pub fn of_std_dev(n: usize) -> Option<(f64, f64)> {
    let dof = n.checked_sub(1).filter(|d| *d > 0)? as f64;
    Some((1.0 / (2.0 * dof).sqrt(), dof))
}

/// Expected range (max - min) of `m` independent standard normal values,
/// d2 of the range chart tables, by numerical integration of
/// `1 - (1 - F)^m - F^m` over the line. Used for the noise floor of a
/// peak-to-peak figure.
pub fn expected_range(m: usize) -> f64 {
    use statrs::distribution::{ContinuousCDF, Normal};
    if m < 2 {
        return 0.0;
    }
    let Ok(n) = Normal::new(0.0, 1.0) else {
        return f64::NAN;
    };
    let m = m as i32;
    let (lo, hi, steps) = (-9.0, 9.0, 3600);
    let h = (hi - lo) / f64::from(steps);
    // Simpson's rule over [-9, 9]: the integrand is below 1e-18 beyond.
    (0..=steps)
        .map(|i| {
            let x = lo + h * f64::from(i);
            let f = n.cdf(x);
            let g = 1.0 - (1.0 - f).powi(m) - f.powi(m);
            let w = if i == 0 || i == steps {
                1.0
            } else if i % 2 == 1 {
                4.0
            } else {
                2.0
            };
            w * g
        })
        .sum::<f64>()
        * h
        / 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn k_follows_the_student_t_and_is_two_when_dof_are_many() {
        assert_eq!(coverage_factor(None), 2.0);
        // GUM table G.2 (95.45 %): nu = 1: 13.97, 5: 2.65, 10: 2.28, 50: 2.05.
        for (dof, t) in [(1.0, 13.97), (5.0, 2.65), (10.0, 2.28), (50.0, 2.05)] {
            assert!((coverage_factor(Some(dof)) - t).abs() < 0.01, "{dof}");
        }
        assert!((coverage_factor(Some(1e6)) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn a_budget_combines_by_root_sum_of_squares_with_welch_satterthwaite() {
        let u = Uncertainty::combine(vec![
            Contribution::type_b("b", 4.0, "rect"),
            Contribution::type_a("a", 3.0, 11.0, "12 blocks"),
        ])
        .expect("combined");
        assert!((u.u - 5.0).abs() < 1e-12);
        // nu_eff = 5^4 / (3^4 / 11) = 84.9; t(84.9) for 95.45 %.
        let dof = u.dof.expect("finite");
        assert!((dof - 625.0 * 11.0 / 81.0).abs() < 1e-9, "{dof}");
        assert!((u.k - coverage_factor(Some(dof))).abs() < 1e-12);
        assert_eq!(u.budget[0].source, "b", "largest first");
        assert!(Uncertainty::combine(Vec::new()).is_none());
    }

    #[test]
    fn a_standard_deviation_of_twelve_blocks_is_known_to_about_22_percent() {
        let (rel, dof) = of_std_dev(12).expect("twelve");
        assert_eq!(dof, 11.0);
        assert!((rel - 0.2132).abs() < 1e-3, "{rel}");
        // Six turn-ons: about 32 %.
        assert!((of_std_dev(6).expect("six").0 - 0.3162).abs() < 1e-3);
        assert!(of_std_dev(1).is_none());
    }

    #[test]
    fn the_expected_range_matches_the_d2_table() {
        // d2 for samples of 2, 5, 10, 25 (ASTM STP 15D).
        for (m, d2) in [(2, 1.128), (5, 2.326), (10, 3.078), (25, 3.931)] {
            assert!((expected_range(m) - d2).abs() < 1e-3, "{m}");
        }
        assert_eq!(expected_range(1), 0.0);
        assert!((rectangular(3f64.sqrt()) - 1.0).abs() < 1e-12);
    }
}
