//! Controllers the simulator can run against the plant.
//!
//! For now the simulator runs on the true plant state; the firmware's control
//! crate, behind the mock HAL and sensor models, plugs in here later.

use crate::plant::Plant;

/// Computes the amplifier current command once per control period.
pub trait Controller {
    /// Short name, as accepted by `hopper-sim run --controller`.
    fn name(&self) -> &'static str;
    /// Current command for the coming period, A.
    fn current_command_a(&mut self, plant: &Plant) -> f64;
}

/// The thesis's passive hopping (section 4.4.1): the motor is off and the
/// spring preload holds the ball nut on its upper mechanical stop, its start
/// position `p = 0`, so the leg acts as a fixed spring.
#[derive(Clone, Copy, Debug, Default)]
pub struct Passive;

impl Controller for Passive {
    fn name(&self) -> &'static str {
        "passive"
    }
    fn current_command_a(&mut self, _plant: &Plant) -> f64 {
        0.0
    }
}

/// Controller names `hopper-sim run --controller` accepts.
pub const CONTROLLER_NAMES: [&str; 1] = ["passive"];

/// Build a controller by name.
pub fn by_name(name: &str) -> Option<Box<dyn Controller>> {
    match name {
        "passive" => Some(Box::new(Passive)),
        _ => None,
    }
}
