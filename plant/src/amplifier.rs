//! The servo amplifier's supply window (MODEL.md): a current-mode
//! amplifier on a supply of `V` drives the current it is told to only
//! while the supply can push it against the motor's back-EMF,
//! `|R i + k_e omega| <= V` (`k_e = k_t` in SI units, `omega = p' / r` for
//! a motor turning a ball screw whose nut moves at `p'`): the motor's
//! torque-speed limit. The vertical hopper's plant and the planar
//! machine's screw-driven leg both drive their motors through it.

/// The supply's window on the current for one motor and screw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupplyWindow {
    /// The supply `V`, volts.
    supply_v: f64,
    /// `k_t / r`: back-EMF per unit nut speed, V s/m.
    kt_over_r: f64,
    /// `1 / R`, 1/ohm.
    inv_resistance: f64,
}

impl SupplyWindow {
    /// The window of a motor of torque constant `torque_constant_nm_per_a`
    /// and winding `winding_ohm` on a screw of `screw_m_per_rad`, driven
    /// from `supply_voltage_v` (all positive: the callers' parameters are
    /// validated).
    pub fn new(
        torque_constant_nm_per_a: f64,
        screw_m_per_rad: f64,
        winding_ohm: f64,
        supply_voltage_v: f64,
    ) -> Self {
        // Reciprocals once, so that the derivative evaluation (four per RK4
        // step) has no division.
        SupplyWindow {
            supply_v: supply_voltage_v,
            kt_over_r: torque_constant_nm_per_a / screw_m_per_rad,
            inv_resistance: 1.0 / winding_ohm,
        }
    }

    /// The current the amplifier delivers, A, for a command already
    /// clipped to its current limit, with the nut at `pd_mps`: clipped
    /// further to what the supply can drive against the back-EMF.
    #[inline(always)]
    pub fn current_a(&self, cmd_limited_a: f64, pd_mps: f64) -> f64 {
        let back_emf = self.kt_over_r * pd_mps;
        let hi = (self.supply_v - back_emf) * self.inv_resistance;
        let lo = (-self.supply_v - back_emf) * self.inv_resistance;
        // `clamp(lo, hi)` (lo < hi: R > 0, V > 0), as a branch rather than
        // min/max: the supply limit is rarely reached, so the processor
        // predicts the command and does not wait for the nut speed.
        if cmd_limited_a > hi || cmd_limited_a < lo {
            supply_limited(cmd_limited_a, lo, hi)
        } else {
            cmd_limited_a
        }
    }
}

/// The current the supply voltage allows when it limits the command, A.
#[cold]
#[inline(never)]
fn supply_limited(cmd_a: f64, lo: f64, hi: f64) -> f64 {
    cmd_a.max(lo).min(hi)
}
