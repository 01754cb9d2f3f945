//! `import ahcmon`: one log's rows (`replay`) and the health-over-flights fit (`history`),
//! the same as `ahcmon scan` and `ahcmon history --json` give, so that an existing engine
//! (Dask, Ray, Spark's Python workers) can fan an archive out one log per task.
//!
//! Values cross as JSON text (serde_json out, Python's `json` in, and back for `history`):
//! a double printed by serde_json reads back as the same double, so the rows are the CLI's
//! to the bit. The GIL is released while a log is replayed.

use ahcmon::airframes::Airframes;
use ahcmon::history::{HistoryRule, series};
use ahcmon::output::flights::log_rows;
use ahcmon::pipeline::PipelineConfig;
use ahcmon::telemetry::Profile;
use pyo3::exceptions::{PyFileNotFoundError, PyValueError};
use pyo3::prelude::*;
use std::path::PathBuf;

fn from_json<'py>(py: Python<'py>, value: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?
        .call_method1("loads", (value.to_string(),))
}

fn to_json(py: Python<'_>, object: &Bound<'_, PyAny>) -> PyResult<serde_json::Value> {
    let text: String = py
        .import("json")?
        .call_method1("dumps", (object,))?
        .extract()?;
    serde_json::from_str(&text).map_err(|e| PyValueError::new_err(format!("not JSON rows: {e}")))
}

/// The rows of one log (tlog, DataFlash .bin or PX4 .ulg, told by content): a list of dicts,
/// one per vehicle × actuator, exactly as `ahcmon scan --rows` writes them.
///
/// profile: a built-in profile name or a profile TOML file for every vehicle (default: chosen
/// from the log and calibrated in flight). airframes: an airframes TOML file naming the
/// log's airframe. Raises FileNotFoundError for a missing log and ValueError for one that
/// cannot be read, or a bad profile or airframes file.
#[pyfunction]
#[pyo3(signature = (path, profile=None, airframes=None))]
fn replay<'py>(
    py: Python<'py>,
    path: PathBuf,
    profile: Option<String>,
    airframes: Option<PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    if !path.exists() {
        return Err(PyFileNotFoundError::new_err(format!(
            "{}: no such file",
            path.display()
        )));
    }
    let config = PipelineConfig {
        profile: profile
            .as_deref()
            .map(Profile::resolve)
            .transpose()
            .map_err(|e| PyValueError::new_err(e.to_string()))?,
        ..PipelineConfig::default()
    };
    let airframes = airframes
        .as_deref()
        .map(Airframes::load)
        .transpose()
        .map_err(|e| PyValueError::new_err(e.to_string()))?;
    // A panic in one log's replay is that log's ValueError, as it is that log's failure in
    // `scan`: PyO3 would raise PanicException, a BaseException an archive's loop won't catch.
    let rows = py
        .detach(|| {
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                log_rows(&path, &config, airframes.as_ref())
            }))
            .unwrap_or_else(|_| {
                Err("internal error while replaying it (a bug: please report the log)".into())
            })
        })
        .map_err(|why| PyValueError::new_err(format!("{}: {why}", path.display())))?;
    from_json(py, &serde_json::Value::Array(rows))
}

/// The health-over-flights fit of `replay`'s rows (any number of logs, any order): a list
/// of series, one per airframe × actuator, as `ahcmon history --json` writes them (flights
/// in start-time order, the trend over the last `window`, the first alarm's flight).
#[pyfunction]
#[pyo3(signature = (rows, loss_gamma=0.8, horizon=10.0, window=12, false_alarm=0.001))]
fn history<'py>(
    py: Python<'py>,
    rows: &Bound<'py, PyAny>,
    loss_gamma: f64,
    horizon: f64,
    window: usize,
    false_alarm: f64,
) -> PyResult<Bound<'py, PyAny>> {
    let check = |name: &str, x: f64, lo: f64, hi: f64| {
        if x.is_finite() && (lo..=hi).contains(&x) {
            Ok(x)
        } else {
            Err(PyValueError::new_err(format!(
                "{name} must be in [{lo}, {hi}], not {x}"
            )))
        }
    };
    let rule = HistoryRule {
        loss_gamma: check("loss_gamma", loss_gamma, 0.0, 2.0)?,
        horizon: check("horizon", horizon, 0.0, 1e6)?,
        window: check("window", window as f64, 4.0, 1000.0)? as usize,
        false_alarm: check("false_alarm", false_alarm, 1e-9, 0.5)?,
    };
    let rows = match to_json(py, rows)? {
        serde_json::Value::Array(rows) => rows,
        _ => return Err(PyValueError::new_err("rows must be a list of dicts")),
    };
    let doc: Vec<serde_json::Value> = series(&rows, &rule).iter().map(|s| s.json()).collect();
    from_json(py, &serde_json::Value::Array(doc))
}

#[pymodule]
#[pyo3(name = "ahcmon")]
fn ahcmon_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(replay, m)?)?;
    m.add_function(wrap_pyfunction!(history, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
