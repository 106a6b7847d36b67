//! The motor's winding temperature, estimated from the current the
//! amplifier is told to drive: derate, then fault.
//!
//! The thesis gives no thermal data for its 80 W motor, and its hopping
//! drives far more than any such motor's continuous current: 17 to 29 A RMS
//! with every controller on the design machine (simulated, 10 cm target),
//! 32 A RMS for energy-apex standing on the ground, against about 6 A
//! continuous. So a real robot needs this protection, and the simulator
//! runs it too (it lives in the [`Supervisor`](crate::supervisor::Supervisor)).
//!
//! The model is the two-body one maxon's catalogue pages give the data for
//! (winding and housing, each with a thermal resistance and a time
//! constant), temperatures in degrees Celsius:
//!
//! ```text
//! C_w dT_w/dt = i^2 R (1 + a (T_w - 25)) - (T_w - T_h) / R_wh
//! C_h dT_h/dt = (T_w - T_h) / R_wh - (T_h - T_a) / R_ha
//! C_w = tau_w / R_wh,   C_h = tau_h / R_ha,   a = 0.0039 / K (copper)
//! ```
//!
//! Its defaults are a 40 mm graphite-brush maxon motor with the model's
//! torque constant (the RE 40, 24 V winding: 30.2 mN m/A against the
//! model's 29.7): 0.299 ohm, 1.93 and 4.65 K/W, 41.6 and 1120 s, at most
//! 155 C in the winding. Replace them with your motor's datasheet values
//! (`thermal.*` parameters). With them, the current that settles at the
//! trip temperature (150 C) is 6.5 A, and a constant current reaches it in:
//!
//! | current, A RMS | 10 | 15 | 20.7 | 25.3 | 28.8 | 32 | 33.67 |
//! |---|---|---|---|---|---|---|---|
//! | trip, s | 392 | 52.6 | 21.1 | 13.1 | 9.8 | 7.8 | 7.0 |
//!
//! (`tests` below check this table against the model.) Between
//! `derate_winding_c` and `trip_winding_c` the current limit falls
//! linearly to `derated_limit_fraction` of the amplifier's; at
//! `trip_winding_c` [`Fault::Overtemperature`](crate::supervisor::Fault)
//! latches, and it clears (`reset-faults`) only once the winding has cooled
//! below `derate_winding_c`.
//!
//! `thermal.protect = 0` keeps the estimate (`hopper-sim`'s summary
//! reports it) without derating or faulting: for control studies past the
//! motor's thermal limit, never on a robot.
//!
//! The state advances once per [`THERMAL_STEP_S`] of accumulated periods:
//! at 10 kHz a period changes the housing temperature by about 1e-7 of
//! itself, below `f32`'s resolution, and thermal time constants are tens
//! of seconds anyway. Per period it costs a multiply-add and a compare.
//! At a power-on the motor is taken to be at the ambient temperature;
//! after a warm reset the board calls [`MotorThermal::assume_warm`].

use crate::param::InvalidField;

/// How much time the model integrates at once, s (see the module docs).
pub const THERMAL_STEP_S: f32 = 0.01;

/// Copper's resistance temperature coefficient, 1/K (winding resistance
/// is stated at 25 C).
pub const COPPER_TEMPCO_PER_K: f32 = 0.0039;

crate::param::config! {
    /// The motor's thermal data and the protection's thresholds; every field
    /// is a `thermal.*` parameter ([`crate::params`]).
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct ThermalConfig;
    params {
        /// Whether the estimate derates the current limit and latches the
        /// fault (`false` only for control studies past the motor's thermal
        /// limit: the temperatures are still estimated and reported).
        88 THERMAL_PROTECT protect: bool {
            "thermal.protect", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
            "Derate and fault on the winding temperature estimate; 0 only for control studies past the motor's thermal limit (the estimate is still reported), never on a robot."
        }
        /// Winding (terminal) resistance at 25 C.
        89 THERMAL_RESISTANCE_OHM winding_resistance_ohm: f32 {
            "thermal.winding_resistance_ohm", "ohm", Real, [1.0e-3, 100.0], 0.299, DISARMED,
            "Motor winding resistance at 25 C (the RE 40 24 V winding's; use your motor's datasheet)."
        }
        90 THERMAL_WINDING_TO_HOUSING winding_to_housing_k_per_w: f32 {
            "thermal.winding_to_housing_k_per_w", "K/W", Real, [1.0e-2, 100.0], 1.93, DISARMED,
            "Thermal resistance winding to housing (motor datasheet)."
        }
        91 THERMAL_HOUSING_TO_AMBIENT housing_to_ambient_k_per_w: f32 {
            "thermal.housing_to_ambient_k_per_w", "K/W", Real, [1.0e-2, 100.0], 4.65, DISARMED,
            "Thermal resistance housing to ambient (motor datasheet; a heat sink lowers it)."
        }
        92 THERMAL_WINDING_TAU winding_time_constant_s: f32 {
            "thermal.winding_time_constant_s", "s", Real, [0.1, 1.0e4], 41.6, DISARMED,
            "Winding thermal time constant (motor datasheet)."
        }
        93 THERMAL_HOUSING_TAU housing_time_constant_s: f32 {
            "thermal.housing_time_constant_s", "s", Real, [1.0, 1.0e5], 1120.0, DISARMED,
            "Motor (housing) thermal time constant (motor datasheet)."
        }
        94 THERMAL_AMBIENT ambient_c: f32 {
            "thermal.ambient_c", "degC", Real, [-40.0, 80.0], 25.0, DISARMED,
            "Ambient temperature; the motor is taken to be at it at boot."
        }
        95 THERMAL_DERATE derate_winding_c: f32 {
            "thermal.derate_winding_c", "degC", Real, [0.0, 250.0], 135.0, DISARMED,
            "Estimated winding temperature where the current limit starts to fall."
        }
        96 THERMAL_TRIP trip_winding_c: f32 {
            "thermal.trip_winding_c", "degC", Real, [0.0, 250.0], 150.0, DISARMED,
            "Estimated winding temperature that latches overtemperature (5 K under the RE 40's 155 C)."
        }
        /// The current limit at `trip_winding_c`, as a fraction of the
        /// amplifier's.
        97 THERMAL_DERATED_FRACTION derated_limit_fraction: f32 {
            "thermal.derated_limit_fraction", "1", Real, [0.05, 1.0], 0.5, DISARMED,
            "Current limit at the trip temperature, as a fraction of the amplifier's (linear from the derate temperature)."
        }
    }
}

impl ThermalConfig {
    /// Every field within its parameter's range, and the derating band
    /// above the ambient and below the trip; the first one that is not is
    /// named.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)?;
        // Finite by the entries' ranges.
        if self.derate_winding_c <= self.ambient_c {
            return Err(InvalidField(entries::THERMAL_DERATE.name));
        }
        if self.trip_winding_c <= self.derate_winding_c {
            return Err(InvalidField(entries::THERMAL_TRIP.name));
        }
        Ok(())
    }

    /// The winding's resistance at `winding_c`, ohm (copper's temperature
    /// coefficient from 25 C; never negative).
    pub fn resistance_at_ohm(&self, winding_c: f32) -> f32 {
        crate::num::max(
            self.winding_resistance_ohm * (1.0 + COPPER_TEMPCO_PER_K * (winding_c - 25.0)),
            0.0,
        )
    }

    /// The RMS current that settles the winding at the trip temperature, A
    /// (the motor's continuous rating under this model; from the fixed point
    /// of [`Self::steady_winding_c`], `i^2 = (T - T_a) / (R(T) (R_wh +
    /// R_ha))` at `T = trip_winding_c`).
    pub fn continuous_current_a(&self) -> f32 {
        let r_ohm = self.resistance_at_ohm(self.trip_winding_c);
        let rth = self.winding_to_housing_k_per_w + self.housing_to_ambient_k_per_w;
        let i2 = (self.trip_winding_c - self.ambient_c) / (r_ohm * rth);
        if i2 > 0.0 && i2 < f32::INFINITY {
            libm::sqrtf(i2)
        } else {
            0.0
        }
    }

    /// The winding temperature a steady mean square current `mean_i2_a2`
    /// settles at, C: the fixed point of the model above with both
    /// derivatives zero, `T = T_a + i^2 R(T) (R_wh + R_ha)`, linear in `T`
    /// because `R(T)` is. `None` where there is none: the heat grows with
    /// the temperature faster than the motor sheds it (thermal runaway,
    /// `i^2 R_25 a (R_wh + R_ha) >= 1`), or the input is not a finite
    /// square.
    pub fn steady_winding_c(&self, mean_i2_a2: f32) -> Option<f32> {
        if !(0.0..f32::INFINITY).contains(&mean_i2_a2) {
            return None;
        }
        let r_th = self.winding_to_housing_k_per_w + self.housing_to_ambient_k_per_w;
        let gain = mean_i2_a2 * self.winding_resistance_ohm * r_th;
        let slope = gain * COPPER_TEMPCO_PER_K;
        if slope >= 1.0 {
            return None;
        }
        let t = (self.ambient_c + gain * (1.0 - 25.0 * COPPER_TEMPCO_PER_K)) / (1.0 - slope);
        t.is_finite().then_some(t)
    }
}

/// The winding and housing temperatures and the current limit they allow.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MotorThermal {
    config: ThermalConfig,
    /// Winding temperature, C.
    winding_c: f32,
    /// Housing temperature, C.
    housing_c: f32,
    /// `i^2 dt` not yet integrated, A^2 s.
    heat_a2s: f32,
    /// Time not yet integrated, s.
    pending_s: f32,
    /// What the last steps added to each temperature below its `f32`
    /// resolution, C (compensated summation: near steady a 10 ms step of
    /// the housing is below half an ulp of its temperature, and without
    /// this the estimate stops short of the model's fixed point, cold).
    winding_carry_c: f32,
    /// The same for the housing, C.
    housing_carry_c: f32,
    /// The current limit's fraction now (1 below the derating band).
    limit_scale: f32,
}

/// `*sum += x` with `*carry` holding what `f32` could not (Kahan's
/// compensated summation).
fn add_compensated(sum: &mut f32, carry: &mut f32, x: f32) {
    let y = x - *carry;
    let t = *sum + y;
    *carry = (t - *sum) - y;
    *sum = t;
}

impl MotorThermal {
    /// A motor at the ambient temperature, once `config` validates.
    pub fn new(config: ThermalConfig) -> Result<Self, InvalidField> {
        config.validate()?;
        Ok(Self {
            config,
            winding_c: config.ambient_c,
            housing_c: config.ambient_c,
            heat_a2s: 0.0,
            pending_s: 0.0,
            winding_carry_c: 0.0,
            housing_carry_c: 0.0,
            limit_scale: 1.0,
        })
    }

    /// The configuration.
    pub const fn config(&self) -> &ThermalConfig {
        &self.config
    }

    /// The winding's resistance at the estimated temperature, ohm.
    pub fn winding_resistance_ohm(&self) -> f32 {
        self.config.resistance_at_ohm(self.winding_c())
    }

    /// Winding temperature, C.
    pub const fn winding_c(&self) -> f32 {
        self.winding_c
    }

    /// Housing temperature, C.
    pub const fn housing_c(&self) -> f32 {
        self.housing_c
    }

    /// The fraction of the amplifier's current limit allowed now.
    pub const fn limit_scale(&self) -> f32 {
        self.limit_scale
    }

    /// Whether the winding is at or above the trip temperature, with the
    /// protection on.
    pub fn tripped(&self) -> bool {
        // A NaN temperature (it cannot come from validated data and finite
        // currents, but fail safe) counts as tripped.
        self.config.protect
            && (self.winding_c >= self.config.trip_winding_c || self.winding_c.is_nan())
    }

    /// Whether the winding has cooled below the derating band (an
    /// overtemperature fault may then be reset).
    pub fn cool(&self) -> bool {
        self.winding_c < self.config.derate_winding_c
    }

    /// After a warm reset (not a power-on: a watchdog, the reset pin, a
    /// debugger) the motor may still be hot from before: take the winding
    /// at the derating temperature and the housing at its steady-state
    /// share of that rise (`R_ha / (R_wh + R_ha)`), so the estimate errs
    /// hot. It then cools as the model says.
    pub fn assume_warm(&mut self) {
        let c = &self.config;
        let rise = c.derate_winding_c - c.ambient_c;
        let share = c.housing_to_ambient_k_per_w
            / (c.winding_to_housing_k_per_w + c.housing_to_ambient_k_per_w);
        self.winding_c = crate::num::max(self.winding_c, c.derate_winding_c);
        self.housing_c = crate::num::max(self.housing_c, c.ambient_c + rise * share);
        self.winding_carry_c = 0.0;
        self.housing_carry_c = 0.0;
        self.update_limit();
    }

    /// Carries the temperatures of `old` over (a rebuilt configuration
    /// does not cool the motor).
    pub fn continue_from(&mut self, old: &MotorThermal) {
        self.winding_c = old.winding_c;
        self.housing_c = old.housing_c;
        self.heat_a2s = old.heat_a2s;
        self.pending_s = old.pending_s;
        self.winding_carry_c = old.winding_carry_c;
        self.housing_carry_c = old.housing_carry_c;
        self.update_limit();
    }

    /// One period of `dt_s` in which the amplifier was told to drive
    /// `current_a` (0 when disabled). A non-finite current counts as the
    /// largest finite one (it heats; a non-finite `dt_s` adds nothing).
    #[inline]
    pub fn add(&mut self, current_a: f32, dt_s: f32) {
        if !(dt_s > 0.0 && dt_s < f32::INFINITY) {
            return;
        }
        let i2 = current_a * current_a;
        let i2 = if i2 < f32::INFINITY { i2 } else { f32::MAX };
        self.heat_a2s += i2 * dt_s;
        self.pending_s += dt_s;
        if self.pending_s >= THERMAL_STEP_S {
            self.integrate();
        }
    }

    /// Advances both temperatures over the pending time (forward Euler:
    /// 10 ms against a 41.6 s winding time constant).
    fn integrate(&mut self) {
        let c = &self.config;
        let h = self.pending_s;
        let mean_i2 = self.heat_a2s / h;
        let power_w = mean_i2 * c.resistance_at_ohm(self.winding_c);
        let to_housing_w = (self.winding_c - self.housing_c) / c.winding_to_housing_k_per_w;
        let to_ambient_w = (self.housing_c - c.ambient_c) / c.housing_to_ambient_k_per_w;
        // C = tau / R_th: dT = dt (P_in - P_out) R_th / tau.
        add_compensated(
            &mut self.winding_c,
            &mut self.winding_carry_c,
            h * (power_w - to_housing_w) * c.winding_to_housing_k_per_w / c.winding_time_constant_s,
        );
        add_compensated(
            &mut self.housing_c,
            &mut self.housing_carry_c,
            h * (to_housing_w - to_ambient_w) * c.housing_to_ambient_k_per_w
                / c.housing_time_constant_s,
        );
        // An overflow (an absurd current for minutes) stays hot, not NaN.
        if !self.winding_c.is_finite() {
            self.winding_c = f32::MAX;
            self.winding_carry_c = 0.0;
        }
        if !self.housing_c.is_finite() {
            self.housing_c = f32::MAX;
            self.housing_carry_c = 0.0;
        }
        if !self.winding_carry_c.is_finite() {
            self.winding_carry_c = 0.0;
        }
        if !self.housing_carry_c.is_finite() {
            self.housing_carry_c = 0.0;
        }
        self.heat_a2s = 0.0;
        self.pending_s = 0.0;
        self.update_limit();
    }

    fn update_limit(&mut self) {
        let c = &self.config;
        if !c.protect {
            self.limit_scale = 1.0;
            return;
        }
        let over = (self.winding_c - c.derate_winding_c) / (c.trip_winding_c - c.derate_winding_c);
        let over = crate::num::clamp(over, 0.0, 1.0);
        // NaN (not reachable: the temperatures stay finite) fails safe to
        // the derated limit.
        self.limit_scale = if over.is_nan() {
            c.derated_limit_fraction
        } else {
            1.0 - over * (1.0 - c.derated_limit_fraction)
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Seconds of constant `current_a` until the fault would latch.
    fn trip_time_s(current_a: f32) -> Option<f32> {
        let mut m = MotorThermal::new(ThermalConfig::default()).unwrap_or_else(|e| panic!("{e:?}"));
        let dt = 1.0e-4;
        for n in 0..10_000_000u32 {
            m.add(current_a, dt);
            if m.tripped() {
                return Some(n as f32 * dt);
            }
        }
        None
    }

    #[test]
    fn trip_times_are_the_documented_ones() {
        // The module docs' table (the model integrated in f64 at 10 ms).
        for (i, t) in [
            (10.0, 392.0),
            (15.0, 52.6),
            (20.7, 21.1),
            (25.3, 13.1),
            (28.8, 9.8),
            (32.0, 7.8),
            (33.67, 7.0),
        ] {
            let got = trip_time_s(i).unwrap_or(f32::NAN);
            assert!(
                (got - t).abs() < 0.02 * t,
                "{i} A: {got} s, documented {t} s"
            );
        }
    }

    #[test]
    fn continuous_current_never_trips() {
        // 6.5 A settles just under the 150 C trip (6.54 A reaches it).
        let mut m = MotorThermal::new(ThermalConfig::default()).unwrap_or_else(|e| panic!("{e:?}"));
        for _ in 0..(20_000.0 / THERMAL_STEP_S) as u32 {
            m.add(6.5, THERMAL_STEP_S);
        }
        assert!(!m.tripped(), "{} C", m.winding_c());
        assert!(m.winding_c() > 140.0, "{} C", m.winding_c());
    }

    #[test]
    fn the_steady_temperature_is_where_the_model_settles() {
        let cfg = ThermalConfig {
            protect: false,
            ..ThermalConfig::default()
        };
        for i in [0.0, 3.0, 6.5, 9.0] {
            let mut m = MotorThermal::new(cfg).unwrap_or_else(|e| panic!("{e:?}"));
            for _ in 0..(30_000.0 / THERMAL_STEP_S) as u32 {
                m.add(i, THERMAL_STEP_S);
            }
            let want = cfg.steady_winding_c(i * i).unwrap_or(f32::NAN);
            // Near steady a 10 ms step of the housing (1,120 s) is below
            // half an f32 ulp of its temperature: only the compensated sum
            // gets there (without it 0.8 C short at 6.5 A, 148 C).
            let rise = want - cfg.ambient_c;
            assert!(
                (m.winding_c() - want).abs() <= 1e-3 * rise,
                "{i} A: settled at {} C, predicted {want} C",
                m.winding_c()
            );
        }
        // The continuous rating settles at the trip temperature: 6.54 A.
        let c = cfg.continuous_current_a();
        assert!((c - 6.535).abs() < 0.005, "{c}");
        let at = cfg.steady_winding_c(c * c).unwrap_or(f32::NAN);
        assert!((at - cfg.trip_winding_c).abs() < 0.01, "{at}");
        // Above 1 / sqrt(R_25 a (R_wh + R_ha)) = 11.4 A the heat outgrows
        // what the motor sheds: no steady temperature.
        assert!(cfg.steady_winding_c(11.3 * 11.3).is_some());
        assert_eq!(cfg.steady_winding_c(11.5 * 11.5), None);
        assert_eq!(cfg.steady_winding_c(f32::NAN), None);
        assert_eq!(cfg.steady_winding_c(-1.0), None);
    }

    #[test]
    fn derates_linearly_then_cools_back() {
        let cfg = ThermalConfig::default();
        let mut m = MotorThermal::new(cfg).unwrap_or_else(|e| panic!("{e:?}"));
        assert_eq!(m.limit_scale(), 1.0);
        while m.winding_c() < 0.5 * (cfg.derate_winding_c + cfg.trip_winding_c) {
            m.add(33.67, 1.0e-3);
        }
        let mid = 1.0 - 0.5 * (1.0 - cfg.derated_limit_fraction);
        assert!((m.limit_scale() - mid).abs() < 0.02, "{}", m.limit_scale());
        assert!(!m.cool());
        // Off: the winding cools toward the housing.
        let mut t = 0.0;
        while !m.cool() {
            m.add(0.0, 0.01);
            t += 0.01;
        }
        assert_eq!(m.limit_scale(), 1.0);
        assert!(t > 1.0 && t < 60.0, "{t} s");
    }

    #[test]
    fn after_a_warm_reset_it_starts_at_the_derating_and_cools() {
        let cfg = ThermalConfig::default();
        let mut m = MotorThermal::new(cfg).unwrap_or_else(|e| panic!("{e:?}"));
        m.assume_warm();
        assert_eq!(m.winding_c(), cfg.derate_winding_c);
        // 25 + 110 x 4.65 / 6.58 = 102.7 C.
        assert!((m.housing_c() - 102.73).abs() < 0.05, "{}", m.housing_c());
        assert_eq!(m.limit_scale(), 1.0);
        // Off for 60 s: the winding falls toward the (slowly cooling) housing.
        for _ in 0..6000 {
            m.add(0.0, THERMAL_STEP_S);
        }
        assert!(m.winding_c() < 110.0 && m.winding_c() > m.housing_c());
    }

    #[test]
    fn unprotected_estimates_but_never_derates_or_trips() {
        let cfg = ThermalConfig {
            protect: false,
            ..ThermalConfig::default()
        };
        let mut m = MotorThermal::new(cfg).unwrap_or_else(|e| panic!("{e:?}"));
        for _ in 0..2000 {
            m.add(33.67, THERMAL_STEP_S);
        }
        assert!(m.winding_c() > 160.0, "{}", m.winding_c());
        assert!(!m.tripped());
        assert_eq!(m.limit_scale(), 1.0);
    }

    #[test]
    fn bad_configs_are_refused_by_name() {
        let bad = |f: fn(&mut ThermalConfig)| {
            let mut c = ThermalConfig::default();
            f(&mut c);
            MotorThermal::new(c).err()
        };
        assert_eq!(
            bad(|c| c.winding_resistance_ohm = f32::NAN),
            Some(InvalidField("thermal.winding_resistance_ohm"))
        );
        assert_eq!(
            bad(|c| c.trip_winding_c = c.derate_winding_c),
            Some(InvalidField("thermal.trip_winding_c"))
        );
        assert_eq!(
            bad(|c| c.derate_winding_c = c.ambient_c),
            Some(InvalidField("thermal.derate_winding_c"))
        );
    }

    #[test]
    fn absurd_inputs_stay_finite_and_hot() {
        let mut m = MotorThermal::new(ThermalConfig::default()).unwrap_or_else(|e| panic!("{e:?}"));
        for x in [f32::NAN, f32::INFINITY, 1.0e30, -1.0e30] {
            m.add(x, THERMAL_STEP_S);
            assert!(m.tripped());
            assert!(m.limit_scale().is_finite() && m.limit_scale() > 0.0);
        }
        m.add(0.0, f32::NAN);
        assert!(m.tripped());
    }
}
