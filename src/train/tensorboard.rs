//! TensorBoard event files beside the CSVs (`RUN/tensorboard/`): every `train.csv` statistic
//! under `train/<column>` and every evaluation under `eval/<column>`, at the environment step.
//! Each process writes a file of its own. A resumed run first cuts every earlier file back to
//! its checkpoint's step, as it cuts the CSVs (each file rewritten whole, atomically), then
//! opens its own with a `SessionLog` START at the step after the checkpoint, TensorBoard's own
//! sign of a restart.
//!
//! The format is TFRecord framing (length, masked CRC-32C, record, masked CRC-32C) around
//! `Event` messages of TensorFlow's `event.proto`, written field by field with the protobuf
//! crate's coded streams: `Event` {1: wall_time (double), 2: step (int64), 3: file_version
//! (string) | 5: summary | 7: session_log}; `Summary` {1: repeated value}; `Summary.Value`
//! {1: tag, 2: simple_value (float)}; `SessionLog` {1: status, START = 1}.
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use protobuf::{CodedInputStream, CodedOutputStream};

use super::{TrainError, io_error};

/// The folder inside a run.
pub const FOLDER: &str = "tensorboard";

/// What an event carries.
enum What<'a> {
    FileVersion(&'a str),
    /// Scalars, `(tag, value)`.
    Summary(Vec<(&'a str, f32)>),
    /// `SessionLog` START: a restart at this event's step.
    SessionStart,
}

/// One `Event` message's bytes.
fn event_bytes(wall_time: f64, step: i64, what: &What<'_>) -> protobuf::Result<Vec<u8>> {
    /// A message's bytes, written by `fill`.
    fn message(
        fill: impl FnOnce(&mut CodedOutputStream<'_>) -> protobuf::Result<()>,
    ) -> protobuf::Result<Vec<u8>> {
        let mut bytes = Vec::new();
        let mut out = CodedOutputStream::vec(&mut bytes);
        fill(&mut out)?;
        out.flush()?;
        drop(out);
        Ok(bytes)
    }
    message(|out| {
        out.write_double(1, wall_time)?;
        out.write_int64(2, step)?;
        match what {
            What::FileVersion(version) => out.write_string(3, version),
            What::Summary(values) => {
                let summary = message(|summary| {
                    for (tag, value) in values {
                        let value = message(|v| {
                            v.write_string(1, tag)?;
                            v.write_float(2, *value)
                        })?;
                        summary.write_bytes(1, &value)?;
                    }
                    Ok(())
                })?;
                out.write_bytes(5, &summary)
            }
            What::SessionStart => out.write_bytes(7, &message(|log| log.write_int32(1, 1))?),
        }
    })
}

/// The `step` of an `Event` message.
fn event_step(bytes: &[u8]) -> protobuf::Result<Option<i64>> {
    let mut input = CodedInputStream::from_bytes(bytes);
    while let Some(tag) = input.read_raw_tag_or_eof()? {
        if tag >> 3 == 2 {
            return Ok(Some(input.read_int64()?));
        }
        protobuf::rt::skip_field_for_tag(tag, &mut input)?;
    }
    Ok(None)
}

/// One process's event file.
pub struct EventLog {
    path: PathBuf,
    file: File,
}

impl EventLog {
    /// A new event file in `RUN/tensorboard/`; `resumed_after` is the checkpoint's step when
    /// the run continues from one.
    pub fn create(run: &Path, resumed_after: Option<u64>) -> Result<EventLog, TrainError> {
        let folder = run.join(FOLDER);
        std::fs::create_dir_all(&folder).map_err(io_error(&folder))?;
        let seconds = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        // Distinct per process and per file of a process (a run resumed in the same process).
        static FILES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let file_number = FILES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = folder.join(format!(
            "events.out.tfevents.{seconds:010}.dhrl.{}.{file_number}",
            std::process::id()
        ));
        let file = File::create(&path).map_err(io_error(&path))?;
        let mut log = EventLog { path, file };
        log.write(0, &What::FileVersion("brain.Event:2"))?;
        if let Some(step) = resumed_after {
            log.write(step + 1, &What::SessionStart)?;
        }
        Ok(log)
    }

    /// `values` (tag, value) at `step`; non-finite values are left out, as the CSVs leave
    /// their cells empty.
    pub fn scalars(&mut self, step: u64, values: &[(String, f64)]) -> Result<(), TrainError> {
        let values = values
            .iter()
            .filter(|(_, v)| v.is_finite())
            .map(|(tag, v)| (tag.as_str(), *v as f32))
            .collect();
        self.write(step, &What::Summary(values))
    }

    fn write(&mut self, step: u64, what: &What<'_>) -> Result<(), TrainError> {
        let wall_time = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        let record = event_bytes(wall_time, step as i64, what).map_err(|e| TrainError::Io {
            path: self.path.display().to_string(),
            message: e.to_string(),
        })?;
        let length = (record.len() as u64).to_le_bytes();
        let mut framed = Vec::with_capacity(record.len() + 16);
        framed.extend_from_slice(&length);
        framed.extend_from_slice(&masked_crc(&length).to_le_bytes());
        framed.extend_from_slice(&record);
        framed.extend_from_slice(&masked_crc(&record).to_le_bytes());
        self.file.write_all(&framed).map_err(io_error(&self.path))?;
        self.file.flush().map_err(io_error(&self.path))
    }
}

/// Cuts every event file of `run` back to the records of steps up to `step` (a record the
/// interrupted process left half-written goes too).
pub fn truncate_after(run: &Path, step: u64) -> Result<(), TrainError> {
    let folder = run.join(FOLDER);
    let Ok(entries) = std::fs::read_dir(&folder) else {
        return Ok(());
    };
    for entry in entries {
        let path = entry.map_err(io_error(&folder))?.path();
        let bytes = std::fs::read(&path).map_err(io_error(&path))?;
        let mut kept = Vec::with_capacity(bytes.len());
        let mut rest = &bytes[..];
        while rest.len() >= 12 {
            let length = u64::from_le_bytes(rest[..8].try_into().expect("8 bytes")) as usize;
            let Some(framed) = rest.get(..length.saturating_add(16)) else {
                break;
            };
            let Ok(Some(event_step)) = event_step(&framed[12..12 + length]) else {
                break;
            };
            if event_step <= step as i64 {
                kept.extend_from_slice(framed);
            }
            rest = &rest[framed.len()..];
        }
        if kept.len() != bytes.len() {
            crate::files::write_atomically(&path, &kept).map_err(io_error(&path))?;
        }
    }
    Ok(())
}

/// TFRecord's masked CRC-32C.
fn masked_crc(bytes: &[u8]) -> u32 {
    let crc = crc32c::crc32c(bytes);
    (crc.rotate_right(15)).wrapping_add(0xa282_ead8)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The steps of a file's records, checking each record's framing and checksums.
    fn steps(path: &Path) -> Vec<i64> {
        let bytes = std::fs::read(path).unwrap();
        let mut rest = &bytes[..];
        let mut out = Vec::new();
        while !rest.is_empty() {
            let length = u64::from_le_bytes(rest[..8].try_into().unwrap()) as usize;
            let crc = |at: usize| u32::from_le_bytes(rest[at..at + 4].try_into().unwrap());
            assert_eq!(crc(8), masked_crc(&rest[..8]));
            let record = &rest[12..12 + length];
            assert_eq!(crc(12 + length), masked_crc(record));
            out.push(event_step(record).unwrap().unwrap());
            rest = &rest[16 + length..];
        }
        out
    }

    #[test]
    fn masked_crc_is_tfrecords() {
        // TFRecord's mask of CRC-32C over "123456789" (CRC 0xE3069283).
        assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
        assert_eq!(
            masked_crc(b"123456789"),
            0xE306_9283u32.rotate_right(15).wrapping_add(0xa282_ead8)
        );
    }

    #[test]
    fn a_resume_cuts_the_files_back_to_the_checkpoint_and_drops_a_torn_record() {
        let run = tempfile::tempdir().unwrap();
        let mut log = EventLog::create(run.path(), None).unwrap();
        for step in [100, 200, 300] {
            log.scalars(
                step,
                &[
                    ("train/x".into(), step as f64),
                    ("train/empty".into(), f64::NAN),
                ],
            )
            .unwrap();
        }
        let path = log.path.clone();
        drop(log);
        // A record torn by a kill: its length and part of its bytes.
        let mut torn = std::fs::read(&path).unwrap();
        torn.extend_from_slice(&40u64.to_le_bytes());
        torn.extend_from_slice(&[0; 10]);
        std::fs::write(&path, &torn).unwrap();
        truncate_after(run.path(), 200).unwrap();
        assert_eq!(
            steps(&path),
            [0, 100, 200],
            "the file version, then steps up to 200"
        );
        let resumed = EventLog::create(run.path(), Some(200)).unwrap();
        assert_ne!(resumed.path, path, "a file of its own");
        assert_eq!(
            steps(&resumed.path),
            [0, 201],
            "a restart marked after the checkpoint"
        );
        assert_eq!(steps(&path), [0, 100, 200]);
    }
}
