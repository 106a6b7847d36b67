//! `hopper-sim`: run the vertical hopper in simulation, print parameter sets.
//!
//! ```text
//! hopper-sim run [--params design|identified|PATH.toml] [--controller NAME]
//!                [--target-apex M] [--torque NM] [--noise off|default] [--seed N]
//!                [--start-apex M] [--duration S] [--out DIR] [--json]
//!                [--scenario FILE] [--inject KIND@TIME ...]   (flags override the file)
//! hopper-sim sweep --param NAME=START:END:N [--param ...] [--metric NAME]
//!                  [--scenario FILE | --preset lead-study | run's flags] --out DIR
//! hopper-sim params show design|identified
//! hopper-sim figures --out DIR
//! ```
//!
//! Each subcommand lives in its own module (`run`, `sweep`, `serve`,
//! `spring`, `design`, `identify`, `planar`, `params`, `figures`);
//! `common` holds the run settings that `run`, `sweep` and `serve` share.

/// `println!` that hands a write error to the caller (`?`) instead of
/// panicking, so that a closed stdout (`hopper-sim run | head`) ends the
/// command quietly (see [`is_closed_pipe`]).
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout().lock(), $($arg)*)?
    }};
}

/// [`say!`] without the newline.
macro_rules! say_raw {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        write!(std::io::stdout().lock(), $($arg)*)?
    }};
}

mod common;
mod design;
mod figures;
mod identify;
mod params;
mod planar;
#[cfg(feature = "live-page")]
mod planar_serve;
mod run;
mod serve;
mod spring;
mod sweep;

use clap::{Parser, Subcommand};
use design::{cmd_design, DesignCmd};
use figures::{cmd_endurance, cmd_figures};
use identify::{cmd_identify, IdentifyArgs};
use params::{cmd_params_show, ParamsCmd};
use planar::{cmd_planar, PlanarCmd};
use run::{cmd_run, RunArgs};
use serve::{cmd_serve, ServeArgs};
use spring::{cmd_spring, SpringArgs};
use std::path::PathBuf;
use sweep::{cmd_sweep, SweepArgs};

#[derive(Parser)]
#[command(
    name = "hopper-sim",
    version,
    about = "Simulate the electrically actuated one-legged hopper (vertical model, thesis ch. 2.1)"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Drop the hopper from a start apex and run a controller; prints a summary.
    Run(RunArgs),
    /// Run a grid of runs (one or two swept parameters) in parallel; writes
    /// sweep.csv and a plot (sweep.png, sweep.svg).
    Sweep(SweepArgs),
    /// The virtual robot: the firmware on the simulated hopper behind the
    /// link protocol on a TCP socket, in real time, for `hopper-link`
    /// (docs/link.md). It boots disarmed and standing, like the board.
    Serve(ServeArgs),
    /// Design a leg spring (thesis section 3.2, eqs 3.1-3.7): coils,
    /// pitch, lengths, stresses, allowable forces and stroke; optionally
    /// checked against the peak spring force of a simulated hop.
    Spring(SpringArgs),
    /// The actuator studies of thesis section 3.1 on the motor's own
    /// torque-speed curve (docs/design.md): `motors` (Table 3.1) and
    /// `leads` (Figures 3.1-3.3).
    Design {
        #[command(subcommand)]
        cmd: DesignCmd,
    },
    /// Identify plant parameters from a recorded hop (thesis section 4.5):
    /// a passive hop gives the planarizer and leg friction, an open-torque
    /// hop the effective stance torque and the nut mass (docs/design.md).
    Identify(IdentifyArgs),
    /// The planar one-legged runner of thesis section 2.2 (Table 2.2,
    /// passive dynamics and the forward-speed stabiliser of eq 2.79).
    Planar {
        #[command(subcommand)]
        cmd: PlanarCmd,
    },
    /// How long every law hops before the motor derates, at apexes from 3
    /// to 15 cm (each released at its target): prints the table (time to
    /// the derating, copper loss per hop) and with --out draws it
    /// (endurance.png, endurance.svg) beside the bound (docs/endurance.md).
    Endurance {
        /// Plant parameters: a preset (design, identified).
        #[arg(long, default_value = "design")]
        params: String,
        /// A catalogue motor on the plant, its thermal data in the firmware,
        /// as `run --motor` (design, re40, pittman-14204).
        #[arg(long, value_parser = hal_sim::motors::named, value_name = "NAME", conflicts_with = "bound")]
        motor: Option<&'static hal_sim::motors::CatalogueMotor>,
        /// Simulated time of each run, s.
        #[arg(long, default_value_t = 120.0)]
        duration: f64,
        /// The bound's longest endurance per apex, a CSV file with the header
        /// `apex_m,endurance_s` (the last-but-one column of the table
        /// `cargo run --release -p hal-sim --example heat_bound` prints;
        /// docs/img/endurance/bound.csv has it, for the design motor), drawn
        /// dashed.
        #[arg(long)]
        bound: Option<PathBuf>,
        /// Directory for endurance.png and endurance.svg (created if missing).
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Parameter sets.
    Params {
        #[command(subcommand)]
        cmd: ParamsCmd,
    },
    /// Regenerate the simulation counterparts of the thesis's Figures 2.4-2.13
    /// and 4.4-4.9 as PNG and SVG (see docs/thesis-comparison.md).
    Figures {
        /// Directory for fig-2-4.png, fig-2-4.svg, ... (created if missing).
        #[arg(long)]
        out: PathBuf,
        /// Short runs (0.3 s of hopping) for quick checks.
        #[arg(long, hide = true)]
        quick: bool,
    },
}

fn main() {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => bad_command_line(e),
    };
    let result = match cli.cmd {
        Cmd::Run(args) => cmd_run(args),
        Cmd::Sweep(args) => cmd_sweep(args),
        Cmd::Serve(args) => cmd_serve(args),
        Cmd::Params {
            cmd: ParamsCmd::Show { preset },
        } => cmd_params_show(&preset),
        Cmd::Figures { out, quick } => cmd_figures(&out, quick),
        Cmd::Endurance {
            params,
            motor,
            duration,
            bound,
            out,
        } => cmd_endurance(&params, motor, duration, bound.as_deref(), out.as_deref()),
        Cmd::Spring(args) => cmd_spring(&args),
        Cmd::Design { cmd } => cmd_design(&cmd),
        Cmd::Identify(args) => cmd_identify(&args),
        Cmd::Planar { cmd } => cmd_planar(&cmd),
    };
    if let Err(e) = result {
        if is_closed_pipe(&e) {
            // The reader has all it wanted (`| head`): not an error, as for
            // any Unix filter whose reader went away.
            return;
        }
        eprintln!("hopper-sim: error: {e:#}");
        std::process::exit(2);
    }
}

/// Whether `e` is a write to a stdout whose reader has closed it. Rust
/// ignores SIGPIPE, so such a write fails with `BrokenPipe` instead of
/// ending the process the way the shell expects.
fn is_closed_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Help and version go out as clap prints them; any other command-line error
/// becomes one `hopper-sim: error:` line (clap's first line and its tip, if
/// any) with exit status 2, like every other bad input, instead of clap's
/// several-line usage block.
fn bad_command_line(e: clap::Error) -> ! {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        e.exit();
    }
    let text = e.render().to_string();
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    let first = lines.next().unwrap_or("invalid command line");
    let first = first.strip_prefix("error: ").unwrap_or(first);
    let tip = lines
        .find_map(|l| l.strip_prefix("tip: "))
        .map(|t| format!("; {t}"))
        .unwrap_or_default();
    eprintln!("hopper-sim: error: {first}{tip} (see `hopper-sim --help`)");
    std::process::exit(2);
}
