//! The hopper's I/O boundary: raw sensor samples in, DAC code and amplifier enable out.
//!
//! embedded-hal 1.0 has no ADC, DAC or quadrature-encoder traits, so
//! [`HopperIo`] is this project's own trait. It works in raw units (counts and
//! converter codes); [`crate::calibration`] turns them into SI.
//! The board (`hopper-app`'s `BoardIo`, register-level: injected ADC,
//! timer encoders, DAC, GPIO) and the simulator (`hopper-plant`'s mock I/O)
//! implement it.

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
