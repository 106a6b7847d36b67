//! `hopper-sim params`: print a parameter preset as TOML.

use anyhow::{bail, Result};
use clap::Subcommand;
use hal_sim::params::Params;
use hal_sim::params_toml;

#[derive(Subcommand)]
pub(crate) enum ParamsCmd {
    /// Print a preset as TOML that `--params PATH.toml` accepts.
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
    say_raw!("{}", params_toml::to_toml(&p, preset));
    Ok(())
}
