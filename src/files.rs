//! Writing files so that a reader never sees a part of one.
use std::path::Path;

/// Writes `contents` to `path` through a temporary file beside it, synced, and a rename: a
/// reader sees the old file or the new one, never a part.
pub fn write_atomically(path: &Path, contents: impl AsRef<[u8]>) -> std::io::Result<()> {
    let mut partial = path.as_os_str().to_owned();
    partial.push(".partial");
    let partial = std::path::PathBuf::from(partial);
    std::fs::write(&partial, contents)?;
    std::fs::File::open(&partial)?.sync_all()?;
    std::fs::rename(&partial, path)
}
