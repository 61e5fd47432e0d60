//! Byte planes: how format version 3 stores a brick's sample words.
//!
//! The words of a payload are stored as `width` planes: byte 0 of every
//! word in sample order, then byte 1 of every word, and so on (the
//! transpose of the words' bytes, as Blosc's shuffle filter does). Within
//! a plane, neighbouring samples of smooth data share their high bytes, so
//! zstd finds longer matches there than in interleaved words. On the
//! 1024^3 CT phantom's bricks with 1-cells (16-bit words) that made the
//! payloads 22 % smaller and zstd's decoding 1.7 times as fast
//! (docs/BENCHMARKS.md, "Byte planes"). The distance codes embedded in
//! the words, and the octant and DDA planes that follow the words, are
//! unchanged.

use std::mem::MaybeUninit;

/// Writes the byte planes of `words` (whole words of `width` bytes, in
/// sample order) to the end of `out`.
///
/// # Panics
/// If `width` is 0 or `words.len()` is not a multiple of it (a
/// programming error: prep builds whole words).
pub fn split(words: &[u8], width: usize, out: &mut Vec<u8>) {
    assert!(
        width > 0 && words.len().is_multiple_of(width),
        "whole words"
    );
    let (start, n) = (out.len(), words.len() / width);
    out.resize(start + words.len(), 0);
    let planes = &mut out[start..];
    if width == 2 {
        let (lo, hi) = planes.split_at_mut(n);
        for ((w, l), h) in words.chunks_exact(2).zip(lo).zip(hi) {
            *l = w[0];
            *h = w[1];
        }
        return;
    }
    for (b, plane) in planes.chunks_exact_mut(n.max(1)).enumerate() {
        for (p, w) in plane.iter_mut().zip(words.chunks_exact(width)) {
            *p = w[b];
        }
    }
}

/// The inverse of [`split`]: appends to `out` the words (of `width`
/// bytes) whose planes are `planes`.
///
/// The words are written straight into `out`'s spare capacity: the
/// reader decompresses the planes into one buffer and joins them into
/// another, with no copy of the planes aside and no zeroing of the
/// destination first (docs/BENCHMARKS.md, "The join without a copy").
///
/// # Panics
/// If `width` is 0 or `planes` is not whole words (a programming error:
/// the reader checks the payload's length before it joins).
pub fn join_into(planes: &[u8], width: usize, out: &mut Vec<u8>) {
    assert!(
        width > 0 && planes.len().is_multiple_of(width),
        "whole words"
    );
    let n = planes.len() / width;
    let start = out.len();
    out.reserve(planes.len());
    let dst = &mut out.spare_capacity_mut()[..planes.len()];
    match width {
        1 => {
            for (d, &b) in dst.iter_mut().zip(planes) {
                d.write(b);
            }
        }
        2 => join2(&planes[..n], &planes[n..], dst),
        _ => {
            for (b, plane) in planes.chunks_exact(n.max(1)).enumerate() {
                for (w, &byte) in dst.chunks_exact_mut(width).zip(plane) {
                    w[b].write(byte);
                }
            }
        }
    }
    // SAFETY: the `planes.len()` bytes after `start` are initialised:
    // width 1 and 2 write every byte of `dst`; wider words write byte `b`
    // of each of the `n` words from plane `b`, for every `b < width`.
    unsafe { out.set_len(start + planes.len()) };
}

/// 16-bit words from their two planes, 16 words per step (a fixed-size
/// body the compiler turns into byte interleaves), then the tail. Writes
/// every byte of `words`, which holds `2 * lo.len()`.
fn join2(lo: &[u8], hi: &[u8], words: &mut [MaybeUninit<u8>]) {
    const STEP: usize = 16;
    let mut out = words.chunks_exact_mut(2 * STEP);
    let (mut l, mut h) = (lo.chunks_exact(STEP), hi.chunks_exact(STEP));
    for ((o, l), h) in (&mut out).zip(&mut l).zip(&mut h) {
        for i in 0..STEP {
            o[2 * i].write(l[i]);
            o[2 * i + 1].write(h[i]);
        }
    }
    let tail = out.into_remainder();
    for ((o, &l), &h) in tail
        .chunks_exact_mut(2)
        .zip(l.remainder())
        .zip(h.remainder())
    {
        o[0].write(l);
        o[1].write(h);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Join undoes split for every word width the format stores, any
        /// length (the 16-bit path's tail included), and split is the
        /// transpose written out: byte `b` of word `i` lands at
        /// `b * n + i`.
        #[test]
        fn join_undoes_split(
            width in prop::sample::select(vec![1usize, 2, 4, 8]),
            n in 0usize..200,
            seed in any::<u64>(),
        ) {
            let words: Vec<u8> = (0..n * width)
                .map(|i| (seed.wrapping_mul(i as u64 + 1) >> 17) as u8)
                .collect();
            let mut planes = vec![7u8; 3];
            split(&words, width, &mut planes);
            prop_assert_eq!(&planes[..3], &[7u8; 3][..], "split appends");
            let planes = &planes[3..];
            for i in 0..n {
                for b in 0..width {
                    prop_assert_eq!(planes[b * n + i], words[i * width + b]);
                }
            }
            let mut back = vec![9u8; 2];
            join_into(planes, width, &mut back);
            prop_assert_eq!(&back[..2], &[9u8; 2][..], "join appends");
            prop_assert_eq!(&back[2..], &words[..]);
        }
    }

    #[test]
    fn empty_words_of_every_width() {
        for width in [1, 2, 4, 8] {
            let mut planes = Vec::new();
            split(&[], width, &mut planes);
            assert!(planes.is_empty());
            let mut back = Vec::new();
            join_into(&[], width, &mut back);
            assert!(back.is_empty());
        }
    }

    #[test]
    #[should_panic(expected = "whole words")]
    fn join_refuses_partial_words() {
        join_into(&[1, 2, 3], 2, &mut Vec::new());
    }
}
