//! Bring-up routines the firmware runs on command while disarmed
//! (`hopper-link calibrate ...`): they measure with the amplifier off
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
//! - [`Routine::Height`]: with the toe on the ground (the robot standing,
//!   amplifier off), the height encoder's origin moved so that the body
//!   height reads `l0 - x` (the potentiometer's leg compression `x`);
//!   refused when the load cell does not carry the robot.
//!
//! The motor-driving routines enable the amplifier, disarmed, at no more
//! than `bringup.current_limit_a`, with the supervisor checking every
//! period as when armed: a fault, the e-stop or a lost link ends them with
//! the amplifier off ([`CalState::FailedFault`]).
//! - [`Routine::Direction`] (toe free): a 0.1 s current pulse down; the
//!   motor encoder must count the nut down and the load cell must see the
//!   spring compress (`k dp` within a factor of three), else arming is
//!   refused as `encoder-or-motor-direction-reversed` until a check passes.
//! - [`Routine::Home`] (after a passed direction check): the nut driven up
//!   at `bringup.speed_mps` until it stalls on its upper stop (0.5 mm
//!   behind its reference), the motor encoder's zero put there. The
//!   incremental encoder boots wherever the nut stands, so this is a
//!   per-boot routine (`arming.require_home`).
//! - [`Routine::Spring`] (homed, body held): a slow sweep of
//!   `bringup.sweep_m` down and back; the least-squares line of the load
//!   cell's force against the spring compression `p + x` gives the rate
//!   `k`, applied as `supervisor.spring_rate_n_per_m` (what the spring
//!   cross-check and the contact evidence use), and an intercept
//!   `k delta0 + F_offset`: a load-cell offset and the preload are both
//!   constant forces, not separable by a sweep, so the preload stays as
//!   configured and the tare (run after the sweep) takes the offset.
//!
//! - [`Routine::Weight`] (homed and tared, standing on the toe): a slow
//!   nut sweep down and back that lifts the body on the spring and lowers
//!   it again. Quasi-static, the spring carries the robot's weight plus the
//!   friction on the leg lifting it and minus it lowering it: the mean of
//!   the two forces is the weight `(M + m_s) g` as the load cell reads it,
//!   half their difference the stance friction. The load cell's gain is
//!   the one error a tare (a zero) cannot see and the spring sweep cannot
//!   tell from the rate (both scale with it): the weight it reads against
//!   the configured one is that gain, and both
//!   `calibration.loadcell_gain_n_per_code` and
//!   `supervisor.spring_rate_n_per_m` (fitted with the same load cell) are
//!   divided by it. The sweep is 60% of the standing leg compression at
//!   most (the leg stays in its stroke), refused when the leg is not
//!   compressed by half the weight's spring deflection (the toe is not on
//!   the ground), and it fails when the body did not rise (held).
//!
//! Each routine that needs the toe somewhere ([`Routine::stance`]) is
//! refused where the sensors say it is not: `LegLoaded` for the hoisted
//! ones when both the load cell and the potentiometer say the leg
//! carries the robot, `NotOnGround` for the standing ones when the load
//! cell does not (the period runner's `check_stance`).
//!
//! The moves track a reference at `bringup.speed_mps` with the flight PD's
//! gains (eq 4.4) plus the spring's measured force as feed-forward, so the
//! nut moves at the set speed whatever the spring pushes.
//!
//! Saving the results is `crate::persist`'s. Not built: the stroke to the
//! lower stop.
//!
//! This file holds the routines, their states, refusals and reports; the
//! statistics are in `stats` ([`Stats`], [`Regression`]) and the state
//! machine that runs a routine in `calibrator` ([`Calibrator`]).

mod calibrator;
mod stats;

pub use calibrator::{Calibrator, DriveInput, DriveParams, STALL_LAG_M};
pub use stats::{Regression, Stats};

use crate::param::InvalidField;

crate::param::config! {
    /// The motor-driving routines' limits (the parameter table's `bringup.*`).
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct BringupConfig;
    params {
        58 BRINGUP_CURRENT_LIMIT_A current_limit_a: f32 {
            "bringup.current_limit_a", "A", Real, [0.1, 10.0], 6.0, DISARMED,
            "Largest current a motor-driving bring-up routine commands (6 A: 200 N on the nut, 18% of the amplifier's limit)."
        }
        59 BRINGUP_SPEED_MPS speed_mps: f32 {
            "bringup.speed_mps", "m/s", Real, [0.001, 0.05], 0.005, DISARMED,
            "Nut speed of the homing move and the spring sweep (5 mm/s: a stop reached at it stores 5 mJ in the 426 kg reflected rotor inertia)."
        }
        60 BRINGUP_SWEEP_M sweep_m: f32 {
            "bringup.sweep_m", "m", Real, [0.002, 0.03], 0.01, DISARMED,
            "Nut travel of the spring sweep, down from the upper stop and back."
        }
    }
}

impl BringupConfig {
    /// Every field within its parameter's range, else the first that is not.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// What a routine does (the discriminant is the wire code; the name,
/// kebab-case, is the link's).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr, strum::VariantArray, strum::FromRepr,
)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
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
    /// From its wire code.
    pub const fn from_code(code: u8) -> Option<Routine> {
        Self::from_repr(code)
    }

    /// Kebab-case name.
    pub fn name(self) -> &'static str {
        self.into()
    }

    /// Every routine, by wire code.
    pub const ALL: &'static [Routine] = <Routine as strum::VariantArray>::VARIANTS;

    /// Where the toe must be (`None`: anywhere).
    pub const fn stance(self) -> Option<Stance> {
        match self {
            Routine::SensorCheck => None,
            Routine::Tare | Routine::Direction | Routine::Home | Routine::Spring => {
                Some(Stance::Free)
            }
            Routine::Height | Routine::Weight => Some(Stance::OnGround),
        }
    }

    /// Whether it drives the motor (the amplifier is on while it runs).
    pub const fn drives_motor(self) -> bool {
        matches!(
            self,
            Routine::Direction | Routine::Home | Routine::Spring | Routine::Weight
        )
    }
}

/// Why a routine did not start (the name, kebab-case, is the link's).
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr, strum::VariantArray)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[strum(serialize_all = "kebab-case")]
pub enum CalRefusal {
    /// The amplifier is armed: routines run disarmed.
    #[strum(serialize = "disarm-first")]
    Armed,
    /// The e-stop is pressed.
    EstopPressed,
    /// Another routine is running.
    Busy,
    /// No such routine.
    #[strum(serialize = "unknown-routine")]
    Unknown,
    /// The duration is not within 0.01..=10 s.
    #[strum(serialize = "bad-duration")]
    Duration,
    /// A fault is latched (reset it first).
    Faulted,
    /// No valid link frame within the timeout: a routine that drives the
    /// motor needs the operator's host on the line.
    LinkDown,
    /// Homing needs a passed direction check since boot.
    #[strum(serialize = "check-direction-first")]
    DirectionFirst,
    /// The spring sweep and the weighing need the nut homed since boot.
    HomeFirst,
    /// The weighing needs the load cell tared (or a saved calibration).
    TareFirst,
    /// The leg carries the robot (the load cell beyond the flight force by
    /// half the body's weight, and the potentiometer compressed by half
    /// its deflection) for a routine that needs the toe free: hang the
    /// robot on the hoist.
    LegLoaded,
    /// The load cell does not carry half the body's weight beyond the
    /// flight force, for a routine that needs the toe on the ground.
    NotOnGround,
    /// No period has read the sensors yet.
    NoMeasurementYet,
}

/// Where the toe must be for a routine: what its measurement assumes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stance {
    /// The toe hangs free (the robot on the hoist): a tare zeroes the
    /// unloaded leg, the direction pulse and the homing move the nut
    /// against the spring alone, the sweep fits the spring alone.
    Free,
    /// The toe on the ground, the robot's weight on the leg.
    OnGround,
}

impl CalRefusal {
    /// Kebab-case name, as the link prints it.
    pub fn name(self) -> &'static str {
        self.into()
    }
}

/// Where a routine is (the discriminant is the wire code).
#[derive(Debug, Clone, Copy, PartialEq, Eq, strum::VariantArray)]
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
    /// A fault latched, the e-stop was pressed or the link was lost while
    /// the motor was driven: amplifier off, nothing applied.
    FailedFault,
    /// The direction pulse moved the nut less than 0.1 mm.
    FailedNoMotion,
    /// The direction pulse moved the nut up: the motor or its encoder is
    /// reversed.
    FailedReversed,
    /// The nut moved down but the load cell did not see the spring
    /// compress: the load cell is reversed (or not on the spring).
    FailedLoadcellReversed,
    /// The homing move found no stop within the stroke and 10 mm more.
    FailedNoStop,
    /// The spring fit is implausible: too few points, or a rate not within
    /// a factor of two of the configured one.
    FailedFit,
    /// The load cell does not carry the robot's weight: the toe is not on
    /// the ground.
    FailedNotOnGround,
    /// The weighing's sweep did not lift the body by half the sweep: the
    /// body is held.
    FailedBodyHeld,
    /// The weight read is not within a factor of two of the configured one,
    /// or a half of the sweep gave fewer than 100 samples.
    FailedWeight,
}

/// What a measuring routine measured (so far, while running): the link's
/// calibration report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CalibrationReport {
    /// The routine.
    pub routine: Routine,
    /// Its state.
    pub state: CalState,
    /// Samples averaged.
    pub samples: u32,
    /// Load-cell mean, ADC code.
    pub loadcell_mean_code: f32,
    /// Load-cell standard deviation, ADC code.
    pub loadcell_std_code: f32,
    /// Potentiometer mean, ADC code.
    pub pot_mean_code: f32,
    /// Potentiometer standard deviation, ADC code.
    pub pot_std_code: f32,
    /// Motor-encoder span over the routine, counts.
    pub motor_span_counts: u32,
    /// Height-encoder span over the routine, counts.
    pub height_span_counts: u32,
    /// The tare's load-cell offset, code (NaN otherwise).
    pub loadcell_offset_code: f32,
    /// The tare's potentiometer offset, code (NaN otherwise).
    pub pot_offset_code: f32,
}

/// What the motor-driving and height routines found (NaN where the
/// routine does not measure a value).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BringupReport {
    /// The routine.
    pub routine: Routine,
    /// Its state.
    pub state: CalState,
    /// Direction check: the nut's travel in the pulse, m (down positive).
    pub nut_travel_m: f32,
    /// Direction check: the load cell's change in the pulse, N.
    pub force_change_n: f32,
    /// Homing: where the upper stop was in the encoder's frame before it
    /// was zeroed there, m.
    pub nut_offset_m: f32,
    /// Spring sweep: the fitted rate, N/m.
    pub spring_rate_n_per_m: f32,
    /// Spring sweep: the fit's force at zero compression, N.
    pub spring_intercept_n: f32,
    /// Spring sweep: RMS of the residuals, N.
    pub fit_rms_n: f32,
    /// Spring sweep: points fitted.
    pub fit_points: u32,
    /// Spring sweep: the compressions' standard deviation, m.
    pub fit_span_m: f32,
    /// Height zero: the correction applied to the body height, m.
    pub height_offset_m: f32,
    /// The largest current commanded, A.
    pub peak_current_a: f32,
}

/// What the last weighing found (NaN where it did not measure).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeighingReport {
    /// Its state (idle when the last routine was another).
    pub state: CalState,
    /// The weight measured, N.
    pub weight_n: f32,
    /// The weight configured, N.
    pub configured_weight_n: f32,
    /// The friction measured, N.
    pub friction_n: f32,
    /// How far the body rose, m.
    pub body_rise_m: f32,
}

impl CalState {
    /// Every state, by wire code.
    pub const ALL: &'static [CalState] = <CalState as strum::VariantArray>::VARIANTS;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The names the link sends as a routine's refusal and `hopper-link`
    /// prints: a contract with the operator's tools.
    #[test]
    fn refusal_names_are_the_contract() {
        use CalRefusal as R;
        let names = [
            (R::Armed, "disarm-first"),
            (R::EstopPressed, "estop-pressed"),
            (R::Busy, "busy"),
            (R::Unknown, "unknown-routine"),
            (R::Duration, "bad-duration"),
            (R::Faulted, "faulted"),
            (R::LinkDown, "link-down"),
            (R::DirectionFirst, "check-direction-first"),
            (R::HomeFirst, "home-first"),
            (R::TareFirst, "tare-first"),
        ];
        for (r, name) in names {
            assert_eq!(r.name(), name);
        }
    }
}
