//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// The Python with the reference packages: `AHCMON_PYTHON`, else the project's `.venv`,
/// created (and brought up to date with `tests/reference/requirements*.txt`) on first use,
/// so that `cargo test --release` on a fresh machine needs only Python 3 and PyPI. A
/// reference that cannot be installed fails the test that needs it, with the reason.
pub fn python() -> PathBuf {
    if let Ok(p) = std::env::var("AHCMON_PYTHON") {
        return PathBuf::from(p);
    }
    static READY: std::sync::OnceLock<Result<PathBuf, String>> = std::sync::OnceLock::new();
    match READY.get_or_init(reference_venv) {
        Ok(p) => p.clone(),
        Err(e) => panic!("{e}"),
    }
}

/// `.venv` with the reference packages; one test process at a time sets it up (a file lock),
/// the others wait and find it ready (a stamp of the requirements it holds).
fn reference_venv() -> Result<PathBuf, String> {
    use std::io::Write;
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let venv = root.join(".venv");
    let py = venv.join("bin/python");
    let reqs = root.join("tests/reference/requirements.txt");
    let nodeps = root.join("tests/reference/requirements-nodeps.txt");
    let read =
        |p: &PathBuf| std::fs::read_to_string(p).map_err(|e| format!("{}: {e}", p.display()));
    let want = format!("{}\n--no-deps\n{}", read(&reqs)?, read(&nodeps)?);
    let stamp = venv.join("ahcmon-references.txt");
    let lock_path = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("reference-venv.lock");
    let lock =
        std::fs::File::create(&lock_path).map_err(|e| format!("{}: {e}", lock_path.display()))?;
    lock.lock()
        .map_err(|e| format!("locking {}: {e}", lock_path.display()))?;
    if py.exists() && std::fs::read_to_string(&stamp).is_ok_and(|s| s == want) {
        return Ok(py);
    }
    // Said on the terminal, not captured: the first run waits for the download.
    let _ = writeln!(
        std::io::stderr().lock(),
        "tests: installing the Python references into {} (tests/reference/requirements*.txt; about a minute, once)",
        venv.display()
    );
    let run = |cmd: &mut Command, what: &str| -> Result<(), String> {
        let out = cmd
            .output()
            .map_err(|e| format!("{what}: cannot run {:?}: {e}", cmd.get_program()))?;
        if out.status.success() {
            Ok(())
        } else {
            Err(format!(
                "{what} failed ({}): {}{}\nThe tests that compare against filterpy, pymavlink and MAVProxy need Python 3 with venv and access to PyPI, or AHCMON_PYTHON naming a Python that has tests/reference/requirements.txt",
                out.status,
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            ))
        }
    };
    if !py.exists() {
        run(
            Command::new("python3").args(["-m", "venv"]).arg(&venv),
            "python3 -m venv .venv",
        )?;
    }
    let pip = |extra: &[&str], file: &PathBuf| {
        let mut c = Command::new(&py);
        c.args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
        ])
        .args(["--prefer-binary"])
        .args(extra)
        .arg("-r")
        .arg(file);
        c
    };
    run(
        &mut pip(&[], &reqs),
        "pip install -r tests/reference/requirements.txt",
    )?;
    run(
        &mut pip(&["--no-deps"], &nodeps),
        "pip install --no-deps -r tests/reference/requirements-nodeps.txt",
    )?;
    std::fs::write(&stamp, want).map_err(|e| format!("{}: {e}", stamp.display()))?;
    Ok(py)
}

/// Run a reference script; a missing interpreter or package fails the test with the fix in the message.
/// Returns the script's standard output.
pub fn run_python(args: &[&str]) -> String {
    let py = python();
    let out = Command::new(&py)
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap_or_else(|e| panic!("cannot run {}: {e}", py.display()));
    assert!(
        out.status.success(),
        "{} {:?} failed: {}\n(the references are tests/reference/requirements*.txt)",
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

/// `ahcmon ARGS`: exit code, stdout, stderr.
pub fn ahcmon(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
