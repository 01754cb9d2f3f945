//! Which built-in profile a vehicle gets, from what it says about itself: HEARTBEAT's MAV_TYPE
//! and, when the stream carries them, ArduPilot's FRAME_CLASS / FRAME_TYPE / H_SW_TYPE and the
//! `SERVOn_*` / `MOT_PWM_*` parameters. Anything assumed is said once, with the override.

use super::assembler::VehicleInfo;
use super::profile::{Profile, ProfileError, Role, VehicleKind};
use crate::protocol::dialects::ahcmon::{MavAutopilot, MavType};
use thiserror::Error;

#[derive(Debug, Error)]
pub enum DetectError {
    #[error(
        "sysid {sysid}: no heartbeat from an autopilot yet, so the vehicle type is unknown; pass --profile NAME|FILE"
    )]
    NoHeartbeat { sysid: u8 },
    #[error(
        "sysid {sysid}: no built-in profile for MAV_TYPE {mav_type:?}; pass --profile NAME|FILE"
    )]
    Unsupported { sysid: u8, mav_type: MavType },
    #[error(transparent)]
    Profile(#[from] ProfileError),
}

/// The profile for a vehicle, and how it was chosen.
#[derive(Debug, Clone)]
pub struct Detection {
    pub profile: Profile,
    /// One line per assumption (what, and how to override it).
    pub warnings: Vec<String>,
    /// How the profile was chosen, for the summary.
    pub source: String,
}

/// ArduPilot's SERVOn_FUNCTION of the actuator `index`-th of its role in a profile.
fn ardupilot_function(role: Role, index: usize) -> Option<u32> {
    match role {
        // k_motor1.. = 33..40 (multirotor motors; TradHeli swash servos 1-3 and the tail).
        Role::Motor | Role::Swash => Some(33 + index as u32),
        Role::Tail => Some(36),
        Role::Aileron => Some(4),
        Role::Elevator => Some(19),
        Role::Rudder => Some(21),
        Role::Throttle => Some(70),
        Role::Custom => None,
    }
}

/// Pick a built-in profile from the heartbeat and the parameters seen so far.
pub fn detect(info: &VehicleInfo) -> Result<Detection, DetectError> {
    let sysid = info.sysid;
    let mav_type = info.mav_type.ok_or(DetectError::NoHeartbeat { sysid })?;
    let mut warnings = Vec::new();
    let frame_class = info.param("FRAME_CLASS");
    let frame_type = info.param("FRAME_TYPE");
    let name = match mav_type {
        MavType::MAV_TYPE_HELICOPTER => {
            // H3 generic (0, an older default) with servos at -60/60/180° and no phase angle is
            // the H3-120 head by another name.
            let generic_is_120 = [
                ("H_SW_H3_SV1_POS", -60.0),
                ("H_SW_H3_SV2_POS", 60.0),
                ("H_SW_H3_SV3_POS", 180.0),
                ("H_SW_H3_PHANG", 0.0),
            ]
            .iter()
            .all(|(k, want)| info.param(k).is_some_and(|v| (v - want).abs() < 0.5));
            match info.param("H_SW_TYPE") {
                Some(v) if v as i64 == 3 => {}
                Some(v) if v as i64 == 0 && generic_is_120 => {}
                Some(v) => warnings.push(format!(
                    "sysid {sysid}: H_SW_TYPE {v} is not H3-120, the only swashplate with a built-in profile; estimates assume H3-120 (write a profile for your head and pass --profile FILE)"
                )),
                None => warnings.push(format!(
                    "sysid {sysid}: H_SW_TYPE not in the stream; assuming ArduPilot's default H3-120 head (servo 1 left, 2 right, 3 rear, 4 tail); --profile overrides"
                )),
            }
            "heli-h3-120"
        }
        MavType::MAV_TYPE_QUADROTOR => match frame_type.map(|v| v as i64) {
            Some(0) => "quad-plus",
            Some(1) => "quad-x",
            Some(other) => {
                warnings.push(format!(
                    "sysid {sysid}: FRAME_TYPE {other} has no built-in profile; assuming quad X; --profile overrides"
                ));
                "quad-x"
            }
            None if info.autopilot == Some(MavAutopilot::MAV_AUTOPILOT_PX4) => {
                warnings.push(format!(
                    "sysid {sysid}: PX4 does not say in the stream whether the frame is + or X; assuming quad X (ArduPilot's motor order: check that the outputs are in it, or write a profile); pass --profile quad-plus for a + frame"
                ));
                "quad-x"
            }
            None => {
                warnings.push(format!(
                    "sysid {sysid}: FRAME_TYPE not in the stream, so + or X is unknown; assuming quad X (ArduPilot motor order); pass --profile quad-plus for a + frame"
                ));
                "quad-x"
            }
        },
        MavType::MAV_TYPE_HEXAROTOR => {
            if frame_type.is_some_and(|v| v as i64 != 1) {
                warnings.push(format!(
                    "sysid {sysid}: FRAME_TYPE {} is not X; assuming hexa X; --profile overrides",
                    frame_type.unwrap_or(0.0)
                ));
            }
            "hexa-x"
        }
        MavType::MAV_TYPE_FIXED_WING => "plane",
        other => {
            return Err(DetectError::Unsupported {
                sysid,
                mav_type: other,
            });
        }
    };
    if let Some(fc) = frame_class {
        let expected = match name {
            "heli-h3-120" => 6,
            "quad-plus" | "quad-x" => 1,
            "hexa-x" => 2,
            _ => fc as i64,
        };
        if fc as i64 != expected {
            warnings.push(format!(
                "sysid {sysid}: FRAME_CLASS {fc} does not match MAV_TYPE {mav_type:?}; using {name}; --profile overrides"
            ));
        }
    }
    let mut profile = Profile::resolve(name)?;
    let mapped = apply_params(&mut profile, info);
    if mapped > 0 {
        warnings.extend(mapping_warnings(&profile, mapped, sysid));
    }
    let source = format!(
        "{name} (from HEARTBEAT {mav_type:?}{}{})",
        if frame_type.is_some() {
            ", FRAME_TYPE"
        } else {
            ""
        },
        if mapped > 0 {
            format!(", {mapped} outputs from SERVOn_* parameters")
        } else {
            String::new()
        }
    );
    Ok(Detection {
        profile,
        warnings,
        source,
    })
}

/// What a partial set of `SERVOn_FUNCTION` parameters leaves doubtful: actuators still on
/// the profile's default output, and outputs two actuators now share.
fn mapping_warnings(profile: &Profile, mapped: usize, sysid: u8) -> Vec<String> {
    let mut out = Vec::new();
    if mapped < profile.actuators.len() {
        out.push(format!(
            "sysid {sysid}: SERVOn_FUNCTION gave the output of {mapped} of {} actuators; the others keep the profile's default channel; --profile overrides",
            profile.actuators.len()
        ));
    }
    for (j, a) in profile.actuators.iter().enumerate() {
        if let Some(b) = profile.actuators[..j]
            .iter()
            .find(|b| b.channel == a.channel)
        {
            out.push(format!(
                "sysid {sysid}: {} and {} are both on output {}: the parameters do not say where one of them is; pass --profile FILE",
                b.name, a.name, a.channel
            ));
        }
    }
    out
}

/// ArduPilot's fixed swash servo travel each side of trim (µs), from 4.0 on.
pub const SWASH_HALF_TRAVEL_US: f64 = 500.0;

/// An old TradHeli whose swash servos were scaled per side by SERVOn_MIN/TRIM/MAX: its
/// swashplate parameter is `H_SWASH_TYPE` and it has none of the swash library's `H_SW_*`
/// (whose `rc_write_swash` drives trim ± 500 µs).
fn pre_4_0_heli(info: &VehicleInfo) -> bool {
    info.param("H_SWASH_TYPE").is_some() && !info.params.keys().any(|k| k.starts_with("H_SW_"))
}

/// Warnings for a profile given with `--profile` on a vehicle whose parameters say how it
/// drives its outputs: a swash servo whose range is not ArduPilot's fixed trim ± 500 µs reads
/// its offsets and stuck positions scaled.
pub fn given_profile_warnings(profile: &Profile, info: &VehicleInfo) -> Vec<String> {
    let mut warnings: Vec<String> = kind_mismatch(profile, info).into_iter().collect();
    let ardupilot_heli = info.param("H_SW_TYPE").is_some() || info.param("H_SWASH_TYPE").is_some();
    if !ardupilot_heli || pre_4_0_heli(info) {
        return warnings;
    }
    warnings.extend(swash_range_warnings(profile, info));
    warnings
}

/// A `--profile` for another kind of vehicle (or another number of motors) than the one whose
/// HEARTBEAT is in the stream: its model fits nothing, and its estimates and decisions mean
/// nothing (a plane's profile on a quadrotor read every gain as 0 and faulted its surfaces).
fn kind_mismatch(profile: &Profile, info: &VehicleInfo) -> Option<String> {
    let mav_type = info.mav_type?;
    let (kind, motors) = match mav_type {
        MavType::MAV_TYPE_HELICOPTER => (VehicleKind::Helicopter, None),
        MavType::MAV_TYPE_QUADROTOR => (VehicleKind::Multirotor, Some(4)),
        MavType::MAV_TYPE_HEXAROTOR => (VehicleKind::Multirotor, Some(6)),
        MavType::MAV_TYPE_OCTOROTOR => (VehicleKind::Multirotor, Some(8)),
        MavType::MAV_TYPE_TRICOPTER => (VehicleKind::Multirotor, Some(3)),
        MavType::MAV_TYPE_FIXED_WING => (VehicleKind::Plane, None),
        _ => return None,
    };
    let profile_motors = profile
        .actuators
        .iter()
        .filter(|a| a.role == Role::Motor)
        .count();
    let what = |k: VehicleKind| match k {
        VehicleKind::Helicopter => "helicopter",
        VehicleKind::Multirotor => "multirotor",
        VehicleKind::Plane => "plane",
    };
    let heartbeat = format!("{mav_type:?}")
        .trim_start_matches("MAV_TYPE_")
        .to_lowercase();
    if profile.vehicle != kind {
        return Some(format!(
            "sysid {}: the profile {} is for a {}, but the vehicle's HEARTBEAT says {heartbeat}: its model will not fit, and its estimates and decisions mean nothing (leave --profile out to choose by the HEARTBEAT)",
            info.sysid,
            profile.name,
            what(profile.vehicle)
        ));
    }
    match motors {
        Some(n) if profile_motors != n => Some(format!(
            "sysid {}: the profile {} has {profile_motors} motors, but the vehicle's HEARTBEAT says {heartbeat} ({n}): its model will not fit, and its estimates and decisions mean nothing",
            info.sysid, profile.name
        )),
        _ => None,
    }
}

fn swash_range_warnings<'a>(
    profile: &'a Profile,
    info: &'a VehicleInfo,
) -> impl Iterator<Item = String> + 'a {
    profile
        .actuators
        .iter()
        .filter(|a| a.role == Role::Swash)
        .filter(|a| {
            (a.pwm_max - a.pwm_trim - SWASH_HALF_TRAVEL_US).abs() > 1.0
                || (a.pwm_trim - a.pwm_min - SWASH_HALF_TRAVEL_US).abs() > 1.0
        })
        .map(|a| {
            format!(
                "sysid {}: {} in the profile spans {}..{} µs about {} µs; ArduPilot drives swash servos at trim ± {SWASH_HALF_TRAVEL_US} µs (SERVOn_MIN/MAX only clip), so its offsets and stuck positions read scaled (write pwm_min/pwm_max = trim ∓ 500)",
                info.sysid, a.name, a.pwm_min, a.pwm_max, a.pwm_trim
            )
        })
}

/// Map the profile's actuators to outputs and PWM ranges from ArduPilot's `SERVOn_FUNCTION`,
/// `SERVOn_MIN/TRIM/MAX/REVERSED`, (motors) `MOT_PWM_MIN/MAX` or the throttle stick's
/// `RCn_MIN/MAX`, and (swash servos) their fixed travel. Returns how many actuators were
/// mapped from parameters.
pub fn apply_params(profile: &mut Profile, info: &VehicleInfo) -> usize {
    let mut mapped = 0;
    let mut seen = std::collections::BTreeMap::<Role, usize>::new();
    for a in profile.actuators.iter_mut() {
        let index = seen.entry(a.role).or_insert(0);
        let function = ardupilot_function(a.role, *index);
        *index += 1;
        let Some(function) = function else { continue };
        // SERVO1..32 (outputs past 16 come in SERVO_OUTPUT_RAW port 1, which is not read:
        // their samples are then counted as missing an output, not read from a wrong one).
        let channel = (1..=32u8).find(|n| {
            info.param(&format!("SERVO{n}_FUNCTION"))
                .is_some_and(|f| f as u32 == function)
        });
        let Some(n) = channel else { continue };
        a.channel = n;
        mapped += 1;
        let get = |what: &str| info.param(&format!("SERVO{n}_{what}"));
        if a.role == Role::Swash && !pre_4_0_heli(info) {
            // ArduPilot drives a swash servo at trim ± 500 µs for a full command
            // (AP_MotorsHeli_Swash: `1500 + 500 * swash_in`, then `set_output_pwm_trimmed`);
            // SERVOn_MIN/MAX only clip it, so they are not its scale. (Before 4.0, with
            // H_SWASH_TYPE, the servos were scaled per side by SERVOn_MIN/TRIM/MAX: the angle
            // branch below.)
            let trim = get("TRIM").filter(|t| (800.0..=2200.0).contains(t));
            let trim = trim.unwrap_or(a.pwm_trim);
            a.pwm_trim = trim;
            a.pwm_min = trim - SWASH_HALF_TRAVEL_US;
            a.pwm_max = trim + SWASH_HALF_TRAVEL_US;
            a.reversed = get("REVERSED").is_some_and(|r| r != 0.0);
        } else if a.role == Role::Motor {
            // AP_MotorsMulticopter::get_pwm_output_min/max: MOT_PWM_MIN/MAX when both are set,
            // else the throttle stick's calibrated range, RC{RCMAP_THROTTLE}_MIN/MAX.
            let throttle_rc = info.param("RCMAP_THROTTLE").map_or(3, |n| n as u32);
            let valid = |lo: Option<f64>, hi: Option<f64>| match (lo, hi) {
                (Some(lo), Some(hi)) if lo > 0.0 && hi > lo => Some((lo, hi)),
                _ => None,
            };
            let (mot_min, mot_max) = (info.param("MOT_PWM_MIN"), info.param("MOT_PWM_MAX"));
            // Without MOT_PWM_* in the stream the profile's range stands (today's defaults).
            let range = if mot_min.is_none() && mot_max.is_none() {
                None
            } else {
                valid(mot_min, mot_max)
                    .or_else(|| {
                        valid(
                            info.param(&format!("RC{throttle_rc}_MIN")),
                            info.param(&format!("RC{throttle_rc}_MAX")),
                        )
                    })
                    .or_else(|| valid(get("MIN"), get("MAX")))
            };
            if let Some((lo, hi)) = range {
                a.pwm_min = lo;
                a.pwm_max = hi;
            }
        } else if a.role.is_range() {
            // A plane's throttle: SRV_Channel scales it over SERVOn_MIN..MAX, reversed if set.
            if let (Some(lo), Some(hi)) = (get("MIN"), get("MAX"))
                && hi > lo
            {
                a.pwm_min = lo;
                a.pwm_max = hi;
            }
            a.reversed = get("REVERSED").is_some_and(|r| r != 0.0);
        } else if let (Some(lo), Some(trim), Some(hi)) = (get("MIN"), get("TRIM"), get("MAX"))
            && lo < trim
            && trim < hi
        {
            a.pwm_min = lo;
            a.pwm_trim = trim;
            a.pwm_max = hi;
            a.reversed = get("REVERSED").is_some_and(|r| r != 0.0);
        }
    }
    mapped
}

#[cfg(test)]
mod tests {
    use super::*;

    fn info(mav_type: MavType, params: &[(&str, f32)]) -> VehicleInfo {
        VehicleInfo {
            sysid: 1,
            compid: Some(1),
            mav_type: Some(mav_type),
            autopilot: Some(MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA),
            params: params.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            ..Default::default()
        }
    }

    #[test]
    fn a_given_profile_for_another_kind_of_vehicle_is_warned_about() {
        let quad = info(MavType::MAV_TYPE_QUADROTOR, &[]);
        let warned = |name: &str, on: &VehicleInfo| {
            given_profile_warnings(&Profile::resolve(name).unwrap(), on)
                .iter()
                .any(|w| w.contains("mean nothing"))
        };
        assert!(warned("plane", &quad));
        assert!(warned("paper-heli", &quad));
        assert!(warned("hexa-x", &quad), "six motors for four");
        assert!(!warned("quad-x", &quad));
        assert!(!warned("quad-plus", &quad));
        assert!(!warned("hexa-x", &info(MavType::MAV_TYPE_HEXAROTOR, &[])));
        assert!(!warned(
            "heli-h3-120",
            &info(MavType::MAV_TYPE_HELICOPTER, &[])
        ));
        assert!(warned("quad-x", &info(MavType::MAV_TYPE_FIXED_WING, &[])));
        // A vehicle type we have no profiles for says nothing either way.
        assert!(!warned("quad-x", &info(MavType::MAV_TYPE_SUBMARINE, &[])));
    }

    #[test]
    fn partial_servo_functions_are_warned_about() {
        // A plane whose rudder is on output 2 (SERVO2_FUNCTION 21) while the elevator's
        // parameter has not arrived: the elevator keeps its default output 2.
        let d = detect(&info(
            MavType::MAV_TYPE_FIXED_WING,
            &[("SERVO1_FUNCTION", 4.0), ("SERVO2_FUNCTION", 21.0)],
        ))
        .unwrap();
        let all = d.warnings.join(" | ");
        assert!(all.contains("2 of 3 actuators"), "{all}");
        assert!(all.contains("both on output 2"), "{all}");
        // All four motors of a quad given: no warning about the mapping. A motor past output
        // 16 is mapped there (and then counted as missing its output).
        let quad = |motor4_output: u8| {
            let motor4 = format!("SERVO{motor4_output}_FUNCTION");
            let params = [
                ("FRAME_TYPE", 1.0),
                ("SERVO1_FUNCTION", 33.0),
                ("SERVO2_FUNCTION", 34.0),
                ("SERVO3_FUNCTION", 35.0),
                (motor4.as_str(), 36.0),
            ];
            detect(&info(MavType::MAV_TYPE_QUADROTOR, &params)).unwrap()
        };
        let d = quad(4);
        assert!(d.warnings.is_empty(), "{:?}", d.warnings);
        let d = quad(17);
        assert_eq!(d.profile.actuators[3].channel, 17);
    }

    #[test]
    fn swash_servos_are_scaled_by_their_fixed_travel_not_their_limits() {
        // ArduPilot drives swash servos at trim ± 500 µs; SERVOn_MIN/MAX only clip.
        let d = detect(&info(
            MavType::MAV_TYPE_HELICOPTER,
            &[
                ("H_SW_TYPE", 3.0),
                ("SERVO1_FUNCTION", 33.0),
                ("SERVO1_MIN", 1100.0),
                ("SERVO1_TRIM", 1520.0),
                ("SERVO1_MAX", 1900.0),
                ("SERVO1_REVERSED", 1.0),
                ("SERVO4_FUNCTION", 36.0),
                ("SERVO4_MIN", 1100.0),
                ("SERVO4_TRIM", 1500.0),
                ("SERVO4_MAX", 1900.0),
            ],
        ))
        .unwrap();
        let p = &d.profile;
        let swash1 = &p.actuators[0];
        assert_eq!(
            (
                swash1.pwm_min,
                swash1.pwm_trim,
                swash1.pwm_max,
                swash1.reversed
            ),
            (1020.0, 1520.0, 2020.0, true)
        );
        // 1770 µs is half a full command on the reversed servo.
        assert!((p.normalise(0, 1770.0) + 0.5).abs() < 1e-12);
        // The tail is an angle output scaled per side by its limits, as ArduPilot does.
        let tail = p.actuators.iter().position(|a| a.name == "tail").unwrap();
        assert!((p.normalise(tail, 1700.0) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn motor_range_falls_back_to_the_throttle_stick_not_the_servo_limits() {
        let quad = |extra: &[(&str, f32)]| {
            let mut params = vec![
                ("FRAME_TYPE", 1.0),
                ("SERVO1_FUNCTION", 33.0),
                ("SERVO1_MIN", 1100.0),
                ("SERVO1_MAX", 1900.0),
                ("RC3_MIN", 1050.0),
                ("RC3_MAX", 1950.0),
            ];
            params.extend_from_slice(extra);
            let d = detect(&info(MavType::MAV_TYPE_QUADROTOR, &params)).unwrap();
            let m = &d.profile.actuators[0];
            (m.pwm_min, m.pwm_max)
        };
        // MOT_PWM_MIN/MAX both set: they rule.
        assert_eq!(
            quad(&[("MOT_PWM_MIN", 1000.0), ("MOT_PWM_MAX", 2000.0)]),
            (1000.0, 2000.0)
        );
        // Left at 0 (ArduCopter's default): the throttle channel's calibrated range.
        assert_eq!(
            quad(&[("MOT_PWM_MIN", 0.0), ("MOT_PWM_MAX", 0.0)]),
            (1050.0, 1950.0)
        );
        // Throttle mapped to RC 1.
        assert_eq!(
            quad(&[
                ("MOT_PWM_MIN", 0.0),
                ("MOT_PWM_MAX", 0.0),
                ("RCMAP_THROTTLE", 1.0),
                ("RC1_MIN", 990.0),
                ("RC1_MAX", 2010.0)
            ]),
            (990.0, 2010.0)
        );
        // No MOT_PWM_* in the stream: the profile's range (today's defaults), not RC3's.
        assert_eq!(quad(&[]), (1000.0, 2000.0));
    }

    #[test]
    fn an_h3_generic_head_at_120_degrees_is_h3_120() {
        let heli = |extra: &[(&str, f32)]| {
            let mut params = vec![("H_SW_TYPE", 0.0)];
            params.extend_from_slice(extra);
            detect(&info(MavType::MAV_TYPE_HELICOPTER, &params)).unwrap()
        };
        let at_120 = [
            ("H_SW_H3_SV1_POS", -60.0),
            ("H_SW_H3_SV2_POS", 60.0),
            ("H_SW_H3_SV3_POS", 180.0),
            ("H_SW_H3_PHANG", 0.0),
        ];
        let d = heli(&at_120);
        assert!(
            !d.warnings.iter().any(|w| w.contains("H_SW_TYPE")),
            "{:?}",
            d.warnings
        );
        // Servos elsewhere: a head the built-in profile does not describe.
        let d = heli(&[
            ("H_SW_H3_SV1_POS", -45.0),
            ("H_SW_H3_SV2_POS", 45.0),
            ("H_SW_H3_SV3_POS", 180.0),
        ]);
        assert!(
            d.warnings
                .iter()
                .any(|w| w.contains("H_SW_TYPE 0 is not H3-120")),
            "{:?}",
            d.warnings
        );
    }

    #[test]
    fn swash_scaling_follows_the_firmware_and_a_given_profile_is_checked() {
        // Swash servo 1's range detected with these parameters besides its own.
        let swash1_range = |extra: &[(&str, f32)]| {
            let mut params = vec![
                ("H_SWASH_TYPE", 0.0),
                ("SERVO1_FUNCTION", 33.0),
                ("SERVO1_MIN", 1100.0),
                ("SERVO1_TRIM", 1500.0),
                ("SERVO1_MAX", 1900.0),
            ];
            params.extend_from_slice(extra);
            let d = detect(&info(MavType::MAV_TYPE_HELICOPTER, &params)).unwrap();
            (
                d.profile.actuators[0].pwm_min,
                d.profile.actuators[0].pwm_max,
            )
        };
        // Before the swash library (H_SWASH_TYPE only): per side by SERVOn_MIN/TRIM/MAX.
        assert_eq!(swash1_range(&[]), (1100.0, 1900.0));
        // H_SWASH_TYPE with the swash library's H_SW_H3_* (3.6): trim ± 500 already.
        assert_eq!(
            swash1_range(&[("H_SW_H3_SV1_POS", -60.0)]),
            (1000.0, 2000.0)
        );
        // A profile written with the clip limits, given to a 4.x heli: said once per servo.
        let mut p = Profile::resolve("heli-h3-120").unwrap();
        assert!(
            given_profile_warnings(
                &p,
                &info(MavType::MAV_TYPE_HELICOPTER, &[("H_SW_TYPE", 3.0)])
            )
            .is_empty()
        );
        p.actuators[1].pwm_min = 1100.0;
        p.actuators[1].pwm_max = 1900.0;
        let w = given_profile_warnings(
            &p,
            &info(MavType::MAV_TYPE_HELICOPTER, &[("H_SW_TYPE", 3.0)]),
        );
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("swash2") && w[0].contains("1100..1900"),
            "{}",
            w[0]
        );
    }
}
