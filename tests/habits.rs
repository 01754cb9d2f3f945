//! The habits of the MAVLink world's command lines, through the binary: `-` for standard
//! output on every output flag.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use common::ahcmon;
use serde_json::Value;

fn sitl_log() -> String {
    common::data("sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog")
        .display()
        .to_string()
}

/// `--decisions -` streams the decisions' JSON lines to standard output, the same lines as a
/// file gets; the lines for a person (decisions, summary) go to standard error instead.
#[test]
fn decisions_to_stdout_are_the_file_s_lines_and_people_s_text_moves_to_stderr() {
    let log = sitl_log();
    let dir = common::temp_dir("habits_stdout");
    let file = dir.join("d.jsonl");
    let (code, to_file_out, _) = ahcmon(&["replay", &log, "--decisions", file.to_str().unwrap()]);
    assert_eq!(code, 0);
    let (code, out, err) = ahcmon(&["replay", &log, "--decisions", "-"]);
    assert_eq!(code, 0, "{err}");
    let from_file = std::fs::read_to_string(&file).unwrap();
    assert!(from_file.lines().count() >= 5, "{from_file}");
    assert_eq!(out, from_file);
    for line in out.lines() {
        let v: Value = serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {line}"));
        assert!(v["event"].is_string(), "{line}");
    }
    // What a person reads is the same text, on stderr now.
    let people: Vec<&str> = to_file_out
        .lines()
        .filter(|l| l.starts_with("t="))
        .collect();
    assert_eq!(people.len(), out.lines().count());
    for l in &people {
        assert!(err.contains(l), "{l} not on stderr");
    }
    assert!(err.contains("replayed "), "{err}");
}

/// Every output flag takes `-`: a plot and a simulated tlog come out on standard output whole
/// (the tlog byte for byte the file's);
/// two outputs cannot both have it.
#[test]
fn every_output_flag_takes_a_dash_and_only_one_may() {
    let log = sitl_log();
    let (code, out, err) = ahcmon(&["replay", &log, "--plot", "-", "-q"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("<?xml") && out.trim_end().ends_with("</svg>"));

    let dir = common::temp_dir("habits_tlog");
    let tlog = std::process::Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .args(["sim", "--scenario", "quad-x-motor2-loe", "--tlog", "-"])
        .output()
        .unwrap();
    assert!(tlog.status.success());
    let path = dir.join("to_file.tlog");
    let (code, _, err) = ahcmon(&[
        "sim",
        "--scenario",
        "quad-x-motor2-loe",
        "--tlog",
        path.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let file = std::fs::read(&path).unwrap();
    assert!(file.len() > 100_000);
    assert!(tlog.stdout == file, "the tlog on stdout is not the file's");
    // sim's own report goes to stderr.
    assert!(
        String::from_utf8_lossy(&tlog.stderr).contains("40 s of quad-x as sysid 1"),
        "{}",
        String::from_utf8_lossy(&tlog.stderr)
    );

    let (code, _, err) = ahcmon(&["replay", &log, "--decisions", "-", "--estimates", "-"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("--decisions and --estimates both name standard output (-)"),
        "{err}"
    );
}

/// A reader that stops early (`| head -1`) ends the run's output quietly, not as an error.
#[test]
fn a_reader_that_stops_early_is_no_error() {
    use std::io::Read;
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_ahcmon"))
        .args(["replay", &sitl_log(), "--estimates", "-", "-q"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = [0u8; 64];
    child.stdout.take().unwrap().read_exact(&mut first).unwrap();
    // stdout is closed here.
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(first.starts_with(b"{\"t\":"));
}

/// The completion script of `shell`, written to a file.
fn completion_script(shell: &str) -> std::path::PathBuf {
    let (code, script, err) = ahcmon(&["completions", shell]);
    assert_eq!(code, 0, "{err}");
    let path = common::temp_dir("habits_completions").join(format!("ahcmon.{shell}"));
    std::fs::write(&path, script).unwrap();
    path
}

/// Every shell's script names every command (they are generated from the same definition).
#[test]
fn completion_scripts_name_every_command() {
    for shell in ["bash", "zsh", "fish", "elvish", "powershell"] {
        let script = std::fs::read_to_string(completion_script(shell)).unwrap();
        for command in [
            "replay",
            "monitor",
            "demo",
            "calibrate",
            "benchmark",
            "completions",
        ] {
            assert!(script.contains(command), "{shell}: no {command}");
        }
        // Flags only one command has: `man --dir`, `replay --summary`, `--decisions`.
        for flag in ["dir", "summary", "decisions"] {
            assert!(script.contains(flag), "{shell}: no --{flag}");
        }
    }
    let (code, _, err) = ahcmon(&["completions", "tcsh"]);
    assert_eq!(code, 2);
    assert!(err.contains("possible values"), "{err}");
}

/// What a shell completes, as it would at the prompt: `shell -c` with the script loaded.
fn complete_in(shell: &str, program: &str) -> String {
    let out = std::process::Command::new(shell)
        .args(["-c", program])
        .output()
        .unwrap_or_else(|e| panic!("{shell} is needed for this test: {e}"));
    assert!(
        out.status.success(),
        "{shell}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// bash completes the commands and a command's flags from the script.
#[test]
fn bash_completes_commands_and_flags() {
    let script = completion_script("bash");
    let complete = |words: &str| {
        complete_in(
            "bash",
            &format!(
                "source '{}'; COMP_WORDS=({words}); COMP_CWORD=$((${{#COMP_WORDS[@]}} - 1)); \
                 _ahcmon ahcmon \"${{COMP_WORDS[-1]}}\" \"${{COMP_WORDS[-2]}}\"; \
                 printf '%s\\n' \"${{COMPREPLY[@]}}\"",
                script.display()
            ),
        )
    };
    assert_eq!(complete("ahcmon rep").trim(), "replay");
    let flags = complete("ahcmon replay --dec");
    assert_eq!(
        flags.trim(),
        "--decisions --decimate".replace(' ', "\n").trim()
    );
}

/// zsh loads the script as a completion function; fish completes from it (`complete -C`).
/// Needs zsh and fish (Debian: apt-get install zsh fish): `cargo test --release --test habits
/// -- --ignored`.
#[test]
#[ignore = "needs zsh and fish installed"]
fn zsh_and_fish_load_and_complete() {
    let zsh = completion_script("zsh");
    let loaded = complete_in(
        "zsh",
        &format!(
            "autoload -U compinit && compinit -u -D; source '{}'; whence -w _ahcmon",
            zsh.display()
        ),
    );
    assert!(loaded.contains("_ahcmon: function"), "{loaded}");
    let fish = completion_script("fish");
    let got = complete_in(
        "fish",
        &format!("source '{}'; complete -C 'ahcmon rep'", fish.display()),
    );
    assert!(got.lines().any(|l| l.starts_with("replay")), "{got}");
    let got = complete_in(
        "fish",
        &format!(
            "source '{}'; complete -C 'ahcmon replay --dec'",
            fish.display()
        ),
    );
    assert!(got.contains("--decisions"), "{got}");
}

/// The manual page renders (man -l) with every command; --dir writes one page per command.
#[test]
fn the_manual_page_renders_and_names_every_command() {
    let dir = common::temp_dir("habits_man");
    let (code, page, err) = ahcmon(&["man"]);
    assert_eq!(code, 0, "{err}");
    let file = dir.join("ahcmon.1");
    std::fs::write(&file, page).unwrap();
    let shown = std::process::Command::new("man")
        .arg("-l")
        .arg(&file)
        .env("MANPAGER", "cat")
        .env("MANWIDTH", "100")
        .output()
        .expect("man (man-db) to render the page");
    let text = String::from_utf8_lossy(&shown.stdout);
    assert!(
        shown.status.success() && text.contains("SYNOPSIS"),
        "{text}"
    );
    for command in ["replay", "monitor", "completions"] {
        assert!(text.contains(command), "no {command} in {text}");
    }
    let pages = dir.join("pages");
    let (code, _, err) = ahcmon(&["man", "--dir", pages.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    for page in ["ahcmon.1", "ahcmon-replay.1", "ahcmon-monitor.1"] {
        assert!(pages.join(page).is_file(), "no {page}");
    }
}

/// `--summary FILE`: the end-of-run summary as JSON, the same counts and states as the text
/// summary and the decisions file.
#[test]
fn the_summary_as_json_agrees_with_the_decisions_and_the_text() {
    let dir = common::temp_dir("habits_summary");
    let (summary, decisions) = (dir.join("s.json"), dir.join("d.jsonl"));
    let (code, text, err) = ahcmon(&[
        "replay",
        &sitl_log(),
        "--summary",
        summary.to_str().unwrap(),
        "--decisions",
        decisions.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&summary).unwrap()).unwrap();
    let ds: Vec<Value> = std::fs::read_to_string(&decisions)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(doc["version"], 1);
    assert_eq!(doc["decisions"].as_u64().unwrap() as usize, ds.len());
    let vehicle = &doc["vehicles"][0];
    assert_eq!(vehicle["sysid"], 1);
    assert_eq!(vehicle["type"], "quadrotor");
    assert_eq!(vehicle["stage"], "estimating");
    let actuators = vehicle["actuators"].as_array().unwrap();
    assert_eq!(actuators.len(), 4);
    for a in actuators {
        let name = a["name"].as_str().unwrap();
        let faults = ds
            .iter()
            .filter(|d| d["actuator"] == name && d["event"] == "fault")
            .count();
        assert_eq!(a["faults"].as_u64().unwrap() as usize, faults, "{name}");
        let state = a["state"].as_str().unwrap();
        assert!(
            text.lines().any(|l| l.contains(name) && l.ends_with(state)),
            "{name}: {state} not in the text summary"
        );
        for filter in ["mit-ukf", "mit-esmf", "set"] {
            let e = &a["estimates"][filter];
            let [lo, hi] = [0, 1].map(|k| e["gamma_bounds"][k].as_f64().unwrap());
            assert!(lo <= hi, "{name} {filter}");
        }
    }
    // The faulted motor: one fault, cleared after its removal (the log's truth).
    assert_eq!(actuators[0]["faults"], 1);
    assert!(
        actuators[0]["state"]
            .as_str()
            .unwrap()
            .starts_with("cleared at")
    );
}

/// A one-hour log's plot: small (an envelope per pixel column), time on the vehicle's clock
/// as m:ss at round steps, the title within the canvas, valid XML.
#[test]
fn a_one_hour_plot_is_small_and_reads_as_a_clock() {
    let dir = common::temp_dir("habits_plot_1h");
    let (tlog, svg) = (dir.join("1h.tlog"), dir.join("1h.svg"));
    let scenario =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("replay/scenarios/quad-x-1h.toml");
    let (code, _, err) = ahcmon(&[
        "sim",
        "--scenario",
        scenario.to_str().unwrap(),
        "--tlog",
        tlog.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = ahcmon(&[
        "replay",
        tlog.to_str().unwrap(),
        "--plot",
        svg.to_str().unwrap(),
        "-q",
    ]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.len() <= 300_000, "{} bytes", text.len());
    for tick in [">10:00<", ">30:00<", ">50:00<"] {
        assert!(text.contains(tick), "no tick {tick}");
    }
    assert!(!text.contains(">-0.0"), "a tick reads -0");
    // Four motors, gamma, delta and the output at the recent command each.
    assert_eq!(text.matches("<rect x=").count(), 12);
    let checked = common::run_python(&[
        "-c",
        "import sys, xml.dom.minidom as m; m.parse(sys.argv[1]); print('ok')",
        svg.to_str().unwrap(),
    ]);
    assert_eq!(checked.trim(), "ok");
}

/// `--plot FILE.png` draws the same picture as the SVG, rasterised at twice its size: a PNG
/// whose every chunk's CRC holds (checked by Python's zlib, not by the encoder's crate) and
/// whose pixels inflate to exactly its stated size.
#[test]
fn a_plot_named_png_is_a_png_of_the_svg() {
    let dir = common::temp_dir("habits_plot_png");
    let (svg, png) = (dir.join("p.svg"), dir.join("p.PNG"));
    for out in [&svg, &png] {
        let (code, _, err) =
            ahcmon(&["replay", &sitl_log(), "--plot", out.to_str().unwrap(), "-q"]);
        assert_eq!(code, 0, "{err}");
    }
    let text = std::fs::read_to_string(&svg).unwrap();
    let attr = |name: &str| -> u32 {
        let at = text.find(&format!(" {name}=\"")).unwrap() + name.len() + 3;
        text[at..at + text[at..].find('"').unwrap()]
            .parse()
            .unwrap()
    };
    let checked = common::run_python(&[
        "-c",
        r#"
import struct, sys, zlib
d = open(sys.argv[1], 'rb').read()
assert d[:8] == b'\x89PNG\r\n\x1a\n', 'no PNG signature'
at, idat, ihdr = 8, b'', None
while at < len(d):
    n, kind = struct.unpack('>I4s', d[at:at + 8])
    body = d[at + 8:at + 8 + n]
    assert struct.unpack('>I', d[at + 8 + n:at + 12 + n])[0] == zlib.crc32(kind + body), kind
    if kind == b'IHDR': ihdr = struct.unpack('>IIBB', body[:10])
    if kind == b'IDAT': idat += body
    at += 12 + n
w, h, depth, colour = ihdr
per_pixel = {6: 4, 2: 3}[colour] * depth // 8
assert len(zlib.decompress(idat)) == h * (1 + w * per_pixel), 'pixel data'
print(w, h)
"#,
        png.to_str().unwrap(),
    ]);
    assert_eq!(
        checked.trim(),
        format!("{} {}", 2 * attr("width"), 2 * attr("height"))
    );
}

/// A decision on a filter alarm carries the numbers behind it (the alarming filter's
/// statistic and threshold), and its line shows them: the SITL quad's first fault line read
/// healthy-looking MIT-UKF numbers while the MIT-ESMF alone alarmed.
#[test]
fn a_filter_alarm_s_decision_shows_the_numbers_behind_it() {
    let dir = common::temp_dir("habits_evidence");
    let file = dir.join("d.jsonl");
    let (code, out, err) = ahcmon(&["replay", &sitl_log(), "--decisions", file.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let ds: Vec<Value> = std::fs::read_to_string(&file)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    for d in &ds {
        let filters = d["filters"].as_array().unwrap();
        let e = &d["evidence"];
        // (A `changed` names the filters that alarmed on the fault; the evidence is of those
        // alarming at its step.)
        if filters.is_empty() {
            assert!(e.is_null(), "{d}");
        } else if !e.is_null() {
            assert!(filters.contains(&e["filter"]), "{d}");
        }
    }
    let first = ds.iter().find(|d| d["event"] == "fault").expect("a fault");
    let e = &first["evidence"];
    let (value, threshold) = (
        e["value"].as_f64().unwrap(),
        e["threshold"].as_f64().unwrap(),
    );
    assert!(value > threshold, "{first}");
    let line = out
        .lines()
        .find(|l| l.contains(" fault "))
        .expect("a fault line");
    assert!(
        line.contains(&format!("dev {value:.3}/{threshold:.3}")),
        "{line}"
    );
}

/// An input that is not a log leaves `--summary`'s file as it was, like the other outputs.
#[test]
fn a_summary_is_not_replaced_when_the_input_is_no_log() {
    let dir = common::temp_dir("habits_summary_kept");
    let (junk, summary) = (dir.join("junk.tlog"), dir.join("s.json"));
    std::fs::write(&junk, vec![0x55u8; 4096]).unwrap();
    std::fs::write(&summary, "yesterday's\n").unwrap();
    let (code, _, err) = ahcmon(&[
        "replay",
        junk.to_str().unwrap(),
        "--summary",
        summary.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert_eq!(std::fs::read_to_string(&summary).unwrap(), "yesterday's\n");
}
