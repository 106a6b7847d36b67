//! `hopper-link`: operate the hopper from a host. One client for
//! the board (`--serial PORT`), the QEMU image and the simulator's virtual
//! robot (`--tcp ADDR`). See the README's "Operating the robot" and
//! docs/link.md.

use anyhow::{anyhow, bail, Context, Result};
use clap::{Parser, Subcommand};
use hopper_control::params::{self, Kind};
use hopper_link::record::Recording;
use hopper_link::{names, Client, Target};
use hopper_protocol::{
    ArmState, CostStats, HostMsg, Name, Request, Response, RobotMsg, Telemetry, ThermalStatus,
    TimingStats,
};
use std::io::{BufRead, IsTerminal, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

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
    /// Clear the latched faults whose cause is gone (only while disarmed).
    ResetFaults,
    /// Record telemetry and hop ledgers: telemetry.csv (units in the
    /// headers), hops.csv and hop.png in DIR.
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
    /// Run a bring-up routine on the robot, disarmed (in this order on a
    /// new robot; docs/board.md): `sensors` (raw codes, noise,
    /// still encoders), `height` (standing: the height encoder's zero),
    /// then on the hoist with the toe free `direction` (a current pulse:
    /// motor, encoder and load cell the right way round), `home` (the nut
    /// to its upper stop, the motor encoder zeroed there), `spring` (a
    /// nut sweep: the spring rate by least squares), `tare` (load-cell
    /// tare and potentiometer zero), then standing again `weight` (a nut
    /// sweep lifting and lowering the body: the weight, hence the load
    /// cell's gain, and the stance friction). `direction`, `home`, `spring`
    /// and `weight` drive the motor at up to `bringup.current_limit_a`.
    Calibrate {
        /// sensors | tare | direction | home | spring | height | weight
        #[arg(value_parser = clap::builder::PossibleValuesParser::new(
            hopper_control::bringup::Routine::ALL.map(|r| r.name())
        ))]
        routine: String,
        /// How long it measures, s of robot time.
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
    /// Save the calibration (the `calibration.*` parameters and the spring's
    /// rate and preload: what the bring-up routines set) to the robot's
    /// flash, to load at every boot; refused while armed.
    Save,
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
    /// Commands from standard input, one per line, on one connection (the
    /// link and the arming survive between them). `#` starts a comment; a
    /// line starting with `!` must fail (e.g. a refused set).
    Shell,
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
            Cmd::Shell => shell(&mut c),
            cmd => run(&mut c, &cmd),
        });
    if let Err(e) = result {
        eprintln!("hopper-link: error: {e:#}");
        std::process::exit(1);
    }
}

fn shell(c: &mut Client) -> Result<()> {
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
                Cmd::Shell => bail!("already in a shell"),
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
    }
    if failures > 0 {
        bail!("{failures} command(s) of the session did not go as written");
    }
    Ok(())
}

fn run(c: &mut Client, cmd: &Cmd) -> Result<()> {
    match cmd {
        Cmd::Status => status(c),
        Cmd::Params { cmd } => match cmd {
            ParamsCmd::List => params_list(c),
            ParamsCmd::Get { name } => {
                let v = match read_param(c, name)? {
                    Ok(v) => v,
                    Err(why) => match inactive_hint(c, name) {
                        Some(hint) => bail!("get {name}: {hint}"),
                        None => bail!("get {name}: {why}"),
                    },
                };
                println!("{name} = {}", shown(name, v));
                Ok(())
            }
            ParamsCmd::Set { name, value } => {
                let v = parse_value(name, value)?;
                match c.request(Request::ParamSet {
                    name: wire_name(name)?,
                    value: v,
                })? {
                    Response::Ok => {
                        let now = get(c, name)?;
                        println!("{name} = {} (set)", shown(name, now));
                        Ok(())
                    }
                    Response::Refused(why) => match read_param(c, name)? {
                        Ok(now) => bail!(
                            "set {name} = {value} refused: {why} (unchanged: {})",
                            shown(name, now)
                        ),
                        Err(_) => match inactive_hint(c, name) {
                            Some(hint) => bail!("set {name} = {value} refused: {why} ({hint})"),
                            None => bail!("set {name} = {value} refused: {why}"),
                        },
                    },
                    r => bail!("unexpected answer {r:?}"),
                }
            }
        },
        Cmd::Arm { retry } => {
            let start = Instant::now();
            loop {
                match c.request(Request::Arm)? {
                    Response::Ok => {
                        println!("armed");
                        return Ok(());
                    }
                    Response::Refused(why)
                        if start.elapsed().as_secs_f64() < retry.unwrap_or(0.0) =>
                    {
                        let _ = why;
                        std::thread::sleep(Duration::from_millis(50));
                    }
                    Response::Refused(why) => bail!("arm refused: {why}"),
                    r => bail!("unexpected answer {r:?}"),
                }
            }
        }
        Cmd::Disarm => disarm(c),
        Cmd::ResetFaults => {
            let r = c.request(Request::ResetFaults)?;
            let st = status_of(c)?;
            match r {
                Response::Ok => {
                    println!("faults reset; latched now: {}", names::faults(st.faults));
                    Ok(())
                }
                Response::Refused(why) => bail!(
                    "reset refused: {why}; still latched: {}",
                    names::faults(st.faults)
                ),
                r => bail!("unexpected answer {r:?}"),
            }
        }
        Cmd::Record {
            duration,
            rate,
            out,
        } => record(c, *duration, *rate, out),
        Cmd::Watch { duration } => watch(c, *duration),
        Cmd::Dump { out } => dump(c, out),
        Cmd::Calibrate { routine, seconds } => calibrate(c, routine, *seconds),
        Cmd::Save => save(c),
        Cmd::Mount { action, toe } => {
            c.expect_ok(Request::SimulateMount {
                hoisted: action == "hoist",
                lift_m: *toe,
            })?;
            println!("mount: {action}");
            Ok(())
        }
        Cmd::Estop { action } => {
            c.expect_ok(Request::SimulateEstop {
                pressed: action == "press",
            })?;
            println!(
                "simulated e-stop {}",
                if action == "press" {
                    "pressed"
                } else {
                    "released"
                }
            );
            Ok(())
        }
        Cmd::Silence { max } => silence(c, *max),
        Cmd::Flood { seconds } => flood(c, *seconds),
        Cmd::Garbage { bytes } => {
            let mut x: u64 = 0x9E37_79B9_7F4A_7C15;
            let junk: Vec<u8> = (0..*bytes)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    (x >> 24) as u8
                })
                .collect();
            c.send_raw(&junk)?;
            c.send_raw(&[0])?;
            println!("sent {bytes} random bytes and a delimiter");
            Ok(())
        }
        Cmd::Wait { seconds } => {
            std::thread::sleep(Duration::from_secs_f64(seconds.clamp(0.0, 3600.0)));
            Ok(())
        }
        Cmd::Shell => bail!("shell is a top-level command"),
    }
}

fn wire_name(name: &str) -> Result<Name> {
    let mut n = Name::new();
    n.push_str(name)
        .map_err(|_| anyhow!("parameter name `{name}` is too long"))?;
    Ok(n)
}

/// A value as typed: a number, or a choice's name (`controller shaped`).
fn parse_value(name: &str, value: &str) -> Result<f32> {
    if let Ok(v) = value.parse::<f32>() {
        return Ok(v);
    }
    match params::find(name).map(|p| p.kind) {
        Some(Kind::Choice(names)) => names
            .iter()
            .position(|n| *n == value)
            .map(|i| i as f32)
            .ok_or_else(|| anyhow!("`{name}` is one of {names:?}, not `{value}`")),
        _ => bail!("`{value}` is not a number"),
    }
}

/// A value for display: a choice by name, else the number and unit.
fn shown(name: &str, v: f32) -> String {
    match params::find(name) {
        Some(p) => match p.kind {
            Kind::Choice(names) => names
                .get(v as usize)
                .map_or(format!("{v}"), |n| format!("{n} ({v})")),
            _ if p.unit == "1" || p.unit == "-" => format!("{v}"),
            _ => format!("{v} {}", p.unit),
        },
        None => format!("{v}"),
    }
}

/// For a parameter of the table that the robot's configuration lacks
/// (another controller's, which the robot refuses to read or set): why,
/// its default, and the command(s) that make it active.
fn inactive_hint(c: &mut Client, name: &str) -> Option<String> {
    let p = params::find(name)?;
    names::owner(name)?;
    let selected = selected_controller(c);
    let steps: Vec<String> = names::activation(name, selected)
        .iter()
        .map(|s| format!("`{s}`"))
        .collect();
    let mut hint = format!(
        "{}; default {}",
        names::inactive_reason(name, selected),
        shown(name, p.default)
    );
    if !steps.is_empty() {
        hint += &format!("; activate it with {}", steps.join(" then "));
    }
    Some(hint)
}

fn get(c: &mut Client, name: &str) -> Result<f32> {
    read_param(c, name)?.map_err(|why| anyhow!("get {name}: {why}"))
}

/// A parameter's value, or the robot's reason for refusing to read it (a
/// name it does not know, or one its configuration lacks); `Err` only when
/// the link failed.
fn read_param(c: &mut Client, name: &str) -> Result<std::result::Result<f32, String>> {
    match c.request(Request::ParamGet {
        name: wire_name(name)?,
    })? {
        Response::Value(v) => Ok(Ok(v)),
        Response::Refused(why) => Ok(Err(why.to_string())),
        r => bail!("unexpected answer {r:?}"),
    }
}

fn status_of(c: &mut Client) -> Result<hopper_protocol::Status> {
    match c.request(Request::Status)? {
        Response::Status(s) => Ok(s),
        r => bail!("unexpected answer {r:?}"),
    }
}

fn calibrate(c: &mut Client, routine: &str, seconds: f32) -> Result<()> {
    use hopper_control::bringup::{CalState, Routine};
    let r = Routine::ALL
        .into_iter()
        .find(|r| r.name() == routine)
        .unwrap_or(Routine::SensorCheck);
    let code = r as u8;
    let was = (
        get(c, "calibration.loadcell_offset_code")?,
        get(c, "calibration.pot_offset_code")?,
    );
    let lc_gain = get(c, "calibration.loadcell_gain_n_per_code")?;
    let pot_gain = get(c, "calibration.pot_gain_m_per_code")?;
    let rate = get(c, "supervisor.spring_rate_n_per_m")?;
    match c.request(Request::Calibrate {
        routine: code,
        seconds,
    })? {
        Response::Ok => {}
        Response::Refused(why) => bail!("calibrate {routine} refused: {why}"),
        r => bail!("unexpected answer {r:?}"),
    }
    // The measuring routines take `seconds` of robot time; the driving ones
    // as long as their moves (homing across the whole stroke: 12 s).
    let limit_s = if r.drives_motor() {
        60.0
    } else {
        seconds * 20.0 + 5.0
    };
    let deadline = Instant::now() + Duration::from_secs_f32(limit_s);
    let r = loop {
        std::thread::sleep(Duration::from_millis(100));
        let r = match c.request(Request::CalibrationReport)? {
            Response::Calibration(r) => r,
            r => bail!("unexpected answer {r:?}"),
        };
        if r.state != CalState::Running as u8 {
            break r;
        }
        if Instant::now() > deadline {
            bail!("calibrate {routine}: still running after {limit_s:.0} s");
        }
    };
    let state = CalState::ALL
        .get(usize::from(r.state))
        .map_or("unknown", |s| s.name());
    println!(
        "calibrate {routine}: {state}: {} samples; encoders moved by {} (motor) and {} (height) counts",
        r.samples, r.motor_span_counts, r.height_span_counts
    );
    println!(
        "load cell: mean {:.2} codes, noise {:.2} codes ({:.2} N)",
        r.loadcell_mean_code,
        r.loadcell_std_code,
        r.loadcell_std_code * lc_gain
    );
    println!(
        "potentiometer: mean {:.2} codes, noise {:.2} codes ({:.3} mm)",
        r.pot_mean_code,
        r.pot_std_code,
        r.pot_std_code * pot_gain * 1000.0
    );
    let b = match c.request(Request::BringupResults)? {
        Response::BringupResults(b) => b,
        r => bail!("unexpected answer {r:?}"),
    };
    print_results(routine, &b, r.state == CalState::Done as u8);
    if routine == Routine::Weight.name() {
        let w = match c.request(Request::Weighing)? {
            Response::Weighing(w) => w,
            r => bail!("unexpected answer {r:?}"),
        };
        print_weighing(&w);
    }
    if r.state != CalState::Done as u8 {
        bail!("calibrate {routine} {state}");
    }
    if routine == Routine::Weight.name() {
        println!(
            "weight: calibration.loadcell_gain_n_per_code {lc_gain:.5} -> {:.5} N/code, supervisor.spring_rate_n_per_m {rate:.0} -> {:.0} N/m (applied)",
            get(c, "calibration.loadcell_gain_n_per_code")?,
            get(c, "supervisor.spring_rate_n_per_m")?
        );
    }
    if r.loadcell_offset_code.is_finite() {
        println!(
            "tare: calibration.loadcell_offset_code {:.2} -> {:.2} codes ({:+.2} N), calibration.pot_offset_code {:.2} -> {:.2} codes ({:+.3} mm) (applied)",
            was.0,
            r.loadcell_offset_code,
            (r.loadcell_offset_code - was.0) * lc_gain,
            was.1,
            r.pot_offset_code,
            (r.pot_offset_code - was.1) * pot_gain * 1000.0
        );
    }
    Ok(())
}

/// What a motor-driving or height routine found, one line each.
fn print_results(routine: &str, b: &hopper_protocol::BringupResults, done: bool) {
    let applied = if done { "applied" } else { "not applied" };
    if b.peak_current_a > 0.0 {
        println!("current: up to {:.2} A", b.peak_current_a);
    }
    if b.nut_travel_m.is_finite() && routine == "direction" {
        println!(
            "direction: a pulse down moved the nut {:+.3} mm and the load cell {:+.2} N",
            b.nut_travel_m * 1000.0,
            b.force_change_n
        );
    }
    if b.nut_offset_m.is_finite() && routine == "home" {
        println!(
            "home: the upper stop was at {:+.3} mm in the motor encoder's frame; zeroed there ({applied})",
            b.nut_offset_m * 1000.0
        );
    }
    if b.spring_rate_n_per_m.is_finite() {
        println!(
            "spring: rate {:.0} N/m, force at zero compression {:+.2} N, fit RMS {:.2} N over {} points spanning {:.2} mm (1 sigma); supervisor.spring_rate_n_per_m ({applied})",
            b.spring_rate_n_per_m,
            b.spring_intercept_n,
            b.fit_rms_n,
            b.fit_points,
            b.fit_span_m * 1000.0
        );
    }
    if b.height_offset_m.is_finite() {
        println!(
            "height: the body height corrected by {:+.3} mm ({applied})",
            b.height_offset_m * 1000.0
        );
    }
}

/// What the weighing found, one line.
fn print_weighing(w: &hopper_protocol::WeighingInfo) {
    if w.weight_n.is_finite() {
        println!(
            "weight: the robot weighs {:.2} N as the load cell reads it, {:.2} N as configured: the load cell reads {:+.2}%; stance friction {:.2} N; the body rose {:.2} mm",
            w.weight_n,
            w.configured_weight_n,
            (w.weight_n / w.configured_weight_n - 1.0) * 100.0,
            w.friction_n,
            w.body_rise_m * 1000.0
        );
    }
}

fn stored_of(c: &mut Client) -> Result<hopper_protocol::StoredInfo> {
    match c.request(Request::Stored)? {
        Response::Stored(s) => Ok(s),
        r => bail!("unexpected answer {r:?}"),
    }
}

/// The saved calibration's state in words; `require_tare`: whether the
/// robot's arming waits for a tare (`arming.require_tare`; `None`: unknown).
fn stored_line(s: &hopper_protocol::StoredInfo, require_tare: Option<bool>) -> String {
    let defaults = match require_tare {
        Some(true) => "the defaults (tare before arming: arming.require_tare is 1)",
        Some(false) => "the defaults",
        None => "the defaults (tare before arming if arming.require_tare is 1)",
    };
    let boot = match s.boot {
        0 => "no flash store on this robot".to_string(),
        1 => format!("nothing saved: {defaults}"),
        2 => format!("loaded from flash at boot ({} parameters)", s.entries),
        _ => format!(
            "the saved record was refused at boot ({}): {defaults}",
            hopper_control::persist::LoadError::name_of(s.boot_error).unwrap_or("unknown")
        ),
    };
    let save = match s.save {
        0 => "",
        1 => "; a save is pending",
        2 => "; saved since boot",
        3 => "; the last save FAILED",
        _ => "; saved: written to flash at the next restart",
    };
    format!("{boot}{save}")
}

/// `save`: the calibration to flash, and how it went.
fn save(c: &mut Client) -> Result<()> {
    // `busy`: a change (a routine's results, a set) is still being
    // installed, a few periods at most: asked again for up to 1 s.
    let deadline = Instant::now() + Duration::from_secs(1);
    loop {
        match c.request(Request::Save)? {
            Response::Ok => break,
            Response::Refused(why) if why.as_str() == "busy" && Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Response::Refused(why) => bail!("save refused: {why}"),
            r => bail!("unexpected answer {r:?}"),
        }
    }
    let deadline = Instant::now() + Duration::from_secs(5);
    loop {
        std::thread::sleep(Duration::from_millis(50));
        let s = stored_of(c)?;
        match s.save {
            1 if Instant::now() < deadline => continue,
            1 => bail!("save: still pending after 5 s"),
            2 => {
                println!(
                    "saved: {} calibration parameters to flash (they load at the next boot)",
                    hopper_control::persist::saved_count()
                );
                return Ok(());
            }
            4 => {
                println!("saved: the robot restarts to write its flash (home it again after)");
                return Ok(());
            }
            _ => {
                let require_tare = flag(c, "arming.require_tare");
                bail!("save failed: {}", stored_line(&s, require_tare))
            }
        }
    }
}

/// A flag parameter, if the robot has it.
fn flag(c: &mut Client, name: &str) -> Option<bool> {
    get(c, name).ok().map(|v| v != 0.0)
}

/// The `arming.*` parameters of the robot that decide what arming needs
/// (`None`: the robot did not say; its firmware may lack the parameter).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct ArmingParams {
    link_timeout_s: Option<f32>,
    untethered: Option<bool>,
    home_tolerance_m: Option<f32>,
    still_velocity_mps: Option<f32>,
    require_tare: Option<bool>,
    require_home: Option<bool>,
}

impl ArmingParams {
    fn read(c: &mut Client) -> Self {
        Self {
            link_timeout_s: get(c, "arming.link_timeout_s").ok(),
            untethered: flag(c, "arming.untethered"),
            home_tolerance_m: get(c, "arming.home_tolerance_m").ok(),
            still_velocity_mps: get(c, "arming.still_velocity_mps").ok(),
            require_tare: flag(c, "arming.require_tare"),
            require_home: flag(c, "arming.require_home"),
        }
    }

    /// What an arm request needs on this robot, in the order the robot
    /// checks (`arming::Arming::refusal`), the boot checks aside (the
    /// `boot:` and `crystal:` lines say when those refuse).
    fn requirements(&self) -> String {
        let mut needs = vec![
            "no latched fault".to_string(),
            "the e-stop released".to_string(),
            "no bring-up routine running".to_string(),
        ];
        let mut not = Vec::new();
        match self.require_home {
            Some(true) => needs.push(
                "the nut homed since boot (`calibrate direction`, `calibrate home`; arming.require_home is 1)"
                    .to_string(),
            ),
            Some(false) => not.push("homing (arming.require_home is 0)"),
            None => {}
        }
        match self.require_tare {
            Some(true) => needs.push(
                "a tare since boot or a saved calibration loaded at boot (`calibrate tare`; arming.require_tare is 1)"
                    .to_string(),
            ),
            Some(false) => not.push("a tare (arming.require_tare is 0)"),
            None => {}
        }
        match (self.untethered, self.link_timeout_s) {
            (Some(true), _) => not.push("the link (arming.untethered is 1)"),
            (_, Some(t)) => needs.push(format!("the link up (a frame from the host within {t} s)")),
            (_, None) => needs.push("the link up".to_string()),
        }
        needs.push("plausible sensors".to_string());
        needs.push(match self.home_tolerance_m {
            Some(m) => format!("the nut within {:.1} mm of its upper stop", m * 1000.0),
            None => "the nut at its upper stop".to_string(),
        });
        needs.push(match self.still_velocity_mps {
            Some(v) => format!("nut and body slower than {v} m/s"),
            None => "nut and body still".to_string(),
        });
        let mut line = format!("needs {}", needs.join(", "));
        if !not.is_empty() {
            line += &format!("; not required: {}", not.join(", "));
        }
        line
    }
}

fn thermal_of(c: &mut Client) -> Result<ThermalStatus> {
    match c.request(Request::Thermal)? {
        Response::Thermal(t) => Ok(t),
        r => bail!("unexpected answer {r:?}"),
    }
}

fn timing_of(c: &mut Client) -> Result<TimingStats> {
    match c.request(Request::Timing)? {
        Response::Timing(t) => Ok(t),
        r => bail!("unexpected answer {r:?}"),
    }
}

/// One telemetry record now (telemetry is switched on for it, then off).
fn one_record(c: &mut Client) -> Result<Telemetry> {
    // Every 100th period: any line carries that. Records queued before
    // the answer may be stale (an earlier stream): only later ones count.
    c.expect_ok(Request::Telemetry { every: 100 })?;
    c.discard_queued();
    let deadline = Instant::now() + Duration::from_secs(3);
    let found = loop {
        match c.next_event(deadline.saturating_duration_since(Instant::now()))? {
            Some(RobotMsg::Telemetry(t)) => break Some(t),
            Some(_) => {}
            None => break None,
        }
    };
    c.expect_ok(Request::Telemetry { every: 0 })?;
    found.ok_or_else(|| anyhow!("no telemetry record within 3 s"))
}

fn status(c: &mut Client) -> Result<()> {
    let s = status_of(c)?;
    let t = timing_of(c)?;
    let r = one_record(c)?;
    let period = f64::from(t.period_s);
    println!(
        "state: {}: {}",
        names::arm_state(s.arm),
        names::advice(s.arm)
    );
    println!("faults: {}", names::faults(s.faults));
    println!(
        "sensors: body height {:.4} m, nut {:.2} mm, spring force {:.1} N, energy {:.2} J, command {:.2} A, phase {}",
        r.body_height_m,
        r.nut_position_m * 1000.0,
        r.spring_force_n,
        r.energy_j,
        r.command_a,
        if r.phase == 1 { "stance" } else { "flight" }
    );
    println!(
        "periods: {} ({:.3} s at {:.0} Hz), missed deadlines {}",
        s.periods,
        f64::from(s.periods) * period,
        1.0 / period,
        t.missed
    );
    println!(
        "link: {} frames in, {} bad; {} telemetry records not sent; host got {} frames, {} bad",
        s.frames_ok,
        s.frames_bad,
        s.telemetry_dropped,
        c.stats().ok,
        c.stats().bad()
    );
    if s.last_apex_m.is_finite() {
        println!("last apex: {:.4} m", s.last_apex_m);
    } else {
        println!("last apex: none yet");
    }
    let b = match c.request(Request::Boot)? {
        Response::Boot(b) => b,
        r => bail!("unexpected answer {r:?}"),
    };
    let resets: Vec<&str> = hopper_control::boot::ResetCauses(b.resets)
        .iter()
        .map(hopper_control::boot::ResetCause::name)
        .collect();
    println!(
        "boot: reset by {}; core clock {:.0} MHz{}; brown-out reset {}",
        if resets.is_empty() {
            "nothing recorded".to_string()
        } else {
            resets.join(", ")
        },
        f64::from(b.sysclk_hz) / 1e6,
        if b.clock_as_configured {
            " as configured"
        } else {
            ", NOT the configured clock (arming refused: clock-fallback)"
        },
        if b.brown_out_reset_on {
            "on"
        } else {
            "OFF (arming refused: brown-out-reset-off; set BOR_LEV in the option bytes, docs/safety.md)"
        }
    );
    match c.request(Request::Crystal)? {
        Response::Crystal(x) if x.expected_hz == 0 => {}
        Response::Crystal(x) => println!(
            "crystal: {}; the profile names {:.3} MHz{}",
            if x.measured_hz == 0 {
                "not measured (it did not start)".to_string()
            } else {
                format!(
                    "{:.3} MHz measured against the internal oscillator",
                    f64::from(x.measured_hz) / 1e6
                )
            },
            f64::from(x.expected_hz) / 1e6,
            if x.measured_hz != 0
                && !hopper_control::boot::Crystal::matches(x.measured_hz, x.expected_hz)
            {
                " (arming refused: crystal-not-the-profiles: build for this board's crystal, docs/board.md)"
            } else {
                ""
            }
        ),
        r => bail!("unexpected answer {r:?}"),
    }
    let arming = ArmingParams::read(c);
    println!(
        "calibration: {}",
        stored_line(&stored_of(c)?, arming.require_tare)
    );
    println!("arming: {}", arming.requirements());
    match c.request(Request::ThermalBoot) {
        Ok(Response::ThermalBoot(b)) => println!(
            "motor estimate at boot: winding {:.1} C ({})",
            b.winding_c,
            if b.assumed_hot {
                "assumed hot, at the derating temperature: nothing of the motor's heat survives a reset or a power cycle on this robot"
            } else {
                "ambient: a simulated motor, cold at start"
            }
        ),
        Ok(r) => bail!("unexpected answer {r:?}"),
        // An older firmware does not know the request.
        Err(_) => {}
    }
    let m = thermal_of(c)?;
    println!(
        "motor (estimated): winding {:.1} C, housing {:.1} C; current limit {:.0}% (derates from {:.0} C, trips at {:.0} C{})",
        m.winding_c,
        m.housing_c,
        m.limit_scale * 100.0,
        m.derate_c,
        m.trip_c,
        if m.protect { "" } else { "; protection off" }
    );
    println!(
        "cost per period (robot counter ticks: board cycles, QEMU instructions, simulator 0): control step mean {} max {}, link mean {} max {}",
        t.step_mean, t.step_max, t.link_mean, t.link_max
    );
    match cost_of(c)? {
        Some(k) => {
            for l in cost_lines(&k) {
                println!("{l}");
            }
        }
        None => println!("control interrupt: not reported by this firmware"),
    }
    Ok(())
}

fn params_list(c: &mut Client) -> Result<()> {
    let n = match c.request(Request::ParamCount)? {
        Response::ParamCount(n) => n,
        r => bail!("unexpected answer {r:?}"),
    };
    let selected = selected_controller(c);
    println!(
        "{:<42} {:>14} {:<8} {:>25} {:>12}  armed",
        "name", "value", "unit", "range", "default"
    );
    let mut inactive = 0;
    for index in 0..n {
        match c.request(Request::ParamInfo { index })? {
            Response::ParamInfo(p) => {
                inactive += usize::from(p.value.is_nan());
                println!("{}", param_row(&p, selected));
            }
            Response::Refused(why) => bail!("parameter {index}: {why}"),
            r => bail!("unexpected answer {r:?}"),
        }
    }
    if inactive > 0 {
        println!(
            "{n} parameters; {inactive} inactive (not used by the selected controller{}: shown at their defaults)",
            selected
                .and_then(|i| params::CONTROLLER_NAMES.get(i))
                .map_or(String::new(), |c| format!(", {c}"))
        );
    } else {
        println!("{n} parameters");
    }
    Ok(())
}

/// The selected controller's index, if the robot says.
fn selected_controller(c: &mut Client) -> Option<usize> {
    get(c, params::CONTROLLER.name)
        .ok()
        .filter(|v| *v >= 0.0)
        .map(|v| v as usize)
}

/// One row of `params list`. The robot reports no value (NaN) for a
/// parameter its configuration lacks (another controller's): the row shows
/// the default, which selecting that controller starts it from, and says
/// what would make it active.
fn param_row(p: &hopper_protocol::ParamInfo, selected: Option<usize>) -> String {
    let name = p.name.as_str();
    let (value, note) = if p.value.is_nan() {
        (
            p.default,
            format!("  ({})", names::inactive_reason(name, selected)),
        )
    } else {
        (p.value, String::new())
    };
    format!(
        "{:<42} {:>14} {:<8} {:>25} {:>12}  {:<8}{note}",
        name,
        names::param_value(name, value),
        p.unit.as_str(),
        format!("{} ..= {}", p.min, p.max),
        names::param_value(name, p.default),
        if p.live { "settable" } else { "-" }
    )
    .trim_end()
    .to_string()
}

fn disarm(c: &mut Client) -> Result<()> {
    c.expect_ok(Request::Telemetry { every: 1 })?;
    c.discard_events();
    c.expect_ok(Request::Disarm)?;
    let deadline = Instant::now() + Duration::from_secs(3);
    let next = loop {
        match c.next_event(deadline.saturating_duration_since(Instant::now()))? {
            Some(RobotMsg::Telemetry(t)) if !t.armed => break Some(t),
            Some(_) => {}
            None => break None,
        }
    };
    c.expect_ok(Request::Telemetry { every: 0 })?;
    let t = next.ok_or_else(|| anyhow!("no disarmed telemetry record within 3 s"))?;
    println!(
        "disarmed; next record: step {}, armed {}, command {:.3} A",
        t.step, t.armed, t.command_a
    );
    if t.command_a != 0.0 {
        bail!("the record after the disarm commands {} A", t.command_a);
    }
    Ok(())
}

fn record(c: &mut Client, duration_s: f64, rate_hz: f64, out: &std::path::Path) -> Result<()> {
    if !(duration_s.is_finite() && duration_s > 0.0) {
        bail!("--duration {duration_s} must be a positive number of seconds");
    }
    let t = timing_of(c)?;
    let period = f64::from(t.period_s);
    if !(rate_hz.is_finite() && rate_hz > 0.0 && rate_hz <= 1.0 / period + 1e-6) {
        bail!(
            "--rate {rate_hz} must be in (0, {:.0}] Hz (the control rate)",
            1.0 / period
        );
    }
    let every = (1.0 / (rate_hz * period)).round().clamp(1.0, 65535.0) as u16;
    let target = get(c, "target_apex_m").ok().map(f64::from);
    let controller = get(c, "controller")
        .ok()
        .and_then(|v| params::CONTROLLER_NAMES.get(v as usize).copied())
        .unwrap_or("the controller");
    let mut rec = Recording {
        period_s: period,
        ..Recording::default()
    };
    let span = (duration_s / period).round() as u64;
    let bar = indicatif::ProgressBar::new(span);
    if !std::io::stderr().is_terminal() {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    c.discard_events();
    c.expect_ok(Request::Telemetry { every })?;
    // Records before the answer may be from an earlier stream.
    c.discard_queued();
    let mut quiet = Instant::now();
    loop {
        match c.next_event(Duration::from_millis(200))? {
            Some(RobotMsg::Telemetry(t)) => {
                quiet = Instant::now();
                let first = rec.records.first().map_or(t.step, |f| f.step);
                let spanned = u64::from(t.step.wrapping_sub(first));
                rec.records.push(t);
                bar.set_position(spanned.min(span));
                if spanned + u64::from(every) > span {
                    break;
                }
            }
            Some(RobotMsg::Hop(h)) => rec.hops.push(h),
            Some(RobotMsg::Faults { step, bits }) => {
                bar.suspend(|| {
                    println!("fault at step {step}: {}", names::faults(bits));
                });
                rec.faults.push((step, bits));
            }
            Some(RobotMsg::State(s)) => bar.suspend(|| println!("state: {}", names::arm_state(s))),
            Some(_) => {}
            None if quiet.elapsed() > Duration::from_secs(3) => {
                bail!("no telemetry for 3 s: the robot stopped streaming")
            }
            None => {}
        }
    }
    c.expect_ok(Request::Telemetry { every: 0 })?;
    bar.finish_and_clear();
    let title = format!("{controller} on the robot ({})", c.target());
    let written = rec.write(out, ("telemetry.csv", "hop.png"), true, &title, target)?;
    let apexes = rec.apexes_m();
    println!(
        "recorded {:.3} s: {} records at {:.0} Hz, {} dropped; {} hops",
        rec.records.len() as f64 * f64::from(every) * period,
        rec.records.len(),
        1.0 / (f64::from(every) * period),
        rec.dropped(),
        rec.hops.len()
    );
    println!(
        "apexes (m): {}",
        apexes
            .iter()
            .map(|a| format!("{a:.4}"))
            .collect::<Vec<_>>()
            .join(" ")
    );
    if let (Some(s), Some(t)) = (hopper_plant::metrics::steady_apex(&apexes), target) {
        println!(
            "steady apex: {s:.4} m (target {t:.4} m, {:+.1}%)",
            (s - t) / t * 100.0
        );
    }
    print_written(&written);
    Ok(())
}

fn print_written(paths: &[PathBuf]) {
    println!(
        "wrote {}",
        paths
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
}

fn watch(c: &mut Client, duration: Option<f64>) -> Result<()> {
    let t = timing_of(c)?;
    let every = ((0.1 / f64::from(t.period_s)).round() as u16).max(1);
    c.discard_events();
    c.expect_ok(Request::Telemetry { every })?;
    c.discard_queued();
    let tty = std::io::stdout().is_terminal();
    let start = Instant::now();
    let mut last_apex = f32::NAN;
    let mut last_seq: Option<u32> = None;
    let mut drops: u64 = 0;
    let mut state = String::from("?");
    while duration.is_none_or(|d| start.elapsed().as_secs_f64() < d) {
        match c.next_event(Duration::from_millis(500))? {
            Some(RobotMsg::Telemetry(r)) => {
                if let Some(p) = last_seq {
                    drops += u64::from(r.seq.wrapping_sub(p).saturating_sub(1));
                }
                last_seq = Some(r.seq);
                let line = format!(
                    "{:<22} faults {:<16} apex {:>7.4} m  z {:.4} m  nut {:>6.2} mm  F {:>6.1} N  I {:>6.2} A  drops {}",
                    if r.armed { "armed".to_string() } else { state.clone() },
                    names::faults(r.faults),
                    last_apex,
                    r.body_height_m,
                    r.nut_position_m * 1000.0,
                    r.spring_force_n,
                    r.command_a,
                    drops
                );
                if tty {
                    print!("\r{line}");
                } else if r.seq.is_multiple_of(10) {
                    println!("{line}");
                }
                let _ = std::io::stdout().flush();
            }
            Some(RobotMsg::Hop(h)) => last_apex = h.apex_height_m,
            Some(RobotMsg::State(s)) => state = names::arm_state(s),
            Some(RobotMsg::Faults { step, bits }) => {
                println!("\nfault at step {step}: {}", names::faults(bits));
            }
            _ => {}
        }
    }
    c.expect_ok(Request::Telemetry { every: 0 })?;
    if tty {
        println!();
    }
    Ok(())
}

fn dump(c: &mut Client, out: &std::path::Path) -> Result<()> {
    let t = timing_of(c)?;
    let st = status_of(c)?;
    // A fault latched less than a quarter capture ago is still being
    // captured: ask again until the capture froze (a fresh dump restarts).
    let asked = Instant::now();
    let info = loop {
        c.discard_events();
        let info = match c.request(Request::Dump)? {
            Response::Dump(i) => i,
            r => bail!("unexpected answer {r:?}"),
        };
        if info.frozen || info.fault_step == 0 || asked.elapsed() > Duration::from_secs(5) {
            // Records that came before this answer belong to an earlier
            // dump still draining from the robot's queue.
            c.discard_queued();
            break info;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    let mut rec = Recording {
        period_s: f64::from(t.period_s),
        ..Recording::default()
    };
    let mut quiet = Instant::now();
    while rec.records.len() < usize::from(info.records) {
        match c.next_event(Duration::from_millis(200))? {
            // In order, or from an earlier dump: skip those.
            Some(RobotMsg::Captured(r)) if r.seq as usize == rec.records.len() => {
                quiet = Instant::now();
                rec.records.push(r);
            }
            Some(_) => {}
            None if quiet.elapsed() > Duration::from_secs(5) => bail!(
                "the dump stopped after {} of {} records",
                rec.records.len(),
                info.records
            ),
            None => {}
        }
    }
    if info.frozen {
        rec.t0_step = Some(info.fault_step);
    }
    let title = if info.frozen {
        // The faults of the first period after the fault's: what latched.
        let latched = rec
            .records
            .iter()
            .find(|r| r.step.wrapping_sub(info.fault_step) as i32 >= 0 && r.faults != 0)
            .map_or_else(String::new, |r| format!(" ({})", names::faults(r.faults)));
        format!(
            "capture around the fault{latched} at step {} (t = 0 there)",
            info.fault_step
        )
    } else {
        "capture of the latest periods (no fault)".to_string()
    };
    let written = rec.write_capture(out, &title)?;
    let span_ms = rec.records.len() as f64 * rec.period_s * 1000.0;
    if info.frozen {
        println!(
            "capture: {} records ({span_ms:.1} ms), frozen by the fault at step {}; latched now: {}",
            rec.records.len(),
            info.fault_step,
            names::faults(st.faults)
        );
    } else {
        println!(
            "capture: {} records ({span_ms:.1} ms) of the latest periods; no fault froze it",
            rec.records.len()
        );
    }
    print_written(&written);
    Ok(())
}

/// What the robot's real-time work cost, if its firmware reports it.
fn cost_of(c: &mut Client) -> Result<Option<CostStats>> {
    match c.request(Request::Cost) {
        Ok(Response::Cost(k)) => Ok(Some(k)),
        Ok(r) => bail!("unexpected answer {r:?}"),
        // An older firmware does not know the request.
        Err(_) => Ok(None),
    }
}

/// The counter's unit for people.
fn cost_unit(k: &CostStats) -> &'static str {
    if k.counter_hz > 0 {
        "cycles"
    } else {
        "instructions (QEMU; 0 on the host simulator)"
    }
}

/// The `control interrupt:`, `serial interrupt:` and `link task:` lines
/// of `status` and `flood`.
fn cost_lines(k: &CostStats) -> [String; 3] {
    let us = |n: u32| {
        if k.counter_hz > 0 {
            format!(" = {:.1} us", f64::from(n) * 1e6 / f64::from(k.counter_hz))
        } else {
            String::new()
        }
    };
    [
        format!(
            "control interrupt: mean {} max {}{} {} (entry to exit: read, step, write, publish, at most one command); start jitter max {:.1} us",
            k.isr_mean,
            k.isr_max,
            us(k.isr_max),
            cost_unit(k),
            f64::from(k.max_jitter_s) * 1e6
        ),
        format!(
            "serial interrupt: max {}{} per interrupt, {} so far (preempts the control interrupt; on the board one byte each way an interrupt, about 18 a period at 921,600 baud; QEMU, with no baud rate, moves many in one)",
            k.serial_max,
            us(k.serial_max),
            k.serial_count
        ),
        format!(
            "link task: mean {} max {} per period, below the control interrupt (decode, answer, encode, build sets); {} period notes dropped",
            k.link_mean, k.link_max, k.notes_dropped
        ),
    ]
}

fn flood(c: &mut Client, seconds: f64) -> Result<()> {
    let n_params = match c.request(Request::ParamCount)? {
        Response::ParamCount(n) => n,
        r => bail!("unexpected answer {r:?}"),
    };
    // (Also starts the robot's window of `isr_max_recent`.)
    let _ = cost_of(c)?;
    let before = status_of(c)?;
    let t = timing_of(c)?;
    let missed_before = t.missed;
    let periods = (seconds / f64::from(t.period_s)).round() as u32;
    let mut now = before.periods;
    let apex = wire_name("target_apex_m")?;
    let start = Instant::now();
    let (mut sent, mut answered, mut refused_sets, mut garbage) = (0u64, 0u64, 0u64, 0u64);
    let mut index = 0u16;
    let mut id = 40_000u16;
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    while now.wrapping_sub(before.periods) < periods {
        // One burst: 24 requests answered without a command to the control
        // period, and 64 bytes of noise.
        let mut bytes = Vec::new();
        let mut ids = Vec::new();
        for k in 0..24u16 {
            let req = match k % 6 {
                0 | 1 => {
                    index = (index + 1) % n_params.max(1);
                    Request::ParamInfo { index }
                }
                2 => Request::Status,
                3 => Request::ParamGet { name: apex.clone() },
                4 => Request::ParamSet {
                    name: apex.clone(),
                    value: 2.0,
                },
                _ if k == 23 => Request::Dump,
                _ => Request::Timing,
            };
            id = id.wrapping_add(1).max(40_000);
            ids.push(id);
            bytes.extend(hopper_link::frame(&HostMsg::Request { id, req })?);
        }
        for _ in 0..64 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            bytes.push((x >> 24) as u8);
        }
        bytes.push(0);
        garbage += 64;
        c.send_raw(&bytes)?;
        sent += ids.len() as u64;
        let deadline = Instant::now() + Duration::from_secs(3);
        let mut left = ids.len();
        while left > 0 {
            match c.next_event(deadline.saturating_duration_since(Instant::now()))? {
                Some(RobotMsg::Response { id: got, resp }) if ids.contains(&got) => {
                    left -= 1;
                    answered += 1;
                    if let Response::Status(s) = &resp {
                        now = s.periods;
                    }
                    if let (Some(4), Response::Refused(_)) =
                        (ids.iter().position(|i| *i == got).map(|p| p % 6), &resp)
                    {
                        refused_sets += 1;
                    }
                }
                Some(_) => {}
                None => bail!(
                    "{left} of a burst's {} requests unanswered within 3 s",
                    ids.len()
                ),
            }
        }
        c.discard_events();
    }
    let wall = start.elapsed().as_secs_f64();
    let after = status_of(c)?;
    let missed = timing_of(c)?.missed.saturating_sub(missed_before);
    println!(
        "flood: {seconds} s of robot time ({} periods, {wall:.1} s wall), {sent} requests ({:.0} per robot s), {answered} answered, {refused_sets} out-of-range sets refused, {garbage} bytes of garbage",
        after.periods.wrapping_sub(before.periods),
        sent as f64 / seconds
    );
    println!(
        "after the flood: {}, faults {}, missed deadlines {missed} during it",
        names::arm_state(after.arm),
        names::faults(after.faults)
    );
    match cost_of(c)? {
        Some(k) => {
            println!(
                "during the flood: control interrupt max {} {}",
                k.isr_max_recent,
                cost_unit(&k)
            );
            for l in cost_lines(&k) {
                println!("{l}");
            }
        }
        None => println!("control interrupt: not reported by this firmware"),
    }
    Ok(())
}

fn silence(c: &mut Client, max_s: f64) -> Result<()> {
    if status_of(c)?.arm != ArmState::Armed {
        bail!("the robot is not armed: arm it first");
    }
    let timeout_s = get(c, "arming.link_timeout_s")?;
    let t = timing_of(c)?;
    let period = f64::from(t.period_s);
    let every = ((0.001 / period).round() as u16).max(1);
    c.expect_ok(Request::Telemetry { every })?;
    // Heartbeats off, then one last frame of our own: a status request,
    // whose answer gives the period the robot received it in. From there
    // to the first disarmed record is the robot's own quiet time, exactly
    // (the host's lag does not enter).
    c.set_heartbeats(false);
    std::thread::sleep(2 * hopper_link::HEARTBEAT);
    let from = status_of(c)?.periods;
    c.discard_queued();
    let start = Instant::now();
    let mut disarmed_at = None;
    let mut reason = None;
    while start.elapsed().as_secs_f64() < max_s {
        match c.next_event(Duration::from_millis(100))? {
            // Only records after the last frame (wrapping comparison).
            Some(RobotMsg::Telemetry(r))
                if !r.armed && disarmed_at.is_none() && (r.step.wrapping_sub(from) as i32) >= 0 =>
            {
                disarmed_at = Some(r.step)
            }
            Some(RobotMsg::State(s @ ArmState::Disarmed(_))) => reason = Some(s),
            _ => {}
        }
        if disarmed_at.is_some() && reason.is_some() {
            break;
        }
    }
    c.set_heartbeats(true);
    c.expect_ok(Request::Telemetry { every: 0 })?;
    let at =
        disarmed_at.ok_or_else(|| anyhow!("still armed {max_s} s after the heartbeats stopped"))?;
    let quiet_s = f64::from(at.wrapping_sub(from)) * period;
    println!(
        "{} {quiet_s:.4} s of robot time after the robot received the host's last frame (link timeout {timeout_s:.3} s)",
        reason.map_or("disarmed".to_string(), names::arm_state)
    );
    if reason != Some(ArmState::Disarmed(5)) {
        bail!("disarmed for another reason: {:?}", reason);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use hopper_protocol::ParamInfo;

    fn info(name: &str, value: f32, default: f32) -> ParamInfo {
        let p = params::find(name).unwrap_or_else(|| panic!("{name}"));
        let mut n = Name::new();
        n.push_str(name).unwrap();
        ParamInfo {
            name: n,
            unit: p.unit.try_into().unwrap(),
            min: p.min,
            max: p.max,
            default,
            value,
            live: false,
        }
    }

    fn index(controller: &str) -> Option<usize> {
        params::CONTROLLER_NAMES
            .iter()
            .position(|c| *c == controller)
    }

    #[test]
    fn an_inactive_parameter_shows_its_default_and_why() {
        let row = param_row(
            &info("energy.gain_nm_per_j", f32::NAN, 0.2),
            index("shaped"),
        );
        assert!(!row.contains("NaN"), "{row}");
        let cells: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cells[..2], ["energy.gain_nm_per_j", "0.2"], "{row}");
        assert!(
            row.ends_with("(inactive: controller energy not selected)"),
            "{row}"
        );
        // The parameter table's row filter (` ..= `) still finds it.
        assert!(row.contains("0 ..= 100"), "{row}");
    }

    #[test]
    fn an_inactive_choice_is_not_shown_as_its_first_name() {
        // NaN cast to an index is 0: it used to read `fixed`.
        let row = param_row(&info("step_closed.gain", f32::NAN, 0.0), index("shaped"));
        assert!(
            row.ends_with("(inactive: controller step-closed not selected)"),
            "{row}"
        );
    }

    #[test]
    fn choices_show_by_name_value_and_default() {
        let row = param_row(&info("controller", 8.0, 5.0), index("shaped"));
        let cells: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(cells[1], "shaped", "{row}");
        assert!(row.contains(" energy-apex "), "{row}");
        assert!(!row.contains("inactive"), "{row}");
    }

    #[test]
    fn arming_requirements_follow_the_robots_parameters() {
        let mut a = ArmingParams {
            link_timeout_s: Some(0.2),
            untethered: Some(false),
            home_tolerance_m: Some(0.001),
            still_velocity_mps: Some(0.05),
            require_tare: Some(false),
            require_home: Some(false),
        };
        let line = a.requirements();
        assert!(
            line.contains("the nut within 1.0 mm of its upper stop"),
            "{line}"
        );
        assert!(
            line.contains("a frame from the host within 0.2 s"),
            "{line}"
        );
        assert!(
            line.ends_with(
                "not required: homing (arming.require_home is 0), a tare (arming.require_tare is 0)"
            ),
            "{line}"
        );
        assert!(
            !line.contains("needs a tare") && !line.contains("tare since boot"),
            "{line}"
        );
        a.require_tare = Some(true);
        a.require_home = Some(true);
        a.untethered = Some(true);
        let line = a.requirements();
        assert!(line.contains("a tare since boot"), "{line}");
        assert!(line.contains("the nut homed since boot"), "{line}");
        assert!(
            line.contains("not required: the link (arming.untethered is 1)"),
            "{line}"
        );
        // A robot that does not say: neither claimed.
        let line = ArmingParams::default().requirements();
        assert!(!line.contains("tare") && !line.contains("homed"), "{line}");
    }

    #[test]
    fn the_saved_calibration_line_says_tare_only_when_required() {
        let nothing = hopper_protocol::StoredInfo {
            boot: 1,
            boot_error: 0,
            entries: 0,
            save: 0,
        };
        assert_eq!(
            stored_line(&nothing, Some(false)),
            "nothing saved: the defaults"
        );
        assert_eq!(
            stored_line(&nothing, Some(true)),
            "nothing saved: the defaults (tare before arming: arming.require_tare is 1)"
        );
    }

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
