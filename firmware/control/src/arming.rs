//! Arming: whether the amplifier may be enabled at all.
//!
//! The supervisor says whether the output is *safe*; arming says whether
//! the operator *asked* for motion. The period runner
//! ([`crate::runner::PeriodRunner`]) holds one [`Arming`] and gates every
//! period's output with it, before the watchdog decision and the writes, so
//! the board, the QEMU image and the simulator share it.
//!
//! - **Disarmed at every boot**, whatever the reset cause (a watchdog reset
//!   is recorded as [`DisarmReason::WatchdogReset`]): 0 A, the zero-current
//!   DAC code and the amplifier disabled. Conversion, estimator, supervisor
//!   and telemetry keep running, so the sensors can be watched.
//! - **Arm** only on [`Arming::request_arm`], decided at the next period on
//!   that period's measurements, and only with no latched fault, the e-stop
//!   released, the link alive (a valid frame within `link_timeout_s`, unless
//!   `untethered`), a sensor sample read and converted, and a safe pose: the
//!   nut within `home_tolerance_m` of its upper stop and nut and body
//!   slower than `still_velocity_mps` (a robot at rest, held up or
//!   standing, about to start from where the flight PD would put the nut
//!   anyway). Otherwise it stays disarmed and says why ([`ArmRefusal`]).
//! - **Disarm** on [`Arming::request_disarm`], the e-stop, any latched
//!   fault, or link loss: in the same period, before its output is written.
//! - Fault resets are the runner's ([`crate::runner::PeriodRunner::reset_faults`]),
//!   allowed only while disarmed.

use crate::param::InvalidField;
use crate::supervisor::Faults;

crate::param::config! {
    /// Arming limits (the parameter table's `arming.*`).
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct ArmingConfig;
    params {
        52 ARM_LINK_TIMEOUT_S link_timeout_s: f32 {
            "arming.link_timeout_s", "s", Real, [1.0e-3, 60.0], 0.2, DISARMED,
            "No valid link frame for this long disarms the amplifier (and a dead link refuses arming)."
        }
        /// Run without a link: the link-alive condition and the link timeout are off. The
        /// default keeps a tethered robot stopping when the host goes quiet; the
        /// simulator, which has no link, sets it.
        53 ARM_UNTETHERED untethered: bool {
            "arming.untethered", "-", Flag, [0.0, 1.0], 0.0, DISARMED,
            "Run without a link: no link needed to arm, and link loss does not disarm (an explicit choice; the simulator sets it)."
        }
        54 ARM_HOME_TOLERANCE_M home_tolerance_m: f32 {
            "arming.home_tolerance_m", "m", Real, [0.0, 0.05], 0.001, DISARMED,
            "To arm, the nut must be at most this far from its upper stop."
        }
        55 ARM_STILL_MPS still_velocity_mps: f32 {
            "arming.still_velocity_mps", "m/s", Real, [1.0e-4, 10.0], 0.05, DISARMED,
            "To arm, nut and body must be slower than this."
        }
        /// Refuse to arm until a tare (`hopper-link calibrate tare`) has succeeded since
        /// boot or a saved calibration was loaded at boot. The board sets it, since
        /// without either its offsets are placeholders.
        56 ARM_REQUIRE_TARE require_tare: bool {
            "arming.require_tare", "-", Flag, [0.0, 1.0], 0.0, DISARMED,
            "Refuse to arm until a tare (hopper-link calibrate tare) has succeeded since boot (the board sets it: its offsets are not saved yet)."
        }
        /// Refuse to arm until the nut was homed since boot
        /// ([`crate::bringup::Routine::Home`], which needs a direction check first). The
        /// board sets it: its motor encoder is incremental and boots wherever the nut
        /// stands.
        57 ARM_REQUIRE_HOME require_home: bool {
            "arming.require_home", "-", Flag, [0.0, 1.0], 0.0, DISARMED,
            "Refuse to arm until the nut was homed (hopper-link calibrate home, after calibrate direction) since boot: the motor encoder is incremental, its zero is lost at power-off."
        }
    }
}

impl ArmingConfig {
    /// Every field in its documented range, or the first one that is not.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// Why the amplifier is not armed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[strum(serialize_all = "kebab-case")]
pub enum DisarmReason {
    /// Power-on or a reset other than the watchdog's.
    Boot,
    /// The watchdog reset the MCU: the control loop stopped or misbehaved.
    WatchdogReset,
    /// The operator asked.
    Command,
    /// The e-stop was pressed.
    Estop,
    /// A fault latched.
    Fault,
    /// No valid link frame within the timeout.
    LinkLost,
}

impl DisarmReason {
    /// Kebab-case name, as the logs and the link print it.
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// Why an arm request was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr, strum::VariantArray)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[strum(serialize_all = "kebab-case")]
pub enum ArmRefusal {
    /// A fault is latched (reset it first, while disarmed).
    Faulted,
    /// The e-stop is pressed.
    EstopPressed,
    /// No valid link frame within the timeout (and not untethered).
    LinkDown,
    /// The sensors could not be read, or a value is not finite.
    SensorsImplausible,
    /// The nut is not within the home tolerance of its upper stop.
    NutNotHome,
    /// Nut or body moves faster than the still velocity.
    Moving,
    /// The core clock is not the one the board's clock profile names (the
    /// PLL fell back to the HSI: [`crate::boot::BootReport`]).
    ClockFallback,
    /// The brown-out reset is off in the option bytes.
    BrownOutResetOff,
    /// The crystal measured at boot is not the one the clock profile names
    /// (a build for another board: the board stays on the HSI).
    #[strum(serialize = "crystal-not-the-profiles")]
    CrystalMismatch,
    /// `arming.require_tare` is on and no tare has succeeded since boot.
    NotCalibrated,
    /// A bring-up routine is measuring.
    Calibrating,
    /// The direction check found the motor encoder or the load cell
    /// counting the wrong way (`calibrate direction`).
    #[strum(serialize = "encoder-or-motor-direction-reversed")]
    DirectionReversed,
    /// `arming.require_home` is on and the nut was not homed since boot.
    NotHomed,
}

impl ArmRefusal {
    /// Kebab-case name, as the logs and the link print it.
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// The arming state.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ArmState {
    /// The amplifier stays off, for this reason.
    Disarmed(DisarmReason),
    /// The supervisor's approved command goes out.
    Armed,
}

/// What an arming decision looks at, from the period being run.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ArmInput {
    /// The supervisor's latched faults after this period's check.
    pub faults: Faults,
    /// The e-stop input.
    pub estop_pressed: bool,
    /// A sample was read and converted (not a failed read or a rejected value).
    pub sensors_ok: bool,
    /// Nut position `p`, m (0 at the upper stop).
    pub nut_position_m: f32,
    /// Nut velocity, m/s.
    pub nut_velocity_mps: f32,
    /// Body velocity, m/s.
    pub body_velocity_mps: f32,
    /// A bring-up routine is measuring ([`crate::bringup`]: it must see the
    /// robot with the amplifier off).
    pub calibrating: bool,
}

/// A change this period made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ArmEvent {
    /// Armed on request.
    Armed,
    /// Disarmed, for this reason.
    Disarmed(DisarmReason),
    /// An arm request was refused.
    Refused(ArmRefusal),
}

/// The arming state machine. See the module doc.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Arming {
    cfg: ArmingConfig,
    state: ArmState,
    /// Time since the last valid link frame, s (saturates).
    since_frame_s: f32,
    arm_requested: bool,
    disarm_requested: bool,
    /// What the board found at boot ([`crate::boot::BootReport::NOT_A_BOARD`] until the
    /// board says otherwise).
    boot: crate::boot::BootReport,
    /// A tare has succeeded since boot.
    tared: bool,
    /// The nut was homed since boot.
    homed: bool,
    /// The last direction check found a sensor or the motor reversed.
    reversed: bool,
    /// A direction check ran to a verdict since boot.
    direction_checked: bool,
}

impl Arming {
    /// Disarmed ([`DisarmReason::Boot`]), the link not yet heard from, once
    /// `cfg` passes [`ArmingConfig::validate`].
    pub fn new(cfg: ArmingConfig) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Self {
            cfg,
            state: ArmState::Disarmed(DisarmReason::Boot),
            since_frame_s: f32::INFINITY,
            arm_requested: false,
            disarm_requested: false,
            boot: crate::boot::BootReport::NOT_A_BOARD,
            tared: false,
            homed: false,
            reversed: false,
            direction_checked: false,
        })
    }

    /// A tare succeeded (the period runner says so): `arming.require_tare`
    /// is met from now on.
    pub fn note_tared(&mut self) {
        self.tared = true;
    }

    /// The nut was homed (the period runner says so): `arming.require_home`
    /// is met from now on.
    pub fn note_homed(&mut self) {
        self.homed = true;
    }

    /// A direction check's verdict: `reversed` refuses arming until a check
    /// passes.
    pub fn note_direction(&mut self, reversed: bool) {
        self.reversed = reversed;
        self.direction_checked = true;
    }

    /// A direction check has passed since boot (and none failed since).
    pub fn direction_ok(&self) -> bool {
        self.direction_checked && !self.reversed
    }

    /// The nut was homed since boot.
    pub fn homed(&self) -> bool {
        self.homed
    }

    /// What the board found at boot: a clock that fell back or a
    /// brown-out reset that is off refuses arming from now on.
    pub fn set_boot(&mut self, report: crate::boot::BootReport) {
        self.boot = report;
    }

    /// What the board found at boot.
    pub const fn boot(&self) -> &crate::boot::BootReport {
        &self.boot
    }

    /// The configuration in use.
    pub const fn config(&self) -> &ArmingConfig {
        &self.cfg
    }

    /// A new (validated) configuration, the state and the link timer kept.
    pub fn reconfigure(&mut self, cfg: ArmingConfig) {
        self.cfg = cfg;
    }

    /// The state now.
    pub const fn state(&self) -> ArmState {
        self.state
    }

    /// Whether the supervisor's command may go out.
    pub const fn is_armed(&self) -> bool {
        matches!(self.state, ArmState::Armed)
    }

    /// The MCU came out of a watchdog reset: stay disarmed, and say so.
    pub fn note_watchdog_reset(&mut self) {
        if !self.is_armed() {
            self.state = ArmState::Disarmed(DisarmReason::WatchdogReset);
        }
    }

    /// Ask to arm; decided at the next period (a disarm request in the
    /// same interval wins).
    pub fn request_arm(&mut self) {
        self.arm_requested = true;
    }

    /// A fault latched after this period's decision (a failed DAC or
    /// enable write): disarm now rather than at the next period. Returns the
    /// change, if it was armed.
    pub fn fault_latched(&mut self) -> Option<ArmEvent> {
        self.is_armed().then(|| {
            self.state = ArmState::Disarmed(DisarmReason::Fault);
            ArmEvent::Disarmed(DisarmReason::Fault)
        })
    }

    /// Whether an arm request waits for the next period.
    pub const fn arm_pending(&self) -> bool {
        self.arm_requested
    }

    /// Whether a disarm request waits for the next period (it also stops a
    /// motor-driving bring-up routine).
    pub const fn disarm_pending(&self) -> bool {
        self.disarm_requested
    }

    /// A tare succeeded or a saved calibration was loaded since boot.
    pub const fn tared(&self) -> bool {
        self.tared
    }

    /// The encoders' or the motor's configuration changed: the direction
    /// check and the homing are to be done again.
    pub fn forget_direction_and_home(&mut self) {
        self.direction_checked = false;
        self.reversed = false;
        self.homed = false;
    }

    /// The load cell's or the potentiometer's configuration changed by hand:
    /// the tare is to be done again.
    pub fn forget_tare(&mut self) {
        self.tared = false;
    }

    /// Ask to disarm; done at the next period, before its output.
    pub fn request_disarm(&mut self) {
        self.disarm_requested = true;
    }

    /// A valid link frame arrived: the link is alive.
    pub fn link_frame(&mut self) {
        self.since_frame_s = 0.0;
    }

    /// Whether the link is alive (or not needed).
    pub fn link_alive(&self) -> bool {
        self.cfg.untethered || self.since_frame_s <= self.cfg.link_timeout_s
    }

    /// One period of `dt_s` seconds: the link timer, then the disarm causes
    /// (while armed) or a pending arm request (while disarmed). Returns what
    /// changed. The runner gates the period's output on
    /// [`is_armed`](Self::is_armed) afterwards.
    pub fn period(&mut self, dt_s: f32, input: &ArmInput) -> Option<ArmEvent> {
        // A bad `dt_s` (NaN, negative) must not keep a dead link alive:
        // `!(x > 0)` counts it as a whole timeout.
        let step = if dt_s > 0.0 {
            dt_s
        } else {
            self.cfg.link_timeout_s
        };
        self.since_frame_s += step;
        let (arm, disarm) = (self.arm_requested, self.disarm_requested);
        self.arm_requested = false;
        self.disarm_requested = false;
        match self.state {
            ArmState::Armed => {
                let cause = if !input.faults.is_empty() {
                    Some(DisarmReason::Fault)
                } else if input.estop_pressed {
                    Some(DisarmReason::Estop)
                } else if !self.link_alive() {
                    Some(DisarmReason::LinkLost)
                } else if disarm {
                    Some(DisarmReason::Command)
                } else {
                    None
                };
                cause.map(|c| {
                    self.state = ArmState::Disarmed(c);
                    ArmEvent::Disarmed(c)
                })
            }
            ArmState::Disarmed(_) if arm && !disarm => Some(match self.refusal(input) {
                Some(r) => ArmEvent::Refused(r),
                None => {
                    self.state = ArmState::Armed;
                    ArmEvent::Armed
                }
            }),
            ArmState::Disarmed(_) => None,
        }
    }

    /// Why arming now would be refused, if it would.
    pub fn refusal(&self, input: &ArmInput) -> Option<ArmRefusal> {
        let still = |v: f32| v.abs() < self.cfg.still_velocity_mps;
        // The e-stop first: pressed, it has latched a fault too, and the
        // button is what the operator must release.
        if input.estop_pressed {
            Some(ArmRefusal::EstopPressed)
        } else if !input.faults.is_empty() {
            Some(ArmRefusal::Faulted)
        } else if input.calibrating {
            Some(ArmRefusal::Calibrating)
        } else if let Some(r) = self.boot.refusal() {
            Some(r)
        } else if self.reversed {
            Some(ArmRefusal::DirectionReversed)
        } else if self.cfg.require_home && !self.homed {
            Some(ArmRefusal::NotHomed)
        } else if self.cfg.require_tare && !self.tared {
            Some(ArmRefusal::NotCalibrated)
        } else if !self.link_alive() {
            Some(ArmRefusal::LinkDown)
        } else if !(input.sensors_ok
            && (input.nut_position_m + input.nut_velocity_mps + input.body_velocity_mps)
                .is_finite())
        {
            Some(ArmRefusal::SensorsImplausible)
        } else if input.nut_position_m.abs() > self.cfg.home_tolerance_m {
            // (Finite here: checked just above.)
            Some(ArmRefusal::NutNotHome)
        } else if !(still(input.nut_velocity_mps) && still(input.body_velocity_mps)) {
            Some(ArmRefusal::Moving)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::supervisor::Fault;
    use proptest::prelude::*;

    /// The names the link sends as refusal text and the logs print: a
    /// contract with the operator's tools.
    #[test]
    fn names_are_the_contract() {
        use ArmRefusal as A;
        let names = [
            (A::Faulted, "faulted"),
            (A::EstopPressed, "estop-pressed"),
            (A::LinkDown, "link-down"),
            (A::SensorsImplausible, "sensors-implausible"),
            (A::NutNotHome, "nut-not-home"),
            (A::Moving, "moving"),
            (A::ClockFallback, "clock-fallback"),
            (A::BrownOutResetOff, "brown-out-reset-off"),
            (A::CrystalMismatch, "crystal-not-the-profiles"),
            (A::NotCalibrated, "not-calibrated"),
            (A::Calibrating, "calibrating"),
            (A::DirectionReversed, "encoder-or-motor-direction-reversed"),
            (A::NotHomed, "not-homed"),
        ];
        for (r, name) in names {
            assert_eq!(r.name(), name);
        }
        assert_eq!(DisarmReason::WatchdogReset.name(), "watchdog-reset");
        assert_eq!(DisarmReason::LinkLost.name(), "link-lost");
    }

    const DT: f32 = 1e-4;

    fn at_rest() -> ArmInput {
        ArmInput {
            faults: Faults::NONE,
            estop_pressed: false,
            sensors_ok: true,
            nut_position_m: 0.0,
            nut_velocity_mps: 0.0,
            body_velocity_mps: 0.0,
            calibrating: false,
        }
    }

    fn tethered() -> Arming {
        Arming::new(ArmingConfig::default()).unwrap_or_else(|e| panic!("{e:?}"))
    }

    #[test]
    fn disarmed_at_boot_and_armed_only_on_request() {
        let mut a = tethered();
        assert_eq!(a.state(), ArmState::Disarmed(DisarmReason::Boot));
        a.link_frame();
        for _ in 0..100 {
            assert_eq!(a.period(DT, &at_rest()), None);
            a.link_frame();
        }
        assert!(!a.is_armed());
        a.request_arm();
        assert_eq!(a.period(DT, &at_rest()), Some(ArmEvent::Armed));
        assert!(a.is_armed());
        a.note_watchdog_reset(); // only at boot: no effect while armed
        assert!(a.is_armed());
    }

    #[test]
    fn a_board_whose_clock_fell_back_or_without_brown_out_reset_never_arms() {
        use crate::boot::BootReport;
        for (report, want) in [
            (
                BootReport {
                    clock_as_configured: false,
                    sysclk_hz: 16_000_000,
                    ..BootReport::NOT_A_BOARD
                },
                ArmRefusal::ClockFallback,
            ),
            (
                BootReport {
                    brown_out_reset_on: false,
                    ..BootReport::NOT_A_BOARD
                },
                ArmRefusal::BrownOutResetOff,
            ),
        ] {
            let mut a = tethered();
            a.set_boot(report);
            a.link_frame();
            a.request_arm();
            assert_eq!(a.period(DT, &at_rest()), Some(ArmEvent::Refused(want)));
            assert!(!a.is_armed());
        }
    }

    #[test]
    fn a_robot_that_requires_a_tare_arms_only_after_one() {
        let mut a = Arming::new(ArmingConfig {
            require_tare: true,
            ..ArmingConfig::default()
        })
        .unwrap_or_else(|e| panic!("{e:?}"));
        a.link_frame();
        a.request_arm();
        assert_eq!(
            a.period(DT, &at_rest()),
            Some(ArmEvent::Refused(ArmRefusal::NotCalibrated))
        );
        a.note_tared();
        a.link_frame();
        a.request_arm();
        assert_eq!(a.period(DT, &at_rest()), Some(ArmEvent::Armed));
    }

    #[test]
    fn each_refusal_reason() {
        let cases = [
            (
                ArmInput {
                    faults: Faults(Fault::Overrun.bit()),
                    ..at_rest()
                },
                ArmRefusal::Faulted,
            ),
            (
                ArmInput {
                    estop_pressed: true,
                    ..at_rest()
                },
                ArmRefusal::EstopPressed,
            ),
            (
                ArmInput {
                    sensors_ok: false,
                    ..at_rest()
                },
                ArmRefusal::SensorsImplausible,
            ),
            (
                ArmInput {
                    body_velocity_mps: f32::NAN,
                    ..at_rest()
                },
                ArmRefusal::SensorsImplausible,
            ),
            (
                ArmInput {
                    nut_position_m: 0.0015,
                    ..at_rest()
                },
                ArmRefusal::NutNotHome,
            ),
            (
                ArmInput {
                    body_velocity_mps: -0.2,
                    ..at_rest()
                },
                ArmRefusal::Moving,
            ),
            (
                ArmInput {
                    nut_velocity_mps: 0.06,
                    ..at_rest()
                },
                ArmRefusal::Moving,
            ),
            (
                ArmInput {
                    calibrating: true,
                    ..at_rest()
                },
                ArmRefusal::Calibrating,
            ),
        ];
        for (input, want) in cases {
            let mut a = tethered();
            a.link_frame();
            a.request_arm();
            assert_eq!(a.period(DT, &input), Some(ArmEvent::Refused(want)));
            assert!(!a.is_armed());
            // The request is used up: the next period does not arm by itself.
            a.link_frame();
            assert_eq!(a.period(DT, &at_rest()), None);
        }
        // No frame yet: the link is down.
        let mut a = tethered();
        a.request_arm();
        assert_eq!(
            a.period(DT, &at_rest()),
            Some(ArmEvent::Refused(ArmRefusal::LinkDown))
        );
    }

    #[test]
    fn disarm_causes_act_in_the_same_period() {
        let armed = || {
            let mut a = tethered();
            a.link_frame();
            a.request_arm();
            assert_eq!(a.period(DT, &at_rest()), Some(ArmEvent::Armed));
            a
        };
        let mut a = armed();
        let estop = ArmInput {
            estop_pressed: true,
            ..at_rest()
        };
        assert_eq!(
            a.period(DT, &estop),
            Some(ArmEvent::Disarmed(DisarmReason::Estop))
        );
        let mut a = armed();
        let fault = ArmInput {
            faults: Faults(Fault::SensorRange.bit()),
            ..at_rest()
        };
        assert_eq!(
            a.period(DT, &fault),
            Some(ArmEvent::Disarmed(DisarmReason::Fault))
        );
        let mut a = armed();
        a.request_disarm();
        assert_eq!(
            a.period(DT, &at_rest()),
            Some(ArmEvent::Disarmed(DisarmReason::Command))
        );
        // Link loss: 0.2 s without a frame is 2,000 periods (give or take
        // one for the rounding of the f32 sum).
        let mut a = armed();
        let mut n = 1;
        while a.period(DT, &at_rest()).is_none() {
            n += 1;
            assert!(n < 2100, "still armed");
        }
        assert!((1999..=2001).contains(&n), "disarmed after {n} periods");
        assert_eq!(a.state(), ArmState::Disarmed(DisarmReason::LinkLost));
        // Untethered: no link needed.
        let mut a = Arming::new(ArmingConfig {
            untethered: true,
            ..ArmingConfig::default()
        })
        .unwrap_or_else(|e| panic!("{e:?}"));
        a.request_arm();
        assert_eq!(a.period(DT, &at_rest()), Some(ArmEvent::Armed));
        for _ in 0..10_000 {
            assert_eq!(a.period(DT, &at_rest()), None);
        }
        assert!(a.is_armed());
    }

    #[test]
    fn a_bad_configuration_is_refused_by_name() {
        for (cfg, field) in [
            (
                ArmingConfig {
                    link_timeout_s: 0.0,
                    ..ArmingConfig::default()
                },
                "arming.link_timeout_s",
            ),
            (
                ArmingConfig {
                    home_tolerance_m: f32::NAN,
                    ..ArmingConfig::default()
                },
                "arming.home_tolerance_m",
            ),
            (
                ArmingConfig {
                    still_velocity_mps: -1.0,
                    ..ArmingConfig::default()
                },
                "arming.still_velocity_mps",
            ),
        ] {
            assert_eq!(Arming::new(cfg).err(), Some(InvalidField(field)));
        }
    }

    /// One step of a random session.
    #[derive(Debug, Clone)]
    struct Step {
        arm: bool,
        disarm: bool,
        frame: bool,
        fault: bool,
        estop: bool,
        moving: bool,
        dt_s: f32,
    }

    fn step() -> impl Strategy<Value = Step> {
        (
            any::<bool>(),
            prop::bool::weighted(0.1),
            prop::bool::weighted(0.9),
            prop::bool::weighted(0.05),
            prop::bool::weighted(0.05),
            prop::bool::weighted(0.1),
            prop_oneof![
                Just(1e-4_f32),
                Just(1e-3),
                Just(0.05),
                Just(f32::NAN),
                Just(-1.0)
            ],
        )
            .prop_map(|(arm, disarm, frame, fault, estop, moving, dt_s)| Step {
                arm,
                disarm,
                frame,
                fault,
                estop,
                moving,
                dt_s,
            })
    }

    proptest! {
        /// Whatever the sequence: armed only right after a request on a
        /// clean, still, linked period, or by staying armed through clean
        /// linked periods; never armed in a period with a fault or the
        /// e-stop; every change is reported.
        #[test]
        fn armed_only_when_every_condition_holds(
            untethered in any::<bool>(),
            steps in proptest::collection::vec(step(), 1..300),
        ) {
            let mut a = Arming::new(ArmingConfig { untethered, ..ArmingConfig::default() })
                .map_err(|e| TestCaseError::fail(std::format!("{e:?}")))?;
            prop_assert!(!a.is_armed());
            for s in steps {
                if s.arm { a.request_arm(); }
                if s.disarm { a.request_disarm(); }
                if s.frame { a.link_frame(); }
                let input = ArmInput {
                    faults: if s.fault { Faults(Fault::Estop.bit()) } else { Faults::NONE },
                    estop_pressed: s.estop,
                    body_velocity_mps: if s.moving { 0.5 } else { 0.0 },
                    ..at_rest()
                };
                let was = a.is_armed();
                let ev = a.period(s.dt_s, &input);
                let now = a.is_armed();
                if now {
                    prop_assert!(!s.fault && !s.estop, "armed with a fault or e-stop");
                    prop_assert!(a.link_alive(), "armed without a link");
                    prop_assert!(!s.disarm, "armed through a disarm request");
                }
                if now && !was {
                    prop_assert!(s.arm && !s.moving);
                    prop_assert_eq!(ev, Some(ArmEvent::Armed));
                }
                if was && !now {
                    prop_assert!(matches!(ev, Some(ArmEvent::Disarmed(_))));
                }
                if was == now {
                    prop_assert!(!matches!(ev, Some(ArmEvent::Armed | ArmEvent::Disarmed(_))));
                }
            }
        }
    }
}
