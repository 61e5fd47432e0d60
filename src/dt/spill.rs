//! Where the forward pass keeps its slices until the backward pass reads
//! them in reverse.

use std::io;

/// Where the forward pass keeps its slices until the backward pass reads
/// them in reverse. Prep uses a temporary file; tests use memory.
pub trait Spill {
    fn put(&mut self, index: usize, data: &[u8]) -> io::Result<()>;
    fn get(&mut self, index: usize, out: &mut [u8]) -> io::Result<()>;
}

/// In-memory spill (tests and small volumes).
#[derive(Default)]
pub struct MemSpill(pub Vec<Vec<u8>>);

impl Spill for MemSpill {
    fn put(&mut self, index: usize, data: &[u8]) -> io::Result<()> {
        if self.0.len() <= index {
            self.0.resize(index + 1, Vec::new());
        }
        self.0[index] = data.to_vec();
        Ok(())
    }
    fn get(&mut self, index: usize, out: &mut [u8]) -> io::Result<()> {
        out.copy_from_slice(&self.0[index]);
        Ok(())
    }
}

/// A spill into a file of fixed-size records: an anonymous temporary
/// file ([`FileSpill::new_in`]), or a named one that outlives the process
/// ([`FileSpill::at`]: a shard's spill, kept between the passes of a
/// sharded prep).
pub struct FileSpill {
    file: std::fs::File,
    record: u64,
    /// The index of the file's first record.
    base: usize,
}

impl FileSpill {
    /// A temporary file in `dir` (deleted when dropped).
    pub fn new_in(dir: &std::path::Path, record: usize) -> io::Result<FileSpill> {
        Ok(FileSpill {
            file: tempfile::tempfile_in(dir)?,
            record: record as u64,
            base: 0,
        })
    }

    /// The records of `file` from index `base` on.
    pub fn at(file: std::fs::File, record: usize, base: usize) -> FileSpill {
        FileSpill {
            file,
            record: record as u64,
            base,
        }
    }

    fn offset(&self, index: usize) -> io::Result<u64> {
        let i = index.checked_sub(self.base).ok_or_else(|| {
            io::Error::other(format!(
                "spill record {index} is below the file's first, {}",
                self.base
            ))
        })?;
        Ok(i as u64 * self.record)
    }
}

impl Spill for FileSpill {
    fn put(&mut self, index: usize, data: &[u8]) -> io::Result<()> {
        use std::os::unix::fs::FileExt;
        self.file.write_all_at(data, self.offset(index)?)
    }
    fn get(&mut self, index: usize, out: &mut [u8]) -> io::Result<()> {
        use std::os::unix::fs::FileExt;
        self.file.read_exact_at(out, self.offset(index)?)
    }
}
