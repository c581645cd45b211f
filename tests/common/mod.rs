//! Helpers shared by the integration tests that train end to end.
#![allow(dead_code)] // each test file uses its own subset

use std::path::Path;
use std::process::Command;

/// Runs `dhrl train ARGS --out RUN`, failing the test with its stderr if it fails.
pub fn train(args: &[&str], run: &Path) {
    let out = Command::new(env!("CARGO_BIN_EXE_dhrl"))
        .arg("train")
        .args(args)
        .arg("--out")
        .arg(run)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The best evaluation `return_mean` of a run, and its `evals.csv` for messages.
pub fn best_return(run: &Path) -> (f64, String) {
    let text = std::fs::read_to_string(run.join("evals.csv")).unwrap();
    let best = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(2).unwrap().parse::<f64>().unwrap())
        .fold(f64::MIN, f64::max);
    (best, text)
}
