//! How long the live monitor takes from a frame's arrival (the reader's receive) to the end of
//! its processing (estimates and any decision written and flushed): a fixed histogram, filled
//! without allocating, read as quantiles for the summary.
//!
//! Buckets are 1 µs wide below 1 ms and 1 ms wide from 1 ms to 10 s, so a quantile below 1 ms
//! is exact to the microsecond and one above to the millisecond; longer times fall in the
//! last bucket. Two quantiles over fixed buckets need no histogram crate.

use std::time::Duration;

const FINE: usize = 1000;
const COARSE: usize = 10_000;

#[derive(Debug, Clone)]
pub struct Latency {
    /// `[0, FINE)`: µs; `[FINE, FINE + COARSE)`: ms (index − FINE + 1).
    buckets: Vec<u64>,
    count: u64,
    max: Duration,
}

impl Default for Latency {
    fn default() -> Self {
        Self {
            buckets: vec![0; FINE + COARSE],
            count: 0,
            max: Duration::ZERO,
        }
    }
}

impl Latency {
    pub fn record(&mut self, d: Duration) {
        let us = d.as_micros();
        let i = if us < FINE as u128 {
            us as usize
        } else {
            (FINE - 1 + (d.as_millis() as usize).min(COARSE)).min(FINE + COARSE - 1)
        };
        self.buckets[i] += 1;
        self.count += 1;
        self.max = self.max.max(d);
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    /// The smallest bucket's upper edge below which at least `q` of the records lie.
    pub fn quantile(&self, q: f64) -> Duration {
        if self.count == 0 {
            return Duration::ZERO;
        }
        let rank = ((q * self.count as f64).ceil() as u64).clamp(1, self.count);
        let mut seen = 0;
        for (i, n) in self.buckets.iter().enumerate() {
            seen += n;
            if seen >= rank {
                // The last bucket holds everything from 10 s: its edge is the largest seen.
                return if i == FINE + COARSE - 1 {
                    self.max
                } else if i < FINE {
                    Duration::from_micros(i as u64 + 1)
                } else {
                    Duration::from_millis((i - FINE + 2) as u64)
                }
                .min(self.max);
            }
        }
        self.max
    }

    /// "p50 12 µs, p99 80 µs, max 1.2 ms over 1000 frames".
    pub fn describe(&self, what: &str) -> String {
        format!(
            "p50 {}, p99 {}, max {} over {} {what}",
            show(self.quantile(0.5)),
            show(self.quantile(0.99)),
            show(self.max),
            self.count
        )
    }
}

fn show(d: Duration) -> String {
    if d < Duration::from_millis(1) {
        format!("{} µs", d.as_micros())
    } else {
        format!("{:.1} ms", d.as_secs_f64() * 1e3)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Quantiles against a sort of the same records, at both bucket widths.
    #[test]
    fn quantiles_match_a_sort_to_the_bucket_width() {
        let mut h = Latency::default();
        let mut all: Vec<Duration> = (0..5000u64)
            .map(|i| Duration::from_nanos((i * 7919 % 5000) * 400 + 150))
            .collect();
        all.push(Duration::from_secs(30));
        for d in &all {
            h.record(*d);
        }
        all.sort();
        for q in [0.01, 0.5, 0.9, 0.99, 0.999] {
            let exact = all[((q * all.len() as f64).ceil() as usize).clamp(1, all.len()) - 1];
            let got = h.quantile(q);
            let width = if exact < Duration::from_millis(1) {
                Duration::from_micros(1)
            } else {
                Duration::from_millis(1)
            };
            assert!(
                got >= exact && got <= exact + width,
                "q {q}: {got:?} against {exact:?}"
            );
        }
        assert_eq!(h.quantile(1.0), Duration::from_secs(30));
        assert_eq!(h.count(), 5001);
        assert_eq!(Latency::default().quantile(0.5), Duration::ZERO);
    }
}
