//! Tests of brick.rs: the fast decode against the reference path, and
//! the planes built on a decoded brick.

use super::{Codes, Planes, RBrick, Samples, OBJECT};
use crate::classify::{Classification, TfPoint, TransferFunction};
use crate::format::word::Word;
use crate::format::{CodeEncoding, Header};
use crate::input::{Dtype, Rescale};
use proptest::prelude::*;

/// A one-brick file's header: `dims` samples, words of `storage`.
fn header(
    storage: Dtype,
    codes: CodeEncoding,
    rescale: Rescale,
    iso: f64,
    dims: [u64; 3],
) -> Header {
    let axis = |n: u64| crate::grid::Axis::uniform(0.0, 1.0, n as usize).expect("axis");
    Header {
        format_version: 1,
        dims,
        axes: [axis(dims[0]), axis(dims[1]), axis(dims[2])],
        dtype: storage,
        storage,
        rescale,
        classification: Classification::Iso { iso },
        codes,
        brick_size: 32,
        bricks: [1, 1, 1],
        aniso_block: None,
        dda: false,
        gradient_halo: false,
        zstd_level: 3,
        source: String::new(),
        notes: Vec::new(),
        orientation: None,
        input: None,
        modality: None,
        landmarks: None,
        look: None,
        labels: None,
        summary: Default::default(),
    }
}

/// `n` words of type `W` from `pick`: 0..3 a code word (code from the
/// low byte), 4 a special value (for floats NaN, +-inf, a foreign
/// NaN; for integers the type's ends), else the raw bits.
fn words<W: Word>(enc: &CodeEncoding, max: u32, pick: &[(u8, u64)], n: usize) -> Vec<u8> {
    let size = std::mem::size_of::<W>();
    let mut out = Vec::with_capacity(n * size);
    for &(k, bits) in pick.iter().cycle().take(n) {
        let w: W = match k % 8 {
            0..=2 => W::code(enc, (bits % (max as u64 + 1)) as u32),
            3 => W::from_raw(
                [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 0.0, -0.0][bits as usize % 5],
            ),
            _ => bytemuck::pod_read_unaligned(&bits.to_le_bytes()[..size]),
        };
        out.extend_from_slice(bytemuck::bytes_of(&w));
    }
    out
}

/// Storage type `ty` of the nine and a code encoding for it with
/// codes up to `max` (an integer range placed by `base_pick`).
fn storage_of(ty: usize, max: u32, base_pick: u64) -> (Dtype, CodeEncoding) {
    let storage = [
        Dtype::U8,
        Dtype::I8,
        Dtype::U16,
        Dtype::I16,
        Dtype::U32,
        Dtype::I32,
        Dtype::I64,
        Dtype::F32,
        Dtype::F64,
    ][ty];
    let enc = if storage.is_float() {
        CodeEncoding::NanPayload { max }
    } else {
        let (lo, hi) = storage.int_range();
        let span = (hi as i128 - lo as i128 - max as i128).max(1);
        let base = (lo as i128 + (base_pick as i128 % span)) as i64;
        CodeEncoding::IntRange { base, max }
    };
    (storage, enc)
}

/// A brick's code plane (one code for a uniform brick).
fn plane_of(b: &RBrick) -> Vec<u8> {
    match &b.codes {
        Codes::Plane(p) => p.clone(),
        Codes::Uniform(c) => vec![*c],
    }
}

/// A brick's values as f32 bits.
fn value_bits(b: &RBrick) -> Vec<u32> {
    b.values.to_f32().iter().map(|v| v.to_bits()).collect()
}

/// 16-bit tables decode kinds and codes by two range tests wherever
/// the words allow (unsigned and signed words, rising and falling
/// rescales, the iso value below, among and above the values, codes
/// at either end of the words), and give the lookup's bytes for all
/// 65536 words.
#[test]
fn range_tests_equal_the_lookup_for_every_word() {
    use crate::format::brick::SampleTable;
    let cases = [
        (Dtype::U16, 65000, 1.0, 0.0, 300.0),
        (Dtype::U16, 0, 1.0, -1024.0, 300.0),
        (Dtype::I16, -32768, 1.0, 0.0, 300.0),
        (Dtype::I16, 32000, -2.0, 5.0, 300.0),
        (Dtype::I16, 100, 0.5, 0.0, -1e9),
        (Dtype::U16, 1000, 1.0, 0.0, 1e9),
        (Dtype::I16, 0, 1.0, 0.0, -32768.0),
    ];
    let words: Vec<u16> = (0..=u16::MAX).collect();
    let raw: &[u8] = bytemuck::cast_slice(&words);
    for (storage, base, slope, intercept, iso) in cases {
        let enc = CodeEncoding::IntRange { base, max: 300 };
        let h = header(storage, enc, Rescale { slope, intercept }, iso, [2, 2, 2]);
        let t = SampleTable::new(&h, Some(iso), super::to_f32).unwrap();
        assert!(
            t.uses_ranges(),
            "{storage:?} base {base} slope {slope} iso {iso}"
        );
        let decode = |t: &SampleTable| {
            let (mut k, mut c, mut w) = (Vec::new(), Vec::new(), Vec::<u16>::new());
            t.decode_words(raw, words.len(), &mut k, &mut c, &mut w);
            let mut v = Vec::new();
            t.decode(raw, words.len(), &mut k, &mut c, &mut v);
            (k, c, w, v.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
        };
        let slow = SampleTable::new(&h, Some(iso), super::to_f32)
            .unwrap()
            .without_ranges();
        let fast = decode(&t);
        assert!(
            fast.0.contains(&2) && fast.1.contains(&254),
            "codes saturate"
        );
        assert!(fast == decode(&slow), "{storage:?} {slope} {iso}");
        // The cells' minimum-corner codes of a 64 x 32 x 32 brick of all
        // the words.
        let (mut a, mut b) = (Vec::new(), Vec::new());
        t.corner_codes(raw, [64, 32, 32], &mut a);
        slow.corner_codes(raw, [64, 32, 32], &mut b);
        assert_eq!(a.len(), 63 * 31 * 31);
        assert!(a == b, "corner codes, {storage:?} {slope} {iso}");
    }
}

proptest! {
    /// The fast decode equals the reference (decode_words + the
    /// per-cell rule) on random bricks of every storage type: codes,
    /// values bit for bit (NaN included), with and without the
    /// no-1-cell flag, aligned and unaligned payloads. (Checked to
    /// fail with the class rule mutated.)
    #[test]
    fn fast_decode_equals_reference(
        ty in 0usize..9,
        samples in proptest::array::uniform3(2u64..8),
        pick in proptest::collection::vec((any::<u8>(), any::<u64>()), 1..400),
        base_pick in any::<u64>(),
        max in 0u32..=254,
        slope in prop_oneof![Just(1.0), Just(-1.0), Just(0.5), Just(1e30), -4.0f64..4.0],
        intercept in prop_oneof![Just(0.0), Just(-1024.0), -1e3f64..1e3],
        iso_pick in 0usize..400,
        iso_off in prop_oneof![Just(0.0), Just(1e-9), Just(-1e-9), -10.0f64..10.0],
        no_object in any::<bool>(),
        offset in 0usize..2,
        block_max in any::<bool>(),
    ) {
        let (storage, enc) = storage_of(ty, max, base_pick);
        let n = samples.iter().product::<u64>() as usize;
        let payload = crate::with_word!(storage, W => words::<W>(&enc, max, &pick, n));
        let rescale = Rescale { slope, intercept };
        // The iso value near a sample's rescaled value, to hit ties.
        let probe = header(storage, enc, rescale, 0.0, samples);
        let (mut vals, mut codes) = (Vec::new(), Vec::new());
        crate::format::brick::decode_words(&probe, &payload, n, crate::format::brick::Values::Rescaled, &mut vals, &mut codes);
        let v = vals[iso_pick % n];
        let iso = if v.is_finite() { v + iso_off } else { iso_off };
        let h = header(storage, enc, rescale, iso, samples);
        let mut buf = vec![0u8; offset];
        buf.extend_from_slice(&payload);
        let raw = &buf[offset..];
        // Values as words, or (a plane derived from them) in f32.
        let planes = Planes { block_max, ..Planes::NONE };
        let fast = RBrick::from_payload(&h, 0, no_object, raw, planes);
        let slow = RBrick::from_payload_reference(&h, 0, no_object, raw, planes);
        prop_assert_eq!(plane_of(&fast), plane_of(&slow));
        prop_assert_eq!(value_bits(&fast), value_bits(&slow));
        let words = matches!(fast.values, Samples::Words8(..) | Samples::Words16(..));
        prop_assert_eq!(
            words,
            storage.size() <= 2 && !fast.values.is_empty()
        );
        // The same planes but for the width of the values.
        let f32_bytes = |b: &RBrick| b.bytes - b.values.bytes() + 4 * b.values.len();
        prop_assert_eq!(f32_bytes(&fast), slow.bytes);
        prop_assert_eq!(&fast.block_max, &slow.block_max);
    }
}

/// A cell whose largest value sits on a control point with opacity,
/// after a point without: a 1-cell by its top value alone (no point
/// with opacity lies strictly inside its range), which the fast path
/// must see as the reference does.
#[test]
fn tf_cell_by_its_top_value() {
    let enc = CodeEncoding::IntRange { base: 200, max: 50 };
    let rescale = Rescale {
        slope: 1.0,
        intercept: 0.0,
    };
    let mut h = header(Dtype::U8, enc, rescale, 0.0, [2, 2, 2]);
    let point = |value, opacity| TfPoint {
        value,
        opacity,
        color: [1.0; 3],
    };
    h.classification = Classification::TransferFunction {
        tf: TransferFunction {
            points: vec![point(7.0, 0.0), point(10.0, 1.0)],
        },
    };
    for (words, class) in [([5u8, 10], OBJECT), ([5, 6], 0), ([8, 9], OBJECT)] {
        let raw: Vec<u8> = words.iter().copied().cycle().take(8).collect();
        let fast =
            crate::render::brick::tf_cells::decode(&h, 0, false, &raw, Planes::NONE).expect("fast");
        let slow = RBrick::from_payload_reference(&h, 0, false, &raw, Planes::NONE);
        for b in [&fast, &slow] {
            assert!(
                matches!(&b.codes, Codes::Plane(p) if p[..] == [class]),
                "{words:?}"
            );
        }
    }
}

proptest! {
    /// The transfer-function fast path (render/brick/tf_cells.rs) equals
    /// the reference on random bricks of every storage type: codes
    /// and values bit for bit, control points on, just off and between
    /// sample values, zero and positive opacities, both slopes. It
    /// runs whenever the values rise with the words (a slope >= 0 and
    /// words of at most 16 bits).
    #[test]
    fn tf_decode_equals_reference(
        ty in 0usize..9,
        samples in proptest::array::uniform3(2u64..8),
        pick in proptest::collection::vec((any::<u8>(), any::<u64>()), 1..400),
        base_pick in any::<u64>(),
        max in 0u32..=254,
        slope in prop_oneof![Just(1.0), Just(-1.0), Just(0.5), Just(1e30), Just(0.0), -4.0f64..4.0],
        intercept in prop_oneof![Just(0.0), Just(-1024.0), -1e3f64..1e3],
        points in proptest::collection::vec(
            (0usize..400, prop_oneof![Just(0.0), Just(1e-9), Just(-1e-9), -10.0f64..10.0],
             prop_oneof![Just(0.0), Just(0.0), Just(0.5), Just(1.0)]),
            1..6),
        no_object in any::<bool>(),
        offset in 0usize..2,
        few_codes in any::<bool>(),
    ) {
        let (storage, enc) = storage_of(ty, max, base_pick);
        let n = samples.iter().product::<u64>() as usize;
        // Mostly value words, so that many cells are decided by the
        // transfer function (a code word among the 8 decides alone).
        let pick: Vec<(u8, u64)> = pick
            .iter()
            .enumerate()
            .map(|(i, &(k, b))| (if few_codes && i % 16 != 0 { 4 + k % 4 } else { k }, b))
            .collect();
        let payload = crate::with_word!(storage, W => words::<W>(&enc, max, &pick, n));
        let rescale = Rescale { slope, intercept };
        let mut h = header(storage, enc, rescale, 0.0, samples);
        let (mut vals, mut codes) = (Vec::new(), Vec::new());
        crate::format::brick::decode_words(&h, &payload, n, crate::format::brick::Values::Rescaled, &mut vals, &mut codes);
        // Control points at sample values (ties), just off them, or
        // between; strictly increasing.
        let mut tf: Vec<TfPoint> = points
            .iter()
            .map(|&(i, off, opacity)| {
                let v = vals[i % n];
                let value = if v.is_finite() { v + off } else { off };
                TfPoint { value, opacity, color: [1.0; 3] }
            })
            .collect();
        tf.sort_by(|a, b| a.value.total_cmp(&b.value));
        tf.dedup_by(|a, b| a.value == b.value);
        h.classification = Classification::TransferFunction {
            tf: TransferFunction { points: tf },
        };
        let mut buf = vec![0u8; offset];
        buf.extend_from_slice(&payload);
        let raw = &buf[offset..];
        let fast = RBrick::from_payload(&h, 0, no_object, raw, Planes::NONE);
        let slow = RBrick::from_payload_reference(&h, 0, no_object, raw, Planes::NONE);
        prop_assert_eq!(plane_of(&fast), plane_of(&slow));
        prop_assert_eq!(value_bits(&fast), value_bits(&slow));
        prop_assert_eq!(fast.bytes, slow.bytes);
        let ran = crate::render::brick::tf_cells::decode(&h, 0, no_object, raw, Planes::NONE).is_some();
        if storage.size() <= 2 && slope >= 0.0 {
            prop_assert!(ran);
        }
    }
}

proptest! {
    /// Against the definition: each cell's 8 vertices, NaN ignored,
    /// folded into its block's maximum.
    #[test]
    fn block_maxima_bound_each_cells_vertices(
        cells in proptest::array::uniform3(1u32..11),
        seed in proptest::collection::vec(prop_oneof![
            3 => -1e3f32..1e3,
            1 => Just(f32::NAN),
            1 => Just(f32::INFINITY),
            1 => Just(f32::NEG_INFINITY),
        ], 1331),
    ) {
        let [sx, sy, sz] = cells.map(|c| c as usize + 1);
        let values: Vec<f32> = (0..sx * sy * sz).map(|i| seed[i % seed.len()]).collect();
        let got = super::block_maxima(&values, cells);
        let nb = cells.map(|c| c.div_ceil(super::BLOCK) as usize);
        let mut want = vec![f32::NEG_INFINITY; nb[0] * nb[1] * nb[2]];
        for z in 0..sz - 1 {
            for y in 0..sy - 1 {
                for x in 0..sx - 1 {
                    let b = ((z / 4) * nb[1] + y / 4) * nb[0] + x / 4;
                    for d in 0..8 {
                        let v = values[((z + d / 4) * sy + y + d / 2 % 2) * sx + x + d % 2];
                        if v > want[b] {
                            want[b] = v;
                        }
                    }
                }
            }
        }
        prop_assert_eq!(got, want);
    }
}

proptest! {
    /// Every node of the max pyramid against the definition: the largest
    /// vertex value (NaN ignored) over the cells of the aligned node of
    /// `BLOCK << i` cells per axis, clipped to the brick; one level per
    /// power of two from `BLOCK` up to the largest dividing the brick size.
    #[test]
    fn max_pyramid_nodes_bound_their_cells_vertices(
        brick_size in prop_oneof![Just(2u32), Just(4), Just(8), Just(12), Just(16), Just(32)],
        cells_seed in proptest::array::uniform3(1u32..33),
        seed in proptest::collection::vec(prop_oneof![
            6 => -1e3f32..1e3,
            1 => Just(f32::NAN),
            1 => Just(f32::INFINITY),
            1 => Just(f32::NEG_INFINITY),
        ], 1..2000),
    ) {
        // A brick holds at most `brick_size` cells per axis.
        let cells = cells_seed.map(|c| c.min(brick_size));
        let [sx, sy, sz] = cells.map(|c| c as usize + 1);
        let values: Vec<f32> = (0..sx * sy * sz).map(|i| seed[(i * 7919) % seed.len()]).collect();
        let got = super::max_pyramid(super::block_maxima(&values, cells), cells, brick_size);
        let b0 = super::BLOCK.trailing_zeros();
        let top = brick_size.trailing_zeros();
        prop_assert_eq!(got.len(), (top + 1).saturating_sub(b0) as usize);
        for (i, plane) in got.iter().enumerate() {
            let s = b0 + i as u32;
            let n = cells.map(|c| c.div_ceil(1 << s) as usize);
            let mut want = vec![f32::NEG_INFINITY; n[0] * n[1] * n[2]];
            for z in 0..sz - 1 {
                for y in 0..sy - 1 {
                    for x in 0..sx - 1 {
                        let b = ((z >> s) * n[1] + (y >> s)) * n[0] + (x >> s);
                        for d in 0..8 {
                            let v = values[((z + d / 4) * sy + y + d / 2 % 2) * sx + x + d % 2];
                            if v > want[b] {
                                want[b] = v;
                            }
                        }
                    }
                }
            }
            prop_assert_eq!(plane, &want, "level {}", s);
        }
    }
}
