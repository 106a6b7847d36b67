//! The planar machine: the one-legged runner of thesis section 2.2 and
//! Appendix A with its hip actuated (section 5.2's next step, "designing
//! the trunk actuation system"): a hip motor between the body and the
//! leg, the leg's thrust along it in stance. What its controllers read
//! each period ([`PlanarEstimate`]) and command ([`PlanarCommand`]); each
//! controller is one type in its own file.

pub mod estimator;
pub mod guard;
pub mod period;
pub mod raibert;
pub mod thrust;

use crate::param::{require, InvalidField};

/// Table 2.2's leg, hip to toe on its stop, m: the planar defaults'
/// (the machine a run builds gives its own).
pub const TABLE_2_2_LEG_LENGTH_M: f32 = 0.65;

/// What a planar controller knows of the machine each period, SI. Angles
/// from the vertical: the body's pitch `phi` (nose up positive, as the
/// plant's), the leg's `theta` (toe ahead positive).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanarEstimate {
    /// The toe is on the ground.
    pub stance: bool,
    /// The hip's forward speed, m/s.
    pub x_dot_mps: f32,
    /// The hip's height above the ground, m.
    pub z_m: f32,
    /// The hip's vertical speed, m/s.
    pub z_dot_mps: f32,
    /// Body pitch, rad.
    pub phi_rad: f32,
    /// Body pitch rate, rad/s.
    pub phi_dot_rad_s: f32,
    /// Leg angle from the vertical, rad.
    pub theta_rad: f32,
    /// Leg angular rate, rad/s.
    pub theta_dot_rad_s: f32,
    /// The leg's lengthening rate, m/s (0 in flight: the leg on its stop).
    pub leg_rate_mps: f32,
    /// The toe's forward position, m: in stance where it stands, in flight
    /// where it is over the ground.
    pub toe_x_m: f32,
}

impl PlanarEstimate {
    /// Whether every measurement is finite.
    pub fn is_finite(&self) -> bool {
        // A finite value times zero is zero, an infinite one or a NaN
        // gives a NaN: the sum is zero exactly when every field is finite
        // (one test in the control period, not nine).
        [
            self.x_dot_mps,
            self.z_m,
            self.z_dot_mps,
            self.phi_rad,
            self.phi_dot_rad_s,
            self.theta_rad,
            self.theta_dot_rad_s,
            self.leg_rate_mps,
            self.toe_x_m,
        ]
        .iter()
        .fold(0.0, |sum, v| sum + v * 0.0)
            == 0.0
    }
}

/// What an amplifier of limit `limit_a` drives for `current_a`, its limit
/// scaled by `limit_scale` (the winding's derating, in `[0, 1]`): within
/// the scaled limit, and 0 for a current that is not finite or a NaN or
/// negative limit (an unvalidated drive, a NaN scale). The hip's and the
/// leg's motors both.
pub fn limited_current_a(current_a: f32, limit_a: f32, limit_scale: f32) -> f32 {
    let limit = limit_a * crate::num::clamp(limit_scale, 0.0, 1.0);
    if current_a.is_finite() && limit >= 0.0 {
        crate::num::clamp(current_a, -limit, limit)
    } else {
        0.0
    }
}

/// What a planar controller commands for the next period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanarCommand {
    /// The hip motor's torque on the leg (the body takes the reaction),
    /// leg forward positive, N m.
    pub hip_torque_nm: f32,
    /// The leg actuator's push along the leg in stance, N (a machine
    /// whose leg is driven by a force).
    pub leg_thrust_n: f32,
    /// The leg motor's current, A, positive compressing the spring (a
    /// machine whose leg is driven through its ball screw,
    /// [`thrust::ScrewThrust`]).
    pub leg_current_a: f32,
}

/// The hip's drive as the firmware commands it: the torque a controller
/// asks for becomes the current the amplifier is told to drive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HipDrive {
    /// The hip's torque per ampere (motor constant, gear ratio and
    /// efficiency), N m/A.
    pub torque_per_amp_nm_per_a: f32,
    /// The amplifier's current limit, A.
    pub current_limit_a: f32,
}

impl HipDrive {
    /// The design machine's hip: the leg's motor through its gearhead
    /// ([`hopper_model::design::HIP_TORQUE_PER_AMP_NM_PER_A`]).
    pub const fn design() -> Self {
        use hopper_model::design as d;
        HipDrive {
            torque_per_amp_nm_per_a: d::HIP_TORQUE_PER_AMP_NM_PER_A as f32,
            current_limit_a: d::CURRENT_LIMIT_A as f32,
        }
    }

    /// Both positive and finite; else the first that is not.
    pub fn validate(&self) -> Result<(), InvalidField> {
        let pos = |v: f32| v.is_finite() && v > 0.0;
        require(pos(self.torque_per_amp_nm_per_a), "torque_per_amp_nm_per_a")?;
        require(pos(self.current_limit_a), "current_limit_a")
    }

    /// The current for `torque_nm`, within the limit scaled by
    /// `limit_scale` (the winding's derating, in `[0, 1]`); 0 for a
    /// non-finite torque.
    pub fn current_a(&self, torque_nm: f32, limit_scale: f32) -> f32 {
        limited_current_a(
            torque_nm / self.torque_per_amp_nm_per_a,
            self.current_limit_a,
            limit_scale,
        )
    }

    /// The hip's torque at the current limit, N m.
    pub fn torque_limit_nm(&self) -> f32 {
        self.current_limit_a * self.torque_per_amp_nm_per_a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Finite is every field finite, whatever its size or sign: the
    /// largest, the subnormal and both zeros count, an infinity or a NaN
    /// in any field does not.
    #[test]
    fn an_estimate_is_finite_when_every_field_is() {
        let tiny = f32::from_bits(1);
        for v in [0.0, -0.0, tiny, -tiny, f32::MAX, f32::MIN, 1.0] {
            let e = PlanarEstimate {
                x_dot_mps: v,
                z_m: f32::MAX,
                toe_x_m: f32::MIN,
                ..PlanarEstimate::default()
            };
            assert!(e.is_finite(), "{v}");
        }
        for bad in [f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            for k in 0..9 {
                let mut f = [1.0_f32; 9];
                f[k] = bad;
                let e = PlanarEstimate {
                    x_dot_mps: f[0],
                    z_m: f[1],
                    z_dot_mps: f[2],
                    phi_rad: f[3],
                    phi_dot_rad_s: f[4],
                    theta_rad: f[5],
                    theta_dot_rad_s: f[6],
                    leg_rate_mps: f[7],
                    toe_x_m: f[8],
                    ..PlanarEstimate::default()
                };
                assert!(!e.is_finite(), "{bad} in field {k}");
            }
        }
    }

    #[test]
    fn the_hip_current_is_limited_and_derated() {
        let d = HipDrive::design();
        assert!(d.validate().is_ok());
        let k = d.torque_per_amp_nm_per_a;
        assert!((d.current_a(10.0, 1.0) - 10.0 / k).abs() < 1e-5);
        // 45 N m at the limit: 60 N m is clamped to it, or to half derated.
        assert!((d.current_limit_a * k - 45.0).abs() < 0.01);
        assert_eq!(d.current_a(-60.0, 1.0), -d.current_limit_a);
        assert_eq!(d.current_a(60.0, 0.5), 0.5 * d.current_limit_a);
        assert_eq!(d.current_a(f32::NAN, 1.0), 0.0);
        assert_eq!(d.current_a(60.0, f32::NAN), 0.0);
        assert!((d.torque_limit_nm() - 45.0).abs() < 0.01);
    }

    proptest::proptest! {
        /// Any drive, torque and scale: no panic, and a current within the
        /// limit (none when the limit is not a number).
        #[test]
        fn the_current_is_within_the_limit(
            per_amp in proptest::prop_oneof![-10.0f32..10.0, proptest::prelude::Just(f32::NAN)],
            limit in proptest::prop_oneof![-10.0f32..100.0, proptest::prelude::Just(f32::NAN), proptest::prelude::Just(f32::INFINITY)],
            torque in proptest::prop_oneof![-1e6f32..1e6, proptest::prelude::Just(f32::NAN), proptest::prelude::Just(f32::NEG_INFINITY)],
            scale in proptest::prop_oneof![-1.0f32..2.0, proptest::prelude::Just(f32::NAN)],
        ) {
            let d = HipDrive { torque_per_amp_nm_per_a: per_amp, current_limit_a: limit };
            let i = d.current_a(torque, scale);
            proptest::prop_assert!(i.is_finite());
            proptest::prop_assert!(i == 0.0 || i.abs() <= limit);
        }
    }
}
