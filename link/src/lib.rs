//! The host end of the hopper's link: a [`Client`] over a serial
//! port or a TCP socket that speaks [`hopper_protocol`] to the board, the
//! QEMU image or `hopper-sim serve`.
//!
//! A reader thread decodes the robot's frames as they come; a heartbeat
//! thread sends [`HostMsg::Heartbeat`] every [`HEARTBEAT`] while
//! connected, so the robot's link timeout (0.2 s by default) only fires
//! when the host is gone (or [`Client::set_heartbeats`] stops them on
//! purpose). Requests carry ids; their responses are matched by id, and
//! everything unsolicited (telemetry, hops, faults, state changes, dump
//! records) waits in order for [`Client::next_event`].

use anyhow::{anyhow, bail, Context, Result};
use hopper_protocol::{
    encode, Decoder, HostMsg, LinkStats, PlanarTelemetry, Request, Response, RobotMsg, Telemetry,
    MAX_FRAME, PROTOCOL_VERSION,
};
use std::collections::VecDeque;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

pub mod bringup;
pub mod names;
pub mod record;

/// Heartbeat period: a tenth of the robot's default 0.2 s link timeout,
/// so a virtual robot may run a few times faster than real time.
pub const HEARTBEAT: Duration = Duration::from_millis(20);

/// How long a TCP connection may take to open.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(3);

/// How long a request waits for its response, its retries included.
pub const RESPONSE_TIMEOUT: Duration = Duration::from_secs(3);
/// How many times a request is sent at most before it fails.
pub const MAX_SENDS: u32 = 8;
/// The shortest and longest wait for an answer before a request is sent
/// again; between them, the link's round trip (its smoothed value and
/// four times its variation, as TCP's retransmission timer).
pub const RETRY_MIN: Duration = Duration::from_millis(100);
/// See [`RETRY_MIN`].
pub const RETRY_MAX: Duration = Duration::from_secs(1);
/// The wait before the first round trip is measured.
pub const RETRY_FIRST: Duration = Duration::from_millis(250);

/// What the host counted besides its decoder's frames.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HostCounts {
    /// Requests sent (each once, however often it was sent).
    pub requests: u64,
    /// Sends again of a request whose answer did not come in time.
    pub retries: u64,
    /// Requests answered after being sent again.
    pub answered_after_retry: u64,
    /// Requests that got no answer at all.
    pub failed: u64,
    /// Telemetry records missing from the sequence (the robot's dropped
    /// ones and the line's lost ones).
    pub telemetry_gaps: u64,
}

/// The link's round trip, smoothed (RFC 6298's estimator): the wait
/// before a request is sent again.
#[derive(Debug, Clone, Copy, Default)]
struct RoundTrip {
    /// Smoothed round trip and its variation, s (`None`: not measured).
    srtt_var_s: Option<(f64, f64)>,
}

impl RoundTrip {
    /// A round trip measured on a request answered at its first send
    /// (Karn: a retried one's answer may be the first send's).
    fn sample(&mut self, rtt: Duration) {
        let r = rtt.as_secs_f64();
        self.srtt_var_s = Some(match self.srtt_var_s {
            None => (r, r / 2.0),
            Some((s, v)) => (0.875 * s + 0.125 * r, 0.75 * v + 0.25 * (s - r).abs()),
        });
    }

    /// The wait for an answer before sending again.
    fn timeout(&self) -> Duration {
        self.srtt_var_s.map_or(RETRY_FIRST, |(s, v)| {
            Duration::from_secs_f64(s + 4.0 * v).clamp(RETRY_MIN, RETRY_MAX)
        })
    }
}
/// The telemetry records missing between the last sequence number
/// `last` and `seq` (none when `seq` went back: a restarted robot).
pub fn seq_gap(last: Option<u32>, seq: u32) -> u32 {
    let gap = last.map_or(0, |l| seq.wrapping_sub(l).wrapping_sub(1));
    if gap < 1 << 30 {
        gap
    } else {
        0
    }
}

/// How often the hello is repeated until the robot answers it.
pub const HELLO_RETRY: Duration = Duration::from_millis(200);

/// Where the robot is.
#[derive(Debug, Clone)]
pub enum Target {
    /// A TCP address (QEMU's `-serial tcp:`, `hopper-sim serve`).
    Tcp(String),
    /// A serial port and its baud rate (the board's USART1).
    Serial(String, u32),
}

impl std::fmt::Display for Target {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Target::Tcp(a) => write!(f, "tcp {a}"),
            Target::Serial(p, b) => write!(f, "serial {p} at {b} baud"),
        }
    }
}

/// What [`Client::connect`]'s errors carry when the address itself is
/// wrong or leads nowhere (it does not resolve, no such serial device,
/// nobody listening there): a caller can then say how to give another.
#[derive(Debug)]
pub struct BadAddress(pub String);

impl std::fmt::Display for BadAddress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadAddress {}

type Writer = Arc<Mutex<Box<dyn Write + Send>>>;

/// How often an urgent request is sent again until answered.
const URGENT_RETRY: Duration = Duration::from_millis(50);

/// Request ids: [`Client::request`]'s below these, [`Urgent`]'s these
/// (above them, `flood`'s own, from 40,000).
const URGENT_IDS: std::ops::Range<u16> = 0x7000..0x8000;

/// A connected robot.
pub struct Client {
    writer: Writer,
    incoming: Receiver<RobotMsg>,
    urgent: Urgent,
    /// Unsolicited messages received while waiting for a response.
    queued: VecDeque<RobotMsg>,
    next_id: u16,
    heartbeats: Arc<AtomicBool>,
    stop: Arc<AtomicBool>,
    stats: Arc<Mutex<LinkStats>>,
    counts: Arc<Mutex<HostCounts>>,
    round_trip: RoundTrip,
    threads: Vec<JoinHandle<()>>,
    target: Target,
}

/// `msg` framed for the line (COBS, CRC, the delimiter).
pub fn frame(msg: &HostMsg) -> Result<Vec<u8>> {
    let mut f = [0u8; MAX_FRAME];
    let n = encode(msg, &mut f).map_err(|e| anyhow!("cannot frame {msg:?}: {e:?}"))?;
    Ok(f.get(..n).unwrap_or_default().to_vec())
}

fn write_all(w: &Writer, bytes: &[u8]) -> Result<()> {
    let mut w = w.lock().map_err(|_| anyhow!("link writer poisoned"))?;
    w.write_all(bytes)?;
    w.flush()?;
    Ok(())
}

impl Client {
    /// Opens `target`, starts the reader and heartbeat threads and does
    /// the version handshake. One clear error for each way it can fail: no
    /// such device, nobody listening, no answer, another protocol version.
    pub fn connect(target: &Target) -> Result<Client> {
        let (reader, writer): (Box<dyn Read + Send>, Box<dyn Write + Send>) = match target {
            Target::Tcp(addr) => {
                use std::net::ToSocketAddrs;
                let bad = |why: String| anyhow::Error::new(BadAddress(why));
                let sock = addr
                    .to_socket_addrs()
                    .map_err(|e| bad(format!("cannot resolve {addr} as HOST:PORT: {e}")))?
                    .next()
                    .ok_or_else(|| bad(format!("cannot resolve {addr} as HOST:PORT")))?;
                let s = TcpStream::connect_timeout(&sock, CONNECT_TIMEOUT).map_err(|e| {
                    bad(format!("cannot connect to {addr}: is `hopper-sim serve` or the QEMU image running?: {e}"))
                })?;
                let _ = s.set_nodelay(true);
                s.set_read_timeout(Some(Duration::from_millis(50)))?;
                (Box::new(s.try_clone()?), Box::new(s))
            }
            Target::Serial(port, baud) => {
                let p = serialport::new(port, *baud)
                    .timeout(Duration::from_millis(50))
                    .open()
                    .map_err(|e| {
                        anyhow::Error::new(BadAddress(format!(
                            "cannot open serial port {port}: {e}"
                        )))
                    })?;
                (Box::new(p.try_clone()?), Box::new(p))
            }
        };
        let writer: Writer = Arc::new(Mutex::new(writer));
        let stop = Arc::new(AtomicBool::new(false));
        let heartbeats = Arc::new(AtomicBool::new(true));
        let stats = Arc::new(Mutex::new(LinkStats::default()));
        let counts = Arc::new(Mutex::new(HostCounts::default()));
        let (tx, incoming) = mpsc::channel();
        let (urgent_tx, urgent_rx) = mpsc::channel();
        let mut threads = Vec::new();
        {
            let (stop, stats, counts) = (stop.clone(), stats.clone(), counts.clone());
            let mut reader = reader;
            threads.push(std::thread::spawn(move || {
                let mut d = Decoder::new();
                let mut last_seq: Option<u32> = None;
                let mut buf = [0u8; 4096];
                while !stop.load(Ordering::Relaxed) {
                    match reader.read(&mut buf) {
                        Ok(0) => break,
                        Ok(n) => {
                            for &b in buf.get(..n).unwrap_or_default() {
                                let Some(m) = d.push::<RobotMsg>(b) else {
                                    continue;
                                };
                                match m {
                                    // An urgent request's answer goes to
                                    // its own waiter, past the queue.
                                    RobotMsg::Response { id, resp } if URGENT_IDS.contains(&id) => {
                                        let _ = urgent_tx.send((id, resp));
                                    }
                                    RobotMsg::Telemetry(Telemetry { seq, .. })
                                    | RobotMsg::Planar(PlanarTelemetry { seq, .. }) => {
                                        let gap = seq_gap(last_seq, seq);
                                        if gap > 0 {
                                            if let Ok(mut c) = counts.lock() {
                                                c.telemetry_gaps += u64::from(gap);
                                            }
                                        }
                                        last_seq = Some(seq);
                                        if tx.send(m).is_err() {
                                            return;
                                        }
                                    }
                                    m => {
                                        if tx.send(m).is_err() {
                                            return;
                                        }
                                    }
                                }
                            }
                            if let Ok(mut s) = stats.lock() {
                                *s = d.stats();
                            }
                        }
                        Err(e)
                            if matches!(
                                e.kind(),
                                std::io::ErrorKind::TimedOut
                                    | std::io::ErrorKind::WouldBlock
                                    | std::io::ErrorKind::Interrupted
                            ) => {}
                        Err(_) => break,
                    }
                }
            }));
        }
        {
            let (stop, on, w) = (stop.clone(), heartbeats.clone(), writer.clone());
            let beat = frame(&HostMsg::Heartbeat)?;
            threads.push(std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    if on.load(Ordering::Relaxed) && write_all(&w, &beat).is_err() {
                        break;
                    }
                    std::thread::sleep(HEARTBEAT);
                }
            }));
        }
        let mut c = Client {
            urgent: Urgent {
                writer: writer.clone(),
                next: Arc::new(std::sync::atomic::AtomicU16::new(URGENT_IDS.start)),
                answers: Arc::new(Mutex::new(urgent_rx)),
            },
            writer,
            incoming,
            queued: VecDeque::new(),
            next_id: 1,
            heartbeats,
            stop,
            stats,
            counts,
            round_trip: RoundTrip::default(),
            threads,
            target: target.clone(),
        };
        // The hello is repeated until answered: a robot that is still
        // booting (its USART not yet enabled), or a TCP server that has not
        // yet taken this connection from its backlog, loses the bytes sent
        // before it listens. Each hello starts with a delimiter, which
        // flushes whatever half frame the line holds.
        let deadline = Instant::now() + RESPONSE_TIMEOUT;
        let mut next_hello = Instant::now();
        loop {
            if Instant::now() >= next_hello {
                c.send_raw(&[0])?;
                c.send(&HostMsg::Hello {
                    version: PROTOCOL_VERSION,
                })?;
                next_hello = Instant::now() + HELLO_RETRY;
            }
            match c.recv_until(next_hello.min(deadline))? {
                Some(RobotMsg::Hello { version }) if version == PROTOCOL_VERSION => return Ok(c),
                Some(RobotMsg::Hello { version }) => bail!(
                    "the robot at {target} speaks protocol version {version}, this hopper-link speaks {PROTOCOL_VERSION}: update one of them"
                ),
                Some(_) => {}
                None if Instant::now() < deadline => {}
                None => bail!(
                    "no answer from {target} within {:.0} s: is it a hopper running firmware with the link (and the baud rate right), and no other hopper-link connected (a robot takes one client at a time)?",
                    RESPONSE_TIMEOUT.as_secs_f64()
                ),
            }
        }
    }

    /// A handle for requests that must not wait behind this client's
    /// (a Disarm): any thread may use it while another runs requests.
    pub fn urgent(&self) -> Urgent {
        self.urgent.clone()
    }

    /// Where this client is connected.
    pub fn target(&self) -> &Target {
        &self.target
    }

    /// Sends one message.
    pub fn send(&self, msg: &HostMsg) -> Result<()> {
        write_all(&self.writer, &frame(msg)?).context("the link closed")
    }

    /// Sends bytes as they are (tests: garbage on the line).
    pub fn send_raw(&self, bytes: &[u8]) -> Result<()> {
        write_all(&self.writer, bytes).context("the link closed")
    }

    /// Starts or stops the heartbeats (stopping them makes the robot
    /// disarm after its link timeout, unless other frames keep coming).
    pub fn set_heartbeats(&self, on: bool) {
        self.heartbeats.store(on, Ordering::Relaxed);
    }

    /// What the host's decoder counted (frames from the robot).
    pub fn stats(&self) -> LinkStats {
        self.stats.lock().map(|s| *s).unwrap_or_default()
    }

    /// What the host counted besides (requests, retries, telemetry gaps).
    pub fn counts(&self) -> HostCounts {
        self.counts.lock().map(|c| *c).unwrap_or_default()
    }

    fn count(&self, f: impl FnOnce(&mut HostCounts)) {
        if let Ok(mut c) = self.counts.lock() {
            f(&mut c);
        }
    }

    fn recv_until(&mut self, deadline: Instant) -> Result<Option<RobotMsg>> {
        let left = deadline.saturating_duration_since(Instant::now());
        match self.incoming.recv_timeout(left) {
            Ok(m) => Ok(Some(m)),
            Err(RecvTimeoutError::Timeout) => Ok(None),
            Err(RecvTimeoutError::Disconnected) => {
                bail!("the link to {} closed", self.target)
            }
        }
    }

    /// Sends `req` and waits for its response; unsolicited messages that
    /// come meanwhile are kept for [`next_event`](Self::next_event).
    ///
    /// A request whose answer does not come within the link's round trip
    /// (measured, [`RETRY_MIN`] to [`RETRY_MAX`]) is sent again with the
    /// same id, up to [`MAX_SENDS`] times within [`RESPONSE_TIMEOUT`]: the
    /// robot answers a repeat of a request that acts from its memory of
    /// the id and never runs it twice. With no answer at all, one error
    /// that says whether the request may have been carried out.
    pub fn request(&mut self, req: Request) -> Result<Response> {
        self.exchange(req, MAX_SENDS)
    }

    /// [`request`](Self::request) sent once, never again: the robot's
    /// answer then says in which period it received the host's last frame
    /// (`silence` times the link timeout from there).
    pub fn request_once(&mut self, req: Request) -> Result<Response> {
        self.exchange(req, 1)
    }

    fn exchange(&mut self, req: Request, max_sends: u32) -> Result<Response> {
        let id = self.next_id;
        // 1 ..= 0x6fff: the ids above are the urgent requests'.
        self.next_id = self.next_id % (URGENT_IDS.start - 1) + 1;
        let what = format!("{req:?}");
        let acts = req.acts();
        let bytes = frame(&HostMsg::Request { id, req })?;
        self.count(|c| c.requests += 1);
        let start = Instant::now();
        let deadline = start + RESPONSE_TIMEOUT;
        let mut sends = 0u32;
        loop {
            write_all(&self.writer, &bytes).context("the link closed")?;
            sends += 1;
            let sent = Instant::now();
            // The last send waits for the rest of the time.
            let wait = if sends >= max_sends {
                deadline
            } else {
                (sent + self.round_trip.timeout()).min(deadline)
            };
            loop {
                match self.recv_until(wait)? {
                    Some(RobotMsg::Response { id: got, resp }) if got == id => {
                        if sends == 1 {
                            self.round_trip.sample(sent.elapsed());
                        } else {
                            self.count(|c| c.answered_after_retry += 1);
                        }
                        return Ok(resp);
                    }
                    // A late answer to an earlier request sent again.
                    Some(RobotMsg::Response { .. }) => {}
                    Some(m) => self.queued.push_back(m),
                    None => break,
                }
            }
            if Instant::now() >= deadline || sends >= max_sends {
                self.count(|c| c.failed += 1);
                let applied = if acts {
                    "whether the robot carried it out is not known (`hopper-link status` and `params get` tell)"
                } else {
                    "it only reads: nothing on the robot changed"
                };
                bail!(
                    "no response to {what} from {}: sent {sends} times over {:.1} s, no answer came back; {applied}",
                    self.target,
                    start.elapsed().as_secs_f64()
                );
            }
            self.count(|c| c.retries += 1);
        }
    }

    /// Like [`request`](Self::request), but a refusal is an error with the
    /// robot's reason.
    pub fn expect_ok(&mut self, req: Request) -> Result<Response> {
        match self.request(req)? {
            Response::Refused(why) => bail!("refused: {why}"),
            r => Ok(r),
        }
    }

    /// The next unsolicited message, waiting up to `timeout`.
    pub fn next_event(&mut self, timeout: Duration) -> Result<Option<RobotMsg>> {
        if let Some(m) = self.queued.pop_front() {
            return Ok(Some(m));
        }
        self.recv_until(Instant::now() + timeout)
    }

    /// Drops the unsolicited messages that came while waiting for the last
    /// response (not those after it).
    pub fn discard_queued(&mut self) {
        self.queued.clear();
    }

    /// The unsolicited messages that came while waiting for the last
    /// response (not those after it), taken from the queue.
    pub fn take_queued(&mut self) -> Vec<RobotMsg> {
        self.queued.drain(..).collect()
    }

    /// Drops every unsolicited message received so far.
    pub fn discard_events(&mut self) {
        self.queued.clear();
        while self.incoming.try_recv().is_ok() {}
    }
}

/// Requests that go out at once, from any thread, whatever requests the
/// [`Client`] has in flight: their frames share the line (each written
/// whole), their answers come back past the client's queue by id. One
/// at a time: a second caller waits for the first's answer.
#[derive(Clone)]
pub struct Urgent {
    writer: Writer,
    next: Arc<std::sync::atomic::AtomicU16>,
    answers: Arc<Mutex<Receiver<(u16, Response)>>>,
}

impl Urgent {
    /// Sends `req` now and waits up to `timeout` for its answer.
    pub fn request(&self, req: Request, timeout: Duration) -> Result<Response> {
        let answers = self
            .answers
            .lock()
            .map_err(|_| anyhow!("urgent requests poisoned"))?;
        let id = self
            .next
            .fetch_update(Ordering::Relaxed, Ordering::Relaxed, |i| {
                Some(if i + 1 < URGENT_IDS.end {
                    i + 1
                } else {
                    URGENT_IDS.start
                })
            })
            .unwrap_or(URGENT_IDS.start);
        let what = format!("{req:?}");
        let bytes = frame(&HostMsg::Request { id, req })?;
        let deadline = Instant::now() + timeout;
        // Sent again every [`URGENT_RETRY`] until answered (a repeat is
        // answered from the robot's memory, never run twice).
        let mut sends = 0;
        loop {
            write_all(&self.writer, &bytes).context("the link closed")?;
            sends += 1;
            let wait = (Instant::now() + URGENT_RETRY).min(deadline);
            loop {
                let left = wait.saturating_duration_since(Instant::now());
                match answers.recv_timeout(left) {
                    Ok((got, resp)) if got == id => return Ok(resp),
                    // An earlier caller's that gave up waiting, or a
                    // repeat's.
                    Ok(_) => {}
                    Err(RecvTimeoutError::Timeout) => break,
                    Err(RecvTimeoutError::Disconnected) => bail!("the link closed"),
                }
            }
            if Instant::now() >= deadline {
                bail!(
                    "no response to {what} within {:.0} ms (sent {sends} times)",
                    timeout.as_secs_f64() * 1e3
                );
            }
        }
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}
