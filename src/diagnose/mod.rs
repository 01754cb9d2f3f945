//! From estimates to decisions (pure): per vehicle, one state machine per actuator
//! (`vehicle`, the rule table in `docs/diagnosis.md`), over the change test on the residual
//! (`change`) and the attribution of deviations to actuators (`isolate`).

pub mod change;
pub mod decision;
pub mod isolate;
pub mod vehicle;

/// A time to the microsecond: stamps in milliseconds times 1e-3, and sums of steps, carry float
/// noise (49.980000000000004) that the JSON would show.
pub fn whole_us(t: f64) -> f64 {
    (t * 1e6).round() / 1e6
}

/// Serialise a time (s) as [`whole_us`] does.
pub fn serialize_time<S: serde::Serializer>(t: &f64, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_f64(whole_us(*t))
}
