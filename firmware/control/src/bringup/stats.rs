//! The routines' statistics, a few operations a period in `f32`: the
//! running mean and variance ([`Stats`]) and the running least-squares
//! line ([`Regression`]), both Welford's update.

/// Running mean and variance (Welford).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stats {
    pub(super) n: u32,
    pub(super) mean: f32,
    pub(super) m2: f32,
}

impl Stats {
    /// Adds one value.
    #[inline]
    pub fn add(&mut self, x: f32) {
        self.n = self.n.saturating_add(1);
        let d = x - self.mean;
        self.mean += d / self.n as f32;
        self.m2 += d * (x - self.mean);
    }

    /// Values added.
    pub const fn count(&self) -> u32 {
        self.n
    }

    /// Their mean (0 before any).
    pub const fn mean(&self) -> f32 {
        self.mean
    }

    /// Their sample standard deviation (0 below two values).
    pub fn std(&self) -> f32 {
        if self.n < 2 {
            0.0
        } else {
            libm::sqrtf(crate::num::max(self.m2, 0.0) / (self.n - 1) as f32)
        }
    }
}

/// Running means and co-moments of two variables (Welford's update): the
/// least-squares line of the spring sweep.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Regression {
    pub(super) n: u32,
    pub(super) mean_x: f32,
    pub(super) mean_y: f32,
    pub(super) cxx: f32,
    pub(super) cxy: f32,
    pub(super) cyy: f32,
}

impl Regression {
    /// Adds one point.
    pub fn add(&mut self, x: f32, y: f32) {
        self.n = self.n.saturating_add(1);
        let n = self.n as f32;
        let dx = x - self.mean_x;
        self.mean_x += dx / n;
        let dy = y - self.mean_y;
        self.mean_y += dy / n;
        // Co-moments with the updated mean on one side.
        self.cxx += dx * (x - self.mean_x);
        self.cxy += dx * (y - self.mean_y);
        self.cyy += dy * (y - self.mean_y);
    }

    /// Points added.
    pub const fn count(&self) -> u32 {
        self.n
    }

    /// Slope of the least-squares line (NaN below two distinct `x`).
    pub fn slope(&self) -> f32 {
        if self.n < 2 || self.cxx <= 0.0 {
            f32::NAN
        } else {
            self.cxy / self.cxx
        }
    }

    /// Intercept of the least-squares line.
    pub fn intercept(&self) -> f32 {
        self.mean_y - self.slope() * self.mean_x
    }

    /// RMS of the residuals about the line.
    pub fn residual_rms(&self) -> f32 {
        if self.n < 3 || self.cxx <= 0.0 {
            return f32::NAN;
        }
        let ss = self.cyy - self.cxy * self.cxy / self.cxx;
        libm::sqrtf(crate::num::max(ss, 0.0) / (self.n - 2) as f32)
    }

    /// The range of `x` seen, as a standard deviation.
    pub fn x_std(&self) -> f32 {
        if self.n < 2 {
            0.0
        } else {
            libm::sqrtf(crate::num::max(self.cxx, 0.0) / (self.n - 1) as f32)
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Welford's mean and deviation agree with the two-pass ones.
        #[test]
        fn stats_match_two_pass(xs in proptest::collection::vec(0u16..4096, 2..500)) {
            let mut s = Stats::default();
            for &x in &xs {
                s.add(f32::from(x));
            }
            let n = xs.len() as f64;
            let mean = xs.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
            let var = xs.iter().map(|&x| (f64::from(x) - mean).powi(2)).sum::<f64>() / (n - 1.0);
            prop_assert!((f64::from(s.mean()) - mean).abs() < 1e-3 * (1.0 + mean));
            prop_assert!((f64::from(s.std()) - var.sqrt()).abs() < 1e-2 * (1.0 + var.sqrt()));
        }

        /// The running least squares agrees with the two-pass fit on a
        /// spring-like line with noise.
        #[test]
        fn regression_matches_two_pass(
            k in 5_000.0f32..20_000.0,
            f0 in -50.0f32..50.0,
            noise in proptest::collection::vec(-3.0f32..3.0, 100..2000),
        ) {
            let mut r = Regression::default();
            let pts: std::vec::Vec<(f64, f64)> = noise
                .iter()
                .enumerate()
                .map(|(i, e)| {
                    let x = 0.012 * (i as f32 / noise.len() as f32);
                    (f64::from(x), f64::from(k * x + f0 + e))
                })
                .collect();
            for &(x, y) in &pts {
                r.add(x as f32, y as f32);
            }
            let n = pts.len() as f64;
            let mx = pts.iter().map(|p| p.0).sum::<f64>() / n;
            let my = pts.iter().map(|p| p.1).sum::<f64>() / n;
            let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
            let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
            let slope = sxy / sxx;
            prop_assert!((f64::from(r.slope()) / slope - 1.0).abs() < 1e-3, "{} {}", r.slope(), slope);
            prop_assert!((f64::from(r.intercept()) - (my - slope * mx)).abs() < 0.05);
        }
    }
}
