//! Fuzzes the opentrack decoder: arbitrary length-prefixed datagrams (see
//! `leman::devices::fuzz_harness::fuzz_decoder` for the invariants checked).
#![no_main]

use leman::devices::fuzz_harness::fuzz_decoder;
use leman::devices::protocol::Protocol;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| fuzz_decoder(Protocol::Opentrack, data));
