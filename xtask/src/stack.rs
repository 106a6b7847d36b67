//! A worst-case stack bound per task of the board image, from its machine
//! code (`cargo xtask size`'s `stack:` line). The stable toolchain has no
//! `-Z emit-stack-sizes`, so the bound is read off the disassembly
//! (`llvm-objdump -d`, from the `llvm-tools` component):
//!
//! - a function's frame is every stack-pointer decrement in its body
//!   (`push`, `vpush`, `sub sp, #N`, `str rX, [sp, #-N]!`), summed: an
//!   upper bound (a function that pushes twice on two paths counts both);
//! - its callees are every `bl` target and every branch to another
//!   function (a tail call, counted as a call: an upper bound again);
//! - a task's depth is its handler's frame plus its deepest callee's,
//!   through the call graph.
//!
//! An indirect call (`blx rN`, `bx rN` other than `bx lr`: a
//! parameter slot's function pointer) may reach any function whose
//! address the image holds in its read-only data or its initialised data
//! (a vtable, a table of slots: [`address_taken`]); it is bounded by the
//! deepest of them (assuming no recursion through function pointers: a
//! candidate already on the call path is left out). What this cannot bound
//! is refused, not guessed: a
//! stack pointer moved by a register, or recursion, reachable from a task,
//! fails the check with the function named.
//!
//! The same call graph says what a task can reach ([`reaches`],
//! [`reachable`]): `cargo xtask size`'s `isolation:` check (no task
//! reaches the panic handler; the control and serial interrupts reach no
//! critical section and mask no interrupt) and the functions `cargo xtask
//! qemu`'s execution trace keeps.
//!
//! The main stack is shared: `init` runs alone first; then `idle` runs,
//! and each priority level's task can preempt the one below, each
//! preemption stacking an exception frame (26 words with the FPU's lazy
//! state reserved: 104 bytes). The worst case is idle plus every level's
//! deepest task plus a frame each, against the stack's room: the RAM the
//! statics leave (flip-link puts the stack below them).

use std::collections::{HashMap, HashSet};

/// One function of the image.
#[derive(Debug, Default, Clone, PartialEq)]
pub struct Function {
    /// Its address.
    pub addr: u64,
    /// Bytes its body moves the stack pointer down, summed.
    pub frame: u64,
    /// Addresses it calls or branches to outside itself.
    pub calls: Vec<u64>,
    /// Whether it calls through a function pointer.
    pub indirect: bool,
    /// What makes its depth unknown, if anything (a stack pointer set
    /// from a register).
    pub unbounded: Option<String>,
    /// Whether it masks every interrupt (`cpsid`, a PRIMASK or FAULTMASK
    /// write).
    pub masks_all: bool,
    /// Whether it raises BASEPRI (`msr basepri_max`).
    pub raises_basepri: bool,
}

/// An image's call graph: its functions, and the targets whose address is
/// taken (what an indirect call may reach).
pub struct Image {
    /// The functions by name.
    pub funcs: HashMap<String, Function>,
    /// The address-taken targets ([`address_taken`]).
    pub taken: Vec<u64>,
    /// The disassembly itself (`llvm-objdump -d`).
    pub dis: String,
}

impl Image {
    /// Disassemble `elf` and read its data sections.
    pub fn read(elf: &std::path::Path) -> Result<Self, String> {
        let dis = crate::llvm_tool("llvm-objdump", &["-d", "--no-show-raw-insn"], elf)?;
        let funcs = parse(&dis);
        let data = crate::llvm_tool("llvm-objdump", &["-s", "-j", ".rodata", "-j", ".data"], elf)?;
        let taken = address_taken(&funcs, &data);
        Ok(Self { funcs, taken, dis })
    }
}

/// The image's functions by name, from `llvm-objdump -d` output.
pub fn parse(dis: &str) -> HashMap<String, Function> {
    let mut funcs: HashMap<String, Function> = HashMap::new();
    let mut cur: Option<String> = None;
    for line in dis.lines() {
        // "080001e0 <ADC>:"
        if let Some((addr, rest)) = line.split_once(" <") {
            if let (Some(name), Ok(a)) = (rest.strip_suffix(">:"), u64::from_str_radix(addr, 16)) {
                cur = Some(name.to_string());
                funcs.insert(
                    name.to_string(),
                    Function {
                        addr: a,
                        ..Function::default()
                    },
                );
                continue;
            }
        }
        let Some(f) = cur.as_ref().and_then(|c| funcs.get_mut(c)) else {
            continue;
        };
        // " 80001e0:      \tpush\t{r4, r5, r6, r7, lr}"
        let Some((addr, insn)) = line.split_once(':') else {
            continue;
        };
        if u64::from_str_radix(addr.trim(), 16).is_err() {
            continue;
        }
        let insn = insn.trim();
        let (op, args) = insn.split_once(char::is_whitespace).unwrap_or((insn, ""));
        let args = args.trim();
        let name = cur.clone().unwrap_or_default();
        apply(f, &name, op, args);
    }
    funcs
}

/// What one instruction adds to `f` (named `name`).
fn apply(f: &mut Function, name: &str, op: &str, args: &str) {
    let regs = |args: &str| -> Vec<String> {
        args.split_once('{')
            .and_then(|(_, r)| r.split_once('}'))
            .map(|(r, _)| r.split(',').map(|s| s.trim().to_string()).collect())
            .unwrap_or_default()
    };
    let count = |rs: &[String]| -> u64 {
        rs.iter()
            .map(|r| match r.split_once('-') {
                Some((a, b)) => {
                    let n = |s: &str| s[1..].parse::<u64>().unwrap_or(0);
                    n(b).saturating_sub(n(a)) + 1
                }
                None => 1,
            })
            .sum()
    };
    let imm = |args: &str| -> Option<u64> {
        let v = args
            .split('#')
            .nth(1)?
            .trim_end_matches(']')
            .trim_end_matches('!');
        let v = v
            .split(|c: char| c == ']' || c == ',' || c.is_whitespace())
            .next()?;
        match v.strip_prefix("0x") {
            Some(h) => u64::from_str_radix(h, 16).ok(),
            None => v.trim_start_matches('-').parse().ok(),
        }
    };
    match op {
        "push" | "push.w" => f.frame += 4 * count(&regs(args)),
        "stmdb" | "stmdb.w" if args.starts_with("sp!") => f.frame += 4 * count(&regs(args)),
        "vpush" | "vpush.64" | "vpush.32" => {
            let rs = regs(args);
            let width = if rs.first().is_some_and(|r| r.starts_with('d')) {
                8
            } else {
                4
            };
            f.frame += width * count(&rs);
        }
        "sub" | "sub.w" | "subw" if args.starts_with("sp,") => {
            match imm(args).filter(|_| args.contains('#')) {
                Some(n) => f.frame += n,
                None => {
                    f.unbounded = Some(format!(
                        "{name}: the stack pointer moved by a register ({op} {args})"
                    ))
                }
            }
        }
        "str" | "str.w" | "strd" if args.contains("[sp, #-") && args.ends_with('!') => {
            f.frame += imm(args).unwrap_or(0);
        }
        "mov" | "msr" if args.starts_with("sp,") || args.starts_with("msp,") => {
            f.unbounded = Some(format!(
                "{name}: the stack pointer set from a register ({op} {args})"
            ));
        }
        "blx" | "bx" if args != "lr" && !args.starts_with("0x") => f.indirect = true,
        "cpsid" => f.masks_all = true,
        "msr" if args.starts_with("primask") || args.starts_with("faultmask") => f.masks_all = true,
        "msr" if args.starts_with("basepri_max") => f.raises_basepri = true,
        _ if op.starts_with('b') || op.starts_with("cb") => {
            // "bl\t0x8003cc8 <name>", "b.w\t0x... <other>": a call, or a
            // branch out of this function (a tail call).
            let Some((target, sym)) = args.split_once(" <") else {
                return;
            };
            let Some(addr) = target
                .trim()
                .rsplit(' ')
                .next()
                .and_then(|t| t.strip_prefix("0x"))
                .and_then(|h| u64::from_str_radix(h, 16).ok())
            else {
                return;
            };
            // "name>    @ imm = #0x28": the symbol, its offset if any.
            let sym = sym.split('>').next().unwrap_or_default();
            let own = sym == name || sym.starts_with(&format!("{name}+"));
            if op.starts_with("bl") || (!own && !sym.contains('+')) {
                f.calls.push(addr);
            }
        }
        _ => {}
    }
}

/// The functions whose address (with the Thumb bit) appears as a word in
/// `dump`, `llvm-objdump -s` of the data sections: the targets an
/// indirect call may have.
pub fn address_taken(funcs: &HashMap<String, Function>, dump: &str) -> Vec<u64> {
    let starts: HashSet<u64> = funcs.values().map(|f| f.addr).collect();
    let mut taken: Vec<u64> = dump
        .lines()
        .filter_map(|l| l.trim_start().split_once(' '))
        .filter(|(a, _)| u64::from_str_radix(a, 16).is_ok())
        .flat_map(|(_, rest)| {
            // " 80195c0 02000000 00000400 ...  ascii": four words a line,
            // each four bytes in memory order (little-endian).
            rest.split_whitespace()
                .take(4)
                .filter(|w| w.len() == 8)
                .filter_map(|w| {
                    let b = u32::from_str_radix(w, 16).ok()?;
                    Some(u64::from(b.swap_bytes()))
                })
                .collect::<Vec<_>>()
        })
        .filter(|w| w & 1 == 1 && starts.contains(&(w & !1)))
        .map(|w| w & !1)
        .collect();
    taken.sort_unstable();
    taken.dedup();
    taken
}

/// A task's depth, bytes, and its deepest path (function names), or what
/// makes it unknown; an indirect call reaches any of `taken`.
pub fn depth(
    funcs: &HashMap<String, Function>,
    taken: &[u64],
    entry: &str,
) -> Result<(u64, Vec<String>), String> {
    let by_addr: HashMap<u64, &str> = funcs.iter().map(|(n, f)| (f.addr, n.as_str())).collect();
    let mut memo: HashMap<String, (u64, Vec<String>)> = HashMap::new();
    walk(
        funcs,
        &by_addr,
        taken,
        entry,
        &mut HashSet::new(),
        &mut memo,
    )
}

fn walk(
    funcs: &HashMap<String, Function>,
    by_addr: &HashMap<u64, &str>,
    taken: &[u64],
    name: &str,
    on_path: &mut HashSet<String>,
    memo: &mut HashMap<String, (u64, Vec<String>)>,
) -> Result<(u64, Vec<String>), String> {
    if let Some(d) = memo.get(name) {
        return Ok(d.clone());
    }
    let f = funcs
        .get(name)
        .ok_or_else(|| format!("no function `{name}` in the image"))?;
    if let Some(why) = &f.unbounded {
        return Err(why.clone());
    }
    if !on_path.insert(name.to_string()) {
        return Err(format!("{name}: recursion"));
    }
    let mut deepest = (0, Vec::new());
    let indirect = if f.indirect { taken } else { &[] };
    let direct = f.calls.len();
    for (k, a) in f.calls.iter().chain(indirect).enumerate() {
        let Some(callee) = by_addr.get(a) else {
            continue;
        };
        // A function pointer's candidates already on the path are left
        // out: the bound assumes no recursion through function pointers
        // (a waker pends an interrupt, a parameter slot reads a field).
        if k >= direct && on_path.contains(*callee) {
            continue;
        }
        let d = walk(funcs, by_addr, taken, callee, on_path, memo)?;
        if d.0 > deepest.0 {
            deepest = d;
        }
    }
    on_path.remove(name);
    let mut path = vec![name.to_string()];
    path.extend(deepest.1);
    let d = (f.frame + deepest.0, path);
    memo.insert(name.to_string(), d.clone());
    Ok(d)
}

/// A path from `entry` to a function `hit` accepts (names, entry first),
/// through direct calls and, from an indirect call, any of `taken`; or
/// `None` when no such function is reachable. An over-approximation in
/// the same way as [`depth`]: a call on one path counts on every path.
pub fn reaches(
    funcs: &HashMap<String, Function>,
    taken: &[u64],
    entry: &str,
    hit: &dyn Fn(&str) -> bool,
) -> Option<Vec<String>> {
    let by_addr: HashMap<u64, &str> = funcs.iter().map(|(n, f)| (f.addr, n.as_str())).collect();
    // Breadth first, so the path named is a shortest one.
    let mut from: HashMap<&str, &str> = HashMap::new();
    let mut queue = std::collections::VecDeque::from([entry]);
    let mut seen: HashSet<&str> = HashSet::from([entry]);
    while let Some(name) = queue.pop_front() {
        if hit(name) {
            let mut path = vec![name.to_string()];
            let mut at = name;
            while let Some(prev) = from.get(at) {
                path.push(prev.to_string());
                at = prev;
            }
            path.reverse();
            return Some(path);
        }
        let Some(f) = funcs.get(name) else {
            continue;
        };
        let indirect = if f.indirect { taken } else { &[] };
        for a in f.calls.iter().chain(indirect) {
            if let Some(callee) = by_addr.get(a) {
                if seen.insert(callee) {
                    from.insert(callee, name);
                    queue.push_back(callee);
                }
            }
        }
    }
    None
}

/// Every function reachable from `entry` (itself included), not going
/// on through the ones `stop` accepts (which are included).
pub fn reachable(
    funcs: &HashMap<String, Function>,
    taken: &[u64],
    entry: &str,
    stop: &dyn Fn(&str) -> bool,
) -> HashSet<String> {
    let by_addr: HashMap<u64, &str> = funcs.iter().map(|(n, f)| (f.addr, n.as_str())).collect();
    let mut seen = HashSet::from([entry.to_string()]);
    let mut queue = vec![entry.to_string()];
    while let Some(name) = queue.pop() {
        let Some(f) = funcs.get(&name).filter(|_| !stop(&name)) else {
            continue;
        };
        let indirect = if f.indirect { taken } else { &[] };
        for a in f.calls.iter().chain(indirect) {
            if let Some(callee) = by_addr.get(a) {
                if seen.insert(callee.to_string()) {
                    queue.push(callee.to_string());
                }
            }
        }
    }
    seen
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIS: &str = "\
08000100 <ADC>:
 8000100:      \tpush\t{r4, r5, r6, r7, lr}
 8000102:      \tpush.w\t{r8, r9, r10, r11}
 8000106:      \tvpush\t{d8, d9}
 800010a:      \tsub\tsp, #0x1c8
 800010c:      \tbl\t0x8000200 <step>    @ imm = #0xf2
 8000110:      \tbeq\t0x8000114 <ADC+0x14>    @ imm = #0x0
 8000111:      \tb\t0x8000100 <ADC>    @ imm = #-0x14
 8000112:      \tb.w\t0x8000300 <leaf>

08000200 <step>:
 8000200:      \tpush\t{r7, lr}
 8000202:      \tsub.w\tsp, sp, #0x100
 8000206:      \tbl\t0x8000300 <leaf>
 800020a:      \tpop\t{r7, pc}

08000300 <leaf>:
 8000300:      \tstr\tr4, [sp, #-8]!
 8000302:      \tcpsid\ti
 8000304:      \tbx\tlr

08000400 <ptr>:
 8000400:      \tpush\t{r7, lr}
 8000402:      \tblx\tr3

08000500 <rec>:
 8000500:      \tpush\t{r7, lr}
 8000502:      \tbl\t0x8000500 <rec>
";

    #[test]
    fn frames_and_the_deepest_path_are_read_off_the_disassembly() {
        let f = parse(DIS);
        // 5 + 4 registers, two doubles, 0x1c8.
        assert_eq!(f["ADC"].frame, 36 + 16 + 456);
        assert_eq!(f["step"].frame, 8 + 256);
        assert_eq!(f["leaf"].frame, 8);
        assert!(f["leaf"].masks_all && !f["step"].masks_all);
        // The branch inside ADC is not a call; the tail call to `leaf` is.
        assert_eq!(f["ADC"].calls, [0x800_0200, 0x800_0300]);
        let (d, path) = depth(&f, &[], "ADC").unwrap();
        assert_eq!(d, 508 + 264 + 8);
        assert_eq!(path, ["ADC", "step", "leaf"]);
    }

    #[test]
    fn an_indirect_call_reaches_the_deepest_address_taken_function() {
        let f = parse(DIS);
        // A vtable in .rodata holding `step` and `leaf` (Thumb bit set),
        // and a word that is no function's.
        let dump = " 8019000 01020008 01030008 00000020 01000000  ................\n";
        let taken = address_taken(&f, dump);
        assert_eq!(taken, [0x800_0200, 0x800_0300]);
        let (d, path) = depth(&f, &taken, "ptr").unwrap();
        assert_eq!(d, 8 + 264 + 8);
        assert_eq!(path, ["ptr", "step", "leaf"]);
    }

    #[test]
    fn recursion_is_refused_by_name() {
        let f = parse(DIS);
        assert!(depth(&f, &[], "rec")
            .unwrap_err()
            .contains("rec: recursion"));
    }

    #[test]
    fn a_reachable_function_is_found_with_its_path() {
        let f = parse(DIS);
        assert_eq!(
            reaches(&f, &[], "ADC", &|n| n == "leaf").unwrap(),
            ["ADC", "leaf"]
        );
        assert_eq!(reaches(&f, &[], "step", &|n| n == "rec"), None);
        // Through a function pointer: any address-taken function.
        assert_eq!(
            reaches(&f, &[0x800_0500], "ptr", &|n| n == "rec").unwrap(),
            ["ptr", "rec"]
        );
    }
}
