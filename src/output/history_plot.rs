//! `history --plot FILE.svg|png`: each series' gain over its flights, one panel per airframe ×
//! actuator. A panel shows each flight's median gamma with its median bounds (a bar), the
//! fitted line over the last window carried on to the horizon, the healthy gain (1) and the
//! loss gain (dashed), and the first alarm (a red line and its flight). Series with an alarm
//! come first, then by falling slope; at most [`MAX_PANELS`] are drawn and the rest counted.

use super::plot::{nice_step, tick_label};
use crate::history::{HistoryRule, Series};
use std::fmt::Write;

pub const MAX_PANELS: usize = 48;
const WIDTH: f64 = 960.0;
const COLUMNS: usize = 2;
const PANEL_H: f64 = 190.0;
const TOP: f64 = 56.0;
const MARGIN: (f64, f64, f64, f64) = (48.0, 16.0, 26.0, 30.0); // left, right, top, bottom

fn esc(s: &str) -> String {
    s.chars()
        .filter(|c| !c.is_control())
        .collect::<String>()
        .replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The order panels are drawn in: alarms first (earliest alarm first), then the steepest
/// falling slope.
fn drawn(series: &[Series]) -> Vec<&Series> {
    let mut v: Vec<&Series> = series.iter().collect();
    v.sort_by(|a, b| {
        let key = |s: &Series| {
            (
                s.alarm.is_none(),
                s.alarm.unwrap_or(0),
                s.trend.map_or(f64::INFINITY, |t| t.slope),
            )
        };
        let (ka, kb) = (key(a), key(b));
        (ka.0, ka.1).cmp(&(kb.0, kb.1)).then(ka.2.total_cmp(&kb.2))
    });
    v.truncate(MAX_PANELS);
    v
}

/// The SVG document.
pub fn render(series: &[Series], rule: &HistoryRule, title: &str) -> String {
    let panels = drawn(series);
    let rows = panels.len().div_ceil(COLUMNS).max(1);
    let height = TOP + rows as f64 * PANEL_H + 10.0;
    let mut out = String::new();
    let _ = write!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height}" viewBox="0 0 {WIDTH} {height}" font-family="sans-serif" font-size="11"><rect width="100%" height="100%" fill="white"/>"#
    );
    let alarms = series.iter().filter(|s| s.alarm.is_some()).count();
    let _ = write!(
        out,
        r##"<text x="12" y="20" font-size="14">{}</text><text x="12" y="40" fill="#444">{} series, {alarms} with an alarm (slope below Student's t at p {} and gamma {} within {} flights, over the last {}){}. Bars: median bounds; blue: the fitted line; dashed: the loss gain.</text>"##,
        esc(title),
        series.len(),
        rule.false_alarm,
        rule.loss_gamma,
        rule.horizon,
        rule.window,
        if series.len() > panels.len() {
            format!("; {} not drawn", series.len() - panels.len())
        } else {
            String::new()
        }
    );
    let panel_w = WIDTH / COLUMNS as f64;
    for (k, s) in panels.iter().enumerate() {
        let x0 = (k % COLUMNS) as f64 * panel_w;
        let y0 = TOP + (k / COLUMNS) as f64 * PANEL_H;
        panel(&mut out, s, rule, x0, y0, panel_w);
    }
    out.push_str("</svg>\n");
    out
}

fn panel(out: &mut String, s: &Series, rule: &HistoryRule, x0: f64, y0: f64, w: f64) {
    let (ml, mr, mt, mb) = MARGIN;
    let (left, right) = (x0 + ml, x0 + w - mr);
    let (top, bottom) = (y0 + mt, y0 + PANEL_H - mb);
    let n = s.flights.len();
    // Flights 1..=n, and the horizon ahead when the line is drawn.
    let ahead = if s.trend.is_some() {
        rule.horizon.min(20.0)
    } else {
        0.0
    };
    let (f_lo, f_hi) = (0.5, n as f64 + 0.5 + ahead);
    let finite = |v: f64| v.is_finite().then_some(v);
    let values = s
        .flights
        .iter()
        .flat_map(|f| [f.point.gamma, f.point.lo, f.point.hi])
        .filter_map(finite)
        .chain([rule.loss_gamma, 1.0]);
    let (mut g_lo, mut g_hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let pad = ((g_hi - g_lo) * 0.08).max(0.02);
    g_lo -= pad;
    g_hi += pad;
    let x = |f: f64| left + (f - f_lo) / (f_hi - f_lo) * (right - left);
    let y = |g: f64| bottom - (g.clamp(g_lo, g_hi) - g_lo) / (g_hi - g_lo) * (bottom - top);
    let _ = write!(
        out,
        r#"<text x="{left}" y="{}" font-size="12">{} {}{}</text>"#,
        top - 8.0,
        esc(&s.airframe),
        esc(&s.actuator),
        s.trend.map_or(String::new(), |t| format!(
            "  slope {:+.4} ± {:.4} / flight",
            t.slope, t.slope_se
        ))
    );
    let _ = write!(
        out,
        r##"<rect x="{left}" y="{top}" width="{}" height="{}" fill="none" stroke="#888"/>"##,
        right - left,
        bottom - top
    );
    let step = nice_step(g_hi - g_lo, 4);
    let mut v = (g_lo / step).ceil() * step;
    while v <= g_hi {
        let _ = write!(
            out,
            r##"<line x1="{left}" x2="{right}" y1="{0:.1}" y2="{0:.1}" stroke="#eee"/><text x="{1}" y="{2:.1}" text-anchor="end" fill="#444">{3}</text>"##,
            y(v),
            left - 4.0,
            y(v) + 4.0,
            tick_label(v, step)
        );
        v += step;
    }
    let fstep = nice_step(f_hi - f_lo, 8).max(1.0);
    let mut f = fstep;
    while f <= f_hi {
        let _ = write!(
            out,
            r##"<text x="{:.1}" y="{}" text-anchor="middle" fill="#444">{f}</text>"##,
            x(f),
            bottom + 14.0
        );
        f += fstep;
    }
    let _ = write!(
        out,
        r##"<text x="{right}" y="{}" text-anchor="end" fill="#444">flight</text>"##,
        bottom + 26.0
    );
    for (g, style) in [
        (1.0, r##"stroke="#2a2""##),
        (rule.loss_gamma, r##"stroke="#c22" stroke-dasharray="5 3""##),
    ] {
        let _ = write!(
            out,
            r#"<line x1="{left}" x2="{right}" y1="{0:.1}" y2="{0:.1}" {style}/>"#,
            y(g)
        );
    }
    for (k, fl) in s.flights.iter().enumerate() {
        let fx = x(k as f64 + 1.0);
        if let (Some(lo), Some(hi)) = (finite(fl.point.lo), finite(fl.point.hi)) {
            let _ = write!(
                out,
                r##"<line x1="{fx:.1}" x2="{fx:.1}" y1="{:.1}" y2="{:.1}" stroke="#999"/>"##,
                y(lo),
                y(hi)
            );
        }
        let _ = write!(
            out,
            r##"<circle cx="{fx:.1}" cy="{:.1}" r="2.5" fill="#222"/>"##,
            y(fl.point.gamma)
        );
    }
    if let Some(t) = s.trend {
        // The line over the window fitted (index k is flight k + 1), carried to the horizon.
        let first = n.saturating_sub(rule.window) as f64;
        let last = (n - 1) as f64 + ahead;
        let _ = write!(
            out,
            r##"<line x1="{:.1}" x2="{:.1}" y1="{:.1}" y2="{:.1}" stroke="#26c" stroke-width="1.5"/>"##,
            x(first + 1.0),
            x(last + 1.0),
            y(t.intercept + t.slope * first),
            y(t.intercept + t.slope * last)
        );
    }
    if let Some(k) = s.alarm {
        let ax = x(k as f64 + 1.0);
        let _ = write!(
            out,
            r##"<line x1="{ax:.1}" x2="{ax:.1}" y1="{top}" y2="{bottom}" stroke="#c22" stroke-width="1.5"/><text x="{:.1}" y="{}" fill="#c22">alarm at flight {}</text>"##,
            ax + 3.0,
            top + 12.0,
            k + 1
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::history::{Flight, Point, series};
    use serde_json::json;

    fn falling(airframe: &str, per_flight: f64, n: usize) -> Vec<serde_json::Value> {
        (0..n)
            .map(|k| {
                let g = 1.0 - per_flight * k as f64 + if k % 2 == 0 { 0.002 } else { -0.002 };
                json!({"airframe": airframe, "actuator": "motor2", "sysid": 1,
                    "file": format!("{airframe}-{k:02}.tlog"), "start_unix_us": k as u64,
                    "mit_ukf": {"gamma": g, "gamma_lo": g - 0.02, "gamma_hi": g + 0.02}})
            })
            .collect()
    }

    #[test]
    fn alarmed_series_come_first_and_the_document_is_well_formed() {
        let rule = HistoryRule::default();
        let mut rows = falling("healthy", 0.0, 12);
        rows.extend(falling("worn", 0.015, 12));
        let all = series(&rows, &rule);
        assert!(
            all.iter().any(|s| s.alarm.is_some()),
            "the worn motor alarms"
        );
        let order = drawn(&all);
        assert_eq!(order[0].airframe, "worn");
        let svg = render(&all, &rule, "fleet <&> history");
        assert!(svg.contains("alarm at flight"));
        assert!(svg.contains("fleet &lt;&amp;&gt; history"));
        let tree = resvg::usvg::Tree::from_str(&svg, &resvg::usvg::Options::default());
        assert!(tree.is_ok(), "{:?}", tree.err());
    }

    #[test]
    fn a_series_without_bounds_or_trend_still_draws() {
        let s = Series {
            airframe: "a".into(),
            actuator: "m".into(),
            flights: vec![Flight {
                start: None,
                file: "f".into(),
                point: Point {
                    gamma: 0.9,
                    lo: f64::NAN,
                    hi: f64::NAN,
                },
            }],
            trend: None,
            alarm: None,
            mixed_start_times: false,
        };
        let svg = render(&[s], &HistoryRule::default(), "t");
        assert!(!svg.contains("NaN"), "{svg}");
    }
}
