//! The end-of-run summary of a replay or monitor session: per vehicle and actuator the final
//! estimates with bounds, the decisions, and every counter of what was dropped.

use crate::diagnose::vehicle::{FaultClass, Health};
use crate::estimate::vehicle::FILTER_NAMES;
use crate::monitor::Monitor;
use crate::protocol::FrameCounters;
use std::fmt::Write;

/// Why most rate instants found no outputs: the outputs come less often, or they are stamped
/// further from the rates than the pairing tolerance.
fn unmatched_note(c: &crate::telemetry::assembler::TelemetryCounters, max_skew_s: f64) -> String {
    let facts = format!(
        "most rate instants had no outputs within {:.0} ms ({} of {} attitude messages; {} output messages)",
        max_skew_s * 1e3,
        c.unmatched,
        c.rate_messages,
        c.output_messages
    );
    if c.output_messages * 2 < c.rate_messages {
        format!(
            "{facts}: the outputs come less often than the attitude; ask the autopilot for both at the same rate (ArduPilot: SRn_RC_CHAN and SRn_EXTRA1; or `monitor --request-rates`)"
        )
    } else {
        format!("{facts}: the outputs are stamped further than that from the attitude")
    }
}

pub fn render(
    monitor: &Monitor,
    frames: &FrameCounters,
    decisions: &[crate::diagnose::vehicle::Decision],
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "link: {frames}");
    if monitor.assembler.vehicles.is_empty() {
        let _ = writeln!(
            s,
            "no vehicle seen (no autopilot HEARTBEAT, ATTITUDE or SERVO_OUTPUT_RAW)"
        );
    }
    for (sysid, v) in &monitor.assembler.vehicles {
        let c = &v.counters;
        let _ = writeln!(
            s,
            "vehicle sysid {sysid}: type {}; telemetry: {} samples, {} unmatched rate instants, {} reordered, {} duplicates, {} reboots ({} messages of the new boots' first {} s dropped while confirming them, {} samples dropped at them), {} stamped over a second ahead (clock jumps no second message confirmed), {} non-finite; {} frames missing from the autopilot's sequence numbers (lost on the link, or dropped as corrupt or of an unknown message id)",
            v.info
                .mav_type
                .map_or("unknown".to_string(), |t| format!("{t:?}")
                    .trim_start_matches("MAV_TYPE_")
                    .to_lowercase()),
            c.samples,
            c.unmatched,
            c.out_of_order,
            c.duplicates,
            c.reboots,
            c.confirming_reboot,
            crate::telemetry::assembler::REBOOT_HOLD_S,
            c.dropped_at_reboot,
            c.ahead_of_clock,
            c.non_finite,
            c.lost_frames
        );
        if c.params_dropped > 0 {
            let _ = writeln!(
                s,
                "  parameters: {} PARAM_VALUE of new names dropped past the {} kept",
                c.params_dropped,
                crate::telemetry::assembler::MAX_PARAMS
            );
        }
        if c.clock_jumps_refused > 0 {
            let _ = writeln!(
                s,
                "  clock: {} jumps of the vehicle clock refused: a new boot whose frames did not arrive over the time they claim, or a jump ahead the next messages went back on (forged or corrupt stamps)",
                c.clock_jumps_refused
            );
        }
        if c.interpolated + c.unpaired_outputs > 0 {
            let _ = writeln!(
                s,
                "  pairing: {} of the samples at their outputs' instant with the rates interpolated between the two around it (rates and outputs not co-timed: {} rate, {} output messages); {} output messages without two consecutive rate instants around them",
                c.interpolated, c.rate_messages, c.output_messages, c.unpaired_outputs
            );
        }
        let Some(p) = monitor.pipelines.get(sysid) else {
            // Say which half never came.
            let missing = match (c.rate_messages, c.output_messages) {
                (0, 0) => {
                    ": no usable ATTITUDE or outputs (SERVO_OUTPUT_RAW, ACTUATOR_OUTPUT_STATUS) arrived"
                }
                (0, _) => ": no usable ATTITUDE arrived",
                (_, 0) => ": no usable outputs (SERVO_OUTPUT_RAW, ACTUATOR_OUTPUT_STATUS) arrived",
                _ => "",
            };
            let _ = writeln!(
                s,
                "  no complete samples (rates and outputs of the same instant){missing}"
            );
            continue;
        };
        let pc = &p.counters;
        let _ = writeln!(
            s,
            "  pipeline: {}; {} filter steps, {} gaps while estimating ({} lost periods coasted over, {} re-measured rates after longer ones), {} while calibrating ({} lost samples filled in), {} filter resets after a failed step, {} samples without a_z, {} without an actuator's PWM",
            p.stage_name(),
            pc.steps,
            pc.gaps,
            pc.coasted,
            pc.reseats,
            pc.calibration_gaps,
            pc.calibration_filled,
            pc.filter_errors,
            pc.missing_az,
            pc.missing_output
        );
        if let Some(why) = p.why_not_estimating(v.info.mav_type.is_some()) {
            let _ = writeln!(s, "  no estimates: {why}");
        }
        if c.unmatched > c.samples {
            let _ = writeln!(s, "  {}", unmatched_note(c, v.max_skew()));
        }
        if let Some(d) = &p.detection {
            let _ = writeln!(s, "  profile: {}", d.source);
        }
        let (Some(profile), Some((t, est))) = (p.profile(), &p.last) else {
            continue;
        };
        // After a reboot the filters start over: until they run again, the estimates shown
        // and the faults then in force are the boot before's (on its clock).
        let old_boot = p.before_reboot.filter(|b| !b.estimated_since);
        let _ = writeln!(
            s,
            "  final estimates at t={t:.2} s{}:",
            if old_boot.is_some() {
                " (before the vehicle rebooted; not estimated since)"
            } else {
                ""
            }
        );
        let _ = writeln!(
            s,
            "    (mit-ukf: probable bounds, 3σ; set: guaranteed bounds, while the noise stays within what the calibration stated, and of the output at the recent command, which the data bound before they split it into gamma and delta; mit-esmf: the detector's outer set, cut to the a priori box)"
        );
        let _ = writeln!(
            s,
            "    {:<10} {:>3}  {:<8} {:>24} {:>27}  {:>17}  {:>9}  state",
            "actuator",
            "ch",
            "filter",
            "gamma [bounds]",
            "delta [bounds]",
            "q_gamma q_delta",
            "faults",
        );
        for (j, a) in profile.actuators.iter().enumerate() {
            let (n, state) = actuator_state(p, *sysid, j, &a.name, decisions);
            for (f, name) in FILTER_NAMES.iter().enumerate() {
                let e = est[f][j];
                // A set filter's bound still at its a priori box says nothing: said instead.
                let num = |v: f64, w: usize, signed: bool| {
                    if signed {
                        format!("{v:>+w$.3}")
                    } else {
                        format!("{v:>w$.3}")
                    }
                };
                let cell = |unexcited: bool, [v, lo, hi]: [f64; 3], w: usize, signed: bool| {
                    if unexcited {
                        format!(
                            "{} {:<n$}",
                            num(v, w, signed),
                            "[not excited]",
                            n = 2 * w + 4
                        )
                    } else {
                        let [v, lo, hi] = [v, lo, hi].map(|x| num(x, w, signed));
                        format!("{v} [{lo}, {hi}]")
                    }
                };
                let gamma = cell(e.unexcited[0], [e.gamma, e.gamma_lo, e.gamma_hi], 6, false);
                let delta = cell(e.unexcited[1], [e.delta, e.delta_lo, e.delta_hi], 7, true);
                let _ = writeln!(
                    s,
                    "    {:<10} {:>3}  {:<8} {gamma} {delta}  {:>8.1e} {:>8.1e}  {:>9}  {}",
                    if f == 0 { a.name.as_str() } else { "" },
                    if f == 0 {
                        a.channel.to_string()
                    } else {
                        String::new()
                    },
                    name,
                    e.q_gamma,
                    e.q_delta,
                    if f == 0 { n.to_string() } else { String::new() },
                    if f == 0 { state.as_str() } else { "" }
                );
                if f == 2 {
                    let bounds = e
                        .output_bounds
                        .map_or("[not excited]".to_string(), |[lo, hi]| {
                            format!("[{lo:+.3}, {hi:+.3}]")
                        });
                    let _ = writeln!(
                        s,
                        "    {:<10} {:>3}  {:<8} output at its recent command {:.3}, less the healthy: {bounds}",
                        "", "", "", e.command_ref
                    );
                }
            }
        }
    }
    s
}

/// Actuator `j`'s fault episodes (not every decision: a healthy motor with six
/// `excitation_low` read "6 decisions, healthy") and its state at the end, in words.
pub(crate) fn actuator_state(
    p: &crate::pipeline::VehiclePipeline,
    sysid: u8,
    j: usize,
    name: &str,
    decisions: &[crate::diagnose::vehicle::Decision],
) -> (usize, String) {
    let old_boot = p.before_reboot.filter(|b| !b.estimated_since);
    let n = decisions
        .iter()
        .filter(|d| {
            d.sysid == sysid
                && d.actuator.as_deref() == Some(name)
                && d.event == crate::diagnose::vehicle::Event::Fault
        })
        .count();
    // With no fault in force: "healthy", or when its fault was cleared, since when
    // (the estimates may still be on their way back: quad + motor 1 read gamma 0.87
    // [0.85, 0.89] a while after its clearing, beside a bare "healthy").
    // With the kind and onset of the fault that cleared: an operator reading the summary
    // of a log learnt only that something had cleared.
    use crate::diagnose::vehicle::Event;
    let mut episode: Option<(f64, Option<FaultClass>)> = None;
    let mut cleared = None;
    for d in decisions
        .iter()
        .filter(|d| d.sysid == sysid && d.actuator.as_deref() == Some(name))
    {
        match d.event {
            Event::Fault => {
                episode = Some((d.t, d.class));
                cleared = None;
            }
            Event::Changed => {
                if let Some(e) = episode.as_mut() {
                    e.1 = d.class;
                }
                cleared = None;
            }
            Event::Cleared => cleared = Some(d.t),
            _ => {}
        }
    }
    // "cleared at t=57.22 s (loss_of_effectiveness from t=45.22 s; <also>)".
    let cleared_with = |also: Option<String>| {
        cleared.map(|t| {
            let mut notes: Vec<String> = episode
                .map(|(onset, class)| {
                    format!(
                        "{} from t={onset:.2} s",
                        class.map_or("fault", |c| c.as_str())
                    )
                })
                .into_iter()
                .collect();
            notes.extend(also);
            if notes.is_empty() {
                format!("cleared at t={t:.2} s")
            } else {
                format!("cleared at t={t:.2} s ({})", notes.join("; "))
            }
        })
    };
    // A fault in force at a reboot is not cleared by it.
    let at_reboot = p.before_reboot.and_then(|b| b.active[j]);
    let state = match (p.active[j], at_reboot, old_boot) {
        (Some(c), _, _) => c.as_str().to_string(),
        (None, Some(c), Some(_)) => {
            format!("{} at the reboot, not judged since", c.as_str())
        }
        // (A clearing after a fault at the reboot is the new boot's own.)
        (None, Some(c), None) => cleared_with(Some(format!("{} before the reboot", c.as_str())))
            .unwrap_or_else(|| format!("healthy since the reboot ({} before)", c.as_str())),
        (None, None, _) if p.health[j] == Health::Suspect => {
            "suspect (evidence short of a fault: see its decision)".into()
        }
        (None, None, _) if p.health[j] == Health::CannotJudge => {
            "cannot judge (the model does not explain its axes: see its decision)".into()
        }
        (None, None, _) => cleared_with(None).unwrap_or_else(|| "healthy".into()),
    };
    (n, state)
}
