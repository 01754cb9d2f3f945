//! Health over flights: each airframe × actuator's gain across its flights (`ahcmon scan`'s
//! rows), a trend, and an alarm when the gain is heading out of its band.
//!
//! **Fit.** The points are the flights' median gamma of the MIT-UKF (`y_k`, flight index `k`
//! in start-time order), weighted by their median bounds: `w_k = 1/σ_k²` with `σ_k` a third of
//! the bounds' half-width (they are 3σ). Over the last [`HistoryRule::window`] flights a
//! weighted least-squares line `y = a + b k` is fitted. The bounds say how the flights compare,
//! not how far the medians scatter from flight to flight (a median of thousands of steps is
//! much tighter than one step's bounds), so the slope's standard error is scaled by the
//! weighted residuals: `se(b)² = s² / Σ w (k - k̄)²`, `s² = Σ w r² / (n - 2)`.
//!
//! **Alarm** at a flight `k`, from the last [`HistoryRule::window`] flights up to it (fewer at
//! the start of a series, from 4 usable flights on): the slope is negative beyond Student's
//! t quantile for the stated false-alarm probability at the fit's degrees of freedom
//! (`b / se(b) < t_{n-2}(p)`, `p` = [`HistoryRule::false_alarm`]), and the line crosses
//! [`HistoryRule::loss_gamma`] within [`HistoryRule::horizon`] flights after it. Were the
//! flights' scatter about the line normal and their weights right, a healthy series would
//! pass the slope test by chance with probability `p` at every flight judged, whatever the
//! number of points (at 10 degrees of freedom and `p` = 0.001 the slope must pass -4.14
//! standard errors; at 2, -22.3). The crossing test removes most of those chance passes
//! again, for a healthy line seldom reaches the loss gain within the horizon.

/// The rule's numbers.
#[derive(Debug, Clone, Copy)]
pub struct HistoryRule {
    /// The gain counted as lost (the crossing predicted).
    pub loss_gamma: f64,
    /// Flights ahead within which a predicted crossing raises the alarm.
    pub horizon: f64,
    /// Flights fitted (the last ones up to the flight judged); at least 4.
    pub window: usize,
    /// Probability that a healthy series' slope passes the test by chance, per flight judged.
    pub false_alarm: f64,
}

impl Default for HistoryRule {
    fn default() -> Self {
        Self {
            loss_gamma: 0.8,
            horizon: 10.0,
            window: 12,
            false_alarm: 0.001,
        }
    }
}

/// One flight's point: its median gamma and the median bounds.
#[derive(Debug, Clone, Copy)]
pub struct Point {
    pub gamma: f64,
    pub lo: f64,
    pub hi: f64,
}

/// A line through the points: `gamma = intercept + slope k` (k: the flight's index in the
/// series), the slope's standard error, and the flight index where it reaches the loss gain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trend {
    pub intercept: f64,
    pub slope: f64,
    pub slope_se: f64,
    pub crossing: Option<f64>,
    /// The usable points fitted.
    pub points: usize,
}

/// The weighted line through `points[first..=last]`, or `None` with under 4 usable points.
pub fn fit(points: &[Point], first: usize, last: usize, loss_gamma: f64) -> Option<Trend> {
    let usable: Vec<(f64, f64, f64)> = (first..=last.min(points.len().saturating_sub(1)))
        .filter_map(|k| {
            let p = points[k];
            let sigma = (p.hi - p.lo) / 6.0;
            (p.gamma.is_finite() && sigma.is_finite() && sigma > 0.0)
                .then(|| (k as f64, p.gamma, 1.0 / (sigma * sigma)))
        })
        .collect();
    if usable.len() < 4 {
        return None;
    }
    let sw: f64 = usable.iter().map(|u| u.2).sum();
    let kbar = usable.iter().map(|u| u.2 * u.0).sum::<f64>() / sw;
    let ybar = usable.iter().map(|u| u.2 * u.1).sum::<f64>() / sw;
    let sxx: f64 = usable.iter().map(|u| u.2 * (u.0 - kbar).powi(2)).sum();
    let sxy: f64 = usable
        .iter()
        .map(|u| u.2 * (u.0 - kbar) * (u.1 - ybar))
        .sum();
    if sxx <= 0.0 {
        return None;
    }
    let slope = sxy / sxx;
    let intercept = ybar - slope * kbar;
    let resid: f64 = usable
        .iter()
        .map(|u| u.2 * (u.1 - intercept - slope * u.0).powi(2))
        .sum();
    let s2 = resid / (usable.len() - 2) as f64;
    let slope_se = (s2 / sxx).sqrt();
    let crossing = (slope < 0.0).then(|| (loss_gamma - intercept) / slope);
    Some(Trend {
        intercept,
        slope,
        slope_se,
        crossing,
        points: usable.len(),
    })
}

/// The t quantile below which the slope alarms: `t_{dof}(p)`, negative.
pub fn slope_threshold(dof: usize, false_alarm: f64) -> f64 {
    use statrs::distribution::{ContinuousCDF, StudentsT};
    StudentsT::new(0.0, 1.0, dof as f64).map_or(f64::NEG_INFINITY, |t| t.inverse_cdf(false_alarm))
}

/// The first flight (index) at which the rule alarms, judging each flight from the ones up to
/// it (the last `window`, from 4 usable on), with that flight's trend.
pub fn first_alarm(points: &[Point], rule: &HistoryRule) -> Option<(usize, Trend)> {
    let window = rule.window.max(4);
    (3..points.len()).find_map(|k| {
        let first = (k + 1).saturating_sub(window);
        let t = fit(points, first, k, rule.loss_gamma)?;
        let limit = slope_threshold(t.points - 2, rule.false_alarm);
        let falling = t.slope < 0.0 && t.slope < limit * t.slope_se;
        let soon = t.crossing.is_some_and(|c| c - k as f64 <= rule.horizon);
        (falling && soon).then_some((k, t))
    })
}

/// One flight of a series, in the order it is sorted by.
#[derive(Debug, Clone)]
pub struct Flight {
    pub start: Option<u64>,
    pub file: String,
    pub point: Point,
}

/// Flights by start time, those without one after them, then by file name.
pub fn order(flights: &mut [Flight]) {
    flights.sort_by(|a, b| {
        (a.start.is_none(), a.start, &a.file).cmp(&(b.start.is_none(), b.start, &b.file))
    });
}

/// One airframe × actuator's flights, in order, its trend over the last window and its first
/// alarm.
#[derive(Debug, Clone)]
pub struct Series {
    pub airframe: String,
    pub actuator: String,
    pub flights: Vec<Flight>,
    pub trend: Option<Trend>,
    /// The flight index (0-based) of the first alarm.
    pub alarm: Option<usize>,
    /// Some flights have a start time and some do not (those go last, by name).
    pub mixed_start_times: bool,
}

impl Series {
    /// As `history --json` writes it (flights counted from 1).
    pub fn json(&self) -> serde_json::Value {
        use serde_json::json;
        json!({
            "airframe": self.airframe,
            "actuator": self.actuator,
            "flights": self.flights.iter().map(|f| json!({
                "file": f.file, "start_unix_us": f.start,
                "gamma": f.point.gamma, "gamma_lo": f.point.lo, "gamma_hi": f.point.hi,
            })).collect::<Vec<_>>(),
            "trend": self.trend.map(|t| json!({
                "slope": t.slope, "slope_se": t.slope_se, "intercept": t.intercept,
                "reaches_loss_at_flight": t.crossing.filter(|c| c.is_finite()).map(|c| c + 1.0),
            })),
            "alarm_from_flight": self.alarm.map(|k| k + 1),
        })
    }
}

/// `scan`'s rows grouped per airframe × actuator (the airframe the user named, else the
/// board id, else `sysid N`), each series ordered, fitted over its last window and judged.
/// Rows without an actuator's MIT-UKF gamma (a vehicle never estimated) are left out.
pub fn series(rows: &[serde_json::Value], rule: &HistoryRule) -> Vec<Series> {
    let mut groups: std::collections::BTreeMap<(String, String), Vec<Flight>> =
        std::collections::BTreeMap::new();
    for row in rows {
        let (Some(actuator), Some(gamma)) =
            (row["actuator"].as_str(), row["mit_ukf"]["gamma"].as_f64())
        else {
            continue;
        };
        let airframe = row["airframe"]
            .as_str()
            .or(row["board_uid"].as_str())
            .map(str::to_string)
            .unwrap_or_else(|| format!("sysid {}", row["sysid"]));
        groups
            .entry((airframe, actuator.to_string()))
            .or_default()
            .push(Flight {
                start: row["start_unix_us"].as_u64(),
                file: row["file"].as_str().unwrap_or_default().to_string(),
                point: Point {
                    gamma,
                    lo: row["mit_ukf"]["gamma_lo"].as_f64().unwrap_or(f64::NAN),
                    hi: row["mit_ukf"]["gamma_hi"].as_f64().unwrap_or(f64::NAN),
                },
            });
    }
    groups
        .into_iter()
        .map(|((airframe, actuator), mut flights)| {
            order(&mut flights);
            let points: Vec<Point> = flights.iter().map(|f| f.point).collect();
            let last = points.len() - 1;
            Series {
                mixed_start_times: flights.iter().any(|f| f.start.is_none())
                    && flights.iter().any(|f| f.start.is_some()),
                trend: fit(
                    &points,
                    (last + 1).saturating_sub(rule.window),
                    last,
                    rule.loss_gamma,
                ),
                alarm: first_alarm(&points, rule).map(|(k, _)| k),
                airframe,
                actuator,
                flights,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points(ys: &[f64]) -> Vec<Point> {
        ys.iter()
            .map(|&y| Point {
                gamma: y,
                lo: y - 0.03,
                hi: y + 0.03,
            })
            .collect()
    }

    /// Equal weights: the slope and its standard error are ordinary least squares', checked
    /// against the textbook formulas on a small series.
    #[test]
    fn equal_weights_give_ordinary_least_squares() {
        let ys = [1.0, 0.99, 0.97, 0.96, 0.95];
        let t = fit(&points(&ys), 0, 4, 0.8).unwrap();
        // x = 0..4: x̄ = 2, ȳ = 0.974, Sxx = 10, Sxy = Σ (x - 2) y = -0.13.
        assert!((t.slope - (-0.013)).abs() < 1e-12, "{t:?}");
        assert!((t.intercept - 1.0).abs() < 1e-12, "{t:?}");
        let resid: f64 = ys
            .iter()
            .enumerate()
            .map(|(x, y)| (y - t.intercept - t.slope * x as f64).powi(2))
            .sum();
        assert!((t.slope_se - (resid / 3.0 / 10.0).sqrt()).abs() < 1e-12);
        assert!((t.crossing.unwrap() - (0.8 - t.intercept) / t.slope).abs() < 1e-9);
    }

    #[test]
    fn a_steady_fall_alarms_early_and_a_flat_series_never() {
        let rule = HistoryRule::default();
        // 0.02 a flight with ±0.004 of scatter: crosses 0.8 at flight 10.
        let scatter = [
            0.003, -0.004, 0.001, 0.004, -0.002, 0.0, -0.003, 0.002, 0.004, -0.001, 0.002, -0.004,
        ];
        let falling: Vec<f64> = (0..12)
            .map(|k| 1.0 - 0.02 * k as f64 + scatter[k])
            .collect();
        // Judged from the fourth flight on, alarmed once the slope passes its threshold and
        // the loss is within the horizon, before the loss.
        let (k, t) = first_alarm(&points(&falling), &rule).unwrap();
        assert!((3..9).contains(&k), "{k} {t:?}");
        assert!(t.crossing.unwrap() > k as f64, "{t:?}");
        assert!(t.slope < slope_threshold(t.points - 2, rule.false_alarm) * t.slope_se);
        let flat: Vec<f64> = scatter.iter().map(|s| 1.0 + s).collect();
        assert_eq!(first_alarm(&points(&flat), &rule), None);
    }

    #[test]
    fn flights_go_by_start_time_then_those_without_by_name() {
        let f = |start: Option<u64>, file: &str| Flight {
            start,
            file: file.into(),
            point: Point {
                gamma: 1.0,
                lo: 0.9,
                hi: 1.1,
            },
        };
        let mut flights = vec![
            f(None, "a.bin"),
            f(Some(30), "b.tlog"),
            f(Some(10), "z.tlog"),
            f(None, "0.ulg"),
        ];
        order(&mut flights);
        let names: Vec<&str> = flights.iter().map(|f| f.file.as_str()).collect();
        assert_eq!(names, ["z.tlog", "b.tlog", "0.ulg", "a.bin"]);
    }

    /// The threshold is Student's t quantile: the textbook values at p = 0.001.
    #[test]
    fn the_slope_threshold_is_student_s_quantile() {
        for (dof, t) in [
            (2, -22.327),
            (4, -7.173),
            (6, -5.208),
            (10, -4.144),
            (30, -3.385),
        ] {
            let got = slope_threshold(dof, 0.001);
            assert!((got - t).abs() < 2e-3, "dof {dof}: {got} against {t}");
        }
    }
}
