//! `hopper-link`: operate the hopper from a host. One client for
//! the board (`--serial PORT`), the QEMU image and the simulator's virtual
//! robot (`--tcp ADDR`). See docs/operate.md and
//! docs/link.md.

mod cmd;

use anyhow::{anyhow, bail, Context, Result};
use clap::{Parser, Subcommand};
use cmd::{
    arm, calibrate, dump, flood, params, record, robot, save, silence, sim, status, ui, wait, watch,
};
use hopper_link::{Client, Target};
use std::io::{BufRead, Write};
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    name = "hopper-link",
    version,
    about = "Operate the hopper over its link: status, parameters, arming, recording, watch, dump"
)]
// One group for the robot's address, so that clap's errors about it (none
// given, both given) name both ways of giving it.
#[command(group(clap::ArgGroup::new("robot").args(["tcp", "serial"]).required(true)))]
struct Cli {
    /// The robot on a TCP address (QEMU's -serial tcp:, `hopper-sim serve`).
    #[arg(long, value_name = "HOST:PORT", value_parser = clap::builder::NonEmptyStringValueParser::new())]
    tcp: Option<String>,
    /// The robot on a serial port (the board's USART1 through a USB-UART
    /// adapter, e.g. /dev/ttyUSB0).
    #[arg(long, value_name = "PORT", value_parser = clap::builder::NonEmptyStringValueParser::new())]
    serial: Option<String>,
    /// Baud rate of --serial (the firmware's USART1 runs at 921,600).
    #[arg(long, default_value_t = 921_600)]
    baud: u32,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// State, faults, sensors, link counts and timing.
    Status,
    /// The parameter table on the robot.
    Params {
        #[command(subcommand)]
        cmd: ParamsCmd,
    },
    /// Enable the amplifier and run the selected controller (refused with
    /// the reason unless no fault is latched, the e-stop is released, the
    /// nut is home and the robot is still, and homed and tared since boot
    /// where `arming.require_home` and `arming.require_tare` are set:
    /// `status` says what this robot needs). The link must stay up: use it
    /// inside `shell`, or the robot disarms 0.2 s after this command exits.
    Arm {
        /// Ask again until accepted or this many wall seconds passed (e.g.
        /// while the robot settles after a disarm).
        #[arg(long, value_name = "SECONDS")]
        retry: Option<f64>,
    },
    /// 0 A and the amplifier off; prints the next telemetry record.
    Disarm,
    /// Clear the latched faults, only while disarmed and only when every
    /// one's cause is gone (otherwise nothing is cleared and the faults
    /// whose cause remains are named).
    ResetFaults {
        /// Ask again until accepted or this many wall seconds passed (e.g.
        /// while the e-stop's release is debounced on a slow robot).
        #[arg(long, value_name = "SECONDS")]
        retry: Option<f64>,
    },
    /// Record telemetry and hop ledgers: telemetry.csv (units in the
    /// headers), hops.csv, telemetry.mcap and hop.png (from two records on)
    /// in DIR.
    Record {
        /// Robot time to record, s.
        #[arg(long)]
        duration: f64,
        /// Records per second (at most the control rate).
        #[arg(long, default_value_t = 1000.0)]
        rate: f64,
        /// Directory for the files (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// A live status line: state, faults, last apex, height, nut, force,
    /// current, drops (Ctrl-C to stop).
    Watch {
        /// Stop after this many seconds (wall clock).
        #[arg(long)]
        duration: Option<f64>,
    },
    /// The capture around the last fault (frozen when it latched): capture.csv
    /// and capture.png in DIR.
    Dump {
        /// Directory for the files (created if missing).
        #[arg(long)]
        out: PathBuf,
    },
    /// Run a bring-up routine on the robot, disarmed. On a new robot, in
    /// this order (the book's Bring-up page): `sensors` (raw codes, noise,
    /// still encoders), then on the hoist with the toe free `direction` (a
    /// current pulse: motor, encoder and load cell the right way round),
    /// `home` (the nut to its upper stop, the motor encoder zeroed there),
    /// `tare` (load-cell tare and potentiometer zero), `spring` (a nut
    /// sweep: the spring rate by least squares) and `tare` again; then
    /// standing on the toe `weight` (a nut sweep lifting and lowering the
    /// body: the weight, hence the load cell's gain, and the stance
    /// friction) and `height` (the height encoder's zero); then `save`.
    /// `direction`, `home`, `spring` and `weight` drive the motor at up to
    /// `bringup.current_limit_a`.
    Calibrate {
        /// sensors | tare | direction | home | spring | height | weight
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(
            hopper_protocol::vocab::Routine::ALL.iter().map(|r| r.name())
        ))]
        routine: String,
        /// How long `sensors`, `tare` and `height` measure, s of robot time
        /// (0.01 to 10); the routines that drive the motor end with their
        /// moves.
        #[arg(long, default_value_t = 0.5)]
        seconds: f32,
    },
    /// Move the simulated robot (QEMU and `hopper-sim serve` only; a real
    /// robot refuses): `hoist` clamps the body and lifts it until the toe
    /// is `--toe` above the ground (at 0.1 m/s); `release` lets go.
    Mount {
        /// hoist | release
        #[arg(value_parser = ["hoist", "release"])]
        action: String,
        /// Toe height to lift to, m.
        #[arg(long, default_value_t = 0.05)]
        toe: f32,
    },
    /// Save the machine's constants and calibration (the `model.*` and
    /// `calibration.*` parameters but the height zero, which is per boot,
    /// and the spring's rate and preload: what a robot file and the
    /// bring-up routines set) to the robot's flash, to load at every boot;
    /// refused while armed.
    Save,
    /// The robot's constants and calibration as a robot file (TOML, the
    /// parameter table's names): `show` writes the robot's, `load` gives it
    /// a file (disarmed; every value checked before any is set; all or
    /// nothing). `hopper-sim params show design` writes one to start from.
    Robot {
        #[command(subcommand)]
        cmd: RobotCmd,
    },
    /// Press or release the simulated e-stop (QEMU and `hopper-sim serve`
    /// only; a real robot refuses).
    Estop {
        /// press | release
        #[arg(value_parser = ["press", "release"])]
        action: String,
    },
    /// Stop the heartbeats and wait for the robot to disarm by link loss;
    /// prints how long it took in robot time. Heartbeats resume after.
    Silence {
        /// Give up after this many wall seconds.
        #[arg(long, default_value_t = 10.0)]
        max: f64,
    },
    /// Load the link as hard as it takes for SECONDS of robot time (a
    /// test of the robot's real-time split): bursts of parameter reads,
    /// statuses, refused sets, dumps and garbage, each burst's answers
    /// awaited. Then prints what the robot's control interrupt cost
    /// meanwhile and whether it is still armed, fault-free and on time.
    Flood {
        /// Robot seconds.
        #[arg(default_value_t = 3.0)]
        seconds: f64,
    },
    /// Send N random bytes (a noisy line), then a frame delimiter.
    Garbage {
        /// Bytes.
        #[arg(default_value_t = 1024)]
        bytes: usize,
    },
    /// Wait (the link stays up, heartbeats go on).
    Wait {
        /// Wall seconds.
        seconds: f64,
    },
    /// The cockpit: a web page with live plots, the state, Arm and an
    /// always-visible Disarm (also Space or Escape), and the parameter
    /// table edited in place. Prints its address with a random token that
    /// every request needs; serves until Ctrl-C.
    Ui {
        /// Where to serve it (port 0: a free one, printed).
        #[arg(long, default_value = "127.0.0.1:8080", value_name = "HOST:PORT")]
        http: String,
        /// Serve on an address that is not loopback (anyone on that
        /// network with the token can drive the motor).
        #[arg(long)]
        allow_remote: bool,
        /// Where Record and Capture save, each in a numbered folder
        /// (recording-N, capture-N).
        #[arg(long, default_value = "recordings", value_name = "DIR")]
        record_dir: std::path::PathBuf,
    },
    /// Commands from standard input, one per line, on one connection (the
    /// link and the arming survive between them). `#` starts a comment; a
    /// line starting with `!` must fail (e.g. a refused set). A command that
    /// does not go as written is reported and the session goes on, then
    /// exits with an error; with --stop-on-error it stops there (nothing
    /// after it is sent: no `save` after a refused routine, no `arm`).
    Shell {
        /// Stop at the first command that does not go as written.
        #[arg(long)]
        stop_on_error: bool,
    },
}

#[derive(Subcommand, Debug)]
enum ParamsCmd {
    /// Every parameter: value, unit, range, default, whether it may change while armed.
    List,
    /// One parameter's value.
    Get {
        /// Table name, e.g. target_apex_m.
        name: String,
    },
    /// Set a parameter (checked on the robot; a refused set changes nothing).
    Set {
        /// Table name.
        name: String,
        /// Value in the parameter's unit; a choice by name or index (controller shaped).
        value: String,
    },
}

#[derive(Subcommand, Debug)]
enum RobotCmd {
    /// Print the robot's robot file (or write it to --out).
    Show {
        /// Write it to this file instead.
        #[arg(long, value_name = "FILE.toml")]
        out: Option<PathBuf>,
    },
    /// Set every entry of a robot file on the robot (disarmed), or none.
    Load {
        /// The robot file.
        file: PathBuf,
    },
}

/// One line of `shell`, parsed like a command line.
#[derive(Parser, Debug)]
#[command(name = ">", no_binary_name = true, disable_help_flag = true)]
struct ShellLine {
    #[command(subcommand)]
    cmd: Cmd,
}

/// How to give the robot's address: every error about a missing or bad
/// address ends with it.
const ADDRESS_HELP: &str =
    "the robot's address is --tcp HOST:PORT (`hopper-sim serve`, the QEMU image) or --serial PORT (the board, e.g. /dev/ttyUSB0), given before the command";

/// `e` with [`ADDRESS_HELP`] as a tip when it is about `--tcp` or
/// `--serial` (missing, both given, no value, or given after the command).
fn with_address_tip(mut e: clap::Error) -> clap::Error {
    use clap::error::{ContextKind, ContextValue};
    let about_address = e.context().any(|(kind, value)| {
        matches!(kind, ContextKind::InvalidArg | ContextKind::PriorArg) && {
            let v = value.to_string();
            v.contains("--tcp") || v.contains("--serial")
        }
    });
    if about_address {
        let mut tips = match e.get(ContextKind::Suggested) {
            Some(ContextValue::StyledStrs(t)) => t.clone(),
            _ => Vec::new(),
        };
        tips.push(ADDRESS_HELP.into());
        e.insert(ContextKind::Suggested, ContextValue::StyledStrs(tips));
    }
    e
}

fn main() {
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => {
            let e = with_address_tip(e);
            let _ = e.print();
            std::process::exit(if e.use_stderr() { 2 } else { 0 });
        }
    };
    let target = match (&cli.tcp, &cli.serial) {
        (Some(a), _) => Target::Tcp(a.clone()),
        (None, Some(p)) => Target::Serial(p.clone(), cli.baud),
        // The argument group requires one; kept as a clear error anyway.
        (None, None) => {
            eprintln!("hopper-link: error: no robot address: {ADDRESS_HELP}");
            std::process::exit(2);
        }
    };
    let result = Client::connect(&target)
        .map_err(|e| {
            if e.chain().any(|c| c.is::<hopper_link::BadAddress>()) {
                anyhow!("{e:#}; {ADDRESS_HELP}")
            } else {
                e
            }
        })
        .and_then(|mut c| match cli.cmd {
            Cmd::Shell { stop_on_error } => shell(&mut c, stop_on_error),
            cmd => run(&mut c, &cmd),
        });
    if let Err(e) = result {
        eprintln!("hopper-link: error: {e:#}");
        std::process::exit(1);
    }
}

fn shell(c: &mut Client, stop_on_error: bool) -> Result<()> {
    let mut failures = 0;
    for (n, line) in std::io::stdin().lock().lines().enumerate() {
        let line = line.context("reading standard input")?;
        let text = line.split('#').next().unwrap_or("").trim();
        if text.is_empty() {
            continue;
        }
        let (must_fail, text) = match text.strip_prefix('!') {
            Some(t) => (true, t.trim()),
            None => (false, text),
        };
        println!("> {}{text}", if must_fail { "! " } else { "" });
        let outcome = ShellLine::try_parse_from(text.split_whitespace())
            .map_err(|e| anyhow!("line {}: {}", n + 1, e.render().to_string().trim()))
            .and_then(|l| match l.cmd {
                Cmd::Shell { .. } => bail!("already in a shell"),
                cmd => run(c, &cmd),
            });
        match (outcome, must_fail) {
            (Ok(()), false) => {}
            (Err(e), true) => println!("failed as expected: {e:#}"),
            (Ok(()), true) => {
                println!("error: line {}: expected to fail, but it succeeded", n + 1);
                failures += 1;
            }
            (Err(e), false) => {
                println!("error: {e:#}");
                failures += 1;
            }
        }
        let _ = std::io::stdout().flush();
        if stop_on_error && failures > 0 {
            bail!(
                "stopped at line {}: it did not go as written (--stop-on-error: nothing after it was sent)",
                n + 1
            );
        }
    }
    if failures > 0 {
        bail!("{failures} command(s) of the session did not go as written");
    }
    Ok(())
}

fn run(c: &mut Client, cmd: &Cmd) -> Result<()> {
    match cmd {
        Cmd::Status => status::status(c),
        Cmd::Params { cmd } => match cmd {
            ParamsCmd::List => params::params_list(c),
            ParamsCmd::Get { name } => params::params_get(c, name),
            ParamsCmd::Set { name, value } => params::params_set(c, name, value),
        },
        Cmd::Arm { retry } => arm::arm(c, *retry),
        Cmd::Disarm => arm::disarm(c),
        Cmd::ResetFaults { retry } => arm::reset_faults(c, *retry),
        Cmd::Record {
            duration,
            rate,
            out,
        } => record::record(c, *duration, *rate, out),
        Cmd::Watch { duration } => watch::watch(c, *duration),
        Cmd::Dump { out } => dump::dump(c, out),
        Cmd::Calibrate { routine, seconds } => calibrate::calibrate(c, routine, *seconds),
        Cmd::Save => save::save(c),
        Cmd::Robot { cmd } => match cmd {
            RobotCmd::Show { out } => robot::show(c, out.as_deref()),
            RobotCmd::Load { file } => robot::load(c, file),
        },
        Cmd::Mount { action, toe } => sim::mount(c, action, *toe),
        Cmd::Estop { action } => sim::estop(c, action),
        Cmd::Silence { max } => silence::silence(c, *max),
        Cmd::Flood { seconds } => flood::flood(c, *seconds),
        Cmd::Garbage { bytes } => flood::garbage(c, *bytes),
        Cmd::Wait { seconds } => wait::wait(*seconds),
        Cmd::Ui {
            http,
            allow_remote,
            record_dir,
        } => ui::ui(c, http, *allow_remote, record_dir),
        Cmd::Shell { .. } => bail!("shell is a top-level command"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every clap error about the address names both ways to give one.
    #[test]
    fn address_errors_name_tcp_and_serial() {
        for args in [
            &["hopper-link", "status"][..],
            &["hopper-link", "params", "list"],
            &[
                "hopper-link",
                "--tcp",
                "a:1",
                "--serial",
                "/dev/x",
                "status",
            ],
            &["hopper-link", "--tcp"],
            &["hopper-link", "--tcp=", "status"],
            &["hopper-link", "--serial", "", "status"],
            &["hopper-link", "status", "--tcp", "a:1"],
        ] {
            let e = match Cli::try_parse_from(args) {
                Ok(_) => panic!("{args:?} parsed"),
                Err(e) => with_address_tip(e).render().to_string(),
            };
            assert!(
                e.contains("--tcp HOST:PORT") && e.contains("--serial PORT"),
                "{args:?}: {e}"
            );
        }
        // Not about the address: no tip.
        let e = match Cli::try_parse_from(["hopper-link", "--tcp", "a:1", "--baud", "x", "status"])
        {
            Ok(_) => panic!("parsed"),
            Err(e) => with_address_tip(e).render().to_string(),
        };
        assert!(!e.contains("the robot's address"), "{e}");
    }
}
