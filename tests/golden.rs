//! Golden digests of the outputs that define ahcmon's behaviour: `eval --json` of every
//! built-in scenario (timing left out), `sim` decisions, estimates and truth of every vehicle
//! scenario, `replay` decisions, estimates, plot and summary of every tlog, `calibrate`'s
//! profile, `thresholds`, and every `--help` text. A restructure must keep them
//! byte-identical; a change of behaviour updates `tests/golden/digests.txt` in the same
//! commit, with the reason in its message.
//!
//! `fast_subset` runs on every `cargo test`; `all` (ignored by default, it also reads the
//! external logs in `../shared/data`) through `tests/golden/recompute`, which with `--update`
//! rewrites the digests file.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;

const DIGESTS: &str = "tests/golden/digests.txt";

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// How a command's stdout is normalised before it is hashed.
#[derive(Clone, Copy)]
enum Stdout {
    AsIs,
    /// `eval --json`: the `us_per_step` timing is removed from every row.
    EvalJson,
    /// `replay`: its last line (`replayed FILE in X s`) is a timing.
    Replay,
}

struct Case {
    name: String,
    args: Vec<String>,
    /// Output files the command writes (file names inside the case's temp dir), each
    /// digested on its own.
    files: Vec<&'static str>,
    stdout: Stdout,
    fast: bool,
}

/// Built-in scenario names, as `ahcmon eval` lists them (the files in `replay/scenarios`
/// that are built in; `quad-x-1h` is a file only).
fn builtin_scenarios() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(root().join("replay/scenarios"))
        .expect("replay/scenarios")
        .map(|e| e.expect("dir entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .map(|p| p.file_stem().expect("stem").to_string_lossy().into_owned())
        .filter(|n| n != "quad-x-1h")
        .collect();
    names.sort();
    names
}

fn is_paper(name: &str) -> bool {
    name.starts_with("paper-") || name == "healthy-10min"
}

fn tlogs(dir: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e == "tlog") {
                out.push(p);
            }
        }
    }
    let mut out = vec![];
    walk(dir, &mut out);
    out.sort();
    out
}

fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// The external logs, beside the repository (read-only, not part of it).
fn shared_data() -> PathBuf {
    std::env::var_os("AHCMON_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("../shared/data"))
}

fn cases(with_shared: bool) -> Vec<Case> {
    let mut cases = vec![];
    let commands = [
        "eval",
        "thresholds",
        "sim",
        "monitor",
        "demo",
        "calibrate",
        "replay",
        "scan",
        "history",
    ];
    for flag in ["--help", "-h", "--version"] {
        cases.push(Case {
            name: format!("ahcmon {flag}"),
            args: s(&[flag]),
            files: vec![],
            stdout: Stdout::AsIs,
            fast: true,
        });
    }
    for c in commands {
        for flag in ["--help", "-h"] {
            cases.push(Case {
                name: format!("{c} {flag}"),
                args: s(&[c, flag]),
                files: vec![],
                stdout: Stdout::AsIs,
                fast: true,
            });
        }
    }
    let scenarios = builtin_scenarios();
    for n in &scenarios {
        cases.push(Case {
            name: format!("eval {n}"),
            args: s(&["eval", "--json", n]),
            files: vec![],
            stdout: Stdout::EvalJson,
            fast: true,
        });
        cases.push(Case {
            name: format!("eval {n} --seeds 3"),
            args: s(&["eval", "--json", "--seeds", "3", n]),
            files: vec![],
            stdout: Stdout::EvalJson,
            fast: false,
        });
    }
    cases.push(Case {
        name: "eval quad-x-1h.toml".into(),
        args: s(&["eval", "--json", "replay/scenarios/quad-x-1h.toml"]),
        files: vec![],
        stdout: Stdout::EvalJson,
        fast: false,
    });
    for n in ["paper-fig9-uniform-step", "heli-demo"] {
        cases.push(Case {
            name: format!("eval {n} --plot"),
            args: s(&["eval", "--json", "--plot", "plots", n]),
            files: vec!["plots"],
            stdout: Stdout::EvalJson,
            fast: false,
        });
    }
    cases.push(Case {
        name: "eval quad-x-motor2-loe --decisions --estimates".into(),
        args: s(&[
            "eval",
            "--json",
            "quad-x-motor2-loe",
            "--decisions",
            "decisions.jsonl",
            "--estimates",
            "estimates.jsonl",
            "--decimate",
            "3",
        ]),
        files: vec!["decisions.jsonl", "estimates.jsonl"],
        stdout: Stdout::EvalJson,
        fast: true,
    });
    for n in scenarios.iter().filter(|n| !is_paper(n)) {
        for seed in [None, Some("11"), Some("23")] {
            let mut args = s(&[
                "sim",
                "--scenario",
                n,
                "--decisions",
                "decisions.jsonl",
                "--estimates",
                "estimates.jsonl",
                "--truth",
                "truth.jsonl",
            ]);
            if let Some(seed) = seed {
                args.extend(s(&["--seed", seed]));
            }
            cases.push(Case {
                name: format!("sim {n} seed {}", seed.unwrap_or("default")),
                args,
                files: vec!["decisions.jsonl", "estimates.jsonl", "truth.jsonl"],
                stdout: Stdout::AsIs,
                fast: seed.is_none(),
            });
        }
    }
    cases.push(Case {
        name: "sim quad-x-motor2-loe --tlog --autopilot px4".into(),
        args: s(&[
            "sim",
            "--scenario",
            "quad-x-motor2-loe",
            "--tlog",
            "sim.tlog",
            "--truth",
            "truth.jsonl",
            "--autopilot",
            "px4",
        ]),
        files: vec!["sim.tlog", "truth.jsonl"],
        stdout: Stdout::AsIs,
        fast: true,
    });
    let mut logs: Vec<(PathBuf, bool)> = tlogs(&root().join("replay/tlogs"))
        .into_iter()
        .map(|p| (p, true))
        .collect();
    if with_shared {
        let shared = shared_data();
        let found = tlogs(&shared);
        assert!(
            !found.is_empty(),
            "no .tlog under {} (set AHCMON_SHARED_DATA to the external logs)",
            shared.display()
        );
        logs.extend(found.into_iter().map(|p| (p, false)));
    }
    for (log, fast) in logs {
        let rel = log
            .strip_prefix(root())
            .map(Path::to_path_buf)
            .unwrap_or(log.clone());
        let rel = rel.to_string_lossy().into_owned();
        cases.push(Case {
            name: format!("replay {rel}"),
            args: s(&[
                "replay",
                &rel,
                "--headless",
                "--decisions",
                "decisions.jsonl",
                "--estimates",
                "estimates.jsonl",
                "--plot",
                "plot.svg",
            ]),
            files: vec!["decisions.jsonl", "estimates.jsonl", "plot.svg"],
            stdout: Stdout::Replay,
            fast,
        });
    }
    for (log, until) in [
        (
            "sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog",
            "120",
        ),
        (
            "sitl_quadx_maneuvers_motor4_gain0p7/sitl_quadx_maneuvers_motor4_gain0p7.tlog",
            "95",
        ),
        (
            "sitl_heli_servo1_gain0p7/arducopter-heli_sitl_servo1_mul0.7.tlog",
            "90",
        ),
        (
            "sitl_heli_maneuvers_servo3_gain0p75/sitl_heli_maneuvers_servo3_gain0p75.tlog",
            "90",
        ),
    ] {
        let path = format!("replay/tlogs/{log}");
        cases.push(Case {
            name: format!("calibrate {log} --until {until}"),
            args: s(&["calibrate", &path, "--until", until, "-o", "profile.toml"]),
            files: vec!["profile.toml"],
            stdout: Stdout::AsIs,
            fast: true,
        });
    }
    cases.push(Case {
        name: "thresholds quad-x-healthy-gusts --seeds 2".into(),
        args: s(&[
            "thresholds",
            "--seeds",
            "2",
            "--json",
            "quad-x-healthy-gusts",
        ]),
        files: vec![],
        stdout: Stdout::AsIs,
        fast: true,
    });
    cases.push(Case {
        name: "thresholds --seeds 3".into(),
        args: s(&["thresholds", "--seeds", "3"]),
        files: vec![],
        stdout: Stdout::AsIs,
        fast: false,
    });
    cases
}

fn sha256(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

fn normalise(kind: Stdout, out: &str) -> String {
    match kind {
        Stdout::AsIs => out.to_string(),
        Stdout::EvalJson => {
            // The eval JSON array is the first thing on stdout; anything after it (the files
            // written) is kept as text.
            let (json, rest) = match out.find("\n]\n") {
                Some(end) => out.split_at(end + 3),
                None => (out, ""),
            };
            let mut rows: serde_json::Value = match serde_json::from_str(json) {
                Ok(v) => v,
                Err(_) => return out.to_string(),
            };
            if let Some(rows) = rows.as_array_mut() {
                for r in rows.iter_mut().filter_map(|r| r.as_object_mut()) {
                    r.remove("us_per_step");
                }
            }
            format!("{rows}\n{rest}")
        }
        Stdout::Replay => out
            .lines()
            .filter(|l| !l.starts_with("replayed "))
            .map(|l| format!("{l}\n"))
            .collect(),
    }
}

/// Digests of one case: its exit code and stdout, and each file it wrote.
fn run_case(case: &Case, tmp: &Path) -> Vec<(String, String)> {
    let dir = tmp.join(sha256(case.name.as_bytes()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("case dir");
    // Outputs are named inside the case dir; inputs relative to the repository root.
    let args: Vec<String> = case
        .args
        .iter()
        .map(|a| {
            if case.files.contains(&a.as_str()) {
                dir.join(a).to_string_lossy().into_owned()
            } else {
                a.clone()
            }
        })
        .collect();
    let out = Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .args(&args)
        .current_dir(root())
        .env_remove("RUST_LOG")
        .output()
        .expect("run ahcmon");
    let stdout = String::from_utf8_lossy(&out.stdout).replace(&*dir.to_string_lossy(), "<out>");
    let mut digests = vec![(
        format!("{} :: stdout", case.name),
        sha256(
            format!(
                "exit {:?}\n{}",
                out.status.code(),
                normalise(case.stdout, &stdout)
            )
            .as_bytes(),
        ),
    )];
    for f in &case.files {
        let p = dir.join(f);
        let bytes = if p.is_dir() {
            // A directory of plots: each file's name and contents, in name order.
            let mut names: Vec<PathBuf> = std::fs::read_dir(&p)
                .map(|r| r.flatten().map(|e| e.path()).collect())
                .unwrap_or_default();
            names.sort();
            let mut all = vec![];
            for n in names {
                all.extend(n.file_name().unwrap_or_default().as_encoded_bytes());
                all.push(0);
                all.extend(std::fs::read(&n).unwrap_or_default());
            }
            all
        } else {
            std::fs::read(&p).unwrap_or_else(|_| b"<missing>".to_vec())
        };
        digests.push((format!("{} :: {f}", case.name), sha256(&bytes)));
    }
    digests
}

fn committed() -> BTreeMap<String, String> {
    let text = std::fs::read_to_string(root().join(DIGESTS)).unwrap_or_default();
    text.lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .filter_map(|l| l.split_once("  "))
        .map(|(d, n)| (n.to_string(), d.to_string()))
        .collect()
}

fn check(fast_only: bool) {
    let update = std::env::var("AHCMON_GOLDEN").is_ok_and(|v| v == "update");
    if update && fast_only {
        // The update writes the whole set (`all`).
        return;
    }
    let tmp = common::temp_dir(if fast_only {
        "golden_fast"
    } else {
        "golden_all"
    });
    let cases = cases(!fast_only);
    let mut got = vec![];
    for c in cases.iter().filter(|c| c.fast || !fast_only) {
        got.extend(run_case(c, &tmp));
    }
    let want = committed();
    if update {
        let mut text = String::from(
            "# sha256 of ahcmon's outputs; tests/golden.rs says what each is, tests/golden/recompute recomputes them\n",
        );
        for (name, d) in &got {
            text += &format!("{d}  {name}\n");
        }
        std::fs::write(root().join(DIGESTS), text).expect("write digests");
        return;
    }
    let mut changed = vec![];
    for (name, d) in &got {
        match want.get(name) {
            Some(w) if w == d => {}
            Some(_) => changed.push(format!("changed: {name}")),
            None => changed.push(format!("no digest committed: {name}")),
        }
    }
    assert!(
        changed.is_empty(),
        "{} of {} outputs differ from {DIGESTS} (a change of behaviour: tests/golden/recompute --update, and say why in the commit):\n{}",
        changed.len(),
        got.len(),
        changed.join("\n")
    );
}

#[test]
fn fast_subset() {
    check(true);
}

#[test]
#[ignore = "the whole set, with the external logs: tests/golden/recompute"]
fn all() {
    check(false);
}
