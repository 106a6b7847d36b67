//! The vertical hopper: equations of motion, transitions and energy ledger
//! (thesis ch. 2.1, as restated consistently in `shared/MODEL.md`).
//!
//! # Model
//! Generalised coordinates `z` (body height, `z = l0` at touchdown) and `p`
//! (nut displacement, positive down). With `alpha = J/r^2 + m_s`,
//! `m_t = M + m_s + m_u`, the mass matrix is `[[m_zz, -m_s], [-m_s, alpha]]`
//! where `m_zz = m_t` in flight (eq 2.12-2.14) and `M + m_s` in stance
//! (eq 2.32-2.34); its inverse (and the constrained ones) is worked out
//! once per parameter set.
//!
//! Generalised forces (friction excluded):
//! * flight: `f_z = -m_t g`, `f_p = m_s g + eta tau / r - k (delta0 + p) - c pd`
//! * stance: `Fs = k (delta0 + l0 - z + p) + c (pd - zd)`,
//!   `f_z = -(M + m_s) g + Fs`, `f_p = m_s g + eta tau / r - Fs`.
//!
//! # Transitions (all located in time by bisection inside the step)
//! * Touchdown (`z` falls to `l0`): the unsprung mass stops, `zd`, `pd`
//!   unchanged, loss `0.5 m_u zd^2` (eq 2.19-2.20).
//! * Liftoff (`z` rises to `l0`): the extension stop picks the unsprung mass
//!   up. The stop's impulse acts on `z` only, so the `p` momentum
//!   `alpha pd - m_s zd` and the total vertical momentum are both conserved.
//!   With `pd = 0` this is eq 2.39-2.40 (`zd+ = (m_t - m_u)/m_t zd-`) up to a
//!   `m_s^2 m_u / (alpha m_t (M+m_s))` ~ 2e-6 relative term the thesis drops;
//!   the loss is `0.5 (M+m_s) m_u / m_t zd^2` (MODEL.md erratum: ~1.13 J at
//!   2 m/s, not the thesis's 75 mJ).
//! * Mechanical stops at `p = 0` and `p = stroke`: perfectly inelastic; the
//!   stop's impulse acts on `p` only (internal between nut and body), so the
//!   `z` momentum `m_zz zd - m_s pd` is conserved and `pd` becomes 0. The nut
//!   then rests on the stop while the stop force pushes it in, and is released
//!   the instant that force would have to pull.
//! * Dry friction (planarizer `F_fp` in both phases, leg sliding `F_fs` in
//!   stance): Coulomb friction with stiction, static = kinetic level. While
//!   the body slides the friction force is `-F dir` with `dir` the sign of
//!   `zd`, constant between events. When `zd` reaches 0 (located in time) the
//!   force needed to hold the body still is computed: if it is within `F` the
//!   body sticks (`zd = 0`, `z` constant) until that force exceeds `F`
//!   (again located in time); otherwise it slides on in the direction of the
//!   net force. No regularisation, so no artificial creep or chatter.
//! * Standing: the body resting on the fully extended leg with the toe on the
//!   ground (`z = l0`, `zd = 0`). Entered when a liftoff happens slower than
//!   [`SETTLE_SPEED_MPS`] (a hop of under 5 um) instead of chattering
//!   between stance and flight (Zeno). Left into stance when the spring can no
//!   longer hold the body against gravity and stiction, or into flight when
//!   the actuator pulls the whole robot off the ground.
//!
//! # Energy (eqs 2.43-2.45, ground reference)
//! `E = 0.5 alpha pd^2 + 0.5 m_zz zd^2 - m_s zd pd + M g z + m_s g (z - p)
//!  + 0.5 k compression^2 (+ m_u g (z - l0) in flight)`.
//! The ledger integrates motor work `eta tau pd / r`, friction and damping
//! dissipation alongside the state (same RK4 stages) and books every impact,
//! so `E(t) - E(0) - W_motor + W_friction + W_damping + losses` is ~0.
//!
//! # Code
//! * this module: the public types, the [`Plant`], its construction and
//!   what it reports;
//! * `dynamics`: the equations of motion, their constants and the RK4 step;
//! * `step_map`: the common RK4 step precomputed as a linear map;
//! * `events`: the guards, their location in time and [`Plant::advance`];
//! * `impacts`: what happens when a guard fires (impacts, stops, stiction,
//!   the liftoff map).

mod dynamics;
mod events;
mod impacts;
mod step_map;

use crate::params::{ParamError, Params};
use dynamics::{AugState, Coef, Config};
use events::{Guard, MAX_EVENTS_PER_ADVANCE};
use step_map::StepMaps;

/// Liftoffs slower than this end in the standing mode instead of a flight
/// phase, m/s. A 0.01 m/s liftoff would rise 5 um and land 2 ms later.
pub const SETTLE_SPEED_MPS: f64 = 0.01;

/// Contact mode of the hopper.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Toe off the ground; unsprung mass rides with the body.
    Flight,
    /// Toe on the ground, leg compressed (`z < l0`).
    Stance,
    /// Toe on the ground, body resting on the fully extended leg (`z = l0`).
    Standing,
}

impl Mode {
    /// Short lower-case name, as in CSV output.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Flight => "flight",
            Mode::Stance => "stance",
            Mode::Standing => "standing",
        }
    }
}

/// Which mechanical stop, if any, holds the nut.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NutStop {
    /// The nut moves freely.
    Free,
    /// Resting on the upper stop, `p = 0` (spring least compressed).
    Top,
    /// Resting on the lower stop, `p = stroke`.
    Bottom,
}

/// Mechanical state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct State {
    /// Body height coordinate `z`, m (`l0` at touchdown).
    pub z_m: f64,
    /// Body velocity, m/s (up positive).
    pub zd_mps: f64,
    /// Nut displacement `p`, m (down positive).
    pub p_m: f64,
    /// Nut velocity relative to the body, m/s.
    pub pd_mps: f64,
}

/// Where the energy went since the start, J. All entries are >= 0 except
/// `motor_work_j`, which is the net work the motor did on the mechanism.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize))]
pub struct Ledger {
    /// Net mechanical work of the actuator on the nut, `int eta tau pd / r`.
    pub motor_work_j: f64,
    /// Dry friction dissipation (planarizer + leg sliding).
    pub friction_j: f64,
    /// Viscous spring damping dissipation.
    pub damping_j: f64,
    /// Unsprung-mass impacts at touchdown.
    pub touchdown_loss_j: f64,
    /// Unsprung-mass pick-up at liftoff.
    pub liftoff_loss_j: f64,
    /// Nut impacts on the mechanical stops.
    pub stop_impact_loss_j: f64,
    /// Kinetic energy dropped when a crawl-speed liftoff became standing.
    pub settle_loss_j: f64,
    /// `int i^2 dt` of the motor current, A^2 s: electrical, outside the
    /// mechanical balance.
    pub current_squared_a2s: f64,
    /// Heat in the motor's winding, `int i^2 R dt`, with `R` the winding's
    /// resistance at its temperature as last given by
    /// [`Plant::set_winding_resistance_ohm`] (until then the electrical
    /// model's `winding_resistance_ohm`, 0.356 ohm on the design preset;
    /// `hal_sim::run` sets the thermal model's instead): electrical,
    /// outside the mechanical balance.
    pub copper_loss_j: f64,
}

impl Ledger {
    /// Sum of all dissipation and impact losses, J.
    pub fn total_losses_j(&self) -> f64 {
        self.friction_j
            + self.damping_j
            + self.touchdown_loss_j
            + self.liftoff_loss_j
            + self.stop_impact_loss_j
            + self.settle_loss_j
    }
}

/// A transition, reported by [`Plant::advance`] as it happens.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// Toe strikes the ground.
    Touchdown {
        /// Time, s.
        t_s: f64,
        /// Body velocity at impact, m/s.
        zd_mps: f64,
        /// Energy lost by the unsprung mass, J.
        loss_j: f64,
    },
    /// Toe leaves the ground.
    Liftoff {
        /// Time, s.
        t_s: f64,
        /// Body velocity just before, m/s.
        zd_before_mps: f64,
        /// Body velocity just after the unsprung mass is picked up, m/s.
        zd_after_mps: f64,
        /// Energy lost, J.
        loss_j: f64,
    },
    /// Highest point of a flight phase.
    Apex {
        /// Time, s.
        t_s: f64,
        /// Toe height above the ground, m.
        toe_height_m: f64,
    },
    /// Deepest point of a stance phase (maximum compression, `t1` of eq 2.49).
    Bottom {
        /// Time, s.
        t_s: f64,
        /// Body coordinate, m.
        z_m: f64,
    },
    /// The nut hit a mechanical stop.
    StopImpact {
        /// Time, s.
        t_s: f64,
        /// Which stop.
        stop: NutStop,
        /// Nut velocity at impact, m/s.
        pd_mps: f64,
        /// Energy lost, J.
        loss_j: f64,
    },
    /// The body came to rest on the extended leg (standing mode).
    Standing {
        /// Time, s.
        t_s: f64,
    },
    /// Stiction started holding the body.
    Stick {
        /// Time, s.
        t_s: f64,
    },
}

/// Why the plant could not advance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlantError {
    /// The current command was NaN or infinite.
    NonFiniteCommand,
    /// The step size was not a positive finite number.
    BadStep,
    /// More than the allowed number of transitions in one call (a model loop).
    EventStorm {
        /// Simulation time, s.
        t_s: f64,
    },
    /// The state left the finite numbers.
    NonFiniteState {
        /// Simulation time, s.
        t_s: f64,
    },
}

impl core::fmt::Display for PlantError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            PlantError::NonFiniteCommand => write!(f, "current command is not finite"),
            PlantError::BadStep => write!(f, "step size must be positive and finite"),
            PlantError::EventStorm { t_s } => {
                write!(
                    f,
                    "more than {MAX_EVENTS_PER_ADVANCE} transitions in one step at t = {t_s} s"
                )
            }
            PlantError::NonFiniteState { t_s } => {
                write!(f, "state became non-finite at t = {t_s} s")
            }
        }
    }
}

/// The hopper plant.
#[derive(Clone, Debug)]
pub struct Plant {
    params: Params,
    c: Coef,
    y: AugState,
    t_s: f64,
    cfg: Config,
    ledger: Ledger,
    e0_j: f64,
    cmd_a: f64,
    /// `cmd_a` clipped to the amplifier's current limit.
    cmd_limited_a: f64,
    max_step_s: f64,
    /// RK4 steps of `max_step_s` as linear maps, for the common step.
    maps: StepMaps,
    /// No guard fires at the present state, configuration and command:
    /// checked when the last [`Plant::advance`] ended. The next call only has
    /// to re-check the guards that depend on the (new) command.
    guards_clear: bool,
    /// The winding's resistance the copper loss is booked at, ohm.
    loss_resistance_ohm: f64,
    /// The body is clamped (a hoist or a stand holds it): `z` moves only by
    /// [`Plant::move_clamped_body`], the nut moves freely against the spring.
    clamped: bool,
}

impl Plant {
    /// Default integration step, s: one RK4 step per 10 kHz control period.
    pub const DEFAULT_MAX_STEP_S: f64 = 1e-4;

    /// A hopper released at rest in flight with its toe `start_apex_m` above
    /// the ground, the nut on its upper stop (`p = 0`).
    pub fn new(params: Params, start_apex_m: f64) -> Result<Self, ParamError> {
        let state = State {
            z_m: params.leg_length_m + start_apex_m,
            zd_mps: 0.0,
            p_m: 0.0,
            pd_mps: 0.0,
        };
        Self::with_state(params, Mode::Flight, state)
    }

    /// A hopper in an arbitrary state. `p` is clamped into the stroke; in
    /// stance `z` must be below `l0` (it is clamped), standing forces
    /// `z = l0`, `zd = 0`.
    pub fn with_state(params: Params, mode: Mode, state: State) -> Result<Self, ParamError> {
        params.validate()?;
        let c = Coef::new(&params);
        let mut s = state;
        s.p_m = s.p_m.clamp(0.0, c.stroke);
        match mode {
            Mode::Stance => s.z_m = s.z_m.min(c.l0),
            Mode::Flight => s.z_m = s.z_m.max(c.l0),
            Mode::Standing => {
                s.z_m = c.l0;
                s.zd_mps = 0.0;
            }
        }
        let mut plant = Plant {
            params,
            c,
            y: AugState::at_rest_books(&s),
            t_s: 0.0,
            cfg: Config {
                mode,
                z_stuck: false,
                z_dir: if s.zd_mps < 0.0 { -1.0 } else { 1.0 },
                nut: NutStop::Free,
            },
            ledger: Ledger::default(),
            e0_j: 0.0,
            cmd_a: 0.0,
            cmd_limited_a: 0.0,
            max_step_s: Self::DEFAULT_MAX_STEP_S,
            maps: StepMaps::new(&c, Self::DEFAULT_MAX_STEP_S),
            guards_clear: false,
            loss_resistance_ohm: params.winding_resistance_ohm,
            clamped: false,
        };
        // A nut starting on a stop at rest may be seated on it.
        if s.pd_mps == 0.0 && (s.p_m <= 0.0 || s.p_m >= c.stroke) {
            plant.cfg.nut = if s.p_m <= 0.0 {
                NutStop::Top
            } else {
                NutStop::Bottom
            };
            if plant.guard(&plant.y, Guard::Release) > 0.0 {
                plant.cfg.nut = NutStop::Free;
            }
        }
        // A body starting at rest either sticks or starts sliding.
        if s.zd_mps == 0.0 && mode != Mode::Standing {
            plant.decide_stick_or_slide();
        }
        plant.e0_j = plant.energy_j();
        Ok(plant)
    }

    /// Set the largest integration step, s (default [`Self::DEFAULT_MAX_STEP_S`]).
    pub fn set_max_step(&mut self, max_step_s: f64) -> Result<(), PlantError> {
        if !(max_step_s.is_finite() && max_step_s > 0.0) {
            return Err(PlantError::BadStep);
        }
        self.max_step_s = max_step_s;
        self.maps = StepMaps::new(&self.c, max_step_s);
        Ok(())
    }

    /// The parameters this plant runs with.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Simulation time, s.
    pub fn time_s(&self) -> f64 {
        self.t_s
    }

    /// Current mechanical state.
    pub fn state(&self) -> State {
        State {
            z_m: self.y.z_m,
            zd_mps: self.y.zd_mps,
            p_m: self.y.p_m,
            pd_mps: self.y.pd_mps,
        }
    }

    /// Contact mode.
    pub fn mode(&self) -> Mode {
        self.cfg.mode
    }

    /// Which stop, if any, holds the nut.
    pub fn nut_stop(&self) -> NutStop {
        self.cfg.nut
    }

    /// Whether stiction holds the body.
    pub fn body_stuck(&self) -> bool {
        self.cfg.z_stuck
    }

    /// Whether the body is clamped ([`Self::clamp_body`]).
    pub fn body_clamped(&self) -> bool {
        self.clamped
    }

    /// Clamps the body where it is (a hoist or a test stand holds it, as the
    /// bring-up routines' mounts do): `z` stays put whatever the forces, until
    /// [`Self::release_body`]; the nut still moves under the motor and the
    /// spring, so a bring-up routine can drive it. In flight the toe hangs
    /// free (the spring compression is `delta0 + p`); on the ground the
    /// stance equations hold with `z` fixed. The clamp's force does no work
    /// (`zd = 0`); a stop impact's impulse goes into the clamp.
    pub fn clamp_body(&mut self) {
        self.clamped = true;
        self.y.zd_mps = 0.0;
        self.cfg.z_stuck = true;
        if self.cfg.mode == Mode::Standing {
            // The standing mode's own guards (sink, lift) decide between
            // stance and flight by forces; a clamp decides instead. With
            // `z = l0` locked the stance equations are the standing ones.
            self.cfg.mode = Mode::Stance;
        }
        self.guards_clear = false;
    }

    /// Lets go of a clamped body: from rest it sticks or slides as the
    /// forces say (in flight it falls).
    pub fn release_body(&mut self) {
        if !self.clamped {
            return;
        }
        self.clamped = false;
        self.decide_stick_or_slide();
        self.guards_clear = false;
    }

    /// Moves a clamped body by `dz_m` (a hoist lifting or lowering it, in
    /// steps small against a period's motion): the toe leaves the ground at
    /// rest when `z` passes `l0` going up (the unsprung mass is picked up
    /// at zero speed: no loss) and touches at rest going down. The hoist's
    /// work is outside the ledger: the starting energy moves with it, so
    /// [`Self::energy_residual_j`] still closes. Nothing happens to a body
    /// that is not clamped.
    pub fn move_clamped_body(&mut self, dz_m: f64) {
        if !self.clamped || !dz_m.is_finite() {
            return;
        }
        let before = self.energy_j();
        let l0 = self.c.l0;
        let z = self.y.z_m + dz_m;
        match self.cfg.mode {
            Mode::Flight if z < l0 => self.cfg.mode = Mode::Stance,
            Mode::Stance | Mode::Standing if z > l0 => self.cfg.mode = Mode::Flight,
            _ => {}
        }
        self.y.z_m = z;
        self.e0_j += self.energy_j() - before;
        self.guards_clear = false;
    }

    /// Energy ledger since the start.
    pub fn ledger(&self) -> &Ledger {
        &self.ledger
    }

    /// The winding's resistance from now on, ohm, for the copper loss
    /// (a thermal model's `R(T)`; the electrical model keeps its own): a
    /// non-finite or negative value is ignored.
    pub fn set_winding_resistance_ohm(&mut self, r_ohm: f64) {
        if r_ohm.is_finite() && r_ohm >= 0.0 {
            self.loss_resistance_ohm = r_ohm;
        }
    }

    /// Toe height above the ground, m (0 on the ground).
    pub fn toe_height_m(&self) -> f64 {
        match self.cfg.mode {
            Mode::Flight => self.y.z_m - self.c.l0,
            _ => 0.0,
        }
    }

    /// Spring compression, m (what the leg potentiometer and load cell see).
    pub fn spring_compression_m(&self) -> f64 {
        Self::compression(&self.c, self.cfg.stance_equations(), &self.y)
    }

    /// Spring force (stiffness plus damping), N: what the load cell measures.
    pub fn spring_force_n(&self) -> f64 {
        let y = &self.y;
        let rate = if self.cfg.stance_equations() {
            y.pd_mps - y.zd_mps
        } else {
            y.pd_mps
        };
        self.c.k * self.spring_compression_m() + self.c.c * rate
    }

    /// Motor angle `theta = p / r`, rad (eq 2.4).
    pub fn motor_angle_rad(&self) -> f64 {
        self.y.p_m / self.c.r
    }

    /// Motor speed, rad/s.
    pub fn motor_speed_rad_s(&self) -> f64 {
        self.motor_speed_at_rad_s(self.y.pd_mps)
    }

    /// Motor speed at nut speed `pd_mps`, rad/s (`theta_dot = pd / r`,
    /// eq 2.4). Monotonic in `pd_mps`, so the fastest motor speed of a run is
    /// this of its fastest nut speed, one division instead of one per period.
    pub fn motor_speed_at_rad_s(&self, pd_mps: f64) -> f64 {
        pd_mps / self.c.r
    }

    /// Current the amplifier drives for the last command at the present
    /// speed, A.
    pub fn motor_current_a(&self) -> f64 {
        self.c
            .motor_current_from_pd(self.cmd_limited_a, self.y.pd_mps)
    }

    /// Motor torque for the last command at the present speed, N m.
    pub fn motor_torque_nm(&self) -> f64 {
        self.c.kt * self.motor_current_a()
    }

    /// Total mechanical energy (eqs 2.43-2.44 in MODEL.md's coordinates), J.
    pub fn energy_j(&self) -> f64 {
        Self::energy(&self.c, self.cfg.mode, &self.y)
    }

    /// Energy at the start, J.
    pub fn initial_energy_j(&self) -> f64 {
        self.e0_j
    }

    /// Ledger residual `E - E0 - W_motor + losses`, J: ~0 when the books close.
    pub fn energy_residual_j(&self) -> f64 {
        self.energy_j() - self.e0_j - self.ledger.motor_work_j + self.ledger.total_losses_j()
    }
}
