//! Sensor and amplifier models between the plant and the firmware's raw I/O:
//! quadrature-encoder quantisation and counter wrap-around, ADC bit depth,
//! offset, saturation and Gaussian noise (seeded, reproducible), DAC
//! resolution, and the servo amplifier's first-order current loop.
//!
//! `no_std`: these run inside the QEMU image as well as on the host.

use rand_distr::{Distribution, StandardNormal};
use rand_xoshiro::rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256PlusPlus;

/// Seeded Gaussian noise source: the same seed gives the same sequence on
/// every machine and target.
#[derive(Clone, Debug)]
pub struct Noise {
    rng: Xoshiro256PlusPlus,
    enabled: bool,
}

impl Noise {
    /// A noise source; `enabled = false` makes every sample exactly 0.
    pub fn new(seed: u64, enabled: bool) -> Self {
        Noise {
            rng: Xoshiro256PlusPlus::seed_from_u64(seed),
            enabled,
        }
    }

    /// One sample of zero-mean Gaussian noise with standard deviation `sigma`.
    pub fn gaussian(&mut self, sigma: f64) -> f64 {
        if !self.enabled || sigma <= 0.0 {
            return 0.0;
        }
        let n: f64 = StandardNormal.sample(&mut self.rng);
        n * sigma
    }
}

/// An incremental encoder read through a hardware counter of `bits` bits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Encoder {
    /// Counts per unit of the measured quantity (counts/rad or counts/m),
    /// quadrature included.
    pub counts_per_unit: f64,
    /// Counter width (16 or 32 on the STM32F405's timers).
    pub bits: u32,
}

impl Encoder {
    /// The counter value for a true position: quantised down to whole counts
    /// (as an edge counter does) and wrapped to the counter width.
    pub fn counter(&self, value: f64) -> u32 {
        let counts = libm::floor(value * self.counts_per_unit);
        // Positions of this machine stay far inside i64; wrap like hardware.
        let c = counts as i64;
        let mask: u64 = if self.bits >= 32 {
            u32::MAX as u64
        } else {
            (1u64 << self.bits) - 1
        };
        ((c as u64) & mask) as u32
    }
}

/// An ADC channel: `code = offset + value / gain + noise`, rounded and
/// saturated to `0 ..= 2^bits - 1` (a rail value is what an open or shorted
/// sensor reads).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdcChannel {
    /// Converter resolution, bits.
    pub bits: u32,
    /// Measured units per code (N/code, m/code).
    pub units_per_code: f64,
    /// Code at zero input.
    pub offset_code: f64,
    /// Noise standard deviation in measured units (N, m).
    pub noise_sigma: f64,
}

impl AdcChannel {
    /// Largest code.
    pub fn full_scale(&self) -> u16 {
        ((1u32 << self.bits.min(16)) - 1) as u16
    }

    /// Convert a true value to a code, with noise drawn from `noise`.
    pub fn code(&self, value: f64, noise: &mut Noise) -> u16 {
        let v = value + noise.gaussian(self.noise_sigma);
        let code = libm::round(self.offset_code + v / self.units_per_code);
        if code.is_nan() {
            return 0;
        }
        code.clamp(0.0, f64::from(self.full_scale())) as u16
    }
}

/// A servo amplifier in current mode: the DAC code sets a current command,
/// a first-order current loop with time constant `tau_s` follows it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Amplifier {
    /// DAC resolution, bits.
    pub dac_bits: u32,
    /// DAC code for zero current.
    pub zero_code: u16,
    /// Amperes per DAC code.
    pub amps_per_code: f64,
    /// Current-loop time constant, s (0: no lag).
    pub tau_s: f64,
    /// Present motor current, A.
    pub current_a: f64,
}

impl Amplifier {
    /// The current command a DAC code stands for, A (codes above full scale
    /// saturate like the DAC does).
    pub fn command_a(&self, code: u16) -> f64 {
        let full = ((1u32 << self.dac_bits.min(16)) - 1) as u16;
        (f64::from(code.min(full)) - f64::from(self.zero_code)) * self.amps_per_code
    }

    /// Follow `command_a` for `dt_s`; returns the mean current over the
    /// interval (what the plant is driven with, so the motor's work is
    /// the same as with the continuous lag). Exact for a first-order lag
    /// with a held command.
    pub fn follow(&mut self, command_a: f64, dt_s: f64) -> f64 {
        if self.tau_s <= 0.0 || dt_s <= 0.0 {
            self.current_a = command_a;
            return command_a;
        }
        let x = dt_s / self.tau_s;
        let decay = libm::exp(-x);
        let i0 = self.current_a;
        let mean = command_a + (i0 - command_a) * (1.0 - decay) / x;
        self.current_a = command_a + (i0 - command_a) * decay;
        mean
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_reproducible_and_has_the_asked_sigma() {
        let mut a = Noise::new(7, true);
        let mut b = Noise::new(7, true);
        let xs: std::vec::Vec<f64> = (0..20_000).map(|_| a.gaussian(2.0)).collect();
        for x in &xs[..100] {
            assert_eq!(*x, b.gaussian(2.0));
        }
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / xs.len() as f64;
        assert!(mean.abs() < 0.05, "{mean}");
        assert!((var.sqrt() - 2.0).abs() < 0.05, "{}", var.sqrt());
        assert_eq!(Noise::new(7, false).gaussian(2.0), 0.0);
    }

    #[test]
    fn encoder_quantises_and_wraps() {
        let e = Encoder {
            counts_per_unit: 2000.0 / (2.0 * core::f64::consts::PI),
            bits: 16,
        };
        assert_eq!(e.counter(0.0), 0);
        assert_eq!(e.counter(2.0 * core::f64::consts::PI), 2000);
        assert_eq!(e.counter(-1e-9), 65535); // one count below zero wraps
        let e32 = Encoder {
            counts_per_unit: 1.0,
            bits: 32,
        };
        assert_eq!(e32.counter(-1.0), u32::MAX);
    }

    #[test]
    fn adc_saturates_at_the_rails() {
        let ch = AdcChannel {
            bits: 12,
            units_per_code: 0.5,
            offset_code: 100.0,
            noise_sigma: 0.0,
        };
        let mut n = Noise::new(1, false);
        assert_eq!(ch.code(10.0, &mut n), 120);
        assert_eq!(ch.code(1e6, &mut n), 4095);
        assert_eq!(ch.code(-1e6, &mut n), 0);
        assert_eq!(ch.code(f64::NAN, &mut n), 0);
    }

    #[test]
    fn amplifier_lag_mean_current_is_exact() {
        let mut a = Amplifier {
            dac_bits: 12,
            zero_code: 2048,
            amps_per_code: 0.02,
            tau_s: 1e-3,
            current_a: 0.0,
        };
        assert!((a.command_a(2148) - 2.0).abs() < 1e-12);
        // Integrate the lag finely and compare the mean.
        let (dt, n) = (1e-4, 10_000);
        let mut i: f64 = 0.0;
        let mut sum = 0.0;
        for _ in 0..n {
            sum += i;
            i += (10.0 - i) * (dt / n as f64) / 1e-3;
        }
        let mean = a.follow(10.0, dt);
        assert!(
            (mean - sum / n as f64).abs() < 1e-3,
            "{mean} vs {}",
            sum / n as f64
        );
        assert!((a.current_a - i).abs() < 1e-3);
    }
}
