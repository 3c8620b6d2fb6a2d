//! The standard ROS 2 messages a ROS user expects of a robot, each twice:
//! declared as a [`Message`] (package, name, fields, as in its `.msg` file of
//! ROS 2 Kilted) and as a Rust type whose serde form the recorder's mapping
//! ([`agent_mcap::cdr`]) encodes to exactly that message's CDR. A test checks
//! that the message made from each Rust type's shape is the declared one, so
//! the encoding and the type hash cannot drift apart.

use agent_core::Payload;
use agent_mcap::cdr::{Field, FieldType, Message, Messages, MsgName, Primitive};
use serde::{Deserialize, Serialize};

/// A Rust type that is a standard ROS 2 message.
pub trait StandardMessage: Payload {
    /// The message as declared in its package (its fields name the messages
    /// they use in their own packages).
    fn message() -> Message;

    /// The message and every standard message it uses, directly or not.
    fn messages() -> Messages {
        super::with_references(Self::message(), &standard_messages())
    }
}

/// Every standard message declared here, in no particular order.
pub fn standard_messages() -> Vec<Message> {
    vec![
        builtin_interfaces::Time::message(),
        std_msgs::Header::message(),
        geometry_msgs::Point::message(),
        geometry_msgs::Quaternion::message(),
        geometry_msgs::Pose::message(),
        geometry_msgs::PoseStamped::message(),
        geometry_msgs::Vector3::message(),
        nav_msgs::Path::message(),
        sensor_msgs::Imu::message(),
        sensor_msgs::CompressedImage::message(),
    ]
}

fn float64() -> FieldType {
    FieldType::primitive(Primitive::Float64)
}

fn nested(package: &str, name: &str) -> FieldType {
    FieldType::message(MsgName::new(package, name))
}

fn declare(package: &str, name: &str, fields: Vec<Field>) -> Message {
    Message::new(MsgName::new(package, name), fields)
}

/// `builtin_interfaces`: time.
pub mod builtin_interfaces {
    use super::*;

    /// `builtin_interfaces/msg/Time`: an instant as whole seconds \[s\] and
    /// nanoseconds \[ns\] since an epoch (the Unix one for wall-clock
    /// stamps).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
    pub struct Time {
        /// Seconds \[s\].
        pub sec: i32,
        /// Nanoseconds within the second \[ns\], below 10^9.
        pub nanosec: u32,
    }

    impl StandardMessage for Time {
        fn message() -> Message {
            declare(
                "builtin_interfaces",
                "Time",
                vec![
                    Field::new("sec", FieldType::primitive(Primitive::Int32)),
                    Field::new("nanosec", FieldType::primitive(Primitive::Uint32)),
                ],
            )
        }
    }
}

/// `std_msgs`: the header of stamped messages.
pub mod std_msgs {
    use super::builtin_interfaces::Time;
    use super::*;

    /// `std_msgs/msg/Header`: when a value was taken and in which frame.
    #[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
    pub struct Header {
        /// The instant the value stands for.
        pub stamp: Time,
        /// The coordinate frame (`map`, `base_link`).
        pub frame_id: String,
    }

    impl StandardMessage for Header {
        fn message() -> Message {
            declare(
                "std_msgs",
                "Header",
                vec![
                    Field::new("stamp", nested("builtin_interfaces", "Time")),
                    Field::new("frame_id", FieldType::string()),
                ],
            )
        }
    }
}

/// `geometry_msgs`: points, vectors, orientations and poses.
pub mod geometry_msgs {
    use super::std_msgs::Header;
    use super::*;

    /// `geometry_msgs/msg/Point`: a position \[m\].
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    #[allow(missing_docs, reason = "the coordinates")]
    pub struct Point {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    /// `geometry_msgs/msg/Vector3`: a vector (its unit is the field's: an
    /// angular velocity \[rad/s\], an acceleration \[m/s^2\]).
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    #[allow(missing_docs, reason = "the components")]
    pub struct Vector3 {
        pub x: f64,
        pub y: f64,
        pub z: f64,
    }

    /// `geometry_msgs/msg/Quaternion`: an orientation, `w` the scalar part;
    /// the default is the identity, as in ROS 2.
    #[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
    #[allow(missing_docs, reason = "the components")]
    pub struct Quaternion {
        pub x: f64,
        pub y: f64,
        pub z: f64,
        pub w: f64,
    }

    impl Default for Quaternion {
        fn default() -> Self {
            Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            }
        }
    }

    /// `geometry_msgs/msg/Pose`: a position and an orientation.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Pose {
        /// Where \[m\].
        pub position: Point,
        /// Which way.
        pub orientation: Quaternion,
    }

    /// `geometry_msgs/msg/PoseStamped`: a pose with its instant and frame.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct PoseStamped {
        /// When, and in which frame.
        pub header: Header,
        /// The pose.
        pub pose: Pose,
    }

    const PACKAGE: &str = "geometry_msgs";

    fn xyz() -> Vec<Field> {
        ["x", "y", "z"]
            .into_iter()
            .map(|n| Field::new(n, float64()))
            .collect()
    }

    impl StandardMessage for Point {
        fn message() -> Message {
            declare(PACKAGE, "Point", xyz())
        }
    }

    impl StandardMessage for Vector3 {
        fn message() -> Message {
            declare(PACKAGE, "Vector3", xyz())
        }
    }

    impl StandardMessage for Quaternion {
        fn message() -> Message {
            let mut fields = xyz();
            fields.push(Field::new("w", float64()));
            declare(PACKAGE, "Quaternion", fields)
        }
    }

    impl StandardMessage for Pose {
        fn message() -> Message {
            declare(
                PACKAGE,
                "Pose",
                vec![
                    Field::new("position", nested(PACKAGE, "Point")),
                    Field::new("orientation", nested(PACKAGE, "Quaternion")),
                ],
            )
        }
    }

    impl StandardMessage for PoseStamped {
        fn message() -> Message {
            declare(
                PACKAGE,
                "PoseStamped",
                vec![
                    Field::new("header", nested("std_msgs", "Header")),
                    Field::new("pose", nested(PACKAGE, "Pose")),
                ],
            )
        }
    }
}

/// `nav_msgs`: paths.
pub mod nav_msgs {
    use super::geometry_msgs::PoseStamped;
    use super::std_msgs::Header;
    use super::*;

    /// `nav_msgs/msg/Path`: poses for a robot to follow, in order.
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    pub struct Path {
        /// When, and the frame of the poses.
        pub header: Header,
        /// The poses.
        pub poses: Vec<PoseStamped>,
    }

    impl StandardMessage for Path {
        fn message() -> Message {
            declare(
                "nav_msgs",
                "Path",
                vec![
                    Field::new("header", nested("std_msgs", "Header")),
                    Field::new("poses", nested("geometry_msgs", "PoseStamped").unbounded()),
                ],
            )
        }
    }
}

/// `sensor_msgs`: an inertial measurement unit and compressed images.
pub mod sensor_msgs {
    use super::geometry_msgs::{Quaternion, Vector3};
    use super::std_msgs::Header;
    use super::*;

    /// `sensor_msgs/msg/Imu`: orientation, angular velocity \[rad/s\] and
    /// linear acceleration \[m/s^2\], each with its covariance (row major
    /// about x, y, z; a first element of -1 says the value is not given).
    #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
    #[allow(missing_docs, reason = "the fields of sensor_msgs/msg/Imu")]
    pub struct Imu {
        pub header: Header,
        pub orientation: Quaternion,
        pub orientation_covariance: [f64; 9],
        pub angular_velocity: Vector3,
        pub angular_velocity_covariance: [f64; 9],
        pub linear_acceleration: Vector3,
        pub linear_acceleration_covariance: [f64; 9],
    }

    /// `sensor_msgs/msg/CompressedImage`: an image in a compressed format
    /// (`png`, `jpeg`).
    #[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
    pub struct CompressedImage {
        /// When the image was taken, and the camera's optical frame.
        pub header: Header,
        /// The format (`png`, `jpeg`).
        pub format: String,
        /// The compressed image.
        pub data: Vec<u8>,
    }

    impl StandardMessage for Imu {
        fn message() -> Message {
            let covariance = || float64().array(9);
            let vector = || nested("geometry_msgs", "Vector3");
            declare(
                "sensor_msgs",
                "Imu",
                vec![
                    Field::new("header", nested("std_msgs", "Header")),
                    Field::new("orientation", nested("geometry_msgs", "Quaternion")),
                    Field::new("orientation_covariance", covariance()),
                    Field::new("angular_velocity", vector()),
                    Field::new("angular_velocity_covariance", covariance()),
                    Field::new("linear_acceleration", vector()),
                    Field::new("linear_acceleration_covariance", covariance()),
                ],
            )
        }
    }

    impl StandardMessage for CompressedImage {
        fn message() -> Message {
            declare(
                "sensor_msgs",
                "CompressedImage",
                vec![
                    Field::new("header", nested("std_msgs", "Header")),
                    Field::new("format", FieldType::string()),
                    Field::new("data", FieldType::primitive(Primitive::Uint8).unbounded()),
                ],
            )
        }
    }
}
