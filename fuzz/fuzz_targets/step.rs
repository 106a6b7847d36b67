//! Arbitrary raw sensor words through the whole control period.
//!
//! The input bytes pick a strategy and a few configuration perturbations,
//! then a sequence of periods, each a raw sample (absolute or relative to the
//! last one, so the fuzzer can reach the laws past the encoder-jump check),
//! a time step, and I/O failures. Every period runs through
//! `Hopper::run_period` on a fake `HopperIo`, and asserts:
//!
//! - no panic (libFuzzer reports one as a crash);
//! - the approved command is finite and within the supervisor's current limit;
//! - the DAC code is within the 12-bit range, and is the code the fake DAC
//!   received (when it accepted the write);
//! - a period with a latched fault commands 0 A, the zero-current code and
//!   the amplifier disabled, and every latched fault stays latched;
//! - the watchdog feed policy (`hopper_control::watchdog`) never starves:
//!   the output never contradicts itself.
//!
//! Input layout (missing bytes read as 0):
//!
//! | byte | meaning |
//! |------|---------|
//! | 0 | strategy: passive, each thesis law, energy-apex (with or without spin-up) |
//! | 1 | target apex, `b / 255` m |
//! | 2 | bit 0: sensor-disagree check off; bit 1: 32-bit encoder counters (the board's); bit 2: apex-loop gain perturbed |
//! | 3.. | periods of 10 bytes: flags, motor (2), height (2), load cell (2), potentiometer (2), dt |
//!
//! Period flags: bit 0 the read fails, 1 e-stop, 2 amplifier fault, 3 the DAC
//! write fails, 4 the enable write fails, 5 absolute words (else deltas from
//! the previous sample), 6 an overrun is reported before the step, 7 the
//! target apex is changed to `dt / 255` m before the step.
#![no_main]

use hopper_control::hal::{HopperIo, IoError, RawSample};
use hopper_control::hopper::{ApexLoop, Hopper, HopperConfig, Strategy};
use hopper_control::laws::{
    constant_torque, energy_torque, modified_torque, shaped, step_closed, step_open, velocity,
    StanceLaw,
};
use hopper_control::supervisor::Command;
use hopper_control::watchdog::{Decision, FeedPolicy};
use libfuzzer_sys::fuzz_target;

/// The fake board: hands out the sample (or fails), records what was written.
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

fn byte(data: &[u8], i: usize) -> u8 {
    data.get(i).copied().unwrap_or(0)
}

fn word(data: &[u8], i: usize) -> u16 {
    u16::from_le_bytes([byte(data, i), byte(data, i + 1)])
}

fn strategy(b: u8) -> Strategy {
    match b % 10 {
        0 => Strategy::Passive,
        1 => Strategy::Thesis(StanceLaw::StepOpen(step_open::Config::default())),
        2 => Strategy::Thesis(StanceLaw::StepClosed(step_closed::Config::default())),
        3 => Strategy::Thesis(StanceLaw::ConstantTorque(constant_torque::Config::default())),
        4 => Strategy::Thesis(StanceLaw::EnergyTorque(energy_torque::Config::default())),
        5 => Strategy::Thesis(StanceLaw::Velocity(velocity::Config::default())),
        6 => Strategy::Thesis(StanceLaw::ModifiedTorque(modified_torque::Config::default())),
        7 => Strategy::EnergyApex(ApexLoop::default()),
        8 => Strategy::Shaped(shaped::Config::default()),
        _ => Strategy::EnergyApex(ApexLoop {
            spin_up_fraction: 0.5,
            proportional: 0.3,
            ..ApexLoop::default()
        }),
    }
}

fn dt_of(b: u8) -> f32 {
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

fn adc_step(code: u16, delta: u16) -> u16 {
    // A signed delta of up to +-512 codes, kept on the 12-bit scale.
    let d = i32::from(delta as i16) / 64;
    (i32::from(code) + d).clamp(0, 4095) as u16
}

fuzz_target!(|data: &[u8]| {
    let mut cfg = HopperConfig {
        strategy: strategy(byte(data, 0)),
        ..HopperConfig::default()
    };
    let perturb = byte(data, 2);
    if perturb & 1 != 0 {
        cfg.supervisor.spring_mismatch_n = f32::INFINITY;
    }
    if perturb & 2 != 0 {
        cfg.calibration.motor_counter_bits = 32;
        cfg.calibration.height_counter_bits = 32;
    }
    if perturb & 4 != 0 {
        if let Strategy::EnergyApex(a) = &mut cfg.strategy {
            a.gain = 0.05 + f32::from(perturb >> 3) * 0.3;
        }
    }
    let Ok(mut hopper) = Hopper::new(cfg) else {
        return;
    };
    let _ = hopper.set_target_apex(f32::from(byte(data, 1)) / 255.0);
    let limit = cfg.supervisor.current_limit_a;
    let zero = cfg.calibration.dac_zero_code;
    let mut policy = FeedPolicy::for_hopper(&cfg);

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
        fail_read: false,
        fail_dac: false,
        fail_enable: false,
        dac: None,
        enable: None,
    };
    let mut latched = hopper.supervisor().faults();

    for rec in data.get(3..).unwrap_or(&[]).chunks(10) {
        let flags = byte(rec, 0);
        let (m, z, lc, pot, dtb) = (
            word(rec, 1),
            word(rec, 3),
            word(rec, 5),
            word(rec, 7),
            byte(rec, 9),
        );
        let s = &mut io.sample;
        if flags & 0x20 != 0 {
            s.motor_counts = u32::from(m) | (u32::from(z) << 16);
            s.height_counts = u32::from(z).wrapping_mul(0x9E37);
            s.loadcell_code = lc;
            s.pot_code = pot;
        } else {
            s.motor_counts = s.motor_counts.wrapping_add(i32::from(m as i16 / 8) as u32);
            s.height_counts = s.height_counts.wrapping_add(i32::from(z as i16 / 8) as u32);
            s.loadcell_code = adc_step(s.loadcell_code, lc);
            s.pot_code = adc_step(s.pot_code, pot);
        }
        s.estop_pressed = flags & 0x02 != 0;
        s.amp_fault = flags & 0x04 != 0;
        io.fail_read = flags & 0x01 != 0;
        io.fail_dac = flags & 0x08 != 0;
        io.fail_enable = flags & 0x10 != 0;
        if flags & 0x40 != 0 {
            hopper.supervisor_mut().report_overrun();
        }
        if flags & 0x80 != 0 {
            let _ = hopper.set_target_apex(f32::from(dtb) / 255.0);
        }
        io.dac = None;
        io.enable = None;

        let out = hopper.run_period(&mut io, dt_of(dtb));

        let c = out.command;
        assert!(c.current_a.is_finite(), "{out:?}");
        assert!(c.current_a.abs() <= limit, "{out:?}");
        assert!(out.dac_code <= 4095, "{out:?}");
        // Every fault latched before stays latched.
        assert_eq!(out.faults.0 & latched.0, latched.0, "{out:?}");
        if !out.faults.is_empty() {
            assert_eq!(c, Command::SAFE, "{out:?}");
            assert_eq!(out.dac_code, zero, "{out:?}");
            assert_ne!(io.enable, Some(true), "{out:?}");
            if let Some(code) = io.dac {
                assert_eq!(code, zero, "{out:?}");
            }
        } else {
            assert_eq!(io.dac, Some(out.dac_code), "{out:?}");
            assert_eq!(io.enable, Some(c.amp_enable), "{out:?}");
        }
        assert_eq!(out.record.faults, out.faults.0);
        assert_eq!(policy.after_step(&out), Decision::Feed, "{out:?}");
        latched = out.faults;
    }
});
