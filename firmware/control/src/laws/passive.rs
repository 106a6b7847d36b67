//! Passive hopping (thesis section 4.4.1): the motor off, 0 A in every
//! phase; the leg acts as a fixed spring with the nut on its upper stop.

use super::{ControlInput, ControlLaw, EventInput};

/// The passive controller. No configuration, no state.
#[derive(Debug, Clone, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Passive;

impl ControlLaw for Passive {
    fn on_event(&mut self, _event: &EventInput) {}

    #[inline]
    fn current_a(&mut self, _x: &ControlInput) -> f32 {
        0.0
    }
}
