//! Filtered derivative of a sampled signal (thesis section 4.2, eq 4.1).
//!
//! The thesis differentiates its measured positions with a first-order low-pass
//! on the finite difference:
//!
//! ```text
//! v_n = G v_(n-1) + (1 - G) (x_n - x_(n-1)) / dt        (eq 4.1)
//! ```
//!
//! `G = 0` is the plain finite difference; `G` towards 1 smooths more and lags
//! more. `G = 1` would freeze the output, so it is rejected.
//!
//! At rest the difference is 0 and the output decays geometrically (by `G`
//! a period) toward 0; below [`REST_RATE_PER_S`] it is set to exactly 0.
//! Without that it would pass through the subnormal floats (below 1.2e-38)
//! within a tenth of a second at 10 kHz, and every product with it (the
//! estimator's look-ahead, the kinetic energies) would run about a hundred
//! times slower on an x86 host's FPU (the Cortex-M4F takes them at full
//! speed): the simulator at rest ran at a quarter of its hopping speed.
//! The threshold is many orders below anything the sensors resolve (one
//! encoder count in one period is above 1 unit/s), so no result the
//! sensors can tell apart changes, and host and target compute the same.
//!
//! The sample period is passed to every update, so the filter is exact for
//! jittery or variable-rate sampling. Bad input (non-finite sample, `dt <= 0`,
//! a difference that overflows) returns an error and leaves the state as it
//! was, so one bad sample cannot poison every later output with NaN.

/// Why a [`FilteredDerivative`] refused a configuration or a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FilterError {
    /// The filter gain `G` is not a finite number in `[0, 1)`.
    GainOutOfRange,
    /// The sample `x_n` is NaN or infinite.
    NonFiniteSample,
    /// The sample period `dt` is not a finite number greater than zero.
    NonPositivePeriod,
    /// The finite difference or the filtered value overflowed to infinity.
    Overflow,
}

/// A filtered rate smaller than this (in the input's unit per second) is
/// exactly 0: the filter has come to rest (see the module's note on
/// subnormal floats). Its square, 1e-24, stays far above the smallest
/// normal `f32` too, so the kinetic energies of a resting body are 0, not
/// subnormal.
pub const REST_RATE_PER_S: f32 = 1.0e-12;

/// Filtered derivative, thesis eq 4.1: `v_n = G v_(n-1) + (1-G)(x_n - x_(n-1))/dt`.
///
/// The output is in the input's unit per second (a position in `m` gives a
/// velocity in `m/s`, an angle in `rad` gives `rad/s`).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FilteredDerivative {
    /// Filter gain `G` of eq 4.1, in `[0, 1)`.
    gain: f32,
    /// Previous sample `x_(n-1)`; `None` until the first sample primes the filter.
    last_sample: Option<f32>,
    /// Previous output `v_(n-1)`, per second.
    rate_per_s: f32,
}

impl FilteredDerivative {
    /// Creates an unprimed filter with gain `G` (eq 4.1); `G` must be finite and in `[0, 1)`.
    pub const fn new(gain: f32) -> Result<Self, FilterError> {
        // `!(gain >= 0.0)` also rejects NaN.
        if !(gain >= 0.0 && gain < 1.0) {
            return Err(FilterError::GainOutOfRange);
        }
        Ok(Self {
            gain,
            last_sample: None,
            rate_per_s: 0.0,
        })
    }

    /// The filter gain `G` of eq 4.1.
    pub const fn gain(&self) -> f32 {
        self.gain
    }

    /// The latest output `v_n` (0 until two samples have been seen).
    pub const fn value(&self) -> f32 {
        self.rate_per_s
    }

    /// Whether a first sample has been stored, so the next update yields a derivative.
    pub const fn is_primed(&self) -> bool {
        self.last_sample.is_some()
    }

    /// Forgets the history: the next sample primes the filter again.
    pub fn reset(&mut self) {
        self.last_sample = None;
        self.rate_per_s = 0.0;
    }

    /// Feeds sample `x_n` taken `dt_s` seconds after the previous one and returns `v_n` (eq 4.1).
    ///
    /// The first sample after construction or [`reset`](Self::reset) only
    /// primes the filter and returns 0 (`dt_s` is still validated). On error
    /// the state is unchanged.
    pub fn update(&mut self, sample: f32, dt_s: f32) -> Result<f32, FilterError> {
        if !sample.is_finite() {
            return Err(FilterError::NonFiniteSample);
        }
        // NaN fails `dt_s > 0.0`, so this also rejects NaN.
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            return Err(FilterError::NonPositivePeriod);
        }
        self.advance(sample, dt_s).ok_or(FilterError::Overflow)
    }

    /// [`update`](Self::update) for a caller that has already checked that
    /// `sample` is finite and `dt_s` finite and positive (the phase
    /// estimator checks all its inputs at once). `None` on overflow, with
    /// the state unchanged.
    #[inline(always)]
    pub(crate) fn advance(&mut self, sample: f32, dt_s: f32) -> Option<f32> {
        let rate = self.peek(sample, dt_s)?;
        self.commit(sample, rate);
        Some(rate)
    }

    /// The output `sample` would give, without changing the state: `None` on
    /// overflow. Inputs checked by the caller as for [`advance`](Self::advance).
    #[inline(always)]
    pub(crate) fn peek(&self, sample: f32, dt_s: f32) -> Option<f32> {
        let Some(last) = self.last_sample else {
            return Some(0.0);
        };
        // dt_s > 0 and finite, both samples finite: the quotient is finite or
        // +-inf (never NaN); the weighted sum is checked before it is stored.
        let difference_rate = (sample - last) / dt_s;
        let rate = self.gain * self.rate_per_s + (1.0 - self.gain) * difference_rate;
        // At rest: exactly 0 rather than a decay into subnormal floats (NaN
        // fails the test and is refused below).
        let rate = if rate.abs() < REST_RATE_PER_S {
            0.0
        } else {
            rate
        };
        rate.is_finite().then_some(rate)
    }

    /// Stores `sample` and the `rate` [`peek`](Self::peek) gave for it.
    #[inline(always)]
    pub(crate) fn commit(&mut self, sample: f32, rate: f32) {
        self.last_sample = Some(sample);
        self.rate_per_s = rate;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn at_rest_the_rate_reaches_exactly_zero_without_subnormals() -> Result<(), FilterError> {
        for gain in [0.0, 0.5, 0.9, 0.99, 0.999] {
            let mut f = FilteredDerivative::new(gain)?;
            f.update(0.0, 1e-4)?;
            // A fast move, then the sample held: the rate decays by `G` a
            // period and must land on 0, never on a subnormal on the way
            // (0.9 x the smallest subnormal rounds back to it: without the
            // rest threshold it would stay there for ever).
            f.update(1.0, 1e-4)?;
            let mut periods = 0;
            while f.value() != 0.0 {
                let v = f.update(1.0, 1e-4)?;
                assert!(v == 0.0 || v.is_normal(), "G {gain}: {v:e}");
                periods += 1;
                assert!(periods < 100_000, "G {gain}: still {v:e}");
            }
            assert_eq!(f.value().to_bits(), 0, "G {gain}: -0 or not 0");
        }
        Ok(())
    }

    #[test]
    fn first_sample_primes_and_returns_zero() -> Result<(), FilterError> {
        let mut f = FilteredDerivative::new(0.5)?;
        assert!(!f.is_primed());
        assert_eq!(f.update(3.0, 1e-3)?, 0.0);
        assert!(f.is_primed());
        Ok(())
    }

    #[test]
    fn constant_slope_converges_to_slope() -> Result<(), FilterError> {
        let slope_per_s = 2.5_f32;
        let dt_s = 1e-4_f32;
        let mut f = FilteredDerivative::new(0.9)?;
        let mut v = 0.0;
        for n in 0..2000_u16 {
            v = f.update(slope_per_s * dt_s * f32::from(n), dt_s)?;
        }
        // 0.9^2000 is negligible; what is left is f32 rounding of the samples.
        assert!(close(v, slope_per_s, 1e-2), "v = {v}");
        Ok(())
    }

    #[test]
    fn gain_zero_is_plain_finite_difference() -> Result<(), FilterError> {
        let mut f = FilteredDerivative::new(0.0)?;
        f.update(1.0, 0.01)?;
        assert!(close(f.update(1.5, 0.01)?, 50.0, 1e-3));
        // Variable period: the difference uses the period given with the sample.
        assert!(close(f.update(1.0, 0.02)?, -25.0, 1e-3));
        Ok(())
    }

    #[test]
    fn one_step_matches_eq_4_1() -> Result<(), FilterError> {
        let mut f = FilteredDerivative::new(0.25)?;
        f.update(0.0, 0.1)?;
        let v1 = f.update(1.0, 0.1)?; // 0.75 * 10 = 7.5
        assert!(close(v1, 7.5, 1e-5));
        let v2 = f.update(1.0, 0.1)?; // 0.25 * 7.5 + 0 = 1.875
        assert!(close(v2, 1.875, 1e-5));
        Ok(())
    }

    #[test]
    fn rejects_nan_and_keeps_state() -> Result<(), FilterError> {
        let mut f = FilteredDerivative::new(0.5)?;
        f.update(0.0, 0.1)?;
        f.update(1.0, 0.1)?;
        let before = f;
        assert_eq!(f.update(f32::NAN, 0.1), Err(FilterError::NonFiniteSample));
        assert_eq!(
            f.update(f32::INFINITY, 0.1),
            Err(FilterError::NonFiniteSample)
        );
        assert_eq!(f.update(2.0, f32::NAN), Err(FilterError::NonPositivePeriod));
        assert_eq!(f, before);
        Ok(())
    }

    #[test]
    fn rejects_non_positive_period_and_keeps_state() -> Result<(), FilterError> {
        let mut f = FilteredDerivative::new(0.5)?;
        assert_eq!(f.update(1.0, 0.0), Err(FilterError::NonPositivePeriod));
        assert!(!f.is_primed());
        f.update(1.0, 0.1)?;
        let before = f;
        assert_eq!(f.update(2.0, -0.1), Err(FilterError::NonPositivePeriod));
        assert_eq!(
            f.update(2.0, f32::INFINITY),
            Err(FilterError::NonPositivePeriod)
        );
        assert_eq!(f, before);
        Ok(())
    }

    #[test]
    fn rejects_overflow_and_keeps_state() -> Result<(), FilterError> {
        let mut f = FilteredDerivative::new(0.0)?;
        f.update(-f32::MAX, 1.0)?;
        let before = f;
        assert_eq!(f.update(f32::MAX, 1.0), Err(FilterError::Overflow));
        assert_eq!(f, before);
        Ok(())
    }

    #[test]
    fn rejects_bad_gain() {
        for g in [1.0, 1.5, -0.1, f32::NAN, f32::INFINITY] {
            assert_eq!(FilteredDerivative::new(g), Err(FilterError::GainOutOfRange));
        }
    }

    #[test]
    fn reset_reprimes() -> Result<(), FilterError> {
        let mut f = FilteredDerivative::new(0.0)?;
        f.update(0.0, 1.0)?;
        f.update(5.0, 1.0)?;
        f.reset();
        assert_eq!(f.value(), 0.0);
        assert_eq!(f.update(100.0, 1.0)?, 0.0);
        Ok(())
    }
}
