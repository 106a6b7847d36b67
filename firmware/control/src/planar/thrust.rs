//! The planar machine's hop by the vertical hopper's laws: the leg's
//! motor drives its ball screw as on the vertical machine, and any of the
//! vertical controllers ([`crate::laws::Controller`], the apex-regulating
//! energy law by default) runs it from the planar estimate.
//!
//! The vertical laws read the hop along the vertical (eqs 2.43-2.45): the
//! body's height and speed, the nut, the spring's force, the phase and its
//! events. On the planar machine those are:
//!
//! - the body's height `z`: the hip's height above the ground (the boom's
//!   height encoder), so that an apex `H` of the toe is `E_D`'s `l_0 + H`
//!   (the leg near the vertical at the apex);
//! - the spring's force: `k (l_0 - l + p)` from the leg's potentiometer
//!   and the nut (the leg has no load cell; eq 2.45 then takes `0.5 F^2 /
//!   k`);
//! - the phase from the planar estimator, the bottom where the leg starts
//!   lengthening, the apex where the hip's vertical speed turns, its toe
//!   height `z - l_0` (the apex as the controller and the runs measure
//!   it);
//! - the motor's rate by eq 4.1, as the vertical estimator's.
//!
//! The forward motion's kinetic energy is left out: the law regulates the
//! hop, the foot's placement the speed. What the two share (the stance
//! turns forward speed into height and back) shows as a bias on the
//! apex, which the energy-apex law's per-hop loop takes out.

use super::PlanarEstimate;
use crate::energy::{EnergyInput, EnergyModel};
use crate::estimator::{Phase, PhaseEvent};
use crate::filter::FilteredDerivative;
use crate::laws::{
    flight_pd, ControlInput, ControlLaw, Controller, ControllerKind, EventInput, Strategy,
};
use crate::model::ModelParams;
use crate::param::InvalidField;

/// The flight PD's 5% settling time on the planar machine, s
/// ([`ScrewThrust::planar_flight`]).
///
/// With eq 4.13's 0.1 s the PD returns the nut bang-bang: at the liftoff
/// the nut (426 kg seen at it) is still running down, and stopping and
/// returning it within 0.1 s took 40 ms at the full 33.7 A and 40 ms at
/// about 22 A every stride, over half the winding's heat. The planar
/// machine's flight is about 0.33 s: settling in 0.5 s (a fifth of eq
/// 4.13's natural frequency) brings the nut most of the way home with a few
/// amperes, and the next descent's spin-up drives it from there. Measured
/// on the speed profile with a 20 N s push over 60 s: the winding at most
/// 97 C, where 0.1 s tripped it (150 C) at 47.4 s; the apex within 8.5%
/// of its target.
pub const PLANAR_FLIGHT_SETTLING_S: f32 = 0.5;

/// The leg's thrust by a vertical law (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct ScrewThrust {
    controller: Controller,
    energy: EnergyModel,
    model: ModelParams,
    motor_rate: FilteredDerivative,
    /// `E_D` of the target apex, J.
    desired_energy_j: f32,
    target_apex_m: f32,
    was_stance: bool,
    /// This phase's bottom (in stance) or apex (in flight) came.
    phase_event_done: bool,
    /// A stance came since the last apex (the next completes a hop).
    hop_open: bool,
    /// The highest toe height of this flight, m.
    flight_peak_toe_m: Option<f32>,
    /// The last apex's toe height, m.
    last_apex_m: Option<f32>,
    /// Half the machine's mass times the forward speed squared at the
    /// touchdown, J.
    forward_at_touchdown_j: f32,
    /// Half the machine's mass, kg.
    half_mass_kg: f32,
    /// The screw's `r`, m/rad.
    screw_m_per_rad: f32,
}

impl ScrewThrust {
    /// The law `strategy` for the leg `model` describes (its masses, spring
    /// and drive), holding the toe's apex at `target_apex_m`; the motor's
    /// rate filtered with eq 4.1's `rate_filter_gain`. A field out of range
    /// is refused by name.
    pub fn new(
        strategy: &Strategy,
        model: &ModelParams,
        target_apex_m: f32,
        rate_filter_gain: f32,
    ) -> Result<Self, InvalidField> {
        crate::param::validate_fields(&mut { *model }, crate::model::FIELDS)?;
        let controller = Controller::new(strategy, model, &Self::flight_of(model)?)?;
        let energy =
            EnergyModel::new(model).map_err(|_| InvalidField("model.spring_stiffness_n_per_m"))?;
        let desired_energy_j = model
            .desired_energy_j(target_apex_m)
            .map_err(|_| InvalidField("target_apex_m"))?;
        let motor_rate = FilteredDerivative::new(rate_filter_gain)
            .map_err(|_| InvalidField("rate_filter_gain"))?;
        Ok(ScrewThrust {
            controller,
            energy,
            model: *model,
            motor_rate,
            desired_energy_j,
            target_apex_m,
            was_stance: false,
            // The loop starts in flight at an apex: the first comes after
            // a stance.
            phase_event_done: true,
            hop_open: false,
            flight_peak_toe_m: None,
            last_apex_m: None,
            forward_at_touchdown_j: 0.0,
            half_mass_kg: 0.5 * (model.body_mass_kg + model.nut_mass_kg + model.unsprung_mass_kg),
            screw_m_per_rad: model.screw_m_per_rad(),
        })
    }

    /// The vertical law `kind` as the planar machine runs it: its
    /// defaults, but for the energy-apex law's, tuned on the actuated
    /// Table 2.2 machine (the speed profile 0, 0.5, 1, 0 m/s: the apex
    /// within 8.5% of its target from the sixth stride, where the
    /// vertical hopper's settings left it 35% low at 1 m/s, with eq
    /// 4.13's flight PD):
    ///
    /// - the stance law from 20% of the target apex on the way down
    ///   (section 4.4.3's spin-up: the rotor moving at the touchdown; the
    ///   stance is 70 ms, against the vertical hopper's 100);
    /// - the outer loop's integral gain 1.0 and proportional gain 0.5 (J
    ///   per J): each speed step moves the energy the hop needs, and the
    ///   loop follows within a few strides.
    pub fn planar_strategy(kind: ControllerKind) -> Strategy {
        let mut s = kind.default_strategy();
        if let Strategy::EnergyApex(a) = &mut s {
            a.spin_up_fraction = 0.2;
            a.gain = 1.0;
            a.proportional = 0.5;
        }
        s
    }

    /// The flight PD (section 4.3) as the planar machine runs it: eq
    /// 4.12's gains for the leg drive's `A = k_m / J` (eq 4.3) at eq
    /// 4.13's damping 0.707, settling in [`PLANAR_FLIGHT_SETTLING_S`]
    /// rather than eq 4.13's 0.1 s.
    pub fn planar_flight(model: &ModelParams) -> Result<flight_pd::Config, InvalidField> {
        crate::param::validate_fields(&mut { *model }, crate::model::FIELDS)?;
        Self::flight_of(model)
    }

    /// [`Self::planar_flight`] for a model already validated.
    fn flight_of(model: &ModelParams) -> Result<flight_pd::Config, InvalidField> {
        let plant_gain_rad_per_s2_a = model.torque_constant_nm_per_a / model.rotor_inertia_kg_m2;
        // Eq 4.13's damping.
        let gains =
            crate::pd_design::pd_gains(plant_gain_rad_per_s2_a, 0.707, PLANAR_FLIGHT_SETTLING_S)
                .map_err(|_| InvalidField("model.torque_constant_nm_per_a"))?;
        Ok(flight_pd::Config {
            gains,
            ..flight_pd::Config::default()
        })
    }

    /// The vertical law.
    pub fn controller(&self) -> &Controller {
        &self.controller
    }

    /// Where the nut stands with the motor at `motor_angle_rad`, m below
    /// its upper stop.
    pub fn nut_position_m(&self, motor_angle_rad: f32) -> f32 {
        self.screw_m_per_rad * motor_angle_rad
    }

    /// The nut's speed by the motor's filtered rate (eq 4.1), m/s.
    pub fn nut_velocity_mps(&self) -> f32 {
        self.screw_m_per_rad * self.motor_rate.value()
    }

    /// The last apex's toe height the law saw, m.
    pub fn last_apex_m(&self) -> Option<f32> {
        self.last_apex_m
    }

    /// This period's event, if any, from the estimate: the touchdown and
    /// the liftoff where the estimator's phase changes, the bottom the
    /// first stance period the leg lengthens, the apex the first flight
    /// period the hip no longer rises. Each once a phase, so that a rate's
    /// noise about zero reports nothing twice; a rate that is not a number
    /// reports nothing.
    fn event(&mut self, est: &PlanarEstimate, toe_m: f32) -> Option<PhaseEvent> {
        let event = if est.stance != self.was_stance {
            self.phase_event_done = false;
            if est.stance {
                self.hop_open = true;
                self.forward_at_touchdown_j = self.half_mass_kg * est.x_dot_mps * est.x_dot_mps;
                Some(PhaseEvent::Touchdown)
            } else {
                self.flight_peak_toe_m = None;
                Some(PhaseEvent::Liftoff)
            }
        } else if est.stance {
            let bottom = !self.phase_event_done && est.leg_rate_mps > 0.0;
            self.phase_event_done |= bottom;
            bottom.then_some(PhaseEvent::Bottom)
        } else {
            if toe_m.is_finite() {
                self.flight_peak_toe_m = Some(match self.flight_peak_toe_m {
                    Some(p) => crate::num::max(p, toe_m),
                    None => toe_m,
                });
            }
            let apex = !self.phase_event_done && est.z_dot_mps <= 0.0;
            self.phase_event_done |= apex;
            apex.then(|| PhaseEvent::Apex {
                toe_height_m: crate::num::max(self.flight_peak_toe_m.unwrap_or(0.0), 0.0),
            })
        };
        self.was_stance = est.stance;
        event
    }

    /// An event to the law (a few times a hop: out of line).
    #[inline(never)]
    fn on_event(&mut self, event: PhaseEvent, faulted: bool) {
        let hop_apex_energy_j = match event {
            PhaseEvent::Apex { toe_height_m } if self.hop_open => {
                self.hop_open = false;
                self.last_apex_m = Some(toe_height_m);
                self.model.desired_energy_j(toe_height_m).ok()
            }
            _ => None,
        };
        self.controller.on_event(&EventInput {
            event,
            hop_apex_energy_j,
            desired_energy_j: self.desired_energy_j,
            faulted,
        });
    }

    /// This period's current for the leg's motor, A (positive compresses
    /// the spring), before the amplifier's limit: from the estimate, the
    /// leg's length `leg_length_m` and the motor's angle `motor_angle_rad`
    /// (0 with the nut on its upper stop); `faulted` when the machine's
    /// guard has latched (the motor is off whatever this asks, and the
    /// laws learn nothing from the hops). Finite for every input.
    pub fn current_a(
        &mut self,
        est: &PlanarEstimate,
        leg_length_m: f32,
        motor_angle_rad: f32,
        faulted: bool,
        dt_s: f32,
    ) -> f32 {
        let r = self.screw_m_per_rad;
        let motor_rate_rad_s = self
            .motor_rate
            .update(motor_angle_rad, dt_s)
            .unwrap_or(f32::NAN);
        let nut_position_m = self.nut_position_m(motor_angle_rad);
        let compression_m = if est.stance {
            crate::num::max(self.model.leg_length_m - leg_length_m, 0.0)
        } else {
            0.0
        };
        let spring_force_n = self.model.spring_stiffness_n_per_m * (compression_m + nut_position_m);
        // The apex as the controller and the runs measure it: the hip's
        // height less the leg's length.
        let toe_height_m = est.z_m - self.model.leg_length_m;
        let phase = if est.stance {
            Phase::Stance
        } else {
            Phase::Flight
        };
        if let Some(event) = self.event(est, toe_height_m) {
            self.on_event(event, faulted);
        }
        // In stance the leg trades the forward motion's energy with the
        // hop's: what the forward motion lent the hop since the touchdown
        // is not the hop's (it is paid back as the stance ends as it
        // began), so it is left out.
        let traded_j = if est.stance {
            self.half_mass_kg * est.x_dot_mps * est.x_dot_mps - self.forward_at_touchdown_j
        } else {
            0.0
        };
        let energy_j = self
            .energy
            .total_j(&EnergyInput {
                body_height_m: est.z_m,
                body_velocity_mps: est.z_dot_mps,
                motor_rate_rad_s,
                nut_position_m,
                spring_force_n,
                phase,
            })
            .map_or(f32::NAN, |e| e + traded_j);
        let i = self.controller.current_a(&ControlInput {
            phase,
            body_height_m: est.z_m,
            toe_height_m,
            body_velocity_mps: est.z_dot_mps,
            motor_angle_rad,
            motor_rate_rad_s,
            nut_position_m,
            nut_velocity_mps: r * motor_rate_rad_s,
            spring_force_n,
            leg_compression_m: compression_m,
            energy_j,
            desired_energy_j: self.desired_energy_j,
            target_apex_m: self.target_apex_m,
            flight_peak_toe_m: self.flight_peak_toe_m,
            last_apex_m: self.last_apex_m,
            dt_s,
        });
        if i.is_finite() {
            i
        } else {
            0.0
        }
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Table 2.2's leg (16.3 kg, 0.3 of it at the toe, on 40,425 N/m)
    /// and the design's planar leg drive.
    pub(crate) fn model() -> ModelParams {
        use crate::model::design as d;
        let scale = d::PLANAR_LEG_MOTOR_SCALE as f32;
        let m = ModelParams::default();
        ModelParams {
            body_mass_kg: 16.0 - m.nut_mass_kg,
            unsprung_mass_kg: 0.3,
            spring_stiffness_n_per_m: 40_425.0,
            leg_length_m: super::super::TABLE_2_2_LEG_LENGTH_M,
            rotor_inertia_kg_m2: scale * m.rotor_inertia_kg_m2,
            screw_lead_m: d::PLANAR_SCREW_LEAD_M as f32,
            torque_constant_nm_per_a: scale * m.torque_constant_nm_per_a,
            torque_limit_nm: scale * m.torque_limit_nm,
            ..m
        }
    }

    fn thrust() -> ScrewThrust {
        ScrewThrust::new(
            &ControllerKind::EnergyApex.default_strategy(),
            &model(),
            0.15,
            0.95,
        )
        .unwrap_or_else(|e| panic!("{e:?}"))
    }

    fn at(stance: bool, z_m: f32, z_dot_mps: f32, leg_rate_mps: f32) -> PlanarEstimate {
        PlanarEstimate {
            stance,
            z_m,
            z_dot_mps,
            leg_rate_mps,
            ..PlanarEstimate::default()
        }
    }

    #[test]
    fn a_low_hop_pushes_in_stance_and_the_flight_returns_the_nut() {
        let limit = crate::laws::Actuator::from_model(&model()).usable_limit_a();
        // 4 N m at 4 x 29.7 mN m/A: the amplifier's 33.67 A.
        assert!((limit - 33.67).abs() < 0.01, "{limit}");
        let mut t = thrust();
        // In stance 3 cm down, nearly still, the nut home: 116 J (18 J of
        // it in the spring) against the 0.15 m hop's 126 J: the law (3 N
        // m/J) asks for its full torque.
        let i = t.current_a(&at(true, 0.62, -0.1, -0.1), 0.62, 0.0, false, 1e-4);
        assert_eq!(i, limit);
        // In flight with the nut 10 rad down: the planar flight PD (eq
        // 4.12 at A = 110, damping 0.707, settling in 0.5 s: 0.8126
        // A/rad, a 25th of eq 4.13's 20.3) drives it home with 8.13 A.
        let mut t = thrust();
        let i = t.current_a(&at(false, 0.7, 1.0, 0.0), 0.65, 10.0, false, 1e-4);
        assert!((i + 8.126).abs() < 0.01, "{i}");
    }

    #[test]
    fn the_events_come_in_the_hops_order_and_the_apex_closes_a_hop() {
        let mut t = thrust();
        let mut seen = [0usize; 4];
        let mut apexes = 0;
        // Two hops: down in flight, a stance that compresses then
        // lengthens, up in flight to the top and down again.
        for _ in 0..2 {
            for (stance, z_dot, leg_rate) in [
                (false, -1.0, 0.0),
                (true, -1.0, -1.0),
                (true, 1.0, 1.0),
                (false, 1.0, 0.0),
                (false, -0.1, 0.0),
            ] {
                let est = at(stance, 0.75, z_dot, leg_rate);
                if let Some(e) = t.event(&est, 0.1) {
                    seen[match e {
                        PhaseEvent::Touchdown => 0,
                        PhaseEvent::Bottom => 1,
                        PhaseEvent::Liftoff => 2,
                        PhaseEvent::Apex { .. } => {
                            apexes += 1;
                            3
                        }
                    }] += 1;
                }
            }
        }
        assert_eq!(seen, [2, 2, 2, 2]);
        assert_eq!(apexes, 2);
    }

    #[test]
    fn a_bad_leg_is_refused_by_name() {
        let bad = ModelParams {
            spring_stiffness_n_per_m: -1.0,
            ..model()
        };
        let e = ScrewThrust::new(
            &ControllerKind::EnergyApex.default_strategy(),
            &bad,
            0.15,
            0.95,
        );
        assert_eq!(e.err().map(|e| e.0), Some("model.spring_stiffness_n_per_m"));
        let e = ScrewThrust::new(
            &ControllerKind::EnergyApex.default_strategy(),
            &model(),
            0.15,
            1.5,
        );
        assert_eq!(e.err().map(|e| e.0), Some("rate_filter_gain"));
    }

    proptest::proptest! {
        /// Any sequence of phases and rates (NaN among them): touchdowns
        /// and liftoffs alternate, a bottom comes at most once a stance
        /// and only in it, an apex at most once a flight and only in it.
        #[test]
        fn each_event_comes_once_a_phase(
            steps in proptest::collection::vec(
                (
                    proptest::bool::weighted(0.3),
                    proptest::prop_oneof![-2.0f32..2.0, proptest::prelude::Just(f32::NAN)],
                    proptest::prop_oneof![-2.0f32..2.0, proptest::prelude::Just(f32::NAN)],
                ),
                1..200,
            ),
        ) {
            let mut t = thrust();
            let mut stance = false;
            let mut this_phase = 0;
            for (s, z_dot, leg_rate) in steps {
                let e = t.event(&at(s, 0.75, z_dot, leg_rate), 0.1);
                if s != stance {
                    let want = if s { PhaseEvent::Touchdown } else { PhaseEvent::Liftoff };
                    proptest::prop_assert_eq!(e, Some(want));
                    stance = s;
                    this_phase = 0;
                    continue;
                }
                match e {
                    None => {}
                    Some(PhaseEvent::Bottom) => proptest::prop_assert!(stance),
                    Some(PhaseEvent::Apex { .. }) => proptest::prop_assert!(!stance),
                    Some(other) => proptest::prop_assert!(false, "{other:?} within a phase"),
                }
                if e.is_some() {
                    this_phase += 1;
                }
                proptest::prop_assert!(this_phase <= 1);
            }
        }

        /// Any estimate and readings: a finite current.
        #[test]
        fn the_current_is_finite_on_any_input(
            stance in proptest::bool::ANY,
            z in proptest::prop_oneof![-10.0f32..10.0, proptest::prelude::Just(f32::NAN)],
            zd in proptest::prop_oneof![-100.0f32..100.0, proptest::prelude::Just(f32::INFINITY)],
            theta in proptest::prop_oneof![-4.0f32..4.0, proptest::prelude::Just(f32::NAN)],
            leg in proptest::prop_oneof![-1.0f32..2.0, proptest::prelude::Just(f32::NAN)],
            angle in proptest::prop_oneof![-1e4f32..1e4, proptest::prelude::Just(f32::NAN)],
        ) {
            let mut t = thrust();
            let est = PlanarEstimate { stance, z_m: z, z_dot_mps: zd, theta_rad: theta, ..PlanarEstimate::default() };
            for _ in 0..3 {
                proptest::prop_assert!(t.current_a(&est, leg, angle, false, 1e-4).is_finite());
            }
        }
    }
}
