//! # hopper-run: running a robot in simulation
//!
//! The firmware's control crate on the `no_std` plant of `hopper-plant`,
//! as a user running a robot sees it: one run (`hopper-sim run`: the
//! controller on the simulated sensors and amplifier, its summary, plot
//! and recording), the scenario, parameter and robot files it reads, the
//! catalogue motors, the virtual robot behind the link (`hopper-sim
//! serve`) and hardware in the loop's host end (`run --hil`). Studying
//! designs over many runs is `hopper-study`'s; the `hopper-sim` command
//! line is `hal-sim`'s, over both.
//!
//! The plant crate's modules are re-exported under their own names
//! (`plant`, `sim_io`, ...), so the simulator's users reach the whole model
//! through one crate.

pub use hopper_plant::{metrics, params, plant, sensors};
pub use hopper_sil::{robot, sim_io};

pub mod controller;
pub mod csv_out;
pub mod flight_stability;
pub mod hil;
pub mod inject;
pub mod motors;
pub mod names;
pub mod out_dir;
pub mod params_toml;
/// The trajectory plot and the plotting helpers: the `hopper-plot` crate,
/// which `hopper-link` shares without the simulator.
pub use hopper_plot as plot;
pub mod run;
pub mod scenario;
pub mod serve;

pub use params::{ParamError, Params};
pub use plant::{Event, Ledger, Mode, NutStop, Plant, PlantError, State};
