//! `hopper-sim figures`: regenerate the simulation counterparts of the
//! thesis's figures as PNG and SVG.

use anyhow::Result;

pub(crate) fn cmd_figures(out: &std::path::Path, quick: bool) -> Result<()> {
    let opts = hal_sim::figures::FigureOptions { quick };
    let report = hal_sim::figures::write_all(out, &opts).map_err(anyhow::Error::msg)?;
    for n in &report.notes {
        say!("{n}");
    }
    say!(
        "hopper-sim: wrote {} files to {}",
        report.files.len(),
        out.display()
    );
    Ok(())
}
