//! The app's build script:
//!
//! * puts the workspace-root `memory.x` where `cortex-m-rt`'s `link.x`
//!   finds it (only the ARM build links with `-Tlink.x`, see
//!   `.cargo/config.toml`; on the host the search path is unused);
//! * turns the build-time settings into checked constants
//!   (`$OUT_DIR/build_config.rs`): `HOPPER_CONTROL_HZ` (100..=20000, default
//!   10000) and `HOPPER_OVERRUN_LIMIT` (1..=1000, default 3);
//! * for the QEMU images (feature `qemu-sim`), reads the scenario the
//!   scenario image runs from `scenarios/qemu/NAME.toml`
//!   (`HOPPER_QEMU_SCENARIO`, default `energy-apex`; the file the xtask's
//!   golden check runs on the host too) into `$OUT_DIR/qemu_scenario.rs`,
//!   its `[params]` included; and the planar image's run from
//!   `scenarios/qemu/planar.toml` into `$OUT_DIR/planar_scenario.rs`.
//!
//! A bad value stops the build with one error naming it.

use std::fmt::Write as _;
use std::{env, error::Error, fs, ops::RangeInclusive, path::PathBuf};

fn main() -> Result<(), Box<dyn Error>> {
    let manifest_dir = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let root = manifest_dir.join("../..");
    let memory_x = root.join("memory.x");
    let out_dir = PathBuf::from(env::var("OUT_DIR")?);
    fs::copy(&memory_x, out_dir.join("memory.x"))?;
    println!("cargo:rustc-link-search={}", out_dir.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");

    let control_hz = env_u32("HOPPER_CONTROL_HZ", 10_000, 100..=20_000)?;
    let overrun_limit = env_u32("HOPPER_OVERRUN_LIMIT", 3, 1..=1000)?;
    let mut config = String::new();
    writeln!(
        config,
        "/// Control loop rate, Hz: 10 kHz unless the build sets `HOPPER_CONTROL_HZ`\n\
         /// (e.g. `HOPPER_CONTROL_HZ=5000 cargo build ...`), in 100..=20_000.\n\
         pub const CONTROL_HZ: u32 = {control_hz};\n\
         /// Missed control deadlines in a row after which the firmware goes safe\n\
         /// (latches `Fault::Overrun`): 3 unless the build sets `HOPPER_OVERRUN_LIMIT`\n\
         /// (1..=1000). One late period is tolerated (the next one catches up); three\n\
         /// in a row mean the loop cannot keep its rate.\n\
         pub const OVERRUN_LIMIT: u32 = {overrun_limit};"
    )?;
    fs::write(out_dir.join("build_config.rs"), config)?;

    if env::var_os("CARGO_FEATURE_QEMU_SIM").is_some() {
        let scenario = qemu_scenario(&root)?;
        fs::write(out_dir.join("qemu_scenario.rs"), scenario)?;
        let planar = planar_scenario(&root)?;
        fs::write(out_dir.join("planar_scenario.rs"), planar)?;
    }
    Ok(())
}

/// `name` from the environment as a whole number in `range`; `default`
/// when unset.
fn env_u32(name: &str, default: u32, range: RangeInclusive<u32>) -> Result<u32, String> {
    println!("cargo:rerun-if-env-changed={name}");
    let Ok(s) = env::var(name) else {
        return Ok(default);
    };
    match s.trim().parse::<u32>() {
        Ok(v) if range.contains(&v) => Ok(v),
        _ => Err(format!(
            "{name}={s:?}: must be a whole number in {}..={}",
            range.start(),
            range.end()
        )),
    }
}

/// The QEMU scenario image's constants from `scenarios/qemu/NAME.toml`.
fn qemu_scenario(root: &std::path::Path) -> Result<String, Box<dyn Error>> {
    println!("cargo:rerun-if-env-changed=HOPPER_QEMU_SCENARIO");
    let name = env::var("HOPPER_QEMU_SCENARIO").unwrap_or_else(|_| "energy-apex".into());
    let path = root.join("scenarios/qemu").join(format!("{name}.toml"));
    println!("cargo:rerun-if-changed={}", path.display());
    let text = fs::read_to_string(&path).map_err(|e| {
        format!(
            "HOPPER_QEMU_SCENARIO={name}: cannot read {}: {e}",
            path.display()
        )
    })?;
    let t: toml::Table = text
        .parse()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let at = |keys: &[&str]| -> Option<&toml::Value> {
        let (last, parents) = keys.split_last()?;
        let mut table = &t;
        for k in parents {
            table = table.get(*k)?.as_table()?;
        }
        table.get(*last)
    };
    let bad = |what: &str| format!("{}: {what}", path.display());
    let number = |keys: &[&str]| -> Result<f64, String> {
        match at(keys) {
            Some(toml::Value::Float(v)) => Ok(*v),
            Some(toml::Value::Integer(v)) => Ok(*v as f64),
            _ => Err(bad(&format!("`{}` must be a number", keys.join(".")))),
        }
    };
    // What the image can run: the design plant with its default sensors
    // (noise on, seed 1), one of the two laws it is built for.
    if at(&["plant"]).and_then(toml::Value::as_str) != Some("design") {
        return Err(bad("the QEMU image runs `plant = \"design\"` only").into());
    }
    if at(&["sensors", "noise"]).and_then(toml::Value::as_bool) != Some(true)
        || at(&["sensors", "seed"]).and_then(toml::Value::as_integer) != Some(1)
    {
        return Err(bad(
            "the QEMU image runs its default sensors: `[sensors] noise = true, seed = 1`",
        )
        .into());
    }
    let controller = at(&["controller", "name"]).and_then(toml::Value::as_str);
    let shaped = match controller {
        Some("shaped") => true,
        Some("energy-apex") => false,
        other => {
            return Err(bad(&format!(
                "`controller.name` {other:?}: the QEMU image runs `shaped` or `energy-apex`"
            ))
            .into())
        }
    };
    let start = number(&["start_apex_m"])?;
    let target = number(&["controller", "target_apex_m"])?;
    let duration = number(&["duration_s"])?;
    if !(duration >= 1.0 && duration.fract() == 0.0 && duration <= 600.0) {
        return Err(bad("`duration_s` must be whole seconds in 1..=600").into());
    }
    // Quick profiling runs shorten it.
    let seconds = env_u32("HOPPER_QEMU_SECONDS", duration as u32, 1..=600)?;
    // Firmware parameters by name, set on the configuration as the host's
    // scenario reader sets them (the image checks each name and value).
    let mut params = String::new();
    if let Some(table) = at(&["params"]) {
        let table = table
            .as_table()
            .ok_or_else(|| bad("`[params]` must be a table of NAME = number"))?;
        for (name, value) in table {
            let v = match value {
                toml::Value::Float(v) => *v,
                toml::Value::Integer(v) => *v as f64,
                toml::Value::Boolean(b) => f64::from(u8::from(*b)),
                _ => return Err(bad(&format!("`params.{name}` must be a number")).into()),
            };
            if !(v as f32).is_finite() {
                return Err(bad(&format!("`params.{name}` must be a finite f32")).into());
            }
            write!(params, "({name:?}, {:?}_f32), ", v as f32)?;
        }
    }
    let mut s = String::new();
    writeln!(
        s,
        "/// The scenario's name, as printed (`scenarios/qemu/{name}.toml`).\n\
         const SCENARIO: &str = {name:?};\n\
         /// The shaped law (else energy-apex).\n\
         const SHAPED: bool = {shaped};\n\
         /// Start toe height, m.\n\
         pub const START_APEX_M: f64 = {start:?};\n\
         /// Apex target, m.\n\
         pub const TARGET_APEX_M: f64 = {target:?};\n\
         /// Simulated time, s (`HOPPER_QEMU_SECONDS` at build time overrides\n\
         /// the file's for quick profiling runs).\n\
         pub const DURATION_S: u32 = {seconds};\n\
         /// The scenario's `[params]`: firmware parameters by name, set in\n\
         /// this order on the configuration before the runner is built.\n\
         pub const PARAMS: &[(&str, f32)] = &[{params}];"
    )?;
    Ok(s)
}

/// The QEMU planar image's constants from `scenarios/qemu/planar.toml`:
/// the speed profile (`T:V,...` from time 0, times increasing), the apex
/// target, the whole seconds it runs and the leg's drive (`thrust`:
/// `force` when left out).
fn planar_scenario(root: &std::path::Path) -> Result<String, Box<dyn Error>> {
    let path = root.join("scenarios/qemu/planar.toml");
    println!("cargo:rerun-if-changed={}", path.display());
    let text = fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let t: toml::Table = text
        .parse()
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let bad = |what: &str| format!("{}: {what}", path.display());
    let profile = t
        .get("speed_profile")
        .and_then(toml::Value::as_str)
        .ok_or_else(|| bad("`speed_profile` must be a string `T:V,...`"))?;
    let mut steps = String::new();
    let mut last = -1.0;
    for item in profile.split(',') {
        let (a, b) = item
            .split_once(':')
            .ok_or_else(|| bad(&format!("`speed_profile` item `{item}` is not T:V")))?;
        let (time, speed): (f64, f64) = (
            a.trim()
                .parse()
                .map_err(|_| bad(&format!("`{a}` is not a time")))?,
            b.trim()
                .parse()
                .map_err(|_| bad(&format!("`{b}` is not a speed")))?,
        );
        if (last < 0.0 && time != 0.0) || time <= last || speed.abs() > 3.0 {
            return Err(bad(
                "`speed_profile` starts at 0 s, its times increase, speeds within +-3 m/s",
            )
            .into());
        }
        last = time;
        write!(steps, "({time:?}, {speed:?}), ")?;
    }
    let target = match t.get("target_apex_m") {
        Some(toml::Value::Float(v)) if (0.02..=0.5).contains(v) => *v,
        _ => return Err(bad("`target_apex_m` must be a number in 0.02..=0.5").into()),
    };
    let duration = match t.get("duration_s") {
        Some(toml::Value::Integer(v)) if (1..=600).contains(v) => *v,
        _ => return Err(bad("`duration_s` must be whole seconds in 1..=600").into()),
    };
    // The leg's drive: a force along it, or its motor and ball screw run
    // by a vertical law (its name checked against the laws at `init`).
    let thrust = match t.get("thrust") {
        None => "force",
        Some(toml::Value::String(v))
            if !v.is_empty()
                && v.bytes()
                    .all(|b| b.is_ascii_lowercase() || b.is_ascii_digit() || b == b'-') =>
        {
            v.as_str()
        }
        Some(_) => {
            return Err(bad("`thrust` must be `force` or a vertical controller's name").into())
        }
    };
    let leg = if thrust == "force" {
        "hopper_sil::planar::ForceLeg"
    } else {
        "hopper_control::planar::thrust::ScrewThrust"
    };
    Ok(format!(
        "/// How the leg is driven: `force` or a vertical law's name.\n\
         pub const PLANAR_THRUST: &str = {thrust:?};\n\
         /// The loop's leg law for [`PLANAR_THRUST`].\n\
         pub type PlanarLeg = {leg};\n\
         /// The speed command's steps `(from s, m/s)`.\n\
         pub const PLANAR_PROFILE: &[(f64, f64)] = &[{steps}];\n\
         /// The toe's apex to hold, m.\n\
         pub const PLANAR_TARGET_APEX_M: f32 = {target:?};\n\
         /// Simulated time, s.\n\
         pub const PLANAR_DURATION_S: u32 = {duration};\n"
    ))
}
