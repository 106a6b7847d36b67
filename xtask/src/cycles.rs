//! Cycles, not only instructions: the QEMU images' control work weighed
//! by the Cortex-M4's cycle counts, from the instruction stream QEMU
//! executes (`-d in_asm,exec,nochain`, the log kept to the firmware's
//! own code with `-dfilter`).
//!
//! QEMU under `-icount shift=0` counts instructions; the M4 spends more
//! than one cycle on many. Each executed instruction is weighed by the
//! Cortex-M4 Technical Reference Manual's table (3.3.1, and the FPU's,
//! 7.2.3), at the upper end of each range:
//!
//! - ALU, moves, compares, `MUL`, long multiplies, `MSR`/`MRS`: 1;
//!   `MLA`/`MLS`: 2; `SDIV`/`UDIV`: 12 (2 to 12, by the operands);
//! - a load or store of one register: 2, or 1 right after another (the
//!   pipelined address phase, N + 1 for N in a row); `LDRD`/`STRD`: 3;
//!   `LDM`/`STM`/`PUSH`/`POP` and the FPU's `VLDM`/`VSTM`/`VPUSH`/`VPOP`:
//!   1 + N words;
//! - a branch not taken: 1; taken (`B`, `BL`, `BX`, `BLX`, `CBZ`, a `POP`
//!   or `LDR` into PC): 1 + P with P = 3, the pipeline refill's longest;
//!   `TBB`/`TBH`: 2 + P; `ISB`/`DSB`/`DMB`: 1 + P;
//! - FPU: add, multiply, compare, convert, move, absolute, negate: 1;
//!   the fused and chained multiply-accumulates: 3; `VDIV`/`VSQRT`: 14;
//!   `VLDR`/`VSTR`: 2.
//!
//! Flash: 5 wait states at 168 MHz (RM0090 3.5.1), hidden by the ART
//! accelerator's prefetch and 1 KB instruction cache when its lines hit,
//! which the estimate assumes (data in SRAM: no wait). Without the cache
//! each 16-byte flash line costs up to 5 cycles more the first time a
//! period touches it: the `cold` figure adds that for every line the
//! window touched.
//!
//! A window is the code between two readings of the period clock (TIM5,
//! read by one out-of-line function, so each reading is a call to its
//! address), or a function from its entry to its return; calls to the
//! simulated world (`with_systick_stopped`) are left out by address.

use std::collections::{HashMap, HashSet};

/// The longest run of consecutive segments weighed as one window.
const CHAIN: usize = 8;
/// The pipeline refill of a taken branch, cycles (1 to 3 in the TRM).
const REFILL: u32 = 3;
/// Flash wait states at 168 MHz and 3.3 V (RM0090 table 10).
const FLASH_WAIT_STATES: u32 = 5;

/// What one instruction costs.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Cost {
    /// Cycles when it does not branch (or a branch is not taken).
    pub base: u32,
    /// Cycles more when it branches.
    pub taken: u32,
    /// A single load or store (pipelines with the one before it).
    pub single_mem: bool,
    /// The period clock's reading mark (`YIELD`).
    pub mark: bool,
}

/// Registers in a `{...}` list, in words (a `d` register is two).
fn words(ops: &str) -> u32 {
    let Some(list) = ops.split_once('{').and_then(|(_, r)| r.split_once('}')) else {
        return 1;
    };
    list.0
        .split(',')
        .map(|r| {
            let r = r.trim();
            let n = match r.split_once('-') {
                Some((a, b)) => {
                    let num = |s: &str| s.trim()[1..].parse::<u32>().unwrap_or(0);
                    num(b).saturating_sub(num(a)) + 1
                }
                None => 1,
            };
            if r.starts_with('d') {
                2 * n
            } else {
                n
            }
        })
        .sum()
}

/// The condition suffixes an instruction may carry.
const CONDITIONS: [&str; 15] = [
    "eq", "ne", "cs", "hs", "cc", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt",
];

/// `mnemonic` without its width (`.w`, `.n`), data type (`.f32`) and
/// condition: the operation.
fn operation(mnemonic: &str) -> &str {
    let m = mnemonic.split('.').next().unwrap_or(mnemonic);
    // "bne" -> "b", "ldrne" -> "ldr", "itt" stays.
    for c in CONDITIONS.iter().chain(&["le", "al"]) {
        if let Some(stem) = m.strip_suffix(c) {
            if matches!(
                stem,
                "b" | "bx" | "bl" | "blx" | "ldr" | "str" | "mov" | "add" | "sub" | "cmp" | "vmov"
            ) {
                return stem;
            }
        }
    }
    m
}

/// The cycles of one instruction, from its mnemonic and operands as QEMU
/// prints them.
pub fn weigh(mnemonic: &str, ops: &str) -> Cost {
    let op = operation(mnemonic);
    let plain = |base| Cost {
        base,
        ..Cost::default()
    };
    let branch = |base, taken| Cost {
        base,
        taken,
        ..Cost::default()
    };
    let mem = |base| Cost {
        base,
        single_mem: true,
        ..Cost::default()
    };
    let writes_pc = ops.starts_with("pc") || ops.contains("pc}");
    match op {
        "b" | "bl" | "bx" | "blx" => branch(1, REFILL),
        "cbz" | "cbnz" => branch(1, REFILL),
        "tbb" | "tbh" => branch(2, REFILL),
        "isb" | "dsb" | "dmb" => plain(1 + REFILL),
        "pop" | "ldm" | "ldmia" | "ldmdb" | "ldmfd" => {
            let c = 1 + words(ops);
            if writes_pc {
                branch(c, REFILL)
            } else {
                plain(c)
            }
        }
        "push" | "stm" | "stmia" | "stmdb" | "stmfd" | "stmea" => plain(1 + words(ops)),
        "vpush" | "vpop" | "vldmia" | "vldmdb" | "vstmia" | "vstmdb" | "vldm" | "vstm" => {
            plain(1 + words(ops))
        }
        "ldrd" | "strd" => plain(3),
        "ldr" if writes_pc => branch(2, REFILL),
        "ldr" | "ldrb" | "ldrh" | "ldrsb" | "ldrsh" | "ldrex" | "ldrexb" | "ldrexh" | "str"
        | "strb" | "strh" | "strex" | "strexb" | "strexh" | "ldrt" | "strt" => mem(2),
        "mla" | "mls" => plain(2),
        "yield" => Cost {
            base: 1,
            mark: true,
            ..Cost::default()
        },
        "sdiv" | "udiv" => plain(12),
        "vldr" | "vstr" => plain(2),
        "vdiv" | "vsqrt" => plain(14),
        "vmla" | "vmls" | "vnmla" | "vnmls" | "vfma" | "vfms" | "vfnma" | "vfnms" => plain(3),
        _ => plain(1),
    }
}

/// One translated block: its instructions' addresses, sizes and costs.
#[derive(Debug, Clone, Default)]
struct Block {
    insns: Vec<(u64, u64, Cost)>,
}

/// What a window weighed: instructions, cycles, and the 16-byte flash
/// lines it touched.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Weight {
    /// Instructions executed.
    pub instructions: u64,
    /// Cycles, by [`weigh`], the cache hitting.
    pub cycles: u64,
    /// Distinct 16-byte flash lines fetched.
    pub lines: u64,
}

impl Weight {
    /// Cycles with every line a cache miss once.
    pub fn cold(&self) -> u64 {
        self.cycles + u64::from(FLASH_WAIT_STATES) * self.lines
    }
}

/// The largest and the mean of a window's weights over a run.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Stats {
    /// Windows seen.
    pub count: u64,
    /// Instructions summed (for the mean).
    pub instructions: u64,
    /// The largest instruction count.
    pub max_instructions: u64,
    /// The largest cycle count.
    pub max_cycles: u64,
    /// The largest cycle count with every line missed once.
    pub max_cold: u64,
}

impl Stats {
    fn add(&mut self, w: &Weight) {
        self.count += 1;
        self.instructions += w.instructions;
        self.max_instructions = self.max_instructions.max(w.instructions);
        self.max_cycles = self.max_cycles.max(w.cycles);
        self.max_cold = self.max_cold.max(w.cold());
    }

    /// Instructions per window, mean.
    pub fn mean_instructions(&self) -> f64 {
        self.instructions as f64 / self.count.max(1) as f64
    }
}

/// The addresses a trace is read with.
#[derive(Debug, Clone, Default)]
pub struct Marks {
    /// A function weighed whole: its entry and its return addresses.
    pub function: Option<(u64, HashSet<u64>)>,
    /// Functions left out (the simulated world): entries, and the
    /// addresses their calls return to.
    pub left_out: (HashSet<u64>, HashSet<u64>),
}

/// An open window: what it weighed so far.
#[derive(Debug, Default)]
struct Open {
    weight: Weight,
    lines: HashSet<u64>,
    /// The last instruction's memory pipelining.
    after_mem: bool,
}

impl Open {
    fn add(&mut self, insns: &[(u64, u64, Cost)]) {
        for &(addr, _, c) in insns {
            self.weight.instructions += 1;
            self.weight.cycles += u64::from(if c.single_mem && self.after_mem {
                1
            } else {
                c.base
            });
            self.after_mem = c.single_mem;
            self.lines.insert(addr / 16);
        }
    }

    fn close(mut self) -> Weight {
        self.weight.lines = self.lines.len() as u64;
        self.weight
    }
}

/// Reads QEMU's log line by line and weighs the windows.
#[derive(Debug, Default)]
pub struct Reader {
    marks: Marks,
    /// Blocks, and their indices by host code address (unique per
    /// translation).
    blocks: Vec<Block>,
    by_host: HashMap<String, usize>,
    /// The block just translated, until its first execution names it.
    translating: Option<Block>,
    /// The block executed last, not yet counted: its address, index and
    /// where a rewind cut it.
    last: Option<(u64, usize, u64)>,
    /// Between two clock readings: the reading it began at, and what it
    /// weighed.
    segment: Option<(u64, Open)>,
    /// Inside the function weighed whole.
    whole: Option<Open>,
    /// Inside a left-out call.
    away: bool,
    /// The last weighed instruction was a branch whose cost waits for
    /// the next block: (fall-through address, cycles more if taken).
    pending: Option<(u64, u32)>,
    /// Segments by (the reading it began at, the one that ended it): the
    /// readings' marks' addresses.
    pub segments: HashMap<(u64, u64), Stats>,
    /// Runs of consecutive segments (the windows the firmware times
    /// across readings of its own, as the control interrupt's), by
    /// (first reading, last reading, segments): up to [`CHAIN`].
    pub chains: HashMap<(u64, u64, usize), Stats>,
    /// The last segments closed, oldest first.
    recent: std::collections::VecDeque<(u64, Weight)>,
    /// The function weighed whole.
    pub function: Stats,
    /// QEMU's other messages (the first 20).
    pub other: Vec<String>,
}

impl Reader {
    /// A reader for `marks`.
    pub fn new(marks: Marks) -> Self {
        Reader {
            marks,
            ..Reader::default()
        }
    }

    /// One line of QEMU's log.
    pub fn line(&mut self, line: &str) {
        if let Some(rest) = line.strip_prefix("0x") {
            // "0x08003378:  b5f0       push     {r4, r5, r6, r7, lr}"
            let Some((addr, rest)) = rest.split_once(':') else {
                return;
            };
            let Ok(addr) = u64::from_str_radix(addr, 16) else {
                return;
            };
            let mut parts = rest.split_whitespace();
            // Encoding: one or two halfwords.
            let mut size = 0;
            let mut mnemonic = "";
            for p in parts.by_ref() {
                if p.len() == 4 && p.chars().all(|c| c.is_ascii_hexdigit()) && size < 4 {
                    size += 2;
                } else {
                    mnemonic = p;
                    break;
                }
            }
            let ops: String = parts.collect::<Vec<_>>().join(" ");
            let cost = weigh(mnemonic, &ops);
            self.translating
                .get_or_insert_with(Block::default)
                .insns
                .push((addr, size, cost));
        } else if let Some(rest) = line.strip_prefix("Trace ") {
            // "Trace 0: 0x7fe7c80f3500 [0080040d/08003378/00000010/ff020200] sym"
            let mut f = rest.split_whitespace();
            let host = f.nth(1).unwrap_or_default().to_string();
            let pc = f
                .next()
                .and_then(|b| b.trim_start_matches('[').split('/').nth(1))
                .and_then(|h| u64::from_str_radix(h, 16).ok());
            let Some(pc) = pc else {
                return;
            };
            if let Some(b) = self.translating.take() {
                self.blocks.push(b);
                self.by_host.insert(host.clone(), self.blocks.len() - 1);
            }
            self.flush();
            if let Some(&i) = self.by_host.get(&host) {
                self.last = Some((pc, i, u64::MAX));
            }
        } else if let Some(rest) =
            line.strip_prefix("cpu_io_recompile: rewound execution of TB to ")
        {
            // The last block ran only up to this instruction (an I/O
            // access must end a block under -icount): it runs again as a
            // block of its own.
            if let (Ok(at), Some((_, _, cut))) = (
                u64::from_str_radix(rest.trim().trim_start_matches("0x"), 16),
                self.last.as_mut(),
            ) {
                *cut = at;
            }
        } else if !line.is_empty()
            && !line.starts_with("----")
            && !line.starts_with("Stopped execution of TB chain")
            && !line.starts_with("IN:")
            && self.other.len() < 20
        {
            // Anything else QEMU said (an error, a warning), for the report.
            self.other.push(line.to_string());
        }
    }

    /// Counts the last executed block.
    fn flush(&mut self) {
        let Some((pc, index, cut)) = self.last.take() else {
            return;
        };
        // The branch that ended the block before: taken unless this one
        // starts where it falls through.
        if let Some((fall, more)) = self.pending.take() {
            if pc != fall {
                for open in self.opens() {
                    open.weight.cycles += u64::from(more);
                }
            }
        }
        let m = &self.marks;
        if m.left_out.0.contains(&pc) {
            self.away = true;
        }
        if self.away {
            if m.left_out.1.contains(&pc) {
                self.away = false;
            } else {
                return;
            }
        }
        if let Some((entry, returns)) = &m.function {
            if pc == *entry && self.whole.is_none() {
                self.whole = Some(Open::default());
            } else if returns.contains(&pc) {
                if let Some(open) = self.whole.take() {
                    self.function.add(&open.close());
                }
            }
        }
        // A reading's mark ends one segment and begins the next: the
        // instructions before it are the old one's, from it on the new.
        let block = std::mem::take(&mut self.blocks[index]);
        let ran = block.insns.iter().take_while(|(a, _, _)| *a < cut).count();
        let insns = &block.insns[..ran];
        let mut from = 0;
        for (i, &(addr, _, c)) in insns.iter().enumerate() {
            if c.mark {
                if let Some(open) = self.whole.as_mut() {
                    open.add(&insns[from..i]);
                }
                if let Some((start, mut open)) = self.segment.take() {
                    open.add(&insns[from..i]);
                    self.close(start, addr, open.close());
                }
                self.segment = Some((addr, Open::default()));
                from = i;
            }
        }
        for open in self.opens() {
            open.add(&insns[from..]);
        }
        if let Some(&(addr, size, c)) = insns.last() {
            if c.taken > 0 && ran == block.insns.len() {
                self.pending = Some((addr + size, c.taken));
            }
        }
        self.blocks[index] = block;
    }

    /// A segment from the reading at `start` to the one at `end` closed.
    fn close(&mut self, start: u64, end: u64, w: Weight) {
        self.segments.entry((start, end)).or_default().add(&w);
        if self.recent.len() == CHAIN {
            self.recent.pop_front();
        }
        self.recent.push_back((start, w));
        // Every run of the last segments that ends here.
        let mut sum = Weight::default();
        for (n, (from, w)) in self.recent.iter().rev().enumerate() {
            sum.instructions += w.instructions;
            sum.cycles += w.cycles;
            sum.lines += w.lines;
            self.chains
                .entry((*from, end, n + 1))
                .or_default()
                .add(&sum);
        }
    }

    fn opens(&mut self) -> impl Iterator<Item = &mut Open> {
        self.segment
            .as_mut()
            .map(|(_, o)| o)
            .into_iter()
            .chain(self.whole.as_mut())
    }

    /// The end of the log.
    pub fn finish(&mut self) {
        self.flush();
    }

    /// The window between two readings (over one segment or a run of
    /// them: the firmware's own window may hold readings of other
    /// windows) whose instruction counts are the firmware's own
    /// `(mean, max)` plus the readings' overhead: the
    /// same difference for both, within one instruction. Its stats, or
    /// why none matches.
    pub fn segment_like(&self, mean: f64, max: u64) -> Result<&Stats, String> {
        let best = self
            .chains
            .values()
            .filter(|s| s.count > 1)
            .map(|s| {
                let over_max = s.max_instructions as f64 - max as f64;
                let over_mean = s.mean_instructions() - mean;
                (s, over_max, over_mean)
            })
            .filter(|(_, a, b)| *a >= 0.0 && (a - b).abs() <= 1.5 && *a < 64.0)
            .min_by(|x, y| x.1.total_cmp(&y.1));
        best.map(|(s, _, _)| s).ok_or_else(|| {
            format!(
                "no traced window matches the firmware's own count (mean {mean:.1}, max {max}) among {} segments",
                self.segments.len()
            )
        })
    }
}

/// An image's marks for a trace of the function `task` (named so, or its
/// demangled path ending so: the control task's handler), and the
/// `-dfilter` that keeps QEMU's log to the firmware's code: the task and
/// what it calls, less the simulated world (the calls run with SysTick
/// stopped, whose entries only are logged, the plant's and the sensor
/// models' code, and the soft `f64` arithmetic they use: the firmware's
/// is `f32` on the FPU; a window that called them would not match the
/// firmware's own count).
pub fn marks_for(elf: &std::path::Path, task: &str) -> Result<(Marks, String), String> {
    let crate::stack::Image { funcs, taken, dis } = crate::stack::Image::read(elf)?;
    // Sizes: "08003378 00005970 t name".
    let nm = crate::llvm_tool("llvm-nm", &["-S"], elf)?;
    let size: HashMap<&str, u64> = nm
        .lines()
        .filter_map(|l| {
            let mut f = l.split_whitespace();
            let (_, sz, _, name) = (f.next()?, f.next()?, f.next()?, f.next()?);
            Some((name, u64::from_str_radix(sz, 16).ok()?))
        })
        .collect();
    let short = |n: &str| format!("{:#}", rustc_demangle::demangle(n));
    let find = |what: &dyn Fn(&str) -> bool| -> Vec<String> {
        funcs.keys().filter(|n| what(&short(n))).cloned().collect()
    };
    let [entry] = &find(&|n| n == task || n.ends_with(&format!("::{task}")))[..] else {
        return Err(format!("no single function `{task}` in the image"));
    };
    let left_out: HashSet<String> = find(&|n| n.contains("with_systick_stopped"))
        .into_iter()
        .collect();
    let world = |n: &str| {
        let d = short(n);
        d.starts_with("hopper_plant::")
            || d.starts_with("hopper_sil::")
            || d.starts_with("compiler_builtins::float::")
            || n.starts_with("__aeabi_d")
            || [
                "__aeabi_f2d",
                "__aeabi_i2d",
                "__aeabi_ui2d",
                "__aeabi_l2d",
                "__aeabi_ul2d",
            ]
            .contains(&n)
    };
    let addr = |n: &str| funcs[n].addr;
    // Return addresses: after each `bl` to a function ("bl\t0x8003cc8 <name>").
    let returns_of = |targets: &HashSet<u64>| -> HashSet<u64> {
        dis.lines()
            .filter_map(|l| {
                let (a, insn) = l.split_once(':')?;
                let a = u64::from_str_radix(a.trim(), 16).ok()?;
                let rest = insn.trim().strip_prefix("bl")?.trim_start();
                let t = rest.split_whitespace().next()?.strip_prefix("0x")?;
                let t = u64::from_str_radix(t, 16).ok()?;
                targets.contains(&t).then_some(a + 4)
            })
            .collect()
    };
    let away: HashSet<u64> = left_out.iter().map(|n| addr(n)).collect();
    let whole_returns = returns_of(&HashSet::from([addr(entry)]));
    let marks = Marks {
        // An exception handler (no caller) is weighed between readings only.
        function: (!whole_returns.is_empty()).then(|| (addr(entry), whole_returns.clone())),
        left_out: (away.clone(), returns_of(&away)),
    };
    let keep =
        crate::stack::reachable(&funcs, &taken, entry, &|n| left_out.contains(n) || world(n));
    // The left-out functions' entries only: their bodies hold the world.
    let mut ranges: Vec<String> = keep
        .iter()
        .filter(|n| !world(n))
        .map(|n| {
            let len = if left_out.contains(n) {
                2
            } else {
                size.get(n.as_str()).copied().unwrap_or(2).max(2)
            };
            format!("0x{:x}+0x{len:x}", addr(n))
        })
        .collect();
    // The blocks the task's callers return to.
    ranges.extend(whole_returns.iter().map(|a| format!("0x{a:x}+0x2")));
    ranges.sort();
    Ok((marks, ranges.join(",")))
}

/// Reads QEMU's log from `err` (its standard error) in a thread, line by
/// line as it comes (hundreds of megabytes: never kept).
pub fn read_in_thread(
    marks: Marks,
    err: impl std::io::Read + Send + 'static,
) -> std::thread::JoinHandle<Reader> {
    std::thread::spawn(move || {
        use std::io::BufRead;
        let mut r = Reader::new(marks);
        let mut lines = std::io::BufReader::with_capacity(1 << 20, err);
        let mut line = String::new();
        while lines.read_line(&mut line).unwrap_or(0) > 0 {
            r.line(line.trim_end());
            line.clear();
        }
        r.finish();
        r
    })
}

/// QEMU's arguments for the trace `marks_for` describes.
pub fn qemu_args(dfilter: &str) -> [String; 4] {
    [
        "-d".into(),
        "in_asm,exec,nochain".into(),
        "-dfilter".into(),
        dfilter.into(),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn instructions_are_weighed_by_the_trm_table() {
        assert_eq!(weigh("adds", "r0, r0, r1").base, 1);
        assert_eq!(weigh("ldr.w", "r0, [sl]").base, 2);
        assert!(weigh("ldr.w", "r0, [sl]").single_mem);
        assert_eq!(weigh("push", "{r4, r5, r6, r7, lr}").base, 6);
        assert_eq!(
            weigh("vpush", "{d8, d9, d10, d11, d12, d13, d14, d15}").base,
            17
        );
        assert_eq!(weigh("vpush", "{d8-d15}").base, 17);
        assert_eq!(
            weigh("pop", "{r4, r5, r6, r7, pc}"),
            Cost {
                base: 6,
                taken: 3,
                ..Cost::default()
            }
        );
        assert!(weigh("yield", "").mark);
        assert_eq!(weigh("bne", "#0x800341a").taken, 3);
        assert_eq!(weigh("cbnz", "r0, #0x800341a").taken, 3);
        assert_eq!(weigh("vdiv.f32", "s0, s1, s2").base, 14);
        assert_eq!(weigh("vsqrt.f32", "s0, s1").base, 14);
        assert_eq!(weigh("vfma.f32", "s0, s1, s2").base, 3);
        assert_eq!(weigh("vmul.f32", "s0, s1, s2").base, 1);
        assert_eq!(weigh("sdiv", "r0, r1, r2").base, 12);
        assert_eq!(weigh("ldrd", "r5, r6, [r0]").base, 3);
        assert_eq!(weigh("mla", "r0, r1, r2, r3").base, 2);
    }

    /// A made-up log: a reading (its mark, `yield`, then the counter's
    /// load) at 0x200, a taken branch, a reading at 0x20a, a call to a
    /// left-out function, its return and a reading at 0x214.
    const LOG: &str = "\
----------------
IN: step
0x00000200:  bf10       yield
0x00000202:  6801       ldr      r1, [r0]
0x00000204:  6842       ldr      r2, [r0, #4]
0x00000206:  d000       beq      #0x20a

Trace 0: 0xa1 [00000000/00000200/00000010/ff020200] step
----------------
IN: step
0x0000020a:  bf10       yield
0x0000020c:  6801       ldr      r1, [r0]
0x0000020e:  f000 f800  bl       #0x300

Trace 0: 0xa2 [00000000/0000020a/00000010/ff020200] step
----------------
IN: world
0x00000300:  4770       bx       lr

Trace 0: 0xa4 [00000000/00000300/00000010/ff020200] world
----------------
IN: step
0x00000212:  bf00       nop
0x00000214:  bf10       yield
0x00000216:  6801       ldr      r1, [r0]

Trace 0: 0xa5 [00000000/00000212/00000010/ff020200] step
";

    #[test]
    fn segments_between_readings_are_weighed_and_the_world_left_out() {
        let mut r = Reader::new(Marks {
            function: None,
            left_out: (HashSet::from([0x300]), HashSet::from([0x212])),
        });
        for l in LOG.lines() {
            r.line(l);
        }
        r.finish();
        // yield 1, ldr 2, ldr 1 (pipelined), beq 1 + 3 (taken: 0x20a is
        // not the fall-through 0x208).
        let first = &r.segments[&(0x200, 0x20a)];
        assert_eq!(first.max_instructions, 4);
        assert_eq!(first.max_cycles, 1 + 2 + 1 + 4);
        // yield 1, ldr 2, bl 1 + 3 (to the world), the world left out,
        // nop 1.
        let second = &r.segments[&(0x20a, 0x214)];
        assert_eq!(second.max_instructions, 4);
        assert_eq!(second.max_cycles, 1 + 2 + 4 + 1);
        // Both as one window, across the reading between them.
        let both = &r.chains[&(0x200, 0x214, 2)];
        assert_eq!(both.max_instructions, 8);
        assert_eq!(both.max_cycles, 8 + 8);
    }

    #[test]
    fn a_rewound_block_counts_up_to_its_io_access() {
        let mut r = Reader::new(Marks::default());
        let log = LOG.replace(
            "Trace 0: 0xa1 [00000000/00000200/00000010/ff020200] step\n",
            "Trace 0: 0xa1 [00000000/00000200/00000010/ff020200] step\ncpu_io_recompile: rewound execution of TB to 00000202\n----------------\nIN: step\n0x00000202:  6801       ldr      r1, [r0]\n\nTrace 0: 0xa9 [00000000/00000202/00000010/ff038201] step\n",
        );
        for l in log.lines() {
            r.line(l);
        }
        r.finish();
        // The block ran up to its load, then the load alone (not
        // pipelined: a block of its own after the rewind, it still
        // follows the yield), then the block at 0x20a: no branch taken
        // counted (the cut block did not reach its end).
        let first = &r.segments[&(0x200, 0x20a)];
        assert_eq!(first.max_instructions, 2);
        assert_eq!(first.max_cycles, 1 + 2);
    }
}
