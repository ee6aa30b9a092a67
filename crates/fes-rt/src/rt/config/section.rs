//! Reading a shared section with the keys of one process in the same table: the shared
//! keys and the process's own ([`OwnKeys`]) are matched by name, and any other key is
//! refused with serde's own message for a struct that denies unknown fields, at the key.

use std::fmt;
use std::marker::PhantomData;

use serde::Deserializer;
use serde::de::{self, DeserializeSeed, MapAccess, SeqAccess, Visitor};

use super::OwnKeys;

/// A shared section: its shared keys, with the process's own keys at one place among them.
pub(super) trait Section: Default {
    /// The type's name, as serde's errors name it ("expected struct IpcConfig").
    const NAME: &'static str;
    /// The shared keys, in their order in the section.
    const SHARED: &'static [&'static str];
    /// The process's own keys sit after this many shared keys (in an error's list of keys
    /// and in the positional form).
    const OWN_AT: usize;
    /// The process's own keys.
    type Own: OwnKeys;

    /// The process's own keys of this section.
    fn own_mut(&mut self) -> &mut Self::Own;
    /// Reads the value of shared key number `i`.
    fn read_shared<'de, A: MapAccess<'de>>(
        &mut self,
        i: usize,
        map: &mut A,
    ) -> Result<(), A::Error>;
    /// Reads shared key number `i` from the positional form; `false` once it has ended.
    fn read_shared_element<'de, A: SeqAccess<'de>>(
        &mut self,
        i: usize,
        seq: &mut A,
    ) -> Result<bool, A::Error>;
}

/// Deserializes section `S` from a table (or, as serde's derive also accepts, an array of
/// its values in order); keys left out keep their defaults.
pub(super) fn deserialize<'de, S: Section, D: Deserializer<'de>>(d: D) -> Result<S, D::Error> {
    d.deserialize_struct(S::NAME, S::SHARED, SectionVisitor::<S>(PhantomData))
}

struct SectionVisitor<S>(PhantomData<fn() -> S>);

impl<'de, S: Section> Visitor<'de> for SectionVisitor<S> {
    type Value = S;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "struct {}", S::NAME)
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<S, A::Error> {
        let mut section = S::default();
        while let Some(key) = map.next_key_seed(KeySeed::<S>(PhantomData))? {
            match key {
                Key::Shared(i) => section.read_shared(i, &mut map)?,
                Key::Own(k) => section.own_mut().read_value(k, &mut map)?,
            }
        }
        Ok(section)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<S, A::Error> {
        let mut section = S::default();
        for i in 0..=S::SHARED.len() {
            if i == S::OWN_AT && !section.own_mut().read_elements(&mut seq)? {
                break;
            }
            if i < S::SHARED.len() && !section.read_shared_element(i, &mut seq)? {
                break;
            }
        }
        Ok(section)
    }
}

/// A key of the section: shared key number `i`, or one of the process's own.
enum Key {
    Shared(usize),
    Own(&'static str),
}

/// Reads a key of section `S`, refusing any other inside the key's own deserialization,
/// where the TOML reader places the error at the key (as it does for a derived struct).
struct KeySeed<S>(PhantomData<fn() -> S>);

impl<'de, S: Section> DeserializeSeed<'de> for KeySeed<S> {
    type Value = Key;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Key, D::Error> {
        d.deserialize_identifier(self)
    }
}

impl<'de, S: Section> Visitor<'de> for KeySeed<S> {
    type Value = Key;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("field identifier")
    }

    fn visit_str<E: de::Error>(self, v: &str) -> Result<Key, E> {
        if let Some(i) = S::SHARED.iter().position(|k| *k == v) {
            return Ok(Key::Shared(i));
        }
        if let Some(k) = <S::Own as OwnKeys>::KEYS.iter().find(|k| **k == v) {
            return Ok(Key::Own(k));
        }
        Err(E::custom(format_args!(
            "unknown field `{v}`, expected {}",
            Expected::<S>(PhantomData)
        )))
    }
}

/// The keys of section `S` in their order, as serde lists a struct's fields.
struct Expected<S>(PhantomData<fn() -> S>);

impl<S: Section> fmt::Display for Expected<S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (before, after) = S::SHARED.split_at(S::OWN_AT);
        let keys: Vec<&str> = before
            .iter()
            .chain(<S::Own as OwnKeys>::KEYS)
            .chain(after)
            .copied()
            .collect();
        match keys.as_slice() {
            [one] => write!(f, "`{one}`"),
            [a, b] => write!(f, "`{a}` or `{b}`"),
            _ => {
                f.write_str("one of ")?;
                for (i, k) in keys.iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    write!(f, "`{k}`")?;
                }
                Ok(())
            }
        }
    }
}
