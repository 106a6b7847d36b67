//! Safety supervisor: latched faults between the control law and the amplifier.
//!
//! Every control period the application passes the latest measurements and
//! the control law's requested current to [`Supervisor::check`]. The returned
//! [`Command`] is what goes to the DAC and the amplifier-enable pin. Any fault
//! latches: from that same call on the command is 0 A with the amplifier
//! disabled, until [`Supervisor::reset`] succeeds. The output current is
//! always finite and within `±current_limit_a`.
//!
//! What each check catches, and how fast (measured in closed loop by
//! `tests/tests/fault_injection.rs`), is tabulated in `docs/safety.md`. The
//! sensor cross-check ([`Fault::SensorDisagree`]) exists because a sensor
//! that sticks at a plausible value, or an encoder that stops counting,
//! passes every range check: the spring ties the three position/force
//! sensors together (`F = k (delta0 + p + x)`), so one that stops following
//! the others shows up as a residual. It costs one multiply-add, an absolute
//! value and a compare on the every-period path. [`Fault::EncoderFrozen`]
//! catches an encoder that stops while the motor turns fast (no count in a
//! period is then physically impossible away from the stops) before the
//! nut has moved far enough for the residual; its common case (a count
//! came in) is one integer compare.
//!
//! The latching property runs 10 000 cases by default;
//! `HOPPER_PROPTEST_CASES` (or, when it is not set, `PROPTEST_CASES`) raises
//! or lowers the count. The output-bound property runs proptest's default
//! count (or `PROPTEST_CASES`).

use crate::param::{require, InvalidField};

/// One kind of fault the supervisor detects (its name: kebab-case, for logs
/// and telemetry).
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, strum::IntoStaticStr, strum::VariantArray, strum::FromRepr,
)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[strum(serialize_all = "kebab-case")]
#[repr(u8)]
pub enum Fault {
    /// A measurement is NaN or infinite.
    #[strum(serialize = "sensor-nonfinite")]
    SensorNonFinite = 0,
    /// A measurement is outside its plausible range.
    SensorRange = 1,
    /// An encoder counter changed more in one period than the fastest physical motion allows.
    EncoderJump = 2,
    /// Load cell and potentiometer disagree about ground contact.
    ContactDisagree = 3,
    /// The nut is predicted to reach a stroke soft limit even under full braking.
    StrokeLimit = 4,
    /// The requested current is far beyond the limit (runaway law or unit error).
    Overcurrent = 5,
    /// The emergency stop is pressed.
    Estop = 6,
    /// The servo amplifier reports a fault.
    AmpFault = 7,
    /// The control period overran (reported by the application).
    Overrun = 8,
    /// Writing the DAC failed (reported by the application).
    DacError = 9,
    /// The requested current is NaN or infinite.
    #[strum(serialize = "command-nonfinite")]
    CommandNonFinite = 10,
    /// Load cell, potentiometer and motor encoder disagree: the measured
    /// spring force is not `k (delta0 + p + x)` (a stuck, frozen or noisy sensor).
    SensorDisagree = 11,
    /// The motor encoder stopped counting while the motor turned fast, away
    /// from the mechanical stops (only a stop can halt it within a period).
    EncoderFrozen = 12,
    /// The period runner's own check of a period's output failed (the
    /// watchdog feed policy starved: a command out of range, a live output
    /// while faulted, or a latch that cleared by itself). Latched so that no
    /// later period can enable the amplifier before the watchdog resets the MCU.
    SelfCheck = 13,
    /// The motor winding's estimated temperature reached
    /// `thermal.trip_winding_c` ([`crate::thermal`]); clears once it has
    /// cooled below `thermal.derate_winding_c`.
    Overtemperature = 14,
}

impl Fault {
    /// Every fault, in bit order.
    pub const ALL: &'static [Fault] = <Fault as strum::VariantArray>::VARIANTS;

    /// Short kebab-case name for logs and telemetry.
    pub fn name(self) -> &'static str {
        self.into()
    }

    /// This fault's bit in [`Faults`].
    pub const fn bit(self) -> u16 {
        1 << (self as u8)
    }
}

/// A set of [`Fault`]s, one bit each (bit `n` is `Fault::ALL[n]`).
/// Written out rather than a `bitflags` type: that would declare every
/// fault a second time, as a flag constant beside its enum variant, and
/// the supervisor, the capture and the wire use a fault as a value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Faults(pub u16);

/// By name (`estop overrun`), as the logs print them; `none` when empty.
#[cfg(feature = "defmt")]
impl defmt::Format for Faults {
    fn format(&self, f: defmt::Formatter) {
        if self.is_empty() {
            defmt::write!(f, "none");
        }
        let mut first = true;
        for &fault in Fault::ALL {
            if self.contains(fault) {
                if !first {
                    defmt::write!(f, " ");
                }
                defmt::write!(f, "{=str}", fault.name());
                first = false;
            }
        }
    }
}

impl Faults {
    /// No fault.
    pub const NONE: Faults = Faults(0);

    /// Whether no fault is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Whether `fault` is set.
    pub const fn contains(self, fault: Fault) -> bool {
        self.0 & fault.bit() != 0
    }

    /// Sets `fault`.
    pub fn insert(&mut self, fault: Fault) {
        self.0 |= fault.bit();
    }

    /// The union of two sets.
    pub const fn union(self, other: Faults) -> Faults {
        Faults(self.0 | other.0)
    }

    /// Iterates over the set faults in bit order.
    pub fn iter(self) -> impl Iterator<Item = Fault> {
        Fault::ALL
            .iter()
            .copied()
            .filter(move |f| self.contains(*f))
    }
}

/// What the supervisor needs each period, SI (MODEL.md coordinates).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SupervisorInput {
    /// Nut displacement `p`, m, positive down.
    pub nut_position_m: f32,
    /// Nut velocity `pd`, m/s.
    pub nut_velocity_mps: f32,
    /// Motor speed, rad/s.
    pub motor_speed_rad_s: f32,
    /// Body height coordinate `z`, m.
    pub body_height_m: f32,
    /// Body velocity `zd`, m/s.
    pub body_velocity_mps: f32,
    /// Spring force from the load cell, N (compression positive).
    pub spring_force_n: f32,
    /// Leg compression from the potentiometer, m.
    pub leg_compression_m: f32,
    /// Raw motor counter change over the last period.
    pub motor_delta_counts: i32,
    /// Raw height counter change over the last period.
    pub height_delta_counts: i32,
    /// The emergency stop is pressed.
    pub estop_pressed: bool,
    /// The servo amplifier reports a fault.
    pub amp_fault: bool,
}

impl SupervisorInput {
    /// Builds the input from a converted sample plus the filtered velocities
    /// (e.g. from [`crate::filter::FilteredDerivative`]).
    #[inline(always)]
    pub fn from_measurements(
        m: &crate::calibration::Measurements,
        nut_velocity_mps: f32,
        motor_speed_rad_s: f32,
        body_velocity_mps: f32,
    ) -> Self {
        Self {
            nut_position_m: m.nut_position_m,
            nut_velocity_mps,
            motor_speed_rad_s,
            body_height_m: m.body_height_m,
            body_velocity_mps,
            spring_force_n: m.spring_force_n,
            leg_compression_m: m.leg_compression_m,
            motor_delta_counts: m.motor_delta_counts,
            height_delta_counts: m.height_delta_counts,
            estop_pressed: m.estop_pressed,
            amp_fault: m.amp_fault,
        }
    }
}

/// A closed range `min..=max` in the unit of the field that holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Range {
    /// Lower bound (inclusive).
    pub min: f32,
    /// Upper bound (inclusive).
    pub max: f32,
}

impl Range {
    /// `0..=0`: the start of a range whose ends are set after (the
    /// configuration's defaults put the parameter table's there).
    pub const ZERO: Range = Range { min: 0.0, max: 0.0 };

    /// Whether `x` is within the range (NaN is not).
    pub fn contains(&self, x: f32) -> bool {
        x >= self.min && x <= self.max
    }
}

crate::param::config! {
    /// Supervisor limits. Defaults are for the thesis hardware at a 10 kHz control rate.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct SupervisorConfig;
    params {
        /// Counted per [`REFERENCE_PERIOD_S`] (100 us); the limit scales with the control
        /// period (at least 2 counts). The default is 1000 rad/s (above the 808 rad/s
        /// no-load speed) at 2000 counts/rev, 32 counts per 100 us, with a x2 margin.
        61 SUP_MAX_MOTOR_DELTA max_motor_delta_counts: u32 {
            "supervisor.max_motor_delta_counts", "counts", Count, [1.0, 1.0e6], 64.0, DISARMED,
            "Largest plausible motor counter change per period (1000 rad/s at 2000 counts/rev and 10 kHz is 32, x2)."
        }
        /// Counted per [`REFERENCE_PERIOD_S`] and scaled with the control period as the
        /// motor's limit is. The default is 10 m/s with a 20 mm pulley at 2000 counts/rev,
        /// 16 counts per 100 us, with a x2 margin.
        62 SUP_MAX_HEIGHT_DELTA max_height_delta_counts: u32 {
            "supervisor.max_height_delta_counts", "counts", Count, [1.0, 1.0e6], 32.0, DISARMED,
            "Largest plausible height counter change per period (10 m/s on a 20 mm pulley at 10 kHz is 16, x2)."
        }
        77 SUP_SPRING_RATE spring_rate_n_per_m: f32 {
            "supervisor.spring_rate_n_per_m", "N/m", Real, [10.0, 1.0e7], 11000.0, DISARMED,
            "Spring rate k of the sensor cross-checks (calibrated; Table 2.1: 11 kN/m)."
        }
        78 SUP_SPRING_PRELOAD spring_preload_m: f32 {
            "supervisor.spring_preload_m", "m", Real, [0.0, 0.5], crate::model::design::SPRING_PRELOAD_M as f32, DISARMED,
            "Spring preload delta0 of the sensor cross-checks (calibrated; design: none)."
        }
        /// The excess is the force above the flight force `k (delta0 + p)`.
        79 SUP_CONTACT_FORCE contact_force_n: f32 {
            "supervisor.contact_force_n", "N", Real, [-1.0e4, 1.0e4], 150.0, DISARMED,
            "Excess force above which the load cell says contact."
        }
        80 SUP_FREE_FORCE free_force_n: f32 {
            "supervisor.free_force_n", "N", Real, [-1.0e4, 1.0e4], 40.0, DISARMED,
            "Excess force below which the load cell says no contact."
        }
        81 SUP_CONTACT_COMPRESSION contact_compression_m: f32 {
            "supervisor.contact_compression_m", "m", Real, [-1.0, 1.0], 0.015, DISARMED,
            "Leg compression above which the potentiometer says contact."
        }
        82 SUP_FREE_COMPRESSION free_compression_m: f32 {
            "supervisor.free_compression_m", "m", Real, [-1.0, 1.0], 0.003, DISARMED,
            "Leg compression below which the potentiometer says no contact."
        }
        /// Counted in [`REFERENCE_PERIOD_S`] units (consecutive periods at 10 kHz; the
        /// time is what counts at any rate).
        83 SUP_CONTACT_DISAGREE_PERIODS contact_disagree_periods: u16 {
            "supervisor.contact_disagree_periods", "periods", Count, [1.0, 65535.0], 20.0, DISARMED,
            "Consecutive disagreeing periods before contact-disagree latches (2 ms at 10 kHz)."
        }
        /// `F` is the load cell's force, `k (delta0 + p + x)` the spring force from the
        /// compression the motor encoder (`p`) and the potentiometer (`x`) give. Beyond
        /// the limit [`Fault::SensorDisagree`] latches in the same period. The default is
        /// 13 sigma of the residual, which is noise only (load cell 2 N and `k` x pot
        /// 1.1 N, 1 sigma: 2.3 N) when the spring has no damping and the model's `k` and
        /// `delta0` are the plant's; it is 2.7 mm of nut or leg travel the other sensors
        /// do not see. `f32::INFINITY` disables the check (e.g. a spring with damping, or
        /// a `k` known only roughly).
        84 SUP_SPRING_MISMATCH spring_mismatch_n: f32 {
            "supervisor.spring_mismatch_n", "N", Real, [1.0e-3, 1.0e30], 30.0, DISARMED,
            "Largest plausible |F - k (delta0 + p + x)| before sensor-disagree (13 sigma; 1e30 turns it off)."
        }
        /// The speed is the filtered one. Above it, [`REFERENCE_PERIOD_S`] (100 us, one
        /// period at 10 kHz, ten at 100 kHz) without a single motor count is impossible
        /// away from the stops: [`Fault::EncoderFrozen`]. The default is 3.2 counts per
        /// 100 us at 2000 counts/rev, and the motor (2 N m stall, 1 N m of spring through
        /// the screw, 2.7e-4 kg m^2) loses at most about 1.1 rad/s in a period; the eq 4.1
        /// filter's lag adds about 10 rad/s. `f32::INFINITY` disables the check.
        85 SUP_FROZEN_SPEED frozen_speed_rad_s: f32 {
            "supervisor.frozen_speed_rad_s", "rad/s", Real, [1.0e-3, 1.0e30], 100.0, DISARMED,
            "Motor speed above which a period without a count is encoder-frozen (1e30 turns it off)."
        }
    }
    nested {
        63 SUP_NUT_POSITION_MIN_M at nut_position_range_m.min {
            "supervisor.nut_position_min_m", "m", Real, [-1.0, 1.0], -0.01, DISARMED,
            "Lowest plausible nut position (stops at 0 and 0.05 m)."
        }
        64 SUP_NUT_POSITION_MAX_M at nut_position_range_m.max {
            "supervisor.nut_position_max_m", "m", Real, [-1.0, 1.0], 0.06, DISARMED,
            "Highest plausible nut position (stops at 0 and 0.05 m)."
        }
        65 SUP_NUT_VELOCITY_MIN_MPS at nut_velocity_range_mps.min {
            "supervisor.nut_velocity_min_mps", "m/s", Real, [-100.0, 100.0], -1.0, DISARMED,
            "Lowest plausible nut velocity (the no-load speed is 0.64 m/s)."
        }
        66 SUP_NUT_VELOCITY_MAX_MPS at nut_velocity_range_mps.max {
            "supervisor.nut_velocity_max_mps", "m/s", Real, [-100.0, 100.0], 1.0, DISARMED,
            "Highest plausible nut velocity (the no-load speed is 0.64 m/s)."
        }
        67 SUP_MOTOR_SPEED_MIN_RAD_S at motor_speed_range_rad_s.min {
            "supervisor.motor_speed_min_rad_s", "rad/s", Real, [-1.0e5, 1.0e5], -1200.0, DISARMED,
            "Lowest plausible motor speed (no-load 808 rad/s)."
        }
        68 SUP_MOTOR_SPEED_MAX_RAD_S at motor_speed_range_rad_s.max {
            "supervisor.motor_speed_max_rad_s", "rad/s", Real, [-1.0e5, 1.0e5], 1200.0, DISARMED,
            "Highest plausible motor speed (no-load 808 rad/s)."
        }
        69 SUP_BODY_HEIGHT_MIN_M at body_height_range_m.min {
            "supervisor.body_height_min_m", "m", Real, [-10.0, 100.0], 0.4, DISARMED,
            "Lowest plausible body height z (l0 = 0.61 m)."
        }
        70 SUP_BODY_HEIGHT_MAX_M at body_height_range_m.max {
            "supervisor.body_height_max_m", "m", Real, [-10.0, 100.0], 3.0, DISARMED,
            "Highest plausible body height z (l0 = 0.61 m)."
        }
        71 SUP_BODY_VELOCITY_MIN_MPS at body_velocity_range_mps.min {
            "supervisor.body_velocity_min_mps", "m/s", Real, [-1000.0, 1000.0], -10.0, DISARMED,
            "Lowest plausible body velocity."
        }
        72 SUP_BODY_VELOCITY_MAX_MPS at body_velocity_range_mps.max {
            "supervisor.body_velocity_max_mps", "m/s", Real, [-1000.0, 1000.0], 10.0, DISARMED,
            "Highest plausible body velocity."
        }
        73 SUP_SPRING_FORCE_MIN_N at spring_force_range_n.min {
            "supervisor.spring_force_min_n", "N", Real, [-1.0e5, 1.0e5], -50.0, DISARMED,
            "Lowest plausible spring force (both load-cell rails outside)."
        }
        74 SUP_SPRING_FORCE_MAX_N at spring_force_range_n.max {
            "supervisor.spring_force_max_n", "N", Real, [-1.0e5, 1.0e5], 1800.0, DISARMED,
            "Highest plausible spring force (both load-cell rails outside)."
        }
        75 SUP_LEG_COMPRESSION_MIN_M at leg_compression_range_m.min {
            "supervisor.leg_compression_min_m", "m", Real, [-1.0, 1.0], -0.004, DISARMED,
            "Lowest plausible leg compression (both potentiometer rails outside)."
        }
        76 SUP_LEG_COMPRESSION_MAX_M at leg_compression_range_m.max {
            "supervisor.leg_compression_max_m", "m", Real, [-1.0, 1.0], 0.1, DISARMED,
            "Highest plausible leg compression (both potentiometer rails outside)."
        }
    }
    plain {
        /// A request with magnitude above this, A, is an overcurrent fault (requests between
        /// the limit and this are clamped silently). Default 337 (10x the limit: a runaway law).
        pub overcurrent_trip_a: f32 = 337.0,
        /// Plausible nut position, m. Default -0.01..=0.06 (stops at 0 and 0.05).
        pub nut_position_range_m: Range = Range::ZERO, // its ends are the entries above
        /// Plausible nut velocity, m/s. Default ±1.0 (1000 rad/s is 0.8 m/s).
        pub nut_velocity_range_mps: Range = Range::ZERO, // its ends are the entries above
        /// Plausible motor speed, rad/s. Default ±1200.
        pub motor_speed_range_rad_s: Range = Range::ZERO, // its ends are the entries above
        /// Plausible body height `z`, m. Default 0.4..=3.0 (`l0` = 0.61, hops up to ~2 m).
        pub body_height_range_m: Range = Range::ZERO, // its ends are the entries above
        /// Plausible body velocity, m/s. Default ±10.
        pub body_velocity_range_mps: Range = Range::ZERO, // its ends are the entries above
        /// Plausible spring force, N. Default -50..=1800: about 600 N at full
        /// stroke in flight, 1.35 kN with the nut down in a 0.25 m hop; both
        /// rails of the default load-cell calibration (-100 N, 1947 N) are outside.
        pub spring_force_range_n: Range = Range::ZERO, // its ends are the entries above
        /// Plausible leg compression, m. Default -0.004..=0.1: both rails of the
        /// default potentiometer calibration (-6 mm, 114 mm) are outside, so an
        /// open or shorted wiper trips.
        pub leg_compression_range_m: Range = Range::ZERO, // its ends are the entries above
        /// The nut's mechanical stops, m (`min`: upper stop, `max`: lower stop).
        /// Within [`STOP_BAND_M`] of one a nut may halt at once, so
        /// [`Fault::EncoderFrozen`] is not checked there. Default 0..=0.05.
        pub nut_stops_m: Range = Range {
                min: 0.0,
                max: 0.05,
            },
        /// Lower stroke soft limit for the predicted stopping point, m. Default -0.005
        /// (hitting the upper stop at 0 faster than about 0.17 m/s under `brake_decel_mps2`).
        pub stroke_min_m: f32 = -0.005,
        /// Upper stroke soft limit for the predicted stopping point, m. Default 0.055 (stop at 0.05).
        pub stroke_max_m: f32 = 0.055,
        /// Nut deceleration available for braking, m/s^2, in `p + pd |pd| / (2 a)`. Default 3.0
        /// (1.0 N m through the 426 kg reflected rotor inertia; spring help ignored). `> 0`.
        pub brake_decel_mps2: f32 = 3.0,
        /// The motor's thermal model and the protection's thresholds.
        pub thermal: crate::thermal::ThermalConfig = crate::thermal::ThermalConfig::default(),
    }
}

impl SupervisorConfig {
    /// The spring force with the leg unloaded (toe free, leg on its
    /// extension stop), N: `k (delta0 + p)` with the calibrated rate and
    /// preload, at nut position `nut_m`. What the load cell reads in flight.
    #[inline(always)]
    pub fn flight_force_n(&self, nut_m: f32) -> f32 {
        self.spring_rate_n_per_m * (self.spring_preload_m + nut_m)
    }

    /// Checks every field, naming the first one out of range: finite,
    /// ordered ranges and stroke limits, a positive current limit with the
    /// trip level at or above it, a positive braking deceleration and spring
    /// rate, finite contact thresholds, and positive cross-check bounds
    /// (`f32::INFINITY` turns a cross-check off). A robot's configuration
    /// is held to the narrower ranges of the `supervisor.*` entries too
    /// (`params::validate`, run by `Hopper::new`: 1e30 turns a cross-check
    /// off there); the supervisor alone needs only these to run.
    pub fn validate(&self) -> Result<(), InvalidField> {
        let finite_range = |r: &Range| r.min.is_finite() && r.max.is_finite() && r.min <= r.max;
        let ranges = [
            (
                &self.nut_position_range_m,
                "supervisor.nut_position_range_m",
            ),
            (
                &self.nut_velocity_range_mps,
                "supervisor.nut_velocity_range_mps",
            ),
            (
                &self.motor_speed_range_rad_s,
                "supervisor.motor_speed_range_rad_s",
            ),
            (&self.body_height_range_m, "supervisor.body_height_range_m"),
            (
                &self.body_velocity_range_mps,
                "supervisor.body_velocity_range_mps",
            ),
            (
                &self.spring_force_range_n,
                "supervisor.spring_force_range_n",
            ),
            (
                &self.leg_compression_range_m,
                "supervisor.leg_compression_range_m",
            ),
            (&self.nut_stops_m, "supervisor.nut_stops_m"),
        ];
        for (r, name) in ranges {
            require(finite_range(r), name)?;
        }
        let positive = |v: f32| v.is_finite() && v > 0.0;
        require(
            positive(self.overcurrent_trip_a),
            "supervisor.overcurrent_trip_a",
        )?;
        require(
            positive(self.spring_rate_n_per_m),
            "supervisor.spring_rate_n_per_m",
        )?;
        require(
            self.spring_preload_m.is_finite(),
            "supervisor.spring_preload_m",
        )?;
        for (v, name) in [
            (self.contact_force_n, "supervisor.contact_force_n"),
            (self.free_force_n, "supervisor.free_force_n"),
            (
                self.contact_compression_m,
                "supervisor.contact_compression_m",
            ),
            (self.free_compression_m, "supervisor.free_compression_m"),
        ] {
            require(v.is_finite(), name)?;
        }
        // NaN fails `> 0`; +inf passes and disables the check.
        require(self.spring_mismatch_n > 0.0, "supervisor.spring_mismatch_n")?;
        require(
            self.frozen_speed_rad_s > 0.0,
            "supervisor.frozen_speed_rad_s",
        )?;
        require(
            self.stroke_min_m.is_finite()
                && self.stroke_max_m.is_finite()
                && self.stroke_min_m <= self.stroke_max_m,
            "supervisor.stroke_min_m",
        )?;
        require(
            positive(self.brake_decel_mps2),
            "supervisor.brake_decel_mps2",
        )?;
        self.thermal.validate()
    }
}

/// The control period the per-period limits are stated for, s (10 kHz).
/// [`Supervisor::check`] scales them to the period it is given, so 1 kHz
/// and 100 kHz runs see the same physical limits (a fixed "no count in one
/// period" would trip `encoder-frozen` on a healthy encoder at 40 kHz and
/// above, and 64 counts per period `encoder-jump` at 200 rad/s at 1 kHz).
pub const REFERENCE_PERIOD_S: f32 = 1.0e-4;

/// Distance from a mechanical stop within which the nut may halt in one
/// period (a stop impact), m: the frozen-encoder check is off there. 0.5 mm
/// is six periods of travel at the 0.8 m/s the no-load speed allows.
pub const STOP_BAND_M: f32 = 0.0005;

/// The encoder-jump limits (motor, height) at `scale` reference periods,
/// counts: the per-100-us limits scaled, at least two counts so that
/// quantisation alone never trips at high rates.
fn jump_limits(c: &SupervisorConfig, scale: f32) -> (f32, f32) {
    let limit = |per_ref: u32| crate::num::max(per_ref as f32 * scale, 2.0);
    (
        limit(c.max_motor_delta_counts),
        limit(c.max_height_delta_counts),
    )
}

/// What goes to the amplifier this period.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Command {
    /// Current command, A: finite, within `±current_limit_a`; 0 when faulted.
    pub current_a: f32,
    /// Amplifier enable (the `AMP_EN` pin); `false` when faulted.
    pub amp_enable: bool,
}

impl Command {
    /// 0 A, amplifier disabled.
    pub const SAFE: Command = Command {
        current_a: 0.0,
        amp_enable: false,
    };
}

/// The safety supervisor. See the module docs. Not `Copy`: a copy would
/// duplicate the fault latch.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Supervisor {
    config: SupervisorConfig,
    latched: Faults,
    /// Time load cell and pot have disagreed, in [`REFERENCE_PERIOD_S`] units.
    disagree_ref: f32,
    /// Time without a motor count while fast, in [`REFERENCE_PERIOD_S`] units.
    frozen_ref: f32,
    /// The last period given to [`Self::check`] over [`REFERENCE_PERIOD_S`]
    /// (1 until then): the scale of the per-period limits.
    period_scale: f32,
    /// The encoder-jump limits at that scale, counts (motor, height):
    /// recomputed only when the period changes.
    jump_limits: (f32, f32),
    /// The current limit, A (validated: finite, > 0).
    limit_a: f32,
    /// `1 / (2 a)` of the braking deceleration (validated: finite, > 0).
    half_inv_decel: f32,
    /// Centre of the stops and the half-width that is more than
    /// [`STOP_BAND_M`] away from both, m (NaN for bad stops: check off).
    stops_centre_m: f32,
    stops_inner_half_m: f32,
    /// The motor's winding temperature: the current limit's derating and
    /// [`Fault::Overtemperature`].
    thermal: crate::thermal::MotorThermal,
}

/// A usable current limit: the configured one if finite and positive, else 0 (always safe).
pub(crate) const fn sane_limit(limit_a: f32) -> f32 {
    if limit_a.is_finite() && limit_a > 0.0 {
        limit_a
    } else {
        0.0
    }
}

impl Supervisor {
    /// Creates a supervisor with no fault latched, once `config` passes
    /// [`SupervisorConfig::validate`]. Commands are clamped to
    /// `±current_limit_a`, the model's usable limit
    /// ([`crate::model::ModelParams::usable_current_limit_a`]: the one
    /// definition of the current limit), which must be finite and positive,
    /// and no higher than the overcurrent trip level.
    pub fn new(config: SupervisorConfig, current_limit_a: f32) -> Result<Self, InvalidField> {
        config.validate()?;
        require(
            current_limit_a.is_finite() && current_limit_a > 0.0,
            "model.current_limit_a",
        )?;
        require(
            config.overcurrent_trip_a >= current_limit_a,
            "supervisor.overcurrent_trip_a",
        )?;
        Ok(Self {
            config,
            latched: Faults::NONE,
            disagree_ref: 0.0,
            frozen_ref: 0.0,
            period_scale: 1.0,
            jump_limits: jump_limits(&config, 1.0),
            limit_a: current_limit_a,
            half_inv_decel: 0.5 / config.brake_decel_mps2,
            stops_centre_m: 0.5 * (config.nut_stops_m.min + config.nut_stops_m.max),
            stops_inner_half_m: 0.5 * (config.nut_stops_m.max - config.nut_stops_m.min)
                - STOP_BAND_M,
            thermal: crate::thermal::MotorThermal::new(config.thermal)?,
        })
    }

    /// The motor's thermal state (winding and housing temperatures, the
    /// current limit's derating).
    pub const fn thermal(&self) -> &crate::thermal::MotorThermal {
        &self.thermal
    }

    /// After a warm reset: the motor may still be hot
    /// ([`crate::thermal::MotorThermal::assume_warm`]).
    pub fn assume_motor_warm(&mut self) {
        self.thermal.assume_warm();
    }

    /// Carries `old`'s motor temperatures over (a rebuilt configuration
    /// does not cool the motor).
    pub fn continue_thermal(&mut self, old: &Supervisor) {
        self.thermal.continue_from(&old.thermal);
    }

    /// One period of `dt_s` in which the amplifier was told to drive
    /// `current_a` (0 when it was disabled): heats the thermal model, and
    /// latches [`Fault::Overtemperature`] at the trip temperature. The
    /// period runner calls it once per period with what it wrote.
    #[inline]
    pub fn heat(&mut self, current_a: f32, dt_s: f32) {
        self.thermal.add(current_a, dt_s);
        if self.thermal.tripped() {
            self.latched.insert(Fault::Overtemperature);
        }
    }

    /// Whether the motor encoder gave no count although the motor turns
    /// faster than `frozen_speed_rad_s`, away from the stops. Every
    /// comparison is false for NaN (a NaN input is caught by the range
    /// checks instead).
    #[inline(always)]
    fn encoder_frozen(&self, input: &SupervisorInput) -> bool {
        input.motor_delta_counts == 0
            && input.motor_speed_rad_s.abs() > self.config.frozen_speed_rad_s
            && (input.nut_position_m - self.stops_centre_m).abs() < self.stops_inner_half_m
    }

    /// The configuration in use.
    pub const fn config(&self) -> &SupervisorConfig {
        &self.config
    }

    /// The current limit commands are clamped to, A.
    pub const fn current_limit_a(&self) -> f32 {
        self.limit_a
    }

    /// The latched faults (empty when running).
    pub const fn faults(&self) -> Faults {
        self.latched
    }

    /// Whether any fault is latched.
    pub const fn is_faulted(&self) -> bool {
        !self.latched.is_empty()
    }

    /// Latches [`Fault::Overrun`] (the application missed a control deadline).
    pub fn report_overrun(&mut self) {
        self.latched.insert(Fault::Overrun);
    }

    /// Latches [`Fault::DacError`] (a DAC write failed).
    pub fn report_dac_error(&mut self) {
        self.latched.insert(Fault::DacError);
    }

    /// Latches an arbitrary fault (e.g. a sensor conversion error seen by the application).
    pub fn report(&mut self, fault: Fault) {
        self.latched.insert(fault);
    }

    /// Faults present in `input` alone (everything but the contact-disagree
    /// persistence, the command checks and the reported events).
    fn input_faults(&self, input: &SupervisorInput) -> Faults {
        let c = &self.config;
        let mut f = Faults::NONE;
        let values = [
            (input.nut_position_m, c.nut_position_range_m),
            (input.nut_velocity_mps, c.nut_velocity_range_mps),
            (input.motor_speed_rad_s, c.motor_speed_range_rad_s),
            (input.body_height_m, c.body_height_range_m),
            (input.body_velocity_mps, c.body_velocity_range_mps),
            (input.spring_force_n, c.spring_force_range_n),
            (input.leg_compression_m, c.leg_compression_range_m),
        ];
        // Every period: all values in range. A NaN compares false and an
        // infinity is outside the (validated, finite) bounds, so this also
        // rules out non-finite values. `&` rather than `&&`: no branch per
        // value.
        let all_in_range = values
            .iter()
            .fold(true, |ok, (x, r)| ok & (*x >= r.min) & (*x <= r.max));
        if !all_in_range {
            // Slow path, only on a fault: say which kind.
            for (x, range) in values {
                if !x.is_finite() {
                    f.insert(Fault::SensorNonFinite);
                } else if !range.contains(x) {
                    f.insert(Fault::SensorRange);
                }
            }
        }
        let (motor_limit, height_limit) = self.jump_limits;
        if input.motor_delta_counts.unsigned_abs() as f32 > motor_limit
            || input.height_delta_counts.unsigned_abs() as f32 > height_limit
        {
            f.insert(Fault::EncoderJump);
        }
        // Values in range are finite; otherwise the position and velocity
        // are checked (a non-finite one is named above, not as a stroke).
        if all_in_range || (input.nut_position_m.is_finite() && input.nut_velocity_mps.is_finite())
        {
            let p = input.nut_position_m;
            let pd = input.nut_velocity_mps;
            let stop_m = p + pd * pd.abs() * self.half_inv_decel;
            // `!(a <= x && x <= b)` also catches NaN from an overflow.
            if !(stop_m >= c.stroke_min_m && stop_m <= c.stroke_max_m) {
                f.insert(Fault::StrokeLimit);
            }
        }
        if input.estop_pressed {
            f.insert(Fault::Estop);
        }
        if input.amp_fault {
            f.insert(Fault::AmpFault);
        }
        // A NaN residual (a non-finite input, already named above) is not a
        // disagreement; only finite residuals beyond the bound are.
        let residual_n = self.spring_residual_n(input);
        // False for a NaN bound too: a bad bound fails safe.
        let within = residual_n.abs() <= c.spring_mismatch_n;
        if residual_n.is_finite() && !within {
            f.insert(Fault::SensorDisagree);
        }
        f
    }

    /// `F - k (delta0 + p + x)`, N: what the load cell measures beyond the
    /// spring compression the motor encoder and the potentiometer give (0
    /// up to noise when all three work; in flight `x` is 0).
    #[inline(always)]
    fn spring_residual_n(&self, input: &SupervisorInput) -> f32 {
        let c = &self.config;
        input.spring_force_n
            - c.spring_rate_n_per_m
                * (c.spring_preload_m + input.nut_position_m + input.leg_compression_m)
    }

    /// Whether load cell and pot disagree about contact in this sample.
    fn contact_disagrees(&self, input: &SupervisorInput) -> bool {
        let c = &self.config;
        let contact_force_n = input.spring_force_n - c.flight_force_n(input.nut_position_m);
        let x = input.leg_compression_m;
        let cell_contact = contact_force_n > c.contact_force_n;
        let cell_free = contact_force_n < c.free_force_n;
        let pot_contact = x > c.contact_compression_m;
        let pot_free = x < c.free_compression_m;
        (cell_contact && pot_free) || (pot_contact && cell_free)
    }

    /// Checks one period's input and request; returns the command for the amplifier.
    ///
    /// Detected faults latch immediately, and the returned command is then
    /// [`Command::SAFE`] (also in this same call). Otherwise the request is
    /// clamped to `±current_limit_a` and the amplifier enabled. A NaN or
    /// infinite request latches [`Fault::CommandNonFinite`]; a request beyond
    /// `overcurrent_trip_a` latches [`Fault::Overcurrent`].
    ///
    /// `dt_s` is the control period: the limits stated per
    /// [`REFERENCE_PERIOD_S`] scale to it (a non-finite or non-positive one
    /// keeps the last good scale). Contact disagreement must persist
    /// `contact_disagree_periods` x 100 us, and a silent encoder 100 us,
    /// before they latch.
    #[inline]
    pub fn check(
        &mut self,
        input: &SupervisorInput,
        requested_current_a: f32,
        dt_s: f32,
    ) -> Command {
        let scale = dt_s * (1.0 / REFERENCE_PERIOD_S);
        if scale != self.period_scale && scale > 0.0 && scale < f32::INFINITY {
            self.period_scale = scale;
            self.jump_limits = jump_limits(&self.config, scale);
        }
        let scale = self.period_scale;
        let mut new = self.input_faults(input);
        // Persistence in time: the sums of scales compare against whole
        // reference periods, less a little for the rounding of the sums.
        const ROUNDING: f32 = 1.0e-3;
        if self.contact_disagrees(input) {
            self.disagree_ref += scale;
            if self.disagree_ref >= f32::from(self.config.contact_disagree_periods) - ROUNDING {
                new.insert(Fault::ContactDisagree);
            }
        } else {
            self.disagree_ref = 0.0;
        }
        if self.encoder_frozen(input) {
            self.frozen_ref += scale;
            if self.frozen_ref >= 1.0 - ROUNDING {
                new.insert(Fault::EncoderFrozen);
            }
        } else {
            self.frozen_ref = 0.0;
        }
        if !requested_current_a.is_finite() {
            new.insert(Fault::CommandNonFinite);
        } else if requested_current_a.abs() > self.config.overcurrent_trip_a {
            // A NaN trip level makes this false; the clamp below still limits the output.
            new.insert(Fault::Overcurrent);
        }
        self.latched = self.latched.union(new);
        if self.is_faulted() {
            return Command::SAFE;
        }
        // Derated by the winding temperature: a scale in (0, 1].
        let limit = self.limit_a * self.thermal.limit_scale();
        // Finite request, finite non-negative limit: the clamp is finite and in range.
        Command {
            current_a: crate::num::clamp(requested_current_a, -limit, limit),
            amp_enable: limit > 0.0,
        }
    }

    /// Clears the latched faults if their conditions are gone in `input`.
    ///
    /// Conditions that are states (sensor non-finite or out of range, encoder
    /// delta too large, stroke prediction outside the soft limits, load cell
    /// disagreeing with encoder and potentiometer, e-stop pressed, amplifier
    /// fault) are re-evaluated on `input`; if any is still
    /// present, nothing is cleared and the faults still present are returned.
    /// Event faults (contact disagreement, overcurrent, non-finite command,
    /// overrun, DAC error) are in the past, so they clear. An
    /// overtemperature clears once the winding is below
    /// `thermal.derate_winding_c`. `SelfCheck` never
    /// clears (only the watchdog's hardware reset does). The
    /// contact-disagreement counter restarts. Call it with a fresh sample,
    /// with the amplifier disabled.
    pub fn reset(&mut self, input: &SupervisorInput) -> Result<(), Faults> {
        // `SelfCheck` means the software's own output contradicted itself:
        // only the hardware reset it leads to clears it.
        let self_check = Faults(self.latched.0 & Fault::SelfCheck.bit());
        let mut still = self.input_faults(input).union(self_check);
        if self.encoder_frozen(input) {
            still.insert(Fault::EncoderFrozen);
        }
        // The winding must have cooled below the derating band.
        if self.latched.contains(Fault::Overtemperature) && !self.thermal.cool() {
            still.insert(Fault::Overtemperature);
        }
        if !still.is_empty() {
            return Err(still);
        }
        self.latched = Faults::NONE;
        self.disagree_ref = 0.0;
        self.frozen_ref = 0.0;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Standing still, nut on its upper stop, leg at free length.
    fn nominal() -> SupervisorInput {
        SupervisorInput {
            nut_position_m: 0.0,
            nut_velocity_mps: 0.0,
            motor_speed_rad_s: 0.0,
            body_height_m: 0.61,
            body_velocity_mps: 0.0,
            spring_force_n: flight_force_n(), // k * delta0
            leg_compression_m: 0.0,
            motor_delta_counts: 0,
            height_delta_counts: 0,
            estop_pressed: false,
            amp_fault: false,
        }
    }

    /// `k delta0` of the default configuration, N: the load cell in flight
    /// with the nut on its upper stop.
    fn flight_force_n() -> f32 {
        let d = SupervisorConfig::default();
        d.spring_rate_n_per_m * d.spring_preload_m
    }

    fn sup() -> Supervisor {
        built(SupervisorConfig::default())
    }

    /// The default model's usable current limit, A.
    const LIMIT_A: f32 = 33.7;

    fn built(c: SupervisorConfig) -> Supervisor {
        Supervisor::new(c, LIMIT_A).unwrap_or_else(|e| panic!("{e:?}"))
    }

    /// Applies `bad` once, expects `fault` latched and SAFE at once, stays latched,
    /// reset fails while `bad` persists (if `state`), succeeds on nominal input.
    fn fault_case(bad: SupervisorInput, request_a: f32, fault: Fault, state: bool) {
        let mut s = sup();
        let ok = s.check(&nominal(), 5.0, REFERENCE_PERIOD_S);
        assert_eq!(
            ok,
            Command {
                current_a: 5.0,
                amp_enable: true
            }
        );
        assert_eq!(
            s.check(&bad, request_a, REFERENCE_PERIOD_S),
            Command::SAFE,
            "{}",
            fault.name()
        );
        assert!(s.faults().contains(fault), "{:?}", s.faults());
        for _ in 0..3 {
            assert_eq!(s.check(&nominal(), 5.0, REFERENCE_PERIOD_S), Command::SAFE);
        }
        if state {
            assert!(s.reset(&bad).is_err(), "{}", fault.name());
            assert!(s.is_faulted());
        }
        assert_eq!(s.reset(&nominal()), Ok(()));
        assert_eq!(s.check(&nominal(), 5.0, REFERENCE_PERIOD_S).current_a, 5.0);
    }

    #[test]
    fn sensor_nonfinite() {
        let bad = SupervisorInput {
            spring_force_n: f32::NAN,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::SensorNonFinite, true);
    }

    #[test]
    fn sensor_range() {
        let bad = SupervisorInput {
            body_height_m: 5.0,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::SensorRange, true);
    }

    #[test]
    fn encoder_jump() {
        let bad = SupervisorInput {
            motor_delta_counts: -65,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::EncoderJump, true);
        let bad = SupervisorInput {
            height_delta_counts: i32::MIN,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::EncoderJump, true);
    }

    #[test]
    fn stroke_limit_predicts_stopping_point() {
        // 0.03 m + 0.6^2 / 6 = 0.09 m > 0.055.
        let bad = SupervisorInput {
            nut_position_m: 0.03,
            nut_velocity_mps: 0.6,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::StrokeLimit, true);
        // 0.03 + 0.3^2/6 = 0.045: fine.
        let mut s = sup();
        let fine = SupervisorInput {
            nut_position_m: 0.03,
            nut_velocity_mps: 0.3,
            spring_force_n: flight_force_n() + 330.0,
            ..nominal()
        };
        assert!(s.check(&fine, 1.0, REFERENCE_PERIOD_S).amp_enable);
        // Upward: 0.01 - 0.4^2/6 = -0.0167 < -0.005.
        let up = SupervisorInput {
            nut_position_m: 0.01,
            nut_velocity_mps: -0.4,
            spring_force_n: flight_force_n() + 110.0,
            ..nominal()
        };
        fault_case(up, 0.0, Fault::StrokeLimit, true);
    }

    #[test]
    fn estop_and_amp_fault() {
        let bad = SupervisorInput {
            estop_pressed: true,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::Estop, true);
        let bad = SupervisorInput {
            amp_fault: true,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::AmpFault, true);
    }

    #[test]
    fn overcurrent_and_nonfinite_command() {
        fault_case(nominal(), 400.0, Fault::Overcurrent, false);
        fault_case(nominal(), f32::NAN, Fault::CommandNonFinite, false);
        fault_case(nominal(), f32::NEG_INFINITY, Fault::CommandNonFinite, false);
    }

    #[test]
    fn request_is_clamped_not_faulted_below_trip() {
        let mut s = sup();
        let c = s.check(&nominal(), 100.0, REFERENCE_PERIOD_S);
        assert_eq!(c.current_a, 33.7);
        assert!(c.amp_enable);
        assert_eq!(
            s.check(&nominal(), -100.0, REFERENCE_PERIOD_S).current_a,
            -33.7
        );
    }

    /// Load cell: k delta0 + 200 N contact force; pot: no compression.
    fn cell_says_contact_pot_says_free() -> SupervisorInput {
        SupervisorInput {
            spring_force_n: flight_force_n() + 200.0,
            ..nominal()
        }
    }

    /// The cross-check would trip on a contact disagreement at once; the
    /// tests of the debounced contact check alone turn it off.
    fn no_cross_check() -> SupervisorConfig {
        SupervisorConfig {
            spring_mismatch_n: f32::INFINITY,
            ..SupervisorConfig::default()
        }
    }

    #[test]
    fn contact_disagree_needs_persistence() {
        let bad = cell_says_contact_pot_says_free();
        let mut s = built(no_cross_check());
        for _ in 0..19 {
            assert!(s.check(&bad, 1.0, REFERENCE_PERIOD_S).amp_enable);
        }
        // An agreeing sample restarts the count.
        assert!(s.check(&nominal(), 1.0, REFERENCE_PERIOD_S).amp_enable);
        for _ in 0..19 {
            assert!(s.check(&bad, 1.0, REFERENCE_PERIOD_S).amp_enable);
        }
        assert_eq!(s.check(&bad, 1.0, REFERENCE_PERIOD_S), Command::SAFE);
        assert!(s.faults().contains(Fault::ContactDisagree));
        assert_eq!(s.check(&nominal(), 1.0, REFERENCE_PERIOD_S), Command::SAFE);
        assert_eq!(s.reset(&nominal()), Ok(()));
        // Pot says compressed, load cell says free.
        let other = SupervisorInput {
            leg_compression_m: 0.03,
            ..nominal()
        };
        let mut last = Command::SAFE;
        for _ in 0..20 {
            last = s.check(&other, 1.0, REFERENCE_PERIOD_S);
        }
        assert_eq!(last, Command::SAFE);
        // Stance where they agree: compression 20 mm, force k (delta0 + 0.02).
        let mut s = sup();
        let stance = SupervisorInput {
            leg_compression_m: 0.02,
            body_height_m: 0.59,
            spring_force_n: flight_force_n() + 220.0,
            ..nominal()
        };
        for _ in 0..100 {
            assert!(s.check(&stance, 1.0, REFERENCE_PERIOD_S).amp_enable);
        }
    }

    #[test]
    fn sensor_disagree_when_the_load_cell_leaves_the_spring_model() {
        // Nut 10 mm down per the encoder, but the load cell still reads the
        // preload: a frozen encoder or a stuck load cell.
        let bad = SupervisorInput {
            nut_position_m: 0.01,
            ..nominal()
        };
        fault_case(bad, 0.0, Fault::SensorDisagree, true);
        // 25 N off (below the 30 N bound): fine.
        let mut s = sup();
        let near = SupervisorInput {
            spring_force_n: flight_force_n() + 25.0,
            ..nominal()
        };
        assert!(s.check(&near, 1.0, REFERENCE_PERIOD_S).amp_enable);
        // A NaN bound is refused.
        let nan = SupervisorConfig {
            spring_mismatch_n: f32::NAN,
            ..SupervisorConfig::default()
        };
        assert_eq!(
            Supervisor::new(nan, LIMIT_A).err(),
            Some(InvalidField("supervisor.spring_mismatch_n"))
        );
    }

    /// The per-100-us limits scale with the period. At 100 kHz a
    /// silent encoder at speed needs ten periods (100 us) to trip and one
    /// count per period is normal; at 1 kHz 300 counts in a period (940
    /// rad/s) are plausible and 700 are not.
    #[test]
    fn limits_scale_with_the_period() {
        let moving = moving_without_a_count();
        let dt = 1e-5;
        let mut s = sup();
        for k in 0..9 {
            assert!(s.check(&moving, 1.0, dt).amp_enable, "period {k}");
        }
        assert_eq!(s.check(&moving, 1.0, dt), Command::SAFE);
        assert!(s.faults().contains(Fault::EncoderFrozen));
        // A count every other period at 100 kHz: fine.
        let mut s = sup();
        for k in 0..100 {
            let input = SupervisorInput {
                motor_delta_counts: k % 2,
                ..moving
            };
            assert!(s.check(&input, 1.0, dt).amp_enable, "period {k}");
        }
        // At 100 kHz the 64 counts per 100 us are 6.4 per period: six pass
        // (1,900 rad/s), seven do not.
        let jump = |n| SupervisorInput {
            motor_delta_counts: n,
            ..moving
        };
        assert!(sup().check(&jump(6), 1.0, dt).amp_enable);
        assert_eq!(sup().check(&jump(7), 1.0, dt), Command::SAFE);
        // 1 kHz: 640 counts per period allowed.
        let dt = 1e-3;
        assert!(sup().check(&jump(300), 1.0, dt).amp_enable);
        assert!(sup().check(&jump(640), 1.0, dt).amp_enable);
        let mut s = sup();
        assert_eq!(s.check(&jump(700), 1.0, dt), Command::SAFE);
        assert!(s.faults().contains(Fault::EncoderJump));
        // Contact disagreement for 2 ms: 2 periods at 1 kHz, 200 at 100 kHz.
        let bad = cell_says_contact_pot_says_free();
        for (dt, periods) in [(1e-3_f32, 2), (1e-5, 200)] {
            let mut s = built(no_cross_check());
            for k in 1..periods {
                assert!(s.check(&bad, 1.0, dt).amp_enable, "dt {dt}: period {k}");
            }
            assert_eq!(s.check(&bad, 1.0, dt), Command::SAFE, "dt {dt}");
            assert!(s.faults().contains(Fault::ContactDisagree));
        }
    }

    /// 20 mm down, motor at 150 rad/s per the filter, no count this period.
    fn moving_without_a_count() -> SupervisorInput {
        SupervisorInput {
            nut_position_m: 0.02,
            motor_speed_rad_s: 150.0,
            nut_velocity_mps: 0.12,
            spring_force_n: flight_force_n() + 220.0,
            motor_delta_counts: 0,
            ..nominal()
        }
    }

    #[test]
    fn encoder_frozen_at_speed_away_from_the_stops() {
        let moving = moving_without_a_count();
        fault_case(moving, 0.0, Fault::EncoderFrozen, true);
        let mut s = sup();
        // Counting: fine.
        let counting = SupervisorInput {
            motor_delta_counts: 4,
            ..moving
        };
        assert!(s.check(&counting, 1.0, REFERENCE_PERIOD_S).amp_enable);
        // Slow: fine.
        let slow = SupervisorInput {
            motor_speed_rad_s: 60.0,
            nut_velocity_mps: 0.05,
            ..moving
        };
        assert!(s.check(&slow, 1.0, REFERENCE_PERIOD_S).amp_enable);
        // On the upper stop (an impact halts the nut at once): fine.
        let on_stop = SupervisorInput {
            nut_position_m: 0.0002,
            nut_velocity_mps: 0.0,
            spring_force_n: flight_force_n() + 2.2,
            ..moving
        };
        assert!(s.check(&on_stop, 1.0, REFERENCE_PERIOD_S).amp_enable);
    }

    #[test]
    fn reported_events() {
        let mut s = sup();
        s.report_overrun();
        assert_eq!(s.check(&nominal(), 1.0, REFERENCE_PERIOD_S), Command::SAFE);
        s.report_dac_error();
        let names: heapless::Vec<&str, 13> = s.faults().iter().map(Fault::name).collect();
        assert_eq!(names.as_slice(), &["overrun", "dac-error"]);
        assert_eq!(s.reset(&nominal()), Ok(()));
        assert!(!s.is_faulted());
    }

    #[test]
    fn bad_configurations_are_refused_by_name() {
        let d = SupervisorConfig::default();
        let refused = |c: SupervisorConfig| Supervisor::new(c, LIMIT_A).err().map(|f| f.0);
        for limit in [f32::NAN, 0.0, -1.0, f32::INFINITY] {
            assert_eq!(
                Supervisor::new(d, limit).err().map(|f| f.0),
                Some("model.current_limit_a")
            );
        }
        assert_eq!(
            refused(SupervisorConfig {
                overcurrent_trip_a: 10.0,
                ..d
            }),
            Some("supervisor.overcurrent_trip_a")
        );
        assert_eq!(
            refused(SupervisorConfig {
                body_height_range_m: Range {
                    min: 0.4,
                    max: f32::INFINITY
                },
                ..d
            }),
            Some("supervisor.body_height_range_m")
        );
        assert_eq!(
            refused(SupervisorConfig {
                brake_decel_mps2: 0.0,
                ..d
            }),
            Some("supervisor.brake_decel_mps2")
        );
        // Infinite cross-check bounds turn the checks off and are allowed.
        assert_eq!(
            refused(SupervisorConfig {
                spring_mismatch_n: f32::INFINITY,
                frozen_speed_rad_s: f32::INFINITY,
                ..d
            }),
            None
        );
    }

    #[test]
    fn from_measurements_copies_fields() {
        let m = crate::calibration::Measurements {
            nut_position_m: 0.01,
            body_height_m: 0.6,
            spring_force_n: 200.0,
            leg_compression_m: 0.01,
            motor_delta_counts: 3,
            height_delta_counts: -2,
            estop_pressed: true,
            ..Default::default()
        };
        let i = SupervisorInput::from_measurements(&m, 0.1, 125.0, -1.0);
        assert_eq!(i.nut_position_m, 0.01);
        assert_eq!(i.nut_velocity_mps, 0.1);
        assert_eq!(i.motor_speed_rad_s, 125.0);
        assert_eq!(i.body_velocity_mps, -1.0);
        assert_eq!(i.height_delta_counts, -2);
        assert!(i.estop_pressed && !i.amp_fault);
    }

    #[test]
    fn names_unique_and_bits_distinct() {
        let mut all = Faults::NONE;
        for &f in Fault::ALL {
            assert!(!all.contains(f));
            all.insert(f);
        }
        assert_eq!(all.iter().count(), Fault::ALL.len());
        for (i, a) in Fault::ALL.iter().enumerate() {
            for b in Fault::ALL.iter().skip(i + 1) {
                assert_ne!(a.name(), b.name());
            }
        }
    }

    fn any_f32() -> impl Strategy<Value = f32> {
        prop_oneof![
            8 => -2.0_f32..2.0,
            2 => -2000.0_f32..2000.0,
            1 => Just(f32::NAN),
            1 => Just(f32::INFINITY),
            1 => Just(f32::NEG_INFINITY),
            1 => any::<f32>(),
        ]
    }

    prop_compose! {
        fn any_input()(
            nut_position_m in any_f32(),
            nut_velocity_mps in any_f32(),
            motor_speed_rad_s in any_f32(),
            body_height_m in any_f32(),
            body_velocity_mps in any_f32(),
            spring_force_n in any_f32(),
            leg_compression_m in any_f32(),
            motor_delta_counts in prop_oneof![4 => -80_i32..80, 1 => any::<i32>()],
            height_delta_counts in prop_oneof![4 => -40_i32..40, 1 => any::<i32>()],
            estop_pressed in prop::bool::weighted(0.02),
            amp_fault in prop::bool::weighted(0.02),
            nominal_sample in prop::bool::weighted(0.5),
        ) -> SupervisorInput {
            if nominal_sample {
                return nominal();
            }
            SupervisorInput {
                nut_position_m, nut_velocity_mps, motor_speed_rad_s, body_height_m,
                body_velocity_mps, spring_force_n, leg_compression_m,
                motor_delta_counts, height_delta_counts, estop_pressed, amp_fault,
            }
        }
    }

    proptest! {
        #[test]
        fn output_always_finite_and_limited(
            steps in prop::collection::vec((any_input(), any_f32(), 0_u8..20), 1..200)
        ) {
            let mut s = sup();
            let limit = s.current_limit_a();
            for (input, request, action) in steps {
                match action {
                    0 => s.report_overrun(),
                    1 => s.report_dac_error(),
                    2 => { let _ = s.reset(&input); }
                    _ => {}
                }
                let c = s.check(&input, request, REFERENCE_PERIOD_S);
                prop_assert!(c.current_a.is_finite());
                prop_assert!(c.current_a.abs() <= limit);
                if !c.amp_enable {
                    prop_assert_eq!(c.current_a, 0.0);
                }
            }
        }
    }

    /// What the application does between supervisor checks.
    #[derive(Debug, Clone, Copy)]
    enum Action {
        Check(SupervisorInput, f32),
        Overrun,
        DacError,
        Reset(SupervisorInput),
    }

    fn any_action() -> impl Strategy<Value = Action> {
        prop_oneof![
            20 => (any_input(), any_f32()).prop_map(|(i, r)| Action::Check(i, r)),
            1 => Just(Action::Overrun),
            1 => Just(Action::DacError),
            3 => any_input().prop_map(Action::Reset),
        ]
    }

    /// Property 2 (supervisor): a latched fault stays latched, with
    /// [`Command::SAFE`] out, through any inputs and requests until a reset
    /// succeeds; faults only accumulate until then, a refused reset clears
    /// nothing, and a successful one clears everything. 10 000 cases by
    /// default ([`crate::proptest_support::cases`]).
    #[test]
    fn latched_fault_stays_until_reset() {
        let result = crate::proptest_support::run(
            "supervisor latched_fault_stays_until_reset",
            prop::collection::vec(any_action(), 1..48),
            |actions| {
                let mut s = sup();
                for action in actions {
                    let before = s.faults();
                    match action {
                        Action::Check(input, request) => {
                            let c = s.check(&input, request, REFERENCE_PERIOD_S);
                            prop_assert_eq!(s.faults().0 & before.0, before.0);
                            if s.is_faulted() {
                                prop_assert_eq!(c, Command::SAFE);
                            }
                        }
                        Action::Overrun => {
                            s.report_overrun();
                            prop_assert!(s.faults().contains(Fault::Overrun));
                        }
                        Action::DacError => {
                            s.report_dac_error();
                            prop_assert!(s.faults().contains(Fault::DacError));
                        }
                        Action::Reset(input) => match s.reset(&input) {
                            Ok(()) => prop_assert!(!s.is_faulted()),
                            Err(_) => prop_assert_eq!(s.faults().0 & before.0, before.0),
                        },
                    }
                    prop_assert_eq!(s.is_faulted(), !s.faults().is_empty());
                }
                Ok(())
            },
        );
        result.unwrap_or_else(|e| panic!("{e}"));
    }

    proptest::proptest! {
        /// With the default thresholds, no sample passes the spring check
        /// while the load cell and the potentiometer disagree about contact.
        #[test]
        fn no_contact_disagreement_passes_the_spring_check(
            f in -100.0f32..2000.0, p in -0.01f32..0.06, x in -0.005f32..0.12,
        ) {
            let s = sup();
            let input = SupervisorInput {
                nut_position_m: p,
                spring_force_n: f,
                leg_compression_m: x,
                ..SupervisorInput::default()
            };
            if s.spring_residual_n(&input).abs() <= s.config.spring_mismatch_n {
                proptest::prop_assert!(!s.contact_disagrees(&input));
            }
        }
    }
}
