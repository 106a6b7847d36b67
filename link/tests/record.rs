//! `hopper-link record` loses nothing: whatever ends a recording early (the
//! link closing, Ctrl-C), every record received is in valid files, the
//! plot is drawn from them, and a line says why it ended.

mod common;

use hopper_protocol::vocab::Refusal;
use hopper_protocol::{Hop, ParamInfo, Request, Response, RobotMsg, Telemetry};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn answer(req: &Request) -> Response {
    match req {
        Request::Timing => common::timing(),
        Request::ParamGet { name } if name.as_str() == "target_apex_m" => Response::Value(0.1),
        Request::ParamCount => Response::ParamCount(2),
        Request::ParamInfo { index } => Response::ParamInfo(ParamInfo {
            name: ["target_apex_m", "energy.gain_nm_per_j"][usize::from(*index).min(1)]
                .try_into()
                .unwrap_or_default(),
            unit: "m".try_into().unwrap_or_default(),
            min: 0.0,
            max: 1.0,
            default: 0.05,
            // The second: another controller's (no value).
            value: if *index == 0 { 0.1 } else { f32::NAN },
            live: true,
        }),
        Request::ParamGet { .. } | Request::ParamMeta { .. } => {
            Response::Refused(Refusal::UnknownParameter.into())
        }
        _ => Response::Ok,
    }
}

/// One telemetry record of period `step` (a 1 kHz robot hopping 0.1 m
/// above its leg).
fn record(step: u32) -> Telemetry {
    let t = f64::from(step) * 1e-3;
    Telemetry {
        seq: step,
        step,
        phase: 0,
        armed: true,
        faults: 0,
        body_height_m: (0.7 + 0.05 * (t * 6.0).sin()) as f32,
        nut_position_m: 0.0,
        spring_force_n: 0.0,
        energy_j: 60.0,
        command_a: 0.0,
    }
}

/// A robot that, once asked to stream, sends `records` telemetry records
/// (one a millisecond when `paced`, else at once) and a hop ledger after
/// the first 500, then closes the link (or, with `hold`, keeps it open
/// for 10 s).
fn robot(records: u32, paced: bool, hold: bool) -> (String, std::thread::JoinHandle<()>) {
    let mut next = 0u32;
    common::robot(15, Duration::from_millis(5), answer, move |s| {
        while next < records {
            if !common::send(s, &RobotMsg::Telemetry(record(next))) {
                return false;
            }
            next += 1;
            if next == 500 {
                common::send(
                    s,
                    &RobotMsg::Hop(Hop {
                        hop: 1,
                        apex_height_m: 0.1,
                        energy_at_touchdown_j: 60.0,
                        energy_at_liftoff_j: 61.0,
                        stance_work_j: 1.0,
                        stance_duration_s: 0.2,
                        peak_current_a: 20.0,
                        peak_stroke_m: 0.02,
                        copper_loss_j: 60.0,
                        stance_copper_loss_j: 20.0,
                    }),
                );
            }
            if paced {
                break;
            }
        }
        // All sent: the robot goes away mid-recording, unless held.
        next < records || hold
    })
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("hopper-link-record-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn lines(p: &Path) -> usize {
    std::fs::read_to_string(p)
        .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
        .lines()
        .count()
}

#[test]
fn a_link_closed_mid_recording_keeps_what_came() {
    let (addr, serve) = robot(1500, false, false);
    let dir = out_dir("closed");
    let o = Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(["--tcp", &addr, "record", "--duration", "5", "--out"])
        .arg(&dir)
        .output()
        .unwrap_or_else(|e| panic!("cannot run hopper-link: {e}"));
    let _ = serve.join();
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    println!("{out}{err}");
    // A failure (exit 1), said once, after the files.
    assert_eq!(o.status.code(), Some(1), "{out}\n{err}");
    assert!(
        err.contains("the recording ended early: ") && err.contains("(1.500 s of 5 s saved in"),
        "{err}"
    );
    assert!(
        out.contains("recorded 1.500 s: 1500 records at 1000 Hz, 0 dropped; 1 hops"),
        "{out}"
    );
    // Every record and the hop, in valid files, and the plot of them.
    assert_eq!(lines(&dir.join("telemetry.csv")), 1 + 1500);
    assert_eq!(lines(&dir.join("hops.csv")), 1 + 1);
    let last = std::fs::read_to_string(dir.join("telemetry.csv")).unwrap_or_default();
    assert!(
        last.lines()
            .last()
            .is_some_and(|l| l.starts_with("1.499000,1499,1499,")),
        "{last}"
    );
    assert!(dir.join("hop.png").metadata().is_ok_and(|m| m.len() > 1000));
    // The MCAP file, read by a reader written from the format's
    // specification: complete (footer, magic) although the link closed,
    // and the same records as the CSV.
    let bytes = std::fs::read(dir.join("telemetry.mcap")).unwrap_or_default();
    let msgs = hopper_mcap::read::messages(&bytes).unwrap_or_else(|e| panic!("{e}"));
    let on = |topic: &str| msgs.iter().filter(|m| m.topic == topic).collect::<Vec<_>>();
    let (telemetry, hops, params) = (on("/telemetry"), on("/hop"), on("/parameters"));
    println!(
        "telemetry.mcap: {} messages: /telemetry {}, /hop {}, /parameters {}, /fault {}",
        msgs.len(),
        telemetry.len(),
        hops.len(),
        params.len(),
        on("/fault").len()
    );
    assert_eq!((telemetry.len(), hops.len(), params.len()), (1500, 1, 1));
    let near = |v: &serde_json::Value, x: f64| v.as_f64().is_some_and(|v| (v - x).abs() < 1e-6);
    assert!(near(&params[0].json["target_apex_m"], 0.1), "{params:?}");
    assert_eq!(
        params[0].json["energy.gain_nm_per_j"],
        serde_json::Value::Null
    );
    assert!(near(&hops[0].json["apex_height_m"], 0.1), "{hops:?}");
    let csv = std::fs::read_to_string(dir.join("telemetry.csv")).unwrap_or_default();
    for (row, m) in csv.lines().skip(1).zip(&telemetry) {
        let cells: Vec<&str> = row.split(',').collect();
        let num = |i: usize| cells[i].parse::<f64>().unwrap_or(f64::NAN);
        let j = |k: &str| m.json[k].as_f64().unwrap_or(f64::NAN);
        // Robot time: the period count times 1 ms.
        assert_eq!(m.log_time_ns, num(2) as u64 * 1_000_000, "{row}");
        assert_eq!(j("step"), num(2), "{row}");
        assert!((j("t_s") - num(0)).abs() < 1e-6, "{row}");
        assert!((j("body_height_m") - num(6)).abs() < 1e-6, "{row}");
        assert!((j("toe_height_m") - num(7)).abs() < 1e-6, "{row}");
        assert_eq!(m.json["phase"], cells[3], "{row}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ctrl_c_ends_a_recording_with_everything_saved() {
    let (addr, serve) = robot(100_000, true, true);
    let dir = out_dir("interrupted");
    let child = Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(["--tcp", &addr, "record", "--duration", "30", "--out"])
        .arg(&dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run hopper-link: {e}"));
    // Until a few hundred records are on disk.
    let csv = dir.join("telemetry.csv");
    let t0 = Instant::now();
    while !(csv.exists() && lines(&csv) > 300) && t0.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(50));
    }
    let interrupted = Instant::now();
    let kill = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    assert!(kill.is_ok_and(|s| s.success()));
    let o = child
        .wait_with_output()
        .unwrap_or_else(|e| panic!("hopper-link: {e}"));
    let took = interrupted.elapsed();
    drop(serve);
    let (out, err) = (
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr),
    );
    println!("{out}{err}");
    // The operator's choice: a success, within a moment.
    assert!(o.status.success(), "{out}\n{err}");
    assert!(took < Duration::from_secs(2), "{took:?}");
    assert!(
        out.contains("the recording ended early: interrupted (Ctrl-C) (")
            && out.contains(" s of 30 s saved in"),
        "{out}"
    );
    let rows = lines(&csv) - 1;
    assert!(rows > 300, "{rows}");
    assert!(
        out.contains(&format!(
            "recorded {:.3} s: {rows} records",
            rows as f64 * 1e-3
        )),
        "{out}"
    );
    assert!(dir.join("hop.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_set_while_recording_is_kept_at_its_time() {
    let dir = out_dir("set");
    let start = [
        ("target_apex_m".to_string(), 0.1f32),
        ("shaped.gain".to_string(), 1.0f32),
    ];
    let mut rec = hopper_link::record::Streamed::create(&dir, 1e-3, &start)
        .unwrap_or_else(|e| panic!("{e:#}"));
    for step in 0..1000 {
        rec.record(record(step)).unwrap_or_else(|e| panic!("{e:#}"));
        if step == 499 {
            rec.set("target_apex_m", 0.12)
                .unwrap_or_else(|e| panic!("{e:#}"));
        }
    }
    // The target read at the end (0.15) is not what the plot draws.
    let (_, written) = rec
        .finish("hop.png", "a set while recording", Some(0.15))
        .unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(written.len(), 4, "{written:?}");
    let bytes = std::fs::read(dir.join("telemetry.mcap")).unwrap_or_default();
    let msgs = hopper_mcap::read::messages(&bytes).unwrap_or_else(|e| panic!("{e}"));
    let params: Vec<_> = msgs.iter().filter(|m| m.topic == "/parameters").collect();
    let at = |i: usize| {
        (
            params[i].log_time_ns,
            params[i].json["target_apex_m"]
                .as_f64()
                .map(|v| (v * 1e6).round()),
            params[i].json["shaped.gain"].as_f64(),
        )
    };
    assert_eq!(params.len(), 2, "{params:?}");
    assert_eq!(at(0), (0, Some(100_000.0), Some(1.0)));
    assert_eq!(at(1), (499_000_000, Some(120_000.0), Some(1.0)));
}
