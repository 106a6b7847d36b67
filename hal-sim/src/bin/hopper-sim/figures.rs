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

/// `hopper-sim endurance`: every law's time to the derating at every apex.
pub(crate) fn cmd_endurance(
    preset: &str,
    motor: Option<&'static hal_sim::motors::CatalogueMotor>,
    duration_s: f64,
    bound: Option<&std::path::Path>,
    out: Option<&std::path::Path>,
) -> Result<()> {
    use hal_sim::endurance;
    let bound = match bound {
        Some(path) => endurance::read_bound(path).map_err(anyhow::Error::msg)?,
        None => Vec::new(),
    };
    let cells = endurance::table(preset, motor, duration_s).map_err(anyhow::Error::msg)?;
    let machine = match motor {
        Some(m) => format!("{preset}+{}", m.name),
        None => preset.to_string(),
    };
    say!(
        "hopper-sim: time to the derating temperature and copper loss per hop (mean 3-8 s), {machine} parameters, {duration_s} s runs released at the target"
    );
    say!("{}", endurance::markdown(&cells).trim_end());
    if let Some(dir) = out {
        let derate_c = hopper_control::thermal::ThermalConfig::default().derate_winding_c;
        let caption = match motor {
            Some(m) => format!(
                "Time to the motor's derating ({derate_c:.0} C), {preset} machine, motor {}",
                m.name
            ),
            None => format!(
                "Time to the motor's derating ({derate_c:.0} C), {preset} machine, stand-in motor"
            ),
        };
        let files = endurance::plot(&cells, &bound, &caption, dir).map_err(anyhow::Error::msg)?;
        for f in files {
            say!("  wrote {}", dir.join(f).display());
        }
    }
    Ok(())
}
