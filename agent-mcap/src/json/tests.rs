//! The JSON read off postcard bytes is what `serde_json` makes of the value;
//! hostile bytes give errors, never panics; the schema describes the JSON.

use std::collections::BTreeMap;

use proptest::prelude::*;
use serde::{Deserialize, Serialize};

use super::*;

/// What `serde_json` cannot carry exactly as a number is a string.
fn big_unsigned(v: u128) -> Value {
    u64::try_from(v).map_or_else(|_| Value::String(v.to_string()), |v| json!(v))
}

fn big_signed(v: i128) -> Value {
    i64::try_from(v).map_or_else(|_| Value::String(v.to_string()), |v| json!(v))
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Unit;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Meters(f64);

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) enum Kind {
    Idle,
    Wait(i16),
    Pair(u8, u8),
    Drive { speed: f64, note: String },
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Inner {
    flag: bool,
    kind: Kind,
    unit: Unit,
    length: Meters,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct Everything {
    a: u8,
    b: i8,
    c: u16,
    d: i32,
    e: i64,
    f: u64,
    g: f32,
    h: f64,
    i: char,
    j: String,
    k: Option<i32>,
    l: Vec<u16>,
    m: [f64; 3],
    n: (u8, String),
    o: BTreeMap<u32, bool>,
    p: (Inner, Inner),
    q: u128,
    r: i128,
}

pub(crate) fn kind() -> impl Strategy<Value = Kind> {
    prop_oneof![
        Just(Kind::Idle),
        any::<i16>().prop_map(Kind::Wait),
        (any::<u8>(), any::<u8>()).prop_map(|(a, b)| Kind::Pair(a, b)),
        (any::<f64>(), ".{0,8}").prop_map(|(speed, note)| Kind::Drive { speed, note }),
    ]
}

pub(crate) fn everything() -> impl Strategy<Value = Everything> {
    let inner = || {
        (any::<bool>(), kind(), any::<f64>()).prop_map(|(flag, kind, l)| Inner {
            flag,
            kind,
            unit: Unit,
            length: Meters(l),
        })
    };
    (
        (
            any::<u8>(),
            any::<i8>(),
            any::<u16>(),
            any::<i32>(),
            any::<i64>(),
            any::<u64>(),
            any::<f32>(),
            any::<f64>(),
            any::<char>(),
        ),
        (
            ".{0,12}",
            any::<Option<i32>>(),
            prop::collection::vec(any::<u16>(), 0..6),
            any::<[f64; 3]>(),
            (any::<u8>(), ".{0,4}"),
            prop::collection::btree_map(any::<u32>(), any::<bool>(), 0..4),
            (inner(), inner()),
            any::<u128>(),
            any::<i128>(),
        ),
    )
        .prop_map(
            |((a, b, c, d, e, f, g, h, i), (j, k, l, m, n, o, p, q, r))| Everything {
                a,
                b,
                c,
                d,
                e,
                f,
                g,
                h,
                i,
                j,
                k,
                l,
                m,
                n,
                o,
                p,
                q,
                r,
            },
        )
}

pub(crate) fn shape() -> TypeShape {
    agent_core::reflect::<Everything>().expect("traceable")
}

proptest! {
    #[test]
    fn the_json_of_the_bytes_is_the_json_of_the_value(v in everything()) {
        let bytes = postcard::to_allocvec(&v).unwrap();
        let small = Everything { q: 0, r: 0, ..v.clone() };
        let mut expected = serde_json::to_value(&small).unwrap();
        // serde_json refuses 128-bit integers beyond 64 bits in a `Value`
        // without its arbitrary precision; they are strings here.
        let _ = &mut expected;
        expected["q"] = big_unsigned(v.q);
        expected["r"] = big_signed(v.r);
        prop_assert_eq!(to_json(&shape(), &bytes).unwrap(), expected);
    }

    #[test]
    fn hostile_bytes_give_an_error_never_a_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let _ = to_json(&shape(), &bytes);
    }

    #[test]
    fn a_cut_or_padded_value_is_an_error_at_its_end(v in everything(), cut in 1usize..8) {
        let bytes = postcard::to_allocvec(&v).unwrap();
        let short = &bytes[..bytes.len().saturating_sub(cut)];
        prop_assert!(to_json(&shape(), short).is_err());
        let mut long = bytes.clone();
        long.push(0);
        let e = to_json(&shape(), &long).unwrap_err();
        prop_assert_eq!(e.offset, bytes.len());
    }
}

#[test]
fn errors_name_the_offset() {
    let s = agent_core::reflect::<(bool, Kind)>().unwrap();
    let e = to_json(&s, &[2]).unwrap_err();
    assert_eq!((e.offset, e.what.as_str()), (0, "a bool byte of 2"));
    let e = to_json(&s, &[1, 9]).unwrap_err();
    assert_eq!(e.offset, 1);
    assert!(e.what.contains("variant 9"), "{e}");
    // A length far beyond the bytes is refused, not allocated.
    let s = agent_core::reflect::<Vec<u64>>().unwrap();
    let e = to_json(&s, &[0xff, 0xff, 0xff, 0xff, 0x0f]).unwrap_err();
    assert!(e.what.contains("length"), "{e}");
}

#[test]
fn the_schema_describes_structs_enums_arrays_and_options() {
    let s = json_schema(&shape(), "Everything");
    assert_eq!(s["title"], "Everything");
    assert_eq!(s["type"], "object");
    let props = s["properties"].as_object().unwrap();
    let names: Vec<&str> = props.keys().map(String::as_str).collect();
    let mut expected = vec![
        "a", "b", "c", "d", "e", "f", "g", "h", "i", "j", "k", "l", "m", "n", "o", "p", "q", "r",
    ];
    expected.sort_unstable();
    assert_eq!(names, expected);
    assert_eq!(props["a"]["type"], "integer");
    assert_eq!(props["h"]["type"], json!(["number", "null"]));
    assert_eq!(props["k"]["anyOf"][1]["type"], "null");
    assert_eq!(props["m"]["maxItems"], 3);
    assert_eq!(props["o"]["type"], "object");
    // A pair of one type is an array of two.
    assert_eq!(props["p"]["maxItems"], 2);
    let inner = &props["p"]["items"];
    assert_eq!(
        inner["properties"]["length"]["type"],
        json!(["number", "null"])
    );
    let kinds = inner["properties"]["kind"]["oneOf"].as_array().unwrap();
    assert_eq!(kinds.len(), 4);
    assert_eq!(kinds[0], json!({"const": "Idle"}));
    assert_eq!(
        kinds[3]["properties"]["Drive"]["properties"]["speed"]["type"],
        json!(["number", "null"])
    );
}

#[test]
fn a_type_that_contains_itself_is_left_open_where_it_recurs() {
    #[derive(Clone, Debug, Serialize, Deserialize)]
    struct Tree {
        value: u8,
        children: Vec<Tree>,
    }
    let s = agent_core::reflect::<Tree>().unwrap();
    let schema = json_schema(&s, "Tree");
    assert_eq!(schema["properties"]["children"]["items"], json!({}));
    let t = Tree {
        value: 1,
        children: vec![Tree {
            value: 2,
            children: Vec::new(),
        }],
    };
    let v = to_json(&s, &postcard::to_allocvec(&t).unwrap()).unwrap();
    assert_eq!(
        v,
        json!({"value": 1, "children": [{"value": 2, "children": []}]})
    );
}

#[test]
fn an_enum_only_inside_a_sequence_has_no_shape_rather_than_a_partial_one() {
    // Inside a field, the tracer stops at a sequence's or an option's first
    // element: the enum's other variants stay unknown, and the type is
    // refused, not half described.
    #[derive(Clone, Debug, Serialize, Deserialize)]
    struct Kinds {
        all: Vec<Kind>,
    }
    #[derive(Clone, Debug, Serialize, Deserialize)]
    struct MaybeKind {
        one: Option<Kind>,
    }
    assert!(agent_core::reflect::<Kinds>().is_none());
    assert!(agent_core::reflect::<MaybeKind>().is_none());
    // At the root, each trace starts afresh: explored in full.
    assert!(agent_core::reflect::<Vec<Kind>>().is_some());
    // Reached directly, in a field or a tuple, it is explored in full.
    let s = agent_core::reflect::<(u8, Inner)>().unwrap();
    let Some(agent_core::serde_reflection::ContainerFormat::Enum(v)) = s.registry.get("Kind")
    else {
        panic!("{s:?}");
    };
    assert_eq!(v.len(), 4);
}

proptest! {
    /// The text the recorder writes is `serde_json`'s own text of the value
    /// (fields in declared order, the same number formatting), for types
    /// without `f32` or 128-bit integers (which `serde_json` writes as
    /// themselves, and the recording widens or quotes).
    #[test]
    fn the_text_written_is_serde_jsons_text(flag in any::<bool>(), kind in kind(), x in any::<f64>()) {
        let v = Inner { flag, kind, unit: Unit, length: Meters(x) };
        let s = agent_core::reflect::<Inner>().unwrap();
        let mut text = Vec::new();
        write_json(&s, &postcard::to_allocvec(&v).unwrap(), &mut text).unwrap();
        prop_assert_eq!(String::from_utf8(text).unwrap(), serde_json::to_string(&v).unwrap());
    }
}
