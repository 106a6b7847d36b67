//! The firmware's runtime parameters, each defined once: name, unit, range,
//! default, whether it may change while the motor is driven, and a one-line
//! doc.
//!
//! Each parameter is declared once, in the `params!` list below. The
//! configuration types' `Default` impls and their `validate` checks read
//! these entries, the host tools (`hopper-sim`'s scenario files and sweeps)
//! look parameters up here by name, the link exposes exactly [`TABLE`], and
//! `docs/parameters.md` is generated from it (a test fails when the page is
//! stale).
//!
//! Every value is an `f32`: a flag is 0 or 1, a choice is the index of one
//! of its names, a count is a whole number. [`get`] and [`set`] read and
//! write a [`HopperConfig`] by name; a parameter of a controller other than
//! the selected one is refused by [`set`] (select the controller first:
//! that starts it from its defaults).

use crate::hopper::HopperConfig;
use crate::laws::{
    energy, energy_apex, modified_torque, open_torque, shaped, step_closed, step_open, velocity,
    ControllerKind, InvalidField, StanceLaw, Strategy,
};

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
    /// Which parameter this is.
    pub id: Id,
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

    /// The default of a flag.
    pub const fn default_flag(&self) -> bool {
        self.default != 0.0
    }
}

const LIVE: bool = true;
const DISARMED: bool = false;

/// Declares every parameter once: `ID { name, unit, kind, [min, max],
/// default, live, doc, |cfg| slot }`, where `slot` is where the value lives
/// in a [`HopperConfig`] (`None` when it belongs to a controller other than
/// the selected one). Generates the `pub const` entry, [`Id`], [`TABLE`] (in
/// declaration order: the link's parameter index and the docs' order) and
/// the slot lookup behind [`get`], [`read`] and [`set`].
macro_rules! params {
    ($(
        $(#[$meta:meta])*
        $id:ident {
            $name:literal, $unit:literal, $kind:expr, [$min:expr, $max:expr], $default:expr, $live:expr,
            $doc:literal,
            |$c:ident| $slot:expr
        }
    )*) => {
        /// Which parameter an entry is: the key of its slot.
        #[allow(non_camel_case_types)]
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Id {
            $(
                #[doc = $doc]
                $id,
            )*
        }

        $(
            $(#[$meta])*
            #[doc = $doc]
            pub const $id: Param = Param {
                id: Id::$id,
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
        )*

        /// Every parameter, in the order the docs list them (a parameter's
        /// index here is its number on the link).
        pub const TABLE: &[&Param] = &[$(&$id),*];

        /// The slot of `p` in `cfg`; `None` when `p` belongs to a
        /// controller other than the selected one.
        fn slot<'a>(cfg: &'a mut HopperConfig, p: &Param) -> Option<Slot<'a>> {
            use Slot::{Flag as B, Real as R};
            match p.id {
                $(Id::$id => {
                    let $c = cfg;
                    $slot
                })*
            }
        }
    };
}

/// The controllers [`CONTROLLER`] chooses from, by name (the index is the
/// value): [`ControllerKind::ALL`]'s names.
pub const CONTROLLER_NAMES: &[&str] = <ControllerKind as strum::VariantNames>::VARIANTS;

/// Names of [`STEP_CLOSED_GAIN`]'s choices.
const STEP_CLOSED_GAINS: [&str; 2] = ["fixed", "normalised"];
/// Names of [`ENERGY_APEX_MEASURE`]'s choices.
const ENERGY_MEASURES: [&str; 2] = ["total", "body"];

use Kind::{Count, Flag, Real};

params! {
    // --- The controller and its target -----------------------------------------
    CONTROLLER {
        "controller", "-", Kind::Choice(CONTROLLER_NAMES), [0.0, 8.0], 5.0, DISARMED,
        "The controller that runs in stance and flight (selecting one starts it from its defaults).",
        |_cfg| Some(Slot::Controller)
    }
    TARGET_APEX_M {
        "target_apex_m", "m", Real, [0.0, 1.0], 0.05, LIVE,
        "Desired apex toe height H_D (E_D of eq 2.43).",
        |c| Some(R(&mut c.target_apex_m))
    }
    // --- Flight PD, eq 4.4 -----------------------------------------------------
    FLIGHT_KP {
        "flight.kp_a_per_rad", "A/rad", Real, [0.0, 1.0e4], 20.3152, LIVE,
        "Flight PD position gain on the motor angle (eq 4.4; default eq 4.13; hopper-sim's design preset runs Table 2.1's 8e4 N/m on the nut, 1.8953 A/rad, with the Chapter 2 laws).",
        |c| Some(R(&mut c.flight.gains.kp))
    }
    FLIGHT_KD {
        "flight.kd_a_s_per_rad", "A s/rad", Real, [0.0, 1.0e3], 0.6077, LIVE,
        "Flight PD rate gain (eq 4.4; default eq 4.13; the design preset's Chapter 2 laws: Table 2.1's 300 N s/m, 0.0071073 A s/rad).",
        |c| Some(R(&mut c.flight.gains.kd))
    }
    FLIGHT_START_M {
        "flight.start_position_m", "m", Real, [0.0, 1.0], 0.0, LIVE,
        "Nut position the flight PD returns to (0: the upper stop; at most the stroke).",
        |c| Some(R(&mut c.flight.start_position_m))
    }
    // --- Thesis stance laws ----------------------------------------------------
    ENERGY_GAIN {
        "energy.gain_nm_per_j", "N m/J", Real, [0.0, 100.0], 0.2, LIVE,
        "K_e of eq 2.52 (Table 2.1: 0.2).",
        |c| energy(c).map(|s| R(&mut s.gain_nm_per_j))
    }
    ENERGY_ALLOW_NEGATIVE {
        "energy.allow_negative", "-", Flag, [0.0, 1.0], 1.0, LIVE,
        "Eq 2.52 may command negative torque on an energy surplus.",
        |c| energy(c).map(|s| B(&mut s.allow_negative))
    }
    // The open-torque law's parameter keeps its `constant_torque.` name:
    // parameter names are a contract (scenario files, the link,
    // docs/parameters.md) kept from before the law was renamed.
    CONSTANT_TORQUE_NM {
        "constant_torque.torque_nm", "N m", Real, [-10.0, 10.0], 1.0, LIVE,
        "Open-loop stance torque (section 2.1.3.4; Table 2.1: 1 N m).",
        |c| open_torque(c).map(|s| R(&mut s.torque_nm))
    }
    MODIFIED_TORQUE_NM {
        "modified_torque.torque_nm", "N m", Real, [-10.0, 10.0], 1.0, LIVE,
        "Modified-torque law's torque in stance and late descent (section 4.4.3).",
        |c| modified_torque(c).map(|s| R(&mut s.torque_nm))
    }
    MODIFIED_TORQUE_APEX_FRACTION {
        "modified_torque.apex_fraction", "1", Real, [0.0, 1.0], 0.4, LIVE,
        "Fraction of the last apex below which the descent starts the torque (section 4.4.3: 40 %).",
        |c| modified_torque(c).map(|s| R(&mut s.apex_fraction))
    }
    STEP_OPEN_M {
        "step_open.step_m", "m", Real, [0.0, 1.0], 0.01, LIVE,
        "Step height l1 of eq 2.49 (Table 2.1: 10 mm; clamped to the stroke).",
        |c| step_open(c).map(|s| R(&mut s.step_m))
    }
    STEP_OPEN_KP {
        "step_open.kp_n_per_m", "N/m", Real, [0.0, 1.0e7], 8.0e4, LIVE,
        "Nut position loop gain k_p,f of eq 2.49 (Table 2.1).",
        |c| step_open(c).map(|s| R(&mut s.pd.kp_n_per_m))
    }
    STEP_OPEN_KD {
        "step_open.kd_n_s_per_m", "N s/m", Real, [0.0, 1.0e5], 300.0, LIVE,
        "Nut velocity loop gain k_v,f of eq 2.49 (Table 2.1).",
        |c| step_open(c).map(|s| R(&mut s.pd.kd_n_s_per_m))
    }
    STEP_OPEN_FEEDFORWARD {
        "step_open.spring_feedforward", "-", Flag, [0.0, 1.0], 1.0, LIVE,
        "Add the measured spring force to the position loop.",
        |c| step_open(c).map(|s| B(&mut s.pd.spring_feedforward))
    }
    STEP_CLOSED_GAIN {
        "step_closed.gain", "-", Kind::Choice(&STEP_CLOSED_GAINS), [0.0, 1.0], 0.0, LIVE,
        "k_p of eq 2.50: fixed (step_closed.kp_m_per_j) or eq 2.51 normalised by the compression.",
        |c| step_closed(c).map(|s| Slot::StepClosedGain(&mut s.gain))
    }
    STEP_CLOSED_KP_M_PER_J {
        "step_closed.kp_m_per_j", "m/J", Real, [0.0, 1.0], 2.0e-3, LIVE,
        "Fixed k_p of eq 2.50 (Table 2.1's 0.2 read as cm/J).",
        |c| step_closed(c).and_then(|s| match &mut s.gain {
            step_closed::Gain::Fixed { kp_m_per_j } => Some(R(kp_m_per_j)),
            step_closed::Gain::Normalised { .. } => None,
        })
    }
    STEP_CLOSED_MIN_COMPRESSION_M {
        "step_closed.min_compression_m", "m", Real, [1.0e-4, 1.0], 0.005, LIVE,
        "Floor on the compression in eq 2.51's normalised gain.",
        |c| step_closed(c).and_then(|s| match &mut s.gain {
            step_closed::Gain::Normalised { min_compression_m } => Some(R(min_compression_m)),
            step_closed::Gain::Fixed { .. } => None,
        })
    }
    STEP_CLOSED_KP {
        "step_closed.kp_n_per_m", "N/m", Real, [0.0, 1.0e7], 8.0e4, LIVE,
        "Nut position loop gain of eq 2.50 (Table 2.1).",
        |c| step_closed(c).map(|s| R(&mut s.pd.kp_n_per_m))
    }
    STEP_CLOSED_KD {
        "step_closed.kd_n_s_per_m", "N s/m", Real, [0.0, 1.0e5], 300.0, LIVE,
        "Nut velocity loop gain of eq 2.50 (Table 2.1).",
        |c| step_closed(c).map(|s| R(&mut s.pd.kd_n_s_per_m))
    }
    STEP_CLOSED_FEEDFORWARD {
        "step_closed.spring_feedforward", "-", Flag, [0.0, 1.0], 1.0, LIVE,
        "Add the measured spring force to the position loop.",
        |c| step_closed(c).map(|s| B(&mut s.pd.spring_feedforward))
    }
    VELOCITY_GAIN {
        "velocity.gain_mps_per_j", "m/(s J)", Real, [0.0, 10.0], 0.03, LIVE,
        "K_v of eq 2.53 (Table 2.1's 30 read as mm/(s J)).",
        |c| velocity(c).map(|s| R(&mut s.gain_mps_per_j))
    }
    VELOCITY_LOOP_GAIN {
        "velocity.loop_gain_n_s_per_m", "N s/m", Real, [0.0, 1.0e6], 5000.0, LIVE,
        "Velocity loop gain from nut speed error to force.",
        |c| velocity(c).map(|s| R(&mut s.loop_gain_n_s_per_m))
    }
    VELOCITY_FEEDFORWARD {
        "velocity.spring_feedforward", "-", Flag, [0.0, 1.0], 1.0, LIVE,
        "Add the measured spring force to the velocity loop.",
        |c| velocity(c).map(|s| B(&mut s.spring_feedforward))
    }
    // --- energy-apex -----------------------------------------------------------
    ENERGY_APEX_GAIN {
        "energy_apex.gain_nm_per_j", "N m/J", Real, [0.0, 100.0], 3.0, LIVE,
        "K_e of the inner eq 2.52 (full torque for a 0.33 J deficit).",
        |c| energy_apex(c).map(|s| R(&mut s.law.gain_nm_per_j))
    }
    ENERGY_APEX_ALLOW_NEGATIVE {
        "energy_apex.allow_negative", "-", Flag, [0.0, 1.0], 0.0, LIVE,
        "The inner law may command negative torque.",
        |c| energy_apex(c).map(|s| B(&mut s.law.allow_negative))
    }
    ENERGY_APEX_MEASURE {
        "energy_apex.measure", "-", Kind::Choice(&ENERGY_MEASURES), [0.0, 1.0], 0.0, LIVE,
        "Energy fed back: total (eq 2.44) or body only.",
        |c| energy_apex(c).map(|s| Slot::Measure(&mut s.measure))
    }
    ENERGY_APEX_PROPORTIONAL {
        "energy_apex.proportional_gain", "1", Real, [0.0, 10.0], 0.0, LIVE,
        "Outer loop's proportional gain on the last apex error (J per J).",
        |c| energy_apex(c).map(|s| R(&mut s.proportional))
    }
    ENERGY_APEX_INTEGRAL {
        "energy_apex.integral_gain", "1", Real, [1.0e-3, 9.99], 0.6, LIVE,
        "Outer loop's integral gain on the apex error (J of offset per J).",
        |c| energy_apex(c).map(|s| R(&mut s.gain))
    }
    ENERGY_APEX_MAX_OFFSET_J {
        "energy_apex.max_offset_j", "J", Real, [0.0, 1000.0], 30.0, LIVE,
        "Upper bound on the outer loop's correction of E_D.",
        |c| energy_apex(c).map(|s| R(&mut s.max_offset_j))
    }
    ENERGY_APEX_MIN_OFFSET_J {
        "energy_apex.min_offset_j", "J", Real, [-1000.0, 0.0], -5.0, LIVE,
        "Lower bound on the outer loop's correction of E_D.",
        |c| energy_apex(c).map(|s| R(&mut s.min_offset_j))
    }
    ENERGY_APEX_SPIN_UP {
        "energy_apex.spin_up_fraction", "1", Real, [0.0, 1.0], 0.0, LIVE,
        "Fraction of the target apex below which the descent runs the stance law (0: off).",
        |c| energy_apex(c).map(|s| R(&mut s.spin_up_fraction))
    }
    // --- shaped ----------------------------------------------------------------
    SHAPED_SPIN_UP_FRACTION {
        "shaped.spin_up_fraction", "1", Real, [0.0, 1.0], 0.6, LIVE,
        "Fraction of the flight's apex below which the descent spins the rotor up.",
        |c| shaped(c).map(|s| R(&mut s.spin_up_fraction))
    }
    SHAPED_SPIN_UP_MIN_APEX_M {
        "shaped.spin_up_min_apex_m", "m", Real, [0.0, 1.0], 0.005, LIVE,
        "Smallest flight apex that spins up.",
        |c| shaped(c).map(|s| R(&mut s.spin_up_min_apex_m))
    }
    SHAPED_SWITCH_FRACTION {
        "shaped.switch_fraction", "1", Real, [0.0, 2.0], 0.6, LIVE,
        "Fraction of the model's stance time T = pi sqrt((M + m_s)/k) after which the push turns to braking.",
        |c| shaped(c).map(|s| R(&mut s.switch_fraction))
    }
    SHAPED_BRAKE_FRACTION {
        "shaped.brake_fraction", "1", Real, [0.0, 1.0], 1.0, LIVE,
        "Braking current, fraction of the current limit.",
        |c| shaped(c).map(|s| R(&mut s.brake_fraction))
    }
    SHAPED_INITIAL_LEVEL {
        "shaped.initial_level", "1", Real, [0.0, 1.0], 1.0, LIVE,
        "Torque level of the first hop, fraction of the current limit.",
        |c| shaped(c).map(|s| R(&mut s.initial_level))
    }
    SHAPED_INTEGRAL_START {
        "shaped.integral_start", "1", Real, [0.0, 1.0], 0.8, LIVE,
        "Starting integral of the per-hop level loop.",
        |c| shaped(c).map(|s| R(&mut s.integral_start))
    }
    SHAPED_LEVEL_GAIN {
        "shaped.level_gain_per_j", "1/J", Real, [0.0, 10.0], 0.1, LIVE,
        "Integral gain of the level loop on the apex energy error.",
        |c| shaped(c).map(|s| R(&mut s.level_gain_per_j))
    }
    SHAPED_LEVEL_PROPORTIONAL {
        "shaped.level_proportional_per_j", "1/J", Real, [0.0, 10.0], 0.2, LIVE,
        "Proportional gain of the level loop.",
        |c| shaped(c).map(|s| R(&mut s.level_proportional_per_j))
    }
    SHAPED_BRAKING_MARGIN {
        "shaped.braking_margin", "1", Real, [1.0e-3, 1.0], 0.7, LIVE,
        "Fraction of the available braking deceleration the flight return plans with.",
        |c| shaped(c).map(|s| R(&mut s.braking_margin))
    }
    SHAPED_TRACKING_TIME_S {
        "shaped.tracking_time_s", "s", Real, [1.0e-3, 0.1], 0.005, LIVE,
        "Time constant of the flight return's speed tracking.",
        |c| shaped(c).map(|s| R(&mut s.tracking_time_s))
    }
    SHAPED_CREEP_SPEED_MPS {
        "shaped.creep_speed_mps", "m/s", Real, [0.0, 0.1], 0.01, LIVE,
        "Speed at which the nut arrives at its stop.",
        |c| shaped(c).map(|s| R(&mut s.creep_speed_mps))
    }
    // --- Phase estimator -------------------------------------------------------
    // Estimator, supervisor and calibration entries are set with the
    // amplifier disabled only. Derived from the model and not listed: the
    // overcurrent trip (10x the current limit), the stroke soft limits with
    // the braking deceleration they assume, the stops, the lead and torque
    // constant of the calibration, and the counter and converter widths
    // (board facts). The height encoder's origin is listed last (the
    // table's order is the link's numbering).
    EST_TOUCHDOWN_FORCE_N {
        "estimator.touchdown_force_n", "N", Real, [0.0, 1.0e4], 40.0, DISARMED,
        "Load-cell force beyond k (delta0 + p) that counts as touchdown evidence (8 sigma of 5 N).",
        |c| Some(R(&mut c.estimator.touchdown_force_n))
    }
    EST_LIFTOFF_FORCE_N {
        "estimator.liftoff_force_n", "N", Real, [-1.0e4, 1.0e4], 20.0, DISARMED,
        "Excess force below which liftoff is considered (below the touchdown force).",
        |c| Some(R(&mut c.estimator.liftoff_force_n))
    }
    EST_TOUCHDOWN_COMPRESSION_M {
        "estimator.touchdown_compression_m", "m", Real, [0.0, 0.5], 0.002, DISARMED,
        "Potentiometer compression above which touchdown is considered.",
        |c| Some(R(&mut c.estimator.touchdown_compression_m))
    }
    EST_LIFTOFF_COMPRESSION_M {
        "estimator.liftoff_compression_m", "m", Real, [-0.5, 0.5], 0.001, DISARMED,
        "Potentiometer compression below which liftoff is considered (below the touchdown compression).",
        |c| Some(R(&mut c.estimator.liftoff_compression_m))
    }
    EST_DEBOUNCE_SAMPLES {
        "estimator.debounce_samples", "samples", Count, [1.0, 255.0], 3.0, DISARMED,
        "Consecutive agreeing samples needed to change phase.",
        |c| Some(Slot::U8(&mut c.estimator.debounce_samples))
    }
    EST_FILTER_GAIN {
        "estimator.velocity_filter_gain", "1", Real, [0.0, 0.999], 0.9, DISARMED,
        "Filter gain G of eq 4.1 for both velocities.",
        |c| Some(R(&mut c.estimator.velocity_filter_gain))
    }
    EST_APEX_ARM_MPS {
        "estimator.apex_arm_velocity_mps", "m/s", Real, [1.0e-4, 10.0], 0.1, DISARMED,
        "Upward body velocity that arms apex detection in flight.",
        |c| Some(R(&mut c.estimator.apex_arm_velocity_mps))
    }
    EST_BOTTOM_ARM_MPS {
        "estimator.bottom_arm_velocity_mps", "m/s", Real, [1.0e-4, 10.0], 0.1, DISARMED,
        "Downward body speed that arms bottom detection in stance.",
        |c| Some(R(&mut c.estimator.bottom_arm_velocity_mps))
    }
    EST_PREDICT_CONTACT {
        "estimator.predict_contact", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
        "Predict touchdown and liftoff from the height encoder (the toe reaching the ground within half a period); load cell and potentiometer confirm (0: those two alone, late by their thresholds).",
        |c| Some(B(&mut c.estimator.predict_contact))
    }
    EST_CONTACT_CONFIRM_S {
        "estimator.contact_confirm_s", "s", Real, [1.0e-3, 1.0], 0.03, DISARMED,
        "Time within which load cell and potentiometer must confirm a predicted touchdown; else it is withdrawn (a liftoff) and prediction stays off.",
        |c| Some(R(&mut c.estimator.contact_confirm_s))
    }
    // --- Arming ----------------------------------------------------------------
    ARM_LINK_TIMEOUT_S {
        "arming.link_timeout_s", "s", Real, [1.0e-3, 60.0], 0.2, DISARMED,
        "No valid link frame for this long disarms the amplifier (and a dead link refuses arming).",
        |c| Some(R(&mut c.arming.link_timeout_s))
    }
    ARM_UNTETHERED {
        "arming.untethered", "-", Flag, [0.0, 1.0], 0.0, DISARMED,
        "Run without a link: no link needed to arm, and link loss does not disarm (an explicit choice; the simulator sets it).",
        |c| Some(B(&mut c.arming.untethered))
    }
    ARM_HOME_TOLERANCE_M {
        "arming.home_tolerance_m", "m", Real, [0.0, 0.05], 0.001, DISARMED,
        "To arm, the nut must be at most this far from its upper stop.",
        |c| Some(R(&mut c.arming.home_tolerance_m))
    }
    ARM_STILL_MPS {
        "arming.still_velocity_mps", "m/s", Real, [1.0e-4, 10.0], 0.05, DISARMED,
        "To arm, nut and body must be slower than this.",
        |c| Some(R(&mut c.arming.still_velocity_mps))
    }
    ARM_REQUIRE_TARE {
        "arming.require_tare", "-", Flag, [0.0, 1.0], 0.0, DISARMED,
        "Refuse to arm until a tare (hopper-link calibrate tare) has succeeded since boot (the board sets it: its offsets are not saved yet).",
        |c| Some(B(&mut c.arming.require_tare))
    }
    ARM_REQUIRE_HOME {
        "arming.require_home", "-", Flag, [0.0, 1.0], 0.0, DISARMED,
        "Refuse to arm until the nut was homed (hopper-link calibrate home, after calibrate direction) since boot: the motor encoder is incremental, its zero is lost at power-off.",
        |c| Some(B(&mut c.arming.require_home))
    }
    // --- Bring-up routines -----------------------------------------------------
    BRINGUP_CURRENT_LIMIT_A {
        "bringup.current_limit_a", "A", Real, [0.1, 10.0], 6.0, DISARMED,
        "Largest current a motor-driving bring-up routine commands (6 A: 200 N on the nut, 18% of the amplifier's limit).",
        |c| Some(R(&mut c.bringup.current_limit_a))
    }
    BRINGUP_SPEED_MPS {
        "bringup.speed_mps", "m/s", Real, [0.001, 0.05], 0.005, DISARMED,
        "Nut speed of the homing move and the spring sweep (5 mm/s: a stop reached at it stores 5 mJ in the 426 kg reflected rotor inertia).",
        |c| Some(R(&mut c.bringup.speed_mps))
    }
    BRINGUP_SWEEP_M {
        "bringup.sweep_m", "m", Real, [0.002, 0.03], 0.01, DISARMED,
        "Nut travel of the spring sweep, down from the upper stop and back.",
        |c| Some(R(&mut c.bringup.sweep_m))
    }
    // --- Supervisor limits -----------------------------------------------------
    SUP_MAX_MOTOR_DELTA {
        "supervisor.max_motor_delta_counts", "counts", Count, [1.0, 1.0e6], 64.0, DISARMED,
        "Largest plausible motor counter change per period (1000 rad/s at 2000 counts/rev and 10 kHz is 32, x2).",
        |c| Some(Slot::U32(&mut c.supervisor.max_motor_delta_counts))
    }
    SUP_MAX_HEIGHT_DELTA {
        "supervisor.max_height_delta_counts", "counts", Count, [1.0, 1.0e6], 32.0, DISARMED,
        "Largest plausible height counter change per period (10 m/s on a 20 mm pulley at 10 kHz is 16, x2).",
        |c| Some(Slot::U32(&mut c.supervisor.max_height_delta_counts))
    }
    SUP_NUT_POSITION_MIN_M {
        "supervisor.nut_position_min_m", "m", Real, [-1.0, 1.0], -0.01, DISARMED,
        "Lowest plausible nut position (stops at 0 and 0.05 m).",
        |c| Some(R(&mut c.supervisor.nut_position_range_m.min))
    }
    SUP_NUT_POSITION_MAX_M {
        "supervisor.nut_position_max_m", "m", Real, [-1.0, 1.0], 0.06, DISARMED,
        "Highest plausible nut position (stops at 0 and 0.05 m).",
        |c| Some(R(&mut c.supervisor.nut_position_range_m.max))
    }
    SUP_NUT_VELOCITY_MIN_MPS {
        "supervisor.nut_velocity_min_mps", "m/s", Real, [-100.0, 100.0], -1.0, DISARMED,
        "Lowest plausible nut velocity (the no-load speed is 0.64 m/s).",
        |c| Some(R(&mut c.supervisor.nut_velocity_range_mps.min))
    }
    SUP_NUT_VELOCITY_MAX_MPS {
        "supervisor.nut_velocity_max_mps", "m/s", Real, [-100.0, 100.0], 1.0, DISARMED,
        "Highest plausible nut velocity (the no-load speed is 0.64 m/s).",
        |c| Some(R(&mut c.supervisor.nut_velocity_range_mps.max))
    }
    SUP_MOTOR_SPEED_MIN_RAD_S {
        "supervisor.motor_speed_min_rad_s", "rad/s", Real, [-1.0e5, 1.0e5], -1200.0, DISARMED,
        "Lowest plausible motor speed (no-load 808 rad/s).",
        |c| Some(R(&mut c.supervisor.motor_speed_range_rad_s.min))
    }
    SUP_MOTOR_SPEED_MAX_RAD_S {
        "supervisor.motor_speed_max_rad_s", "rad/s", Real, [-1.0e5, 1.0e5], 1200.0, DISARMED,
        "Highest plausible motor speed (no-load 808 rad/s).",
        |c| Some(R(&mut c.supervisor.motor_speed_range_rad_s.max))
    }
    SUP_BODY_HEIGHT_MIN_M {
        "supervisor.body_height_min_m", "m", Real, [-10.0, 100.0], 0.4, DISARMED,
        "Lowest plausible body height z (l0 = 0.61 m).",
        |c| Some(R(&mut c.supervisor.body_height_range_m.min))
    }
    SUP_BODY_HEIGHT_MAX_M {
        "supervisor.body_height_max_m", "m", Real, [-10.0, 100.0], 3.0, DISARMED,
        "Highest plausible body height z (l0 = 0.61 m).",
        |c| Some(R(&mut c.supervisor.body_height_range_m.max))
    }
    SUP_BODY_VELOCITY_MIN_MPS {
        "supervisor.body_velocity_min_mps", "m/s", Real, [-1000.0, 1000.0], -10.0, DISARMED,
        "Lowest plausible body velocity.",
        |c| Some(R(&mut c.supervisor.body_velocity_range_mps.min))
    }
    SUP_BODY_VELOCITY_MAX_MPS {
        "supervisor.body_velocity_max_mps", "m/s", Real, [-1000.0, 1000.0], 10.0, DISARMED,
        "Highest plausible body velocity.",
        |c| Some(R(&mut c.supervisor.body_velocity_range_mps.max))
    }
    SUP_SPRING_FORCE_MIN_N {
        "supervisor.spring_force_min_n", "N", Real, [-1.0e5, 1.0e5], -50.0, DISARMED,
        "Lowest plausible spring force (both load-cell rails outside).",
        |c| Some(R(&mut c.supervisor.spring_force_range_n.min))
    }
    SUP_SPRING_FORCE_MAX_N {
        "supervisor.spring_force_max_n", "N", Real, [-1.0e5, 1.0e5], 1800.0, DISARMED,
        "Highest plausible spring force (both load-cell rails outside).",
        |c| Some(R(&mut c.supervisor.spring_force_range_n.max))
    }
    SUP_LEG_COMPRESSION_MIN_M {
        "supervisor.leg_compression_min_m", "m", Real, [-1.0, 1.0], -0.004, DISARMED,
        "Lowest plausible leg compression (both potentiometer rails outside).",
        |c| Some(R(&mut c.supervisor.leg_compression_range_m.min))
    }
    SUP_LEG_COMPRESSION_MAX_M {
        "supervisor.leg_compression_max_m", "m", Real, [-1.0, 1.0], 0.1, DISARMED,
        "Highest plausible leg compression (both potentiometer rails outside).",
        |c| Some(R(&mut c.supervisor.leg_compression_range_m.max))
    }
    SUP_SPRING_RATE {
        "supervisor.spring_rate_n_per_m", "N/m", Real, [10.0, 1.0e7], 11000.0, DISARMED,
        "Spring rate k of the sensor cross-checks (calibrated; Table 2.1: 11 kN/m).",
        |c| Some(R(&mut c.supervisor.spring_rate_n_per_m))
    }
    SUP_SPRING_PRELOAD {
        "supervisor.spring_preload_m", "m", Real, [0.0, 0.5], crate::model::design::SPRING_PRELOAD_M as f32, DISARMED,
        "Spring preload delta0 of the sensor cross-checks (calibrated; design: none).",
        |c| Some(R(&mut c.supervisor.spring_preload_m))
    }
    SUP_CONTACT_FORCE {
        "supervisor.contact_force_n", "N", Real, [-1.0e4, 1.0e4], 150.0, DISARMED,
        "Excess force above which the load cell says contact.",
        |c| Some(R(&mut c.supervisor.contact_force_n))
    }
    SUP_FREE_FORCE {
        "supervisor.free_force_n", "N", Real, [-1.0e4, 1.0e4], 40.0, DISARMED,
        "Excess force below which the load cell says no contact.",
        |c| Some(R(&mut c.supervisor.free_force_n))
    }
    SUP_CONTACT_COMPRESSION {
        "supervisor.contact_compression_m", "m", Real, [-1.0, 1.0], 0.015, DISARMED,
        "Leg compression above which the potentiometer says contact.",
        |c| Some(R(&mut c.supervisor.contact_compression_m))
    }
    SUP_FREE_COMPRESSION {
        "supervisor.free_compression_m", "m", Real, [-1.0, 1.0], 0.003, DISARMED,
        "Leg compression below which the potentiometer says no contact.",
        |c| Some(R(&mut c.supervisor.free_compression_m))
    }
    SUP_CONTACT_DISAGREE_PERIODS {
        "supervisor.contact_disagree_periods", "periods", Count, [1.0, 65535.0], 20.0, DISARMED,
        "Consecutive disagreeing periods before contact-disagree latches (2 ms at 10 kHz).",
        |c| Some(Slot::U16(&mut c.supervisor.contact_disagree_periods))
    }
    SUP_SPRING_MISMATCH {
        "supervisor.spring_mismatch_n", "N", Real, [1.0e-3, 1.0e30], 30.0, DISARMED,
        "Largest plausible |F - k (delta0 + p + x)| before sensor-disagree (13 sigma; 1e30 turns it off).",
        |c| Some(R(&mut c.supervisor.spring_mismatch_n))
    }
    SUP_FROZEN_SPEED {
        "supervisor.frozen_speed_rad_s", "rad/s", Real, [1.0e-3, 1.0e30], 100.0, DISARMED,
        "Motor speed above which a period without a count is encoder-frozen (1e30 turns it off).",
        |c| Some(R(&mut c.supervisor.frozen_speed_rad_s))
    }
    // --- E-stop debounce -------------------------------------------------------
    ESTOP_PRESS_S {
        "estop.press_s", "s", Real, [0.0, 0.01], 2.0e-4, DISARMED,
        "The e-stop input pressed without a break for this long is a press (shorter is a glitch; the button also breaks the amplifier enable in hardware).",
        |c| Some(R(&mut c.estop.press_s))
    }
    ESTOP_RELEASE_S {
        "estop.release_s", "s", Real, [0.0, 2.0], 0.05, DISARMED,
        "The e-stop input released without a break for this long is a release (arming and fault resets wait for it: longer than a contact's bounce).",
        |c| Some(R(&mut c.estop.release_s))
    }
    // --- Motor thermal model and protection ------------------------------------
    THERMAL_PROTECT {
        "thermal.protect", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
        "Derate and fault on the winding temperature estimate; 0 only for control studies past the motor's thermal limit (the estimate is still reported), never on a robot.",
        |c| Some(B(&mut c.supervisor.thermal.protect))
    }
    THERMAL_RESISTANCE_OHM {
        "thermal.winding_resistance_ohm", "ohm", Real, [1.0e-3, 100.0], 0.299, DISARMED,
        "Motor winding resistance at 25 C (the RE 40 24 V winding's; use your motor's datasheet).",
        |c| Some(R(&mut c.supervisor.thermal.winding_resistance_ohm))
    }
    THERMAL_WINDING_TO_HOUSING {
        "thermal.winding_to_housing_k_per_w", "K/W", Real, [1.0e-2, 100.0], 1.93, DISARMED,
        "Thermal resistance winding to housing (motor datasheet).",
        |c| Some(R(&mut c.supervisor.thermal.winding_to_housing_k_per_w))
    }
    THERMAL_HOUSING_TO_AMBIENT {
        "thermal.housing_to_ambient_k_per_w", "K/W", Real, [1.0e-2, 100.0], 4.65, DISARMED,
        "Thermal resistance housing to ambient (motor datasheet; a heat sink lowers it).",
        |c| Some(R(&mut c.supervisor.thermal.housing_to_ambient_k_per_w))
    }
    THERMAL_WINDING_TAU {
        "thermal.winding_time_constant_s", "s", Real, [0.1, 1.0e4], 41.6, DISARMED,
        "Winding thermal time constant (motor datasheet).",
        |c| Some(R(&mut c.supervisor.thermal.winding_time_constant_s))
    }
    THERMAL_HOUSING_TAU {
        "thermal.housing_time_constant_s", "s", Real, [1.0, 1.0e5], 1120.0, DISARMED,
        "Motor (housing) thermal time constant (motor datasheet).",
        |c| Some(R(&mut c.supervisor.thermal.housing_time_constant_s))
    }
    THERMAL_AMBIENT {
        "thermal.ambient_c", "degC", Real, [-40.0, 80.0], 25.0, DISARMED,
        "Ambient temperature; the motor is taken to be at it at boot.",
        |c| Some(R(&mut c.supervisor.thermal.ambient_c))
    }
    THERMAL_DERATE {
        "thermal.derate_winding_c", "degC", Real, [0.0, 250.0], 135.0, DISARMED,
        "Estimated winding temperature where the current limit starts to fall.",
        |c| Some(R(&mut c.supervisor.thermal.derate_winding_c))
    }
    THERMAL_TRIP {
        "thermal.trip_winding_c", "degC", Real, [0.0, 250.0], 150.0, DISARMED,
        "Estimated winding temperature that latches overtemperature (5 K under the RE 40's 155 C).",
        |c| Some(R(&mut c.supervisor.thermal.trip_winding_c))
    }
    THERMAL_DERATED_FRACTION {
        "thermal.derated_limit_fraction", "1", Real, [0.05, 1.0], 0.5, DISARMED,
        "Current limit at the trip temperature, as a fraction of the amplifier's (linear from the derate temperature).",
        |c| Some(R(&mut c.supervisor.thermal.derated_limit_fraction))
    }
    // --- Sensor and DAC calibration --------------------------------------------
    CAL_MOTOR_COUNTS_PER_REV {
        "calibration.motor_counts_per_rev", "counts", Count, [1.0, 1.0e6], 2000.0, DISARMED,
        "Motor encoder counts per revolution (500 lines x 4).",
        |c| Some(Slot::U32(&mut c.calibration.motor_counts_per_rev))
    }
    CAL_MOTOR_POSITIVE_DOWN {
        "calibration.motor_counts_positive_down", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
        "Motor counts increase when the nut moves down.",
        |c| Some(B(&mut c.calibration.motor_counts_positive_down))
    }
    CAL_HEIGHT_COUNTS_PER_REV {
        "calibration.height_counts_per_rev", "counts", Count, [1.0, 1.0e6], 2000.0, DISARMED,
        "Height encoder counts per pulley revolution (placeholder).",
        |c| Some(Slot::U32(&mut c.calibration.height_counts_per_rev))
    }
    CAL_HEIGHT_POSITIVE_UP {
        "calibration.height_counts_positive_up", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
        "Height counts increase when the body moves up.",
        |c| Some(B(&mut c.calibration.height_counts_positive_up))
    }
    CAL_PULLEY_RADIUS {
        "calibration.height_pulley_radius_m", "m", Real, [1.0e-4, 1.0], 0.02, DISARMED,
        "Radius of the height-sensor pulley (placeholder).",
        |c| Some(R(&mut c.calibration.height_pulley_radius_m))
    }
    CAL_LOADCELL_GAIN {
        "calibration.loadcell_gain_n_per_code", "N/code", Real, [-1.0e3, 1.0e3], 0.5, DISARMED,
        "Load-cell gain, compression positive (placeholder; not 0).",
        |c| Some(R(&mut c.calibration.loadcell_gain_n_per_code))
    }
    CAL_LOADCELL_OFFSET {
        "calibration.loadcell_offset_code", "code", Real, [-1.0e5, 1.0e5], 200.0, DISARMED,
        "Load-cell code at zero force (placeholder).",
        |c| Some(R(&mut c.calibration.loadcell_offset_code))
    }
    CAL_POT_GAIN {
        "calibration.pot_gain_m_per_code", "m/code", Real, [-1.0, 1.0], 0.12 / 4096.0, DISARMED,
        "Potentiometer gain, m of leg compression per code (placeholder 0.12/4096; not 0).",
        |c| Some(R(&mut c.calibration.pot_gain_m_per_code))
    }
    CAL_POT_OFFSET {
        "calibration.pot_offset_code", "code", Real, [-1.0e5, 1.0e5], 205.0, DISARMED,
        "Potentiometer code at zero compression (placeholder).",
        |c| Some(R(&mut c.calibration.pot_offset_code))
    }
    CAL_DAC_ZERO {
        "calibration.dac_zero_code", "code", Count, [0.0, 65535.0], 2048.0, DISARMED,
        "DAC code for zero current (mid-scale; within the DAC range).",
        |c| Some(Slot::U16(&mut c.calibration.dac_zero_code))
    }
    CAL_DAC_AMPS {
        "calibration.dac_amps_per_code", "A/code", Real, [1.0e-6, 100.0], 0.01953125, DISARMED,
        "Amplifier current per DAC code (placeholder 40 A / 2048).",
        |c| Some(R(&mut c.calibration.dac_amps_per_code))
    }
    CAL_HEIGHT_AT_ORIGIN_M {
        "calibration.height_at_origin_m", "m", Real, [0.0, 10.0], 0.61, DISARMED,
        "Body height z where the height encoder counted from at boot (the leg length l0 with the toe on the ground; a simulated run's start height).",
        |c| Some(R(&mut c.calibration.height_at_origin_m))
    }
    // --- added later: at the end, so the link's numbers of the others stay ---
    SHAPED_LEAST_EFFORT_RETURN {
        "shaped.least_effort_return", "-", Flag, [0.0, 1.0], 0.0, LIVE,
        "Bring the nut home in flight with the least int i^2 dt (the spring helping, reaching the stop when the push is due) instead of along the braking curve.",
        |c| shaped(c).map(|s| B(&mut s.least_effort_return))
    }
}

/// The master switches of protections, each with its safe value: a real
/// robot's link refuses any other value (a simulator keeps them, for
/// control studies). The protections' thresholds (`thermal.*`, the link
/// timeout) stay settable within their ranges: they are the motor's and
/// the bench's data, which a user must be able to enter.
pub const PROTECTIONS: [(&Param, f32); 2] = [(&THERMAL_PROTECT, 1.0), (&ARM_UNTETHERED, 0.0)];

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

/// The selected controller's configuration, if it is the one named: a
/// controller's parameters exist only while it is selected.
macro_rules! selected {
    ($($(#[$meta:meta])* $fn:ident => $pattern:pat => $cfg:ident: $ty:ty;)*) => {$(
        $(#[$meta])*
        fn $fn(c: &mut HopperConfig) -> Option<&mut $ty> {
            match &mut c.strategy {
                $pattern => Some($cfg),
                _ => None,
            }
        }
    )*};
}

selected! {
    energy => Strategy::Thesis(StanceLaw::Energy(s)) => s: energy::Config;
    open_torque => Strategy::Thesis(StanceLaw::OpenTorque(s)) => s: open_torque::Config;
    modified_torque => Strategy::Thesis(StanceLaw::ModifiedTorque(s)) => s: modified_torque::Config;
    step_open => Strategy::Thesis(StanceLaw::StepOpen(s)) => s: step_open::Config;
    step_closed => Strategy::Thesis(StanceLaw::StepClosed(s)) => s: step_closed::Config;
    velocity => Strategy::Thesis(StanceLaw::Velocity(s)) => s: velocity::Config;
    energy_apex => Strategy::EnergyApex(s) => s: energy_apex::ApexLoop;
    shaped => Strategy::Shaped(s) => s: shaped::Config;
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
    Ok(match slot(c, p).ok_or(ParamError::NotSelected(p.name))? {
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

/// Checks every parameter `cfg` holds against its entry's range (and
/// wholeness), naming the first one out of range in table order: the one
/// range check of a configuration, so a new entry is checked with no code
/// of its own. `Hopper::new` runs it on the whole configuration; each
/// part's `validate` runs it on the part in place ([`validate_part`]).
pub fn validate(cfg: &HopperConfig) -> Result<(), InvalidField> {
    check_in(&mut { *cfg })
}

/// [`validate`] for one part of a configuration, whose entries are found
/// where they live: `place` puts the part into the default configuration
/// (whose other values are the table's defaults, all in range).
pub fn validate_part(place: impl FnOnce(&mut HopperConfig)) -> Result<(), InvalidField> {
    let mut cfg = defaults();
    place(&mut cfg);
    check_in(&mut cfg)
}

/// The default configuration, built in one place in the image (not once
/// per part that [`validate_part`] checks).
#[inline(never)]
fn defaults() -> HopperConfig {
    HopperConfig::default()
}

/// [`validate`] through a configuration lent mutably (the slots are
/// reached by `&mut`; nothing is changed).
#[inline(never)]
fn check_in(cfg: &mut HopperConfig) -> Result<(), InvalidField> {
    for p in TABLE {
        // A parameter of another controller is not in `cfg` to check.
        if let Ok(v) = read(cfg, p) {
            p.check(v)?;
        }
    }
    Ok(())
}

/// Sets parameter `name` of `cfg` to `value`, after checking it against the
/// parameter's range. The whole configuration is validated again when a
/// controller is built from it (`Hopper::new`).
pub fn set(cfg: &mut HopperConfig, name: &str, value: f32) -> Result<(), ParamError> {
    write(cfg, find(name).ok_or(ParamError::Unknown)?, value)
}

/// [`set`] by table entry.
pub fn write(cfg: &mut HopperConfig, p: &Param, value: f32) -> Result<(), ParamError> {
    let v = p.check(value).map_err(|f| ParamError::OutOfRange(f.0))?;
    match slot(cfg, p).ok_or(ParamError::NotSelected(p.name))? {
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

/// Where a parameter lives: the controller whose configuration holds it,
/// and a choice of that controller it needs (`step_closed.min_compression_m`
/// exists only with `step_closed.gain` normalised).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Owner {
    /// The controller, an index of [`CONTROLLER_NAMES`].
    pub controller: usize,
    /// The choice of that controller and the value it must have.
    pub choice: Option<(&'static Param, usize)>,
}

/// The configuration of controller `index` at its defaults.
fn with_controller(index: usize) -> Option<HopperConfig> {
    let mut cfg = HopperConfig::default();
    write(&mut cfg, &CONTROLLER, index as f32).ok()?;
    Some(cfg)
}

/// Whether `p` is in `cfg` with choice `q` set to `v`.
fn readable_with(cfg: &HopperConfig, q: &Param, v: usize, p: &Param) -> bool {
    let mut c = *cfg;
    write(&mut c, q, v as f32).is_ok() && read(&mut c, p).is_ok()
}

/// The choices (other than the controller) that `cfg` has, with their
/// number of values.
fn choices_of(cfg: &HopperConfig) -> impl Iterator<Item = (&'static Param, usize)> + '_ {
    TABLE.iter().copied().filter_map(move |q| match q.kind {
        Kind::Choice(values) if q.id != Id::CONTROLLER && read(&mut { *cfg }, q).is_ok() => {
            Some((q, values.len()))
        }
        _ => None,
    })
}

/// Which controller (and choice) `p` belongs to; `None` for a parameter of
/// every configuration (`target_apex_m`, `arming.*`). Found by trying the
/// configurations themselves rather than from the names, so a new
/// controller or choice needs no change here. The link answers it
/// (`ParamMeta`) so the host can say what would make a parameter active.
pub fn owner(p: &Param) -> Option<Owner> {
    let n = CONTROLLER_NAMES.len();
    // Readable in some variant of a configuration: at its defaults, or
    // with one of its choices switched.
    let has = |i: usize| {
        with_controller(i).is_some_and(|cfg| {
            read(&mut { cfg }, p).is_ok()
                || choices_of(&cfg).any(|(q, k)| (0..k).any(|v| readable_with(&cfg, q, v, p)))
        })
    };
    if (0..n).all(has) {
        return None;
    }
    let controller = (0..n).find(|&i| has(i))?;
    let cfg = with_controller(controller)?;
    // A choice of the controller that some of its values leave `p` out of.
    let choice = choices_of(&cfg).find_map(|(q, k)| {
        let first = (0..k).find(|&v| readable_with(&cfg, q, v, p))?;
        (!(0..k).all(|v| readable_with(&cfg, q, v, p))).then_some((q, first))
    });
    Some(Owner { controller, choice })
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    #[test]
    fn parameters_belong_to_their_controllers() {
        let index = |n: &str| CONTROLLER_NAMES.iter().position(|c| *c == n);
        let of = |name: &str| find(name).and_then(owner).map(|o| o.controller);
        assert_eq!(of("energy.gain_nm_per_j"), index("energy"));
        assert_eq!(of("constant_torque.torque_nm"), index("open-torque"));
        assert_eq!(of("shaped.switch_fraction"), index("shaped"));
        assert_eq!(of("energy_apex.measure"), index("energy-apex"));
        // Every configuration has these.
        for general in ["controller", "target_apex_m", "arming.require_tare"] {
            assert_eq!(find(general).and_then(owner), None, "{general}");
        }
        // Only with the non-default choice, and with the default one.
        let o = find("step_closed.min_compression_m").and_then(owner);
        assert_eq!(o.map(|o| o.controller), index("step-closed"));
        assert_eq!(
            o.and_then(|o| o.choice).map(|(q, v)| (q.name, v)),
            Some(("step_closed.gain", 1))
        );
        let o = find("step_closed.kp_m_per_j").and_then(owner);
        assert_eq!(
            o.and_then(|o| o.choice).map(|(q, v)| (q.name, v)),
            Some(("step_closed.gain", 0))
        );
    }

    /// Every parameter that some controller's configuration lacks has an
    /// owner: none would be reported as "not in the robot's configuration".
    #[test]
    fn every_controller_parameter_has_an_owner() {
        for i in 0..CONTROLLER_NAMES.len() {
            let cfg = with_controller(i).unwrap_or_else(|| panic!("controller {i}"));
            for p in TABLE {
                if read(&mut { cfg }, p).is_err() {
                    assert!(owner(p).is_some(), "{}", p.name);
                }
            }
        }
    }
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

    /// Every entry's range is enforced with no code of its own: a value
    /// out of range put straight into its slot (past `set`'s check) makes
    /// [`validate`] name that entry and `Hopper::new` refuse the
    /// configuration, for every controller's parameters.
    #[test]
    fn every_entry_out_of_range_is_refused_by_name() {
        let mut checked = 0;
        for i in 0..CONTROLLER_NAMES.len() {
            let cfg = with_controller(i).unwrap_or_else(|| panic!("controller {i}"));
            assert_eq!(validate(&cfg), Ok(()), "defaults of controller {i}");
            for p in TABLE {
                let mut c = cfg;
                let put = match slot(&mut c, p) {
                    Some(Slot::Real(v)) => {
                        *v = f32::NAN;
                        true
                    }
                    // Below the least count (flags and choices cannot be
                    // out of range).
                    Some(Slot::U32(n)) if p.min >= 1.0 => {
                        *n = 0;
                        true
                    }
                    Some(Slot::U16(n)) if p.min >= 1.0 => {
                        *n = 0;
                        true
                    }
                    Some(Slot::U8(n)) if p.min >= 1.0 => {
                        *n = 0;
                        true
                    }
                    _ => false,
                };
                if !put {
                    continue;
                }
                assert_eq!(validate(&c), Err(InvalidField(p.name)), "{}", p.name);
                assert!(Hopper::new(c).is_err(), "{} = NaN was built", p.name);
                checked += 1;
            }
        }
        // Every real and count entry of some controller was tried.
        assert!(checked >= 100, "{checked}");
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
