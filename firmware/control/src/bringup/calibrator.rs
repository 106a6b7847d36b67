//! The routines' state machine ([`Calibrator`]): a routine in progress or
//! the last one's report, its measurements and, for a motor-driving one,
//! the current it asks for each period.

use super::{
    BringupConfig, BringupReport, CalState, CalibrationReport, Regression, Routine, Stats,
    WeighingReport,
};
use crate::hal::RawSample;

/// What a motor-driving routine needs to know of the machine, from the
/// configuration at its start.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveParams {
    /// The routines' limits.
    pub limits: BringupConfig,
    /// Force on the nut per ampere, `eta k_m / r`, N/A.
    pub newtons_per_amp: f32,
    /// Screw ratio `r`, m/rad.
    pub screw_m_per_rad: f32,
    /// The nut's weight `m_s g`, N.
    pub nut_weight_n: f32,
    /// The PD's gains, A/rad and A s/rad (the flight PD's, eq 4.4).
    pub kp_a_per_rad: f32,
    /// See `kp_a_per_rad`.
    pub kd_a_s_per_rad: f32,
    /// The spring rate as configured, N/m (the direction check's scale and
    /// the spring fit's plausibility).
    pub spring_rate_n_per_m: f32,
    /// The nut's stroke, m (the homing move's longest travel beyond it).
    pub stroke_m: f32,
    /// The robot's weight as configured, `(M + m_s) g`, N (the weighing's
    /// reference).
    pub weight_n: f32,
    /// Where homing leaves the nut, m below the stop: where the spring
    /// carries its weight, `max(0, m_s g / k - delta0)` (an unpowered nut
    /// released anywhere else swings on its spring).
    pub park_m: f32,
}

/// One period's converted measurements, for a motor-driving routine.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveInput {
    /// Motor angle, rad.
    pub motor_angle_rad: f32,
    /// Filtered motor rate (eq 4.1), rad/s.
    pub motor_rate_rad_s: f32,
    /// Spring force from the load cell, N.
    pub spring_force_n: f32,
    /// Leg compression from the potentiometer, m.
    pub leg_compression_m: f32,
    /// Body height from its encoder, m.
    pub body_height_m: f32,
    /// The period, s.
    pub dt_s: f32,
}

/// The homing move stalls when the nut is this far behind its reference, m.
pub const STALL_LAG_M: f32 = 5.0e-4;
/// Pushing on the stop this long after the stall before the zero is set, s.
const STALL_PUSH_S: f32 = 0.05;
/// The direction check: baseline, pulse and return times, s.
const DIRECTION_BASELINE_S: f32 = 0.05;
const DIRECTION_PULSE_S: f32 = 0.1;
const DIRECTION_RETURN_S: f32 = 0.3;
/// Smallest nut travel the direction pulse must cause, m.
const DIRECTION_MIN_TRAVEL_M: f32 = 1.0e-4;
/// Holding still after a move before a routine ends, s.
const SETTLE_S: f32 = 0.1;
/// The weighing ignores each half's first this long (the body and the
/// friction's breakaway settling to the steady sweep), s.
const WEIGH_SKIP_S: f32 = 0.25;
/// The weighing's sweep as a fraction of the standing leg compression.
const WEIGH_SWEEP_FRACTION: f32 = 0.6;

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
    /// A motor-driving routine's machine constants (`None`: measuring only).
    drive: Option<DriveParams>,
    /// Time since the routine's first driven period, s.
    t_s: f32,
    /// Where the routine is, and since when, s.
    stage: u8,
    stage_t_s: f32,
    /// The motor angle at the start and the reference the PD tracks, rad.
    theta0_rad: f32,
    theta_ref_rad: f32,
    /// Force statistics: the direction check's baseline and pulse end;
    /// the weighing's lift and lowering.
    force_before: Stats,
    force_after: Stats,
    /// Nut positions pushed on the stop, m.
    at_stop: Stats,
    /// Nut positions while measuring, m (an unpowered nut may swing on its
    /// spring: the tare takes the mean).
    nut: Stats,
    fit: Regression,
    /// Results, NaN where the routine does not measure them.
    travel_m: f32,
    force_change_n: f32,
    nut_offset_m: f32,
    height_offset_m: f32,
    peak_a: f32,
    /// The weighing: the body height at the start and how far it rose, m.
    body_start_m: f32,
    body_rise_m: f32,
    /// A driven routine ended in the last period (the runner acts once).
    ended: bool,
}

impl Default for Calibrator {
    fn default() -> Self {
        Self::new()
    }
}

const NO_STATS: Stats = Stats {
    n: 0,
    mean: 0.0,
    m2: 0.0,
};

impl Calibrator {
    /// Nothing run yet.
    pub const fn new() -> Self {
        Self {
            routine: Routine::SensorCheck,
            state: CalState::Idle,
            wanted: 0,
            loadcell: NO_STATS,
            pot: NO_STATS,
            first: None,
            motor_span: 0,
            height_span: 0,
            offsets: (f32::NAN, f32::NAN),
            drive: None,
            t_s: 0.0,
            stage: 0,
            stage_t_s: 0.0,
            theta0_rad: 0.0,
            theta_ref_rad: 0.0,
            force_before: NO_STATS,
            force_after: NO_STATS,
            at_stop: NO_STATS,
            nut: NO_STATS,
            fit: Regression {
                n: 0,
                mean_x: 0.0,
                mean_y: 0.0,
                cxx: 0.0,
                cxy: 0.0,
                cyy: 0.0,
            },
            travel_m: f32::NAN,
            force_change_n: f32::NAN,
            nut_offset_m: f32::NAN,
            height_offset_m: f32::NAN,
            peak_a: 0.0,
            body_start_m: f32::NAN,
            body_rise_m: f32::NAN,
            ended: false,
        }
    }

    /// Whether a routine is measuring.
    pub fn running(&self) -> bool {
        self.state == CalState::Running
    }

    /// Whether a motor-driving routine is running (the amplifier may be on).
    pub fn driving(&self) -> bool {
        self.running() && self.drive.is_some()
    }

    /// Starts `routine` for `samples` periods (the caller checked the
    /// preconditions). A motor-driving routine needs `drive` (else it
    /// measures only) and ends when its moves are done.
    pub fn start(&mut self, routine: Routine, samples: u32, drive: Option<DriveParams>) {
        *self = Self {
            routine,
            state: CalState::Running,
            wanted: samples.max(2),
            drive: if routine.drives_motor() { drive } else { None },
            ..Self::new()
        };
    }

    /// One period's raw sample (`None`: unreadable); returns whether the
    /// measurement just completed (the caller then finishes it). A
    /// motor-driving routine only keeps the statistics (it ends by
    /// [`Self::drive`]).
    pub fn sample(&mut self, raw: Option<&RawSample>) -> bool {
        if self.state != CalState::Running {
            return false;
        }
        let Some(r) = raw else {
            self.end(CalState::FailedSensors);
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
        self.drive.is_none() && self.loadcell.count() >= self.wanted
    }

    /// One period's converted nut position, m, while measuring.
    pub fn add_nut_position(&mut self, p_m: f32) {
        if self.state == CalState::Running && self.drive.is_none() {
            self.nut.add(p_m);
        }
    }

    /// The mean nut position while measuring, m (NaN before a sample).
    pub fn nut_mean_m(&self) -> f32 {
        if self.nut.count() == 0 {
            f32::NAN
        } else {
            self.nut.mean()
        }
    }

    fn end(&mut self, state: CalState) {
        if self.state == CalState::Running {
            self.ended = self.drive.is_some();
        }
        self.state = state;
    }

    /// Stops a motor-driving routine: a fault latched, the e-stop or a
    /// lost link (the caller has made the output safe).
    pub fn abort(&mut self) {
        if self.driving() {
            self.end(CalState::FailedFault);
        }
    }

    /// Whether a driven routine ended since the last call (once per end).
    pub fn take_ended(&mut self) -> bool {
        core::mem::take(&mut self.ended)
    }

    /// One period of a motor-driving routine on its converted measurements:
    /// the current it asks for, A (within `bringup.current_limit_a`; 0
    /// once it has ended). Out of line: it runs only during bring-up, and
    /// inlined it would crowd the control step's registers.
    #[inline(never)]
    #[cold]
    pub fn drive(&mut self, m: &DriveInput) -> f32 {
        let Some(d) = self.drive else {
            return 0.0;
        };
        if self.state != CalState::Running {
            return 0.0;
        }
        let finite = (m.motor_angle_rad + m.motor_rate_rad_s + m.spring_force_n + m.dt_s)
            .is_finite()
            && (m.leg_compression_m + m.body_height_m).is_finite();
        if !finite {
            self.end(CalState::FailedSensors);
            return 0.0;
        }
        if self.t_s == 0.0 {
            self.theta0_rad = m.motor_angle_rad;
            self.theta_ref_rad = m.motor_angle_rad;
        }
        self.t_s += m.dt_s;
        // What holds the nut against the spring: `eta tau / r = F - m_s g`
        // (the nut's equation with `pdd = 0`), from the measured force.
        let hold_a = (m.spring_force_n - d.nut_weight_n) / d.newtons_per_amp;
        let rate_rad_s = d.limits.speed_mps / d.screw_m_per_rad;
        // The PD of eq 4.4 on the reference and its rate, plus the hold.
        let track = |theta_ref: f32, omega_ref: f32| {
            hold_a
                + d.kp_a_per_rad * (theta_ref - m.motor_angle_rad)
                + d.kd_a_s_per_rad * (omega_ref - m.motor_rate_rad_s)
        };
        let in_stage = self.t_s - self.stage_t_s;
        let i = match self.routine {
            Routine::Direction => self.direction(m, &d, in_stage, track(self.theta0_rad, 0.0)),
            Routine::Home => self
                .home(m, &d, in_stage, rate_rad_s)
                .unwrap_or_else(|(r, w)| track(r, w)),
            Routine::Spring => {
                let (r, w) = self.sweep(m, &d, rate_rad_s);
                track(r, w)
            }
            Routine::Weight => {
                let (r, w) = self.weigh(m, &d, in_stage, rate_rad_s);
                track(r, w)
            }
            _ => 0.0,
        };
        if self.state != CalState::Running {
            return 0.0;
        }
        let lim = d.limits.current_limit_a;
        let i = crate::num::clamp(i, -lim, lim);
        self.peak_a = crate::num::max(self.peak_a, i.abs());
        i
    }

    fn next_stage(&mut self) {
        self.stage += 1;
        self.stage_t_s = self.t_s;
    }

    /// The direction check: a baseline, a pulse down, the verdict, then
    /// back to the start (`back_a`: the PD toward it).
    fn direction(&mut self, m: &DriveInput, d: &DriveParams, in_stage: f32, back_a: f32) -> f32 {
        match self.stage {
            0 => {
                self.force_before.add(m.spring_force_n);
                if in_stage >= DIRECTION_BASELINE_S {
                    self.next_stage();
                }
                0.0
            }
            1 => {
                // The force over the pulse's last 20 ms.
                if in_stage >= DIRECTION_PULSE_S - 0.02 {
                    self.force_after.add(m.spring_force_n);
                }
                if in_stage < DIRECTION_PULSE_S {
                    return d.limits.current_limit_a / 3.0;
                }
                let travel_m = (m.motor_angle_rad - self.theta0_rad) * d.screw_m_per_rad;
                let force_change_n = self.force_after.mean() - self.force_before.mean();
                self.travel_m = travel_m;
                self.force_change_n = force_change_n;
                if travel_m < -DIRECTION_MIN_TRAVEL_M {
                    self.end(CalState::FailedReversed);
                } else if travel_m <= DIRECTION_MIN_TRAVEL_M {
                    self.end(CalState::FailedNoMotion);
                } else if force_change_n < d.spring_rate_n_per_m * travel_m / 3.0 {
                    self.end(CalState::FailedLoadcellReversed);
                } else {
                    self.next_stage();
                }
                0.0
            }
            _ => {
                if in_stage >= DIRECTION_RETURN_S {
                    self.end(CalState::Done);
                }
                back_a
            }
        }
    }

    /// The homing move: `Ok(current)` or `Err((reference, its rate))` for
    /// the PD.
    fn home(
        &mut self,
        m: &DriveInput,
        d: &DriveParams,
        in_stage: f32,
        rate_rad_s: f32,
    ) -> Result<f32, (f32, f32)> {
        let r = d.screw_m_per_rad;
        match self.stage {
            0 => {
                // Up at the set speed until the nut lags its reference: the stop.
                self.theta_ref_rad -= rate_rad_s * m.dt_s;
                let lag_m = (m.motor_angle_rad - self.theta_ref_rad) * r;
                if lag_m > STALL_LAG_M {
                    self.theta_ref_rad = m.motor_angle_rad - STALL_LAG_M / r;
                    self.next_stage();
                    return Err((self.theta_ref_rad, 0.0));
                }
                if (self.theta0_rad - self.theta_ref_rad) * r > d.stroke_m + 0.01 {
                    self.end(CalState::FailedNoStop);
                    return Ok(0.0);
                }
                Err((self.theta_ref_rad, -rate_rad_s))
            }
            1 => {
                // Pushing on the stop: where it is.
                self.at_stop.add(m.motor_angle_rad * r);
                if in_stage >= STALL_PUSH_S {
                    self.nut_offset_m = self.at_stop.mean();
                    self.theta_ref_rad = (self.nut_offset_m + d.park_m) / r;
                    self.next_stage();
                }
                Err((self.theta_ref_rad, 0.0))
            }
            _ => {
                // Parked where the spring carries the nut, then released.
                if in_stage >= 2.0 * SETTLE_S {
                    self.end(CalState::Done);
                    return Ok(0.0);
                }
                Err((self.theta_ref_rad, 0.0))
            }
        }
    }

    /// One period of the sweeps' reference ramp, the spring fit's and the
    /// weighing's: `down` from the start to `bottom_rad`, else back, at
    /// `rate_rad_s`; at either end the reference stops there and the next
    /// stage begins. Returns the reference's rate and whether it just
    /// reached the bottom.
    fn ramp(&mut self, down: bool, bottom_rad: f32, rate_rad_s: f32, dt_s: f32) -> (f32, bool) {
        let w = if down { rate_rad_s } else { -rate_rad_s };
        self.theta_ref_rad += w * dt_s;
        if down && self.theta_ref_rad >= bottom_rad {
            self.theta_ref_rad = bottom_rad;
            self.next_stage();
            return (w, true);
        }
        if !down && self.theta_ref_rad <= self.theta0_rad {
            self.theta_ref_rad = self.theta0_rad;
            self.next_stage();
        }
        (w, false)
    }

    /// The spring sweep's reference (and its rate): down by the sweep, back,
    /// hold; the fit's points on the way.
    fn sweep(&mut self, m: &DriveInput, d: &DriveParams, rate_rad_s: f32) -> (f32, f32) {
        let r = d.screw_m_per_rad;
        let bottom = self.theta0_rad + d.limits.sweep_m / r;
        match self.stage {
            0 | 1 => {
                self.fit.add(
                    m.motor_angle_rad * r + m.leg_compression_m,
                    m.spring_force_n,
                );
                let (w, _) = self.ramp(self.stage == 0, bottom, rate_rad_s, m.dt_s);
                (self.theta_ref_rad, w)
            }
            _ => {
                if self.t_s - self.stage_t_s >= SETTLE_S {
                    let k = self.fit.slope();
                    let k0 = d.spring_rate_n_per_m;
                    let plausible = self.fit.count() >= 100 && k >= 0.5 * k0 && k <= 2.0 * k0;
                    self.end(if plausible {
                        CalState::Done
                    } else {
                        CalState::FailedFit
                    });
                }
                (self.theta0_rad, 0.0)
            }
        }
    }

    /// The weighing's reference (and its rate): the sweep chosen at the
    /// start, down (the body lifted), back up (lowered), hold, verdict; the
    /// force averaged over each half after its first `WEIGH_SKIP_S`.
    fn weigh(
        &mut self,
        m: &DriveInput,
        d: &DriveParams,
        in_stage: f32,
        rate_rad_s: f32,
    ) -> (f32, f32) {
        let r = d.screw_m_per_rad;
        match self.stage {
            0 => {
                // Standing, the leg is compressed by about the weight's
                // deflection less the preload: half the deflection at
                // least, else the toe is off the ground.
                let x0 = m.leg_compression_m;
                if x0.is_nan() || x0 < 0.5 * d.weight_n / d.spring_rate_n_per_m {
                    self.end(CalState::FailedNotOnGround);
                    return (self.theta0_rad, 0.0);
                }
                self.travel_m = crate::num::clamp(WEIGH_SWEEP_FRACTION * x0, 0.0, d.limits.sweep_m);
                self.body_start_m = m.body_height_m;
                self.next_stage();
                (self.theta0_rad, 0.0)
            }
            1 | 2 => {
                let down = self.stage == 1;
                if in_stage >= WEIGH_SKIP_S {
                    if down {
                        self.force_before.add(m.spring_force_n);
                    } else {
                        self.force_after.add(m.spring_force_n);
                    }
                }
                let bottom = self.theta0_rad + self.travel_m / r;
                let (w, at_bottom) = self.ramp(down, bottom, rate_rad_s, m.dt_s);
                if at_bottom {
                    self.body_rise_m = m.body_height_m - self.body_start_m;
                }
                (self.theta_ref_rad, w)
            }
            _ => {
                if in_stage >= SETTLE_S {
                    let w = self.measured_weight_n();
                    let enough =
                        self.force_before.count() >= 100 && self.force_after.count() >= 100;
                    let rise = self.body_rise_m;
                    let state = if rise.is_nan() || rise < 0.5 * self.travel_m {
                        CalState::FailedBodyHeld
                    } else if enough && w >= 0.5 * d.weight_n && w <= 2.0 * d.weight_n {
                        CalState::Done
                    } else {
                        CalState::FailedWeight
                    };
                    self.end(state);
                }
                (self.theta0_rad, 0.0)
            }
        }
    }

    /// The weighing's weight: the mean of the lift's and the lowering's
    /// mean forces, N (NaN before both halves have samples).
    fn measured_weight_n(&self) -> f32 {
        if self.force_before.count() == 0 || self.force_after.count() == 0 {
            f32::NAN
        } else {
            0.5 * (self.force_before.mean() + self.force_after.mean())
        }
    }

    /// The weighing's weight as measured against the configured one: the
    /// load cell's gain relative to its calibration (NaN unless the last
    /// routine was a weighing that measured both halves).
    pub fn weight_gain(&self) -> f32 {
        match (self.routine, self.drive) {
            (Routine::Weight, Some(d)) => self.measured_weight_n() / d.weight_n,
            _ => f32::NAN,
        }
    }

    /// What the last weighing found (NaN where it did not measure, state
    /// idle when the last routine was another).
    pub fn weighing(&self) -> WeighingReport {
        let weighed = self.routine == Routine::Weight;
        let nan_unless = |ok: bool, x: f32| if ok { x } else { f32::NAN };
        let halves = self.force_before.count() > 0 && self.force_after.count() > 0;
        WeighingReport {
            state: if weighed { self.state } else { CalState::Idle },
            weight_n: nan_unless(weighed, self.measured_weight_n()),
            configured_weight_n: match self.drive {
                Some(d) if weighed => d.weight_n,
                _ => f32::NAN,
            },
            friction_n: nan_unless(
                weighed && halves,
                0.5 * (self.force_before.mean() - self.force_after.mean()),
            ),
            body_rise_m: nan_unless(weighed, self.body_rise_m),
        }
    }

    /// Ends the measurement: a counter that moved more than its allowance
    /// (motor, height) fails it; otherwise it is done, with `offsets` (load
    /// cell, pot; a tare's, NaN otherwise). Returns whether it is done.
    pub fn finish(&mut self, still_counts: (u32, u32), offsets: (f32, f32)) -> bool {
        if self.state != CalState::Running {
            return false;
        }
        if self.motor_span > still_counts.0 || self.height_span > still_counts.1 {
            self.state = CalState::FailedMoving;
            return false;
        }
        self.offsets = offsets;
        self.state = CalState::Done;
        true
    }

    /// Marks the routine failed with `state` (its results were not
    /// applied: out of range, or the toe not on the ground).
    pub fn fail(&mut self, state: CalState) {
        self.state = state;
        self.offsets = (f32::NAN, f32::NAN);
    }

    /// Marks the routine failed because its results could not be applied.
    pub fn apply_failed(&mut self) {
        self.fail(CalState::FailedApply);
    }

    /// Records the height routine's correction, m.
    pub fn set_height_offset(&mut self, offset_m: f32) {
        self.height_offset_m = offset_m;
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

    /// Where the homing move found the stop in the encoder's old frame, m
    /// (NaN before).
    pub const fn nut_offset_m(&self) -> f32 {
        self.nut_offset_m
    }

    /// The spring sweep's fit.
    pub const fn fit(&self) -> &Regression {
        &self.fit
    }

    /// What it measured (so far, while running).
    pub fn report(&self) -> CalibrationReport {
        CalibrationReport {
            routine: self.routine,
            state: self.state,
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

    /// What the motor-driving and height routines found (NaN where the
    /// routine does not measure a value).
    pub fn results(&self) -> BringupReport {
        let fitted = self.routine == Routine::Spring && self.fit.count() >= 2;
        let nan_unless = |ok: bool, x: f32| if ok { x } else { f32::NAN };
        BringupReport {
            routine: self.routine,
            state: self.state,
            nut_travel_m: self.travel_m,
            force_change_n: self.force_change_n,
            nut_offset_m: self.nut_offset_m,
            spring_rate_n_per_m: nan_unless(fitted, self.fit.slope()),
            spring_intercept_n: nan_unless(fitted, self.fit.intercept()),
            fit_rms_n: nan_unless(fitted, self.fit.residual_rms()),
            fit_points: self.fit.count(),
            fit_span_m: nan_unless(fitted, self.fit.x_std()),
            height_offset_m: self.height_offset_m,
            peak_current_a: self.peak_a,
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
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
        c.start(Routine::SensorCheck, 4, None);
        for (i, lc) in [200u16, 204, 196, 200].into_iter().enumerate() {
            let done = c.sample(Some(&raw(lc, 100, u32::MAX, 7)));
            assert_eq!(done, i == 3);
        }
        assert!(c.finish((0, 0), (f32::NAN, f32::NAN)));
        let r = c.report();
        assert_eq!(r.state, CalState::Done);
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
        c.start(Routine::Tare, 3, None);
        c.sample(Some(&raw(200, 100, u32::MAX - 1, 0)));
        c.sample(Some(&raw(200, 100, 2, 0)));
        c.sample(Some(&raw(200, 100, 1, 0)));
        assert!(!c.finish((2, 2), (1.0, 2.0)));
        let r = c.report();
        assert_eq!(r.state, CalState::FailedMoving);
        assert_eq!(r.motor_span_counts, 4);
        assert!(r.loadcell_offset_code.is_nan());
    }

    #[test]
    fn an_unreadable_sample_fails_it() {
        let mut c = Calibrator::new();
        c.start(Routine::SensorCheck, 10, None);
        c.sample(Some(&raw(1, 1, 0, 0)));
        assert!(!c.sample(None));
        assert_eq!(c.state(), CalState::FailedSensors);
        assert!(!c.finish((0, 0), (0.0, 0.0)));
    }

    fn params() -> DriveParams {
        DriveParams {
            limits: BringupConfig::default(),
            newtons_per_amp: 33.6,
            screw_m_per_rad: 7.957_747e-4,
            nut_weight_n: 2.45,
            kp_a_per_rad: 20.3,
            kd_a_s_per_rad: 0.6,
            spring_rate_n_per_m: 11_000.0,
            stroke_m: 0.05,
            weight_n: 95.0,
            park_m: 2.2e-4,
        }
    }

    /// A direction check on a scripted nut: `travel` m and `force` N at
    /// the pulse's end.
    fn direction_on(travel_m: f32, force_n: f32) -> CalState {
        let d = params();
        let mut c = Calibrator::new();
        c.start(Routine::Direction, 10, Some(d));
        for i in 0..10_000 {
            let t = i as f32 * 1e-4;
            let (theta, f) = if t < DIRECTION_BASELINE_S {
                (0.0, 0.0)
            } else {
                (travel_m / d.screw_m_per_rad, force_n)
            };
            c.drive(&DriveInput {
                motor_angle_rad: theta,
                motor_rate_rad_s: 0.0,
                spring_force_n: f,
                leg_compression_m: 0.0,
                body_height_m: 0.6,
                dt_s: 1e-4,
            });
            if !c.running() {
                break;
            }
        }
        assert!(c.take_ended() && !c.take_ended());
        c.state()
    }

    #[test]
    fn the_direction_verdicts() {
        // 0.8 mm down and the spring's 8.8 N: right.
        assert_eq!(direction_on(8e-4, 8.8), CalState::Done);
        assert_eq!(direction_on(-8e-4, -8.8), CalState::FailedReversed);
        assert_eq!(direction_on(5e-5, 0.5), CalState::FailedNoMotion);
        // Down, but the load cell reads a third of k dp or less (or less).
        assert_eq!(direction_on(8e-4, -8.8), CalState::FailedLoadcellReversed);
        assert_eq!(direction_on(8e-4, 2.9), CalState::FailedLoadcellReversed);
        assert_eq!(direction_on(8e-4, 3.0), CalState::Done);
    }

    #[test]
    fn homing_with_no_stop_gives_up_after_the_stroke() {
        // A nut that follows its reference exactly never lags: no stop.
        let d = params();
        let mut c = Calibrator::new();
        c.start(Routine::Home, 10, Some(d));
        let mut theta = 0.0;
        let mut periods = 0u32;
        while c.running() && periods < 200_000 {
            c.drive(&DriveInput {
                motor_angle_rad: theta,
                motor_rate_rad_s: 0.0,
                spring_force_n: 0.0,
                leg_compression_m: 0.0,
                body_height_m: 0.6,
                dt_s: 1e-4,
            });
            theta -= d.limits.speed_mps / d.screw_m_per_rad * 1e-4;
            periods += 1;
        }
        assert_eq!(c.state(), CalState::FailedNoStop);
        // 60 mm at 5 mm/s.
        assert!((periods as f32 * 1e-4 - 12.0).abs() < 0.01, "{periods}");
    }

    /// A weighing on a scripted standing robot: the nut follows the PD
    /// (half its correction a period); standing (`held` false) the body
    /// rises with the nut and the spring carries `weight + friction`
    /// lifting, `weight - friction` lowering; held, the spring is
    /// compressed by the nut instead. Returns the verdict and the info.
    fn weigh_on(
        x0_m: f32,
        weight_n: f32,
        friction_n: f32,
        held: bool,
    ) -> (CalState, WeighingReport) {
        let d = params();
        let r = d.screw_m_per_rad;
        let mut c = Calibrator::new();
        c.start(Routine::Weight, 10, Some(d));
        let (mut theta, mut last) = (0.0f32, 0.0f32);
        for _ in 0..100_000 {
            let dp_m = (theta - last) * r;
            let p_m = theta * r;
            let force = if held {
                weight_n + d.spring_rate_n_per_m * p_m
            } else if dp_m > 1e-9 {
                weight_n + friction_n
            } else if dp_m < -1e-9 {
                weight_n - friction_n
            } else {
                weight_n
            };
            let rise = if held { 0.0 } else { p_m };
            let a = c.drive(&DriveInput {
                motor_angle_rad: theta,
                // (The rate unmeasured: the scripted nut has no dynamics
                // for the PD's damping to act on.)
                motor_rate_rad_s: 0.0,
                spring_force_n: force,
                leg_compression_m: x0_m - rise,
                body_height_m: 0.6 + rise,
                dt_s: 1e-4,
            });
            if !c.running() {
                break;
            }
            let hold_a = (force - d.nut_weight_n) / d.newtons_per_amp;
            last = theta;
            theta += 0.5 * (a - hold_a) / d.kp_a_per_rad;
        }
        (c.state(), c.weighing())
    }

    #[test]
    fn the_weighing_reads_weight_and_friction_and_its_verdicts() {
        // 5% light against the configured 95 N, 8 N of friction, 6.6 mm
        // standing compression: a 3.96 mm sweep.
        let (s, w) = weigh_on(6.6e-3, 90.25, 8.0, false);
        assert_eq!(s, CalState::Done, "{w:?}");
        assert!((w.weight_n - 90.25).abs() < 0.05, "{w:?}");
        assert!((w.friction_n - 8.0).abs() < 0.05, "{w:?}");
        assert_eq!(w.configured_weight_n, 95.0);
        // (The scripted nut leads its reference by the PD's damping term.)
        assert!((w.body_rise_m - 3.96e-3).abs() < 0.2e-3, "{w:?}");
        // Hoisted: the leg is not compressed.
        assert_eq!(
            weigh_on(0.0, 12.0, 0.0, false).0,
            CalState::FailedNotOnGround
        );
        assert_eq!(
            weigh_on(4.0e-3, 95.0, 0.0, false).0,
            CalState::FailedNotOnGround
        );
        // The body held: it does not rise.
        assert_eq!(
            weigh_on(6.6e-3, 95.0, 0.0, true).0,
            CalState::FailedBodyHeld
        );
        // Far off the configured weight.
        assert_eq!(weigh_on(6.6e-3, 40.0, 0.0, false).0, CalState::FailedWeight);
        assert_eq!(
            weigh_on(6.6e-3, 200.0, 0.0, false).0,
            CalState::FailedWeight
        );
        // Another routine since: no weighing to report.
        let mut c = Calibrator::new();
        c.start(Routine::Tare, 10, None);
        let w = c.weighing();
        assert_eq!(w.state, CalState::Idle);
        assert!(w.weight_n.is_nan() && c.weight_gain().is_nan());
    }

    proptest! {
        /// Any measurements, however wild: the drive asks for a finite
        /// current within the routines' limit, and never panics.
        #[test]
        fn drive_is_bounded_on_any_input(
            routine in proptest::sample::select(std::vec![2u8, 3, 4, 6]),
            inputs in proptest::collection::vec(
                (-1e6f32..1e6, -1e6f32..1e6, -1e5f32..1e5, -1.0f32..1.0), 1..300),
            nan_at in proptest::option::of(0usize..300),
        ) {
            let mut c = Calibrator::new();
            let routine = Routine::from_code(routine).unwrap_or(Routine::Home);
            c.start(routine, 10, Some(params()));
            for (i, &(theta, omega, f, x)) in inputs.iter().enumerate() {
                let f = if nan_at == Some(i) { f32::NAN } else { f };
                let was_running = c.running();
                let a = c.drive(&DriveInput {
                    motor_angle_rad: theta,
                    motor_rate_rad_s: omega,
                    spring_force_n: f,
                    leg_compression_m: x,
                    body_height_m: 0.6 - x,
                    dt_s: 1e-4,
                });
                prop_assert!(a.is_finite() && a.abs() <= 6.0, "{a}");
                // (A weighing off the ground ends at its first period.)
                if nan_at == Some(i) && was_running {
                    prop_assert_eq!(c.state(), CalState::FailedSensors);
                }
            }
        }
    }
}
