//! `hopper-sim planar serve`: the planar machine run live and drawn in a
//! browser. The page carries the drawing; the frames it is fed are those
//! of the recorded run (`planar run --out`'s run.html: the same loop),
//! paced by the wall clock; the run's end is reported.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The server, killed when dropped.
struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `hopper-sim planar serve` with `args` and `run`: the server and the
/// first line it printed (where it listens).
fn serve(args: &[&str], run: &[&str]) -> (Served, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args(["planar", "serve"])
        .args(args)
        .args(run)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    (Served(child), line)
}

/// `GET path` on `addr`: the status line and the body.
fn get(addr: &str, path: &str) -> (String, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap();
    (head.lines().next().unwrap().to_string(), body.to_string())
}

const RUN: [&str; 4] = ["--speed-profile", "0:0.5", "--duration", "4"];

#[test]
fn the_live_page_draws_the_recorded_runs_frames_paced_by_the_clock() {
    let (_served, line) = serve(&["--http", "127.0.0.1:0", "--time-scale", "4"], &RUN);
    let started = Instant::now();
    // "planar: http://127.0.0.1:PORT/ (...)"
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|r| r.split('/').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();

    let (status, page) = get(&addr, "/");
    assert!(status.contains("200"), "{status}");
    assert!(page.contains("function drawPlanar(svg, f)"), "{page}");
    assert!(page.contains("id=\"p-hip\""));

    let (mut frames, mut strides) = (Vec::new(), 0);
    let done = loop {
        assert!(started.elapsed() < Duration::from_secs(60), "no end");
        let (_, body) = get(
            &addr,
            &format!("/frames?from={}&strides={strides}", frames.len()),
        );
        let v: serde_json::Value = serde_json::from_str(&body).unwrap();
        let new = v["frames"].as_array().unwrap();
        strides += v["strides"].as_array().unwrap().len();
        frames.extend(new.iter().cloned());
        if let Some(d) = v["done"].as_str() {
            if new.is_empty() {
                break d.to_string();
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    // 4 s at four times real time: not all at once.
    assert!(started.elapsed() >= Duration::from_millis(900));
    assert!(done.starts_with("ran 4.0 s"), "{done}");
    assert!(strides >= 5, "{strides} strides");
    assert_eq!(frames.len(), 400);
    // Both phases drawn, and the command after the drawing's seven.
    let stance: Vec<f64> = frames.iter().map(|f| f[6].as_f64().unwrap()).collect();
    assert!(stance.contains(&0.0) && stance.contains(&1.0));
    assert!(frames.iter().all(|f| f[7].as_f64() == Some(0.5)));

    // The recorded run's frames, the same numbers.
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args(["planar", "run", "--controller", "raibert", "--out"])
        .arg(dir.path())
        .args(RUN)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(dir.path().join("run.html")).unwrap();
    let recorded = html
        .split("const F = ")
        .nth(1)
        .and_then(|r| r.split(";\n").next())
        .unwrap();
    let recorded: Vec<Vec<f64>> = serde_json::from_str(recorded).unwrap();
    let live: Vec<Vec<f64>> = frames
        .iter()
        .map(|f| {
            f.as_array().unwrap()[..7]
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect();
    assert_eq!(live, recorded);
}

#[test]
fn a_bad_time_scale_or_address_is_refused_naming_it() {
    for (args, flag) in [
        (
            &["--http", "127.0.0.1:0", "--time-scale", "0"][..],
            "--time-scale",
        ),
        (&["--http", "nowhere"][..], "--http"),
        (
            &["--http", "127.0.0.1:0", "--duration", "700"][..],
            "--duration",
        ),
        (&["--tcp", "nowhere"][..], "--tcp"),
        (
            &["--tcp", "127.0.0.1:0", "--inject", "push@1:20"][..],
            "--inject",
        ),
        (
            &["--tcp", "127.0.0.1:0", "--time-scale", "0"][..],
            "--time-scale",
        ),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
            .args(["planar", "serve"])
            .args(args)
            .output()
            .unwrap();
        assert!(!o.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(flag), "{args:?}: {err}");
    }
}

/// A host on the link to `hopper-sim planar serve --tcp`: frames out,
/// messages in.
struct Host {
    s: TcpStream,
    rx: hopper_protocol::Decoder,
    next_id: u16,
}

impl Host {
    fn send(&mut self, m: &hopper_protocol::HostMsg) {
        let mut f = [0u8; hopper_protocol::MAX_FRAME];
        let n = hopper_protocol::encode(m, &mut f).unwrap();
        self.s.write_all(&f[..n]).unwrap();
    }

    /// What came within `wait` (a heartbeat every 20 ms meanwhile, when
    /// `beat`).
    fn read(&mut self, wait: Duration, beat: bool) -> Vec<hopper_protocol::RobotMsg> {
        let end = Instant::now() + wait;
        let mut got = Vec::new();
        let mut buf = [0u8; 4096];
        while Instant::now() < end {
            if beat {
                self.send(&hopper_protocol::HostMsg::Heartbeat);
            }
            if let Ok(n) = self.s.read(&mut buf) {
                got.extend(buf[..n].iter().filter_map(|&b| self.rx.push(b)));
            }
        }
        got
    }

    /// The robot's answer to `req`.
    fn ask(&mut self, req: hopper_protocol::Request) -> hopper_protocol::Response {
        self.next_id += 1;
        let id = self.next_id;
        self.send(&hopper_protocol::HostMsg::Request { id, req });
        let end = Instant::now() + Duration::from_secs(5);
        while Instant::now() < end {
            for m in self.read(Duration::from_millis(20), true) {
                if let hopper_protocol::RobotMsg::Response { id: i, resp } = m {
                    if i == id {
                        return resp;
                    }
                }
            }
        }
        panic!("no answer to request {id}");
    }
}

fn planar(msgs: &[hopper_protocol::RobotMsg]) -> Vec<hopper_protocol::PlanarTelemetry> {
    msgs.iter()
        .filter_map(|m| match m {
            hopper_protocol::RobotMsg::Planar(t) => Some(*t),
            _ => None,
        })
        .collect()
}

/// The machine behind the link is disarmed and held on the boom at
/// first (both amplifiers at 0 A, the hip still); armed, it is let go and
/// hops (stance and flight, the hip at many heights); when the host goes
/// quiet it disarms for a lost link and both amplifiers get 0 A. What it
/// has not is refused by name.
#[test]
fn the_planar_robot_on_the_link_moves_only_while_armed() {
    use hopper_protocol::vocab::Refusal;
    use hopper_protocol::{ArmState, HostMsg, Request, Response, RobotMsg};
    let (_served, line) = serve(
        &["--tcp", "127.0.0.1:0"],
        &["--speed-profile", "0:0.5", "--duration", "60"],
    );
    let addr = line
        .split("listening on ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();
    let s = TcpStream::connect(&addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(5))).unwrap();
    let mut h = Host {
        s,
        rx: hopper_protocol::Decoder::new(),
        next_id: 0,
    };
    h.send(&HostMsg::Hello {
        version: hopper_protocol::PROTOCOL_VERSION,
    });
    assert!(h
        .read(Duration::from_millis(300), false)
        .contains(&RobotMsg::Hello {
            version: hopper_protocol::PROTOCOL_VERSION
        }));
    assert_eq!(
        h.ask(Request::Dump),
        Response::Refused(Refusal::NotThisMachine.into())
    );
    // Held, disarmed: a record every 10 ms.
    assert_eq!(h.ask(Request::Telemetry { every: 100 }), Response::Ok);
    let held = planar(&h.read(Duration::from_millis(500), true));
    assert!(held.len() >= 20, "{} records", held.len());
    assert!(held.iter().all(|t| !t.armed
        && t.hip_current_a == 0.0
        && t.leg_current_a == 0.0
        && t.z_m == held[0].z_m
        && !t.stance));
    assert_eq!(h.ask(Request::Arm), Response::Ok);
    let hopping = planar(&h.read(Duration::from_millis(1500), true));
    assert!(hopping.iter().all(|t| t.armed && t.fault == 0));
    assert!(hopping.iter().any(|t| t.stance) && hopping.iter().any(|t| !t.stance));
    let mut heights: Vec<i64> = hopping.iter().map(|t| (t.z_m * 1e3) as i64).collect();
    heights.dedup();
    assert!(heights.len() >= 20, "{heights:?}");
    assert!(hopping.iter().any(|t| t.leg_current_a != 0.0));
    // Quiet: the link is lost after its 0.2 s.
    let quiet = h.read(Duration::from_millis(800), false);
    assert!(
        quiet.contains(&RobotMsg::State(ArmState::Disarmed(5))),
        "{quiet:?}"
    );
    let after = planar(&quiet);
    let last = after.last().unwrap();
    assert!(!last.armed && last.hip_current_a == 0.0 && last.leg_current_a == 0.0);
}
