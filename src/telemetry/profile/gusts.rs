//! Rule T1: a profile's threshold against the gusts a flight's calibration measures.

use super::DiagnosisSpec;

/// Rule T1 raises a threshold at most this much. The rule was checked on gusts 1.5 times the
/// reference; a wind state read at over twice it on a 20 s stretch is more likely a slow drift,
/// whose long time constant the fit extrapolates to a large spread, than gusts.
pub const MAX_GUST_FACTOR: f64 = 2.0;

impl DiagnosisSpec {
    /// Rule T1: the factor (over 1) by which the deviation threshold is raised for a flight
    /// whose calibration measured `measured` gusts: their level against the profile's
    /// `gusts` ([`Self::gust_level`]). A healthy actuator's deviation is the wind the filters
    /// cannot tell from an offset; the rate model is linear, so it scales with the gusts, and a
    /// threshold alarm-free under the reference gusts stays so under stronger ones scaled by
    /// their ratio (at most [`MAX_GUST_FACTOR`]). Never lowered: a calmer flight keeps the
    /// threshold. The gain statistic is not scaled: the MIT-UKF's bounds it reads widen with
    /// the noise the calibration measures.
    pub fn gust_factor(&self, measured: &[Option<f64>; 3]) -> Option<f64> {
        let reference = self.gusts?.map(Some);
        Self::gust_level(measured, &reference)
            .filter(|f| *f > 1.0 && !f.is_nan())
            .map(|f| f.min(MAX_GUST_FACTOR))
    }

    /// The level of `measured` gusts against `reference` ones: the root mean square of their
    /// ratios over the axes both have. Gusts scale together on every axis; one 20 s stretch
    /// reads each axis to about 20 %, and the three together to about 12 %.
    pub fn gust_level(measured: &[Option<f64>; 3], reference: &[Option<f64>; 3]) -> Option<f64> {
        let ratios: Vec<f64> = (0..3)
            .filter_map(|i| Some(measured[i]? / reference[i].filter(|r| *r > 0.0)?))
            .collect();
        (!ratios.is_empty())
            .then(|| (ratios.iter().map(|r| r * r).sum::<f64>() / ratios.len() as f64).sqrt())
    }
}
