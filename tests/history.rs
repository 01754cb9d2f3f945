//! A generated archive through `scan` and `history`: two simulated quads (system ids 1 and 2)
//! × 12 flights of 90 s in gusts with 10 % damping mismatch, each flight its own seed. On
//! airframe 1 motor 2's gain falls 0.02 a flight from 1.0 (0.8 at flight 11); the rest are
//! healthy. A profile `calibrate` identified on a healthy flight of the type is given to
//! `scan`, so each flight is measured against the healthy model from its take-off.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::ahcmon;
use serde_json::Value;

const FLIGHTS: usize = 12;
const FALL: f64 = 0.02;

#[test]
fn a_slowly_weakening_motor_is_flagged_before_it_is_lost_and_no_healthy_one_is() {
    let dir = common::temp_dir("history_archive");
    let base = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("replay/scenarios/quad-x-motor2-loe-live.toml"),
    )
    .unwrap();
    // The scenario without its fault, 90 s long, with a seed.
    let healthy = |seed: usize| -> String {
        base.split("[[fault]]")
            .next()
            .unwrap()
            .lines()
            .map(|l| match l {
                l if l.starts_with("duration_s") => "duration_s = 90.0".to_string(),
                l if l.starts_with("seed") => format!("seed = {seed}"),
                l => l.to_string(),
            })
            .collect::<Vec<_>>()
            .join("\n")
    };
    let sim = |name: &str, scenario: String, sysid: u8| {
        let (toml, tlog) = (
            dir.join(format!("{name}.toml")),
            dir.join(format!("{name}.tlog")),
        );
        std::fs::write(&toml, scenario).unwrap();
        let (code, _, err) = ahcmon(&[
            "-q",
            "sim",
            "--scenario",
            toml.to_str().unwrap(),
            "--sysid",
            &sysid.to_string(),
            "--tlog",
            tlog.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{name}: {err}");
        tlog
    };
    let cal = sim("calibration", healthy(500), 9);
    let profile = dir.join("airframe.toml");
    let (code, _, err) = ahcmon(&[
        "calibrate",
        cal.to_str().unwrap(),
        "--until",
        "40",
        "-o",
        profile.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let mut logs = Vec::new();
    for airframe in [1u8, 2] {
        for m in 0..FLIGHTS {
            let mut scenario = healthy(100 * usize::from(airframe) + m);
            if airframe == 1 {
                let gamma = 1.0 - FALL * m as f64;
                scenario.push_str(&format!(
                    "\n\n[[fault]]\nactuator = \"motor2\"\nt = 0.0\ngamma = {gamma}\n"
                ));
            }
            logs.push(sim(&format!("a{airframe}-f{m:02}"), scenario, airframe));
        }
    }
    let rows = dir.join("rows.jsonl");
    let mut args = vec!["scan".to_string()];
    args.extend(logs.iter().map(|p| p.display().to_string()));
    args.extend([
        "--profile".into(),
        profile.display().to_string(),
        "--rows".into(),
        rows.display().to_string(),
    ]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let (code, _, err) = ahcmon(&args);
    assert_eq!(code, 0, "{err}");
    let report = dir.join("history.json");
    let plot = report.with_extension("png");
    let (code, out, err) = ahcmon(&[
        "history",
        rows.to_str().unwrap(),
        "--json",
        report.to_str().unwrap(),
        "--plot",
        plot.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let png = std::fs::read(&plot).unwrap();
    assert!(
        png.starts_with(b"\x89PNG\r\n\x1a\n"),
        "--plot .png writes a PNG"
    );
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    let series = doc["series"].as_array().unwrap();
    assert_eq!(series.len(), 8, "{out}");
    // The flight (1-based) at which the truth reaches the loss gain 0.8.
    let lost_at = (0.2 / FALL).round() as u64 + 1;
    for s in series {
        let (airframe, actuator) = (
            s["airframe"].as_str().unwrap(),
            s["actuator"].as_str().unwrap(),
        );
        assert_eq!(s["flights"].as_array().unwrap().len(), FLIGHTS);
        let alarm = s["alarm_from_flight"].as_u64();
        if (airframe, actuator) == ("sysid 1", "motor2") {
            let at = alarm.unwrap_or_else(|| panic!("the weakening motor not flagged:\n{out}"));
            assert!(
                at < lost_at,
                "flagged at flight {at}, lost at {lost_at}:\n{out}"
            );
            eprintln!(
                "flagged at flight {at}, {} flights before the loss",
                lost_at - at
            );
        } else {
            assert_eq!(alarm, None, "{airframe} {actuator} flagged:\n{out}");
        }
    }
}
