//! Procedural macros for embodied-agents.
//!
//! This crate will hold the derives for buffer and memory structs, the behaviour and
//! FSM DSL, and the code generated from RON specifications. It only parses, checks
//! and generates code; every semantic lives in `agent-core`.
