//! The firmware's runtime parameters, each defined once: name, unit, range,
//! default, whether it may change while the motor is driven, and a one-line
//! doc.
//!
//! The configuration types' `Default` impls and their `validate` checks read
//! these entries, the host tools (`hopper-sim`'s scenario files and sweeps)
//! look parameters up here by name, the link of issue #10 exposes exactly
//! [`TABLE`], and `docs/parameters.md` is generated from it (a test fails
//! when the page is stale).
//!
//! Every value is an `f32`: a flag is 0 or 1, a choice is the index of one
//! of its names, a count is a whole number. [`get`] and [`set`] read and
//! write a [`HopperConfig`] by name; a parameter of a controller other than
//! the selected one is refused by [`set`] (select the controller first:
//! that starts it from its defaults).

use crate::hopper::HopperConfig;
use crate::laws::{energy_apex, step_closed, ControllerKind, InvalidField, StanceLaw, Strategy};

/// What kind of value a parameter holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Kind {
    /// A real number in its unit.
    Real,
    /// A whole number (counts, samples, codes).
    Count,
    /// 0 (off) or 1 (on).
    Flag,
    /// The index of one of these names.
    Choice(&'static [&'static str]),
}

/// One runtime parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Param {
    /// Name, as a path in the configuration (`flight.kp_a_per_rad`).
    pub name: &'static str,
    /// Unit (SI; `1` for a dimensionless number, `-` for flags and choices).
    pub unit: &'static str,
    /// The value's kind.
    pub kind: Kind,
    /// Smallest allowed value (inclusive).
    pub min: f32,
    /// Largest allowed value (inclusive).
    pub max: f32,
    /// The default.
    pub default: f32,
    /// Whether it may change while the motor is driven (armed); otherwise
    /// only while the amplifier is disabled.
    pub live: bool,
    /// One line: what it is, and where it comes from (thesis equation);
    /// empty in the firmware image.
    pub doc: &'static str,
}

impl Param {
    /// `v` if it is finite and within `min..=max` (and whole for counts,
    /// flags and choices), else this parameter's name.
    pub fn check(&self, v: f32) -> Result<f32, InvalidField> {
        let whole = !matches!(self.kind, Kind::Real);
        let ok =
            v.is_finite() && v >= self.min && v <= self.max && (!whole || v == libm::truncf(v));
        if ok {
            Ok(v)
        } else {
            Err(InvalidField(self.name))
        }
    }

    /// Checks a flag's or choice's stored value (`true` is 1).
    pub fn check_flag(&self, on: bool) -> Result<bool, InvalidField> {
        self.check(if on { 1.0 } else { 0.0 }).map(|_| on)
    }

    /// The default of a flag.
    pub const fn default_flag(&self) -> bool {
        self.default != 0.0
    }
}

const LIVE: bool = true;
const DISARMED: bool = false;

macro_rules! param {
    ($id:ident, $name:literal, $unit:literal, $kind:expr, $min:expr, $max:expr, $default:expr, $live:expr, $doc:literal) => {
        #[doc = $doc]
        pub const $id: Param = Param {
            name: $name,
            unit: $unit,
            kind: $kind,
            min: $min,
            max: $max,
            default: $default,
            live: $live,
            // The firmware image carries no docs (the host tools and
            // docs/parameters.md do): the link's table needs names and
            // units only, and the docs were 7 KB of flash.
            doc: if cfg!(target_os = "none") { "" } else { $doc },
        };
    };
}

/// The controllers [`CONTROLLER`] chooses from, by name (the index is the
/// value): [`ControllerKind::ALL`]'s names.
pub const CONTROLLER_NAMES: [&str; 9] = controller_names();

#[allow(clippy::indexing_slicing)] // const evaluation: a bad index fails the build.
const fn controller_names() -> [&'static str; 9] {
    let mut names = [""; 9];
    let mut i = 0;
    while i < names.len() {
        names[i] = ControllerKind::ALL[i].name();
        i += 1;
    }
    names
}

/// Names of [`STEP_CLOSED_GAIN`]'s choices.
const STEP_CLOSED_GAINS: [&str; 2] = ["fixed", "normalised"];
/// Names of [`ENERGY_APEX_MEASURE`]'s choices.
const ENERGY_MEASURES: [&str; 2] = ["total", "body"];

use Kind::{Count, Flag, Real};

// --- The controller and its target -------------------------------------
param!(
    CONTROLLER,
    "controller",
    "-",
    Kind::Choice(&CONTROLLER_NAMES),
    0.0,
    8.0,
    5.0,
    DISARMED,
    "The controller that runs in stance and flight (selecting one starts it from its defaults)."
);
param!(
    TARGET_APEX_M,
    "target_apex_m",
    "m",
    Real,
    0.0,
    1.0,
    0.05,
    LIVE,
    "Desired apex toe height H_D (E_D of eq 2.43)."
);

// --- Flight PD, eq 4.4 ----------------------------------------------------
param!(
    FLIGHT_KP,
    "flight.kp_a_per_rad",
    "A/rad",
    Real,
    0.0,
    1.0e4,
    20.3152,
    LIVE,
    "Flight PD position gain on the motor angle (eq 4.4; default eq 4.13; hopper-sim's design preset runs Table 2.1's 8e4 N/m on the nut, 1.8953 A/rad, with the Chapter 2 laws)."
);
param!(
    FLIGHT_KD,
    "flight.kd_a_s_per_rad",
    "A s/rad",
    Real,
    0.0,
    1.0e3,
    0.6077,
    LIVE,
    "Flight PD rate gain (eq 4.4; default eq 4.13; the design preset's Chapter 2 laws: Table 2.1's 300 N s/m, 0.0071073 A s/rad)."
);
param!(
    FLIGHT_START_M,
    "flight.start_position_m",
    "m",
    Real,
    0.0,
    1.0,
    0.0,
    LIVE,
    "Nut position the flight PD returns to (0: the upper stop; at most the stroke)."
);

// --- Thesis stance laws ---------------------------------------------------
param!(
    ENERGY_GAIN,
    "energy.gain_nm_per_j",
    "N m/J",
    Real,
    0.0,
    100.0,
    0.2,
    LIVE,
    "K_e of eq 2.52 (Table 2.1: 0.2)."
);
param!(
    ENERGY_ALLOW_NEGATIVE,
    "energy.allow_negative",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    LIVE,
    "Eq 2.52 may command negative torque on an energy surplus."
);
param!(
    CONSTANT_TORQUE_NM,
    "constant_torque.torque_nm",
    "N m",
    Real,
    -10.0,
    10.0,
    1.0,
    LIVE,
    "Open-loop stance torque (section 2.1.3.4; Table 2.1: 1 N m)."
);
param!(
    MODIFIED_TORQUE_NM,
    "modified_torque.torque_nm",
    "N m",
    Real,
    -10.0,
    10.0,
    1.0,
    LIVE,
    "Modified-torque law's torque in stance and late descent (section 4.4.3)."
);
param!(
    MODIFIED_TORQUE_APEX_FRACTION,
    "modified_torque.apex_fraction",
    "1",
    Real,
    0.0,
    1.0,
    0.4,
    LIVE,
    "Fraction of the last apex below which the descent starts the torque (section 4.4.3: 40 %)."
);
param!(
    STEP_OPEN_M,
    "step_open.step_m",
    "m",
    Real,
    0.0,
    1.0,
    0.01,
    LIVE,
    "Step height l1 of eq 2.49 (Table 2.1: 10 mm; clamped to the stroke)."
);
param!(
    STEP_OPEN_KP,
    "step_open.kp_n_per_m",
    "N/m",
    Real,
    0.0,
    1.0e7,
    8.0e4,
    LIVE,
    "Nut position loop gain k_p,f of eq 2.49 (Table 2.1)."
);
param!(
    STEP_OPEN_KD,
    "step_open.kd_n_s_per_m",
    "N s/m",
    Real,
    0.0,
    1.0e5,
    300.0,
    LIVE,
    "Nut velocity loop gain k_v,f of eq 2.49 (Table 2.1)."
);
param!(
    STEP_OPEN_FEEDFORWARD,
    "step_open.spring_feedforward",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    LIVE,
    "Add the measured spring force to the position loop."
);
param!(
    STEP_CLOSED_GAIN,
    "step_closed.gain",
    "-",
    Kind::Choice(&STEP_CLOSED_GAINS),
    0.0,
    1.0,
    0.0,
    LIVE,
    "k_p of eq 2.50: fixed (step_closed.kp_m_per_j) or eq 2.51 normalised by the compression."
);
param!(
    STEP_CLOSED_KP_M_PER_J,
    "step_closed.kp_m_per_j",
    "m/J",
    Real,
    0.0,
    1.0,
    2.0e-3,
    LIVE,
    "Fixed k_p of eq 2.50 (Table 2.1's 0.2 read as cm/J)."
);
param!(
    STEP_CLOSED_MIN_COMPRESSION_M,
    "step_closed.min_compression_m",
    "m",
    Real,
    1.0e-4,
    1.0,
    0.005,
    LIVE,
    "Floor on the compression in eq 2.51's normalised gain."
);
param!(
    STEP_CLOSED_KP,
    "step_closed.kp_n_per_m",
    "N/m",
    Real,
    0.0,
    1.0e7,
    8.0e4,
    LIVE,
    "Nut position loop gain of eq 2.50 (Table 2.1)."
);
param!(
    STEP_CLOSED_KD,
    "step_closed.kd_n_s_per_m",
    "N s/m",
    Real,
    0.0,
    1.0e5,
    300.0,
    LIVE,
    "Nut velocity loop gain of eq 2.50 (Table 2.1)."
);
param!(
    STEP_CLOSED_FEEDFORWARD,
    "step_closed.spring_feedforward",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    LIVE,
    "Add the measured spring force to the position loop."
);
param!(
    VELOCITY_GAIN,
    "velocity.gain_mps_per_j",
    "m/(s J)",
    Real,
    0.0,
    10.0,
    0.03,
    LIVE,
    "K_v of eq 2.53 (Table 2.1's 30 read as mm/(s J))."
);
param!(
    VELOCITY_LOOP_GAIN,
    "velocity.loop_gain_n_s_per_m",
    "N s/m",
    Real,
    0.0,
    1.0e6,
    5000.0,
    LIVE,
    "Velocity loop gain from nut speed error to force."
);
param!(
    VELOCITY_FEEDFORWARD,
    "velocity.spring_feedforward",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    LIVE,
    "Add the measured spring force to the velocity loop."
);

// --- energy-apex ------------------------------------------------------------
param!(
    ENERGY_APEX_GAIN,
    "energy_apex.gain_nm_per_j",
    "N m/J",
    Real,
    0.0,
    100.0,
    3.0,
    LIVE,
    "K_e of the inner eq 2.52 (full torque for a 0.33 J deficit)."
);
param!(
    ENERGY_APEX_ALLOW_NEGATIVE,
    "energy_apex.allow_negative",
    "-",
    Flag,
    0.0,
    1.0,
    0.0,
    LIVE,
    "The inner law may command negative torque."
);
param!(
    ENERGY_APEX_MEASURE,
    "energy_apex.measure",
    "-",
    Kind::Choice(&ENERGY_MEASURES),
    0.0,
    1.0,
    0.0,
    LIVE,
    "Energy fed back: total (eq 2.44) or body only."
);
param!(
    ENERGY_APEX_PROPORTIONAL,
    "energy_apex.proportional_gain",
    "1",
    Real,
    0.0,
    10.0,
    0.0,
    LIVE,
    "Outer loop's proportional gain on the last apex error (J per J)."
);
param!(
    ENERGY_APEX_INTEGRAL,
    "energy_apex.integral_gain",
    "1",
    Real,
    1.0e-3,
    9.99,
    0.6,
    LIVE,
    "Outer loop's integral gain on the apex error (J of offset per J)."
);
param!(
    ENERGY_APEX_MAX_OFFSET_J,
    "energy_apex.max_offset_j",
    "J",
    Real,
    0.0,
    1000.0,
    30.0,
    LIVE,
    "Upper bound on the outer loop's correction of E_D."
);
param!(
    ENERGY_APEX_MIN_OFFSET_J,
    "energy_apex.min_offset_j",
    "J",
    Real,
    -1000.0,
    0.0,
    -5.0,
    LIVE,
    "Lower bound on the outer loop's correction of E_D."
);
param!(
    ENERGY_APEX_SPIN_UP,
    "energy_apex.spin_up_fraction",
    "1",
    Real,
    0.0,
    1.0,
    0.0,
    LIVE,
    "Fraction of the target apex below which the descent runs the stance law (0: off)."
);

// --- shaped -------------------------------------------------------------------
param!(
    SHAPED_SPIN_UP_FRACTION,
    "shaped.spin_up_fraction",
    "1",
    Real,
    0.0,
    1.0,
    0.6,
    LIVE,
    "Fraction of the flight's apex below which the descent spins the rotor up."
);
param!(
    SHAPED_SPIN_UP_MIN_APEX_M,
    "shaped.spin_up_min_apex_m",
    "m",
    Real,
    0.0,
    1.0,
    0.005,
    LIVE,
    "Smallest flight apex that spins up."
);
param!(SHAPED_SWITCH_FRACTION, "shaped.switch_fraction", "1", Real, 0.0, 2.0, 0.6, LIVE,
    "Fraction of the model's stance time T = pi sqrt((M + m_s)/k) after which the push turns to braking.");
param!(
    SHAPED_BRAKE_FRACTION,
    "shaped.brake_fraction",
    "1",
    Real,
    0.0,
    1.0,
    1.0,
    LIVE,
    "Braking current, fraction of the current limit."
);
param!(
    SHAPED_INITIAL_LEVEL,
    "shaped.initial_level",
    "1",
    Real,
    0.0,
    1.0,
    1.0,
    LIVE,
    "Torque level of the first hop, fraction of the current limit."
);
param!(
    SHAPED_INTEGRAL_START,
    "shaped.integral_start",
    "1",
    Real,
    0.0,
    1.0,
    0.8,
    LIVE,
    "Starting integral of the per-hop level loop."
);
param!(
    SHAPED_LEVEL_GAIN,
    "shaped.level_gain_per_j",
    "1/J",
    Real,
    0.0,
    10.0,
    0.1,
    LIVE,
    "Integral gain of the level loop on the apex energy error."
);
param!(
    SHAPED_LEVEL_PROPORTIONAL,
    "shaped.level_proportional_per_j",
    "1/J",
    Real,
    0.0,
    10.0,
    0.2,
    LIVE,
    "Proportional gain of the level loop."
);
param!(
    SHAPED_BRAKING_MARGIN,
    "shaped.braking_margin",
    "1",
    Real,
    1.0e-3,
    1.0,
    0.7,
    LIVE,
    "Fraction of the available braking deceleration the flight return plans with."
);
param!(
    SHAPED_TRACKING_TIME_S,
    "shaped.tracking_time_s",
    "s",
    Real,
    1.0e-3,
    0.1,
    0.005,
    LIVE,
    "Time constant of the flight return's speed tracking."
);
param!(
    SHAPED_CREEP_SPEED_MPS,
    "shaped.creep_speed_mps",
    "m/s",
    Real,
    0.0,
    0.1,
    0.01,
    LIVE,
    "Speed at which the nut arrives at its stop."
);

// --- Phase estimator, supervisor limits, calibration ------------------------
// Set with the amplifier disabled only. Derived from the model and not
// listed: the overcurrent trip (10x the current limit), the stroke soft
// limits with the braking deceleration they assume, and the stops, the lead, torque constant and start height of the
// calibration, and the counter and converter widths (board facts).
param!(
    EST_TOUCHDOWN_FORCE_N,
    "estimator.touchdown_force_n",
    "N",
    Real,
    0.0,
    1.0e4,
    40.0,
    DISARMED,
    "Load-cell force beyond k (delta0 + p) that counts as touchdown evidence (8 sigma of 5 N)."
);
param!(
    EST_LIFTOFF_FORCE_N,
    "estimator.liftoff_force_n",
    "N",
    Real,
    -1.0e4,
    1.0e4,
    20.0,
    DISARMED,
    "Excess force below which liftoff is considered (below the touchdown force)."
);
param!(
    EST_TOUCHDOWN_COMPRESSION_M,
    "estimator.touchdown_compression_m",
    "m",
    Real,
    0.0,
    0.5,
    0.002,
    DISARMED,
    "Potentiometer compression above which touchdown is considered."
);
param!(
    EST_LIFTOFF_COMPRESSION_M,
    "estimator.liftoff_compression_m",
    "m",
    Real,
    -0.5,
    0.5,
    0.001,
    DISARMED,
    "Potentiometer compression below which liftoff is considered (below the touchdown compression)."
);
param!(
    EST_DEBOUNCE_SAMPLES,
    "estimator.debounce_samples",
    "samples",
    Count,
    1.0,
    255.0,
    3.0,
    DISARMED,
    "Consecutive agreeing samples needed to change phase."
);
param!(
    EST_FILTER_GAIN,
    "estimator.velocity_filter_gain",
    "1",
    Real,
    0.0,
    0.999,
    0.9,
    DISARMED,
    "Filter gain G of eq 4.1 for both velocities."
);
param!(
    EST_APEX_ARM_MPS,
    "estimator.apex_arm_velocity_mps",
    "m/s",
    Real,
    1.0e-4,
    10.0,
    0.1,
    DISARMED,
    "Upward body velocity that arms apex detection in flight."
);
param!(
    EST_BOTTOM_ARM_MPS,
    "estimator.bottom_arm_velocity_mps",
    "m/s",
    Real,
    1.0e-4,
    10.0,
    0.1,
    DISARMED,
    "Downward body speed that arms bottom detection in stance."
);
// --- Arming (issue 17) ------------------------------------------------------
param!(
    ARM_LINK_TIMEOUT_S,
    "arming.link_timeout_s",
    "s",
    Real,
    1.0e-3,
    60.0,
    0.2,
    DISARMED,
    "No valid link frame for this long disarms the amplifier (and a dead link refuses arming)."
);
param!(
    ARM_UNTETHERED,
    "arming.untethered",
    "-",
    Flag,
    0.0,
    1.0,
    0.0,
    DISARMED,
    "Run without a link: no link needed to arm, and link loss does not disarm (an explicit choice; the simulator sets it)."
);
param!(
    ARM_HOME_TOLERANCE_M,
    "arming.home_tolerance_m",
    "m",
    Real,
    0.0,
    0.05,
    0.001,
    DISARMED,
    "To arm, the nut must be at most this far from its upper stop."
);
param!(
    ARM_STILL_MPS,
    "arming.still_velocity_mps",
    "m/s",
    Real,
    1.0e-4,
    10.0,
    0.05,
    DISARMED,
    "To arm, nut and body must be slower than this."
);
param!(
    ESTOP_PRESS_S,
    "estop.press_s",
    "s",
    Real,
    0.0,
    0.01,
    2.0e-4,
    DISARMED,
    "The e-stop input pressed without a break for this long is a press (shorter is a glitch; the button also breaks the amplifier enable in hardware)."
);
param!(
    ESTOP_RELEASE_S,
    "estop.release_s",
    "s",
    Real,
    0.0,
    2.0,
    0.05,
    DISARMED,
    "The e-stop input released without a break for this long is a release (arming and fault resets wait for it: longer than a contact's bounce)."
);
param!(
    THERMAL_PROTECT,
    "thermal.protect",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    DISARMED,
    "Derate and fault on the winding temperature estimate; 0 only for control studies past the motor's thermal limit (the estimate is still reported), never on a robot."
);
param!(
    THERMAL_RESISTANCE_OHM,
    "thermal.winding_resistance_ohm",
    "ohm",
    Real,
    1.0e-3,
    100.0,
    0.299,
    DISARMED,
    "Motor winding resistance at 25 C (the RE 40 24 V winding's; use your motor's datasheet)."
);
param!(
    THERMAL_WINDING_TO_HOUSING,
    "thermal.winding_to_housing_k_per_w",
    "K/W",
    Real,
    1.0e-2,
    100.0,
    1.93,
    DISARMED,
    "Thermal resistance winding to housing (motor datasheet)."
);
param!(
    THERMAL_HOUSING_TO_AMBIENT,
    "thermal.housing_to_ambient_k_per_w",
    "K/W",
    Real,
    1.0e-2,
    100.0,
    4.65,
    DISARMED,
    "Thermal resistance housing to ambient (motor datasheet; a heat sink lowers it)."
);
param!(
    THERMAL_WINDING_TAU,
    "thermal.winding_time_constant_s",
    "s",
    Real,
    0.1,
    1.0e4,
    41.6,
    DISARMED,
    "Winding thermal time constant (motor datasheet)."
);
param!(
    THERMAL_HOUSING_TAU,
    "thermal.housing_time_constant_s",
    "s",
    Real,
    1.0,
    1.0e5,
    1120.0,
    DISARMED,
    "Motor (housing) thermal time constant (motor datasheet)."
);
param!(
    THERMAL_AMBIENT,
    "thermal.ambient_c",
    "degC",
    Real,
    -40.0,
    80.0,
    25.0,
    DISARMED,
    "Ambient temperature; the motor is taken to be at it at boot."
);
param!(
    THERMAL_DERATE,
    "thermal.derate_winding_c",
    "degC",
    Real,
    0.0,
    250.0,
    135.0,
    DISARMED,
    "Estimated winding temperature where the current limit starts to fall."
);
param!(
    THERMAL_TRIP,
    "thermal.trip_winding_c",
    "degC",
    Real,
    0.0,
    250.0,
    150.0,
    DISARMED,
    "Estimated winding temperature that latches overtemperature (5 K under the RE 40's 155 C)."
);
param!(
    THERMAL_DERATED_FRACTION,
    "thermal.derated_limit_fraction",
    "1",
    Real,
    0.05,
    1.0,
    0.5,
    DISARMED,
    "Current limit at the trip temperature, as a fraction of the amplifier's (linear from the derate temperature)."
);
param!(
    ARM_REQUIRE_TARE,
    "arming.require_tare",
    "-",
    Flag,
    0.0,
    1.0,
    0.0,
    DISARMED,
    "Refuse to arm until a tare (hopper-link calibrate tare) has succeeded since boot (the board sets it: its offsets are not saved yet)."
);
param!(
    ARM_REQUIRE_HOME,
    "arming.require_home",
    "-",
    Flag,
    0.0,
    1.0,
    0.0,
    DISARMED,
    "Refuse to arm until the nut was homed (hopper-link calibrate home, after calibrate direction) since boot: the motor encoder is incremental, its zero is lost at power-off."
);
param!(
    BRINGUP_CURRENT_LIMIT_A,
    "bringup.current_limit_a",
    "A",
    Real,
    0.1,
    10.0,
    6.0,
    DISARMED,
    "Largest current a motor-driving bring-up routine commands (6 A: 200 N on the nut, 18% of the amplifier's limit)."
);
param!(
    BRINGUP_SPEED_MPS,
    "bringup.speed_mps",
    "m/s",
    Real,
    0.001,
    0.05,
    0.005,
    DISARMED,
    "Nut speed of the homing move and the spring sweep (5 mm/s: a stop reached at it stores 5 mJ in the 426 kg reflected rotor inertia)."
);
param!(
    BRINGUP_SWEEP_M,
    "bringup.sweep_m",
    "m",
    Real,
    0.002,
    0.03,
    0.01,
    DISARMED,
    "Nut travel of the spring sweep, down from the upper stop and back."
);
param!(
    EST_PREDICT_CONTACT,
    "estimator.predict_contact",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    DISARMED,
    "Predict touchdown and liftoff from the height encoder (the toe reaching the ground within half a period); load cell and potentiometer confirm (0: those two alone, late by their thresholds)."
);
param!(
    EST_CONTACT_CONFIRM_S,
    "estimator.contact_confirm_s",
    "s",
    Real,
    1.0e-3,
    1.0,
    0.03,
    DISARMED,
    "Time within which load cell and potentiometer must confirm a predicted touchdown; else it is withdrawn (a liftoff) and prediction stays off."
);
param!(
    SUP_MAX_MOTOR_DELTA,
    "supervisor.max_motor_delta_counts",
    "counts",
    Count,
    1.0,
    1.0e6,
    64.0,
    DISARMED,
    "Largest plausible motor counter change per period (1000 rad/s at 2000 counts/rev and 10 kHz is 32, x2)."
);
param!(
    SUP_MAX_HEIGHT_DELTA,
    "supervisor.max_height_delta_counts",
    "counts",
    Count,
    1.0,
    1.0e6,
    32.0,
    DISARMED,
    "Largest plausible height counter change per period (10 m/s on a 20 mm pulley at 10 kHz is 16, x2)."
);
param!(
    SUP_NUT_POSITION_MIN_M,
    "supervisor.nut_position_min_m",
    "m",
    Real,
    -1.0,
    1.0,
    -0.01,
    DISARMED,
    "Lowest plausible nut position (stops at 0 and 0.05 m)."
);
param!(
    SUP_NUT_POSITION_MAX_M,
    "supervisor.nut_position_max_m",
    "m",
    Real,
    -1.0,
    1.0,
    0.06,
    DISARMED,
    "Highest plausible nut position (stops at 0 and 0.05 m)."
);
param!(
    SUP_NUT_VELOCITY_MIN_MPS,
    "supervisor.nut_velocity_min_mps",
    "m/s",
    Real,
    -100.0,
    100.0,
    -1.0,
    DISARMED,
    "Lowest plausible nut velocity (the no-load speed is 0.64 m/s)."
);
param!(
    SUP_NUT_VELOCITY_MAX_MPS,
    "supervisor.nut_velocity_max_mps",
    "m/s",
    Real,
    -100.0,
    100.0,
    1.0,
    DISARMED,
    "Highest plausible nut velocity (the no-load speed is 0.64 m/s)."
);
param!(
    SUP_MOTOR_SPEED_MIN_RAD_S,
    "supervisor.motor_speed_min_rad_s",
    "rad/s",
    Real,
    -1.0e5,
    1.0e5,
    -1200.0,
    DISARMED,
    "Lowest plausible motor speed (no-load 808 rad/s)."
);
param!(
    SUP_MOTOR_SPEED_MAX_RAD_S,
    "supervisor.motor_speed_max_rad_s",
    "rad/s",
    Real,
    -1.0e5,
    1.0e5,
    1200.0,
    DISARMED,
    "Highest plausible motor speed (no-load 808 rad/s)."
);
param!(
    SUP_BODY_HEIGHT_MIN_M,
    "supervisor.body_height_min_m",
    "m",
    Real,
    -10.0,
    100.0,
    0.4,
    DISARMED,
    "Lowest plausible body height z (l0 = 0.61 m)."
);
param!(
    SUP_BODY_HEIGHT_MAX_M,
    "supervisor.body_height_max_m",
    "m",
    Real,
    -10.0,
    100.0,
    3.0,
    DISARMED,
    "Highest plausible body height z (l0 = 0.61 m)."
);
param!(
    SUP_BODY_VELOCITY_MIN_MPS,
    "supervisor.body_velocity_min_mps",
    "m/s",
    Real,
    -1000.0,
    1000.0,
    -10.0,
    DISARMED,
    "Lowest plausible body velocity."
);
param!(
    SUP_BODY_VELOCITY_MAX_MPS,
    "supervisor.body_velocity_max_mps",
    "m/s",
    Real,
    -1000.0,
    1000.0,
    10.0,
    DISARMED,
    "Highest plausible body velocity."
);
param!(
    SUP_SPRING_FORCE_MIN_N,
    "supervisor.spring_force_min_n",
    "N",
    Real,
    -1.0e5,
    1.0e5,
    -50.0,
    DISARMED,
    "Lowest plausible spring force (both load-cell rails outside)."
);
param!(
    SUP_SPRING_FORCE_MAX_N,
    "supervisor.spring_force_max_n",
    "N",
    Real,
    -1.0e5,
    1.0e5,
    1800.0,
    DISARMED,
    "Highest plausible spring force (both load-cell rails outside)."
);
param!(
    SUP_LEG_COMPRESSION_MIN_M,
    "supervisor.leg_compression_min_m",
    "m",
    Real,
    -1.0,
    1.0,
    -0.004,
    DISARMED,
    "Lowest plausible leg compression (both potentiometer rails outside)."
);
param!(
    SUP_LEG_COMPRESSION_MAX_M,
    "supervisor.leg_compression_max_m",
    "m",
    Real,
    -1.0,
    1.0,
    0.1,
    DISARMED,
    "Highest plausible leg compression (both potentiometer rails outside)."
);
param!(
    SUP_SPRING_RATE,
    "supervisor.spring_rate_n_per_m",
    "N/m",
    Real,
    10.0,
    1.0e7,
    11000.0,
    DISARMED,
    "Spring rate k of the sensor cross-checks (calibrated; Table 2.1: 11 kN/m)."
);
param!(
    SUP_SPRING_PRELOAD,
    "supervisor.spring_preload_m",
    "m",
    Real,
    0.0,
    0.5,
    crate::model::design::SPRING_PRELOAD_M as f32,
    DISARMED,
    "Spring preload delta0 of the sensor cross-checks (calibrated; design: none)."
);
param!(
    SUP_CONTACT_FORCE,
    "supervisor.contact_force_n",
    "N",
    Real,
    -1.0e4,
    1.0e4,
    150.0,
    DISARMED,
    "Excess force above which the load cell says contact."
);
param!(
    SUP_FREE_FORCE,
    "supervisor.free_force_n",
    "N",
    Real,
    -1.0e4,
    1.0e4,
    40.0,
    DISARMED,
    "Excess force below which the load cell says no contact."
);
param!(
    SUP_CONTACT_COMPRESSION,
    "supervisor.contact_compression_m",
    "m",
    Real,
    -1.0,
    1.0,
    0.015,
    DISARMED,
    "Leg compression above which the potentiometer says contact."
);
param!(
    SUP_FREE_COMPRESSION,
    "supervisor.free_compression_m",
    "m",
    Real,
    -1.0,
    1.0,
    0.003,
    DISARMED,
    "Leg compression below which the potentiometer says no contact."
);
param!(
    SUP_CONTACT_DISAGREE_PERIODS,
    "supervisor.contact_disagree_periods",
    "periods",
    Count,
    1.0,
    65535.0,
    20.0,
    DISARMED,
    "Consecutive disagreeing periods before contact-disagree latches (2 ms at 10 kHz)."
);
param!(
    SUP_SPRING_MISMATCH,
    "supervisor.spring_mismatch_n",
    "N",
    Real,
    1.0e-3,
    1.0e30,
    30.0,
    DISARMED,
    "Largest plausible |F - k (delta0 + p + x)| before sensor-disagree (13 sigma; 1e30 turns it off)."
);
param!(
    SUP_FROZEN_SPEED,
    "supervisor.frozen_speed_rad_s",
    "rad/s",
    Real,
    1.0e-3,
    1.0e30,
    100.0,
    DISARMED,
    "Motor speed above which a period without a count is encoder-frozen (1e30 turns it off)."
);
param!(
    CAL_MOTOR_COUNTS_PER_REV,
    "calibration.motor_counts_per_rev",
    "counts",
    Count,
    1.0,
    1.0e6,
    2000.0,
    DISARMED,
    "Motor encoder counts per revolution (500 lines x 4)."
);
param!(
    CAL_MOTOR_POSITIVE_DOWN,
    "calibration.motor_counts_positive_down",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    DISARMED,
    "Motor counts increase when the nut moves down."
);
param!(
    CAL_HEIGHT_COUNTS_PER_REV,
    "calibration.height_counts_per_rev",
    "counts",
    Count,
    1.0,
    1.0e6,
    2000.0,
    DISARMED,
    "Height encoder counts per pulley revolution (placeholder)."
);
param!(
    CAL_HEIGHT_POSITIVE_UP,
    "calibration.height_counts_positive_up",
    "-",
    Flag,
    0.0,
    1.0,
    1.0,
    DISARMED,
    "Height counts increase when the body moves up."
);
param!(
    CAL_PULLEY_RADIUS,
    "calibration.height_pulley_radius_m",
    "m",
    Real,
    1.0e-4,
    1.0,
    0.02,
    DISARMED,
    "Radius of the height-sensor pulley (placeholder)."
);
param!(
    CAL_LOADCELL_GAIN,
    "calibration.loadcell_gain_n_per_code",
    "N/code",
    Real,
    -1.0e3,
    1.0e3,
    0.5,
    DISARMED,
    "Load-cell gain, compression positive (placeholder; not 0)."
);
param!(
    CAL_LOADCELL_OFFSET,
    "calibration.loadcell_offset_code",
    "code",
    Real,
    -1.0e5,
    1.0e5,
    200.0,
    DISARMED,
    "Load-cell code at zero force (placeholder)."
);
param!(
    CAL_POT_GAIN,
    "calibration.pot_gain_m_per_code",
    "m/code",
    Real,
    -1.0,
    1.0,
    0.12 / 4096.0,
    DISARMED,
    "Potentiometer gain, m of leg compression per code (placeholder 0.12/4096; not 0)."
);
param!(
    CAL_POT_OFFSET,
    "calibration.pot_offset_code",
    "code",
    Real,
    -1.0e5,
    1.0e5,
    205.0,
    DISARMED,
    "Potentiometer code at zero compression (placeholder)."
);
param!(
    CAL_DAC_ZERO,
    "calibration.dac_zero_code",
    "code",
    Count,
    0.0,
    65535.0,
    2048.0,
    DISARMED,
    "DAC code for zero current (mid-scale; within the DAC range)."
);
param!(
    CAL_DAC_AMPS,
    "calibration.dac_amps_per_code",
    "A/code",
    Real,
    1.0e-6,
    100.0,
    0.01953125,
    DISARMED,
    "Amplifier current per DAC code (placeholder 40 A / 2048)."
);

/// The master switches of protections, each with its safe value: a real
/// robot's link refuses any other value (a simulator keeps them, for
/// control studies). The protections' thresholds (`thermal.*`, the link
/// timeout) stay settable within their ranges: they are the motor's and
/// the bench's data, which a user must be able to enter.
pub const PROTECTIONS: [(&Param, f32); 2] = [(&THERMAL_PROTECT, 1.0), (&ARM_UNTETHERED, 0.0)];

/// Every parameter, in the order the docs list them.
pub const TABLE: &[&Param] = &[
    &CONTROLLER,
    &TARGET_APEX_M,
    &FLIGHT_KP,
    &FLIGHT_KD,
    &FLIGHT_START_M,
    &ENERGY_GAIN,
    &ENERGY_ALLOW_NEGATIVE,
    &CONSTANT_TORQUE_NM,
    &MODIFIED_TORQUE_NM,
    &MODIFIED_TORQUE_APEX_FRACTION,
    &STEP_OPEN_M,
    &STEP_OPEN_KP,
    &STEP_OPEN_KD,
    &STEP_OPEN_FEEDFORWARD,
    &STEP_CLOSED_GAIN,
    &STEP_CLOSED_KP_M_PER_J,
    &STEP_CLOSED_MIN_COMPRESSION_M,
    &STEP_CLOSED_KP,
    &STEP_CLOSED_KD,
    &STEP_CLOSED_FEEDFORWARD,
    &VELOCITY_GAIN,
    &VELOCITY_LOOP_GAIN,
    &VELOCITY_FEEDFORWARD,
    &ENERGY_APEX_GAIN,
    &ENERGY_APEX_ALLOW_NEGATIVE,
    &ENERGY_APEX_MEASURE,
    &ENERGY_APEX_PROPORTIONAL,
    &ENERGY_APEX_INTEGRAL,
    &ENERGY_APEX_MAX_OFFSET_J,
    &ENERGY_APEX_MIN_OFFSET_J,
    &ENERGY_APEX_SPIN_UP,
    &SHAPED_SPIN_UP_FRACTION,
    &SHAPED_SPIN_UP_MIN_APEX_M,
    &SHAPED_SWITCH_FRACTION,
    &SHAPED_BRAKE_FRACTION,
    &SHAPED_INITIAL_LEVEL,
    &SHAPED_INTEGRAL_START,
    &SHAPED_LEVEL_GAIN,
    &SHAPED_LEVEL_PROPORTIONAL,
    &SHAPED_BRAKING_MARGIN,
    &SHAPED_TRACKING_TIME_S,
    &SHAPED_CREEP_SPEED_MPS,
    &EST_TOUCHDOWN_FORCE_N,
    &EST_LIFTOFF_FORCE_N,
    &EST_TOUCHDOWN_COMPRESSION_M,
    &EST_LIFTOFF_COMPRESSION_M,
    &EST_DEBOUNCE_SAMPLES,
    &EST_FILTER_GAIN,
    &EST_APEX_ARM_MPS,
    &EST_BOTTOM_ARM_MPS,
    &EST_PREDICT_CONTACT,
    &EST_CONTACT_CONFIRM_S,
    &ARM_LINK_TIMEOUT_S,
    &ARM_UNTETHERED,
    &ARM_HOME_TOLERANCE_M,
    &ARM_STILL_MPS,
    &ARM_REQUIRE_TARE,
    &ARM_REQUIRE_HOME,
    &BRINGUP_CURRENT_LIMIT_A,
    &BRINGUP_SPEED_MPS,
    &BRINGUP_SWEEP_M,
    &SUP_MAX_MOTOR_DELTA,
    &SUP_MAX_HEIGHT_DELTA,
    &SUP_NUT_POSITION_MIN_M,
    &SUP_NUT_POSITION_MAX_M,
    &SUP_NUT_VELOCITY_MIN_MPS,
    &SUP_NUT_VELOCITY_MAX_MPS,
    &SUP_MOTOR_SPEED_MIN_RAD_S,
    &SUP_MOTOR_SPEED_MAX_RAD_S,
    &SUP_BODY_HEIGHT_MIN_M,
    &SUP_BODY_HEIGHT_MAX_M,
    &SUP_BODY_VELOCITY_MIN_MPS,
    &SUP_BODY_VELOCITY_MAX_MPS,
    &SUP_SPRING_FORCE_MIN_N,
    &SUP_SPRING_FORCE_MAX_N,
    &SUP_LEG_COMPRESSION_MIN_M,
    &SUP_LEG_COMPRESSION_MAX_M,
    &SUP_SPRING_RATE,
    &SUP_SPRING_PRELOAD,
    &SUP_CONTACT_FORCE,
    &SUP_FREE_FORCE,
    &SUP_CONTACT_COMPRESSION,
    &SUP_FREE_COMPRESSION,
    &SUP_CONTACT_DISAGREE_PERIODS,
    &SUP_SPRING_MISMATCH,
    &SUP_FROZEN_SPEED,
    &ESTOP_PRESS_S,
    &ESTOP_RELEASE_S,
    &THERMAL_PROTECT,
    &THERMAL_RESISTANCE_OHM,
    &THERMAL_WINDING_TO_HOUSING,
    &THERMAL_HOUSING_TO_AMBIENT,
    &THERMAL_WINDING_TAU,
    &THERMAL_HOUSING_TAU,
    &THERMAL_AMBIENT,
    &THERMAL_DERATE,
    &THERMAL_TRIP,
    &THERMAL_DERATED_FRACTION,
    &CAL_MOTOR_COUNTS_PER_REV,
    &CAL_MOTOR_POSITIVE_DOWN,
    &CAL_HEIGHT_COUNTS_PER_REV,
    &CAL_HEIGHT_POSITIVE_UP,
    &CAL_PULLEY_RADIUS,
    &CAL_LOADCELL_GAIN,
    &CAL_LOADCELL_OFFSET,
    &CAL_POT_GAIN,
    &CAL_POT_OFFSET,
    &CAL_DAC_ZERO,
    &CAL_DAC_AMPS,
];

/// The parameter called `name`.
pub fn find(name: &str) -> Option<&'static Param> {
    TABLE.iter().copied().find(|p| p.name == name)
}

/// Why [`get`] or [`set`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ParamError {
    /// No parameter has this name.
    Unknown,
    /// The value is outside the parameter's range (or not whole).
    OutOfRange(&'static str),
    /// The parameter belongs to a controller other than the selected one.
    NotSelected(&'static str),
}

/// The index of the controller `strategy` is (the [`CONTROLLER`] value).
pub fn controller_index(strategy: &Strategy) -> usize {
    let kind = strategy.kind();
    ControllerKind::ALL
        .iter()
        .position(|k| *k == kind)
        .unwrap_or(0)
}

/// The controller at `index` of [`CONTROLLER_NAMES`], with its defaults.
pub fn controller_default(index: usize) -> Option<Strategy> {
    ControllerKind::ALL.get(index).map(|k| k.default_strategy())
}

/// Where a parameter lives in a configuration.
enum Slot<'a> {
    Real(&'a mut f32),
    Flag(&'a mut bool),
    U32(&'a mut u32),
    U16(&'a mut u16),
    U8(&'a mut u8),
    Controller,
    StepClosedGain(&'a mut step_closed::Gain),
    Measure(&'a mut energy_apex::EnergyMeasure),
}

/// The slot of `p` in `cfg`, or the reason there is none.
fn slot<'a>(cfg: &'a mut HopperConfig, p: &Param) -> Result<Slot<'a>, ParamError> {
    use Slot::{Flag as B, Real as R};
    let not = Err(ParamError::NotSelected(p.name));
    let name = p.name;
    if name == CONTROLLER.name {
        return Ok(Slot::Controller);
    }
    if name == TARGET_APEX_M.name {
        return Ok(R(&mut cfg.target_apex_m));
    }
    if let Some(rest) = name.strip_prefix("flight.") {
        let f = &mut cfg.flight;
        return match rest {
            "kp_a_per_rad" => Ok(R(&mut f.gains.kp)),
            "kd_a_s_per_rad" => Ok(R(&mut f.gains.kd)),
            "start_position_m" => Ok(R(&mut f.start_position_m)),
            _ => Err(ParamError::Unknown),
        };
    }
    if let Some(rest) = name.strip_prefix("arming.") {
        let a = &mut cfg.arming;
        return match rest {
            "link_timeout_s" => Ok(R(&mut a.link_timeout_s)),
            "untethered" => Ok(B(&mut a.untethered)),
            "home_tolerance_m" => Ok(R(&mut a.home_tolerance_m)),
            "still_velocity_mps" => Ok(R(&mut a.still_velocity_mps)),
            "require_tare" => Ok(B(&mut a.require_tare)),
            "require_home" => Ok(B(&mut a.require_home)),
            _ => Err(ParamError::Unknown),
        };
    }
    if let Some(rest) = name.strip_prefix("estimator.") {
        let e = &mut cfg.estimator;
        return match rest {
            "touchdown_force_n" => Ok(R(&mut e.touchdown_force_n)),
            "liftoff_force_n" => Ok(R(&mut e.liftoff_force_n)),
            "touchdown_compression_m" => Ok(R(&mut e.touchdown_compression_m)),
            "liftoff_compression_m" => Ok(R(&mut e.liftoff_compression_m)),
            "debounce_samples" => Ok(Slot::U8(&mut e.debounce_samples)),
            "velocity_filter_gain" => Ok(R(&mut e.velocity_filter_gain)),
            "apex_arm_velocity_mps" => Ok(R(&mut e.apex_arm_velocity_mps)),
            "bottom_arm_velocity_mps" => Ok(R(&mut e.bottom_arm_velocity_mps)),
            "predict_contact" => Ok(B(&mut e.predict_contact)),
            "contact_confirm_s" => Ok(R(&mut e.contact_confirm_s)),
            _ => Err(ParamError::Unknown),
        };
    }
    if let Some(rest) = name.strip_prefix("supervisor.") {
        let c = &mut cfg.supervisor;
        return match rest {
            "max_motor_delta_counts" => Ok(Slot::U32(&mut c.max_motor_delta_counts)),
            "max_height_delta_counts" => Ok(Slot::U32(&mut c.max_height_delta_counts)),
            "nut_position_min_m" => Ok(R(&mut c.nut_position_range_m.min)),
            "nut_position_max_m" => Ok(R(&mut c.nut_position_range_m.max)),
            "nut_velocity_min_mps" => Ok(R(&mut c.nut_velocity_range_mps.min)),
            "nut_velocity_max_mps" => Ok(R(&mut c.nut_velocity_range_mps.max)),
            "motor_speed_min_rad_s" => Ok(R(&mut c.motor_speed_range_rad_s.min)),
            "motor_speed_max_rad_s" => Ok(R(&mut c.motor_speed_range_rad_s.max)),
            "body_height_min_m" => Ok(R(&mut c.body_height_range_m.min)),
            "body_height_max_m" => Ok(R(&mut c.body_height_range_m.max)),
            "body_velocity_min_mps" => Ok(R(&mut c.body_velocity_range_mps.min)),
            "body_velocity_max_mps" => Ok(R(&mut c.body_velocity_range_mps.max)),
            "spring_force_min_n" => Ok(R(&mut c.spring_force_range_n.min)),
            "spring_force_max_n" => Ok(R(&mut c.spring_force_range_n.max)),
            "leg_compression_min_m" => Ok(R(&mut c.leg_compression_range_m.min)),
            "leg_compression_max_m" => Ok(R(&mut c.leg_compression_range_m.max)),
            "spring_rate_n_per_m" => Ok(R(&mut c.spring_rate_n_per_m)),
            "spring_preload_m" => Ok(R(&mut c.spring_preload_m)),
            "contact_force_n" => Ok(R(&mut c.contact_force_n)),
            "free_force_n" => Ok(R(&mut c.free_force_n)),
            "contact_compression_m" => Ok(R(&mut c.contact_compression_m)),
            "free_compression_m" => Ok(R(&mut c.free_compression_m)),
            "contact_disagree_periods" => Ok(Slot::U16(&mut c.contact_disagree_periods)),
            "spring_mismatch_n" => Ok(R(&mut c.spring_mismatch_n)),
            "frozen_speed_rad_s" => Ok(R(&mut c.frozen_speed_rad_s)),
            _ => Err(ParamError::Unknown),
        };
    }
    if let Some(rest) = name.strip_prefix("bringup.") {
        let b = &mut cfg.bringup;
        return match rest {
            "current_limit_a" => Ok(R(&mut b.current_limit_a)),
            "speed_mps" => Ok(R(&mut b.speed_mps)),
            "sweep_m" => Ok(R(&mut b.sweep_m)),
            _ => Err(ParamError::Unknown),
        };
    }
    if let Some(rest) = name.strip_prefix("estop.") {
        let e = &mut cfg.estop;
        return match rest {
            "press_s" => Ok(R(&mut e.press_s)),
            "release_s" => Ok(R(&mut e.release_s)),
            _ => Err(ParamError::Unknown),
        };
    }
    if let Some(rest) = name.strip_prefix("thermal.") {
        let t = &mut cfg.supervisor.thermal;
        return match rest {
            "protect" => Ok(B(&mut t.protect)),
            "winding_resistance_ohm" => Ok(R(&mut t.winding_resistance_ohm)),
            "winding_to_housing_k_per_w" => Ok(R(&mut t.winding_to_housing_k_per_w)),
            "housing_to_ambient_k_per_w" => Ok(R(&mut t.housing_to_ambient_k_per_w)),
            "winding_time_constant_s" => Ok(R(&mut t.winding_time_constant_s)),
            "housing_time_constant_s" => Ok(R(&mut t.housing_time_constant_s)),
            "ambient_c" => Ok(R(&mut t.ambient_c)),
            "derate_winding_c" => Ok(R(&mut t.derate_winding_c)),
            "trip_winding_c" => Ok(R(&mut t.trip_winding_c)),
            "derated_limit_fraction" => Ok(R(&mut t.derated_limit_fraction)),
            _ => Err(ParamError::Unknown),
        };
    }
    if let Some(rest) = name.strip_prefix("calibration.") {
        let c = &mut cfg.calibration;
        return match rest {
            "motor_counts_per_rev" => Ok(Slot::U32(&mut c.motor_counts_per_rev)),
            "motor_counts_positive_down" => Ok(B(&mut c.motor_counts_positive_down)),
            "height_counts_per_rev" => Ok(Slot::U32(&mut c.height_counts_per_rev)),
            "height_counts_positive_up" => Ok(B(&mut c.height_counts_positive_up)),
            "height_pulley_radius_m" => Ok(R(&mut c.height_pulley_radius_m)),
            "loadcell_gain_n_per_code" => Ok(R(&mut c.loadcell_gain_n_per_code)),
            "loadcell_offset_code" => Ok(R(&mut c.loadcell_offset_code)),
            "pot_gain_m_per_code" => Ok(R(&mut c.pot_gain_m_per_code)),
            "pot_offset_code" => Ok(R(&mut c.pot_offset_code)),
            "dac_zero_code" => Ok(Slot::U16(&mut c.dac_zero_code)),
            "dac_amps_per_code" => Ok(R(&mut c.dac_amps_per_code)),
            _ => Err(ParamError::Unknown),
        };
    }
    match &mut cfg.strategy {
        Strategy::Thesis(StanceLaw::EnergyTorque(c)) if name.starts_with("energy.") => match name {
            "energy.gain_nm_per_j" => Ok(R(&mut c.gain_nm_per_j)),
            "energy.allow_negative" => Ok(B(&mut c.allow_negative)),
            _ => Err(ParamError::Unknown),
        },
        Strategy::Thesis(StanceLaw::ConstantTorque(c)) if name == CONSTANT_TORQUE_NM.name => {
            Ok(R(&mut c.torque_nm))
        }
        Strategy::Thesis(StanceLaw::ModifiedTorque(c)) if name.starts_with("modified_torque.") => {
            match name {
                "modified_torque.torque_nm" => Ok(R(&mut c.torque_nm)),
                "modified_torque.apex_fraction" => Ok(R(&mut c.apex_fraction)),
                _ => Err(ParamError::Unknown),
            }
        }
        Strategy::Thesis(StanceLaw::StepOpen(c)) if name.starts_with("step_open.") => match name {
            "step_open.step_m" => Ok(R(&mut c.step_m)),
            "step_open.kp_n_per_m" => Ok(R(&mut c.pd.kp_n_per_m)),
            "step_open.kd_n_s_per_m" => Ok(R(&mut c.pd.kd_n_s_per_m)),
            "step_open.spring_feedforward" => Ok(B(&mut c.pd.spring_feedforward)),
            _ => Err(ParamError::Unknown),
        },
        Strategy::Thesis(StanceLaw::StepClosed(c)) if name.starts_with("step_closed.") => {
            match name {
                "step_closed.gain" => Ok(Slot::StepClosedGain(&mut c.gain)),
                "step_closed.kp_m_per_j" => match &mut c.gain {
                    step_closed::Gain::Fixed { kp_m_per_j } => Ok(R(kp_m_per_j)),
                    _ => not,
                },
                "step_closed.min_compression_m" => match &mut c.gain {
                    step_closed::Gain::Normalised { min_compression_m } => Ok(R(min_compression_m)),
                    _ => not,
                },
                "step_closed.kp_n_per_m" => Ok(R(&mut c.pd.kp_n_per_m)),
                "step_closed.kd_n_s_per_m" => Ok(R(&mut c.pd.kd_n_s_per_m)),
                "step_closed.spring_feedforward" => Ok(B(&mut c.pd.spring_feedforward)),
                _ => Err(ParamError::Unknown),
            }
        }
        Strategy::Thesis(StanceLaw::Velocity(c)) if name.starts_with("velocity.") => match name {
            "velocity.gain_mps_per_j" => Ok(R(&mut c.gain_mps_per_j)),
            "velocity.loop_gain_n_s_per_m" => Ok(R(&mut c.loop_gain_n_s_per_m)),
            "velocity.spring_feedforward" => Ok(B(&mut c.spring_feedforward)),
            _ => Err(ParamError::Unknown),
        },
        Strategy::EnergyApex(a) if name.starts_with("energy_apex.") => match name {
            "energy_apex.gain_nm_per_j" => Ok(R(&mut a.law.gain_nm_per_j)),
            "energy_apex.allow_negative" => Ok(B(&mut a.law.allow_negative)),
            "energy_apex.measure" => Ok(Slot::Measure(&mut a.measure)),
            "energy_apex.proportional_gain" => Ok(R(&mut a.proportional)),
            "energy_apex.integral_gain" => Ok(R(&mut a.gain)),
            "energy_apex.max_offset_j" => Ok(R(&mut a.max_offset_j)),
            "energy_apex.min_offset_j" => Ok(R(&mut a.min_offset_j)),
            "energy_apex.spin_up_fraction" => Ok(R(&mut a.spin_up_fraction)),
            _ => Err(ParamError::Unknown),
        },
        Strategy::Shaped(c) if name.starts_with("shaped.") => match name {
            "shaped.spin_up_fraction" => Ok(R(&mut c.spin_up_fraction)),
            "shaped.spin_up_min_apex_m" => Ok(R(&mut c.spin_up_min_apex_m)),
            "shaped.switch_fraction" => Ok(R(&mut c.switch_fraction)),
            "shaped.brake_fraction" => Ok(R(&mut c.brake_fraction)),
            "shaped.initial_level" => Ok(R(&mut c.initial_level)),
            "shaped.integral_start" => Ok(R(&mut c.integral_start)),
            "shaped.level_gain_per_j" => Ok(R(&mut c.level_gain_per_j)),
            "shaped.level_proportional_per_j" => Ok(R(&mut c.level_proportional_per_j)),
            "shaped.braking_margin" => Ok(R(&mut c.braking_margin)),
            "shaped.tracking_time_s" => Ok(R(&mut c.tracking_time_s)),
            "shaped.creep_speed_mps" => Ok(R(&mut c.creep_speed_mps)),
            _ => Err(ParamError::Unknown),
        },
        _ => not,
    }
}

/// The value of parameter `name` in `cfg`.
pub fn get(cfg: &HopperConfig, name: &str) -> Result<f32, ParamError> {
    let p = find(name).ok_or(ParamError::Unknown)?;
    let mut c = *cfg;
    read(&mut c, p)
}

/// [`get`] by table entry, through a configuration the caller lends
/// mutably (the slots are reached by `&mut`; nothing is changed): reading
/// many parameters costs no lookups by name and no copies.
pub fn read(c: &mut HopperConfig, p: &Param) -> Result<f32, ParamError> {
    let index = controller_index(&c.strategy);
    Ok(match slot(c, p)? {
        Slot::Real(v) => *v,
        Slot::Flag(b) => f32::from(u8::from(*b)),
        // Counts are checked against their (below 2^24) ranges on set, so
        // they are exact in f32.
        Slot::U32(n) => *n as f32,
        Slot::U16(n) => f32::from(*n),
        Slot::U8(n) => f32::from(*n),
        Slot::Controller => index as f32,
        Slot::StepClosedGain(g) => match g {
            step_closed::Gain::Fixed { .. } => 0.0,
            step_closed::Gain::Normalised { .. } => 1.0,
        },
        Slot::Measure(m) => match m {
            energy_apex::EnergyMeasure::Total => 0.0,
            energy_apex::EnergyMeasure::Body => 1.0,
        },
    })
}

/// Sets parameter `name` of `cfg` to `value`, after checking it against the
/// parameter's range. The whole configuration is validated again when a
/// controller is built from it (`Hopper::new`).
pub fn set(cfg: &mut HopperConfig, name: &str, value: f32) -> Result<(), ParamError> {
    let p = find(name).ok_or(ParamError::Unknown)?;
    let v = p.check(value).map_err(|f| ParamError::OutOfRange(f.0))?;
    match slot(cfg, p)? {
        Slot::Real(x) => *x = v,
        Slot::Flag(b) => *b = v != 0.0,
        // Whole and within the count's range (checked above).
        Slot::U32(n) => *n = v as u32,
        Slot::U16(n) => *n = v as u16,
        Slot::U8(n) => *n = v as u8,
        Slot::Controller => {
            cfg.strategy = controller_default(v as usize).ok_or(ParamError::OutOfRange(p.name))?;
        }
        Slot::StepClosedGain(g) => {
            let fixed = matches!(g, step_closed::Gain::Fixed { .. });
            if fixed == (v == 0.0) {
                // The same choice: keep its value.
                return Ok(());
            }
            *g = if v == 0.0 {
                step_closed::Gain::Fixed {
                    kp_m_per_j: STEP_CLOSED_KP_M_PER_J.default,
                }
            } else {
                step_closed::Gain::Normalised {
                    min_compression_m: STEP_CLOSED_MIN_COMPRESSION_M.default,
                }
            };
        }
        Slot::Measure(m) => {
            *m = if v == 0.0 {
                energy_apex::EnergyMeasure::Total
            } else {
                energy_apex::EnergyMeasure::Body
            };
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::hopper::Hopper;
    use std::string::String;
    use std::vec::Vec;

    #[test]
    fn names_are_unique_and_defaults_in_range() {
        for (i, p) in TABLE.iter().enumerate() {
            assert!(
                p.check(p.default).is_ok(),
                "{}: default out of range",
                p.name
            );
            assert!(p.min <= p.max, "{}", p.name);
            assert!(!p.doc.is_empty() && !p.unit.is_empty(), "{}", p.name);
            for q in &TABLE[i + 1..] {
                assert_ne!(p.name, q.name);
            }
        }
    }

    /// Every parameter can be read and written once its controller is
    /// selected, and reads back its default from a fresh selection: the
    /// configuration types' defaults are the table's.
    #[test]
    fn every_parameter_reads_its_default_and_writes() {
        for p in TABLE {
            let mut cfg = HopperConfig::default();
            // Select the controller the parameter belongs to.
            let owner = CONTROLLER_NAMES.iter().position(|n| {
                let prefix = match *n {
                    "open-torque" => "constant_torque",
                    "modified-torque" => "modified_torque",
                    "step-open" => "step_open",
                    "step-closed" => "step_closed",
                    "energy-apex" => "energy_apex",
                    other => other,
                };
                p.name.starts_with(&[prefix, "."].concat())
            });
            if let Some(i) = owner {
                set(&mut cfg, CONTROLLER.name, i as f32).unwrap_or_else(|e| panic!("{e:?}"));
            }
            if p.name == STEP_CLOSED_MIN_COMPRESSION_M.name {
                set(&mut cfg, STEP_CLOSED_GAIN.name, 1.0).unwrap_or_else(|e| panic!("{e:?}"));
            }
            let got = get(&cfg, p.name).unwrap_or_else(|e| panic!("{}: {e:?}", p.name));
            if p.name != CONTROLLER.name {
                assert_eq!(
                    got, p.default,
                    "{}: the type's default is not the table's",
                    p.name
                );
            }
            let v = if p.kind == Kind::Real { p.max } else { p.min };
            set(&mut cfg, p.name, v).unwrap_or_else(|e| panic!("{}: {e:?}", p.name));
            assert_eq!(get(&cfg, p.name), Ok(v), "{}", p.name);
        }
        assert_eq!(
            get(&HopperConfig::default(), CONTROLLER.name),
            Ok(CONTROLLER.default)
        );
    }

    #[test]
    fn bad_values_and_names_are_refused() {
        let mut cfg = HopperConfig::default();
        assert_eq!(set(&mut cfg, "no.such", 1.0), Err(ParamError::Unknown));
        assert_eq!(
            set(&mut cfg, FLIGHT_KP.name, -1.0),
            Err(ParamError::OutOfRange(FLIGHT_KP.name))
        );
        assert_eq!(
            set(&mut cfg, FLIGHT_KP.name, f32::NAN),
            Err(ParamError::OutOfRange(FLIGHT_KP.name))
        );
        assert_eq!(
            set(&mut cfg, CONTROLLER.name, 2.5),
            Err(ParamError::OutOfRange(CONTROLLER.name))
        );
        // The default controller is energy-apex: a shaped constant is refused.
        assert_eq!(
            set(&mut cfg, SHAPED_BRAKE_FRACTION.name, 0.5),
            Err(ParamError::NotSelected(SHAPED_BRAKE_FRACTION.name))
        );
        assert_eq!(
            cfg,
            HopperConfig::default(),
            "a refused set changed nothing"
        );
    }

    #[test]
    fn a_configuration_set_within_the_table_builds() {
        for i in 0..CONTROLLER_NAMES.len() {
            let mut cfg = HopperConfig::default();
            set(&mut cfg, CONTROLLER.name, i as f32).unwrap_or_else(|e| panic!("{e:?}"));
            for p in TABLE {
                if p.name == CONTROLLER.name || get(&cfg, p.name).is_err() {
                    continue;
                }
                let mut c = cfg;
                // Sensor, estimator and supervisor limits have cross-field
                // rules (a range's min below its max, the liftoff threshold
                // below the touchdown one, ...) that one value at its bound
                // may break: the construction must then refuse, not panic.
                let coupled = ["estimator.", "supervisor.", "calibration.", "thermal."]
                    .iter()
                    .any(|prefix| p.name.starts_with(prefix));
                for v in [p.min, p.max, p.default] {
                    if coupled {
                        set(&mut c, p.name, v).unwrap_or_else(|e| panic!("{e:?}"));
                        let _ = Hopper::new(c);
                        continue;
                    }
                    set(&mut c, p.name, v).unwrap_or_else(|e| panic!("{e:?}"));
                    // The flight start must lie on the stroke: the one
                    // cross-field rule beyond the table's ranges (checked
                    // by the flight PD's own test).
                    if p.name == FLIGHT_START_M.name && v > c.model.stroke_m {
                        continue;
                    }
                    assert!(
                        Hopper::new(c).is_ok(),
                        "{} = {v}: {:?}",
                        p.name,
                        Hopper::new(c).err()
                    );
                }
            }
        }
    }

    /// The parameter table as Markdown (`docs/parameters.md`).
    pub fn markdown() -> String {
        let mut s = String::from(
            "# Runtime parameters\n\n\
             Generated from `firmware/control/src/params.rs` (`hopper_control::params::TABLE`) by\n\
             `HOPPER_WRITE_DOCS=1 cargo test -p hopper-control params_doc`; a test fails when this\n\
             page is stale. Live: may change while the motor is driven; otherwise only with\n\
             the amplifier disabled. Flags are 0/1, choices the index of a name.\n\n\
             | Name | Unit | Range | Default | Live | What |\n\
             |------|------|-------|---------|------|------|\n",
        );
        for p in TABLE {
            // Large bounds (1e30: a check turned off) in exponent form.
            let num = |v: f32| {
                if v.abs() >= 1e7 {
                    std::format!("{v:e}")
                } else {
                    std::format!("{v}")
                }
            };
            let range = match p.kind {
                Kind::Choice(names) => names.join(", "),
                Kind::Flag => String::from("0, 1"),
                _ => std::format!("{} ..= {}", num(p.min), num(p.max)),
            };
            let default = match p.kind {
                Kind::Choice(names) => String::from(names[p.default as usize]),
                _ => num(p.default),
            };
            s += &std::format!(
                "| `{}` | {} | {} | {} | {} | {} |\n",
                p.name,
                p.unit,
                range,
                default,
                if p.live { "yes" } else { "no" },
                // A `|` would end the table cell.
                p.doc.replace('|', "\\|")
            );
        }
        s
    }

    #[test]
    fn params_doc_is_current() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/parameters.md");
        let want = markdown();
        if std::env::var_os("HOPPER_WRITE_DOCS").is_some() {
            std::fs::write(path, &want).unwrap_or_else(|e| panic!("{path}: {e}"));
        }
        let have = std::fs::read_to_string(path).unwrap_or_default();
        let stale: Vec<_> = want.lines().filter(|l| !have.contains(l)).take(3).collect();
        assert!(
            have == want,
            "docs/parameters.md is stale (first differing lines: {stale:?}); regenerate with \
             `HOPPER_WRITE_DOCS=1 cargo test -p hopper-control params_doc`"
        );
    }
}
