//! Where results go, behind one [`Sink`] trait: the decision and estimate JSON lines, the
//! planner alerts, the SVG plots, the dashboard, the summary and the eval table.

pub mod alerts;
pub mod dashboard;
pub mod file;
pub mod flights;
pub mod history_plot;
pub mod jsonl;
pub mod matrix;
pub mod parquet;
pub mod plot;
pub mod png;
pub mod summary;
pub mod summary_json;
pub mod svg;
pub mod table;

/// Text for a terminal or a file format: control characters (from file names, say, which
/// may hold an escape sequence) shown as `\u{1b}`, never written raw; line feeds and tabs stay.
pub fn printable(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.chars().any(|c| c.is_control() && c != '\n' && c != '\t') {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        if c.is_control() && c != '\n' && c != '\t' {
            out.push_str(&format!("\\u{{{:x}}}", c as u32));
        } else {
            out.push(c);
        }
    }
    std::borrow::Cow::Owned(out)
}

/// A decision's filters as the planner's alerts and the decision lines name them: `UKF+ESMF`.
pub fn filters_short(d: &crate::diagnose::vehicle::Decision) -> String {
    let by: Vec<&str> = d
        .filters
        .iter()
        .map(|f| match *f {
            "mit-ukf" => "UKF",
            "mit-esmf" => "ESMF",
            other => other,
        })
        .collect();
    by.join("+")
}

use crate::diagnose::vehicle::Decision;
use crate::estimate::vehicle::AhcEstimate;
use crate::sim::vehicle::VehicleSample;
use crate::telemetry::Profile;

/// What a run hands its results to: the pipeline (replay, the live monitor) and `eval` call
/// the same methods ([`crate::pipeline::Core::step`]). Every method but `decision` may be
/// ignored.
pub trait Sink {
    /// A decision: an actuator's fault, its change or end, or a monitor event (link lost or
    /// restored, a filter reset).
    fn decision(&mut self, d: &Decision);
    /// Every filter step: both filters' estimates per actuator.
    fn estimates(&mut self, _t: f64, _sysid: u8, _est: &[&[AhcEstimate]; 3], _profile: &Profile) {}
    /// Progress and warnings, one line each.
    fn message(&mut self, _sysid: u8, _text: &str) {}
    /// The simulator's truth of the sample about to be estimated (`sim`, `eval`).
    fn truth(&mut self, _s: &VehicleSample, _profile: &Profile) {}
}
