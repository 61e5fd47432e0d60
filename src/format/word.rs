//! Stored sample words and the distance codes embedded in them.

use super::CodeEncoding;
use crate::input::Dtype;

/// Payload flag of a float code word (f32: bit 21 of the 22 payload bits;
/// f64 uses bit 50). A NaN with this bit set is a code, any other NaN is a
/// missing sample.
pub const NAN_CODE_FLAG: u64 = 1 << 21;
const F32_QNAN: u32 = 0x7fc0_0000;
const F64_QNAN: u64 = 0x7ff8_0000_0000_0000;
const F64_CODE_FLAG: u64 = 1 << 50;

/// A stored sample word type.
pub trait Word: bytemuck::Pod + Send + Sync + PartialEq + std::fmt::Debug {
    const DTYPE: Dtype;
    /// The word holding raw value `v` (exact for values of this type; NaN
    /// becomes the canonical quiet NaN).
    fn from_raw(v: f64) -> Self;
    /// The raw value of a word that is not a code.
    fn to_raw(self) -> f64;
    /// The word that stores code `n` (already saturated).
    fn code(enc: &CodeEncoding, n: u32) -> Self;
    /// The code stored in this word, if it is a code word.
    fn as_code(self, enc: &CodeEncoding) -> Option<u32>;
}

macro_rules! int_word {
    ($t:ty, $d:expr) => {
        impl Word for $t {
            const DTYPE: Dtype = $d;
            #[inline]
            fn from_raw(v: f64) -> Self {
                v as $t
            }
            #[inline]
            fn to_raw(self) -> f64 {
                self as f64
            }
            #[inline]
            fn code(enc: &CodeEncoding, n: u32) -> Self {
                match *enc {
                    CodeEncoding::IntRange { base, .. } => (base + n as i64) as $t,
                    CodeEncoding::NanPayload { .. } => {
                        unreachable!("float encoding on integer words")
                    }
                }
            }
            #[inline]
            fn as_code(self, enc: &CodeEncoding) -> Option<u32> {
                match *enc {
                    CodeEncoding::IntRange { base, max } => {
                        let d = (self as i64).wrapping_sub(base);
                        (0..=max as i64).contains(&d).then_some(d as u32)
                    }
                    CodeEncoding::NanPayload { .. } => None,
                }
            }
        }
    };
}

int_word!(u8, Dtype::U8);
int_word!(i8, Dtype::I8);
int_word!(u16, Dtype::U16);
int_word!(i16, Dtype::I16);
int_word!(u32, Dtype::U32);
int_word!(i32, Dtype::I32);
int_word!(i64, Dtype::I64);

impl Word for f32 {
    const DTYPE: Dtype = Dtype::F32;
    #[inline]
    fn from_raw(v: f64) -> Self {
        if v.is_nan() {
            f32::from_bits(F32_QNAN)
        } else {
            v as f32
        }
    }
    #[inline]
    fn to_raw(self) -> f64 {
        self as f64
    }
    #[inline]
    fn code(_: &CodeEncoding, n: u32) -> Self {
        f32::from_bits(F32_QNAN | NAN_CODE_FLAG as u32 | n)
    }
    #[inline]
    fn as_code(self, _: &CodeEncoding) -> Option<u32> {
        let b = self.to_bits();
        let flag = F32_QNAN | NAN_CODE_FLAG as u32;
        (b & 0xffe0_0000 == flag).then_some(b & 0x001f_ffff)
    }
}

impl Word for f64 {
    const DTYPE: Dtype = Dtype::F64;
    #[inline]
    fn from_raw(v: f64) -> Self {
        if v.is_nan() {
            f64::from_bits(F64_QNAN)
        } else {
            v
        }
    }
    #[inline]
    fn to_raw(self) -> f64 {
        self
    }
    #[inline]
    fn code(_: &CodeEncoding, n: u32) -> Self {
        f64::from_bits(F64_QNAN | F64_CODE_FLAG | n as u64)
    }
    #[inline]
    fn as_code(self, _: &CodeEncoding) -> Option<u32> {
        let b = self.to_bits();
        let flag = F64_QNAN | F64_CODE_FLAG;
        (b & 0xfffc_0000_0000_0000 == flag).then_some((b & 0xffff_ffff) as u32)
    }
}

/// Runs `$body` with `$W` bound to the word type of `$dtype`.
#[macro_export]
#[doc(hidden)]
macro_rules! with_word {
    ($dtype:expr, $W:ident => $body:expr) => {
        match $dtype {
            $crate::input::Dtype::U8 => {
                type $W = u8;
                $body
            }
            $crate::input::Dtype::I8 => {
                type $W = i8;
                $body
            }
            $crate::input::Dtype::U16 => {
                type $W = u16;
                $body
            }
            $crate::input::Dtype::I16 => {
                type $W = i16;
                $body
            }
            $crate::input::Dtype::U32 => {
                type $W = u32;
                $body
            }
            $crate::input::Dtype::I32 => {
                type $W = i32;
                $body
            }
            $crate::input::Dtype::I64 => {
                type $W = i64;
                $body
            }
            $crate::input::Dtype::F32 => {
                type $W = f32;
                $body
            }
            $crate::input::Dtype::F64 => {
                type $W = f64;
                $body
            }
        }
    };
}

/// Fewest codes worth keeping in the input type; with less free range the
/// words are widened (docs/FORMAT.md, "Code embedding").
pub const MIN_CODES: i64 = 64;
/// Codes come from an 8-bit transform: 0..=254 (255 means "far").
pub const MAX_CODE: u32 = 254;

/// Chooses the stored word type and code encoding for an input type and
/// its observed raw range (NaN excluded; `None` when every sample is NaN).
pub fn choose_encoding(dtype: Dtype, range: Option<(f64, f64)>) -> (Dtype, CodeEncoding) {
    if dtype.is_float() {
        return (dtype, CodeEncoding::NanPayload { max: MAX_CODE });
    }
    let mut storage = dtype;
    loop {
        let (tmin, tmax) = storage.int_range();
        let (dmin, dmax) = range.map_or((tmin, tmin), |(a, b)| (a as i64, b as i64));
        let below = dmin.saturating_sub(tmin);
        let above = tmax.saturating_sub(dmax);
        let (base, gap) = if above >= below {
            (dmax + 1, above)
        } else {
            (tmin, below)
        };
        if gap >= MIN_CODES || storage == Dtype::I64 {
            let max = (gap - 1).clamp(0, MAX_CODE as i64) as u32;
            return (storage, CodeEncoding::IntRange { base, max });
        }
        storage = storage.widened();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip<W: Word>(enc: CodeEncoding, values: &[f64]) {
        for n in 0..=enc.max_code() {
            assert_eq!(W::code(&enc, n).as_code(&enc), Some(n));
        }
        for &v in values {
            let w = W::from_raw(v);
            assert_eq!(w.as_code(&enc), None, "{v} read as a code");
            let back = w.to_raw();
            assert!(back == v || (v.is_nan() && back.is_nan()), "{v} -> {back}");
        }
    }

    #[test]
    fn codes_never_collide_with_values() {
        // u8 using the whole range: widened.
        let (s, e) = choose_encoding(Dtype::U8, Some((0.0, 255.0)));
        assert_eq!(s, Dtype::I16);
        roundtrip::<i16>(e, &[0.0, 255.0, 128.0]);
        // CT in i16: codes below the data.
        let (s, e) = choose_encoding(Dtype::I16, Some((-1024.0, 3071.0)));
        assert_eq!(s, Dtype::I16);
        roundtrip::<i16>(e, &[-1024.0, 3071.0, 0.0]);
        // u16 using the whole range: widened.
        let (s, e) = choose_encoding(Dtype::U16, Some((0.0, 65535.0)));
        assert_eq!(s, Dtype::I32);
        roundtrip::<i32>(e, &[0.0, 65535.0]);
        let (s, e) = choose_encoding(Dtype::I32, Some((i32::MIN as f64, i32::MAX as f64)));
        assert_eq!(s, Dtype::I64);
        roundtrip::<i64>(e, &[i32::MIN as f64, i32::MAX as f64]);
        let (_, e) = choose_encoding(Dtype::F32, Some((0.0, 1.0)));
        roundtrip::<f32>(
            e,
            &[
                0.0,
                -0.0,
                f64::NAN,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f32::from_bits(1) as f64,
                f32::MAX as f64,
            ],
        );
        roundtrip::<f64>(
            e,
            &[0.0, f64::NAN, f64::INFINITY, f64::MIN_POSITIVE, -1e300],
        );
        // Small free range: codes saturate lower but stay in the type.
        let (s, e) = choose_encoding(Dtype::U8, Some((0.0, 155.0)));
        assert_eq!((s, e.max_code()), (Dtype::U8, 99));
    }
}
