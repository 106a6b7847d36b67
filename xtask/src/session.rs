//! The scripted link session (`tests/link-session.txt`), run by
//! the real `hopper-link` binary against a robot: the QEMU link image
//! (`cargo xtask qemu`, the `qemu-link:` line) and `hopper-sim serve` (the
//! `link-sim:` line, in `cargo xtask test`).
//!
//! The session's own `!` lines make refusals part of the script (the
//! client exits with failure if one is accepted, or if any other command
//! fails); on top of that this checks the session's figures:
//! the recorded apexes converge to the target within 2%, the disarm's
//! next record commands 0 A, the link-loss disarm comes within the
//! timeout, garbage on the line is counted and latches no fault, and the
//! link's cost per period is reported.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::{build_executables, cargo};

/// The session's target apex, m (`params set target_apex_m 0.12`).
const TARGET_APEX_M: f64 = 0.12;
/// Convergence tolerance of the recorded apexes (within 2%).
const APEX_TOLERANCE: f64 = 0.02;
/// Apexes at the end of the recording that must all be within tolerance.
const LAST_APEXES: usize = 5;
/// The link timeout the session runs with (the default), s.
const LINK_TIMEOUT_S: f64 = 0.2;
/// How much later than the timeout the disarm may come, s of robot time
/// (measured by the robot: from the period that received the host's last
/// frame to the first disarmed record): one period of rounding.
const LINK_LOST_SLACK_S: f64 = 0.0015;
/// The control interrupt's bound, counter ticks (QEMU: instructions; the
/// host simulator counts 0): read, step, write, publish, one command.
const ISR_BOUND: u64 = 2_000;
/// Wall-clock limit for a session.
const SESSION_TIMEOUT: Duration = Duration::from_secs(600);
/// The virtual robot's speed for the session (robot s per wall s): fast,
/// with the 20 ms heartbeats still well inside the 0.2 s timeout.
const SERVE_SPEED: &str = "3";

/// Kills the child when dropped (a failed check must not leave a server
/// or a QEMU behind).
pub(crate) struct Reaped(pub(crate) Child);

impl Drop for Reaped {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A free TCP port on the loopback (bound, read and let go: QEMU listens
/// on it next).
pub(crate) fn free_addr() -> Result<String, String> {
    let port = TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map_err(|e| format!("no free port: {e}"))?
        .port();
    Ok(format!("127.0.0.1:{port}"))
}

/// Waits up to 20 s for QEMU to listen on `addr` (a probe connection,
/// closed at once: QEMU's server then waits for the next client).
pub(crate) fn wait_listening(addr: &str) -> Result<(), String> {
    let started = Instant::now();
    while TcpStream::connect(addr).is_err() {
        if started.elapsed() > Duration::from_secs(20) {
            return Err(format!("QEMU did not listen on {addr} within 20 s"));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(())
}

/// `hopper-link` and `hopper-sim` as the test suite builds them: `cargo
/// test --workspace --no-run` builds every test and these binaries with
/// the workspace's features (dependencies at opt-level 2), so the suite
/// that runs next builds nothing again; the virtual robot keeps 3x real
/// time in this profile.
pub(crate) fn host_binaries(root: &Path) -> Result<(PathBuf, PathBuf), String> {
    let [link, sim] = build_executables(
        root,
        "workspace test build (and the hopper-link, hopper-sim binaries)",
        ["hopper-link", "hopper-sim"],
        cargo().args(["test", "--workspace", "--no-run"]),
    )?;
    Ok((link, sim))
}

/// `cargo xtask test`'s session against `hopper-sim serve`.
pub fn against_serve(root: &Path) -> Result<(), String> {
    let (link, sim) = host_binaries(root)?;
    let out_dir = crate::target_dir(root)?.join("link-session").join("sim");
    let _ = std::fs::remove_dir_all(&out_dir);
    std::fs::create_dir_all(&out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    // The robot's flash in a file: the session saves its calibration, and
    // the next start of the simulator must load it.
    let flash = out_dir.join("flash.bin");
    let (server, addr) = start_serve(&sim, &flash)?;
    let report = run_session(&link, &addr, &out_dir.join("session"), "link-sim");
    drop(server);
    let report = report.and_then(|mut r| {
        let (server, addr) = start_serve(&sim, &flash)?;
        r.reboot = after_reboot(&link, &addr)?;
        drop(server);
        Ok(r)
    });
    report.map(|r| println!("{}", r.line("link-sim", "ticks")))
}

/// After a restart of the simulator on the saved flash: the calibration
/// loaded, arming refused only for homing.
fn after_reboot(link: &Path, addr: &str) -> Result<String, String> {
    let out = Command::new(link)
        .args(["--tcp", addr, "status"])
        .output()
        .map_err(|e| format!("cannot start hopper-link: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix("calibration: "))
        .unwrap_or("")
        .to_string();
    for l in text.lines() {
        println!("link-sim (restarted)| {l}");
    }
    if !line.starts_with("loaded from flash at boot") {
        return Err(format!(
            "after a restart on the saved flash the calibration is `{line}`, not loaded"
        ));
    }
    let arm = Command::new(link)
        .args(["--tcp", addr, "arm"])
        .output()
        .map_err(|e| format!("cannot start hopper-link: {e}"))?;
    let err = String::from_utf8_lossy(&arm.stderr).to_string();
    println!("link-sim (restarted)| arm: {}", err.trim());
    if !err.contains("arm refused: not-homed") {
        return Err(format!(
            "after a restart on the saved flash arming is not refused for homing only: {}",
            err.trim()
        ));
    }
    Ok("loaded".into())
}

/// `hopper-sim serve` on the session's mis-calibrated robot with its flash
/// in `flash`; the server (killed when dropped) and its address.
fn start_serve(sim: &Path, flash: &Path) -> Result<(Reaped, String), String> {
    eprintln!("xtask: starting hopper-sim serve (virtual robot, {SERVE_SPEED}x real time)");
    let mut cmd = Command::new(sim);
    cmd.args([
        "serve",
        "--tcp",
        "127.0.0.1:0",
        "--speed",
        SERVE_SPEED,
        "--start-apex",
        "0.05",
        // As the board and the QEMU link image: no arming before a tare
        // and homing.
        "--set",
        "arming.require_tare=1",
        "--set",
        "arming.require_home=1",
    ])
    // The mis-calibrated robot of the QEMU link image: the session's
    // bring-up routines must find it.
    .arg("--loadcell-bias-n")
    .arg(MIS.loadcell_bias_n.to_string())
    .arg("--pot-bias-m")
    .arg(MIS.pot_bias_m.to_string())
    .arg("--nut-start-m")
    .arg(MIS.nut_start_m.to_string())
    .arg("--spring-rate-error")
    .arg(MIS.spring_rate_error.to_string())
    .arg("--height-zero-error-m")
    .arg(MIS.height_zero_error_m.to_string())
    .arg("--loadcell-gain-error")
    .arg(MIS.loadcell_gain_error.to_string())
    .arg("--flash")
    .arg(flash);
    spawn_serve(&mut cmd)
}

/// Starts `hopper-sim serve` as `cmd` says; the server (killed when
/// dropped) and the address its first line names.
pub(crate) fn spawn_serve(cmd: &mut Command) -> Result<(Reaped, String), String> {
    spawn_server(cmd, "hopper-sim serve", "listening on ")
}

/// Starts the server `cmd` (`what`, for errors), which prints where it
/// listens on its first line, right after `after`: the server (killed
/// when dropped) and that address. The rest of its output is read and
/// dropped, so the pipe neither closes nor fills.
pub(crate) fn spawn_server(
    cmd: &mut Command,
    what: &str,
    after: &str,
) -> Result<(Reaped, String), String> {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|e| format!("cannot start {what}: {e}"))?;
    let out = child
        .stdout
        .take()
        .ok_or_else(|| format!("no stdout from {what}"))?;
    let server = Reaped(child);
    let mut out = BufReader::new(out);
    let mut first = String::new();
    out.read_line(&mut first)
        .map_err(|e| format!("{what}: {e}"))?;
    let addr = first
        .split(after)
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .ok_or_else(|| format!("{what} printed no address: {}", first.trim()))?
        .to_string();
    std::thread::spawn(move || {
        let mut sink = String::new();
        while out.read_line(&mut sink).is_ok_and(|n| n > 0) {
            sink.clear();
        }
    });
    Ok((server, addr))
}

/// `cargo xtask qemu`'s session against the QEMU link image `elf`, run
/// traced: the control interrupt's window is weighed in cycles
/// (`cycles`), the one
/// whose instruction counts are the session's own `status` figures plus
/// the readings' overhead (`isr_cycles_est_max=` on the line).
pub fn against_qemu(root: &Path, link: &Path, elf: &Path) -> Result<(), String> {
    let out_dir = crate::target_dir(root)?.join("link-session").join("qemu");
    let trace = crate::cycles::marks_for(elf, "SysTick")?;
    let (r, traced) = on_link_image_traced(elf, "qemu-link", Some(trace), |addr| {
        run_session(link, addr, &out_dir, "qemu-link")
    })?;
    let traced = traced.ok_or("no trace of the link image")?;
    let mut r = r?;
    let w = traced.segment_like(r.isr_mean as f64, r.isr_max)?;
    eprintln!(
        "xtask: qemu-link: the control interrupt traced over {} periods: the window's instructions mean {:.1} max {} (the session's {}/{} plus the readings'), cycles max {} ({:.2} a instruction), {} with every 16-byte flash line a miss once (5 wait states)",
        w.count,
        w.mean_instructions(),
        w.max_instructions,
        r.isr_mean,
        r.isr_max,
        w.max_cycles,
        w.max_cycles as f64 / w.max_instructions.max(1) as f64,
        w.max_cold
    );
    r.isr_cycles_est_max = Some(w.max_cycles);
    println!("{}", r.line("qemu-link", "instr"));
    Ok(())
}

/// The bring-up order (`tests/link-session-bringup.txt`:
/// every routine, the weighing, the height, a target and the shaped law,
/// arming, then `params list` and `status` while armed) against a fresh
/// QEMU link image: it must end armed with `faults: none` and `missed
/// deadlines 0`. Prints `qemu-link-bringup: missed=N faults=F
/// start_jitter_max_us=J`.
pub fn bringup_against_qemu(root: &Path, link: &Path, elf: &Path) -> Result<(), String> {
    const LABEL: &str = "qemu-link-bringup";
    let script = crate::workspace_root()
        .join("tests")
        .join("link-session-bringup.txt");
    let out_dir = crate::target_dir(root)?.join("link-session").join(LABEL);
    let (ok, out, err) = on_link_image(elf, LABEL, |addr| {
        shell(link, addr, &script, &out_dir, LABEL)
    })?;
    let lines: Vec<String> = out.lines().map(str::to_string).collect();
    // The last `status`'s figures: the first number after each phrase.
    let after = |phrase: &str| {
        lines
            .iter()
            .rev()
            .find_map(|l| l.split_once(phrase))
            .and_then(|(_, rest)| numbers(rest).first().copied())
    };
    let missed = after("missed deadlines ");
    let jitter = after("start jitter max ");
    let faults = lines
        .iter()
        .rev()
        .find_map(|l| l.strip_prefix("faults: "))
        .unwrap_or("-")
        .to_string();
    println!(
        "{LABEL}: missed={} faults={faults} start_jitter_max_us={}",
        missed.map_or("-".into(), |m| format!("{m:.0}")),
        jitter.map_or("-".into(), |j| format!("{j:.1}"))
    );
    let mut problems = Vec::new();
    if !ok {
        problems.push(format!("hopper-link failed: {}", err.trim()));
    }
    if missed != Some(0.0) {
        problems.push(format!("missed deadlines {missed:?}, not 0"));
    }
    if faults != "none" {
        problems.push(format!("faults {faults}, not none"));
    }
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!("{LABEL} failed: {}", problems.join("; ")))
    }
}

/// The QEMU link image `elf` booted with its USART1 on a free TCP port,
/// `session` run against it (given the address), then QEMU stopped and
/// its log printed as `<label>| ...`.
pub(crate) fn on_link_image<T>(
    elf: &Path,
    label: &str,
    session: impl FnOnce(&str) -> Result<T, String>,
) -> Result<T, String> {
    on_link_image_traced(elf, label, None, session).and_then(|(r, _)| r)
}

/// [`on_link_image`], with QEMU's execution log read as it runs when
/// `trace` (marks and `-dfilter`) is given.
fn on_link_image_traced<T>(
    elf: &Path,
    label: &str,
    trace: Option<(crate::cycles::Marks, String)>,
    session: impl FnOnce(&str) -> Result<T, String>,
) -> Result<(Result<T, String>, Option<crate::cycles::Reader>), String> {
    let addr = free_addr()?;
    eprintln!(
        "xtask: running the link image on qemu-system-arm, USART1 on tcp {addr}{}",
        if trace.is_some() {
            ", execution traced"
        } else {
            ""
        }
    );
    let mut cmd = crate::qemu::qemu_command(elf, 0, &format!("tcp:{addr},server=on,wait=off"));
    if let Some((_, dfilter)) = &trace {
        cmd.args(crate::cycles::qemu_args(dfilter));
        cmd.stderr(Stdio::piped());
    }
    let mut child = cmd
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
    let mut stdout = child.stdout.take().ok_or("no stdout from qemu")?;
    let tracer = match (trace, child.stderr.take()) {
        (Some((marks, _)), Some(err)) => Some(crate::cycles::read_in_thread(marks, err)),
        _ => None,
    };
    let qemu = Reaped(child);
    let log = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = stdout.read_to_end(&mut buf);
        buf
    });
    wait_listening(&addr)?;
    let result = session(&addr);
    drop(qemu);
    if let Ok(bytes) = log.join() {
        match crate::qemu::decode(elf, &bytes) {
            Ok(lines) => lines.iter().for_each(|l| println!("{label}| {l}")),
            Err(e) => eprintln!("xtask: the link image's log: {e}"),
        }
    }
    let traced = match tracer {
        Some(t) => Some(t.join().map_err(|_| "reading qemu's trace failed")?),
        None => None,
    };
    for l in traced.iter().flat_map(|t| &t.other) {
        eprintln!("xtask: qemu: {l}");
    }
    Ok((result, traced))
}

/// What a session showed.
#[derive(Debug, Default)]
struct Report {
    /// The tare's load-cell and potentiometer corrections, N and mm.
    tare_n: f64,
    tare_mm: f64,
    /// Where homing found the stop, mm; the spring rate found (after the
    /// weighing's correction), N/m; the height correction, mm.
    home_mm: f64,
    spring_n_per_m: f64,
    height_mm: f64,
    /// The load cell's gain error the weighing found.
    gain_error: f64,
    /// The saved calibration after a restart (`loaded`; the QEMU image's
    /// flash is RAM: `-`).
    reboot: String,
    steady_apex_m: f64,
    records: u64,
    dropped: u64,
    link_lost_s: f64,
    frames_bad: u64,
    step_mean: u64,
    step_max: u64,
    link_mean: u64,
    link_max: u64,
    /// The whole control interrupt, over the session (`status`).
    isr_mean: u64,
    isr_max: u64,
    /// Requests the flood sent, and the control interrupt's largest cost
    /// by its end.
    flood_requests: u64,
    flood_isr_max: u64,
    /// The control interrupt's largest, in estimated cycles (a traced run).
    isr_cycles_est_max: Option<u64>,
}

impl Report {
    fn line(&self, label: &str, unit: &str) -> String {
        format!(
            "{label}: steady_apex_m={:.4} records={} dropped={} link_lost_s={:.4} frames_bad={} step_{unit}_mean={} step_{unit}_max={} link_{unit}_mean={} link_{unit}_max={}",
            self.steady_apex_m,
            self.records,
            self.dropped,
            self.link_lost_s,
            self.frames_bad,
            self.step_mean,
            self.step_max,
            self.link_mean,
            self.link_max
        ) + &format!(
            " isr_{unit}_mean={} isr_{unit}_max={} flood_requests={} flood_isr_{unit}_max={}",
            self.isr_mean, self.isr_max, self.flood_requests, self.flood_isr_max
        ) + &format!(
            " tare_loadcell_n={:+.3} tare_pot_mm={:+.4} home_mm={:+.4} spring_n_per_m={:.0} height_mm={:+.3} saved_after_restart={} loadcell_gain_error={:+.4}",
            self.tare_n,
            self.tare_mm,
            self.home_mm,
            self.spring_n_per_m,
            self.height_mm,
            if self.reboot.is_empty() { "-" } else { &self.reboot },
            self.gain_error
        ) + &self
            .isr_cycles_est_max
            .map_or(String::new(), |c| format!(" isr_cycles_est_max={c}"))
    }
}

/// The session robot's mis-calibration (`hopper-sim serve`'s flags, the
/// QEMU link image's constants), which its bring-up routines must recover.
const MIS: hopper_sil::robot::Miscalibration = hopper_sil::robot::Miscalibration::SESSION;
/// How close the tare must come, N and mm: 2% of the biases (the means of
/// 5,000 samples with 2 N and 0.1 mm of noise are good to 0.03 N and
/// 0.002 mm).
const TARE_TOLERANCE: (f64, f64) = (0.24, 0.01);
/// How close homing must find the stop, mm: 2% of the nut's 1 mm (the
/// stall is found to an encoder count, 2.5 um).
const HOME_TOLERANCE_MM: f64 = 0.02;
/// How close the spring sweep's rate must come: 1% (the fit of 40,000
/// points over 10 mm; the residual's 2.4 N RMS is the load cell's noise).
const SPRING_TOLERANCE: f64 = 0.01;
/// How close the weighing must find the load cell's gain: 0.5% (its 5%
/// error found to a tenth; the two halves' means over some 5,000 samples
/// each are good to 0.03 N of the 95 N, the rest is the sweep's dynamics).
const GAIN_TOLERANCE: f64 = 0.005;
/// How close the height zero must come, mm: the potentiometer's 0.1 mm
/// noise averaged over 5,000 samples, its 29 um code and the encoder's
/// count.
const HEIGHT_TOLERANCE_MM: f64 = 0.1;

/// The numbers of a line after `prefix` (`1,234` and `0.12` alike), in order.
pub(crate) fn numbers_after(lines: &[String], prefix: &str) -> Option<Vec<f64>> {
    let l = lines.iter().rev().find_map(|l| l.strip_prefix(prefix))?;
    Some(numbers(l))
}

/// The numbers in `l` (`1,234` and `0.12` alike), in order.
fn numbers(l: &str) -> Vec<f64> {
    l.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .filter_map(|w| w.trim_matches('.').parse().ok())
        .collect()
}

/// `hopper-link --tcp ADDR shell < SCRIPT` (its `OUT/` paths under
/// `out_dir`), its output printed as `<label>| ...`: whether it succeeded,
/// its stdout and its stderr.
pub(crate) fn shell(
    link: &Path,
    addr: &str,
    script_path: &Path,
    out_dir: &Path,
    label: &str,
) -> Result<(bool, String, String), String> {
    let script = std::fs::read_to_string(script_path)
        .map_err(|e| format!("{}: {e}", script_path.display()))?
        .replace("OUT/", &format!("{}/", out_dir.display()));
    let _ = std::fs::remove_dir_all(out_dir);
    // The script's relative paths land in `out_dir`.
    std::fs::create_dir_all(out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    eprintln!(
        "xtask: {label}: hopper-link --tcp {addr} shell < {}",
        script_path.display()
    );
    let started = Instant::now();
    let mut child = Command::new(link)
        .args(["--tcp", addr, "shell", "--stop-on-error"])
        .current_dir(out_dir)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start hopper-link: {e}"))?;
    if let Some(mut stdin) = child.stdin.take() {
        stdin
            .write_all(script.as_bytes())
            .map_err(|e| format!("hopper-link stdin: {e}"))?;
    }
    let mut stdout = child.stdout.take().ok_or("no stdout from hopper-link")?;
    let mut stderr = child.stderr.take().ok_or("no stderr from hopper-link")?;
    let reader = std::thread::spawn(move || {
        let mut out = String::new();
        let _ = stdout.read_to_string(&mut out);
        let mut err = String::new();
        let _ = stderr.read_to_string(&mut err);
        (out, err)
    });
    let mut child = Reaped(child);
    let status = loop {
        match child.0.try_wait() {
            Ok(Some(s)) => break s,
            Ok(None) if started.elapsed() > SESSION_TIMEOUT => {
                return Err(format!("{label}: the session timed out"));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(100)),
            Err(e) => return Err(format!("{label}: {e}")),
        }
    };
    let (out, err) = reader.join().map_err(|_| "reading hopper-link failed")?;
    // The parameter table is long: leave its rows out of the log.
    for l in out.lines().filter(|l| !l.contains(" ..= ")) {
        println!("{label}| {l}");
    }
    for l in err.lines() {
        println!("{label}| {l}");
    }
    eprintln!(
        "xtask: {label}: the session took {:.1} s",
        started.elapsed().as_secs_f64()
    );
    Ok((status.success(), out, err))
}

fn run_session(link: &Path, addr: &str, out_dir: &Path, label: &str) -> Result<Report, String> {
    let script_path = crate::workspace_root()
        .join("tests")
        .join("link-session.txt");
    let (success, out, err) = shell(link, addr, &script_path, out_dir, label)?;
    let lines: Vec<String> = out.lines().map(str::to_string).collect();
    let mut problems = Vec::new();
    if !success {
        problems.push(format!("hopper-link failed: {}", err.trim()));
    }
    let mut r = Report::default();
    // Convergence: the steady apex and the last hops of hops.csv.
    match numbers_after(&lines, "steady apex: ").and_then(|v| v.first().copied()) {
        Some(s) => r.steady_apex_m = s,
        None => problems.push("no steady apex in the recording".into()),
    }
    let hops = out_dir.join("record").join("hops.csv");
    let apexes: Vec<f64> = std::fs::read_to_string(&hops)
        .unwrap_or_default()
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(1)?.parse().ok())
        .collect();
    let tail = &apexes[apexes.len().saturating_sub(LAST_APEXES)..];
    if tail.len() < LAST_APEXES
        || tail
            .iter()
            .any(|a| (a - TARGET_APEX_M).abs() > APEX_TOLERANCE * TARGET_APEX_M)
    {
        problems.push(format!(
            "the last {LAST_APEXES} recorded apexes are not within {:.0}% of {TARGET_APEX_M} m: {tail:?} ({})",
            APEX_TOLERANCE * 100.0,
            hops.display()
        ));
    }
    if let Some(v) = numbers_after(&lines, "recorded ") {
        // "recorded 8.001 s: 8001 records at 1000 Hz, 0 dropped; 20 hops"
        r.records = v.get(1).copied().unwrap_or(0.0) as u64;
        r.dropped = v.get(3).copied().unwrap_or(0.0) as u64;
        if r.records < 7_900 || r.dropped * 100 > r.records {
            problems.push(format!(
                "recorded {} records with {} dropped (8 s at 1 kHz, at most 1% lost)",
                r.records, r.dropped
            ));
        }
    } else {
        problems.push("no recording summary".into());
    }
    if !lines
        .iter()
        .any(|l| l.starts_with("disarmed; next record:") && l.ends_with("command 0.000 A"))
    {
        problems.push("the record after the disarm does not command 0 A".into());
    }
    for expected in [
        "failed as expected: arm refused: not-homed: home the nut first (`calibrate direction`, then `calibrate home`, on the hoist)",
        "failed as expected: calibrate home refused: check-direction-first",
        "failed as expected: calibrate height refused: not-on-ground: the toe is off the ground; stand the robot on its toe with the hoist slack (`mount release` on a simulated robot), then run it again",
        "failed as expected: calibrate tare refused: leg-loaded: the leg carries the robot; hang it on the hoist with the toe free (`mount hoist` on a simulated robot), then run it again",
        "failed as expected: calibrate spring refused: leg-loaded: the leg carries the robot; hang it on the hoist with the toe free (`mount hoist` on a simulated robot), then run it again",
        "failed as expected: calibrate weight refused: not-on-ground: the toe is off the ground; stand the robot on its toe with the hoist slack (`mount release` on a simulated robot), then run it again",
        "saved: 27 calibration parameters to flash (they load at the next boot)",
        "failed as expected: arm refused: estop-pressed: release the e-stop",
        "failed as expected: set target_apex_m = 2.0 refused: out-of-range (unchanged: 0.12 m)",
        "target_apex_m = 0.12 m",
    ] {
        if !lines.iter().any(|l| l == expected) {
            problems.push(format!("missing `{expected}`"));
        }
    }
    // The dump while the e-stop's fault is latched: the frozen capture.
    if !lines
        .iter()
        .any(|l| l.starts_with("capture: ") && l.contains("frozen by the fault at step"))
    {
        problems.push("the dump is not the capture frozen by the e-stop's fault".into());
    }
    match numbers_after(&lines, "disarmed (link-lost) ").and_then(|v| v.first().copied()) {
        Some(s) => {
            r.link_lost_s = s;
            if !(LINK_TIMEOUT_S - 1e-3..=LINK_TIMEOUT_S + LINK_LOST_SLACK_S).contains(&s) {
                problems.push(format!(
                    "the link-loss disarm came {s} s after the last frame (timeout {LINK_TIMEOUT_S} s)"
                ));
            }
        }
        None => problems.push("no link-loss disarm".into()),
    }
    // The last status (after the garbage): bad frames counted, no fault.
    match numbers_after(&lines, "link: ") {
        Some(v) => r.frames_bad = v.get(1).copied().unwrap_or(0.0) as u64,
        None => problems.push("no status after the garbage".into()),
    }
    if r.frames_bad == 0 {
        problems.push("the garbage was not counted as bad frames".into());
    }
    if lines.iter().rev().find(|l| l.starts_with("faults: ")) != Some(&"faults: none".to_string()) {
        problems.push("a fault is latched after the garbage".into());
    }
    // The bring-up routines on the mis-calibrated robot: what they found
    // against the truth.
    match numbers_after(&lines, "direction: a pulse down moved the nut ") {
        Some(v) if v.len() >= 2 && v[0] > 0.1 && v[1] > 0.0 => {}
        v => problems.push(format!(
            "the direction check did not move the nut down and compress the spring: {v:?}"
        )),
    }
    match numbers_after(&lines, "home: the upper stop was at ") {
        Some(v) if !v.is_empty() => {
            r.home_mm = v[0];
            let want = -MIS.nut_start_m * 1000.0;
            if (r.home_mm - want).abs() > HOME_TOLERANCE_MM {
                problems.push(format!(
                    "homing found the stop at {:+.4} mm, not {want:+} mm (within {HOME_TOLERANCE_MM} mm)",
                    r.home_mm
                ));
            }
        }
        _ => problems.push("no homing result".into()),
    }
    // The sweep finds the rate as the load cell reads it (its gain error
    // included); the weighing then takes the gain error out of both.
    let k_true =
        hopper_plant::Params::design().spring_stiffness_n_per_m * (1.0 + MIS.spring_rate_error);
    match numbers_after(&lines, "spring: rate ") {
        Some(v) if !v.is_empty() => {
            let want = k_true * (1.0 + MIS.loadcell_gain_error);
            if (v[0] / want - 1.0).abs() > SPRING_TOLERANCE {
                problems.push(format!(
                    "the spring sweep found {:.0} N/m, not {want:.0} N/m (within {:.0}%)",
                    v[0],
                    SPRING_TOLERANCE * 100.0
                ));
            }
        }
        _ => problems.push("no spring result".into()),
    }
    // "weighs W N as the load cell reads it, C N as configured: the load
    // cell reads E%; stance friction F N; the body rose R mm"
    match numbers_after(&lines, "weight: the robot weighs ") {
        Some(v) if v.len() >= 3 => {
            r.gain_error = v[0] / v[1] - 1.0;
            if (r.gain_error - MIS.loadcell_gain_error).abs() > GAIN_TOLERANCE {
                problems.push(format!(
                    "the weighing found the load cell's gain off by {:+.4}, not {:+} (within {GAIN_TOLERANCE})",
                    r.gain_error, MIS.loadcell_gain_error
                ));
            }
        }
        _ => problems.push("no weighing result".into()),
    }
    // "gain A -> B N/code, supervisor.spring_rate_n_per_m C -> D N/m"
    match numbers_after(&lines, "weight: calibration.loadcell_gain_n_per_code ") {
        Some(v) if v.len() >= 4 => {
            r.spring_n_per_m = v[3];
            if (r.spring_n_per_m / k_true - 1.0).abs() > SPRING_TOLERANCE {
                problems.push(format!(
                    "after the weighing the spring rate is {:.0} N/m, not {k_true:.0} N/m (within {:.0}%)",
                    r.spring_n_per_m,
                    SPRING_TOLERANCE * 100.0
                ));
            }
        }
        _ => problems.push("no weighing correction".into()),
    }
    match numbers_after(&lines, "height: the body height corrected by ") {
        Some(v) if !v.is_empty() => {
            r.height_mm = v[0];
            let want = -MIS.height_zero_error_m * 1000.0;
            if (r.height_mm - want).abs() > HEIGHT_TOLERANCE_MM {
                problems.push(format!(
                    "the height zero corrected {:+.3} mm, not {want:+} mm (within {HEIGHT_TOLERANCE_MM} mm)",
                    r.height_mm
                ));
            }
        }
        _ => problems.push("no height result".into()),
    }
    // The tares with the robot held up (before and after the spring
    // sweep): their corrections together are the biases.
    let want = (MIS.loadcell_bias_n, MIS.pot_bias_m * 1000.0);
    let tares: Vec<Vec<f64>> = lines
        .iter()
        .filter_map(|l| l.strip_prefix("tare: calibration.loadcell_offset_code "))
        .map(numbers)
        .collect();
    // "A -> B codes (+N N), calibration.pot_offset_code C -> D codes (+M mm) (applied)"
    match tares
        .iter()
        .map(|v| Some((*v.get(2)?, *v.get(5)?)))
        .collect::<Option<Vec<(f64, f64)>>>()
    {
        Some(v) if !v.is_empty() => {
            r.tare_n = v.iter().map(|(n, _)| n).sum();
            r.tare_mm = v.iter().map(|(_, mm)| mm).sum();
            if (r.tare_n - want.0).abs() > TARE_TOLERANCE.0
                || (r.tare_mm - want.1).abs() > TARE_TOLERANCE.1
            {
                problems.push(format!(
                    "the tare found {:+.3} N and {:+.4} mm, not {:+} N and {:+} mm (within {} N, {} mm)",
                    r.tare_n, r.tare_mm, want.0, want.1, TARE_TOLERANCE.0, TARE_TOLERANCE.1
                ));
            }
        }
        _ => problems.push("no tare result".into()),
    }
    // What the robot found at boot: the virtual robots have no reset
    // flags, clock or option bytes of their own (`BootReport::NOT_A_BOARD`).
    if !lines.iter().any(|l| {
        l.starts_with(
            "boot: reset by power-on; core clock 168 MHz as configured; brown-out reset on",
        )
    }) {
        problems.push("no boot report in the status".into());
    }
    // The motor heated while it hopped (8 s recorded, 1 s flooded, and
    // as long as the host's commands between take: at 0.12 m the winding
    // reaches the 135 C derating after about 11 s of hopping, so it may
    // have begun to derate) and never tripped (150 C):
    // "motor (estimated): winding W C, housing H C; ..."
    match numbers_after(&lines, "motor (estimated): winding ") {
        Some(v) if v.first().is_some_and(|w| (30.0..150.0).contains(w)) => {}
        Some(v) => problems.push(format!(
            "the motor's winding estimate after hopping is {:?} C, not warm and below the trip",
            v.first()
        )),
        None => problems.push("no motor temperature in the status".into()),
    }
    // The flood while hopping: still armed, no fault, on time, and the
    // control interrupt within its bound.
    match numbers_after(&lines, "flood: ") {
        // "flood: S s of robot time (P periods, W s wall), N requests ..."
        Some(v) if v.len() >= 4 => r.flood_requests = v[3] as u64,
        _ => problems.push("no flood summary".into()),
    }
    match lines
        .iter()
        .find_map(|l| l.strip_prefix("after the flood: "))
    {
        Some(l) if l.starts_with("armed, faults none, missed deadlines 0 ") => {}
        Some(l) => problems.push(format!("after the flood: {l}")),
        None => problems.push("no state after the flood".into()),
    }
    match numbers_after(&lines, "during the flood: control interrupt max ") {
        Some(v) if !v.is_empty() => {
            r.flood_isr_max = v[0] as u64;
            if r.flood_isr_max > ISR_BOUND {
                problems.push(format!(
                    "the control interrupt took up to {} counter ticks during the flood (bound {ISR_BOUND})",
                    r.flood_isr_max
                ));
            }
        }
        _ => problems.push("no control interrupt cost after the flood".into()),
    }
    match numbers_after(&lines, "control interrupt: ") {
        Some(v) if v.len() >= 2 => (r.isr_mean, r.isr_max) = (v[0] as u64, v[1] as u64),
        _ => problems.push("no control interrupt cost in the status".into()),
    }
    match numbers_after(&lines, "cost per period ") {
        // "(robot counter ticks: board cycles, QEMU instructions, simulator
        // 0): control step mean A max B, link mean C max D"
        Some(v) if v.len() >= 5 => {
            let n = v.len();
            (r.step_mean, r.step_max, r.link_mean, r.link_max) = (
                v[n - 4] as u64,
                v[n - 3] as u64,
                v[n - 2] as u64,
                v[n - 1] as u64,
            );
        }
        _ => problems.push("no cost per period in the status".into()),
    }
    if problems.is_empty() {
        Ok(r)
    } else {
        for p in &problems {
            eprintln!("xtask: {label}: {p}");
        }
        println!("{}", r.line(label, "ticks"));
        Err(format!("{label} session failed: {}", problems.join("; ")))
    }
}
