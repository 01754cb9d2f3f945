//! Diagnostics on stderr through `tracing`: progress, warnings and the pipeline's stages.
//! Results (decisions, tables, summaries) are plain stdout, never logged.
//!
//! The level is INFO, DEBUG with `-v` (the pipeline's stages), TRACE with `-vv`, ERROR only
//! with `-q`; without either flag `RUST_LOG` (`debug`, `ahcmon::pipeline=trace,info`) sets
//! it. INFO, WARN and ERROR lines are their message as written (it says `warning:` or
//! `error:` itself); DEBUG and TRACE lines name their level and module.
//!
//! While the dashboard owns the terminal, lines are held (the first and the last
//! `KEPT_LINES`, the number left out between them) and written once it has restored the
//! terminal: nothing reaches the dashboard's screen, and nothing is lost unsaid.

use std::collections::VecDeque;
use std::io::Write;
use std::sync::Mutex;
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::filter::{LevelFilter, Targets};
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields, MakeWriter};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::registry::LookupSpan;
use tracing_subscriber::util::SubscriberInitExt;

/// How many of the first and of the last held lines are kept.
const KEPT_LINES: usize = 20;

/// Lines held while the dashboard is up; `None` when they go to stderr at once.
static HELD: Mutex<Option<Held>> = Mutex::new(None);

#[derive(Default)]
struct Held {
    first: Vec<String>,
    last: VecDeque<String>,
    skipped: u64,
}

impl Held {
    fn keep(&mut self, line: String) {
        if self.first.len() < KEPT_LINES {
            self.first.push(line);
            return;
        }
        self.last.push_back(line);
        if self.last.len() > KEPT_LINES {
            self.last.pop_front();
            self.skipped += 1;
        }
    }

    /// The lines to say: the first, how many were left out, the last.
    fn lines(self) -> Vec<String> {
        let mut out = self.first;
        if self.skipped > 0 {
            out.push(format!(
                "({} more lines like these, not repeated)\n",
                self.skipped
            ));
        }
        out.extend(self.last);
        out
    }
}

/// The filter: `-q` and `-v` win over `RUST_LOG`.
fn targets(verbose: u8, quiet: bool) -> Targets {
    let level = |l| Targets::new().with_default(l);
    if quiet {
        return level(LevelFilter::ERROR);
    }
    match verbose {
        0 => {}
        1 => return level(LevelFilter::DEBUG),
        _ => return level(LevelFilter::TRACE),
    }
    match std::env::var("RUST_LOG") {
        Ok(spec) if !spec.trim().is_empty() => match spec.parse::<Targets>() {
            Ok(t) => t,
            Err(e) => {
                eprintln!("ahcmon: RUST_LOG={spec}: {e}; logging at info");
                level(LevelFilter::INFO)
            }
        },
        _ => level(LevelFilter::INFO),
    }
}

/// Install the subscriber for this process.
pub fn init(verbose: u8, quiet: bool) {
    let fmt = tracing_subscriber::fmt::layer()
        .event_format(Plain)
        .with_writer(StderrOrHeld);
    // Fails only when a subscriber is already set (never in this binary).
    let _ = tracing_subscriber::registry()
        .with(fmt)
        .with(targets(verbose, quiet))
        .try_init();
}

/// Lines are held from now until the guard is dropped: declare it before the dashboard, so
/// that it drops after the dashboard has restored the terminal, on every way out.
#[must_use = "the lines are held only while the guard lives"]
pub struct HoldGuard(());

pub fn hold() -> HoldGuard {
    if let Ok(mut held) = HELD.lock() {
        held.get_or_insert_with(Held::default);
    }
    HoldGuard(())
}

impl Drop for HoldGuard {
    /// Write the held lines and stop holding.
    fn drop(&mut self) {
        let held = HELD.lock().ok().and_then(|mut h| h.take());
        if let Some(held) = held {
            let mut err = std::io::stderr().lock();
            for line in held.lines() {
                let _ = err.write_all(line.as_bytes());
            }
        }
    }
}

/// Whether INFO lines are shown (progress bars follow them: `-q` silences both).
pub fn progress_enabled() -> bool {
    tracing::enabled!(Level::INFO)
}

/// The line format (see the module's documentation).
struct Plain;

impl<S, N> FormatEvent<S, N> for Plain
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &FmtContext<'_, S, N>,
        mut w: Writer<'_>,
        event: &Event<'_>,
    ) -> std::fmt::Result {
        let meta = event.metadata();
        // More verbose than INFO.
        if *meta.level() > Level::INFO {
            write!(
                w,
                "{} {}: ",
                meta.level().as_str().to_lowercase(),
                meta.target()
            )?;
        }
        ctx.field_format().format_fields(w.by_ref(), event)?;
        writeln!(w)
    }
}

/// One writer per line: the line goes to stderr, or to the held lines.
struct StderrOrHeld;

struct Line(Vec<u8>);

impl Write for Line {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Drop for Line {
    fn drop(&mut self) {
        let text = String::from_utf8_lossy(&self.0);
        let line = ahcmon::output::printable(&text);
        if let Ok(mut held) = HELD.lock()
            && let Some(held) = held.as_mut()
        {
            held.keep(line.into_owned());
            return;
        }
        let _ = std::io::stderr().lock().write_all(line.as_bytes());
    }
}

impl<'a> MakeWriter<'a> for StderrOrHeld {
    type Writer = Line;
    fn make_writer(&'a self) -> Line {
        Line(Vec::with_capacity(128))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Under the dashboard a flapping peer's notes are kept first and last, the rest counted.
    #[test]
    fn held_lines_keep_the_first_and_the_last() {
        let mut h = Held::default();
        for k in 0..1000 {
            h.keep(format!("note {k}\n"));
        }
        let said = h.lines();
        assert_eq!(said.len(), 2 * KEPT_LINES + 1, "{said:?}");
        assert_eq!(said[0], "note 0\n");
        assert_eq!(
            said[KEPT_LINES],
            "(960 more lines like these, not repeated)\n"
        );
        assert_eq!(said.last().map(String::as_str), Some("note 999\n"));
        let mut few = Held::default();
        few.keep("only\n".into());
        assert_eq!(few.lines(), vec!["only\n".to_string()]);
    }
}
