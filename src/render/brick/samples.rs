//! A decoded brick's sample values, as f32 or as the stored words.
//!
//! Files of 8- or 16-bit words (most CT and MRI series) keep each brick's
//! words as decoded and look a value up in the file's table of every
//! word's value ([`SampleTable`](crate::format::brick::SampleTable), the
//! decoder's own): half the memory of f32 values for 16-bit words, a
//! quarter for 8-bit ones, and no f32 plane to write when a brick is
//! decoded. The table is built by the same per-word rule as the f32
//! plane, so every lookup gives the f32 plane's bits (NaN for code
//! words) and images do not change. Wider words, transfer-function files
//! (whose composite reads every value it samples), and bricks whose values
//! the renderer rewrites or derives planes from hold f32.
//! docs/BENCHMARKS.md, "Values as stored words".

use std::borrow::Cow;
use std::sync::Arc;

/// A brick's sample values, `(cells + 1)` per axis, x fastest.
#[derive(Clone, Default)]
pub enum Samples {
    /// No values: a brick without 1-cells.
    #[default]
    Empty,
    /// Values in f32 (NaN where a word held a code).
    F32(Vec<f32>),
    /// 8-bit words, the value of each of the 256 words, and the order
    /// in which the values rise.
    Words8(Vec<u8>, Arc<[f32; 256]>, Order),
    /// 16-bit words (native-endian bits), the value of each word, and the
    /// order in which the values rise.
    Words16(Vec<u16>, Arc<[f32; 65536]>, Order),
}

/// In which order of the words, taken as integers, a table's values
/// (NaN left out) never fall: then the largest word of a cell has its
/// largest value, one lookup instead of eight ([`Samples::top`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    /// The words' bits as unsigned integers.
    Unsigned,
    /// The words' bits as two's-complement integers.
    Signed,
    /// Neither (a negative rescale slope, for one).
    None,
}

impl Order {
    /// The order of `table` (256 or 65536 entries, indexed by the words'
    /// bits).
    pub fn of(table: &[f32]) -> Order {
        let v = |i: usize| Some(table[i]).filter(|v| !v.is_nan());
        match rising_flip(table.len(), v) {
            Some(0) => Order::Unsigned,
            Some(_) => Order::Signed,
            None => Order::None,
        }
    }

    /// The key under which word `w` (its bits, `bits` wide) sorts in
    /// this order as an unsigned integer.
    #[inline(always)]
    fn key(self, w: u16, bits: u32) -> u16 {
        match self {
            Order::Signed => w ^ (1 << (bits - 1)),
            _ => w,
        }
    }
}

/// What to XOR into a word (`len` = 256 or 65536 words, indexed by their
/// bits) so that the values `value` gives (`None` left out) never fall as
/// the result rises as an unsigned integer: 0 (unsigned order) or the
/// sign bit (two's-complement order); `None` when neither holds. Shared
/// by [`Order::of`] and the transfer-function tables (render/brick/tf_cells.rs).
pub fn rising_flip<V: PartialOrd + Copy>(
    len: usize,
    value: impl Fn(usize) -> Option<V>,
) -> Option<u16> {
    let sign = (len / 2) as u16;
    let rising = |flip: u16| {
        let mut last: Option<V> = None;
        (0..len)
            .filter_map(|k| value((k as u16 ^ flip) as usize))
            .all(|v| last.replace(v).is_none_or(|l| l <= v))
    };
    [0, sign].into_iter().find(|&f| rising(f))
}

/// The shared table of a file's word values, in the shape [`Samples`]
/// keeps it: built once per table, cloned per brick.
#[derive(Clone)]
pub enum WordValues {
    W8(Arc<[f32; 256]>, Order),
    W16(Arc<[f32; 65536]>, Order),
}

impl WordValues {
    /// The table `values` (256 or 65536 entries) in array form, with its
    /// order; `None` for any other length.
    pub fn of(values: &Arc<[f32]>) -> Option<WordValues> {
        let order = Order::of(values);
        match values.len() {
            256 => Arc::clone(values)
                .try_into()
                .ok()
                .map(|t| WordValues::W8(t, order)),
            65536 => Arc::clone(values)
                .try_into()
                .ok()
                .map(|t| WordValues::W16(t, order)),
            _ => None,
        }
    }
}

impl std::fmt::Debug for Samples {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = match self {
            Samples::Empty => "none",
            Samples::F32(_) => "f32",
            Samples::Words8(..) => "8-bit words",
            Samples::Words16(..) => "16-bit words",
        };
        write!(f, "Samples({} x {kind})", self.len())
    }
}

/// One word's value from its table (`N` is 256 for `u8` words and
/// 65536 for `u16` ones, so the mask is a no-op and the load unchecked).
#[inline(always)]
fn look<W: Into<usize>, const N: usize>(t: &[f32; N], w: W) -> f32 {
    t[w.into() & (N - 1)]
}

impl Samples {
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        match self {
            Samples::Empty => 0,
            Samples::F32(v) => v.len(),
            Samples::Words8(w, ..) => w.len(),
            Samples::Words16(w, ..) => w.len(),
        }
    }

    /// Bytes of the samples themselves (the shared table not counted).
    pub fn bytes(&self) -> usize {
        match self {
            Samples::Empty => 0,
            Samples::F32(v) => v.len() * 4,
            Samples::Words8(w, ..) => w.len(),
            Samples::Words16(w, ..) => w.len() * 2,
        }
    }

    /// Value of sample `i`.
    #[inline(always)]
    pub fn get(&self, i: usize) -> f32 {
        match self {
            Samples::Empty => panic!("sample {i} of a brick without values"),
            Samples::F32(v) => v[i],
            Samples::Words8(w, t, _) => look(t, w[i]),
            Samples::Words16(w, t, _) => look(t, w[i]),
        }
    }

    /// The values at the 8 vertices `c` (x fastest).
    #[inline(always)]
    pub fn gather(&self, c: Corners) -> [f32; 8] {
        match self {
            Samples::Empty => panic!("vertices of a brick without values"),
            Samples::F32(v) => gather8(v, c, |x| x),
            Samples::Words8(w, t, _) => gather8(w, c, |x| look(t, x)),
            Samples::Words16(w, t, _) => gather8(w, c, |x| look(t, x)),
        }
    }

    /// An upper bound of the values at the 8 vertices `c`: their
    /// largest (NaN left out; `-inf` if all are NaN), or NaN (no bound
    /// known) when the largest word of an ordered table is a code word.
    /// For words in [`Order`], the value of the largest word.
    #[inline(always)]
    pub fn top(&self, c: Corners) -> f32 {
        // The word of the largest key, and its value.
        fn largest<W: Copy + Into<u16>>(g: [W; 8], o: Order, bits: u32) -> W {
            let mut best = g[0];
            for &x in &g[1..] {
                if o.key(x.into(), bits) > o.key(best.into(), bits) {
                    best = x;
                }
            }
            best
        }
        match self {
            Samples::Words8(w, t, o) if *o != Order::None => {
                look(t, largest(gather8(w, c, |x| x), *o, 8))
            }
            Samples::Words16(w, t, o) if *o != Order::None => {
                look(t, largest(gather8(w, c, |x| x), *o, 16))
            }
            _ => self
                .gather(c)
                .iter()
                .fold(f32::NEG_INFINITY, |m, &x| m.max(x)),
        }
    }

    /// `out[to[k]]` = the value of sample `from[k]`, for every `k`: many
    /// samples, one dispatch on the representation.
    #[inline(always)]
    pub fn gather_into<const N: usize>(&self, from: [usize; N], to: [usize; N], out: &mut [f32]) {
        match self {
            Samples::Empty => panic!("samples of a brick without values"),
            Samples::F32(v) => from.iter().zip(to).for_each(|(&i, o)| out[o] = v[i]),
            Samples::Words8(w, t, _) => from
                .iter()
                .zip(to)
                .for_each(|(&i, o)| out[o] = look(t, w[i])),
            Samples::Words16(w, t, _) => from
                .iter()
                .zip(to)
                .for_each(|(&i, o)| out[o] = look(t, w[i])),
        }
    }

    /// All values in f32: borrowed when already f32.
    pub fn to_f32(&self) -> Cow<'_, [f32]> {
        match self {
            Samples::Empty => Cow::Borrowed(&[]),
            Samples::F32(v) => Cow::Borrowed(v),
            Samples::Words8(w, t, _) => Cow::Owned(w.iter().map(|&x| look(t, x)).collect()),
            Samples::Words16(w, t, _) => Cow::Owned(w.iter().map(|&x| look(t, x)).collect()),
        }
    }

    /// The values as an f32 plane to rewrite (converted first if they
    /// are words).
    pub fn make_f32(&mut self) -> &mut Vec<f32> {
        if !matches!(self, Samples::F32(_)) {
            *self = Samples::F32(self.to_f32().into_owned());
        }
        match self {
            Samples::F32(v) => v,
            _ => unreachable!("converted above"),
        }
    }
}

/// A cell's 8 vertices in a plane of samples, x fastest: sample `base`
/// (the minimum corner) and the steps `sx` (one row) and `z` (one
/// slice) to the others.
#[derive(Clone, Copy, Debug)]
pub struct Corners {
    pub base: usize,
    pub sx: usize,
    pub z: usize,
}

impl Corners {
    /// The vertices' sample indices, x fastest; the last is the largest.
    #[inline(always)]
    pub fn indices(self) -> [usize; 8] {
        let Corners { base: b, sx, z } = self;
        [
            b,
            b + 1,
            b + sx,
            b + sx + 1,
            b + z,
            b + z + 1,
            b + z + sx,
            b + z + sx + 1,
        ]
    }
}

/// `f` of the entries of `v` at the 8 vertices `c`, written out (`[T;
/// 8]::map` is not always inlined, and this is on every cell a ray
/// samples), with one bounds check for all eight instead of one each.
///
/// Panics if a vertex lies beyond `v`.
#[inline(always)]
pub fn gather8<T: Copy, U, F: Fn(T) -> U>(v: &[T], c: Corners, f: F) -> [U; 8] {
    gather8_ref(v, c, |x| f(*x))
}

/// [`gather8`] with `f` reading each entry through a reference (for
/// entries that are not `Copy`, such as atomics).
#[inline(always)]
pub fn gather8_ref<T, U, F: Fn(&T) -> U>(v: &[T], c: Corners, f: F) -> [U; 8] {
    // The largest index, saturating: a sum that would wrap fails the check.
    let last = c
        .base
        .saturating_add(c.z)
        .saturating_add(c.sx)
        .saturating_add(1);
    assert!(last < v.len(), "vertex {last} of a plane of {}", v.len());
    // SAFETY: every index below is at most `base + z + sx + 1 = last`,
    // computed without wrapping (it did not saturate, as `last < len`),
    // and `last < v.len()`.
    let at = |i: usize| f(unsafe { v.get_unchecked(i) });
    let [i0, i1, i2, i3, i4, i5, i6, i7] = c.indices();
    [
        at(i0),
        at(i1),
        at(i2),
        at(i3),
        at(i4),
        at(i5),
        at(i6),
        at(i7),
    ]
}

#[cfg(test)]
mod tests {
    //! Every way of reading a brick's samples gives the table's values,
    //! bit for bit, in every representation.
    use super::*;
    use proptest::prelude::*;

    /// The same samples as f32, 8-bit words and 16-bit words (the 16-bit
    /// word `w << 8 | 3` has the value of 8-bit word `w`, so the tables
    /// rise in the same orders).
    fn three(words: &[u8], table: &[f32]) -> [Samples; 3] {
        let t8: [f32; 256] = std::array::from_fn(|i| table[i]);
        let t16: Vec<f32> = (0..65536).map(|i| table[i >> 8]).collect();
        let t16: Arc<[f32; 65536]> = Arc::<[f32]>::from(t16).try_into().expect("65536");
        [
            Samples::F32(words.iter().map(|&w| t8[w as usize]).collect()),
            Samples::Words8(words.to_vec(), Arc::new(t8), Order::of(&t8)),
            Samples::Words16(
                words.iter().map(|&w| (w as u16) << 8 | 3).collect(),
                t16.clone(),
                Order::of(&t16[..]),
            ),
        ]
    }

    #[test]
    #[should_panic(expected = "vertex 7 of a plane of 7")]
    fn a_vertex_beyond_the_plane_is_refused() {
        // base 1, row 2, slice 3: the last vertex is sample 7 of 0..7.
        gather8(
            &[0u8; 7],
            Corners {
                base: 1,
                sx: 2,
                z: 3,
            },
            |x| x,
        );
    }

    #[test]
    #[should_panic(expected = "vertex 18446744073709551615")]
    fn a_wrapping_vertex_is_refused() {
        gather8(
            &[0u8; 8],
            Corners {
                base: usize::MAX - 2,
                sx: 1,
                z: 1,
            },
            |x| x,
        );
    }

    proptest! {
        #[test]
        fn representations_read_alike(
            words in proptest::collection::vec(any::<u8>(), 8..200),
            table in proptest::collection::vec(
                prop_oneof![any::<f32>(), Just(f32::NAN), Just(-0.0f32)], 256),
            base in any::<prop::sample::Index>(),
            sx in 0usize..3,
            z in 0usize..5,
            shape in 0usize..3,
        ) {
            // Random, rising with the words unsigned, or rising with them
            // signed (NaN for code words anywhere).
            let mut table = table;
            if shape > 0 {
                let mut v: Vec<f32> = table.iter().copied().filter(|x| !x.is_nan()).collect();
                v.sort_by(f32::total_cmp);
                let mut v = v.into_iter();
                let order: Vec<usize> = match shape {
                    1 => (0..256).collect(),
                    _ => (128..256).chain(0..128).collect(),
                };
                for i in order {
                    if !table[i].is_nan() {
                        table[i] = v.next().expect("as many as left out");
                    }
                }
            }
            let n = words.len();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            let reps = three(&words, &table);
            let want = bits(&reps[0].to_f32());
            let c = Corners { base: base.index(n - (z + sx + 1)), sx, z };
            let idx = c.indices();
            // The vertices x fastest, written out here rather than taken
            // from `indices` alone.
            let b = c.base;
            prop_assert_eq!(idx, [b, b + 1, b + sx, b + sx + 1, b + z, b + z + 1, b + z + sx, b + z + sx + 1]);
            for mut s in reps {
                prop_assert_eq!(s.len(), n);
                prop_assert_eq!(bits(&s.to_f32()), want.clone());
                let each: Vec<f32> = (0..n).map(|i| s.get(i)).collect();
                prop_assert_eq!(bits(&each), want.clone());
                let g = s.gather(c);
                prop_assert_eq!(bits(&g), idx.map(|i| want[i]).to_vec());
                let mut out = [0.0f32; 8];
                s.gather_into(idx, [7, 6, 5, 4, 3, 2, 1, 0], &mut out);
                let rev: Vec<u32> = (0..8).map(|k| want[idx[7 - k]]).collect();
                prop_assert_eq!(bits(&out), rev);
                // The bound: the largest value, or NaN from an ordered
                // table's largest word.
                let vals = idx.map(|i| want[i]).map(f32::from_bits);
                let fold = vals.iter().fold(f32::NEG_INFINITY, |m, &x| m.max(x));
                let top = s.top(c);
                let ordered = match &s {
                    Samples::Words8(_, _, o) | Samples::Words16(_, _, o) => *o != Order::None,
                    _ => false,
                };
                prop_assert!(top == fold || (top.is_nan() && ordered), "{} {}", top, fold);
                if shape > 0 && !matches!(s, Samples::F32(_)) {
                    prop_assert!(ordered);
                }
                prop_assert_eq!(bits(s.make_f32()), want.clone());
                prop_assert!(matches!(s, Samples::F32(_)));
            }
        }
    }
}
