//! Hardware in the loop: the robot's side of the lockstep exchange.
//!
//! The host runs the plant, sensor and amplifier models and sends each
//! period's raw sample ([`HilSample`]); the robot image runs the same
//! control period as on the robot ([`crate::ControlLoop::period`]) on it,
//! with [`HilIo`] as its I/O, and answers with what the period wrote
//! ([`HilActuate`]: the DAC code, the amplifier enable, the control
//! interrupt's cost, and what a host run reports of the firmware). The
//! host owns the clock: a period runs when its sample arrives.
//!
//! The board's own e-stop input and amplifier-enable output stay in the
//! loop ([`HilPins`]): a bench e-stop presses the robot's e-stop as on the
//! robot, and the enable pin follows the period's output.

use hopper_control::estimator::PhaseEvent;
use hopper_control::hal::{HopperIo, IoError, RawSample};
use hopper_control::hopper::HopperConfig;
use hopper_control::runner::{HopperSlot, Period, PeriodRunner};
use hopper_protocol::{vocab, HilActuate, HilSample};

/// The largest DAC code (a 12-bit converter, as the board's).
const DAC_MAX_CODE: u16 = 4095;

/// The HIL image's configuration at boot: the firmware's defaults (the
/// design machine) and, as on the board, no arming before a tare and
/// homing. The host sets the rest over the link, by the parameters'
/// names; what the link cannot set (the machine's lead, torque constant,
/// stops, converter widths) must be these for a run to go ahead.
pub fn boot_config() -> HopperConfig {
    let mut cfg = HopperConfig::default();
    cfg.arming.require_tare = true;
    cfg.arming.require_home = true;
    cfg
}

/// The board's pins that stay real in the loop.
pub trait HilPins {
    /// What a pin reports when it fails.
    type Error: core::fmt::Debug;
    /// The board's e-stop input reads pressed.
    fn estop_pressed(&mut self) -> bool;
    /// Drives the amplifier-enable output.
    fn set_amp_enabled(&mut self, on: bool) -> Result<(), Self::Error>;
}

/// No pins (a host-side target, tests): the e-stop is the sample's alone.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoPins;

impl HilPins for NoPins {
    type Error = core::convert::Infallible;
    fn estop_pressed(&mut self) -> bool {
        false
    }
    fn set_amp_enabled(&mut self, _on: bool) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// The control period's I/O in the loop: the host's sample in, the
/// outputs kept for the answer (and the enable on the board's pin).
#[derive(Debug, Clone)]
pub struct HilIo<P> {
    pins: P,
    seq: u32,
    sample: RawSample,
    dac_code: u16,
    amp_enabled: bool,
}

impl<P: HilPins> HilIo<P> {
    /// Nothing received yet; the amplifier off.
    pub fn new(pins: P) -> Self {
        Self {
            pins,
            seq: 0,
            sample: RawSample::default(),
            dac_code: 0,
            amp_enabled: false,
        }
    }

    /// The sample the next period reads.
    pub fn load(&mut self, s: &HilSample) {
        self.seq = s.seq;
        self.sample = RawSample {
            motor_counts: s.motor_counts,
            height_counts: s.height_counts,
            loadcell_code: s.loadcell_code,
            pot_code: s.pot_code,
            estop_pressed: s.estop_pressed,
            amp_fault: s.amp_fault,
        };
    }

    /// The answer to the loaded sample, after `period` ran on it:
    /// `isr_ticks` is the control interrupt's cost, in the robot's
    /// counter's ticks.
    pub fn actuate<H: HopperSlot>(
        &self,
        period: &Period,
        runner: &PeriodRunner<H>,
        isr_ticks: u32,
    ) -> HilActuate {
        let hopper = runner.hopper();
        let supervisor = hopper.supervisor();
        let motor = supervisor.thermal();
        let event = match period.out.event {
            None => 0,
            Some(PhaseEvent::Touchdown) => vocab::PhaseEvent::Touchdown.code(),
            Some(PhaseEvent::Liftoff) => vocab::PhaseEvent::Liftoff.code(),
            Some(PhaseEvent::Apex { .. }) => vocab::PhaseEvent::Apex.code(),
            Some(PhaseEvent::Bottom) => vocab::PhaseEvent::Bottom.code(),
        };
        HilActuate {
            seq: self.seq,
            dac_code: self.dac_code,
            amp_enabled: self.amp_enabled,
            isr_ticks,
            event,
            faults: period.out.faults.0,
            armed: period.armed,
            winding_c: motor.winding_c(),
            current_limit_a: supervisor.current_limit_a() * motor.limit_scale(),
            derated: motor.limit_scale() < 1.0,
            withdrawn_touchdowns: hopper.estimator().withdrawn_touchdowns(),
            hop: period.out.hop.as_ref().map(crate::wire_hop),
        }
    }
}

impl<P: HilPins> HopperIo for HilIo<P> {
    type Error = P::Error;

    /// The host's sample; the board's e-stop input presses it too.
    fn read(&mut self) -> Result<RawSample, IoError<P::Error>> {
        let mut s = self.sample;
        s.estop_pressed |= self.pins.estop_pressed();
        Ok(s)
    }

    /// Kept for the answer; codes beyond the 12-bit converter are refused
    /// as the board's DAC refuses them.
    fn write_dac(&mut self, code: u16) -> Result<(), IoError<P::Error>> {
        if code > DAC_MAX_CODE {
            return Err(IoError::Dac);
        }
        self.dac_code = code;
        Ok(())
    }

    /// The board's pin, and kept for the answer.
    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<P::Error>> {
        self.pins.set_amp_enabled(on).map_err(IoError::Pin)?;
        self.amp_enabled = on;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The board's e-stop input in the loop.
    struct Pins {
        estop: bool,
        enabled: Option<bool>,
    }

    impl HilPins for Pins {
        type Error = ();
        fn estop_pressed(&mut self) -> bool {
            self.estop
        }
        fn set_amp_enabled(&mut self, on: bool) -> Result<(), ()> {
            self.enabled = Some(on);
            Ok(())
        }
    }

    fn sample(estop_pressed: bool) -> HilSample {
        HilSample {
            seq: 7,
            motor_counts: 1,
            height_counts: 2,
            loadcell_code: 3,
            pot_code: 4,
            estop_pressed,
            amp_fault: true,
        }
    }

    /// The period reads the host's sample with either e-stop pressing it,
    /// the enable reaches the board's pin, and a DAC code the 12-bit
    /// converter cannot take is refused as the board's refuses it.
    #[test]
    fn the_sample_is_read_and_the_outputs_kept() {
        let mut io = HilIo::new(Pins {
            estop: false,
            enabled: None,
        });
        io.load(&sample(false));
        let r = io.read().unwrap_or_default();
        assert_eq!(
            (r.motor_counts, r.height_counts, r.loadcell_code, r.pot_code),
            (1, 2, 3, 4)
        );
        assert!(!r.estop_pressed && r.amp_fault);
        io.load(&sample(true));
        assert!(io.read().is_ok_and(|r| r.estop_pressed));
        io.pins.estop = true;
        io.load(&sample(false));
        assert!(io.read().is_ok_and(|r| r.estop_pressed));
        assert_eq!(io.write_dac(4096), Err(IoError::Dac));
        assert_eq!(io.write_dac(4095), Ok(()));
        assert_eq!(io.set_amp_enabled(true), Ok(()));
        assert_eq!(io.pins.enabled, Some(true));
        assert_eq!((io.seq, io.dac_code, io.amp_enabled), (7, 4095, true));
    }
}
