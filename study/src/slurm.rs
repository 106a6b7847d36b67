//! A sharded sweep as a Slurm job array (`hopper-sim sweep ... --slurm N
//! --out DIR`): the job scripts a user submits on a cluster. Task `K` of
//! the array runs `hopper-sim sweep ... --shard K/N` into `DIR/parts/K`
//! (its log in `DIR/logs/shard-K.log`); the merge job combines the parts
//! into `DIR` once every task has succeeded, and refuses an incomplete set
//! (`sweep merge` names the missing shards).
//!
//! Each task gets one CPU by default and runs rayon on the CPUs Slurm gave
//! it (`SLURM_CPUS_PER_TASK`), not on every core of the node it shares.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The job array's script, in the output directory.
pub const ARRAY_SCRIPT: &str = "sweep.sbatch";
/// The merge job's script, in the output directory.
pub const MERGE_SCRIPT: &str = "merge.sbatch";
/// The tasks' parts, `parts/K` for task `K`.
pub const PARTS_DIR: &str = "parts";
/// The tasks' logs, `logs/shard-K.log` for task `K`.
pub const LOGS_DIR: &str = "logs";

/// One sweep grid cut into a Slurm job array.
#[derive(Clone, Debug)]
pub struct Job {
    /// Tasks in the array, one shard each.
    pub tasks: usize,
    /// The sweep's own arguments (grid, controller, scenario), without
    /// `--slurm`, `--shard` or `--out`.
    pub grid_args: Vec<String>,
    /// The `hopper-sim` the tasks run unless `HOPPER_SIM` names another.
    pub exe: PathBuf,
    /// Where the tasks start (`--chdir`), so that relative paths in
    /// `grid_args` mean what they meant when the scripts were written.
    pub workdir: PathBuf,
    /// The output directory, absolute.
    pub out: PathBuf,
}

/// `arg` quoted for bash: as is when it holds only characters the shell
/// leaves alone, else in single quotes.
pub fn shell_quote(arg: &str) -> String {
    let plain = !arg.is_empty()
        && arg
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_./=:,+-@%".contains(c));
    if plain {
        arg.to_string()
    } else {
        format!("'{}'", arg.replace('\'', r"'\''"))
    }
}

fn quoted_path(p: &Path) -> String {
    shell_quote(&p.to_string_lossy())
}

impl Job {
    /// The directory of task `k`'s part.
    pub fn part_dir(&self, k: usize) -> PathBuf {
        self.out.join(PARTS_DIR).join(k.to_string())
    }

    /// Task `k`'s log.
    pub fn log(&self, k: usize) -> PathBuf {
        self.out.join(LOGS_DIR).join(format!("shard-{k}.log"))
    }

    /// The common head of both scripts: the interpreter, what wrote it and
    /// how to submit it.
    fn head(&self, name: &str, what: &str) -> String {
        let out = quoted_path(&self.out);
        let mut s = String::new();
        let _ = writeln!(s, "#!/bin/bash");
        let _ = writeln!(s, "# {what}");
        let _ = writeln!(
            s,
            "# Written by `hopper-sim sweep ... --slurm {} --out {out}`. Submit the",
            self.tasks
        );
        let _ = writeln!(
            s,
            "# tasks, then the merge, which runs once every task has succeeded:"
        );
        let _ = writeln!(s, "#   job=$(sbatch --parsable {out}/{ARRAY_SCRIPT})");
        let _ = writeln!(
            s,
            "#   sbatch --dependency=afterok:$job {out}/{MERGE_SCRIPT}"
        );
        let _ = writeln!(s, "#SBATCH --job-name={name}");
        let _ = writeln!(s, "#SBATCH --chdir={}", quoted_path(&self.workdir));
        s
    }

    /// The job array: task `K` runs shard `K` of `tasks`.
    pub fn array_script(&self) -> String {
        let mut s = self.head(
            "hopper-sweep",
            &format!(
                "A hopper-sim sweep as a Slurm job array: task K runs shard K/{} of the grid.",
                self.tasks
            ),
        );
        let _ = writeln!(s, "#SBATCH --array=1-{}", self.tasks);
        let _ = writeln!(s, "#SBATCH --cpus-per-task=1");
        let _ = writeln!(
            s,
            "#SBATCH --output={}",
            quoted_path(&self.out.join(LOGS_DIR).join("shard-%a.log"))
        );
        let _ = writeln!(s, "set -eu");
        let _ = writeln!(
            s,
            "export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\""
        );
        let _ = writeln!(
            s,
            "HOPPER_SIM=\"${{HOPPER_SIM:-{}}}\"",
            quoted_path(&self.exe)
        );
        let args: Vec<String> = self.grid_args.iter().map(|a| shell_quote(a)).collect();
        let _ = writeln!(
            s,
            "exec \"$HOPPER_SIM\" sweep {} --shard \"$SLURM_ARRAY_TASK_ID/{}\" --out {}/\"$SLURM_ARRAY_TASK_ID\"",
            args.join(" "),
            self.tasks,
            quoted_path(&self.out.join(PARTS_DIR))
        );
        s
    }

    /// The merge job: every part into the output directory's sweep.csv and
    /// plots (refused, naming the missing shards, when a task failed).
    pub fn merge_script(&self) -> String {
        let mut s = self.head(
            "hopper-sweep-merge",
            "The merge of a hopper-sim sweep's Slurm job array: its parts into one sweep.csv and its plots.",
        );
        let _ = writeln!(
            s,
            "#SBATCH --output={}",
            quoted_path(&self.out.join(LOGS_DIR).join("merge.log"))
        );
        // A failed task: the merge is cancelled rather than left pending
        // for ever (a cluster's default keeps it waiting).
        let _ = writeln!(s, "#SBATCH --kill-on-invalid-dep=yes");
        let _ = writeln!(s, "set -eu");
        let _ = writeln!(
            s,
            "HOPPER_SIM=\"${{HOPPER_SIM:-{}}}\"",
            quoted_path(&self.exe)
        );
        let _ = writeln!(
            s,
            "exec \"$HOPPER_SIM\" sweep merge {}/* --out {}",
            quoted_path(&self.out.join(PARTS_DIR)),
            quoted_path(&self.out)
        );
        s
    }

    /// Writes both scripts (executable) and the logs' directory (Slurm
    /// does not create it, and a task whose log cannot open fails without
    /// a word); the files written.
    pub fn write(&self) -> Result<Vec<PathBuf>, String> {
        // The merge reads every part under parts/: another grid's (an
        // earlier --slurm into the same directory) would spoil it.
        let parts = self.out.join(PARTS_DIR);
        if std::fs::read_dir(&parts).is_ok_and(|mut d| d.next().is_some()) {
            return Err(format!(
                "{} already holds a sweep's parts: give --out an empty directory (or remove them)",
                parts.display()
            ));
        }
        let logs = self.out.join(LOGS_DIR);
        std::fs::create_dir_all(&logs).map_err(|e| format!("{}: {e}", logs.display()))?;
        let mut written = Vec::new();
        for (name, text) in [
            (ARRAY_SCRIPT, self.array_script()),
            (MERGE_SCRIPT, self.merge_script()),
        ] {
            let path = self.out.join(name);
            std::fs::write(&path, text).map_err(|e| format!("{}: {e}", path.display()))?;
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt;
                std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))
                    .map_err(|e| format!("{}: {e}", path.display()))?;
            }
            written.push(path);
        }
        Ok(written)
    }
}

/// The sweep's own arguments from `hopper-sim`'s command line (everything
/// after `sweep`), without `--slurm N` and `--out DIR` (in either the
/// `--flag VALUE` or the `--flag=VALUE` form).
pub fn grid_args(after_sweep: &[String]) -> Vec<String> {
    let mut out = Vec::new();
    let mut it = after_sweep.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--slurm" | "--out" => {
                it.next();
            }
            _ if a.starts_with("--slurm=") || a.starts_with("--out=") => {}
            _ => out.push(a.clone()),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job() -> Job {
        Job {
            tasks: 3,
            grid_args: grid_args(
                &[
                    "--params",
                    "identified",
                    "--param",
                    "k=5000:30000:4",
                    "--out",
                    "x",
                    "--slurm=3",
                    "--scenario",
                    "my run.toml",
                ]
                .map(String::from),
            ),
            exe: PathBuf::from("/opt/bin/hopper-sim"),
            workdir: PathBuf::from("/home/u/study"),
            out: PathBuf::from("/home/u/study/out/k"),
        }
    }

    #[test]
    fn the_array_runs_one_shard_per_task_into_its_part() {
        let s = job().array_script();
        assert!(s.starts_with("#!/bin/bash\n"));
        assert!(s.contains("#SBATCH --array=1-3\n"), "{s}");
        assert!(s.contains("#SBATCH --chdir=/home/u/study\n"), "{s}");
        assert!(
            s.contains("#SBATCH --output=/home/u/study/out/k/logs/shard-%a.log\n"),
            "{s}"
        );
        assert!(
            s.contains(
                "exec \"$HOPPER_SIM\" sweep --params identified --param k=5000:30000:4 \
                 --scenario 'my run.toml' --shard \"$SLURM_ARRAY_TASK_ID/3\" \
                 --out /home/u/study/out/k/parts/\"$SLURM_ARRAY_TASK_ID\"\n"
            ),
            "{s}"
        );
        assert!(s.contains("HOPPER_SIM=\"${HOPPER_SIM:-/opt/bin/hopper-sim}\"\n"));
    }

    #[test]
    fn the_merge_reads_every_part_into_the_output() {
        let s = job().merge_script();
        assert!(
            s.contains(
                "exec \"$HOPPER_SIM\" sweep merge /home/u/study/out/k/parts/* --out /home/u/study/out/k\n"
            ),
            "{s}"
        );
        assert!(s.contains("#SBATCH --output=/home/u/study/out/k/logs/merge.log\n"));
        assert!(s.contains("#SBATCH --kill-on-invalid-dep=yes\n"));
    }

    #[test]
    fn scripts_are_written_once_per_set_of_parts() {
        let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
        let j = Job {
            out: dir.path().join("k"),
            ..job()
        };
        let written = j.write().unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(written.len(), 2);
        assert!(j.out.join(LOGS_DIR).is_dir(), "Slurm does not create it");
        // A finished task's part there: another --slurm into it is refused.
        std::fs::create_dir_all(j.part_dir(1)).unwrap_or_else(|e| panic!("{e}"));
        let e = j.write().err().unwrap_or_default();
        assert!(e.contains("already holds a sweep's parts"), "{e}");
    }

    #[test]
    fn quoting_keeps_every_byte() {
        assert_eq!(shell_quote("k=1:2:3"), "k=1:2:3");
        assert_eq!(shell_quote(""), "''");
        assert_eq!(shell_quote("it's $x"), r"'it'\''s $x'");
    }
}
