//! ROS 2 message types as data (REP 2011).
