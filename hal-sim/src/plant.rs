//! The vertical hopper: equations of motion, transitions and energy ledger
//! (thesis ch. 2.1, as restated consistently in `shared/MODEL.md`).
//!
//! # Model
//! Generalised coordinates `z` (body height, `z = l0` at touchdown) and `p`
//! (nut displacement, positive down). With `alpha = J/r^2 + m_s`,
//! `m_t = M + m_s + m_u`, the mass matrix is `[[m_zz, -m_s], [-m_s, alpha]]`
//! where `m_zz = m_t` in flight (eq 2.12-2.14) and `M + m_s` in stance
//! (eq 2.32-2.34); it is solved as a 2x2 system every evaluation.
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

use crate::params::{ParamError, Params};

/// Liftoffs slower than this end in the standing mode instead of a flight
/// phase, m/s. A 0.01 m/s liftoff would rise 5 um and land 2 ms later.
pub const SETTLE_SPEED_MPS: f64 = 0.01;

/// Events are located in time to this tolerance, s.
const TIME_TOL_S: f64 = 1e-12;

/// At most this many transitions within one [`Plant::advance`] call; more
/// means the model is stuck in a loop, reported as [`PlantError::EventStorm`].
const MAX_EVENTS_PER_ADVANCE: u32 = 256;

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
#[cfg_attr(feature = "std", derive(serde::Serialize))]
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

/// Constants derived once from [`Params`].
#[derive(Clone, Copy, Debug)]
struct Coef {
    m_body_nut: f64,
    m_total: f64,
    m_nut: f64,
    m_u: f64,
    m_body: f64,
    alpha: f64,
    r: f64,
    eta: f64,
    g: f64,
    k: f64,
    c: f64,
    preload: f64,
    l0: f64,
    f_flight: f64,
    f_stance: f64,
    stroke: f64,
    kt: f64,
    resistance: f64,
    supply: f64,
    i_limit: f64,
}

impl Coef {
    fn new(p: &Params) -> Self {
        let r = p.screw_m_per_rad();
        Coef {
            m_body_nut: p.body_mass_kg + p.nut_mass_kg,
            m_total: p.body_mass_kg + p.nut_mass_kg + p.unsprung_mass_kg,
            m_nut: p.nut_mass_kg,
            m_u: p.unsprung_mass_kg,
            m_body: p.body_mass_kg,
            alpha: p.rotor_inertia_kg_m2 / (r * r) + p.nut_mass_kg,
            r,
            eta: p.efficiency,
            g: p.gravity_mps2,
            k: p.spring_stiffness_n_per_m,
            c: p.spring_damping_ns_per_m,
            preload: p.spring_preload_m,
            l0: p.leg_length_m,
            f_flight: p.planarizer_friction_n,
            f_stance: p.planarizer_friction_n + p.leg_friction_n,
            stroke: p.stroke_m,
            kt: p.torque_constant_nm_per_a,
            resistance: p.winding_resistance_ohm,
            supply: p.supply_voltage_v,
            i_limit: p.current_limit_a,
        }
    }

    /// Motor current the amplifier delivers for a command, A: the command is
    /// clipped to the amplifier's current limit and to what the supply voltage
    /// can drive against the back-EMF (`|R i + k_e omega| <= V`), the motor's
    /// torque-speed limit.
    fn motor_current_a(&self, cmd_a: f64, omega_rad_s: f64) -> f64 {
        let back_emf = self.kt * omega_rad_s;
        let hi = (self.supply - back_emf) / self.resistance;
        let lo = (-self.supply - back_emf) / self.resistance;
        cmd_a.clamp(-self.i_limit, self.i_limit).clamp(lo, hi)
    }
}

/// Which equations hold: the dynamics formulation and the constraints.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Config {
    mode: Mode,
    z_stuck: bool,
    /// Sign of `zd` while sliding (+1 / -1); friction is `-F * z_dir`.
    z_dir: f64,
    nut: NutStop,
}

impl Config {
    fn z_locked(&self) -> bool {
        self.z_stuck || self.mode == Mode::Standing
    }
    fn stance_equations(&self) -> bool {
        self.mode != Mode::Flight
    }
}

/// Augmented state for integration: z, zd, p, pd, motor work, friction work,
/// damping work.
type Y = [f64; 7];

/// Generalised forces (friction excluded) and the applied torque.
#[derive(Clone, Copy)]
struct Forces {
    f_z: f64,
    f_p: f64,
    damping_w: f64,
    torque_nm: f64,
}

/// Guards: an event fires when its guard becomes positive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Guard {
    StopTop,
    StopBottom,
    Touchdown,
    Liftoff,
    ZeroVelocity,
    Unstick,
    Release,
    Sink,
    Lift,
}

/// The hopper plant.
#[derive(Clone, Debug)]
pub struct Plant {
    params: Params,
    c: Coef,
    y: Y,
    t_s: f64,
    cfg: Config,
    ledger: Ledger,
    e0_j: f64,
    cmd_a: f64,
    max_step_s: f64,
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
            y: [s.z_m, s.zd_mps, s.p_m, s.pd_mps, 0.0, 0.0, 0.0],
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
            max_step_s: Self::DEFAULT_MAX_STEP_S,
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
            z_m: self.y[0],
            zd_mps: self.y[1],
            p_m: self.y[2],
            pd_mps: self.y[3],
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

    /// Energy ledger since the start.
    pub fn ledger(&self) -> &Ledger {
        &self.ledger
    }

    /// Toe height above the ground, m (0 on the ground).
    pub fn toe_height_m(&self) -> f64 {
        match self.cfg.mode {
            Mode::Flight => self.y[0] - self.c.l0,
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
            y[3] - y[1]
        } else {
            y[3]
        };
        self.c.k * self.spring_compression_m() + self.c.c * rate
    }

    /// Motor angle `theta = p / r`, rad (eq 2.4).
    pub fn motor_angle_rad(&self) -> f64 {
        self.y[2] / self.c.r
    }

    /// Motor speed, rad/s.
    pub fn motor_speed_rad_s(&self) -> f64 {
        self.y[3] / self.c.r
    }

    /// Current the amplifier drives for the last command at the present
    /// speed, A.
    pub fn motor_current_a(&self) -> f64 {
        self.c.motor_current_a(self.cmd_a, self.motor_speed_rad_s())
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

    fn compression(c: &Coef, stance: bool, y: &Y) -> f64 {
        if stance {
            c.preload + c.l0 - y[0] + y[2]
        } else {
            c.preload + y[2]
        }
    }

    fn kinetic(c: &Coef, m_zz: f64, zd: f64, pd: f64) -> f64 {
        0.5 * c.alpha * pd * pd + 0.5 * m_zz * zd * zd - c.m_nut * zd * pd
    }

    fn energy(c: &Coef, mode: Mode, y: &Y) -> f64 {
        let (z, zd, p, pd) = (y[0], y[1], y[2], y[3]);
        let stance = mode != Mode::Flight;
        let m_zz = if stance { c.m_body_nut } else { c.m_total };
        let x = Self::compression(c, stance, y);
        let mut e = Self::kinetic(c, m_zz, zd, pd)
            + c.m_body * c.g * z
            + c.m_nut * c.g * (z - p)
            + 0.5 * c.k * x * x;
        if !stance {
            e += c.m_u * c.g * (z - c.l0);
        }
        e
    }

    fn forces(&self, cfg: &Config, y: &Y) -> Forces {
        let c = &self.c;
        let (zd, pd) = (y[1], y[3]);
        let torque_nm = c.kt * c.motor_current_a(self.cmd_a, pd / c.r);
        let drive = c.eta * torque_nm / c.r;
        let stance = cfg.stance_equations();
        let rate = if stance { pd - zd } else { pd };
        let fs = c.k * Self::compression(c, stance, y) + c.c * rate;
        let f_z = if stance {
            -c.m_body_nut * c.g + fs
        } else {
            -c.m_total * c.g
        };
        Forces {
            f_z,
            f_p: c.m_nut * c.g + drive - fs,
            damping_w: c.c * rate * rate,
            torque_nm,
        }
    }

    fn m_zz(&self, cfg: &Config) -> f64 {
        if cfg.stance_equations() {
            self.c.m_body_nut
        } else {
            self.c.m_total
        }
    }

    fn friction_level(&self, cfg: &Config) -> f64 {
        if cfg.stance_equations() {
            self.c.f_stance
        } else {
            self.c.f_flight
        }
    }

    /// Accelerations `(zdd, pdd)` under the configuration's constraints.
    fn accel(&self, cfg: &Config, f: &Forces) -> (f64, f64) {
        let c = &self.c;
        let m_zz = self.m_zz(cfg);
        let z_free = !cfg.z_locked();
        let p_free = cfg.nut == NutStop::Free;
        let f_z = if z_free {
            f.f_z - self.friction_level(cfg) * cfg.z_dir
        } else {
            f.f_z
        };
        match (z_free, p_free) {
            (true, true) => {
                let det = m_zz * c.alpha - c.m_nut * c.m_nut;
                (
                    (c.alpha * f_z + c.m_nut * f.f_p) / det,
                    (c.m_nut * f_z + m_zz * f.f_p) / det,
                )
            }
            (false, true) => (0.0, f.f_p / c.alpha),
            (true, false) => (f_z / m_zz, 0.0),
            (false, false) => (0.0, 0.0),
        }
    }

    /// Force on `z` needed to hold the body still (up positive), N.
    fn z_hold_force(&self, cfg: &Config, y: &Y) -> f64 {
        let f = self.forces(cfg, y);
        let pdd = if cfg.nut == NutStop::Free {
            f.f_p / self.c.alpha
        } else {
            0.0
        };
        -f.f_z - self.c.m_nut * pdd
    }

    /// Force on `p` needed to hold the nut still (down positive), N.
    fn p_hold_force(&self, cfg: &Config, y: &Y) -> f64 {
        let f = self.forces(cfg, y);
        let mut held = *cfg;
        held.nut = NutStop::Top; // any non-free value: solve with pdd = 0
        let (zdd, _) = self.accel(&held, &f);
        -f.f_p - self.c.m_nut * zdd
    }

    fn deriv(&self, cfg: &Config, y: &Y) -> Y {
        let f = self.forces(cfg, y);
        let (zdd, pdd) = self.accel(cfg, &f);
        let z_free = !cfg.z_locked();
        let zd = if z_free { y[1] } else { 0.0 };
        let pd = if cfg.nut == NutStop::Free { y[3] } else { 0.0 };
        let friction_w = if z_free {
            self.friction_level(cfg) * cfg.z_dir * zd
        } else {
            0.0
        };
        [
            zd,
            zdd,
            pd,
            pdd,
            self.c.eta * f.torque_nm / self.c.r * pd,
            friction_w,
            f.damping_w,
        ]
    }

    fn rk4(&self, y0: &Y, h: f64) -> Y {
        let cfg = &self.cfg;
        let add = |a: &Y, k: &Y, s: f64| -> Y {
            let mut o = *a;
            for (oi, ki) in o.iter_mut().zip(k.iter()) {
                *oi += s * ki;
            }
            o
        };
        let k1 = self.deriv(cfg, y0);
        let k2 = self.deriv(cfg, &add(y0, &k1, 0.5 * h));
        let k3 = self.deriv(cfg, &add(y0, &k2, 0.5 * h));
        let k4 = self.deriv(cfg, &add(y0, &k3, h));
        let mut out = *y0;
        for (i, o) in out.iter_mut().enumerate() {
            *o += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        out
    }

    /// Guards that apply in the present configuration, in priority order.
    fn active_guards(&self) -> ([Guard; 5], usize) {
        let cfg = &self.cfg;
        let mut g = [Guard::StopTop; 5];
        let mut n = 0;
        let mut push = |x: Guard| {
            if n < g.len() {
                g[n] = x;
                n += 1;
            }
        };
        if cfg.nut == NutStop::Free {
            push(Guard::StopTop);
            push(Guard::StopBottom);
        } else {
            push(Guard::Release);
        }
        match cfg.mode {
            Mode::Flight => push(Guard::Touchdown),
            Mode::Stance => push(Guard::Liftoff),
            Mode::Standing => {
                push(Guard::Sink);
                push(Guard::Lift);
            }
        }
        if cfg.mode != Mode::Standing {
            push(if cfg.z_stuck {
                Guard::Unstick
            } else {
                Guard::ZeroVelocity
            });
        }
        (g, n)
    }

    fn guard(&self, y: &Y, g: Guard) -> f64 {
        let c = &self.c;
        let cfg = &self.cfg;
        match g {
            Guard::StopTop => -y[2],
            Guard::StopBottom => y[2] - c.stroke,
            Guard::Touchdown => c.l0 - y[0],
            Guard::Liftoff => y[0] - c.l0,
            Guard::ZeroVelocity => -cfg.z_dir * y[1],
            Guard::Unstick => libm::fabs(self.z_hold_force(cfg, y)) - self.friction_level(cfg),
            Guard::Release => {
                let r = self.p_hold_force(cfg, y);
                if cfg.nut == NutStop::Bottom {
                    r
                } else {
                    -r
                }
            }
            Guard::Sink => {
                // Stance equations with z held: upward force the body needs.
                self.z_hold_force(cfg, y) - c.f_stance
            }
            Guard::Lift => {
                let flight = Config {
                    mode: Mode::Flight,
                    ..*cfg
                };
                -self.z_hold_force(&flight, y) - c.f_flight
            }
        }
    }

    fn first_firing(&self, y: &Y) -> Option<Guard> {
        let (gs, n) = self.active_guards();
        gs.iter().take(n).copied().find(|&g| self.guard(y, g) > 0.0)
    }

    /// Advance by `dt_s` with the amplifier current command `cmd_a` held
    /// (zero-order hold, like a DAC), reporting transitions to `on_event`.
    pub fn advance(
        &mut self,
        dt_s: f64,
        cmd_a: f64,
        on_event: &mut impl FnMut(Event),
    ) -> Result<(), PlantError> {
        if !cmd_a.is_finite() {
            return Err(PlantError::NonFiniteCommand);
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(PlantError::BadStep);
        }
        self.cmd_a = cmd_a;
        let t_end = self.t_s + dt_s;
        let mut events = 0u32;
        loop {
            if let Some(g) = self.first_firing(&self.y) {
                events += 1;
                if events > MAX_EVENTS_PER_ADVANCE {
                    return Err(PlantError::EventStorm { t_s: self.t_s });
                }
                self.fire(g, on_event);
                continue;
            }
            let remaining = t_end - self.t_s;
            if remaining <= TIME_TOL_S {
                self.t_s = t_end;
                break;
            }
            let h = remaining.min(self.max_step_s);
            let y0 = self.y;
            let y1 = self.rk4(&y0, h);
            if self.first_firing(&y1).is_none() {
                self.y = y1;
                self.t_s += h;
            } else {
                // Locate the earliest crossing: bisection on the step length
                // of a single RK4 step from y0 (smooth in h).
                let (mut lo, mut hi, mut y_hi) = (0.0, h, y1);
                while hi - lo > TIME_TOL_S {
                    let mid = 0.5 * (lo + hi);
                    let ym = self.rk4(&y0, mid);
                    if self.first_firing(&ym).is_some() {
                        hi = mid;
                        y_hi = ym;
                    } else {
                        lo = mid;
                    }
                }
                self.y = y_hi;
                self.t_s += hi;
            }
            self.sync_ledger();
            if !self.y.iter().all(|v| v.is_finite()) {
                return Err(PlantError::NonFiniteState { t_s: self.t_s });
            }
        }
        self.sync_ledger();
        Ok(())
    }

    fn sync_ledger(&mut self) {
        self.ledger.motor_work_j = self.y[4];
        self.ledger.friction_j = self.y[5];
        self.ledger.damping_j = self.y[6];
    }

    /// After `zd` reached 0 (or at the start): stick if stiction can hold the
    /// body, else slide in the direction of the net force.
    fn decide_stick_or_slide(&mut self) {
        self.y[1] = 0.0;
        let hold = self.z_hold_force(&self.cfg, &self.y);
        if libm::fabs(hold) <= self.friction_level(&self.cfg) {
            self.cfg.z_stuck = true;
        } else {
            self.cfg.z_stuck = false;
            // The body moves against the force that would be needed to hold it.
            self.cfg.z_dir = if hold > 0.0 { -1.0 } else { 1.0 };
        }
    }

    fn fire(&mut self, g: Guard, on_event: &mut impl FnMut(Event)) {
        let t_s = self.t_s;
        let c = self.c;
        match g {
            Guard::StopTop | Guard::StopBottom => {
                let (stop, p) = if g == Guard::StopTop {
                    (NutStop::Top, 0.0)
                } else {
                    (NutStop::Bottom, c.stroke)
                };
                let pd = self.y[3];
                let e_before = self.energy_j();
                self.y[2] = p;
                self.y[3] = 0.0;
                // The stop's impulse acts on p only: m_zz zd - m_s pd is
                // conserved. A body held by stiction or standing is knocked
                // loose by it (stiction cannot absorb an impulse).
                let m_zz = self.m_zz(&self.cfg);
                self.y[1] -= c.m_nut * pd / m_zz;
                self.cfg.nut = stop;
                let zd = self.y[1];
                let loss = e_before - self.energy_j();
                self.ledger.stop_impact_loss_j += loss;
                on_event(Event::StopImpact {
                    t_s,
                    stop,
                    pd_mps: pd,
                    loss_j: loss,
                });
                if zd != 0.0 {
                    self.cfg.z_stuck = false;
                    self.cfg.z_dir = if zd > 0.0 { 1.0 } else { -1.0 };
                    if self.cfg.mode == Mode::Standing {
                        self.cfg.mode = Mode::Stance;
                        if zd > 0.0 {
                            self.lift_off(on_event);
                        }
                    }
                }
            }
            Guard::Touchdown => {
                let zd = self.y[1];
                let loss = 0.5 * c.m_u * zd * zd;
                self.y[0] = c.l0;
                self.cfg.mode = Mode::Stance;
                self.ledger.touchdown_loss_j += loss;
                on_event(Event::Touchdown {
                    t_s,
                    zd_mps: zd,
                    loss_j: loss,
                });
            }
            Guard::Liftoff => {
                self.y[0] = c.l0;
                self.lift_off(on_event);
            }
            Guard::ZeroVelocity => {
                let rising = self.cfg.z_dir > 0.0;
                self.decide_stick_or_slide();
                if self.cfg.z_stuck {
                    on_event(Event::Stick { t_s });
                }
                match (self.cfg.mode, rising) {
                    (Mode::Flight, true) => on_event(Event::Apex {
                        t_s,
                        toe_height_m: self.y[0] - c.l0,
                    }),
                    (Mode::Stance, false) => on_event(Event::Bottom {
                        t_s,
                        z_m: self.y[0],
                    }),
                    _ => {}
                }
            }
            Guard::Unstick => self.decide_stick_or_slide(),
            Guard::Release => self.cfg.nut = NutStop::Free,
            Guard::Sink => {
                self.cfg.mode = Mode::Stance;
                self.cfg.z_stuck = false;
                self.cfg.z_dir = -1.0;
            }
            Guard::Lift => {
                // The actuator pulls the whole robot off the ground from
                // rest: the unsprung mass is picked up at zero speed.
                self.cfg.mode = Mode::Flight;
                self.cfg.z_stuck = false;
                self.cfg.z_dir = 1.0;
                on_event(Event::Liftoff {
                    t_s,
                    zd_before_mps: 0.0,
                    zd_after_mps: 0.0,
                    loss_j: 0.0,
                });
            }
        }
        self.sync_ledger();
    }

    /// Liftoff impact map (from stance at `z = l0`): picks up the unsprung
    /// mass conserving vertical and `p` momentum; a crawl-speed liftoff
    /// becomes standing.
    fn lift_off(&mut self, on_event: &mut impl FnMut(Event)) {
        let c = self.c;
        let t_s = self.t_s;
        let (zd, pd) = (self.y[1], self.y[3]);
        let e_before = self.energy_j();
        if zd < SETTLE_SPEED_MPS {
            self.y[1] = 0.0;
            self.cfg.mode = Mode::Standing;
            self.cfg.z_stuck = false;
            let loss = e_before - self.energy_j();
            self.ledger.settle_loss_j += loss;
            on_event(Event::Standing { t_s });
            return;
        }
        let a = c.alpha * pd - c.m_nut * zd; // p momentum
        let b = c.m_body_nut * zd - c.m_nut * pd; // vertical momentum
        let gamma = c.alpha * c.m_total - c.m_nut * c.m_nut;
        let (zd_after, pd_after) = if self.cfg.nut == NutStop::Free {
            (
                (c.alpha * b + c.m_nut * a) / gamma,
                (c.m_nut * b + c.m_total * a) / gamma,
            )
        } else {
            // Nut held by a stop (pd = 0): eq 2.40 exactly.
            (b / c.m_total, 0.0)
        };
        self.y[1] = zd_after;
        self.y[3] = pd_after;
        self.cfg.mode = Mode::Flight;
        self.cfg.z_dir = 1.0;
        self.cfg.z_stuck = false;
        let loss = e_before - self.energy_j();
        self.ledger.liftoff_loss_j += loss;
        on_event(Event::Liftoff {
            t_s,
            zd_before_mps: zd,
            zd_after_mps: zd_after,
            loss_j: loss,
        });
    }
}
