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
pub(super) fn xml(s: &str) -> std::borrow::Cow<'_, str> {
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
