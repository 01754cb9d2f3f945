//! `ahcmon eval --matrix`: the cases of [`ahcmon::eval::matrix`] on every core, with progress,
//! then the report (a table, or JSON with every case).

use super::Progress;
use ahcmon::eval::matrix::{self, MatrixSpec};
use ahcmon::output::matrix::render;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

pub fn run(spec: MatrixSpec, json: bool) -> anyhow::Result<()> {
    let cases = matrix::cases(&spec)?;
    let started = std::time::Instant::now();
    let done = AtomicUsize::new(0);
    let n = cases.len();
    let progress = Progress::new(true, "eval --matrix", n as u64);
    let results = cases
        .par_iter()
        .map(|c| {
            let r = matrix::run_case(c);
            let k = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress.step(&format!("{k}/{n} flights"));
            r
        })
        .collect::<Result<Vec<_>, _>>()?;
    progress.clear();
    let rows = matrix::report(&results);
    if json {
        let doc = serde_json::json!({ "report": rows, "cases": results });
        outln!("{doc}");
    } else {
        out!("{}", render(&rows));
        outln!(
            "{n} flights in {:.0} s; a fault is oracle-detectable when the matched filter that knows the true model and the fault reaches lambda >= {:.1} within {} s (false alarm 1e-6, power 95 %)",
            started.elapsed().as_secs_f64(),
            ahcmon::eval::oracle::DETECTABLE_LAMBDA,
            matrix::NAME_WITHIN_S
        );
    }
    Ok(())
}
