//! `cargo xtask test`'s noisy link: a proxy of our own between
//! `hopper-link` and `hopper-sim serve` that flips bits, drops and
//! duplicates bytes at seeded rates, and a session through it (status,
//! sets, a bring-up routine, arming, a recording, a disarm). Prints
//! `noisy-link: ber=1e-4 commands=N failed=0 retries=R applied_twice=0
//! wrong_values=0` and the same at 1e-3, where a command may fail but
//! only with the clear error; then, through the same line going silent,
//! the robot disarms by its link timeout.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::session::{host_binaries, Reaped};

/// The session (`OUT/` replaced by its folder).
const SESSION: &str = "\
status
params set target_apex_m 0.11
params set controller shaped
calibrate sensors
params set target_apex_m 0.12
arm --retry 5
record --duration 2 --rate 200 --out OUT/record
params set target_apex_m 0.13
disarm
params set target_apex_m 0.115
params set controller energy
params set controller shaped
status
";

/// The session on the QEMU link image, whose robot refuses to arm before
/// its bring-up (homing): the refusal must come back through the noise.
const QEMU_SESSION: &str = "\
status
params set target_apex_m 0.11
calibrate sensors
params set target_apex_m 0.12
! arm
record --duration 1 --rate 200 --out OUT/record
disarm
params set target_apex_m 0.115
status
";

/// The same line at `ber` = 1e-4 between `hopper-link` and the QEMU link
/// image `elf`: `noisy-link-qemu: ber=1e-4 commands=N failed=0 ...`.
fn on_qemu(root: &Path, link: &Path, elf: &Path) -> Result<(), String> {
    let out_dir = crate::target_dir(root)?.join("noisy-link").join("qemu");
    let _ = std::fs::remove_dir_all(&out_dir);
    let line = Line {
        ber: 1e-4,
        seed: 0x5eed_0003,
        silent: Arc::new(AtomicBool::new(false)),
    };
    let o = crate::session::on_link_image(elf, "noisy-link-qemu", |addr| {
        session(link, addr, &line, &out_dir, QEMU_SESSION, "noisy-link-qemu")
    })?;
    println!(
        "noisy-link-qemu: ber=1e-4 commands={} failed={} retries={} applied_twice={} wrong_values={}",
        o.commands,
        o.failed,
        o.retries,
        o.applied_twice,
        o.wrong.len()
    );
    if o.failed > 0 || o.applied_twice > 0 || !o.wrong.is_empty() {
        return Err(format!(
            "noisy link on QEMU: {} failed ({:?}), applied twice {}, wrong values {:?}",
            o.failed, o.unclear, o.applied_twice, o.wrong
        ));
    }
    Ok(())
}

/// The line's faults: each bit flipped with probability `ber`, each byte
/// dropped or sent twice with probability `ber` (a UART's lost and
/// doubled characters), everything dropped while `silent`.
#[derive(Clone)]
struct Line {
    ber: f64,
    seed: u64,
    silent: Arc<AtomicBool>,
}

/// A small seeded generator (xorshift64*): the same faults every run.
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Trials until the next success of probability `p` (geometric).
    fn skip(&mut self, p: f64) -> u64 {
        let u = self.unit().max(1e-300);
        (u.ln() / (1.0 - p).ln()).floor() as u64
    }
}

/// Copies `from` to `to` through the line's faults.
fn pump(mut from: TcpStream, mut to: TcpStream, line: Line, seed: u64) {
    let mut rng = Rng(seed | 1);
    let (mut to_flip, mut to_drop, mut to_dup) =
        (rng.skip(line.ber), rng.skip(line.ber), rng.skip(line.ber));
    let mut buf = [0u8; 4096];
    let mut out = Vec::with_capacity(8192);
    loop {
        let n = match from.read(&mut buf) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        out.clear();
        if line.silent.load(Ordering::Relaxed) {
            continue;
        }
        for &b in &buf[..n] {
            let mut b = b;
            for bit in 0..8 {
                if to_flip == 0 {
                    b ^= 1 << bit;
                    to_flip = rng.skip(line.ber);
                } else {
                    to_flip -= 1;
                }
            }
            if to_drop == 0 {
                to_drop = rng.skip(line.ber);
                continue;
            }
            to_drop -= 1;
            out.push(b);
            if to_dup == 0 {
                to_dup = rng.skip(line.ber);
                out.push(b);
            } else {
                to_dup -= 1;
            }
        }
        if to.write_all(&out).is_err() {
            break;
        }
    }
    let _ = to.shutdown(std::net::Shutdown::Both);
}

/// The proxy: listens on a free port; each connection to it goes to
/// `upstream` through `line`. Its address.
fn proxy(upstream: String, line: Line) -> Result<String, String> {
    let l = TcpListener::bind("127.0.0.1:0").map_err(|e| format!("proxy: {e}"))?;
    let addr = l.local_addr().map_err(|e| e.to_string())?.to_string();
    std::thread::spawn(move || {
        for (k, client) in l.incoming().flatten().enumerate() {
            let Ok(robot) = TcpStream::connect(&upstream) else {
                continue;
            };
            let _ = client.set_nodelay(true);
            let _ = robot.set_nodelay(true);
            let (Ok(c2), Ok(r2)) = (client.try_clone(), robot.try_clone()) else {
                continue;
            };
            let k = k as u64;
            let l1 = line.clone();
            let l2 = line.clone();
            let s = line.seed.wrapping_add(k.wrapping_mul(0x9e37_79b9));
            std::thread::spawn(move || pump(client, robot, l1, s));
            std::thread::spawn(move || pump(r2, c2, l2, s ^ 0xdead_beef));
        }
    });
    Ok(addr)
}

/// `hopper-sim serve` on a free port, the robot held 5 cm up until armed.
fn serve(sim: &Path) -> Result<(Reaped, String), String> {
    crate::session::spawn_serve(Command::new(sim).args([
        "serve",
        "--tcp",
        "127.0.0.1:0",
        "--start-apex",
        "0.05",
    ]))
}

/// `hopper-link --tcp addr shell` on `script`; each line of its output as
/// it comes to `each` (which may act on the line: silence it), then all
/// of it.
fn shell(
    link: &Path,
    addr: &str,
    script: &str,
    label: &str,
    mut each: impl FnMut(&str),
) -> Result<String, String> {
    let mut child = Command::new(link)
        .args(["--tcp", addr, "shell"])
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
    let stdout = child.stdout.take().ok_or("no stdout from hopper-link")?;
    let mut stderr = child.stderr.take().ok_or("no stderr from hopper-link")?;
    let _child = Reaped(child);
    let mut all = String::new();
    for l in BufReader::new(stdout).lines() {
        let l = l.map_err(|e| e.to_string())?;
        each(&l);
        if !l.contains(" ..= ") {
            println!("{label}| {l}");
        }
        all += &l;
        all.push('\n');
    }
    let mut err = String::new();
    let _ = stderr.read_to_string(&mut err);
    for l in err.lines() {
        println!("{label}| {l}");
    }
    Ok(all)
}

/// What one session through the line did.
struct Outcome {
    commands: usize,
    failed: usize,
    /// Failures without the clear error.
    unclear: Vec<String>,
    retries: u64,
    applied_twice: u64,
    wrong: Vec<String>,
}

/// The numbers in `text` after `key` (`"12 sent again"` for `"sent again"`
/// reads the number before it).
fn number_before(text: &str, key: &str) -> Option<u64> {
    let head = &text[..text.find(key)?];
    head.split_whitespace().last()?.parse().ok()
}

/// Runs `script` through `line` and reads back, on a clean connection,
/// what it set.
fn session(
    link: &Path,
    robot: &str,
    line: &Line,
    out_dir: &Path,
    script: &str,
    label: &str,
) -> Result<Outcome, String> {
    let via = proxy(robot.to_string(), line.clone())?;
    let script = script.replace("OUT/", &format!("{}/", out_dir.display()));
    let out = shell(link, &via, &script, label, |_| {})?;
    let mut o = Outcome {
        commands: 0,
        failed: 0,
        unclear: Vec::new(),
        retries: 0,
        applied_twice: 0,
        wrong: Vec::new(),
    };
    // Each parameter's values the robot may hold now: the last set that
    // succeeded, and any later one that failed (not known to be applied).
    let mut may: std::collections::BTreeMap<String, Vec<String>> = Default::default();
    let mut set: Option<(String, String)> = None;
    let mut failed_here = false;
    let close = |set: &mut Option<(String, String)>,
                 failed: bool,
                 may: &mut std::collections::BTreeMap<String, Vec<String>>| {
        if let Some((name, value)) = set.take() {
            let v = may.entry(name).or_default();
            if !failed {
                v.clear();
            }
            v.push(value);
        }
    };
    for l in out.lines() {
        if let Some(cmd) = l.strip_prefix("> ") {
            close(&mut set, failed_here, &mut may);
            failed_here = false;
            o.commands += 1;
            let w: Vec<&str> = cmd.split_whitespace().collect();
            if let ["params", "set", name, value] = w[..] {
                set = Some((name.to_string(), value.to_string()));
            }
        } else if let Some(e) = l.strip_prefix("error: ") {
            o.failed += 1;
            failed_here = true;
            if !(e.contains("sent ") && e.contains("no answer came back")) {
                o.unclear.push(e.to_string());
            }
        } else if l.starts_with("link losses: host") {
            o.retries = number_before(l, "sent again").unwrap_or(0);
        } else if l.starts_with("link losses: robot") {
            // "... applied twice N": the line's last number.
            o.applied_twice = l
                .split_whitespace()
                .last()
                .and_then(|n| n.parse().ok())
                .unwrap_or(0);
        }
    }
    close(&mut set, failed_here, &mut may);
    for (name, values) in &may {
        let got = Command::new(link)
            .args(["--tcp", robot, "params", "get", name])
            .output()
            .map_err(|e| format!("cannot run hopper-link: {e}"))?;
        let text = String::from_utf8_lossy(&got.stdout).to_string();
        let shown = text
            .split(" = ")
            .nth(1)
            .and_then(|v| v.split_whitespace().next())
            .unwrap_or("")
            .to_string();
        let same = |v: &String| {
            *v == shown
                || matches!((v.parse::<f64>(), shown.parse::<f64>()), (Ok(a), Ok(b)) if (a - b).abs() < 1e-6)
        };
        println!("{label}| read back on a clean connection: {name} = {shown} (the session left {values:?})");
        if !values.iter().any(same) {
            o.wrong.push(format!("{name} = {shown}, set {values:?}"));
        }
    }
    Ok(o)
}

/// Through the line going silent for 0.6 s while armed: the robot
/// disarms by its link timeout (`disarmed (link-lost)`).
fn silenced(link: &Path, robot: &str, line: &Line) -> Result<String, String> {
    let via = proxy(robot.to_string(), line.clone())?;
    let label = format!("noisy-link {:e} silent", line.ber);
    let silent = line.silent.clone();
    let out = shell(
        link,
        &via,
        "arm --retry 5\nwait 2\nstatus\n",
        &label,
        move |l| {
            if l == "> wait 2" {
                let silent = silent.clone();
                std::thread::spawn(move || {
                    std::thread::sleep(Duration::from_millis(300));
                    silent.store(true, Ordering::Relaxed);
                    std::thread::sleep(Duration::from_millis(600));
                    silent.store(false, Ordering::Relaxed);
                });
            }
        },
    )?;
    Ok(out
        .lines()
        .find_map(|l| l.strip_prefix("state: "))
        .map(|s| s.split(':').next().unwrap_or(s).to_string())
        .unwrap_or_default())
}

/// The noisy-link lines (against `hopper-sim serve`, and the QEMU link
/// image too when `with_qemu`).
pub fn run(root: &Path, with_qemu: bool) -> Result<(), String> {
    let (link, sim) = host_binaries(root)?;
    let out_dir = crate::target_dir(root)?.join("noisy-link");
    let _ = std::fs::remove_dir_all(&out_dir);
    let started = Instant::now();
    let mut problems = Vec::new();
    let mut lines = Vec::new();
    for (ber, seed, may_fail) in [(1e-4, 0x5eed_0001u64, false), (1e-3, 0x5eed_0002, true)] {
        let (server, robot) = serve(&sim)?;
        let line = Line {
            ber,
            seed,
            silent: Arc::new(AtomicBool::new(false)),
        };
        let label = format!("noisy-link {ber:e}");
        let dir = out_dir.join(format!("{ber:e}"));
        let o = session(&link, &robot, &line, &dir, SESSION, &label)?;
        let lost = if may_fail {
            Some(silenced(&link, &robot, &line)?)
        } else {
            None
        };
        drop(server);
        let mut text = format!(
            "noisy-link: ber={ber:e} commands={} failed={} retries={} applied_twice={} wrong_values={}",
            o.commands,
            o.failed,
            o.retries,
            o.applied_twice,
            o.wrong.len()
        );
        if may_fail {
            text += &format!(" unclear_errors={}", o.unclear.len());
        }
        if let Some(l) = &lost {
            text += &format!(
                " silent_line={}",
                if l == "disarmed (link-lost)" {
                    "disarmed"
                } else {
                    l.as_str()
                }
            );
        }
        if !may_fail && o.failed > 0 {
            problems.push(format!("at {ber:e} {} commands failed", o.failed));
        }
        if !o.unclear.is_empty() {
            problems.push(format!(
                "at {ber:e} failures without the clear error: {:?}",
                o.unclear
            ));
        }
        if o.applied_twice > 0 || !o.wrong.is_empty() {
            problems.push(format!(
                "at {ber:e}: applied twice {}, wrong values {:?}",
                o.applied_twice, o.wrong
            ));
        }
        if lost.as_deref().is_some_and(|l| l != "disarmed (link-lost)") {
            problems.push(format!(
                "the line silent for 0.6 s left the robot `{}`, not disarmed by its link timeout",
                lost.unwrap_or_default()
            ));
        }
        lines.push(text);
    }
    eprintln!(
        "xtask: noisy link: {:.1} s",
        started.elapsed().as_secs_f64()
    );
    for l in &lines {
        println!("{l}");
    }
    if !problems.is_empty() {
        return Err(format!("noisy link: {}", problems.join("; ")));
    }
    if with_qemu {
        crate::qemu::ensure_qemu()?;
        let elf = crate::qemu::link_image(root)?;
        on_qemu(root, &link, &elf)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_line_flips_about_one_bit_in_ber() {
        let mut rng = Rng(0x5eed_0001);
        let p = 1e-3;
        let n = 1_000_000u64;
        let (mut bits, mut flips) = (0u64, 0u64);
        while bits < n {
            let k = rng.skip(p);
            bits += k + 1;
            flips += 1;
        }
        let rate = flips as f64 / bits as f64;
        assert!((rate / p - 1.0).abs() < 0.05, "{rate}");
    }
}
