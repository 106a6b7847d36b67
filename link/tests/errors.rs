//! The client's one clear error for each way a connection can fail:
//! nobody listening, a robot that never answers, another
//! protocol version.

use hopper_link::{Client, Target};
use hopper_protocol::{encode, RobotMsg, MAX_FRAME, PROTOCOL_VERSION};
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
        e.contains(&format!(
            "speaks protocol version 99, this hopper-link speaks {PROTOCOL_VERSION}"
        )),
        "{e}"
    );
    let _ = robot.join();
}

#[test]
fn a_robot_still_booting_gets_the_hello_again() {
    // Like the QEMU image just started (or a board coming out of reset):
    // the bytes of the first 0.5 s are lost, then it answers every hello.
    let l = TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let addr = l.local_addr().unwrap_or_else(|e| panic!("{e}"));
    let robot = std::thread::spawn(move || {
        let Ok((mut s, _)) = l.accept() else { return 0 };
        let booted = Instant::now() + Duration::from_millis(500);
        let _ = s.set_read_timeout(Some(Duration::from_millis(20)));
        let mut d = hopper_protocol::Decoder::new();
        let mut buf = [0u8; 256];
        let mut hellos = 0;
        let end = Instant::now() + Duration::from_secs(2);
        while Instant::now() < end {
            let n = std::io::Read::read(&mut s, &mut buf).unwrap_or(0);
            if Instant::now() < booted {
                continue;
            }
            for &b in &buf[..n] {
                if let Some(hopper_protocol::HostMsg::Hello { .. }) = d.push(b) {
                    hellos += 1;
                    let mut f = [0u8; MAX_FRAME];
                    let k = encode(
                        &RobotMsg::Hello {
                            version: PROTOCOL_VERSION,
                        },
                        &mut f,
                    )
                    .unwrap_or(0);
                    let _ = s.write_all(&f[..k]);
                }
            }
        }
        hellos
    });
    let t0 = Instant::now();
    let c = Client::connect(&Target::Tcp(addr.to_string()));
    let took = t0.elapsed();
    assert!(c.is_ok(), "{:?}", c.err());
    // Connected on the first hello after the boot: hellos repeat every 0.2 s.
    assert!(
        took >= Duration::from_millis(500) && took < Duration::from_millis(800),
        "{took:?}"
    );
    drop(c);
    assert_eq!(robot.join().unwrap_or(0), 1);
}

/// A wrong address (and only that) is marked, so that a caller can say how
/// to give another; a robot that answers in another version is not.
#[test]
fn a_bad_address_is_marked_as_one() {
    let bad = |t: &Target| match Client::connect(t) {
        Ok(_) => panic!("connected to {t}"),
        Err(e) => e.chain().any(|c| c.is::<hopper_link::BadAddress>()),
    };
    assert!(bad(&Target::Tcp("no-port-here".into())));
    assert!(bad(&Target::Tcp("127.0.0.1:99999".into())));
    assert!(bad(&Target::Serial("/dev/no-such-hopper".into(), 921_600)));
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
    assert!(!bad(&Target::Tcp(addr.to_string())));
    let _ = robot.join();
}
