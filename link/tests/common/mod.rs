//! A small robot on a loopback port for `hopper-link`'s tests: it answers
//! the hello and each request, and while streaming (asked for telemetry)
//! lets the test send what it wants. One loop for every test that needs a
//! robot.

use hopper_protocol::{
    encode, Decoder, HostMsg, Request, Response, RobotMsg, TimingStats, MAX_FRAME, PROTOCOL_VERSION,
};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// The fake robot's answer to `Timing`: a 1 kHz control period.
#[allow(dead_code)] // (not every test binary asks for it)
pub fn timing() -> Response {
    Response::Timing(TimingStats {
        period_s: 0.001,
        periods: 0,
        missed: 0,
        step_mean: 0,
        step_max: 0,
        link_mean: 0,
        link_max: 0,
    })
}

/// Sends one message; whether the link took it.
pub fn send(s: &mut TcpStream, m: &RobotMsg) -> bool {
    let mut f = [0u8; MAX_FRAME];
    let n = encode(m, &mut f).unwrap_or(0);
    s.write_all(&f[..n]).is_ok()
}

/// A robot answering one connection with `answer`, for `secs` at most,
/// reading with a `poll` timeout; after each read, while the host has
/// telemetry on, `stream` sends what it wants and says whether to keep
/// the link (false closes it).
pub fn robot(
    secs: u64,
    poll: Duration,
    mut answer: impl FnMut(&Request) -> Response + Send + 'static,
    mut stream: impl FnMut(&mut TcpStream) -> bool + Send + 'static,
) -> (String, JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let addr = l.local_addr().unwrap_or_else(|e| panic!("{e}")).to_string();
    let serve = std::thread::spawn(move || {
        let Ok((mut s, _)) = l.accept() else { return };
        let _ = s.set_read_timeout(Some(poll));
        let (mut d, mut buf) = (Decoder::new(), [0u8; 512]);
        let mut streaming = false;
        let end = Instant::now() + Duration::from_secs(secs);
        while Instant::now() < end {
            let n = match s.read(&mut buf) {
                Ok(0) => return,
                Ok(n) => n,
                Err(_) => 0,
            };
            for &b in &buf[..n] {
                let reply = match d.push::<HostMsg>(b) {
                    Some(HostMsg::Hello { .. }) => RobotMsg::Hello {
                        version: PROTOCOL_VERSION,
                    },
                    Some(HostMsg::Request { id, req }) => {
                        if let Request::Telemetry { every } = req {
                            streaming = every > 0;
                        }
                        RobotMsg::Response {
                            id,
                            resp: answer(&req),
                        }
                    }
                    _ => continue,
                };
                send(&mut s, &reply);
            }
            if streaming && !stream(&mut s) {
                // A robot's end of the link closes gracefully: dropping a
                // socket with the host's heartbeats unread resets it, and
                // the reset throws away telemetry not yet delivered.
                let _ = s.shutdown(std::net::Shutdown::Write);
                let _ = s.set_read_timeout(Some(Duration::from_secs(5)));
                while matches!(s.read(&mut buf), Ok(n) if n > 0) {}
                return;
            }
        }
    });
    (addr, serve)
}
