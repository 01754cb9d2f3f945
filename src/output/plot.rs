//! `replay --plot`: every actuator's gamma, delta and output at its recent command over the
//! log, both filters' estimates and bounds, the healthy value and the decisions, as SVG.
//!
//! Memory and file size stay flat in the length of the log: samples are kept as buckets (the
//! estimate's lowest and highest value, the lower bound's lowest, the upper bound's highest),
//! and when a vehicle's buckets reach [`BUCKETS`] neighbours merge and each bucket covers twice
//! the samples. Drawn, each column of [`COLUMN_PX`] pixels shows the envelope of the buckets in
//! it, so a spike of one sample in an hour is still there. The set filter is drawn by its
//! bounds alone, behind the MIT-UKF. Ticks fall on round values, time on
//! the vehicle's clock as m:ss; decision labels take the first of [`LANES`] rows where they
//! overlap no other, and a decision with no free row is a mark without a label (counted in the
//! legend).

use super::svg::xml;
use crate::diagnose::vehicle::{Decision, Event};
use crate::estimate::vehicle::AhcEstimate;
use std::fmt::Write;

const W: f64 = 960.0;
const LEFT: f64 = 60.0;
const RIGHT: f64 = 200.0;
const TOP: f64 = 44.0;
const PANEL_H: f64 = 150.0;
const PANEL_GAP: f64 = 44.0;
/// Buckets kept per series before neighbours merge.
pub const BUCKETS: usize = 2048;
/// Width of a drawn column (px).
pub const COLUMN_PX: f64 = 2.0;
/// Rows for decision labels at the top of a panel.
pub const LANES: usize = 3;
const LABEL_PX_PER_CHAR: f64 = 5.6;
const COLOURS: [&str; 2] = ["#1f77b4", "#d62728"];
const MARK: &str = "#444";
/// The filters drawn (`FILTER_NAMES` indices): the MIT-UKF's probable bounds and the set
/// filter's guaranteed ones. The MIT-ESMF is a detector whose vehicle bounds are its a priori
/// box; its estimates are in the estimates JSONL.
const PLOTTED: [usize; 2] = [0, 2];
const LEGEND: [(Option<&str>, &str); 2] = [
    (Some("MIT-UKF: estimate,"), "probable bounds (3σ)"),
    (None, "set filter: guaranteed bounds"),
];

/// A stretch of samples of one coefficient of one filter.
#[derive(Debug, Clone, Copy)]
struct Bucket {
    t0: f64,
    t1: f64,
    est_lo: f64,
    est_hi: f64,
    /// The bounds' outer envelope; NaN where the bound was the a priori box throughout.
    lo: f64,
    hi: f64,
}

impl Bucket {
    fn new(t: f64, est: f64, lo: f64, hi: f64) -> Self {
        Self {
            t0: t,
            t1: t,
            est_lo: est,
            est_hi: est,
            lo,
            hi,
        }
    }
    /// `f64::min`/`max` skip a NaN: a bucket's bound is NaN only when all its samples' are.
    fn merge(&mut self, o: &Bucket) {
        self.t0 = self.t0.min(o.t0);
        self.t1 = self.t1.max(o.t1);
        self.est_lo = self.est_lo.min(o.est_lo);
        self.est_hi = self.est_hi.max(o.est_hi);
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
    }
}

/// Per filter drawn, the buckets of gamma, delta and the output's departure from the healthy
/// one at the recent command, `(γ - 1) ū + δ`.
type Series = [[Vec<Bucket>; 3]; 2];

/// Each panel of an actuator: its title and the healthy value.
const PANELS: [(&str, f64); 3] = [
    ("gamma", 1.0),
    ("delta", 0.0),
    ("output (γ-1)ū+δ at the recent command ū", 0.0),
];

#[derive(Debug, Default)]
pub struct PlotRecorder {
    /// (sysid, actuator name, channel) → series.
    traces: Vec<((u8, String, u8), Series)>,
    /// Per vehicle: samples per bucket, and samples in its newest bucket.
    stride: std::collections::BTreeMap<u8, (u64, u64)>,
    /// Decisions to mark: (sysid, t, actuator, label).
    marks: Vec<(u8, f64, Option<String>, String)>,
}

impl PlotRecorder {
    pub fn record(
        &mut self,
        t: f64,
        sysid: u8,
        est: &[&[AhcEstimate]; 3],
        profile: &crate::telemetry::Profile,
    ) {
        let (stride, filled) = self.stride.entry(sysid).or_insert((1, 0));
        let new_bucket = *filled == 0;
        *filled = (*filled + 1) % *stride;
        let mut full = false;
        for (j, a) in profile.actuators.iter().enumerate() {
            let key = (sysid, a.name.clone(), a.channel);
            let idx = match self.traces.iter().position(|(k, _)| *k == key) {
                Some(i) => i,
                None => {
                    self.traces.push((key, Default::default()));
                    self.traces.len() - 1
                }
            };
            // Both filters' output at the set's recent command.
            let command = est[2][j].command_ref;
            for (f, series) in self.traces[idx].1.iter_mut().enumerate() {
                let e = est[PLOTTED[f]][j];
                let output = if PLOTTED[f] == 2 {
                    let [lo, hi] = e.output_bounds.unwrap_or([f64::NAN; 2]);
                    [e.output_at(command), lo, hi]
                } else {
                    e.output_probable(command)
                };
                for (c, buckets) in series.iter_mut().enumerate() {
                    let [v, lo, hi] = match c {
                        0 => [e.gamma, e.gamma_lo, e.gamma_hi],
                        1 => [e.delta, e.delta_lo, e.delta_hi],
                        _ => output,
                    };
                    // Bounds still at the a priori box are not drawn (the legend says so).
                    let (lo, hi) = if e.unexcited.get(c).copied().unwrap_or(false) {
                        (f64::NAN, f64::NAN)
                    } else {
                        (lo, hi)
                    };
                    let b = Bucket::new(t, v, lo, hi);
                    match buckets.last_mut() {
                        Some(last) if !new_bucket => last.merge(&b),
                        _ => buckets.push(b),
                    }
                    full |= buckets.len() >= BUCKETS;
                }
            }
        }
        if full {
            for (k, series) in self.traces.iter_mut() {
                if k.0 == sysid {
                    series.iter_mut().flatten().for_each(merge_pairs);
                }
            }
            let s = self.stride.entry(sysid).or_insert((1, 0));
            *s = (s.0 * 2, 0);
        }
    }

    /// Faults, their changes and ends, an actuator that cannot be judged and the monitor's
    /// events; not the statements excitation low, suspect and its end, which the decisions file
    /// keeps (on a long healthy log they hid the faults).
    pub fn mark(&mut self, d: &Decision) {
        if d.event.is_statement() && d.event != Event::CannotJudge {
            return;
        }
        let label = match d.class {
            Some(c) => format!("{} {}", d.event.as_str(), super::jsonl::short_class(c)),
            None => d.event.as_str().to_string(),
        };
        self.marks.push((d.sysid, d.t, d.actuator.clone(), label));
    }

    /// One SVG: for every actuator a gamma, a delta and an output panel.
    pub fn render(&self, title: &str) -> String {
        let n = self.traces.len().max(1);
        let height = TOP + (PANELS.len() * n) as f64 * (PANEL_H + PANEL_GAP);
        let mut out = String::new();
        // The title cut to the canvas.
        let room = ((W - LEFT) / 7.5) as usize;
        let title: String = if title.chars().count() > room {
            title
                .chars()
                .take(room.saturating_sub(1))
                .chain(['…'])
                .collect()
        } else {
            title.to_string()
        };
        let _ = writeln!(
            out,
            r#"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{height}" viewBox="0 0 {W} {height}" font-family="sans-serif" font-size="11">
<rect width="100%" height="100%" fill="white"/>
<text x="{LEFT}" y="22" font-size="14">{}</text>"#,
            xml(&title)
        );
        if self.traces.is_empty() {
            let _ = writeln!(
                out,
                r#"<text x="{LEFT}" y="60">no estimates (no flight found)</text>"#
            );
        }
        let all = self
            .traces
            .iter()
            .flat_map(|(_, s)| s.iter().flatten().flatten());
        let t0 = all.clone().map(|b| b.t0).fold(f64::INFINITY, f64::min);
        let t1 = all.map(|b| b.t1).fold(f64::NEG_INFINITY, f64::max);
        let span = (t1 - t0).max(1e-3);
        let mut panel = 0;
        for ((sysid, name, channel), series) in &self.traces {
            for (c, (which, healthy)) in PANELS.into_iter().enumerate() {
                let y0 = TOP + panel as f64 * (PANEL_H + PANEL_GAP);
                panel += 1;
                let frame = Frame::new(y0, t0, span, series, c, healthy);
                let _ = writeln!(
                    out,
                    r##"<rect x="{LEFT}" y="{y0}" width="{}" height="{PANEL_H}" fill="none" stroke="#888"/>
<text x="{LEFT}" y="{}">sysid {sysid} · {} (ch {channel}) · {which}</text>"##,
                    frame.plot_w,
                    y0 - 6.0,
                    xml(name)
                );
                frame.axes(&mut out, healthy);
                // The set filter behind, and only its bounds: its centre is no estimate, only
                // the middle of what is possible.
                for (f, s) in series.iter().enumerate().rev() {
                    frame.envelope(&mut out, &s[c], COLOURS[f], f == 0);
                }
                let hidden = frame.marks(&mut out, &self.marks, *sysid, name);
                legend(&mut out, y0, hidden);
            }
        }
        out.push_str("</svg>\n");
        out
    }
}

/// Neighbouring buckets merged: half as many, each twice as long.
fn merge_pairs(buckets: &mut Vec<Bucket>) {
    let merged: Vec<Bucket> = buckets
        .chunks(2)
        .map(|pair| {
            let mut b = pair[0];
            if let Some(o) = pair.get(1) {
                b.merge(o);
            }
            b
        })
        .collect();
    *buckets = merged;
}

/// A tick step of 1, 2 or 5 times a power of ten giving at most `max` intervals over `span`.
pub fn nice_step(span: f64, max: usize) -> f64 {
    let raw = (span / max as f64).max(1e-12);
    let mag = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|k| k * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag)
}

/// A time step (s) of a clock's round values giving at most `max` intervals over `span`.
pub fn time_step(span: f64, max: usize) -> f64 {
    const STEPS: [f64; 14] = [
        1.0, 2.0, 5.0, 10.0, 15.0, 30.0, 60.0, 120.0, 300.0, 600.0, 900.0, 1800.0, 3600.0, 7200.0,
    ];
    STEPS
        .iter()
        .copied()
        .find(|s| span / s <= max as f64)
        .unwrap_or_else(|| nice_step(span, max))
}

/// The vehicle's clock as m:ss (h:mm:ss from an hour).
pub fn clock(t: f64) -> String {
    let s = t.round().max(0.0) as u64;
    if s >= 3600 {
        format!("{}:{:02}:{:02}", s / 3600, s / 60 % 60, s % 60)
    } else {
        format!("{}:{:02}", s / 60, s % 60)
    }
}

/// A tick value with the decimals its step needs, never "-0".
pub fn tick_label(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let scale = 10f64.powi(decimals as i32);
    let v = (v * scale).round() / scale;
    // (-0.0 == 0.0: a value that rounds to zero prints without its sign.)
    let v = if v == 0.0 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

/// One panel's coordinates.
struct Frame {
    y0: f64,
    t0: f64,
    span: f64,
    lo: f64,
    hi: f64,
    plot_w: f64,
}

impl Frame {
    /// Scaled on the estimates and the healthy value (bounds may be much wider: clipped).
    fn new(y0: f64, t0: f64, span: f64, series: &Series, c: usize, healthy: f64) -> Self {
        let (mut lo, mut hi) = (healthy, healthy);
        for b in series.iter().flat_map(|s| s[c].iter()) {
            for v in [b.est_lo, b.est_hi] {
                if v.is_finite() {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
        let pad = ((hi - lo) * 0.2).max(0.05);
        Self {
            y0,
            t0,
            span,
            lo: lo - pad,
            hi: hi + pad,
            plot_w: W - LEFT - RIGHT,
        }
    }
    fn x(&self, t: f64) -> f64 {
        LEFT + (t - self.t0) / self.span * self.plot_w
    }
    fn y(&self, v: f64) -> f64 {
        self.y0 + PANEL_H - (v.clamp(self.lo, self.hi) - self.lo) / (self.hi - self.lo) * PANEL_H
    }

    fn axes(&self, out: &mut String, healthy: f64) {
        let step = nice_step(self.hi - self.lo, 4);
        let mut v = (self.lo / step).ceil() * step;
        while v <= self.hi {
            let y = self.y(v);
            let _ = writeln!(
                out,
                r##"<line x1="{LEFT}" x2="{:.1}" y1="{y:.1}" y2="{y:.1}" stroke="#eee"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
                LEFT + self.plot_w,
                LEFT - 4.0,
                y + 4.0,
                tick_label(v, step)
            );
            v += step;
        }
        let yh = self.y(healthy);
        let _ = writeln!(
            out,
            r##"<line x1="{LEFT}" x2="{:.1}" y1="{yh:.1}" y2="{yh:.1}" stroke="#666" stroke-dasharray="1 3"/>"##,
            LEFT + self.plot_w
        );
        let step = time_step(self.span, 8);
        let mut t = (self.t0 / step).ceil() * step;
        while t <= self.t0 + self.span {
            let x = self.x(t);
            let _ = writeln!(
                out,
                r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
                self.y0 + PANEL_H + 14.0,
                clock(t)
            );
            t += step;
        }
    }

    /// One filter's series: per column the estimate's range, the lower bound's lowest and
    /// the upper bound's highest; a column the bounds were not excited in breaks their line.
    fn envelope(&self, out: &mut String, buckets: &[Bucket], colour: &str, centre: bool) {
        let columns = (self.plot_w / COLUMN_PX).ceil() as usize;
        let mut cols: Vec<Option<Bucket>> = vec![None; columns.max(1)];
        for b in buckets {
            let mid = 0.5 * (b.t0 + b.t1);
            let k = (((mid - self.t0) / self.span * columns as f64) as usize).min(columns - 1);
            match &mut cols[k] {
                Some(c) => c.merge(b),
                slot => *slot = Some(*b),
            }
        }
        let mut est = String::new();
        let mut bounds = [vec![String::new()], vec![String::new()]];
        for (k, c) in cols.iter().enumerate() {
            let Some(c) = c else { continue };
            let x = LEFT + (k as f64 + 0.5) * COLUMN_PX;
            if centre && c.est_lo.is_finite() && c.est_hi.is_finite() {
                let (a, b) = (self.y(c.est_lo), self.y(c.est_hi));
                if (a - b).abs() < 0.05 {
                    let _ = write!(est, "{x:.1},{a:.1} ");
                } else {
                    let _ = write!(est, "{x:.1},{a:.1} {x:.1},{b:.1} ");
                }
            }
            for (line, v) in bounds.iter_mut().zip([c.lo, c.hi]) {
                if v.is_finite() {
                    if let Some(l) = line.last_mut() {
                        let _ = write!(l, "{x:.1},{:.1} ", self.y(v));
                    }
                } else if line.last().is_some_and(|l| !l.is_empty()) {
                    line.push(String::new());
                }
            }
        }
        for pts in bounds.iter().flatten().filter(|p| !p.is_empty()) {
            let _ = writeln!(
                out,
                r#"<polyline fill="none" stroke="{colour}" stroke-width="0.8" stroke-dasharray="4 3" points="{pts}"/>"#
            );
        }
        if !est.is_empty() {
            let _ = writeln!(
                out,
                r#"<polyline fill="none" stroke="{colour}" stroke-width="1.3" points="{est}"/>"#
            );
        }
    }

    /// The decisions on this actuator (and the vehicle's own, link events) as vertical lines,
    /// labelled in the first free lane. Returns how many went unlabelled.
    fn marks(
        &self,
        out: &mut String,
        marks: &[(u8, f64, Option<String>, String)],
        sysid: u8,
        name: &str,
    ) -> usize {
        let mut lane_end = [f64::NEG_INFINITY; LANES];
        let mut hidden = 0;
        let mut mine: Vec<&(u8, f64, Option<String>, String)> = marks
            .iter()
            .filter(|(s, _, a, _)| *s == sysid && a.as_deref().is_none_or(|a| a == name))
            .collect();
        mine.sort_by(|a, b| a.1.total_cmp(&b.1));
        for (_, t, _, label) in mine {
            let x = self.x(*t);
            let _ = writeln!(
                out,
                r##"<line x1="{x:.1}" x2="{x:.1}" y1="{}" y2="{}" stroke="{MARK}" stroke-width="0.8"/>"##,
                self.y0,
                self.y0 + PANEL_H
            );
            let width = label.chars().count() as f64 * LABEL_PX_PER_CHAR;
            // A label runs right of its mark, or left of it near the right edge.
            let (start, anchor) = if x + 2.0 + width <= LEFT + self.plot_w {
                (x + 2.0, "start")
            } else {
                (x - 2.0 - width, "end")
            };
            let Some(lane) = (0..LANES).find(|&l| lane_end[l] < start) else {
                hidden += 1;
                continue;
            };
            lane_end[lane] = start + width + 4.0;
            let tx = if anchor == "start" { start } else { x - 2.0 };
            let _ = writeln!(
                out,
                r##"<text x="{tx:.1}" y="{:.1}" fill="{MARK}" font-size="10" text-anchor="{anchor}">{}</text>"##,
                self.y0 + 11.0 + 11.0 * lane as f64,
                xml(label)
            );
        }
        hidden
    }
}

fn legend(out: &mut String, y0: f64, hidden: usize) {
    let lx = W - RIGHT + 12.0;
    let mut y = y0 + 14.0;
    for (f, (a, b)) in LEGEND.iter().enumerate() {
        let c = COLOURS[f];
        if let Some(a) = a {
            let _ = writeln!(
                out,
                r#"<line x1="{lx}" x2="{}" y1="{:.1}" y2="{:.1}" stroke="{c}" stroke-width="1.3"/><text x="{}" y="{y:.1}" fill="{c}">{a}</text>"#,
                lx + 14.0,
                y - 4.0,
                y - 4.0,
                lx + 18.0
            );
            y += 13.0;
        }
        let _ = writeln!(
            out,
            r#"<line x1="{lx}" x2="{}" y1="{:.1}" y2="{:.1}" stroke="{c}" stroke-dasharray="4 3"/><text x="{}" y="{y:.1}" fill="{c}">{b}</text>"#,
            lx + 14.0,
            y - 4.0,
            y - 4.0,
            lx + 18.0
        );
        y += 17.0;
    }
    for text in [
        "dotted: healthy value".to_string(),
        "grey lines: faults, their ends".to_string(),
        "bound gaps: not excited".to_string(),
    ]
    .into_iter()
    .chain((hidden > 0).then(|| format!("{hidden} decisions unlabelled")))
    {
        let _ = writeln!(
            out,
            r##"<text x="{lx}" y="{y:.1}" fill="#555" font-size="10">{text}</text>"##
        );
        y += 13.0;
    }
}

#[cfg(test)]
#[path = "plot_tests.rs"]
mod tests;
