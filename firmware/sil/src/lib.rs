//! # hopper-sil: the firmware in the loop with the simulated hopper
//!
//! What joins the firmware's control crate to the plant: the simulated
//! hardware ([`sim_io`]: the plant seen through the sensor, DAC and
//! amplifier models, behind the firmware's `HopperIo` trait, and the
//! firmware configuration for a plant) and the virtual robot ([`robot`]:
//! the period runner and the link's endpoint on it, behind a byte link).
//! `hopper-sim`, the SIL tests and the QEMU images run these; the plant
//! itself (`hopper-plant`) knows nothing of the firmware.
//!
//! `no_std` and allocation-free: the QEMU images link it.
#![cfg_attr(not(test), no_std)]

pub mod planar;
pub mod robot;
pub mod sim_io;
