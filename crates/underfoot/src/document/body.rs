//! Deserializes a document's body from the file's top-level object, skipping the header
//! keys, so that serde's errors point into the file as the user wrote it.

use std::fmt;
use std::marker::PhantomData;

use serde::de::value::{MapAccessDeserializer, StringDeserializer};
use serde::de::{DeserializeOwned, DeserializeSeed, IgnoredAny, MapAccess, Visitor};

use super::TAG_KEY;

/// A visitor of the top-level object that hands every key but the header's to `T`.
pub(super) struct Body<T> {
    legacy: bool,
    body: PhantomData<T>,
}

impl<T> Body<T> {
    pub(super) fn new(legacy: bool) -> Self {
        Self {
            legacy,
            body: PhantomData,
        }
    }
}

impl<'de, T: DeserializeOwned> Visitor<'de> for Body<T> {
    type Value = T;

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("a JSON object")
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<T, A::Error> {
        T::deserialize(MapAccessDeserializer::new(WithoutHeader {
            map,
            legacy: self.legacy,
        }))
    }
}

struct WithoutHeader<A> {
    map: A,
    legacy: bool,
}

impl<A> WithoutHeader<A> {
    fn is_header(&self, key: &str) -> bool {
        key == TAG_KEY || (self.legacy && (key == "kind" || key == "version"))
    }
}

impl<'de, A: MapAccess<'de>> MapAccess<'de> for WithoutHeader<A> {
    type Error = A::Error;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, A::Error> {
        while let Some(key) = self.map.next_key::<String>()? {
            if self.is_header(&key) {
                self.map.next_value::<IgnoredAny>()?;
            } else {
                return seed.deserialize(StringDeserializer::new(key)).map(Some);
            }
        }
        Ok(None)
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, A::Error> {
        self.map.next_value_seed(seed)
    }
}
