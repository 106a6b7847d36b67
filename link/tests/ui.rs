//! `hopper-link ui`, the cockpit, against a small robot: it lets in only
//! its operator (the token, `Host`, `Origin`), and nothing a refused
//! request asks reaches the robot; its page's websocket streams moving
//! values, and Arm, an out-of-range set and Disarm are answered as the
//! robot answers them.

mod common;

use hopper_protocol::vocab::Refusal;
use hopper_protocol::{
    ArmState, CostStats, ParamInfo, ParamMeta, Request, Response, RobotMsg, Status, Telemetry,
    ThermalStatus,
};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What reached the robot: arm and disarm requests, sets.
#[derive(Default)]
struct Seen {
    arms: AtomicU32,
    disarms: AtomicU32,
    sets: AtomicU32,
}

fn answer(req: &Request, armed: &AtomicBool, seen: &Seen) -> Response {
    match req {
        Request::Timing => common::timing(),
        Request::Status => Response::Status(Status {
            arm: if armed.load(Ordering::Relaxed) {
                ArmState::Armed
            } else {
                ArmState::Disarmed(0)
            },
            faults: 0,
            periods: 0,
            frames_ok: 0,
            frames_bad: 0,
            telemetry_dropped: 0,
            last_apex_m: f32::NAN,
        }),
        Request::Cost => Response::Cost(CostStats {
            counter_hz: 168_000_000,
            isr_mean: 1300,
            isr_max: 1500,
            isr_max_recent: 1500,
            link_mean: 0,
            link_max: 0,
            serial_max: 0,
            serial_count: 0,
            max_jitter_s: 0.0,
            notes_dropped: 0,
            pacing: 1,
            late_period: hopper_protocol::NO_LATE_PERIOD,
            late_cause: 0,
            late_jitter_s: 0.0,
            late_serial: 0,
            serial_lost: 0,
        }),
        Request::Thermal => Response::Thermal(ThermalStatus {
            winding_c: 40.0,
            housing_c: 30.0,
            limit_scale: 1.0,
            derate_c: 135.0,
            trip_c: 150.0,
            protect: true,
        }),
        Request::ParamCount => Response::ParamCount(1),
        Request::ParamInfo { .. } => Response::ParamInfo(ParamInfo {
            name: "target_apex_m".try_into().unwrap_or_default(),
            unit: "m".try_into().unwrap_or_default(),
            min: 0.0,
            max: 1.0,
            default: 0.05,
            value: 0.1,
            live: true,
        }),
        Request::ParamMeta { name } if name.as_str() == "target_apex_m" => {
            Response::ParamMeta(ParamMeta {
                index: 0,
                kind: 0,
                choices: 0,
                controller: None,
                needs: None,
            })
        }
        Request::ParamMeta { .. } | Request::ParamGet { .. } => {
            Response::Refused(Refusal::UnknownParameter.into())
        }
        Request::ParamSet { value, .. } => {
            seen.sets.fetch_add(1, Ordering::Relaxed);
            if (0.0..=1.0).contains(value) {
                Response::Ok
            } else {
                Response::Refused(Refusal::OutOfRange.into())
            }
        }
        Request::Arm => {
            seen.arms.fetch_add(1, Ordering::Relaxed);
            armed.store(true, Ordering::Relaxed);
            Response::Ok
        }
        Request::Disarm => {
            seen.disarms.fetch_add(1, Ordering::Relaxed);
            armed.store(false, Ordering::Relaxed);
            Response::Ok
        }
        _ => Response::Ok,
    }
}

/// A robot streaming a hop (one record a millisecond of wall time) once
/// asked; 30 s at most.
fn robot(seen: Arc<Seen>) -> String {
    let armed = Arc::new(AtomicBool::new(false));
    let on = armed.clone();
    let mut step = 0u32;
    let (addr, _) = common::robot(
        30,
        Duration::from_millis(1),
        move |req| answer(req, &armed, &seen),
        move |s| {
            step += 5;
            let t = f64::from(step) * 1e-3;
            let r = Telemetry {
                seq: step,
                step,
                phase: 0,
                armed: on.load(Ordering::Relaxed),
                faults: 0,
                body_height_m: (0.7 + 0.05 * (t * 6.0).sin()) as f32,
                nut_position_m: 0.0,
                spring_force_n: 10.0,
                energy_j: 60.0,
                command_a: 0.0,
            };
            common::send(s, &RobotMsg::Telemetry(r))
        },
    );
    addr
}

struct Cockpit {
    child: Child,
    /// Held open: the cockpit prints more after its address.
    _stdout: BufReader<std::process::ChildStdout>,
    url: String,
    host: String,
    token: String,
}

impl Drop for Cockpit {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn cockpit(robot: &str) -> Cockpit {
    let mut child = Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(["--tcp", robot, "ui", "--http", "127.0.0.1:0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot run hopper-link: {e}"));
    let mut line = String::new();
    let stdout = child.stdout.take().unwrap_or_else(|| panic!("no stdout"));
    let mut stdout = BufReader::new(stdout);
    stdout
        .read_line(&mut line)
        .unwrap_or_else(|e| panic!("{e}"));
    let url = line
        .trim()
        .strip_prefix("cockpit: ")
        .unwrap_or_else(|| panic!("first line: {line}"))
        .to_string();
    let host = url
        .trim_start_matches("http://")
        .split('/')
        .next()
        .unwrap_or_default()
        .to_string();
    let token = url.split("token=").nth(1).unwrap_or_default().to_string();
    Cockpit {
        child,
        _stdout: stdout,
        url,
        host,
        token,
    }
}

/// A plain HTTP GET with these headers: the status line.
fn get(host: &str, target: &str, headers: &[(&str, &str)]) -> String {
    let mut s = TcpStream::connect(host).unwrap_or_else(|e| panic!("{e}"));
    let mut req = format!("GET {target} HTTP/1.1\r\n");
    for (k, v) in headers {
        req += &format!("{k}: {v}\r\n");
    }
    req += "\r\n";
    s.write_all(req.as_bytes())
        .unwrap_or_else(|e| panic!("{e}"));
    let mut out = String::new();
    let _ = s.read_to_string(&mut out);
    out.lines().next().unwrap_or_default().to_string()
}

type Socket = tungstenite::WebSocket<TcpStream>;

fn websocket(c: &Cockpit, origin: &str, token: &str) -> Result<Socket, String> {
    let stream = TcpStream::connect(&c.host).map_err(|e| e.to_string())?;
    handshake(c, origin, token, stream)
}

/// [`websocket`] with a small receive buffer: a page that does not read
/// fills it, and the cockpit's own queue, within a second or two.
fn small_websocket(c: &Cockpit, origin: &str, token: &str) -> Result<Socket, String> {
    let addr: std::net::SocketAddr = c.host.parse().map_err(|e| format!("{e}"))?;
    let s = socket2::Socket::new(socket2::Domain::IPV4, socket2::Type::STREAM, None)
        .map_err(|e| e.to_string())?;
    s.set_recv_buffer_size(4096).map_err(|e| e.to_string())?;
    s.connect(&addr.into()).map_err(|e| e.to_string())?;
    handshake(c, origin, token, s.into())
}

fn handshake(c: &Cockpit, origin: &str, token: &str, stream: TcpStream) -> Result<Socket, String> {
    let req = tungstenite::http::Request::builder()
        .uri(format!("ws://{}/ws?token={token}", c.host))
        .header("Host", &c.host)
        .header("Origin", origin)
        .header("Connection", "Upgrade")
        .header("Upgrade", "websocket")
        .header("Sec-WebSocket-Version", "13")
        .header(
            "Sec-WebSocket-Key",
            tungstenite::handshake::client::generate_key(),
        )
        .body(())
        .map_err(|e| e.to_string())?;
    tungstenite::client(req, stream)
        .map(|(ws, _)| ws)
        .map_err(|e| e.to_string())
}

/// The next message of `kind` within 5 s.
fn next(ws: &mut Socket, kind: &str) -> serde_json::Value {
    let end = Instant::now() + Duration::from_secs(5);
    while Instant::now() < end {
        if let Ok(tungstenite::Message::Text(t)) = ws.read() {
            let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap_or_default();
            if v["type"] == kind {
                return v;
            }
        }
    }
    panic!("no {kind} message within 5 s")
}

fn command(ws: &mut Socket, cmd: serde_json::Value) -> serde_json::Value {
    ws.send(tungstenite::Message::text(cmd.to_string()))
        .unwrap_or_else(|e| panic!("{e}"));
    next(ws, "result")
}

#[test]
fn the_cockpit_lets_in_only_its_operator_and_drives_the_robot() {
    let seen = Arc::new(Seen::default());
    let c = cockpit(&robot(seen.clone()));
    assert!(
        c.url.starts_with("http://127.0.0.1:") && c.token.len() == 32,
        "{}",
        c.url
    );
    let page = format!("/?token={}", c.token);
    // The page, with the token and this server's name.
    assert_eq!(get(&c.host, &page, &[("Host", &c.host)]), "HTTP/1.1 200 OK");
    // Refused: no token, a wrong one, another name (DNS rebinding).
    for (target, host) in [
        ("/", c.host.as_str()),
        ("/?token=00000000000000000000000000000000", c.host.as_str()),
        (page.as_str(), "evil.example:8080"),
    ] {
        assert_eq!(
            get(&c.host, target, &[("Host", host)]),
            "HTTP/1.1 403 Forbidden",
            "{target} {host}"
        );
    }
    // Two `Host` headers (the second someone else's), and a websocket
    // handshake without its key: malformed, refused before anything else.
    assert_eq!(
        get(
            &c.host,
            &page,
            &[("Host", &c.host), ("Host", "evil.example:8080")]
        ),
        "HTTP/1.1 400 Bad Request"
    );
    let ws_target = format!("/ws?token={}", c.token);
    let own_origin = format!("http://{}", c.host);
    assert_eq!(
        get(
            &c.host,
            &ws_target,
            &[
                ("Host", &c.host),
                ("Origin", &own_origin),
                ("Upgrade", "websocket"),
                ("Connection", "Upgrade"),
                ("Sec-WebSocket-Version", "13"),
            ]
        ),
        "HTTP/1.1 400 Bad Request"
    );
    // A cross-origin websocket (another page in the same browser, with the
    // token even), and one without the token: refused, and none of their
    // commands reaches the robot.
    let own = format!("http://{}", c.host);
    for (origin, token) in [
        ("http://evil.example", c.token.as_str()),
        (own.as_str(), "nope"),
    ] {
        let e = websocket(&c, origin, token).err();
        assert!(
            e.as_deref().is_some_and(|e| e.contains("403")),
            "{origin}: {e:?}"
        );
    }
    assert_eq!(seen.arms.load(Ordering::Relaxed), 0);

    let mut ws = websocket(&c, &own, &c.token).unwrap_or_else(|e| panic!("{e}"));
    let _ = ws
        .get_mut()
        .set_read_timeout(Some(Duration::from_millis(100)));
    let table = next(&mut ws, "params");
    assert_eq!(table["rows"][0]["name"], "target_apex_m");
    assert_eq!(table["rows"][0]["value"], "0.1");
    // Values move between two reads.
    let last_height = |v: &serde_json::Value| {
        v["records"]
            .as_array()
            .and_then(|r| r.last())
            .and_then(|r| r[1].as_f64())
            .unwrap_or(f64::NAN)
    };
    let a = last_height(&next(&mut ws, "telemetry"));
    std::thread::sleep(Duration::from_millis(200));
    let b = last_height(&next(&mut ws, "telemetry"));
    assert!(a.is_finite() && b.is_finite() && a != b, "{a} {b}");
    // Arm, then the state says armed.
    let r = command(&mut ws, serde_json::json!({ "cmd": "arm" }));
    assert_eq!(
        (r["ok"].as_bool(), r["text"].as_str()),
        (Some(true), Some("armed"))
    );
    assert_eq!(seen.arms.load(Ordering::Relaxed), 1);
    let mut state = next(&mut ws, "state");
    while state["armed"] != true {
        state = next(&mut ws, "state");
    }
    assert_eq!(state["arm"], "armed");
    // An out-of-range set: refused with the reason and the old value.
    let r = command(
        &mut ws,
        serde_json::json!({ "cmd": "set", "name": "target_apex_m", "value": "2.0" }),
    );
    assert_eq!(r["ok"], false);
    let text = r["text"].as_str().unwrap_or_default();
    assert!(
        text.contains("refused: out-of-range") && text.contains("unchanged"),
        "{text}"
    );
    // Disarm.
    let r = command(&mut ws, serde_json::json!({ "cmd": "disarm" }));
    assert_eq!(r["text"], "disarmed");
    assert_eq!(seen.disarms.load(Ordering::Relaxed), 1);
    while state["armed"] != false {
        state = next(&mut ws, "state");
    }
    assert_eq!(state["arm"], "disarmed (boot)");
}

/// For the README's screenshot: arms the robot behind the cockpit at
/// `HOPPER_COCKPIT_URL` and keeps the page's link for 20 s (run by hand:
/// `cargo test -p hopper-link --test ui -- --ignored`).
#[test]
#[ignore = "drives a cockpit started by hand"]
fn arm_a_running_cockpit() {
    let Ok(url) = std::env::var("HOPPER_COCKPIT_URL") else {
        return;
    };
    let host = url
        .trim_start_matches("http://")
        .split('/')
        .next()
        .unwrap_or_default();
    let token = url.split("token=").nth(1).unwrap_or_default();
    let c = Cockpit {
        child: Command::new("true")
            .spawn()
            .unwrap_or_else(|e| panic!("{e}")),
        _stdout: BufReader::new(
            Command::new("true")
                .stdout(Stdio::piped())
                .spawn()
                .ok()
                .and_then(|mut c| c.stdout.take())
                .unwrap_or_else(|| panic!("no pipe")),
        ),
        url: url.clone(),
        host: host.to_string(),
        token: token.to_string(),
    };
    let mut ws = websocket(&c, &format!("http://{host}"), token).unwrap_or_else(|e| panic!("{e}"));
    let _ = ws
        .get_mut()
        .set_read_timeout(Some(Duration::from_millis(100)));
    println!("{}", command(&mut ws, serde_json::json!({ "cmd": "arm" })));
    let end = Instant::now() + Duration::from_secs(20);
    while Instant::now() < end {
        let _ = ws.read();
    }
}

/// One call of the Chrome DevTools protocol on the page's debugger socket.
fn cdp(
    ws: &mut tungstenite::WebSocket<TcpStream>,
    id: u64,
    method: &str,
    params: serde_json::Value,
) -> serde_json::Value {
    ws.send(tungstenite::Message::text(
        serde_json::json!({ "id": id, "method": method, "params": params }).to_string(),
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    loop {
        if let Ok(tungstenite::Message::Text(t)) = ws.read() {
            let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap_or_default();
            if v["id"] == id {
                return v;
            }
        }
    }
}

/// For the README's screenshot: the page open in a browser with
/// `--remote-debugging-port` (its debugger socket in
/// `HOPPER_CDP_WS`), captured as base64 PNG into `HOPPER_SHOT` (run by
/// hand with `--ignored`).
#[test]
#[ignore = "needs a browser started by hand"]
fn screenshot_of_a_running_page() {
    let (Ok(ws_url), Ok(out)) = (std::env::var("HOPPER_CDP_WS"), std::env::var("HOPPER_SHOT"))
    else {
        return;
    };
    let addr = ws_url
        .trim_start_matches("ws://")
        .split('/')
        .next()
        .unwrap_or_default()
        .to_string();
    let stream = TcpStream::connect(&addr).unwrap_or_else(|e| panic!("{e}"));
    let (mut ws, _) =
        tungstenite::client(ws_url.as_str(), stream).unwrap_or_else(|e| panic!("{e}"));
    let state = cdp(
        &mut ws,
        1,
        "Runtime.evaluate",
        serde_json::json!({ "expression": "document.getElementById('armstate').textContent" }),
    );
    println!("{state}");
    let shot = cdp(
        &mut ws,
        2,
        "Page.captureScreenshot",
        serde_json::json!({ "format": "png" }),
    );
    std::fs::write(out, shot["result"]["data"].as_str().unwrap_or_default())
        .unwrap_or_else(|e| panic!("{e}"));
}

/// The cockpit process's thread count (Linux).
fn threads(pid: u32) -> u32 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("Threads:")?.trim().parse().ok())
        })
        .unwrap_or(0)
}

#[test]
fn held_trickled_and_unread_connections_are_bounded() {
    let seen = Arc::new(Seen::default());
    let c = cockpit(&robot(seen.clone()));
    let own = format!("http://{}", c.host);
    let page = format!("/?token={}", c.token);
    // A page that never reads.
    let mut lazy = small_websocket(&c, &own, &c.token).unwrap_or_else(|e| panic!("{e}"));
    // 200 connections held open, saying nothing: no thread each, and the
    // operator's page still loads.
    let held: Vec<TcpStream> = (0..200)
        .filter_map(|_| TcpStream::connect(&c.host).ok())
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let n = threads(c.child.id());
    eprintln!("{n} threads with {} connections held", held.len());
    assert!(n <= 32, "{n} threads with {} connections held", held.len());
    assert_eq!(get(&c.host, &page, &[("Host", &c.host)]), "HTTP/1.1 200 OK");
    // A head trickled a byte every 0.5 s is cut off within its time.
    let mut slow = TcpStream::connect(&c.host).unwrap_or_else(|e| panic!("{e}"));
    let _ = slow.set_read_timeout(Some(Duration::from_millis(500)));
    let start = Instant::now();
    let mut byte = [0u8; 1];
    let cut = loop {
        if slow.write_all(b"G").is_err() {
            break start.elapsed();
        }
        match slow.read(&mut byte) {
            Ok(_) => break start.elapsed(),
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionReset => break start.elapsed(),
            Err(_) if start.elapsed() > Duration::from_secs(12) => break start.elapsed(),
            Err(_) => {}
        }
    };
    eprintln!("a trickled head cut after {cut:?}");
    assert!(
        cut < Duration::from_secs(8),
        "a trickled head held for {cut:?}"
    );
    drop(held);
    // The page that did not read: told how much telemetry it skipped, and
    // still connected (its state kept as the newest, not queued).
    let _ = lazy
        .get_mut()
        .set_read_timeout(Some(Duration::from_millis(100)));
    let told = next(&mut lazy, "page");
    assert!(told["dropped"].as_u64().is_some_and(|n| n > 0), "{told}");
    // A set sent as a JSON number is taken as that number.
    let r = command(
        &mut lazy,
        serde_json::json!({ "cmd": "set", "name": "target_apex_m", "value": 0.12 }),
    );
    assert_eq!(r["ok"], true, "{r}");
    assert_eq!(seen.sets.load(Ordering::Relaxed), 1);
}
