//! Bring-up routines the firmware runs on command while disarmed (issue
//! 18), `hopper-link calibrate ...`: they measure with the amplifier off
//! and report what they measured.
//!
//! - [`Routine::SensorCheck`]: raw codes of the load cell and the
//!   potentiometer, their noise (standard deviation), and whether the
//!   encoder counters stayed still;
//! - [`Routine::Tare`]: the same with the leg unloaded (the robot held up,
//!   the toe free), then the load cell's offset such that it reads the
//!   flight force `k (delta0 + p)` and the potentiometer's such that it
//!   reads 0, applied as the `calibration.loadcell_offset_code` and
//!   `calibration.pot_offset_code` parameters.
//!
//! Each refuses to start while armed or with the e-stop pressed, and fails
//! when an encoder counter moves during it (the robot is not still: the
//! averages would be of a moving leg). The period runner feeds it the raw
//! samples; the statistics are Welford's running mean and variance in
//! `f32`, a few operations a period.
//!
//! Not yet: nut homing, the direction check, the spring sweep and the
//! height-encoder zero (they drive the motor), and saving the results to
//! flash.

use crate::hal::RawSample;

/// What a routine does (the discriminant is the wire code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Routine {
    /// Raw codes, noise and still counters, amplifier off.
    SensorCheck = 0,
    /// Load-cell tare and potentiometer zero with the leg unloaded.
    Tare = 1,
}

impl Routine {
    /// From its wire code.
    pub const fn from_code(code: u8) -> Option<Routine> {
        match code {
            0 => Some(Routine::SensorCheck),
            1 => Some(Routine::Tare),
            _ => None,
        }
    }

    /// Kebab-case name.
    pub const fn name(self) -> &'static str {
        match self {
            Routine::SensorCheck => "sensors",
            Routine::Tare => "tare",
        }
    }
}

/// Why a routine did not start.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalRefusal {
    /// The amplifier is armed: routines run disarmed.
    Armed,
    /// The e-stop is pressed.
    EstopPressed,
    /// Another routine is running.
    Busy,
    /// No such routine.
    Unknown,
    /// The duration is not within 0.01..=10 s.
    Duration,
}

impl CalRefusal {
    /// Kebab-case name, as the link prints it.
    pub const fn name(self) -> &'static str {
        match self {
            CalRefusal::Armed => "disarm-first",
            CalRefusal::EstopPressed => "estop-pressed",
            CalRefusal::Busy => "busy",
            CalRefusal::Unknown => "unknown-routine",
            CalRefusal::Duration => "bad-duration",
        }
    }
}

/// Running mean and variance (Welford).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stats {
    n: u32,
    mean: f32,
    m2: f32,
}

impl Stats {
    /// Adds one value.
    #[inline]
    pub fn add(&mut self, x: f32) {
        self.n = self.n.saturating_add(1);
        let d = x - self.mean;
        self.mean += d / self.n as f32;
        self.m2 += d * (x - self.mean);
    }

    /// Values added.
    pub const fn count(&self) -> u32 {
        self.n
    }

    /// Their mean (0 before any).
    pub const fn mean(&self) -> f32 {
        self.mean
    }

    /// Their sample standard deviation (0 below two values).
    pub fn std(&self) -> f32 {
        if self.n < 2 {
            0.0
        } else {
            libm::sqrtf(crate::num::max(self.m2, 0.0) / (self.n - 1) as f32)
        }
    }
}

/// Where a routine is (the discriminant is the wire code).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum CalState {
    /// Nothing has run since boot.
    Idle,
    /// Measuring.
    Running,
    /// Finished; the report holds what it measured (and, for a tare, the
    /// new offsets are applied).
    Done,
    /// An encoder moved while measuring: nothing applied.
    FailedMoving,
    /// The sensors could not be read while measuring: nothing applied.
    FailedSensors,
    /// The new offsets were refused by the parameter table (out of range):
    /// nothing applied.
    FailedApply,
}

impl CalState {
    /// Every state, by wire code.
    pub const ALL: [CalState; 6] = [
        CalState::Idle,
        CalState::Running,
        CalState::Done,
        CalState::FailedMoving,
        CalState::FailedSensors,
        CalState::FailedApply,
    ];

    /// Kebab-case name.
    pub const fn name(self) -> &'static str {
        match self {
            CalState::Idle => "idle",
            CalState::Running => "running",
            CalState::Done => "done",
            CalState::FailedMoving => "failed: an encoder moved (hold the robot still)",
            CalState::FailedSensors => "failed: the sensors could not be read",
            CalState::FailedApply => "failed: the new offsets are out of the parameters' ranges",
        }
    }
}

/// A routine in progress, or the last one's report.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Calibrator {
    routine: Routine,
    state: CalState,
    wanted: u32,
    loadcell: Stats,
    pot: Stats,
    first: Option<(u32, u32)>,
    motor_span: u32,
    height_span: u32,
    offsets: (f32, f32),
}

impl Default for Calibrator {
    fn default() -> Self {
        Self::new()
    }
}

impl Calibrator {
    /// Nothing run yet.
    pub const fn new() -> Self {
        Self {
            routine: Routine::SensorCheck,
            state: CalState::Idle,
            wanted: 0,
            loadcell: Stats {
                n: 0,
                mean: 0.0,
                m2: 0.0,
            },
            pot: Stats {
                n: 0,
                mean: 0.0,
                m2: 0.0,
            },
            first: None,
            motor_span: 0,
            height_span: 0,
            offsets: (f32::NAN, f32::NAN),
        }
    }

    /// Whether a routine is measuring.
    pub fn running(&self) -> bool {
        self.state == CalState::Running
    }

    /// Starts `routine` for `samples` periods (the caller checked the
    /// preconditions).
    pub fn start(&mut self, routine: Routine, samples: u32) {
        *self = Self {
            routine,
            state: CalState::Running,
            wanted: samples.max(2),
            ..Self::new()
        };
    }

    /// One period's raw sample (`None`: unreadable); returns whether the
    /// measurement just completed (the caller then finishes it).
    pub fn sample(&mut self, raw: Option<&RawSample>) -> bool {
        if self.state != CalState::Running {
            return false;
        }
        let Some(r) = raw else {
            self.state = CalState::FailedSensors;
            return false;
        };
        self.loadcell.add(f32::from(r.loadcell_code));
        self.pot.add(f32::from(r.pot_code));
        let (m0, h0) = *self.first.get_or_insert((r.motor_counts, r.height_counts));
        let span = |now: u32, first: u32| {
            let d = now.wrapping_sub(first) as i32;
            d.unsigned_abs()
        };
        self.motor_span = self.motor_span.max(span(r.motor_counts, m0));
        self.height_span = self.height_span.max(span(r.height_counts, h0));
        self.loadcell.count() >= self.wanted
    }

    /// Ends the measurement: a counter that moved fails it; otherwise it is
    /// done, with `offsets` (load cell, pot; a tare's, NaN otherwise).
    /// Returns whether it is done.
    pub fn finish(&mut self, still_counts: u32, offsets: (f32, f32)) -> bool {
        if self.state != CalState::Running {
            return false;
        }
        if self.motor_span > still_counts || self.height_span > still_counts {
            self.state = CalState::FailedMoving;
            return false;
        }
        self.offsets = offsets;
        self.state = CalState::Done;
        true
    }

    /// Marks the routine failed because its results could not be applied.
    pub fn apply_failed(&mut self) {
        self.state = CalState::FailedApply;
        self.offsets = (f32::NAN, f32::NAN);
    }

    /// The routine being measured.
    pub const fn routine(&self) -> Routine {
        self.routine
    }

    /// The load cell's mean code so far.
    pub const fn loadcell_mean_code(&self) -> f32 {
        self.loadcell.mean
    }

    /// The potentiometer's mean code so far.
    pub const fn pot_mean_code(&self) -> f32 {
        self.pot.mean
    }

    /// Where it is.
    pub const fn state(&self) -> CalState {
        self.state
    }

    /// What it measured (so far, while running), as the link sends it.
    pub fn report(&self) -> hopper_protocol::CalibrationInfo {
        hopper_protocol::CalibrationInfo {
            routine: self.routine as u8,
            state: self.state as u8,
            samples: self.loadcell.count(),
            loadcell_mean_code: self.loadcell.mean(),
            loadcell_std_code: self.loadcell.std(),
            pot_mean_code: self.pot.mean(),
            pot_std_code: self.pot.std(),
            motor_span_counts: self.motor_span,
            height_span_counts: self.height_span,
            loadcell_offset_code: self.offsets.0,
            pot_offset_code: self.offsets.1,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn raw(lc: u16, pot: u16, m: u32, h: u32) -> RawSample {
        RawSample {
            motor_counts: m,
            height_counts: h,
            loadcell_code: lc,
            pot_code: pot,
            estop_pressed: false,
            amp_fault: false,
        }
    }

    #[test]
    fn mean_and_noise_of_still_sensors() {
        let mut c = Calibrator::new();
        c.start(Routine::SensorCheck, 4);
        for (i, lc) in [200u16, 204, 196, 200].into_iter().enumerate() {
            let done = c.sample(Some(&raw(lc, 100, u32::MAX, 7)));
            assert_eq!(done, i == 3);
        }
        assert!(c.finish(0, (f32::NAN, f32::NAN)));
        let r = c.report();
        assert_eq!(r.state, CalState::Done as u8);
        assert_eq!(r.samples, 4);
        assert_eq!(r.loadcell_mean_code, 200.0);
        // Sample std of 0, 4, -4, 0: sqrt(32 / 3).
        assert!((r.loadcell_std_code - libm::sqrtf(32.0 / 3.0)).abs() < 1e-5);
        assert_eq!(r.pot_std_code, 0.0);
        assert_eq!((r.motor_span_counts, r.height_span_counts), (0, 0));
    }

    #[test]
    fn a_moving_encoder_fails_it_across_the_wrap() {
        let mut c = Calibrator::new();
        c.start(Routine::Tare, 3);
        c.sample(Some(&raw(200, 100, u32::MAX - 1, 0)));
        c.sample(Some(&raw(200, 100, 2, 0)));
        c.sample(Some(&raw(200, 100, 1, 0)));
        assert!(!c.finish(2, (1.0, 2.0)));
        let r = c.report();
        assert_eq!(r.state, CalState::FailedMoving as u8);
        assert_eq!(r.motor_span_counts, 4);
        assert!(r.loadcell_offset_code.is_nan());
    }

    #[test]
    fn an_unreadable_sample_fails_it() {
        let mut c = Calibrator::new();
        c.start(Routine::SensorCheck, 10);
        c.sample(Some(&raw(1, 1, 0, 0)));
        assert!(!c.sample(None));
        assert_eq!(c.state(), CalState::FailedSensors);
        assert!(!c.finish(0, (0.0, 0.0)));
    }

    proptest! {
        /// Welford's mean and deviation agree with the two-pass ones.
        #[test]
        fn stats_match_two_pass(xs in proptest::collection::vec(0u16..4096, 2..500)) {
            let mut s = Stats::default();
            for &x in &xs {
                s.add(f32::from(x));
            }
            let n = xs.len() as f64;
            let mean = xs.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
            let var = xs.iter().map(|&x| (f64::from(x) - mean).powi(2)).sum::<f64>() / (n - 1.0);
            prop_assert!((f64::from(s.mean()) - mean).abs() < 1e-3 * (1.0 + mean));
            prop_assert!((f64::from(s.std()) - var.sqrt()).abs() < 1e-2 * (1.0 + var.sqrt()));
        }
    }
}
