//! The bring-up routines in the runner ([`crate::bringup`]): starting one
//! (only disarmed, its preconditions checked), its completion (a measuring
//! routine's samples, a motor-driving one's end) and its results applied
//! to the configuration through a controller built outside the control
//! period and installed at a period boundary.

use super::{HopperSlot, Owned, PeriodRunner, SetError, Then};
use crate::hopper::HopperConfig;
use crate::params::{self, Param, ParamError};

/// One result of a routine: the configuration field it sets, with its
/// new value. Set by field, not through the parameter table by name: a
/// routine knows which field it measured, and the table's entry is only
/// its range.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Change {
    /// `calibration.loadcell_offset_code`, code (the tare).
    LoadcellOffset(f32),
    /// `calibration.pot_offset_code`, code (the tare).
    PotOffset(f32),
    /// `calibration.loadcell_gain_n_per_code`, N/code (the weighing).
    LoadcellGain(f32),
    /// `supervisor.spring_rate_n_per_m`, N/m (the spring sweep, the
    /// weighing).
    SpringRate(f32),
}

impl Change {
    /// Sets its field of `cfg`, if the value is within its parameter's
    /// range (else nothing changes: the refusal a set by name gives).
    fn apply(self, cfg: &mut HopperConfig) -> Result<(), SetError> {
        let checked = |p: &Param, v: f32| {
            p.check(v)
                .map_err(|f| SetError::Param(ParamError::OutOfRange(f.0)))
        };
        match self {
            Change::LoadcellOffset(v) => {
                cfg.calibration.loadcell_offset_code = checked(&params::CAL_LOADCELL_OFFSET, v)?;
            }
            Change::PotOffset(v) => {
                cfg.calibration.pot_offset_code = checked(&params::CAL_POT_OFFSET, v)?;
            }
            Change::LoadcellGain(v) => {
                cfg.calibration.loadcell_gain_n_per_code = checked(&params::CAL_LOADCELL_GAIN, v)?;
            }
            Change::SpringRate(v) => {
                cfg.supervisor.spring_rate_n_per_m = checked(&params::SUP_SPRING_RATE, v)?;
            }
        }
        Ok(())
    }
}

/// A routine's results: up to two fields and their new values.
pub type Changes = [Option<Change>; 2];

impl PeriodRunner<Owned> {
    /// `cfg` with a routine's changes.
    pub fn apply_changes(cfg: &HopperConfig, changes: &Changes) -> Result<HopperConfig, SetError> {
        let mut new = *cfg;
        for c in changes.iter().flatten() {
            c.apply(&mut new)?;
        }
        Ok(new)
    }
}

impl<H: HopperSlot> PeriodRunner<H> {
    /// Whether a bring-up routine is running.
    pub fn calibrating(&self) -> bool {
        self.cal.running() || self.rebuild_outstanding
    }

    /// Starts a bring-up routine ([`crate::bringup`]) for `seconds` of
    /// periods (a motor-driving one ends when its moves are done): only
    /// disarmed, with the e-stop released, one at a time; one that drives
    /// the motor also needs no latched fault and a live link, homing a
    /// passed direction check and the spring sweep a homed nut.
    pub fn start_calibration(
        &mut self,
        routine: crate::bringup::Routine,
        seconds: f32,
    ) -> Result<(), crate::bringup::CalRefusal> {
        use crate::bringup::{CalRefusal, DriveParams, Routine};
        if self.arming.is_armed() {
            return Err(CalRefusal::Armed);
        }
        if self.hopper.estop_pressed() {
            return Err(CalRefusal::EstopPressed);
        }
        if self.calibrating() {
            return Err(CalRefusal::Busy);
        }
        if !(0.01..=10.0).contains(&seconds) {
            return Err(CalRefusal::Duration);
        }
        let drive = if routine.drives_motor() {
            if self.hopper.supervisor().is_faulted() {
                return Err(CalRefusal::Faulted);
            }
            if !self.arming.link_alive() {
                return Err(CalRefusal::LinkDown);
            }
            if routine == Routine::Home && !self.arming.direction_ok() {
                return Err(CalRefusal::DirectionFirst);
            }
            if matches!(routine, Routine::Spring | Routine::Weight) && !self.arming.homed() {
                return Err(CalRefusal::HomeFirst);
            }
            let cfg = self.hopper.config();
            // The weighing reads forces through the offset: a tare's (or a
            // saved one), unless the configuration says its offsets hold.
            if routine == Routine::Weight && cfg.arming.require_tare && !self.arming.tared() {
                return Err(CalRefusal::TareFirst);
            }
            let m = &cfg.model;
            let r = m.screw_m_per_rad();
            Some(DriveParams {
                limits: cfg.bringup,
                newtons_per_amp: m.efficiency * m.torque_constant_nm_per_a / r,
                screw_m_per_rad: r,
                nut_weight_n: m.nut_mass_kg * m.gravity_mps2,
                kp_a_per_rad: cfg.flight.gains.kp,
                kd_a_s_per_rad: cfg.flight.gains.kd,
                spring_rate_n_per_m: cfg.supervisor.spring_rate_n_per_m,
                stroke_m: m.stroke_m,
                weight_n: (m.body_mass_kg + m.nut_mass_kg) * m.gravity_mps2,
                park_m: crate::num::max(
                    0.0,
                    m.nut_mass_kg * m.gravity_mps2 / cfg.supervisor.spring_rate_n_per_m
                        - cfg.supervisor.spring_preload_m,
                ),
            })
        } else {
            None
        };
        // After the order's prerequisites (direction, home, tare first):
        // where the toe is, is the last thing to fix before it runs.
        if let Some(stance) = routine.stance() {
            self.check_stance(stance)?;
        }
        let samples = (seconds / self.timing.period_s) as u32;
        self.cal.start(routine, samples, drive);
        Ok(())
    }

    /// Refuses a routine whose measurement assumes the toe where the
    /// sensors say it is not, read through the calibration as it stands:
    /// the load cell's force beyond the flight force `k (delta0 + p)` at
    /// the nut's position (what the leg carries), and the potentiometer's
    /// compression. A tare on a standing robot would take its weight for
    /// the zero (and the firmware would then see flight while it stands);
    /// so the toe counts as loaded only when both sensors say so, by half
    /// the body's weight and half its spring deflection (an offset a tare
    /// has yet to correct is far smaller), and as on the ground when the
    /// load cell carries half the weight (the height zero's own check).
    fn check_stance(
        &self,
        stance: crate::bringup::Stance,
    ) -> Result<(), crate::bringup::CalRefusal> {
        use crate::bringup::{CalRefusal, Stance};
        let Some(i) = self.hopper.last_input() else {
            return Err(CalRefusal::NoMeasurementYet);
        };
        let cfg = self.hopper.config();
        let s = &cfg.supervisor;
        let weight_n = cfg.model.body_mass_kg * cfg.model.gravity_mps2;
        let carried_n = i.spring_force_n - s.flight_force_n(i.nut_position_m);
        let carries = carried_n > 0.5 * weight_n;
        let compressed = i.leg_compression_m > 0.5 * weight_n / s.spring_rate_n_per_m;
        match stance {
            Stance::Free if carries && compressed => Err(CalRefusal::LegLoaded),
            Stance::OnGround if !carries => Err(CalRefusal::NotOnGround),
            _ => Ok(()),
        }
    }

    /// The last bring-up routine's report.
    pub fn calibration(&self) -> crate::bringup::CalibrationReport {
        self.cal.report()
    }

    /// What the last bring-up routine found.
    pub fn bringup_results(&self) -> crate::bringup::BringupReport {
        self.cal.results()
    }

    /// What the last weighing found.
    pub fn weighing(&self) -> crate::bringup::WeighingReport {
        self.cal.weighing()
    }

    /// A measuring routine's samples are complete: check, compute, apply.
    pub(super) fn finish_calibration(&mut self) {
        use crate::bringup::{CalState, Routine};
        // The body still: a count of quantisation flicker at most. The
        // nut, unpowered, may swing on its spring (it has no brake; a
        // frictionless simulated screw swings for ever): up to 2 mm, its
        // mean position is what the averages were taken at (the spring is
        // linear: the mean force is that of the mean position).
        const STILL_COUNTS: u32 = 1;
        const NUT_SWING_M: f32 = 2.0e-3;
        // Copies of the few constants used (the 408-byte configuration is
        // not copied in the control period).
        let cfg = self.hopper.config();
        let c = cfg.calibration;
        let s = cfg.supervisor;
        let (body_mass_kg, gravity_mps2, leg_length_m) = (
            cfg.model.body_mass_kg,
            cfg.model.gravity_mps2,
            cfg.model.leg_length_m,
        );
        // (The count's size: negative with the encoder counting up.)
        let nut_swing_counts = ((NUT_SWING_M / c.nut_m_per_count()).abs() as u32).max(STILL_COUNTS);
        let last = self.hopper.last_input().copied();
        let p_m = self.cal.nut_mean_m();
        let p_m = if p_m.is_finite() { p_m } else { 0.0 };
        let offsets = match self.cal.routine() {
            Routine::Tare => {
                // Unloaded leg: the load cell must read the flight force
                // k (delta0 + p) at the nut's position, the pot 0.
                let force_n = s.flight_force_n(p_m);
                (
                    self.cal.loadcell_mean_code() - force_n / c.loadcell_gain_n_per_code,
                    self.cal.pot_mean_code(),
                )
            }
            _ => (f32::NAN, f32::NAN),
        };
        if !self.cal.finish((nut_swing_counts, STILL_COUNTS), offsets) {
            return;
        }
        match self.cal.routine() {
            Routine::Tare => self.request_rebuild(
                [
                    Some(Change::LoadcellOffset(offsets.0)),
                    Some(Change::PotOffset(offsets.1)),
                ],
                Then::Tared,
            ),
            Routine::Height => {
                // Toe on the ground: the load cell carries the robot beyond
                // the flight force (half its weight at least: friction
                // holds the rest at worst), and then `z = l0 - x`.
                let force_n = (self.cal.loadcell_mean_code() - c.loadcell_offset_code)
                    * c.loadcell_gain_n_per_code;
                let x_m = (self.cal.pot_mean_code() - c.pot_offset_code) * c.pot_gain_m_per_code;
                let weight_n = body_mass_kg * gravity_mps2;
                let carried_n = force_n - s.flight_force_n(p_m);
                let Some(z_m) = last.map(|i| i.body_height_m) else {
                    self.cal.fail(CalState::FailedSensors);
                    return;
                };
                if carried_n.is_nan() || carried_n <= 0.5 * weight_n {
                    self.cal.fail(CalState::FailedNotOnGround);
                    return;
                }
                let offset_m = leg_length_m - x_m - z_m;
                self.request_rebuild([None, None], Then::Height(offset_m));
            }
            _ => {}
        }
    }

    /// A motor-driving routine ended (the amplifier is off from this
    /// period on): its verdict to arming, its results applied.
    pub(super) fn finish_drive(&mut self) {
        use crate::bringup::{CalState, Routine};
        let state = self.cal.state();
        match self.cal.routine() {
            Routine::Direction => match state {
                CalState::Done => self.arming.note_direction(false),
                CalState::FailedReversed | CalState::FailedLoadcellReversed => {
                    self.arming.note_direction(true)
                }
                _ => {}
            },
            Routine::Home if state == CalState::Done => {
                // The stop is the zero from now on.
                self.request_rebuild([None, None], Then::Homed(self.cal.nut_offset_m()));
            }
            Routine::Spring if state == CalState::Done => self.request_rebuild(
                [Some(Change::SpringRate(self.cal.fit().slope())), None],
                Then::Fitted,
            ),
            Routine::Weight if state == CalState::Done => {
                // The load cell read the weight `gain` times too much: its
                // gain, and the spring rate fitted through it, are that
                // much too high. The tare's offset (in codes) stays: the
                // flight force it was set to read scales with the rate.
                let gain = self.cal.weight_gain();
                let old = self.hopper.config();
                let changes = [
                    Some(Change::LoadcellGain(
                        old.calibration.loadcell_gain_n_per_code / gain,
                    )),
                    Some(Change::SpringRate(
                        old.supervisor.spring_rate_n_per_m / gain,
                    )),
                ];
                self.request_rebuild(changes, Then::Fitted);
            }
            _ => {}
        }
    }

    /// A routine's results, for a controller built outside the period: it
    /// counts as running until [`install`](Self::install)ed.
    fn request_rebuild(&mut self, changes: Changes, then: Then) {
        self.rebuild_request = Some((changes, then));
        self.rebuild_outstanding = true;
    }

    /// The rebuild a finished routine asks for, once: the lower-priority
    /// task applies the changes to its copy of the configuration
    /// ([`PeriodRunner::apply_changes`]) and prepares the controller
    /// ([`PeriodRunner::prepare_at`]), and the control period
    /// [`install`](Self::install)s it.
    pub fn take_rebuild_request(&mut self) -> Option<(Changes, Then)> {
        // (Checked first: `take` would copy the whole option every period.)
        if self.rebuild_request.is_some() {
            self.rebuild_request.take()
        } else {
            None
        }
    }

    /// A routine's rebuild could not be built (its configuration is
    /// refused): the routine fails, nothing changes.
    pub fn rebuild_failed(&mut self) {
        if self.rebuild_outstanding {
            self.rebuild_outstanding = false;
            self.cal.apply_failed();
        }
    }

    /// Builds and installs a routine's rebuild at once, where nothing runs
    /// at a lower priority (the host's tests and runs without a link).
    pub fn serve_rebuild(&mut self) {
        if let Some((changes, then)) = self.take_rebuild_request() {
            let prepared = PeriodRunner::apply_changes(self.hopper.config(), &changes)
                .and_then(|cfg| PeriodRunner::prepare_at(cfg, self.config_gen));
            match prepared {
                Ok(p) => {
                    let _ = self.install_value(p, then);
                }
                Err(_) => self.rebuild_failed(),
            }
        }
    }

    /// A routine's install completes it (or fails it).
    pub(super) fn routine_done(&mut self, result: Result<(), SetError>, then: Then) {
        if matches!(then, Then::Param(_)) {
            return;
        }
        self.rebuild_outstanding = false;
        match (result, then) {
            (Ok(()), Then::Tared) => self.arming.note_tared(),
            (Ok(()), Then::Homed(_)) => self.arming.note_homed(),
            (Ok(()), Then::Height(m)) => self.cal.set_height_offset(m),
            (Ok(()), _) => {}
            (Err(_), _) => self.cal.apply_failed(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::Io;
    use super::super::{NoCounter, Timing};
    use super::*;

    #[test]
    fn a_tare_applies_the_offsets_it_measured_and_only_disarmed() {
        use crate::bringup::{CalRefusal, CalState, Routine};
        let cal = HopperConfig::default().calibration;
        let mut rest = crate::proptest_support::rest_sample(&cal);
        // The load cell reads 24 codes high, the pot 17.
        rest.loadcell_code += 24;
        rest.pot_code += 17;
        let mut r = PeriodRunner::new(HopperConfig::default(), Timing::default())
            .unwrap_or_else(|e| panic!("{e:?}"));
        let mut io = Io::new(rest);
        // Before the first sample the e-stop counts as pressed.
        assert_eq!(
            r.start_calibration(Routine::Tare, 0.05),
            Err(CalRefusal::EstopPressed)
        );
        r.arming_mut().link_frame();
        r.run_period(&mut io, &mut NoCounter);
        assert_eq!(
            r.start_calibration(Routine::Tare, 20.0),
            Err(CalRefusal::Duration)
        );
        assert_eq!(r.start_calibration(Routine::Tare, 0.05), Ok(()));
        assert_eq!(
            r.start_calibration(Routine::Tare, 0.05),
            Err(CalRefusal::Busy)
        );
        for _ in 0..501 {
            r.arming_mut().link_frame();
            r.run_period(&mut io, &mut NoCounter);
        }
        let rep = r.calibration();
        assert_eq!(rep.state, CalState::Done, "{rep:?}");
        assert_eq!(rep.samples, 500);
        // Its results wait for a controller built outside the period:
        // nothing arms or starts until it is installed.
        assert!(r.calibrating());
        assert_eq!(r.hopper().config().calibration, cal);
        assert_eq!(
            r.start_calibration(Routine::Tare, 0.05),
            Err(CalRefusal::Busy)
        );
        r.serve_rebuild();
        assert!(!r.calibrating());
        // The rebuilt controller's velocity filters measure after two
        // periods.
        for _ in 0..2 {
            r.arming_mut().link_frame();
            r.run_period(&mut io, &mut NoCounter);
        }
        let c = r.hopper().config().calibration;
        assert_eq!(c.loadcell_offset_code, cal.loadcell_offset_code + 24.0);
        assert_eq!(c.pot_offset_code, cal.pot_offset_code + 17.0);
        assert_eq!(rep.loadcell_offset_code, c.loadcell_offset_code);
        // Armed: refused.
        r.arming_mut().link_frame();
        r.arming_mut().request_arm();
        r.run_period(&mut io, &mut NoCounter);
        assert!(r.arming().is_armed());
        assert_eq!(
            r.start_calibration(Routine::SensorCheck, 0.05),
            Err(CalRefusal::Armed)
        );
    }
}
