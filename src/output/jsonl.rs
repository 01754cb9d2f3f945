//! JSON-lines files: decisions, estimates and the simulator's truth. One
//! object per line, flushed per line so a reader (or a crash) never sees half a record.
//!
//! An output file is opened when the run starts (so a path that cannot be written fails at
//! once) but not emptied: an existing file is replaced in place when the run writes its first
//! line, or at its end ([`Outputs::finish`]) if it wrote none. A run that stops on an error
//! before either (an input that is not a log, an empty one) leaves the file as it was. Not a
//! rename: a live run's lines are in the named file as they are made (`tail -f`). `-` is
//! standard output ([`crate::output::file`]).

use crate::diagnose::vehicle::Decision;
use crate::estimate::vehicle::{AhcEstimate, FILTER_NAMES};
use crate::output::Sink;
pub use crate::output::file::OutputFile;
use crate::sim::vehicle::VehicleSample;
use crate::telemetry::Profile;
use serde::Serialize;
use std::io::{BufWriter, Write};
use std::path::Path;

pub struct JsonlWriter<W: Write> {
    out: W,
    pub lines: u64,
    /// The file's name, for its write errors (a full disk said only "No space left on device",
    /// not whether the decisions or the estimates were lost).
    name: Option<String>,
}

/// A JSON-lines output file.
pub type JsonlFile = JsonlWriter<BufWriter<OutputFile>>;

impl JsonlFile {
    /// Open the file for this run (see the module note); the error names it.
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let mut w = Self::new(BufWriter::new(OutputFile::open(path)?));
        w.name = Some(path.display().to_string());
        Ok(w)
    }

    /// The run is over: a file it wrote nothing to is emptied (its outputs are none).
    pub fn finish(&mut self) -> std::io::Result<()> {
        let r = self.out.flush().and_then(|()| self.out.get_mut().empty());
        r.map_err(|e| match &self.name {
            Some(name) => std::io::Error::new(e.kind(), format!("{name}: {e}")),
            None => e,
        })
    }
}

impl<W: Write> JsonlWriter<W> {
    pub fn new(out: W) -> Self {
        Self {
            out,
            lines: 0,
            name: None,
        }
    }

    pub fn write<T: Serialize>(&mut self, record: &T) -> std::io::Result<()> {
        self.write_line(record).map_err(|e| match &self.name {
            Some(name) => std::io::Error::new(e.kind(), format!("{name}: {e}")),
            None => e,
        })
    }

    fn write_line<T: Serialize>(&mut self, record: &T) -> std::io::Result<()> {
        serde_json::to_writer(&mut self.out, record)?;
        self.out.write_all(b"\n")?;
        self.out.flush()?;
        self.lines += 1;
        Ok(())
    }
}

#[derive(Debug, Serialize)]
pub struct ActuatorEstimate<'a> {
    pub name: &'a str,
    pub channel: u8,
    pub gamma: f64,
    pub gamma_lo: f64,
    pub gamma_hi: f64,
    pub delta: f64,
    pub delta_lo: f64,
    pub delta_hi: f64,
    /// Effective output deviation the measurements attribute to this actuator (the detectors'
    /// statistic; none for the set filter).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub deviation: Option<f64>,
    /// The set filter: whether the gamma, the delta bounds are still the a priori box's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unexcited: Option<[bool; 2]>,
    /// The set filter: the bounds of the effective output less the healthy one at the
    /// actuator's recent command `command_ref`, `(gamma - 1) command_ref + delta`; absent
    /// where the data have not bounded it (the a priori box's extent).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output_bounds: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub command_ref: Option<f64>,
}

#[derive(Debug, Serialize)]
pub struct EstimateRecord<'a> {
    #[serde(serialize_with = "crate::diagnose::serialize_time")]
    pub t: f64,
    pub sysid: u8,
    pub filter: &'static str,
    pub actuators: Vec<ActuatorEstimate<'a>>,
}

impl<'a> EstimateRecord<'a> {
    pub fn new(
        t: f64,
        sysid: u8,
        filter: usize,
        est: &[AhcEstimate],
        profile: &'a Profile,
    ) -> Self {
        Self {
            t,
            sysid,
            filter: FILTER_NAMES[filter],
            actuators: est
                .iter()
                .zip(&profile.actuators)
                .map(|(e, a)| ActuatorEstimate {
                    name: &a.name,
                    channel: a.channel,
                    gamma: e.gamma,
                    gamma_lo: e.gamma_lo,
                    gamma_hi: e.gamma_hi,
                    delta: e.delta,
                    delta_lo: e.delta_lo,
                    delta_hi: e.delta_hi,
                    deviation: (filter < 2).then_some(e.deviation),
                    unexcited: (filter == 2).then_some(e.unexcited),
                    output_bounds: e.output_bounds,
                    command_ref: (filter == 2).then_some(e.command_ref),
                })
                .collect(),
        }
    }
}

#[derive(Debug, Serialize)]
pub struct ActuatorTruth<'a> {
    pub name: &'a str,
    pub channel: u8,
    pub gamma: f64,
    pub delta: f64,
}

#[derive(Debug, Serialize)]
pub struct NoiseInForce {
    /// Gyro noise std (rad/s) and a_z noise std (m/s²).
    pub gyro: f64,
    pub az: f64,
}

#[derive(Debug, Serialize)]
pub struct TruthRecord<'a> {
    #[serde(serialize_with = "crate::diagnose::serialize_time")]
    pub t: f64,
    pub actuators: Vec<ActuatorTruth<'a>>,
    pub noise: NoiseInForce,
}

impl<'a> TruthRecord<'a> {
    pub fn new(s: &VehicleSample, profile: &'a Profile, noise: NoiseInForce) -> Self {
        Self {
            t: s.t,
            actuators: profile
                .actuators
                .iter()
                .enumerate()
                .map(|(j, a)| ActuatorTruth {
                    name: &a.name,
                    channel: a.channel,
                    gamma: s.gamma[j],
                    delta: s.delta[j],
                })
                .collect(),
            noise,
        }
    }
}

/// Keep the first write error (later ones are usually its consequence); nothing is dropped
/// silently: the caller reports it at the end.
fn keep_first(slot: &mut Option<std::io::Error>, r: std::io::Result<()>) {
    if let (Err(e), None) = (r, &*slot) {
        *slot = Some(e);
    }
}

/// Where a run's results go: the decision, estimate and truth JSON lines, the decisions
/// echoed for the user, the `--plot` traces and the planner alerts. One for `replay`,
/// `monitor` and `calibrate` (any number of vehicles) and for `sim` and `eval`. The first
/// write error is kept and reported at the end (nothing panics, nothing is silently dropped).
pub struct Outputs {
    pub decisions: Option<JsonlFile>,
    pub estimates: Option<JsonlFile>,
    /// The simulator's truth, with the sensor noise in force (`sim --truth`).
    pub truth: Option<(JsonlFile, f64, f64)>,
    /// Write every k-th step's estimates (per vehicle).
    pub decimate: u64,
    steps: std::collections::BTreeMap<u8, u64>,
    /// Print decisions to stdout as they are made.
    pub echo: bool,
    /// With each printed decision, its reasons (`--explain`).
    pub explain: bool,
    pub error: Option<std::io::Error>,
    /// All decisions seen (for summaries and tests).
    pub seen: Vec<Decision>,
    /// Traces for `--plot`.
    pub plot: Option<crate::output::plot::PlotRecorder>,
    /// Planner alerts (`--alerts`): frames are queued here for the live loop to send.
    pub alerts: Option<crate::output::alerts::Alerts>,
}

impl Outputs {
    pub fn new(
        decisions: Option<&Path>,
        estimates: Option<&Path>,
        decimate: u64,
    ) -> std::io::Result<Self> {
        Ok(Self {
            decisions: decisions.map(JsonlWriter::create).transpose()?,
            estimates: estimates.map(JsonlWriter::create).transpose()?,
            truth: None,
            decimate: decimate.max(1),
            steps: Default::default(),
            echo: true,
            explain: false,
            error: None,
            seen: vec![],
            plot: None,
            alerts: None,
        })
    }

    /// Also write the truth file (`sim --truth`).
    pub fn with_truth(mut self, path: &Path, gyro: f64, az: f64) -> std::io::Result<Self> {
        self.truth = Some((JsonlWriter::create(path)?, gyro, az));
        Ok(self)
    }

    /// The run is over: every output it wrote nothing to is emptied (see the module note).
    /// Not called when a run stops on an error, so its files stay as they were.
    pub fn finish(&mut self) {
        let mut results = vec![];
        for w in [&mut self.decisions, &mut self.estimates]
            .into_iter()
            .flatten()
            .chain(self.truth.as_mut().map(|t| &mut t.0))
        {
            results.push(w.finish());
        }
        for r in results {
            self.keep(r);
        }
    }

    fn keep(&mut self, r: std::io::Result<()>) {
        let first = self.error.is_none() && r.is_err();
        keep_first(&mut self.error, r);
        // Say it at once (a full disk should not wait for the end of a live run; under the
        // dashboard it is said once the terminal is restored).
        if let (true, Some(e)) = (first, &self.error) {
            tracing::error!(
                "ahcmon: error writing JSON lines: {e}; the run goes on, the lines from now on are lost"
            );
        }
    }
}

/// One line for a person, in fixed columns: time, vehicle, actuator, event, class, the
/// MIT-UKF's gamma and delta with bounds, the alarming filter's statistic over its threshold,
/// the rule that decided, the filters that alarmed:
/// `t=  113.66 s  sysid 1    motor1 ch1    fault            unclassified  gamma 0.95 [0.93, 0.97]  delta +0.035 [+0.024, +0.045]  dev 0.123/0.070  F1  ESMF`.
/// With `explain`, the decision's reasons (its rule's words and numbers) follow on a second
/// line.
pub fn describe(d: &Decision, explain: bool) -> String {
    describe_with(d, true, explain)
}

/// `describe`, leaving out the system id where the reader knows the vehicle (a dashboard
/// showing one).
pub fn describe_with(d: &Decision, sysid: bool, explain: bool) -> String {
    let mut s = format!("t={:8.2} s", d.t);
    if sysid {
        s += &format!("  sysid {:<3}", d.sysid);
    }
    let who = match (&d.actuator, d.channel) {
        (Some(a), Some(c)) => format!("{a} ch{c}"),
        (Some(a), None) => a.clone(),
        (None, _) => String::new(),
    };
    s += &format!("  {who:<12}  {:<15}", d.event.as_str());
    s += &format!("  {:<12}", d.class.map_or("", short_class));
    if let (Some(g), Some(b)) = (d.gamma, d.gamma_bounds) {
        s += &format!("  gamma {g:.2} [{:.2}, {:.2}]", b[0], b[1]);
    }
    if let (Some(g), Some(b)) = (d.delta, d.delta_bounds) {
        s += &format!("  delta {g:+.3} [{:+.3}, {:+.3}]", b[0], b[1]);
    }
    s += &evidence(d);
    if let Some(r) = d.rule {
        s += &format!("  {r:?}");
    }
    if !d.filters.is_empty() {
        s += &format!("  {}", crate::output::filters_short(d));
    }
    if !d.also.is_empty() {
        s += &format!("  also {}", d.also.join(","));
    }
    let mut s = s.trim_end().to_string();
    if let Some(x) = d.detail.as_ref().filter(|_| explain) {
        s += &format!("\n             {x}");
    }
    s
}

/// The same columns narrower, for an 80-column dashboard: no delta, no filters, the time bare
/// (`  113.68  motor1 ch1    changed          loss          gamma 0.74 [0.68, 0.79]  K1`).
pub fn describe_narrow(d: &Decision, explain: bool) -> String {
    let who = match (&d.actuator, d.channel) {
        (Some(a), Some(c)) => format!("{a} ch{c}"),
        (Some(a), None) => a.clone(),
        (None, _) => String::new(),
    };
    let mut s = format!(
        "{:8.2}  {who:<12}  {:<15}  {:<12}",
        d.t,
        d.event.as_str(),
        d.class.map_or("", short_class)
    );
    if let (Some(g), Some(b)) = (d.gamma, d.gamma_bounds) {
        s += &format!("  gamma {g:.2} [{:.2}, {:.2}]", b[0], b[1]);
    }
    s += &evidence(d);
    if let Some(r) = d.rule {
        s += &format!("  {r:?}");
    }
    let mut s = s.trim_end().to_string();
    if let Some(x) = d.detail.as_ref().filter(|_| explain) {
        s += &format!("\n          {x}");
    }
    s
}

/// The numbers behind a filter alarm, `dev 0.081/0.050` (the statistic over its threshold):
/// a first decision's gamma and delta may still look healthy while the alarm stands.
fn evidence(d: &Decision) -> String {
    d.evidence.map_or(String::new(), |e| {
        let what = if e.statistic == "deviation" {
            "dev"
        } else {
            "gain"
        };
        format!("  {what} {:.3}/{:.3}", e.value, e.threshold)
    })
}

/// A class in one word, for a line (the JSON keeps the full name).
pub(crate) fn short_class(c: crate::diagnose::vehicle::FaultClass) -> &'static str {
    use crate::diagnose::vehicle::FaultClass;
    match c {
        FaultClass::LossOfEffectiveness => "loss",
        other => other.as_str(),
    }
}

impl Outputs {
    fn record(&mut self, d: &Decision) {
        if self.echo {
            use std::io::Write as _;
            // The echo is a convenience copy (the decisions file keeps every record): if the
            // terminal or pipe is gone, stop echoing rather than fail.
            if writeln!(
                crate::output::file::for_people(),
                "{}",
                describe(d, self.explain)
            )
            .is_err()
            {
                self.echo = false;
            }
        }
        if let Some(w) = self.decisions.as_mut() {
            let r = w.write(d);
            self.keep(r);
        }
        if let Some(p) = self.plot.as_mut() {
            p.mark(d);
        }
        if let Some(a) = self.alerts.as_mut() {
            a.on_decision(d);
        }
        self.seen.push(d.clone());
    }
}

impl Sink for Outputs {
    fn decision(&mut self, d: &Decision) {
        self.record(d);
    }

    fn estimates(&mut self, t: f64, sysid: u8, est: &[&[AhcEstimate]; 3], profile: &Profile) {
        if let Some(p) = self.plot.as_mut() {
            p.record(t, sysid, est, profile);
        }
        if let Some(a) = self.alerts.as_mut() {
            a.on_estimates(t, sysid, est, profile);
        }
        let k = self.steps.entry(sysid).or_insert(0);
        *k += 1;
        if !(*k - 1).is_multiple_of(self.decimate) {
            return;
        }
        if let Some(w) = self.estimates.as_mut() {
            let mut r = Ok(());
            for (f, e) in est.iter().enumerate() {
                r = r.and(w.write(&EstimateRecord::new(t, sysid, f, e, profile)));
            }
            self.keep(r);
        }
    }

    fn message(&mut self, sysid: u8, text: &str) {
        // A note says its severity in its first word; the level follows it, so that `-q`
        // and RUST_LOG filter the pipeline's notes as any other diagnostics.
        if text.starts_with("error:") {
            tracing::error!(target: "ahcmon::pipeline", "sysid {sysid}: {text}");
        } else if text.starts_with("warning:") {
            tracing::warn!(target: "ahcmon::pipeline", "sysid {sysid}: {text}");
        } else {
            tracing::info!(target: "ahcmon::pipeline", "sysid {sysid}: {text}");
        }
    }

    fn truth(&mut self, s: &VehicleSample, profile: &Profile) {
        if let Some((w, gyro, az)) = self.truth.as_mut() {
            let noise = NoiseInForce {
                gyro: *gyro,
                az: *az,
            };
            let r = w.write(&TruthRecord::new(s, profile, noise));
            self.keep(r);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnose::vehicle::Event;

    #[test]
    fn times_are_written_to_the_microsecond() {
        // 49980 ms read as 49980 * 1e-3, and sums of 20 ms steps, carry float noise.
        let t = 49980.0 * 1e-3;
        assert_ne!(t.to_string(), "49.98");
        let d = Decision::monitor(t, 1, Event::LinkLost, "no frame for 2 s");
        let mut w = JsonlWriter::new(Vec::new());
        w.write(&d).unwrap();
        let line = String::from_utf8(w.out.clone()).unwrap();
        assert!(line.starts_with(r#"{"t":49.98,"#), "{line}");
        let p = Profile::resolve("quad-x").unwrap();
        let est = [AhcEstimate::default(); 4];
        let mut w = JsonlWriter::new(Vec::new());
        w.write(&EstimateRecord::new(0.1 + 0.2, 1, 0, &est, &p))
            .unwrap();
        let line = String::from_utf8(w.out.clone()).unwrap();
        assert!(line.starts_with(r#"{"t":0.3,"#), "{line}");
    }
}
