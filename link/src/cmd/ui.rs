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
//! start (then a session cookie); the HTTP server checks `Host` (a DNS-rebinding site names its
//! own) and the websocket checks `Origin` (another page open in the same
//! browser is not this one). Nothing of a refused request reaches the
//! robot. The robot still disarms by its link timeout when this client
//! goes away, and by the operator deadman below when its pages do.
//!
//! One thread owns the link (the [`Client`]): it streams telemetry, polls
//! the state, and runs the commands the pages send, one at a time (a
//! page's table reads and sets in a burst cost one table read); the
//! pages are served by [`server`] (hyper and axum on tokio, every queue
//! and limit bounded). A Disarm does not wait in that line: the page's
//! task sends it at once ([`Urgent`]), whatever the link's thread has in
//! flight. An operator deadman disarms the robot
//! when no page has been connected for [`OPERATOR_DEADMAN`]; pages
//! reconnect by themselves. Losing the robot is an event, not an exit:
//! a recording in progress is finished (every file, its plot), the pages
//! say so, and the cockpit connects again when the robot comes back.

use super::common::wire_name;
use super::record_planar::PlanarFiles;
use super::stream::Sink;
use anyhow::{bail, Context, Result};
use hopper_link::record::{Recording, Streamed};
use hopper_link::{names, Client, Urgent};
use hopper_protocol::{ArmState, DumpInfo, Request, Response, RobotMsg};
use std::io::Write;
use std::net::{SocketAddr, TcpListener};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicUsize, Ordering};
use std::sync::mpsc::{sync_channel, Receiver};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The page (HTML, CSS and script in one file).
const PAGE: &str = include_str!("ui.html");

/// Telemetry records a second the page is sent (the robot streams at this
/// rate; the page draws at its frame rate).
const TELEMETRY_HZ: f64 = 200.0;

mod server;
use server::Tab;

/// A command from a page, with where its answer goes.
struct Command {
    /// The page's JSON command.
    json: serde_json::Value,
    /// The answer's way back to that page.
    reply: Tab,
}

/// The pages connected: each one's queue of messages.
type Pages = Arc<Mutex<Vec<Tab>>>;

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
    /// Arm sessions seen: one more each time the robot is seen armed
    /// after it was not (the hop ledger and its plot are per session).
    arm_session: Arc<AtomicU32>,
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

    /// The robot seen armed or not; a new arm session when it was not.
    fn seen_armed(&self, armed: bool) {
        if armed && !self.armed.swap(true, Ordering::Relaxed) {
            self.arm_session.fetch_add(1, Ordering::Relaxed);
        }
        if !armed {
            self.armed.store(false, Ordering::Relaxed);
        }
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
    let token = server::secret()?;
    println!("cockpit: http://{bound}/?token={token}");
    println!("(open it in a browser; the robot is disarmed when no page is open for 0.5 s; Ctrl-C stops, and the robot disarms by its link timeout then)");
    std::io::stdout().flush()?;
    let shared = Shared::default();
    if let Ok(mut u) = shared.urgent.lock() {
        *u = Some(c.urgent());
    }
    let (commands, inbox) = sync_channel::<Command>(server::COMMANDS_WAITING);
    server::spawn(
        listener,
        server::Server {
            token,
            session: server::secret()?,
            hosts: server::hosts_for(bound),
            shared: shared.clone(),
            commands,
        },
    )?;
    {
        let shared = shared.clone();
        std::thread::spawn(move || deadman(&shared));
    }
    let mut session = Session {
        period_s: 0.0,
        record_dir: record_dir.to_path_buf(),
        recording: None,
        planar_recording: None,
        planar_machine: false,
        batch: Vec::new(),
        planar: Vec::new(),
        calibrating: None,
        capturing: None,
        target_apex_m: None,
        arm_session: shared.arm_session.clone(),
        table_due: false,
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
    let lost = |pages: Pages| {
        move |r: Result<String>| {
            let (ok, text) = match r {
                Ok(t) => (true, format!("the robot was lost; {t}")),
                Err(e) => (false, format!("the robot was lost; the recording: {e:#}")),
            };
            broadcast(
                &pages,
                &serde_json::json!({ "type": "notice", "ok": ok, "text": text, "recording_finished": true }),
            );
        }
    };
    if let Some((rec, dir)) = session.recording.take() {
        finish_recording(
            rec,
            dir,
            session.period_s,
            session.target_apex_m,
            c.target().to_string(),
            lost(pages.clone()),
        );
    }
    if let Some(rec) = session.planar_recording.take() {
        finish_planar(rec, c.target().to_string(), lost(pages.clone()));
    }
    let target = c.target().clone();
    loop {
        while let Ok(cmd) = inbox.try_recv() {
            cmd.reply.taken();
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

/// Sends `msg` to every page (dropping those gone).
fn broadcast(pages: &Pages, msg: &serde_json::Value) {
    let text = msg.to_string();
    let kind = msg["type"].as_str().unwrap_or("");
    if let Ok(mut p) = pages.lock() {
        p.retain(|tab| tab.push(kind, text.clone()).is_ok());
    }
}

/// What the link's thread keeps between commands: the recording in
/// progress and where recordings and captures go.
struct Session {
    /// The control period, s.
    period_s: f64,
    /// The robot is the planar machine.
    planar_machine: bool,
    /// Recordings and captures go in numbered folders here.
    record_dir: PathBuf,
    /// The recording in progress and its folder.
    recording: Option<(Streamed, PathBuf)>,
    /// The planar machine's recording in progress.
    planar_recording: Option<PlanarFiles>,
    /// Telemetry for the pages, sent about 30 times a second.
    batch: Vec<serde_json::Value>,
    /// The planar machine's records not yet sent to the pages.
    planar: Vec<serde_json::Value>,
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
    /// The arm session (the shared count), for the hops.
    arm_session: Arc<AtomicU32>,
    /// The parameter table is to be read and sent to the pages.
    table_due: bool,
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
                let toe_m = hopper_link::record::toe_height_m(&r);
                self.batch.push(serde_json::json!([
                    f64::from(r.step) * self.period_s,
                    r.body_height_m,
                    toe_m,
                    r.nut_position_m,
                    r.spring_force_n,
                    r.command_a,
                    r.energy_j,
                ]));
                self.recording.as_mut().map(|(rec, _)| rec.record(r))
            }
            RobotMsg::Planar(t) => {
                // The drawing's frame (`drawPlanar`: t, x, z, pitch, leg
                // angle, leg length, stance), then the speed, its command,
                // both currents, the guard's latch and the arming.
                self.planar.push(serde_json::json!([
                    f64::from(t.step) * self.period_s,
                    t.x_m,
                    t.z_m,
                    t.pitch_rad,
                    t.leg_angle_rad,
                    t.leg_length_m,
                    u8::from(t.stance),
                    t.speed_mps,
                    t.speed_command_mps,
                    t.hip_current_a,
                    t.leg_current_a,
                    super::status::planar_fault(t.fault),
                    t.armed,
                ]));
                self.planar_recording.as_mut().map(|rec| rec.record(t))
            }
            RobotMsg::Hop(h) => {
                broadcast(
                    pages,
                    &serde_json::json!({ "type": "hop", "hop": h, "session": self.arm_session.load(Ordering::Relaxed) }),
                );
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
            let dir = match (self.recording.take(), self.planar_recording.take()) {
                (Some((_, d)), _) => d.display().to_string(),
                (None, Some(p)) => p.dir().display().to_string(),
                (None, None) => String::new(),
            };
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
    session.planar_machine = super::common::is_planar(c)?;
    session.target_apex_m = super::common::get(c, "target_apex_m").ok().map(f64::from);
    let session = &mut *session;
    let mut last_poll = Instant::now();
    let mut last_send = Instant::now();
    let mut last_state = Instant::now() - Duration::from_secs(1);
    let mut last_thermal = last_state;
    loop {
        while let Ok(cmd) = inbox.try_recv() {
            cmd.reply.taken();
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
        if std::mem::take(&mut session.table_due) {
            broadcast(pages, &parameters(c)?);
        }
        progress_capture(c, pages, session);
        if session.calibrating.is_some() && last_poll.elapsed() >= Duration::from_millis(100) {
            last_poll = Instant::now();
            let mut out = String::new();
            let ended = match &mut session.calibrating {
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
            let recording = session
                .recording
                .as_ref()
                .map(|(_, d)| d.as_path())
                .or_else(|| session.planar_recording.as_ref().map(PlanarFiles::dir));
            broadcast(pages, &state(c, recording, session.target_apex_m, shared)?);
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
                        "protection": th.protect,
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
                let flushed = session.planar_recording.as_mut().map(Sink::flush);
                session.check(pages, flushed);
            }
        }
        // About 30 frames a second to the pages.
        if last_send.elapsed() >= Duration::from_millis(33)
            && !(session.batch.is_empty() && session.planar.is_empty())
        {
            last_send = Instant::now();
            if !session.batch.is_empty() {
                broadcast(
                    pages,
                    &serde_json::json!({ "type": "telemetry", "records": std::mem::take(&mut session.batch) }),
                );
            }
            if !session.planar.is_empty() {
                broadcast(
                    pages,
                    &serde_json::json!({ "type": "planar", "records": std::mem::take(&mut session.planar) }),
                );
            }
        }
    }
}

/// The robot's state for the page.
fn state(
    c: &mut Client,
    recording: Option<&std::path::Path>,
    target_apex_m: Option<f64>,
    shared: &Shared,
) -> Result<serde_json::Value> {
    let s = match c.request(Request::Status)? {
        Response::Status(s) => s,
        r => bail!("unexpected answer {r:?}"),
    };
    shared.seen_armed(s.arm == ArmState::Armed);
    let cost = match c.request(Request::Cost)? {
        Response::Cost(x) => Some(x),
        _ => None,
    };
    let host = c.stats();
    let counts = c.counts();
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
        "telemetry_missing": counts.telemetry_gaps,
        "retries": counts.retries,
        "requests_failed": counts.failed,
        "last_apex_m": s.last_apex_m,
        "isr_mean": cost.map(|x| x.isr_mean),
        "isr_max": cost.map(|x| x.isr_max),
        "counter_hz": cost.map(|x| x.counter_hz),
        "recording": recording.map(|d| d.display().to_string()),
        "note": shared.note(),
        "target_apex_m": target_apex_m,
        "arm_session": shared.arm_session.load(Ordering::Relaxed),
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
                "shown": {
                    "value": d.number(if active { p.value } else { p.default }),
                    "min": names::plain_number(p.min),
                    "max": names::plain_number(p.max),
                    "default": d.number(p.default),
                },
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
                shared.seen_armed(true);
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
        // The table is read once the waiting commands ran: one read for
        // every page's ask and every set in a burst.
        "params" => {
            session.table_due = true;
            Ok(String::new())
        }
        "set" => {
            let name = cmd["name"].as_str().unwrap_or("");
            // A value as typed, or a JSON number.
            let text = match &cmd["value"] {
                serde_json::Value::Number(n) => n.to_string(),
                v => v.as_str().unwrap_or("").to_string(),
            };
            let text = text.as_str();
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
                    // The recording keeps every set at its time.
                    let written = session
                        .recording
                        .as_mut()
                        .map(|(rec, _)| rec.set(name, value));
                    session.check(pages, written);
                    session.table_due = true;
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
            if let Some(rec) = &session.planar_recording {
                bail!("already recording into {}", rec.dir().display());
            }
            if session.planar_machine {
                let dir = session.folder("recording");
                session.planar_recording = Some(PlanarFiles::create(&dir, session.period_s)?);
                return Ok(format!("recording into {}", dir.display()));
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
    if let Some(rec) = session.planar_recording.take() {
        finish_planar(rec, c.target().to_string(), move |result| {
            let _ = cmd.reply.send(answer(&cmd.json, result).to_string());
        });
        return;
    }
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

/// The files' names, `a, b, c`.
fn file_names(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Completes the planar machine's recording and draws its plot on a
/// thread of its own, then calls `done` with its summary.
fn finish_planar(
    rec: PlanarFiles,
    robot: String,
    done: impl FnOnce(Result<String>) + Send + 'static,
) {
    let title = format!("the planar machine, recorded from the cockpit ({robot})");
    std::thread::spawn(move || {
        let dir = rec.dir().to_path_buf();
        let result = rec.finish(&title).map(|(records, dropped, written)| {
            format!(
                "recorded the planar machine: {records} records, {dropped} dropped, into {}: {}",
                dir.display(),
                file_names(&written)
            )
        });
        done(result);
    });
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
                file_names(&written)
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
