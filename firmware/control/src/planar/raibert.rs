//! Raibert's three-part controller for a one-legged runner (*Legged
//! Robots That Balance*, 1986, the thesis's reference [21]): the hop's
//! height by the leg's thrust in stance, the forward speed by where the
//! foot is placed in flight, the body's attitude by the hip's torque in
//! stance.
//!
//! - **Foot placement.** In flight the leg is servoed to the angle that
//!   puts the toe `x_f = x' T_s / 2 + k_x (x' - x'_d)` ahead of the hip:
//!   the neutral point (half the distance the hip travels in a stance of
//!   `T_s`, the last one measured), where the stance neither speeds the
//!   body up nor slows it down, plus the speed error's correction.
//! - **Attitude.** In stance the ground holds the leg, so the hip's torque
//!   turns the body: a PD on the pitch.
//! - **Thrust.** A push along the leg while it lengthens in stance, set
//!   anew at each apex from the apex's error against the target.

use super::{PlanarCommand, PlanarEstimate};
use crate::param::{require, InvalidField};

/// The controller's settings, SI.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RaibertConfig {
    /// The leg's length on its stop, hip to toe, m.
    pub leg_length_m: f32,
    /// The speed error's gain on the foot's placement `k_x`, m per m/s.
    pub speed_gain_s: f32,
    /// The speed error's integral on the foot's placement, per stride:
    /// the placement that running against the machine's losses needs, m
    /// per m/s.
    pub speed_trim_gain_s: f32,
    /// The integral learns only from speed errors smaller than this, m/s:
    /// it is there for a steady bias (the swing's, the friction's), and a
    /// push would wind it up and turn one disturbance into a slow
    /// undershoot (10 strides to recover from a 20 N s push without the
    /// band, 6 with it).
    pub speed_trim_band_mps: f32,
    /// The speed error's correction of the foot's placement at most, m (a
    /// larger step of the foot swings the leg further in flight, and the
    /// body the other way).
    pub max_correction_m: f32,
    /// How much the speed the controller runs at may move toward the
    /// command per stride, m/s (a step of the command becomes a ramp: a
    /// sudden change of the foot's placement turns the body).
    pub max_speed_change_mps: f32,
    /// The flight leg servo's stiffness, N m/rad.
    pub leg_kp_nm_per_rad: f32,
    /// The flight leg servo's damping, N m s/rad.
    pub leg_kd_nms_per_rad: f32,
    /// The stance pitch servo's stiffness, N m/rad.
    pub pitch_kp_nm_per_rad: f32,
    /// The stance pitch servo's damping, N m s/rad.
    pub pitch_kd_nms_per_rad: f32,
    /// The pitch at each apex's integral on the stance's pitch target,
    /// per stride (the flight's leg swing turns the body the other way:
    /// the stance leaves it turned ahead of that), rad/rad.
    pub pitch_trim_gain: f32,
    /// How far the body turns back per radian the leg swings forward in
    /// flight (the angular momentum the two share: about the leg's
    /// inertia about the machine's centre over the body's): the stance
    /// leaves the body turned ahead by half the next flight's swing, rad
    /// per rad.
    pub swing_ratio: f32,
    /// The hip motor's torque limit, N m.
    pub max_hip_torque_nm: f32,
    /// The leg angle the placement may ask for at most, rad.
    pub max_leg_angle_rad: f32,
    /// The toe's apex height above the ground to hold, m.
    pub target_apex_m: f32,
    /// The thrust of the first stance, N.
    pub initial_thrust_n: f32,
    /// The thrust's share proportional to the last apex's error, N/m
    /// (the hop's energy integrates the thrust's work already: this is
    /// the loop's damping).
    pub thrust_gain_n_per_m: f32,
    /// The thrust's integral on the apex's error, per stride, N/m (the
    /// thrust the losses need).
    pub thrust_trim_gain_n_per_m: f32,
    /// The thrust limit, N.
    pub max_thrust_n: f32,
    /// The stance time assumed before one is measured, s.
    pub initial_stance_s: f32,
    /// The thesis's forward-speed stabiliser (eqs 2.79-2.80) on top: in
    /// stance the leg's force less `K_c (x'_d - x')`, N s/m (0: off).
    pub stabiliser_gain_ns_per_m: f32,
}

impl RaibertConfig {
    /// Settings for the thesis's planar runner (Table 2.2: 16 kg, a
    /// 0.65 m leg, a 40 kN/m leg spring, stances of about 0.07 s).
    pub const fn table_2_2() -> Self {
        RaibertConfig {
            leg_length_m: super::TABLE_2_2_LEG_LENGTH_M,
            speed_gain_s: 0.1,
            speed_trim_gain_s: 0.03,
            speed_trim_band_mps: 0.2,
            max_correction_m: 0.05,
            max_speed_change_mps: 0.15,
            leg_kp_nm_per_rad: 150.0,
            leg_kd_nms_per_rad: 8.0,
            pitch_kp_nm_per_rad: 300.0,
            pitch_kd_nms_per_rad: 60.0,
            pitch_trim_gain: 0.5,
            swing_ratio: 0.3,
            max_hip_torque_nm: hopper_model::design::HIP_TORQUE_LIMIT_NM as f32,
            max_leg_angle_rad: 0.4,
            target_apex_m: 0.15,
            initial_thrust_n: 100.0,
            thrust_gain_n_per_m: 6_000.0,
            thrust_trim_gain_n_per_m: 800.0,
            max_thrust_n: 1_500.0,
            initial_stance_s: 0.07,
            stabiliser_gain_ns_per_m: 0.0,
        }
    }

    /// Every field finite and in its range; else the first that is not.
    pub fn validate(&self) -> Result<(), InvalidField> {
        let pos = |v: f32| v.is_finite() && v > 0.0;
        let nonneg = |v: f32| v.is_finite() && v >= 0.0;
        require(pos(self.leg_length_m), "leg_length_m")?;
        require(nonneg(self.speed_gain_s), "speed_gain_s")?;
        require(nonneg(self.speed_trim_gain_s), "speed_trim_gain_s")?;
        require(pos(self.speed_trim_band_mps), "speed_trim_band_mps")?;
        require(pos(self.max_correction_m), "max_correction_m")?;
        require(pos(self.max_speed_change_mps), "max_speed_change_mps")?;
        require(
            nonneg(self.swing_ratio) && self.swing_ratio <= 2.0,
            "swing_ratio",
        )?;
        require(
            nonneg(self.pitch_trim_gain) && self.pitch_trim_gain <= 2.0,
            "pitch_trim_gain",
        )?;
        require(
            nonneg(self.thrust_trim_gain_n_per_m),
            "thrust_trim_gain_n_per_m",
        )?;
        require(nonneg(self.leg_kp_nm_per_rad), "leg_kp_nm_per_rad")?;
        require(nonneg(self.leg_kd_nms_per_rad), "leg_kd_nms_per_rad")?;
        require(nonneg(self.pitch_kp_nm_per_rad), "pitch_kp_nm_per_rad")?;
        require(nonneg(self.pitch_kd_nms_per_rad), "pitch_kd_nms_per_rad")?;
        require(pos(self.max_hip_torque_nm), "max_hip_torque_nm")?;
        require(
            pos(self.max_leg_angle_rad) && self.max_leg_angle_rad < 1.2,
            "max_leg_angle_rad",
        )?;
        require(nonneg(self.target_apex_m), "target_apex_m")?;
        require(pos(self.max_thrust_n), "max_thrust_n")?;
        require(
            nonneg(self.initial_thrust_n) && self.initial_thrust_n <= self.max_thrust_n,
            "initial_thrust_n",
        )?;
        require(nonneg(self.thrust_gain_n_per_m), "thrust_gain_n_per_m")?;
        require(pos(self.initial_stance_s), "initial_stance_s")?;
        require(
            self.stabiliser_gain_ns_per_m.is_finite() && self.stabiliser_gain_ns_per_m.abs() <= 1e4,
            "stabiliser_gain_ns_per_m",
        )
    }
}

/// Raibert's controller (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Raibert {
    cfg: RaibertConfig,
    /// The last complete stance's duration, s.
    stance_s: f32,
    /// Time in the current stance, s.
    stance_clock_s: f32,
    /// The thrust of the next stances, N.
    thrust_n: f32,
    /// The thrust the losses need (the integral), N.
    thrust_trim_n: f32,
    /// The foot placement running against the losses needs (the
    /// integral), m.
    speed_trim_m: f32,
    /// The stance's pitch target (the integral), rad.
    pitch_target_rad: f32,
    /// The speed the controller runs at, moving toward the command, m/s
    /// (`None` until the first step).
    speed_target_mps: Option<f32>,
    /// In stance at the last step.
    was_stance: bool,
    /// Rising at the last step (for the apex).
    rising: bool,
    /// The last apex's toe height, m.
    last_apex_m: Option<f32>,
}

impl Raibert {
    /// A controller with `cfg`, checked.
    pub fn new(cfg: RaibertConfig) -> Result<Self, InvalidField> {
        cfg.validate()?;
        Ok(Raibert {
            cfg,
            stance_s: cfg.initial_stance_s,
            stance_clock_s: 0.0,
            thrust_n: cfg.initial_thrust_n,
            thrust_trim_n: cfg.initial_thrust_n,
            speed_trim_m: 0.0,
            pitch_target_rad: 0.0,
            speed_target_mps: None,
            was_stance: false,
            rising: false,
            last_apex_m: None,
        })
    }

    /// Its settings.
    pub fn config(&self) -> &RaibertConfig {
        &self.cfg
    }

    /// The last complete stance's duration, s.
    pub fn stance_s(&self) -> f32 {
        self.stance_s
    }

    /// The thrust the next stance pushes with, N.
    pub fn thrust_n(&self) -> f32 {
        self.thrust_n
    }

    /// The last apex's toe height, m.
    pub fn last_apex_m(&self) -> Option<f32> {
        self.last_apex_m
    }

    /// Where the foot goes ahead of the hip at `speed_mps` for the
    /// commanded `speed_command_mps`, m: the neutral point plus the speed
    /// error's correction.
    pub fn foot_placement_m(&self, speed_mps: f32, speed_command_mps: f32) -> f32 {
        speed_mps * self.stance_s * 0.5
            + (self.cfg.speed_gain_s * (speed_mps - speed_command_mps))
                .clamp(-self.cfg.max_correction_m, self.cfg.max_correction_m)
            + self.speed_trim_m
    }

    /// The leg angle that places the foot (from the vertical, toe ahead
    /// positive), rad.
    fn leg_angle_for(&self, speed_mps: f32, speed_command_mps: f32) -> f32 {
        let c = &self.cfg;
        let x_f = self.foot_placement_m(speed_mps, speed_command_mps);
        let sine = (x_f / c.leg_length_m).clamp(-0.99, 0.99);
        libm::asinf(sine).clamp(-c.max_leg_angle_rad, c.max_leg_angle_rad)
    }

    /// One period of `dt_s`: the command for `est` at the commanded
    /// forward speed `speed_command_mps`. A non-finite input commands
    /// nothing.
    pub fn step(
        &mut self,
        est: &PlanarEstimate,
        speed_command_in: f32,
        dt_s: f32,
    ) -> PlanarCommand {
        let finite = est.is_finite() && speed_command_in.is_finite() && dt_s.is_finite();
        if !finite || dt_s <= 0.0 {
            return PlanarCommand::default();
        }
        let speed_command_mps = *self.speed_target_mps.get_or_insert(speed_command_in);
        let commanded = speed_command_in;
        let c = &self.cfg;
        let torque_limit = |t: f32| t.clamp(-c.max_hip_torque_nm, c.max_hip_torque_nm);
        let cmd = if est.stance {
            self.stance_clock_s += dt_s;
            // The ground holds the leg: the hip's reaction turns the body
            // (its torque on the leg is the body's, reversed).
            // The next flight swings the leg from about the mirror of its
            // touchdown angle to the next one: the body leaves ahead by
            // half what that swing turns it back.
            let next = self.leg_angle_for(est.x_dot_mps, speed_command_mps);
            let target = self.pitch_target_rad + c.swing_ratio * next;
            let hip = c.pitch_kp_nm_per_rad * (est.phi_rad - target)
                + c.pitch_kd_nms_per_rad * est.phi_dot_rad_s;
            let push = if est.leg_rate_mps > 0.0 {
                self.thrust_n
            } else {
                0.0
            };
            // Eq 2.80's stabiliser: the leg's force less `K_c (x'_d - x')`
            // (the actuator may pull as well as push here).
            let stabiliser = c.stabiliser_gain_ns_per_m * (speed_command_mps - est.x_dot_mps);
            let thrust = (push - stabiliser).clamp(-c.max_thrust_n, c.max_thrust_n);
            PlanarCommand {
                hip_torque_nm: torque_limit(hip),
                leg_thrust_n: thrust,
                leg_current_a: 0.0,
            }
        } else {
            if self.was_stance {
                self.stance_s = self.stance_clock_s.max(0.2 * c.initial_stance_s);
                self.stance_clock_s = 0.0;
                self.rising = true;
            }
            if self.rising && est.z_dot_mps <= 0.0 {
                // The apex: the thrust set anew from its error.
                self.rising = false;
                let apex = est.z_m - c.leg_length_m;
                self.last_apex_m = Some(apex);
                let error = c.target_apex_m - apex;
                self.thrust_trim_n = (self.thrust_trim_n + c.thrust_trim_gain_n_per_m * error)
                    .clamp(0.0, c.max_thrust_n);
                self.thrust_n =
                    (self.thrust_trim_n + c.thrust_gain_n_per_m * error).clamp(0.0, c.max_thrust_n);
                // Once a stride: the speed the controller runs at moves
                // toward the command, and the speed's and the pitch's
                // integrals.
                let step = c.max_speed_change_mps;
                self.speed_target_mps =
                    Some(speed_command_mps + (commanded - speed_command_mps).clamp(-step, step));
                let limit = 0.5 * c.leg_length_m;
                let speed_error = est.x_dot_mps - speed_command_mps;
                if speed_error.abs() < c.speed_trim_band_mps {
                    self.speed_trim_m = (self.speed_trim_m + c.speed_trim_gain_s * speed_error)
                        .clamp(-limit, limit);
                }
                self.pitch_target_rad =
                    (self.pitch_target_rad - c.pitch_trim_gain * est.phi_rad).clamp(-0.3, 0.3);
            }
            let theta_d = self.leg_angle_for(est.x_dot_mps, speed_command_mps);
            let hip = c.leg_kp_nm_per_rad * (theta_d - est.theta_rad)
                - c.leg_kd_nms_per_rad * est.theta_dot_rad_s;
            PlanarCommand {
                hip_torque_nm: torque_limit(hip),
                leg_thrust_n: 0.0,
                leg_current_a: 0.0,
            }
        };
        self.was_stance = est.stance;
        cmd
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn a_bad_setting_is_refused_by_name() {
        let mut c = RaibertConfig::table_2_2();
        c.max_thrust_n = f32::NAN;
        assert_eq!(Raibert::new(c).err(), Some(InvalidField("max_thrust_n")));
        let mut c = RaibertConfig::table_2_2();
        c.initial_thrust_n = c.max_thrust_n + 1.0;
        assert_eq!(
            Raibert::new(c).err(),
            Some(InvalidField("initial_thrust_n"))
        );
    }

    /// Running at the commanded speed, the foot goes to the neutral point
    /// (half a stance's travel); faster than commanded, further ahead.
    #[test]
    fn the_foot_goes_to_the_neutral_point_plus_the_error() {
        let r = Raibert::new(RaibertConfig::table_2_2()).unwrap_or_else(|e| panic!("{e:?}"));
        let t = r.stance_s();
        assert!((r.foot_placement_m(1.0, 1.0) - 0.5 * t).abs() < 1e-6);
        assert!((r.foot_placement_m(1.2, 1.0) - (0.6 * t + 0.1 * 0.2)).abs() < 1e-6);
    }

    /// A stance's length is measured at liftoff, and an apex below the
    /// target raises the thrust.
    #[test]
    fn stance_time_and_thrust_follow_the_hops() {
        let mut r = Raibert::new(RaibertConfig::table_2_2()).unwrap_or_else(|e| panic!("{e:?}"));
        let stance = PlanarEstimate {
            stance: true,
            z_m: 0.6,
            leg_rate_mps: 0.5,
            ..Default::default()
        };
        for _ in 0..80 {
            let c = r.step(&stance, 0.0, 1e-3);
            assert_eq!(c.leg_thrust_n, 100.0);
        }
        let rising = PlanarEstimate {
            z_m: 0.7,
            z_dot_mps: 1.0,
            ..Default::default()
        };
        r.step(&rising, 0.0, 1e-3);
        assert!((r.stance_s() - 0.08).abs() < 1e-4, "{}", r.stance_s());
        // The apex: 0.05 m of toe clearance against 0.15.
        let apex = PlanarEstimate {
            z_m: 0.7,
            z_dot_mps: -0.01,
            ..Default::default()
        };
        r.step(&apex, 0.0, 1e-3);
        assert!((r.last_apex_m().unwrap_or(0.0) - 0.05).abs() < 1e-6);
        assert!((r.thrust_n() - 780.0).abs() < 1e-3, "{}", r.thrust_n());
    }

    proptest! {
        /// Whatever it reads, its command is finite and within the limits.
        #[test]
        fn the_command_stays_within_its_limits(
            v in proptest::collection::vec(-1e6f32..1e6, 9),
            stance in any::<bool>(),
            steps in 1usize..50,
        ) {
            let mut r = Raibert::new(RaibertConfig::table_2_2()).unwrap_or_else(|e| panic!("{e:?}"));
            let est = PlanarEstimate {
                stance,
                x_dot_mps: v[0],
                z_m: v[1],
                z_dot_mps: v[2],
                phi_rad: v[3],
                phi_dot_rad_s: v[4],
                theta_rad: v[5],
                theta_dot_rad_s: v[6],
                leg_rate_mps: v[7],
                toe_x_m: 0.0,
            };
            for _ in 0..steps {
                let c = r.step(&est, v[8], 1e-3);
                prop_assert!(c.hip_torque_nm.abs() <= 100.0);
                prop_assert!(c.leg_thrust_n.abs() <= 1_500.0);
            }
        }
    }
}
