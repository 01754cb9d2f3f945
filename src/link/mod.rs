//! Where frames come from and go to: tlog files and live MAVLink connections, one file per
//! transport. I/O only: the frames themselves are `crate::protocol`.

pub mod conn;
mod serial;
pub mod spec;
mod tcp;
pub mod tlog;
mod udp;

pub use conn::{Link, Received};
pub use spec::{ConnError, ConnSpec};
pub use tlog::{TlogReader, TlogWriter};
