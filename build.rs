//! Generates the MAVLink dialect `ahcmon` (ardupilotmega + common + our AHC_ESTIMATE) from
//! `dialects/ahcmon.xml` with mavlink-bindgen; `src/protocol/mod.rs` includes the result.
use mavlink_bindgen::{XmlDefinitions, emit_cargo_build_messages, generate};
use std::path::PathBuf;
use std::process::ExitCode;

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("build.rs: {e}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), String> {
    let var = |name: &str| std::env::var(name).map_err(|e| format!("{name}: {e}"));
    let dir = PathBuf::from(var("CARGO_MANIFEST_DIR")?).join("dialects");
    let out = var("OUT_DIR")?;
    // Only the top file: its <include>s are merged into the one module `ahcmon`.
    let result = generate(XmlDefinitions::Files(vec![dir.join("ahcmon.xml")]), out)
        .map_err(|e| format!("mavlink-bindgen on dialects/ahcmon.xml: {e}"))?;
    emit_cargo_build_messages(&result);
    let entries = std::fs::read_dir(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    for entry in entries.flatten() {
        println!("cargo:rerun-if-changed={}", entry.path().display());
    }
    Ok(())
}
