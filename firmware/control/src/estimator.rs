//! Phase estimator: flight/stance with hysteresis and debounce, plus the
//! touchdown, liftoff, apex and bottom events, and the filtered velocities.
//!
//! Contact evidence uses two independent sensors that must agree:
//! - the load cell's *excess* force `F - k (delta0 + p)`: in flight the lower
//!   leg rests on its stop and the load cell reads the spring force the stop
//!   carries, `k (delta0 + p)` (55 N at `p = 0` with the design preload, up to
//!   605 N with the nut at the bottom), so the raw force is no contact signal;
//!   the excess is `k (l0 - z)` in stance and 0 in flight;
//! - the leg potentiometer's compression `l0 - z` (0 in flight).
//!
//! Touchdown needs both above their *enter* thresholds, liftoff both below
//! their lower *exit* thresholds (hysteresis), each for `debounce_samples`
//! consecutive samples (debounce). Touchdown and liftoff therefore strictly
//! alternate, whatever the input.
//!
//! Those thresholds make the sensor evidence late: at 1 m/s the 40 N and
//! 2 mm take 3.5-4.5 ms of compression to build, and against the 426 kg of
//! reflected rotor inertia the nut's travel grows with the square of the
//! time it is driven, so a stance law switched on that late loses about
//! 1 J per hop. So the events are *predicted* from the height encoder
//! (`predict_contact`): touchdown and liftoff are both the body coordinate
//! crossing `l0` (MODEL.md's transitions), so with the filtered body
//! velocity `v` the crossing falls within half a period of this sample when
//! `z - l0 + v dt / 2` has crossed 0 (descending in flight, rising in
//! stance). The event is then reported at the sample nearest the crossing:
//! within `dt / 2` plus one height count over `|v|` (63 us at 1 m/s) of it.
//! The other sensors check the prediction:
//! - a predicted liftoff waits while load cell or potentiometer still show
//!   contact above their touchdown thresholds (a ground higher than the
//!   height origin says);
//! - a predicted touchdown must be confirmed, both above their touchdown
//!   thresholds, within `contact_confirm_s`; if it is not (a ground lower
//!   than the origin says, the robot held up, or the toe resting on the
//!   ground with the leg on its extension stop), it is withdrawn with a
//!   liftoff event and counted ([`PhaseEstimator::withdrawn_touchdowns`]);
//! - in stance the potentiometer measures what the height encoder does,
//!   `l0 - z`. When they disagree by more than the pot's contact threshold
//!   at a withdrawal or at a touchdown the sensors found, the height origin
//!   is off and prediction stops until they agree again at such a touchdown.
//!
//! The sensor evidence with its debounce still changes the phase when it
//! comes first (or when the height encoder says the leg is compressed by
//! more than the pot's contact threshold while the sensors say "free"), so
//! a wrong height origin costs timing, not the hop. With the leg on its
//! extension stop and the toe on the ground (the nut holding the body up)
//! no sensor can see the contact: such sub-millimetre hops are not events.
//!
//! Velocities come from the filtered derivative of eq 4.1
//! ([`FilteredDerivative`]) of the body height and motor angle. Apex: in
//! flight, once the filtered body velocity has exceeded `+apex_arm_velocity`,
//! the first sample with velocity `<= 0` reports the apex, at most once per
//! flight; its height is the peak body height seen since liftoff (not the
//! lagging filtered crossing) minus `l0`. Bottom: the same in stance,
//! armed below `-bottom_arm_velocity`, reported at the first velocity `>= 0`.

use crate::filter::{FilterError, FilteredDerivative};
use crate::model::{ModelError, ModelParams};

/// Contact phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Phase {
    /// Toe off the ground.
    Flight,
    /// Toe on the ground.
    Stance,
}

/// Events reported by [`PhaseEstimator::update`].
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PhaseEvent {
    /// Flight -> stance.
    Touchdown,
    /// Stance -> flight.
    Liftoff,
    /// Top of a flight (after a liftoff); toe height of the peak, m.
    Apex {
        /// Peak toe height above the ground, `max z - l0` since liftoff, m (>= 0).
        toe_height_m: f32,
    },
    /// Maximum leg compression in stance (body velocity turning upward): `t1` of eqs 2.49-2.50.
    Bottom,
}

/// One sample of the sensors the estimator uses.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PhaseInput {
    /// Body height coordinate `z`, m (`l0` at touchdown).
    pub body_height_m: f32,
    /// Motor angle `theta`, rad (`p = r theta`; 0 at the nut's upper stop).
    pub motor_angle_rad: f32,
    /// Load-cell spring force, N (compression positive).
    pub spring_force_n: f32,
    /// Leg potentiometer compression `l0 - z`, m (0 in flight).
    pub leg_compression_m: f32,
}

/// Filtered velocities (eq 4.1).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Velocities {
    /// Body velocity `zd`, m/s, up positive.
    pub body_mps: f32,
    /// Motor rate `theta dot`, rad/s.
    pub motor_rad_s: f32,
}

crate::param::config! {
    /// Estimator tuning.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct EstimatorConfig;
    params {
        /// Must exceed `liftoff_force_n`. The default is 8 sigma of 5 N of noise.
        42 EST_TOUCHDOWN_FORCE_N touchdown_force_n: f32 {
            "estimator.touchdown_force_n", "N", Real, [0.0, 1.0e4], 40.0, DISARMED,
            "Load-cell force beyond k (delta0 + p) that counts as touchdown evidence (8 sigma of 5 N)."
        }
        43 EST_LIFTOFF_FORCE_N liftoff_force_n: f32 {
            "estimator.liftoff_force_n", "N", Real, [-1.0e4, 1.0e4], 20.0, DISARMED,
            "Excess force below which liftoff is considered (below the touchdown force)."
        }
        /// Must exceed `liftoff_compression_m`.
        44 EST_TOUCHDOWN_COMPRESSION_M touchdown_compression_m: f32 {
            "estimator.touchdown_compression_m", "m", Real, [0.0, 0.5], 0.002, DISARMED,
            "Potentiometer compression above which touchdown is considered."
        }
        45 EST_LIFTOFF_COMPRESSION_M liftoff_compression_m: f32 {
            "estimator.liftoff_compression_m", "m", Real, [-0.5, 0.5], 0.001, DISARMED,
            "Potentiometer compression below which liftoff is considered (below the touchdown compression)."
        }
        46 EST_DEBOUNCE_SAMPLES debounce_samples: u8 {
            "estimator.debounce_samples", "samples", Count, [1.0, 255.0], 3.0, DISARMED,
            "Consecutive agreeing samples needed to change phase."
        }
        47 EST_FILTER_GAIN velocity_filter_gain: f32 {
            "estimator.velocity_filter_gain", "1", Real, [0.0, 0.999], 0.9, DISARMED,
            "Filter gain G of eq 4.1 for both velocities."
        }
        48 EST_APEX_ARM_MPS apex_arm_velocity_mps: f32 {
            "estimator.apex_arm_velocity_mps", "m/s", Real, [1.0e-4, 10.0], 0.1, DISARMED,
            "Upward body velocity that arms apex detection in flight."
        }
        49 EST_BOTTOM_ARM_MPS bottom_arm_velocity_mps: f32 {
            "estimator.bottom_arm_velocity_mps", "m/s", Real, [1.0e-4, 10.0], 0.1, DISARMED,
            "Downward body speed that arms bottom detection in stance."
        }
        /// The module doc describes the prediction.
        50 EST_PREDICT_CONTACT predict_contact: bool {
            "estimator.predict_contact", "-", Flag, [0.0, 1.0], 1.0, DISARMED,
            "Predict touchdown and liftoff from the height encoder (the toe reaching the ground within half a period); load cell and potentiometer confirm (0: those two alone, late by their thresholds)."
        }
        /// The default allows for the touchdown thresholds: the 40 N and 2 mm take 9 ms at
        /// a 1 cm hop's 0.44 m/s.
        51 EST_CONTACT_CONFIRM_S contact_confirm_s: f32 {
            "estimator.contact_confirm_s", "s", Real, [1.0e-3, 1.0], 0.03, DISARMED,
            "Time within which load cell and potentiometer must confirm a predicted touchdown; else it is withdrawn (a liftoff) and prediction stays off."
        }
    }
}

/// Why a [`PhaseEstimator`] could not be built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EstimatorError {
    /// Force thresholds non-finite or not `touchdown_force_n > liftoff_force_n`.
    ForceThresholds,
    /// Compression thresholds non-finite or not `touchdown > liftoff`.
    CompressionThresholds,
    /// `debounce_samples` is 0.
    Debounce,
    /// `velocity_filter_gain` outside [0, 1).
    FilterGain(FilterError),
    /// An arming velocity is not a finite positive number.
    ArmVelocity,
    /// `contact_confirm_s` is not a finite positive number.
    ConfirmTime,
    /// The model parameters are invalid.
    Model(ModelError),
}

/// Flight/stance estimator with event detection. See the module doc.
#[derive(Debug, Clone, PartialEq)]
pub struct PhaseEstimator {
    cfg: EstimatorConfig,
    stiffness_n_per_m: f32,
    preload_m: f32,
    screw_m_per_rad: f32,
    leg_length_m: f32,
    phase: Phase,
    pending: u8,
    body_filter: FilteredDerivative,
    motor_filter: FilteredDerivative,
    extremum_armed: bool,
    extremum_done: bool,
    peak_height_m: f32,
    last_apex_m: Option<f32>,
    rejected_samples: u32,
    /// Prediction is on (configured, and no touchdown withdrawn since).
    predicting: bool,
    /// A predicted touchdown awaits the sensors' confirmation.
    unconfirmed: bool,
    /// Time since that touchdown, s.
    unconfirmed_s: f32,
    /// The height encoder has put the toe above the ground in this flight:
    /// only then may a touchdown be predicted (after a liftoff the sensors
    /// decided with the body still below `l0`, the height would predict
    /// the same stance's touchdown again).
    toe_cleared: bool,
    withdrawn_touchdowns: u32,
}

impl PhaseEstimator {
    /// Builds an estimator that starts in [`Phase::Flight`].
    pub fn new(cfg: EstimatorConfig, model: &ModelParams) -> Result<Self, EstimatorError> {
        model.validate().map_err(EstimatorError::Model)?;
        if !(cfg.touchdown_force_n > cfg.liftoff_force_n
            && cfg.touchdown_force_n.is_finite()
            && cfg.liftoff_force_n.is_finite())
        {
            return Err(EstimatorError::ForceThresholds);
        }
        if !(cfg.touchdown_compression_m > cfg.liftoff_compression_m
            && cfg.touchdown_compression_m.is_finite()
            && cfg.liftoff_compression_m.is_finite())
        {
            return Err(EstimatorError::CompressionThresholds);
        }
        if cfg.debounce_samples == 0 {
            return Err(EstimatorError::Debounce);
        }
        let arm_ok = |v: f32| v > 0.0 && v.is_finite();
        if !(arm_ok(cfg.apex_arm_velocity_mps) && arm_ok(cfg.bottom_arm_velocity_mps)) {
            return Err(EstimatorError::ArmVelocity);
        }
        if !(cfg.contact_confirm_s > 0.0 && cfg.contact_confirm_s < f32::INFINITY) {
            return Err(EstimatorError::ConfirmTime);
        }
        let filter = FilteredDerivative::new(cfg.velocity_filter_gain)
            .map_err(EstimatorError::FilterGain)?;
        Ok(Self {
            cfg,
            stiffness_n_per_m: model.spring_stiffness_n_per_m,
            preload_m: model.preload_m,
            screw_m_per_rad: model.screw_m_per_rad(),
            leg_length_m: model.leg_length_m,
            phase: Phase::Flight,
            pending: 0,
            body_filter: filter,
            motor_filter: filter,
            extremum_armed: false,
            extremum_done: false,
            peak_height_m: f32::NEG_INFINITY,
            last_apex_m: None,
            rejected_samples: 0,
            predicting: cfg.predict_contact,
            unconfirmed: false,
            unconfirmed_s: 0.0,
            toe_cleared: false,
            withdrawn_touchdowns: 0,
        })
    }

    /// The current phase estimate.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// Forces the phase (e.g. at start-up standing on the ground) and clears the
    /// debounce and event state; the velocity filters are kept. Prediction
    /// is on again if configured (a new start, e.g. after recalibration).
    pub fn set_phase(&mut self, phase: Phase) {
        self.change_phase(phase);
        self.predicting = self.cfg.predict_contact;
    }

    /// Touchdowns predicted from the height encoder that load cell and
    /// potentiometer did not confirm in time (each withdrawn with a liftoff).
    pub fn withdrawn_touchdowns(&self) -> u32 {
        self.withdrawn_touchdowns
    }

    /// Whether touchdown and liftoff are predicted from the height encoder
    /// (configured, and no touchdown withdrawn since the last [`set_phase`](Self::set_phase)).
    pub fn predicting(&self) -> bool {
        self.predicting
    }

    fn change_phase(&mut self, phase: Phase) {
        self.phase = phase;
        self.unconfirmed = false;
        self.unconfirmed_s = 0.0;
        self.toe_cleared = false;
        self.reset_phase_state();
    }

    /// The latest filtered velocities (eq 4.1).
    pub fn velocities(&self) -> Velocities {
        Velocities {
            body_mps: self.body_filter.value(),
            motor_rad_s: self.motor_filter.value(),
        }
    }

    /// Toe height of the last reported apex, m (`None` before the first).
    pub fn last_apex_m(&self) -> Option<f32> {
        self.last_apex_m
    }

    /// Toe height of the highest point of the present flight so far, m
    /// (`None` in stance, before a sample, or with the toe never above the
    /// ground). Once the body descends this is the flight's apex, also for
    /// the first flight after a release from rest, which has no apex event.
    #[inline]
    pub fn flight_peak_toe_m(&self) -> Option<f32> {
        // A plain comparison (-inf and NaN fail it): `f32::max` is a library
        // call on the M4F, and this runs every flight period.
        let toe_m = self.peak_height_m - self.leg_length_m;
        (self.phase == Phase::Flight && toe_m > 0.0).then_some(toe_m)
    }

    /// Samples ignored because an input or `dt_s` was non-finite/non-positive.
    pub fn rejected_samples(&self) -> u32 {
        self.rejected_samples
    }

    fn reset_phase_state(&mut self) {
        self.pending = 0;
        self.extremum_armed = false;
        self.extremum_done = false;
        self.peak_height_m = f32::NEG_INFINITY;
    }

    /// Feeds one sample taken `dt_s` seconds after the previous and returns
    /// the event it completes, if any (at most one per sample; a phase change
    /// takes precedence). A sample with a non-finite value or a non-positive
    /// `dt_s` is ignored entirely (counted in [`rejected_samples`](Self::rejected_samples)).
    pub fn update(&mut self, m: &PhaseInput, dt_s: f32) -> Option<PhaseEvent> {
        // One sum, one test: NaN and infinities propagate (finite values whose
        // sum overflows are rejected too, the safe side).
        let finite = (m.body_height_m + m.motor_angle_rad + m.spring_force_n + m.leg_compression_m)
            .is_finite();
        if !finite {
            self.rejected_samples = self.rejected_samples.saturating_add(1);
            return None;
        }
        // NaN fails `dt_s > 0.0`; +inf fails `dt_s < f32::INFINITY`.
        if !(dt_s > 0.0 && dt_s < f32::INFINITY) {
            self.rejected_samples = self.rejected_samples.saturating_add(1);
            return None;
        }
        // Update both filters or neither.
        let (Some(body_v), Some(motor_v)) = (
            self.body_filter.peek(m.body_height_m, dt_s),
            self.motor_filter.peek(m.motor_angle_rad, dt_s),
        ) else {
            self.rejected_samples = self.rejected_samples.saturating_add(1);
            return None;
        };
        self.body_filter.commit(m.body_height_m, body_v);
        self.motor_filter.commit(m.motor_angle_rad, motor_v);

        let nut_m = self.screw_m_per_rad * m.motor_angle_rad;
        let excess_n = m.spring_force_n - self.stiffness_n_per_m * (self.preload_m + nut_m);
        let c = &self.cfg;
        let force_contact = excess_n >= c.touchdown_force_n;
        let pot_contact = m.leg_compression_m >= c.touchdown_compression_m;
        // The toe's height above the ground half a period from now (eq 4.1
        // velocity; in stance the negative leg compression).
        let toe_m = m.body_height_m - self.leg_length_m;
        let toe_ahead_m = toe_m + 0.5 * dt_s * body_v;
        self.toe_cleared |= self.phase == Phase::Flight && toe_m > 0.0;
        let slightly_compressed = toe_ahead_m < 0.0 && toe_ahead_m >= -c.touchdown_compression_m;
        let height_holds_stance = self.predicting && slightly_compressed;
        let (evidence, predicted) = match self.phase {
            Phase::Flight => (
                force_contact && pot_contact,
                self.predicting && self.toe_cleared && body_v < 0.0 && toe_ahead_m <= 0.0,
            ),
            // Not before a predicted touchdown is confirmed: at the ground
            // the sensors still read "free".
            // And, when predicting, not while the height encoder says the
            // leg is still compressed, unless by more than the pot's own
            // contact threshold (then the height origin is off): the
            // sensors read "free" about a millimetre early.
            Phase::Stance => (
                !self.unconfirmed
                    && !height_holds_stance
                    && excess_n <= c.liftoff_force_n
                    && m.leg_compression_m <= c.liftoff_compression_m,
                self.predicting
                    && body_v > 0.0
                    && toe_ahead_m >= 0.0
                    && !(force_contact || pot_contact),
            ),
        };
        self.pending = if evidence {
            self.pending.saturating_add(1)
        } else {
            0
        };
        // In stance the potentiometer measures what the height encoder
        // does, `l0 - z`: agreement within the pot's contact threshold
        // says the height origin is right.
        // Only needed at a phase change or a withdrawal: not every period.
        let origin_agrees = || {
            let height_compression_m = crate::num::max(-toe_m, 0.0);
            (height_compression_m - m.leg_compression_m).abs() <= c.touchdown_compression_m
        };
        if predicted || self.pending >= c.debounce_samples {
            let confirmed = force_contact && pot_contact;
            if !predicted && self.phase == Phase::Flight && self.cfg.predict_contact {
                // A touchdown the sensors found: prediction resumes if the
                // height encoder agrees with the potentiometer.
                self.predicting = origin_agrees();
            }
            let (next, event) = match self.phase {
                Phase::Flight => (Phase::Stance, PhaseEvent::Touchdown),
                Phase::Stance => (Phase::Flight, PhaseEvent::Liftoff),
            };
            self.change_phase(next);
            self.unconfirmed = next == Phase::Stance && !confirmed;
            return Some(event);
        }
        if self.unconfirmed {
            if force_contact && pot_contact {
                self.unconfirmed = false;
            } else {
                self.unconfirmed_s += dt_s;
                if self.unconfirmed_s > self.cfg.contact_confirm_s {
                    // No load: withdraw the touchdown. If the height encoder
                    // says the leg is compressed and the potentiometer does
                    // not, its origin is off: the sensors alone decide
                    // until they agree again (otherwise the toe only rests
                    // on the ground with the leg at its stop).
                    self.withdrawn_touchdowns = self.withdrawn_touchdowns.saturating_add(1);
                    self.predicting = origin_agrees();
                    self.change_phase(Phase::Flight);
                    return Some(PhaseEvent::Liftoff);
                }
            }
        }

        match self.phase {
            Phase::Flight => {
                // A plain comparison: `f32::max` is a library call on the
                // M4F (the height is finite here).
                if m.body_height_m > self.peak_height_m {
                    self.peak_height_m = m.body_height_m;
                }
                if self.extremum_done {
                    return None;
                }
                if body_v >= self.cfg.apex_arm_velocity_mps {
                    self.extremum_armed = true;
                }
                if self.extremum_armed && body_v <= 0.0 {
                    self.extremum_done = true;
                    let toe_height_m = crate::num::max(self.peak_height_m - self.leg_length_m, 0.0);
                    self.last_apex_m = Some(toe_height_m);
                    return Some(PhaseEvent::Apex { toe_height_m });
                }
            }
            Phase::Stance => {
                if self.extremum_done {
                    return None;
                }
                if body_v <= -self.cfg.bottom_arm_velocity_mps {
                    self.extremum_armed = true;
                }
                if self.extremum_armed && body_v >= 0.0 {
                    self.extremum_done = true;
                    return Some(PhaseEvent::Bottom);
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    const L0: f32 = 0.61;
    const K: f32 = 11_000.0;
    const D0: f32 = crate::model::design::SPRING_PRELOAD_M as f32;
    const G: f32 = 9.81;

    /// Tiny deterministic LCG (Knuth MMIX constants).
    struct Lcg(u64);
    impl Lcg {
        fn uniform(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            ((self.0 >> 40) as f32) / ((1_u64 << 24) as f32)
        }
        /// Approximately normal, unit variance (sum of 12 uniforms).
        fn normal(&mut self) -> f32 {
            (0..12).map(|_| self.uniform()).sum::<f32>() - 6.0
        }
    }

    /// Noise-free synthetic hop trajectory: (z, p, compression) at time t.
    /// Segments: descent from `apex[i]`, sinusoidal stance (100 ms), ascent to `apex[i+1]`.
    fn trajectory(apexes: &[f32], dt: f32) -> Vec<(f32, f32, f32)> {
        let mut out = Vec::new();
        let stance_s = 0.1_f32;
        let mut push = |z: f32, p: f32| out.push((z, p, (L0 - z).max(0.0)));
        for (i, &h) in apexes.iter().enumerate() {
            let v = libm::sqrtf(2.0 * G * h);
            // Descent from h (the last one stops short of the ground).
            let fall_s = if i + 1 == apexes.len() { 0.9 } else { 1.0 } * v / G;
            let mut t = 0.0;
            while t < fall_s {
                push(L0 + h - 0.5 * G * t * t, 0.0);
                t += dt;
            }
            if i + 1 == apexes.len() {
                break;
            }
            // Stance: half sine of compression; nut pushed down 5 mm and back.
            let v_next = libm::sqrtf(2.0 * G * apexes[i + 1]);
            let amp = 0.5 * (v + v_next) * stance_s / core::f32::consts::PI;
            let mut t = 0.0;
            while t < stance_s {
                let s = libm::sinf(core::f32::consts::PI * t / stance_s);
                push(L0 - amp * s, 0.005 * s);
                t += dt;
            }
            // Ascent to the next apex.
            let mut t = 0.0;
            while t < v_next / G {
                push(L0 + v_next * t - 0.5 * G * t * t, 0.0);
                t += dt;
            }
        }
        out
    }

    #[test]
    fn flight_peak_is_the_release_height_then_each_apex() -> Result<(), EstimatorError> {
        let model = ModelParams::default();
        let dt = 1e-3_f32;
        let mut est = PhaseEstimator::new(EstimatorConfig::default(), &model)?;
        assert_eq!(est.flight_peak_toe_m(), None);
        // Released from rest 0.05 m up: no apex event on the way down, but
        // the flight's peak is the release height from the first sample.
        let traj = trajectory(&[0.05, 0.04], dt);
        let mut seen_stance = false;
        for &(z, p, comp) in &traj {
            let input = PhaseInput {
                body_height_m: z,
                motor_angle_rad: p / model.screw_m_per_rad(),
                spring_force_n: K * (D0 + comp + p),
                leg_compression_m: comp,
            };
            let _ = est.update(&input, dt);
            match est.phase() {
                Phase::Stance => {
                    seen_stance = true;
                    assert_eq!(est.flight_peak_toe_m(), None);
                }
                Phase::Flight if !seen_stance => {
                    let peak = est.flight_peak_toe_m().unwrap_or(0.0);
                    assert!((peak - 0.05).abs() < 1e-4, "{peak}");
                }
                Phase::Flight => {}
            }
        }
        // After the next apex, the peak is that apex.
        let peak = est.flight_peak_toe_m().unwrap_or(0.0);
        assert!(seen_stance && (peak - 0.04).abs() < 1e-3, "{peak}");
        Ok(())
    }

    #[test]
    fn one_event_of_each_kind_per_hop_under_noise() -> Result<(), EstimatorError> {
        let model = ModelParams::default();
        let r = model.screw_m_per_rad();
        let dt = 1e-3_f32;
        let apexes = [0.15, 0.12, 0.10, 0.08, 0.05, 0.03, 0.02];
        let traj = trajectory(&apexes, dt);
        for seed in [12_345_u64, 1, 987_654_321, 42] {
            let mut est = PhaseEstimator::new(EstimatorConfig::default(), &model)?;
            let mut rng = Lcg(seed);
            let count_per_rad = 2000.0 / (2.0 * core::f32::consts::PI); // 500-line quadrature
            let mut events = Vec::new();
            for &(z, p, comp) in &traj {
                let theta = p / r;
                let input = PhaseInput {
                    // Body height from an encoder with 0.1 mm resolution.
                    body_height_m: libm::roundf(z / 1e-4) * 1e-4,
                    motor_angle_rad: libm::roundf(theta * count_per_rad) / count_per_rad,
                    spring_force_n: K * (D0 + comp + p) + 5.0 * rng.normal(),
                    leg_compression_m: comp + 2e-4 * rng.normal(),
                };
                if let Some(e) = est.update(&input, dt) {
                    events.push(e);
                }
            }
            let hops = apexes.len() - 1;
            assert_eq!(events.len(), 4 * hops, "{events:?}");
            for (i, chunk) in events.chunks(4).enumerate() {
                assert_eq!(chunk[0], PhaseEvent::Touchdown);
                assert_eq!(chunk[1], PhaseEvent::Bottom);
                assert_eq!(chunk[2], PhaseEvent::Liftoff);
                let PhaseEvent::Apex { toe_height_m } = chunk[3] else {
                    panic!("expected apex, got {:?}", chunk[3]);
                };
                let want = apexes[i + 1];
                assert!(
                    (toe_height_m - want).abs() < 0.005,
                    "{toe_height_m} vs {want}"
                );
            }
            assert_eq!(est.phase(), Phase::Flight);
        }
        Ok(())
    }

    #[test]
    fn rejects_bad_config_and_bad_samples() -> Result<(), EstimatorError> {
        let model = ModelParams::default();
        let cfg = EstimatorConfig {
            liftoff_force_n: 50.0,
            ..EstimatorConfig::default()
        };
        assert_eq!(
            PhaseEstimator::new(cfg, &model).err(),
            Some(EstimatorError::ForceThresholds)
        );
        let cfg = EstimatorConfig {
            debounce_samples: 0,
            ..EstimatorConfig::default()
        };
        assert_eq!(
            PhaseEstimator::new(cfg, &model).err(),
            Some(EstimatorError::Debounce)
        );
        let mut est = PhaseEstimator::new(EstimatorConfig::default(), &model)?;
        let bad = PhaseInput {
            body_height_m: f32::NAN,
            motor_angle_rad: 0.0,
            spring_force_n: 1000.0,
            leg_compression_m: 0.05,
        };
        for _ in 0..10 {
            assert_eq!(est.update(&bad, 1e-3), None);
        }
        assert_eq!(est.rejected_samples(), 10);
        assert_eq!(est.phase(), Phase::Flight);
        Ok(())
    }

    /// Samples of the synthetic trajectory as the sensors read them
    /// (noise-free; the height on a 0.1 mm grid).
    fn inputs(traj: &[(f32, f32, f32)], model: &ModelParams) -> Vec<PhaseInput> {
        traj.iter()
            .map(|&(z, p, comp)| PhaseInput {
                body_height_m: libm::roundf(z / 1e-4) * 1e-4,
                motor_angle_rad: p / model.screw_m_per_rad(),
                spring_force_n: K * (D0 + comp + p),
                leg_compression_m: comp,
            })
            .collect()
    }

    /// Touchdown and liftoff come at the sample nearest the
    /// height's crossing of `l0` (prediction), at 1 kHz and 10 kHz; the
    /// sensors alone are many samples late at touchdown.
    #[test]
    fn contact_events_at_the_crossing_sample() -> Result<(), EstimatorError> {
        let model = ModelParams::default();
        for dt in [1e-4_f32, 1e-3] {
            let traj = trajectory(&[0.10, 0.08, 0.05, 0.03], dt);
            // The true crossings: the first sample at or below l0 after
            // flight, the first above it after stance.
            let mut crossings = Vec::new();
            let mut below = false;
            for (i, &(z, _, _)) in traj.iter().enumerate() {
                if (z <= L0) != below {
                    below = z <= L0;
                    crossings.push(i);
                }
            }
            for predict in [true, false] {
                let cfg = EstimatorConfig {
                    predict_contact: predict,
                    ..EstimatorConfig::default()
                };
                let mut est = PhaseEstimator::new(cfg, &model)?;
                let mut events = Vec::new();
                for (i, input) in inputs(&traj, &model).iter().enumerate() {
                    if let Some(e @ (PhaseEvent::Touchdown | PhaseEvent::Liftoff)) =
                        est.update(input, dt)
                    {
                        events.push((i, e));
                    }
                }
                assert_eq!(events.len(), crossings.len(), "dt {dt}: {events:?}");
                for (&(i, e), &c) in events.iter().zip(&crossings) {
                    let late = i as i64 - c as i64;
                    if predict {
                        // One sample either way: the nearest sample, with
                        // the 0.1 mm grid of the height.
                        assert!(late.abs() <= 1, "dt {dt}: {e:?} at {i}, crossing {c}");
                    } else if e == PhaseEvent::Touchdown && dt < 5e-4 {
                        // 40 N and 2 mm at about 1 m/s: 2-4 ms.
                        assert!(late >= 20, "dt {dt}: {e:?} at {i}, crossing {c}");
                    }
                }
                assert_eq!(est.withdrawn_touchdowns(), 0);
            }
        }
        Ok(())
    }

    /// A height origin that puts the ground too high (the robot
    /// held up, lowered by hand): the predicted touchdown is not confirmed
    /// and is withdrawn with a liftoff, prediction stops; a touchdown the
    /// sensors find with the height agreeing turns it back on.
    #[test]
    fn an_unconfirmed_touchdown_is_withdrawn() -> Result<(), EstimatorError> {
        let model = ModelParams::default();
        let cfg = EstimatorConfig::default();
        let mut est = PhaseEstimator::new(cfg, &model)?;
        let dt = 1e-4_f32;
        // Lowered at 0.2 m/s from 5 mm above l0 to 10 mm below it, the leg
        // unloaded (no force, no compression).
        let mut events = Vec::new();
        let mut z = L0 + 0.005;
        for k in 0..2000 {
            if z > L0 - 0.01 {
                z -= 0.2 * dt;
            }
            let input = PhaseInput {
                body_height_m: z,
                motor_angle_rad: 0.0,
                spring_force_n: K * D0,
                leg_compression_m: 0.0,
            };
            if let Some(e) = est.update(&input, dt) {
                events.push((k, e));
            }
        }
        assert_eq!(events.len(), 2, "{events:?}");
        assert_eq!(events[0].1, PhaseEvent::Touchdown);
        assert_eq!(events[1].1, PhaseEvent::Liftoff);
        // Withdrawn after the confirmation time (30 ms = 300 samples).
        let waited = events[1].0 - events[0].0;
        assert!((300..=302).contains(&waited), "{events:?}");
        assert_eq!(est.withdrawn_touchdowns(), 1);
        assert!(!est.predicting());
        assert_eq!(est.phase(), Phase::Flight);
        // Now a real touchdown: leg compressed 5 mm by the pot and the
        // height alike; the sensors decide it, and prediction resumes.
        let stance = PhaseInput {
            body_height_m: L0 - 0.005,
            motor_angle_rad: 0.0,
            spring_force_n: K * (D0 + 0.005),
            leg_compression_m: 0.005,
        };
        let mut got = None;
        for _ in 0..3 {
            got = got.or(est.update(&stance, dt));
        }
        assert_eq!(got, Some(PhaseEvent::Touchdown));
        assert!(est.predicting());
        Ok(())
    }

    mod prop {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn touchdown_and_liftoff_alternate(
                samples in proptest::collection::vec(
                    (0.0_f32..700.0, -0.002_f32..0.01, 0.55_f32..0.8), 1..600),
            ) {
                let model = ModelParams::default();
                let mut est = PhaseEstimator::new(EstimatorConfig::default(), &model)
                    .map_err(|e| TestCaseError::fail(std::format!("{e:?}")))?;
                let mut phase = Phase::Flight;
                let mut bottoms = 0;
                let mut apexes = 0;
                for (force, comp, z) in samples {
                    let input = PhaseInput {
                        body_height_m: z,
                        motor_angle_rad: 0.0,
                        spring_force_n: force,
                        leg_compression_m: comp,
                    };
                    match est.update(&input, 1e-3) {
                        Some(PhaseEvent::Touchdown) => {
                            prop_assert_eq!(phase, Phase::Flight);
                            phase = Phase::Stance;
                            bottoms = 0;
                        }
                        Some(PhaseEvent::Liftoff) => {
                            prop_assert_eq!(phase, Phase::Stance);
                            phase = Phase::Flight;
                            apexes = 0;
                        }
                        Some(PhaseEvent::Bottom) => {
                            prop_assert_eq!(phase, Phase::Stance);
                            bottoms += 1;
                            prop_assert!(bottoms <= 1);
                        }
                        Some(PhaseEvent::Apex { toe_height_m }) => {
                            prop_assert_eq!(phase, Phase::Flight);
                            prop_assert!(toe_height_m >= 0.0);
                            apexes += 1;
                            prop_assert!(apexes <= 1);
                        }
                        None => {}
                    }
                    prop_assert_eq!(est.phase(), phase);
                }
            }
        }

        /// One physical stance: samples of rise, dwell and fall of the true
        /// compression, its peak (m), and how far the nut moves (fraction of
        /// the compression, m/m).
        #[derive(Debug, Clone, Copy)]
        struct Stance {
            flight_before: usize,
            rise: usize,
            dwell: usize,
            fall: usize,
            peak_m: f32,
            nut_per_compression: f32,
        }

        /// Property 3: on noisy but plausible streams (noise below half of
        /// each hysteresis gap, isolated glitches of any size when the
        /// debounce is at least 2, peaks chattering at the thresholds, random
        /// thresholds, debounce, filter and model) the estimator reports at
        /// most one touchdown and one liftoff per physical stance, touchdown
        /// first. 10 000 cases by default ([`crate::proptest_support::cases`]).
        ///
        /// Why it must hold: touchdown needs a measured compression above
        /// `td`, so the true one above `td - n`; liftoff needs it below `lo`,
        /// so the true one below `lo + n < td - n` (`n` under half the gap).
        /// A stance's compression rises then falls, so once it has been
        /// above `td - n` and then below `lo + n`, it never rises again
        /// before the next stance. A glitch spaced a debounce from the next
        /// can fill at most one sample of a debounce window.
        #[test]
        fn at_most_one_touchdown_and_liftoff_per_stance() {
            let thresholds = (
                20.0f32..80.0,
                0.1f32..0.9,
                1e-3f32..4e-3,
                0.1f32..0.9,
                1u8..=5,
                0.0f32..0.95,
            );
            let model = (5e3f32..3e4, 0.0f32..0.01, 2e-3f32..1e-2);
            let stance = (
                0usize..12,
                1usize..12,
                0usize..12,
                1usize..12,
                0.0f32..1.0,
                0u8..3,
                0.0f32..0.5,
            );
            let strategy = (
                thresholds,
                model,
                proptest::collection::vec(stance, 1..4),
                (0.0f32..1.0, 0.0f32..0.2, any::<u64>()),
            );
            let result = crate::proptest_support::run(
                "at_most_one_touchdown_and_liftoff_per_stance",
                strategy,
                |(
                    (td_f, lo_frac_f, td_c, lo_frac_c, debounce, g),
                    (k, d0, lead),
                    stances,
                    (noise, glitch_p, seed),
                )| {
                    let cfg = EstimatorConfig {
                        touchdown_force_n: td_f,
                        liftoff_force_n: td_f * lo_frac_f,
                        touchdown_compression_m: td_c,
                        liftoff_compression_m: td_c * lo_frac_c,
                        debounce_samples: debounce,
                        velocity_filter_gain: g,
                        ..EstimatorConfig::default()
                    };
                    let model = ModelParams {
                        spring_stiffness_n_per_m: k,
                        preload_m: d0,
                        screw_lead_m: lead,
                        ..ModelParams::default()
                    };
                    let r = model.screw_m_per_rad();
                    let mut est = PhaseEstimator::new(cfg, &model)
                        .map_err(|e| TestCaseError::fail(std::format!("{e:?}")))?;
                    // Noise bounds: a fraction of half of each hysteresis gap.
                    let nf = noise * 0.5 * (cfg.touchdown_force_n - cfg.liftoff_force_n);
                    let nc =
                        noise * 0.5 * (cfg.touchdown_compression_m - cfg.liftoff_compression_m);
                    let mut rng = Lcg(seed);
                    let d = usize::from(debounce);
                    let mut since_glitch = d;
                    // (true compression, nut position, stance index or MAX in flight) per sample.
                    let mut samples: Vec<(f32, f32, usize)> = Vec::new();
                    for (i, &(fl, rise, dwell, fall, peak_u, kind, nut)) in
                        stances.iter().enumerate()
                    {
                        let st = Stance {
                            // At least a debounce of flight between stances, as
                            // any real flight has.
                            flight_before: if i == 0 { fl } else { fl + d },
                            rise,
                            dwell,
                            fall,
                            // Peaks chattering at the touchdown or liftoff
                            // compression, or clearly above.
                            peak_m: match kind {
                                0 => cfg.touchdown_compression_m + (peak_u - 0.5) * 4.0 * nc,
                                1 => cfg.liftoff_compression_m + (peak_u - 0.5) * 4.0 * nc,
                                _ => cfg.touchdown_compression_m + nc + 1e-4 + peak_u * 0.03,
                            }
                            .max(0.0),
                            nut_per_compression: nut,
                        };
                        for _ in 0..st.flight_before {
                            samples.push((0.0, 0.0, usize::MAX));
                        }
                        let up = (1..=st.rise).map(|j| st.peak_m * j as f32 / st.rise as f32);
                        let hold = core::iter::repeat_n(st.peak_m, st.dwell);
                        let down = (0..st.fall)
                            .map(|j| st.peak_m * (st.fall - 1 - j) as f32 / st.fall as f32);
                        for c in up.chain(hold).chain(down) {
                            samples.push((c, c * st.nut_per_compression, i));
                        }
                    }
                    // A debounce and one more of flight at the end: the last liftoff.
                    for _ in 0..=d {
                        samples.push((0.0, 0.0, usize::MAX));
                    }
                    let mut events: Vec<(usize, PhaseEvent)> = Vec::new();
                    for (n, &(c, p, _)) in samples.iter().enumerate() {
                        let glitch = debounce >= 2 && since_glitch >= d && rng.uniform() < glitch_p;
                        since_glitch = if glitch { 0 } else { since_glitch + 1 };
                        let (force, comp) = if glitch {
                            (rng.uniform() * 3000.0 - 500.0, rng.uniform() * 0.1 - 0.01)
                        } else {
                            (
                                k * (d0 + p + c) + nf * (2.0 * rng.uniform() - 1.0),
                                c + nc * (2.0 * rng.uniform() - 1.0),
                            )
                        };
                        let input = PhaseInput {
                            body_height_m: L0 - c,
                            motor_angle_rad: p / r,
                            spring_force_n: force,
                            leg_compression_m: comp,
                        };
                        if let Some(e @ (PhaseEvent::Touchdown | PhaseEvent::Liftoff)) =
                            est.update(&input, 1e-3)
                        {
                            events.push((n, e));
                        }
                    }
                    // Touchdown and liftoff alternate, touchdown first (a
                    // liftoff belongs to the touchdown before it); every
                    // touchdown falls in a stance's contact samples, at most
                    // one per stance. A liftoff may come late (a glitch can
                    // break the flight's debounce run), so it is counted
                    // through the alternation, not by position.
                    let mut per_stance = std::vec![0usize; stances.len()];
                    for (j, &(n, e)) in events.iter().enumerate() {
                        let want = if j % 2 == 0 {
                            PhaseEvent::Touchdown
                        } else {
                            PhaseEvent::Liftoff
                        };
                        prop_assert_eq!(e, want, "events {:?}", events);
                        if e == PhaseEvent::Touchdown {
                            let i = samples[n].2;
                            prop_assert!(
                                i < stances.len(),
                                "touchdown in flight at {}: {:?}",
                                n,
                                events
                            );
                            per_stance[i] += 1;
                            prop_assert!(per_stance[i] <= 1, "stance {}: {:?}", i, events);
                        }
                    }
                    Ok(())
                },
            );
            result.unwrap_or_else(|e| panic!("{e}"));
        }
    }
}
