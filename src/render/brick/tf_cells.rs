//! Cell classes of a brick of a transfer-function file from its 8- or
//! 16-bit words, without the per-cell rule's f64 values and control-point
//! search: the fast path of [`RBrick::from_payload`] for such files.
//!
//! The rule is [`Classification::cell_of_words`]: the code at the cell's
//! minimum corner; else code 0 if any vertex is a code; else a 1-cell
//! when [`TransferFunction::nonzero_on`] holds on the range of the 8
//! rescaled values. That is `opacity(lo) > 0 || opacity(hi) > 0 || some
//! control point of opacity > 0 lies strictly between lo and hi`.
//!
//! When the rescaled values of the value words never fall as the words
//! rise (as unsigned or as signed integers: a positive rescale slope),
//! `lo` and `hi` are the values of the cell's smallest and largest word.
//! So the rule needs, per word, computed once per file and thread from
//! the decoder's own f64 values ([`decode_words`]):
//! - whether the opacity at its value is > 0;
//! - how many positive control points lie below its value, and how many
//!   at or below it.
//!
//! Then the points strictly between `lo` and `hi` number
//! `below[hi] - at_or_below[lo]`. Per brick, the smallest and largest
//! word of each cell come from separable passes over whole rows (x
//! edges, xy faces, cells), as the iso path's OR of sample kinds. Files
//! whose values do not rise with the words (a negative slope), and wider
//! words, take the reference path. A property test checks this path
//! against the reference decoder bit for bit (render/brick/decode.rs).
//!
//! [`Classification::cell_of_words`]: crate::classify::Classification::cell_of_words
//! [`TransferFunction::nonzero_on`]: crate::classify::TransferFunction::nonzero_on
//! [`decode_words`]: crate::format::brick::decode_words

use crate::classify::Classification;
use crate::format::brick::{decode_words, SampleTable, Values, SAMPLE_CODE};
use crate::format::Header;

use super::samples::Samples;
use super::{to_f32, Codes, Planes, RBrick};

use super::samples::rising_flip;
use crate::render::traverse::OBJECT;

/// What a [`TfWords`] is built from: the storage, code encoding, rescale
/// and classification of a file.
type Key = (
    crate::input::Dtype,
    crate::format::CodeEncoding,
    [u64; 2],
    Classification,
);

/// The [`Key`] of `h`.
fn key(h: &Header) -> Key {
    (
        h.storage,
        h.codes,
        [h.rescale.slope, h.rescale.intercept].map(f64::to_bits),
        h.classification.clone(),
    )
}

/// Brick `id` of a file classified by a transfer function from its
/// decompressed payload `raw`, as [`RBrick::from_payload`] gives it:
/// codes by the per-word tables, values in f32 through the decoder's
/// [`SampleTable`], then the planes `planes` asks for. `None` for files
/// whose words the tables cannot take (module docs): the reference
/// decoder then reads them.
pub(super) fn decode(
    h: &Header,
    id: u64,
    no_object: bool,
    raw: &[u8],
    planes: Planes,
) -> Option<RBrick> {
    let mut b = RBrick::uniform(h, id, 0);
    let samples = b.cells.map(|c| (c + 1) as usize);
    let n = samples.iter().product();
    let mut plane = Vec::with_capacity(b.cells.iter().product::<u32>() as usize);
    let done = TF.with_borrow_mut(|f| {
        let key = key(h);
        if f.built_for.as_ref() != Some(&key) {
            f.words = TfWords::new(h);
            f.table = f
                .words
                .as_ref()
                .and_then(|_| SampleTable::new(h, None, to_f32));
            f.built_for = Some(key);
        }
        let (Some(w), Some(t)) = (&f.words, &f.table) else {
            return false;
        };
        if no_object {
            t.corner_codes(raw, samples, &mut plane);
            return true;
        }
        let mut v = Vec::new();
        t.decode(raw, n, &mut f.kinds, &mut f.codes, &mut v);
        w.classify(raw, samples, &f.kinds, &f.codes, &mut f.scratch, &mut plane);
        b.values = Samples::F32(v);
        true
    });
    if !done {
        return None;
    }
    b.codes = Codes::Plane(plane);
    b.add_planes(h, id, raw, planes);
    Some(b)
}

/// Per-thread tables and buffers of [`decode`].
#[derive(Default)]
struct TfScratch {
    /// The file the tables are for (built, or found unusable, once).
    built_for: Option<Key>,
    words: Option<TfWords>,
    table: Option<SampleTable>,
    kinds: Vec<u8>,
    codes: Vec<u8>,
    scratch: Scratch,
}

thread_local! {
    static TF: std::cell::RefCell<TfScratch> = std::cell::RefCell::new(TfScratch::default());
}

/// Per word (its native-endian bits as the index) what the cell rule
/// needs of it; see the module docs.
struct TfWords {
    /// XORed into a word to make its order an unsigned one (0, or the
    /// sign bit when the values rise with the words as signed integers).
    flip: u16,
    /// Opacity at the word's value > 0 (false for code words).
    positive: Vec<bool>,
    /// Positive control points below the word's value.
    below: Vec<u32>,
    /// Positive control points at or below the word's value.
    at_or_below: Vec<u32>,
}

impl TfWords {
    /// The table of `h`'s words: `None` unless the file is classified by
    /// a transfer function, its words have at most 16 bits, and the
    /// values of its value words rise with the words (module docs).
    fn new(h: &Header) -> Option<TfWords> {
        let Classification::TransferFunction { tf } = &h.classification else {
            return None;
        };
        let size = h.storage.size();
        if size > 2 {
            return None;
        }
        let len = 1usize << (8 * size);
        // Every word, in index order: index i's native-endian bytes.
        let bytes: Vec<u8> = (0..len)
            .flat_map(|i| (i as u16).to_ne_bytes().into_iter().take(size))
            .collect();
        let (mut vals, mut codes) = (Vec::new(), Vec::new());
        decode_words(h, &bytes, len, Values::Rescaled, &mut vals, &mut codes);
        if (0..len).any(|i| codes[i].is_none() && vals[i].is_nan()) {
            return None;
        }
        let flip = rising_flip(len, |i| codes[i].is_none().then_some(vals[i]))?;
        let mut points: Vec<f64> = tf
            .points
            .iter()
            .filter(|p| p.opacity > 0.0 && !p.value.is_nan())
            .map(|p| p.value)
            .collect();
        points.sort_by(f64::total_cmp);
        let value = |i: usize| codes[i].is_none().then_some(vals[i]);
        Some(TfWords {
            flip,
            positive: (0..len)
                .map(|i| value(i).is_some_and(|v| tf.opacity(v) > 0.0))
                .collect(),
            below: (0..len)
                .map(|i| value(i).map_or(0, |v| points.partition_point(|&p| p < v) as u32))
                .collect(),
            at_or_below: (0..len)
                .map(|i| value(i).map_or(0, |v| points.partition_point(|&p| p <= v) as u32))
                .collect(),
        })
    }

    /// Whether a cell whose smallest and largest value words are `lo`
    /// and `hi` is a 1-cell (`TransferFunction::nonzero_on`).
    #[inline(always)]
    fn object(&self, lo: usize, hi: usize) -> bool {
        self.positive[lo] || self.positive[hi] || self.below[hi] > self.at_or_below[lo]
    }

    /// The code plane of a brick with `samples` per axis: `kinds` and
    /// `codes` per sample as [`SampleTable::decode`] gives them (iso
    /// `None`), `raw` its words. `keys`, `lo_*` and `hi_*` are scratch.
    ///
    /// [`SampleTable::decode`]: crate::format::brick::SampleTable::decode
    fn classify(
        &self,
        raw: &[u8],
        samples: [usize; 3],
        kinds: &[u8],
        codes: &[u8],
        s: &mut Scratch,
        plane: &mut Vec<u8>,
    ) {
        let [sx, sy, sz] = samples;
        let (cx, cy, cz) = (sx - 1, sy - 1, sz - 1);
        let n = sx * sy * sz;
        // Each word's place in the rising order.
        s.keys.clear();
        if self.positive.len() == 256 {
            s.keys
                .extend(raw[..n].iter().map(|&b| b as u16 ^ self.flip));
        } else {
            s.keys.extend(
                raw[..2 * n]
                    .chunks_exact(2)
                    .map(|b| u16::from_ne_bytes([b[0], b[1]]) ^ self.flip),
            );
        }
        // OR of the kinds, smallest and largest key: x edges, per row...
        let (or_x, lo_x, hi_x) = (&mut s.or_x, &mut s.lo_x, &mut s.hi_x);
        or_x.clear();
        lo_x.clear();
        hi_x.clear();
        for (k, w) in kinds.chunks_exact(sx).zip(s.keys.chunks_exact(sx)) {
            or_x.extend(k.windows(2).map(|p| p[0] | p[1]));
            lo_x.extend(w.windows(2).map(|p| p[0].min(p[1])));
            hi_x.extend(w.windows(2).map(|p| p[0].max(p[1])));
        }
        // ... xy faces, per slice...
        let (or_xy, lo_xy, hi_xy) = (&mut s.or_xy, &mut s.lo_xy, &mut s.hi_xy);
        or_xy.clear();
        lo_xy.clear();
        hi_xy.clear();
        for z in 0..sz {
            let sl = z * sy * cx..(z + 1) * sy * cx;
            let (o, l, h) = (&or_x[sl.clone()], &lo_x[sl.clone()], &hi_x[sl]);
            for y in 0..cy {
                let (r0, r1) = (y * cx..(y + 1) * cx, (y + 1) * cx..(y + 2) * cx);
                or_xy.extend(o[r0.clone()].iter().zip(&o[r1.clone()]).map(|(a, b)| a | b));
                lo_xy.extend(
                    l[r0.clone()]
                        .iter()
                        .zip(&l[r1.clone()])
                        .map(|(a, b)| *a.min(b)),
                );
                hi_xy.extend(h[r0].iter().zip(&h[r1]).map(|(a, b)| *a.max(b)));
            }
        }
        // ... cells: the class.
        let face = cy * cx;
        for z in 0..cz {
            let (s0, s1) = (z * face..(z + 1) * face, (z + 1) * face..(z + 2) * face);
            let (o0, o1) = (&or_xy[s0.clone()], &or_xy[s1.clone()]);
            let (l0, l1) = (&lo_xy[s0.clone()], &lo_xy[s1.clone()]);
            let (h0, h1) = (&hi_xy[s0], &hi_xy[s1]);
            for y in 0..cy {
                let r = y * cx..(y + 1) * cx;
                let corner = &codes[(z * sy + y) * sx..(z * sy + y) * sx + cx];
                for (i, &c) in (r.start..r.end).zip(corner) {
                    let code = (o0[i] | o1[i]) & SAMPLE_CODE != 0;
                    plane.push(if code {
                        // The corner's code, or 0 for a value there.
                        c
                    } else {
                        let lo = (l0[i].min(l1[i]) ^ self.flip) as usize;
                        let hi = (h0[i].max(h1[i]) ^ self.flip) as usize;
                        if self.object(lo, hi) {
                            OBJECT
                        } else {
                            0
                        }
                    });
                }
            }
        }
    }
}

/// Per-thread buffers of [`TfWords::classify`].
#[derive(Default)]
struct Scratch {
    keys: Vec<u16>,
    or_x: Vec<u8>,
    lo_x: Vec<u16>,
    hi_x: Vec<u16>,
    or_xy: Vec<u8>,
    lo_xy: Vec<u16>,
    hi_xy: Vec<u16>,
}
