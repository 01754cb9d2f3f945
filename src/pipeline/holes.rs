//! Short holes in a calibration stretch, filled: a lost sample put back on the period's grid
//! by straight lines between its neighbours, marked so that a fit takes it as history only.

use super::calibrating::StoredSample;

/// The stretch with its short holes filled: between two samples further apart than one step
/// (`max_interval` periods) but no further than the longest period the model
/// supports (`max_span`: the rate rule's bound, in calibrating.rs), the lost
/// samples are put back on the period's grid by straight lines between the two: rates,
/// outputs and a_z (a command is smooth on that scale, as the rates are; its error is second
/// order in the span). They are marked filled, so a fit takes them as history only; a longer
/// hole stays a gap. Returns the samples with `measured` flags, and how many were filled.
pub(super) fn fill_short_holes(
    samples: &[StoredSample],
    dt: f64,
    max_interval: f64,
    max_span: f64,
) -> (Vec<(StoredSample, bool)>, u64) {
    let mut out = Vec::with_capacity(samples.len() + samples.len() / 2);
    let mut filled = 0;
    for (k, s) in samples.iter().enumerate() {
        if let Some(prev) = k.checked_sub(1).map(|j| &samples[j]) {
            let span = s.t - prev.t;
            if span > max_interval * dt && span <= max_span {
                let n = ((span / dt).round() as usize).max(1);
                for i in 1..n {
                    let w = i as f64 / n as f64;
                    let lerp = |a: f64, b: f64| a + w * (b - a);
                    out.push((
                        StoredSample {
                            t: lerp(prev.t, s.t),
                            rates: [0, 1, 2].map(|a| lerp(prev.rates[a], s.rates[a])),
                            u: std::array::from_fn(|j| lerp(prev.u[j], s.u[j])),
                            az: prev.az.zip(s.az).map(|(a, b)| lerp(a, b)),
                        },
                        false,
                    ));
                    filled += 1;
                }
            }
        }
        out.push((*s, true));
    }
    (out, filled)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::MAX_ACTUATORS;

    /// Samples of straight lines in t, which filling must reproduce exactly.
    fn at(t: f64) -> StoredSample {
        let mut u = [0.0; MAX_ACTUATORS];
        u[0] = 0.5 + 0.1 * t;
        StoredSample {
            t,
            rates: [t, -2.0 * t, 0.3],
            u,
            az: Some(-9.8 + t),
        }
    }

    #[test]
    fn short_holes_are_filled_on_the_grid_and_long_ones_left() {
        let dt = 0.02;
        // Holes: 2 samples lost (60 ms span) and 9 lost (200 ms, over a 111 ms bound).
        let kept = [0, 1, 2, 5, 6, 16, 17];
        let samples: Vec<StoredSample> = kept.iter().map(|&k| at(k as f64 * dt)).collect();
        let (grid, filled) = fill_short_holes(&samples, dt, 1.5, 0.5 / 4.5);
        assert_eq!(filled, 2);
        let ts: Vec<i64> = grid
            .iter()
            .map(|(s, _)| (s.t / dt).round() as i64)
            .collect();
        assert_eq!(ts, [0, 1, 2, 3, 4, 5, 6, 16, 17]);
        let measured: Vec<bool> = grid.iter().map(|(_, m)| *m).collect();
        assert_eq!(
            measured,
            [true, true, true, false, false, true, true, true, true]
        );
        for (s, _) in &grid {
            let want = at(s.t);
            assert!((s.rates[0] - want.rates[0]).abs() < 1e-12);
            assert!((s.rates[1] - want.rates[1]).abs() < 1e-12);
            assert!((s.u[0] - want.u[0]).abs() < 1e-12);
            assert!((s.az.unwrap_or(0.0) - want.az.unwrap_or(1.0)).abs() < 1e-12);
        }
    }
}
