//! A plot per scenario like the paper's figures: truth, each filter's estimate and bounds, for
//! gamma and delta, as plain SVG (no plotting dependency for two line charts).

use crate::eval::{Run, Trace};
use std::fmt::Write;

const COLORS: [&str; 5] = ["#1f77b4", "#2ca02c", "#d62728", "#9467bd", "#ff7f0e"];
const W: f64 = 900.0;
const PANEL_H: f64 = 260.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 150.0;
const TOP: f64 = 40.0;

/// (estimate, lower bound, upper bound) of one coefficient in a trace.
type Pick = fn(&Trace) -> (&[f64], &[f64], &[f64]);

struct Panel<'a> {
    title: &'a str,
    pick: Pick,
}

/// Text for an SVG text node: names come from files and profiles (`R&D.tlog`).
fn xml(s: &str) -> std::borrow::Cow<'_, str> {
    // Control characters are not XML 1.0 text.
    let s = match super::printable(s) {
        std::borrow::Cow::Borrowed(s) => s,
        std::borrow::Cow::Owned(o) => return std::borrow::Cow::Owned(xml(&o).into_owned()),
    };
    if !s.contains(['&', '<', '>', '"', '\'']) {
        return std::borrow::Cow::Borrowed(s);
    }
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    std::borrow::Cow::Owned(out)
}

fn finite_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.05).max(1e-6);
    (lo - pad, hi + pad)
}

fn polyline(
    out: &mut String,
    t: &[f64],
    v: &[f64],
    map: &dyn Fn(f64, f64) -> (f64, f64),
    style: &str,
) {
    // A non-finite value (a set filter's bound still at its a priori box) breaks the line.
    let mut segments = vec![String::new()];
    for (x, y) in t.iter().zip(v) {
        if y.is_finite() {
            let (px, py) = map(*x, *y);
            if let Some(last) = segments.last_mut() {
                let _ = write!(last, "{px:.1},{py:.1} ");
            }
        } else if segments.last().is_some_and(|s| !s.is_empty()) {
            segments.push(String::new());
        }
    }
    if segments.len() > 1 && segments.last().is_some_and(|s| s.is_empty()) {
        segments.pop();
    }
    for pts in segments {
        let _ = writeln!(out, r#"<polyline fill="none" {style} points="{pts}"/>"#);
    }
}

pub fn render(run: &Run) -> String {
    let panels = [
        Panel {
            title: "gamma_lon",
            pick: |t| (&t.gamma, &t.gamma_lo, &t.gamma_hi),
        },
        Panel {
            title: "delta_lon (rad)",
            pick: |t| (&t.delta, &t.delta_lo, &t.delta_hi),
        },
    ];
    let height = TOP + panels.len() as f64 * (PANEL_H + 50.0);
    let mut out = String::new();
    let _ = writeln!(
        out,
        r#"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{height}" viewBox="0 0 {W} {height}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<text x="{LEFT}" y="22" font-size="15">{} (seed {})</text>"#,
        xml(&run.scenario),
        run.seed
    );
    let t_end = run.truth.t.last().copied().unwrap_or(1.0);
    for (pi, panel) in panels.iter().enumerate() {
        let y0 = TOP + pi as f64 * (PANEL_H + 50.0);
        let (truth_v, _, _) = (panel.pick)(&run.truth);
        // Scale on truth and estimates; bounds may be far wider early on, so clip them.
        let (lo, hi) = finite_range(
            truth_v.iter().copied().chain(
                run.filters
                    .iter()
                    .flat_map(|f| (panel.pick)(&f.trace).0.iter().copied()),
            ),
        );
        let span = hi - lo;
        let (lo, hi) = (lo - 0.5 * span, hi + 0.5 * span);
        let plot_w = W - LEFT - RIGHT;
        let map = move |t: f64, v: f64| {
            let x = LEFT + t / t_end * plot_w;
            let y = y0 + PANEL_H - (v.clamp(lo, hi) - lo) / (hi - lo) * PANEL_H;
            (x, y)
        };
        let _ = writeln!(
            out,
            r##"<rect x="{LEFT}" y="{y0}" width="{plot_w}" height="{PANEL_H}" fill="none" stroke="#888"/>
<text x="{LEFT}" y="{}" >{}</text>"##,
            y0 - 6.0,
            panel.title
        );
        for k in 0..=4 {
            let v = lo + (hi - lo) * k as f64 / 4.0;
            let (_, y) = map(0.0, v);
            let _ = writeln!(
                out,
                r##"<line x1="{LEFT}" x2="{}" y1="{y:.1}" y2="{y:.1}" stroke="#eee"/><text x="{}" y="{:.1}" text-anchor="end">{v:.3}</text>"##,
                LEFT + plot_w,
                LEFT - 4.0,
                y + 4.0
            );
        }
        for k in 0..=8 {
            let t = t_end * k as f64 / 8.0;
            let (x, _) = map(t, lo);
            let _ = writeln!(
                out,
                r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle">{t:.0} s</text>"#,
                y0 + PANEL_H + 16.0
            );
        }
        for (fi, f) in run.filters.iter().enumerate() {
            let c = COLORS[fi % COLORS.len()];
            let (est, blo, bhi) = (panel.pick)(&f.trace);
            let bound_style =
                format!(r#"stroke="{c}" stroke-width="0.8" stroke-dasharray="4 3" opacity="0.6""#);
            polyline(&mut out, &f.trace.t, blo, &map, &bound_style);
            polyline(&mut out, &f.trace.t, bhi, &map, &bound_style);
            polyline(
                &mut out,
                &f.trace.t,
                est,
                &map,
                &format!(r#"stroke="{c}" stroke-width="1.5""#),
            );
        }
        polyline(
            &mut out,
            &run.truth.t,
            truth_v,
            &map,
            r#"stroke="black" stroke-width="2""#,
        );
        // Legend.
        let lx = LEFT + plot_w + 12.0;
        let _ = writeln!(
            out,
            r#"<text x="{lx}" y="{}" font-weight="bold">truth</text>"#,
            y0 + 14.0
        );
        for (fi, f) in run.filters.iter().enumerate() {
            let _ = writeln!(
                out,
                r#"<text x="{lx}" y="{}" fill="{}">{} (dashed: bounds)</text>"#,
                y0 + 32.0 + 16.0 * fi as f64,
                COLORS[fi % COLORS.len()],
                f.filter
            );
        }
    }
    out.push_str("</svg>\n");
    out
}

/// Keeps a bounded trace per vehicle, actuator and filter for `replay --plot`: when a trace
/// reaches its cap every other point is dropped and the stride doubles, so memory stays flat
/// in the length of the log.
#[derive(Debug, Default)]
pub struct PlotRecorder {
    /// (sysid, actuator name, channel) → [MIT-UKF, set filter] traces: the probable and the
    /// guaranteed bounds.
    pub traces: Vec<((u8, String, u8), [Trace; 2])>,
    steps: std::collections::BTreeMap<u8, u64>,
    stride: std::collections::BTreeMap<u8, u64>,
    /// Decisions to mark: (sysid, t, actuator, label).
    pub marks: Vec<(u8, f64, Option<String>, String)>,
}

const PLOT_POINTS: usize = 4000;

/// The filters drawn (`FILTER_NAMES` indices): the MIT-UKF's probable bounds and the set
/// filter's guaranteed ones. The MIT-ESMF is a detector whose vehicle bounds are its a priori
/// box; its estimates are in the estimates JSONL.
const PLOTTED: [usize; 2] = [0, 2];

fn halve(v: &mut Vec<f64>) {
    let mut k = 0;
    v.retain(|_| {
        k += 1;
        k % 2 == 1
    });
}

impl PlotRecorder {
    pub fn record(
        &mut self,
        t: f64,
        sysid: u8,
        est: &[&[crate::estimate::vehicle::AhcEstimate]; 3],
        profile: &crate::telemetry::Profile,
    ) {
        let step = self.steps.entry(sysid).or_insert(0);
        let stride = self.stride.entry(sysid).or_insert(1);
        *step += 1;
        if !(*step - 1).is_multiple_of(*stride) {
            return;
        }
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
            for (f, tr) in self.traces[idx].1.iter_mut().enumerate() {
                let e = est[PLOTTED[f]][j];
                // Bounds still at the a priori box are not drawn (the legend says so).
                let bounds = |unexcited: bool, lo: f64, hi: f64| {
                    if unexcited {
                        (f64::NAN, f64::NAN)
                    } else {
                        (lo, hi)
                    }
                };
                tr.push(
                    t,
                    e.gamma,
                    bounds(e.unexcited[0], e.gamma_lo, e.gamma_hi),
                    e.delta,
                    bounds(e.unexcited[1], e.delta_lo, e.delta_hi),
                );
                full |= tr.t.len() >= PLOT_POINTS;
            }
        }
        if full {
            *stride *= 2;
            for (k, traces) in self.traces.iter_mut() {
                if k.0 != sysid {
                    continue;
                }
                for tr in traces.iter_mut() {
                    for v in [
                        &mut tr.t,
                        &mut tr.gamma,
                        &mut tr.gamma_lo,
                        &mut tr.gamma_hi,
                        &mut tr.delta,
                        &mut tr.delta_lo,
                        &mut tr.delta_hi,
                    ] {
                        halve(v);
                    }
                }
            }
        }
    }

    pub fn mark(&mut self, d: &crate::diagnose::vehicle::Decision) {
        if matches!(d.event, crate::diagnose::vehicle::Event::ExcitationLow) {
            return;
        }
        let label = match d.class {
            Some(c) => format!("{} {}", d.event.as_str(), c.as_str()),
            None => d.event.as_str().to_string(),
        };
        self.marks.push((d.sysid, d.t, d.actuator.clone(), label));
    }

    /// One SVG: for every actuator a gamma panel and a delta panel with both filters'
    /// estimates and bounds; decisions as vertical lines on their actuator's panels (link
    /// events on all).
    pub fn render(&self, title: &str) -> String {
        let n = self.traces.len().max(1);
        let panel_h = 150.0;
        let height = TOP + 2.0 * n as f64 * (panel_h + 40.0);
        let mut out = String::new();
        let _ = writeln!(
            out,
            r#"<?xml version="1.0" encoding="UTF-8"?>
<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{height}" viewBox="0 0 {W} {height}" font-family="sans-serif" font-size="12">
<rect width="100%" height="100%" fill="white"/>
<text x="{LEFT}" y="22" font-size="15">{}</text>"#,
            xml(title)
        );
        if self.traces.is_empty() {
            let _ = writeln!(
                out,
                r#"<text x="{LEFT}" y="60">no estimates (no flight found)</text>"#
            );
        }
        let t0 = self
            .traces
            .iter()
            .filter_map(|(_, tr)| tr[0].t.first().copied())
            .fold(f64::INFINITY, f64::min);
        let t1 = self
            .traces
            .iter()
            .filter_map(|(_, tr)| tr[0].t.last().copied())
            .fold(f64::NEG_INFINITY, f64::max);
        let span_t = (t1 - t0).max(1e-3);
        let names = ["MIT-UKF (probable)", "set (guaranteed)"];
        let mut panel = 0;
        for ((sysid, name, channel), traces) in &self.traces {
            for (which, healthy) in [("gamma", 1.0), ("delta", 0.0)] {
                let y0 = TOP + panel as f64 * (panel_h + 40.0);
                panel += 1;
                let pick = |tr: &'_ Trace| -> (Vec<f64>, Vec<f64>, Vec<f64>) {
                    if which == "gamma" {
                        (tr.gamma.clone(), tr.gamma_lo.clone(), tr.gamma_hi.clone())
                    } else {
                        (tr.delta.clone(), tr.delta_lo.clone(), tr.delta_hi.clone())
                    }
                };
                // Scale on the estimates (bounds may be much wider; they are clipped).
                let (lo, hi) = finite_range(
                    traces
                        .iter()
                        .flat_map(|tr| pick(tr).0)
                        .chain(std::iter::once(healthy)),
                );
                let pad = 0.25 * (hi - lo);
                let (lo, hi) = (lo - pad, hi + pad);
                let plot_w = W - LEFT - RIGHT;
                let map = move |t: f64, v: f64| {
                    let x = LEFT + (t - t0) / span_t * plot_w;
                    let y = y0 + panel_h - (v.clamp(lo, hi) - lo) / (hi - lo) * panel_h;
                    (x, y)
                };
                let _ = writeln!(
                    out,
                    r##"<rect x="{LEFT}" y="{y0}" width="{plot_w}" height="{panel_h}" fill="none" stroke="#888"/>
<text x="{LEFT}" y="{}">sysid {sysid} · {} (ch {channel}) · {which}</text>"##,
                    y0 - 6.0,
                    xml(name)
                );
                for k in 0..=2 {
                    let v = lo + (hi - lo) * k as f64 / 2.0;
                    let (_, y) = map(t0, v);
                    let _ = writeln!(
                        out,
                        r##"<text x="{}" y="{:.1}" text-anchor="end">{v:.2}</text>"##,
                        LEFT - 4.0,
                        y + 4.0
                    );
                }
                let (_, yh) = map(t0, healthy);
                let _ = writeln!(
                    out,
                    r##"<line x1="{LEFT}" x2="{}" y1="{yh:.1}" y2="{yh:.1}" stroke="#aaa" stroke-dasharray="2 2"/>"##,
                    LEFT + plot_w
                );
                for k in 0..=8 {
                    let t = t0 + span_t * k as f64 / 8.0;
                    let (x, _) = map(t, lo);
                    let _ = writeln!(
                        out,
                        r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle">{t:.0} s</text>"#,
                        y0 + panel_h + 14.0
                    );
                }
                for (f, tr) in traces.iter().enumerate() {
                    let c = COLORS[f];
                    let (est, blo, bhi) = pick(tr);
                    let bound = format!(
                        r#"stroke="{c}" stroke-width="0.8" stroke-dasharray="4 3" opacity="0.6""#
                    );
                    polyline(&mut out, &tr.t, &blo, &map, &bound);
                    polyline(&mut out, &tr.t, &bhi, &map, &bound);
                    polyline(
                        &mut out,
                        &tr.t,
                        &est,
                        &map,
                        &format!(r#"stroke="{c}" stroke-width="1.4""#),
                    );
                }
                for (s, t, act, label) in &self.marks {
                    if s != sysid || act.as_deref().is_some_and(|a| a != name) {
                        continue;
                    }
                    let (x, _) = map(*t, lo);
                    let _ = writeln!(
                        out,
                        r##"<line x1="{x:.1}" x2="{x:.1}" y1="{y0}" y2="{}" stroke="#d62728" stroke-width="1"/><text x="{:.1}" y="{}" fill="#d62728" font-size="10">{}</text>"##,
                        y0 + panel_h,
                        x + 2.0,
                        y0 + 10.0,
                        xml(label)
                    );
                }
                let lx = LEFT + plot_w + 12.0;
                for (f, n) in names.iter().enumerate() {
                    let _ = writeln!(
                        out,
                        r#"<text x="{lx}" y="{}" fill="{}">{n}</text>"#,
                        y0 + 16.0 + 16.0 * f as f64,
                        COLORS[f]
                    );
                }
                let _ = writeln!(
                    out,
                    r##"<text x="{lx}" y="{}" fill="#666">dashed: bounds</text>"##,
                    y0 + 52.0
                );
                let _ = writeln!(
                    out,
                    r##"<text x="{lx}" y="{}" fill="#666" font-size="10">gaps: not excited</text>"##,
                    y0 + 66.0
                );
            }
        }
        out.push_str("</svg>\n");
        out
    }
}
