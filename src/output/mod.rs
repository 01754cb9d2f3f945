//! Sinks: the eval table and JSON, SVG plots.

pub mod alerts;
pub mod dashboard;
pub mod jsonl;
pub mod summary;
pub mod svg;
pub mod table;
