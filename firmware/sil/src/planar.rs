//! The planar machine in the loop: Appendix A's runner with its hip
//! actuated ([`hopper_plant::planar_general`]) and a planar controller of
//! the control crate, one period at a time. `hopper-sim planar run
//! --controller raibert` and the QEMU planar image both run this, so the
//! golden check compares the same computation on two instruction sets.
//!
//! The controller reads the plant's state ([`PlanarLoop::estimate`]: the
//! boom's and the hip's measurements as a planar machine would have them,
//! without their noise), and its command holds over the period.

use hopper_control::planar::guard::{Guard, GuardConfig, PlanarFault};
use hopper_control::planar::raibert::{Raibert, RaibertConfig};
use hopper_control::planar::{PlanarCommand, PlanarEstimate};
use hopper_plant::planar::{ApexState, PlanarError, PlanarEvent, PlanarState};
use hopper_plant::planar_general::{Actuation, GeneralParams, GeneralRunner};

/// The plant's integration step and the controller's period, s (the
/// firmware's 10 kHz).
pub const DT_S: f64 = 1e-4;

/// The plant and the controller.
#[derive(Clone, Copy, Debug)]
pub struct PlanarLoop {
    plant: GeneralRunner,
    /// The controller.
    pub controller: Raibert,
    /// The pitch, leg-angle and fall limits over its command.
    guard: Guard,
    /// The leg's length at the last period, m (for its rate).
    prev_leg_m: f64,
}

impl PlanarLoop {
    /// The machine `p` at an apex with the toe `cfg.target_apex_m` up,
    /// moving at `speed_mps`, run by Raibert's controller with `cfg`.
    pub fn new(p: GeneralParams, cfg: RaibertConfig, speed_mps: f64) -> Result<Self, PlanarError> {
        let controller = Raibert::new(cfg).map_err(|e| PlanarError::OutOfRange(e.0))?;
        let guard =
            Guard::new(GuardConfig::table_2_2()).map_err(|e| PlanarError::OutOfRange(e.0))?;
        let start = ApexState {
            z_m: p.leg_length_m + f64::from(cfg.target_apex_m),
            x_dot_mps: speed_mps,
            phi_rad: 0.0,
            theta_rad: 0.0,
            phi_dot_rad_s: 0.0,
            theta_dot_rad_s: 0.0,
        };
        Ok(PlanarLoop {
            plant: GeneralRunner::from_apex(p, &start)?,
            controller,
            guard,
            prev_leg_m: p.leg_length_m,
        })
    }

    /// The plant's state.
    pub fn state(&self) -> PlanarState {
        self.plant.state()
    }

    /// The machine's parameters.
    pub fn params(&self) -> &GeneralParams {
        self.plant.params()
    }

    /// What the controller reads this period: the plant's state, the
    /// leg's rate from its length a period ago.
    pub fn estimate(&mut self) -> PlanarEstimate {
        let st = self.plant.state();
        let leg_rate = (st.leg_length_m - self.prev_leg_m) / DT_S;
        self.prev_leg_m = st.leg_length_m;
        PlanarEstimate {
            stance: st.stance,
            x_dot_mps: st.x_dot_mps as f32,
            z_m: st.z_m as f32,
            z_dot_mps: st.z_dot_mps as f32,
            phi_rad: st.phi_rad as f32,
            phi_dot_rad_s: st.phi_dot_rad_s as f32,
            theta_rad: st.theta_rad as f32,
            theta_dot_rad_s: st.theta_dot_rad_s as f32,
            leg_rate_mps: if st.stance { leg_rate as f32 } else { 0.0 },
        }
    }

    /// The controller's period: its command for `est` at the commanded
    /// speed, through the guard (zero on both actuators once a limit
    /// latched).
    pub fn control(&mut self, est: &PlanarEstimate, speed_command_mps: f64) -> PlanarCommand {
        let cmd = self
            .controller
            .step(est, speed_command_mps as f32, DT_S as f32);
        self.guard.filter(est, cmd)
    }

    /// What the guard latched, if anything.
    pub fn fault(&self) -> Option<PlanarFault> {
        self.guard.fault()
    }

    /// Applies `cmd` (and a push on the body of `push_n`) and integrates
    /// the plant over the period, its transitions to `on_event`.
    pub fn advance(
        &mut self,
        cmd: PlanarCommand,
        push_n: f64,
        on_event: &mut impl FnMut(PlanarEvent),
    ) {
        self.plant.set_actuation(Actuation {
            hip_torque_nm: f64::from(cmd.hip_torque_nm),
            leg_thrust_n: f64::from(cmd.leg_thrust_n),
            push_n,
        });
        self.plant.step(DT_S, on_event);
    }
}
