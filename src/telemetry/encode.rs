//! The simulated vehicle speaking MAVLink like an ArduPilot autopilot: HEARTBEAT (its MAV_TYPE,
//! armed), ATTITUDE, SERVO_OUTPUT_RAW, RAW_IMU at the sample rate, SYS_STATUS and
//! GLOBAL_POSITION_INT at 1 Hz, and the frame parameters a GCS would read (FRAME_CLASS,
//! FRAME_TYPE, H_SW_TYPE, SERVOn_FUNCTION) every 10 s. Or like PX4 ([`Flavour::Px4`]):
//! ACTUATOR_OUTPUT_STATUS (`active` = the number of outputs, values in µs) and HIGHRES_IMU
//! (m/s²) instead, and no ArduPilot parameters. Pure: messages out, no I/O.

use super::{Profile, Role, VehicleKind};
use crate::protocol::dialects::ahcmon::{
    ACTUATOR_OUTPUT_STATUS_DATA, ATTITUDE_DATA, GLOBAL_POSITION_INT_DATA, HEARTBEAT_DATA,
    HIGHRES_IMU_DATA, MavAutopilot, MavMessage, MavModeFlag, MavParamType, MavState,
    MavSysStatusSensor, MavType, PARAM_VALUE_DATA, RAW_IMU_DATA, SERVO_OUTPUT_RAW_DATA,
    SYS_STATUS_DATA,
};

const G0: f64 = 9.80665;
/// The simulated autopilot "booted" this long before the scenario starts (s).
pub const BOOT_OFFSET_S: f64 = 10.0;

/// Which autopilot the simulated vehicle sounds like.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Flavour {
    #[default]
    ArduPilot,
    Px4,
}

pub struct SimTelemetry {
    flavour: Flavour,
    profile: Profile,
    mav_type: MavType,
    params: Vec<(String, f32)>,
    next_heartbeat: f64,
    next_params: f64,
}

fn mav_type(profile: &Profile) -> MavType {
    match profile.vehicle {
        VehicleKind::Helicopter => MavType::MAV_TYPE_HELICOPTER,
        VehicleKind::Plane => MavType::MAV_TYPE_FIXED_WING,
        VehicleKind::Multirotor => match profile.actuators.len() {
            6 => MavType::MAV_TYPE_HEXAROTOR,
            8 => MavType::MAV_TYPE_OCTOROTOR,
            _ => MavType::MAV_TYPE_QUADROTOR,
        },
    }
}

impl SimTelemetry {
    pub fn new(profile: &Profile) -> Self {
        Self::with_flavour(profile, Flavour::ArduPilot)
    }

    pub fn with_flavour(profile: &Profile, flavour: Flavour) -> Self {
        let mut params: Vec<(String, f32)> = vec![];
        match profile.vehicle {
            VehicleKind::Helicopter => {
                params.push(("FRAME_CLASS".into(), 6.0));
                params.push(("H_SW_TYPE".into(), 3.0));
            }
            VehicleKind::Multirotor => {
                let class = if profile.actuators.len() == 6 {
                    2.0
                } else {
                    1.0
                };
                params.push(("FRAME_CLASS".into(), class));
                let plus = profile.name.contains("plus");
                params.push(("FRAME_TYPE".into(), if plus { 0.0 } else { 1.0 }));
            }
            VehicleKind::Plane => {}
        }
        let mut motor = 0;
        for a in &profile.actuators {
            let function = match a.role {
                Role::Motor | Role::Swash => {
                    motor += 1;
                    32 + motor
                }
                Role::Tail => 36,
                Role::Aileron => 4,
                Role::Elevator => 19,
                Role::Rudder => 21,
                Role::Throttle => 70,
                Role::Custom => continue,
            };
            let n = a.channel;
            params.push((format!("SERVO{n}_FUNCTION"), function as f32));
            params.push((format!("SERVO{n}_MIN"), a.pwm_min as f32));
            params.push((format!("SERVO{n}_TRIM"), a.pwm_trim as f32));
            params.push((format!("SERVO{n}_MAX"), a.pwm_max as f32));
            params.push((
                format!("SERVO{n}_REVERSED"),
                f32::from(u8::from(a.reversed)),
            ));
        }
        if flavour == Flavour::Px4 {
            // PX4's parameters are its own; a GCS reading them would not find these.
            params.clear();
        }
        Self {
            flavour,
            profile: profile.clone(),
            mav_type: mav_type(profile),
            params,
            next_heartbeat: f64::NEG_INFINITY,
            next_params: f64::NEG_INFINITY,
        }
    }

    /// Messages for a simulator sample: its rates (and a_z, where the profile measures it;
    /// level flight's otherwise) with the outputs commanded next (`next_u`, acting until the
    /// next sample), as an autopilot reports them.
    pub fn sample_messages(
        &mut self,
        s: &crate::sim::vehicle::VehicleSample,
        next_u: &[f64],
        out: &mut Vec<MavMessage>,
    ) {
        let az = if self.profile.model.measure_az {
            s.y[3]
        } else {
            -9.80665
        };
        let rates = [s.y[0], s.y[1], s.y[2]];
        self.messages(s.t, rates, s.attitude, az, next_u, out);
    }

    /// Messages for one instant `t` (s since the scenario start): the rates and a_z measured
    /// then, the outputs commanded then (normalised, acting until the next instant).
    pub fn messages(
        &mut self,
        t: f64,
        rates: [f64; 3],
        attitude: [f64; 3],
        az: f64,
        u: &[f64],
        out: &mut Vec<MavMessage>,
    ) {
        let boot_s = t + BOOT_OFFSET_S;
        let time_boot_ms = (boot_s * 1e3).round() as u32;
        let time_usec = (boot_s * 1e6).round() as u64;
        if t >= self.next_heartbeat {
            self.next_heartbeat = t + 1.0;
            out.push(MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 4, // GUIDED
                mavtype: self.mav_type,
                autopilot: match self.flavour {
                    Flavour::ArduPilot => MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
                    Flavour::Px4 => MavAutopilot::MAV_AUTOPILOT_PX4,
                },
                base_mode: MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED
                    | MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                    | MavModeFlag::MAV_MODE_FLAG_STABILIZE_ENABLED
                    | MavModeFlag::MAV_MODE_FLAG_GUIDED_ENABLED,
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }));
            let sensors = MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_GYRO
                | MavSysStatusSensor::MAV_SYS_STATUS_SENSOR_3D_ACCEL;
            out.push(MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                onboard_control_sensors_present: sensors,
                onboard_control_sensors_enabled: sensors,
                onboard_control_sensors_health: sensors,
                load: 200,
                voltage_battery: 12600,
                current_battery: 1500,
                battery_remaining: 80,
                ..Default::default()
            }));
            out.push(MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
                time_boot_ms,
                lat: -353_632_610,
                lon: 1_491_652_300,
                alt: 599_000,
                relative_alt: 15_000,
                ..Default::default()
            }));
        }
        if t >= self.next_params {
            self.next_params = t + 10.0;
            let count = self.params.len() as u16;
            for (i, (name, value)) in self.params.iter().enumerate() {
                out.push(MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
                    param_value: *value,
                    param_count: count,
                    param_index: i as u16,
                    param_id: name.as_str().into(),
                    param_type: MavParamType::MAV_PARAM_TYPE_REAL32,
                }));
            }
        }
        out.push(MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms,
            roll: attitude[0] as f32,
            pitch: attitude[1] as f32,
            yaw: attitude[2] as f32,
            rollspeed: rates[0] as f32,
            pitchspeed: rates[1] as f32,
            yawspeed: rates[2] as f32,
        }));
        let mut pwm = [0u16; 16];
        for (j, a) in self.profile.actuators.iter().enumerate() {
            let slot = usize::from(a.channel).wrapping_sub(1);
            if let (Some(p), Some(v)) = (pwm.get_mut(slot), u.get(j)) {
                *p = self.profile.to_pwm(j, *v).round().clamp(0.0, 65535.0) as u16;
            }
        }
        if self.flavour == Flavour::Px4 {
            // PX4: `active` is the number of outputs (actuator_outputs.noutputs).
            let noutputs = self
                .profile
                .actuators
                .iter()
                .map(|a| usize::from(a.channel))
                .max()
                .unwrap_or(0)
                .min(16);
            let mut actuator = [0.0f32; 32];
            for (v, p) in actuator.iter_mut().zip(&pwm).take(noutputs) {
                *v = f32::from(*p);
            }
            out.push(MavMessage::ACTUATOR_OUTPUT_STATUS(
                ACTUATOR_OUTPUT_STATUS_DATA {
                    time_usec,
                    active: noutputs as u32,
                    actuator,
                },
            ));
            out.push(MavMessage::HIGHRES_IMU(HIGHRES_IMU_DATA {
                time_usec,
                zacc: az as f32,
                xgyro: rates[0] as f32,
                ygyro: rates[1] as f32,
                zgyro: rates[2] as f32,
                ..Default::default()
            }));
            return;
        }
        out.push(MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
            // u32 µs since boot: wraps every 71.6 min, as on the real thing.
            time_usec: time_usec as u32,
            servo1_raw: pwm[0],
            servo2_raw: pwm[1],
            servo3_raw: pwm[2],
            servo4_raw: pwm[3],
            servo5_raw: pwm[4],
            servo6_raw: pwm[5],
            servo7_raw: pwm[6],
            servo8_raw: pwm[7],
            port: 0,
            servo9_raw: pwm[8],
            servo10_raw: pwm[9],
            servo11_raw: pwm[10],
            servo12_raw: pwm[11],
            servo13_raw: pwm[12],
            servo14_raw: pwm[13],
            servo15_raw: pwm[14],
            servo16_raw: pwm[15],
        }));
        // ArduPilot's RAW_IMU: accelerations in mG, gyro in mrad/s.
        out.push(MavMessage::RAW_IMU(RAW_IMU_DATA {
            time_usec,
            zacc: (az / G0 * 1e3).round().clamp(-32768.0, 32767.0) as i16,
            xgyro: (rates[0] * 1e3).round().clamp(-32768.0, 32767.0) as i16,
            ygyro: (rates[1] * 1e3).round().clamp(-32768.0, 32767.0) as i16,
            zgyro: (rates[2] * 1e3).round().clamp(-32768.0, 32767.0) as i16,
            ..Default::default()
        }));
    }
}
