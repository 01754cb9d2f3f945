//! The dashboard's chart: the selected actuator's gamma and delta over the last 30 s, each
//! drawn filter's estimate and bounds, the healthy value and the decisions.

use super::panels::DRAWN;
use super::{History, UiState};
use crate::diagnose::vehicle::{Decision, Event};
use crate::estimate::vehicle::{AhcEstimate, FILTER_NAMES};
use crate::monitor::Monitor;
use ratatui::Frame;
use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::Span;
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType};

/// A line's points split where it is not drawn.
type Runs = Vec<Vec<(f64, f64)>>;

/// The colour of a decision's mark on the chart: a fault's red, its end's green, a statement's
/// yellow.
pub fn mark_colour(e: Event) -> Color {
    match e {
        Event::Fault | Event::Changed => Color::Red,
        Event::Cleared | Event::SuspectCleared => Color::Green,
        _ => Color::Yellow,
    }
}

/// The colour of the healthy value's line on the chart.
pub const HEALTHY_COLOUR: Color = Color::Gray;

/// The selected actuator's gamma and delta over the last 30 s: each drawn filter's estimate
/// and bounds as lines, the healthy value as a line, and the decisions on the actuator as
/// vertical marks.
pub(super) fn chart(
    f: &mut Frame,
    area: Rect,
    monitor: &Monitor,
    history: &History,
    decisions: &[Decision],
    sysid: Option<u8>,
    ui: &UiState,
) {
    let Some(s) = sysid else {
        f.render_widget(
            Block::default().borders(Borders::ALL).title(" chart "),
            area,
        );
        return;
    };
    let name = monitor
        .pipelines
        .get(&s)
        .and_then(|p| p.profile())
        .and_then(|p| p.actuators.get(ui.actuator))
        .map_or("-".to_string(), |a| a.name.clone());
    let series = history.series.get(&(s, ui.actuator));
    let halves = Layout::default()
        .direction(Direction::Horizontal)
        .constraints([Constraint::Percentage(50), Constraint::Percentage(50)])
        .split(area);
    for (k, (what, healthy)) in [("gamma", 1.0), ("delta", 0.0)].into_iter().enumerate() {
        let pick = |e: &AhcEstimate| -> (f64, f64, f64) {
            if k == 0 {
                (e.gamma, e.gamma_lo, e.gamma_hi)
            } else {
                (e.delta, e.delta_lo, e.delta_hi)
            }
        };
        // Each drawn filter's estimate.
        let mut lines: [Vec<(f64, f64)>; 2] = Default::default();
        // Each drawn filter's bounds as runs of excited samples (a line must not join them
        // across a stretch where the bound is still the a priori box): [filter][lo, hi][run].
        let mut runs: [[Runs; 2]; 2] = Default::default();
        let (mut t0, mut t1) = (0.0, 1.0);
        if let Some(series) = series {
            if let (Some(a), Some(b)) = (series.front(), series.back()) {
                t0 = a.0;
                t1 = b.0.max(a.0 + 1.0);
            }
            for (t, est) in series {
                for fi in 0..2 {
                    let (v, lo, hi) = pick(&est[fi]);
                    lines[fi].push((*t, v));
                    // A set filter's bound still at the a priori box is not drawn.
                    for (b, v) in [lo, hi].into_iter().enumerate() {
                        let r = &mut runs[fi][b];
                        if est[fi].unexcited[k] {
                            if r.last().is_some_and(|run| !run.is_empty()) {
                                r.push(vec![]);
                            }
                        } else {
                            match r.last_mut() {
                                Some(run) => run.push((*t, v)),
                                None => r.push(vec![(*t, v)]),
                            }
                        }
                    }
                }
            }
        }
        // Scale on the estimates and the healthy value; bounds are clipped.
        let (mut lo, mut hi): (f64, f64) = (healthy - 0.2, healthy + 0.2);
        for l in &lines {
            for (_, v) in l.iter() {
                if v.is_finite() {
                    lo = lo.min(*v);
                    hi = hi.max(*v);
                }
            }
        }
        let pad = 0.1 * (hi - lo);
        let (lo, hi) = (lo - pad, hi + pad);
        for l in lines.iter_mut().chain(runs.iter_mut().flatten().flatten()) {
            for p in l.iter_mut() {
                p.1 = p.1.clamp(lo, hi);
            }
        }
        let healthy_line = [(t0, healthy), (t1, healthy)];
        // Each decision on this actuator in view, as a vertical mark.
        let marks: Vec<([(f64, f64); 2], Color)> = decisions
            .iter()
            .filter(|d| d.sysid == s && d.actuator.as_deref() == Some(name.as_str()))
            .filter(|d| (t0..=t1).contains(&d.t))
            .map(|d| ([(d.t, lo), (d.t, hi)], mark_colour(d.event)))
            .collect();
        let colours = [Color::Cyan, Color::Magenta];
        let mut sets = vec![];
        for fi in 0..2 {
            // Bounds as thin lines in the filter's colour, dimmed.
            for run in runs[fi].iter().flatten() {
                sets.push(
                    Dataset::default()
                        .marker(Marker::Braille)
                        .graph_type(GraphType::Line)
                        .style(Style::default().fg(colours[fi]).add_modifier(Modifier::DIM))
                        .data(run),
                );
            }
            sets.push(
                Dataset::default()
                    .name(FILTER_NAMES[DRAWN[fi]])
                    .marker(Marker::Braille)
                    .graph_type(GraphType::Line)
                    .style(Style::default().fg(colours[fi]))
                    .data(&lines[fi]),
            );
        }
        // The healthy value and the decisions over the estimates: a cell shows the last series
        // drawn in it, and these are what the estimates are read against.
        sets.push(
            Dataset::default()
                .name("healthy")
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::default().fg(HEALTHY_COLOUR))
                .data(&healthy_line),
        );
        for (line, colour) in &marks {
            sets.push(
                Dataset::default()
                    .marker(Marker::Braille)
                    .graph_type(GraphType::Line)
                    .style(Style::default().fg(*colour))
                    .data(line),
            );
        }
        let title = format!(
            " {name} {what}{} ",
            if ui.frozen { " (frozen)" } else { "" }
        );
        let chart = Chart::new(sets)
            .block(Block::default().borders(Borders::ALL).title(title))
            .x_axis(Axis::default().bounds([t0, t1]).labels(vec![
                Span::raw(format!("{t0:.0} s")),
                Span::raw(format!("{t1:.0} s")),
            ]))
            .y_axis(Axis::default().bounds([lo, hi]).labels(vec![
                Span::raw(format!("{lo:.2}")),
                Span::raw(format!("{hi:.2}")),
            ]));
        f.render_widget(chart, halves[k]);
    }
}
