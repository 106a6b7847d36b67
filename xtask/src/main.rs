//! Project automation, run from the workspace root as `cargo xtask <task>`.
//!
//! * `cargo xtask test`: everything CI checks, in order: toolchain set-up
//!   (rustup target and components from `rust-toolchain.toml`), formatting,
//!   clippy on the host and on the MCU target (the QEMU variant's takes in
//!   the `no_std` plant), the panic-never link check of the control
//!   period, the firmware release build with its size
//!   budget, the control crate's tests on their own (without the
//!   simulator's features), and the whole host test suite. It ends with a
//!   `xtask: N passed, M failed` line counting the tests of every run
//!   (the control crate alone, the workspace, the fuzz target's stable tests).
//! * `cargo xtask size`: build the board firmware with defmt and check its size
//!   budget: `size: flash=N ram=M capture=C` (bytes); then, from its
//!   machine code ([`stack`]), `stack: control=N ... bytes (budget B)` and
//!   `isolation: panic_paths=none ... critical_section=basepri` (no task
//!   can panic; the control and serial interrupts take no critical
//!   section and mask nothing).
//! * `cargo xtask qemu`: build the QEMU variant (`--features qemu-sim`), run
//!   the closed-loop scenarios in `qemu-system-arm` (installing it with
//!   apt-get if missing), decode their defmt logs, check each against the
//!   host simulation of the same scenario (the golden check) and the
//!   instruction budget. The `shaped` scenario prints `qemu-shaped: ...`,
//!   its heat-aware mode `qemu-heat-aware: ...`;
//!   the last line is `qemu: steady_apex_m=... hops_to_converge=...
//!   step_instr_min=... step_instr_mean=... step_instr_max=... missed=...
//!   stack_peak_b=... log_frame_instr_max=... step_cycles_est_max=...
//!   cs_masks_control=false` (the energy-apex scenario; the step in
//!   estimated Cortex-M4 cycles from QEMU's execution trace, [`cycles`]). Before the scenarios it runs the link
//!   session (`tests/link-session.txt`) with `hopper-link` against the QEMU
//!   link image: `qemu-link: steady_apex_m=... records=... dropped=...
//!   link_lost_s=... frames_bad=... step_instr_mean=... step_instr_max=...
//!   link_instr_mean=... link_instr_max=... isr_instr_mean=...
//!   isr_instr_max=... flood_requests=... flood_isr_instr_max=... ...
//!   isr_cycles_est_max=...`, and the bring-up order on a fresh image,
//!   `qemu-link-bringup: missed=0 faults=none start_jitter_max_us=...`. Then
//!   the board image's init
//!   on QEMU with `-d unimp`, checked against `tests/board-init.trace`:
//!   `board-init: writes=... polled_registers=... longest_poll_reads=...
//!   terminated=... golden=...`, and the same for the Feather's pin map
//!   against `tests/board-init-feather.trace`: `board-init-feather: ...`;
//!   then the HardFault entry on both maps: `fault-test: ...`,
//!   `fault-test-feather: ...`; then the planar machine's controller on
//!   its image against the host's run of the same loop: `qemu-planar:
//!   strides=N golden_max_diff=D step_instr_min=.. step_instr_mean=..
//!   step_instr_max=.. missed=0 step_cycles_est_max=-` (untraced; `cargo
//!   xtask qemu-planar` runs it alone, traced, the period in cycles).
//! * `cargo xtask board-init`: the board image's init check alone.
//! * `cargo xtask hil [--serial PORT]`: the hardware-in-the-loop image
//!   (`hopper-hil`) on QEMU (or a board on PORT) against `hopper-sim run
//!   --hil`, its apexes checked against the host run of the same scenario,
//!   and on QEMU a run that loses a frame, which must stop with its error
//!   and write nothing: `hil: apexes=N max_diff_m=X frames_per_s=Y
//!   isr_max=Z`. Part of `cargo xtask test`, after `qemu`.
//! * `cargo xtask docs`: every `console` example in README.md and docs/
//!   run and compared with the output the doc shows, and the figures they
//!   regenerate compared with the committed ones ([`docs`]): `docs: N
//!   commands checked, M stale` (`cargo xtask test` runs it after the
//!   cockpit, its release simulator built beside the link sessions;
//!   `cargo xtask docs FILE.md...` checks only those files).
//! * `cargo xtask bring-up-page`: the book's bring-up page followed as
//!   written against the virtual robot it starts ([`bringup_page`]):
//!   `bring-up-page: commands=N save=accepted steady_apex_m=A target_m=T`.
//! * `cargo xtask book`: the user guide built as a book (`mdbook build
//!   docs`, mdBook installed when missing) and every link inside it
//!   followed ([`book`]): `book: N pages, M internal links checked, K
//!   broken`.
//! * `cargo xtask robot-file`: one robot file (tests/robots/heavy.toml)
//!   on `hopper-sim run --robot` and on `serve --robot` driven by
//!   `hopper-link` (sets, a refused file, the round trip, the hops
//!   compared): `robot-file: ...` (`cargo xtask test` runs it after the
//!   noisy link).
//! * `cargo xtask new-law NAME`: a new control law from the template,
//!   registered with one line ([`new_law`], docs/laws.md).
//! * `cargo xtask link-session`: the same session against `hopper-sim
//!   serve` (the virtual robot), `link-sim: ...` (`cargo xtask test` runs
//!   it after the QEMU runs).
//! * `cargo xtask cockpit`: `hopper-link ui` in headless chromium
//!   (installed when missing) against `hopper-sim serve`, driven through
//!   the DevTools protocol: `cockpit: loaded=... moved=... arm=...
//!   refused=... disarm=...`, then the planar machine behind the link
//!   (`hopper-sim planar serve --tcp`) in the same cockpit and browser:
//!   `cockpit-planar: drawn_heights=N drawn_phases=2 armed="armed"
//!   disarmed="disarmed (command)" recorded_files=2` (`cargo xtask test`
//!   runs it after the session).
//! * `cargo xtask slurm`: a sharded sweep on a one-node Slurm cluster
//!   (Debian's slurmctld, slurmd and MUNGE, installed when missing and
//!   started by hand): the job array `hopper-sim sweep --slurm` writes,
//!   its merge byte for byte the unsharded sweep, and a failed task
//!   reported with its shard and log while the merge refuses the
//!   incomplete set: `slurm: tasks=N runs=M merged=identical
//!   failed_task=K merge_refused=yes` (`cargo xtask test` runs it after
//!   the cockpit).
//! * `cargo xtask speed`: the release simulator's speed on this machine,
//!   hopping and at rest side by side: `speed: hopping=Nx at_rest=Mx
//!   ratio=R` (reported, not asserted; `cargo xtask test` runs it after
//!   the Slurm run).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};

mod board_init;
mod book;
mod bringup_page;
mod cockpit;
mod cycles;
mod docs;
mod hil;
mod new_law;
mod noisy;
mod qemu;
mod robot_file;
mod session;
mod slurm;
mod speed;
mod stack;

const TARGET: &str = "thumbv7em-none-eabihf";

/// Flash budget for the board image with defmt (text + data), bytes:
/// 144 KiB of the 768 KiB the image may take (the last two 128 KiB
/// sectors of the STM32F405's 1 MiB hold the saved calibration,
/// `memory.x`). The image holds every controller's constructor and
/// validation (the controller is chosen at run time), the host link (the
/// postcard encoders and decoders of every message, the endpoint, the
/// parameter table's names and units for `params list`; its docs stay on
/// the host), the USART driver, the thermal protection, the e-stop
/// debounce, the boot report, the bring-up routines and the flash store
/// (sequential-storage's map, monomorphised for the internal flash, and
/// the driver), with `info`-level defmt logging; `cargo xtask size` prints
/// what it takes. The store's crates are not built for size: `opt-level =
/// "z"` for them saves only 1.6 KB, since under fat LTO their generic code
/// is the application's. It was 128 KiB until the machine's constants
/// became parameters (their entries, the table's slots by group) left
/// 1 KB: 144 KiB leaves room for laws added with `cargo xtask new-law`.
/// How the image grew: docs/history.md.
const FLASH_BUDGET_BYTES: u64 = 144 * 1024;
/// Static RAM budget (data + bss) without the telemetry capture buffer,
/// bytes: the link's queues, three controller slots, the parameter bank
/// and the flash store's buffers (docs/history.md: how it grew).
const RAM_BUDGET_BYTES: u64 = 17 * 1024;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let root = workspace_root();
    let result = match args.first().map(String::as_str) {
        Some("test") => test(&root),
        Some("size") => setup(&root).and_then(|_| size(&root)),
        Some("qemu") => setup(&root)
            .and_then(|_| qemu::start(&root))
            .and_then(|ahead| qemu::run(&root, ahead)),
        Some("qemu-planar") => setup(&root).and_then(|_| qemu::planar(&root)),
        Some("link-session") => session::against_serve(&root),
        Some("noisy-link") => setup(&root).and_then(|_| noisy::run(&root, true)),
        Some("robot-file") => setup(&root).and_then(|_| robot_file::run(&root)),
        Some("new-law") => match args.get(1) {
            Some(name) => new_law::run(&root, name),
            None => Err("usage: cargo xtask new-law NAME (e.g. my-thrust)".into()),
        },
        Some("cockpit") => setup(&root).and_then(|_| cockpit::run(&root)),
        Some("slurm") => slurm::run(&root),
        Some("speed") => speed::run(&root),
        Some("board-init") => setup(&root)
            .and_then(|_| qemu::ensure_qemu())
            .and_then(|_| board_init::run(&root)),
        Some("hil") => {
            let serial = match &args[1..] {
                [] => Ok(None),
                [flag, port] if flag == "--serial" => Ok(Some(port.as_str())),
                _ => Err("usage: cargo xtask hil [--serial PORT]".to_string()),
            };
            serial.and_then(|s| setup(&root).and_then(|_| hil::run(&root, s)))
        }
        Some("docs") => docs_check(&root, &args[1..]),
        Some("book") => book::run_check(&root),
        Some("bring-up-page") => bringup_page::run(&root),
        _ => {
            eprintln!(
                "usage: cargo xtask <test|size|qemu|hil|link-session|noisy-link|robot-file|new-law NAME|cockpit|slurm|speed|board-init|docs>"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: FAILED: {e}");
            ExitCode::FAILURE
        }
    }
}

fn workspace_root() -> PathBuf {
    let manifest = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    manifest.parent().map(Path::to_path_buf).unwrap_or(manifest)
}

fn cargo() -> Command {
    Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
}

/// Prints how long a step took (`xtask: WHAT: N.N s`), so the suite's
/// time can be kept within its budget step by step.
fn took(what: &str, started: std::time::Instant) {
    eprintln!("xtask: {what}: {:.1} s", started.elapsed().as_secs_f64());
}

fn run(root: &Path, what: &str, cmd: &mut Command) -> Result<(), String> {
    eprintln!("xtask: {what}");
    let started = std::time::Instant::now();
    let status = cmd
        .current_dir(root)
        .status()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    took(what, started);
    if status.success() {
        Ok(())
    } else {
        Err(format!("{what} ({status})"))
    }
}

/// Runs the `cargo build` in `cmd` and returns the path of the executable
/// `bin` it built, as cargo's own JSON messages name it (diagnostics still
/// go to the terminal, rendered as usual).
fn build_executable(
    root: &Path,
    what: &str,
    bin: &str,
    cmd: &mut Command,
) -> Result<PathBuf, String> {
    let [exe] = build_executables(root, what, [bin], cmd)?;
    Ok(exe)
}

/// Like [`build_executable`], for several executables of one cargo run.
fn build_executables<const N: usize>(
    root: &Path,
    what: &str,
    bins: [&str; N],
    cmd: &mut Command,
) -> Result<[PathBuf; N], String> {
    eprintln!("xtask: {what}");
    let started = std::time::Instant::now();
    let out = cmd
        .arg("--message-format=json-render-diagnostics")
        .current_dir(root)
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("{what}: cannot start: {e}"))?;
    took(what, started);
    if !out.status.success() {
        return Err(format!("{what} ({})", out.status));
    }
    let messages: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let mut found = Vec::with_capacity(N);
    for bin in bins {
        let exe = messages
            .iter()
            .filter(|m| {
                m["reason"] == "compiler-artifact"
                    && m["target"]["name"] == bin
                    && m["profile"]["test"] == false
            })
            .find_map(|m| m["executable"].as_str().map(PathBuf::from))
            .ok_or_else(|| format!("{what}: cargo reported no executable `{bin}`"))?;
        found.push(exe);
    }
    found
        .try_into()
        .map_err(|_| format!("{what}: executables missing"))
}

/// The target directory of every firmware image but the default board
/// image: QEMU's, the other pin map's and the fault tests'. They share
/// their dependencies' builds (each image is used before the next build
/// replaces a binary of the same name); the default board image keeps
/// cargo's usual path, the one the docs tell a user to flash.
fn images_dir(root: &Path) -> Result<PathBuf, String> {
    Ok(target_dir(root)?.join("images"))
}

/// The workspace's target directory as cargo resolves it (CARGO_TARGET_DIR,
/// `build.target-dir`, else `ROOT/target`), for builds that pass their own
/// `--target-dir` under it. A relative CARGO_TARGET_DIR is taken from `root`,
/// where every cargo command of xtask runs.
fn target_dir(root: &Path) -> Result<PathBuf, String> {
    let out = cargo()
        .args(["metadata", "--format-version", "1", "--no-deps"])
        .current_dir(root)
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cargo metadata: cannot start: {e}"))?;
    if !out.status.success() {
        return Err(format!("cargo metadata ({})", out.status));
    }
    serde_json::from_slice::<serde_json::Value>(&out.stdout)
        .ok()
        .and_then(|m| m["target_directory"].as_str().map(PathBuf::from))
        .ok_or_else(|| "cargo metadata printed no target_directory".to_string())
}

/// Install what a fresh machine lacks: the MCU target and the components
/// `rust-toolchain.toml` names (rustup does not add them to an installed
/// toolchain by itself). Idempotent.
fn setup(root: &Path) -> Result<(), String> {
    ensure_flip_link(root)?;
    if Command::new("rustup").arg("--version").output().is_err() {
        eprintln!("xtask: rustup not found; assuming the toolchain is complete");
        return Ok(());
    }
    run(
        root,
        "rustup target add",
        Command::new("rustup").args(["target", "add", TARGET]),
    )?;
    run(
        root,
        "rustup component add",
        Command::new("rustup").args(["component", "add", "rustfmt", "clippy", "llvm-tools"]),
    )
}

/// The MCU images link through flip-link (`.cargo/config.toml`): installs
/// it when missing (a few seconds of `cargo install`).
pub(crate) fn ensure_flip_link(root: &Path) -> Result<(), String> {
    if Command::new("flip-link").arg("--version").output().is_ok() {
        return Ok(());
    }
    run(
        root,
        "cargo install flip-link",
        cargo().args(["install", "flip-link", "--locked"]),
    )
}

fn test(root: &Path) -> Result<(), String> {
    setup(root)?;
    run(
        root,
        "cargo fmt --check",
        cargo().args(["fmt", "--all", "--", "--check"]),
    )?;
    // The QEMU scenarios run on one core while the steps below compile
    // and check on the others; `qemu::run` reports them in their place.
    let ahead = qemu::start(root)?;
    run(
        root,
        "clippy (host)",
        cargo().args([
            "clippy",
            "--workspace",
            "--all-targets",
            "--",
            "-D",
            "warnings",
        ]),
    )?;
    mcu_clippy(
        root,
        "clippy (MCU target)",
        &[
            "-p",
            "hopper-model",
            "-p",
            "hopper-control",
            "-p",
            "hopper-robot-link",
            "-p",
            "hopper-protocol",
        ],
    )?;
    // The control period linked with a panic handler that calls an undefined
    // function (`firmware/app/src/bin/panic-check.rs`): a panic path the
    // optimiser cannot remove fails the link.
    run(
        root,
        "panic-never link check (MCU target)",
        cargo().args([
            "build",
            "-p",
            "hopper-app",
            "--bin",
            "panic-check",
            "--release",
            "--target",
            TARGET,
        ]),
    )?;
    // The 12 MHz crystal profile: its PLL constants pass the
    // same compile-time checks.
    mcu_clippy(
        root,
        "clippy (MCU target, 12 MHz crystal profile)",
        &["--features", "hse-12mhz"],
    )?;
    // The Adafruit Feather's pin map (its timers, channels and USART are
    // other PAC types; `cargo xtask board-init` runs its init on QEMU).
    mcu_clippy(
        root,
        "clippy (MCU target, Feather pin map)",
        &["--features", "feather"],
    )?;
    // The QEMU variant pulls in the plant: this also checks that
    // `hopper-plant` builds `no_std` for the MCU (the QEMU images then build
    // it for real).
    mcu_clippy(
        root,
        "clippy (MCU target, QEMU variant)",
        &["--no-default-features", "--features", "qemu-sim"],
    )?;
    // The simulated hopper on the chip (`hopper-sih`): the plant for the
    // MCU with the board's logger.
    mcu_clippy(
        root,
        "clippy (MCU target, the simulated hopper on the chip)",
        &["--features", "sih"],
    )?;
    // The on-target self-test image links (the default features' clippy
    // above checked its source).
    run(
        root,
        "self-test image build (MCU target)",
        cargo().args([
            "build",
            "-p",
            "hopper-app",
            "--bin",
            "hopper-selftest",
            "--release",
            "--target",
            TARGET,
        ]),
    )?;
    size(root)?;
    // The workspace's test build first (it is `qemu::run`'s first step,
    // which then finds it done; a failure is reported there): the
    // low-priority builds must not slow it, only fill what the QEMU
    // sessions leave of the cores.
    let _ = session::host_binaries(root);
    let prebuilt = prebuild(root);
    qemu::run(root, ahead)?;
    hil::run(root, None)?;
    session::against_serve(root)?;
    bringup_page::run(root)?;
    noisy::run(root, true)?;
    robot_file::run(root)?;
    cockpit::run(root)?;
    // The release simulator they run was built at low priority beside the
    // QEMU sessions (`prebuild`); cargo finishes it here if it is not done.
    docs_check(root, &[])?;
    book::run_check(root)?;
    slurm::run(root)?;
    speed::run(root)?;
    if let Some(mut child) = prebuilt {
        let started = std::time::Instant::now();
        // Its outcome is the tests' to report: they build what it did not.
        let _ = child.wait();
        took("waiting for the tests built at low priority", started);
    }
    cargo_test(root)
}

/// The release simulator (for the docs' examples, the Slurm run and the
/// speed figure), then the control crate's test build on its own
/// features and the fuzz crate's, started at the lowest priority (`nice
/// -n 19`) to take what the QEMU sessions and the steps after them leave
/// of the cores (a session's QEMU keeps about one and a half busy): the
/// steps after them then only run. Each builds in a target directory of
/// its own, so cargo's lock on the workspace's stays free. Its output goes
/// to `prebuild.log` in the target directory; `None` when it cannot start
/// (the tests then build as before).
fn prebuild(root: &Path) -> Option<std::process::Child> {
    let target = target_dir(root).ok()?;
    let log = std::fs::File::create(target.join("prebuild.log")).ok()?;
    let err = log.try_clone().ok()?;
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    Command::new("nice")
        .args(["-n", "19", "sh", "-c"])
        .arg(
            "\"$0\" build $3 --target-dir \"$2\"; \
             \"$0\" test -p hopper-control --target-dir \"$1\" --no-run; \
             \"$0\" test --manifest-path fuzz/Cargo.toml --no-run",
        )
        .arg(cargo)
        .arg(control_target_dir(&target))
        .arg(sim_target_dir(&target))
        .arg(RELEASE_SIM.join(" "))
        .current_dir(root)
        .stdout(log)
        .stderr(err)
        .spawn()
        .ok()
}

/// The control crate's own-feature test build's target directory.
fn control_target_dir(target: &Path) -> PathBuf {
    target.join("control")
}

/// The docs' examples against the release `hopper-sim` they name; `only`
/// (markdown paths from the root) limits the check to those files.
fn docs_check(root: &Path, only: &[String]) -> Result<(), String> {
    let sim = release_sim(root, "hopper-sim release build (for the docs' examples)")?;
    docs::check(root, &sim, only)
}

/// The release `hopper-sim`'s build arguments after `cargo build`:
/// without the `live-page` feature (`planar serve`, which none of the
/// steps running this build runs and whose web stack's fat-LTO build
/// cost CI about 50 s); the test build's `hopper-sim` has it.
const RELEASE_SIM: [&str; 6] = [
    "--release",
    "-p",
    "hal-sim",
    "--bin",
    "hopper-sim",
    "--no-default-features",
];

/// The release `hopper-sim`'s target directory (of its own: `prebuild`
/// builds it at low priority while other steps build in the workspace's).
fn sim_target_dir(target: &Path) -> PathBuf {
    target.join("sim")
}

/// The release `hopper-sim` (the docs' examples, the Slurm run and the
/// speed figures run it), built if it is not current.
fn release_sim(root: &Path, what: &str) -> Result<PathBuf, String> {
    let target = target_dir(root)?;
    build_executable(
        root,
        what,
        "hopper-sim",
        cargo()
            .arg("build")
            .args(RELEASE_SIM)
            .arg("--target-dir")
            .arg(sim_target_dir(&target)),
    )
}

/// `cargo clippy -p hopper-app --target MCU EXTRA -- -D warnings`.
fn mcu_clippy(root: &Path, what: &str, extra: &[&str]) -> Result<(), String> {
    run(
        root,
        what,
        cargo()
            .args(["clippy", "-p", "hopper-app", "--target", TARGET])
            .args(extra)
            .args(["--", "-D", "warnings"]),
    )
}

/// The board image (default features), built: the image cargo reports
/// having just built, not a path guessed from `target/` (with
/// CARGO_TARGET_DIR set, or `build.target-dir`, the guess fails on a fresh
/// clone and reads a stale image on an old one).
fn board_image(root: &Path) -> Result<PathBuf, String> {
    ensure_flip_link(root)?;
    build_executable(
        root,
        "firmware release build",
        "hopper-fw",
        &mut hopper_fw_build(),
    )
}

/// `cargo build` of the board image, `hopper-fw`, in release for the MCU:
/// the default image here, the other pin maps and the fault test add
/// their features and target directories.
fn hopper_fw_build() -> Command {
    let mut cmd = cargo();
    cmd.args([
        "build",
        "-p",
        "hopper-app",
        "--bin",
        "hopper-fw",
        "--release",
        "--target",
        TARGET,
    ]);
    cmd
}

fn size(root: &Path) -> Result<(), String> {
    let elf = board_image(root)?;
    let text = llvm_tool("llvm-size", &[], &elf)?;
    // Berkeley format: "text data bss dec hex filename".
    let nums: Vec<u64> = text
        .lines()
        .nth(1)
        .unwrap_or("")
        .split_whitespace()
        .take(3)
        .filter_map(|s| s.parse().ok())
        .collect();
    let [t, d, b] = nums[..] else {
        return Err(format!("cannot parse llvm-size output: {text}"));
    };
    let (flash, ram) = (t + d, d + b);
    let capture = capture_bytes(&elf)?;
    let ok = flash <= FLASH_BUDGET_BYTES && ram <= RAM_BUDGET_BYTES + capture;
    eprintln!(
        "xtask: size budget: flash <= {FLASH_BUDGET_BYTES} B, ram <= {RAM_BUDGET_BYTES} B + capture (text={t} data={d} bss={b}){}",
        if ok { "" } else { ": EXCEEDED" }
    );
    println!("size: flash={flash} ram={ram} capture={capture}");
    if !ok {
        return Err("firmware exceeds its size budget".into());
    }
    stack_bound(&elf, RAM_BYTES.saturating_sub(ram))
}

/// The board's RAM (memory.x: SRAM1 and SRAM2, 128 KiB); the stack has
/// what the statics leave.
const RAM_BYTES: u64 = 128 * 1024;

/// An exception's stacked frame with the FPU's state reserved (lazy
/// stacking): 26 words.
const EXCEPTION_FRAME_BYTES: u64 = 104;

/// The worst-case stack per task of the board image (`stack::depth` on its
/// disassembly): prints `stack: control=N link=N serial=N logger=N idle=N
/// init=N worst=N bytes (budget B); largest frame F (N B)`, and fails when
/// the worst case (idle, then every priority level's task preempting the
/// one below, each with an exception frame) or `init` exceeds the budget,
/// or when a task's depth cannot be bounded (an indirect call, recursion).
fn stack_bound(elf: &Path, budget: u64) -> Result<(), String> {
    let stack::Image { funcs, taken, .. } = stack::Image::read(elf)?;
    // The board image's handlers (src/main.rs): the control task on the
    // ADC's interrupt (priority 3), the link task on SDIO's (2), the
    // serial interrupt on USART1's (4), the logger and the dump on the
    // priority-1 dispatcher; `main` runs `init`, then idle's loop, which
    // calls nothing.
    let task = |entry: &str| {
        stack::depth(&funcs, &taken, entry).map_err(|e| format!("stack: {entry}: {e}"))
    };
    let (control, control_path) = task("ADC")?;
    let (link, _) = task("SDIO")?;
    let (serial, _) = task("USART1")?;
    // The logger on CAN2_RX1's vector (main.rs's `LOGGER_IRQ`).
    let (logger, _) = task("CAN2_RX1")?;
    let (init, _) = task("main")?;
    let idle = funcs.get("main").map_or(0, |f| f.frame);
    let worst = idle
        + [logger, link, control, serial]
            .iter()
            .map(|d| d + EXCEPTION_FRAME_BYTES)
            .sum::<u64>();
    let (largest, largest_frame) = funcs
        .iter()
        .map(|(n, f)| (n.as_str(), f.frame))
        .max_by_key(|(_, b)| *b)
        .unwrap_or(("-", 0));
    let ok = worst <= budget && init <= budget;
    let short = |n: &str| format!("{:#}", rustc_demangle::demangle(n));
    let isolation = isolation(&funcs, &taken);
    let largest = short(largest);
    eprintln!(
        "xtask: stack: the control task's deepest path: {}",
        control_path
            .iter()
            .map(|n| short(n))
            .collect::<Vec<_>>()
            .join(" > ")
    );
    println!(
        "stack: control={control} link={link} serial={serial} logger={logger} idle={idle} init={init} worst={worst} bytes (budget {budget}); largest frame {largest} ({largest_frame} B)"
    );
    let isolation = isolation?;
    println!("{isolation}");
    if ok {
        Ok(())
    } else {
        Err(format!(
            "the stack's worst case ({worst} B, init {init} B) exceeds its room ({budget} B)"
        ))
    }
}

/// What the board image's tasks can reach, from its call graph: no task
/// reaches the panic handler (the board's own types, the RTIC glue and
/// the libraries as linked, beyond `panic-check`'s control period), and
/// neither the control task nor the serial interrupt takes a critical
/// section or masks interrupts, which is what makes the image's BASEPRI
/// critical section (masking the tasks below them) exclusive. Prints
/// `isolation: panic_paths=none masking=none critical_section=basepri(0xe0)
/// masks=1-2`, or fails naming the path.
fn isolation(
    funcs: &std::collections::HashMap<String, stack::Function>,
    taken: &[u64],
) -> Result<String, String> {
    let short = |n: &str| format!("{:#}", rustc_demangle::demangle(n));
    let path = |p: Vec<String>| p.iter().map(|n| short(n)).collect::<Vec<_>>().join(" > ");
    let is_panic =
        |n: &str| n.ends_with("rust_begin_unwind") || short(n).starts_with("core::panicking::");
    let is_cs = |n: &str| short(n).ends_with("critical_section::Impl>::acquire");
    let masks = |n: &str| funcs.get(n).is_some_and(|f| f.masks_all);
    let tasks = [
        ("control", "ADC"),
        ("serial", "USART1"),
        ("link", "SDIO"),
        ("logger", "CAN2_RX1"),
    ];
    // defmt-rtt's two guards (a frame begun inside a frame, a frame ended
    // that never began) are the logger's only panics: left out, because
    // the tasks that could begin a frame inside one (control, serial) are
    // shown below never to take the critical section a frame holds.
    let panic_at: std::collections::HashSet<u64> = funcs
        .iter()
        .filter(|(n, _)| is_panic(n))
        .map(|(_, f)| f.addr)
        .collect();
    let mut guarded = funcs.clone();
    for n in ["_defmt_acquire", "_defmt_release"] {
        if let Some(f) = guarded.get_mut(n) {
            f.calls.retain(|a| !panic_at.contains(a));
        }
    }
    for (task, entry) in tasks {
        if let Some(p) = stack::reaches(&guarded, taken, entry, &is_panic) {
            return Err(format!("isolation: the {task} task can panic: {}", path(p)));
        }
    }
    for (task, entry) in &tasks[..2] {
        if let Some(p) = stack::reaches(funcs, taken, entry, &|n| is_cs(n) || masks(n)) {
            return Err(format!(
                "isolation: the {task} task takes a critical section or masks interrupts: {}",
                path(p)
            ));
        }
    }
    // The critical section in use raises BASEPRI and never masks all.
    let acquire: Vec<_> = funcs.iter().filter(|(n, _)| is_cs(n)).collect();
    let [(name, f)] = acquire[..] else {
        return Err(format!(
            "isolation: expected one critical-section acquire, found {}",
            acquire.len()
        ));
    };
    if f.masks_all || !f.raises_basepri {
        return Err(format!(
            "isolation: {} does not raise BASEPRI alone (masks all: {})",
            short(name),
            f.masks_all
        ));
    }
    Ok("isolation: panic_paths=none (control serial link logger; defmt-rtt's frame guards left out) masking=none (control serial) critical_section=basepri".to_string())
}

/// Size of the telemetry capture buffer, bytes: the board's `init` local
/// `capture` (built in place; a shared resource named `capture` matches
/// too).
fn capture_bytes(elf: &Path) -> Result<u64, String> {
    llvm_tool("llvm-nm", &["-S", "-C"], elf)?
        .lines()
        .find(|l| l.contains("local_init_capture") || l.contains("shared_resource_capture"))
        .and_then(|l| u64::from_str_radix(l.split_whitespace().nth(1)?, 16).ok())
        .ok_or_else(|| "no capture buffer symbol in the firmware".to_string())
}

/// What the LLVM tool `name` (of the `llvm-tools` component) prints for
/// `args` and the image `elf`; its error output when it fails.
pub(crate) fn llvm_tool(name: &str, args: &[&str], elf: &Path) -> Result<String, String> {
    let tool = llvm_size()?.with_file_name(name);
    let out = Command::new(&tool)
        .args(args)
        .arg(elf)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", tool.display()))?;
    if !out.status.success() {
        return Err(format!(
            "{name} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

fn llvm_size() -> Result<PathBuf, String> {
    let out = Command::new("rustc")
        .args(["--print", "sysroot"])
        .output()
        .map_err(|e| format!("rustc --print sysroot: {e}"))?;
    let sysroot = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    let lib = sysroot.join("lib").join("rustlib");
    let found = std::fs::read_dir(&lib)
        .map_err(|e| format!("{}: {e}", lib.display()))?
        .filter_map(Result::ok)
        .map(|d| d.path().join("bin").join("llvm-size"))
        .find(|p| p.exists());
    found.ok_or_else(|| "llvm-size not found: run `rustup component add llvm-tools`".into())
}

/// Run the host test suites, echoing their output and counting the results
/// into one `xtask: N passed, M failed` line.
///
/// The control crate runs first on its own: in the workspace run it is
/// built with the features hal-sim turns on (`fault-injection`, `serde`),
/// so only this run tests it as the firmware builds it.
fn cargo_test(root: &Path) -> Result<(), String> {
    // In a target directory of its own: built there at low priority
    // while the QEMU sessions ran ([`prebuild`]).
    let control_dir = control_target_dir(&target_dir(root)?);
    let control = counted_cargo_test(
        root,
        &[
            "test",
            "-p",
            "hopper-control",
            "--target-dir",
            &control_dir.to_string_lossy(),
        ],
    )?;
    let workspace = counted_cargo_test(root, &["test", "--workspace"])?;
    // The fuzz target's logic on stable, over seeded inputs and the kept
    // regressions (the fuzz crate is outside the workspace: it needs
    // libFuzzer to fuzz, not to test).
    let fuzz = counted_cargo_test(root, &["test", "--manifest-path", "fuzz/Cargo.toml"])?;
    let runs = [&control, &workspace, &fuzz];
    let passed: u64 = runs.iter().map(|r| r.passed).sum();
    let failed: u64 = runs.iter().map(|r| r.failed).sum();
    println!("xtask: {passed} passed, {failed} failed");
    for run in runs {
        if !run.status.success() || run.failed > 0 {
            return Err(format!("{} ({})", run.what, run.status));
        }
    }
    Ok(())
}

/// What one `cargo test` run reported.
struct TestRun {
    /// The command, for messages.
    what: String,
    /// Tests passed, summed over its `test result:` lines.
    passed: u64,
    /// Tests failed, summed likewise.
    failed: u64,
    /// Cargo's exit status: a failure with no failed test is a test binary
    /// that did not build, which no `test result:` line shows.
    status: std::process::ExitStatus,
}

/// Runs `cargo ARGS`, echoing its output and counting its results.
fn counted_cargo_test(root: &Path, args: &[&str]) -> Result<TestRun, String> {
    let what = format!("cargo {}", args.join(" "));
    eprintln!("xtask: {what}");
    let started = std::time::Instant::now();
    let mut child = cargo()
        .args(args)
        .current_dir(root)
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start {what}: {e}"))?;
    let (mut passed, mut failed) = (0u64, 0u64);
    if let Some(out) = child.stdout.take() {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            println!("{line}");
            if let Some(rest) = line.strip_prefix("test result: ") {
                let mut words = rest.split([' ', ';']).filter(|w| !w.is_empty());
                while let Some(w) = words.next() {
                    if let Ok(n) = w.parse::<u64>() {
                        match words.next() {
                            Some("passed") => passed += n,
                            Some("failed") => failed += n,
                            _ => {}
                        }
                    }
                }
            }
        }
    }
    let status = child.wait().map_err(|e| format!("{what}: {e}"))?;
    took(&what, started);
    Ok(TestRun {
        what,
        passed,
        failed,
        status,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn target_dir_follows_cargo_target_dir() {
        // This test's own build directory is the one cargo resolved.
        let root = workspace_root();
        let dir = target_dir(&root).unwrap_or_default();
        assert!(dir.is_absolute(), "{}", dir.display());
        let expected = match std::env::var_os("CARGO_TARGET_DIR") {
            Some(d) => root.join(d),
            None => root.join("target"),
        };
        assert_eq!(dir, expected);
    }
}
