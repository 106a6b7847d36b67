//! Shaped torque (`shaped`): the thesis's modified-torque idea (section
//! 4.4.3) done so that the actuator's energy ends up in the body instead of
//! in the mechanical stops, with an outer per-hop loop on the measured apex.
//!
//! # Why
//! The reflected rotor inertia `alpha = J / r^2 + m_s` (about 426 kg with
//! Table 2.1) makes the nut a heavy mass behind the leg spring. Under the
//! thesis's laws the motor does far more work per hop than friction and the
//! foot impacts take, but most of it leaves as rotor kinetic energy at
//! liftoff, which the Table 2.1 flight PD (lightly damped against `alpha`)
//! then throws into the upper stop. This law
//!
//! 1. spins the rotor up on the way down (from `spin_up_fraction` of the
//!    flight's apex, also on the first descent after a release, and only in
//!    a fall: see [`Constants::spin_up`]), where the spring force it works
//!    against is small, so the motor's work goes into rotor kinetic energy
//!    cheaply;
//! 2. keeps pushing through the first part of stance, where that kinetic
//!    energy and the motor's force compress the spring under the body;
//! 3. brakes the nut from `switch_fraction` of the model's stance time
//!    `T = pi sqrt((M + m_s) / k)` (the body on the leg spring, eqs
//!    2.32-2.34 without gravity and actuator) until it stops, so less rotor
//!    energy is carried into flight;
//! 4. in flight, brings the nut home along a braking curve (below) instead of
//!    the PD: no stop impact, within the current limit.
//!
//! The torque level `u` (fraction of the current limit, both for the
//! spin-up and the stance push) is the outer loop's output, a PI on the apex
//! energy error `e_k = E_D(H_target) - E_D(H_k)` (`E_D` of eq 2.43, J) after
//! each apex `H_k`:
//!
//! ```text
//! b <- clamp(b + K_i e_k, 0, 1)  (only while b + K_p e_k is in [0, 1])
//! u  = clamp(b + K_p e_k, 0, 1)
//! ```
//!
//! with `b` starting at the level expected to hold the target
//! (`integral_start`): the climb runs at full level on the proportional
//! term, which lets the level down as the apex nears the target, and the
//! integral does not wind up meanwhile.
//!
//! # Braking-curve back-drive
//! In flight the nut obeys `alpha pdd = eta k_m i / r - k (delta0 + p)`
//! (eqs 2.12-2.14 with `m_s` small against `alpha`). The largest braking
//! deceleration of a nut moving up (towards the stop at `p = 0`) is
//! `a(p) = (eta k_m i_max / r - k (delta0 + p)) / alpha`; the nut can stop in
//! the distance `p` from speed `sqrt(2 a p)`. The law tracks
//! `v_ref = -min(max(sqrt(2 margin a p), v_creep), p / t_track)` (`v_ref = 0`
//! at or above the stop; the last term makes it continuous there, so the nut
//! settles onto the stop instead of chattering between creep and rest) with
//! a model-based acceleration command:
//!
//! ```text
//! i = r / (eta k_m) (alpha (v_ref - pd) / t_track + k (delta0 + p))
//! ```
//!
//! clamped to the current limit, so the nut arrives at the stop at the creep
//! speed.
//!
//! # Least-effort return
//! With `least_effort_return` (the heat-aware mode), the nut comes home
//! with the least `int i^2 dt` instead, as the least-heat hop of
//! docs/endurance.md does: the spring helps, and the nut strikes its stop
//! when the push is due rather than creeping onto it. With `y = delta0 +
//! p` and `w^2 = k / alpha`, the nut in flight obeys `y'' = -w^2 y + u`
//! (`u = eta k_m i / (r alpha)`). Unforced it would be at `y_free = y0
//! cos(w tau) + v0 sin(w tau) / w` when the push is due, `tau` from now
//! (the toe falling to `spin_up_fraction` of the flight's apex, predicted
//! from the body's height and speed in free fall; touchdown for a flight
//! too low to spin up). The `u` of least `int u^2 dt` that puts it at
//! `delta0` (the stop) then, whatever its speed, is `mu sin(w (tau - t))`
//! with `mu = w (delta0 - y_free) / S` and `S = int_0^tau sin^2(w s) ds =
//! tau / 2 - sin(2 w tau) / (4 w)`: the current is largest at liftoff and
//! falls to zero at the stop. It is planned again every period from the
//! measured state (the plan of an exact model is the same at every
//! step); the braking curve takes over on the stop, within the last
//! millisecond and for non-finite inputs. A push due more than a quarter
//! of the nut's period `2 pi / w` away gets no current until it is within
//! it: the spring alone moves the nut towards its stop meanwhile.
//!
//! The square root is [`sqrt_approx`] (two Newton steps, about 20
//! instructions; `libm::sqrtf` costs several times that on the M4F without
//! `vsqrt.f32`).

use super::{require, Actuator, ControlInput, ControlLaw, EventInput, InvalidField};
use crate::estimator::{Phase, PhaseEvent};
use crate::model::ModelParams;

crate::param::config! {
    /// Configuration of the shaped-torque law. Times are fractions of the
    /// model's stance time, levels fractions of the current limit.
    #[derive(Debug, Clone, Copy, PartialEq)]
    #[cfg_attr(feature = "defmt", derive(defmt::Format))]
    pub struct Config;
    params {
        /// On the way down, the push starts once the toe is below this fraction of the
        /// present flight's apex (its highest point). The default is tuned in simulation
        /// (design parameters; the thesis used 0.4).
        31 SHAPED_SPIN_UP_FRACTION spin_up_fraction: f32 {
            "shaped.spin_up_fraction", "1", Real, [0.0, 1.0], 0.6, LIVE,
            "Fraction of the flight's apex below which the descent spins the rotor up."
        }
        /// No spin-up in a flight whose apex is below this toe height: a flight that low
        /// is too short for the back-drive to bring the nut home, and a robot standing on
        /// its extended leg reads as a flight of zero height (the spin-up would pump the
        /// nut into its stops).
        32 SHAPED_SPIN_UP_MIN_APEX_M spin_up_min_apex_m: f32 {
            "shaped.spin_up_min_apex_m", "m", Real, [0.0, 1.0], 0.005, LIVE,
            "Smallest flight apex that spins up."
        }
        /// The push ends and braking starts this far into stance, as a fraction of the
        /// model's stance time `pi sqrt((M + m_s) / k)`. The default is tuned in
        /// simulation: 0.66 converges sooner with an exact model but fails with the
        /// model's `k` 20 % low.
        33 SHAPED_SWITCH_FRACTION switch_fraction: f32 {
            "shaped.switch_fraction", "1", Real, [0.0, 2.0], 0.6, LIVE,
            "Fraction of the model's stance time T = pi sqrt((M + m_s)/k) after which the push turns to braking."
        }
        /// Applied after the switch.
        34 SHAPED_BRAKE_FRACTION brake_fraction: f32 {
            "shaped.brake_fraction", "1", Real, [0.0, 1.0], 1.0, LIVE,
            "Braking current, fraction of the current limit."
        }
        /// Used until the first apex.
        35 SHAPED_INITIAL_LEVEL initial_level: f32 {
            "shaped.initial_level", "1", Real, [0.0, 1.0], 1.0, LIVE,
            "Torque level of the first hop, fraction of the current limit."
        }
        /// The outer loop's integral at start: the level expected to hold the target. The
        /// default is about what holds 0.15 m with the design parameters (tuned there; for
        /// other targets or machines the integral moves to its own steady level once the
        /// climb is done). Starting it at the steady level rather than at full lets the
        /// proportional term take the level down as the apex nears the target, instead of
        /// climbing at full level into an overshoot (16 instead of 19 hops to converge
        /// from 0.05 m, with the spin-up otherwise unchanged).
        36 SHAPED_INTEGRAL_START integral_start: f32 {
            "shaped.integral_start", "1", Real, [0.0, 1.0], 0.8, LIVE,
            "Starting integral of the per-hop level loop."
        }
        /// `K_i`: level change per J of apex energy error. The default is tuned in
        /// simulation with `K_p` (design parameters, 0.15 m target).
        37 SHAPED_LEVEL_GAIN level_gain_per_j: f32 {
            "shaped.level_gain_per_j", "1/J", Real, [0.0, 10.0], 0.1, LIVE,
            "Integral gain of the level loop on the apex energy error."
        }
        /// `K_p`: level change per J of apex energy error.
        38 SHAPED_LEVEL_PROPORTIONAL level_proportional_per_j: f32 {
            "shaped.level_proportional_per_j", "1/J", Real, [0.0, 10.0], 0.2, LIVE,
            "Proportional gain of the level loop."
        }
        /// Braking-curve margin: the fraction of the largest braking deceleration the
        /// back-drive plans with. The default leaves room for a 20 % error in `k` and for
        /// friction.
        39 SHAPED_BRAKING_MARGIN braking_margin: f32 {
            "shaped.braking_margin", "1", Real, [1.0e-3, 1.0], 0.7, LIVE,
            "Fraction of the available braking deceleration the flight return plans with."
        }
        /// The default is 50 control periods at 10 kHz; the eq 4.1 filter lags about 1 ms.
        40 SHAPED_TRACKING_TIME_S tracking_time_s: f32 {
            "shaped.tracking_time_s", "s", Real, [1.0e-3, 0.1], 0.005, LIVE,
            "Time constant of the flight return's speed tracking."
        }
        /// At the default the impact is 0.02 J with Table 2.1's rotor.
        41 SHAPED_CREEP_SPEED_MPS creep_speed_mps: f32 {
            "shaped.creep_speed_mps", "m/s", Real, [0.0, 0.1], 0.01, LIVE,
            "Speed at which the nut arrives at its stop."
        }
        /// Bring the nut home in flight with the least effort instead of along the braking
        /// curve: the current that reaches the stop when the push is due with the least
        /// `int i^2 dt`, the spring helping, arriving at the speed that takes (module
        /// docs, "Least-effort return").
        110 SHAPED_LEAST_EFFORT_RETURN least_effort_return: bool {
            "shaped.least_effort_return", "-", Flag, [0.0, 1.0], 0.0, LIVE,
            "Bring the nut home in flight with the least int i^2 dt (the spring helping, reaching the stop when the push is due) instead of along the braking curve."
        }
    }
}

impl Config {
    /// The heat-aware mode: the same law tuned for copper loss per hop
    /// instead of climb speed (random searches over its parameters at a
    /// 5 cm apex on the design machine, docs/endurance.md). The nut comes
    /// home in flight with the least effort (the braking curve, at half
    /// the braking deceleration with a 65 ms time constant, only holds it
    /// on its stop), the push ends at half the model's stance time and the
    /// stance brake uses 30 % of the limit: 13.3 A RMS at 5 cm instead of
    /// 23.4, within 25 % of the least heat per hop any schedule needs at
    /// 3-15 cm, and the motor reaches its derating temperature after
    /// 58.5 s instead of 13.9.
    pub fn heat_aware() -> Self {
        Self {
            switch_fraction: 0.5,
            brake_fraction: 0.3,
            braking_margin: 0.5,
            tracking_time_s: 0.065,
            least_effort_return: true,
            ..Self::default()
        }
    }

    /// Checks every field (finite and in its documented range), naming the
    /// first one out of range.
    pub fn validate(&self) -> Result<(), InvalidField> {
        crate::param::validate_fields(&mut { *self }, FIELDS)
    }
}

/// The shaped controller: its constants ([`Constants`]) and its state, the
/// torque level of the per-hop loop and the stance's clock and braking flag.
#[derive(Debug, Clone, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Shaped {
    k: Constants,
    /// Torque level `u`, fraction of the current limit.
    level: f32,
    /// The per-hop loop's integral `b`.
    integral: f32,
    /// Time since touchdown, s.
    stance_time_s: f32,
    /// Whether braking has stopped the nut this stance.
    braked: bool,
}

impl Shaped {
    /// Checks `cfg` and works out its constants for `model`.
    pub fn new(cfg: &Config, act: &Actuator, model: &ModelParams) -> Result<Self, InvalidField> {
        let k = Constants::new(cfg, act, model)?;
        Ok(Self {
            level: cfg.initial_level,
            integral: cfg.integral_start,
            k,
            stance_time_s: 0.0,
            braked: false,
        })
    }

    /// The torque level, fraction of the current limit.
    pub fn level(&self) -> f32 {
        self.level
    }
}

impl ControlLaw for Shaped {
    fn on_event(&mut self, event: &EventInput) {
        match event.event {
            PhaseEvent::Touchdown => {
                self.stance_time_s = 0.0;
                self.braked = false;
            }
            PhaseEvent::Apex { .. } => {
                // With the motor off (a fault latched) the hop decays whatever
                // the level: integrating that error would only wind up.
                if let (Some(measured_j), false) = (event.hop_apex_energy_j, event.faulted) {
                    (self.integral, self.level) = self.k.next_level(
                        self.integral,
                        self.level,
                        event.desired_energy_j,
                        measured_j,
                    );
                }
            }
            _ => {}
        }
    }

    #[inline]
    fn current_a(&mut self, x: &ControlInput) -> f32 {
        if x.phase == Phase::Flight {
            // The flight's own peak, not the last apex event: the same
            // height once descending, and it also exists on the first
            // descent after a release from rest.
            if self
                .k
                .spin_up(x.toe_height_m, x.body_velocity_mps, x.flight_peak_toe_m)
            {
                return self.k.push_current_a(self.level);
            }
            if self.k.cfg.least_effort_return {
                if let Some(i) = self.k.least_effort_current_a(x) {
                    return i;
                }
            }
            return self
                .k
                .backdrive_current_a(x.nut_position_m, x.nut_velocity_mps);
        }
        // A non-finite `dt_s` makes the sum NaN: the comparisons in
        // `stance_current_a` then fall through to braking or 0 A, both safe.
        self.stance_time_s += x.dt_s;
        self.k.stance_current_a(
            self.level,
            self.stance_time_s,
            x.nut_velocity_mps,
            &mut self.braked,
        )
    }
}

/// The law with its model constants worked out once.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Constants {
    cfg: Config,
    /// Current limit, A.
    limit_a: f32,
    /// Switch time after touchdown, s.
    switch_s: f32,
    /// Amps per newton on the nut, `r / (eta k_m)`.
    a_per_n: f32,
    /// `alpha / t_track`, N s/m.
    tracking_n_s_per_m: f32,
    /// `1 / t_track`, 1/s.
    per_tracking_s: f32,
    /// Spring `k`, N/m, and preload force `k delta0`, N.
    spring_n_per_m: f32,
    preload_n: f32,
    /// `2 margin / alpha`, 1/kg: `v^2 = 2 margin a p` with `a = F_brake / alpha`.
    two_margin_per_alpha: f32,
    /// Largest braking force on the nut, `eta k_m i_max / r`, N.
    max_force_n: f32,
    /// Gravitational acceleration of the model, m/s^2 (the fall test of
    /// the spin-up).
    gravity_mps2: f32,
    /// The nut's natural frequency on the spring in flight,
    /// `w = sqrt(k / alpha)`, rad/s, and its inverse, s.
    omega_rad_s: f32,
    per_omega_s: f32,
    /// The least-effort plan's gain `4 w^2 alpha r / (eta k_m)`, A/m (the
    /// current now is this times `(delta0 - y_free) sin(w tau) /
    /// (2 w tau - sin(2 w tau))`).
    plan_a_per_m: f32,
    /// Spring preload `delta0`, m.
    preload_m: f32,
}

impl Constants {
    /// `None` if `cfg` is invalid or the model gives no usable constants.
    pub fn new(cfg: &Config, act: &Actuator, model: &ModelParams) -> Result<Self, InvalidField> {
        cfg.validate()?;
        let r = act.screw_m_per_rad;
        let torque_per_a = act.efficiency * act.torque_constant_nm_per_a;
        let alpha = model.reflected_inertia_kg();
        let k = model.spring_stiffness_n_per_m;
        let stance_s =
            core::f32::consts::PI * libm::sqrtf((model.body_mass_kg + model.nut_mass_kg) / k);
        let limit_a = act.usable_limit_a();
        let p = Self {
            cfg: *cfg,
            limit_a,
            switch_s: cfg.switch_fraction * stance_s,
            a_per_n: r / torque_per_a,
            tracking_n_s_per_m: alpha / cfg.tracking_time_s,
            per_tracking_s: 1.0 / cfg.tracking_time_s,
            spring_n_per_m: k,
            preload_n: k * model.preload_m,
            two_margin_per_alpha: 2.0 * cfg.braking_margin / alpha,
            max_force_n: torque_per_a * limit_a / r,
            gravity_mps2: model.gravity_mps2,
            omega_rad_s: libm::sqrtf(k / alpha),
            per_omega_s: libm::sqrtf(alpha / k),
            plan_a_per_m: 4.0 * k * r / torque_per_a,
            preload_m: model.preload_m,
        };
        let all_finite = [
            p.switch_s,
            p.a_per_n,
            p.tracking_n_s_per_m,
            p.preload_n,
            p.two_margin_per_alpha,
            p.max_force_n,
            p.gravity_mps2,
            p.omega_rad_s,
            p.per_omega_s,
            p.plan_a_per_m,
            p.preload_m,
        ]
        .iter()
        .all(|v| v.is_finite() && *v >= 0.0);
        // The model was validated; what is left to refuse is a combination
        // of valid values whose constants overflow.
        require(all_finite, "model")?;
        Ok(p)
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.cfg
    }

    /// Whether the push runs in flight: falling, with the toe below
    /// `spin_up_fraction` of `apex_m`, the present flight's peak (false
    /// without one, or with one below `spin_up_min_apex_m`).
    ///
    /// "Falling": descending at least `1/sqrt(2)` of the free-fall speed
    /// from the peak, `v^2 >= g (apex - toe)` (free fall gives `2 g`). A
    /// robot lifted and lowered by hand, or standing on its extended leg
    /// after a lift (both read as a flight), moves far slower than that, so
    /// the motor stays off there; a multiply and a comparison, no root.
    #[inline]
    pub fn spin_up(&self, toe_height_m: f32, body_velocity_mps: f32, apex_m: Option<f32>) -> bool {
        apex_m.is_some_and(|apex| {
            apex >= self.cfg.spin_up_min_apex_m
                && body_velocity_mps * body_velocity_mps
                    >= self.gravity_mps2 * (apex - toe_height_m)
                && super::modified_torque::descent_window(
                    self.cfg.spin_up_fraction,
                    toe_height_m,
                    body_velocity_mps,
                    apex,
                )
        })
    }

    /// Stance command, A, `stance_time_s` after touchdown with the nut moving
    /// at `nut_velocity_mps` (down positive). `braked` latches when braking
    /// has stopped the nut (reset it at touchdown).
    #[inline]
    pub fn stance_current_a(
        &self,
        level: f32,
        stance_time_s: f32,
        nut_velocity_mps: f32,
        braked: &mut bool,
    ) -> f32 {
        if stance_time_s < self.switch_s {
            return self.push_current_a(level);
        }
        if !*braked && nut_velocity_mps > 0.0 {
            return -self.cfg.brake_fraction * self.limit_a;
        }
        *braked = true;
        0.0
    }

    /// The push (spin-up and early stance), A.
    #[inline]
    pub fn push_current_a(&self, level: f32) -> f32 {
        // `level` is kept in [0, 1] by `next_level`; clamp anyway (NaN -> 0).
        let l = if level >= 1.0 {
            1.0
        } else if level >= 0.0 {
            level
        } else {
            0.0
        };
        l * self.limit_a
    }

    /// Braking-curve back-drive to the upper stop, A (see the module docs).
    /// Non-finite inputs give 0 A.
    #[inline]
    pub fn backdrive_current_a(&self, nut_position_m: f32, nut_velocity_mps: f32) -> f32 {
        let p = nut_position_m;
        let spring_n = self.preload_n + self.spring_n_per_m * p;
        // Within the creep zone (the nut resting on or near the stop, most of
        // the flight) the linear term is the smaller one: skip the root.
        let linear_mps = p * self.per_tracking_s;
        let v_ref = if p <= 0.0 {
            0.0
        } else if linear_mps <= self.cfg.creep_speed_mps {
            -linear_mps
        } else {
            // Plain comparisons: `f32::max`/`min` (NaN-aware) become library
            // calls on the M4F. `sqrt_approx` gives 0 for a negative force.
            let brake_n = self.max_force_n - spring_n;
            let v = sqrt_approx(self.two_margin_per_alpha * brake_n * p);
            let v = if v > self.cfg.creep_speed_mps {
                v
            } else {
                self.cfg.creep_speed_mps
            };
            -(if v < linear_mps { v } else { linear_mps })
        };
        let i = self.a_per_n * (self.tracking_n_s_per_m * (v_ref - nut_velocity_mps) + spring_n);
        if i.is_finite() {
            crate::num::clamp(i, -self.limit_a, self.limit_a)
        } else {
            0.0
        }
    }

    /// Least-effort return to the upper stop, A (module docs), or `None`
    /// where the braking curve takes over: the nut at or above its stop,
    /// the push due within a millisecond, or a non-finite input.
    #[inline]
    pub fn least_effort_current_a(&self, x: &ControlInput) -> Option<f32> {
        let g = self.gravity_mps2;
        let vb = x.body_velocity_mps;
        let toe = x.toe_height_m;
        // The flight's apex: predicted while rising, the peak once falling.
        let rising = if vb > 0.0 { vb * vb / (2.0 * g) } else { 0.0 };
        let peak = x.flight_peak_toe_m.unwrap_or(toe);
        let apex = if toe + rising > peak {
            toe + rising
        } else {
            peak
        };
        // The push is due at the spin-up height, or at touchdown without one.
        let push_m = if apex >= self.cfg.spin_up_min_apex_m {
            self.cfg.spin_up_fraction * apex
        } else {
            0.0
        };
        // `toe + vb t - g t^2 / 2 = push_m`, the later root (none once the
        // toe is past it on the way down: the push runs).
        let discriminant = vb * vb + 2.0 * g * (toe - push_m);
        if !(x.nut_position_m > 0.0 && discriminant > 0.0) {
            return None;
        }
        let tau_s = (vb + sqrt_approx(discriminant)) / g;
        // NaN fails the comparison too: the braking curve then.
        let due_later = tau_s > 1.0e-3;
        if !due_later {
            return None;
        }
        // `y = delta0 + p` obeys `y'' = -w^2 y + u`; unforced it would be at
        // `y_free` after `tau`. The `u` of least `int u^2 dt` that puts it
        // at `delta0` (the stop) then is `mu sin(w (tau - t))`, now
        // `mu sin(w tau)`, with `mu = w (delta0 - y_free) / S`,
        // `S = int_0^tau sin^2(w s) ds = (2 w tau - sin(2 w tau)) / (4 w)`.
        // The current is `alpha r / (eta k_m) u`, and with `S` written out,
        // `u = 4 w^2 (delta0 - y_free) sin(w tau) / (2 w tau - sin(2 w tau))`.
        // With the push more than a quarter of the nut's period away, no
        // current: the spring alone brings the nut towards its stop (from
        // rest, within that quarter period), and the plan starts once the
        // push is within it (the range of `sin_cos_quadrant`).
        let theta = self.omega_rad_s * tau_s;
        if theta > core::f32::consts::FRAC_PI_2 {
            return Some(0.0);
        }
        let (s, c) = sin_cos_quadrant(theta);
        let y0 = self.preload_m + x.nut_position_m;
        let y_free = y0 * c + x.nut_velocity_mps * s * self.per_omega_s;
        let i =
            self.plan_a_per_m * (self.preload_m - y_free) * s / two_theta_minus_sin(theta, s, c);
        i.is_finite()
            .then(|| crate::num::clamp(i, -self.limit_a, self.limit_a))
    }

    /// The outer loop after an apex whose energy `measured_j` fell short of
    /// `desired_j` (J): the new integral `b` and the level `u` to use, both
    /// in `[0, 1]`. A non-finite error leaves both unchanged.
    pub fn next_level(
        &self,
        integral: f32,
        level: f32,
        desired_j: f32,
        measured_j: f32,
    ) -> (f32, f32) {
        let e = desired_j - measured_j;
        let kp = self.cfg.level_proportional_per_j;
        let trial = integral + kp * e;
        if !trial.is_finite() {
            return (integral, level);
        }
        // Conditional integration (anti-windup): the integral only moves
        // while the level is not saturated, so a long climb at full level
        // does not wind it up and overshoot the target.
        let b = if (0.0..=1.0).contains(&trial) {
            crate::num::clamp(integral + self.cfg.level_gain_per_j * e, 0.0, 1.0)
        } else {
            integral
        };
        (b, crate::num::clamp(b + kp * e, 0.0, 1.0))
    }
}

/// `(sin x, cos x)` for `x` in `[0, pi/2]`: their Taylor polynomials to
/// `x^9` and `x^10`, whose first terms left out are below 4e-6 and 5e-7
/// there. (libm's `sinf`/`cosf` bring their reduction of any argument,
/// with its table of `2/pi`, and 13 KB of flash; the least-effort return
/// needs only this quadrant.)
#[inline]
pub fn sin_cos_quadrant(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let s =
        x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 / 362_880.0))));
    let c = 1.0
        + x2 * (-0.5
            + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 - x2 / 3_628_800.0))));
    (s, c)
}

/// `2 theta - sin(2 theta)` for `theta` in `[0, pi/2]`, given `s` and `c`,
/// its sine and cosine: `2 theta - 2 s c` from `theta = 0.5` on (at least
/// 0.1585 there, so the rounding of `2 s c` is a few millionths of it), and
/// below, where the difference is all rounding, its series in `phi = 2
/// theta`, `phi^3/3! - phi^5/5! + phi^7/7! - phi^9/9!` (the next term is
/// below 3e-8).
#[inline]
pub fn two_theta_minus_sin(theta: f32, s: f32, c: f32) -> f32 {
    let phi = 2.0 * theta;
    if theta >= 0.5 {
        return phi - 2.0 * s * c;
    }
    let p2 = phi * phi;
    phi * p2 * (1.0 / 6.0 + p2 * (-1.0 / 120.0 + p2 * (1.0 / 5040.0 - p2 / 362_880.0)))
}

/// `sqrt(x)` to a relative error below 1e-5 for normal positive `x` (0 for
/// `x <= 0` or NaN, `+inf` for `+inf`): the classic bit-level estimate of
/// `1 / sqrt(x)` refined by two Newton steps, times `x`.
#[inline]
pub fn sqrt_approx(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    if x == f32::INFINITY {
        return x;
    }
    // The exponent halved and negated in the bit pattern: within 3.5 % of
    // 1 / sqrt(x); each Newton step squares the relative error.
    let mut y = f32::from_bits(0x5f37_59df_u32.wrapping_sub(x.to_bits() >> 1));
    let half = 0.5 * x;
    y *= 1.5 - half * y * y;
    y *= 1.5 - half * y * y;
    x * y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqrt_approx_is_accurate_over_the_range_used() {
        // v^2 = 2 margin a p spans about 1e-8 .. 1 (m/s)^2; check wider.
        let mut x = 1e-12_f32;
        while x < 1e6 {
            let (a, e) = (sqrt_approx(x), libm::sqrtf(x));
            assert!(((a - e) / e).abs() < 1e-5, "{x}: {a} vs {e}");
            x *= 1.37;
        }
        assert_eq!(sqrt_approx(0.0), 0.0);
        assert_eq!(sqrt_approx(-1.0), 0.0);
        assert_eq!(sqrt_approx(f32::NAN), 0.0);
        assert_eq!(sqrt_approx(f32::INFINITY), f32::INFINITY);
    }

    /// A 5 cm flight from liftoff, the nut 8 mm down and at rest, the
    /// body in free fall, the nut on the spring and its stop: the nut's
    /// position when the push is due and the flight's `int i^2 dt`.
    fn return_flight(least_effort: bool) -> (f32, f32) {
        let model = ModelParams::default();
        let act = Actuator::from_model(&model);
        let cfg = Config {
            least_effort_return: least_effort,
            ..Config::heat_aware()
        };
        let k = Constants::new(&cfg, &act, &model).unwrap_or_else(|e| panic!("{e:?}"));
        let (alpha, g, dt) = (model.reflected_inertia_kg(), model.gravity_mps2, 1.0e-4);
        let (mut p, mut v) = (0.008_f32, 0.0_f32);
        let (mut toe, mut vb, mut peak) = (0.0_f32, libm::sqrtf(2.0 * g * 0.05), 0.0_f32);
        let mut a2s = 0.0;
        while !k.spin_up(toe, vb, Some(peak)) {
            let x = ControlInput {
                phase: Phase::Flight,
                body_height_m: 0.61 + toe,
                toe_height_m: toe,
                body_velocity_mps: vb,
                motor_angle_rad: p / act.screw_m_per_rad,
                motor_rate_rad_s: v / act.screw_m_per_rad,
                nut_position_m: p,
                nut_velocity_mps: v,
                spring_force_n: 0.0,
                leg_compression_m: 0.0,
                energy_j: 0.0,
                desired_energy_j: 0.0,
                target_apex_m: 0.05,
                flight_peak_toe_m: Some(peak),
                last_apex_m: None,
                dt_s: dt,
            };
            let i = if least_effort {
                k.least_effort_current_a(&x)
                    .unwrap_or_else(|| k.backdrive_current_a(p, v))
            } else {
                k.backdrive_current_a(p, v)
            };
            a2s += i * i * dt;
            let force_n = i / k.a_per_n - model.spring_stiffness_n_per_m * (model.preload_m + p);
            v += force_n / alpha * dt;
            p += v * dt;
            if p < 0.0 {
                (p, v) = (0.0, 0.0);
            }
            toe += vb * dt;
            vb -= g * dt;
            peak = if toe > peak { toe } else { peak };
        }
        (p, a2s)
    }

    /// The least-effort return brings the nut home by the time the push is
    /// due, for much less heat than the braking curve (which also gets it
    /// home): the gap between the heat-aware mode and the least-heat hop
    /// was mostly this.
    #[test]
    fn least_effort_return_is_home_for_the_push_at_less_heat() {
        let (p_least, a2s_least) = return_flight(true);
        let (p_curve, a2s_curve) = return_flight(false);
        assert!(p_least < 1.0e-4, "{p_least} m from the stop");
        assert!(p_curve < 1.0e-4, "{p_curve} m from the stop");
        // 3.76 against 12.1 A^2 s on this frictionless nut.
        assert!((a2s_least - 3.76).abs() < 0.05 * 3.76, "{a2s_least} A^2 s");
        assert!(
            a2s_least < 0.35 * a2s_curve,
            "{a2s_least} against {a2s_curve} A^2 s"
        );
    }

    #[test]
    fn the_quadrant_trigonometry_matches_libm() {
        let mut x = 0.0_f32;
        while x <= core::f32::consts::FRAC_PI_2 {
            let (s, c) = sin_cos_quadrant(x);
            assert!((s - libm::sinf(x)).abs() < 4.0e-6, "sin {x}");
            assert!((c - libm::cosf(x)).abs() < 1.0e-6, "cos {x}");
            let phi = 2.0 * f64::from(x);
            let exact = phi - libm::sin(phi);
            let got = f64::from(two_theta_minus_sin(x, s, c));
            assert!(
                (got - exact).abs() <= 2.0e-5 * exact + 1.0e-30,
                "2 theta - sin(2 theta) at {x}: {got} against {exact}"
            );
            x += 1.0e-3;
        }
    }

    fn prepared() -> Constants {
        let model = ModelParams::default();
        Constants::new(&Config::default(), &Actuator::from_model(&model), &model)
            .unwrap_or_else(|e| panic!("default shaped law: {e:?}"))
    }

    #[test]
    fn spin_up_only_descending_low_in_a_real_flight() {
        let p = prepared();
        // 0.10 m apex, falling through 0.05 m (below 0.6 of it; free fall
        // gives 0.99 m/s there): push.
        assert!(p.spin_up(0.05, -1.0, Some(0.10)));
        assert!(p.spin_up(0.05, -0.8, Some(0.10)));
        // Lowered by hand at 0.2 m/s, or creeping down on the extended leg
        // after a lift: not a fall, no push.
        assert!(!p.spin_up(0.05, -0.2, Some(0.10)));
        assert!(!p.spin_up(0.0, -0.05, Some(0.02)));
        // Still rising, or above 0.6 of the apex, or no flight peak: no.
        assert!(!p.spin_up(0.05, 1.0, Some(0.10)));
        assert!(!p.spin_up(0.07, -1.0, Some(0.10)));
        assert!(!p.spin_up(0.05, -1.0, None));
        // A "flight" below 5 mm (a micro-hop, or standing on the extended
        // leg): no spin-up however it moves.
        assert!(!p.spin_up(0.001, -0.1, Some(0.004)));
        assert!(!p.spin_up(f32::NAN, -1.0, Some(0.10)));
    }

    #[test]
    fn stance_timing_comes_from_the_model() {
        let p = prepared();
        // pi sqrt(9.25 / 11000) = 0.0911 s; 0.6 of it.
        assert!((p.switch_s - 0.05466).abs() < 2e-4, "{}", p.switch_s);
        let mut braked = false;
        assert_eq!(p.stance_current_a(1.0, 0.03, 0.2, &mut braked), p.limit_a);
        assert_eq!(
            p.stance_current_a(0.5, 0.03, 0.2, &mut braked),
            0.5 * p.limit_a
        );
        assert_eq!(p.stance_current_a(1.0, 0.06, 0.2, &mut braked), -p.limit_a);
        assert!(!braked);
        // Once the nut stops, braking ends for the rest of the stance.
        assert_eq!(p.stance_current_a(1.0, 0.08, -0.01, &mut braked), 0.0);
        assert!(braked);
        assert_eq!(p.stance_current_a(1.0, 0.09, 0.2, &mut braked), 0.0);
    }

    #[test]
    fn backdrive_brakes_on_the_curve_and_rests_at_the_stop() {
        let p = prepared();
        // At rest on the stop: the spring feed-forward only (no tracking error).
        let hold = p.backdrive_current_a(0.0, 0.0);
        assert!((hold - p.a_per_n * p.preload_n).abs() < 1e-4, "{hold}");
        // 10 mm out, moving up faster than the curve allows: brake (push down).
        assert!(p.backdrive_current_a(0.01, -0.5) > 0.0);
        // 10 mm out, at rest: pull up, saturated.
        assert_eq!(p.backdrive_current_a(0.01, 0.0), -p.limit_a);
        // Moving down after liftoff: full reverse current.
        assert_eq!(p.backdrive_current_a(0.02, 0.2), -p.limit_a);
        assert_eq!(p.backdrive_current_a(f32::NAN, 0.0), 0.0);
        let i = p.backdrive_current_a(0.01, f32::INFINITY);
        assert!(i.is_finite() && i.abs() <= p.limit_a);
    }

    #[test]
    fn outer_loop_integrates_the_apex_energy_error_within_bounds() {
        let p = prepared();
        // 2 J short: integral +0.2, level = integral + 0.4.
        let (b, u) = p.next_level(0.5, 0.5, 10.0, 8.0);
        assert!((b - 0.7).abs() < 1e-6 && (u - 1.0).abs() < 1e-6, "{b} {u}");
        let (b, u) = p.next_level(0.5, 0.5, 10.0, 9.5);
        assert!(
            (b - 0.55).abs() < 1e-6 && (u - 0.65).abs() < 1e-6,
            "{b} {u}"
        );
        // Saturated either way: the level clamps, the integral holds (no
        // wind-up).
        assert_eq!(p.next_level(0.99, 0.99, 100.0, 0.0), (0.99, 1.0));
        assert_eq!(p.next_level(0.01, 0.01, 0.0, 100.0), (0.01, 0.0));
        assert_eq!(p.next_level(0.3, 0.4, f32::NAN, 1.0), (0.3, 0.4));
    }

    #[test]
    fn invalid_configs_are_refused() {
        let model = ModelParams::default();
        let act = Actuator::from_model(&model);
        for c in [
            Config {
                spin_up_fraction: 1.5,
                ..Config::default()
            },
            Config {
                braking_margin: 0.0,
                ..Config::default()
            },
            Config {
                tracking_time_s: f32::NAN,
                ..Config::default()
            },
            Config {
                level_gain_per_j: -1.0,
                ..Config::default()
            },
            Config {
                integral_start: 1.5,
                ..Config::default()
            },
            Config {
                integral_start: f32::NAN,
                ..Config::default()
            },
            Config {
                spin_up_min_apex_m: -0.001,
                ..Config::default()
            },
            Config {
                spin_up_min_apex_m: f32::INFINITY,
                ..Config::default()
            },
        ] {
            assert!(Constants::new(&c, &act, &model).is_err(), "{c:?}");
        }
    }
}
