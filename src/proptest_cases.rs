//! How many cases the library's property tests run: the suite's own count, or
//! `PROPTEST_CASES` from the environment for a deeper run. A count written into a
//! `ProptestConfig` would otherwise ignore it. The integration tests include this file too
//! (`tests/common/mod.rs`).

/// `PROPTEST_CASES` from the environment when it is set to a number, else `default`.
pub(crate) fn cases_or(default: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}
