//! What an input was when a packed file was made from it: each file's
//! path, size, modification time and a content fingerprint. `prep-batch`
//! records it in the header of every output ([`crate::format::Header`]
//! `input`) and, on a re-run, redoes an output whose input no longer
//! matches (docs/RELIABILITY.md, "Batch identity").
//!
//! The fingerprint is the CRC-32 of the file's size and of three 1 MiB
//! windows: the first (which holds every format's header), the middle and
//! the last; a file of at most 3 MiB is hashed whole. A full hash would
//! read every input in full on every re-run, so resuming a batch of a
//! terabyte would cost as much as reading it; the windows cost at most
//! 3 MiB per file. An edit that keeps the size and the modification time
//! and touches only bytes outside the windows is not seen; touch the input
//! (or remove the output) to force a redo.

use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::time::UNIX_EPOCH;

use serde::{Deserialize, Serialize};

/// Bytes of each fingerprint window.
pub const WINDOW: u64 = 1 << 20;

/// One file an input reads.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileStamp {
    /// Absolute path (symlinks resolved).
    pub path: PathBuf,
    pub size: u64,
    /// Modification time: seconds and nanoseconds since the Unix epoch
    /// (negative seconds before it).
    pub mtime_s: i64,
    pub mtime_ns: u32,
    /// `crc32:XXXXXXXX` of the size and the three windows (module doc).
    pub fingerprint: String,
}

/// Every file an input reads, in the order the input names them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputStamp {
    pub files: Vec<FileStamp>,
}

impl InputStamp {
    /// Stamps `files` (the input's [`crate::input::SliceSource::files`]).
    pub fn of(files: &[PathBuf]) -> std::io::Result<InputStamp> {
        Ok(InputStamp {
            files: files
                .iter()
                .map(|p| FileStamp::of(p))
                .collect::<std::io::Result<_>>()?,
        })
    }

    /// Why `self` (recorded) is not `now`, in a few words
    /// (`size 100 -> 120`), or None when they match.
    pub fn differs(&self, now: &InputStamp) -> Option<String> {
        if self.files.len() != now.files.len() {
            return Some(format!("files {} -> {}", self.files.len(), now.files.len()));
        }
        for (a, b) in self.files.iter().zip(&now.files) {
            let name = b.path.display();
            if a.path != b.path {
                return Some(format!("path {} -> {name}", a.path.display()));
            }
            if a.size != b.size {
                return Some(format!("size of {name} {} -> {}", a.size, b.size));
            }
            if a.fingerprint != b.fingerprint {
                return Some(format!(
                    "content of {name}, {} -> {}",
                    a.fingerprint, b.fingerprint
                ));
            }
            if (a.mtime_s, a.mtime_ns) != (b.mtime_s, b.mtime_ns) {
                return Some(format!(
                    "mtime of {name} {}.{:09} -> {}.{:09}",
                    a.mtime_s, a.mtime_ns, b.mtime_s, b.mtime_ns
                ));
            }
        }
        None
    }
}

impl FileStamp {
    pub fn of(path: &Path) -> std::io::Result<FileStamp> {
        let mut f = crate::fsutil::open_regular(path)?;
        let m = f.metadata()?;
        let size = m.len();
        let (mtime_s, mtime_ns) = match m.modified()?.duration_since(UNIX_EPOCH) {
            Ok(d) => (d.as_secs() as i64, d.subsec_nanos()),
            Err(e) => {
                let d = e.duration();
                if d.subsec_nanos() == 0 {
                    (-(d.as_secs() as i64), 0)
                } else {
                    (-(d.as_secs() as i64) - 1, 1_000_000_000 - d.subsec_nanos())
                }
            }
        };
        let mut h = crc32fast::Hasher::new();
        h.update(&size.to_le_bytes());
        let mut buf = Vec::new();
        let starts: Vec<u64> = if size <= 3 * WINDOW {
            vec![0]
        } else {
            vec![0, size / 2 - WINDOW / 2, size - WINDOW]
        };
        let len = if size <= 3 * WINDOW { size } else { WINDOW };
        for s in starts {
            f.seek(SeekFrom::Start(s))?;
            buf.clear();
            (&mut f).take(len).read_to_end(&mut buf)?;
            h.update(&buf);
        }
        Ok(FileStamp {
            path: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
            size,
            mtime_s,
            mtime_ns,
            fingerprint: format!("crc32:{:08x}", h.finalize()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_see_the_head_middle_and_tail_of_a_big_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("big");
        let n = 5 * WINDOW as usize;
        let mut b = vec![7u8; n];
        std::fs::write(&p, &b).unwrap();
        let a = FileStamp::of(&p).unwrap();
        for at in [0, n / 2, n - 1] {
            b[at] ^= 1;
            std::fs::write(&p, &b).unwrap();
            assert_ne!(
                FileStamp::of(&p).unwrap().fingerprint,
                a.fingerprint,
                "{at}"
            );
            b[at] ^= 1;
        }
        std::fs::write(&p, &b).unwrap();
        assert_eq!(FileStamp::of(&p).unwrap().fingerprint, a.fingerprint);
    }
}
