//! Helpers shared by the integration tests. Each test file is its own crate and includes this
//! module whole, using only a part of it.
#![allow(dead_code)]

pub mod damage;

/// `PROPTEST_CASES` from the environment when set (for a deeper run than the suite's), else
/// `default`: `ProptestConfig::with_cases` would otherwise ignore it.
pub fn cases_or(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}
