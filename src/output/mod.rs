//! Sinks: the eval table and JSON, SVG plots.

pub mod svg;
pub mod table;
