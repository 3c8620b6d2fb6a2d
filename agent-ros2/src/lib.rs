//! Embodied agents on ROS 2, over rmw_zenoh (ROS 2 Kilted and later): the
//! buffers a spec shows to ROS 2 become topics that ROS 2 nodes discover,
//! subscribe to and publish on, with no ROS installation on our side.
//!
//! - [`types`]: ROS 2 message types as data: the type descriptions of REP 2011,
//!   their `RIHS01_` hashes, the messages made from a buffer type (the
//!   recorder's `ros2msg` schemas) and the standard messages a ROS user
//!   expects (`geometry_msgs/msg/PoseStamped`, `nav_msgs/msg/Path`, ...).
//! - [`wire`]: rmw_zenoh's wire format: key expressions, the attachment of
//!   every sample, liveliness tokens for discovery, QoS, name mangling.
//! - [`bridge`]: the buffers a spec publishes, put on their topics from a
//!   run's observer without blocking its nodes, with the tokens that make
//!   ROS 2 tools discover them.

pub mod access;
pub mod bridge;
pub mod package;
pub mod types;
pub mod wire;
