//! The wire's vocabulary: what the codes in the messages mean, with the
//! names both ends print. A message carries a code as a plain `u8` (or a
//! bitset), so a newer robot's unknown code still decodes (the host shows
//! it as a number); these enums give a known code its meaning, in one place
//! for the robot (`hopper-robot-link` maps the firmware's own types onto
//! them, and a test there checks every name and code agrees) and the host.

use strum::{FromRepr, IntoStaticStr, VariantArray};

/// Gives each vocabulary enum its name and its code.
macro_rules! vocabulary {
    ($($ty:ident),*) => {$(
        impl $ty {
            /// Its name, as both ends print it.
            pub fn name(self) -> &'static str {
                self.into()
            }

            /// Its code on the wire.
            pub const fn code(self) -> u8 {
                self as u8
            }

            /// The variant with wire code `code` (`None` for an unknown
            /// one, e.g. from a newer robot).
            pub const fn from_code(code: u8) -> Option<Self> {
                Self::from_repr(code)
            }

            /// Every variant, by code.
            pub const ALL: &'static [Self] = <Self as VariantArray>::VARIANTS;
        }
    )*};
}

vocabulary!(
    Fault,
    PlanarFault,
    DisarmReason,
    ResetCause,
    Routine,
    CalState,
    LoadError,
    PhaseEvent,
    Refusal,
    ParamKind,
    Pacing,
    LateCause
);

/// What paces the robot's control periods (`CostStats::pacing`), and so
/// whether their starts are checked against the period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[repr(u8)]
pub enum Pacing {
    /// A trigger at the control rate (the board's timer, QEMU's SysTick):
    /// every start is checked.
    #[strum(serialize = "a trigger at the control rate (starts checked)")]
    Trigger = 0,
    /// No clock counts the periods' time (the simulator): no check.
    #[strum(serialize = "the simulator (no clock: starts not checked)")]
    NoClock = 1,
    /// The host paces them (hardware in the loop): no check.
    #[strum(serialize = "the host's samples (starts not checked)")]
    Host = 2,
    /// A trigger slowed to what the chip sustains (the simulated hopper on
    /// a board): no check.
    #[strum(serialize = "the rate the chip sustains (starts not checked)")]
    Sustained = 3,
}

/// How a period was late (`CostStats::late_cause`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[repr(u8)]
pub enum LateCause {
    /// The next period's trigger came before it ended.
    #[strum(serialize = "missed its deadline")]
    Deadline = 0,
    /// It started outside the jitter bound.
    #[strum(serialize = "started off the period")]
    Start = 1,
}

/// One fault the robot's supervisor latches: its code is its bit in
/// `Status::faults` and `Telemetry::faults` (bit `n` is the fault of code
/// `n`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum Fault {
    /// A measurement is NaN or infinite.
    SensorNonfinite = 0,
    /// A measurement is outside its plausible range.
    SensorRange = 1,
    /// An encoder counter changed more in one period than the fastest
    /// physical motion allows.
    EncoderJump = 2,
    /// Load cell and potentiometer disagree about ground contact.
    ContactDisagree = 3,
    /// The nut is predicted to reach a stroke soft limit even under full
    /// braking.
    StrokeLimit = 4,
    /// The requested current is far beyond the limit.
    Overcurrent = 5,
    /// The emergency stop is pressed.
    Estop = 6,
    /// The servo amplifier reports a fault.
    AmpFault = 7,
    /// The control period overran.
    Overrun = 8,
    /// Writing the DAC failed.
    DacError = 9,
    /// The requested current is NaN or infinite.
    CommandNonfinite = 10,
    /// Load cell, potentiometer and motor encoder disagree.
    SensorDisagree = 11,
    /// The motor encoder stopped counting while the motor turned fast.
    EncoderFrozen = 12,
    /// The period runner's own check of a period's output failed.
    SelfCheck = 13,
    /// The motor winding's estimated temperature reached its trip level.
    Overtemperature = 14,
}

impl Fault {
    /// Its bit in a fault set.
    pub const fn bit(self) -> u16 {
        1 << (self as u8)
    }

    /// The names of the faults in `bits`, in bit order, and the bits no
    /// known fault has.
    pub fn names(bits: u16) -> (impl Iterator<Item = &'static str>, u16) {
        let known = Self::ALL.iter().fold(0u16, |a, f| a | f.bit());
        (
            Self::ALL
                .iter()
                .filter(move |f| bits & f.bit() != 0)
                .map(|f| f.name()),
            bits & !known,
        )
    }
}

/// Why the robot is disarmed (`ArmState::Disarmed`'s code).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum DisarmReason {
    /// Power-on or a reset other than the watchdog's.
    Boot = 0,
    /// The watchdog reset the MCU: the control loop stopped or misbehaved.
    WatchdogReset = 1,
    /// The operator asked.
    Command = 2,
    /// The e-stop was pressed.
    Estop = 3,
    /// A fault latched.
    Fault = 4,
    /// No valid link frame within the timeout.
    LinkLost = 5,
}

/// One reset cause the board read at boot (`BootInfo::resets`, bit `n` is
/// the cause of code `n`; RCC_CSR's flags from bit 25, RM0090 7.3.21).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum ResetCause {
    /// The supply fell below the brown-out level.
    BrownOut = 0,
    /// The NRST pin (the reset button, a debugger).
    Pin = 1,
    /// Power-on or power-down.
    PowerOn = 2,
    /// Software (a requested restart, a debugger's reset).
    Software = 3,
    /// The independent watchdog (the control task stopped).
    #[strum(serialize = "watchdog")]
    IndependentWatchdog = 4,
    /// The window watchdog (unused).
    WindowWatchdog = 5,
    /// Low-power management.
    LowPower = 6,
}

impl ResetCause {
    /// The causes in the set `bits`, in bit order.
    pub fn in_set(bits: u8) -> impl Iterator<Item = ResetCause> {
        Self::ALL
            .iter()
            .copied()
            .filter(move |c| bits & (1 << *c as u8) != 0)
    }
}

/// A bring-up routine (`Request::Calibrate` and the reports' code).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum Routine {
    /// Raw codes, noise and still counters, amplifier off.
    #[strum(serialize = "sensors")]
    SensorCheck = 0,
    /// Load-cell tare and potentiometer zero with the leg unloaded.
    Tare = 1,
    /// A current pulse: do the motor encoder and the load cell count the
    /// right way?
    Direction = 2,
    /// The nut driven to its upper stop, the motor encoder zeroed there.
    Home = 3,
    /// A nut sweep: the spring rate by least squares.
    Spring = 4,
    /// The height encoder zeroed with the toe on the ground.
    Height = 5,
    /// A standing nut sweep: the robot's weight, hence the load cell's gain.
    Weight = 6,
}

impl Routine {
    /// Whether it drives the motor (the amplifier is on while it runs, and
    /// it lasts as long as its moves).
    pub const fn drives_motor(self) -> bool {
        matches!(
            self,
            Routine::Direction | Routine::Home | Routine::Spring | Routine::Weight
        )
    }
}

/// Where a bring-up routine is (the reports' `state`); a failure's name
/// says what to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[repr(u8)]
pub enum CalState {
    /// Nothing has run since boot.
    #[strum(serialize = "idle")]
    Idle = 0,
    /// Measuring.
    #[strum(serialize = "running")]
    Running = 1,
    /// Finished; the results applied.
    #[strum(serialize = "done")]
    Done = 2,
    /// An encoder moved.
    #[strum(serialize = "failed: an encoder moved (hold the robot still)")]
    FailedMoving = 3,
    /// The sensors could not be read.
    #[strum(serialize = "failed: the sensors could not be read")]
    FailedSensors = 4,
    /// The new offsets are out of the parameters' ranges.
    #[strum(serialize = "failed: the new offsets are out of the parameters' ranges")]
    FailedApply = 5,
    /// A fault, the e-stop or a lost link stopped it.
    #[strum(serialize = "failed: a fault, the e-stop or a lost link stopped it (amplifier off)")]
    FailedFault = 6,
    /// The nut did not move.
    #[strum(serialize = "failed: the nut did not move (amplifier not enabled or not wired?)")]
    FailedNoMotion = 7,
    /// The nut moved up on a down command.
    #[strum(
        serialize = "failed: the nut moved up on a down command: the motor or its encoder is reversed"
    )]
    FailedReversed = 8,
    /// The load cell did not see the spring compress.
    #[strum(
        serialize = "failed: the nut moved down but the load cell did not see the spring compress (reversed?)"
    )]
    FailedLoadcellReversed = 9,
    /// No stop within the stroke.
    #[strum(serialize = "failed: no stop within the stroke")]
    FailedNoStop = 10,
    /// The spring fit is implausible.
    #[strum(serialize = "failed: the spring fit is implausible")]
    FailedFit = 11,
    /// The load cell does not carry the robot.
    #[strum(
        serialize = "failed: the load cell does not carry the robot (put the toe on the ground)"
    )]
    FailedNotOnGround = 12,
    /// The body did not rise with the nut.
    #[strum(serialize = "failed: the body did not rise with the nut (let go of it)")]
    FailedBodyHeld = 13,
    /// The weight read is implausible.
    #[strum(
        serialize = "failed: the weight read is implausible (not within a factor of two of the configured one)"
    )]
    FailedWeight = 14,
}

/// Why the saved calibration was not loaded at boot
/// (`StoredInfo::boot_error`; 0 is none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum LoadError {
    /// Too short, or not a calibration record.
    NotARecord = 1,
    /// Written by a firmware with another format version.
    #[strum(serialize = "other-version")]
    Version = 2,
    /// The CRC does not match: a torn or corrupted write.
    #[strum(serialize = "bad-crc")]
    Crc = 3,
    /// An entry names no parameter of this firmware.
    UnknownEntry = 4,
    /// A value is refused by its parameter.
    #[strum(serialize = "value-refused")]
    Refused = 5,
}

/// An event of the robot's phase estimator (`HilActuate::event`; 0 is
/// none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum PhaseEvent {
    /// Flight to stance.
    Touchdown = 1,
    /// Stance to flight.
    Liftoff = 2,
    /// The top of a flight.
    Apex = 3,
    /// The deepest compression of a stance.
    Bottom = 4,
}

/// Why the robot refused a request (`Response::Refused`'s code): an arm
/// refusal, a parameter's, a bring-up routine's, or the link's own. One
/// name per meaning: where the arming check and a routine refuse for the
/// same reason (a latched fault, the e-stop), it is one code.
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum Refusal {
    /// A fault is latched (reset it first, while disarmed).
    Faulted = 0,
    /// The e-stop is pressed.
    EstopPressed = 1,
    /// No valid link frame within the timeout (and not untethered).
    LinkDown = 2,
    /// The sensors could not be read, or a value is not finite.
    SensorsImplausible = 3,
    /// The nut is not within the home tolerance of its upper stop.
    NutNotHome = 4,
    /// Nut or body moves faster than the still velocity.
    Moving = 5,
    /// The core clock is not the one the board's clock profile names.
    ClockFallback = 6,
    /// The brown-out reset is off in the option bytes.
    BrownOutResetOff = 7,
    /// The crystal measured at boot is not the one the clock profile names.
    #[strum(serialize = "crystal-not-the-profiles")]
    CrystalMismatch = 8,
    /// `arming.require_tare` is on and no tare has succeeded since boot.
    NotCalibrated = 9,
    /// A bring-up routine is running.
    Calibrating = 10,
    /// The direction check found the motor encoder or the load cell
    /// counting the wrong way.
    #[strum(serialize = "encoder-or-motor-direction-reversed")]
    DirectionReversed = 11,
    /// `arming.require_home` is on and the nut was not homed since boot.
    NotHomed = 12,
    /// A disarm was asked for in the same period as the arm.
    DisarmRequested = 13,
    /// No parameter has this name.
    UnknownParameter = 14,
    /// The value is outside the parameter's range, or not whole where it
    /// must be.
    OutOfRange = 15,
    /// The parameter belongs to a controller that is not selected.
    ControllerNotSelected = 16,
    /// Only while disarmed.
    DisarmFirst = 17,
    /// The new configuration as a whole breaks a cross-field rule.
    InvalidConfiguration = 18,
    /// Another request of the kind is still being handled: ask again.
    Busy = 19,
    /// No bring-up routine has this code.
    UnknownRoutine = 20,
    /// The routine's duration is not within 0.01..=10 s.
    BadDuration = 21,
    /// Homing needs a passed direction check since boot.
    CheckDirectionFirst = 22,
    /// The spring sweep and the weighing need the nut homed since boot.
    HomeFirst = 23,
    /// The weighing needs the load cell tared (or a saved calibration).
    TareFirst = 24,
    /// The robot is restarting (to write its flash).
    Restarting = 25,
    /// Nothing measured yet since boot.
    NoMeasurementYet = 26,
    /// Some latched faults' causes are still present.
    FaultsRemain = 27,
    /// A save is in progress.
    Saving = 28,
    /// No table entry has this index.
    NoSuchIndex = 29,
    /// The thermal protection's parameters are locked on this robot.
    ProtectionLocked = 30,
    /// The hoist's lift is outside its range.
    LiftOutOfRange = 31,
    /// Only a simulated robot does this (a real one's e-stop is a button).
    NotSimulated = 32,
    /// An arm request is already being decided.
    Arming = 33,
    /// The leg carries the robot for a routine that needs the toe free:
    /// hang the robot on the hoist.
    LegLoaded = 34,
    /// The toe is not on the ground for a routine that needs it there.
    NotOnGround = 35,
    /// The board cannot save: the hardware watchdog option (WDG_SW = 0)
    /// would reset it in the middle of the sector erase.
    HardwareWatchdogOption = 36,
    /// The board cannot save: its supply is below the sector erase's
    /// minimum (the PVD at 2.8 V).
    #[strum(serialize = "supply-too-low-to-erase-flash")]
    SupplyLow = 37,
    /// The robot is another machine (the planar one): it has no such
    /// table, routine or figure.
    #[strum(serialize = "not-on-this-machine")]
    NotThisMachine = 38,
}

/// What the planar machine's guard latched (`PlanarTelemetry::fault`'s
/// code; 0 is nothing): both amplifiers are off until it is reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum PlanarFault {
    /// A measurement was not finite.
    Nonfinite = 1,
    /// The body pitched beyond its limit.
    Pitch = 2,
    /// The leg swung beyond its limit.
    LegAngle = 3,
    /// The hip fell below its height.
    Fall = 4,
    /// The hip motor's winding reached its trip temperature.
    HipOvertemperature = 5,
    /// The leg motor's winding reached its trip temperature.
    LegOvertemperature = 6,
}

/// What kind of value a parameter holds (`ParamMeta::kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, IntoStaticStr, VariantArray, FromRepr)]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum ParamKind {
    /// A real number in its unit.
    Real = 0,
    /// A whole number (counts, samples, codes).
    Count = 1,
    /// 0 (off) or 1 (on).
    Flag = 2,
    /// The index of one of its names.
    Choice = 3,
}

/// A refusal's code as it travels (`Response::Refused`): a plain byte, so a
/// newer robot's unknown reason still decodes; it prints as its name, or as
/// the number when this end does not know it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(transparent)]
pub struct RefusalCode(pub u8);

impl RefusalCode {
    /// The reason, if this end knows the code.
    pub const fn refusal(self) -> Option<Refusal> {
        Refusal::from_code(self.0)
    }
}

impl From<Refusal> for RefusalCode {
    fn from(r: Refusal) -> Self {
        Self(r.code())
    }
}

impl PartialEq<Refusal> for RefusalCode {
    fn eq(&self, r: &Refusal) -> bool {
        self.0 == r.code()
    }
}

impl core::fmt::Display for RefusalCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self.refusal() {
            Some(r) => f.write_str(r.name()),
            None => write!(f, "refusal {}", self.0),
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn codes_are_positions_and_names_unique() {
        fn check<T: Copy + PartialEq + core::fmt::Debug>(
            all: &[T],
            code: impl Fn(T) -> u8,
            from: impl Fn(u8) -> Option<T>,
            name: impl Fn(T) -> &'static str,
        ) {
            for (i, v) in all.iter().enumerate() {
                assert_eq!(from(code(*v)), Some(*v));
                for w in &all[i + 1..] {
                    assert_ne!(name(*v), name(*w));
                }
            }
        }
        check(Fault::ALL, Fault::code, Fault::from_code, Fault::name);
        check(
            DisarmReason::ALL,
            DisarmReason::code,
            DisarmReason::from_code,
            DisarmReason::name,
        );
        check(
            ResetCause::ALL,
            ResetCause::code,
            ResetCause::from_code,
            ResetCause::name,
        );
        check(
            Routine::ALL,
            Routine::code,
            Routine::from_code,
            Routine::name,
        );
        check(
            CalState::ALL,
            CalState::code,
            CalState::from_code,
            CalState::name,
        );
        check(
            LoadError::ALL,
            LoadError::code,
            LoadError::from_code,
            LoadError::name,
        );
        check(
            PhaseEvent::ALL,
            PhaseEvent::code,
            PhaseEvent::from_code,
            PhaseEvent::name,
        );
        check(
            ParamKind::ALL,
            ParamKind::code,
            ParamKind::from_code,
            ParamKind::name,
        );
        check(
            PlanarFault::ALL,
            PlanarFault::code,
            PlanarFault::from_code,
            PlanarFault::name,
        );
        check(
            Refusal::ALL,
            Refusal::code,
            Refusal::from_code,
            Refusal::name,
        );
        assert_eq!(
            std::format!("{}", RefusalCode::from(Refusal::DisarmFirst)),
            "disarm-first"
        );
        assert_eq!(std::format!("{}", RefusalCode(200)), "refusal 200");
        assert_eq!(Fault::from_code(15), None);
        assert_eq!(Routine::SensorCheck.name(), "sensors");
        assert_eq!(ResetCause::IndependentWatchdog.name(), "watchdog");
        assert_eq!(Fault::AmpFault.name(), "amp-fault");
        let (names, unknown) = Fault::names(Fault::Estop.bit() | Fault::Overrun.bit() | 0x8000);
        assert_eq!(names.collect::<std::vec::Vec<_>>(), ["estop", "overrun"]);
        assert_eq!(unknown, 0x8000);
    }
}
