//! Chamber air and the gyro's three-node thermal network.
//!
//! Integration uses a per-node exponential step (each node relaxes towards
//! the equilibrium its neighbours set during the step), which is stable for
//! any step and exact for a single node; the twin steps it every 0.1 s, far
//! below the shortest time constant.

use super::config::{ChamberConfig, ThermalConfig};

/// A chamber command the chamber cannot carry out.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ChamberLimit {
    /// Set point outside the chamber's range.
    #[error("chamber set point {set_c} degC is outside the chamber's range {min_c}..{max_c} degC")]
    SetPoint { set_c: f64, min_c: f64, max_c: f64 },
    /// Ramp faster than the chamber can go (or not a positive number).
    #[error(
        "chamber ramp {ramp_c_per_min} degC/min is beyond its capability (0 < ramp <= {max_c_per_min} degC/min)"
    )]
    Ramp {
        ramp_c_per_min: f64,
        max_c_per_min: f64,
    },
}

/// Chamber air: the controller ramps its working set point towards the
/// target at the commanded rate; the air follows through a first-order lag.
#[derive(Debug, Clone)]
pub struct ChamberAir {
    cfg: ChamberConfig,
    target_c: f64,
    ramp_c_per_s: f64,
    working_sp_c: f64,
    air_c: f64,
}

impl ChamberAir {
    /// Air and set point at the configured initial temperature.
    pub fn new(cfg: &ChamberConfig) -> Self {
        Self {
            cfg: cfg.clone(),
            target_c: cfg.initial_c,
            ramp_c_per_s: cfg.max_ramp_c_per_min / 60.0,
            working_sp_c: cfg.initial_c,
            air_c: cfg.initial_c,
        }
    }

    /// Command a new set point, reached at `ramp_c_per_min`.
    pub fn set_point(&mut self, set_c: f64, ramp_c_per_min: f64) -> Result<(), ChamberLimit> {
        let cfg = &self.cfg;
        if !(set_c.is_finite() && (cfg.min_c..=cfg.max_c).contains(&set_c)) {
            return Err(ChamberLimit::SetPoint {
                set_c,
                min_c: cfg.min_c,
                max_c: cfg.max_c,
            });
        }
        if !(ramp_c_per_min.is_finite()
            && ramp_c_per_min > 0.0
            && ramp_c_per_min <= cfg.max_ramp_c_per_min)
        {
            return Err(ChamberLimit::Ramp {
                ramp_c_per_min,
                max_c_per_min: cfg.max_ramp_c_per_min,
            });
        }
        self.target_c = set_c;
        self.ramp_c_per_s = ramp_c_per_min / 60.0;
        Ok(())
    }

    /// Advance by `dt_s`.
    pub fn step(&mut self, dt_s: f64) {
        let max_step = self.ramp_c_per_s * dt_s;
        let diff = self.target_c - self.working_sp_c;
        self.working_sp_c += diff.clamp(-max_step, max_step);
        relax(
            &mut self.air_c,
            self.working_sp_c,
            dt_s / self.cfg.air_tau_s,
        );
    }

    /// Air temperature, degC.
    pub fn air_c(&self) -> f64 {
        self.air_c
    }

    /// Final set point, degC.
    pub fn target_c(&self) -> f64 {
        self.target_c
    }

    /// The controller's ramped set point, degC.
    pub fn working_set_point_c(&self) -> f64 {
        self.working_sp_c
    }
}

/// Case (housing) node and two block nodes carrying sensors T1 and T2,
/// with an optional mount node between the air and the case and an
/// optional heat sink on the case.
#[derive(Debug, Clone)]
pub struct ThermalNetwork {
    cfg: ThermalConfig,
    /// Mount node, degC (follows the air when the network has none).
    pub mount_c: f64,
    /// Case temperature T_K, degC.
    pub case_c: f64,
    /// Block node 1 temperature (sensor T1), degC.
    pub t1_c: f64,
    /// Block node 2 temperature (sensor T2), degC.
    pub t2_c: f64,
    /// Heat-sink node (follows the case when the network has none), degC.
    pub sink_c: f64,
    /// d(T1 - T2)/dt over the last step, degC/s.
    pub ddt_dt_c_per_s: f64,
}

impl ThermalNetwork {
    /// All nodes soaked at `temp_c`.
    pub fn soaked(cfg: &ThermalConfig, temp_c: f64) -> Self {
        let temp_c = cfg.air_gain * temp_c;
        Self {
            cfg: cfg.clone(),
            mount_c: temp_c,
            case_c: temp_c,
            t1_c: temp_c,
            t2_c: temp_c,
            sink_c: temp_c,
            ddt_dt_c_per_s: 0.0,
        }
    }

    /// Advance by `dt_s` with the air at `air_c`; `powered` turns the
    /// self-heating on; `convection` (>= 1) speeds up the block exchange.
    pub fn step(&mut self, dt_s: f64, air_c: f64, powered: bool, convection: f64) {
        let c = &self.cfg;
        let on = if powered { 1.0 } else { 0.0 };
        let dt_before = self.t1_c - self.t2_c;
        let air_c = c.air_gain * air_c;
        if c.mount_tau_s > 0.0 {
            relax(&mut self.mount_c, air_c, dt_s / c.mount_tau_s);
        } else {
            self.mount_c = air_c;
        }
        let [r1, r2] = c.block_capacity_ratio;
        let bs = if c.sink_tau_s > 0.0 {
            c.sink_capacity_ratio / c.sink_tau_s
        } else {
            0.0
        };
        if r1 > 0.0 || r2 > 0.0 || bs > 0.0 {
            // The blocks' and the sink's heat flows back into the case in
            // proportion to their capacities.
            let kk = 1.0 / c.case_tau_s;
            let (b1, b2) = (r1 / c.block1_tau_s, r2 / c.block2_tau_s);
            let eq = (kk * (self.mount_c + c.case_rise_c * on)
                + b1 * self.t1_c
                + b2 * self.t2_c
                + bs * self.sink_c)
                / (kk + b1 + b2 + bs);
            relax(&mut self.case_c, eq, dt_s * (kk + b1 + b2 + bs));
        } else {
            relax(
                &mut self.case_c,
                self.mount_c + c.case_rise_c * on,
                dt_s / c.case_tau_s,
            );
        }

        if c.sink_tau_s > 0.0 {
            relax(&mut self.sink_c, self.case_c, dt_s / c.sink_tau_s);
        } else {
            self.sink_c = self.case_c;
        }

        let k1 = 1.0 / c.block1_tau_s;
        let k2 = 1.0 / c.block2_tau_s;
        let kc = convection / c.coupling_tau_s;
        // One conductance between the blocks, seen from both ends.
        let kc2 = kc * c.block_capacity_1_over_2;
        let (t1, t2) = (self.t1_c, self.t2_c);
        let eq1 = (k1 * (self.case_c + c.block1_rise_c * on) + kc * t2) / (k1 + kc);
        let eq2 = (k2 * (self.case_c + c.block2_rise_c * on) + kc2 * t1) / (k2 + kc2);
        relax(&mut self.t1_c, eq1, dt_s * (k1 + kc));
        relax(&mut self.t2_c, eq2, dt_s * (k2 + kc2));
        self.ddt_dt_c_per_s = ((self.t1_c - self.t2_c) - dt_before) / dt_s;
    }

    /// Mean of the two block nodes, degC.
    pub fn block_c(&self) -> f64 {
        0.5 * (self.t1_c + self.t2_c)
    }

    /// Block gradient dT = T1 - T2, degC.
    pub fn gradient_c(&self) -> f64 {
        self.t1_c - self.t2_c
    }

    /// Steady state (case, T1, T2) for air at `air_c`, powered, with
    /// `convection`: the closed form the integrator must settle to.
    pub fn steady_state(cfg: &ThermalConfig, air_c: f64, convection: f64) -> (f64, f64, f64) {
        let kk = 1.0 / cfg.case_tau_s;
        let (k1, k2) = (1.0 / cfg.block1_tau_s, 1.0 / cfg.block2_tau_s);
        let (b1, b2) = (
            cfg.block_capacity_ratio[0] * k1,
            cfg.block_capacity_ratio[1] * k2,
        );
        let kc = convection / cfg.coupling_tau_s;
        let kc2 = kc * cfg.block_capacity_1_over_2;
        // Heat balance of the case, block 1 and block 2 (the mount node
        // settles at the air it sees, the sink at the case).
        let a = nalgebra::Matrix3::new(
            kk + b1 + b2,
            -b1,
            -b2,
            -k1,
            k1 + kc,
            -kc,
            -k2,
            -kc2,
            k2 + kc2,
        );
        let rhs = nalgebra::Vector3::new(
            kk * (cfg.air_gain * air_c + cfg.case_rise_c),
            k1 * cfg.block1_rise_c,
            k2 * cfg.block2_rise_c,
        );
        let x = a.lu().solve(&rhs).unwrap_or(rhs);
        (x[0], x[1], x[2])
    }
}

/// One exponential relaxation step of `x` towards `target` over `dt/tau`.
fn relax(x: &mut f64, target: f64, dt_over_tau: f64) {
    *x += (target - *x) * (-(-dt_over_tau).exp_m1());
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::twin::TwinConfig;

    #[test]
    fn chamber_refuses_set_points_and_ramps_beyond_capability() {
        let cfg = TwinConfig::default_rl16().chamber;
        let mut ch = ChamberAir::new(&cfg);
        assert!(matches!(
            ch.set_point(cfg.max_c + 1.0, 1.0),
            Err(ChamberLimit::SetPoint { .. })
        ));
        assert!(matches!(
            ch.set_point(0.0, cfg.max_ramp_c_per_min * 1.01),
            Err(ChamberLimit::Ramp { .. })
        ));
        assert!(matches!(
            ch.set_point(0.0, 0.0),
            Err(ChamberLimit::Ramp { .. })
        ));
    }

    #[test]
    fn chamber_ramps_at_the_commanded_rate_then_settles_with_its_lag() {
        let cfg = TwinConfig::default_rl16().chamber;
        let mut ch = ChamberAir::new(&cfg);
        ch.set_point(cfg.initial_c - 60.0, 1.0)
            .expect("within limits");
        let dt = 0.1;
        for _ in 0..(1800.0 / dt) as usize {
            ch.step(dt);
        }
        // After 30 min at 1 degC/min the working set point moved 30 degC ...
        assert!((ch.working_set_point_c() - (cfg.initial_c - 30.0)).abs() < 1e-6);
        // ... and the air trails it by ramp * tau (steady tracking error).
        let lag = ch.air_c() - ch.working_set_point_c();
        assert!((lag - cfg.air_tau_s / 60.0).abs() < 0.01, "lag {lag}");
        for _ in 0..(7200.0 / dt) as usize {
            ch.step(dt);
        }
        assert!((ch.air_c() - (cfg.initial_c - 60.0)).abs() < 1e-3);
    }

    #[test]
    fn case_node_has_its_configured_time_constant() {
        let mut cfg = TwinConfig::default_rl16().thermal;
        cfg.case_rise_c = 0.0;
        let mut net = ThermalNetwork::soaked(&cfg, 20.0);
        let dt = 0.1;
        let n = (cfg.case_tau_s / dt).round() as usize;
        for _ in 0..n {
            net.step(dt, 30.0, false, 1.0);
        }
        // 1 - 1/e of a 10 degC step after one time constant.
        let frac = (net.case_c - 20.0) / 10.0;
        assert!((frac - (1.0 - (-1.0f64).exp())).abs() < 1e-6, "{frac}");
    }

    #[test]
    fn powered_network_settles_to_the_closed_form_steady_state() {
        let mut other = TwinConfig::default_rl16().thermal;
        other.mount_tau_s = 400.0;
        other.air_gain = 1.03;
        other.block_capacity_ratio = [0.3, 0.15];
        other.sink_tau_s = 600.0;
        other.sink_capacity_ratio = 0.8;
        other.block_capacity_1_over_2 = 2.5;
        for (cfg, convection) in [
            (TwinConfig::default_rl16().thermal, 1.0),
            (TwinConfig::default_rl16().thermal, 1.5),
            (other, 1.2),
        ] {
            let mut net = ThermalNetwork::soaked(&cfg, -40.0);
            for _ in 0..(100_000.0 / 0.1) as usize {
                net.step(0.1, -40.0, true, convection);
            }
            let (case, t1, t2) = ThermalNetwork::steady_state(&cfg, -40.0, convection);
            assert!((net.case_c - case).abs() < 1e-6, "{} vs {case}", net.case_c);
            assert!((net.t1_c - t1).abs() < 1e-4, "{} vs {t1}", net.t1_c);
            assert!((net.t2_c - t2).abs() < 1e-4, "{} vs {t2}", net.t2_c);
            assert!(net.ddt_dt_c_per_s.abs() < 1e-7);
        }
        let cfg = TwinConfig::default_rl16().thermal;
        // Self-heating warms side 1 more than side 2: a positive gradient.
        let (_, t1, t2) = ThermalNetwork::steady_state(&cfg, 20.0, 1.0);
        assert!(t1 - t2 > 0.1);
        // More convection shrinks the gradient.
        let (_, t1c, t2c) = ThermalNetwork::steady_state(&cfg, 20.0, 2.0);
        assert!(t1c - t2c < t1 - t2);
    }
}
