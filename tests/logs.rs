//! Vehicles' own logs (ArduPilot DataFlash, PX4 ULog) against the reference readers
//! (pymavlink's DFReader, pyulog) on every such file of the external data, and `replay` on
//! each, whole and damaged. The logs are not in the repository (several have no licence), so
//! these run on request, where the logs are: `cargo test --release --test logs -- --ignored`.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use ahcmon::link::{dataflash, ulog};
use ahcmon::telemetry::Record;
use std::path::{Path, PathBuf};
use std::process::Command;

fn shared_data() -> PathBuf {
    std::env::var_os("AHCMON_SHARED_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"))
}

/// Every DataFlash and ULog file of the external data, told by content.
fn own_logs() -> Vec<PathBuf> {
    let mut out = vec![];
    let root = shared_data();
    let dirs = std::fs::read_dir(&root).unwrap_or_else(|e| {
        panic!(
            "{}: {e} (set AHCMON_SHARED_DATA to the external logs)",
            root.display()
        )
    });
    for dir in dirs.flatten() {
        let Ok(files) = std::fs::read_dir(dir.path()) else {
            continue;
        };
        for f in files.flatten() {
            let p = f.path();
            let format = std::fs::File::open(&p).and_then(ahcmon::link::sniff);
            if matches!(
                format,
                Ok(ahcmon::link::LogFormat::DataFlash | ahcmon::link::LogFormat::ULog)
            ) {
                out.push(p);
            }
        }
    }
    out.sort();
    assert!(
        out.len() >= 20,
        "only {} own logs under {}",
        out.len(),
        root.display()
    );
    out
}

#[derive(Default)]
struct Seen {
    rates: Vec<(f64, [f64; 3])>,
    outputs: Vec<(f64, [u16; 16])>,
    az: Vec<(f64, f64)>,
    params: usize,
}

fn read(path: &Path) -> (Seen, ahcmon::link::LogReport) {
    let mut seen = Seen::default();
    let mut emit = |r: &Record| match r {
        Record::Rates { t, rates } => seen.rates.push((*t, *rates)),
        Record::Outputs { t, pwm } => seen.outputs.push((*t, *pwm)),
        Record::Az { t, az } => seen.az.push((*t, *az)),
        Record::Param { .. } => seen.params += 1,
        _ => {}
    };
    let head = std::fs::read(path).unwrap();
    let report = if head.starts_with(b"ULog") {
        ulog::read(path, &mut emit)
    } else {
        dataflash::read(&head[..], &mut emit, &mut |_| {})
    }
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (seen, report)
}

fn num(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap()
}

#[test]
#[ignore = "needs the external logs (../shared/data or AHCMON_SHARED_DATA): cargo test --release --test logs -- --ignored"]
fn the_readers_see_what_pymavlink_and_pyulog_see() {
    let logs = own_logs();
    for path in &logs {
        let reference: serde_json::Value = serde_json::from_str(&common::run_python(&[
            "tests/reference/log_reference.py",
            path.to_str().unwrap(),
        ]))
        .unwrap();
        let (seen, report) = read(path);
        let name = path.display();
        assert_eq!(
            seen.rates.len() as u64,
            reference["rates"].as_u64().unwrap(),
            "{name}: rates"
        );
        assert_eq!(
            seen.outputs.len() as u64,
            reference["outputs"].as_u64().unwrap(),
            "{name}: outputs"
        );
        assert_eq!(
            seen.params as u64,
            reference["params"].as_u64().unwrap(),
            "{name}: parameters"
        );
        if let Some(n) = reference.get("messages") {
            assert_eq!(
                report.counters.frames,
                n.as_u64().unwrap(),
                "{name}: messages"
            );
            assert_eq!(
                seen.az.len() as u64,
                reference["az"].as_u64().unwrap(),
                "{name}: IMU 0"
            );
            for (i, row) in reference["first_az"].as_array().unwrap().iter().enumerate() {
                let row = row.as_array().unwrap();
                assert_eq!(seen.az[i].0, num(&row[0]) * 1e-6, "{name}: a_z stamp {i}");
                assert!(
                    (seen.az[i].1 - num(&row[1])).abs() < 1e-6,
                    "{name}: a_z {i}"
                );
            }
        }
        // Stamps to the µs; values as the reference decodes them (f32 fields: to rounding).
        for (i, row) in reference["first_rates"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            let row = row.as_array().unwrap();
            assert!(
                (seen.rates[i].0 - num(&row[0]) * 1e-6).abs() < 1e-9,
                "{name}: rate stamp {i}"
            );
            for k in 0..3 {
                let (ours, theirs) = (seen.rates[i].1[k], num(&row[k + 1]));
                assert!(
                    (ours - theirs).abs() <= 1e-6 * theirs.abs().max(1e-3),
                    "{name}: rate {i}.{k}: {ours} vs {theirs}"
                );
            }
        }
        for (i, row) in reference["first_outputs"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            let row = row.as_array().unwrap();
            assert!(
                (seen.outputs[i].0 - num(&row[0]) * 1e-6).abs() < 1e-9,
                "{name}: output stamp {i}"
            );
            for k in 0..4 {
                assert_eq!(
                    f64::from(seen.outputs[i].1[k]),
                    num(&row[k + 1]).round(),
                    "{name}: output {i}.{k}"
                );
            }
        }
        assert_eq!(
            report.counters.resync, 0,
            "{name}: an intact log needs no resync"
        );
    }
}

fn ahcmon() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ahcmon"))
}

#[test]
#[ignore = "needs the external logs (../shared/data or AHCMON_SHARED_DATA): cargo test --release --test logs -- --ignored"]
fn replay_reads_every_own_log_without_a_converter() {
    for path in own_logs() {
        let out = ahcmon().arg("replay").arg(&path).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{}: {}\n{}",
            path.display(),
            stdout,
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            stdout.contains("telemetry:") && stdout.contains("replayed"),
            "{}: {stdout}",
            path.display()
        );
    }
}

#[test]
#[ignore = "needs the external logs (../shared/data or AHCMON_SHARED_DATA): cargo test --release --test logs -- --ignored"]
fn damaged_own_logs_are_read_up_to_the_damage_and_say_so() {
    let dir = common::temp_dir("damaged-own-logs");
    let logs = own_logs();
    let bin = logs
        .iter()
        .find(|p| !std::fs::read(p).unwrap().starts_with(b"ULog"))
        .unwrap();
    let ulg = logs
        .iter()
        .find(|p| std::fs::read(p).unwrap().starts_with(b"ULog"))
        .unwrap();
    for (src, kind) in [(bin, "bin"), (ulg, "ulg")] {
        let bytes = std::fs::read(src).unwrap();
        // Cut mid-message, and garbage written over a stretch in the middle.
        let cut = dir.join(format!("cut.{kind}"));
        std::fs::write(&cut, &bytes[..bytes.len() / 2 + 7]).unwrap();
        let mut garbled = bytes.clone();
        let mid = bytes.len() / 3;
        for (i, b) in garbled[mid..mid + 5000].iter_mut().enumerate() {
            *b = (i * 131 % 251) as u8;
        }
        let garbled_path = dir.join(format!("garbled.{kind}"));
        std::fs::write(&garbled_path, &garbled).unwrap();
        let (whole, _) = read(src);
        for p in [&cut, &garbled_path] {
            let (seen, report) = read(p);
            assert!(
                !seen.rates.is_empty() && seen.rates.len() < whole.rates.len(),
                "{}",
                p.display()
            );
            let c = report.counters;
            assert!(
                c.truncated + c.parse_error + c.resync > 0,
                "{}: the damage is counted: {c:?}",
                p.display()
            );
            let out = ahcmon().arg("replay").arg(p).output().unwrap();
            assert!(out.status.code().is_some(), "{}: no crash", p.display());
        }
        // The garbled DataFlash log is read past the damage: it resynchronises.
        if kind == "bin" {
            let (seen, report) = read(&garbled_path);
            assert!(
                report.counters.skipped_bytes >= 4000,
                "{:?}",
                report.counters
            );
            assert!(
                seen.rates.len() * 10 > whole.rates.len() * 9,
                "{} of {}",
                seen.rates.len(),
                whole.rates.len()
            );
        }
    }
}

/// `calibrate` reads a vehicle's own log as `replay` does: a PX4 ULog's healthy stretch gives
/// a profile that `replay` then uses; a DataFlash log whose model fits worse than a constant
/// is refused with that reason, not written.
#[test]
#[ignore = "needs the external logs (../shared/data or AHCMON_SHARED_DATA): cargo test --release --test logs -- --ignored"]
fn calibrate_reads_own_logs() {
    let dir = common::temp_dir("logs_calibrate");
    let profile = dir.join("p.toml");
    let ulog = shared_data().join("rflymad/TestCase_1_2000000000.ulg");
    let out = ahcmon()
        .arg("calibrate")
        .arg(&ulog)
        .args(["--until", "50", "-o"])
        .arg(&profile)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("quad-x identified from"), "{stdout}");
    let replayed = ahcmon()
        .arg("replay")
        .arg(&ulog)
        .arg("--profile")
        .arg(&profile)
        .output()
        .unwrap();
    assert!(replayed.status.success());
    assert!(String::from_utf8_lossy(&replayed.stdout).contains("quad-x-calibrated"));
    let bin = shared_data().join("rrc_prop_cut/Hover__good_prop_hover_1.BIN");
    let refused = dir.join("refused.toml");
    let out = ahcmon()
        .arg("calibrate")
        .arg(&bin)
        .args(["--until", "120", "-o"])
        .arg(&refused)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("worse than a constant"));
    assert!(!refused.exists());
}
