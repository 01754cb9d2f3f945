//! A long-range radio link: each SITL log streamed live over real UDP on 127.0.0.1 to
//! `ahcmon monitor`, at 10× real time, with a fifth of the packets dropped at random. The
//! monitor must still calibrate and name the fault within 5 s of its onset, as it does from
//! the whole log (tests/datasets.rs), with nothing decided before the onset.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use ahcmon::eval::datasets::DatasetTruth;
use serde_json::Value;
use std::io::Read as _;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const LOSS: f64 = 0.2;
const SPEED: f64 = 10.0;

/// The raw entries of a tlog: (µs timestamp, the frame's bytes as sent).
fn tlog_entries(path: &Path) -> Vec<(u64, Vec<u8>)> {
    let mut bytes = vec![];
    std::fs::File::open(path)
        .unwrap()
        .read_to_end(&mut bytes)
        .unwrap();
    let mut out = vec![];
    let mut at = 0;
    while at + 8 + 8 <= bytes.len() {
        let ts = u64::from_be_bytes(bytes[at..at + 8].try_into().unwrap());
        let f = &bytes[at + 8..];
        let len = match f[0] {
            // v2: header 10, payload, CRC 2, signature 13 when flagged
            0xFD => 12 + usize::from(f[1]) + if f[2] & 1 == 1 { 13 } else { 0 },
            0xFE => 8 + usize::from(f[1]),
            m => panic!(
                "{}: no frame at byte {} (0x{m:02x})",
                path.display(),
                at + 8
            ),
        };
        out.push((ts, f[..len].to_vec()));
        at += 8 + len;
    }
    out
}

/// A fixed-seed generator, so that a failure replays the same losses.
struct SplitMix(u64);

impl SplitMix {
    fn next_f64(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

struct Streamed {
    decisions: Vec<Value>,
    summary: String,
    /// Frames sent, on each link.
    sent: Vec<usize>,
    dropped: usize,
    /// Frames that went out on every link.
    on_all: usize,
    frames: usize,
}

/// `log` to a monitor over UDP on `links` links at once, paced by its timestamps at `SPEED`,
/// each link losing its own `LOSS` of it.
fn stream(log: &Path, profile: Option<&str>, seed: u64, dir: &Path, links: usize) -> Streamed {
    let dec = dir.join("decisions.jsonl");
    let ports: Vec<u16> = (0..links)
        .map(|_| {
            std::net::UdpSocket::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port()
        })
        .collect();
    let mut args = vec!["monitor".to_string()];
    args.extend(ports.iter().map(|p| format!("udpin:127.0.0.1:{p}")));
    args.extend([
        "--headless".into(),
        "--exit-idle".into(),
        "2".into(),
        "--decisions".into(),
        dec.to_str().unwrap().into(),
    ]);
    if let Some(p) = profile {
        args.extend(["--profile".into(), p.into()]);
    }
    let mut monitor = Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .args(&args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Said once each socket is bound.
    let mut stderr = std::io::BufReader::new(monitor.stderr.take().unwrap());
    let mut line = String::new();
    let mut bound = 0;
    while bound < links && std::io::BufRead::read_line(&mut stderr, &mut line).unwrap() > 0 {
        bound += usize::from(line.contains("listening on"));
        line.clear();
    }
    let drain = std::thread::spawn(move || {
        let mut rest = String::new();
        stderr.read_to_string(&mut rest).ok();
        rest
    });
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let entries = tlog_entries(log);
    let mut rngs: Vec<SplitMix> = (0..links as u64)
        .map(|k| SplitMix(seed + 1000 * k))
        .collect();
    let (t0, started) = (entries[0].0, Instant::now());
    let (mut dropped, mut on_all) = (0, 0);
    let mut sent = vec![0; links];
    for (ts, frame) in &entries {
        let due = Duration::from_secs_f64(ts.saturating_sub(t0) as f64 / 1e6 / SPEED);
        if let Some(wait) = due.checked_sub(started.elapsed()) {
            std::thread::sleep(wait);
        }
        let mut on = 0;
        for (k, port) in ports.iter().enumerate() {
            if rngs[k].next_f64() < LOSS {
                continue;
            }
            socket.send_to(frame, ("127.0.0.1", *port)).unwrap();
            sent[k] += 1;
            on += 1;
        }
        dropped += usize::from(on == 0);
        on_all += usize::from(on == links);
    }
    let out = monitor.wait_with_output().unwrap();
    let err = drain.join().unwrap();
    assert!(
        out.status.success(),
        "{}: monitor failed: {err}",
        log.display()
    );
    Streamed {
        decisions: std::fs::read_to_string(&dec)
            .unwrap_or_default()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect(),
        summary: String::from_utf8_lossy(&out.stdout).into_owned(),
        sent,
        dropped,
        on_all,
        frames: entries.len(),
    }
}

#[test]
fn a_fifth_of_the_packets_lost_still_names_each_sitl_fault_within_5_s() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("tests/datasets/sitl.toml");
    let truth = DatasetTruth::from_toml(
        &std::fs::read_to_string(&path).unwrap(),
        &path.display().to_string(),
    )
    .unwrap();
    // All four at once, each to its own monitor: the suite's wall time is one log's.
    let runs: Vec<_> = truth
        .cases
        .iter()
        .enumerate()
        .map(|(i, case)| {
            let case = case.clone();
            let log = root.join("replay/tlogs").join(&case.file);
            std::thread::spawn(move || {
                let dir = common::temp_dir(&format!("lossy_link_{i}"));
                let run = stream(&log, case.profile.as_deref(), 1 + i as u64, &dir, 1);
                (case, run)
            })
        })
        .collect();
    for handle in runs {
        let (case, run) = handle.join().unwrap();
        let fault = case.fault.as_ref().unwrap();
        let onset = fault.onset_s.unwrap();
        let share = run.dropped as f64 / run.frames as f64;
        assert!(
            (share - LOSS).abs() < 0.01,
            "{}: dropped {share:.3}",
            case.file
        );
        let faults: Vec<&Value> = run
            .decisions
            .iter()
            .filter(|d| d["event"] == "fault")
            .collect();
        let report = format!("{}: {faults:?}\n{}", case.file, run.summary);
        let before = faults.iter().filter(|d| d["t"].as_f64().unwrap() < onset);
        assert_eq!(before.count(), 0, "{report}");
        let first = faults
            .first()
            .unwrap_or_else(|| panic!("no fault: {report}"));
        let delay = first["t"].as_f64().unwrap() - onset;
        let channel = first["channel"].as_u64().unwrap() as u8;
        assert!(fault.channels.contains(&channel), "{report}");
        assert!(delay < 5.0, "named {delay:.2} s after the onset: {report}");
        eprintln!(
            "{}: {} of {} packets lost; {} named {delay:.2} s after the onset",
            case.file, run.dropped, run.frames, first["actuator"]
        );
    }
}

/// Two radios to one vehicle, each losing its own fifth of the frames, into one monitor: one
/// stream that lost only the frames both lost (4 %), the copies dropped and counted, no
/// `contaminated` decision, and the fault named as from one link.
#[test]
fn two_lossy_links_to_one_vehicle_fill_each_other_s_gaps() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("tests/datasets/sitl.toml");
    let truth = DatasetTruth::from_toml(
        &std::fs::read_to_string(&path).unwrap(),
        &path.display().to_string(),
    )
    .unwrap();
    let case = &truth.cases[0];
    let log = root.join("replay/tlogs").join(&case.file);
    let dir = common::temp_dir("lossy_link_two");
    let run = stream(&log, case.profile.as_deref(), 7, &dir, 2);
    let report = format!("{}\n{:?}", run.summary, run.decisions);
    let share = run.dropped as f64 / run.frames as f64;
    assert!(
        (share - LOSS * LOSS).abs() < 0.01,
        "lost on both: {share:.3}"
    );
    // Every frame sent on both links is one copy; the links' frames add up to what was sent.
    let copies = format!("{} frames dropped as copies of another link's", run.on_all);
    assert!(run.summary.contains(&copies), "want {copies:?}: {report}");
    let total: usize = run.sent.iter().sum();
    assert!(
        run.summary.contains(&format!("link: frames {total} ")),
        "want {total} frames: {report}"
    );
    assert!(
        !run.decisions.iter().any(|d| d["event"] == "contaminated"),
        "{report}"
    );
    let fault = case.fault.as_ref().unwrap();
    let onset = fault.onset_s.unwrap();
    let faults: Vec<&Value> = run
        .decisions
        .iter()
        .filter(|d| d["event"] == "fault")
        .collect();
    assert!(
        faults.iter().all(|d| d["t"].as_f64().unwrap() >= onset),
        "{report}"
    );
    let first = faults
        .first()
        .unwrap_or_else(|| panic!("no fault: {report}"));
    let channel = first["channel"].as_u64().unwrap() as u8;
    assert!(fault.channels.contains(&channel), "{report}");
    assert!(first["t"].as_f64().unwrap() - onset < 5.0, "{report}");
}
