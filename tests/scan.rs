//! `ahcmon scan`: many logs in one command, on several threads, rows per flight × actuator;
//! bad inputs named, the rest go on.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::ahcmon;
use serde_json::Value;
use std::path::PathBuf;

fn rows(text: &str) -> Vec<Value> {
    text.lines()
        .map(|l| serde_json::from_str(l).expect("each line is one JSON object"))
        .collect()
}

fn tlogs() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("replay/tlogs")
}

/// The repository's tlogs with a corrupt one and a missing path among them: every good log's
/// rows, the bad ones named with their reason, exit 1; the same rows on one thread as on two,
/// byte for byte.
#[test]
fn a_directory_of_logs_with_a_bad_one_gives_every_good_log_s_rows() {
    let dir = common::temp_dir("scan_dir");
    let bad = dir.join("noise.tlog");
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    let noise: Vec<u8> = (0..50_000)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x as u8
        })
        .collect();
    std::fs::write(&bad, noise).unwrap();
    let missing = dir.join("none.tlog");
    let outs: Vec<(i32, String, String)> = ["1", "2"]
        .iter()
        .map(|jobs| {
            let file = dir.join(format!("rows-{jobs}.jsonl"));
            let (code, _, err) = ahcmon(&[
                "scan",
                tlogs().to_str().unwrap(),
                bad.to_str().unwrap(),
                missing.to_str().unwrap(),
                "--jobs",
                jobs,
                "--rows",
                file.to_str().unwrap(),
            ]);
            (code, std::fs::read_to_string(&file).unwrap(), err)
        })
        .collect();
    let (code, text, err) = &outs[0];
    assert_eq!(*code, 1, "{err}");
    assert_eq!(text, &outs[1].1, "one thread and two differ");
    assert!(
        err.contains("noise.tlog: no MAVLink frame of a known message"),
        "{err}"
    );
    assert!(
        err.contains("none.tlog: no such file or directory"),
        "{err}"
    );
    assert!(
        err.contains("1 logs or directories could not be read and 1 paths named nothing"),
        "{err}"
    );
    let rows = rows(text);
    // Each of the four SITL logs: one row per actuator of its vehicle (4 motors, 4 servos).
    for sitl in [
        "sitl_heli_maneuvers_servo3_gain0p75",
        "sitl_heli_servo1_gain0p7",
        "sitl_quad_motor1_gain0p7",
        "sitl_quadx_maneuvers_motor4_gain0p7",
    ] {
        let of: Vec<&Value> = rows
            .iter()
            .filter(|r| r["file"].as_str().unwrap().contains(sitl))
            .collect();
        assert_eq!(of.len(), 4, "{sitl}: {of:?}");
        for r in &of {
            assert!(r["start_unix_us"].as_u64().unwrap() > 1_600_000_000_000_000);
            let g = r["mit_ukf"]["gamma"].as_f64().unwrap();
            assert!((0.3..1.5).contains(&g), "{sitl}: {r}");
            assert!(r["mit_ukf"]["gamma_lo"].as_f64().unwrap() <= g);
            assert!(r["mit_ukf"]["gamma_hi"].as_f64().unwrap() >= g);
        }
    }
    // In the order named: the directory's logs sorted by path.
    let files: Vec<&str> = rows.iter().map(|r| r["file"].as_str().unwrap()).collect();
    let mut sorted = files.clone();
    sorted.sort();
    assert_eq!(files, sorted);
}

/// A simulated flight whose truth is known (`quad-x-motor2-loe-live`: a quad in gusts with
/// 10 % damping mismatch, healthy, then motor 2 at gamma 0.7 from t = 45 s on the vehicle's
/// clock). Each row's medians are those of the filter's own estimates, as `replay
/// --estimates` writes them, taken by Python (`statistics.median_low`, to the histogram's bin
/// of 0.001). Against the truth: no fault on the healthy motors, motor 2's after its onset,
/// and its median gamma within 0.05 of 0.7, the truth over most of the estimated steps.
#[test]
fn a_simulated_flight_s_rows_are_its_estimates_medians() {
    let dir = common::temp_dir("scan_sim");
    let (tlog, estimates) = (dir.join("quad.tlog"), dir.join("estimates.jsonl"));
    let (code, _, err) = ahcmon(&[
        "sim",
        "--scenario",
        "quad-x-motor2-loe-live",
        "--tlog",
        tlog.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = ahcmon(&[
        "replay",
        tlog.to_str().unwrap(),
        "--estimates",
        estimates.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{err}");
    let reference: Value = serde_json::from_str(&common::run_python(&[
        "-c",
        r#"
import collections, json, statistics, sys
series = collections.defaultdict(list)
for line in open(sys.argv[1]):
    e = json.loads(line)
    if e["filter"] != "mit-ukf":
        continue
    for a in e["actuators"]:
        for k in ("gamma", "gamma_lo", "gamma_hi", "delta", "delta_lo", "delta_hi"):
            series[a["name"] + " " + k].append(a[k])
print(json.dumps({k: statistics.median_low(v) for k, v in series.items()}))
"#,
        estimates.to_str().unwrap(),
    ]))
    .unwrap();
    let (code, out, err) = ahcmon(&["scan", tlog.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let rows = rows(&out);
    assert_eq!(rows.len(), 4, "{out}");
    for r in &rows {
        let name = r["actuator"].as_str().unwrap();
        for k in [
            "gamma", "gamma_lo", "gamma_hi", "delta", "delta_lo", "delta_hi",
        ] {
            let (ours, python) = (
                r["mit_ukf"][k].as_f64().unwrap(),
                reference[format!("{name} {k}")].as_f64().unwrap(),
            );
            assert!(
                (ours - python).abs() <= 1e-3,
                "{name} {k}: {ours} against {python}"
            );
        }
        let faults = r["faults"].as_u64().unwrap();
        if name == "motor2" {
            assert!(faults >= 1, "{r}");
            assert!(r["first_fault_t"].as_f64().unwrap() >= 45.0, "{r}");
            let g = r["mit_ukf"]["gamma"].as_f64().unwrap();
            assert!((g - 0.7).abs() < 0.05, "motor2: median gamma {g}");
        } else {
            assert_eq!(faults, 0, "{r}");
        }
    }
}

/// Nothing to scan is the command line's mistake (exit 2): an empty directory, paths that
/// name nothing; an output that would replace an input is refused (exit 2); a scan that
/// writes no row leaves no earlier rows behind.
#[test]
fn nothing_to_scan_is_exit_2() {
    let dir = common::temp_dir("scan_empty");
    let (code, _, err) = ahcmon(&["scan", dir.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no log in"), "{err}");
    let typo = dir.join("typo");
    let (code, _, err) = ahcmon(&["scan", typo.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("typo: no such file or directory"), "{err}");
    // A log without a vehicle's samples: no row, and yesterday's rows gone.
    let quiet = dir.join("quiet.tlog");
    let log = std::fs::read(common::data("mavlink/rust-mavlink-log.tlog")).unwrap();
    std::fs::write(&quiet, &log[..log.len().min(200)]).unwrap();
    let rows = dir.join("rows.jsonl");
    std::fs::write(&rows, "yesterday\n").unwrap();
    let (code, _, err) = ahcmon(&[
        "scan",
        quiet.to_str().unwrap(),
        "--rows",
        rows.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(std::fs::read_to_string(&rows).unwrap(), "", "{err}");
    let log = common::data("sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog");
    let (code, _, err) = ahcmon(&[
        "scan",
        log.to_str().unwrap(),
        "--rows",
        log.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
}

/// The mixed archive: every tlog, DataFlash and ULog file of the external data, and a cut
/// DataFlash log. Every good file gives its rows (where it cannot be estimated, one row per
/// vehicle saying why); the bad one is named with its reason; exit 1.
#[test]
#[ignore = "needs the external logs (../shared/data or AHCMON_SHARED_DATA): cargo test --release --test scan -- --ignored"]
fn the_external_archive_with_a_bad_file_is_scanned_whole() {
    let root = std::env::var_os("AHCMON_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    assert!(root.is_dir(), "{}: no external logs", root.display());
    let dir = common::temp_dir("scan_archive");
    // A DataFlash log's first 4 bytes: its magic and nothing more.
    let bad = dir.join("cut.bin");
    std::fs::write(&bad, [0xA3, 0x95, 0x80, 0x80]).unwrap();
    let out = dir.join("rows.jsonl");
    let (code, said, err) = ahcmon(&[
        "scan",
        root.to_str().unwrap(),
        bad.to_str().unwrap(),
        "--rows",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("cut.bin: ArduPilot DataFlash log:"), "{err}");
    let rows = rows(&std::fs::read_to_string(&out).unwrap());
    let mut logs = Vec::new();
    let mut stack = vec![root.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            let ext = p
                .extension()
                .and_then(|x| x.to_str())
                .unwrap_or("")
                .to_lowercase();
            if p.is_dir() {
                stack.push(p);
            } else if ["tlog", "bin", "ulg"].contains(&ext.as_str()) {
                logs.push(p);
            }
        }
    }
    assert!(logs.len() >= 40, "{} logs", logs.len());
    assert!(
        err.contains("1 logs or directories could not be read and 0 paths named nothing"),
        "{err}"
    );
    assert!(
        said.contains(&format!("scanned {} logs", logs.len() + 1)),
        "{said}"
    );
    for log in &logs {
        let of: Vec<&Value> = rows
            .iter()
            .filter(|r| std::path::Path::new(r["file"].as_str().unwrap()) == log)
            .collect();
        assert!(!of.is_empty(), "{}: no row", log.display());
        for r in of {
            assert!(
                r["mit_ukf"]["gamma"].is_f64() || r["no_estimates"].is_string(),
                "{r}"
            );
        }
    }
    // A ULog's board id is its sys_uuid as pyulog reads it.
    let mut ulogs = 0;
    for log in logs
        .iter()
        .filter(|l| l.extension().is_some_and(|x| x == "ulg"))
    {
        let uuid = common::run_python(&[
            "-c",
            "import sys; from pyulog import ULog; print(ULog(sys.argv[1], [], False).msg_info_dict.get('sys_uuid', ''))",
            log.to_str().unwrap(),
        ]);
        let uuid = uuid.trim();
        let expected = (!uuid.is_empty()).then(|| format!("px4 {}", uuid.to_ascii_uppercase()));
        for r in rows
            .iter()
            .filter(|r| std::path::Path::new(r["file"].as_str().unwrap()) == log)
        {
            assert_eq!(
                r["board_uid"].as_str(),
                expected.as_deref(),
                "{}",
                log.display()
            );
        }
        ulogs += usize::from(expected.is_some());
    }
    assert!(ulogs > 0, "no ULog with a sys_uuid");
}

/// `--parquet` beside `--rows`: pyarrow and pandas read the table, every value equals the JSON
/// line's (flattened), and the schema is the one docs/fleet.md states; `--airframes` names the
/// logs its patterns match, and only those.
#[test]
fn the_parquet_table_is_the_rows_in_the_documented_schema() {
    let dir = common::temp_dir("scan_parquet");
    let (jsonl, table, map) = (
        dir.join("rows.jsonl"),
        dir.join("rows.parquet"),
        dir.join("airframes.toml"),
    );
    let pattern = tlogs().join("sitl_quad_*/*.tlog");
    std::fs::write(
        &map,
        format!(
            "[[airframe]]\nname = \"quad-a\"\nlogs = [{:?}]\n",
            pattern.to_str().unwrap()
        ),
    )
    .unwrap();
    let (code, _, err) = ahcmon(&[
        "scan",
        tlogs().to_str().unwrap(),
        "--rows",
        jsonl.to_str().unwrap(),
        "--parquet",
        table.to_str().unwrap(),
        "--airframes",
        map.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let rows = rows(&std::fs::read_to_string(&jsonl).unwrap());
    assert!(rows.len() >= 12, "{} rows", rows.len());
    for r in &rows {
        let file = r["file"].as_str().unwrap();
        let want = file.contains("/sitl_quad_").then_some("quad-a");
        assert_eq!(r["airframe"].as_str(), want, "{file}");
    }
    let out = common::run_python(&[
        "tests/reference/parquet_rows.py",
        jsonl.to_str().unwrap(),
        table.to_str().unwrap(),
    ]);
    let mut lines = out.lines();
    assert_eq!(
        lines.next(),
        Some(format!("ok {} rows 35 columns", rows.len()).as_str()),
        "{out}"
    );
    let schema: Vec<(String, String, bool)> = serde_json::from_str(lines.next().unwrap()).unwrap();
    // The documented schema: docs/fleet.md's table under "The Parquet table".
    let doc =
        std::fs::read_to_string(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/fleet.md"))
            .unwrap();
    let section = doc
        .split("## The Parquet table")
        .nth(1)
        .expect("docs/fleet.md has a section `## The Parquet table`");
    let section = section.split("\n## ").next().unwrap();
    let documented: Vec<(String, String, bool)> = section
        .lines()
        .filter(|l| l.starts_with("| `"))
        .map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            (
                cells[1].trim_matches('`').to_string(),
                cells[2].to_string(),
                cells[3] == "yes",
            )
        })
        .collect();
    assert_eq!(schema, documented, "pyarrow's schema against the docs'");
    // A row that does not fit the schema is impossible from scan; a table the scan cannot write
    // leaves the JSON lines as they were: a directory as the table.
    let before = std::fs::read(&jsonl).unwrap();
    let (code, _, err) = ahcmon(&[
        "scan",
        tlogs().to_str().unwrap(),
        "--rows",
        jsonl.to_str().unwrap(),
        "--parquet",
        dir.to_str().unwrap(),
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("cannot write"), "{err}");
    assert_eq!(std::fs::read(&jsonl).unwrap(), before);
    // Both on standard output is refused before anything runs.
    let (code, _, err) = ahcmon(&[
        "scan",
        tlogs().to_str().unwrap(),
        "--rows",
        "-",
        "--parquet",
        "-",
    ]);
    assert_eq!(code, 2, "{err}");
}
