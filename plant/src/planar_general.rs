//! The general planar runner of thesis Appendix A: a trunk whose
//! centre of mass is offset from the hip, a leg whose sprung mass sits
//! along it, an unsprung point mass at the toe, a leg spring with its
//! damper, a hip spring with its damper, and dry friction on the
//! planarizer, the leg and the hip.
//!
//! Appendix A derives the equations by Lagrange (eq A.1) from its kinetic
//! and potential energies (eqs A.2-A.4 in flight, A.14-A.17 in stance), but
//! the printed result does not hold together: A.2's trunk velocity puts the
//! trunk's centre at `z - d_z cos phi - d_x sin phi` while A.4's potential
//! puts it at `z + d_x sin phi + d_z cos phi`; A.4 drops `g` from the toe's
//! weight; A.13's `A_2` repeats `A_1`'s `cos(phi + alpha)` where A.6 has
//! the sine, and its `a_3` reads `m_l d^2 m_u l_0^2` for `m_l d^2 + m_u
//! l_0^2`; B_1 gives the trunk's and the leg's weights opposite signs where
//! A.18 gives them the same, and divides only its friction term by the
//! mass; the text puts the sprung mass's centre at `b` from the toe, the
//! equations at `d` from the hip. So this module takes the model (the
//! bodies, the springs, the losses) from Appendix A and derives the
//! equations itself, as `M(q) q'' = Q(q, q')` built from each body's
//! position and its Jacobian:
//!
//! - **Coordinates.** Flight: the hip `(x, z)`, the body pitch `phi` and the
//!   leg angle `theta` (from the vertical, toe ahead positive), the leg held
//!   at its stop `l_0` ("mechanical stops keep the stretched length of leg
//!   constant"). Stance: the toe pinned at `(x_f, 0)` (no slip), the leg
//!   length `l` from the toe to the hip, `theta` and `phi` (A.14's polar
//!   form).
//! - **Bodies.** The trunk, `m_t` and `J_t` about its centre, which is at
//!   `(d_x, d_z)` from the hip in the body's frame (forward, up); the leg's
//!   sprung mass `m_l` and `J_l` about its centre, at `d` from the hip
//!   along the leg; the unsprung mass `m_u`, a point at the toe.
//! - **Springs.** The leg spring `k_l (l_0 - l)` (and its damper `c_l`) in
//!   stance, with no preload: the leg's length at the stop is the spring's
//!   rest length. The hip spring: Appendix A's linear spring `k_h` on an
//!   arm `r_h` with its actuator at `p_h` is the torsional spring `k_h
//!   r_h^2` about the rest angle `(p_h - p_h0) / r_h`; that is how it is
//!   given here (`hip_stiffness_nm_per_rad`, `hip_rest_angle_rad`), with its
//!   damper `c_h r_h^2`.
//! - **Friction.** Dry friction on the hip's forward and vertical motion
//!   (the planarizer, A.5-A.6's `F_fr,x`, `F_fr,z`), on the leg's sliding in
//!   stance (A.18's `F_fr`), and at the hip joint on the leg's rate relative
//!   to the body (A.7-A.8's `T_fr`: a joint's friction acts on the relative
//!   rate, not on `phi'` and `theta'` apart as printed). Each is the
//!   Coulomb force regularised linearly below [`DRY_FRICTION_SPEED`], so
//!   that the fixed-step integrator meets no discontinuity; the
//!   regularisation is a stiff viscous law near rest, not stiction.
//! - **Transitions.** Touchdown, when the toe reaches the ground moving
//!   down: a plastic impact stops the toe (both components; along the leg
//!   the spring gives way, so the unsprung mass alone loses its speed along
//!   it): the stance velocities are those that keep the generalized
//!   momentum of every stance-admissible motion (the ground's impulse
//!   does no work on them). Liftoff, when the leg returns to its stop: the
//!   stop picks the unsprung mass up, a plastic impact that keeps the
//!   flight's generalized momentum, so linear and angular momentum are
//!   conserved and, moving straight up at `v`, `0.5 (m - m_u) m_u / m v^2`
//!   goes (eq 2.40's pick-up, as in the vertical model). Both report what
//!   they took.
//!
//! With the offsets, `d`, `m_u` and the friction zero this is the section
//! 2.2 runner ([`crate::planar::PlanarRunner`]); with the motion vertical
//! (angles and forward speed zero, the trunk's centre above the hip: the
//! hip then never turns) it is the vertical hopper with the nut locked,
//! its touchdown loss `0.5 m_u z'^2` and its liftoff pick-up (MODEL.md).
//! The tests hold it to both.

use crate::planar::{next_apex_hybrid, step_hybrid, ApexState, Hybrid, PlanarError, PlanarEvent};
use crate::planar::{PlanarParams, PlanarState, Stabiliser};

/// Below this speed (m/s, or rad/s at the hip) dry friction grows linearly
/// from zero to its Coulomb value.
pub const DRY_FRICTION_SPEED: f64 = 1e-3;

/// The range an Appendix A term is accepted in.
#[derive(Clone, Copy, Debug)]
pub struct TermLimit {
    /// The [`GeneralParams`] field.
    pub field: &'static str,
    /// Least value.
    pub min: f64,
    /// Greatest value.
    pub max: f64,
    /// Unit.
    pub unit: &'static str,
    /// Reads it.
    pub get: fn(&GeneralParams) -> f64,
}

/// The ranges of the Appendix A terms (the leg's centre must also lie on
/// the leg). The dampers' and dry frictions' upper bounds keep the fixed
/// 0.1 ms RK4 step stable for masses like Table 2.2's (16 kg, an
/// effective hip inertia of 0.18 kg m^2): the regularised friction is a
/// viscous `F / DRY_FRICTION_SPEED` near rest, and RK4 needs `h c / m`
/// below 2.8; at the bounds it is below 0.7.
pub const TERM_LIMITS: [TermLimit; 11] = [
    TermLimit {
        field: "trunk_offset_x_m",
        min: -1.0,
        max: 1.0,
        unit: "m",
        get: |p| p.trunk_offset_x_m,
    },
    TermLimit {
        field: "trunk_offset_z_m",
        min: -1.0,
        max: 1.0,
        unit: "m",
        get: |p| p.trunk_offset_z_m,
    },
    TermLimit {
        field: "leg_com_from_hip_m",
        min: 0.0,
        max: 1.0,
        unit: "m",
        get: |p| p.leg_com_from_hip_m,
    },
    TermLimit {
        field: "toe_mass_kg",
        min: 0.0,
        max: 10.0,
        unit: "kg",
        get: |p| p.toe_mass_kg,
    },
    TermLimit {
        field: "leg_damping_ns_per_m",
        min: 0.0,
        max: 10_000.0,
        unit: "N s/m",
        get: |p| p.leg_damping_ns_per_m,
    },
    TermLimit {
        field: "hip_stiffness_nm_per_rad",
        min: 0.0,
        max: 1e6,
        unit: "N m/rad",
        get: |p| p.hip_stiffness_nm_per_rad,
    },
    TermLimit {
        field: "hip_rest_angle_rad",
        min: -1.0,
        max: 1.0,
        unit: "rad",
        get: |p| p.hip_rest_angle_rad,
    },
    TermLimit {
        field: "hip_damping_nms_per_rad",
        min: 0.0,
        max: 100.0,
        unit: "N m s/rad",
        get: |p| p.hip_damping_nms_per_rad,
    },
    TermLimit {
        field: "planarizer_friction_n",
        min: 0.0,
        max: 100.0,
        unit: "N",
        get: |p| p.planarizer_friction_n,
    },
    TermLimit {
        field: "leg_friction_n",
        min: 0.0,
        max: 100.0,
        unit: "N",
        get: |p| p.leg_friction_n,
    },
    TermLimit {
        field: "hip_friction_nm",
        min: 0.0,
        max: 1.0,
        unit: "N m",
        get: |p| p.hip_friction_nm,
    },
];

/// The general planar runner's parameters (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneralParams {
    /// Trunk mass `m_t`, kg.
    pub trunk_mass_kg: f64,
    /// Trunk pitch inertia about its centre `J_t`, kg m^2.
    pub trunk_inertia_kg_m2: f64,
    /// The trunk's centre ahead of the hip in the body's frame `d_x`, m.
    pub trunk_offset_x_m: f64,
    /// The trunk's centre above the hip in the body's frame `d_z`, m.
    pub trunk_offset_z_m: f64,
    /// The leg's sprung mass `m_l`, kg.
    pub leg_mass_kg: f64,
    /// The leg's inertia about its centre `J_l`, kg m^2.
    pub leg_inertia_kg_m2: f64,
    /// The leg's centre from the hip along the leg `d`, m.
    pub leg_com_from_hip_m: f64,
    /// The unsprung mass at the toe `m_u`, kg.
    pub toe_mass_kg: f64,
    /// Hip to toe with the leg on its stop `l_0` (the spring's rest), m.
    pub leg_length_m: f64,
    /// Leg spring `k_l`, N/m.
    pub leg_stiffness_n_per_m: f64,
    /// Leg damper `c_l`, N s/m.
    pub leg_damping_ns_per_m: f64,
    /// Hip spring `k_h r_h^2`, N m/rad.
    pub hip_stiffness_nm_per_rad: f64,
    /// The hip spring's rest angle of the leg to the body `(p_h - p_h0) /
    /// r_h`, rad.
    pub hip_rest_angle_rad: f64,
    /// Hip damper `c_h r_h^2`, N m s/rad.
    pub hip_damping_nms_per_rad: f64,
    /// Planarizer dry friction on the hip's forward and on its vertical
    /// motion, N.
    pub planarizer_friction_n: f64,
    /// Dry friction on the leg's sliding in stance, N.
    pub leg_friction_n: f64,
    /// Dry friction torque at the hip joint, N m.
    pub hip_friction_nm: f64,
    /// Gravity, m/s^2.
    pub gravity_mps2: f64,
}

impl GeneralParams {
    /// The section 2.2 runner as a general one: no offsets, the leg's
    /// centre at the hip, no toe mass, no dampers, no friction.
    pub fn from_section_2_2(p: &PlanarParams) -> Self {
        GeneralParams {
            trunk_mass_kg: p.body_mass_kg,
            trunk_inertia_kg_m2: p.body_inertia_kg_m2,
            trunk_offset_x_m: 0.0,
            trunk_offset_z_m: 0.0,
            leg_mass_kg: p.leg_mass_kg,
            leg_inertia_kg_m2: p.leg_inertia_kg_m2,
            leg_com_from_hip_m: 0.0,
            toe_mass_kg: 0.0,
            leg_length_m: p.leg_rest_length_m,
            leg_stiffness_n_per_m: p.leg_stiffness_n_per_m,
            leg_damping_ns_per_m: 0.0,
            hip_stiffness_nm_per_rad: p.hip_stiffness_nm_per_rad,
            hip_rest_angle_rad: 0.0,
            hip_damping_nms_per_rad: 0.0,
            planarizer_friction_n: 0.0,
            leg_friction_n: 0.0,
            hip_friction_nm: 0.0,
            gravity_mps2: p.gravity_mps2,
        }
    }

    /// Total mass, kg.
    pub fn total_mass_kg(&self) -> f64 {
        self.trunk_mass_kg + self.leg_mass_kg + self.toe_mass_kg
    }

    /// The runner with its hip actuated: Table 2.2's masses, the passive
    /// design's hip spring replaced by a motor (no spring), and the losses
    /// Appendix A lists that the machine would have: a 0.3 kg toe, the
    /// leg's centre 0.1 m below the hip, a 20 N s/m leg damper, 5 N of dry
    /// friction on the planarizer and on the leg, 0.2 N m at the hip.
    pub fn actuated_table_2_2() -> Self {
        let mut p = Self::from_section_2_2(&PlanarParams::table_2_2());
        p.hip_stiffness_nm_per_rad = 0.0;
        p.toe_mass_kg = 0.3;
        p.leg_com_from_hip_m = 0.1;
        p.leg_damping_ns_per_m = 20.0;
        p.planarizer_friction_n = 5.0;
        p.leg_friction_n = 5.0;
        p.hip_friction_nm = 0.2;
        p
    }

    /// Masses, inertias, the leg and its spring and gravity positive; the
    /// other terms within [`TERM_LIMITS`]; the leg's centre on the leg.
    /// Else the first field that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        for (name, v) in [
            ("trunk_mass_kg", self.trunk_mass_kg),
            ("trunk_inertia_kg_m2", self.trunk_inertia_kg_m2),
            ("leg_mass_kg", self.leg_mass_kg),
            ("leg_inertia_kg_m2", self.leg_inertia_kg_m2),
            ("leg_length_m", self.leg_length_m),
            ("leg_stiffness_n_per_m", self.leg_stiffness_n_per_m),
            ("gravity_mps2", self.gravity_mps2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlanarError::NotPositive(name));
            }
        }
        for l in &TERM_LIMITS {
            let v = (l.get)(self);
            if !(v.is_finite() && v >= l.min && v <= l.max) {
                return Err(PlanarError::OutOfRange(l.field));
            }
        }
        let d = self.leg_com_from_hip_m;
        if !(d.is_finite() && (0.0..=self.leg_length_m).contains(&d)) {
            return Err(PlanarError::OutOfRange("leg_com_from_hip_m"));
        }
        Ok(())
    }
}

/// Where the general runner is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum GeneralPhase {
    /// In the air: `[x, z, phi, theta, x', z', phi', theta']`.
    Flight,
    /// The toe pinned at `toe_x_m`: `[l, theta, phi, 0, l', theta', phi',
    /// 0]` (the fourth coordinate unused).
    Stance {
        /// The toe's position, m.
        toe_x_m: f64,
    },
}

/// A point mass of the model at one state: its mass, position, the
/// Jacobian of its position in the phase's coordinates (`jac[axis][coord]`)
/// and the part of its acceleration that is not `jac q''` (`conv`).
#[derive(Clone, Copy, Debug)]
struct Point {
    m: f64,
    pos: [f64; 2],
    jac: [[f64; 4]; 2],
    conv: [f64; 2],
}

/// The general runner (module docs), on the section 2.2 runner's stepper.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeneralRunner {
    p: GeneralParams,
    phase: GeneralPhase,
    s: [f64; 8],
    t_s: f64,
    stabiliser: Stabiliser,
    actuation: Actuation,
}

/// What the machine's actuators apply, held until set again (zero: the
/// passive runner).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Actuation {
    /// The hip motor's torque on the leg, the body taking the reaction
    /// (leg forward positive, as `theta`), N m.
    pub hip_torque_nm: f64,
    /// The leg actuator's force along the leg in stance, pushing the hip
    /// away from the toe, N (in flight the leg rests on its stop and the
    /// actuator has nothing to push against).
    pub leg_thrust_n: f64,
    /// A push on the body at the hip, forward positive (a disturbance: an
    /// impulse is this force held for a while), N.
    pub push_n: f64,
}

/// Solves `a x = b` by Gaussian elimination with partial pivoting; `None`
/// for a singular `a`.
fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    for c in 0..4 {
        let mut piv = c;
        for r in c + 1..4 {
            if a[r][c].abs() > a[piv][c].abs() {
                piv = r;
            }
        }
        if a[piv][c].abs() < 1e-300 || !a[piv][c].is_finite() {
            return None;
        }
        a.swap(c, piv);
        b.swap(c, piv);
        let (top, rest) = a.split_at_mut(c + 1);
        let pivot_row = &top[c];
        for (k, row) in rest.iter_mut().enumerate() {
            let f = row[c] / pivot_row[c];
            for (x, y) in row.iter_mut().zip(pivot_row).skip(c) {
                *x -= f * y;
            }
            b[c + 1 + k] -= f * b[c];
        }
    }
    let mut x = [0.0; 4];
    for c in (0..4).rev() {
        let mut v = b[c];
        for k in c + 1..4 {
            v -= a[c][k] * x[k];
        }
        x[c] = v / a[c][c];
    }
    Some(x)
}

/// Coulomb friction of magnitude `f` against `v`, linear below
/// [`DRY_FRICTION_SPEED`].
fn dry(f: f64, v: f64) -> f64 {
    -f * (v / DRY_FRICTION_SPEED).clamp(-1.0, 1.0)
}

impl GeneralRunner {
    /// In flight at the apex `apex` (hip at forward position 0), time 0.
    pub fn from_apex(p: GeneralParams, apex: &ApexState) -> Result<Self, PlanarError> {
        p.validate()?;
        Ok(GeneralRunner {
            p,
            phase: GeneralPhase::Flight,
            s: apex.flight_state(),
            t_s: 0.0,
            stabiliser: Stabiliser::PASSIVE,
            actuation: Actuation::default(),
        })
    }

    /// Applies `a` from now on (a zero-order hold: the controller's
    /// output between two of its periods).
    pub fn set_actuation(&mut self, a: Actuation) {
        self.actuation = a;
    }

    /// What the actuators apply.
    pub fn actuation(&self) -> Actuation {
        self.actuation
    }

    /// With the forward-speed stabiliser of eqs 2.79-2.80: in stance the
    /// leg's force is less by `K_c (x_dot_d - x')`, `x'` the hip's speed.
    pub fn stabilised(mut self, gain_ns_per_m: f64, speed_mps: f64) -> Self {
        self.stabiliser = Stabiliser {
            gain_ns_per_m,
            speed_mps,
        };
        self
    }

    /// The phase.
    pub fn phase(&self) -> GeneralPhase {
        self.phase
    }

    /// The parameters.
    pub fn params(&self) -> &GeneralParams {
        &self.p
    }

    /// The three point masses (trunk, leg, toe) at `s` in `phase`; the
    /// hip's position and Jacobian.
    fn points(&self, phase: GeneralPhase, s: &[f64; 8]) -> ([Point; 3], Point) {
        let p = &self.p;
        let (ip, it) = Self::angle_index(phase);
        let (phi, th, phid, thd) = (s[ip], s[it], s[ip + 4], s[it + 4]);
        let (sn, cs) = (libm::sin(th), libm::cos(th));
        let (sp, cp) = (libm::sin(phi), libm::cos(phi));
        // The leg's unit vector hip to toe, and its derivative in theta.
        let e = [sn, -cs];
        let e1 = [cs, sn];
        // The trunk's offset in the world, and its derivative in phi.
        let rc = [
            p.trunk_offset_x_m * cp - p.trunk_offset_z_m * sp,
            p.trunk_offset_x_m * sp + p.trunk_offset_z_m * cp,
        ];
        let rc1 = [-rc[1], rc[0]];
        let d = p.leg_com_from_hip_m;
        match phase {
            GeneralPhase::Flight => {
                // q = [x, z, phi, theta].
                let hip = Point {
                    m: 0.0,
                    pos: [s[0], s[1]],
                    jac: [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]],
                    conv: [0.0, 0.0],
                };
                let along = |m: f64, r: f64| Point {
                    m,
                    pos: [s[0] + r * e[0], s[1] + r * e[1]],
                    jac: [[1.0, 0.0, 0.0, r * e1[0]], [0.0, 1.0, 0.0, r * e1[1]]],
                    conv: [-r * e[0] * thd * thd, -r * e[1] * thd * thd],
                };
                let trunk = Point {
                    m: p.trunk_mass_kg,
                    pos: [s[0] + rc[0], s[1] + rc[1]],
                    jac: [[1.0, 0.0, rc1[0], 0.0], [0.0, 1.0, rc1[1], 0.0]],
                    conv: [-rc[0] * phid * phid, -rc[1] * phid * phid],
                };
                (
                    [
                        trunk,
                        along(p.leg_mass_kg, d),
                        along(p.toe_mass_kg, p.leg_length_m),
                    ],
                    hip,
                )
            }
            GeneralPhase::Stance { toe_x_m } => {
                // q = [l, theta, phi, unused]; hip = toe - l e.
                let (l, ld) = (s[0], s[4]);
                let from_toe = |r: f64| {
                    // The point at r from the toe towards the hip.
                    let conv = [
                        -2.0 * ld * thd * e1[0] + r * thd * thd * e[0],
                        -2.0 * ld * thd * e1[1] + r * thd * thd * e[1],
                    ];
                    (
                        [toe_x_m - r * e[0], -r * e[1]],
                        [[-e[0], -r * e1[0], 0.0, 0.0], [-e[1], -r * e1[1], 0.0, 0.0]],
                        conv,
                    )
                };
                let (hpos, hjac, hconv) = from_toe(l);
                let hip = Point {
                    m: 0.0,
                    pos: hpos,
                    jac: hjac,
                    conv: hconv,
                };
                let (lpos, ljac, lconv) = from_toe(l - d);
                let mut tjac = hjac;
                tjac[0][2] = rc1[0];
                tjac[1][2] = rc1[1];
                let trunk = Point {
                    m: p.trunk_mass_kg,
                    pos: [hpos[0] + rc[0], hpos[1] + rc[1]],
                    jac: tjac,
                    conv: [
                        hconv[0] - rc[0] * phid * phid,
                        hconv[1] - rc[1] * phid * phid,
                    ],
                };
                let leg = Point {
                    m: p.leg_mass_kg,
                    pos: lpos,
                    jac: ljac,
                    conv: lconv,
                };
                // The toe rests on the ground: it moves with no
                // coordinate.
                let toe = Point {
                    m: p.toe_mass_kg,
                    pos: [toe_x_m, 0.0],
                    jac: [[0.0; 4]; 2],
                    conv: [0.0, 0.0],
                };
                ([trunk, leg, toe], hip)
            }
        }
    }

    /// The coordinates of `phi` and `theta` in `phase`.
    fn angle_index(phase: GeneralPhase) -> (usize, usize) {
        match phase {
            GeneralPhase::Flight => (2, 3),
            GeneralPhase::Stance { .. } => (2, 1),
        }
    }

    /// The mass matrix at `s` in `phase` (the stance's unused coordinate
    /// given unit mass).
    fn mass_matrix(&self, phase: GeneralPhase, pts: &[Point; 3]) -> [[f64; 4]; 4] {
        let mut m = [[0.0; 4]; 4];
        for pt in pts {
            for (a, row) in m.iter_mut().enumerate() {
                for (b, v) in row.iter_mut().enumerate() {
                    *v += pt.m * (pt.jac[0][a] * pt.jac[0][b] + pt.jac[1][a] * pt.jac[1][b]);
                }
            }
        }
        let (ip, it) = Self::angle_index(phase);
        m[ip][ip] += self.p.trunk_inertia_kg_m2;
        m[it][it] += self.p.leg_inertia_kg_m2;
        if let GeneralPhase::Stance { .. } = phase {
            m[3][3] = 1.0;
        }
        m
    }

    /// The generalized momentum in `phase`'s coordinates at the
    /// configuration `pts` of bodies moving at `vel` (trunk, leg, toe) with
    /// the pitch rate `phid` and the leg rate `thd`.
    fn momentum(
        &self,
        phase: GeneralPhase,
        pts: &[Point; 3],
        vel: &[[f64; 2]; 3],
        phid: f64,
        thd: f64,
    ) -> [f64; 4] {
        let mut h = [0.0; 4];
        for (pt, v) in pts.iter().zip(vel) {
            for (a, h) in h.iter_mut().enumerate() {
                *h += pt.m * (pt.jac[0][a] * v[0] + pt.jac[1][a] * v[1]);
            }
        }
        let (ip, it) = Self::angle_index(phase);
        h[ip] += self.p.trunk_inertia_kg_m2 * phid;
        h[it] += self.p.leg_inertia_kg_m2 * thd;
        h
    }

    /// Each body's velocity at `s`.
    fn velocities(pts: &[Point; 3], s: &[f64; 8]) -> [[f64; 2]; 3] {
        let v = [s[4], s[5], s[6], s[7]];
        pts.map(|pt| {
            [
                (0..4).map(|a| pt.jac[0][a] * v[a]).sum(),
                (0..4).map(|a| pt.jac[1][a] * v[a]).sum(),
            ]
        })
    }

    fn rate(&self, phase: GeneralPhase, s: &[f64; 8]) -> [f64; 8] {
        let p = &self.p;
        let g = p.gravity_mps2;
        let (pts, hip) = self.points(phase, s);
        let mm = self.mass_matrix(phase, &pts);
        let mut q = [0.0; 4];
        for pt in &pts {
            let f = [-pt.m * pt.conv[0], -pt.m * (g + pt.conv[1])];
            for (a, q) in q.iter_mut().enumerate() {
                *q += pt.jac[0][a] * f[0] + pt.jac[1][a] * f[1];
            }
        }
        let (ip, it) = Self::angle_index(phase);
        let (rel, reld) = (s[it] - s[ip], s[it + 4] - s[ip + 4]);
        let hip_torque = -p.hip_stiffness_nm_per_rad * (rel - p.hip_rest_angle_rad)
            - p.hip_damping_nms_per_rad * reld
            + dry(p.hip_friction_nm, reld)
            + self.actuation.hip_torque_nm;
        q[it] += hip_torque;
        q[ip] -= hip_torque;
        // The planarizer on the hip's velocity.
        let v = [s[4], s[5], s[6], s[7]];
        let hv = [
            (0..4).map(|a| hip.jac[0][a] * v[a]).sum::<f64>(),
            (0..4).map(|a| hip.jac[1][a] * v[a]).sum::<f64>(),
        ];
        let fp = [
            dry(p.planarizer_friction_n, hv[0]) + self.actuation.push_n,
            dry(p.planarizer_friction_n, hv[1]),
        ];
        for (a, q) in q.iter_mut().enumerate() {
            *q += hip.jac[0][a] * fp[0] + hip.jac[1][a] * fp[1];
        }
        if let GeneralPhase::Stance { .. } = phase {
            q[0] += self.leg_force_at(s, hv[0]);
        }
        // A singular mass matrix (no valid parameters give one) shows as a
        // non-finite state rather than a silent zero.
        let acc = solve4(mm, q).unwrap_or([f64::NAN; 4]);
        [s[4], s[5], s[6], s[7], acc[0], acc[1], acc[2], acc[3]]
    }

    /// In stance at `s`, the leg's force along it (the spring, its damper,
    /// the leg's friction, less the stabiliser's `F_c` at the hip's speed
    /// `x_dot_mps`, plus the leg actuator's thrust), N.
    fn leg_force_at(&self, s: &[f64; 8], x_dot_mps: f64) -> f64 {
        let p = &self.p;
        let (l, ld) = (s[0], s[4]);
        p.leg_stiffness_n_per_m * (p.leg_length_m - l) - p.leg_damping_ns_per_m * ld
            + dry(p.leg_friction_n, ld)
            - self.stabiliser.force_n(x_dot_mps)
            + self.actuation.leg_thrust_n
    }

    /// The leg's force along it (spring, damper, friction, less the
    /// stabiliser, plus the leg actuator's thrust), N (0 in flight).
    pub fn leg_force_n(&self) -> f64 {
        match self.phase {
            GeneralPhase::Flight => 0.0,
            GeneralPhase::Stance { .. } => self.leg_force_at(&self.s, self.state().x_dot_mps),
        }
    }

    /// The stabiliser's force `F_c` (eq 2.79), N (0 in flight).
    pub fn stabiliser_force_n(&self) -> f64 {
        match self.phase {
            GeneralPhase::Flight => 0.0,
            GeneralPhase::Stance { .. } => self.stabiliser.force_n(self.state().x_dot_mps),
        }
    }

    /// The state in Cartesian form: the hip, the angles and their rates,
    /// the leg's length (`l_0` in flight).
    pub fn state(&self) -> PlanarState {
        let s = &self.s;
        let (_, hip) = self.points(self.phase, s);
        let v = [s[4], s[5], s[6], s[7]];
        let hv = |k: usize| (0..4).map(|a| hip.jac[k][a] * v[a]).sum::<f64>();
        let (ip, it) = Self::angle_index(self.phase);
        let stance = matches!(self.phase, GeneralPhase::Stance { .. });
        PlanarState {
            t_s: self.t_s,
            x_m: hip.pos[0],
            z_m: hip.pos[1],
            phi_rad: s[ip],
            theta_rad: s[it],
            x_dot_mps: hv(0),
            z_dot_mps: hv(1),
            phi_dot_rad_s: s[ip + 4],
            theta_dot_rad_s: s[it + 4],
            leg_length_m: if stance { s[0] } else { self.p.leg_length_m },
            stance,
        }
    }

    /// Kinetic energy, J.
    fn kinetic_j(&self, phase: GeneralPhase, s: &[f64; 8]) -> f64 {
        let (pts, _) = self.points(phase, s);
        let vel = Self::velocities(&pts, s);
        let (ip, it) = Self::angle_index(phase);
        pts.iter()
            .zip(&vel)
            .map(|(pt, v)| 0.5 * pt.m * (v[0] * v[0] + v[1] * v[1]))
            .sum::<f64>()
            + 0.5 * self.p.trunk_inertia_kg_m2 * s[ip + 4] * s[ip + 4]
            + 0.5 * self.p.leg_inertia_kg_m2 * s[it + 4] * s[it + 4]
    }

    /// Total mechanical energy: kinetic, gravity from the ground, both
    /// springs, J.
    pub fn energy_j(&self) -> f64 {
        let p = &self.p;
        let s = &self.s;
        let (pts, _) = self.points(self.phase, s);
        let (ip, it) = Self::angle_index(self.phase);
        let rel = s[it] - s[ip] - p.hip_rest_angle_rad;
        let mut e = self.kinetic_j(self.phase, s)
            + pts
                .iter()
                .map(|pt| pt.m * p.gravity_mps2 * pt.pos[1])
                .sum::<f64>()
            + 0.5 * p.hip_stiffness_nm_per_rad * rel * rel;
        if let GeneralPhase::Stance { .. } = self.phase {
            let c = p.leg_length_m - s[0];
            e += 0.5 * p.leg_stiffness_n_per_m * c * c;
        }
        e
    }

    /// Linear momentum `[x, z]`, kg m/s, and the angular momentum about
    /// the point `o` (counter-clockwise positive), kg m^2/s.
    pub fn momentum_about(&self, o: [f64; 2]) -> ([f64; 2], f64) {
        let s = &self.s;
        let (pts, _) = self.points(self.phase, s);
        let vel = Self::velocities(&pts, s);
        let (ip, it) = Self::angle_index(self.phase);
        let mut lin = [0.0; 2];
        let mut ang = self.p.trunk_inertia_kg_m2 * s[ip + 4] + self.p.leg_inertia_kg_m2 * s[it + 4];
        for (pt, v) in pts.iter().zip(&vel) {
            lin[0] += pt.m * v[0];
            lin[1] += pt.m * v[1];
            ang += pt.m * ((pt.pos[0] - o[0]) * v[1] - (pt.pos[1] - o[1]) * v[0]);
        }
        (lin, ang)
    }

    /// The centre of mass, m.
    pub fn centre_of_mass_m(&self) -> [f64; 2] {
        let (pts, _) = self.points(self.phase, &self.s);
        let m: f64 = pts.iter().map(|pt| pt.m).sum();
        [
            pts.iter().map(|pt| pt.m * pt.pos[0]).sum::<f64>() / m,
            pts.iter().map(|pt| pt.m * pt.pos[1]).sum::<f64>() / m,
        ]
    }

    /// Advances `dt_s`, reporting transitions (and apexes) to `on_event`.
    pub fn step(&mut self, dt_s: f64, on_event: &mut impl FnMut(PlanarEvent)) {
        step_hybrid(self, dt_s, on_event);
    }

    /// Runs in steps of `dt_s` to the next apex, at most `max_s`: that
    /// apex and what its touchdown took, or `None` if the hip fell below
    /// half the leg's length or no apex came.
    pub fn next_apex(&mut self, dt_s: f64, max_s: f64) -> Option<(ApexState, f64)> {
        let floor = 0.5 * self.p.leg_length_m;
        next_apex_hybrid(self, dt_s, max_s, floor, |r| r.state().z_m)
    }

    /// Touchdown at the flight state `at`: the stance velocities keep the
    /// generalized momentum of every motion with the toe at rest.
    fn land(&mut self, at: &[f64; 8], on_event: &mut dyn FnMut(PlanarEvent)) {
        let l0 = self.p.leg_length_m;
        let (pts, _) = self.points(GeneralPhase::Flight, at);
        let vel = Self::velocities(&pts, at);
        let before = self.kinetic_j(GeneralPhase::Flight, at);
        let (th, phi) = (at[3], at[2]);
        let phase = GeneralPhase::Stance {
            toe_x_m: at[0] + l0 * libm::sin(th),
        };
        let q = [l0, th, phi, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (spts, _) = self.points(phase, &q);
        let h = self.momentum(phase, &spts, &vel, at[6], at[7]);
        let mm = self.mass_matrix(phase, &spts);
        let u = solve4(mm, h).unwrap_or([f64::NAN; 4]);
        let s = [l0, th, phi, 0.0, u[0], u[1], u[2], 0.0];
        let after = self.kinetic_j(phase, &s);
        self.phase = phase;
        self.s = s;
        on_event(PlanarEvent::Touchdown {
            t_s: self.t_s,
            loss_j: before - after,
        });
        if u[0] >= 0.0 {
            // The hip moves away from the toe along the leg: the leg is
            // already on its stop, so the toe leaves at once.
            self.lift(&s, on_event);
        }
    }

    /// Liftoff at the stance state `at`: the stop picks the toe up, and
    /// the flight's generalized momentum is kept.
    fn lift(&mut self, at: &[f64; 8], on_event: &mut dyn FnMut(PlanarEvent)) {
        let phase = self.phase;
        let (pts, hip) = self.points(phase, at);
        let vel = Self::velocities(&pts, at);
        let before = self.kinetic_j(phase, at);
        let (th, phi) = (at[1], at[2]);
        let q = [hip.pos[0], hip.pos[1], phi, th, 0.0, 0.0, 0.0, 0.0];
        let (fpts, _) = self.points(GeneralPhase::Flight, &q);
        let h = self.momentum(GeneralPhase::Flight, &fpts, &vel, at[6], at[5]);
        let mm = self.mass_matrix(GeneralPhase::Flight, &fpts);
        let u = solve4(mm, h).unwrap_or([f64::NAN; 4]);
        let s = [q[0], q[1], phi, th, u[0], u[1], u[2], u[3]];
        let after = self.kinetic_j(GeneralPhase::Flight, &s);
        self.phase = GeneralPhase::Flight;
        self.s = s;
        on_event(PlanarEvent::Liftoff {
            t_s: self.t_s,
            loss_j: before - after,
        });
    }
}

impl Hybrid for GeneralRunner {
    fn in_flight(&self) -> bool {
        matches!(self.phase, GeneralPhase::Flight)
    }
    fn rate_of(&self, s: &[f64; 8]) -> [f64; 8] {
        self.rate(self.phase, s)
    }
    fn leg_length_m(&self) -> f64 {
        self.p.leg_length_m
    }
    fn gravity(&self) -> f64 {
        self.p.gravity_mps2
    }
    fn state_time(&mut self) -> (&mut [f64; 8], &mut f64) {
        (&mut self.s, &mut self.t_s)
    }
    fn transition(&mut self, at: &[f64; 8], on_event: &mut dyn FnMut(PlanarEvent)) {
        match self.phase {
            GeneralPhase::Flight => self.land(at, on_event),
            GeneralPhase::Stance { .. } => self.lift(at, on_event),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planar::{passive_design, Gait, PlanarRunner};

    const DT: f64 = 1e-4;

    fn design_apex(v: f64) -> ApexState {
        let p = PlanarParams::table_2_2();
        let d = passive_design(&p, &Gait::table_2_2(v)).unwrap_or_else(|e| panic!("{e:?}"));
        ApexState::of_design(&d, v)
    }

    /// A runner with every Appendix A term but the losses: the trunk's
    /// centre 1 cm ahead and 5 cm above the hip, the leg's 10 cm down it
    /// (Table 2.2's design gait is not this runner's: it falls within two
    /// or three hops, which is all the bookkeeping needs).
    fn offset_params(toe_mass_kg: f64) -> GeneralParams {
        GeneralParams {
            trunk_offset_x_m: 0.01,
            trunk_offset_z_m: 0.05,
            leg_com_from_hip_m: 0.1,
            toe_mass_kg,
            ..GeneralParams::from_section_2_2(&PlanarParams::table_2_2())
        }
    }

    /// With no offsets, no toe mass and no friction the general runner is
    /// the section 2.2 runner: the same apexes (every component within
    /// 1e-9) and touchdown losses (1e-9 J) for 8 hops at 2 m/s and at 4
    /// m/s with the stabiliser (K_c = 1000), and until the passive 4 m/s
    /// gait falls.
    #[test]
    fn reduces_to_the_section_2_2_runner() {
        let p = PlanarParams::table_2_2();
        for (v, kc) in [(2.0, 0.0), (4.0, 0.0), (4.0, 1000.0)] {
            let a = design_apex(v);
            let mut simple = PlanarRunner::from_apex(p, &a)
                .unwrap_or_else(|e| panic!("{e:?}"))
                .stabilised(kc, v);
            let mut general = GeneralRunner::from_apex(GeneralParams::from_section_2_2(&p), &a)
                .unwrap_or_else(|e| panic!("{e:?}"))
                .stabilised(kc, v);
            let mut hops = 0;
            for _ in 0..8 {
                let (s, g) = (simple.next_apex(DT, 5.0), general.next_apex(DT, 5.0));
                match (s, g) {
                    (Some((sa, sl)), Some((ga, gl))) => {
                        for (x, y) in sa.to_array().iter().zip(ga.to_array()) {
                            assert!((x - y).abs() < 1e-9, "{v} m/s hop {hops}: {sa:?} {ga:?}");
                        }
                        assert!((sl - gl).abs() < 1e-9, "{sl} {gl}");
                        hops += 1;
                    }
                    (None, None) => break,
                    (s, g) => panic!("{v} m/s hop {hops}: one fell: {s:?} {g:?}"),
                }
            }
            assert!(
                hops >= if v < 3.0 || kc > 0.0 { 8 } else { 3 },
                "{v}: {hops}"
            );
        }
    }

    /// With the motion vertical the hip never turns, and the general runner
    /// is the vertical hopper with its nut locked: dropped from 15 cm, its
    /// apexes are the closed form's (each touchdown takes `0.5 m_u v^2`,
    /// each liftoff's pick-up keeps the momentum; 1e-9 m) and the vertical
    /// plant's (0.1 mm), whatever the offsets along the vertical.
    #[test]
    fn reduces_to_the_vertical_model_with_the_hip_still() {
        use crate::params::Params;
        use crate::plant::{Event, Plant};
        let (m_body, m_nut, m_u, l0, k) = (9.0, 0.25, 0.6, 0.61, 11_000.0);
        let g = GeneralParams {
            trunk_mass_kg: m_body,
            trunk_inertia_kg_m2: 0.4,
            trunk_offset_x_m: 0.0,
            trunk_offset_z_m: 0.12,
            leg_mass_kg: m_nut,
            leg_inertia_kg_m2: 0.02,
            leg_com_from_hip_m: 0.2,
            toe_mass_kg: m_u,
            leg_length_m: l0,
            leg_stiffness_n_per_m: k,
            hip_stiffness_nm_per_rad: 28.4,
            ..GeneralParams::from_section_2_2(&PlanarParams::table_2_2())
        };
        let apex = ApexState {
            z_m: l0 + 0.15,
            x_dot_mps: 0.0,
            phi_rad: 0.0,
            theta_rad: 0.0,
            phi_dot_rad_s: 0.0,
            theta_dot_rad_s: 0.0,
        };
        let mut r = GeneralRunner::from_apex(g, &apex).unwrap_or_else(|e| panic!("{e:?}"));
        let plant_params = Params {
            body_mass_kg: m_body,
            nut_mass_kg: m_nut,
            unsprung_mass_kg: m_u,
            leg_length_m: l0,
            spring_stiffness_n_per_m: k,
            spring_damping_ns_per_m: 0.0,
            spring_preload_m: 0.0,
            planarizer_friction_n: 0.0,
            leg_friction_n: 0.0,
            rotor_inertia_kg_m2: 1.0,
            gravity_mps2: g.gravity_mps2,
            ..Params::design()
        };
        let mut plant = Plant::new(plant_params, 0.15).unwrap_or_else(|e| panic!("{e:?}"));
        let mut plant_apexes = std::vec::Vec::new();
        while plant_apexes.len() < 4 {
            plant
                .advance(1e-3, 0.0, &mut |e| {
                    if let Event::Apex { toe_height_m, .. } = e {
                        plant_apexes.push(toe_height_m + l0);
                    }
                })
                .unwrap_or_else(|e| panic!("{e:?}"));
            assert!(plant.time_s() < 10.0);
        }
        let ratio = ((m_body + m_nut) / (m_body + m_nut + m_u)).powi(2);
        let mut closed = apex.z_m - l0;
        for (hop, plant_apex) in plant_apexes.iter().enumerate() {
            let (a, loss) = r.next_apex(DT, 5.0).unwrap_or_else(|| panic!("fell"));
            let v2 = 2.0 * g.gravity_mps2 * closed;
            assert!(
                (loss - 0.5 * m_u * v2).abs() < 1e-9,
                "touchdown took {loss}"
            );
            closed *= ratio;
            assert!(
                (a.z_m - (l0 + closed)).abs() < 1e-9,
                "hop {hop}: {a:?}, closed form {}",
                l0 + closed
            );
            assert!(
                (a.z_m - plant_apex).abs() < 1e-4,
                "hop {hop}: {} against the plant's {plant_apex}",
                a.z_m
            );
            for x in [
                a.x_dot_mps,
                a.phi_rad,
                a.theta_rad,
                a.phi_dot_rad_s,
                a.theta_dot_rad_s,
            ] {
                assert!(x == 0.0, "{a:?}");
            }
        }
    }

    /// Run `r` for `t_s` (or until it falls), checking at every step that
    /// the energy plus what the transitions and friction took stays at the
    /// start's: within `tol_j` (no friction) or never rising (friction).
    fn run_ledger(r: &mut GeneralRunner, t_s: f64, tol_j: f64) -> (f64, usize) {
        let e0 = r.energy_j();
        let mut taken = 0.0;
        let mut transitions = 0;
        let mut last = e0;
        for _ in 0..(t_s / DT) as usize {
            r.step(DT, &mut |e| match e {
                PlanarEvent::Touchdown { loss_j, .. } | PlanarEvent::Liftoff { loss_j, .. } => {
                    assert!(loss_j > -1e-9, "{e:?}");
                    taken += loss_j;
                    transitions += 1;
                }
                PlanarEvent::Apex { .. } => {}
            });
            let now = r.energy_j() + taken;
            if tol_j > 0.0 {
                assert!(
                    (now - e0).abs() < tol_j,
                    "{e0} -> {now} at {}",
                    r.state().t_s
                );
            } else {
                assert!(now <= last + 1e-9, "energy rose {last} -> {now}");
            }
            last = now;
            if r.state().z_m < 0.4 {
                break;
            }
        }
        (taken, transitions)
    }

    /// Without losses but with the offsets and a toe mass, the energy is
    /// conserved within each phase (1e-6 J at every step until it falls),
    /// and the transitions' reported losses close the books; the toe's
    /// impacts take energy.
    #[test]
    fn energy_is_conserved_apart_from_the_impacts() {
        for m_u in [0.0, 0.5] {
            let mut r = GeneralRunner::from_apex(offset_params(m_u), &design_apex(2.0))
                .unwrap_or_else(|e| panic!("{e:?}"));
            let (taken, transitions) = run_ledger(&mut r, 3.0, 1e-6);
            assert!(transitions >= 3, "{transitions}");
            if m_u > 0.0 {
                assert!(taken > 1.0, "the toe mass's impacts took {taken} J");
            }
        }
    }

    /// With the dampers and the three dry frictions the energy with what
    /// the impacts took never rises, and it falls.
    #[test]
    fn friction_and_damping_only_take_energy() {
        let p = GeneralParams {
            leg_damping_ns_per_m: 20.0,
            hip_damping_nms_per_rad: 0.2,
            planarizer_friction_n: 5.0,
            leg_friction_n: 5.0,
            hip_friction_nm: 0.3,
            ..offset_params(0.5)
        };
        let mut r =
            GeneralRunner::from_apex(p, &design_apex(2.0)).unwrap_or_else(|e| panic!("{e:?}"));
        let e0 = r.energy_j();
        let (taken, _) = run_ledger(&mut r, 1.0, 0.0);
        assert!(r.energy_j() + taken < e0 - 1.0, "{e0} {}", r.energy_j());
    }

    /// Momentum: in flight the linear momentum changes only by gravity and
    /// the angular momentum about the centre of mass holds; in stance the
    /// angular momentum about the toe changes by gravity's moment alone;
    /// the touchdown keeps the angular momentum about the toe (the ground's
    /// impulse acts there); the liftoff's pick-up keeps both.
    #[test]
    fn momentum_through_flight_stance_and_the_transitions() {
        let p = offset_params(0.5);
        let m = p.total_mass_kg();
        let g = p.gravity_mps2;
        let mut r =
            GeneralRunner::from_apex(p, &design_apex(2.0)).unwrap_or_else(|e| panic!("{e:?}"));
        let (mut landings, mut liftoffs, mut stance_steps) = (0, 0, 0);
        for _ in 0..(2.0 / DT) as usize {
            let before = r;
            let phase0 = r.phase();
            let mut hit = false;
            r.step(DT, &mut |e| {
                if !matches!(e, PlanarEvent::Apex { .. }) {
                    hit = true;
                }
            });
            if hit {
                continue;
            }
            match (phase0, r.phase()) {
                (GeneralPhase::Flight, GeneralPhase::Flight) => {
                    let c0 = before.centre_of_mass_m();
                    let c1 = r.centre_of_mass_m();
                    let (l0, h0) = before.momentum_about(c0);
                    let (l1, h1) = r.momentum_about(c1);
                    assert!((l1[0] - l0[0]).abs() < 1e-9, "{l0:?} {l1:?}");
                    assert!((l1[1] - l0[1] + m * g * DT).abs() < 1e-9, "{l0:?} {l1:?}");
                    assert!((h1 - h0).abs() < 1e-9, "{h0} {h1}");
                }
                (GeneralPhase::Stance { toe_x_m }, GeneralPhase::Stance { .. }) => {
                    let o = [toe_x_m, 0.0];
                    let (_, h0) = before.momentum_about(o);
                    let (_, h1) = r.momentum_about(o);
                    // Gravity's moment about the toe, trapezoidal.
                    let moment = |q: &GeneralRunner| -g * m * (q.centre_of_mass_m()[0] - toe_x_m);
                    let expect = 0.5 * DT * (moment(&before) + moment(&r));
                    assert!(
                        (h1 - h0 - expect).abs() < 1e-6 * expect.abs().max(1e-3),
                        "{h0} {h1} {expect}"
                    );
                    stance_steps += 1;
                }
                _ => {}
            }
        }
        assert!(stance_steps > 600, "{stance_steps}");
        // The transitions themselves, at the states where they happen.
        let mut r =
            GeneralRunner::from_apex(p, &design_apex(2.0)).unwrap_or_else(|e| panic!("{e:?}"));
        for _ in 0..100_000 {
            if liftoffs >= 2 {
                break;
            }
            let s = r.s;
            let next = rk4_of(&r, &s);
            let (g0, g1) = (r.guard_of(&s), r.guard_of(&next));
            if g0 > 0.0 && g1 <= 0.0 && (!r.in_flight() || next[5] < 0.0) {
                // Land or lift exactly at the guard by bisection.
                let (mut lo, mut hi) = (0.0, DT);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if r.guard_of(&crate::planar::rk4(&r, &s, mid)) > 0.0 {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                let at = crate::planar::rk4(&r, &s, hi);
                r.s = at;
                let flight = r.in_flight();
                let toe = if flight {
                    [at[0] + p.leg_length_m * libm::sin(at[3]), 0.0]
                } else {
                    match r.phase {
                        GeneralPhase::Stance { toe_x_m } => [toe_x_m, 0.0],
                        GeneralPhase::Flight => unreachable!(),
                    }
                };
                let (l0, h0) = r.momentum_about(toe);
                r.transition(&at, &mut |_| {});
                let (l1, h1) = r.momentum_about(toe);
                assert!(
                    (h1 - h0).abs() < 1e-9,
                    "angular momentum about the toe {h0} -> {h1}"
                );
                if flight {
                    landings += 1;
                } else {
                    for k in 0..2 {
                        assert!((l1[k] - l0[k]).abs() < 1e-9, "pick-up: {l0:?} -> {l1:?}");
                    }
                    liftoffs += 1;
                }
            } else {
                r.s = next;
            }
        }
        assert!(landings >= 2 && liftoffs >= 2, "{landings} {liftoffs}");
    }

    fn rk4_of(r: &GeneralRunner, s: &[f64; 8]) -> [f64; 8] {
        crate::planar::rk4(r, s, DT)
    }

    #[test]
    fn bad_parameters_are_refused_by_name() {
        let ok = offset_params(0.5);
        assert_eq!(ok.validate(), Ok(()));
        for (bad, name) in [
            (
                GeneralParams {
                    toe_mass_kg: -0.1,
                    ..ok
                },
                "toe_mass_kg",
            ),
            (
                GeneralParams {
                    leg_com_from_hip_m: 0.7,
                    ..ok
                },
                "leg_com_from_hip_m",
            ),
            (
                GeneralParams {
                    hip_friction_nm: f64::NAN,
                    ..ok
                },
                "hip_friction_nm",
            ),
            (
                GeneralParams {
                    trunk_offset_x_m: f64::INFINITY,
                    ..ok
                },
                "trunk_offset_x_m",
            ),
        ] {
            assert_eq!(bad.validate(), Err(PlanarError::OutOfRange(name)));
        }
        assert_eq!(
            GeneralParams {
                trunk_mass_kg: 0.0,
                ..ok
            }
            .validate(),
            Err(PlanarError::NotPositive("trunk_mass_kg"))
        );
    }
}
