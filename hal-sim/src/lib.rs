//! # hal-sim: the vertical hopper in simulation, and `hopper-sim`
//!
//! The `hopper-sim` command line over the simulator's two crates:
//! `hopper-run` (running a robot: `run`, `serve`, hardware in the loop,
//! the scenario, parameter and robot files) and `hopper-study` (studying
//! designs: sweeps, Slurm arrays, the design search, endurance,
//! identification, the figures, the planar machine). Both are re-exported
//! here under their modules' names (`hal_sim::scenario`,
//! `hal_sim::sweep`, ...), with the plant's (`hal_sim::plant`,
//! `hal_sim::sim_io`, ...).

pub use hopper_run::*;
pub use hopper_study::{
    design, endurance, figures, heat_bound, identify, planar_raibert, planar_robot, planar_sim,
    planar_stability, slurm, spring, sweep,
};
