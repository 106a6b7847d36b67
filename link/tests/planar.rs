//! `hopper-link` against the planar machine's firmware end of the link
//! (`hopper_robot_link::planar::PlanarPort` over its period), standing
//! upright on the boom: `status` shows the machine, `arm` and `disarm`
//! work, `record` writes its records, and what only the vertical hopper
//! has is refused by name.

use hopper_control::arming::ArmingConfig;
use hopper_control::planar::estimator::PlanarReadings;
use hopper_control::planar::period::PlanarPeriod;
use hopper_control::planar::raibert::RaibertConfig;
use hopper_control::planar::{HipDrive, TABLE_2_2_LEG_LENGTH_M};
use hopper_robot_link::planar::PlanarPort;
use hopper_robot_link::Tx;
use std::io::{ErrorKind, Read, Write};
use std::net::TcpListener;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

const DT_S: f32 = 1e-4;

struct Bytes(Vec<u8>);
impl Tx for Bytes {
    fn room(&self) -> usize {
        16_384usize.saturating_sub(self.0.len())
    }
    fn put(&mut self, frame: &[u8]) {
        self.0.extend_from_slice(frame);
    }
}

/// The planar machine's firmware standing upright, its periods paced by
/// the wall clock, serving `connections` connections one after another
/// (20 s at most).
fn planar_robot(connections: usize) -> (String, std::thread::JoinHandle<()>) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let addr = l.local_addr().unwrap_or_else(|e| panic!("{e}")).to_string();
    let serve = std::thread::spawn(move || {
        let mut period = PlanarPeriod::new(
            RaibertConfig::table_2_2(),
            TABLE_2_2_LEG_LENGTH_M,
            HipDrive::design(),
            false,
        )
        .unwrap_or_else(|e| panic!("{e:?}"));
        let mut port = PlanarPort::new(ArmingConfig::default(), DT_S, true)
            .unwrap_or_else(|e| panic!("{e:?}"));
        let standing = PlanarReadings {
            boom_z_m: 0.64,
            leg_length_m: 0.64,
            ..PlanarReadings::default()
        };
        let start = Instant::now();
        let mut done = 0u64;
        for _ in 0..connections {
            let Ok((mut s, _)) = l.accept() else { return };
            let _ = s.set_nonblocking(true);
            let mut tx = Bytes(Vec::new());
            let mut buf = [0u8; 4096];
            loop {
                if start.elapsed() > Duration::from_secs(20) {
                    return;
                }
                let rx = match s.read(&mut buf) {
                    Ok(0) => break,
                    Ok(n) => buf[..n].to_vec(),
                    Err(e) if e.kind() == ErrorKind::WouldBlock => Vec::new(),
                    Err(_) => break,
                };
                port.receive(rx, &mut tx);
                let due = (start.elapsed().as_secs_f64() / f64::from(DT_S)) as u64;
                while done < due {
                    port.period(&mut period, &standing, 0.0, DT_S, &mut tx);
                    done += 1;
                }
                if s.write_all(&tx.0).is_err() {
                    break;
                }
                tx.0.clear();
                std::thread::sleep(Duration::from_millis(1));
            }
        }
    });
    (addr, serve)
}

fn hopper_link(addr: &str, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_hopper-link"))
        .args(["--tcp", addr])
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cannot run hopper-link: {e}"))
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn hopper_link_runs_the_planar_machine() {
    let (addr, serve) = planar_robot(5);
    let o = hopper_link(&addr, &["status"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("state: disarmed (boot)"), "{t}");
    assert!(t.contains("the planar machine's guard: none"), "{t}");
    assert!(
        t.contains("planar machine: hip at x 0.000 m, height 0.6400 m, pitch 0.00 deg"),
        "{t}"
    );
    assert!(t.contains("hip 0.00 A, leg 0.00 A"), "{t}");

    let o = hopper_link(&addr, &["arm"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout), "armed\n");

    let o = hopper_link(&addr, &["disarm"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("armed false, hip 0.000 A, leg 0.000 A"), "{t}");

    let o = hopper_link(&addr, &["calibrate", "sensors"]);
    let t = text(&o);
    assert!(!o.status.success(), "{t}");
    assert!(
        t.contains("calibrate sensors refused: not-on-this-machine"),
        "{t}"
    );
    // A recording: the machine's records, numbered without a gap, and
    // their plot.
    let dir = std::env::temp_dir().join(format!("planar-record-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let o = hopper_link(
        &addr,
        &[
            "record",
            "--duration",
            "0.5",
            "--out",
            &dir.to_string_lossy(),
        ],
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains("of the planar machine: 501 records at 1000 Hz, 0 dropped"),
        "{t}"
    );
    let csv = std::fs::read_to_string(dir.join("planar.csv")).unwrap_or_default();
    assert_eq!(csv.lines().count(), 502, "{csv}");
    assert!(csv.starts_with("t_s,x_m,z_m,pitch_rad,"));
    assert!(dir.join("planar.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
    let _ = serve.join();
}
