//! The client's one clear error for each way a connection can fail
//! (issue 17): nobody listening, a robot that never answers, another
//! protocol version.

use hopper_link::{Client, Target};
use hopper_protocol::{encode, RobotMsg, MAX_FRAME};
use std::io::Write;
use std::net::TcpListener;
use std::time::{Duration, Instant};

fn error_of(target: &Target) -> String {
    match Client::connect(target) {
        Ok(_) => panic!("connected to {target}"),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn nobody_listening() {
    // A port just freed: nothing listens there.
    let port = TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .unwrap_or_else(|e| panic!("{e}"));
    let e = error_of(&Target::Tcp(format!("127.0.0.1:{port}")));
    assert!(
        e.starts_with(&format!("cannot connect to 127.0.0.1:{port}")),
        "{e}"
    );
}

#[test]
fn no_such_serial_port() {
    let e = error_of(&Target::Serial("/dev/no-such-hopper".into(), 921_600));
    assert!(
        e.starts_with("cannot open serial port /dev/no-such-hopper"),
        "{e}"
    );
}

#[test]
fn a_robot_that_never_answers() {
    let l = TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let addr = l.local_addr().unwrap_or_else(|e| panic!("{e}"));
    let silent = std::thread::spawn(move || {
        let s = l.accept();
        std::thread::sleep(Duration::from_secs(4));
        drop(s);
    });
    let t0 = Instant::now();
    let e = error_of(&Target::Tcp(addr.to_string()));
    assert!(
        e.starts_with(&format!("no answer from tcp {addr} within 3 s")),
        "{e}"
    );
    assert!(t0.elapsed() < Duration::from_secs(4), "{:?}", t0.elapsed());
    let _ = silent.join();
}

#[test]
fn another_protocol_version() {
    let l = TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let addr = l.local_addr().unwrap_or_else(|e| panic!("{e}"));
    let robot = std::thread::spawn(move || {
        if let Ok((mut s, _)) = l.accept() {
            let mut f = [0u8; MAX_FRAME];
            let n = encode(&RobotMsg::Hello { version: 99 }, &mut f).unwrap_or(0);
            let _ = s.write_all(&f[..n]);
            std::thread::sleep(Duration::from_millis(500));
        }
    });
    let e = error_of(&Target::Tcp(addr.to_string()));
    assert!(
        e.contains("speaks protocol version 99, this hopper-link speaks 1"),
        "{e}"
    );
    let _ = robot.join();
}
