//! `cargo xtask slurm` (part of `cargo xtask test`): a sharded sweep on a
//! real scheduler. Installs Debian's Slurm (slurmctld, slurmd, the client
//! commands) and MUNGE when missing, starts a one-node cluster by hand in
//! `target/slurm/` (no systemd, no cgroups: processes tracked through
//! /proc), writes a grid's job array with `hopper-sim sweep --slurm 3`,
//! submits it and its merge job with `sbatch`, waits for both, and checks
//! the merged sweep is byte for byte the unsharded sweep of the same grid.
//! Then the same job array with one task made to fail (its part's
//! directory taken by a file): the failed task is reported with its shard
//! and its log, the merge job never runs, and `sweep merge` refuses the
//! incomplete set. Prints `slurm: tasks=3 runs=... merged=identical
//! failed_task=2 merge_refused=yes`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::session::Reaped;

/// Tasks in the array.
const TASKS: usize = 3;
/// The grid: 12 runs of 6 s from 0.08 m, 4 target apexes by 3 noise seeds.
const GRID: [&str; 12] = [
    "--params",
    "design",
    "--controller",
    "energy-apex",
    "--param",
    "target_apex=0.04:0.10:4",
    "--param",
    "seed=1:3:3",
    "--start-apex",
    "0.08",
    "--duration",
    "6",
];
/// The task whose part directory is taken in the failing array.
const FAILING_TASK: usize = 2;
/// How long a job may take to end.
const JOB_TIMEOUT: Duration = Duration::from_secs(300);
/// What the whole sweep writes, compared byte for byte.
const COMPARED: [&str; 3] = ["sweep.csv", "sweep.svg", "sweep.png"];

/// `program` on the PATH or in the system directories a root shell has
/// (the daemons live in /usr/sbin).
fn find_program(program: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&path)
        .chain(["/usr/sbin", "/sbin", "/usr/bin"].map(PathBuf::from))
        .map(|d| d.join(program))
        .find(|p| p.is_file())
}

/// `program`, installing Debian's `package` when it is missing.
fn program(program: &str, package: &str) -> Result<PathBuf, String> {
    if let Some(p) = find_program(program) {
        return Ok(p);
    }
    crate::qemu::ensure_package(program, package, true)?;
    find_program(program).ok_or_else(|| format!("{package} installed, but no {program}"))
}

fn write(path: &Path, text: &str) -> Result<(), String> {
    std::fs::write(path, text).map_err(|e| format!("{}: {e}", path.display()))
}

/// The one-node cluster's configuration: this machine as controller and
/// node, its CPUs, root as the Slurm user, MUNGE on a socket of our own,
/// no accounting, and process tracking through /proc (no cgroups here).
fn slurm_conf(dir: &Path, host: &str, cpus: usize, ports: (u16, u16)) -> String {
    let d = dir.display();
    let (ctld_port, d_port) = ports;
    format!(
        "ClusterName=hopper\n\
         SlurmctldHost={host}(127.0.0.1)\n\
         SlurmUser=root\n\
         SlurmdUser=root\n\
         SlurmctldPort={ctld_port}\n\
         SlurmdPort={d_port}\n\
         AuthType=auth/munge\n\
         CredType=cred/munge\n\
         AuthInfo=socket={d}/munge/munge.socket\n\
         StateSaveLocation={d}/state\n\
         SlurmdSpoolDir={d}/spool\n\
         SlurmctldPidFile={d}/slurmctld.pid\n\
         SlurmdPidFile={d}/slurmd.pid\n\
         SlurmctldLogFile={d}/slurmctld.log\n\
         SlurmdLogFile={d}/slurmd.log\n\
         ProctrackType=proctrack/linuxproc\n\
         TaskPlugin=task/none\n\
         JobAcctGatherType=jobacct_gather/none\n\
         AccountingStorageType=accounting_storage/none\n\
         JobCompType=jobcomp/none\n\
         MpiDefault=none\n\
         SchedulerType=sched/backfill\n\
         SelectType=select/cons_tres\n\
         SelectTypeParameters=CR_CPU\n\
         DependencyParameters=kill_invalid_depend\n\
         ReturnToService=2\n\
         NodeName=hopper-node NodeHostname={host} NodeAddr=127.0.0.1 CPUs={cpus} State=UNKNOWN\n\
         PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP\n"
    )
}

/// The running cluster: its daemons (stopped when dropped) and its
/// configuration for the client commands.
struct Cluster {
    conf: PathBuf,
    dir: PathBuf,
    _daemons: Vec<Reaped>,
}

impl Drop for Cluster {
    /// Cancels what is still queued or running (an error path: a job that
    /// timed out) before the daemons stop, so that no job outlives them.
    fn drop(&mut self) {
        let _ = self
            .client("scancel")
            .args(["--partition", "debug"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
    }
}

impl Cluster {
    /// A client command (`sbatch`, `squeue`, `sinfo`) of this cluster.
    fn client(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    /// `program args`' standard output, or its error.
    fn ask(&self, program: &str, args: &[&str]) -> Result<String, String> {
        let out = self
            .client(program)
            .args(args)
            .output()
            .map_err(|e| format!("cannot start {program}: {e}"))?;
        if !out.status.success() {
            return Err(format!(
                "{program} {}: {}",
                args.join(" "),
                String::from_utf8_lossy(&out.stderr).trim()
            ));
        }
        Ok(String::from_utf8_lossy(&out.stdout).trim().to_string())
    }

    /// The tail of a daemon's log, for an error.
    fn log_tail(&self, name: &str) -> String {
        tail(&self.dir.join(name), 8)
    }

    /// Submits `script` (with `extra` sbatch options); the job's id.
    fn submit(&self, script: &Path, extra: &[&str]) -> Result<String, String> {
        let mut args = vec!["--parsable"];
        args.extend_from_slice(extra);
        let s = script.to_string_lossy();
        args.push(&s);
        let id = self.ask("sbatch", &args)?;
        Ok(id.split(';').next().unwrap_or_default().to_string())
    }

    /// Waits until none of `jobs` is queued or running.
    fn wait(&self, jobs: &[&str]) -> Result<(), String> {
        let started = Instant::now();
        loop {
            let queued = self.ask("squeue", &["-h", "-o", "%i %T", "-j", &jobs.join(",")])?;
            if queued.is_empty() {
                return Ok(());
            }
            if started.elapsed() > JOB_TIMEOUT {
                return Err(format!(
                    "jobs {} still queued after {} s:\n{queued}\nslurmd.log ends:\n{}",
                    jobs.join(","),
                    JOB_TIMEOUT.as_secs(),
                    self.log_tail("slurmd.log")
                ));
            }
            std::thread::sleep(Duration::from_millis(250));
        }
    }
}

/// The last `n` lines of a file (or why there are none).
fn tail(path: &Path, n: usize) -> String {
    match std::fs::read_to_string(path) {
        Ok(t) => {
            let lines: Vec<&str> = t.lines().collect();
            lines[lines.len().saturating_sub(n)..].join("\n")
        }
        Err(e) => format!("({}: {e})", path.display()),
    }
}

/// Starts MUNGE, slurmctld and slurmd in `dir` and waits for the node to
/// be idle.
fn start(dir: &Path) -> Result<Cluster, String> {
    let munged = program("munged", "munge")?;
    let slurmctld = program("slurmctld", "slurmctld")?;
    let slurmd = program("slurmd", "slurmd")?;
    program("sbatch", "slurm-client")?;
    // Daemons an interrupted earlier run left behind, by their pid files.
    for pid_file in [
        dir.join("slurmd.pid"),
        dir.join("slurmctld.pid"),
        dir.join("munge").join("munged.pid"),
    ] {
        if let Some(pid) = std::fs::read_to_string(&pid_file)
            .ok()
            .and_then(|t| t.trim().parse::<u32>().ok())
        {
            let _ = Command::new("kill").arg(pid.to_string()).status();
        }
    }
    let _ = std::fs::remove_dir_all(dir);
    for sub in ["munge", "state", "spool"] {
        let d = dir.join(sub);
        std::fs::create_dir_all(&d).map_err(|e| format!("{}: {e}", d.display()))?;
    }
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map_err(|e| format!("hostname: {e}"))?
        .trim()
        .split('.')
        .next()
        .unwrap_or("localhost")
        .to_string();
    let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
    let conf = dir.join("slurm.conf");
    // Ports of its own, free now (not Slurm's 6817/6818: a real cluster's
    // daemons may hold those).
    let port = || -> Result<u16, String> {
        crate::session::free_addr()?
            .rsplit(':')
            .next()
            .and_then(|p| p.parse().ok())
            .ok_or_else(|| "no free port".to_string())
    };
    let ports = (port()?, port()?);
    if ports.0 == ports.1 {
        return Err("the same free port twice; run again".into());
    }
    write(&conf, &slurm_conf(dir, &host, cpus, ports))?;

    // MUNGE: a fresh key only this cluster uses, readable by root alone.
    let munge = dir.join("munge");
    let key = munge.join("munge.key");
    let mut bytes = vec![0u8; 1024];
    std::io::Read::read_exact(
        &mut std::fs::File::open("/dev/urandom").map_err(|e| format!("/dev/urandom: {e}"))?,
        &mut bytes,
    )
    .map_err(|e| format!("/dev/urandom: {e}"))?;
    std::fs::write(&key, &bytes).map_err(|e| format!("{}: {e}", key.display()))?;
    {
        use std::os::unix::fs::PermissionsExt;
        for (p, mode) in [(&key, 0o600), (&munge, 0o700)] {
            std::fs::set_permissions(p, std::fs::Permissions::from_mode(mode))
                .map_err(|e| format!("{}: {e}", p.display()))?;
        }
    }
    let spawn = |cmd: &mut Command, what: &str| -> Result<Reaped, String> {
        cmd.stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map(Reaped)
            .map_err(|e| format!("cannot start {what}: {e}"))
    };
    let mut daemons = vec![spawn(
        Command::new(&munged)
            .arg("--foreground")
            .arg("--force")
            .arg(format!("--socket={}", munge.join("munge.socket").display()))
            .arg(format!("--key-file={}", key.display()))
            .arg(format!("--pid-file={}", munge.join("munged.pid").display()))
            .arg(format!("--log-file={}", munge.join("munged.log").display()))
            .arg(format!(
                "--seed-file={}",
                munge.join("munged.seed").display()
            )),
        "munged",
    )?];
    let socket = munge.join("munge.socket");
    let started = Instant::now();
    while !socket.exists() {
        if started.elapsed() > Duration::from_secs(10) {
            return Err(format!(
                "munged did not start; its log ends:\n{}",
                tail(&munge.join("munged.log"), 8)
            ));
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    daemons.push(spawn(
        Command::new(&slurmctld).arg("-D").arg("-f").arg(&conf),
        "slurmctld",
    )?);
    daemons.push(spawn(
        Command::new(&slurmd)
            .args(["-D", "-N", "hopper-node", "-f"])
            .arg(&conf),
        "slurmd",
    )?);
    let cluster = Cluster {
        conf,
        dir: dir.to_path_buf(),
        _daemons: daemons,
    };
    let started = Instant::now();
    loop {
        let state = cluster
            .ask("sinfo", &["-h", "-o", "%t"])
            .unwrap_or_default();
        if state.starts_with("idle") {
            break;
        }
        if started.elapsed() > Duration::from_secs(60) {
            return Err(format!(
                "the node is not idle after 60 s (sinfo: `{state}`)\nslurmctld.log ends:\n{}\nslurmd.log ends:\n{}",
                cluster.log_tail("slurmctld.log"),
                cluster.log_tail("slurmd.log")
            ));
        }
        std::thread::sleep(Duration::from_millis(250));
    }
    Ok(cluster)
}

/// `hopper-sim sweep GRID --slurm TASKS --out dir`: the job's scripts.
fn write_job(sim: &Path, dir: &Path) -> Result<(PathBuf, PathBuf), String> {
    let out = Command::new(sim)
        .arg("sweep")
        .args(GRID)
        .arg("--slurm")
        .arg(TASKS.to_string())
        .arg("--out")
        .arg(dir)
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot start hopper-sim: {e}"))?;
    if !out.status.success() {
        return Err(format!("hopper-sim sweep --slurm: {}", out.status));
    }
    Ok((dir.join("sweep.sbatch"), dir.join("merge.sbatch")))
}

/// The tasks (1-based) whose part is missing from `dir/parts`.
fn failed_tasks(dir: &Path) -> Vec<usize> {
    (1..=TASKS)
        .filter(|k| {
            !dir.join("parts")
                .join(k.to_string())
                .join("sweep-part.json")
                .is_file()
        })
        .collect()
}

/// `cargo xtask slurm`.
pub fn run(root: &Path) -> Result<(), String> {
    let sim = crate::release_sim(root, "hopper-sim release build")?;
    eprintln!("xtask: slurm");
    let started = Instant::now();
    let dir = crate::target_dir(root)?.join("slurm");
    // Nothing of an earlier run may pass for this one's (the cluster's
    // own directory is cleared by `start`, after its daemons are stopped).
    for old in ["whole", "job", "failing"] {
        let _ = std::fs::remove_dir_all(dir.join(old));
    }
    let cluster = start(&dir.join("cluster"))?;
    eprintln!(
        "xtask: slurm: one-node cluster up in {:.1} s",
        started.elapsed().as_secs_f64()
    );

    // The unsharded sweep, the reference.
    let whole = dir.join("whole");
    let status = Command::new(&sim)
        .arg("sweep")
        .args(GRID)
        .arg("--out")
        .arg(&whole)
        .stdout(Stdio::null())
        .status()
        .map_err(|e| format!("cannot start hopper-sim: {e}"))?;
    if !status.success() {
        return Err(format!("hopper-sim sweep (unsharded): {status}"));
    }

    // The job array and its merge, as a user submits them.
    let job = dir.join("job");
    let (array, merge) = write_job(&sim, &job)?;
    let id = cluster.submit(&array, &[])?;
    let merge_id = cluster.submit(&merge, &[&format!("--dependency=afterok:{id}")])?;
    cluster.wait(&[&id, &merge_id])?;
    if let Some(k) = failed_tasks(&job).first() {
        return Err(format!(
            "slurm: task {k} (shard {k}/{TASKS}) left no part; its log {} ends:\n{}",
            job.join(format!("logs/shard-{k}.log")).display(),
            tail(&job.join(format!("logs/shard-{k}.log")), 8)
        ));
    }
    let mut runs = 0;
    for name in COMPARED {
        let (a, b) = (whole.join(name), job.join(name));
        let read = |p: &Path| std::fs::read(p).map_err(|e| format!("{}: {e}", p.display()));
        let (x, y) = (read(&a)?, read(&b)?);
        if x != y {
            return Err(format!(
                "slurm: the merged {} differs from the unsharded sweep's {} (merge log: {})",
                b.display(),
                a.display(),
                tail(&job.join("logs/merge.log"), 8)
            ));
        }
        if name == "sweep.csv" {
            runs = x.iter().filter(|&&c| c == b'\n').count().saturating_sub(1);
        }
    }

    // One task fails: its part's directory is a file.
    let failing = dir.join("failing");
    let (array, merge) = write_job(&sim, &failing)?;
    let taken = failing.join("parts").join(FAILING_TASK.to_string());
    std::fs::create_dir_all(failing.join("parts")).map_err(|e| format!("{e}"))?;
    write(&taken, "not a directory\n")?;
    let id = cluster.submit(&array, &[])?;
    let merge_id = cluster.submit(&merge, &[&format!("--dependency=afterok:{id}")])?;
    cluster.wait(&[&id, &merge_id])?;
    let failed = failed_tasks(&failing);
    if failed != [FAILING_TASK] {
        return Err(format!(
            "slurm: expected task {FAILING_TASK} alone to fail, got {failed:?}"
        ));
    }
    for k in &failed {
        let log = failing.join(format!("logs/shard-{k}.log"));
        eprintln!(
            "xtask: slurm: task {k} (shard {k}/{TASKS}) failed; its log {} ends:\n{}",
            log.display(),
            tail(&log, 3)
        );
    }
    if failing.join("sweep.csv").exists() {
        return Err("slurm: the merge job ran although a task failed".into());
    }
    let parts: Vec<PathBuf> = (1..=TASKS)
        .filter(|k| !failed.contains(k))
        .map(|k| failing.join("parts").join(k.to_string()))
        .collect();
    let out = Command::new(&sim)
        .args(["sweep", "merge"])
        .args(&parts)
        .arg("--out")
        .arg(failing.join("merged"))
        .output()
        .map_err(|e| format!("cannot start hopper-sim: {e}"))?;
    let said = String::from_utf8_lossy(&out.stderr);
    let expected = format!("1 of {TASKS} shards missing: {FAILING_TASK}");
    if out.status.success() || !said.contains(&expected) {
        return Err(format!(
            "slurm: the merge of an incomplete set should be refused naming shard {FAILING_TASK}; it said: {said}"
        ));
    }
    eprintln!("xtask: slurm: merge refused: {}", said.trim());
    drop(cluster);
    crate::took("slurm", started);
    println!(
        "slurm: tasks={TASKS} runs={runs} merged=identical failed_task={FAILING_TASK} merge_refused=yes"
    );
    Ok(())
}
