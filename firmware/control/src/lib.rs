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
//! Contents so far:
//! - [`filter`]: the filtered derivative of thesis eq 4.1, used to turn
//!   encoder and potentiometer positions into velocities.
//! - [`pd_design`]: flight-phase PD gain design for the motor position loop,
//!   plant `A / s^2` (thesis section 4.3, eqs 4.3-4.18).
//!
//! Later work adds here the hardware-abstraction trait the firmware and the
//! simulator both implement, the state/energy estimator, the stance and flight
//! control laws, and the supervisor (phase detection, limits, fault handling).
#![no_std]

pub mod calibration;
pub mod energy;
pub mod estimator;
pub mod filter;
pub mod hal;
pub mod laws;
pub mod model;
pub mod pd_design;
pub mod supervisor;
pub mod telemetry;
