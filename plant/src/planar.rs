//! The planar one-legged runner of thesis section 2.2 (after Thompson and
//! Raibert): body of mass `m_b` and pitch inertia `J_b` with its centre at
//! the hip, a leg of mass `m_l` and inertia `J_l` (centre at the hip) on a
//! torsional hip spring `k_h`, a massless leg spring `k_l` of rest length
//! `r_0`, no losses.
//!
//! This module holds Table 2.2's parameters and the passive-dynamics design
//! of sections 2.2.2.4-2.2.2.5: from the step period `T_step`, the stance
//! fraction `rho` and the running speed, the spring constants (eqs 2.73,
//! 2.75) and the initial conditions (eqs 2.76-2.78). The flight and stance
//! dynamics ([`PlanarRunner`]: eqs 2.54-2.57 in flight, the pinned-toe
//! stance below, the stabiliser of eqs 2.79-2.80).
//!
//! The stance. Eqs 2.54-2.61 give the leg spring's force
//! along the leg but not the ground force across it that a pinned toe
//! needs (the hip spring's torque on the leg, `J_l theta''`). Appendix A
//! writes stance in polar coordinates about the toe (eqs A.14-A.17), and
//! the section 2.2 model is its special case (no offsets, no unsprung
//! mass, no friction): with `m = m_b + m_l`, the toe at `x_f`, `x = x_f -
//! r sin theta`, `z = r cos theta`, Lagrange gives
//! `m (r'' - r theta'^2) = k_l (r_0 - r) - m g cos theta`,
//! `(m r^2 + J_l) theta'' + 2 m r r' theta' = m g r sin theta + k_h (phi - theta)`,
//! `J_b phi'' = k_h (theta - phi)`; flight is eqs 2.54-2.57 with `F = 0`.
//! At touchdown a plastic impact stops the toe's velocity across the leg
//! (along it the massless spring gives way): the impulse changes the hip's
//! velocity and the leg's rate, and takes energy unless the toe lands
//! without sliding speed, which the passive design aims at;
//! [`PlanarEvent::Touchdown`] reports what it took.
//!
//! This runner keeps section 2.2's own equations on purpose: Appendix A's
//! general runner ([`crate::planar_general`]) is derived independently and
//! tested against it (it must reduce to this one to 1e-9); both run on the
//! one stepper (`step_hybrid`). The return map and its eigenvalues are
//! this runner's (`hal_sim::planar_stability`).
//!
//! Erratum: eq 2.77 prints the zero-angular-momentum condition as
//! `phi_dot / J_l = -theta_dot / J_d`; the angular momentum of body and leg
//! about the hip is `J_b phi_dot + J_l theta_dot`, so the condition is
//! `J_b phi_dot = -J_l theta_dot`, which is the thesis's own result
//! `phi_dot_0 = -(J_l / J_b) theta_dot_0`.

use core::f64::consts::PI;

/// The runner's masses, inertias, springs and leg length (SI).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarParams {
    /// Body mass `m_b`, kg.
    pub body_mass_kg: f64,
    /// Body pitch inertia about the hip `J_b`, kg m^2.
    pub body_inertia_kg_m2: f64,
    /// Leg mass `m_l`, kg.
    pub leg_mass_kg: f64,
    /// Leg inertia about its centre, at the hip, `J_l`, kg m^2.
    pub leg_inertia_kg_m2: f64,
    /// Leg rest length `r_0`, m.
    pub leg_rest_length_m: f64,
    /// Hip torsional spring `k_h`, N m/rad.
    pub hip_stiffness_nm_per_rad: f64,
    /// Leg spring `k_l`, N/m.
    pub leg_stiffness_n_per_m: f64,
    /// Gravity `g`, m/s^2.
    pub gravity_mps2: f64,
}

impl PlanarParams {
    /// Table 2.2.
    pub const fn table_2_2() -> Self {
        PlanarParams {
            body_mass_kg: 12.5,
            body_inertia_kg_m2: 0.82,
            leg_mass_kg: 3.5,
            leg_inertia_kg_m2: 0.23,
            leg_rest_length_m: 0.65,
            hip_stiffness_nm_per_rad: 28.4,
            leg_stiffness_n_per_m: 40_425.0,
            gravity_mps2: 9.81,
        }
    }

    /// Total mass `m_b + m_l`, kg.
    pub fn total_mass_kg(&self) -> f64 {
        self.body_mass_kg + self.leg_mass_kg
    }

    /// The hip oscillation's effective inertia `J_b J_l / (J_b + J_l)`
    /// (eq 2.70), kg m^2.
    pub fn effective_inertia_kg_m2(&self) -> f64 {
        self.body_inertia_kg_m2 * self.leg_inertia_kg_m2
            / (self.body_inertia_kg_m2 + self.leg_inertia_kg_m2)
    }

    /// The hip oscillation's natural frequency `sqrt(k_h / J_eff)` (eq
    /// 2.68), rad/s.
    pub fn hip_rate_rad_s(&self) -> f64 {
        libm::sqrt(self.hip_stiffness_nm_per_rad / self.effective_inertia_kg_m2())
    }

    /// The stance rebound's natural frequency `sqrt(k_l / m)` (eq 2.65),
    /// rad/s.
    pub fn leg_rate_rad_s(&self) -> f64 {
        libm::sqrt(self.leg_stiffness_n_per_m / self.total_mass_kg())
    }

    /// Every field positive and finite, else the first that is not.
    pub fn validate(&self) -> Result<(), PlanarError> {
        for (name, v) in [
            ("body_mass_kg", self.body_mass_kg),
            ("body_inertia_kg_m2", self.body_inertia_kg_m2),
            ("leg_mass_kg", self.leg_mass_kg),
            ("leg_inertia_kg_m2", self.leg_inertia_kg_m2),
            ("leg_rest_length_m", self.leg_rest_length_m),
            ("hip_stiffness_nm_per_rad", self.hip_stiffness_nm_per_rad),
            ("leg_stiffness_n_per_m", self.leg_stiffness_n_per_m),
            ("gravity_mps2", self.gravity_mps2),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(PlanarError::NotPositive(name));
            }
        }
        Ok(())
    }
}

/// The gait asked for: the three independent parameters of section
/// 2.2.2.5.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gait {
    /// Step period `T_step`, s.
    pub step_period_s: f64,
    /// Stance time over step time `rho` (the thesis tried 0.125-0.25).
    pub stance_fraction: f64,
    /// Running speed `x_dot_d`, m/s.
    pub speed_mps: f64,
}

impl Gait {
    /// Table 2.2's gait (`T_step` 0.5 s, `rho` 0.125) at `speed_mps`.
    pub const fn table_2_2(speed_mps: f64) -> Self {
        Gait {
            step_period_s: 0.5,
            stance_fraction: 0.125,
            speed_mps,
        }
    }
}

/// A gait or parameter set that cannot be designed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlanarError {
    /// A field that must be positive and finite is not (its name).
    NotPositive(&'static str),
    /// `rho` is not within (0, 1).
    StanceFraction,
    /// A field that must be finite and not negative (or, for the leg's
    /// centre, on the leg) is not (its name).
    OutOfRange(&'static str),
}

/// What the passive-dynamics design gives: the springs and the initial
/// conditions (the drop at mid flight, angles zero).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PassiveDesign {
    /// `k_h = (2 pi / T_step)^2 J_eff` (eq 2.73), N m/rad.
    pub hip_stiffness_nm_per_rad: f64,
    /// `k_l = m (pi / (rho T_step))^2` (eq 2.75), N/m.
    pub leg_stiffness_n_per_m: f64,
    /// Leg rate at the apex `x_dot_d / r_0` (eq 2.76), rad/s.
    pub leg_rate0_rad_s: f64,
    /// Body rate at the apex `-(J_l / J_b) theta_dot_0` (eq 2.77), rad/s.
    pub body_rate0_rad_s: f64,
    /// Flight time `T_step (1 - rho)`, s.
    pub flight_time_s: f64,
    /// The leg angle at touchdown `theta_dot_0 / omega_h sin(omega_h T_f
    /// / 2)` (eq 2.72 at half the flight), rad.
    pub touchdown_angle_rad: f64,
    /// Drop height of the hip `z_max` (eq 2.78), m.
    pub apex_height_m: f64,
}

/// The passive-dynamics design of `gait` for the masses, inertias and leg
/// length of `p` (its springs are what this computes; eqs 2.73-2.78).
pub fn passive_design(p: &PlanarParams, gait: &Gait) -> Result<PassiveDesign, PlanarError> {
    p.validate()?;
    if !(gait.step_period_s.is_finite() && gait.step_period_s > 0.0) {
        return Err(PlanarError::NotPositive("step_period_s"));
    }
    if !(gait.speed_mps.is_finite() && gait.speed_mps >= 0.0) {
        return Err(PlanarError::NotPositive("speed_mps"));
    }
    let rho = gait.stance_fraction;
    if !(rho > 0.0 && rho < 1.0) {
        return Err(PlanarError::StanceFraction);
    }
    let omega_h = 2.0 * PI / gait.step_period_s;
    let k_h = omega_h * omega_h * p.effective_inertia_kg_m2();
    let leg = PI / (rho * gait.step_period_s);
    let k_l = p.total_mass_kg() * leg * leg;
    let theta0 = gait.speed_mps / p.leg_rest_length_m;
    let phi0 = -p.leg_inertia_kg_m2 / p.body_inertia_kg_m2 * theta0;
    let t_f = gait.step_period_s * (1.0 - rho);
    let td_angle = theta0 / omega_h * libm::sin(omega_h * t_f / 2.0);
    let z_max = p.gravity_mps2 / 8.0 * t_f * t_f + p.leg_rest_length_m * libm::cos(td_angle);
    Ok(PassiveDesign {
        hip_stiffness_nm_per_rad: k_h,
        leg_stiffness_n_per_m: k_l,
        leg_rate0_rad_s: theta0,
        body_rate0_rad_s: phi0,
        flight_time_s: t_f,
        touchdown_angle_rad: td_angle,
        apex_height_m: z_max,
    })
}

/// Where the runner is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlanarPhase {
    /// In the air: `[x, z, phi, theta, x', z', phi', theta']`.
    Flight,
    /// The toe pinned at `toe_x_m`: `[r, theta, phi, r', theta', phi']`
    /// about it.
    Stance {
        /// The toe's position, m.
        toe_x_m: f64,
    },
}

/// A transition, as [`PlanarRunner::step`] reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PlanarEvent {
    /// The toe landed: a plastic impact stopped its sliding, which took
    /// `loss_j` of kinetic energy (0 when it lands without sliding speed).
    Touchdown {
        /// Time, s.
        t_s: f64,
        /// Kinetic energy the leg's rate jump took, J.
        loss_j: f64,
    },
    /// The leg spring reached its rest length (the leg its stop).
    Liftoff {
        /// Time, s.
        t_s: f64,
        /// Kinetic energy the stop's pick-up of the toe mass took, J (0
        /// for a massless toe).
        loss_j: f64,
    },
    /// The top of a flight.
    Apex {
        /// Time, s.
        t_s: f64,
        /// The state there.
        apex: ApexState,
    },
}

/// The state at the top of a flight (`z' = 0`), the return map's
/// coordinates: everything but the forward position, which the dynamics
/// do not depend on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ApexState {
    /// Hip height, m.
    pub z_m: f64,
    /// Forward speed, m/s.
    pub x_dot_mps: f64,
    /// Body pitch, rad.
    pub phi_rad: f64,
    /// Leg angle, rad.
    pub theta_rad: f64,
    /// Body pitch rate, rad/s.
    pub phi_dot_rad_s: f64,
    /// Leg rate, rad/s.
    pub theta_dot_rad_s: f64,
}

impl ApexState {
    /// The design's apex at `speed_mps`: angles zero, the design's rates.
    pub fn of_design(d: &PassiveDesign, speed_mps: f64) -> Self {
        ApexState {
            z_m: d.apex_height_m,
            x_dot_mps: speed_mps,
            phi_rad: 0.0,
            theta_rad: 0.0,
            phi_dot_rad_s: d.body_rate0_rad_s,
            theta_dot_rad_s: d.leg_rate0_rad_s,
        }
    }

    /// The flight state there, the hip at forward position 0: `[x, z,
    /// phi, theta, x', z', phi', theta']`.
    pub(crate) fn flight_state(&self) -> [f64; 8] {
        [
            0.0,
            self.z_m,
            self.phi_rad,
            self.theta_rad,
            self.x_dot_mps,
            0.0,
            self.phi_dot_rad_s,
            self.theta_dot_rad_s,
        ]
    }

    /// As `[z, x', phi, theta, phi', theta']`.
    pub fn to_array(&self) -> [f64; 6] {
        [
            self.z_m,
            self.x_dot_mps,
            self.phi_rad,
            self.theta_rad,
            self.phi_dot_rad_s,
            self.theta_dot_rad_s,
        ]
    }

    /// From `[z, x', phi, theta, phi', theta']`.
    pub fn from_array(a: [f64; 6]) -> Self {
        ApexState {
            z_m: a[0],
            x_dot_mps: a[1],
            phi_rad: a[2],
            theta_rad: a[3],
            phi_dot_rad_s: a[4],
            theta_dot_rad_s: a[5],
        }
    }
}

/// The section 2.2 runner (module docs): fixed-step RK4, transitions
/// located by bisection inside the step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarRunner {
    p: PlanarParams,
    phase: PlanarPhase,
    /// Flight: `[x, z, phi, theta, x', z', phi', theta']`; stance: `[r,
    /// theta, phi, r', theta', phi', 0, 0]`.
    s: [f64; 8],
    t_s: f64,
    stabiliser: Stabiliser,
}

/// The forward-speed stabiliser of eqs 2.79-2.80: in stance the leg's
/// force is less by `F_c = K_c (x_dot_d - x')`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Stabiliser {
    /// `K_c`, N s/m (0: passive).
    pub gain_ns_per_m: f64,
    /// `x_dot_d`, m/s.
    pub speed_mps: f64,
}

impl Stabiliser {
    /// None: passive running.
    pub const PASSIVE: Stabiliser = Stabiliser {
        gain_ns_per_m: 0.0,
        speed_mps: 0.0,
    };

    /// `F_c` at the hip's forward speed `x_dot_mps` (eq 2.79), N.
    pub fn force_n(&self, x_dot_mps: f64) -> f64 {
        self.gain_ns_per_m * (self.speed_mps - x_dot_mps)
    }
}

/// The state in Cartesian form, whatever the phase.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarState {
    /// Time, s.
    pub t_s: f64,
    /// Hip position, m.
    pub x_m: f64,
    /// Hip height, m.
    pub z_m: f64,
    /// Body pitch, rad.
    pub phi_rad: f64,
    /// Leg angle from the vertical (toe ahead positive), rad.
    pub theta_rad: f64,
    /// Hip velocity, m/s.
    pub x_dot_mps: f64,
    /// Hip vertical velocity, m/s.
    pub z_dot_mps: f64,
    /// Body pitch rate, rad/s.
    pub phi_dot_rad_s: f64,
    /// Leg rate, rad/s.
    pub theta_dot_rad_s: f64,
    /// Leg length, m (`r_0` in flight).
    pub leg_length_m: f64,
    /// On the ground.
    pub stance: bool,
}

impl PlanarRunner {
    /// At the apex of a passive design's gait: hip `d.apex_height_m` up,
    /// moving at `speed_mps`, angles zero, the design's rates.
    pub fn at_apex(
        p: PlanarParams,
        d: &PassiveDesign,
        speed_mps: f64,
    ) -> Result<Self, PlanarError> {
        Self::from_apex(p, &ApexState::of_design(d, speed_mps))
    }

    /// At `apex` (forward position 0, time 0), passive until
    /// [`PlanarRunner::stabilised`].
    pub fn from_apex(p: PlanarParams, apex: &ApexState) -> Result<Self, PlanarError> {
        p.validate()?;
        Ok(PlanarRunner {
            p,
            phase: PlanarPhase::Flight,
            s: apex.flight_state(),
            t_s: 0.0,
            stabiliser: Stabiliser::PASSIVE,
        })
    }

    /// With the forward-speed stabiliser of eqs 2.79-2.80: in stance the
    /// leg force is `k_l (r_0 - r) - K_c (x_dot_d - x')`.
    pub fn stabilised(mut self, gain_ns_per_m: f64, speed_mps: f64) -> Self {
        self.stabiliser = Stabiliser {
            gain_ns_per_m,
            speed_mps,
        };
        self
    }

    /// The phase.
    pub fn phase(&self) -> PlanarPhase {
        self.phase
    }

    /// The state in Cartesian form.
    pub fn state(&self) -> PlanarState {
        let s = &self.s;
        match self.phase {
            PlanarPhase::Flight => PlanarState {
                t_s: self.t_s,
                x_m: s[0],
                z_m: s[1],
                phi_rad: s[2],
                theta_rad: s[3],
                x_dot_mps: s[4],
                z_dot_mps: s[5],
                phi_dot_rad_s: s[6],
                theta_dot_rad_s: s[7],
                leg_length_m: self.p.leg_rest_length_m,
                stance: false,
            },
            PlanarPhase::Stance { toe_x_m } => {
                let (r, th, rd, thd) = (s[0], s[1], s[3], s[4]);
                let (sn, cs) = (libm::sin(th), libm::cos(th));
                PlanarState {
                    t_s: self.t_s,
                    x_m: toe_x_m - r * sn,
                    z_m: r * cs,
                    phi_rad: s[2],
                    theta_rad: th,
                    x_dot_mps: -rd * sn - r * cs * thd,
                    z_dot_mps: rd * cs - r * sn * thd,
                    phi_dot_rad_s: s[5],
                    theta_dot_rad_s: thd,
                    leg_length_m: r,
                    stance: true,
                }
            }
        }
    }

    /// The leg's force along it, `k_l (r_0 - r) - F_c` (eq 2.80), N (0 in
    /// flight).
    pub fn leg_force_n(&self) -> f64 {
        let q = self.state();
        if q.stance {
            self.p.leg_stiffness_n_per_m * (self.p.leg_rest_length_m - q.leg_length_m)
                - self.stabiliser.force_n(q.x_dot_mps)
        } else {
            0.0
        }
    }

    /// The stabiliser's force `F_c` (eq 2.79), N (0 in flight).
    pub fn stabiliser_force_n(&self) -> f64 {
        let q = self.state();
        if q.stance {
            self.stabiliser.force_n(q.x_dot_mps)
        } else {
            0.0
        }
    }

    /// Total mechanical energy (kinetic, gravity from the ground, both
    /// springs), J.
    pub fn energy_j(&self) -> f64 {
        let q = self.state();
        let p = &self.p;
        let m = p.total_mass_kg();
        let spring = p.leg_rest_length_m - q.leg_length_m;
        0.5 * m * (q.x_dot_mps * q.x_dot_mps + q.z_dot_mps * q.z_dot_mps)
            + 0.5 * p.body_inertia_kg_m2 * q.phi_dot_rad_s * q.phi_dot_rad_s
            + 0.5 * p.leg_inertia_kg_m2 * q.theta_dot_rad_s * q.theta_dot_rad_s
            + m * p.gravity_mps2 * q.z_m
            + 0.5
                * p.hip_stiffness_nm_per_rad
                * (q.theta_rad - q.phi_rad)
                * (q.theta_rad - q.phi_rad)
            + 0.5 * p.leg_stiffness_n_per_m * spring * spring
    }

    /// The state's rate in `phase` (eqs 2.54-2.57 in flight; the polar
    /// stance equations of the module docs, with the stabiliser).
    fn rate(&self, phase: PlanarPhase, s: &[f64; 8]) -> [f64; 8] {
        let p = &self.p;
        let m = p.total_mass_kg();
        let g = p.gravity_mps2;
        match phase {
            PlanarPhase::Flight => {
                let hip = p.hip_stiffness_nm_per_rad * (s[3] - s[2]);
                [
                    s[4],
                    s[5],
                    s[6],
                    s[7],
                    0.0,
                    -g,
                    hip / p.body_inertia_kg_m2,
                    -hip / p.leg_inertia_kg_m2,
                ]
            }
            PlanarPhase::Stance { .. } => {
                let (r, th, ph, rd, thd, phd) = (s[0], s[1], s[2], s[3], s[4], s[5]);
                let (sn, cs) = (libm::sin(th), libm::cos(th));
                let x_dot = -rd * sn - r * cs * thd;
                let force = p.leg_stiffness_n_per_m * (p.leg_rest_length_m - r)
                    - self.stabiliser.force_n(x_dot);
                let hip = p.hip_stiffness_nm_per_rad * (th - ph);
                let rdd = r * thd * thd + force / m - g * cs;
                let thdd = (m * g * r * sn - hip - 2.0 * m * r * rd * thd)
                    / (m * r * r + p.leg_inertia_kg_m2);
                [
                    rd,
                    thd,
                    phd,
                    rdd,
                    thdd,
                    hip / p.body_inertia_kg_m2,
                    0.0,
                    0.0,
                ]
            }
        }
    }

    /// Advances `dt_s`, reporting transitions (and apexes) to `on_event`.
    pub fn step(&mut self, dt_s: f64, on_event: &mut impl FnMut(PlanarEvent)) {
        step_hybrid(self, dt_s, on_event);
    }

    /// Runs in steps of `dt_s` to the next apex, at most `max_s`: that
    /// apex and what its touchdown took, or `None` if the hip fell below
    /// half the leg's length or no apex came.
    pub fn next_apex(&mut self, dt_s: f64, max_s: f64) -> Option<(ApexState, f64)> {
        let floor = 0.5 * self.p.leg_rest_length_m;
        next_apex_hybrid(self, dt_s, max_s, floor, |r| r.state().z_m)
    }

    /// Touchdown (the plastic impact across the leg) or liftoff at `at`.
    fn transition_at(&mut self, at: &[f64; 8], on_event: &mut dyn FnMut(PlanarEvent)) {
        let r0 = self.p.leg_rest_length_m;
        match self.phase {
            PlanarPhase::Flight => {
                // The toe may not slide: a plastic impact across the leg
                // (along it the massless spring gives way) stops the toe's
                // velocity across the leg, `v_n = x' cos + z' sin + r_0
                // theta'`, with the impulse `lambda = v_n / (1/m + r_0^2 /
                // J_l)` through `G = [cos, sin, 0, r_0]`: it takes `v_n
                // lambda / 2` (nothing when the toe lands without sliding
                // speed, as the passive design aims).
                let (x, th, xd, zd, thd) = (at[0], at[3], at[4], at[5], at[7]);
                let (sn, cs) = (libm::sin(th), libm::cos(th));
                let m = self.p.total_mass_kg();
                let j = self.p.leg_inertia_kg_m2;
                let v_n = xd * cs + zd * sn + r0 * thd;
                let lambda = v_n / (1.0 / m + r0 * r0 / j);
                let (xd, zd) = (xd - cs * lambda / m, zd - sn * lambda / m);
                let thd = thd - r0 * lambda / j;
                let loss = 0.5 * v_n * lambda;
                let rd = -xd * sn + zd * cs;
                self.phase = PlanarPhase::Stance {
                    toe_x_m: x + r0 * sn,
                };
                self.s = [r0, th, at[2], rd, thd, at[6], 0.0, 0.0];
                on_event(PlanarEvent::Touchdown {
                    t_s: self.t_s,
                    loss_j: loss,
                });
            }
            PlanarPhase::Stance { toe_x_m } => {
                let (th, rd, thd) = (at[1], at[3], at[4]);
                let (sn, cs) = (libm::sin(th), libm::cos(th));
                self.phase = PlanarPhase::Flight;
                self.s = [
                    toe_x_m - r0 * sn,
                    r0 * cs,
                    at[2],
                    th,
                    -rd * sn - r0 * cs * thd,
                    rd * cs - r0 * sn * thd,
                    at[5],
                    thd,
                ];
                on_event(PlanarEvent::Liftoff {
                    t_s: self.t_s,
                    loss_j: 0.0,
                });
            }
        }
    }
}

/// A planar runner as the shared stepper sees it: an 8-element state whose
/// flight layout is `[x, z, phi, theta, x', z', phi', theta']` and whose
/// stance layout starts with the leg's length, the leg's length at its
/// stop, and the transition that ends a phase.
/// [`PlanarRunner`] and [`crate::planar_general::GeneralRunner`] both run
/// on [`step_hybrid`].
pub(crate) trait Hybrid {
    /// In flight (the apex and the landing are looked for).
    fn in_flight(&self) -> bool;
    /// The state's rate in the present phase.
    fn rate_of(&self, s: &[f64; 8]) -> [f64; 8];
    /// The leg's length at its stop (the leg spring's rest), m.
    fn leg_length_m(&self) -> f64;
    /// Positive within the present phase; its fall through 0 ends it.
    /// Flight: the toe's height; stance: the leg's distance from its stop.
    fn guard_of(&self, s: &[f64; 8]) -> f64 {
        if self.in_flight() {
            s[1] - self.leg_length_m() * libm::cos(s[3])
        } else {
            self.leg_length_m() - s[0]
        }
    }
    /// Gravity, m/s^2 (the apex within a step is found by the flight's
    /// exact parabola).
    fn gravity(&self) -> f64;
    /// The state and the time.
    fn state_time(&mut self) -> (&mut [f64; 8], &mut f64);
    /// Ends the phase at `at` (the state where the guard reached 0).
    fn transition(&mut self, at: &[f64; 8], on_event: &mut dyn FnMut(PlanarEvent));
}

/// One classical RK4 step of `h` in `m`'s present phase.
pub(crate) fn rk4<H: Hybrid>(m: &H, s: &[f64; 8], h: f64) -> [f64; 8] {
    let add = |a: &[f64; 8], b: &[f64; 8], k: f64| {
        let mut o = *a;
        for (o, b) in o.iter_mut().zip(b) {
            *o += k * b;
        }
        o
    };
    let k1 = m.rate_of(s);
    let k2 = m.rate_of(&add(s, &k1, h / 2.0));
    let k3 = m.rate_of(&add(s, &k2, h / 2.0));
    let k4 = m.rate_of(&add(s, &k3, h));
    let mut o = *s;
    for i in 0..8 {
        o[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    o
}

/// Advances `m` by `dt_s`: fixed-step RK4, a transition located by
/// bisection on the step fraction (60 halvings: to rounding), at most four
/// in one step; an apex reported when the hip's vertical speed passes 0 in
/// flight. Flight ends when the guard falls through 0 with the hip moving
/// down; stance when it falls through 0.
pub(crate) fn step_hybrid<H: Hybrid>(m: &mut H, dt_s: f64, on_event: &mut impl FnMut(PlanarEvent)) {
    let mut left = dt_s;
    for _ in 0..4 {
        if left <= 0.0 {
            break;
        }
        let s = *m.state_time().0;
        let t = *m.state_time().1;
        let next = rk4(m, &s, left);
        let (g0, g1) = (m.guard_of(&s), m.guard_of(&next));
        let flight = m.in_flight();
        let crossed = g0 > 0.0 && g1 <= 0.0 && (!flight || next[5] < 0.0);
        if flight && s[5] > 0.0 && next[5] <= 0.0 && !crossed {
            // The apex within the step: z' = 0. The hip's height is the
            // flight's exact parabola when the hip is the centre of mass
            // (section 2.2); with Appendix A's offsets it is not quite,
            // and a few Newton steps with z'' ~ -g finish the root.
            let g = m.gravity();
            let mut tau = s[5] / g;
            let mut at = rk4(m, &s, tau);
            for _ in 0..4 {
                if at[5].abs() < 1e-12 {
                    break;
                }
                tau += at[5] / g;
                at = rk4(m, &s, tau);
            }
            on_event(PlanarEvent::Apex {
                t_s: t + tau,
                apex: ApexState {
                    z_m: at[1],
                    x_dot_mps: at[4],
                    phi_rad: at[2],
                    theta_rad: at[3],
                    phi_dot_rad_s: at[6],
                    theta_dot_rad_s: at[7],
                },
            });
        }
        if !crossed {
            *m.state_time().0 = next;
            *m.state_time().1 = t + left;
            break;
        }
        let (mut lo, mut hi) = (0.0, left);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if m.guard_of(&rk4(m, &s, mid)) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let at = rk4(m, &s, hi);
        *m.state_time().1 = t + hi;
        left -= hi;
        m.transition(&at, &mut |e| on_event(e));
    }
}

/// Runs `m` in steps of `dt_s` to its next apex, at most `max_s`: that
/// apex and what the touchdowns on the way took, or `None` if the hip
/// (`hip_z`) fell below `floor_m` or no apex came.
pub(crate) fn next_apex_hybrid<H: Hybrid>(
    m: &mut H,
    dt_s: f64,
    max_s: f64,
    floor_m: f64,
    hip_z: impl Fn(&H) -> f64,
) -> Option<(ApexState, f64)> {
    let mut loss = 0.0;
    let mut found = None;
    let t_end = *m.state_time().1 + max_s;
    while found.is_none() && *m.state_time().1 < t_end {
        step_hybrid(m, dt_s, &mut |e| match e {
            PlanarEvent::Apex { apex, .. } => found = Some(apex),
            PlanarEvent::Touchdown { loss_j, .. } => loss += loss_j,
            PlanarEvent::Liftoff { .. } => {}
        });
        if hip_z(m) < floor_m {
            return None;
        }
    }
    found.map(|a| (a, loss))
}

impl Hybrid for PlanarRunner {
    fn in_flight(&self) -> bool {
        matches!(self.phase, PlanarPhase::Flight)
    }
    fn rate_of(&self, s: &[f64; 8]) -> [f64; 8] {
        self.rate(self.phase, s)
    }
    fn leg_length_m(&self) -> f64 {
        self.p.leg_rest_length_m
    }
    fn gravity(&self) -> f64 {
        self.p.gravity_mps2
    }
    fn state_time(&mut self) -> (&mut [f64; 8], &mut f64) {
        (&mut self.s, &mut self.t_s)
    }
    fn transition(&mut self, at: &[f64; 8], on_event: &mut dyn FnMut(PlanarEvent)) {
        self.transition_at(at, on_event);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE_GAIT: Gait = Gait::table_2_2(2.0);

    /// Table 2.2's springs are the design's for its T_step = 0.5 s and rho
    /// = 0.125: 28.4 N m/rad and 40 425 N/m.
    #[test]
    fn table_2_2_springs_follow_from_the_passive_design() {
        let p = PlanarParams::table_2_2();
        let d = passive_design(&p, &TABLE_GAIT).unwrap_or_else(|e| panic!("{e:?}"));
        assert!((d.hip_stiffness_nm_per_rad - 28.4).abs() < 0.05, "{d:?}");
        assert!((d.leg_stiffness_n_per_m - 40_425.0).abs() < 2.0, "{d:?}");
        // And rho = omega_h / (2 omega_l) (eq 2.74) with them.
        assert!((p.hip_rate_rad_s() / (2.0 * p.leg_rate_rad_s()) - 0.125).abs() < 1e-3);
    }

    /// The initial conditions at 2 and 4 m/s (eqs 2.76-2.78).
    #[test]
    fn initial_conditions_at_2_and_4_mps() {
        let p = PlanarParams::table_2_2();
        for (v, theta0, phi0, z) in [
            (2.0, 3.0769, -0.8630, 0.8819),
            (4.0, 6.1538, -1.7261, 0.8733),
        ] {
            let d = passive_design(&p, &Gait::table_2_2(v)).unwrap_or_else(|e| panic!("{e:?}"));
            assert!((d.leg_rate0_rad_s - theta0).abs() < 1e-4, "{d:?}");
            assert!((d.body_rate0_rad_s - phi0).abs() < 1e-4, "{d:?}");
            assert!((d.flight_time_s - 0.4375).abs() < 1e-12);
            assert!((d.apex_height_m - z).abs() < 1e-4, "{v}: {d:?}");
            // Zero angular momentum about the hip in flight.
            let h =
                p.body_inertia_kg_m2 * d.body_rate0_rad_s + p.leg_inertia_kg_m2 * d.leg_rate0_rad_s;
            assert!(h.abs() < 1e-12);
        }
    }

    #[test]
    fn bad_gaits_and_parameters_are_refused_by_name() {
        let p = PlanarParams::table_2_2();
        let g = |rho| Gait {
            stance_fraction: rho,
            ..TABLE_GAIT
        };
        assert_eq!(
            passive_design(&p, &g(0.0)),
            Err(PlanarError::StanceFraction)
        );
        assert_eq!(
            passive_design(&p, &g(1.0)),
            Err(PlanarError::StanceFraction)
        );
        assert_eq!(
            passive_design(&p, &g(f64::NAN)),
            Err(PlanarError::StanceFraction)
        );
        let bad = PlanarParams {
            leg_inertia_kg_m2: -1.0,
            ..p
        };
        assert_eq!(
            passive_design(&bad, &TABLE_GAIT),
            Err(PlanarError::NotPositive("leg_inertia_kg_m2"))
        );
    }

    /// Running from the design's apex, 5 s: passive at 2 m/s nearly
    /// reentrant (the apexes within 2 cm of the design's, 0.025 J taken by
    /// the touchdowns), passive at 4 m/s drifting (Figures 2.18-2.20: the
    /// apexes 0.63-1.19 m, falling within four hops), and 4 m/s with the
    /// stabiliser of eq 2.79 at K_c = 1000 holding them within 2 cm again
    /// (Figures 2.21-2.22). Passive, the energy is conserved to 1e-6 J a
    /// hop apart from what the touchdowns report, and in flight the
    /// angular momentum about the hip holds.
    #[test]
    fn passive_running_conserves_energy_and_drifts_at_4_mps() {
        let p = PlanarParams::table_2_2();
        for (v, kc, drift_lo, drift_hi) in [
            (2.0, 0.0, 0.0, 0.02),
            (4.0, 0.0, 0.02, 10.0),
            (4.0, 1000.0, 0.0, 0.02),
        ] {
            let d = passive_design(&p, &Gait::table_2_2(v)).unwrap_or_else(|e| panic!("{e:?}"));
            let mut r = PlanarRunner::at_apex(p, &d, v)
                .unwrap_or_else(|e| panic!("{e:?}"))
                .stabilised(kc, v);
            let e0 = r.energy_j();
            let mut lost = 0.0;
            let mut apexes = std::vec::Vec::new();
            let mut touchdowns = 0;
            let mut last_h: Option<(bool, f64)> = None;
            for _ in 0..(5.0 / 1e-4) as usize {
                r.step(1e-4, &mut |e| match e {
                    PlanarEvent::Touchdown { loss_j, .. } => {
                        lost += loss_j;
                        touchdowns += 1;
                    }
                    PlanarEvent::Apex { apex, .. } => apexes.push(apex.z_m),
                    PlanarEvent::Liftoff { .. } => {}
                });
                let q = r.state();
                // The hip spring is internal: in flight the angular
                // momentum about the hip holds (the ground's force across
                // the leg changes it in stance).
                let h = p.body_inertia_kg_m2 * q.phi_dot_rad_s
                    + p.leg_inertia_kg_m2 * q.theta_dot_rad_s;
                if let (false, Some((false, h0))) = (q.stance, last_h) {
                    assert!((h - h0).abs() < 1e-9, "{v}: angular momentum {h0} -> {h}");
                }
                last_h = Some((q.stance, h));
                if q.z_m < 0.3 {
                    break;
                }
            }
            let e1 = r.energy_j();
            std::eprintln!("{v} m/s, K_c {kc}: {touchdowns} touchdowns, lost {lost:.4} J, energy {e0:.4} -> {e1:.4}, apexes {apexes:?}");
            // (The stabiliser's force does work: no bookkeeping for it.)
            if kc == 0.0 {
                assert!(
                    (e0 - lost - e1).abs() < 1e-6 * f64::from(touchdowns.max(1)),
                    "{e0} {lost} {e1}"
                );
            }
            assert!(touchdowns >= 5, "{touchdowns}");
            if drift_hi < 1.0 {
                assert!(
                    touchdowns >= 9,
                    "{v} m/s, K_c {kc}: {touchdowns} touchdowns in 5 s"
                );
            }
            let spread = apexes
                .iter()
                .fold(0.0f64, |m, a| m.max((a - d.apex_height_m).abs()));
            assert!(
                spread >= drift_lo && spread < drift_hi,
                "{v}: apex spread {spread}"
            );
        }
    }

    /// The passive-dynamics conditions (sections 2.2.2.4-2.2.2.5) as the
    /// runner meets them from the design's apex at 2 m/s: the hip swings
    /// by eq 2.72 exactly, so the toe lands at half the flight time
    /// `T_step (1 - rho) / 2` = 0.21875 s with the design's leg angle; the
    /// stance lasts 63.85 ms, between eq 2.66's `rho T_step` = 62.5 ms and
    /// eq 2.67's 66.1 ms for a vertical bounce with gravity (the leg here
    /// sweeps through the stance).
    #[test]
    fn the_design_meets_its_passive_dynamics_conditions() {
        let table = PlanarParams::table_2_2();
        let d = passive_design(&table, &TABLE_GAIT).unwrap_or_else(|e| panic!("{e:?}"));
        // The design's springs, not Table 2.2's rounded ones.
        let p = PlanarParams {
            hip_stiffness_nm_per_rad: d.hip_stiffness_nm_per_rad,
            leg_stiffness_n_per_m: d.leg_stiffness_n_per_m,
            ..table
        };
        let mut r = PlanarRunner::at_apex(p, &d, 2.0).unwrap_or_else(|e| panic!("{e:?}"));
        let (mut landed, mut lifted) = (None, None);
        let mut angle = 0.0;
        for _ in 0..10_000 {
            if lifted.is_some() {
                break;
            }
            let before = r;
            r.step(1e-4, &mut |e| match e {
                PlanarEvent::Touchdown { t_s, .. } => landed = Some(t_s),
                PlanarEvent::Liftoff { t_s, .. } => lifted = Some(t_s),
                PlanarEvent::Apex { .. } => {}
            });
            if landed.is_some() && angle == 0.0 {
                angle = before.state().theta_rad;
                // Eq 2.72 in flight, to RK4's error.
                let w = p.hip_rate_rad_s();
                let t = before.state().t_s;
                let exact = d.leg_rate0_rad_s / w * libm::sin(w * t);
                assert!((angle - exact).abs() < 1e-9, "{angle} {exact}");
            }
        }
        let (td, lo) = (landed.unwrap_or(0.0), lifted.unwrap_or(0.0));
        std::eprintln!(
            "touchdown {td} (design {}), stance {} s",
            d.flight_time_s / 2.0,
            lo - td
        );
        assert!(
            (td - d.flight_time_s / 2.0).abs() < 1e-9,
            "touchdown at {td}"
        );
        // Eq 2.66's rho T_step = 62.5 ms and eq 2.67's exact vertical
        // bounce (gravity in stance, landing at g T_f / 2 = 2.146 m/s) 66.1
        // ms: the runner's 63.85 ms lies between.
        let stance = lo - td;
        let w = p.leg_rate_rad_s();
        let v = p.gravity_mps2 * d.flight_time_s / 2.0;
        let exact = 2.0 * (PI - libm::atan(v * w / p.gravity_mps2)) / w;
        assert!(
            (PI / w - 0.0625).abs() < 1e-9 && (exact - 0.0661).abs() < 1e-4,
            "{exact}"
        );
        assert!((stance - 0.06385).abs() < 1e-4, "stance {stance}");
    }
}
