//! `hopper-sim params`: print a parameter preset as a robot file.

use anyhow::{bail, Result};
use clap::Subcommand;
use hal_sim::params::Params;
use hal_sim::params_toml;

#[derive(Subcommand)]
pub(crate) enum ParamsCmd {
    /// Print a preset as a robot file: the firmware's entries for the
    /// machine (`[model]`, `[calibration]`, `[supervisor]`, by their names
    /// in docs/parameters.md) and the plant's own fields (`[plant]`), which
    /// `--robot`, `--params` and `hopper-link robot load` read.
    Show {
        /// Preset: design | identified
        preset: String,
    },
}

pub(crate) fn cmd_params_show(preset: &str) -> Result<()> {
    let Some(p) = Params::preset(preset) else {
        bail!(
            "unknown preset `{preset}`: expected one of {:?}",
            Params::PRESET_NAMES
        );
    };
    say_raw!("{}", params_toml::robot_toml(&p, preset));
    Ok(())
}
