//! `ahcmon scan`'s rows: one per flight (a log) × vehicle × actuator, for a fleet's health
//! history.
//!
//! Each coefficient of each filter is told by its **median over the filter steps after the
//! calibration**, with the medians of its lower and upper bounds: a fault in the last minute
//! of an hour's flight moves the median little, which is what a trend across flights wants;
//! the faults themselves are counted beside it. The set filter's medians are over the steps
//! where that coefficient was excited (its bounds are the a priori box otherwise). Medians
//! are read from histograms of [`BIN`] wide bins over the range the filters' boxes allow, so
//! memory stays flat in the log's length and a median is exact to [`BIN`]. `gamma_steps` and
//! `delta_steps` say over how many steps.

use super::Sink;
use super::summary::actuator_state;
use crate::diagnose::vehicle::{Decision, Event};
use crate::estimate::vehicle::AhcEstimate;
use crate::link::{LogFormat, LogItem, TlogReader, read_log, sniff};
use crate::monitor::Monitor;
use crate::telemetry::Profile;
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::path::Path;

/// Histogram bin width: the medians' resolution.
pub const BIN: f64 = 1e-3;
/// The filters reported: the MIT-UKF (probable bounds) and the set filter (guaranteed).
const FILTERS: [(usize, &str); 2] = [(0, "mit_ukf"), (2, "set")];
/// Range of each coefficient's histogram: the filters' a priori boxes with room.
const GAMMA_RANGE: (f64, f64) = (-1.5, 3.5);
const DELTA_RANGE: (f64, f64) = (-2.5, 2.5);

/// A median over a stream in fixed memory: counts per bin, and outside the range.
#[derive(Debug, Clone)]
struct Median {
    lo: f64,
    counts: Vec<u32>,
    below: u64,
    above: u64,
    n: u64,
}

impl Median {
    fn new((lo, hi): (f64, f64)) -> Self {
        Self {
            lo,
            counts: vec![0; ((hi - lo) / BIN).round() as usize],
            below: 0,
            above: 0,
            n: 0,
        }
    }

    fn add(&mut self, x: f64) {
        if !x.is_finite() {
            return;
        }
        self.n += 1;
        let k = ((x - self.lo) / BIN).floor();
        if k < 0.0 {
            self.below += 1;
        } else if k >= self.counts.len() as f64 {
            self.above += 1;
        } else {
            self.counts[k as usize] += 1;
        }
    }

    /// The median, at its bin's centre; `None` with no value, or when it falls outside.
    fn get(&self) -> Option<f64> {
        if self.n == 0 {
            return None;
        }
        let half = self.n.div_ceil(2);
        let mut seen = self.below;
        if seen >= half {
            return None;
        }
        for (k, &c) in self.counts.iter().enumerate() {
            seen += u64::from(c);
            if seen >= half {
                // At the bin's centre, rounded to a tenth of a bin (no 0.99449999 in the rows).
                let centre = self.lo + (k as f64 + 0.5) * BIN;
                return Some(round_to(centre, 0.1 * BIN));
            }
        }
        None
    }
}

/// `x` to a multiple of `step` (a power of ten below one), as the nearest double to the
/// decimal: dividing by the exact integer `1/step` leaves no 0.99449999 in the rows.
fn round_to(x: f64, step: f64) -> f64 {
    let per_unit = (1.0 / step).round();
    (x * per_unit).round() / per_unit
}

/// One filter's view of one actuator: estimate, lower and upper bound of gamma, then delta;
/// the steps counted for each.
#[derive(Debug, Clone)]
struct Coefficients {
    stats: [Median; 6],
    steps: [u64; 2],
}

impl Coefficients {
    fn new() -> Self {
        let g = Median::new(GAMMA_RANGE);
        let d = Median::new(DELTA_RANGE);
        Self {
            stats: [g.clone(), g.clone(), g, d.clone(), d.clone(), d],
            steps: [0; 2],
        }
    }

    /// A step's estimate of gamma and delta, each when `use_` it.
    fn add(&mut self, e: &AhcEstimate, use_: [bool; 2]) {
        let values = [
            [e.gamma, e.gamma_lo, e.gamma_hi],
            [e.delta, e.delta_lo, e.delta_hi],
        ];
        for c in 0..2 {
            if use_[c] {
                self.steps[c] += 1;
                for (m, v) in self.stats[3 * c..3 * c + 3].iter_mut().zip(values[c]) {
                    m.add(v);
                }
            }
        }
    }

    fn json(&self) -> Value {
        let m = |k: usize| self.stats[k].get();
        json!({
            "gamma": m(0), "gamma_lo": m(1), "gamma_hi": m(2),
            "delta": m(3), "delta_lo": m(4), "delta_hi": m(5),
            "gamma_steps": self.steps[0], "delta_steps": self.steps[1],
        })
    }
}

/// Collects what the rows need while a log is replayed: the decisions and, per vehicle and
/// actuator, each reported filter's medians.
#[derive(Debug, Default)]
pub struct FlightSink {
    pub decisions: Vec<Decision>,
    actuators: BTreeMap<(u8, usize), [Coefficients; 2]>,
    first_t: BTreeMap<u8, f64>,
    last_t: BTreeMap<u8, f64>,
}

impl Sink for FlightSink {
    fn decision(&mut self, d: &Decision) {
        self.decisions.push(d.clone());
    }

    fn estimates(&mut self, t: f64, sysid: u8, est: &[&[AhcEstimate]; 3], _profile: &Profile) {
        self.first_t.entry(sysid).or_insert(t);
        self.last_t.insert(sysid, t);
        for j in 0..est[0].len() {
            let a = self
                .actuators
                .entry((sysid, j))
                .or_insert_with(|| [Coefficients::new(), Coefficients::new()]);
            for (slot, &(f, _)) in FILTERS.iter().enumerate() {
                if let Some(e) = est[f].get(j) {
                    // The set filter's bounds where unexcited are its a priori box.
                    let use_ = if f == 2 {
                        [!e.unexcited[0], !e.unexcited[1]]
                    } else {
                        [true; 2]
                    };
                    a[slot].add(e, use_);
                }
            }
        }
    }
}

/// What a row says of its log, besides what the monitor knows.
#[derive(Debug, Clone, Default)]
pub struct LogInfo {
    pub file: String,
    pub format: &'static str,
    /// The first record's time (µs since the Unix epoch), where the log has one (tlog).
    pub start_unix_us: Option<u64>,
    /// Frames or messages the reader dropped (bad checksums, cut records, unknown ids).
    pub dropped: u64,
}

/// The rows of one replayed log: per vehicle that sent samples, one per actuator of its
/// profile; a vehicle that was never estimated gets one row without an actuator, saying why.
pub fn rows(monitor: &Monitor, sink: &FlightSink, log: &LogInfo) -> Vec<Value> {
    let mut out = Vec::new();
    for (sysid, v) in &monitor.assembler.vehicles {
        if v.counters.samples == 0 {
            continue;
        }
        let p = monitor.pipelines.get(sysid);
        let heartbeat = v.info.mav_type.is_some();
        let base = json!({
            "file": log.file,
            "format": log.format,
            // Set by `scan` from the user's mapping (`crate::airframes`).
            "airframe": null,
            "board_uid": v.info.board_uid,
            "sysid": sysid,
            "vehicle_type": v.info.mav_type.map(|t| format!("{t:?}")
                .trim_start_matches("MAV_TYPE_")
                .to_lowercase()),
            "profile": p.and_then(|p| p.profile()).map(|pr| pr.name.clone()),
            "start_unix_us": log.start_unix_us,
            "log_dropped": log.dropped,
            "estimated_s": match (sink.first_t.get(sysid), sink.last_t.get(sysid)) {
                (Some(a), Some(b)) => Some(round_to(b - a, 1e-3)),
                _ => None,
            },
            "samples": v.counters.samples,
            "frames_missing": v.counters.lost_frames,
            "stage": p.map(|p| p.stage_name()),
            "no_estimates": p.and_then(|p| p.why_not_estimating(heartbeat)),
        });
        let profile = p.and_then(|p| p.profile());
        let (Some(p), Some(profile)) = (p, profile) else {
            out.push(base);
            continue;
        };
        for (j, a) in profile.actuators.iter().enumerate() {
            let (faults, state) = actuator_state(p, *sysid, j, &a.name, &sink.decisions);
            let first_fault = sink.decisions.iter().find(|d| {
                d.sysid == *sysid
                    && d.actuator.as_deref() == Some(&a.name)
                    && d.event == Event::Fault
            });
            let mut row = base.clone();
            row["actuator"] = json!(a.name);
            row["channel"] = json!(a.channel);
            row["faults"] = json!(faults);
            row["first_fault_t"] = json!(first_fault.map(|d| d.t));
            row["state"] = json!(state);
            if let Some(c) = sink.actuators.get(&(*sysid, j)) {
                for (slot, &(_, name)) in FILTERS.iter().enumerate() {
                    row[name] = c[slot].json();
                }
            }
            out.push(row);
        }
    }
    out
}

/// One log through its own monitor: its rows (the airframe set where `airframes` names it),
/// or why it could not be read.
pub fn log_rows(
    path: &Path,
    config: &crate::pipeline::PipelineConfig,
    airframes: Option<&crate::airframes::Airframes>,
) -> Result<Vec<Value>, String> {
    let mut monitor = Monitor::new(config.clone());
    let mut sink = FlightSink::default();
    let format = std::fs::File::open(path)
        .and_then(sniff)
        .map_err(|e| e.to_string())?;
    let mut info = LogInfo {
        file: path.display().to_string(),
        format: format.name(),
        ..LogInfo::default()
    };
    if format == LogFormat::Tlog {
        let mut reader = TlogReader::open(path).map_err(|e| e.to_string())?;
        while let Some((ts, frame)) = reader.next_frame().map_err(|e| e.to_string())? {
            info.start_unix_us.get_or_insert(ts);
            monitor.on_frame(&frame, &mut sink);
        }
        if reader.counters.frames == 0 {
            return Err("no MAVLink frame of a known message: not a telemetry log".into());
        }
        info.dropped = reader.counters.dropped();
    } else {
        let (_, report) = read_log(
            path,
            &mut |item| match item {
                LogItem::Frame(f) => monitor.on_frame(f, &mut sink),
                LogItem::Record(r) => monitor.on_record(1, r, &mut sink),
            },
            &mut |_| {},
        )
        .map_err(|e| format!("{}: {e}", format.name()))?;
        info.dropped = report.counters.dropped();
    }
    monitor.finish(&mut sink);
    let mut rows = rows(&monitor, &sink, &info);
    if let Some(airframes) = airframes {
        let mut said = false;
        // A log of several vehicles is several airframes: the name its path matched is told
        // apart by system id (a board id names one vehicle already).
        let vehicles: std::collections::BTreeSet<u64> =
            rows.iter().filter_map(|r| r["sysid"].as_u64()).collect();
        for row in &mut rows {
            let board = row["board_uid"].as_str();
            let by_board =
                board.is_some_and(|b| !airframes.names_for(Path::new(""), Some(b)).is_empty());
            let names = airframes.names_for(path, board);
            if names.len() > 1 && !said {
                tracing::warn!(
                    "scan: {}: named by airframes {} in the airframes file; taken as {}",
                    path.display(),
                    names.join(", "),
                    names[0]
                );
                said = true;
            }
            row["airframe"] = match names.first() {
                None => Value::Null,
                Some(&n) if vehicles.len() > 1 && !by_board => {
                    format!("{n} sysid {}", row["sysid"]).into()
                }
                Some(&n) => n.into(),
            };
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The histogram's median against the sorted list's, to the bin width, on random data.
    #[test]
    fn the_median_is_the_sorted_middle_to_a_bin() {
        let mut x = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % 1_000_000) as f64 / 1e6
        };
        for n in [1usize, 2, 3, 10, 1001] {
            let mut m = Median::new(GAMMA_RANGE);
            let mut v: Vec<f64> = (0..n).map(|_| 0.5 + next()).collect();
            for &x in &v {
                m.add(x);
            }
            v.sort_by(f64::total_cmp);
            let lower_middle = v[n.div_ceil(2) - 1];
            let got = m.get().unwrap();
            assert!(
                (got - lower_middle).abs() <= BIN,
                "n {n}: {got} vs {lower_middle}"
            );
        }
    }

    #[test]
    fn a_median_outside_the_range_or_of_nothing_is_none() {
        let mut m = Median::new((0.0, 1.0));
        assert_eq!(m.get(), None);
        for x in [5.0, 6.0, 0.5, f64::NAN] {
            m.add(x);
        }
        assert_eq!(m.get(), None, "two of three above the range");
        m.add(0.25);
        m.add(0.75);
        // 0.25, 0.5, 0.75, 5, 6: the third.
        assert!((m.get().unwrap() - 0.75).abs() <= BIN);
    }
}
