//! MAVLink end to end through real processes, real UDP sockets on 127.0.0.1 and real files:
//! `ahcmon sim --out` speaking like an autopilot, `ahcmon monitor` listening; tlogs written by
//! `sim --tlog` read back by pymavlink; corrupted real logs replayed.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_ahcmon")
}

fn free_udp_port() -> u16 {
    let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    s.local_addr().unwrap().port()
}

fn decisions(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap_or_default()
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is one JSON object"))
        .collect()
}

/// The number after `key` in the summary's `link: ` line.
fn link_count(link: &str, key: &str) -> u64 {
    let at = link
        .find(key)
        .unwrap_or_else(|| panic!("{key} missing in {link}"));
    link[at + key.len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}

/// A tlog of the simulated quad (`sim --tlog`) in `dir`, and what the simulator printed.
fn sim_quad_tlog(dir: &Path) -> (std::path::PathBuf, String) {
    let tlog = dir.join("quad.tlog");
    let out = Command::new(bin())
        .args(["sim", "--scenario", "quad-x-motor2-loe-live", "--tlog"])
        .arg(&tlog)
        .output()
        .unwrap();
    assert!(out.status.success());
    (tlog, String::from_utf8_lossy(&out.stdout).into_owned())
}

fn faults(ds: &[Value], sysid: u64) -> Vec<&Value> {
    ds.iter()
        .filter(|d| d["sysid"] == sysid && (d["event"] == "fault" || d["event"] == "changed"))
        .collect()
}

/// `ahcmon monitor` on udpin at `port`, headless, its decisions into `dec`, ending `idle_s`
/// after the last frame; returned once it has had time to start listening.
fn headless_monitor(port: u16, dec: &Path, idle_s: u32) -> std::process::Child {
    let monitor = Command::new(bin())
        .args([
            "monitor",
            &format!("udpin:127.0.0.1:{port}"),
            "--headless",
            "--exit-idle",
            &idle_s.to_string(),
        ])
        .arg("--decisions")
        .arg(dec)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    monitor
}

/// Wait for a monitor started by [`headless_monitor`] to end by itself; it must succeed. Its
/// summary (stdout).
fn finished_monitor(monitor: std::process::Child) -> String {
    let out = monitor.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "monitor failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Monitor on udpin, one or more simulators on udpout at 10x real time, all as processes.
fn run_live(sims: &[(&str, u8)], name: &str) -> Vec<Value> {
    let dir = common::temp_dir(name);
    let dec = dir.join("decisions.jsonl");
    let port = free_udp_port();
    let monitor = headless_monitor(port, &dec, 2);
    let handles: Vec<_> = sims
        .iter()
        .map(|(scenario, sysid)| {
            Command::new(bin())
                .args(["sim", "--scenario", scenario, "--speed", "10", "--sysid"])
                .arg(sysid.to_string())
                .arg("--out")
                .arg(format!("udpout:127.0.0.1:{port}"))
                .stdout(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for h in handles {
        let out = h.wait_with_output().unwrap();
        assert!(out.status.success());
    }
    let summary = finished_monitor(monitor);
    assert!(summary.contains("bad_crc 0"), "{summary}");
    decisions(&dec)
}

#[test]
fn heli_servo_fault_over_udp_between_two_processes() {
    let ds = run_live(&[("heli-swash2-loe-live", 1)], "live_heli");
    let f = faults(&ds, 1);
    assert!(!f.is_empty(), "no fault decision: {ds:?}");
    // The scenario's fault is at 35 s of flight = 45 s of vehicle time (10 s boot offset).
    let first = f[0];
    assert_eq!(first["actuator"], "swash2", "{first}");
    assert_eq!(first["channel"], 2);
    let t = first["t"].as_f64().unwrap();
    assert!((45.0..=47.0).contains(&t), "detected at {t}");
    assert!(f.iter().all(|d| d["actuator"] == "swash2"), "{f:?}");
    // The end of the stream is a lost link.
    assert!(
        ds.iter()
            .any(|d| d["event"] == "link_lost" && d["sysid"] == 1)
    );
}

/// Two forged ATTITUDEs of the vehicle's system id from another socket, back to back,
/// stamped 1.0 and 1.6 s, 25 s into a live flight: they used to confirm a "reboot" (filters
/// reset, a new calibration, and the flight's real motor fault missed). Now refused (their
/// arrival does not cover the clock they claim): no reset, the real fault found on time.
#[test]
fn two_forged_frames_during_a_live_flight_change_no_decision() {
    use ahcmon::protocol::dialects::ahcmon::{ATTITUDE_DATA, MavMessage};
    let dir = common::temp_dir("live_forged");
    let dec = dir.join("decisions.jsonl");
    let port = free_udp_port();
    let monitor = headless_monitor(port, &dec, 2);
    let sim = Command::new(bin())
        .args([
            "sim",
            "--scenario",
            "quad-x-motor2-loe-live",
            "--speed",
            "10",
        ])
        .arg("--out")
        .arg(format!("udpout:127.0.0.1:{port}"))
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    // 25 s of flight at 10x (the monitor is estimating by then).
    std::thread::sleep(std::time::Duration::from_millis(3500));
    let forger = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let mut frame = Vec::new();
    for (seq, ms) in [(7u8, 1000u32), (8, 1600)] {
        let msg = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: ms,
            ..Default::default()
        });
        ahcmon::protocol::frame::encode_v2(1, 1, seq, &msg, &mut frame);
        forger.send_to(&frame, ("127.0.0.1", port)).unwrap();
    }
    assert!(sim.wait_with_output().unwrap().status.success());
    let summary = finished_monitor(monitor);
    assert!(
        summary.contains("clock: 1 jumps of the vehicle clock"),
        "the forged pair was not seen and refused: {summary}"
    );
    let ds = decisions(&dec);
    assert!(!ds.iter().any(|d| d["event"] == "filter_reset"), "{ds:?}");
    let f = faults(&ds, 1);
    assert!(!f.is_empty(), "the real fault was missed: {ds:?}");
    assert!(f.iter().all(|d| d["actuator"] == "motor2"), "{f:?}");
    // The fault is at 35 s of flight = 45 s of vehicle time.
    let t = f[0]["t"].as_f64().unwrap();
    assert!((45.0..=48.0).contains(&t), "decided at {t}");
}

/// One autopilot HEARTBEAT from each of 252 stray system ids, then silence: none of them sent
/// a sample, so none is a vehicle to lose (they made 252 `link_lost` decisions).
#[test]
fn stray_system_ids_make_no_decisions() {
    use ahcmon::protocol::dialects::ahcmon::{
        HEARTBEAT_DATA, MavAutopilot, MavMessage, MavModeFlag, MavState, MavType,
    };
    let dir = common::temp_dir("live_stray");
    let dec = dir.join("decisions.jsonl");
    let port = free_udp_port();
    let monitor = headless_monitor(port, &dec, 3);
    let sender = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let msg = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        custom_mode: 0,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        base_mode: MavModeFlag::empty(),
        system_status: MavState::MAV_STATE_STANDBY,
        mavlink_version: 3,
    });
    let mut frame = Vec::new();
    for sysid in 2..=253u8 {
        ahcmon::protocol::frame::encode_v2(sysid, 1, 0, &msg, &mut frame);
        sender.send_to(&frame, ("127.0.0.1", port)).unwrap();
    }
    finished_monitor(monitor);
    let ds = decisions(&dec);
    assert!(ds.is_empty(), "{} decisions: {:?}", ds.len(), ds.first());
}

/// Two simulated vehicles with the same system id: the monitor cannot tell their streams
/// apart, and says so as a decision (it used to be a stderr line only), once, naming both
/// senders.
#[test]
fn one_system_id_from_two_senders_is_a_decision() {
    let ds = run_live(
        &[("quad-x-motor2-loe-live", 1), ("quad-x-motor2-loe-live", 1)],
        "live_two_senders",
    );
    let mixed: Vec<&Value> = ds.iter().filter(|d| d["event"] == "contaminated").collect();
    assert_eq!(mixed.len(), 1, "{mixed:?}");
    assert_eq!(mixed[0]["sysid"], 1);
    let detail = mixed[0]["detail"].as_str().unwrap();
    assert!(
        detail.starts_with("system 1 is heard from 127.0.0.1:"),
        "{detail}"
    );
}

/// Two vehicles with one system id, each on its own link into one monitor: their frames
/// have little in common (equal ones happen: both at rest), so they are no redundant links to
/// merge; said as a decision once.
#[test]
fn one_system_id_on_two_links_with_few_frames_in_common_is_a_decision() {
    let dir = common::temp_dir("live_two_links_two_vehicles");
    let dec = dir.join("decisions.jsonl");
    let ports = [free_udp_port(), free_udp_port()];
    let monitor = Command::new(bin())
        .arg("monitor")
        .args(ports.map(|p| format!("udpin:127.0.0.1:{p}")))
        .args(["--headless", "--exit-idle", "2", "--decisions"])
        .arg(&dec)
        .arg("--summary")
        .arg(dir.join("summary.json"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    let sims: Vec<_> = [
        ("heli-swash2-loe-live", ports[0]),
        ("quad-x-motor2-loe-live", ports[1]),
    ]
    .iter()
    .map(|(scenario, port)| {
        Command::new(bin())
            .args([
                "sim",
                "--scenario",
                scenario,
                "--speed",
                "10",
                "--sysid",
                "1",
            ])
            .arg("--out")
            .arg(format!("udpout:127.0.0.1:{port}"))
            .stdout(Stdio::piped())
            .spawn()
            .unwrap()
    })
    .collect();
    for sim in sims {
        assert!(sim.wait_with_output().unwrap().status.success());
    }
    let out = monitor.wait_with_output().unwrap();
    let (summary, err) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{err}");
    // Said by the merging of the links; the decision (once per vehicle) may come first from
    // the vehicle's clock going back and forth, which the monitor checks on every sample.
    let (a, b) = (
        format!("udpin:127.0.0.1:{}", ports[0]),
        format!("udpin:127.0.0.1:{}", ports[1]),
    );
    assert!(
        err.contains(&format!(
            "system 1 (component 1) arrives on {a} and {b} at once with"
        )) || err.contains(&format!(
            "system 1 (component 1) arrives on {b} and {a} at once with"
        )),
        "{err}"
    );
    let ds = decisions(&dec);
    let mixed: Vec<&Value> = ds.iter().filter(|d| d["event"] == "contaminated").collect();
    assert_eq!(mixed.len(), 1, "{mixed:?}\n{summary}");
    assert_eq!(mixed[0]["sysid"], 1);
    // Each link's own counters in the summary, and in the JSON summary, which adds them up.
    for port in ports {
        assert!(
            summary.contains(&format!("  udpin:127.0.0.1:{port}: frames ")),
            "{summary}"
        );
    }
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("summary.json")).unwrap()).unwrap();
    let each = json["links"]["each"].as_array().unwrap();
    assert_eq!(each.len(), 2);
    let frames: u64 = each
        .iter()
        .map(|l| l["counters"]["frames"].as_u64().unwrap())
        .sum();
    assert_eq!(json["link"]["frames"].as_u64(), Some(frames));
    assert!(json["links"]["copies"].as_u64().is_some() && json["links"]["late"].as_u64().is_some());
}

#[test]
fn two_vehicles_at_once_keep_their_own_decisions() {
    let ds = run_live(
        &[("heli-swash2-loe-live", 1), ("quad-x-motor2-loe-live", 2)],
        "live_two",
    );
    let heli = faults(&ds, 1);
    let quad = faults(&ds, 2);
    assert!(!heli.is_empty() && !quad.is_empty(), "{ds:?}");
    assert!(heli.iter().all(|d| d["actuator"] == "swash2"), "{heli:?}");
    assert!(quad.iter().all(|d| d["actuator"] == "motor2"), "{quad:?}");
    for d in heli.iter().chain(&quad) {
        let t = d["t"].as_f64().unwrap();
        assert!(t >= 45.0, "a fault decision before the onset: {d}");
    }
}

#[test]
fn sim_tlog_loads_in_pymavlink_with_the_same_counts() {
    let dir = common::temp_dir("live_tlog");
    let (tlog, said) = sim_quad_tlog(&dir);
    // Our own reader's per-type counts ...
    let mut ours = std::collections::BTreeMap::new();
    let mut r = ahcmon::link::TlogReader::open(&tlog).unwrap();
    while let Some((_, f)) = r.next_frame().unwrap() {
        *ours
            .entry(mavlink_core::Message::message_name(&f.msg).to_string())
            .or_insert(0u64) += 1;
    }
    assert_eq!(r.counters.dropped(), 0);
    // ... the sim's own report ...
    for (name, n) in &ours {
        assert!(said.contains(&format!("{name} {n}")), "{said}");
    }
    // ... and pymavlink's.
    let py = common::run_python(&["tests/reference/tlog_counts.py", tlog.to_str().unwrap()]);
    let mut theirs = std::collections::BTreeMap::new();
    for line in py.lines() {
        let (name, n) = line.split_once(' ').unwrap();
        theirs.insert(name.to_string(), n.parse::<u64>().unwrap());
    }
    assert_eq!(theirs.remove("BAD_DATA"), Some(0), "{py}");
    assert_eq!(ours, theirs);
    assert!(ours["ATTITUDE"] > 2900);
}

#[test]
fn corrupted_real_log_is_counted_and_still_estimated() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join(
        "replay/tlogs/sitl_quadx_maneuvers_motor4_gain0p7/sitl_quadx_maneuvers_motor4_gain0p7.tlog",
    );
    let mut bytes = std::fs::read(src).unwrap();
    // Flip a byte every 10 kB, insert garbage in the middle, cut the tail, append noise.
    let mut i = 5000;
    while i < bytes.len() {
        bytes[i] ^= 0xA5;
        i += 10_007;
    }
    let mid = bytes.len() / 2;
    let garbage: Vec<u8> = (0..3000u32)
        .map(|k| (k.wrapping_mul(2654435761) >> 13) as u8)
        .collect();
    bytes.splice(mid..mid, garbage.iter().copied());
    bytes.truncate(bytes.len() - 7);
    bytes.extend_from_slice(&garbage);
    let dir = common::temp_dir("live_corrupt");
    let path = dir.join("corrupt.tlog");
    std::fs::write(&path, &bytes).unwrap();
    let est = dir.join("estimates.jsonl");
    let out = Command::new(bin())
        .args(["replay"])
        .arg(&path)
        .arg("--estimates")
        .arg(&est)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = String::from_utf8_lossy(&out.stdout);
    let link = summary.lines().find(|l| l.starts_with("link: ")).unwrap();
    let count = |key: &str| link_count(link, key);
    assert!(count("resync ") > 0, "{link}");
    assert!(count("bad_crc ") > 0, "{link}");
    assert!(count("frames ") > 41_000, "{link}");
    let lines = std::fs::read_to_string(&est).unwrap().lines().count();
    assert!(lines > 8000, "only {lines} estimate lines");
}

/// A pymavlink udpin listener (tests/reference/alerts_listener.py) on `port`: started and ready
/// to receive; `finish` waits for its JSON report of what arrived from component 191.
struct Listener {
    child: std::process::Child,
    out: std::io::BufReader<std::process::ChildStdout>,
}

impl Listener {
    fn start(port: u16, timeout_s: u32) -> Self {
        use std::io::BufRead;
        let py = common::python();
        let mut child = Command::new(&py)
            .args([
                "tests/reference/alerts_listener.py",
                &port.to_string(),
                &timeout_s.to_string(),
            ])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot run {}: {e}", py.display()));
        let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
        let mut line = String::new();
        out.read_line(&mut line).unwrap();
        assert_eq!(line.trim(), "ready", "listener did not start");
        Self { child, out }
    }

    fn finish(mut self) -> Value {
        use std::io::BufRead;
        let mut line = String::new();
        self.out.read_line(&mut line).unwrap();
        let _ = self.child.wait();
        serde_json::from_str(&line).expect("listener JSON")
    }
}

#[test]
fn demo_alerts_reach_a_pymavlink_listener() {
    let port = free_udp_port();
    let listener = Listener::start(port, 40);
    let demo = Command::new(bin())
        .args(["demo", "--headless", "--speed", "4", "--alerts"])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .output()
        .unwrap();
    assert!(
        demo.status.success(),
        "{}",
        String::from_utf8_lossy(&demo.stderr)
    );
    let seen = listener.finish();
    // HEARTBEAT: MAV_TYPE_ONBOARD_CONTROLLER (18), MAV_AUTOPILOT_INVALID (8), as the vehicle's sysid.
    assert!(
        seen["heartbeat"]
            .as_array()
            .unwrap()
            .iter()
            .any(|h| h == &serde_json::json!([18, 8])),
        "{seen}"
    );
    assert_eq!(seen["sysids"], serde_json::json!([1]));
    let texts: Vec<String> = seen["statustext"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s[1].as_str().unwrap().to_string())
        .collect();
    assert!(
        texts
            .iter()
            .any(|t| t.starts_with("ahcmon: swash2 ") && t.len() <= 50),
        "{texts:?}"
    );
    let names = seen["named_value_float"].as_array().unwrap();
    assert!(names.iter().any(|n| n == "g_swash2"), "{names:?}");
    assert!(names.iter().any(|n| n == "d_tail"), "{names:?}");
    // AHC_ESTIMATE, decoded by pymavlink's code generated from dialects/ahcmon.xml: every
    // actuator, each guaranteed bound either a finite interval about its estimate or NaN
    // with its not-excited bit.
    assert!(seen["ahc_estimate"].as_u64().unwrap() >= 4, "{seen}");
    let estimated = seen["ahc_estimate_names"].as_array().unwrap();
    for name in ["swash1", "swash2", "swash3", "tail"] {
        assert!(estimated.iter().any(|n| n == name), "{estimated:?}");
    }
    assert_eq!(seen["ahc_estimate_bad"], serde_json::json!([]), "{seen}");
    // Its extension fields: the output's bounds at the recent command, the set filter's finite
    // once calibrated (the helicopter's servos through a_z).
    assert!(seen["set_output_bounded"].as_u64().unwrap() > 0, "{seen}");
    assert!(seen["command_ref_nonzero"].as_u64().unwrap() > 0, "{seen}");
}

/// MAVProxy (tests/reference/requirements-nodeps.txt) listening on `masters` and sending to `out` (all on
/// 127.0.0.1), its state in `dir`; returns once it has had time to start listening.
fn mavproxy(masters: &[u16], out: u16, dir: &Path) -> std::process::Child {
    mavproxy_with(masters, out, dir, &[], Stdio::null())
}

fn mavproxy_with(
    masters: &[u16],
    out: u16,
    dir: &Path,
    extra: &[&str],
    console: Stdio,
) -> std::process::Child {
    let py = common::python();
    let mavproxy = py.with_file_name("mavproxy.py");
    assert!(
        mavproxy.exists(),
        "{} missing: it is in tests/reference/requirements-nodeps.txt (AHCMON_PYTHON names a Python without it?)",
        mavproxy.display()
    );
    let proxy = Command::new(&py)
        .arg(&mavproxy)
        .args(
            masters
                .iter()
                .map(|p| format!("--master=udpin:127.0.0.1:{p}")),
        )
        .arg(format!("--out=udp:127.0.0.1:{out}"))
        .arg("--non-interactive")
        .arg(format!("--state-basedir={}", dir.display()))
        .args(extra)
        .stdin(Stdio::null())
        .stdout(console)
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // MAVProxy needs a few seconds to start listening.
    std::thread::sleep(std::time::Duration::from_secs(5));
    proxy
}

/// The demo at 4 times real time, its alerts sent to `port` on 127.0.0.1.
fn demo_alerting_to(port: u16) -> std::process::Output {
    Command::new(bin())
        .args(["demo", "--headless", "--speed", "4", "--alerts"])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .output()
        .unwrap()
}

#[test]
fn mavproxy_forwards_our_statustext_to_its_outputs() {
    let (master, out_port) = (free_udp_port(), free_udp_port());
    let state = common::temp_dir("live_mavproxy");
    // The planner side: a pymavlink listener on MAVProxy's --out.
    let listener = Listener::start(out_port, 60);
    let mut proxy = mavproxy(&[master], out_port, &state);
    let demo = demo_alerting_to(master);
    let seen = listener.finish();
    let _ = proxy.kill();
    let _ = proxy.wait();
    assert!(
        demo.status.success(),
        "{}",
        String::from_utf8_lossy(&demo.stderr)
    );
    let texts: Vec<&str> = seen["statustext"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s[1].as_str().unwrap())
        .collect();
    assert!(
        texts.iter().any(|t| t.starts_with("ahcmon: swash2 ")),
        "MAVProxy did not forward our STATUSTEXT: {seen}"
    );
}

/// MAVProxy's own console shows our alerts with `--target-system=1 --target-component=0` (the
/// vehicle's system, any of its components; by default it follows the first HEARTBEAT's
/// component, the autopilot's, and shows no other's STATUSTEXT). It prints every STATUSTEXT as
/// `AP: ...`, so the text names its sender: `AP: ahcmon: swash2 LOE ...`.
#[test]
fn mavproxy_s_console_shows_our_alerts_as_ours() {
    let (master, out_port) = (free_udp_port(), free_udp_port());
    let state = common::temp_dir("live_mavproxy_console");
    let console = state.join("console.txt");
    let mut proxy = mavproxy_with(
        &[master],
        out_port,
        &state,
        &["--target-system=1", "--target-component=0"],
        std::fs::File::create(&console).unwrap().into(),
    );
    let demo = demo_alerting_to(master);
    std::thread::sleep(std::time::Duration::from_secs(1));
    let _ = proxy.kill();
    let _ = proxy.wait();
    assert!(
        demo.status.success(),
        "{}",
        String::from_utf8_lossy(&demo.stderr)
    );
    let shown = std::fs::read_to_string(&console).unwrap();
    assert!(
        shown.lines().any(|l| l.contains("AP: ahcmon: swash2 LOE")),
        "MAVProxy's console: {shown}"
    );
}

/// The README's MAVProxy set-up: the vehicle and our alerts both masters of MAVProxy, whose
/// --out feeds the monitor. MAVProxy sends the alerts back in under the vehicle's system id;
/// they kept a vehicle that had gone silent "alive" (no link_lost, --exit-idle never fired).
#[test]
fn our_alerts_echoed_back_by_mavproxy_do_not_hide_a_lost_vehicle() {
    let (vehicle_in, alerts_in, monitor_in) = (free_udp_port(), free_udp_port(), free_udp_port());
    let dir = common::temp_dir("live_mavproxy_echo");
    let mut proxy = mavproxy(&[vehicle_in, alerts_in], monitor_in, &dir);
    let file = dir.join("d.jsonl");
    let mut monitor = Command::new(bin())
        .args([
            "monitor",
            &format!("udpin:127.0.0.1:{monitor_in}"),
            "--headless",
        ])
        .args(["--alerts", &format!("udpout:127.0.0.1:{alerts_in}")])
        .args(["--exit-idle", "3", "--decisions"])
        .arg(&file)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let sim = Command::new(bin())
        .args([
            "sim",
            "--scenario",
            "quad-x-motor2-loe-live",
            "--speed",
            "4",
        ])
        .args(["--out", &format!("udpout:127.0.0.1:{vehicle_in}")])
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    // The vehicle is silent now: link_lost after 2 s, and --exit-idle 3 ends the monitor.
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    while monitor.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            monitor.kill().ok();
            let _ = proxy.kill();
            panic!(
                "the monitor did not see the vehicle go: {:?}",
                decisions(&file)
            );
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let _ = proxy.kill();
    let _ = proxy.wait();
    let out = monitor.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}");
    let ds = decisions(&file);
    assert!(ds.iter().any(|d| d["event"] == "link_lost"), "{ds:?}");
    assert!(
        !faults(&ds, 1).is_empty(),
        "the vehicle was watched: {ds:?}"
    );
    assert!(
        stdout.contains("of our own alert frames (component 191) came back"),
        "{stdout}"
    );
}

/// The monitor on udpin beside a stand-in autopilot; returns what the autopilot received and
/// the monitor's stderr.
fn vehicle_hears(extra: &[&str]) -> (Value, String) {
    vehicle_hears_as(extra, &["4", "3"])
}

/// As `vehicle_hears`, from an autopilot run with `vehicle`'s arguments: seconds, MAV_AUTOPILOT
/// (3 ArduPilot, 12 PX4), and "noack" for one that never acknowledges.
fn vehicle_hears_as(extra: &[&str], vehicle: &[&str]) -> (Value, String) {
    let port = free_udp_port();
    let monitor = Command::new(bin())
        .args([
            "monitor",
            &format!("udpin:127.0.0.1:{port}"),
            "--headless",
            "--exit-idle",
            "1.5",
        ])
        .args(extra)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(300));
    let port = port.to_string();
    let mut args = vec!["tests/reference/fake_vehicle.py", port.as_str()];
    args.extend_from_slice(vehicle);
    let vehicle = common::run_python(&args);
    let out = monitor.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    (
        serde_json::from_str(vehicle.trim()).expect("vehicle JSON"),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn nothing_goes_to_the_vehicle_unless_rates_are_requested() {
    let (heard, _) = vehicle_hears(&[]);
    assert_eq!(
        heard,
        serde_json::json!([]),
        "the monitor sent something: {heard}"
    );

    let (heard, stderr) = vehicle_hears(&["--request-rates", "25"]);
    let msgs = heard.as_array().unwrap();
    assert_eq!(msgs.len(), 3, "{heard}");
    let mut ids = vec![];
    for m in msgs {
        assert_eq!(m["type"], "COMMAND_LONG", "{m}");
        assert_eq!(m["command"], 511, "MAV_CMD_SET_MESSAGE_INTERVAL: {m}");
        assert_eq!(m["param2"], 40000.0, "25 Hz = 40000 us: {m}");
        assert_eq!(m["target"], serde_json::json!([1, 1]));
        assert_eq!(m["src"], serde_json::json!([1, 191]));
        ids.push(m["param1"].as_f64().unwrap() as u32);
    }
    ids.sort();
    assert_eq!(ids, vec![27, 30, 36]);
    assert!(
        stderr.contains("COMMAND_ACK SET_MESSAGE_INTERVAL 3/3"),
        "{stderr}"
    );

    // PX4's RAW_IMU is in sensor units, which the monitor does not read: it asks for HIGHRES_IMU.
    let (heard, stderr) = vehicle_hears_as(&["--request-rates", "25"], &["4", "12"]);
    let mut ids: Vec<u32> = heard
        .as_array()
        .unwrap()
        .iter()
        .map(|m| m["param1"].as_f64().unwrap() as u32)
        .collect();
    ids.sort();
    assert_eq!(ids, vec![30, 36, 105], "{heard}");
    assert!(stderr.contains("HIGHRES_IMU at 25 Hz"), "{stderr}");

    // An autopilot that never acknowledges (or a one-way link) is said, with the rates
    // achieved: none of the asked messages came from this stand-in.
    let (heard, stderr) = vehicle_hears_as(&["--request-rates", "25"], &["6.5", "3", "noack"]);
    assert_eq!(heard.as_array().unwrap().len(), 3, "{heard}");
    assert!(
        !stderr.contains("COMMAND_ACK SET_MESSAGE_INTERVAL"),
        "{stderr}"
    );
    assert!(
        stderr.contains("3 of 3 requests got no COMMAND_ACK"),
        "{stderr}"
    );
    assert!(stderr.contains("ATTITUDE 0.0 Hz"), "{stderr}");
    assert!(
        stderr.contains("under 80 % of the 25 Hz asked for"),
        "{stderr}"
    );
}

/// The serial transport through a real pseudo-terminal (tests/reference/serial_feeder.py writes
/// a simulated flight's frames in raw mode, some corrupted, some garbage): frames are framed by
/// our own framer, so bad CRCs and resyncs on a radio link are counted like on UDP.
#[test]
fn serial_link_frames_and_counts_what_it_drops() {
    serial_link("live_serial", 3000, |device| {
        format!("serial:{device}:57600")
    });
}

/// The same through MAVProxy's spelling of a serial device, `DEVICE,BAUD`.
#[test]
fn a_serial_device_spelled_as_for_mavproxy_is_read() {
    serial_link("live_serial_mavproxy", 600, |device| {
        format!("{device},57600")
    });
}

fn serial_link(name: &str, frames: u32, conn: impl Fn(&str) -> String) {
    use std::io::BufRead;
    let dir = common::temp_dir(name);
    let (tlog, _) = sim_quad_tlog(&dir);
    let mut feeder = Command::new(common::python())
        .arg("tests/reference/serial_feeder.py")
        .arg(&tlog)
        .arg(frames.to_string())
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(Stdio::piped())
        .spawn()
        .expect("python with pymavlink (tests/reference/requirements.txt)");
    let mut out = std::io::BufReader::new(feeder.stdout.take().unwrap());
    let mut device = String::new();
    out.read_line(&mut device).unwrap();
    let device = device.trim().to_string();
    assert!(device.starts_with("/dev/"), "feeder said {device:?}");
    let monitor = Command::new(bin())
        .args(["monitor", &conn(&device), "--headless"])
        .args(["--exit-idle", "2"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut report = String::new();
    out.read_line(&mut report).unwrap();
    let report: Value = serde_json::from_str(&report).unwrap();
    let result = monitor.wait_with_output().unwrap();
    let _ = feeder.kill();
    let _ = feeder.wait();
    assert!(
        result.status.success(),
        "{}",
        String::from_utf8_lossy(&result.stderr)
    );
    let summary = String::from_utf8_lossy(&result.stdout);
    let link = summary
        .lines()
        .find(|l| l.starts_with("link: "))
        .unwrap_or_else(|| panic!("no link line in {summary}"));
    let count = |key: &str| link_count(link, key);
    let (sent, corrupted) = (
        report["frames"].as_u64().unwrap(),
        report["corrupted"].as_u64().unwrap(),
    );
    println!("feeder {report}; monitor {link}");
    // Each corrupted frame is one bad CRC; the 300 garbage bytes can add a few more (a 0xFD/0xFE
    // in them looks like a frame start).
    assert!(
        (corrupted..=corrupted + 5).contains(&count("bad_crc ")),
        "{link}"
    );
    assert!(count("resync ") > 0, "{link}");
    // Every good frame arrives; the garbage may hide at most the frame it runs into.
    let good = sent - corrupted;
    assert!(
        count("frames ") + 1 >= good && count("frames ") <= good,
        "{link}"
    );
}

/// ctrl-c while the simulator speaks to a link and writes a tlog: the tlog ends on a whole
/// record (nothing left in the buffer, nothing cut) and the run says it was interrupted.
#[test]
fn sim_interrupted_leaves_a_whole_tlog() {
    let dir = common::temp_dir("live_sim_interrupt");
    let tlog = dir.join("cut.tlog");
    let port = free_udp_port();
    let child = Command::new(bin())
        .args(["sim", "--scenario", "heli-demo", "--speed", "2", "--out"])
        .arg(format!("udpout:127.0.0.1:{port}"))
        .arg("--tlog")
        .arg(&tlog)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let out = interrupt(child);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout} {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("interrupted"), "{stdout}");
    let bytes = std::fs::read(&tlog).unwrap();
    let mut r = ahcmon::link::TlogReader::new(bytes.as_slice());
    let mut frames = 0;
    while r.next_frame().unwrap().is_some() {
        frames += 1;
    }
    // About 1.5 s at twice real time, 50 Hz, several messages per instant.
    assert!(frames > 200, "{frames} frames: {}", r.counters);
    assert_eq!(
        r.counters.truncated + r.counters.bad_crc + r.counters.resync,
        0,
        "{}",
        r.counters
    );
}

/// A monitor that hears nothing says so once (a wrong port looks like this), and its summary
/// says no vehicle was seen.
#[test]
fn a_silent_link_is_told_not_waited_on_quietly() {
    use std::io::BufRead as _;
    let port = free_udp_port();
    let mut child = Command::new(bin())
        .args(["monitor", &format!("udpin:127.0.0.1:{port}"), "--headless"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Read stderr as it comes: the hint is due 5 s after the start; a loaded machine may be late.
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        for line in std::io::BufReader::new(stderr)
            .lines()
            .map_while(Result::ok)
        {
            let _ = tx.send(line);
        }
    });
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(30);
    let mut lines = Vec::new();
    while !lines
        .iter()
        .any(|l: &String| l.contains("no MAVLink frame in 5 s"))
    {
        let left = deadline.saturating_duration_since(std::time::Instant::now());
        match rx.recv_timeout(left) {
            Ok(l) => lines.push(l),
            Err(_) => break,
        }
    }
    // A second's more silence must not repeat it.
    std::thread::sleep(std::time::Duration::from_millis(1000));
    let out = interrupt(child);
    reader.join().unwrap();
    lines.extend(rx.try_iter());
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = lines.join("\n");
    assert!(out.status.success(), "{stdout} {stderr}");
    assert_eq!(
        stderr.matches("no MAVLink frame in 5 s").count(),
        1,
        "{stderr}"
    );
    assert!(stdout.contains("no vehicle seen"), "{stdout}");
}

/// ctrl-c (SIGINT) to a child, then its output.
fn interrupt(child: std::process::Child) -> std::process::Output {
    signal(child, "-INT")
}

/// `sig` to a child, then its output; a child still running 10 s later is killed and the
/// test fails (rather than hang).
fn signal(mut child: std::process::Child, sig: &str) -> std::process::Output {
    let status = Command::new("kill")
        .args([sig, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
    while child.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            child.kill().ok();
            panic!("{sig} did not end the monitor within 10 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    child.wait_with_output().unwrap()
}

/// Whether this process ignores SIGHUP (run under `nohup`): its children then inherit that.
fn hangup_ignored_here() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find_map(|l| l.strip_prefix("SigIgn:"))
                .and_then(|h| u64::from_str_radix(h.trim(), 16).ok())
        })
        .is_some_and(|mask| mask & 1 != 0)
}

/// A headless monitor on a free port, started by `launcher` (e.g. `nohup`) when given; returns
/// once it has said it listens (its signal handlers are set just after).
fn started_monitor(launcher: Option<&str>) -> std::process::Child {
    use std::io::BufRead as _;
    let port = free_udp_port();
    let mut cmd = match launcher {
        Some(l) => {
            let mut c = Command::new(l);
            c.arg(bin());
            c
        }
        None => Command::new(bin()),
    };
    let mut child = cmd
        .args(["monitor", &format!("udpin:127.0.0.1:{port}"), "--headless"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    while stderr.read_line(&mut line).unwrap() > 0 && !line.contains("listening on") {
        line.clear();
    }
    assert!(line.contains("listening on"), "{line}");
    // Keep draining stderr so the child never blocks on it.
    std::thread::spawn(move || std::io::copy(&mut stderr, &mut std::io::sink()));
    std::thread::sleep(std::time::Duration::from_millis(300));
    child
}

/// SIGTERM and SIGHUP (a closed terminal) end the monitor as ctrl-c does: exit 0, summary
/// printed (SIGHUP killed it with 129 and no summary). Under `nohup` a hangup is ignored.
#[cfg(target_os = "linux")]
#[test]
fn term_and_hangup_end_the_monitor_with_its_summary() {
    // Under a runner that ignores SIGHUP the monitor rightly ignores it too: only TERM then.
    let hup = !hangup_ignored_here();
    if !hup {
        eprintln!("this test process ignores SIGHUP: the hangup half is not tested");
    }
    for sig in ["-TERM", "-HUP"]
        .into_iter()
        .filter(|s| hup || *s != "-HUP")
    {
        let out = signal(started_monitor(None), sig);
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert_eq!(out.status.code(), Some(0), "{sig}: {stdout}");
        assert!(stdout.contains("no vehicle seen"), "{sig}: {stdout}");
    }
    if !hup {
        return;
    }
    let mut child = started_monitor(Some("nohup"));
    let status = Command::new("kill")
        .args(["-HUP", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    std::thread::sleep(std::time::Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "nohup: a hangup ended it"
    );
    let out = interrupt(child);
    assert_eq!(out.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&out.stdout).contains("no vehicle seen"));
}
