//! What happens when a guard fires: the unsprung-mass impacts at touchdown
//! and liftoff, the nut's stop impacts and release, stiction, the standing
//! mode; each booked in the energy ledger and reported as an [`Event`].

use super::events::Guard;
use super::{Event, Mode, NutStop, Plant, SETTLE_SPEED_MPS};

impl Plant {
    pub(super) fn sync_ledger(&mut self) {
        self.ledger.motor_work_j = self.y.motor_work_j;
        self.ledger.friction_j = self.y.friction_work_j;
        self.ledger.damping_j = self.y.damping_work_j;
        // The resistance can change between calls: book the increment.
        let d_a2s = self.y.current_sq_a2s - self.ledger.current_squared_a2s;
        self.ledger.copper_loss_j += d_a2s * self.loss_resistance_ohm;
        self.ledger.current_squared_a2s = self.y.current_sq_a2s;
    }

    /// After `zd` reached 0 (or at the start): stick if stiction can hold the
    /// body, else slide in the direction of the net force.
    pub(super) fn decide_stick_or_slide(&mut self) {
        self.y.zd_mps = 0.0;
        let hold = self.z_hold_force(&self.cfg, &self.y);
        if self.clamped || libm::fabs(hold) <= self.friction_level(&self.cfg) {
            self.cfg.z_stuck = true;
        } else {
            self.cfg.z_stuck = false;
            // The body moves against the force that would be needed to hold it.
            self.cfg.z_dir = if hold > 0.0 { -1.0 } else { 1.0 };
        }
    }

    pub(super) fn fire(&mut self, g: Guard, on_event: &mut impl FnMut(Event)) {
        let t_s = self.t_s;
        let c = self.c;
        match g {
            Guard::StopTop | Guard::StopBottom => {
                let (stop, p) = if g == Guard::StopTop {
                    (NutStop::Top, 0.0)
                } else {
                    (NutStop::Bottom, c.stroke)
                };
                let pd = self.y.pd_mps;
                let e_before = self.energy_j();
                self.y.p_m = p;
                self.y.pd_mps = 0.0;
                // The stop's impulse acts on p only: m_zz zd - m_s pd is
                // conserved. A body held by stiction or standing is knocked
                // loose by it (stiction cannot absorb an impulse).
                // A clamp takes the impulse instead.
                let m_zz = self.m_zz(&self.cfg);
                if !self.clamped {
                    self.y.zd_mps -= c.m_nut * pd / m_zz;
                }
                self.cfg.nut = stop;
                let zd = self.y.zd_mps;
                let loss = e_before - self.energy_j();
                self.ledger.stop_impact_loss_j += loss;
                on_event(Event::StopImpact {
                    t_s,
                    stop,
                    pd_mps: pd,
                    loss_j: loss,
                });
                if zd != 0.0 {
                    self.cfg.z_stuck = false;
                    self.cfg.z_dir = if zd > 0.0 { 1.0 } else { -1.0 };
                    if self.cfg.mode == Mode::Standing {
                        self.cfg.mode = Mode::Stance;
                        if zd > 0.0 {
                            self.lift_off(on_event);
                        }
                    }
                }
            }
            Guard::Touchdown => {
                let zd = self.y.zd_mps;
                let loss = 0.5 * c.m_u * zd * zd;
                self.y.z_m = c.l0;
                self.cfg.mode = Mode::Stance;
                self.ledger.touchdown_loss_j += loss;
                on_event(Event::Touchdown {
                    t_s,
                    zd_mps: zd,
                    loss_j: loss,
                });
            }
            Guard::Liftoff => {
                self.y.z_m = c.l0;
                self.lift_off(on_event);
            }
            Guard::ZeroVelocity => {
                let rising = self.cfg.z_dir > 0.0;
                self.decide_stick_or_slide();
                if self.cfg.z_stuck {
                    on_event(Event::Stick { t_s });
                }
                match (self.cfg.mode, rising) {
                    (Mode::Flight, true) => on_event(Event::Apex {
                        t_s,
                        toe_height_m: self.y.z_m - c.l0,
                    }),
                    (Mode::Stance, false) => on_event(Event::Bottom {
                        t_s,
                        z_m: self.y.z_m,
                    }),
                    _ => {}
                }
            }
            Guard::Unstick => self.decide_stick_or_slide(),
            Guard::Release => self.cfg.nut = NutStop::Free,
            Guard::Sink => {
                self.cfg.mode = Mode::Stance;
                self.cfg.z_stuck = false;
                self.cfg.z_dir = -1.0;
            }
            Guard::Lift => {
                // The actuator pulls the whole robot off the ground from
                // rest: the unsprung mass is picked up at zero speed.
                self.cfg.mode = Mode::Flight;
                self.cfg.z_stuck = false;
                self.cfg.z_dir = 1.0;
                on_event(Event::Liftoff {
                    t_s,
                    zd_before_mps: 0.0,
                    zd_after_mps: 0.0,
                    loss_j: 0.0,
                });
            }
        }
        self.sync_ledger();
    }

    /// Liftoff impact map (from stance at `z = l0`): picks up the unsprung
    /// mass conserving vertical and `p` momentum; a crawl-speed liftoff
    /// becomes standing.
    pub(super) fn lift_off(&mut self, on_event: &mut impl FnMut(Event)) {
        let c = self.c;
        let t_s = self.t_s;
        let (zd, pd) = (self.y.zd_mps, self.y.pd_mps);
        let e_before = self.energy_j();
        if zd < SETTLE_SPEED_MPS {
            self.y.zd_mps = 0.0;
            self.cfg.mode = Mode::Standing;
            self.cfg.z_stuck = false;
            let loss = e_before - self.energy_j();
            self.ledger.settle_loss_j += loss;
            on_event(Event::Standing { t_s });
            return;
        }
        let a = c.alpha * pd - c.m_nut * zd; // p momentum
        let b = c.m_body_nut * zd - c.m_nut * pd; // vertical momentum
        let gamma = c.alpha * c.m_total - c.m_nut * c.m_nut;
        let (zd_after, pd_after) = if self.cfg.nut == NutStop::Free {
            (
                (c.alpha * b + c.m_nut * a) / gamma,
                (c.m_nut * b + c.m_total * a) / gamma,
            )
        } else {
            // Nut held by a stop (pd = 0): eq 2.40 exactly.
            (b / c.m_total, 0.0)
        };
        self.y.zd_mps = zd_after;
        self.y.pd_mps = pd_after;
        self.cfg.mode = Mode::Flight;
        self.cfg.z_dir = 1.0;
        self.cfg.z_stuck = false;
        let loss = e_before - self.energy_j();
        self.ledger.liftoff_loss_j += loss;
        on_event(Event::Liftoff {
            t_s,
            zd_before_mps: zd,
            zd_after_mps: zd_after,
            loss_j: loss,
        });
    }
}
