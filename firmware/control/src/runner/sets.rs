//! Runtime parameter sets in the runner: a set planned and its controller
//! prepared outside the control period ([`Prepared`]), installed at a period
//! boundary (the slots exchanged, the state carried over), the target apex
//! changed in place while armed, and the configuration's generation that
//! tells a stale preparation from a current one.

use super::{HopperSlot, Owned, PeriodRunner, RunnerError};
use crate::arming::Arming;
use crate::hopper::{Hopper, HopperConfig};

/// Why [`PeriodRunner::set_param`] refused a set (nothing changed).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SetError {
    /// Unknown name, out of range or the wrong type, or a constant of a
    /// controller that is not selected.
    Param(crate::params::ParamError),
    /// The parameter may be set only while disarmed.
    WhileArmed(&'static str),
    /// Nothing may be set while a bring-up routine runs.
    Calibrating,
    /// The new configuration as a whole is refused (a cross-field rule).
    Config(RunnerError),
    /// The configuration changed since the new one was built from it (it
    /// would undo that change): nothing installed; ask again.
    Stale,
}

/// A controller built and validated from a configuration outside the
/// control period ([`PeriodRunner::prepare_at`], the expensive part of a
/// parameter set: every field's check and the controller's constants),
/// installed at a period boundary by [`PeriodRunner::install`] (the slots
/// exchanged, the state carried over).
#[derive(Debug, Clone)]
pub struct Prepared<H = Owned> {
    hopper: H,
    arming: crate::arming::ArmingConfig,
    feed: crate::watchdog::FeedConfig,
    /// The configuration generation it was built from
    /// ([`PeriodRunner::config_gen`]).
    base_gen: u32,
}

impl<H: HopperSlot> Prepared<H> {
    /// The configuration it holds.
    pub fn config(&self) -> &HopperConfig {
        self.hopper.config()
    }
}

impl<H: HopperSlot> Prepared<H> {
    /// Its slot (a set refused before it was installed gives it back).
    pub fn into_slot_handle(self) -> H {
        self.hopper
    }
}

impl Prepared<Owned> {
    /// Into a slot of another kind (`spare`, for a bank's; `None` when
    /// a bank's has none).
    pub fn into_slot<H: HopperSlot>(self, spare: Option<H>) -> Option<Prepared<H>> {
        let Prepared {
            hopper,
            arming,
            feed,
            base_gen,
        } = self;
        H::fill(spare, hopper.0).map(|hopper| Prepared {
            hopper,
            arming,
            feed,
            base_gen,
        })
    }
}

/// What the bring-up verdicts rest on, to compare across an install (a
/// few words, not the 408-byte configuration, in the control period).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Verdicts {
    /// The direction check and homing: the encoder's sign and count, the
    /// screw's lead.
    direction: (bool, u32, f32),
    /// The tare: the load cell's and the potentiometer's gains and offsets.
    tare: [f32; 4],
}

impl Verdicts {
    fn of(cfg: &HopperConfig) -> Self {
        let c = &cfg.calibration;
        Verdicts {
            direction: (
                c.motor_counts_positive_down,
                c.motor_counts_per_rev,
                cfg.model.screw_lead_m,
            ),
            tare: [
                c.loadcell_gain_n_per_code,
                c.loadcell_offset_code,
                c.pot_gain_m_per_code,
                c.pot_offset_code,
            ],
        }
    }
}

/// What an [`install`](PeriodRunner::install) completes.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Then {
    /// A parameter set from the host: only disarmed and with no routine
    /// running; the bring-up verdicts it invalidates are forgotten.
    Param(&'static crate::params::Param),
    /// A tare's new offsets: the tare counts for arming.
    Tared,
    /// The homing's new zero, the stop's position in the old one, m: the
    /// nut counts as homed.
    Homed(f32),
    /// The height routine's correction of the body height, m.
    Height(f32),
    /// A fitted constant (the spring rate, the load cell's gain).
    Fitted,
}

impl PeriodRunner<Owned> {
    /// Whether [`set_param`](PeriodRunner::set_param) takes `p` while
    /// armed: only the target apex, which changes in place (anything else
    /// rebuilds the controller).
    pub fn settable_while_armed(p: &crate::params::Param) -> bool {
        p.name == crate::params::TARGET_APEX_M.name
    }

    /// `cfg` with `name` set to `value` (no state: where the set is
    /// checked, outside the control period), and the parameter.
    pub fn plan_set(
        cfg: &HopperConfig,
        name: &str,
        value: f32,
    ) -> Result<(&'static crate::params::Param, HopperConfig), SetError> {
        let p =
            crate::params::find(name).ok_or(SetError::Param(crate::params::ParamError::Unknown))?;
        let mut new = *cfg;
        crate::params::set(&mut new, p.name, value).map_err(SetError::Param)?;
        Ok((p, new))
    }

    /// Validates `cfg` and builds its controller, as of configuration
    /// generation `base_gen` ([`PeriodRunner::config_gen`]): the costly half
    /// of a set, for a lower-priority task (the link task's copy of the
    /// configuration and its generation).
    pub fn prepare_at(cfg: HopperConfig, base_gen: u32) -> Result<Prepared, SetError> {
        let arming =
            Arming::new(cfg.arming).map_err(|e| SetError::Config(RunnerError::Arming(e)))?;
        let hopper = Hopper::new(cfg).map_err(|e| SetError::Config(RunnerError::Config(e)))?;
        Ok(Prepared {
            hopper: Owned(hopper),
            arming: *arming.config(),
            feed: crate::watchdog::FeedConfig::for_hopper(&cfg),
            base_gen,
        })
    }
}

impl<H: HopperSlot> PeriodRunner<H> {
    /// Sets a runtime parameter by its table name ([`crate::params`]),
    /// between periods (the application calls it from the control task
    /// between two [`run_period`](Self::run_period)s, so it applies at a
    /// period boundary). While armed only the target apex may change (in
    /// place); everything else needs the runner disarmed, and then the
    /// controller is rebuilt from the new configuration with the latched
    /// faults carried over (a set never clears a latch) and the arming
    /// state kept. The whole new configuration is checked before anything
    /// changes: a refused set changes nothing.
    pub fn set_param(&mut self, name: &str, value: f32) -> Result<(), SetError> {
        if crate::params::find(name).is_some() && self.calibrating() {
            // A routine's loop was built on the configuration it started
            // with (a flipped encoder sign would turn its PD around).
            return Err(SetError::Calibrating);
        }
        let (p, cfg) = PeriodRunner::plan_set(self.hopper.config(), name, value)?;
        if self.arming.is_armed() {
            if !PeriodRunner::settable_while_armed(p) {
                return Err(SetError::WhileArmed(p.name));
            }
            return self.set_live(p, value);
        }
        let prepared = PeriodRunner::prepare_at(cfg, self.config_gen)?;
        self.install_value(prepared, Then::Param(p))
    }

    /// A parameter that changes in place ([`settable_while_armed`](Self::settable_while_armed)),
    /// armed or not: a few operations, fit for the control period.
    pub fn set_live(
        &mut self,
        p: &'static crate::params::Param,
        value: f32,
    ) -> Result<(), SetError> {
        if !PeriodRunner::settable_while_armed(p) {
            return Err(SetError::WhileArmed(p.name));
        }
        self.hopper
            .set_target_apex(value)
            .map_err(|_| SetError::Param(crate::params::ParamError::OutOfRange(p.name)))?;
        self.config_gen = self.config_gen.wrapping_add(1);
        Ok(())
    }

    /// The configuration's generation: bumped by every change
    /// ([`install`](Self::install), [`set_live`](Self::set_live)).
    pub fn config_gen(&self) -> u32 {
        self.config_gen
    }

    /// Installs a prepared controller between periods by exchanging its
    /// slot with the running one's (a few words for a bank's slots),
    /// carrying the state that must survive over
    /// ([`Hopper::continue_from`]): bounded and the same every time.
    /// Refused (nothing changes) when the configuration changed since it
    /// was prepared, and for a host's set while armed or while a routine
    /// runs. Gives back the slot not in use: the old one, or the refused.
    pub fn install(&mut self, mut new: Prepared<H>, then: Then) -> (Result<(), SetError>, H) {
        let result = self.check_install(new.base_gen, then).map(|()| {
            let old = Verdicts::of(self.hopper.config());
            new.hopper.continue_from(&self.hopper);
            Self::shift(&mut new.hopper, then);
            core::mem::swap(&mut self.hopper, &mut new.hopper);
            self.installed(&old, new.arming, new.feed, then);
        });
        self.routine_done(result, then);
        (result, new.hopper)
    }

    /// [`install`](Self::install) of a controller held by value, copied
    /// into the running slot (boot, and runs with no lower-priority task:
    /// the host's tests, [`set_param`](Self::set_param)).
    pub fn install_value(&mut self, new: Prepared, then: Then) -> Result<(), SetError> {
        let result = self.check_install(new.base_gen, then).map(|()| {
            let old = Verdicts::of(self.hopper.config());
            let mut h = new.hopper.0;
            h.continue_from(&self.hopper);
            Self::shift(&mut h, then);
            *self.hopper = h;
            self.installed(&old, new.arming, new.feed, then);
        });
        self.routine_done(result, then);
        result
    }

    fn check_install(&self, base_gen: u32, then: Then) -> Result<(), SetError> {
        if base_gen != self.config_gen {
            return Err(SetError::Stale);
        }
        if let Then::Param(p) = then {
            if self.arming.is_armed() {
                return Err(SetError::WhileArmed(p.name));
            }
            if self.calibrating() {
                return Err(SetError::Calibrating);
            }
        }
        Ok(())
    }

    /// A routine's new origin moves the measurements: on the new
    /// controller, whose filters start from it (on the running one they
    /// would see a jump).
    fn shift(h: &mut Hopper, then: Then) {
        match then {
            Then::Homed(nut_m) => h.shift_origin(nut_m, 0.0),
            Then::Height(m) => h.shift_origin(0.0, m),
            _ => {}
        }
    }

    fn installed(
        &mut self,
        old: &Verdicts,
        arming: crate::arming::ArmingConfig,
        feed: crate::watchdog::FeedConfig,
        then: Then,
    ) {
        self.unsettled = 2;
        self.arming.reconfigure(arming);
        self.feed.reconfigure(feed);
        self.config_gen = self.config_gen.wrapping_add(1);
        if matches!(then, Then::Param(_)) {
            let new = Verdicts::of(self.hopper.config());
            // What the bring-up verdicts were made on, changed by hand: they
            // no longer hold (a flipped encoder sign, another lead or count).
            if new.direction != old.direction {
                self.arming.forget_direction_and_home();
            }
            if new.tare != old.tare {
                self.arming.forget_tare();
            }
        }
    }

    /// Rebuilds the controller from `cfg` at once (boot, before the first
    /// period); nothing changes if `cfg` is refused.
    pub(super) fn rebuild(&mut self, cfg: HopperConfig) -> Result<(), SetError> {
        let prepared = PeriodRunner::prepare_at(cfg, self.config_gen)?;
        let result = self.check_install(prepared.base_gen, Then::Fitted);
        result.map(|()| {
            let old = Verdicts::of(self.hopper.config());
            let mut h = prepared.hopper.0;
            h.continue_from(&self.hopper);
            *self.hopper = h;
            self.installed(&old, prepared.arming, prepared.feed, Then::Fitted);
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::tests::{runner, Io};
    use super::*;
    use crate::hopper::Strategy;
    use crate::runner::NoCounter;
    use crate::supervisor::Fault;

    #[test]
    fn parameter_sets_are_checked_and_applied_between_periods() {
        use crate::params;
        let mut r = runner(Strategy::default());
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        assert!(r.run_period(&mut io, &mut NoCounter).armed);
        let before = *r.hopper().config();
        // Armed: the target apex changes in place, nothing else may.
        assert_eq!(r.set_param(params::TARGET_APEX_M.name, 0.12), Ok(()));
        assert_eq!(r.hopper().config().target_apex_m, 0.12);
        assert_eq!(
            r.set_param(params::CONTROLLER.name, 8.0),
            Err(SetError::WhileArmed(params::CONTROLLER.name))
        );
        // Refused sets change nothing, armed or not.
        for (name, v) in [
            (params::TARGET_APEX_M.name, 1.5),
            (params::TARGET_APEX_M.name, f32::NAN),
            ("no.such", 1.0),
        ] {
            let cfg = *r.hopper().config();
            assert!(r.set_param(name, v).is_err(), "{name} = {v}");
            assert_eq!(*r.hopper().config(), cfg);
        }
        assert!(matches!(
            r.set_param("no.such", 1.0),
            Err(SetError::Param(crate::params::ParamError::Unknown))
        ));
        // Disarmed: a latched fault survives a controller change.
        r.arming_mut().request_disarm();
        r.report_overrun();
        // The body moves 2 counts a period (a slow settle) for 20 periods.
        let mut p = r.run_period(&mut io, &mut NoCounter);
        for _ in 0..20 {
            io.raw.height_counts += 2;
            p = r.run_period(&mut io, &mut NoCounter);
        }
        assert!(!p.armed && p.out.faults.contains(Fault::Overrun));
        let (height_m, step) = (p.out.record.body_height_m, p.out.record.step);
        assert_eq!(r.set_param(params::CONTROLLER.name, 8.0), Ok(()));
        assert_eq!(r.hopper().config().strategy.kind().name(), "shaped");
        assert!(r.hopper().supervisor().faults().contains(Fault::Overrun));
        let p = r.run_period(&mut io, &mut NoCounter);
        assert!(p.feed_watchdog && p.newly_latched.is_empty());
        // The rebuilt controller goes on from the old one: the encoders'
        // origin (the same body height, not re-zeroed where it stands) and
        // the step count.
        assert_eq!(p.out.record.body_height_m, height_m);
        assert_eq!(p.out.record.step, step + 1);
        assert_eq!(io.enabled, Some(false));
        assert_ne!(*r.hopper().config(), before);
    }
}
