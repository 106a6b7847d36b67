//! When to feed the independent watchdog: the decision, without the register.
//!
//! The board's IWDG (`hopper-app`'s `board::Watchdog`, about 5 ms, i.e. 50
//! periods at 10 kHz) resets the MCU when it is not fed; after a reset the
//! amplifier-enable pin is an input again and the external pull-down turns the
//! amplifier off. [`FeedPolicy`] decides, once per control period, whether the
//! control task may feed it. It is pure and `no_std`, so the decision is
//! unit-tested on the host; the application only turns [`Decision::Feed`]
//! into the register write.
//!
//! # The policy
//!
//! 1. **Only a completed step earns a feed.** The application asks the
//!    policy right after `Hopper::run_period` wrote the DAC and the enable,
//!    from the control task only. A control task that stops running (hung
//!    higher-priority code, a dead clock, a HardFault loop, an interrupt that
//!    fires without fresh samples and returns early) never asks, so the
//!    watchdog times out: missing periods are the IWDG's own job (50 periods),
//!    a few missed or late ones are the supervisor's (`overrun`).
//! 2. **A latched fault keeps the watchdog fed.** The supervisor holds the
//!    safe state (0 A, the zero-current DAC code, `AMP_EN` low) in software
//!    from the latching period on, and a reset would gain nothing: it would
//!    throw away the latch (RAM) and the telemetry capture of the last 256
//!    periods, the evidence of what happened, and a firmware that restarts
//!    after a reset would run the controller again. Keeping the MCU alive and
//!    safe is what the fault latch is for.
//! 3. **Stop feeding for good when the step's output contradicts itself**
//!    ([`StarveReason`]): a command that is not finite or over the current
//!    limit, a DAC code out of range, a latched fault with anything but the
//!    safe output, or a latch that cleared without the application resetting
//!    it. None of these can happen in a correct build (the fuzz target in
//!    `fuzz/` hunts for them); if one does, the software can no longer be
//!    trusted to hold the amplifier off, and the hardware reset is the one
//!    path left that does. The decision latches: later good periods do not
//!    feed again.
//!
//! After a watchdog reset the firmware must come up with a fault latched
//! (`board::Watchdog::caused_last_reset`), so a reset never restarts hopping
//! by itself.

use crate::hopper::{HopperConfig, StepOutput};

/// What the policy needs from the configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FeedConfig {
    /// The zero-current DAC code (what a faulted period must write).
    pub dac_zero_code: u16,
    /// Largest DAC code, `2^dac_bits - 1`.
    pub dac_max_code: u16,
    /// The supervisor's current limit, A (`|command| <=` this).
    pub current_limit_a: f32,
}

impl FeedConfig {
    /// The values `cfg`'s calibration and supervisor use.
    pub fn for_hopper(cfg: &HopperConfig) -> Self {
        let bits = u32::from(cfg.calibration.dac_bits.clamp(1, 16));
        let max = (1u32 << bits) - 1;
        Self {
            dac_zero_code: cfg.calibration.dac_zero_code,
            dac_max_code: u16::try_from(max).unwrap_or(u16::MAX),
            current_limit_a: cfg.model.usable_current_limit_a(),
        }
    }
}

/// What one completed control period wrote (from [`StepOutput`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PeriodOutput {
    /// Some fault is latched after this period.
    pub faulted: bool,
    /// The amplifier enable written.
    pub amp_enable: bool,
    /// The approved current command, A.
    pub current_a: f32,
    /// The DAC code written.
    pub dac_code: u16,
}

impl From<&StepOutput> for PeriodOutput {
    fn from(out: &StepOutput) -> Self {
        Self {
            faulted: !out.faults.is_empty(),
            amp_enable: out.command.amp_enable,
            current_a: out.command.current_a,
            dac_code: out.dac_code,
        }
    }
}

/// Why the policy stopped feeding.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StarveReason {
    /// The command was not finite, or over the current limit, or the DAC
    /// code was above the DAC's range.
    CommandOutOfRange,
    /// A fault was latched but the output was not 0 A, the zero-current code
    /// and the amplifier disabled.
    UnsafeWhileFaulted,
    /// The fault latch cleared without [`FeedPolicy::fault_reset`].
    LatchCleared,
}

/// The decision for one period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Decision {
    /// Reload the watchdog.
    Feed,
    /// Do not reload it (ever again): the MCU resets within the timeout.
    /// The application should also write the zero code and drop the enable.
    Starve(StarveReason),
}

/// The feed decision, one call per completed control period. See the
/// [module documentation](self).
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FeedPolicy {
    cfg: FeedConfig,
    faulted: bool,
    starved: Option<StarveReason>,
}

impl FeedPolicy {
    /// The same policy (its fault and starve state kept) for a new
    /// configuration: a runtime parameter set that rebuilt the controller.
    pub fn reconfigure(&mut self, cfg: FeedConfig) {
        self.cfg = cfg;
    }

    /// A policy that has seen no period yet.
    pub const fn new(cfg: FeedConfig) -> Self {
        Self {
            cfg,
            faulted: false,
            starved: None,
        }
    }

    /// [`new`](Self::new) with [`FeedConfig::for_hopper`].
    pub fn for_hopper(cfg: &HopperConfig) -> Self {
        Self::new(FeedConfig::for_hopper(cfg))
    }

    /// The decision after a control period that ran and wrote `out`.
    pub fn after_period(&mut self, out: &PeriodOutput) -> Decision {
        if let Some(r) = self.starved {
            return Decision::Starve(r);
        }
        let verdict = self.check(out);
        self.faulted |= out.faulted;
        match verdict {
            Some(r) => {
                self.starved = Some(r);
                Decision::Starve(r)
            }
            None => Decision::Feed,
        }
    }

    /// [`after_period`](Self::after_period) for a [`StepOutput`] (what
    /// `Hopper::run_period` returns).
    pub fn after_step(&mut self, out: &StepOutput) -> Decision {
        self.after_period(&PeriodOutput::from(out))
    }

    /// The application cleared the supervisor's faults on purpose
    /// (`Supervisor::reset` succeeded): a fault-free period is expected again.
    /// Does not undo a starve decision.
    pub fn fault_reset(&mut self) {
        self.faulted = false;
    }

    /// Why the policy stopped feeding, if it did.
    pub fn starved(&self) -> Option<StarveReason> {
        self.starved
    }

    fn check(&self, out: &PeriodOutput) -> Option<StarveReason> {
        let c = &self.cfg;
        if !(out.current_a.is_finite() && out.current_a.abs() <= c.current_limit_a)
            || out.dac_code > c.dac_max_code
        {
            return Some(StarveReason::CommandOutOfRange);
        }
        if self.faulted && !out.faulted {
            return Some(StarveReason::LatchCleared);
        }
        if out.faulted
            && (out.amp_enable || out.current_a != 0.0 || out.dac_code != c.dac_zero_code)
        {
            return Some(StarveReason::UnsafeWhileFaulted);
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::hopper::Hopper;

    fn policy() -> FeedPolicy {
        FeedPolicy::for_hopper(&HopperConfig::default())
    }

    const RUNNING: PeriodOutput = PeriodOutput {
        faulted: false,
        amp_enable: true,
        current_a: 12.5,
        dac_code: 2688,
    };
    const SAFE: PeriodOutput = PeriodOutput {
        faulted: true,
        amp_enable: false,
        current_a: 0.0,
        dac_code: 2048,
    };

    #[test]
    fn config_follows_the_hopper() {
        let c = FeedConfig::for_hopper(&HopperConfig::default());
        assert_eq!(c.dac_zero_code, 2048);
        assert_eq!(c.dac_max_code, 4095);
        let limit = HopperConfig::default().model.usable_current_limit_a();
        assert_eq!(c.current_limit_a, limit);
    }

    #[test]
    fn feeds_while_running_and_while_safely_faulted() {
        let mut p = policy();
        for _ in 0..100 {
            assert_eq!(p.after_period(&RUNNING), Decision::Feed);
        }
        for _ in 0..100 {
            assert_eq!(p.after_period(&SAFE), Decision::Feed);
        }
        assert_eq!(p.starved(), None);
    }

    #[test]
    fn a_bad_command_starves_for_good() {
        for bad in [
            PeriodOutput {
                current_a: f32::NAN,
                ..RUNNING
            },
            PeriodOutput {
                current_a: -f32::INFINITY,
                ..RUNNING
            },
            PeriodOutput {
                current_a: 1000.0,
                ..RUNNING
            },
            PeriodOutput {
                dac_code: 4096,
                ..RUNNING
            },
        ] {
            let mut p = policy();
            assert_eq!(p.after_period(&RUNNING), Decision::Feed);
            let d = Decision::Starve(StarveReason::CommandOutOfRange);
            assert_eq!(p.after_period(&bad), d, "{bad:?}");
            // Latched: good periods after it do not feed again.
            assert_eq!(p.after_period(&RUNNING), d);
            assert_eq!(p.after_period(&SAFE), d);
            p.fault_reset();
            assert_eq!(p.after_period(&RUNNING), d);
            assert_eq!(p.starved(), Some(StarveReason::CommandOutOfRange));
        }
    }

    #[test]
    fn a_fault_with_a_live_output_starves() {
        for bad in [
            PeriodOutput {
                amp_enable: true,
                ..SAFE
            },
            PeriodOutput {
                current_a: 0.5,
                ..SAFE
            },
            PeriodOutput {
                dac_code: 2049,
                ..SAFE
            },
        ] {
            let mut p = policy();
            assert_eq!(
                p.after_period(&bad),
                Decision::Starve(StarveReason::UnsafeWhileFaulted),
                "{bad:?}"
            );
        }
    }

    #[test]
    fn a_latch_may_clear_only_through_fault_reset() {
        let mut p = policy();
        assert_eq!(p.after_period(&SAFE), Decision::Feed);
        p.fault_reset();
        assert_eq!(p.after_period(&RUNNING), Decision::Feed);
        assert_eq!(p.after_period(&SAFE), Decision::Feed);
        assert_eq!(
            p.after_period(&RUNNING),
            Decision::Starve(StarveReason::LatchCleared)
        );
    }

    #[test]
    fn the_real_step_is_always_fed() {
        let cfg = HopperConfig::default();
        let mut h = Hopper::new(cfg).unwrap_or_else(|e| panic!("{e:?}"));
        let mut p = FeedPolicy::for_hopper(&cfg);
        let cal = cfg.calibration;
        let mut raw = crate::proptest_support::rest_sample(&cal);
        for k in 0..200 {
            if k == 100 {
                raw.estop_pressed = true;
            }
            let out = h.step(Some(&raw), 1e-4);
            assert_eq!(p.after_step(&out), Decision::Feed, "period {k}: {out:?}");
            // The e-stop counts from its second period (`estop.press_s`).
            assert_eq!(out.faults.is_empty(), k < 101);
        }
        // Sensors unreadable, then a NaN time step: still safe, still fed.
        let out = h.step(None, f32::NAN);
        assert_eq!(p.after_step(&out), Decision::Feed);
    }
}
