//! Arbitrary raw sensor words through the whole control period: the logic
//! of the `step` fuzz target (`fuzz_targets/step.rs`), in a library so that
//! a plain `cargo test --manifest-path fuzz/Cargo.toml` runs it on the stable
//! toolchain too (see the tests at the end, and docs/safety.md, "Fuzzing").
//!
//! The fuzz input is decoded with [`arbitrary`] into an [`Input`]: a
//! strategy, the target apex, a few configuration [`Perturbations`], the
//! control period (one per input: the runner's [`Timing`] is fixed), and a
//! sequence of [`PeriodRecord`]s, each a raw sample (absolute, or steps from
//! the last one so that the fuzzer can reach the laws past the encoder-jump
//! check), I/O failures, an overrun report, a change of target apex and
//! whether the period was late. A configuration or timing the runner refuses
//! ends the input quietly. Every period runs through
//! [`PeriodRunner::run_period`] on a fake [`HopperIo`], and [`run`] asserts:
//!
//! - no panic (libFuzzer reports one as a crash; cargo-fuzz and `cargo test`
//!   build with debug assertions, so an arithmetic overflow is one too);
//! - the approved command is finite and within the supervisor's current limit;
//! - the DAC code is within the 12-bit range, and is the code the fake DAC
//!   received (when it accepted the write), and the enable pin got the
//!   command's enable;
//! - a period with a latched fault commands 0 A, the zero-current code and
//!   the amplifier disabled, and every latched fault stays latched;
//! - `newly_latched` is exactly what latched since the last period (in it,
//!   or between periods: a reported overrun), and the log
//!   item names it (else the completed hop, if any);
//! - the watchdog feed policy never starves on a correct build: every period
//!   feeds (`feed_watchdog`), `Fault::SelfCheck` never latches and the
//!   runner never reports itself starved.

pub mod link;
pub mod persist;

use arbitrary::{Arbitrary, Unstructured};
use hopper_control::hal::{HopperIo, IoError, RawSample};
use hopper_control::hopper::{ApexLoop, HopperConfig, Strategy};
use hopper_control::laws::{
    energy, modified_torque, open_torque, shaped, step_closed, step_open, velocity, StanceLaw,
};
use hopper_control::runner::{LogItem, NoCounter, Period, PeriodRunner, Timing};
use hopper_control::supervisor::{Command, Fault, Faults};

/// One fuzz input.
#[derive(Debug, Clone, Arbitrary)]
pub struct Input {
    /// The controller.
    pub strategy: StrategyChoice,
    /// Target apex, `b / 255` m.
    pub target_apex: u8,
    /// Configuration perturbations.
    pub perturb: Perturbations,
    /// The control period, one per input (see [`period_s`]).
    pub period: u8,
    /// Late periods in a row that latch an overrun: `1 + b % 4`.
    pub overrun_limit: u8,
    /// The periods, in order: records decoded one after the other until
    /// the input runs out (not `Vec`'s own `take_rest` decoding, which
    /// reads a "one more" flag before each element and so gives a few
    /// periods at most from most inputs).
    #[arbitrary(with = to_the_end)]
    pub periods: Vec<PeriodRecord>,
}

/// The controller under test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Arbitrary)]
pub enum StrategyChoice {
    /// Motor off.
    Passive,
    /// Thesis eq 2.49.
    StepOpen,
    /// Thesis eqs 2.50-2.51.
    StepClosed,
    /// Open-loop constant torque.
    OpenTorque,
    /// Thesis eq 2.52.
    Energy,
    /// Thesis eq 2.53.
    Velocity,
    /// Thesis section 4.4.3.
    ModifiedTorque,
    /// `energy-apex`, default configuration.
    EnergyApex,
    /// `shaped`, default configuration.
    Shaped,
    /// `energy-apex` with pre-touchdown spin-up and a proportional term.
    EnergyApexSpinUp,
}

impl StrategyChoice {
    /// Every choice, in declaration order.
    pub const ALL: [StrategyChoice; 10] = [
        StrategyChoice::Passive,
        StrategyChoice::StepOpen,
        StrategyChoice::StepClosed,
        StrategyChoice::OpenTorque,
        StrategyChoice::Energy,
        StrategyChoice::Velocity,
        StrategyChoice::ModifiedTorque,
        StrategyChoice::EnergyApex,
        StrategyChoice::Shaped,
        StrategyChoice::EnergyApexSpinUp,
    ];

    /// The strategy with its default configuration.
    pub fn strategy(self) -> Strategy {
        match self {
            StrategyChoice::Passive => Strategy::Passive,
            StrategyChoice::StepOpen => {
                Strategy::Thesis(StanceLaw::StepOpen(step_open::Config::default()))
            }
            StrategyChoice::StepClosed => {
                Strategy::Thesis(StanceLaw::StepClosed(step_closed::Config::default()))
            }
            StrategyChoice::OpenTorque => {
                Strategy::Thesis(StanceLaw::OpenTorque(open_torque::Config::default()))
            }
            StrategyChoice::Energy => {
                Strategy::Thesis(StanceLaw::Energy(energy::Config::default()))
            }
            StrategyChoice::Velocity => {
                Strategy::Thesis(StanceLaw::Velocity(velocity::Config::default()))
            }
            StrategyChoice::ModifiedTorque => {
                Strategy::Thesis(StanceLaw::ModifiedTorque(modified_torque::Config::default()))
            }
            StrategyChoice::EnergyApex => Strategy::EnergyApex(ApexLoop::default()),
            StrategyChoice::Shaped => Strategy::Shaped(shaped::Config::default()),
            StrategyChoice::EnergyApexSpinUp => Strategy::EnergyApex(ApexLoop {
                spin_up_fraction: 0.5,
                proportional: 0.3,
                ..ApexLoop::default()
            }),
        }
    }
}

/// Configuration perturbations.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Arbitrary)]
pub struct Perturbations {
    /// The `sensor-disagree` check off (infinite spring mismatch), so the
    /// laws run longer on arbitrary words.
    pub disagree_off: bool,
    /// 32-bit encoder counters (the board's) instead of 16-bit.
    pub counters_32: bool,
    /// The apex loop's integral gain `0.05 + b * 0.04` (`energy-apex` only;
    /// 249 and above are out of range and refused).
    pub apex_gain: Option<u8>,
}

/// One control period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Arbitrary)]
pub struct PeriodRecord {
    /// The four raw sensor words.
    pub words: Words,
    /// The sensor read fails.
    pub read_fails: bool,
    /// The emergency stop is pressed.
    pub estop: bool,
    /// The amplifier reports a fault.
    pub amp_fault: bool,
    /// The DAC write fails.
    pub dac_fails: bool,
    /// The amplifier-enable write fails.
    pub enable_fails: bool,
    /// An overrun is reported (`report_overrun`) before the period.
    pub overrun: bool,
    /// The target apex is changed to `b / 255` m before the period.
    pub new_target_apex: Option<u8>,
    /// The application calls the period late (`end_period(true)`) after it.
    pub late: bool,
    /// An arm (`true`) or disarm (`false`) request before the period.
    pub arm: Option<bool>,
}

/// The raw sensor words of a period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Arbitrary)]
pub enum Words {
    /// Absolute words (an arbitrary jump).
    Absolute {
        /// Motor counter.
        motor: u32,
        /// Height counter.
        height: u32,
        /// Load-cell code (any `u16`, also above 12 bits).
        loadcell: u16,
        /// Potentiometer code (any `u16`).
        pot: u16,
    },
    /// Steps from the last sample: the counters by `d / 8` counts (up to
    /// +-4096), the ADC codes by `d / 64` codes (up to +-512, kept on the
    /// 12-bit scale).
    Delta {
        /// Motor counter step.
        motor: i16,
        /// Height counter step.
        height: i16,
        /// Load-cell step.
        loadcell: i16,
        /// Potentiometer step.
        pot: i16,
    },
}

/// [`PeriodRecord`]s until `u` is empty (a last, partial record reads the
/// missing bytes as zeros).
fn to_the_end(u: &mut Unstructured<'_>) -> arbitrary::Result<Vec<PeriodRecord>> {
    let mut v = Vec::new();
    while !u.is_empty() {
        v.push(PeriodRecord::arbitrary(u)?);
    }
    Ok(v)
}

/// The control period for the input's `period` byte, s: mostly the
/// board's 0.1 ms, also values the runner refuses (0, NaN, infinity,
/// negative) and odd ones it accepts (1 us, 10 ms, 1 s, the smallest normal
/// `f32`, `f32::MAX`, multiples of 50 us).
pub fn period_s(b: u8) -> f32 {
    match b {
        0..=239 => 1e-4,
        240 => 0.0,
        241 => f32::NAN,
        242 => f32::INFINITY,
        243 => -1e-4,
        244 => 1e-6,
        245 => 1e-2,
        246 => 1.0,
        247 => f32::MIN_POSITIVE,
        248 => f32::MAX,
        _ => f32::from(b - 248) * 5e-5,
    }
}

/// The fake board: hands out the sample (or fails), records what was written.
#[derive(Debug, Default)]
struct FakeIo {
    sample: RawSample,
    fail_read: bool,
    fail_dac: bool,
    fail_enable: bool,
    dac: Option<u16>,
    enable: Option<bool>,
}

impl HopperIo for FakeIo {
    type Error = ();
    fn read(&mut self) -> Result<RawSample, IoError<()>> {
        if self.fail_read {
            Err(IoError::Sensor)
        } else {
            Ok(self.sample)
        }
    }
    fn write_dac(&mut self, code: u16) -> Result<(), IoError<()>> {
        if self.fail_dac {
            return Err(IoError::Dac);
        }
        self.dac = Some(code);
        Ok(())
    }
    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<()>> {
        if self.fail_enable {
            return Err(IoError::Pin(()));
        }
        self.enable = Some(on);
        Ok(())
    }
}

fn adc_step(code: u16, delta: i16) -> u16 {
    let d = i32::from(delta) / 64;
    (i32::from(code) + d).clamp(0, 4095) as u16
}

fn apply(words: Words, s: &mut RawSample) {
    match words {
        Words::Absolute {
            motor,
            height,
            loadcell,
            pot,
        } => {
            s.motor_counts = motor;
            s.height_counts = height;
            s.loadcell_code = loadcell;
            s.pot_code = pot;
        }
        Words::Delta {
            motor,
            height,
            loadcell,
            pot,
        } => {
            s.motor_counts = s.motor_counts.wrapping_add(i32::from(motor / 8) as u32);
            s.height_counts = s.height_counts.wrapping_add(i32::from(height / 8) as u32);
            s.loadcell_code = adc_step(s.loadcell_code, loadcell);
            s.pot_code = adc_step(s.pot_code, pot);
        }
    }
}

/// The configuration and timing an input asks for.
pub fn config(input: &Input) -> (HopperConfig, Timing) {
    let mut cfg = HopperConfig {
        strategy: input.strategy.strategy(),
        target_apex_m: f32::from(input.target_apex) / 255.0,
        ..HopperConfig::default()
    };
    // No link in the harness: untethered, armed at the first period (the
    // records then arm and disarm at will).
    cfg.arming.untethered = true;
    let p = input.perturb;
    if p.disagree_off {
        // The table's "off" (its range ends at 1e30; infinity is refused).
        cfg.supervisor.spring_mismatch_n = 1.0e30;
    }
    if p.counters_32 {
        cfg.calibration.motor_counter_bits = 32;
        cfg.calibration.height_counter_bits = 32;
    }
    if let (Some(b), Strategy::EnergyApex(a)) = (p.apex_gain, &mut cfg.strategy) {
        a.gain = 0.05 + f32::from(b) * 0.04;
    }
    let timing = Timing {
        period_s: period_s(input.period),
        overrun_limit: 1 + u32::from(input.overrun_limit % 4),
        ..Timing::default()
    };
    (cfg, timing)
}

/// What one input did (for the stable test's summary).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Outcome {
    /// The runner refused the configuration or timing.
    pub refused: bool,
    /// Periods run.
    pub periods: usize,
    /// Periods that ended with no fault latched.
    pub clean_periods: usize,
    /// Periods that commanded a non-zero current.
    pub driven_periods: usize,
    /// Faults latched at the end.
    pub faults: Faults,
}

/// Runs one input through the period runner, asserting the invariants in
/// the [crate documentation](crate). Panics on a violation.
pub fn run(input: &Input) -> Outcome {
    let (cfg, timing) = config(input);
    let Ok(mut runner) = PeriodRunner::new(cfg, timing) else {
        return Outcome {
            refused: true,
            ..Outcome::default()
        };
    };
    let limit = cfg.model.usable_current_limit_a();
    let zero = cfg.calibration.dac_zero_code;

    // Start from rest: nut on its stop, spring at its preload.
    let cal = cfg.calibration;
    let preload_n = cfg.model.spring_stiffness_n_per_m * cfg.model.preload_m;
    let mut io = FakeIo {
        sample: RawSample {
            loadcell_code: (cal.loadcell_offset_code + preload_n / cal.loadcell_gain_n_per_code)
                as u16,
            pot_code: cal.pot_offset_code as u16,
            ..RawSample::default()
        },
        ..FakeIo::default()
    };
    runner.arming_mut().request_arm();
    let mut latched = runner.hopper().supervisor().faults();
    let mut outcome = Outcome::default();

    for rec in &input.periods {
        apply(rec.words, &mut io.sample);
        io.sample.estop_pressed = rec.estop;
        io.sample.amp_fault = rec.amp_fault;
        io.fail_read = rec.read_fails;
        io.fail_dac = rec.dac_fails;
        io.fail_enable = rec.enable_fails;
        if rec.overrun {
            runner.report_overrun();
        }
        match rec.arm {
            Some(true) => runner.arming_mut().request_arm(),
            Some(false) => runner.arming_mut().request_disarm(),
            None => {}
        }
        if let Some(b) = rec.new_target_apex {
            // Always in range (0..=1 m): a refusal would be a bug.
            let r = runner.hopper_mut().set_target_apex(f32::from(b) / 255.0);
            assert_eq!(r, Ok(()), "target apex {b}/255 refused");
        }
        io.dac = None;
        io.enable = None;
        let before = runner.hopper().supervisor().faults();

        let period = runner.run_period(&mut io, &mut NoCounter);

        check(&period, &io, before, latched, limit, zero);
        assert!(!runner.starved(), "{period:?}");
        latched = period.out.faults;
        runner.end_period(rec.late);
        outcome.periods += 1;
        if latched.is_empty() {
            outcome.clean_periods += 1;
        }
        if period.out.command.current_a != 0.0 {
            outcome.driven_periods += 1;
        }
    }
    outcome.faults = runner.hopper().supervisor().faults();
    outcome
}

/// The per-period assertions. `before`: the faults latched when the period
/// started (after any overrun report); `latched`: those at the end of the
/// previous period.
fn check(p: &Period, io: &FakeIo, before: Faults, latched: Faults, limit: f32, zero: u16) {
    let out = &p.out;
    let c = out.command;
    assert!(c.current_a.is_finite(), "{p:?}");
    assert!(c.current_a.abs() <= limit, "{p:?}");
    assert!(out.dac_code <= 4095, "{p:?}");
    // Every fault latched before stays latched.
    assert_eq!(out.faults.0 & latched.0, latched.0, "{p:?}");
    assert_eq!(out.faults.0 & before.0, before.0, "{p:?}");
    if !out.faults.is_empty() {
        assert_eq!(c, Command::SAFE, "{p:?}");
        assert_eq!(out.dac_code, zero, "{p:?}");
        assert_ne!(io.enable, Some(true), "{p:?}");
        if let Some(code) = io.dac {
            assert_eq!(code, zero, "{p:?}");
        }
    } else {
        assert_eq!(io.dac, Some(out.dac_code), "{p:?}");
        assert_eq!(io.enable, Some(c.amp_enable), "{p:?}");
    }
    assert_eq!(out.record.faults, out.faults.0, "{p:?}");
    // Disarmed (at boot, on request, after a fault or the e-stop): the safe
    // output; armed only without a fault or the e-stop.
    if !p.armed {
        assert_eq!(c, Command::SAFE, "{p:?}");
        assert_eq!(out.dac_code, zero, "{p:?}");
        assert_ne!(io.enable, Some(true), "{p:?}");
    } else {
        assert!(out.faults.is_empty(), "{p:?}");
    }
    if p.arm_event == Some(hopper_control::arming::ArmEvent::Armed) {
        assert!(out.faults.is_empty(), "{p:?}");
    }
    // The feed policy never starves on a correct build.
    assert!(p.feed_watchdog, "{p:?}");
    assert!(!out.faults.contains(Fault::SelfCheck), "{p:?}");
    // What latched in this period, and what is logged.
    // Since the last period's report: an overrun reported between periods
    // counts as newly latched in the period that first shows it.
    assert_eq!(p.newly_latched, Faults(out.faults.0 & !latched.0), "{p:?}");
    if p.newly_latched.is_empty() {
        // Compared as printed: a ledger may hold NaN energies (a rejected
        // sample), which `==` would call unequal to themselves.
        assert_eq!(
            format!("{:?}", p.log),
            format!("{:?}", out.hop.map(LogItem::Hop)),
            "{p:?}"
        );
    } else {
        assert_eq!(
            p.log,
            Some(LogItem::Faults {
                step: out.record.step,
                faults: out.faults,
            }),
            "{p:?}"
        );
    }
    assert_eq!(p.step_cost, 0, "{p:?}");
}

#[cfg(test)]
mod tests {
    //! The stable-toolchain path: no libFuzzer, no coverage feedback, just
    //! [`run`] over inputs from a fixed seed. `FUZZ_CASES` sets the number
    //! of random-byte inputs (default 400).

    use super::*;

    /// SplitMix64: a fixed, dependency-free byte source.
    struct SplitMix(u64);

    impl SplitMix {
        fn next(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }

        fn bytes(&mut self, n: usize) -> Vec<u8> {
            (0..n).map(|_| self.next() as u8).collect()
        }
    }

    fn cases() -> usize {
        std::env::var("FUZZ_CASES")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(400)
    }

    #[derive(Debug, Default)]
    struct Tally {
        inputs: usize,
        refused: usize,
        periods: usize,
        clean: usize,
        driven: usize,
        ended_clean: usize,
        /// How many inputs ended with each fault latched.
        faults: std::collections::BTreeMap<String, usize>,
    }

    impl Tally {
        fn add(&mut self, o: Outcome) {
            self.inputs += 1;
            self.refused += usize::from(o.refused);
            self.periods += o.periods;
            self.clean += o.clean_periods;
            self.driven += o.driven_periods;
            self.ended_clean += usize::from(!o.refused && o.faults.is_empty());
            for f in o.faults.iter() {
                *self.faults.entry(format!("{f:?}")).or_default() += 1;
            }
        }
    }

    /// Random bytes decoded as libFuzzer's would be (`arbitrary_take_rest`).
    #[test]
    fn random_bytes_through_arbitrary() {
        let mut rng = SplitMix(0x5EED_0015);
        let mut t = Tally::default();
        for _ in 0..cases() {
            let len = (rng.next() % 4096) as usize;
            let data = rng.bytes(len);
            let Ok(input) = Input::arbitrary_take_rest(Unstructured::new(&data)) else {
                continue;
            };
            t.add(run(&input));
        }
        println!("random bytes: {t:?}");
        assert!(t.periods > 0);
    }

    /// Every input in `fuzz/regressions/` (inputs libFuzzer once stopped
    /// on), decoded as libFuzzer does.
    #[test]
    fn regressions_replay() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("regressions");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap_or_else(|e| panic!("{dir:?}: {e}")) {
            let path = entry.unwrap_or_else(|e| panic!("{e}")).path();
            let data = std::fs::read(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
            if let Ok(input) = Input::arbitrary_take_rest(Unstructured::new(&data)) {
                let o = run(&input);
                println!("{}: {o:?}", path.display());
            }
            n += 1;
        }
        assert!(n > 0, "no input in {dir:?}");
    }

    /// Inputs built to stay near rest (small steps, rare failures), so the
    /// laws run for many periods instead of the first jump faulting.
    #[test]
    fn small_steps_run_the_laws() {
        let mut rng = SplitMix(0xC0FF_EE15);
        let mut t = Tally::default();
        for i in 0..cases() / 2 {
            let n = 50 + (rng.next() % 1500) as usize;
            let periods = (0..n)
                .map(|_| {
                    let r = rng.next();
                    // Counter steps of -1..=1 counts, ADC steps of -1..=1 codes.
                    let small = |x: u64| ((x % 3) as i16 - 1) * 8;
                    let adc = |x: u64| ((x % 3) as i16 - 1) * 64;
                    let rare = |bit: u32| (r >> 40) & 0xFFF == u64::from(bit);
                    PeriodRecord {
                        words: Words::Delta {
                            motor: small(r),
                            height: small(r >> 8),
                            loadcell: adc(r >> 16),
                            pot: adc(r >> 24),
                        },
                        read_fails: rare(1),
                        estop: rare(2),
                        amp_fault: rare(3),
                        dac_fails: rare(4),
                        enable_fails: rare(5),
                        overrun: rare(6),
                        new_target_apex: ((r >> 52) & 0x3F == 0).then_some((r >> 32) as u8 % 40),
                        late: (r >> 58) == 0,
                        // Now and then a disarm, and an arm request after it.
                        arm: match (r >> 44) & 0x1FF {
                            0 => Some(false),
                            1..=3 => Some(true),
                            _ => None,
                        },
                    }
                })
                .collect();
            let r = rng.next();
            let input = Input {
                strategy: StrategyChoice::ALL[i % StrategyChoice::ALL.len()],
                target_apex: 5 + (r % 15) as u8,
                perturb: Perturbations {
                    disagree_off: r & 0x100 != 0,
                    counters_32: r & 0x200 != 0,
                    apex_gain: (r & 0x400 != 0).then_some((r >> 16) as u8),
                },
                period: if r & 0x800 != 0 { 0 } else { (r >> 24) as u8 },
                overrun_limit: (r >> 32) as u8,
                periods,
            };
            t.add(run(&input));
        }
        println!("small steps: {t:?}");
        assert!(t.clean > 0, "no period ran without a fault: {t:?}");
        assert!(t.driven > 0, "no law commanded a current: {t:?}");
    }

    /// Every strategy and every period choice, at rest: accepted timings
    /// run clean, refused ones return.
    #[test]
    fn every_strategy_and_period_at_rest() {
        let mut t = Tally::default();
        for strategy in StrategyChoice::ALL {
            for period in 230..=255u8 {
                let input = Input {
                    strategy,
                    target_apex: 13,
                    perturb: Perturbations::default(),
                    period,
                    overrun_limit: 2,
                    periods: vec![
                        PeriodRecord {
                            words: Words::Delta {
                                motor: 0,
                                height: 0,
                                loadcell: 0,
                                pot: 0,
                            },
                            read_fails: false,
                            estop: false,
                            amp_fault: false,
                            dac_fails: false,
                            enable_fails: false,
                            overrun: false,
                            new_target_apex: None,
                            late: false,
                            arm: None,
                        };
                        200
                    ],
                };
                let p = period_s(period);
                let o = run(&input);
                assert_eq!(o.refused, !(p > 0.0 && p.is_finite()), "{period}: {o:?}");
                t.add(o);
            }
        }
        println!("at rest: {t:?}");
    }
}
