//! The bad-input matrix through the binary: each row an input a user or a link can give,
//! with the outcome it must have (exit code, what is said, what is counted). In every row no
//! panic, and a run that fails leaves the decisions file it was given as it was.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use ahcmon::link::{TlogReader, TlogWriter};
use ahcmon::protocol::dialects::ahcmon::MavMessage;
use std::path::{Path, PathBuf};

const QUAD: &str = "sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog";

/// A tlog's records: (stamp bytes and frame) as they are in the file.
fn records(bytes: &[u8]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut i = 0;
    while i + 10 < bytes.len() {
        let len = match bytes[i + 8] {
            0xFD => 12 + usize::from(bytes[i + 9]) + if bytes[i + 10] & 1 != 0 { 13 } else { 0 },
            0xFE => 8 + usize::from(bytes[i + 9]),
            m => panic!("no magic at {i}: {m:#x}"),
        };
        out.push(bytes[i..i + 8 + len].to_vec());
        i += 8 + len;
    }
    out
}

/// The quad's log with every ATTITUDE's roll rate set to `value` in one in `every`.
fn with_attitude_rate(every: usize, value: f32) -> Vec<u8> {
    let mut reader = TlogReader::open(&common::data(QUAD)).unwrap();
    let mut out = Vec::new();
    let mut w = TlogWriter::new(&mut out);
    let mut k = 0;
    while let Some((ts, frame)) = reader.next_frame().unwrap() {
        let mut msg = frame.msg.clone();
        if let MavMessage::ATTITUDE(a) = &mut msg {
            k += 1;
            if k % every == 0 {
                a.rollspeed = value;
            }
        }
        w.write(ts, frame.sysid, frame.compid, &msg).unwrap();
    }
    w.flush().unwrap();
    drop(w);
    out
}

enum Input {
    /// A tlog's bytes, written to `log.tlog`.
    Tlog(Vec<u8>),
    /// A path as given (a directory, a missing file).
    Path(PathBuf),
    /// The quad's log with a profile file of this text (`--profile`).
    Profile(&'static str),
    /// The quad's log with this path as its profile.
    ProfilePath(&'static str),
}

struct Row {
    what: &'static str,
    input: Input,
    code: i32,
    /// Said on stdout or stderr.
    says: String,
}

fn run(dir: &Path, row: &Row) -> (i32, String) {
    let decisions = dir.join("decisions.jsonl");
    std::fs::write(&decisions, "yesterday's decisions\n").unwrap();
    let log = dir.join("log.tlog");
    let mut args: Vec<String> = vec!["-q".into(), "replay".into()];
    match &row.input {
        Input::Tlog(bytes) => {
            std::fs::write(&log, bytes).unwrap();
            args.push(log.display().to_string());
        }
        Input::Path(p) => args.push(p.display().to_string()),
        Input::Profile(text) => {
            let profile = dir.join("profile.toml");
            std::fs::write(&profile, text).unwrap();
            args.push(common::data(QUAD).display().to_string());
            args.extend(["--profile".into(), profile.display().to_string()]);
        }
        Input::ProfilePath(path) => {
            args.push(common::data(QUAD).display().to_string());
            args.extend(["--profile".into(), path.to_string()]);
        }
    }
    args.extend(["--decisions".into(), decisions.display().to_string()]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let (code, out, err) = common::ahcmon(&args);
    let said = format!("{out}{err}");
    assert!(!said.contains("panicked"), "{}: {said}", row.what);
    if code != 0 {
        assert_eq!(
            std::fs::read_to_string(&decisions).unwrap(),
            "yesterday's decisions\n",
            "{}: a failed run changed the decisions file",
            row.what
        );
    }
    (code, said)
}

#[test]
fn every_bad_input_has_its_stated_outcome() {
    let dir = common::temp_dir("bad-input-matrix");
    let quad = std::fs::read(common::data(QUAD)).unwrap();
    let recs = records(&quad);
    let join = |r: &[Vec<u8>]| r.concat();
    // Frames with a byte of their payload flipped: one in 50.
    let corrupt: Vec<Vec<u8>> = recs
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let mut r = r.clone();
            if k % 50 == 7 && r.len() > 20 {
                r[18] ^= 0x5a;
            }
            r
        })
        .collect();
    let flipped = recs
        .iter()
        .enumerate()
        .filter(|(k, r)| k % 50 == 7 && r.len() > 20)
        .count();
    let attitudes = {
        let mut r = TlogReader::open(&common::data(QUAD)).unwrap();
        std::iter::from_fn(|| r.next_frame().unwrap())
            .filter(|(_, f)| matches!(f.msg, MavMessage::ATTITUDE(_)))
            .count()
    };
    let twice: Vec<Vec<u8>> = recs.iter().flat_map(|r| [r.clone(), r.clone()]).collect();
    // One ATTITUDE in 20 swapped with the next ATTITUDE: that many rate instants go back.
    let mut swapped = recs.clone();
    let is_attitude = |r: &Vec<u8>| match r[8] {
        0xFD => r[15] == 30 && r[16] == 0 && r[17] == 0,
        _ => r[13] == 30,
    };
    let at: Vec<usize> = (0..recs.len()).filter(|&k| is_attitude(&recs[k])).collect();
    let mut swaps = 0;
    for pair in at.chunks(2).step_by(10).filter(|p| p.len() == 2) {
        swapped.swap(pair[0], pair[1]);
        swaps += 1;
    }
    let mut noise: Vec<u8> = Vec::with_capacity(200_000);
    let mut x = 0x2545_f491_4f6c_dd1du64;
    for _ in 0..200_000 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        noise.push(x as u8);
    }
    let rows = [
        Row {
            what: "the log as recorded",
            input: Input::Tlog(quad.clone()),
            code: 0,
            says: "truncated 0".into(),
        },
        Row {
            what: "cut inside a frame",
            input: Input::Tlog(quad[..500_011].to_vec()),
            code: 0,
            says: "truncated 1".into(),
        },
        Row {
            what: "one frame in 50 with a byte flipped",
            input: Input::Tlog(join(&corrupt)),
            code: 0,
            // Each flipped frame is lost alone: the reader slides to the next frame once.
            says: format!("frames {} · resync {flipped} ·", recs.len() - flipped),
        },
        Row {
            what: "every frame twice",
            input: Input::Tlog(join(&twice)),
            code: 0,
            says: "contaminated".into(),
        },
        Row {
            what: "one ATTITUDE in 20 swapped with the next",
            input: Input::Tlog(join(&swapped)),
            code: 0,
            says: format!(", {swaps} reordered, 0 duplicates"),
        },
        Row {
            what: "NaN roll rates (one ATTITUDE in 100)",
            input: Input::Tlog(with_attitude_rate(100, f32::NAN)),
            code: 0,
            says: format!("), {} non-finite;", attitudes / 100),
        },
        Row {
            what: "infinite roll rates (one ATTITUDE in 100)",
            input: Input::Tlog(with_attitude_rate(100, f32::INFINITY)),
            code: 0,
            says: format!("), {} non-finite;", attitudes / 100),
        },
        Row {
            what: "200 kB of random bytes",
            input: Input::Tlog(noise),
            code: 2,
            says: "no MAVLink frame of a known message".into(),
        },
        Row {
            what: "a device that never ends as the log",
            input: Input::Path(PathBuf::from("/dev/zero")),
            code: 2,
            says: "no MAVLink frame of a known message in its first 1 MiB".into(),
        },
        Row {
            what: "an empty file",
            input: Input::Tlog(Vec::new()),
            code: 2,
            says: "no MAVLink frame of a known message in its 0 bytes".into(),
        },
        Row {
            what: "a directory",
            input: Input::Path(dir.clone()),
            code: 2,
            says: "Is a directory".into(),
        },
        Row {
            what: "a missing file",
            input: Input::Path(dir.join("none.tlog")),
            code: 2,
            says: "No such file".into(),
        },
        Row {
            what: "a device that never ends as a profile",
            input: Input::ProfilePath("/dev/zero"),
            code: 2,
            says: "over 1024 KiB".into(),
        },
        Row {
            what: "an unknown profile key",
            input: Input::Profile("name = \"x\"\nbogus_key = 1\n"),
            code: 2,
            says: "unknown field `bogus_key`".into(),
        },
        Row {
            what: "a profile that is not TOML",
            input: Input::Profile("name = \"x\n"),
            code: 2,
            says: "profile.toml:1:".into(),
        },
    ];
    let mut failures = Vec::new();
    for row in &rows {
        let (code, said) = run(&dir, row);
        if code != row.code || !said.contains(&row.says) {
            failures.push(format!(
                "{}: exit {code} (want {}), want {:?} in:\n{said}",
                row.what, row.code, row.says
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}
