//! `ui`: the operator's cockpit, a web page served by this client (assets
//! in the binary, no internet needed): live plots, the state with an
//! always-visible Disarm, Arm with its refusal, the parameter table
//! edited in place, the hop ledger, Record and Stop (telemetry, hops and
//! faults to CSV and MCAP as they arrive, in a new numbered folder), the
//! fault capture plotted on demand (and saved), and the bring-up routines
//! as a guided sequence, each step's result shown.
//!
//! The page can drive a real motor, so it lets in only its operator: it
//! listens on loopback unless `--allow-remote` says otherwise; every
//! request and the websocket need the random token printed in the URL at
//! start; the HTTP server checks `Host` (a DNS-rebinding site names its
//! own) and the websocket checks `Origin` (another page open in the same
//! browser is not this one). Nothing of a refused request reaches the
//! robot. The robot still disarms by its link timeout when this client
//! goes away, and by the operator deadman below when its pages do.
//!
//! One thread owns the link (the [`Client`]): it streams telemetry, polls
//! the state, and runs the commands the pages send, one at a time; each
//! connection has a thread of its own. A Disarm does not wait in that
//! line: the page's thread sends it at once ([`Urgent`]), whatever the
//! link's thread has in flight. An operator deadman disarms the robot
//! when no page has been connected for [`OPERATOR_DEADMAN`]; pages
//! reconnect by themselves. Losing the robot is an event, not an exit:
//! a recording in progress is finished (every file, its plot), the pages
//! say so, and the cockpit connects again when the robot comes back.

use super::common::wire_name;
use anyhow::{bail, Context, Result};
use hopper_link::record::{Recording, Streamed};
use hopper_link::{names, Client, Urgent};
use hopper_protocol::{ArmState, DumpInfo, Request, Response, RobotMsg};
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tungstenite::protocol::Role;
use tungstenite::{Message, WebSocket};

/// The page (HTML, CSS and script in one file).
const PAGE: &str = include_str!("ui.html");

/// Telemetry records a second the page is sent (the robot streams at this
/// rate; the page draws at its frame rate).
const TELEMETRY_HZ: f64 = 200.0;

/// A command from a page, with where its answer goes.
struct Command {
    /// The page's JSON command.
    json: serde_json::Value,
    /// The answer's way back to that page.
    reply: Sender<String>,
}

/// The pages connected: each one's queue of messages.
type Pages = Arc<Mutex<Vec<Sender<String>>>>;

/// With no page connected for this long, the robot is disarmed: a closed
/// page (or a browser that died) leaves no one to press Disarm.
pub(crate) const OPERATOR_DEADMAN: Duration = Duration::from_millis(500);

/// How long a page's Disarm waits for the robot's answer.
const DISARM_TIMEOUT: Duration = Duration::from_secs(1);

/// What the link's thread, the pages' threads and the deadman share.
#[derive(Clone, Default)]
struct Shared {
    /// Each page's queue.
    pages: Pages,
    /// Pages with a live websocket.
    live: Arc<AtomicUsize>,
    /// The robot armed, as last seen (its state, or an arm just granted).
    armed: Arc<AtomicBool>,
    /// What the cockpit did on its own (the deadman's disarm, the robot's
    /// loss), for every page's header until the next arm.
    note: Arc<Mutex<Option<String>>>,
    /// The link's urgent requests (replaced when the robot reconnects).
    urgent: Arc<Mutex<Option<Urgent>>>,
}

impl Shared {
    fn set_note(&self, text: Option<String>) {
        if let Ok(mut n) = self.note.lock() {
            *n = text;
        }
    }

    fn note(&self) -> Option<String> {
        self.note.lock().ok().and_then(|n| n.clone())
    }

    /// Disarms the robot now, past every queue.
    fn disarm(&self) -> Result<()> {
        let urgent = self
            .urgent
            .lock()
            .ok()
            .and_then(|u| u.clone())
            .ok_or_else(|| anyhow::anyhow!("no robot connected"))?;
        match urgent.request(Request::Disarm, DISARM_TIMEOUT)? {
            Response::Ok => {
                self.armed.store(false, Ordering::Relaxed);
                Ok(())
            }
            r => bail!("disarm: unexpected answer {r:?}"),
        }
    }
}

/// Counts a page's websocket as live while it exists.
struct Live(Arc<AtomicUsize>);

impl Live {
    fn new(n: &Arc<AtomicUsize>) -> Self {
        n.fetch_add(1, Ordering::Relaxed);
        Live(n.clone())
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

/// The operator deadman: with no live page for [`OPERATOR_DEADMAN`], a
/// Disarm, once per such gap (and the note, when the robot was armed).
fn deadman(shared: &Shared) {
    let mut gap: Option<Instant> = None;
    let mut done = false;
    loop {
        std::thread::sleep(Duration::from_millis(20));
        if shared.live.load(Ordering::Relaxed) > 0 {
            (gap, done) = (None, false);
            continue;
        }
        let since = *gap.get_or_insert_with(Instant::now);
        if done || since.elapsed() < OPERATOR_DEADMAN {
            continue;
        }
        let was_armed = shared.armed.load(Ordering::Relaxed);
        if shared.disarm().is_ok() {
            done = true;
            if was_armed {
                shared.set_note(Some(format!(
                    "disarmed by the cockpit: operator page closed (no page for {:.1} s)",
                    OPERATOR_DEADMAN.as_secs_f64()
                )));
            }
        }
    }
}

/// `hopper-link ui --http ADDR [--allow-remote]`: serves the cockpit until
/// the link closes or the process is stopped.
pub(crate) fn ui(
    c: &mut Client,
    http: &str,
    allow_remote: bool,
    record_dir: &std::path::Path,
) -> Result<()> {
    let addr: SocketAddr = http.parse().with_context(|| {
        format!("--http {http}: not an address HOST:PORT (e.g. 127.0.0.1:8080)")
    })?;
    if !addr.ip().is_loopback() {
        if !allow_remote {
            bail!("--http {addr} is not a loopback address: anyone who can reach it could arm the robot; add --allow-remote to serve it anyway");
        }
        eprintln!("hopper-link: warning: serving the cockpit on {addr}, beyond this machine: anyone on that network who has the token can drive the motor");
    }
    let listener = TcpListener::bind(addr).with_context(|| format!("cannot listen on {addr}"))?;
    let bound = listener.local_addr()?;
    let token = token()?;
    let hosts = hosts_for(bound);
    println!("cockpit: http://{bound}/?token={token}");
    println!("(open it in a browser; the robot is disarmed when no page is open for 0.5 s; Ctrl-C stops, and the robot disarms by its link timeout then)");
    std::io::stdout().flush()?;
    let shared = Shared::default();
    if let Ok(mut u) = shared.urgent.lock() {
        *u = Some(c.urgent());
    }
    let (commands, inbox) = channel::<Command>();
    {
        let shared = shared.clone();
        let token = token.clone();
        std::thread::spawn(move || {
            for stream in listener.incoming().flatten() {
                let (shared, commands, token, hosts) = (
                    shared.clone(),
                    commands.clone(),
                    token.clone(),
                    hosts.clone(),
                );
                std::thread::spawn(move || {
                    let _ = connection(stream, &token, &hosts, &shared, &commands);
                });
            }
        });
    }
    {
        let shared = shared.clone();
        std::thread::spawn(move || deadman(&shared));
    }
    let mut session = Session {
        period_s: 0.0,
        record_dir: record_dir.to_path_buf(),
        recording: None,
        batch: Vec::new(),
        calibrating: None,
        capturing: None,
        target_apex_m: None,
    };
    loop {
        let Err(e) = robot(c, &shared, &inbox, &mut session) else {
            return Ok(());
        };
        lost(c, &shared, &inbox, &mut session, &e);
    }
}

/// The robot is gone (`e`): the pages told, a recording in progress
/// finished with what it has (every file and its plot), the pages'
/// commands answered with the loss until the robot answers again.
fn lost(
    c: &mut Client,
    shared: &Shared,
    inbox: &Receiver<Command>,
    session: &mut Session,
    e: &anyhow::Error,
) {
    let pages = &shared.pages;
    let text = format!("robot lost: {e:#}; connecting again to {}", c.target());
    shared.armed.store(false, Ordering::Relaxed);
    shared.set_note(Some(text.clone()));
    if let Ok(mut u) = shared.urgent.lock() {
        *u = None;
    }
    broadcast(pages, &serde_json::json!({ "type": "lost", "text": text }));
    // (The routine and the capture in progress end with the link.)
    if let Some((_, cmd)) = session.calibrating.take() {
        let _ = cmd
            .reply
            .send(answer(&cmd.json, Err(anyhow::anyhow!("{text}"))).to_string());
    }
    if let Some(cap) = session.capturing.take() {
        let _ = cap
            .cmd
            .reply
            .send(answer(&cap.cmd.json, Err(anyhow::anyhow!("{text}"))).to_string());
    }
    if let Some((rec, dir)) = session.recording.take() {
        let pages = pages.clone();
        finish_recording(
            rec,
            dir,
            session.period_s,
            session.target_apex_m,
            c.target().to_string(),
            move |r| {
                let (ok, text) = match r {
                    Ok(t) => (true, format!("the robot was lost; {t}")),
                    Err(e) => (false, format!("the robot was lost; the recording: {e:#}")),
                };
                broadcast(
                    &pages,
                    &serde_json::json!({ "type": "notice", "ok": ok, "text": text, "recording_finished": true }),
                );
            },
        );
    }
    let target = c.target().clone();
    loop {
        while let Ok(cmd) = inbox.try_recv() {
            let _ = cmd
                .reply
                .send(answer(&cmd.json, Err(anyhow::anyhow!("{text}"))).to_string());
        }
        match Client::connect(&target) {
            Ok(n) => {
                *c = n;
                if let Ok(mut u) = shared.urgent.lock() {
                    *u = Some(c.urgent());
                }
                shared.set_note(Some(format!(
                    "the robot answered again at {target} after it was lost"
                )));
                broadcast(
                    pages,
                    &serde_json::json!({ "type": "notice", "ok": true, "text": format!("connected to the robot again ({target})") }),
                );
                return;
            }
            Err(_) => std::thread::sleep(Duration::from_millis(500)),
        }
    }
}

/// The names a browser may use for this server (its `Host`): its
/// address, `localhost` on loopback, each without the port too when the
/// port is HTTP's default 80 (browsers leave `:80` out).
pub(crate) fn hosts_for(bound: SocketAddr) -> Vec<String> {
    let mut names = vec![bound.ip().to_string()];
    if bound.ip().is_loopback() {
        names.push("localhost".into());
    }
    let mut hosts: Vec<String> = names
        .iter()
        .map(|n| match bound {
            SocketAddr::V6(_) if n != "localhost" => format!("[{n}]:{}", bound.port()),
            _ => format!("{n}:{}", bound.port()),
        })
        .collect();
    if bound.port() == 80 {
        hosts.extend(names.iter().map(|n| match bound {
            SocketAddr::V6(_) if n != "localhost" => format!("[{n}]"),
            _ => n.clone(),
        }));
    }
    hosts
}

/// A random token: 128 bits as hex.
fn token() -> Result<String> {
    let mut b = [0u8; 16];
    getrandom::fill(&mut b).map_err(|e| anyhow::anyhow!("no random token: {e}"))?;
    Ok(b.iter().map(|x| format!("{x:02x}")).collect())
}

/// Sends `msg` to every page (dropping those gone).
fn broadcast(pages: &Pages, msg: &serde_json::Value) {
    let text = msg.to_string();
    if let Ok(mut p) = pages.lock() {
        p.retain(|tx| tx.send(text.clone()).is_ok());
    }
}

/// What the link's thread keeps between commands: the recording in
/// progress and where recordings and captures go.
struct Session {
    /// The control period, s.
    period_s: f64,
    /// Recordings and captures go in numbered folders here.
    record_dir: PathBuf,
    /// The recording in progress and its folder.
    recording: Option<(Streamed, PathBuf)>,
    /// Telemetry for the pages, sent about 30 times a second.
    batch: Vec<serde_json::Value>,
    /// The bring-up routine running, polled while the pages' other
    /// commands (Disarm above all, which aborts a driving routine) still
    /// run, and whom to answer when it ends.
    calibrating: Option<(super::calibrate::Started, Command)>,
    /// The fault capture being read, record by record, while the link's
    /// thread goes on (Disarm above all).
    capturing: Option<Capturing>,
    /// The target apex as last read or set, for a recording's plot when
    /// the robot is gone.
    target_apex_m: Option<f64>,
}

/// A fault capture on its way from the robot.
struct Capturing {
    /// Whom to answer.
    cmd: Command,
    /// The faults latched when it was asked for.
    latched: u16,
    /// When it was first asked for.
    asked: Instant,
    /// When to ask again (the capture still filling after a fault: a
    /// fresh dump restarts), `None` once the robot answered for good.
    retry_at: Option<Instant>,
    /// What the robot said it will send.
    info: Option<DumpInfo>,
    /// The records so far.
    rec: Recording,
    /// When the last record came.
    quiet: Instant,
}

impl Session {
    /// One message from the robot: to the recording, if one runs, and to
    /// the pages.
    fn on(&mut self, pages: &Pages, msg: RobotMsg) {
        let written = match msg {
            RobotMsg::Telemetry(r) => {
                self.batch.push(serde_json::json!([
                    f64::from(r.step) * self.period_s,
                    r.body_height_m,
                    f64::from(r.body_height_m) - hopper_model::design::LEG_LENGTH_M,
                    r.nut_position_m,
                    r.spring_force_n,
                    r.command_a,
                    r.energy_j,
                ]));
                self.recording.as_mut().map(|(rec, _)| rec.record(r))
            }
            RobotMsg::Hop(h) => {
                broadcast(pages, &serde_json::json!({ "type": "hop", "hop": h }));
                self.recording.as_mut().map(|(rec, _)| rec.hop(h))
            }
            RobotMsg::Faults { step, bits } => {
                broadcast(
                    pages,
                    &serde_json::json!({ "type": "fault", "step": step, "faults": names::faults(bits) }),
                );
                self.recording
                    .as_mut()
                    .map(|(rec, _)| rec.fault(step, bits))
            }
            RobotMsg::Captured(r) => {
                if let Some(cap) = &mut self.capturing {
                    // In order, or from an earlier dump: skip those.
                    if cap.info.is_some() && r.seq as usize == cap.rec.records.len() {
                        cap.rec.records.push(r);
                        cap.quiet = Instant::now();
                    }
                }
                None
            }
            _ => None,
        };
        self.check(pages, written);
    }

    /// A recording that cannot be written (a full disk) stops, and the
    /// pages say so; the cockpit, its Disarm first, goes on.
    fn check(&mut self, pages: &Pages, written: Option<Result<()>>) {
        if let Some(Err(e)) = written {
            let dir = self
                .recording
                .take()
                .map_or_else(String::new, |(_, d)| d.display().to_string());
            broadcast(
                pages,
                &serde_json::json!({ "type": "notice", "ok": false, "text": format!("recording into {dir} stopped: {e:#}") }),
            );
        }
    }

    /// The first free `NAME-N` folder under the record directory.
    fn folder(&self, name: &str) -> PathBuf {
        (1..)
            .map(|n| self.record_dir.join(format!("{name}-{n}")))
            .find(|p| !p.exists())
            .unwrap_or_else(|| self.record_dir.join(name))
    }
}

/// The link's thread: telemetry, the state, and the pages' commands.
fn robot(
    c: &mut Client,
    shared: &Shared,
    inbox: &Receiver<Command>,
    session: &mut Session,
) -> Result<()> {
    let pages = &shared.pages;
    let t = match c.request(Request::Timing)? {
        Response::Timing(t) => t,
        r => bail!("unexpected answer {r:?}"),
    };
    let period = f64::from(t.period_s);
    let every = (1.0 / (TELEMETRY_HZ * period)).round().clamp(1.0, 65535.0) as u16;
    c.expect_ok(Request::Telemetry { every })?;
    session.period_s = period;
    session.target_apex_m = super::common::get(c, "target_apex_m").ok().map(f64::from);
    let session = &mut *session;
    let mut last_poll = Instant::now();
    let mut last_send = Instant::now();
    let mut last_state = Instant::now() - Duration::from_secs(1);
    let mut last_thermal = last_state;
    loop {
        while let Ok(cmd) = inbox.try_recv() {
            if cmd.json["cmd"] == "capture" {
                start_capture(c, pages, cmd, session);
                continue;
            }
            if cmd.json["cmd"] == "record-stop" {
                stop_recording(c, cmd, session);
                continue;
            }
            if cmd.json["cmd"] == "calibrate" {
                match start_routine(c, &cmd.json, session) {
                    Ok(started) => session.calibrating = Some((started, cmd)),
                    Err(e) => {
                        let _ = cmd.reply.send(answer(&cmd.json, Err(e)).to_string());
                    }
                }
                continue;
            }
            let answer = run(c, &cmd.json, shared, session);
            let _ = cmd.reply.send(answer.to_string());
        }
        progress_capture(c, pages, session);
        if session.calibrating.is_some() && last_poll.elapsed() >= Duration::from_millis(100) {
            last_poll = Instant::now();
            let mut out = String::new();
            let ended = match &session.calibrating {
                Some((started, _)) => super::calibrate::poll(c, started, &mut out).transpose(),
                None => None,
            };
            // (Taken only once it ended: until then it is polled again.)
            if let Some((result, Some((_, cmd)))) = ended.map(|r| (r, session.calibrating.take())) {
                let found = out.trim_end().to_string();
                let result = match result {
                    Ok(()) => Ok(found),
                    Err(e) if found.is_empty() => Err(e),
                    Err(e) => Err(anyhow::anyhow!("{e:#}\n{found}")),
                };
                let _ = cmd.reply.send(answer(&cmd.json, result).to_string());
            }
        }
        if last_state.elapsed() >= Duration::from_millis(100) {
            last_state = Instant::now();
            let recording = session.recording.as_ref().map(|(_, d)| d.as_path());
            broadcast(pages, &state(c, recording, shared)?);
        }
        if last_thermal.elapsed() >= Duration::from_millis(500) {
            last_thermal = Instant::now();
            if let Response::Thermal(th) = c.request(Request::Thermal)? {
                broadcast(
                    pages,
                    &serde_json::json!({
                        "type": "thermal",
                        "winding_c": th.winding_c,
                        "housing_c": th.housing_c,
                        "limit_scale": th.limit_scale,
                        "derate_c": th.derate_c,
                        "trip_c": th.trip_c,
                    }),
                );
            }
        }
        // What came while the requests above waited, then what comes now.
        for m in c.take_queued() {
            session.on(pages, m);
        }
        match c.next_event(Duration::from_millis(10))? {
            Some(m) => session.on(pages, m),
            // Idle: what is recorded so far is on disk.
            None => {
                let flushed = session.recording.as_mut().map(|(rec, _)| rec.flush());
                session.check(pages, flushed);
            }
        }
        // About 30 frames a second to the pages.
        if last_send.elapsed() >= Duration::from_millis(33) && !session.batch.is_empty() {
            last_send = Instant::now();
            broadcast(
                pages,
                &serde_json::json!({ "type": "telemetry", "records": std::mem::take(&mut session.batch) }),
            );
        }
    }
}

/// The robot's state for the page.
fn state(
    c: &mut Client,
    recording: Option<&std::path::Path>,
    shared: &Shared,
) -> Result<serde_json::Value> {
    let s = match c.request(Request::Status)? {
        Response::Status(s) => s,
        r => bail!("unexpected answer {r:?}"),
    };
    shared
        .armed
        .store(s.arm == ArmState::Armed, Ordering::Relaxed);
    let cost = match c.request(Request::Cost)? {
        Response::Cost(x) => Some(x),
        _ => None,
    };
    let host = c.stats();
    Ok(serde_json::json!({
        "type": "state",
        "armed": s.arm == ArmState::Armed,
        "arm": names::arm_state(s.arm),
        "advice": names::advice(s.arm),
        "faults": names::faults(s.faults),
        "periods": s.periods,
        "frames_ok": s.frames_ok,
        "frames_bad": s.frames_bad,
        "host_frames_ok": host.ok,
        "host_frames_bad": host.too_long + host.bad_cobs + host.bad_crc + host.bad_message,
        "telemetry_dropped": s.telemetry_dropped,
        "last_apex_m": s.last_apex_m,
        "isr_mean": cost.map(|x| x.isr_mean),
        "isr_max": cost.map(|x| x.isr_max),
        "counter_hz": cost.map(|x| x.counter_hz),
        "recording": recording.map(|d| d.display().to_string()),
        "note": shared.note(),
    }))
}

/// Every parameter, for the page's table.
fn parameters(c: &mut Client) -> Result<serde_json::Value> {
    let controllers = names::controller_names(c)?;
    let selected = super::common::get(c, names::CONTROLLER)
        .ok()
        .and_then(|v| controllers.get(v as usize).cloned());
    let rows: Vec<serde_json::Value> = names::table(c)?
        .iter()
        .map(|d| {
            let p = &d.info;
            let active = !p.value.is_nan();
            serde_json::json!({
                "name": p.name.as_str(),
                "value": if active { d.value(p.value) } else { d.value(p.default) },
                "unit": p.unit.as_str(),
                "min": p.min,
                "max": p.max,
                "default": d.value(p.default),
                "live": p.live,
                "choices": d.choices,
                "inactive": (!active).then(|| d.inactive_reason(selected.as_deref())),
            })
        })
        .collect();
    Ok(serde_json::json!({ "type": "params", "rows": rows }))
}

/// Runs one of the page's commands on the robot; the answer for the page.
fn run(
    c: &mut Client,
    cmd: &serde_json::Value,
    shared: &Shared,
    session: &mut Session,
) -> serde_json::Value {
    let pages = &shared.pages;
    let what = cmd["cmd"].as_str().unwrap_or("");
    let result: Result<String> = (|| match what {
        // An arm asked for by a page that has gone since (its command
        // waited in line) arms a robot no one watches: refused.
        "arm" if shared.live.load(Ordering::Relaxed) == 0 => {
            bail!("arm refused: no operator page is connected to the cockpit")
        }
        "arm" => match c.request(Request::Arm)? {
            Response::Ok => {
                shared.armed.store(true, Ordering::Relaxed);
                shared.set_note(None);
                Ok("armed".into())
            }
            Response::Refused(why) => {
                bail!("arm refused: {why}{}", super::arm::next_step(why.refusal()))
            }
            r => bail!("unexpected answer {r:?}"),
        },
        "disarm" => {
            shared.disarm()?;
            Ok("disarmed".into())
        }
        "reset-faults" => match c.request(Request::ResetFaults)? {
            Response::Ok => Ok("faults reset".into()),
            Response::Refused(why) => bail!("reset-faults refused: {why}"),
            r => bail!("unexpected answer {r:?}"),
        },
        "params" => {
            let p = parameters(c)?;
            broadcast(pages, &p);
            Ok(String::new())
        }
        "set" => {
            let name = cmd["name"].as_str().unwrap_or("");
            let text = cmd["value"].as_str().unwrap_or("");
            let d =
                names::describe(c, name)?.ok_or_else(|| anyhow::anyhow!("no parameter {name}"))?;
            let value = d.parse(text)?;
            match c.request(Request::ParamSet {
                name: wire_name(name)?,
                value,
            })? {
                Response::Ok => {
                    if name == "target_apex_m" {
                        session.target_apex_m = Some(f64::from(value));
                    }
                    let p = parameters(c)?;
                    broadcast(pages, &p);
                    Ok(format!("{name} = {text}"))
                }
                Response::Refused(why) => {
                    let old = super::common::read_param(c, name)?
                        .map_or_else(|_| "inactive".to_string(), |v| d.shown(v));
                    bail!("set {name} = {text} refused: {why} (unchanged: {old})")
                }
                r => bail!("unexpected answer {r:?}"),
            }
        }
        "record-start" => {
            if let Some((_, dir)) = &session.recording {
                bail!("already recording into {}", dir.display());
            }
            let dir = session.folder("recording");
            let parameters = super::record::all_parameters(c)?;
            let rec = Streamed::create(&dir, session.period_s, &parameters)?;
            let text = format!("recording into {}", dir.display());
            session.recording = Some((rec, dir));
            Ok(text)
        }
        "mount" => {
            let hoisted = cmd["how"] == "hoist";
            c.expect_ok(Request::SimulateMount {
                hoisted,
                lift_m: 0.05,
            })
            .context("mount: only a simulated robot has a hoist to drive")?;
            Ok(if hoisted {
                "mount: hoist (the toe 0.05 m above the ground)".into()
            } else {
                "mount: release".into()
            })
        }
        "save" => super::save::run(c),
        _ => bail!("unknown command `{what}`"),
    })();
    answer(cmd, result)
}

/// The page's answer to `cmd`.
fn answer(cmd: &serde_json::Value, result: Result<String>) -> serde_json::Value {
    let id = cmd["id"].clone();
    match result {
        Ok(text) => serde_json::json!({ "type": "result", "id": id, "ok": true, "text": text }),
        Err(e) => {
            serde_json::json!({ "type": "result", "id": id, "ok": false, "text": format!("{e:#}") })
        }
    }
}

/// Asks the robot for its capture (a page's Capture); the records then
/// come with the rest of the link's traffic.
fn start_capture(c: &mut Client, pages: &Pages, cmd: Command, session: &mut Session) {
    if session.capturing.is_some() {
        let _ = cmd
            .reply
            .send(answer(&cmd.json, Err(anyhow::anyhow!("a capture is still coming"))).to_string());
        return;
    }
    let latched = match super::common::status_of(c) {
        Ok(s) => s.faults,
        Err(e) => {
            let _ = cmd.reply.send(answer(&cmd.json, Err(e)).to_string());
            return;
        }
    };
    let now = Instant::now();
    session.capturing = Some(Capturing {
        cmd,
        latched,
        asked: now,
        retry_at: Some(now),
        info: None,
        rec: Recording {
            period_s: session.period_s,
            ..Recording::default()
        },
        quiet: now,
    });
    progress_capture(c, pages, session);
}

/// Moves the capture on: asks (again) when due, and once every record came
/// writes its files and plot on a thread of its own, which answers the
/// page and shows the plot.
fn progress_capture(c: &mut Client, pages: &Pages, session: &mut Session) {
    let Some(cap) = &session.capturing else {
        return;
    };
    if cap.retry_at.is_some_and(|t| Instant::now() >= t) {
        let asked = c.request(Request::Dump).and_then(|r| match r {
            Response::Dump(i) => Ok(i),
            r => bail!("unexpected answer {r:?}"),
        });
        // Records before the answer belong to an earlier dump: dropped.
        for m in c.take_queued() {
            if !matches!(m, RobotMsg::Captured(_)) {
                session.on(pages, m);
            }
        }
        let Some(cap) = &mut session.capturing else {
            return;
        };
        match asked {
            Ok(info)
                if info.frozen
                    || info.fault_step == 0
                    || cap.asked.elapsed() > Duration::from_secs(5) =>
            {
                cap.info = Some(info);
                cap.retry_at = None;
                cap.quiet = Instant::now();
            }
            Ok(_) => cap.retry_at = Some(Instant::now() + Duration::from_millis(100)),
            Err(e) => {
                if let Some(cap) = session.capturing.take() {
                    let _ = cap
                        .cmd
                        .reply
                        .send(answer(&cap.cmd.json, Err(e)).to_string());
                }
            }
        }
        return;
    }
    let Some(info) = cap.info else {
        return;
    };
    let complete = cap.rec.records.len() >= usize::from(info.records);
    if !complete && cap.quiet.elapsed() <= Duration::from_secs(5) {
        return;
    }
    let Some(mut cap) = session.capturing.take() else {
        return;
    };
    if !complete {
        let e = anyhow::anyhow!(
            "the capture stopped after {} of {} records",
            cap.rec.records.len(),
            info.records
        );
        let _ = cap
            .cmd
            .reply
            .send(answer(&cap.cmd.json, Err(e)).to_string());
        return;
    }
    if info.frozen {
        cap.rec.t0_step = Some(info.fault_step);
    }
    // The folder taken now, so that a second capture gets the next one.
    let dir = session.folder("capture");
    let _ = std::fs::create_dir_all(&dir);
    let pages = pages.clone();
    std::thread::spawn(move || {
        let result = (|| -> Result<String> {
            let rec = &cap.rec;
            let written = rec.write_capture(&dir, &super::dump::title(rec, &info))?;
            let png = written
                .iter()
                .find(|p| p.extension().is_some_and(|e| e == "png"))
                .map(std::fs::read)
                .transpose()?;
            broadcast(
                &pages,
                &serde_json::json!({
                    "type": "capture",
                    "png": png.map(|b| format!("data:image/png;base64,{}", data_encoding::BASE64.encode(&b))),
                }),
            );
            Ok(format!(
                "{}; wrote {}",
                super::dump::summary(rec, &info, cap.latched),
                dir.display()
            ))
        })();
        let _ = cap
            .cmd
            .reply
            .send(answer(&cap.cmd.json, result).to_string());
    });
}

/// Stops the recording: its files completed and its plot drawn on a
/// thread of their own (a long recording's plot takes a while, and the
/// link's thread must stay free for Disarm), which answers the page.
fn stop_recording(c: &mut Client, cmd: Command, session: &mut Session) {
    let Some((rec, dir)) = session.recording.take() else {
        let _ = cmd
            .reply
            .send(answer(&cmd.json, Err(anyhow::anyhow!("not recording"))).to_string());
        return;
    };
    let target = super::common::get(c, "target_apex_m")
        .ok()
        .map(f64::from)
        .or(session.target_apex_m);
    finish_recording(
        rec,
        dir,
        session.period_s,
        target,
        c.target().to_string(),
        move |result| {
            let _ = cmd.reply.send(answer(&cmd.json, result).to_string());
        },
    );
}

/// Completes a recording's files and draws its plot on a thread of its
/// own, then calls `done` with its summary.
fn finish_recording(
    rec: Streamed,
    dir: PathBuf,
    period_s: f64,
    target: Option<f64>,
    robot: String,
    done: impl FnOnce(Result<String>) + Send + 'static,
) {
    let title = format!("recorded from the cockpit ({robot})");
    std::thread::spawn(move || {
        let result = rec.finish("hop.png", &title, target).map(|(rec, written)| {
            let span_s = rec
                .records
                .first()
                .zip(rec.records.last())
                .map_or(0.0, |(a, b)| {
                    f64::from(b.step.wrapping_sub(a.step)) * period_s
                });
            format!(
                "recorded {span_s:.3} s: {} records, {} dropped, {} hops, into {}: {}",
                rec.records.len(),
                rec.dropped(),
                rec.hops.len(),
                dir.display(),
                written
                    .iter()
                    .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        });
        done(result);
    });
}

/// A bring-up routine the page asked for, started (one at a time).
fn start_routine(
    c: &mut Client,
    cmd: &serde_json::Value,
    session: &Session,
) -> Result<super::calibrate::Started> {
    let routine = cmd["routine"].as_str().unwrap_or("");
    if !hopper_protocol::vocab::Routine::ALL
        .iter()
        .any(|r| r.name() == routine)
    {
        bail!("no bring-up routine `{routine}`");
    }
    if session.calibrating.is_some() {
        bail!("calibrate {routine}: another routine is still running");
    }
    super::calibrate::start(c, routine, 0.5)
}

/// The value of query parameter `key` in `target` (`/ws?token=...`).
fn query<'a>(target: &'a str, key: &str) -> Option<&'a str> {
    target
        .split_once('?')?
        .1
        .split('&')
        .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
}

fn respond(s: &mut TcpStream, status: &str, kind: &str, body: &str) -> std::io::Result<()> {
    write!(
        s,
        "HTTP/1.1 {status}\r\nContent-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
}

/// Why a request is refused, if it is: the `Host` is not this server's,
/// the token is missing or wrong, or (a websocket) the `Origin` is not this
/// page's.
pub(crate) fn refusal(
    host: Option<&str>,
    origin: Option<&str>,
    target: &str,
    token: &str,
    hosts: &[String],
    websocket: bool,
) -> Option<&'static str> {
    let Some(host) = host.filter(|h| hosts.iter().any(|x| x == h)) else {
        return Some("wrong Host");
    };
    if query(target, "token") != Some(token) {
        return Some("no valid token");
    }
    if websocket && origin != Some(&format!("http://{host}")) {
        return Some("wrong Origin");
    }
    None
}

/// One connection: the page, or its websocket.
fn connection(
    mut s: TcpStream,
    token: &str,
    hosts: &[String],
    shared: &Shared,
    commands: &Sender<Command>,
) -> Result<()> {
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    // Small frames (a Disarm's answer) go out at once: with Nagle's
    // algorithm one waited for the browser's delayed acknowledgement,
    // about 40 ms, every few Disarms.
    s.set_nodelay(true)?;
    // The request's head (a browser's fits in 8 KiB).
    let mut buf = vec![0u8; 8192];
    let mut n = 0;
    let head_len = loop {
        let k = s.read(&mut buf[n..])?;
        if k == 0 {
            return Ok(());
        }
        n += k;
        let mut headers = [httparse::EMPTY_HEADER; 32];
        let mut req = httparse::Request::new(&mut headers);
        match req.parse(&buf[..n]) {
            Ok(httparse::Status::Complete(len)) => break len,
            Ok(httparse::Status::Partial) if n < buf.len() => continue,
            _ => {
                return respond(&mut s, "400 Bad Request", "text/plain", "bad request\n")
                    .map_err(Into::into)
            }
        }
    };
    let mut headers = [httparse::EMPTY_HEADER; 32];
    let mut req = httparse::Request::new(&mut headers);
    req.parse(&buf[..head_len])?;
    let header = |name: &str| {
        req.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .and_then(|h| std::str::from_utf8(h.value).ok())
    };
    let target = req.path.unwrap_or("/");
    let path = target.split('?').next().unwrap_or("/");
    let websocket = header("Upgrade").is_some_and(|u| u.eq_ignore_ascii_case("websocket"));
    // One `Host`, not a first one trusted and a second ignored; a
    // websocket's handshake with its key (16 bytes in base64).
    let hosts_given = req
        .headers
        .iter()
        .filter(|h| h.name.eq_ignore_ascii_case("Host"))
        .count();
    let key_ok = header("Sec-WebSocket-Key").is_some_and(|k| {
        data_encoding::BASE64
            .decode(k.trim().as_bytes())
            .is_ok_and(|b| b.len() == 16)
    });
    if hosts_given > 1 || (websocket && !key_ok) {
        return respond(&mut s, "400 Bad Request", "text/plain", "bad request\n")
            .map_err(Into::into);
    }
    if let Some(why) = refusal(
        header("Host"),
        header("Origin"),
        target,
        token,
        hosts,
        websocket,
    ) {
        return respond(
            &mut s,
            "403 Forbidden",
            "text/plain",
            &format!("refused: {why}\n"),
        )
        .map_err(Into::into);
    }
    match (req.method, path, websocket) {
        (Some("GET"), "/", false) => {
            respond(&mut s, "200 OK", "text/html; charset=utf-8", PAGE)?;
            Ok(())
        }
        (Some("GET"), "/ws", true) => {
            let key = header("Sec-WebSocket-Key").unwrap_or("").trim();
            write!(
                s,
                "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Accept: {}\r\n\r\n",
                tungstenite::handshake::derive_accept_key(key.as_bytes())
            )?;
            page(s, shared, commands)
        }
        _ => respond(&mut s, "404 Not Found", "text/plain", "not found\n").map_err(Into::into),
    }
}

/// A page's websocket: the broadcasts out, its commands in; a Disarm
/// sent to the robot from here, at once.
fn page(s: TcpStream, shared: &Shared, commands: &Sender<Command>) -> Result<()> {
    s.set_read_timeout(Some(Duration::from_millis(10)))?;
    let mut ws = WebSocket::from_raw_socket(s, Role::Server, None);
    let _live = Live::new(&shared.live);
    let (tx, rx) = channel::<String>();
    if let Ok(mut p) = shared.pages.lock() {
        p.push(tx.clone());
    }
    // The table first.
    let _ = commands.send(Command {
        json: serde_json::json!({ "cmd": "params" }),
        reply: tx.clone(),
    });
    loop {
        match ws.read() {
            Ok(Message::Text(t)) => {
                if let Ok(json) = serde_json::from_str::<serde_json::Value>(t.as_str()) {
                    if json["cmd"] == "disarm" {
                        let result = shared.disarm().map(|()| "disarmed".to_string());
                        ws.send(Message::text(answer(&json, result).to_string()))?;
                        continue;
                    }
                    let _ = commands.send(Command {
                        json,
                        reply: tx.clone(),
                    });
                }
            }
            Ok(Message::Close(_)) => return Ok(()),
            Ok(_) => {}
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return Ok(()),
        }
        while let Ok(text) = rx.try_recv() {
            ws.send(Message::text(text))?;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_host_may_leave_out_the_default_port() {
        let on = |a: &str| hosts_for(a.parse().unwrap_or_else(|e| panic!("{e}")));
        assert_eq!(on("127.0.0.1:8080"), ["127.0.0.1:8080", "localhost:8080"]);
        assert_eq!(
            on("127.0.0.1:80"),
            ["127.0.0.1:80", "localhost:80", "127.0.0.1", "localhost"]
        );
        assert_eq!(on("192.168.1.5:80"), ["192.168.1.5:80", "192.168.1.5"]);
        assert_eq!(on("[::1]:8080"), ["[::1]:8080", "localhost:8080"]);
    }

    #[test]
    fn only_this_pages_requests_with_the_token_pass() {
        let hosts = vec!["127.0.0.1:8080".to_string(), "localhost:8080".to_string()];
        let ok = |host, origin, target, ws| refusal(host, origin, target, "abc", &hosts, ws);
        assert_eq!(ok(Some("127.0.0.1:8080"), None, "/?token=abc", false), None);
        assert_eq!(
            ok(
                Some("localhost:8080"),
                Some("http://localhost:8080"),
                "/ws?token=abc",
                true
            ),
            None
        );
        // DNS rebinding: the attacker's name in Host.
        assert_eq!(
            ok(Some("evil.example:8080"), None, "/?token=abc", false),
            Some("wrong Host")
        );
        assert_eq!(ok(None, None, "/?token=abc", false), Some("wrong Host"));
        assert_eq!(
            ok(Some("127.0.0.1:8080"), None, "/", false),
            Some("no valid token")
        );
        assert_eq!(
            ok(Some("127.0.0.1:8080"), None, "/?token=abd", false),
            Some("no valid token")
        );
        // Another page in the same browser (it knows the token, say).
        assert_eq!(
            ok(
                Some("127.0.0.1:8080"),
                Some("http://evil.example"),
                "/ws?token=abc",
                true
            ),
            Some("wrong Origin")
        );
        assert_eq!(
            ok(Some("127.0.0.1:8080"), None, "/ws?token=abc", true),
            Some("wrong Origin")
        );
    }
}
