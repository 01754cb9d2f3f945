//! Where frames come from and go to: tlog files and live MAVLink connections, one file per
//! transport. I/O only: the frames themselves are `crate::protocol`.

pub mod conn;
pub mod dataflash;
pub mod logfile;
mod serial;
pub mod spec;
mod tcp;
pub mod tlog;
mod udp;
pub mod ulog;

pub use conn::{Link, Received};
pub use logfile::{LogError, LogFormat, LogItem, LogReport, read_log, sniff};
pub use spec::{ConnError, ConnSpec};
pub use tlog::{TlogReader, TlogWriter};
