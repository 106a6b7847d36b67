//! `cargo xtask hil`: the hardware-in-the-loop image (`hopper-hil`) closes
//! the loop on the host's simulated hopper.
//!
//! 1. builds `hopper-hil` (the board image's firmware, its sensors the
//!    host's models);
//! 2. runs it on QEMU's netduinoplus2 with USART1 on a TCP socket (or, with
//!    `--serial PORT`, on a board), and `hopper-sim run --hil` against it on
//!    [`SCENARIO`];
//! 3. runs the same scenario on the host (`hopper-sim run`) and compares
//!    the apexes (the golden check: within [`GOLDEN_TOLERANCE_M`]);
//! 4. on QEMU, runs it again through a relay that drops one of the host's
//!    frames: the run must stop with its error and write nothing;
//! 5. prints `hil: apexes=N max_diff_m=X frames_per_s=Y isr_max=Z`.

use std::io::{Read, Write};
use std::net::{Shutdown, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use crate::session::{free_addr, wait_listening, Reaped};
use crate::{cargo, TARGET};

/// The scenario both runs take (the QEMU scenario image's, declared once
/// in `scenarios/`), shortened to [`DURATION_S`]: a HIL run on QEMU is
/// slower than real time.
const SCENARIO: &str = "scenarios/qemu/energy-apex.toml";
/// Simulated seconds of the HIL run.
const DURATION_S: &str = "2";

/// Largest |host apex - HIL apex| accepted, m. The plant and the sensor
/// models (and their noise) run on the host in both runs; only the control
/// period runs on the MCU, whose `f32` arithmetic and `libm` are the
/// host's, so the runs agree to the bit unless the target rounds
/// differently somewhere.
const GOLDEN_TOLERANCE_M: f64 = 1e-4;

/// The host frame the drop test loses (frame 0 is the hello): a sample
/// of the run (configuring and arming take about 2,300 frames).
const DROPPED_FRAME: u64 = 3_000;

/// The HIL image, built (board features, into the default target
/// directory next to the board image).
fn hil_image(root: &Path) -> Result<PathBuf, String> {
    crate::ensure_flip_link(root)?;
    crate::build_executable(
        root,
        "firmware build (HIL image)",
        "hopper-hil",
        cargo().args([
            "build",
            "-p",
            "hopper-app",
            "--bin",
            "hopper-hil",
            "--release",
            "--target",
            TARGET,
        ]),
    )
}

/// The HIL image on QEMU, USART1 on a TCP server at the returned address.
fn start_qemu(elf: &Path) -> Result<(Reaped, String), String> {
    let addr = free_addr()?;
    eprintln!("xtask: running the HIL image on qemu-system-arm, USART1 on tcp {addr}");
    // `nodelay`: one small frame each way per period, each waited for;
    // with Nagle's algorithm against the host's delayed ACK, every
    // period would wait 40 ms.
    let child =
        crate::qemu::qemu_command(elf, 0, &format!("tcp:{addr},server=on,wait=off,nodelay=on"))
            .stdout(Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
    let qemu = Reaped(child);
    wait_listening(&addr)?;
    Ok((qemu, addr))
}

/// `hopper-sim run` on the scenario with `extra` arguments; its JSON
/// summary, or its error text.
fn sim_run(sim: &Path, extra: &[&str]) -> Result<serde_json::Value, String> {
    let out = Command::new(sim)
        .args([
            "run",
            "--scenario",
            SCENARIO,
            "--duration",
            DURATION_S,
            "--json",
        ])
        .args(extra)
        .output()
        .map_err(|e| format!("cannot run hopper-sim: {e}"))?;
    let stderr = String::from_utf8_lossy(&out.stderr).trim().to_string();
    if !out.status.success() {
        return Err(stderr);
    }
    serde_json::from_slice(&out.stdout).map_err(|e| format!("hopper-sim's JSON: {e}"))
}

fn apexes(v: &serde_json::Value) -> Vec<f64> {
    v["apex_heights_m"]
        .as_array()
        .map(|a| a.iter().filter_map(serde_json::Value::as_f64).collect())
        .unwrap_or_default()
}

/// Relays one connection from a local port to `upstream`, dropping the
/// host's frame number `drop` (frames end at a 0 byte; a lone delimiter is
/// no frame). Returns the local address.
fn lossy_relay(upstream: String, drop: u64) -> Result<String, String> {
    let listener = TcpListener::bind("127.0.0.1:0").map_err(|e| format!("relay: {e}"))?;
    let addr = listener
        .local_addr()
        .map_err(|e| format!("relay: {e}"))?
        .to_string();
    std::thread::spawn(move || {
        let Ok((host, _)) = listener.accept() else {
            return;
        };
        let Ok(robot) = TcpStream::connect(&upstream) else {
            return;
        };
        let (Ok(mut host_r), Ok(mut robot_w)) = (host.try_clone(), robot.try_clone()) else {
            return;
        };
        // One small frame each way per period, each waited for: no
        // Nagle delay here either.
        let _ = (host.set_nodelay(true), robot.set_nodelay(true));
        let (mut robot_r, mut host_w) = (robot, host);
        std::thread::spawn(move || {
            let _ = std::io::copy(&mut robot_r, &mut host_w);
            let _ = host_w.shutdown(Shutdown::Both);
        });
        let (mut frame, mut index) = (Vec::new(), 0u64);
        let mut buf = [0u8; 512];
        while let Ok(n) = host_r.read(&mut buf) {
            if n == 0 {
                break;
            }
            for &b in &buf[..n] {
                frame.push(b);
                if b != 0 {
                    continue;
                }
                let whole = frame.len() > 1;
                if !(whole && index == drop) && robot_w.write_all(&frame).is_err() {
                    return;
                }
                index += u64::from(whole);
                frame.clear();
            }
        }
        let _ = robot_w.shutdown(Shutdown::Both);
    });
    Ok(addr)
}

/// `cargo xtask hil [--serial PORT]`.
pub fn run(root: &Path, serial: Option<&str>) -> Result<(), String> {
    let result = run_inner(root, serial);
    if result.is_err() {
        println!("hil: error (see above)");
    }
    result
}

fn run_inner(root: &Path, serial: Option<&str>) -> Result<(), String> {
    let elf = hil_image(root)?;
    let (_, sim) = crate::session::host_binaries(root)?;
    let started = Instant::now();
    let host = sim_run(&sim, &[]).map_err(|e| format!("the host run failed: {e}"))?;
    crate::took("HIL: the host run", started);
    let started = Instant::now();
    let hil = match serial {
        Some(port) => sim_run(&sim, &["--hil", "--serial", port]),
        None => {
            crate::qemu::ensure_qemu()?;
            let (qemu, addr) = start_qemu(&elf)?;
            let r = sim_run(&sim, &["--hil", "--tcp", &addr]);
            drop(qemu);
            r
        }
    }
    .map_err(|e| format!("the HIL run failed: {e}"))?;
    crate::took("HIL: the run in the loop", started);
    let (a, b) = (apexes(&host), apexes(&hil));
    let max_diff = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0_f64, f64::max);
    let h = &hil["hil"];
    let fps = h["frames_per_s"].as_f64().unwrap_or(0.0);
    let isr_max = h["isr_max"].as_u64().unwrap_or(0);
    eprintln!(
        "xtask: HIL: {} periods (+{} to configure and arm, {} parameters set), {:.1} B/period out, {:.1} in, {:.0} periods/s ({:.4}x real time); control interrupt mean {:.0}, max {isr_max} {}",
        h["periods"],
        h["setup_periods"],
        h["params_set"],
        h["bytes_out_per_period"].as_f64().unwrap_or(0.0),
        h["bytes_in_per_period"].as_f64().unwrap_or(0.0),
        fps,
        h["realtime_factor"].as_f64().unwrap_or(0.0),
        h["isr_mean"].as_f64().unwrap_or(0.0),
        h["isr_unit"].as_str().unwrap_or("?"),
    );
    let mut problems = Vec::new();
    if a.len() != b.len() || a.is_empty() {
        problems.push(format!(
            "apex counts differ or are zero: host {}, HIL {}",
            a.len(),
            b.len()
        ));
    }
    if max_diff > GOLDEN_TOLERANCE_M {
        problems.push(format!(
            "apexes differ by {max_diff:.2e} m (tolerance {GOLDEN_TOLERANCE_M:.0e} m)"
        ));
    }
    if serial.is_none() {
        let started = Instant::now();
        if let Err(e) = dropped_frame(root, &elf, &sim) {
            problems.push(e);
        }
        crate::took("HIL: the dropped-frame run", started);
    }
    println!(
        "hil: apexes={} max_diff_m={max_diff:.2e} frames_per_s={fps:.0} isr_max={isr_max}",
        b.len()
    );
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!("HIL check failed: {}", problems.join("; ")))
    }
}

/// A HIL run that loses one host frame must stop with an error naming it
/// and leave its output directory unwritten.
fn dropped_frame(root: &Path, elf: &Path, sim: &Path) -> Result<(), String> {
    let (qemu, addr) = start_qemu(elf)?;
    let relay = lossy_relay(addr, DROPPED_FRAME)?;
    let out_dir = crate::target_dir(root)?.join("hil-dropped");
    let _ = std::fs::remove_dir_all(&out_dir);
    let out = out_dir.to_string_lossy().to_string();
    let r = sim_run(
        sim,
        &[
            "--hil",
            "--tcp",
            &relay,
            "--hil-timeout-s",
            "2",
            "--out",
            &out,
        ],
    );
    drop(qemu);
    match r {
        Ok(_) => Err(format!(
            "a HIL run that lost frame {DROPPED_FRAME} did not fail"
        )),
        Err(e) if !e.contains("no answer from the robot for sample") => Err(format!(
            "a HIL run that lost frame {DROPPED_FRAME} failed, but not for the lost frame: {e}"
        )),
        Err(_) if out_dir.exists() => Err(format!(
            "a HIL run that lost a frame left {} behind",
            out_dir.display()
        )),
        Err(e) => {
            eprintln!("xtask: HIL: lost frame {DROPPED_FRAME} stopped the run: {e}");
            Ok(())
        }
    }
}
