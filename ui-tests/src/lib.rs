//! Nothing to use: this crate holds the macros' UI tests (`tests/macros_ui.rs`, the
//! programs and the errors expected of them in `tests/ui/`). They live apart from the
//! root package so that trybuild builds them against `embodied` with its default
//! features only (see `Cargo.toml`).
