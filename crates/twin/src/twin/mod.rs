//! The simulated RL-16 and its bench: chamber air, gyro thermal network,
//! rate output, and the two-axis table, on virtual time.
//!
//! Deterministic: the same configuration and seed give the same frames bit
//! for bit. The slow physics (air, thermal network, bias, flicker) advances on
//! a fixed 0.1 s step; each frame adds white angle noise to the cached rate
//! and quantizes the angle, carrying the residual so no angle is lost. A
//! unit whose frame clock is off nominal (`gyro.frame_clock_error_ppm`)
//! sends its frames on its own period; the physics keeps the nominal one.

pub mod config;
pub mod effects;
pub mod noise;
pub mod table;
pub mod thermal;
pub mod thermal_effects;

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use rand_xoshiro::Xoshiro256PlusPlus;

pub use config::TwinConfig;
pub use table::{Axis, AxisDemand};
pub use thermal::ChamberLimit;

use effects::{EffectInputs, Effects};
use gyrobench_analysis::compensation::Model4Inputs;
use gyrobench_model::geometry::{DPS_TO_DPH, Orientation, TableAngles, gravity_ned_g};
use noise::Noise;
use thermal::{ChamberAir, Exchange, ThermalNetwork};

/// Length of the slow-physics step, s (ours: 40 frames at 400 Hz).
pub const THERMAL_STEP_S: f64 = 0.1;

/// Status bits of a gyro frame.
pub mod status {
    /// Laser discharge lit.
    pub const LASING: u16 = 1 << 0;
    /// Mechanical dither running.
    pub const DITHER: u16 = 1 << 1;
    /// Path-length control locked.
    pub const PATH_LENGTH_LOCK: u16 = 1 << 2;
    /// Built-in self-test passed.
    pub const SELF_TEST_OK: u16 = 1 << 3;
    /// Everything nominal.
    pub const NOMINAL: u16 = LASING | DITHER | PATH_LENGTH_LOCK | SELF_TEST_OK;
}

/// One output frame of the gyro, as its digital interface reports it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GyroSample {
    /// Frame index since power-on (the wire counter is this modulo 256).
    pub index: u64,
    /// Device time at the end of the frame, s since the twin started.
    pub time_s: f64,
    /// Delta-angle counts since the previous frame (LSB from the config).
    pub delta_counts: i32,
    /// Block sensor 1, degC (quantized to the output resolution).
    pub t1_c: f64,
    /// Block sensor 2, degC.
    pub t2_c: f64,
    /// Case sensor, degC.
    pub tcase_c: f64,
    /// Status bits ([`status`]).
    pub status: u16,
}

/// What the twin knows that a real bench would not: for tests and diagnosis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    /// Chamber air, degC.
    pub air_c: f64,
    /// True node temperatures (case, T1, T2), degC.
    pub case_c: f64,
    /// Block node 1, degC.
    pub t1_c: f64,
    /// Block node 2, degC.
    pub t2_c: f64,
    /// Kinematic rate on the sensitive axis (Earth + table), deg/h.
    pub kinematic_dph: f64,
    /// Thermal and effect bias now (without white noise), deg/h.
    pub bias_dph: f64,
    /// Time since power-on, s.
    pub tau_s: f64,
    /// Angle fed to the quantizer since power-on (true rate plus white
    /// noise), arcsec; the counts must add up to it.
    pub angle_arcsec: f64,
}

/// The simulated gyro on its bench.
#[derive(Debug, Clone)]
pub struct Twin {
    cfg: TwinConfig,
    rng: Xoshiro256PlusPlus,
    frame_dt_s: f64,
    frames_per_step: u64,
    step_dt_s: f64,
    /// Frames since the twin started (powered or not).
    tick: u64,
    power_on_tick: Option<u64>,
    frame_index: u64,
    chamber: ChamberAir,
    thermal: ThermalNetwork,
    outer: Axis,
    inner: Axis,
    noise: Noise,
    effects: Effects,
    axis_body: Vector3<f64>,
    turn_on_dph: f64,
    // Caches refreshed by the slow step or when the table moves.
    kinematic_dph: f64,
    scale_factor: f64,
    /// The rate response when it is not nominal.
    response: Option<config::RateResponseConfig>,
    bias_dph: f64,
    effect_dph: f64,
    noise_dph: f64,
    exchange: Exchange,
    gravity_body_g: Vector3<f64>,
    magnetic_body_ut: Vector3<f64>,
    sensor_c: [f64; 3],
    // Angle bookkeeping.
    residual_arcsec: f64,
    /// Dither-stripping residual of a dithered (locking) gyro: white angle
    /// jitter of one count rms, and the last frame's.
    jitter: Option<(f64, f64)>,
    true_angle_arcsec: f64,
    true_angle_comp: f64,
    /// The unit's frame oscillator when it is off nominal (none: one
    /// frame ends with every period of `frame_dt_s`).
    frame_clock: Option<FrameClock>,
    /// A second frame that ended within the last period (a fast frame
    /// clock), handed over after the first.
    extra: Option<GyroSample>,
    /// With a frame clock off nominal: the table's angles at the end of
    /// the last frame, and the period it ended in.
    frame_latch: Option<(u64, TableAngles)>,
    /// The path-length control, when it resets.
    plc: Option<Plc>,
    /// The status word of the frames now.
    status: u16,
}

/// The path-length control of a unit whose control resets
/// (`config::PathLengthControlConfig`).
#[derive(Debug, Clone, PartialEq)]
struct Plc {
    cfg: config::PathLengthControlConfig,
    /// The blocks' mean temperature at the last reset (or power-on), degC.
    from_c: f64,
    /// The period until which the control is out of lock.
    relock_until: u64,
    /// On the second mode (its bias added).
    second_mode: bool,
    /// Rate error while out of lock now, deg/h.
    error_dph: f64,
}

/// The unit's frame oscillator off nominal: its frames end every
/// `frame_dt_s / ratio` of device time, not every `frame_dt_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct FrameClock {
    /// Frames per nominal period, `1 + e 1e-6`.
    ratio: f64,
    /// How far the frame under way has got, in frames, at the end of the
    /// last period (0 <= phase < 1).
    phase: f64,
}

impl Twin {
    /// A twin soaked at the chamber's initial temperature, gyro powered on at t = 0.
    pub fn new(cfg: TwinConfig, seed: u64) -> Self {
        let mut twin = Self::unpowered(cfg, seed);
        twin.power_on();
        twin
    }

    /// A twin soaked at the chamber's initial temperature with the gyro off.
    pub fn unpowered(cfg: TwinConfig, seed: u64) -> Self {
        let frame_dt_s = 1.0 / cfg.gyro.frame_rate_hz;
        let frames_per_step = (THERMAL_STEP_S / frame_dt_s).round().max(1.0) as u64;
        let step_dt_s = frames_per_step as f64 * frame_dt_s;
        let t = &cfg.table;
        let mut twin = Self {
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
            frame_dt_s,
            frames_per_step,
            step_dt_s,
            tick: 0,
            power_on_tick: None,
            frame_index: 0,
            chamber: ChamberAir::new(&cfg.chamber),
            thermal: ThermalNetwork::soaked(&cfg.thermal, cfg.chamber.initial_c),
            outer: Axis::at_rest(t.initial.outer_deg, t.max_rate_dps, t.max_acc_dps2)
                .with_rate_mode(t.rate_mode_max_dps, t.rate_mode_max_acc_dps2),
            inner: Axis::at_rest(t.initial.inner_deg, t.max_rate_dps, t.max_acc_dps2)
                .with_rate_mode(t.rate_mode_max_dps, t.rate_mode_max_acc_dps2),
            noise: Noise::new(&with_dither(&cfg), frame_dt_s, step_dt_s),
            effects: Effects::new(&cfg.effects),
            axis_body: Vector3::x(),
            turn_on_dph: 0.0,
            kinematic_dph: 0.0,
            scale_factor: 1.0,
            response: (cfg.rate_response != config::RateResponseConfig::default())
                .then(|| cfg.rate_response.clone()),
            bias_dph: 0.0,
            effect_dph: 0.0,
            noise_dph: 0.0,
            exchange: Exchange::convection(1.0),
            gravity_body_g: Vector3::zeros(),
            magnetic_body_ut: Vector3::zeros(),
            sensor_c: [cfg.chamber.initial_c; 3],
            residual_arcsec: 0.0,
            jitter: (cfg.rate_response.lock_in_dph > 0.0
                && cfg.rate_response.dither_residual_counts > 0.0)
                .then_some((
                    cfg.rate_response.dither_residual_counts * cfg.gyro.lsb_arcsec,
                    0.0,
                )),
            true_angle_arcsec: 0.0,
            true_angle_comp: 0.0,
            frame_clock: (cfg.gyro.frame_clock_error_ppm != 0.0).then_some(FrameClock {
                ratio: 1.0 + cfg.gyro.frame_clock_error_ppm * 1e-6,
                phase: 0.0,
            }),
            extra: None,
            frame_latch: None,
            plc: (!cfg.path_length_control.is_off()).then(|| Plc {
                cfg: cfg.path_length_control.clone(),
                from_c: cfg.chamber.initial_c,
                relock_until: 0,
                second_mode: false,
                error_dph: 0.0,
            }),
            status: status::NOMINAL,
            cfg,
        };
        twin.axis_body = twin.effects.sensitive_axis_body();
        twin.update_orientation();
        twin.read_sensors();
        twin
    }

    /// The configuration this twin runs.
    pub fn config(&self) -> &TwinConfig {
        &self.cfg
    }

    /// Switch the gyro on: time since power-on restarts, a new turn-on bias
    /// is drawn, self-heating begins.
    pub fn power_on(&mut self) {
        self.power_on_tick = Some(self.tick);
        self.frame_index = 0;
        self.turn_on_dph =
            self.cfg.bias.turn_on_sigma_dph * self.rng.sample::<f64, _>(StandardNormal);
        self.noise.randomize(&mut self.rng);
        self.residual_arcsec = 0.0;
        self.true_angle_arcsec = 0.0;
        self.true_angle_comp = 0.0;
        if let Some(c) = &mut self.frame_clock {
            c.phase = 0.0;
        }
        self.extra = None;
        let block_c = self.thermal.block_c();
        let relock = self.relock_periods();
        if let Some(p) = &mut self.plc {
            // The control acquires its lock as the laser lights (its
            // first frame is the next period's).
            p.from_c = block_c;
            p.relock_until = self.tick + 1 + relock;
            p.second_mode = false;
            p.error_dph = 0.0;
        }
        self.refresh_bias();
    }

    /// Periods a reset of the path-length control keeps it out of lock.
    fn relock_periods(&self) -> u64 {
        self.plc
            .as_ref()
            .map_or(0, |p| (p.cfg.relock_s / self.frame_dt_s).round() as u64)
    }

    /// Reset the path-length control when the blocks have moved its
    /// transducer to the end of its travel: out of lock for `relock_s`,
    /// onto the other mode.
    fn path_length_control(&mut self) {
        let block_c = self.thermal.block_c();
        let relock = self.relock_periods();
        let Some(p) = &mut self.plc else {
            return;
        };
        if (block_c - p.from_c).abs() >= p.cfg.reset_span_c {
            p.from_c = block_c;
            p.relock_until = self.tick + relock;
            p.second_mode = !p.second_mode;
            let sign = if self.rng.random::<bool>() { 1.0 } else { -1.0 };
            p.error_dph = sign * p.cfg.relock_error_dph;
        }
    }

    /// Switch the gyro off (no frames; the unit cools towards the case).
    pub fn power_off(&mut self) {
        self.power_on_tick = None;
    }

    /// Follow the power the unit gets: switched on (a new turn-on) or off
    /// when that changes, nothing when it does not.
    pub fn set_powered(&mut self, powered: bool) {
        match (powered, self.is_powered()) {
            (true, false) => self.power_on(),
            (false, true) => self.power_off(),
            _ => {}
        }
    }

    /// True while the gyro is powered.
    pub fn is_powered(&self) -> bool {
        self.power_on_tick.is_some()
    }

    /// Device time since the twin started, s.
    pub fn time_s(&self) -> f64 {
        self.tick as f64 * self.frame_dt_s
    }

    /// Time between frames as the bench takes it (the nominal frame
    /// period, `1 / gyro.frame_rate_hz`), s. The twin advances its
    /// physics on it; with a frame-clock error
    /// (`gyro.frame_clock_error_ppm`) the unit's frames end on its own
    /// period, a little shorter or longer.
    pub fn frame_dt_s(&self) -> f64 {
        self.frame_dt_s
    }

    /// Command the chamber.
    pub fn set_chamber(&mut self, set_c: f64, ramp_c_per_min: f64) -> Result<(), ChamberLimit> {
        self.chamber.set_point(set_c, ramp_c_per_min)
    }

    /// Chamber state: (air, final set point, ramped working set point), degC.
    pub fn chamber_state(&self) -> (f64, f64, f64) {
        (
            self.chamber.air_c(),
            self.chamber.target_c(),
            self.chamber.working_set_point_c(),
        )
    }

    /// Demand motion on the outer and/or inner table axis.
    pub fn demand_table(&mut self, outer: Option<AxisDemand>, inner: Option<AxisDemand>) {
        if let Some(d) = outer {
            self.outer.demand(d);
        }
        if let Some(d) = inner {
            self.inner.demand(d);
        }
    }

    /// The outer (`false`) or inner (`true`) axis.
    pub fn axis(&self, inner: bool) -> &Axis {
        if inner { &self.inner } else { &self.outer }
    }

    /// Set an axis' rate and acceleration limits, clamped to the physical
    /// limits of the configuration.
    pub fn set_axis_limits(&mut self, inner: bool, rate_dps: f64, acc_dps2: f64) {
        let physical = (self.cfg.table.max_rate_dps, self.cfg.table.max_acc_dps2);
        let ax = if inner {
            &mut self.inner
        } else {
            &mut self.outer
        };
        ax.set_limits(rate_dps, acc_dps2, physical);
    }

    /// Move both axes to `angles` (a position demand).
    pub fn move_table(&mut self, angles: TableAngles) {
        self.demand_table(
            Some(AxisDemand::Position(angles.outer_deg)),
            Some(AxisDemand::Position(angles.inner_deg)),
        );
    }

    /// Table angles now.
    pub fn table_angles(&self) -> TableAngles {
        TableAngles {
            outer_deg: self.outer.pos_deg,
            inner_deg: self.inner.pos_deg,
        }
    }

    /// Table axis rates now, deg/s.
    pub fn table_rates(&self) -> TableAngles {
        TableAngles {
            outer_deg: self.outer.rate_dps,
            inner_deg: self.inner.rate_dps,
        }
    }

    /// Table angles at the end of the gyro's last frame, as a bench whose
    /// encoder is latched by the unit's frame strobe reads them: the
    /// angles now when the frames end with the periods (no frame-clock
    /// error), or when the gyro sent no frame in the last two periods.
    pub fn frame_table_angles(&self) -> TableAngles {
        match self.frame_latch {
            Some((period, angles)) if self.is_powered() && period + 1 >= self.tick => angles,
            _ => self.table_angles(),
        }
    }

    /// True while either axis moves.
    pub fn table_moving(&self) -> bool {
        self.outer.is_moving() || self.inner.is_moving()
    }

    /// Body orientation now.
    pub fn orientation(&self) -> Orientation {
        self.cfg.table.geometry.orientation(self.table_angles())
    }

    /// What the twin knows that a real bench would not.
    pub fn truth(&self) -> Truth {
        Truth {
            air_c: self.chamber.air_c(),
            case_c: self.thermal.case_c,
            t1_c: self.thermal.t1_c,
            t2_c: self.thermal.t2_c,
            kinematic_dph: self.kinematic_dph,
            bias_dph: self.bias_dph,
            tau_s: self.tau_s(),
            angle_arcsec: self.true_angle_arcsec + self.true_angle_comp,
        }
    }

    fn tau_s(&self) -> f64 {
        self.power_on_tick
            .map_or(0.0, |t0| (self.tick - t0) as f64 * self.frame_dt_s)
    }

    /// Advance one (nominal) frame period. Returns the frame the gyro
    /// sent, or `None` while it is off (or, its frame clock slow, when no
    /// frame ended in the period); a second frame ending in the same
    /// period (its frame clock fast) waits in `extra`.
    #[inline]
    fn step(&mut self) -> Option<GyroSample> {
        self.tick += 1;
        let moving = self.outer.is_moving() || self.inner.is_moving();
        // Where the table was at the period's start, for the frames that
        // end within it (a frame clock off nominal).
        let from = (moving && self.frame_clock.is_some()).then(|| self.table_angles());
        if moving {
            self.outer.step(self.frame_dt_s);
            self.inner.step(self.frame_dt_s);
            self.update_orientation();
        }
        if self.tick.is_multiple_of(self.frames_per_step) {
            self.slow_step();
        }
        self.power_on_tick?;
        let relock_dph = match &self.plc {
            Some(p) if self.tick < p.relock_until => {
                self.status = status::NOMINAL & !status::PATH_LENGTH_LOCK;
                p.error_dph
            }
            _ => {
                self.status = status::NOMINAL;
                0.0
            }
        };

        let rate_dph = match &self.response {
            None => self.scale_factor * self.kinematic_dph + self.bias_dph,
            Some(r) => r.output_dph(self.kinematic_dph, self.scale_factor, self.bias_dph),
        };
        // An undithered unit inside its lock-in sends nothing: its beams
        // are locked, and its noise with them.
        let locked = rate_dph == 0.0 && self.response.as_ref().is_some_and(|r| r.locks_clean());
        let d_angle = if locked {
            0.0
        } else {
            (rate_dph + relock_dph) * self.frame_dt_s + self.noise.frame_angle_arcsec(&mut self.rng)
        };
        // Kahan sum: the reference angle must stay exact over 1e7+ frames.
        let y = d_angle - self.true_angle_comp;
        let t = self.true_angle_arcsec + y;
        self.true_angle_comp = (t - self.true_angle_arcsec) - y;
        self.true_angle_arcsec = t;

        match self.frame_clock {
            None => {
                self.residual_arcsec += d_angle;
                Some(self.frame(self.time_s()))
            }
            Some(clock) => self.clocked_frames(clock, d_angle, from),
        }
    }

    /// The frames of a unit whose frame clock is off nominal that end in
    /// the period just stepped, which brought `d_angle_arcsec`: at most
    /// two (`|error| <= 1000 ppm`), each quantizing the angle up to its
    /// own end (the angle taken as even over the period), the rest carried
    /// to the next. The first is returned, a second left in `extra`. The
    /// table's angles at each frame's end are latched, between `from`
    /// (the period's start; none: the table did not move) and now.
    fn clocked_frames(
        &mut self,
        clock: FrameClock,
        d_angle_arcsec: f64,
        from: Option<TableAngles>,
    ) -> Option<GyroSample> {
        let start_s = self.time_s() - self.frame_dt_s;
        let now = self.table_angles();
        // A turning axis reads within one turn: its step is under a degree.
        let step = |a: f64, b: f64| (b - a + 180.0).rem_euclid(360.0) - 180.0;
        let end_phase = clock.phase + clock.ratio;
        let mut given = 0.0;
        let mut first = None;
        let mut boundary = 1.0;
        while boundary <= end_phase {
            let at = (boundary - clock.phase) / clock.ratio;
            self.residual_arcsec += (at - given) * d_angle_arcsec;
            given = at;
            let sample = self.frame(start_s + at * self.frame_dt_s);
            let angles = from.map_or(now, |a| TableAngles {
                outer_deg: a.outer_deg + at * step(a.outer_deg, now.outer_deg),
                inner_deg: a.inner_deg + at * step(a.inner_deg, now.inner_deg),
            });
            self.frame_latch = Some((self.tick, angles));
            if first.is_none() {
                first = Some(sample);
            } else {
                self.extra = Some(sample);
            }
            boundary += 1.0;
        }
        self.residual_arcsec += (1.0 - given) * d_angle_arcsec;
        self.frame_clock = Some(FrameClock {
            phase: end_phase - (boundary - 1.0),
            ..clock
        });
        first
    }

    /// The frame ending at `time_s`: the angle in the quantizer (with the
    /// dither's jitter) as whole counts, the rest carried.
    #[inline]
    fn frame(&mut self, time_s: f64) -> GyroSample {
        if let Some((sigma, last)) = &mut self.jitter {
            let j = *sigma * self.rng.sample::<f64, _>(StandardNormal);
            self.residual_arcsec += j - *last;
            *last = j;
        }
        let lsb = self.cfg.gyro.lsb_arcsec;
        let counts = (self.residual_arcsec / lsb).floor();
        self.residual_arcsec -= counts * lsb;
        self.frame_index += 1;
        GyroSample {
            index: self.frame_index,
            time_s,
            delta_counts: counts as i32,
            t1_c: self.sensor_c[0],
            t2_c: self.sensor_c[1],
            tcase_c: self.sensor_c[2],
            status: self.status,
        }
    }

    /// Advance until device time reaches `t_s`, handing every frame to `sink`.
    pub fn run_until(&mut self, t_s: f64, mut sink: impl FnMut(&Self, &GyroSample)) {
        let end_tick = (t_s / self.frame_dt_s).round() as u64;
        while self.tick < end_tick {
            if let Some(sample) = self.step() {
                sink(self, &sample);
            }
            if let Some(sample) = self.extra.take() {
                sink(self, &sample);
            }
        }
    }

    /// Recompute everything that depends on the table pose.
    fn update_orientation(&mut self) {
        let geom = &self.cfg.table.geometry;
        let angles = self.table_angles();
        let r_nb = geom.rotation(angles);
        let axis_ned = r_nb * self.axis_body;
        let omega_ned_dph = self.cfg.site.earth_rate_ned_dph()
            + self.effects.earth_rate_error_ned_dph(&self.cfg.site)
            + geom.angular_velocity_ned_dps(angles, self.table_rates()) * DPS_TO_DPH;
        self.kinematic_dph = axis_ned.dot(&omega_ned_dph);
        let r_bn = r_nb.inverse();
        self.gravity_body_g = r_bn * gravity_ned_g();
        self.magnetic_body_ut = r_bn * self.cfg.site.magnetic_ned_ut();
        self.exchange = Exchange::at(&self.cfg.thermal, &self.gravity_body_g);
    }

    /// The 0.1 s physics step: air, thermal network, bias, sensors.
    fn slow_step(&mut self) {
        let dt = self.step_dt_s;
        let powered = self.is_powered();
        self.chamber.step(dt);
        self.thermal
            .step_in(dt, self.chamber.air_c(), powered, &self.exchange);
        let th = &self.thermal;
        self.scale_factor = self.effects.scale_factor(0.5 * (th.t1_c + th.t2_c));
        let t_s = self.time_s();
        self.effect_dph = self.effects.step_bias_dph(&EffectInputs {
            dt_s: dt,
            t_s,
            case_c: th.case_c,
            blocks_c: [th.t1_c, th.t2_c],
            gravity_body_g: self.gravity_body_g,
            magnetic_body_ut: self.magnetic_body_ut,
        });
        self.noise_dph = self.noise.step_bias_dph(&mut self.rng);
        if powered {
            self.path_length_control();
        }
        self.refresh_bias();
        self.read_sensors();
    }

    fn refresh_bias(&mut self) {
        let b = &self.cfg.bias;
        self.bias_dph = b.model4.offset_dph
            + self.turn_on_dph
            + b.model4
                .thermal_bias_dph(&model4_inputs(&self.thermal, self.tau_s()), b.terms)
            + self.effect_dph
            + self.noise_dph
            + self
                .plc
                .as_ref()
                .filter(|p| p.second_mode)
                .map_or(0.0, |p| p.cfg.mode_bias_dph);
    }

    fn read_sensors(&mut self) {
        let reading = self.thermal.readings_c();
        let (noise, lsb) = (self.cfg.thermal.sensor_noise_c, self.cfg.gyro.temp_lsb_c);
        for (out, r) in self.sensor_c.iter_mut().zip(reading) {
            let noisy = r + noise * self.rng.sample::<f64, _>(StandardNormal);
            *out = (noisy / lsb).round() * lsb;
        }
    }
}

/// The noise terms with the dither's random walk added to the angle
/// random walk (independent white noises add in variance).
fn with_dither(cfg: &TwinConfig) -> config::NoiseConfig {
    let mut n = cfg.noise.clone();
    let d = cfg.rate_response.dither_random_walk_deg_per_rt_h;
    if d > 0.0 {
        n.arw_deg_per_rt_h = n.arw_deg_per_rt_h.hypot(d);
    }
    n
}

/// Model 4's inputs from the thermal network now.
fn model4_inputs(th: &ThermalNetwork, tau_s: f64) -> Model4Inputs {
    Model4Inputs {
        gradient_c: th.gradient_c(),
        gradient_rate_c_per_s: th.ddt_dt_c_per_s,
        case_c: th.case_c,
        tau_s,
    }
}

#[cfg(test)]
mod tests;
