//! # hal-sim: the vertical hopper in simulation
//!
//! The host simulator around the `no_std` plant of `hopper-plant`: the
//! scenario runner, file I/O, sweeps, figures, plots and the `hopper-sim`
//! command line.
//!
//! The plant crate's modules are re-exported under their own names
//! (`hal_sim::plant`, `hal_sim::sim_io`, ...), so the simulator's users reach
//! the whole model through one crate.

pub use hopper_plant::{metrics, params, plant, sensors};
pub use hopper_sil::{robot, sim_io};

pub mod controller;
pub mod csv_out;
pub mod design;
pub mod endurance;
pub mod figures;
pub mod flight_stability;
pub mod heat_bound;
pub mod hil;
pub mod identify;
pub mod inject;
pub mod motors;
pub mod names;
pub mod out_dir;
pub mod params_toml;
pub mod planar_sim;
pub mod planar_stability;
/// The trajectory plot and the plotting helpers: the `hopper-plot` crate,
/// which `hopper-link` shares without the simulator.
pub use hopper_plot as plot;
pub mod run;
pub mod scenario;
pub mod serve;
pub mod slurm;
pub mod spring;
pub mod sweep;

pub use params::{ParamError, Params};
pub use plant::{Event, Ledger, Mode, NutStop, Plant, PlantError, State};
