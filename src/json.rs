//! Strict JSON: user files (sidecars, transfer functions, render look
//! keys) must not repeat a key. `serde_json` keeps the last of a repeated
//! key in a `Value` and has no flag to refuse it, so [`duplicate_key`]
//! walks the text once with a visitor that remembers each object's keys.

use std::collections::HashSet;
use std::fmt;

use serde::de::{DeserializeSeed, Deserializer, Error, MapAccess, SeqAccess, Visitor};

/// The path (`x.spacing`, `points[1].opacity`) of the first key an object
/// of `text` repeats, or None. Text that is not JSON gives None: the
/// caller's own parse reports that.
pub fn duplicate_key(text: &str) -> Option<String> {
    let mut de = serde_json::Deserializer::from_str(text);
    match (Walk {
        path: String::new(),
    })
    .deserialize(&mut de)
    {
        Err(e) => {
            let m = e.to_string();
            let m = m.strip_prefix(PREFIX)?;
            // serde_json appends " at line L column C".
            Some(match m.rfind(" at line ") {
                Some(i) => m[..i].to_string(),
                None => m.to_string(),
            })
        }
        Ok(()) => None,
    }
}

const PREFIX: &str = "\u{1}duplicate key ";

struct Walk {
    path: String,
}

impl<'de> DeserializeSeed<'de> for Walk {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk {
    type Value = ();
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("JSON")
    }
    fn visit_bool<E: Error>(self, _: bool) -> Result<(), E> {
        Ok(())
    }
    fn visit_i64<E: Error>(self, _: i64) -> Result<(), E> {
        Ok(())
    }
    fn visit_u64<E: Error>(self, _: u64) -> Result<(), E> {
        Ok(())
    }
    fn visit_f64<E: Error>(self, _: f64) -> Result<(), E> {
        Ok(())
    }
    fn visit_str<E: Error>(self, _: &str) -> Result<(), E> {
        Ok(())
    }
    fn visit_unit<E: Error>(self) -> Result<(), E> {
        Ok(())
    }
    fn visit_none<E: Error>(self) -> Result<(), E> {
        Ok(())
    }
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<(), A::Error> {
        let mut i = 0usize;
        while seq
            .next_element_seed(Walk {
                path: format!("{}[{i}]", self.path),
            })?
            .is_some()
        {
            i += 1;
        }
        Ok(())
    }
    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<(), A::Error> {
        let mut seen = HashSet::new();
        while let Some(k) = map.next_key::<String>()? {
            let path = if self.path.is_empty() {
                k.clone()
            } else {
                format!("{}.{k}", self.path)
            };
            if !seen.insert(k) {
                return Err(A::Error::custom(format!("{PREFIX}{path}")));
            }
            map.next_value_seed(Walk { path })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::duplicate_key;

    #[test]
    fn finds_the_first_repeated_key_with_its_path() {
        assert_eq!(duplicate_key(r#"{"a": 1, "b": 2}"#), None);
        assert_eq!(duplicate_key(r#"{"a": 1, "a": 2}"#).as_deref(), Some("a"));
        assert_eq!(
            duplicate_key(r#"{"p": [{"v": 1}, {"v": 1, "w": [], "v": 2}]}"#).as_deref(),
            Some("p[1].v")
        );
        assert_eq!(
            duplicate_key(r#"{"x": {"s": 1, "s": 1}}"#).as_deref(),
            Some("x.s")
        );
        // Same key in two objects is fine; broken JSON is left to the parse.
        assert_eq!(duplicate_key(r#"[{"a": 1}, {"a": 2}]"#), None);
        assert_eq!(duplicate_key(r#"{"a": 1, "b""#), None);
        assert_eq!(
            duplicate_key(r#"{"a\u0041": 1, "aA": 2}"#).as_deref(),
            Some("aA")
        );
    }
}

/// `#[serde(with = "crate::json::f64_bits")]`: an `f64` as its bits, so
/// that infinities and NaN survive JSON (which has neither) and every
/// value comes back exactly (intermediate files, such as a sharded prep's
/// scans).
pub mod f64_bits {
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(v.to_bits())
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        u64::deserialize(d).map(f64::from_bits)
    }
}
