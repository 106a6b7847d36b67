//! Control laws (thesis sections 2.1.3, 4.3, 4.4.3). Every law returns a motor
//! **current command in A**, positive drives the nut down (compresses the
//! spring), clamped to the actuator's usable current limit. A non-finite input
//! gives `Err(LawError::NonFiniteInput)`; the caller must then command 0 A
//! (see [`or_zero`]). Nothing here can return NaN.
//!
//! Torque and current: `i = tau / k_m`. Where a law computes a force on the
//! nut (position and velocity loops), the motor torque that balances it is
//! `tau = F r / eta` (the plant's drive force is `eta tau / r`).
//!
//! Every controller is one type in one module with its own state, behind
//! one interface ([`ControlLaw`]: events in, current out), dispatched from
//! one enum ([`Controller`], built from a [`Strategy`] and validated once):
//! [`passive`], each thesis law below with the flight PD in flight,
//! [`energy_apex`] and [`shaped`].
//!
//! Stance laws ([`StanceLaw`]):
//! - [`step_open`]: open-loop position step (eq 2.49);
//! - [`step_closed`]: closed-loop position step (eqs 2.50-2.51);
//! - [`open_torque`]: open-loop constant torque (section 2.1.3.4);
//! - [`energy`]: energy-feedback torque (eq 2.52);
//! - [`velocity`]: actuator velocity (eq 2.53);
//! - [`modified_torque`]: full torque in stance and late in the descent (section 4.4.3).
//!
//! Flight law: [`flight_pd`] (section 4.3, eq 4.4).

pub mod energy;
pub mod energy_apex;
pub mod flight_pd;
pub mod modified_torque;
pub mod open_torque;
pub mod passive;
pub mod shaped;
pub mod step_closed;
pub mod step_open;
pub mod velocity;

use crate::estimator::{Phase, PhaseEvent};
use crate::model::ModelParams;

pub use crate::param::InvalidField;

pub(crate) use crate::param::require;

/// Why a law refused to produce a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LawError {
    /// An input or a gain is NaN or infinite; command 0 A.
    NonFiniteInput,
}

/// The caller's fallback: the command, or 0 A on error.
pub fn or_zero(command: Result<f32, LawError>) -> f32 {
    command.unwrap_or(0.0)
}

/// Plant constants every law needs (from [`ModelParams`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Actuator {
    /// Motor torque constant `k_m`, N m/A (> 0).
    pub torque_constant_nm_per_a: f32,
    /// Symmetric current clamp, A (>= 0): `min(amplifier limit, torque limit / k_m)`.
    pub current_limit_a: f32,
    /// Screw ratio `r`, m/rad.
    pub screw_m_per_rad: f32,
    /// Motor + screw efficiency `eta`, in (0, 1].
    pub efficiency: f32,
    /// Spring stiffness `k`, N/m (for the eq 2.51 normalisation).
    pub spring_stiffness_n_per_m: f32,
    /// Nut stroke, m: position references are clamped to `0..stroke`.
    pub stroke_m: f32,
}

impl Actuator {
    /// Takes the constants from a model (validate it first).
    pub fn from_model(m: &ModelParams) -> Self {
        Self {
            torque_constant_nm_per_a: m.torque_constant_nm_per_a,
            current_limit_a: m.usable_current_limit_a(),
            screw_m_per_rad: m.screw_m_per_rad(),
            efficiency: m.efficiency,
            spring_stiffness_n_per_m: m.spring_stiffness_n_per_m,
            stroke_m: m.stroke_m,
        }
    }

    /// The clamp actually applied, A: `current_limit_a` if finite and
    /// positive, else 0 (a bad limit can only make the output safer).
    pub fn usable_limit_a(&self) -> f32 {
        crate::supervisor::sane_limit(self.current_limit_a)
    }

    /// Clamps a current to `+-current_limit_a`; non-finite gives the error.
    pub fn clamp_current(&self, current_a: f32) -> Result<f32, LawError> {
        let limit = self.usable_limit_a();
        if current_a.is_nan() {
            return Err(LawError::NonFiniteInput);
        }
        // +-inf (e.g. a huge gain) saturates like any large value.
        Ok(current_a.clamp(-limit, limit))
    }

    /// Current for a motor torque, `i = tau / k_m`, A, clamped.
    pub fn torque_to_current(&self, torque_nm: f32) -> Result<f32, LawError> {
        if !torque_nm.is_finite() {
            return Err(LawError::NonFiniteInput);
        }
        let kt = self.torque_constant_nm_per_a;
        if !(kt > 0.0 && kt.is_finite()) {
            return Err(LawError::NonFiniteInput);
        }
        self.clamp_current(torque_nm / kt)
    }

    /// Current for a force on the nut: `tau = F r / eta`, `i = tau / k_m`, A, clamped.
    pub fn nut_force_to_current(&self, force_n: f32) -> Result<f32, LawError> {
        let eta = self.efficiency;
        if !(eta > 0.0 && eta.is_finite()) {
            return Err(LawError::NonFiniteInput);
        }
        self.torque_to_current(force_n * self.screw_m_per_rad / eta)
    }
}

impl Default for Actuator {
    fn default() -> Self {
        Self::from_model(&ModelParams::default())
    }
}

/// `Ok(())` if every value is finite.
///
/// One addition per value and one test: the sum is non-finite if any value
/// is NaN or infinite. Finite values so large that their sum overflows are
/// refused too, which is the safe side (the caller commands 0 A).
#[inline(always)]
pub(crate) fn check_finite(values: &[f32]) -> Result<(), LawError> {
    if values.iter().fold(0.0_f32, |acc, v| acc + v).is_finite() {
        Ok(())
    } else {
        Err(LawError::NonFiniteInput)
    }
}

/// Position PD on the nut used by the step laws (eqs 2.49-2.50):
/// `F = F_ff + k_p,f (p_ref - p) - k_v,f pd`, then `tau = F r / eta`, where
/// the feed-forward `F_ff` is the measured spring force (clamped at >= 0) when
/// `spring_feedforward` is set, else 0. Without it the PD settles where
/// `k_p,f (p_ref - p)` balances the spring (~500 N at the bottom of stance:
/// 6 mm short of a 10 mm step), so the step is not tracked.
///
/// Table 2.1 gives `k_p,f = 8e4` and `k_v,f = 300` without units. Read as
/// N/m and N s/m on the nut they are sensible: a 10 mm error gives 800 N
/// (0.71 N m, near the 1 N m limit) and 1 m/s gives 300 N. (Read as N m/rad
/// of motor angle, or per metre in torque, they would saturate at any error.)
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NutPositionPd {
    /// Position gain `k_p,f`, N/m (force on the nut per metre of error), >= 0. Default 8e4.
    pub kp_n_per_m: f32,
    /// Velocity gain `k_v,f`, N s/m (force per m/s of nut velocity), >= 0. Default 300.
    pub kd_n_s_per_m: f32,
    /// Whether to add the measured spring force as feed-forward. Default true.
    pub spring_feedforward: bool,
}

impl Default for NutPositionPd {
    /// Table 2.1's loop: the open-loop step's defaults
    /// ([`step_open::entries::STEP_OPEN_KP`] and the entries after it).
    fn default() -> Self {
        Self {
            kp_n_per_m: step_open::entries::STEP_OPEN_KP.default,
            kd_n_s_per_m: step_open::entries::STEP_OPEN_KD.default,
            spring_feedforward: step_open::entries::STEP_OPEN_FEEDFORWARD.default_flag(),
        }
    }
}

impl NutPositionPd {
    /// Current that drives the nut from `p` (m) at `pd` (m/s) to `p_ref` (m)
    /// against the measured spring force `spring_force_n` (N), A, clamped.
    pub fn current_a(
        &self,
        act: &Actuator,
        p_ref_m: f32,
        p_m: f32,
        pd_mps: f32,
        spring_force_n: f32,
    ) -> Result<f32, LawError> {
        check_finite(&[p_ref_m, p_m, pd_mps, self.kp_n_per_m, self.kd_n_s_per_m])?;
        check_finite(&[spring_force_n])?;
        let ff = if self.spring_feedforward {
            crate::num::max(spring_force_n, 0.0)
        } else {
            0.0
        };
        let force_n = ff + self.kp_n_per_m * (p_ref_m - p_m) - self.kd_n_s_per_m * pd_mps;
        act.nut_force_to_current(force_n)
    }
}

/// Measurements and targets a stance law uses.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StanceInput {
    /// Estimated energy `E`, J (e.g. [`crate::energy::total_energy_j`]).
    pub energy_j: f32,
    /// Desired energy `E_D`, J (e.g. [`ModelParams::desired_energy_j`]).
    pub desired_energy_j: f32,
    /// Nut position `p`, m (down positive).
    pub nut_position_m: f32,
    /// Nut velocity `pd = r theta dot`, m/s.
    pub nut_velocity_mps: f32,
    /// Leg compression `l0 - z`, m (equals `z(t_td) - z(t)` of eq 2.51).
    pub leg_compression_m: f32,
    /// Load-cell spring force, N (velocity law feed-forward).
    pub spring_force_n: f32,
    /// Whether the bottom of stance (`t1`, the `Bottom` event) has passed.
    pub after_bottom: bool,
}

/// The stance law in use, with its configuration.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StanceLaw {
    /// Open-loop position step, eq 2.49.
    StepOpen(step_open::Config),
    /// Closed-loop position step, eqs 2.50-2.51.
    StepClosed(step_closed::Config),
    /// Open-loop constant torque.
    OpenTorque(open_torque::Config),
    /// Energy-feedback torque, eq 2.52.
    Energy(energy::Config),
    /// Actuator velocity, eq 2.53.
    Velocity(velocity::Config),
    /// Modified torque (section 4.4.3); in flight see [`modified_torque::flight_active`].
    ModifiedTorque(modified_torque::Config),
}

impl Default for StanceLaw {
    fn default() -> Self {
        StanceLaw::Energy(energy::Config::default())
    }
}

/// Declares the laws: the thesis's and this project's own (written out
/// below), then the laws added to the registry ([`registry!`]'s one line
/// each), and everything that lists them: [`ControllerKind`] (whose names
/// are the `controller` parameter's choices, the command line's and the
/// link's), [`Strategy`], [`Controller`] and its dispatch, each added
/// law's parameters in the table and the reach of its configuration.
macro_rules! laws {
    ($( $(#[$doc:meta])* $variant:ident => $module:ident, )*) => {
        $( pub mod $module; )*

        /// What runs in stance and in flight: the controller's configuration. Each
        /// variant is built into its [`Controller`] (validated once).
        #[derive(Debug, Clone, Copy, PartialEq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Strategy {
            /// Motor off: 0 A in every phase (thesis section 4.4.1, passive hopping).
            Passive,
            /// A thesis stance law, with the flight PD back-drive in flight.
            Thesis(StanceLaw),
            /// The apex-regulating energy law, with the flight PD in flight.
            EnergyApex(energy_apex::ApexLoop),
            /// Shaped torque with its own braking-curve back-drive in flight and a
            /// per-hop loop on the torque level ([`shaped`]).
            Shaped(shaped::Config),
            $(
                $(#[$doc])*
                $variant($module::Config),
            )*
        }

        /// Which controller, without its settings. The index in [`ControllerKind::ALL`]
        /// is the value of the `controller` parameter ([`crate::params::CONTROLLER`]).
        ///
        /// The declaration order is that index (strum's [`strum::VariantArray`] and
        /// [`strum::VariantNames`] list the variants in it), and each variant's name
        /// is its kebab-case spelling ([`ControllerKind::name`]): a law added to the
        /// registry comes after the others, so no other law's index changes.
        #[derive(
            Debug,
            Clone,
            Copy,
            PartialEq,
            Eq,
            Hash,
            strum::VariantArray,
            strum::VariantNames,
            strum::IntoStaticStr,
        )]
        #[strum(serialize_all = "kebab-case")]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum ControllerKind {
            /// `passive`: the motor off.
            Passive,
            /// `step-open`: eq 2.49.
            StepOpen,
            /// `step-closed`: eqs 2.50-2.51.
            StepClosed,
            /// `open-torque`: constant stance torque.
            OpenTorque,
            /// `energy`: eq 2.52.
            Energy,
            /// `energy-apex`: eq 2.52 with a per-hop loop on the apex.
            EnergyApex,
            /// `velocity`: eq 2.53.
            Velocity,
            /// `modified-torque`: section 4.4.3.
            ModifiedTorque,
            /// `shaped`: this project's shaped torque.
            Shaped,
            $(
                $(#[$doc])*
                $variant,
            )*
        }

        impl ControllerKind {
            /// This controller with its default settings.
            pub fn default_strategy(self) -> Strategy {
                match self {
                    ControllerKind::Passive => Strategy::Passive,
                    ControllerKind::StepOpen => {
                        Strategy::Thesis(StanceLaw::StepOpen(step_open::Config::default()))
                    }
                    ControllerKind::StepClosed => {
                        Strategy::Thesis(StanceLaw::StepClosed(step_closed::Config::default()))
                    }
                    ControllerKind::OpenTorque => {
                        Strategy::Thesis(StanceLaw::OpenTorque(open_torque::Config::default()))
                    }
                    ControllerKind::Energy => {
                        Strategy::Thesis(StanceLaw::Energy(energy::Config::default()))
                    }
                    ControllerKind::EnergyApex => {
                        Strategy::EnergyApex(energy_apex::ApexLoop::default())
                    }
                    ControllerKind::Velocity => {
                        Strategy::Thesis(StanceLaw::Velocity(velocity::Config::default()))
                    }
                    ControllerKind::ModifiedTorque => Strategy::Thesis(StanceLaw::ModifiedTorque(
                        modified_torque::Config::default(),
                    )),
                    ControllerKind::Shaped => Strategy::Shaped(shaped::Config::default()),
                    $(
                        ControllerKind::$variant => Strategy::$variant($module::Config::default()),
                    )*
                }
            }

            /// Whether this is one of the thesis's laws or this project's own
            /// (which the results pages study), not one added to the registry.
            #[allow(clippy::match_single_binding, unreachable_patterns)]
            pub const fn is_builtin(self) -> bool {
                match self {
                    $( ControllerKind::$variant => false, )*
                    _ => true,
                }
            }
        }

        impl Strategy {
            /// Which controller this is.
            pub fn kind(&self) -> ControllerKind {
                match self {
                    Strategy::Passive => ControllerKind::Passive,
                    Strategy::Thesis(StanceLaw::StepOpen(_)) => ControllerKind::StepOpen,
                    Strategy::Thesis(StanceLaw::StepClosed(_)) => ControllerKind::StepClosed,
                    Strategy::Thesis(StanceLaw::OpenTorque(_)) => ControllerKind::OpenTorque,
                    Strategy::Thesis(StanceLaw::Energy(_)) => ControllerKind::Energy,
                    Strategy::EnergyApex(_) => ControllerKind::EnergyApex,
                    Strategy::Thesis(StanceLaw::Velocity(_)) => ControllerKind::Velocity,
                    Strategy::Thesis(StanceLaw::ModifiedTorque(_)) => {
                        ControllerKind::ModifiedTorque
                    }
                    Strategy::Shaped(_) => ControllerKind::Shaped,
                    $( Strategy::$variant(_) => ControllerKind::$variant, )*
                }
            }
        }

        /// Every controller, with its own state; [`Strategy`] says which one.
        #[derive(Debug, Clone, PartialEq)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub enum Controller {
            /// [`passive::Passive`].
            Passive(passive::Passive),
            /// [`step_open::StepOpen`].
            StepOpen(step_open::StepOpen),
            /// [`step_closed::StepClosed`].
            StepClosed(step_closed::StepClosed),
            /// [`open_torque::OpenTorque`].
            OpenTorque(open_torque::OpenTorque),
            /// [`energy::Energy`].
            Energy(energy::Energy),
            /// [`velocity::Velocity`].
            Velocity(velocity::Velocity),
            /// [`modified_torque::ModifiedTorque`].
            ModifiedTorque(modified_torque::ModifiedTorque),
            /// [`energy_apex::EnergyApex`].
            EnergyApex(energy_apex::EnergyApex),
            /// [`shaped::Shaped`].
            Shaped(shaped::Shaped),
            $(
                $(#[$doc])*
                $variant($module::Law),
            )*
        }

        impl Controller {
            /// Builds the controller `strategy` names for `model`, with `flight` as
            /// the thesis laws' flight back-drive. A field out of range is refused
            /// by name.
            pub fn new(
                strategy: &Strategy,
                model: &ModelParams,
                flight: &flight_pd::Config,
            ) -> Result<Self, InvalidField> {
                let act = Actuator::from_model(model);
                let pd = || flight_pd::FlightPd::new(flight, &act);
                Ok(match strategy {
                    Strategy::Passive => Controller::Passive(passive::Passive),
                    Strategy::Thesis(law) => match law {
                        StanceLaw::StepOpen(c) => {
                            Controller::StepOpen(step_open::StepOpen::new(c, &act, pd()?)?)
                        }
                        StanceLaw::StepClosed(c) => {
                            Controller::StepClosed(step_closed::StepClosed::new(c, &act, pd()?)?)
                        }
                        StanceLaw::OpenTorque(c) => {
                            Controller::OpenTorque(open_torque::OpenTorque::new(c, &act, pd()?)?)
                        }
                        StanceLaw::Energy(c) => {
                            Controller::Energy(energy::Energy::new(c, &act, pd()?)?)
                        }
                        StanceLaw::Velocity(c) => {
                            Controller::Velocity(velocity::Velocity::new(c, &act, pd()?)?)
                        }
                        StanceLaw::ModifiedTorque(c) => Controller::ModifiedTorque(
                            modified_torque::ModifiedTorque::new(c, &act, pd()?)?,
                        ),
                    },
                    Strategy::EnergyApex(a) => Controller::EnergyApex(
                        energy_apex::EnergyApex::new(a, &act, model, pd()?)?,
                    ),
                    Strategy::Shaped(c) => {
                        Controller::Shaped(shaped::Shaped::new(c, &act, model)?)
                    }
                    $(
                        Strategy::$variant(c) => {
                            Controller::$variant($module::Law::new(c, &act, model, pd()?)?)
                        }
                    )*
                })
            }
        }

        impl ControlLaw for Controller {
            #[inline]
            fn on_event(&mut self, event: &EventInput) {
                match self {
                    Controller::Passive(c) => c.on_event(event),
                    Controller::StepOpen(c) => c.on_event(event),
                    Controller::StepClosed(c) => c.on_event(event),
                    Controller::OpenTorque(c) => c.on_event(event),
                    Controller::Energy(c) => c.on_event(event),
                    Controller::Velocity(c) => c.on_event(event),
                    Controller::ModifiedTorque(c) => c.on_event(event),
                    Controller::EnergyApex(c) => c.on_event(event),
                    Controller::Shaped(c) => c.on_event(event),
                    $( Controller::$variant(c) => c.on_event(event), )*
                }
            }

            #[inline]
            fn current_a(&mut self, x: &ControlInput) -> f32 {
                match self {
                    Controller::Passive(c) => c.current_a(x),
                    Controller::StepOpen(c) => c.current_a(x),
                    Controller::StepClosed(c) => c.current_a(x),
                    Controller::OpenTorque(c) => c.current_a(x),
                    Controller::Energy(c) => c.current_a(x),
                    Controller::Velocity(c) => c.current_a(x),
                    Controller::ModifiedTorque(c) => c.current_a(x),
                    Controller::EnergyApex(c) => c.current_a(x),
                    Controller::Shaped(c) => c.current_a(x),
                    $( Controller::$variant(c) => c.current_a(x), )*
                }
            }
        }

        /// The added laws' parameter entries, which the table gathers
        /// ([`crate::params::TABLE`]) with everyone else's, in the
        /// registry's order.
        pub(crate) const ADDED_PARAMS: &[&[&crate::param::Param]] = &[$( $module::PARAMS, )*];

        /// Each added law's entries' slots in a strategy: there while that
        /// law is the selected one (in the registry's order).
        const ADDED_SLOTS: &[for<'a> fn(&'a mut Strategy, usize) -> Option<crate::param::Slot<'a>>] = &[$(
            |s, i| match s {
                Strategy::$variant(c) => $module::FIELDS.get(i).and_then(|f| (f.slot)(c)),
                _ => None,
            },
        )*];

        /// Entry `index` of added law `law` in `strategy`, while that law is
        /// selected.
        pub(crate) fn added_slot(
            strategy: &mut Strategy,
            law: usize,
            index: usize,
        ) -> Option<crate::param::Slot<'_>> {
            ADDED_SLOTS.get(law).and_then(|f| f(strategy, index))
        }
    };
}

// The registry of laws added after the thesis's and this project's own:
// one line each, `Variant => module,`, the law in `laws/module.rs` (its
// `Config`, declared with `param::config!`, and its `Law`, a `ControlLaw`
// built by `Law::new(&Config, &Actuator, &ModelParams, FlightPd)`).
// `cargo xtask new-law NAME` writes a law from the template and adds its
// line here (docs/laws.md).
laws! {
    // new laws: above this line
}

impl ControllerKind {
    /// Whether this is one of the stance laws of section 2.1.3 that the
    /// thesis simulated on its design machine with Table 2.1's flight law
    /// (position steps, constant torque, energy feedback, velocity). The
    /// modified torque law (section 4.4.3) ran on the Chapter 4 machine
    /// with eq 4.13's flight PD, and this project's energy-apex law was
    /// tuned with it; shaped has a back-drive of its own.
    pub const fn is_chapter_2_law(self) -> bool {
        matches!(
            self,
            ControllerKind::StepOpen
                | ControllerKind::StepClosed
                | ControllerKind::OpenTorque
                | ControllerKind::Energy
                | ControllerKind::Velocity
        )
    }

    /// Every controller, in the parameter table's order.
    pub const ALL: &'static [Self] = <Self as strum::VariantArray>::VARIANTS;

    /// Every controller's name, by index (the `controller` parameter's
    /// choices).
    pub const NAMES: &'static [&'static str] = <Self as strum::VariantNames>::VARIANTS;

    /// The `controller` parameter's largest value: the last registered
    /// law's index (a law added to the registry widens it).
    pub const MAX_INDEX: f32 = (Self::NAMES.len() - 1) as f32;

    /// The default controller: the apex-regulating energy law.
    pub const DEFAULT: Self = ControllerKind::EnergyApex;

    /// [`Self::DEFAULT`]'s index, the `controller` parameter's default.
    pub const DEFAULT_INDEX: f32 = Self::DEFAULT as usize as f32;

    /// The name the host tools and the link use (`energy-apex`).
    pub fn name(self) -> &'static str {
        self.into()
    }

    /// The controller called `name`, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.iter().copied().find(|k| k.name() == name)
    }
}

impl core::fmt::Display for ControllerKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

impl Default for Strategy {
    /// The default controller's ([`ControllerKind::DEFAULT`]).
    fn default() -> Self {
        ControllerKind::DEFAULT.default_strategy()
    }
}

/// What a controller sees every period: the estimator's phase and filtered
/// rates, the converted sample and the energy estimate, all SI.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControlInput {
    /// Phase estimate after this sample.
    pub phase: Phase,
    /// Body height `z`, m.
    pub body_height_m: f32,
    /// Toe height `z - l0`, m (the model's leg length).
    pub toe_height_m: f32,
    /// Filtered body velocity `zd`, m/s (eq 4.1).
    pub body_velocity_mps: f32,
    /// Motor angle `theta = p / r`, rad.
    pub motor_angle_rad: f32,
    /// Filtered motor rate, rad/s (eq 4.1).
    pub motor_rate_rad_s: f32,
    /// Nut position `p`, m (down positive).
    pub nut_position_m: f32,
    /// Nut velocity `r theta dot`, m/s.
    pub nut_velocity_mps: f32,
    /// Load-cell spring force, N.
    pub spring_force_n: f32,
    /// Leg compression from the potentiometer, m.
    pub leg_compression_m: f32,
    /// Total energy estimate, J (eq 2.44 with eq 2.45; NaN if it overflowed).
    pub energy_j: f32,
    /// `E_D` of the target apex, J (eq 2.43).
    pub desired_energy_j: f32,
    /// The target apex toe height `H_D`, m.
    pub target_apex_m: f32,
    /// The flight's highest toe height so far, m (None before any flight
    /// sample; the same as the apex once descending).
    pub flight_peak_toe_m: Option<f32>,
    /// The last apex toe height, m.
    pub last_apex_m: Option<f32>,
    /// The control period, s.
    pub dt_s: f32,
}

impl ControlInput {
    /// The stance laws' view of this period.
    #[inline]
    pub fn stance(&self, after_bottom: bool) -> StanceInput {
        StanceInput {
            energy_j: self.energy_j,
            desired_energy_j: self.desired_energy_j,
            nut_position_m: self.nut_position_m,
            nut_velocity_mps: self.nut_velocity_mps,
            leg_compression_m: self.leg_compression_m,
            spring_force_n: self.spring_force_n,
            after_bottom,
        }
    }
}

/// An estimator event as a controller sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EventInput {
    /// The event.
    pub event: PhaseEvent,
    /// At an apex that completes a hop (a stance came before it): `E_D` of
    /// the measured apex height, J (eq 2.43), for per-hop loops. `None` at
    /// every other event.
    pub hop_apex_energy_j: Option<f32>,
    /// `E_D` of the target apex, J.
    pub desired_energy_j: f32,
    /// Whether a fault is latched (the motor is off whatever is commanded).
    pub faulted: bool,
}

/// The one interface of every controller: events in, current out.
pub trait ControlLaw {
    /// An estimator event (touchdown, liftoff, bottom, apex), before this
    /// period's [`current_a`](Self::current_a).
    fn on_event(&mut self, event: &EventInput);

    /// This period's current request, A (positive compresses the spring),
    /// before the supervisor. Finite for every input.
    fn current_a(&mut self, x: &ControlInput) -> f32;
}

impl Controller {
    /// The energy-apex loop's current correction of `E_D`, J (0 for other controllers).
    pub fn apex_offset_j(&self) -> f32 {
        match self {
            Controller::EnergyApex(c) => c.offset_j(),
            _ => 0.0,
        }
    }

    /// The shaped law's torque level, fraction of the current limit (0 for
    /// other controllers).
    pub fn shaped_level(&self) -> f32 {
        match self {
            Controller::Shaped(c) => c.level(),
            _ => 0.0,
        }
    }
}

/// After-bottom tracking shared by the position-step laws: set at the
/// bottom of stance (`t1`), cleared at touchdown.
#[inline]
pub(crate) fn track_bottom(after_bottom: &mut bool, event: &EventInput) {
    match event.event {
        PhaseEvent::Touchdown => *after_bottom = false,
        PhaseEvent::Bottom => *after_bottom = true,
        _ => {}
    }
}

#[cfg(test)]
pub(crate) mod test_util {
    use super::*;

    /// A neutral stance input: at the target energy, nut at rest at 0.
    pub fn input() -> StanceInput {
        StanceInput {
            energy_j: 70.0,
            desired_energy_j: 70.0,
            nut_position_m: 0.0,
            nut_velocity_mps: 0.0,
            leg_compression_m: 0.03,
            spring_force_n: 385.0,
            after_bottom: false,
        }
    }

    pub fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_and_clamp() -> Result<(), LawError> {
        let act = Actuator::default();
        assert!(test_util::close(
            act.torque_to_current(0.5)?,
            0.5 / 0.0297,
            1e-3
        ));
        assert_eq!(act.torque_to_current(5.0)?, act.current_limit_a);
        assert_eq!(act.torque_to_current(-5.0)?, -act.current_limit_a);
        assert_eq!(act.clamp_current(f32::INFINITY)?, act.current_limit_a);
        assert_eq!(act.clamp_current(f32::NAN), Err(LawError::NonFiniteInput));
        // 100 N on the nut: tau = 100 * 7.9577e-4 / 0.9 = 0.08842 N m -> 2.977 A.
        assert!(test_util::close(
            act.nut_force_to_current(100.0)?,
            2.977,
            2e-3
        ));
        assert_eq!(or_zero(Err(LawError::NonFiniteInput)), 0.0);
        Ok(())
    }

    /// The derived names are the host tools' and the link's, in the
    /// `controller` parameter's order.
    #[test]
    fn controller_names_and_order() {
        let names = [
            "passive",
            "step-open",
            "step-closed",
            "open-torque",
            "energy",
            "energy-apex",
            "velocity",
            "modified-torque",
            "shaped",
        ];
        // The thesis's and this project's own first; laws added to the
        // registry after them.
        let variants = <ControllerKind as strum::VariantNames>::VARIANTS;
        assert_eq!(variants.get(..names.len()), Some(&names[..]));
        assert_eq!(ControllerKind::ALL.len(), variants.len());
        for (i, k) in ControllerKind::ALL.iter().enumerate() {
            assert_eq!(k.is_builtin(), i < names.len(), "{k}");
            assert_eq!(ControllerKind::from_name(k.name()), Some(*k));
            assert_eq!(k.default_strategy().kind(), *k);
        }
        assert_eq!(ControllerKind::from_name("constant-torque"), None);
    }
}
