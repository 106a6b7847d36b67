//! # hopper-plant: the vertical hopper's plant and sensors
//!
//! The plant the firmware controls, modelled after thesis chapter 2.1 with the
//! errata of `shared/MODEL.md` applied ([`plant`]), its parameter sets
//! ([`params`]), the sensor, DAC and amplifier models ([`sensors`]) and the
//! hop metrics ([`metrics`], re-exported from `hopper-model`). It knows
//! nothing of the firmware: the physical facts it shares with the
//! controller come from `hopper-model`, and the firmware runs on it
//! through `hopper-sil`.
//!
//! `no_std` (math through `libm`) and allocation-free, so the same plant
//! links into the QEMU firmware image; the host simulator (`hal-sim`, the
//! `hopper-sim` CLI) builds on it.
#![cfg_attr(not(test), no_std)]

pub mod amplifier;
pub mod params;
pub mod planar;
pub mod planar_general;
pub mod planar_screw;
pub mod plant;
pub mod sensors;

/// The hop metrics, defined in `hopper-model` (shared with `hopper-link`).
pub use hopper_model::metrics;
pub use params::{ParamError, Params};
pub use plant::{Event, Ledger, Mode, NutStop, Plant, PlantError, State};
