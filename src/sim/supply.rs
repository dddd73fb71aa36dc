//! A programmable DC supply speaking SCPI (Keysight E36300 or Rigol DP800
//! commands), with the unit hanging on one of its channels.
//!
//! Each output slews to its setting, limits its current (the voltage then
//! falls as the load's resistance allows), and trips its over-current
//! protection the way its maker's does: a Keysight when the output stays
//! in current limit for the protection delay, a Rigol as soon as the
//! current demanded passes the protection level. A tripped output is off
//! until the trip is cleared and the output switched on again. Errors go
//! to the SCPI error queue with the standard numbers, never inline.

use std::sync::Arc;

use tokio::io::{AsyncRead, AsyncWrite};

use super::SharedBench;
use super::faults::Action;
use super::lines::serve_lines;
use crate::protocol::scpi::{ErrorQueue, NO_ERROR, Numeric, ScpiError, format_nr3};
use crate::protocol::supply::{Addressed, Command, Dialect, Rating, parse_message, ratings};

/// Longest message accepted, bytes.
pub const MAX_LINE: usize = 1024;
/// Output slew rate, V/s, up and down (ours: 15 V in 30 ms, the order of
/// a bench supply's programming response time).
pub const SLEW_V_PER_S: f64 = 500.0;
/// Keysight: time in current limit before the protection trips, s (ours;
/// the E36300's `CURR:PROT:DEL` sets it on the instrument).
pub const OCP_DELAY_S: f64 = 0.05;
/// Longest integration step while something changes, s.
const STEP_S: f64 = 0.002;

/// The simulated supply's `*IDN?` answer: the model it imitates, naming
/// itself as a simulator.
pub fn idn(dialect: Dialect) -> String {
    let model = match dialect {
        Dialect::KeysightE36300 => "E36312A",
        Dialect::RigolDp800 => "DP832",
    };
    format!(
        "gyrobench,{model} simulator,SIM-SUPPLY,{}",
        env!("CARGO_PKG_VERSION")
    )
}

/// The unit as a load: below half its nominal voltage its converters stay
/// off; above it, it draws a turn-on inrush (the discharge igniting, the
/// converters charging) decaying to a steady current, scaled with the
/// voltage as a resistive load would be (ours: a small RLG's 8 W at 15 V).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UnitLoad {
    /// Nominal supply voltage, V.
    pub nominal_v: f64,
    /// Steady draw at the nominal voltage, A.
    pub steady_a: f64,
    /// Extra draw at turn-on, A.
    pub inrush_a: f64,
    /// Decay time of the inrush, s.
    pub inrush_tau_s: f64,
}

impl UnitLoad {
    /// The RL-16 of the twin (ours).
    pub const RL16: Self = Self {
        nominal_v: 15.0,
        steady_a: 0.55,
        inrush_a: 0.6,
        inrush_tau_s: 0.1,
    };

    /// Current drawn at `v` after `powered_s` of operation, A.
    pub fn current_a(&self, v: f64, powered_s: f64) -> f64 {
        if v < 0.5 * self.nominal_v {
            return 0.0;
        }
        v / self.nominal_v
            * (self.steady_a + self.inrush_a * (-powered_s / self.inrush_tau_s).exp())
    }

    /// True once the inrush is over (within 1e-6 of it left).
    fn settled(&self, powered_s: f64) -> bool {
        powered_s > 14.0 * self.inrush_tau_s
    }
}

/// One output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Channel {
    /// What it can deliver.
    pub rating: Rating,
    /// Voltage setting, V.
    pub set_v: f64,
    /// Current limit, A.
    pub limit_a: f64,
    /// Output switched on.
    pub on: bool,
    /// Over-current protection enabled.
    pub ocp: bool,
    /// Rigol: the protection's trip level, A.
    pub ocp_level_a: f64,
    /// The protection has tripped (and the output is off).
    pub tripped: bool,
    /// Open-circuit voltage the output has slewed to, V.
    pub source_v: f64,
    /// Voltage at the terminals, V.
    pub out_v: f64,
    /// Current delivered, A.
    pub out_a: f64,
    /// Time spent in current limit, s.
    pub in_limit_s: f64,
}

impl Channel {
    fn new(rating: Rating) -> Self {
        Self {
            rating,
            set_v: 0.0,
            limit_a: rating.max_a,
            on: false,
            ocp: false,
            ocp_level_a: rating.max_a,
            tripped: false,
            source_v: 0.0,
            out_v: 0.0,
            out_a: 0.0,
            in_limit_s: 0.0,
        }
    }
}

/// The supply's state.
#[derive(Debug, Clone)]
pub struct Supply {
    /// Whose commands it takes.
    pub dialect: Dialect,
    /// Its outputs, channel 1 first.
    pub channels: Vec<Channel>,
    /// The channel commands act on (0-based).
    pub selected: usize,
    /// The error queue.
    pub errors: ErrorQueue,
    /// The unit, and the channel (0-based) it hangs on.
    pub load: (UnitLoad, usize),
    /// How long the unit has been powered, s (0 while off).
    pub powered_s: f64,
    /// Peak current drawn since the last power-on, A.
    pub peak_a: f64,
    /// A faulty supply (`--inject supply-ignores-off`): `OUTP OFF` is
    /// taken without an error and does nothing, its output stays on.
    pub ignores_off: bool,
    /// Time of the state, s.
    t_s: f64,
}

impl Supply {
    /// A supply of `dialect`'s model, outputs off, the unit on channel 2.
    pub fn new(dialect: Dialect) -> Self {
        Self {
            dialect,
            channels: ratings(dialect).into_iter().map(Channel::new).collect(),
            selected: 0,
            errors: ErrorQueue::default(),
            load: (UnitLoad::RL16, 1),
            powered_s: 0.0,
            peak_a: 0.0,
            ignores_off: false,
            t_s: 0.0,
        }
    }

    /// True while the unit draws power.
    pub fn unit_powered(&self) -> bool {
        self.powered_s > 0.0
    }

    /// The channel the unit hangs on.
    pub fn unit_channel(&self) -> &Channel {
        &self.channels[self.load.1.min(self.channels.len() - 1)]
    }

    /// A supply of `dialect`'s model already powering the unit from
    /// channel 2 at its nominal voltage, settled: the state a bench is in
    /// when a run starts on a unit switched on beforehand (`sim serve`
    /// starts so).
    pub fn powering_unit(dialect: Dialect) -> Self {
        let limit = ratings(dialect)[1].max_a;
        Self::powering(dialect, 2, UnitLoad::RL16.nominal_v, limit, false)
    }

    /// The same with the unit on `channel` (1-based; channel 2 when the
    /// model has no such channel) at `volts`, `limit_a`, its protection
    /// on or off; an output that cannot give that is left off.
    pub fn powering(
        dialect: Dialect,
        channel: u8,
        volts: f64,
        limit_a: f64,
        protection: bool,
    ) -> Self {
        let mut s = Self::new(dialect);
        let at = usize::from(channel)
            .checked_sub(1)
            .filter(|i| *i < s.channels.len())
            .unwrap_or(1);
        s.load.1 = at;
        let rating = s.channels[at].rating;
        if !(0.0..=rating.max_v).contains(&volts) || !(0.0..=rating.max_a).contains(&limit_a) {
            return s;
        }
        let load = s.load.0;
        let c = &mut s.channels[at];
        c.set_v = volts;
        c.limit_a = limit_a;
        c.ocp = protection;
        c.ocp_level_a = limit_a;
        c.on = true;
        c.source_v = volts;
        let demand = load.current_a(volts, f64::INFINITY);
        (c.out_v, c.out_a) = if demand > limit_a {
            (volts * limit_a / demand, limit_a)
        } else {
            (volts, demand)
        };
        if load.current_a(c.out_v, 0.0) > 0.0 {
            s.powered_s = 20.0 * load.inrush_tau_s;
            s.peak_a = c.out_a;
        }
        s
    }

    /// The unit wired to `channel` (1-based) with the output set to
    /// `volts` and `limit_a` and switched off: a bench before its run
    /// switches the unit on (`OUTP ON` powers it at the bench's voltage).
    pub fn wired(
        dialect: Dialect,
        channel: u8,
        volts: f64,
        limit_a: f64,
        protection: bool,
    ) -> Self {
        let mut s = Self::powering(dialect, channel, volts, limit_a, protection);
        let c = &mut s.channels[s.load.1];
        c.on = false;
        c.source_v = 0.0;
        c.out_v = 0.0;
        c.out_a = 0.0;
        s.powered_s = 0.0;
        s.peak_a = 0.0;
        s
    }

    /// A supply of `dialect`'s model with the unit wired to channel 2 at
    /// its nominal voltage, output off (`sim serve` starts so: the unit
    /// is off until a run switches it on).
    pub fn unit_off(dialect: Dialect) -> Self {
        let limit = ratings(dialect)[1].max_a;
        Self::wired(dialect, 2, UnitLoad::RL16.nominal_v, limit, false)
    }

    /// Move the outputs to time `t_s`: fine steps while anything changes,
    /// one step once everything is steady.
    pub fn advance_to(&mut self, t_s: f64) {
        while self.advance_until_change(t_s).is_some() {}
    }

    /// Move towards `t_s`, stopping early at the end of the step in which
    /// the unit's power came or went; that time, or none once at `t_s`.
    pub fn advance_until_change(&mut self, t_s: f64) -> Option<f64> {
        let was = self.unit_powered();
        while self.t_s < t_s {
            let left = t_s - self.t_s;
            let dt = if self.steady() {
                left
            } else {
                left.min(STEP_S)
            };
            self.step(dt);
            self.t_s = if dt == left { t_s } else { self.t_s + dt };
            if self.unit_powered() != was {
                return Some(self.t_s);
            }
        }
        None
    }

    fn steady(&self) -> bool {
        let (load, at) = self.load;
        self.channels.iter().enumerate().all(|(i, c)| {
            let target = if c.on && !c.tripped { c.set_v } else { 0.0 };
            let demand = if i == at {
                load.current_a(c.source_v, self.powered_s)
            } else {
                0.0
            };
            // Held at the limit (or about to be: a lower limit, a short)
            // is a change the protection acts on within milliseconds.
            c.source_v == target
                && c.in_limit_s == 0.0
                && demand <= c.limit_a
                && !(c.ocp && demand > c.ocp_level_a)
                && (i != at || !self.unit_powered() || load.settled(self.powered_s))
        })
    }

    fn step(&mut self, dt: f64) {
        let (load, at) = self.load;
        let dialect = self.dialect;
        for (i, c) in self.channels.iter_mut().enumerate() {
            let target = if c.on && !c.tripped { c.set_v } else { 0.0 };
            let max_dv = SLEW_V_PER_S * dt;
            if (target - c.source_v).abs() <= max_dv {
                // Exactly there, so that the state counts as steady.
                c.source_v = target;
            } else {
                c.source_v += max_dv.copysign(target - c.source_v);
            }
            let demand = if i == at {
                load.current_a(c.source_v, self.powered_s)
            } else {
                0.0
            };
            if demand > c.limit_a {
                c.out_a = c.limit_a;
                c.out_v = c.source_v * c.limit_a / demand;
                c.in_limit_s += dt;
            } else {
                c.out_a = demand;
                c.out_v = c.source_v;
                c.in_limit_s = 0.0;
            }
            let trip = c.ocp
                && match dialect {
                    Dialect::KeysightE36300 => c.in_limit_s >= OCP_DELAY_S,
                    Dialect::RigolDp800 => demand > c.ocp_level_a,
                };
            if trip {
                c.tripped = true;
                c.on = false;
                c.source_v = 0.0;
                c.out_v = 0.0;
                c.out_a = 0.0;
                c.in_limit_s = 0.0;
            }
            if i == at {
                if load.current_a(c.out_v, 0.0) > 0.0 {
                    self.powered_s += dt;
                    self.peak_a = self.peak_a.max(c.out_a);
                } else {
                    self.powered_s = 0.0;
                    self.peak_a = 0.0;
                }
            }
        }
    }

    fn number(&self, v: f64) -> String {
        match self.dialect {
            Dialect::KeysightE36300 => format_nr3(v),
            Dialect::RigolDp800 => format!("{v:.4}"),
        }
    }

    fn flag(&self, b: bool, words: (&str, &str)) -> String {
        match (self.dialect, b) {
            (Dialect::KeysightE36300, true) => "1".into(),
            (Dialect::KeysightE36300, false) => "0".into(),
            (Dialect::RigolDp800, true) => words.0.into(),
            (Dialect::RigolDp800, false) => words.1.into(),
        }
    }

    fn level(n: Numeric, max: f64) -> Result<f64, ScpiError> {
        match n {
            Numeric::Min => Ok(0.0),
            Numeric::Max => Ok(max),
            Numeric::Value(v) if (0.0..=max).contains(&v) => Ok(v),
            Numeric::Value(_) => Err(ScpiError::OUT_OF_RANGE),
        }
    }

    fn execute(&mut self, c: Command) -> Result<Option<String>, ScpiError> {
        let ch = self.selected;
        let rating = self.channels[ch].rating;
        let reply = match c {
            Command::Identify => Some(idn(self.dialect)),
            Command::Reset => {
                let keep = (self.load, self.t_s);
                *self = Self::new(self.dialect);
                (self.load, self.t_s) = keep;
                None
            }
            Command::ClearStatus => {
                self.errors.clear();
                None
            }
            Command::OperationComplete => Some("1".into()),
            Command::Select(n) => {
                self.selected = usize::from(n)
                    .checked_sub(1)
                    .filter(|i| *i < self.channels.len())
                    .ok_or(ScpiError::OUT_OF_RANGE)?;
                None
            }
            Command::SelectQuery => Some((self.selected + 1).to_string()),
            Command::Voltage(n) => {
                self.channels[ch].set_v = Self::level(n, rating.max_v)?;
                None
            }
            Command::VoltageQuery => Some(self.number(self.channels[ch].set_v)),
            Command::Current(n) => {
                self.channels[ch].limit_a = Self::level(n, rating.max_a)?;
                None
            }
            Command::CurrentQuery => Some(self.number(self.channels[ch].limit_a)),
            Command::Output(on) => {
                if on && self.channels[ch].tripped {
                    return Err(ScpiError::SETTINGS_CONFLICT);
                }
                if !on && self.ignores_off {
                    return Ok(None);
                }
                self.channels[ch].on = on;
                None
            }
            Command::OutputQuery => Some(self.flag(self.channels[ch].on, ("ON", "OFF"))),
            Command::MeasureVoltage => Some(self.number(round_to(self.channels[ch].out_v, 1e-3))),
            Command::MeasureCurrent => Some(self.number(round_to(self.channels[ch].out_a, 1e-4))),
            Command::Protection(on) => {
                self.channels[ch].ocp = on;
                None
            }
            Command::ProtectionQuery => Some(self.flag(self.channels[ch].ocp, ("ON", "OFF"))),
            Command::ProtectionLevel(n) => {
                self.channels[ch].ocp_level_a = Self::level(n, rating.max_a * 1.1)?;
                None
            }
            Command::ProtectionLevelQuery => Some(self.number(self.channels[ch].ocp_level_a)),
            Command::Tripped => Some(self.flag(self.channels[ch].tripped, ("YES", "NO"))),
            Command::ClearProtection => {
                self.channels[ch].tripped = false;
                None
            }
            Command::ErrorQuery => Some(
                self.errors
                    .pop()
                    .map_or_else(|| NO_ERROR.to_owned(), |e| e.reply()),
            ),
            Command::Remote => None,
        };
        Ok(reply)
    }

    /// A command on the channels it names, each in turn (a query's
    /// answers joined with `,`, in the list's order; the selection left as
    /// it was), or on the selected channel. A channel the supply lacks, or
    /// a setting one of them refuses, refuses the whole command: no
    /// channel is touched.
    fn execute_on(&mut self, a: Addressed) -> Result<Option<String>, ScpiError> {
        let Some(list) = a.channels else {
            return self.execute(a.command);
        };
        let mut trial = self.clone();
        let mut answers = Vec::new();
        for n in list.iter() {
            trial.selected = usize::from(n)
                .checked_sub(1)
                .filter(|i| *i < trial.channels.len())
                .ok_or(ScpiError::OUT_OF_RANGE)?;
            answers.extend(trial.execute(a.command)?);
        }
        trial.selected = self.selected;
        *self = trial;
        Ok((!answers.is_empty()).then(|| answers.join(",")))
    }

    /// Execute one message; the answers of its queries joined with `;`,
    /// none when it holds no query.
    pub fn message(&mut self, line: &str) -> Option<String> {
        let mut answers = Vec::new();
        for parsed in parse_message(line, self.dialect) {
            match parsed.and_then(|a| self.execute_on(a)) {
                Ok(Some(a)) => answers.push(a),
                Ok(None) => {}
                Err(e) => self.errors.push(e),
            }
        }
        (!answers.is_empty()).then(|| answers.join(";"))
    }
}

impl Supply {
    /// Carry out `cmds` on `channel` (1-based) as the instrument does when
    /// a driver sends them; the errors they queued, in words
    /// (`-222 Data out of range`), the queue emptied.
    pub fn program(&mut self, channel: u8, cmds: &[Command]) -> Vec<String> {
        self.errors.clear();
        for c in std::iter::once(Command::Select(channel)).chain(cmds.iter().copied()) {
            if let Err(e) = self.execute(c) {
                self.errors.push(e);
            }
        }
        std::iter::from_fn(|| self.errors.pop())
            .map(|e| format!("{} {}", e.code, e.text))
            .collect()
    }

    /// `channel` (1-based) as a driver reads it (measurements at the
    /// instrument's resolution); none when there is no such channel.
    pub fn reading(&self, channel: u8) -> Option<crate::driver::SupplyReading> {
        let c = self.channels.get(usize::from(channel).checked_sub(1)?)?;
        Some(crate::driver::SupplyReading {
            set_v: c.set_v,
            limit_a: c.limit_a,
            v: round_to(c.out_v, 1e-3),
            a: round_to(c.out_a, 1e-4),
            on: c.on,
            tripped: c.tripped,
        })
    }
}

fn round_to(v: f64, step: f64) -> f64 {
    (v / step).round() * step
}

/// Serve the supply's SCPI on one connection until it closes.
pub async fn serve_supply<S>(stream: S, bench: Arc<SharedBench>) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    serve_lines(
        stream,
        bench,
        |f| &f.supply,
        MAX_LINE,
        |bench, action, line| {
            let mut b = bench.lock();
            if action == Action::ErrorReply {
                // Errors go to the queue, never inline.
                b.supply.errors.push(ScpiError::SETTINGS_CONFLICT);
            }
            b.supply
                .message(line)
                .map(|text| format!("{text}\n").into_bytes())
        },
    )
    .await
}

#[cfg(test)]
mod tests {
    use super::*;

    fn num(s: Option<String>) -> f64 {
        s.and_then(|s| s.trim().parse().ok()).expect("a number")
    }

    fn powered(dialect: Dialect, limit_a: f64, ocp: bool) -> Supply {
        let mut s = Supply::new(dialect);
        assert_eq!(
            s.message(&format!(
                "INST:NSEL 2;:VOLT 15;:CURR {limit_a};:CURR:PROT:STAT {}",
                if ocp { "ON" } else { "OFF" }
            )),
            None
        );
        s.message("OUTP ON");
        s
    }

    #[test]
    fn the_output_slews_then_the_unit_draws_its_inrush_then_steady() {
        let mut s = powered(Dialect::KeysightE36300, 1.0, false);
        s.advance_to(0.01);
        let v = num(s.message("MEAS:VOLT?"));
        assert!((v - 5.0).abs() < 0.01, "10 ms at 500 V/s: {v}");
        assert_eq!(num(s.message("MEAS:CURR?")), 0.0, "below half the nominal");
        s.advance_to(0.04);
        let a = num(s.message("MEAS:CURR?"));
        assert!(a > 0.9 && a <= 1.0, "the inrush at turn-on: {a}");
        s.advance_to(5.0);
        assert_eq!(num(s.message("MEAS:VOLT?")), 15.0);
        let a = num(s.message("MEAS:CURR?"));
        assert!((a - UnitLoad::RL16.steady_a).abs() < 1e-3, "{a}");
        assert!(s.unit_powered() && s.peak_a > 0.9);
        s.message("OUTP OFF");
        s.advance_to(5.1);
        assert!(!s.unit_powered());
        assert_eq!(num(s.message("MEAS:VOLT?")), 0.0);
    }

    #[test]
    fn a_keysight_trips_after_its_delay_in_current_limit() {
        // 1 A covers the inrush but for a moment: no trip.
        let mut s = powered(Dialect::KeysightE36300, 1.0, true);
        s.advance_to(2.0);
        assert_eq!(s.message("CURR:PROT:TRIP?").as_deref(), Some("0"));
        // At 0.8 A the unit stays in limit longer than the delay.
        let mut s = powered(Dialect::KeysightE36300, 0.8, true);
        s.advance_to(2.0);
        assert_eq!(s.message("CURR:PROT:TRIP?;:OUTP?").as_deref(), Some("1;0"));
        assert!(!s.unit_powered());
        s.message("OUTP ON");
        assert_eq!(
            s.message("SYST:ERR?;:SYST:ERR?").as_deref(),
            Some("-221,\"Settings conflict\";0,\"No error\"")
        );
        s.message("CURR 1.0;:OUTP:PROT:CLE;:OUTP ON");
        s.advance_to(4.0);
        assert_eq!(s.message("CURR:PROT:TRIP?;:OUTP?").as_deref(), Some("0;1"));
        assert!(s.unit_powered());
    }

    #[test]
    fn a_rigol_trips_above_its_level_and_answers_in_words() {
        let mut s = Supply::new(Dialect::RigolDp800);
        s.message("INST:NSEL 2;:VOLT 15;:CURR 2;:CURR:PROT 0.9;:CURR:PROT:STAT ON;:OUTP ON");
        s.advance_to(1.0);
        assert_eq!(
            s.message("CURR:PROT:TRIP?;:OUTP?").as_deref(),
            Some("YES;OFF")
        );
        s.message("CURR:PROT 1.5;:CURR:PROT:CLE;:OUTP ON");
        s.advance_to(2.0);
        assert_eq!(
            s.message("CURR:PROT:TRIP?;:OUTP?").as_deref(),
            Some("NO;ON")
        );
        assert_eq!(s.message("MEAS:VOLT?").as_deref(), Some("15.0000"));
    }

    #[test]
    fn a_bench_starts_with_the_unit_powered_and_settled() {
        let mut s = Supply::powering_unit(Dialect::KeysightE36300);
        assert!(s.unit_powered());
        assert_eq!(s.advance_until_change(100.0), None);
        assert_eq!(
            s.message("INST:NSEL 2;:MEAS:CURR?;:OUTP?").as_deref(),
            Some("+5.50000000E-01;1")
        );
        s.message("OUTP OFF");
        let off = s.advance_until_change(200.0).expect("the unit goes off");
        assert!(off > 100.0 && off < 100.02, "within the slew down: {off}");
        s.advance_to(200.0);
        s.message("OUTP ON");
        let on = s.advance_until_change(300.0).expect("and on again");
        assert!(on > 200.0 && on < 200.02, "{on}");
        assert_eq!(s.advance_until_change(300.0), None);
    }

    #[test]
    fn the_twin_runs_on_the_supply_s_power() {
        let mut b = crate::sim::test_bench();
        let mut rx = b.subscribe_gyro();
        b.advance_to(1.0);
        assert!(
            b.twin.is_powered() && rx.try_recv().is_ok(),
            "frames while powered"
        );
        b.supply.message("INST:NSEL 2;:OUTP OFF");
        b.advance_to(2.0);
        while rx.try_recv().is_ok() {}
        b.advance_to(3.0);
        assert!(!b.twin.is_powered());
        assert!(rx.try_recv().is_err(), "no frames from an unpowered unit");
        b.supply.message("OUTP ON");
        b.advance_to(4.0);
        assert!(b.twin.is_powered() && rx.try_recv().is_ok());
        let tau = b.twin.truth().tau_s;
        assert!(
            tau > 0.9 && tau < 1.0,
            "time since power-on restarted: {tau}"
        );
    }

    /// Every error left in the queue, oldest first.
    fn drain(s: &mut Supply) -> Vec<String> {
        std::iter::from_fn(|| s.message("SYST:ERR?").filter(|e| !e.starts_with('0'))).collect()
    }

    #[test]
    fn a_keysight_answers_and_sets_the_channels_a_list_names() {
        let mut s = Supply::powering_unit(Dialect::KeysightE36300);
        s.message("INST:NSEL 1");
        assert_eq!(
            s.message("MEAS:VOLT? (@2)").as_deref(),
            Some("+1.50000000E+01")
        );
        assert_eq!(
            s.message("MEAS:VOLT? (@1:3);:OUTP? (@3,2,1)").as_deref(),
            Some("+0.00000000E+00,+1.50000000E+01,+0.00000000E+00;0,1,0")
        );
        s.message("VOLT 5,(@1,3);CURR 0.5,(@3)");
        assert_eq!(
            s.message("VOLT? (@1:3);CURR? (@3)").as_deref(),
            Some("+5.00000000E+00,+1.50000000E+01,+5.00000000E+00;+5.00000000E-01")
        );
        assert_eq!(
            s.message("INST:NSEL?").as_deref(),
            Some("1"),
            "selection kept"
        );
        // 20 V is beyond channel 1's 6 V: refused whole, channel 2 untouched;
        // a channel the supply lacks is out of range.
        s.message("VOLT 20,(@1,2);:MEAS:VOLT? (@4);:SYST:ERR? (@1)");
        assert_eq!(
            drain(&mut s),
            [
                "-222,\"Data out of range\"",
                "-222,\"Data out of range\"",
                "-108,\"Parameter not allowed\""
            ]
        );
        assert_eq!(
            s.message("VOLT? (@1,2)").as_deref(),
            Some("+5.00000000E+00,+1.50000000E+01")
        );
        s.message("OUTP OFF,(@2)");
        s.advance_to(1.0);
        assert!(!s.unit_powered(), "switched off through the list");
    }

    #[test]
    fn a_rigol_answers_the_channel_it_is_given_as_a_dp832_does() {
        let mut s = Supply::powering_unit(Dialect::RigolDp800);
        s.message("INST:NSEL 1");
        assert_eq!(
            s.message("MEAS:VOLT? CH2;:OUTP? CH2;:OUTP? CH1").as_deref(),
            Some("15.0000;ON;OFF")
        );
        s.message("SOUR3:VOLT 3.3;CURR 0.2;:OUTP CH3,ON");
        assert_eq!(
            s.message("INST:NSEL 3;:VOLT?;CURR?;:OUTP?").as_deref(),
            Some("3.3000;0.2000;ON")
        );
        s.message("MEAS:VOLT? (@2)");
        assert_eq!(drain(&mut s), ["-108,\"Parameter not allowed\""]);
    }

    /// A channel-list query split at every byte boundary on the wire gets
    /// the same answer: the line is whole before it is parsed.
    #[tokio::test(flavor = "current_thread")]
    async fn a_query_split_at_every_byte_boundary_gets_one_answer() {
        use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
        let clock: Arc<dyn crate::clock::Clock> =
            Arc::new(crate::clock::VirtualClock::new(crate::clock::Pacing::Max));
        let bench = SharedBench::new(crate::sim::test_bench(), clock);
        let msg = b"MEAS:VOLT? (@1:3);:OUTP? (@2)\n";
        for k in 1..msg.len() {
            let (a, b) = tokio::io::duplex(256);
            let server = tokio::spawn(serve_supply(b, bench.clone()));
            let (r, mut w) = tokio::io::split(a);
            w.write_all(&msg[..k]).await.expect("first part");
            w.flush().await.expect("flush");
            tokio::task::yield_now().await;
            w.write_all(&msg[k..]).await.expect("second part");
            let mut line = String::new();
            BufReader::new(r)
                .read_line(&mut line)
                .await
                .expect("an answer");
            assert_eq!(
                line, "+0.00000000E+00,+1.50000000E+01,+0.00000000E+00;1\n",
                "split at {k}"
            );
            drop(w);
            server.abort();
        }
    }

    #[test]
    fn settings_beyond_the_rating_are_refused_with_their_number() {
        let mut s = Supply::new(Dialect::KeysightE36300);
        s.message("INST:NSEL 1;:VOLT 7;:INST:NSEL 4;:FOO;:VOLT MAX");
        assert_eq!(s.message("VOLT?").as_deref(), Some("+6.00000000E+00"));
        let mut errors = Vec::new();
        loop {
            let e = s.message("SYST:ERR?").expect("an answer");
            if e.starts_with('0') {
                break;
            }
            errors.push(e);
        }
        assert_eq!(
            errors,
            [
                "-222,\"Data out of range\"",
                "-222,\"Data out of range\"",
                "-113,\"Undefined header\""
            ]
        );
        assert!(s.message("*IDN?").is_some_and(|i| i.contains("E36312A")));
        s.message("*RST");
        assert_eq!(
            s.message("VOLT?;:OUTP?").as_deref(),
            Some("+0.00000000E+00;0")
        );
    }
}
