//! The one control-period runner shared by the board, the QEMU image and
//! the host simulator: they differ only in their I/O ([`HopperIo`]), their
//! cycle counter ([`CycleCounter`]) and what paces them.
//!
//! One [`PeriodRunner::run_period`] call is one whole period:
//!
//! 1. read the sensors through the I/O;
//! 2. [`Hopper::step`]: conversion, estimator and eq 4.1 filters, energy
//!    (eqs 2.44-2.45), the selected controller, the supervisor, the DAC code,
//!    the hop ledger and the telemetry record (timed with the counter);
//! 3. arming ([`Arming`]): the link timer, the disarm causes (a
//!    fault, the e-stop, link loss, a request) or a pending arm request, on
//!    this period's measurements; while disarmed the output is 0 A, the
//!    zero-current code and the amplifier off (disarmed at every boot);
//! 4. the watchdog feed decision ([`FeedPolicy`]) on the output; a
//!    starve decision latches [`Fault::SelfCheck`] and makes this and every
//!    later period's output 0 A with the amplifier off before it is written;
//! 5. write the DAC code and the amplifier enable; an I/O error latches a
//!    fault and the amplifier is disabled in the same period (and disarms
//!    from the next period on: the latched fault);
//! 6. what to log: newly latched faults first, else a completed hop.
//!
//! After it the application tells [`PeriodRunner::end_period`] whether the
//! period met its deadline (the board: the next trigger is not pending yet;
//! QEMU: SysTick not pending; the host: always); `overrun_limit` late
//! periods in a row latch [`Fault::Overrun`].
//!
//! Fault resets ([`PeriodRunner::reset_faults`]) are allowed only while
//! disarmed.
//!
//! This file holds the period; the runner's other concerns are `impl`
//! blocks of [`PeriodRunner`] in files of their own: `calibrate` (the
//! bring-up routines: [`PeriodRunner::start_calibration`], their
//! completion, their results applied), `sets` (parameter sets:
//! [`PeriodRunner::set_param`], [`PeriodRunner::install`] of a [`Prepared`]
//! controller) and `saved` (the saved calibration record:
//! [`PeriodRunner::load_calibration`]).

mod calibrate;
mod saved;
mod sets;

pub use calibrate::{Change, Changes};
pub use sets::{Prepared, SetError, Then};

use crate::arming::{ArmEvent, ArmInput, Arming};
use crate::hal::HopperIo;
use crate::hopper::{ConfigError, Hopper, HopperConfig, StepOutput};
use crate::supervisor::{Command, Fault, Faults, SupervisorInput};
use crate::telemetry::HopLedger;
use crate::watchdog::{Decision, FeedPolicy};
use core::sync::atomic::{compiler_fence, Ordering};

/// A free-running counter the runner times the control step with (cycles,
/// or guest instructions under QEMU's `-icount`). Wraps at `u32::MAX`.
pub trait CycleCounter {
    /// The counter now.
    fn now(&mut self) -> u32;

    /// What reading the counter twice back to back costs, in its units
    /// (subtracted from every measurement).
    fn overhead(&self) -> u32 {
        0
    }

    /// Its rate, Hz, when it counts real time (the board's cycle counter
    /// at the core clock); 0 when it does not (QEMU's instruction count,
    /// the simulator). For the cost figures' units only: what the period
    /// starts are checked against is [`Self::pacing`].
    fn hz(&self) -> u32 {
        0
    }

    /// What paces the periods, and so whether (and against what) their
    /// starts are checked.
    fn pacing(&self) -> Pacing {
        Pacing::NoClock
    }

    /// The clock the period starts are read from: everything counted (the
    /// interrupts that preempt the period included, which [`Self::now`]
    /// may leave out); `None` when it was found stopped or disturbed (a
    /// debugger turned the cycle counter off, and it was started again):
    /// the interval around it is not checked.
    fn clock(&mut self) -> Option<u32> {
        Some(self.now())
    }
}

/// What paces the control periods: whether the runner checks their
/// starts ([`Timing::max_jitter_s`]) and against what.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Pacing {
    /// A hardware trigger at the control rate, `ticks` of
    /// [`CycleCounter::clock`] a period (the board's timer; SysTick on
    /// QEMU, in guest instructions): the starts are checked.
    Trigger {
        /// Clock ticks a period.
        ticks: u32,
    },
    /// No clock that counts the periods' time (the host simulator): no
    /// check.
    NoClock,
    /// The host paces the periods (hardware in the loop: a period per
    /// sample received): no check, the host owns the clock.
    Host,
    /// A trigger that slows to the rate the chip sustains (the simulated
    /// hopper on a board, whose robot time is a count of periods): no
    /// check.
    Sustained,
}

/// A period that was late ([`PeriodRunner::last_late`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LatePeriod {
    /// Its number ([`PeriodRunner::periods`] when it ran: the periods
    /// before it).
    pub period: u32,
    /// How it was late.
    pub cause: LateCause,
    /// For [`LateCause::Start`]: how far its start was from the period,
    /// s (negative: early); 0 otherwise.
    pub jitter_s: f32,
}

/// How a period was late.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LateCause {
    /// The next period's trigger came before it ended.
    Deadline,
    /// It started outside the jitter bound.
    Start,
}

/// No counter (the host simulator): every step costs 0.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoCounter;

impl CycleCounter for NoCounter {
    #[inline]
    fn now(&mut self) -> u32 {
        0
    }
}

/// Min / mean / max of the control step's cost, in the counter's units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct StepStats {
    /// Smallest sample (`u32::MAX` before the first).
    pub min: u32,
    /// Largest sample.
    pub max: u32,
    /// Sum of the samples.
    pub sum: u64,
    /// Number of samples.
    pub count: u32,
}

impl Default for StepStats {
    fn default() -> Self {
        Self::new()
    }
}

impl StepStats {
    /// No samples yet.
    pub const fn new() -> Self {
        StepStats {
            min: u32::MAX,
            max: 0,
            sum: 0,
            count: 0,
        }
    }

    /// Adds one sample.
    pub fn add(&mut self, x: u32) {
        self.min = self.min.min(x);
        self.max = self.max.max(x);
        self.sum = self.sum.saturating_add(u64::from(x));
        self.count = self.count.saturating_add(1);
    }

    /// Mean, rounded down (0 without samples).
    pub fn mean(&self) -> u32 {
        if self.count == 0 {
            0
        } else {
            u32::try_from(self.sum / u64::from(self.count)).unwrap_or(u32::MAX)
        }
    }
}

/// What the application's logger gets from a period.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LogItem {
    /// A hop ended (the firmware's own ledger).
    Hop(HopLedger),
    /// Faults latched, with the control period they latched in.
    Faults {
        /// Control period number ([`crate::telemetry::StepRecord::step`]).
        step: u32,
        /// All latched faults.
        faults: Faults,
    },
}

/// Pacing of the runner.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Timing {
    /// The control period, s (finite, > 0).
    pub period_s: f32,
    /// Late periods in a row that latch [`Fault::Overrun`] (>= 1). One late
    /// period is tolerated (the next one catches up); three in a row mean
    /// the loop cannot keep its rate.
    pub overrun_limit: u32,
    /// Largest deviation of the time between two period starts from
    /// `period_s`, s, on a counter that counts real time
    /// ([`CycleCounter::hz`]); beyond it [`Fault::Overrun`] latches at
    /// once: a control task that started late (a stall shorter than the
    /// watchdog's timeout) or twice (a spurious trigger). Default 25 us, a
    /// quarter of the 10 kHz period.
    pub max_jitter_s: f32,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            period_s: 1e-4,
            overrun_limit: 3,
            max_jitter_s: DEFAULT_MAX_JITTER_S,
        }
    }
}

/// [`Timing::max_jitter_s`]'s default, s.
pub const DEFAULT_MAX_JITTER_S: f32 = 25.0e-6;

/// Why a [`PeriodRunner`] could not be built.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RunnerError {
    /// The controller's configuration.
    Config(ConfigError),
    /// `timing.period_s` is not finite and positive.
    Period,
    /// `timing.overrun_limit` is 0.
    OverrunLimit,
    /// `timing.max_jitter_s` is not finite and positive.
    MaxJitter,
    /// The arming configuration (`arming.*`, by name).
    Arming(crate::param::InvalidField),
}

/// Where a period runner keeps its controller: owned ([`Owned`], the host
/// and the tests) or a slot of a static bank (`&'static mut Hopper`, the
/// board and the QEMU link image), where a new controller built by the
/// link task goes in by exchanging two references at the period boundary
/// instead of copying 1.2 KB in the control interrupt.
pub trait HopperSlot: core::ops::DerefMut<Target = Hopper> + Sized {
    /// Whether a slot an install gave back goes back to the link task for
    /// the next one (the static bank's; an owned one is just dropped).
    const RECYCLED: bool;

    /// `h` in a slot of this kind: into `spare` for a bank's (`None`
    /// without one), owned as it is otherwise.
    fn fill(spare: Option<Self>, h: Hopper) -> Option<Self>;
}

/// A controller held by value.
#[derive(Debug, Clone)]
pub struct Owned(pub Hopper);

impl core::ops::Deref for Owned {
    type Target = Hopper;
    fn deref(&self) -> &Hopper {
        &self.0
    }
}

impl core::ops::DerefMut for Owned {
    fn deref_mut(&mut self) -> &mut Hopper {
        &mut self.0
    }
}

impl HopperSlot for Owned {
    const RECYCLED: bool = false;
    fn fill(_: Option<Self>, h: Hopper) -> Option<Self> {
        Some(Owned(h))
    }
}

impl HopperSlot for &'static mut Hopper {
    const RECYCLED: bool = true;
    fn fill(spare: Option<Self>, h: Hopper) -> Option<Self> {
        spare.map(|s| {
            *s = h;
            s
        })
    }
}

/// What one period did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Period {
    /// The step's output, as written (the safe output after an I/O error or
    /// a starve decision).
    pub out: StepOutput,
    /// Whether the application may reload the hardware watchdog now.
    pub feed_watchdog: bool,
    /// Faults latched since the last period reported (in this period, or
    /// between periods: an overrun from `end_period`, a reported one).
    pub newly_latched: Faults,
    /// What to log, if anything.
    pub log: Option<LogItem>,
    /// The control step's cost, in the counter's units.
    pub step_cost: u32,
    /// Whether the output went out armed (otherwise it is the safe one).
    pub armed: bool,
    /// What arming did this period, if anything.
    pub arm_event: Option<ArmEvent>,
}

/// The period runner: the controller, the watchdog feed decision, overrun
/// and step-cost accounting. Not `Copy`: it holds the fault latch.
#[derive(Debug, Clone)]
pub struct PeriodRunner<H = Owned> {
    hopper: H,
    arming: Arming,
    feed: FeedPolicy,
    timing: Timing,
    late_in_a_row: u32,
    missed: u32,
    periods: u32,
    cost: StepStats,
    /// The faults the last period reported (for `newly_latched`).
    reported: Faults,
    /// Periods until a rebuilt controller's velocity filters measure.
    unsettled: u8,
    /// The current the amplifier was told to drive last period, A (0 while
    /// disabled): the thermal model's input.
    applied_a: f32,
    /// The clock at the last period's start (`None` before the first).
    last_start: Option<u32>,
    /// Period starts read since the clock was last (re)started (2 and up:
    /// the interval is checked).
    starts: u8,
    /// The last period that was late, and how.
    late: Option<LatePeriod>,
    /// What paced the last period (its counter's).
    pacing: Pacing,
    /// The start check in ticks: the clock's ticks a period, the jitter
    /// bound in them, and the largest deviation seen at that rate.
    bound: (u32, u32, u32),
    /// The bring-up routine running, or the last one's report.
    cal: crate::bringup::Calibrator,
    /// Largest deviation of a period-start interval from the period so
    /// far, s (0 on a counter that does not count real time).
    max_jitter_s: f32,
    /// What was found in flash at boot.
    at_boot: crate::persist::AtBoot,
    /// Bumped at every change of the controller's configuration (an
    /// install, a live target change).
    config_gen: u32,
    /// A routine's results wait for their controller to be built outside
    /// the period: the parameters it changes and what the install
    /// completes.
    rebuild_request: Option<(Changes, Then)>,
    /// A rebuild was asked for and is not installed yet: the routine counts
    /// as running (nothing arms, saves or sets in between).
    rebuild_outstanding: bool,
    /// The motor's winding estimate at boot, C, and whether it was
    /// assumed warm.
    thermal_boot: (f32, bool),
}

impl PeriodRunner<Owned> {
    /// Validates `cfg` and `timing`; the controller held by value.
    pub fn new(cfg: HopperConfig, timing: Timing) -> Result<Self, RunnerError> {
        let hopper = Hopper::new(cfg).map_err(RunnerError::Config)?;
        Self::in_slot(cfg, timing, Owned(hopper))
    }
}

impl<H: HopperSlot> PeriodRunner<H> {
    /// Validates `cfg` and `timing`; the controller is the one in `slot`
    /// (built from `cfg`: a static bank's slot filled by
    /// [`HopperSlot::fill`]).
    pub fn in_slot(cfg: HopperConfig, timing: Timing, hopper: H) -> Result<Self, RunnerError> {
        if !(timing.period_s > 0.0 && timing.period_s.is_finite()) {
            return Err(RunnerError::Period);
        }
        if timing.overrun_limit == 0 {
            return Err(RunnerError::OverrunLimit);
        }
        if !(timing.max_jitter_s > 0.0 && timing.max_jitter_s.is_finite()) {
            return Err(RunnerError::MaxJitter);
        }
        let arming = Arming::new(cfg.arming).map_err(RunnerError::Arming)?;
        let thermal_boot = (hopper.supervisor().thermal().winding_c(), false);
        Ok(Self {
            thermal_boot,
            arming,
            feed: FeedPolicy::for_hopper(hopper.config()),
            hopper,
            timing,
            late_in_a_row: 0,
            missed: 0,
            periods: 0,
            cost: StepStats::new(),
            reported: Faults::NONE,
            unsettled: 0,
            applied_a: 0.0,
            last_start: None,
            starts: 0,
            late: None,
            pacing: Pacing::NoClock,
            bound: (0, 0, 0),
            cal: crate::bringup::Calibrator::new(),
            max_jitter_s: 0.0,
            at_boot: crate::persist::AtBoot::NoStore,
            config_gen: 0,
            rebuild_request: None,
            rebuild_outstanding: false,
        })
    }

    /// The controller.
    pub fn hopper(&self) -> &Hopper {
        &self.hopper
    }

    /// The controller, mutably (simulated faults, target changes).
    pub fn hopper_mut(&mut self) -> &mut Hopper {
        &mut self.hopper
    }

    /// Arming: the state, the link timer, arm and disarm requests.
    pub fn arming(&self) -> &Arming {
        &self.arming
    }

    /// Arming, mutably: [`Arming::request_arm`], [`Arming::request_disarm`],
    /// [`Arming::link_frame`], [`Arming::note_watchdog_reset`]. Requests
    /// take effect at the next period.
    pub fn arming_mut(&mut self) -> &mut Arming {
        &mut self.arming
    }

    /// The pacing in use.
    pub fn timing(&self) -> &Timing {
        &self.timing
    }

    /// Latches [`Fault::Overrun`]: the application knows a deadline was
    /// missed (e.g. after a watchdog reset, or a simulated overrun).
    pub fn report_overrun(&mut self) {
        self.hopper.supervisor_mut().report_overrun();
    }

    /// Clears the latched faults whose causes are gone in `input` (see
    /// [`crate::supervisor::Supervisor::reset`]) and tells the feed policy
    /// the latch cleared on purpose. Refused once the policy has starved:
    /// the hardware reset is on its way, and only it clears that.
    pub fn reset_faults(&mut self, input: &SupervisorInput) -> Result<(), Faults> {
        if self.arming.is_armed() {
            // Only while disarmed (a latched fault disarms, so this is a
            // reset without a fault: nothing to clear, and nothing changes).
            return Err(self.hopper.supervisor().faults());
        }
        if self.starved() {
            return Err(self
                .hopper
                .supervisor()
                .faults()
                .union(Faults(Fault::SelfCheck.bit())));
        }
        self.hopper.supervisor_mut().reset(input)?;
        self.feed.fault_reset();
        self.reported = Faults::NONE;
        // A late period before the reset does not count towards an overrun
        // after it.
        self.late_in_a_row = 0;
        Ok(())
    }

    /// Starts the motor's estimate hot, at the derating temperature
    /// ([`crate::thermal`]): the board at every boot, since nothing of the
    /// motor's heat survives a reset or a power cycle there.
    pub fn assume_motor_warm(&mut self) {
        self.hopper.supervisor_mut().assume_motor_warm();
        self.thermal_boot = (self.hopper.supervisor().thermal().winding_c(), true);
    }

    /// Where the motor's estimate started: the winding, C, and whether it
    /// was [assumed warm](Self::assume_motor_warm).
    pub fn thermal_at_boot(&self) -> (f32, bool) {
        self.thermal_boot
    }

    /// Whether the feed policy has stopped feeding for good.
    pub fn starved(&self) -> bool {
        self.feed.starved().is_some()
    }

    /// The period-start check: the interval since the last start must be
    /// the period within [`Timing::max_jitter_s`], on a trigger-paced
    /// clock ([`Pacing::Trigger`]). The first interval after the first
    /// period is not checked: the first period runs whenever start-up
    /// ends (its trigger pending since the timer started), the second at
    /// the next trigger, any time up to a period later. Nor is one around
    /// a clock found stopped, or one that runs backwards (a debugger
    /// cleared the counter; a wrap is told apart by the last start lying
    /// within two periods of the top).
    fn check_start<C: CycleCounter>(&mut self, counter: &mut C) {
        self.pacing = counter.pacing();
        let Pacing::Trigger { ticks } = self.pacing else {
            return;
        };
        let Some(start) = counter.clock() else {
            self.last_start = None;
            self.starts = 0;
            return;
        };
        if let Some(last) = self.last_start {
            let went_back = start < last && last < u32::MAX - ticks.saturating_mul(2);
            if went_back {
                self.starts = 0;
            } else if self.starts >= 2 && ticks > 0 {
                let interval = start.wrapping_sub(last);
                let off = interval.abs_diff(ticks);
                // In ticks every period; seconds only for a new largest
                // deviation or a late start (rare): the bound in ticks is
                // worked out once per clock rate.
                if self.bound.0 != ticks {
                    let bound = self.timing.max_jitter_s / self.timing.period_s * ticks as f32;
                    self.bound = (ticks, bound as u32, 0);
                }
                let to_s = |off: u32| off as f32 / ticks as f32 * self.timing.period_s;
                if off > self.bound.2 {
                    self.bound.2 = off;
                    self.max_jitter_s = crate::num::max(self.max_jitter_s, to_s(off));
                }
                if off > self.bound.1 {
                    let jitter_s = to_s(off);
                    self.late = Some(LatePeriod {
                        period: self.periods,
                        cause: LateCause::Start,
                        jitter_s: if interval < ticks {
                            -jitter_s
                        } else {
                            jitter_s
                        },
                    });
                    self.report_overrun();
                }
            }
        }
        self.starts = self.starts.saturating_add(1);
        self.last_start = Some(start);
    }

    /// One whole control period (see the [module documentation](self)).
    pub fn run_period<Io: HopperIo, C: CycleCounter>(
        &mut self,
        io: &mut Io,
        counter: &mut C,
    ) -> Period {
        // Each period's start, from the hardware counter: the interval
        // since the last one must be the period, within the jitter bound.
        self.check_start(counter);
        let raw = io.read().ok();
        // The motor heated with last period's current: an overtemperature
        // latches before this period's step, so the step's output is
        // already the safe one (100 us late: nothing on a thermal scale).
        self.hopper.heat(self.applied_a, self.timing.period_s);
        // A bring-up routine measures disarmed: it starts only disarmed,
        // and arming is refused while it runs. A tare's new offsets apply
        // before this period's step, as a parameter set between periods
        // would.
        if self.cal.sample(raw.as_ref()) {
            self.finish_calibration();
        }
        let t0 = counter.now();
        // The step alone between the two readings: no memory access of
        // the period's other work moved into (or out of) the window.
        compiler_fence(Ordering::SeqCst);
        let mut out =
            self.hopper
                .step_with(raw.as_ref(), self.timing.period_s, Some(&mut self.cal));
        compiler_fence(Ordering::SeqCst);
        let t1 = counter.now();
        // A motor-driving routine stops at a fault (the e-stop latches one)
        // or a lost link; the output below is then the safe one.
        if self.cal.driving()
            && (!out.faults.is_empty() || !self.arming.link_alive() || self.arming.disarm_pending())
        {
            self.cal.abort();
        }
        // Whether this period's command is a routine's (approved by the
        // supervisor above) rather than disarmed's zero.
        let driven = self.cal.driving();
        if self.cal.take_ended() {
            self.finish_drive();
        }
        self.cal.add_nut_position(out.record.nut_position_m);
        let step_cost = t1.wrapping_sub(t0).saturating_sub(counter.overhead());
        self.cost.add(step_cost);
        self.periods = self.periods.wrapping_add(1);
        let zero = self.hopper.zero_code();
        // Arming, on this period's measurements, before anything is written.
        // The pose only matters to an arm request.
        let (nut_velocity_mps, body_velocity_mps) = if self.arming.arm_pending() {
            (
                self.hopper.nut_velocity_mps(),
                self.hopper.estimator().velocities().body_mps,
            )
        } else {
            (0.0, 0.0)
        };
        let arm_input = ArmInput {
            faults: out.faults,
            // Debounced: a release counts after `estop.release_s`.
            estop_pressed: self.hopper.estop_pressed(),
            // A controller rebuilt less than two periods ago has velocity
            // filters that read 0 m/s whatever the robot does (it may still
            // be bouncing): not a measurement to arm on.
            sensors_ok: raw.is_some() && out.energy_j.is_finite() && self.unsettled == 0,
            nut_position_m: out.record.nut_position_m,
            nut_velocity_mps,
            body_velocity_mps,
            calibrating: self.calibrating(),
        };
        self.unsettled = self.unsettled.saturating_sub(1);
        let arm_event = self.arming.period(self.timing.period_s, &arm_input);
        let armed = self.arming.is_armed();
        if !armed && !driven {
            // Disarmed: the safe output, without a fault.
            out.command = Command::SAFE;
            out.dac_code = zero;
            out.record.command_a = 0.0;
            out.record.dac_code = zero;
        }
        // The feed decision first, on the step's own output (`FeedPolicy` is
        // pure): an output that contradicts itself never reaches the pins.
        // A starve latches `SelfCheck`, so no later period can enable the
        // amplifier though the hardware reset is up to one watchdog timeout
        // away (and `Supervisor::reset` never clears it).
        let feed_watchdog = match self.feed.after_step(&out) {
            Decision::Feed => true,
            Decision::Starve(_) => {
                self.hopper.supervisor_mut().report(Fault::SelfCheck);
                self.make_safe(&mut out, zero);
                false
            }
        };
        if io.write_dac(out.dac_code).is_err() {
            self.hopper.supervisor_mut().report(Fault::DacError);
            // The DAC may hold any code now: ask once more for zero (it may
            // fail again; the disable below is what makes it safe), and say
            // zero is what this period commands.
            let _ = io.write_dac(zero);
            self.make_safe(&mut out, zero);
        }
        if io.set_amp_enabled(out.command.amp_enable).is_err() {
            // The enable pin failed: we cannot know the amplifier's state, so
            // make sure the command is zero and ask for "off" once more.
            self.hopper.supervisor_mut().report(Fault::AmpFault);
            let _ = io.write_dac(zero);
            let _ = io.set_amp_enabled(false);
            self.make_safe(&mut out, zero);
        }
        // What the amplifier was told, for the thermal model next period.
        self.applied_a = if out.command.amp_enable {
            out.command.current_a
        } else {
            0.0
        };
        out.record.faults = out.faults.0;
        let mut arm_event = arm_event;
        if !out.faults.is_empty() {
            // A write failure after the decision: disarmed as of now.
            arm_event = self.arming.fault_latched().or(arm_event);
        }
        out.record.armed = self.arming.is_armed() && out.command.amp_enable;
        // Since the last report, not since this period began: a fault that
        // latched between periods (`end_period`'s overrun, `report_overrun`)
        // is reported with the period that first shows it.
        let newly_latched = Faults(out.faults.0 & !self.reported.0);
        self.reported = out.faults;
        let log = if !newly_latched.is_empty() {
            Some(LogItem::Faults {
                step: out.record.step,
                faults: out.faults,
            })
        } else {
            out.hop.map(LogItem::Hop)
        };
        Period {
            out,
            feed_watchdog,
            newly_latched,
            log,
            step_cost,
            armed: out.record.armed,
            arm_event,
        }
    }

    fn make_safe(&self, out: &mut StepOutput, zero: u16) {
        out.command = Command::SAFE;
        out.dac_code = zero;
        out.faults = self.hopper.supervisor().faults();
        // The capture shows what was written, not what was withdrawn.
        out.record.command_a = 0.0;
        out.record.dac_code = zero;
    }

    /// The application's verdict on the period just run: `late` when the
    /// next period's trigger came before it finished. `overrun_limit` late
    /// periods in a row latch [`Fault::Overrun`] (the next period is safe).
    pub fn end_period(&mut self, late: bool) {
        if late {
            self.late = Some(LatePeriod {
                // This period's number: `run_period` counted it already.
                period: self.periods.wrapping_sub(1),
                cause: LateCause::Deadline,
                jitter_s: 0.0,
            });
            self.missed = self.missed.saturating_add(1);
            self.late_in_a_row = self.late_in_a_row.saturating_add(1);
            if self.late_in_a_row >= self.timing.overrun_limit {
                self.report_overrun();
            }
        } else {
            self.late_in_a_row = 0;
        }
    }

    /// Periods run so far.
    pub fn periods(&self) -> u32 {
        self.periods
    }

    /// Periods that missed their deadline so far.
    pub fn missed(&self) -> u32 {
        self.missed
    }

    /// Largest deviation of a period-start interval from the period so
    /// far, s (0 when the counter does not count real time).
    pub fn max_jitter_s(&self) -> f32 {
        self.max_jitter_s
    }

    /// What paced the last period ([`CycleCounter::pacing`]).
    pub fn pacing(&self) -> Pacing {
        self.pacing
    }

    /// The last period that was late (missed its deadline, or started
    /// outside the jitter bound), if any.
    pub fn last_late(&self) -> Option<LatePeriod> {
        self.late
    }

    /// The control step's cost over every period so far.
    pub fn step_cost(&self) -> &StepStats {
        &self.cost
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::hal::{IoError, RawSample};
    use crate::hopper::Strategy;

    /// I/O that records what was written and can fail on command.
    pub(super) struct Io {
        pub(super) raw: RawSample,
        pub(super) dac: Option<u16>,
        pub(super) enabled: Option<bool>,
        /// How many times the enable was written high.
        pub(super) enable_writes: u32,
        pub(super) fail_dac: bool,
        pub(super) fail_enable: bool,
    }

    impl Io {
        pub(super) fn new(raw: RawSample) -> Self {
            Io {
                raw,
                dac: None,
                enabled: None,
                enable_writes: 0,
                fail_dac: false,
                fail_enable: false,
            }
        }
    }

    impl HopperIo for Io {
        type Error = ();
        fn read(&mut self) -> Result<RawSample, IoError<()>> {
            Ok(self.raw)
        }
        fn write_dac(&mut self, code: u16) -> Result<(), IoError<()>> {
            if self.fail_dac {
                return Err(IoError::Dac);
            }
            self.dac = Some(code);
            Ok(())
        }
        fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<()>> {
            if self.fail_enable {
                return Err(IoError::Pin(()));
            }
            self.enabled = Some(on);
            self.enable_writes += u32::from(on);
            Ok(())
        }
    }

    /// A runner armed (untethered) at its first period, as the simulator
    /// and the QEMU scenario run it.
    pub(super) fn runner(strategy: Strategy) -> PeriodRunner {
        let mut cfg = HopperConfig {
            strategy,
            ..HopperConfig::default()
        };
        cfg.arming.untethered = true;
        let mut r = PeriodRunner::new(cfg, Timing::default()).unwrap_or_else(|e| panic!("{e:?}"));
        r.arming_mut().request_arm();
        r
    }

    #[test]
    fn disarmed_at_boot_until_an_arm_request_is_accepted() {
        let mut r = PeriodRunner::new(HopperConfig::default(), Timing::default())
            .unwrap_or_else(|e| panic!("{e:?}"));
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        for _ in 0..100 {
            let p = r.run_period(&mut io, &mut NoCounter);
            assert_eq!((io.dac, io.enabled), (Some(2048), Some(false)));
            assert!(!p.armed && p.feed_watchdog && p.out.faults.is_empty());
            r.end_period(false);
        }
        // No link yet: refused, and still safe.
        r.arming_mut().request_arm();
        let p = r.run_period(&mut io, &mut NoCounter);
        assert_eq!(
            p.arm_event,
            Some(ArmEvent::Refused(crate::arming::ArmRefusal::LinkDown))
        );
        assert_eq!(io.enabled, Some(false));
        // A frame, then the request: armed in that very period.
        r.arming_mut().link_frame();
        r.arming_mut().request_arm();
        let p = r.run_period(&mut io, &mut NoCounter);
        assert_eq!(p.arm_event, Some(ArmEvent::Armed));
        assert_eq!(io.enabled, Some(true));
        assert!(p.armed);
        // The e-stop while armed: 0 A and off in the period that completes
        // the press (0.2 ms: the second at 10 kHz).
        io.raw.estop_pressed = true;
        r.arming_mut().link_frame();
        let p = r.run_period(&mut io, &mut NoCounter);
        assert!(p.armed, "one period pressed is a glitch");
        r.arming_mut().link_frame();
        let p = r.run_period(&mut io, &mut NoCounter);
        assert_eq!((io.dac, io.enabled), (Some(2048), Some(false)));
        assert!(!p.armed);
        assert!(matches!(p.arm_event, Some(ArmEvent::Disarmed(_))));
        // Released, and seen released for `estop.release_s` (50 ms): the
        // estop fault resets only while disarmed, and arming needs a new
        // request.
        io.raw.estop_pressed = false;
        for _ in 0..500 {
            r.arming_mut().link_frame();
            r.run_period(&mut io, &mut NoCounter);
        }
        let raw = io.raw;
        let rest = {
            let m = crate::calibration::Converter::new(HopperConfig::default().calibration)
                .and_then(|mut c| c.convert(&raw))
                .unwrap_or_else(|e| panic!("{e:?}"));
            crate::supervisor::SupervisorInput::from_measurements(&m, 0.0, 0.0, 0.0)
        };
        assert_eq!(r.reset_faults(&rest), Ok(()));
        r.arming_mut().link_frame();
        let p = r.run_period(&mut io, &mut NoCounter);
        assert!(!p.armed && p.out.faults.is_empty());
    }

    #[test]
    fn a_running_period_writes_the_command_and_feeds() {
        let mut r = runner(Strategy::Passive);
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        let p = r.run_period(&mut io, &mut NoCounter);
        assert_eq!(p.arm_event, Some(ArmEvent::Armed));
        assert_eq!(io.dac, Some(2048));
        assert_eq!(io.enabled, Some(true));
        assert!(p.feed_watchdog);
        assert!(p.newly_latched.is_empty());
        assert_eq!(p.log, None);
    }

    #[test]
    fn a_dac_write_error_disables_the_amplifier_in_the_same_period() {
        let mut r = runner(Strategy::default());
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        io.fail_dac = true;
        let p = r.run_period(&mut io, &mut NoCounter);
        assert_eq!(io.enabled, Some(false), "amplifier left enabled");
        assert_eq!(p.out.command, Command::SAFE);
        assert!(p.newly_latched.contains(Fault::DacError));
        assert!(matches!(p.log, Some(LogItem::Faults { .. })));
        // A safely faulted period still feeds (the latch holds it safe).
        assert!(p.feed_watchdog);
    }

    #[test]
    fn an_enable_pin_error_latches_and_asks_for_zero() {
        let mut r = runner(Strategy::default());
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        io.fail_enable = true;
        let p = r.run_period(&mut io, &mut NoCounter);
        assert_eq!(io.dac, Some(2048));
        assert!(p.out.faults.contains(Fault::AmpFault));
        assert_eq!(p.out.command, Command::SAFE);
    }

    #[test]
    fn late_periods_in_a_row_latch_an_overrun() {
        let mut r = runner(Strategy::Passive);
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        for late in [true, true, false, true, true] {
            assert!(r.run_period(&mut io, &mut NoCounter).out.faults.is_empty());
            r.end_period(late);
        }
        assert_eq!(r.missed(), 4);
        let late = r.last_late().expect("a late period recorded");
        assert_eq!((late.period, late.cause), (4, LateCause::Deadline));
        r.end_period(true);
        let p = r.run_period(&mut io, &mut NoCounter);
        assert!(p.out.faults.contains(Fault::Overrun));
        assert_eq!(io.enabled, Some(false));
        // Latched between periods, reported with the first period that shows it.
        assert!(p.newly_latched.contains(Fault::Overrun));
        assert!(matches!(p.log, Some(LogItem::Faults { .. })));
        assert!(r
            .run_period(&mut io, &mut NoCounter)
            .newly_latched
            .is_empty());
    }

    #[test]
    fn a_starve_decision_latches_so_no_later_period_enables() {
        let mut r = runner(Strategy::Passive);
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        assert!(r.run_period(&mut io, &mut NoCounter).feed_watchdog);
        // Fault, then a latch that clears without a fault reset: the policy
        // starves (`LatchCleared`).
        r.report_overrun();
        assert!(r.run_period(&mut io, &mut NoCounter).feed_watchdog);
        let raw = io.raw;
        let sup_in = {
            let m = crate::calibration::Converter::new(HopperConfig::default().calibration)
                .and_then(|mut c| c.convert(&raw))
                .unwrap_or_else(|e| panic!("{e:?}"));
            crate::supervisor::SupervisorInput::from_measurements(&m, 0.0, 0.0, 0.0)
        };
        assert!(r.hopper_mut().supervisor_mut().reset(&sup_in).is_ok());
        io.enable_writes = 0;
        let p = r.run_period(&mut io, &mut NoCounter);
        // Decided before the writes: the starving period never enables.
        assert_eq!(io.enable_writes, 0);
        assert_eq!(p.out.record.command_a, 0.0);
        assert!(!p.feed_watchdog);
        assert!(r.starved());
        assert!(p.out.faults.contains(Fault::SelfCheck));
        assert_eq!(io.enabled, Some(false));
        assert_eq!(io.dac, Some(2048));
        // Neither reset clears it: only the watchdog's hardware reset does.
        assert!(r.reset_faults(&sup_in).is_err());
        assert!(r.hopper_mut().supervisor_mut().reset(&sup_in).is_err());
        assert!(r.hopper().supervisor().faults().contains(Fault::SelfCheck));
        // Every later period stays off and unfed, whatever the supervisor says.
        for _ in 0..10 {
            let p = r.run_period(&mut io, &mut NoCounter);
            assert!(!p.feed_watchdog);
            assert_eq!(p.out.command, Command::SAFE);
            assert_eq!(io.enabled, Some(false));
        }
        assert_eq!(io.enable_writes, 0);
    }

    /// A 1 MHz real-time counter that `now` moves by the next interval.
    struct Clock {
        t: u32,
        intervals: std::vec::Vec<u32>,
        hz: u32,
    }

    impl CycleCounter for Clock {
        fn now(&mut self) -> u32 {
            let t = self.t;
            // Only the period's first reading moves the clock.
            if !self.intervals.is_empty() {
                self.t = self.t.wrapping_add(self.intervals.remove(0));
            }
            t
        }
        fn hz(&self) -> u32 {
            self.hz
        }
        fn pacing(&self) -> Pacing {
            if self.hz > 0 {
                Pacing::Trigger {
                    ticks: self.hz / 10_000,
                }
            } else {
                Pacing::NoClock
            }
        }
    }

    /// Where [`run_gaps`]'s clock starts: 40 periods of 168 MHz below the
    /// top, so that a longer run wraps.
    const PACED_START: u32 = u32::MAX - 40 * 16_800;

    /// Periods whose starts are `gaps` apart, in ticks of a counter of
    /// `hz` with `pacing`, optionally found stopped at some periods;
    /// whether overrun latched, and the largest jitter.
    fn run_gaps(gaps: &[u32], pacing: Pacing, hz: u32, stopped_at: &[usize]) -> (bool, f32) {
        struct Paced {
            t: u32,
            gaps: std::vec::Vec<u32>,
            next: usize,
            pacing: Pacing,
            hz: u32,
            stopped_at: std::vec::Vec<usize>,
        }
        impl CycleCounter for Paced {
            fn now(&mut self) -> u32 {
                self.t
            }
            fn hz(&self) -> u32 {
                self.hz
            }
            fn pacing(&self) -> Pacing {
                self.pacing
            }
            fn clock(&mut self) -> Option<u32> {
                let k = self.next;
                if k > 0 {
                    self.t = self.t.wrapping_add(self.gaps[k - 1]);
                }
                self.next += 1;
                (!self.stopped_at.contains(&k)).then_some(self.t)
            }
        }
        let rest = crate::proptest_support::rest_sample(&HopperConfig::default().calibration);
        let mut r = runner(Strategy::default());
        let mut io = Io::new(rest);
        let mut c = Paced {
            t: PACED_START,
            gaps: gaps.to_vec(),
            next: 0,
            pacing,
            hz,
            stopped_at: stopped_at.to_vec(),
        };
        for _ in 0..=gaps.len() {
            r.arming_mut().link_frame();
            r.run_period(&mut io, &mut c);
        }
        (
            r.hopper().supervisor().faults().contains(Fault::Overrun),
            r.max_jitter_s(),
        )
    }

    /// The board: TIM4 starts in `init`, whose flash and watchdog work go
    /// on meanwhile, so the first period runs when `init` ends and the
    /// second at the next trigger, any time up to a period later. Any such
    /// boot at 168 MHz, the periods then on time, latches nothing; a
    /// later short interval still does.
    #[test]
    fn a_boot_at_any_phase_of_the_control_timer_latches_no_overrun() {
        use proptest::prelude::*;
        const TICKS: u32 = 168_000_000 / 10_000;
        let pacing = Pacing::Trigger { ticks: TICKS };
        proptest!(ProptestConfig::with_cases(64), |(first in 0u32..=TICKS, jitter in proptest::collection::vec(-800i32..800, 20))| {
            let mut gaps = std::vec![first];
            gaps.extend(jitter.iter().map(|j| TICKS.wrapping_add_signed(*j)));
            let (latched, max) = run_gaps(&gaps, pacing, 168_000_000, &[]);
            prop_assert!(!latched, "first interval {first}, max jitter {max}");
            prop_assert!(max < 5e-6);
        });
        // A spurious trigger later on is still caught.
        let (latched, _) = run_gaps(&[3_000, TICKS, TICKS / 3, TICKS], pacing, 168_000_000, &[]);
        assert!(latched);
    }

    /// Hardware in the loop and the simulated hopper on a board: the
    /// cycle counter runs at 168 MHz, but the host (a sample at a time)
    /// or a slowed SysTick paces the periods: no check, whatever the
    /// intervals; the same intervals on a trigger-paced clock latch.
    #[test]
    fn periods_the_host_or_a_sustained_rate_paces_are_not_checked_against_the_clock() {
        let gaps = [168_000, 90_000, 400_000, 17_000, 1_680_000, 168_000];
        for pacing in [Pacing::Host, Pacing::Sustained, Pacing::NoClock] {
            assert_eq!(
                run_gaps(&gaps, pacing, 168_000_000, &[]),
                (false, 0.0),
                "{pacing:?}"
            );
        }
        let trigger = Pacing::Trigger { ticks: 16_800 };
        assert!(run_gaps(&gaps, trigger, 168_000_000, &[]).0);
    }

    /// A debugger that turns the cycle counter off (the clock is found
    /// stopped and started again) or clears it (the count runs backwards)
    /// costs the check an interval, not a spurious overrun.
    #[test]
    fn a_cycle_counter_stopped_or_cleared_by_a_debugger_latches_no_overrun() {
        const TICKS: u32 = 16_800;
        let trigger = Pacing::Trigger { ticks: TICKS };
        let mut gaps = std::vec![TICKS; 30];
        // Found stopped at period 10 (then, restarted, from some other count).
        gaps[10] = 7;
        gaps[11] = 3_000_000;
        assert!(!run_gaps(&gaps, trigger, 168_000_000, &[11]).0);
        // Cleared to a small count at period 20 (the start runs backwards).
        let mut gaps = std::vec![TICKS; 30];
        gaps[19] = 500u32.wrapping_sub(PACED_START.wrapping_add(19 * TICKS));
        assert!(!run_gaps(&gaps, trigger, 168_000_000, &[]).0);
        // The counter wraps on time (at period 40): still checked, on time;
        // late across the wrap, caught.
        let wrap = run_gaps(&std::vec![TICKS; 60], trigger, 168_000_000, &[]);
        assert_eq!(wrap, (false, 0.0));
        let mut gaps = std::vec![TICKS; 60];
        gaps[40] = TICKS + TICKS / 2;
        assert!(run_gaps(&gaps, trigger, 168_000_000, &[]).0);
    }

    #[test]
    fn a_period_that_starts_late_or_early_latches_overrun() {
        let rest = crate::proptest_support::rest_sample(&HopperConfig::default().calibration);
        // (intervals in us between period starts, hz, whether it latches)
        for (gaps, hz, latches) in [
            (std::vec![100u32; 50], 1_000_000u32, false),
            // 24 us of jitter either way: within the 25 us bound.
            (std::vec![124, 76, 124, 76, 100], 1_000_000, false),
            // A stall of 30 us (the task started late).
            (std::vec![100, 100, 130, 100], 1_000_000, true),
            // A spurious second start 40 us after the first.
            (std::vec![100, 40, 100], 1_000_000, true),
            // The counter wraps: still 100 us.
            (std::vec![100; 5], 1_000_000, false),
            // Not a real-time counter (QEMU, the simulator): no check.
            (std::vec![100, 500, 3, 100], 0, false),
        ] {
            let mut r = runner(Strategy::default());
            let mut io = Io::new(rest);
            // Each period reads the clock twice more around the step: put
            // the interval on the period's first reading only.
            let mut steps = std::vec::Vec::new();
            for g in &gaps {
                steps.extend_from_slice(&[*g, 0, 0]);
            }
            let mut clock = Clock {
                t: u32::MAX - 150,
                intervals: steps,
                hz,
            };
            for _ in 0..=gaps.len() {
                r.arming_mut().link_frame();
                r.run_period(&mut io, &mut clock);
            }
            let latched = r.hopper().supervisor().faults().contains(Fault::Overrun);
            assert_eq!(latched, latches, "{gaps:?} at {hz} Hz");
            // The late start is recorded, with how far off it was.
            let late = r.last_late();
            assert_eq!(late.is_some(), latches, "{gaps:?}");
            if let Some(l) = late {
                assert_eq!(l.cause, LateCause::Start);
                assert!(l.jitter_s.abs() > 25e-6, "{l:?}");
            }
            if hz > 0 && !latches {
                assert!(r.max_jitter_s() <= 24.5e-6, "{}", r.max_jitter_s());
            }
        }
    }

    #[test]
    fn bad_timing_is_refused() {
        let cfg = HopperConfig::default();
        let t = |period_s, overrun_limit| Timing {
            period_s,
            overrun_limit,
            ..Timing::default()
        };
        assert_eq!(
            PeriodRunner::new(cfg, t(0.0, 3)).err(),
            Some(RunnerError::Period)
        );
        let no_bound = Timing {
            max_jitter_s: f32::NAN,
            ..Timing::default()
        };
        assert_eq!(
            PeriodRunner::new(cfg, no_bound).err(),
            Some(RunnerError::MaxJitter)
        );
        assert_eq!(
            PeriodRunner::new(cfg, t(f32::NAN, 3)).err(),
            Some(RunnerError::Period)
        );
        assert_eq!(
            PeriodRunner::new(cfg, t(1e-4, 0)).err(),
            Some(RunnerError::OverrunLimit)
        );
    }

    struct Ticks(u32);
    impl CycleCounter for Ticks {
        fn now(&mut self) -> u32 {
            self.0 = self.0.wrapping_add(100);
            self.0
        }
        fn overhead(&self) -> u32 {
            10
        }
    }

    #[test]
    fn the_step_cost_is_counted_without_the_counter_overhead() {
        let mut r = runner(Strategy::Passive);
        let mut io = Io::new(crate::proptest_support::rest_sample(
            &HopperConfig::default().calibration,
        ));
        let mut c = Ticks(u32::MAX - 50);
        for _ in 0..4 {
            assert_eq!(r.run_period(&mut io, &mut c).step_cost, 90);
        }
        assert_eq!(r.step_cost().mean(), 90);
        assert_eq!(r.step_cost().count, 4);
        assert_eq!(r.periods(), 4);
    }
}
