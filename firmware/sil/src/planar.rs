//! The planar machine in the loop: Appendix A's runner with its hip
//! actuated ([`hopper_plant::planar_general`]) and a planar controller of
//! the control crate, one period at a time. `hopper-sim planar run
//! --controller raibert` and the QEMU planar image both run this, so the
//! golden check compares the same computation on two instruction sets.
//!
//! The firmware's side is the control crate's planar period
//! ([`PlanarPeriod`]: the estimator, the controller, the leg's drive, the
//! guard and both windings); this module is the world's: it reads what a
//! boom-mounted machine's sensors measure ([`PlanarSensors`]: the plant's
//! state quantised to each encoder's and the potentiometer's resolution),
//! and the period's command holds over the period.
//!
//! The leg is driven one of two ways: by a force along it in stance (the
//! controller's own thrust, [`PlanarLoop::of`]), or as on the vertical
//! hopper, a motor turning a ball screw in series with the leg spring
//! ([`hopper_plant::planar_screw`]), run by a vertical law
//! ([`PlanarLoop::with_screw`], [`ScrewThrust`]). Which one is the loop's
//! type ([`LegLaw`]), so that a loop driving its leg by force runs
//! nothing of the other in its period.

use hopper_control::arming::ArmingConfig;
use hopper_control::laws::{ControllerKind, Strategy};
use hopper_control::model::ModelParams;
use hopper_control::planar::estimator::PlanarReadings;
use hopper_control::planar::guard::PlanarFault;
pub use hopper_control::planar::period::ForceLeg;
use hopper_control::planar::period::{LegDrive, PlanarPeriod};
use hopper_control::planar::raibert::RaibertConfig;
use hopper_control::planar::thrust::ScrewThrust;
use hopper_control::planar::{HipDrive, PlanarCommand, PlanarEstimate};
use hopper_plant::planar::{ApexState, PlanarError, PlanarEvent, PlanarState};
use hopper_plant::planar_general::{Actuation, GeneralParams, GeneralRunner};
use hopper_plant::planar_screw::{LegScrew, Nut};
use hopper_robot_link::planar::{Mount, Output, PlanarPort};
use hopper_robot_link::Tx;

/// The plant's integration step and the controller's period, s (the
/// firmware's 10 kHz).
pub const DT_S: f64 = 1e-4;

/// A planar machine: Appendix A's runner, its hip's drive and its
/// sensors (what a robot file describes).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarMachine {
    /// The runner.
    pub params: GeneralParams,
    /// The hip's drive: torque per ampere and the amplifier's limit.
    pub hip: HipDrive,
    /// The hip motor's winding resistance, ohm.
    pub hip_winding_ohm: f64,
    /// The leg's motor and ball screw (when the leg is driven through it).
    pub leg: LegScrew,
    /// The sensors.
    pub sensors: PlanarSensors,
}

impl PlanarMachine {
    /// Table 2.2's machine with its hip actuated
    /// ([`GeneralParams::actuated_table_2_2`]), the leg's motor through
    /// the design's gearhead at the hip ([`HipDrive::design`], the leg
    /// motor's winding), on a boom ([`PlanarSensors::boom`]).
    pub fn design() -> Self {
        PlanarMachine {
            params: GeneralParams::actuated_table_2_2(),
            hip: HipDrive::design(),
            hip_winding_ohm: hopper_plant::params::Params::design().winding_resistance_ohm,
            leg: LegScrew::design(),
            sensors: PlanarSensors::boom(),
        }
    }

    /// Every part within its ranges; else the first field that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        self.params.validate()?;
        self.hip
            .validate()
            .map_err(|e| PlanarError::OutOfRange(e.0))?;
        if !(self.hip_winding_ohm.is_finite() && self.hip_winding_ohm > 0.0) {
            return Err(PlanarError::NotPositive("hip_winding_ohm"));
        }
        self.leg.validate()?;
        self.sensors.validate()
    }

    /// The leg as the vertical laws' model reads it: the trunk's and the
    /// leg's masses as the body's (the nut's among them), the toe's as the
    /// unsprung mass, the leg spring, the leg's length and its drive.
    pub fn leg_model(&self) -> ModelParams {
        let (p, d) = (&self.params, &self.leg);
        let design = hopper_plant::params::Params::design();
        crate::sim_io::model_params(&hopper_plant::params::Params {
            body_mass_kg: p.trunk_mass_kg + p.leg_mass_kg - design.nut_mass_kg,
            unsprung_mass_kg: p.toe_mass_kg.max(1e-9),
            spring_stiffness_n_per_m: p.leg_stiffness_n_per_m,
            spring_preload_m: 0.0,
            leg_length_m: p.leg_length_m,
            gravity_mps2: p.gravity_mps2,
            rotor_inertia_kg_m2: d.rotor_inertia_kg_m2,
            screw_lead_m: d.screw_lead_m,
            efficiency: d.efficiency,
            stroke_m: d.stroke_m,
            torque_constant_nm_per_a: d.torque_constant_nm_per_a,
            current_limit_a: d.current_limit_a,
            winding_resistance_ohm: d.winding_ohm,
            ..design
        })
    }
}

/// The sensors of a planar hopper on a boom, by their resolution.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarSensors {
    /// The hip's forward position, m a count; 0: the machine has no
    /// forward encoder, and the estimator takes the speed from the leg's
    /// kinematics in stance.
    pub boom_x_m: f64,
    /// The hip's height, m a count.
    pub boom_z_m: f64,
    /// The body's pitch, rad a count.
    pub pitch_rad: f64,
    /// The hip's angle (the leg against the body), rad a count.
    pub hip_rad: f64,
    /// The leg's length, m a step of the potentiometer's converter.
    pub leg_m: f64,
    /// The leg motor's angle, rad a count (its encoder).
    pub leg_motor_rad: f64,
}

impl PlanarSensors {
    /// A 1.5 m boom with 20,000-line encoders read in quadrature (80,000
    /// counts a turn: 118 um at the hip), 16,384-line encoders on the
    /// pitch and the hip (65,536 counts: 96 urad), the leg's potentiometer
    /// read by a 12-bit converter over 0.1 m (24 um), and the leg motor's
    /// encoder as the vertical hopper's (2,000 counts a turn).
    pub const fn boom() -> Self {
        const TURN: f64 = 2.0 * core::f64::consts::PI;
        PlanarSensors {
            boom_x_m: TURN * 1.5 / 80_000.0,
            boom_z_m: TURN * 1.5 / 80_000.0,
            pitch_rad: TURN / 65_536.0,
            hip_rad: TURN / 65_536.0,
            leg_m: 0.1 / 4096.0,
            leg_motor_rad: TURN / 2000.0,
        }
    }

    /// Every resolution finite and positive; else the first that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        if !(self.boom_x_m.is_finite() && self.boom_x_m >= 0.0) {
            return Err(PlanarError::OutOfRange("boom_x_m"));
        }
        for (name, v) in [
            ("boom_z_m", self.boom_z_m),
            ("pitch_rad", self.pitch_rad),
            ("hip_rad", self.hip_rad),
            ("leg_m", self.leg_m),
            ("leg_motor_rad", self.leg_motor_rad),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlanarError::NotPositive(name));
            }
        }
        Ok(())
    }

    /// What they read of `st`, the leg motor at `leg_motor_rad`.
    pub fn read(&self, st: &PlanarState, leg_motor_rad: f64) -> PlanarReadings {
        // (No encoder, step 0: it reads 0.)
        let q = |v: f64, step: f64| {
            if step > 0.0 {
                (libm::round(v / step) * step) as f32
            } else {
                0.0
            }
        };
        PlanarReadings {
            boom_x_m: q(st.x_m, self.boom_x_m),
            boom_z_m: q(st.z_m, self.boom_z_m),
            pitch_rad: q(st.phi_rad, self.pitch_rad),
            hip_angle_rad: q(st.theta_rad - st.phi_rad, self.hip_rad),
            leg_length_m: q(st.leg_length_m, self.leg_m),
            leg_motor_rad: q(leg_motor_rad, self.leg_motor_rad),
        }
    }
}

/// The plant and the firmware's planar period, their leg driven as `L`
/// says.
#[derive(Clone, Debug)]
pub struct PlanarLoop<L: LegLaw = ForceLeg> {
    /// The firmware's period.
    period: PlanarPeriod<L>,
    /// The hip's copper loss so far, by the plant's winding, J.
    hip_copper_loss_j: f64,
    /// The hip motor's winding resistance, ohm.
    hip_winding_ohm: f64,
    /// The largest hip current so far, A.
    hip_peak_current_a: f32,
    /// The sensors.
    sensors: PlanarSensors,
    plant: GeneralRunner,
    /// The leg's nut, when the leg is driven through its screw.
    nut: Nut,
    /// The largest leg-motor current so far, A.
    leg_peak_current_a: f32,
    /// The leg's model, as the vertical laws read it.
    leg_model: ModelParams,
}

/// The leg's drive named `name`: `force` (`None`: Raibert's thrust, a
/// force along the leg), or a vertical law's name (its strategy for the
/// leg's ball screw, [`ScrewThrust::planar_strategy`]); else refused,
/// naming `thrust`.
pub fn thrust_named(name: &str) -> Result<Option<Strategy>, PlanarError> {
    if name == "force" {
        return Ok(None);
    }
    let kind = ControllerKind::from_name(name).ok_or(PlanarError::OutOfRange("thrust"))?;
    Ok(Some(ScrewThrust::planar_strategy(kind)))
}

/// What drives a planar loop's leg, by the name a run gives it.
pub trait LegLaw: LegDrive {
    /// The loop `lp` with its leg driven as `thrust` names it (`force`,
    /// or a vertical law's name for the screw), where that is this law;
    /// else refused.
    fn drive(lp: PlanarLoop<ForceLeg>, thrust: &str) -> Result<PlanarLoop<Self>, PlanarError>;
}

impl LegLaw for ForceLeg {
    fn drive(lp: PlanarLoop<ForceLeg>, thrust: &str) -> Result<PlanarLoop<Self>, PlanarError> {
        match thrust_named(thrust)? {
            None => Ok(lp),
            Some(_) => Err(PlanarError::OutOfRange("thrust")),
        }
    }
}

impl LegLaw for ScrewThrust {
    fn drive(lp: PlanarLoop<ForceLeg>, thrust: &str) -> Result<PlanarLoop<Self>, PlanarError> {
        match thrust_named(thrust)? {
            Some(strategy) => lp.with_screw(&strategy),
            None => Err(PlanarError::OutOfRange("thrust")),
        }
    }
}

impl PlanarLoop {
    /// The design machine ([`PlanarMachine::design`]) at an apex with the
    /// toe `cfg.target_apex_m` up, moving at `speed_mps`, run by Raibert's
    /// controller with `cfg`.
    pub fn new(cfg: RaibertConfig, speed_mps: f64) -> Result<Self, PlanarError> {
        Self::of(&PlanarMachine::design(), cfg, speed_mps)
    }

    /// The machine `m` at an apex with the toe `cfg.target_apex_m` up,
    /// moving at `speed_mps`, run by Raibert's controller with `cfg` (its
    /// leg's length and the estimator's taken from the machine's, its
    /// torque limit at most the hip drive's).
    pub fn of(m: &PlanarMachine, cfg: RaibertConfig, speed_mps: f64) -> Result<Self, PlanarError> {
        m.validate()?;
        let p = m.params;
        let period =
            PlanarPeriod::new(cfg, p.leg_length_m as f32, m.hip, m.sensors.boom_x_m == 0.0)
                .map_err(|e| PlanarError::OutOfRange(e.0))?;
        let start = ApexState {
            z_m: p.leg_length_m + f64::from(cfg.target_apex_m),
            x_dot_mps: speed_mps,
            phi_rad: 0.0,
            theta_rad: 0.0,
            phi_dot_rad_s: 0.0,
            theta_dot_rad_s: 0.0,
        };
        Ok(PlanarLoop {
            period,
            plant: GeneralRunner::from_apex(p, &start)?,
            sensors: m.sensors,
            hip_copper_loss_j: 0.0,
            hip_winding_ohm: m.hip_winding_ohm,
            hip_peak_current_a: 0.0,
            nut: Nut::new(m.leg)?,
            leg_model: m.leg_model(),
            leg_peak_current_a: 0.0,
        })
    }

    /// The leg driven as on the vertical hopper: its motor turns the ball
    /// screw, run by the vertical law `strategy` holding the controller's
    /// apex target (the controller's own thrust unused).
    pub fn with_screw(self, strategy: &Strategy) -> Result<PlanarLoop<ScrewThrust>, PlanarError> {
        let period = self
            .period
            .with_screw(strategy, &self.leg_model)
            .map_err(|e| PlanarError::OutOfRange(e.0))?;
        Ok(PlanarLoop {
            period,
            hip_copper_loss_j: self.hip_copper_loss_j,
            hip_winding_ohm: self.hip_winding_ohm,
            hip_peak_current_a: self.hip_peak_current_a,
            sensors: self.sensors,
            plant: self.plant,
            nut: self.nut,
            leg_peak_current_a: self.leg_peak_current_a,
            leg_model: self.leg_model,
        })
    }
}

impl PlanarLoop<ScrewThrust> {
    /// The vertical law driving the leg's screw.
    pub fn screw(&self) -> &ScrewThrust {
        self.period.leg()
    }
}

impl<L: LegLaw> PlanarLoop<L> {
    /// The firmware's period (what a control interrupt runs).
    pub fn period_mut(&mut self) -> &mut PlanarPeriod<L> {
        &mut self.period
    }

    /// The leg's nut.
    pub fn nut(&self) -> &Nut {
        &self.nut
    }

    /// The largest leg-motor current so far, A.
    pub fn leg_peak_current_a(&self) -> f32 {
        self.leg_peak_current_a
    }

    /// The plant's state.
    pub fn state(&self) -> PlanarState {
        self.plant.state()
    }

    /// The machine's parameters.
    pub fn params(&self) -> &GeneralParams {
        self.plant.params()
    }

    /// What the sensors read of the plant this period.
    pub fn sense(&self) -> PlanarReadings {
        self.sensors
            .read(&self.plant.state(), self.nut.motor_angle_rad())
    }

    /// The estimator's period: the estimate from this period's readings.
    pub fn estimate_from(&mut self, r: &PlanarReadings) -> PlanarEstimate {
        self.period.estimate_from(r, DT_S as f32)
    }

    /// What the controller reads this period: the sensors' readings of
    /// the plant, through the estimator.
    pub fn estimate(&mut self) -> PlanarEstimate {
        let r = self.sense();
        self.estimate_from(&r)
    }

    /// The controller's period ([`PlanarPeriod::control`]) at the
    /// commanded speed.
    pub fn control(&mut self, est: &PlanarEstimate, speed_command_mps: f64) -> PlanarCommand {
        self.period
            .control(est, speed_command_mps as f32, DT_S as f32)
    }

    /// The leg motor's winding temperature as the firmware estimates it,
    /// C (a leg driven through its screw).
    pub fn leg_winding_c(&self) -> f32 {
        self.period.leg_winding_c()
    }

    /// The hip motor's winding temperature as the firmware estimates it, C.
    pub fn hip_winding_c(&self) -> f32 {
        self.period.hip_winding_c()
    }

    /// The hip's copper loss so far, J.
    pub fn hip_copper_loss_j(&self) -> f64 {
        self.hip_copper_loss_j
    }

    /// The hip current commanded this period, A.
    pub fn hip_current_a(&self) -> f32 {
        self.period.hip_current_a()
    }

    /// The largest hip current so far, A.
    pub fn hip_peak_current_a(&self) -> f32 {
        self.hip_peak_current_a
    }

    /// What the guard latched, if anything.
    pub fn fault(&self) -> Option<PlanarFault> {
        self.period.fault()
    }

    /// Applies `cmd` (and a push on the body of `push_n`) and integrates
    /// the plant over the period, its transitions to `on_event`.
    pub fn advance(
        &mut self,
        cmd: PlanarCommand,
        push_n: f64,
        on_event: &mut impl FnMut(PlanarEvent),
    ) {
        // The hip's amplifier drives the current the torque was made of,
        // within its own limit; its winding turns it to heat.
        // (The plant's amplifier limits it as the firmware does: the same
        // drive, at the full limit.)
        let per_amp = f64::from(self.period.hip().torque_per_amp_nm_per_a);
        let current_a = f64::from(self.period.hip().current_a(cmd.hip_torque_nm, 1.0));
        self.hip_peak_current_a = self.hip_peak_current_a.max(libm::fabs(current_a) as f32);
        self.hip_copper_loss_j += current_a * current_a * self.hip_winding_ohm * DT_S;
        let leg_thrust_n = if L::SCREW {
            // The nut against the spring: its compression is the leg's
            // and the nut's (the lower leg on its stop in flight).
            let st = self.plant.state();
            let p = self.plant.params();
            let k = p.leg_stiffness_n_per_m;
            let compression_m = p.leg_length_m - st.leg_length_m;
            let i = self.nut.amplifier_a(f64::from(cmd.leg_current_a));
            self.leg_peak_current_a = self.leg_peak_current_a.max(libm::fabs(i) as f32);
            let spring_n = k * (compression_m + self.nut.position_m());
            self.nut.step(DT_S, i, spring_n, 0.0);
            self.nut.thrust_n(k)
        } else {
            f64::from(cmd.leg_thrust_n)
        };
        self.plant.set_actuation(Actuation {
            hip_torque_nm: current_a * per_amp,
            leg_thrust_n,
            push_n,
        });
        self.plant.step(DT_S, on_event);
    }
}

impl<L: LegLaw> PlanarLoop<L> {
    /// The body taken back up and held upright, the leg vertical, the toe
    /// `toe_m` above the ground at the boom's origin, at rest (the
    /// firmware's period keeps what it has: a hoist moves the machine,
    /// not its firmware).
    pub fn remount(&mut self, toe_m: f64) -> Result<(), PlanarError> {
        let p = *self.plant.params();
        let start = ApexState {
            z_m: p.leg_length_m + toe_m,
            x_dot_mps: 0.0,
            phi_rad: 0.0,
            theta_rad: 0.0,
            phi_dot_rad_s: 0.0,
            theta_dot_rad_s: 0.0,
        };
        self.plant = GeneralRunner::from_apex(p, &start)?;
        Ok(())
    }
}

/// The planar machine behind the host link, as `hopper-sim planar serve
/// --tcp` runs it: the plant, the firmware's period and the link's port
/// ([`PlanarPort`]). The body starts held upright on the boom, the toe
/// off the ground, and is let go when the machine arms (a hoist through
/// the link holds it again); disarmed, both amplifiers get 0 A.
#[derive(Clone, Debug)]
pub struct PlanarRobot<L: LegLaw = ForceLeg> {
    lp: PlanarLoop<L>,
    port: PlanarPort,
    held: bool,
    /// Robot time since the machine was last let go, s.
    since_release_s: f64,
}

impl<L: LegLaw> PlanarRobot<L> {
    /// `lp`'s machine held with the toe `toe_m` up until armed, its port
    /// the simulator's (the e-stop and the hoist simulated) with the
    /// arming's defaults.
    pub fn new(mut lp: PlanarLoop<L>, toe_m: f64) -> Result<Self, PlanarError> {
        lp.remount(toe_m)?;
        let port = PlanarPort::new(ArmingConfig::default(), DT_S as f32, true)
            .map_err(|e| PlanarError::OutOfRange(e.0))?;
        Ok(Self {
            lp,
            port,
            held: true,
            since_release_s: 0.0,
        })
    }

    /// The loop (the plant and the firmware's period).
    pub fn planar_loop(&self) -> &PlanarLoop<L> {
        &self.lp
    }

    /// Whether the body is held.
    pub fn held(&self) -> bool {
        self.held
    }

    /// Robot time since the body was last let go, s (0 while held): what
    /// a speed profile runs on.
    pub fn since_release_s(&self) -> f64 {
        self.since_release_s
    }

    /// One period: the host's bytes `rx` to the port, the firmware's
    /// period at the commanded speed, the port's decision over both
    /// amplifiers, then the plant over the period (frozen while held).
    pub fn period(
        &mut self,
        rx: impl IntoIterator<Item = u8>,
        speed_mps: f64,
        tx: &mut impl Tx,
    ) -> Result<Output, PlanarError> {
        self.port.receive(rx, tx);
        match self.port.take_mount() {
            Some(Mount::Hoist { toe_m }) => {
                self.lp.remount(f64::from(toe_m))?;
                self.held = true;
                self.since_release_s = 0.0;
            }
            Some(Mount::Release) => {
                self.held = false;
                self.since_release_s = 0.0;
            }
            None => {}
        }
        let r = self.lp.sense();
        let out = self
            .port
            .period(self.lp.period_mut(), &r, speed_mps as f32, DT_S as f32, tx);
        if out.armed_now && self.held {
            self.held = false;
            self.since_release_s = 0.0;
        }
        if !self.held {
            self.lp.advance(out.cmd, 0.0, &mut |_| {});
            self.since_release_s += DT_S;
        }
        Ok(out)
    }
}
