//! `hopper-sim sweep`: a grid of runs in parallel (whole or sharded), and
//! `sweep merge` to combine a sharded sweep's parts.

use crate::common::{resolve, BaseArgs};
use anyhow::{bail, Result};
use clap::{Parser, Subcommand};
use hal_sim::scenario;
use hal_sim::sweep::{self, Sweep};
use std::path::PathBuf;

#[derive(Parser)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub(crate) struct SweepArgs {
    /// `merge`: combine the parts of a sharded sweep.
    #[command(subcommand)]
    cmd: Option<SweepCmd>,
    #[command(flatten)]
    base: BaseArgs,
    /// A swept parameter, NAME=START:END:N (N values from START to END);
    /// repeat for a second one. NAME: a plant parameter (e.g. screw_lead_m)
    /// or torque, target_apex, start_apex, ke, flight_kp, flight_kd, seed
    /// (the noise seed: the same run under different noise), and for the
    /// shaped controller spin_up, switch, brake, level_ki, level_kp,
    /// braking_margin, integral_start.
    #[arg(long = "param")]
    param: Vec<String>,
    /// A named sweep instead of --scenario: lead-study (thesis Figures
    /// 3.1-3.3, the energy the motor adds in the first stance against the
    /// ball-screw lead).
    #[arg(long, conflicts_with = "scenario")]
    preset: Option<String>,
    /// Metric to plot: a sweep.csv column [default: the scenario's, else
    /// steady_apex_m, falling back to the last apex where not steady].
    #[arg(long)]
    metric: Option<String>,
    /// Run only slice K of N of the grid (1 <= K <= N: diagonal stripes,
    /// the points whose row and last-axis indexes sum to K-1 modulo N, so
    /// that every slice gets values of both axes) and write its part (sweep-part.csv and
    /// sweep-part.json) into --out; `sweep merge` combines the N parts into
    /// the sweep.csv and plots of the whole grid (docs/design.md, "Sweeps
    /// past one machine").
    #[arg(long, value_name = "K/N")]
    shard: Option<String>,
    /// Write the grid as a Slurm job array of N tasks instead of running
    /// it: --out gets sweep.sbatch (task K runs --shard K/N into
    /// parts/K, its log in logs/shard-K.log) and merge.sbatch (the parts
    /// into --out once every task succeeded); submit with `sbatch`
    /// (docs/design.md, "Sweeps past one machine").
    #[arg(long, value_name = "N", conflicts_with = "shard")]
    slurm: Option<usize>,
    /// Directory for sweep.csv, sweep.png and sweep.svg (created if missing).
    #[arg(long, required = true)]
    out: Option<PathBuf>,
}

#[derive(Subcommand)]
enum SweepCmd {
    /// Combine the parts of a sharded sweep (`sweep --shard K/N --out
    /// PART_DIR`, every K of the same N) into the sweep.csv and plots an
    /// unsharded run of the grid writes.
    Merge {
        /// The parts' directories, in any order.
        #[arg(required = true, value_name = "PART_DIR")]
        parts: Vec<PathBuf>,
        /// Directory for sweep.csv, sweep.png and sweep.svg (created if
        /// missing).
        #[arg(long)]
        out: PathBuf,
    },
}

/// `1 thread`, `2 threads`.
fn threads(n: usize) -> String {
    match n {
        1 => "1 thread".to_string(),
        n => format!("{n} threads"),
    }
}

/// Most points a sweep prints one line each for; a bigger grid gets the
/// tally only (sweep.csv has every point).
const TABLE_ROWS: usize = 40;

/// A finished sweep's table (small grids) and its tally: each point's
/// metric and whether it converged, derated or faulted.
fn print_table(sw: &Sweep, rows: &[sweep::Row]) -> Result<()> {
    if rows.len() <= TABLE_ROWS {
        for line in sw.text_table(rows) {
            say!("{line}");
        }
    }
    say!("  {}", sweep::tally(rows, sw.about_the_apex()));
    Ok(())
}

fn cmd_sweep_merge(parts: &[PathBuf], out: &std::path::Path) -> Result<()> {
    let (sw, rows, title) = sweep::merge(parts).map_err(anyhow::Error::msg)?;
    let written = sw.write(&rows, out, &title).map_err(anyhow::Error::msg)?;
    say!(
        "hopper-sim sweep merge: {} parts, {} runs",
        parts.len(),
        rows.len()
    );
    print_table(&sw, &rows)?;
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}

/// `--slurm N`: the grid's job scripts, every shard's points checked first
/// (a grid that cannot run writes nothing).
fn write_slurm_job(sw: &Sweep, tasks: usize, out: &std::path::Path) -> Result<()> {
    let grid_runs: usize = sw.axes.iter().map(|x| x.values.len()).product();
    if tasks == 0 || tasks > grid_runs {
        bail!("--slurm {tasks}: the grid has {grid_runs} runs; give 1 to {grid_runs} tasks");
    }
    let sizes = sw.slice_sizes(tasks).map_err(anyhow::Error::msg)?;
    let most = sizes.iter().copied().max().unwrap_or(0);
    let here = std::env::current_dir()?;
    let argv: Vec<String> = std::env::args().collect();
    let after = argv
        .iter()
        .position(|a| a == "sweep")
        .map_or(&argv[..0], |i| &argv[i + 1..]);
    let job = hal_sim::slurm::Job {
        tasks,
        grid_args: hal_sim::slurm::grid_args(after),
        exe: std::env::current_exe()?,
        workdir: here.clone(),
        out: here.join(out),
    };
    job.write().map_err(anyhow::Error::msg)?;
    // The files as the user named the directory (the scripts hold it
    // absolute).
    let (array, merge) = (
        out.join(hal_sim::slurm::ARRAY_SCRIPT),
        out.join(hal_sim::slurm::MERGE_SCRIPT),
    );
    say!(
        "hopper-sim sweep: a Slurm job array of {tasks} tasks for {grid_runs} runs of {} s (at most {most} a task)",
        sw.base.duration_s
    );
    say!("  wrote {}", array.display());
    say!("  wrote {}", merge.display());
    say!("  submit: job=$(sbatch --parsable {})", array.display());
    say!(
        "          sbatch --dependency=afterok:$job {}",
        merge.display()
    );
    Ok(())
}

pub(crate) fn cmd_sweep(a: SweepArgs) -> Result<()> {
    if let Some(SweepCmd::Merge { parts, out }) = &a.cmd {
        return cmd_sweep_merge(parts, out);
    }
    let Some(out) = a.out.clone() else {
        bail!("--out DIR is required");
    };
    let shard = a
        .shard
        .as_deref()
        .map(sweep::Shard::parse)
        .transpose()
        .map_err(anyhow::Error::msg)?;
    // Everything is parsed and every grid point checked before any run or
    // any file: bad input writes nothing.
    let file = match &a.preset {
        Some(name) => {
            let Some((_, text)) = sweep::PRESETS.iter().find(|(n, _)| n == name) else {
                let names: Vec<&str> = sweep::PRESETS.iter().map(|(n, _)| *n).collect();
                bail!("unknown sweep preset `{name}`: expected one of {names:?}");
            };
            Some(
                scenario::from_toml_str(text, &format!("scenarios/{name}.toml"))
                    .map_err(anyhow::Error::msg)?,
            )
        }
        None => a.base.scenario()?,
    };
    let base = resolve(file.as_ref(), &a.base)?;
    let specs: Vec<String> = if a.param.is_empty() {
        file.as_ref()
            .map(|f| f.sweep.params.clone())
            .unwrap_or_default()
    } else {
        a.param.clone()
    };
    if specs.is_empty() {
        bail!(
            "nothing to sweep: give --param NAME=START:END:N (or a scenario with a [sweep] table)"
        );
    }
    let axes = specs
        .iter()
        .map(|s| sweep::parse_axis(s))
        .collect::<Result<Vec<_>, _>>()
        .map_err(anyhow::Error::msg)?;
    let metric = a
        .metric
        .clone()
        .or_else(|| file.as_ref().and_then(|f| f.sweep.metric.clone()))
        .unwrap_or_else(|| sweep::DEFAULT_METRIC.to_string());
    let sw = Sweep { base, axes, metric };
    if let Some(tasks) = a.slurm {
        return write_slurm_job(&sw, tasks, &out);
    }
    let slice = shard.unwrap_or(sweep::Shard::WHOLE);
    let runs = sw.shard_points(slice).map_err(anyhow::Error::msg)?.len();
    let grid_runs: usize = sw.axes.iter().map(|x| x.values.len()).product();

    // A progress bar for sweeps worth waiting for; indicatif also draws
    // nothing when stderr is not a terminal.
    let bar = indicatif::ProgressBar::new(runs as u64);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} sweep [{bar:40}] {pos}/{len} runs ({eta} left)",
        )
        .map_err(anyhow::Error::msg)?
        .progress_chars("=> "),
    );
    if runs as f64 * sw.base.duration_s < 60.0 {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    let started = std::time::Instant::now();
    let indexed = sw
        .run_shard(slice, &|| bar.inc(1))
        .map_err(anyhow::Error::msg)?;
    bar.finish_and_clear();
    let elapsed_s = started.elapsed().as_secs_f64();

    let swept: Vec<&str> = sw.axes.iter().map(|x| x.knob.column()).collect();
    // A sweep run without the motor's thermal protection says so.
    let protect_off = sw
        .base
        .firmware_params
        .iter()
        .rev()
        .find(|(p, _)| p.name == hopper_control::params::THERMAL_PROTECT.name)
        .is_some_and(|(_, v)| *v == 0.0);
    let title = format!(
        "{} sweep: {} controller, {} parameters{}",
        swept.join(" x "),
        sw.base.controller,
        sw.base.params_name,
        if protect_off {
            ", no motor thermal limit"
        } else {
            ""
        }
    );
    if let Some(k) = shard {
        let written = sw
            .write_part(k, &indexed, &out, &title)
            .map_err(anyhow::Error::msg)?;
        say!(
            "hopper-sim sweep: shard {}/{}: {runs} of {grid_runs} runs of {} s in {elapsed_s:.1} s on {}",
            k.index,
            k.count,
            sw.base.duration_s,
            threads(rayon::current_num_threads())
        );
        for p in &written {
            say!("  wrote {}", p.display());
        }
        return Ok(());
    }
    let rows: Vec<sweep::Row> = indexed.into_iter().map(|(_, r)| r).collect();
    let written = sw.write(&rows, &out, &title).map_err(anyhow::Error::msg)?;

    say!(
        "hopper-sim sweep: {runs} runs of {} s ({} controller, {} parameters) in {elapsed_s:.1} s on {}",
        sw.base.duration_s,
        sw.base.controller,
        sw.base.params_name,
        threads(rayon::current_num_threads())
    );
    print_table(&sw, &rows)?;
    for p in &written {
        say!("  wrote {}", p.display());
    }
    Ok(())
}
