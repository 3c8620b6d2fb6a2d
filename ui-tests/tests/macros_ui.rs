//! Compile-fail tests of the macros, by category: each `tests/ui/<category>/*.rs`
//! must fail to compile with the error in its `.stderr` file, which is what a user
//! sees. `tests/ui/pass` must compile and run.
//!
//! After changing a message on purpose: `TRYBUILD=overwrite cargo test -p
//! embodied-ui-tests`, then read the new `.stderr` files before committing them.

#[test]
fn programs_using_the_macros_correctly_compile_and_run() {
    trybuild::TestCases::new().pass("tests/ui/pass/*.rs");
}

#[test]
fn unknown_buffer() {
    trybuild::TestCases::new().compile_fail("tests/ui/unknown_buffer/*.rs");
}

#[test]
fn wrong_function_signature() {
    trybuild::TestCases::new().compile_fail("tests/ui/wrong_signature/*.rs");
}

#[test]
fn spec_with_a_checker_error() {
    trybuild::TestCases::new().compile_fail("tests/ui/checker_error/*.rs");
}

#[test]
fn missing_transition_function() {
    trybuild::TestCases::new().compile_fail("tests/ui/missing_function/*.rs");
}

#[test]
fn duplicate_behaviour() {
    trybuild::TestCases::new().compile_fail("tests/ui/duplicate_behaviour/*.rs");
}

#[test]
fn misused_derives() {
    trybuild::TestCases::new().compile_fail("tests/ui/derive/*.rs");
}
