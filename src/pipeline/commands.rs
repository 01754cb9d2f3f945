//! A sample's outputs as the profile's normalised commands; a sample whose output channel
//! carries no pulse width is dropped, counted and said once.

use super::{PipelineCounters, VehiclePipeline};
use crate::model::MAX_ACTUATORS;
use crate::output::Sink;
use crate::telemetry::{Profile, TelemetrySample};

/// The PWM (µs) on actuator `a`'s output channel in sample `s`; 0 when the sample has none.
fn pwm_of(a: &crate::telemetry::profile::ActuatorSpec, s: &TelemetrySample) -> u16 {
    usize::from(a.channel)
        .checked_sub(1)
        .and_then(|c| s.pwm.get(c))
        .copied()
        .unwrap_or(0)
}

/// Longest output pulse taken as a command (µs): servo and ESC pulses stay within 500-2500;
/// 65535 marks an unused channel.
pub const MAX_PWM_US: f64 = 3000.0;

impl VehiclePipeline {
    /// The profile's actuators' commands, normalised; Err(index of the first actuator whose
    /// channel carried no PWM, or not a pulse width).
    pub(super) fn normalise(
        profile: &Profile,
        s: &TelemetrySample,
    ) -> Result<[f64; MAX_ACTUATORS], usize> {
        let mut u = [0.0; MAX_ACTUATORS];
        for (j, a) in profile.actuators.iter().enumerate() {
            let pwm = pwm_of(a, s);
            // 0: the channel is unused; 65535 (UINT16_MAX) marks it unused too, and no servo
            // or ESC pulse is longer than MAX_PWM_US.
            if pwm == 0 || f64::from(pwm) > MAX_PWM_US {
                return Err(j);
            }
            u[j] = profile.normalise(j, f64::from(pwm));
        }
        Ok(u)
    }

    /// `normalise`, counting a sample it cannot use and saying so once per run.
    pub(super) fn commands(
        counters: &mut PipelineCounters,
        warned: &mut bool,
        sysid: u8,
        profile: &Profile,
        s: &TelemetrySample,
        sink: &mut dyn Sink,
    ) -> Option<[f64; MAX_ACTUATORS]> {
        match Self::normalise(profile, s) {
            Ok(u) => Some(u),
            Err(j) => {
                counters.missing_output += 1;
                if !std::mem::replace(warned, true) {
                    let a = &profile.actuators[j];
                    let pwm = pwm_of(a, s);
                    let what = if pwm == 0 {
                        format!("no PWM on output channel {} ({})", a.channel, a.name)
                    } else {
                        format!(
                            "output channel {} ({}) reads {pwm} µs, not a pulse width (over {MAX_PWM_US} µs; 65535 marks an unused channel)",
                            a.channel, a.name
                        )
                    };
                    sink.message(
                        sysid,
                        &format!(
                            "warning: {what}: samples without a pulse width are dropped and counted"
                        ),
                    );
                }
                None
            }
        }
    }
}
