//! # hal-sim: the vertical hopper in simulation
//!
//! The plant the firmware controls, modelled after thesis chapter 2.1 with the
//! errata of `shared/MODEL.md` applied ([`plant`]), its parameter sets
//! ([`params`]), and, with the `std` feature, the scenario runner, file I/O,
//! plots and the `hopper-sim` command line.
//!
//! Without the `std` feature the crate is `no_std` (math through `libm`), so
//! the same plant links into the QEMU firmware image.
#![cfg_attr(not(feature = "std"), no_std)]

pub mod metrics;
pub mod mock;
pub mod params;
pub mod plant;
pub mod sensors;

#[cfg(feature = "std")]
pub mod controller;
#[cfg(feature = "std")]
pub mod figures;
#[cfg(feature = "std")]
pub mod flight_stability;
#[cfg(feature = "std")]
pub mod inject;
#[cfg(feature = "std")]
pub mod out_dir;
#[cfg(feature = "std")]
pub mod params_toml;
#[cfg(feature = "std")]
pub mod plot;
#[cfg(feature = "std")]
pub mod run;
#[cfg(feature = "std")]
pub mod scenario;
#[cfg(feature = "std")]
pub mod sweep;

pub use params::{ParamError, Params};
pub use plant::{Event, Ledger, Mode, NutStop, Plant, PlantError, State};
