//! Mutations for the property tests of the file parsers: byte-level edits of a real file
//! (truncation, bit flips, overwritten, inserted and removed bytes) and structural edits of a
//! JSON document (a value replaced by arbitrary JSON, a key removed or added), each described by
//! a small `Debug` value so that a failing case reads as what was done to the file, not as
//! thousands of bytes.
//!
//! The number of cases is bounded so that `cargo test` stays fast; `PROPTEST_CASES=100000`
//! runs a longer search locally.

// Every test crate that includes this module uses a subset of it.
#![allow(dead_code)]

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, FileFailurePersistence};
use serde_json::{Map, Value};

/// A proptest configuration running `default_cases` cases, or `PROPTEST_CASES` when set. No
/// failure files are written into the source tree: a failure found becomes a named regression
/// test instead.
pub fn config(default_cases: u32) -> Config {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default_cases);
    Config {
        cases,
        failure_persistence: Some(Box::new(FileFailurePersistence::Off)),
        ..Config::default()
    }
}

/// One edit of a byte string; positions are relative to its length at the time of the edit.
#[derive(Debug, Clone)]
pub enum ByteEdit {
    /// Keep only the first `len` fraction of the bytes.
    Truncate(Index),
    /// Flip one bit anywhere.
    FlipBit(Index, u8),
    /// Flip one bit in the first 64 bytes, where the headers are.
    FlipHeaderBit(u8, u8),
    /// Overwrite one byte.
    Set(Index, u8),
    /// Overwrite four bytes with a big- and little-endian-interesting 32-bit value (sizes,
    /// lengths and counts are 32-bit words in PNG and `.flo` headers).
    SetWord(Index, u32),
    /// Insert bytes.
    Insert(Index, Vec<u8>),
    /// Remove up to `n` bytes.
    Remove(Index, u8),
}

fn interesting_u32() -> impl Strategy<Value = u32> {
    prop_oneof![
        Just(0u32),
        Just(1),
        Just(0x7fff_ffff),
        Just(0x8000_0000),
        Just(u32::MAX),
        Just(16_000),
        Just(65_536),
        any::<u32>(),
    ]
}

fn byte_edit() -> impl Strategy<Value = ByteEdit> {
    prop_oneof![
        any::<Index>().prop_map(ByteEdit::Truncate),
        (any::<Index>(), 0u8..8).prop_map(|(i, b)| ByteEdit::FlipBit(i, b)),
        (0u8..64, 0u8..8).prop_map(|(i, b)| ByteEdit::FlipHeaderBit(i, b)),
        (any::<Index>(), any::<u8>()).prop_map(|(i, v)| ByteEdit::Set(i, v)),
        (any::<Index>(), interesting_u32()).prop_map(|(i, v)| ByteEdit::SetWord(i, v)),
        (any::<Index>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(i, v)| ByteEdit::Insert(i, v)),
        (any::<Index>(), 1u8..64).prop_map(|(i, n)| ByteEdit::Remove(i, n)),
    ]
}

/// One to four byte edits.
pub fn byte_edits() -> impl Strategy<Value = Vec<ByteEdit>> {
    prop::collection::vec(byte_edit(), 1..=4)
}

/// `original` with `edits` applied in order.
pub fn apply_bytes(original: &[u8], edits: &[ByteEdit]) -> Vec<u8> {
    let mut b = original.to_vec();
    for edit in edits {
        // An edit of an empty file other than an insertion has nothing to act on.
        let len = b.len();
        match edit {
            ByteEdit::Truncate(i) => b.truncate(if len == 0 { 0 } else { i.index(len) }),
            ByteEdit::FlipBit(i, bit) if len > 0 => b[i.index(len)] ^= 1 << bit,
            ByteEdit::FlipHeaderBit(i, bit) if usize::from(*i) < len => {
                b[usize::from(*i)] ^= 1 << bit
            }
            ByteEdit::Set(i, v) if len > 0 => b[i.index(len)] = *v,
            ByteEdit::SetWord(i, v) if len >= 4 => {
                let at = i.index(len - 3);
                let bytes = if at % 2 == 0 {
                    v.to_be_bytes()
                } else {
                    v.to_le_bytes()
                };
                b[at..at + 4].copy_from_slice(&bytes);
            }
            ByteEdit::Insert(i, v) => {
                let at = i.index(len + 1);
                b.splice(at..at, v.iter().copied());
            }
            ByteEdit::Remove(i, n) if len > 0 => {
                let at = i.index(len);
                let end = (at + usize::from(*n)).min(len);
                b.drain(at..end);
            }
            _ => {}
        }
    }
    b
}

/// Arbitrary JSON: every type, numbers at the edges of what the parsers convert (negative,
/// huge, fractional where integers are expected, beyond f32), strings with odd characters,
/// nested arrays and objects.
pub fn arbitrary_json() -> impl Strategy<Value = Value> {
    let number = prop_oneof![
        any::<i64>().prop_map(Value::from),
        any::<u64>().prop_map(Value::from),
        prop_oneof![
            Just(0.0f64),
            Just(-0.0),
            Just(0.5),
            Just(-1.0),
            Just(1e39),
            Just(-1e39),
            Just(1e300),
            Just(f64::MIN_POSITIVE),
            Just(4294967296.0),
            any::<f64>().prop_filter("JSON numbers are finite", |f| f.is_finite()),
        ]
        .prop_map(Value::from),
    ];
    let leaf = prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::from),
        number,
        "\\PC{0,12}".prop_map(Value::from),
    ];
    let nested = leaf.clone().prop_recursive(3, 24, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..4).prop_map(Value::Array),
            prop::collection::btree_map("[a-z_]{1,8}", inner, 0..4)
                .prop_map(|m| Value::Object(m.into_iter().collect::<Map<_, _>>())),
        ]
    });
    // `prop_recursive` alone yields a container nine times in ten; most fields hold a scalar,
    // and a wrong scalar is the likelier damage.
    prop_oneof![3 => leaf, 1 => nested]
}

/// One structural edit of a JSON document, at the node picked by `at` among all nodes below the
/// root (object members and array elements, depth first).
#[derive(Debug, Clone)]
pub enum JsonEdit {
    /// Replace the node's value.
    Replace(Index, Value),
    /// Remove the node from its object or array.
    Remove(Index),
    /// Add a member to the node if it is an object (an unknown key), or an element to it if
    /// it is an array.
    Add(Index, String, Value),
}

pub fn json_edit() -> impl Strategy<Value = JsonEdit> {
    prop_oneof![
        3 => (any::<Index>(), arbitrary_json()).prop_map(|(i, v)| JsonEdit::Replace(i, v)),
        1 => any::<Index>().prop_map(JsonEdit::Remove),
        1 => (any::<Index>(), "[a-z_]{1,10}", arbitrary_json())
            .prop_map(|(i, k, v)| JsonEdit::Add(i, k, v)),
    ]
}

/// One step of a path from the root.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Step {
    Key(String),
    Item(usize),
}

/// Every node below the root, depth first, as paths.
fn paths(v: &Value, prefix: &mut Vec<Step>, out: &mut Vec<Vec<Step>>) {
    match v {
        Value::Object(m) => {
            for (k, child) in m {
                prefix.push(Step::Key(k.clone()));
                out.push(prefix.clone());
                paths(child, prefix, out);
                prefix.pop();
            }
        }
        Value::Array(a) => {
            for (i, child) in a.iter().enumerate() {
                prefix.push(Step::Item(i));
                out.push(prefix.clone());
                paths(child, prefix, out);
                prefix.pop();
            }
        }
        _ => {}
    }
}

fn node_mut<'a>(root: &'a mut Value, path: &[Step]) -> &'a mut Value {
    path.iter().fold(root, |v, step| match step {
        Step::Key(k) => &mut v[k.as_str()],
        Step::Item(i) => &mut v[*i],
    })
}

/// `doc` with `edit` applied, and the path of the node edited (empty when the document has no
/// node below the root).
pub fn apply_json(doc: &Value, edit: &JsonEdit) -> (Value, Vec<Step>) {
    let mut doc = doc.clone();
    let mut all = Vec::new();
    paths(&doc, &mut Vec::new(), &mut all);
    if all.is_empty() {
        return (doc, Vec::new());
    }
    let at = match edit {
        JsonEdit::Replace(i, _) | JsonEdit::Remove(i) | JsonEdit::Add(i, _, _) => {
            i.index(all.len())
        }
    };
    let path = all.swap_remove(at);
    match edit {
        JsonEdit::Replace(_, v) => *node_mut(&mut doc, &path) = v.clone(),
        JsonEdit::Remove(_) => {
            let (last, parent) = path.split_last().expect("paths are not empty");
            match (node_mut(&mut doc, parent), last) {
                (Value::Object(m), Step::Key(k)) => {
                    m.remove(k);
                }
                (Value::Array(a), Step::Item(i)) => {
                    a.remove(*i);
                }
                _ => unreachable!("a path step matches its parent's type"),
            }
        }
        JsonEdit::Add(_, k, v) => match node_mut(&mut doc, &path) {
            Value::Object(m) => {
                m.insert(k.clone(), v.clone());
            }
            Value::Array(a) => a.push(v.clone()),
            other => *other = v.clone(),
        },
    }
    (doc, path)
}

/// The first key of `path`, the top-level field an edit is under.
pub fn top_key(path: &[Step]) -> Option<&str> {
    match path.first() {
        Some(Step::Key(k)) => Some(k),
        _ => None,
    }
}
