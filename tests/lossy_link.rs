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

/// `log` to a monitor over UDP on one link per entry of `delays` at once, paced by its
/// timestamps at `SPEED`, each link losing its own `LOSS` of it and sending each frame its
/// delay (wall clock) late.
fn stream(
    log: &Path,
    profile: Option<&str>,
    seed: u64,
    dir: &Path,
    delays: &[Duration],
) -> Streamed {
    let links = delays.len();
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
    let entries = std::sync::Arc::new(tlog_entries(log));
    // Which frames each link carries, drawn before any is sent.
    let carried: Vec<Vec<bool>> = (0..links as u64)
        .map(|k| {
            let mut rng = SplitMix(seed + 1000 * k);
            entries.iter().map(|_| rng.next_f64() >= LOSS).collect()
        })
        .collect();
    let on = |i: usize| carried.iter().filter(|c| c[i]).count();
    let dropped = (0..entries.len()).filter(|&i| on(i) == 0).count();
    let on_all = (0..entries.len()).filter(|&i| on(i) == links).count();

    let sent: Vec<usize> = carried
        .iter()
        .map(|c| c.iter().filter(|&&x| x).count())
        .collect();
    let started = Instant::now();
    let senders: Vec<_> = (0..links)
        .map(|k| {
            let (entries, keep, port, delay) =
                (entries.clone(), carried[k].clone(), ports[k], delays[k]);
            std::thread::spawn(move || {
                let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
                let t0 = entries[0].0;
                for ((ts, frame), keep) in entries.iter().zip(keep) {
                    let due =
                        Duration::from_secs_f64(ts.saturating_sub(t0) as f64 / 1e6 / SPEED) + delay;
                    if let Some(wait) = due.checked_sub(started.elapsed()) {
                        std::thread::sleep(wait);
                    }
                    if keep {
                        socket.send_to(frame, ("127.0.0.1", port)).unwrap();
                    }
                }
            })
        })
        .collect();
    for s in senders {
        s.join().unwrap();
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

/// The repository's root and the SITL logs' truth.
fn sitl_truth() -> (PathBuf, DatasetTruth) {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let path = root.join("tests/datasets/sitl.toml");
    let truth = DatasetTruth::from_toml(
        &std::fs::read_to_string(&path).unwrap(),
        &path.display().to_string(),
    )
    .unwrap();
    (root, truth)
}

#[test]
fn a_fifth_of_the_packets_lost_still_names_each_sitl_fault_within_5_s() {
    let (root, truth) = sitl_truth();
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
                let run = stream(
                    &log,
                    case.profile.as_deref(),
                    1 + i as u64,
                    &dir,
                    &[Duration::ZERO],
                );
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

/// The number before `what` in `text` (`"123 frames dropped"`).
fn count_before(text: &str, what: &str) -> usize {
    let at = text
        .find(what)
        .unwrap_or_else(|| panic!("no {what:?} in {text}"));
    text[..at]
        .split_whitespace()
        .last()
        .unwrap()
        .parse()
        .unwrap()
}

/// One stream reaching the monitor by two paths (a port split to two radios), each losing its
/// own fifth of the frames: the copies dropped and counted, no `contaminated` decision, every
/// frame the monitor misses accounted for, and the fault named as from one link.
fn two_paths(second_path_delay: Duration, name: &str) -> (Streamed, usize, usize) {
    let (root, truth) = sitl_truth();
    let case = &truth.cases[0];
    let log = root.join("replay/tlogs").join(&case.file);
    let dir = common::temp_dir(name);
    let run = stream(
        &log,
        case.profile.as_deref(),
        7,
        &dir,
        &[Duration::ZERO, second_path_delay],
    );
    let report = format!("{}\n{:?}", run.summary, run.decisions);
    let share = run.dropped as f64 / run.frames as f64;
    assert!(
        (share - LOSS * LOSS).abs() < 0.01,
        "lost on both: {share:.3}"
    );
    // Every frame sent on both paths is dropped once: as a copy, or as late where the
    // machine's load held its second delivery past the copy window, behind a newer frame (the
    // count of frames handled below shows none went through twice). The links' frames add up
    // to what was sent.
    let copies = count_before(&run.summary, "frames dropped as copies of another link's");
    let late_all = count_before(&run.summary, "as late");
    assert!(
        copies <= run.on_all && run.on_all - copies <= late_all,
        "{copies} copies, {late_all} late of {} sent on both: {report}",
        run.on_all
    );
    let late = late_all - (run.on_all - copies);
    let total: usize = run.sent.iter().sum();
    assert!(
        run.summary.contains(&format!("link: frames {total} ")),
        "want {total} frames: {report}"
    );
    // The monitor handles each frame some path delivered, once, less those dropped as late
    // with no copy handled before; none reaches it out of order.
    let handled: usize = run
        .summary
        .lines()
        .find(|l| l.starts_with("latency from a frame's receive"))
        .and_then(|l| l.rsplit_once(" over "))
        .and_then(|(_, n)| n.trim_end_matches(" frames").parse().ok())
        .unwrap_or_else(|| panic!("no latency line: {report}"));
    assert_eq!(handled, run.frames - run.dropped - late, "{report}");
    assert_eq!(count_before(&run.summary, "reordered"), 0, "{report}");
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
    (run, late, handled)
}

/// Both paths at once: the monitor gets more than either path alone. (At 10x real time
/// frames are 0.4 ms apart, so a fill often comes after the sender's next frame: late.)
#[test]
fn two_lossy_paths_to_one_vehicle_fill_each_other_s_gaps() {
    let (run, late, handled) = two_paths(Duration::ZERO, "lossy_link_two");
    let best = run.sent.iter().max().copied().unwrap_or(0);
    assert!(
        handled > best,
        "{handled} handled, the better path alone {best} ({late} late)"
    );
}

/// The second path 5 ms behind (50 ms of the vehicle's clock at 10x, several frames): its
/// fills come after the sender's next frame and are dropped as late, never passed on out of
/// order; the monitor misses what the first path lost, and decides as from it alone.
#[test]
fn a_slower_second_path_s_late_fills_do_not_mix_the_stream() {
    let (run, late, handled) = two_paths(Duration::from_millis(5), "lossy_link_two_delayed");
    let first_lost = run.frames - run.sent[0];
    assert!(
        late > first_lost / 2,
        "{late} late of {first_lost} lost on the first path"
    );
    assert!(
        handled >= run.sent[0],
        "{handled} handled of {}",
        run.sent[0]
    );
}
