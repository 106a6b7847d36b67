//! The planar machine's leg actuator as the vertical hopper's: a DC motor
//! turning a ball screw whose nut compresses the leg spring from above
//! (MODEL.md's `p`, down positive), here on the leg of Appendix A's runner
//! ([`crate::planar_general`]).
//!
//! The spring sits between the nut and the toe, so its compression is
//! `(l_0 - l) + p` in stance and `p` in flight (the lower leg on its stop),
//! and its force on the toe is the runner's `k_l (l_0 - l)` plus `k_l p`:
//! the nut enters the runner as the leg's thrust `k_l p`
//! ([`crate::planar_general::Actuation::leg_thrust_n`]). In flight that
//! force is internal (the stop takes it), and the runner ignores the
//! thrust there.
//!
//! The nut's own dynamics are the vertical model's second equation (eqs
//! 2.13, 2.33) with the nut's sliding mass lumped into the hip: `J / r^2
//! p'' = eta tau / r - k_l c` (`c` the compression; the leg's damper is
//! Appendix A's, on the leg's sliding in the runner, rather than MODEL.md's
//! across the spring: at the design's 20 N s/m against the nut's 426 kg
//! the difference is small). What that
//! drops is `m_s` times the hip's acceleration along the leg, against a
//! reflected inertia of hundreds of kilograms (0.6 kg against 430 kg for
//! the design's drive: a part in 700). The nut is advanced beside the
//! runner by a semi-implicit Euler step with the spring force at the
//! step's start: on the spring, the nut's frequency `sqrt(k_l r^2 / J)`,
//! about 10 rad/s, is a thousand times slower than the 10 kHz step. The
//! mechanical stops bound the stroke `[0, stroke]`; a stop takes the nut's
//! speed (a plastic impact on the rotor, its loss booked).

use crate::amplifier::SupplyWindow;
use crate::planar::PlanarError;

/// The leg's drive: motor, screw and amplifier (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LegScrew {
    /// Rotor and screw inertia `J`, kg m^2.
    pub rotor_inertia_kg_m2: f64,
    /// The screw's lead, nut travel per motor revolution, m.
    pub screw_lead_m: f64,
    /// Motor and screw efficiency `eta`: the nut sees `eta tau / r`.
    pub efficiency: f64,
    /// Motor torque constant, N m/A.
    pub torque_constant_nm_per_a: f64,
    /// The amplifier's current limit, A.
    pub current_limit_a: f64,
    /// The nut's stroke between its stops, m.
    pub stroke_m: f64,
    /// The motor's winding resistance, ohm.
    pub winding_ohm: f64,
    /// The amplifier's supply, V: it drives at most `(V - k_e w) / R`
    /// into the turning motor (`k_e` the torque constant in V s/rad).
    pub supply_voltage_v: f64,
}

impl LegScrew {
    /// The planar machine's design drive
    /// ([`hopper_model::design::PLANAR_LEG_MOTOR_SCALE`]): the vertical
    /// hopper's motor family, that many times its torque constant and
    /// rotor, at the same amplifier's limit, on a screw of
    /// [`hopper_model::design::PLANAR_SCREW_LEAD_M`].
    pub fn design() -> Self {
        use hopper_model::design as d;
        let s = d::PLANAR_LEG_MOTOR_SCALE;
        LegScrew {
            rotor_inertia_kg_m2: s * d::ROTOR_INERTIA_KG_M2,
            screw_lead_m: d::PLANAR_SCREW_LEAD_M,
            efficiency: d::EFFICIENCY,
            torque_constant_nm_per_a: s * d::TORQUE_CONSTANT_NM_PER_A,
            current_limit_a: d::CURRENT_LIMIT_A,
            stroke_m: d::STROKE_M,
            // A motor of the family with `s` times the torque at the same
            // current: the design winding (the thermal model is the leg
            // motor's).
            winding_ohm: crate::params::Params::design().winding_resistance_ohm,
            supply_voltage_v: crate::params::Params::design().supply_voltage_v,
        }
    }

    /// `r = lead / 2 pi`, m/rad.
    pub fn screw_m_per_rad(&self) -> f64 {
        self.screw_lead_m / (2.0 * core::f64::consts::PI)
    }

    /// The rotor's inertia seen at the nut `J / r^2`, kg.
    pub fn reflected_inertia_kg(&self) -> f64 {
        let r = self.screw_m_per_rad();
        self.rotor_inertia_kg_m2 / (r * r)
    }

    /// The motor's torque at the current limit, N m.
    pub fn torque_limit_nm(&self) -> f64 {
        self.torque_constant_nm_per_a * self.current_limit_a
    }

    /// Every field finite and positive (the efficiency at most 1); else
    /// the first that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        for (name, v) in [
            ("leg_rotor_inertia_kg_m2", self.rotor_inertia_kg_m2),
            ("leg_screw_lead_m", self.screw_lead_m),
            (
                "leg_torque_constant_nm_per_a",
                self.torque_constant_nm_per_a,
            ),
            ("leg_current_limit_a", self.current_limit_a),
            ("leg_stroke_m", self.stroke_m),
            ("leg_winding_ohm", self.winding_ohm),
            ("leg_supply_voltage_v", self.supply_voltage_v),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlanarError::NotPositive(name));
            }
        }
        if !(self.efficiency > 0.0 && self.efficiency <= 1.0) {
            return Err(PlanarError::OutOfRange("leg_efficiency"));
        }
        Ok(())
    }
}

/// The nut, driven by the motor against the leg spring.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nut {
    drive: LegScrew,
    /// The amplifier's supply window on the drive.
    window: SupplyWindow,
    /// Position `p`, m (down positive, 0 on the upper stop).
    p_m: f64,
    /// Velocity `p'`, m/s.
    pd_mps: f64,
    /// The motor's work on the screw so far, J.
    motor_work_j: f64,
    /// The rotor's kinetic energy the stops took, J.
    stop_loss_j: f64,
    /// The winding's copper loss so far, J.
    copper_loss_j: f64,
}

impl Nut {
    /// On its upper stop, at rest.
    pub fn new(drive: LegScrew) -> Result<Self, PlanarError> {
        drive.validate()?;
        Ok(Nut {
            drive,
            window: SupplyWindow::new(
                drive.torque_constant_nm_per_a,
                drive.screw_m_per_rad(),
                drive.winding_ohm,
                drive.supply_voltage_v,
            ),
            p_m: 0.0,
            pd_mps: 0.0,
            motor_work_j: 0.0,
            stop_loss_j: 0.0,
            copper_loss_j: 0.0,
        })
    }

    /// The drive.
    pub fn drive(&self) -> &LegScrew {
        &self.drive
    }

    /// Position `p`, m.
    pub fn position_m(&self) -> f64 {
        self.p_m
    }

    /// Velocity `p'`, m/s.
    pub fn velocity_mps(&self) -> f64 {
        self.pd_mps
    }

    /// The motor's angle `p / r`, rad (0 on the upper stop).
    pub fn motor_angle_rad(&self) -> f64 {
        self.p_m / self.drive.screw_m_per_rad()
    }

    /// The thrust the nut adds to the leg spring's own force in stance,
    /// `k_l p`, N.
    pub fn thrust_n(&self, leg_stiffness_n_per_m: f64) -> f64 {
        leg_stiffness_n_per_m * self.p_m
    }

    /// The rotor's kinetic energy `0.5 J (p' / r)^2`, J.
    pub fn rotor_energy_j(&self) -> f64 {
        0.5 * self.drive.reflected_inertia_kg() * self.pd_mps * self.pd_mps
    }

    /// The motor's work on the screw so far (`eta tau` times the rotor's
    /// turn), J.
    pub fn motor_work_j(&self) -> f64 {
        self.motor_work_j
    }

    /// The rotor's kinetic energy the stops took so far, J.
    pub fn stop_loss_j(&self) -> f64 {
        self.stop_loss_j
    }

    /// The winding's copper loss so far, J.
    pub fn copper_loss_j(&self) -> f64 {
        self.copper_loss_j
    }

    /// The current the amplifier drives for `command_a` into the motor
    /// turning at the nut's speed: within its limit and what its supply
    /// can push against the motor's back-EMF (the vertical plant's
    /// amplifier, MODEL.md); 0 for a command that is not a number.
    pub fn amplifier_a(&self, command_a: f64) -> f64 {
        let l = self.drive.current_limit_a;
        if !command_a.is_finite() {
            return 0.0;
        }
        self.window.current_a(command_a.clamp(-l, l), self.pd_mps)
    }

    /// Advances `dt_s` with the motor at `command_a` (through the
    /// amplifier) against the spring's force `spring_n` on the nut and the
    /// a damper's `damping_n` (both up positive, as they act on it).
    pub fn step(&mut self, dt_s: f64, command_a: f64, spring_n: f64, damping_n: f64) {
        let d = &self.drive;
        let i = self.amplifier_a(command_a);
        let r = d.screw_m_per_rad();
        let drive_n = d.efficiency * d.torque_constant_nm_per_a * i / r;
        let a = (drive_n - spring_n - damping_n) / d.reflected_inertia_kg();
        let v0 = self.pd_mps;
        self.pd_mps += a * dt_s;
        self.p_m += self.pd_mps * dt_s;
        // The work over the step at its mean speed: free of the spring it
        // is the rotor's energy gained, exactly.
        self.motor_work_j += drive_n * 0.5 * (v0 + self.pd_mps) * dt_s;
        self.copper_loss_j += i * i * d.winding_ohm * dt_s;
        let stop = if self.p_m < 0.0 {
            Some(0.0)
        } else if self.p_m > d.stroke_m {
            Some(d.stroke_m)
        } else {
            None
        };
        if let Some(at) = stop {
            self.stop_loss_j += self.rotor_energy_j();
            self.p_m = at;
            self.pd_mps = 0.0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_design_drive_is_four_vertical_motors_on_a_10_mm_lead() {
        let d = LegScrew::design();
        assert!(d.validate().is_ok());
        assert!((d.torque_limit_nm() - 4.0).abs() < 1e-9);
        // J / r^2: 4 x 2.7e-4 / (0.01 / 2 pi)^2 = 426 kg.
        assert!(
            (d.reflected_inertia_kg() - 426.4).abs() < 0.1,
            "{}",
            d.reflected_inertia_kg()
        );
    }

    #[test]
    fn held_against_the_spring_the_nut_settles_where_the_forces_balance() {
        let d = LegScrew::design();
        let k = 40_425.0;
        let mut n = Nut::new(d).unwrap_or_else(|e| panic!("{e:?}"));
        let i = 10.0;
        // A damper on the nut so that it settles: 2 sqrt(k m).
        let c = 2.0 * libm::sqrt(k * d.reflected_inertia_kg());
        for _ in 0..100_000 {
            let (p, pd) = (n.position_m(), n.velocity_mps());
            n.step(1e-4, i, k * p, c * pd);
        }
        let want = d.efficiency * d.torque_constant_nm_per_a * i / d.screw_m_per_rad() / k;
        assert!(
            (n.position_m() - want).abs() < 1e-6 * want.max(1e-3),
            "{} {want}",
            n.position_m()
        );
        // What the motor did went into the spring and the damper.
        let spring_j = 0.5 * k * want * want;
        assert!(
            n.motor_work_j() > spring_j,
            "{} {spring_j}",
            n.motor_work_j()
        );
        assert!(n.copper_loss_j() > 0.0);
    }

    #[test]
    fn the_stops_bound_the_nut_and_book_what_they_take() {
        let d = LegScrew::design();
        let mut n = Nut::new(d).unwrap_or_else(|e| panic!("{e:?}"));
        // Up to the step that reaches the lower stop.
        for _ in 0..20_000 {
            n.step(1e-4, 1e3, 0.0, 0.0);
            if n.position_m() == d.stroke_m {
                break;
            }
        }
        assert_eq!(n.position_m(), d.stroke_m);
        assert_eq!(n.velocity_mps(), 0.0);
        // Free of the spring, everything the motor did went to the stop.
        assert!((n.stop_loss_j() - n.motor_work_j()).abs() < 1e-6 * n.motor_work_j());
        assert_eq!(n.amplifier_a(f64::NAN), 0.0);
        // At rest the limit; turning, what the supply drives against the
        // back-EMF.
        let at_rest = Nut::new(d).unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(at_rest.amplifier_a(1e3), d.current_limit_a);
        let mut turning = at_rest;
        turning.pd_mps = 0.2;
        let w = 0.2 / d.screw_m_per_rad();
        let hi = (d.supply_voltage_v - d.torque_constant_nm_per_a * w) / d.winding_ohm;
        assert!((turning.amplifier_a(1e3) - hi).abs() < 1e-9, "{hi}");
        // 0.2 m/s is 126 rad/s: 14.9 V of back-EMF, 9.1 V left, 25.4 A.
        assert!((hi - 25.45).abs() < 0.05, "{hi}");
    }

    /// The nut on Appendix A's runner without friction or dampers
    /// (section 2.2's machine, hopping forward): over two seconds of a
    /// stance push and a flight return, the machine's energy (the
    /// runner's, the spring's share the nut holds, the rotor's) gains what
    /// the motor did on the screw less what the stops and the touchdowns'
    /// impacts took, to 0.5% of the motor's work.
    #[test]
    fn the_nut_and_the_runner_keep_the_energy_ledger() {
        use crate::planar::{ApexState, PlanarParams};
        use crate::planar_general::{Actuation, GeneralParams, GeneralRunner};
        let p = GeneralParams::from_section_2_2(&PlanarParams::table_2_2());
        let start = ApexState {
            z_m: p.leg_length_m + 0.15,
            x_dot_mps: 0.5,
            phi_rad: 0.0,
            theta_rad: 0.05,
            phi_dot_rad_s: 0.0,
            theta_dot_rad_s: 0.0,
        };
        let mut run = GeneralRunner::from_apex(p, &start).unwrap_or_else(|e| panic!("{e:?}"));
        let mut nut = Nut::new(LegScrew::design()).unwrap_or_else(|e| panic!("{e:?}"));
        let k = p.leg_stiffness_n_per_m;
        // The runner counts its spring as `0.5 k c^2`; with the nut it is
        // `0.5 k (c + p)^2`.
        let total = |run: &GeneralRunner, nut: &Nut| {
            let c = p.leg_length_m - run.state().leg_length_m;
            let q = c + nut.position_m();
            run.energy_j() + 0.5 * k * (q * q - c * c) + nut.rotor_energy_j()
        };
        let e0 = total(&run, &nut);
        let dt = 1e-4;
        let mut stances = 0;
        let mut impacts_j = 0.0;
        for _ in 0..20_000 {
            let st = run.state();
            let command_a = if st.stance { 20.0 } else { -20.0 };
            let c = p.leg_length_m - st.leg_length_m;
            let i = nut.amplifier_a(command_a);
            nut.step(dt, i, k * (c + nut.position_m()), 0.0);
            run.set_actuation(Actuation {
                leg_thrust_n: nut.thrust_n(k),
                ..Actuation::default()
            });
            run.step(dt, &mut |e| match e {
                crate::planar::PlanarEvent::Touchdown { loss_j, .. } => {
                    stances += 1;
                    impacts_j += loss_j;
                }
                crate::planar::PlanarEvent::Liftoff { loss_j, .. } => impacts_j += loss_j,
                crate::planar::PlanarEvent::Apex { .. } => {}
            });
        }
        let booked = nut.motor_work_j() - nut.stop_loss_j() - impacts_j;
        let gained = total(&run, &nut) - e0;
        assert!(stances >= 3, "{stances}");
        assert!(nut.motor_work_j().abs() > 5.0, "{}", nut.motor_work_j());
        assert!(
            (gained - booked).abs() < 0.005 * nut.motor_work_j().abs(),
            "gained {gained} J, booked {booked} J"
        );
    }

    #[test]
    fn a_bad_drive_is_refused_by_name() {
        let mut d = LegScrew::design();
        d.screw_lead_m = 0.0;
        assert_eq!(
            Nut::new(d).err(),
            Some(PlanarError::NotPositive("leg_screw_lead_m"))
        );
        let mut d = LegScrew::design();
        d.efficiency = 1.5;
        assert_eq!(
            Nut::new(d).err(),
            Some(PlanarError::OutOfRange("leg_efficiency"))
        );
    }
}
