//! Time for everything else in the crate.
//!
//! Nothing outside this module reads the system time. Simulated benches run on
//! a [`VirtualClock`] that jumps forward as fast as the machine allows or is
//! paced at a speed factor; real devices run on a [`WallClock`].

use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// A source of run time, in seconds since the clock's epoch (the run start).
pub trait Clock: Send + Sync {
    /// Seconds since the epoch of this clock.
    fn now_s(&self) -> f64;

    /// Block the calling thread until the clock reads at least `t_s`.
    ///
    /// A virtual clock moves its time to `t_s` (pacing itself against the
    /// wall when it has a speed factor); a wall clock sleeps.
    fn sleep_until(&self, t_s: f64);

    /// True when time here is simulated rather than physical.
    fn is_virtual(&self) -> bool;
}

/// How a virtual clock relates to the wall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// Jump straight to the requested time.
    Max,
    /// Run `factor` times faster than real time (1.0 = real time).
    Factor(f64),
}

/// Simulated time, held as whole nanoseconds so that it never drifts by
/// rounding however many small steps are taken.
#[derive(Debug)]
pub struct VirtualClock {
    nanos: AtomicU64,
    pacing: Pacing,
    /// Wall instant and virtual time at which pacing was anchored.
    anchor: Mutex<Option<(Instant, u64)>>,
}

impl VirtualClock {
    /// A virtual clock at t = 0 with the given pacing.
    pub fn new(pacing: Pacing) -> Self {
        Self {
            nanos: AtomicU64::new(0),
            pacing,
            anchor: Mutex::new(None),
        }
    }

    /// Advance by `dt_s` seconds (negative or NaN steps are ignored).
    pub fn advance(&self, dt_s: f64) {
        self.sleep_until(self.now_s() + dt_s);
    }

    /// How long the wall must wait until this clock, paced, may read
    /// `t_s` (none at full speed or when that time is already due). An
    /// async caller awaits it (`tokio::time::sleep`) before
    /// [`Clock::sleep_until`], which then moves the time without blocking.
    pub fn wall_wait(&self, t_s: f64) -> Option<Duration> {
        if !t_s.is_finite() {
            return None;
        }
        let target = (t_s.max(0.0) * 1e9).round() as u64;
        if target <= self.nanos.load(Ordering::Relaxed) {
            return None;
        }
        let due = self.due(target)?;
        due.checked_duration_since(Instant::now())
            .filter(|d| !d.is_zero())
    }

    /// The wall instant virtual time `target_ns` is due at (none at full
    /// speed).
    fn due(&self, target_ns: u64) -> Option<Instant> {
        let Pacing::Factor(factor) = self.pacing else {
            return None;
        };
        if !(factor.is_finite() && factor > 0.0) {
            return None;
        }
        let (start, start_ns) = {
            let mut anchor = self.anchor.lock().unwrap_or_else(|p| p.into_inner());
            *anchor.get_or_insert_with(|| (Instant::now(), self.nanos.load(Ordering::Relaxed)))
        };
        let virtual_elapsed = target_ns.saturating_sub(start_ns) as f64 * 1e-9;
        // A factor so small that the wait overflows a Duration or an
        // Instant waits as long as one can (a year at a time), never panics.
        let wait = Duration::try_from_secs_f64(virtual_elapsed / factor)
            .unwrap_or(Duration::from_secs(365 * 86_400));
        Some(
            start
                .checked_add(wait)
                .unwrap_or_else(|| Instant::now() + Duration::from_secs(365 * 86_400)),
        )
    }

    fn pace(&self, target_ns: u64) {
        let Some(due) = self.due(target_ns) else {
            return;
        };
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
    }
}

impl Clock for VirtualClock {
    fn now_s(&self) -> f64 {
        self.nanos.load(Ordering::Relaxed) as f64 * 1e-9
    }

    fn sleep_until(&self, t_s: f64) {
        if !t_s.is_finite() {
            return;
        }
        let target = (t_s.max(0.0) * 1e9).round() as u64;
        if target <= self.nanos.load(Ordering::Relaxed) {
            return;
        }
        self.pace(target);
        self.nanos.fetch_max(target, Ordering::Relaxed);
    }

    fn is_virtual(&self) -> bool {
        true
    }
}

/// Physical time from the monotonic clock, for runs on real devices;
/// optionally sped up (a simulated bench served to real drivers at N x).
#[derive(Debug)]
pub struct WallClock {
    start: Instant,
    speed: f64,
}

impl WallClock {
    /// A wall clock whose epoch is now.
    pub fn start() -> Self {
        Self::scaled(1.0)
    }

    /// A clock running `speed` times faster than the wall (non-positive or
    /// non-finite speeds mean real time).
    pub fn scaled(speed: f64) -> Self {
        Self {
            start: Instant::now(),
            speed: if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            },
        }
    }
}

impl Clock for WallClock {
    fn now_s(&self) -> f64 {
        self.start.elapsed().as_secs_f64() * self.speed
    }

    fn sleep_until(&self, t_s: f64) {
        let now = self.now_s();
        if t_s.is_finite() && t_s > now {
            let wait = Duration::try_from_secs_f64((t_s - now) / self.speed)
                .unwrap_or(Duration::from_secs(365 * 86_400));
            std::thread::sleep(wait);
        }
    }

    fn is_virtual(&self) -> bool {
        self.speed != 1.0
    }
}

/// The current UTC date and time, for the start time logged with a run.
pub fn utc_now() -> chrono::DateTime<chrono::Utc> {
    chrono::Utc::now()
}

/// Wall time elapsed since it was started (for flushing logs every second
/// of wall time whatever the device time does).
#[derive(Debug, Clone, Copy)]
pub struct Stopwatch(Instant);

impl Stopwatch {
    /// Start now.
    pub fn start() -> Self {
        Self(Instant::now())
    }

    /// Seconds since start.
    pub fn elapsed_s(&self) -> f64 {
        self.0.elapsed().as_secs_f64()
    }

    /// Seconds since start, and restart.
    pub fn lap_s(&mut self) -> f64 {
        let e = self.elapsed_s();
        self.0 = Instant::now();
        e
    }
}

/// Wall-clock seconds taken by `f`, for benchmarks that report speed.
pub fn time_it<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let start = Instant::now();
    let out = f();
    (out, start.elapsed().as_secs_f64())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_paced_clock_says_how_long_to_wait_and_a_free_one_never_waits() {
        let paced = VirtualClock::new(Pacing::Factor(100.0));
        let w = paced.wall_wait(10.0).expect("10 s at 100x: a wait");
        assert!(
            w > Duration::from_millis(80) && w <= Duration::from_millis(100),
            "{w:?}"
        );
        assert_eq!(paced.wall_wait(0.0), None, "now is due");
        assert_eq!(VirtualClock::new(Pacing::Max).wall_wait(10.0), None);
    }

    #[test]
    fn virtual_clock_jumps_without_waiting_and_never_goes_back() {
        let clock = VirtualClock::new(Pacing::Max);
        let ((), wall) = time_it(|| clock.sleep_until(36_000.0));
        assert_eq!(clock.now_s(), 36_000.0);
        assert!(wall < 1.0, "a max-speed virtual clock must not sleep");
        clock.sleep_until(10.0);
        assert_eq!(clock.now_s(), 36_000.0);
    }

    #[test]
    fn many_small_steps_do_not_accumulate_rounding() {
        let clock = VirtualClock::new(Pacing::Max);
        for _ in 0..400_000 {
            clock.advance(1.0 / 400.0);
        }
        assert!((clock.now_s() - 1000.0).abs() < 1e-3);
    }

    #[test]
    fn paced_clock_waits_for_the_wall() {
        let clock = VirtualClock::new(Pacing::Factor(100.0));
        let ((), wall) = time_it(|| clock.sleep_until(5.0));
        // 5 s of device time at 100x takes at least 50 ms of wall time.
        assert!(wall >= 0.045, "paced clock returned after {wall} s");
        assert_eq!(clock.now_s(), 5.0);
    }
}
