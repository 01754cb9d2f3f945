//! Reading the change test's store each step: searched while a change is under way (about
//! every `SEARCH_INTERVAL_S`), scanned every `SCAN_S` while nothing is.

use super::Diagnoser;
use crate::diagnose::change::ChangeKind;

/// While nothing is under way, the data are read this often (s): a quarter of `CLASS_MIN_S`,
/// the least a change lasts before the data alarm on it.
const SCAN_S: f64 = 0.25;
/// While a change is under way the store is searched about this often (s): a twentieth of
/// `CHANGE_MIN_S`. Between two searches the last reading stands, its stretch extended by the
/// samples stored since. At 50 Hz every sample is searched; at 400 Hz every fourth (the search
/// is most of a step's cost, and a 400 Hz vehicle took 4 % of a core).
const SEARCH_INTERVAL_S: f64 = 0.01;

impl Diagnoser {
    /// This step's reading of the store (`self.reading`, `self.whitened`).
    pub(super) fn read_store(&mut self, t: f64, warm: bool) {
        let under_way = warm && self.under_way();
        // While nothing is under way the data are still read, every `SCAN_S`: a change that
        // the filters' statistics do not reach (a surface's loss near trim) is theirs to find.
        let scan = warm && !under_way && t >= self.next_scan;
        if scan {
            self.next_scan = t + SCAN_S;
        }
        // Under way, between two searches the last reading stands, over the samples since.
        // (Half a period early: a search every 10 ms at 100 Hz despite rounding.)
        let search = !under_way || t >= self.next_search;
        let pushed = self.change.pushed();
        if !search && let Some(r) = &mut self.reading {
            let since = usize::try_from(pushed - self.search_pushed).unwrap_or(usize::MAX);
            r.samples = r.samples.saturating_add(since).min(self.change.len());
        }
        self.search_pushed = pushed;
        if search {
            self.next_search = if under_way {
                t + SEARCH_INTERVAL_S - 0.5 * self.dt
            } else {
                f64::NEG_INFINITY
            };
            // Until a fault is in force the whitened search reads changes (a step's weight is in
            // its first samples, before the wind has moved); a level that has stood longer than
            // the store looks to it like the wind, so a decided fault is followed by the plain one.
            let whitened_reading = if (under_way || scan) && !self.fault_in_force() {
                self.change.whitened_search()
            } else {
                None
            };
            self.reading_whitened = whitened_reading.is_some();
            self.reading_scanned = !under_way;
            self.reading = if under_way {
                whitened_reading.or_else(|| self.change.evaluate())
            } else {
                whitened_reading
            };
            self.whitened = self.reading.and_then(|r| {
                let gain_or_offset = matches!(r.kind, ChangeKind::Gain | ChangeKind::Offset);
                (!self.is_angle[r.actuator] && gain_or_offset)
                    .then(|| self.change.whitened_gain_or_offset(r.actuator, r.samples))
                    .flatten()
            });
        }
    }
}
