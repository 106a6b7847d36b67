//! The board image's `init` executed in QEMU: `board.rs` runs
//! on no test rig otherwise, since the QEMU images replace the board with
//! simulated I/O.
//!
//! netduinoplus2 models no RCC, GPIO, DAC or IWDG: QEMU logs every access
//! to them with `-d unimp`, which makes the log a trace of the board's
//! register writes, in order. With no RCC model every ready flag reads 0:
//! the first clock wait (HSIRDY) times out, so `configure_clocks` stays on
//! the HSI as it does when the crystal never starts, and the LSI never
//! becomes ready, so the run is also the test that `init`'s waits are
//! bounded and it still starts the watchdog. (The HSE-specific branch,
//! HSI ready and HSE not, is beyond QEMU 7.2: it would need an RCC model.) The ADC's injected group is not modelled
//! either, so the control task never runs, and the trace ends with the
//! watchdog's first reload.
//!
//! The same runs for each pin map (`firmware/app/src/pinmap.rs`): the
//! default (Olimex STM32-H405) against `tests/board-init.trace`, the
//! Adafruit Feather's (`--features feather`) against
//! `tests/board-init-feather.trace`, whose deadman (TIM12) and motor
//! encoder (TIM8) QEMU does not model, so their writes are traced too.
//!
//! The trace (writes by device and register, and the polled registers,
//! each poll run collapsed to one line) must equal the map's golden file;
//! `HOPPER_UPDATE_GOLDEN=1 cargo xtask qemu` rewrites it after a deliberate
//! change. Beyond the equality, the properties that matter are checked by
//! name, so a failure says which one broke: AMP_EN (the map's pin) driven
//! low before the pin becomes an output; the deadman's output forced low
//! before AMP_EN becomes its pin (where the timer is traced); the DAC's zero-current code written before
//! the DAC is enabled; the alternate functions of the encoder, USART and
//! analog pins; the watchdog's key order (unlock, prescaler, reload, start,
//! reload); every wait bounded. The ADC trigger selection is in a register
//! QEMU models (so not in the trace): `board.rs`'s host tests cover it.

use std::fmt::Write as _;
use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

/// A pin map of the board image (`firmware/app/src/pinmap.rs`): what its
/// init must do, by name.
#[derive(Debug)]
struct Map {
    /// The summary line's prefix.
    line: &'static str,
    /// The image's cargo feature (`None`: the default map).
    feature: Option<&'static str>,
    /// Built in [`crate::images_dir`] (else cargo's own directory), so
    /// that the default image at cargo's usual path stays the default
    /// map's (the one the docs tell a user to flash).
    own_dir: bool,
    /// The golden trace, relative to the workspace root.
    golden: &'static str,
    /// AMP_EN's pin number on GPIOB.
    amp_en: u32,
    /// `(register, pin, AF, what)`: the alternate functions the map sets.
    alternate: &'static [(&'static str, u32, u32, &'static str)],
    /// The deadman's channel-mode register and the value that forces its
    /// output low, where QEMU does not model the timer (so its writes are
    /// in the trace): the channel must be forced low before AMP_EN becomes
    /// the timer's pin.
    deadman_forced_low: Option<(&'static str, u32)>,
    /// The fault test's summary line prefix (its image is built in
    /// [`crate::images_dir`]).
    fault_line: &'static str,
    /// The fault test's writes after init that enable the deadman (its
    /// counter running, its channel in PWM mode 2), where QEMU does not
    /// model the timer.
    fault_enable: &'static [&'static str],
    /// The HardFault entry's writes before the DAC's zero code: AMP_EN low
    /// (BSRR, then a GPIO output), the deadman channel forced inactive and
    /// its counter stopped and cleared where QEMU does not model the timer.
    fault_entry: &'static [&'static str],
    /// Where QEMU models the deadman timer: its CR1, channel mode register
    /// and CNT addresses, read back through QEMU's monitor after the fault.
    deadman_readback: Option<[u32; 3]>,
}

/// The default map (Olimex STM32-H405). Its deadman timer, TIM3, is one
/// QEMU models, so its writes are not in the trace.
const H405: Map = Map {
    line: "board-init",
    feature: None,
    own_dir: false,
    golden: "tests/board-init.trace",
    amp_en: 0,
    alternate: &[
        ("GPIOA.AFRH", 9, 7, "PA9 USART1_TX"),
        ("GPIOA.AFRH", 10, 7, "PA10 USART1_RX"),
        ("GPIOA.AFRH", 15, 1, "PA15 TIM2_CH1"),
        ("GPIOB.AFRL", 3, 1, "PB3 TIM2_CH2"),
        ("GPIOA.AFRL", 0, 2, "PA0 TIM5_CH1"),
        ("GPIOA.AFRL", 1, 2, "PA1 TIM5_CH2"),
        ("GPIOB.AFRL", 0, 2, "PB0 TIM3_CH3 (AMP_EN)"),
        ("GPIOC.AFRL", 6, 3, "PC6 TIM8_CH1 (hip encoder)"),
        ("GPIOC.AFRL", 7, 3, "PC7 TIM8_CH2 (hip encoder)"),
    ],
    deadman_forced_low: None,
    fault_line: "fault-test",
    fault_enable: &[],
    fault_entry: &["GPIOB.BSRR = 0x00010000", "GPIOB.MODER = 0x00000001"],
    // TIM3's CR1, CCMR2 and CNT.
    deadman_readback: Some([0x4000_0400, 0x4000_041c, 0x4000_0424]),
};

/// The Adafruit Feather STM32F405 Express's map (`--features feather`).
/// QEMU models neither TIM8 nor TIM12: their writes are in the trace.
const FEATHER: Map = Map {
    line: "board-init-feather",
    feature: Some("feather"),
    own_dir: true,
    golden: "tests/board-init-feather.trace",
    amp_en: 14,
    alternate: &[
        ("GPIOB.AFRH", 10, 7, "PB10 USART3_TX"),
        ("GPIOB.AFRH", 11, 7, "PB11 USART3_RX"),
        ("GPIOC.AFRL", 6, 3, "PC6 TIM8_CH1"),
        ("GPIOC.AFRL", 7, 3, "PC7 TIM8_CH2"),
        ("GPIOA.AFRL", 6, 2, "PA6 TIM3_CH1"),
        ("GPIOA.AFRL", 7, 2, "PA7 TIM3_CH2"),
        ("GPIOB.AFRH", 14, 9, "PB14 TIM12_CH1 (AMP_EN)"),
        ("GPIOB.AFRL", 6, 2, "PB6 TIM4_CH1 (hip encoder)"),
        ("GPIOB.AFRL", 7, 2, "PB7 TIM4_CH2 (hip encoder)"),
    ],
    // OC1M = 100 (force inactive), CC1S = 00 (output).
    deadman_forced_low: Some(("TIM12.CCMR1", 0x0000_0040)),
    fault_line: "fault-test-feather",
    // CR1 = OPM | CEN, CNT = 1, CCMR1's OC1M = 111 (PWM mode 2).
    fault_enable: &[
        "TIM12.CR1 = 0x00000009",
        "TIM12.CNT = 0x00000001",
        "TIM12.CCMR1 = 0x00000070",
    ],
    // QEMU reads the timer as 0, so the entry's read-modify-write of CCMR1
    // shows only OC1M = 100 (forced inactive); then CR1 = OPM, CNT = 0.
    fault_entry: &[
        "GPIOB.BSRR = 0x40000000",
        "GPIOB.MODER = 0x10000000",
        "TIM12.CCMR1 = 0x00000040",
        "TIM12.CR1 = 0x00000008",
        "TIM12.CNT = 0x00000000",
    ],
    deadman_readback: None,
};
/// How long init may take in wall time before it counts as hung.
const INIT_TIMEOUT: Duration = Duration::from_secs(90);

/// One register access QEMU logged.
#[derive(Debug, Clone, PartialEq)]
struct Access {
    device: String,
    offset: u32,
    write: Option<u32>,
}

/// The register's name (RM0090) for the trace.
fn register(device: &str, offset: u32) -> String {
    let name = match (device, offset) {
        (d, o) if d.starts_with("GPIO") => match o {
            0x00 => "MODER",
            0x04 => "OTYPER",
            0x08 => "OSPEEDR",
            0x0c => "PUPDR",
            0x10 => "IDR",
            0x14 => "ODR",
            0x18 => "BSRR",
            0x20 => "AFRL",
            0x24 => "AFRH",
            _ => "",
        },
        ("RCC", o) => match o {
            0x00 => "CR",
            0x04 => "PLLCFGR",
            0x08 => "CFGR",
            0x30 => "AHB1ENR",
            0x40 => "APB1ENR",
            0x44 => "APB2ENR",
            0x74 => "CSR",
            _ => "",
        },
        ("FLASH", o) => match o {
            0x00 => "ACR",
            0x14 => "OPTCR",
            _ => "",
        },
        ("PWR", o) => match o {
            0x00 => "CR",
            0x04 => "CSR",
            _ => "",
        },
        ("DAC", o) => match o {
            0x00 => "CR",
            0x08 => "DHR12R1",
            0x14 => "DHR12R2",
            _ => "",
        },
        (d, o) if d.starts_with("TIM") => match o {
            0x00 => "CR1",
            0x08 => "SMCR",
            0x0c => "DIER",
            0x10 => "SR",
            0x14 => "EGR",
            0x18 => "CCMR1",
            0x1c => "CCMR2",
            0x20 => "CCER",
            0x24 => "CNT",
            0x28 => "PSC",
            0x2c => "ARR",
            0x34 => "CCR1",
            _ => "",
        },
        // QEMU 7.2 names the unimplemented region at 0x4000_3000, which
        // is the IWDG's, `I2S2ext`.
        ("IWDG", o) => match o {
            0x00 => "KR",
            0x04 => "PR",
            0x08 => "RLR",
            0x0c => "SR",
            _ => "",
        },
        _ => "",
    };
    if name.is_empty() {
        format!("{device}+0x{offset:03x}")
    } else {
        format!("{device}.{name}")
    }
}

/// The accesses in a `-d unimp` log, in order.
fn parse(log: &str) -> Vec<Access> {
    let mut out = Vec::new();
    for line in log.lines() {
        let Some((device, rest)) = line.split_once(": unimplemented device ") else {
            continue;
        };
        let device = match device {
            "I2S2ext" => "IWDG".to_string(),
            "Flash Int" => "FLASH".to_string(),
            // The timers QEMU does not model (TIM1, TIM8-TIM14) are
            // `timer[N]`.
            d => match d.strip_prefix("timer[").and_then(|n| n.strip_suffix(']')) {
                Some(n) => format!("TIM{n}"),
                None => d.to_string(),
            },
        };
        let field = |key: &str| {
            rest.split_once(key)
                .and_then(|(_, v)| v.split([',', ')']).next())
                .and_then(|v| u32::from_str_radix(v.trim().trim_start_matches("0x"), 16).ok())
        };
        let Some(offset) = field("offset ") else {
            continue;
        };
        out.push(Access {
            device,
            offset,
            write: if rest.starts_with("write") {
                field("value ")
            } else {
                None
            },
        });
    }
    out
}

/// The trace: each write as `DEV.REG = 0xVALUE`; a read followed by the
/// write of the same register is the write's read-modify-write and is
/// dropped; other runs of reads of one register are `poll DEV.REG`.
/// Returns it with the longest poll run (reads).
fn trace(accesses: &[Access]) -> (Vec<String>, usize) {
    let mut lines = Vec::new();
    let mut longest = 0;
    let mut i = 0;
    while i < accesses.len() {
        let a = &accesses[i];
        let reg = register(&a.device, a.offset);
        match a.write {
            Some(v) => {
                lines.push(format!("{reg} = 0x{v:08x}"));
                i += 1;
            }
            None => {
                let mut j = i;
                while j < accesses.len()
                    && accesses[j].write.is_none()
                    && accesses[j].device == a.device
                    && accesses[j].offset == a.offset
                {
                    j += 1;
                }
                let reads = j - i;
                let rmw = reads == 1
                    && accesses
                        .get(j)
                        .is_some_and(|n| n.device == a.device && n.offset == a.offset);
                if !rmw {
                    lines.push(format!("poll {reg}"));
                    longest = longest.max(reads);
                }
                i = j;
            }
        }
    }
    (lines, longest)
}

/// Index of the first line satisfying `f`.
fn position(lines: &[String], f: impl Fn(&str) -> bool) -> Option<usize> {
    lines.iter().position(|l| f(l))
}

fn value_of(line: &str) -> Option<u32> {
    line.split_once(" = 0x")
        .and_then(|(_, v)| u32::from_str_radix(v, 16).ok())
}

/// The properties that matter on `map`, by name; the problems found.
fn check(lines: &[String], map: &Map) -> Vec<String> {
    let mut problems = Vec::new();
    // AMP_EN: BSRR's reset bit (16 + pin) before its MODER field becomes
    // output (01).
    let pin = map.amp_en;
    let moder = |l: &str| value_of(l).map(|v| (v >> (2 * pin)) & 0b11);
    let low = position(lines, |l| {
        l.starts_with("GPIOB.BSRR = ") && value_of(l).is_some_and(|v| v & (1 << (16 + pin)) != 0)
    });
    let output = position(lines, |l| {
        l.starts_with("GPIOB.MODER = ") && moder(l) == Some(0b01)
    });
    match (low, output) {
        (Some(l), Some(o)) if l < o => {}
        _ => problems.push(format!(
            "AMP_EN (PB{pin}) is not driven low before it becomes an output (BSRR BR{pin} at {low:?}, MODER{pin} = output at {output:?})"
        )),
    }
    // The deadman's output forced low before AMP_EN becomes its pin (10).
    if let Some((register, forced)) = map.deadman_forced_low {
        let low = position(lines, |l| {
            l.starts_with(&format!("{register} = ")) && value_of(l) == Some(forced)
        });
        let handed = position(lines, |l| {
            l.starts_with("GPIOB.MODER = ") && moder(l) == Some(0b10)
        });
        match (low, handed) {
            (Some(l), Some(h)) if l < h => {}
            _ => problems.push(format!(
                "the deadman's output is not forced low before AMP_EN (PB{pin}) becomes its pin ({register} at {low:?}, MODER{pin} = alternate at {handed:?})"
            )),
        }
    }
    // The DAC: each channel's DHR12Rn = 0x800 (the zero-current code)
    // before its CR.ENn (bit 0 for the leg's, 16 for the hip's).
    for (channel, bit) in [(1, 0), (2, 16)] {
        let zero = position(lines, |l| l == format!("DAC.DHR12R{channel} = 0x00000800"));
        let enable = position(lines, |l| {
            l.starts_with("DAC.CR = ") && value_of(l).is_some_and(|v| v & (1 << bit) != 0)
        });
        match (zero, enable) {
            (Some(z), Some(e)) if z < e => {}
            _ => problems.push(format!(
                "the DAC's zero code is not written before the DAC is enabled (DHR12R{channel} at {zero:?}, EN{channel} at {enable:?})"
            )),
        }
    }
    // Alternate functions: the map's link, encoder and deadman pins. An
    // unmodelled register reads 0, so each read-modify-write shows only
    // the fields it sets: a pin's function is its field in the last write
    // that sets it.
    let af = |reg: &str, pin: u32| {
        lines
            .iter()
            .rev()
            .filter(|l| l.starts_with(&format!("{reg} = ")))
            .filter_map(|l| value_of(l))
            .map(|v| (v >> (4 * (pin % 8))) & 0xF)
            .find(|f| *f != 0)
    };
    for &(reg, pin, want, what) in map.alternate {
        let got = af(reg, pin);
        if got != Some(want) {
            problems.push(format!("{what}: AF{got:?}, not AF{want}"));
        }
    }
    // The watchdog: unlock (0x5555), prescaler, reload, start (0xCCCC),
    // then reloads (0xAAAA).
    let iwdg: Vec<&String> = lines.iter().filter(|l| l.starts_with("IWDG.")).collect();
    let order = [
        "IWDG.KR = 0x00005555",
        "IWDG.PR = ",
        "IWDG.RLR = ",
        "IWDG.KR = 0x0000cccc",
        "IWDG.KR = 0x0000aaaa",
    ];
    let mut next = 0;
    for l in &iwdg {
        if next < order.len() && l.starts_with(order[next]) {
            next += 1;
        }
    }
    if next < order.len() {
        problems.push(format!(
            "the watchdog's keys are not in the order unlock, prescaler, reload, start, reload: {iwdg:?}"
        ));
    }
    problems
}

/// QEMU on `elf`, logging every access to an unmodelled register
/// (`-d unimp`) to `log_path`.
fn spawn_unimp(
    elf: &Path,
    log_path: &Path,
    monitor: Option<&Path>,
) -> Result<std::process::Child, String> {
    let mut cmd = crate::qemu::qemu_command(elf, 0, "null");
    if let Some(m) = monitor {
        cmd.arg("-monitor")
            .arg(format!("unix:{},server=on,wait=off", m.display()));
    }
    cmd.args(["-d", "unimp"])
        .arg("-D")
        .arg(log_path)
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
        .map_err(|e| format!("cannot start qemu-system-arm: {e}"))
}

/// Builds the board image on each pin map, runs its init on QEMU and
/// checks the trace; prints `board-init: ...` (the default map) and
/// `board-init-feather: ...`, then runs the fault test.
pub fn run(root: &Path) -> Result<(), String> {
    let dir = crate::target_dir(root)?.join("board-init");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let elf = crate::board_image(root)?;
    let h405 = run_map(root, &H405, &elf, &dir);
    let feather = match map_image(root, &FEATHER) {
        Ok(elf) => run_map(root, &FEATHER, &elf, &dir),
        Err(e) => {
            println!("{}: error (see above)", FEATHER.line);
            Err(format!("board init failed ({}): {e}", FEATHER.line))
        }
    };
    h405.and(feather)?;
    let h405 = fault_test(root, &H405);
    let feather = fault_test(root, &FEATHER);
    h405.and(feather)
}

/// The board image built with `map`'s features, in its own target
/// directory (so that cargo's usual path keeps the default map's image).
fn map_image(root: &Path, map: &Map) -> Result<std::path::PathBuf, String> {
    let mut cmd = crate::hopper_fw_build();
    if let Some(f) = map.feature {
        cmd.args(["--features", f]);
    }
    if map.own_dir {
        cmd.arg("--target-dir").arg(crate::images_dir(root)?);
    }
    crate::build_executable(
        root,
        &format!("firmware release build ({} pin map)", map.line),
        "hopper-fw",
        &mut cmd,
    )
}

/// `elf`'s init on QEMU, its trace checked against `map`; prints
/// `<map.line>: ...`.
fn run_map(root: &Path, map: &Map, elf: &Path, dir: &Path) -> Result<(), String> {
    let log_path = dir.join(format!("{}-unimp.log", map.line));
    let _ = std::fs::remove_file(&log_path);
    eprintln!(
        "xtask: running the board image's init ({}) on qemu-system-arm (netduinoplus2, -d unimp)",
        map.line
    );
    let started = Instant::now();
    let mut child = spawn_unimp(elf, &log_path, None)?;
    // Init is done at the watchdog's first reload: nothing follows it in
    // QEMU (the control task waits for an ADC interrupt that never comes).
    let done = loop {
        std::thread::sleep(Duration::from_millis(200));
        let log = std::fs::read_to_string(&log_path).unwrap_or_default();
        if log.contains("I2S2ext: unimplemented device write (size 2, offset 0x000, value 0xaaaa)")
        {
            break true;
        }
        if started.elapsed() > INIT_TIMEOUT || child.try_wait().ok().flatten().is_some() {
            break false;
        }
    };
    let _ = child.kill();
    let _ = child.wait();
    crate::took(&format!("{} on QEMU", map.line), started);
    let log =
        std::fs::read_to_string(&log_path).map_err(|e| format!("{}: {e}", log_path.display()))?;
    let (lines, longest_poll) = trace(&parse(&log));
    let mut problems = Vec::new();
    if !done {
        problems.push(format!(
            "init did not reach the watchdog's first reload within {} s without a crystal (it hangs, or QEMU stopped)",
            INIT_TIMEOUT.as_secs()
        ));
    }
    problems.extend(check(&lines, map));
    let mut text = String::from(
        "# The board image's init on QEMU netduinoplus2 (-d unimp): writes to the\n\
         # registers QEMU does not model, in order, and the registers polled\n\
         # (xtask/src/board_init.rs). QEMU reads these registers as 0, so a\n\
         # read-modify-write shows only the fields it sets, and every ready\n\
         # flag stays low: the first clock wait (HSIRDY) and the LSI's time\n\
         # out, and init goes on on the HSI, as when the crystal never starts.\n",
    );
    if let Some(f) = map.feature {
        let _ = writeln!(text, "# The image built with `--features {f}`.");
    }
    for l in &lines {
        let _ = writeln!(text, "{l}");
    }
    let golden_name = map.golden;
    let golden_path = root.join(golden_name);
    let actual_path = dir.join(format!("{}-actual.trace", map.line));
    let _ = std::fs::write(&actual_path, &text);
    if std::env::var_os("HOPPER_UPDATE_GOLDEN").is_some() {
        std::fs::write(&golden_path, &text).map_err(|e| format!("{golden_name}: {e}"))?;
        eprintln!("xtask: wrote {golden_name}");
    }
    let golden = std::fs::read_to_string(&golden_path).unwrap_or_default();
    let same = golden == text;
    if !same {
        let g: Vec<&str> = golden.lines().filter(|l| !l.starts_with('#')).collect();
        let first = lines
            .iter()
            .zip(g.iter())
            .position(|(a, b)| a != b)
            .unwrap_or(lines.len().min(g.len()));
        problems.push(format!(
            "the trace differs from {golden_name} at write {first}: got {:?}, golden {:?} (whole trace: {}; HOPPER_UPDATE_GOLDEN=1 accepts a deliberate change)",
            lines.get(first),
            g.get(first),
            actual_path.display()
        ));
    }
    let writes = lines.iter().filter(|l| !l.starts_with("poll ")).count();
    let polls = lines.len() - writes;
    println!(
        "{}: writes={writes} polled_registers={polls} longest_poll_reads={longest_poll} terminated={done} golden={}",
        map.line,
        if same { "same" } else { "DIFFERENT" }
    );
    if !problems.is_empty() {
        for p in &problems {
            eprintln!("xtask: {}: {p}", map.line);
        }
        return Err(format!(
            "board init failed ({}): {}",
            map.line,
            problems.join("; ")
        ));
    }
    Ok(())
}

/// The HardFault entry on QEMU: the board image on `map` built with
/// `fault-test` (a calibrated zero code of 2050) faults right after init
/// with its main stack pointer off the SRAM, so the exception cannot
/// stack. What it writes after init, in order, must be AMP_EN low (BSRR's
/// reset bit, then the pin a GPIO output; on the Feather's map the
/// deadman timer stopped too) and the calibrated zero code, from the
/// assembly entry that uses no stack, then the same again from the Rust
/// handler on its fresh stack. Prints `fault-test: ...` (the default map)
/// or `fault-test-feather: ...`.
fn fault_test(root: &Path, map: &Map) -> Result<(), String> {
    let target_dir = crate::images_dir(root)?;
    let features = match map.feature {
        Some(f) => format!("{f},fault-test"),
        None => "fault-test".to_string(),
    };
    let elf = crate::build_executable(
        root,
        &format!("firmware release build ({})", map.fault_line),
        "hopper-fw",
        crate::hopper_fw_build()
            .args(["--features", &features, "--target-dir"])
            .arg(&target_dir),
    )?;
    let dir = crate::target_dir(root)?.join("board-init");
    let log_path = dir.join(format!("{}.log", map.fault_line));
    let _ = std::fs::remove_file(&log_path);
    let started = Instant::now();
    let monitor = dir.join(format!("{}.monitor", map.fault_line));
    let _ = std::fs::remove_file(&monitor);
    let mut child = spawn_unimp(&elf, &log_path, Some(&monitor))?;
    // Done when the Rust handler's zero code is written (the second after
    // init), or after the timeout.
    let after_init = |log: &str| -> Vec<String> {
        let (lines, _) = trace(&parse(log));
        let start = lines
            .iter()
            .position(|l| l == "IWDG.KR = 0x0000aaaa")
            .map_or(lines.len(), |i| i + 1);
        lines[start..]
            .iter()
            .filter(|l| !l.starts_with("poll ") && !l.starts_with("IWDG."))
            .cloned()
            .collect()
    };
    let mut writes = Vec::new();
    while started.elapsed() < INIT_TIMEOUT {
        std::thread::sleep(Duration::from_millis(200));
        let log = std::fs::read_to_string(&log_path).unwrap_or_default();
        writes = after_init(&log);
        if writes
            .iter()
            .filter(|l| l.starts_with("DAC.DHR12R1"))
            .count()
            >= 2
            || child.try_wait().ok().flatten().is_some()
        {
            break;
        }
    }
    // Where QEMU models the timer, its registers after the fault.
    let readback = map
        .deadman_readback
        .map(|addrs| read_words(&monitor, &addrs));
    let _ = child.kill();
    let _ = child.wait();
    crate::took(&format!("{} on QEMU", map.fault_line), started);
    let zero = "DAC.DHR12R1 = 0x00000802";
    let expected: Vec<&str> = map
        .fault_enable
        .iter()
        .chain(map.fault_entry.iter())
        .copied()
        .chain([zero])
        .collect();
    let entry_first =
        writes.len() >= expected.len() && writes.iter().zip(expected.iter()).all(|(w, e)| w == e);
    let handler = writes
        .get(expected.len()..)
        .is_some_and(|rest| rest.iter().any(|l| l == zero));
    // The channel forced inactive (OCxM = 100), the counter stopped, CNT 0:
    // in the traced writes, or read back.
    let (forced, how) = match &readback {
        None => (
            entry_first
                && map
                    .fault_entry
                    .iter()
                    .any(|w| w.ends_with(&format!("= 0x{:08x}", 0b100u32 << 4))),
            "traced".to_string(),
        ),
        // QEMU 7.2's timer derives CNT from the virtual clock whether or
        // not CEN is set, so CNT is shown, not checked, here (the host
        // tests of `hopper_control::deadman` check it).
        Some(Ok([cr1, ccmr, cnt])) => (
            (ccmr >> 4) & 0b111 == 0b100 && cr1 & 1 == 0,
            format!("read_back_cr1=0x{cr1:x} ccmr=0x{ccmr:x} cnt_qemu={cnt}"),
        ),
        Some(Err(e)) => (false, format!("read_back_failed ({e})")),
    };
    println!(
        "{}: hardfault_off_the_stack amp_en_low_first={entry_first} calibrated_zero_first={entry_first} deadman_forced_inactive={forced} ({how}) rust_handler_ran={handler} writes_after_init={}",
        map.fault_line,
        writes.len()
    );
    if entry_first && handler && forced {
        Ok(())
    } else {
        Err(format!(
            "the HardFault entry's writes after init are {writes:?}, not {expected:?} then the Rust handler's {zero}; the deadman forced inactive: {forced} ({how})"
        ))
    }
}

/// Three words at `addrs`, read through QEMU's monitor on the unix socket
/// `monitor` (`xp`, which reads a modelled device's registers).
fn read_words(monitor: &Path, addrs: &[u32; 3]) -> Result<[u32; 3], String> {
    use std::io::{Read as _, Write as _};
    let mut sock = std::os::unix::net::UnixStream::connect(monitor)
        .map_err(|e| format!("{}: {e}", monitor.display()))?;
    sock.set_read_timeout(Some(Duration::from_millis(500)))
        .map_err(|e| e.to_string())?;
    let mut out = [0u32; 3];
    let mut text = String::new();
    for (k, a) in addrs.iter().enumerate() {
        write!(sock, "xp /1wx 0x{a:08x}\r\n").map_err(|e| e.to_string())?;
        let key = format!("{a:016x}:");
        let started = Instant::now();
        let value = loop {
            let mut buf = [0u8; 512];
            match sock.read(&mut buf) {
                Ok(0) => return Err("the monitor closed".into()),
                Ok(n) => text.push_str(&String::from_utf8_lossy(&buf[..n])),
                Err(_) if started.elapsed() < Duration::from_secs(5) => {}
                Err(e) => return Err(format!("no answer for 0x{a:08x}: {e}")),
            }
            if let Some(v) = text.split(&key).nth(1).and_then(|rest| {
                let w = rest.split_whitespace().next()?;
                u32::from_str_radix(w.trim_start_matches("0x"), 16).ok()
            }) {
                break v;
            }
        };
        out[k] = value;
        text.clear();
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const LOG: &str = "RCC: unimplemented device read  (size 4, offset 0x030)\n\
RCC: unimplemented device write (size 4, offset 0x030, value 0x00000007)\n\
GPIOB: unimplemented device write (size 4, offset 0x018, value 0x00010000)\n\
GPIOB: unimplemented device read  (size 4, offset 0x000)\n\
GPIOB: unimplemented device write (size 4, offset 0x000, value 0x00000001)\n\
RCC: unimplemented device read  (size 4, offset 0x000)\n\
RCC: unimplemented device read  (size 4, offset 0x000)\n\
RCC: unimplemented device read  (size 4, offset 0x000)\n\
I2S2ext: unimplemented device write (size 2, offset 0x000, value 0x5555)\n";

    #[test]
    fn a_log_becomes_named_writes_and_polls() {
        let (lines, longest) = trace(&parse(LOG));
        assert_eq!(
            lines,
            [
                "RCC.AHB1ENR = 0x00000007",
                "GPIOB.BSRR = 0x00010000",
                "GPIOB.MODER = 0x00000001",
                "poll RCC.CR",
                "IWDG.KR = 0x00005555",
            ]
        );
        assert_eq!(longest, 3);
    }

    /// Whether `check` names a problem starting with `what` in `trace`.
    fn caught(trace: &[&str], what: &str) -> bool {
        let lines: Vec<String> = trace.iter().map(|l| l.to_string()).collect();
        check(&lines, &H405).iter().any(|p| p.starts_with(what))
    }

    #[test]
    fn amp_en_made_an_output_before_it_is_low_is_caught() {
        assert!(caught(
            &["GPIOB.MODER = 0x00000001", "GPIOB.BSRR = 0x00010000"],
            "AMP_EN"
        ));
    }

    #[test]
    fn the_feathers_amp_en_and_deadman_order_is_checked() {
        let lines = |t: &[&str]| t.iter().map(|l| l.to_string()).collect::<Vec<_>>();
        let good = [
            "GPIOB.BSRR = 0x40000000",
            "GPIOB.MODER = 0x10000000",
            "TIM12.CCMR1 = 0x00000040",
            "GPIOB.AFRH = 0x09000000",
            "GPIOB.MODER = 0x20000000",
        ];
        let problems = check(&lines(&good), &FEATHER);
        assert!(
            !problems
                .iter()
                .any(|p| p.starts_with("AMP_EN") || p.starts_with("the deadman")),
            "{problems:?}"
        );
        // PB14 handed to the timer before its output is forced low.
        let early = [good[0], good[1], good[3], good[4], good[2]];
        assert!(check(&lines(&early), &FEATHER)
            .iter()
            .any(|p| p.starts_with("the deadman's output is not forced low")));
        // PB0's order says nothing about PB14.
        let pb0 = ["GPIOB.BSRR = 0x00010000", "GPIOB.MODER = 0x00000001"];
        assert!(check(&lines(&pb0), &FEATHER)
            .iter()
            .any(|p| p.starts_with("AMP_EN (PB14)")));
    }

    #[test]
    fn unmodelled_timers_are_named() {
        let log =
            "timer[12]: unimplemented device write (size 4, offset 0x018, value 0x00000040)\n";
        assert_eq!(trace(&parse(log)).0, ["TIM12.CCMR1 = 0x00000040"]);
    }

    #[test]
    fn a_dac_enabled_before_its_zero_code_is_caught() {
        assert!(caught(
            &["DAC.CR = 0x00000001", "DAC.DHR12R1 = 0x00000800"],
            "the DAC"
        ));
    }

    #[test]
    fn a_watchdog_started_before_its_reload_is_set_is_caught() {
        assert!(caught(
            &[
                "IWDG.KR = 0x00005555",
                "IWDG.KR = 0x0000cccc",
                "IWDG.PR = 0x00000000",
                "IWDG.RLR = 0x00000027",
                "IWDG.KR = 0x0000aaaa",
            ],
            "the watchdog"
        ));
    }
}
