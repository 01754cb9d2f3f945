//! Rule G2: which actuators the calibrated model can judge (`docs/diagnosis.md`).
//!
//! The calibration says, per rate axis, whether the model explains that axis's motion (the
//! pipeline's checks: its R² against a constant's, and whether the commands explain a moving
//! axis at all). An actuator's evidence is its effect per step on each axis (`b_j`, the rows
//! the filters and the change test weigh it by). Where more than half of `|b_j|²` lies on
//! axes the model does not explain, most of what the data say of that actuator is what the
//! model misses: it is `cannot_judge`, said once with the reason, and no rule decides on it.
//! Actuators acting mostly on explained axes are judged as usual.

use super::*;

/// The largest share of an actuator's squared effect that may lie on unexplained axes for it
/// to be judged: over half, and most of its evidence is the model's error.
pub const MAX_UNEXPLAINED_SHARE: f64 = 0.5;

const AXES: [&str; 3] = ["roll", "pitch", "yaw"];

/// A rate axis (0 roll, 1 pitch, 2 yaw) the calibrated model does not explain, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct AxisFailure {
    pub axis: usize,
    pub why: String,
}

/// Each actuator's share of its squared effect on the rate axes that lies on `failing` ones
/// (0 for an actuator with no effect on the rates).
pub fn unexplained_share(effects: &[[f64; 4]], failing: &[AxisFailure]) -> Vec<f64> {
    effects
        .iter()
        .map(|b| {
            let total: f64 = b[..3].iter().map(|v| v * v).sum();
            let on_failing: f64 = failing.iter().map(|f| b[f.axis].powi(2)).sum();
            if total > 0.0 { on_failing / total } else { 0.0 }
        })
        .collect()
}

impl Diagnoser {
    /// G2 at the start of estimating: every actuator whose effect lies mostly on `failing`
    /// axes becomes `cannot_judge` (a decision each, appended to `out`). Returns how many
    /// actuators are still judged.
    pub fn cannot_judge(
        &mut self,
        t: f64,
        failing: &[AxisFailure],
        out: &mut Vec<Decision>,
    ) -> usize {
        let share = unexplained_share(&self.isolation.effects, failing);
        tracing::debug!(
            "sysid {}: G2 shares of each actuator's effect on unexplained axes: {share:.2?}",
            self.sysid
        );
        let reasons: Vec<String> = failing
            .iter()
            .map(|f| format!("{} ({})", AXES[f.axis], f.why))
            .collect();
        for (j, s) in share.iter().enumerate() {
            if *s <= MAX_UNEXPLAINED_SHARE {
                continue;
            }
            self.actuators[j].health = Health::CannotJudge;
            let mut d = self.decision(t, j, Event::CannotJudge, None, 0, Rule::G2);
            // Said before any estimate: no numbers to show.
            (
                d.gamma,
                d.delta,
                d.gamma_bounds,
                d.delta_bounds,
                d.deviation,
            ) = (None, None, None, None, None);
            d.detail = Some(format!(
                "{:.0} % of its effect is on axes the calibrated model does not explain: {}; no fault is decided on it (G2)",
                100.0 * s,
                reasons.join("; ")
            ));
            out.push(d);
        }
        share
            .iter()
            .filter(|s| **s <= MAX_UNEXPLAINED_SHARE)
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn failing(axes: &[usize]) -> Vec<AxisFailure> {
        axes.iter()
            .map(|&axis| AxisFailure {
                axis,
                why: "R²=-2.00".into(),
            })
            .collect()
    }

    #[test]
    fn the_share_on_failing_axes_is_of_the_rate_effect_only() {
        let effects = [[3.0, 4.0, 0.0, 9.0], [0.0, 0.0, 0.0, 1.0]];
        let s = unexplained_share(&effects, &failing(&[1]));
        assert!((s[0] - 16.0 / 25.0).abs() < 1e-12);
        assert_eq!(s[1], 0.0);
    }

    #[test]
    fn g2_a_plane_whose_yaw_is_unexplained_judges_all_but_its_rudder() {
        let p = Profile::resolve("plane").unwrap();
        let mut d = Diagnoser::new(DiagnosisParams::default(), 1, &p, 0.02);
        let mut out = vec![];
        let judged = d.cannot_judge(10.0, &failing(&[2]), &mut out);
        let rudder = p.actuator_index("rudder").unwrap();
        assert_eq!(judged, p.actuators.len() - 1);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].actuator.as_deref(), Some("rudder"));
        assert_eq!(
            (out[0].event, out[0].rule),
            (Event::CannotJudge, Some(Rule::G2))
        );
        assert!(out[0].detail.as_deref().unwrap().contains("yaw (R²=-2.00)"));
        assert_eq!(d.health(rudder), Health::CannotJudge);
        // Nothing is decided on it afterwards, however strong the filters' evidence.
        let mut est = vec![AhcEstimate::default(); p.actuators.len()];
        for e in &mut est {
            *e = AhcEstimate {
                gamma: 1.0,
                gamma_lo: 0.9,
                gamma_hi: 1.1,
                delta_lo: -0.02,
                delta_hi: 0.02,
                ..Default::default()
            };
        }
        est[rudder] = AhcEstimate {
            gamma: 0.4,
            gamma_lo: 0.35,
            gamma_hi: 0.45,
            delta_lo: -0.02,
            delta_hi: 0.02,
            ..Default::default()
        };
        let u = vec![0.3; p.actuators.len()];
        let mut decided = vec![];
        for k in 0..1500 {
            let t = 10.0 + k as f64 * 0.02;
            let u: Vec<f64> = (u.iter()).map(|v| v + 0.2 * (t * 3.0).sin()).collect();
            d.update(t, &u, &[&est, &est], &mut decided);
        }
        assert!(
            decided
                .iter()
                .all(|x| x.actuator.as_deref() != Some("rudder")),
            "{decided:?}"
        );
        assert_eq!(d.health(rudder), Health::CannotJudge);
    }

    #[test]
    fn g2_a_quad_with_one_unexplained_rate_axis_is_judged_and_with_two_is_not() {
        let p = Profile::resolve("quad-x").unwrap();
        let mut d = Diagnoser::new(DiagnosisParams::default(), 1, &p, 0.02);
        let mut out = vec![];
        // A motor acts on roll and pitch alike: with one of them explained, half its effect is.
        assert_eq!(d.cannot_judge(0.0, &failing(&[1]), &mut out), 4);
        assert!(out.is_empty());
        assert_eq!(d.cannot_judge(0.0, &failing(&[0, 1]), &mut out), 0);
        assert_eq!(out.len(), 4);
    }
}
