//! The common RK4 step, precomputed once per configuration as the linear
//! map it is there (no spring damping, the supply not limiting the current).

use super::dynamics::{AugState, Coef, Linear};
use super::{NutStop, Plant};

/// A 4x4 matrix over the mechanical state `x = (z, zd, p, pd)`.
pub(super) type Mat4 = [[f64; 4]; 4];

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
pub(super) struct StepMap {
    /// `M` (the state's increment per unit state).
    pub(super) m: Mat4,
    /// `G` (the increment per unit input).
    pub(super) g: [[f64; 3]; 4],
    /// `pd` at RK4's second to fourth stage minus `pd0`, as rows over `x0`
    /// and `u`: the nut speeds the derivative evaluates the motor current
    /// at, to check that the supply limit stays out of the step.
    pub(super) stage_x: [[f64; 4]; 3],
    pub(super) stage_u: [[f64; 3]; 3],
}

impl StepMap {
    /// For the configuration (stance equations, body free, nut free); only
    /// valid without spring damping (`c = 0`), which the caller checks.
    pub(super) fn new<const STANCE: bool, const Z_FREE: bool, const P_FREE: bool>(
        c: &Coef,
        h: f64,
    ) -> Self {
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
    pub(super) fn from_affine(a: &Mat4, b: &[[f64; 3]; 4], h: f64) -> Self {
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
    pub(super) fn all(c: &Coef, h: f64) -> [StepMap; 8] {
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
    pub(super) const fn index(stance: bool, z_free: bool, p_free: bool) -> usize {
        (stance as usize) << 2 | (z_free as usize) << 1 | p_free as usize
    }

    /// One output of the map, `mx . x + mu . (u, 1)`. Grouped in pairs:
    /// independent products, short dependency chains. Always inlined (as
    /// a closure it was sometimes left out of line in the closed loop).
    #[inline(always)]
    pub(super) fn row(mx: &[f64; 4], mu: &[f64; 3], x: &[f64; 4], u: &[f64; 2]) -> f64 {
        ((mx[0] * x[0] + mx[1] * x[1]) + (mx[2] * x[2] + mx[3] * x[3]))
            + ((mu[0] * u[0] + mu[1] * u[1]) + mu[2])
    }
}

/// [`StepMap`]s for one step length.
#[derive(Clone, Copy, Debug)]
pub(super) struct StepMaps {
    /// The step they are for, s; NaN where they do not apply (spring
    /// damping: the damping work is quadratic in the state).
    pub(super) h_s: f64,
    pub(super) maps: [StepMap; 8],
}

impl StepMaps {
    pub(super) fn new(c: &Coef, h_s: f64) -> Self {
        StepMaps {
            h_s: if c.c == 0.0 { h_s } else { f64::NAN },
            maps: StepMap::all(c, h_s),
        }
    }
}

impl Plant {
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
    pub(super) fn rk4_step<const SPECIALISED: bool>(
        &self,
        y0: &AugState,
        h: f64,
        t_end: f64,
    ) -> AugState {
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
    pub(super) fn rk4_linear<const SPECIALISED: bool>(
        &self,
        y0: &AugState,
        h: f64,
        t_end: f64,
    ) -> Option<AugState> {
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
    pub(super) fn rk4_linear_in<const Z_FREE: bool, const P_FREE: bool>(
        &self,
        y0: &AugState,
        map: &StepMap,
    ) -> Option<AugState> {
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
        let (z, zd, p, pd) = (y0.z_m, y0.zd_mps, y0.p_m, y0.pd_mps);
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
        Some(AugState {
            z_m: z + dz,
            zd_mps: zd + dzd,
            p_m: p + dp,
            pd_mps: pd + dpd,
            motor_work_j: y0.motor_work_j + drive * dp,
            friction_work_j: y0.friction_work_j + friction * dz,
            damping_work_j: y0.damping_work_j,
            // The current is the command throughout (checked above).
            current_sq_a2s: y0.current_sq_a2s + cmd * cmd * self.maps.h_s,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;
    use crate::plant::dynamics::Config;
    use crate::plant::Mode;
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
                            let y0 = AugState {
                                z_m: c.l0 + uniform(-0.05, 0.05),
                                zd_mps: uniform(-2.0, 2.0),
                                p_m: uniform(0.0, c.stroke),
                                pd_mps: uniform(-pd_max, pd_max),
                                motor_work_j: uniform(-5.0, 5.0),
                                friction_work_j: uniform(0.0, 5.0),
                                damping_work_j: uniform(0.0, 5.0),
                                current_sq_a2s: uniform(0.0, 5.0),
                            };
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
                            let components = got
                                .to_array()
                                .into_iter()
                                .zip(want.to_array())
                                .zip(y0.to_array())
                                .enumerate();
                            for (i, ((got_i, want_i), y0_i)) in components {
                                let scale = libm::fabs(want_i).max(libm::fabs(y0_i));
                                assert!(
                                    libm::fabs(got_i - want_i) <= 1e-12 * scale,
                                    "{:?} y0 {y0:?} cmd {cmd}: [{i}] {got_i} vs {want_i}",
                                    plant.cfg,
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
}
