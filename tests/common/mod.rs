//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// The Python with the reference packages: `AHCMON_PYTHON`, else the project's `.venv`
/// (what `.ci/run` creates), else `python3`.
pub fn python() -> PathBuf {
    if let Ok(p) = std::env::var("AHCMON_PYTHON") {
        return PathBuf::from(p);
    }
    let venv = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python");
    if venv.exists() {
        venv
    } else {
        PathBuf::from("python3")
    }
}

/// Run a reference script; a missing interpreter or package fails the test with the fix in the message.
/// Returns the script's standard output.
pub fn run_python(args: &[&str]) -> String {
    let py = python();
    let out = Command::new(&py)
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "cannot run {}: {e}; run `bash .ci/run` once (it creates .venv)",
                py.display()
            )
        });
    assert!(
        out.status.success(),
        "{} {:?} failed: {}\n(the references need tests/reference/requirements.txt: `bash .ci/run` installs them into .venv)",
        py.display(),
        args,
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

pub fn temp_dir(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A log under `replay/tlogs` (copies of `../shared/data`, with their SOURCE.md).
pub fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("replay/tlogs")
        .join(rel)
}
