//! Sensor and actuator calibration: raw counts and codes to SI, current to DAC code.
//!
//! Coordinates are MODEL.md's: `p` is the ball-nut displacement, positive
//! down, `p = theta * lead / (2 pi)`; `z` is the body height coordinate with
//! `z = l0 = 0.61 m` at touchdown.
//!
//! The thesis names the sensors (section 3: two optical encoders, motor angle
//! and body height via a pulley and rope; a load cell for the spring force; a
//! linear potentiometer for the leg compression) but not their scale factors.
//! Defaults marked *placeholder* are plausible values to be replaced by the
//! identified ones of the real board.

use core::f32::consts::PI;

/// Which sensor channel a conversion error refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Channel {
    /// Motor quadrature encoder.
    MotorEncoder,
    /// Body-height quadrature encoder.
    HeightEncoder,
    /// Load cell (spring force).
    LoadCell,
    /// Leg-compression potentiometer.
    Pot,
}

/// Why a calibration was rejected or a sample could not be converted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalError {
    /// A [`Calibration`] field is out of its documented range (the field's name).
    InvalidField(&'static str),
    /// A raw count or code does not fit the configured counter or converter width.
    RawOutOfRange(Channel),
    /// The accumulated encoder position left the range where `f32` is exact (2^24 counts).
    PositionOutOfRange(Channel),
    /// A converted value is NaN or infinite.
    NonFinite(Channel),
}

crate::param::config! {
    /// Calibration of the hopper's sensors and current command. All fields SI unless stated.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Calibration;
    params {
        98 CAL_MOTOR_COUNTS_PER_REV motor_counts_per_rev: u32 {
            "calibration.motor_counts_per_rev", "counts", Count, [1.0, 1.0e6], 2000.0, DISARMED,
            "Motor encoder counts per revolution (500 lines x 4)."
        }
        99 CAL_MOTOR_POSITIVE_DOWN motor_counts_positive_down: bool {
            "calibration.motor_counts_positive_down", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
            "Motor counts increase when the nut moves down."
        }
        100 CAL_HEIGHT_COUNTS_PER_REV height_counts_per_rev: u32 {
            "calibration.height_counts_per_rev", "counts", Count, [1.0, 1.0e6], 2000.0, DISARMED,
            "Height encoder counts per pulley revolution (placeholder)."
        }
        101 CAL_HEIGHT_POSITIVE_UP height_counts_positive_up: bool {
            "calibration.height_counts_positive_up", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
            "Height counts increase when the body moves up."
        }
        102 CAL_PULLEY_RADIUS height_pulley_radius_m: f32 {
            "calibration.height_pulley_radius_m", "m", Real, [1.0e-4, 1.0], 0.02, DISARMED,
            "Radius of the height-sensor pulley (placeholder)."
        }
        /// The height at the first sample after [`Converter::new`] or a re-zero. The
        /// default is `l0`: started standing on the uncompressed leg.
        109 CAL_HEIGHT_AT_ORIGIN_M height_at_origin_m: f32 {
            "calibration.height_at_origin_m", "m", Real, [0.0, 10.0], 0.61, DISARMED,
            "Body height z where the height encoder counted from at boot (the leg length l0 with the toe on the ground; a simulated run's start height)."
        }
        /// The default is a placeholder: with the default offset it spans -100 N to
        /// 1947 N over 12 bits (the spring reaches about 1.3 kN with the nut down in a
        /// 0.15 m hop).
        103 CAL_LOADCELL_GAIN loadcell_gain_n_per_code: f32 {
            "calibration.loadcell_gain_n_per_code", "N/code", Real, [-1.0e3, 1.0e3], 0.5, DISARMED,
            "Load-cell gain, compression positive (placeholder; not 0)."
        }
        /// The default is a placeholder that leaves a small negative range, so a rail
        /// reading is distinguishable from 0 N.
        104 CAL_LOADCELL_OFFSET loadcell_offset_code: f32 {
            "calibration.loadcell_offset_code", "code", Real, [-1.0e5, 1.0e5], 200.0, DISARMED,
            "Load-cell code at zero force (placeholder)."
        }
        /// The default is a placeholder: with the default offset it spans -6 mm to 114 mm.
        105 CAL_POT_GAIN pot_gain_m_per_code: f32 {
            "calibration.pot_gain_m_per_code", "m/code", Real, [-1.0, 1.0], 0.12 / 4096.0, DISARMED,
            "Potentiometer gain, m of leg compression per code (placeholder 0.12/4096; not 0)."
        }
        /// The default is a placeholder that puts both rails outside the physical range,
        /// so an open wiper is detected.
        106 CAL_POT_OFFSET pot_offset_code: f32 {
            "calibration.pot_offset_code", "code", Real, [-1.0e5, 1.0e5], 205.0, DISARMED,
            "Potentiometer code at zero compression (placeholder)."
        }
        /// At most `2^dac_bits - 1`.
        107 CAL_DAC_ZERO dac_zero_code: u16 {
            "calibration.dac_zero_code", "code", Count, [0.0, 65535.0], 2048.0, DISARMED,
            "DAC code for zero current (mid-scale; within the DAC range)."
        }
        /// A positive current command is torque pushing the nut down. The default is a
        /// placeholder (±10 V to ±40 A).
        108 CAL_DAC_AMPS dac_amps_per_code: f32 {
            "calibration.dac_amps_per_code", "A/code", Real, [1.0e-6, 100.0], 0.01953125, DISARMED,
            "Amplifier current per DAC code (placeholder 40 A / 2048)."
        }
    }
    plain {
        /// Motor counter width in bits, for wrap-around. Default 16. `8..=32`.
        pub motor_counter_bits: u8 = 16,
        /// Ball-screw lead, m per motor revolution. Default 0.005 (Table 2.1). Finite, `> 0`.
        pub lead_m_per_rev: f32 = 0.005,
        /// Height counter width in bits. Default 16. `8..=32`.
        pub height_counter_bits: u8 = 16,
        /// ADC resolution, bits. Default 12. `1..=16`.
        pub adc_bits: u8 = 12,
        /// DAC resolution, bits. Default 12. `1..=16`.
        pub dac_bits: u8 = 12,
        /// Motor torque constant, N m/A. Default 0.0297 (eq 4.3). Finite, `> 0`.
        pub torque_constant_nm_per_a: f32 = 0.0297,
    }
}

fn finite_positive(x: f32) -> bool {
    x.is_finite() && x > 0.0
}

fn finite_nonzero(x: f32) -> bool {
    x.is_finite() && x != 0.0
}

/// Largest code of a converter with `bits` bits (`bits` in `1..=16`).
fn max_code(bits: u8) -> u16 {
    let shift = u32::from(bits.clamp(1, 16));
    // shift <= 16: 1 << 16 fits u32, minus 1 fits u16.
    u16::try_from((1_u32 << shift) - 1).unwrap_or(u16::MAX)
}

/// Largest accumulated count magnitude converted to `f32` (exact below 2^24).
const MAX_ACCUMULATED_COUNTS: i32 = 1 << 24;

impl Calibration {
    /// Checks every field against its documented range; the error names the first bad field.
    pub fn validate(&self) -> Result<(), CalError> {
        let checks: [(bool, &'static str); 15] = [
            (self.motor_counts_per_rev > 0, "motor_counts_per_rev"),
            (
                (8..=32).contains(&self.motor_counter_bits),
                "motor_counter_bits",
            ),
            (finite_positive(self.lead_m_per_rev), "lead_m_per_rev"),
            (self.height_counts_per_rev > 0, "height_counts_per_rev"),
            (
                (8..=32).contains(&self.height_counter_bits),
                "height_counter_bits",
            ),
            (
                finite_positive(self.height_pulley_radius_m),
                "height_pulley_radius_m",
            ),
            (self.height_at_origin_m.is_finite(), "height_at_origin_m"),
            (
                finite_nonzero(self.loadcell_gain_n_per_code),
                "loadcell_gain_n_per_code",
            ),
            (
                self.loadcell_offset_code.is_finite(),
                "loadcell_offset_code",
            ),
            (
                finite_nonzero(self.pot_gain_m_per_code),
                "pot_gain_m_per_code",
            ),
            (self.pot_offset_code.is_finite(), "pot_offset_code"),
            ((1..=16).contains(&self.adc_bits), "adc_bits"),
            ((1..=16).contains(&self.dac_bits), "dac_bits"),
            (
                (1..=16).contains(&self.dac_bits) && self.dac_zero_code <= max_code(self.dac_bits),
                "dac_zero_code",
            ),
            (finite_positive(self.dac_amps_per_code), "dac_amps_per_code"),
        ];
        for (ok, name) in checks {
            if !ok {
                return Err(CalError::InvalidField(name));
            }
        }
        if !finite_positive(self.torque_constant_nm_per_a) {
            return Err(CalError::InvalidField("torque_constant_nm_per_a"));
        }
        Ok(())
    }

    /// Nut displacement per motor encoder count, m (positive down).
    pub fn nut_m_per_count(&self) -> f32 {
        let m = self.lead_m_per_rev / count_f32(self.motor_counts_per_rev);
        if self.motor_counts_positive_down {
            m
        } else {
            -m
        }
    }

    /// Motor angle per encoder count, rad (same sign as [`nut_m_per_count`](Self::nut_m_per_count)).
    pub fn motor_rad_per_count(&self) -> f32 {
        let r = 2.0 * PI / count_f32(self.motor_counts_per_rev);
        if self.motor_counts_positive_down {
            r
        } else {
            -r
        }
    }

    /// Body height change per height encoder count, m (positive up).
    pub fn height_m_per_count(&self) -> f32 {
        let m = 2.0 * PI * self.height_pulley_radius_m / count_f32(self.height_counts_per_rev);
        if self.height_counts_positive_up {
            m
        } else {
            -m
        }
    }

    /// Current commanded by a DAC code, A (codes above the DAC range are clamped to it).
    pub fn dac_code_to_current_a(&self, code: u16) -> f32 {
        let max = max_code(self.dac_bits);
        let c = code.min(max);
        (f32::from(c) - f32::from(self.dac_zero_code)) * self.dac_amps_per_code
    }

    /// Motor torque for a current, N m.
    pub fn torque_nm(&self, current_a: f32) -> f32 {
        current_a * self.torque_constant_nm_per_a
    }
}

/// The current-to-DAC-code map of a [`Calibration`], its constants worked
/// out once when it is built (the control step keeps one): about fifteen
/// instructions on the M4F.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DacMap {
    zero_code: u16,
    zero_f: f32,
    max_f: f32,
    codes_per_amp: f32,
    limit_a: f32,
}

impl DacMap {
    /// The map for `cal`, clamping to `±current_limit_a` (the model's
    /// usable limit, [`crate::model::ModelParams::usable_current_limit_a`]).
    /// Any calibration and limit work: an invalid gain or limit maps
    /// everything to the zero-current code.
    pub fn new(cal: &Calibration, current_limit_a: f32) -> Self {
        let max = max_code(cal.dac_bits);
        let zero_code = cal.dac_zero_code.min(max);
        // A gain so small that its inverse overflows is as unusable as zero.
        let valid =
            finite_positive(cal.dac_amps_per_code) && finite_positive(1.0 / cal.dac_amps_per_code);
        DacMap {
            zero_code,
            zero_f: f32::from(zero_code),
            max_f: f32::from(max),
            codes_per_amp: if valid {
                1.0 / cal.dac_amps_per_code
            } else {
                0.0
            },
            limit_a: if valid && finite_positive(current_limit_a) {
                current_limit_a
            } else {
                0.0
            },
        }
    }

    /// The DAC code for a current command, A: the current clamped to
    /// `±current_limit_a`, then `zero + current / amps_per_code` rounded to the
    /// nearest code (halves up) and clamped to the DAC range. NaN gives the
    /// zero-current code.
    #[inline]
    pub fn code(&self, current_a: f32) -> u16 {
        if current_a.is_nan() {
            return self.zero_code;
        }
        let i = crate::num::clamp(current_a, -self.limit_a, self.limit_a);
        let x = crate::num::clamp(self.zero_f + i * self.codes_per_amp, 0.0, self.max_f);
        // 0 <= x <= 65535: truncating x + 0.5 rounds to nearest, exactly, and
        // the result fits u16 (going through u32 saves the u16 saturation).
        (x + 0.5) as u32 as u16
    }
}

/// Counts as `f32`: exact below 2^24, which covers every sensible counts-per-rev.
fn count_f32(counts: u32) -> f32 {
    // A u32 to f32 `as` conversion rounds to nearest; no wrap or panic.
    counts as f32
}

/// Signed difference `new - old` of a `bits`-wide wrapping counter (`bits` in `8..=32`).
///
/// The result is in `-2^(bits-1) .. 2^(bits-1)`: a real change of half the
/// counter range or more in one period is indistinguishable from the opposite
/// change, which is what the supervisor's encoder-jump check is for.
pub fn wrapping_count_delta(new: u32, old: u32, bits: u8) -> i32 {
    delta_with_shift(new, old, 32 - u32::from(bits.clamp(8, 32)))
}

/// [`wrapping_count_delta`] with `shift = 32 - bits` precomputed: moving the
/// counter's top bit to bit 31 and shifting back arithmetically sign-extends
/// the modular difference (two instructions, no branches).
#[inline(always)]
fn delta_with_shift(new: u32, old: u32, shift: u32) -> i32 {
    let raw = new.wrapping_sub(old) << (shift & 31);
    i32::from_ne_bytes(raw.to_ne_bytes()) >> (shift & 31)
}

/// A converted sample, SI, MODEL.md coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Measurements {
    /// Motor angle `theta` since the origin, rad (positive drives the nut down).
    pub motor_angle_rad: f32,
    /// Nut displacement `p = theta * lead / (2 pi)`, m, positive down; 0 at the origin.
    pub nut_position_m: f32,
    /// Body height coordinate `z`, m (`z = l0` at touchdown).
    pub body_height_m: f32,
    /// Spring force from the load cell, N (compression positive).
    pub spring_force_n: f32,
    /// Leg compression from the potentiometer, m.
    pub leg_compression_m: f32,
    /// Raw motor counter change since the previous sample (0 for the first).
    pub motor_delta_counts: i32,
    /// Raw height counter change since the previous sample (0 for the first).
    pub height_delta_counts: i32,
    /// The emergency stop is pressed.
    pub estop_pressed: bool,
    /// The servo amplifier reports a fault.
    pub amp_fault: bool,
}

/// Turns [`crate::hal::RawSample`]s into [`Measurements`], unwrapping the encoder counters.
///
/// The first sample after [`new`](Self::new) or [`rezero`](Self::rezero) is
/// the origin: `p = 0` (nut on its upper stop, the start position) and
/// `z = height_at_origin_m`. Positions are accumulated in `i32` counts and
/// converted to `f32` only while within ±2^24 counts, where the conversion
/// is exact (and a single `vcvt` on the M4F, where an `i64` would need a
/// library call): with the defaults that is ±8388 motor revolutions
/// (±42 m of nut travel, far beyond the 50 mm stroke) and ±1054 m of height.
/// Beyond that the conversion returns [`CalError::PositionOutOfRange`].
#[derive(Debug, Clone, PartialEq)]
pub struct Converter {
    cal: Calibration,
    last: Option<(u32, u32)>,
    motor_counts: i32,
    height_counts: i32,
    // Derived from `cal` once, so a period does no divisions or clamps for them.
    motor_rad_per_count: f32,
    nut_m_per_count: f32,
    height_m_per_count: f32,
    motor_counter_max: u32,
    height_counter_max: u32,
    motor_shift: u32,
    height_shift: u32,
    adc_max: u16,
}

impl Converter {
    /// Takes over `old`'s encoder state (the last raw counts and the
    /// accumulated positions): the incremental encoders' origin survives a
    /// reconfiguration, so the body height and nut position stay what
    /// they are instead of being re-zeroed where the robot stands.
    pub fn continue_from(&mut self, old: &Converter) {
        self.last = old.last;
        self.motor_counts = old.motor_counts;
        self.height_counts = old.height_counts;
    }

    /// Creates a converter; the calibration is validated first.
    pub fn new(cal: Calibration) -> Result<Self, CalError> {
        cal.validate()?;
        let counter_max = |bits: u8| -> u32 {
            let bits = u32::from(bits.clamp(8, 32));
            u32::MAX >> (32 - bits)
        };
        Ok(Self {
            cal,
            last: None,
            motor_counts: 0,
            height_counts: 0,
            motor_rad_per_count: cal.motor_rad_per_count(),
            nut_m_per_count: cal.nut_m_per_count(),
            height_m_per_count: cal.height_m_per_count(),
            motor_counter_max: counter_max(cal.motor_counter_bits),
            height_counter_max: counter_max(cal.height_counter_bits),
            motor_shift: 32 - u32::from(cal.motor_counter_bits.clamp(8, 32)),
            height_shift: 32 - u32::from(cal.height_counter_bits.clamp(8, 32)),
            adc_max: max_code(cal.adc_bits),
        })
    }

    /// The calibration in use.
    pub const fn calibration(&self) -> &Calibration {
        &self.cal
    }

    /// Moves the encoders' origin (the homing and height-zero routines): from
    /// the next sample on the nut position reads `nut_m` less and the body
    /// height `height_m` more than it would, to the nearest count.
    pub fn shift_origin(&mut self, nut_m: f32, height_m: f32) {
        let counts = |x_m: f32, m_per_count: f32| {
            let c = libm::roundf(x_m / m_per_count);
            // Within the accumulator's exact range, else no shift at all.
            if c.abs() <= MAX_ACCUMULATED_COUNTS as f32 {
                c as i32
            } else {
                0
            }
        };
        self.motor_counts = self
            .motor_counts
            .saturating_sub(counts(nut_m, self.nut_m_per_count));
        self.height_counts = self
            .height_counts
            .saturating_add(counts(height_m, self.height_m_per_count));
    }

    /// Makes the next sample the origin again.
    pub fn rezero(&mut self) {
        self.last = None;
        self.motor_counts = 0;
        self.height_counts = 0;
    }

    /// Converts one raw sample. On error the converter state is unchanged.
    pub fn convert(&mut self, raw: &crate::hal::RawSample) -> Result<Measurements, CalError> {
        let cal = &self.cal;
        if raw.motor_counts > self.motor_counter_max {
            return Err(CalError::RawOutOfRange(Channel::MotorEncoder));
        }
        if raw.height_counts > self.height_counter_max {
            return Err(CalError::RawOutOfRange(Channel::HeightEncoder));
        }
        if raw.loadcell_code > self.adc_max {
            return Err(CalError::RawOutOfRange(Channel::LoadCell));
        }
        if raw.pot_code > self.adc_max {
            return Err(CalError::RawOutOfRange(Channel::Pot));
        }
        let (dm, dh) = match self.last {
            Some((m, h)) => (
                delta_with_shift(raw.motor_counts, m, self.motor_shift),
                delta_with_shift(raw.height_counts, h, self.height_shift),
            ),
            None => (0, 0),
        };
        let motor = self.motor_counts.saturating_add(dm);
        let height = self.height_counts.saturating_add(dh);
        let in_range = |c: i32| (-MAX_ACCUMULATED_COUNTS..=MAX_ACCUMULATED_COUNTS).contains(&c);
        if !in_range(motor) {
            return Err(CalError::PositionOutOfRange(Channel::MotorEncoder));
        }
        if !in_range(height) {
            return Err(CalError::PositionOutOfRange(Channel::HeightEncoder));
        }
        // |c| <= 2^24 (checked above): the i32 to f32 `as` conversion is exact.
        let motor_f = motor as f32;
        let height_f = height as f32;
        let m = Measurements {
            motor_angle_rad: motor_f * self.motor_rad_per_count,
            nut_position_m: motor_f * self.nut_m_per_count,
            body_height_m: cal.height_at_origin_m + height_f * self.height_m_per_count,
            spring_force_n: (f32::from(raw.loadcell_code) - cal.loadcell_offset_code)
                * cal.loadcell_gain_n_per_code,
            leg_compression_m: (f32::from(raw.pot_code) - cal.pot_offset_code)
                * cal.pot_gain_m_per_code,
            motor_delta_counts: dm,
            height_delta_counts: dh,
            estop_pressed: raw.estop_pressed,
            amp_fault: raw.amp_fault,
        };
        // One test on the sum in the common case; name the channel only when it fails.
        let sum = m.motor_angle_rad
            + m.nut_position_m
            + m.body_height_m
            + m.spring_force_n
            + m.leg_compression_m;
        if !sum.is_finite() {
            if !(m.motor_angle_rad.is_finite() && m.nut_position_m.is_finite()) {
                return Err(CalError::NonFinite(Channel::MotorEncoder));
            }
            if !m.body_height_m.is_finite() {
                return Err(CalError::NonFinite(Channel::HeightEncoder));
            }
            if !m.spring_force_n.is_finite() {
                return Err(CalError::NonFinite(Channel::LoadCell));
            }
            if !m.leg_compression_m.is_finite() {
                return Err(CalError::NonFinite(Channel::Pot));
            }
            // Every value finite but the sum overflowed: some value is absurd.
            return Err(CalError::NonFinite(Channel::LoadCell));
        }
        self.last = Some((raw.motor_counts, raw.height_counts));
        self.motor_counts = motor;
        self.height_counts = height;
        Ok(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hal::RawSample;

    /// The default model's usable current limit, A (1 N m at 0.0297 N m/A).
    const LIMIT_A: f32 = 33.7;

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol
    }

    #[test]
    fn default_is_valid() {
        assert_eq!(Calibration::default().validate(), Ok(()));
    }

    #[test]
    fn validate_names_field() {
        let mut c = Calibration {
            lead_m_per_rev: f32::NAN,
            ..Calibration::default()
        };
        assert_eq!(c.validate(), Err(CalError::InvalidField("lead_m_per_rev")));
        c = Calibration {
            motor_counter_bits: 33,
            ..Calibration::default()
        };
        assert_eq!(
            c.validate(),
            Err(CalError::InvalidField("motor_counter_bits"))
        );
        c = Calibration {
            dac_zero_code: 4096,
            ..Calibration::default()
        };
        assert_eq!(c.validate(), Err(CalError::InvalidField("dac_zero_code")));
        c = Calibration {
            torque_constant_nm_per_a: 0.0,
            ..Calibration::default()
        };
        assert_eq!(
            c.validate(),
            Err(CalError::InvalidField("torque_constant_nm_per_a"))
        );
        assert!(Converter::new(c).is_err());
    }

    #[test]
    fn wrap_around_16_and_32_bits() {
        assert_eq!(wrapping_count_delta(2, 65534, 16), 4);
        assert_eq!(wrapping_count_delta(65534, 2, 16), -4);
        assert_eq!(wrapping_count_delta(1, u32::MAX, 32), 2);
        assert_eq!(wrapping_count_delta(u32::MAX, 1, 32), -2);
        assert_eq!(wrapping_count_delta(100, 40, 16), 60);
        assert_eq!(wrapping_count_delta(0x8000, 0, 16), -32768);
    }

    #[test]
    fn converter_unwraps_and_scales() -> Result<(), CalError> {
        let cal = Calibration::default();
        let mut conv = Converter::new(cal)?;
        let mut raw = RawSample {
            motor_counts: 65000,
            ..RawSample::default()
        };
        let m0 = conv.convert(&raw)?;
        assert_eq!(m0.nut_position_m, 0.0);
        assert!(close(m0.body_height_m, 0.61, 1e-6));
        // Forward 2000 counts (one revolution) across the 16-bit wrap.
        let mut c = 65000_u32;
        for _ in 0..20 {
            c = (c + 100) % 65536;
            raw.motor_counts = c;
            conv.convert(&raw)?;
        }
        let m = conv.convert(&raw)?;
        assert!(close(m.nut_position_m, 0.005, 1e-7), "{}", m.nut_position_m);
        assert!(close(m.motor_angle_rad, 2.0 * PI, 1e-5));
        Ok(())
    }

    #[test]
    fn converter_height_and_analog() -> Result<(), CalError> {
        let cal = Calibration::default();
        let mut conv = Converter::new(cal)?;
        conv.convert(&RawSample::default())?;
        let m = conv.convert(&RawSample {
            height_counts: 65536 - 2000, // one pulley revolution down
            loadcell_code: 400,
            pot_code: 205 + 1024, // 1024 codes above the zero offset
            ..RawSample::default()
        })?;
        let expect_z = 0.61 - 2.0 * PI * 0.02;
        assert!(close(m.body_height_m, expect_z, 1e-6));
        assert!(close(m.spring_force_n, 100.0, 1e-4));
        assert!(close(m.leg_compression_m, 0.03, 1e-6));
        assert_eq!(m.height_delta_counts, -2000);
        Ok(())
    }

    #[test]
    fn converter_rejects_out_of_range_and_keeps_state() -> Result<(), CalError> {
        let mut conv = Converter::new(Calibration::default())?;
        conv.convert(&RawSample::default())?;
        let before = conv.clone();
        assert_eq!(
            conv.convert(&RawSample {
                loadcell_code: 4096,
                ..RawSample::default()
            }),
            Err(CalError::RawOutOfRange(Channel::LoadCell))
        );
        assert_eq!(
            conv.convert(&RawSample {
                motor_counts: 65536,
                ..RawSample::default()
            }),
            Err(CalError::RawOutOfRange(Channel::MotorEncoder))
        );
        assert_eq!(conv, before);
        Ok(())
    }

    #[test]
    fn converter_rejects_non_finite() -> Result<(), CalError> {
        let cal = Calibration {
            loadcell_gain_n_per_code: f32::MAX,
            loadcell_offset_code: -f32::MAX,
            ..Calibration::default()
        };
        let mut conv = Converter::new(cal)?;
        assert_eq!(
            conv.convert(&RawSample::default()),
            Err(CalError::NonFinite(Channel::LoadCell))
        );
        Ok(())
    }

    #[test]
    fn position_range_is_enforced() -> Result<(), CalError> {
        let cal = Calibration {
            motor_counter_bits: 32,
            ..Calibration::default()
        };
        let mut conv = Converter::new(cal)?;
        let mut raw = RawSample::default();
        conv.convert(&raw)?;
        let step = 1_u32 << 22;
        let mut result = Ok(Measurements::default());
        for _ in 0..5 {
            raw.motor_counts = raw.motor_counts.wrapping_add(step);
            result = conv.convert(&raw);
        }
        assert_eq!(
            result,
            Err(CalError::PositionOutOfRange(Channel::MotorEncoder))
        );
        Ok(())
    }

    #[test]
    fn dac_round_trip_and_clamps() {
        let cal = Calibration::default();
        assert_eq!(DacMap::new(&cal, LIMIT_A).code(0.0), 2048);
        assert_eq!(DacMap::new(&cal, LIMIT_A).code(f32::NAN), 2048);
        // 10 A / (40/2048 A) = 512 codes.
        assert_eq!(DacMap::new(&cal, LIMIT_A).code(10.0), 2560);
        assert_eq!(DacMap::new(&cal, LIMIT_A).code(-10.0), 1536);
        // Clamped to the 33.7 A limit: 33.7 * 51.2 = 1725.44 -> 1725.
        assert_eq!(DacMap::new(&cal, LIMIT_A).code(1e9), 2048 + 1725);
        assert_eq!(
            DacMap::new(&cal, LIMIT_A).code(f32::NEG_INFINITY),
            2048 - 1725
        );
        assert!(close(cal.dac_code_to_current_a(2560), 10.0, 1e-5));
        assert!(close(
            cal.dac_code_to_current_a(DacMap::new(&cal, LIMIT_A).code(5.0)),
            5.0,
            0.5 * cal.dac_amps_per_code
        ));
        // DAC range clamp when the limit exceeds the DAC's reach.
        let wide = cal;
        assert_eq!(DacMap::new(&wide, 1000.0).code(1000.0), 4095);
        assert_eq!(DacMap::new(&wide, 1000.0).code(-1000.0), 0);
        assert!(close(cal.torque_nm(33.7), 1.0, 1e-3));
    }

    proptest::proptest! {
        /// The code stands for the clamped current within half a code, and
        /// never leaves the DAC range, for any current and any calibration.
        #[test]
        fn dac_code_is_the_nearest_code(
            current in proptest::prop_oneof![-50.0f32..50.0, proptest::num::f32::ANY],
            amps_per_code in proptest::prop_oneof![1e-3f32..1.0, proptest::num::f32::ANY],
            limit in proptest::prop_oneof![0.0f32..100.0, proptest::num::f32::ANY],
            zero in 0u16..5000,
            bits in 1u8..=16,
        ) {
            let cal = Calibration {
                dac_amps_per_code: amps_per_code,
                dac_zero_code: zero,
                dac_bits: bits,
                ..Calibration::default()
            };
            let code = DacMap::new(&cal, limit).code(current);
            proptest::prop_assert!(code <= max_code(bits));
            let sane = amps_per_code.is_finite() && amps_per_code > 0.0 && (1.0 / amps_per_code).is_finite()
                && limit.is_finite() && limit > 0.0;
            if current.is_nan() || !sane {
                proptest::prop_assert_eq!(code, zero.min(max_code(bits)));
            } else {
                let i = current.clamp(-limit, limit);
                let ideal = f32::from(zero.min(max_code(bits))) + i / amps_per_code;
                let ideal = ideal.clamp(0.0, f32::from(max_code(bits)));
                proptest::prop_assert!((f32::from(code) - ideal).abs() <= 0.5 + ideal.abs() * 1e-6, "{} vs {}", code, ideal);
            }
        }
    }
}
