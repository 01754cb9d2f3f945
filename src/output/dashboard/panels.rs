//! The dashboard's panels: the header, the actuator table with both filters' bounds, the
//! chart, the decision list, the footer with the link's counters, the help overlay.

use super::{LinkInfo, UiState};
use crate::diagnose::vehicle::{Decision, Event, FaultClass, Health};
use crate::estimate::vehicle::AhcEstimate;
use crate::model::MAX_ACTUATORS;
use crate::monitor::Monitor;
use crate::output::jsonl::{describe_narrow, describe_with};
use ratatui::Frame;
use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Borders, Clear, Paragraph, Row, Table, Wrap};

pub(super) fn class_style(c: Option<FaultClass>) -> (String, Style) {
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
/// The filters the dashboard shows (`FILTER_NAMES` indices): the MIT-UKF's probable bounds and
/// the set filter's guaranteed ones.
pub(super) const DRAWN: [usize; 2] = [0, 2];

pub(super) fn bound_bar(
    e: f64,
    lo: f64,
    hi: f64,
    healthy: f64,
    axis: (f64, f64),
    width: usize,
) -> String {
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

pub(super) fn table_height(monitor: &Monitor, sysid: Option<u8>) -> u16 {
    let n = sysid
        .and_then(|s| monitor.pipelines.get(&s))
        .and_then(|p| p.profile())
        .map_or(1, |p| p.actuators.len());
    (n as u16 + 3).min(MAX_ACTUATORS as u16 + 3)
}

pub(super) fn header_spans(
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

pub(super) fn actuator_table(
    f: &mut Frame,
    area: Rect,
    monitor: &Monitor,
    decisions: &[Decision],
    sysid: Option<u8>,
    ui: &UiState,
) {
    let block = Block::default()
        .borders(Borders::ALL)
        // What each pair of columns is comes first: a narrow terminal cuts the title's end.
        .title(
            " actuators · UKF: probable bounds (3σ) · set: guaranteed bounds · gamma [0, 2], delta [-1, 1], output (γ-1)ū+δ at the recent command ū [-0.5, 0.5], bound ─, healthy │, estimate ● ",
        );
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
    // Bar width from the space left after the fixed columns (name 8, channel 3, two gamma
    // values 6, the state 13, seven gaps, the borders) for five bars: at 80 columns 7, which
    // holds every heading and "unexc.".
    let bar = ((area.width as usize).saturating_sub(8 + 3 + 2 * 6 + 13 + 7 + 2) / 5).clamp(6, 30);
    let unexcited = if bar >= 11 {
        "not excited"
    } else if bar >= 9 {
        "unexcited"
    } else {
        "unexc."
    };
    let header = Row::new(vec![
        "actuator".to_string(),
        "ch".into(),
        format!("{:<w$}", "UKF gamma", w = bar + 6),
        format!(
            "{:<w$}",
            if bar >= 9 { "UKF delta" } else { "UKF δ" },
            w = bar
        ),
        format!("{:<w$}", "set gamma", w = bar + 6),
        format!(
            "{:<w$}",
            if bar >= 9 { "set delta" } else { "set δ" },
            w = bar
        ),
        format!(
            "{:<w$}",
            if bar >= 10 { "set output" } else { "set out" },
            w = bar
        ),
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
        if p.active[j].is_none() && p.health[j] == Health::Suspect {
            state = "suspect".into();
            style = Style::default().fg(Color::Yellow);
        } else if p.health[j] == Health::CannotJudge {
            state = "cannot judge".into();
            style = Style::default().fg(Color::DarkGray);
        } else if p.active[j].is_none() && last.is_some_and(|d| d.event == Event::ExcitationLow) {
            // (Cut to fit 13 columns on a narrow terminal.)
            state = if bar >= 11 {
                "excitation low"
            } else {
                "excit. low"
            }
            .into();
            style = Style::default().fg(Color::Yellow);
        }
        // A set filter's bound that is still the a priori box says nothing: said instead of
        // drawn.
        let cells = |e: &AhcEstimate| {
            let gamma = if e.unexcited[0] {
                format!("{:<bar$}", unexcited)
            } else {
                bound_bar(e.gamma, e.gamma_lo, e.gamma_hi, 1.0, (0.0, 2.0), bar)
            };
            let delta = if e.unexcited[1] {
                format!("{:<bar$}", unexcited)
            } else {
                bound_bar(e.delta, e.delta_lo, e.delta_hi, 0.0, (-1.0, 1.0), bar)
            };
            (format!("{:5.2} {gamma}", e.gamma), delta)
        };
        let (ug, ud) = cells(&est[0][j]);
        let set = &est[2][j];
        let (eg, ed) = cells(set);
        // What the set bounds before it splits gain from bias: the output's departure from
        // the healthy one at the recent command (healthy 0).
        let output = match set.output_bounds {
            Some([lo, hi]) => bound_bar(
                set.output_at(set.command_ref),
                lo,
                hi,
                0.0,
                (-0.5, 0.5),
                bar,
            ),
            None => format!("{:<bar$}", unexcited),
        };
        let mut row = Row::new(vec![
            a.name.clone(),
            a.channel.to_string(),
            ug,
            ud,
            eg,
            ed,
            output,
            state,
        ])
        .style(style);
        if j == ui.actuator {
            row = row.style(style.add_modifier(Modifier::REVERSED));
        }
        rows.push(row);
    }
    let widths = [
        Constraint::Length(8),
        Constraint::Length(3),
        Constraint::Length(bar as u16 + 6),
        Constraint::Length(bar as u16),
        Constraint::Length(bar as u16 + 6),
        Constraint::Length(bar as u16),
        Constraint::Length(bar as u16),
        Constraint::Min(8),
    ];
    f.render_widget(Table::new(rows, widths).header(header).block(block), area);
}

pub(super) fn decision_list(f: &mut Frame, area: Rect, decisions: &[Decision], sysid: Option<u8>) {
    let n = area.height.saturating_sub(2) as usize;
    let width = area.width.saturating_sub(2) as usize;
    // Statements (`excitation_low`, `suspect`) only as the newest: the table's state column
    // says them per actuator, and a steady end of flight filled the panel with them, pushing
    // the fault out of sight.
    let shown: Vec<(Style, Vec<String>)> = decisions
        .iter()
        .rev()
        .filter(|d| sysid.is_none_or(|s| d.sysid == s))
        .enumerate()
        .filter(|(k, d)| *k == 0 || !d.event.is_statement())
        .map(|(_, d)| d)
        .take(n)
        .enumerate()
        .map(|(k, d)| {
            let style = match d.event {
                Event::Fault | Event::Changed => Style::default().fg(Color::Red),
                Event::Cleared | Event::LinkRestored | Event::SuspectCleared => {
                    Style::default().fg(Color::Green)
                }
                Event::LinkLost
                | Event::Contaminated
                | Event::FilterReset
                | Event::CannotEstimate
                | Event::CannotJudge
                | Event::Suspect => Style::default().fg(Color::Yellow),
                Event::ExcitationLow => Style::default().fg(Color::DarkGray),
            };
            // The vehicle shown is the selected one: its id on every line only cuts the rest.
            // The newest decision with its reasons, which the operator reads now.
            // Under the full line's width, the narrow one (no delta, no filters).
            let text = if width >= 130 {
                describe_with(d, sysid.is_none(), k == 0)
            } else {
                describe_narrow(d, k == 0)
            };
            let text = text.replace('\n', " ");
            (style, wrap(&text, width))
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
pub(super) fn decision_rows(lens: &[usize], n: usize) -> Vec<usize> {
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
pub(super) fn wrap(text: &str, width: usize) -> Vec<String> {
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
pub(super) fn footer(f: &mut Frame, area: Rect, link: &LinkInfo, lost: u64, ui: &UiState) {
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

pub(super) fn help(f: &mut Frame, area: Rect) {
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
