//! `hopper-link robot load` is all or nothing: a file whose second value
//! the robot refuses leaves the first as it was (put back), and the error
//! says so; an armed robot is refused before anything is sent.

mod common;

use hopper_protocol::vocab::{ParamKind, Refusal};
use hopper_protocol::{ArmState, ParamInfo, ParamMeta, Request, Response, Status};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The two entries the file sets, with the robot's values.
const NAMES: [&str; 2] = ["model.body_mass_kg", "model.nut_mass_kg"];

/// A robot holding 9 kg and 0.25 kg that refuses any nut mass set (as a
/// robot whose firmware checks more than this host does would), armed or
/// not; every set it takes is recorded in `sets`.
fn answer(
    armed: bool,
    values: Arc<Mutex<[f32; 2]>>,
    sets: Arc<Mutex<Vec<(String, f32)>>>,
) -> impl FnMut(&Request) -> Response + Send + 'static {
    move |req| {
        let index = |n: &str| NAMES.iter().position(|x| *x == n);
        match req {
            Request::Status => Response::Status(Status {
                arm: if armed {
                    ArmState::Armed
                } else {
                    ArmState::Disarmed(0)
                },
                faults: 0,
                periods: 1,
                frames_ok: 1,
                frames_bad: 0,
                telemetry_dropped: 0,
                last_apex_m: f32::NAN,
            }),
            Request::ParamMeta { name } => match index(name.as_str()) {
                Some(i) => Response::ParamMeta(ParamMeta {
                    index: i as u16,
                    kind: ParamKind::Real.code(),
                    choices: 0,
                    controller: None,
                    needs: None,
                }),
                None => Response::Refused(Refusal::UnknownParameter.into()),
            },
            Request::ParamInfo { index } => {
                let i = usize::from(*index).min(1);
                Response::ParamInfo(ParamInfo {
                    name: NAMES[i].try_into().unwrap_or_default(),
                    unit: "kg".try_into().unwrap_or_default(),
                    min: 1e-9,
                    max: 1000.0,
                    default: 1.0,
                    value: values.lock().map(|v| v[i]).unwrap_or(f32::NAN),
                    live: false,
                })
            }
            Request::ParamGet { name } => match index(name.as_str()) {
                Some(i) => Response::Value(values.lock().map(|v| v[i]).unwrap_or(f32::NAN)),
                None => Response::Refused(Refusal::UnknownParameter.into()),
            },
            Request::ParamSet { name, value } => {
                let Some(i) = index(name.as_str()) else {
                    return Response::Refused(Refusal::UnknownParameter.into());
                };
                if i == 1 {
                    return Response::Refused(Refusal::OutOfRange.into());
                }
                if let Ok(mut s) = sets.lock() {
                    s.push((name.to_string(), *value));
                }
                if let Ok(mut v) = values.lock() {
                    v[i] = *value;
                }
                Response::Ok
            }
            Request::Timing => common::timing(),
            _ => Response::Ok,
        }
    }
}

fn load(armed: bool) -> (std::process::Output, [f32; 2], Vec<(String, f32)>) {
    let values = Arc::new(Mutex::new([9.0f32, 0.25]));
    let sets = Arc::new(Mutex::new(Vec::new()));
    let (addr, robot) = common::robot(
        10,
        Duration::from_millis(5),
        answer(armed, values.clone(), sets.clone()),
        |_| true,
    );
    let file = std::env::temp_dir().join(format!(
        "hopper-link-robot-{}-{}.toml",
        std::process::id(),
        u8::from(armed)
    ));
    std::fs::write(&file, "[model]\nbody_mass_kg = 12.0\nnut_mass_kg = 0.3\n")
        .unwrap_or_else(|e| panic!("{e}"));
    let o = Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(["--tcp", &addr, "robot", "load"])
        .arg(&file)
        .output()
        .unwrap_or_else(|e| panic!("{e}"));
    drop(robot);
    let _ = std::fs::remove_file(&file);
    let v = values.lock().map(|v| *v).unwrap_or([f32::NAN; 2]);
    let s = sets.lock().map(|s| s.clone()).unwrap_or_default();
    (o, v, s)
}

#[test]
fn a_refused_value_puts_back_what_was_set_before_it() {
    let (o, values, sets) = load(false);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains(
            "`model.nut_mass_kg = 0.3` refused by the robot: out-of-range; nothing changed"
        ),
        "{err}"
    );
    // The mass was set to 12 kg, then put back to 9 kg.
    assert_eq!(
        sets,
        vec![
            ("model.body_mass_kg".to_string(), 12.0),
            ("model.body_mass_kg".to_string(), 9.0)
        ]
    );
    assert_eq!(values, [9.0, 0.25]);
}

#[test]
fn an_armed_robot_is_refused_before_anything_is_sent() {
    let (o, values, sets) = load(true);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{err}");
    assert!(err.contains("refused: the robot is armed"), "{err}");
    assert!(err.contains("nothing changed"), "{err}");
    assert!(sets.is_empty(), "{sets:?}");
    assert_eq!(values, [9.0, 0.25]);
}
