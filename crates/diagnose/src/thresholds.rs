//! The decision thresholds of the diagnosis's selection in one place, each
//! with where its value comes from. "Ours" marks a choice of this project,
//! measured on the self-check (`docs/diagnosis.md`); the rest are
//! conventions of the statistics they belong to. `diagnosis.json` carries
//! the set it was made with (`thresholds`), so a reviewer reads the bars
//! beside the figures. (Search limits and the bias-jump search's spacing,
//! `MAX_PASSES` and the `STEP_*` constants in `diagnose`, are not bars and
//! stay beside their code.)

use serde::Serialize;

/// The bars selection, confounding, the inconclusive step and the outside
/// disturbances are judged by.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Thresholds {
    /// Family-wise significance level of the selection: each step tests
    /// every remaining candidate at `alpha` / their number (Bonferroni; the
    /// conventional 0.05).
    pub alpha: f64,
    /// Smallest held-out improvement an effect must bring, as a fraction
    /// of the held-out sum of squares (ours: an effect at 1.5x the noise
    /// removes about 70 %; on the tuning seeds 101..140 of the self-check,
    /// the best candidate removed at most 6 % in null runs and up to 18 %
    /// in runs with the periodic disturbance outside the library, so 25 %
    /// keeps them out; checked on fresh seeds).
    pub min_gain: f64,
    /// Candidates whose held-out gains lie within this fraction of the best
    /// are tied (ours: measured by the self-check, where a case-temperature
    /// term, a short thermal lag and, axis up, a scale-factor drift come
    /// within 1-2 % of each other).
    pub tie: f64,
    /// A swap explains as much as the accepted effect when it leaves no
    /// more than this fraction of what the effect removed (held-out sum of
    /// squares) unexplained (ours: a fifth; two sets that are one at these
    /// positions differ by their parameter count and the noise).
    pub swap_within: f64,
    /// Smallest held-out improvement, as a fraction of the held-out sum of
    /// squares, for a candidate that misses the bar to be reported as
    /// inconclusive rather than nothing (ours: the null runs' best
    /// candidate removes up to 6 %).
    pub inconclusive_gain: f64,
    /// Largest p-value of a candidate reported as inconclusive (ours: one
    /// whose improvement is as likely as not noise is not worth a run).
    pub inconclusive_p: f64,
    /// A candidate that passed alone is a rival of the one named (checked
    /// for a confound) when its held-out gain is over this share of the
    /// named one's (ours).
    pub rival_share: f64,
    /// Power the deciding run is sized for (the conventional 80 %).
    pub deciding_power: f64,
    /// The repeated run's share of the gap the candidate removes, taken
    /// this much smaller for its scatter when the deciding run is sized
    /// (ours).
    pub share_margin: f64,
    /// Share of the total above which a periodic fit is reported (ours).
    pub periodic_above: f64,
    /// A candidate that adds less than this to the degrees of freedom spent
    /// on the record means does not live between records: no
    /// between-record test (ours).
    pub min_between_dof: f64,
    /// At most this many effects are named (ours).
    pub max_effects: usize,
    /// Most disturbances outside the library held as nuisances (ours).
    pub max_outside: usize,
    /// Candidates a joint step pairs: the best by held-out gain alone
    /// (ours).
    pub joint_from: usize,
}

/// The thresholds every diagnosis is made with.
pub const THRESHOLDS: Thresholds = Thresholds {
    alpha: 0.05,
    min_gain: 0.25,
    tie: 0.03,
    swap_within: 0.2,
    inconclusive_gain: 0.10,
    inconclusive_p: 0.5,
    rival_share: 0.5,
    deciding_power: 0.8,
    share_margin: 0.8,
    periodic_above: 0.3,
    min_between_dof: 0.05,
    max_effects: 3,
    max_outside: 2,
    joint_from: 3,
};

#[cfg(test)]
mod tests {
    use super::*;

    /// The bars fit together: fractions are fractions, a candidate
    /// reported inconclusive is one that missed the naming bar, and the
    /// selection has room for the joint step's pair.
    #[test]
    fn the_bars_are_consistent_with_each_other() {
        let t = THRESHOLDS;
        for (name, v) in [
            ("alpha", t.alpha),
            ("min_gain", t.min_gain),
            ("tie", t.tie),
            ("swap_within", t.swap_within),
            ("inconclusive_gain", t.inconclusive_gain),
            ("inconclusive_p", t.inconclusive_p),
            ("rival_share", t.rival_share),
            ("deciding_power", t.deciding_power),
            ("periodic_above", t.periodic_above),
            ("min_between_dof", t.min_between_dof),
        ] {
            assert!(v > 0.0 && v < 1.0, "{name} = {v}");
        }
        assert!(t.share_margin > 0.0 && t.share_margin <= 1.0);
        // Inconclusive: a gain below the bar, a p-value above it.
        assert!(t.inconclusive_gain < t.min_gain);
        assert!(t.inconclusive_p > t.alpha);
        // Tied candidates both pass the bar when the best clears it well.
        assert!(t.tie < t.min_gain);
        // A joint step names two effects and pairs at least two.
        assert!(t.max_effects >= 2 && t.joint_from >= 2);
        assert!(t.max_outside >= 1);
        // A run offset spends one degree of freedom on the record means:
        // the bar for a between-record test lies far below it.
        assert!(t.min_between_dof < 0.5);
    }

    /// The values docs/diagnosis.md gives for the bars are the ones the
    /// selection uses.
    #[test]
    fn the_documentation_gives_the_bars_in_use() {
        let doc: String = include_str!("../../../docs/diagnosis.md")
            .split_whitespace()
            .collect::<Vec<_>>()
            .join(" ");
        let t = THRESHOLDS;
        let count = ["one", "two", "three", "four", "five"];
        for phrase in [
            format!(
                "at least {:.0} % of the held-out sum of squares (`min_gain`",
                100.0 * t.min_gain
            ),
            format!(
                "within {:.0} % of the best improvement (`tie`)",
                100.0 * t.tie
            ),
            format!("below {} / (candidates left)", t.alpha),
            format!(
                "less than {} there gets no between-record test",
                t.min_between_dof
            ),
            format!("at most {} effects", count[t.max_effects - 1]),
            format!("at most {})", count[t.max_outside - 1]),
        ] {
            assert!(doc.contains(&phrase), "docs/diagnosis.md lacks {phrase:?}");
        }
        assert_eq!(t.swap_within, 0.2, "the documentation says a fifth");
    }
}
