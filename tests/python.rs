//! The Python package (`pip install ./python`, PyO3 + maturin) and its Dask example: the same
//! rows as `ahcmon scan` on the same logs, and the same history as `ahcmon history --json`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::ahcmon;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Build the package with pip (maturin from the reference requirements, on the PATH the
/// build hook looks it up in) into a folder of this build's, not into the reference Python's
/// environment; the Python to run it with and that folder, for `PYTHONPATH`. One build at a
/// time (a file lock), once per test process.
fn install_package() -> (PathBuf, PathBuf) {
    static INSTALLED: std::sync::OnceLock<(PathBuf, PathBuf)> = std::sync::OnceLock::new();
    INSTALLED.get_or_init(install).clone()
}

fn install() -> (PathBuf, PathBuf) {
    let py = common::python();
    let target = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("python-package");
    let lock = std::fs::File::create(target.with_extension("lock")).unwrap();
    lock.lock().unwrap();
    let bin = py.parent().unwrap();
    let path = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );
    let out = Command::new(&py)
        .args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "--no-build-isolation",
            "--no-deps",
            "--upgrade",
            "--target",
        ])
        .arg(&target)
        .arg("./python")
        .env("PATH", path)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "pip install ./python failed: {}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (py, target)
}

/// The package's Python, with the package on its path.
fn python(args: &[&str]) -> std::process::Output {
    let (py, target) = install_package();
    Command::new(py)
        .args(args)
        .env("PYTHONPATH", target)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap()
}

fn rows(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

#[test]
fn the_dask_example_gives_scan_s_rows_and_history() {
    let dir = common::temp_dir("python_dask");
    let archive = dir.join("archive");
    let tlogs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("replay/tlogs");
    // The repository's logs, and one that is not a log, which both name and go past.
    let status = Command::new("cp")
        .arg("-r")
        .arg(&tlogs)
        .arg(&archive)
        .status()
        .unwrap();
    assert!(status.success());
    std::fs::write(archive.join("mavlink/zz-not-a-log.tlog"), b"not a log\n").unwrap();
    // Named as a user would from the project: relative, with `./`, and a glob naming nothing.
    let relative = archive
        .strip_prefix(env!("CARGO_MANIFEST_DIR"))
        .map(|p| Path::new(".").join(p))
        .unwrap_or(archive.clone());
    let (archive_arg, nothing) = (
        relative.to_str().unwrap().to_string(),
        format!("{}/*/none-*.tlog", relative.display()),
    );

    let scan_rows = dir.join("scan.jsonl");
    let (code, _, err) = ahcmon(&[
        "scan",
        &archive_arg,
        &nothing,
        "--rows",
        scan_rows.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{err}");
    let dask_rows = dir.join("dask.jsonl");
    let out = python(&[
        "python/examples/dask_archive.py",
        &archive_arg,
        &nothing,
        "--workers",
        "2",
        "--rows",
        dask_rows.to_str().unwrap(),
    ]);
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert_eq!(out.status.code(), Some(1), "{stdout}{stderr}");
    assert!(
        stderr.contains("zz-not-a-log.tlog: no MAVLink frame"),
        "{stderr}"
    );
    assert!(
        stdout.contains("rows, 1 could not be read, 1 paths named nothing"),
        "{stdout}"
    );
    let (ours, theirs) = (rows(&scan_rows), rows(&dask_rows));
    assert!(ours.len() >= 12, "{} rows", ours.len());
    assert_eq!(ours, theirs, "scan's rows and the Dask example's differ");
    assert!(stdout.contains("rows, 1 could not be read"), "{stdout}");

    // The package's history of the rows is the CLI's.
    let cli_history = dir.join("history.json");
    let (code, _, err) = ahcmon(&[
        "history",
        scan_rows.to_str().unwrap(),
        "--json",
        cli_history.to_str().unwrap(),
        "--window",
        "4",
    ]);
    assert_eq!(code, 0, "{err}");
    let out = python(&[
        "-c",
        "import ahcmon, json, sys\nrows = [json.loads(l) for l in open(sys.argv[1])]\nprint(json.dumps({'series': ahcmon.history(rows, window=4)}))",
        scan_rows.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let package: Value = serde_json::from_slice(&out.stdout).unwrap();
    let cli: Value = serde_json::from_str(&std::fs::read_to_string(&cli_history).unwrap()).unwrap();
    assert!(!cli["series"].as_array().unwrap().is_empty());
    assert_eq!(package, cli);
}

/// Errors as Python expects them: a missing log is FileNotFoundError, a file that is no log
/// and bad arguments are ValueError, each with the reason.
#[test]
fn the_package_raises_python_s_errors_with_the_reason() {
    let out = python(&[
        "-c",
        r#"
import ahcmon
def raises(kind, f, *a, **k):
    try:
        f(*a, **k)
    except kind as e:
        print(type(e).__name__, e)
        return
    raise SystemExit(f"no {kind.__name__} from {a} {k}")
raises(FileNotFoundError, ahcmon.replay, "no/such.tlog")
raises(ValueError, ahcmon.replay, "README.md")
raises(ValueError, ahcmon.replay, "README.md", profile="no-such-profile")
raises(ValueError, ahcmon.history, [], window=2)
raises(ValueError, ahcmon.history, {"not": "a list"})
print("rows of nothing:", ahcmon.history([]))
"#,
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for want in [
        "FileNotFoundError no/such.tlog: no such file",
        "ValueError README.md: no MAVLink frame of a known message",
        "ValueError no profile file or built-in profile named `no-such-profile`",
        "ValueError window must be in [4, 1000], not 2",
        "ValueError rows must be a list of dicts",
        "rows of nothing: []",
    ] {
        assert!(stdout.contains(want), "{want:?} not in:\n{stdout}");
    }
}
