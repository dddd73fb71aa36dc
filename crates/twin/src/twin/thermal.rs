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
    /// The temperature of each sensor itself (T1, T2, TK): the node it
    /// sits on, through the sensor's own lag when it has one, degC.
    pub sensor_c: [f64; 3],
    /// d(T1 - T2)/dt over the last step, degC/s.
    pub ddt_dt_c_per_s: f64,
}

/// What the orientation changes in the network: the exchange between the
/// blocks (convection along the sensors' line, >= 1) and each block's
/// conductance to the case (`[thermal.effects]`, 1 without the effect).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exchange {
    /// Factor on the blocks' exchange.
    pub convection: f64,
    /// Factor on block 1's and block 2's conductance to the case.
    pub block_conductance: [f64; 2],
}

impl Exchange {
    /// The exchange of a network `cfg` with gravity at `gravity_body_g`
    /// (g, body frame).
    pub fn at(cfg: &ThermalConfig, gravity_body_g: &nalgebra::Vector3<f64>) -> Self {
        let s = nalgebra::Vector3::from(cfg.sensor_axis_body).normalize();
        Self {
            convection: 1.0 + cfg.convection_gain * gravity_body_g.dot(&s).abs(),
            block_conductance: cfg.effects.block_conductance(gravity_body_g),
        }
    }

    /// Convection alone, the blocks' conductances as configured.
    pub fn convection(convection: f64) -> Self {
        Self {
            convection,
            block_conductance: [1.0; 2],
        }
    }
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
            sensor_c: [temp_c; 3],
            ddt_dt_c_per_s: 0.0,
        }
    }

    /// What the sensors read, without their noise and resolution: each
    /// sensor's own temperature through its gain error, plus its offset
    /// (T1, T2, TK), degC.
    pub fn readings_c(&self) -> [f64; 3] {
        let c = &self.cfg;
        std::array::from_fn(|k| {
            (1.0 + c.effects.sensor_gain_error[k]) * self.sensor_c[k] + c.sensor_offset_c[k]
        })
    }

    /// Advance by `dt_s` with the air at `air_c`; `powered` turns the
    /// self-heating on; `convection` (>= 1) speeds up the block exchange.
    pub fn step(&mut self, dt_s: f64, air_c: f64, powered: bool, convection: f64) {
        self.step_in(dt_s, air_c, powered, &Exchange::convection(convection));
    }

    /// Advance by `dt_s` with the air at `air_c` (the chamber's); `powered`
    /// turns the self-heating on; `exchange` holds what the orientation
    /// changes.
    pub fn step_in(&mut self, dt_s: f64, air_c: f64, powered: bool, exchange: &Exchange) {
        let c = &self.cfg;
        let on = if powered { 1.0 } else { 0.0 };
        let dt_before = self.t1_c - self.t2_c;
        let chamber_c = air_c;
        let air_c = c.air_gain * air_c;
        if c.mount_tau_s > 0.0 {
            relax(&mut self.mount_c, air_c, dt_s / c.mount_tau_s);
        } else {
            self.mount_c = air_c;
        }
        let fx = &c.effects;
        let [f1, f2] = exchange.block_conductance;
        let sc = fx.case_conductance(chamber_c);
        let [r1, r2] = c.block_capacity_ratio;
        let bs = if c.sink_tau_s > 0.0 {
            c.sink_capacity_ratio / c.sink_tau_s
        } else {
            0.0
        };
        if r1 > 0.0 || r2 > 0.0 || bs > 0.0 || sc != 1.0 {
            // The blocks' and the sink's heat flows back into the case in
            // proportion to their capacities; the self-heating is a heat
            // input, the same whatever the case's conductance.
            let kk = 1.0 / c.case_tau_s;
            let (b1, b2) = (f1 * r1 / c.block1_tau_s, f2 * r2 / c.block2_tau_s);
            let ka = sc * kk;
            let drive = if sc == 1.0 {
                kk * (self.mount_c + c.case_rise_c * on)
            } else {
                ka * self.mount_c + kk * c.case_rise_c * on
            };
            let eq =
                (drive + b1 * self.t1_c + b2 * self.t2_c + bs * self.sink_c) / (ka + b1 + b2 + bs);
            relax(&mut self.case_c, eq, dt_s * (ka + b1 + b2 + bs));
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
        let kc = exchange.convection / c.coupling_tau_s;
        // One conductance between the blocks, seen from both ends.
        let kc2 = kc * c.block_capacity_1_over_2;
        let (t1, t2) = (self.t1_c, self.t2_c);
        let path = fx
            .air_path_tau_s
            .map(|tau| if tau > 0.0 { 1.0 / tau } else { 0.0 });
        if f1 != 1.0 || f2 != 1.0 || path != [0.0; 2] {
            // Each block's conductance to the case scaled, a path from the
            // air beside it; the rise is a heat input.
            let block = |k: f64, f: f64, rise: f64, kx: f64, other: f64, kp: f64| {
                let rate = f * k + kx + kp;
                (
                    (f * k * self.case_c + k * rise * on + kx * other + kp * air_c) / rate,
                    rate,
                )
            };
            let (eq1, rate1) = block(k1, f1, c.block1_rise_c, kc, t2, path[0]);
            let (eq2, rate2) = block(k2, f2, c.block2_rise_c, kc2, t1, path[1]);
            relax(&mut self.t1_c, eq1, dt_s * rate1);
            relax(&mut self.t2_c, eq2, dt_s * rate2);
        } else {
            let eq1 = (k1 * (self.case_c + c.block1_rise_c * on) + kc * t2) / (k1 + kc);
            let eq2 = (k2 * (self.case_c + c.block2_rise_c * on) + kc2 * t1) / (k2 + kc2);
            relax(&mut self.t1_c, eq1, dt_s * (k1 + kc));
            relax(&mut self.t2_c, eq2, dt_s * (k2 + kc2));
        }
        self.ddt_dt_c_per_s = ((self.t1_c - self.t2_c) - dt_before) / dt_s;
        let nodes = [self.t1_c, self.t2_c, self.case_c];
        for ((sensor, node), lag) in self.sensor_c.iter_mut().zip(nodes).zip(fx.sensor_lag_s) {
            if lag > 0.0 {
                relax(sensor, node, dt_s / lag);
            } else {
                *sensor = node;
            }
        }
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

    /// A network with no exchange between the blocks and no loading of
    /// the case, settled at `air_c` with `exchange`: each node on its own.
    fn settled(cfg: &ThermalConfig, air_c: f64, exchange: &Exchange) -> ThermalNetwork {
        let mut net = ThermalNetwork::soaked(cfg, air_c);
        // Each node's step is exact on its own: a long step settles as well.
        for _ in 0..200_000 {
            net.step_in(1.0, air_c, true, exchange);
        }
        net
    }

    fn lone_blocks() -> ThermalConfig {
        let mut cfg = TwinConfig::default_rl16().thermal;
        cfg.coupling_tau_s = 1e12;
        cfg
    }

    /// Each block's conductance to the case scaled by the orientation:
    /// the self-heating is a heat input, so a block's rise above the case
    /// is its configured rise over the factor; the factor follows gravity
    /// along the configured axis.
    #[test]
    fn an_orientation_coupling_scales_each_blocks_conductance_to_the_case() {
        let mut cfg = lone_blocks();
        cfg.effects.orientation_coupling = [0.5, -0.2];
        cfg.effects.orientation_axis_body = [0.0, 0.0, 2.0];
        let down_z = nalgebra::Vector3::new(0.0, 0.0, 1.0);
        let ex = Exchange::at(&cfg, &down_z);
        assert_eq!(ex.block_conductance, [1.5, 0.8]);
        let level = Exchange::at(&cfg, &nalgebra::Vector3::new(1.0, 0.0, 0.0));
        assert_eq!(level.block_conductance, [1.0, 1.0]);
        let net = settled(&cfg, 20.0, &ex);
        assert!((net.t1_c - net.case_c - cfg.block1_rise_c / 1.5).abs() < 1e-6);
        assert!((net.t2_c - net.case_c - cfg.block2_rise_c / 0.8).abs() < 1e-6);
    }

    /// A path from the air to block 2: it settles between the case (plus
    /// its rise) and the air, weighted by the two conductances; block 1
    /// is not touched.
    #[test]
    fn an_air_path_pulls_its_block_toward_the_air() {
        let mut cfg = lone_blocks();
        cfg.effects.air_path_tau_s = [0.0, 2.0 * cfg.block2_tau_s];
        let ex = Exchange::convection(1.0);
        let net = settled(&cfg, -30.0, &ex);
        let (k, kp) = (1.0 / cfg.block2_tau_s, 0.5 / cfg.block2_tau_s);
        let want = (k * (net.case_c + cfg.block2_rise_c) + kp * -30.0) / (k + kp);
        assert!((net.t2_c - want).abs() < 1e-6, "{} vs {want}", net.t2_c);
        assert!((net.t1_c - net.case_c - cfg.block1_rise_c).abs() < 1e-6);
    }

    /// The case's conductance to the air grows with the air temperature:
    /// its rise over the air is the configured one at 20 degC and that
    /// over the factor elsewhere.
    #[test]
    fn a_case_conductance_that_changes_with_temperature_changes_the_rise() {
        let mut cfg = lone_blocks();
        cfg.effects.case_conductance_per_c = 0.01;
        let ex = Exchange::convection(1.0);
        for (air, factor) in [(20.0, 1.0), (50.0, 1.3), (-40.0, 0.4)] {
            assert!((cfg.effects.case_conductance(air) - factor).abs() < 1e-12);
            let net = settled(&cfg, air, &ex);
            let rise = net.case_c - air;
            assert!(
                (rise - cfg.case_rise_c / factor).abs() < 1e-6,
                "{air}: {rise}"
            );
        }
    }

    /// A sensor with its own lag trails its node on a ramp by the ramp
    /// times the lag, and one with a gain error reads `(1 + e) T` plus its
    /// offset; the other sensors read their nodes.
    #[test]
    fn sensors_read_their_nodes_through_their_lag_and_gain() {
        let mut cfg = TwinConfig::default_rl16().thermal;
        cfg.effects.sensor_lag_s = [0.0, 0.0, 90.0];
        cfg.effects.sensor_gain_error = [0.02, 0.0, 0.0];
        cfg.sensor_offset_c = [0.1, -0.2, 0.0];
        let mut net = ThermalNetwork::soaked(&cfg, 20.0);
        let ramp = 1.0 / 60.0;
        let ex = Exchange::convection(1.0);
        // Three hours of a 1 degC/min ramp: the case follows at nearly its
        // rate, the sensor that rate times 90 s behind it.
        let mut before = net.case_c;
        for k in 0..108_000 {
            before = net.case_c;
            net.step_in(0.1, 20.0 + ramp * 0.1 * f64::from(k), true, &ex);
        }
        let rate = (net.case_c - before) / 0.1;
        assert!(rate > 0.99 * ramp, "{rate}");
        let r = net.readings_c();
        let trail = net.case_c - r[2];
        assert!((trail - rate * 90.0).abs() < 1e-3 * trail, "trails {trail}");
        assert!((r[0] - (1.02 * net.t1_c + 0.1)).abs() < 1e-12);
        assert!((r[1] - (net.t2_c - 0.2)).abs() < 1e-12);
    }
}
