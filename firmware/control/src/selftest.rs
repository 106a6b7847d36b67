//! The on-target self-test: for a user with a bare F405 board
//! and the loopback harness of docs/board.md, every peripheral path the
//! firmware uses, checked in the order a fault would show it. The harness
//! ties each output to an input:
//!
//! | output | wired to | checks |
//! |---|---|---|
//! | PC10 (probe) | PC11 | the harness is there (else only the inputs are read: nothing is driven into a robot's wiring) |
//! | DAC PA4 | load-cell ADC PA2 | the command path: 512, 2048, 3584 codes read back within 41 codes (1% of full scale) |
//! | PC6/PC7 (quadrature) | TIM2 PA15/PB3 | the motor encoder: 400 states forward count 400 (either sign: the wiring's), 400 back return to the start |
//! | PC8/PC9 (quadrature) | TIM5 PA0/PA1 | the height encoder, the same |
//! | AMP_EN PB0 | PC12 | the enable pin drives high and low (only with the harness verified and the amplifier unplugged) |
//! | PB1 (e-stop) | GND | the e-stop input reads released when closed |
//!
//! This module is the sequence and its verdicts, one call per control
//! period, host-tested against a simulated harness; the board application
//! (`--features selftest`) only moves the pins.

use crate::hal::RawSample;

/// What is checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Check {
    /// The probe loopback: the harness is fitted.
    Harness,
    /// The DAC read back by the load-cell ADC at this code.
    Dac(u16),
    /// The motor encoder's counter follows the quadrature.
    MotorEncoder,
    /// The height encoder's counter follows the quadrature.
    HeightEncoder,
    /// AMP_EN read back.
    AmpEnable,
    /// The e-stop input reads released (closed to GND).
    Estop,
}

/// One check's outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Verdict {
    /// What was checked.
    pub check: Check,
    /// Whether it passed.
    pub passed: bool,
    /// What was measured (codes, counts, a level as 0/1).
    pub measured: i32,
    /// What was expected.
    pub expected: i32,
}

/// What the board reads each period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inputs {
    /// The sensors as the control period reads them.
    pub sample: RawSample,
    /// PC11: the probe's loopback.
    pub harness_in: bool,
    /// PC12: AMP_EN's loopback.
    pub amp_loop_in: bool,
}

/// What the board drives this period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Outputs {
    /// The DAC's code.
    pub dac_code: u16,
    /// AMP_EN.
    pub amp_enable: bool,
    /// PC10.
    pub probe: bool,
    /// PC6/PC7 (A, B), `None`: high-impedance is not needed, so low.
    pub motor_ab: (bool, bool),
    /// PC8/PC9 (A, B).
    pub height_ab: (bool, bool),
}

/// The quadrature states in forward order (A leads B).
const QUADRATURE: [(bool, bool); 4] = [(false, false), (true, false), (true, true), (false, true)];
/// Quadrature states per direction.
pub const STEPS: i32 = 400;
/// Periods a level or a code settles before it is read.
const SETTLE: u32 = 20;
/// Samples averaged per DAC code.
const AVERAGE: u32 = 32;
/// The DAC codes read back.
pub const DAC_CODES: [u16; 3] = [512, 2048, 3584];
/// How far a read-back code may be off: 1% of the 12-bit scale.
pub const DAC_TOLERANCE: i32 = 41;
const CHECKS: usize = 8;

/// The sequence's state.
#[derive(Debug, Clone)]
pub struct SelfTest {
    dac_zero: u16,
    stage: u8,
    t: u32,
    sum: u32,
    start: u32,
    phase: u8,
    harness: bool,
    probe_seen_high: bool,
    verdicts: [Option<Verdict>; CHECKS],
    n: usize,
}

impl SelfTest {
    /// Ready; `dac_zero` is the zero-current code (what the DAC holds
    /// whenever it is not being checked).
    pub const fn new(dac_zero: u16) -> Self {
        Self {
            dac_zero,
            stage: 0,
            t: 0,
            sum: 0,
            start: 0,
            phase: 0,
            harness: false,
            probe_seen_high: false,
            verdicts: [None; CHECKS],
            n: 0,
        }
    }

    /// Whether every check has run.
    pub fn done(&self) -> bool {
        self.stage >= 6
    }

    /// The verdicts so far, in order.
    pub fn verdicts(&self) -> impl Iterator<Item = &Verdict> {
        self.verdicts.iter().flatten()
    }

    /// Whether every check that ran passed (and at least one ran).
    pub fn passed(&self) -> bool {
        self.n > 0 && self.verdicts().all(|v| v.passed)
    }

    fn record(&mut self, check: Check, measured: i32, expected: i32, passed: bool) {
        if let Some(slot) = self.verdicts.get_mut(self.n) {
            *slot = Some(Verdict {
                check,
                passed,
                measured,
                expected,
            });
            self.n += 1;
        }
    }

    fn next(&mut self) {
        self.stage += 1;
        self.t = 0;
        self.sum = 0;
        self.phase = 0;
    }

    /// One period: the inputs read, the outputs to drive.
    pub fn period(&mut self, i: &Inputs) -> Outputs {
        let mut o = Outputs {
            dac_code: self.dac_zero,
            amp_enable: false,
            probe: false,
            motor_ab: QUADRATURE[0],
            height_ab: QUADRATURE[0],
        };
        self.t += 1;
        match self.stage {
            // The harness: the probe high, then low, read back each time.
            0 => {
                o.probe = self.t <= SETTLE;
                if self.t == SETTLE {
                    self.probe_seen_high = i.harness_in;
                }
                if self.t == 2 * SETTLE {
                    self.harness = self.probe_seen_high && !i.harness_in;
                    self.record(Check::Harness, i32::from(self.harness), 1, self.harness);
                    // No harness: nothing is driven; only the e-stop input.
                    self.stage = if self.harness { 1 } else { 4 };
                    self.t = 0;
                }
            }
            // The DAC codes, each settled, then averaged on the load cell.
            1 => {
                let Some(&code) = DAC_CODES.get(usize::from(self.phase)) else {
                    self.next();
                    return o;
                };
                o.dac_code = code;
                if self.t > SETTLE {
                    self.sum += u32::from(i.sample.loadcell_code);
                }
                if self.t == SETTLE + AVERAGE {
                    let mean = ((self.sum + AVERAGE / 2) / AVERAGE) as i32;
                    let want = i32::from(code);
                    self.record(
                        Check::Dac(code),
                        mean,
                        want,
                        (mean - want).abs() <= DAC_TOLERANCE,
                    );
                    self.phase += 1;
                    self.t = 0;
                    self.sum = 0;
                }
            }
            // The encoders: forward, then back.
            2 | 3 => {
                let motor = self.stage == 2;
                let counts = if motor {
                    i.sample.motor_counts
                } else {
                    i.sample.height_counts
                };
                let steps = STEPS as u32;
                if self.t == 1 {
                    self.start = counts;
                }
                // Period t drives state t (forward) or back down again.
                let k = if self.t <= steps {
                    self.t
                } else {
                    (2 * steps).saturating_sub(self.t)
                };
                let ab = QUADRATURE
                    .get((k % 4) as usize)
                    .copied()
                    .unwrap_or(QUADRATURE[0]);
                if motor {
                    o.motor_ab = ab;
                } else {
                    o.height_ab = ab;
                }
                // Read a period after the last state of each direction.
                let delta = counts.wrapping_sub(self.start) as i32;
                if self.t == steps + 1 {
                    self.sum = delta as u32;
                }
                if self.t == 2 * steps + 1 {
                    let forward = self.sum as i32;
                    let check = if motor {
                        Check::MotorEncoder
                    } else {
                        Check::HeightEncoder
                    };
                    let passed = (forward.abs() - STEPS).abs() <= 2 && delta.abs() <= 2;
                    self.record(check, forward, STEPS, passed);
                    self.next();
                }
            }
            // AMP_EN: high then low, read back (the harness is verified).
            4 if self.harness => {
                o.amp_enable = self.t <= SETTLE;
                if self.t == SETTLE {
                    self.probe_seen_high = i.amp_loop_in;
                }
                if self.t == 2 * SETTLE {
                    let ok = self.probe_seen_high && !i.amp_loop_in;
                    self.record(Check::AmpEnable, i32::from(ok), 1, ok);
                    self.next();
                }
            }
            4 => self.next(),
            // The e-stop input, closed: released.
            5 if self.t == SETTLE => {
                let pressed = i.sample.estop_pressed;
                self.record(Check::Estop, i32::from(pressed), 0, !pressed);
                self.next();
            }
            _ => {}
        }
        o
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use proptest::prelude::*;

    /// A harness: each output read back, the counters decoding the
    /// quadrature (x4), optionally broken.
    struct Harness {
        fitted: bool,
        dac_broken: bool,
        swapped: bool,
        motor: u32,
        height: u32,
        last: ((bool, bool), (bool, bool)),
    }

    fn decode(prev: (bool, bool), now: (bool, bool)) -> i32 {
        let idx = |s: (bool, bool)| QUADRATURE.iter().position(|&q| q == s).unwrap_or(0) as i32;
        match (idx(now) - idx(prev)).rem_euclid(4) {
            1 => 1,
            3 => -1,
            _ => 0,
        }
    }

    impl Harness {
        fn new() -> Self {
            Self {
                fitted: true,
                dac_broken: false,
                swapped: false,
                motor: 1000,
                height: u32::MAX - 5,
                last: (QUADRATURE[0], QUADRATURE[0]),
            }
        }

        fn run(&mut self, t: &mut SelfTest) -> u32 {
            let mut o = Outputs {
                dac_code: 2048,
                amp_enable: false,
                probe: false,
                motor_ab: QUADRATURE[0],
                height_ab: QUADRATURE[0],
            };
            let mut enabled_periods = 0;
            for _ in 0..10_000 {
                let m = if self.swapped {
                    (o.motor_ab.1, o.motor_ab.0)
                } else {
                    o.motor_ab
                };
                self.motor = self.motor.wrapping_add(decode(self.last.0, m) as u32);
                self.height = self
                    .height
                    .wrapping_add(decode(self.last.1, o.height_ab) as u32);
                self.last = (m, o.height_ab);
                let i = Inputs {
                    sample: RawSample {
                        motor_counts: self.motor,
                        height_counts: self.height,
                        loadcell_code: if self.dac_broken { 0 } else { o.dac_code },
                        pot_code: 0,
                        estop_pressed: !self.fitted,
                        amp_fault: false,
                    },
                    harness_in: self.fitted && o.probe,
                    amp_loop_in: self.fitted && o.amp_enable,
                };
                o = t.period(&i);
                enabled_periods += u32::from(o.amp_enable);
                if t.done() {
                    break;
                }
            }
            enabled_periods
        }
    }

    #[test]
    fn a_good_board_passes_every_check() {
        let mut t = SelfTest::new(2048);
        Harness::new().run(&mut t);
        assert!(
            t.done() && t.passed(),
            "{:?}",
            t.verdicts().collect::<std::vec::Vec<_>>()
        );
        assert_eq!(t.verdicts().count(), 8);
    }

    #[test]
    fn a_broken_dac_and_swapped_encoder_wires_are_told() {
        let mut h = Harness::new();
        h.dac_broken = true;
        h.swapped = true;
        let mut t = SelfTest::new(2048);
        h.run(&mut t);
        let v: std::vec::Vec<_> = t.verdicts().copied().collect();
        assert!(v
            .iter()
            .filter(|v| matches!(v.check, Check::Dac(_)))
            .all(|v| !v.passed));
        // Swapped A/B counts backwards: the wiring's sign, still a pass.
        let m = v.iter().find(|v| v.check == Check::MotorEncoder);
        assert!(m.is_some_and(|m| m.passed && m.measured == -STEPS), "{m:?}");
        assert!(!t.passed());
    }

    #[test]
    fn without_the_harness_nothing_is_driven() {
        let mut h = Harness::new();
        h.fitted = false;
        let mut t = SelfTest::new(2048);
        let enabled = h.run(&mut t);
        assert_eq!(enabled, 0);
        let v: std::vec::Vec<_> = t.verdicts().map(|v| (v.check, v.passed)).collect();
        assert_eq!(v, [(Check::Harness, false), (Check::Estop, false)]);
    }

    proptest! {
        /// Any inputs: the amplifier is enabled only after the harness
        /// answered the probe both ways, and the DAC is at zero whenever
        /// the DAC check is not running.
        #[test]
        fn the_amplifier_only_with_a_verified_harness(
            inputs in proptest::collection::vec((any::<bool>(), any::<bool>(), any::<u16>(), any::<u32>()), 1..3000)
        ) {
            let mut t = SelfTest::new(2048);
            for (h, a, lc, c) in inputs {
                let o = t.period(&Inputs {
                    sample: RawSample {
                        motor_counts: c,
                        height_counts: c,
                        loadcell_code: lc,
                        pot_code: 0,
                        estop_pressed: false,
                        amp_fault: false,
                    },
                    harness_in: h,
                    amp_loop_in: a,
                });
                if o.amp_enable {
                    prop_assert!(t.harness);
                }
                if t.stage != 1 {
                    prop_assert_eq!(o.dac_code, 2048);
                }
            }
        }
    }
}
