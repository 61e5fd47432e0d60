//! The packed, bricked file (docs/FORMAT.md): header, brick index, zstd
//! payloads, and distance codes embedded in background samples.
//!
//! Layout: a 16-byte preamble, the brick payloads, then the trailer (the
//! JSON header and the binary brick index), then a 40-byte footer that
//! locates the trailer and carries its CRC-32. Everything a writer learns
//! only at the end (index, summary) therefore sits at the end, and a
//! truncated file has no footer and is refused.

pub mod brick;
pub mod histogram;
pub mod landmarks;
pub mod planes;
pub mod reader;
pub mod word;
pub mod writer;

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::classify::Classification;
use crate::grid::Axis;
use crate::input::{Dtype, Rescale};

/// First 8 bytes of every packed file.
pub const MAGIC: &[u8; 8] = b"CDVOLPK\x01";
/// Last 8 bytes of every complete packed file.
pub const END_MAGIC: &[u8; 8] = b"CDVOLEND";
/// Format version written by this crate. Version 2 adds the index's
/// brick value maxima ([`FLAG_VALUE_MAX`]); version 3 stores each
/// payload's sample words as byte planes ([`BYTE_PLANES_VERSION`]).
/// Readers take every version from [`OLDEST_READ_VERSION`] to this one
/// and refuse others.
pub const FORMAT_VERSION: u32 = 3;
/// The first format version whose payloads hold their sample words as
/// byte planes ([`planes`]): byte 0 of every word, then byte 1, and so
/// on. Earlier versions interleave them (word after word).
pub const BYTE_PLANES_VERSION: u32 = 3;
/// The oldest format version prep can still write (`prep
/// --format-version`), for sites whose older cdvol builds read their
/// files: version 2 is the newest layout without byte planes.
pub const OLDEST_WRITE_VERSION: u32 = 2;
/// The oldest format version this crate reads (version 1: no value
/// maxima in the index).
pub const OLDEST_READ_VERSION: u32 = 1;
/// Bytes before the first payload.
pub const PREAMBLE_LEN: u64 = 16;
/// Bytes of the footer.
pub const FOOTER_LEN: u64 = 40;
/// Bytes of one brick index entry.
pub const INDEX_ENTRY_LEN: usize = 32;
/// Largest JSON header a reader accepts: three axes of 2^20 positions of
/// at most 25 characters each fit in 80 MB.
pub const MAX_HEADER_LEN: u64 = 1 << 28;
/// Largest decompressed brick payload (prep refuses brick sizes beyond it;
/// readers refuse headers that imply more, so a crafted header cannot make
/// them allocate without bound).
pub const MAX_PAYLOAD_LEN: u64 = 1 << 30;

/// How distance codes are stored in sample words.
///
/// On write: a sample that is the minimum corner of a cell with code
/// `n >= 1` is a vertex of no 1-cell, and its word is replaced by the
/// code word of `min(n, max)`. On read: a word that is a code word gives
/// the code of the cell at whose minimum corner it sits; every other word
/// is an exact sample value.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum CodeEncoding {
    /// Integer words: code `n` is the word `base + n`, `0 <= n <= max`. The
    /// data never uses that range (prep picks a free range of the type, or
    /// widens the type when there is none).
    IntRange { base: i64, max: u32 },
    /// Float words: code `n` is a quiet NaN whose payload is
    /// [`word::NAN_CODE_FLAG`] `| n`. Input NaNs are stored as the canonical
    /// quiet NaN (payload 0), so they never read as codes.
    NanPayload { max: u32 },
}

/// For people: `integer words base+0 .. base+max (codes 0 .. max)` or
/// `NaN payloads (codes 0 .. max)`.
impl std::fmt::Display for CodeEncoding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            CodeEncoding::IntRange { base, max } => write!(
                f,
                "integer words {base} .. {} (codes 0 .. {max})",
                base.saturating_add(max as i64)
            ),
            CodeEncoding::NanPayload { max } => write!(f, "NaN payloads (codes 0 .. {max})"),
        }
    }
}

impl CodeEncoding {
    /// Largest code the file can hold (codes saturate there).
    pub fn max_code(&self) -> u32 {
        match *self {
            CodeEncoding::IntRange { max, .. } | CodeEncoding::NanPayload { max } => max,
        }
    }
}

/// Summary figures computed while preparing (for `cdvol info`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    pub cells: u64,
    pub one_cells: u64,
    /// `code_histogram[n]` = number of 0-cells with code n (after
    /// saturation at the encoding's maximum).
    pub code_histogram: Vec<u64>,
    pub uniform_bricks: u64,
    /// Smallest and largest raw sample (NaN excluded; None if all NaN).
    pub raw_min: Option<f64>,
    pub raw_max: Option<f64>,
    pub nan_samples: u64,
    /// Bytes of input samples (dims product times the input type size).
    pub input_bytes: u64,
    /// Bytes of compressed payloads in the file.
    pub payload_bytes: u64,
    /// Bytes of payloads before compression.
    pub raw_payload_bytes: u64,
    /// Histogram and percentiles of the rescaled sample values, recorded
    /// in prep's first pass; absent in older files and omitted from the
    /// JSON when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub histogram: Option<histogram::ValueHistogram>,
}

/// The imaging modality of a file's data and where that was learnt.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ModalityRecord {
    pub modality: crate::presets::Modality,
    /// Where it came from: the input's header (DICOM Modality, a sidecar's
    /// `modality`), `--modality`, or a guess from the values, said as such.
    pub source: String,
}

/// The JSON header (see docs/FORMAT.md).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub format_version: u32,
    /// Samples per axis.
    pub dims: [u64; 3],
    /// Sample positions in mm along x, y and z.
    pub axes: [Axis; 3],
    /// Sample type of the input.
    pub dtype: Dtype,
    /// Type of the stored words (the input type, or a wider one).
    pub storage: Dtype,
    pub rescale: Rescale,
    pub classification: Classification,
    pub codes: CodeEncoding,
    /// Cells per brick edge.
    pub brick_size: u32,
    /// Bricks per axis.
    pub bricks: [u64; 3],
    /// Anisotropic (octant) codes: cells per block edge, when present.
    pub aniso_block: Option<u32>,
    /// City-block and chamfer 3-4-5 distance planes for the DDA traversals
    /// (one `u8` each per cell, after the octant planes); absent (false)
    /// in older files and omitted from the JSON when false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub dda: bool,
    /// Codes are embedded only in words whose cell has code >= 2 (`prep
    /// --gradient-halo`): every sample within one cell of a 1-cell keeps
    /// its value, and code-1 cells of stored bricks read back as code 0
    /// (conservative). Absent (false) in older files and omitted from the
    /// JSON when false.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub gradient_halo: bool,
    pub zstd_level: i32,
    pub source: String,
    /// What the input told about itself that a reader should know (a
    /// DICOM series' z spacing report); absent in older files.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// Which way the sample axes point in the patient (LPS), and where
    /// that came from; absent when unknown (and in older files).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orientation: Option<crate::orient::Orientation>,
    /// What the input was when the file was made (`prep-batch` records it
    /// to know, on a re-run, whether the input changed); absent in files
    /// made by `prep` and in older files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input: Option<crate::identity::InputStamp>,
    /// The data's modality (CT, MR) and where that came from; absent in
    /// older files, whose modality is guessed from their values.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub modality: Option<ModalityRecord>,
    /// The values' landmarks that MR presets are placed on
    /// ([`landmarks::Landmarks`]); absent in older files, which take them
    /// from the value histogram.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landmarks: Option<landmarks::Landmarks>,
    /// The preset the file was prepared with (`prep --preset`): its
    /// default look in `render` and `serve`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub look: Option<String>,
    /// A label file (`prep --labels`): the labels it holds and its colour
    /// table ([`crate::labels`]); absent otherwise, so older files read
    /// unchanged.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub labels: Option<crate::labels::LabelInfo>,
    pub summary: Summary,
}

impl Header {
    /// The file's modality: the recorded one, or for older files a guess
    /// from the value range ([`crate::presets::Modality::guess`]).
    pub fn modality(&self) -> ModalityRecord {
        if let Some(m) = &self.modality {
            return m.clone();
        }
        let (lo, _) = self.value_range().unwrap_or((0.0, 0.0));
        let (modality, why) = crate::presets::Modality::guess(lo);
        ModalityRecord {
            modality,
            source: format!("guessed: the file does not record one, and {why}"),
        }
    }

    /// The landmarks MR presets are placed on: the recorded ones, else
    /// those of the value histogram; `None` without either.
    pub fn landmarks(&self) -> Option<landmarks::Landmarks> {
        if let Some(l) = &self.landmarks {
            return Some(l.clone());
        }
        let h = self.summary.histogram.as_ref()?;
        landmarks::Landmarks::of(h, "the file's value histogram")
    }

    /// Smallest and largest sample value in rescaled units (NaN left
    /// out), from the summary; `None` when every sample is NaN.
    pub fn value_range(&self) -> Option<(f64, f64)> {
        let (a, b) = (self.summary.raw_min?, self.summary.raw_max?);
        let (a, b) = (self.rescale.apply(a), self.rescale.apply(b));
        Some((a.min(b), a.max(b)))
    }

    pub fn cells(&self) -> [u64; 3] {
        self.dims.map(|d| d - 1)
    }

    pub fn brick_count(&self) -> u64 {
        self.bricks.iter().product()
    }

    /// Cell range `[lo, hi)` of brick `b` along one axis.
    pub fn brick_cells(&self, axis: usize, b: u64) -> (u64, u64) {
        let bs = self.brick_size as u64;
        let lo = b * bs;
        (lo, (lo + bs).min(self.cells()[axis]))
    }

    /// Brick coordinates of linear brick id (x fastest).
    pub fn brick_coords(&self, id: u64) -> [u64; 3] {
        let [bx, by, _] = self.bricks;
        [id % bx, id / bx % by, id / bx / by]
    }

    pub fn brick_id(&self, c: [u64; 3]) -> u64 {
        (c[2] * self.bricks[1] + c[1]) * self.bricks[0] + c[0]
    }

    /// Samples per axis stored in brick `c` (cells + 1 apron sample).
    pub fn brick_samples(&self, c: [u64; 3]) -> [u64; 3] {
        std::array::from_fn(|k| {
            let (lo, hi) = self.brick_cells(k, c[k]);
            hi - lo + 1
        })
    }

    /// Anisotropic blocks per axis in brick `c`.
    pub fn brick_blocks(&self, c: [u64; 3]) -> Option<[u64; 3]> {
        let g = self.aniso_block? as u64;
        Some(std::array::from_fn(|k| {
            let (lo, hi) = self.brick_cells(k, c[k]);
            (hi - lo).div_ceil(g)
        }))
    }

    /// Bytes of brick `c`'s sample words (the front of its payload).
    pub fn words_len(&self, c: [u64; 3]) -> u64 {
        self.brick_samples(c).iter().product::<u64>() * self.storage.size() as u64
    }

    /// Whether the payloads hold their sample words as byte planes
    /// ([`BYTE_PLANES_VERSION`]; one-byte words are the same either way).
    pub fn byte_planes(&self) -> bool {
        self.format_version >= BYTE_PLANES_VERSION && self.storage.size() > 1
    }

    /// Decompressed payload size of a full (not edge) brick: the largest.
    pub fn max_payload_len(&self) -> u64 {
        let s = self.brick_size as u64 + 1;
        let aniso = self.aniso_block.map_or(0, |g| {
            8 * (self.brick_size as u64).div_ceil(g as u64).pow(3)
        });
        let dda = if self.dda {
            2 * (self.brick_size as u64).pow(3)
        } else {
            0
        };
        s * s * s * self.storage.size() as u64 + aniso + dda
    }

    /// Bytes of the DDA planes of brick `c` (0 without them).
    pub fn dda_len(&self, c: [u64; 3]) -> u64 {
        if !self.dda {
            return 0;
        }
        let s = self.brick_samples(c);
        2 * (s[0] - 1) * (s[1] - 1) * (s[2] - 1)
    }

    /// Exact decompressed payload size of brick `c`.
    pub fn payload_len(&self, c: [u64; 3]) -> u64 {
        let words = self.words_len(c);
        let aniso = self.brick_blocks(c).map_or(0, |b| 8 * b[0] * b[1] * b[2]);
        words + aniso + self.dda_len(c)
    }
}

/// One brick index entry (32 bytes, little-endian).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct IndexEntry {
    /// Byte offset of the compressed payload in the file.
    pub offset: u64,
    /// Compressed length in bytes (0 for uniform bricks).
    pub length: u32,
    /// CRC-32 (IEEE) of the compressed payload.
    pub crc32: u32,
    /// Bit 0: uniform (no payload; every cell is a 0-cell with
    /// `uniform_code`). Bit 1: no 1-cell in the brick; `uniform_code` is
    /// then the smallest code of its cells. Bit 2 ([`FLAG_VALUE_MAX`],
    /// version 2): `value_max` holds the brick's largest value.
    pub flags: u32,
    pub uniform_code: u32,
    /// With [`FLAG_VALUE_MAX`]: the bits of an f64, the largest rescaled
    /// value of the brick's samples that hold values (the apron
    /// included; NaN samples ignored). 0 otherwise.
    pub value_max: u64,
}

pub const FLAG_UNIFORM: u32 = 1;
/// Index flag bit 1: the brick holds no 1-cell, so a reader needs only its
/// codes (on write: set by prep from the distances; on read: a hint that
/// lets the renderer skip values and classification).
pub const FLAG_NO_OBJECT: u32 = 2;
/// Index flag bit 2 (format version 2): the entry's `value_max` holds the
/// largest value of the brick, set by prep on every stored brick with
/// 1-cells. A render at an iso value above it knows, without reading the
/// brick, that none of its cells is a 1-cell of the scene (render/brick/envelope.rs).
pub const FLAG_VALUE_MAX: u32 = 4;

impl IndexEntry {
    pub fn is_uniform(&self) -> bool {
        self.flags & FLAG_UNIFORM != 0
    }

    /// True when the brick holds no 1-cell.
    pub fn has_no_object(&self) -> bool {
        self.flags & FLAG_NO_OBJECT != 0
    }

    /// The brick's largest value, when the index records it
    /// ([`FLAG_VALUE_MAX`]).
    pub fn value_max(&self) -> Option<f64> {
        (self.flags & FLAG_VALUE_MAX != 0).then(|| f64::from_bits(self.value_max))
    }

    pub fn to_bytes(&self) -> [u8; INDEX_ENTRY_LEN] {
        let mut b = [0u8; INDEX_ENTRY_LEN];
        b[0..8].copy_from_slice(&self.offset.to_le_bytes());
        b[8..12].copy_from_slice(&self.length.to_le_bytes());
        b[12..16].copy_from_slice(&self.crc32.to_le_bytes());
        b[16..20].copy_from_slice(&self.flags.to_le_bytes());
        b[20..24].copy_from_slice(&self.uniform_code.to_le_bytes());
        b[24..32].copy_from_slice(&self.value_max.to_le_bytes());
        b
    }

    pub fn from_bytes(b: &[u8]) -> IndexEntry {
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
        let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().expect("4 bytes"));
        IndexEntry {
            offset: u64_at(0),
            length: u32_at(8),
            crc32: u32_at(12),
            flags: u32_at(16),
            uniform_code: u32_at(20),
            value_max: u64_at(24),
        }
    }
}

/// Errors reading or writing a packed file. Each names the file and,
/// where one is at fault, the brick or field.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("{}: {what}: {source}", path.display())]
    Io {
        path: PathBuf,
        what: &'static str,
        source: std::io::Error,
    },
    #[error("{}: not a cdvol packed file (magic {found:02x?}, expected {:02x?})", path.display(), MAGIC)]
    NotPacked { path: PathBuf, found: Vec<u8> },
    #[error(
        "{}: format version {found}, this cdvol reads versions {OLDEST_READ_VERSION} to {FORMAT_VERSION}",
        path.display()
    )]
    Version { path: PathBuf, found: u32 },
    #[error("{}: truncated or incomplete: {msg}", path.display())]
    Truncated { path: PathBuf, msg: String },
    #[error("{}: corrupt header: {msg}", path.display())]
    Header { path: PathBuf, msg: String },
    #[error("{}: brick {brick} {coords:?}: {msg}", path.display())]
    Brick {
        path: PathBuf,
        brick: u64,
        coords: [u64; 3],
        msg: String,
    },
}
