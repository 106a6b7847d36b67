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
        // Positions of this machine stay far inside i64; wrap like hardware.
        let c = floor_to_i64(value * self.counts_per_unit);
        // Two's complement: the low 32 bits of `c` are the count modulo 2^32.
        self.wrap(c as u32)
    }

    /// A count wrapped to the counter width, as the hardware counter holds it.
    pub fn wrap(&self, counts: u32) -> u32 {
        let mask = if self.bits >= 32 {
            u32::MAX
        } else {
            (1u32 << self.bits) - 1
        };
        counts & mask
    }
}

/// `libm::floor(x) as i64`, without the software `floor` (the host's
/// baseline x86-64 has no rounding instruction): truncate, then step down
/// for negative non-integers. Same result for every `x`, NaN (0) and the
/// saturated ends included.
#[inline]
fn floor_to_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// `libm::round(x).clamp(0.0, max) as u16` for `max < 2^16` (NaN gives 0),
/// without the software `round`: clamp first (rounding is monotonic and
/// the bounds are whole numbers), then round half away from zero by
/// truncating and looking at the (exactly computed) fraction.
#[inline]
fn round_clamped_u16(x: f64, max: u16) -> u16 {
    if x.is_nan() {
        return 0;
    }
    let x = x.clamp(0.0, f64::from(max));
    let t = x as u16; // x >= 0: truncation is floor
                      // Branch-free: with noise the fraction is random, a branch would be
                      // mispredicted half the time.
    t + u16::from(x - f64::from(t) >= 0.5)
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
        round_clamped_u16(
            self.offset_code + v / self.units_per_code,
            self.full_scale(),
        )
    }
}

/// A lag within this of its command has settled, A
/// ([`Amplifier::follow_cached`]).
pub const SETTLED_A: f64 = 1.0e-12;

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
        let mut lag = LagFactor::default();
        self.follow_cached(command_a, dt_s, &mut lag)
    }

    /// [`Self::follow`], taking `exp(-dt/tau)` and the mean's factor from
    /// `lag` when they were worked out for the same `dt_s` and time constant
    /// (a fixed control period pays for the `exp` and the division once).
    pub fn follow_cached(&mut self, command_a: f64, dt_s: f64, lag: &mut LagFactor) -> f64 {
        if self.tau_s <= 0.0 || dt_s <= 0.0 {
            self.current_a = command_a;
            return command_a;
        }
        if !(lag.valid && lag.dt_s == dt_s && lag.tau_s == self.tau_s) {
            let x = dt_s / self.tau_s;
            let decay = libm::exp(-x);
            *lag = LagFactor {
                valid: true,
                dt_s,
                tau_s: self.tau_s,
                mean_factor: (1.0 - decay) / x,
                decay,
            };
        }
        let (mean_factor, decay) = (lag.mean_factor, lag.decay);
        let i0 = self.current_a;
        // Settled: the current is the command. Without this a current
        // decaying to a zero command passes through the subnormal doubles
        // (below 2.2e-308) some 1,100 periods after the amplifier is
        // disabled, and the plant's every product with it then runs about
        // a hundred times slower on an x86 host (the resting simulator
        // did). A picoampere is far below anything the motor feels.
        if (i0 - command_a).abs() < SETTLED_A {
            self.current_a = command_a;
            return command_a;
        }
        // Mean of `command + (i0 - command) exp(-t/tau)` over the step.
        let mean = command_a + (i0 - command_a) * mean_factor;
        self.current_a = command_a + (i0 - command_a) * decay;
        mean
    }
}

/// `dt / tau` and `exp(-dt / tau)` of an [`Amplifier`] step, kept between
/// steps by [`Amplifier::follow_cached`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LagFactor {
    valid: bool,
    dt_s: f64,
    tau_s: f64,
    /// `(1 - exp(-dt/tau)) / (dt/tau)`.
    mean_factor: f64,
    decay: f64,
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
    fn fast_floor_and_round_match_libm() {
        let mut xs = std::vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            2.5,
            -1.5,
            0.49999999999999994,
            4094.5,
            4095.4,
            4095.5,
            1e300,
            -1e300,
            9.3e18,
            -9.3e18,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        let mut n = Noise::new(3, true);
        for _ in 0..100_000 {
            xs.push(n.gaussian(3000.0));
            xs.push(2048.0 + n.gaussian(0.7));
            let k = libm::round(n.gaussian(100.0));
            xs.push(k + 0.5);
            xs.push(k);
        }
        for &x in &xs {
            assert_eq!(floor_to_i64(x), libm::floor(x) as i64, "floor {x}");
            let r = libm::round(x);
            let want = if r.is_nan() {
                0
            } else {
                r.clamp(0.0, 4095.0) as u16
            };
            assert_eq!(round_clamped_u16(x, 4095), want, "round {x}");
        }
    }

    #[test]
    fn a_disabled_amplifier_settles_to_exactly_zero_without_subnormals() {
        let mut a = Amplifier {
            dac_bits: 12,
            zero_code: 2048,
            amps_per_code: 0.02,
            tau_s: 1.5e-4,
            current_a: 33.67,
        };
        let mut lag = LagFactor::default();
        let mut periods = 0;
        while a.current_a != 0.0 {
            let mean = a.follow_cached(0.0, 1e-4, &mut lag);
            for v in [mean, a.current_a] {
                assert!(v == 0.0 || v.is_normal(), "{v:e} after {periods} periods");
            }
            periods += 1;
            assert!(periods < 10_000, "still {:e}", a.current_a);
        }
        // ln(33.67 A / 1e-12 A) = 31 time constants of 1.5 periods: 47
        // periods, not the 1,100 to the subnormals (below 2.2e-308 A).
        assert!((46..50).contains(&periods), "{periods} periods");
    }

    #[test]
    fn cached_amplifier_lag_is_the_same() {
        let mut a = Amplifier {
            dac_bits: 12,
            zero_code: 2048,
            amps_per_code: 0.02,
            tau_s: 1.5e-4,
            current_a: 0.0,
        };
        let mut b = a;
        let mut lag = LagFactor::default();
        for k in 0..1000 {
            let cmd = f64::from(k % 37) - 18.0;
            let dt = if k % 100 == 99 { 2e-4 } else { 1e-4 };
            assert_eq!(a.follow(cmd, dt), b.follow_cached(cmd, dt, &mut lag));
            assert_eq!(a.current_a, b.current_a);
        }
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
