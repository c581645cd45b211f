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

/// Column `name` of a CSV file.
pub fn column(path: &Path, name: &str) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let k = header
        .iter()
        .position(|h| *h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"));
    lines
        .map(|l| l.split(',').nth(k).unwrap().to_string())
        .collect()
}

/// The best evaluation `return_mean` of a run, and its `evals.csv` for messages.
pub fn best_return(run: &Path) -> (f64, String) {
    let evals = run.join("evals.csv");
    let best = column(&evals, "return_mean")
        .iter()
        .map(|v| v.parse::<f64>().unwrap())
        .fold(f64::MIN, f64::max);
    (best, std::fs::read_to_string(evals).unwrap())
}
