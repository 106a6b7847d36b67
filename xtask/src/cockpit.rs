//! `cargo xtask cockpit` (part of `cargo xtask test`): the operator's web
//! cockpit (`hopper-link ui`) in a real browser, Debian's chromium
//! headless (installed when missing), against `hopper-sim serve`. Driven
//! through the Chrome DevTools protocol as an operator would: the page
//! loads and shows the robot disarmed, the plotted values move between two
//! reads, Arm shows armed, the machine's drawing follows the hops (its
//! body at many heights, its leg on the ground and off it), an out-of-range set shows the refusal, the
//! Escape key disarms while a parameter box has the focus, a Disarm
//! answers within 50 ms while five more tabs read and set parameters, a
//! page closed while armed disarms the robot (the operator deadman), and
//! a robot lost in the middle of a recording leaves the recording whole
//! and the page up. Prints one line `cockpit: loaded=... moved=...
//! arm=... refused=... disarm=... disarm_ms_p99=N escape_in_input=...
//! page_closed=... robot_lost=...` and leaves a screenshot in
//! `target/cockpit/cockpit.png`. Then, in the same browser, the planar
//! machine behind the link (`hopper-sim planar serve --tcp`) in the
//! cockpit: disarmed, Arm lets it go, its hip drawn at many heights and its
//! leg on the ground and off it within a second, recorded meanwhile
//! (planar.csv, planar.png), Disarm stops it; prints `cockpit-planar:
//! drawn_heights=N drawn_phases=2 armed="armed" disarmed="disarmed
//! (command)" recorded_files=2` and leaves `target/cockpit/planar.png`.

use std::collections::BTreeSet;
use std::io::Read;
use std::net::TcpStream;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::session::{free_addr, host_binaries, Reaped};

/// How long each step may take to show on the page.
const STEP_TIMEOUT: Duration = Duration::from_secs(20);

/// A Disarm's answer under load, 99th percentile, ms at most.
const DISARM_MS_P99_BOUND: f64 = 50.0;

/// Run in the page: five more websockets (tabs) each read the parameter
/// table and set `target_apex_m` again as soon as their last answer came,
/// and send bursts that wait for nothing (three commands every 100 ms:
/// more than the link can serve, so the cockpit refuses some as busy);
/// this one disarms 40 times, 25 ms apart, each timed from its send to
/// its answer. Resolves to JSON `{p99, median, max, n, load, busy}` (ms).
const DISARM_UNDER_LOAD: &str = r#"(async () => {
  const url = `ws://${location.host}/ws`;
  const open = () => new Promise(r => { const w = new WebSocket(url); w.onopen = () => r(w); });
  let load = 0, busy = 0, on = true;
  const tabs = [];
  for (let k = 0; k < 5; k++) {
    const w = await open();
    let i = 0;
    const next = () => { if (!on) return; i++; load++;
      w.send(JSON.stringify(i % 2 ? { cmd: 'params', id: 1000000 + i } : { cmd: 'set', name: 'target_apex_m', value: '0.10', id: 1000000 + i })); };
    w.onmessage = ev => { const m = JSON.parse(ev.data); if (m.type === 'result') { if (m.text.startsWith('refused: the cockpit has')) busy++; else next(); } };
    next(); tabs.push(w);
    // And bursts that wait for nothing: three commands every 100 ms.
    const burst = setInterval(() => { if (!on) return clearInterval(burst);
      for (let b = 0; b < 3; b++) { load++; w.send(JSON.stringify(b % 2 ? { cmd: 'params', id: 2000000 + b } : { cmd: 'set', name: 'target_apex_m', value: '0.10', id: 2000000 + b })); } }, 100);
  }
  const me = await open();
  const waiting = {};
  me.onmessage = ev => { const m = JSON.parse(ev.data); if (m.type === 'result' && waiting[m.id]) { waiting[m.id](); delete waiting[m.id]; } };
  await new Promise(r => setTimeout(r, 500));
  const times = [];
  for (let i = 0; i < 40; i++) {
    const id = 5000000 + i, t0 = performance.now();
    await new Promise(r => { waiting[id] = r; me.send(JSON.stringify({ cmd: 'disarm', id })); });
    times.push(performance.now() - t0);
    await new Promise(r => setTimeout(r, 25));
  }
  on = false; for (const w of tabs) w.close(); me.close();
  const raw = times.map(t => Math.round(t * 10) / 10);
  times.sort((a, b) => a - b);
  return JSON.stringify({ p99: times[Math.ceil(0.99 * times.length) - 1], median: times[times.length >> 1], max: times[times.length - 1], n: times.length, load, busy, raw });
})()"#;

type Socket = tungstenite::WebSocket<TcpStream>;

/// The DevTools protocol on one page.
struct Page {
    ws: Socket,
    next_id: u64,
}

impl Page {
    /// Calls `method`; its result.
    fn call(
        &mut self,
        method: &str,
        params: serde_json::Value,
    ) -> Result<serde_json::Value, String> {
        self.next_id += 1;
        let id = self.next_id;
        let msg = serde_json::json!({ "id": id, "method": method, "params": params });
        self.ws
            .send(tungstenite::Message::text(msg.to_string()))
            .map_err(|e| format!("DevTools: {e}"))?;
        let end = Instant::now() + STEP_TIMEOUT;
        while Instant::now() < end {
            match self.ws.read() {
                Ok(tungstenite::Message::Text(t)) => {
                    let v: serde_json::Value = serde_json::from_str(t.as_str()).unwrap_or_default();
                    if v["id"] == id {
                        return Ok(v["result"].clone());
                    }
                }
                Ok(_) => {}
                Err(tungstenite::Error::Io(e))
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) => {}
                Err(e) => return Err(format!("DevTools: {e}")),
            }
        }
        Err(format!("DevTools: no answer to {method}"))
    }

    /// The page as it shows now, to a PNG file at `path`.
    fn screenshot(&mut self, path: &Path) -> Result<(), String> {
        let shot = self.call(
            "Page.captureScreenshot",
            serde_json::json!({ "format": "png" }),
        )?;
        let png = data_encoding::BASE64
            .decode(shot["data"].as_str().unwrap_or_default().as_bytes())
            .map_err(|e| format!("the screenshot: {e}"))?;
        std::fs::write(path, png).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The value of the page's JavaScript `expr`.
    fn eval(&mut self, expr: &str) -> Result<serde_json::Value, String> {
        let r = self.call(
            "Runtime.evaluate",
            serde_json::json!({ "expression": expr, "returnByValue": true }),
        )?;
        Ok(r["result"]["value"].clone())
    }

    /// The value the page's JavaScript promise `expr` resolves to.
    fn eval_async(&mut self, expr: &str) -> Result<serde_json::Value, String> {
        let r = self.call(
            "Runtime.evaluate",
            serde_json::json!({ "expression": expr, "returnByValue": true, "awaitPromise": true }),
        )?;
        Ok(r["result"]["value"].clone())
    }

    /// Waits until `expr` (a string) satisfies `ok`; its last value.
    fn until(&mut self, expr: &str, ok: impl Fn(&str) -> bool) -> Result<String, String> {
        let end = Instant::now() + STEP_TIMEOUT;
        loop {
            let v = self.eval(expr)?;
            let s = v.as_str().unwrap_or_default().to_string();
            if ok(&s) {
                return Ok(s);
            }
            if Instant::now() > end {
                return Err(format!("the page never showed it: `{expr}` is `{s}`"));
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

/// The page's DevTools socket address, from chromium's `/json` list.
fn debugger_url(port: u16) -> Result<String, String> {
    let end = Instant::now() + STEP_TIMEOUT;
    while Instant::now() < end {
        if let Ok(mut s) = TcpStream::connect(("127.0.0.1", port)) {
            use std::io::Write;
            // (It may keep the connection open: read what came in a second.)
            let _ = s.set_read_timeout(Some(Duration::from_secs(1)));
            let _ = s.write_all(
                format!("GET /json HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n").as_bytes(),
            );
            let mut bytes = Vec::new();
            let mut buf = [0u8; 4096];
            while let Ok(n) = s.read(&mut buf) {
                if n == 0 {
                    break;
                }
                bytes.extend_from_slice(&buf[..n]);
                if bytes.ends_with(b"]\n") || bytes.ends_with(b"]") {
                    break;
                }
            }
            let body = String::from_utf8_lossy(&bytes);
            if let Some(json) = body.split("\r\n\r\n").nth(1) {
                let v: serde_json::Value = serde_json::from_str(json).unwrap_or_default();
                if let Some(url) = v
                    .as_array()
                    .and_then(|a| a.iter().find(|p| p["type"] == "page"))
                    .and_then(|p| p["webSocketDebuggerUrl"].as_str())
                {
                    return Ok(url.to_string());
                }
            }
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    Err("chromium did not open its DevTools port".into())
}

/// `cargo xtask cockpit`.
pub fn run(root: &Path) -> Result<(), String> {
    crate::qemu::ensure_package("chromium", "chromium", true)?;
    let (link, sim) = host_binaries(root)?;
    let started = Instant::now();
    let out_dir = crate::target_dir(root)?.join("cockpit");
    std::fs::create_dir_all(&out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    // The robot: the default virtual robot (no homing or tare needed), the
    // shaped controller.
    let robot = free_addr()?;
    let recordings = out_dir.join("recordings");
    let _ = std::fs::remove_dir_all(&recordings);
    let mut serve = Reaped(
        Command::new(&sim)
            .args(["serve", "--tcp", &robot, "--start-apex", "0.05"])
            .args(["--controller", "shaped", "--target-apex", "0.10"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start hopper-sim serve: {e}"))?,
    );
    crate::session::wait_listening(&robot)?;
    let (_ui, url) = cockpit(&link, &robot, &recordings)?;
    let port = free_addr()?
        .rsplit(':')
        .next()
        .and_then(|p| p.parse::<u16>().ok())
        .ok_or("no free port")?;
    let profile = out_dir.join("profile");
    let _browser = Reaped(
        Command::new("chromium")
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--hide-scrollbars",
                "--no-first-run",
                "--window-size=1400,860",
            ])
            .arg(format!("--remote-debugging-port={port}"))
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg(&url)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start chromium: {e}"))?,
    );
    eprintln!("xtask: cockpit: {url} in chromium (DevTools on port {port})");
    let ws_url = debugger_url(port)?;
    eprintln!("xtask: cockpit: DevTools {ws_url}");
    let addr = ws_url
        .trim_start_matches("ws://")
        .split('/')
        .next()
        .unwrap_or_default()
        .to_string();
    let stream = TcpStream::connect(&addr).map_err(|e| format!("DevTools {addr}: {e}"))?;
    let (ws, _) =
        tungstenite::client(ws_url.as_str(), stream).map_err(|e| format!("DevTools: {e}"))?;
    let _ = ws
        .get_ref()
        .set_read_timeout(Some(Duration::from_millis(200)));
    let mut page = Page { ws, next_id: 0 };
    let state = "document.getElementById('armstate').textContent";
    let message = "document.getElementById('message').textContent";
    // Loaded: the state from the robot, the parameter table.
    let loaded = page.until(state, |s| s.starts_with("disarmed"))?;
    page.until(
        "String(document.querySelectorAll('#rows tr').length)",
        |s| s.parse::<u32>().is_ok_and(|n| n > 50),
    )?;
    // The plotted values move between two reads.
    let read = "String(series.t.length) + ' ' + String(series.body[series.body.length - 1])";
    let first = page.until(read, |s| !s.starts_with("0 "))?;
    std::thread::sleep(Duration::from_millis(500));
    let second = page.eval(read)?.as_str().unwrap_or_default().to_string();
    let moved = first != second;
    // The first bring-up step, as the guide offers it: its result shown.
    page.eval("document.querySelector('#steps button[data-step=\"0\"]').click(), ''")?;
    let bringup = page.until(message, |s| s.starts_with("calibrate sensors"))?;
    page.until("document.querySelector('#steps pre').textContent", |s| {
        s.contains("samples")
    })?;
    // Arm, as the operator clicks it.
    page.eval("document.getElementById('arm').click(), ''")?;
    let armed = page.until(state, |s| s == "armed")?;
    // Hopping: the hop ledger fills its table.
    let ledger = page.until(
        "String(document.querySelectorAll('#ledger tr').length)",
        |s| s.parse::<u32>().is_ok_and(|n| n >= 3),
    )?;
    // The machine drawn as it hops: over a second, the body's box at many
    // heights, and the leg drawn on the ground (red) and off it.
    let (heights, phases) = sample_drawing(
        &mut page,
        "document.getElementById('m-body').getAttribute('y') + ' ' + \
         (document.getElementById('m-leg').getAttribute('class') || 'flight')",
    )?;
    let drawn = format!(
        "drawn_heights={} drawn_phases={}",
        heights.len(),
        phases.len()
    );
    let drawn_ok = heights.len() >= 10 && phases.len() == 2;
    // Record a second of it into a folder.
    page.eval("document.getElementById('record').click(), ''")?;
    page.until("document.getElementById('recording').textContent", |s| {
        s.contains("recording-1")
    })?;
    std::thread::sleep(Duration::from_secs(1));
    page.eval("document.getElementById('record').click(), ''")?;
    let recorded = page.until(message, |s| s.starts_with("recorded"))?;
    let folder = recordings.join("recording-1");
    let files = ["telemetry.csv", "hops.csv", "telemetry.mcap", "hop.png"]
        .iter()
        .filter(|f| folder.join(f).is_file())
        .count();
    // An out-of-range set, typed into the table.
    page.eval(
        "(() => { const i = document.querySelector('input[data-name=\"target_apex_m\"]'); \
         i.value = '2.0'; i.dispatchEvent(new KeyboardEvent('keydown', { key: 'Enter' })); return ''; })()",
    )?;
    let refused = page.until(message, |s| s.contains("refused"))?;
    page.screenshot(&out_dir.join("cockpit.png"))?;
    // Disarm by its key, typed into a parameter box that has the focus.
    page.eval(
        "(() => { const i = document.querySelector('input[data-name=\"target_apex_m\"]'); i.focus(); \
         i.dispatchEvent(new KeyboardEvent('keydown', { key: 'Escape', bubbles: true })); return ''; })()",
    )?;
    let disarmed = page
        .until(state, |s| s.starts_with("disarmed"))
        .unwrap_or_else(|e| {
            // (Disarmed by its button then, to go on.)
            let _ = page.eval("document.getElementById('disarm').click(), ''");
            format!("still armed: {e}")
        });
    let escape_in_input = if disarmed == "disarmed (command)" {
        "disarmed"
    } else {
        "armed"
    };
    // The capture of the latest periods, plotted on demand.
    page.eval("document.getElementById('capture-button').click(), ''")?;
    let captured = page.until(message, |s| s.starts_with("capture:"))?;
    let plotted = page
        .until(
            "String(document.getElementById('capture-png').src.length)",
            |s| s.parse::<usize>().is_ok_and(|n| n > 1000),
        )
        .is_ok()
        && recordings.join("capture-1").join("capture.png").is_file();
    // The simulated robot's hoist from the bring-up panel, and the save
    // that ends the sequence.
    page.eval("document.getElementById('hoist').click(), ''")?;
    let hoist = page.until(message, |s| s.starts_with("mount:"))?;
    page.eval("document.getElementById('release').click(), ''")?;
    page.until(message, |s| s.starts_with("mount: release"))?;
    page.eval("document.querySelector('#steps button[data-step=\"8\"]').click(), ''")?;
    let save = page.until(message, |s| s.starts_with("save"))?;
    eprintln!("xtask: cockpit: {hoist}; {save} (only the sensors checked)");
    // The page with the capture, for a look.
    page.screenshot(&out_dir.join("cockpit-capture.png"))?;
    // Disarm under load: five more tabs each read the table and set a
    // parameter again as soon as the last answer came, and in bursts;
    // meanwhile this one disarms 40 times, each timed from its send to
    // its answer.
    let load = page.eval_async(DISARM_UNDER_LOAD).unwrap_or_else(|e| {
        eprintln!("xtask: cockpit: disarm under load: {e}");
        serde_json::Value::Null
    });
    let load: serde_json::Value =
        serde_json::from_str(load.as_str().unwrap_or_default()).unwrap_or_default();
    let disarm_ms_p99 = load["p99"].as_f64().unwrap_or(f64::INFINITY);
    eprintln!(
        "xtask: cockpit: disarm under load: {} disarms, median {:.1} ms, p99 {disarm_ms_p99:.1} ms, max {:.1} ms, while five tabs sent {} reads and sets ({} refused as busy)",
        load["n"], load["median"].as_f64().unwrap_or(f64::NAN), load["max"].as_f64().unwrap_or(f64::NAN), load["load"], load["busy"]
    );
    eprintln!("xtask: cockpit: each disarm, ms, in order: {}", load["raw"]);
    // The operator deadman: armed, the page closed, opened again.
    let closed = (|| -> Result<(String, String, String), String> {
        page.eval("document.getElementById('arm').click(), ''")?;
        page.until(message, |s| s == "armed" || s.starts_with("arm refused"))?;
        let rearmed = page.until(state, |s| s == "armed")?;
        page.call("Page.navigate", serde_json::json!({ "url": "about:blank" }))?;
        std::thread::sleep(Duration::from_millis(1500));
        page.call("Page.navigate", serde_json::json!({ "url": url }))?;
        let after = page.until(state, |s| s.starts_with("disarmed") || s == "armed")?;
        let note = page.until("document.getElementById('note').textContent", |_| true)?;
        Ok((rearmed, after, note))
    })();
    let page_closed = match &closed {
        Ok((rearmed, after, note))
            if rearmed == "armed"
                && after.starts_with("disarmed")
                && note.contains("operator page closed") =>
        {
            "disarmed"
        }
        _ => "armed",
    };
    eprintln!("xtask: cockpit: armed, the page closed for 1.5 s, opened again: {closed:?}");
    // The robot lost in the middle of a recording.
    let lost = (|| -> Result<(String, String), String> {
        page.eval("document.getElementById('record').click(), ''")?;
        page.until("document.getElementById('recording').textContent", |s| {
            s.contains("recording-2")
        })?;
        std::thread::sleep(Duration::from_secs(1));
        let _ = serve.0.kill();
        let _ = serve.0.wait();
        let lost = page.until(message, |s| s.starts_with("the robot was lost;"))?;
        let lost_state = page.eval(state)?.as_str().unwrap_or_default().to_string();
        Ok((lost, lost_state))
    })();
    let (lost, lost_state) = lost.unwrap_or_else(|e| (e, String::new()));
    let folder2 = recordings.join("recording-2");
    let lost_files = ["telemetry.csv", "hops.csv", "telemetry.mcap", "hop.png"]
        .iter()
        .filter(|f| folder2.join(f).is_file())
        .count();
    let robot_lost = if lost_files == 4 && lost.contains("recorded") && lost_state == "robot lost" {
        "recording_complete"
    } else {
        "recording_lost"
    };
    eprintln!(
        "xtask: cockpit: the robot killed while recording: the page shows `{lost_state}`; {lost}"
    );
    // The planar machine drawn live, in the same browser.
    let (planar, planar_ok) = planar_drawn(&mut page, &sim, &link, &out_dir)
        .unwrap_or_else(|e| (format!("cockpit-planar: error: {e}"), false));
    eprintln!(
        "xtask: cockpit: {:.1} s in chromium; the screenshot: {}",
        started.elapsed().as_secs_f64(),
        out_dir.join("cockpit.png").display()
    );
    let ok = loaded == "disarmed (boot)"
        && disarm_ms_p99 <= DISARM_MS_P99_BOUND
        && escape_in_input == "disarmed"
        && page_closed == "disarmed"
        && robot_lost == "recording_complete"
        && moved
        && drawn_ok
        && ledger.parse::<u32>().is_ok_and(|n| n >= 3)
        && armed == "armed"
        && refused.contains("refused: out-of-range")
        && disarmed == "disarmed (command)"
        && bringup == "calibrate sensors: done"
        && files == 4
        && plotted
        && hoist.starts_with("mount: hoist")
        && save == "save refused: not-calibrated";
    println!(
        "cockpit: loaded=\"{loaded}\" moved={moved} arm=\"{armed}\" ledger_rows={ledger} refused=\"{refused}\" disarm=\"{disarmed}\" bringup=\"{bringup}\" recorded_files={files} capture_plotted={plotted} disarm_ms_p99={disarm_ms_p99:.1} escape_in_input={escape_in_input} page_closed={page_closed} robot_lost={robot_lost} {drawn}"
    );
    println!("{planar}");
    eprintln!("xtask: cockpit: {recorded}");
    eprintln!("xtask: cockpit: {captured}");
    if ok && planar_ok {
        Ok(())
    } else {
        Err("the cockpit did not show what it should (the line above)".into())
    }
}

/// `hopper-link ui` on the robot at `robot`, recording into
/// `recordings`: the cockpit (killed when dropped) and its address.
fn cockpit(link: &Path, robot: &str, recordings: &Path) -> Result<(Reaped, String), String> {
    crate::session::spawn_server(
        Command::new(link)
            .args([
                "--tcp",
                robot,
                "ui",
                "--http",
                "127.0.0.1:0",
                "--record-dir",
            ])
            .arg(recordings),
        "hopper-link ui",
        "cockpit: ",
    )
}

/// Over a second, `expr` (the drawing's `HEIGHT PHASE`) read 40 times
/// in `page`: the heights and the phases it showed.
fn sample_drawing(
    page: &mut Page,
    expr: &str,
) -> Result<(BTreeSet<String>, BTreeSet<String>), String> {
    let mut heights = BTreeSet::new();
    let mut phases = BTreeSet::new();
    for _ in 0..40 {
        let v = page.eval(expr)?;
        if let Some((y, phase)) = v.as_str().unwrap_or_default().split_once(' ') {
            heights.insert(y.to_string());
            phases.insert(phase.to_string());
        }
        std::thread::sleep(Duration::from_millis(25));
    }
    Ok((heights, phases))
}

/// The planar machine behind the link (`hopper-sim planar serve --tcp`)
/// in the cockpit (`hopper-link ui`), opened in `page`: disarmed at first,
/// armed as the operator clicks it, then within a second the hip drawn at
/// many heights and the leg on the ground and off it, and disarmed again
/// by the Disarm button; the page saved as `planar.png` in `out_dir`.
/// The summary line `cockpit-planar: drawn_heights=N drawn_phases=N
/// armed=".." disarmed=".."` and whether it passes.
fn planar_drawn(
    page: &mut Page,
    sim: &Path,
    link: &Path,
    out_dir: &Path,
) -> Result<(String, bool), String> {
    let (_served, robot) = crate::session::spawn_server(
        Command::new(sim)
            .args(["planar", "serve", "--tcp", "127.0.0.1:0"])
            .args(["--speed-profile", "0:0.5", "--duration", "120"]),
        "hopper-sim planar serve --tcp",
        "listening on ",
    )?;
    let recordings = out_dir.join("planar-recordings");
    let _ = std::fs::remove_dir_all(&recordings);
    let (_ui, url) = cockpit(link, &robot, &recordings)?;
    page.call("Page.navigate", serde_json::json!({ "url": url }))?;
    let state = "document.getElementById('armstate').textContent";
    page.until(state, |s| s.starts_with("disarmed"))?;
    page.until(
        "document.querySelector('#planar #p-hip') ? 'drawn' : 'not yet'",
        |s| s == "drawn",
    )?;
    page.eval("document.getElementById('arm').click(), ''")?;
    let armed = page.until(state, |s| s == "armed")?;
    // Let go, it lands and hops: the first stance comes within 0.3 s.
    std::thread::sleep(Duration::from_millis(500));
    // Recorded while it is drawn.
    page.eval("document.getElementById('record').click(), ''")?;
    page.until("document.getElementById('recording').textContent", |s| {
        s.contains("recording-1")
    })?;
    let (heights, phases) = sample_drawing(
        page,
        "document.querySelector('#planar #p-hip').getAttribute('cy') + ' ' + \
         document.querySelector('#planar #p-leg').getAttribute('class')",
    )?;
    let info = page.eval("document.getElementById('m-text').textContent")?;
    eprintln!(
        "xtask: cockpit: the planar machine at {robot} in the cockpit {url}: {}",
        info.as_str().unwrap_or_default()
    );
    page.screenshot(&out_dir.join("planar.png"))?;
    page.eval("document.getElementById('record').click(), ''")?;
    let message = "document.getElementById('message').textContent";
    let recorded = page.until(message, |s| s.starts_with("recorded"))?;
    eprintln!("xtask: cockpit: {recorded}");
    let folder = recordings.join("recording-1");
    let files = ["planar.csv", "planar.png"]
        .iter()
        .filter(|f| folder.join(f).is_file())
        .count();
    page.eval("document.getElementById('disarm').click(), ''")?;
    let disarmed = page.until(state, |s| s.starts_with("disarmed ("))?;
    Ok((
        format!(
            "cockpit-planar: drawn_heights={} drawn_phases={} armed=\"{armed}\" disarmed=\"{disarmed}\" recorded_files={files}",
            heights.len(),
            phases.len()
        ),
        heights.len() >= 10
            && phases.len() == 2
            && armed == "armed"
            && disarmed == "disarmed (command)"
            && files == 2,
    ))
}
