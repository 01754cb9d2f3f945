//! Generates the MAVLink dialect `ahcmon` (ardupilotmega + common + our AHC_ESTIMATE) from
//! `dialects/ahcmon.xml` with mavlink-bindgen; `src/protocol/mod.rs` includes the result.
use mavlink_bindgen::{XmlDefinitions, emit_cargo_build_messages, generate};
use std::path::PathBuf;

fn main() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR");
    let dir = PathBuf::from(manifest).join("dialects");
    let out = std::env::var("OUT_DIR").expect("cargo sets OUT_DIR");
    // Only the top file: its <include>s are merged into the one module `ahcmon`.
    let result = generate(XmlDefinitions::Files(vec![dir.join("ahcmon.xml")]), out)
        .unwrap_or_else(|e| panic!("mavlink-bindgen on dialects/ahcmon.xml: {e}"));
    emit_cargo_build_messages(&result);
    for entry in std::fs::read_dir(&dir).expect("dialects/ exists").flatten() {
        println!("cargo:rerun-if-changed={}", entry.path().display());
    }
}
