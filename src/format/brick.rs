//! The one decoder of brick payloads (docs/FORMAT.md, "Brick payload"):
//! sample words into values and embedded codes, then the optional octant
//! codes and DDA planes. The reader ([`super::reader`]) builds its
//! [`Brick`](super::reader::Brick) on it and the render cache builds its
//! decoded bricks on it; neither parses words itself.

use super::word::Word;
use super::Header;
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
