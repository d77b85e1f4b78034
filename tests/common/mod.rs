//! Helpers shared by the integration tests. Each test file is its own crate and includes this
//! module whole, using only a part of it.
#![allow(dead_code)]

pub mod damage;

// The library's own helper, compiled into each test crate (a `cfg(test)` item of the library is
// not built for integration tests): one definition of how the suites read `PROPTEST_CASES`.
#[path = "../../src/proptest_cases.rs"]
mod proptest_cases;
pub(crate) use proptest_cases::cases_or;
