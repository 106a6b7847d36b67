//! Portable control code for the electrically actuated one-legged hopper.
//!
//! This crate is the part of the controller firmware that does not know which
//! machine it runs on. It is `#![no_std]`, allocation-free and panic-free, works
//! in `f32` SI units (names carry unit suffixes: `_m`, `_mps`, `_n`, `_nm`,
//! `_rad`, `_s`, `_a`), and is compiled both into the STM32F405 firmware
//! (`hopper-app`) and into host-side simulations and tests.
//!
//! Equation numbers refer to the thesis (`thesis.md`); where it is ambiguous
//! or wrong, `MODEL.md` records the reading used here.
//!
//! Contents:
//! - [`hal`]: the I/O trait ([`hal::HopperIo`]) the board and the simulator implement;
//! - [`calibration`]: raw counts and codes to SI, current to DAC code;
//! - [`filter`]: the filtered derivative of thesis eq 4.1;
//! - [`estimator`]: flight/stance phase, touchdown, liftoff, apex, bottom;
//! - [`energy`]: the energy estimate of eqs 2.44-2.45;
//! - [`model`]: the parameters the controller believes and `E_D` (eq 2.43);
//! - [`laws`]: every thesis stance law and the flight PD (eq 4.4);
//! - [`pd_design`]: flight PD gain design (eqs 4.3-4.18);
//! - [`supervisor`]: latched faults and the current clamp;
//! - [`telemetry`]: the per-step record ring and the per-hop ledger;
//! - [`hopper`]: the whole control period, [`hopper::Hopper::step`].
#![no_std]

pub mod calibration;
pub mod energy;
pub mod estimator;
pub mod filter;
pub mod hal;
pub mod hopper;
pub mod laws;
pub mod model;
pub mod pd_design;
pub mod supervisor;
pub mod telemetry;
