//! The hopper's I/O boundary: raw sensor samples in, DAC code and amplifier enable out.
//!
//! embedded-hal 1.0 has no ADC, DAC or quadrature-encoder traits, so
//! [`HopperIo`] is this project's own trait. It works in raw units (counts and
//! converter codes); [`crate::calibration`] turns them into SI.
//!
//! The amplifier-enable output and the e-stop input are ordinary digital pins,
//! so [`PinsIo`] implements [`HopperIo`] from two `embedded_hal::digital` pins
//! plus a board-specific [`RawSensors`] + [`DacWriter`] part: a board only has
//! to supply the pins and its sensor reads.

use embedded_hal::digital::{Error as _, ErrorKind, InputPin, OutputPin};

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
    /// [`crate::calibration::Calibration::current_to_dac_code`]).
    fn write_dac(&mut self, code: u16) -> Result<(), IoError<Self::Error>>;

    /// Enables (`true`) or disables (`false`) the servo amplifier.
    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<Self::Error>>;
}

/// The analog and encoder part of a sample, without the e-stop (which [`PinsIo`] reads from a pin).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorFrame {
    /// Motor quadrature counter, raw.
    pub motor_counts: u32,
    /// Height quadrature counter, raw.
    pub height_counts: u32,
    /// Load-cell ADC code.
    pub loadcell_code: u16,
    /// Potentiometer ADC code.
    pub pot_code: u16,
    /// The servo amplifier reports a fault.
    pub amp_fault: bool,
}

/// A sensor read failed (the board decides what that means: ADC timeout, counter error, ...).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorReadError;

/// A DAC write failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DacWriteError;

/// Board-specific reads of the encoders, ADC channels and amplifier fault line.
pub trait RawSensors {
    /// Reads every sensor except the e-stop once.
    fn read_sensors(&mut self) -> Result<SensorFrame, SensorReadError>;
}

/// Board-specific DAC output for the amplifier's current command.
pub trait DacWriter {
    /// Writes `code` to the DAC.
    fn write_code(&mut self, code: u16) -> Result<(), DacWriteError>;
}

/// Level of the e-stop input that means "pressed".
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EstopPolarity {
    /// Pressed reads high.
    ActiveHigh,
    /// Pressed reads low (a normally-closed switch to ground with a pull-up
    /// reads high when pressed, so use `ActiveHigh` for that wiring).
    ActiveLow,
}

/// [`HopperIo`] from an amplifier-enable output pin (active high), an e-stop
/// input pin and a board part `S` for the sensors and the DAC.
///
/// Pin errors are reported as their [`ErrorKind`], so the two pins may have
/// different error types.
#[derive(Debug)]
pub struct PinsIo<En, Stop, S> {
    enable: En,
    estop: Stop,
    estop_polarity: EstopPolarity,
    board: S,
}

impl<En, Stop, S> PinsIo<En, Stop, S>
where
    En: OutputPin,
    Stop: InputPin,
    S: RawSensors + DacWriter,
{
    /// Takes the pins and board part and drives the amplifier enable low (disabled) first.
    pub fn new(
        mut enable: En,
        estop: Stop,
        estop_polarity: EstopPolarity,
        board: S,
    ) -> Result<Self, IoError<ErrorKind>> {
        enable.set_low().map_err(|e| IoError::Pin(e.kind()))?;
        Ok(Self {
            enable,
            estop,
            estop_polarity,
            board,
        })
    }

    /// Gives the pins and board part back (the enable pin is left as it is).
    pub fn release(self) -> (En, Stop, S) {
        (self.enable, self.estop, self.board)
    }

    /// The board part, e.g. for board-specific diagnostics.
    pub fn board_mut(&mut self) -> &mut S {
        &mut self.board
    }
}

impl<En, Stop, S> HopperIo for PinsIo<En, Stop, S>
where
    En: OutputPin,
    Stop: InputPin,
    S: RawSensors + DacWriter,
{
    type Error = ErrorKind;

    fn read(&mut self) -> Result<RawSample, IoError<ErrorKind>> {
        let estop_pressed = match self.estop_polarity {
            EstopPolarity::ActiveHigh => self.estop.is_high(),
            EstopPolarity::ActiveLow => self.estop.is_low(),
        }
        .map_err(|e| IoError::Pin(e.kind()))?;
        let frame = self
            .board
            .read_sensors()
            .map_err(|SensorReadError| IoError::Sensor)?;
        Ok(RawSample {
            motor_counts: frame.motor_counts,
            height_counts: frame.height_counts,
            loadcell_code: frame.loadcell_code,
            pot_code: frame.pot_code,
            estop_pressed,
            amp_fault: frame.amp_fault,
        })
    }

    fn write_dac(&mut self, code: u16) -> Result<(), IoError<ErrorKind>> {
        self.board
            .write_code(code)
            .map_err(|DacWriteError| IoError::Dac)
    }

    fn set_amp_enabled(&mut self, on: bool) -> Result<(), IoError<ErrorKind>> {
        if on {
            self.enable.set_high()
        } else {
            self.enable.set_low()
        }
        .map_err(|e| IoError::Pin(e.kind()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::digital::ErrorType;

    #[derive(Debug, Default)]
    struct MockPin {
        high: bool,
        fail: bool,
    }

    impl ErrorType for MockPin {
        type Error = ErrorKind;
    }

    impl OutputPin for MockPin {
        fn set_low(&mut self) -> Result<(), ErrorKind> {
            if self.fail {
                return Err(ErrorKind::Other);
            }
            self.high = false;
            Ok(())
        }
        fn set_high(&mut self) -> Result<(), ErrorKind> {
            if self.fail {
                return Err(ErrorKind::Other);
            }
            self.high = true;
            Ok(())
        }
    }

    impl InputPin for MockPin {
        fn is_high(&mut self) -> Result<bool, ErrorKind> {
            if self.fail {
                return Err(ErrorKind::Other);
            }
            Ok(self.high)
        }
        fn is_low(&mut self) -> Result<bool, ErrorKind> {
            self.is_high().map(|h| !h)
        }
    }

    #[derive(Debug, Default)]
    struct MockBoard {
        frame: SensorFrame,
        last_code: Option<u16>,
        fail_read: bool,
        fail_dac: bool,
    }

    impl RawSensors for MockBoard {
        fn read_sensors(&mut self) -> Result<SensorFrame, SensorReadError> {
            if self.fail_read {
                Err(SensorReadError)
            } else {
                Ok(self.frame)
            }
        }
    }

    impl DacWriter for MockBoard {
        fn write_code(&mut self, code: u16) -> Result<(), DacWriteError> {
            if self.fail_dac {
                return Err(DacWriteError);
            }
            self.last_code = Some(code);
            Ok(())
        }
    }

    fn io(
        estop_high: bool,
        polarity: EstopPolarity,
    ) -> Result<PinsIo<MockPin, MockPin, MockBoard>, IoError<ErrorKind>> {
        let enable = MockPin {
            high: true,
            fail: false,
        };
        let estop = MockPin {
            high: estop_high,
            fail: false,
        };
        let board = MockBoard {
            frame: SensorFrame {
                motor_counts: 7,
                height_counts: 9,
                loadcell_code: 100,
                pot_code: 200,
                amp_fault: true,
            },
            ..MockBoard::default()
        };
        PinsIo::new(enable, estop, polarity, board)
    }

    #[test]
    fn new_disables_amplifier() -> Result<(), IoError<ErrorKind>> {
        let io = io(false, EstopPolarity::ActiveHigh)?;
        let (en, _, _) = io.release();
        assert!(!en.high);
        Ok(())
    }

    #[test]
    fn read_merges_pins_and_sensors() -> Result<(), IoError<ErrorKind>> {
        let mut io = io(true, EstopPolarity::ActiveHigh)?;
        let s = io.read()?;
        assert_eq!(
            s,
            RawSample {
                motor_counts: 7,
                height_counts: 9,
                loadcell_code: 100,
                pot_code: 200,
                estop_pressed: true,
                amp_fault: true,
            }
        );
        let mut io = io_low()?;
        assert!(io.read()?.estop_pressed);
        Ok(())
    }

    fn io_low() -> Result<PinsIo<MockPin, MockPin, MockBoard>, IoError<ErrorKind>> {
        io(false, EstopPolarity::ActiveLow)
    }

    #[test]
    fn enable_and_dac_pass_through() -> Result<(), IoError<ErrorKind>> {
        let mut io = io(false, EstopPolarity::ActiveHigh)?;
        io.set_amp_enabled(true)?;
        io.write_dac(1234)?;
        assert_eq!(io.board_mut().last_code, Some(1234));
        let (en, _, _) = io.release();
        assert!(en.high);
        Ok(())
    }

    #[test]
    fn errors_are_typed() -> Result<(), IoError<ErrorKind>> {
        let mut io = io(false, EstopPolarity::ActiveHigh)?;
        io.board_mut().fail_read = true;
        assert_eq!(io.read(), Err(IoError::Sensor));
        io.board_mut().fail_dac = true;
        assert_eq!(io.write_dac(1), Err(IoError::Dac));
        let (mut en, stop, board) = io.release();
        en.fail = true;
        assert!(matches!(
            PinsIo::new(en, stop, EstopPolarity::ActiveHigh, board),
            Err(IoError::Pin(ErrorKind::Other))
        ));
        Ok(())
    }
}
