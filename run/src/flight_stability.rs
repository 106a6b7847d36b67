//! Is the flight PD stable at this control rate on this plant?
//!
//! In flight the nut is a driven inertia: `theta_dd = A i`, with
//! `A = k_m / (J + m_s r^2)` (thesis eq 4.3 with the nut's reflected mass).
//! The firmware samples `theta` every control period `T`, differentiates it
//! with the eq 4.1 filter (`v_n = G v_(n-1) + (1 - G)(theta_n - theta_(n-1)) / T`)
//! and commands `i = kp (ref - theta) - kd v`; the amplifier follows with a
//! first-order lag and the plant sees the period's mean current (as in
//! [`crate::sensors::Amplifier`]). Linearised (no saturation, no quantisation)
//! that is a 5-state linear recursion; the loop is stable when every root of
//! its characteristic polynomial lies inside the unit circle.
//!
//! Why not a closed-form rule such as `A kd T < 2` and `kd > kp T / 2`: those
//! hold for the plain finite difference without amplifier lag. The eq 4.1
//! filter (G = 0.9 lags by about 9 periods) and the 0.15 ms amplifier lag
//! move the limit a long way: at 10 kHz with `kp = 20.3` the largest stable
//! `kd` is 51 A s/rad (`A kd T = 0.56`), not 182; at 100 Hz even the eq 4.13
//! gains grow. So the check computes the roots.

use nalgebra::linalg::balancing::balance_parlett_reinsch;
use nalgebra::{Complex, Matrix4, Matrix5, Schur};

use crate::params::Params;

/// The sampled flight loop, linearised.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlightLoop {
    /// Plant gain `A = k_m / (J + m_s r^2)`, rad/s^2 per A.
    pub plant_gain: f64,
    /// Proportional gain, A/rad.
    pub kp: f64,
    /// Derivative gain, A s/rad.
    pub kd: f64,
    /// Control period `T`, s.
    pub dt_s: f64,
    /// Velocity-filter gain `G` of eq 4.1, in `[0, 1)`.
    pub filter_gain: f64,
    /// Amplifier current-loop time constant, s (0: no lag).
    pub amp_tau_s: f64,
}

/// `A = k_m / (J + m_s r^2)` of a parameter set, rad/s^2 per A.
pub fn plant_gain(p: &Params) -> f64 {
    let r = p.screw_m_per_rad();
    p.torque_constant_nm_per_a / (p.rotor_inertia_kg_m2 + p.nut_mass_kg * r * r)
}

impl FlightLoop {
    /// The one-period transition matrix over the state
    /// `[theta, omega, theta_prev, v_prev, i_amp]`.
    fn matrix(&self) -> [[f64; 5]; 5] {
        let (a, t, g) = (self.plant_gain, self.dt_s, self.filter_gain);
        let c = (1.0 - g) / t;
        // Filtered rate and commanded current as rows over the state.
        let v = [c, 0.0, -c, g, 0.0];
        let i = v.map(|x| -self.kd * x);
        let i = [i[0] - self.kp, i[1], i[2], i[3], i[4]];
        // Amplifier: mean over the period and end value (sensors.rs).
        let (mean, decay) = if self.amp_tau_s > 0.0 {
            let x = t / self.amp_tau_s;
            ((1.0 - (-x).exp()) / x, (-x).exp())
        } else {
            (0.0, 0.0)
        };
        let mut i_mean = i.map(|x| (1.0 - mean) * x);
        i_mean[4] += mean;
        let mut i_end = i.map(|x| (1.0 - decay) * x);
        i_end[4] += decay;
        let mut m = [[0.0; 5]; 5];
        for k in 0..5 {
            m[0][k] = 0.5 * a * t * t * i_mean[k];
            m[1][k] = a * t * i_mean[k];
        }
        m[0][0] += 1.0;
        m[0][1] += t;
        m[1][1] += 1.0;
        m[2][0] = 1.0;
        m[3] = v;
        m[4] = i_end;
        m
    }

    /// Largest magnitude of the loop's roots: below 1 is stable. With
    /// `kp = 0` the angle is not fed back and its root sits at exactly 1
    /// (the nut stays where the damping stops it); that root is left out.
    ///
    /// The roots are the transition matrix's eigenvalues: nalgebra's real
    /// Schur form after Parlett-Reinsch balancing (the entries span about
    /// 1e-10 to 1e5 at 100 kHz; balancing by powers of 2 is exact and keeps
    /// the roots near 1 to about 1e-13). With `kp = 0` the loop sees the
    /// angle only through the step `theta - theta_prev`: in the state
    /// `[theta - theta_prev, omega, theta_prev, v_prev, i_amp]` the column
    /// of `theta_prev` is the unit vector, so the root 1 stands alone and
    /// the others are those of the 4 x 4 rest.
    pub fn spectral_radius(&self) -> f64 {
        let m = self.matrix();
        if self.kp == 0.0 {
            // S M S^-1 with S: theta -> theta - theta_prev, i.e. row 0 -=
            // row 2, then column 2 += column 0; theta_prev's row and column
            // dropped.
            let step = |r: usize, c: usize| {
                let mc = |c: usize| {
                    if r == 0 {
                        m[0][c] - m[2][c]
                    } else {
                        m[r][c]
                    }
                };
                if c == 2 {
                    mc(2) + mc(0)
                } else {
                    mc(c)
                }
            };
            const REST: [usize; 4] = [0, 1, 3, 4];
            let mut rest = Matrix4::from_fn(|r, c| step(REST[r], REST[c]));
            balance_parlett_reinsch(&mut rest);
            max_abs(
                Schur::try_new(rest, f64::EPSILON, MAX_SCHUR_ITERATIONS)
                    .map(|s| s.complex_eigenvalues())
                    .as_ref()
                    .map(|e| e.as_slice()),
            )
        } else {
            let mut full = Matrix5::from_fn(|r, c| m[r][c]);
            balance_parlett_reinsch(&mut full);
            max_abs(
                Schur::try_new(full, f64::EPSILON, MAX_SCHUR_ITERATIONS)
                    .map(|s| s.complex_eigenvalues())
                    .as_ref()
                    .map(|e| e.as_slice()),
            )
        }
    }

    /// Whether the linearised loop decays.
    pub fn is_stable(&self) -> bool {
        self.spectral_radius() < 1.0
    }
}

/// Schur iterations before giving up (a 5 x 5 matrix needs a few dozen).
const MAX_SCHUR_ITERATIONS: usize = 10_000;

/// Largest |eigenvalue|, or infinity (unstable) when the Schur iteration
/// did not converge (a non-finite entry).
fn max_abs(eigenvalues: Option<&[Complex<f64>]>) -> f64 {
    eigenvalues.map_or(f64::INFINITY, |e| {
        e.iter().map(|z| z.norm()).fold(0.0, f64::max)
    })
}

/// The stable `kd` interval for this loop's `kp` (other settings as given),
/// or `None` when no `kd` up to 1000 A s/rad is stable. Found on a
/// logarithmic grid and refined by bisection; for messages only.
pub fn stable_kd_range(l: &FlightLoop) -> Option<(f64, f64)> {
    let at = |kd: f64| FlightLoop { kd, ..*l }.is_stable();
    let grid: Vec<f64> = (0..=280)
        .map(|k| 1e-4 * 10f64.powf(k as f64 / 40.0))
        .collect();
    let first = grid.iter().position(|&kd| at(kd))?;
    let last = grid.iter().rposition(|&kd| at(kd))?;
    let refine = |mut stable: f64, mut unstable: f64| {
        for _ in 0..50 {
            let mid = 0.5 * (stable + unstable);
            if at(mid) {
                stable = mid;
            } else {
                unstable = mid;
            }
        }
        stable
    };
    let lo = if first == 0 {
        grid[0]
    } else {
        refine(grid[first], grid[first - 1])
    };
    let hi = if last + 1 == grid.len() {
        grid[last]
    } else {
        refine(grid[last], grid[last + 1])
    };
    Some((lo, hi))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn lp(kp: f64, kd: f64, dt_s: f64, amp_tau_s: f64) -> FlightLoop {
        FlightLoop {
            plant_gain: 110.0,
            kp,
            kd,
            dt_s,
            filter_gain: 0.9,
            amp_tau_s,
        }
    }

    /// Simulate the recursion the matrix describes, step by step, and
    /// measure the growth per period over the last half of a long run.
    fn simulated_growth(l: &FlightLoop) -> f64 {
        let (a, t, g) = (l.plant_gain, l.dt_s, l.filter_gain);
        let (mut th, mut om, mut thp, mut vp, mut ia) = (1.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let x = t / l.amp_tau_s;
        let (mean, decay) = ((1.0 - (-x).exp()) / x, (-x).exp());
        let n = 40_000;
        let mut log = 0.0;
        let mut log_half = 0.0;
        for k in 0..n {
            let v = g * vp + (1.0 - g) * (th - thp) / t;
            let i = -l.kp * th - l.kd * v;
            let im = i + (ia - i) * mean;
            ia = i + (ia - i) * decay;
            thp = th;
            vp = v;
            th += t * om + 0.5 * a * t * t * im;
            om += a * t * im;
            let s = th.abs() + thp.abs() + (om * t).abs() + (vp * t).abs() + ia.abs();
            log += s.ln();
            th /= s;
            om /= s;
            thp /= s;
            vp /= s;
            ia /= s;
            if k == n / 2 {
                log_half = log;
            }
        }
        ((log - log_half) / (n / 2) as f64).exp()
    }

    #[test]
    fn roots_agree_with_a_simulation_of_the_loop() {
        for (kp, kd, dt) in [
            (20.3152, 0.6077, 1e-4),
            (20.3152, 40.0, 1e-4),
            (20.3152, 60.0, 1e-4),
            (20.3152, 0.0, 1e-4),
            (20.3152, 5.0, 1e-3),
            (20.3152, 0.6077, 1e-2),
        ] {
            let l = lp(kp, kd, dt, 1.5e-4);
            let (rho, sim) = (l.spectral_radius(), simulated_growth(&l));
            assert!(
                (rho - sim).abs() < 1e-4,
                "{l:?}: roots {rho}, simulated {sim}"
            );
        }
    }

    #[test]
    fn eq_4_13_gains_are_stable_at_10_khz_and_the_limits_are_where_found() {
        assert!(lp(20.3152, 0.6077, 1e-4, 1.5e-4).is_stable());
        // Position feedback without damping grows (product of roots > 1).
        assert!(!lp(20.3152, 0.0, 1e-4, 1.5e-4).is_stable());
        // Damping only: the angle root at 1 is left out, the rest decay.
        assert!(lp(0.0, 1.0, 1e-4, 1.5e-4).is_stable());
        let (lo, hi) = stable_kd_range(&lp(20.3152, 1.0, 1e-4, 1.5e-4)).unwrap();
        assert!(lo < 0.01 && (50.0..52.0).contains(&hi), "{lo} {hi}");
        // Without the filter lag and amplifier the textbook limit
        // A kd T < 2 comes back.
        let plain = FlightLoop {
            filter_gain: 0.0,
            ..lp(20.3152, 1.0, 1e-3, 0.0)
        };
        let (_, hi) = stable_kd_range(&plain).unwrap();
        assert!((110.0 * hi * 1e-3 - 2.0).abs() < 0.02, "{hi}");
        // 100 Hz: the filter's lag alone makes every kd unstable.
        assert!(stable_kd_range(&lp(20.3152, 0.6077, 1e-2, 1.5e-4)).is_none());
    }

    #[test]
    fn plant_gain_is_eq_4_3_with_the_nut() {
        let a = plant_gain(&Params::design());
        assert!((109.0..110.0).contains(&a), "{a}");
    }
}
