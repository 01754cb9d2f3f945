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

/// A whole output written at once (a plot, a profile, a JSON document, a table): to standard
/// output for `-`, else the file is replaced atomically: the bytes go to a new file beside it,
/// which is renamed over it once they are all written, so a failed write (a full disk) leaves
/// the file as it was and no reader sees half of it. The new file takes the old one's
/// permissions. What is not a regular file or a missing one (a device such as `/dev/null`, a
/// pipe, a symbolic link) is written in place, since renaming would replace it.
pub fn write_whole(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if is_stdout(path) {
        let mut out = std::io::stdout().lock();
        return reader_gone(out.write_all(bytes).and_then(|()| out.flush()));
    }
    let old = match std::fs::symlink_metadata(path) {
        Ok(m) if !m.is_file() => return std::fs::write(path, bytes),
        Ok(m) => Some(m.permissions()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(e),
    };
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file name"))?;
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(name);
    temp_name.push(format!(".{}.partial", std::process::id()));
    let temp = path.with_file_name(temp_name);
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&temp)?;
    let written = (|| {
        file.write_all(bytes)?;
        if let Some(permissions) = old {
            file.set_permissions(permissions)?;
        }
        file.sync_all()?;
        std::fs::rename(&temp, path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&temp);
    }
    written
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

#[cfg(test)]
mod tests {
    use super::write_whole;
    use std::os::unix::fs::PermissionsExt;

    fn dir() -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!(
            "ahcmon-write-whole-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(d: &std::path::Path) -> Vec<String> {
        let mut names: Vec<String> = (std::fs::read_dir(d).unwrap())
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_whole_output_replaces_the_file_keeping_its_permissions_and_leaves_nothing_beside() {
        let d = dir();
        let path = d.join("plot.svg");
        write_whole(&path, b"first").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_whole(&path, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second, longer");
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o640);
        assert_eq!(entries(&d), ["plot.svg"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_write_that_fails_leaves_the_old_file_as_it_was() {
        let d = dir();
        let path = d.join("rows.parquet");
        std::fs::write(&path, b"yesterday").unwrap();
        // The new file's name taken by a directory: the write fails before the rename.
        let temp = d.join(format!(".rows.parquet.{}.partial", std::process::id()));
        std::fs::create_dir(&temp).unwrap();
        assert!(write_whole(&path, b"today").is_err());
        assert_eq!(std::fs::read(&path).unwrap(), b"yesterday");
        assert!(temp.is_dir(), "what was not the write's own is left alone");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_device_is_written_in_place_not_replaced() {
        let null = std::path::Path::new("/dev/null");
        write_whole(null, b"nothing").unwrap();
        use std::os::unix::fs::FileTypeExt;
        assert!(
            std::fs::metadata(null)
                .unwrap()
                .file_type()
                .is_char_device()
        );
    }
}
