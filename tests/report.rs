//! `dhrl report`: rliable's statistics against hand values, the shipped Table 1, and a report
//! of run folders with known final returns (their configurations planned by a real
//! experiment), checked cell by cell.
// Needs the `dhrl` program (here or in tests/common) or `dhrl::report`: the default `cli` feature.
#![cfg(feature = "cli")]
use std::path::Path;
use std::process::Command;

use dhrl::report::{iqm, mean_std, paper_table1, probability_of_improvement};
use dhrl::sweep::Experiment;

#[test]
fn iqm_and_probability_of_improvement_match_hand_values() {
    // 8 scores: a quarter (2) cut from each end, the mean of 3, 4, 5, 6.
    assert_eq!(iqm(&[8.0, 1.0, 7.0, 2.0, 6.0, 3.0, 5.0, 4.0]), 4.5);
    // 5 scores: one cut from each end (⌊5/4⌋), as scipy's trim_mean(·, 0.25).
    assert_eq!(iqm(&[100.0, 1.0, 2.0, 3.0, -50.0]), 2.0);
    // Task 1: x {1, 3} against y {2}: 3 > 2 wins, 1 < 2 loses → 0.5.
    // Task 2: x {5} against y {5, 4}: a tie (0.5) and a win (1) → 0.75. Mean 0.625.
    let p = probability_of_improvement(
        &vec![vec![1.0, 3.0], vec![5.0]],
        &vec![vec![2.0], vec![5.0, 4.0]],
    );
    assert!((p - 0.625).abs() < 1e-12, "{p}");
    let (mean, std) = mean_std(&[1.0, 3.0]);
    assert_eq!((mean, std), (2.0, 1.0));
}

#[test]
fn the_shipped_table1_is_the_papers() {
    let table = paper_table1();
    // Delay-free SAC once, then 6 algorithms at 3 delays, on 6 tasks.
    assert_eq!(table.len(), (1 + 6 * 3) * 6);
    let cell = |delay: usize, algorithm: &str, task: &str| {
        table
            .iter()
            .find(|c| c.delay == delay && c.algorithm == algorithm && c.task.to_string() == task)
            .unwrap()
            .clone()
    };
    let d2hpg = cell(5, "d2hpg", "inverted-pendulum");
    assert_eq!((d2hpg.mean, d2hpg.std, d2hpg.best), (949.8, 6.0, true));
    assert_eq!(cell(0, "sac", "half-cheetah").mean, 8608.4);
    assert_eq!(cell(20, "vdpo", "inverted-pendulum").mean, 19.4);
    // One highlighted cell per task and delay.
    assert_eq!(table.iter().filter(|c| c.best).count(), 6 * 3);
}

/// The final return the fake run of `algorithm`/`seed` ends with.
fn final_return(task: &str, algorithm: &str, seed: u64) -> f64 {
    let base = if task == "hopper" { 2000.0 } else { 900.0 };
    let algo = match algorithm {
        "bpql" => 0.0,
        _ => 30.0,
    };
    base + algo + 10.0 * seed as f64
}

/// Writes a run folder: the planned configuration, and evaluations at 500 and 1,000 steps
/// (the second at `final_return`).
fn fake_run(dir: &Path, config: &dhrl::train::TrainConfig) {
    std::fs::create_dir_all(dir).unwrap();
    std::fs::write(dir.join("config.toml"), toml::to_string(config).unwrap()).unwrap();
    let last = final_return(&config.task.to_string(), config.algo.name(), config.seed)
        - 100.0 * config.delay.actuator_noise;
    std::fs::write(
        dir.join("evals.csv"),
        format!(
            "step,wall_seconds,return_mean,return_std,length_mean,episodes\n\
             500,10.0,{},1.0,100,5\n1000,36.0,{last},2.0,1000,5\n",
            last / 2.0
        ),
    )
    .unwrap();
}

#[test]
fn a_report_of_known_runs_has_their_numbers_and_every_file() {
    let experiment = r#"
tasks = ["inverted-pendulum", "hopper"]
algorithms = ["bpql", "d2hpg"]
delays = [5]
actuator_noise = [0.0, 0.05]
seeds = [0, 1, 2]
steps = 1000
"#;
    let planned = Experiment::from_toml(experiment, "known.toml")
        .unwrap()
        .expand()
        .unwrap();
    assert_eq!(planned.len(), 2 * 2 * 2 * 3);
    let dir = tempfile::tempdir().unwrap();
    for run in &planned {
        fake_run(&dir.path().join("runs").join(&run.id), &run.config);
    }
    // A run that has not evaluated yet is left out, and said so.
    let early = dir.path().join("runs").join("early");
    std::fs::create_dir_all(&early).unwrap();
    std::fs::write(
        early.join("config.toml"),
        toml::to_string(&planned[0].config).unwrap(),
    )
    .unwrap();
    let out = dir.path().join("report");
    let mut args = vec!["report".to_string()];
    for entry in std::fs::read_dir(dir.path().join("runs")).unwrap() {
        args.push(entry.unwrap().path().display().to_string());
    }
    args.extend([
        "--out".into(),
        out.display().to_string(),
        "--bootstrap".into(),
        "500".into(),
    ]);
    let run = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(&args)
        .output()
        .unwrap();
    let printed = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(
        run.status.success(),
        "{printed}{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(
        printed.contains("24 runs (1 more without an evaluation yet"),
        "{printed}"
    );

    // Table 1 cells: noise-free runs only; seeds 0, 1, 2 add 0, 10, 20 → mean +10, std √(200/3).
    let csv = std::fs::read_to_string(out.join("table1.csv")).unwrap();
    let std = (200.0f64 / 3.0).sqrt();
    for (algorithm, task, mean, best, paper) in [
        ("bpql", "hopper", 2010.0, false, "2136.3"),
        ("d2hpg", "hopper", 2040.0, true, "2509.8"),
        ("bpql", "inverted-pendulum", 910.0, false, "945.5"),
        ("d2hpg", "inverted-pendulum", 940.0, true, "949.8"),
    ] {
        // The default protocol, run by dhrl itself.
        let row = format!(
            "5,{algorithm},dhrl,dhrl,{task},3,{mean:.3},{std:.3},1000,{best},false,{paper},"
        );
        assert!(csv.contains(&row), "{row} not in\n{csv}");
    }
    let markdown = std::fs::read_to_string(out.join("table1.md")).unwrap();
    assert!(markdown.contains("**2040.0 ± 8.2 (3)**"), "{markdown}");
    assert!(
        markdown.contains(
            "| 5 | BPQL | dhrl | 2010.0 ± 8.2 (3) | 2136.3 ± 158 | 910.0 ± 8.2 (3) | 945.5 ± 20 |"
        ),
        "{markdown}"
    );
    let latex = std::fs::read_to_string(out.join("table1.tex")).unwrap();
    assert!(
        latex.contains("\\textbf{$2040.0_{\\pm 8.2}$ (3)}"),
        "{latex}"
    );

    // D2HPG's seed i ends 30 + 10i above the task's base, BPQL's seed j 10j: every one of the
    // 9 pairs per task is a win (30 + 10i > 10j for i, j in 0..3), so P = 1, in every resample.
    let aggregate = std::fs::read_to_string(out.join("aggregate.csv")).unwrap();
    assert!(
        aggregate.contains(
            "probability_of_improvement,5,fixed,0,d2hpg,dhrl,dhrl,bpql,dhrl,dhrl,,1.000000,1.000000,1.000000"
        ),
        "{aggregate}"
    );
    // Under actuator noise σ = 0.05 every run ends 5 lower: still a win in every pair, stated
    // as a condition of its own.
    assert!(
        aggregate.contains(
            "probability_of_improvement,5,fixed,0.05,d2hpg,dhrl,dhrl,bpql,dhrl,dhrl,,1.000000,1.000000,1.000000"
        ),
        "{aggregate}"
    );
    // IQM of BPQL at Δ 5: 6 normalised scores, the middle 4 (⌊6/4⌋ = 1 cut each end).
    let mut scores: Vec<f64> = [0.0, 10.0, 20.0]
        .iter()
        .flat_map(|s| [(900.0 + s) / 964.3, (2000.0 + s) / 2435.2])
        .collect();
    scores.sort_by(f64::total_cmp);
    let expected = scores[1..5].iter().sum::<f64>() / 4.0;
    assert!(
        aggregate.contains(&format!("iqm,5,fixed,0,bpql,dhrl,dhrl,,,,6,{expected:.6},")),
        "{expected:.6} in {aggregate}"
    );

    // Every evaluation of every run, long format.
    let returns = std::fs::read_to_string(out.join("returns.csv")).unwrap();
    assert_eq!(returns.lines().count(), 1 + 24 * 2);
    assert!(returns.starts_with(
        "algorithm,protocol,implementation,task,delay,delay_kind,actuator_noise,seed,step,return\n"
    ));

    // The figures: curves per task × condition, noise, runtime; each SVG with its PNG.
    for name in [
        "curves-hopper-d5",
        "curves-inverted-pendulum-d5",
        "curves-hopper-d5-noise0.05",
        "noise",
        "runtime",
    ] {
        let svg = std::fs::read_to_string(out.join(format!("{name}.svg"))).unwrap();
        assert!(
            svg.contains("<svg") && svg.contains("<polyline"),
            "{name}.svg"
        );
        let png = std::fs::read(out.join(format!("{name}.png"))).unwrap();
        assert!(
            png.starts_with(b"\x89PNG\r\n\x1a\n") && png.len() > 2000,
            "{name}.png"
        );
    }
    assert!(
        !out.join("ablation.svg").exists(),
        "no D2HPG-naive runs, no ablation figure"
    );
}

#[test]
fn reports_of_nothing_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .args(["report", dir.path().to_str().unwrap(), "--out"])
        .arg(dir.path().join("out"))
        .output()
        .unwrap();
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("neither a run folder") && stderr.contains("manifest.jsonl"),
        "{stderr}"
    );
}
