//! `hopper-sim serve --tcp ADDR`: the virtual robot on a TCP socket, in
//! real time (or `--speed N` times it), so `hopper-link` can be learned and
//! tested without hardware. `hopper-sim planar serve --tcp` serves the
//! planar machine through the same loop ([`Served`]).
//!
//! One client at a time. The loop runs the periods that are due by the
//! wall clock, hands the bytes that arrived since the last batch to its
//! first period, and writes what the robot queued. The transmit queue is
//! bounded like a UART's ring ([`TX_QUEUE_BYTES`]): a client that does not
//! read loses telemetry (counted by the robot), never blocks the robot.

use hopper_control::runner::NoCounter;
use hopper_control::telemetry::{FaultCapture, CAPTURE_LEN};
use hopper_robot_link::Tx;
use hopper_sil::robot::VirtualRobot;
use std::io::{ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::time::{Duration, Instant};

/// The transmit queue's size, bytes: 16 KiB, about 170 ms of the board's
/// 921,600 baud line.
pub const TX_QUEUE_BYTES: usize = 16 * 1024;

/// Periods run in one batch at most before the socket is serviced again
/// (0.1 s of robot time at 10 kHz): a slow host falls behind the clock
/// instead of starving the link.
const MAX_BATCH: u64 = 1000;

/// The robot's side of the socket: a bounded byte queue.
#[derive(Debug, Default)]
pub struct Queue {
    bytes: Vec<u8>,
}

impl Tx for Queue {
    fn room(&self) -> usize {
        TX_QUEUE_BYTES.saturating_sub(self.bytes.len())
    }
    fn put(&mut self, frame: &[u8]) {
        self.bytes.extend_from_slice(frame);
    }
}

/// The virtual robot's flash: two 2 KiB pages in RAM, kept in a file
/// when one is given (`hopper-sim serve --flash FILE`), so a saved
/// calibration survives a restart of the simulator as a board's does.
pub struct Flash {
    store: hopper_store::Store<SimFlash>,
    path: Option<std::path::PathBuf>,
}

/// The simulator's flash.
pub type SimFlash = hopper_store::RamFlash<2, 2048>;

impl Flash {
    /// The flash, read from `path` if it exists, and the record it holds.
    pub fn open(path: Option<&std::path::Path>) -> Result<(Self, Option<Vec<u8>>), String> {
        let mut flash = SimFlash::new();
        if let Some(p) = path {
            match std::fs::read(p) {
                Ok(bytes) => flash.load_bytes(&bytes),
                Err(e) if e.kind() == ErrorKind::NotFound => {}
                Err(e) => return Err(format!("{}: {e}", p.display())),
            }
        }
        let mut store =
            hopper_store::Store::new(flash, 0..4096).map_err(|e| e.name().to_string())?;
        let mut out = [0u8; hopper_control::persist::MAX_RECORD];
        let record = hopper_store::block_on(store.load(&mut out))
            .map_err(|e| format!("flash: {}", e.name()))?
            .map(|n| out[..n].to_vec());
        Ok((
            Self {
                store,
                path: path.map(std::path::Path::to_path_buf),
            },
            record,
        ))
    }

    /// Writes `record` (and the file).
    pub fn save(&mut self, record: &[u8]) -> Result<(), String> {
        hopper_store::block_on(self.store.save(record)).map_err(|e| e.name().to_string())?;
        if let Some(p) = &self.path {
            // The store is taken apart to read its pages, then rebuilt on them.
            let flash = std::mem::replace(
                &mut self.store,
                hopper_store::Store::new(SimFlash::new(), 0..4096)
                    .map_err(|e| e.name().to_string())?,
            )
            .into_flash();
            let bytes: Vec<u8> = flash.pages().iter().flatten().copied().collect();
            self.store =
                hopper_store::Store::new(flash, 0..4096).map_err(|e| e.name().to_string())?;
            std::fs::write(p, bytes).map_err(|e| format!("{}: {e}", p.display()))?;
        }
        Ok(())
    }
}

/// Loads the calibration `flash` holds into `robot` (as a board does at boot,
/// before [`serve`] builds the link task's end from it).
pub fn load_at_boot(robot: &mut VirtualRobot, record: Option<&[u8]>) {
    robot.firmware.runner.load_calibration(record);
}

/// How the loop runs.
#[derive(Debug, Clone, Copy)]
pub struct ServeOptions {
    /// Robot seconds per wall second.
    pub speed: f64,
    /// Stop after this much robot time, s (None: until killed).
    pub limit_s: Option<f64>,
    /// Control period, s.
    pub dt_s: f64,
}

/// How long the end of a session waits for the client to take the last
/// bytes and close its side.
const CLOSE_WAIT: Duration = Duration::from_secs(2);

/// Ends a connection without losing what was sent: writes `pending`, says
/// end-of-stream (FIN), then reads and discards until the peer closes or
/// `wait` passes. Dropping a socket whose peer's bytes (heartbeats) are
/// still unread makes the kernel send a reset instead, and a reset throws
/// away the telemetry still queued for the peer.
pub fn close_after(mut s: TcpStream, pending: &[u8], wait: Duration) {
    let end = Instant::now() + wait;
    let _ = s.set_nonblocking(false);
    let _ = s.set_write_timeout(Some(wait));
    let _ = s.write_all(pending);
    let _ = s.shutdown(std::net::Shutdown::Write);
    let mut buf = [0u8; 4096];
    while let Some(left) = end.checked_duration_since(Instant::now()) {
        if left.is_zero() || s.set_read_timeout(Some(left)).is_err() {
            break;
        }
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(_) => {}
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(_) => break,
        }
    }
}

/// A robot the serve loop runs, one period at a time.
pub trait Served {
    /// One period, given the bytes `rx` that came since the last; what it
    /// sends goes into `tx`. An error ends the serving.
    fn period(&mut self, rx: Vec<u8>, tx: &mut Queue) -> Result<(), String>;
}

/// The vertical hopper's virtual robot with its link's two ends, its
/// capture and its flash.
struct Vertical {
    robot: VirtualRobot,
    flash: Flash,
    /// The robot's capture, frozen around a fault (32 KiB: on the heap).
    capture: Box<FaultCapture<CAPTURE_LEN>>,
    queues: Box<hopper_robot_link::Queues>,
    link: hopper_robot_link::Endpoint,
}

impl Served for Vertical {
    fn period(&mut self, rx: Vec<u8>, tx: &mut Queue) -> Result<(), String> {
        let Vertical {
            robot,
            flash,
            capture,
            queues,
            link,
        } = self;
        robot.control(link, rx.into_iter(), tx, capture, queues, &mut NoCounter);
        robot.firmware.runner.end_period(false);
        // A save: written between two periods, as the host's clock
        // allows (a board defers it to its next boot).
        if let Some(record) = link.take_save().map(<[u8]>::to_vec) {
            let ok = flash.save(&record);
            if let Err(e) = &ok {
                eprintln!("hopper-sim: save failed: {e}");
            }
            link.save_done(ok.is_ok(), false);
        }
        robot
            .advance(&mut |_| {})
            .map_err(|e| format!("plant integration failed: {e:?}"))
    }
}

/// Serves the vertical hopper's `robot` on `listener` until the time
/// limit (or forever). Messages about clients go to stderr.
pub fn serve(
    robot: VirtualRobot,
    flash: Flash,
    listener: &TcpListener,
    opts: ServeOptions,
) -> Result<(), String> {
    // The link task's end, built from the configuration as loaded (as the
    // board builds its endpoint after loading the saved calibration).
    let link = hopper_robot_link::Endpoint::simulated(&robot.firmware.runner);
    serve_robot(
        &mut Vertical {
            robot,
            flash,
            capture: Box::new(FaultCapture::<CAPTURE_LEN>::new()),
            queues: Box::default(),
            link,
        },
        listener,
        opts,
    )
}

/// Serves `robot` on `listener` until the time limit (or forever).
/// Messages about clients go to stderr.
pub fn serve_robot(
    robot: &mut dyn Served,
    listener: &TcpListener,
    opts: ServeOptions,
) -> Result<(), String> {
    listener
        .set_nonblocking(true)
        .map_err(|e| format!("socket: {e}"))?;
    let mut client: Option<TcpStream> = None;
    let mut tx = Queue::default();
    let mut inbox: Vec<u8> = Vec::new();
    let mut buf = [0u8; 4096];
    let start = Instant::now();
    let mut done: u64 = 0;
    let limit = opts.limit_s.map(|s| (s / opts.dt_s).round() as u64);
    loop {
        if client.is_none() {
            match listener.accept() {
                Ok((s, peer)) => {
                    let _ = s.set_nodelay(true);
                    if s.set_nonblocking(true).is_ok() {
                        eprintln!("hopper-sim: client {peer} connected");
                        // What was queued for nobody is not the new client's.
                        tx.bytes.clear();
                        client = Some(s);
                    }
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {}
                Err(e) => return Err(format!("accept: {e}")),
            }
        }
        if let Some(s) = client.as_mut() {
            let mut closed = false;
            loop {
                match s.read(&mut buf) {
                    Ok(0) => {
                        closed = true;
                        break;
                    }
                    Ok(n) => inbox.extend_from_slice(buf.get(..n).unwrap_or_default()),
                    Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                    Err(e) if e.kind() == ErrorKind::Interrupted => {}
                    Err(_) => {
                        closed = true;
                        break;
                    }
                }
            }
            if closed {
                eprintln!("hopper-sim: client disconnected");
                client = None;
            }
        }
        // The periods due by the clock, the first with the bytes that came.
        let due = (start.elapsed().as_secs_f64() * opts.speed / opts.dt_s) as u64;
        let due = limit.map_or(due, |l| due.min(l));
        let batch = due.saturating_sub(done).min(MAX_BATCH);
        for _ in 0..batch {
            robot.period(std::mem::take(&mut inbox), &mut tx)?;
            done += 1;
        }
        if let Some(s) = client.as_mut() {
            match s.write(&tx.bytes) {
                Ok(n) => {
                    tx.bytes.drain(..n);
                }
                Err(e) if e.kind() == ErrorKind::WouldBlock => {}
                Err(_) => {
                    eprintln!("hopper-sim: client disconnected");
                    client = None;
                }
            }
        } else {
            tx.bytes.clear();
        }
        if limit.is_some_and(|l| done >= l) {
            // The client gets everything the robot queued before the end.
            if let Some(s) = client.take() {
                close_after(s, &tx.bytes, CLOSE_WAIT);
            }
            return Ok(());
        }
        if batch < MAX_BATCH {
            std::thread::sleep(Duration::from_micros(500));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A peer that has sent bytes the robot never read, and that reads
    /// slowly, still receives every byte sent before the close.
    #[test]
    fn a_close_loses_nothing_that_was_sent() {
        for graceful in [false, true] {
            let l = TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
            let addr = l.local_addr().unwrap_or_else(|e| panic!("{e}"));
            let client = std::thread::spawn(move || {
                let mut c = TcpStream::connect(addr).unwrap_or_else(|e| panic!("{e}"));
                // Heartbeats the robot will not read.
                let _ = c.write_all(&[0u8; 64]);
                // A slow reader: the robot's queue fills meanwhile.
                std::thread::sleep(Duration::from_millis(300));
                let mut got = Vec::new();
                let _ = c.set_read_timeout(Some(Duration::from_secs(5)));
                let _ = c.read_to_end(&mut got);
                got.len()
            });
            let (mut s, _) = l.accept().unwrap_or_else(|e| panic!("{e}"));
            std::thread::sleep(Duration::from_millis(50));
            // As much as the kernel takes without the peer reading, and a
            // queue of bytes still to write.
            let _ = s.set_nonblocking(true);
            let chunk = [7u8; 4096];
            let mut sent = 0usize;
            while let Ok(n) = s.write(&chunk) {
                sent += n;
            }
            let pending = vec![9u8; 10_000];
            if graceful {
                close_after(s, &pending, Duration::from_secs(5));
                sent += pending.len();
            } else {
                drop(s);
            }
            let got = client.join().unwrap_or_default();
            if graceful {
                assert_eq!(got, sent, "a graceful close lost bytes");
            } else {
                // What the fixed close prevents: a reset drops the queue.
                assert!(got < sent, "dropped: {got} of {sent} bytes arrived");
            }
        }
    }
}
