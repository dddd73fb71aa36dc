//! Acting on a lot's diagnosis: the bench's correction (the shared
//! effects, as a twin's `[effects]` take them) and each unit's twin (its
//! fitted thermal network and its own effects; on this bench, the shared
//! effects that hold for it as well).

use super::{Lot, SharedEffect};
use crate::twin::TwinConfig;
use crate::twin::config::EffectsConfig;
use crate::{Accepted, updated_twin};

impl SharedEffect {
    /// The shared effect as an accepted effect (the form a twin takes).
    fn as_accepted(&self) -> Accepted {
        Accepted {
            name: self.name.clone(),
            parameters: self.parameters.clone(),
            uncertainties: self.uncertainties.clone(),
            held_out_gap_before_dph: self.held_out_gap_before_dph,
            held_out_gap_after_dph: self.held_out_gap_after_dph,
            shrink: self.shrink,
            p_value: self.p_value,
            temperature: self.temperature.clone(),
            fitted: self.fitted.clone(),
        }
    }
}

impl Lot {
    /// Unit `k`'s twin: `base` with the thermal network its own diagnosis
    /// fitted and its own effects; `on_this_bench`: the shared effects
    /// that hold for it as well (the unit as this bench shows it: its
    /// runs diagnosed against it leave nothing to name). `None` when the
    /// lot has no unit `k`.
    pub fn unit_twin(
        &self,
        k: usize,
        base: &TwinConfig,
        on_this_bench: bool,
    ) -> Option<TwinConfig> {
        let (unit, d) = (self.units.get(k)?, self.diagnoses.get(k)?);
        let mut d = d.clone();
        d.effects.clone_from(&unit.effects);
        if on_this_bench {
            d.effects.extend(
                self.shared_effects
                    .iter()
                    .filter(|s| s.units.contains(&unit.serial))
                    .map(SharedEffect::as_accepted),
            );
        }
        Some(updated_twin(base, &d))
    }

    /// The shared effects as a twin's `[effects]` (model-4 terms a lot
    /// shares are left out: they are each unit's compensation).
    pub fn bench_effects(&self) -> EffectsConfig {
        let mut base = TwinConfig::default_rl16();
        base.effects = EffectsConfig::default();
        let Some(first) = self.diagnoses.first() else {
            return base.effects;
        };
        let mut d = first.clone();
        d.layers.thermal.fitted = None;
        d.effects = self
            .shared_effects
            .iter()
            .map(SharedEffect::as_accepted)
            .collect();
        updated_twin(&base, &d).effects
    }
}
