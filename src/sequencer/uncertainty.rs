//! Each judged figure's uncertainty budget (`docs/figures.md` gives each
//! one): the Type A part from the run's own data (the spread of block
//! means, the Allan deviation at the figure's averaging time with its
//! equivalent degrees of freedom, the fit's covariance, the turn-ons), and
//! the Type B part from what the bench file declares (`typeb`), each
//! contribution turned into the figure's unit by its sensitivity.
//! Combined and expanded as the GUM says (`analysis::uncertainty`).

use crate::analysis::allan::{edf_oadev, noise_alpha, oadev};
use crate::analysis::figures::{block_means, mean, moving_average, std_dev};
use crate::analysis::series::Interval;
use crate::analysis::uncertainty::{Contribution, Uncertainty, expected_range, of_std_dev};
use crate::geometry::EARTH_RATE_DPH;
use crate::procedure::Metric;
use crate::typeb::{Source, TypeB};

/// Arcseconds per radian.
const ARCSEC_PER_RAD: f64 = 206_264.806;

/// What a figure's computation knows that its budget needs.
#[derive(Debug, Clone, Default)]
pub struct Known {
    /// Type A lines the computation formed itself (a fit's standard
    /// error, the scatter of turn-ons).
    pub type_a: Vec<Contribution>,
    /// The series the figure's noise is read from (a compensated drift's
    /// residual), when not the Earth-removed rate itself.
    pub noise_series: Option<Vec<f64>>,
    /// Mean supply voltage and current over the figure's readings, V, A.
    pub supply: Option<(f64, f64)>,
    /// The fewest whole table revolutions a record of the figure was
    /// taken over, when every record was taken in the angle domain (none:
    /// some were taken over time, or the figure is not a rate figure).
    pub revolutions: Option<u32>,
}

/// The standard deviation of `tau`-sample means of `x` as its overlapping
/// Allan deviation there (the two agree for white rate noise and stay
/// close for flicker over a few octaves; `docs/figures.md`), with its
/// equivalent degrees of freedom (Greenhall); none when `x` is too short.
pub fn noise_of_means(x: &[f64], tau: usize) -> Option<(f64, f64)> {
    let tau = tau.max(1);
    if x.len() < 3 * tau {
        return None;
    }
    // A slow trend (a thermal drift, a warm-up) is not noise: what a
    // moving mean three averaging times long follows is taken out first.
    let trend = moving_average(x, 3 * tau);
    let lead = (x.len() - trend.len()) / 2;
    let hp: Vec<f64> = trend
        .iter()
        .enumerate()
        .map(|(i, t)| x[i + lead] - t)
        .collect();
    let (_, adev) = *oadev(&hp, 1.0, &[tau]).first()?;
    let alpha = noise_alpha(&hp, tau).unwrap_or(0);
    let edf = edf_oadev(alpha, tau, hp.len() + 1);
    (adev.is_finite() && edf.is_finite()).then_some((adev, edf.max(1.0)))
}

/// The noise floor of a peak-to-peak of `window`-sample moving means over
/// `n` samples whose `window` means scatter by `sigma_w`: the expected
/// range of `n / window` independent such means (`expected_range`, the d2
/// of range charts). What a perfectly compensated unit's peak-to-peak
/// reads from its noise alone.
pub fn noise_floor(sigma_w: f64, n: usize, window: usize) -> f64 {
    sigma_w * expected_range(n / window.max(1))
}

/// A declared Type B contribution `s` at sensitivity `c` (the figure's
/// change per unit of the declared quantity).
fn declared(b: &TypeB, s: Source, c: f64, out: &mut Vec<Contribution>, missing: &mut Vec<&str>) {
    match b.get(s) {
        Some(d) => out.push(Contribution::type_b(s.words(), c * d.standard(), d.basis())),
        None => missing.push(s.key()),
    }
}

/// The declared Type B sources that reach `metric`, with their
/// sensitivities, for a figure of `value` over `series`.
fn type_b(
    metric: Metric,
    value: f64,
    series: &[Interval],
    known: &Known,
    b: &TypeB,
) -> (Vec<Contribution>, Vec<&'static str>) {
    let mut out = Vec::new();
    let mut missing = Vec::new();
    let per_ppm = |v: f64| v.abs() * 1e-6;
    match metric {
        Metric::ScaleFactor => match known.revolutions {
            // Counts per angle: the table's encoder latched at both ends
            // of the shortest span (each end's error, over its turns) is
            // the input; neither clock is in it beyond the Earth and bias
            // terms' share, parts in 1e7 (`docs/figures.md`).
            Some(turns) => {
                let per_arcsec =
                    std::f64::consts::SQRT_2 / (f64::from(turns.max(1)) * 360.0 * 3600.0) * 1e6;
                declared(b, Source::TableAngle, per_arcsec, &mut out, &mut missing);
            }
            // Over time: the table's rate is the input the scale factor
            // is against; the unit's clock turns counts into a rate (1 ppm
            // per ppm).
            None => {
                declared(b, Source::TableRate, 1.0, &mut out, &mut missing);
                declared(b, Source::UnitClock, 1.0, &mut out, &mut missing);
            }
        },
        Metric::AxisMisalignment | Metric::DeadBand | Metric::Threshold => {
            declared(b, Source::TableRate, per_ppm(value), &mut out, &mut missing);
            declared(b, Source::UnitClock, per_ppm(value), &mut out, &mut missing);
        }
        Metric::ScaleFactorNonlinearity | Metric::ScaleFactorAsymmetry => {}
        Metric::ScaleFactorTemperature
        | Metric::TemperatureSensitivity
        | Metric::TemperatureRateSensitivity => {
            // A slope over the temperature span: each end's sensor error.
            let temps: Vec<f64> = series
                .iter()
                .map(|i| match metric {
                    Metric::ScaleFactorTemperature => 0.5 * (i.t1_c + i.t2_c),
                    _ => i.tcase_c,
                })
                .collect();
            let span = temps.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - temps.iter().copied().fold(f64::INFINITY, f64::min);
            if span > 0.0 {
                declared(
                    b,
                    Source::SensorTemperature,
                    std::f64::consts::SQRT_2 * value.abs() / span,
                    &mut out,
                    &mut missing,
                );
            }
        }
        Metric::MeanBias => {
            // The Earth rate taken out depends on where the axis points:
            // a rotation by the north, level or latitude error moves it by
            // up to W sqrt(1 - (r/W)^2) per radian (r the rate it reads).
            let r = mean(&series.iter().map(|i| i.reference_dph).collect::<Vec<_>>());
            if r.abs() <= EARTH_RATE_DPH * 1.001 {
                let c = EARTH_RATE_DPH * (1.0 - (r / EARTH_RATE_DPH).powi(2)).max(0.0).sqrt();
                declared(
                    b,
                    Source::NorthAlignment,
                    c / ARCSEC_PER_RAD,
                    &mut out,
                    &mut missing,
                );
                declared(b, Source::Level, c / ARCSEC_PER_RAD, &mut out, &mut missing);
                declared(b, Source::Latitude, c.to_radians(), &mut out, &mut missing);
            }
            let rate = mean(&series.iter().map(|i| i.rate_dph).collect::<Vec<_>>());
            declared(b, Source::UnitClock, per_ppm(rate), &mut out, &mut missing);
        }
        Metric::BiasStability
        | Metric::DriftPp
        | Metric::CompensatedDriftPp
        | Metric::CompensatedDriftFitResidualPp
        | Metric::SelfHeating
        | Metric::BiasRepeatability => {
            declared(b, Source::UnitClock, per_ppm(value), &mut out, &mut missing);
        }
        Metric::GSensitivity | Metric::BiasSpread => {
            // Each position's Earth rate taken out moves with the table's
            // north and level errors, up to W per radian: two positions'
            // differ by up to sqrt(2) of it (over the 1 g between axis up
            // and horizontal, for the slope).
            let c = std::f64::consts::SQRT_2 * EARTH_RATE_DPH;
            declared(
                b,
                Source::NorthAlignment,
                c / ARCSEC_PER_RAD,
                &mut out,
                &mut missing,
            );
            declared(b, Source::Level, c / ARCSEC_PER_RAD, &mut out, &mut missing);
        }
        Metric::Arw | Metric::BiasInstability | Metric::RateRandomWalk => {
            declared(b, Source::UnitClock, per_ppm(value), &mut out, &mut missing);
        }
        Metric::WarmUpTime => {
            declared(
                b,
                Source::BenchClock,
                per_ppm(value),
                &mut out,
                &mut missing,
            );
        }
        Metric::PowerSteady | Metric::PowerPeak => {
            if let Some((v, a)) = known.supply {
                declared(b, Source::SupplyVolts, a, &mut out, &mut missing);
                declared(b, Source::SupplyAmps, v, &mut out, &mut missing);
            }
        }
    }
    (out, missing)
}

/// The Type A lines `metric` forms from the series itself (those its
/// computation did not form in `known`), or why it cannot.
fn type_a(
    metric: Metric,
    value: f64,
    series: &[Interval],
    averaging_s: f64,
    known: &Known,
) -> Result<Vec<Contribution>, NoUncertainty> {
    let bias: Vec<f64> = series.iter().map(Interval::bias_dph).collect();
    // Seconds as intervals: 1 s each at a 1 Hz tick, longer where the
    // host polls slower; the words say seconds.
    let cadence = crate::analysis::study::cadence_s(series);
    let window = crate::analysis::study::intervals_for(averaging_s, cadence);
    let secs = |n: usize| (n as f64 * cadence).round();
    match metric {
        Metric::BiasStability => {
            let n = bias.len() / window;
            let (rel, dof) = of_std_dev(n).ok_or(NoUncertainty::TooFewBlocks {
                blocks: n,
                block_s: secs(window),
            })?;
            Ok(vec![Contribution::type_a(
                "noise: the spread of the block means",
                value * rel,
                dof,
                format!(
                    "{n} blocks of {} s: s / sqrt(2 (n - 1)) (GUM E.4.3)",
                    secs(window)
                ),
            )])
        }
        Metric::MeanBias => {
            let block = window.max(crate::analysis::study::intervals_for(100.0, cadence));
            let blocks = block_means(&bias, block);
            let n = blocks.len();
            if n < 2 {
                return Err(NoUncertainty::TooShort {
                    recorded_s: secs(bias.len()),
                    block_s: secs(block),
                });
            }
            Ok(vec![Contribution::type_a(
                "noise: the scatter of the block means",
                std_dev(&blocks) / (n as f64).sqrt(),
                (n - 1) as f64,
                format!("{n} blocks of {} s: s / sqrt(n)", secs(block)),
            )])
        }
        Metric::DriftPp
        | Metric::CompensatedDriftPp
        | Metric::CompensatedDriftFitResidualPp
        | Metric::SelfHeating => {
            let x = known.noise_series.as_deref().unwrap_or(&bias);
            let tau = match metric {
                Metric::SelfHeating => crate::analysis::study::intervals_for(
                    crate::analysis::study::SELF_HEATING_WINDOW_S,
                    cadence,
                ),
                _ => window,
            };
            let (sigma, edf) = noise_of_means(x, tau).ok_or(NoUncertainty::TooShortForNoise {
                data_s: secs(x.len()),
                mean_s: secs(tau),
            })?;
            Ok(vec![Contribution::type_a(
                "noise of the means at either end",
                std::f64::consts::SQRT_2 * sigma,
                edf,
                format!(
                    "Allan deviation at {} s ({sigma:.5}), two means: sqrt(2) x it; Greenhall EDF",
                    secs(tau)
                ),
            )])
        }
        Metric::PowerSteady
        | Metric::PowerPeak
        | Metric::WarmUpTime
        | Metric::ScaleFactor
        | Metric::ScaleFactorNonlinearity
        | Metric::ScaleFactorAsymmetry
        | Metric::ScaleFactorTemperature
        | Metric::DeadBand
        | Metric::Threshold
        | Metric::AxisMisalignment
        | Metric::BiasRepeatability
        | Metric::TemperatureSensitivity
        | Metric::TemperatureRateSensitivity
        | Metric::GSensitivity
        | Metric::BiasSpread
        | Metric::Arw
        | Metric::BiasInstability
        | Metric::RateRandomWalk => Ok(known.type_a.clone()),
    }
}

/// Why a figure's uncertainty cannot be formed (the report says it
/// beside the figure).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NoUncertainty {
    /// The figure has no value.
    #[error("the figure has no value")]
    NoValue,
    /// Too few blocks for a spread.
    #[error("{blocks} blocks of {block_s} s: a spread needs two or more")]
    TooFewBlocks {
        /// Blocks recorded.
        blocks: usize,
        /// A block's length, s.
        block_s: f64,
    },
    /// Too short a record for the mean's noise.
    #[error("{recorded_s} s recorded: the mean's noise needs two blocks of {block_s} s or more")]
    TooShort {
        /// The record's length, s.
        recorded_s: f64,
        /// A block's length, s.
        block_s: f64,
    },
    /// Too little data for the noise of the means.
    #[error("{data_s} s of data: the noise of {mean_s} s means needs three times that")]
    TooShortForNoise {
        /// The data's length, s.
        data_s: f64,
        /// The means' length, s.
        mean_s: f64,
    },
    /// No statistic of the data bounds the figure.
    #[error("no statistic of its data bounds it")]
    NoStatistic,
    /// The budget's contributions do not combine (not finite).
    #[error("its budget does not combine")]
    DoesNotCombine,
}

/// The uncertainty of `metric`'s `value` over `series` (its records),
/// with the bench's declared contributions `b`; or why it cannot be
/// formed. A declared source the figure needs but the bench does not
/// declare is named in the budget as not declared.
pub fn of(
    metric: Metric,
    value: f64,
    series: &[Interval],
    averaging_s: f64,
    known: &Known,
    b: &TypeB,
) -> Result<Uncertainty, NoUncertainty> {
    let mut budget = type_a(metric, value, series, averaging_s, known)?;
    if budget.is_empty() && !matches!(metric, Metric::PowerPeak) {
        return Err(NoUncertainty::NoStatistic);
    }
    let (declared, missing) = type_b(metric, value, series, known, b);
    budget.extend(declared);
    for key in missing {
        budget.push(Contribution::type_b(
            &format!("{key} (not declared)"),
            0.0,
            format!("the bench file's [uncertainty] does not declare {key}: counted as 0"),
        ));
    }
    Uncertainty::combine(budget).ok_or(NoUncertainty::DoesNotCombine)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn white(n: usize, sigma: f64, seed: u64) -> Vec<f64> {
        use rand::SeedableRng;
        use rand_distr::{Distribution, Normal};
        let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(seed);
        let d = Normal::new(0.0, sigma).expect("normal");
        (0..n).map(|_| d.sample(&mut rng)).collect()
    }

    #[test]
    fn the_noise_of_means_is_the_spread_of_the_means_for_white_noise() {
        let x = white(36_000, 0.12, 1);
        let (sigma, edf) = noise_of_means(&x, 600).expect("long enough");
        // 0.12 / sqrt(600) = 0.0049.
        assert!(
            (sigma / (0.12 / 600f64.sqrt()) - 1.0).abs() < 0.2,
            "{sigma}"
        );
        assert!(edf > 20.0, "{edf}");
        assert!(noise_of_means(&x[..1000], 600).is_none());
    }

    #[test]
    fn the_noise_floor_of_a_drift_is_the_range_of_its_independent_means() {
        // Ten hours of 600 s means of 0.005 deg/h scatter: 60 means,
        // expected range 4.64 of them.
        let floor = noise_floor(0.005, 36_000, 600);
        assert!((floor - 0.005 * 4.639).abs() < 1e-4, "{floor}");
    }

    fn steady(n: usize, rate: f64, reference: f64) -> Vec<Interval> {
        white(n, 0.12, 3)
            .into_iter()
            .enumerate()
            .map(|(i, w)| Interval {
                time_s: i as f64,
                rate_dph: rate + w,
                reference_dph: reference,
                tcase_c: 20.0 + i as f64 * 1e-3,
                ..Interval::default()
            })
            .collect()
    }

    #[test]
    fn a_bias_stability_of_twelve_blocks_is_known_to_22_percent_plus_the_clock() {
        let s = steady(1200, 10.0, 10.0);
        let b = TypeB::default();
        let u = of(
            Metric::BiasStability,
            0.01,
            &s,
            100.0,
            &Known::default(),
            &b,
        )
        .expect("formed");
        assert!((u.u - 0.01 * 0.2132).abs() < 1e-4, "{}", u.u);
        assert_eq!(u.dof, Some(11.0));
        assert!(
            u.budget
                .iter()
                .any(|c| c.source.contains("unit_clock_ppm (not declared)"))
        );
        let too_short = of(
            Metric::BiasStability,
            0.01,
            &s[..150],
            100.0,
            &Known::default(),
            &b,
        );
        assert!(too_short.is_err_and(|e| e.to_string().contains("1 blocks of 100 s")));
    }

    #[test]
    fn a_mean_bias_takes_the_alignment_where_the_axis_feels_it() {
        let text = "[uncertainty]\nnorth_alignment_arcsec = { u = 30.0, source = \"r\" }\n\
                    level_arcsec = { u = 0.0, source = \"r\" }\nlatitude_deg = { u = 0.0, source = \"r\" }\n\
                    unit_clock_ppm = { u = 0.0, source = \"r\" }\n";
        #[derive(serde::Deserialize)]
        struct W {
            uncertainty: TypeB,
        }
        let w: W = toml::from_str(text).expect("toml");
        let north = |r: f64| {
            let s = steady(1200, r, r);
            let u = of(
                Metric::MeanBias,
                0.0,
                &s,
                100.0,
                &Known::default(),
                &w.uncertainty,
            )
            .expect("formed");
            u.budget
                .iter()
                .find(|c| c.source == "north alignment of the table")
                .map_or(0.0, |c| c.u)
        };
        // Axis along the Earth's axis: no first-order change; across it,
        // W x 30 arcsec = 0.0022 deg/h.
        assert!(north(EARTH_RATE_DPH) < 1e-9);
        assert!((north(0.0) - EARTH_RATE_DPH * 30.0 / ARCSEC_PER_RAD).abs() < 1e-9);
    }
}
