//! The `hopper-link` binary as an operator runs it: its address errors,
//! and `params` against a small robot that answers like the firmware
//! (a parameter of an unselected controller has no value: NaN, and
//! reading or setting it is refused).

mod common;

use hopper_protocol::vocab::{Refusal, RefusalCode};
use hopper_protocol::{ParamInfo, ParamMeta, Request, Response};
use std::process::{Command, Output};
use std::time::Duration;

fn hopper_link(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run hopper-link: {e}"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn every_address_error_names_both_ways_to_give_one() {
    let runs: [&[&str]; 5] = [
        &["status"],
        &[
            "--tcp",
            "127.0.0.1:7300",
            "--serial",
            "/dev/ttyUSB0",
            "status",
        ],
        &["--tcp", "no-port-here", "status"],
        &["--tcp", "127.0.0.1:99999", "status"],
        &["--serial", "/dev/no-such-hopper", "status"],
    ];
    for args in runs {
        let o = hopper_link(args);
        let e = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(
            e.contains("--tcp HOST:PORT") && e.contains("--serial PORT"),
            "{args:?}: {e}"
        );
    }
}

/// The firmware's table entry `name` with `value` (NaN: not in the
/// robot's configuration).
fn entry(name: &str, value: f32) -> ParamInfo {
    let p = hopper_control::params::find(name).unwrap_or_else(|| panic!("{name}"));
    ParamInfo {
        name: name.try_into().unwrap_or_else(|_| panic!("{name}")),
        unit: p.unit.try_into().unwrap_or_else(|_| panic!("{name}")),
        min: p.min,
        max: p.max,
        default: p.default,
        value,
        live: p.name == "target_apex_m",
    }
}

/// A robot running `shaped` whose table is three entries; answers one
/// connection until it closes or 10 s passed.
fn robot() -> (String, std::thread::JoinHandle<()>) {
    let table = [
        entry("controller", 8.0),
        entry("target_apex_m", 0.1),
        entry("energy.gain_nm_per_j", f32::NAN),
    ];
    common::robot(
        10,
        Duration::from_millis(20),
        move |req| answer(&table, req),
        |_| true,
    )
}

fn refused(why: Refusal) -> Response {
    Response::Refused(why.into())
}

/// What the firmware's endpoint answers (`hopper_robot_link`).
fn answer(table: &[ParamInfo], req: &Request) -> Response {
    match req {
        Request::ParamCount => Response::ParamCount(table.len() as u16),
        Request::ParamInfo { index } => table.get(usize::from(*index)).map_or_else(
            || refused(Refusal::NoSuchIndex),
            |p| Response::ParamInfo(p.clone()),
        ),
        Request::ParamGet { name } => match table.iter().find(|p| p.name == *name) {
            Some(p) if !p.value.is_nan() => Response::Value(p.value),
            _ => refused(Refusal::UnknownParameter),
        },
        Request::ParamSet { .. } => refused(Refusal::ControllerNotSelected),
        // The firmware's description, with the index into this table.
        Request::ParamMeta { name } => match (
            hopper_robot_link::param_meta(name.as_str()),
            table.iter().position(|p| p.name == *name),
        ) {
            (Response::ParamMeta(m), Some(i)) => Response::ParamMeta(ParamMeta {
                index: i as u16,
                needs: None,
                ..m
            }),
            _ => refused(Refusal::UnknownParameter),
        },
        Request::ParamChoice { name, value } => {
            hopper_robot_link::param_choice(name.as_str(), *value)
        }
        // A reason this host does not know (a newer robot's).
        _ => Response::Refused(RefusalCode(250)),
    }
}

#[test]
fn params_list_shows_defaults_for_inactive_parameters_and_choices_by_name() {
    let (addr, serve) = robot();
    let o = hopper_link(&["--tcp", &addr, "params", "list"]);
    let out = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(o.status.success(), "{}", stderr(&o));
    serve
        .join()
        .unwrap_or_else(|_| panic!("the robot thread panicked"));
    assert!(!out.contains("NaN"), "{out}");
    let row = |name: &str| -> Vec<String> {
        out.lines()
            .find(|l| l.starts_with(&format!("{name} ")))
            .unwrap_or_else(|| panic!("no {name} row: {out}"))
            .split_whitespace()
            .map(str::to_string)
            .collect()
    };
    // Value and default by name.
    let controller = row("controller");
    assert_eq!(controller[1], "shaped", "{out}");
    assert!(controller.contains(&"energy-apex".to_string()), "{out}");
    // The default, marked.
    let energy = row("energy.gain_nm_per_j");
    assert_eq!(energy[1], "0.2", "{out}");
    assert!(
        energy
            .join(" ")
            .ends_with("(inactive: controller energy not selected)"),
        "{out}"
    );
    assert!(
        !row("target_apex_m").join(" ").contains("inactive"),
        "{out}"
    );
    assert!(
        out.trim_end().ends_with(
            "3 parameters; 1 inactive (not used by the selected controller, shaped: shown at their defaults)"
        ),
        "{out}"
    );
}

#[test]
fn reading_or_setting_an_inactive_parameter_says_how_to_activate_it() {
    for (args, start) in [
        (
            &["params", "get", "energy.gain_nm_per_j"][..],
            "get energy.gain_nm_per_j: ",
        ),
        (
            &["params", "set", "energy.gain_nm_per_j", "0.3"],
            "set energy.gain_nm_per_j = 0.3 refused: controller-not-selected (",
        ),
    ] {
        let (addr, serve) = robot();
        let o = hopper_link(&[&["--tcp", addr.as_str()][..], args].concat());
        serve
            .join()
            .unwrap_or_else(|_| panic!("the robot thread panicked"));
        let e = stderr(&o);
        assert!(!o.status.success(), "{args:?}");
        assert!(
            e.starts_with(&format!("hopper-link: error: {start}inactive: controller energy not selected; default 0.2 N m/J; activate it with `params set controller energy`")),
            "{args:?}: {e}"
        );
    }
}

/// A robot whose e-stop was just released: its debounce (50 ms of robot
/// time, which a slow robot such as QEMU takes seconds of wall time to
/// run) refuses the first three resets, then clears the latch.
fn releasing_robot() -> (String, std::thread::JoinHandle<()>) {
    let mut refusals = 3;
    common::robot(
        10,
        Duration::from_millis(20),
        move |req| match req {
            Request::ResetFaults if refusals > 0 => {
                refusals -= 1;
                refused(Refusal::FaultsRemain)
            }
            Request::ResetFaults => Response::Ok,
            Request::Status => Response::Status(hopper_protocol::Status {
                arm: hopper_protocol::ArmState::Disarmed(0),
                faults: if refusals > 0 { 1 } else { 0 },
                periods: 1,
                frames_ok: 1,
                frames_bad: 0,
                telemetry_dropped: 0,
                last_apex_m: f32::NAN,
            }),
            _ => Response::Ok,
        },
        |_| true,
    )
}

/// `reset-faults` asks once: a latch still held is refused and named.
/// `reset-faults --retry S` asks again until the robot clears it (or S
/// wall seconds passed), as `arm --retry` does.
#[test]
fn reset_faults_retries_while_a_cause_is_still_going() {
    let (addr, robot) = releasing_robot();
    let o = hopper_link(&["--tcp", &addr, "reset-faults"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("faults-remain"), "{}", stderr(&o));
    let _ = robot.join();
    let (addr, robot) = releasing_robot();
    let o = hopper_link(&["--tcp", &addr, "reset-faults", "--retry", "5"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains("faults reset; latched now: none"),
        "{}",
        String::from_utf8_lossy(&o.stdout)
    );
    let _ = robot.join();
}

/// A robot whose control periods run `robot_per_wall` robot seconds per
/// wall second (a traced QEMU image runs about 1/8 of real time) and
/// whose `sensors` routine ends after `routine_s` of its own time (never,
/// for infinity).
fn slow_robot(robot_per_wall: f64, routine_s: f64) -> (String, std::thread::JoinHandle<()>) {
    use hopper_protocol::vocab::CalState;
    use hopper_protocol::{BringupResults, CalibrationInfo, TimingStats};
    use std::time::Instant;
    let boot = Instant::now();
    let period_s = 0.001;
    let periods = move || (boot.elapsed().as_secs_f64() * robot_per_wall / period_s) as u32;
    let mut started = None;
    common::robot(
        20,
        Duration::from_millis(20),
        move |req| match req {
            Request::ParamGet { .. } => Response::Value(1.0),
            Request::Calibrate { .. } => {
                started = Some(periods());
                Response::Ok
            }
            Request::Timing => Response::Timing(TimingStats {
                period_s: period_s as f32,
                periods: periods(),
                missed: 0,
                step_mean: 0,
                step_max: 0,
                link_mean: 0,
                link_max: 0,
            }),
            Request::CalibrationReport => {
                let ran_s = started.map_or(0.0, |p| f64::from(periods() - p) * period_s);
                let state = if ran_s >= routine_s {
                    CalState::Done
                } else {
                    CalState::Running
                };
                Response::Calibration(CalibrationInfo {
                    routine: 0,
                    state: state.code(),
                    samples: (ran_s / period_s) as u32,
                    loadcell_mean_code: 2048.0,
                    loadcell_std_code: 1.0,
                    pot_mean_code: 2048.0,
                    pot_std_code: 1.0,
                    motor_span_counts: 0,
                    height_span_counts: 0,
                    loadcell_offset_code: f32::NAN,
                    pot_offset_code: f32::NAN,
                })
            }
            Request::BringupResults => Response::BringupResults(BringupResults {
                routine: 0,
                state: CalState::Done.code(),
                nut_travel_m: f32::NAN,
                force_change_n: f32::NAN,
                nut_offset_m: f32::NAN,
                spring_rate_n_per_m: f32::NAN,
                spring_intercept_n: f32::NAN,
                fit_rms_n: f32::NAN,
                fit_points: 0,
                fit_span_m: f32::NAN,
                height_offset_m: f32::NAN,
                peak_current_a: 0.0,
            }),
            _ => Response::Refused(RefusalCode(250)),
        },
        |_| true,
    )
}

/// A routine's time limit is robot time: a robot running at 1/200 of
/// real time (a loaded machine's traced QEMU image, slower still) takes
/// 6 s of wall time for 0.03 s of measuring, past the 5.2 s the limit
/// (`--seconds 0.01`: 20 times it plus 5 s) would be in wall time, and
/// its routine still ends as it should.
#[test]
fn a_routine_on_a_slow_robot_is_timed_by_the_robots_clock() {
    let (addr, robot) = slow_robot(1.0 / 200.0, 0.03);
    let o = hopper_link(&["--tcp", &addr, "calibrate", "sensors", "--seconds", "0.01"]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}{out}", stderr(&o));
    // (30 samples or a few more: the fake robot's clock goes on between
    // the poll that sees it done and the report.)
    let samples = out
        .split("calibrate sensors: done: ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|n| n.parse::<u32>().ok());
    assert!(samples.is_some_and(|n| (30..40).contains(&n)), "{out}");
    let _ = robot.join();
}

/// A robot whose periods stopped (its control interrupt no longer runs,
/// though the link still answers) does not keep the host waiting: after
/// 10 s without a new count the routine is given up with the period it
/// stopped at.
#[test]
fn a_routine_on_a_robot_whose_clock_stopped_is_given_up() {
    let (addr, robot) = slow_robot(0.0, f64::INFINITY);
    let o = hopper_link(&["--tcp", &addr, "calibrate", "sensors", "--seconds", "0.01"]);
    let e = stderr(&o);
    assert!(!o.status.success());
    assert!(
        e.contains("the robot's control periods stopped at period 0 (10 s without one)"),
        "{e}"
    );
    let _ = robot.join();
}
