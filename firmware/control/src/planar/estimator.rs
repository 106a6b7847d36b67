//! The planar estimator: what a boom-mounted planar hopper measures, made
//! into what its controllers read ([`PlanarEstimate`]).
//!
//! The sensors: the boom's two encoders give the hip's forward position
//! and height, a third the body's pitch against the boom; the hip encoder
//! gives the leg's angle against the body; the leg potentiometer its
//! length. The leg's angle from the vertical is the body's pitch plus the
//! hip's angle. Every rate is the thesis's filtered derivative (eq 4.1) of
//! its position, the forward speed the boom's. The phase is the leg's
//! compression with hysteresis, as the vertical estimator's potentiometer
//! test: stance once it is compressed beyond `touchdown_compression_m`,
//! flight once it is back below `liftoff_compression_m` (in flight the leg
//! rests on its stop, at its full length). In stance the toe's forward
//! position is the hip's plus the leg's reach, `x + l sin(theta)`.
//!
//! A reading that is not finite makes every rate it feeds NaN for that
//! period, so the guard latches ([`super::guard`]); the filters keep their
//! state, so one bad sample does not poison the periods after it.

use super::PlanarEstimate;
use crate::filter::FilteredDerivative;
use crate::param::{require, InvalidField};

/// One period's readings, SI.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlanarReadings {
    /// The hip's forward position along the boom's circle, m.
    pub boom_x_m: f32,
    /// The hip's height above the ground, m.
    pub boom_z_m: f32,
    /// The body's pitch, nose up positive, rad.
    pub pitch_rad: f32,
    /// The leg's angle against the body (toe ahead positive), rad.
    pub hip_angle_rad: f32,
    /// The leg's length, m.
    pub leg_length_m: f32,
    /// The leg motor's angle, rad (0 with its ball screw's nut on the
    /// upper stop; a machine whose leg is driven through its screw).
    pub leg_motor_rad: f32,
}

/// The estimator's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarEstimatorConfig {
    /// The leg's length on its stop, m.
    pub leg_length_m: f32,
    /// Compression beyond which the toe is down, m.
    pub touchdown_compression_m: f32,
    /// Compression below which it is up again, m (less than the
    /// touchdown's).
    pub liftoff_compression_m: f32,
    /// Eq 4.1's `G` for every rate, in `[0, 1)`.
    pub rate_filter_gain: f32,
    /// The forward speed from the leg's kinematics rather than the boom's
    /// forward encoder (a machine without one): in stance the toe stands,
    /// so the hip moves at `-(l' sin(theta) + l theta' cos(theta))`; in
    /// flight, the stance's mean, the hip's travel over the toe
    /// (`-l sin(theta)` from touchdown to liftoff) over the stance's time
    /// (the speed the neutral point needs, free of the rates' lag).
    pub speed_from_leg: bool,
}

impl PlanarEstimatorConfig {
    /// For the thesis's planar runner (a 0.65 m leg): touchdown at 1.0 mm
    /// of compression, liftoff below 0.5 mm (many steps of a 12-bit
    /// potentiometer reading), and `G = 0.95` (a lag of `G dt / (1 - G)`,
    /// 1.9 ms at 10 kHz: the boom encoder's count in one period is 1.2 m/s
    /// of finite difference, and this is the gain the runs settled on).
    pub const fn table_2_2() -> Self {
        PlanarEstimatorConfig {
            leg_length_m: super::TABLE_2_2_LEG_LENGTH_M,
            touchdown_compression_m: 1.0e-3,
            liftoff_compression_m: 0.5e-3,
            rate_filter_gain: 0.95,
            speed_from_leg: false,
        }
    }

    /// Every field in its range; else the first that is not.
    pub fn validate(&self) -> Result<(), InvalidField> {
        let pos = |v: f32| v.is_finite() && v > 0.0;
        require(pos(self.leg_length_m), "leg_length_m")?;
        require(
            pos(self.touchdown_compression_m) && self.touchdown_compression_m < self.leg_length_m,
            "touchdown_compression_m",
        )?;
        require(
            pos(self.liftoff_compression_m)
                && self.liftoff_compression_m < self.touchdown_compression_m,
            "liftoff_compression_m",
        )?;
        require(
            FilteredDerivative::new(self.rate_filter_gain).is_ok(),
            "rate_filter_gain",
        )
    }
}

/// The estimator's state: the phase and one filter per rate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlanarEstimator {
    cfg: PlanarEstimatorConfig,
    stance: bool,
    x: FilteredDerivative,
    z: FilteredDerivative,
    phi: FilteredDerivative,
    theta: FilteredDerivative,
    leg: FilteredDerivative,
    /// The hip's speed by the leg's kinematics, m/s: in stance this
    /// period's, in flight the last stance's mean.
    leg_speed_mps: f32,
    /// The hip's position over the toe at touchdown and now, m, and the
    /// stance's time so far, s.
    stance_from_m: f32,
    stance_at_m: f32,
    stance_s: f32,
}

impl PlanarEstimator {
    /// In flight, its filters unprimed, once `cfg` validates.
    pub fn new(cfg: PlanarEstimatorConfig) -> Result<Self, InvalidField> {
        cfg.validate()?;
        let f = FilteredDerivative::new(cfg.rate_filter_gain)
            .map_err(|_| InvalidField("rate_filter_gain"))?;
        Ok(PlanarEstimator {
            cfg,
            stance: false,
            x: f,
            z: f,
            phi: f,
            theta: f,
            leg: f,
            leg_speed_mps: 0.0,
            stance_from_m: 0.0,
            stance_at_m: 0.0,
            stance_s: 0.0,
        })
    }

    /// Its settings.
    pub fn config(&self) -> &PlanarEstimatorConfig {
        &self.cfg
    }

    /// The estimate from this period's readings `r`, taken `dt_s` after
    /// the last.
    pub fn update(&mut self, r: &PlanarReadings, dt_s: f32) -> PlanarEstimate {
        let theta = r.pitch_rad + r.hip_angle_rad;
        // Every reading and the period checked at once (a sum of finite
        // numbers that does not overflow is finite); a reading that fails
        // goes through the filters' own checks, and shows as a NaN rate.
        let checked = (r.boom_x_m + r.boom_z_m + theta + r.leg_length_m).is_finite()
            && dt_s > 0.0
            && dt_s.is_finite();
        let rate = |f: &mut FilteredDerivative, v: f32| {
            if checked {
                f.advance(v, dt_s)
            } else {
                f.update(v, dt_s).ok()
            }
            .unwrap_or(f32::NAN)
        };
        let x_dot = rate(&mut self.x, r.boom_x_m);
        let z_dot = rate(&mut self.z, r.boom_z_m);
        let phi_dot = rate(&mut self.phi, r.pitch_rad);
        let theta_dot = rate(&mut self.theta, theta);
        let leg_rate = rate(&mut self.leg, r.leg_length_m);
        let compression = self.cfg.leg_length_m - r.leg_length_m;
        let (sine, cosine) = leg_sine_cosine(theta);
        let over_toe_m = -r.leg_length_m * sine;
        if self.stance && compression < self.cfg.liftoff_compression_m {
            self.stance = false;
            if self.stance_s > 0.0 {
                self.leg_speed_mps = (self.stance_at_m - self.stance_from_m) / self.stance_s;
            }
        } else if !self.stance && compression > self.cfg.touchdown_compression_m {
            self.stance = true;
            self.stance_from_m = over_toe_m;
            self.stance_s = 0.0;
        } else if self.stance {
            self.stance_s += dt_s;
        }
        if self.stance {
            self.stance_at_m = over_toe_m;
            self.leg_speed_mps = -(leg_rate * sine + r.leg_length_m * theta_dot * cosine);
        }
        // A NaN compression keeps the phase; the NaN rate reports it.
        // In stance the toe stands where the leg reaches; in flight it is
        // over the ground a whole leg from the hip.
        let reach_m = if self.stance {
            r.leg_length_m
        } else {
            self.cfg.leg_length_m
        };
        PlanarEstimate {
            stance: self.stance,
            x_dot_mps: if self.cfg.speed_from_leg {
                self.leg_speed_mps
            } else {
                x_dot
            },
            z_m: r.boom_z_m,
            z_dot_mps: z_dot,
            phi_rad: r.pitch_rad,
            phi_dot_rad_s: phi_dot,
            theta_rad: theta,
            theta_dot_rad_s: theta_dot,
            // (A bad potentiometer reading shows in flight too.)
            leg_rate_mps: if self.stance || leg_rate.is_nan() {
                leg_rate
            } else {
                0.0
            },
            toe_x_m: r.boom_x_m + reach_m * sine,
        }
    }
}

/// `(sin(theta), cos(theta))` for a leg angle: their series on `[-pi/2,
/// pi/2]` (a leg beyond the horizontal is taken at it; the guard stops the
/// machine long before; both series are even or odd, so the quadrant's
/// serve its mirror). libm's `sinf` reduces in `f64`, which the
/// Cortex-M4F does in software: a thousand instructions a period.
fn leg_sine_cosine(theta: f32) -> (f32, f32) {
    const HALF_PI: f32 = core::f32::consts::FRAC_PI_2;
    // (NaN passes through the comparisons.)
    crate::laws::shaped::sin_cos_quadrant(crate::num::clamp(theta, -HALF_PI, HALF_PI))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const DT: f32 = 1.0e-4;

    fn reading(t: f32, leg_m: f32) -> PlanarReadings {
        PlanarReadings {
            boom_x_m: 0.8 * t,
            boom_z_m: 0.8 - 0.5 * t,
            pitch_rad: 0.1 + 0.2 * t,
            hip_angle_rad: -0.3 * t,
            leg_length_m: leg_m,
            leg_motor_rad: 0.0,
        }
    }

    #[test]
    fn rates_converge_to_the_motion() {
        let mut e = PlanarEstimator::new(PlanarEstimatorConfig::table_2_2()).unwrap_or_else(|f| {
            panic!("{f:?}");
        });
        let mut est = PlanarEstimate::default();
        for k in 0..200 {
            est = e.update(&reading(k as f32 * DT, 0.65), DT);
        }
        let near = |a: f32, b: f32| (a - b).abs() < 1e-3 * b.abs().max(1.0);
        assert!(near(est.x_dot_mps, 0.8), "{est:?}");
        assert!(near(est.z_dot_mps, -0.5), "{est:?}");
        assert!(near(est.phi_dot_rad_s, 0.2), "{est:?}");
        // The leg's angle is the pitch plus the hip's.
        assert!(near(est.theta_dot_rad_s, -0.1), "{est:?}");
        assert!(near(
            est.theta_rad,
            0.1 + 0.2 * 199.0 * DT - 0.3 * 199.0 * DT
        ));
        assert!(!est.stance);
        assert_eq!(est.leg_rate_mps, 0.0);
    }

    #[test]
    fn the_phase_has_hysteresis() {
        let mut e = PlanarEstimator::new(PlanarEstimatorConfig::table_2_2()).unwrap_or_else(|f| {
            panic!("{f:?}");
        });
        let phase = |e: &mut PlanarEstimator, leg: f32| e.update(&reading(0.0, leg), DT).stance;
        assert!(!phase(&mut e, 0.65));
        assert!(!phase(&mut e, 0.6495)); // 0.5 mm: not yet
        assert!(phase(&mut e, 0.6485)); // 1.5 mm: down
        assert!(phase(&mut e, 0.6493)); // 0.7 mm: still down
        assert!(!phase(&mut e, 0.6497)); // 0.3 mm: up
                                         // In stance the toe is where the leg reaches.
        let est = e.update(&reading(0.0, 0.6), DT);
        assert!(est.stance);
        let toe = 0.6 * libm::sinf(0.1);
        let (s, c) = leg_sine_cosine(-0.6);
        assert!((s + libm::sinf(0.6)).abs() < 1e-6 && (c - libm::cosf(0.6)).abs() < 1e-6);
        assert!((est.toe_x_m - toe).abs() < 1e-6, "{est:?}");
    }

    /// In stance the hip's speed is the leg's kinematics about the toe;
    /// in flight the liftoff's holds.
    #[test]
    fn the_speed_from_the_leg() {
        let cfg = PlanarEstimatorConfig {
            speed_from_leg: true,
            ..PlanarEstimatorConfig::table_2_2()
        };
        let mut e = PlanarEstimator::new(cfg).unwrap_or_else(|f| panic!("{f:?}"));
        // The toe at x = 0.1 m, the leg 0.6 m long and shortening at
        // 0.1 m/s, the hip moving at 0.8 m/s: theta = asin((0.1 - x) / l).
        let at = |t: f32| {
            let x = 0.8 * t;
            let l = 0.6 - 0.1 * t;
            PlanarReadings {
                boom_x_m: 0.0,
                boom_z_m: 0.6,
                pitch_rad: 0.0,
                hip_angle_rad: libm::asinf((0.1 - x) / l),
                leg_length_m: l,
                leg_motor_rad: 0.0,
            }
        };
        let mut est = PlanarEstimate::default();
        for k in 0..300 {
            est = e.update(&at(k as f32 * DT), DT);
        }
        assert!(est.stance);
        assert!((est.x_dot_mps - 0.8).abs() < 0.01, "{est:?}");
        // Liftoff: the leg back on its stop, the speed held.
        let mut flight = at(300.0 * DT);
        flight.leg_length_m = 0.65;
        let est = e.update(&flight, DT);
        assert!(!est.stance);
        assert!((est.x_dot_mps - 0.8).abs() < 0.01, "{est:?}");
    }

    #[test]
    fn a_bad_setting_is_refused_by_name() {
        let mut c = PlanarEstimatorConfig::table_2_2();
        c.liftoff_compression_m = 2.0e-3;
        assert_eq!(
            PlanarEstimator::new(c).err(),
            Some(InvalidField("liftoff_compression_m"))
        );
        let mut c = PlanarEstimatorConfig::table_2_2();
        c.rate_filter_gain = 1.0;
        assert_eq!(
            PlanarEstimator::new(c).err(),
            Some(InvalidField("rate_filter_gain"))
        );
    }

    proptest! {
        /// Any reading, finite or not: no panic; a non-finite one makes
        /// the estimate non-finite (the guard's cue) and the next good
        /// reading gives finite rates again.
        #[test]
        fn any_reading_is_taken_or_flagged(
            v in prop::array::uniform5(prop_oneof![
                -10.0f32..10.0,
                Just(f32::NAN),
                Just(f32::INFINITY),
            ]),
        ) {
            let mut e = PlanarEstimator::new(PlanarEstimatorConfig::table_2_2())
                .map_err(|f| TestCaseError::fail(f.0))?;
            let good = reading(0.0, 0.65);
            e.update(&good, DT);
            let r = PlanarReadings {
                boom_x_m: v[0],
                boom_z_m: v[1],
                pitch_rad: v[2],
                hip_angle_rad: v[3],
                leg_length_m: v[4],
                leg_motor_rad: 0.0,
            };
            let est = e.update(&r, DT);
            prop_assert_eq!(est.is_finite(), v.iter().all(|x| x.is_finite()));
            e.update(&good, DT);
            prop_assert!(e.update(&good, DT).is_finite());
        }
    }
}
