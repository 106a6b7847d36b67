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
    g: f64,
    k: f64,
    c: f64,
    preload: f64,
    l0: f64,
    f_flight: f64,
    f_stance: f64,
    stroke: f64,
    kt: f64,
    supply: f64,
    i_limit: f64,
    // Derived once, so that the derivative evaluation (four per RK4 step)
    // has no divisions: products with reciprocals instead of quotients
    // (results differ from the quotients by float rounding only).
    /// `k_t / r`: back-EMF torque per unit nut speed.
    kt_over_r: f64,
    /// `eta / r`.
    eta_over_r: f64,
    /// `1 / R`.
    inv_resistance: f64,
    /// `m_s g`.
    nut_weight: f64,
    /// `-(M + m_s) g`.
    neg_weight_stance: f64,
    /// `-m_t g`.
    neg_weight_flight: f64,
    /// Inverse mass matrices (both coordinates free), flight and stance.
    inv_flight: InvMass,
    inv_stance: InvMass,
    /// `1 / alpha`.
    inv_alpha: f64,
    /// Winding resistance `R`, ohm.
    resistance: f64,
    /// `r / k_t`: nut speed per volt of back-EMF.
    r_over_kt: f64,
}

/// The accelerations of one configuration as affine functions of the drive
/// force `eta tau / r` and the spring force `fs` (what [`Plant::accel`]
/// computes, regrouped): `zdd = z0 + z_drive drive + z_spring fs`, and the
/// same for `pdd`.
#[derive(Clone, Copy, Debug)]
struct Linear {
    z0: f64,
    z_drive: f64,
    z_spring: f64,
    p0: f64,
    p_drive: f64,
    p_spring: f64,
    /// `d z0 / d friction` and `d p0 / d friction`: only [`StepMap`] uses
    /// them (it takes the friction force as an input, so one map serves both
    /// sliding directions); the derivative has it folded into `z0`, `p0`.
    z_friction: f64,
    p_friction: f64,
}

impl Linear {
    /// For the configuration (stance equations, body free, nut free), with
    /// friction force `friction` (`level * z_dir`) on a sliding body.
    #[inline(always)]
    fn new<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(
        c: &Coef,
        friction: f64,
    ) -> Self {
        let inv = if STANCE { &c.inv_stance } else { &c.inv_flight };
        // Generalised forces: f_z = fz0 + kz fs, f_p = nut_weight + drive - fs.
        let weight = if STANCE {
            c.neg_weight_stance
        } else {
            c.neg_weight_flight
        };
        let fz0 = if Z_FREE { weight - friction } else { weight };
        let kz = if STANCE { 1.0 } else { 0.0 };
        // The inverse of the constrained mass matrix: (zdd, pdd) =
        // [[mzz, mzp], [mpz, mpp]] (f_z, f_p).
        let (mzz, mzp, mpz, mpp) = match (Z_FREE, P_FREE) {
            (true, true) => (inv.zz, inv.zp, inv.zp, inv.pp),
            (false, true) => (0.0, 0.0, 0.0, c.inv_alpha),
            (true, false) => (inv.inv_m_zz, 0.0, 0.0, 0.0),
            (false, false) => (0.0, 0.0, 0.0, 0.0),
        };
        Linear {
            z0: mzz * fz0 + mzp * c.nut_weight,
            z_drive: mzp,
            z_spring: mzz * kz - mzp,
            p0: mpz * fz0 + mpp * c.nut_weight,
            p_drive: mpp,
            p_spring: mpz * kz - mpp,
            // f_z = weight - friction while the body slides; a held body
            // has mzz = mpz = 0.
            z_friction: -mzz,
            p_friction: -mpz,
        }
    }
}

/// A 4x4 matrix over the mechanical state `x = (z, zd, p, pd)`.
type Mat4 = [[f64; 4]; 4];

fn mat4_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut o = [[0.0; 4]; 4];
    for (oi, ai) in o.iter_mut().zip(a.iter()) {
        for (j, oij) in oi.iter_mut().enumerate() {
            *oij = ai.iter().zip(b.iter()).map(|(aik, bk)| aik * bk[j]).sum();
        }
    }
    o
}

/// `sum_k coef_k m_k` elementwise.
fn mat4_comb(terms: &[(f64, &Mat4)]) -> Mat4 {
    let mut o = [[0.0; 4]; 4];
    for &(coef, m) in terms {
        for (oi, mi) in o.iter_mut().zip(m.iter()) {
            for (oij, mij) in oi.iter_mut().zip(mi.iter()) {
                *oij += coef * mij;
            }
        }
    }
    o
}

/// `m b` for a 4x3 `b`.
fn mat4_mul_43(m: &Mat4, b: &[[f64; 3]; 4]) -> [[f64; 3]; 4] {
    let mut o = [[0.0; 3]; 4];
    for (oi, mi) in o.iter_mut().zip(m.iter()) {
        for (j, oij) in oi.iter_mut().enumerate() {
            *oij = mi.iter().zip(b.iter()).map(|(mik, bk)| mik * bk[j]).sum();
        }
    }
    o
}

/// One RK4 step of a fixed length `h` in one configuration, as the linear
/// map it is there. Without spring damping and with the motor current not
/// limited by the supply, the dynamics are affine, `x' = A x + B u` with
/// `u = (drive, friction, 1)` constant over the step, and RK4 applied to
/// them is exactly `x1 = x0 + M x0 + G u` with `M = P + P^2/2 + P^3/6 +
/// P^4/24`, `P = h A`, and `G = h (I + P/2 + P^2/6 + P^3/24) B`: a few
/// independent dot products instead of four dependent derivative stages.
/// The ledger rows come out of the same increments: with the drive and the
/// friction constant, RK4's `int drive pd` is `drive dp` and `int friction
/// zd` is `friction dz` (the same weighted stage sums as `dp`, `dz`).
#[derive(Clone, Copy, Debug)]
struct StepMap {
    /// `M` (the state's increment per unit state).
    m: Mat4,
    /// `G` (the increment per unit input).
    g: [[f64; 3]; 4],
    /// `pd` at RK4's second to fourth stage minus `pd0`, as rows over `x0`
    /// and `u`: the nut speeds the derivative evaluates the motor current
    /// at, to check that the supply limit stays out of the step.
    stage_x: [[f64; 4]; 3],
    stage_u: [[f64; 3]; 3],
}

impl StepMap {
    /// For the configuration (stance equations, body free, nut free); only
    /// valid without spring damping (`c = 0`), which the caller checks.
    fn new<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(c: &Coef, h: f64) -> Self {
        let lin = Linear::new::<STANCE, Z_FREE, P_FREE>(c, 0.0);
        // fs = k compression = fs0 + fs_z z + k p (Plant::compression).
        let fs0 = c.k * (c.preload + if STANCE { c.l0 } else { 0.0 });
        let fs_z = if STANCE { -c.k } else { 0.0 };
        let one = |free: bool| if free { 1.0 } else { 0.0 };
        let a: Mat4 = [
            [0.0, one(Z_FREE), 0.0, 0.0],
            [lin.z_spring * fs_z, 0.0, lin.z_spring * c.k, 0.0],
            [0.0, 0.0, 0.0, one(P_FREE)],
            [lin.p_spring * fs_z, 0.0, lin.p_spring * c.k, 0.0],
        ];
        let b = [
            [0.0; 3],
            [lin.z_drive, lin.z_friction, lin.z0 + lin.z_spring * fs0],
            [0.0; 3],
            [lin.p_drive, lin.p_friction, lin.p0 + lin.p_spring * fs0],
        ];
        Self::from_affine(&a, &b, h)
    }

    /// The RK4 step of length `h` for `x' = A x + B u`. Out of line and not
    /// generic: it runs once per configuration and plant, and one copy of
    /// it is enough (on the M4, where `f64` is software, eight inlined
    /// copies took 20 KB of flash).
    #[inline(never)]
    fn from_affine(a: &Mat4, b: &[[f64; 3]; 4], h: f64) -> Self {
        let id: Mat4 = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let p1 = mat4_comb(&[(h, a)]);
        let p2 = mat4_mul(&p1, &p1);
        let p3 = mat4_mul(&p2, &p1);
        let p4 = mat4_mul(&p3, &p1);
        let m = mat4_comb(&[(1.0, &p1), (0.5, &p2), (1.0 / 6.0, &p3), (1.0 / 24.0, &p4)]);
        let n = mat4_comb(&[(h, &id), (0.5 * h, &p1), (h / 6.0, &p2), (h / 24.0, &p3)]);
        // Stage arguments minus y0 (k_i the RK4 stages, b = B u):
        // s2 = h/2 k1 = P/2 x0 + h/2 b,
        // s3 = h/2 k2 = (P/2 + P^2/4) x0 + h (I/2 + P/4) b,
        // s4 = h k3 = (P + P^2/2 + P^3/4) x0 + h (I + P/2 + P^2/4) b.
        let s2 = mat4_comb(&[(0.5, &p1)]);
        let s3 = mat4_comb(&[(0.5, &p1), (0.25, &p2)]);
        let s4 = mat4_comb(&[(1.0, &p1), (0.5, &p2), (0.25, &p3)]);
        let t2 = mat4_comb(&[(0.5 * h, &id)]);
        let t3 = mat4_comb(&[(0.5 * h, &id), (0.25 * h, &p1)]);
        let t4 = mat4_comb(&[(h, &id), (0.5 * h, &p1), (0.25 * h, &p2)]);
        let pd_row = |t: &Mat4| mat4_mul_43(t, b)[3];
        StepMap {
            m,
            g: mat4_mul_43(&n, b),
            stage_x: [s2[3], s3[3], s4[3]],
            stage_u: [pd_row(&t2), pd_row(&t3), pd_row(&t4)],
        }
    }

    /// The maps of all eight configurations, indexed by [`Self::index`].
    fn all(c: &Coef, h: f64) -> [StepMap; 8] {
        [
            Self::new::<false, false, false>(c, h),
            Self::new::<false, false, true>(c, h),
            Self::new::<false, true, false>(c, h),
            Self::new::<false, true, true>(c, h),
            Self::new::<true, false, false>(c, h),
            Self::new::<true, false, true>(c, h),
            Self::new::<true, true, false>(c, h),
            Self::new::<true, true, true>(c, h),
        ]
    }

    /// The index of the configuration's map in [`Self::all`].
    const fn index(stance: bool, z_free: bool, p_free: bool) -> usize {
        (stance as usize) << 2 | (z_free as usize) << 1 | p_free as usize
    }

    /// One output of the map, `mx . x + mu . (u, 1)`. Grouped in pairs:
    /// independent products, short dependency chains. Always inlined (as
    /// a closure it was sometimes left out of line in the closed loop).
    #[inline(always)]
    fn row(mx: &[f64; 4], mu: &[f64; 3], x: &[f64; 4], u: &[f64; 2]) -> f64 {
        ((mx[0] * x[0] + mx[1] * x[1]) + (mx[2] * x[2] + mx[3] * x[3]))
            + ((mu[0] * u[0] + mu[1] * u[1]) + mu[2])
    }
}

/// [`StepMap`]s for one step length.
#[derive(Clone, Copy, Debug)]
struct StepMaps {
    /// The step they are for, s; NaN where they do not apply (spring
    /// damping: the damping work is quadratic in the state).
    h_s: f64,
    maps: [StepMap; 8],
}

impl StepMaps {
    fn new(c: &Coef, h_s: f64) -> Self {
        StepMaps {
            h_s: if c.c == 0.0 { h_s } else { f64::NAN },
            maps: StepMap::all(c, h_s),
        }
    }
}

/// Inverse of the 2x2 mass matrix `[[m_zz, -m_s], [-m_s, alpha]]`:
/// `zdd = zz f_z + zp f_p`, `pdd = zp f_z + pp f_p`, and `1 / m_zz` for the
/// nut held on a stop.
#[derive(Clone, Copy, Debug)]
struct InvMass {
    zz: f64,
    zp: f64,
    pp: f64,
    inv_m_zz: f64,
}

impl InvMass {
    fn new(m_zz: f64, alpha: f64, m_nut: f64) -> Self {
        let det = m_zz * alpha - m_nut * m_nut;
        InvMass {
            zz: alpha / det,
            zp: m_nut / det,
            pp: m_zz / det,
            inv_m_zz: 1.0 / m_zz,
        }
    }
}

impl Coef {
    fn new(p: &Params) -> Self {
        let r = p.screw_m_per_rad();
        let alpha = p.reflected_inertia_kg();
        let m_body_nut = p.body_mass_kg + p.nut_mass_kg;
        let m_total = p.body_mass_kg + p.nut_mass_kg + p.unsprung_mass_kg;
        let g = p.gravity_mps2;
        Coef {
            kt_over_r: p.torque_constant_nm_per_a / r,
            eta_over_r: p.efficiency / r,
            inv_resistance: 1.0 / p.winding_resistance_ohm,
            nut_weight: p.nut_mass_kg * g,
            neg_weight_stance: -m_body_nut * g,
            neg_weight_flight: -m_total * g,
            inv_flight: InvMass::new(m_total, alpha, p.nut_mass_kg),
            inv_stance: InvMass::new(m_body_nut, alpha, p.nut_mass_kg),
            inv_alpha: 1.0 / alpha,
            resistance: p.winding_resistance_ohm,
            r_over_kt: r / p.torque_constant_nm_per_a,
            m_body_nut,
            m_total,
            m_nut: p.nut_mass_kg,
            m_u: p.unsprung_mass_kg,
            m_body: p.body_mass_kg,
            alpha,
            r,
            g,
            k: p.spring_stiffness_n_per_m,
            c: p.spring_damping_ns_per_m,
            preload: p.spring_preload_m,
            l0: p.leg_length_m,
            f_flight: p.planarizer_friction_n,
            f_stance: p.planarizer_friction_n + p.leg_friction_n,
            stroke: p.stroke_m,
            kt: p.torque_constant_nm_per_a,
            supply: p.supply_voltage_v,
            i_limit: p.current_limit_a,
        }
    }

    /// Motor current the amplifier delivers, A, for a command already
    /// clipped to the amplifier's current limit: clipped further to what the
    /// supply voltage can drive against the back-EMF at nut speed `pd_mps`
    /// (`|R i + k_e omega| <= V`, `omega = pd / r`), the motor's torque-speed
    /// limit.
    #[inline(always)]
    fn motor_current_from_pd(&self, cmd_limited_a: f64, pd_mps: f64) -> f64 {
        let back_emf = self.kt_over_r * pd_mps;
        let hi = (self.supply - back_emf) * self.inv_resistance;
        let lo = (-self.supply - back_emf) * self.inv_resistance;
        // `clamp(lo, hi)` (lo < hi: R > 0, V > 0), as a branch rather than
        // min/max: the supply limit is rarely reached, so the processor
        // predicts the command and does not wait for the nut speed.
        if cmd_limited_a > hi || cmd_limited_a < lo {
            supply_limited(cmd_limited_a, lo, hi)
        } else {
            cmd_limited_a
        }
    }
}

/// The current the supply voltage allows when it limits the command, A.
#[cold]
#[inline(never)]
fn supply_limited(cmd_a: f64, lo: f64, hi: f64) -> f64 {
    cmd_a.max(lo).min(hi)
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

/// Generalised forces (friction excluded).
#[derive(Clone, Copy)]
struct Forces {
    f_z: f64,
    f_p: f64,
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

impl Guard {
    /// Whether the guard is a force balance, and so changes with the motor
    /// command (the others are functions of the state alone).
    fn depends_on_command(self) -> bool {
        matches!(
            self,
            Guard::Unstick | Guard::Release | Guard::Sink | Guard::Lift
        )
    }
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
    /// `cmd_a` clipped to the amplifier's current limit.
    cmd_limited_a: f64,
    max_step_s: f64,
    /// RK4 steps of `max_step_s` as linear maps, for the common step.
    maps: StepMaps,
    /// No guard fires at the present state, configuration and command:
    /// checked when the last [`Plant::advance`] ended. The next call only has
    /// to re-check the guards that depend on the (new) command.
    guards_clear: bool,
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
            cmd_limited_a: 0.0,
            max_step_s: Self::DEFAULT_MAX_STEP_S,
            maps: StepMaps::new(&c, Self::DEFAULT_MAX_STEP_S),
            guards_clear: false,
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
        self.motor_speed_at_rad_s(self.y[3])
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
        self.c.motor_current_from_pd(self.cmd_limited_a, self.y[3])
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

    #[inline(always)]
    fn forces(&self, cfg: &Config, y: &Y) -> Forces {
        let c = &self.c;
        let (zd, pd) = (y[1], y[3]);
        let torque_nm = c.kt * c.motor_current_from_pd(self.cmd_limited_a, pd);
        let drive = c.eta_over_r * torque_nm;
        let stance = cfg.stance_equations();
        let rate = if stance { pd - zd } else { pd };
        let fs = c.k * Self::compression(c, stance, y) + c.c * rate;
        let f_z = if stance {
            c.neg_weight_stance + fs
        } else {
            c.neg_weight_flight
        };
        Forces {
            f_z,
            f_p: c.nut_weight + drive - fs,
        }
    }

    fn inv_mass(&self, cfg: &Config) -> &InvMass {
        if cfg.stance_equations() {
            &self.c.inv_stance
        } else {
            &self.c.inv_flight
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
    #[inline(always)]
    fn accel(&self, cfg: &Config, f: &Forces) -> (f64, f64) {
        let inv = self.inv_mass(cfg);
        let z_free = !cfg.z_locked();
        let p_free = cfg.nut == NutStop::Free;
        let f_z = if z_free {
            f.f_z - self.friction_level(cfg) * cfg.z_dir
        } else {
            f.f_z
        };
        match (z_free, p_free) {
            (true, true) => (inv.zz * f_z + inv.zp * f.f_p, inv.zp * f_z + inv.pp * f.f_p),
            (false, true) => (0.0, f.f_p * self.c.inv_alpha),
            (true, false) => (f_z * inv.inv_m_zz, 0.0),
            (false, false) => (0.0, 0.0),
        }
    }

    /// Force on `z` needed to hold the body still (up positive), N.
    fn z_hold_force(&self, cfg: &Config, y: &Y) -> f64 {
        let f = self.forces(cfg, y);
        let pdd = if cfg.nut == NutStop::Free {
            f.f_p * self.c.inv_alpha
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

    /// One RK4 step of length `h` from `y0` in the present configuration,
    /// part of the advance to `t_end`: through the precomputed [`StepMap`]
    /// when it applies, else [`Self::rk4`]. `SPECIALISED`: with the map
    /// picked per configuration at compile time (constant addresses, the
    /// rows that are zero there skipped), eight inlined copies; else one
    /// copy with the map indexed at run time. [`Self::advance`]'s fast path
    /// takes the specialised form with the `specialised-step` feature (the
    /// simulator's: 10 ns of the 40 a period took); the loop, and builds
    /// without it (the QEMU image, where `f64` is software and the eight
    /// copies would take 10 KB of flash), the generic one.
    #[inline(always)]
    fn rk4_step<const SPECIALISED: bool>(&self, y0: &Y, h: f64, t_end: f64) -> Y {
        match self.rk4_linear::<SPECIALISED>(y0, h, t_end) {
            Some(y1) => y1,
            None => self.rk4(y0, h),
        }
    }

    /// [`Self::rk4`] as the configuration's [`StepMap`], or `None` where
    /// that does not apply: the maps are for another step (or for none: spring
    /// damping), or the supply limits the motor current at one of RK4's
    /// stages (the dynamics are not affine there).
    #[inline(always)]
    fn rk4_linear<const SPECIALISED: bool>(&self, y0: &Y, h: f64, t_end: f64) -> Option<Y> {
        // `h` is `t_end - t_s`, or `max_step_s`: a period of the maps' step
        // may differ from it by the clock's rounding, up to an ulp of
        // `t_end`. Integrating the maps' step instead is an error of that
        // rounding's size. (A NaN `h_s` fails the test.)
        let for_this_step = libm::fabs(h - self.maps.h_s) <= f64::EPSILON * libm::fabs(t_end);
        if !for_this_step {
            return None;
        }
        let cfg = &self.cfg;
        let (stance, z_free, p_free) = (
            cfg.stance_equations(),
            !cfg.z_locked(),
            cfg.nut == NutStop::Free,
        );
        if !SPECIALISED {
            // All rows: those of a held coordinate are zero.
            let map = &self.maps.maps[StepMap::index(stance, z_free, p_free)];
            return self.rk4_linear_in::<true, true>(y0, map);
        }
        let m = &self.maps.maps;
        match (stance, z_free, p_free) {
            (false, false, false) => self.rk4_linear_in::<false, false>(y0, &m[0]),
            (false, false, true) => self.rk4_linear_in::<false, true>(y0, &m[1]),
            (false, true, false) => self.rk4_linear_in::<true, false>(y0, &m[2]),
            (false, true, true) => self.rk4_linear_in::<true, true>(y0, &m[3]),
            (true, false, false) => self.rk4_linear_in::<false, false>(y0, &m[4]),
            (true, false, true) => self.rk4_linear_in::<false, true>(y0, &m[5]),
            (true, true, false) => self.rk4_linear_in::<true, false>(y0, &m[6]),
            (true, true, true) => self.rk4_linear_in::<true, true>(y0, &m[7]),
        }
    }

    /// The step through `map`, the present configuration's; `Z_FREE`,
    /// `P_FREE` false skip the rows that are zero with the body or the nut
    /// held.
    #[inline(always)]
    fn rk4_linear_in<const Z_FREE: bool, const P_FREE: bool>(
        &self,
        y0: &Y,
        map: &StepMap,
    ) -> Option<Y> {
        let c = &self.c;
        let cfg = &self.cfg;
        let cmd = self.cmd_limited_a;
        // The motor current is the command (Coef::motor_current_from_pd)
        // while `|R cmd + k_e pd| <= V`, i.e. for `pd` in `[pd_lo, pd_hi]`.
        // The stage speeds below differ from RK4's by rounding; the margin
        // (1e-9 of the no-load speed) covers that.
        let margin = 1e-9 * c.supply * c.r_over_kt;
        let pd_hi = (c.supply - c.resistance * cmd) * c.r_over_kt - margin;
        let pd_lo = (-c.supply - c.resistance * cmd) * c.r_over_kt + margin;
        // As Self::deriv_in computes them.
        let drive = c.eta_over_r * (c.kt * cmd);
        let level = if cfg.stance_equations() {
            c.f_stance
        } else {
            c.f_flight
        };
        let friction = level * cfg.z_dir;
        let (z, zd, p, pd) = (y0[0], y0[1], y0[2], y0[3]);
        let x = [z, zd, p, pd];
        let u = [drive, friction];
        let (pd2, pd3, pd4) = if P_FREE {
            (
                pd + StepMap::row(&map.stage_x[0], &map.stage_u[0], &x, &u),
                pd + StepMap::row(&map.stage_x[1], &map.stage_u[1], &x, &u),
                pd + StepMap::row(&map.stage_x[2], &map.stage_u[2], &x, &u),
            )
        } else {
            (pd, pd, pd)
        };
        let within = |v: f64| v >= pd_lo && v <= pd_hi;
        // `&`, not `&&`: all four are at hand, no need for four branches.
        if !(within(pd) & within(pd2) & within(pd3) & within(pd4)) {
            return None;
        }
        let (dz, dzd) = if Z_FREE {
            (
                StepMap::row(&map.m[0], &map.g[0], &x, &u),
                StepMap::row(&map.m[1], &map.g[1], &x, &u),
            )
        } else {
            (0.0, 0.0)
        };
        let (dp, dpd) = if P_FREE {
            (
                StepMap::row(&map.m[2], &map.g[2], &x, &u),
                StepMap::row(&map.m[3], &map.g[3], &x, &u),
            )
        } else {
            (0.0, 0.0)
        };
        // Ledger: motor work `drive dp`, friction work `friction dz` (zero
        // for a held body: dz = 0); no damping work (c = 0).
        Some([
            z + dz,
            zd + dzd,
            p + dp,
            pd + dpd,
            y0[4] + drive * dp,
            y0[5] + friction * dz,
            y0[6],
        ])
    }

    /// One RK4 step of length `h` from `y0` in the present configuration.
    fn rk4(&self, y0: &Y, h: f64) -> Y {
        let cfg = &self.cfg;
        // The configuration is fixed over a step: pick the derivative
        // specialised for it once, not in every evaluation.
        match (
            cfg.stance_equations(),
            !cfg.z_locked(),
            cfg.nut == NutStop::Free,
        ) {
            (false, false, false) => self.rk4_in::<false, false, false>(y0, h),
            (false, false, true) => self.rk4_in::<false, false, true>(y0, h),
            (false, true, false) => self.rk4_in::<false, true, false>(y0, h),
            (false, true, true) => self.rk4_in::<false, true, true>(y0, h),
            (true, false, false) => self.rk4_in::<true, false, false>(y0, h),
            (true, false, true) => self.rk4_in::<true, false, true>(y0, h),
            (true, true, false) => self.rk4_in::<true, true, false>(y0, h),
            (true, true, true) => self.rk4_in::<true, true, true>(y0, h),
        }
    }

    #[inline(always)]
    fn rk4_in<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(
        &self,
        y0: &Y,
        h: f64,
    ) -> Y {
        let c = &self.c;
        let level = if STANCE { c.f_stance } else { c.f_flight };
        // Friction on z while sliding is `-level * z_dir`.
        let friction = level * self.cfg.z_dir;
        let lin = Linear::new::<STANCE, Z_FREE, P_FREE>(c, friction);
        let d = |y: &Y| self.deriv_in::<STANCE, Z_FREE, P_FREE>(y, friction, &lin);
        let add = |a: &Y, k: &Y, s: f64| -> Y {
            let mut o = *a;
            for (oi, ki) in o.iter_mut().zip(k.iter()) {
                *oi += s * ki;
            }
            o
        };
        let k1 = d(y0);
        let k2 = d(&add(y0, &k1, 0.5 * h));
        let k3 = d(&add(y0, &k2, 0.5 * h));
        let k4 = d(&add(y0, &k3, h));
        let mut out = *y0;
        for (i, o) in out.iter_mut().enumerate() {
            *o += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
        out
    }

    /// Time derivative of the augmented state: [`Self::forces`] and
    /// [`Self::accel`] for one configuration (stance equations, body free,
    /// nut free), with the friction force `friction` (`level * z_dir`) and
    /// the accelerations' affine form `lin` worked out by the caller.
    #[inline(always)]
    fn deriv_in<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(
        &self,
        y: &Y,
        friction: f64,
        lin: &Linear,
    ) -> Y {
        let c = &self.c;
        let (zd, pd) = (y[1], y[3]);
        let torque_nm = c.kt * c.motor_current_from_pd(self.cmd_limited_a, pd);
        let drive = c.eta_over_r * torque_nm;
        let rate = if STANCE { pd - zd } else { pd };
        let fs = c.k * Self::compression(c, STANCE, y) + c.c * rate;
        // The drive terms do not depend on the state (unless the supply
        // limits the current), so only `fs` is on the dependency chain
        // from one RK4 stage to the next.
        let zdd = (lin.z0 + lin.z_drive * drive) + lin.z_spring * fs;
        let pdd = (lin.p0 + lin.p_drive * drive) + lin.p_spring * fs;
        let zd = if Z_FREE { zd } else { 0.0 };
        let pd = if P_FREE { pd } else { 0.0 };
        let friction_w = if Z_FREE { friction * zd } else { 0.0 };
        [zd, zdd, pd, pdd, drive * pd, friction_w, c.c * rate * rate]
    }

    /// Guards that apply in the present configuration, in priority order
    /// (the reference [`Self::first_firing`] is checked against).
    #[cfg(test)]
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

    #[inline(always)]
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

    /// The first guard, in priority order, that fires at `y`.
    #[cfg(test)]
    fn first_firing_reference(&self, y: &Y) -> Option<Guard> {
        let (gs, n) = self.active_guards();
        gs.iter().take(n).copied().find(|&g| self.guard(y, g) > 0.0)
    }

    /// The first guard that fires at `y`: the guards that apply in the
    /// present configuration, in priority order (nut, contact, body
    /// velocity), evaluated one by one until one fires.
    #[inline]
    fn first_firing(&self, y: &Y) -> Option<Guard> {
        self.first_firing_in::<false>(y)
    }

    /// [`Self::first_firing`] when the guards that do not depend on the
    /// motor command are known not to fire at `y`: only the force guards
    /// (stiction, nut release, standing) are evaluated, in the same order.
    fn first_firing_force_guards(&self, y: &Y) -> Option<Guard> {
        self.first_firing_in::<true>(y)
    }

    #[inline(always)]
    fn first_firing_in<const FORCE_ONLY: bool>(&self, y: &Y) -> Option<Guard> {
        let cfg = &self.cfg;
        let fires = |g: Guard| (!FORCE_ONLY || g.depends_on_command()) && self.guard(y, g) > 0.0;
        if cfg.nut == NutStop::Free {
            if fires(Guard::StopTop) {
                return Some(Guard::StopTop);
            }
            if fires(Guard::StopBottom) {
                return Some(Guard::StopBottom);
            }
        } else if fires(Guard::Release) {
            return Some(Guard::Release);
        }
        match cfg.mode {
            Mode::Flight => {
                if fires(Guard::Touchdown) {
                    return Some(Guard::Touchdown);
                }
            }
            Mode::Stance => {
                if fires(Guard::Liftoff) {
                    return Some(Guard::Liftoff);
                }
            }
            Mode::Standing => {
                if fires(Guard::Sink) {
                    return Some(Guard::Sink);
                }
                if fires(Guard::Lift) {
                    return Some(Guard::Lift);
                }
                return None;
            }
        }
        let g = if cfg.z_stuck {
            Guard::Unstick
        } else {
            Guard::ZeroVelocity
        };
        fires(g).then_some(g)
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
        self.cmd_limited_a = cmd_a.clamp(-self.c.i_limit, self.c.i_limit);
        let t_end = self.t_s + dt_s;
        // What is known about the guards at the present state: the
        // state-only guards were clear when the last call ended (only the
        // force guards need a look under the new command), or, after a step
        // that fired nothing, all of them are (nothing to evaluate).
        let state_guards_clear = self.guards_clear;
        self.guards_clear = false;
        // The common case, one integration step with no transition in it:
        // what the loop below does for it, without its bookkeeping. Anything
        // else (a guard firing, a non-finite state, a longer period) leaves
        // the plant untouched for the loop to redo from the start. The step
        // is the loop's, `min(remaining, max_step_s)`: a period of exactly
        // `max_step_s` often comes out a rounding above it (`t_end - t_s`),
        // and the loop then drops the sub-`TIME_TOL_S` remainder.
        if state_guards_clear && self.first_firing_force_guards(&self.y).is_none() {
            let remaining = t_end - self.t_s;
            let h = remaining.min(self.max_step_s);
            // One step, and what is left after it within the tolerance (a
            // period longer than max_step_s needs the loop: decided before
            // integrating, not after).
            if remaining > TIME_TOL_S && t_end - (self.t_s + h) <= TIME_TOL_S {
                let y1 = self.rk4_step::<{ cfg!(feature = "specialised-step") }>(&self.y, h, t_end);
                if self.first_firing(&y1).is_none() && y1.iter().all(|v| v.is_finite()) {
                    self.y = y1;
                    self.t_s = t_end;
                    self.sync_ledger();
                    self.guards_clear = true;
                    return Ok(());
                }
            }
        }
        self.advance_loop(t_end, state_guards_clear, on_event)
    }

    /// [`Self::advance`]'s general case: integration steps up to `t_end`,
    /// with every transition located and fired.
    fn advance_loop(
        &mut self,
        t_end: f64,
        mut state_guards_clear: bool,
        on_event: &mut impl FnMut(Event),
    ) -> Result<(), PlantError> {
        let mut events = 0u32;
        let mut all_clear = false;
        loop {
            let firing = if all_clear {
                None
            } else if state_guards_clear {
                self.first_firing_force_guards(&self.y)
            } else {
                self.first_firing(&self.y)
            };
            if let Some(g) = firing {
                events += 1;
                if events > MAX_EVENTS_PER_ADVANCE {
                    return Err(PlantError::EventStorm { t_s: self.t_s });
                }
                self.fire(g, on_event);
                state_guards_clear = false;
                all_clear = false;
                continue;
            }
            let remaining = t_end - self.t_s;
            if remaining <= TIME_TOL_S {
                self.t_s = t_end;
                break;
            }
            let h = remaining.min(self.max_step_s);
            let y0 = self.y;
            let y1 = self.rk4_step::<false>(&y0, h, t_end);
            if self.first_firing(&y1).is_none() {
                self.y = y1;
                self.t_s += h;
                all_clear = true;
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
                state_guards_clear = false;
                all_clear = false;
            }
            self.sync_ledger();
            if !self.y.iter().all(|v| v.is_finite()) {
                return Err(PlantError::NonFiniteState { t_s: self.t_s });
            }
        }
        self.sync_ledger();
        // The loop only ends after finding no guard firing at the final state.
        self.guards_clear = true;
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand_distr::{Distribution, StandardUniform};
    use rand_xoshiro::rand_core::SeedableRng;
    use rand_xoshiro::Xoshiro256PlusPlus;

    /// The precomputed RK4 step maps agree with RK4 itself to rounding in
    /// every configuration, on random states and commands; where the supply
    /// limits the current somewhere in the step, or the spring is damped,
    /// they decline.
    #[test]
    fn step_map_matches_rk4() {
        let params = Params::design();
        let mut plant = match Plant::new(params, 0.1) {
            Ok(p) => p,
            Err(e) => panic!("{e}"),
        };
        let h = Plant::DEFAULT_MAX_STEP_S;
        let c = plant.c;
        // The sensor noise's generator, seeded: reproducible.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(0x9e37_79b9_7f4a_7c15);
        let mut uniform = |lo: f64, hi: f64| {
            let u: f64 = StandardUniform.sample(&mut rng);
            lo + (hi - lo) * u
        };
        // Nut speeds and currents past the supply and amplifier limits.
        let pd_max = 1.2 * c.supply * c.r_over_kt;
        let (mut mapped, mut declined) = (0, 0);
        for mode in [Mode::Flight, Mode::Stance, Mode::Standing] {
            for z_stuck in [false, true] {
                for z_dir in [-1.0, 1.0] {
                    for nut in [NutStop::Free, NutStop::Top, NutStop::Bottom] {
                        plant.cfg = Config {
                            mode,
                            z_stuck,
                            z_dir,
                            nut,
                        };
                        for _ in 0..300 {
                            let cmd = uniform(-1.2, 1.2) * c.i_limit;
                            plant.cmd_a = cmd;
                            plant.cmd_limited_a = cmd.clamp(-c.i_limit, c.i_limit);
                            let y0 = [
                                c.l0 + uniform(-0.05, 0.05),
                                uniform(-2.0, 2.0),
                                uniform(0.0, c.stroke),
                                uniform(-pd_max, pd_max),
                                uniform(-5.0, 5.0),
                                uniform(0.0, 5.0),
                                uniform(0.0, 5.0),
                            ];
                            let want = plant.rk4(&y0, h);
                            let Some(got) = plant.rk4_linear::<true>(&y0, h, 1.0) else {
                                assert!(plant.rk4_linear::<false>(&y0, h, 1.0).is_none());
                                declined += 1;
                                continue;
                            };
                            mapped += 1;
                            // The generic form: the same up to the sign of
                            // a zero increment.
                            assert_eq!(plant.rk4_linear::<false>(&y0, h, 1.0), Some(got));
                            for i in 0..7 {
                                let scale = libm::fabs(want[i]).max(libm::fabs(y0[i]));
                                assert!(
                                    libm::fabs(got[i] - want[i]) <= 1e-12 * scale,
                                    "{:?} y0 {y0:?} cmd {cmd}: [{i}] {} vs {}",
                                    plant.cfg,
                                    got[i],
                                    want[i]
                                );
                            }
                            // Outside the maps' step (beyond the clock's
                            // rounding) they do not apply.
                            assert!(plant.rk4_linear::<true>(&y0, 0.5 * h, 1.0).is_none());
                        }
                    }
                }
            }
        }
        assert!(mapped > 5_000 && declined > 1_000, "{mapped} {declined}");

        let damped = Params {
            spring_damping_ns_per_m: 10.0,
            ..params
        };
        let plant = match Plant::new(damped, 0.1) {
            Ok(p) => p,
            Err(e) => panic!("{e}"),
        };
        assert!(plant.rk4_linear::<true>(&plant.y, h, 1.0).is_none());
        assert!(plant.rk4_linear::<false>(&plant.y, h, 1.0).is_none());
    }

    /// The unrolled guard search agrees with the table-driven one in every
    /// configuration, for states on both sides of every guard.
    #[test]
    fn first_firing_matches_the_reference() {
        let params = Params::design();
        let mut plant = match Plant::new(params, 0.1) {
            Ok(p) => p,
            Err(e) => panic!("{e}"),
        };
        let l0 = params.leg_length_m;
        let stroke = params.stroke_m;
        let mut checked = 0;
        for mode in [Mode::Flight, Mode::Stance, Mode::Standing] {
            for z_stuck in [false, true] {
                for z_dir in [-1.0, 1.0] {
                    for nut in [NutStop::Free, NutStop::Top, NutStop::Bottom] {
                        for cmd in [-40.0, -3.0, 0.0, 3.0, 40.0] {
                            for z in [l0 - 0.03, l0 - 1e-9, l0, l0 + 1e-9, l0 + 0.05] {
                                for p in [-1e-6, 0.0, 0.01, stroke, stroke + 1e-6] {
                                    for zd in [-1.0, 0.0, 0.5] {
                                        for pd in [-0.3, 0.0, 0.3] {
                                            plant.cfg = Config {
                                                mode,
                                                z_stuck,
                                                z_dir,
                                                nut,
                                            };
                                            plant.cmd_a = cmd;
                                            plant.cmd_limited_a =
                                                cmd.clamp(-plant.c.i_limit, plant.c.i_limit);
                                            let y = [z, zd, p, pd, 0.0, 0.0, 0.0];
                                            let want = plant.first_firing_reference(&y);
                                            assert_eq!(plant.first_firing(&y), want);
                                            // With the state guards clear, the
                                            // force-guard search finds the same.
                                            let state_clear = plant
                                                .active_guards()
                                                .0
                                                .iter()
                                                .take(plant.active_guards().1)
                                                .all(|&g| {
                                                    g.depends_on_command()
                                                        || plant.guard(&y, g) <= 0.0
                                                });
                                            if state_clear {
                                                assert_eq!(
                                                    plant.first_firing_force_guards(&y),
                                                    want
                                                );
                                            }
                                            checked += 1;
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(checked > 10_000);
    }
}
