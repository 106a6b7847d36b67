//! `robot show` and `robot load`: one machine's constants and calibration
//! as a robot file (the firmware table's names, `hopper_robot_file`), read
//! from a robot or given to it all at once.

use super::common::{read_param, status_of, wire_name};
use anyhow::{anyhow, bail, Context, Result};
use hopper_link::names;
use hopper_link::Client;
use hopper_protocol::{vocab::Refusal, ArmState, Request, Response};
use std::path::Path;
use std::time::{Duration, Instant};

/// `robot show [--out FILE]`: the robot's values of every robot-file entry,
/// as a robot file that `robot load` takes back.
pub(crate) fn show(c: &mut Client, out: Option<&Path>) -> Result<()> {
    let mut values = Vec::new();
    for p in hopper_robot_file::entries() {
        match read_param(c, p.name)? {
            Ok(v) => values.push((*p, v)),
            Err(why) => bail!(
                "robot show: the robot has no `{}` ({why}): its firmware is older than this hopper-link",
                p.name
            ),
        }
    }
    let text = hopper_robot_file::to_toml(&values, "as read from the robot", None);
    match out {
        Some(path) => {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .with_context(|| format!("creating {}", dir.display()))?;
            }
            std::fs::write(path, &text).with_context(|| format!("writing {}", path.display()))?;
            println!(
                "wrote {}: {} entries (model, calibration, supervisor spring)",
                path.display(),
                values.len()
            );
        }
        None => print!("{text}"),
    }
    Ok(())
}

/// One set, asked again while the robot is still installing the previous
/// change (`busy`, a few periods), for up to 1 s.
fn set(c: &mut Client, name: &str, v: f32) -> Result<std::result::Result<(), String>> {
    let deadline = Instant::now() + Duration::from_secs(1);
    loop {
        match c.request(Request::ParamSet {
            name: wire_name(name)?,
            value: v,
        })? {
            Response::Ok => return Ok(Ok(())),
            Response::Refused(why) if why == Refusal::Busy && Instant::now() < deadline => {
                std::thread::sleep(Duration::from_millis(10));
            }
            Response::Refused(why) => return Ok(Err(why.to_string())),
            r => bail!("unexpected answer {r:?}"),
        }
    }
}

/// `robot load FILE`: every entry of the file set on the robot, or none.
/// The file is checked whole first (each name, each value in its range on
/// this host's table and on the robot's, the machine as the controller
/// would build it), the robot must be disarmed, and a set the robot
/// refuses puts back the entries set before it.
pub(crate) fn load(c: &mut Client, path: &Path) -> Result<()> {
    let shown = path.display();
    let robot =
        hopper_robot_file::load(path).map_err(|e| anyhow!("robot load: {e}; nothing changed"))?;
    if matches!(status_of(c)?.arm, ArmState::Armed) {
        bail!(
            "robot load {shown} refused: the robot is armed (the machine's constants change only disarmed): disarm first; nothing changed"
        );
    }
    // The robot's own table: each entry present and the value in its range.
    let mut before = Vec::with_capacity(robot.values.len());
    for (p, v) in &robot.values {
        let d = names::describe(c, p.name)?.ok_or_else(|| {
            anyhow!(
                "robot load {shown}: the robot has no `{}`: its firmware is older than this hopper-link; nothing changed",
                p.name
            )
        })?;
        if !(*v >= d.info.min && *v <= d.info.max) {
            bail!(
                "robot load {shown}: `{} = {v}` is out of the robot's range {} ..= {} {}; nothing changed",
                p.name,
                d.info.min,
                d.info.max,
                d.info.unit
            );
        }
        let now = read_param(c, p.name)?.map_err(|why| {
            anyhow!(
                "robot load {shown}: reading `{}`: {why}; nothing changed",
                p.name
            )
        })?;
        before.push((*p, now));
    }
    let mut done: Vec<(&str, f32)> = Vec::new();
    for ((p, v), (_, was)) in robot.values.iter().zip(&before) {
        if *v == *was {
            continue;
        }
        if let Err(why) = set(c, p.name, *v)? {
            // Put back, newest first, what was set before the refusal.
            let mut restored = 0;
            for (name, old) in done.iter().rev() {
                if set(c, name, *old)?.is_ok() {
                    restored += 1;
                }
            }
            let undone = if restored == done.len() {
                "nothing changed".to_string()
            } else {
                format!(
                    "{} of {} entries set before it could not be put back: check with `robot show`",
                    done.len() - restored,
                    done.len()
                )
            };
            bail!(
                "robot load {shown}: `{} = {v}` refused by the robot: {why}; {undone}",
                p.name
            );
        }
        done.push((p.name, *was));
    }
    let plant = if robot.plant.is_empty() {
        String::new()
    } else {
        format!(
            "; its [plant] section ({} entries) is the simulator's and was not sent",
            robot.plant.len()
        )
    };
    println!(
        "loaded {shown}: {} of {} entries changed, the rest already so (not saved: `save` keeps them across a reset){plant}",
        done.len(),
        robot.values.len()
    );
    Ok(())
}
