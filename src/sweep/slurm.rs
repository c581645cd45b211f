//! Slurm job arrays for a sweep: one array task per unfinished run, each running
//! `dhrl sweep run-one`, so that Slurm does the scheduling, the limits and the requeueing.
//!
//! A run stops with a checkpoint on SIGTERM (what Slurm sends every process of a job it
//! preempts, requeues or times out) and on SIGUSR1, which the script asks for `signal_lead`
//! seconds before the time limit: the array task then requeues itself, and the requeued task
//! resumes the run from its checkpoint.
use std::path::{Path, PathBuf};

use super::SweepError;
use super::manifest::{ManifestRun, Sweep};
use super::runner::EXIT_INTERRUPTED;

/// What `dhrl sweep slurm` puts into the job script beyond the runs themselves.
#[derive(Debug, Clone, PartialEq)]
pub struct SlurmOptions {
    pub partition: Option<String>,
    pub account: Option<String>,
    /// Each task's time limit, in one of Slurm's formats (`MM`, `HH:MM:SS`, `D-HH:MM`, …).
    pub time: Option<String>,
    /// Memory per task, as `--mem` takes it (`4G`, `4000M`).
    pub mem: Option<String>,
    /// Array tasks running at once (`--array=…%K`).
    pub max_parallel: Option<usize>,
    /// Cores per task; by default the most learner threads among the sweep's algorithms.
    pub cpus_per_task: Option<usize>,
    /// Seconds before the time limit at which a run is told to checkpoint and requeue.
    pub signal_lead: u64,
    /// The cluster's MaxArraySize: array task ids stay below it, so a larger sweep is split
    /// into several scripts.
    pub max_array_size: usize,
    /// More `#SBATCH` options, each one argument as given to `sbatch` (`--qos=long`).
    pub extra: Vec<String>,
    /// Runs per task: each task trains a group of [`super::stack_groups`] as one stack.
    pub stack: usize,
}

impl Default for SlurmOptions {
    fn default() -> SlurmOptions {
        SlurmOptions {
            partition: None,
            account: None,
            time: None,
            mem: None,
            max_parallel: None,
            cpus_per_task: None,
            signal_lead: 300,
            max_array_size: 1001,
            extra: Vec::new(),
            stack: 1,
        }
    }
}

/// One job script written into `DIR/slurm/`: its array task `i` runs manifest run `runs[i]`
/// (with a stack, group `runs[i]` of [`super::stack_groups`]).
#[derive(Debug, Clone, PartialEq)]
pub struct ArrayScript {
    pub path: PathBuf,
    pub runs: Vec<usize>,
}

/// Writes one Slurm array script per `max_array_size` unfinished runs of `sweep` into
/// `DIR/slurm/` (replacing the scripts of an earlier call), each task running `exe sweep
/// run-one DIR --index I`, its output appended to `DIR/slurm/logs/<job>_<task>.log`.
/// Nothing is written when every run has finished.
pub fn write_array_scripts(
    sweep: &Sweep,
    exe: &Path,
    options: &SlurmOptions,
) -> Result<Vec<ArrayScript>, SweepError> {
    check(options)?;
    let dir = sweep.dir.canonicalize().map_err(|e| SweepError::Io {
        path: sweep.dir.display().to_string(),
        message: e.to_string(),
    })?;
    let slurm = dir.join("slurm");
    let logs = slurm.join("logs");
    std::fs::create_dir_all(&logs).map_err(|e| SweepError::Io {
        path: logs.display().to_string(),
        message: e.to_string(),
    })?;
    remove_earlier_scripts(&slurm)?;
    let unfinished: Vec<&ManifestRun> = sweep.runs.iter().filter(|r| !sweep.finished(r)).collect();
    // What the array's tasks take: the unfinished runs, or the groups holding one.
    let units: Vec<usize> = super::stack_groups(sweep, options.stack)
        .into_iter()
        .enumerate()
        .filter(|(_, group)| group.iter().any(|&i| !sweep.finished(&sweep.runs[i])))
        .map(|(number, group)| if options.stack <= 1 { group[0] } else { number })
        .collect();
    let cpus = match options.cpus_per_task {
        Some(cpus) => cpus,
        None => unfinished
            .iter()
            .map(|r| r.config.algo.info().learner_threads)
            .max()
            .unwrap_or(1),
    };
    let name = dir
        .file_name()
        .map_or("sweep".into(), |n| n.to_string_lossy().into_owned());
    let mut scripts = Vec::new();
    for (k, chunk) in units
        .chunks(options.max_array_size.min(units.len().max(1)))
        .enumerate()
    {
        let runs: Vec<usize> = chunk.to_vec();
        let path = slurm.join(format!("array-{k}.sbatch"));
        let text = script(&dir, &logs, exe, &name, &runs, cpus, options);
        super::write_atomically(&path, &text)?;
        scripts.push(ArrayScript { path, runs });
    }
    Ok(scripts)
}

fn remove_earlier_scripts(slurm: &Path) -> Result<(), SweepError> {
    let io = |path: &Path| {
        let path = path.display().to_string();
        move |e: std::io::Error| SweepError::Io {
            path,
            message: e.to_string(),
        }
    };
    for entry in std::fs::read_dir(slurm).map_err(io(slurm))? {
        let path = entry.map_err(io(slurm))?.path();
        let name = path.file_name().unwrap_or_default().to_string_lossy();
        if name.starts_with("array-") && name.ends_with(".sbatch") {
            std::fs::remove_file(&path).map_err(io(&path))?;
        }
    }
    Ok(())
}

fn script(
    dir: &Path,
    logs: &Path,
    exe: &Path,
    name: &str,
    runs: &[usize],
    cpus: usize,
    options: &SlurmOptions,
) -> String {
    let mut directives = vec![
        format!("--job-name={}", quote_free(&format!("dhrl-{name}"))),
        format!(
            "--array=0-{}{}",
            runs.len() - 1,
            options
                .max_parallel
                .map_or(String::new(), |k| format!("%{k}"))
        ),
        format!("--cpus-per-task={cpus}"),
        "--ntasks=1".into(),
        "--requeue".into(),
        format!("--signal=B:USR1@{}", options.signal_lead),
        "--open-mode=append".into(),
        format!("--output={}/%A_%a.log", logs.display()),
    ];
    for (flag, value) in [
        ("partition", &options.partition),
        ("account", &options.account),
        ("time", &options.time),
        ("mem", &options.mem),
    ] {
        if let Some(value) = value {
            directives.push(format!("--{flag}={value}"));
        }
    }
    directives.extend(options.extra.iter().cloned());
    let runs_list = runs
        .iter()
        .map(usize::to_string)
        .collect::<Vec<_>>()
        .join(" ");
    format!(
        r#"#!/bin/bash
# Written by `dhrl sweep slurm` for the sweep in {dir}:
# array task i runs {what} ${{runs[i]}} through `dhrl sweep run-one`.
{sbatch}
runs=({runs_list})
index=${{runs[$SLURM_ARRAY_TASK_ID]}}
echo "dhrl: array task $SLURM_ARRAY_TASK_ID (restart ${{SLURM_RESTART_COUNT:-0}}) runs {what} $index on $(hostname) at $(date -Is)"
{exe} sweep run-one {dir_quoted} {unit} "$index" &
run=$!
# Slurm's SIGTERM (a preemption, `scontrol requeue`, the time limit) reaches every process of
# the job, the run included, which checkpoints and exits: this shell only waits for it.
trap ':' TERM
# The pre-limit signal reaches this shell only (B:): the run checkpoints, then the task requeues.
requeue=0
trap 'requeue=1; kill -USR1 "$run"' USR1
while kill -0 "$run" 2>/dev/null; do wait "$run"; done
wait "$run"
status=$?
if [[ $status == {interrupted} && $requeue == 1 ]]; then
    echo "dhrl: stopped with a checkpoint before the time limit; requeueing"
    scontrol requeue "${{SLURM_ARRAY_JOB_ID}}_${{SLURM_ARRAY_TASK_ID}}"
fi
exit "$status"
"#,
        dir = dir.display(),
        sbatch = directives
            .iter()
            .map(|d| format!("#SBATCH {d}"))
            .collect::<Vec<_>>()
            .join("\n"),
        exe = shell_quote(&exe.display().to_string()),
        dir_quoted = shell_quote(&dir.display().to_string()),
        interrupted = EXIT_INTERRUPTED,
        what = if options.stack <= 1 {
            "the manifest's run".to_string()
        } else {
            "stack group".to_string()
        },
        unit = if options.stack <= 1 {
            "--index".to_string()
        } else {
            format!("--stack {} --group", options.stack)
        },
    )
}

/// `text` in single quotes for the shell.
pub fn shell_quote(text: &str) -> String {
    format!("'{}'", text.replace('\'', r"'\''"))
}

/// A job name without what would end an `#SBATCH` line or need quoting.
fn quote_free(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn check(options: &SlurmOptions) -> Result<(), SweepError> {
    let invalid = |what: &str, value: &str, accepted: &str| {
        Err(SweepError::Invalid(format!(
            "{what} '{value}' is not accepted: {accepted}"
        )))
    };
    for (what, value) in [
        ("--partition", &options.partition),
        ("--account", &options.account),
        ("--mem", &options.mem),
    ] {
        if let Some(value) = value
            && (value.is_empty()
                || !value
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_.,:+".contains(c)))
        {
            return invalid(
                what,
                value,
                "letters, digits and - _ . , : + only (as Slurm names and sizes are)",
            );
        }
    }
    for extra in &options.extra {
        if !extra.starts_with("--") || extra.contains(['\n', '\r']) {
            return invalid(
                "--sbatch",
                extra,
                "one sbatch option per --sbatch, starting with -- (e.g. --sbatch=--qos=long)",
            );
        }
    }
    if options.max_parallel == Some(0) || options.cpus_per_task == Some(0) {
        return Err(SweepError::Invalid(
            "--max-parallel and --cpus-per-task take at least 1".into(),
        ));
    }
    if options.max_array_size < 1 {
        return Err(SweepError::Invalid(
            "--max-array-size takes at least 1 (the cluster's MaxArraySize)".into(),
        ));
    }
    // Slurm's --signal takes at most 65535 s.
    if !(1..=65_535).contains(&options.signal_lead) {
        return invalid(
            "--signal-lead",
            &options.signal_lead.to_string(),
            "seconds from 1 to 65535",
        );
    }
    if let Some(time) = &options.time {
        let Some(limit) = time_limit_seconds(time) else {
            return invalid(
                "--time",
                time,
                "one of Slurm's formats: MM, MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS",
            );
        };
        if options.signal_lead >= limit {
            return Err(SweepError::Invalid(format!(
                "the pre-limit signal (--signal-lead {} s) must come after the start of a task \
                 limited to --time {time} ({limit} s): give a longer --time or a shorter lead",
                options.signal_lead
            )));
        }
    }
    Ok(())
}

/// Seconds of a Slurm time limit: `MM`, `MM:SS`, `HH:MM:SS`, `D-HH`, `D-HH:MM`, `D-HH:MM:SS`.
pub fn time_limit_seconds(text: &str) -> Option<u64> {
    let number = |s: &str| -> Option<u64> {
        (!s.is_empty() && s.chars().all(|c| c.is_ascii_digit()))
            .then(|| s.parse().ok())
            .flatten()
    };
    let (days, rest) = match text.split_once('-') {
        Some((days, rest)) => (Some(number(days)?), rest),
        None => (None, text),
    };
    let parts: Vec<u64> = rest.split(':').map(number).collect::<Option<_>>()?;
    let seconds = match (days, parts.as_slice()) {
        (None, [m]) => m * 60,
        (None, [m, s]) => m * 60 + s,
        (None, [h, m, s]) => h * 3600 + m * 60 + s,
        (Some(d), [h]) => d * 86_400 + h * 3600,
        (Some(d), [h, m]) => d * 86_400 + h * 3600 + m * 60,
        (Some(d), [h, m, s]) => d * 86_400 + h * 3600 + m * 60 + s,
        _ => return None,
    };
    (seconds > 0).then_some(seconds)
}
