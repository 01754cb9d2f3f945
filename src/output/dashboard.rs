//! The operator's dashboard (ratatui): per actuator gamma and delta from both filters with
//! their bounds as bars, the state in colour, a chart of the selected actuator, the decisions,
//! and a footer with the link's health. Rendering is a pure function of a snapshot, drawn at a
//! fixed rate by the caller, so tests render it into a `TestBackend`.

use crate::diagnose::vehicle::{Decision, Event, FaultClass};
use crate::estimate::vehicle::{AhcEstimate, FILTER_NAMES};
use crate::model::MAX_ACTUATORS;
use crate::monitor::Monitor;
use crate::output::jsonl::describe_with;
use crate::protocol::FrameCounters;
use ratatui::Frame;
use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{
    Axis, Block, Borders, Chart, Clear, Dataset, GraphType, Paragraph, Row, Table, Wrap,
};
use std::collections::{BTreeMap, VecDeque};

/// What the operator selected and toggled.
#[derive(Debug, Clone, Default)]
pub struct UiState {
    pub vehicle: usize,
    pub actuator: usize,
    pub paused: bool,
    pub frozen: bool,
    pub help: bool,
    /// A line of context after the vehicle (the demo's script, in the vehicle's clock).
    pub note: Option<String>,
}

/// The link as the footer shows it.
#[derive(Debug, Clone, Default)]
pub struct LinkInfo {
    pub name: String,
    pub counters: FrameCounters,
    /// Frames per second over the last second.
    pub rate_hz: f64,
    /// Seconds since the last frame; `None` before the first.
    pub data_age_s: Option<f64>,
    /// The stream has ended, and what the footer says instead of a link state ("END OF LOG"
    /// for a replay, "END OF FLIGHT" for the demo); the dashboard stays until q.
    pub ended: Option<&'static str>,
    /// The selected vehicle's link is lost (or, with no vehicle selected, some vehicle's).
    pub lost: bool,
    /// Other vehicles whose links are lost.
    pub others_lost: Vec<u8>,
}

impl LinkInfo {
    /// The footer speaks of the selected vehicle's link (its age, lost or not); other vehicles
    /// whose links are lost are named. `last_frame_age_s`: since any frame (`None` before the
    /// first).
    pub fn set_vehicles(
        &mut self,
        monitor: &Monitor,
        ui: &UiState,
        last_frame_age_s: Option<f64>,
        vehicles: &VehicleLinks,
    ) {
        let selected = selected_sysid(monitor, ui);
        let (age, lost) = match selected.and_then(|s| vehicles.get(&s)) {
            Some(&(age, lost)) => (Some(age), lost),
            None => (last_frame_age_s, vehicles.values().any(|v| v.1)),
        };
        self.data_age_s = last_frame_age_s.and(age);
        self.lost = lost;
        self.others_lost = vehicles
            .iter()
            .filter(|(s, v)| v.1 && Some(**s) != selected)
            .map(|(s, _)| *s)
            .collect();
    }
}

/// Per vehicle (sysid): seconds since its last frame, and whether its link is lost.
pub type VehicleLinks = BTreeMap<u8, (f64, bool)>;

/// The vehicle the operator selected (Tab), of those with a pipeline.
fn selected_sysid(monitor: &Monitor, ui: &UiState) -> Option<u8> {
    let n = monitor.pipelines.len();
    monitor
        .pipelines
        .keys()
        .nth(ui.vehicle.min(n.saturating_sub(1)))
        .copied()
}

/// Time-stamped estimates of both filters for one actuator.
type Series = VecDeque<(f64, [AhcEstimate; 2])>;

/// Chart history: per (sysid, actuator) the last `window_s` of both filters' estimates.
#[derive(Debug, Default, Clone)]
pub struct History {
    pub window_s: f64,
    series: BTreeMap<(u8, usize), Series>,
    /// Per vehicle, its reboots when last sampled (a new boot's chart starts afresh), and the
    /// old boot's last estimate time, which the pipeline holds until the new boot estimates.
    boots: BTreeMap<u8, (u64, Option<f64>)>,
}

impl History {
    pub fn new(window_s: f64) -> Self {
        Self {
            window_s,
            series: BTreeMap::new(),
            boots: BTreeMap::new(),
        }
    }

    /// Take the pipelines' latest estimates (called at the redraw rate).
    pub fn sample(&mut self, monitor: &Monitor) {
        for (sysid, p) in &monitor.pipelines {
            let reboots = monitor
                .assembler
                .vehicles
                .get(sysid)
                .map_or(0, |v| v.counters.reboots);
            let last_t = p.last.as_ref().map(|(t, _)| *t);
            let boot = self.boots.entry(*sysid).or_insert((reboots, None));
            if boot.0 != reboots {
                *boot = (reboots, last_t);
                self.series.retain(|(s, _), _| s != sysid);
            }
            let (Some(profile), Some((t, est))) = (p.profile(), &p.last) else {
                continue;
            };
            if boot.1 == Some(*t) {
                continue;
            }
            let l = profile.actuators.len().min(MAX_ACTUATORS);
            for (j, (ukf, esmf)) in est[0][..l].iter().zip(&est[1][..l]).enumerate() {
                let s = self.series.entry((*sysid, j)).or_default();
                if s.back().is_some_and(|(last, _)| *last >= *t) {
                    continue;
                }
                s.push_back((*t, [*ukf, *esmf]));
                while s.front().is_some_and(|(t0, _)| t - t0 > self.window_s) {
                    s.pop_front();
                }
            }
        }
    }

    /// The times charted for one actuator of one vehicle.
    pub fn times(&self, sysid: u8, actuator: usize) -> impl Iterator<Item = f64> + '_ {
        self.series
            .get(&(sysid, actuator))
            .into_iter()
            .flat_map(|s| s.iter().map(|(t, _)| *t))
    }
}

/// The chart's history as the dashboard keeps it: recorded at every redraw, paused or
/// frozen too (so no hole is drawn as a flat line when it goes on), and shown as it stood
/// when frozen.
#[derive(Debug, Default)]
pub struct ChartHistory {
    pub live: History,
    frozen: Option<History>,
}

impl ChartHistory {
    pub fn new(window_s: f64) -> Self {
        Self {
            live: History::new(window_s),
            frozen: None,
        }
    }

    /// Record the pipelines' latest estimates; the history to draw.
    pub fn update(&mut self, monitor: &Monitor, frozen: bool) -> &History {
        self.live.sample(monitor);
        if !frozen {
            self.frozen = None;
        } else if self.frozen.is_none() {
            self.frozen = Some(self.live.clone());
        }
        self.frozen.as_ref().unwrap_or(&self.live)
    }
}

fn class_style(c: Option<FaultClass>) -> (String, Style) {
    match c {
        None => ("healthy".into(), Style::default().fg(Color::Green)),
        Some(FaultClass::Drift) => ("drift".into(), Style::default().fg(Color::Yellow)),
        Some(FaultClass::Unclassified) => (
            "output off".into(),
            Style::default().fg(Color::Red).add_modifier(Modifier::BOLD),
        ),
        Some(c) => (
            match c {
                FaultClass::LossOfEffectiveness => "LOE".into(),
                other => other.as_str().into(),
            },
            Style::default().fg(Color::Red).add_modifier(Modifier::BOLD),
        ),
    }
}

/// A bar of `width` cells over [lo_axis, hi_axis]: the bound as `─`, the healthy value as
/// `│`, the estimate as `●`.
fn bound_bar(e: f64, lo: f64, hi: f64, healthy: f64, axis: (f64, f64), width: usize) -> String {
    let cell = |v: f64| -> usize {
        let x = ((v - axis.0) / (axis.1 - axis.0)).clamp(0.0, 1.0);
        ((x * (width - 1) as f64).round() as usize).min(width - 1)
    };
    let mut bar = vec![' '; width];
    if lo.is_finite() && hi.is_finite() {
        for c in bar.iter_mut().take(cell(hi) + 1).skip(cell(lo)) {
            *c = '─';
        }
    }
    bar[cell(healthy)] = '│';
    if e.is_finite() {
        bar[cell(e)] = '●';
    }
    bar.into_iter().collect()
}

/// Draw the whole screen.
pub fn render(
    f: &mut Frame,
    monitor: &Monitor,
    decisions: &[Decision],
    history: &History,
    ui: &UiState,
    link: &LinkInfo,
) {
    let area = f.area();
    let sysids: Vec<u8> = monitor.pipelines.keys().copied().collect();
    let sysid = selected_sysid(monitor, ui);
    // On a short terminal the chart gives way first, then the decisions: the header, the
    // actuators and the footer stay (at 60x15 the table had no rows left).
    // The header wraps onto a second line where it does not fit (the demo's script was cut
    // at 100 columns) and the terminal has rows to spare.
    let header = Line::from(header_spans(monitor, &sysids, sysid, ui));
    let header_h: u16 = if header.width() > usize::from(area.width) && area.height >= 24 {
        2
    } else {
        1
    };
    let table = table_height(monitor, sysid);
    // Four rows inside: the newest decision wrapped on up to three, one for the one before.
    let list = if area.height >= 40 { 10 } else { 6 };
    let spare = area.height.saturating_sub(header_h + 1 + table);
    let (chart_min, list) = if spare >= list + 6 {
        (6, list)
    } else {
        (0, list.min(spare))
    };
    let rows = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(header_h),
            Constraint::Length(table),
            Constraint::Min(chart_min),
            Constraint::Length(list),
            Constraint::Length(1),
        ])
        .split(area);
    f.render_widget(Paragraph::new(header).wrap(Wrap { trim: false }), rows[0]);
    actuator_table(f, rows[1], monitor, decisions, sysid, ui);
    chart(f, rows[2], monitor, history, sysid, ui);
    decision_list(f, rows[3], decisions, sysid);
    let lost: u64 = monitor
        .assembler
        .vehicles
        .values()
        .map(|v| v.counters.lost_frames)
        .sum();
    footer(f, rows[4], link, lost, ui);
    if ui.help {
        help(f, area);
    }
}

fn table_height(monitor: &Monitor, sysid: Option<u8>) -> u16 {
    let n = sysid
        .and_then(|s| monitor.pipelines.get(&s))
        .and_then(|p| p.profile())
        .map_or(1, |p| p.actuators.len());
    (n as u16 + 3).min(MAX_ACTUATORS as u16 + 3)
}

fn header_spans(
    monitor: &Monitor,
    sysids: &[u8],
    sysid: Option<u8>,
    ui: &UiState,
) -> Vec<Span<'static>> {
    let mut spans = vec![Span::styled(
        " ahcmon ",
        Style::default().fg(Color::Black).bg(Color::Cyan),
    )];
    for s in sysids {
        let style = if Some(*s) == sysid {
            Style::default().add_modifier(Modifier::REVERSED)
        } else {
            Style::default()
        };
        let kind = monitor
            .assembler
            .vehicles
            .get(s)
            .and_then(|v| v.info.mav_type)
            .map_or("?".to_string(), |t| {
                format!("{t:?}")
                    .trim_start_matches("MAV_TYPE_")
                    .to_lowercase()
            });
        spans.push(Span::raw(" "));
        spans.push(Span::styled(format!("sysid {s} {kind}"), style));
    }
    if let Some(p) = sysid.and_then(|s| monitor.pipelines.get(&s)) {
        let name = p.profile().map_or("-", |p| p.name.as_str());
        spans.push(Span::raw(format!("  {name} · {}", p.stage_name())));
    } else {
        spans.push(Span::raw("  waiting for a vehicle"));
    }
    if ui.paused {
        spans.push(Span::styled("  PAUSED", Style::default().fg(Color::Yellow)));
    }
    if let Some(note) = &ui.note {
        spans.push(Span::styled(
            format!("  {note}"),
            Style::default().fg(Color::DarkGray),
        ));
    }
    spans
}

fn actuator_table(
    f: &mut Frame,
    area: Rect,
    monitor: &Monitor,
    decisions: &[Decision],
    sysid: Option<u8>,
    ui: &UiState,
) {
    let block = Block::default()
        .borders(Borders::ALL)
        .title(" actuators: gamma [0, 2] and delta [-1, 1], bound ─, healthy │, estimate ● ");
    let Some(p) = sysid.and_then(|s| monitor.pipelines.get(&s)) else {
        f.render_widget(Paragraph::new("no samples yet").block(block), area);
        return;
    };
    let (Some(profile), Some((_, est))) = (p.profile(), &p.last) else {
        let text = match p.calibration_progress() {
            Some((done, Some(target))) => format!(
                "calibrating on healthy flight: {done:.1} of {target:.0} s (the model's gains, damping and offsets are identified before any judgement)"
            ),
            Some((done, None)) => format!("calibrating on healthy flight: {done:.1} s so far"),
            None => format!("{} …", p.stage_name()),
        };
        f.render_widget(
            Paragraph::new(text).wrap(Wrap { trim: true }).block(block),
            area,
        );
        return;
    };
    // Bar width from the space left after the fixed columns.
    let bar = ((area.width as usize).saturating_sub(10 + 4 + 2 * 7 + 12 + 8) / 4).clamp(4, 30);
    let header = Row::new(vec![
        "actuator".to_string(),
        "ch".into(),
        format!("{:<w$}", "UKF gamma", w = bar + 6),
        format!("{:<w$}", "UKF delta", w = bar),
        format!("{:<w$}", "ESMF gamma", w = bar + 6),
        format!("{:<w$}", "ESMF delta", w = bar),
        "state".into(),
    ])
    .style(Style::default().add_modifier(Modifier::BOLD));
    let mut rows = vec![];
    for (j, a) in profile.actuators.iter().enumerate() {
        let (mut state, mut style) = class_style(p.active[j]);
        // No fault, but the last word on this actuator was that gain and bias cannot be told
        // apart: say so rather than "healthy".
        let last = decisions
            .iter()
            .rev()
            .find(|d| Some(d.sysid) == sysid && d.actuator.as_deref() == Some(a.name.as_str()));
        if p.active[j].is_none() && last.is_some_and(|d| d.event == Event::ExcitationLow) {
            state = "excitation low".into();
            style = Style::default().fg(Color::Yellow);
        }
        let cells = |e: &AhcEstimate| {
            (
                format!(
                    "{:5.2} {}",
                    e.gamma,
                    bound_bar(e.gamma, e.gamma_lo, e.gamma_hi, 1.0, (0.0, 2.0), bar)
                ),
                bound_bar(e.delta, e.delta_lo, e.delta_hi, 0.0, (-1.0, 1.0), bar),
            )
        };
        let (ug, ud) = cells(&est[0][j]);
        let (eg, ed) = cells(&est[1][j]);
        let mut row = Row::new(vec![
            a.name.clone(),
            a.channel.to_string(),
            ug,
            ud,
            eg,
            ed,
            state,
        ])
        .style(style);
        if j == ui.actuator {
            row = row.style(style.add_modifier(Modifier::REVERSED));
        }
        rows.push(row);
    }
    let widths = [
        Constraint::Length(9),
        Constraint::Length(3),
        Constraint::Length(bar as u16 + 6),
        Constraint::Length(bar as u16),
        Constraint::Length(bar as u16 + 6),
        Constraint::Length(bar as u16),
        Constraint::Min(8),
    ];
    f.render_widget(Table::new(rows, widths).header(header).block(block), area);
}

fn chart(
    f: &mut Frame,
    area: Rect,
    monitor: &Monitor,
    history: &History,
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
        let mut lines: Vec<Vec<(f64, f64)>> = vec![vec![]; 6];
        let (mut t0, mut t1) = (0.0, 1.0);
        if let Some(series) = series {
            if let (Some(a), Some(b)) = (series.front(), series.back()) {
                t0 = a.0;
                t1 = b.0.max(a.0 + 1.0);
            }
            for (t, est) in series {
                for fi in 0..2 {
                    let (v, lo, hi) = pick(&est[fi]);
                    lines[3 * fi].push((*t, v));
                    lines[3 * fi + 1].push((*t, lo));
                    lines[3 * fi + 2].push((*t, hi));
                }
            }
        }
        // Scale on the estimates and the healthy value; bounds are clipped.
        let (mut lo, mut hi): (f64, f64) = (healthy - 0.2, healthy + 0.2);
        for l in [&lines[0], &lines[3]] {
            for (_, v) in l.iter() {
                if v.is_finite() {
                    lo = lo.min(*v);
                    hi = hi.max(*v);
                }
            }
        }
        let pad = 0.1 * (hi - lo);
        let (lo, hi) = (lo - pad, hi + pad);
        for l in lines.iter_mut() {
            for p in l.iter_mut() {
                p.1 = p.1.clamp(lo, hi);
            }
        }
        let colours = [Color::Cyan, Color::Magenta];
        let mut sets = vec![];
        for fi in 0..2 {
            sets.push(
                Dataset::default()
                    .name(FILTER_NAMES[fi])
                    .marker(Marker::Braille)
                    .graph_type(GraphType::Line)
                    .style(Style::default().fg(colours[fi]))
                    .data(&lines[3 * fi]),
            );
            for b in 1..3 {
                sets.push(
                    Dataset::default()
                        .marker(Marker::Dot)
                        .style(Style::default().fg(colours[fi]).add_modifier(Modifier::DIM))
                        .data(&lines[3 * fi + b]),
                );
            }
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

fn decision_list(f: &mut Frame, area: Rect, decisions: &[Decision], sysid: Option<u8>) {
    let n = area.height.saturating_sub(2) as usize;
    let width = area.width.saturating_sub(2) as usize;
    // `excitation_low` only as the newest: the table's state column says it per actuator, and
    // a steady end of flight filled the panel with them, pushing the fault out of sight.
    let shown: Vec<(Style, Vec<String>)> = decisions
        .iter()
        .rev()
        .filter(|d| sysid.is_none_or(|s| d.sysid == s))
        .enumerate()
        .filter(|(k, d)| *k == 0 || d.event != Event::ExcitationLow)
        .map(|(_, d)| d)
        .take(n)
        .map(|d| {
            let style = match d.event {
                Event::Fault | Event::Changed => Style::default().fg(Color::Red),
                Event::Cleared | Event::LinkRestored => Style::default().fg(Color::Green),
                Event::LinkLost | Event::FilterReset => Style::default().fg(Color::Yellow),
                Event::ExcitationLow => Style::default().fg(Color::DarkGray),
            };
            // The vehicle shown is the selected one: its id on every line only cuts the rest.
            (style, wrap(&describe_with(d, sysid.is_none()), width))
        })
        .collect();
    let rows = decision_rows(&shown.iter().map(|(_, l)| l.len()).collect::<Vec<_>>(), n);
    let mut lines: Vec<Line> = vec![];
    for ((style, parts), rows) in shown.into_iter().zip(rows) {
        let cut = rows < parts.len();
        for (i, mut part) in parts.into_iter().take(rows).enumerate() {
            // A decision cut short says so.
            if cut && i + 1 == rows {
                part.truncate(part.trim_end().len());
                if part.chars().count() >= width {
                    part.pop();
                }
                part.push('…');
            }
            lines.push(Line::styled(part, style));
        }
    }
    f.render_widget(
        Paragraph::new(lines).block(
            Block::default()
                .borders(Borders::ALL)
                .title(" decisions (newest first) "),
        ),
        area,
    );
}

/// Rows for each decision (newest first, each `lens[k]` lines in full) in `n` rows: one each
/// at least, the newest in full as far as that allows (its numbers and detail are what the
/// operator reads now), then what rows are left to the older ones in turn.
fn decision_rows(lens: &[usize], n: usize) -> Vec<usize> {
    let m = lens.len().min(n);
    let mut rows = vec![1; m];
    let Some(newest) = lens.first().filter(|_| m > 0) else {
        return rows;
    };
    rows[0] = (*newest).min(n + 1 - m).max(1);
    let mut left = n - rows.iter().sum::<usize>();
    for (r, len) in rows.iter_mut().zip(lens).skip(1) {
        let more = (len.saturating_sub(1)).min(left);
        *r += more;
        left -= more;
    }
    rows
}

/// `text` in lines of at most `width` characters, broken at spaces (a word longer than a line
/// is cut); the continuation lines are indented by two.
fn wrap(text: &str, width: usize) -> Vec<String> {
    if width < 8 {
        return vec![text.to_string()];
    }
    let mut out: Vec<String> = vec![];
    let mut line = String::new();
    let mut len = 0;
    for word in text.split(' ') {
        let wlen = word.chars().count();
        if len > 0 && len + wlen > width {
            out.push(std::mem::take(&mut line));
            line.push_str("  ");
            len = 2;
            if word.is_empty() {
                continue;
            }
        }
        let mut rest: Vec<char> = word.chars().collect();
        while len + rest.len() > width {
            let cut = width - len;
            line.extend(&rest[..cut]);
            out.push(std::mem::take(&mut line));
            line.push_str("  ");
            len = 2;
            rest.drain(..cut);
        }
        line.extend(&rest);
        len += rest.len();
        if len < width {
            line.push(' ');
            len += 1;
        }
    }
    let last = line.trim_end();
    if !last.trim().is_empty() || out.is_empty() {
        out.push(last.to_string());
    }
    out
}

/// `lost`: the vehicles' frames their sequence numbers say never arrived.
fn footer(f: &mut Frame, area: Rect, link: &LinkInfo, lost: u64, ui: &UiState) {
    let state = if let Some(end) = link.ended {
        Span::styled(
            format!(" {end} "),
            Style::default().fg(Color::Black).bg(Color::Gray),
        )
    } else if link.data_age_s.is_none() {
        // Nothing has arrived yet: a wrong port or a silent sender, not a lost link.
        Span::styled(
            " NO DATA YET ",
            Style::default().fg(Color::Black).bg(Color::Yellow),
        )
    } else if link.lost {
        Span::styled(
            " LINK LOST ",
            Style::default().fg(Color::White).bg(Color::Red),
        )
    } else {
        Span::styled(
            " link ok ",
            Style::default().fg(Color::Black).bg(Color::Green),
        )
    };
    let c = &link.counters;
    let age = link
        .data_age_s
        .map_or("-".to_string(), |a| format!("{a:.1} s"));
    let others = if link.others_lost.is_empty() {
        String::new()
    } else {
        let ids: Vec<String> = link.others_lost.iter().map(u8::to_string).collect();
        format!(" · link lost: sysid {}", ids.join(", "))
    };
    // The drop counters only when they count something: all three always cut the line at
    // 110 columns.
    let drops: String = [
        ("bad crc", c.bad_crc),
        ("resync", c.resync),
        ("unknown", c.unknown_id),
    ]
    .iter()
    .filter(|(_, n)| *n > 0)
    .map(|(what, n)| format!(" · {what} {n}"))
    .collect();
    let text = format!(
        " {}{others} · {:.0} msg/s · age {age} · lost {lost}{drops}",
        link.name, link.rate_hz,
    );
    // The keys keep their place at the right; the counters give way on a narrow terminal.
    let keys = if ui.paused {
        " p resume "
    } else {
        " ?: help q: quit "
    };
    let parts = Layout::default()
        .direction(Direction::Horizontal)
        .constraints([Constraint::Min(0), Constraint::Length(keys.len() as u16)])
        .split(area);
    f.render_widget(
        Paragraph::new(Line::from(vec![state, Span::raw(text)])),
        parts[0],
    );
    f.render_widget(
        Paragraph::new(Span::styled(keys, Style::default().fg(Color::DarkGray))),
        parts[1],
    );
}

fn help(f: &mut Frame, area: Rect) {
    let w = 50.min(area.width);
    let h = 11.min(area.height);
    let r = Rect::new(
        area.x + (area.width - w) / 2,
        area.y + (area.height - h) / 2,
        w,
        h,
    );
    let text = vec![
        Line::raw("↑/↓      select actuator"),
        Line::raw("tab      next vehicle"),
        Line::raw("p        pause / resume the display"),
        Line::raw("f        freeze / unfreeze the chart"),
        Line::raw("?        this help"),
        Line::raw("q ctrl-c quit (the summary is printed)"),
        Line::raw(""),
        Line::raw("bars: bound ─, healthy │, estimate ●"),
    ];
    f.render_widget(Clear, r);
    f.render_widget(
        Paragraph::new(text).block(Block::default().borders(Borders::ALL).title(" keys ")),
        r,
    );
}

/// The dashboard on a real terminal: raw mode and the alternate screen while it lives, the
/// terminal restored on drop, on panic (hook) and on quit.
pub struct TerminalUi {
    terminal: ratatui::Terminal<ratatui::backend::CrosstermBackend<std::io::Stdout>>,
    pub history: ChartHistory,
    pub ui: UiState,
    pub link: LinkInfo,
    frames_window: VecDeque<(std::time::Instant, u64)>,
    /// Set by whoever feeds the stream when it is over (the demo's flight): then the footer
    /// says `ends_as`.
    ends_when: Option<(std::sync::Arc<std::sync::atomic::AtomicBool>, &'static str)>,
    /// The paused screen has been drawn (with its PAUSED mark).
    pause_drawn: bool,
}

fn restore_terminal() {
    use ratatui::crossterm::{execute, terminal};
    let _ = terminal::disable_raw_mode();
    let _ = execute!(
        std::io::stdout(),
        terminal::LeaveAlternateScreen,
        ratatui::crossterm::cursor::Show
    );
}

/// What a key press asks for.
pub enum KeyAction {
    None,
    Quit,
}

impl TerminalUi {
    pub fn start(link_name: &str) -> std::io::Result<Self> {
        use ratatui::crossterm::{execute, terminal};
        terminal::enable_raw_mode()?;
        execute!(std::io::stdout(), terminal::EnterAlternateScreen)?;
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            restore_terminal();
            previous(info);
        }));
        let backend = ratatui::backend::CrosstermBackend::new(std::io::stdout());
        let terminal = ratatui::Terminal::new(backend)?;
        Ok(Self {
            terminal,
            history: ChartHistory::new(30.0),
            ui: UiState::default(),
            link: LinkInfo {
                name: link_name.to_string(),
                ..Default::default()
            },
            frames_window: VecDeque::new(),
            ends_when: None,
            pause_drawn: false,
        })
    }

    /// The stream has ended: the footer says `label` ("END OF LOG") instead of a link state.
    pub fn mark_ended(&mut self, label: &'static str) {
        self.link.ended = Some(label);
    }

    /// Mark the stream ended as `label` once `flag` is set (by a task feeding it).
    pub fn end_when(
        &mut self,
        flag: std::sync::Arc<std::sync::atomic::AtomicBool>,
        label: &'static str,
    ) {
        self.ends_when = Some((flag, label));
    }

    /// Show `note` in the header (see [`UiState::note`]).
    pub fn set_note(&mut self, note: String) {
        self.ui.note = Some(note);
    }

    /// Read pending keys without waiting.
    pub fn keys(&mut self, monitor: &Monitor) -> KeyAction {
        use ratatui::crossterm::event::{
            self, Event as CEvent, KeyCode, KeyEventKind, KeyModifiers,
        };
        while event::poll(std::time::Duration::ZERO).unwrap_or(false) {
            let k = match event::read() {
                Ok(CEvent::Key(k)) => k,
                // A new size is drawn even while paused.
                Ok(CEvent::Resize(..)) => {
                    self.pause_drawn = false;
                    continue;
                }
                _ => continue,
            };
            if k.kind != KeyEventKind::Press {
                continue;
            }
            // Paused, the screen is drawn again for what a key changes (help, selection).
            self.pause_drawn = false;
            let actuators = monitor
                .pipelines
                .values()
                .nth(self.ui.vehicle)
                .and_then(|p| p.profile())
                .map_or(1, |p| p.actuators.len());
            match k.code {
                KeyCode::Char('q') => return KeyAction::Quit,
                KeyCode::Char('c') if k.modifiers.contains(KeyModifiers::CONTROL) => {
                    return KeyAction::Quit;
                }
                KeyCode::Char('p') => self.ui.paused = !self.ui.paused,
                KeyCode::Char('f') => self.ui.frozen = !self.ui.frozen,
                KeyCode::Char('?') => self.ui.help = !self.ui.help,
                KeyCode::Esc => self.ui.help = false,
                KeyCode::Down | KeyCode::Char('j') => {
                    self.ui.actuator = (self.ui.actuator + 1) % actuators.max(1);
                }
                KeyCode::Up | KeyCode::Char('k') => {
                    self.ui.actuator = (self.ui.actuator + actuators.max(1) - 1) % actuators.max(1);
                }
                KeyCode::Tab | KeyCode::Right => {
                    self.ui.vehicle = (self.ui.vehicle + 1) % monitor.pipelines.len().max(1);
                    self.ui.actuator = 0;
                }
                KeyCode::BackTab | KeyCode::Left => {
                    let n = monitor.pipelines.len().max(1);
                    self.ui.vehicle = (self.ui.vehicle + n - 1) % n;
                    self.ui.actuator = 0;
                }
                _ => {}
            }
        }
        KeyAction::None
    }

    /// Redraw from the current state (called at a fixed rate). `last_frame_age_s`: since any
    /// frame (`None` before the first); `vehicles`: each vehicle's link.
    pub fn draw(
        &mut self,
        monitor: &Monitor,
        decisions: &[Decision],
        counters: FrameCounters,
        last_frame_age_s: Option<f64>,
        vehicles: &VehicleLinks,
    ) -> std::io::Result<()> {
        let now = std::time::Instant::now();
        self.frames_window.push_back((now, counters.frames));
        while self
            .frames_window
            .front()
            .is_some_and(|(t, _)| now.duration_since(*t).as_secs_f64() > 1.0)
        {
            self.frames_window.pop_front();
        }
        if let (Some(a), Some(b)) = (self.frames_window.front(), self.frames_window.back()) {
            let dt = b.0.duration_since(a.0).as_secs_f64();
            if dt > 0.0 {
                self.link.rate_hz = (b.1 - a.1) as f64 / dt;
            }
        }
        self.link.counters = counters;
        self.link
            .set_vehicles(monitor, &self.ui, last_frame_age_s, vehicles);
        if let Some((flag, label)) = &self.ends_when
            && flag.load(std::sync::atomic::Ordering::Relaxed)
        {
            self.link.ended = Some(label);
        }
        // Recorded while paused too: the chart has no hole when it goes on.
        let history = self.history.update(monitor, self.ui.frozen);
        // Paused: the screen stands, once drawn with its PAUSED mark.
        if self.ui.paused && self.pause_drawn {
            return Ok(());
        }
        self.pause_drawn = self.ui.paused;
        let (ui, link) = (&self.ui, &self.link);
        self.terminal
            .draw(|f| render(f, monitor, decisions, history, ui, link))?;
        Ok(())
    }
}

impl Drop for TerminalUi {
    fn drop(&mut self) {
        restore_terminal();
    }
}

#[cfg(test)]
mod tests {
    use super::{decision_rows, wrap};

    #[test]
    fn decision_rows_fill_the_panel_newest_first() {
        // The newest in full, the older ones in full while rows are left.
        assert_eq!(decision_rows(&[3, 2, 2], 8), vec![3, 2, 2]);
        assert_eq!(decision_rows(&[3, 3, 3], 6), vec![3, 2, 1]);
        // Many decisions: one row each, the newest leaving one row for each other.
        assert_eq!(
            decision_rows(&[4, 3, 3, 3, 3, 3], 6),
            vec![1, 1, 1, 1, 1, 1]
        );
        assert_eq!(decision_rows(&[4, 3, 3], 6), vec![4, 1, 1]);
        assert_eq!(decision_rows(&[9], 4), vec![4]);
        assert_eq!(decision_rows(&[], 4), Vec::<usize>::new());
        assert_eq!(decision_rows(&[3, 2], 0), Vec::<usize>::new());
    }

    #[test]
    fn wrap_keeps_every_word_within_the_width() {
        let text = "t=   42.58 s  changed  swash2 (ch 2)  loss_of_effectiveness  gamma 0.80 [0.35, 1.24]  (since t=42.02 s the data fit a gain of 0.59 best, clearly; µs ≥ 20)";
        for width in [8, 13, 40, 97] {
            let lines = wrap(text, width);
            assert!(
                lines.iter().all(|l| l.chars().count() <= width),
                "{width}: {lines:?}"
            );
            assert!(lines[1..].iter().all(|l| l.starts_with("  ")), "{lines:?}");
            // Nothing lost: the same characters apart from the breaks and indents.
            let squeeze = |s: &str| s.split_whitespace().collect::<String>();
            assert_eq!(squeeze(&lines.concat()), squeeze(text), "{width}");
        }
        assert_eq!(wrap(text, 400), vec![text.to_string()]);
        assert_eq!(wrap("", 40), vec![String::new()]);
    }
}
