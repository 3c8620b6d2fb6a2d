//! The standard Rust types encode to their declared messages, the type
//! descriptions follow REP 2011's rules (field type ids, capacities, the
//! empty message's field, the canonical JSON's form) and the CDR of a
//! standard value is laid out as ROS 2 lays it out. (Their hashes against the
//! official ones, and rosbags' reading of the CDR: `tests/types_interop.rs`.)

use super::standard::builtin_interfaces::Time;
use super::standard::geometry_msgs::{Point, Pose, PoseStamped, Quaternion, Vector3};
use super::standard::nav_msgs::Path;
use super::standard::sensor_msgs::{CompressedImage, Imu};
use super::standard::std_msgs::Header;
use super::standard::{StandardMessage, standard_messages};
use super::*;
use sha2::Digest;

/// The messages made from `T`'s shape by the recorder's mapping, each named
/// as the standard message of the same name.
fn made_from_shape<T: StandardMessage>() -> Messages {
    let declared = T::message().name;
    let shape = agent_core::reflect::<T>().unwrap();
    let made = messages(&shape, &declared.package, &declared.name).unwrap();
    let catalog = standard_messages();
    let mut made = made.renamed(|n| {
        catalog
            .iter()
            .find(|m| m.name.name == n.name)
            .map_or_else(|| n.clone(), |m| m.name.clone())
    });
    made.referenced.sort_by(|a, b| a.name.cmp(&b.name));
    made
}

fn same_as_declared<T: StandardMessage>() {
    let declared = T::messages();
    assert_eq!(made_from_shape::<T>(), declared, "{}", declared.name());
    // Complete: every message it uses is declared.
    TypeDescription::of(&declared).unwrap();
}

#[test]
fn each_standard_type_encodes_as_its_declared_message() {
    same_as_declared::<Time>();
    same_as_declared::<Header>();
    same_as_declared::<Point>();
    same_as_declared::<Quaternion>();
    same_as_declared::<Pose>();
    same_as_declared::<PoseStamped>();
    same_as_declared::<Vector3>();
    same_as_declared::<Path>();
    same_as_declared::<Imu>();
    same_as_declared::<CompressedImage>();
    assert_eq!(standard_messages().len(), 10);
}

#[test]
fn a_description_holds_every_message_reached_sorted_by_name() {
    let path = TypeDescription::of(&Path::messages()).unwrap();
    assert_eq!(path.type_description.type_name, "nav_msgs/msg/Path");
    let names: Vec<_> = path
        .referenced_type_descriptions
        .iter()
        .map(|t| t.type_name.as_str())
        .collect();
    assert_eq!(
        names,
        [
            "builtin_interfaces/msg/Time",
            "geometry_msgs/msg/Point",
            "geometry_msgs/msg/Pose",
            "geometry_msgs/msg/PoseStamped",
            "geometry_msgs/msg/Quaternion",
            "std_msgs/msg/Header",
        ]
    );
    let poses = &path.type_description.fields[1];
    assert_eq!(poses.name, "poses");
    // A nested type's unbounded sequence: 1 + 144.
    assert_eq!(
        poses.ty,
        FieldTypeDescription {
            type_id: 145,
            capacity: 0,
            string_capacity: 0,
            nested_type_name: "geometry_msgs/msg/PoseStamped".into(),
        }
    );
    // A message missing from the set is named.
    let mut broken = Path::messages();
    broken.referenced.retain(|m| m.name.name != "Quaternion");
    let e = TypeDescription::of(&broken).unwrap_err();
    assert!(
        e.to_string()
            .contains("`orientation` of `geometry_msgs/msg/Pose`")
            && e.to_string().contains("geometry_msgs/msg/Quaternion"),
        "{e}"
    );
}

#[test]
fn field_type_ids_capacities_and_the_empty_message_follow_rep_2011() {
    let p = |p| FieldType::primitive(p);
    let empty = MsgName::new("pkg", "Nothing");
    let root = Message::new(
        MsgName::new("pkg", "Kinds"),
        vec![
            Field::new("a", p(Primitive::Bool)),
            Field::new("b", p(Primitive::Byte)),
            Field::new("c", p(Primitive::Char)),
            Field::new("d", p(Primitive::Float32).array(3)),
            Field::new("e", p(Primitive::Int64).bounded(5)),
            Field::new(
                "f",
                FieldType {
                    base: BaseType::String(Some(8)),
                    arity: Arity::Unbounded,
                },
            ),
            Field::new("g", FieldType::string().bounded(2)),
            Field::new("h", FieldType::message(empty.clone()).array(4)),
            Field::new("i", p(Primitive::Uint16)),
        ],
    );
    let set = with_references(root, &[Message::new(empty, Vec::new())]);
    let d = TypeDescription::of(&set).unwrap();
    let ids: Vec<_> = d
        .type_description
        .fields
        .iter()
        .map(|f| (f.ty.type_id, f.ty.capacity, f.ty.string_capacity))
        .collect();
    assert_eq!(
        ids,
        [
            (15, 0, 0),
            (16, 0, 0),
            (3, 0, 0),
            (10 + 48, 3, 0),
            (8 + 96, 5, 0),
            (21 + 144, 0, 8),
            (17 + 96, 2, 0),
            (1 + 48, 4, 0),
            (5, 0, 0)
        ]
    );
    // An empty message has ROS 2's one `uint8` field.
    let nothing = &d.referenced_type_descriptions[0];
    assert_eq!(nothing.type_name, "pkg/msg/Nothing");
    assert_eq!(nothing.fields.len(), 1);
    assert_eq!(nothing.fields[0].name, EMPTY_MESSAGE_FIELD);
    assert_eq!(nothing.fields[0].ty.type_id, 3);
}

#[test]
fn the_canonical_json_is_pythons_with_its_separators_and_the_hash_its_sha_256() {
    let time = TypeDescription::of(&Time::messages()).unwrap();
    let field = |name: &str, id: u8| {
        format!(
            "{{\"name\": \"{name}\", \"type\": {{\"type_id\": {id}, \"capacity\": 0, \
             \"string_capacity\": 0, \"nested_type_name\": \"\"}}}}"
        )
    };
    let expected = format!(
        "{{\"type_description\": {{\"type_name\": \"builtin_interfaces/msg/Time\", \
         \"fields\": [{}, {}]}}, \"referenced_type_descriptions\": []}}",
        field("sec", 6),
        field("nanosec", 7)
    );
    assert_eq!(time.canonical_json(), expected);
    let digest = sha2::Sha256::digest(expected.as_bytes());
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(time.hash().to_string(), format!("RIHS01_{hex}"));
    assert_eq!(type_hash(&Time::messages()).unwrap(), time.hash());
    // Non-ASCII as `json.dumps` escapes it (UTF-16 units), quotes escaped.
    let odd = Message::new(
        MsgName::new("pkg", "Caf\u{e9}\u{1f600}\u{7f}\""),
        vec![Field::new("x", FieldType::primitive(Primitive::Uint8))],
    );
    let json = TypeDescription::of(&with_references(odd, &[]))
        .unwrap()
        .canonical_json();
    assert!(
        json.contains(r#""type_name": "pkg/msg/Caf\u00e9\ud83d\ude00\u007f\"""#),
        "{json}"
    );
}

#[test]
fn a_standard_value_encodes_as_ros_2_lays_it_out() {
    let v = PoseStamped {
        header: Header {
            stamp: Time {
                sec: -2,
                nanosec: 500,
            },
            frame_id: "map".into(),
        },
        pose: Pose {
            position: Point {
                x: 1.0,
                y: 2.0,
                z: 3.0,
            },
            orientation: Quaternion::default(),
        },
    };
    let mut out = Vec::new();
    encode_cdr(&v, &agent_core::reflect::<PoseStamped>().unwrap(), &mut out).unwrap();
    let mut expected = vec![0, 1, 0, 0];
    expected.extend((-2i32).to_le_bytes()); // sec at 0
    expected.extend(500u32.to_le_bytes()); // nanosec at 4
    expected.extend(4u32.to_le_bytes()); // "map" and its NUL at 8
    expected.extend(b"map\0"); // 12..16
    for x in [1.0f64, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
        expected.extend(x.to_le_bytes()); // 16.., aligned to 8
    }
    assert_eq!(out, expected);
    // The identity is ROS 2's default orientation.
    assert_eq!(Quaternion::default().w, 1.0);
}

/// Published test vectors, pinned so that `cargo test` checks our hashes
/// against ROS 2's offline (the interop test compares every standard message
/// with the official wheels at run time).
#[test]
fn the_published_type_hashes_are_ours() {
    // rmw_zenoh's design document (docs/design.md of rmw_zenoh 0.6.7): the
    // hash in its example keys and tokens of `std_msgs/msg/String`.
    let string = Message::new(
        MsgName::new("std_msgs", "String"),
        vec![Field::new("data", FieldType::string())],
    );
    assert_eq!(
        type_hash(&with_references(string, &[]))
            .unwrap()
            .to_string(),
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    );
    // The official ROS 2 Kilted wheel `ros-builtin-interfaces` 2.3.0, its
    // `share/builtin_interfaces/msg/Time.json` (`type_hashes`).
    assert_eq!(
        type_hash(&Time::messages()).unwrap().to_string(),
        "RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197"
    );
}
