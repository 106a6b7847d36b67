//! The hopper's I/O boundary: raw sensor samples in, DAC code and amplifier enable out.
//!
//! embedded-hal 1.0 has no ADC, DAC or quadrature-encoder traits, so
//! [`HopperIo`] is this project's own trait. It works in raw units (counts and
//! converter codes); [`crate::calibration`] turns them into SI. A board
//! composes it from its parts with [`PinnedIo`]: the converters and
//! counters behind [`Converters`] (this project's trait, for what
//! embedded-hal lacks), the e-stop and amplifier-fault inputs as
//! embedded-hal `InputPin`s, the amplifier enable behind [`AmpEnable`]
//! (the board's hardware deadman, or any `OutputPin` through
//! [`PlainEnable`]). `hopper-app`'s `BoardIo` is that composition for the
//! STM32F405 board; the simulator (`hopper-sil`'s `sim_io`) implements the
//! trait over the plant.

/// One raw reading of every sensor, taken at the start of a control period.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RawSample {
    /// Motor quadrature counter, raw (wraps at the counter width).
    pub motor_counts: u32,
    /// Height (planarizer pulley) quadrature counter, raw (wraps at the counter width).
    pub height_counts: u32,
    /// Load-cell ADC code.
    pub loadcell_code: u16,
    /// Leg-compression potentiometer ADC code.
    pub pot_code: u16,
    /// The emergency stop is pressed.
    pub estop_pressed: bool,
    /// The servo amplifier reports a fault.
    pub amp_fault: bool,
}

impl RawSample {
    /// A hopper at rest in flight at the origin, as `cal` reads it: nut on
    /// its stop, the spring at the default model's preload (the tests' and
    /// the self-checks' quiet input).
    pub fn at_rest(cal: &crate::calibration::Calibration) -> Self {
        let m = crate::model::ModelParams::default();
        let preload_n = m.spring_stiffness_n_per_m * m.preload_m;
        RawSample {
            loadcell_code: (cal.loadcell_offset_code + preload_n / cal.loadcell_gain_n_per_code)
                as u16,
            pot_code: cal.pot_offset_code as u16,
            ..RawSample::default()
        }
    }
}

/// Why a [`HopperIo`] operation failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum IoError<E> {
    /// A sensor (encoder counter, ADC) could not be read.
    Sensor,
    /// The DAC did not accept the code.
    Dac,
    /// A digital pin (amplifier enable, e-stop) failed.
    Pin(E),
}

/// The hopper's I/O, in raw units. Implemented by the board and by the simulator.
pub trait HopperIo {
    /// The error a pin (or other board resource) reports.
    type Error: core::fmt::Debug;

    /// Reads every sensor once.
    fn read(&mut self) -> Result<RawSample, IoError<Self::Error>>;

    /// Writes the current command as a DAC code (see
    /// [`crate::calibration::DacMap::code`]).
    fn write_dac(&mut self, code: u16) -> Result<(), IoError<Self::Error>>;

    /// Enables (`true`) or disables (`false`) the servo amplifier.
    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<Self::Error>>;
}

/// The amplifier-enable output: what [`PinnedIo`] drives each period.
/// A board with the hardware deadman implements it with its timer (the
/// enable lapses by itself when the periods stop); a board without one
/// uses any embedded-hal output pin ([`PlainEnable`]).
pub trait AmpEnable {
    /// What the output reports when it fails (a lapsed deadman).
    type Error: core::fmt::Debug;
    /// Drives the enable on or off.
    fn set(&mut self, on: bool) -> Result<(), Self::Error>;
    /// Whether the pin reads off, where it can be read back (`None`: it
    /// cannot). Read after an off period, so that a pin stuck on (a
    /// shorted driver, a pin left to another function) latches a fault.
    fn reads_off(&mut self) -> Option<bool> {
        None
    }
}

/// A plain output pin as the amplifier enable (a board without the
/// deadman): high is enabled.
#[derive(Debug)]
pub struct PlainEnable<P>(pub P);

impl<P: embedded_hal::digital::OutputPin> AmpEnable for PlainEnable<P> {
    type Error = P::Error;
    fn set(&mut self, on: bool) -> Result<(), P::Error> {
        if on {
            self.0.set_high()
        } else {
            self.0.set_low()
        }
    }
}

/// What embedded-hal 1.0 has no traits for: the encoder counters, the
/// converters' codes of this period and the DAC.
pub trait Converters {
    /// The motor's and the height encoder's counters, raw.
    fn counters(&mut self) -> (u32, u32);
    /// The load cell's and the potentiometer's codes of this period.
    fn codes(&mut self) -> (u16, u16);
    /// Writes the current command's code; `false` when the DAC refuses it
    /// (beyond its width).
    fn write_dac(&mut self, code: u16) -> bool;
}

/// Why a pin of [`PinnedIo`] failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PinError<E> {
    /// The e-stop or amplifier-fault input could not be read.
    Input,
    /// The enable output failed (a lapsed deadman).
    Enable(E),
    /// The enable reads on a period after it was driven off.
    EnableStuckOn,
}

/// The hopper's I/O from a board's parts: the converters and counters
/// ([`Converters`]), the e-stop and amplifier-fault inputs (embedded-hal
/// input pins) and the amplifier enable ([`AmpEnable`]). Another board is
/// another set of parts: a pin map.
///
/// The e-stop input is normally closed to ground with a pull-up: high is
/// pressed (or a broken wire). The amplifier's fault output is open drain,
/// active low.
#[derive(Debug)]
pub struct PinnedIo<C, E, F, A> {
    /// The converters and counters.
    pub converters: C,
    estop: E,
    amp_fault: F,
    enable: A,
    /// The enable was driven off in the last period.
    was_off: bool,
}

impl<C, E, F, A> PinnedIo<C, E, F, A> {
    /// The I/O over these parts; the enable is taken to be off.
    pub fn new(converters: C, estop: E, amp_fault: F, enable: A) -> Self {
        Self {
            converters,
            estop,
            amp_fault,
            enable,
            was_off: true,
        }
    }

    /// The enable output (the board reads its deadman's state).
    pub fn enable(&mut self) -> &mut A {
        &mut self.enable
    }
}

impl<C, E, F, A> HopperIo for PinnedIo<C, E, F, A>
where
    C: Converters,
    E: embedded_hal::digital::InputPin,
    F: embedded_hal::digital::InputPin,
    A: AmpEnable,
{
    type Error = PinError<A::Error>;

    fn read(&mut self) -> Result<RawSample, IoError<Self::Error>> {
        let (motor_counts, height_counts) = self.converters.counters();
        let (loadcell_code, pot_code) = self.converters.codes();
        let estop_pressed = self
            .estop
            .is_high()
            .map_err(|_| IoError::Pin(PinError::Input))?;
        let amp_fault = self
            .amp_fault
            .is_low()
            .map_err(|_| IoError::Pin(PinError::Input))?;
        Ok(RawSample {
            motor_counts,
            height_counts,
            loadcell_code,
            pot_code,
            estop_pressed,
            amp_fault,
        })
    }

    fn write_dac(&mut self, code: u16) -> Result<(), IoError<Self::Error>> {
        if self.converters.write_dac(code) {
            Ok(())
        } else {
            Err(IoError::Dac)
        }
    }

    /// Drives the enable; off for a second period, it must read off where
    /// it can be read back.
    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<Self::Error>> {
        self.enable
            .set(on)
            .map_err(|e| IoError::Pin(PinError::Enable(e)))?;
        let stuck = !on && self.was_off && self.enable.reads_off() == Some(false);
        self.was_off = !on;
        if stuck {
            return Err(IoError::Pin(PinError::EnableStuckOn));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::digital::{Mock as Pin, State, Transaction as T};

    /// Converters that read fixed values and take codes up to 4095.
    struct Fixed;

    impl Converters for Fixed {
        fn counters(&mut self) -> (u32, u32) {
            (11, 22)
        }
        fn codes(&mut self) -> (u16, u16) {
            (333, 444)
        }
        fn write_dac(&mut self, code: u16) -> bool {
            code <= 4095
        }
    }

    /// An enable whose pin reads back what a test says.
    struct Readback {
        pin: Pin,
        reads_off: Option<bool>,
    }

    impl AmpEnable for Readback {
        type Error = core::convert::Infallible;
        fn set(&mut self, on: bool) -> Result<(), Self::Error> {
            let _ = PlainEnable(&mut self.pin).set(on);
            Ok(())
        }
        fn reads_off(&mut self) -> Option<bool> {
            self.reads_off
        }
    }

    /// The inputs' levels become the sample's e-stop (high: pressed) and
    /// amplifier fault (low: faulted); the enable follows the period.
    #[test]
    fn the_pins_read_and_drive_the_hopper_io() {
        let estop = Pin::new(&[T::get(State::Low), T::get(State::High)]);
        let fault = Pin::new(&[T::get(State::High), T::get(State::Low)]);
        let en = Pin::new(&[T::set(State::High), T::set(State::Low)]);
        let mut io = PinnedIo::new(Fixed, estop, fault, PlainEnable(en));
        let a = io.read().unwrap_or_default();
        assert_eq!(
            (a.motor_counts, a.height_counts, a.loadcell_code, a.pot_code),
            (11, 22, 333, 444)
        );
        assert!(!a.estop_pressed && !a.amp_fault);
        let b = io.read().unwrap_or_default();
        assert!(b.estop_pressed && b.amp_fault);
        assert_eq!(io.set_amp_enabled(true), Ok(()));
        assert_eq!(io.set_amp_enabled(false), Ok(()));
        assert_eq!(io.write_dac(4095), Ok(()));
        assert_eq!(io.write_dac(4096), Err(IoError::Dac));
        let PinnedIo {
            mut estop,
            mut amp_fault,
            enable: PlainEnable(mut en),
            ..
        } = io;
        estop.done();
        amp_fault.done();
        en.done();
    }

    /// An enable that reads on a period after it was driven off latches
    /// (the period runner then disables and latches amp-fault); the
    /// period that switches it off is not judged (the pin may lag).
    #[test]
    fn an_enable_stuck_on_is_an_error() {
        let en = Pin::new(&[T::set(State::High), T::set(State::Low), T::set(State::Low)]);
        let mut io = PinnedIo::new(
            Fixed,
            Pin::new(&[]),
            Pin::new(&[]),
            Readback {
                pin: en,
                reads_off: Some(false),
            },
        );
        assert_eq!(io.set_amp_enabled(true), Ok(()));
        assert_eq!(io.set_amp_enabled(false), Ok(()));
        assert_eq!(
            io.set_amp_enabled(false),
            Err(IoError::Pin(PinError::EnableStuckOn))
        );
        let PinnedIo {
            mut estop,
            mut amp_fault,
            mut enable,
            ..
        } = io;
        estop.done();
        amp_fault.done();
        enable.pin.done();
    }
}
