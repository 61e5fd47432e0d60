//! Whole-file writes that never leave a half-written file behind: the
//! one place every stage that writes an output (prep, render, batch,
//! experiments, the CLI's JSON) goes through.

use std::path::{Path, PathBuf};

/// Why [`write_atomic`] could not write a file.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// No temporary file could be made in the target's directory.
    #[error("{}: cannot create a temporary file beside it: {source}", path.display())]
    Temp {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Writing the bytes to the temporary file failed.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Renaming the complete temporary file onto the target failed.
    #[error("{}: {source}", path.display())]
    Rename {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Writes `bytes` to `target` through a temporary file beside it, renamed
/// when complete.
pub fn write_atomic(target: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    let dir = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let path = || target.to_path_buf();
    let tmp = tempfile::Builder::new()
        .prefix(".cdvol-partial-")
        .tempfile_in(&dir)
        .map_err(|source| WriteError::Temp {
            path: path(),
            source,
        })?;
    std::fs::write(tmp.path(), bytes).map_err(|source| WriteError::Write {
        path: path(),
        source,
    })?;
    tmp.persist(target).map_err(|e| WriteError::Rename {
        path: path(),
        source: e.error,
    })?;
    Ok(())
}
