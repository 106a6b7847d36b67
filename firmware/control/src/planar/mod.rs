//! The planar machine: the one-legged runner of thesis section 2.2 and
//! Appendix A with its hip actuated (section 5.2's next step, "designing
//! the trunk actuation system"): a hip motor between the body and the
//! leg, the leg's thrust along it in stance. What its controllers read
//! each period ([`PlanarEstimate`]) and command ([`PlanarCommand`]); each
//! controller is one type in its own file.

pub mod guard;
pub mod raibert;

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
}

impl PlanarEstimate {
    /// Whether every measurement is finite.
    pub fn is_finite(&self) -> bool {
        [
            self.x_dot_mps,
            self.z_m,
            self.z_dot_mps,
            self.phi_rad,
            self.phi_dot_rad_s,
            self.theta_rad,
            self.theta_dot_rad_s,
            self.leg_rate_mps,
        ]
        .iter()
        .all(|v| v.is_finite())
    }
}

/// What a planar controller commands for the next period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanarCommand {
    /// The hip motor's torque on the leg (the body takes the reaction),
    /// leg forward positive, N m.
    pub hip_torque_nm: f32,
    /// The leg actuator's push along the leg in stance, N.
    pub leg_thrust_n: f32,
}
