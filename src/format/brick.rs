//! The one decoder of brick payloads (docs/FORMAT.md, "Brick payload"):
//! sample words into values and embedded codes, then the optional octant
//! codes and DDA planes. The reader ([`super::reader`]) builds its
//! [`Brick`](super::reader::Brick) on it and the render cache builds its
//! decoded bricks on it; neither parses words itself.

use super::word::Word;
use super::{CodeEncoding, Header};
use crate::with_word;

/// What [`decode_words`] makes of the value words.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Values {
    /// Raw sample values, as stored (before rescale).
    Raw,
    /// Rescaled by the header's rescale, in f64 (the precision prep
    /// classified with).
    Rescaled,
    /// Left at 0: the caller needs only the codes.
    Skip,
}

/// Decodes the sample words at the start of the decompressed payload
/// `raw` of a brick with `n` samples (x fastest): `codes[i]` is the code
/// word `i` carries (`None` for a value word) and `values[i]` the word's
/// value as `mode` asks (0 where the word is a code). Both buffers are
/// cleared and refilled, so callers can keep them as scratch.
pub fn decode_words(
    h: &Header,
    raw: &[u8],
    n: usize,
    mode: Values,
    values: &mut Vec<f64>,
    codes: &mut Vec<Option<u32>>,
) {
    values.clear();
    values.resize(n, 0.0);
    codes.clear();
    codes.resize(n, None);
    let enc = h.codes;
    let rs = h.rescale;
    with_word!(h.storage, W => {
        let size = std::mem::size_of::<W>();
        let words = raw[..n * size].chunks_exact(size);
        for ((w, v), c) in words.zip(values.iter_mut()).zip(codes.iter_mut()) {
            let w: W = bytemuck::pod_read_unaligned(w);
            match w.as_code(&enc) {
                Some(code) => *c = Some(code),
                None => match mode {
                    Values::Raw => *v = w.to_raw(),
                    Values::Rescaled => *v = rs.apply(w.to_raw()),
                    Values::Skip => {}
                },
            }
        }
    });
}

/// Sample class bit of [`decode_samples`]: the word is a code.
pub const SAMPLE_CODE: u8 = 2;
/// Sample class bit of [`decode_samples`]: a value word whose rescaled
/// value is at or above the iso value (never set for NaN).
pub const SAMPLE_ABOVE: u8 = 1;

/// The renderer's decoder of the sample words, one pass with no
/// intermediate f64 or `Option` buffers; the same words, codes and
/// rescaled values as [`decode_words`] with [`Values::Rescaled`] (the same
/// f64 arithmetic), delivered as:
/// - `kinds[i]`: [`SAMPLE_CODE`] for a code word, else [`SAMPLE_ABOVE`]
///   when `iso` is given and the rescaled value is `>= iso` (NaN never
///   is), else 0;
/// - `codes[i]`: the code, saturated to 254, or 0 for a value word;
/// - with `values = Some((out, map))`: `out[i] = map(rescaled value)` for
///   a value word and NaN for a code word (`out` cleared and refilled).
///
/// `kinds` and `codes` are cleared and refilled, so callers can keep them
/// as scratch.
pub fn decode_samples<F: Fn(f64) -> f32>(
    h: &Header,
    raw: &[u8],
    n: usize,
    iso: Option<f64>,
    kinds: &mut Vec<u8>,
    codes: &mut Vec<u8>,
    values: Option<(&mut Vec<f32>, F)>,
) {
    kinds.clear();
    kinds.resize(n, 0);
    codes.clear();
    codes.resize(n, 0);
    // `v >= NaN` is never true: no iso value, no "above" bit.
    let iso = iso.unwrap_or(f64::NAN);
    let rs = h.rescale;
    with_word!(h.storage, W => {
        let size = std::mem::size_of::<W>();
        let bytes = &raw[..n * size];
        // The encoding matched once here, so that the loop's code test
        // is a constant-folded range or NaN-payload check.
        match h.codes {
            CodeEncoding::IntRange { base, max } => {
                let enc = CodeEncoding::IntRange { base, max };
                samples_of::<W, F>(bytes, &enc, rs, iso, kinds, codes, values);
            }
            CodeEncoding::NanPayload { max } => {
                let enc = CodeEncoding::NanPayload { max };
                samples_of::<W, F>(bytes, &enc, rs, iso, kinds, codes, values);
            }
        }
    });
}

/// The loop of [`decode_samples`] over words of type `W`: aligned words
/// are read in place, others one at a time.
#[inline(always)]
fn samples_of<W: Word, F: Fn(f64) -> f32>(
    bytes: &[u8],
    enc: &CodeEncoding,
    rs: crate::input::Rescale,
    iso: f64,
    kinds: &mut [u8],
    codes: &mut [u8],
    values: Option<(&mut Vec<f32>, F)>,
) {
    let n = kinds.len();
    let kc = kinds.iter_mut().zip(codes.iter_mut());
    match (bytemuck::try_cast_slice::<u8, W>(bytes), values) {
        (Ok(words), Some((out, map))) => {
            out.clear();
            out.reserve_exact(n);
            out.extend(
                words
                    .iter()
                    .zip(kc)
                    .map(|(&w, (k, c))| sample(w, enc, rs, iso, k, c, &map)),
            );
        }
        (Ok(words), None) => {
            for (&w, (k, c)) in words.iter().zip(kc) {
                sample(w, enc, rs, iso, k, c, &|_| 0.0);
            }
        }
        (Err(_), values) => {
            let words = bytes
                .chunks_exact(std::mem::size_of::<W>())
                .map(bytemuck::pod_read_unaligned::<W>);
            match values {
                Some((out, map)) => {
                    out.clear();
                    out.reserve_exact(n);
                    out.extend(
                        words
                            .zip(kc)
                            .map(|(w, (k, c))| sample(w, enc, rs, iso, k, c, &map)),
                    );
                }
                None => {
                    for (w, (k, c)) in words.zip(kc) {
                        sample(w, enc, rs, iso, k, c, &|_| 0.0);
                    }
                }
            }
        }
    }
}

/// One word of [`decode_samples`]: its kind and code written, its mapped
/// value returned (NaN for a code).
#[inline(always)]
fn sample<W: Word>(
    w: W,
    enc: &CodeEncoding,
    rs: crate::input::Rescale,
    iso: f64,
    k: &mut u8,
    c: &mut u8,
    map: &impl Fn(f64) -> f32,
) -> f32 {
    match w.as_code(enc) {
        Some(code) => {
            *k = SAMPLE_CODE;
            *c = code.min(254) as u8;
            f32::NAN
        }
        None => {
            let v = rs.apply(w.to_raw());
            *k = (v >= iso) as u8 * SAMPLE_ABOVE;
            map(v)
        }
    }
}

/// [`decode_samples`] as a lookup table, for 8- and 16-bit words: every
/// possible word's kind, code and mapped value, computed once by the same
/// per-word rule, so a table decode gives the same bytes as
/// [`decode_samples`] with the same `iso` and `map`.
pub struct SampleTable {
    key: TableKey,
    /// Per word (its native-endian bits as the index): the mapped value.
    /// Shared: a decoded brick may keep its words and look values up here
    /// (`render::samples`).
    values: std::sync::Arc<[f32]>,
    /// Per word: `kind << 8 | code`.
    kind_code: Vec<u16>,
    /// The same as two range tests, for 16-bit words whose table has them.
    ranges: Option<Ranges>,
}

/// What a [`SampleTable`] was built for (floats as bits).
type TableKey = (crate::input::Dtype, CodeEncoding, [u64; 3]);

fn table_key(h: &Header, iso: Option<f64>) -> TableKey {
    let iso = iso.unwrap_or(f64::NAN);
    (
        h.storage,
        h.codes,
        [h.rescale.slope, h.rescale.intercept, iso].map(f64::to_bits),
    )
}

impl SampleTable {
    /// The table of `h`'s words, for words of at most 16 bits (`None`
    /// otherwise). The caller keeps using the same `map` with it.
    pub fn new<F: Fn(f64) -> f32>(h: &Header, iso: Option<f64>, map: F) -> Option<SampleTable> {
        let size = h.storage.size();
        if size > 2 {
            return None;
        }
        let len = 1usize << (8 * size);
        let (mut kinds, mut codes) = (vec![0u8; len], vec![0u8; len]);
        let mut values = Vec::new();
        // Every word, in index order: index i's native-endian bytes (one
        // buffer; a Vec per word cost more than the decode).
        let mut bytes = Vec::with_capacity(len * size);
        for i in 0..len {
            if size == 1 {
                bytes.push(i as u8);
            } else {
                bytes.extend_from_slice(&(i as u16).to_ne_bytes());
            }
        }
        decode_samples(
            h,
            &bytes,
            len,
            iso,
            &mut kinds,
            &mut codes,
            Some((&mut values, map)),
        );
        let kind_code: Vec<u16> = kinds
            .iter()
            .zip(&codes)
            .map(|(&k, &c)| (k as u16) << 8 | c as u16)
            .collect();
        Some(SampleTable {
            key: table_key(h, iso),
            values: values.into(),
            ranges: Ranges::of(&kind_code),
            kind_code,
        })
    }

    /// The range tests and the first `n` words of `raw` in place, when
    /// this table has range tests and the payload is aligned for 16-bit
    /// words (else the caller looks words up in the table).
    fn range_words<'a>(&self, raw: &'a [u8], n: usize) -> Option<(Ranges, &'a [u16])> {
        let r = self.ranges?;
        let words = bytemuck::try_cast_slice::<u8, u16>(&raw[..2 * n]).ok()?;
        Some((r, words))
    }

    /// Whether this 16-bit table decodes kinds and codes by range tests
    /// (for tests: the fast path is taken where it is expected).
    #[doc(hidden)]
    pub fn uses_ranges(&self) -> bool {
        self.ranges.is_some()
    }

    /// This table with its range tests dropped (for tests: the lookup
    /// path to compare with).
    #[doc(hidden)]
    pub fn without_ranges(self) -> SampleTable {
        SampleTable {
            ranges: None,
            ..self
        }
    }

    /// Whether this table decodes `h`'s words with `iso`.
    pub fn fits(&self, h: &Header, iso: Option<f64>) -> bool {
        self.key == table_key(h, iso)
    }

    /// [`decode_samples`] through the table (which must [`fit`](Self::fits)
    /// the file `raw` comes from).
    pub fn decode(
        &self,
        raw: &[u8],
        n: usize,
        kinds: &mut Vec<u8>,
        codes: &mut Vec<u8>,
        values: &mut Vec<f32>,
    ) {
        self.decode_into(raw, n, kinds, codes, values, |i| self.values[i]);
    }

    /// [`SampleTable::decode`] keeping the words themselves (their
    /// native-endian bits, the table's index) instead of their values: half
    /// the memory of f32 values for 16-bit words, a quarter for 8-bit ones.
    /// `T` is `u8` for 8-bit words and `u16` for 16-bit ones.
    pub fn decode_words<T: TableWord>(
        &self,
        raw: &[u8],
        n: usize,
        kinds: &mut Vec<u8>,
        codes: &mut Vec<u8>,
        words: &mut Vec<T>,
    ) {
        debug_assert_eq!(self.values.len(), 1 << (8 * std::mem::size_of::<T>()));
        self.decode_into(raw, n, kinds, codes, words, T::from_index);
    }

    /// The one pass of both decodes: each word's kind and code, and `out`
    /// of the word's table index.
    #[inline(always)]
    fn decode_into<T, F: Fn(usize) -> T>(
        &self,
        raw: &[u8],
        n: usize,
        kinds: &mut Vec<u8>,
        codes: &mut Vec<u8>,
        out: &mut Vec<T>,
        f: F,
    ) {
        kinds.clear();
        codes.clear();
        out.clear();
        out.reserve_exact(n);
        // Each plane written once, with no clearing pass before it.
        if let Some((r, words)) = self.range_words(raw, n) {
            kinds.extend(words.iter().map(|&w| r.kind_code(w).0));
            codes.extend(words.iter().map(|&w| r.kind_code(w).1));
            out.extend(words.iter().map(|&w| f(w as usize)));
            return;
        }
        kinds.resize(n, 0);
        codes.resize(n, 0);
        let kc = kinds.iter_mut().zip(codes.iter_mut());
        let one = |i: usize, (k, c): (&mut u8, &mut u8)| {
            let e = self.kind_code[i];
            *k = (e >> 8) as u8;
            *c = e as u8;
            f(i)
        };
        if self.values.len() == 256 {
            out.extend(raw[..n].iter().zip(kc).map(|(&b, kc)| one(b as usize, kc)));
        } else {
            out.extend(
                raw[..2 * n]
                    .chunks_exact(2)
                    .zip(kc)
                    .map(|(b, kc)| one(u16::from_ne_bytes([b[0], b[1]]) as usize, kc)),
            );
        }
    }

    /// Every word's mapped value, indexed by the word's native-endian
    /// bits: 256 entries for 8-bit words, 65536 for 16-bit ones.
    pub fn values(&self) -> &std::sync::Arc<[f32]> {
        &self.values
    }
}

/// The kinds and codes of a table of 16-bit words as two wrapping range
/// tests instead of a lookup per word, so that the decode loop runs in
/// vector registers: code words are one range of words (the code is the
/// distance from its start, saturated to 254), and value words at or
/// above the iso value one range in unsigned or in signed order (`flip`
/// turns signed order into unsigned). [`Ranges::of`] derives them from a
/// table and keeps them only if they give every one of the 65536 words
/// exactly the table's kind and code, so a decode through them writes the
/// table's bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Ranges {
    code_lo: u16,
    code_span: u16,
    flip: u16,
    above_lo: u16,
    above_span: u16,
    /// [`SAMPLE_ABOVE`], or 0 when no word is above the iso value.
    above_bit: u8,
}

impl Ranges {
    /// The kind and code of word `w`.
    #[inline(always)]
    fn kind_code(self, w: u16) -> (u8, u8) {
        let d = w.wrapping_sub(self.code_lo);
        let is_code = d <= self.code_span;
        let above = (w ^ self.flip).wrapping_sub(self.above_lo) <= self.above_span;
        let code = if d < 254 { d as u8 } else { 254 };
        (
            if is_code {
                SAMPLE_CODE
            } else {
                above as u8 & self.above_bit
            },
            if is_code { code } else { 0 },
        )
    }

    /// The ranges of a 16-bit table's `kind << 8 | code` entries, if
    /// there are such ranges (see the type).
    fn of(kind_code: &[u16]) -> Option<Ranges> {
        if kind_code.len() != 1 << 16 {
            return None;
        }
        let kind = |w: u16| (kind_code[w as usize] >> 8) as u8;
        let (code_lo, code_span) = span((0..=u16::MAX).filter(|&w| kind(w) == SAMPLE_CODE))?;
        [0, 0x8000].into_iter().find_map(|flip: u16| {
            let above = (0..=u16::MAX)
                .filter(|&w| kind(w) == SAMPLE_ABOVE)
                .map(|w| w ^ flip);
            let (above_lo, above_span, above_bit) = match span(above) {
                Some((lo, s)) => (lo, s, SAMPLE_ABOVE),
                None => (0, 0, 0),
            };
            let r = Ranges {
                code_lo,
                code_span,
                flip,
                above_lo,
                above_span,
                above_bit,
            };
            let exact = (0..=u16::MAX).all(|w| {
                let (k, c) = r.kind_code(w);
                kind_code[w as usize] == (k as u16) << 8 | c as u16
            });
            exact.then_some(r)
        })
    }
}

/// The smallest of `keys` and how far the largest lies above it.
fn span(keys: impl Iterator<Item = u16>) -> Option<(u16, u16)> {
    let (lo, hi) = keys.fold(None, |m, k| match m {
        None => Some((k, k)),
        Some((a, b)) => Some((k.min(a), k.max(b))),
    })?;
    Some((lo, hi - lo))
}

/// A stored word kept as its [`SampleTable`] index.
pub trait TableWord: Copy {
    /// The word of table index `i` (below the table's length).
    fn from_index(i: usize) -> Self;
}

impl TableWord for u8 {
    #[inline(always)]
    fn from_index(i: usize) -> u8 {
        i as u8
    }
}

impl TableWord for u16 {
    #[inline(always)]
    fn from_index(i: usize) -> u16 {
        i as u16
    }
}

impl SampleTable {
    /// The code of each cell's minimum corner word (0 for a value word),
    /// cells x fastest, appended to `plane`: all a brick without 1-cells
    /// needs (its cells are coded at their minimum corner or have code 0).
    /// `samples` per axis; only the corner words are read.
    pub fn corner_codes(&self, raw: &[u8], samples: [usize; 3], plane: &mut Vec<u8>) {
        let [sx, sy, sz] = samples;
        let size = if self.values.len() == 256 { 1 } else { 2 };
        if let Some((r, words)) = self.range_words(raw, sx * sy * sz) {
            for z in 0..sz - 1 {
                for y in 0..sy - 1 {
                    let row = &words[(z * sy + y) * sx..(z * sy + y) * sx + sx - 1];
                    plane.extend(row.iter().map(|&w| r.kind_code(w).1));
                }
            }
            return;
        }
        for z in 0..sz - 1 {
            for y in 0..sy - 1 {
                let row = &raw[(z * sy + y) * sx * size..((z * sy + y) * sx + sx - 1) * size];
                if size == 1 {
                    plane.extend(row.iter().map(|&b| self.kind_code[b as usize] as u8));
                } else {
                    plane.extend(
                        row.chunks_exact(2).map(|b| {
                            self.kind_code[u16::from_ne_bytes([b[0], b[1]]) as usize] as u8
                        }),
                    );
                }
            }
        }
    }
}

/// The octant codes of brick `coords` (anisotropic files, section 4.2.1):
/// per block of [`crate::dt::ANISO_BLOCK`]^3 cells, x fastest, the 8
/// codes, stored after the words as 8 planes of one byte per block.
pub fn octant_codes(h: &Header, coords: [u64; 3], raw: &[u8]) -> Option<Vec<[u8; 8]>> {
    let b = h.brick_blocks(coords)?;
    let nb = (b[0] * b[1] * b[2]) as usize;
    let wbytes = h.brick_samples(coords).iter().product::<u64>() as usize * h.storage.size();
    let a = &raw[wbytes..];
    Some(
        (0..nb)
            .map(|i| std::array::from_fn(|o| a[o * nb + i]))
            .collect(),
    )
}

/// The DDA planes of brick `coords` (files prepared with `--dda`): city
/// block, then chamfer 3-4-5, one byte per cell, x fastest, at the end of
/// the payload. The reader has checked the payload's length.
pub fn dda_planes(h: &Header, coords: [u64; 3], raw: &[u8]) -> Option<[Vec<u8>; 2]> {
    if !h.dda {
        return None;
    }
    let len = (h.dda_len(coords) / 2) as usize;
    let start = raw.len() - 2 * len;
    Some([
        raw[start..start + len].to_vec(),
        raw[start + len..].to_vec(),
    ])
}
