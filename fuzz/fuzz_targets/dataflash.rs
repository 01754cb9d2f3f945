#![no_main]
libfuzzer_sys::fuzz_target!(|data: &[u8]| ahcmon::fuzzing::dataflash(data));
