//! `evals.csv` and `train.csv`: appended a line at a time (flushed), and cut back to the
//! checkpoint's step, atomically, when a run resumes.
use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};

use super::{TrainError, io_error};

pub struct CsvLog {
    path: PathBuf,
    file: File,
}

impl CsvLog {
    /// Opens `path` for appending, writing `header` if the file is new.
    pub fn open(path: PathBuf, header: &[&str]) -> Result<CsvLog, TrainError> {
        let fresh = !path.exists();
        let mut file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(io_error(&path))?;
        if fresh {
            writeln!(file, "{}", header.join(",")).map_err(io_error(&path))?;
        }
        Ok(CsvLog { path, file })
    }

    pub fn append(&mut self, values: &[String]) -> Result<(), TrainError> {
        writeln!(self.file, "{}", values.join(",")).map_err(io_error(&self.path))?;
        self.file.flush().map_err(io_error(&self.path))
    }
}

/// Keeps the header and the rows whose first column (the step) is at most `step`, replacing
/// the file atomically.
pub fn truncate_after(path: &Path, step: u64) -> Result<(), TrainError> {
    if !path.exists() {
        return Ok(());
    }
    let reader = BufReader::new(File::open(path).map_err(io_error(path))?);
    let mut kept = Vec::new();
    for (i, line) in reader.lines().enumerate() {
        let line = line.map_err(io_error(path))?;
        let row_step = line.split(',').next().and_then(|s| s.parse::<u64>().ok());
        if i == 0 || row_step.is_some_and(|s| s <= step) {
            kept.push(line);
        }
    }
    let text: String = kept.iter().map(|line| format!("{line}\n")).collect();
    crate::files::write_atomically(path, text).map_err(io_error(path))
}

/// `train.csv`'s statistic cells: each statistic's mean over the updates that reported it,
/// empty where none did (so a statistic an update skipped never shifts into another column).
pub fn stat_means(sums: &[f64], counts: &[u64]) -> Vec<String> {
    sums.iter()
        .zip(counts)
        .map(|(sum, &count)| {
            if count == 0 {
                String::new()
            } else {
                format!("{:.6}", sum / count as f64)
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_statistic_no_update_reported_is_an_empty_cell() {
        assert_eq!(
            super::stat_means(&[3.0, 0.0, 1.0], &[2, 0, 4]),
            ["1.500000", "", "0.250000"]
        );
    }
}
