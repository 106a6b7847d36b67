//! The equations of motion: the constants derived once per parameter set,
//! the configuration (which equations and constraints hold), the forces,
//! the accelerations and the RK4 step through them.

use super::{Mode, NutStop, Plant, State};
use crate::amplifier::SupplyWindow;
use crate::params::Params;

/// Constants derived once from [`Params`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Coef {
    pub(super) m_body_nut: f64,
    pub(super) m_total: f64,
    pub(super) m_nut: f64,
    pub(super) m_u: f64,
    pub(super) m_body: f64,
    pub(super) alpha: f64,
    pub(super) r: f64,
    pub(super) g: f64,
    pub(super) k: f64,
    pub(super) c: f64,
    pub(super) preload: f64,
    pub(super) l0: f64,
    pub(super) f_flight: f64,
    pub(super) f_stance: f64,
    pub(super) stroke: f64,
    pub(super) kt: f64,
    pub(super) supply: f64,
    pub(super) i_limit: f64,
    // Derived once, so that the derivative evaluation (four per RK4 step)
    // has no divisions: products with reciprocals instead of quotients
    // (results differ from the quotients by float rounding only).
    /// The amplifier's supply window.
    pub(super) window: SupplyWindow,
    /// `eta / r`.
    pub(super) eta_over_r: f64,
    /// `m_s g`.
    pub(super) nut_weight: f64,
    /// `-(M + m_s) g`.
    pub(super) neg_weight_stance: f64,
    /// `-m_t g`.
    pub(super) neg_weight_flight: f64,
    /// Inverse mass matrices (both coordinates free), flight and stance.
    pub(super) inv_flight: InvMass,
    pub(super) inv_stance: InvMass,
    /// `1 / alpha`.
    pub(super) inv_alpha: f64,
    /// Winding resistance `R`, ohm.
    pub(super) resistance: f64,
    /// `r / k_t`: nut speed per volt of back-EMF.
    pub(super) r_over_kt: f64,
}

/// The accelerations of one configuration as affine functions of the drive
/// force `eta tau / r` and the spring force `fs` (what [`Plant::accel`]
/// computes, regrouped): `zdd = z0 + z_drive drive + z_spring fs`, and the
/// same for `pdd`.
#[derive(Clone, Copy, Debug)]
pub(super) struct Linear {
    pub(super) z0: f64,
    pub(super) z_drive: f64,
    pub(super) z_spring: f64,
    pub(super) p0: f64,
    pub(super) p_drive: f64,
    pub(super) p_spring: f64,
    /// `d z0 / d friction` and `d p0 / d friction`: only [`StepMap`] uses
    /// them (it takes the friction force as an input, so one map serves both
    /// sliding directions); the derivative has it folded into `z0`, `p0`.
    pub(super) z_friction: f64,
    pub(super) p_friction: f64,
}

impl Linear {
    /// For the configuration (stance equations, body free, nut free), with
    /// friction force `friction` (`level * z_dir`) on a sliding body.
    #[inline(always)]
    pub(super) fn new<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(
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

/// Inverse of the 2x2 mass matrix `[[m_zz, -m_s], [-m_s, alpha]]`:
/// `zdd = zz f_z + zp f_p`, `pdd = zp f_z + pp f_p`, and `1 / m_zz` for the
/// nut held on a stop.
#[derive(Clone, Copy, Debug)]
pub(super) struct InvMass {
    pub(super) zz: f64,
    pub(super) zp: f64,
    pub(super) pp: f64,
    pub(super) inv_m_zz: f64,
}

impl InvMass {
    pub(super) fn new(m_zz: f64, alpha: f64, m_nut: f64) -> Self {
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
    pub(super) fn new(p: &Params) -> Self {
        let r = p.screw_m_per_rad();
        let alpha = p.reflected_inertia_kg();
        let m_body_nut = p.body_mass_kg + p.nut_mass_kg;
        let m_total = p.body_mass_kg + p.nut_mass_kg + p.unsprung_mass_kg;
        let g = p.gravity_mps2;
        Coef {
            window: SupplyWindow::new(
                p.torque_constant_nm_per_a,
                r,
                p.winding_resistance_ohm,
                p.supply_voltage_v,
            ),
            eta_over_r: p.efficiency / r,
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
    /// clipped to the amplifier's current limit, the nut at `pd_mps`: its
    /// supply window ([`SupplyWindow::current_a`]).
    #[inline(always)]
    pub(super) fn motor_current_from_pd(&self, cmd_limited_a: f64, pd_mps: f64) -> f64 {
        self.window.current_a(cmd_limited_a, pd_mps)
    }
}

/// Which equations hold: the dynamics formulation and the constraints.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Config {
    pub(super) mode: Mode,
    pub(super) z_stuck: bool,
    /// Sign of `zd` while sliding (+1 / -1); friction is `-F * z_dir`.
    pub(super) z_dir: f64,
    pub(super) nut: NutStop,
}

impl Config {
    pub(super) fn z_locked(&self) -> bool {
        self.z_stuck || self.mode == Mode::Standing
    }
    pub(super) fn stance_equations(&self) -> bool {
        self.mode != Mode::Flight
    }
}

/// The state RK4 integrates: the mechanical state and the ledger's work
/// integrals, which take the same stages so that the books close to the
/// integration error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct AugState {
    /// Body height `z`, m.
    pub(super) z_m: f64,
    /// Body velocity, m/s.
    pub(super) zd_mps: f64,
    /// Nut displacement `p`, m.
    pub(super) p_m: f64,
    /// Nut velocity relative to the body, m/s.
    pub(super) pd_mps: f64,
    /// Net motor work on the nut since the start, J.
    pub(super) motor_work_j: f64,
    /// Dry friction dissipation since the start, J.
    pub(super) friction_work_j: f64,
    /// Spring damping dissipation since the start, J.
    pub(super) damping_work_j: f64,
    /// `int i^2 dt` of the motor current since the start, A^2 s (times
    /// the winding's resistance, the copper loss).
    pub(super) current_sq_a2s: f64,
}

impl AugState {
    /// `s` with the work integrals at zero.
    pub(super) fn at_rest_books(s: &State) -> Self {
        AugState {
            z_m: s.z_m,
            zd_mps: s.zd_mps,
            p_m: s.p_m,
            pd_mps: s.pd_mps,
            motor_work_j: 0.0,
            friction_work_j: 0.0,
            damping_work_j: 0.0,
            current_sq_a2s: 0.0,
        }
    }

    /// Every component finite.
    pub(super) fn is_finite(&self) -> bool {
        self.z_m.is_finite()
            && self.zd_mps.is_finite()
            && self.p_m.is_finite()
            && self.pd_mps.is_finite()
            && self.motor_work_j.is_finite()
            && self.friction_work_j.is_finite()
            && self.damping_work_j.is_finite()
            && self.current_sq_a2s.is_finite()
    }

    /// `self + dt_s k`: an RK4 stage's argument.
    #[inline(always)]
    fn stage(&self, k: &Rates, dt_s: f64) -> Self {
        AugState {
            z_m: self.z_m + dt_s * k.zd_mps,
            zd_mps: self.zd_mps + dt_s * k.zdd_mps2,
            p_m: self.p_m + dt_s * k.pd_mps,
            pd_mps: self.pd_mps + dt_s * k.pdd_mps2,
            motor_work_j: self.motor_work_j + dt_s * k.motor_power_w,
            friction_work_j: self.friction_work_j + dt_s * k.friction_power_w,
            damping_work_j: self.damping_work_j + dt_s * k.damping_power_w,
            current_sq_a2s: self.current_sq_a2s + dt_s * k.current_sq_a2,
        }
    }

    /// The RK4 step of length `h_s` from `self` with stage derivatives
    /// `k`: `y0 + h/6 (k1 + 2 k2 + 2 k3 + k4)` per component.
    #[inline(always)]
    fn rk4_combine(&self, k: [&Rates; 4], h_s: f64) -> Self {
        let w = h_s / 6.0;
        let [k1, k2, k3, k4] = k;
        // Written out per component, in the order the array form summed.
        let sum = |a: f64, b: f64, c: f64, d: f64| w * (a + 2.0 * b + 2.0 * c + d);
        AugState {
            z_m: self.z_m + sum(k1.zd_mps, k2.zd_mps, k3.zd_mps, k4.zd_mps),
            zd_mps: self.zd_mps + sum(k1.zdd_mps2, k2.zdd_mps2, k3.zdd_mps2, k4.zdd_mps2),
            p_m: self.p_m + sum(k1.pd_mps, k2.pd_mps, k3.pd_mps, k4.pd_mps),
            pd_mps: self.pd_mps + sum(k1.pdd_mps2, k2.pdd_mps2, k3.pdd_mps2, k4.pdd_mps2),
            motor_work_j: self.motor_work_j
                + sum(
                    k1.motor_power_w,
                    k2.motor_power_w,
                    k3.motor_power_w,
                    k4.motor_power_w,
                ),
            friction_work_j: self.friction_work_j
                + sum(
                    k1.friction_power_w,
                    k2.friction_power_w,
                    k3.friction_power_w,
                    k4.friction_power_w,
                ),
            damping_work_j: self.damping_work_j
                + sum(
                    k1.damping_power_w,
                    k2.damping_power_w,
                    k3.damping_power_w,
                    k4.damping_power_w,
                ),
            current_sq_a2s: self.current_sq_a2s
                + sum(
                    k1.current_sq_a2,
                    k2.current_sq_a2,
                    k3.current_sq_a2,
                    k4.current_sq_a2,
                ),
        }
    }

    /// The components in a fixed order, for the tests' comparisons.
    #[cfg(test)]
    pub(super) fn to_array(self) -> [f64; 8] {
        [
            self.z_m,
            self.zd_mps,
            self.p_m,
            self.pd_mps,
            self.motor_work_j,
            self.friction_work_j,
            self.damping_work_j,
            self.current_sq_a2s,
        ]
    }
}

/// Time derivative of an [`AugState`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Rates {
    zd_mps: f64,
    zdd_mps2: f64,
    pd_mps: f64,
    pdd_mps2: f64,
    /// `drive pd`, W.
    motor_power_w: f64,
    /// `friction zd`, W.
    friction_power_w: f64,
    /// `c rate^2`, W.
    damping_power_w: f64,
    /// `i^2`, A^2.
    current_sq_a2: f64,
}

/// Generalised forces (friction excluded).
#[derive(Clone, Copy)]
pub(super) struct Forces {
    pub(super) f_z: f64,
    pub(super) f_p: f64,
}

impl Plant {
    pub(super) fn compression(c: &Coef, stance: bool, y: &AugState) -> f64 {
        if stance {
            c.preload + c.l0 - y.z_m + y.p_m
        } else {
            c.preload + y.p_m
        }
    }

    pub(super) fn kinetic(c: &Coef, m_zz: f64, zd: f64, pd: f64) -> f64 {
        0.5 * c.alpha * pd * pd + 0.5 * m_zz * zd * zd - c.m_nut * zd * pd
    }

    pub(super) fn energy(c: &Coef, mode: Mode, y: &AugState) -> f64 {
        let (z, zd, p, pd) = (y.z_m, y.zd_mps, y.p_m, y.pd_mps);
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
    pub(super) fn forces(&self, cfg: &Config, y: &AugState) -> Forces {
        let c = &self.c;
        let (zd, pd) = (y.zd_mps, y.pd_mps);
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

    pub(super) fn inv_mass(&self, cfg: &Config) -> &InvMass {
        if cfg.stance_equations() {
            &self.c.inv_stance
        } else {
            &self.c.inv_flight
        }
    }

    pub(super) fn m_zz(&self, cfg: &Config) -> f64 {
        if cfg.stance_equations() {
            self.c.m_body_nut
        } else {
            self.c.m_total
        }
    }

    pub(super) fn friction_level(&self, cfg: &Config) -> f64 {
        if cfg.stance_equations() {
            self.c.f_stance
        } else {
            self.c.f_flight
        }
    }

    /// Accelerations `(zdd, pdd)` under the configuration's constraints.
    #[inline(always)]
    pub(super) fn accel(&self, cfg: &Config, f: &Forces) -> (f64, f64) {
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
    pub(super) fn z_hold_force(&self, cfg: &Config, y: &AugState) -> f64 {
        let f = self.forces(cfg, y);
        let pdd = if cfg.nut == NutStop::Free {
            f.f_p * self.c.inv_alpha
        } else {
            0.0
        };
        -f.f_z - self.c.m_nut * pdd
    }

    /// Force on `p` needed to hold the nut still (down positive), N.
    pub(super) fn p_hold_force(&self, cfg: &Config, y: &AugState) -> f64 {
        let f = self.forces(cfg, y);
        let mut held = *cfg;
        held.nut = NutStop::Top; // any non-free value: solve with pdd = 0
        let (zdd, _) = self.accel(&held, &f);
        -f.f_p - self.c.m_nut * zdd
    }

    /// One RK4 step of length `h` from `y0` in the present configuration.
    pub(super) fn rk4(&self, y0: &AugState, h: f64) -> AugState {
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
    pub(super) fn rk4_in<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(
        &self,
        y0: &AugState,
        h: f64,
    ) -> AugState {
        let c = &self.c;
        let level = if STANCE { c.f_stance } else { c.f_flight };
        // Friction on z while sliding is `-level * z_dir`.
        let friction = level * self.cfg.z_dir;
        let lin = Linear::new::<STANCE, Z_FREE, P_FREE>(c, friction);
        let d = |y: &AugState| self.deriv_in::<STANCE, Z_FREE, P_FREE>(y, friction, &lin);
        let k1 = d(y0);
        let k2 = d(&y0.stage(&k1, 0.5 * h));
        let k3 = d(&y0.stage(&k2, 0.5 * h));
        let k4 = d(&y0.stage(&k3, h));
        y0.rk4_combine([&k1, &k2, &k3, &k4], h)
    }

    /// Time derivative of the augmented state: [`Self::forces`] and
    /// [`Self::accel`] for one configuration (stance equations, body free,
    /// nut free), with the friction force `friction` (`level * z_dir`) and
    /// the accelerations' affine form `lin` worked out by the caller.
    #[inline(always)]
    pub(super) fn deriv_in<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(
        &self,
        y: &AugState,
        friction: f64,
        lin: &Linear,
    ) -> Rates {
        let c = &self.c;
        let (zd, pd) = (y.zd_mps, y.pd_mps);
        let current_a = c.motor_current_from_pd(self.cmd_limited_a, pd);
        let drive = c.eta_over_r * (c.kt * current_a);
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
        Rates {
            zd_mps: zd,
            zdd_mps2: zdd,
            pd_mps: pd,
            pdd_mps2: pdd,
            motor_power_w: drive * pd,
            friction_power_w: friction_w,
            damping_power_w: c.c * rate * rate,
            current_sq_a2: current_a * current_a,
        }
    }
}
