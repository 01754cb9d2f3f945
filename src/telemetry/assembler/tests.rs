//! The assembler's tests: pairing, a_z, clocks, reboots, sequence numbers.

use super::*;
use crate::protocol::dialects::ahcmon::{ATTITUDE_DATA, RAW_IMU_DATA, SERVO_OUTPUT_RAW_DATA};

fn attitude(ms: u32) -> MavMessage {
    MavMessage::ATTITUDE(ATTITUDE_DATA {
        time_boot_ms: ms,
        rollspeed: 0.1,
        ..Default::default()
    })
}

fn outputs(ms: u32, pwm: u16) -> MavMessage {
    MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
        // The autopilot's 32-bit micros() wraps every 71.6 min.
        time_usec: ms.wrapping_mul(1000),
        servo1_raw: pwm,
        ..Default::default()
    })
}

fn imu(ms: u32) -> MavMessage {
    MavMessage::RAW_IMU(RAW_IMU_DATA {
        time_usec: u64::from(ms) * 1000,
        zacc: -1000,
        ..Default::default()
    })
}

/// Feed `msgs` from the autopilot component; the samples that come out.
fn feed(a: &mut VehicleAssembler, msgs: &[MavMessage]) -> Vec<TelemetrySample> {
    let mut out = Vec::new();
    for m in msgs {
        a.on_message(1, m, &mut out);
    }
    out
}

#[test]
fn a_z_stays_with_one_imu() {
    use crate::protocol::dialects::ahcmon::SCALED_IMU2_DATA;
    let imu2 = |ms: u32| {
        MavMessage::SCALED_IMU2(SCALED_IMU2_DATA {
            time_boot_ms: ms,
            zacc: -1100,
            ..Default::default()
        })
    };
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    // ArduPilot's RAW_SENSORS stream: RAW_IMU (IMU 1, -1000 mG) and SCALED_IMU2 (IMU 2,
    // -1100 mG) of the same instant; IMU 2's ms stamp is not older, so it used to win.
    let got = feed(
        &mut a,
        &[imu(1000), imu2(1000), attitude(1000), outputs(1000, 1500)],
    );
    assert_eq!(got.len(), 1);
    assert!((got[0].az.unwrap() + G0).abs() < 1e-9, "{:?}", got[0].az);
    // IMU 1 silent for over a second: IMU 2 takes over.
    let got = feed(&mut a, &[imu2(2100), attitude(2100), outputs(2100, 1500)]);
    assert!(
        (got[0].az.unwrap() + 1.1 * G0).abs() < 1e-9,
        "{:?}",
        got[0].az
    );
    // IMU 1 back (e.g. its rate requested): the preferred source takes over at once.
    let got = feed(
        &mut a,
        &[imu(2120), imu2(2120), attitude(2120), outputs(2120, 1500)],
    );
    assert!((got[0].az.unwrap() + G0).abs() < 1e-9, "{:?}", got[0].az);
    // RAW_IMU at 2 Hz against SCALED_IMU2 at 50 Hz: the slow one does not take a_z.
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    feed(&mut a, &[imu2(1000), imu2(1020), imu(1030), imu2(1040)]);
    let got = feed(
        &mut a,
        &[imu(1530), imu2(1540), attitude(1540), outputs(1540, 1500)],
    );
    assert!(
        (got[0].az.unwrap() + 1.1 * G0).abs() < 1e-9,
        "{:?}",
        got[0].az
    );
    // SCALED_IMU2 first and slow, RAW_IMU later at 50 Hz: RAW_IMU takes over from its
    // second message.
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    feed(&mut a, &[imu2(1000), imu2(1500), imu(1500)]);
    let got = feed(&mut a, &[imu(1520), attitude(1520), outputs(1520, 1500)]);
    assert!((got[0].az.unwrap() + G0).abs() < 1e-9, "{:?}", got[0].az);
}

#[test]
fn a_32_bit_raw_imu_stamp_is_unwrapped() {
    // Older ArduPilot: RAW_IMU.time_usec is micros() (u32), wrapped after 4294.97 s, like
    // SERVO_OUTPUT_RAW's; ATTITUDE's ms stamp is not.
    let ms = 4_300_000u32;
    let wrapped = (u64::from(ms) * 1000 % (1u64 << 32)) as u32;
    let servo = MavMessage::SERVO_OUTPUT_RAW(SERVO_OUTPUT_RAW_DATA {
        time_usec: wrapped,
        servo1_raw: 1500,
        ..Default::default()
    });
    let raw = MavMessage::RAW_IMU(RAW_IMU_DATA {
        time_usec: u64::from(wrapped),
        zacc: -1000,
        ..Default::default()
    });
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let got = feed(
        &mut a,
        &[attitude(ms - 20), raw.clone(), attitude(ms), servo],
    );
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].t, 4300.0);
    assert!(
        got[0].az.is_some_and(|z| (z + G0).abs() < 1e-9),
        "{:?}",
        got[0].az
    );
}

#[test]
fn px4_actuator_output_status_counts_its_active_outputs() {
    use crate::protocol::dialects::ahcmon::ACTUATOR_OUTPUT_STATUS_DATA;
    // PX4 sets `active` to the number of outputs (4 on a quad), not a bitmask (4 = 0b100
    // would leave only output 3).
    let mut actuator = [0.0f32; 32];
    actuator[..5].copy_from_slice(&[1510.4, 1520.0, 1530.0, 1540.0, 1550.0]);
    let px4 = |active: u32, actuator: [f32; 32]| {
        MavMessage::ACTUATOR_OUTPUT_STATUS(ACTUATOR_OUTPUT_STATUS_DATA {
            time_usec: 1_000_000,
            active,
            actuator,
        })
    };
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let got = feed(&mut a, &[attitude(1000), px4(4, actuator)]);
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].pwm[..6], [1510, 1520, 1530, 1540, 0, 0]);
    assert_eq!(a.counters.output_messages, 1);
    // A channel inside the count that reads 0 is unused, and NaN is never a PWM.
    actuator[1] = 0.0;
    actuator[2] = f32::NAN;
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let got = feed(&mut a, &[attitude(1000), px4(8, actuator)]);
    assert_eq!(got[0].pwm[..6], [1510, 0, 0, 1540, 1550, 0]);
}

#[test]
fn duplicates_and_reordered_messages_are_counted_not_used() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let got = feed(&mut a, &[attitude(1000), outputs(1000, 1500)]);
    assert_eq!(got.len(), 1);
    // The same instant again, and an older one: dropped and counted.
    let got = feed(
        &mut a,
        &[attitude(1000), attitude(980), outputs(1000, 1500)],
    );
    assert!(got.is_empty());
    assert_eq!((a.counters.duplicates, a.counters.out_of_order), (1, 1));
    // Rates waiting for their outputs are not replaced by older or repeated rates.
    let got = feed(&mut a, &[attitude(1040), attitude(1020), attitude(1040)]);
    assert!(got.is_empty());
    assert_eq!((a.counters.duplicates, a.counters.out_of_order), (2, 2));
    // Outputs older than those held do not replace them; the waiting rates then pair with
    // their own instant's outputs.
    let got = feed(&mut a, &[outputs(1040, 1600), outputs(1000, 1400)]);
    assert_eq!(got.len(), 1);
    assert_eq!((got[0].t, got[0].pwm[0]), (1.04, 1600));
    assert_eq!(a.counters.out_of_order, 3);
    assert_eq!(a.counters.unmatched, 0);
}

#[test]
fn at_100_hz_rates_never_pair_with_the_next_instants_outputs() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    // 100 Hz, outputs stamped with their own instant, in step.
    for k in 0..20 {
        let ms = 1000 + 10 * k;
        assert_eq!(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]).len(), 1);
    }
    // The outputs of one instant are lost; rates wait and the next instant's outputs
    // (10 ms later, inside the 15 ms default) must not be taken for them.
    let got = feed(
        &mut a,
        &[attitude(1200), attitude(1210), outputs(1210, 1600)],
    );
    assert_eq!(got.len(), 1);
    assert_eq!(got[0].t, 1.21);
    let got = feed(&mut a, &[attitude(1220), outputs(1230, 1700)]);
    assert!(got.is_empty(), "paired with a neighbour: {got:?}");
    assert_eq!(a.counters.unmatched, 1);
}

#[test]
fn one_stale_message_is_not_a_reboot() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    feed(&mut a, &[attitude(600_000), outputs(600_000, 1500)]);
    // A copy from a second link, 5 s late, then the stream goes on.
    let got = feed(
        &mut a,
        &[attitude(595_000), attitude(600_020), outputs(600_020, 1500)],
    );
    assert_eq!(got.len(), 1);
    assert!(!a.rebooted);
    assert_eq!((a.counters.reboots, a.counters.out_of_order), (0, 1));
}

#[test]
fn a_reboot_drops_the_sample_waiting_for_its_az_and_starts_the_new_clock() {
    // Late in a u32-µs wrap period of SERVO_OUTPUT_RAW (3000 s of uptime), so that the
    // outputs' stamps after the reboot must unwrap behind the clock too.
    let up = 3_000_000;
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let got = feed(&mut a, &[attitude(up), outputs(up, 1500), imu(up)]);
    assert_eq!(got.len(), 1);
    // The next instant's IMU message is lost; then the vehicle reboots.
    let got = feed(&mut a, &[attitude(up + 20), outputs(up + 20, 1500)]);
    assert!(got.is_empty(), "waits for its a_z");
    let mut after = vec![];
    for k in 0..60 {
        let ms = 2_000 + 20 * k;
        after.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500), imu(ms)]));
    }
    assert!(a.rebooted);
    assert_eq!(a.counters.reboots, 1);
    assert_eq!(a.counters.dropped_at_reboot, 1);
    // The new boot's first half second (25 instants of ATTITUDE and outputs, the clock's
    // messages) confirmed it: not reordered.
    assert_eq!(
        (a.counters.out_of_order, a.counters.confirming_reboot),
        (0, 50)
    );
    // Nothing of the old boot comes out after it; the new clock's instants do, once half a
    // second of it has confirmed the reboot.
    assert!(after.iter().all(|s| s.t < 10.0), "{after:?}");
    assert!(after.len() >= 30, "{}", after.len());
}

#[test]
fn a_reboot_after_a_u32_wrap_period_of_uptime_is_seen_and_the_new_flight_kept() {
    // 5000 s of uptime: SERVO_OUTPUT_RAW's µs stamps have wrapped once, and the new boot's
    // (2 s) unwrapped next to the old clock read 4297 s. The reboot was never confirmed
    // and every later message was dropped as reordered.
    let up = 5_000_000;
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let got = feed(&mut a, &[attitude(up), outputs(up, 1500)]);
    assert_eq!(
        got.len(),
        1,
        "the old boot's stamps unwrap next to its clock"
    );
    let mut after = vec![];
    for k in 0..100 {
        let ms = 2_000 + 20 * k;
        after.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]));
    }
    assert_eq!(a.counters.reboots, 1);
    assert!(after.iter().all(|s| s.t < 10.0), "{after:?}");
    // Half a second of the new clock confirms the reboot; the rest of it comes out.
    assert!(after.len() >= 70, "{}", after.len());
    // The same with the outputs first at each instant.
    let mut b = VehicleAssembler::new(1, AssemblerConfig::default());
    feed(&mut b, &[outputs(up, 1500), attitude(up)]);
    let mut after = vec![];
    for k in 0..100 {
        let ms = 2_000 + 20 * k;
        after.extend(feed(&mut b, &[outputs(ms, 1500), attitude(ms)]));
    }
    assert_eq!(b.counters.reboots, 1);
    assert!(after.len() >= 70, "{}", after.len());
}

#[test]
fn one_message_stamped_far_ahead_does_not_move_the_clock() {
    // A CRC-valid ATTITUDE with a wild time_boot_ms (2^31 ms) in a steady stream: it used
    // to move the clock 24 days ahead, and the rest of the flight read as reordered.
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let mut got = vec![];
    for k in 0..200 {
        let ms = 60_000 + 20 * k;
        if k == 50 {
            got.extend(feed(&mut a, &[attitude(1 << 31)]));
        }
        got.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]));
    }
    assert_eq!(got.len(), 200);
    assert!(got.iter().all(|s| s.t < 70.0));
    assert_eq!(a.counters.ahead_of_clock, 1);
    assert_eq!((a.counters.out_of_order, a.counters.reboots), (0, 0));
}

#[test]
fn a_log_that_starts_with_wrapped_output_stamps_takes_the_attitude_clock() {
    // 21 h of uptime (as in rust-mavlink-log.tlog): the first message, SERVO_OUTPUT_RAW,
    // sets the clock from its wrapped µs stamp, 17 wrap periods behind the ATTITUDE's.
    let up = 76_674_000;
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let mut got = feed(&mut a, &[outputs(up - 250, 1500)]);
    for k in 0..50 {
        let ms = up + 250 * k;
        got.extend(feed(&mut a, &[attitude(ms), outputs(ms, 1500)]));
    }
    assert_eq!(got.len(), 50);
    assert!(got.iter().all(|s| s.t > 76_000.0), "{:?}", got[0]);
    assert_eq!((a.counters.ahead_of_clock, a.counters.out_of_order), (0, 0));
}

#[test]
fn after_a_link_outage_the_stream_goes_on_from_its_second_message() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let mut got = vec![];
    for k in (0..50).chain(150..200) {
        // 2 s with nothing between k = 49 and k = 150; an IMU message between each
        // instant's rates and outputs (it is on no clock and decides nothing).
        let ms = 60_000 + 20 * k;
        got.extend(feed(&mut a, &[attitude(ms), imu(ms), outputs(ms, 1500)]));
    }
    // The first message after the outage waits for a second on its clock, then both count.
    assert_eq!(a.counters.ahead_of_clock, 0);
    assert_eq!(got.len(), 100);
    assert_eq!(a.counters.out_of_order, 0);
}

#[test]
fn a_lagging_links_bursts_of_old_instants_are_no_reboot() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    for k in 0..100 {
        let ms = 600_000 + 20 * k;
        feed(&mut a, &[attitude(ms), outputs(ms, 1500)]);
        // The same flight through a second link, 3 s late, in bursts between live ones.
        if k % 10 == 0 {
            feed(&mut a, &[attitude(ms - 3000), outputs(ms - 3000, 1500)]);
        }
    }
    assert!(!a.rebooted);
    assert_eq!(a.counters.reboots, 0);
    assert_eq!(a.counters.samples, 100);
    assert_eq!(a.counters.out_of_order, 20);
}

#[test]
fn sequence_numbers_count_lost_frames_across_the_wrap_and_take_late_ones_off() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let mut feed = |seqs: &[u8]| {
        for &s in seqs {
            a.on_sequence(1, s);
        }
        a.counters.lost_frames
    };
    // 253, 254 lost; the wrap from 255 to 0 loses nothing.
    assert_eq!(feed(&[250, 251, 252, 255, 0, 1]), 2);
    // A duplicate is no loss; a late frame (5 after 7) is taken off, its duplicate not.
    assert_eq!(feed(&[1, 3, 4, 7, 5, 5]), 2 + 1 + 2 - 1);
    // An outage of 150 frames (a second or two of radio dropout), then a stream with one
    // more lost.
    assert_eq!(feed(&[158, 159, 161]), 4 + 150 + 1);
    // A jump of 64 or more clears the window: what came before it is not "late".
    assert_eq!(feed(&[240, 100]), 155 + 78 + 115);
    // Another component's counter is not the autopilot's.
    a.on_sequence(2, 100);
    assert_eq!(a.counters.lost_frames, 348);
}

/// A frame from before the first one is not a late arrival of something counted lost.
#[test]
fn a_frame_older_than_the_first_takes_no_loss_off() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    for s in [10, 12, 5] {
        a.on_sequence(1, s);
    }
    assert_eq!(a.counters.lost_frames, 1);
}

/// A reboot restarts the sequence: the jump to the new boot's numbers is no loss.
#[test]
fn a_reboot_takes_back_the_jump_of_its_sequence() {
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let mut out = vec![];
    let send = |a: &mut VehicleAssembler, out: &mut Vec<TelemetrySample>, ms: u32, seq: u8| {
        a.on_message(1, &attitude(ms), out);
        a.on_sequence(1, seq);
    };
    for (k, ms) in (100_000..110_000).step_by(20).enumerate() {
        send(&mut a, &mut out, ms, k as u8);
    }
    assert_eq!(a.counters.lost_frames, 0);
    // The new boot's counter starts at 0 (and one of its frames, at 2 s, is lost).
    for (k, ms) in (1_000..3_000).step_by(20).enumerate() {
        send(&mut a, &mut out, ms, (k + usize::from(ms >= 2_000)) as u8);
    }
    assert_eq!(a.counters.reboots, 1);
    assert_eq!(a.counters.lost_frames, 1);
}

/// The same when the new boot speaks first with unstamped frames (a HEARTBEAT, as
/// ArduPilot and our simulator do): their jump comes before the reboot is suspected. A
/// loss of the old boot before its last stamped frame stays counted.
#[test]
fn a_reboot_takes_back_the_jump_of_the_new_boots_unstamped_frames() {
    use crate::protocol::dialects::ahcmon::HEARTBEAT_DATA;
    let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA::default());
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let mut out = vec![];
    let send = |a: &mut VehicleAssembler, out: &mut Vec<_>, msg: &MavMessage, seq: &mut u8| {
        a.on_message(1, msg, out);
        a.on_sequence(1, *seq);
        *seq = seq.wrapping_add(1);
    };
    // 5593 frames (the last numbered 5592 mod 256 = 216), two lost near the end.
    let mut seq = 0u8;
    for (k, ms) in (100_000..100_000 + 20 * 5593).step_by(20).enumerate() {
        if k == 5590 {
            seq = seq.wrapping_add(2);
        }
        send(&mut a, &mut out, &attitude(ms), &mut seq);
    }
    assert_eq!(a.counters.lost_frames, 2);
    let mut seq = 0u8;
    send(&mut a, &mut out, &heartbeat, &mut seq);
    send(&mut a, &mut out, &heartbeat, &mut seq);
    for ms in (1_000..3_000).step_by(20) {
        send(&mut a, &mut out, &attitude(ms), &mut seq);
    }
    assert_eq!(a.counters.reboots, 1);
    assert_eq!(a.counters.lost_frames, 2);
}

/// Another component claiming to be the autopilot first does not hide the autopilot's
/// (component 1) samples.
#[test]
fn the_autopilot_component_takes_over_from_an_earlier_claimant() {
    use crate::protocol::dialects::ahcmon::HEARTBEAT_DATA;
    let heartbeat = MavMessage::HEARTBEAT(HEARTBEAT_DATA {
        autopilot: MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
        mavtype: MavType::MAV_TYPE_QUADROTOR,
        ..Default::default()
    });
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    let mut out = vec![];
    a.on_message(2, &heartbeat, &mut out);
    assert_eq!(a.info.compid, Some(2));
    a.on_message(1, &heartbeat, &mut out);
    assert_eq!(a.info.compid, Some(1));
    // Component 2 cannot take it back.
    a.on_message(2, &heartbeat, &mut out);
    assert_eq!(a.info.compid, Some(1));
    for ms in (1000..1100).step_by(20) {
        a.on_message(1, &attitude(ms), &mut out);
        a.on_message(1, &outputs(ms, 1500), &mut out);
    }
    assert_eq!(out.len(), 5);
}

/// Feed `msgs` through the fleet assembler as frames that arrived at `arrival` (s).
fn feed_at(a: &mut Assembler, arrival: f64, msgs: &[MavMessage]) -> Vec<TelemetrySample> {
    let mut out = Vec::new();
    for m in msgs {
        a.on_frame_at(1, 1, m, Some(arrival), &mut out);
    }
    out
}

/// Two seconds of a 50 Hz flight at 600 s of uptime, with two ATTITUDEs stamped `forged` (ms)
/// arriving back to back after its 51st instant; the samples that came out.
fn flight_with_forged_pair(a: &mut Assembler, forged: [u32; 2]) -> usize {
    let mut samples = 0;
    for k in 0..100u32 {
        let ms = 600_000 + 20 * k;
        let at = f64::from(k) * 0.02;
        samples += feed_at(a, at, &[attitude(ms), outputs(ms, 1500)]).len();
        if k == 50 {
            feed_at(a, at + 0.0005, &[attitude(forged[0])]);
            feed_at(a, at + 0.0006, &[attitude(forged[1])]);
        }
    }
    samples
}

/// Two forged ATTITUDEs sent back to back (stamped 1.0 and 1.6 s) during a flight at 600 s
/// used to confirm a reboot (the filters reset, the calibration restarted and a real fault was
/// missed). Arriving within a millisecond they do not cover `REBOOT_ARRIVAL_S` of arrival
/// time: no reboot, the flight's samples go on. A real reboot, whose new clock arrives over
/// time, is still confirmed.
#[test]
fn two_forged_frames_do_not_make_a_reboot_but_a_real_one_does() {
    let mut a = Assembler::new(AssemblerConfig::default());
    let samples = flight_with_forged_pair(&mut a, [1000, 1600]);
    let v = &a.vehicles[&1];
    assert!(!v.rebooted);
    assert_eq!(v.counters.reboots, 0);
    assert_eq!(v.counters.clock_jumps_refused, 1);
    assert_eq!(samples, 100);
    // Without arrival times the same two frames are a reboot (the rule needs them).
    let mut b = VehicleAssembler::new(1, AssemblerConfig::default());
    feed(&mut b, &[attitude(600_000), outputs(600_000, 1500)]);
    feed(&mut b, &[attitude(1000), attitude(1600)]);
    assert_eq!(b.counters.reboots, 1);
    // A real reboot: the stream stops, the new boot's messages arrive at their own pace.
    for k in 0..50u32 {
        let ms = 2_000 + 20 * k;
        feed_at(
            &mut a,
            10.0 + f64::from(k) * 0.02,
            &[attitude(ms), outputs(ms, 1500)],
        );
    }
    let v = &a.vehicles[&1];
    assert!(v.rebooted);
    assert_eq!(v.counters.reboots, 1);
}

/// Two forged frames stamped far ahead move the clock (a second message on the same clock
/// confirms a jump: an outage does that); the real stream's next message, back on the clock
/// from before the jump, undoes it instead of starting a reboot that its messages, arriving
/// over time, would confirm. Nothing of the real stream is lost. A real outage stays taken.
#[test]
fn a_jump_ahead_the_next_messages_go_back_on_is_undone() {
    let mut a = Assembler::new(AssemblerConfig::default());
    let samples = flight_with_forged_pair(&mut a, [700_000, 700_020]);
    let v = &a.vehicles[&1];
    assert_eq!(samples, 100);
    assert_eq!((v.counters.reboots, v.counters.clock_jumps_refused), (0, 1));
    assert!(!v.rebooted);
    assert!(v.clock().unwrap() < 610.0);
    // A 100 s outage: the stream comes back 100 s later and stays.
    let got: usize = (0..10u32)
        .map(|k| {
            let ms = 702_000 + 20 * k;
            feed_at(
                &mut a,
                102.0 + f64::from(k) * 0.02,
                &[attitude(ms), outputs(ms, 1500)],
            )
            .len()
        })
        .sum();
    assert!(got >= 9, "{got}");
    let v = &a.vehicles[&1];
    assert_eq!((v.counters.reboots, v.counters.clock_jumps_refused), (0, 1));
}

/// 300,000 PARAM_VALUEs of made-up names keep at most `MAX_PARAMS` (the first, real ones
/// among them, still updated), the rest counted.
#[test]
fn parameters_are_capped_and_the_excess_counted() {
    use crate::protocol::dialects::ahcmon::PARAM_VALUE_DATA;
    let param = |name: &str, value: f32| {
        let mut id = [0u8; 16];
        id[..name.len()].copy_from_slice(name.as_bytes());
        MavMessage::PARAM_VALUE(PARAM_VALUE_DATA {
            param_id: id.into(),
            param_value: value,
            ..Default::default()
        })
    };
    let mut a = VehicleAssembler::new(1, AssemblerConfig::default());
    feed(&mut a, &[param("FRAME_CLASS", 1.0)]);
    for k in 0..300_000 {
        feed(&mut a, &[param(&format!("X{k}"), 1.0)]);
    }
    feed(&mut a, &[param("FRAME_CLASS", 2.0)]);
    assert_eq!(a.info.params.len(), MAX_PARAMS);
    assert_eq!(a.counters.params_dropped, 300_001 - MAX_PARAMS as u64);
    assert_eq!(a.info.param("FRAME_CLASS"), Some(2.0));
}
