//! Event location: the guards (an event fires when one becomes positive),
//! the search for the first that fires, and [`Plant::advance`], which
//! integrates up to the end of the period and locates every crossing in
//! time by bisection.

use super::dynamics::{AugState, Config};
use super::{Event, Mode, NutStop, Plant, PlantError};

/// Events are located in time to this tolerance, s.
const TIME_TOL_S: f64 = 1e-12;

/// At most this many transitions within one [`Plant::advance`] call; more
/// means the model is stuck in a loop, reported as [`PlantError::EventStorm`].
pub(super) const MAX_EVENTS_PER_ADVANCE: u32 = 256;

/// Guards: an event fires when its guard becomes positive.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Guard {
    StopTop,
    StopBottom,
    Touchdown,
    Liftoff,
    ZeroVelocity,
    Unstick,
    Release,
    Sink,
    Lift,
}

impl Guard {
    /// Whether the guard is a force balance, and so changes with the motor
    /// command (the others are functions of the state alone).
    pub(super) fn depends_on_command(self) -> bool {
        matches!(
            self,
            Guard::Unstick | Guard::Release | Guard::Sink | Guard::Lift
        )
    }
}

impl Plant {
    /// Guards that apply in the present configuration, in priority order
    /// (the reference [`Self::first_firing`] is checked against).
    #[cfg(test)]
    pub(super) fn active_guards(&self) -> ([Guard; 5], usize) {
        let cfg = &self.cfg;
        let mut g = [Guard::StopTop; 5];
        let mut n = 0;
        let mut push = |x: Guard| {
            if n < g.len() {
                g[n] = x;
                n += 1;
            }
        };
        if cfg.nut == NutStop::Free {
            push(Guard::StopTop);
            push(Guard::StopBottom);
        } else {
            push(Guard::Release);
        }
        match cfg.mode {
            Mode::Flight => push(Guard::Touchdown),
            Mode::Stance => push(Guard::Liftoff),
            Mode::Standing => {
                push(Guard::Sink);
                push(Guard::Lift);
            }
        }
        if cfg.mode != Mode::Standing {
            push(if cfg.z_stuck {
                Guard::Unstick
            } else {
                Guard::ZeroVelocity
            });
        }
        (g, n)
    }

    #[inline(always)]
    pub(super) fn guard(&self, y: &AugState, g: Guard) -> f64 {
        let c = &self.c;
        let cfg = &self.cfg;
        match g {
            Guard::StopTop => -y.p_m,
            Guard::StopBottom => y.p_m - c.stroke,
            Guard::Touchdown => c.l0 - y.z_m,
            Guard::Liftoff => y.z_m - c.l0,
            Guard::ZeroVelocity => -cfg.z_dir * y.zd_mps,
            // A clamped body never comes unstuck.
            Guard::Unstick if self.clamped => -1.0,
            Guard::Unstick => libm::fabs(self.z_hold_force(cfg, y)) - self.friction_level(cfg),
            Guard::Release => {
                let r = self.p_hold_force(cfg, y);
                if cfg.nut == NutStop::Bottom {
                    r
                } else {
                    -r
                }
            }
            Guard::Sink => {
                // Stance equations with z held: upward force the body needs.
                self.z_hold_force(cfg, y) - c.f_stance
            }
            Guard::Lift => {
                let flight = Config {
                    mode: Mode::Flight,
                    ..*cfg
                };
                -self.z_hold_force(&flight, y) - c.f_flight
            }
        }
    }

    /// The first guard, in priority order, that fires at `y`.
    #[cfg(test)]
    pub(super) fn first_firing_reference(&self, y: &AugState) -> Option<Guard> {
        let (gs, n) = self.active_guards();
        gs.iter().take(n).copied().find(|&g| self.guard(y, g) > 0.0)
    }

    /// The first guard that fires at `y`: the guards that apply in the
    /// present configuration, in priority order (nut, contact, body
    /// velocity), evaluated one by one until one fires.
    #[inline]
    pub(super) fn first_firing(&self, y: &AugState) -> Option<Guard> {
        self.first_firing_in::<false>(y)
    }

    /// [`Self::first_firing`] when the guards that do not depend on the
    /// motor command are known not to fire at `y`: only the force guards
    /// (stiction, nut release, standing) are evaluated, in the same order.
    pub(super) fn first_firing_force_guards(&self, y: &AugState) -> Option<Guard> {
        self.first_firing_in::<true>(y)
    }

    #[inline(always)]
    pub(super) fn first_firing_in<const FORCE_ONLY: bool>(&self, y: &AugState) -> Option<Guard> {
        let cfg = &self.cfg;
        let fires = |g: Guard| (!FORCE_ONLY || g.depends_on_command()) && self.guard(y, g) > 0.0;
        if cfg.nut == NutStop::Free {
            if fires(Guard::StopTop) {
                return Some(Guard::StopTop);
            }
            if fires(Guard::StopBottom) {
                return Some(Guard::StopBottom);
            }
        } else if fires(Guard::Release) {
            return Some(Guard::Release);
        }
        match cfg.mode {
            Mode::Flight => {
                if fires(Guard::Touchdown) {
                    return Some(Guard::Touchdown);
                }
            }
            Mode::Stance => {
                if fires(Guard::Liftoff) {
                    return Some(Guard::Liftoff);
                }
            }
            Mode::Standing => {
                if fires(Guard::Sink) {
                    return Some(Guard::Sink);
                }
                if fires(Guard::Lift) {
                    return Some(Guard::Lift);
                }
                return None;
            }
        }
        let g = if cfg.z_stuck {
            Guard::Unstick
        } else {
            Guard::ZeroVelocity
        };
        fires(g).then_some(g)
    }

    /// Advance by `dt_s` with the amplifier current command `cmd_a` held
    /// (zero-order hold, like a DAC), reporting transitions to `on_event`.
    pub fn advance(
        &mut self,
        dt_s: f64,
        cmd_a: f64,
        on_event: &mut impl FnMut(Event),
    ) -> Result<(), PlantError> {
        if !cmd_a.is_finite() {
            return Err(PlantError::NonFiniteCommand);
        }
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return Err(PlantError::BadStep);
        }
        self.cmd_a = cmd_a;
        self.cmd_limited_a = cmd_a.clamp(-self.c.i_limit, self.c.i_limit);
        let t_end = self.t_s + dt_s;
        // What is known about the guards at the present state: the
        // state-only guards were clear when the last call ended (only the
        // force guards need a look under the new command), or, after a step
        // that fired nothing, all of them are (nothing to evaluate).
        let state_guards_clear = self.guards_clear;
        self.guards_clear = false;
        // The common case, one integration step with no transition in it:
        // what the loop below does for it, without its bookkeeping. Anything
        // else (a guard firing, a non-finite state, a longer period) leaves
        // the plant untouched for the loop to redo from the start. The step
        // is the loop's, `min(remaining, max_step_s)`: a period of exactly
        // `max_step_s` often comes out a rounding above it (`t_end - t_s`),
        // and the loop then drops the sub-`TIME_TOL_S` remainder.
        if state_guards_clear && self.first_firing_force_guards(&self.y).is_none() {
            let remaining = t_end - self.t_s;
            let h = remaining.min(self.max_step_s);
            // One step, and what is left after it within the tolerance (a
            // period longer than max_step_s needs the loop: decided before
            // integrating, not after).
            if remaining > TIME_TOL_S && t_end - (self.t_s + h) <= TIME_TOL_S {
                let y1 = self.rk4_step::<{ cfg!(feature = "specialised-step") }>(&self.y, h, t_end);
                if self.first_firing(&y1).is_none() && y1.is_finite() {
                    self.y = y1;
                    self.t_s = t_end;
                    self.sync_ledger();
                    self.guards_clear = true;
                    return Ok(());
                }
            }
        }
        self.advance_loop(t_end, state_guards_clear, on_event)
    }

    /// [`Self::advance`]'s general case: integration steps up to `t_end`,
    /// with every transition located and fired.
    pub(super) fn advance_loop(
        &mut self,
        t_end: f64,
        mut state_guards_clear: bool,
        on_event: &mut impl FnMut(Event),
    ) -> Result<(), PlantError> {
        let mut events = 0u32;
        let mut all_clear = false;
        loop {
            let firing = if all_clear {
                None
            } else if state_guards_clear {
                self.first_firing_force_guards(&self.y)
            } else {
                self.first_firing(&self.y)
            };
            if let Some(g) = firing {
                events += 1;
                if events > MAX_EVENTS_PER_ADVANCE {
                    return Err(PlantError::EventStorm { t_s: self.t_s });
                }
                self.fire(g, on_event);
                state_guards_clear = false;
                all_clear = false;
                continue;
            }
            let remaining = t_end - self.t_s;
            if remaining <= TIME_TOL_S {
                self.t_s = t_end;
                break;
            }
            let h = remaining.min(self.max_step_s);
            let y0 = self.y;
            let y1 = self.rk4_step::<false>(&y0, h, t_end);
            if self.first_firing(&y1).is_none() {
                self.y = y1;
                self.t_s += h;
                all_clear = true;
            } else {
                // Locate the earliest crossing: bisection on the step length
                // of a single RK4 step from y0 (smooth in h).
                let (mut lo, mut hi, mut y_hi) = (0.0, h, y1);
                while hi - lo > TIME_TOL_S {
                    let mid = 0.5 * (lo + hi);
                    let ym = self.rk4(&y0, mid);
                    if self.first_firing(&ym).is_some() {
                        hi = mid;
                        y_hi = ym;
                    } else {
                        lo = mid;
                    }
                }
                self.y = y_hi;
                self.t_s += hi;
                state_guards_clear = false;
                all_clear = false;
            }
            self.sync_ledger();
            if !self.y.is_finite() {
                return Err(PlantError::NonFiniteState { t_s: self.t_s });
            }
        }
        self.sync_ledger();
        // The loop only ends after finding no guard firing at the final state.
        self.guards_clear = true;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;
    use crate::plant::State;

    /// The unrolled guard search agrees with the table-driven one in every
    /// configuration, for states on both sides of every guard.
    #[test]
    fn first_firing_matches_the_reference() {
        let params = Params::design();
        let mut plant = match Plant::new(params, 0.1) {
            Ok(p) => p,
            Err(e) => panic!("{e}"),
        };
        let l0 = params.leg_length_m;
        let stroke = params.stroke_m;
        let mut checked = 0;
        for mode in [Mode::Flight, Mode::Stance, Mode::Standing] {
            for z_stuck in [false, true] {
                for z_dir in [-1.0, 1.0] {
                    for nut in [NutStop::Free, NutStop::Top, NutStop::Bottom] {
                        for cmd in [-40.0, -3.0, 0.0, 3.0, 40.0] {
                            for z in [l0 - 0.03, l0 - 1e-9, l0, l0 + 1e-9, l0 + 0.05] {
                                for p in [-1e-6, 0.0, 0.01, stroke, stroke + 1e-6] {
                                    for zd in [-1.0, 0.0, 0.5] {
                                        for pd in [-0.3, 0.0, 0.3] {
                                            plant.cfg = Config {
                                                mode,
                                                z_stuck,
                                                z_dir,
                                                nut,
                                            };
                                            plant.cmd_a = cmd;
                                            plant.cmd_limited_a =
                                                cmd.clamp(-plant.c.i_limit, plant.c.i_limit);
                                            let y = AugState::at_rest_books(&State {
                                                z_m: z,
                                                zd_mps: zd,
                                                p_m: p,
                                                pd_mps: pd,
                                            });
                                            let want = plant.first_firing_reference(&y);
                                            assert_eq!(plant.first_firing(&y), want);
                                            // With the state guards clear, the
                                            // force-guard search finds the same.
                                            let state_clear = plant
                                                .active_guards()
                                                .0
                                                .iter()
                                                .take(plant.active_guards().1)
                                                .all(|&g| {
                                                    g.depends_on_command()
                                                        || plant.guard(&y, g) <= 0.0
                                                });
                                            if state_clear {
                                                assert_eq!(
                                                    plant.first_firing_force_guards(&y),
                                                    want
                                                );
                                            }
                                            checked += 1;
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
        assert!(checked > 10_000);
    }
}
