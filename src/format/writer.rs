//! Writes a packed file: payloads appended as they come, the trailer at
//! the end, into a temporary file beside the target that is renamed only
//! when complete. A failure or a crash leaves the target untouched
//! (fsutil: the file's mode follows the umask, and a crash's partial
//! file is cleaned by a later write).

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::{
    FormatError, Header, IndexEntry, END_MAGIC, FLAG_NO_OBJECT, FLAG_UNIFORM, FLAG_VALUE_MAX,
    MAGIC, PREAMBLE_LEN,
};

pub struct PackedWriter {
    target: PathBuf,
    tmp: BufWriter<tempfile::NamedTempFile>,
    pos: u64,
    index: Vec<IndexEntry>,
    version: u32,
}

impl PackedWriter {
    /// Starts a packed file of format `version` that will become `target`
    /// with `bricks` bricks. The caller lays the payloads out for that
    /// version ([`Header::byte_planes`]) and gives [`finish`](Self::finish)
    /// a header of the same version.
    pub fn create(target: &Path, bricks: u64, version: u32) -> Result<PackedWriter, FormatError> {
        let io = |what, source| FormatError::Io {
            path: target.to_path_buf(),
            what,
            source,
        };
        let tmp = crate::fsutil::temp_beside(target)
            .map_err(|e| io("cannot create a temporary file beside the output", e))?;
        let mut w = BufWriter::with_capacity(1 << 20, tmp);
        let mut pre = [0u8; PREAMBLE_LEN as usize];
        pre[..8].copy_from_slice(MAGIC);
        pre[8..12].copy_from_slice(&version.to_le_bytes());
        w.write_all(&pre).map_err(|e| io("cannot write", e))?;
        let n = usize::try_from(bricks).map_err(|_| FormatError::Header {
            path: target.to_path_buf(),
            msg: format!("{bricks} bricks do not fit in memory on this platform"),
        })?;
        Ok(PackedWriter {
            target: target.to_path_buf(),
            tmp: w,
            pos: PREAMBLE_LEN,
            index: vec![IndexEntry::default(); n],
            version,
        })
    }

    fn io(&self, what: &'static str) -> impl FnOnce(std::io::Error) -> FormatError + '_ {
        move |source| FormatError::Io {
            path: self.target.clone(),
            what,
            source,
        }
    }

    /// Appends the compressed payload of brick `id`. `no_object` is the
    /// smallest code of its cells when the brick holds no 1-cell (index
    /// flag bit 1, code in `uniform_code`); `value_max`, for a brick with
    /// 1-cells, its largest value (index flag bit 2, [`FLAG_VALUE_MAX`]).
    pub fn put_brick(
        &mut self,
        id: u64,
        compressed: &[u8],
        no_object: Option<u32>,
        value_max: Option<f64>,
    ) -> Result<(), FormatError> {
        let length = u32::try_from(compressed.len()).map_err(|_| FormatError::Brick {
            path: self.target.clone(),
            brick: id,
            coords: [0; 3],
            msg: format!(
                "compressed payload of {} bytes exceeds 4 GiB",
                compressed.len()
            ),
        })?;
        self.tmp
            .write_all(compressed)
            .map_err(self.io("cannot write brick"))?;
        self.index[id as usize] = IndexEntry {
            offset: self.pos,
            length,
            crc32: crc32fast::hash(compressed),
            flags: match (no_object, value_max) {
                (Some(_), _) => FLAG_NO_OBJECT,
                (None, Some(_)) => FLAG_VALUE_MAX,
                (None, None) => 0,
            },
            uniform_code: no_object.unwrap_or(0),
            value_max: match (no_object, value_max) {
                (None, Some(v)) => v.to_bits(),
                _ => 0,
            },
        };
        self.pos += compressed.len() as u64;
        Ok(())
    }

    /// Records brick `id` as uniform: no payload, every cell a 0-cell with
    /// `code`.
    pub fn put_uniform(&mut self, id: u64, code: u32) {
        self.index[id as usize] = IndexEntry {
            offset: self.pos,
            length: 0,
            crc32: 0,
            flags: FLAG_UNIFORM | FLAG_NO_OBJECT,
            uniform_code: code,
            value_max: 0,
        };
    }

    /// Bytes of payload written so far.
    pub fn payload_bytes(&self) -> u64 {
        self.pos - PREAMBLE_LEN
    }

    /// Writes the trailer and footer, syncs, and renames into place.
    pub fn finish(mut self, header: &Header) -> Result<(), FormatError> {
        if header.format_version != self.version {
            return Err(FormatError::Header {
                path: self.target.clone(),
                msg: format!(
                    "header says format version {}, the file was started as {}",
                    header.format_version, self.version
                ),
            });
        }
        let json = serde_json::to_vec(header).map_err(|e| FormatError::Header {
            path: self.target.clone(),
            msg: e.to_string(),
        })?;
        let mut index = Vec::with_capacity(self.index.len() * super::INDEX_ENTRY_LEN);
        for e in &self.index {
            index.extend_from_slice(&e.to_bytes());
        }
        let mut crc = crc32fast::Hasher::new();
        crc.update(&json);
        crc.update(&index);
        let mut footer = Vec::with_capacity(super::FOOTER_LEN as usize);
        footer.extend_from_slice(&self.pos.to_le_bytes());
        footer.extend_from_slice(&(json.len() as u64).to_le_bytes());
        footer.extend_from_slice(&(index.len() as u64).to_le_bytes());
        footer.extend_from_slice(&crc.finalize().to_le_bytes());
        footer.extend_from_slice(&self.version.to_le_bytes());
        footer.extend_from_slice(END_MAGIC);
        self.tmp
            .write_all(&json)
            .map_err(self.io("cannot write header"))?;
        self.tmp
            .write_all(&index)
            .map_err(self.io("cannot write brick index"))?;
        self.tmp
            .write_all(&footer)
            .map_err(self.io("cannot write footer"))?;
        let tmp = self.tmp.into_inner().map_err(|e| FormatError::Io {
            path: self.target.clone(),
            what: "cannot flush",
            source: e.into_error(),
        })?;
        tmp.as_file().sync_all().map_err(|source| FormatError::Io {
            path: self.target.clone(),
            what: "cannot sync",
            source,
        })?;
        tmp.persist(&self.target).map_err(|e| FormatError::Io {
            path: self.target.clone(),
            what: "cannot rename the finished file into place",
            source: e.error,
        })?;
        Ok(())
    }
}
