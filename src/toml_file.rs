//! The TOML files ahcmon reads (scenarios, vehicle profiles): lookup of a name among the
//! built-in ones or as a path, parsing with the line of the error, and validation. One error
//! type for both, so a bad file reads the same whatever kind it is.

use serde::de::DeserializeOwned;
use std::borrow::Cow;
use std::path::Path;
use thiserror::Error;

#[derive(Debug, Error)]
pub enum TomlFileError {
    // Not `source`: the reason is in the message already, and a source would print twice in
    // an error chain.
    #[error("{path}: cannot read: {reason}")]
    Io {
        path: String,
        reason: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: String,
        line: usize,
        message: String,
    },
    #[error("{path}: {message}")]
    Invalid { path: String, message: String },
    #[error("no {kind} file or built-in {kind} named `{name}` (built-in: {builtin})")]
    NotFound {
        kind: &'static str,
        name: String,
        builtin: String,
    },
}

/// What a name led to: the file's stem, the label errors name it by, and its text.
#[derive(Debug)]
pub struct Source {
    pub stem: String,
    pub label: String,
    pub text: Cow<'static, str>,
}

/// A built-in file by stem (`builtin` holds `(stem, text)`; `dir` is where the repository keeps
/// them, for error labels), else a file by path. A name that looks like a path (`.toml`, `/`)
/// and is not there is a missing file; any other unknown name lists the built-in ones.
pub fn find(
    name_or_path: &str,
    builtin: &[(&str, &'static str)],
    dir: &str,
    kind: &'static str,
) -> Result<Source, TomlFileError> {
    if let Some((stem, text)) = builtin.iter().find(|(stem, _)| *stem == name_or_path) {
        return Ok(Source {
            stem: stem.to_string(),
            label: format!("{dir}/{stem}.toml"),
            text: Cow::Borrowed(text),
        });
    }
    let path = Path::new(name_or_path);
    if path.exists() || name_or_path.ends_with(".toml") || name_or_path.contains('/') {
        let text = read_capped(path).map_err(|reason| TomlFileError::Io {
            path: name_or_path.to_string(),
            reason,
        })?;
        let stem = path.file_stem().map_or(name_or_path.to_string(), |s| {
            s.to_string_lossy().into_owned()
        });
        return Ok(Source {
            stem,
            label: name_or_path.to_string(),
            text: Cow::Owned(text),
        });
    }
    Err(TomlFileError::NotFound {
        kind,
        name: name_or_path.to_string(),
        builtin: builtin
            .iter()
            .map(|(s, _)| *s)
            .collect::<Vec<_>>()
            .join(", "),
    })
}

/// The largest TOML file read: a profile or scenario is a few kilobytes, and a path to a
/// device or pipe that never ends (`/dev/zero`) must not be read until memory runs out.
pub const MAX_TOML_BYTES: u64 = 1 << 20;

fn read_capped(path: &Path) -> std::io::Result<String> {
    let bytes = read_at_most(path, MAX_TOML_BYTES, "a profile or scenario")?;
    String::from_utf8(bytes)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()))
}

/// A small input file's bytes, refused past `cap` (`what` names it in the error) instead of
/// read to the end of a device or pipe that never ends.
pub fn read_at_most(path: &Path, cap: u64, what: &str) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut bytes = Vec::new();
    std::fs::File::open(path)?
        .take(cap + 1)
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > cap {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("over {} KiB: not {what}", cap >> 10),
        ));
    }
    Ok(bytes)
}

/// Parse `text` (unknown keys are errors where the type says `deny_unknown_fields`) and
/// validate it; `path` only names the source in errors.
pub fn parse<T: DeserializeOwned>(
    text: &str,
    path: &str,
    validate: impl FnOnce(&T) -> Result<(), String>,
) -> Result<T, TomlFileError> {
    let value: T = toml::from_str(text).map_err(|e| TomlFileError::Parse {
        path: path.to_string(),
        line: error_line(text, &e),
        message: e.message().trim().replace('\n', " "),
    })?;
    validate(&value).map_err(|message| match key_line(text, &message) {
        Some(line) => TomlFileError::Parse {
            path: path.to_string(),
            line,
            message,
        },
        None => TomlFileError::Invalid {
            path: path.to_string(),
            message,
        },
    })?;
    Ok(value)
}

/// The 1-based line of the key a validation message starts with (`noise.gyro must be ...`,
/// `model: ...`): a `key = ` line under its table, or the table's header. None when the key is
/// not written as such (an inline table, an array of tables, a default).
fn key_line(text: &str, message: &str) -> Option<usize> {
    let end = message
        .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '.'))
        .unwrap_or(message.len());
    let key = &message[..end];
    if key.is_empty() || !message[end..].starts_with([' ', ':']) {
        return None;
    }
    let mut table = String::new();
    // Inside a multi-line string (its delimiter): its lines are text, not keys or headers.
    let mut open: Option<&str> = None;
    for (i, line) in text.lines().enumerate() {
        if let Some(delim) = open {
            if line.matches(delim).count() % 2 == 1 {
                open = None;
            }
            continue;
        }
        let line = line.trim();
        if let Some(header) = line.strip_prefix('[') {
            if header.starts_with('[') {
                // Arrays of tables hold many entries of one key: no single line to name.
                table = "\u{0}".into();
                continue;
            }
            // Up to the closing bracket (a comment may follow).
            table = header
                .split(']')
                .next()
                .unwrap_or_default()
                .trim()
                .to_string();
            if table == key {
                return Some(i + 1);
            }
        } else if let Some((k, value)) = line.split_once('=') {
            let k = k.trim();
            let full = if table.is_empty() {
                k.to_string()
            } else {
                format!("{table}.{k}")
            };
            if full == key {
                return Some(i + 1);
            }
            open = ["\"\"\"", "'''"]
                .into_iter()
                .find(|d| value.matches(d).count() % 2 == 1);
        }
    }
    None
}

/// 1-based line of a TOML error (0 when the error has no position).
fn error_line(text: &str, e: &toml::de::Error) -> usize {
    e.span().map_or(0, |s| {
        text[..s.start.min(text.len())].matches('\n').count() + 1
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    struct Thing {
        size: f64,
    }

    const BUILTIN: &[(&str, &str)] = &[("small", "size = 1.0\n")];

    fn positive(t: &Thing) -> Result<(), String> {
        (t.size > 0.0)
            .then_some(())
            .ok_or_else(|| format!("size must be positive (got {})", t.size))
    }

    #[test]
    fn finds_builtin_then_files_and_names_what_is_missing() {
        let s = find("small", BUILTIN, "things", "thing").expect("built-in");
        assert_eq!(
            (s.stem.as_str(), s.label.as_str()),
            ("small", "things/small.toml")
        );
        let dir = std::env::temp_dir().join(format!("ahcmon-toml-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("dir");
        let file = dir.join("big.toml");
        std::fs::write(&file, "size = 3.0\n").expect("write");
        let s = find(file.to_str().expect("utf-8"), BUILTIN, "things", "thing").expect("file");
        assert_eq!(s.stem, "big");
        assert_eq!(s.text, "size = 3.0\n");
        let missing = find("nope.toml", BUILTIN, "things", "thing").unwrap_err();
        assert!(matches!(missing, TomlFileError::Io { .. }), "{missing}");
        // The reason is said once, also where the error is printed as a chain.
        let chain = format!("{:#}", anyhow::Error::from(missing));
        assert_eq!(chain.matches("No such file").count(), 1, "{chain}");
        let unknown = find("nope", BUILTIN, "things", "thing").unwrap_err();
        assert_eq!(
            unknown.to_string(),
            "no thing file or built-in thing named `nope` (built-in: small)"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn parse_errors_name_the_line_and_the_key() {
        let t: Thing = parse("size = 2.0\n", "t.toml", positive).expect("valid");
        assert_eq!(t.size, 2.0);
        let e = parse::<Thing>("\nsize = 2.0\ncolour = 1\n", "t.toml", positive).unwrap_err();
        let msg = e.to_string();
        assert!(msg.starts_with("t.toml:3: "), "{msg}");
        assert!(msg.contains("colour"), "{msg}");
        // A value check names the line of its key too.
        let e = parse::<Thing>("# a thing\nsize = -1.0\n", "t.toml", positive).unwrap_err();
        assert_eq!(e.to_string(), "t.toml:2: size must be positive (got -1)");
    }

    #[test]
    fn a_value_check_finds_its_key_under_its_table() {
        let text = "rate_hz = 0\n[model]\ndamping = 1\n[noise]\ngyro = nan\n[[fault]]\ngyro = 1\n";
        assert_eq!(key_line(text, "rate_hz must be positive"), Some(1));
        assert_eq!(key_line(text, "noise.gyro must be positive"), Some(5));
        assert_eq!(key_line(text, "model: numbers must be finite"), Some(2));
        // Not written (a default), or in an array of tables: no line.
        assert_eq!(key_line(text, "noise.az must be positive"), None);
        assert_eq!(key_line(text, "fault.gyro must be positive"), None);
        assert_eq!(key_line(text, "the actuators overlap"), None);
        // Not inside a multi-line string; a header may carry a comment.
        let text = "description = \"\"\"\nrate_hz = 50 on the bench\n[noise]\n\"\"\"\nrate_hz = -1\n[noise] # levels\ngyro = nan\n";
        assert_eq!(key_line(text, "rate_hz must be positive"), Some(5));
        assert_eq!(key_line(text, "noise.gyro must be positive"), Some(7));
    }
}
