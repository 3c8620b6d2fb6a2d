//! rmw_zenoh's wire format.
