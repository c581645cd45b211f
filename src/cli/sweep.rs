//! `dhrl sweep`: plan an experiment into a sweep folder, then run it here, print one command
//! per run for another scheduler, or look at where it stands.
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use clap::{Args, Subcommand};
use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};

use dhrl::protocol::Protocol;
use dhrl::sweep::{
    EXIT_BUSY, EXIT_INTERRUPTED, Experiment, PRESETS, RunOneResult, RunOutcome, RunState,
    SlurmOptions, Sweep, estimate_cost, run_group, run_local, shell_quote, stack_groups,
    steps_done, write_array_scripts, write_atomically,
};
use dhrl::tasks::TaskName;

#[derive(Subcommand)]
pub enum SweepCommand {
    /// Expand an experiment (a preset or a TOML file) into DIR/manifest.jsonl, one line per
    /// run, and print what it will cost on this machine.
    Plan(PlanArgs),
    /// Run every unfinished run of a sweep on this machine, N at a time; kill it and start it
    /// again at any moment.
    Run(RunArgs),
    /// Run (or resume) one run of a sweep, by its manifest index: what every engine calls.
    RunOne(RunOneArgs),
    /// Write a Slurm job-array script (one array task per unfinished run, requeued when
    /// preempted or near its time limit) into DIR/slurm/, and submit it with --submit.
    Slurm(SlurmArgs),
    /// One shell command per unfinished run, for GNU parallel, `xargs -P` or `ray job submit`.
    Commands(DirArgs),
    /// Where each run of a sweep stands.
    Status(DirArgs),
}

#[derive(Args)]
pub struct PlanArgs {
    /// A preset (table1, noise, random-delay, ablation, runtime) or an experiment TOML file.
    experiment: String,
    /// The sweep folder (created, or extended when it holds an earlier plan).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Multiply every run's steps (and checkpoint interval) by this, for a quick look.
    #[arg(long, default_value_t = 1.0)]
    scale: f64,
    /// Environment steps of every run (after --scale).
    #[arg(long)]
    steps: Option<u64>,
    /// Environment steps between evaluations of every run (the presets: 5,000), for
    /// learning curves of a shortened sweep.
    #[arg(long, value_name = "STEPS")]
    eval_every: Option<u64>,
    /// Run the experiment under this protocol instead of its own (the presets: authors; dhrl
    /// for dhrl's own settings: `dhrl train --protocol`).
    #[arg(long, value_enum)]
    protocol: Option<Protocol>,
    /// These tasks instead of the experiment's (comma-separated).
    #[arg(long, value_enum, value_delimiter = ',')]
    tasks: Vec<TaskName>,
    /// These algorithms instead of the experiment's (comma-separated).
    #[arg(long, value_delimiter = ',')]
    algos: Vec<String>,
    /// These delays instead of the experiment's (comma-separated).
    #[arg(long, value_delimiter = ',')]
    delays: Vec<usize>,
    /// These seeds instead of the experiment's (comma-separated).
    #[arg(long, value_delimiter = ',')]
    seeds: Vec<u64>,
    /// Gradient updates timed per (algorithm, task, Δ) for the cost estimate; 0 skips it.
    #[arg(long, default_value_t = 5)]
    cost_updates: usize,
}

#[derive(Args)]
pub struct RunArgs {
    dir: PathBuf,
    /// Runs at a time, each on one core (D2HPG's two learners may use two).
    #[arg(long, default_value_t = 1)]
    jobs: usize,
    /// Run failed runs again (by default they stay failed, with their error in status/).
    #[arg(long)]
    retry_failed: bool,
    /// Train up to S runs of one cell (seeds apart) as one stack per process (`dhrl train
    /// --seeds`); each run keeps its own folder, status and resume.
    #[arg(long, value_name = "S", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    stack: u64,
}

#[derive(Args)]
pub struct RunOneArgs {
    dir: PathBuf,
    /// The run's line in the manifest, from 0; $SLURM_ARRAY_TASK_ID when not given.
    #[arg(long, conflicts_with = "group")]
    index: Option<usize>,
    /// Runs the stack group G (of `dhrl sweep status`'s groups of --stack S) instead of one
    /// run; $SLURM_ARRAY_TASK_ID when not given.
    #[arg(long, value_name = "S", value_parser = clap::value_parser!(u64).range(1..))]
    stack: Option<u64>,
    /// The stack group, from 0 (with --stack).
    #[arg(long, value_name = "G", requires = "stack")]
    group: Option<usize>,
}

#[derive(Args)]
pub struct SlurmArgs {
    dir: PathBuf,
    /// The partition the tasks run in (the cluster's default when not given).
    #[arg(long)]
    partition: Option<String>,
    /// The account the tasks are charged to.
    #[arg(long)]
    account: Option<String>,
    /// Each task's time limit (MM, HH:MM:SS, D-HH:MM, …); a run cut by it resumes when its
    /// task is requeued.
    #[arg(long)]
    time: Option<String>,
    /// Memory per task (`--mem`: 4G, 4000M).
    #[arg(long)]
    mem: Option<String>,
    /// Array tasks running at once.
    #[arg(long, value_name = "K")]
    max_parallel: Option<usize>,
    /// Cores per task (default: the most learner threads among the sweep's algorithms).
    #[arg(long)]
    cpus_per_task: Option<usize>,
    /// Seconds before the time limit at which a run checkpoints and its task requeues.
    #[arg(long, default_value_t = 300)]
    signal_lead: u64,
    /// The cluster's MaxArraySize (`scontrol show config`): larger sweeps get several scripts.
    #[arg(long, default_value_t = 1001)]
    max_array_size: usize,
    /// One more sbatch option for the script, e.g. --sbatch=--qos=long (repeatable).
    #[arg(long = "sbatch", value_name = "OPTION", allow_hyphen_values = true)]
    extra: Vec<String>,
    /// Submit the scripts with `sbatch` (otherwise they are only written).
    #[arg(long)]
    submit: bool,
    /// Runs per task: up to S runs of one cell (seeds apart) trained as one stack.
    #[arg(long, value_name = "S", default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..))]
    stack: u64,
}

#[derive(Args)]
pub struct DirArgs {
    dir: PathBuf,
}

pub fn run(command: &SweepCommand) -> anyhow::Result<()> {
    match command {
        SweepCommand::Plan(args) => plan(args),
        SweepCommand::Run(args) => run_here(args),
        SweepCommand::RunOne(args) => run_single(args),
        SweepCommand::Slurm(args) => slurm(args),
        SweepCommand::Commands(args) => commands(&args.dir),
        SweepCommand::Status(args) => status(&args.dir),
    }
}

fn load_experiment(source: &str) -> anyhow::Result<Experiment> {
    if PRESETS.iter().any(|(name, _)| *name == source) {
        return Ok(Experiment::preset(source)?);
    }
    let path = Path::new(source);
    if !path.is_file() {
        anyhow::bail!(
            "'{source}' is neither a preset ({}) nor an experiment file",
            PRESETS
                .iter()
                .map(|(p, _)| *p)
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {source}"))?;
    Ok(Experiment::from_toml(&text, source)?)
}

fn plan(args: &PlanArgs) -> anyhow::Result<()> {
    let mut experiment = load_experiment(&args.experiment)?;
    experiment.restrict(&args.tasks, &args.algos, &args.delays, &args.seeds);
    experiment.scale(args.scale)?;
    if let Some(steps) = args.steps {
        experiment.steps = steps;
    }
    if let Some(protocol) = args.protocol {
        experiment.train.insert(
            "protocol".into(),
            toml::Value::String(protocol.name().into()),
        );
    }
    if let Some(every) = args.eval_every {
        experiment.train.insert(
            "eval_every".into(),
            toml::Value::Integer(i64::try_from(every).unwrap_or(i64::MAX)),
        );
    }
    let planned = experiment.expand()?;
    let (sweep, change) = Sweep::plan(&args.out, &planned)?;
    // The experiment as last planned (earlier plans' runs stay in the manifest).
    write_atomically(
        &args.out.join("experiment.toml"),
        &toml::to_string(&experiment).context("writing the experiment")?,
    )?;
    if !experiment.description.is_empty() {
        println!("{}", experiment.description);
    }
    println!(
        "{}: {} runs planned ({} new, {} planned before; {} earlier runs not in this plan, kept)",
        args.out.display(),
        planned.len(),
        change.added,
        change.kept,
        change.not_in_plan
    );
    if change.like_earlier > 0 {
        eprintln!(
            "warning: {} new runs share task, algorithm, delay and seed with earlier runs of this \
             sweep but differ in configuration (a changed setting, or a dhrl that resolves more \
             fields): they run beside the earlier ones",
            change.like_earlier
        );
    }
    let runs: Vec<_> = planned
        .iter()
        .filter_map(|p| sweep.runs.iter().find(|r| r.id == p.id))
        .collect();
    let steps: u64 = runs.iter().map(|r| r.config.steps).sum();
    println!("{} runs × steps = {steps} environment steps", runs.len());
    if args.cost_updates > 0 {
        println!(
            "cost at this machine's measured update rates ({} updates timed per algorithm, task and Δ):",
            args.cost_updates
        );
        let rows = estimate_cost(&runs, args.cost_updates)?;
        println!(
            "{:<14} {:<18} {:>3} {:>5} {:>10} {:>8} {:>11}",
            "algorithm", "task", "Δ", "runs", "ms/update", "threads", "core-hours"
        );
        for row in &rows {
            println!(
                "{:<14} {:<18} {:>3} {:>5} {:>10.2} {:>8} {:>11.1}",
                row.algo,
                row.task.to_string(),
                row.delay,
                row.runs,
                row.ms_per_update,
                row.threads,
                row.core_hours
            );
        }
        println!(
            "total: {:.1} core-hours",
            rows.iter().map(|r| r.core_hours).sum::<f64>()
        );
    }
    println!(
        "next: dhrl sweep run {0} --jobs N | dhrl sweep slurm {0} --submit | dhrl sweep commands {0}",
        args.out.display()
    );
    Ok(())
}

fn run_here(args: &RunArgs) -> anyhow::Result<()> {
    let sweep = Sweep::open(&args.dir)?;
    let exe = std::env::current_exe().context("finding the dhrl executable")?;
    // The runner's own SIGTERM, SIGINT (Ctrl-C) or SIGHUP: its runs checkpoint and exit. Each
    // run has its own process group, so that it hears only the runner's one SIGTERM.
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [SIGTERM, SIGINT, SIGHUP] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .context("installing the runner's signal handlers")?;
    }
    let stack = args.stack as usize;
    let summary = run_local(
        &sweep,
        args.jobs,
        stack,
        args.retry_failed,
        std::io::IsTerminal::is_terminal(&std::io::stderr()),
        &stop,
        |unit, log| {
            let err = log.try_clone()?;
            let which = match stack {
                1 => vec!["--index".to_string(), unit.to_string()],
                _ => vec![
                    "--stack".into(),
                    stack.to_string(),
                    "--group".into(),
                    unit.to_string(),
                ],
            };
            Command::new(&exe)
                .args(["sweep", "run-one"])
                .arg(&args.dir)
                .args(which)
                .env_remove("SLURM_ARRAY_TASK_ID")
                .stdin(Stdio::null())
                .stdout(log)
                .stderr(err)
                .process_group(0)
                .spawn()
        },
    )?;
    println!(
        "{}: {} finished, {} failed, {} interrupted, {} running elsewhere (of {})",
        args.dir.display(),
        summary.finished,
        summary.failed,
        summary.interrupted,
        summary.busy,
        sweep.runs.len()
    );
    if summary.failed > 0 {
        println!(
            "the failed runs' errors: dhrl sweep status {} (--retry-failed runs them again)",
            args.dir.display()
        );
    }
    if stop.load(Ordering::Relaxed) {
        std::process::exit(EXIT_INTERRUPTED);
    }
    Ok(())
}

fn run_single(args: &RunOneArgs) -> anyhow::Result<()> {
    let index = match args.index.or(args.group) {
        Some(index) => index,
        None => std::env::var("SLURM_ARRAY_TASK_ID")
            .ok()
            .and_then(|v| v.parse().ok())
            .context(
                "--index (or --group) is needed, or SLURM_ARRAY_TASK_ID inside a Slurm array job",
            )?,
    };
    let sweep = Sweep::open(&args.dir)?;
    dhrl::train::stop_on_signals()?;
    let group = match args.stack {
        None => vec![sweep.run(index)?.index],
        Some(stack) => {
            let groups = stack_groups(&sweep, stack as usize);
            groups.get(index).cloned().with_context(|| {
                format!(
                    "no stack group {index}: with --stack {stack} the sweep has groups 0..={}",
                    groups.len().saturating_sub(1)
                )
            })?
        }
    };
    let (mut interrupted, mut busy, mut failed) = (false, false, Vec::new());
    for (index, result) in run_group(&sweep, &group, false)? {
        let id = &sweep.runs[index].id;
        match result {
            RunOneResult::AlreadyFinished => println!("{id}: finished before"),
            RunOneResult::Busy => {
                eprintln!("{id}: another process is running it");
                busy = true;
            }
            RunOneResult::Ended(RunOutcome::Finished {
                env_steps,
                wall_seconds,
                final_return,
            }) => println!(
                "{id}: finished, {env_steps} steps in {wall_seconds:.0} s, final return {}",
                final_return.map_or("-".into(), |r| format!("{r:.1}"))
            ),
            RunOneResult::Ended(RunOutcome::Interrupted { env_steps }) => {
                eprintln!(
                    "{id}: stopped at step {env_steps} with a checkpoint; start it again to resume"
                );
                interrupted = true;
            }
            RunOneResult::Ended(RunOutcome::Failed { error }) => {
                eprintln!("{id}: {error}");
                failed.push(id.clone());
            }
        }
    }
    if interrupted {
        std::process::exit(EXIT_INTERRUPTED);
    }
    if busy {
        std::process::exit(EXIT_BUSY);
    }
    match failed.len() {
        0 => Ok(()),
        _ => anyhow::bail!("failed: {}", failed.join(", ")),
    }
}

fn slurm(args: &SlurmArgs) -> anyhow::Result<()> {
    let sweep = Sweep::open(&args.dir)?;
    let exe = std::env::current_exe().context("finding the dhrl executable")?;
    let options = SlurmOptions {
        partition: args.partition.clone(),
        account: args.account.clone(),
        time: args.time.clone(),
        mem: args.mem.clone(),
        max_parallel: args.max_parallel,
        cpus_per_task: args.cpus_per_task,
        signal_lead: args.signal_lead,
        max_array_size: args.max_array_size,
        extra: args.extra.clone(),
        stack: args.stack as usize,
    };
    let scripts = write_array_scripts(&sweep, &exe, &options)?;
    if scripts.is_empty() {
        println!(
            "{}: every run has finished; no script written",
            args.dir.display()
        );
        return Ok(());
    }
    for script in &scripts {
        println!(
            "{}: {} {} (manifest {} {}..={})",
            script.path.display(),
            script.runs.len(),
            if args.stack > 1 { "stacks" } else { "runs" },
            if args.stack > 1 {
                "stack groups"
            } else {
                "indices"
            },
            script.runs[0],
            script.runs[script.runs.len() - 1]
        );
    }
    if !args.submit {
        println!("submit with: sbatch SCRIPT (or run this again with --submit)");
        return Ok(());
    }
    let mut submitted = String::new();
    for script in &scripts {
        let out = Command::new("sbatch")
            .arg("--parsable")
            .arg(&script.path)
            .output()
            .with_context(|| {
                format!(
                    "running sbatch (is this a Slurm login node?); the script is {}",
                    script.path.display()
                )
            })?;
        anyhow::ensure!(
            out.status.success(),
            "sbatch {} failed: {}",
            script.path.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
        let stdout = String::from_utf8_lossy(&out.stdout);
        let job = stdout
            .trim()
            .split(';')
            .next()
            .unwrap_or_default()
            .to_string();
        println!("submitted {}: job {job}", script.path.display());
        submitted += &format!("{job} {}\n", script.path.display());
    }
    let record = sweep.dir.join("slurm").join("submitted.txt");
    let earlier = std::fs::read_to_string(&record).unwrap_or_default();
    write_atomically(&record, &(earlier + &submitted))?;
    println!(
        "follow with: squeue --me; dhrl sweep status {}",
        args.dir.display()
    );
    Ok(())
}

fn commands(dir: &Path) -> anyhow::Result<()> {
    let sweep = Sweep::open(dir)?;
    let exe = std::env::current_exe().context("finding the dhrl executable")?;
    let dir = dir
        .canonicalize()
        .with_context(|| format!("resolving {}", dir.display()))?;
    let mut out = String::new();
    for run in &sweep.runs {
        if !sweep.finished(run) {
            out += &format!(
                "{} sweep run-one {} --index {}\n",
                shell_quote(&exe.display().to_string()),
                shell_quote(&dir.display().to_string()),
                run.index
            );
        }
    }
    print_all(&out)
}

fn status(dir: &Path) -> anyhow::Result<()> {
    let sweep = Sweep::open(dir)?;
    let mut out = format!(
        "{:>5}  {:<56} {:<12} {:>17}  final return / error\n",
        "index", "id", "state", "steps"
    );
    for run in &sweep.runs {
        let state = sweep.state(run);
        let (name, detail) = match &state {
            RunState::Pending => ("pending", String::new()),
            RunState::Started => ("started", String::new()),
            RunState::Ended(RunOutcome::Finished { final_return, .. }) => (
                "finished",
                final_return.map_or(String::new(), |r| format!("{r:.1}")),
            ),
            RunState::Ended(RunOutcome::Interrupted { .. }) => ("interrupted", String::new()),
            RunState::Ended(RunOutcome::Failed { error }) => ("failed", error.clone()),
        };
        out += &format!(
            "{:>5}  {:<56} {:<12} {:>17}  {detail}\n",
            run.index,
            run.id,
            name,
            format!("{}/{}", steps_done(&sweep, run), run.config.steps)
        );
    }
    print_all(&out)
}

/// Writes `text` to stdout; a reader that stops early (`| head`) is not an error.
fn print_all(text: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        result => result.context("writing to stdout"),
    }
}
