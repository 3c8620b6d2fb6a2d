//! The CDR written off postcard bytes is aligned and laid out as the schema
//! says; hostile bytes give errors, never panics; what ROS 2 messages cannot
//! express is refused when the schema is made. (An independent decoder, the
//! `mcap_ros2` Python package, reads and re-encodes every message of a Rex
//! recording byte for byte: `rex-agent/tests/record.rs`.)

use proptest::prelude::*;
use serde::{Deserialize, Serialize};

use super::shape::{constant_name, field_name_ok, message_name, snake};
use super::*;
use crate::json::tests::{Kind, everything, kind, shape};

fn cdr<T: Serialize>(shape: &TypeShape, v: &T) -> Vec<u8> {
    let bytes = postcard::to_allocvec(v).unwrap();
    let mut out = Vec::new();
    write_cdr(shape, &bytes, &mut out).unwrap();
    out
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Mixed {
    a: u8,
    b: f64,
    c: u16,
    d: String,
    e: Option<u32>,
    f: Vec<i16>,
    g: bool,
    h: i64,
}

#[test]
fn fields_are_aligned_to_their_size_from_after_the_header() {
    let shape = agent_core::reflect::<Mixed>().unwrap();
    let v = Mixed {
        a: 7,
        b: 1.5,
        c: 0x0102,
        d: "hi".into(),
        e: Some(9),
        f: vec![-1, 2],
        g: true,
        h: -2,
    };
    let mut expected = vec![0, 1, 0, 0]; // CDR_LE
    expected.push(7); // a at 0
    expected.extend([0; 7]); // b aligned to 8
    expected.extend(1.5f64.to_le_bytes()); // 8..16
    expected.extend(0x0102u16.to_le_bytes()); // c at 16
    expected.extend([0; 2]); // length aligned to 4
    expected.extend(3u32.to_le_bytes()); // "hi" + NUL at 20
    expected.extend(b"hi\0"); // 24..27
    expected.push(0); // count aligned to 4
    expected.extend(1u32.to_le_bytes()); // e: one element at 28
    expected.extend(9u32.to_le_bytes()); // 32
    expected.extend(2u32.to_le_bytes()); // f: two at 36
    expected.extend((-1i16).to_le_bytes()); // 40
    expected.extend(2i16.to_le_bytes()); // 42
    expected.push(1); // g at 44
    expected.extend([0; 3]); // h aligned to 8
    expected.extend((-2i64).to_le_bytes()); // 48..56
    assert_eq!(cdr(&shape, &v), expected);
    let schema = ros2msg_schema(&shape, "Mixed").unwrap();
    assert_eq!(schema.name, "embodied/msg/Mixed");
    assert_eq!(
        schema.text,
        "uint8 a\nfloat64 b\nuint16 c\nstring d\nuint32[<=1] e\nint16[] f\nbool g\nint64 h\n"
    );
}

#[test]
fn an_enum_is_its_variant_and_one_optional_field_per_variant_with_data() {
    let shape = agent_core::reflect::<Kind>().unwrap();
    let schema = ros2msg_schema(&shape, "Kind").unwrap();
    assert_eq!(schema.name, "embodied/msg/Kind");
    let sep = "=".repeat(80);
    assert_eq!(
        schema.text,
        format!(
            "uint32 IDLE=0\nuint32 WAIT=1\nuint32 PAIR=2\nuint32 DRIVE=3\n\
             uint32 variant\nint16[<=1] wait\nembodied/KindPair[<=1] pair\n\
             embodied/KindDrive[<=1] drive\n\
             {sep}\nMSG: embodied/KindPair\nuint8 item0\nuint8 item1\n\
             {sep}\nMSG: embodied/KindDrive\nfloat64 speed\nstring note\n"
        )
    );
    let none = 0u32.to_le_bytes();
    let one = 1u32.to_le_bytes();
    let mut idle = vec![0, 1, 0, 0];
    idle.extend(0u32.to_le_bytes());
    idle.extend(none.repeat(3));
    assert_eq!(cdr(&shape, &Kind::Idle), idle);
    let mut pair = vec![0, 1, 0, 0];
    pair.extend(2u32.to_le_bytes());
    pair.extend(none); // wait
    pair.extend(one);
    pair.extend([4, 5]); // pair's two bytes
    pair.extend([0, 0]);
    pair.extend(none); // drive
    assert_eq!(cdr(&shape, &Kind::Pair(4, 5)), pair);
}

#[test]
fn everything_has_a_schema_and_nested_arrays_are_wrapped() {
    #[derive(Clone, Debug, Serialize, Deserialize)]
    struct Nested {
        grid: Vec<Vec<f64>>,
        maybe: Option<[u8; 2]>,
    }
    let nested = agent_core::reflect::<Nested>().unwrap();
    let schema = ros2msg_schema(&nested, "Nested").unwrap();
    let sep = "=".repeat(80);
    assert_eq!(
        schema.text,
        format!(
            "embodied/Item[] grid\nembodied/Item2[<=1] maybe\n\
             {sep}\nMSG: embodied/Item\nfloat64[] value\n\
             {sep}\nMSG: embodied/Item2\nuint8[2] value\n"
        )
    );
    // A wrapped element is encoded as its one field.
    let v = Nested {
        grid: vec![vec![1.0], vec![]],
        maybe: Some([3, 4]),
    };
    let mut expected = vec![0, 1, 0, 0];
    expected.extend(2u32.to_le_bytes());
    expected.extend(1u32.to_le_bytes());
    expected.extend(1.0f64.to_le_bytes());
    expected.extend(0u32.to_le_bytes());
    expected.extend(1u32.to_le_bytes());
    expected.extend([3, 4]);
    assert_eq!(cdr(&nested, &v), expected);
    // The whole test type: every format has a message.
    let schema = ros2msg_schema(&shape(), "Everything").unwrap();
    assert_eq!(schema.name, "embodied/msg/Everything");
    for line in [
        "uint8[16] q",
        "uint32 i",
        "embodied/Entry[] o",
        "embodied/Tuple n",
    ] {
        assert!(schema.text.contains(line), "{line}: {}", schema.text);
    }
}

#[test]
fn what_a_ros_2_message_cannot_express_is_refused() {
    #[derive(Clone, Debug, Serialize, Deserialize)]
    struct Tree {
        children: Vec<Tree>,
    }
    let e = ros2msg_schema(&agent_core::reflect::<Tree>().unwrap(), "Tree").unwrap_err();
    assert!(e.0.contains("contains itself"), "{e}");
    #[derive(Clone, Debug, Serialize, Deserialize)]
    #[allow(non_snake_case, reason = "the case under test")]
    struct Shouting {
        Speed: f64,
    }
    let e = ros2msg_schema(&agent_core::reflect::<Shouting>().unwrap(), "S").unwrap_err();
    assert!(e.0.contains("`Speed`"), "{e}");
    // Variants name constants: each must be one ROS 2 accepts, and unique.
    #[derive(Clone, Debug, Serialize, Deserialize)]
    enum Drink {
        Tea,
        Café,
    }
    let e = ros2msg_schema(&agent_core::reflect::<Drink>().unwrap(), "D").unwrap_err();
    assert!(e.0.contains("`Café`") && e.0.contains("`CAF_`"), "{e}");
    #[derive(Clone, Debug, Serialize, Deserialize)]
    #[allow(non_camel_case_types, reason = "the case under test")]
    enum Twins {
        NoEstimate,
        No_Estimate,
    }
    let e = ros2msg_schema(&agent_core::reflect::<Twins>().unwrap(), "T").unwrap_err();
    assert!(
        e.0.contains("`No_Estimate`") && e.0.contains("NO_ESTIMATE"),
        "{e}"
    );
    #[derive(Clone, Debug, Serialize, Deserialize)]
    enum Fine {
        NoEstimate,
        Pose2d(f64),
    }
    let schema = ros2msg_schema(&agent_core::reflect::<Fine>().unwrap(), "F").unwrap();
    assert!(
        schema
            .text
            .starts_with("uint32 NO_ESTIMATE=0\nuint32 POSE2D=1\n"),
        "{}",
        schema.text
    );
}

#[test]
fn a_primitive_or_a_sequence_is_the_field_of_a_message() {
    let shape = agent_core::reflect::<Vec<f32>>().unwrap();
    let schema = ros2msg_schema(&shape, "Samples").unwrap();
    assert_eq!(schema.name, "embodied/msg/Samples");
    assert_eq!(schema.text, "float32[] value\n");
    let mut expected = vec![0, 1, 0, 0];
    expected.extend(1u32.to_le_bytes());
    expected.extend(0.5f32.to_le_bytes());
    assert_eq!(cdr(&shape, &vec![0.5f32]), expected);
}

proptest! {
    #[test]
    fn every_value_encodes_and_its_length_follows_from_its_content(v in everything()) {
        let out = cdr(&shape(), &v);
        // At least the fixed-size fields' bytes, aligned: a lower bound that
        // a dropped field would break.
        prop_assert!(out.len() >= 4 + 1 + 1 + 2 + 4 + 8 + 8 + 4 + 8 + 4 + 16 + 16);
        prop_assert_eq!(&out[..4], &[0, 1, 0, 0]);
    }

    #[test]
    fn an_enum_value_names_its_variant(k in kind()) {
        let out = cdr(&agent_core::reflect::<Kind>().unwrap(), &k);
        let variant = u32::from_le_bytes([out[4], out[5], out[6], out[7]]);
        let expected = match k {
            Kind::Idle => 0,
            Kind::Wait(_) => 1,
            Kind::Pair(..) => 2,
            Kind::Drive { .. } => 3,
        };
        prop_assert_eq!(variant, expected);
    }

    #[test]
    fn hostile_bytes_give_an_error_never_a_panic(bytes in prop::collection::vec(any::<u8>(), 0..200)) {
        let _ = write_cdr(&shape(), &bytes, &mut Vec::new());
    }

    #[test]
    fn a_cut_or_padded_value_is_an_error(v in everything(), cut in 1usize..8) {
        let bytes = postcard::to_allocvec(&v).unwrap();
        let short = &bytes[..bytes.len().saturating_sub(cut)];
        prop_assert!(write_cdr(&shape(), short, &mut Vec::new()).is_err());
        let mut long = bytes.clone();
        long.push(0);
        let e = write_cdr(&shape(), &long, &mut Vec::new()).unwrap_err();
        prop_assert_eq!(e.offset, bytes.len());
    }
}

#[test]
fn names_are_made_valid_for_ros_2() {
    assert_eq!(message_name("rex_agent::a1::State"), "RexAgentA1State");
    assert_eq!(message_name("f64"), "F64");
    assert_eq!(snake("NoEstimate"), "no_estimate");
    assert_eq!(constant_name("NoEstimate"), "NO_ESTIMATE");
    assert!(field_name_ok("q_est") && !field_name_ok("q__est") && !field_name_ok("q_"));
}

#[test]
fn the_schema_is_the_model_rendered_and_the_package_is_a_parameter() {
    let shape = agent_core::reflect::<Kind>().unwrap();
    let ours = messages(&shape, "rex_msgs", "Kind").unwrap();
    assert_eq!(ours.name().to_string(), "rex_msgs/msg/Kind");
    let pair = MsgName::new("rex_msgs", "KindPair");
    let drive = MsgName::new("rex_msgs", "KindDrive");
    let names: Vec<_> = ours.referenced.iter().map(|m| &m.name).collect();
    assert_eq!(names, [&pair, &drive]);
    let constants: Vec<_> = ours
        .root
        .constants
        .iter()
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(constants, ["IDLE", "WAIT", "PAIR", "DRIVE"]);
    assert_eq!(
        ours.root.fields,
        [
            Field::new("variant", FieldType::primitive(Primitive::Uint32)),
            Field::new("wait", FieldType::primitive(Primitive::Int16).bounded(1)),
            Field::new("pair", FieldType::message(pair.clone()).bounded(1)),
            Field::new("drive", FieldType::message(drive).bounded(1)),
        ]
    );
    assert_eq!(ours.root.uses().len(), 2);
    assert_eq!(ours.get(&pair).map(|m| m.fields.len()), Some(2), "{ours:?}");
    // The recordings' package, rendered: the schema the recorder writes.
    let recorded = messages(&shape, PACKAGE, "Kind").unwrap();
    let schema = ros2msg_schema(&shape, "Kind").unwrap();
    assert_eq!(schema.text, recorded.msg_text());
    assert_eq!(schema.name, recorded.name().to_string());
    assert!(ours.msg_text().contains("rex_msgs/KindPair[<=1] pair\n"));
    assert!(ours.msg_text().contains("\nMSG: rex_msgs/KindDrive\n"));
}

#[test]
fn field_types_are_written_as_msg_files_write_them() {
    let header = MsgName::new("std_msgs", "Header");
    assert_eq!(header.to_string(), "std_msgs/msg/Header");
    assert_eq!(FieldType::message(header).to_string(), "std_msgs/Header");
    let f64s = FieldType::primitive(Primitive::Float64);
    assert_eq!(f64s.clone().array(9).to_string(), "float64[9]");
    assert_eq!(f64s.unbounded().to_string(), "float64[]");
    let short = FieldType {
        base: BaseType::String(Some(8)),
        arity: Arity::Bounded(2),
    };
    assert_eq!(short.to_string(), "string<=8[<=2]");
    assert_eq!(FieldType::primitive(Primitive::Byte).to_string(), "byte");
    let empty = Message::new(MsgName::new("p", "Empty"), Vec::new());
    assert_eq!(empty.msg_text(), "");
}
