//! The e-stop input, debounced.
//!
//! The e-stop is the firmware's second channel: the button also breaks the
//! amplifier enable in hardware (docs/safety.md, "E-stop"). A press counts
//! once the input has read pressed for `estop.press_s` without a break
//! (default 0.2 ms, two periods at 10 kHz): a glitch on the cable shorter
//! than that is not a press, and a bouncing contact is taken at its first
//! steady 0.2 ms. A release counts once it has read released for
//! `estop.release_s` (default 50 ms, longer than a contact's bounce), so
//! neither arming nor a fault reset acts on a button still bouncing open.
//! Times, not periods: the same at every control rate.

use crate::param::InvalidField;

crate::param::config! {
    /// How long the input must hold a new level before it counts.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct DebounceConfig;
    params {
        86 ESTOP_PRESS_S press_s: f32 {
            "estop.press_s", "s", Real, [0.0, 0.01], 2.0e-4, DISARMED,
            "The e-stop input pressed without a break for this long is a press (shorter is a glitch; the button also breaks the amplifier enable in hardware)."
        }
        87 ESTOP_RELEASE_S release_s: f32 {
            "estop.release_s", "s", Real, [0.0, 2.0], 0.05, DISARMED,
            "The e-stop input released without a break for this long is a release (arming and fault resets wait for it: longer than a contact's bounce)."
        }
    }
}

impl DebounceConfig {
    /// Both times within their parameters' ranges, else the one that is not.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// A debounced input. Its first sample sets the state as it reads (the
/// amplifier is off at boot whatever it says: a press then only keeps the
/// robot from arming, and a boot with the button released may arm at once).
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Debounce {
    config: DebounceConfig,
    pressed: bool,
    /// Whether a sample has been seen.
    started: bool,
    /// How long the raw input has differed from `pressed`, s.
    changing_s: f32,
}

/// Sums of periods compare against whole times less this much (the float
/// rounding of the sums), s: a tenth of a 1 MHz period.
const ROUNDING_S: f32 = 1.0e-7;

impl Debounce {
    /// Pressed until the first sample, once `config` validates.
    pub fn new(config: DebounceConfig) -> Result<Self, InvalidField> {
        config.validate()?;
        Ok(Self {
            config,
            pressed: true,
            started: false,
            changing_s: 0.0,
        })
    }

    /// The debounced state.
    pub const fn pressed(&self) -> bool {
        self.pressed
    }

    /// Carries `old`'s state over (a rebuilt configuration keeps what the
    /// input has shown), with this one's times.
    pub fn continue_from(&mut self, old: &Debounce) {
        self.pressed = old.pressed;
        self.started = old.started;
        self.changing_s = old.changing_s;
    }

    /// One period of `dt_s` with the input reading `raw_pressed`; returns
    /// the debounced state. A non-finite or negative `dt_s` adds no time.
    #[inline]
    pub fn update(&mut self, raw_pressed: bool, dt_s: f32) -> bool {
        if !self.started {
            self.started = true;
            self.pressed = raw_pressed;
        }
        if raw_pressed == self.pressed {
            self.changing_s = 0.0;
            return self.pressed;
        }
        if dt_s > 0.0 && dt_s < f32::INFINITY {
            self.changing_s += dt_s;
        }
        let needed = if raw_pressed {
            self.config.press_s
        } else {
            self.config.release_s
        };
        if self.changing_s >= needed - ROUNDING_S {
            self.pressed = raw_pressed;
            self.changing_s = 0.0;
        }
        self.pressed
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f32 = 1.0e-4;

    fn released() -> Debounce {
        let mut d = Debounce::new(DebounceConfig::default()).unwrap_or_else(|e| panic!("{e:?}"));
        for _ in 0..1000 {
            d.update(false, DT);
        }
        assert!(!d.pressed());
        d
    }

    #[test]
    fn the_first_sample_sets_the_state_then_a_release_takes_50_ms() {
        let mut d = Debounce::new(DebounceConfig::default()).unwrap_or_else(|e| panic!("{e:?}"));
        assert!(d.pressed());
        assert!(d.update(true, DT));
        for n in 1..=500 {
            let pressed = d.update(false, DT);
            assert_eq!(pressed, n < 500, "period {n}");
        }
        let mut d = Debounce::new(DebounceConfig::default()).unwrap_or_else(|e| panic!("{e:?}"));
        assert!(!d.update(false, DT));
    }

    #[test]
    fn a_press_counts_after_two_periods_at_10_khz() {
        let mut d = released();
        assert!(!d.update(true, DT));
        assert!(d.update(true, DT));
    }

    #[test]
    fn a_one_period_glitch_is_not_a_press() {
        let mut d = released();
        for _ in 0..100 {
            assert!(!d.update(true, DT));
            assert!(!d.update(false, DT));
        }
    }

    #[test]
    fn a_bounce_while_releasing_restarts_the_release() {
        let mut d = released();
        d.update(true, DT);
        d.update(true, DT);
        assert!(d.pressed());
        for _ in 0..499 {
            d.update(false, DT);
        }
        d.update(true, DT); // the contact bounces closed once
        for n in 1..=500 {
            assert_eq!(d.update(false, DT), n < 500, "period {n}");
        }
    }

    #[test]
    fn the_times_hold_at_any_rate() {
        for hz in [1_000.0f32, 40_000.0, 100_000.0] {
            let dt = 1.0 / hz;
            let mut d = released();
            let mut t = 0.0;
            while !d.update(true, dt) {
                t += dt;
            }
            // Pressed from the first period that completes 0.2 ms.
            assert!(
                t + dt >= 2.0e-4 - 1e-6 && t <= 2.0e-4 + 1e-6,
                "{hz} Hz: {t}"
            );
        }
    }

    #[test]
    fn bad_configs_are_refused_by_name() {
        let bad = DebounceConfig {
            release_s: f32::NAN,
            ..DebounceConfig::default()
        };
        assert_eq!(
            Debounce::new(bad).err(),
            Some(InvalidField("estop.release_s"))
        );
    }

    proptest! {
        /// Whatever the input does, the state only changes after the input
        /// has held the new level for the whole debounce time.
        #[test]
        fn changes_only_after_a_steady_level(
            inputs in proptest::collection::vec(any::<bool>(), 1..4000),
        ) {
            let cfg = DebounceConfig::default();
            let mut d = Debounce::new(cfg).unwrap_or_else(|e| panic!("{e:?}"));
            let first = inputs.first().copied().unwrap_or(true);
            d.update(first, DT);
            let mut run_level = first;
            let mut run_s = DT;
            for x in inputs.into_iter().skip(1) {
                if x == run_level {
                    run_s += DT;
                } else {
                    run_level = x;
                    run_s = DT;
                }
                let before = d.pressed();
                let now = d.update(x, DT);
                if now != before {
                    prop_assert_eq!(now, x);
                    let needed = if x { cfg.press_s } else { cfg.release_s };
                    prop_assert!(run_s >= needed - 1.0e-6, "{} s < {} s", run_s, needed);
                }
            }
        }
    }
}
