//! A plain binary format for the large arrays of a checkpoint (replay store, delay rings):
//! each section is a little-endian u64 element count followed by the elements' bytes.
use std::io::{Read, Write};

use bytemuck::Pod;

#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error(
        "saved {what} holds {found} values, this run expects {expected}: the checkpoint is from a different configuration"
    )]
    Mismatch {
        what: &'static str,
        found: usize,
        expected: usize,
    },
}

/// Writes one section.
pub fn write_section<T: Pod>(out: &mut impl Write, values: &[T]) -> Result<(), SnapshotError> {
    out.write_all(&(values.len() as u64).to_le_bytes())?;
    out.write_all(bytemuck::cast_slice(values))?;
    Ok(())
}

/// Reads one section into `into`, which must already have the expected length.
pub fn read_section<T: Pod>(
    input: &mut impl Read,
    what: &'static str,
    into: &mut [T],
) -> Result<(), SnapshotError> {
    let mut len = [0u8; 8];
    input.read_exact(&mut len)?;
    let found = u64::from_le_bytes(len) as usize;
    if found != into.len() {
        return Err(SnapshotError::Mismatch {
            what,
            found,
            expected: into.len(),
        });
    }
    input.read_exact(bytemuck::cast_slice_mut(into))?;
    Ok(())
}
