//! Everything the control period needs, in one configuration: the model
//! the controller believes, the calibration, the estimator, the supervisor,
//! the flight back-drive, the selected law, arming, the e-stop's debounce
//! and the bring-up routines; its own two parameters (the controller and
//! the target apex), and what follows from the model ([`HopperConfig::for_model`],
//! [`HopperConfig::follow_model`]).

use crate::arming::ArmingConfig;
use crate::calibration::Calibration;
use crate::estimator::EstimatorConfig;
use crate::laws::{flight_pd, ControllerKind, Strategy};
use crate::model::ModelParams;
use crate::supervisor::SupervisorConfig;

/// Largest nut speed at a mechanical stop the default supervisor limits
/// tolerate, m/s. The thesis's laws hit the stops at up to about 0.3 m/s
/// (flight PD return, full-torque stance; measured in simulation); a nut
/// faster than 0.4 m/s means a runaway (the motor's no-load speed gives
/// 0.64 m/s) or a bad velocity estimate. With the 3 m/s^2 braking assumed,
/// the soft limits sit 26.7 mm outside the stops.
pub const STOP_IMPACT_SPEED_MPS: f32 = 0.4;

crate::param::config! {
    /// Everything the control period needs. Each part documents its units.
    /// Its default is [`HopperConfig::for_model`] of the default model.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct HopperConfig;
    params {
        1 TARGET_APEX_M target_apex_m: f32 {
            "target_apex_m", "m", Real, [0.0, 1.0], 0.05, LIVE,
            "Desired apex toe height H_D (E_D of eq 2.43)."
        }
    }
    custom {
        // The selected controller is the strategy's variant.
        0 CONTROLLER |_s| Some(Slot::Controller), {
            "controller", "-", Kind::Choice(ControllerKind::NAMES),
            [0.0, ControllerKind::MAX_INDEX], ControllerKind::DEFAULT_INDEX,
            DISARMED,
            "The controller that runs in stance and flight (selecting one starts it from its defaults)."
        }
    }
    plain {
        /// The model the controller believes (energy, `E_D`, actuator constants).
        pub model: ModelParams = ModelParams::default(),
        /// Raw-to-SI conversion.
        pub calibration: Calibration = Self::calibration_for(&ModelParams::default()),
        /// Phase estimator and velocity filters.
        pub estimator: EstimatorConfig = EstimatorConfig::default(),
        /// Safety limits.
        pub supervisor: SupervisorConfig = Self::supervisor_for(&ModelParams::default()),
        /// Flight back-drive (eq 4.4 with the eq 4.13 gains by default).
        pub flight: flight_pd::Config = flight_pd::Config::default(),
        /// Stance and flight laws (the default is [`ControllerKind::DEFAULT`]'s).
        pub strategy: Strategy = Strategy::default(),
        /// Arming: the period runner's gate on the output.
        pub arming: ArmingConfig = ArmingConfig::default(),
        /// The e-stop input's debouncing.
        pub estop: crate::debounce::DebounceConfig = crate::debounce::DebounceConfig::default(),
        /// The motor-driving bring-up routines.
        pub bringup: crate::bringup::BringupConfig = crate::bringup::BringupConfig::default(),
    }
}

impl HopperConfig {
    /// Defaults for `model`: the supervisor's current limit, spring and
    /// stroke limits follow the model; everything else is the default.
    pub fn for_model(model: ModelParams) -> Self {
        Self {
            model,
            calibration: Self::calibration_for(&model),
            supervisor: Self::supervisor_for(&model),
            ..Self::default()
        }
    }

    /// After the model changed from `old` to `self.model` (a `model.*`
    /// set, a robot file, a saved record): every value derived from the
    /// model ([`Self::for_model`]: the calibration's lead and torque
    /// constant and start height, the supervisor's overcurrent trip, spring
    /// rate and preload, stops and soft limits) that still holds what `old`
    /// derived takes what the new model derives; one set apart (the spring
    /// rate the bench sweep measured, say) stays.
    pub fn follow_model(&mut self, old: &ModelParams) {
        let (was, now) = (Self::for_model(*old), Self::for_model(self.model));
        macro_rules! follow {
            ($($part:ident . $field:ident),* $(,)?) => {$(
                if self.$part.$field == was.$part.$field {
                    self.$part.$field = now.$part.$field;
                }
            )*};
        }
        follow!(
            calibration.torque_constant_nm_per_a,
            calibration.lead_m_per_rev,
            calibration.height_at_origin_m,
            supervisor.overcurrent_trip_a,
            supervisor.spring_rate_n_per_m,
            supervisor.spring_preload_m,
            supervisor.stroke_min_m,
            supervisor.nut_stops_m,
            supervisor.stroke_max_m,
        );
    }

    /// The supervisor's defaults for `model`: its current limit, spring and
    /// stroke limits follow the model.
    fn supervisor_for(model: &ModelParams) -> SupervisorConfig {
        let mut supervisor = SupervisorConfig {
            // A request ten times the limit is a runaway law or a unit error.
            overcurrent_trip_a: 10.0 * model.usable_current_limit_a(),
            spring_rate_n_per_m: model.spring_stiffness_n_per_m,
            spring_preload_m: model.preload_m,
            ..SupervisorConfig::default()
        };
        // Soft limits outside the mechanical stops by the braking distance
        // from the largest stop-impact speed tolerated (see
        // `STOP_IMPACT_SPEED_MPS`): a nut that cannot be slowed below it
        // before a stop trips the supervisor.
        let a = supervisor.brake_decel_mps2;
        let margin_m = STOP_IMPACT_SPEED_MPS * STOP_IMPACT_SPEED_MPS / (2.0 * a);
        supervisor.stroke_min_m = -margin_m;
        supervisor.nut_stops_m = crate::supervisor::Range {
            min: 0.0,
            max: model.stroke_m,
        };
        supervisor.stroke_max_m = model.stroke_m + margin_m;
        supervisor
    }

    /// The calibration's defaults for `model`: its lead, torque constant and
    /// start height are the model's.
    fn calibration_for(model: &ModelParams) -> Calibration {
        Calibration {
            torque_constant_nm_per_a: model.torque_constant_nm_per_a,
            lead_m_per_rev: model.screw_lead_m,
            height_at_origin_m: model.leg_length_m,
            ..Calibration::default()
        }
    }
}
