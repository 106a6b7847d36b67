//! `cargo xtask qemu`: the firmware's closed loop on QEMU's STM32F405.
//!
//! 1. builds `hopper-qemu` with `--no-default-features --features qemu-sim`
//!    into its own target directory (so it never overwrites the board image);
//! 2. runs it on `qemu-system-arm -machine netduinoplus2` with
//!    `-icount shift=0,sleep=off` (one guest instruction per virtual ns, so
//!    TIM5 counts instructions and SysTick ticks exactly) and semihosting;
//! 3. decodes the defmt stream from the guest's stdout with `defmt-decoder`
//!    (no extra binary needed) and echoes it;
//! 4. runs the same scenario on the host (`hopper-sim run ... --json`, same
//!    parameters, seed and sensor models) and compares the apex sequences
//!    (the golden check);
//! 5. checks the control-step instruction budget and prints the summary.

use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::{cargo, run as run_cmd, TARGET};

/// A scripted QEMU scenario (see `firmware/app/src/main.rs`).
struct Scenario {
    /// `HOPPER_QEMU_SCENARIO` at build time: the image's build script reads
    /// `scenarios/qemu/NAME.toml`, and the golden check runs the same file
    /// on the host (`hopper-sim run --scenario`).
    name: &'static str,
    /// Prefix of the summary line (`qemu:` for the first, a contract).
    label: &'static str,
    /// Whether to run the slowed-down overrun check on this image too.
    overrun_check: bool,
}

impl Scenario {
    /// The scenario file, from the repository root.
    fn file(&self) -> String {
        format!("scenarios/qemu/{}.toml", self.name)
    }
}

/// The shaped law from 0.05 m to the thesis's 0.15 m (the `qemu-shaped:`
/// line), its heat-aware mode holding 0.05 m (`qemu-heat-aware:`, the
/// least-effort return's cost on the target), then the energy-apex scenario
/// (the `qemu:` line, last as before).
const SCENARIOS: [Scenario; 3] = [
    Scenario {
        name: "shaped",
        label: "qemu-shaped",
        overrun_check: false,
    },
    Scenario {
        name: "heat-aware",
        label: "qemu-heat-aware",
        overrun_check: false,
    },
    Scenario {
        name: "energy-apex",
        label: "qemu",
        overrun_check: true,
    },
];

/// Largest |host apex - QEMU apex| accepted, m. Host and MCU run the same
/// code, but `rand_distr`'s Gaussian sampler uses the platform's `ln`/`exp`
/// with `std` and `libm`'s without, so the noise differs in the last bits
/// and the runs drift apart by a few hundredths of a millimetre.
const GOLDEN_TOLERANCE_M: f64 = 5e-4;

/// Mean control-step instructions allowed: the whole `Hopper::step`, the
/// hop ledger and the telemetry record included (one implementation per
/// computation, no fast twin for inputs known to be finite), 4.8% of a
/// 168 MHz core at 10 kHz.
const STEP_MEAN_BUDGET: u64 = 800;
/// Hard ceiling per step: 10% of a 168 MHz core at 10 kHz.
const STEP_MAX_CEILING: u64 = 1_680;

/// Wall-clock limit for the QEMU run.
const QEMU_TIMEOUT: Duration = Duration::from_secs(900);

/// The planar and scenario images' QEMU runs, started by [`start`].
pub struct Ahead(std::thread::JoinHandle<Runs>);

/// What [`Ahead`]'s thread ran: each image with its run, or why not.
struct Runs {
    planar: Result<(PlanarScenario, PathBuf, Ran), String>,
    scenarios: Vec<Result<(PathBuf, Ran), String>>,
}

/// Builds the planar and scenario images and starts their QEMU runs, one
/// after the other in a thread of their own, while the caller goes on
/// (`cargo xtask test` compiles and checks meanwhile: a QEMU run takes
/// one core, and `-icount` makes its guest time its instruction count,
/// whatever else the machine does). [`run`] reports them.
pub fn start(root: &Path) -> Result<Ahead, String> {
    crate::ensure_flip_link(root)?;
    ensure_qemu()?;
    let planar = planar_image(root);
    let images: Vec<Result<PathBuf, String>> =
        SCENARIOS.iter().map(|s| scenario_image(root, s)).collect();
    Ok(Ahead(std::thread::spawn(move || {
        // Untraced here: its trace (`cargo xtask qemu-planar`) keeps QEMU
        // busy 165 s more, which `cargo xtask test` cannot afford.
        let planar = planar.and_then(|(cfg, elf)| {
            let ran = run_qemu(&elf, 0)?;
            Ok((cfg, elf, ran))
        });
        let scenarios = images
            .into_iter()
            .map(|image| {
                let elf = image?;
                // Traced: QEMU's log of the firmware's code, weighed in
                // cycles.
                let trace = crate::cycles::marks_for(&elf, "SysTick")?;
                let ran = run_qemu_traced(&elf, 0, Some(trace))?;
                Ok((elf, ran))
            })
            .collect();
        Runs { planar, scenarios }
    })))
}

/// The link sessions and the board's init on QEMU, then the reports of
/// the runs `ahead` started (waited for first: no two QEMU runs share the
/// machine). flip-link and QEMU were checked by [`start`], the only way
/// to an [`Ahead`].
pub fn run(root: &Path, ahead: Ahead) -> Result<(), String> {
    // `hopper-link` for the link session, `hopper-sim` for the golden
    // checks: one workspace test build for both.
    let (link, sim) = match crate::session::host_binaries(root) {
        Ok(b) => b,
        Err(e) => {
            // Every summary line still printed, `qemu:` last.
            println!("qemu-link: error (see above)");
            println!("board-init: error (see above)");
            println!("board-init-feather: error (see above)");
            for s in &SCENARIOS {
                println!("{}: error (see above)", s.label);
            }
            return Err(e);
        }
    };
    // Done before the link sessions, whose host runs on the wall clock.
    let runs = ahead
        .0
        .join()
        .map_err(|_| "the thread running the QEMU images panicked".to_string())?;
    let mut failed = Vec::new();
    if let Err(e) = link_session(root, &link) {
        if !e.starts_with("qemu-link session failed") && !e.starts_with("qemu-link-bringup failed")
        {
            println!("qemu-link: error (see above)");
        }
        failed.push(e);
    }
    if let Err(e) = crate::board_init::run(root) {
        if !e.starts_with("board init failed") {
            println!("board-init: error (see above)");
        }
        failed.push(e);
    }
    let planar_result = runs
        .planar
        .and_then(|(cfg, elf, ran)| report_planar(&cfg, &elf, &sim, ran));
    if let Err(e) = planar_result {
        if !e.starts_with("qemu planar scenario failed") {
            println!("qemu-planar: error (see above)");
        }
        failed.push(e);
    }
    for (s, run) in SCENARIOS.iter().zip(runs.scenarios) {
        let result = run.and_then(|(elf, ran)| report_scenario(root, s, &sim, &elf, ran));
        if let Err(e) = result {
            // A failure before the summary (build, QEMU, decoding, the host
            // run) printed no summary line: print one, so the last line is
            // still the `qemu:` line whatever happened.
            if !e.starts_with(&format!("qemu {} scenario failed", s.name)) {
                println!("{}: error (see above)", s.label);
            }
            failed.push(e);
        }
    }
    if failed.is_empty() {
        Ok(())
    } else {
        Err(failed.join("; "))
    }
}

/// Builds the QEMU binary `bin` (`hopper-qemu` or `hopper-qemu-link`;
/// `cmd` is cargo, with any environment the build needs) into
/// `target_dir`; returns the ELF.
fn build_image(
    root: &Path,
    what: &str,
    bin: &str,
    mut cmd: Command,
    target_dir: &Path,
) -> Result<PathBuf, String> {
    run_cmd(
        root,
        what,
        cmd.args([
            "build",
            "-p",
            "hopper-app",
            "--release",
            "--target",
            TARGET,
            "--no-default-features",
            "--features",
            "qemu-sim",
            "--bin",
            bin,
            "--target-dir",
        ])
        .arg(target_dir),
    )?;
    Ok(target_dir.join(TARGET).join("release").join(bin))
}

/// The link image (`hopper-qemu-link`) and the scripted session
/// against it (the `qemu-link:` line).
/// The QEMU link image, built (once: later calls find it built).
pub fn link_image(root: &Path) -> Result<std::path::PathBuf, String> {
    let target_dir = crate::images_dir(root)?;
    build_image(
        root,
        "firmware build (QEMU link image)",
        "hopper-qemu-link",
        cargo(),
        &target_dir,
    )
}

fn link_session(root: &Path, link: &Path) -> Result<(), String> {
    let elf = link_image(root)?;
    // The main session runs traced (the control interrupt in cycles).
    let main = crate::session::against_qemu(root, link, &elf);
    let bringup = crate::session::bringup_against_qemu(root, link, &elf);
    main.and(bringup)
}

/// The scenario's image, built and copied to a name of its own (the
/// scenarios build the same binary, and run side by side).
fn scenario_image(root: &Path, scenario: &Scenario) -> Result<PathBuf, String> {
    // The second scenario's build recompiles only the application crate
    // (the scenario is an `option_env!`).
    let target_dir = crate::images_dir(root)?;
    let mut build = cargo();
    build.env("HOPPER_QEMU_SCENARIO", scenario.name);
    let built = build_image(
        root,
        &format!("firmware build (QEMU variant, {} scenario)", scenario.name),
        "hopper-qemu",
        build,
        &target_dir,
    )?;
    let elf = target_dir.join(format!("hopper-qemu-{}.elf", scenario.name));
    std::fs::copy(&built, &elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    Ok(elf)
}

/// The scenario's QEMU run (`ran`, of `elf`) checked and reported: its
/// log, the golden check against the host, the budgets and the summary
/// line.
fn report_scenario(
    root: &Path,
    scenario: &Scenario,
    sim: &Path,
    elf: &Path,
    ran: Ran,
) -> Result<(), String> {
    ran.print_notes();
    let Ran {
        bytes,
        ok: status,
        traced,
        ..
    } = ran;
    let lines = decode(elf, &bytes)?;
    for l in &lines {
        println!("qemu| {l}");
    }
    let (summary, kv) =
        parse_summary(&lines).ok_or("the QEMU run printed no summary (see the log above)")?;
    let num = |k: &str| -> Result<f64, String> {
        kv.get(k)
            .and_then(|v| v.parse::<f64>().ok())
            .ok_or(format!("summary lacks {k}: {summary}"))
    };
    let steady = num("steady_apex_m")?;
    let htc = num("hops_to_converge")?;
    let (imin, imean, imax) = (
        num("step_instr_min")? as u64,
        num("step_instr_mean")? as u64,
        num("step_instr_max")? as u64,
    );
    let missed = num("missed")? as u64;
    let faults = num("faults")? as u64;

    let qemu_apexes: Vec<f64> = lines
        .iter()
        .filter_map(|l| l.strip_prefix("apex "))
        .filter_map(|r| r.split_whitespace().nth(1)?.parse().ok())
        .collect();
    let host_apexes = host_apexes(root, sim, &["--scenario", &scenario.file()])?;
    let golden = compare(&host_apexes, &qemu_apexes);

    let mut problems = Vec::new();
    if !status {
        problems.push(
            "the firmware exited with failure (not converged, a fault or a missed deadline)"
                .to_string(),
        );
    }
    if htc < 0.0 {
        problems.push("the hop did not converge to the target".into());
    }
    if faults != 0 {
        problems.push(format!("faults latched (bits {faults:#x})"));
    }
    if missed != 0 {
        problems.push(format!("{missed} missed deadlines"));
    }
    match golden {
        Ok(diff) => eprintln!(
            "xtask: golden check: {} apexes, max |host - qemu| = {diff:.2e} m (tolerance {GOLDEN_TOLERANCE_M:.0e} m)",
            qemu_apexes.len()
        ),
        Err(e) => problems.push(format!("golden check: {e}")),
    }
    if imax > STEP_MAX_CEILING {
        problems.push(format!(
            "control step max {imax} instructions exceeds the ceiling {STEP_MAX_CEILING}"
        ));
    }
    if imean > STEP_MEAN_BUDGET {
        problems.push(format!(
            "control step mean {imean} instructions exceeds the budget {STEP_MEAN_BUDGET}"
        ));
    }
    if scenario.overrun_check {
        if let Err(e) = overrun_check(elf) {
            problems.push(format!("overrun check: {e}"));
        }
    }
    // The step in cycles: the traced window between the two clock
    // readings around it.
    let cycles_txt = match step_cycles(scenario.label, traced, (imean, imax)) {
        Ok(c) => c.to_string(),
        Err(e) => {
            problems.push(format!("cycle estimate: {e}"));
            "-".to_string()
        }
    };
    let steady_txt = if steady < 0.0 {
        "none".to_string()
    } else {
        format!("{steady:.4}")
    };
    let htc_txt = if htc < 0.0 {
        "none".to_string()
    } else {
        format!("{htc}")
    };
    // The stack's depth after init, bytes from its top: idle's frame and
    // the deepest the tasks went (the firmware paints the free stack).
    let stack_peak = kv.get("stack_peak_b").copied().unwrap_or("-");
    let log_frame = kv.get("log_frame_instr_max").copied().unwrap_or("-");
    // A log frame's critical section must not hold off the control
    // task's priority (the image pends a task there inside one).
    let cs_masks = kv.get("cs_masks_control").copied().unwrap_or("-");
    if cs_masks != "false" {
        problems.push(format!(
            "a critical section masks the control task's priority (cs_masks_control={cs_masks})"
        ));
    }
    let line = format!(
        "{}: steady_apex_m={steady_txt} hops_to_converge={htc_txt} step_instr_min={imin} step_instr_mean={imean} step_instr_max={imax} missed={missed} stack_peak_b={stack_peak} log_frame_instr_max={log_frame} step_cycles_est_max={cycles_txt} cs_masks_control={cs_masks}",
        scenario.label
    );
    if problems.is_empty() {
        println!("{line}");
        Ok(())
    } else {
        for p in &problems {
            eprintln!("xtask: {}: {p}", scenario.label);
        }
        println!("{line}");
        Err(format!(
            "qemu {} scenario failed: {}",
            scenario.name,
            problems.join("; ")
        ))
    }
}

/// `cargo xtask qemu-planar`: the planar image alone ([`report_planar`]).
pub fn planar(root: &Path) -> Result<(), String> {
    crate::ensure_flip_link(root)?;
    ensure_qemu()?;
    let (_, sim) = crate::session::host_binaries(root)?;
    let (cfg, elf) = planar_image(root)?;
    let ran = run_planar(&elf)?;
    report_planar(&cfg, &elf, &sim, ran)
}

/// Largest |host - QEMU| of a stride's apex or speed in the planar run
/// (no sensor noise there: the same code on both, in IEEE arithmetic and
/// `libm`), m or m/s.
const PLANAR_GOLDEN_TOLERANCE: f64 = 1e-9;

/// What the host's golden run of the planar scenario needs from
/// `scenarios/qemu/planar.toml`.
struct PlanarScenario {
    profile: String,
    target: String,
    duration: String,
    /// The leg's drive, as the image's build script reads it.
    thrust: String,
}

/// The planar image (`hopper-qemu-planar`) built, and its scenario read.
fn planar_image(root: &Path) -> Result<(PlanarScenario, PathBuf), String> {
    let file = root.join("scenarios/qemu/planar.toml");
    let text = std::fs::read_to_string(&file).map_err(|e| format!("{}: {e}", file.display()))?;
    let t: toml::Table = text
        .parse()
        .map_err(|e| format!("{}: {e}", file.display()))?;
    let get = |k: &str| {
        t.get(k)
            .map(|v| v.as_str().map_or_else(|| v.to_string(), str::to_string))
            .ok_or(format!("{}: no `{k}`", file.display()))
    };
    let cfg = PlanarScenario {
        profile: get("speed_profile")?,
        target: get("target_apex_m")?,
        duration: get("duration_s")?,
        thrust: get("thrust").unwrap_or_else(|_| "force".into()),
    };
    let target_dir = crate::images_dir(root)?;
    let elf = build_image(
        root,
        "firmware build (QEMU planar image)",
        "hopper-qemu-planar",
        cargo(),
        &target_dir,
    )?;
    Ok((cfg, elf))
}

/// The planar machine's controller on the target (`hopper-qemu-planar`,
/// `scenarios/qemu/planar.toml`), its run `ran` checked: its strides
/// against the host's run of the same loop (`hopper-sim planar run
/// --controller raibert`), its step within the vertical laws' budgets.
/// Prints `qemu-planar: strides=N golden_max_diff=D step_instr_min=..
/// step_instr_mean=.. step_instr_max=.. missed=N step_cycles_est_max=C`
/// (C: the period's cycles when `ran` was traced, else `-`).
fn report_planar(cfg: &PlanarScenario, elf: &Path, sim: &Path, ran: Ran) -> Result<(), String> {
    ran.print_notes();
    let Ran {
        bytes,
        ok: status,
        traced,
        ..
    } = ran;
    let lines = decode(elf, &bytes)?;
    for l in lines.iter().filter(|l| !l.starts_with("stride ")) {
        println!("qemu-planar| {l}");
    }
    let (summary, kv) = parse_summary(&lines)
        .ok_or("the QEMU planar run printed no summary (see the log above)")?;
    let num = |k: &str| -> Result<f64, String> {
        kv.get(k)
            .and_then(|v| v.parse::<f64>().ok())
            .ok_or(format!("summary lacks {k}: {summary}"))
    };
    let (imin, imean, imax, missed) = (
        num("step_instr_min")? as u64,
        num("step_instr_mean")? as u64,
        num("step_instr_max")? as u64,
        num("missed")? as u64,
    );
    let qemu: Vec<(f64, f64)> = lines
        .iter()
        .filter_map(|l| l.strip_prefix("stride "))
        .filter_map(|r| {
            let v: Vec<f64> = r
                .split_whitespace()
                .filter_map(|x| x.parse().ok())
                .collect();
            Some((*v.get(1)?, *v.get(2)?))
        })
        .collect();
    let out = Command::new(sim)
        .args([
            "planar",
            "run",
            "--controller",
            "raibert",
            "--speed-profile",
            &cfg.profile,
            "--target-apex",
            &cfg.target,
            "--duration",
            &cfg.duration,
            "--thrust",
            &cfg.thrust,
            "--json",
        ])
        .output()
        .map_err(|e| format!("hopper-sim: {e}"))?;
    let json: serde_json::Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("hopper-sim planar run --json: {e}"))?;
    let host: Vec<(f64, f64)> = json["strides"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|s| Some((s["apex_m"].as_f64()?, s["speed_mps"].as_f64()?)))
                .collect()
        })
        .unwrap_or_default();
    let mut problems = Vec::new();
    let diff = host
        .iter()
        .zip(&qemu)
        .map(|(h, q)| (h.0 - q.0).abs().max((h.1 - q.1).abs()))
        .fold(0.0, f64::max);
    if host.len() != qemu.len() || host.is_empty() {
        problems.push(format!(
            "golden check: {} strides on the host, {} on QEMU",
            host.len(),
            qemu.len()
        ));
    } else if diff > PLANAR_GOLDEN_TOLERANCE {
        problems.push(format!(
            "golden check: a stride differs by {diff:.2e} (tolerance {PLANAR_GOLDEN_TOLERANCE:.0e})"
        ));
    }
    if !status {
        problems.push("the image exited with failure (a fall or a missed deadline)".into());
    }
    if missed != 0 {
        problems.push(format!("{missed} missed deadlines"));
    }
    if imax > STEP_MAX_CEILING {
        problems.push(format!(
            "control step max {imax} instructions exceeds the ceiling {STEP_MAX_CEILING}"
        ));
    }
    if imean > STEP_MEAN_BUDGET {
        problems.push(format!(
            "control step mean {imean} instructions exceeds the budget {STEP_MEAN_BUDGET}"
        ));
    }
    // The period in cycles, when the run was traced: the traced window
    // between the two clock readings around it.
    let cycles_txt = match traced.map(|t| step_cycles("qemu-planar", Some(t), (imean, imax))) {
        Some(Ok(c)) => c.to_string(),
        Some(Err(e)) => {
            problems.push(format!("cycle estimate: {e}"));
            "-".to_string()
        }
        None => {
            eprintln!(
                "xtask: qemu-planar: run untraced (`cargo xtask qemu-planar` weighs the period in cycles)"
            );
            "-".to_string()
        }
    };
    println!(
        "qemu-planar: strides={} golden_max_diff={diff:.2e} step_instr_min={imin} step_instr_mean={imean} step_instr_max={imax} missed={missed} step_cycles_est_max={cycles_txt}",
        qemu.len()
    );
    if problems.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "qemu planar scenario failed: {}",
            problems.join("; ")
        ))
    }
}

/// The scenario's step in cycles: the traced window between the two
/// clock readings around the step (the one whose instruction counts are
/// the run's own step `(mean, max)` plus the reading's overhead), its
/// largest.
fn step_cycles(
    label: &str,
    traced: Option<crate::cycles::Reader>,
    (mean, max): (u64, u64),
) -> Result<u64, String> {
    let traced = traced.ok_or("no trace read")?;
    let s = traced.segment_like(mean as f64, max)?;
    eprintln!(
        "xtask: {}: the step traced over {} periods: the window's instructions mean {:.1} max {} (the step's {mean}/{max} plus the reading's), cycles max {} ({:.2} a instruction), {} with every 16-byte flash line a miss once (5 wait states)",
        label,
        s.count,
        s.mean_instructions(),
        s.max_instructions,
        s.max_cycles,
        s.max_cycles as f64 / s.max_instructions.max(1) as f64,
        s.max_cold,
    );
    Ok(s.max_cycles)
}

/// The firmware's last `summary key=value ...` line, whole and as a map.
fn parse_summary(lines: &[String]) -> Option<(&str, BTreeMap<&str, &str>)> {
    let summary = lines
        .iter()
        .rev()
        .find_map(|l| l.strip_prefix("summary "))?;
    let kv = summary
        .split_whitespace()
        .filter_map(|w| w.split_once('='))
        .collect();
    Some((summary, kv))
}

/// Installs `qemu-system-arm` with apt-get when it is missing.
pub(crate) fn ensure_qemu() -> Result<(), String> {
    ensure_package("qemu-system-arm", "qemu-system-arm", false)
}

/// Installs Debian's `package` with apt-get (without its recommended
/// packages when `lean`) when `program --version` does not run.
pub(crate) fn ensure_package(program: &str, package: &str, lean: bool) -> Result<(), String> {
    if Command::new(program)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
    {
        return Ok(());
    }
    eprintln!("xtask: {program} not found; installing {package} with apt-get");
    let sudo = !matches!(
        Command::new("id").arg("-u").output().map(|o| o.stdout),
        Ok(ref out) if out.starts_with(b"0")
    );
    let apt = |args: &[&str]| -> bool {
        let mut cmd = if sudo {
            let mut c = Command::new("sudo");
            c.arg("apt-get");
            c
        } else {
            Command::new("apt-get")
        };
        cmd.args(args)
            .env("DEBIAN_FRONTEND", "noninteractive")
            .status()
            .is_ok_and(|s| s.success())
    };
    let install: &[&str] = if lean {
        &["install", "-y", "--no-install-recommends", package]
    } else {
        &["install", "-y", package]
    };
    let installed = apt(install) || (apt(&["update"]) && apt(install));
    if !installed {
        return Err(format!(
            "cannot install {package}: run `apt-get install -y {package}`"
        ));
    }
    Ok(())
}

/// `-icount` shift of the overrun check: every guest instruction takes
/// 2^5 = 32 virtual ns, so the 100 us period holds about 3,100 instructions,
/// fewer than a period's work (sensor models, control step, I/O, logging).
const OVERRUN_SHIFT: u32 = 5;

/// Timing fault: the same image on a guest slowed down until the control
/// period overruns. The firmware must count the missed deadlines, latch
/// `overrun` after `OVERRUN_LIMIT` in a row, disable the amplifier and
/// command 0 A from then on, and exit with failure.
fn overrun_check(elf: &Path) -> Result<(), String> {
    let ran = run_qemu(elf, OVERRUN_SHIFT)?;
    ran.print_notes();
    let (bytes, ok) = (ran.bytes, ran.ok);
    let lines = decode(elf, &bytes)?;
    let (summary, kv) = parse_summary(&lines).ok_or("the slowed-down run printed no summary")?;
    let get = |k: &str| kv.get(k).copied().unwrap_or("");
    let faults: u32 = get("faults").parse().unwrap_or(0);
    let missed: u32 = get("missed").parse().unwrap_or(0);
    let fault_period: i64 = get("fault_period").parse().unwrap_or(-1);
    let after: f64 = get("max_current_after_fault_a").parse().unwrap_or(f64::NAN);
    // Bit 8 of the fault set is `Fault::Overrun`.
    let overrun_latched = faults & (1 << 8) != 0;
    if ok || !overrun_latched || get("amp_enabled") != "false" || after != 0.0 || missed == 0 {
        return Err(format!(
            "expected a failing exit with `overrun` latched, the amplifier off and 0 A after the fault; got exit {}, {summary}",
            if ok { "success" } else { "failure" }
        ));
    }
    eprintln!(
        "xtask: overrun check (-icount shift={OVERRUN_SHIFT}, guest 32x slower): {missed} missed deadlines, `overrun` latched in period {fault_period}, amplifier disabled, max 0 A after the fault"
    );
    Ok(())
}

/// `qemu-system-arm` on the netduinoplus2 with `elf`, semihosting, `-icount
/// shift=SHIFT,sleep=off` and USART1 on the chardev `serial`.
pub(crate) fn qemu_command(elf: &Path, shift: u32, serial: &str) -> Command {
    let mut c = Command::new("qemu-system-arm");
    c.args([
        "-cpu",
        "cortex-m4",
        "-machine",
        "netduinoplus2",
        "-display",
        "none",
        "-monitor",
        "none",
        "-serial",
        serial,
        "-semihosting-config",
        "enable=on,target=native",
        "-icount",
        &format!("shift={shift},sleep=off"),
        "-kernel",
    ])
    .arg(elf);
    c
}

/// One QEMU run: the guest's stdout (the defmt stream), whether it exited
/// with success, the trace read when asked, and xtask's lines about the
/// run, kept to be printed with its report (runs go side by side).
struct Ran {
    bytes: Vec<u8>,
    ok: bool,
    traced: Option<crate::cycles::Reader>,
    notes: Vec<String>,
}

impl Ran {
    fn print_notes(&self) {
        for n in &self.notes {
            eprintln!("xtask: {n}");
        }
    }
}

/// Runs the planar image, traced: its period weighed in cycles as the
/// vertical scenarios' step is.
fn run_planar(elf: &Path) -> Result<Ran, String> {
    let trace = crate::cycles::marks_for(elf, "SysTick")?;
    run_qemu_traced(elf, 0, Some(trace))
}

/// Runs the image with `-icount shift=SHIFT`.
fn run_qemu(elf: &Path, shift: u32) -> Result<Ran, String> {
    run_qemu_traced(elf, shift, None)
}

/// [`run_qemu`], and with `trace` (marks and `-dfilter`) QEMU's execution
/// log of the firmware's code read as it runs (`cycles::Reader`).
fn run_qemu_traced(
    elf: &Path,
    shift: u32,
    trace: Option<(crate::cycles::Marks, String)>,
) -> Result<Ran, String> {
    let mut notes = vec![format!(
        "running {} on qemu-system-arm (netduinoplus2, -icount shift={shift}{})",
        elf.display(),
        if trace.is_some() {
            ", execution traced"
        } else {
            ""
        }
    )];
    let started = Instant::now();
    let mut cmd = qemu_command(elf, shift, "none");
    if let Some((_, dfilter)) = &trace {
        cmd.args(crate::cycles::qemu_args(dfilter));
        cmd.stderr(Stdio::piped());
    }
    let mut child = cmd
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm: {e}"))?;
    let mut out = child.stdout.take().ok_or("no stdout from qemu")?;
    let reader = std::thread::spawn(move || {
        let mut buf = Vec::new();
        let _ = out.read_to_end(&mut buf);
        buf
    });
    // The log, line by line as QEMU writes it (hundreds of megabytes:
    // never kept).
    let tracer = match (trace, child.stderr.take()) {
        (Some((marks, _)), Some(err)) => Some(crate::cycles::read_in_thread(marks, err)),
        _ => None,
    };
    let status = loop {
        match child.try_wait() {
            Ok(Some(s)) => break s,
            Ok(None) if started.elapsed() > QEMU_TIMEOUT => {
                let _ = child.kill();
                let _ = child.wait();
                return Err(format!("QEMU run timed out after {QEMU_TIMEOUT:?}"));
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(200)),
            Err(e) => return Err(format!("waiting for qemu: {e}")),
        }
    };
    let bytes = reader.join().map_err(|_| "reading qemu output failed")?;
    let traced = match tracer {
        Some(t) => Some(t.join().map_err(|_| "reading qemu's trace failed")?),
        None => None,
    };
    notes.extend(
        traced
            .iter()
            .flat_map(|t| &t.other)
            .map(|l| format!("qemu: {l}")),
    );
    notes.push(format!(
        "QEMU finished in {:.1} s ({status})",
        started.elapsed().as_secs_f64()
    ));
    Ok(Ran {
        bytes,
        ok: status.success(),
        traced,
        notes,
    })
}

/// Decodes a defmt byte stream with the ELF's format table.
pub(crate) fn decode(elf: &Path, bytes: &[u8]) -> Result<Vec<String>, String> {
    let image = std::fs::read(elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    let table = defmt_decoder::Table::parse(&image)
        .map_err(|e| format!("defmt table: {e}"))?
        .ok_or("the firmware has no defmt table")?;
    let mut decoder = table.new_stream_decoder();
    decoder.received(bytes);
    let mut lines = Vec::new();
    loop {
        match decoder.decode() {
            Ok(frame) => lines.push(frame.display_message().to_string()),
            Err(defmt_decoder::DecodeError::UnexpectedEof) => break,
            Err(defmt_decoder::DecodeError::Malformed) => {
                return Err(format!(
                    "malformed defmt frame after {} lines (is the ELF the one that ran?)",
                    lines.len()
                ))
            }
        }
    }
    Ok(lines)
}

/// Apex heights of the same scenario on the host.
///
/// `hopper-sim` is the workspace test build's (the one the link sessions
/// use): a release build of it, with fat LTO, took CI longer than both
/// scenarios' runs.
fn host_apexes(root: &Path, sim: &Path, scenario: &[&str]) -> Result<Vec<f64>, String> {
    let out = Command::new(sim)
        .arg("run")
        .args(scenario)
        .arg("--json")
        .current_dir(root)
        .output()
        .map_err(|e| format!("cannot run hopper-sim: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "host run failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)
        .map_err(|e| format!("host run printed no JSON: {e}"))?;
    v.get("apex_heights_m")
        .and_then(|a| a.as_array())
        .map(|a| a.iter().filter_map(serde_json::Value::as_f64).collect())
        .ok_or_else(|| "host JSON lacks apex_heights_m".to_string())
}

/// Max |difference| of two apex sequences; they must have the same length.
fn compare(host: &[f64], qemu: &[f64]) -> Result<f64, String> {
    if host.is_empty() || host.len() != qemu.len() {
        return Err(format!(
            "{} apexes on the host, {} in QEMU",
            host.len(),
            qemu.len()
        ));
    }
    let diff = host
        .iter()
        .zip(qemu)
        .map(|(h, q)| (h - q).abs())
        .fold(0.0, f64::max);
    if diff > GOLDEN_TOLERANCE_M {
        return Err(format!(
            "apexes differ by up to {diff:.2e} m (tolerance {GOLDEN_TOLERANCE_M:.0e} m)"
        ));
    }
    Ok(diff)
}
