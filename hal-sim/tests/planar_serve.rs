//! `hopper-sim planar serve`: the planar machine run live and drawn in a
//! browser. The page carries the drawing; the frames it is fed are those
//! of the recorded run (`planar run --out`'s run.html: the same loop),
//! paced by the wall clock; the run's end is reported.

// Test helpers may panic on impossible setup errors: that is a failed test.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The server, killed when dropped.
struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `GET path` on `addr`: the status line and the body.
fn get(addr: &str, path: &str) -> (String, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut text = String::new();
    s.read_to_string(&mut text).unwrap();
    let (head, body) = text.split_once("\r\n\r\n").unwrap();
    (head.lines().next().unwrap().to_string(), body.to_string())
}

const RUN: [&str; 4] = ["--speed-profile", "0:0.5", "--duration", "4"];

#[test]
fn the_live_page_draws_the_recorded_runs_frames_paced_by_the_clock() {
    let mut child = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args([
            "planar",
            "serve",
            "--http",
            "127.0.0.1:0",
            "--time-scale",
            "4",
        ])
        .args(RUN)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let started = Instant::now();
    let _served = Served(child);
    // "planar: http://127.0.0.1:PORT/ (...)"
    let addr = line
        .split("http://")
        .nth(1)
        .and_then(|r| r.split('/').next())
        .unwrap_or_else(|| panic!("no address in {line:?}"))
        .to_string();

    let (status, page) = get(&addr, "/");
    assert!(status.contains("200"), "{status}");
    assert!(page.contains("function drawPlanar(svg, f)"), "{page}");
    assert!(page.contains("id=\"p-hip\""));

    let (mut frames, mut strides) = (Vec::new(), 0);
    let done = loop {
        assert!(started.elapsed() < Duration::from_secs(60), "no end");
        let (_, body) = get(
            &addr,
            &format!("/frames?from={}&strides={strides}", frames.len()),
        );
        let v: serde_json::Value = serde_json::from_str(&body).unwrap();
        let new = v["frames"].as_array().unwrap();
        strides += v["strides"].as_array().unwrap().len();
        frames.extend(new.iter().cloned());
        if let Some(d) = v["done"].as_str() {
            if new.is_empty() {
                break d.to_string();
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    // 4 s at four times real time: not all at once.
    assert!(started.elapsed() >= Duration::from_millis(900));
    assert!(done.starts_with("ran 4.0 s"), "{done}");
    assert!(strides >= 5, "{strides} strides");
    assert_eq!(frames.len(), 400);
    // Both phases drawn, and the command after the drawing's seven.
    let stance: Vec<f64> = frames.iter().map(|f| f[6].as_f64().unwrap()).collect();
    assert!(stance.contains(&0.0) && stance.contains(&1.0));
    assert!(frames.iter().all(|f| f[7].as_f64() == Some(0.5)));

    // The recorded run's frames, the same numbers.
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
        .args(["planar", "run", "--controller", "raibert", "--out"])
        .arg(dir.path())
        .args(RUN)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let html = std::fs::read_to_string(dir.path().join("run.html")).unwrap();
    let recorded = html
        .split("const F = ")
        .nth(1)
        .and_then(|r| r.split(";\n").next())
        .unwrap();
    let recorded: Vec<Vec<f64>> = serde_json::from_str(recorded).unwrap();
    let live: Vec<Vec<f64>> = frames
        .iter()
        .map(|f| {
            f.as_array().unwrap()[..7]
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        })
        .collect();
    assert_eq!(live, recorded);
}

#[test]
fn a_bad_time_scale_or_address_is_refused_naming_it() {
    for (args, flag) in [
        (
            &["--http", "127.0.0.1:0", "--time-scale", "0"][..],
            "--time-scale",
        ),
        (&["--http", "nowhere"][..], "--http"),
        (
            &["--http", "127.0.0.1:0", "--duration", "700"][..],
            "--duration",
        ),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_hopper-sim"))
            .args(["planar", "serve"])
            .args(args)
            .output()
            .unwrap();
        assert!(!o.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(flag), "{args:?}: {err}");
    }
}
