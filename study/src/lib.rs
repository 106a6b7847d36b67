//! # hopper-study: studying designs in simulation
//!
//! What a user studying a design runs, each over many of `hopper-run`'s
//! runs: sweeps (`hopper-sim sweep`, on every core or as a Slurm array),
//! the actuator studies and the design search of thesis section 3.1
//! (`design`), endurance and its bound (`endurance`, `heat_bound`), the
//! identification fit (`identify`), the spring sweep on the bench's
//! model (`spring`), the thesis's figures (`figures`) and the planar
//! machine (`planar_sim`, `planar_stability`).

// The runs these studies are made of, under the names the modules use.
pub(crate) use hopper_run::{
    controller, csv_out, motors, names, out_dir, params, params_toml, plant, plot, run, scenario,
    sim_io, Event, Params,
};

pub mod design;
pub mod endurance;
pub mod figures;
pub mod heat_bound;
pub mod identify;
pub mod planar_raibert;
pub mod planar_robot;
pub mod planar_sim;
pub mod planar_stability;
pub mod slurm;
pub mod spring;
pub mod sweep;
