//! `tf.train.Example` as hand-written `prost` messages (no protoc), plus small accessors.

use std::collections::BTreeMap;

/// `tf.train.Example`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Example {
    /// The features.
    #[prost(message, optional, tag = "1")]
    pub features: Option<Features>,
}

/// `tf.train.Features`: name → feature.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Features {
    /// The feature map.
    #[prost(btree_map = "string, message", tag = "1")]
    pub feature: BTreeMap<String, Feature>,
}

/// `tf.train.Feature`: one of bytes, float or int64 lists.
#[derive(Clone, PartialEq, prost::Message)]
pub struct Feature {
    /// The list.
    #[prost(oneof = "Kind", tags = "1, 2, 3")]
    pub kind: Option<Kind>,
}

/// The three list kinds of a feature.
#[derive(Clone, PartialEq, prost::Oneof)]
pub enum Kind {
    /// Byte strings.
    #[prost(message, tag = "1")]
    BytesList(BytesList),
    /// 32-bit floats.
    #[prost(message, tag = "2")]
    FloatList(FloatList),
    /// 64-bit integers.
    #[prost(message, tag = "3")]
    Int64List(Int64List),
}

/// `tf.train.BytesList`.
#[derive(Clone, PartialEq, prost::Message)]
pub struct BytesList {
    /// Values.
    #[prost(bytes = "vec", repeated, tag = "1")]
    pub value: Vec<Vec<u8>>,
}

/// `tf.train.FloatList` (packed).
#[derive(Clone, PartialEq, prost::Message)]
pub struct FloatList {
    /// Values.
    #[prost(float, repeated, tag = "1")]
    pub value: Vec<f32>,
}

/// `tf.train.Int64List` (packed).
#[derive(Clone, PartialEq, prost::Message)]
pub struct Int64List {
    /// Values.
    #[prost(int64, repeated, tag = "1")]
    pub value: Vec<i64>,
}

impl Example {
    /// Feature by key, if present.
    pub fn get(&self, key: &str) -> Option<&Kind> {
        self.features.as_ref()?.feature.get(key)?.kind.as_ref()
    }

    /// All feature keys.
    pub fn keys(&self) -> Vec<&str> {
        self.features
            .as_ref()
            .map(|f| f.feature.keys().map(|k| k.as_str()).collect())
            .unwrap_or_default()
    }

    /// Float list by key; `Err` names the key when present with another type.
    pub fn floats(&self, key: &str) -> Result<Option<&[f32]>, String> {
        match self.get(key) {
            None => Ok(None),
            Some(Kind::FloatList(l)) => Ok(Some(&l.value)),
            Some(_) => Err(format!("feature `{key}` is not a float list")),
        }
    }

    /// Bytes list by key.
    pub fn bytes(&self, key: &str) -> Result<Option<&[Vec<u8>]>, String> {
        match self.get(key) {
            None => Ok(None),
            Some(Kind::BytesList(l)) => Ok(Some(&l.value)),
            Some(_) => Err(format!("feature `{key}` is not a bytes list")),
        }
    }

    /// Int64 list by key.
    pub fn ints(&self, key: &str) -> Result<Option<&[i64]>, String> {
        match self.get(key) {
            None => Ok(None),
            Some(Kind::Int64List(l)) => Ok(Some(&l.value)),
            Some(_) => Err(format!("feature `{key}` is not an int64 list")),
        }
    }

    /// Inserts a feature (builder helper for writing fixtures).
    pub fn insert(&mut self, key: &str, kind: Kind) {
        self.features
            .get_or_insert_with(Features::default)
            .feature
            .insert(key.to_string(), Feature { kind: Some(kind) });
    }
}
