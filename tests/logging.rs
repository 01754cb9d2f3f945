//! Diagnostics on stderr through tracing: `RUST_LOG=debug` and `-v` show the pipeline's
//! stages, the default shows the notes but no debug lines, `-q` leaves only the results on
//! stdout.

// Test code: a failed unwrap is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

mod common;

use std::process::Command;

const LOG: &str = "sitl_quad_motor1_gain0p7/arducopter_quad_sitl_motor1_mul0.7.tlog";

/// `ahcmon replay --headless LOG` with `flags` before the command and `rust_log`: (exit code,
/// stdout, stderr).
fn replay(flags: &[&str], rust_log: Option<&str>) -> (i32, String, String) {
    let log = common::data(LOG);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_ahcmon"));
    cmd.args(flags)
        .args(["replay", "--headless"])
        .arg(&log)
        .env_remove("RUST_LOG");
    if let Some(v) = rust_log {
        cmd.env("RUST_LOG", v);
    }
    let out = cmd.output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

const TO_CALIBRATING: &str =
    "debug ahcmon::pipeline: sysid 1: stage waiting for flight -> calibrating";
const TO_ESTIMATING: &str = "debug ahcmon::pipeline: sysid 1: stage calibrating -> estimating";

#[test]
fn rust_log_debug_and_v_show_the_pipelines_stages() {
    for (flags, rust_log) in [(&[][..], Some("debug")), (&["-v"][..], None)] {
        let (code, out, err) = replay(flags, rust_log);
        assert_eq!(code, 0, "{err}");
        let calibrating = err.find(TO_CALIBRATING).expect(&err);
        let estimating = err.find(TO_ESTIMATING).expect(&err);
        assert!(calibrating < estimating, "{err}");
        assert!(
            err.contains("debug ahcmon::monitor: sysid 1: a new vehicle"),
            "{err}"
        );
        // Results stay on stdout.
        assert!(out.contains("link: frames"), "{out}");
        assert!(!out.contains("debug "), "{out}");
    }
    // A module's level alone.
    let (_, _, err) = replay(&[], Some("ahcmon::pipeline=debug"));
    assert!(err.contains(TO_ESTIMATING), "{err}");
    assert!(!err.contains("ahcmon::monitor"), "{err}");
}

#[test]
fn the_default_says_the_notes_and_q_only_the_results() {
    let (code, out, err) = replay(&[], None);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("sysid 1: airborne at t="), "{err}");
    assert!(
        err.contains("sysid 1: warning: FRAME_TYPE not in the stream"),
        "{err}"
    );
    assert!(!err.contains("debug "), "{err}");
    let (code, quiet_out, quiet_err) = replay(&["-q"], None);
    assert_eq!(code, 0, "{quiet_err}");
    assert_eq!(quiet_err, "", "-q printed diagnostics");
    // The same results, without the timing line.
    let results = |s: &str| -> Vec<String> {
        s.lines()
            .filter(|l| !l.starts_with("replayed "))
            .map(str::to_owned)
            .collect()
    };
    assert_eq!(results(&quiet_out), results(&out));
    assert!(quiet_out.contains("motor1 ch1    fault "), "{quiet_out}");
    // -q and -v contradict each other.
    let (code, _, err) = replay(&["-q", "-v"], None);
    assert_eq!(code, 2, "{err}");
}

#[test]
fn a_bad_rust_log_is_said_and_the_default_kept() {
    let (code, _, err) = replay(&[], Some("ahcmon=loud"));
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("RUST_LOG=ahcmon=loud"), "{err}");
    assert!(err.contains("sysid 1: airborne at t="), "{err}");
}
