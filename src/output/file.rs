//! Output files, and `-` for standard output on every output flag.
//!
//! An output file is opened when the run starts (so a path that cannot be written fails at
//! once) but not emptied: an existing file is replaced in place when the run writes its first
//! byte, or at its end if it wrote none. A run that stops on an error before either leaves the
//! file as it was (see `jsonl`).
//!
//! `-` is standard output. Once an output flag names it ([`take_stdout`]), what would be
//! printed for a person (decision lines, tables, the summary) goes to standard error, so that
//! standard output carries that output alone (`ahcmon replay f.tlog --decisions - | jq`).

use std::fs::File;
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

static STDOUT_TAKEN: AtomicBool = AtomicBool::new(false);

/// Whether an output path is `-`, standard output.
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// An output flag names standard output: the text for a person goes to standard error.
pub fn take_stdout() {
    STDOUT_TAKEN.store(true, Ordering::Relaxed);
}

/// Whether standard output carries an output (see [`take_stdout`]).
pub fn stdout_taken() -> bool {
    STDOUT_TAKEN.load(Ordering::Relaxed)
}

/// Where text for a person goes: standard output, or standard error once an output flag took
/// standard output.
pub fn for_people() -> Box<dyn Write> {
    if stdout_taken() {
        Box::new(std::io::stderr())
    } else {
        Box::new(std::io::stdout())
    }
}

/// A whole output written at once (a plot, a profile, a JSON document): to the file, which is
/// replaced, or to standard output for `-`.
pub fn write_whole(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if is_stdout(path) {
        let mut out = std::io::stdout().lock();
        reader_gone(out.write_all(bytes).and_then(|()| out.flush()))
    } else {
        std::fs::write(path, bytes)
    }
}

/// Standard output's reader may stop reading (`| head`): what it did not want is not an
/// error of the run, said once.
fn reader_gone(r: std::io::Result<()>) -> std::io::Result<()> {
    match r {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
            static SAID: AtomicBool = AtomicBool::new(false);
            if !SAID.swap(true, Ordering::Relaxed) {
                tracing::info!("standard output's reader stopped reading: the rest is not written");
            }
            Ok(())
        }
        r => r,
    }
}

#[derive(Debug)]
enum Target {
    File(File),
    /// Standard output; `None` once its reader stopped reading.
    Stdout(Option<std::io::Stdout>),
}

/// A file opened for writing without emptying it: emptied before its first byte is written,
/// or by [`OutputFile::empty`] (see the module note). `-` is standard output.
#[derive(Debug)]
pub struct OutputFile {
    target: Target,
    emptied: bool,
    /// The file this run created (it did not exist): removed when the run ends without
    /// writing or emptying it (it stopped on an error).
    created: Option<std::path::PathBuf>,
}

impl OutputFile {
    /// Open (create if missing) without truncating; the error names the file.
    pub fn open(path: &Path) -> std::io::Result<Self> {
        if is_stdout(path) {
            return Ok(Self {
                target: Target::Stdout(Some(std::io::stdout())),
                emptied: true,
                created: None,
            });
        }
        let existed = std::fs::symlink_metadata(path).is_ok();
        let file = std::fs::OpenOptions::new()
            .append(true)
            .create(true)
            .open(path)
            .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))?;
        Ok(Self {
            target: Target::File(file),
            emptied: false,
            created: (!existed).then(|| path.to_path_buf()),
        })
    }

    /// Empty the file unless done already (a device, a pipe or stdout has nothing to empty).
    pub fn empty(&mut self) -> std::io::Result<()> {
        if !self.emptied {
            if let Target::File(file) = &self.target
                && file.metadata()?.is_file()
            {
                file.set_len(0)?;
            }
            self.emptied = true;
        }
        Ok(())
    }
}

impl Drop for OutputFile {
    fn drop(&mut self) {
        if let (false, Some(path), Target::File(file)) = (self.emptied, &self.created, &self.target)
            && file.metadata().is_ok_and(|m| m.len() == 0)
        {
            let _ = std::fs::remove_file(path);
        }
    }
}

impl Write for OutputFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.empty()?;
        match &mut self.target {
            Target::File(f) => f.write(buf),
            Target::Stdout(out) => {
                if let Some(s) = out {
                    match s.write(buf) {
                        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => {
                            *out = None;
                            reader_gone(Err(e))?;
                        }
                        r => return r,
                    }
                }
                Ok(buf.len())
            }
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.target {
            Target::File(f) => f.flush(),
            Target::Stdout(Some(s)) => match s.flush() {
                Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => reader_gone(Err(e)),
                r => r,
            },
            Target::Stdout(None) => Ok(()),
        }
    }
}
