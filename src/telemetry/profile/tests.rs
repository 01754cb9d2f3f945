//! The profiles' tests: built-ins load, normalisation, errors name the line.

use super::*;

#[test]
fn builtin_profiles_parse() {
    for (name, _) in BUILTIN {
        let p = Profile::resolve(name).unwrap();
        assert_eq!(&p.name, name);
        let rp = p.rate_params();
        assert_eq!(rp.actuators(), p.actuators.len());
    }
}

#[test]
fn quad_x_follows_ardupilot_motor_order() {
    let p = Profile::resolve("quad-x").unwrap();
    // Motor 1 front right CCW, 2 back left CCW, 3 front left CW, 4 back right CW.
    let sign = |v: f64| v.signum() as i32;
    let expect = [[-1, 1, 1], [1, -1, 1], [1, 1, -1], [-1, -1, -1]];
    for (j, e) in expect.iter().enumerate() {
        let (c, v) = p.column(j);
        assert_eq!([sign(c[0]), sign(c[1]), sign(c[2])], *e, "motor {}", j + 1);
        assert!(v < 0.0);
        assert_eq!(p.actuators[j].channel as usize, j + 1);
    }
}

#[test]
fn normalisation_round_trips_and_respects_kind() {
    let p = Profile::resolve("heli-h3-120").unwrap();
    for j in 0..p.actuators.len() {
        for u in [-1.0, -0.3, 0.0, 0.4, 1.0] {
            let back = p.normalise(j, p.to_pwm(j, u));
            assert!((back - u).abs() < 1e-12);
        }
    }
    let q = Profile::resolve("quad-x").unwrap();
    assert_eq!(q.normalise(0, 1000.0), 0.0);
    assert_eq!(q.normalise(0, 2000.0), 1.0);
    assert_eq!(q.normalise(0, 1500.0), 0.5);
}

#[test]
fn unknown_key_names_file_line_and_key() {
    let text = include_str!("../../../replay/profiles/quad-x.toml")
        .replace("[noise]", "[noise]\nwobble = 3");
    let e = Profile::from_toml(&text, "x.toml").unwrap_err().to_string();
    assert!(e.starts_with("x.toml:"), "{e}");
    assert!(e.contains("wobble"), "{e}");
    let line: usize = e.split(':').nth(1).unwrap().parse().unwrap();
    assert!(line > 1);
}

/// An identified ARX profile whose model was left out would run on the bare geometry as if
/// identified (11 false decisions on the SITL heli manoeuvres log).
#[test]
fn an_identified_arx_profile_needs_its_model() {
    let text = include_str!("../../../replay/profiles/heli-h3-120.toml");
    assert!(Profile::from_toml(text, "h.toml").is_ok());
    let identified = text.replacen("rate_hz = 50.0", "rate_hz = 50.0\nidentified = true", 1);
    let e = Profile::from_toml(&identified, "h.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("needs its [model.arx] section"), "{e}");
}

#[test]
fn actuator_names_are_unique_and_printable() {
    let text = include_str!("../../../replay/profiles/quad-x.toml");
    let twice = text.replacen("name = \"motor2\"", "name = \"motor1\"", 1);
    let e = Profile::from_toml(&twice, "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("`motor1` is used twice"), "{e}");
    let empty = text.replacen("name = \"motor3\"", "name = \" \"", 1);
    let e = Profile::from_toml(&empty, "x.toml")
        .unwrap_err()
        .to_string();
    assert!(e.contains("actuator 3"), "{e}");
    // Any printable text is fine (the planner's 10-byte names are cut on a character).
    let umlaut = text.replacen("name = \"motor4\"", "name = \"höhe_ä\"", 1);
    assert!(Profile::from_toml(&umlaut, "x.toml").is_ok());
}

#[test]
fn missing_file_is_a_clear_error() {
    let e = Profile::resolve("/no/such/profile.toml").unwrap_err();
    assert!(e.to_string().contains("cannot read"), "{e}");
    let e = Profile::resolve("octo-z").unwrap_err();
    assert!(e.to_string().contains("quad-x"), "{e}");
}

/// Rule T1: the threshold is raised by the gusts' level over the reference (the root mean
/// square of the axes' ratios), never lowered, and not without a reference or a measurement.
#[test]
fn the_gust_factor_scales_with_the_measured_gusts() {
    let spec = DiagnosisSpec {
        gusts: Some([0.5, 0.5, 0.2]),
        ..DiagnosisSpec::default()
    };
    let f = spec
        .gust_factor(&[Some(0.75), Some(0.75), Some(0.3)])
        .unwrap();
    assert!((f - 1.5).abs() < 1e-12, "{f}");
    // Pooled: ratios 1.2, 1.0 and an unmeasured axis give sqrt((1.44 + 1) / 2).
    let f = spec.gust_factor(&[Some(0.6), Some(0.5), None]).unwrap();
    assert!((f - (2.44f64 / 2.0).sqrt()).abs() < 1e-12, "{f}");
    assert_eq!(spec.gust_factor(&[Some(0.4), Some(0.5), Some(0.2)]), None);
    // Never more than MAX_GUST_FACTOR.
    assert_eq!(spec.gust_factor(&[Some(5.0); 3]), Some(MAX_GUST_FACTOR));
    assert_eq!(spec.gust_factor(&[None; 3]), None);
    assert_eq!(DiagnosisSpec::default().gust_factor(&[Some(5.0); 3]), None);
    // A profile's reference must be positive.
    let text = include_str!("../../../replay/profiles/plane.toml").replace(
        "gusts = [0.575, 0.589, 0.178]",
        "gusts = [0.575, 0.0, 0.178]",
    );
    assert!(Profile::from_toml(&text, "plane.toml").is_err());
}

/// Numbers that are not finite, or so large that the calibration's products overflow, are
/// refused with their key before any maths runs (they used to reach nalgebra's SVD, which
/// panics on NaN and never returns on an infinity).
#[test]
fn out_of_range_numbers_are_refused_with_their_key() {
    let quad = include_str!("../../../replay/profiles/quad-x.toml");
    let first_angle = "angle_deg = 45.0";
    assert!(quad.contains(first_angle) && quad.contains("roll_gain = 60.0"));
    for (text, key) in [
        (
            quad.replace("roll_gain = 60.0", "roll_gain = 1e308"),
            "model.roll_gain",
        ),
        (
            quad.replacen(first_angle, "angle_deg = inf", 1),
            "angle_deg",
        ),
        (
            quad.replacen(first_angle, "angle_deg = nan", 1),
            "angle_deg",
        ),
        (
            quad.replacen(first_angle, "angle_deg = 45.0\nvertical = nan", 1),
            "vertical",
        ),
        (
            quad.replacen(
                first_angle,
                "angle_deg = 45.0\neffectiveness = [1e300, 0.0, 0.0]",
                1,
            ),
            "effectiveness",
        ),
        (
            quad.replacen("[[actuator]]", "[[actuator]]\npwm_max = 1e9", 1),
            "pwm_max",
        ),
        (quad.replace("gyro = ", "gyro = 1e6 #"), "noise.gyro"),
    ] {
        let e = Profile::from_toml(&text, "x.toml").unwrap_err().to_string();
        assert!(
            e.contains(key) && e.contains("must be within"),
            "{key}: {e}"
        );
    }
    // Every built-in profile is inside the ranges.
    for (name, _) in BUILTIN {
        Profile::resolve(name).unwrap();
    }
}
