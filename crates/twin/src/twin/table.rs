//! Axis dynamics of the two-axis motion simulator: position and rate modes
//! with rate and acceleration limits.

/// What an axis is asked to do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AxisDemand {
    /// Go to an angle and hold it, deg.
    Position(f64),
    /// Turn at a constant rate, deg/s.
    Rate(f64),
    /// Controlled stop: decelerate to rest where the axis is.
    Stop,
}

/// One table axis.
#[derive(Debug, Clone)]
pub struct Axis {
    /// Angle, deg.
    pub pos_deg: f64,
    /// Rate, deg/s.
    pub rate_dps: f64,
    demand: AxisDemand,
    max_rate_dps: f64,
    max_acc_dps2: f64,
    /// Rate and acceleration limits of rate mode (and of stopping from it).
    rate_mode: (f64, f64),
}

impl Axis {
    /// An axis at rest at `pos_deg`.
    pub fn at_rest(pos_deg: f64, max_rate_dps: f64, max_acc_dps2: f64) -> Self {
        Self {
            pos_deg,
            rate_dps: 0.0,
            demand: AxisDemand::Position(pos_deg),
            max_rate_dps,
            max_acc_dps2,
            rate_mode: (max_rate_dps, max_acc_dps2),
        }
    }

    /// With rate-mode limits of its own (a rate table turns far faster
    /// than it positions).
    pub fn with_rate_mode(mut self, rate_dps: f64, acc_dps2: f64) -> Self {
        self.rate_mode = (rate_dps, acc_dps2);
        self
    }

    /// Rate and acceleration limits of rate mode, deg/s and deg/s^2.
    pub fn rate_mode_limits(&self) -> (f64, f64) {
        self.rate_mode
    }

    /// Replace the demand (rates beyond the rate-mode limit are clamped
    /// to it).
    pub fn demand(&mut self, demand: AxisDemand) {
        self.demand = match demand {
            AxisDemand::Rate(r) => AxisDemand::Rate(r.clamp(-self.rate_mode.0, self.rate_mode.0)),
            d => d,
        };
    }

    /// Lower the rate and acceleration limits (never above `physical`).
    pub fn set_limits(&mut self, rate_dps: f64, acc_dps2: f64, physical: (f64, f64)) {
        self.max_rate_dps = rate_dps.clamp(0.0, physical.0);
        self.max_acc_dps2 = acc_dps2.clamp(0.0, physical.1);
    }

    /// Rate and acceleration limits in force, deg/s and deg/s^2.
    pub fn limits(&self) -> (f64, f64) {
        (self.max_rate_dps, self.max_acc_dps2)
    }

    /// The current demand.
    pub fn current_demand(&self) -> AxisDemand {
        self.demand
    }

    /// True while the axis moves or has not reached its demanded position.
    pub fn is_moving(&self) -> bool {
        match self.demand {
            AxisDemand::Position(p) => self.rate_dps != 0.0 || self.pos_deg != p,
            AxisDemand::Rate(r) => r != 0.0 || self.rate_dps != 0.0,
            AxisDemand::Stop => self.rate_dps != 0.0,
        }
    }

    /// Advance by `dt_s` within the rate and acceleration limits.
    pub fn step(&mut self, dt_s: f64) {
        // Turning, and stopping from a turn faster than position moves go,
        // use the rate-mode acceleration; position moves the positioning
        // profile.
        let acc = match self.demand {
            AxisDemand::Rate(_) => self.rate_mode.1,
            AxisDemand::Stop if self.rate_dps.abs() > self.max_rate_dps => self.rate_mode.1,
            AxisDemand::Position(_) | AxisDemand::Stop => self.max_acc_dps2,
        };
        let dv = acc * dt_s;
        let v_target = match self.demand {
            AxisDemand::Rate(r) => r,
            AxisDemand::Stop => 0.0,
            AxisDemand::Position(p) => {
                let err = p - self.pos_deg;
                if err.abs() <= 1e-9 && self.rate_dps.abs() <= dv {
                    self.pos_deg = p;
                    self.rate_dps = 0.0;
                    return;
                }
                // Fastest rate from which we can still brake to a stop at p.
                let brake = (2.0 * self.max_acc_dps2 * err.abs()).sqrt();
                let v = brake.min(self.max_rate_dps).min(err.abs() / dt_s);
                v * err.signum()
            }
        };
        let v_new = self.rate_dps + (v_target - self.rate_dps).clamp(-dv, dv);
        self.pos_deg += 0.5 * (self.rate_dps + v_new) * dt_s;
        self.rate_dps = v_new;
        // A turning axis reads its angle as its encoder does on slip rings:
        // within one turn (the pose is the same).
        if let AxisDemand::Rate(_) = self.demand
            && !(-180.0..180.0).contains(&self.pos_deg)
        {
            self.pos_deg = (self.pos_deg + 180.0).rem_euclid(360.0) - 180.0;
        }
        if let AxisDemand::Stop = self.demand
            && self.rate_dps == 0.0
        {
            self.demand = AxisDemand::Position(self.pos_deg);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn position_move_respects_limits_and_arrives() {
        let mut ax = Axis::at_rest(0.0, 20.0, 10.0);
        ax.demand(AxisDemand::Position(90.0));
        let dt = 1.0 / 400.0;
        let mut t = 0.0;
        let mut last_v: f64 = 0.0;
        while ax.is_moving() && t < 60.0 {
            ax.step(dt);
            assert!(ax.rate_dps.abs() <= 20.0 + 1e-9);
            assert!((ax.rate_dps - last_v).abs() <= 10.0 * dt + 1e-9);
            last_v = ax.rate_dps;
            t += dt;
        }
        assert_eq!(ax.pos_deg, 90.0);
        // Ideal trapezoid: 2 s accelerating, 2.5 s cruising, 2 s braking =
        // 6.5 s; the discrete brake adds a short final creep, never a shortcut.
        assert!((6.5..7.0).contains(&t), "move took {t} s");
    }

    #[test]
    fn stop_decelerates_and_holds() {
        let mut ax = Axis::at_rest(0.0, 20.0, 10.0);
        ax.demand(AxisDemand::Rate(100.0));
        assert_eq!(
            ax.rate_mode_limits(),
            (20.0, 10.0),
            "no rate mode of its own"
        );
        for _ in 0..400 {
            ax.step(0.01);
        }
        assert_eq!(ax.rate_dps, 20.0, "rate demand is clamped to the limit");
        ax.demand(AxisDemand::Stop);
        for _ in 0..300 {
            ax.step(0.01);
        }
        assert_eq!(ax.rate_dps, 0.0);
        assert!(!ax.is_moving());
    }
}
