//! The fuzz targets (`fuzz/`, cargo-fuzz on nightly) on stable, with a fixed budget: each
//! target's seeds and a fixed set of mutants of them (bit flips, bytes set to edge values,
//! cuts, repeated and inserted chunks; a fixed-seed generator), so CI runs the same inputs
//! every time. Seeds: the repository's tlogs, profiles and scenarios, and small DataFlash and
//! ULog logs made here (the external logs are not in the repository). An input may be
//! refused; a panic fails the test, and so does an input that takes over 10 s.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use ahcmon::fuzzing;
use std::time::Duration;

fn repo(rel: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// A fixed-seed xorshift: the same mutants on every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// One mutant of `seed`: one to four edits.
fn mutate(seed: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(b.len());
        match rng.below(6) {
            0 if !b.is_empty() => b[at] ^= 1 << rng.below(8),
            1 if !b.is_empty() => b[at] = [0, 0xff, 0x7f, 0x80, 0xfd, 0xfe][rng.below(6)],
            2 => b.truncate(at),
            3 if !b.is_empty() => {
                let end = (at + 1 + rng.below(64)).min(b.len());
                let chunk = b[at..end].to_vec();
                let to = rng.below(b.len());
                b.splice(to..to, chunk);
            }
            4 => {
                let junk: Vec<u8> = (0..1 + rng.below(16)).map(|_| rng.next() as u8).collect();
                b.splice(at..at, junk);
            }
            _ if b.len() > 1 => {
                let end = (at + 1 + rng.below(32)).min(b.len());
                b.drain(at..end);
            }
            _ => {}
        }
    }
    b
}

/// Run `target` on each input in a thread of its own; fail on a panic or an input that does
/// not return within 10 s.
fn run_all(name: &str, target: fn(&[u8]), inputs: Vec<Vec<u8>>) {
    let n = inputs.len();
    let (tx, rx) = std::sync::mpsc::channel();
    let worker = std::thread::spawn(move || {
        for (i, input) in inputs.into_iter().enumerate() {
            tx.send(i).unwrap();
            target(&input);
        }
    });
    let mut last = None;
    loop {
        match rx.recv_timeout(Duration::from_secs(10)) {
            Ok(i) => last = Some(i),
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {
                panic!("{name}: input {last:?} of {n} has not returned in 10 s")
            }
        }
    }
    if worker.join().is_err() {
        panic!("{name}: input {last:?} of {n} panicked");
    }
}

fn seeds_and_mutants(seeds: &[Vec<u8>], mutants: usize, seed: u64) -> Vec<Vec<u8>> {
    let mut rng = Rng(seed);
    let mut all = seeds.to_vec();
    for k in 0..mutants {
        all.push(mutate(&seeds[k % seeds.len()], &mut rng));
    }
    all
}

/// Heads of the repository's tlogs (their parameters and first seconds of flight).
fn tlog_seeds() -> Vec<Vec<u8>> {
    let mut seeds = Vec::new();
    for dir in std::fs::read_dir(repo("replay/tlogs")).unwrap() {
        for f in std::fs::read_dir(dir.unwrap().path()).unwrap() {
            let p = f.unwrap().path();
            if p.extension().is_some_and(|e| e == "tlog") {
                let mut b = std::fs::read(&p).unwrap();
                b.truncate(16 * 1024);
                seeds.push(b);
            }
        }
    }
    assert!(seeds.len() >= 4, "the repository's tlogs: {}", seeds.len());
    seeds
}

#[test]
fn tlog_and_datagram_targets_survive_their_corpus() {
    let seeds = tlog_seeds();
    run_all(
        "tlog",
        fuzzing::tlog,
        seeds_and_mutants(&seeds, 20_000, 0x7105),
    );
    // The same frames without their stamps, as 128-byte datagrams.
    let datagrams: Vec<Vec<u8>> = seeds
        .iter()
        .map(|t| {
            let mut out = vec![127u8];
            let mut r = ahcmon::link::TlogReader::new(&t[..]);
            while let Ok(Some((_, f))) = r.next_frame() {
                ahcmon::protocol::frame::encode_v2(f.sysid, f.compid, f.seq, &f.msg, &mut out);
            }
            out
        })
        .collect();
    run_all(
        "datagrams",
        fuzzing::datagrams,
        seeds_and_mutants(&datagrams, 20_000, 0xda7a),
    );
}

/// A DataFlash log: FMT records, the firmware's MSG, FRAME_CLASS and FRAME_TYPE, then
/// `seconds` of RATE, ATT, RCOU and IMU at 50 Hz.
fn dataflash_log(seconds: f64) -> Vec<u8> {
    fn size(c: u8) -> usize {
        match c {
            b'B' => 1,
            b'H' => 2,
            b'f' => 4,
            b'Q' => 8,
            b'N' => 16,
            b'Z' => 64,
            _ => unreachable!(),
        }
    }
    fn padded<const N: usize>(s: &str) -> [u8; N] {
        let mut a = [0u8; N];
        a[..s.len()].copy_from_slice(s.as_bytes());
        a
    }
    let formats: [(u8, &str, &str, &str); 7] = [
        (0x80, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns"),
        (1, "PARM", "QNf", "TimeUS,Name,Value"),
        (2, "MSG", "QZ", "TimeUS,Message"),
        (3, "RATE", "Qfff", "TimeUS,R,P,Y"),
        (4, "ATT", "Qfff", "TimeUS,Roll,Pitch,Yaw"),
        (5, "RCOU", "QHHHH", "TimeUS,C1,C2,C3,C4"),
        (6, "IMU", "QBf", "TimeUS,I,AccZ"),
    ];
    let mut out = Vec::new();
    for (kind, name, format, labels) in formats {
        let len = if kind == 0x80 {
            89
        } else {
            3 + format.bytes().map(size).sum::<usize>()
        };
        out.extend([0xA3, 0x95, 0x80, kind, len as u8]);
        out.extend(padded::<4>(name));
        out.extend(padded::<16>(format));
        out.extend(padded::<64>(labels));
    }
    let head = |out: &mut Vec<u8>, kind: u8, us: u64| {
        out.extend([0xA3, 0x95, kind]);
        out.extend(us.to_le_bytes());
    };
    head(&mut out, 2, 0);
    out.extend(padded::<64>("ArduCopter V4.5.7 (2a3dc4b7)"));
    for (name, value) in [("FRAME_CLASS", 1.0f32), ("FRAME_TYPE", 1.0)] {
        head(&mut out, 1, 0);
        out.extend(padded::<16>(name));
        out.extend(value.to_le_bytes());
    }
    for k in 0..(seconds * 50.0) as u64 {
        let t = k as f64 * 0.02;
        let us = 1_000_000 + k * 20_000;
        let wave = (t * 3.0).sin() as f32;
        head(&mut out, 3, us);
        for v in [10.0 * wave, -8.0 * wave, 2.0 * wave] {
            out.extend(v.to_le_bytes());
        }
        head(&mut out, 4, us);
        for v in [2.0 * wave, -1.5 * wave, 90.0] {
            out.extend(v.to_le_bytes());
        }
        head(&mut out, 5, us);
        for j in 0..4u16 {
            out.extend((1500 + j * 10 + (40.0 * wave) as u16).to_le_bytes());
        }
        head(&mut out, 6, us);
        out.push(0);
        out.extend((-9.8f32 + 0.1 * wave).to_le_bytes());
    }
    out
}

#[test]
fn dataflash_target_survives_its_corpus() {
    let seeds = vec![dataflash_log(4.0), dataflash_log(0.2)];
    // The seed is a DataFlash log the reader takes: it gives rates and outputs.
    let mut records = 0;
    ahcmon::link::dataflash::read(&seeds[0][..], &mut |_| records += 1, &mut |_| {}).unwrap();
    assert!(records >= 4 * 200, "{records} records from the seed");
    run_all(
        "dataflash",
        fuzzing::dataflash,
        seeds_and_mutants(&seeds, 20_000, 0xdf),
    );
}

/// A ULog (version 1): formats and subscriptions of the topics ahcmon reads, MAV_TYPE, then
/// `seconds` of angular velocity, attitude and outputs at 50 Hz. `empty_add` makes the first
/// subscription an empty message.
fn ulog_log(seconds: f64, empty_add: bool) -> Vec<u8> {
    let mut out = b"ULog\x01\x12\x35\x01".to_vec();
    out.extend(0u64.to_le_bytes());
    let msg = |out: &mut Vec<u8>, kind: u8, body: &[u8]| {
        out.extend((body.len() as u16).to_le_bytes());
        out.push(kind);
        out.extend(body);
    };
    msg(&mut out, b'B', &[0u8; 40]);
    for f in [
        "vehicle_angular_velocity:uint64_t timestamp;uint64_t timestamp_sample;float[3] xyz;",
        "vehicle_attitude:uint64_t timestamp;float[4] q;",
        "actuator_outputs:uint64_t timestamp;uint32_t noutputs;float[16] output;",
    ] {
        msg(&mut out, b'F', f.as_bytes());
    }
    let mut param = vec![16u8];
    param.extend(b"int32_t MAV_TYPE");
    param.extend(2i32.to_le_bytes());
    msg(&mut out, b'P', &param);
    for (id, name) in [
        (0u16, "vehicle_angular_velocity"),
        (1, "vehicle_attitude"),
        (2, "actuator_outputs"),
    ] {
        if empty_add && id == 0 {
            msg(&mut out, b'A', &[]);
            continue;
        }
        let mut body = vec![0u8];
        body.extend(id.to_le_bytes());
        body.extend(name.as_bytes());
        msg(&mut out, b'A', &body);
    }
    for k in 0..(seconds * 50.0) as u64 {
        let us = 1_000_000 + k * 20_000;
        let wave = (k as f32 * 0.06).sin();
        let mut d = 0u16.to_le_bytes().to_vec();
        d.extend(us.to_le_bytes());
        d.extend(us.to_le_bytes());
        for v in [0.2 * wave, -0.1 * wave, 0.05 * wave] {
            d.extend(v.to_le_bytes());
        }
        msg(&mut out, b'D', &d);
        let mut d = 1u16.to_le_bytes().to_vec();
        d.extend(us.to_le_bytes());
        for v in [1.0f32, 0.01 * wave, 0.0, 0.0] {
            d.extend(v.to_le_bytes());
        }
        msg(&mut out, b'D', &d);
        let mut d = 2u16.to_le_bytes().to_vec();
        d.extend(us.to_le_bytes());
        d.extend(4u32.to_le_bytes());
        for j in 0..16 {
            let v = if j < 4 { 1500.0 + 40.0 * wave } else { 0.0 };
            d.extend(v.to_le_bytes());
        }
        msg(&mut out, b'D', &d);
    }
    out
}

/// Write `bytes` to a file and read it with the ULog reader: records, or the error.
fn read_ulog(bytes: &[u8], name: &str) -> Result<usize, ahcmon::link::LogError> {
    let path = common::temp_dir(name).join("log.ulg");
    std::fs::write(&path, bytes).unwrap();
    let mut records = 0;
    ahcmon::link::ulog::read(&path, &mut |_| records += 1).map(|_| records)
}

#[test]
fn ulog_target_survives_its_corpus() {
    let seeds = vec![ulog_log(4.0, false), ulog_log(0.2, false)];
    // The seed is a ULog the reader takes: it gives rates and outputs.
    let records = read_ulog(&seeds[0], "fuzz-ulog-seed").unwrap();
    assert!(records >= 3 * 200, "{records} records from the seed");
    let mut seeds = seeds;
    seeds.push(ulog_log(1.0, true));
    run_all(
        "ulog",
        fuzzing::ulog,
        seeds_and_mutants(&seeds, 5000, 0x0106),
    );
}

/// Found by fuzzing: px4-ulog indexes into an empty subscription message and panicked, which
/// crashed `replay`. Now the log is read up to it and called damaged.
#[test]
fn a_ulog_with_an_empty_subscription_is_a_damaged_log_not_a_panic() {
    let log = ulog_log(1.0, true);
    let dir = common::temp_dir("fuzz-ulog-empty-add");
    let path = dir.join("damaged.ulg");
    std::fs::write(&path, &log).unwrap();
    let (code, out, err) = common::ahcmon(&["replay", path.to_str().unwrap()]);
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        out.contains("a damaged message (the ULog reader failed on it: index out of bounds"),
        "exit {code}\n{out}\n{err}"
    );
}

/// Profiles and scenarios: the repository's, and mutants of their text. A mutant that loads
/// flies (1500 steps), so fewer are run.
#[test]
fn profile_and_scenario_targets_survive_their_corpus() {
    let texts = |dir: &str| -> Vec<Vec<u8>> {
        let mut v: Vec<Vec<u8>> = std::fs::read_dir(repo(dir))
            .unwrap()
            .map(|f| std::fs::read(f.unwrap().path()).unwrap())
            .collect();
        v.sort();
        v
    };
    let profiles = texts("replay/profiles");
    let scenarios = texts("replay/scenarios");
    assert!(profiles.len() >= 5 && scenarios.len() >= 20);
    run_all(
        "profile",
        fuzzing::profile,
        seeds_and_mutants(&profiles, 1000, 0x9f),
    );
    // The scenarios themselves fly in their own tests: mutants only here.
    run_all(
        "scenario",
        fuzzing::scenario,
        seeds_and_mutants(&scenarios, 1000, 0x5c).split_off(scenarios.len()),
    );
}
