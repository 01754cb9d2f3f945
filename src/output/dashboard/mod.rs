//! The operator's dashboard (ratatui): per actuator gamma and delta from both filters with
//! their bounds as bars, the state in colour, a chart of the selected actuator, the decisions,
//! and a footer with the link's health. Rendering is a pure function of a snapshot, drawn at a
//! fixed rate by the caller, so tests render it into a `TestBackend`.

use crate::diagnose::vehicle::Decision;
use crate::estimate::vehicle::AhcEstimate;
use crate::model::MAX_ACTUATORS;
use crate::monitor::Monitor;
use crate::protocol::FrameCounters;
use ratatui::Frame;
use ratatui::layout::{Constraint, Direction, Layout};
use ratatui::text::Line;
use ratatui::widgets::{Paragraph, Wrap};
use std::collections::{BTreeMap, VecDeque};

mod chart;
mod panels;
use chart::chart;
pub use chart::{HEALTHY_COLOUR, mark_colour};
use panels::{actuator_table, decision_list, footer, header_spans, help, table_height};

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

impl UiState {
    /// Another vehicle: its first actuator; the same one (the only one) keeps the actuator.
    pub fn select_vehicle(&mut self, vehicle: usize) {
        if vehicle != self.vehicle {
            self.vehicle = vehicle;
            self.actuator = 0;
        }
    }
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
            let drawn = panels::DRAWN;
            for (j, (ukf, set)) in (est[drawn[0]][..l].iter())
                .zip(&est[drawn[1]][..l])
                .enumerate()
            {
                let s = self.series.entry((*sysid, j)).or_default();
                if s.back().is_some_and(|(last, _)| *last >= *t) {
                    continue;
                }
                s.push_back((*t, [*ukf, *set]));
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
    chart(f, rows[2], monitor, history, decisions, sysid, ui);
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
                name: crate::output::printable(link_name).into_owned(),
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
                    let n = monitor.pipelines.len().max(1);
                    self.ui.select_vehicle((self.ui.vehicle + 1) % n);
                }
                KeyCode::BackTab | KeyCode::Left => {
                    let n = monitor.pipelines.len().max(1);
                    self.ui.select_vehicle((self.ui.vehicle + n - 1) % n);
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
